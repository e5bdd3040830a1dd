//! Crop rows, not edges: the centre lines that the edge and combined methods publish.
//!
//! Owns the step after their vanishing point is fixed. The edge method finds a crop row's two
//! boundaries (plant against soil on either side); a steering controller wants the row's
//! centre line and, as a bonus, its width. Every row here is a plane through the vanishing
//! point, so it is an angle ψ around it (modulo π), and a row's width is the angle between
//! its boundaries. With Hough rows present (the combined method), each Hough row is the
//! centre line and takes its width from the boundaries either side of it (the strongest edge
//! row on each side within half the way to the next Hough row, as
//! [`super::combine::pair_edge_rows`] pairs them for the fit); the edge rows themselves are
//! then evidence for the vanishing point, not published rows. With edge rows only, two
//! neighbouring boundaries are one crop row when the band between them holds more
//! vegetation per unit angle than the bands of the same width outside them (`MIN_CONTRAST`
//! times their mean): the band between the boundaries of one row is plants, the band
//! between two rows is soil. Such a pair becomes its bisecting plane with the pair's width;
//! boundaries that pair with nothing are not published. Buffers are reused: a warmed-up
//! caller allocates nothing.

use super::types::{Detection, Method, Row};
use nalgebra::Vector3;
use std::f64::consts::PI;

/// A pair of neighbouring boundaries is one crop row when its band holds at least this
/// times the vegetation per unit angle of the bands either side.
pub const MIN_CONTRAST: f64 = 1.5;

/// The reusable state of [`CentreLines::publish`].
#[derive(Debug, Clone, Default)]
pub struct CentreLines {
    /// (ψ, index into the rows) of the rows, sorted by ψ.
    psi: Vec<(f64, usize)>,
    /// The vegetation points' ψ, sorted, and the cumulative weight up to each.
    pts: Vec<(f64, f64)>,
    cum: Vec<f64>,
    /// Candidate pairs (contrast, first, second) as indices into `psi`.
    cand: Vec<(f64, usize, usize)>,
    used: Vec<bool>,
    out: Vec<Row>,
}

/// The angle basis around a vanishing point: ψ of a plane through it is the angle of its
/// normal from `a` towards `b`.
#[derive(Debug, Clone, Copy)]
struct Basis {
    vp: Vector3<f64>,
    a: Vector3<f64>,
    b: Vector3<f64>,
}

impl Basis {
    fn new(vp: &Vector3<f64>) -> Self {
        let vp = vp.normalize();
        let a = crate::sphere::any_perpendicular(&vp);
        Basis {
            vp,
            a,
            b: vp.cross(&a),
        }
    }

    /// ψ of a row's normal, in [0, π).
    fn of_normal(&self, n: &Vector3<f64>) -> f64 {
        n.dot(&self.b).atan2(n.dot(&self.a)).rem_euclid(PI)
    }

    /// ψ of the plane through the vanishing point and a ray; `None` near the vanishing point.
    fn of_ray(&self, r: &Vector3<f64>) -> Option<f64> {
        let n = self.vp.cross(r);
        (n.norm_squared() > 1e-8).then(|| self.of_normal(&n))
    }

    /// The normal at angle ψ.
    fn normal(&self, psi: f64) -> Vector3<f64> {
        self.a * psi.cos() + self.b * psi.sin()
    }
}

/// Signed difference of two angles modulo π, in [−π/2, π/2).
fn wrap(d: f64) -> f64 {
    (d + 0.5 * PI).rem_euclid(PI) - 0.5 * PI
}

/// Half the way from `ph` to the nearest of the `others` (angles around the vanishing point),
/// at most `max`: how far a row's boundaries may lie from it.
pub(super) fn half_way_limit(ph: f64, max: f64, others: impl Iterator<Item = f64>) -> f64 {
    let mut limit = max;
    for p in others {
        let d = wrap(p - ph).abs();
        if d > 1e-9 {
            limit = limit.min(0.5 * d);
        }
    }
    limit
}

/// Among `candidates` (angle, support, id), the one of largest support (the first of equals)
/// on each side of `ph` within `limit`: [left, right] as (support, signed angle from `ph`, id).
/// A long, exact boundary wins over a short stray section nearer the row's centre.
pub(super) fn strongest_either_side(
    ph: f64,
    limit: f64,
    candidates: impl Iterator<Item = (f64, u32, usize)>,
) -> [Option<(u32, f64, usize)>; 2] {
    let mut sides: [Option<(u32, f64, usize)>; 2] = [None, None];
    for (p, support, id) in candidates {
        let d = wrap(p - ph);
        if d.abs() >= limit {
            continue;
        }
        let side = &mut sides[usize::from(d >= 0.0)];
        if side.is_none_or(|(best, _, _)| support > best) {
            *side = Some((support, d, id));
        }
    }
    sides
}

impl CentreLines {
    /// The edge and combined methods' published rows: the edge rows of `out` (boundaries)
    /// move to `out.boundaries`; those through the vanishing point (within `sin_tol`, the
    /// sine of the inlier tolerance) become the widths of the Hough rows, or pair into centre
    /// lines ([`Self::publish`], rows at most `max_half_rad` half-wide), the rest are
    /// dropped. Without a vanishing point no boundary is published.
    pub fn publish_detection(
        &mut self,
        out: &mut Detection,
        sin_tol: f64,
        max_half_rad: f64,
        rays: &[[f32; 3]],
        weights: &[f32],
    ) {
        out.boundaries.clear();
        out.boundaries
            .extend(out.rows.iter().filter(|r| r.method == Method::Edge));
        let Some(vp) = out.vanishing_point.map(|v| v.direction) else {
            out.rows.retain(|r| r.method != Method::Edge);
            return;
        };
        out.rows
            .retain(|r| r.method != Method::Edge || r.normal.dot(&vp).abs() < sin_tol);
        self.publish(&mut out.rows, &vp, max_half_rad, rays, weights);
    }

    /// Replaces `rows` (through the vanishing point `vp`) by the crop rows' centre lines:
    /// see the module's text. `max_half_rad` bounds a row's half-width; `rays` and
    /// `weights` are the image's vegetation points (used only with edge rows alone).
    /// Returns the number of rows given a width.
    pub fn publish(
        &mut self,
        rows: &mut Vec<Row>,
        vp: &Vector3<f64>,
        max_half_rad: f64,
        rays: &[[f32; 3]],
        weights: &[f32],
    ) -> usize {
        let basis = Basis::new(vp);
        let has_hough = rows.iter().any(|r| r.method != Method::Edge);
        let widened = if has_hough {
            self.widen_hough_rows(rows, &basis, max_half_rad)
        } else {
            self.pair_boundaries(rows, &basis, max_half_rad, rays, weights)
        };
        rows.clear();
        rows.extend_from_slice(&self.out);
        widened
    }

    /// Each non-edge row with its width from the boundaries either side into `self.out`.
    fn widen_hough_rows(&mut self, rows: &[Row], basis: &Basis, max_half_rad: f64) -> usize {
        self.out.clear();
        self.psi.clear();
        self.psi.extend(
            rows.iter()
                .enumerate()
                .map(|(i, r)| (basis.of_normal(&r.normal), i)),
        );
        let mut widened = 0;
        for (i, r) in rows.iter().enumerate() {
            if r.method == Method::Edge {
                continue;
            }
            let ph = self.psi[i].0;
            let others = self
                .psi
                .iter()
                .filter(|&&(_, j)| rows[j].method != Method::Edge && j != i)
                .map(|&(p, _)| p);
            let limit = half_way_limit(ph, max_half_rad, others);
            let edges = self
                .psi
                .iter()
                .filter(|&&(_, j)| rows[j].method == Method::Edge)
                .map(|&(p, j)| (p, rows[j].support, j));
            let [left, right] = strongest_either_side(ph, limit, edges);
            let mut row = *r;
            if let (Some((_, l, _)), Some((_, rr, _))) = (left, right) {
                row.width_rad = l.abs() + rr.abs();
                widened += 1;
            }
            self.out.push(row);
        }
        widened
    }

    /// Neighbouring edge rows that bound a band of vegetation, as centre lines into
    /// `self.out`.
    fn pair_boundaries(
        &mut self,
        rows: &[Row],
        basis: &Basis,
        max_half_rad: f64,
        rays: &[[f32; 3]],
        weights: &[f32],
    ) -> usize {
        self.out.clear();
        self.psi.clear();
        self.psi.extend(
            rows.iter()
                .enumerate()
                .map(|(i, r)| (basis.of_normal(&r.normal), i)),
        );
        self.psi.sort_unstable_by(|x, y| x.0.total_cmp(&y.0));
        self.index_points(basis, rays, weights);
        let n = self.psi.len();
        self.cand.clear();
        if n >= 2 {
            for k in 0..n {
                // neighbours in ψ, around the wrap too (with two rows, both arcs)
                let l = (k + 1) % n;
                let (p0, p1) = (self.psi[k].0, self.psi[l].0);
                let g = (p1 - p0).rem_euclid(PI);
                if g <= 1e-9 || g > 2.0 * max_half_rad {
                    continue;
                }
                let inside = self.density(p0, g);
                let flanks =
                    0.5 * (self.density(p0 - 0.5 * g, 0.5 * g) + self.density(p1, 0.5 * g));
                if inside > 0.0 && inside >= MIN_CONTRAST * flanks {
                    let contrast = if flanks > 0.0 {
                        inside / flanks
                    } else {
                        f64::MAX
                    };
                    self.cand.push((contrast, k, l));
                }
            }
        }
        self.cand.sort_unstable_by(|x, y| y.0.total_cmp(&x.0));
        self.used.clear();
        self.used.resize(n, false);
        for c in 0..self.cand.len() {
            let (_, k, l) = self.cand[c];
            if self.used[k] || self.used[l] {
                continue;
            }
            self.used[k] = true;
            self.used[l] = true;
            let (p0, i0) = self.psi[k];
            let (_, i1) = self.psi[l];
            let g = (self.psi[l].0 - p0).rem_euclid(PI);
            self.out.push(Row {
                normal: basis.normal(p0 + 0.5 * g),
                method: rows[i0].method,
                support: rows[i0].support.saturating_add(rows[i1].support),
                width_rad: g,
            });
        }
        self.out.len()
    }

    /// Sorts the points' ψ and their cumulative weights for [`Self::density`].
    fn index_points(&mut self, basis: &Basis, rays: &[[f32; 3]], weights: &[f32]) {
        self.pts.clear();
        for (r, &w) in rays.iter().zip(weights) {
            if !(w > 0.0 && w.is_finite()) {
                continue;
            }
            let v = Vector3::new(r[0] as f64, r[1] as f64, r[2] as f64);
            if let Some(p) = basis.of_ray(&v) {
                self.pts.push((p, w as f64));
            }
        }
        self.pts.sort_unstable_by(|x, y| x.0.total_cmp(&y.0));
        self.cum.clear();
        let mut acc = 0.0;
        self.cum.push(0.0);
        for &(_, w) in &self.pts {
            acc += w;
            self.cum.push(acc);
        }
    }

    /// Weight of the points with ψ in [from, from + width) modulo π, per radian.
    fn density(&self, from: f64, width: f64) -> f64 {
        if width <= 0.0 || self.pts.is_empty() {
            return 0.0;
        }
        let lo = from.rem_euclid(PI);
        let hi = lo + width;
        let upto = |x: f64| self.cum[self.pts.partition_point(|p| p.0 < x)];
        let sum = if hi <= PI {
            upto(hi) - upto(lo)
        } else {
            (self.cum[self.pts.len()] - upto(lo)) + upto(hi - PI)
        };
        sum / width
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(b: &Basis, psi_deg: f64, method: Method, support: u32) -> Row {
        Row {
            normal: b.normal(psi_deg.to_radians()),
            method,
            support,
            width_rad: 0.0,
        }
    }

    /// Points on the planes through the vanishing point at the given angles (degrees),
    /// `n` each, spread along the plane's half that is in front (z < 0).
    fn points(b: &Basis, bands: &[(f64, f64, usize)]) -> (Vec<[f32; 3]>, Vec<f32>) {
        let (mut rays, mut w) = (Vec::new(), Vec::new());
        for &(lo, hi, n) in bands {
            for i in 0..n {
                let psi = (lo + (hi - lo) * (i as f64 + 0.5) / n as f64).to_radians();
                let normal = b.normal(psi);
                // a direction in the plane, away from the vanishing point
                let along = normal.cross(&b.vp).normalize();
                for t in [0.3f64, 0.6, 0.9] {
                    let r = (b.vp * t.cos() + along * t.sin()).normalize();
                    let r = if r.z > 0.0 {
                        (b.vp * t.cos() - along * t.sin()).normalize()
                    } else {
                        r
                    };
                    rays.push([r.x as f32, r.y as f32, r.z as f32]);
                    w.push(1.0);
                }
            }
        }
        (rays, w)
    }

    fn vp() -> Vector3<f64> {
        Vector3::new(0.2, 0.1, -1.0).normalize()
    }

    #[test]
    fn hough_rows_take_their_width_and_boundaries_are_not_published() {
        let b = Basis::new(&vp());
        let mut rows = vec![
            row(&b, 40.0, Method::Hough, 100),
            row(&b, 60.0, Method::Hough, 90),
            row(&b, 37.0, Method::Edge, 50),
            row(&b, 44.0, Method::Edge, 40),
            // a weaker boundary nearer the centre: the stronger one sets the width
            row(&b, 42.0, Method::Edge, 10),
            // one boundary only for the second row: no width
            row(&b, 63.0, Method::Edge, 30),
            // a stray boundary far from every row
            row(&b, 120.0, Method::Edge, 80),
        ];
        let mut c = CentreLines::default();
        let widened = c.publish(&mut rows, &vp(), 5f64.to_radians(), &[], &[]);
        assert_eq!(widened, 1);
        assert_eq!(rows.len(), 2);
        assert!(rows.iter().all(|r| r.method == Method::Hough));
        assert!(
            (rows[0].width_rad.to_degrees() - 7.0).abs() < 1e-9,
            "{:?}",
            rows[0]
        );
        assert_eq!(rows[1].width_rad, 0.0);
    }

    #[test]
    fn edge_boundaries_pair_across_the_vegetation_not_across_the_soil() {
        let b = Basis::new(&vp());
        // crop rows 10..16° and 30..36°: dense points; soil between: sparse
        let (rays, w) = points(&b, &[(10.0, 16.0, 60), (16.0, 30.0, 14), (30.0, 36.0, 60)]);
        let mut rows = vec![
            row(&b, 10.0, Method::Edge, 10),
            row(&b, 16.0, Method::Edge, 10),
            row(&b, 30.0, Method::Edge, 10),
            row(&b, 36.0, Method::Edge, 10),
            // a stray boundary with nothing beside it
            row(&b, 90.0, Method::Edge, 10),
        ];
        let mut c = CentreLines::default();
        let n = c.publish(&mut rows, &vp(), 10f64.to_radians(), &rays, &w);
        assert_eq!(n, 2, "{rows:?}");
        let mut centres: Vec<f64> = rows
            .iter()
            .map(|r| b.of_normal(&r.normal).to_degrees())
            .collect();
        centres.sort_by(f64::total_cmp);
        assert!(
            (centres[0] - 13.0).abs() < 1e-6 && (centres[1] - 33.0).abs() < 1e-6,
            "{centres:?}"
        );
        for r in &rows {
            assert!((r.width_rad.to_degrees() - 6.0).abs() < 1e-6);
            assert_eq!(r.support, 20);
            assert!(
                r.normal.dot(&vp()).abs() < 1e-9,
                "the centre line goes through the vanishing point"
            );
        }
    }

    #[test]
    fn boundaries_around_the_wrap_pair_and_nothing_without_vegetation() {
        let b = Basis::new(&vp());
        let (rays, w) = points(&b, &[(176.0, 180.0, 40), (0.0, 2.0, 20), (2.0, 40.0, 10)]);
        let mut rows = vec![
            row(&b, 176.0, Method::Edge, 5),
            row(&b, 2.0, Method::Edge, 5),
        ];
        let mut c = CentreLines::default();
        assert_eq!(c.publish(&mut rows, &vp(), 5f64.to_radians(), &rays, &w), 1);
        assert!((rows[0].width_rad.to_degrees() - 6.0).abs() < 1e-6);
        assert!(wrap(b.of_normal(&rows[0].normal) - 179f64.to_radians()).abs() < 1e-9);
        // the same boundaries over uniform vegetation: no row
        let (rays, w) = points(&b, &[(0.0, 180.0, 180)]);
        let mut rows = vec![
            row(&b, 176.0, Method::Edge, 5),
            row(&b, 2.0, Method::Edge, 5),
        ];
        assert_eq!(c.publish(&mut rows, &vp(), 5f64.to_radians(), &rays, &w), 0);
        assert!(rows.is_empty());
    }
}
