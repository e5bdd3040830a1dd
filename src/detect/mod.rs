//! The row detector: from one image to rows, their vanishing point, and heading and tilt.
//!
//! Owns the result types every stage shares ([`Row`], [`VanishingPoint`], [`Detection`]).
//! The stages (mask, vegetation, Hough, edge, vanishing point, pose) live in their own files;
//! [`Detector`] owns their buffers and runs them in order (prepare → Hough → vanishing point).

pub mod centre;
pub mod chords;
pub mod comb;
pub mod combine;
pub mod detector;
pub mod edge;
pub mod hough;
pub mod mask;
pub mod options;
pub mod overlay;
pub mod pencil;
pub mod pose;
pub mod prior;
pub mod refit;
pub mod scale;
pub mod sections;
pub mod smooth;
pub mod strips;
pub mod threshold;
pub mod vanishing;
pub mod vegetation;

/// `n` pseudo-random bytes (xorshift64 from `seed`, non-zero), for the stages' tests.
#[cfg(test)]
pub(crate) fn noise_bytes(mut seed: u64, n: usize) -> Vec<u8> {
    (0..n)
        .map(|_| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 56) as u8
        })
        .collect()
}

pub use detector::{
    CombinedOptions, Detector, DetectorOptions, Points, Preparer, PriorOutcome, VanishingStage,
};
pub use prior::DetectorPrior;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// An error from a detector stage. Names what was wrong with which input.
#[derive(Debug, thiserror::Error)]
pub enum DetectError {
    #[error("invalid detector option: {0}")]
    Options(String),
    #[error("image {height}x{width}: {problem}")]
    Image {
        height: u32,
        width: u32,
        problem: String,
    },
    #[error("calibration: {0}")]
    Calibration(String),
    #[error("mask: {0}")]
    Mask(String),
    #[error("buffer: {0}")]
    Buffer(String),
}

impl Method {
    /// The method's name as the command line and the JSON output spell it.
    pub fn name(self) -> &'static str {
        match self {
            Method::Hough => "hough",
            Method::Edge => "edge",
            Method::Combined => "combined",
            Method::Pencil => "pencil",
            Method::Strips => "strips",
            Method::Auto => "auto",
        }
    }
}

/// An owned single-channel 8-bit image (row-major, no padding), reused across frames.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GreyImage {
    pub width: usize,
    pub height: usize,
    pub data: Vec<u8>,
}

impl GreyImage {
    /// Sets the size; allocates only when the buffer must grow.
    pub fn resize(&mut self, width: usize, height: usize) {
        self.width = width;
        self.height = height;
        self.data.resize(width * height, 0);
    }

    #[inline]
    pub fn get(&self, row: usize, col: usize) -> u8 {
        self.data[row * self.width + col]
    }
}

/// Which method found a row (or produced a detection).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    Hough,
    Edge,
    Combined,
    /// Rows as the peaks of the vegetation across the pencil of great circles through the
    /// vanishing point that makes them sharpest ([`pencil`]).
    Pencil,
    /// Rows of a forward-looking camera as the strips' vegetation peaks lined up through
    /// the vanishing point, on the teeth of their evenly spaced comb ([`strips`]).
    Strips,
    /// An option only, never a row's method: the method for the calibration's lens,
    /// resolved when the detector is built ([`scale::resolve`]): `strips` for a field of
    /// view narrower than [`scale::NARROW_EXTENT_RAD`] on a forward-looking mounting (a
    /// perspective camera; `pencil` if it looks down), `combined` otherwise (the
    /// omnidirectional lenses of the paper).
    Auto,
}

/// A row: the great circle where its plane cuts the unit sphere.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Row {
    /// Unit normal of the row's plane, OCamCalib camera frame. Sign is free.
    pub normal: Vector3<f64>,
    pub method: Method,
    /// Number of image points that support the row.
    pub support: u32,
    /// The crop row's width: the angle around the vanishing point between its two
    /// boundaries (radians), where the edge method found both; 0 where it was not measured.
    pub width_rad: f64,
}

/// The common vanishing point of the rows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VanishingPoint {
    /// Unit direction along the rows, OCamCalib camera frame. Sign is free.
    pub direction: Vector3<f64>,
    /// Number of rows consistent with it.
    pub inliers: usize,
    /// RMS angular distance (radians) of the inlier normals from the plane perpendicular
    /// to the direction.
    pub residual_rad: f64,
}

/// The detector's answer for one image.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Detection {
    pub rows: Vec<Row>,
    pub vanishing_point: Option<VanishingPoint>,
    /// Heading (radians, counter-clockwise from the robot's forward axis) of the rows.
    pub heading_rad: Option<f64>,
    /// Elevation (radians) of the row direction in the robot frame.
    pub tilt_rad: Option<f64>,
    /// Quality in 0..=1 (0 when there is no vanishing point).
    pub quality: f64,
    /// The edge method's boundaries through the vanishing point (edge and combined methods):
    /// evidence behind the published centre lines, not rows themselves. Row guidance
    /// measures on them beside the rows.
    pub boundaries: Vec<Row>,
}
