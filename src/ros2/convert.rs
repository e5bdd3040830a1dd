//! From omnirow's estimate, status and frames to ROS 2 messages: pure functions, no DDS.
//!
//! Owns the meaning of every published field: how heading and tilt become an orientation
//! (REP 103: x forward, y left, z up; yaw about z counter-clockwise, pitch about y, positive
//! nose down), how quality becomes a covariance, which diagnostic level a status maps to.
//!
//! The orientation is the robot's attitude in the *rows frame*: x along the rows (the
//! direction the robot drives along them), z up, y left. The detector sees the row direction
//! in the robot frame at heading `h` (counter-clockwise from forward) and elevation `t`, i.e.
//! `d = (cos t cos h, cos t sin h, sin t)`. The published rotation `R` (robot to rows frame)
//! satisfies `Rᵀ · x̂ = d` exactly, with roll — the rotation about the rows, which rows
//! cannot observe — set to zero in ZYX (yaw, pitch, roll) angles. That gives
//! `yaw = −asin(cos t · sin h)` and `pitch = atan2(sin t, cos t · cos h)`, so for small
//! angles `yaw ≈ −heading` (rows seen turned left mean the robot is turned right of them)
//! and `pitch ≈ tilt`. The row direction's sign is free, so `h` is first folded into
//! (−90°, 90°]. `~/heading_tilt` carries `h` and `t` unchanged, for plotting.

use super::config::Ros2Config;
use super::input::{RosEstimate, RosGuidance, RosStatus};
use super::msg::{
    DiagnosticArray, DiagnosticStatus, Header, Image, Imu, KeyValue, Quaternion, Time,
    TimeRangeError, Vector3, Vector3Stamped,
};
use crate::frame::ImageView;
use nalgebra::UnitQuaternion;
use std::f64::consts::PI;

/// Variance (rad²) published for roll, which the rows do not observe: large enough that
/// any fusion filter gives it no weight.
pub const UNOBSERVED_VARIANCE: f64 = 1.0e6;

/// Quality below which the covariance stops growing (σ is at most 100× its best).
pub const MIN_QUALITY: f64 = 0.01;

/// Covariance matrices' element 0 set to this marks a quantity as not provided (Imu.msg).
pub const NOT_PROVIDED: [f64; 9] = [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];

/// The robot's attitude in the rows frame, from the row direction seen in the robot frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RowAttitude {
    /// Rotation about z, radians (REP 103: counter-clockwise seen from above).
    pub yaw_rad: f64,
    /// Rotation about y, radians (positive nose down).
    pub pitch_rad: f64,
    /// The same rotation (robot frame to rows frame) as a unit quaternion.
    pub quaternion: Quaternion,
}

impl RowAttitude {
    /// From heading and tilt (radians) of the rows in the robot frame; see the module doc.
    pub fn from_heading_tilt(heading_rad: f64, tilt_rad: f64) -> RowAttitude {
        let (mut h, mut t) = (heading_rad, tilt_rad);
        if h.cos() < 0.0 {
            // The opposite row direction: heading + 180°, elevation negated.
            h = (h + PI).rem_euclid(2.0 * PI);
            if h > PI {
                h -= 2.0 * PI;
            }
            t = -t;
        }
        let yaw = -(t.cos() * h.sin()).clamp(-1.0, 1.0).asin();
        let pitch = t.sin().atan2(t.cos() * h.cos());
        let q = UnitQuaternion::from_euler_angles(0.0, pitch, yaw);
        RowAttitude {
            yaw_rad: yaw,
            pitch_rad: pitch,
            quaternion: Quaternion {
                x: q.i,
                y: q.j,
                z: q.k,
                w: q.w,
            },
        }
    }
}

/// Builds every message omnirow publishes; holds what the config fixes. The row guidance
/// messages are built in [`super::rows`].
#[derive(Debug, Clone)]
pub struct MessageBuilder {
    pub(super) frame_id: String,
    image_frame_id: String,
    pub(super) rows_frame_id: String,
    pub(super) node_name: String,
    sigma_best_rad: f64,
    pub(super) path_length_m: f64,
    pub(super) path_step_m: f64,
    /// The guidance's tool point (base_link x, y, metres), where its offset is measured.
    pub(super) tool_point_m: [f64; 2],
}

impl MessageBuilder {
    pub fn new(config: &Ros2Config) -> MessageBuilder {
        MessageBuilder {
            frame_id: config.frame_id.clone(),
            image_frame_id: config.image_frame_id.clone(),
            rows_frame_id: config.rows_frame_id.clone(),
            node_name: config.node_name.clone(),
            sigma_best_rad: config.sigma_deg_at_full_quality.to_radians(),
            path_length_m: config.path_length_m,
            path_step_m: config.path_step_m,
            tool_point_m: [0.0, 0.0],
        }
    }

    /// The guidance's tool point (`[guidance] tool_point_m`, base_link x and y, metres): the
    /// row guidance measures its offset there, `row_pose` moves it to base_link.
    pub fn with_tool_point(mut self, tool_point_m: [f64; 2]) -> MessageBuilder {
        self.tool_point_m = tool_point_m;
        self
    }

    pub(super) fn header(&self, ns: u64) -> Result<Header, TimeRangeError> {
        Ok(Header {
            stamp: Time::from_nanos(ns)?,
            frame_id: self.frame_id.clone(),
        })
    }

    /// Standard deviation (radians) of heading and tilt at this quality: σ_best / quality,
    /// quality clamped to [`MIN_QUALITY`]..=1 (NaN counts as the minimum).
    pub fn sigma_rad(&self, quality: f64) -> f64 {
        let q = if quality.is_nan() {
            MIN_QUALITY
        } else {
            quality.clamp(MIN_QUALITY, 1.0)
        };
        self.sigma_best_rad / q
    }

    /// `sensor_msgs/Imu` for an estimate with both heading and tilt; `None` otherwise (the
    /// status then travels on `/diagnostics` only).
    pub fn imu(&self, e: &RosEstimate) -> Result<Option<Imu>, TimeRangeError> {
        let (Some(h), Some(t)) = (e.heading_rad, e.tilt_rad) else {
            return Ok(None);
        };
        let att = RowAttitude::from_heading_tilt(h, t);
        let var = self.sigma_rad(e.quality).powi(2);
        let mut cov = [0.0; 9];
        cov[0] = UNOBSERVED_VARIANCE; // roll
        cov[4] = var; // pitch
        cov[8] = var; // yaw
        Ok(Some(Imu {
            header: self.header(e.capture_ns)?,
            orientation: att.quaternion,
            orientation_covariance: cov,
            angular_velocity: Vector3::default(),
            angular_velocity_covariance: NOT_PROVIDED,
            linear_acceleration: Vector3::default(),
            linear_acceleration_covariance: NOT_PROVIDED,
        }))
    }

    /// `geometry_msgs/Vector3Stamped` (x = heading, y = tilt, radians; z = quality) for an
    /// estimate with both heading and tilt; `None` otherwise.
    pub fn heading_tilt(&self, e: &RosEstimate) -> Result<Option<Vector3Stamped>, TimeRangeError> {
        let (Some(h), Some(t)) = (e.heading_rad, e.tilt_rad) else {
            return Ok(None);
        };
        Ok(Some(Vector3Stamped {
            header: self.header(e.capture_ns)?,
            vector: Vector3 {
                x: h,
                y: t,
                z: e.quality,
            },
        }))
    }

    /// The diagnostic level of an estimate status: `ok` is OK, `camera_lost` is ERROR,
    /// anything else (`no_rows`, `degraded`, ...) is WARN.
    pub fn level(estimate_status: &str) -> u8 {
        match estimate_status {
            "ok" => DiagnosticStatus::OK,
            "camera_lost" => DiagnosticStatus::ERROR,
            _ => DiagnosticStatus::WARN,
        }
    }

    /// `diagnostic_msgs/DiagnosticArray` with a status named `<node_name>: pipeline` and,
    /// when the node runs row guidance, one named `<node_name>: guidance` (the latest
    /// frame's), stamped `now_ns` (wall clock: the summary is not tied to a frame).
    pub fn diagnostics(
        &self,
        s: &RosStatus,
        guidance: Option<&RosGuidance>,
        now_ns: u64,
    ) -> Result<DiagnosticArray, TimeRangeError> {
        let kv = |key: &str, value: String| KeyValue {
            key: key.to_string(),
            value,
        };
        let mut values = vec![
            kv("estimate_status", s.estimate_status.to_string()),
            kv("source_state", s.source_state.to_string()),
            kv("frames_in", s.frames_in.to_string()),
            kv("frames_out", s.frames_out.to_string()),
            kv("dropped", s.dropped.to_string()),
            kv("latency_p50_ms", format!("{:.2}", s.latency_p50_ms)),
            kv("latency_p99_ms", format!("{:.2}", s.latency_p99_ms)),
        ];
        if let Some(c) = s.camera_state {
            values.push(kv("camera_state", c.to_string()));
        }
        let message = match s.camera_state {
            Some(c) => format!(
                "{}; source {}; camera {}",
                s.estimate_status, s.source_state, c
            ),
            None => format!("{}; source {}", s.estimate_status, s.source_state),
        };
        let mut status = vec![DiagnosticStatus {
            level: Self::level(s.estimate_status),
            name: format!("{}: pipeline", self.node_name),
            message,
            hardware_id: s.hardware_id.to_string(),
            values,
        }];
        if let Some(g) = guidance {
            status.push(self.guidance_status(g, s.hardware_id));
        }
        Ok(DiagnosticArray {
            header: Header {
                stamp: Time::from_nanos(now_ns)?,
                frame_id: String::new(),
            },
            status,
        })
    }

    /// `sensor_msgs/Image` of a frame (copied: the message owns its bytes), in the camera's
    /// frame (`image_frame_id`).
    pub fn image(&self, view: &ImageView, capture_ns: u64) -> Result<Image, TimeRangeError> {
        Ok(Image {
            header: Header {
                stamp: Time::from_nanos(capture_ns)?,
                frame_id: self.image_frame_id.clone(),
            },
            height: view.height,
            width: view.width,
            encoding: view.format.ros_encoding().to_string(),
            is_bigendian: 0,
            step: view.width * view.format.bytes_per_pixel() as u32,
            data: view.data.to_vec(),
        })
    }
}

/// Decides which frames go out on `image_raw`: at most `rate_hz` per second of capture time.
#[derive(Debug, Clone)]
pub struct ImageThrottle {
    period_ns: Option<u64>,
    last_ns: Option<u64>,
}

impl ImageThrottle {
    /// `rate_hz` ≤ 0 lets no frame through.
    pub fn new(rate_hz: f64) -> ImageThrottle {
        let period_ns = (rate_hz > 0.0 && rate_hz.is_finite()).then(|| (1e9 / rate_hz) as u64);
        ImageThrottle {
            period_ns,
            last_ns: None,
        }
    }

    /// Whether the frame captured at `capture_ns` is due; if so, it counts as sent. A clock
    /// that goes backwards (a replay that loops) restarts the schedule.
    pub fn due(&mut self, capture_ns: u64) -> bool {
        let Some(period) = self.period_ns else {
            return false;
        };
        let due = match self.last_ns {
            None => true,
            Some(last) => capture_ns < last || capture_ns - last >= period,
        };
        if due {
            self.last_ns = Some(capture_ns);
        }
        due
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::PixelFormat;
    use nalgebra::Vector3 as V3;
    use proptest::prelude::*;

    fn rows_dir_in_robot(q: &Quaternion) -> V3<f64> {
        let uq = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q.w, q.x, q.y, q.z));
        // R maps robot to rows frame; the rows' x axis seen from the robot is Rᵀ x̂.
        uq.inverse() * V3::x()
    }

    fn est(h: Option<f64>, t: Option<f64>, q: f64) -> RosEstimate<'static> {
        RosEstimate {
            capture_ns: 1_700_000_000_250_000_000,
            heading_rad: h,
            tilt_rad: t,
            quality: q,
            status: "ok",
            guidance: None,
        }
    }

    #[test]
    fn zero_heading_and_tilt_is_the_identity() {
        let a = RowAttitude::from_heading_tilt(0.0, 0.0);
        assert_eq!((a.yaw_rad, a.pitch_rad), (0.0, 0.0));
        assert!((a.quaternion.w - 1.0).abs() < 1e-15);
    }

    #[test]
    fn rows_to_the_left_mean_the_robot_is_yawed_right_of_them() {
        let a = RowAttitude::from_heading_tilt(0.1, 0.0);
        assert!((a.yaw_rad + 0.1).abs() < 1e-12, "{a:?}");
        assert!(a.pitch_rad.abs() < 1e-12);
        // Pure yaw: z component carries it, sin(-0.05).
        assert!((a.quaternion.z - (-0.05f64).sin()).abs() < 1e-12);
        assert!(a.quaternion.x.abs() < 1e-15 && a.quaternion.y.abs() < 1e-15);
    }

    #[test]
    fn rows_seen_above_the_horizon_mean_the_nose_is_down() {
        let a = RowAttitude::from_heading_tilt(0.0, 0.05);
        assert!((a.pitch_rad - 0.05).abs() < 1e-12, "{a:?}");
        assert!((a.quaternion.y - 0.025f64.sin()).abs() < 1e-12);
    }

    proptest! {
        #[test]
        fn the_quaternion_reproduces_the_row_direction(
            h in -3.1f64..3.1, t in -1.2f64..1.2
        ) {
            let a = RowAttitude::from_heading_tilt(h, t);
            let d = rows_dir_in_robot(&a.quaternion);
            let want = V3::new(t.cos() * h.cos(), t.cos() * h.sin(), t.sin());
            // Equal up to the free sign of the row direction.
            let err = (d - want).norm().min((d + want).norm());
            prop_assert!(err < 1e-9, "h {} t {} got {:?} want {:?}", h, t, d, want);
            let q = a.quaternion;
            prop_assert!(((q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w) - 1.0).abs() < 1e-12);
            // Folded into the forward half: |yaw| <= 90°, and roll is zero.
            prop_assert!(a.yaw_rad.abs() <= PI / 2.0 + 1e-12);
            // Away from gimbal lock (pitch ±90°), ZYX angles read back as published.
            if a.pitch_rad.abs() < 1.4 {
                let uq = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q.w, q.x, q.y, q.z));
                let (roll, pitch, yaw) = uq.euler_angles();
                prop_assert!(roll.abs() < 1e-9);
                prop_assert!((pitch - a.pitch_rad).abs() < 1e-9);
                prop_assert!((yaw - a.yaw_rad).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn imu_carries_stamp_frame_covariance_and_absent_markers() {
        let b = MessageBuilder::new(&Ros2Config::default());
        let imu = b.imu(&est(Some(0.2), Some(-0.03), 0.5)).unwrap().unwrap();
        assert_eq!(imu.header.frame_id, "base_link");
        assert_eq!(imu.header.stamp.sec, 1_700_000_000);
        assert_eq!(imu.header.stamp.nanosec, 250_000_000);
        let sigma = 1.0f64.to_radians() / 0.5;
        assert_eq!(imu.orientation_covariance[0], UNOBSERVED_VARIANCE);
        assert!((imu.orientation_covariance[4] - sigma * sigma).abs() < 1e-15);
        assert!((imu.orientation_covariance[8] - sigma * sigma).abs() < 1e-15);
        for i in [1, 2, 3, 5, 6, 7] {
            assert_eq!(imu.orientation_covariance[i], 0.0);
        }
        assert_eq!(imu.angular_velocity_covariance[0], -1.0);
        assert_eq!(imu.linear_acceleration_covariance[0], -1.0);
        let d = rows_dir_in_robot(&imu.orientation);
        assert!((d.y.atan2(d.x) - 0.2).abs() < 1e-9);
    }

    #[test]
    fn covariance_grows_as_quality_falls_and_is_capped() {
        let b = MessageBuilder::new(&Ros2Config::default());
        let s1 = b.sigma_rad(1.0);
        assert!((s1 - 1.0f64.to_radians()).abs() < 1e-15);
        assert!(b.sigma_rad(0.25) > b.sigma_rad(0.5));
        assert_eq!(b.sigma_rad(0.0), b.sigma_rad(MIN_QUALITY));
        assert_eq!(b.sigma_rad(f64::NAN), b.sigma_rad(MIN_QUALITY));
        assert_eq!(b.sigma_rad(7.0), s1);
    }

    #[test]
    fn no_estimate_publishes_no_orientation() {
        let b = MessageBuilder::new(&Ros2Config::default());
        for (h, t) in [(None, None), (Some(0.1), None), (None, Some(0.1))] {
            assert_eq!(b.imu(&est(h, t, 0.0)).unwrap(), None);
            assert_eq!(b.heading_tilt(&est(h, t, 0.0)).unwrap(), None);
        }
    }

    #[test]
    fn heading_tilt_is_raw_heading_tilt_quality() {
        let b = MessageBuilder::new(&Ros2Config::default());
        let v = b
            .heading_tilt(&est(Some(-0.4), Some(0.02), 0.8))
            .unwrap()
            .unwrap();
        assert_eq!((v.vector.x, v.vector.y, v.vector.z), (-0.4, 0.02, 0.8));
        assert_eq!(v.header.stamp.nanosec, 250_000_000);
    }

    #[test]
    fn stamps_past_2038_are_errors_not_wraparounds() {
        let b = MessageBuilder::new(&Ros2Config::default());
        let mut e = est(Some(0.0), Some(0.0), 1.0);
        e.capture_ns = u64::MAX;
        assert!(b.imu(&e).is_err());
        assert!(b.heading_tilt(&e).is_err());
    }

    #[test]
    fn diagnostics_level_and_values() {
        let b = MessageBuilder::new(&Ros2Config::default());
        let s = RosStatus {
            frames_in: 100,
            frames_out: 97,
            dropped: 3,
            latency_p50_ms: 12.345,
            latency_p99_ms: 28.0,
            estimate_status: "camera_lost",
            source_state: "reconnecting",
            camera_state: Some("lost"),
            hardware_id: "Prosilica GC2450C 02-2131A",
        };
        let d = b.diagnostics(&s, None, 5_000_000_001).unwrap();
        assert_eq!(d.status.len(), 1, "no guidance, no guidance status");
        assert_eq!(d.header.stamp, Time { sec: 5, nanosec: 1 });
        let st = &d.status[0];
        assert_eq!(st.level, DiagnosticStatus::ERROR);
        assert_eq!(st.name, "omnirow: pipeline");
        assert_eq!(st.hardware_id, "Prosilica GC2450C 02-2131A");
        let get = |k: &str| {
            st.values
                .iter()
                .find(|kv| kv.key == k)
                .map(|kv| kv.value.as_str())
        };
        assert_eq!(get("frames_in"), Some("100"));
        assert_eq!(get("frames_out"), Some("97"));
        assert_eq!(get("dropped"), Some("3"));
        assert_eq!(get("latency_p50_ms"), Some("12.35"));
        assert_eq!(get("camera_state"), Some("lost"));
        assert_eq!(get("source_state"), Some("reconnecting"));
        assert_eq!(MessageBuilder::level("ok"), DiagnosticStatus::OK);
        assert_eq!(MessageBuilder::level("no_rows"), DiagnosticStatus::WARN);
        assert_eq!(MessageBuilder::level("degraded"), DiagnosticStatus::WARN);
        let replay = RosStatus {
            camera_state: None,
            ..s
        };
        let d = b.diagnostics(&replay, None, 0).unwrap();
        assert!(d.status[0].values.iter().all(|kv| kv.key != "camera_state"));
    }

    #[test]
    fn image_copies_pixels_with_encoding_and_step() {
        let b = MessageBuilder::new(&Ros2Config::default());
        let data: Vec<u8> = (0..24).collect();
        let view = ImageView::new(4, 2, PixelFormat::Rgb8, &data).unwrap();
        let img = b.image(&view, 1_000_000_123).unwrap();
        assert_eq!((img.width, img.height, img.step), (4, 2, 12));
        assert_eq!(img.encoding, "rgb8");
        assert_eq!(img.data, data);
        assert_eq!(
            img.header.stamp,
            Time {
                sec: 1,
                nanosec: 123
            }
        );
    }

    #[test]
    fn image_throttle_follows_capture_time() {
        let mut off = ImageThrottle::new(0.0);
        assert!(!off.due(0));
        let mut t = ImageThrottle::new(2.0); // every 500 ms
        let ms = 1_000_000u64;
        let sent: Vec<u64> = (0..20u64)
            .map(|i| 1_000 * ms + i * 100 * ms)
            .filter(|&ns| t.due(ns))
            .collect();
        assert_eq!(sent, vec![1_000 * ms, 1_500 * ms, 2_000 * ms, 2_500 * ms]);
        // A replay that starts over is sent at once.
        assert!(t.due(1_000 * ms));
    }
}
