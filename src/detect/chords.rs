//! The edge method on a curved field: its rows are chords, turned back to their tangents.
//!
//! Owns the bend of the edge rows. On a fisheye or PAL image each edge row is a boundary's
//! chain on one side of the robot only (the chains break at the robot's foot and the mask),
//! a few camera heights ahead or behind. On a field curved to κ (1/radius) such a chord
//! turns from its row's tangent beside the robot by atan(k·ā), ā the chord's mean distance
//! along the rows (negative behind) and k its row's curvature (the rows are concentric:
//! 1/(1/κ − l) for the row l to the left): those ahead one way, those behind the other, and
//! the vote for the vanishing point takes one side. [`ChordBend`] fits the rows' heading and
//! κ to the chords' headings (Gauss–Newton, Tukey's biweight against chords of no row), and
//! where κ stands out of its noise turns each chord on the fit to its row's tangent beside
//! the robot, where the rows are parallel, so that the vote finds their direction where the
//! robot is. The detector keeps the turned rows only when they agree on a vanishing point
//! where the chords did not (a tilted robot on a straight field also makes the chords'
//! headings on the nominal ground change with the distance ahead).

use super::types::Row;
use crate::detect::edge::{merge, Section};
use nalgebra::{Matrix2, Rotation3, Vector2, Vector3};

/// The bend found in the chords: the rows' heading beside the robot (radians, from the
/// robot's forward axis, counter-clockwise) and their curvature (1/camera heights).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bend {
    pub heading: f64,
    pub curvature: f64,
    /// How many standard deviations of its noise the curvature stands from zero.
    pub sigma: f64,
    /// The chords on the line: within `scale` (radians) of it.
    pub chords: usize,
    pub scale: f64,
}

/// One edge row's chord on the ground: its heading (folded into (−π/2, π/2]), its points'
/// mean distance ahead, and its weight (its points on the ground).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Chord {
    row: usize,
    heading: f64,
    ahead: f64,
    /// Its points' mean offset to the left of the robot.
    left: f64,
    weight: f64,
}

impl Chord {
    /// The chord's mean point along and to the left of rows heading `h`.
    fn along(&self, h: f64) -> (f64, f64) {
        let (s, c) = h.sin_cos();
        (
            self.ahead * c + self.left * s,
            self.left * c - self.ahead * s,
        )
    }
}

impl Bend {
    /// The curvature of the row `l` camera heights to the left of the robot where it passes
    /// the robot: the rows are concentric, 1 / (1/κ − l).
    fn curvature_at(&self, l: f64) -> f64 {
        self.curvature / (1.0 - self.curvature * l)
    }

    /// Where a chord's row passes the robot (to the left, camera heights) and that row's
    /// curvature: its arc lies ½·k·ā² to the side of its tangent at the chord's mean point.
    fn row_of(&self, c: &Chord) -> (f64, f64, f64) {
        let (a, l) = c.along(self.heading);
        let mut k = self.curvature_at(l);
        let foot = l - 0.5 * k * a * a;
        k = self.curvature_at(foot);
        (a, foot, k)
    }

    /// A chord's heading off the bend's: the chord of an arc of curvature k turns by
    /// atan(k·ā) from the arc's tangent beside the robot.
    fn residual(&self, c: &Chord) -> f64 {
        let (a, _, k) = self.row_of(c);
        fold(c.heading - self.heading) - (k * a).atan()
    }

    /// tan of a chord's turn from the heading, less the model's k·ā, and the terms of its
    /// linearisation in a step of the heading (δ) and of κ: tan(d − δ) ≈ tan d − δ·(1 +
    /// tan² d), and k·ā = ā·κ / (1 − κ·l) grows by ā / (1 − κ·l)² per unit of κ.
    fn terms(&self, c: &Chord) -> (f64, Vector2<f64>) {
        let (a, foot, k) = self.row_of(c);
        let t = fold(c.heading - self.heading).tan();
        let q = 1.0 - self.curvature * foot;
        (t - k * a, Vector2::new(1.0 + t * t, a / (q * q)))
    }
}

/// Tukey's biweight tuning constant (95 % efficiency), times the MAD's normal scale.
const TUKEY: f64 = 4.685 * 1.4826;
/// Rounds of the reweighted fit.
const ROUNDS: usize = 8;
/// The residuals' scale never drops below this (radians): chords are not that precise.
const MIN_SCALE: f64 = 0.005;
/// The largest turn of a chord from the rows' heading that takes part in the fit (radians).
const MAX_TURN: f64 = 1.0;
/// The largest curvature fitted (1/camera heights): a radius of 4 camera heights.
const MAX_CURVATURE: f64 = 0.25;

/// The edge rows' bend and the buffers reused from frame to frame.
#[derive(Debug, Clone, Default)]
pub struct ChordBend {
    chords: Vec<Chord>,
    residuals: Vec<f64>,
    /// Every row's points on the ground, row after row, and each row's range of them.
    points: Vec<Vector3<f64>>,
    spans: Vec<std::ops::Range<usize>>,
    /// The sections ordered by their row (counting sort), and where each row's begin.
    order: Vec<u32>,
    firsts: Vec<usize>,
}

impl ChordBend {
    /// Finds the bend of `rows` (the edge method's, the rows of `sections` by `assignment`,
    /// their rays in `rays`) and, when its curvature stands `min_sigma` of its noise from
    /// zero, turns each row to its tangent beside the robot. `robot_from_camera` is the
    /// mounting's rotation. Returns the bend when the rows were turned.
    pub fn turn(
        &mut self,
        rows: &mut [Row],
        sections: &[Section],
        assignment: &[u32],
        rays: &[Vector3<f64>],
        robot_from_camera: &Rotation3<f64>,
        min_sigma: f64,
    ) -> Option<Bend> {
        self.group_points(rows.len(), sections, assignment, rays, robot_from_camera);
        self.chords.clear();
        for (k, row) in rows.iter().enumerate() {
            let points = &self.points[self.spans[k].clone()];
            if let Some(c) = chord(k, row, points, robot_from_camera) {
                self.chords.push(c);
            }
        }
        let bend = self.fit()?;
        if bend.sigma.is_nan() || bend.sigma.abs() < min_sigma {
            return None;
        }
        for c in &self.chords {
            // a chord off the line is no row boundary (or not one of these rows): as it is
            if bend.residual(c).abs() >= bend.scale {
                continue;
            }
            let (_, _, k) = bend.row_of(c);
            let points = &self.points[self.spans[c.row].clone()];
            if let Some(n) = tangent(bend.heading, k, points, robot_from_camera) {
                rows[c.row].normal = n;
            }
        }
        Some(bend)
    }

    /// The points of each of the `rows` on the ground, robot frame, camera heights (z = −1):
    /// its sections' rays below the horizon, into `self.points`, row after row (each row's
    /// sections in their order), and each row's range of them into `self.spans`.
    fn group_points(
        &mut self,
        rows: usize,
        sections: &[Section],
        assignment: &[u32],
        rays: &[Vector3<f64>],
        robot_from_camera: &Rotation3<f64>,
    ) {
        let row_of = |a: u32| (a != merge::NONE && (a as usize) < rows).then_some(a as usize);
        self.firsts.clear();
        self.firsts.resize(rows + 1, 0);
        for &a in assignment.iter().take(sections.len()) {
            if let Some(k) = row_of(a) {
                self.firsts[k + 1] += 1;
            }
        }
        for k in 0..rows {
            self.firsts[k + 1] += self.firsts[k];
        }
        self.order.clear();
        self.order.resize(self.firsts[rows], 0);
        // the spans first serve as each row's cursor into `order`
        let mut next = std::mem::take(&mut self.spans);
        next.clear();
        next.extend((0..rows).map(|k| self.firsts[k]..self.firsts[k]));
        for (i, &a) in assignment.iter().take(sections.len()).enumerate() {
            if let Some(k) = row_of(a) {
                self.order[next[k].end] = i as u32;
                next[k].end += 1;
            }
        }
        self.points.clear();
        for (k, span) in next.iter_mut().enumerate() {
            let start = self.points.len();
            for &i in &self.order[self.firsts[k]..self.firsts[k + 1]] {
                let s = &sections[i as usize];
                for x in rays.get(s.start as usize..s.end as usize).unwrap_or(&[]) {
                    let r = robot_from_camera * x;
                    if r.z < -0.05 {
                        self.points.push(r / -r.z);
                    }
                }
            }
            *span = start..self.points.len();
        }
        self.spans = next;
    }

    /// The bend through the chords (each turned by atan(k·ā) from the heading h, k the
    /// curvature of its concentric row; Gauss–Newton steps, weighted by their points and
    /// Tukey's biweight on the residuals), and κ's standard deviation from the weighted
    /// residuals. `None` with fewer than six chords or a singular fit.
    fn fit(&mut self) -> Option<Bend> {
        if self.chords.len() < 6 {
            return None;
        }
        let mut bend = Bend {
            heading: 0.0,
            curvature: 0.0,
            sigma: 0.0,
            chords: 0,
            scale: f64::INFINITY,
        };
        let mut cov = Matrix2::zeros();
        for _ in 0..ROUNDS {
            let (mut ata, mut aty) = (Matrix2::<f64>::zeros(), Vector2::<f64>::zeros());
            let mut chi2 = 0.0;
            let mut used = 0usize;
            for c in &self.chords {
                let r = bend.residual(c);
                let z = r / bend.scale;
                let w = c.weight
                    * if z.abs() < 1.0 {
                        (1.0 - z * z).powi(2)
                    } else {
                        0.0
                    };
                // a chord turned that far from the rows is none of theirs (and its tangent
                // would swamp the linearisation)
                let w = if fold(c.heading - bend.heading).abs() < MAX_TURN {
                    w
                } else {
                    0.0
                };
                if w > 0.0 {
                    let (t, phi) = bend.terms(c);
                    ata += w * phi * phi.transpose();
                    aty += w * t * phi;
                    chi2 += w * r * r;
                    used += 1;
                }
            }
            let inv = ata.try_inverse()?;
            let step = inv * aty;
            bend.heading = fold(bend.heading + step[0]);
            // a step that would put the robot beyond the bend's centre is cut short
            bend.curvature = (bend.curvature + step[1]).clamp(-MAX_CURVATURE, MAX_CURVATURE);
            bend.chords = used;
            self.residuals.clear();
            self.residuals
                .extend(self.chords.iter().map(|c| bend.residual(c).abs()));
            let mid = self.residuals.len() / 2;
            let mad = *self.residuals.select_nth_unstable_by(mid, f64::total_cmp).1;
            bend.scale = (TUKEY * mad).max(MIN_SCALE);
            // the weights are relative: the residuals give their scale
            cov = inv * (chi2 / used.saturating_sub(2).max(1) as f64);
        }
        let sd = cov[(1, 1)].max(0.0).sqrt();
        bend.sigma = if sd > 0.0 { bend.curvature / sd } else { 0.0 };
        Some(bend)
    }
}

/// An edge row's chord: its great circle's direction on the ground (robot frame) and its
/// points' mean distance ahead. `None` for a row along the horizon or with fewer than 10
/// points on the ground.
fn chord(
    k: usize,
    row: &Row,
    points: &[Vector3<f64>],
    robot_from_camera: &Rotation3<f64>,
) -> Option<Chord> {
    if points.len() < 10 {
        return None;
    }
    let n = robot_from_camera * row.normal;
    // the great circle meets the ground plane along n × up
    let d = n.cross(&Vector3::z());
    if d.norm() < 0.05 {
        return None;
    }
    let n_points = points.len() as f64;
    Some(Chord {
        row: k,
        heading: fold(d.y.atan2(d.x)),
        ahead: points.iter().map(|p| p.x).sum::<f64>() / n_points,
        left: points.iter().map(|p| p.y).sum::<f64>() / n_points,
        weight: n_points,
    })
}

/// The great circle (camera frame, canonical) of the tangent beside the robot of the arc of
/// curvature κ through the chord's points: every row's tangent there has the bend's heading
/// (the rows are parallel where the robot is), at the lateral offset where the chord's arc
/// passes the robot.
fn tangent(
    h: f64,
    k: f64,
    points: &[Vector3<f64>],
    robot_from_camera: &Rotation3<f64>,
) -> Option<Vector3<f64>> {
    if points.is_empty() {
        return None;
    }
    let along = Vector3::new(h.cos(), h.sin(), 0.0);
    let left = Vector3::new(-h.sin(), h.cos(), 0.0);
    let offset = points
        .iter()
        .map(|p| {
            let a = p.dot(&along);
            p.dot(&left) - 0.5 * k * a * a
        })
        .sum::<f64>()
        / points.len() as f64;
    let foot = Vector3::new(0.0, 0.0, -1.0) + left * offset;
    let n = robot_from_camera.inverse() * foot.cross(&along);
    n.try_normalize(1e-12).map(|n| crate::sphere::canonical(&n))
}

/// An angle folded into (−π/2, π/2] (a line's heading, either way along it).
fn fold(h: f64) -> f64 {
    use std::f64::consts::{FRAC_PI_2, PI};
    let mut h = h.rem_euclid(PI);
    if h > FRAC_PI_2 {
        h -= PI;
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points (robot frame, z = −1) of the row `left` camera heights to the left of the
    /// robot on a field of curvature `k` (centre to the left) heading `h`, from `x0` to
    /// `x1` ahead of the robot.
    fn arc(h: f64, k: f64, left: f64, x0: f64, x1: f64) -> Vec<Vector3<f64>> {
        let kr = if k == 0.0 {
            0.0
        } else {
            1.0 / (1.0 / k - left)
        };
        (0..40)
            .map(|i| {
                let a = x0 + (x1 - x0) * i as f64 / 39.0;
                let y = left + 0.5 * kr * a * a;
                let (s, c) = h.sin_cos();
                Vector3::new(a * c - y * s, a * s + y * c, -1.0)
            })
            .collect()
    }

    /// The chord of `points`: their least-squares line's heading, mean x and y.
    fn chord_of(row: usize, points: &[Vector3<f64>]) -> Chord {
        let n = points.len() as f64;
        let (mx, my) = (
            points.iter().map(|p| p.x).sum::<f64>() / n,
            points.iter().map(|p| p.y).sum::<f64>() / n,
        );
        let (mut sxx, mut sxy) = (0.0, 0.0);
        for p in points {
            sxx += (p.x - mx) * (p.x - mx);
            sxy += (p.x - mx) * (p.y - my);
        }
        Chord {
            row,
            heading: fold(sxy.atan2(sxx)),
            ahead: mx,
            left: my,
            weight: n,
        }
    }

    fn field(h: f64, k: f64) -> ChordBend {
        let mut b = ChordBend::default();
        let mut row = 0;
        for j in -4..=4 {
            let left = 0.75 * j as f64;
            for (x0, x1) in [(3.0, 6.0), (-6.0, -3.5), (2.5, 5.0)] {
                b.chords.push(chord_of(row, &arc(h, k, left, x0, x1)));
                row += 1;
            }
        }
        b
    }

    #[test]
    fn the_chords_of_a_curved_field_give_its_heading_and_curvature_beside_the_robot() {
        for (h, k) in [(-0.07, 0.05), (0.1, -0.1), (0.0, 0.05)] {
            let mut b = field(h, k);
            // a chord of no row
            b.chords.push(Chord {
                row: 99,
                heading: 0.6,
                ahead: 4.0,
                left: 1.0,
                weight: 40.0,
            });
            let bend = b.fit().expect("a bend");
            assert!((bend.heading - h).abs() < 2e-3, "{h} {k}: {bend:?}");
            assert!(
                (bend.curvature - k).abs() < 0.1 * k.abs(),
                "{h} {k}: {bend:?}"
            );
            assert!(bend.sigma.abs() > 4.0, "{bend:?}");
            assert!(bend.chords >= 24 && bend.chords <= 27, "{bend:?}");
            assert!(b
                .chords
                .last()
                .is_some_and(|c| bend.residual(c).abs() > bend.scale));
        }
        let straight = field(0.05, 0.0).fit().expect("a fit");
        assert!((straight.heading - 0.05).abs() < 1e-9, "{straight:?}");
        assert!(straight.sigma.abs() < 4.0, "{straight:?}");
    }

    #[test]
    fn a_chord_is_turned_to_its_rows_tangent_where_the_robot_is() {
        let (h, k, left) = (0.08, 0.05, 1.5);
        let points = arc(h, k, left, 3.0, 6.0);
        let kr = 1.0 / (1.0 / k - left);
        let n = tangent(h, kr, &points, &Rotation3::identity()).expect("a tangent");
        // the tangent beside the robot: through (−s·left, c·left, −1) along (c, s, 0)
        let (s, c) = h.sin_cos();
        let foot = Vector3::new(-s * left, c * left, -1.0);
        let truth = crate::sphere::canonical(&foot.cross(&Vector3::new(c, s, 0.0)).normalize());
        assert!(
            crate::sphere::axis_angle(&n, &truth) < 1e-9,
            "{n:?} {truth:?}"
        );
        assert_eq!(tangent(h, k, &[], &Rotation3::identity()), None);
    }

    #[test]
    fn a_lines_heading_is_folded_either_way_along_it() {
        use std::f64::consts::PI;
        for h in [-1.5, -0.3, 0.0, 0.7, 1.5] {
            assert!((fold(h) - h).abs() < 1e-12);
            assert!((fold(h + PI) - h).abs() < 1e-12);
            assert!((fold(h - PI) - h).abs() < 1e-12);
        }
        assert!((fold(PI / 2.0) - PI / 2.0).abs() < 1e-12);
    }
}
