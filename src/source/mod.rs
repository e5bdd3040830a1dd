//! Frame sources: where the node's frames come from.
//!
//! Owns the [`Source`] abstraction the pipeline's source thread drives — replay of MCAP
//! recordings ([`mcap_replay`]), replay of image folders ([`folder`]), the synthetic drive
//! ([`synthetic`]), and the camera ([`gige`], feature `camera`) — the replay [`Pacer`]
//! (recorded rate, a multiple of it, or as fast as possible), and the `[source]` and
//! `[camera]` sections of the configuration ([`SourceConfig`], [`CalibrationChoice`]). A source never blocks longer than the timeout it is given,
//! so the pipeline can always stop it and report its state.

mod config;
pub mod folder;
#[cfg(feature = "camera")]
pub mod gige;
pub mod mcap_replay;
pub mod synthetic;

pub use config::{CalibrationChoice, ReplayConfig, SourceConfig};
pub(crate) use config::{RawCamera, RawSource};

use crate::frame::Frame;
use std::time::{Duration, Instant};

/// Errors of a source.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    #[error("{path}: {source}")]
    Io {
        path: std::path::PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {problem}")]
    Invalid {
        path: std::path::PathBuf,
        problem: String,
    },
    #[error("{0}")]
    Other(String),
}

/// What a [`Source::poll`] returns.
#[derive(Debug)]
pub enum Poll {
    /// A frame. Its `receive_ns` is stamped by the pipeline when it arrives, unless the
    /// source set it (a camera stamps the buffer's arrival from the network).
    Frame(Frame),
    /// No frame within the timeout (not yet due, or the camera is silent); see [`Source::state`].
    Idle,
    /// The source has no more frames (end of a replay that does not loop).
    End,
}

/// The state of a source, as reported in the status and to systemd.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SourceState {
    /// Opened, no frame delivered yet.
    Starting,
    /// Delivering frames.
    Streaming,
    /// The camera is gone (reconnecting); estimates say `camera_lost`.
    Lost,
    /// No more frames.
    Ended,
}

impl SourceState {
    pub fn name(self) -> &'static str {
        match self {
            SourceState::Starting => "starting",
            SourceState::Streaming => "streaming",
            SourceState::Lost => "camera_lost",
            SourceState::Ended => "ended",
        }
    }
}

/// A source of frames, driven by the pipeline's source thread.
pub trait Source: Send {
    /// A short description for logs (kind and path or device).
    fn describe(&self) -> String;
    /// The next frame, waiting at most `timeout` for it. Frames carry `seq` and `capture_ns`.
    fn poll(&mut self, timeout: Duration) -> Result<Poll, SourceError>;
    /// The source's state now.
    fn state(&self) -> SourceState;
    /// True (the default) for sources that run on their own clock (a camera, a paced replay):
    /// when the pipeline falls behind, their oldest queued frames are dropped. False for
    /// replays as fast as possible: the pipeline then waits for the detector instead, and
    /// every frame is processed.
    fn realtime(&self) -> bool {
        true
    }
    /// The calibration the frames go with, when the source knows it (the synthetic lens, a
    /// recording's attached calibration); the configuration may override it.
    fn calibration(&self) -> Option<&crate::camera::Calibration> {
        None
    }
    /// Where the pipeline gives back the pixel buffers of frames it is done with, for sources
    /// that reuse them (the camera's preallocated pool, so steady state allocates nothing).
    /// None (the default): finished buffers are freed.
    fn recycler(&self) -> Option<crate::gige::Recycler> {
        None
    }
}

/// How fast a replay runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rate {
    /// At the recorded rate times this factor (1.0 = as recorded).
    Recorded(f64),
    /// As fast as the pipeline takes frames.
    Max,
}

/// Paces replayed frames: a frame recorded at time `t` is due at wall time
/// `start + (t - t0) / speed`.
#[derive(Debug, Clone)]
pub struct Pacer {
    rate: Rate,
    base: Option<(Instant, u64)>,
}

impl Pacer {
    pub fn new(rate: Rate) -> Self {
        Pacer { rate, base: None }
    }

    /// Restarts the clock (e.g. when a replay loops).
    pub fn reset(&mut self) {
        self.base = None;
    }

    /// How long until the frame recorded at `t_ns` is due (zero if due now).
    pub fn wait_for(&mut self, t_ns: u64) -> Duration {
        let Rate::Recorded(speed) = self.rate else {
            return Duration::ZERO;
        };
        let (start, t0) = *self.base.get_or_insert((Instant::now(), t_ns));
        // Time going backwards in a recording: play the frame at once and rebase.
        if t_ns < t0 {
            self.base = Some((Instant::now(), t_ns));
            return Duration::ZERO;
        }
        let due = start + Duration::from_secs_f64((t_ns - t0) as f64 / 1e9 / speed);
        due.saturating_duration_since(Instant::now())
    }
}

/// Sleeps until a pending frame is due or the timeout passes; true when the frame is due.
pub(crate) fn wait_due(pacer: &mut Pacer, t_ns: u64, timeout: Duration) -> bool {
    let wait = pacer.wait_for(t_ns);
    if wait <= timeout {
        std::thread::sleep(wait);
        true
    } else {
        std::thread::sleep(timeout);
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pacer_recorded_and_max() {
        let mut p = Pacer::new(Rate::Max);
        assert_eq!(p.wait_for(5), Duration::ZERO);
        assert_eq!(p.wait_for(5_000_000_000), Duration::ZERO);
        let mut p = Pacer::new(Rate::Recorded(2.0));
        assert_eq!(p.wait_for(1_000_000_000), Duration::ZERO);
        let w = p.wait_for(2_000_000_000);
        assert!(
            w > Duration::from_millis(400) && w <= Duration::from_millis(500),
            "{w:?}"
        );
        // Backwards time rebases instead of waiting.
        assert_eq!(p.wait_for(10), Duration::ZERO);
    }
}
