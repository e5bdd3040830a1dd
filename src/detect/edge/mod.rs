//! The paper's edge method (II-C): rows as great circles found from image edges.
//!
//! Owns the edge path from an 8-bit image (vegetation or greyscale) and a mask to rows:
//! Canny ([`canny`]), chains of connected edge pixels turned into rays ([`chains`]), chains
//! split into sections that each lie on one great circle ([`split`]), and sections merged into
//! rows with their support ([`merge`]). [`EdgeDetector`] does the heavy setup once for a
//! calibration and an image size; its `process` allocates nothing once warmed up.
//!
//! The configuration ([`EdgeOptions`], the `[detector.edge]` table) holds only the support a
//! row needs. Every other parameter is fixed: [`EdgeParams`] gathers them, stage by stage,
//! built from the options and the merge angle the calibration gives
//! ([`EdgeParams::from_options`]).
//!
//! The edge method finds the two boundaries of a solid row (the paper's figures 6–7), so
//! each crop row usually gives two rows here, both through the row's vanishing point.

pub mod canny;
pub mod chains;
pub mod merge;
pub mod split;

pub use canny::{Canny, CannyParams, CannyResult, ThresholdMode};
pub use chains::{ChainParams, ChainResult, ChainTracer, Chains};
pub use merge::{MergeParams, MergeResult, Merger, REFERENCE_MAX_ANGLE_RAD};
pub use split::{Section, SplitParams, SplitResult, Splitter};

use crate::camera::Calibration;
use crate::detect::types::Row;
use crate::frame::{ImageView, PixelFormat};
use serde::{Deserialize, Serialize};

/// Errors of the edge path.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum EdgeError {
    /// A buffer does not match the image size.
    #[error("{what} has {actual} bytes but a {width}x{height} image needs {expected}")]
    Size {
        what: &'static str,
        width: usize,
        height: usize,
        expected: usize,
        actual: usize,
    },
    /// A parameter is out of range, or stages disagree.
    #[error("edge parameters: {0}")]
    Options(String),
    /// The calibration does not fit the image.
    #[error("edge calibration: {0}")]
    Calibration(String),
    /// The image is not a one-byte-per-pixel image.
    #[error("edge method needs a one-byte-per-pixel (vegetation or grey) image, got {0:?}")]
    Format(PixelFormat),
}

/// The edge method's configuration (the `[detector.edge]` table).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EdgeOptions {
    /// Rows with fewer edge points are dropped (default 30); lower it for sparse plants or a
    /// low resolution, where a row's boundary gives fewer points.
    pub min_support: u32,
}

impl Default for EdgeOptions {
    fn default() -> Self {
        EdgeOptions {
            min_support: MergeParams::default().min_support,
        }
    }
}

/// Every parameter of the edge method, stage by stage (not configurable: the detector builds
/// them with [`EdgeParams::from_options`]; tests and benchmarks set others to run the method
/// on an unsmoothed full-resolution image).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeParams {
    pub canny: CannyParams,
    pub chains: ChainParams,
    pub split: SplitParams,
    pub merge: MergeParams,
    /// The image is reduced by this factor (mean of factor×factor blocks) before Canny, and
    /// the calibration rescaled with it (1 = full resolution, the detector's: it hands over
    /// its working image). Pixel parameters (tolerances, lengths, sigma, the mask's margin)
    /// are in pixels of the reduced image. When the image size is not a multiple of the
    /// factor, the last partial block of rows and columns is left out.
    pub downsample: u32,
}

/// The mask is shrunk by this many pixels (of the working resolution) before use, so that its
/// own boundary (the rim of the lens's image circle, the robot's body) gives no edges; at
/// least the radius of the Gaussian Canny may smooth with.
const MASK_MARGIN_PX: usize = 5;

impl Default for EdgeParams {
    fn default() -> Self {
        EdgeParams {
            canny: CannyParams::default(),
            chains: ChainParams::default(),
            split: SplitParams::default(),
            merge: MergeParams::default(),
            downsample: 1,
        }
    }
}

impl EdgeParams {
    /// The parameters the detector runs the method with: the configuration's `min_support`
    /// and the merge angle `max_angle_rad` (radians; [`REFERENCE_MAX_ANGLE_RAD`] times the
    /// calibration's angle factor, see [`crate::detect::scale`]), the rest fixed.
    pub fn from_options(options: &EdgeOptions, max_angle_rad: f64) -> Self {
        let mut p = EdgeParams::default();
        p.merge.min_support = options.min_support;
        p.merge.max_angle_rad = max_angle_rad;
        p
    }

    /// Checks every parameter (the same checks the stages make when they are built).
    pub fn validate(&self) -> Result<(), EdgeError> {
        if !(1..=8).contains(&self.downsample) {
            return Err(EdgeError::Options(format!(
                "downsample = {} must be in 1..=8",
                self.downsample
            )));
        }
        // A plausible angular pixel size; the stages only use it to read pixel parameters.
        let pixel = 1e-3;
        Canny::new(self.canny)?;
        ChainTracer::new(self.chains, 1, 1)?;
        Splitter::new(self.split, pixel)?;
        Merger::new(self.merge, pixel)?;
        Ok(())
    }
}

/// What one run of the edge method did, stage by stage.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EdgeResult {
    pub canny: CannyResult,
    pub chains: ChainResult,
    pub split: SplitResult,
    pub merge: MergeResult,
}

/// The edge method for one calibration and image size.
#[derive(Debug, Clone)]
pub struct EdgeDetector {
    params: EdgeParams,
    /// The calibration at the working resolution.
    calibration: Calibration,
    /// Input image size.
    width: usize,
    height: usize,
    /// Reduction factor and working size.
    factor: usize,
    work_width: usize,
    work_height: usize,
    pixel_angle_rad: f64,
    canny: Canny,
    tracer: ChainTracer,
    splitter: Splitter,
    merger: Merger,
    /// The caller's mask as last seen, and its eroded copy (recomputed only when it changes).
    mask_seen: Vec<u8>,
    mask_eroded: Vec<u8>,
    mask_valid: bool,
    erode_tmp: Vec<u8>,
    erode_run: Vec<u16>,
    reduced: Vec<u8>,
    reduced_mask: Vec<u8>,
    edges: Vec<u8>,
    chains: Chains,
    sections: Vec<Section>,
}

impl EdgeDetector {
    /// Sets the method up for `width`×`height` images; the calibration is rescaled to that
    /// size when it is a uniform scaling of the calibration's own (and then to the working
    /// resolution, see [`EdgeParams::downsample`]).
    pub fn new(
        calibration: &Calibration,
        width: usize,
        height: usize,
        params: EdgeParams,
    ) -> Result<Self, EdgeError> {
        params.validate()?;
        let factor = params.downsample as usize;
        let (ww, wh) = (width / factor, height / factor);
        if ww < 3 || wh < 3 {
            return Err(EdgeError::Options(format!(
                "image {width}x{height} is too small"
            )));
        }
        let calibration = calibration
            .rescaled_to(height as u32, width as u32)
            .and_then(|c| c.reduced_cropped(factor as u32))
            .map_err(EdgeError::Calibration)?;
        let pixel_angle_rad = pixel_angle(&calibration);
        let n = ww * wh;
        let reduced = if factor > 1 { n } else { 0 };
        Ok(EdgeDetector {
            params,
            canny: Canny::new(params.canny)?,
            tracer: ChainTracer::new(params.chains, ww, wh)?,
            splitter: Splitter::new(params.split, pixel_angle_rad)?,
            merger: Merger::new(params.merge, pixel_angle_rad)?,
            calibration,
            width,
            height,
            factor,
            work_width: ww,
            work_height: wh,
            pixel_angle_rad,
            mask_seen: vec![0; width * height],
            mask_eroded: vec![0; n],
            mask_valid: false,
            erode_tmp: vec![0; n],
            erode_run: vec![0; ww],
            reduced: vec![0; reduced],
            reduced_mask: vec![0; reduced],
            edges: vec![0; n],
            chains: Chains::default(),
            sections: Vec::new(),
        })
    }

    pub fn params(&self) -> &EdgeParams {
        &self.params
    }

    /// The calibration at the working resolution (chain pixels are in its pixels).
    pub fn calibration(&self) -> &Calibration {
        &self.calibration
    }

    /// Input image size (width, height).
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Working resolution (width, height) and the reduction factor from the input: working
    /// pixel (r, c) covers input pixels f·r..f·r+f−1, so its centre is at
    /// (f·r + (f−1)/2, f·c + (f−1)/2).
    pub fn working_size(&self) -> (usize, usize, usize) {
        (self.work_width, self.work_height, self.factor)
    }

    /// The angle (radians) one pixel subtends, as used to read pixel tolerances.
    pub fn pixel_angle_rad(&self) -> f64 {
        self.pixel_angle_rad
    }

    /// Edge pixels of the last run (255 = edge), at the working resolution.
    pub fn edges(&self) -> &[u8] {
        &self.edges
    }

    /// Chains of the last run.
    pub fn chains(&self) -> &Chains {
        &self.chains
    }

    /// Great-circle sections of the last run.
    pub fn sections(&self) -> &[Section] {
        &self.sections
    }

    /// For each section of the last run, the index of its row in the output (or
    /// [`merge::NONE`]).
    pub fn assignment(&self) -> &[u32] {
        self.merger.assignment()
    }

    /// Runs the edge method on a Mono8 view (vegetation or grey image).
    pub fn process_view(
        &mut self,
        image: &ImageView<'_>,
        mask: &[u8],
        rows: &mut Vec<Row>,
    ) -> Result<EdgeResult, EdgeError> {
        if image.format != PixelFormat::Mono8 {
            return Err(EdgeError::Format(image.format));
        }
        if (image.width as usize, image.height as usize) != (self.width, self.height) {
            return Err(EdgeError::Size {
                what: "image",
                width: self.width,
                height: self.height,
                expected: self.width * self.height,
                actual: image.data.len(),
            });
        }
        self.process(image.data, mask, rows)
    }

    /// Runs the edge method on `image` (one byte per pixel, plants bright) where `mask` is
    /// nonzero, writing the rows (method edge, by decreasing support) to `rows`.
    pub fn process(
        &mut self,
        image: &[u8],
        mask: &[u8],
        rows: &mut Vec<Row>,
    ) -> Result<EdgeResult, EdgeError> {
        let (w, h) = (self.width, self.height);
        if mask.len() != w * h {
            return Err(EdgeError::Size {
                what: "mask",
                width: w,
                height: h,
                expected: w * h,
                actual: mask.len(),
            });
        }
        if image.len() != w * h {
            return Err(EdgeError::Size {
                what: "image",
                width: w,
                height: h,
                expected: w * h,
                actual: image.len(),
            });
        }
        self.update_mask(mask);
        let (ww, wh) = (self.work_width, self.work_height);
        let work: &[u8] = if self.factor > 1 {
            reduce(image, w, h, self.factor, &mut self.reduced);
            &self.reduced
        } else {
            image
        };
        let canny = self
            .canny
            .process(work, ww, wh, &self.mask_eroded, &mut self.edges)?;
        let canny_ref = &self.canny;
        let chains = self.tracer.trace_located(
            &self.edges,
            &self.calibration.model,
            |r, c| canny_ref.subpixel(r, c, ww),
            &mut self.chains,
        )?;
        let split =
            self.splitter
                .split(&self.chains.rays, &self.chains.ranges, &mut self.sections)?;
        let merge = self.merger.merge(&self.sections, rows)?;
        tracing::trace!(
            edges = canny.edge_pixels,
            chains = chains.kept,
            sections = split.sections,
            rows = merge.rows,
            "edge method"
        );
        Ok(EdgeResult {
            canny,
            chains,
            split,
            merge,
        })
    }

    /// Erodes the caller's mask by the margin, only when it differs from the last one.
    fn update_mask(&mut self, mask: &[u8]) {
        if self.mask_valid && self.mask_seen.as_slice() == mask {
            return;
        }
        self.mask_seen.copy_from_slice(mask);
        let work: &[u8] = if self.factor > 1 {
            reduce_mask(
                mask,
                self.width,
                self.height,
                self.factor,
                &mut self.reduced_mask,
            );
            &self.reduced_mask
        } else {
            mask
        };
        erode(
            work,
            self.work_width,
            self.work_height,
            MASK_MARGIN_PX,
            &mut self.erode_tmp,
            &mut self.erode_run,
            &mut self.mask_eroded,
        );
        self.mask_valid = true;
    }
}

/// Mean of `f`×`f` blocks (rounded), row by row with a 16-bit accumulator.
fn reduce(image: &[u8], width: usize, height: usize, f: usize, out: &mut [u8]) {
    let (ww, wh) = (width / f, height / f);
    let (norm, half) = ((f * f) as u32, (f * f / 2) as u32);
    for r in 0..wh {
        let dst = &mut out[r * ww..(r + 1) * ww];
        if f == 2 {
            let a = &image[2 * r * width..(2 * r + 1) * width];
            let b = &image[(2 * r + 1) * width..(2 * r + 2) * width];
            for (c, d) in dst.iter_mut().enumerate() {
                let s =
                    a[2 * c] as u16 + a[2 * c + 1] as u16 + b[2 * c] as u16 + b[2 * c + 1] as u16;
                *d = ((s + 2) >> 2) as u8;
            }
        } else {
            for (c, d) in dst.iter_mut().enumerate() {
                let mut s = 0u32;
                for dr in 0..f {
                    let row =
                        &image[(f * r + dr) * width + f * c..(f * r + dr) * width + f * c + f];
                    s += row.iter().map(|&v| v as u32).sum::<u32>();
                }
                *d = ((s + half) / norm) as u8;
            }
        }
    }
}

/// A reduced pixel is in the mask when all the pixels it covers are.
fn reduce_mask(mask: &[u8], width: usize, height: usize, f: usize, out: &mut [u8]) {
    let (ww, wh) = (width / f, height / f);
    for r in 0..wh {
        for c in 0..ww {
            let mut all = true;
            for dr in 0..f {
                let row = &mask[(f * r + dr) * width + f * c..(f * r + dr) * width + f * c + f];
                all &= row.iter().all(|&v| v != 0);
            }
            out[r * ww + c] = all as u8;
        }
    }
}

/// Square erosion of a mask (nonzero = in) by `margin` pixels; outside the image counts as
/// out. Output is 1 (in) or 0.
fn erode(
    mask: &[u8],
    width: usize,
    height: usize,
    margin: usize,
    tmp: &mut [u8],
    run: &mut [u16],
    out: &mut [u8],
) {
    let need = (margin + 1).min(u16::MAX as usize) as u16;
    // Horizontal: a pixel stays when the runs of "in" to its left and right both reach it.
    for r in 0..height {
        let src = &mask[r * width..(r + 1) * width];
        let dst = &mut tmp[r * width..(r + 1) * width];
        let mut count = 0u16;
        for (d, &m) in dst.iter_mut().zip(src) {
            count = if m != 0 { count.saturating_add(1) } else { 0 };
            *d = (count >= need) as u8;
        }
        let mut count = 0u16;
        for (d, &m) in dst.iter_mut().zip(src).rev() {
            count = if m != 0 { count.saturating_add(1) } else { 0 };
            *d &= (count >= need) as u8;
        }
    }
    // Vertical, with one running count per column, downwards then upwards.
    run.fill(0);
    for r in 0..height {
        let src = &tmp[r * width..(r + 1) * width];
        let dst = &mut out[r * width..(r + 1) * width];
        for ((d, &m), c) in dst.iter_mut().zip(src).zip(run.iter_mut()) {
            *c = if m != 0 { c.saturating_add(1) } else { 0 };
            *d = (*c >= need) as u8;
        }
    }
    run.fill(0);
    for r in (0..height).rev() {
        let src = &tmp[r * width..(r + 1) * width];
        let dst = &mut out[r * width..(r + 1) * width];
        for ((d, &m), c) in dst.iter_mut().zip(src).zip(run.iter_mut()) {
            *c = if m != 0 { c.saturating_add(1) } else { 0 };
            *d &= (*c >= need) as u8;
        }
    }
}

/// The angle one pixel subtends, averaged over the field of view: the mean of the radial and
/// tangential angular steps at radii spread over the mask (or the inscribed circle).
fn pixel_angle(cal: &Calibration) -> f64 {
    let m = &cal.model;
    let (r0, r1) = match cal.mask {
        Some(mk) => (mk.inner_radius_px, mk.outer_radius_px),
        None => (0.0, cal.inscribed_radius_px()),
    };
    let mut sum = 0.0;
    let mut count = 0usize;
    for k in 1..=16 {
        let r = r0 + (r1 - r0) * (k as f64 - 0.5) / 16.0;
        let (row, col) = (m.xc, m.yc + r);
        let p = m.cam2world(row, col);
        let radial = crate::sphere::axis_angle(&p, &m.cam2world(row, col + 1.0));
        let tangential = crate::sphere::axis_angle(&p, &m.cam2world(row + 1.0, col));
        let a = 0.5 * (radial + tangential);
        if a.is_finite() && a > 0.0 {
            sum += a;
            count += 1;
        }
    }
    if count == 0 {
        0.0
    } else {
        sum / count as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{ideal_fisheye, ideal_pal};
    use crate::sphere::axis_angle;
    use nalgebra::Vector3;

    #[test]
    fn erosion_shrinks_by_margin() {
        let (w, h) = (20, 15);
        let mut mask = vec![0u8; w * h];
        for r in 2..13 {
            for c in 3..17 {
                mask[r * w + c] = 1;
            }
        }
        let mut out = vec![0u8; w * h];
        erode(
            &mask,
            w,
            h,
            2,
            &mut vec![0; w * h],
            &mut vec![0; w],
            &mut out,
        );
        for r in 0..h {
            for c in 0..w {
                let inside = (4..11).contains(&r) && (5..15).contains(&c);
                assert_eq!(out[r * w + c] != 0, inside, "({r},{c})");
            }
        }
        erode(
            &mask,
            w,
            h,
            0,
            &mut vec![0; w * h],
            &mut vec![0; w],
            &mut out,
        );
        assert_eq!(out, mask);
    }

    #[test]
    fn pixel_angle_is_plausible() {
        let f = pixel_angle(&ideal_fisheye(2050, 2448).unwrap());
        // 92.5 degrees over 1022 pixels radially, a little less tangentially.
        assert!((0.0012..0.0017).contains(&f), "{f}");
        let p = pixel_angle(&ideal_pal(2050, 2448).unwrap());
        assert!((0.0010..0.0025).contains(&p), "{p}");
    }

    /// Draws bright bands into a grey image: each band lies between the great circles
    /// `bounds[k].0` and `bounds[k].1` (the thin wedge between the two planes).
    fn render(cal: &Calibration, bounds: &[(Vector3<f64>, Vector3<f64>)]) -> Vec<u8> {
        let m = &cal.model;
        let (w, h) = (m.width as usize, m.height as usize);
        let mut img = vec![30u8; w * h];
        for r in 0..h {
            for c in 0..w {
                let p = m.cam2world(r as f64, c as f64);
                if bounds.iter().any(|(a, b)| a.dot(&p) * b.dot(&p) < 0.0) {
                    img[r * w + c] = 200;
                }
            }
        }
        img
    }

    fn fov_mask(cal: &Calibration) -> Vec<u8> {
        let m = &cal.model;
        let (w, h) = (m.width as usize, m.height as usize);
        let mut mask = vec![0u8; w * h];
        for r in 0..h {
            for c in 0..w {
                mask[r * w + c] = cal.pixel_in_fov(r as f64, c as f64) as u8;
            }
        }
        mask
    }

    #[test]
    fn bands_give_two_boundaries_each() {
        let cal = ideal_fisheye(300, 360).unwrap();
        // Three rows along the direction (1, 0.2, -0.1); each is a band between two planes
        // through that direction, `half` either side of its centre plane.
        let along = Vector3::new(1.0, 0.2, -0.1).normalize();
        let half = 0.04;
        let side = along.cross(&Vector3::z()).normalize();
        let plane = |a: f64| {
            along
                .cross(&(side * a.sin() + Vector3::z() * a.cos()))
                .normalize()
        };
        let centres = [-0.6f64, 0.1, 0.8];
        let bounds: Vec<_> = centres
            .iter()
            .map(|&a| (plane(a - half), plane(a + half)))
            .collect();
        let img = render(&cal, &bounds);
        let mask = fov_mask(&cal);
        let opts = EdgeParams {
            canny: CannyParams {
                sigma: 1.4,
                ..Default::default()
            },
            ..Default::default()
        };
        let mut det = EdgeDetector::new(&cal, 360, 300, opts).unwrap();
        let mut rows = Vec::new();
        let res = det.process(&img, &mask, &mut rows).unwrap();
        assert!(res.canny.edge_pixels > 500, "{res:?}");
        // Each band has two boundaries, small circles at ±half from the centre circle; each
        // row found is close to one of those and perpendicular to the common direction.
        assert!(rows.len() >= 6, "{} rows: {res:?}", rows.len());
        // Where the bands converge near the vanishing point their edges meet and give short
        // stray sections; the rows with real support are the boundaries.
        let total: u32 = rows.iter().map(|r| r.support).sum();
        let mut stray = 0u32;
        let mut hit = vec![[0usize; 2]; bounds.len()];
        for row in &rows {
            let (k, side, d) = bounds
                .iter()
                .enumerate()
                .flat_map(|(k, (a, b))| {
                    [
                        (k, 0, axis_angle(a, &row.normal)),
                        (k, 1, axis_angle(b, &row.normal)),
                    ]
                })
                .min_by(|a, b| a.2.total_cmp(&b.2))
                .unwrap();
            if d < 0.005 {
                hit[k][side] += 1;
            } else {
                stray += row.support;
            }
        }
        assert!(
            stray * 10 < total,
            "{stray} of {total} points in stray rows"
        );
        assert!(
            hit.iter().flatten().all(|&n| n >= 1),
            "boundaries per row {hit:?}"
        );
        // Second run on the same frame gives the same rows.
        let mut again = Vec::new();
        det.process(&img, &mask, &mut again).unwrap();
        assert_eq!(rows, again);
    }

    #[test]
    fn wrong_sizes_and_formats_are_errors() {
        let cal = ideal_pal(100, 120).unwrap();
        let mut det = EdgeDetector::new(&cal, 120, 100, EdgeParams::default()).unwrap();
        let img = vec![0u8; 120 * 100];
        let mut rows = Vec::new();
        let e = det.process(&img, &img[1..], &mut rows).unwrap_err();
        assert!(e.to_string().contains("mask"), "{e}");
        let rgb = vec![0u8; 120 * 100 * 3];
        let view = ImageView::new(120, 100, PixelFormat::Rgb8, &rgb).unwrap();
        assert!(matches!(
            det.process_view(&view, &img, &mut rows),
            Err(EdgeError::Format(PixelFormat::Rgb8))
        ));
        assert!(EdgeDetector::new(&cal, 100, 100, EdgeParams::default()).is_err());
        let halve = EdgeParams {
            downsample: 2,
            ..Default::default()
        };
        let half = EdgeDetector::new(&cal, 60, 50, halve).unwrap();
        assert_eq!(half.calibration().size(), (25, 30));
        assert_eq!(half.working_size(), (30, 25, 2));
        // Sizes not a multiple of the factor leave the last partial block out.
        let odd = EdgeDetector::new(&ideal_pal(101, 121).unwrap(), 121, 101, halve).unwrap();
        assert_eq!(odd.working_size(), (60, 50, 2));
        assert_eq!(odd.calibration().size(), (50, 60));
        let e = EdgeDetector::new(
            &cal,
            120,
            100,
            EdgeParams {
                downsample: 0,
                ..Default::default()
            },
        );
        assert!(e.is_err());
    }

    #[test]
    fn reduce_averages_blocks_and_mask_needs_all() {
        let (w, h) = (4, 2);
        let img = [0u8, 4, 10, 10, 8, 4, 10, 11];
        let mut out = [0u8; 2];
        reduce(&img, w, h, 2, &mut out);
        assert_eq!(out, [4, 10]);
        let mask = [1u8, 1, 1, 0, 1, 1, 1, 1];
        reduce_mask(&mask, w, h, 2, &mut out);
        assert_eq!(out, [1, 0]);
        let img3 = [9u8; 9];
        let mut one = [0u8; 1];
        reduce(&img3, 3, 3, 3, &mut one);
        assert_eq!(one, [9]);
    }

    #[test]
    fn options_hold_only_the_support() {
        let o: EdgeOptions = toml::from_str("min_support = 12\n").unwrap();
        assert_eq!(o.min_support, 12);
        let p = EdgeParams::from_options(&o, 0.004);
        assert_eq!((p.merge.min_support, p.merge.max_angle_rad), (12, 0.004));
        assert_eq!(
            EdgeParams::from_options(&EdgeOptions::default(), REFERENCE_MAX_ANGLE_RAD),
            EdgeParams::default()
        );
        for removed in ["mask_margin_px = 2\n", "[canny]\nsigma = 1.0\n"] {
            let e = toml::from_str::<EdgeOptions>(removed).unwrap_err();
            assert!(e.to_string().contains("unknown field"), "{e}");
        }
    }
}
