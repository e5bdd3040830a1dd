//! Publishing: where estimates go.
//!
//! Owns the [`Publisher`] seam the pipeline's publisher thread calls for every estimate (in
//! frame order) and with the [`StatusSummary`] once per status interval, and the publishers
//! omnirow ships: UDP JSON datagrams to unicast or multicast destinations ([`udp`]), JSON lines
//! on stdout ([`stdout`]), and the HTTP endpoint with /healthz, /metrics and /overlay.png
//! ([`http`], which reads the node's [`crate::status`] instead of being called). A ROS 2
//! publisher plugs in as one more [`Publisher`].

pub mod http;
pub mod stdout;
pub mod udp;

use crate::estimate::Estimate;
use crate::frame::Frame;
use crate::status::StatusSummary;
use std::sync::Arc;

/// Errors of a publisher (never fatal to the pipeline: it logs them and goes on).
#[derive(Debug, thiserror::Error)]
pub enum PublishError {
    #[error("{what}: {source}")]
    Io {
        what: String,
        source: std::io::Error,
    },
}

/// A sink for estimates, called from the pipeline's publisher thread.
pub trait Publisher: Send {
    /// A short name for logs.
    fn name(&self) -> &str;
    /// Publishes one estimate; `frame` is the frame it was computed from (`None` for
    /// estimates without a frame, e.g. `camera_lost`). Must not block for long.
    fn publish(
        &mut self,
        estimate: &Estimate,
        frame: Option<&Arc<Frame>>,
    ) -> Result<(), PublishError>;
    /// The status summary, once per status interval.
    fn status(&mut self, _status: &StatusSummary) {}
    /// The pipeline is finishing: flush what is buffered.
    fn finish(&mut self) {}
}
