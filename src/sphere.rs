//! Geometry on the unit sphere: rows as great circles, and their common direction.
//!
//! Owns the paper's row model (II-B): a row is the great circle where its plane through the
//! viewpoint cuts the unit sphere, stored as the plane's unit normal. Fitting a normal to
//! weighted unit vectors (the smallest eigenvector of their scatter matrix, i.e. the smallest
//! singular vector), the sign-invariant angle between normals, the distance of a point from
//! a great circle, and the common direction of several great circles (the vanishing point),
//! which is the same fit applied to their normals. Nothing here allocates.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

/// Accumulates the weighted scatter matrix Σ w·p·pᵀ of unit vectors, so that a fit over
/// any number of points needs no buffer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scatter {
    m: Matrix3<f64>,
    weight: f64,
    count: usize,
}

impl Default for Scatter {
    fn default() -> Self {
        Scatter {
            m: Matrix3::zeros(),
            weight: 0.0,
            count: 0,
        }
    }
}

/// The result of fitting a great circle (or a common direction).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fit {
    /// Unit normal (for a great circle) or common direction (for normals). Sign is free.
    pub normal: Vector3<f64>,
    /// Weighted mean of (normal·p)², i.e. the mean squared sine of the points' angular
    /// distance from the great circle.
    pub mean_sq_residual: f64,
    /// Ratio of the smallest to the middle eigenvalue: near 0 for a well-defined fit,
    /// near 1 when the points do not single out a great circle.
    pub degeneracy: f64,
    /// Number of points accumulated.
    pub count: usize,
    /// Total weight.
    pub weight: f64,
}

impl Scatter {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn clear(&mut self) {
        *self = Self::default();
    }

    /// Adds a unit vector with a weight.
    #[inline]
    pub fn add(&mut self, p: &Vector3<f64>, w: f64) {
        self.add_if(p, w, true);
    }

    /// Adds a unit vector with a weight when `keep`, without a branch: otherwise its terms
    /// are exact zeros, so the sums are those of [`Self::add`] on the kept vectors alone.
    #[inline]
    pub fn add_if(&mut self, p: &Vector3<f64>, w: f64, keep: bool) {
        let w = if keep { w } else { 0.0 };
        let (x, y, z) = (p.x, p.y, p.z);
        let m = &mut self.m;
        m[(0, 0)] += w * x * x;
        m[(0, 1)] += w * x * y;
        m[(0, 2)] += w * x * z;
        m[(1, 1)] += w * y * y;
        m[(1, 2)] += w * y * z;
        m[(2, 2)] += w * z * z;
        self.weight += w;
        self.count += keep as usize;
    }

    /// Adds another accumulator.
    pub fn merge(&mut self, other: &Scatter) {
        self.m += other.m;
        self.weight += other.weight;
        self.count += other.count;
    }

    pub fn count(&self) -> usize {
        self.count
    }

    /// The accumulated Σ w·p·pᵀ (symmetric).
    pub fn matrix(&self) -> Matrix3<f64> {
        let mut m = self.m;
        m[(1, 0)] = m[(0, 1)];
        m[(2, 0)] = m[(0, 2)];
        m[(2, 1)] = m[(1, 2)];
        m
    }

    pub fn weight(&self) -> f64 {
        self.weight
    }

    /// The unit vector minimising Σ w (n·p)²: the normal of the best great circle through the
    /// points. `None` with fewer than two points or zero weight.
    pub fn fit(&self) -> Option<Fit> {
        if self.count < 2 || self.weight <= 0.0 {
            return None;
        }
        let mut m = self.m;
        m[(1, 0)] = m[(0, 1)];
        m[(2, 0)] = m[(0, 2)];
        m[(2, 1)] = m[(1, 2)];
        let eig = SymmetricEigen::new(m);
        let mut idx = [0usize, 1, 2];
        idx.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
        let n: Vector3<f64> = eig.eigenvectors.column(idx[0]).into_owned();
        let norm = n.norm();
        if norm.is_nan() || norm <= 0.0 || norm.is_infinite() {
            return None;
        }
        let l0 = eig.eigenvalues[idx[0]].max(0.0);
        let l1 = eig.eigenvalues[idx[1]].max(0.0);
        Some(Fit {
            normal: canonical(&(n / norm)),
            mean_sq_residual: l0 / self.weight,
            degeneracy: if l1 > 0.0 { l0 / l1 } else { 1.0 },
            count: self.count,
            weight: self.weight,
        })
    }
}

/// Fits a great-circle normal to weighted unit vectors (weights default to 1 when `None`).
pub fn fit_normal(points: &[Vector3<f64>], weights: Option<&[f64]>) -> Option<Fit> {
    let mut s = Scatter::new();
    for (i, p) in points.iter().enumerate() {
        s.add(p, weights.map_or(1.0, |w| w[i]));
    }
    s.fit()
}

/// The common direction of several great circles given by their normals: the unit vector
/// most nearly perpendicular to all of them (the vanishing point of parallel rows).
pub fn common_direction(normals: &[Vector3<f64>], weights: Option<&[f64]>) -> Option<Fit> {
    fit_normal(normals, weights)
}

/// Sign-invariant angle (radians, 0..=π/2) between two unit normals (or two axes).
#[inline]
pub fn axis_angle(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    // atan2 of |a×b| and |a·b| is accurate for small angles, where acos is not.
    let c = a.dot(b).abs();
    let s = a.cross(b).norm();
    s.atan2(c)
}

/// Angular distance (radians, 0..=π/2) of unit vector `p` from the great circle with normal `n`.
#[inline]
pub fn distance_to_great_circle(n: &Vector3<f64>, p: &Vector3<f64>) -> f64 {
    n.dot(p).clamp(-1.0, 1.0).abs().asin()
}

/// Picks a canonical sign for an axis (normal or direction): the largest-magnitude
/// component positive, so equal axes compare equal.
#[inline]
pub fn canonical(v: &Vector3<f64>) -> Vector3<f64> {
    let (ax, ay, az) = (v.x.abs(), v.y.abs(), v.z.abs());
    let key = if ax >= ay && ax >= az {
        v.x
    } else if ay >= az {
        v.y
    } else {
        v.z
    };
    if key < 0.0 {
        -v
    } else {
        *v
    }
}

/// Spherical coordinates of a normal as the paper's eq. 3:
/// n = (sin φ cos θ, sin φ sin θ, cos φ), φ ∈ [0, π], θ ∈ [0, 2π).
#[inline]
pub fn to_phi_theta(n: &Vector3<f64>) -> (f64, f64) {
    let phi = n.z.clamp(-1.0, 1.0).acos();
    let mut theta = n.y.atan2(n.x);
    if theta < 0.0 {
        theta += std::f64::consts::TAU;
    }
    (phi, theta)
}

/// The normal of eq. 3 from (φ, θ).
#[inline]
pub fn from_phi_theta(phi: f64, theta: f64) -> Vector3<f64> {
    let (sp, cp) = phi.sin_cos();
    let (st, ct) = theta.sin_cos();
    Vector3::new(sp * ct, sp * st, cp)
}

/// A unit vector perpendicular to `n` (any one), for building bases on a great circle.
pub fn any_perpendicular(n: &Vector3<f64>) -> Vector3<f64> {
    let a = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    n.cross(&a).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn unit(a: f64, b: f64) -> Vector3<f64> {
        from_phi_theta(a, b)
    }

    #[test]
    fn add_if_sums_as_add_on_the_kept_vectors() {
        let (mut a, mut b) = (Scatter::new(), Scatter::new());
        for i in 0..50 {
            let p = unit(0.1 * i as f64, 0.37 * i as f64);
            let w = 0.5 + (i % 7) as f64;
            let keep = i % 3 != 0;
            a.add_if(&p, w, keep);
            if keep {
                b.add(&p, w);
            }
        }
        assert_eq!(a.matrix(), b.matrix());
        assert_eq!((a.weight(), a.count()), (b.weight(), b.count()));
    }

    proptest! {
        #[test]
        fn fit_recovers_great_circle(phi in 0.05f64..3.1, theta in 0.0f64..6.2, n in 3usize..40, spread in 0.2f64..3.0) {
            let normal = unit(phi, theta);
            let u = any_perpendicular(&normal);
            let v = normal.cross(&u);
            let pts: Vec<_> = (0..n).map(|i| {
                let t = spread * i as f64 / n as f64;
                u * t.cos() + v * t.sin()
            }).collect();
            let fit = fit_normal(&pts, None).unwrap();
            prop_assert!(axis_angle(&fit.normal, &normal) < 1e-9);
            prop_assert!(fit.mean_sq_residual < 1e-15);
        }

        #[test]
        fn axis_angle_is_sign_invariant_and_symmetric(p1 in 0.0f64..3.1, t1 in 0.0f64..6.2, p2 in 0.0f64..3.1, t2 in 0.0f64..6.2) {
            let a = unit(p1, t1);
            let b = unit(p2, t2);
            let d = axis_angle(&a, &b);
            prop_assert!((d - axis_angle(&-a, &b)).abs() < 1e-12);
            prop_assert!((d - axis_angle(&b, &a)).abs() < 1e-12);
            prop_assert!((0.0..=std::f64::consts::FRAC_PI_2 + 1e-12).contains(&d));
        }

        #[test]
        fn distance_to_circle_matches_construction(phi in 0.05f64..3.1, theta in 0.0f64..6.2, off in -1.5f64..1.5, t in 0.0f64..6.2) {
            let n = unit(phi, theta);
            let u = any_perpendicular(&n);
            let v = n.cross(&u);
            let on = u * t.cos() + v * t.sin();
            let p = on * off.cos() + n * off.sin();
            prop_assert!((distance_to_great_circle(&n, &p) - off.abs()).abs() < 1e-9);
        }

        #[test]
        fn common_direction_of_planes_through_an_axis(phi in 0.05f64..3.1, theta in 0.0f64..6.2, k in 2usize..8) {
            let d = unit(phi, theta);
            let u = any_perpendicular(&d);
            let v = d.cross(&u);
            let normals: Vec<_> = (0..k).map(|i| {
                let a = 0.3 + 2.5 * i as f64 / k as f64;
                u * a.cos() + v * a.sin()
            }).collect();
            let fit = common_direction(&normals, None).unwrap();
            prop_assert!(axis_angle(&fit.normal, &d) < 1e-9);
        }

        #[test]
        fn phi_theta_round_trip(phi in 0.01f64..3.13, theta in 0.0f64..6.2) {
            let n = from_phi_theta(phi, theta);
            let (p, t) = to_phi_theta(&n);
            prop_assert!((p - phi).abs() < 1e-9);
            prop_assert!((t - theta).abs() < 1e-9);
        }
    }

    #[test]
    fn weighted_fit_prefers_heavy_points() {
        let pts = [
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 1.0, 0.0),
            Vector3::new(0.0, 0.0, 1.0),
        ];
        let fit = fit_normal(&pts, Some(&[10.0, 10.0, 0.1])).unwrap();
        assert!(axis_angle(&fit.normal, &Vector3::z()) < 1e-9);
        assert!(fit_normal(&pts[..1], None).is_none());
    }
}
