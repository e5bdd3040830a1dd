//! The pencil method for a narrow camera looking down: rows as the peaks of the
//! vegetation's profile across the pencil of great circles through the vanishing point that
//! makes them sharpest, on their evenly spaced comb ([`crate::detect::pencil`]).
//!
//! Owns [`PencilMethod`]: the search and its rows. The vote for the vanishing point is the
//! detector's, on those rows; the method has no finishing step (a polish of the rows on the
//! image's pixels, as the strips method's, dragged rows cut by the image's edge onto wrong
//! lines: docs/detector.md). The pencil searches the whole field of view on every frame: it
//! does not narrow to the tracker's window.

use super::{Frame, RowMethod};
use crate::camera::Mounting;
use crate::detect::pencil::{PencilOptions, PencilRows};
use crate::detect::types::DetectError;
use crate::detect::vanishing::support_weights;

/// The pencil method.
#[derive(Debug, Clone)]
pub struct PencilMethod {
    pencil: PencilRows,
}

impl PencilMethod {
    /// The method with the `[detector.pencil]` options for a camera mounted as `mounting`,
    /// the vanishing point searched within `max_tilt_deg` of the robot's horizontal plane.
    pub fn new(
        opts: PencilOptions,
        max_tilt_deg: f64,
        mounting: &Mounting,
    ) -> Result<Self, DetectError> {
        Ok(PencilMethod {
            pencil: PencilRows::new(opts, max_tilt_deg, mounting)?,
        })
    }
}

impl RowMethod for PencilMethod {
    fn narrows(&self) -> bool {
        false
    }

    fn rows(&mut self, frame: &mut Frame<'_>) -> Result<(), DetectError> {
        self.pencil.find(frame.points, &mut frame.out.rows)?;
        support_weights(&frame.out.rows, frame.weights);
        Ok(())
    }

    fn finish(&mut self, _frame: &mut Frame<'_>) -> Result<(), DetectError> {
        Ok(())
    }
}
