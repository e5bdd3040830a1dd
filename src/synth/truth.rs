//! Ground truth of a synthetic image: what the detector should find.

use serde::{Deserialize, Serialize};

/// Ground truth of one synthetic image. Vectors are unit vectors in the calibration's
/// OCamCalib camera frame (x down the image rows, y along the columns, z back out of the lens).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GroundTruth {
    /// Direction along the rows (the vanishing point of the rows). Sign is free.
    pub vp_along: [f64; 3],
    /// Direction across the rows (the second, orthogonal vanishing point). Sign is free.
    pub vp_across: [f64; 3],
    /// Robot pose relative to the rows, radians: yaw (about up), pitch, roll.
    pub yaw_rad: f64,
    pub pitch_rad: f64,
    pub roll_rad: f64,
    /// Heading and tilt as omnirow reports them (row direction in the robot frame).
    pub heading_rad: f64,
    pub tilt_rad: f64,
    /// Camera height above the ground, metres.
    pub height_m: f64,
    /// Lateral offset of the camera from the nearest row, metres.
    pub lateral_offset_m: f64,
    pub row_spacing_m: f64,
    pub plant_distance_m: f64,
    /// Noise settings used to render the image.
    pub noise: NoiseTruth,
    /// Plane normal of every row visible in the image (sign free).
    pub row_normals: Vec<[f64; 3]>,
    /// Seed the image was rendered from.
    pub seed: u64,
}

/// The noise settings recorded with the ground truth.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct NoiseTruth {
    /// Salt-and-pepper density of the background noise (0..1).
    pub background_density: f64,
    /// Standard deviation of the plant position error along the row, metres.
    pub along_row_sd_m: f64,
    /// Standard deviation of the plant position error across the row, metres.
    pub across_row_sd_m: f64,
    /// Number of weeds placed at random.
    pub weeds: usize,
}
