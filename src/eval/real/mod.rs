//! `omnirow eval real`: the detector scored on real images with labelled crop rows.
//!
//! Owns the run over a folder of images and their labels (each image through the detector
//! with the given options, its published rows projected into the image and scored against
//! the labelled centre lines), the per-image outcomes, and the report: Markdown tables, the
//! outcomes as JSON lines, and overlays of the worst images. The label formats live in
//! [`labels`], the metrics in [`score`]; docs/real.md defines both.

pub mod ceiling;
pub mod labels;
mod report;
pub mod score;

pub use ceiling::Ceiling;
pub use labels::{LabelError, MaskTracing, ScanCurve};
pub use report::{markdown, write, Summary};
pub use score::{ImageScore, LabelFit, ProjectedRow, ScoreOptions};

use crate::camera::Calibration;
use crate::detect::method::strips::StripsMethod;
use crate::detect::{Detection, Detector, DetectorOptions, Method};
use crate::frame::{Frame, ImageView, PixelFormat};
use crate::perception::{Perception, PerceptionError, PerceptionOptions};
use nalgebra::Vector3;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// An error that stops the whole run (an image's own problems are outcomes, not errors).
#[derive(Debug, thiserror::Error)]
pub enum RealEvalError {
    #[error("{path}: cannot list the folder: {source}")]
    Folder {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{0}: no images (PNG, JPEG, PGM/PPM, BMP) in the folder")]
    NoImages(PathBuf),
    #[error(transparent)]
    Perception(#[from] PerceptionError),
}

/// What to score.
#[derive(Debug, Clone)]
pub struct RealEvalOptions {
    /// Folder of images.
    pub images: PathBuf,
    /// Folder of labels: for image `NAME.ext`, `NAME.json` or a mask image `NAME.*`.
    pub labels: PathBuf,
    pub calibration: Calibration,
    pub detector: DetectorOptions,
    pub tracing: MaskTracing,
    pub score: ScoreOptions,
    /// Score only the first N images (natural order).
    pub limit: Option<usize>,
    /// 0: each image is one frame. N > 0: each image is N frames of a robot standing still,
    /// through the node's tracker with the search narrowed by its prediction (as
    /// `[pipeline] narrow_search = true`); the last frame is scored.
    pub track_frames: usize,
    /// Threads each image's independent parts run on ([`PerceptionOptions::threads`]).
    pub threads: usize,
}

/// What happened on one image.
#[derive(Debug, Clone, Serialize)]
pub struct RealOutcome {
    pub image: String,
    pub label: Option<String>,
    /// The image's or its label's problem, or the detector's error; the rest is then empty.
    pub error: Option<String>,
    pub labelled_rows: usize,
    pub published_rows: usize,
    /// Published rows entering the labelled rows' band (docs/real.md).
    pub inside_rows: usize,
    pub matched_rows: usize,
    /// Row-position score 0..=1; `null` when the labels give no row spacing.
    pub score: Option<f64>,
    /// The labels' common vanishing point (row, col) and the RMS distance of the straight
    /// labelled rows from it.
    pub vp_labels_px: Option<[f64; 2]>,
    pub vp_labels_rms_px: Option<f64>,
    pub vp_detected_px: Option<[f64; 2]>,
    pub vp_error_px: Option<f64>,
    /// The detector's time for the image (decoding excluded).
    pub detect_ms: f64,
    /// The published rows' unit normals (OCamCalib camera frame), as `omnirow detect` gives them.
    pub rows: Vec<[f64; 3]>,
    /// The vanishing direction, if any.
    pub vanishing_point: Option<[f64; 3]>,
    /// For each labelled row, how near the published rows came to it (docs/real.md, "Why
    /// rows are missed").
    pub label_fits: Vec<LabelFit>,
    /// The labelled rows each ceiling's rows find (docs/real.md, "Ceilings").
    pub ceiling: Ceiling,
    /// The strips method's measure at its own answer and near the labels' vanishing point
    /// (docs/real.md, "Search or measure"); `null` for the other methods or without either
    /// point.
    pub vp_agreement: Option<VpAgreement>,
}

/// The strips' agreement (the measure their search maximises) at the search's answer and at
/// the summit nearest the labels' vanishing point
/// ([`StripsMethod::agreement_near`]), and how far that summit lies
/// from the search's answer (pixels of the strips' virtual image). Where the vanishing point
/// is far off, a higher summit elsewhere says the search missed it; a lower one, or the
/// search's own (the climb from the labels' point may end there), that the measure itself
/// prefers the wrong point.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct VpAgreement {
    pub search: f64,
    pub labels: f64,
    pub labels_summit_from_search_px: f64,
}

/// Two climbs that end this close (virtual image pixels) reached the same summit: the
/// search and the climb stop at 1 px steps from different starts.
pub const SAME_SUMMIT_PX: f64 = 3.0;

impl VpAgreement {
    /// Whether the search missed a summit, away from its answer, that the measure rates
    /// higher than that answer.
    pub fn search_missed(&self) -> bool {
        self.labels > self.search && self.labels_summit_from_search_px > SAME_SUMMIT_PX
    }
}

impl RealOutcome {
    fn new(image: &Path) -> Self {
        RealOutcome {
            image: image.display().to_string(),
            label: None,
            error: None,
            labelled_rows: 0,
            published_rows: 0,
            inside_rows: 0,
            matched_rows: 0,
            score: None,
            vp_labels_px: None,
            vp_labels_rms_px: None,
            vp_detected_px: None,
            vp_error_px: None,
            detect_ms: 0.0,
            rows: Vec::new(),
            vanishing_point: None,
            label_fits: Vec::new(),
            ceiling: Ceiling::default(),
            vp_agreement: None,
        }
    }
}

/// All outcomes of a run, in image order.
#[derive(Debug, Clone)]
pub struct RealResults {
    pub outcomes: Vec<RealOutcome>,
    /// The method that ran (`auto` resolved for the calibration) and the one asked for.
    pub method: Method,
    pub requested: Method,
}

/// The image files of a folder in natural order (2.jpg before 10.jpg).
pub fn list_images(dir: &Path) -> Result<Vec<PathBuf>, RealEvalError> {
    let folder = |source| RealEvalError::Folder {
        path: dir.to_path_buf(),
        source,
    };
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(folder)?
        .map(|e| e.map(|e| e.path()).map_err(folder))
        .collect::<Result<Vec<_>, _>>()?
        .into_iter()
        .filter(|p| p.is_file() && is_image(p))
        .collect();
    files.sort_by_key(|p| natural_key(p));
    if files.is_empty() {
        return Err(RealEvalError::NoImages(dir.to_path_buf()));
    }
    Ok(files)
}

fn is_image(p: &Path) -> bool {
    p.extension().and_then(|e| e.to_str()).is_some_and(|e| {
        ["png", "jpg", "jpeg", "pgm", "ppm", "pnm", "bmp"]
            .iter()
            .any(|x| e.eq_ignore_ascii_case(x))
    })
}

/// Sort key: a numeric stem by its number first, then the name.
fn natural_key(p: &Path) -> (u64, String) {
    let stem = p.file_stem().and_then(|s| s.to_str()).unwrap_or_default();
    (
        stem.parse::<u64>().unwrap_or(u64::MAX),
        p.file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default(),
    )
}

/// The label file for `image` in `dir`: `STEM.json`, else a mask image `STEM.*`.
pub fn label_for(image: &Path, dir: &Path) -> Option<PathBuf> {
    let stem = image.file_stem()?.to_string_lossy();
    ["json", "png", "jpg", "jpeg", "pgm", "bmp", "PNG", "JPG"]
        .iter()
        .map(|e| dir.join(format!("{stem}.{e}")))
        .find(|p| p.is_file())
}

/// A decoded image: greyscale stays Mono8, anything else becomes RGB8.
pub struct Decoded {
    pub width: u32,
    pub height: u32,
    pub format: PixelFormat,
    pub data: Vec<u8>,
}

impl Decoded {
    pub fn open(path: &Path) -> Result<Self, String> {
        let img = image::ImageReader::open(path)
            .and_then(|r| r.with_guessed_format())
            .map_err(|e| format!("{}: cannot read the image: {e}", path.display()))?
            .decode()
            .map_err(|e| format!("{}: cannot decode the image: {e}", path.display()))?;
        let (width, height) = (img.width(), img.height());
        let (format, data) = match img {
            image::DynamicImage::ImageLuma8(g) => (PixelFormat::Mono8, g.into_raw()),
            other => (PixelFormat::Rgb8, other.to_rgb8().into_raw()),
        };
        Ok(Decoded {
            width,
            height,
            format,
            data,
        })
    }

    pub fn view(&self) -> Result<ImageView<'_>, String> {
        ImageView::new(self.width, self.height, self.format, &self.data).map_err(|e| e.to_string())
    }
}

/// Scores the detector on every image of `opts.images`; `progress(done, total)` after each.
pub fn run(
    opts: &RealEvalOptions,
    mut progress: impl FnMut(usize, usize),
) -> Result<RealResults, RealEvalError> {
    let mut images = list_images(&opts.images)?;
    images.truncate(opts.limit.unwrap_or(usize::MAX));
    let step = PerceptionOptions {
        detector: opts.detector.clone(),
        narrow_search: true,
        threads: opts.threads,
        ..PerceptionOptions::default()
    };
    let mut perception = Perception::new(&opts.calibration, &step)?;
    let mut det = Detection::default();
    let mut outcomes = Vec::with_capacity(images.len());
    for (i, path) in images.iter().enumerate() {
        let mut o = RealOutcome::new(path);
        if let Err(e) = score_one(opts, &mut perception, &mut det, path, &mut o) {
            o.error = Some(e);
        }
        outcomes.push(o);
        progress(i + 1, images.len());
    }
    Ok(RealResults {
        outcomes,
        method: perception.detector().options().method,
        requested: opts.detector.method,
    })
}

/// The strips' agreement at their answer and near the labels' vanishing direction, when the
/// strips method found a vanishing point on the last image.
fn vp_agreement(detector: &mut Detector, labels_vp: Option<&Vector3<f64>>) -> Option<VpAgreement> {
    let strips = detector.method_as_mut::<StripsMethod>()?;
    let search = strips.last();
    search.vanishing_px?;
    let (labels, away) = strips.agreement_near(labels_vp?)?;
    Some(VpAgreement {
        search: search.agreement,
        labels,
        labels_summit_from_search_px: away,
    })
}

/// Runs `img` as `n` frames at 15 fps of a robot standing still through the perception
/// step (the detector, the row fit and a fresh tracker), each frame's search narrowed by
/// the tracker's prediction as the node's pipeline does
/// ([`crate::perception::NarrowSearch`]); `det` holds the last frame's detection.
fn detect_tracked(
    perception: &mut Perception,
    det: &mut Detection,
    img: &Decoded,
    n: usize,
) -> Result<usize, String> {
    perception.reset().map_err(|e| e.to_string())?;
    let mut frame = Frame {
        seq: 0,
        capture_ns: 0,
        receive_ns: 0,
        width: img.width,
        height: img.height,
        format: img.format,
        data: img.data.clone(),
        truth: None,
    };
    for k in 0..n {
        frame.seq = k as u64;
        frame.capture_ns = k as u64 * 66_666_667;
        frame.receive_ns = frame.capture_ns;
        perception.process(&frame).map_err(|e| e.to_string())?;
    }
    det.clone_from(perception.detection());
    Ok(n)
}

/// Detects and scores one image into `o`; an error names what was wrong.
fn score_one(
    opts: &RealEvalOptions,
    perception: &mut Perception,
    det: &mut Detection,
    path: &Path,
    o: &mut RealOutcome,
) -> Result<(), String> {
    let label = label_for(path, &opts.labels).ok_or_else(|| {
        format!(
            "no label for {} in {} (NAME.json or a mask image NAME.png/.jpg)",
            path.display(),
            opts.labels.display()
        )
    })?;
    o.label = Some(label.display().to_string());
    let img = Decoded::open(path)?;
    let view = img.view()?;
    let labels = labels::load(
        &label,
        img.height as usize,
        img.width as usize,
        &opts.tracing,
    )
    .map_err(|e| e.to_string())?;
    o.labelled_rows = labels.len();
    let t0 = Instant::now();
    perception
        .detector_mut()
        .preparer_mut()
        .refind_fov(&view)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    let frames = match opts.track_frames {
        0 => perception
            .detector_mut()
            .process(&view, det)
            .map(|_| 1)
            .map_err(|e| e.to_string()),
        n => detect_tracked(perception, det, &img, n),
    }
    .map_err(|e| format!("{}: {e}", path.display()))?;
    let detector = perception.detector_mut();
    o.detect_ms = t0.elapsed().as_secs_f64() * 1e3 / frames as f64;
    let cal = detector
        .view_calibration()
        .ok_or_else(|| "the detector has no calibration for the image".to_string())?;
    let projected: Vec<ProjectedRow> = det
        .rows
        .iter()
        .map(|r| ProjectedRow::project(cal, &r.normal))
        .collect();
    let s = ImageScore::compute(&labels, &projected, &opts.score);
    o.published_rows = s.published;
    o.inside_rows = s.inside;
    o.matched_rows = s.matched;
    o.score = s.score;
    o.label_fits = s.fits;
    o.rows = det
        .rows
        .iter()
        .map(|r| [r.normal.x, r.normal.y, r.normal.z])
        .collect();
    if let Some((p, rms)) = score::labels_vanishing_point(&labels, &opts.score) {
        o.vp_labels_px = Some(p);
        o.vp_labels_rms_px = Some(rms);
    }
    if let Some(vp) = det.vanishing_point {
        o.vanishing_point = Some([vp.direction.x, vp.direction.y, vp.direction.z]);
        o.vp_detected_px = score::vanishing_pixel(cal, &vp.direction);
    }
    let detected = det.vanishing_point.map(|v| v.direction);
    o.ceiling = Ceiling::compute(cal, &labels, detected.as_ref(), &opts.score);
    let labels_vp = o.vp_labels_px.map(|[r, c]| cal.model.cam2world(r, c));
    o.vp_agreement = vp_agreement(detector, labels_vp.as_ref());
    if let (Some(a), Some(b)) = (o.vp_labels_px, o.vp_detected_px) {
        o.vp_error_px = Some((a[0] - b[0]).hypot(a[1] - b[1]));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn natural_order_and_labels() {
        let dir = std::env::temp_dir().join(format!("omnirow-real-{}", std::process::id()));
        let (imgs, lbls) = (dir.join("image"), dir.join("label"));
        std::fs::create_dir_all(&imgs).unwrap();
        std::fs::create_dir_all(&lbls).unwrap();
        for n in ["10.jpg", "2.jpg", "b.png", "notes.txt"] {
            std::fs::write(imgs.join(n), b"x").unwrap();
        }
        std::fs::write(lbls.join("2.json"), b"{}").unwrap();
        std::fs::write(lbls.join("2.jpg"), b"x").unwrap();
        std::fs::write(lbls.join("10.png"), b"x").unwrap();
        let list = list_images(&imgs).unwrap();
        let names: Vec<_> = list
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["2.jpg", "10.jpg", "b.png"]);
        assert_eq!(label_for(&list[0], &lbls), Some(lbls.join("2.json")));
        assert_eq!(label_for(&list[1], &lbls), Some(lbls.join("10.png")));
        assert_eq!(label_for(&list[2], &lbls), None);
        let e = list_images(&lbls.join("none")).unwrap_err().to_string();
        assert!(e.contains("cannot list"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
