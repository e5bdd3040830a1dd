//! The synthetic field: parallel crop rows rendered through any calibration, with ground truth.
//!
//! Owns the paper's section III-B reproduced and extended: the field model (rows, plants with
//! four leaves, weeds), the camera pose over it, the renderer (supersampled, greyscale or
//! colour or Bayer), the three kinds of noise, and the ground truth of every image.

mod truth;

pub use truth::GroundTruth;
