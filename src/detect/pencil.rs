//! The pencil method: rows as the peaks of the vegetation's profile across the pencil of
//! great circles through the vanishing point.
//!
//! Owns the search for the vanishing point that makes the rows sharpest, and the rows read
//! off the profile there. Every great circle through a direction v is one plane of the pencil
//! around v, labelled by its angle ψ from the plane that holds v and the robot's down axis;
//! a ray p lies on the plane with tan ψ = (p·e₂)/(p·e₁), where e₁ is the down axis made
//! perpendicular to v and e₂ = v × e₁. For rows on flat ground seen from height h,
//! tan ψ = y/h with y the row's lateral offset, so each crop row is one value of tan ψ and the
//! rows of a field are a comb in it, whatever the lens. With the right v the weighted
//! histogram of tan ψ over the vegetation points has sharp peaks (the rows); with a wrong v
//! each row smears across many bins. The search maximises the histogram's contrast (its
//! energy above a local mean, relative to its total energy) over v within the expected tilt
//! and heading, on a coarse grid and then by halving steps. Every scale — the grid's step,
//! the histogram's bins, the local mean's width, the rows' separation — is stated in pixels
//! of the working image and converted through the calibration (the angular size of the
//! points' pixels), so that the same image through any focal length gives the same rows.

use super::comb::{fit_peak_comb_rolled, CombSearch, RolledComb, TanAxis};
use super::pose::RobotAxes;
use super::types::{DetectError, Method, Points, Row};
use crate::camera::Mounting;
use crate::sphere::Scatter;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// `[detector.pencil]`: the pencil method's options. Lengths are pixels of the working
/// image near the robot.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PencilOptions {
    /// Largest heading of the rows from the robot's forward axis searched (degrees).
    pub max_heading_deg: f64,
    /// At most this many rows are reported (strongest first).
    pub max_rows: usize,
    /// Rows closer than this are one row: about the narrowest row spacing in the image.
    pub min_separation_px: f64,
    /// Longest row spacing the comb searches (pixels across the rows near the robot).
    pub comb_max_period_px: f64,
}

impl Default for PencilOptions {
    fn default() -> Self {
        PencilOptions {
            max_heading_deg: 45.0,
            max_rows: 12,
            min_separation_px: 24.0,
            comb_max_period_px: 400.0,
        }
    }
}

/// Width of one bin of the profile across the rows (pixels).
const BIN_PX: f64 = 3.0;
/// Half-width of the local mean that the profile's contrast is measured against (about a
/// row spacing: structure finer than this counts as rows; pixels).
const REFERENCE_PX: f64 = 100.0;
/// Step of the coarse grid of candidate vanishing points (pixels).
const SEARCH_STEP_PX: f64 = 14.0;
/// At most this many points take part in the search (an even stride through them).
const SEARCH_POINTS: usize = 2000;
/// Smoothing of the profile before its peaks are read (Gaussian sigma, pixels).
const SMOOTH_PX: f64 = 6.0;
/// A peak is a row when it stands this fraction above the profile's local mean.
const MIN_PROMINENCE: f64 = 0.3;
/// A peak is a row only when its excess over the local mean is at least this fraction of
/// the strongest peak's.
const MIN_PEAK_FRACTION: f64 = 0.1;
/// Iterations of each row's refit on the points near it (see [`refine_row`]).
const REFINE_ITERATIONS: usize = 3;
/// Rows are taken within |tan ψ| ≤ this (lateral offset over camera height).
const MAX_TAN: f64 = 4.0;
/// The comb (equal spacing in tan ψ, [`super::comb`]) is used for the rows only when its
/// contrast is at least this: then peaks off it are not rows, and an empty tooth between
/// rows gets the weak peak there.
const COMB_MIN_CONTRAST: f64 = 0.25;
/// A weak peak on an empty tooth is a row when it stands this fraction above the profile's
/// local mean (the strong peaks need `MIN_PROMINENCE`).
const COMB_WEAK_PROMINENCE: f64 = 0.1;
/// The comb is searched at reference angles (around the vanishing point) within ± this of
/// the assumed ground normal's (degrees): a roll about the rows, or a wrong focal length,
/// bends the comb in tan ψ ([`super::comb::TanAxis`]).
const COMB_MAX_ROLL_DEG: f64 = 20.0;
/// Step of the comb's reference angles (degrees), before two halvings around the best.
const COMB_ROLL_STEP_DEG: f64 = 2.0;

/// The comb's search on a profile whose rows are at least `sep` bins apart: periods from
/// `sep` to `comb_max_period_px`, a peak on a tooth within half of `sep`.
fn comb_search(sep: usize, opts: &PencilOptions) -> CombSearch {
    CombSearch {
        min_period: sep as f64,
        max_period: opts.comb_max_period_px / BIN_PX,
        tolerance: (0.5 * sep as f64).max(1.0),
        ..CombSearch::default()
    }
}

impl PencilOptions {
    pub fn validate(&self) -> Result<(), DetectError> {
        let bad = |m: String| Err(DetectError::Options(m));
        if !(self.max_heading_deg > 0.0 && self.max_heading_deg <= 90.0) {
            return bad(format!(
                "pencil.max_heading_deg = {} must be within (0, 90]",
                self.max_heading_deg
            ));
        }
        if !(1..=256).contains(&self.max_rows) {
            return bad(format!(
                "pencil.max_rows = {} must be within 1..=256",
                self.max_rows
            ));
        }
        for (name, v) in [
            ("min_separation_px", self.min_separation_px),
            ("comb_max_period_px", self.comb_max_period_px),
        ] {
            if !(v.is_finite() && (BIN_PX..=10_000.0).contains(&v)) {
                return bad(format!(
                    "pencil.{name} = {v} must be within {BIN_PX}..=10000"
                ));
            }
        }
        Ok(())
    }
}

/// The scales of one image, in the units the search works in.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PencilScales {
    /// Pixels per radian where the points are (median over the points).
    pub pixels_per_rad: f64,
    /// One pixel across the rows, in tan ψ (median over the points, at the robot's forward
    /// direction).
    pub tan_per_px: f64,
}

/// What the pencil method found.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PencilResult {
    /// The vanishing point that makes the profile sharpest (camera frame).
    pub direction: Option<Vector3<f64>>,
    /// The profile's contrast there.
    pub contrast: f64,
    pub scales: PencilScales,
    /// Candidate directions scored.
    pub evaluated: usize,
    /// Rows appended.
    pub rows: usize,
}

/// The pencil method's buffers (allocated once, reused).
#[derive(Debug, Clone)]
pub struct PencilRows {
    opts: PencilOptions,
    max_tilt: f64,
    axes: RobotAxes,
    hist: Vec<f64>,
    smooth: Vec<f64>,
    prefix: Vec<f64>,
    kernel: Vec<f64>,
    tans: Vec<f64>,
    peaks: Vec<(f64, usize)>,
    sel: Vec<usize>,
    sc: PencilScales,
    grid: Vec<(f64, f64, f64)>,
    starts: Vec<(f64, f64, f64)>,
    evaluated: usize,
    /// The share of the points' weight the last histogram held.
    coverage: f64,
    /// The comb fitted by the last [`PencilRows::read_rows`], however weak.
    comb: Option<RolledComb>,
    /// The peaks as the comb takes them (weight, bin position), and rolled.
    comb_peaks: Vec<(f64, f64)>,
    rolled: Vec<(f64, f64)>,
    /// The teeth taken by the comb's selection, as (tooth, bin).
    teeth: Vec<(i64, usize)>,
}

/// A candidate vanishing point and the contrast of the profile around it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    pub direction: Vector3<f64>,
    pub contrast: f64,
}

/// The orthonormal frame of the pencil around `v`: e₁ (the down axis made perpendicular to
/// v) and e₂ = v × e₁. `None` when v is (anti)parallel to the down axis.
fn pencil_frame(v: &Vector3<f64>, down: &Vector3<f64>) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let e1 = down - v * down.dot(v);
    let n = e1.norm();
    if n < 1e-9 {
        return None;
    }
    let e1 = e1 / n;
    Some((e1, v.cross(&e1)))
}

impl PencilRows {
    /// `max_tilt_deg`: the vanishing point is searched within ± this angle of the robot's
    /// horizontal plane; the mounting says where that plane and the robot's forward axis are.
    pub fn new(
        opts: PencilOptions,
        max_tilt_deg: f64,
        mounting: &Mounting,
    ) -> Result<Self, DetectError> {
        opts.validate()?;
        Ok(PencilRows {
            opts,
            max_tilt: max_tilt_deg.to_radians(),
            axes: RobotAxes::new(mounting),
            hist: Vec::new(),
            smooth: Vec::new(),
            prefix: Vec::new(),
            kernel: Vec::new(),
            tans: Vec::new(),
            peaks: Vec::new(),
            sel: Vec::new(),
            sc: PencilScales::default(),
            grid: Vec::new(),
            starts: Vec::new(),
            evaluated: 0,
            coverage: 0.0,
            comb: None,
            comb_peaks: Vec::with_capacity(64),
            rolled: Vec::with_capacity(64),
            teeth: Vec::with_capacity(64),
        })
    }

    pub fn options(&self) -> &PencilOptions {
        &self.opts
    }

    /// The direction at azimuth `az` (from forward towards left) and elevation `el`.
    fn direction(&self, az: f64, el: f64) -> Vector3<f64> {
        self.axes.direction(az, el)
    }

    /// The image's scales from its points: `pixel_rad[i]` is the angular size of point i's
    /// pixel.
    fn scales(&mut self, rays: &[[f32; 3]], pixel_rad: &[f32]) -> PencilScales {
        let stride = rays.len().div_ceil(512).max(1);
        self.tans.clear();
        for &a in pixel_rad.iter().step_by(stride) {
            if a > 0.0 {
                self.tans.push(a as f64);
            }
        }
        let ppr = match median(&mut self.tans) {
            Some(m) if m > 0.0 => 1.0 / m,
            _ => return PencilScales::default(),
        };
        // d(tan ψ)/d(pixel across the pencil) = pixel angle · (1 + tan²ψ) / sin(angle to v).
        let v = self.axes.fwd;
        let Some((e1, e2)) = pencil_frame(&v, &-self.axes.up) else {
            return PencilScales::default();
        };
        self.tans.clear();
        for (r, &a) in rays.iter().zip(pixel_rad).step_by(stride) {
            let p = Vector3::new(r[0] as f64, r[1] as f64, r[2] as f64);
            let (x, y) = (p.dot(&e1), p.dot(&e2));
            if x <= 1e-6 {
                continue;
            }
            let t = y / x;
            let sin_v = (1.0 - p.dot(&v).powi(2)).max(1e-12).sqrt();
            self.tans.push(a as f64 * (1.0 + t * t) / sin_v);
        }
        PencilScales {
            pixels_per_rad: ppr,
            tan_per_px: quantile(&mut self.tans, NEAR_QUANTILE).unwrap_or(0.0),
        }
    }

    /// Fills `self.hist` with the weighted histogram of tan ψ around `v` (bins of `bw`,
    /// over ±max_tan), using every `stride`-th point. Returns false when v has no pencil.
    fn histogram(
        &mut self,
        v: &Vector3<f64>,
        rays: &[[f32; 3]],
        weights: &[f32],
        stride: usize,
        bw: f64,
    ) -> bool {
        let Some((e1, e2)) = pencil_frame(v, &-self.axes.up) else {
            return false;
        };
        let m = MAX_TAN;
        let nb = ((2.0 * m / bw).ceil() as usize).max(1);
        self.hist.clear();
        self.hist.resize(nb, 0.0);
        let (a, b) = (
            [e1.x as f32, e1.y as f32, e1.z as f32],
            [e2.x as f32, e2.y as f32, e2.z as f32],
        );
        let scale = (1.0 / bw) as f32;
        let (mf, nbf) = (m as f32, nb as f32);
        let (mut w_all, mut w_in) = (0.0f64, 0.0f64);
        for (r, &w) in rays.iter().zip(weights).step_by(stride) {
            w_all += w as f64;
            let x = a[0] * r[0] + a[1] * r[1] + a[2] * r[2];
            if x <= 1e-6 {
                continue;
            }
            let t = (b[0] * r[0] + b[1] * r[1] + b[2] * r[2]) / x;
            let k = (t + mf) * scale;
            if k >= 0.0 && k < nbf {
                self.hist[k as usize] += w as f64;
                w_in += w as f64;
            }
        }
        self.coverage = if w_all > 0.0 { w_in / w_all } else { 0.0 };
        true
    }

    /// The contrast of `self.hist`: Σ(h − local mean)² / Σh², the local mean over ±`half`
    /// bins.
    fn contrast(&mut self, half: usize) -> f64 {
        let h = &self.hist;
        let nb = h.len();
        self.prefix.clear();
        self.prefix.push(0.0);
        let mut acc = 0.0;
        for &x in h {
            acc += x;
            self.prefix.push(acc);
        }
        let (mut num, mut den) = (0.0, 0.0);
        for (i, &x) in h.iter().enumerate() {
            let lo = i.saturating_sub(half);
            let hi = (i + half + 1).min(nb);
            let mean = (self.prefix[hi] - self.prefix[lo]) / (2 * half + 1) as f64;
            num += (x - mean) * (x - mean);
            den += x * x;
        }
        if den > 0.0 {
            num / den
        } else {
            0.0
        }
    }

    /// The image's scales from its points (unit rays and the angular size of each ray's
    /// pixel); call before [`Self::candidate`] and [`Self::read_rows`] for each image.
    pub fn prepare(&mut self, rays: &[[f32; 3]], pixel_rad: &[f32]) -> PencilScales {
        self.sc = self.scales(rays, pixel_rad);
        self.sc
    }

    /// The vanishing point that makes the profile sharpest: the strongest local maximum of
    /// the profile's contrast on the coarse grid, refined by halving steps. `None` when the
    /// image has too few points or no scale.
    pub fn candidate(&mut self, rays: &[[f32; 3]], weights: &[f32]) -> Option<Candidate> {
        let sc = self.sc;
        if rays.len() < 16 || sc.pixels_per_rad <= 0.0 || sc.tan_per_px <= 0.0 {
            return None;
        }
        let stride = rays.len().div_ceil(SEARCH_POINTS).max(1);
        let step0 = SEARCH_STEP_PX / sc.pixels_per_rad;
        let az_max = self.opts.max_heading_deg.to_radians();
        let n_az = (az_max / step0).ceil() as i64;
        let n_el = (self.max_tilt / step0).ceil() as i64;
        let (w_az, w_el) = ((2 * n_az + 1) as usize, (2 * n_el + 1) as usize);
        let mut evaluated = 0;
        let mut grid = std::mem::take(&mut self.grid);
        grid.clear();
        for i in -n_az..=n_az {
            let az = (i as f64 * step0).clamp(-az_max, az_max);
            for j in -n_el..=n_el {
                let el = (j as f64 * step0).clamp(-self.max_tilt, self.max_tilt);
                grid.push((self.score(az, el, rays, weights, stride), az, el));
                evaluated += 1;
            }
        }
        // Local maxima of the grid (8 neighbours).
        self.starts.clear();
        for a in 0..w_az {
            for e in 0..w_el {
                let c = grid[a * w_el + e].0;
                let mut top = true;
                for da in -1i64..=1 {
                    for de in -1i64..=1 {
                        let (aa, ee) = (a as i64 + da, e as i64 + de);
                        if (da, de) == (0, 0)
                            || aa < 0
                            || ee < 0
                            || aa >= w_az as i64
                            || ee >= w_el as i64
                        {
                            continue;
                        }
                        if grid[aa as usize * w_el + ee as usize].0 > c {
                            top = false;
                        }
                    }
                }
                if top {
                    self.starts.push(grid[a * w_el + e]);
                }
            }
        }
        self.grid = grid;
        self.starts.sort_unstable_by(|a, b| b.0.total_cmp(&a.0));
        let &(c, az, el) = self.starts.first()?;
        let (c, az, el, n) = self.climb(c, az, el, step0, rays, weights, stride);
        self.evaluated = evaluated + n;
        Some(Candidate {
            direction: self.direction(az, el),
            contrast: c,
        })
    }

    /// Scores evaluated by the last [`Self::candidate`].
    pub fn evaluated(&self) -> usize {
        self.evaluated
    }

    /// The contrast of the profile around the direction (az, el).
    fn score(
        &mut self,
        az: f64,
        el: f64,
        rays: &[[f32; 3]],
        weights: &[f32],
        stride: usize,
    ) -> f64 {
        let bw = BIN_PX * self.sc.tan_per_px;
        let half = (REFERENCE_PX / BIN_PX).round().max(1.0) as usize;
        let v = self.direction(az, el);
        if !self.histogram(&v, rays, weights, stride, bw) {
            return -1.0;
        }
        self.contrast(half) * self.coverage
    }

    /// Halving steps from (az, el) while the contrast grows; returns the best and the
    /// number of scores evaluated.
    #[allow(clippy::too_many_arguments)]
    fn climb(
        &mut self,
        c0: f64,
        az0: f64,
        el0: f64,
        step0: f64,
        rays: &[[f32; 3]],
        weights: &[f32],
        stride: usize,
    ) -> (f64, f64, f64, usize) {
        let (mut c0, mut az0, mut el0) = (c0, az0, el0);
        let mut n = 0;
        let mut st = step0 / 2.0;
        while st > step0 / 40.0 {
            let (mut bc, mut ba, mut be) = (c0, az0, el0);
            for da in -2i32..=2 {
                for de in -2i32..=2 {
                    if da == 0 && de == 0 {
                        continue;
                    }
                    let az = az0 + da as f64 * st;
                    let el = (el0 + de as f64 * st).clamp(-self.max_tilt, self.max_tilt);
                    let c = self.score(az, el, rays, weights, stride);
                    n += 1;
                    if c > bc {
                        (bc, ba, be) = (c, az, el);
                    }
                }
            }
            (c0, az0, el0) = (bc, ba, be);
            st /= 2.0;
        }
        (c0, az0, el0, n)
    }

    /// The sharpest vanishing point and its rows: [`Self::prepare`], [`Self::candidate`],
    /// then [`Self::read_rows`] there.
    pub fn find(
        &mut self,
        points: &Points,
        rows: &mut Vec<Row>,
    ) -> Result<PencilResult, DetectError> {
        points.check("pencil")?;
        let (rays, weights) = (&points.rays, &points.weights);
        let scales = self.prepare(rays, &points.pixel_rad);
        let best = self.candidate(rays, weights);
        let mut res = PencilResult {
            scales,
            evaluated: self.evaluated,
            ..PencilResult::default()
        };
        if let Some(c) = best {
            res.direction = Some(c.direction);
            res.contrast = c.contrast;
            res.rows = self.read_rows(&c.direction, rays, weights, rows);
        }
        Ok(res)
    }

    /// The comb of the smoothed profile (periods from `sep` bins to
    /// `comb_max_period_px`).
    fn fit_comb(&mut self, sep: usize, axis: &TanAxis) -> Option<RolledComb> {
        let search = comb_search(sep, &self.opts);
        self.comb_peaks.clear();
        self.comb_peaks
            .extend(self.peaks.iter().map(|&(e, i)| (e.sqrt(), i as f64 + 0.5)));
        fit_peak_comb_rolled(
            &self.comb_peaks,
            axis,
            &search,
            COMB_MAX_ROLL_DEG.to_radians(),
            COMB_ROLL_STEP_DEG.to_radians(),
            &mut self.rolled,
        )
    }

    /// Fills `self.sel` from `self.peaks` (strongest first) with the comb: each peak within
    /// the comb's tolerance of a tooth is that tooth's row (the strongest one only); peaks off
    /// the comb are dropped; each empty tooth between the outermost rows gets the highest
    /// local maximum of the profile within the tolerance of it, when that stands
    /// `comb_weak_prominence` above the local mean over ±`wide` bins (`self.prefix` holds the
    /// smoothed profile's prefix sums).
    fn select_on_comb(&mut self, rc: &RolledComb, axis: &TanAxis, sep: usize, wide: usize) {
        let comb = &rc.comb;
        let tol = comb_search(sep, &self.opts).tolerance;
        let (mut kmin, mut kmax) = (i64::MAX, i64::MIN);
        let mut taken = std::mem::take(&mut self.teeth);
        taken.clear();
        for &(_, i) in &self.peaks {
            if taken.len() >= self.opts.max_rows {
                break;
            }
            let (k, d) = comb.nearest_tooth(axis.to_rolled(i as f64 + 0.5, rc.roll));
            if d <= tol && taken.iter().all(|t| t.0 != k) {
                taken.push((k, i));
                kmin = kmin.min(k);
                kmax = kmax.max(k);
            }
        }
        let nb = self.smooth.len();
        let mut k = kmin;
        while k < kmax && taken.len() < self.opts.max_rows {
            k += 1;
            if taken.iter().any(|t| t.0 == k) {
                continue;
            }
            let c = comb.tooth(k);
            let lo = axis.from_rolled(c - tol, rc.roll).floor().max(1.0) as usize;
            let hi = (axis.from_rolled(c + tol, rc.roll).ceil().max(0.0) as usize)
                .min(nb.saturating_sub(1));
            let mut best: Option<usize> = None;
            for i in lo..hi {
                let x = self.smooth[i];
                if x >= self.smooth[i - 1]
                    && x > self.smooth[i + 1]
                    && best.is_none_or(|b| x > self.smooth[b])
                {
                    best = Some(i);
                }
            }
            let Some(i) = best else { continue };
            let a = i.saturating_sub(wide);
            let b = (i + wide + 1).min(nb);
            let mean = (self.prefix[b] - self.prefix[a]) / (b - a) as f64;
            if self.smooth[i] > mean * (1.0 + COMB_WEAK_PROMINENCE) {
                taken.push((k, i));
            }
        }
        self.sel.extend(taken.iter().map(|t| t.1));
        self.teeth = taken;
    }

    /// The smoothed profile's peaks into `self.peaks` (excess over the local mean, bin),
    /// strongest first: its local maxima standing `MIN_PROMINENCE` above the mean over ±`wide`
    /// bins, and at least `MIN_PEAK_FRACTION` of the strongest's excess. Leaves the profile's
    /// prefix sums in `self.prefix`.
    fn profile_peaks(&mut self, wide: usize) {
        let nb = self.smooth.len();
        self.prefix.clear();
        self.prefix.push(0.0);
        let mut acc = 0.0;
        for &x in &self.smooth {
            acc += x;
            self.prefix.push(acc);
        }
        self.peaks.clear();
        for i in 1..nb.saturating_sub(1) {
            let x = self.smooth[i];
            if !(x >= self.smooth[i - 1] && x > self.smooth[i + 1]) {
                continue;
            }
            let lo = i.saturating_sub(wide);
            let hi = (i + wide + 1).min(nb);
            let mean = (self.prefix[hi] - self.prefix[lo]) / (hi - lo) as f64;
            if x > mean * (1.0 + MIN_PROMINENCE) && x > 0.0 {
                self.peaks.push((x - mean, i));
            }
        }
        self.peaks
            .sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        let floor = self.peaks.first().map_or(0.0, |p| p.0) * MIN_PEAK_FRACTION;
        self.peaks.retain(|p| p.0 >= floor);
    }

    /// The rows' bins into `self.sel`: on the peaks' comb when it is strong enough
    /// ([`Self::select_on_comb`]), else the strongest peaks at least `sep` bins apart.
    fn select_rows(&mut self, sep: usize, wide: usize, axis: &TanAxis) {
        self.sel.clear();
        self.comb = self.fit_comb(sep, axis);
        tracing::debug!(
            comb = ?self.comb,
            peaks = ?self.peaks.iter().map(|p| p.1).collect::<Vec<_>>(),
            "pencil profile's comb"
        );
        match self.comb.filter(|c| c.comb.contrast >= COMB_MIN_CONTRAST) {
            Some(comb) => self.select_on_comb(&comb, axis, sep, wide),
            None => {
                for &(_, i) in &self.peaks {
                    if self.sel.len() >= self.opts.max_rows {
                        break;
                    }
                    if self.sel.iter().all(|&j| i.abs_diff(j) >= sep) {
                        self.sel.push(i);
                    }
                }
            }
        }
    }

    /// Reads the rows off the profile around `v`: smoothed, the local maxima standing
    /// `min_prominence` above the local mean, at least `min_separation_px` apart, strongest
    /// first; each row's position the weighted mean of its peak.
    pub fn read_rows(
        &mut self,
        v: &Vector3<f64>,
        rays: &[[f32; 3]],
        weights: &[f32],
        rows: &mut Vec<Row>,
    ) -> usize {
        let bw = BIN_PX * self.sc.tan_per_px;
        if bw <= 0.0 {
            return 0;
        }
        if !self.histogram(v, rays, weights, 1, bw) {
            return 0;
        }
        let sigma = SMOOTH_PX / BIN_PX;
        gaussian_1d(&self.hist, sigma, &mut self.kernel, &mut self.smooth);
        let sep = (self.opts.min_separation_px / BIN_PX).round().max(1.0) as usize;
        let wide = 2 * sep;
        self.profile_peaks(wide);
        let axis = TanAxis {
            start: -MAX_TAN,
            bin: bw,
        };
        self.select_rows(sep, wide, &axis);
        let Some((e1, e2)) = pencil_frame(v, &-self.axes.up) else {
            return 0;
        };
        let nb = self.smooth.len();
        let m = MAX_TAN;
        let start = rows.len();
        for k in 0..self.sel.len() {
            let i = self.sel[k];
            let lo = i.saturating_sub(sep / 2);
            let hi = (i + sep / 2 + 1).min(nb);
            let (mut sw, mut sx) = (0.0, 0.0);
            for j in lo..hi {
                sw += self.smooth[j];
                sx += self.smooth[j] * (j as f64 + 0.5);
            }
            let centre = if sw > 0.0 { sx / sw } else { i as f64 + 0.5 };
            let t = centre * bw - m;
            let psi = t.atan();
            let d = e1 * psi.cos() + e2 * psi.sin();
            let n = v.cross(&d).normalize();
            // The peak's half-width as an angle around v (tan ψ changes by bw per bin).
            let band = 0.5 * sep as f64 * bw / (1.0 + t * t);
            let (n, support) = refine_row(&n, v, rays, weights, band, REFINE_ITERATIONS);
            rows.push(Row {
                normal: crate::sphere::canonical(&n),
                method: Method::Pencil,
                support,
                width_rad: 0.0,
            });
        }
        rows.len() - start
    }
}

/// Refits a row's great circle `n0` on the points within `band` (radians, as an angle around
/// the vanishing point `v`, so the band keeps its width in the image from near to far): the
/// weighted least-squares normal, `iterations` times, the band narrowing to 2.5 times the
/// points' RMS angle but never below a quarter of its first width. The fit is free to leave
/// v: each row's own direction is what the vanishing stage then reconciles. Returns the
/// normal and the number of points in the last band (n0 and 0 when the fit fails).
fn refine_row(
    n0: &Vector3<f64>,
    v: &Vector3<f64>,
    rays: &[[f32; 3]],
    weights: &[f32],
    band: f64,
    iterations: usize,
) -> (Vector3<f64>, u32) {
    let mut n = *n0;
    let mut tol = band;
    let floor = 0.25 * band;
    let mut support = 0u32;
    for _ in 0..iterations.max(1) {
        let s_tol = tol.sin();
        let mut sc = Scatter::new();
        let (mut sum_d2, mut sum_w) = (0.0, 0.0);
        support = 0;
        for (r, &w) in rays.iter().zip(weights) {
            let p = Vector3::new(r[0] as f64, r[1] as f64, r[2] as f64);
            let sin_v = (1.0 - p.dot(v).powi(2)).max(0.0).sqrt();
            if sin_v < 1e-3 {
                continue;
            }
            let d = n.dot(&p).abs() / sin_v;
            if d < s_tol {
                sc.add(&p, w as f64);
                sum_d2 += w as f64 * d * d;
                sum_w += w as f64;
                support += 1;
            }
        }
        let Some(fit) = sc.fit() else {
            return (*n0, 0);
        };
        if fit.degeneracy > 0.5 {
            return (*n0, 0);
        }
        n = fit.normal;
        let rms = if sum_w > 0.0 {
            (sum_d2 / sum_w).sqrt().asin()
        } else {
            tol
        };
        tol = (2.5 * rms).clamp(floor, tol);
    }
    (n, support)
}

/// The median of `v` (reordered), `None` when empty.
fn median(v: &mut [f64]) -> Option<f64> {
    quantile(v, 0.5)
}

/// The `q`-quantile of `v` (reordered), `None` when empty.
fn quantile(v: &mut [f64], q: f64) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let k = ((v.len() - 1) as f64 * q).round() as usize;
    let (_, m, _) = v.select_nth_unstable_by(k, f64::total_cmp);
    Some(*m)
}

/// The pixel scale across the rows is taken where they are best resolved: the points of the
/// nearest quarter (the smallest change of tan ψ per pixel).
const NEAR_QUANTILE: f64 = 0.25;

/// Gaussian smoothing of `x` (sigma in bins, zero beyond the ends) into `out`.
fn gaussian_1d(x: &[f64], sigma: f64, kernel: &mut Vec<f64>, out: &mut Vec<f64>) {
    let r = (3.0 * sigma).ceil().max(1.0) as usize;
    kernel.clear();
    for i in 0..=2 * r {
        let d = i as f64 - r as f64;
        kernel.push((-0.5 * d * d / (sigma * sigma).max(1e-12)).exp());
    }
    let sum: f64 = kernel.iter().sum();
    for k in kernel.iter_mut() {
        *k /= sum;
    }
    out.clear();
    out.resize(x.len(), 0.0);
    for (i, o) in out.iter_mut().enumerate() {
        let mut acc = 0.0;
        for (j, &k) in kernel.iter().enumerate() {
            let idx = i as isize + j as isize - r as isize;
            if idx >= 0 && (idx as usize) < x.len() {
                acc += k * x[idx as usize];
            }
        }
        *o = acc;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A seeded generator for the test fields (xorshift64*).
    struct Rng(u64);

    impl Rng {
        fn stream(seed: u64, _: u64) -> Self {
            Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
        }
        fn range(&mut self, lo: f64, hi: f64) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            let u = (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64;
            lo + (hi - lo) * u
        }
    }

    /// Rays (camera frame) of plants on rows at lateral offsets `rows_m` (robot frame, camera
    /// 1 m high looking down with the default mounting), the rows turned by `yaw` from the
    /// robot's forward axis, plus uniformly scattered weeds.
    fn field(rows_m: &[f64], yaw: f64, weeds: usize, seed: u64) -> Vec<[f32; 3]> {
        let m = Mounting::default();
        let cam_from_robot = m.robot_from_camera().inverse();
        let mut rng = Rng::stream(seed, 0);
        let mut out = Vec::new();
        let (c, s) = (yaw.cos(), yaw.sin());
        let mut push = |x: f64, y: f64| {
            let p = cam_from_robot * Vector3::new(x, y, -1.0).normalize();
            out.push([p.x as f32, p.y as f32, p.z as f32]);
        };
        for &y0 in rows_m {
            for i in 0..400 {
                let along = -4.0 + 8.0 * i as f64 / 400.0;
                let across = y0 + rng.range(-0.03, 0.03);
                push(along * c - across * s, along * s + across * c);
            }
        }
        for _ in 0..weeds {
            push(rng.range(-4.0, 4.0), rng.range(-3.0, 3.0));
        }
        out
    }

    fn run(rays: &[[f32; 3]]) -> (PencilResult, Vec<Row>) {
        let mut p = PencilRows::new(PencilOptions::default(), 15.0, &Mounting::default()).unwrap();
        let points = Points {
            rays: rays.to_vec(),
            weights: vec![1.0f32; rays.len()],
            pixel_rad: vec![1.0f32 / 300.0; rays.len()],
        };
        let mut rows = Vec::new();
        let r = p.find(&points, &mut rows).unwrap();
        (r, rows)
    }

    #[test]
    fn finds_the_rows_direction_and_each_row() {
        let yaw = 0.2f64;
        let offsets = [-1.25, -0.75, -0.25, 0.25, 0.75, 1.25];
        let rays = field(&offsets, yaw, 800, 3);
        let (r, rows) = run(&rays);
        let m = Mounting::default();
        let truth = m.robot_from_camera().inverse() * Vector3::new(yaw.cos(), yaw.sin(), 0.0);
        let v = r.direction.expect("a vanishing point");
        let err = crate::sphere::axis_angle(&v, &truth);
        assert!(err < 0.01, "vanishing point off by {err} rad");
        assert_eq!(rows.len(), offsets.len(), "{rows:?}");
        // Each true row (a plane through the truth direction and its ground line) is found.
        for &y0 in &offsets {
            let p = m.robot_from_camera().inverse()
                * Vector3::new(-y0 * yaw.sin(), y0 * yaw.cos(), -1.0).normalize();
            let n = truth.cross(&p).normalize();
            let best = rows
                .iter()
                .map(|r| crate::sphere::axis_angle(&r.normal, &n))
                .fold(f64::INFINITY, f64::min);
            assert!(
                best < 0.01,
                "row at {y0} m: nearest found row {best} rad away"
            );
        }
        assert!(rows
            .iter()
            .all(|r| r.method == Method::Pencil && r.support > 100));
    }

    #[test]
    fn weeds_alone_give_no_rows_direction_worth_a_row() {
        let rays = field(&[], 0.0, 3000, 5);
        let (r, rows) = run(&rays);
        // Uniform weeds: whatever direction wins, the profile has no prominent peaks.
        assert!(r.contrast < 0.2, "contrast {} on weeds", r.contrast);
        assert!(rows.len() <= 2, "{} rows on weeds", rows.len());
    }

    #[test]
    fn bad_options_are_named() {
        for (o, key) in [
            (
                PencilOptions {
                    max_heading_deg: 0.0,
                    ..PencilOptions::default()
                },
                "pencil.max_heading_deg",
            ),
            (
                PencilOptions {
                    max_rows: 0,
                    ..PencilOptions::default()
                },
                "pencil.max_rows",
            ),
            // a separation too fine to finish is refused by name
            (
                PencilOptions {
                    min_separation_px: 1e-6,
                    ..PencilOptions::default()
                },
                "pencil.min_separation_px",
            ),
            (
                PencilOptions {
                    comb_max_period_px: f64::NAN,
                    ..PencilOptions::default()
                },
                "pencil.comb_max_period_px",
            ),
        ] {
            let e = PencilRows::new(o, 15.0, &Mounting::default()).unwrap_err();
            assert!(e.to_string().contains(key), "{e}");
        }
    }

    #[test]
    fn mismatched_buffers_are_an_error() {
        let mut p = PencilRows::new(PencilOptions::default(), 15.0, &Mounting::default()).unwrap();
        let mut rows = Vec::new();
        let mismatched = Points {
            rays: vec![[0.0, 0.0, -1.0]],
            pixel_rad: vec![1.0],
            ..Points::default()
        };
        assert!(p.find(&mismatched, &mut rows).is_err());
    }
}
