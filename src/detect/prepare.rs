//! The frame's preparation, the stage every method starts from: image → vegetation →
//! smoothing → threshold → the kept points.
//!
//! Owns [`Preparer`] and its per-image-size setup (the calibration rescaled to the image, the
//! field-of-view mask found from the image when the calibration has none, the mask and the
//! per-pixel ray and solid-angle tables, the refit's tiles), rebuilt only when the image's
//! size or pixel format changes; the frame's vegetation image and its smoothed version; and
//! the refit of rows on the smoothed image's pixels ([`super::refit`]), which reads them. The
//! hot path allocates nothing once warmed up.

use super::mask::{build_mask, find_fov, MaskOptions, MaskResult};
use super::refit::{refit_rows, Candidates, NearFoot, RefitImage, RefitOptions, RowFits, Tiles};
use super::sections::NearField;
use super::smooth::{Gaussian, SmoothOptions};
use super::threshold::{keep_brightest_on, ThresholdOptions, ThresholdResult};
use super::types::{DetectError, GreyImage, Points, Row};
use super::vegetation::{vegetation_image_on, working_factor, Binning, VegetationOptions};
use crate::camera::Calibration;
use crate::frame::{ImageView, PixelFormat};
use nalgebra::Vector3;
use rayon::ThreadPool;

/// What the preparation is told: the `[detector]` options it reads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrepareOptions {
    /// Largest expected tilt of the robot (degrees): bounds the sky mask.
    pub max_tilt_deg: f64,
    pub binning: Binning,
    pub vegetation: VegetationOptions,
    pub mask: MaskOptions,
    pub smooth: SmoothOptions,
    pub threshold: ThresholdOptions,
    pub refit: RefitOptions,
}

/// The last image at the working resolution as the stages after the preparation read it.
#[derive(Debug, Clone, Copy)]
pub struct PreparedImage<'a> {
    /// The smoothed vegetation image.
    pub smoothed: &'a GreyImage,
    /// Its mask (0xFF = use).
    pub mask: &'a [u8],
    /// The calibration at the working resolution.
    pub calibration: &'a Calibration,
}

/// The refit of rows on the last image ([`Preparer::split`]).
pub struct Refitter<'a> {
    img: RefitImage<'a>,
    candidates: &'a mut Candidates,
    fits: &'a mut RowFits,
}

impl Refitter<'_> {
    /// As [`Preparer::refit`].
    pub fn refit(
        &mut self,
        rows: &mut [Row],
        bands: &[f64],
        vp: Option<&Vector3<f64>>,
    ) -> Result<usize, DetectError> {
        refit_rows(&self.img, rows, bands, vp, self.candidates, self.fits)
    }
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

/// The preparation: image → vegetation → smoothing → threshold → kept rays.
#[derive(Debug, Clone)]
pub struct Preparer {
    cal: Calibration,
    /// The field-of-view mask is found from the image (the calibration has none).
    fov_auto: bool,
    opts: PrepareOptions,
    gauss: Gaussian,
    setup: Option<Setup>,
    veg: GreyImage,
    smoothed: GreyImage,
    tmp: Vec<u8>,
    kept: Vec<u32>,
    /// The threshold's second half's kept pixels, when split across threads.
    spare: Vec<u32>,
    /// The refit's pixels near one row (room for every valid pixel, reserved at setup).
    candidates: Candidates,
    /// Per row of the last refit: the variance of its normal along the vanishing point, and
    /// the curved rows' points beside the robot.
    fits: RowFits,
    last_threshold: ThresholdResult,
}

impl Preparer {
    pub fn new(cal: &Calibration, opts: &PrepareOptions) -> Result<Self, DetectError> {
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
            opts: *opts,
            gauss: Gaussian::new(&opts.smooth)?,
            setup: None,
            veg: GreyImage::default(),
            smoothed: GreyImage::default(),
            tmp: Vec::new(),
            kept: Vec::new(),
            spare: Vec::new(),
            candidates: Candidates::default(),
            fits: RowFits::with_capacity(256),
            last_threshold: ThresholdResult::default(),
        })
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

    /// Builds the setup for `view`'s size and format unless it has it already; whether it
    /// was rebuilt.
    fn ensure_setup(&mut self, view: &ImageView) -> Result<bool, DetectError> {
        if let Some(s) = &self.setup {
            if (s.width, s.height, s.format) == (view.width, view.height, view.format) {
                return Ok(false);
            }
        }
        let (view_cal, bin2, factor, work_cal) = self.calibrations(view)?;
        let mut mask = Vec::new();
        let mut rays = Vec::new();
        let mut solid = Vec::new();
        let mask_result = build_mask(
            &work_cal,
            &self.opts.mask,
            self.opts.max_tilt_deg,
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
        self.veg.resize(ww, wh);
        self.smoothed.resize(ww, wh);
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

    /// The calibration at `view`'s resolution (with its field-of-view mask, found from the
    /// image when the calibration has none), whether the image is binned 2×2, the reduction
    /// to the working image and the calibration there.
    fn calibrations(
        &self,
        view: &ImageView,
    ) -> Result<(Calibration, bool, u32, Calibration), DetectError> {
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
        let bin2 = self.opts.binning.bins(view.width, view.height);
        let factor = working_factor(view.width, view.height, view.format, bin2)?;
        let work_cal = if factor == 1 {
            view_cal.clone()
        } else {
            view_cal.rescaled(factor as f64).map_err(img_err)?
        };
        Ok((view_cal, bin2, factor, work_cal))
    }

    /// Runs the stage on one image, writing the kept points into `points`.
    pub fn run(
        &mut self,
        view: &ImageView,
        points: &mut Points,
    ) -> Result<PrepareResult, DetectError> {
        self.run_on(view, points, None)
    }

    /// [`Self::run`] with the vegetation image, the smoothing and the threshold split across
    /// `pool`'s threads when there is one: the same points.
    pub fn run_on(
        &mut self,
        view: &ImageView,
        points: &mut Points,
        pool: Option<&ThreadPool>,
    ) -> Result<PrepareResult, DetectError> {
        let rebuilt = self.ensure_setup(view)?;
        let s = self.setup.as_ref().expect("setup just ensured");
        vegetation_image_on(view, &self.opts.vegetation, s.bin2, &mut self.veg, pool)?;
        let (w, h) = (self.veg.width, self.veg.height);
        let (veg, smoothed) = (&self.veg.data, &mut self.smoothed.data);
        self.gauss
            .apply_on(veg, w, h, &mut self.tmp, smoothed, pool)?;
        let thr = keep_brightest_on(
            &self.smoothed.data,
            &s.mask,
            &self.opts.threshold,
            &mut self.kept,
            pool.map(|p| (p, &mut self.spare)),
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
    /// Refits rows (with the bands they were found in, radians at their foot) on every
    /// pixel of the last image near them, weighted by intensity above the background (see
    /// [`super::refit`]). With the rows' vanishing point `vp` (an estimate), each row's band
    /// narrows towards it. Returns the number of rows refitted.
    pub fn refit(
        &mut self,
        rows: &mut [Row],
        bands: &[f64],
        vp: Option<&Vector3<f64>>,
    ) -> Result<usize, DetectError> {
        match self.split() {
            Some((_, mut refitter)) => refitter.refit(rows, bands, vp),
            None => Ok(0),
        }
    }

    /// The last image as other stages read it, beside the refit on it, which writes only
    /// its own scratch: the two can be used at once (the combined method's Hough rows are
    /// refitted while the edge detector reads the image). `None` before the first image.
    pub fn split(&mut self) -> Option<(PreparedImage<'_>, Refitter<'_>)> {
        let near = self.near_field();
        let s = self.setup.as_ref()?;
        let t = &self.last_threshold;
        let bg = t.median as f64
            + super::refit::BACKGROUND_FRACTION * (t.level as f64 - t.median as f64).max(0.0);
        let img = RefitImage {
            values: &self.smoothed.data,
            mask: &s.mask,
            rays: &s.rays,
            solid: &s.solid,
            tiles: &s.tiles,
            pixel_angle: s.pixel_angle,
            model: &s.work_cal.model,
            background: bg.round().clamp(0.0, 254.0) as u8,
            plateau_cap: super::refit::PLATEAU_CAP,
            near,
        };
        let image = PreparedImage {
            smoothed: &self.smoothed,
            mask: &s.mask,
            calibration: &s.work_cal,
        };
        let refitter = Refitter {
            img,
            candidates: &mut self.candidates,
            fits: &mut self.fits,
        };
        Some((image, refitter))
    }

    /// The curved rows of the last refit: their points beside the robot.
    pub fn near_feet(&self) -> &[NearFoot] {
        &self.fits.feet
    }

    /// The rows' near part for the refit's near-field fit, from the mounting (`None`
    /// when `refit.near_reach_m` is 0).
    fn near_field(&self) -> Option<NearField> {
        let r = &self.opts.refit;
        let m = &self.cal.mounting;
        (r.near_reach_m > 0.0).then(|| NearField {
            down: m.robot_from_camera().inverse() * -Vector3::z(),
            reach: r.near_reach_m / m.height_m,
            min_sigma: super::refit::NEAR_MIN_SIGMA,
        })
    }

    /// Per row of the last refit given a vanishing point: the variance of the row normal's
    /// component along it, relative to the image's noise (NaN where not estimated).
    pub fn row_variances(&self) -> &[f64] {
        &self.fits.along_var
    }
}
