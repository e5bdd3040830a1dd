//! A prior on the next frame's answer: where the vanishing point is expected, and how far from
//! there it may be (issue 14 §2, "the prediction narrows the next frame's search").
//!
//! Owns [`DetectorPrior`], plain data the caller (the pipeline, from the row tracker's
//! prediction) hands to [`super::Detector::process_with_prior`]. With a prior, the row Hough
//! votes only for great circles that pass within the window of the expected vanishing point
//! (a ray then casts its votes in a few accumulator columns instead of all of them), and the
//! vanishing-point Hough takes its winner only inside the window. The narrowed answer is
//! accepted when it has a vanishing point inside the window; otherwise the detector runs the
//! full search on the same prepared points, so a wrong prior costs time, never the answer.

use super::types::DetectError;
use crate::camera::Mounting;
use nalgebra::Vector3;

/// The expected vanishing point and the window around it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectorPrior {
    /// Expected direction of the rows (OCamCalib camera frame, sign free, any length > 0).
    pub vanishing_point: Vector3<f64>,
    /// Half-angle (radians) of the window around it: rows whose vanishing point is farther
    /// than this are not searched for.
    pub window_rad: f64,
}

/// The narrowest window a prior may have (radians, 0.1°): below the accumulators' cells a
/// window only loses rows.
pub const MIN_WINDOW_RAD: f64 = 0.001_745;
/// The widest window (radians, 30°); wider is no narrowing.
pub const MAX_WINDOW_RAD: f64 = std::f64::consts::FRAC_PI_6;

impl DetectorPrior {
    /// The prior of rows with `heading_rad` and `tilt_rad` in the robot frame (as
    /// [`super::pose::heading_tilt`] defines them), through the camera's `mounting`.
    pub fn from_heading_tilt(
        heading_rad: f64,
        tilt_rad: f64,
        window_rad: f64,
        mounting: &Mounting,
    ) -> Self {
        let d = Vector3::new(
            tilt_rad.cos() * heading_rad.cos(),
            tilt_rad.cos() * heading_rad.sin(),
            tilt_rad.sin(),
        );
        DetectorPrior {
            vanishing_point: mounting.robot_from_camera().inverse() * d,
            window_rad,
        }
    }

    /// The unit direction, or an error naming the bad value.
    pub fn validate(&self) -> Result<Vector3<f64>, DetectError> {
        let n = self.vanishing_point.norm();
        if !(n.is_finite() && n > 1e-12) {
            return Err(DetectError::Options(format!(
                "prior: vanishing point {:?} is not a direction",
                self.vanishing_point.as_slice()
            )));
        }
        if !(MIN_WINDOW_RAD..=MAX_WINDOW_RAD).contains(&self.window_rad) {
            return Err(DetectError::Options(format!(
                "prior: window_rad = {} must be within [{MIN_WINDOW_RAD}, {MAX_WINDOW_RAD}]",
                self.window_rad
            )));
        }
        Ok(self.vanishing_point / n)
    }

    /// Whether `direction` (sign free) lies within the window.
    pub fn contains(&self, direction: &Vector3<f64>) -> bool {
        crate::sphere::axis_angle(&self.vanishing_point.normalize(), direction) <= self.window_rad
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::pose::heading_tilt;

    #[test]
    fn heading_and_tilt_round_trip_through_the_mounting() {
        let m = Mounting {
            pitch_deg: -50.0,
            yaw_deg: 3.0,
            ..Mounting::default()
        };
        let p = DetectorPrior::from_heading_tilt(0.1, -0.02, 0.05, &m);
        let ht = heading_tilt(&p.vanishing_point, &m);
        assert!((ht.heading_rad - 0.1).abs() < 1e-12);
        assert!((ht.tilt_rad + 0.02).abs() < 1e-12);
        assert!(p.contains(&p.vanishing_point));
        assert!(p.contains(&-p.vanishing_point));
        let off = DetectorPrior::from_heading_tilt(0.2, -0.02, 0.05, &m).vanishing_point;
        assert!(!p.contains(&off));
    }

    #[test]
    fn bad_priors_are_named() {
        let p = DetectorPrior {
            vanishing_point: Vector3::zeros(),
            window_rad: 0.05,
        };
        assert!(p
            .validate()
            .unwrap_err()
            .to_string()
            .contains("not a direction"));
        let p = DetectorPrior {
            vanishing_point: Vector3::x(),
            window_rad: 2.0,
        };
        assert!(p.validate().unwrap_err().to_string().contains("window_rad"));
        let p = DetectorPrior {
            vanishing_point: Vector3::new(0.0, 2.0, 0.0),
            window_rad: 0.05,
        };
        assert_eq!(p.validate().unwrap(), Vector3::y());
    }
}
