//! The combined method's final vanishing-point fit: rows weighted by their method's precision.
//!
//! Owns the step after the paper's eq. 5 vote (II-F). The vote, with edge rows weighted
//! w·support and Hough rows (1−w)·support, picks the vanishing point and its inlier rows
//! robustly; but the two methods' rows are not equally precise (the edge method's boundary
//! lines scatter several times more about the vanishing point than the Hough centre lines on
//! nearly solid rows, and less on sparse ones), so a final fit with the vote's weights lets
//! the noisier method pull the answer away from the better one. Here each method's scatter
//! is measured on the image itself: the inlier rows of one method alone are fitted to a
//! common direction and their residual scale, corrected for the two degrees of freedom the
//! fit absorbs, is that method's σₘ (with fewer than three inlier rows, the
//! residual about the other method's fit is used instead). The final fit weights row i of
//! method m by (supportᵢ / mean supportₘ) / σ²ₘ: inverse-variance weighting between methods,
//! support weighting within one (edge rows halved, as each crop row gives two boundaries),
//! times a Cauchy weight 1 / (1 + (rᵢ / (c·σₘ))²) of the row's own residual rᵢ, iterated
//! (IRLS): short stray sections a few mrad off would otherwise outweigh long exact ones.
//! The scatter σₘ is robust (1.4826 × the support-weighted median |residual|, the MAD).
//! Rows the vote rejected stay rejected. The same fit serves the edge method alone (one
//! method: a robust support-weighted fit).

use super::centre::{half_way_limit, strongest_either_side};
use super::types::{Detection, Method, Row};
use crate::sphere::Scatter;
use nalgebra::Vector3;

/// The outcome of [`precision_fit`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrecisionFit {
    /// The refitted direction (the sign of the vote's direction).
    pub direction: Vector3<f64>,
    /// Weighted RMS angular residual (radians) of the inlier rows.
    pub residual_rad: f64,
    /// The per-method robust scatter (radians) used: Hough, edge (0 for a method without
    /// inlier rows).
    pub sigma_hough: f64,
    pub sigma_edge: f64,
    /// The same for the centre lines of paired edge boundaries ([`pair_edge_rows`]).
    pub sigma_paired: f64,
}

/// The widest half-width of a crop row (degrees, around the vanishing point) at the
/// reference angular resolution: a Hough row and an edge boundary pair when they are at most
/// this far apart (the half-width of a crop row seen from the camera is a few degrees;
/// neighbouring rows are farther apart).
pub const REFERENCE_PAIR_MAX_DEG: f64 = 5.0;

/// The smallest per-method scatter (mrad) the precision fit assumes, so that a few rows
/// agreeing by chance cannot take all the weight.
pub const PRECISION_FLOOR_MRAD: f64 = 0.02;

/// The final fit of the edge and combined methods, with its reusable buffers: the vote's
/// vanishing point refitted over its inlier rows with each method weighted by the
/// precision its rows show on the image ([`precision_fit`]).
#[derive(Debug, Clone, Default)]
pub struct PrecisionRefit {
    weights: Vec<f64>,
    scratch: Vec<(f64, f64)>,
    paired_rows: Vec<Row>,
    paired_inliers: Vec<bool>,
    pair_scratch: Vec<(f64, usize, Kind)>,
}

impl PrecisionRefit {
    /// Refits `out`'s vanishing point over the rows flagged in `inliers`. With
    /// `pair_max_rad` (the combined method), the edge boundaries either side of a Hough row
    /// first pair into its centre line ([`pair_edge_rows`]); `hough_var` holds the Hough
    /// rows' variances along the vanishing point as the refit estimated them. Keeps the
    /// vote's fit when the refit cannot be made.
    pub fn run(
        &mut self,
        out: &mut Detection,
        inliers: &[bool],
        pair_max_rad: Option<f64>,
        hough_var: &[f64],
    ) {
        let Some(vp) = out.vanishing_point else {
            return;
        };
        let floor = PRECISION_FLOOR_MRAD * 1e-3;
        let paired = pair_max_rad.is_some_and(|max_half| {
            pair_edge_rows(
                &out.rows,
                inliers,
                &vp.direction,
                max_half,
                &mut self.paired_rows,
                &mut self.paired_inliers,
                &mut self.pair_scratch,
            ) > 0
        });
        let (rows, inliers) = if paired {
            (&self.paired_rows[..], &self.paired_inliers[..])
        } else {
            (&out.rows[..], inliers)
        };
        let Some(fit) = precision_fit(
            rows,
            inliers,
            &vp.direction,
            floor,
            EDGE_PAIR_FACTOR,
            hough_var,
            &mut self.weights,
            &mut self.scratch,
        ) else {
            return;
        };
        out.set_vanishing_point(fit.direction, vp.inliers, fit.residual_rad);
    }
}

/// Cauchy constant, in units of the method's robust scatter. Wider than the textbook 2.385
/// (95% efficiency on Gaussian residuals): rows' errors are heavy-tailed but not Gaussian in
/// the core, and 3.5–5 gave the best Table I figures for both lenses (seeds 1–20, 1224×1025).
const CAUCHY: f64 = 4.0;
/// The edge method finds both boundaries of a crop row, and their errors are not
/// independent (the same plants, the same smoothing): the edge rows' weight is halved so that
/// a crop row counts about once, as its Hough centre line does. Measured on Table I (40
/// images per lens, 1224×1025): 1.0 let the edge rows' common bias pull the fisheye answer
/// past the Hough one on some seeds; 0.5 keeps the combined method the better on both lenses.
pub const EDGE_PAIR_FACTOR: f64 = 0.5;
/// Reweighting iterations of the final fit.
const ITERATIONS: usize = 6;

/// Per-method sums for the fit.
#[derive(Debug, Clone, Copy, Default)]
struct MethodStats {
    support: f64,
    count: usize,
    sigma: f64,
}

fn slot(m: Method) -> Option<usize> {
    match m {
        Method::Hough => Some(0),
        Method::Edge => Some(1),
        // Centre lines of paired edge boundaries (see [`pair_edge_rows`]): a class of
        // their own, with their own scatter.
        Method::Combined => Some(2),
        Method::Pencil | Method::Strips | Method::Auto => None,
    }
}

/// Robust (Cauchy-weighted) direction of the inlier rows of method slot `k` (all methods
/// when `None`), each weighted by `base(i)`, starting from `v0`; with `sigma` the residual
/// scale. Returns the direction.
fn irls(
    rows: &[Row],
    inliers: &[bool],
    only: Option<usize>,
    v0: &Vector3<f64>,
    base: &dyn Fn(usize) -> f64,
    sigma: &dyn Fn(usize) -> f64,
) -> Option<Vector3<f64>> {
    let mut v = *v0;
    for _ in 0..ITERATIONS {
        let mut sc = Scatter::new();
        for (i, r) in rows.iter().enumerate() {
            if !inliers[i] || (only.is_some() && slot(r.method) != only) {
                continue;
            }
            let u = r.normal.dot(&v) / (CAUCHY * sigma(i));
            let w = base(i) / (1.0 + u * u);
            if w > 0.0 {
                sc.add(&r.normal, w);
            }
        }
        let fit = sc.fit()?;
        v = if fit.normal.dot(&v) < 0.0 {
            -fit.normal
        } else {
            fit.normal
        };
    }
    Some(v)
}

/// Support-weighted median of |n·v| over the inlier rows of method slot `k`.
fn weighted_median_abs(
    rows: &[Row],
    inliers: &[bool],
    k: usize,
    v: &Vector3<f64>,
    buf: &mut Vec<(f64, f64)>,
) -> f64 {
    buf.clear();
    for (r, _) in rows.iter().zip(inliers).filter(|(_, &ok)| ok) {
        if slot(r.method) == Some(k) {
            buf.push((r.normal.dot(v).abs(), r.support as f64));
        }
    }
    buf.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let half = 0.5 * buf.iter().map(|x| x.1).sum::<f64>();
    let mut seen = 0.0;
    for &(x, w) in buf.iter() {
        seen += w;
        if seen >= half {
            return x;
        }
    }
    0.0
}

/// Each method's inlier rows: their number and summed support.
fn method_stats(rows: &[Row], inliers: &[bool]) -> [MethodStats; 3] {
    let mut stats = [MethodStats::default(); 3];
    for (r, _) in rows.iter().zip(inliers).filter(|(_, &ok)| ok) {
        let Some(k) = slot(r.method) else { continue };
        stats[k].support += r.support as f64;
        stats[k].count += 1;
    }
    stats
}

/// Each method's scatter σₘ into `stats`: the weighted median residual (MAD scale) about
/// its own robust direction (three or more rows), corrected for the two degrees of freedom
/// the direction absorbs; with fewer rows, the residual about another method's direction.
fn method_sigmas(
    rows: &[Row],
    inliers: &[bool],
    v0: &Vector3<f64>,
    floor_rad: f64,
    stats: &mut [MethodStats; 3],
    buf: &mut Vec<(f64, f64)>,
) {
    let mut own: [Option<Vector3<f64>>; 3] = [None, None, None];
    for k in 0..3 {
        if stats[k].count >= 3 {
            let m0 = weighted_median_abs(rows, inliers, k, v0, buf);
            let s0 = (1.4826 * m0).max(floor_rad);
            let sup = |i: usize| rows[i].support as f64;
            own[k] = irls(rows, inliers, Some(k), v0, &sup, &|_| s0);
        }
    }
    for k in 0..3 {
        let n = stats[k].count as f64;
        // Another class's own direction: the Hough rows' first, as the most precise.
        let other = [0, 2, 1]
            .into_iter()
            .filter(|&j| j != k)
            .find_map(|j| own[j]);
        let (reference, dof_scale) = match (own[k], other) {
            (Some(v), _) => (v, (n / (n - 2.0)).sqrt()),
            (None, Some(v)) => (v, 1.0),
            (None, None) => (*v0, 1.0),
        };
        if stats[k].count > 0 {
            let m = weighted_median_abs(rows, inliers, k, &reference, buf);
            stats[k].sigma = (1.4826 * m * dof_scale).max(floor_rad);
        }
    }
}

/// Whether every Hough inlier has an inverse variance in `hough_var` (by Hough ordinal), and
/// their mean over the inliers.
fn hough_inverse_variances(
    rows: &[Row],
    inliers: &[bool],
    hough_var: &[f64],
    stats: &[MethodStats; 3],
) -> (bool, f64) {
    let mut inv_sum = 0.0;
    let mut inv_ok = stats[0].count > 0;
    let mut j = 0;
    for (r, &ok) in rows.iter().zip(inliers) {
        if r.method != Method::Hough {
            continue;
        }
        if ok {
            match hough_var.get(j) {
                Some(&v) if v.is_finite() && v > 0.0 => inv_sum += 1.0 / v,
                _ => inv_ok = false,
            }
        }
        j += 1;
    }
    (inv_ok, inv_sum / stats[0].count.max(1) as f64)
}

/// Refits the vanishing point `v0` over the inlier rows (`inliers[i]`), weighting each method
/// by its measured precision and each row robustly (see the module documentation).
/// `floor_rad` bounds each method's σ from below so that a few rows agreeing by chance cannot
/// take all the weight. `weights` receives the final weight of every row (0 for rejected
/// ones); `scratch` is a work buffer (both are reused, so that a warmed-up caller allocates
/// nothing). Returns `None` (and leaves `weights` empty) with fewer than three inlier rows or
/// when the fit degenerates: then the vote's own fit stands.
///
/// `hough_var` holds, for the Hough rows in their order, the variance of each normal along
/// the vanishing point that the refit estimated from its own pixels (may be empty). When
/// every Hough inlier has one, the Hough class's weight is shared among its rows by the
/// inverse of that variance instead of by support, as the Hough method's own final fit does;
/// the class's total stays set by its measured scatter.
#[allow(clippy::too_many_arguments)]
pub fn precision_fit(
    rows: &[Row],
    inliers: &[bool],
    v0: &Vector3<f64>,
    floor_rad: f64,
    edge_factor: f64,
    hough_var: &[f64],
    weights: &mut Vec<f64>,
    scratch: &mut Vec<(f64, f64)>,
) -> Option<PrecisionFit> {
    weights.clear();
    if rows.len() != inliers.len() {
        return None;
    }
    let mut stats = method_stats(rows, inliers);
    if stats.iter().map(|s| s.count).sum::<usize>() < 3 {
        return None;
    }
    method_sigmas(rows, inliers, v0, floor_rad, &mut stats, scratch);
    let (inv_ok, inv_mean) = hough_inverse_variances(rows, inliers, hough_var, &stats);
    let hough_ordinal = |i: usize| {
        rows[..i]
            .iter()
            .filter(|r| r.method == Method::Hough)
            .count()
    };
    let base = |i: usize| -> f64 {
        match slot(rows[i].method) {
            Some(k) if inliers[i] => {
                let s = &stats[k];
                let f = if k == 1 { edge_factor } else { 1.0 };
                let share = if k == 0 && inv_ok {
                    1.0 / hough_var[hough_ordinal(i)] / inv_mean
                } else {
                    rows[i].support as f64 / (s.support / s.count as f64)
                };
                f * share / (s.sigma * s.sigma)
            }
            _ => 0.0,
        }
    };
    let sigma = |i: usize| slot(rows[i].method).map_or(1.0, |k| stats[k].sigma.max(floor_rad));
    let v = irls(rows, inliers, None, v0, &base, &sigma)?;
    let mut sc = Scatter::new();
    for (i, r) in rows.iter().enumerate() {
        let b = base(i);
        let w = if b > 0.0 {
            let u = r.normal.dot(&v) / (CAUCHY * sigma(i));
            b / (1.0 + u * u)
        } else {
            0.0
        };
        weights.push(w);
        if w > 0.0 {
            sc.add(&r.normal, w);
        }
    }
    let Some(fit) = sc.fit() else {
        weights.clear();
        return None;
    };
    let direction = if v.dot(v0) < 0.0 { -v } else { v };
    // The residual in the same units as the vote's: the weighted RMS angle.
    let residual_rad = fit.mean_sq_residual.max(0.0).sqrt().asin();
    Some(PrecisionFit {
        direction,
        residual_rad,
        sigma_hough: stats[0].sigma,
        sigma_edge: stats[1].sigma,
        sigma_paired: stats[2].sigma,
    })
}

/// The centre line of two boundaries of one crop row: their bisecting plane, a row of its
/// own class ([`Method::Combined`]) with their summed support; `None` when they cancel.
fn centre_line(l: &Row, r: &Row) -> Option<Row> {
    let (nl, nr) = (l.normal, r.normal);
    let nr = if nl.dot(&nr) < 0.0 { -nr } else { nr };
    let c = nl + nr;
    let norm = c.norm();
    (norm > 1e-12).then(|| Row {
        normal: c / norm,
        method: Method::Combined,
        support: l.support.saturating_add(r.support),
        width_rad: 0.0,
    })
}

/// Pairs the edge method's two boundary lines of a crop row into one centre line, using the
/// Hough rows as the crop rows' centres ("edge rows only where they agree with Hough's
/// structure"). For each Hough inlier row, the edge inlier row of largest support on either side of it
/// (around the vanishing point `vp`), each within `max_half_rad` and within half the way to
/// the neighbouring Hough inlier row, form a pair; its centre line is the bisecting plane
/// (the normalised sum of the two normals, signs aligned), which still contains the
/// vanishing point, and whose error is the mean of the two boundaries' (the boundaries of
/// one row are biased in opposite directions by the plants' width and the smoothing, so the
/// mean cancels most of it). `out` receives every Hough row, then the centre lines (method
/// [`Method::Combined`], a class of their own in [`precision_fit`], with the pair's summed
/// support), then the unpaired edge rows; `out_inliers` flags them (centre lines as inliers,
/// the others as `inliers` did). Returns the number of pairs. Work buffers are the caller's (`psi`), so that a warmed-up caller allocates
/// nothing.
#[allow(clippy::too_many_arguments)]
pub fn pair_edge_rows(
    rows: &[Row],
    inliers: &[bool],
    vp: &Vector3<f64>,
    max_half_rad: f64,
    out: &mut Vec<Row>,
    out_inliers: &mut Vec<bool>,
    psi: &mut Vec<(f64, usize, Kind)>,
) -> usize {
    out.clear();
    out_inliers.clear();
    psi.clear();
    if rows.len() != inliers.len() {
        return 0;
    }
    let a = crate::sphere::any_perpendicular(vp);
    let b = vp.cross(&a);
    // Angle of a normal around the vanishing point, modulo π (the sign is free).
    let angle = |n: &Vector3<f64>| -> f64 {
        let t = n.dot(&b).atan2(n.dot(&a));
        t.rem_euclid(std::f64::consts::PI)
    };
    for (i, r) in rows.iter().enumerate() {
        let kind = match r.method {
            Method::Hough => Kind::Hough,
            Method::Edge => Kind::Edge,
            Method::Combined | Method::Pencil | Method::Strips | Method::Auto => continue,
        };
        if inliers[i] {
            psi.push((angle(&r.normal), i, kind));
        }
        if kind == Kind::Hough {
            out.push(*r);
            out_inliers.push(inliers[i]);
        }
    }
    let n = psi.len();
    let mut pairs = 0;
    for h in 0..n {
        let (ph, _, kind) = psi[h];
        if kind != Kind::Hough {
            continue;
        }
        // Half the way to the nearest other Hough inlier row, at most max_half_rad; on each
        // side the strongest boundary not yet paired.
        let hough = psi
            .iter()
            .filter(|&&(_, _, k)| k == Kind::Hough)
            .map(|&(p, _, _)| p);
        let limit = half_way_limit(ph, max_half_rad, hough);
        let edges = psi
            .iter()
            .enumerate()
            .filter(|&(_, &(_, _, k))| k == Kind::Edge)
            .map(|(j, &(p, i, _))| (p, rows[i].support, j));
        let [left, right] = strongest_either_side(ph, limit, edges);
        if let (Some((_, _, jl)), Some((_, _, jr))) = (left, right) {
            if let Some(centre) = centre_line(&rows[psi[jl].1], &rows[psi[jr].1]) {
                out.push(centre);
                out_inliers.push(true);
                psi[jl].2 = Kind::Paired;
                psi[jr].2 = Kind::Paired;
                pairs += 1;
            }
        }
    }
    // The unpaired edge rows keep their own class (and their inlier flags).
    for (i, r) in rows.iter().enumerate() {
        if r.method == Method::Edge && !psi.iter().any(|&(_, j, k)| j == i && k == Kind::Paired) {
            out.push(*r);
            out_inliers.push(inliers[i]);
        }
    }
    pairs
}

/// What [`pair_edge_rows`] made of a row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Hough,
    Edge,
    /// An edge boundary paired with the other boundary of its crop row.
    Paired,
}

/// How well both methods' rows agree with a candidate vanishing point `v` (see
/// [`consensus_score`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Consensus {
    /// Per method (Hough, edge): the share of the method's total support on rows within the
    /// tolerance of `v`, times (1 − 2^(1 − inlier rows)), so that one row alone counts
    /// nothing and two count half (as the vanishing stage's quality does).
    pub hough: f64,
    pub edge: f64,
    /// Inlier rows per method (Hough, edge).
    pub hough_rows: usize,
    pub edge_rows: usize,
}

impl Consensus {
    /// The score: the two methods' agreement, summed with equal weight. A vanishing point
    /// that both methods' rows support scores higher than one only its own method's rows
    /// support; the paper's w balances the methods' votes, but the support of one method's
    /// rows is not comparable with the other's (edge points against accumulator weight), so
    /// each method's agreement is measured as a share of its own rows.
    pub fn score(&self) -> f64 {
        self.hough + self.edge
    }
}

/// Scores candidate vanishing point `v` by how much of each method's rows (by support) pass
/// within `sin_tol` (the sine of the inlier tolerance) of the plane perpendicular to it.
pub fn consensus_score(rows: &[Row], v: &Vector3<f64>, sin_tol: f64) -> Consensus {
    let mut total = [0.0f64; 2];
    let mut inl = [0.0f64; 2];
    let mut count = [0usize; 2];
    for r in rows {
        let Some(k) = slot(r.method).filter(|&k| k < 2) else {
            continue;
        };
        total[k] += r.support as f64;
        if r.normal.dot(v).abs() < sin_tol {
            inl[k] += r.support as f64;
            count[k] += 1;
        }
    }
    let q = |k: usize| -> f64 {
        if total[k] <= 0.0 || count[k] == 0 {
            0.0
        } else {
            inl[k] / total[k] * (1.0 - 0.5f64.powi(count[k] as i32 - 1))
        }
    };
    Consensus {
        hough: q(0),
        edge: q(1),
        hough_rows: count[0],
        edge_rows: count[1],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`precision_fit`] with the edge factor of the detector and a fresh scratch buffer.
    fn pfit(
        rows: &[Row],
        inliers: &[bool],
        v0: &Vector3<f64>,
        floor_rad: f64,
        hough_var: &[f64],
        weights: &mut Vec<f64>,
    ) -> Option<PrecisionFit> {
        precision_fit(
            rows,
            inliers,
            v0,
            floor_rad,
            EDGE_PAIR_FACTOR,
            hough_var,
            weights,
            &mut Vec::new(),
        )
    }
    use crate::sphere::{any_perpendicular, axis_angle};

    /// Rows through `vp` at the given angles around it, each tilted off by `off` radians.
    fn rows(vp: &Vector3<f64>, method: Method, spec: &[(f64, f64, u32)]) -> Vec<Row> {
        let a = any_perpendicular(vp);
        let b = vp.cross(&a);
        spec.iter()
            .map(|&(ang, off, support)| {
                let n = a * ang.cos() + b * ang.sin();
                Row {
                    normal: (n + vp * off).normalize(),
                    method,
                    support,
                    width_rad: 0.0,
                }
            })
            .collect()
    }

    #[test]
    fn hough_rows_share_their_weight_by_their_refit_variance() {
        let vp = Vector3::new(0.1, 0.9, -0.2).normalize();
        // Four Hough rows; the last one is off by 1 mrad and its refit says it is imprecise.
        let all = rows(
            &vp,
            Method::Hough,
            &[
                (0.3, 0.0, 1000),
                (0.9, 0.0, 1000),
                (1.6, 0.0, 1000),
                (2.4, 1e-3, 1000),
            ],
        );
        let inl = vec![true; all.len()];
        let fit = |var: &[f64]| {
            let p = pfit(&all, &inl, &vp, 1e-6, var, &mut Vec::new()).unwrap();
            axis_angle(&p.direction, &vp)
        };
        let by_support = fit(&[]);
        let by_variance = fit(&[1e-10, 1e-10, 1e-10, 1e-6]);
        assert!(
            by_variance < 0.1 * by_support,
            "by variance {by_variance}, by support {by_support}"
        );
        // One Hough inlier without an estimate: support weighting, as without variances.
        assert_eq!(fit(&[1e-10, 1e-10, 1e-10, f64::NAN]), by_support);
    }

    #[test]
    fn precise_method_dominates_noisy_one() {
        let vp = Vector3::new(0.1, 0.9, -0.2).normalize();
        // Hough: four rows within ±0.05 mrad; edge: ten rows scattered ±1 mrad, and
        // biased, with twice the support each.
        let mut all = rows(
            &vp,
            Method::Hough,
            &[
                (0.3, 5e-5, 1000),
                (0.9, -5e-5, 900),
                (1.6, 4e-5, 1100),
                (2.4, -3e-5, 800),
            ],
        );
        let spec: Vec<(f64, f64, u32)> = (0..10)
            .map(|i| {
                let s = if i % 2 == 0 { 1.0 } else { -0.6 };
                (0.2 + 0.25 * i as f64, s * 1e-3, 2000)
            })
            .collect();
        all.extend(rows(&vp, Method::Edge, &spec));
        let inl = vec![true; all.len()];
        // The support-weighted fit is pulled off by the edge rows' bias.
        let mut plain = Scatter::new();
        for r in &all {
            plain.add(&r.normal, r.support as f64);
        }
        let e_plain = axis_angle(&plain.fit().unwrap().normal, &vp);
        let mut w = Vec::new();
        let p = pfit(&all, &inl, &vp, 1e-5, &[], &mut w).unwrap();
        let e = axis_angle(&p.direction, &vp);
        assert!(e < 6e-5, "precision fit error {e}");
        assert!(e_plain > 1.5e-4, "plain fit error {e_plain}");
        assert!(p.sigma_edge > 5.0 * p.sigma_hough, "{p:?}");
        assert_eq!(w.len(), all.len());
        assert!(p.direction.dot(&vp) > 0.0);
    }

    #[test]
    fn rejected_rows_and_single_methods() {
        let vp = Vector3::new(0.0, 1.0, -0.1).normalize();
        let mut all = rows(&vp, Method::Hough, &[(0.3, 0.0, 100), (1.2, 0.0, 100)]);
        all.extend(rows(
            &vp,
            Method::Edge,
            &[(0.5, 2e-4, 100), (1.0, -2e-4, 100), (2.0, 1e-4, 100)],
        ));
        // An outlier edge row far off the vanishing point, not an inlier: ignored.
        all.extend(rows(&vp, Method::Edge, &[(0.7, 0.2, 5000)]));
        let mut inl = vec![true; all.len()];
        inl[5] = false;
        let mut w = Vec::new();
        let p = pfit(&all, &inl, &vp, 1e-5, &[], &mut w).unwrap();
        assert_eq!(w[5], 0.0);
        assert!(axis_angle(&p.direction, &vp) < 2e-4, "{p:?}");
        // Two Hough rows only: their σ comes from the residual about the edge fit.
        assert!(p.sigma_hough < p.sigma_edge, "{p:?}");
        // One method alone: no refit.
        let hough_only = &all[..2];
        assert!(pfit(hough_only, &inl[..2], &vp, 1e-5, &[], &mut w).is_none());
        assert!(w.is_empty());
        // Mismatched lengths: no refit.
        assert!(pfit(&all, &inl[..3], &vp, 1e-5, &[], &mut w).is_none());
    }

    #[test]
    fn one_method_short_stray_rows_are_down_weighted() {
        let vp = Vector3::new(0.3, -0.8, -0.4).normalize();
        // Edge method alone: five long boundary rows within ±0.1 mrad and two short stray
        // sections 4 mrad off on the same side.
        let all = rows(
            &vp,
            Method::Edge,
            &[
                (0.2, 1e-4, 1000),
                (0.7, -1e-4, 1100),
                (1.3, 5e-5, 900),
                (1.9, -5e-5, 1000),
                (2.6, 0.0, 950),
                (0.5, 4e-3, 300),
                (2.2, 4e-3, 300),
            ],
        );
        let inl = vec![true; all.len()];
        let mut plain = Scatter::new();
        for r in &all {
            plain.add(&r.normal, r.support as f64);
        }
        let e_plain = axis_angle(&plain.fit().unwrap().normal, &vp);
        let mut w = Vec::new();
        let p = pfit(&all, &inl, &vp, 1e-5, &[], &mut w).unwrap();
        let e = axis_angle(&p.direction, &vp);
        assert!(e_plain > 5e-4, "plain {e_plain}");
        assert!(e < 1.5e-4, "robust {e} (plain {e_plain})");
        assert!(w[5] < 0.05 * w[0], "{w:?}");
        assert_eq!(p.sigma_hough, 0.0);
    }

    #[test]
    fn consensus_counts_each_method_as_a_share_of_its_own_rows() {
        let vp = Vector3::new(0.2, 0.95, -0.1).normalize();
        let other = Vector3::new(0.9, 0.3, 0.1).normalize();
        // Three Hough rows through vp (large support), one through `other`; four edge rows
        // through vp (small support), one through `other`.
        let mut all = rows(
            &vp,
            Method::Hough,
            &[(0.3, 0.0, 900), (1.1, 0.0, 800), (2.0, 0.0, 700)],
        );
        all.extend(rows(&other, Method::Hough, &[(0.5, 0.0, 1000)]));
        all.extend(rows(
            &vp,
            Method::Edge,
            &[
                (0.2, 0.0, 40),
                (0.9, 0.0, 50),
                (1.5, 0.0, 30),
                (2.5, 0.0, 40),
            ],
        ));
        all.extend(rows(&other, Method::Edge, &[(1.0, 0.0, 40)]));
        let tol = 1f64.to_radians().sin();
        let c = consensus_score(&all, &vp, tol);
        assert_eq!((c.hough_rows, c.edge_rows), (3, 4));
        assert!((c.hough - 2400.0 / 3400.0 * 0.75).abs() < 1e-9, "{c:?}");
        assert!((c.edge - 160.0 / 200.0 * 0.875).abs() < 1e-9, "{c:?}");
        // A direction only one row of each method passes through scores nothing.
        let d = consensus_score(&all, &other, tol);
        assert_eq!((d.hough_rows, d.edge_rows), (1, 1));
        assert_eq!(d.score(), 0.0);
        assert!(c.score() > d.score());
        assert_eq!(consensus_score(&[], &vp, tol), Consensus::default());
    }

    #[test]
    fn boundary_pairs_straddling_a_hough_row_become_its_centre_line() {
        let vp = Vector3::new(0.1, 0.9, -0.2).normalize();
        let mut all = rows(&vp, Method::Hough, &[(0.3, 0.0, 900), (1.0, 0.0, 800)]);
        // Row at 0.3: two long boundaries biased in opposite directions, and a short stray
        // section between them; row at 1.0: one boundary only.
        all.extend(rows(
            &vp,
            Method::Edge,
            &[
                (0.27, 2e-4, 400),
                (0.33, -2e-4, 380),
                (0.31, 3e-3, 20),
                (1.04, 1e-4, 300),
            ],
        ));
        // Far from both Hough rows: never paired.
        all.extend(rows(
            &vp,
            Method::Edge,
            &[(2.0, 0.0, 500), (2.05, 0.0, 500)],
        ));
        let inl = vec![true; all.len()];
        let (mut out, mut out_inl, mut psi) = (Vec::new(), Vec::new(), Vec::new());
        // The centre line and its class in the fit.
        assert_eq!(slot(Method::Combined), Some(2));
        let k = pair_edge_rows(
            &all,
            &inl,
            &vp,
            5f64.to_radians(),
            &mut out,
            &mut out_inl,
            &mut psi,
        );
        assert_eq!(k, 1);
        // Two Hough rows, one centre line, four unpaired edge rows.
        assert_eq!(out.len(), 7);
        assert_eq!(out_inl, vec![true; 7]);
        assert!(out[..2].iter().all(|r| r.method == Method::Hough));
        assert!(out[3..].iter().all(|r| r.method == Method::Edge));
        let c = out[2];
        assert_eq!((c.method, c.support), (Method::Combined, 780));
        // The opposite biases cancel (to the supports' imbalance, not weighted here).
        assert!(c.normal.dot(&vp).abs() < 1e-5, "{}", c.normal.dot(&vp));
        // Rejected rows take no part; mismatched lengths give nothing.
        let mut inl2 = inl.clone();
        inl2[4] = false;
        assert_eq!(
            pair_edge_rows(&all, &inl2, &vp, 0.1, &mut out, &mut out_inl, &mut psi),
            1
        );
        assert_eq!(out.len(), 7);
        assert!(!out_inl[3]);
        assert_eq!(out[2].support, 780);
        // Without its left boundary, the row has no pair.
        inl2[2] = false;
        assert_eq!(
            pair_edge_rows(&all, &inl2, &vp, 0.1, &mut out, &mut out_inl, &mut psi),
            0
        );
        assert_eq!(
            pair_edge_rows(&all, &inl[..3], &vp, 0.1, &mut out, &mut out_inl, &mut psi),
            0
        );
        assert!(out.is_empty());
    }
}
