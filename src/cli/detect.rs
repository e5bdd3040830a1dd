//! `omnirow detect`: rows, vanishing point, heading and tilt of image files, one JSON line
//! per image, in input order (a contract other tools rely on).

use crate::camera::{Calibration, FovMask};
use crate::detect::overlay::draw_overlay;
use crate::detect::{Detection, Detector, DetectorOptions, Method};
use crate::frame::{ImageView, PixelFormat};
use anyhow::Context;
use clap::Args;
use serde::Serialize;
use std::collections::HashSet;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

#[derive(Debug, Args)]
pub struct DetectArgs {
    /// OCamCalib calib_results.txt or omnirow TOML calibration.
    #[arg(long, value_name = "FILE")]
    pub calib: PathBuf,
    /// Row-detection method [default: the configuration's, else auto: combined for an
    /// omnidirectional lens, strips for a forward-looking perspective camera, hough for a
    /// narrow lens looking down].
    #[arg(long, value_enum)]
    pub method: Option<Method>,
    /// Take the detector's options from the `[detector]` section of this node
    /// configuration (`omnirow config detector` prints them all), to tune offline.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Field-of-view mask radii MIN,MAX in pixels of the calibration's own resolution
    /// (overrides the calibration's mask).
    #[arg(long, value_name = "MIN,MAX", value_parser = parse_radii)]
    pub mask_radius: Option<(f64, f64)>,
    /// Write a PNG per image with the rows and the vanishing point drawn into this folder.
    #[arg(long, value_name = "DIR")]
    pub overlay: Option<PathBuf>,
    /// Images (PNG, JPEG, PGM/PPM).
    #[arg(required = true, value_name = "IMAGE")]
    pub images: Vec<PathBuf>,
}

fn parse_radii(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = s
        .split_once(',')
        .ok_or_else(|| format!("'{s}' is not MIN,MAX"))?;
    let p = |t: &str| {
        t.trim()
            .parse::<f64>()
            .map_err(|_| format!("'{t}' is not a number of pixels"))
    };
    let (lo, hi) = (p(a)?, p(b)?);
    FovMask {
        inner_radius_px: lo,
        outer_radius_px: hi,
    }
    .validate()?;
    Ok((lo, hi))
}

#[derive(Serialize)]
struct RowJson {
    normal: [f64; 3],
    method: &'static str,
    support: u32,
    width_rad: f64,
}

#[derive(Serialize)]
struct DetectionJson<'a> {
    image: &'a str,
    method: &'static str,
    vanishing_point: Option<[f64; 3]>,
    vanishing_point_px: Option<[f64; 2]>,
    heading_rad: Option<f64>,
    tilt_rad: Option<f64>,
    rows: Vec<RowJson>,
    quality: f64,
    elapsed_ms: f64,
}

#[derive(Serialize)]
struct ErrorJson<'a> {
    image: &'a str,
    error: String,
}

/// A decoded image in one of the detector's pixel formats.
pub struct Decoded {
    pub width: u32,
    pub height: u32,
    pub format: PixelFormat,
    pub data: Vec<u8>,
}

/// Reads and decodes an image file: greyscale stays Mono8, anything else becomes RGB8.
pub fn decode(path: &Path) -> anyhow::Result<Decoded> {
    let img = image::ImageReader::open(path)
        .with_context(|| format!("cannot open {}", path.display()))?
        .with_guessed_format()
        .with_context(|| format!("cannot read {}", path.display()))?
        .decode()
        .with_context(|| format!("cannot decode {}", path.display()))?;
    let (width, height) = (img.width(), img.height());
    let (format, data) = match img {
        image::DynamicImage::ImageLuma8(g) => (PixelFormat::Mono8, g.into_raw()),
        image::DynamicImage::ImageLuma16(_) | image::DynamicImage::ImageLumaA8(_) => {
            (PixelFormat::Mono8, img.to_luma8().into_raw())
        }
        other => (PixelFormat::Rgb8, other.to_rgb8().into_raw()),
    };
    Ok(Decoded {
        width,
        height,
        format,
        data,
    })
}

pub fn run(args: DetectArgs) -> anyhow::Result<ExitCode> {
    let mut cal = Calibration::load(&args.calib)?;
    if let Some((lo, hi)) = args.mask_radius {
        cal.mask = Some(FovMask {
            inner_radius_px: lo,
            outer_radius_px: hi,
        });
    }
    let mut opts = match &args.config {
        Some(p) => crate::config::Config::load(p)?.detector,
        None => DetectorOptions::default(),
    };
    if let Some(m) = args.method {
        opts.method = m;
    }
    let mut detector = Detector::new(&cal, opts)?;
    // the method that runs: `auto` resolved for the calibration
    let method: Method = detector.options().method;
    if let Some(dir) = &args.overlay {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create overlay folder {}", dir.display()))?;
    }
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    let mut det = Detection::default();
    let mut failed = 0usize;
    let mut overlay_names = HashSet::new();
    let mut rgb = Vec::new();
    for path in &args.images {
        let name = path.to_string_lossy();
        let result = detect_one(&mut detector, path, &mut det).and_then(|(elapsed_ms, img)| {
            if let Some(dir) = &args.overlay {
                write_overlay(
                    &detector,
                    &img,
                    &det,
                    dir,
                    path,
                    &mut overlay_names,
                    &mut rgb,
                )?;
            }
            Ok(elapsed_ms)
        });
        let line = match result {
            Ok(elapsed_ms) => {
                let view_cal = detector.view_calibration();
                serde_json::to_string(&DetectionJson {
                    image: &name,
                    method: method.name(),
                    vanishing_point: det
                        .vanishing_point
                        .map(|v| [v.direction.x, v.direction.y, v.direction.z]),
                    vanishing_point_px: det
                        .vanishing_point
                        .zip(view_cal)
                        .and_then(|(v, c)| c.direction_to_pixel(&v.direction)),
                    heading_rad: det.heading_rad,
                    tilt_rad: det.tilt_rad,
                    rows: det
                        .rows
                        .iter()
                        .map(|r| RowJson {
                            normal: [r.normal.x, r.normal.y, r.normal.z],
                            method: r.method.name(),
                            support: r.support,
                            width_rad: r.width_rad,
                        })
                        .collect(),
                    quality: det.quality,
                    elapsed_ms,
                })?
            }
            Err(e) => {
                failed += 1;
                tracing::warn!(image = %name, "{e:#}");
                serde_json::to_string(&ErrorJson {
                    image: &name,
                    error: format!("{e:#}"),
                })?
            }
        };
        writeln!(out, "{line}").context("writing to stdout")?;
        out.flush().context("writing to stdout")?;
    }
    if failed > 0 {
        tracing::error!("{failed} of {} images failed", args.images.len());
        return Ok(ExitCode::from(1));
    }
    Ok(ExitCode::SUCCESS)
}

/// Decodes one image and runs the detector on it; returns the detector's time (ms).
fn detect_one(
    detector: &mut Detector,
    path: &Path,
    det: &mut Detection,
) -> anyhow::Result<(f64, Decoded)> {
    let img = decode(path)?;
    let view = ImageView::new(img.width, img.height, img.format, &img.data)?;
    let t0 = Instant::now();
    detector.preparer_mut().refind_fov(&view)?;
    detector.process(&view, det)?;
    let elapsed_ms = t0.elapsed().as_secs_f64() * 1e3;
    Ok((elapsed_ms, img))
}

fn write_overlay(
    detector: &Detector,
    img: &Decoded,
    det: &Detection,
    dir: &Path,
    path: &Path,
    names: &mut HashSet<String>,
    rgb: &mut Vec<u8>,
) -> anyhow::Result<()> {
    let view = ImageView::new(img.width, img.height, img.format, &img.data)?;
    let cal = detector
        .view_calibration()
        .context("no calibration for the overlay")?;
    draw_overlay(&view, cal, det, rgb)?;
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "image".into());
    let mut name = format!("{stem}.png");
    let mut k = 1;
    while !names.insert(name.clone()) {
        k += 1;
        name = format!("{stem}-{k}.png");
    }
    let file = dir.join(&name);
    image::save_buffer(
        &file,
        rgb,
        img.width,
        img.height,
        image::ExtendedColorType::Rgb8,
    )
    .with_context(|| format!("cannot write overlay {}", file.display()))?;
    Ok(())
}
