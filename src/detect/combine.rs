//! The combined method's final vanishing-point fit: rows weighted by their method's precision.
//!
//! Owns the step after the paper's eq. 5 vote (II-F). The vote, with edge rows weighted
//! w·support and Hough rows (1−w)·support, picks the vanishing point and its inlier rows
//! robustly; but the two methods' rows are not equally precise (the edge method's boundary
//! lines scatter several times more about the vanishing point than the Hough centre lines on
//! nearly solid rows, and less on sparse ones), so a final fit with the vote's weights lets
//! the noisier method pull the answer away from the better one. Here each method's scatter
//! is measured on the image itself: the inlier rows of one method alone are fitted to a
//! common direction and their mean squared residual, corrected for the two degrees of freedom
//! the fit absorbs, is that method's variance σ²ₘ (with fewer than three inlier rows, the
//! residual about the other method's fit is used instead). The final fit weights row i of
//! method m by (supportᵢ / mean supportₘ) / σ²ₘ: inverse-variance weighting between methods,
//! support weighting within one. Rows the vote rejected stay rejected.

use super::{Method, Row};
use crate::sphere::Scatter;
use nalgebra::Vector3;

/// The outcome of [`precision_fit`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrecisionFit {
    /// The refitted direction (the sign of the vote's direction).
    pub direction: Vector3<f64>,
    /// Weighted RMS angular residual (radians) of the inlier rows.
    pub residual_rad: f64,
    /// The per-method RMS scatter (radians) used: Hough, edge.
    pub sigma_hough: f64,
    pub sigma_edge: f64,
}

/// Per-method sums for the fit.
#[derive(Debug, Clone, Copy, Default)]
struct MethodFit {
    scatter: Scatter,
    support: f64,
    count: usize,
}

/// Refits the vanishing point `v0` over the inlier rows (`inliers[i]`), weighting each method
/// by its measured precision (see the module documentation). `floor_rad` bounds each
/// method's σ from below so that a few rows agreeing by chance cannot take all the weight.
/// `weights` receives the final weight of every row (0 for rejected ones). Returns `None`
/// (and leaves `weights` empty) when the rows do not hold two methods with at least two
/// inliers each: then the vote's own fit stands.
pub fn precision_fit(
    rows: &[Row],
    inliers: &[bool],
    v0: &Vector3<f64>,
    floor_rad: f64,
    weights: &mut Vec<f64>,
) -> Option<PrecisionFit> {
    weights.clear();
    if rows.len() != inliers.len() {
        return None;
    }
    let slot = |m: Method| match m {
        Method::Hough => Some(0usize),
        Method::Edge => Some(1),
        Method::Combined => None,
    };
    let mut fits = [MethodFit::default(); 2];
    for (r, _) in rows.iter().zip(inliers).filter(|(_, &ok)| ok) {
        let Some(k) = slot(r.method) else { continue };
        let f = &mut fits[k];
        f.scatter.add(&r.normal, r.support as f64);
        f.support += r.support as f64;
        f.count += 1;
    }
    if fits.iter().any(|f| f.count < 2) {
        return None;
    }
    // Each method's own direction (for three or more rows) and its variance.
    let own: [Option<Vector3<f64>>; 2] = [0, 1].map(|k| {
        if fits[k].count >= 3 {
            fits[k].scatter.fit().map(|f| f.normal)
        } else {
            None
        }
    });
    let mut var = [0.0f64; 2];
    for k in 0..2 {
        let (reference, dof) = match (own[k], own[1 - k]) {
            (Some(v), _) => (v, fits[k].count as f64 - 2.0),
            (None, Some(v)) => (v, fits[k].count as f64),
            (None, None) => (*v0, fits[k].count as f64),
        };
        let mut sum = 0.0;
        for (r, _) in rows.iter().zip(inliers).filter(|(_, &ok)| ok) {
            if slot(r.method) == Some(k) {
                sum += r.support as f64 * r.normal.dot(&reference).powi(2);
            }
        }
        let mean_sq = sum / fits[k].support;
        var[k] = (mean_sq * fits[k].count as f64 / dof.max(1.0)).max(floor_rad * floor_rad);
    }
    let mut sc = Scatter::new();
    for (r, &ok) in rows.iter().zip(inliers) {
        let w = match slot(r.method) {
            Some(k) if ok => {
                let mean_support = fits[k].support / fits[k].count as f64;
                r.support as f64 / mean_support / var[k]
            }
            _ => 0.0,
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
    let mut direction = fit.normal;
    if direction.dot(v0) < 0.0 {
        direction = -direction;
    }
    // The residual in the same units as the vote's: the weighted RMS angle.
    let residual_rad = fit.mean_sq_residual.max(0.0).sqrt().asin();
    Some(PrecisionFit {
        direction,
        residual_rad,
        sigma_hough: var[0].sqrt(),
        sigma_edge: var[1].sqrt(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
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
                }
            })
            .collect()
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
        let p = precision_fit(&all, &inl, &vp, 1e-5, &mut w).unwrap();
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
        let p = precision_fit(&all, &inl, &vp, 1e-5, &mut w).unwrap();
        assert_eq!(w[5], 0.0);
        assert!(axis_angle(&p.direction, &vp) < 2e-4, "{p:?}");
        // Two Hough rows only: their σ comes from the residual about the edge fit.
        assert!(p.sigma_hough < p.sigma_edge, "{p:?}");
        // One method alone: no refit.
        let hough_only = &all[..2];
        assert!(precision_fit(hough_only, &inl[..2], &vp, 1e-5, &mut w).is_none());
        assert!(w.is_empty());
        // Mismatched lengths: no refit.
        assert!(precision_fit(&all, &inl[..3], &vp, 1e-5, &mut w).is_none());
    }
}
