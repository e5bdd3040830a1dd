//! The frame's preparation, the stage every method starts from: image → vegetation →
//! smoothing → threshold → the kept points.
//!
//! Owns [`Preparer`] and its per-image-size setup (the calibration rescaled to the image, the
//! field-of-view mask found from the image when the calibration has none, the mask and the
//! per-pixel ray and solid-angle tables, the refit's tiles), rebuilt only when the image's
//! size or pixel format changes; the frame's vegetation image and its smoothed version; and
//! the refit of rows on the smoothed image's pixels ([`super::refit`]), which reads them. The
//! hot path allocates nothing once warmed up.

use super::bands::{self, Band};
use super::mask::{build_mask, find_fov, MaskOptions, MaskResult};
use super::refit::{refit_rows, Candidates, NearFoot, RefitImage, RefitOptions, RowFits, Tiles};
use super::sections::NearField;
use super::smooth::{BandScratch, Gaussian, SmoothOptions};
use super::threshold::{histogram, keep_counted, valid_pixels, Counts};
use super::threshold::{ThresholdOptions, ThresholdResult};
use super::types::{DetectError, GreyImage, Points, Row};
use super::vegetation::{working_factor, Binning, Vegetation, VegetationOptions};
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

/// A band's part of the preparation's fused pass: its scratch, and the rows and the
/// histogram of its last frame.
#[derive(Debug, Clone)]
struct PrepBand {
    smooth: BandScratch,
    rows: std::ops::Range<usize>,
    hist: [u32; 256],
}

impl Default for PrepBand {
    fn default() -> Self {
        PrepBand {
            smooth: BandScratch::default(),
            rows: 0..0,
            hist: [0; 256],
        }
    }
}

/// The fused pass's outputs and inputs as bands of rows split them.
struct Bands<'a> {
    veg: &'a mut [u8],
    smoothed: &'a mut [u8],
    mask: &'a [u8],
    width: usize,
    scratch: &'a mut [PrepBand],
}

impl Band for Bands<'_> {
    fn parts(&self) -> usize {
        self.scratch.len()
    }

    fn split(self, rows: usize, parts: usize) -> (Self, Self) {
        let at = rows * self.width;
        let (v0, v1) = self.veg.split_at_mut(at);
        let (s0, s1) = self.smoothed.split_at_mut(at);
        let (m0, m1) = self.mask.split_at(at);
        let (c0, c1) = self.scratch.split_at_mut(parts);
        let width = self.width;
        (
            Bands {
                veg: v0,
                smoothed: s0,
                mask: m0,
                width,
                scratch: c0,
            },
            Bands {
                veg: v1,
                smoothed: s1,
                mask: m1,
                width,
                scratch: c1,
            },
        )
    }
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
    /// The mask's valid pixels.
    valid: u64,
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
    /// Per band of the fused pass: its scratch, rows and histogram.
    bands: Vec<PrepBand>,
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
            bands: Vec::new(),
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
            valid: valid_pixels(&mask),
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
    ///
    /// The vegetation image, its smoothing and the threshold's histogram are one pass, band
    /// by band ([`bands::each`]) and strip by strip within a band
    /// ([`Gaussian::apply_band`]): each strip's rows are computed, smoothed and counted
    /// while they are in the cache. The threshold then chooses its level from the bands'
    /// histograms and collects the points from the smoothed image.
    pub fn run_on(
        &mut self,
        view: &ImageView,
        points: &mut Points,
        pool: Option<&ThreadPool>,
    ) -> Result<PrepareResult, DetectError> {
        let rebuilt = self.ensure_setup(view)?;
        let s = self.setup.as_ref().expect("setup just ensured");
        let veg = Vegetation::new(view, &self.opts.vegetation, s.bin2)?;
        let (w, h) = veg.size();
        if s.mask.len() != w * h {
            return Err(DetectError::Buffer(format!(
                "prepare: a {w}x{h} working image with a mask of {} pixels",
                s.mask.len()
            )));
        }
        self.veg.resize(w, h);
        self.smoothed.resize(w, h);
        let threads = pool.map_or(1, |p| p.current_num_threads());
        if self.bands.len() < threads {
            self.bands.resize_with(threads, PrepBand::default);
        }
        let band = Bands {
            veg: &mut self.veg.data,
            smoothed: &mut self.smoothed.data,
            mask: &s.mask,
            width: w,
            scratch: &mut self.bands[..],
        };
        let gauss = &self.gauss;
        let failed = std::sync::atomic::AtomicBool::new(false);
        let parts = bands::each(pool, h, band, &|rows, b: Bands| {
            let (mask, sc) = (b.mask, &mut b.scratch[0]);
            sc.rows = rows.clone();
            sc.hist = [0; 256];
            let y0 = rows.start;
            let hist = &mut sc.hist;
            let r = gauss.apply_band(
                w,
                h,
                rows,
                b.veg,
                b.smoothed,
                &mut sc.smooth,
                |r, out| veg.rows(r, out),
                |r, smoothed| {
                    let m = &mask[(r.start - y0) * w..(r.end - y0) * w];
                    for (t, c) in hist.iter_mut().zip(histogram(smoothed, m)) {
                        *t += c;
                    }
                },
            );
            if r.is_err() {
                failed.store(true, std::sync::atomic::Ordering::Relaxed);
            }
        });
        if failed.into_inner() {
            return Err(DetectError::Buffer(format!(
                "prepare: the bands of a {w}x{h} working image do not match it"
            )));
        }
        let used = &self.bands[..parts];
        let mut counts = Counts {
            hist: [0; 256],
            valid: s.valid,
            first: None,
        };
        for b in used {
            for (t, &c) in counts.hist.iter_mut().zip(&b.hist) {
                *t += c;
            }
        }
        // The points are collected in two parts at once, split where the bands of the
        // first half of the threads end.
        if used.len() > 1 {
            let firsts = &used[..used.len() / 2];
            let mut first = [0u32; 256];
            for b in firsts {
                for (t, &c) in first.iter_mut().zip(&b.hist) {
                    *t += c;
                }
            }
            counts.first = Some((firsts[firsts.len() - 1].rows.end * w, first));
        }
        let thr = keep_counted(
            &self.smoothed.data,
            &s.mask,
            &self.opts.threshold,
            &counts,
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::smooth::SmoothOptions;
    use crate::detect::threshold::keep_brightest;
    use crate::detect::vegetation::vegetation_image;
    use crate::detect::DetectorOptions;

    /// The preparation as separate passes over the whole image: the vegetation image, the
    /// smoothing, then the threshold.
    fn separate_passes(
        p: &Preparer,
        view: &ImageView,
    ) -> (Vec<u8>, Vec<u8>, Vec<u32>, ThresholdResult) {
        let s = p.setup.as_ref().unwrap();
        let mut veg = GreyImage::default();
        vegetation_image(view, &p.opts.vegetation, s.bin2, &mut veg).unwrap();
        let (mut tmp, mut smoothed) = (Vec::new(), vec![0u8; veg.data.len()]);
        p.gauss
            .apply(&veg.data, veg.width, veg.height, &mut tmp, &mut smoothed)
            .unwrap();
        let mut kept = Vec::new();
        let t = keep_brightest(&smoothed, &s.mask, &p.opts.threshold, &mut kept).unwrap();
        (veg.data, smoothed, kept, t)
    }

    #[test]
    fn the_fused_pass_keeps_the_separate_passes_points_on_any_threads() {
        let pool = |n| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap()
        };
        let pools = [None, Some(pool(1)), Some(pool(2)), Some(pool(3))];
        // Bayer (quads), Mono8 binned and not, RGB; a working image whose height is not a
        // multiple of the strips or the bands; σ 0 (a copy) and a wide kernel
        let cases = [
            (PixelFormat::BayerRggb8, 482, 398, 0.8, 4000),
            (PixelFormat::Mono8, 242, 300, 1.5, 700),
            (PixelFormat::Mono8, 101, 120, 1.5, 700),
            (PixelFormat::Rgb8, 130, 162, 0.0, 300),
            (PixelFormat::Rgb8, 130, 162, 0.8, 300),
            (PixelFormat::BayerRggb8, 300, 260, 3.0, 1_000_000),
        ];
        for (i, (format, height, width, sigma, target)) in cases.into_iter().enumerate() {
            let cal = crate::camera::ideal_fisheye(height, width).unwrap();
            let mut opts = DetectorOptions::default().prepare();
            opts.smooth = SmoothOptions { sigma_px: sigma };
            opts.threshold.target_points = Some(target);
            if i == 1 || i == 4 {
                opts.binning = Binning::Half;
            }
            let n = (height * width) as usize * format.bytes_per_pixel();
            let mut data = crate::detect::noise_bytes(height as u64 ^ 0xfeed, n);
            // a run of one value: pixels at the level thinned across the bands
            for v in data.iter_mut().skip(n / 3).take(n / 5) {
                *v = 230;
            }
            let view = ImageView::new(width, height, format, &data).unwrap();
            let mut p = Preparer::new(&cal, &opts).unwrap();
            let mut points = Points::default();
            for (k, pool) in pools.iter().enumerate() {
                let r = p.run_on(&view, &mut points, pool.as_ref()).unwrap();
                assert_eq!(r.setup_rebuilt, k == 0);
                let (veg, smoothed, kept, t) = separate_passes(&p, &view);
                let what = format!("{format:?} {width}x{height} σ {sigma}, pool {k}");
                assert_eq!(p.veg.data, veg, "{what}");
                assert_eq!(p.smoothed.data, smoothed, "{what}");
                assert_eq!(
                    (p.kept.as_slice(), p.last_threshold),
                    (&kept[..], t),
                    "{what}"
                );
                assert_eq!(r.threshold, t);
                assert!(t.kept > 0, "{what}");
                assert_eq!(points.rays.len(), kept.len());
            }
        }
    }
}
