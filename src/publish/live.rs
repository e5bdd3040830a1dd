//! What the live view reads: the `/status` document (the pipeline's summary with the latest
//! estimate), the `/history.json` document (the estimates of the last minute, sampled by the
//! HTTP service) and the page itself (`web/live.html`, embedded in the binary: the page loads
//! nothing from elsewhere). Schemas in docs/http.md.

use crate::estimate::{Estimate, Status};
use crate::status::{Shared, StatusSummary};
use serde::Serialize;
use std::collections::VecDeque;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// The live view: HTML, CSS and script in one file.
pub const PAGE: &str = include_str!("web/live.html");

/// The version of the `/status` and `/history.json` schemas. Bumped on any incompatible change.
pub const STATUS_SCHEMA_VERSION: u32 = 1;

/// The `/status` document.
#[derive(Debug, Clone, Serialize)]
pub struct StatusDocument {
    /// [`STATUS_SCHEMA_VERSION`].
    pub schema_version: u32,
    /// What `/healthz` answers: the pipeline is alive and the source is starting or streaming.
    pub healthy: bool,
    pub pipeline_alive: bool,
    /// The pipeline's summary, its fields at the top level.
    #[serde(flatten)]
    pub summary: StatusSummary,
    /// The latest estimate computed from a frame (`null` before the first).
    pub latest: Option<Estimate>,
}

impl StatusDocument {
    /// The document now.
    pub fn now(shared: &Shared) -> Self {
        let summary = shared.status();
        let alive = shared.alive();
        let healthy = alive
            && matches!(
                summary.source_state,
                crate::source::SourceState::Streaming | crate::source::SourceState::Starting
            );
        StatusDocument {
            schema_version: STATUS_SCHEMA_VERSION,
            healthy,
            pipeline_alive: alive,
            summary,
            latest: shared.latest().map(|l| l.estimate.clone()),
        }
    }
}

/// One sampled estimate.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HistoryPoint {
    /// When it was sampled, seconds on the history's clock (see [`HistoryDocument::now_s`]).
    pub t_s: f64,
    pub seq: u64,
    pub status: Status,
    pub heading_rad: Option<f64>,
    pub tilt_rad: Option<f64>,
    pub quality: f64,
    /// The guidance's lateral offset from the followed row, metres (`null` without guidance).
    pub lateral_offset_m: Option<f64>,
}

/// The `/history.json` document.
#[derive(Debug, Clone, Serialize)]
pub struct HistoryDocument {
    /// [`STATUS_SCHEMA_VERSION`].
    pub schema_version: u32,
    /// Now on the history's clock (seconds since the HTTP service started): a point's age is
    /// `now_s - t_s`.
    pub now_s: f64,
    /// How far back the points go, seconds.
    pub window_s: f64,
    /// Oldest first; one per new frame at each sampling tick.
    pub points: Vec<HistoryPoint>,
}

/// The latest estimates of the last `window`, sampled from the pipeline's shared state.
pub struct History {
    started: Instant,
    window: Duration,
    points: Mutex<VecDeque<HistoryPoint>>,
}

impl History {
    pub fn new(window: Duration) -> Self {
        History {
            started: Instant::now(),
            window,
            points: Mutex::new(VecDeque::new()),
        }
    }

    /// Records the latest estimate if it is new, and forgets the points older than the window.
    pub fn sample(&self, shared: &Shared) {
        let Some(e) = shared.latest().map(|l| l.estimate.clone()) else {
            return;
        };
        self.push(&e, self.started.elapsed().as_secs_f64());
    }

    fn push(&self, e: &Estimate, t_s: f64) {
        let mut points = self.points.lock().unwrap_or_else(|p| p.into_inner());
        if points.back().is_some_and(|p| p.seq == e.seq) {
            return;
        }
        points.push_back(HistoryPoint {
            t_s,
            seq: e.seq,
            status: e.status,
            heading_rad: e.heading_rad,
            tilt_rad: e.tilt_rad,
            quality: e.quality,
            lateral_offset_m: e.guidance.as_ref().and_then(|g| g.lateral_offset_m),
        });
        let oldest = t_s - self.window.as_secs_f64();
        while points.front().is_some_and(|p| p.t_s < oldest) {
            points.pop_front();
        }
    }

    /// The document now.
    pub fn document(&self) -> HistoryDocument {
        let points = self.points.lock().unwrap_or_else(|p| p.into_inner());
        HistoryDocument {
            schema_version: STATUS_SCHEMA_VERSION,
            now_s: self.started.elapsed().as_secs_f64(),
            window_s: self.window.as_secs_f64(),
            points: points.iter().cloned().collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn estimate(seq: u64, heading: f64) -> Estimate {
        let mut e: Estimate = serde_json::from_value(serde_json::json!({
            "schema_version": 1, "seq": seq, "capture_ns": 0, "receive_ns": 0, "publish_ns": 0,
            "latency_ms": 1.0, "detector_ms": 1.0, "status": "ok", "heading_rad": heading,
            "tilt_rad": 0.1, "vanishing_point": [1.0, 0.0, 0.0], "rows": [], "quality": 0.5
        }))
        .unwrap();
        e.seq = seq;
        e
    }

    #[test]
    fn history_keeps_one_point_per_frame_within_the_window() {
        let h = History::new(Duration::from_secs(60));
        h.push(&estimate(1, 0.1), 0.0);
        h.push(&estimate(1, 0.1), 0.2); // same frame: not again
        h.push(&estimate(2, 0.2), 30.0);
        h.push(&estimate(3, 0.3), 61.0); // the first is now older than 60 s
        let p = h.points.lock().unwrap();
        let seqs: Vec<u64> = p.iter().map(|p| p.seq).collect();
        assert_eq!(seqs, [2, 3]);
        assert_eq!(p[1].heading_rad, Some(0.3));
        assert_eq!(p[1].status, Status::Ok);
    }
}
