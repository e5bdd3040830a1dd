//! The robot: a planar pose and unicycle kinematics, driven by a curvature command through a
//! differential drive (yaw-rate limit) or an Ackermann chassis (wheelbase, steering limit).
//!
//! Owns [`Pose2`] (world x, y, heading θ, REP 103: x forward at θ = 0, y left, θ
//! counter-clockwise), [`RobotModel`] (how a commanded curvature becomes a yaw rate) and the
//! exact integration of constant speed and yaw rate over a time step (an arc).

use serde::Serialize;

/// A pose on the ground plane: world metres and radians.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Pose2 {
    pub x: f64,
    pub y: f64,
    pub theta: f64,
}

impl Pose2 {
    /// Moves the pose at speed `v` (m/s) and yaw rate `omega` (rad/s) for `dt` seconds:
    /// the exact arc (a straight line when `omega` is 0).
    pub fn integrate(&mut self, v: f64, omega: f64, dt: f64) {
        let dth = omega * dt;
        if dth.abs() < 1e-9 {
            let th = self.theta + dth / 2.0;
            self.x += v * dt * th.cos();
            self.y += v * dt * th.sin();
        } else {
            let r = v / omega;
            self.x += r * ((self.theta + dth).sin() - self.theta.sin());
            self.y -= r * ((self.theta + dth).cos() - self.theta.cos());
        }
        self.theta += dth;
    }

    /// The world position of a point at (`fx` forward, `fy` left) in this pose's frame.
    pub fn point(&self, fx: f64, fy: f64) -> (f64, f64) {
        let (s, c) = self.theta.sin_cos();
        (self.x + c * fx - s * fy, self.y + s * fx + c * fy)
    }
}

/// How the robot turns.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum RobotModel {
    /// Differential drive: turns at yaw rate v·κ, at most `max_yaw_rate_rad_s` either way.
    DiffDrive { max_yaw_rate_rad_s: f64 },
    /// Ackermann (bicycle model about the rear axle, which is base_link): the steering angle
    /// δ = atan(L·κ) clamped to ±`max_steer_rad`, yaw rate v·tan(δ)/L.
    Ackermann {
        wheelbase_m: f64,
        max_steer_rad: f64,
    },
}

impl RobotModel {
    /// The yaw rate, rad/s, the chassis turns at when commanded curvature `kappa` (1/m,
    /// positive left) at speed `v`.
    pub fn yaw_rate(&self, v: f64, kappa: f64) -> f64 {
        match *self {
            RobotModel::DiffDrive { max_yaw_rate_rad_s } => {
                (v * kappa).clamp(-max_yaw_rate_rad_s, max_yaw_rate_rad_s)
            }
            RobotModel::Ackermann {
                wheelbase_m,
                max_steer_rad,
            } => {
                let delta = (wheelbase_m * kappa)
                    .atan()
                    .clamp(-max_steer_rad, max_steer_rad);
                v * delta.tan() / wheelbase_m
            }
        }
    }

    /// Checks the limits (positive, finite; a steering limit below 90°).
    pub fn validate(&self) -> Result<(), String> {
        match *self {
            RobotModel::DiffDrive { max_yaw_rate_rad_s } => {
                if !(max_yaw_rate_rad_s.is_finite() && max_yaw_rate_rad_s > 0.0) {
                    return Err(format!(
                        "the yaw-rate limit {max_yaw_rate_rad_s} rad/s must be positive"
                    ));
                }
            }
            RobotModel::Ackermann {
                wheelbase_m,
                max_steer_rad,
            } => {
                if !(wheelbase_m.is_finite() && wheelbase_m > 0.0 && wheelbase_m <= 20.0) {
                    return Err(format!(
                        "the wheelbase {wheelbase_m} m must be in (0, 20] metres"
                    ));
                }
                if !(max_steer_rad > 0.0 && max_steer_rad < std::f64::consts::FRAC_PI_2) {
                    return Err(format!(
                        "the steering limit {:.1}° must be in (0°, 90°)",
                        max_steer_rad.to_degrees()
                    ));
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_constant_turn_drives_a_circle_exactly() {
        // curvature 0.1 /m at 2 m/s: radius 10 m; a quarter circle in (π/2)·10/2 s
        let mut p = Pose2 {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
        };
        let (v, omega) = (2.0, 0.2);
        let t = std::f64::consts::FRAC_PI_2 / omega;
        let n = 37;
        for _ in 0..n {
            p.integrate(v, omega, t / n as f64);
        }
        assert!((p.x - 10.0).abs() < 1e-9, "{p:?}");
        assert!((p.y - 10.0).abs() < 1e-9, "{p:?}");
        assert!((p.theta - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        // straight on
        let mut q = Pose2 {
            x: 1.0,
            y: 2.0,
            theta: 0.5,
        };
        q.integrate(1.0, 0.0, 2.0);
        assert!((q.x - (1.0 + 2.0 * 0.5f64.cos())).abs() < 1e-12);
        assert!((q.y - (2.0 + 2.0 * 0.5f64.sin())).abs() < 1e-12);
    }

    #[test]
    fn the_chassis_limits_the_turn() {
        let dd = RobotModel::DiffDrive {
            max_yaw_rate_rad_s: 0.5,
        };
        assert_eq!(dd.yaw_rate(1.0, 0.2), 0.2);
        assert_eq!(dd.yaw_rate(1.0, -2.0), -0.5);
        let ack = RobotModel::Ackermann {
            wheelbase_m: 2.0,
            max_steer_rad: 30f64.to_radians(),
        };
        // small curvature: exactly v·κ
        assert!((ack.yaw_rate(1.5, 0.05) - 1.5 * 0.05).abs() < 1e-12);
        // beyond the steering limit: the tightest turn, tan(30°)/2 per metre
        let max = 1.5 * 30f64.to_radians().tan() / 2.0;
        assert!((ack.yaw_rate(1.5, 5.0) - max).abs() < 1e-12);
        assert!((ack.yaw_rate(1.5, -5.0) + max).abs() < 1e-12);
        assert!(ack.validate().is_ok());
        assert!(RobotModel::Ackermann {
            wheelbase_m: 2.0,
            max_steer_rad: 2.0
        }
        .validate()
        .is_err());
    }
}
