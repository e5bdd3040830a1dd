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

use crate::sphere::{Fit, Scatter};
use nalgebra::{Matrix2, Matrix3, Vector3};

/// The largest number of bins (the bins live on the stack).
pub const MAX_SECTIONS: usize = 1024;

/// The refit's cross-sections around the whole great circle.
pub const SECTION_BINS: usize = 256;
/// Cross-sections farther than this many of their σ from the line lose weight (Huber).
pub const SECTION_HUBER: f64 = 1.5;
/// The plant-structure term of a cross-section's variance grows as its width to this power
/// (2: the centre wanders by a share of the width; higher: also the correlation of
/// neighbouring sections within one wide plant).
pub const SECTION_POWER: f64 = 4.0;

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
    /// After [`Sections::fit`]: the centres in use and the variance model's (a, b).
    fitted: usize,
    model: (f64, f64),
}

/// Where a row's near part is fitted ([`Sections::near_foot`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NearField {
    /// The ground's downward normal in the camera frame (unit).
    pub down: Vector3<f64>,
    /// How far along the row, ahead and behind, the near part reaches (camera heights).
    pub reach: f64,
    /// The bend must be this many of its standard deviations from zero to count.
    pub min_sigma: f64,
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
            fitted: 0,
            model: (0.0, 0.0),
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

    /// A bin's centre on the sphere: its weighted mean angle along the circle and offset
    /// from it.
    fn centre(&self, b: &Bin) -> Vector3<f64> {
        let c = b.wd / b.w;
        let s = b.ws / b.w;
        let q = self.f1 * s.cos() + self.f2 * s.sin();
        q * (1.0 - c * c).max(0.0).sqrt() + self.n * c
    }

    /// The great circle through the sections' centres, each weighted by its mass: the pixel
    /// fit without each section's spread along and across the circle, and the start of
    /// [`Sections::fit`] (so that the refit need not also accumulate every pixel's scatter).
    pub fn mass_fit(&self) -> Option<Fit> {
        let mut sc = Scatter::new();
        for b in self.bins[..self.count].iter().filter(|b| b.w > 0.0) {
            sc.add(&self.centre(b), b.w);
        }
        sc.fit()
    }

    /// Fits the circle to the sections' centres starting from `start` (e.g. [`Sections::mass_fit`]), with
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
            self.centres[m] = Centre {
                x: self.centre(b),
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
        self.fitted = m;
        self.model = (a, b);
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

impl Sections {
    /// After [`Sections::fit`] gave the circle `n`: where the row's sections bend off that
    /// circle (a curved row), the ray to the row's point beside the camera's foot; else
    /// `None` (the circle stands).
    ///
    /// The centres are taken to the ground plane (in camera heights, relative to the
    /// camera's foot: `a` along the row's direction on the horizon, `y` across), those
    /// within `reach` of the foot along the row fitted with `y = c0 + c1·a + c2·a²/2`, each
    /// by the inverse of its variance (the fit's variance model carried to the ground) and
    /// a Huber weight, the curvature's standard deviation scaled by the residuals. A bend of
    /// fewer than `min_sigma` standard deviations is no bend: a straight row keeps the fit
    /// over its whole length, which the far field makes the more precise. Otherwise the
    /// row's point at `a = 0`, `y = c0`, is where the controller steers: a whole curved
    /// row's circle is its chord, off the row there by a share of its sagitta. The row's
    /// direction is best left to the chord and the other rows' (a symmetric arc's chord is
    /// parallel to its tangent at the middle, and far more precise than the near part's
    /// slope): the detector turns the row about the final vanishing point through this
    /// point. The centres must reach a quarter of `reach` on both sides of the foot (an
    /// omnidirectional lens sees beside the robot; a forward-looking camera does not, and
    /// extrapolating its bend back to the robot made CRDLD's rows worse).
    pub fn near_foot(&self, n: &Vector3<f64>, near: &NearField) -> Option<Vector3<f64>> {
        let g = near.down;
        let v = n.cross(&g);
        if v.norm() < 0.05 {
            return None;
        }
        let v = v.normalize();
        let w = g.cross(&v);
        let (a_m, b_m) = self.model;
        let (ng, nw) = (n.dot(&g), n.dot(&w));
        // Each centre on the ground: (a, y, weight of y), or None outside the near part.
        let ground = |c: &Centre| {
            let t = c.x.dot(&g);
            if t < 0.05 {
                return None;
            }
            let (a, y) = (c.x.dot(&v) / t, c.x.dot(&w) / t);
            if a.abs() > near.reach {
                return None;
            }
            // dy per radian of the centre's offset across the circle
            let j = nw / t - y * ng / t;
            let var = (a_m / c.mass + b_m * c.spread) * j * j;
            (var > 0.0 && var.is_finite()).then_some((a, y, 1.0 / var))
        };
        let centres = &self.centres[..self.fitted];
        let mut coef = Vector3::zeros();
        // The variance model gives the centres' relative weights; their scale is the
        // residuals' own (the model was fitted about the chord, whose misfit it absorbed).
        let mut scale2 = f64::NAN;
        let mut inv = Matrix3::zeros();
        for round in 0..ROUNDS_NEAR {
            let (mut ata, mut aty) = (Matrix3::<f64>::zeros(), Vector3::<f64>::zeros());
            let (mut chi2, mut k) = (0.0, 0usize);
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for (a, y, wt) in centres.iter().filter_map(ground) {
                let phi = Vector3::new(1.0, a, 0.5 * a * a);
                let mut wt = wt;
                if round > 0 {
                    let r = y - phi.dot(&coef);
                    if round > 1 {
                        let z = r * (wt / scale2).sqrt();
                        if z.abs() > HUBER_NEAR {
                            wt *= HUBER_NEAR / z.abs();
                        }
                    }
                    chi2 += r * r * wt;
                }
                ata += wt * phi * phi.transpose();
                aty += wt * y * phi;
                (lo, hi) = (lo.min(a), hi.max(a));
                k += 1;
            }
            // The near part must be seen on both sides of the foot: a lens that sees only
            // ahead (a forward-looking camera) would extrapolate the bend back to the robot.
            if k < 8 || lo > -0.25 * near.reach || hi < 0.25 * near.reach {
                return None;
            }
            inv = ata.try_inverse()?;
            if round > 0 {
                scale2 = (chi2 / (k - 3) as f64).max(f64::MIN_POSITIVE);
            }
            coef = inv * aty;
        }
        let bend = coef[2] / (inv[(2, 2)] * scale2).sqrt();
        if bend.is_nan() || bend.abs() < near.min_sigma {
            return None;
        }
        (g + w * coef[0]).try_normalize(1e-12)
    }
}

/// The near-field fit's Huber threshold (standard deviations) and its rounds (the first
/// plain, the second measuring the residuals' scale, the rest robust).
const HUBER_NEAR: f64 = 2.5;
const ROUNDS_NEAR: usize = 4;

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
    use crate::sphere::{any_perpendicular, axis_angle};

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
    fn mass_weighted(s: &Sections) -> Vector3<f64> {
        s.mass_fit().unwrap().normal
    }

    #[test]
    fn the_mass_fit_is_the_pixel_fit_of_the_same_pixels() {
        // Pixels scattered about a circle tilted from the sections' own by 3 mrad: the
        // centres' fit by mass and the scatter of every pixel agree to a small share of that.
        let n0 = Vector3::new(0.2, 1.0, -0.1).normalize();
        let truth = (n0 + any_perpendicular(&n0) * 0.003).normalize();
        let g1 = any_perpendicular(&truth);
        let g2 = truth.cross(&g1);
        let mut rng = Lcg(9);
        let mut s = Sections::new(&n0, 256);
        let (f1, f2) = s.frame();
        let mut sc = Scatter::new();
        for _ in 0..20000 {
            let t = 0.3 + 1.8 * rng.next_f64();
            let d: f64 = 0.01 * (rng.next_f64() - 0.5);
            let q = (g1 * t.cos() + g2 * t.sin()) * (1.0 - d * d).sqrt() + truth * d;
            let w = 0.5 + rng.next_f64();
            sc.add(&q, w);
            s.add(q.dot(&f2).atan2(q.dot(&f1)) as f32, n0.dot(&q) as f32, w);
        }
        let pixels = sc.fit().unwrap().normal;
        let centres = mass_weighted(&s);
        assert!(axis_angle(&pixels, &truth) < 1e-4, "{pixels:?}");
        assert!(
            axis_angle(&centres, &pixels) < 1e-4,
            "{centres:?} vs {pixels:?}"
        );
        // Nothing added: no fit.
        assert!(Sections::new(&n0, 64).mass_fit().is_none());
    }

    #[test]
    fn wide_wandering_sections_lose_weight() {
        let truth = Vector3::new(0.1, 1.0, 0.2).normalize();
        let vp = truth.cross(&Vector3::z()).normalize();
        let (mut plain, mut weighted) = (0.0, 0.0);
        for seed in 0..20 {
            let mut s = row(&truth, 0.3, seed);
            let p = mass_weighted(&s);
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
        let p = mass_weighted(&s);
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

    /// A row on flat ground 1 m below the camera (down = −z), `y0` across, bending as
    /// `y0 + κ·a²/2` over 6 m ahead and behind; each 2 cm along it a cross-section of 20
    /// pixels 4 cm wide with noise of 5 mm on the ground. Sections around the row's
    /// straight line at `y0`, fitted.
    fn ground_row(y0: f64, kappa: f64, seed: u64) -> (Sections, Vector3<f64>) {
        let mut rng = Lcg(seed);
        let chord = Vector3::new(0.0, y0, -1.0).cross(&Vector3::x()).normalize();
        let mut s = Sections::new(&chord, 256);
        let (f1, f2) = s.frame();
        for k in 0..600 {
            let a = -6.0 + 12.0 * (k as f64 + 0.5) / 600.0;
            for j in 0..20 {
                let y = y0 + kappa * a * a / 2.0 + 0.04 * ((j as f64 + 0.5) / 20.0 - 0.5);
                let q = Vector3::new(a, y + 0.005 * rng.gauss(), -1.0).normalize();
                s.add(
                    q.dot(&f2).atan2(q.dot(&f1)) as f32,
                    chord.dot(&q) as f32,
                    1.0,
                );
            }
        }
        let fit = s.fit(&chord, None, 1.5, 4.0).unwrap();
        (s, fit.normal)
    }

    #[test]
    fn a_curved_rows_point_beside_the_robot_is_found_and_a_straight_one_stays() {
        let near = NearField {
            down: -Vector3::z(),
            reach: 2.0,
            min_sigma: 4.0,
        };
        for (y0, kappa) in [(0.4, 0.05), (-0.9, -0.1), (1.5, 0.1)] {
            let (s, n) = ground_row(y0, kappa, 7);
            let truth = Vector3::new(0.0, y0, -1.0).normalize();
            // the whole row's circle misses the foot by a share of the sagitta
            let chord_miss = n.dot(&truth).abs();
            let foot = s.near_foot(&n, &near).expect("a bend");
            let miss = axis_angle(&foot, &truth);
            assert!(
                miss < 1e-3 && miss < 0.1 * chord_miss,
                "{y0} {kappa}: {miss} vs {chord_miss}"
            );
        }
        for seed in 0..5 {
            let (s, n) = ground_row(0.4, 0.0, seed);
            assert!(s.near_foot(&n, &near).is_none(), "seed {seed}");
        }
        // A lens that sees only ahead: no foot.
        let mut ahead = Sections::new(&Vector3::y(), 256);
        let (f1, f2) = ahead.frame();
        for k in 0..300 {
            let a = 0.5 + 5.0 * k as f64 / 300.0;
            let q = Vector3::new(a, 0.4 + 0.05 * a * a, -1.0).normalize();
            ahead.add(q.dot(&f2).atan2(q.dot(&f1)) as f32, q.y as f32, 1.0);
        }
        let n = ahead.fit(&Vector3::y(), None, 1.5, 4.0);
        assert!(n.is_some_and(|f| ahead.near_foot(&f.normal, &near).is_none()));
    }
}
