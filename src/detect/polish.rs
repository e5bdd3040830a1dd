//! The polish: rows placed on a coarse grid refitted on the image's pixels near each, and
//! their vanishing point found again and refitted by the rows' precision.
//!
//! Owns [`Polish`], the finishing step of a method whose rows come from a profile or a comb
//! (the strips method): each row is refitted as the Hough rows are ([`Preparer::refit`]), in
//! a wedge towards the vanishing point a quarter of the angle to its nearest neighbour wide
//! on each side (at most the band given), which gives it the sub-pixel precision of the
//! image; then the vanishing stage runs on the refitted rows and its answer is refitted with
//! each row weighted by its estimated precision ([`VanishingStage::refit_by_variances`]).

use super::prepare::Preparer;
use super::types::{DetectError, Detection};
use super::vanishing::VanishingStage;
use nalgebra::Vector3;
use std::f64::consts::PI;

/// The polish's band per row, reused from image to image.
#[derive(Debug, Clone, Default)]
pub struct Polish {
    bands: Vec<f64>,
}

impl Polish {
    /// Polishes `out`'s rows about its vanishing point (nothing without one), each in a
    /// wedge at most `max_band_rad` wide on each side at its foot.
    pub fn run(
        &mut self,
        prep: &mut Preparer,
        vanish: &mut VanishingStage,
        out: &mut Detection,
        max_band_rad: f64,
    ) -> Result<(), DetectError> {
        let Some(vp) = out.vanishing_point.map(|v| v.direction) else {
            return Ok(());
        };
        let a = crate::sphere::any_perpendicular(&vp);
        let b = vp.cross(&a);
        let angle = |n: &Vector3<f64>| n.dot(&b).atan2(n.dot(&a)).rem_euclid(PI);
        self.bands.clear();
        for (i, r) in out.rows.iter().enumerate() {
            let pi = angle(&r.normal);
            let mut gap = PI;
            for (j, q) in out.rows.iter().enumerate() {
                if i != j {
                    let d = (angle(&q.normal) - pi).rem_euclid(PI);
                    gap = gap.min(d.min(PI - d));
                }
            }
            self.bands.push((0.25 * gap).min(max_band_rad));
        }
        prep.refit(&mut out.rows, &self.bands, Some(&vp))?;
        vanish.run(None, out)?;
        vanish.refit_by_variances(out, prep.row_variances());
        Ok(())
    }
}
