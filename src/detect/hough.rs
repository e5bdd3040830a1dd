//! The spherical Hough transform for rows (paper II-D, eq. 3–4), with the line-fitting step.
//!
//! Owns the accumulator over the normals n(φ, θ) = (sin φ cos θ, sin φ sin θ, cos φ) of great
//! circles, its voting, the peaks and their refinement. A normal and its opposite are the same
//! row, so the accumulator covers φ ∈ [0, π) × θ ∈ [0, π) once (90 × 90 cells of 2° at the GC2450C's
//! angular resolution, finer for finer lenses: [`super::scale`]);
//! it wraps in φ at the poles ((−ε, θ) ≡ (π − ε, θ)) and in θ with a flip ((φ, θ + π) ≡ (π − φ, θ)).
//!
//! Each ray p votes for every great circle through it: for θ, eq. 4 gives
//! φ(θ) = atan2(−p_z, p_x cos θ + p_y sin θ). The curve is rasterised column by column (φ at both
//! edges of each θ column and every cell in between), so a ray casts one vote in every cell
//! its curve crosses even where the curve is steep — near the poles the paper's one-vote-per-θ
//! sampling would miss cells. Peaks are local maxima under non-maximum suppression; each is refined by
//! fitting the normal to the rays near its great circle ([`Scatter`], the smallest eigenvector
//! of their weighted scatter matrix), iterated with a tolerance that shrinks to three times
//! the RMS distance of the points; rows that converge onto the same great circle are merged.

use super::types::{DetectError, Method, Row};
use crate::sphere::{axis_angle, canonical, from_phi_theta, Scatter};
use multiversion::multiversion;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::f32::consts::PI as PI32;

/// `[detector.hough]`: the row Hough transform's options.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HoughOptions {
    /// At most this many rows are reported, strongest first: raise it when the lens sees
    /// more rows than 12 (a narrow row spacing).
    pub max_rows: usize,
    /// A row needs this many kept points: lower it for sparse or small plants, raise it
    /// when weeds make rows.
    pub min_support: u32,
}

impl HoughOptions {
    pub fn validate(&self) -> Result<(), DetectError> {
        if (1..=256).contains(&self.max_rows) {
            Ok(())
        } else {
            Err(DetectError::Options(format!(
                "hough.max_rows = {} must be 1..=256",
                self.max_rows
            )))
        }
    }
}

impl Default for HoughOptions {
    fn default() -> Self {
        HoughOptions {
            max_rows: 12,
            min_support: 40,
        }
    }
}

/// The accumulator's cells along φ and along θ (0..π each) at the reference angular
/// resolution: 2° cells ([`super::scale`]).
pub const REFERENCE_BINS: usize = 90;
/// The refinement never narrows its band below this half-width (degrees) at the reference
/// angular resolution.
pub const REFERENCE_MIN_TOLERANCE_DEG: f64 = 0.15;
/// Refined rows closer than this (degrees between normals) at the reference angular
/// resolution are one row.
pub const REFERENCE_MERGE_ANGLE_DEG: f64 = 1.0;

/// The transform's parameters: the options, and the angular scales the calibration's
/// field of view sets ([`super::scale`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HoughParams {
    /// Accumulator cells along φ and along θ (θ + π is the same row).
    pub bins: usize,
    /// The refinement's narrowest band (half-width, degrees).
    pub min_tolerance_deg: f64,
    /// Refined rows closer than this (degrees between normals) are one row.
    pub merge_angle_deg: f64,
    pub max_rows: usize,
    pub min_support: u32,
    /// At most about this many points vote (an even stride through the kept points; 0: all
    /// of them); the refinement fits every point. Voting is the transform's cost per point,
    /// and the peaks need fewer points than the fits do. `min_support` counts in kept
    /// points: a peak needs `min_support / stride` votes. 3000.
    pub vote_points: usize,
    /// Peaks below this fraction of the highest peak are dropped (0.1).
    pub min_peak_fraction: f64,
    /// Half-size (cells) of the non-maximum-suppression window (2).
    pub nms_radius: usize,
    /// Iterations of the refinement fit (6).
    pub refine_iterations: usize,
    /// A row whose points do not single out a great circle (ratio of the two smallest
    /// eigenvalues of their scatter matrix above this) is dropped (0.2).
    pub max_degeneracy: f64,
}

impl HoughParams {
    /// The parameters of `opts` with the angular scales at `angle_factor` times their
    /// reference values.
    pub fn new(opts: &HoughOptions, angle_factor: f64) -> Self {
        HoughParams {
            bins: super::scale::scaled_bins(REFERENCE_BINS, angle_factor),
            min_tolerance_deg: REFERENCE_MIN_TOLERANCE_DEG * angle_factor,
            merge_angle_deg: REFERENCE_MERGE_ANGLE_DEG * angle_factor,
            max_rows: opts.max_rows,
            min_support: opts.min_support,
            vote_points: 3_000,
            min_peak_fraction: 0.1,
            nms_radius: 2,
            refine_iterations: 6,
            max_degeneracy: 0.2,
        }
    }

    pub fn validate(&self) -> Result<(), DetectError> {
        let bad = |m: String| Err(DetectError::Options(m));
        if !(4..=2048).contains(&self.bins) {
            return bad(format!(
                "hough accumulator {0}x{0} must have 4..=2048 cells on each side",
                self.bins
            ));
        }
        if self.max_rows == 0 || self.max_rows > 256 {
            return bad(format!(
                "hough.max_rows = {} must be 1..=256",
                self.max_rows
            ));
        }
        let t = self.min_tolerance_deg;
        if !(t > 0.0 && t < 10.0) {
            return bad(format!(
                "the Hough refinement's narrowest band {t}° must be within (0, 10): angle_scale too large"
            ));
        }
        Ok(())
    }
}

impl Default for HoughParams {
    fn default() -> Self {
        HoughParams::new(&HoughOptions::default(), 1.0)
    }
}

/// Statistics of one run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct HoughResult {
    /// Points that voted.
    pub points: usize,
    /// Peaks refined.
    pub peaks: usize,
    /// Highest accumulator cell.
    pub max_votes: u32,
    /// Rows appended.
    pub rows: usize,
}

/// The row Hough transform with its accumulator and scratch buffers (allocated once).
#[derive(Debug, Clone)]
pub struct HoughRows {
    opts: HoughParams,
    /// cos θ and sin θ at the θ column edges (theta_bins + 1 values).
    cos_e: Vec<f32>,
    sin_e: Vec<f32>,
    /// φ cell at each column edge for the current ray.
    edge: Vec<i32>,
    /// Votes, column-major: acc[k * phi_bins + j] for θ column k, φ cell j.
    acc: Vec<u32>,
    /// The votes as differences along each column (phi_bins + 1 per column).
    diff: Vec<u32>,
    /// Every how many kept points one voted in the last run.
    vote_stride: usize,
    peaks: Vec<(u32, u32)>,
    /// Points near the refined peak (ray, weight), converted once.
    sel: Vec<([f64; 3], f64)>,
    /// The refinement's first selection: indices of the points near the peak's circle.
    sel_index: Vec<u32>,
    /// Refined candidates with the half-width (radians) of their final band.
    found: Vec<(Row, f64)>,
    /// Per point: claimed by an accepted row.
    owned: Vec<bool>,
    /// Band half-widths (radians) of the rows appended by the last run, in their order.
    bands: Vec<f64>,
    /// Non-maximum-suppression window offsets, nearest first (most cells lose to a neighbour).
    nms: Vec<(isize, isize)>,
    /// The search window of the next runs ([`HoughRows::set_window`]), if any.
    window: Option<Window>,
}

/// Only great circles through (near) a known vanishing point: their normals lie in a band
/// around the great circle perpendicular to it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Window {
    /// The vanishing point (unit, camera frame).
    vp: Vector3<f64>,
    /// Sine of the band's half-width for voting (the window widened by the cells the
    /// peaks' non-maximum suppression looks at, so that cells inside see the same votes and
    /// neighbours as in the full transform).
    sin_vote: f64,
    /// Sine of the band's half-width a peak's cell centre must lie within.
    sin_peak: f64,
}

/// atan2 for f32 with an error below 1e-5 rad (enough to pick a 2° cell), branch-free so
/// that loops over it vectorise (and random signs cost no mispredicted branches).
#[inline]
pub fn fast_atan2(y: f32, x: f32) -> f32 {
    let r = atan2_upper(y.abs(), x);
    if y < 0.0 {
        -r
    } else {
        r
    }
}

/// atan2(y, x) for y ≥ 0 (result in [0, π]), branch-free so that loops over it vectorise;
/// the same polynomial as [`fast_atan2`].
#[inline(always)]
fn atan2_upper(y: f32, x: f32) -> f32 {
    let ax = x.abs();
    let mn = ax.min(y);
    let mx = ax.max(y).max(f32::MIN_POSITIVE);
    let a = mn / mx;
    let s = a * a;
    let r = ((((-0.013_480_47 * s + 0.057_477_314) * s - 0.121_239_07) * s + 0.195_635_93) * s
        - 0.332_994_96)
        * s
        * a
        + a;
    let r = if y > ax {
        std::f32::consts::FRAC_PI_2 - r
    } else {
        r
    };
    if x < 0.0 {
        PI32 - r
    } else {
        r
    }
}

/// ⌊v⌋ for v in [0, 2²²) (NaN or larger values give some value in that range's images),
/// by the float's own rounding: adding 2²³ leaves the integer nearest to v in the
/// mantissa's low bits, and one less when that rounded up. Unlike `as i32`, whose
/// saturation keeps the conversion scalar, this vectorises with the loop around it.
#[inline(always)]
fn floor_small(v: f32) -> i32 {
    const MAGIC: f32 = 8_388_608.0;
    let t = v + MAGIC;
    let nearest = (t.to_bits() as i32).wrapping_sub(MAGIC.to_bits() as i32);
    nearest - ((t - MAGIC > v) as i32)
}

/// The φ cell of a ray's curve φ(θ) = atan2(y, px cos θ + py sin θ) (`ray`: y, px, py) at
/// each column edge whose cos θ and sin θ are given: ⌊min(φ·scale, pmax)⌋ (`cell`: scale,
/// pmax). Compiled also for AVX2, chosen at run time where the processor has it (the same
/// cells: no operation changes, only the lanes' width).
#[multiversion(targets("x86_64+avx2"))]
fn curve_cells(ray: [f32; 3], cos_e: &[f32], sin_e: &[f32], cell: [f32; 2], edges: &mut [i32]) {
    let [y, px, py] = ray;
    let [scale, pmax] = cell;
    for ((e, &c), &s) in edges.iter_mut().zip(cos_e).zip(sin_e) {
        *e = floor_small((atan2_upper(y, px * c + py * s) * scale).min(pmax));
    }
}

impl HoughRows {
    pub fn new(opts: HoughParams) -> Result<Self, DetectError> {
        opts.validate()?;
        let t = opts.bins;
        let (cos_e, sin_e) = (0..=t)
            .map(|k| {
                let th = k as f64 * std::f64::consts::PI / t as f64;
                (th.cos() as f32, th.sin() as f32)
            })
            .unzip();
        Ok(HoughRows {
            opts,
            cos_e,
            sin_e,
            edge: vec![0; t + 1],
            acc: vec![0; t * opts.bins],
            diff: vec![0; t * (opts.bins + 1)],
            vote_stride: 1,
            peaks: Vec::with_capacity(t * opts.bins),
            sel: Vec::new(),
            sel_index: Vec::new(),
            found: Vec::with_capacity(4 * opts.max_rows),
            owned: Vec::new(),
            bands: Vec::with_capacity(opts.max_rows),
            nms: {
                let r = opts.nms_radius as isize;
                let mut v: Vec<(isize, isize)> = (-r..=r)
                    .flat_map(|a| (-r..=r).map(move |b| (a, b)))
                    .filter(|&o| o != (0, 0))
                    .collect();
                v.sort_by_key(|&(a, b)| a * a + b * b);
                v
            },
            window: None,
        })
    }

    /// Narrows the next runs to rows whose vanishing point lies within `half_width_rad` of
    /// `vp` (unit, camera frame; sign free), or lifts the narrowing (`None`). A ray then
    /// votes only in the accumulator columns where its curve passes through the band of
    /// normals perpendicular to such a vanishing point, and only peaks in that band become
    /// rows. Cells inside the band get the same votes as without a window.
    pub fn set_window(&mut self, window: Option<(&Vector3<f64>, f64)>) {
        let cell = std::f64::consts::PI / self.opts.bins as f64;
        let diag = std::f64::consts::SQRT_2 * cell;
        self.window = window.map(|(vp, w)| Window {
            vp: vp.normalize(),
            sin_vote: (w + (self.opts.nms_radius as f64 + 1.0) * diag)
                .min(std::f64::consts::FRAC_PI_2)
                .sin(),
            sin_peak: (w + diag).min(std::f64::consts::FRAC_PI_2).sin(),
        });
    }

    /// The accumulator columns (first, count; wrapping past the last) where the curve of
    /// `ray` passes through the window's band, or `None` for every column. The normals
    /// perpendicular to the ray form a great circle n(t) = cos t·a + sin t·b with
    /// a = ray × vp / |ray × vp| and b = ray × a, on which |n·vp| = |sin t|·|ray × vp|: the
    /// band holds the arc |t| ≤ δ = asin(sin w / |ray × vp|). Each column holds one of the
    /// circle's normals (up to sign) and θ (mod π) runs monotonically along it, so the arc's
    /// columns are those between its ends' θ on the side that holds a's, widened by one.
    /// An arc that passes near a pole of the accumulator (where θ turns fast) takes them all.
    fn window_columns(&self, ray: &[f32; 3]) -> Option<(usize, usize)> {
        use std::f64::consts::PI;
        let w = self.window.as_ref()?;
        let t = self.opts.bins;
        let p = Vector3::new(ray[0] as f64, ray[1] as f64, ray[2] as f64).normalize();
        let c = p.cross(&w.vp);
        let s = c.norm();
        if s <= w.sin_vote {
            return None;
        }
        let a = c / s;
        let b = p.cross(&a);
        let delta = (w.sin_vote / s).asin();
        // The circle's point nearest the pole (±z): within the arc or its antipode and near
        // the pole, the arc sweeps (almost) every column.
        let t_pole = b.z.atan2(a.z);
        let off = (t_pole.rem_euclid(PI) - PI / 2.0).abs();
        if PI / 2.0 - off <= delta && p.z.abs() < w.sin_vote {
            return None;
        }
        let theta = |n: Vector3<f64>| n.y.atan2(n.x).rem_euclid(PI);
        let (sd, cd) = delta.sin_cos();
        let (th0, lo, hi) = (theta(a), theta(a * cd - b * sd), theta(a * cd + b * sd));
        let ahead = |from: f64, to: f64| (to - from).rem_euclid(PI);
        let (start, span) = if ahead(lo, th0) <= ahead(lo, hi) {
            (lo, ahead(lo, hi))
        } else {
            (hi, ahead(hi, lo))
        };
        let cell = PI / t as f64;
        let first = ((start / cell) as usize).min(t - 1);
        let count = ((start + span) / cell) as usize - first + 3;
        (count < t).then_some(((first + t - 1) % t, count))
    }

    /// Half-width (radians) of the band of points each row of the last run was fitted to,
    /// in the order the rows were appended.
    pub fn bands(&self) -> &[f64] {
        &self.bands
    }

    /// The accumulator of the last run, column-major (θ column × φ cells).
    pub fn accumulator(&self) -> &[u32] {
        &self.acc
    }

    /// The normal at the centre of cell (θ column k, φ cell j).
    pub fn cell_normal(&self, k: usize, j: usize) -> Vector3<f64> {
        let dphi = std::f64::consts::PI / self.opts.bins as f64;
        let dth = std::f64::consts::PI / self.opts.bins as f64;
        from_phi_theta((j as f64 + 0.5) * dphi, (k as f64 + 0.5) * dth)
    }

    /// The cell (θ column, φ cell) of a normal (either sign).
    pub fn cell_of(&self, n: &Vector3<f64>) -> (usize, usize) {
        let (mut phi, mut th) = crate::sphere::to_phi_theta(n);
        if th >= std::f64::consts::PI {
            th -= std::f64::consts::PI;
            phi = std::f64::consts::PI - phi;
        }
        let p = self.opts.bins;
        let t = self.opts.bins;
        let j = ((phi / std::f64::consts::PI * p as f64) as usize).min(p - 1);
        let k = ((th / std::f64::consts::PI * t as f64) as usize).min(t - 1);
        (k, j)
    }

    /// Casts the votes of all rays.
    ///
    /// Each ray fills, in every θ column, the run of φ cells between its curve's values at
    /// the column's two edges. A run is recorded as +1 at its first cell and −1 after its
    /// last in a difference array, and the columns are summed once at the end, so a vote
    /// costs the same whatever the run's length (a ray on the accumulator's equator fills
    /// whole columns).
    #[inline(never)]
    fn vote(&mut self, rays: &[[f32; 3]]) {
        let p = self.opts.bins;
        let t = self.opts.bins;
        let stride = p + 1;
        self.diff.fill(0);
        self.vote_stride = match self.opts.vote_points {
            0 => 1,
            v => rays.len().div_ceil(v).max(1),
        };
        for r in rays.iter().step_by(self.vote_stride) {
            // φ(θ) = atan2(−p_z, p_x cos θ + p_y sin θ) taken in [0, π): the same as
            // atan2(|p_z|, ±(p_x cos θ + p_y sin θ)) with the sign of −p_z.
            let mz = -r[2];
            let sign = if mz < 0.0 { -1.0f32 } else { 1.0 };
            let (px, py, y) = (r[0] * sign, r[1] * sign, mz.abs());
            match self.window_columns(r) {
                None => self.vote_columns(y, px, py, 0, t),
                Some((first, count)) if first + count <= t => {
                    self.vote_columns(y, px, py, first, first + count)
                }
                Some((first, count)) => {
                    self.vote_columns(y, px, py, first, t);
                    self.vote_columns(y, px, py, 0, first + count - t);
                }
            }
        }
        for k in 0..t {
            let mut sum = 0u32;
            let col = &self.diff[k * stride..k * stride + p];
            for (a, &d) in self.acc[k * p..(k + 1) * p].iter_mut().zip(col) {
                sum = sum.wrapping_add(d);
                *a = sum;
            }
        }
    }

    /// One ray's votes in θ columns `from..to`: the φ cell of its curve at each column edge
    /// (a loop the compiler vectorises), then the run of cells between a column's two edges,
    /// recorded in the difference array. φ(θ) is continuous for a fixed ray (atan2 of a
    /// fixed-sign numerator), so the cells between a column's two edges are exactly those
    /// the curve crosses. `y`, `px`, `py`: the ray with φ(θ) = atan2(y, px cos θ + py sin θ).
    #[inline(always)]
    fn vote_columns(&mut self, y: f32, px: f32, py: f32, from: usize, to: usize) {
        let scale = self.opts.bins as f32 / PI32;
        let pmax = (self.opts.bins - 1) as f32;
        let stride = self.opts.bins + 1;
        let edges = &mut self.edge[from..=to];
        curve_cells(
            [y, px, py],
            &self.cos_e[from..=to],
            &self.sin_e[from..=to],
            [scale, pmax],
            edges,
        );
        for (col, e) in self.diff[from * stride..to * stride]
            .chunks_exact_mut(stride)
            .zip(edges.windows(2))
        {
            let (lo, hi) = (e[0].min(e[1]) as usize, e[0].max(e[1]) as usize);
            col[lo] = col[lo].wrapping_add(1);
            col[hi + 1] = col[hi + 1].wrapping_sub(1);
        }
    }

    /// Neighbour of cell (k, j) at offset (dk, dj) on the wrapped accumulator.
    #[inline]
    fn neighbour(&self, k: usize, j: usize, dk: isize, dj: isize) -> usize {
        let p = self.opts.bins as isize;
        let t = self.opts.bins as isize;
        let mut jj = (j as isize + dj).rem_euclid(p);
        let kk = k as isize + dk;
        let kk = if kk < 0 || kk >= t {
            jj = p - 1 - jj;
            kk.rem_euclid(t)
        } else {
            kk
        };
        (kk * p + jj) as usize
    }

    /// Whether cell (θ column k, φ cell j) may hold a row of the window (always without one).
    #[inline]
    fn in_window(&self, k: usize, j: usize) -> bool {
        self.window
            .as_ref()
            .is_none_or(|w| self.cell_normal(k, j).dot(&w.vp).abs() < w.sin_peak)
    }

    /// The highest cell in the window (the peaks' fraction is of the window's rows).
    fn window_max(&self) -> u32 {
        let p = self.opts.bins;
        let mut max = 0;
        for (idx, &v) in self.acc.iter().enumerate() {
            if v > max && self.in_window(idx / p, idx % p) {
                max = v;
            }
        }
        max
    }

    #[inline(never)]
    fn find_peaks(&mut self) -> u32 {
        let p = self.opts.bins;
        let t = self.opts.bins;
        let max = match self.window {
            None => self.acc.iter().copied().max().unwrap_or(0),
            Some(_) => self.window_max(),
        };
        let floor = (self
            .opts
            .min_support
            .div_ceil(self.vote_stride as u32)
            .max(1))
        .max((self.opts.min_peak_fraction * max as f64).ceil() as u32);
        self.peaks.clear();
        for k in 0..t {
            for j in 0..p {
                let idx = k * p + j;
                let v = self.acc[idx];
                if v < floor || !self.in_window(k, j) {
                    continue;
                }
                let mut is_peak = true;
                for &(dk, dj) in &self.nms {
                    let n = self.neighbour(k, j, dk, dj);
                    let w = self.acc[n];
                    if w > v || (w == v && n < idx) {
                        is_peak = false;
                        break;
                    }
                }
                if is_peak {
                    self.peaks.push((v, idx as u32));
                }
            }
        }
        self.peaks
            .sort_unstable_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
        self.peaks.truncate(2 * self.opts.max_rows);
        max
    }

    /// Refines a peak's normal on the points near its great circle. Returns the row, or
    /// `None` when too few points support it or they do not define a great circle.
    #[inline(never)]
    fn refine(
        &mut self,
        n0: Vector3<f64>,
        rays: &[[f32; 3]],
        weights: &[f32],
    ) -> Option<(Row, f64)> {
        let cell = std::f64::consts::PI / self.opts.bins as f64;
        let mut tol = 1.5 * cell;
        let min_tol = self.opts.min_tolerance_deg.to_radians();
        // Points within twice the first band: later bands are narrower and the normal moves
        // little, so they never need points outside this set.
        let wide = (2.0 * tol).sin() as f32;
        // The indices compacted without branches (every ray's index is written, the end
        // moves past the ones kept: whether a ray is in varies from ray to ray, so a branch
        // would mispredict), then only the points kept widened to f64.
        if self.sel_index.len() < rays.len() {
            self.sel_index.resize(rays.len(), 0);
        }
        let mut len = 0;
        let nf = [n0.x as f32, n0.y as f32, n0.z as f32];
        for (k, r) in rays.iter().enumerate() {
            let d = nf[0] * r[0] + nf[1] * r[1] + nf[2] * r[2];
            self.sel_index[len] = k as u32;
            len += (d.abs() < wide) as usize;
        }
        self.sel.clear();
        self.sel.extend(self.sel_index[..len].iter().map(|&k| {
            let (r, w) = (rays[k as usize], weights[k as usize]);
            ([r[0] as f64, r[1] as f64, r[2] as f64], w as f64)
        }));
        let mut n = n0;
        let mut support = 0u32;
        let mut fit = None;
        for _ in 0..self.opts.refine_iterations.max(1) {
            let s_tol = tol.sin();
            // The next bands are no wider and the normal moves less than a band: points
            // beyond twice this band are never needed again (the same rule as the first
            // selection), so the later, narrow iterations visit only the points near the row.
            let s_keep = (2.0 * tol).min(std::f64::consts::FRAC_PI_2).sin();
            let mut sc = Scatter::new();
            support = 0;
            let mut kept = 0;
            for i in 0..len {
                let (r, w) = self.sel[i];
                let pv = Vector3::from(r);
                let d = n.dot(&pv).abs();
                let inside = d < s_tol;
                sc.add_if(&pv, w, inside);
                support += inside as u32;
                self.sel[kept] = (r, w);
                kept += (d < s_keep) as usize;
            }
            len = kept;
            let f = sc.fit()?;
            let change = axis_angle(&f.normal, &n);
            n = f.normal;
            fit = Some(f);
            let rms = f.mean_sq_residual.max(0.0).sqrt().asin();
            let next = (3.0 * rms).clamp(min_tol, tol);
            if change < 1e-7 && (next - tol).abs() < 1e-9 {
                break;
            }
            tol = next;
        }
        let f = fit?;
        if support < self.opts.min_support || f.degeneracy > self.opts.max_degeneracy {
            return None;
        }
        Some((
            Row {
                normal: canonical(&n),
                method: Method::Hough,
                support,
                width_rad: 0.0,
            },
            tol,
        ))
    }

    /// Finds rows among unit rays (camera frame) with per-point weights (used by the
    /// refinement fit; votes count the voting points, see [`HoughParams::vote_points`]). Appends the rows to `rows`, strongest first.
    pub fn find_rows(
        &mut self,
        rays: &[[f32; 3]],
        weights: &[f32],
        rows: &mut Vec<Row>,
    ) -> Result<HoughResult, DetectError> {
        if rays.len() != weights.len() {
            return Err(DetectError::Buffer(format!(
                "hough: {} rays but {} weights",
                rays.len(),
                weights.len()
            )));
        }
        self.vote(rays);
        let max_votes = self.find_peaks();
        let p = self.opts.bins;
        self.found.clear();
        let npeaks = self.peaks.len();
        for pi in 0..npeaks {
            let idx = self.peaks[pi].1 as usize;
            let n0 = self.cell_normal(idx / p, idx % p);
            if let Some(row) = self.refine(n0, rays, weights) {
                self.found.push(row);
            }
        }
        self.found
            .sort_unstable_by_key(|r| std::cmp::Reverse(r.0.support));
        // Accept rows strongest first; a candidate whose points mostly belong to rows already
        // accepted (a great circle through a row's wide near part, or the same row again)
        // is not a row of its own.
        let merge = self.opts.merge_angle_deg.to_radians();
        let start = rows.len();
        self.bands.clear();
        self.owned.clear();
        self.owned.resize(rays.len(), false);
        for fi in 0..self.found.len() {
            let (row, tol) = self.found[fi];
            if rows.len() - start >= self.opts.max_rows {
                break;
            }
            if rows[start..]
                .iter()
                .any(|r| axis_angle(&r.normal, &row.normal) <= merge)
            {
                continue;
            }
            let s_tol = tol.sin() as f32;
            let nf = [
                row.normal.x as f32,
                row.normal.y as f32,
                row.normal.z as f32,
            ];
            let mut own = 0u32;
            let mut all = 0u32;
            for (r, &o) in rays.iter().zip(&self.owned) {
                let inside = ((nf[0] * r[0] + nf[1] * r[1] + nf[2] * r[2]).abs() < s_tol) as u32;
                all += inside;
                own += inside & !o as u32;
            }
            if own < self.opts.min_support || (own as f64) < 0.5 * all as f64 {
                continue;
            }
            for (r, o) in rays.iter().zip(self.owned.iter_mut()) {
                *o |= (nf[0] * r[0] + nf[1] * r[1] + nf[2] * r[2]).abs() < s_tol;
            }
            rows.push(row);
            self.bands.push(tol);
        }
        Ok(HoughResult {
            points: rays.len(),
            peaks: npeaks,
            max_votes,
            rows: rows.len() - start,
        })
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::sphere::any_perpendicular;

    /// Deterministic generator for tests.
    pub(crate) struct Lcg(pub u64);
    impl Lcg {
        pub fn next_f64(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
        pub fn gauss(&mut self) -> f64 {
            let (u, v) = (self.next_f64().max(1e-300), self.next_f64());
            (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        }
    }

    /// Rays on the great circle of `n` (arc `from..to` radians), spread across it by `width_rad`.
    pub(crate) fn circle_rays(
        n: &Vector3<f64>,
        count: usize,
        from: f64,
        to: f64,
        width_rad: f64,
        rng: &mut Lcg,
        out: &mut Vec<[f32; 3]>,
    ) {
        let u = any_perpendicular(n);
        let v = n.cross(&u);
        for i in 0..count {
            let t = from + (to - from) * (i as f64 + 0.5) / count as f64;
            let off = width_rad * (rng.next_f64() - 0.5) * 2.0;
            let p = (u * t.cos() + v * t.sin()) * off.cos() + n * off.sin();
            out.push([p.x as f32, p.y as f32, p.z as f32]);
        }
    }

    #[test]
    fn fast_atan2_is_accurate() {
        let mut worst = 0.0f32;
        for i in 0..3600 {
            let a = i as f32 * 0.1f32.to_radians();
            for &r in &[1e-3f32, 0.5, 3.0] {
                let (y, x) = (r * a.sin(), r * a.cos());
                worst = worst.max((fast_atan2(y, x) - y.atan2(x)).abs());
            }
        }
        assert!(worst < 2e-5, "{worst}");
        assert_eq!(fast_atan2(0.0, 0.0), 0.0);
        // The sign of a zero y: (−0, −1) is +π, as the branching form gave.
        assert_eq!(fast_atan2(-0.0, -1.0), PI32);
        assert_eq!(fast_atan2(-1e-30, -1.0), -PI32);
    }

    proptest::proptest! {
        #[test]
        fn floor_small_is_floor(v in 0.0f32..4_194_303.0) {
            proptest::prop_assert_eq!(floor_small(v), v.floor() as i32);
        }
    }

    #[test]
    fn floor_small_at_integers_and_just_below_them() {
        for k in [0i32, 1, 2, 89, 90, 179, 4_194_303] {
            assert_eq!(floor_small(k as f32), k);
            if k > 0 {
                let below = f32::from_bits((k as f32).to_bits() - 1);
                assert_eq!(floor_small(below), k - 1, "{below}");
            }
        }
    }

    /// Rows through one vanishing point `vp` at angles `at` around it (`per_row` rays each, in
    /// a ±0.01 rad band), then `noise` rays uniform on the sphere: the rows' normals and rays.
    fn rows_through(
        vp: Vector3<f64>,
        at: &[f64],
        per_row: usize,
        noise: usize,
        seed: u64,
    ) -> (Vec<Vector3<f64>>, Vec<[f32; 3]>) {
        let vp = vp.normalize();
        let a = any_perpendicular(&vp);
        let b = vp.cross(&a);
        let normals: Vec<Vector3<f64>> = at
            .iter()
            .map(|&t| canonical(&(a * t.cos() + b * t.sin())))
            .collect();
        let mut rng = Lcg(seed);
        let mut rays = Vec::new();
        for n in &normals {
            circle_rays(n, per_row, 0.2, 2.6, 0.01, &mut rng, &mut rays);
        }
        for _ in 0..noise {
            let p = Vector3::new(rng.gauss(), rng.gauss(), rng.gauss()).normalize();
            rays.push([p.x as f32, p.y as f32, p.z as f32]);
        }
        (normals, rays)
    }

    #[test]
    fn a_window_votes_as_the_full_transform_inside_it_and_keeps_only_its_rows() {
        // Three rows through one vanishing point, two through another 20° away, noise.
        let vp = Vector3::new(0.2, 1.0, 0.05).normalize();
        let other = Vector3::new(-0.15, 1.0, 0.05).normalize();
        let (normals, mut rays) = rows_through(vp, &[0.3, 1.2, 2.2], 1500, 1000, 7);
        let (others, more) = rows_through(other, &[0.7, 1.9], 1500, 0, 8);
        rays.extend(more);
        let weights = vec![1.0f32; rays.len()];
        let opts = HoughParams {
            vote_points: 0,
            bins: 180,
            ..Default::default()
        };
        let mut full = HoughRows::new(opts).unwrap();
        let mut all = Vec::new();
        full.find_rows(&rays, &weights, &mut all).unwrap();
        let mut narrow = HoughRows::new(opts).unwrap();
        let w = 0.02;
        narrow.set_window(Some((&vp, w)));
        let mut rows = Vec::new();
        narrow.find_rows(&rays, &weights, &mut rows).unwrap();
        // Every cell whose normal is within the window's band sees exactly the full votes.
        let (p, t) = (opts.bins, opts.bins);
        let mut inside = 0;
        for k in 0..t {
            for j in 0..p {
                if narrow.cell_normal(k, j).dot(&vp).abs() < (w + 0.03).sin() {
                    inside += 1;
                    assert_eq!(narrow.acc[k * p + j], full.acc[k * p + j], "cell {k},{j}");
                }
            }
        }
        assert!(inside > 500, "{inside}");
        // Fewer cells got votes at all (rays near the vanishing point vote everywhere).
        let voted = |h: &HoughRows| h.acc.iter().filter(|&&v| v > 0).count();
        assert!(
            voted(&narrow) * 3 < voted(&full) * 2,
            "{} {}",
            voted(&narrow),
            voted(&full)
        );
        let near =
            |rows: &[Row], n: &Vector3<f64>| rows.iter().any(|r| axis_angle(&r.normal, n) < 1e-3);
        for n in &normals {
            assert!(near(&all, n) && near(&rows, n), "row {n:?}");
        }
        for n in &others {
            assert!(near(&all, n), "the full transform finds {n:?}");
            assert!(!near(&rows, n), "the window keeps out {n:?}");
        }
        // Lifting the window restores the full transform.
        narrow.set_window(None);
        rows.clear();
        narrow.find_rows(&rays, &weights, &mut rows).unwrap();
        assert_eq!(rows, all);
        assert_eq!(narrow.acc, full.acc);
    }

    #[test]
    fn finds_rows_from_rays_on_known_circles() {
        // Three rows sharing a direction (a vanishing point near the horizon), plus noise rays.
        let (normals, rays) = rows_through(
            Vector3::new(0.2, 1.0, 0.05),
            &[0.3, 1.2, 2.2],
            1500,
            1000,
            7,
        );
        let weights = vec![1.0f32; rays.len()];
        let mut h = HoughRows::new(HoughParams::default()).unwrap();
        let mut rows = Vec::new();
        let res = h.find_rows(&rays, &weights, &mut rows).unwrap();
        assert!(res.rows >= 3, "{res:?} {rows:?}");
        for n in &normals {
            let best = rows
                .iter()
                .map(|r| axis_angle(&r.normal, n))
                .fold(f64::INFINITY, f64::min);
            // uniform noise across a ±0.01 rad band: the fit is far finer than a 2° cell
            assert!(best < 1e-3, "row {n:?} best {best}");
        }
        let strongest: Vec<u32> = rows.iter().take(3).map(|r| r.support).collect();
        assert!(strongest.iter().all(|&s| s >= 1400), "{strongest:?}");
    }

    #[test]
    fn a_stride_of_points_votes_and_every_point_is_fitted() {
        // 3 rows × 3000 rays + 2000 noise rays; 1000 vote (every 11th), all 11000 are fitted.
        let (normals, rays) = rows_through(
            Vector3::new(-0.3, 1.0, 0.1),
            &[0.4, 1.4, 2.5],
            3000,
            2000,
            19,
        );
        let weights = vec![1.0f32; rays.len()];
        let run = |vote_points| {
            let mut h = HoughRows::new(HoughParams {
                vote_points,
                ..Default::default()
            })
            .unwrap();
            let mut rows = Vec::new();
            h.find_rows(&rays, &weights, &mut rows).unwrap();
            let top = h.accumulator().iter().copied().max().unwrap();
            (rows, top)
        };
        let (all, top_all) = run(0);
        let (some, top_some) = run(1000);
        // Votes count the voting points: 11000 / 11 = 1000 voted.
        assert!(
            top_some * 9 < top_all && top_some * 13 > top_all,
            "{top_some} of {top_all}"
        );
        for n in &normals {
            for rows in [&all, &some] {
                let r = rows
                    .iter()
                    .min_by(|x, y| axis_angle(&x.normal, n).total_cmp(&axis_angle(&y.normal, n)))
                    .unwrap();
                assert!(axis_angle(&r.normal, n) < 1e-3, "{n:?}: {rows:?}");
                // The fit's support counts every kept point near the row, voter or not.
                assert!(r.support >= 2900, "{r:?}");
            }
        }
    }

    #[test]
    fn rows_near_the_poles_of_the_accumulator_are_found() {
        // Normals within a cell of the accumulator's poles (z) and of its θ seam (θ = 0 ≡ π).
        let cases = [
            Vector3::new(0.01, 0.02, 1.0).normalize(),
            Vector3::new(1.0, 0.003, 0.2).normalize(),
            Vector3::new(1.0, -0.003, -0.02).normalize(),
        ];
        for n in cases {
            let mut rng = Lcg(11);
            let mut rays = Vec::new();
            circle_rays(&n, 2000, 0.0, 2.0, 0.005, &mut rng, &mut rays);
            let weights = vec![1.0f32; rays.len()];
            let mut h = HoughRows::new(HoughParams::default()).unwrap();
            let mut rows = Vec::new();
            h.find_rows(&rays, &weights, &mut rows).unwrap();
            assert_eq!(rows.len(), 1, "{n:?}: {rows:?}");
            assert!(axis_angle(&rows[0].normal, &n) < 1e-3, "{n:?}: {rows:?}");
            assert!(rows[0].support >= 1900);
        }
    }

    #[test]
    fn every_ray_votes_in_the_cell_of_every_circle_through_it() {
        // The rasterised curve of a ray passes through the cell of any normal perpendicular to it.
        let mut rng = Lcg(3);
        let mut h = HoughRows::new(HoughParams::default()).unwrap();
        for _ in 0..200 {
            let p = Vector3::new(rng.gauss(), rng.gauss(), rng.gauss()).normalize();
            h.vote(&[[p.x as f32, p.y as f32, p.z as f32]]);
            let u = any_perpendicular(&p);
            let v = p.cross(&u);
            for i in 0..50 {
                let t = i as f64 * 0.0628;
                let n = u * t.cos() + v * t.sin();
                let (k, j) = h.cell_of(&n);
                // allow the neighbouring φ cell (the curve may turn inside a column)
                let p_ = h.opts.bins;
                let hit = (-1isize..=1).any(|dj| h.acc[h.neighbour(k, j, 0, dj)] > 0)
                    || h.acc[k * p_ + j] > 0;
                assert!(hit, "ray {p:?} normal {n:?} cell {k},{j}");
            }
        }
    }

    #[test]
    fn difference_votes_equal_filling_each_run() {
        // The vote as first written: every cell of each column's run incremented.
        let mut rng = Lcg(17);
        let rays: Vec<[f32; 3]> = (0..300)
            .map(|i| {
                let mut p = Vector3::new(rng.gauss(), rng.gauss(), rng.gauss()).normalize();
                if i % 50 == 0 {
                    p.z = 0.0; // on the accumulator's equator: whole columns
                }
                let p = p.normalize();
                [p.x as f32, p.y as f32, p.z as f32]
            })
            .collect();
        let mut h = HoughRows::new(HoughParams::default()).unwrap();
        h.vote(&rays);
        let (p, t) = (h.opts.bins, h.opts.bins);
        let mut naive = vec![0u32; p * t];
        let cell = |phi: f32| (phi * p as f32 / PI32).min((p - 1) as f32) as usize;
        for r in &rays {
            let phi = |k: usize| {
                let th = k as f32 * PI32 / t as f32;
                let f = fast_atan2(-r[2], r[0] * th.cos() + r[1] * th.sin());
                cell(if f < 0.0 { f + PI32 } else { f })
            };
            for k in 0..t {
                let (a, b) = (phi(k), phi(k + 1));
                for v in &mut naive[k * p + a.min(b)..=k * p + a.max(b)] {
                    *v += 1;
                }
            }
        }
        let differ = naive
            .iter()
            .zip(h.accumulator())
            .filter(|(a, b)| a != b)
            .count();
        // Only cells whose edge value falls within float rounding of a cell boundary differ.
        assert!(differ < 20, "{differ} cells differ");
        let total: u64 = naive.iter().map(|&v| v as u64).sum();
        let got: u64 = h.accumulator().iter().map(|&v| v as u64).sum();
        assert!((total as i64 - got as i64).abs() < 40, "{total} vs {got}");
    }

    #[test]
    fn noise_alone_gives_few_or_no_rows_and_bad_input_errors() {
        let mut rng = Lcg(5);
        let rays: Vec<[f32; 3]> = (0..3000)
            .map(|_| {
                let p = Vector3::new(rng.gauss(), rng.gauss(), rng.gauss()).normalize();
                [p.x as f32, p.y as f32, p.z as f32]
            })
            .collect();
        let weights = vec![1.0f32; rays.len()];
        let mut h = HoughRows::new(HoughParams::default()).unwrap();
        let mut rows = Vec::new();
        h.find_rows(&rays, &weights, &mut rows).unwrap();
        // random rays: any "row" has support near the 3° band's share, far below a real row's
        assert!(rows.iter().all(|r| r.support < 400), "{rows:?}");
        assert!(h.find_rows(&rays, &weights[1..], &mut rows).is_err());
        assert!(HoughRows::new(HoughParams {
            bins: 1,
            ..Default::default()
        })
        .is_err());
        // a hostile row count is refused by name
        let e = HoughRows::new(HoughParams {
            max_rows: 1_000_000_000,
            ..Default::default()
        })
        .unwrap_err();
        assert!(e.to_string().contains("hough.max_rows"), "{e}");
    }
}
