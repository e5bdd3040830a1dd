//! The combined method (paper II-F): the Hough method's rows and the edge method's
//! boundaries voting together for the vanishing point, the choice for omnidirectional
//! lenses.
//!
//! Owns [`CombinedMethod`]: the Hough rows ([`hough_rows`]) and the boundaries
//! ([`Boundaries`]), found at once on two threads when the detector has them ([`join`]),
//! weighted as the paper's eq. 5 (edge rows w·support, Hough rows
//! (1 − w)·support) in one vote; after it, a consensus among three candidates (the vote's
//! vanishing point and those of each method's rows alone), the vanishing point refitted
//! with each method weighted by its measured precision and the boundaries either side of a
//! Hough row paired into its centre line ([`PrecisionRefit`]), the curved rows turned to
//! where they pass the robot, and the Hough rows published as the crop rows' centre lines
//! with their widths from the boundaries ([`CentreLines`]).

use super::{hough_rows, join, Frame, RowMethod};
use crate::detect::boundaries::Boundaries;
use crate::detect::centre::CentreLines;
use crate::detect::combine::{consensus_score, PrecisionRefit, REFERENCE_PAIR_MAX_DEG};
use crate::detect::edge::EdgeOptions;
use crate::detect::hough::{HoughOptions, HoughParams, HoughRows};
use crate::detect::refit::turn_to_feet;
use crate::detect::types::{DetectError, Detection, Method};
use crate::detect::vanishing::REFINE_ITERATIONS;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// `[detector.combined]`: the combined method's option.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CombinedOptions {
    /// The paper's w (eq. 5): edge rows vote for the vanishing point with w·support, Hough
    /// rows with (1 − w)·support; within (0, 1). Lower it where the plants' outlines are
    /// ragged (large leafy plants), raise it for thin, sharp rows.
    pub edge_weight: f64,
}

impl Default for CombinedOptions {
    fn default() -> Self {
        CombinedOptions { edge_weight: 0.7 }
    }
}

impl CombinedOptions {
    pub fn validate(&self) -> Result<(), DetectError> {
        let w = self.edge_weight;
        if w > 0.0 && w < 1.0 {
            Ok(())
        } else {
            Err(DetectError::Options(format!(
                "combined.edge_weight = {w} must be within (0, 1)"
            )))
        }
    }
}

/// The combined method.
#[derive(Debug, Clone)]
pub struct CombinedMethod {
    edge_weight: f64,
    transform: HoughRows,
    boundaries: Boundaries,
    /// The rows agreeing with the final vanishing point.
    inliers: Vec<bool>,
    /// The consensus step's per-method weights and inlier flags.
    candidate_weights: Vec<f64>,
    candidate_inliers: Vec<bool>,
    refit: PrecisionRefit,
    centre: CentreLines,
    /// The widest half-width of a crop row (radians).
    pair_max_rad: f64,
}

impl CombinedMethod {
    /// The method with the `[detector.combined]`, `[detector.hough]` and
    /// `[detector.edge]` options, its angular scales at `angle_factor` times their reference
    /// values.
    pub fn new(
        opts: &CombinedOptions,
        hough: &HoughOptions,
        edge: &EdgeOptions,
        angle_factor: f64,
    ) -> Result<Self, DetectError> {
        opts.validate()?;
        Ok(CombinedMethod {
            edge_weight: opts.edge_weight,
            transform: HoughRows::new(HoughParams::new(hough, angle_factor))?,
            boundaries: Boundaries::new(edge, angle_factor)?,
            inliers: Vec::with_capacity(128),
            candidate_weights: Vec::with_capacity(128),
            candidate_inliers: Vec::with_capacity(128),
            refit: PrecisionRefit::default(),
            centre: CentreLines::default(),
            pair_max_rad: (REFERENCE_PAIR_MAX_DEG * angle_factor).to_radians(),
        })
    }

    /// The consensus step: the vote's vanishing point against those of the Hough rows alone
    /// and of the edge rows alone, scored by how much of each method's rows agree with
    /// each ([`consensus_score`]). The vote is dominated by whichever method's support is
    /// larger (Hough accumulator weight outnumbers edge points), so on a noisy image where
    /// the Hough rows are few and bent, many boundaries agreeing with some Hough rows would
    /// otherwise be outvoted. Another candidate replaces the vote's only when it scores
    /// higher and passes through at least two Hough rows and three rows in all; then the
    /// rows of either method within the inlier tolerance of it become the inliers (iterated
    /// with the vote's weights, as the vanishing stage does) and `out` takes its vanishing
    /// point. `self.inliers` holds the inliers either way.
    fn consensus(&mut self, frame: &mut Frame<'_>, sin_tol: f64) -> Result<(), DetectError> {
        let (out, weights) = (&mut *frame.out, &*frame.weights);
        let Some(vote) = out.vanishing_point else {
            return Ok(());
        };
        let mut best = consensus_score(&out.rows, &vote.direction, sin_tol).score();
        let mut chosen: Option<Vector3<f64>> = None;
        for only in [Method::Hough, Method::Edge] {
            self.candidate_weights.clear();
            for (r, &w) in out.rows.iter().zip(weights) {
                self.candidate_weights
                    .push(if r.method == only { w } else { 0.0 });
            }
            let r = frame.vanish.finder_mut().find(
                &out.rows,
                &self.candidate_weights,
                &mut self.candidate_inliers,
            )?;
            let Some(vp) = r.vanishing_point else {
                continue;
            };
            let c = consensus_score(&out.rows, &vp.direction, sin_tol);
            if c.hough_rows >= 2 && c.hough_rows + c.edge_rows >= 3 && c.score() > best {
                best = c.score();
                chosen = Some(vp.direction);
            }
        }
        if let Some(v) = chosen {
            self.refit_inliers(out, weights, v, sin_tol);
        }
        Ok(())
    }

    /// The vanishing point `v` refitted over the rows within the inlier tolerance of it,
    /// iterated as the vanishing stage does, into `out` and `self.inliers`.
    fn refit_inliers(
        &mut self,
        out: &mut Detection,
        weights: &[f64],
        mut v: Vector3<f64>,
        sin_tol: f64,
    ) {
        let mut residual = 0.0;
        let mut count = 0;
        for _ in 0..REFINE_ITERATIONS {
            let mut sc = crate::sphere::Scatter::new();
            for (i, r) in out.rows.iter().enumerate() {
                let ok = r.normal.dot(&v).abs() < sin_tol && weights[i] > 0.0;
                self.inliers[i] = ok;
                if ok {
                    sc.add(&r.normal, weights[i]);
                }
            }
            count = sc.count();
            let Some(fit) = sc.fit() else { break };
            let n = if fit.normal.dot(&v) < 0.0 {
                -fit.normal
            } else {
                fit.normal
            };
            let moved = crate::sphere::axis_angle(&n, &v);
            v = n;
            residual = fit.mean_sq_residual.max(0.0).sqrt().asin();
            if moved < 1e-12 {
                break;
            }
        }
        for (i, r) in out.rows.iter().enumerate() {
            self.inliers[i] = r.normal.dot(&v).abs() < sin_tol && weights[i] > 0.0;
        }
        out.set_vanishing_point(v, count, residual);
    }
}

impl RowMethod for CombinedMethod {
    fn rows(&mut self, frame: &mut Frame<'_>) -> Result<(), DetectError> {
        // The Hough rows with their refit, and the edge detector's boundaries, at once:
        // they read the same prepared image and write nothing the other reads.
        let (rebuilt, fresh) = (frame.prepared.setup_rebuilt, frame.fresh);
        let (image, refitter) = frame.prep.split().unzip();
        let (transform, boundaries) = (&mut self.transform, &mut self.boundaries);
        let (points, window, vanish) = (frame.points, frame.window, &mut *frame.vanish);
        let out = &mut *frame.out;
        let (hough, edge) = join(
            frame.pool,
            || hough_rows(transform, points, window, vanish, refitter, out),
            || match (image, fresh) {
                (Some(image), true) => boundaries.run(&image, rebuilt),
                (None, true) => Err(DetectError::Buffer(
                    "edge method: the preparer has no setup".into(),
                )),
                (_, false) => Ok(()),
            },
        );
        hough?;
        edge?;
        let w = self.edge_weight;
        let (hough_w, edge_w) = (1.0 - w, w);
        let (out, weights) = (&mut *frame.out, &mut *frame.weights);
        weights.clear();
        for r in out.rows.iter() {
            weights.push(hough_w * r.support as f64);
        }
        for r in &self.boundaries.rows {
            weights.push(edge_w * r.support as f64);
            out.rows.push(*r);
        }
        Ok(())
    }

    fn finish(&mut self, frame: &mut Frame<'_>) -> Result<(), DetectError> {
        let sin_tol = frame.vanish.params().inlier_deg.to_radians().sin();
        self.inliers.clear();
        self.inliers.extend_from_slice(frame.vanish.inliers());
        self.consensus(frame, sin_tol)?;
        let out = &mut *frame.out;
        self.refit.run(
            out,
            &self.inliers,
            Some(self.pair_max_rad),
            frame.prep.row_variances(),
        );
        turn_to_feet(out, frame.prep.near_feet());
        // Only the boundaries through the vanishing point are this field's; the edge
        // method's boundaries of sparse rows are mostly stray plant outlines.
        let v = out.vanishing_point.map(|v| v.direction);
        out.rows.retain(|r| {
            r.method != Method::Edge || v.is_some_and(|v| r.normal.dot(&v).abs() < sin_tol)
        });
        let p = frame.points;
        self.centre
            .publish_detection(out, sin_tol, self.pair_max_rad, &p.rays, &p.weights);
        Ok(())
    }
}
