//! The Fourier component of the peaks' u at one frequency, the comb's strength and phase at
//! one period, with a sin and cos that vectorise.

/// Σ wᵢ·cos(f·uᵢ) and Σ wᵢ·sin(f·uᵢ): the Fourier component at angular frequency `f` of
/// peaks at `u` weighing `w` (the same length). Summed in four lanes, with [`sin_cos`] where
/// every |f·u| ≤ 10⁶ (so that the loop vectorises), the C library's beyond.
pub(super) fn fourier(u: &[f64], w: &[f64], f: f64) -> (f64, f64) {
    let reach = u.iter().fold(0.0f64, |m, &x| m.max(x.abs())) * f.abs();
    if reach.is_nan() || reach > 1e6 {
        return u.iter().zip(w).fold((0.0, 0.0), |(c, s), (&x, &w)| {
            let (sn, cs) = (f * x).sin_cos();
            (c + w * cs, s + w * sn)
        });
    }
    let (mut c, mut s) = ([0.0f64; 4], [0.0f64; 4]);
    for (u, w) in u.chunks_exact(4).zip(w.chunks_exact(4)) {
        for l in 0..4 {
            let (sn, cs) = sin_cos(f * u[l]);
            c[l] += w[l] * cs;
            s[l] += w[l] * sn;
        }
    }
    let full = u.len() / 4 * 4;
    for (&x, &w) in u[full..].iter().zip(&w[full..]) {
        let (sn, cs) = sin_cos(f * x);
        c[0] += w * cs;
        s[0] += w * sn;
    }
    ((c[0] + c[1]) + (c[2] + c[3]), (s[0] + s[1]) + (s[2] + s[3]))
}

/// sin and cos of `x` for |x| ≤ 10⁶, within a few units in the last place of the C
/// library's: range reduction by a three-part π/2, then fdlibm's kernel polynomials on
/// |r| ≤ π/4. Branch-free, so that loops over it vectorise.
#[inline(always)]
fn sin_cos(x: f64) -> (f64, f64) {
    // Rounded to the nearest integer by the addition's own rounding: q = x / (π/2).
    const ROUND: f64 = 6_755_399_441_055_744.0; // 1.5 · 2^52
    let t = x * std::f64::consts::FRAC_2_PI + ROUND;
    // The quadrant's low bits (32-bit lanes vectorise where 64-bit compares do not).
    let quadrant = t.to_bits() as u32;
    let q = t - ROUND;
    // π/2 in three parts, the first two of 33 bits, so that q times them is exact.
    const P1: f64 = 1.5707963267341256;
    const P2: f64 = 6.077100506303966e-11;
    const P3: f64 = 2.0222662487959506e-21;
    let r = ((x - q * P1) - q * P2) - q * P3;
    let z = r * r;
    let sin = r + r
        * z
        * (-0.16666666666666632
            + z * (0.00833333333332249
                + z * (-0.0001984126982985795
                    + z * (2.7557313707070068e-6
                        + z * (-2.5050760253406863e-8 + z * 1.58969099521155e-10)))));
    let cos = 1.0 - 0.5 * z
        + z * z
            * (0.0416666666666666
                + z * (-0.001388888888887411
                    + z * (2.480158728947673e-5
                        + z * (-2.7557314351390663e-7
                            + z * (2.087572321298175e-9 + z * -1.1359647557788195e-11)))));
    // Swapped in odd quadrants, negated in the second half-turn (sin) or the middle two
    // quadrants (cos); as products with 0 and ±1, which are exact.
    let odd = (quadrant & 1) as f64;
    let s = odd * cos + (1.0 - odd) * sin;
    let c = odd * sin + (1.0 - odd) * cos;
    let s_sign = 1.0 - 2.0 * ((quadrant >> 1) & 1) as f64;
    let c_sign = 1.0 - 2.0 * ((quadrant.wrapping_add(1) >> 1) & 1) as f64;
    (s * s_sign, c * c_sign)
}

#[cfg(test)]
mod tests {
    use super::super::testing::uniform;
    use super::*;

    #[test]
    fn sin_cos_is_the_c_librarys_to_a_few_ulp() {
        let mut next = uniform(17);
        let mut worst = 0.0f64;
        for k in 0..200_000 {
            // every scale from 10⁻⁶ to 10⁶, both signs, and the quadrants' boundaries
            let x = match k % 3 {
                0 => (next() - 0.5) * 10f64.powf(12.0 * next() - 6.0) * 2.0,
                1 => (k as f64 - 100_000.0) * std::f64::consts::FRAC_PI_4,
                _ => (next() - 0.5) * 2000.0,
            };
            let (s, c) = sin_cos(x);
            let (s0, c0) = x.sin_cos();
            worst = worst.max((s - s0).abs()).max((c - c0).abs());
        }
        assert!(worst < 4.0 * f64::EPSILON, "worst error {worst:e}");
    }

    #[test]
    fn fourier_sums_are_the_c_librarys_and_far_arguments_fall_back_to_it() {
        let mut next = uniform(5);
        for n in [0, 1, 3, 4, 7, 250] {
            let u: Vec<f64> = (0..n).map(|_| (next() - 0.5) * 6.0).collect();
            let w: Vec<f64> = (0..n).map(|_| next()).collect();
            // ordinary frequencies, and one that takes the arguments beyond 10⁶
            for f in [8.4, 83.7, 2e6] {
                let (c, s) = fourier(&u, &w, f);
                let (c0, s0) = u.iter().zip(&w).fold((0.0, 0.0), |(c, s), (&x, &w)| {
                    let (sn, cs) = (f * x).sin_cos();
                    (c + w * cs, s + w * sn)
                });
                let tol = 1e-13 * (1.0 + n as f64);
                assert!((c - c0).abs() < tol && (s - s0).abs() < tol, "n {n} f {f}");
            }
        }
    }
}
