//! From row guidance to ROS 2 messages: pure functions, no DDS.
//!
//! Owns [`RowPose`] (base_link's planar pose relative to the followed line, with the filter's
//! covariance carried through) and the messages built from it: `row_pose`
//! (`geometry_msgs/PoseWithCovarianceStamped` in the rows frame), `row_path` (`nav_msgs/Path`
//! of the followed line in base_link, bent by the tracked curvature), `row_offset` and
//! `row_heading_error` (`std_msgs/Float32`), and the `<node>: guidance` diagnostic status.
//!
//! Signs are REP 103's throughout (x forward, y left, yaw counter-clockwise seen from above):
//! the rows frame has x along the followed line in the direction of travel, y to its left and
//! its origin on the line abeam of base_link, so base_link's `y` is its offset (positive: left
//! of the line) and its yaw the heading error (positive: turned left of the rows, i.e. the
//! negative of the guidance's `heading_rad`, which is the rows' heading seen from the robot).
//! The guidance measures the offset at its tool point (`[guidance] tool_point_m`); the pose is
//! base_link's, moved from the tool point through the heading. ISOBUS equivalents: docs/ros2.md.

use super::convert::{MessageBuilder, UNOBSERVED_VARIANCE};
use super::input::{RosEstimate, RosGuidance, TrackedRow};
use super::msg::{
    DiagnosticStatus, Float32, Header, KeyValue, Path, Point, Pose, PoseStamped,
    PoseWithCovariance, PoseWithCovarianceStamped, Quaternion, Time, TimeRangeError,
};

/// base_link's pose relative to the followed line (planar: offset, yaw) and its covariance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RowPose {
    /// base_link's offset from the followed line, metres, positive when it is left of it.
    pub lateral_m: f64,
    /// base_link's yaw relative to the rows, radians, counter-clockwise (the heading error).
    pub yaw_rad: f64,
    /// Curvature of the followed line, 1/m, positive when it bends to the left.
    pub curvature_per_m: f64,
    /// Variances and covariance of (lateral_m, yaw_rad): m², m·rad, rad².
    pub var_lateral: f64,
    pub cov_lateral_yaw: f64,
    pub var_yaw: f64,
}

impl RowPose {
    /// From the tracker's estimate for the tool point at `tool_point_m` (base_link x, y).
    /// The tool sits at base_link + R(yaw)·tool, so base_link's offset is the tool's minus
    /// `sin(yaw)·tx + cos(yaw)·ty`; the covariance follows through that Jacobian.
    pub fn new(t: &TrackedRow, tool_point_m: [f64; 2]) -> RowPose {
        let yaw = -t.heading_rad;
        let [tx, ty] = tool_point_m;
        let (s, c) = yaw.sin_cos();
        let lateral = t.lateral_offset_m - (s * tx + c * ty);
        // d lateral / d yaw; d lateral / d offset = 1
        let j = -(c * tx - s * ty);
        let p = &t.covariance;
        // (offset, yaw) covariance: yaw = −heading flips the cross term.
        let (p_ee, p_ey, p_yy) = (p[0][0], -p[0][1], p[1][1]);
        RowPose {
            lateral_m: lateral,
            yaw_rad: yaw,
            curvature_per_m: t.curvature_per_m,
            var_lateral: p_ee + 2.0 * j * p_ey + j * j * p_yy,
            cov_lateral_yaw: p_ey + j * p_yy,
            var_yaw: p_yy,
        }
    }

    /// The followed line's point `s` metres along it from base_link's foot point, in
    /// base_link: (x, y, direction counter-clockwise from forward). The line is a circular
    /// arc of the tracked curvature (a straight line at curvature 0).
    pub fn line_point(&self, s: f64) -> [f64; 3] {
        let k = self.curvature_per_m;
        // In the rows frame: the arc from the origin, tangent to x.
        let (xr, yr) = if k == 0.0 {
            (s, 0.0)
        } else {
            // 2·sin²(ks/2)/k = (1 − cos ks)/k without the cancellation at small k·s.
            ((k * s).sin() / k, 2.0 * (k * s / 2.0).sin().powi(2) / k)
        };
        // base_link from the rows frame: rotate by −yaw about base_link's origin.
        let (sn, cs) = (-self.yaw_rad).sin_cos();
        let (dx, dy) = (xr, yr - self.lateral_m);
        [cs * dx - sn * dy, sn * dx + cs * dy, k * s - self.yaw_rad]
    }

    /// The 6×6 covariance of `geometry_msgs/PoseWithCovariance` (x, y, z, roll, pitch, yaw):
    /// y and yaw from the filter; x (along the rows), z, roll and pitch unobserved.
    pub fn covariance(&self) -> [f64; 36] {
        let mut c = [0.0; 36];
        for i in [0, 2, 3, 4] {
            c[i * 6 + i] = UNOBSERVED_VARIANCE;
        }
        c[6 + 1] = self.var_lateral;
        c[6 + 5] = self.cov_lateral_yaw;
        c[5 * 6 + 1] = self.cov_lateral_yaw;
        c[5 * 6 + 5] = self.var_yaw;
        c
    }
}

/// A rotation by `yaw` about z.
fn yaw_quaternion(yaw: f64) -> Quaternion {
    let (s, c) = (yaw / 2.0).sin_cos();
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: s,
        w: c,
    }
}

/// The diagnostic level of a tracking state: `coasting` WARN, `lost` ERROR, otherwise OK.
pub fn tracking_level(tracking: &str) -> u8 {
    match tracking {
        "tracking" | "reacquired" => DiagnosticStatus::OK,
        "coasting" => DiagnosticStatus::WARN,
        _ => DiagnosticStatus::ERROR,
    }
}

impl MessageBuilder {
    /// The tracked estimate of a frame, when it has one.
    fn tracked<'e>(e: &'e RosEstimate) -> Option<&'e TrackedRow> {
        e.guidance.as_ref()?.tracked.as_ref()
    }

    /// base_link's pose relative to the followed line, when the frame has a tracked estimate.
    pub fn row_pose_of(&self, e: &RosEstimate) -> Option<RowPose> {
        Self::tracked(e).map(|t| RowPose::new(t, self.tool_point_m))
    }

    /// `geometry_msgs/PoseWithCovarianceStamped` of base_link in the rows frame
    /// (`rows_frame_id`); `None` without a tracked estimate.
    pub fn row_pose(
        &self,
        e: &RosEstimate,
    ) -> Result<Option<PoseWithCovarianceStamped>, TimeRangeError> {
        let Some(r) = self.row_pose_of(e) else {
            return Ok(None);
        };
        Ok(Some(PoseWithCovarianceStamped {
            header: Header {
                stamp: Time::from_nanos(e.capture_ns)?,
                frame_id: self.rows_frame_id.clone(),
            },
            pose: PoseWithCovariance {
                pose: Pose {
                    position: Point {
                        x: 0.0,
                        y: r.lateral_m,
                        z: 0.0,
                    },
                    orientation: yaw_quaternion(r.yaw_rad),
                },
                covariance: r.covariance(),
            },
        }))
    }

    /// `nav_msgs/Path` of the followed line in base_link (`frame_id`): poses every
    /// `path_step_m` from abeam of base_link to `path_length_m` ahead, each facing along the
    /// line; `None` without a tracked estimate.
    pub fn row_path(&self, e: &RosEstimate) -> Result<Option<Path>, TimeRangeError> {
        let Some(r) = self.row_pose_of(e) else {
            return Ok(None);
        };
        let header = self.header(e.capture_ns)?;
        let n = (self.path_length_m / self.path_step_m + 1e-9).floor() as usize + 1;
        let poses = (0..n)
            .map(|i| {
                let [x, y, yaw] = r.line_point(i as f64 * self.path_step_m);
                PoseStamped {
                    header: header.clone(),
                    pose: Pose {
                        position: Point { x, y, z: 0.0 },
                        orientation: yaw_quaternion(yaw),
                    },
                }
            })
            .collect();
        Ok(Some(Path { header, poses }))
    }

    /// `row_offset` and `row_heading_error` (`std_msgs/Float32`): the tool point's offset from
    /// the followed line (metres, positive left of it) and the robot's yaw relative to the
    /// rows (radians, positive turned left). `None` without a tracked estimate: nothing is
    /// sent, so a controller's timeout sees the loss (a NaN would reach its arithmetic).
    pub fn row_follow(e: &RosEstimate) -> Option<(Float32, Float32)> {
        let t = Self::tracked(e)?;
        Some((
            Float32 {
                data: t.lateral_offset_m as f32,
            },
            Float32 {
                data: -t.heading_rad as f32,
            },
        ))
    }

    /// The `<node_name>: guidance` diagnostic status: level OK while tracking, WARN while
    /// coasting or with a configuration warning, ERROR when lost.
    pub fn guidance_status(&self, g: &RosGuidance, hardware_id: &str) -> DiagnosticStatus {
        let kv = |key: &str, value: String| KeyValue {
            key: key.to_string(),
            value,
        };
        let mut level = tracking_level(g.tracking);
        let mut values = vec![kv("tracking", g.tracking.to_string())];
        values.push(kv("mode", g.mode.to_string()));
        let mut message = g.tracking.to_string();
        if let Some(t) = &g.tracked {
            let r = RowPose::new(t, self.tool_point_m);
            values.extend([
                kv("lateral_offset_m", format!("{:.4}", t.lateral_offset_m)),
                kv(
                    "lateral_offset_sd_m",
                    format!("{:.4}", t.covariance[0][0].sqrt()),
                ),
                kv("heading_error_rad", format!("{:.5}", r.yaw_rad)),
                kv("curvature_per_m", format!("{:.5}", t.curvature_per_m)),
                kv("row_spacing_m", format!("{:.4}", t.row_spacing_m)),
                kv("row_index", t.row_index.to_string()),
            ]);
            message = format!(
                "{}; offset {:+.3} m; row {}; spacing {:.3} m",
                g.tracking, t.lateral_offset_m, t.row_index, t.row_spacing_m
            );
        } else {
            message.push_str("; no estimate");
        }
        let opt = |v: Option<f64>, digits: usize, none: &str| match v {
            Some(v) => format!("{v:.digits$}"),
            None => none.to_string(),
        };
        values.push(kv("roll_rad", opt(g.roll_rad, 5, "unobserved")));
        values.push(kv("end_of_row_m", opt(g.end_of_row_m, 2, "not seen")));
        values.push(kv("crop", g.crop.to_string()));
        if let Some(e) = g.end_of_row_m {
            message = format!("{message}; rows end {e:.1} m ahead");
        }
        if g.crop != "rows" {
            // an empty stretch or no crop in view: what the controller steers by is far
            // away, or nothing
            level = level.max(DiagnosticStatus::WARN);
            message = format!("{message}; crop: {}", g.crop);
        }
        let warnings: Vec<&str> = g.warnings.iter().map(|w| w.name()).collect();
        values.push(kv("warnings", warnings.join(",")));
        if !warnings.is_empty() {
            level = level.max(DiagnosticStatus::WARN);
            message = format!("{message}; check the mounting: {}", warnings.join(", "));
        }
        DiagnosticStatus {
            level,
            name: format!("{}: guidance", self.node_name),
            message,
            hardware_id: hardware_id.to_string(),
            values,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::guidance::Warning;
    use crate::ros2::Ros2Config;
    use proptest::prelude::*;

    fn tracked(offset: f64, heading: f64, curvature: f64) -> TrackedRow {
        TrackedRow {
            lateral_offset_m: offset,
            heading_rad: heading,
            curvature_per_m: curvature,
            row_spacing_m: 0.5,
            row_index: 0,
            covariance: [
                [4e-4, 1e-5, 0.0, 0.0],
                [1e-5, 9e-6, 0.0, 0.0],
                [0.0, 0.0, 1e-4, 0.0],
                [0.0, 0.0, 0.0, 1e-6],
            ],
        }
    }

    fn guidance(tracking: &'static str, t: Option<TrackedRow>) -> RosGuidance<'static> {
        RosGuidance {
            tracking,
            mode: "between_rows",
            tracked: t,
            roll_rad: None,
            end_of_row_m: None,
            crop: "rows",
            warnings: &[],
        }
    }

    fn est(g: Option<RosGuidance<'static>>) -> RosEstimate<'static> {
        RosEstimate {
            capture_ns: 1_700_000_000_500_000_000,
            heading_rad: Some(0.0),
            tilt_rad: Some(0.0),
            quality: 1.0,
            status: "ok",
            guidance: g,
        }
    }

    fn yaw_of(q: &Quaternion) -> f64 {
        (2.0 * (q.w * q.z + q.x * q.y)).atan2(1.0 - 2.0 * (q.y * q.y + q.z * q.z))
    }

    #[test]
    fn pose_is_offset_and_heading_error_in_the_rows_frame_with_the_filter_covariance() {
        let b = MessageBuilder::new(&Ros2Config::default());
        // left of the line by 4 cm, rows seen turned 0.02 rad to the right: robot turned left
        let e = est(Some(guidance("tracking", Some(tracked(0.04, -0.02, 0.0)))));
        let m = b.row_pose(&e).unwrap().unwrap();
        assert_eq!(m.header.frame_id, "rows");
        assert_eq!(m.header.stamp, Time::from_nanos(e.capture_ns).unwrap());
        let p = &m.pose.pose;
        assert_eq!((p.position.x, p.position.y, p.position.z), (0.0, 0.04, 0.0));
        assert!((yaw_of(&p.orientation) - 0.02).abs() < 1e-12);
        let c = &m.pose.covariance;
        assert_eq!(c[7], 4e-4);
        assert_eq!(c[35], 9e-6);
        assert_eq!(
            (c[11], c[31]),
            (-1e-5, -1e-5),
            "yaw = −heading flips the sign"
        );
        for i in [0, 2, 3, 4] {
            assert_eq!(c[i * 7], UNOBSERVED_VARIANCE);
        }
        let (off, head) = MessageBuilder::row_follow(&e).unwrap();
        assert_eq!((off.data, head.data), (0.04f32, 0.02f32));
    }

    #[test]
    fn the_covariance_is_the_filters_not_a_constant() {
        let b = MessageBuilder::new(&Ros2Config::default());
        let mut t = tracked(0.0, 0.0, 0.0);
        let small = b
            .row_pose(&est(Some(guidance("tracking", Some(t)))))
            .unwrap()
            .unwrap();
        t.covariance[0][0] = 1e-2;
        t.covariance[1][1] = 4e-4;
        let coasting = b
            .row_pose(&est(Some(guidance("coasting", Some(t)))))
            .unwrap()
            .unwrap();
        assert_eq!(coasting.pose.covariance[7], 1e-2);
        assert_eq!(coasting.pose.covariance[35], 4e-4);
        assert!(coasting.pose.covariance[7] > small.pose.covariance[7]);
    }

    #[test]
    fn nothing_without_a_tracked_estimate() {
        let b = MessageBuilder::new(&Ros2Config::default());
        for e in [est(None), est(Some(guidance("lost", None)))] {
            assert_eq!(b.row_pose(&e).unwrap(), None);
            assert_eq!(b.row_path(&e).unwrap(), None);
            assert_eq!(MessageBuilder::row_follow(&e), None);
        }
    }

    #[test]
    fn a_tool_point_moves_the_pose_to_base_link() {
        // tool 1 m behind base_link; robot turned left of the rows by 0.1 rad, the tool 5 cm
        // left of the line: base_link, ahead of the tool, is further left by sin(0.1).
        let b = MessageBuilder::new(&Ros2Config::default()).with_tool_point([-1.0, 0.0]);
        let e = est(Some(guidance("tracking", Some(tracked(0.05, -0.1, 0.0)))));
        let r = b.row_pose_of(&e).unwrap();
        assert!((r.lateral_m - (0.05 + 0.1f64.sin())).abs() < 1e-12, "{r:?}");
        // The covariance through the Jacobian: d lateral / d yaw = cos(0.1).
        let j = 0.1f64.cos();
        let want = 4e-4 + 2.0 * j * -1e-5 + j * j * 9e-6;
        assert!((r.var_lateral - want).abs() < 1e-15);
        assert!((r.cov_lateral_yaw - (-1e-5 + j * 9e-6)).abs() < 1e-15);
        // the row-follow pair stays the tool point's
        assert_eq!(MessageBuilder::row_follow(&e).unwrap().0.data, 0.05f32);
    }

    proptest! {
        /// The path's first pose lies on the followed line at the pose's offset and faces
        /// along it; with zero curvature every pose is on the same straight line; along the
        /// path the poses are `path_step_m` apart and turn by curvature × step.
        #[test]
        fn the_path_is_the_followed_line_in_base_link(
            off in -0.4f64..0.4, heading in -0.3f64..0.3, k in -0.05f64..0.05,
            tx in -1.0f64..1.0, ty in -0.3f64..0.3,
        ) {
            let b = MessageBuilder::new(&Ros2Config::default()).with_tool_point([tx, ty]);
            let e = est(Some(guidance("tracking", Some(tracked(off, heading, k)))));
            let r = b.row_pose_of(&e).unwrap();
            let path = b.row_path(&e).unwrap().unwrap();
            prop_assert_eq!(path.header.frame_id.as_str(), "base_link");
            prop_assert_eq!(path.poses.len(), 11);
            let p0 = &path.poses[0].pose;
            // The line's direction in base_link is the rows' heading.
            prop_assert!((yaw_of(&p0.orientation) - heading).abs() < 1e-9);
            // base_link's origin is `lateral_m` left of the line: the line point is at
            // distance |lateral| from the origin, to the right when lateral > 0.
            let (x0, y0) = (p0.position.x, p0.position.y);
            let left = -(heading.cos() * y0 - heading.sin() * x0);
            prop_assert!((left - r.lateral_m).abs() < 1e-9, "{} vs {}", left, r.lateral_m);
            prop_assert!((x0 * heading.cos() + y0 * heading.sin()).abs() < 1e-9);
            // The tool point is `off` left of the line, measured across it.
            let tool_left = -(heading.cos() * (y0 - ty) - heading.sin() * (x0 - tx));
            prop_assert!((tool_left - off).abs() < 1e-9);
            for w in path.poses.windows(2) {
                let (a, c) = (&w[0].pose, &w[1].pose);
                let d = ((c.position.x - a.position.x).powi(2)
                    + (c.position.y - a.position.y).powi(2)).sqrt();
                // chord of an arc of 0.5 m
                let chord = if k == 0.0 { 0.5 } else { 2.0 * (k * 0.25).sin() / k };
                prop_assert!((d - chord).abs() < 1e-9);
                let turn = yaw_of(&c.orientation) - yaw_of(&a.orientation);
                prop_assert!((turn - k * 0.5).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn a_left_bend_curves_the_path_to_the_left() {
        let b = MessageBuilder::new(&Ros2Config::default());
        let e = est(Some(guidance("tracking", Some(tracked(0.0, 0.0, 0.05)))));
        let path = b.row_path(&e).unwrap().unwrap();
        let last = &path.poses.last().unwrap().pose;
        // 5 m along a 20 m radius: y = R(1 − cos(s/R)) ≈ 0.62 m to the left.
        let want = 20.0 * (1.0 - 0.25f64.cos());
        assert!((last.position.y - want).abs() < 1e-9, "{last:?}");
        assert!((last.position.x - 20.0 * 0.25f64.sin()).abs() < 1e-9);
    }

    #[test]
    fn diagnostics_levels_follow_the_tracking_state_and_the_warnings() {
        let b = MessageBuilder::new(&Ros2Config::default());
        let mut g = guidance("tracking", Some(tracked(-0.031, 0.01, 0.002)));
        let s = b.guidance_status(&g, "cam 7");
        assert_eq!(s.level, DiagnosticStatus::OK);
        assert_eq!(s.name, "omnirow: guidance");
        assert_eq!(s.hardware_id, "cam 7");
        let get = |s: &DiagnosticStatus, k: &str| {
            s.values
                .iter()
                .find(|kv| kv.key == k)
                .map(|kv| kv.value.clone())
        };
        assert_eq!(get(&s, "tracking").as_deref(), Some("tracking"));
        assert_eq!(get(&s, "lateral_offset_m").as_deref(), Some("-0.0310"));
        assert_eq!(get(&s, "lateral_offset_sd_m").as_deref(), Some("0.0200"));
        assert_eq!(get(&s, "heading_error_rad").as_deref(), Some("-0.01000"));
        assert_eq!(get(&s, "row_spacing_m").as_deref(), Some("0.5000"));
        assert_eq!(get(&s, "row_index").as_deref(), Some("0"));
        assert_eq!(get(&s, "roll_rad").as_deref(), Some("unobserved"));
        assert_eq!(get(&s, "warnings").as_deref(), Some(""));
        assert_eq!(get(&s, "crop").as_deref(), Some("rows"));
        assert_eq!(get(&s, "end_of_row_m").as_deref(), Some("not seen"));
        assert!(s.message.contains("offset -0.031 m"), "{}", s.message);
        // the rows end ahead, then the robot is in an empty stretch: WARN, said in the message
        let mut g2 = g;
        g2.end_of_row_m = Some(3.1249);
        let s = b.guidance_status(&g2, "");
        assert_eq!(s.level, DiagnosticStatus::OK);
        assert_eq!(get(&s, "end_of_row_m").as_deref(), Some("3.12"));
        assert!(s.message.contains("rows end 3.1 m ahead"), "{}", s.message);
        g2.crop = "empty_stretch";
        let s = b.guidance_status(&g2, "");
        assert_eq!(s.level, DiagnosticStatus::WARN);
        assert_eq!(get(&s, "crop").as_deref(), Some("empty_stretch"));
        assert!(s.message.ends_with("crop: empty_stretch"), "{}", s.message);

        g.tracking = "coasting";
        assert_eq!(b.guidance_status(&g, "").level, DiagnosticStatus::WARN);
        g.tracking = "reacquired";
        g.roll_rad = Some(0.0123);
        let s = b.guidance_status(&g, "");
        assert_eq!(s.level, DiagnosticStatus::OK);
        assert_eq!(get(&s, "roll_rad").as_deref(), Some("0.01230"));
        g.warnings = &[Warning::SpacingDiffersFromConfigured];
        let s = b.guidance_status(&g, "");
        assert_eq!(s.level, DiagnosticStatus::WARN);
        assert_eq!(
            get(&s, "warnings").as_deref(),
            Some("spacing_differs_from_configured")
        );
        let lost = b.guidance_status(&guidance("lost", None), "");
        assert_eq!(lost.level, DiagnosticStatus::ERROR);
        assert!(get(&lost, "lateral_offset_m").is_none());
        assert_eq!(lost.message, "lost; no estimate");
    }
}
