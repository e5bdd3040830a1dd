//! `omnirow sim`: the closed steering loop on a synthetic field (docs/sim.md): the robot
//! steered by a controller on the node's own published guidance, scored against its true
//! pose.

use super::calib::LensArg;
use crate::camera::{Calibration, IdealLens};
use crate::eval::chart::{Chart, Kind, Series};
use crate::perception::{Perception, PerceptionOptions};
use crate::sim::{
    self, Controller, FrameRecord, Ground, Latency, RobotModel, SimOptions, Summary,
    SyntheticFieldOptions, SyntheticGround,
};
use crate::synth::Style;
use anyhow::{bail, Context};
use clap::{Args, ValueEnum};
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Sensor size of the built-in lenses (the GC2450C's), rows × columns.
const SENSOR: (u32, u32) = (2050, 2448);

#[derive(Debug, Args)]
#[command(group(clap::ArgGroup::new("camera").required(true).args(["calib", "lens"])))]
pub struct SimArgs {
    /// The node's configuration: its `[detector]`, `[guidance]` and `[pipeline]` sections
    /// (narrow_search, min_quality, threads) as `omnirow run` reads them.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// The camera's calibration (OCamCalib calib_results.txt or omnirow TOML); the field is
    /// rendered through it and the detector uses it.
    #[arg(long, value_name = "FILE", conflicts_with = "lens")]
    calib: Option<PathBuf>,
    /// A built-in ideal lens instead of --calib, for the GC2450C's 2448x2050 sensor unless
    /// --image-height/--image-width say otherwise.
    #[arg(long, value_enum)]
    lens: Option<LensArg>,
    /// Image height of the built-in lens, pixels.
    #[arg(long, default_value_t = SENSOR.0, conflicts_with = "calib")]
    image_height: u32,
    /// Image width of the built-in lens, pixels.
    #[arg(long, default_value_t = SENSOR.1, conflicts_with = "calib")]
    image_width: u32,
    /// Resolution factor: the calibration rescaled to K times its size (0.5: half).
    #[arg(long, value_name = "K", default_value_t = 1.0)]
    scale: f64,
    /// Forward speed, m/s.
    #[arg(long, value_name = "V", default_value_t = 1.5)]
    speed_mps: f64,
    /// Distance to drive along the rows, metres (the run also ends at the rows' end).
    #[arg(long, value_name = "D", default_value_t = 30.0)]
    distance_m: f64,
    /// Start this far left of the path's centre line, metres (negative: right).
    #[arg(
        long,
        value_name = "X",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    start_offset_m: f64,
    /// Start turned this far left of the rows, degrees (negative: right).
    #[arg(
        long,
        value_name = "Y",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    start_heading_deg: f64,
    /// Seed of the field's random quantities (soil texture).
    #[arg(long, value_name = "S", default_value_t = 1)]
    seed: u64,
    /// Frame rate, frames per second (the loop's step).
    #[arg(long, default_value_t = 15.0)]
    fps: f64,
    /// Steering controller.
    #[arg(long, value_enum, default_value_t = ControllerArg::PurePursuit)]
    controller: ControllerArg,
    /// Pure pursuit's lookahead, metres.
    #[arg(long, value_name = "M", default_value_t = 1.5)]
    lookahead_m: f64,
    /// Stanley's cross-track gain, 1/s.
    #[arg(long, value_name = "K", default_value_t = 1.0)]
    stanley_gain: f64,
    /// The frames' look [default: bayer where both image sides are even, else grey].
    #[arg(long, value_enum)]
    style: Option<StyleArg>,
    /// Robot model.
    #[arg(long, value_enum, default_value_t = RobotArg::DiffDrive)]
    robot: RobotArg,
    /// Wheelbase, metres: the Ackermann robot's, and Stanley's reference length (both
    /// robots).
    #[arg(long, value_name = "M", default_value_t = 1.0)]
    wheelbase_m: f64,
    /// The Ackermann robot's steering limit, degrees.
    #[arg(long, value_name = "DEG", default_value_t = 35.0)]
    max_steer_deg: f64,
    /// The differential drive's yaw-rate limit, degrees per second.
    #[arg(long, value_name = "DEG_S", default_value_t = 90.0)]
    max_yaw_rate_dps: f64,
    /// A fixed latency from a frame's capture to its command acting, milliseconds
    /// [default: the per-frame step's measured time for each frame].
    #[arg(long, value_name = "MS")]
    latency_ms: Option<f64>,
    /// Curvature of the rows, 1/m, positive bending left (radius 1/|c|; within ±0.2).
    #[arg(
        long,
        value_name = "C",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    curvature_per_m: f64,
    /// An empty stretch (no plant in any row) starting this far along, metres.
    #[arg(long, value_name = "M", requires = "gap_length_m")]
    gap_start_m: Option<f64>,
    /// The empty stretch's length, metres.
    #[arg(long, value_name = "M", requires = "gap_start_m")]
    gap_length_m: Option<f64>,
    /// The rows end this far along, metres: the robot stops there and the run ends.
    #[arg(long, value_name = "M")]
    rows_end_m: Option<f64>,
    /// The statistics leave out the first this many metres (the approach from the start).
    #[arg(long, value_name = "M", default_value_t = 5.0)]
    settle_m: f64,
    /// Write frames.jsonl (every frame), summary.json and the plots path.png and
    /// heading.png into DIR.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Print the summary as one JSON line, the last on stdout.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    photo: super::synth::photo::PhotoArgs,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum ControllerArg {
    PurePursuit,
    Stanley,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum StyleArg {
    /// The GC2450C's raw RGGB mosaic of the colour field.
    Bayer,
    /// Green plants on textured soil, RGB.
    Colour,
    /// The paper's bright plants on a dark ground.
    Grey,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum RobotArg {
    DiffDrive,
    Ackermann,
}

/// The calibration of `--calib FILE` or `--lens L`, rescaled by `--scale K` (K times the
/// resolution).
fn calibration(a: &SimArgs) -> anyhow::Result<Calibration> {
    let cal = match (&a.calib, a.lens) {
        (Some(path), _) => Calibration::load(path)?,
        (None, Some(lens)) => {
            let (h, w) = (a.image_height, a.image_width);
            IdealLens::from(lens)
                .calibration(h, w)
                .map_err(|e| anyhow::anyhow!("--image-height {h} --image-width {w}: {e}"))?
        }
        (None, None) => bail!("give --calib FILE or --lens"),
    };
    scaled(cal, a.scale)
}

/// `cal` at `k` times its resolution (`--scale K`: 0.5 is half), or an error naming `--scale`.
pub(super) fn scaled(cal: Calibration, k: f64) -> anyhow::Result<Calibration> {
    if !(k.is_finite() && k > 0.0) {
        bail!("--scale {k}: must be a positive factor (0.5: half resolution)");
    }
    if k == 1.0 {
        return Ok(cal);
    }
    cal.rescaled(1.0 / k)
        .map_err(|e| anyhow::anyhow!("--scale {k}: {e}"))
}

/// The field's ground textured from the photograph `--images`/`--labels` choose.
fn photo_ground(
    ground: SyntheticGround,
    args: &super::synth::photo::PhotoArgs,
    seed: u64,
) -> anyhow::Result<SyntheticGround> {
    if args.photo_survey {
        bail!("--photo-survey belongs to omnirow synth (it renders nothing)");
    }
    let (photo, path) = super::synth::photo::choose(args, ground.row_spacing_m(), seed)?;
    eprintln!("sim: the ground from {}", path.display());
    ground
        .with_photo_ground(std::sync::Arc::new(photo))
        .with_context(|| format!("the ground of {}", path.display()))
}

pub fn run(a: SimArgs) -> anyhow::Result<ExitCode> {
    let cal = calibration(&a)?;
    let (mut perception_opts, tool_point) = match &a.config {
        Some(p) => {
            let cfg = crate::config::Config::load(p)?;
            let Some(g) = cfg.guidance else {
                bail!(
                    "{}: [guidance] enabled = false: the loop steers on row guidance",
                    p.display()
                );
            };
            let opts = cfg.perception();
            (opts, g.tool_point_m)
        }
        None => {
            let opts = PerceptionOptions::default();
            let tool = opts.guidance.map(|g| g.tool_point_m).unwrap_or_default();
            (opts, tool)
        }
    };
    // the node is told the robot's speed (as `[guidance] speed_mps` on the robot)
    if let Some(g) = perception_opts.guidance.as_mut() {
        g.tracker.speed_mps = a.speed_mps;
    }
    let controller = match a.controller {
        ControllerArg::PurePursuit => Controller::PurePursuit {
            lookahead_m: a.lookahead_m,
        },
        ControllerArg::Stanley => Controller::Stanley {
            gain: a.stanley_gain,
            wheelbase_m: a.wheelbase_m,
        },
    };
    let robot = match a.robot {
        RobotArg::DiffDrive => RobotModel::DiffDrive {
            max_yaw_rate_rad_s: a.max_yaw_rate_dps.to_radians(),
        },
        RobotArg::Ackermann => RobotModel::Ackermann {
            wheelbase_m: a.wheelbase_m,
            max_steer_rad: a.max_steer_deg.to_radians(),
        },
    };
    let opts = SimOptions {
        speed_mps: a.speed_mps,
        distance_m: a.distance_m,
        fps: a.fps,
        start_offset_m: a.start_offset_m,
        start_heading_deg: a.start_heading_deg,
        robot,
        controller,
        latency: match a.latency_ms {
            Some(ms) => Latency::Fixed { seconds: ms / 1e3 },
            None => Latency::Measured,
        },
        settle_m: a.settle_m,
    };
    opts.validate().map_err(|e| anyhow::anyhow!("{e}"))?;
    let field = SyntheticFieldOptions {
        curvature_per_m: a.curvature_per_m,
        gap_m: a.gap_start_m.zip(a.gap_length_m).map(|(s, l)| [s, s + l]),
        rows_end_m: a.rows_end_m,
        length_m: a.distance_m,
        seed: a.seed,
        style: a.style.map(|s| match s {
            StyleArg::Bayer => Style::Bayer,
            StyleArg::Colour => Style::Colour,
            StyleArg::Grey => Style::Grey,
        }),
    };
    if let Some(d) = &a.out {
        std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
    }
    let mut ground = SyntheticGround::new(&cal, &field).context("the synthetic field")?;
    if a.photo.images.is_some() {
        ground = photo_ground(ground, &a.photo, a.seed)?;
    }
    let mut perception = Perception::new(&cal, &perception_opts)?;
    let mut jsonl = match &a.out {
        Some(d) => {
            let p = d.join("frames.jsonl");
            Some(std::io::BufWriter::new(
                std::fs::File::create(&p).with_context(|| format!("creating {}", p.display()))?,
            ))
        }
        None => None,
    };
    let expected = (a.distance_m.min(a.rows_end_m.unwrap_or(f64::INFINITY)) / a.speed_mps * a.fps)
        .ceil() as u64;
    let bar = std::io::stderr().is_terminal().then(|| {
        indicatif::ProgressBar::new(expected).with_style(
            indicatif::ProgressStyle::with_template(
                "sim [{bar:30}] {pos}/{len} frames, {elapsed} (eta {eta}) {msg}",
            )
            .expect("a valid template")
            .progress_chars("#>-"),
        )
    });
    let mut frames: Vec<FrameRecord> = Vec::new();
    let mut write_err = None;
    let summary = sim::run(
        &mut ground,
        &mut perception,
        &cal.mounting,
        tool_point,
        &opts,
        |r| {
            if let Some(w) = jsonl.as_mut() {
                let line = serde_json::to_string(r).expect("records serialise");
                if let Err(e) = writeln!(w, "{line}") {
                    write_err.get_or_insert(e);
                }
            }
            if let Some(b) = &bar {
                b.inc(1);
                b.set_message(format!("cross-track {:+.1} cm", r.cross_track_m * 100.0));
            }
            frames.push(r.clone());
        },
    )
    .map_err(|e| anyhow::anyhow!("{e}"))?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    if let Some(e) = write_err {
        return Err(e).context("writing frames.jsonl");
    }
    if let Some(d) = &a.out {
        jsonl
            .take()
            .map(|mut w| w.flush())
            .transpose()
            .context("writing frames.jsonl")?;
        let p = d.join("summary.json");
        std::fs::write(&p, serde_json::to_string_pretty(&summary)? + "\n")
            .with_context(|| format!("writing {}", p.display()))?;
        plots(&frames, d)?;
        eprintln!(
            "sim: wrote frames.jsonl, summary.json, path.png and heading.png into {}",
            d.display()
        );
    }
    if a.json {
        println!("{}", serde_json::to_string(&summary)?);
    } else {
        print!("{}", table(&summary, &opts, a.curvature_per_m));
    }
    Ok(ExitCode::SUCCESS)
}

/// The human summary.
fn table(s: &Summary, o: &SimOptions, curvature: f64) -> String {
    let ctl = match o.controller {
        Controller::PurePursuit { lookahead_m } => {
            format!("pure pursuit, lookahead {lookahead_m} m")
        }
        Controller::Stanley { gain, wheelbase_m } => {
            format!("Stanley, gain {gain}, reference length {wheelbase_m} m")
        }
    };
    let field = if curvature == 0.0 {
        "straight rows".to_string()
    } else {
        format!("rows of radius {:.1} m", 1.0 / curvature.abs())
    };
    let rows = [
        ("controller", ctl),
        ("field", field),
        (
            "frames (without guidance)",
            format!("{} ({})", s.frames, s.frames_without_guidance),
        ),
        (
            "distance",
            format!(
                "{:.1} m{}",
                s.distance_m,
                match s.end {
                    sim::End::Distance => "",
                    sim::End::RowsEnd => " (stopped at the rows' end)",
                    sim::End::LeftRows => " (ended: the robot left the rows)",
                    sim::End::Timeout => " (ended: no headway in twice the time)",
                }
            ),
        ),
        (
            "cross-track mean / std / max",
            format!(
                "{:+.2} / {:.2} / {:.2} cm (past {} m, {} frames)",
                s.cross_track_mean_m * 100.0,
                s.cross_track_std_m * 100.0,
                s.cross_track_max_m * 100.0,
                s.settle_m,
                s.settled_frames
            ),
        ),
        (
            "cross-track max, whole run",
            format!("{:.2} cm", s.cross_track_max_all_m * 100.0),
        ),
        (
            "heading error p99",
            format!("{:.3}°", s.heading_error_p99_deg),
        ),
        ("row changes", s.row_changes.to_string()),
        (
            "latency mean / max",
            format!("{:.1} / {:.1} ms", s.latency_mean_ms, s.latency_max_ms),
        ),
        ("wall time", format!("{:.1} s", s.wall_s)),
    ];
    let w = rows.iter().map(|r| r.0.len()).max().unwrap_or(0);
    rows.iter()
        .map(|(k, v)| format!("{k:<w$}  {v}\n"))
        .collect()
}

/// path.png: the tool point's true offset from the path's centre line and the published
/// one along the way; heading.png: the true heading error and the published heading's
/// negative.
fn plots(frames: &[FrameRecord], dir: &Path) -> anyhow::Result<()> {
    let along = |f: &FrameRecord| f.rows.along_m;
    let charts = [
        (
            "path.png",
            Chart {
                title: "sim: offset from the followed path's centre line".into(),
                x_label: "along the rows (m)".into(),
                y_label: "offset, left positive (cm)".into(),
                x_range: None,
                y_range: None,
                x_categories: Vec::new(),
                series: vec![
                    Series {
                        label: "truth".into(),
                        colour: [40, 40, 40],
                        points: frames
                            .iter()
                            .map(|f| (along(f), f.cross_track_m * 100.0))
                            .collect(),
                        kind: Kind::Line,
                    },
                    Series {
                        label: "published".into(),
                        colour: [220, 60, 30],
                        points: frames
                            .iter()
                            .filter_map(|f| Some((along(f), f.estimate.offset_m? * 100.0)))
                            .collect(),
                        kind: Kind::Markers,
                    },
                ],
            },
        ),
        (
            "heading.png",
            Chart {
                title: "sim: heading error (robot yaw relative to the rows)".into(),
                x_label: "along the rows (m)".into(),
                y_label: "heading error, left positive (deg)".into(),
                x_range: None,
                y_range: None,
                x_categories: Vec::new(),
                series: vec![
                    Series {
                        label: "truth".into(),
                        colour: [40, 40, 40],
                        points: frames
                            .iter()
                            .map(|f| (along(f), f.heading_error_deg))
                            .collect(),
                        kind: Kind::Line,
                    },
                    Series {
                        label: "published (-heading)".into(),
                        colour: [220, 60, 30],
                        points: frames
                            .iter()
                            .filter_map(|f| Some((along(f), -f.estimate.heading_rad?.to_degrees())))
                            .collect(),
                        kind: Kind::Markers,
                    },
                ],
            },
        ),
    ];
    for (name, chart) in charts {
        let p = dir.join(name);
        chart
            .render()?
            .save(&p)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(())
}
