//! The strips' peaks: the virtual image cut into strips along the horizon, each strip's
//! vegetation profile across the image (the points' weights in 1 px bins), smoothed, and its
//! peaks: the local maxima that stand out by their prominence, where crop rows cross the
//! strip. The peaks can be read with each strip straightened about a vanishing point, so that
//! a row crossing a strip at a slant is one sharp peak rather than a smear as wide as the
//! strip's height times its slope.

use super::StripsRows;

/// Height of one strip along the virtual image's vertical (pixels).
const STRIP_PX: f64 = 11.0;

/// Gaussian smoothing (sigma, pixels) of a strip's profile before its peaks are read: about
/// a plant's half-width.
const SMOOTH_PX: f64 = 2.5;

/// A peak's height is its prominence within this many pixels on either side: how far it
/// stands above the higher of the lowest points left and right of it. Rows inside dense
/// canopy stand above their valleys, though not above the strip's typical level.
const PROMINENCE_PX: usize = 15;

/// A local maximum is a peak when its prominence is at least this fraction of the strip's
/// most prominent one.
const PEAK_FRACTION: f64 = 0.15;

/// A peak of a strip: along the horizon, below it (pixels), its height, its strip.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Peak {
    pub(super) a: f64,
    pub(super) p: f64,
    pub(super) w: f64,
    pub(super) strip: u32,
}

impl StripsRows {
    /// Each strip's profile across the image, smoothed, and its peaks into `self.peaks` (in
    /// the strips' order, deepest last), each strip's extent into `self.spans`; with `about`
    /// (a vanishing point, along and below), each point first moved along its line through
    /// that point to its strip's centre line.
    pub(super) fn read_peaks(&mut self, about: Option<(f64, f64)>) {
        self.peaks.clear();
        let (mut p0, mut p1) = (f64::MAX, f64::MIN);
        for &[_, p, _] in &self.pts {
            p0 = p0.min(p);
            p1 = p1.max(p);
        }
        let centre = |s: usize| p0 + (s as f64 + 0.5) * STRIP_PX;
        // the point's strip and its position along it, straightened about `about` (a point
        // less than a strip below that point stays: its line is too steep to follow)
        let place = |a: f64, p: f64| {
            let s = ((p - p0) / STRIP_PX) as usize;
            let Some((av, pv)) = about else {
                return (s, a);
            };
            let (d, dc) = (p - pv, centre(s) - pv);
            if d >= STRIP_PX && dc >= 0.5 * STRIP_PX {
                (s, av + (a - av) * dc / d)
            } else {
                (s, a)
            }
        };
        let (mut a0, mut a1) = (f64::MAX, f64::MIN);
        for &[a, p, _] in &self.pts {
            let (_, a) = place(a, p);
            a0 = a0.min(a);
            a1 = a1.max(a);
        }
        if self.pts.len() < 2 || a1 <= a0 || p1 <= p0 {
            return;
        }
        // at most 4096 strips and 16384 bins: a hostile calibration or image cannot make
        // the buffers grow without bound
        let strips = (((p1 - p0) / STRIP_PX).floor() as usize + 1).min(4096);
        let bins = ((a1 - a0).floor() as usize + 1).min(16384);
        self.hist.clear();
        self.hist.resize(strips * bins, 0.0);
        for &[a, p, w] in &self.pts {
            let (s, a) = place(a, p);
            let b = (a - a0) as usize;
            if s < strips && b < bins {
                self.hist[s * bins + b] += w;
            }
        }
        self.spans.clear();
        for s in 0..strips {
            let row = &self.hist[s * bins..(s + 1) * bins];
            let lo = row.iter().position(|&x| x > 0.0);
            let hi = row.iter().rposition(|&x| x > 0.0);
            if let (Some(lo), Some(hi)) = (lo, hi) {
                self.spans
                    .push([centre(s), a0 + lo as f64, a0 + hi as f64 + 1.0]);
            }
            self.strip_peaks(s, bins, a0, centre(s));
        }
    }

    /// The peaks of strip `s` (its centre `p` below the horizon), its profile the `bins`
    /// bins of `self.hist` from `a0` along.
    fn strip_peaks(&mut self, s: usize, bins: usize, a0: f64, p: f64) {
        let row = &self.hist[s * bins..(s + 1) * bins];
        if row.iter().all(|&x| x == 0.0) {
            return;
        }
        smooth_profile(row, &self.kernel, &mut self.smooth);
        let sm = &self.smooth;
        let is_max = |i: usize| sm[i] > sm[i - 1] && sm[i] >= sm[i + 1];
        let top = (1..bins.saturating_sub(1))
            .filter(|&i| is_max(i))
            .map(|i| prominence(sm, i, PROMINENCE_PX))
            .fold(0.0f64, f64::max);
        if top <= 0.0 {
            return;
        }
        let floor = PEAK_FRACTION * top;
        for i in 1..bins.saturating_sub(1) {
            let (l, c, r) = (sm[i - 1], sm[i], sm[i + 1]);
            let h = if is_max(i) {
                prominence(sm, i, PROMINENCE_PX)
            } else {
                0.0
            };
            if h > 0.0 && h >= floor {
                // the parabola through the three bins for the peak's sub-pixel position
                let den = l - 2.0 * c + r;
                let off = if den < 0.0 {
                    (0.5 * (l - r) / den).clamp(-0.5, 0.5)
                } else {
                    0.0
                };
                self.peaks.push(Peak {
                    a: a0 + i as f64 + 0.5 + off,
                    p,
                    w: h,
                    strip: s as u32,
                });
            }
        }
    }
}

/// The profiles' smoothing kernel: a Gaussian of sigma [`SMOOTH_PX`] cut at 3 sigma, summing
/// to 1.
pub(super) fn smoothing_kernel() -> Vec<f64> {
    let sigma = SMOOTH_PX;
    let half = (3.0 * sigma).ceil() as usize;
    let mut kernel: Vec<f64> = (0..=2 * half)
        .map(|i| {
            let x = i as f64 - half as f64;
            (-0.5 * x * x / (sigma * sigma)).exp()
        })
        .collect();
    let sum: f64 = kernel.iter().sum();
    for k in &mut kernel {
        *k /= sum;
    }
    kernel
}

/// `row` convolved with the odd-length `kernel` into `out` (cleared first), the kernel cut
/// at the row's ends: out[i] = Σ over j within the kernel's reach of i and inside the row of
/// row[j]·kernel[j + half − i], summed in increasing j. Where the kernel lies wholly inside
/// the row, eight outputs at a time (each summed in the same order, so the same to the bit).
fn smooth_profile(row: &[f64], kernel: &[f64], out: &mut Vec<f64>) {
    const LANES: usize = 8;
    let (bins, half) = (row.len(), kernel.len() / 2);
    let cut = |i: usize| {
        let (lo, hi) = (
            i.saturating_sub(half),
            (i + half).min(bins.saturating_sub(1)),
        );
        let mut acc = 0.0;
        for (j, x) in row.iter().enumerate().take(hi + 1).skip(lo) {
            acc += x * kernel[j + half - i];
        }
        acc
    };
    out.clear();
    // outputs half..inner_end in blocks of eight have the whole kernel inside the row
    let inner = bins.saturating_sub(2 * half);
    let inner_end = half + inner / LANES * LANES;
    out.extend((0..half.min(bins)).map(cut));
    for i0 in (half..inner_end).step_by(LANES) {
        let mut acc = [0.0f64; LANES];
        for (t, &k) in kernel.iter().enumerate() {
            let x = &row[i0 - half + t..i0 - half + t + LANES];
            for l in 0..LANES {
                acc[l] += x[l] * k;
            }
        }
        out.extend_from_slice(&acc);
    }
    out.extend((out.len()..bins).map(cut));
}

/// How far `sm[i]` stands above the higher of the lowest values within `win` bins on its
/// left and on its right (the profile's ends bound a side with fewer bins).
fn prominence(sm: &[f64], i: usize, win: usize) -> f64 {
    let low = |xs: &[f64]| xs.iter().fold(f64::INFINITY, |m, &x| m.min(x));
    let left = low(&sm[i.saturating_sub(win)..i]);
    let right = low(&sm[(i + 1).min(sm.len())..(i + 1 + win).min(sm.len())]);
    let base = left.max(right);
    if base.is_finite() {
        sm[i] - base
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::*;
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn the_profile_smoothed_in_blocks_is_the_cut_convolution_to_the_bit() {
        let mut next = uniform(9);
        let mut out = Vec::new();
        for bins in [0, 1, 2, 5, 16, 17, 33, 40, 257] {
            for half in [0, 1, 3, 8] {
                let row: Vec<f64> = (0..bins)
                    .map(|_| if next() < 0.3 { 0.0 } else { next() * 100.0 })
                    .collect();
                let kernel: Vec<f64> = (0..2 * half + 1).map(|_| next()).collect();
                smooth_profile(&row, &kernel, &mut out);
                assert_eq!(out.len(), bins);
                for (i, &o) in out.iter().enumerate() {
                    let mut want = 0.0;
                    for (j, x) in row.iter().enumerate() {
                        if j + half >= i && j <= i + half {
                            want += x * kernel[j + half - i];
                        }
                    }
                    assert_eq!(o.to_bits(), want.to_bits(), "bins {bins} half {half} i {i}");
                }
            }
        }
    }

    #[test]
    fn a_peak_stands_above_its_valleys_not_above_the_profiles_level() {
        // a small bump on a high plateau, a big one beside a deep valley
        let sm = [5.0, 6.0, 5.0, 5.0, 5.0, 0.0, 0.0, 9.0, 0.0, 0.0];
        assert_eq!(prominence(&sm, 1, 3), 1.0);
        assert_eq!(prominence(&sm, 7, 3), 9.0);
        // the profile's ends bound the sides
        assert_eq!(prominence(&sm, 7, 100), 9.0);
        // a maximum in the profile's last bin has no right side to stand above
        assert_eq!(prominence(&[1.0, 3.0], 1, 2), 0.0);
    }

    #[test]
    fn rows_beside_dense_canopy_stand_out_by_their_prominence() {
        // 0.5 m rows; on the left of y = -0.3 m (REP 103: y to the left) a carpet of
        // vegetation between them, denser than the rows' own plants a little way out: it
        // raises every strip's typical level above the bare right side's rows
        let m = forward_camera();
        let ys: Vec<f64> = (-4..=4).map(|k| 0.1 + k as f64 * 0.5).collect();
        let mut fld = field_at(300.0, 512.0, &m, &ys, 0.0);
        let cam_from_robot = m.robot_from_camera().inverse();
        let mut rnd = uniform(777);
        for _ in 0..200_000 {
            let x = 1.0 / (1.0 - rnd() * (1.0 - 1.0 / 40.0));
            let y = -0.3 + rnd() * 6.0;
            fld.see(
                &(cam_from_robot * Vector3::new(x, y, -m.height_m)),
                300.0,
                512.0,
            );
        }
        // the true rows right of the carpet, each found (within 4 px-angles)
        let bare: Vec<Vector3<f64>> = ys
            .iter()
            .zip(&fld.normals)
            .filter(|(y, _)| **y < -0.3)
            .map(|(_, n)| *n)
            .collect();
        let (_, _, rows) = detect(&fld, &m);
        let found = bare
            .iter()
            .filter(|t| {
                rows.iter()
                    .any(|r| nearest(&r.normal, &[**t]) < 4.0 / 300.0)
            })
            .count();
        assert_eq!(found, bare.len(), "rows beside the canopy found");
    }

    #[test]
    fn rows_slanting_across_the_strips_are_found_once_straightened() {
        let m = forward_camera();
        let fld = field(300.0, 512.0, &m, 0.5, 0.2, 2f64.to_radians());
        let (mut s, vp, rows) = detect(&fld, &m);
        vp.expect("a vanishing point");
        for r in &rows {
            let e = nearest(&r.normal, &fld.normals);
            assert!(e < 2.5 / 300.0, "a row {e} rad off");
        }
        // the comb on the peaks as the search read them, not straightened: the outer rows
        // cross each strip at a slant, a smear rather than a peak
        let [a, p] = s.last().vanishing_px.unwrap();
        s.read_peaks(None);
        let mut sheared = Vec::new();
        s.comb_rows(a, p, &mut sheared);
        assert!(
            rows.len() >= sheared.len() + 4,
            "{} rows straightened, {} not",
            rows.len(),
            sheared.len()
        );
    }
}
