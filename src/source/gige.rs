//! The GigE Vision camera as a pipeline [`Source`]: a thin adapter over
//! [`crate::gige::GigeSource`], whose acquisition thread does the work (configuration, buffer
//! pool, loss detection, reconnection). Frames cross a small channel; when the pipeline falls
//! behind, the newest frame is dropped there and counted in the camera's `dropped` counter.

use super::{Poll, Source, SourceError, SourceState};
use crate::frame::Frame;
use crate::gige::{
    CameraState, FrameSink, GigeConfig, GigeCounters, GigeError, GigeSource, OnConnect,
};
use crossbeam_channel::{Receiver, RecvTimeoutError};
use std::sync::Arc;
use std::time::Duration;

/// A camera source for the pipeline.
pub struct CameraSource {
    camera: GigeSource,
    rx: Receiver<Frame>,
    counters: Arc<GigeCounters>,
    name: String,
}

impl CameraSource {
    /// Starts acquisition with `cfg`; `queue` frames may wait for the pipeline (at least 1).
    /// Returns at once: the camera may still be connecting (state `starting`).
    pub fn start(cfg: GigeConfig, queue: usize) -> Result<Self, GigeError> {
        Self::start_with(cfg, queue, None)
    }

    /// [`CameraSource::start`] with a hook run on the camera after each (re)connection (see
    /// [`GigeSource::start_with`]).
    pub fn start_with(
        cfg: GigeConfig,
        queue: usize,
        on_connect: Option<OnConnect>,
    ) -> Result<Self, GigeError> {
        let name = match &cfg.camera {
            Some(c) => format!("GigE camera {c}"),
            None => "GigE camera (first found)".to_string(),
        };
        let (tx, rx) = crossbeam_channel::bounded(queue.max(1));
        let camera = GigeSource::start_with(cfg, FrameSink::Channel(tx), on_connect)?;
        let counters = camera.counters();
        Ok(CameraSource {
            camera,
            rx,
            counters,
            name,
        })
    }

    /// The camera's live counters (received, incomplete, missing, timeouts, reconnects, ...).
    pub fn counters(&self) -> Arc<GigeCounters> {
        self.counters.clone()
    }

    /// The underlying acquisition (session info, buffer recycler).
    pub fn camera(&self) -> &GigeSource {
        &self.camera
    }
}

impl Source for CameraSource {
    fn describe(&self) -> String {
        self.name.clone()
    }

    fn poll(&mut self, timeout: Duration) -> Result<Poll, SourceError> {
        match self.rx.recv_timeout(timeout) {
            Ok(f) => Ok(Poll::Frame(f)),
            Err(RecvTimeoutError::Timeout) => Ok(Poll::Idle),
            Err(RecvTimeoutError::Disconnected) => Err(SourceError::Other(format!(
                "{}: the acquisition thread ended",
                self.name
            ))),
        }
    }

    fn state(&self) -> SourceState {
        map_state(self.counters.state())
    }

    fn recycler(&self) -> Option<crate::gige::Recycler> {
        Some(self.camera.recycler())
    }
}

/// The pipeline's view of the camera state.
pub fn map_state(s: CameraState) -> SourceState {
    match s {
        CameraState::Connecting => SourceState::Starting,
        CameraState::Streaming => SourceState::Streaming,
        CameraState::CameraLost => SourceState::Lost,
        CameraState::Stopped => SourceState::Ended,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn states_map_to_the_status_words() {
        assert_eq!(map_state(CameraState::CameraLost).name(), "camera_lost");
        assert_eq!(map_state(CameraState::Streaming).name(), "streaming");
        assert_eq!(map_state(CameraState::Connecting), SourceState::Starting);
        assert_eq!(map_state(CameraState::Stopped), SourceState::Ended);
    }
}
