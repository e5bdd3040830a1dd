//! omnirow's node ↔ ROS 2: the mapping from the pipeline's [`Estimate`] and
//! [`StatusSummary`] onto [`RosEstimate`] and [`RosStatus`], and the ROS 2 publisher as one more
//! [`Publisher`] of the node's publisher thread.
//!
//! Owns [`node_publisher`], the one call the node makes: `None` when `[ros2] enabled = false`,
//! an error naming the cause when ROS 2 is wanted but cannot be had (bad config, DDS setup
//! failure, or a build without the `ros2` feature).

use super::config::Ros2Config;
use super::error::Ros2Error;
use super::input::{RosEstimate, RosStatus};
use crate::estimate::Estimate;
use crate::publish::Publisher;
use crate::status::StatusSummary;

impl<'a> From<&'a Estimate> for RosEstimate<'a> {
    fn from(e: &'a Estimate) -> Self {
        RosEstimate {
            capture_ns: e.capture_ns,
            heading_rad: e.heading_rad,
            tilt_rad: e.tilt_rad,
            quality: e.quality,
            status: e.status.name(),
        }
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
/// `hardware_id` names the source in `/diagnostics` (camera model and serial, recording).
pub fn node_publisher(
    config: &Ros2Config,
    hardware_id: &str,
) -> Result<Option<Box<dyn Publisher>>, Ros2Error> {
    if !config.enabled {
        return Ok(None);
    }
    config.validate()?;
    build(config, hardware_id)
}

#[cfg(not(feature = "ros2"))]
fn build(_: &Ros2Config, _: &str) -> Result<Option<Box<dyn Publisher>>, Ros2Error> {
    Err(Ros2Error::NotBuilt)
}

#[cfg(feature = "ros2")]
fn build(config: &Ros2Config, hardware_id: &str) -> Result<Option<Box<dyn Publisher>>, Ros2Error> {
    Ok(Some(Box::new(with_feature::NodePublisher {
        inner: super::Ros2Publisher::new(config)?,
        hardware_id: hardware_id.to_string(),
        last_status: "starting",
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
        /// Status of the latest estimate, for `/diagnostics`.
        pub(super) last_status: &'static str,
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
            if let Err(e) = self.inner.publish_status(&s) {
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
        assert!(node_publisher(&off, "x").unwrap().is_none());
        let bad = Ros2Config {
            enabled: true,
            namespace: "no_slash".into(),
            ..Ros2Config::default()
        };
        let e = node_publisher(&bad, "x").err().unwrap();
        assert!(e.to_string().contains("ros2.namespace"), "{e}");
    }

    #[cfg(not(feature = "ros2"))]
    #[test]
    fn enabled_without_the_feature_says_how_to_build_it() {
        let on = Ros2Config {
            enabled: true,
            ..Ros2Config::default()
        };
        let e = node_publisher(&on, "x").err().unwrap();
        assert!(e.to_string().contains("--features ros2"), "{e}");
    }
}
