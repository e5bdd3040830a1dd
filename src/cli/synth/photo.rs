//! `omnirow synth --images DIR --labels DIR`: the ground textured from a labelled
//! photograph, chosen by index or seed, and `--photo-survey`, which rectifies every
//! photograph of the folder and prints why each is accepted or rejected.

use crate::eval::real::{label_for, labels, list_images, Decoded, MaskTracing};
use crate::frame::PixelFormat;
use crate::synth::photo::{Photo, PhotoGround, PhotoOptions, Rejection};
use anyhow::bail;
use clap::Args;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The photograph-ground options of `omnirow synth`.
#[derive(Debug, Args)]
pub struct PhotoArgs {
    /// Folder of labelled perspective photographs of straight rows: the ground is textured
    /// from one of them (docs/synth.md, "A ground from your own photographs").
    #[arg(long, requires = "labels", value_name = "DIR")]
    pub images: Option<PathBuf>,
    /// Folder of their labels, as `omnirow eval real` reads them (NAME.json polylines or a
    /// mask image NAME.png/.jpg of the rows' centre lines).
    #[arg(long, requires = "images", value_name = "DIR")]
    pub labels: Option<PathBuf>,
    /// Use the photograph at this 0-based position (natural order: 2.jpg before 10.jpg);
    /// without it, the first that fits from position seed mod count on.
    #[arg(long, requires = "images")]
    pub photo_index: Option<usize>,
    /// The photographs' focal length, pixels (default: 0.8 x the larger side). It sets the
    /// scale along the rows.
    #[arg(long, requires = "images")]
    pub photo_focal_px: Option<f64>,
    /// The texture must be sampled finer than this, metres per pixel.
    #[arg(long, requires = "images", default_value_t = PhotoOptions::default().max_sampling_m)]
    pub photo_max_sampling_m: f64,
    /// The texture spans at most this many row spacings across (1: the strip between the two
    /// rows nearest the camera; wider shows more of the photograph, with the outer rows
    /// displaced by the plants' lean away from the camera).
    #[arg(long, requires = "images", default_value_t = PhotoOptions::default().max_band_spacings)]
    pub photo_band_spacings: usize,
    /// Rectify every photograph, print each one's outcome and a summary, render nothing.
    #[arg(long, requires = "images")]
    pub photo_survey: bool,
}

impl PhotoArgs {
    fn options(&self, row_spacing_m: f64) -> PhotoOptions {
        let mut o = PhotoOptions {
            max_sampling_m: self.photo_max_sampling_m,
            max_band_spacings: self.photo_band_spacings,
            ..Default::default()
        };
        o.rectify.row_spacing_m = row_spacing_m;
        o.rectify.focal_px = self.photo_focal_px;
        o
    }
}

/// Why one photograph could not serve: its label or image could not be read, or the
/// rectification rejected it.
enum Refusal {
    Unreadable(String),
    Rejected(Rejection),
}

impl Refusal {
    fn kind(&self) -> &'static str {
        match self {
            Refusal::Unreadable(_) => "unreadable",
            Refusal::Rejected(r) => r.kind(),
        }
    }
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Refusal::Unreadable(e) => write!(f, "{e}"),
            Refusal::Rejected(r) => write!(f, "{r}"),
        }
    }
}

/// Reads one photograph and its label and builds its ground.
fn ground_of(image: &Path, label_dir: &Path, opts: &PhotoOptions) -> Result<PhotoGround, Refusal> {
    let label = label_for(image, label_dir).ok_or_else(|| {
        Refusal::Unreadable(format!(
            "no label in {} (NAME.json or a mask image NAME.png/.jpg)",
            label_dir.display()
        ))
    })?;
    let img = Decoded::open(image).map_err(Refusal::Unreadable)?;
    let (w, h) = (img.width as usize, img.height as usize);
    let curves = labels::load(&label, h, w, &MaskTracing::default())
        .map_err(|e| Refusal::Unreadable(e.to_string()))?;
    let rows: Vec<Vec<[f64; 2]>> = curves.iter().map(|c| c.points().collect()).collect();
    let photo = Photo {
        width: img.width,
        height: img.height,
        channels: if img.format == PixelFormat::Mono8 {
            1
        } else {
            3
        },
        data: &img.data,
    };
    PhotoGround::new(&photo, &rows, opts).map_err(Refusal::Rejected)
}

/// The ground of one photograph `image`, its label in `label_dir` (the node's
/// `[source.synthetic] photo`): an error names the photograph and why it cannot serve.
pub fn ground_of_photograph(
    image: &Path,
    label_dir: &Path,
    opts: &PhotoOptions,
) -> anyhow::Result<PhotoGround> {
    let name = image.display().to_string();
    if let Err(e) = std::fs::metadata(image) {
        bail!("{name}: cannot read the photograph: {e}");
    }
    ground_of(image, label_dir, opts).map_err(|e| match e {
        Refusal::Unreadable(why) if why.starts_with(&name) => anyhow::anyhow!(why),
        Refusal::Unreadable(why) => anyhow::anyhow!("{name}: {why}"),
        Refusal::Rejected(r) => anyhow::anyhow!("{name}: rejected ({}): {r}", r.kind()),
    })
}

/// The photograph's ground: the one at `--photo-index`, else the first that fits from
/// position `seed` mod count on. The error lists the photographs rejected and why.
pub fn choose(
    args: &PhotoArgs,
    row_spacing_m: f64,
    seed: u64,
) -> anyhow::Result<(PhotoGround, PathBuf)> {
    let mut one = choose_many(args, row_spacing_m, seed, 1)?;
    Ok(one.remove(0))
}

/// Up to `n` photographs' grounds: from `--photo-index` (or position `seed` mod count) on,
/// the first `n` that fit, in order. With `--photo-index` the first must fit. Fewer than
/// `n` when the folder holds fewer that fit; an error, listing the photographs rejected and
/// why, when none does.
pub fn choose_many(
    args: &PhotoArgs,
    row_spacing_m: f64,
    seed: u64,
    n: usize,
) -> anyhow::Result<Vec<(PhotoGround, PathBuf)>> {
    let (Some(dir), Some(label_dir)) = (&args.images, &args.labels) else {
        bail!("--images and --labels go together");
    };
    let images = list_images(dir)?;
    let opts = args.options(row_spacing_m);
    let start = match args.photo_index {
        Some(i) if i >= images.len() => bail!(
            "--photo-index {i}: {} holds {} photographs (0..{})",
            dir.display(),
            images.len(),
            images.len()
        ),
        Some(i) => i,
        None => (seed % images.len() as u64) as usize,
    };
    let mut refused = Vec::new();
    let mut chosen = Vec::new();
    for k in 0..images.len() {
        let image = &images[(start + k) % images.len()];
        match ground_of(image, label_dir, &opts) {
            Ok(g) => {
                chosen.push((g, image.clone()));
                if chosen.len() == n {
                    break;
                }
            }
            Err(e) if k == 0 && args.photo_index.is_some() => {
                bail!("{}: rejected: {e}", image.display())
            }
            Err(e) => refused.push((image.display().to_string(), e)),
        }
    }
    if !chosen.is_empty() {
        for (name, why) in &refused {
            tracing::info!("{name}: rejected: {why}");
        }
        return Ok(chosen);
    }
    let shown: Vec<String> = refused
        .iter()
        .take(8)
        .map(|(n, e)| format!("{n}: {e}"))
        .collect();
    bail!(
        "no photograph in {} fits ({} rejected: {}): {}{}",
        dir.display(),
        refused.len(),
        counts(refused.iter().map(|r| r.1.kind())),
        shown.join("; "),
        if refused.len() > shown.len() {
            format!("; and {} more", refused.len() - shown.len())
        } else {
            String::new()
        }
    )
}

/// "3 spacing uneven, 2 too few rows": counts of reasons, most frequent first.
fn counts<'a>(kinds: impl Iterator<Item = &'a str>) -> String {
    let mut m: BTreeMap<&str, usize> = BTreeMap::new();
    for k in kinds {
        *m.entry(k).or_default() += 1;
    }
    let mut v: Vec<_> = m.into_iter().collect();
    v.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(b.0)));
    v.iter()
        .map(|(k, n)| format!("{n} {k}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The value at fraction `q` of sorted `v` (nearest rank), or NaN when empty.
fn quantile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// Rectifies every photograph and prints one line each and a summary to stdout.
pub fn survey(args: &PhotoArgs, row_spacing_m: f64) -> anyhow::Result<()> {
    let (Some(dir), Some(label_dir)) = (&args.images, &args.labels) else {
        bail!("--images and --labels go together");
    };
    let images = list_images(dir)?;
    let opts = args.options(row_spacing_m);
    let (mut residual, mut rms, mut length, mut width) = (vec![], vec![], vec![], vec![]);
    let mut kinds = Vec::new();
    for image in &images {
        let name = image.file_name().unwrap_or_default().to_string_lossy();
        match ground_of(image, label_dir, &opts) {
            Ok(g) => {
                let r = g.rectification();
                let reg = g.region();
                let worst = r.row_residual_m.iter().fold(0.0f64, |m, e| m.max(e.abs()));
                let worst_rms = r.row_rms_px.iter().fold(0.0f64, |m, e| m.max(*e));
                println!(
                    "{name}: accepted: {} rows (k = {:?}), worst row {worst:.3} m from its place, straight within {worst_rms:.2} px RMS, camera {:.2} m high at y = {:.2} m, texture x {:.2}..{:.2} m y {:.2}..{:.2} m, sampled at {:.3} m/px or finer",
                    r.row_index.len(),
                    r.row_index,
                    r.camera_height_m,
                    r.camera_y_m,
                    reg.x[0],
                    reg.x[1],
                    reg.y[0],
                    reg.y[1],
                    reg.worst_sampling_m
                );
                residual.push(worst);
                rms.push(worst_rms);
                length.push(reg.x[1] - reg.x[0]);
                width.push(reg.y[1] - reg.y[0]);
            }
            Err(e) => {
                println!("{name}: rejected: {e}");
                kinds.push(e.kind());
            }
        }
    }
    for v in [&mut residual, &mut rms, &mut length, &mut width] {
        v.sort_by(f64::total_cmp);
    }
    println!(
        "accepted {} of {} photographs; rejected: {}",
        residual.len(),
        images.len(),
        counts(kinds.into_iter())
    );
    println!(
        "accepted: worst row from its place median {:.3} m, 90th percentile {:.3} m (spacing {row_spacing_m} m); row straightness (worst RMS per photograph) median {:.2} px, 90th percentile {:.2} px; texture length median {:.2} m, width median {:.2} m",
        quantile(&residual, 0.5),
        quantile(&residual, 0.9),
        quantile(&rms, 0.5),
        quantile(&rms, 0.9),
        quantile(&length, 0.5),
        quantile(&width, 0.5)
    );
    Ok(())
}
