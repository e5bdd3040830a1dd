//! JSON lines on stdout: one estimate per line, flushed per line.

use super::{PublishError, Publisher};
use crate::estimate::Estimate;
use crate::frame::Frame;
use std::io::Write;
use std::sync::Arc;

/// When estimates are printed on stdout (`[publish] stdout`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StdoutMode {
    /// When stdout is a terminal.
    Auto,
    Always,
    Never,
}

/// Prints every estimate as one JSON line on stdout. A closed stdout (broken pipe) stops
/// the printing, not the node.
#[derive(Debug, Default)]
pub struct StdoutPublisher {
    closed: bool,
}

impl StdoutPublisher {
    pub fn new() -> Self {
        StdoutPublisher { closed: false }
    }
}

impl Publisher for StdoutPublisher {
    fn name(&self) -> &str {
        "stdout"
    }

    fn publish(&mut self, e: &Estimate, _frame: Option<&Arc<Frame>>) -> Result<(), PublishError> {
        if self.closed {
            return Ok(());
        }
        let mut out = std::io::stdout().lock();
        let r = writeln!(out, "{}", e.to_json()).and_then(|_| out.flush());
        if let Err(source) = r {
            self.closed = true;
            tracing::warn!("stdout closed ({source}): no more estimates printed");
            return Err(PublishError::Io {
                what: "stdout".into(),
                source,
            });
        }
        Ok(())
    }
}
