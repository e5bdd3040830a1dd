//! Curvature of the rows, measured from their points on the ground.
//!
//! Owns [`RowFit`] and the [`RowFitMeasurement`] it gives. The detector reports rows
//! as great circles (straight lines on the ground); a curved row leaves its points off that
//! line by its sagitta. Each kept image point (the detector's vegetation points, unit rays in
//! the camera frame) is projected on the ground ([`GroundFrame::ray_on_ground`]) in the frame
//! of the rows' vanishing point, assigned to the nearest detected row's ground line, and the
//! rows near the robot are fitted together as concentric arcs, to second order: a point at
//! `a` along the rows lies across them at
//!
//! ```text
//! y = y_i + α_i + β·a + κ_i·a²/2,    κ_i = κ / (1 − κ·y_i)
//! ```
//!
//! with `y_i` the row's detected lateral position, `α_i` its own shift, `β` a common turn (the
//! vanishing point is the rows' mean direction, not their tangent below the robot) and `κ` the
//! curvature of the line through the camera's foot point (positive: bending to the left, REP
//! 103; rows farther from the turn's centre bend less). Points are weighted by the ground area
//! their pixel covers, so near and far plants count alike. The fit widens its reach in passes
//! (1.5 m, 3 m, then `range_m` along the rows), each assigning the points by the previous
//! pass's arcs, so a strong bend does not hand far points to the neighbouring row. Weighted
//! sums per row are kept in a reused buffer: a fit allocates nothing once warmed up.

use super::GroundFrame;
use crate::camera::Mounting;
use crate::detect::{Detection, Points};
use nalgebra::{Rotation3, Vector3};
use serde::{Deserialize, Serialize};

/// Settings of the curvature fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RowFitOptions {
    /// Farthest distance along the rows, ahead and behind, of the points used, metres.
    pub range_m: f64,
    /// Farthest distance across the rows of the rows used, metres.
    pub across_m: f64,
    /// Fewest points in the fit.
    pub min_points: usize,
    /// Floor of the measurement's standard deviation, 1/m.
    pub min_sd_per_m: f64,
    /// Largest curvature taken for a measurement, 1/m: a tighter fit (a radius under 5 m
    /// by default, no crop row's) comes from points that do not pin the arcs down (far rows
    /// seen across an empty stretch) and is no measurement.
    pub max_curvature_per_m: f64,
}

impl Default for RowFitOptions {
    fn default() -> Self {
        RowFitOptions {
            range_m: 4.0,
            across_m: 2.0,
            min_points: 100,
            min_sd_per_m: 0.001,
            max_curvature_per_m: 0.2,
        }
    }
}

/// One frame's curvature measurement.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RowFitMeasurement {
    /// Curvature of the row-parallel line through the camera's foot point, 1/m, positive
    /// when it bends to the left (`None`: too few points near the robot). A line `y` metres
    /// to the left bends by `κ / (1 − κ·y)`.
    pub curvature_per_m: Option<f64>,
    /// Its standard deviation, 1/m.
    pub sd_per_m: f64,
    /// Points in the fit.
    pub points: usize,
    /// Distance ahead along the rows from the camera's foot point to where the rows end,
    /// metres, when the points show it within [`END_MEASURE_M`] (negative: behind, once
    /// past): the last plant seen on the rows, with none after it for the bins' reach.
    pub end_of_rows_m: Option<f64>,
    /// Plants are seen on the rows within [`NEAR_M`] along them, ahead or behind (false: an
    /// empty stretch or the headland around the robot, the rows seen only farther away).
    pub crop_near: bool,
    /// How far the rows' arcs lie to the left of their detected lines (great circles: chords
    /// over the visible stretch) at the camera's foot point, metres: the rows' own shifts
    /// `α_i`, averaged with the comb's weights (0 without a fit).
    #[serde(default)]
    pub shift_m: f64,
    /// The arcs' common turn `β` at the camera's foot point: their tangent there runs
    /// `atan(β)` to the left of the vanishing point's direction (0 without a fit).
    #[serde(default)]
    pub turn: f64,
    /// The standard deviation of [`shift_m`](Self::shift_m), metres: small when plants grow
    /// beside the camera, large when the arcs are extrapolated under it from rows seen only
    /// farther away (an empty stretch); 0 without a fit.
    #[serde(default)]
    pub shift_sd_m: f64,
}

impl RowFitMeasurement {
    /// Curvature of the row-parallel line `lateral_m` to the left of the camera's foot point.
    pub fn at_lateral(&self, lateral_m: f64) -> Option<f64> {
        self.curvature_per_m.map(|k| k / (1.0 - k * lateral_m))
    }

    /// How far the arc of the row-parallel line `lateral_m` to the left of the camera's foot
    /// point lies to the left of its straight (detected) line, `along_m` ahead of the foot
    /// point, metres: `shift + β·a + κ_line·a²/2`.
    pub fn arc_shift_m(&self, lateral_m: f64, along_m: f64) -> f64 {
        let k = self.at_lateral(lateral_m).unwrap_or(0.0);
        self.shift_m + self.turn * along_m + k * along_m * along_m / 2.0
    }
}

/// Detected lines closer than this across the rows are one row, metres (the detector may
/// report both edges of a row; rows are at least 0.2 m apart, `min_spacing_m`).
const MERGE_M: f64 = 0.12;

/// Bins of the rows' points along the rows, ahead and behind, for the end of the rows: 12 m
/// each way, so that the rows after an empty stretch come into view well before it.
const END_BIN_M: f64 = 0.2;
const END_BINS: usize = 60;
/// The rows end where the points ahead stay below this share of those behind (at the same
/// distances) over [`END_EMPTY_M`] and no planted bin follows within the bins' reach (one
/// does: an empty stretch, the rows resume after it).
const END_RATIO: f64 = 0.15;
const END_EMPTY_M: f64 = 2.4;
/// Farthest end of the rows measured in one frame, metres ahead (and behind, once past); the
/// guidance publishes it within [`END_RANGE_M`] and confirms it over frames before that.
pub const END_MEASURE_M: f64 = 8.0;
/// Farthest end of the rows published, metres ahead (and behind, once past): the 5 m within
/// which a steering controller needs it, plus the 0.5 m it may be off. The tracked end comes
/// from 0.2 m bins and trails the truth by up to a bin; cut at exactly 5 m, the first frames
/// with the end 5 m ahead went without it (issue 14's 10-minute drive).
pub const END_RANGE_M: f64 = 5.5;
/// Along the rows, ahead and behind, within which plants make [`RowFitMeasurement::crop_near`].
pub const NEAR_M: f64 = 3.0;

/// Image points of one plant whose errors go together (the fit's variance is inflated by it).
const CORRELATED_PIXELS: f64 = 20.0;

/// Weighted sums of one row's points: w, w·a, w·a², w·a³, w·a⁴, w·r, w·a·r, w·a²·r, w·r², n.
type Sums = [f64; 10];

/// The curvature fit for one camera (one per detector worker: it keeps buffers).
#[derive(Debug, Clone, PartialEq)]
pub struct RowFit {
    opts: RowFitOptions,
    mounting: Mounting,
    robot_from_camera: Rotation3<f64>,
    /// Detected rows' lateral positions on the ground, ascending.
    lines: Vec<f64>,
    sums: Vec<Sums>,
}

/// One pass's arcs: common turn and curvature, each row's own shift.
#[derive(Debug, Clone, Copy, Default)]
struct Arcs {
    beta: f64,
    kappa: f64,
}

impl RowFit {
    pub fn new(mounting: Mounting, opts: RowFitOptions) -> Self {
        RowFit {
            opts,
            mounting,
            robot_from_camera: mounting.robot_from_camera(),
            lines: Vec::with_capacity(64),
            sums: Vec::with_capacity(64),
        }
    }

    /// [`Self::measure`] on a detection and the detector's points: `None` without a
    /// vanishing point.
    pub fn measure_detection(
        &mut self,
        det: &Detection,
        points: &Points,
    ) -> Option<RowFitMeasurement> {
        let vp = det.vanishing_point?.direction;
        self.measure(
            &vp.into(),
            // the edge boundaries measure beside the rows, as in the tracker
            det.rows
                .iter()
                .chain(&det.boundaries)
                .map(|r| r.normal.into()),
            &points.rays,
            &points.weights,
        )
    }

    /// The curvature from the vanishing point `vp` and the rows' plane normals (camera frame)
    /// and the image points `rays` (unit, camera frame) with their `weights`. `None` when too
    /// few points fall near the rows or the fit is degenerate.
    pub fn measure(
        &mut self,
        vp: &[f64; 3],
        normals: impl IntoIterator<Item = [f64; 3]>,
        rays: &[[f32; 3]],
        weights: &[f32],
    ) -> Option<RowFitMeasurement> {
        let frame = GroundFrame::with_rotation(
            &Vector3::from(*vp),
            &self.robot_from_camera,
            &self.mounting,
            0.0,
        )?;
        self.lines.clear();
        for n in normals {
            let n = self.robot_from_camera * Vector3::from(n);
            if let Some(y) = frame.row_lateral_m(&n) {
                if y.abs() <= self.opts.across_m {
                    self.lines.push(y);
                }
            }
        }
        if self.lines.is_empty() {
            return None;
        }
        self.lines.sort_by(f64::total_cmp);
        // lines closer than MERGE_M are one row found twice (both its edges): their mean
        let mut w = 0;
        let mut r = 0;
        while r < self.lines.len() {
            let (mut sum, mut n) = (self.lines[r], 1.0);
            while r + 1 < self.lines.len() && self.lines[r + 1] - self.lines[r] < MERGE_M {
                r += 1;
                sum += self.lines[r];
                n += 1.0;
            }
            self.lines[w] = sum / n;
            w += 1;
            r += 1;
        }
        self.lines.truncate(w);
        let gap = self
            .lines
            .windows(2)
            .map(|w| w[1] - w[0])
            .fold(f64::INFINITY, f64::min);
        let gate = if gap.is_finite() { gap / 3.0 } else { 0.15 };
        let mut arcs = Arcs::default();
        let mut result = None;
        for reach in [1.5, 3.0, self.opts.range_m] {
            let reach = reach.min(self.opts.range_m);
            self.accumulate(&frame, rays, weights, reach, gate, &arcs);
            match self.solve(&arcs) {
                Some((a, m)) => {
                    arcs = a;
                    result = Some(m);
                }
                None => break,
            }
        }
        let max_k = self.opts.max_curvature_per_m;
        let mut m = result
            .filter(|m| m.points >= self.opts.min_points)
            .filter(|m| m.curvature_per_m.is_some_and(|k| k.abs() <= max_k))
            .unwrap_or(RowFitMeasurement {
                curvature_per_m: None,
                sd_per_m: f64::INFINITY,
                points: 0,
                end_of_rows_m: None,
                crop_near: false,
                shift_m: 0.0,
                turn: 0.0,
                shift_sd_m: 0.0,
            });
        if m.curvature_per_m.is_none() {
            arcs = Arcs::default();
        }
        (m.end_of_rows_m, m.crop_near) = self.along_the_rows(&frame, rays, weights, gate, &arcs);
        Some(m)
    }

    /// The rows' points along them: where they end (the distance ahead of the camera's foot
    /// point, negative behind, within [`END_MEASURE_M`]) and whether any grow within
    /// [`NEAR_M`]. A bin of the rows counts as planted when its points' ground area reaches
    /// [`END_RATIO`] of the larger of the two bins at the same distance ahead and behind (the
    /// lens sees both alike) and that larger one is not empty; the rows end after the last
    /// planted bin when at least [`END_EMPTY_M`] of unplanted ones follow it to the bins'
    /// reach. Unplanted bins with planted ones after them are an empty stretch, not the end.
    fn along_the_rows(
        &self,
        frame: &GroundFrame,
        rays: &[[f32; 3]],
        weights: &[f32],
        gate: f64,
        arcs: &Arcs,
    ) -> (Option<f64>, bool) {
        let mut ahead = [0.0f64; END_BINS];
        let mut behind = [0.0f64; END_BINS];
        let h = frame.height_m;
        for (ray, &w) in rays.iter().zip(weights) {
            let ray = Vector3::new(ray[0] as f64, ray[1] as f64, ray[2] as f64);
            let Some([a, l]) = frame.ray_on_ground(&(self.robot_from_camera * ray)) else {
                continue;
            };
            let bin = (a.abs() / END_BIN_M) as usize;
            if bin >= END_BINS || !self.near_an_arc(a, l, gate, arcs) {
                continue;
            }
            let dist2 = a * a + l * l + h * h;
            let w = w as f64 * dist2 * dist2.sqrt() / h;
            if a >= 0.0 {
                ahead[bin] += w;
            } else {
                behind[bin] += w;
            }
        }
        let top = ahead.iter().chain(&behind).fold(0.0f64, |m, &v| m.max(v));
        // bins in order along the rows: i < END_BINS behind (farthest first), then ahead
        let planted = |i: usize| -> bool {
            let (w, j) = if i < END_BINS {
                (behind[END_BINS - 1 - i], END_BINS - 1 - i)
            } else {
                (ahead[i - END_BINS], i - END_BINS)
            };
            let r = ahead[j].max(behind[j]);
            top > 0.0 && r >= 0.01 * top && w >= END_RATIO * r
        };
        let near = (NEAR_M / END_BIN_M).round() as usize;
        let crop_near = (END_BINS - near..END_BINS + near).any(planted);
        let win = (END_EMPTY_M / END_BIN_M).round() as usize;
        let reach = (END_MEASURE_M / END_BIN_M).round() as usize;
        let first = END_BINS.saturating_sub(reach).max(1);
        let last = (END_BINS + reach).min(2 * END_BINS - win);
        // the last planted bin: the rows cannot end before it (an empty stretch ends there)
        let last_planted = (0..2 * END_BINS).rev().find(|&i| planted(i));
        let end = last_planted
            .map(|i| i + 1)
            .filter(|i| (first..=last).contains(i))
            .map(|i| (i as f64 - END_BINS as f64) * END_BIN_M);
        (end, crop_near)
    }

    /// Whether ground point (a, l) lies within `gate` across of a row's predicted arc.
    fn near_an_arc(&self, a: f64, l: f64, gate: f64, arcs: &Arcs) -> bool {
        let shift = arcs.beta * a;
        self.lines.iter().any(|&y| {
            let k = arcs.kappa / (1.0 - arcs.kappa * y);
            (l - (y + shift + k * a * a / 2.0)).abs() < gate
        })
    }

    /// Sums the points within `reach` along the rows that lie within `gate` across of a
    /// row's arc as `arcs` predicts it.
    fn accumulate(
        &mut self,
        frame: &GroundFrame,
        rays: &[[f32; 3]],
        weights: &[f32],
        reach: f64,
        gate: f64,
        arcs: &Arcs,
    ) {
        self.sums.clear();
        self.sums.resize(self.lines.len(), [0.0; 10]);
        let h = frame.height_m;
        for (ray, &w) in rays.iter().zip(weights) {
            let ray = Vector3::new(ray[0] as f64, ray[1] as f64, ray[2] as f64);
            let ray = self.robot_from_camera * ray;
            let Some([a, l]) = frame.ray_on_ground(&ray) else {
                continue;
            };
            if a.abs() > reach {
                continue;
            }
            // the row whose predicted arc passes nearest
            let shift = arcs.beta * a;
            let (mut best, mut best_d) = (usize::MAX, gate);
            for (i, &y) in self.lines.iter().enumerate() {
                let k = arcs.kappa / (1.0 - arcs.kappa * y);
                let d = (l - (y + shift + k * a * a / 2.0)).abs();
                if d < best_d {
                    best = i;
                    best_d = d;
                }
            }
            if best == usize::MAX {
                continue;
            }
            // the ground area of the pixel: solid angle × distance³ / height
            let dist2 = a * a + l * l + h * h;
            let w = w as f64 * dist2 * dist2.sqrt() / h;
            let r = l - self.lines[best];
            let s = &mut self.sums[best];
            let a2 = a * a;
            s[0] += w;
            s[1] += w * a;
            s[2] += w * a2;
            s[3] += w * a2 * a;
            s[4] += w * a2 * a2;
            s[5] += w * r;
            s[6] += w * a * r;
            s[7] += w * a2 * r;
            s[8] += w * r * r;
            s[9] += 1.0;
        }
    }

    /// Solves for the common turn and curvature (two fixed-point rounds for the rows' own
    /// curvatures `κ_i`), starting from `prev`'s curvature.
    fn solve(&self, prev: &Arcs) -> Option<(Arcs, RowFitMeasurement)> {
        let mut kappa = prev.kappa;
        let mut out = None;
        for _ in 0..3 {
            let (mut saa, mut saq, mut sqq, mut sar, mut sqr, mut srr) =
                (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
            let (mut n, mut rows) = (0.0, 0.0);
            for (s, &y) in self.sums.iter().zip(&self.lines) {
                if s[9] < 3.0 || s[0] <= 0.0 {
                    continue;
                }
                // q = g·a²/2: the curvature's regressor for this row
                let g = 1.0 / (1.0 - kappa * y);
                let w = s[0];
                saa += s[2] - s[1] * s[1] / w;
                saq += g / 2.0 * (s[3] - s[1] * s[2] / w);
                sqq += g * g / 4.0 * (s[4] - s[2] * s[2] / w);
                sar += s[6] - s[1] * s[5] / w;
                sqr += g / 2.0 * (s[7] - s[2] * s[5] / w);
                srr += s[8] - s[5] * s[5] / w;
                n += s[9];
                rows += 1.0;
            }
            let det = saa * sqq - saq * saq;
            if rows < 1.0 || n < rows + 3.0 || det.is_nan() || det <= 1e-12 * saa * sqq {
                return None;
            }
            let beta = (sqq * sar - saq * sqr) / det;
            let k = (saa * sqr - saq * sar) / det;
            if !k.is_finite() || k.abs() > 1.0 {
                return None;
            }
            // weighted least squares: cov = σ²·M⁻¹, σ² from the residuals; the pixels of one
            // plant are not independent errors, so the variance is inflated by the pixels a
            // plant spans (about CORRELATED_PIXELS)
            let ssr = (srr - beta * sar - k * sqr).max(0.0);
            let var_unit = ssr / (n - rows - 2.0) * CORRELATED_PIXELS;
            let sd = (var_unit * saa / det).sqrt();
            kappa = k;
            let shift = self.shifts(beta, k, var_unit, [saa, saq, sqq], det);
            out = Some((
                Arcs { beta, kappa: k },
                RowFitMeasurement {
                    curvature_per_m: Some(k),
                    sd_per_m: sd.max(self.opts.min_sd_per_m),
                    points: n as usize,
                    end_of_rows_m: None,
                    crop_near: true,
                    shift_m: shift.0,
                    turn: beta,
                    shift_sd_m: shift.1,
                },
            ));
        }
        out
    }

    /// The rows' own shifts `α_i = (Σw·r − β·Σw·a − κ_i/2·Σw·a²)/Σw`, averaged with the comb's
    /// weights `(1 + (y/h)²)⁻²`, and that mean's standard deviation: each row's mean residual
    /// (`var_unit / Σw`) and the common turn and curvature's covariance (`var_unit·M⁻¹`, `m`
    /// the normal matrix's `[aa, aq, qq]`, `det` its determinant) carried to the camera's foot
    /// point, where the rows' points may lie far away.
    fn shifts(&self, beta: f64, k: f64, var_unit: f64, m: [f64; 3], det: f64) -> (f64, f64) {
        let h = self.mounting.height_m;
        let (mut sa, mut sw, mut noise) = (0.0, 0.0, 0.0);
        let (mut ga, mut gq) = (0.0, 0.0);
        for (s, &y) in self.sums.iter().zip(&self.lines) {
            if s[9] < 3.0 || s[0] <= 0.0 {
                continue;
            }
            let g = 1.0 / (1.0 - k * y);
            let alpha = (s[5] - beta * s[1] - k * g / 2.0 * s[2]) / s[0];
            let w = (1.0 + (y / h).powi(2)).powi(-2);
            sa += w * alpha;
            sw += w;
            noise += w * w / s[0];
            // ∂α_i/∂β = −mean(a), ∂α_i/∂κ = −g·mean(a²)/2
            ga += w * s[1] / s[0];
            gq += w * g / 2.0 * s[2] / s[0];
        }
        if sw <= 0.0 {
            return (0.0, 0.0);
        }
        let (ga, gq) = (ga / sw, gq / sw);
        let [aa, aq, qq] = m;
        let var = var_unit
            * (noise / (sw * sw) + (ga * ga * qq - 2.0 * ga * gq * aq + gq * gq * aa) / det);
        (sa / sw, var.max(0.0).sqrt())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::ideal_fisheye;
    use crate::detect::{Detection, Detector, DetectorOptions};
    use crate::synth::{render, SynthOptions};

    /// Renders a field of curvature `k`, runs the detector and the fit: the measurement.
    fn measured(k: f64, lateral: f64, yaw_deg: f64) -> RowFitMeasurement {
        measured_with(SynthOptions {
            curvature_per_m: k,
            lateral_m: lateral,
            yaw_deg,
            plant_distance_m: 0.05,
            ..Default::default()
        })
    }

    /// Renders `opts`' field, runs the detector and the fit: the measurement.
    fn measured_with(opts: SynthOptions) -> RowFitMeasurement {
        let cal = ideal_fisheye(512, 612).unwrap();
        let (img, truth) = render(&cal, &opts, 3).unwrap();
        let frame = img.into_frame(0, truth);
        let mut det = Detector::new(&cal, DetectorOptions::default()).unwrap();
        let mut out = Detection::default();
        det.process(&frame.view().unwrap(), &mut out).unwrap();
        let vp = out.vanishing_point.expect("a vanishing point").direction;
        let mut fit = RowFit::new(cal.mounting, RowFitOptions::default());
        let p = det.points();
        fit.measure(
            &vp.into(),
            out.rows.iter().map(|r| r.normal.into()),
            &p.rays,
            &p.weights,
        )
        .expect("a curvature")
    }

    #[test]
    fn curved_and_straight_fields_through_the_detector() {
        // the truth at the camera's foot point: c / (1 − c·y_camera)
        for (k, lat, yaw) in [(0.05, 0.25, 3.0), (-0.02, 0.1, -4.0)] {
            let m = measured(k, lat, yaw);
            let truth = k / (1.0 - k * lat);
            assert!(m.crop_near && m.end_of_rows_m.is_none(), "{m:?}");
            let c = m.curvature_per_m.unwrap();
            let err = (c - truth) / truth;
            assert!(err.abs() < 0.05, "{k}: {m:?} vs {truth}");
            assert!(m.points > 1000 && m.sd_per_m < 0.01, "{m:?}");
            // a line one spacing to the left bends by c / (1 − c·y)
            let left = m.at_lateral(0.5).unwrap();
            assert!((left - c / (1.0 - c * 0.5)).abs() < 1e-12);
        }
        let m = measured(0.0, 0.25, 0.0);
        assert!(m.curvature_per_m.unwrap().abs() < 0.002, "{m:?}");
    }

    /// Plants on four arcs of curvature `k` (0.5 m apart, straddling the camera) at the
    /// distances along the rows in `along` (metres, 5 cm apart), jittered by up to ±1 cm,
    /// seen by a camera looking straight down; the rows' lines are the arcs' chords over the
    /// stretch seen. The fit's measurement.
    fn measured_on_arcs(k: f64, along: [f64; 2]) -> RowFitMeasurement {
        let mounting = Mounting::default();
        let h = mounting.height_m;
        let camera_from_robot = mounting.robot_from_camera().inverse();
        let (mut rays, mut normals) = (Vec::new(), Vec::new());
        let n = ((along[1] - along[0]) / 0.05) as usize;
        let mean_a2 = (0..=n)
            .map(|j| (along[0] + 0.05 * j as f64).powi(2))
            .sum::<f64>()
            / (n + 1) as f64;
        for (i, y) in [-0.75, -0.25, 0.25, 0.75].into_iter().enumerate() {
            for j in 0..=n {
                let a = along[0] + 0.05 * j as f64;
                let jitter = 0.01 * ((i * 131 + j * 17) as f64 * 0.618).fract() * 2.0 - 0.01;
                let l = y + k * a * a / 2.0 + jitter;
                let ray = camera_from_robot * Vector3::new(a, l, -h).normalize();
                rays.push([ray.x as f32, ray.y as f32, ray.z as f32]);
            }
            // the chord's plane: through the camera, along x, at y + k·mean(a²)/2
            let chord = y + k * mean_a2 / 2.0;
            normals.push(
                (camera_from_robot * Vector3::new(0.0, h, chord))
                    .normalize()
                    .into(),
            );
        }
        let weights = vec![1.0f32; rays.len()];
        let vp: [f64; 3] = (camera_from_robot * Vector3::x()).into();
        let mut fit = RowFit::new(mounting, RowFitOptions::default());
        fit.measure(&vp, normals, &rays, &weights).expect("a fit")
    }

    #[test]
    fn the_shift_is_loose_when_the_plants_near_the_robot_are_few() {
        let k = 0.01;
        let full = measured_on_arcs(k, [-6.0, 6.0]);
        // the robot at the end of an empty stretch: the rows resume just ahead
        let ahead = measured_on_arcs(k, [1.0, 8.0]);
        for m in [&full, &ahead] {
            assert!(m.crop_near && m.curvature_per_m.is_some(), "{m:?}");
        }
        // with plants all around the camera the arcs pin the shift to millimetres; from
        // plants only ahead it is extrapolated back under the camera and says so
        assert!(full.shift_sd_m > 0.0 && full.shift_sd_m < 0.003, "{full:?}");
        assert!(
            ahead.shift_sd_m > 4.0 * full.shift_sd_m,
            "{full:?} {ahead:?}"
        );
        // and both shifts are within their uncertainty of the truth: the chords lie
        // k·mean(a²)/2 to the left of the arcs' foot points
        let truth = |a: [f64; 2]| -k * (a[1].powi(3) - a[0].powi(3)) / (a[1] - a[0]) / 6.0;
        for (m, a) in [(&full, [-6.0, 6.0]), (&ahead, [1.0, 8.0])] {
            let err = m.shift_m - truth(a);
            assert!(
                err.abs() < 3.0 * m.shift_sd_m + 0.003,
                "{m:?} vs {}",
                truth(a)
            );
        }
    }

    #[test]
    fn too_few_points_or_no_rows_give_nothing() {
        let mut fit = RowFit::new(Mounting::default(), RowFitOptions::default());
        let rays = [[0.0f32, 0.0, 1.0]; 10];
        let w = [1.0f32; 10];
        // rows along the camera's x axis (the default mounting looks down)
        let vp = [1.0, 0.0, 0.0];
        let m = fit.measure(&vp, [[0.0, 1.0, 0.0]], &rays, &w).unwrap();
        assert!(m.curvature_per_m.is_none() && !m.crop_near && m.end_of_rows_m.is_none());
        assert!(fit.measure(&vp, [], &rays, &w).is_none());
        assert!(fit
            .measure(&[0.0, 0.0, 0.0], [[0.0, 1.0, 0.0]], &rays, &w)
            .is_none());
    }
}
