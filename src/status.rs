//! The running node's status: what the pipeline threads report and the monitors read.
//!
//! Owns [`Shared`] — frame counters, drop counters, detector and latency samples, the source's
//! state, the recording's state, the latest published frame and each thread's heartbeat —
//! and the [`StatusSummary`] built from it once a second for the log, the publishers, the
//! HTTP endpoint and systemd. The pipeline writes it (through the crate-internal counting
//! methods); everything else only reads it.

use crate::detect::Detection;
use crate::estimate::{Estimate, Status};
use crate::frame::Frame;
use crate::source::SourceState;
use std::collections::{BTreeMap, VecDeque};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The status summary: once a second in the log, to the publishers, on /metrics.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StatusSummary {
    pub uptime_s: f64,
    pub frames_in: u64,
    pub frames_out: u64,
    /// Frames dropped by the drop-oldest policy (detector too slow).
    pub dropped: u64,
    /// Frames or estimates the recorder dropped (disk too slow).
    pub record_dropped: u64,
    pub detector_errors: u64,
    /// Frames per second in and out over the last status interval.
    pub fps_in: f64,
    pub fps_out: f64,
    /// Detector time per frame over the last 1024 frames, milliseconds.
    pub detector_p50_ms: f64,
    pub detector_p99_ms: f64,
    /// End-to-end latency (receive → publish) over the last 1024 frames, milliseconds.
    pub latency_p50_ms: f64,
    pub latency_p99_ms: f64,
    /// Each stage's time per frame ([`crate::estimate::STAGES`]) over the last 1024 frames,
    /// milliseconds.
    pub stage_p50_ms: [f64; 4],
    pub stage_p99_ms: [f64; 4],
    pub source_state: SourceState,
    pub recording: String,
    pub recorded_frames: u64,
    /// Estimates published per status since the start.
    pub status_counts: BTreeMap<String, u64>,
}

/// The latest published frame with its detection (for /overlay.png).
#[derive(Debug, Clone)]
pub struct Latest {
    pub frame: Arc<Frame>,
    pub detection: Detection,
    pub estimate: Estimate,
}

/// State shared by the pipeline threads and read by the monitors (HTTP, systemd).
pub struct Shared {
    started: Instant,
    stop: AtomicBool,
    frames_in: AtomicU64,
    frames_out: AtomicU64,
    dropped: AtomicU64,
    record_dropped: AtomicU64,
    detector_errors: AtomicU64,
    recorded_frames: AtomicU64,
    source_state: Mutex<SourceState>,
    recording: Mutex<String>,
    samples: Mutex<Samples>,
    latest: Mutex<Option<Arc<Latest>>>,
    /// Last loop time of each thread, ns since `started` (0 = finished).
    heartbeats: Mutex<Vec<(&'static str, u64)>>,
    rates: Mutex<Rates>,
    source_error: Mutex<Option<String>>,
}

#[derive(Default)]
struct Samples {
    detector_ms: VecDeque<f64>,
    latency_ms: VecDeque<f64>,
    stage_ms: [VecDeque<f64>; 4],
    status_counts: BTreeMap<String, u64>,
}

struct Rates {
    at: Instant,
    frames_in: u64,
    frames_out: u64,
    fps_in: f64,
    fps_out: f64,
}

const SAMPLE_WINDOW: usize = 1024;
/// A thread that has not looped for this long counts as stuck.
const STUCK_AFTER: Duration = Duration::from_secs(5);

/// The `p` quantile of `sorted` (ascending); 0 when empty.
fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let i = ((p * (sorted.len() - 1) as f64).round() as usize).min(sorted.len() - 1);
    sorted[i]
}

/// `v` sorted ascending.
fn sorted(mut v: Vec<f64>) -> Vec<f64> {
    v.sort_by(f64::total_cmp);
    v
}

/// Locks a mutex, recovering the data if a thread panicked while holding it.
fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// One pipeline thread's entry among the heartbeats: it beats once per loop and retires when
/// it finishes. A thread that panics never retires, so it soon counts as stuck.
pub(crate) struct Heartbeat {
    shared: Arc<Shared>,
    id: usize,
}

impl Heartbeat {
    pub(crate) fn beat(&self) {
        let t = self.shared.elapsed_ns().max(1);
        lock(&self.shared.heartbeats)[self.id].1 = t;
    }

    pub(crate) fn retire(self) {
        lock(&self.shared.heartbeats)[self.id].1 = 0;
    }

    /// The status the thread reports to.
    pub(crate) fn shared(&self) -> &Shared {
        &self.shared
    }
}

impl Default for Shared {
    fn default() -> Self {
        Self::new()
    }
}

impl Shared {
    /// A status with no thread registered and no frame yet (the pipeline makes its own; the
    /// HTTP fuzz target serves one).
    pub fn new() -> Self {
        let now = Instant::now();
        Shared {
            started: now,
            stop: AtomicBool::new(false),
            frames_in: AtomicU64::new(0),
            frames_out: AtomicU64::new(0),
            dropped: AtomicU64::new(0),
            record_dropped: AtomicU64::new(0),
            detector_errors: AtomicU64::new(0),
            recorded_frames: AtomicU64::new(0),
            source_state: Mutex::new(SourceState::Starting),
            recording: Mutex::new("off".into()),
            samples: Mutex::new(Samples::default()),
            latest: Mutex::new(None),
            heartbeats: Mutex::new(Vec::new()),
            rates: Mutex::new(Rates {
                at: now,
                frames_in: 0,
                frames_out: 0,
                fps_in: 0.0,
                fps_out: 0.0,
            }),
            source_error: Mutex::new(None),
        }
    }

    /// Adds a thread to the heartbeats (it counts as alive from now on).
    pub(crate) fn register(self: &Arc<Self>, name: &'static str) -> Heartbeat {
        let mut h = lock(&self.heartbeats);
        h.push((name, self.elapsed_ns().max(1)));
        Heartbeat {
            shared: self.clone(),
            id: h.len() - 1,
        }
    }

    fn elapsed_ns(&self) -> u64 {
        self.started.elapsed().as_nanos() as u64
    }

    /// Asks the source to stop; the pipeline then drains and finishes.
    pub fn request_stop(&self) {
        self.stop.store(true, Ordering::SeqCst);
    }

    pub fn stop_requested(&self) -> bool {
        self.stop.load(Ordering::SeqCst)
    }

    /// True while every pipeline thread that is still running loops (none is stuck; threads
    /// that finished do not count).
    pub fn alive(&self) -> bool {
        let now = self.elapsed_ns();
        let h = lock(&self.heartbeats);
        !h.is_empty()
            && h.iter()
                .all(|&(_, t)| t == 0 || now.saturating_sub(t) < STUCK_AFTER.as_nanos() as u64)
    }

    /// The names of the threads that are stuck (for the log).
    pub fn stuck_threads(&self) -> Vec<&'static str> {
        let now = self.elapsed_ns();
        lock(&self.heartbeats)
            .iter()
            .filter(|&&(_, t)| t != 0 && now.saturating_sub(t) >= STUCK_AFTER.as_nanos() as u64)
            .map(|&(n, _)| n)
            .collect()
    }

    pub fn frames_in(&self) -> u64 {
        self.frames_in.load(Ordering::Relaxed)
    }

    pub fn source_state(&self) -> SourceState {
        *lock(&self.source_state)
    }

    /// The error the source stopped with, if it failed.
    pub fn source_error(&self) -> Option<String> {
        lock(&self.source_error).clone()
    }

    /// The latest published frame, shared: a reader holds the lock only to clone a pointer
    /// (the readers are the HTTP service's low-priority threads; one preempted while it
    /// cloned rows under the lock would hold up the publisher).
    pub fn latest(&self) -> Option<Arc<Latest>> {
        lock(&self.latest).clone()
    }

    /// The status summary now (frame rates over the last status interval).
    pub fn status(&self) -> StatusSummary {
        let (fps_in, fps_out) = {
            let r = lock(&self.rates);
            (r.fps_in, r.fps_out)
        };
        // Copy the samples out and sort them after the lock is released: the readers are the
        // HTTP service's low-priority threads, and a reader preempted while it sorted under
        // the lock would hold up the publisher, which samples every frame.
        let (detector_ms, latency_ms, stage_ms, status_counts) = {
            let s = lock(&self.samples);
            (
                s.detector_ms.iter().copied().collect::<Vec<f64>>(),
                s.latency_ms.iter().copied().collect::<Vec<f64>>(),
                s.stage_ms
                    .clone()
                    .map(|v| v.into_iter().collect::<Vec<f64>>()),
                s.status_counts.clone(),
            )
        };
        let (detector_ms, latency_ms) = (sorted(detector_ms), sorted(latency_ms));
        let stage_ms = stage_ms.map(sorted);
        StatusSummary {
            uptime_s: self.started.elapsed().as_secs_f64(),
            frames_in: self.frames_in.load(Ordering::Relaxed),
            frames_out: self.frames_out.load(Ordering::Relaxed),
            dropped: self.dropped.load(Ordering::Relaxed),
            record_dropped: self.record_dropped.load(Ordering::Relaxed),
            detector_errors: self.detector_errors.load(Ordering::Relaxed),
            fps_in,
            fps_out,
            detector_p50_ms: percentile(&detector_ms, 0.5),
            detector_p99_ms: percentile(&detector_ms, 0.99),
            latency_p50_ms: percentile(&latency_ms, 0.5),
            latency_p99_ms: percentile(&latency_ms, 0.99),
            stage_p50_ms: std::array::from_fn(|i| percentile(&stage_ms[i], 0.5)),
            stage_p99_ms: std::array::from_fn(|i| percentile(&stage_ms[i], 0.99)),
            source_state: self.source_state(),
            recording: lock(&self.recording).clone(),
            recorded_frames: self.recorded_frames.load(Ordering::Relaxed),
            status_counts,
        }
    }

    /// Frame rates in and out since the last call.
    pub(crate) fn update_rates(&self) {
        let mut r = lock(&self.rates);
        let dt = r.at.elapsed().as_secs_f64();
        if dt <= 0.0 {
            return;
        }
        let fin = self.frames_in.load(Ordering::Relaxed);
        let fout = self.frames_out.load(Ordering::Relaxed);
        r.fps_in = (fin - r.frames_in) as f64 / dt;
        r.fps_out = (fout - r.frames_out) as f64 / dt;
        r.frames_in = fin;
        r.frames_out = fout;
        r.at = Instant::now();
    }

    // What the pipeline's threads report.

    pub(crate) fn set_source_state(&self, state: SourceState) {
        *lock(&self.source_state) = state;
    }

    /// The source thread finished: its state is `ended`, unless the camera was lost.
    pub(crate) fn source_ended(&self) {
        let mut st = lock(&self.source_state);
        if *st != SourceState::Lost {
            *st = SourceState::Ended;
        }
    }

    pub(crate) fn set_source_error(&self, error: String) {
        *lock(&self.source_error) = Some(error);
    }

    pub(crate) fn count_frame_in(&self) {
        self.frames_in.fetch_add(1, Ordering::Relaxed);
    }

    pub(crate) fn count_dropped(&self, n: u64) {
        self.dropped.fetch_add(n, Ordering::Relaxed);
    }

    pub(crate) fn count_record_dropped(&self, n: u64) {
        self.record_dropped.fetch_add(n, Ordering::Relaxed);
    }

    pub(crate) fn count_detector_error(&self) {
        self.detector_errors.fetch_add(1, Ordering::Relaxed);
    }

    /// An estimate of a frame was published: counts it and samples its timings.
    pub(crate) fn count_published(&self, e: &Estimate) {
        self.frames_out.fetch_add(1, Ordering::Relaxed);
        let mut s = lock(&self.samples);
        if s.detector_ms.len() == SAMPLE_WINDOW {
            s.detector_ms.pop_front();
            s.latency_ms.pop_front();
            for v in s.stage_ms.iter_mut() {
                v.pop_front();
            }
        }
        s.detector_ms.push_back(e.detector_ms);
        s.latency_ms.push_back(e.latency_ms);
        for (v, &ms) in s.stage_ms.iter_mut().zip(&e.stage_ms) {
            v.push_back(ms);
        }
        *s.status_counts
            .entry(e.status.name().to_string())
            .or_default() += 1;
    }

    /// An estimate without a frame (`camera_lost`) was published.
    pub(crate) fn count_status(&self, status: Status) {
        *lock(&self.samples)
            .status_counts
            .entry(status.name().to_string())
            .or_default() += 1;
    }

    /// Makes `latest` the latest published frame; returns the frame it replaces (for its
    /// buffer to go back to the source once no reader holds it).
    /// No reader holding the previous one (the usual case), its allocation is reused: the
    /// publisher allocates nothing here per frame.
    pub(crate) fn replace_latest(&self, latest: Latest) -> Option<Arc<Frame>> {
        let mut slot = lock(&self.latest);
        if let Some(previous) = slot.as_mut().and_then(Arc::get_mut) {
            let previous = std::mem::replace(previous, latest);
            drop(slot);
            return Some(previous.frame);
        }
        let previous = slot.replace(Arc::new(latest));
        drop(slot);
        previous.map(|p| p.frame.clone())
    }

    pub(crate) fn set_recording(&self, state: String) {
        *lock(&self.recording) = state;
    }

    pub(crate) fn set_recorded_frames(&self, n: u64) {
        self.recorded_frames.store(n, Ordering::Relaxed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::PixelFormat;

    fn latest(seq: u64) -> Latest {
        let frame = Frame {
            seq,
            capture_ns: seq,
            receive_ns: seq,
            width: 2,
            height: 1,
            format: PixelFormat::Mono8,
            data: vec![0, 0],
            truth: None,
        };
        Latest {
            estimate: Estimate::empty(&frame, Status::NoRows),
            frame: Arc::new(frame),
            detection: Detection::default(),
        }
    }

    #[test]
    fn replacing_the_latest_hands_back_the_previous_frame_whoever_reads_it() {
        let s = Shared::new();
        assert!(s.replace_latest(latest(1)).is_none());
        // no reader: the previous frame comes back, its slot reused
        assert_eq!(s.replace_latest(latest(2)).unwrap().seq, 1);
        // a reader holds frame 2: it keeps it, and the publisher still gets it back
        let held = s.latest().unwrap();
        assert_eq!(s.replace_latest(latest(3)).unwrap().seq, 2);
        assert_eq!(held.frame.seq, 2);
        assert_eq!(s.latest().unwrap().estimate.seq, 3);
    }
}
