//! omnirow's node ↔ ROS 2: the mapping from the pipeline's [`Estimate`] and
//! [`StatusSummary`] onto [`RosEstimate`] and [`RosStatus`], and the ROS 2 publisher as one more
//! [`Publisher`] of the node's publisher thread.
//!
//! Owns [`node_publisher`], the one call the node makes: `None` when `[ros2] enabled = false`,
//! an error naming the cause when ROS 2 is wanted but cannot be had (bad config, DDS setup
//! failure, or a build without the `ros2` feature).

use super::config::Ros2Config;
use super::error::Ros2Error;
use super::input::{RosEstimate, RosGuidance, RosStatus, TrackedRow};
use crate::estimate::Estimate;
use crate::guidance::{GuidanceEstimate, Mode, OdometryFeed};
use crate::publish::Publisher;
use crate::status::StatusSummary;
use std::sync::Arc;

impl<'a> From<&'a Estimate> for RosEstimate<'a> {
    fn from(e: &'a Estimate) -> Self {
        RosEstimate {
            capture_ns: e.capture_ns,
            heading_rad: e.heading_rad,
            tilt_rad: e.tilt_rad,
            quality: e.quality,
            status: e.status.name(),
            guidance: e.guidance.as_ref().map(RosGuidance::from),
        }
    }
}

/// The tracked part of the guidance: all of it or, when lost, none.
fn tracked(g: &GuidanceEstimate) -> Option<TrackedRow> {
    Some(TrackedRow {
        lateral_offset_m: g.lateral_offset_m?,
        heading_rad: g.heading_rad?,
        curvature_per_m: g.curvature_per_m?,
        row_spacing_m: g.row_spacing_m?,
        row_index: g.row_index?,
        covariance: g.covariance?,
    })
}

fn mode_name(m: Mode) -> &'static str {
    match m {
        Mode::BetweenRows => "between_rows",
        Mode::OverRow => "over_row",
    }
}

impl<'a> From<&'a GuidanceEstimate> for RosGuidance<'a> {
    fn from(g: &'a GuidanceEstimate) -> Self {
        RosGuidance {
            tracking: g.tracking.name(),
            mode: mode_name(g.mode),
            tracked: tracked(g),
            roll_rad: g.roll_rad,
            end_of_row_m: g.end_of_row_m,
            crop: g.crop.name(),
            warnings: &g.warnings,
        }
    }
}

/// The latest frame's guidance, kept for the once-a-second `/diagnostics` (its warnings'
/// buffer reused: keeping it allocates nothing once warmed up).
#[cfg(feature = "ros2")]
#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct LatestGuidance {
    present: bool,
    tracking: &'static str,
    mode: &'static str,
    tracked: Option<TrackedRow>,
    roll_rad: Option<f64>,
    end_of_row_m: Option<f64>,
    crop: &'static str,
    warnings: Vec<crate::guidance::Warning>,
}

#[cfg(feature = "ros2")]
impl LatestGuidance {
    pub(super) fn set(&mut self, g: Option<&GuidanceEstimate>) {
        self.present = g.is_some();
        self.warnings.clear();
        if let Some(g) = g {
            self.tracking = g.tracking.name();
            self.mode = mode_name(g.mode);
            self.tracked = tracked(g);
            self.roll_rad = g.roll_rad;
            self.end_of_row_m = g.end_of_row_m;
            self.crop = g.crop.name();
            self.warnings.extend_from_slice(&g.warnings);
        }
    }

    pub(super) fn get(&self) -> Option<RosGuidance<'_>> {
        self.present.then_some(RosGuidance {
            tracking: self.tracking,
            mode: self.mode,
            tracked: self.tracked,
            roll_rad: self.roll_rad,
            end_of_row_m: self.end_of_row_m,
            crop: self.crop,
            warnings: &self.warnings,
        })
    }
}

impl<'a> RosStatus<'a> {
    /// The pipeline's summary, with the latest estimate's status and the source's identity
    /// (which the summary does not carry). `camera_state` stays `None`: the summary's
    /// source state already says `camera_lost` when a camera goes away.
    pub fn from_summary(
        s: &'a StatusSummary,
        estimate_status: &'a str,
        hardware_id: &'a str,
    ) -> RosStatus<'a> {
        RosStatus {
            frames_in: s.frames_in,
            frames_out: s.frames_out,
            dropped: s.dropped,
            latency_p50_ms: s.latency_p50_ms,
            latency_p99_ms: s.latency_p99_ms,
            estimate_status,
            source_state: s.source_state.name(),
            camera_state: None,
            hardware_id,
        }
    }
}

/// The ROS 2 publisher for the node's publisher list, or `None` when `[ros2]` is disabled.
/// `hardware_id` names the source in `/diagnostics` (camera model and serial, recording);
/// `tool_point_m` is the row guidance's (`[guidance] tool_point_m`; `[0, 0]` without
/// guidance), from which `row_pose` moves the offset to base_link. With `odometry` (row
/// guidance reads it) and `odometry_topic` configured, the node subscribes to odometry there.
pub fn node_publisher(
    config: &Ros2Config,
    hardware_id: &str,
    tool_point_m: [f64; 2],
    odometry: Option<Arc<OdometryFeed>>,
) -> Result<Option<Box<dyn Publisher>>, Ros2Error> {
    if !config.enabled {
        return Ok(None);
    }
    config.validate()?;
    build(config, hardware_id, tool_point_m, odometry)
}

#[cfg(not(feature = "ros2"))]
fn build(
    _: &Ros2Config,
    _: &str,
    _: [f64; 2],
    _: Option<Arc<OdometryFeed>>,
) -> Result<Option<Box<dyn Publisher>>, Ros2Error> {
    Err(Ros2Error::NotBuilt)
}

#[cfg(feature = "ros2")]
fn build(
    config: &Ros2Config,
    hardware_id: &str,
    tool_point_m: [f64; 2],
    odometry: Option<Arc<OdometryFeed>>,
) -> Result<Option<Box<dyn Publisher>>, Ros2Error> {
    let mut inner = super::Ros2Publisher::new(config)?;
    inner.set_tool_point(tool_point_m);
    if let Some(feed) = odometry {
        inner.subscribe_odometry(config, feed)?;
    }
    Ok(Some(Box::new(with_feature::NodePublisher {
        inner,
        hardware_id: hardware_id.to_string(),
        last_status: "starting",
        guidance: LatestGuidance::default(),
    })))
}

#[cfg(feature = "ros2")]
mod with_feature {
    use super::*;
    use crate::frame::Frame;
    use crate::publish::PublishError;
    use std::sync::Arc;

    /// [`super::super::Ros2Publisher`] driven by the pipeline's publisher thread.
    pub(super) struct NodePublisher {
        pub(super) inner: super::super::Ros2Publisher,
        pub(super) hardware_id: String,
        /// Status and guidance of the latest estimate, for `/diagnostics`.
        pub(super) last_status: &'static str,
        pub(super) guidance: LatestGuidance,
    }

    fn err(e: impl std::fmt::Display) -> PublishError {
        PublishError::Io {
            what: "ROS 2".to_string(),
            source: std::io::Error::other(e.to_string()),
        }
    }

    impl Publisher for NodePublisher {
        fn name(&self) -> &str {
            "ros2"
        }

        fn publish(
            &mut self,
            estimate: &Estimate,
            frame: Option<&Arc<Frame>>,
        ) -> Result<(), PublishError> {
            self.last_status = estimate.status.name();
            self.guidance.set(estimate.guidance.as_ref());
            self.inner
                .publish_estimate(&RosEstimate::from(estimate))
                .map_err(err)?;
            if let Some(f) = frame {
                let view = f.view().map_err(err)?;
                self.inner.publish_frame(&view, f.capture_ns).map_err(err)?;
            }
            Ok(())
        }

        fn status(&mut self, status: &StatusSummary) {
            let s = RosStatus::from_summary(status, self.last_status, &self.hardware_id);
            if let Err(e) = self.inner.publish_status(&s, self.guidance.get().as_ref()) {
                tracing::warn!("ROS 2 diagnostics: {e}");
            }
        }

        fn finish(&mut self) {
            tracing::info!(counts = ?self.inner.counts(), "ROS 2 publisher done");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::Status;
    use crate::frame::{Frame, PixelFormat};
    use crate::source::SourceState;

    #[test]
    fn estimate_maps_field_for_field() {
        let f = Frame {
            seq: 3,
            capture_ns: 1_700_000_000_000_000_123,
            receive_ns: 0,
            width: 1,
            height: 1,
            format: PixelFormat::Mono8,
            data: vec![0],
            truth: None,
        };
        let mut e = Estimate::empty(&f, Status::Degraded);
        e.heading_rad = Some(0.25);
        e.tilt_rad = Some(-0.01);
        e.quality = 0.4;
        let r = RosEstimate::from(&e);
        assert_eq!(r.capture_ns, 1_700_000_000_000_000_123);
        assert_eq!(
            (r.heading_rad, r.tilt_rad, r.quality),
            (Some(0.25), Some(-0.01), 0.4)
        );
        assert_eq!(r.status, "degraded");
        assert_eq!(r.guidance, None);
    }

    #[test]
    fn guidance_maps_whole_or_not_at_all() {
        use crate::guidance::{TrackState, Warning};
        let mut g = GuidanceEstimate {
            mode: Mode::OverRow,
            tracking: TrackState::Coasting,
            lateral_offset_m: Some(0.07),
            heading_rad: Some(-0.01),
            curvature_per_m: Some(0.002),
            row_spacing_m: Some(0.75),
            row_index: Some(-1),
            covariance: Some([
                [1e-4, 0.0, 0.0, 0.0],
                [0.0, 2e-6, 0.0, 0.0],
                [0.0; 4],
                [0.0; 4],
            ]),
            roll_rad: Some(0.01),
            warnings: vec![Warning::RowsTilted],
            ..GuidanceEstimate::default()
        };
        let r = RosGuidance::from(&g);
        assert_eq!((r.tracking, r.mode), ("coasting", "over_row"));
        let t = r.tracked.unwrap();
        assert_eq!(
            (
                t.lateral_offset_m,
                t.heading_rad,
                t.curvature_per_m,
                t.row_spacing_m,
                t.row_index
            ),
            (0.07, -0.01, 0.002, 0.75, -1)
        );
        assert_eq!(t.covariance[1][1], 2e-6);
        assert_eq!(r.roll_rad, Some(0.01));
        assert_eq!(r.warnings, &[Warning::RowsTilted]);

        #[cfg(feature = "ros2")]
        {
            let mut latest = LatestGuidance::default();
            assert_eq!(latest.get(), None);
            latest.set(Some(&g));
            assert_eq!(latest.get(), Some(r));
            latest.set(None);
            assert_eq!(latest.get(), None);
        }
        // lost: nothing tracked, even if a field were left behind
        g.tracking = TrackState::Lost;
        g.covariance = None;
        let r = RosGuidance::from(&g);
        assert_eq!((r.tracking, r.tracked), ("lost", None));
    }

    #[test]
    fn summary_maps_onto_the_diagnostics_input() {
        let s = StatusSummary {
            uptime_s: 1.0,
            frames_in: 10,
            frames_out: 8,
            dropped: 2,
            record_dropped: 0,
            detector_errors: 0,
            fps_in: 15.0,
            fps_out: 15.0,
            detector_p50_ms: 5.0,
            detector_p99_ms: 9.0,
            latency_p50_ms: 11.0,
            latency_p99_ms: 21.0,
            stage_p50_ms: [1.0; 4],
            stage_p99_ms: [2.0; 4],
            source_state: SourceState::Lost,
            recording: String::new(),
            recorded_frames: 0,
            status_counts: Default::default(),
        };
        let r = RosStatus::from_summary(&s, "camera_lost", "GC2450C 42");
        assert_eq!((r.frames_in, r.frames_out, r.dropped), (10, 8, 2));
        assert_eq!((r.latency_p50_ms, r.latency_p99_ms), (11.0, 21.0));
        assert_eq!(r.source_state, "camera_lost");
        assert_eq!(r.estimate_status, "camera_lost");
        assert_eq!(r.hardware_id, "GC2450C 42");
    }

    #[test]
    fn disabled_gives_no_publisher_and_a_bad_config_an_error() {
        let off = Ros2Config::default();
        assert!(node_publisher(&off, "x", [0.0; 2], None).unwrap().is_none());
        let bad = Ros2Config {
            enabled: true,
            namespace: "no_slash".into(),
            ..Ros2Config::default()
        };
        let e = node_publisher(&bad, "x", [0.0; 2], None).err().unwrap();
        assert!(e.to_string().contains("ros2.namespace"), "{e}");
    }

    #[cfg(not(feature = "ros2"))]
    #[test]
    fn enabled_without_the_feature_says_how_to_build_it() {
        let on = Ros2Config {
            enabled: true,
            ..Ros2Config::default()
        };
        let e = node_publisher(&on, "x", [0.0; 2], None).err().unwrap();
        assert!(e.to_string().contains("--features ros2"), "{e}");
    }
}
