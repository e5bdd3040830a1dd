//! The rows' comb: evenly spaced parallel lines on the ground fitted to the rows' lateral
//! positions.
//!
//! Owns [`fit_comb`] and its result [`Comb`]: from the lateral positions `y_i` of the detected
//! rows (metres, left of the camera's foot point) it finds the spacing `s` (estimated, or
//! configured and only checked), the comb's position `c` (the comb line nearest the camera,
//! in (−s/2, s/2]) and each row's integer index `k_i` with `y_i ≈ c + k_i·s`, by weighted least
//! squares. A row's lateral position is measured through the angle of its plane, so its error
//! grows as `(h² + y²)/h`: rows are weighted by `(1 + (y/h)²)⁻²`. Rows more than a quarter
//! spacing from their comb line are not the field's rows (weeds, a headland's edge): they
//! get index `None` and no weight. [`fit_comb_with_roll`] also finds the roll about the rows
//! that makes the comb most even (the comb's spacing left and right of the robot differ
//! under a roll on flat ground).

use super::ground::GroundFrame;
use nalgebra::Vector3;

/// A fitted comb.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Comb {
    /// Row spacing, metres (the configured one when it is fixed).
    pub spacing_m: f64,
    /// Spacing measured from the rows whether or not it is fixed (`None` with fewer than two
    /// distinct comb lines).
    pub measured_spacing_m: Option<f64>,
    /// Lateral position (left of the camera's foot point) of the comb line nearest the
    /// camera, metres, in (−s/2, s/2].
    pub offset_m: f64,
    /// Weighted RMS distance of the rows from their comb lines, metres.
    pub rms_m: f64,
    /// Standard deviation of `offset_m` and of `spacing_m` from the fit, metres.
    pub offset_sd_m: f64,
    pub spacing_sd_m: f64,
    /// Rows on the comb, and how many of them lie left (index > 0) and right (< 0) of the
    /// camera's comb line.
    pub rows_used: usize,
    pub rows_left: usize,
    pub rows_right: usize,
}

/// What [`fit_comb`] needs besides the rows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CombOptions {
    /// The spacing when it is configured; with `fixed_spacing` it is not estimated.
    pub spacing_m: Option<f64>,
    pub fixed_spacing: bool,
    /// Plausible spacings, metres.
    pub min_spacing_m: f64,
    pub max_spacing_m: f64,
    /// Camera height (sets the weights), metres.
    pub height_m: f64,
    /// Floor of the per-row position error, metres (the fit's residual below it is luck).
    pub min_row_sd_m: f64,
}

/// Fits the comb to the rows' lateral positions `ys`, writing each row's index (relative to
/// the comb line nearest the camera) into `index`. `None` with no two rows on one comb of a
/// plausible spacing.
pub fn fit_comb(ys: &[f64], opts: &CombOptions, index: &mut [Option<i64>]) -> Option<Comb> {
    let n = ys.len();
    debug_assert_eq!(index.len(), n);
    if n < 2 {
        return None;
    }
    let h = opts.height_m;
    let weight = |y: f64| {
        let q = 1.0 + (y / h).powi(2);
        1.0 / (q * q)
    };
    let (mut s, mut c) = initial_comb(ys, opts)?;
    let mut fit = None;
    for _ in 0..4 {
        // indices relative to the current comb, rows far from a line left out
        let (mut sw, mut swk, mut swkk, mut swy, mut swky) = (0.0, 0.0, 0.0, 0.0, 0.0);
        let mut used = 0;
        for (i, &y) in ys.iter().enumerate() {
            let kf = (y - c) / s;
            let k = kf.round();
            if (kf - k).abs() > 0.25 {
                index[i] = None;
                continue;
            }
            index[i] = Some(k as i64);
            let w = weight(y);
            sw += w;
            swk += w * k;
            swkk += w * k * k;
            swy += w * y;
            swky += w * k * y;
            used += 1;
        }
        if used < 2 {
            return None;
        }
        let det = sw * swkk - swk * swk;
        let distinct = det > 1e-9 * sw * sw.max(1.0);
        let measured = distinct.then(|| (sw * swky - swk * swy) / det);
        let (new_s, new_c) = match (measured, opts.fixed_spacing) {
            (Some(ms), false) => (ms, (swy - ms * swk) / sw),
            _ => (s, (swy - s * swk) / sw),
        };
        if !(new_s >= opts.min_spacing_m && new_s <= opts.max_spacing_m && new_c.is_finite()) {
            return None;
        }
        s = new_s;
        c = new_c;
        fit = Some((measured, sw, swk, swkk, used, det));
    }
    let (measured, sw, swk, swkk, used, det) = fit?;
    // residuals and the side counts
    let (mut ssr, mut left, mut right) = (0.0, 0, 0);
    for (i, &y) in ys.iter().enumerate() {
        if let Some(k) = index[i] {
            let r = y - c - k as f64 * s;
            ssr += weight(y) * r * r;
        }
    }
    // move the reference line to the one nearest the camera
    let shift = (c / s - 0.5).ceil();
    c -= shift * s;
    for k in index.iter_mut().flatten() {
        *k += shift as i64;
        if *k > 0 {
            left += 1;
        } else if *k < 0 {
            right += 1;
        }
    }
    let rms = (ssr / sw).sqrt();
    let two = !opts.fixed_spacing && measured.is_some();
    let dof = if two { 2.0 } else { 1.0 };
    let sigma2 = (ssr / sw * used as f64 / (used as f64 - dof).max(1.0))
        .max(opts.min_row_sd_m * opts.min_row_sd_m);
    // covariance sigma²·(XᵀWX)⁻¹ of (c, s), X = [1, k], the weights relative to a row straight
    // below the camera; c moved by `shift` lines: Var(c − shift·s)
    let (var_c, var_s) = if two {
        (
            sigma2 * (swkk + 2.0 * shift * swk + shift * shift * sw) / det,
            sigma2 * sw / det,
        )
    } else {
        (sigma2 / sw, 0.0)
    };
    Some(Comb {
        spacing_m: s,
        measured_spacing_m: measured.filter(|m| m.is_finite()),
        offset_m: c,
        rms_m: rms,
        offset_sd_m: var_c.max(0.0).sqrt(),
        spacing_sd_m: var_s.max(0.0).sqrt(),
        rows_used: used,
        rows_left: left,
        rows_right: right,
    })
}

/// Indices of the (up to) `N` rows nearest the camera, nearest first.
fn nearest<const N: usize>(ys: &[f64]) -> ([usize; N], usize) {
    let mut idx = [0usize; N];
    let mut m = 0;
    for (i, y) in ys.iter().enumerate() {
        let mut pos = m;
        while pos > 0 && ys[idx[pos - 1]].abs() > y.abs() {
            pos -= 1;
        }
        if pos < N {
            let end = m.min(N - 1);
            for j in (pos..end).rev() {
                idx[j + 1] = idx[j];
            }
            idx[pos] = i;
            m = (m + 1).min(N);
        }
    }
    (idx, m)
}

/// The first guess of the comb: a spacing and a row on it. Candidate spacings are the gaps
/// between the six rows nearest the camera divided by 1, 2 or 3 (or the configured one),
/// candidate anchors the three nearest rows. Within three heights of the camera, each pair
/// scores the rows near its comb lines, less half a point per comb line between the outermost
/// such rows with no row near it; the best score wins, ties to the larger spacing. A half
/// spacing fits every row (and a weed line between rows) but leaves half its lines empty; a
/// double one misses every other row.
fn initial_comb(ys: &[f64], opts: &CombOptions) -> Option<(f64, f64)> {
    let (near, m) = nearest::<6>(ys);
    // rows near a comb line count (down to 0 at 15% of a spacing off), comb lines between the
    // outermost rows with no row near them count against, by half
    let reach = 3.0 * opts.height_m;
    let score = |s: f64, anchor: f64| -> f64 {
        let (mut hits, mut lo, mut hi) = (0.0, f64::INFINITY, f64::NEG_INFINITY);
        let mut near_lines = 0usize;
        for &y in ys.iter().filter(|y| y.abs() <= reach) {
            let f = (y - anchor) / s;
            let r = (f - f.round()).abs();
            hits += (1.0 - r / 0.15).max(0.0);
            if r < 0.15 {
                near_lines += 1;
                lo = lo.min(f.round());
                hi = hi.max(f.round());
            }
        }
        let lines = if hi >= lo { (hi - lo) as usize + 1 } else { 0 };
        hits - 0.5 * lines.saturating_sub(near_lines) as f64
    };
    // every candidate spacing, once with the best score any anchor gives it
    let each = |f: &mut dyn FnMut(f64)| match opts.spacing_m {
        Some(s) => f(s),
        None => {
            for i in 0..m {
                for j in i + 1..m {
                    let d = (ys[near[i]] - ys[near[j]]).abs();
                    for div in 1..=3 {
                        f(d / div as f64);
                    }
                }
            }
        }
    };
    let best_anchor = |s: f64| -> Option<(f64, f64)> {
        if !(s >= opts.min_spacing_m && s <= opts.max_spacing_m) {
            return None;
        }
        near[..m.min(3)]
            .iter()
            .map(|&a| (score(s, ys[a]), ys[a]))
            .max_by(|x, y| x.0.total_cmp(&y.0))
    };
    let mut best: Option<(f64, f64, f64)> = None; // score, s, anchor
    each(&mut |s| {
        if let Some((sc, a)) = best_anchor(s) {
            let better =
                best.is_none_or(|(bsc, bs, _)| sc > bsc + 1e-9 || (sc > bsc - 1e-9 && s > bs));
            if better {
                best = Some((sc, s, a));
            }
        }
    });
    best.map(|(_, s, a)| (s, a))
}

/// The comb's weighted squared residual over all rows, each capped at a quarter spacing (a
/// row off the comb counts, but boundedly).
fn comb_cost(ys: &[f64], c: &Comb, h: f64) -> f64 {
    let cap = (c.spacing_m / 4.0).powi(2);
    ys.iter()
        .map(|&y| {
            let f = (y - c.offset_m) / c.spacing_m;
            let r = (f - f.round()) * c.spacing_m;
            let q = 1.0 + (y / h).powi(2);
            (r * r).min(cap) / (q * q)
        })
        .sum()
}

/// Fits the comb as [`fit_comb`] after finding the roll about the rows that makes it most even,
/// when enough rows are seen on both sides (two each, five in all); else at zero roll.
/// `normals` are the rows' plane normals in the robot frame; `ys` receives their lateral
/// positions at the chosen roll. Returns the comb, the frame at the chosen roll and the
/// roll (`None`: unobserved).
pub fn fit_comb_with_roll(
    frame: &GroundFrame,
    normals: &[Vector3<f64>],
    max_roll_rad: f64,
    opts: &CombOptions,
    ys: &mut [f64],
    index: &mut [Option<i64>],
) -> Option<(Comb, GroundFrame, Option<f64>)> {
    let lateral = |g: &GroundFrame, ys: &mut [f64]| -> bool {
        for (y, n) in ys.iter_mut().zip(normals) {
            match g.row_lateral_m(n) {
                Some(v) => *y = v,
                None => return false,
            }
        }
        true
    };
    if !lateral(frame, ys) {
        return None;
    }
    let flat = fit_comb(ys, opts, index)?;
    if max_roll_rad <= 0.0 || flat.rows_left < 2 || flat.rows_right < 2 || flat.rows_used < 5 {
        return Some((flat, *frame, None));
    }
    // the comb's weighted residual, each row's capped at a quarter spacing, over the roll:
    // a grid, then a golden-section search around its best point
    let hint = CombOptions {
        spacing_m: Some(flat.spacing_m),
        ..*opts
    };
    let mut cost = |roll: f64| -> f64 {
        let g = frame.rolled(roll);
        if !lateral(&g, ys) {
            return f64::INFINITY;
        }
        match fit_comb(ys, &hint, index) {
            Some(c) => comb_cost(ys, &c, opts.height_m),
            None => f64::INFINITY,
        }
    };
    const GRID: usize = 16;
    let step = 2.0 * max_roll_rad / GRID as f64;
    let (mut best, mut best_cost) = (0.0, cost(0.0));
    for i in 0..=GRID {
        let x = -max_roll_rad + i as f64 * step;
        let c = cost(x);
        if c < best_cost {
            (best, best_cost) = (x, c);
        }
    }
    let phi = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut b) = (best - step, best + step);
    let mut x1 = b - phi * (b - a);
    let mut x2 = a + phi * (b - a);
    let (mut f1, mut f2) = (cost(x1), cost(x2));
    for _ in 0..40 {
        if f1 <= f2 {
            b = x2;
            x2 = x1;
            f2 = f1;
            x1 = b - phi * (b - a);
            f1 = cost(x1);
        } else {
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + phi * (b - a);
            f2 = cost(x2);
        }
        if b - a < 1e-6 {
            break;
        }
    }
    let roll = 0.5 * (a + b);
    let g = frame.rolled(roll);
    if !lateral(&g, ys) {
        lateral(frame, ys);
        let flat = fit_comb(ys, opts, index)?;
        return Some((flat, *frame, None));
    }
    let comb = fit_comb(ys, opts, index)?;
    Some((comb, g, Some(roll)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Mounting;
    use crate::synth::Pose;
    use proptest::prelude::*;

    fn opts(spacing: Option<f64>, fixed: bool) -> CombOptions {
        CombOptions {
            spacing_m: spacing,
            fixed_spacing: fixed,
            min_spacing_m: 0.2,
            max_spacing_m: 1.5,
            height_m: 1.0,
            min_row_sd_m: 0.002,
        }
    }

    #[test]
    fn exact_comb_with_a_gap_and_a_weed() {
        // rows at 0.5 k - 0.1, row k = 2 missing, a weed line at 0.13
        let ys = [-1.1, -0.6, -0.1, 0.4, 1.4, 1.9, 0.13];
        let mut idx = [None; 7];
        let c = fit_comb(&ys, &opts(None, false), &mut idx).unwrap();
        assert!((c.spacing_m - 0.5).abs() < 1e-12, "{c:?}");
        assert!((c.offset_m + 0.1).abs() < 1e-12);
        assert_eq!(
            idx,
            [Some(-2), Some(-1), Some(0), Some(1), Some(3), Some(4), None]
        );
        assert_eq!((c.rows_used, c.rows_left, c.rows_right), (6, 3, 2));
        assert!(c.rms_m < 1e-12);
        assert!(c.offset_sd_m > 0.0 && c.offset_sd_m < 0.003);
    }

    #[test]
    fn fixed_spacing_is_kept_and_measured() {
        let ys = [-0.55, -0.0, 0.55, 1.1];
        let mut idx = [None; 4];
        let c = fit_comb(&ys, &opts(Some(0.5), true), &mut idx).unwrap();
        assert_eq!(c.spacing_m, 0.5);
        assert!((c.measured_spacing_m.unwrap() - 0.55).abs() < 1e-9);
        assert!(fit_comb(&[0.1], &opts(None, false), &mut [None]).is_none());
    }

    proptest! {
        /// Any comb, any offset, some rows missing: spacing, offset and indices come back.
        #[test]
        fn comb_recovered(
            s in 0.3f64..1.0, c in -0.5f64..0.5, lo in -6i64..-1, hi in 1i64..6, skip in 0usize..4,
        ) {
            let c = c * s; // (-s/2, s/2)
            let mut ys = Vec::new();
            let mut ks = Vec::new();
            for (j, k) in (lo..=hi).enumerate() {
                if j == skip + 2 { continue; }
                ys.push(c + k as f64 * s);
                ks.push(Some(k));
            }
            let mut idx = vec![None; ys.len()];
            let o = CombOptions { min_spacing_m: 0.25, max_spacing_m: 1.2, ..opts(None, false) };
            let comb = fit_comb(&ys, &o, &mut idx).unwrap();
            prop_assert!((comb.spacing_m - s).abs() < 1e-9);
            prop_assert!((comb.offset_m - c).abs() < 1e-9);
            prop_assert_eq!(idx, ks);
        }
    }

    #[test]
    fn roll_found_from_uneven_comb() {
        let m = Mounting::default();
        let roll = 2f64.to_radians();
        let pose = Pose::new(0.0, 0.0, roll, &m, Vector3::new(0.0, 0.2, 1.0));
        let r = m.robot_from_camera();
        let normals: Vec<_> = (-4..=5)
            .map(|k| {
                let n = pose
                    .line_normal(&Vector3::new(0.0, k as f64 * 0.5, 0.0), &Vector3::x())
                    .unwrap();
                r * n
            })
            .collect();
        let frame = GroundFrame::new(&pose.vp_along(), &m, 0.0).unwrap();
        let mut ys = vec![0.0; normals.len()];
        let mut idx = vec![None; normals.len()];
        let (comb, _, got) =
            fit_comb_with_roll(&frame, &normals, 0.2, &opts(None, false), &mut ys, &mut idx)
                .unwrap();
        let got = got.unwrap();
        assert!((got - roll).abs() < 1e-4, "{got} vs {roll}");
        assert!((comb.spacing_m - 0.5).abs() < 1e-4);
        assert!((comb.offset_m - -0.2).abs() < 1e-4, "{comb:?}");
    }
}
