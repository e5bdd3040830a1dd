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
    /// Resolution divisor: 1 full, 2 half (default 1; 2 with --quick).
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
}

/// `omnirow eval guidance`.
fn guidance(a: GuidanceArgs) -> anyhow::Result<ExitCode> {
    anyhow::ensure!(
        a.seconds.is_finite() && a.seconds > 0.0 && a.seconds <= 3600.0,
        "--seconds {} must be in (0, 3600]",
        a.seconds
    );
    let detector = crate::detect::DetectorOptions::default();
    let all = eval::guidance::scenarios(a.width, a.height, a.seconds);
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
        eprintln!("eval guidance: {} ({} frames)", s.name, s.frames);
        scores.push(eval::guidance::run_drive(
            &s,
            &detector,
            !a.no_narrow,
            a.threads.into(),
        )?);
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
        anyhow::ensure!(s.is_finite() && s > 0.0, "--scale {s} must be positive");
        opts.scale = s;
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
