//! The Prometheus text exposition (format 0.0.4) of the pipeline's state, served on the HTTP
//! service's `/metrics`: counters, gauges and latency summaries, one family per metric with
//! its `# HELP` and `# TYPE` lines. Checked against the Prometheus project's own parser in
//! tests/http_service.rs.

use crate::source::SourceState;
use crate::status::Shared;

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

/// The Prometheus text exposition of the pipeline's state.
pub fn metrics(shared: &Shared) -> String {
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
    }
    m
}

#[cfg(test)]
mod tests {
    use super::sample_value;

    #[test]
    fn special_values_are_spelled_as_prometheus_reads_them() {
        assert_eq!(sample_value(f64::NAN), "NaN");
        assert_eq!(sample_value(f64::INFINITY), "+Inf");
        assert_eq!(sample_value(f64::NEG_INFINITY), "-Inf");
        assert_eq!(sample_value(12.0), "12");
        assert_eq!(sample_value(0.25), "0.25");
    }
}
