//! The Hough method (paper II-D): rows as the peaks of a spherical Hough transform over the
//! great circles through the kept points.
//!
//! Owns [`HoughMethod`]: the transform's rows ([`super::super::hough`]), refitted on the
//! image's pixels in wedges towards a first vanishing point of theirs; after the vote, the
//! vanishing point refitted with each row weighted by its estimated precision, and the
//! curved rows turned to where they pass the robot.

use super::{Frame, RowMethod};
use crate::detect::hough::{HoughOptions, HoughParams, HoughResult, HoughRows};
use crate::detect::refit::turn_to_feet;
use crate::detect::types::{DetectError, Detection, Method};
use std::any::Any;

/// The Hough method.
#[derive(Debug, Clone)]
pub struct HoughMethod {
    transform: HoughRows,
    last: HoughResult,
}

impl HoughMethod {
    /// The method with the `[detector.hough]` options, its angular scales at
    /// `angle_factor` times their reference values.
    pub fn new(opts: &HoughOptions, angle_factor: f64) -> Result<Self, DetectError> {
        Ok(HoughMethod {
            transform: HoughRows::new(HoughParams::new(opts, angle_factor))?,
            last: HoughResult::default(),
        })
    }

    /// What the transform did in the last image.
    pub fn last(&self) -> HoughResult {
        self.last
    }
}

/// The Hough transform's rows of the frame into `out.rows`, refitted on the image's pixels
/// in wedges towards the vanishing point of the rows as found (the stage the Hough and the
/// combined methods share).
pub fn hough_rows(
    transform: &mut HoughRows,
    frame: &mut Frame<'_>,
    out: &mut Detection,
) -> Result<HoughResult, DetectError> {
    transform.set_window(frame.window.as_ref().map(|(v, w)| (v, *w)));
    let p = frame.points;
    let found = transform.find_rows(&p.rays, &p.weights, &mut out.rows)?;
    // A first vanishing point from the rows shapes the refit's bands.
    frame.vanish.run(None, out)?;
    let vp = out.vanishing_point.map(|v| v.direction);
    frame
        .prep
        .refit(&mut out.rows, transform.bands(), vp.as_ref())?;
    Ok(found)
}

impl RowMethod for HoughMethod {
    fn method(&self) -> Method {
        Method::Hough
    }

    fn rows(
        &mut self,
        frame: &mut Frame<'_>,
        out: &mut Detection,
        weights: &mut Vec<f64>,
    ) -> Result<(), DetectError> {
        self.last = hough_rows(&mut self.transform, frame, out)?;
        weights.clear();
        weights.extend(out.rows.iter().map(|r| r.support as f64));
        Ok(())
    }

    fn finish(
        &mut self,
        frame: &mut Frame<'_>,
        out: &mut Detection,
        _weights: &[f64],
    ) -> Result<(), DetectError> {
        frame
            .vanish
            .refit_by_variances(out, frame.prep.row_variances());
        turn_to_feet(out, frame.prep.near_feet());
        Ok(())
    }

    fn as_any(&self) -> &dyn Any {
        self
    }

    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}
