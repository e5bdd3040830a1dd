//! The Prometheus text exposition (format 0.0.4) of the pipeline's state, served on the HTTP
//! service's `/metrics`: counters, gauges and latency summaries, one family per metric with
//! its `# HELP` and `# TYPE` lines. Checked against the Prometheus project's own parser in
//! tests/http_service.rs. Also owns [`TrackingCounts`], the guidance's tracking-state changes
//! counted on every published estimate by the [`TrackingCounter`] publisher (the HTTP service
//! only sees the latest estimate, which would miss changes between two scrapes).

use super::{PublishError, Publisher};
use crate::estimate::Estimate;
use crate::frame::Frame;
use crate::guidance::TrackState;
use crate::source::SourceState;
use crate::status::Shared;
use std::sync::atomic::{AtomicU64, AtomicU8, Ordering};
use std::sync::Arc;

/// The guidance's tracking states, in the order of [`TrackingCounts`]' counters.
const TRACK_STATES: [TrackState; 4] = [
    TrackState::Tracking,
    TrackState::Coasting,
    TrackState::Lost,
    TrackState::Reacquired,
];

/// No state seen yet.
const NO_STATE: u8 = u8::MAX;

/// How often the guidance's tracking state changed, by the state it changed to. Written by
/// one [`TrackingCounter`], read by any number of `/metrics` requests.
#[derive(Debug)]
pub struct TrackingCounts {
    last: AtomicU8,
    entered: [AtomicU64; 4],
}

impl Default for TrackingCounts {
    fn default() -> Self {
        TrackingCounts {
            last: AtomicU8::new(NO_STATE),
            entered: Default::default(),
        }
    }
}

impl TrackingCounts {
    /// Folds in one published estimate: a change of its guidance's tracking state from the
    /// previous estimate's is counted (the first state seen is not a change). Estimates
    /// without guidance (e.g. `camera_lost`) leave the state as it was.
    pub fn observe(&self, e: &Estimate) {
        let Some(g) = &e.guidance else {
            return;
        };
        let Some(i) = TRACK_STATES.iter().position(|s| *s == g.tracking) else {
            return;
        };
        let previous = self.last.swap(i as u8, Ordering::Relaxed);
        if previous != NO_STATE && previous as usize != i {
            self.entered[i].fetch_add(1, Ordering::Relaxed);
        }
    }

    /// The changes into each state so far.
    pub fn changes(&self) -> [(TrackState, u64); 4] {
        std::array::from_fn(|i| (TRACK_STATES[i], self.entered[i].load(Ordering::Relaxed)))
    }
}

/// The publisher that counts the tracking-state changes for `/metrics`.
pub struct TrackingCounter(pub Arc<TrackingCounts>);

impl Publisher for TrackingCounter {
    fn name(&self) -> &str {
        "tracking-counter"
    }

    fn publish(&mut self, e: &Estimate, _frame: Option<&Arc<Frame>>) -> Result<(), PublishError> {
        self.0.observe(e);
        Ok(())
    }
}

/// A sample value as the exposition format spells it (`NaN`, `+Inf`, `-Inf`, or a number).
fn sample_value(v: f64) -> String {
    if v.is_nan() {
        "NaN".into()
    } else if v == f64::INFINITY {
        "+Inf".into()
    } else if v == f64::NEG_INFINITY {
        "-Inf".into()
    } else {
        v.to_string()
    }
}

/// The Prometheus text exposition of the pipeline's state and of the guidance's tracking
/// `changes`.
pub fn metrics(shared: &Shared, changes: &TrackingCounts) -> String {
    use std::fmt::Write as _;
    let s = shared.status();
    let mut m = String::new();
    let mut metric = |name: &str, kind: &str, help: &str, lines: &[(String, f64)]| {
        let _ = writeln!(m, "# HELP {name} {help}");
        let _ = writeln!(m, "# TYPE {name} {kind}");
        for (labels, v) in lines {
            let _ = writeln!(m, "{name}{labels} {}", sample_value(*v));
        }
    };
    let plain = |v: f64| vec![(String::new(), v)];
    metric(
        "omnirow_frames_in_total",
        "counter",
        "Frames delivered by the source.",
        &plain(s.frames_in as f64),
    );
    metric(
        "omnirow_frames_out_total",
        "counter",
        "Estimates published for frames.",
        &plain(s.frames_out as f64),
    );
    metric(
        "omnirow_frames_dropped_total",
        "counter",
        "Frames dropped because the detector was busy (oldest first).",
        &plain(s.dropped as f64),
    );
    metric(
        "omnirow_record_dropped_total",
        "counter",
        "Frames or estimates the recorder dropped because the disk was busy.",
        &plain(s.record_dropped as f64),
    );
    metric(
        "omnirow_recorded_frames_total",
        "counter",
        "Frames written to recordings.",
        &plain(s.recorded_frames as f64),
    );
    metric(
        "omnirow_detector_errors_total",
        "counter",
        "Frames the detector failed on.",
        &plain(s.detector_errors as f64),
    );
    metric(
        "omnirow_frames_per_second",
        "gauge",
        "Estimates published per second over the last status interval.",
        &plain(s.fps_out),
    );
    metric(
        "omnirow_detector_ms",
        "summary",
        "Detector time per frame over the last 1024 frames, milliseconds.",
        &[
            ("{quantile=\"0.5\"}".into(), s.detector_p50_ms),
            ("{quantile=\"0.99\"}".into(), s.detector_p99_ms),
        ],
    );
    metric(
        "omnirow_latency_ms",
        "summary",
        "End-to-end latency (frame received to estimate published) over the last 1024 frames, milliseconds.",
        &[
            ("{quantile=\"0.5\"}".into(), s.latency_p50_ms),
            ("{quantile=\"0.99\"}".into(), s.latency_p99_ms),
        ],
    );
    let stages: Vec<(String, f64)> = crate::estimate::STAGES
        .iter()
        .enumerate()
        .flat_map(|(i, name)| {
            [
                (
                    format!("{{stage=\"{name}\",quantile=\"0.5\"}}"),
                    s.stage_p50_ms[i],
                ),
                (
                    format!("{{stage=\"{name}\",quantile=\"0.99\"}}"),
                    s.stage_p99_ms[i],
                ),
            ]
        })
        .collect();
    metric(
        "omnirow_stage_ms",
        "summary",
        "Each stage's time per frame over the last 1024 frames, milliseconds: the detector's preparation, its method's rows, the vote for the vanishing point with the method's finish, and the rows' fit on the ground.",
        &stages,
    );
    let states = [
        SourceState::Starting,
        SourceState::Streaming,
        SourceState::Lost,
        SourceState::Ended,
    ];
    metric(
        "omnirow_source_state",
        "gauge",
        "The source's state (1 for the current one).",
        &states
            .iter()
            .map(|st| {
                (
                    format!("{{state=\"{}\"}}", st.name()),
                    f64::from(u8::from(*st == s.source_state)),
                )
            })
            .collect::<Vec<_>>(),
    );
    metric(
        "omnirow_pipeline_alive",
        "gauge",
        "1 while every pipeline thread is looping.",
        &plain(f64::from(u8::from(shared.alive()))),
    );
    metric(
        "omnirow_recording",
        "gauge",
        "1 while a recording is being written.",
        &plain(f64::from(u8::from(s.recording.starts_with("recording")))),
    );
    metric(
        "omnirow_recording_failed",
        "gauge",
        "1 when the recording failed or stopped at the disk reserve (detection goes on).",
        &plain(f64::from(u8::from(
            s.recording.starts_with("failed") || s.recording.starts_with("stopped"),
        ))),
    );
    metric(
        "omnirow_estimates_total",
        "counter",
        "Estimates published, by status.",
        &s.status_counts
            .iter()
            .map(|(k, v)| (format!("{{status=\"{k}\"}}"), *v as f64))
            .collect::<Vec<_>>(),
    );
    if let Some(l) = shared.latest() {
        let e = &l.estimate;
        let opt = |v: Option<f64>| v.unwrap_or(f64::NAN);
        metric(
            "omnirow_heading_rad",
            "gauge",
            "Heading of the rows in the latest estimate (NaN without one).",
            &plain(opt(e.heading_rad)),
        );
        metric(
            "omnirow_tilt_rad",
            "gauge",
            "Tilt of the rows in the latest estimate (NaN without one).",
            &plain(opt(e.tilt_rad)),
        );
        metric(
            "omnirow_quality",
            "gauge",
            "Quality of the latest estimate.",
            &plain(e.quality),
        );
        metric(
            "omnirow_last_seq",
            "gauge",
            "Sequence number of the latest published frame.",
            &plain(e.seq as f64),
        );
        if let Some(g) = &e.guidance {
            metric(
                "omnirow_guidance_tracking",
                "gauge",
                "The guidance's tracking state in the latest estimate (1 for the current one).",
                &TRACK_STATES
                    .iter()
                    .map(|st| {
                        (
                            format!("{{state=\"{}\"}}", st.name()),
                            f64::from(u8::from(*st == g.tracking)),
                        )
                    })
                    .collect::<Vec<_>>(),
            );
            for (name, help, v) in [
                (
                    "omnirow_guidance_lateral_offset_m",
                    "Lateral offset of the tool point from the followed line, metres, positive to the left (NaN when lost).",
                    g.lateral_offset_m,
                ),
                (
                    "omnirow_guidance_heading_error_rad",
                    "Heading of the rows in the robot frame (the guidance's heading_rad), radians, counter-clockwise (NaN when lost).",
                    g.heading_rad,
                ),
                (
                    "omnirow_guidance_row_spacing_m",
                    "Row spacing, metres (NaN when lost).",
                    g.row_spacing_m,
                ),
                (
                    "omnirow_guidance_curvature_per_m",
                    "Curvature of the followed line, 1/m, positive to the left (NaN when lost).",
                    g.curvature_per_m,
                ),
                (
                    "omnirow_guidance_row_index",
                    "Index of the followed line relative to the line nearest the tool point (NaN when lost).",
                    g.row_index.map(|i| i as f64),
                ),
            ] {
                metric(name, "gauge", help, &plain(opt(v)));
            }
        }
    }
    metric(
        "omnirow_guidance_state_changes_total",
        "counter",
        "Changes of the guidance's tracking state, by the state changed to.",
        &changes
            .changes()
            .iter()
            .map(|(st, n)| (format!("{{to=\"{}\"}}", st.name()), *n as f64))
            .collect::<Vec<_>>(),
    );
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    fn estimate(tracking: Option<TrackState>) -> Estimate {
        let mut e: Estimate = serde_json::from_value(serde_json::json!({
            "schema_version": 2, "seq": 1, "capture_ns": 0, "receive_ns": 0, "publish_ns": 0,
            "latency_ms": 1.0, "detector_ms": 1.0, "status": "ok", "heading_rad": 0.0,
            "tilt_rad": 0.0, "vanishing_point": [1.0, 0.0, 0.0], "rows": [], "quality": 0.5
        }))
        .unwrap();
        e.guidance = tracking.map(|t| crate::guidance::GuidanceEstimate {
            tracking: t,
            ..Default::default()
        });
        e
    }

    #[test]
    fn tracking_changes_are_counted_by_the_state_entered() {
        use TrackState::*;
        let c = TrackingCounts::default();
        for t in [
            Some(Lost),
            Some(Lost),
            Some(Reacquired),
            Some(Tracking),
            None, // camera_lost: no guidance, no change
            Some(Tracking),
            Some(Coasting),
            Some(Tracking),
            Some(Coasting),
            Some(Lost),
        ] {
            c.observe(&estimate(t));
        }
        assert_eq!(
            c.changes(),
            [(Tracking, 2), (Coasting, 2), (Lost, 1), (Reacquired, 1)]
        );
    }

    #[test]
    fn special_values_are_spelled_as_prometheus_reads_them() {
        assert_eq!(sample_value(f64::NAN), "NaN");
        assert_eq!(sample_value(f64::INFINITY), "+Inf");
        assert_eq!(sample_value(f64::NEG_INFINITY), "-Inf");
        assert_eq!(sample_value(12.0), "12");
        assert_eq!(sample_value(0.25), "0.25");
    }
}
