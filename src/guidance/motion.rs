//! The robot's own motion as guidance takes it: odometry when fresh, the configured speed
//! otherwise.
//!
//! Owns [`Odometry`] (one sample: forward speed and yaw rate, with the time it arrived) and
//! [`Motion`], which keeps the latest sample and answers, for a frame's capture time, the
//! speed and yaw rate the tracker and the end-of-rows filter predict with: the odometry's
//! while it is no older than the configured age (`odometry_max_age_s`), else the configured
//! `speed_mps` (no yaw rate), else unknown (the filters' process noise carries the motion).
//! [`OdometryFeed`] hands samples from another thread (the ROS 2 subscription) to guidance.

use std::sync::Mutex;

/// One odometry sample (e.g. ROS 2 `nav_msgs/Odometry`'s twist in the robot frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Odometry {
    /// When it arrived (or was stamped), nanoseconds on the frames' capture clock (UNIX
    /// epoch): the staleness is judged against the frame's capture time.
    pub stamp_ns: u64,
    /// Forward speed along base_link's x, m/s (negative: reversing).
    pub speed_mps: f64,
    /// Yaw rate about base_link's z, rad/s, counter-clockwise positive (REP 103).
    pub yaw_rate_rps: f64,
}

/// The robot's motion at a frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MotionAt {
    /// Forward speed, m/s; `None`: unknown.
    pub speed_mps: Option<f64>,
    /// Yaw rate, rad/s; `None`: unknown.
    pub yaw_rate_rps: Option<f64>,
    /// The odometry gave it (it was fresh).
    pub from_odometry: bool,
}

/// The latest odometry and the fallbacks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    /// The configured speed, m/s (0: unknown).
    configured_mps: f64,
    max_age_ns: u64,
    latest: Option<Odometry>,
}

impl Motion {
    pub fn new(configured_mps: f64, max_age_s: f64) -> Self {
        Motion {
            configured_mps,
            max_age_ns: (max_age_s * 1e9) as u64,
            latest: None,
        }
    }

    /// Keeps `odom` when it is not older than the sample kept; non-finite samples are refused
    /// (false).
    pub fn set(&mut self, odom: Odometry) -> bool {
        if !(odom.speed_mps.is_finite() && odom.yaw_rate_rps.is_finite()) {
            return false;
        }
        if self.latest.is_none_or(|l| l.stamp_ns <= odom.stamp_ns) {
            self.latest = Some(odom);
        }
        true
    }

    /// The motion for a frame captured at `t_ns`: the odometry when it is at most the
    /// configured age away from the frame (either side: the frames may queue), else the
    /// configured speed, else unknown.
    pub fn at(&self, t_ns: u64) -> MotionAt {
        if let Some(o) = self.latest {
            if t_ns.abs_diff(o.stamp_ns) <= self.max_age_ns {
                return MotionAt {
                    speed_mps: Some(o.speed_mps),
                    yaw_rate_rps: Some(o.yaw_rate_rps),
                    from_odometry: true,
                };
            }
        }
        MotionAt {
            speed_mps: (self.configured_mps > 0.0).then_some(self.configured_mps),
            yaw_rate_rps: None,
            from_odometry: false,
        }
    }
}

/// The latest odometry sample, shared between the thread that receives it and guidance.
#[derive(Debug, Default)]
pub struct OdometryFeed {
    latest: Mutex<Option<Odometry>>,
}

impl PartialEq for OdometryFeed {
    fn eq(&self, other: &Self) -> bool {
        self.latest() == other.latest()
    }
}

impl OdometryFeed {
    pub fn new() -> Self {
        OdometryFeed::default()
    }

    /// Replaces the sample kept.
    pub fn put(&self, odom: Odometry) {
        if let Ok(mut l) = self.latest.lock() {
            *l = Some(odom);
        }
    }

    /// The latest sample, if any arrived.
    pub fn latest(&self) -> Option<Odometry> {
        self.latest.lock().ok().and_then(|l| *l)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: u64 = 1_000_000_000;

    #[test]
    fn fresh_odometry_wins_stale_falls_back_to_the_configured_speed() {
        let mut m = Motion::new(0.8, 0.5);
        assert_eq!(m.at(10 * S).speed_mps, Some(0.8));
        assert!(m.set(Odometry {
            stamp_ns: 10 * S,
            speed_mps: 1.3,
            yaw_rate_rps: 0.1,
        }));
        let a = m.at(10 * S + S / 4);
        assert_eq!((a.speed_mps, a.yaw_rate_rps), (Some(1.3), Some(0.1)));
        assert!(a.from_odometry);
        // older than 0.5 s: ignored
        let a = m.at(11 * S);
        assert_eq!((a.speed_mps, a.yaw_rate_rps), (Some(0.8), None));
        assert!(!a.from_odometry);
        // an older sample arriving late does not replace the newer one
        m.set(Odometry {
            stamp_ns: 9 * S,
            speed_mps: 0.1,
            yaw_rate_rps: 0.0,
        });
        assert_eq!(m.at(10 * S).speed_mps, Some(1.3));
        assert!(!m.set(Odometry {
            stamp_ns: 12 * S,
            speed_mps: f64::NAN,
            yaw_rate_rps: 0.0,
        }));
        // no configured speed: unknown
        assert_eq!(Motion::new(0.0, 0.5).at(S), MotionAt::default());
    }
}
