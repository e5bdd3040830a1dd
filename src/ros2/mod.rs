//! ROS 2 interop: heading, tilt, row guidance and status as ROS 2 topics, from pure Rust (no
//! ROS install).
//!
//! Owns everything omnirow shows a ROS 2 system: the `[ros2]` config ([`Ros2Config`]), the
//! message types laid out as their IDL ([`msg`]), the mapping from omnirow's estimate and
//! status to those messages ([`convert`]; row guidance: [`rows`]), the small input types the
//! node maps its own estimate onto ([`RosEstimate`], [`RosGuidance`], [`RosStatus`]), and, with the `ros2` cargo feature, the
//! node itself (`Ros2Publisher`, DDS through `ros2-client`/RustDDS) and its place among the
//! node's publishers ([`node_publisher`]). The config, messages and mapping build without the
//! feature, so a `[ros2]` section is validated everywhere.
//! Topic table and how to use it from ROS 2: docs/ros2.md.

pub mod config;
pub mod convert;
mod error;
mod input;
pub mod msg;
mod node;
#[cfg(feature = "ros2")]
mod publisher;
pub mod rows;

pub use config::{QosConfig, Reliability, Ros2Config, Ros2ConfigError};
pub use convert::{MessageBuilder, RowAttitude};
pub use error::Ros2Error;
pub use input::{RosEstimate, RosGuidance, RosStatus, TrackedRow};
pub use node::node_publisher;
#[cfg(feature = "ros2")]
pub use publisher::{PublishCounts, Ros2Publisher, TopicInfo};
pub use rows::RowPose;
