//! The strips method for a forward-looking perspective camera: rows as vegetation peaks
//! in horizontal strips of the image, lined up through a searched vanishing point
//! ([`crate::detect::strips`]), then polished on the image's pixels ([`Polish`]).
//!
//! Owns [`StripsMethod`]: the search and its rows; after the vote, the polish, and where the
//! vote finds no vanishing point among the rows (one or two rows), the search's own, which
//! the rows meet in by construction.

use super::{Frame, RowMethod};
use crate::camera::Mounting;
use crate::detect::polish::Polish;
use crate::detect::strips::{
    StripsOptions, StripsResult, StripsRows, REFERENCE_POLISH_MAX_BAND_DEG,
};
use crate::detect::types::DetectError;
use crate::detect::vanishing::support_weights;
use nalgebra::Vector3;

/// The strips method.
#[derive(Debug, Clone)]
pub struct StripsMethod {
    strips: StripsRows,
    polish: Polish,
    /// The polish's widest band around a row (radians).
    max_band_rad: f64,
    /// The search's vanishing point in the last frame.
    found: Option<Vector3<f64>>,
}

impl StripsMethod {
    /// The method with the `[detector.strips]` options for a camera mounted as
    /// `mounting`, the vanishing point searched within `max_tilt_deg` of the robot's
    /// horizontal plane, its angular scales at `angle_factor` times their reference values.
    pub fn new(
        opts: StripsOptions,
        max_tilt_deg: f64,
        mounting: &Mounting,
        angle_factor: f64,
    ) -> Result<Self, DetectError> {
        Ok(StripsMethod {
            strips: StripsRows::new(opts, max_tilt_deg, mounting)?,
            polish: Polish::default(),
            max_band_rad: (REFERENCE_POLISH_MAX_BAND_DEG * angle_factor).to_radians(),
            found: None,
        })
    }

    /// What the search found in the last frame.
    pub fn last(&self) -> StripsResult {
        self.strips.last()
    }

    /// The search's agreement at the summit nearest a vanishing direction in the last
    /// frame, and that summit's distance from its answer ([`StripsRows::agreement_near`]).
    pub fn agreement_near(&mut self, dir: &Vector3<f64>) -> Option<(f64, f64)> {
        self.strips.agreement_near(dir)
    }
}

impl RowMethod for StripsMethod {
    fn rows(&mut self, frame: &mut Frame<'_>) -> Result<(), DetectError> {
        self.strips
            .set_window(frame.window.as_ref().map(|(v, w)| (v, *w)));
        self.found = self
            .strips
            .find_on(frame.points, &mut frame.out.rows, frame.pool)?;
        support_weights(&frame.out.rows, frame.weights);
        Ok(())
    }

    fn finish(&mut self, frame: &mut Frame<'_>) -> Result<(), DetectError> {
        let out = &mut *frame.out;
        self.polish
            .run(frame.prep, frame.vanish, out, self.max_band_rad)?;
        if let (None, Some(v), false) = (out.vanishing_point, self.found, out.rows.is_empty()) {
            let n = out.rows.len();
            out.set_vanishing_point(v, n, 0.0);
            out.quality = self.strips.last().comb_strength.clamp(0.0, 1.0);
        }
        Ok(())
    }
}
