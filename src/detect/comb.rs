//! The rows' comb in a profile: equally spaced peaks (period and phase) fitted to the peaks
//! of a histogram across the rows.
//!
//! Owns [`fit_peak_comb`], [`fit_peak_comb_rolled`] and their result [`ProfileComb`]. Crop
//! rows on flat ground are equally spaced, so in the pencil around their vanishing point
//! their tan ψ values (lateral offset over camera height) form a comb: tooth k at
//! `phase + k·period`. The fit takes the profile's peaks (position, weight) and scores a
//! comb by the share of the peaks' weight on its teeth (each peak counting by
//! max(0, 1 − (d/tolerance)²), d its distance to the nearest tooth), times the square root
//! of the share of the teeth between the outermost peaks on the comb that hold a peak. The
//! second factor keeps the fit off the sub-harmonics (half the period puts every row on a
//! tooth, but half the teeth stay empty); at twice the period half the rows fall between
//! the teeth. The comb then tells which peaks are rows (those on a tooth), which are not
//! (weeds, the field's edge, a tramline between the teeth), and where a weak row should be
//! (an empty tooth between two rows). Positions are in bins of the profile; the caller
//! converts.

/// A fitted comb, in bins of the profile.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProfileComb {
    /// Distance between neighbouring teeth (bins).
    pub period: f64,
    /// Position of tooth 0 (bins).
    pub phase: f64,
    /// The comb's score in `[0, 1]`: the share of the peaks' weight on its teeth times the
    /// square root of the share of its teeth (between the outermost peaks on it) that hold
    /// a peak.
    pub contrast: f64,
    /// Peaks on the comb (within the tolerance of a tooth).
    pub on_comb: usize,
}

impl ProfileComb {
    /// Index of the tooth nearest `x` (bins) and the distance to it (bins).
    pub fn nearest_tooth(&self, x: f64) -> (i64, f64) {
        let k = ((x - self.phase) / self.period).round();
        (k as i64, (x - self.phase - k * self.period).abs())
    }

    /// Position (bins) of tooth `k`.
    pub fn tooth(&self, k: i64) -> f64 {
        self.phase + k as f64 * self.period
    }
}

/// How the comb is searched.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CombSearch {
    /// Periods searched, bins (geometric steps of `period_step` between them).
    pub min_period: f64,
    pub max_period: f64,
    /// Ratio between successive periods tried (> 1).
    pub period_step: f64,
    /// A peak is on a tooth within this distance (bins).
    pub tolerance: f64,
    /// A comb needs at least this many peaks on its teeth.
    pub min_teeth: usize,
}

impl Default for CombSearch {
    fn default() -> Self {
        CombSearch {
            min_period: 4.0,
            max_period: 100.0,
            period_step: 1.01,
            tolerance: 3.0,
            min_teeth: 3,
        }
    }
}

/// The score of the comb (period, phase) on `peaks` (weight, position), with the number of
/// peaks on it.
fn score(peaks: &[(f64, f64)], period: f64, phase: f64, tol: f64) -> (f64, usize) {
    let (mut on, mut total, mut n) = (0.0, 0.0, 0usize);
    let (mut kmin, mut kmax) = (i64::MAX, i64::MIN);
    // Teeth holding a peak, as a bit set relative to the first tooth seen (at most 64
    // teeth apart is plenty for a row's comb).
    let mut filled: u128 = 0;
    let mut base: Option<i64> = None;
    for &(w, x) in peaks {
        total += w;
        let k = ((x - phase) / period).round();
        let d = (x - phase - k * period).abs();
        if d < tol {
            on += w * (1.0 - (d / tol).powi(2));
            n += 1;
            let k = k as i64;
            kmin = kmin.min(k);
            kmax = kmax.max(k);
            let b = *base.get_or_insert(k);
            let bit = k - b + 64;
            if (0..128).contains(&bit) {
                filled |= 1u128 << bit;
            }
        }
    }
    if n == 0 || total <= 0.0 {
        return (0.0, 0);
    }
    let teeth = (kmax - kmin + 1) as f64;
    let fill = filled.count_ones() as f64 / teeth;
    (on / total * fill.min(1.0).sqrt(), n)
}

/// Fits a comb to `peaks` (weight, position in bins): the period and phase of highest score
/// (the phase through one of the peaks), then refined by weighted least squares on the
/// peaks on it. `None` when fewer than `min_teeth` peaks lie on any comb in the search.
pub fn fit_peak_comb(peaks: &[(f64, f64)], search: &CombSearch) -> Option<ProfileComb> {
    if peaks.len() < search.min_teeth || search.min_period.is_nan() || search.min_period <= 0.0 {
        return None;
    }
    let step = search.period_step.max(1.0001);
    let tol = search.tolerance;
    let mut best: Option<ProfileComb> = None;
    let mut period = search.min_period;
    while period <= search.max_period {
        for &(_, anchor) in peaks {
            let (c, n) = score(peaks, period, anchor, tol);
            if n >= search.min_teeth && best.is_none_or(|b| c > b.contrast) {
                best = Some(ProfileComb {
                    period,
                    phase: anchor,
                    contrast: c,
                    on_comb: n,
                });
            }
        }
        period *= step;
    }
    best.map(|b| refine(peaks, b, tol))
}

/// Weighted least squares of x = phase + k·period over the peaks on `b`'s teeth.
fn refine(peaks: &[(f64, f64)], b: ProfileComb, tol: f64) -> ProfileComb {
    let (mut sw, mut sk, mut sx, mut skk, mut skx) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(w, x) in peaks {
        let (k, d) = b.nearest_tooth(x);
        if d < tol {
            let k = k as f64;
            sw += w;
            sk += w * k;
            sx += w * x;
            skk += w * k * k;
            skx += w * k * x;
        }
    }
    let det = sw * skk - sk * sk;
    if det.is_nan() || det <= 1e-9 * sw * sw {
        return b;
    }
    let period = (sw * skx - sk * sx) / det;
    let phase = (sx - period * sk) / sw;
    if !(period > 0.5 * b.period && period < 2.0 * b.period) {
        return b;
    }
    let r = ProfileComb { period, phase, ..b };
    let (c, n) = score(peaks, period, phase, tol);
    if c >= b.contrast {
        ProfileComb {
            contrast: c,
            on_comb: n,
            ..r
        }
    } else {
        b
    }
}

/// A profile over tan ψ, read at another reference angle.
///
/// The comb is exactly even in tan(ψ − ψ₀) only when ψ is measured from the plane that
/// holds the vanishing point and the ground's normal; a roll of the camera about the rows,
/// or a wrong focal length, moves that plane by ψ₀ and bends the comb (tan ψ becomes a
/// Möbius map of the lateral offset). [`fit_peak_comb_rolled`] therefore also searches
/// ψ₀.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TanAxis {
    /// tan ψ at the profile's left edge (bin 0's lower edge).
    pub start: f64,
    /// Width of one bin in tan ψ.
    pub bin: f64,
}

impl TanAxis {
    /// The bin position (fractional, centres at i + 0.5) of `tan ψ` = `t`.
    pub fn bin_of(&self, t: f64) -> f64 {
        (t - self.start) / self.bin
    }

    /// tan ψ at fractional bin position `x`.
    pub fn tan_at(&self, x: f64) -> f64 {
        self.start + x * self.bin
    }

    /// Bin position, in the profile rolled by `roll` (ψ₀), of bin position `x` of the
    /// profile as measured.
    pub fn to_rolled(&self, x: f64, roll: f64) -> f64 {
        self.bin_of((self.tan_at(x).atan() - roll).tan())
    }

    /// Bin position, in the profile as measured, of bin position `x` of the profile rolled
    /// by `roll`.
    pub fn from_rolled(&self, x: f64, roll: f64) -> f64 {
        self.bin_of((self.tan_at(x).atan() + roll).tan())
    }
}

/// A comb fitted at a reference angle ψ₀.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RolledComb {
    /// The comb, in bins of the profile rolled by `roll`.
    pub comb: ProfileComb,
    /// ψ₀ (radians).
    pub roll: f64,
}

/// Fits a comb to `peaks` (weight, bin position on `axis`) at every ψ₀ within ±`max_roll`
/// (radians) in steps of `roll_step`, then halving the step twice around the best; the one
/// of highest score. `rolled` is a buffer for the peaks' rolled positions.
pub fn fit_peak_comb_rolled(
    peaks: &[(f64, f64)],
    axis: &TanAxis,
    search: &CombSearch,
    max_roll: f64,
    roll_step: f64,
    rolled: &mut Vec<(f64, f64)>,
) -> Option<RolledComb> {
    let fit_at = |roll: f64, rolled: &mut Vec<(f64, f64)>| {
        rolled.clear();
        rolled.extend(peaks.iter().map(|&(w, x)| (w, axis.to_rolled(x, roll))));
        fit_peak_comb(rolled, search).map(|comb| RolledComb { comb, roll })
    };
    let better = |a: Option<RolledComb>, b: Option<RolledComb>| match (a, b) {
        (Some(x), Some(y)) if y.comb.contrast > x.comb.contrast => Some(y),
        (None, y) => y,
        (x, _) => x,
    };
    let mut best = fit_at(0.0, rolled);
    if max_roll > 0.0 && roll_step > 0.0 {
        let n = (max_roll / roll_step).floor() as i64;
        for k in (-n..=n).filter(|&k| k != 0) {
            best = better(best, fit_at(k as f64 * roll_step, rolled));
        }
        let mut step = roll_step / 2.0;
        for _ in 0..2 {
            if let Some(b) = best {
                for r in [b.roll - step, b.roll + step] {
                    if r.abs() <= max_roll {
                        best = better(best, fit_at(r, rolled));
                    }
                }
            }
            step /= 2.0;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn a_clean_comb_is_found() {
        let peaks: Vec<(f64, f64)> = (2..9).map(|k| (1.0, 12.0 + 37.0 * k as f64)).collect();
        let c = fit_peak_comb(&peaks, &CombSearch::default()).unwrap();
        assert!((c.period - 37.0).abs() < 0.1, "{c:?}");
        assert!(c.nearest_tooth(12.0 + 5.0 * 37.0).1 < 0.1, "{c:?}");
        assert!(c.contrast > 0.99 && c.on_comb == 7, "{c:?}");
    }

    #[test]
    fn too_few_peaks_give_no_comb() {
        let search = CombSearch::default();
        assert!(fit_peak_comb(&[(1.0, 10.0), (1.0, 50.0)], &search).is_none());
        assert!(fit_peak_comb(&[], &search).is_none());
    }

    #[test]
    fn nearest_tooth_and_tooth_agree() {
        let c = ProfileComb {
            period: 10.0,
            phase: 3.0,
            contrast: 1.0,
            on_comb: 3,
        };
        assert_eq!(c.nearest_tooth(24.0), (2, 1.0));
        assert_eq!(c.tooth(2), 23.0);
        assert_eq!(c.nearest_tooth(-6.0).0, -1);
    }

    #[test]
    fn a_rolled_comb_is_found_at_its_roll() {
        // Rows evenly spaced in tan(ψ − 0.2), measured in tan ψ: the comb bends.
        let axis = TanAxis {
            start: -4.0,
            bin: 0.01,
        };
        let roll = 0.2f64;
        let peaks: Vec<(f64, f64)> = (-4..=4)
            .map(|k| (1.0, axis.bin_of((((k as f64) * 0.3).atan() + roll).tan())))
            .collect();
        let search = CombSearch {
            tolerance: 2.0,
            ..CombSearch::default()
        };
        let flat = fit_peak_comb(&peaks, &search).unwrap();
        let mut buf = Vec::new();
        let r = fit_peak_comb_rolled(&peaks, &axis, &search, 0.35, 0.05, &mut buf).unwrap();
        assert!((r.roll - roll).abs() < 0.02, "{r:?}");
        assert!((r.comb.period - 30.0).abs() < 0.5, "{r:?}");
        assert!(
            r.comb.on_comb == 9 && r.comb.contrast > flat.contrast,
            "{r:?} against {flat:?}"
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]
        /// A comb with jitter, a missing tooth and an off-comb outlier still gives its period
        /// (not a harmonic) and its phase, and the outlier is off it.
        #[test]
        fn noisy_comb_with_outliers_gives_period_and_phase(
            period in 15.0f64..60.0,
            phase in 0.0f64..100.0,
            missing in 1i64..6,
            outlier_frac in 0.3f64..0.7,
            jitter in proptest::collection::vec(-1.0f64..1.0, 7),
            weights in proptest::collection::vec(0.5f64..1.0, 7),
        ) {
            let mut peaks: Vec<(f64, f64)> = (0..7)
                .filter(|&k| k != missing)
                .map(|k| (weights[k as usize], phase + k as f64 * period + jitter[k as usize]))
                .collect();
            let outlier = phase + (2.0 + outlier_frac) * period;
            peaks.push((0.7, outlier));
            let c = fit_peak_comb(&peaks, &CombSearch::default()).unwrap();
            prop_assert!((c.period - period).abs() < 0.03 * period, "{c:?} period {period}");
            let (_, d) = c.nearest_tooth(phase + 3.0 * period);
            prop_assert!(d < 1.5, "{c:?} phase {phase}: off by {d}");
            let (_, d) = c.nearest_tooth(outlier);
            prop_assert!(d > 0.2 * period, "{c:?}: outlier {outlier} on a tooth");
        }
    }
}
