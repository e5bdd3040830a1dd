//! Ground geometry: a detected row (a great circle, its plane's normal in the camera frame)
//! becomes a line on the ground plane in the robot frame.
//!
//! Owns [`GroundFrame`]: the row-aligned frame on the ground built from the rows' direction
//! (the vanishing point), the camera's mounting and height, and an optional roll about the
//! row direction. With no roll the robot's y axis lies in the ground plane (the robot stands
//! on the ground it sees), so the ground's up direction is `d × ŷ` normalised. Every row plane contains the camera centre and the row direction `d`; it
//! cuts the ground (the plane through `d` at `height_m` below the camera, perpendicular to the
//! up direction `u`) in a line parallel to `d` at the lateral position
//! `y = h · (m·u) / (m·l)`, where `m` is the row plane's normal in the robot frame and
//! `l = u × d` points to the robot's left (REP 103). A roll φ turns `u` and `l` about `d`.

use crate::camera::Mounting;
use nalgebra::{Rotation3, Vector3};

/// The row-aligned frame on the ground, robot (base_link) coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundFrame {
    /// Unit direction along the rows, robot frame, pointing forward (x ≥ 0).
    pub along: Vector3<f64>,
    /// Unit ground normal (up), robot frame, perpendicular to `along`.
    pub up: Vector3<f64>,
    /// Unit direction across the rows to the left: `up × along`.
    pub left: Vector3<f64>,
    /// Camera height above the ground, metres.
    pub height_m: f64,
    /// Camera centre in base_link, metres.
    pub camera_m: Vector3<f64>,
}

impl GroundFrame {
    /// The frame for the rows' direction `vp_camera` (camera frame, sign free), the camera's
    /// `mounting`, and a roll `roll_rad` about the row direction (REP 103 sense: positive
    /// turns the robot's right side down relative to the ground). `None` when the direction
    /// is not finite or points nearly straight up or down in the robot frame.
    pub fn new(vp_camera: &Vector3<f64>, mounting: &Mounting, roll_rad: f64) -> Option<Self> {
        Self::with_rotation(vp_camera, &mounting.robot_from_camera(), mounting, roll_rad)
    }

    /// As [`GroundFrame::new`] with the mounting's rotation already computed.
    pub fn with_rotation(
        vp_camera: &Vector3<f64>,
        robot_from_camera: &Rotation3<f64>,
        mounting: &Mounting,
        roll_rad: f64,
    ) -> Option<Self> {
        let mut d = robot_from_camera * vp_camera;
        let n = d.norm();
        if !(n.is_finite() && n > 1e-12) {
            return None;
        }
        d /= n;
        if d.x < 0.0 {
            d = -d;
        }
        // rows rising more than ~53° in the robot frame are no ground the robot stands on
        if d.z.abs() > 0.8 {
            return None;
        }
        // zero roll: the robot's y axis lies in the ground plane, so up ⟂ (d, y)
        let u0 = d.cross(&Vector3::y());
        let un = u0.norm();
        if un < 0.1 {
            return None;
        }
        let u0 = u0 / un;
        let l0 = u0.cross(&d);
        let (s, c) = roll_rad.sin_cos();
        let up = u0 * c + l0 * s;
        let left = up.cross(&d);
        Some(GroundFrame {
            along: d,
            up,
            left,
            height_m: mounting.height_m,
            camera_m: Vector3::from(mounting.position_m),
        })
    }

    /// The same frame turned by `roll_rad` more about the row direction.
    pub fn rolled(&self, roll_rad: f64) -> Self {
        let (s, c) = roll_rad.sin_cos();
        let up = self.up * c + self.left * s;
        GroundFrame {
            up,
            left: up.cross(&self.along),
            ..*self
        }
    }

    /// Heading of the rows on the ground: the angle from the robot's forward axis projected
    /// on the ground to the rows, counter-clockwise about the ground's up, radians. (The
    /// robot's yaw relative to the rows is its negative, whatever its pitch.)
    pub fn heading_rad(&self) -> f64 {
        let x = Vector3::x();
        let f = x - self.up * x.dot(&self.up);
        let s = self.up.cross(&f);
        self.along.dot(&s).atan2(self.along.dot(&f))
    }

    /// Lateral position (metres, to the left of the camera's foot point, across the rows on
    /// the ground) of the row whose plane has unit normal `normal_robot` (robot frame). `None`
    /// when the plane is nearly parallel to the ground (the row would be beyond the horizon).
    pub fn row_lateral_m(&self, normal_robot: &Vector3<f64>) -> Option<f64> {
        let a = normal_robot.dot(&self.left);
        let b = normal_robot.dot(&self.up);
        let y = self.height_m * b / a;
        (a.abs() > 1e-9 && y.is_finite()).then_some(y)
    }

    /// Lateral position of a base_link point (its projection on the ground), metres, to the
    /// left of the camera's foot point.
    pub fn point_lateral_m(&self, p: &Vector3<f64>) -> f64 {
        self.left.dot(&(p - self.camera_m))
    }

    /// The camera's foot point: the ground point straight below the camera along `up`.
    pub fn foot_m(&self) -> Vector3<f64> {
        self.camera_m - self.up * self.height_m
    }

    /// A point of the ground line at lateral position `lateral_m` (base_link), the one
    /// closest to the camera's foot point.
    pub fn line_point_m(&self, lateral_m: f64) -> Vector3<f64> {
        self.foot_m() + self.left * lateral_m
    }

    /// Where the camera ray `ray_robot` (robot frame) meets the ground, in the row-aligned
    /// coordinates (along, left) from the camera's foot point, metres. `None` for rays that
    /// do not point below the ground's horizon.
    pub fn ray_on_ground(&self, ray_robot: &Vector3<f64>) -> Option<[f64; 2]> {
        let down = -ray_robot.dot(&self.up);
        if down < 1e-6 {
            return None;
        }
        let t = self.height_m / down;
        Some([
            t * ray_robot.dot(&self.along),
            t * ray_robot.dot(&self.left),
        ])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::Pose;
    use proptest::prelude::*;

    fn mounting(h: f64) -> Mounting {
        Mounting {
            height_m: h,
            ..Mounting::default()
        }
    }

    /// Normal (camera frame) of the row at world y = `row_y` seen by a camera at world
    /// (0, `cam_y`, `h`) with robot yaw and pitch.
    fn row_normal(yaw: f64, pitch: f64, roll: f64, cam_y: f64, h: f64, row_y: f64) -> Vector3<f64> {
        let pose = Pose::new(
            yaw,
            pitch,
            roll,
            &Mounting::default(),
            Vector3::new(0.0, cam_y, h),
        );
        pose.line_normal(&Vector3::new(0.0, row_y, 0.0), &Vector3::x())
            .unwrap()
    }

    fn vp(yaw: f64, pitch: f64, roll: f64) -> Vector3<f64> {
        Pose::new(yaw, pitch, roll, &Mounting::default(), Vector3::zeros()).vp_along()
    }

    #[test]
    fn level_robot_sees_rows_at_their_lateral_positions() {
        let m = mounting(1.0);
        let g = GroundFrame::new(&vp(0.0, 0.0, 0.0), &m, 0.0).unwrap();
        assert!((g.along - Vector3::x()).norm() < 1e-12);
        assert!((g.left - Vector3::y()).norm() < 1e-12);
        let r = m.robot_from_camera();
        for row_y in [-1.0, -0.5, 0.0, 0.5, 1.5] {
            let n = r * row_normal(0.0, 0.0, 0.0, 0.1, 1.0, row_y);
            let y = g.row_lateral_m(&n).unwrap();
            assert!((y - (row_y - 0.1)).abs() < 1e-12, "{y} vs {row_y}");
        }
    }

    proptest! {
        /// Yaw and pitch are taken out by the vanishing point: the lateral positions are
        /// those on the ground, measured across the rows, for any height.
        #[test]
        fn lateral_exact_under_yaw_and_pitch(
            yaw in -0.5f64..0.5, pitch in -0.15f64..0.15, cam_y in -0.3f64..0.3,
            h in 0.5f64..2.0, k in -6i32..6,
        ) {
            let m = mounting(h);
            let g = GroundFrame::new(&vp(yaw, pitch, 0.0), &m, 0.0).unwrap();
            prop_assert!((g.heading_rad() + yaw).abs() < 1e-9);
            let row_y = k as f64 * 0.5;
            // the ground in the robot frame is tilted by pitch: the perpendicular distance from
            // the camera to the ground is h (the camera is h above it along world up)
            let n = m.robot_from_camera() * row_normal(yaw, pitch, 0.0, cam_y, h, row_y);
            if let Some(y) = g.row_lateral_m(&n) {
                prop_assert!((y - (row_y - cam_y)).abs() < 1e-9 * (1.0 + (row_y - cam_y).abs()), "{} vs {}", y, row_y - cam_y);
            }
        }

        /// A roll about the rows, given to the frame, gives back the true positions.
        #[test]
        fn lateral_exact_with_known_roll(
            roll in -0.1f64..0.1, cam_y in -0.3f64..0.3, k in -4i32..4,
        ) {
            let m = mounting(1.0);
            let g = GroundFrame::new(&vp(0.0, 0.0, roll), &m, roll).unwrap();
            let row_y = k as f64 * 0.5;
            let n = m.robot_from_camera() * row_normal(0.0, 0.0, roll, cam_y, 1.0, row_y);
            let y = g.row_lateral_m(&n).unwrap();
            prop_assert!((y - (row_y - cam_y)).abs() < 1e-9, "{} vs {}", y, row_y - cam_y);
        }
    }

    #[test]
    fn ray_meets_ground_below_camera() {
        let m = mounting(1.2);
        let g = GroundFrame::new(&vp(0.0, 0.0, 0.0), &m, 0.0).unwrap();
        let ray = Vector3::new(2.0, -1.0, -1.2).normalize();
        let p = g.ray_on_ground(&ray).unwrap();
        assert!((p[0] - 2.0).abs() < 1e-12 && (p[1] + 1.0).abs() < 1e-12);
        assert!(g.ray_on_ground(&Vector3::new(1.0, 0.0, 0.1)).is_none());
        assert!((g.foot_m() - Vector3::new(0.0, 0.0, -1.2)).norm() < 1e-12);
    }

    #[test]
    fn vertical_direction_has_no_frame() {
        assert!(GroundFrame::new(&Vector3::z(), &mounting(1.0), 0.0).is_none());
        assert!(GroundFrame::new(&Vector3::zeros(), &mounting(1.0), 0.0).is_none());
    }
}
