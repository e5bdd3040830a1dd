//! The detector: one image in, rows, vanishing point, heading and tilt out.
//!
//! Owns every buffer the stages need and the per-image-size setup (the calibration rescaled
//! to the image, the field-of-view mask found from the image when the calibration has none,
//! the mask and the per-pixel ray table), rebuilt only when the image's size or pixel format
//! changes. The hot path allocates nothing once warmed up. The stages are separate types so
//! that a pipeline can run them on threads: [`Preparer`] (vegetation, smoothing, threshold →
//! [`Points`]), [`HoughRows`] (points → rows), [`EdgeDetector`] (smoothed vegetation image →
//! rows, paper II-C) and [`VanishingStage`] (rows → vanishing point, heading, tilt, quality).
//! [`Detector`] runs them in order for the chosen method: Hough, edge, or both combined
//! (paper II-F, eq. 5: edge rows weighted w·support, Hough rows (1−w)·support, in one
//! vanishing-point Hough).

use super::centre::CentreLines;
use super::combine::{consensus_score, pair_edge_rows, precision_fit, EDGE_PAIR_FACTOR};
use super::edge::{EdgeDetector, EdgeError, EdgeResult};
use super::hough::{HoughResult, HoughRows};
use super::mask::{build_mask, find_fov, MaskResult};
pub use super::options::{Binning, CombinedOptions, DetectorOptions, REFERENCE_PAIR_MAX_DEG};
use super::pencil::{Candidate, PencilResult, PencilRows};
use super::pose::heading_tilt;
use super::prior::DetectorPrior;
use super::refit::{refit_rows, Candidates, RefitImage, RowFits, Tiles};
use super::smooth::Gaussian;
use super::strips::{StripsResult, StripsRows, REFERENCE_POLISH_MAX_BAND_DEG};
use super::threshold::{keep_brightest, ThresholdResult};
use super::vanishing::{refit_direction, VanishingFinder, VanishingResult};
use super::vegetation::{vegetation_image, working_factor};
use super::{DetectError, Detection, GreyImage, Method, Row};
use crate::camera::{Calibration, FovMask};
use crate::frame::{ImageView, PixelFormat};
use nalgebra::Vector3;
use std::time::{Duration, Instant};

impl From<EdgeError> for DetectError {
    fn from(e: EdgeError) -> Self {
        match e {
            EdgeError::Options(m) => DetectError::Options(format!("edge.{m}")),
            EdgeError::Calibration(m) => DetectError::Calibration(m),
            other => DetectError::Buffer(other.to_string()),
        }
    }
}

/// The kept points handed from [`Preparer`] to [`HoughRows`]: unit rays (camera frame) and
/// their weights (smoothed vegetation value times the pixel's solid angle, so that fits are
/// integrals over the sphere, free of the lens's varying pixel density).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Points {
    pub rays: Vec<[f32; 3]>,
    pub weights: Vec<f32>,
    /// The angular size (radians) of each point's pixel: the calibration's resolution where
    /// the point is, from which the stages' pixel scales become angles.
    pub pixel_rad: Vec<f32>,
}

/// What the preparation stage did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PrepareResult {
    pub threshold: ThresholdResult,
    /// Size reduction from the image to the working image (1 or 2).
    pub working_factor: u32,
    /// True when this image caused the per-size setup to be rebuilt.
    pub setup_rebuilt: bool,
}

/// Per-image-size setup.
#[derive(Debug, Clone)]
struct Setup {
    width: u32,
    height: u32,
    format: PixelFormat,
    bin2: bool,
    factor: u32,
    view_cal: Calibration,
    work_cal: Calibration,
    mask: Vec<u8>,
    rays: Vec<[f32; 3]>,
    solid: Vec<f32>,
    tiles: Tiles,
    pixel_angle: f64,
    mask_result: MaskResult,
}

/// Stage 1: image → vegetation → smoothing → threshold → kept rays.
#[derive(Debug, Clone)]
pub struct Preparer {
    cal: Calibration,
    /// The field-of-view mask is found from the image (the calibration has none).
    fov_auto: bool,
    opts: DetectorOptions,
    gauss: Gaussian,
    user_mask: Option<GreyImage>,
    setup: Option<Setup>,
    veg: GreyImage,
    smoothed: GreyImage,
    tmp: Vec<u8>,
    kept: Vec<u32>,
    /// The refit's pixels near one row (room for every valid pixel, reserved at setup).
    candidates: Candidates,
    /// Per row of the last refit: the variance of its normal along the vanishing point, and
    /// the curved rows' points beside the robot.
    fits: RowFits,
    last_threshold: ThresholdResult,
}

impl Preparer {
    pub fn new(cal: &Calibration, opts: &DetectorOptions) -> Result<Self, DetectError> {
        opts.mask.validate()?;
        opts.refit.validate()?;
        opts.threshold.validate()?;
        if !(opts.max_tilt_deg > 0.0 && opts.max_tilt_deg <= 80.0) {
            return Err(DetectError::Options(format!(
                "max_tilt_deg = {} must be within (0, 80]",
                opts.max_tilt_deg
            )));
        }
        if let Some(m) = &cal.mask {
            m.validate().map_err(DetectError::Calibration)?;
        }
        Ok(Preparer {
            fov_auto: cal.mask.is_none(),
            cal: cal.clone(),
            opts: opts.clone(),
            gauss: Gaussian::new(&opts.smooth)?,
            user_mask: None,
            setup: None,
            veg: GreyImage::default(),
            smoothed: GreyImage::default(),
            tmp: Vec::new(),
            kept: Vec::new(),
            candidates: Candidates::default(),
            fits: RowFits::with_capacity(256),
            last_threshold: ThresholdResult::default(),
        })
    }

    /// Sets an optional user mask image (white = use), at any resolution with the image's
    /// aspect. Takes effect at the next image.
    pub fn set_user_mask(&mut self, mask: Option<GreyImage>) {
        self.user_mask = mask;
        self.setup = None;
    }

    /// Replaces the field-of-view mask (calibration's own pixels); `None` = find it from the
    /// next image if the calibration has none. Takes effect at the next image.
    pub fn set_fov_mask(&mut self, mask: Option<FovMask>) {
        self.fov_auto = mask.is_none();
        self.cal.mask = mask;
        self.setup = None;
    }

    /// When the field-of-view mask is found from the image, finds it again in `view` and
    /// rebuilds the setup if it moved by more than a pixel (for a sequence of images from
    /// different cameras). Returns whether the setup was rebuilt.
    pub fn refind_fov(&mut self, view: &ImageView) -> Result<bool, DetectError> {
        if !self.fov_auto {
            return Ok(false);
        }
        let Some(s) = &self.setup else {
            return Ok(false);
        };
        if (s.width, s.height, s.format) != (view.width, view.height, view.format) {
            return Ok(false);
        }
        let m = find_fov(view, (s.view_cal.model.xc, s.view_cal.model.yc))?;
        let old = s.view_cal.mask.unwrap_or(m);
        if (old.inner_radius_px - m.inner_radius_px).abs() > 1.0
            || (old.outer_radius_px - m.outer_radius_px).abs() > 1.0
        {
            self.setup = None;
            self.ensure_setup(view)?;
            return Ok(true);
        }
        Ok(false)
    }

    /// The calibration as given.
    pub fn calibration(&self) -> &Calibration {
        &self.cal
    }

    /// The calibration at the last image's resolution (with its field-of-view mask).
    pub fn view_calibration(&self) -> Option<&Calibration> {
        self.setup.as_ref().map(|s| &s.view_cal)
    }

    /// The calibration at the working resolution.
    pub fn working_calibration(&self) -> Option<&Calibration> {
        self.setup.as_ref().map(|s| &s.work_cal)
    }

    /// The mask of the working image (0xFF = use) and its counts.
    pub fn mask(&self) -> Option<(&[u8], MaskResult)> {
        self.setup.as_ref().map(|s| (&s.mask[..], s.mask_result))
    }

    /// The last vegetation image and its smoothed version (working resolution).
    pub fn vegetation(&self) -> (&GreyImage, &GreyImage) {
        (&self.veg, &self.smoothed)
    }

    fn ensure_setup(&mut self, view: &ImageView) -> Result<bool, DetectError> {
        if let Some(s) = &self.setup {
            if (s.width, s.height, s.format) == (view.width, view.height, view.format) {
                return Ok(false);
            }
        }
        let img_err = |problem: String| DetectError::Image {
            height: view.height,
            width: view.width,
            problem,
        };
        let mut view_cal = self
            .cal
            .rescaled_to(view.height, view.width)
            .map_err(img_err)?;
        if view_cal.mask.is_none() {
            let m = find_fov(view, (view_cal.model.xc, view_cal.model.yc))?;
            tracing::info!(
                inner_px = m.inner_radius_px,
                outer_px = m.outer_radius_px,
                "field-of-view mask found from the image"
            );
            view_cal.mask = Some(m);
        }
        let pixels = view.width as u64 * view.height as u64;
        let even = view.width % 2 == 0 && view.height % 2 == 0;
        let bin2 = match self.opts.binning {
            Binning::Off => false,
            Binning::Half => true,
            Binning::Auto => pixels > self.opts.auto_bin_above_px && even,
        };
        let factor = working_factor(view.width, view.height, view.format, bin2)?;
        let work_cal = if factor == 1 {
            view_cal.clone()
        } else {
            view_cal.rescaled(factor as f64).map_err(img_err)?
        };
        let mut mask = Vec::new();
        let mut rays = Vec::new();
        let mut solid = Vec::new();
        let mask_result = build_mask(
            &work_cal,
            &self.opts.mask,
            self.opts.max_tilt_deg,
            self.user_mask.as_ref(),
            &mut mask,
            &mut rays,
            &mut solid,
        )?;
        let n = mask.len();
        let (ww, wh) = (
            work_cal.model.width as usize,
            work_cal.model.height as usize,
        );
        let tiles = Tiles::new(&mask, &rays, ww, wh, 16);
        let m = &work_cal.model;
        let pixel_angle = crate::sphere::axis_angle(
            &m.cam2world(m.xc, m.yc + 0.5),
            &m.cam2world(m.xc, m.yc - 0.5),
        );
        self.veg.resize(
            work_cal.model.width as usize,
            work_cal.model.height as usize,
        );
        self.smoothed.resize(
            work_cal.model.width as usize,
            work_cal.model.height as usize,
        );
        self.tmp.resize(n, 0);
        self.kept.reserve(self.opts.threshold.target_points() + 1);
        self.candidates = Candidates::with_capacity(mask_result.valid);
        tracing::debug!(
            width = view.width,
            height = view.height,
            factor,
            valid = mask_result.valid,
            "detector setup rebuilt"
        );
        self.setup = Some(Setup {
            width: view.width,
            height: view.height,
            format: view.format,
            bin2,
            factor,
            view_cal,
            work_cal,
            mask,
            rays,
            solid,
            tiles,
            pixel_angle,
            mask_result,
        });
        Ok(true)
    }

    /// Runs the stage on one image, writing the kept points into `points`.
    pub fn run(
        &mut self,
        view: &ImageView,
        points: &mut Points,
    ) -> Result<PrepareResult, DetectError> {
        let rebuilt = self.ensure_setup(view)?;
        let s = self.setup.as_ref().expect("setup just ensured");
        vegetation_image(view, &self.opts.vegetation, s.bin2, &mut self.veg)?;
        let (w, h) = (self.veg.width, self.veg.height);
        self.gauss
            .apply(&self.veg.data, w, h, &mut self.tmp, &mut self.smoothed.data)?;
        let thr = keep_brightest(
            &self.smoothed.data,
            &s.mask,
            &self.opts.threshold,
            &mut self.kept,
        )?;
        self.last_threshold = thr;
        points.rays.clear();
        points.weights.clear();
        points.pixel_rad.clear();
        let pixel_angle = s.pixel_angle as f32;
        for &i in &self.kept {
            points.rays.push(s.rays[i as usize]);
            let i = i as usize;
            points
                .weights
                .push(self.smoothed.data[i] as f32 * s.solid[i]);
            points.pixel_rad.push(pixel_angle * s.solid[i].sqrt());
        }
        Ok(PrepareResult {
            threshold: thr,
            working_factor: s.factor,
            setup_rebuilt: rebuilt,
        })
    }
}

impl Preparer {
    /// Refits rows (with the Hough bands they were fitted in) on every pixel of the last
    /// image near them, weighted by intensity above the background (see [`super::refit`]).
    /// Returns the number of rows refitted.
    /// With the rows' vanishing point `vp` (an estimate), each row's band narrows towards
    /// it; with `perspective` too, each row's perspective bias is removed.
    pub fn refit(
        &mut self,
        rows: &mut [Row],
        bands: &[f64],
        vp: Option<&Vector3<f64>>,
        perspective: bool,
    ) -> Result<usize, DetectError> {
        let Some(s) = &self.setup else {
            return Ok(0);
        };
        if !self.opts.refit.enabled {
            return Ok(0);
        }
        let t = &self.last_threshold;
        let bg = t.median as f64
            + self.opts.refit.background_fraction * (t.level as f64 - t.median as f64).max(0.0);
        let img = RefitImage {
            values: &self.smoothed.data,
            mask: &s.mask,
            rays: &s.rays,
            solid: &s.solid,
            tiles: &s.tiles,
            pixel_angle: s.pixel_angle,
            model: &s.work_cal.model,
            background: bg.round().clamp(0.0, 254.0) as u8,
            near: self.near_field(),
        };
        refit_rows(
            &img,
            rows,
            bands,
            vp,
            perspective,
            &self.opts.refit,
            &mut self.candidates,
            &mut self.fits,
        )
    }

    /// The curved rows of the last refit: their points beside the robot.
    pub fn near_feet(&self) -> &[super::refit::NearFoot] {
        &self.fits.feet
    }

    /// The rows' near part for the refit's near-field fit, from the mounting (`None`
    /// when `refit.near_reach_m` is 0).
    fn near_field(&self) -> Option<super::sections::NearField> {
        let r = &self.opts.refit;
        let m = &self.cal.mounting;
        (r.near_reach_m > 0.0).then(|| super::sections::NearField {
            down: m.robot_from_camera().inverse() * -Vector3::z(),
            reach: r.near_reach_m / m.height_m,
            min_sigma: r.near_min_sigma,
        })
    }

    /// Per row of the last refit given a vanishing point: the variance of the row normal's
    /// component along it, relative to the image's noise (NaN where not estimated).
    pub fn row_variances(&self) -> &[f64] {
        &self.fits.along_var
    }
}

/// The edge rows turned by a bend are kept when this many times more of their support
/// passes through their vanishing point than the chords' did.
const BEND_GAIN: f64 = 1.25;

/// Stage 3: rows → vanishing point → heading, tilt and quality, into a [`Detection`].
#[derive(Debug, Clone)]
pub struct VanishingStage {
    finder: VanishingFinder,
    mounting: crate::camera::Mounting,
    weights: Vec<f64>,
    inliers: Vec<bool>,
}

impl VanishingStage {
    pub fn new(cal: &Calibration, opts: &DetectorOptions) -> Result<Self, DetectError> {
        Ok(VanishingStage {
            finder: VanishingFinder::new(opts.vanishing, opts.max_tilt_deg, &cal.mounting)?,
            mounting: cal.mounting,
            weights: Vec::with_capacity(64),
            inliers: Vec::with_capacity(64),
        })
    }

    /// Finds the vanishing point of `out.rows` (weighted by `weights`, or by each row's
    /// support when `None`) and fills the rest of `out`.
    pub fn run(
        &mut self,
        weights: Option<&[f64]>,
        out: &mut Detection,
    ) -> Result<VanishingResult, DetectError> {
        let w: &[f64] = match weights {
            Some(w) => w,
            None => {
                super::vanishing::support_weights(&out.rows, &mut self.weights);
                &self.weights
            }
        };
        let r = self.finder.find(&out.rows, w, &mut self.inliers)?;
        out.vanishing_point = r.vanishing_point;
        out.quality = r.quality;
        match r.vanishing_point {
            Some(vp) => {
                let ht = heading_tilt(&vp.direction, &self.mounting);
                out.heading_rad = Some(ht.heading_rad);
                out.tilt_rad = Some(ht.tilt_rad);
            }
            None => {
                out.heading_rad = None;
                out.tilt_rad = None;
            }
        }
        Ok(r)
    }

    /// Per row of the last run: whether it agrees with the vanishing point.
    pub fn inliers(&self) -> &[bool] {
        &self.inliers
    }
}

/// What a prior on the vanishing point did in the last image
/// ([`Detector::process_with_prior`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PriorOutcome {
    /// No prior (or the pencil method, which ignores it): the full search ran.
    #[default]
    None,
    /// The narrowed search found a vanishing point inside the prior's window.
    Accepted,
    /// The narrowed search found none inside the window; the full search ran after it.
    FullSearch,
}

/// Time spent in each stage of the last image.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StageTimes {
    /// Vegetation, smoothing, threshold.
    pub prepare: Duration,
    /// Hough rows and their refit on the image.
    pub hough: Duration,
    /// The edge method (Canny, chains, sections, merging).
    pub edge: Duration,
    /// Vanishing point, heading and tilt (and the optional perspective refit).
    pub vanishing: Duration,
}

impl StageTimes {
    pub fn total(&self) -> Duration {
        self.prepare + self.hough + self.edge + self.vanishing
    }
}

/// The whole detector (Hough, edge or combined method).
#[derive(Debug, Clone)]
pub struct Detector {
    opts: DetectorOptions,
    prep: Preparer,
    hough: HoughRows,
    pencil: PencilRows,
    /// The strips method, built only when it is the method (it needs a forward-looking
    /// camera).
    strips: Option<StripsRows>,
    /// The strips polish's widest band (degrees): the reference times the angle factor.
    strips_polish_band_deg: f64,
    vanish: VanishingStage,
    points: Points,
    /// The edge method, set up for the working image size (built at the first image and
    /// again whenever the preparer's setup is rebuilt).
    edge: Option<EdgeDetector>,
    edge_rows: Vec<Row>,
    /// The edge method's chords turned to their tangents on a curved field.
    bend: super::chords::ChordBend,
    last_bend: Option<super::chords::Bend>,
    /// The edge rows before the bend, and a detection to vote on them.
    chord_rows: Vec<Row>,
    bend_probe: Detection,
    weights: Vec<f64>,
    precision_weights: Vec<f64>,
    precision_scratch: Vec<(f64, f64)>,
    /// The consensus step's per-method weights and inlier flags, and the final inliers.
    candidate_weights: Vec<f64>,
    candidate_inliers: Vec<bool>,
    final_inliers: Vec<bool>,
    paired_rows: Vec<Row>,
    paired_inliers: Vec<bool>,
    /// The crop rows' centre lines from the edge boundaries ([`super::centre`]).
    centre: CentreLines,
    /// The edge method's centre lines' half-widths, as the refit's bands.
    centre_bands: Vec<f64>,
    pair_scratch: Vec<(f64, usize, super::combine::Kind)>,
    times: StageTimes,
    last_prepare: PrepareResult,
    last_hough: HoughResult,
    last_edge: EdgeResult,
    last_pencil: PencilResult,
    last_prior: PriorOutcome,
    pencil_candidates: Vec<Candidate>,
    pencil_rows: Vec<Row>,
    pencil_bands: Vec<f64>,
}

impl Detector {
    /// A detector for images of `cal` (at its size; another size scales it). Every angular
    /// option left absent is derived from the calibration's field of view
    /// ([`super::scale::resolve`]); [`Detector::options`] gives the values in force.
    pub fn new(cal: &Calibration, opts: DetectorOptions) -> Result<Self, DetectError> {
        let (opts, scales) = super::scale::resolve(cal, &opts)?;
        let w = opts.combined.edge_weight;
        if !(w > 0.0 && w < 1.0) {
            return Err(DetectError::Options(format!(
                "combined.edge_weight = {w} must be within (0, 1)"
            )));
        }
        let p = opts.combined.pair_max_deg();
        if !(p > 0.0 && p < 45.0) {
            return Err(DetectError::Options(format!(
                "combined.pair_max_deg = {p} must be within (0, 45)"
            )));
        }
        let f = opts.combined.precision_floor_mrad;
        if !(f > 0.0 && f < 100.0) {
            return Err(DetectError::Options(format!(
                "combined.precision_floor_mrad = {f} must be within (0, 100)"
            )));
        }
        // Check the edge options now rather than at the first image.
        opts.edge.validate()?;
        opts.strips.validate()?;
        let strips = match opts.method {
            Method::Strips => Some(StripsRows::new(
                opts.strips,
                opts.max_tilt_deg,
                &cal.mounting,
            )?),
            _ => None,
        };
        Ok(Detector {
            strips,
            strips_polish_band_deg: REFERENCE_POLISH_MAX_BAND_DEG * scales.factor,
            prep: Preparer::new(cal, &opts)?,
            hough: HoughRows::new(opts.hough)?,
            pencil: PencilRows::new(opts.pencil, opts.max_tilt_deg, &cal.mounting)?,
            vanish: VanishingStage::new(cal, &opts)?,
            points: Points {
                rays: Vec::with_capacity(opts.threshold.target_points() + 1),
                weights: Vec::with_capacity(opts.threshold.target_points() + 1),
                pixel_rad: Vec::with_capacity(opts.threshold.target_points() + 1),
            },
            opts,
            edge: None,
            edge_rows: Vec::with_capacity(64),
            bend: Default::default(),
            last_bend: None,
            chord_rows: Vec::with_capacity(64),
            bend_probe: Detection::default(),
            weights: Vec::with_capacity(128),
            precision_weights: Vec::with_capacity(128),
            precision_scratch: Vec::with_capacity(128),
            candidate_weights: Vec::with_capacity(128),
            candidate_inliers: Vec::with_capacity(128),
            final_inliers: Vec::with_capacity(128),
            paired_rows: Vec::with_capacity(128),
            paired_inliers: Vec::with_capacity(128),
            centre: CentreLines::default(),
            centre_bands: Vec::with_capacity(64),
            pair_scratch: Vec::with_capacity(128),
            times: StageTimes::default(),
            last_prepare: PrepareResult::default(),
            last_hough: HoughResult::default(),
            last_edge: EdgeResult::default(),
            last_pencil: PencilResult::default(),
            last_prior: PriorOutcome::None,
            pencil_candidates: Vec::with_capacity(16),
            pencil_rows: Vec::with_capacity(64),
            pencil_bands: Vec::with_capacity(64),
        })
    }

    pub fn options(&self) -> &DetectorOptions {
        &self.opts
    }

    /// Detects rows, the vanishing point, heading and tilt in one image, into `out`.
    pub fn process(&mut self, view: &ImageView, out: &mut Detection) -> Result<(), DetectError> {
        self.process_with_prior(view, None, out)
    }

    /// As [`Detector::process`], narrowed by a `prior` on the vanishing point when there is
    /// one ([`super::prior`]): the row Hough votes and peaks only where rows through the
    /// prior's window are, and the vanishing point is sought there. When that gives no
    /// vanishing point inside the window, the full search runs on the same prepared points
    /// (and edge rows), so the answer is never worse than without a prior.
    /// [`Detector::last_prior`] tells which happened. The strips method searches its vanishing
    /// point only in the window ([`super::strips::StripsRows::set_window`]); the pencil
    /// method ignores the prior.
    pub fn process_with_prior(
        &mut self,
        view: &ImageView,
        prior: Option<&DetectorPrior>,
        out: &mut Detection,
    ) -> Result<(), DetectError> {
        // a bad prior is an error whichever method runs (the pencil ignores a good one)
        let checked = prior
            .map(|p| p.validate().map(|v| (v, p.window_rad)))
            .transpose()?;
        let window = checked.filter(|_| self.opts.method != Method::Pencil);
        let t0 = Instant::now();
        self.last_prepare = self.prep.run(view, &mut self.points)?;
        let t1 = Instant::now();
        self.last_prior = PriorOutcome::None;
        let Some((vp, w)) = window else {
            return self.detect_prepared(out, t0, t1, true);
        };
        self.set_windows(Some((&vp, w)));
        let narrowed = self.detect_prepared(out, t0, t1, true);
        self.set_windows(None);
        narrowed?;
        let inside = out
            .vanishing_point
            .is_some_and(|v| crate::sphere::axis_angle(&v.direction, &vp) <= w);
        if inside {
            self.last_prior = PriorOutcome::Accepted;
            return Ok(());
        }
        // The full search; the narrowed attempt's time counts in the Hough stage.
        let spent = self.times.hough + self.times.vanishing;
        self.detect_prepared(out, t0, t1, false)?;
        self.times.hough += spent;
        self.last_prior = PriorOutcome::FullSearch;
        Ok(())
    }

    /// Narrows (or widens again, `None`) the searches of the rows and their vanishing point.
    fn set_windows(&mut self, window: Option<(&Vector3<f64>, f64)>) {
        self.hough.set_window(window);
        self.vanish.finder.set_window(window);
        if let Some(s) = self.strips.as_mut() {
            s.set_window(window);
        }
    }

    /// What the prior did in the last image.
    pub fn last_prior(&self) -> PriorOutcome {
        self.last_prior
    }

    /// Everything after the preparation (started at `t0`, done at `t1`): the chosen method's
    /// rows, the vanishing point, heading and tilt. `edge` false keeps the edge rows of the
    /// previous call on the same points.
    fn detect_prepared(
        &mut self,
        out: &mut Detection,
        t0: Instant,
        t1: Instant,
        edge: bool,
    ) -> Result<(), DetectError> {
        self.last_pencil = PencilResult::default();
        out.boundaries.clear();
        match self.opts.method {
            Method::Strips => self.run_strips(out)?,
            Method::Pencil => {
                // the combined method's vanishing point, one more candidate for the pencil's
                let seed = if self.opts.pencil.seed_with_combined {
                    self.detect_with(Method::Combined, out, t0, t1, edge)?;
                    out.vanishing_point.map(|v| v.direction)
                } else {
                    None
                };
                out.rows.clear();
                out.boundaries.clear();
                self.run_pencil(seed, out)?;
            }
            _ => return self.detect_with(self.opts.method, out, t0, t1, edge),
        }
        // the strips' and the pencil's search counts as the Hough stage
        self.times = StageTimes {
            prepare: t1 - t0,
            hough: Instant::now() - t1,
            edge: Duration::ZERO,
            vanishing: Duration::ZERO,
        };
        Ok(())
    }

    /// The Hough, edge or combined `method`'s rows and vanishing point (as
    /// [`Self::detect_prepared`]).
    fn detect_with(
        &mut self,
        method: Method,
        out: &mut Detection,
        t0: Instant,
        t1: Instant,
        edge: bool,
    ) -> Result<(), DetectError> {
        out.rows.clear();
        self.last_hough = HoughResult::default();
        if method != Method::Edge {
            self.last_hough =
                self.hough
                    .find_rows(&self.points.rays, &self.points.weights, &mut out.rows)?;
            // A first vanishing point from the Hough rows shapes the refit's bands.
            let vp = if self.opts.refit.enabled && self.opts.refit.wedge {
                self.vanish.run(None, out)?;
                out.vanishing_point.map(|v| v.direction)
            } else {
                None
            };
            self.prep
                .refit(&mut out.rows, self.hough.bands(), vp.as_ref(), false)?;
        }
        let n_hough = out.rows.len();
        let t2 = Instant::now();
        if edge {
            self.edge_rows.clear();
            self.last_edge = EdgeResult::default();
            if method != Method::Hough {
                self.run_edge()?;
            }
            if method == Method::Edge {
                self.bend_edge_rows()?;
            }
        }
        let t3 = Instant::now();
        // Eq. 5: edge rows weigh w·support, Hough rows (1−w)·support. A single method's
        // rows weigh their support.
        let (hough_w, edge_w) = match method {
            Method::Combined => {
                let w = self.opts.combined.edge_weight;
                (1.0 - w, w)
            }
            _ => (1.0, 1.0),
        };
        self.weights.clear();
        for r in out.rows.iter() {
            self.weights.push(hough_w * r.support as f64);
        }
        for r in &self.edge_rows {
            self.weights.push(edge_w * r.support as f64);
            out.rows.push(*r);
        }
        self.vanish.run(Some(&self.weights), out)?;
        if self.opts.refit.perspective && n_hough > 0 {
            if let Some(vp) = out.vanishing_point {
                self.prep.refit(
                    &mut out.rows[..n_hough],
                    self.hough.bands(),
                    Some(&vp.direction),
                    true,
                )?;
                self.vanish.run(Some(&self.weights), out)?;
            }
        }
        self.final_inliers.clear();
        self.final_inliers.extend_from_slice(self.vanish.inliers());
        if method == Method::Combined && self.opts.combined.consensus {
            self.consensus(out)?;
        }
        if method != Method::Hough && self.opts.combined.precision_weighting {
            self.refit_by_precision(method, out);
        }
        if method == Method::Hough && self.opts.refit.precision_weights {
            self.refit_hough_by_precision(out);
        }
        // The edge method's rows are refitted, and turned, once they are centre lines; its
        // feet here would be the last frame's.
        if method != Method::Edge {
            self.turn_curved_rows(out);
        }
        if method == Method::Combined && self.opts.combined.reject_edge_outliers {
            let sin_tol = self.opts.vanishing.inlier_deg().to_radians().sin();
            let v = out.vanishing_point.map(|v| v.direction);
            out.rows.retain(|r| {
                r.method != Method::Edge || v.is_some_and(|v| r.normal.dot(&v).abs() < sin_tol)
            });
        }
        if method != Method::Hough {
            self.publish_centre_lines(out);
        }
        if method == Method::Edge {
            self.refit_centre_lines(out)?;
        }
        let t4 = Instant::now();
        self.times = StageTimes {
            prepare: t1 - t0,
            hough: t2 - t1,
            edge: if edge { t3 - t2 } else { self.times.edge },
            vanishing: t4 - t3,
        };
        Ok(())
    }

    /// The curved rows of the refit ([`super::sections::Sections::near_foot`]) turned about
    /// the final vanishing point through their point beside the robot: there the controller
    /// steers. The vanishing point, found from the rows' whole chords, stays as it is.
    fn turn_curved_rows(&self, out: &mut Detection) {
        let feet = self.prep.near_feet();
        let Some(vp) = out.vanishing_point.map(|v| v.direction) else {
            return;
        };
        if feet.is_empty() {
            return;
        }
        for r in out.rows.iter_mut() {
            let turned = feet
                .iter()
                .find(|f| f.normal == r.normal)
                .and_then(|f| f.foot.cross(&vp).try_normalize(1e-9));
            if let Some(n) = turned {
                r.normal = crate::sphere::canonical(&n);
            }
        }
    }

    /// The edge method alone on a curved field ([`super::chords`]): its rows, chords on one
    /// side of the robot, turned to their tangents beside it before the vote (with the
    /// refit's near-field fit, `refit.near_reach_m` > 0, and its `near_min_sigma`). Kept
    /// only when the turned rows agree on their vanishing point better than the chords did:
    /// a tilted robot on a straight field also makes the chords' headings, projected on the
    /// nominal ground, change with the distance ahead, but their great circles still meet.
    fn bend_edge_rows(&mut self) -> Result<(), DetectError> {
        self.last_bend = None;
        let (Some(edge), true) = (self.edge.as_ref(), self.opts.refit.near_reach_m > 0.0) else {
            return Ok(());
        };
        self.chord_rows.clear();
        self.chord_rows.extend_from_slice(&self.edge_rows);
        let Some(bend) = self.bend.turn(
            &mut self.edge_rows,
            edge.sections(),
            edge.assignment(),
            &edge.chains().rays,
            &self.prep.calibration().mounting.robot_from_camera(),
            self.opts.refit.near_min_sigma,
        ) else {
            return Ok(());
        };
        let chords = self.agreement(true)?;
        let turned = self.agreement(false)?;
        if turned > BEND_GAIN * chords {
            self.last_bend = Some(bend);
        } else {
            self.edge_rows.clear();
            self.edge_rows.extend_from_slice(&self.chord_rows);
        }
        Ok(())
    }

    /// The share of the edge rows' support (the chords before the bend, or the turned rows)
    /// that passes through their vanishing point.
    fn agreement(&mut self, chords: bool) -> Result<f64, DetectError> {
        let probe = &mut self.bend_probe;
        probe.rows.clear();
        probe.rows.extend_from_slice(if chords {
            &self.chord_rows
        } else {
            &self.edge_rows
        });
        self.vanish.run(None, probe)?;
        let total: f64 = probe.rows.iter().map(|r| r.support as f64).sum();
        let inside: f64 = probe
            .rows
            .iter()
            .zip(self.vanish.inliers())
            .filter(|(_, &i)| i)
            .map(|(r, _)| r.support as f64)
            .sum();
        Ok(if total > 0.0 { inside / total } else { 0.0 })
    }

    /// The bend the edge method found in its rows on the last image, when it turned them.
    pub fn last_bend(&self) -> Option<super::chords::Bend> {
        self.last_bend
    }

    /// The edge method's centre lines, each the bisector of two boundaries, refitted on the
    /// image's pixels between them as the Hough rows are (the band: half the row's width at
    /// its foot), and the curved ones turned through their point beside the robot
    /// ([`Self::turn_curved_rows`]). A bisector of the boundaries' great circles is not the
    /// row's centre line: the boundaries are each off by their own edge's bias, and the
    /// angle halfway between two lines on the ground is not the line halfway between them.
    fn refit_centre_lines(&mut self, out: &mut Detection) -> Result<(), DetectError> {
        let Some(vp) = out.vanishing_point.map(|v| v.direction) else {
            return Ok(());
        };
        self.centre_bands.clear();
        self.centre_bands
            .extend(out.rows.iter().map(|r| 0.5 * r.width_rad));
        self.prep
            .refit(&mut out.rows, &self.centre_bands, Some(&vp), false)?;
        self.turn_curved_rows(out);
        Ok(())
    }

    /// The edge and combined methods publish crop rows' centre lines, not boundaries
    /// ([`super::centre`]): the edge rows through the vanishing point become the widths of
    /// the Hough rows, or pair into centre lines; the boundaries stay readable in
    /// `out.boundaries`. Without a vanishing point no boundary is published.
    fn publish_centre_lines(&mut self, out: &mut Detection) {
        out.boundaries.clear();
        out.boundaries
            .extend(out.rows.iter().filter(|r| r.method == Method::Edge));
        let Some(vp) = out.vanishing_point.map(|v| v.direction) else {
            out.rows.retain(|r| r.method != Method::Edge);
            return;
        };
        // only rows through the vanishing point are crop rows of this field
        let sin_tol = self.opts.vanishing.inlier_deg().to_radians().sin();
        out.rows
            .retain(|r| r.method != Method::Edge || r.normal.dot(&vp).abs() < sin_tol);
        let max_half = self.opts.combined.pair_max_deg().to_radians();
        self.centre.publish(
            &mut out.rows,
            &vp,
            max_half,
            &self.points.rays,
            &self.points.weights,
        );
    }

    /// Replaces `out`'s vanishing point by a refitted one and derives heading and tilt
    /// from it (the final fits of the combined and Hough methods and the consensus step).
    fn set_vanishing_point(
        &self,
        out: &mut Detection,
        direction: Vector3<f64>,
        inliers: usize,
        residual_rad: f64,
    ) {
        let ht = heading_tilt(&direction, &self.prep.calibration().mounting);
        out.vanishing_point = Some(super::VanishingPoint {
            direction,
            inliers,
            residual_rad,
        });
        out.heading_rad = Some(ht.heading_rad);
        out.tilt_rad = Some(ht.tilt_rad);
    }

    /// The combined method's final fit: the vote's vanishing point refitted over its inlier
    /// rows with each method weighted by its measured precision ([`precision_fit`]).
    fn refit_by_precision(&mut self, method: Method, out: &mut Detection) {
        let Some(vp) = out.vanishing_point else {
            return;
        };
        let floor = self.opts.combined.precision_floor_mrad * 1e-3;
        let paired = method == Method::Combined
            && self.opts.combined.pair_edge_rows
            && pair_edge_rows(
                &out.rows,
                &self.final_inliers,
                &vp.direction,
                self.opts.combined.pair_max_deg().to_radians(),
                &mut self.paired_rows,
                &mut self.paired_inliers,
                &mut self.pair_scratch,
            ) > 0;
        let (rows, inliers) = if paired {
            (&self.paired_rows[..], &self.paired_inliers[..])
        } else {
            (&out.rows[..], &self.final_inliers[..])
        };
        let Some(fit) = precision_fit(
            rows,
            inliers,
            &vp.direction,
            floor,
            EDGE_PAIR_FACTOR,
            if self.opts.refit.precision_weights {
                self.prep.row_variances()
            } else {
                &[]
            },
            &mut self.precision_weights,
            &mut self.precision_scratch,
        ) else {
            return;
        };
        self.set_vanishing_point(out, fit.direction, vp.inliers, fit.residual_rad);
    }

    /// The Hough method's final fit: the vanishing point refitted over its inlier rows, each
    /// weighted by the inverse of its normal's variance along the vanishing point as the
    /// refit estimated it. Keeps the vote's fit when any inlier lacks an estimate.
    fn refit_hough_by_precision(&mut self, out: &mut Detection) {
        let Some(vp) = out.vanishing_point else {
            return;
        };
        let var = self.prep.row_variances();
        let inliers = self.vanish.inliers();
        if var.len() != out.rows.len() || inliers.len() != out.rows.len() {
            return;
        }
        self.precision_weights.clear();
        for (&v, &ok) in var.iter().zip(inliers) {
            if !ok {
                self.precision_weights.push(0.0);
            } else if v.is_finite() && v > 0.0 {
                self.precision_weights.push(1.0 / v);
            } else {
                return;
            }
        }
        let Some((direction, residual_rad)) =
            refit_direction(&out.rows, inliers, &self.precision_weights, &vp.direction)
        else {
            return;
        };
        self.set_vanishing_point(out, direction, vp.inliers, residual_rad);
    }

    /// The combined method's consensus step (see [`CombinedOptions::consensus`]): the vote's
    /// vanishing point against those of the Hough rows alone and of the edge rows alone,
    /// scored by how much of each method's rows agree with each. When another candidate
    /// wins, the rows of either method within the inlier tolerance of it become the inliers
    /// (iterated with the vote's weights, as the vanishing stage does) and `out` takes its
    /// vanishing point; `final_inliers` holds the inliers either way.
    fn consensus(&mut self, out: &mut Detection) -> Result<(), DetectError> {
        let Some(vote) = out.vanishing_point else {
            return Ok(());
        };
        let sin_tol = self.opts.vanishing.inlier_deg().to_radians().sin();
        let mut best = consensus_score(&out.rows, &vote.direction, sin_tol).score();
        let mut chosen: Option<Vector3<f64>> = None;
        for only in [Method::Hough, Method::Edge] {
            self.candidate_weights.clear();
            for (r, &w) in out.rows.iter().zip(&self.weights) {
                self.candidate_weights
                    .push(if r.method == only { w } else { 0.0 });
            }
            let r = self.vanish.finder.find(
                &out.rows,
                &self.candidate_weights,
                &mut self.candidate_inliers,
            )?;
            let Some(vp) = r.vanishing_point else {
                continue;
            };
            let c = consensus_score(&out.rows, &vp.direction, sin_tol);
            if c.hough_rows >= 2 && c.hough_rows + c.edge_rows >= 3 && c.score() > best {
                best = c.score();
                chosen = Some(vp.direction);
            }
        }
        let Some(mut v) = chosen else {
            return Ok(());
        };
        let mut residual = 0.0;
        let mut count = 0;
        for _ in 0..self.opts.vanishing.refine_iterations.max(1) {
            let mut sc = crate::sphere::Scatter::new();
            for (i, r) in out.rows.iter().enumerate() {
                let ok = r.normal.dot(&v).abs() < sin_tol && self.weights[i] > 0.0;
                self.final_inliers[i] = ok;
                if ok {
                    sc.add(&r.normal, self.weights[i]);
                }
            }
            count = sc.count();
            let Some(fit) = sc.fit() else { break };
            let n = if fit.normal.dot(&v) < 0.0 {
                -fit.normal
            } else {
                fit.normal
            };
            let moved = crate::sphere::axis_angle(&n, &v);
            v = n;
            residual = fit.mean_sq_residual.max(0.0).sqrt().asin();
            if moved < 1e-12 {
                break;
            }
        }
        for (i, r) in out.rows.iter().enumerate() {
            self.final_inliers[i] = r.normal.dot(&v).abs() < sin_tol && self.weights[i] > 0.0;
        }
        self.set_vanishing_point(out, v, count, residual);
        Ok(())
    }

    /// The pencil method: the vanishing point that makes the rows sharpest and the rows
    /// read off the profile there, then the vanishing stage on those rows.
    ///
    /// Each candidate vanishing point (the strongest local maxima of the profile's
    /// contrast) gives its rows, each refitted freely on its points; the vanishing stage
    /// then tells how well those rows still meet in one point, and the comb fitted to its
    /// profile how evenly spaced its rows are. The candidate whose contrast times that
    /// quality times the comb's contrast (to `pencil.comb_power`) is highest wins: a wrong candidate that lines up one strong
    /// structure sharply gives rows that do not agree once refitted.
    fn run_pencil(
        &mut self,
        seed: Option<Vector3<f64>>,
        out: &mut Detection,
    ) -> Result<(), DetectError> {
        let p = &self.points;
        let scales = self.pencil.prepare(&p.rays, &p.weights, &p.pixel_rad)?;
        let seeds = seed.as_slice();
        self.pencil
            .candidates(&p.rays, &p.weights, seeds, &mut self.pencil_candidates);
        let mut best: Option<(f64, usize)> = None;
        for k in 0..self.pencil_candidates.len() {
            let c = self.pencil_candidates[k];
            out.rows.clear();
            self.pencil
                .read_rows(&c.direction, &p.rays, &p.weights, &mut out.rows);
            let r = self.vanish.run(None, out)?;
            let comb = self
                .pencil
                .last_comb()
                .map_or(0.0, |c| c.comb.contrast)
                .max(0.05);
            let score = c.contrast * r.quality * comb.powf(self.opts.pencil.comb_power);
            if best.map_or(true, |b| score > b.0) {
                best = Some((score, k));
                self.pencil_rows.clear();
                self.pencil_rows.extend_from_slice(&out.rows);
            }
        }
        out.rows.clear();
        self.last_pencil = PencilResult {
            scales,
            evaluated: self.pencil.evaluated(),
            ..PencilResult::default()
        };
        if let Some((_, k)) = best {
            let c = self.pencil_candidates[k];
            out.rows.extend_from_slice(&self.pencil_rows);
            self.last_pencil.direction = Some(c.direction);
            self.last_pencil.contrast = c.contrast;
            self.last_pencil.rows = out.rows.len();
        }
        self.vanish.run(None, out)?;
        if self.opts.pencil.polish {
            let band = self.opts.pencil.polish_max_band_deg();
            self.polish_pencil_rows(out, band)?;
        }
        Ok(())
    }

    /// The strips method ([`super::strips`]): its rows through its vanishing point, then
    /// the vanishing stage on those rows and the polish.
    fn run_strips(&mut self, out: &mut Detection) -> Result<(), DetectError> {
        out.rows.clear();
        let Some(strips) = self.strips.as_mut() else {
            return Err(DetectError::Options(
                "method strips was not set up for this detector".into(),
            ));
        };
        let p = &self.points;
        let vp = strips.find(&p.rays, &p.weights, &p.pixel_rad, &mut out.rows)?;
        self.vanish.run(None, out)?;
        self.polish_pencil_rows(out, self.strips_polish_band_deg)?;
        // The rows meet in the strips' vanishing point by construction; where the
        // vanishing stage finds none among them (one or two rows), that point is the answer.
        if let (None, Some(v), false) = (out.vanishing_point, vp, out.rows.is_empty()) {
            let n = out.rows.len();
            self.set_vanishing_point(out, v, n, 0.0);
            out.quality = self
                .last_strips()
                .map_or(0.0, |s| s.comb_strength.clamp(0.0, 1.0));
        }
        Ok(())
    }

    /// The strips' agreement at the summit nearest a vanishing direction, on the last
    /// image, and that summit's distance from their answer ([`StripsRows::agreement_near`]);
    /// `None` unless the strips method ran.
    pub fn strips_agreement_near(&mut self, dir: &Vector3<f64>) -> Option<(f64, f64)> {
        self.strips.as_mut()?.agreement_near(dir)
    }

    /// What the strips method found in the last image (`None` unless it is the method).
    pub fn last_strips(&self) -> Option<StripsResult> {
        self.strips.as_ref().map(|s| s.last())
    }

    /// Refits the pencil's rows on the image's pixels near each (as the Hough rows are,
    /// [`Preparer::refit`]), each in a wedge towards the vanishing point a quarter of the
    /// angle to its nearest neighbour wide on each side (at most `max_band_deg`), then finds
    /// the vanishing point again and refits it by the rows' precision. The pencil places rows on a grid of
    /// profile bins; the refit gives them the sub-pixel precision of the Hough method.
    fn polish_pencil_rows(
        &mut self,
        out: &mut Detection,
        max_band_deg: f64,
    ) -> Result<(), DetectError> {
        let Some(vp) = out.vanishing_point.map(|v| v.direction) else {
            return Ok(());
        };
        let a = crate::sphere::any_perpendicular(&vp);
        let b = vp.cross(&a);
        let angle = |n: &Vector3<f64>| n.dot(&b).atan2(n.dot(&a)).rem_euclid(std::f64::consts::PI);
        let max_band = max_band_deg.to_radians();
        self.pencil_bands.clear();
        for (i, r) in out.rows.iter().enumerate() {
            let pi = angle(&r.normal);
            let mut gap = std::f64::consts::PI;
            for (j, q) in out.rows.iter().enumerate() {
                if i != j {
                    let d = (angle(&q.normal) - pi).rem_euclid(std::f64::consts::PI);
                    gap = gap.min(d.min(std::f64::consts::PI - d));
                }
            }
            self.pencil_bands.push((0.25 * gap).min(max_band));
        }
        self.prep
            .refit(&mut out.rows, &self.pencil_bands, Some(&vp), false)?;
        self.vanish.run(None, out)?;
        if self.opts.refit.precision_weights {
            self.refit_hough_by_precision(out);
        }
        Ok(())
    }

    /// Runs the edge method on the preparer's smoothed vegetation image and mask.
    fn run_edge(&mut self) -> Result<(), DetectError> {
        let (_, smoothed) = self.prep.vegetation();
        let (w, h) = (smoothed.width, smoothed.height);
        let (Some(cal), Some((mask, _))) = (self.prep.working_calibration(), self.prep.mask())
        else {
            return Err(DetectError::Buffer(
                "edge method: the preparer has no setup".into(),
            ));
        };
        let stale = match &self.edge {
            None => true,
            Some(e) => self.last_prepare.setup_rebuilt || e.size() != (w, h),
        };
        if stale {
            self.edge = Some(EdgeDetector::new(cal, w, h, self.opts.edge)?);
        }
        let Some(edge) = self.edge.as_mut() else {
            return Err(DetectError::Buffer("edge method: no setup".into()));
        };
        self.last_edge = edge.process(&smoothed.data, mask, &mut self.edge_rows)?;
        Ok(())
    }

    /// The stages, for running them separately (e.g. pipelined on threads).
    pub fn into_stages(self) -> (Preparer, HoughRows, VanishingStage) {
        (self.prep, self.hough, self.vanish)
    }

    pub fn preparer(&self) -> &Preparer {
        &self.prep
    }

    pub fn preparer_mut(&mut self) -> &mut Preparer {
        &mut self.prep
    }

    pub fn hough(&self) -> &HoughRows {
        &self.hough
    }

    pub fn vanishing_stage(&self) -> &VanishingStage {
        &self.vanish
    }

    /// The points kept from the last image.
    pub fn points(&self) -> &Points {
        &self.points
    }

    pub fn last_times(&self) -> StageTimes {
        self.times
    }

    pub fn last_prepare(&self) -> PrepareResult {
        self.last_prepare
    }

    pub fn last_pencil(&self) -> PencilResult {
        self.last_pencil
    }

    pub fn last_hough(&self) -> HoughResult {
        self.last_hough
    }

    /// What the edge method did on the last image (all zero when it did not run).
    pub fn last_edge(&self) -> EdgeResult {
        self.last_edge
    }

    /// The edge method's state after the last image (edges, chains, sections), if it ran.
    pub fn edge(&self) -> Option<&EdgeDetector> {
        self.edge.as_ref()
    }

    /// The calibration at the last image's resolution.
    pub fn view_calibration(&self) -> Option<&Calibration> {
        self.prep.view_calibration()
    }
}

/// The pixel (row, col) of a direction (either sign) in an image described by `cal`:
/// the sign whose pixel lies inside the field of view, else inside the image, else `None`.
pub fn direction_to_pixel(cal: &Calibration, dir: &Vector3<f64>) -> Option<[f64; 2]> {
    for d in [*dir, -*dir] {
        if let Some(p) = cal.ray_to_pixel_in_fov(&d) {
            return Some(p);
        }
    }
    let (h, w) = (cal.model.height as f64, cal.model.width as f64);
    [*dir, -*dir].iter().find_map(|d| {
        cal.model
            .world2cam(d)
            .filter(|p| p[0] >= -0.5 && p[1] >= -0.5 && p[0] < h - 0.5 && p[1] < w - 0.5)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::ideal_fisheye;
    use crate::detect::edge::EdgeOptions;

    #[test]
    fn auto_is_default_and_resolves_by_the_lens() {
        assert_eq!(DetectorOptions::default().method, Method::Auto);
        // an omnidirectional lens keeps the paper's combined method
        let fisheye = ideal_fisheye(100, 120).unwrap();
        let d = Detector::new(&fisheye, DetectorOptions::default()).unwrap();
        assert_eq!(d.options().method, Method::Combined);
        // a forward-looking perspective camera gets the strips
        let pinhole = crate::camera::Calibration::parse_toml(
            include_str!("../../config/calib/pinhole_512_f300.toml"),
            std::path::Path::new("pinhole_512_f300.toml"),
        )
        .unwrap();
        let d = Detector::new(&pinhole, DetectorOptions::default()).unwrap();
        assert_eq!(d.options().method, Method::Strips);
        // the same lens looking straight down gets the pencil
        let mut down = pinhole.clone();
        down.mounting.pitch_deg = 0.0;
        let d = Detector::new(&down, DetectorOptions::default()).unwrap();
        assert_eq!(d.options().method, Method::Pencil);
        // an explicit method is kept whatever the lens
        let hough = DetectorOptions {
            method: Method::Hough,
            ..Default::default()
        };
        let d = Detector::new(&pinhole, hough).unwrap();
        assert_eq!(d.options().method, Method::Hough);
    }

    #[test]
    fn weight_is_checked() {
        let cal = ideal_fisheye(100, 120).unwrap();
        for w in [0.0, 1.0, -0.5, f64::NAN] {
            let e = Detector::new(
                &cal,
                DetectorOptions {
                    combined: CombinedOptions {
                        edge_weight: w,
                        ..Default::default()
                    },
                    ..Default::default()
                },
            )
            .unwrap_err()
            .to_string();
            assert!(e.contains("edge_weight"), "{e}");
        }
        let o: DetectorOptions = toml::from_str(
            "method = \"edge\"\n[edge.split]\ntolerance_px = 2.0\n[combined]\nedge_weight = 0.5\n",
        )
        .unwrap();
        assert_eq!(o.method, Method::Edge);
        assert_eq!(o.edge.split.tolerance_px, 2.0);
        assert_eq!(o.combined.edge_weight, 0.5);
        let bad = DetectorOptions {
            edge: EdgeOptions {
                split: crate::detect::edge::SplitOptions {
                    tolerance_px: -1.0,
                    ..Default::default()
                },
                ..Default::default()
            },
            ..Default::default()
        };
        let e = Detector::new(&cal, bad).unwrap_err().to_string();
        assert!(e.contains("tolerance_px"), "{e}");
    }

    #[test]
    fn rejects_images_not_a_uniform_scale_of_the_calibration() {
        let cal = ideal_fisheye(100, 120).unwrap();
        let mut d = Detector::new(&cal, DetectorOptions::default()).unwrap();
        let data = vec![0u8; 100 * 100];
        let v = ImageView::new(100, 100, PixelFormat::Mono8, &data).unwrap();
        let mut out = Detection::default();
        let e = d.process(&v, &mut out).unwrap_err().to_string();
        assert!(e.contains("not the calibration"), "{e}");
    }

    #[test]
    fn options_reject_unknown_keys() {
        let e = toml::from_str::<DetectorOptions>("max_tilt_deg = 10\nbogus = 1\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("bogus"), "{e}");
        let o: DetectorOptions = toml::from_str("[hough]\nphi_bins = 60\n").unwrap();
        assert_eq!(o.hough.phi_bins, Some(60));
        assert_eq!(o.hough.theta_bins, None);
    }
}
