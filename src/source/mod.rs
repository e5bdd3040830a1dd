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
/// `start + (t - t0) / speed`. A looping replay's next pass starts one recorded frame
/// interval after the last frame of the pass before ([`Pacer::next_pass`]), so that the
/// frame rate holds across the seam.
#[derive(Debug, Clone)]
pub struct Pacer {
    rate: Rate,
    base: Option<(Instant, u64)>,
    /// The last frame's recorded time and due time.
    last: Option<(u64, Instant)>,
    /// The last interval between two frames, recorded nanoseconds.
    interval_ns: u64,
    /// When the next pass's first frame is due.
    carry: Option<Instant>,
}

impl Pacer {
    pub fn new(rate: Rate) -> Self {
        Pacer {
            rate,
            base: None,
            last: None,
            interval_ns: 0,
            carry: None,
        }
    }

    /// Restarts the clock at the next frame: the next pass of a looping replay, whose
    /// first frame is due one recorded frame interval after the last one of this pass.
    pub fn next_pass(&mut self) {
        self.base = None;
        let speed = match self.rate {
            Rate::Recorded(s) => s,
            Rate::Max => return,
        };
        self.carry = self
            .last
            .take()
            .map(|(_, due)| due + Duration::from_secs_f64(self.interval_ns as f64 / 1e9 / speed));
    }

    /// How long until the frame recorded at `t_ns` is due (zero if due now).
    pub fn wait_for(&mut self, t_ns: u64) -> Duration {
        self.wait_at(t_ns, Instant::now())
    }

    /// [`Self::wait_for`] with the clock read as `now`.
    fn wait_at(&mut self, t_ns: u64, now: Instant) -> Duration {
        let Rate::Recorded(speed) = self.rate else {
            return Duration::ZERO;
        };
        let (start, t0) = *self
            .base
            .get_or_insert((self.carry.take().unwrap_or(now), t_ns));
        // Time going backwards in a recording: play the frame at once and rebase.
        if t_ns < t0 {
            self.base = Some((now, t_ns));
            self.last = Some((t_ns, now));
            return Duration::ZERO;
        }
        let due = start + Duration::from_secs_f64((t_ns - t0) as f64 / 1e9 / speed);
        if let Some((t_last, _)) = self.last {
            if t_ns > t_last {
                self.interval_ns = t_ns - t_last;
            }
        }
        self.last = Some((t_ns, due));
        due.saturating_duration_since(now)
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

    #[test]
    fn a_looping_replay_keeps_its_frame_rate_across_the_seam() {
        let ms = |m: u64| m * 1_000_000;
        let t0 = Instant::now();
        let at = |m: u64| t0 + Duration::from_millis(m);
        let mut p = Pacer::new(Rate::Recorded(1.0));
        // one pass of three frames 40 ms apart, each played when due: at 0, 40 and 80 ms
        assert_eq!(p.wait_at(ms(100), at(0)), Duration::ZERO);
        assert_eq!(p.wait_at(ms(140), at(0)), Duration::from_millis(40));
        assert_eq!(p.wait_at(ms(180), at(40)), Duration::from_millis(40));
        // the next pass read at once: its first frame is due one interval after the last
        p.next_pass();
        assert_eq!(p.wait_at(ms(100), at(80)), Duration::from_millis(40));
        assert_eq!(p.wait_at(ms(140), at(120)), Duration::from_millis(40));
        // read late, a frame is due at once
        assert_eq!(p.wait_at(ms(180), at(500)), Duration::ZERO);
        // as fast as possible: nothing waits
        let mut p = Pacer::new(Rate::Max);
        p.wait_at(ms(100), at(0));
        p.next_pass();
        assert_eq!(p.wait_at(ms(100), at(0)), Duration::ZERO);
    }
}
