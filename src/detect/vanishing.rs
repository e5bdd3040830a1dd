//! The rows' common vanishing point (paper II-E): a second Hough transform over the row
//! normals, then a fit over the consistent ones.
//!
//! Owns the second accumulator, over directions near the horizon (robot frame: azimuth
//! α ∈ [0, π), the sign of a direction being free, and elevation β within ± the largest
//! expected tilt, as the paper limits it to "the range of expected vanishing points"). Each
//! row normal n votes, with its weight (its support, or w·support in the combined method),
//! for every direction perpendicular to it: β(α) = atan(−(n_x cos α + n_y sin α) / n_z),
//! rasterised like the row Hough. The winning cell is refined by the smallest eigenvector of
//! the weighted scatter of its inlier normals (the SVD fit), iterated until the inlier set is
//! stable; rows farther than the inlier tolerance from the plane perpendicular to the
//! direction are rejected. Fewer than two consistent rows, or rows that all share one
//! normal, give no vanishing point: the answer is "none", never a guess.

use super::types::{DetectError, Detection, Row, VanishingPoint};
use crate::camera::Mounting;
use crate::sphere::{axis_angle, Scatter};
use nalgebra::{Rotation3, Vector3};
use serde::{Deserialize, Serialize};

/// `[detector.vanishing]`: the vanishing-point stage's option.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VanishingOptions {
    /// A row is consistent with the vanishing point when its normal is within this angle
    /// (degrees) of the plane perpendicular to the direction: raise it for rows that bend
    /// or a wandering drill, lower it when weeds line up. Absent: derived from the
    /// calibration (1° at the GC2450C's field of view; [`super::scale`]).
    pub inlier_deg: Option<f64>,
}

/// The stage's angular scales at the reference angular resolution ([`super::scale`]):
/// accumulator cells along the azimuth (0..180°), the cells' height along the elevation
/// (degrees), the inlier tolerance (degrees), and the smallest spread of the rows' normals
/// (degrees) that defines a direction.
pub const REFERENCE_AZIMUTH_BINS: usize = 180;
pub const REFERENCE_ELEVATION_BIN_DEG: f64 = 1.0;
pub const REFERENCE_INLIER_DEG: f64 = 1.0;
pub const REFERENCE_MIN_SPREAD_DEG: f64 = 2.0;
/// Iterations of the fit / inlier update.
pub const REFINE_ITERATIONS: usize = 10;

impl VanishingOptions {
    /// Inlier tolerance (degrees) in force (the option, else the reference value).
    pub fn inlier_deg(&self) -> f64 {
        self.inlier_deg.unwrap_or(REFERENCE_INLIER_DEG)
    }

    pub fn validate(&self) -> Result<(), DetectError> {
        match self.inlier_deg {
            Some(i) if !(i > 0.0 && i < 30.0) => Err(DetectError::Options(format!(
                "vanishing.inlier_deg = {i} must be within (0, 30)"
            ))),
            _ => Ok(()),
        }
    }
}

/// The stage's parameters: the inlier tolerance and the angular scales the calibration's
/// field of view sets ([`super::scale`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VanishingParams {
    /// Accumulator cells along the azimuth (0..180°).
    pub azimuth_bins: usize,
    /// Accumulator cell height along the elevation (degrees).
    pub elevation_bin_deg: f64,
    /// See [`VanishingOptions::inlier_deg`].
    pub inlier_deg: f64,
    /// Rows whose normals are all within this angle (degrees) of each other do not define
    /// a direction.
    pub min_spread_deg: f64,
}

impl VanishingParams {
    /// The parameters of `opts` with the angular scales at `angle_factor` times their
    /// reference values (and the inlier tolerance too, when the option is absent).
    pub fn new(opts: &VanishingOptions, angle_factor: f64) -> Self {
        VanishingParams {
            azimuth_bins: super::scale::scaled_bins(REFERENCE_AZIMUTH_BINS, angle_factor),
            elevation_bin_deg: REFERENCE_ELEVATION_BIN_DEG * angle_factor,
            inlier_deg: opts
                .inlier_deg
                .unwrap_or(REFERENCE_INLIER_DEG * angle_factor),
            min_spread_deg: REFERENCE_MIN_SPREAD_DEG * angle_factor,
        }
    }

    pub fn validate(&self) -> Result<(), DetectError> {
        let bad = |m: String| Err(DetectError::Options(m));
        let a = self.azimuth_bins;
        let e = self.elevation_bin_deg;
        if !((4..=4096).contains(&a) && e > 0.01 && e <= 10.0) {
            return bad(format!(
                "the vanishing accumulator's cells ({a} along the azimuth, {e}° high) must \
                 be 4..=4096 and (0.01, 10]: angle_scale out of range"
            ));
        }
        let i = self.inlier_deg;
        if !(i > 0.0 && i < 30.0) {
            return bad(format!("vanishing.inlier_deg = {i} must be within (0, 30)"));
        }
        Ok(())
    }
}

impl Default for VanishingParams {
    fn default() -> Self {
        VanishingParams::new(&VanishingOptions::default(), 1.0)
    }
}

/// The outcome of the vanishing-point stage.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct VanishingResult {
    pub vanishing_point: Option<VanishingPoint>,
    /// Quality in 0..=1 (0 without a vanishing point): the inliers' share of the total weight,
    /// times (1 − residual / inlier tolerance), times (1 − 2^(1 − inliers)) so that two rows
    /// alone count half.
    pub quality: f64,
    /// Total weight of the inlier rows and of all rows.
    pub inlier_weight: f64,
    pub total_weight: f64,
}

/// The second Hough transform and its fit (buffers allocated once).
#[derive(Debug, Clone)]
pub struct VanishingFinder {
    opts: VanishingParams,
    max_tilt: f64,
    robot_from_camera: Rotation3<f64>,
    cos_e: Vec<f64>,
    sin_e: Vec<f64>,
    elev_bins: usize,
    /// tan of the elevation bins' edges, −`max_tilt` to `max_tilt` (`elev_bins` + 1): a
    /// great circle's elevation is found among them by its tangent, without an arc tangent.
    tan_edges: Vec<f64>,
    acc: Vec<f64>,
    robot_normals: Vec<Vector3<f64>>,
    /// The search window of the next runs ([`VanishingFinder::set_window`]): the expected
    /// direction (unit, robot frame) and the cosine of the window's half-angle widened by a
    /// cell's diagonal.
    window: Option<(Vector3<f64>, f64)>,
}

impl VanishingFinder {
    /// `max_tilt_deg`: the vanishing point is searched within ± this angle of the robot's
    /// horizontal plane.
    pub fn new(
        opts: VanishingParams,
        max_tilt_deg: f64,
        mounting: &Mounting,
    ) -> Result<Self, DetectError> {
        opts.validate()?;
        if !(max_tilt_deg > 0.0 && max_tilt_deg <= 80.0) {
            return Err(DetectError::Options(format!(
                "max_tilt_deg = {max_tilt_deg} must be within (0, 80]"
            )));
        }
        let a = opts.azimuth_bins;
        let (cos_e, sin_e) = (0..=a)
            .map(|k| (k as f64 * std::f64::consts::PI / a as f64).sin_cos())
            .map(|(s, c)| (c, s))
            .unzip();
        let elev_bins = (2.0 * max_tilt_deg / opts.elevation_bin_deg).ceil() as usize;
        let tilt = max_tilt_deg.to_radians();
        let tan_edges = (0..=elev_bins)
            .map(|m| (-tilt + m as f64 * 2.0 * tilt / elev_bins as f64).tan())
            .collect();
        Ok(VanishingFinder {
            opts,
            max_tilt: tilt,
            robot_from_camera: mounting.robot_from_camera(),
            cos_e,
            sin_e,
            elev_bins,
            tan_edges,
            acc: vec![0.0; a * elev_bins],
            robot_normals: Vec::with_capacity(64),
            window: None,
        })
    }

    /// Takes the next runs' winning cell only within `half_width_rad` of `vp` (camera frame,
    /// sign free), or anywhere (`None`). The fit that follows may still move the direction
    /// out of the window; the caller checks it.
    pub fn set_window(&mut self, window: Option<(&Vector3<f64>, f64)>) {
        let cell = (std::f64::consts::PI / self.opts.azimuth_bins as f64)
            .max(2.0 * self.max_tilt / self.elev_bins as f64);
        self.window = window.map(|(vp, w)| {
            (
                (self.robot_from_camera * vp).normalize(),
                (w + std::f64::consts::SQRT_2 * cell)
                    .min(std::f64::consts::FRAC_PI_2)
                    .cos(),
            )
        });
    }

    /// Finds the vanishing point of `rows`, each weighted by `weights[i]` (e.g. its support).
    /// `inliers` receives, per row, whether it is consistent with the vanishing point.
    pub fn find(
        &mut self,
        rows: &[Row],
        weights: &[f64],
        inliers: &mut Vec<bool>,
    ) -> Result<VanishingResult, DetectError> {
        if rows.len() != weights.len() {
            return Err(DetectError::Buffer(format!(
                "vanishing point: {} rows but {} weights",
                rows.len(),
                weights.len()
            )));
        }
        if let Some(w) = weights.iter().find(|w| !(w.is_finite() && **w >= 0.0)) {
            return Err(DetectError::Options(format!(
                "vanishing point: row weight {w} is not a finite non-negative number"
            )));
        }
        inliers.clear();
        inliers.resize(rows.len(), false);
        let total_weight: f64 = weights.iter().sum();
        let none = VanishingResult {
            total_weight,
            ..Default::default()
        };
        if rows.len() < 2 || total_weight <= 0.0 {
            return Ok(none);
        }
        self.robot_normals.clear();
        for r in rows {
            self.robot_normals.push(self.robot_from_camera * r.normal);
        }
        self.vote(weights);
        let Some(v0) = self.winner() else {
            return Ok(none);
        };
        let v = self.robot_from_camera.inverse() * v0;
        let s_tol = self.opts.inlier_deg.to_radians().sin();
        let (mut v, fit) = refine(rows, weights, inliers, v, s_tol);
        let Fitted {
            residual,
            inlier_weight,
            count,
        } = fit;
        // Final inlier set for the final direction.
        let mut count_final = 0;
        for (i, r) in rows.iter().enumerate() {
            inliers[i] = r.normal.dot(&v).abs() < s_tol && weights[i] > 0.0;
            count_final += inliers[i] as usize;
        }
        if count < 2 || count_final < 2 {
            inliers.fill(false);
            return Ok(none);
        }
        // Rows that all share one normal do not fix a direction.
        if spread(rows, inliers) < self.opts.min_spread_deg.to_radians() {
            inliers.fill(false);
            return Ok(none);
        }
        // Sign: pointing forward in the robot frame.
        if (self.robot_from_camera * v).x < 0.0 {
            v = -v;
        }
        let quality = (inlier_weight / total_weight).clamp(0.0, 1.0)
            * (1.0 - residual / self.opts.inlier_deg.to_radians()).clamp(0.0, 1.0)
            * (1.0 - 0.5f64.powi(count_final as i32 - 1));
        Ok(VanishingResult {
            vanishing_point: Some(VanishingPoint {
                direction: v,
                inliers: count_final,
                residual_rad: residual,
            }),
            quality,
            inlier_weight,
            total_weight,
        })
    }

    /// Each row's great circle votes, with its weight, for the cells it crosses: between
    /// two neighbouring azimuths its elevation spans a range of bins. The elevation's tangent
    /// (t / n.z) is placed among the bins' edges' tangents, which orders it as its angle.
    fn vote(&mut self, weights: &[f64]) {
        let a = self.opts.azimuth_bins;
        let e = self.elev_bins;
        self.acc.fill(0.0);
        let edges = &self.tan_edges;
        let (below, above) = (edges[0], edges[e]);
        // the bin of tangent x: the inner edges at or below it
        let bin = |x: f64| edges[1..e].partition_point(|&t| t <= x);
        for (n, &w) in self.robot_normals.iter().zip(weights) {
            if w <= 0.0 {
                continue;
            }
            let tangent = |k: usize| -> f64 {
                let t = -(n.x * self.cos_e[k] + n.y * self.sin_e[k]);
                if n.z == 0.0 {
                    f64::INFINITY.copysign(t)
                } else {
                    t / n.z
                }
            };
            let mut x0 = tangent(0);
            for k in 0..a {
                let x1 = tangent(k + 1);
                let (lo, hi) = if x0 <= x1 { (x0, x1) } else { (x1, x0) };
                x0 = x1;
                if hi < below || lo > above {
                    continue;
                }
                let (j0, j1) = (bin(lo), bin(hi));
                for v in &mut self.acc[k * e + j0..=k * e + j1] {
                    *v += w;
                }
            }
        }
    }

    /// Direction (robot frame) at the centre of the highest cell, if any cell has votes.
    fn winner(&self) -> Option<Vector3<f64>> {
        let (idx, best) = match self.window {
            None => self
                .acc
                .iter()
                .copied()
                .enumerate()
                .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)))?,
            // The first highest cell in the window, as above (the lowest index of equals).
            Some((v, cos_w)) => {
                let mut best = (0, 0.0);
                for (idx, &x) in self.acc.iter().enumerate() {
                    if x > best.1 && self.cell_direction(idx).dot(&v).abs() >= cos_w {
                        best = (idx, x);
                    }
                }
                best
            }
        };
        if best <= 0.0 {
            return None;
        }
        Some(self.cell_direction(idx))
    }

    /// The direction (robot frame) at the centre of accumulator cell `idx`.
    fn cell_direction(&self, idx: usize) -> Vector3<f64> {
        let e = self.elev_bins;
        let tilt = self.max_tilt;
        let (k, j) = (idx / e, idx % e);
        let alpha = (k as f64 + 0.5) * std::f64::consts::PI / self.opts.azimuth_bins as f64;
        let beta = -tilt + (j as f64 + 0.5) * 2.0 * tilt / e as f64;
        Vector3::new(
            beta.cos() * alpha.cos(),
            beta.cos() * alpha.sin(),
            beta.sin(),
        )
    }
}

/// The vanishing-point stage a method calls: the finder with its scratch, over a
/// detection's rows.
#[derive(Debug, Clone)]
pub struct VanishingStage {
    finder: VanishingFinder,
    weights: Vec<f64>,
    inliers: Vec<bool>,
}

impl VanishingStage {
    /// `max_tilt_deg`: the vanishing point is searched within ± this angle of the robot's
    /// horizontal plane.
    pub fn new(
        params: VanishingParams,
        max_tilt_deg: f64,
        mounting: &Mounting,
    ) -> Result<Self, DetectError> {
        Ok(VanishingStage {
            finder: VanishingFinder::new(params, max_tilt_deg, mounting)?,
            weights: Vec::with_capacity(64),
            inliers: Vec::with_capacity(64),
        })
    }

    /// The stage's parameters.
    pub fn params(&self) -> &VanishingParams {
        &self.finder.opts
    }

    /// Finds the vanishing point of `out.rows` (weighted by `weights`, or by each row's
    /// support when `None`) and sets `out`'s vanishing point and quality.
    pub fn run(
        &mut self,
        weights: Option<&[f64]>,
        out: &mut Detection,
    ) -> Result<VanishingResult, DetectError> {
        let w: &[f64] = match weights {
            Some(w) => w,
            None => {
                support_weights(&out.rows, &mut self.weights);
                &self.weights
            }
        };
        let r = self.finder.find(&out.rows, w, &mut self.inliers)?;
        out.vanishing_point = r.vanishing_point;
        out.quality = r.quality;
        Ok(r)
    }

    /// The finder, for other rows or weights with their own inlier flags (a method's
    /// candidates), leaving the last run's inliers as they are.
    pub fn finder_mut(&mut self) -> &mut VanishingFinder {
        &mut self.finder
    }

    /// Per row of the last run: whether it agrees with the vanishing point.
    pub fn inliers(&self) -> &[bool] {
        &self.inliers
    }

    /// Narrows the finder's search to a window, or widens it again (`None`).
    pub fn set_window(&mut self, window: Option<(&Vector3<f64>, f64)>) {
        self.finder.set_window(window);
    }

    /// The last run's vanishing point refitted over its inlier rows, each weighted by the
    /// inverse of `variances[i]`, its normal's variance along the vanishing point as the
    /// refit estimated it ([`super::refit::RowFits::along_var`]): a row's precision
    /// depends on how far it reaches towards the vanishing point and how wide and long its
    /// edges are, not on its number of points. Keeps the vote's fit when any inlier lacks
    /// an estimate.
    pub fn refit_by_variances(&mut self, out: &mut Detection, variances: &[f64]) {
        let Some(vp) = out.vanishing_point else {
            return;
        };
        let inliers = &self.inliers;
        if variances.len() != out.rows.len() || inliers.len() != out.rows.len() {
            return;
        }
        self.weights.clear();
        for (&v, &ok) in variances.iter().zip(inliers) {
            if !ok {
                self.weights.push(0.0);
            } else if v.is_finite() && v > 0.0 {
                self.weights.push(1.0 / v);
            } else {
                return;
            }
        }
        let Some((direction, residual_rad)) =
            refit_direction(&out.rows, inliers, &self.weights, &vp.direction)
        else {
            return;
        };
        out.set_vanishing_point(direction, vp.inliers, residual_rad);
    }
}

/// What [`refine`] fitted: the inliers' RMS residual (radians), their weight and number.
#[derive(Debug, Clone, Copy, Default)]
struct Fitted {
    residual: f64,
    inlier_weight: f64,
    count: usize,
}

/// The direction `v` refitted over the rows within `s_tol` (sine of the inlier tolerance)
/// of it, iterated until the inlier set and the direction settle; `inliers` holds the last
/// iteration's.
fn refine(
    rows: &[Row],
    weights: &[f64],
    inliers: &mut [bool],
    mut v: Vector3<f64>,
    s_tol: f64,
) -> (Vector3<f64>, Fitted) {
    let mut f = Fitted::default();
    for _ in 0..REFINE_ITERATIONS {
        let mut sc = Scatter::new();
        let mut changed = false;
        for (i, r) in rows.iter().enumerate() {
            let ok = r.normal.dot(&v).abs() < s_tol && weights[i] > 0.0;
            changed |= ok != inliers[i];
            inliers[i] = ok;
            if ok {
                sc.add(&r.normal, weights[i]);
            }
        }
        f.count = sc.count();
        if f.count < 2 {
            break;
        }
        let Some(fit) = sc.fit() else { break };
        let moved = axis_angle(&fit.normal, &v);
        v = fit.normal;
        f.residual = fit.mean_sq_residual.max(0.0).sqrt().asin();
        f.inlier_weight = fit.weight;
        if !changed && moved < 1e-12 {
            break;
        }
    }
    (v, f)
}

/// The largest angle between two inlier rows' normals.
fn spread(rows: &[Row], inliers: &[bool]) -> f64 {
    let mut spread: f64 = 0.0;
    for i in 0..rows.len() {
        for j in i + 1..rows.len() {
            if inliers[i] && inliers[j] {
                spread = spread.max(axis_angle(&rows[i].normal, &rows[j].normal));
            }
        }
    }
    spread
}

/// Refits the direction over the `inliers` rows, each weighted by `weights[i]` (e.g. the
/// inverse of its variance): the smallest eigenvector of Σ w·n·nᵀ, signed like `previous`.
/// Returns it with the weighted rms residual (radians); `None` with fewer than two weighted
/// inliers or a degenerate fit.
pub fn refit_direction(
    rows: &[Row],
    inliers: &[bool],
    weights: &[f64],
    previous: &Vector3<f64>,
) -> Option<(Vector3<f64>, f64)> {
    let mut sc = Scatter::new();
    for ((r, &ok), &w) in rows.iter().zip(inliers).zip(weights) {
        if ok && w > 0.0 && w.is_finite() {
            sc.add(&r.normal, w);
        }
    }
    if sc.count() < 2 {
        return None;
    }
    let fit = sc.fit()?;
    let v = if fit.normal.dot(previous) < 0.0 {
        -fit.normal
    } else {
        fit.normal
    };
    Some((v, fit.mean_sq_residual.max(0.0).sqrt().asin()))
}

/// Row weights for the Hough method: each row's support.
pub fn support_weights(rows: &[Row], out: &mut Vec<f64>) {
    out.clear();
    out.extend(rows.iter().map(|r| r.support as f64));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::Method;
    use crate::sphere::{any_perpendicular, canonical};

    /// The vote as it was written first: each great circle's elevation by its arc tangent.
    fn vote_by_angles(f: &VanishingFinder, weights: &[f64]) -> Vec<f64> {
        let (a, e, tilt) = (f.opts.azimuth_bins, f.elev_bins, f.max_tilt);
        let scale = e as f64 / (2.0 * tilt);
        let mut acc = vec![0.0; a * e];
        for (n, &w) in f.robot_normals.iter().zip(weights) {
            let beta = |k: usize| {
                let t = -(n.x * f.cos_e[k] + n.y * f.sin_e[k]);
                if n.z == 0.0 {
                    std::f64::consts::FRAC_PI_2.copysign(t)
                } else {
                    (t / n.z).atan()
                }
            };
            for k in 0..a {
                let (b0, b1) = (beta(k), beta(k + 1));
                let (lo, hi) = (b0.min(b1), b0.max(b1));
                if hi < -tilt || lo > tilt {
                    continue;
                }
                let j0 = (((lo.max(-tilt) + tilt) * scale) as usize).min(e - 1);
                let j1 = (((hi.min(tilt) + tilt) * scale) as usize).min(e - 1);
                for v in &mut acc[k * e + j0..=k * e + j1] {
                    *v += w;
                }
            }
        }
        acc
    }

    #[test]
    fn the_vote_by_tangents_fills_the_cells_the_angles_did() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        for (tilt, opts) in [
            (15.0, VanishingParams::default()),
            (40.0, VanishingParams::default()),
        ] {
            let mut f = VanishingFinder::new(opts, tilt, &Mounting::default()).unwrap();
            f.robot_normals.clear();
            // random circles, steep and shallow ones, and some through the zenith (n.z = 0)
            for i in 0..3000 {
                let z = if i % 50 == 0 { 0.0 } else { next() * next() };
                f.robot_normals
                    .push(Vector3::new(next(), next(), z).normalize());
            }
            let weights: Vec<f64> = (0..3000).map(|i| 1.0 + (i % 7) as f64).collect();
            f.vote(&weights);
            assert_eq!(f.acc, vote_by_angles(&f, &weights), "max tilt {tilt}°");
        }
    }

    fn rows_through(vp: &Vector3<f64>, angles: &[f64], support: u32) -> Vec<Row> {
        let a = any_perpendicular(vp);
        let b = vp.cross(&a);
        angles
            .iter()
            .map(|&t| Row {
                normal: canonical(&(a * t.cos() + b * t.sin())),
                method: Method::Hough,
                support,
                width_rad: 0.0,
            })
            .collect()
    }

    fn dir(heading: f64, tilt: f64) -> Vector3<f64> {
        // robot frame direction → camera frame with the default mounting
        let d = Vector3::new(
            tilt.cos() * heading.cos(),
            tilt.cos() * heading.sin(),
            tilt.sin(),
        );
        Mounting::default().robot_from_camera().inverse() * d
    }

    #[test]
    fn recovers_direction_and_rejects_outlier_row() {
        let vp = dir(0.3, 0.05);
        let mut rows = rows_through(&vp, &[0.2, 0.9, 1.6, 2.4], 500);
        // an outlier row (a weed line) not through the vanishing point
        rows.push(Row {
            normal: Vector3::new(0.3, 0.5, 0.8).normalize(),
            method: Method::Hough,
            support: 900,
            width_rad: 0.0,
        });
        let mut f =
            VanishingFinder::new(VanishingParams::default(), 15.0, &Mounting::default()).unwrap();
        let mut w = Vec::new();
        support_weights(&rows, &mut w);
        let mut inl = Vec::new();
        let r = f.find(&rows, &w, &mut inl).unwrap();
        let v = r.vanishing_point.unwrap();
        assert!(axis_angle(&v.direction, &vp) < 1e-9, "{v:?}");
        assert_eq!(v.inliers, 4);
        assert_eq!(inl, vec![true, true, true, true, false]);
        assert!(v.residual_rad < 1e-7, "{}", v.residual_rad);
        assert!(r.quality > 0.5 && r.quality < 1.0, "{r:?}");
        // sign: forward in the robot frame
        assert!((Mounting::default().robot_from_camera() * v.direction).x > 0.0);
    }

    #[test]
    fn two_rows_suffice_one_does_not() {
        let vp = dir(-1.0, -0.1);
        let rows = rows_through(&vp, &[0.4, 1.9], 100);
        let mut f =
            VanishingFinder::new(VanishingParams::default(), 15.0, &Mounting::default()).unwrap();
        let mut inl = Vec::new();
        let r = f.find(&rows, &[100.0, 100.0], &mut inl).unwrap();
        assert!(axis_angle(&r.vanishing_point.unwrap().direction, &vp) < 1e-9);
        let r = f.find(&rows[..1], &[100.0], &mut inl).unwrap();
        assert!(r.vanishing_point.is_none());
        assert_eq!(r.quality, 0.0);
        // two copies of one row: no direction
        let same = vec![rows[0], rows[0]];
        let r = f.find(&same, &[1.0, 1.0], &mut inl).unwrap();
        assert!(r.vanishing_point.is_none());
        // two rows whose common direction is far above the horizon: not a field's rows
        let sky = Vector3::new(0.0, 0.0, 1.0);
        let r = f
            .find(
                &rows_through(&sky, &[0.1, 1.2, 2.0], 100),
                &[1.0; 3],
                &mut inl,
            )
            .unwrap();
        assert!(r.vanishing_point.is_none());
        assert!(f.find(&rows, &[1.0], &mut inl).is_err());
    }

    #[test]
    fn refit_direction_follows_the_weights() {
        let vp = dir(0.2, 0.03);
        let mut rows = rows_through(&vp, &[0.3, 1.1, 2.0], 100);
        // tilt the third row's normal off the vanishing point
        rows[2].normal = (rows[2].normal + vp * 0.01).normalize();
        let inl = [true, true, true];
        let (v, res) = refit_direction(&rows, &inl, &[1.0, 1.0, 1e-9], &vp).unwrap();
        assert!(axis_angle(&v, &vp) < 1e-6, "{}", axis_angle(&v, &vp));
        assert!(v.dot(&vp) > 0.0 && res < 1e-4);
        let (v, _) = refit_direction(&rows, &inl, &[1.0, 1.0, 1.0], &-vp).unwrap();
        assert!(axis_angle(&v, &vp) > 1e-3 && v.dot(&vp) < 0.0);
        assert!(refit_direction(&rows, &[true, false, false], &[1.0; 3], &vp).is_none());
    }

    #[test]
    fn noisy_normals_are_averaged() {
        let vp = dir(0.7, 0.02);
        let a = any_perpendicular(&vp);
        let b = vp.cross(&a);
        let mut rng = crate::detect::hough::tests::Lcg(9);
        let rows: Vec<Row> = (0..10)
            .map(|i| {
                let t = 0.1 + 0.3 * i as f64;
                let n = a * t.cos() + b * t.sin() + vp * (2e-4 * rng.gauss());
                Row {
                    normal: n.normalize(),
                    method: Method::Hough,
                    support: 100,
                    width_rad: 0.0,
                }
            })
            .collect();
        let mut f =
            VanishingFinder::new(VanishingParams::default(), 15.0, &Mounting::default()).unwrap();
        let mut inl = Vec::new();
        let r = f.find(&rows, &[1.0; 10], &mut inl).unwrap();
        let v = r.vanishing_point.unwrap();
        assert_eq!(v.inliers, 10);
        assert!(
            axis_angle(&v.direction, &vp) < 2e-4,
            "{}",
            axis_angle(&v.direction, &vp)
        );
        assert!(v.residual_rad > 0.0 && v.residual_rad < 5e-4);
    }
}
