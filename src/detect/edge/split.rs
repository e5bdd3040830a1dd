//! Splitting chains of rays into sections that each lie on one great circle.
//!
//! After Bazin et al., "Rectangle extraction in catadioptric images" (ICCV 2007): a chain is
//! kept whole when all its rays lie within a tolerance of one great circle, and otherwise split
//! at its farthest ray and both halves examined again. The great circle tested is the one
//! through the section's two end rays (Douglas–Peucker on the sphere), which finds a corner
//! even where a least-squares circle would put its worst residual at an end; every accepted
//! section is then fitted by least squares (the smallest singular vector of its rays, through
//! [`Scatter`]) and rejected if that fit still leaves a ray beyond the tolerance. Sections
//! shorter than a minimum length are dropped.

use super::EdgeError;
use crate::sphere::Scatter;
use nalgebra::Vector3;

/// Parameters of the split stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SplitParams {
    /// Largest distance of a ray from its section's great circle, in pixels (converted to an
    /// angle with the calibration's angular pixel size). Default 1.5.
    pub tolerance_px: f64,
    /// Sections with fewer rays are dropped. Default 20.
    pub min_length: usize,
}

impl Default for SplitParams {
    fn default() -> Self {
        SplitParams {
            tolerance_px: 1.5,
            min_length: 20,
        }
    }
}

/// A section of a chain lying on one great circle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Section {
    /// Index of the chain it comes from.
    pub chain: u32,
    /// Start and end (exclusive) of its rays in the chains' flat ray buffer.
    pub start: u32,
    pub end: u32,
    /// Least-squares great-circle normal (canonical sign).
    pub normal: Vector3<f64>,
    /// Scatter of its rays, kept so that merging can refit without the rays.
    pub scatter: Scatter,
    /// Largest angular distance (radians) of its rays from the fitted great circle.
    pub max_residual_rad: f64,
}

impl Section {
    /// Number of rays (the section's support).
    pub fn len(&self) -> usize {
        (self.end - self.start) as usize
    }

    pub fn is_empty(&self) -> bool {
        self.end == self.start
    }
}

/// What one split run did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SplitResult {
    /// Sections kept.
    pub sections: usize,
    /// Pieces dropped as shorter than the minimum length or not fitting a great circle.
    pub dropped: usize,
}

/// Splits chains into great-circle sections, reusing its work stack.
#[derive(Debug, Clone)]
pub struct Splitter {
    params: SplitParams,
    tolerance_rad: f64,
    sin_tol: f64,
    stack: Vec<(u32, u32)>,
}

impl Splitter {
    /// `pixel_angle_rad` is the angle one pixel subtends (to read `tolerance_px`).
    pub fn new(params: SplitParams, pixel_angle_rad: f64) -> Result<Self, EdgeError> {
        if !(params.tolerance_px > 0.0 && params.tolerance_px.is_finite()) {
            return Err(EdgeError::Options(format!(
                "split: tolerance_px = {} must be > 0",
                params.tolerance_px
            )));
        }
        if params.min_length < 3 {
            return Err(EdgeError::Options(format!(
                "split: min_length = {} must be at least 3",
                params.min_length
            )));
        }
        if !(pixel_angle_rad > 0.0 && pixel_angle_rad < 0.5) {
            return Err(EdgeError::Options(format!(
                "split: angular pixel size {pixel_angle_rad} rad is not plausible"
            )));
        }
        let tolerance_rad = params.tolerance_px * pixel_angle_rad;
        Ok(Splitter {
            params,
            tolerance_rad,
            sin_tol: tolerance_rad.sin(),
            stack: Vec::new(),
        })
    }

    pub fn params(&self) -> &SplitParams {
        &self.params
    }

    /// The tolerance as an angle (radians).
    pub fn tolerance_rad(&self) -> f64 {
        self.tolerance_rad
    }

    /// Splits every chain (`ranges` into `rays`) and appends the sections to `out` (cleared
    /// first), in chain order and in order along each chain.
    pub fn split(
        &mut self,
        rays: &[Vector3<f64>],
        ranges: &[(u32, u32)],
        out: &mut Vec<Section>,
    ) -> Result<SplitResult, EdgeError> {
        out.clear();
        let mut result = SplitResult::default();
        let min_len = self.params.min_length as u32;
        for (k, &(a, b)) in ranges.iter().enumerate() {
            if a > b || b as usize > rays.len() {
                return Err(EdgeError::Options(format!(
                    "split: chain {k} range {a}..{b} is outside the {} rays",
                    rays.len()
                )));
            }
            if b - a < min_len {
                result.dropped += 1;
                continue;
            }
            // Inclusive ranges on the stack. On the sphere the farthest ray from a chord can
            // lie inside an arc rather than at a corner, so pieces of any length are kept for
            // now, neighbours that fit one circle are joined again, and only then are short
            // pieces dropped.
            let first = out.len();
            self.stack.clear();
            self.stack.push((a, b - 1));
            while let Some((s, e)) = self.stack.pop() {
                match self.farthest(rays, s, e) {
                    Some((i, d)) if d > self.sin_tol => {
                        // Right half first onto the stack so pieces come out in order.
                        self.stack.push((i + 1, e));
                        self.stack.push((s, i));
                    }
                    _ => {
                        let prev = out[first..].last().filter(|p| p.end == s).map(|p| p.start);
                        let joined = prev.and_then(|ps| self.fit(rays, k as u32, ps, e + 1));
                        match (joined, out.last_mut()) {
                            (Some(j), Some(last)) => *last = j,
                            _ => match self.fit(rays, k as u32, s, e + 1) {
                                Some(sec) => out.push(sec),
                                None => result.dropped += 1,
                            },
                        }
                    }
                }
            }
            let mut keep = first;
            for q in first..out.len() {
                if out[q].len() >= min_len as usize {
                    out[keep] = out[q];
                    keep += 1;
                } else {
                    result.dropped += 1;
                }
            }
            out.truncate(keep);
        }
        result.sections = out.len();
        Ok(result)
    }

    /// The ray of `s..=e` farthest from the great circle through rays `s` and `e`, with the
    /// sine of its distance.
    fn farthest(&self, rays: &[Vector3<f64>], s: u32, e: u32) -> Option<(u32, f64)> {
        if e <= s + 1 {
            return None;
        }
        let (ps, pe) = (&rays[s as usize], &rays[e as usize]);
        let n = ps.cross(pe);
        let norm = n.norm();
        let mut best = (s, -1.0);
        if norm > 1e-9 {
            let n = n / norm;
            for i in s + 1..e {
                let d = n.dot(&rays[i as usize]).abs();
                if d > best.1 {
                    best = (i, d);
                }
            }
        } else {
            // Ends coincide (a closed chain): split at the ray farthest from the start.
            for i in s + 1..e {
                let d = ps.cross(&rays[i as usize]).norm();
                if d > best.1 {
                    best = (i, d);
                }
            }
            best.1 = f64::INFINITY;
        }
        Some(best)
    }

    /// Least-squares section over rays `s..e`, or `None` when the fit leaves a ray beyond
    /// the tolerance or is undefined.
    fn fit(&self, rays: &[Vector3<f64>], chain: u32, s: u32, e: u32) -> Option<Section> {
        let pts = &rays[s as usize..e as usize];
        let mut scatter = Scatter::new();
        for p in pts {
            scatter.add(p, 1.0);
        }
        let fit = scatter.fit()?;
        let n = fit.normal;
        let max_sin = pts.iter().fold(0.0f64, |m, p| m.max(n.dot(p).abs()));
        if max_sin > self.sin_tol {
            return None;
        }
        Some(Section {
            chain,
            start: s,
            end: e,
            normal: n,
            scatter,
            max_residual_rad: max_sin.min(1.0).asin(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sphere::{any_perpendicular, axis_angle, from_phi_theta};
    use proptest::prelude::*;

    /// `n` rays along the great circle with normal `normal`, from angle `t0` in steps `dt`.
    fn arc(normal: &Vector3<f64>, t0: f64, dt: f64, n: usize) -> Vec<Vector3<f64>> {
        let u = any_perpendicular(normal);
        let v = normal.cross(&u);
        (0..n)
            .map(|i| {
                let t = t0 + dt * i as f64;
                u * t.cos() + v * t.sin()
            })
            .collect()
    }

    /// A chain of `k` great-circle arcs joined end to end: each arc starts where the previous
    /// one ended and turns by `turn` radians about that point.
    fn polyline(
        first: &Vector3<f64>,
        turns: &[f64],
        per: usize,
        dt: f64,
    ) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
        let mut normals = vec![*first];
        let mut pts = arc(first, 0.0, dt, per);
        for &turn in turns {
            let end = *pts.last().unwrap();
            let prev = *normals.last().unwrap();
            // Rotate the previous normal about the end point by `turn`.
            let rot =
                nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(end), turn);
            let n = rot * prev;
            // Continue from `end` along the new circle, in the forward direction.
            let tangent = n.cross(&end);
            let fwd = prev.cross(&end);
            let sgn = if tangent.dot(&fwd) < 0.0 { -1.0 } else { 1.0 };
            for i in 1..=per {
                let t = sgn * dt * i as f64;
                pts.push(end * t.cos() + tangent * t.sin());
            }
            normals.push(n);
        }
        (pts, normals)
    }

    #[test]
    fn straight_chain_is_one_section() {
        let n = from_phi_theta(1.0, 2.0);
        let rays = arc(&n, 0.3, 0.002, 200);
        let mut sp = Splitter::new(SplitParams::default(), 0.0016).unwrap();
        let mut out = Vec::new();
        let r = sp.split(&rays, &[(0, 200)], &mut out).unwrap();
        assert_eq!(r.sections, 1);
        assert_eq!(out[0].len(), 200);
        assert!(axis_angle(&out[0].normal, &n) < 1e-9);
    }

    #[test]
    fn short_chains_dropped_and_bad_ranges_rejected() {
        let n = from_phi_theta(1.0, 2.0);
        let rays = arc(&n, 0.3, 0.002, 10);
        let mut sp = Splitter::new(SplitParams::default(), 0.0016).unwrap();
        let mut out = Vec::new();
        let r = sp.split(&rays, &[(0, 10)], &mut out).unwrap();
        assert_eq!((r.sections, r.dropped), (0, 1));
        assert!(sp.split(&rays, &[(0, 11)], &mut out).is_err());
        assert!(Splitter::new(SplitParams::default(), 0.0).is_err());
    }

    proptest! {
        #[test]
        fn joined_arcs_split_into_their_circles(
            phi in 0.2f64..2.9, theta in 0.0f64..6.2,
            turns in proptest::collection::vec((0.4f64..1.2, proptest::bool::ANY), 0..4),
            per in 40usize..120,
            noise_seed in 0u64..1000,
        ) {
            let first = from_phi_theta(phi, theta);
            let turns: Vec<f64> = turns.iter().map(|&(t, s)| if s { t } else { -t }).collect();
            let dt = 0.0016;
            let (mut pts, normals) = polyline(&first, &turns, per, dt);
            // Sub-pixel jitter, well inside the tolerance.
            let mut x = noise_seed.wrapping_mul(6364136223846793005).wrapping_add(1);
            for p in pts.iter_mut() {
                x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let j = ((x >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.3 * dt;
                let off = any_perpendicular(p);
                *p = (*p + off * j).normalize();
            }
            // A piece straddling a corner stays within the tolerance over up to about
            // 2·tolerance/sin(turn) rays (≈ 8 here); sections must be longer than that.
            let mut sp = Splitter::new(SplitParams { tolerance_px: 1.5, min_length: 16 }, dt).unwrap();
            let mut out = Vec::new();
            sp.split(&pts, &[(0, pts.len() as u32)], &mut out).unwrap();
            prop_assert_eq!(out.len(), normals.len(), "sections {:?}", out.iter().map(|s| (s.start, s.end)).collect::<Vec<_>>());
            for (s, n) in out.iter().zip(&normals) {
                prop_assert!(axis_angle(&s.normal, n) < 0.02, "normal off by {}", axis_angle(&s.normal, n));
                prop_assert!(s.len() + 10 >= per && s.len() <= per + 10, "section length {} in {:?}", s.len(), out.iter().map(|s| (s.start, s.end)).collect::<Vec<_>>());
                prop_assert!(s.max_residual_rad <= sp.tolerance_rad());
            }
            // Sections are ordered and disjoint.
            for w in out.windows(2) {
                prop_assert!(w[0].end <= w[1].start);
            }
        }
    }
}
