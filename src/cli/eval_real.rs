//! `omnirow eval real`: the detector scored on real images with labelled crop rows
//! (docs/real.md).

use crate::camera::Calibration;
use crate::detect::{DetectorOptions, Method};
use crate::eval::real::{self, MaskTracing, RealEvalOptions, ScoreOptions};
use anyhow::Context;
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct RealArgs {
    /// Folder of images (PNG, JPEG, PGM/PPM, BMP).
    #[arg(long, value_name = "DIR")]
    pub images: PathBuf,
    /// Folder of labels: for image NAME.ext, NAME.json (polylines) or a mask image NAME.png/.jpg
    /// of the rows' centre lines.
    #[arg(long, value_name = "DIR")]
    pub labels: PathBuf,
    /// The camera's calibration (OCamCalib or omnirow TOML, e.g. a pinhole one).
    #[arg(long, value_name = "FILE")]
    pub calib: PathBuf,
    /// Take the detector's options from the `[detector]` section of this node configuration.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Row-detection method [default: the configuration's, else the detector's default].
    #[arg(long, value_enum)]
    pub method: Option<Method>,
    /// Folder for README.md (the tables), outcomes.jsonl and overlays/.
    #[arg(long, value_name = "DIR", default_value = "eval-real-out")]
    pub out: PathBuf,
    /// Score only the first N images (in natural order: 2.jpg before 10.jpg).
    #[arg(long, value_name = "N")]
    pub limit: Option<usize>,
    /// Run each image as N frames of a robot standing still through the node's tracker, the
    /// search narrowed by its prediction (`[pipeline] narrow_search = true`), and score the
    /// last frame: what the tracker does to a single image's answer. The pencil method
    /// ignores the narrowing. 0: one frame, no tracker.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub track: usize,
    /// Threads each image's independent parts run on (the answers are the same with any
    /// number) [default: the configuration's `[pipeline] threads`, else 2].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(1..=16))]
    pub threads: Option<u16>,
    /// How many of the worst images get an overlay and a line in the report.
    #[arg(long, value_name = "N", default_value_t = 12)]
    pub worst: usize,
}

pub fn run(a: RealArgs) -> anyhow::Result<ExitCode> {
    let (mut detector, threads) = match &a.config {
        Some(p) => {
            let c = crate::config::Config::load(p)?;
            (c.detector, c.threads)
        }
        None => (
            DetectorOptions::default(),
            crate::pipeline::DEFAULT_THREADS as usize,
        ),
    };
    if let Some(m) = a.method {
        detector.method = m;
    }
    let opts = RealEvalOptions {
        images: a.images,
        labels: a.labels,
        calibration: Calibration::load(&a.calib)?,
        detector,
        tracing: MaskTracing::default(),
        score: ScoreOptions::default(),
        limit: a.limit,
        track_frames: a.track,
        threads: a.threads.map_or(threads, usize::from),
    };
    let bar = indicatif::ProgressBar::new(0).with_style(
        indicatif::ProgressStyle::with_template(
            "eval real [{bar:30}] {pos}/{len} images, {elapsed} (eta {eta})",
        )
        .context("progress bar template")?
        .progress_chars("#>-"),
    );
    let results = real::run(&opts, |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    bar.finish_and_clear();
    let command: Vec<String> = std::env::args().collect();
    let command = format!("omnirow {}", command[1..].join(" "));
    let files = real::write(&results, &opts, &a.out, &command, a.worst)
        .with_context(|| format!("writing the report into {}", a.out.display()))?;
    print!("{}", real::markdown(&results, &command, a.worst));
    for f in files.iter().take(2) {
        eprintln!("eval real: wrote {}", f.display());
    }
    eprintln!(
        "eval real: wrote {} overlays into {}",
        files.len().saturating_sub(2),
        a.out.join("overlays").display()
    );
    Ok(ExitCode::SUCCESS)
}
