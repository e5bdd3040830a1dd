//! Heading and tilt of the robot relative to the rows, from the vanishing point.
//!
//! Owns the conversion of the rows' direction (the vanishing point, camera frame, sign free)
//! into the robot frame (ROS REP 103: x forward, y left, z up) through the camera's mounting
//! rotation: d = R·vp with the sign chosen so that d points forward (d.x ≥ 0);
//! heading = atan2(d.y, d.x), counter-clockwise positive from the robot's forward axis, in
//! (−π/2, π/2]; tilt = atan2(d.z, hypot(d.x, d.y)), the elevation of the row direction
//! (positive when the rows rise ahead of the robot, i.e. the robot's nose is pitched down
//! relative to the field). The synthetic field's ground truth uses exactly this definition.
//!
//! Worked example: camera looking straight down, image top forward (default mounting). Rows
//! running towards the image's top-left corner at 45° have the camera-frame direction
//! (−1, −1, 0)/√2 (x down the image, y right); in the robot frame that is (1, 1, 0)/√2:
//! heading +45° (rows to the robot's left of straight ahead), tilt 0.

use crate::camera::Mounting;
use nalgebra::Vector3;

/// Heading and tilt (radians) and the row direction in the robot frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadingTilt {
    pub heading_rad: f64,
    pub tilt_rad: f64,
    /// Unit row direction in the robot frame, pointing forward (x ≥ 0).
    pub direction_robot: Vector3<f64>,
}

/// The robot's axes (REP 103) in the camera frame, through the mounting.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotAxes {
    pub fwd: Vector3<f64>,
    pub left: Vector3<f64>,
    pub up: Vector3<f64>,
}

impl RobotAxes {
    pub fn new(mounting: &Mounting) -> Self {
        let rot = mounting.robot_from_camera().inverse();
        RobotAxes {
            fwd: rot * Vector3::x(),
            left: rot * Vector3::y(),
            up: rot * Vector3::z(),
        }
    }

    /// The camera-frame direction at heading `az` (from forward towards left) and
    /// elevation `el` (radians): the inverse of [`heading_tilt`].
    pub fn direction(&self, az: f64, el: f64) -> Vector3<f64> {
        (self.fwd * az.cos() + self.left * az.sin()) * el.cos() + self.up * el.sin()
    }
}

/// Heading and tilt from a vanishing point (camera frame, any sign, any length > 0).
pub fn heading_tilt(vp_camera: &Vector3<f64>, mounting: &Mounting) -> HeadingTilt {
    let mut d = mounting.robot_from_camera() * vp_camera.normalize();
    if d.x < 0.0 || (d.x == 0.0 && d.y < 0.0) {
        d = -d;
    }
    HeadingTilt {
        heading_rad: d.y.atan2(d.x),
        tilt_rad: d.z.atan2(d.x.hypot(d.y)),
        direction_robot: d,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn worked_example() {
        let m = Mounting::default();
        let h = heading_tilt(&Vector3::new(-1.0, -1.0, 0.0), &m);
        assert!((h.heading_rad - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
        assert!(h.tilt_rad.abs() < 1e-12);
        // the opposite sign gives the same answer
        let h2 = heading_tilt(&Vector3::new(1.0, 1.0, 0.0), &m);
        assert_eq!(h, h2);
        // rows straight ahead, rising 5 degrees ahead: camera z is robot up
        let a = 5f64.to_radians();
        let h = heading_tilt(&Vector3::new(-a.cos(), 0.0, a.sin()), &m);
        assert!(h.heading_rad.abs() < 1e-12);
        assert!((h.tilt_rad - a).abs() < 1e-12);
    }

    proptest! {
        #[test]
        fn recovers_heading_and_tilt_through_any_mounting(
            heading in -1.5f64..1.5, tilt in -0.5f64..0.5,
            roll in -30.0f64..30.0, pitch in -30.0f64..30.0, yaw in -180.0f64..180.0,
            flip in proptest::bool::ANY)
        {
            let m = Mounting { roll_deg: roll, pitch_deg: pitch, yaw_deg: yaw, ..Mounting::default() };
            let d = Vector3::new(tilt.cos() * heading.cos(), tilt.cos() * heading.sin(), tilt.sin());
            let mut vp = m.robot_from_camera().inverse() * d;
            if flip { vp = -vp; }
            let h = heading_tilt(&vp, &m);
            prop_assert!((h.heading_rad - heading).abs() < 1e-9);
            prop_assert!((h.tilt_rad - tilt).abs() < 1e-9);
        }
    }
}
