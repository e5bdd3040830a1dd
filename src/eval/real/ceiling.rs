//! What an image's rows could at best score: each labelled row's best great circle, free or
//! through a given vanishing point, scored as the published rows are.
//!
//! Owns the three ceilings `omnirow eval real` reports beside the detector's figures: the
//! labelled rows found when every one of them is published as the great circle that fits its
//! own centre line best (the metric's limit for straight rows), as the best one through the
//! detector's vanishing point (what the detector's point allows its rows), and as the best
//! one through the labels' own vanishing direction (what a right point would allow). The gap
//! between the last two is what the vanishing point's error costs; the gap between the
//! detector's recall and the second is what its rows lose on their own. Every fit is on the
//! unit sphere through the calibration, so the ceilings hold for any lens.

use super::labels::ScanCurve;
use super::score::{ImageScore, ProjectedRow, ScoreOptions};
use crate::camera::Calibration;
use crate::sphere::{any_perpendicular, fit_normal};
use nalgebra::{Matrix2, Matrix3, SymmetricEigen, Vector3};
use serde::Serialize;

/// The labelled rows of one image found by each ceiling's rows (`None` where that ceiling's
/// vanishing point does not exist).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct Ceiling {
    /// Each labelled row's own best great circle.
    pub free: usize,
    /// Each row's best great circle through the detector's vanishing point.
    pub detected_vp: Option<usize>,
    /// Each row's best great circle through the labels' vanishing direction
    /// ([`labels_direction`]).
    pub labels_vp: Option<usize>,
}

impl Ceiling {
    /// The ceilings of `labels` (an image `cal` describes), with the detector's vanishing
    /// direction `detected` (either sign).
    pub fn compute(
        cal: &Calibration,
        labels: &[ScanCurve],
        detected: Option<&Vector3<f64>>,
        opts: &ScoreOptions,
    ) -> Self {
        let rays: Vec<Vec<Vector3<f64>>> = labels.iter().map(|l| label_rays(cal, l)).collect();
        let found = |through: Option<&Vector3<f64>>| {
            let rows: Vec<ProjectedRow> = rays
                .iter()
                .filter_map(|r| best_circle(r, through))
                .map(|n| ProjectedRow::project(cal, &n))
                .collect();
            ImageScore::compute(labels, &rows, opts).matched
        };
        let own = labels_direction(labels, &rays, opts);
        Ceiling {
            free: found(None),
            detected_vp: detected.map(|v| found(Some(v))),
            labels_vp: own.map(|v| found(Some(&v))),
        }
    }
}

/// The rays of a labelled row's points through the calibration.
pub fn label_rays(cal: &Calibration, l: &ScanCurve) -> Vec<Vector3<f64>> {
    l.points().map(|[r, c]| cal.model.cam2world(r, c)).collect()
}

/// The unit normal of the great circle nearest `rays` in the least-squares sense (the
/// smallest eigenvector of Σ r rᵀ), constrained through `through` when given; `None` with
/// fewer than two rays or a degenerate fit.
pub fn best_circle(rays: &[Vector3<f64>], through: Option<&Vector3<f64>>) -> Option<Vector3<f64>> {
    if rays.len() < 2 {
        return None;
    }
    let n = match through {
        None => return fit_normal(rays, None).map(|f| f.normal),
        Some(v) => {
            // the normal lies in the plane perpendicular to v: a 2 × 2 problem there
            let v = v.try_normalize(0.0)?;
            let a = any_perpendicular(&v);
            let b = v.cross(&a);
            let mut s = Matrix2::zeros();
            for r in rays {
                let q = nalgebra::Vector2::new(r.dot(&a), r.dot(&b));
                s += q * q.transpose();
            }
            let e = SymmetricEigen::new(s);
            let i = e.eigenvalues.imin();
            let (x, y) = (e.eigenvectors[(0, i)], e.eigenvectors[(1, i)]);
            a * x + b * y
        }
    };
    n.try_normalize(1e-12)
}

/// The labels' vanishing direction: the least-squares intersection of the great circles
/// fitted to the labelled rows spanning at least `straight_min_rows` scan lines (the
/// smallest eigenvector of Σ n nᵀ); `None` with fewer than two such rows or rows closer to
/// parallel than `vp_min_angle_deg`. `rays` are the labels' [`label_rays`].
pub fn labels_direction(
    labels: &[ScanCurve],
    rays: &[Vec<Vector3<f64>>],
    opts: &ScoreOptions,
) -> Option<Vector3<f64>> {
    let normals: Vec<Vector3<f64>> = labels
        .iter()
        .zip(rays)
        .filter(|(l, _)| l.cols.len() >= opts.straight_min_rows)
        .filter_map(|(_, r)| best_circle(r, None))
        .collect();
    if normals.len() < 2 {
        return None;
    }
    let s: Matrix3<f64> = normals.iter().map(|n| n * n.transpose()).sum();
    let e = SymmetricEigen::new(s / normals.len() as f64);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&x, &y| e.eigenvalues[x].total_cmp(&e.eigenvalues[y]));
    // the normals must spread: for two rows, the middle eigenvalue is (1 − cos angle) / 2
    if e.eigenvalues[order[1]] < (1.0 - opts.vp_min_angle_deg.to_radians().cos()) / 2.0 {
        return None;
    }
    e.eigenvectors
        .column(order[0])
        .into_owned()
        .try_normalize(1e-12)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn pinhole() -> Calibration {
        let toml = "[pinhole]\nwidth = 400\nheight = 300\nfx = 300.0\nfy = 300.0\n\
                    cx = 199.5\ncy = 149.5\n\n[mounting]\npitch_deg = -60.0\n";
        Calibration::parse_toml(toml, Path::new("p.toml")).unwrap()
    }

    /// Three straight rows through (row −40, col 200), 120 px apart at the last scan line,
    /// from scan line 30 down; the middle one bent by `bend` px at its ends (a parabola).
    fn fan(bend: f64) -> Vec<ScanCurve> {
        [-120.0, 0.0, 120.0]
            .into_iter()
            .map(|dx| ScanCurve {
                first_row: 30,
                cols: (30..300)
                    .map(|r| {
                        let t = (r as f64 - 165.0) / 135.0;
                        let b = if dx == 0.0 { bend * t * t } else { 0.0 };
                        200.0 + dx * (r as f64 + 40.0) / 339.0 + b
                    })
                    .collect(),
            })
            .collect()
    }

    #[test]
    fn a_circle_through_its_own_rays_and_through_a_point_on_it() {
        let n = Vector3::new(0.3, -0.2, 0.9).normalize();
        let a = any_perpendicular(&n);
        let b = n.cross(&a);
        let rays: Vec<_> = (0..20)
            .map(|k| a * (k as f64 * 0.1).cos() + b * (k as f64 * 0.1).sin())
            .collect();
        let free = best_circle(&rays, None).unwrap();
        assert!(free.dot(&n).abs() > 1.0 - 1e-12, "{free}");
        let on = a * 0.3f64.cos() - b * 0.3f64.sin();
        let through = best_circle(&rays, Some(&on)).unwrap();
        assert!(through.dot(&n).abs() > 1.0 - 1e-12, "{through}");
        // through a point off the circle the fit must pass through that point
        let off = (on + n * 0.2).normalize();
        let tilted = best_circle(&rays, Some(&off)).unwrap();
        assert!(tilted.dot(&off).abs() < 1e-12);
        assert!(tilted.dot(&n).abs() < 1.0 - 1e-4);
        assert_eq!(best_circle(&rays[..1], None), None);
    }

    #[test]
    fn straight_rows_reach_every_ceiling_and_a_wrong_point_loses_them() {
        let cal = pinhole();
        let labels = fan(0.0);
        let rays: Vec<_> = labels.iter().map(|l| label_rays(&cal, l)).collect();
        let opts = ScoreOptions::default();
        let own = labels_direction(&labels, &rays, &opts).unwrap();
        let truth = cal.model.cam2world(-40.0, 200.0);
        assert!(own.dot(&truth).abs() > 1.0 - 1e-9, "{own} against {truth}");
        let c = Ceiling::compute(&cal, &labels, Some(&truth), &opts);
        assert_eq!(
            c,
            Ceiling {
                free: 3,
                detected_vp: Some(3),
                labels_vp: Some(3)
            }
        );
        // a point 30 px to the side: the outer rows' best circles through it stray
        let wrong = cal.model.cam2world(-40.0, 230.0);
        let c = Ceiling::compute(&cal, &labels, Some(&wrong), &opts);
        assert_eq!((c.free, c.labels_vp), (3, Some(3)));
        assert!(c.detected_vp.unwrap() < 3, "{c:?}");
        let c = Ceiling::compute(&cal, &labels, None, &opts);
        assert_eq!(c.detected_vp, None);
    }

    #[test]
    fn a_strongly_bent_row_is_beyond_a_straight_circle() {
        let cal = pinhole();
        let opts = ScoreOptions::default();
        // 40 px of bend against a spacing of at most 120 px: no straight line holds it
        let c = Ceiling::compute(&cal, &fan(40.0), None, &opts);
        assert_eq!(c.free, 2, "{c:?}");
        // one labelled row: no spacing, nothing found, no labels' direction
        let one = &fan(0.0)[..1];
        let c = Ceiling::compute(&cal, one, None, &opts);
        assert_eq!((c.free, c.labels_vp), (0, None));
    }
}
