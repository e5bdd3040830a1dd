//! The detector's shared vocabulary: what every stage and method reads and writes.
//!
//! Owns the result types ([`Row`], [`VanishingPoint`], [`Detection`]), what the stages share
//! ([`GreyImage`], the kept [`Points`]), the list of methods ([`Method`]) and the detector's error
//! ([`DetectError`]). It depends on nothing else in the detector, so that every stage and
//! method can depend on it.

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

/// A row-detection method: the `method` option (`auto` included), the command line's
/// `--method`, and the method that found a row (never `auto`). The one list of methods: the
/// configuration (serde) and the command line (clap) both read it, and [`Method::name`]
/// spells it as they do.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// The paper's spherical Hough method (II-D): rows as peaks of a Hough transform over
    /// the great circles through the kept points.
    Hough,
    /// The paper's edge method (II-C): rows from the plants' boundary lines.
    Edge,
    /// Both, combined (II-F, eq. 5); the choice for omnidirectional lenses.
    Combined,
    /// Rows of a narrow camera looking down as the peaks of the vegetation's profile across
    /// the pencil of great circles through the vanishing point ([`super::pencil`]).
    Pencil,
    /// Rows of a forward-looking perspective camera as vegetation peaks in horizontal
    /// strips, lined up through the vanishing point ([`super::strips`]).
    Strips,
    /// The method for the calibration's lens, resolved when the detector is built
    /// ([`super::method::choose`]).
    Auto,
}

impl Method {
    /// The method's name as the configuration, the command line and the JSON output spell
    /// it.
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

/// The kept points of an image, what the methods read: unit rays (camera frame) and
/// their weights (smoothed vegetation value times the pixel's solid angle, so that fits are
/// integrals over the sphere, free of the lens's varying pixel density).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Points {
    pub rays: Vec<[f32; 3]>,
    pub weights: Vec<f32>,
    /// The angular size (radians) of each point's pixel: the calibration's resolution where
    /// the point is, from which the stages' pixel scales become angles.
    pub pixel_rad: Vec<f32>,
}

impl Points {
    /// Checks that every point has its weight and pixel size (`what` names the reader in
    /// the error).
    pub fn check(&self, what: &str) -> Result<(), DetectError> {
        let n = self.rays.len();
        if self.weights.len() == n && self.pixel_rad.len() == n {
            return Ok(());
        }
        Err(DetectError::Buffer(format!(
            "{what}: {n} rays, {} weights, {} pixel sizes",
            self.weights.len(),
            self.pixel_rad.len()
        )))
    }
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

impl Detection {
    /// Sets the vanishing point (a method's final fit replacing the vote's); heading and
    /// tilt follow from it when the detector finishes the image.
    pub fn set_vanishing_point(&mut self, direction: Vector3<f64>, inliers: usize, residual: f64) {
        self.vanishing_point = Some(VanishingPoint {
            direction,
            inliers,
            residual_rad: residual,
        });
    }
}

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

#[cfg(test)]
mod tests {
    use super::*;
    use clap::ValueEnum;

    #[test]
    fn a_method_is_spelled_alike_by_its_name_the_configuration_and_the_command_line() {
        for &m in Method::value_variants() {
            let cli = m.to_possible_value().unwrap();
            assert_eq!(cli.get_name(), m.name());
            assert_eq!(serde_json::to_value(m).unwrap(), m.name());
            assert_eq!(Method::from_str(m.name(), false), Ok(m));
        }
    }
}
