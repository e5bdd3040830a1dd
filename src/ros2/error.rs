//! Errors of the ROS 2 side: setting the node up and publishing.
//!
//! Owns [`Ros2Error`]. It names no `ros2-client` type, so it exists in builds without the
//! `ros2` feature too (where the only possible error is [`Ros2Error::NotBuilt`]).

use super::config::Ros2ConfigError;
use super::msg::TimeRangeError;

/// Why the ROS 2 node could not be set up or a message not be sent.
#[derive(Debug, thiserror::Error)]
pub enum Ros2Error {
    #[error(transparent)]
    Config(#[from] Ros2ConfigError),
    #[error(
        "ros2.enabled = true, but this omnirow was built without ROS 2 support \
         (build it with `cargo build --release --features ros2`)"
    )]
    NotBuilt,
    #[error("ROS 2: cannot create {what}: {reason}")]
    Create { what: String, reason: String },
    #[error("ROS 2: cannot publish on {topic}: {reason}")]
    Write { topic: String, reason: String },
    #[error(transparent)]
    Stamp(#[from] TimeRangeError),
}
