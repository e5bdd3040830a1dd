//! A row's centre line from its cross-sections, weighted by how much each one can be trusted.
//!
//! Owns [`Sections`]: the refit's pixels of one row binned by their angle along the row's
//! great circle, each bin reduced to its cross-section's centre (the weighted mean offset
//! from the circle), mass and width, and the great circle fitted to those centres. The
//! plain pixel fit weighs each cross-section by its mass, which is right when the only
//! error is the image's noise (the first synthetic appearance). Real plants, and the
//! `leafy` appearance, are clusters of leaves whose centre wanders off the stem by a share of
//! the plant's size: that error grows with the row's width in the image, so near the camera,
//! where a row is widest and holds most of the mass, the few plants there decide the fit.
//! Here each centre's variance is modelled as `a / mass + b · width^p` (noise plus plant
//! structure), `a` and `b` estimated from the centres' own residuals, and the circle
//! refitted with the inverse variances, with a Huber weight for the sections far off (a
//! weed, a leaf cluster much larger than its neighbours). A centre wanders by a share of its
//! width (p = 2), and one wide plant spans many neighbouring sections whose errors are then
//! one error (another power or two); p = 4 (`refit.section_power`) measured best on `leafy`
//! (docs/real.md). Where the structure term is absent the weights are the masses again and
//! the fit is the pixel fit's.

use crate::sphere::Scatter;
use nalgebra::{Matrix2, Vector3};

/// The largest number of bins (the bins live on the stack).
pub const MAX_SECTIONS: usize = 1024;

/// Reweighting rounds (fit, residuals, variance model).
const ROUNDS: usize = 4;

/// One bin's sums: mass Σw, Σw·d, Σw·d², Σw·s (d the offset from the circle, s the angle
/// along it).
#[derive(Debug, Clone, Copy, Default)]
struct Bin {
    w: f64,
    wd: f64,
    wdd: f64,
    ws: f64,
}

/// A section reduced to its centre on the sphere, with its mass and its width to the
/// variance model's power (squared by default).
#[derive(Debug, Clone, Copy, Default)]
struct Centre {
    x: Vector3<f64>,
    mass: f64,
    spread: f64,
}

/// The outcome of a section fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SectionFit {
    pub normal: Vector3<f64>,
    /// The variance (rad²) of the normal's component along the vanishing point given to
    /// [`Sections::fit`], from the fitted variance model (NaN without one).
    pub along_var: f64,
    /// The variance model's structure coefficient relative to its noise one, b·mean(width^p)·mean(mass) / a
    /// (0: noise only).
    pub structure: f64,
}

/// The cross-sections of one row (no allocation: a fixed array of bins).
#[derive(Debug, Clone)]
pub struct Sections {
    n: Vector3<f64>,
    f1: Vector3<f64>,
    f2: Vector3<f64>,
    count: usize,
    /// Bins per radian (`count` / 2π, once rather than at every pixel).
    per_rad: f32,
    bins: [Bin; MAX_SECTIONS],
    centres: [Centre; MAX_SECTIONS],
}

impl Sections {
    /// Empty sections around the great circle of the unit normal `n`, `count` bins (clamped
    /// to 8..=[`MAX_SECTIONS`]).
    pub fn new(n: &Vector3<f64>, count: usize) -> Self {
        let f1 = crate::sphere::any_perpendicular(n);
        let f2 = n.cross(&f1);
        let count = count.clamp(8, MAX_SECTIONS);
        Sections {
            n: *n,
            f1,
            f2,
            count,
            per_rad: count as f32 / std::f32::consts::TAU,
            bins: [Bin::default(); MAX_SECTIONS],
            centres: [Centre::default(); MAX_SECTIONS],
        }
    }

    /// The circle's frame (f1, f2): a pixel's angle along the circle is atan2(f2·p, f1·p).
    pub fn frame(&self) -> (Vector3<f64>, Vector3<f64>) {
        (self.f1, self.f2)
    }

    /// Adds a pixel at angle `s` (radians, −π..π) along the circle, signed offset `d` (n·p)
    /// and weight `w`.
    #[inline]
    pub fn add(&mut self, s: f32, d: f32, w: f64) {
        let k = ((s + std::f32::consts::PI) * self.per_rad) as usize;
        let b = &mut self.bins[k.min(self.count - 1)];
        let (s, d) = (s as f64, d as f64);
        b.w += w;
        b.wd += w * d;
        b.wdd += w * d * d;
        b.ws += w * s;
    }

    /// Fits the circle to the sections' centres starting from `start` (the pixel fit), with
    /// the variance model of the module documentation (the width to the power `power`) and a
    /// Huber weight at `huber` σ (0: none).
    /// `vp` gives the direction along which `along_var` is reported. `None` with fewer than
    /// four sections or a degenerate fit.
    pub fn fit(
        &mut self,
        start: &Vector3<f64>,
        vp: Option<&Vector3<f64>>,
        huber: f64,
        power: f64,
    ) -> Option<SectionFit> {
        let mut m = 0;
        for b in &self.bins[..self.count] {
            if b.w <= 0.0 {
                continue;
            }
            let c = b.wd / b.w;
            let s = b.ws / b.w;
            let q = self.f1 * s.cos() + self.f2 * s.sin();
            self.centres[m] = Centre {
                x: q * (1.0 - c * c).max(0.0).sqrt() + self.n * c,
                mass: b.w,
                spread: (b.wdd / b.w - c * c).max(0.0).powf(0.5 * power),
            };
            m += 1;
        }
        if m < 4 {
            return None;
        }
        let centres = &self.centres[..m];
        let mut n = *start;
        let (mut a, mut b) = (0.0, 0.0);
        for _ in 0..ROUNDS {
            (a, b) = variance_model(centres, &n)?;
            let mut sc = Scatter::new();
            for c in centres {
                let var = a / c.mass + b * c.spread;
                let mut w = 1.0 / var;
                if huber > 0.0 {
                    let z = n.dot(&c.x).abs() / var.sqrt();
                    if z > huber {
                        w *= huber / z;
                    }
                }
                sc.add(&c.x, w);
            }
            let f = sc.fit().filter(|f| f.degeneracy < 0.5)?;
            n = if f.normal.dot(&n) < 0.0 {
                -f.normal
            } else {
                f.normal
            };
        }
        let along_var = vp.map_or(f64::NAN, |v| along_variance(centres, &n, v, a, b));
        let (mean_w2, mean_m) = centres.iter().fold((0.0, 0.0), |acc, c| {
            (acc.0 + c.spread / m as f64, acc.1 + c.mass / m as f64)
        });
        Some(SectionFit {
            normal: n,
            along_var,
            structure: b * mean_w2 * mean_m / a,
        })
    }
}

/// The variance model's coefficients (a, b ≥ 0, a > 0) for centres about the circle of `n`:
/// squared residuals regressed on (1/mass, width^p), each weighted by the inverse square of
/// its modelled variance (iterated), as a squared Gaussian residual's spread is its mean.
fn variance_model(centres: &[Centre], n: &Vector3<f64>) -> Option<(f64, f64)> {
    let mean_r2 = centres.iter().map(|c| n.dot(&c.x).powi(2)).sum::<f64>() / centres.len() as f64;
    if !(mean_r2.is_finite() && mean_r2 > 0.0) {
        return None;
    }
    // Start from noise alone: a / mass with the mean squared residual.
    let mean_inv_m = centres.iter().map(|c| 1.0 / c.mass).sum::<f64>() / centres.len() as f64;
    let mean_v = centres.iter().map(|c| c.spread).sum::<f64>() / centres.len() as f64;
    let (mut a, mut b) = (mean_r2 / mean_inv_m, 0.0);
    for _ in 0..3 {
        let mut ata = Matrix2::<f64>::zeros();
        let (mut y0, mut y1) = (0.0, 0.0);
        for c in centres {
            let (u, v) = (1.0 / c.mass, c.spread);
            let var = a * u + b * v;
            let w = 1.0 / (var * var);
            let r2 = n.dot(&c.x).powi(2);
            ata[(0, 0)] += w * u * u;
            ata[(0, 1)] += w * u * v;
            ata[(1, 1)] += w * v * v;
            y0 += w * u * r2;
            y1 += w * v * r2;
        }
        ata[(1, 0)] = ata[(0, 1)];
        let sol = ata
            .try_inverse()
            .map(|inv| inv * nalgebra::Vector2::new(y0, y1));
        let (na, nb) = match sol {
            Some(x) if x[0] > 0.0 && x[1] >= 0.0 => (x[0], x[1]),
            // The noise term below zero (sections as sharp as their mass allows): the
            // structure alone, with a noise floor a thousandth of it on average so that no
            // section's variance is zero.
            Some(x) if x[1] > 0.0 && ata[(1, 1)] > 0.0 => {
                let b_only = y1 / ata[(1, 1)];
                (b_only * mean_v / mean_inv_m * 1e-3, b_only)
            }
            // The structure term below zero: the noise alone.
            _ => {
                let a_only = y0 / ata[(0, 0)];
                (a_only.max(f64::MIN_POSITIVE), 0.0)
            }
        };
        if !(na.is_finite() && nb.is_finite()) {
            return None;
        }
        (a, b) = (na, nb);
    }
    Some((a, b))
}

/// The variance of the fitted normal's component along `v`: the inverse of the fit's
/// information Σ x·xᵀ / var over the centres, in the tangent plane of `n`.
fn along_variance(centres: &[Centre], n: &Vector3<f64>, v: &Vector3<f64>, a: f64, b: f64) -> f64 {
    let ev = v - n * n.dot(v);
    if ev.norm() < 1e-6 {
        return f64::NAN;
    }
    let ev = ev.normalize();
    let ef = n.cross(&ev);
    let mut info = Matrix2::<f64>::zeros();
    for c in centres {
        let w = 1.0 / (a / c.mass + b * c.spread);
        let (x, y) = (ef.dot(&c.x), ev.dot(&c.x));
        info[(0, 0)] += w * x * x;
        info[(0, 1)] += w * x * y;
        info[(1, 1)] += w * y * y;
    }
    info[(1, 0)] = info[(0, 1)];
    info.try_inverse().map_or(f64::NAN, |c| c[(1, 1)])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::hough::tests::Lcg;
    use crate::sphere::axis_angle;

    /// A row along the great circle of `truth`, 200 sections between angles 0.2 and 2.4 rad;
    /// in each, 40 pixels of weight 1 evenly spread over a width that grows towards the row's
    /// near end (0.002 to 0.03 rad), the cross-section's centre displaced by `structure` ×
    /// its width (a plant cluster off the stem), each pixel with noise of 2e-4 rad.
    fn row(truth: &Vector3<f64>, structure: f64, seed: u64) -> Sections {
        let mut rng = Lcg(seed);
        let mut s = Sections::new(truth, 512);
        let (f1, f2) = s.frame();
        for k in 0..200 {
            let t = 0.2 + 2.2 * (k as f64 + 0.5) / 200.0;
            let width = 0.002 + 0.028 * (k as f64 / 199.0).powi(2);
            let off = structure * width * rng.gauss();
            for j in 0..40 {
                let d = off + width * ((j as f64 + 0.5) / 40.0 - 0.5) + 2e-4 * rng.gauss();
                let q = (f1 * t.cos() + f2 * t.sin()) * (1.0 - d * d).sqrt() + truth * d;
                let s_ang = q.dot(&f2).atan2(q.dot(&f1));
                s.add(s_ang as f32, truth.dot(&q) as f32, 1.0);
            }
        }
        s
    }

    /// The plain fit: every section's centre by its mass.
    fn mass_weighted(s: &Sections, n: &Vector3<f64>) -> Vector3<f64> {
        let mut sc = Scatter::new();
        for b in &s.bins[..s.count] {
            if b.w > 0.0 {
                let (c, a) = (b.wd / b.w, b.ws / b.w);
                let q = s.f1 * a.cos() + s.f2 * a.sin();
                sc.add(&(q * (1.0 - c * c).sqrt() + n * c), b.w);
            }
        }
        sc.fit().unwrap().normal
    }

    #[test]
    fn wide_wandering_sections_lose_weight() {
        let truth = Vector3::new(0.1, 1.0, 0.2).normalize();
        let vp = truth.cross(&Vector3::z()).normalize();
        let (mut plain, mut weighted) = (0.0, 0.0);
        for seed in 0..20 {
            let mut s = row(&truth, 0.3, seed);
            let p = mass_weighted(&s, &truth);
            plain += axis_angle(&p, &truth).powi(2);
            let f = s.fit(&p, Some(&vp), 2.5, 2.0).unwrap();
            assert!(f.along_var.is_finite() && f.along_var > 0.0, "{f:?}");
            assert!(f.structure > 1.0, "{f:?}");
            weighted += axis_angle(&f.normal, &truth).powi(2);
        }
        assert!(weighted < 0.5 * plain, "{weighted} vs {plain}");
    }

    #[test]
    fn without_structure_the_fit_stays_the_mass_weighted_one() {
        let truth = Vector3::new(-0.3, 1.0, 0.1).normalize();
        let mut s = row(&truth, 0.0, 3);
        let p = mass_weighted(&s, &truth);
        let f = s.fit(&p, None, 2.5, 2.0).unwrap();
        assert!(f.along_var.is_nan());
        assert!(axis_angle(&f.normal, &truth) < 2e-5, "{f:?}");
        assert!(axis_angle(&f.normal, &p) < 1e-5, "{f:?} vs {p:?}");
        // Too few sections: no fit.
        let mut few = Sections::new(&truth, 64);
        few.add(0.1, 0.0, 1.0);
        few.add(0.5, 0.0, 1.0);
        assert!(few.fit(&truth, None, 0.0, 2.0).is_none());
    }
}
