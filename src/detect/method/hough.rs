//! The Hough method (paper II-D): rows as the peaks of a spherical Hough transform over the
//! great circles through the kept points.
//!
//! Owns [`HoughMethod`]: the transform's rows ([`super::super::hough`]), refitted on the
//! image's pixels in wedges towards a first vanishing point of theirs; after the vote, the
//! vanishing point refitted with each row weighted by its estimated precision, and the
//! curved rows turned to where they pass the robot.

use super::{hough_rows, Frame, RowMethod};
use crate::detect::hough::{HoughOptions, HoughParams, HoughRows};
use crate::detect::refit::turn_to_feet;
use crate::detect::types::DetectError;
use crate::detect::vanishing::support_weights;

/// The Hough method.
#[derive(Debug, Clone)]
pub struct HoughMethod {
    transform: HoughRows,
}

impl HoughMethod {
    /// The method with the `[detector.hough]` options, its angular scales at
    /// `angle_factor` times their reference values.
    pub fn new(opts: &HoughOptions, angle_factor: f64) -> Result<Self, DetectError> {
        Ok(HoughMethod {
            transform: HoughRows::new(HoughParams::new(opts, angle_factor))?,
        })
    }
}

impl RowMethod for HoughMethod {
    fn rows(&mut self, frame: &mut Frame<'_>) -> Result<(), DetectError> {
        let refitter = frame.prep.split().map(|(_, r)| r);
        hough_rows(
            &mut self.transform,
            frame.points,
            frame.window,
            frame.vanish,
            refitter,
            frame.out,
        )?;
        support_weights(&frame.out.rows, frame.weights);
        Ok(())
    }

    fn finish(&mut self, frame: &mut Frame<'_>) -> Result<(), DetectError> {
        frame
            .vanish
            .refit_by_variances(frame.out, frame.prep.row_variances());
        turn_to_feet(frame.out, frame.prep.near_feet());
        Ok(())
    }
}
