//! omnirow: crop-row and vanishing-point detection for field robots with an omnidirectional
//! (fisheye or catadioptric) camera, after Ericson and Åstrand, "Row-detection on an
//! agricultural field using omnidirectional camera".
//!
//! The library is organised one concept per module: the camera model ([`camera`]), geometry on
//! the unit sphere ([`sphere`]), the synthetic field with ground truth ([`synth`]), and the
//! command-line front end ([`cli`]) that the thin binary calls.

pub mod affinity;
pub mod camera;
pub mod check;
pub mod cli;
pub mod config;
pub mod detect;
pub mod estimate;
pub mod eval;
pub mod frame;
pub mod gige;
pub mod guidance;
pub mod logging;
pub mod memory;
pub mod notify;
pub mod perception;
pub mod pipeline;
pub mod publish;
pub mod record;
pub mod ros2;
pub mod sim;
pub mod source;
pub mod sphere;
pub mod status;
pub mod synth;
