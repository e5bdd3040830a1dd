//! `omnirow eval`: the paper's experiments regenerated on synthetic images and scored.

use crate::camera::Calibration;
use crate::detect::Method;
use crate::eval::{self, EvalOptions, Lens};
use anyhow::Context;
use clap::{Args, Subcommand};
use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct EvalArgs {
    #[command(subcommand)]
    pub command: Option<EvalCommand>,
    /// Folder for README.md (the tables), the PNG plots and outcomes.jsonl.
    #[arg(long, default_value = "eval-out")]
    pub out: PathBuf,
    /// A run of under a minute: few images, half resolution.
    #[arg(long)]
    pub quick: bool,
    /// Images for Table I (default 100; 8 with --quick).
    #[arg(long)]
    pub images: Option<usize>,
    /// Also draw Table I's scenes with the second appearance model (`synth --style leafy`)
    /// and report Table I on it.
    #[arg(long)]
    pub leafy: bool,
    /// Images per lens for Table II (default 100; 6 with --quick).
    #[arg(long)]
    pub table2_images: Option<usize>,
    /// Images per lens and plant distance for figures 8 and 9 (default 10; 2 with --quick).
    #[arg(long)]
    pub distance_images: Option<usize>,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Calibration files to evaluate on (OCamCalib or TOML), repeatable. Default: omnirow's
    /// ideal 185° fisheye and panoramic annular lens for the GC2450C.
    #[arg(long = "lens")]
    pub lenses: Vec<PathBuf>,
    /// Resolution factor: 1 full, 0.5 half (default 1; 0.5 with --quick).
    #[arg(long)]
    pub scale: Option<f64>,
    /// Score the detector with the `[detector]` options of this node configuration (the
    /// method is set by --methods), to see what a tuning does on the paper's protocol.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Methods to score, comma-separated.
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "edge,hough,combined"
    )]
    pub methods: Vec<Method>,
}

/// Evaluations other than the paper's synthetic protocol.
#[derive(Debug, Subcommand)]
pub enum EvalCommand {
    /// Score the detector on real images with labelled crop rows (docs/real.md).
    Real(super::eval_real::RealArgs),
    /// Score row guidance (offset, heading, curvature, end of rows, empty stretches) on
    /// synthetic drives through the detector and the tracker (docs/guidance.md).
    Guidance(GuidanceArgs),
}

#[derive(Debug, Args)]
pub struct GuidanceArgs {
    /// Folder for README.md (the table) and the PNG plots.
    #[arg(long, default_value = "eval-guidance")]
    pub out: PathBuf,
    /// Seconds per drive (15 frames a second).
    #[arg(long, default_value_t = 20.0)]
    pub seconds: f64,
    /// Frame size (default: the GC2450C at half resolution).
    #[arg(long, default_value_t = 1224)]
    pub width: u32,
    #[arg(long, default_value_t = 1024)]
    pub height: u32,
    /// Run every frame's full search (no prior from the tracker's prediction, as the node
    /// with `[pipeline] narrow_search = false`).
    #[arg(long)]
    pub no_narrow: bool,
    /// The drives to run: weaving, crossing, curved_r20, headland, field (all in one drive:
    /// weaving, the crossing, an empty stretch and the rows' end; for long runs).
    #[arg(long, value_delimiter = ',', default_values_t = eval::guidance::DEFAULT_DRIVES.map(String::from))]
    pub drives: Vec<String>,
    /// Threads each frame's independent parts run on (the answers are the same with any
    /// number; the node's `[pipeline] threads`).
    #[arg(long, value_name = "N", default_value_t = crate::pipeline::DEFAULT_THREADS as u16,
          value_parser = clap::value_parser!(u16).range(1..=16))]
    pub threads: u16,
    /// Render the drives through this calibration (OCamCalib or omnirow TOML) instead of the
    /// ideal fisheye of --width x --height.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["width", "height"])]
    pub calib: Option<PathBuf>,
    /// With --calib: its resolution times K (0.5: half).
    #[arg(long, value_name = "K", requires = "calib")]
    pub scale: Option<f64>,
    /// The drives' weaving: largest lateral offset from the path's centre line, metres.
    #[arg(long, value_name = "M")]
    pub offset_amplitude_m: Option<f64>,
    /// The drives' weaving: largest heading, degrees.
    #[arg(long, value_name = "DEG")]
    pub heading_amplitude_deg: Option<f64>,
    /// With --images: run each drive over this many photographs' grounds (those that fit,
    /// from --photo-index or the first on) and add a row pooling them.
    #[arg(long, value_name = "N", default_value_t = 1, requires = "images",
          value_parser = clap::value_parser!(u16).range(1..=500))]
    pub photos: u16,
    /// The node's configuration: its `[detector]`, `[guidance]` and `[pipeline]`
    /// (narrow_search, min_quality) as `omnirow run` reads them [default: the defaults,
    /// the search narrowed unless --no-narrow].
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    #[command(flatten)]
    pub photo: super::synth::photo::PhotoArgs,
}

/// `omnirow eval guidance`.
fn guidance(a: GuidanceArgs) -> anyhow::Result<ExitCode> {
    anyhow::ensure!(
        a.seconds.is_finite() && a.seconds > 0.0 && a.seconds <= 3600.0,
        "--seconds {} must be in (0, 3600]",
        a.seconds
    );
    let mut step = match &a.config {
        Some(p) => {
            let cfg = crate::config::Config::load(p)?;
            anyhow::ensure!(
                cfg.guidance.is_some(),
                "{}: [guidance] enabled = false: the drives score row guidance",
                p.display()
            );
            cfg.perception()
        }
        None => crate::perception::PerceptionOptions::default(),
    };
    if a.no_narrow {
        step.narrow_search = false;
    }
    step.threads = a.threads.into();
    let mut all = eval::guidance::scenarios(a.width, a.height, a.seconds);
    for s in &mut all {
        if let Some(m) = a.offset_amplitude_m {
            anyhow::ensure!((0.0..=5.0).contains(&m), "--offset-amplitude-m {m}: 0..=5");
            s.drive.offset_amplitude_m = m;
        }
        if let Some(d) = a.heading_amplitude_deg {
            anyhow::ensure!(
                (0.0..=45.0).contains(&d),
                "--heading-amplitude-deg {d}: 0..=45"
            );
            s.drive.heading_amplitude_deg = d;
        }
    }
    let settings = guidance_settings(&a)?;
    if let Some(bad) = a
        .drives
        .iter()
        .find(|d| !all.iter().any(|s| s.name == d.as_str()))
    {
        anyhow::bail!(
            "--drives: no drive {bad:?} (there are {})",
            all.iter().map(|s| s.name).collect::<Vec<_>>().join(", ")
        );
    }
    let mut scores = Vec::new();
    for s in all
        .into_iter()
        .filter(|s| a.drives.iter().any(|d| d == s.name))
    {
        for setting in &settings {
            let name = setting.photo.as_ref().map(|p| p.1.as_str()).unwrap_or("");
            eprintln!("eval guidance: {} {name} ({} frames)", s.name, s.frames);
            scores.push(eval::guidance::run_drive(&s, setting, &step)?);
        }
        if settings.len() > 1 {
            let name = format!("{} ({} photographs)", s.name, settings.len());
            scores.extend(eval::guidance::pooled(&scores, s.name, &name));
        }
    }
    let command: Vec<String> = std::env::args().collect();
    let command = format!("omnirow {}", command[1..].join(" "));
    let files = eval::guidance::write(&scores, &a.out, &command)?;
    print!("{}", eval::guidance::markdown(&scores, &command));
    for f in files {
        eprintln!("eval: wrote {}", f.display());
    }
    Ok(ExitCode::SUCCESS)
}

/// The settings the drives run in: `--calib` (at `--scale`) or the ideal fisheye, over the
/// synthetic ground or each of `--photos` photographs' grounds.
fn guidance_settings(a: &GuidanceArgs) -> anyhow::Result<Vec<eval::guidance::Setting>> {
    let calibration = match &a.calib {
        Some(p) => Some(super::sim::scaled(
            Calibration::load(p)?,
            a.scale.unwrap_or(1.0),
        )?),
        None => None,
    };
    if a.photo.images.is_none() {
        return Ok(vec![eval::guidance::Setting {
            calibration,
            photo: None,
        }]);
    }
    anyhow::ensure!(
        !a.photo.photo_survey,
        "--photo-survey belongs to omnirow synth (it renders nothing)"
    );
    let spacing = crate::synth::SynthOptions::default().row_spacing_m;
    let photos = super::synth::photo::choose_many(&a.photo, spacing, 0, a.photos.into())?;
    if photos.len() < a.photos.into() {
        eprintln!(
            "eval guidance: {} of the {} photographs asked for fit",
            photos.len(),
            a.photos
        );
    }
    Ok(photos
        .into_iter()
        .map(|(g, path)| eval::guidance::Setting {
            calibration: calibration.clone(),
            photo: Some((
                std::sync::Arc::new(g),
                path.file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_else(|| path.display().to_string()),
            )),
        })
        .collect())
}

pub fn run(a: EvalArgs) -> anyhow::Result<ExitCode> {
    match a.command {
        Some(EvalCommand::Real(r)) => return super::eval_real::run(r),
        Some(EvalCommand::Guidance(g)) => return guidance(g),
        None => {}
    }
    let lenses = if a.lenses.is_empty() {
        Lens::builtin()
    } else {
        a.lenses
            .iter()
            .map(|p| {
                Ok(Lens {
                    name: p
                        .file_stem()
                        .map(|s| s.to_string_lossy().into_owned())
                        .unwrap_or_else(|| p.display().to_string()),
                    calibration: Calibration::load(p)?,
                })
            })
            .collect::<anyhow::Result<Vec<_>>>()?
    };
    let mut opts = if a.quick {
        EvalOptions::quick(lenses)
    } else {
        EvalOptions::full(lenses)
    };
    opts.seed = a.seed;
    opts.table1_leafy = a.leafy;
    if let Some(p) = &a.config {
        opts.detector = crate::config::Config::load(p)?.detector;
    }
    if let Some(n) = a.images {
        opts.table1_images = n;
    }
    if let Some(n) = a.table2_images {
        opts.table2_images = n;
    }
    if let Some(n) = a.distance_images {
        opts.distance_images = n;
    }
    if let Some(s) = a.scale {
        anyhow::ensure!(
            s.is_finite() && s > 0.0,
            "--scale {s}: must be a positive factor (0.5: half resolution)"
        );
        // the evaluation divides the calibration's resolution by its `scale`
        opts.scale = 1.0 / s;
    }
    opts.methods = a.methods;
    let tty = std::io::stderr().is_terminal();
    let started = std::time::Instant::now();
    let mut last_pct = usize::MAX;
    let results = eval::run(&opts, |done, total| {
        let pct = done * 100 / total.max(1);
        let mut err = std::io::stderr();
        if tty {
            let bar = "#".repeat(pct / 4) + &" ".repeat(25 - pct / 4);
            let _ = write!(
                err,
                "\reval [{bar}] {done}/{total} images, {:.0} s",
                started.elapsed().as_secs_f64()
            );
            if done == total {
                let _ = writeln!(err);
            }
        } else if pct / 10 != last_pct / 10 || done == total {
            let _ = writeln!(err, "eval: {done}/{total} images ({pct}%)");
        }
        last_pct = pct;
    })?;
    let command: Vec<String> = std::env::args().collect();
    let command = format!("omnirow {}", command[1..].join(" "));
    let files = eval::report::write(&results, &a.out, &command)
        .with_context(|| format!("writing the report into {}", a.out.display()))?;
    print!("{}", eval::report::markdown(&results, &command));
    for f in files {
        eprintln!("eval: wrote {}", f.display());
    }
    Ok(ExitCode::SUCCESS)
}
