//! The camera's pose over the synthetic field, and the pose quantities the detector reports.
//!
//! Owns the conventions the whole project shares (the detector computes heading and tilt the
//! same way): R_world_robot = Rz(yaw)·Ry(pitch)·Rx(roll); R_world_cam = R_world_robot ·
//! mounting.robot_from_camera(); the row direction in the robot frame d = R_world_robotᵀ·x̂ with
//! its sign chosen so that d.x ≥ 0; heading = atan2(d.y, d.x); tilt = atan2(d.z, |d.xy|).

use crate::camera::Mounting;
use nalgebra::{Rotation3, Vector3};

/// Where the camera is and how it is turned, in the field's world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Robot attitude: robot-frame vectors to world-frame vectors.
    pub world_from_robot: Rotation3<f64>,
    /// Camera attitude: OCamCalib camera-frame vectors to world-frame vectors.
    pub world_from_camera: Rotation3<f64>,
    /// Camera centre (single effective viewpoint), world frame, metres.
    pub centre: Vector3<f64>,
}

impl Pose {
    /// The pose for robot yaw, pitch, roll (radians), a camera mounting, and a camera centre.
    pub fn new(yaw: f64, pitch: f64, roll: f64, mounting: &Mounting, centre: Vector3<f64>) -> Self {
        let world_from_robot = Rotation3::from_euler_angles(roll, pitch, yaw);
        let world_from_camera = world_from_robot * mounting.robot_from_camera();
        Pose {
            world_from_robot,
            world_from_camera,
            centre,
        }
    }

    /// A world direction expressed in the camera frame.
    pub fn to_camera(&self, world_dir: &Vector3<f64>) -> Vector3<f64> {
        self.world_from_camera.inverse_transform_vector(world_dir)
    }

    /// The direction along the rows (world +X) in the camera frame: the vanishing point.
    pub fn vp_along(&self) -> Vector3<f64> {
        self.to_camera(&Vector3::x())
    }

    /// The direction across the rows (world +Y) in the camera frame.
    pub fn vp_across(&self) -> Vector3<f64> {
        self.to_camera(&Vector3::y())
    }

    /// The row direction in the robot frame, sign chosen so that it points forward (x ≥ 0).
    pub fn row_direction_robot(&self) -> Vector3<f64> {
        let d = self
            .world_from_robot
            .inverse_transform_vector(&Vector3::x());
        if d.x < 0.0 {
            -d
        } else {
            d
        }
    }

    /// Heading of the rows in the robot frame, radians (counter-clockwise from forward).
    pub fn heading(&self) -> f64 {
        let d = self.row_direction_robot();
        d.y.atan2(d.x)
    }

    /// Elevation of the row direction in the robot frame, radians.
    pub fn tilt(&self) -> f64 {
        let d = self.row_direction_robot();
        d.z.atan2(d.x.hypot(d.y))
    }

    /// Unit normal (camera frame) of the plane through the camera centre that contains the
    /// world line through `point` with direction `dir`. `None` when the line passes through
    /// the centre.
    pub fn line_normal(&self, point: &Vector3<f64>, dir: &Vector3<f64>) -> Option<Vector3<f64>> {
        let n = dir.cross(&(point - self.centre));
        let len = n.norm();
        (len > 1e-12).then(|| self.to_camera(&(n / len)))
    }

    /// Unit direction (camera frame) from the camera centre to a world point.
    pub fn direction_to(&self, point: &Vector3<f64>) -> Option<Vector3<f64>> {
        let v = point - self.centre;
        let len = v.norm();
        (len > 1e-12).then(|| self.to_camera(&(v / len)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pure_yaw_gives_minus_yaw_heading() {
        for yaw_deg in [-30.0f64, -5.0, 0.0, 12.0, 29.0] {
            let p = Pose::new(
                yaw_deg.to_radians(),
                0.0,
                0.0,
                &Mounting::default(),
                Vector3::new(0.0, 0.0, 1.0),
            );
            assert!((p.heading() + yaw_deg.to_radians()).abs() < 1e-12);
            assert!(p.tilt().abs() < 1e-12);
        }
    }

    #[test]
    fn pitch_gives_tilt_and_default_camera_looks_down() {
        let p = Pose::new(
            0.0,
            7f64.to_radians(),
            0.0,
            &Mounting::default(),
            Vector3::new(0.0, 0.0, 1.0),
        );
        // nose down: the rows rise in the robot frame
        assert!((p.tilt() - 7f64.to_radians()).abs() < 1e-12);
        let level = Pose::new(
            0.0,
            0.0,
            0.0,
            &Mounting::default(),
            Vector3::new(0.0, 0.0, 1.0),
        );
        // straight down is the optical axis (-z camera)
        assert!((level.to_camera(&-Vector3::z()) - -Vector3::z()).norm() < 1e-12);
        // rows run up the image (camera -x) at zero yaw
        assert!((level.vp_along() - -Vector3::x()).norm() < 1e-12);
    }
}
