//! `omnirow synth`: render a synthetic field image through a calibration, with its ground truth;
//! its ground the synthetic plants or a labelled photograph's ([`photo`]).

pub(super) mod photo;

use super::calib::LensArg;
use crate::camera::{Calibration, IdealLens};
use crate::synth::{random_scene, Protocol, Renderer, Scene, Style, SynthOptions};
use anyhow::{bail, Context};
use clap::{Args, ValueEnum};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

/// Sensor size of the built-in lenses (the GC2450C's).
const SENSOR: (u32, u32) = (2050, 2448);

#[derive(Debug, Args)]
pub struct SynthArgs {
    /// Calibration to render through (OCamCalib calib_results.txt or omnirow TOML).
    #[arg(long, conflicts_with = "lens")]
    calib: Option<PathBuf>,
    /// Built-in ideal lens (when no --calib), for the GC2450C's 2448x2050 sensor unless
    /// --image-height/--image-width say otherwise.
    #[arg(long, value_enum)]
    lens: Option<LensArg>,
    /// Image height of the built-in lens, pixels (the lens's image circle fits it).
    #[arg(long, default_value_t = SENSOR.0, conflicts_with = "calib")]
    image_height: u32,
    /// Image width of the built-in lens, pixels.
    #[arg(long, default_value_t = SENSOR.1, conflicts_with = "calib")]
    image_width: u32,
    /// Seed of every random quantity (plant errors, weeds, noise, texture, --random).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Scene settings from a TOML file (keys of SynthOptions, e.g. `leaf_length_m = 0.05`;
    /// unknown keys are errors). Options given on the command line override it.
    #[arg(long, conflicts_with = "random")]
    options: Option<PathBuf>,
    /// Draw the scene settings at random as in one of the paper's tests (explicit options
    /// below override what it draws).
    #[arg(long, value_enum)]
    random: Option<ProtocolArg>,
    /// Robot yaw relative to the rows, degrees.
    #[arg(long, allow_negative_numbers = true)]
    yaw_deg: Option<f64>,
    /// Robot pitch, degrees (positive: nose down).
    #[arg(long, allow_negative_numbers = true)]
    pitch_deg: Option<f64>,
    /// Robot roll, degrees.
    #[arg(long, allow_negative_numbers = true)]
    roll_deg: Option<f64>,
    /// Camera height above the ground, metres.
    #[arg(long)]
    height_m: Option<f64>,
    /// Camera position across the rows, metres (row 0 at 0).
    #[arg(long, allow_negative_numbers = true)]
    lateral_m: Option<f64>,
    /// Distance between rows, metres.
    #[arg(long)]
    row_spacing_m: Option<f64>,
    /// Distance between plants along a row, metres.
    #[arg(long)]
    plant_distance_m: Option<f64>,
    /// Background salt-and-pepper noise density (0..1), smoothed afterwards.
    #[arg(long)]
    noise: Option<f64>,
    /// Standard deviation of the plant position error along the row, metres.
    #[arg(long)]
    along_sd_m: Option<f64>,
    /// Standard deviation of the plant position error across the row, metres.
    #[arg(long)]
    across_sd_m: Option<f64>,
    /// Number of weeds (plants at random positions).
    #[arg(long)]
    weeds: Option<usize>,
    /// Image style.
    #[arg(long, value_enum)]
    style: Option<StyleArg>,
    /// Render at K times the calibration's resolution (0.5: half), through the rescaled
    /// calibration.
    #[arg(long, default_value_t = 1.0)]
    scale: f64,
    /// Output image (PNG; the Bayer style is written as a one-channel PNG of the mosaic).
    #[arg(long, required_unless_present = "photo_survey")]
    out: Option<PathBuf>,
    /// Ground truth output (JSON).
    #[arg(long)]
    truth: Option<PathBuf>,
    #[command(flatten)]
    photo: photo::PhotoArgs,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum StyleArg {
    Grey,
    Colour,
    Bayer,
    /// The second appearance model: leaf clusters, uneven light, blur, Bayer, JPEG.
    Leafy,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum ProtocolArg {
    Table1,
    Table2,
}

pub fn run(args: SynthArgs) -> anyhow::Result<ExitCode> {
    if args.photo.photo_survey {
        let spacing = args
            .row_spacing_m
            .unwrap_or(SynthOptions::default().row_spacing_m);
        photo::survey(&args.photo, spacing)?;
        return Ok(ExitCode::SUCCESS);
    }
    let Some(out) = args.out.clone() else {
        bail!("--out: give the image to write (a .png file)");
    };
    if !out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"))
    {
        bail!(
            "--out {}: the image is written as PNG; give a .png file name",
            out.display()
        );
    }
    let (cal, lens_name) = match &args.calib {
        Some(path) => (Calibration::load(path)?, path.display().to_string()),
        None => {
            let lens = IdealLens::from(args.lens.unwrap_or(LensArg::Fisheye185));
            let (h, w) = (args.image_height, args.image_width);
            let cal = lens
                .calibration(h, w)
                .map_err(|e| anyhow::anyhow!("--image-height {h} --image-width {w}: {e}"))?;
            (cal, lens.name().to_string())
        }
    };
    let cal = super::sim::scaled(cal, args.scale)?;
    let mut opts = match args.random {
        Some(ProtocolArg::Table1) => random_scene(args.seed, Protocol::Table1),
        Some(ProtocolArg::Table2) => random_scene(args.seed, Protocol::Table2),
        None => match &args.options {
            Some(path) => {
                let text = std::fs::read_to_string(path)
                    .with_context(|| format!("reading {}", path.display()))?;
                toml::from_str::<SynthOptions>(&text)
                    .map_err(|e| anyhow::anyhow!("{}: {}", path.display(), e))?
            }
            None => SynthOptions::default(),
        },
    };
    let set = |slot: &mut f64, v: Option<f64>| {
        if let Some(v) = v {
            *slot = v;
        }
    };
    set(&mut opts.yaw_deg, args.yaw_deg);
    set(&mut opts.pitch_deg, args.pitch_deg);
    set(&mut opts.roll_deg, args.roll_deg);
    set(&mut opts.height_m, args.height_m);
    set(&mut opts.lateral_m, args.lateral_m);
    set(&mut opts.row_spacing_m, args.row_spacing_m);
    set(&mut opts.plant_distance_m, args.plant_distance_m);
    set(&mut opts.noise, args.noise);
    set(&mut opts.along_sd_m, args.along_sd_m);
    set(&mut opts.across_sd_m, args.across_sd_m);
    if let Some(w) = args.weeds {
        opts.weeds = w;
    }
    if let Some(s) = args.style {
        opts.style = match s {
            StyleArg::Grey => Style::Grey,
            StyleArg::Colour => Style::Colour,
            StyleArg::Bayer => Style::Bayer,
            StyleArg::Leafy => Style::Leafy,
        };
    }

    let t0 = Instant::now();
    let mut scene = Scene::new(&opts, args.seed, &cal.mounting)?;
    let mut ground_name = String::new();
    if args.photo.images.is_some() {
        let (ground, path) = photo::choose(&args.photo, opts.row_spacing_m, args.seed)?;
        let r = ground.rectification();
        ground_name = format!(
            ", ground from {} ({} rows, camera {:.2} m high)",
            path.display(),
            r.row_index.len(),
            r.camera_height_m
        );
        scene = scene.with_photo_ground(std::sync::Arc::new(ground))?;
    }
    let mut renderer = Renderer::new(&cal)?;
    let t1 = Instant::now();
    let cpu0 = process_cpu_s();
    let mut data = vec![0u8; renderer.buffer_len(opts.style)];
    renderer.render_into(&scene, &mut data)?;
    let t2 = Instant::now();
    let cpu_render = process_cpu_s().zip(cpu0).map(|(b, a)| b - a);
    let truth = crate::synth::GroundTruth::of_scene(&scene, &cal);
    let (w, h) = renderer.size();
    let colour = match opts.style {
        Style::Colour | Style::Leafy => image::ExtendedColorType::Rgb8,
        Style::Grey | Style::Bayer => image::ExtendedColorType::L8,
    };
    image::save_buffer_with_format(&out, &data, w, h, colour, image::ImageFormat::Png)
        .with_context(|| format!("writing {}", out.display()))?;
    if let Some(path) = &args.truth {
        let json = serde_json::to_string_pretty(&truth).context("serialising the ground truth")?;
        std::fs::write(path, json + "\n").with_context(|| format!("writing {}", path.display()))?;
    }
    eprintln!(
        "synth: {lens_name} {w}x{h} {:?} seed {} yaw {:.2} pitch {:.2} roll {:.2} deg, heading {:.3} tilt {:.3} deg, {} rows listed{ground_name}; setup {:.0} ms, render {:.0} ms{} -> {}",
        opts.style,
        args.seed,
        opts.yaw_deg,
        opts.pitch_deg,
        opts.roll_deg,
        truth.heading_rad.to_degrees(),
        truth.tilt_rad.to_degrees(),
        truth.row_normals.len(),
        (t1 - t0).as_secs_f64() * 1e3,
        (t2 - t1).as_secs_f64() * 1e3,
        cpu_render
            .map(|c| format!(" ({:.0} ms CPU)", c * 1e3))
            .unwrap_or_default(),
        out.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// CPU time (user + system) this process has used, seconds, where the OS tells (Linux).
fn process_cpu_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which is in parentheses and may hold spaces).
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    // utime and stime are fields 14 and 15 of the whole line, i.e. 11 and 12 here, in
    // clock ticks of USER_HZ (100 on Linux).
    let utime: f64 = f.get(11)?.parse().ok()?;
    let stime: f64 = f.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}
