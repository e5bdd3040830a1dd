//! Steering controllers on the node's published guidance: the lateral offset (positive when
//! the robot is left of the followed line), the rows' heading in the robot frame (counter-
//! clockwise from forward: a robot turned left of the rows sees them at a negative heading)
//! and the followed line's curvature (positive bending left), as docs/guidance.md defines
//! them. Each returns a curvature command, 1/m, positive turning left; the robot model
//! turns it into a yaw rate.

use serde::Serialize;

/// What the controller is told about the followed line (the estimate's guidance).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineMeasurement {
    /// Offset of the tool point from the line, metres, positive left of it.
    pub offset_m: f64,
    /// The line's heading in the robot frame, radians, counter-clockwise from forward.
    pub heading_rad: f64,
    /// The line's curvature, 1/m, positive bending left (0 when unknown).
    pub curvature_per_m: f64,
}

/// A steering law.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Controller {
    /// Pure pursuit: the arc through the point `lookahead_m` ahead on the line (the line
    /// continued with its curvature to second order).
    PurePursuit { lookahead_m: f64 },
    /// Stanley: steering angle δ = heading + atan(−gain·offset / v) + atan(L·curvature)
    /// (the last term the curvature's feed-forward), curvature command tan(δ)/L with L the
    /// `wheelbase_m` (a differential drive's reference length), δ within ±80°.
    Stanley { gain: f64, wheelbase_m: f64 },
}

/// Stanley's steering angle is kept within this, radians (80°).
const STANLEY_MAX_RAD: f64 = 1.396;

impl Controller {
    /// The curvature command for `m` at speed `v` (m/s).
    pub fn command(&self, m: &LineMeasurement, v: f64) -> f64 {
        match *self {
            Controller::PurePursuit { lookahead_m } => {
                let (e, h, k) = (m.offset_m, m.heading_rad, m.curvature_per_m);
                // robot frame: the line's direction d and its left normal n; the robot sits
                // at +e along n from the line's foot point
                let (s, c) = h.sin_cos();
                let (d, n) = ((c, s), (-s, c));
                let a = (lookahead_m * lookahead_m - e * e).max(0.0).sqrt();
                let side = -e + k * a * a / 2.0;
                let (px, py) = (a * d.0 + side * n.0, a * d.1 + side * n.1);
                let l2 = (px * px + py * py).max(1e-6);
                2.0 * py / l2
            }
            Controller::Stanley { gain, wheelbase_m } => {
                let delta = m.heading_rad
                    + (-gain * m.offset_m).atan2(v.abs().max(0.1))
                    + (wheelbase_m * m.curvature_per_m).atan();
                delta.clamp(-STANLEY_MAX_RAD, STANLEY_MAX_RAD).tan() / wheelbase_m
            }
        }
    }

    /// Checks the parameters (positive, finite).
    pub fn validate(&self) -> Result<(), String> {
        let ok = |v: f64| v.is_finite() && v > 0.0;
        match *self {
            Controller::PurePursuit { lookahead_m } if !ok(lookahead_m) => Err(format!(
                "the pure-pursuit lookahead {lookahead_m} m must be positive"
            )),
            Controller::Stanley { gain, .. } if !ok(gain) => {
                Err(format!("the Stanley gain {gain} must be positive"))
            }
            Controller::Stanley { wheelbase_m, .. } if !ok(wheelbase_m) => Err(format!(
                "the Stanley reference length {wheelbase_m} m must be positive"
            )),
            _ => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::robot::{Pose2, RobotModel};

    /// Drives a robot along the straight line y = 0 (heading +x) from `y0` and `yaw0`,
    /// the controller fed the exact offset and heading every `dt`; the largest |y| and |yaw|
    /// over the last second.
    fn follow(ctl: Controller, y0: f64, yaw0: f64) -> (f64, f64) {
        let robot = RobotModel::DiffDrive {
            max_yaw_rate_rad_s: 2.0,
        };
        let (v, dt) = (1.5, 1.0 / 15.0);
        let mut p = Pose2 {
            x: 0.0,
            y: y0,
            theta: yaw0,
        };
        let (mut worst_y, mut worst_yaw) = (0.0f64, 0.0f64);
        for i in 0..(20.0 / dt) as usize {
            let m = LineMeasurement {
                offset_m: p.y,
                heading_rad: -p.theta,
                curvature_per_m: 0.0,
            };
            let omega = robot.yaw_rate(v, ctl.command(&m, v));
            p.integrate(v, omega, dt);
            if i as f64 * dt > 19.0 {
                worst_y = worst_y.max(p.y.abs());
                worst_yaw = worst_yaw.max(p.theta.abs());
            }
        }
        (worst_y, worst_yaw)
    }

    #[test]
    fn both_controllers_converge_from_an_offset_and_a_heading() {
        for ctl in [
            Controller::PurePursuit { lookahead_m: 1.5 },
            Controller::Stanley {
                gain: 1.0,
                wheelbase_m: 1.0,
            },
        ] {
            for (y0, yaw0) in [(0.1, 0.0), (-0.2, 0.1), (0.0, -0.2), (0.15, 0.15)] {
                let (y, yaw) = follow(ctl, y0, yaw0);
                assert!(
                    y < 1e-3 && yaw < 1e-3,
                    "{ctl:?} from {y0}, {yaw0}: {y}, {yaw}"
                );
            }
        }
    }

    #[test]
    fn left_of_the_line_steers_right_and_turned_left_steers_right() {
        for ctl in [
            Controller::PurePursuit { lookahead_m: 1.5 },
            Controller::Stanley {
                gain: 1.0,
                wheelbase_m: 1.0,
            },
        ] {
            let m = |offset_m, heading_rad, curvature_per_m| LineMeasurement {
                offset_m,
                heading_rad,
                curvature_per_m,
            };
            // left of the line: turn right (negative curvature)
            assert!(ctl.command(&m(0.1, 0.0, 0.0), 1.5) < 0.0, "{ctl:?}");
            assert!(ctl.command(&m(-0.1, 0.0, 0.0), 1.5) > 0.0, "{ctl:?}");
            // turned left of the rows (they appear at a negative heading): turn right
            assert!(ctl.command(&m(0.0, -0.1, 0.0), 1.5) < 0.0, "{ctl:?}");
            // on the line, the line bending left: follow it (about its curvature)
            let k = ctl.command(&m(0.0, 0.0, 0.05), 1.5);
            assert!((k - 0.05).abs() < 0.005, "{ctl:?}: {k}");
        }
    }
}
