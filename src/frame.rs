//! Frames: the image data that flows from a source through the pipeline.
//!
//! Owns [`Frame`] (an owned image plus its sequence number, capture and receive timestamps,
//! and, for synthetic frames, the ground truth) and [`ImageView`], the borrowed view the
//! detector reads. Pixel formats are those the GC2450C and recordings deliver: Mono8, RGB8,
//! and 8-bit Bayer RGGB (GenICam `BayerRG8`).

use std::sync::Arc;

/// Pixel layout of a frame's bytes (row-major, no padding).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PixelFormat {
    /// One byte per pixel, grey.
    Mono8,
    /// Three bytes per pixel, R G B.
    Rgb8,
    /// One byte per pixel, Bayer mosaic with R at (0,0), G at (0,1) and (1,0), B at (1,1).
    BayerRggb8,
}

impl PixelFormat {
    /// Bytes per pixel.
    pub fn bytes_per_pixel(self) -> usize {
        match self {
            PixelFormat::Mono8 | PixelFormat::BayerRggb8 => 1,
            PixelFormat::Rgb8 => 3,
        }
    }

    /// The ROS 2 `sensor_msgs/Image` encoding name.
    pub fn ros_encoding(self) -> &'static str {
        match self {
            PixelFormat::Mono8 => "mono8",
            PixelFormat::Rgb8 => "rgb8",
            PixelFormat::BayerRggb8 => "bayer_rggb8",
        }
    }

    /// Parses a ROS 2 / Foxglove encoding name.
    pub fn from_ros_encoding(enc: &str) -> Option<Self> {
        match enc {
            "mono8" | "8UC1" => Some(PixelFormat::Mono8),
            "rgb8" => Some(PixelFormat::Rgb8),
            "bayer_rggb8" => Some(PixelFormat::BayerRggb8),
            _ => None,
        }
    }
}

/// Error for a frame whose size and data disagree.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("frame {width}x{height} {format:?} needs {expected} bytes, has {actual}")]
pub struct FrameSizeError {
    pub width: u32,
    pub height: u32,
    pub format: PixelFormat,
    pub expected: usize,
    pub actual: usize,
}

/// A borrowed image: what the detector reads.
#[derive(Debug, Clone, Copy)]
pub struct ImageView<'a> {
    pub width: u32,
    pub height: u32,
    pub format: PixelFormat,
    pub data: &'a [u8],
}

impl<'a> ImageView<'a> {
    /// Wraps bytes, checking that their length matches the size and format.
    pub fn new(
        width: u32,
        height: u32,
        format: PixelFormat,
        data: &'a [u8],
    ) -> Result<Self, FrameSizeError> {
        let expected = width as usize * height as usize * format.bytes_per_pixel();
        if data.len() != expected {
            return Err(FrameSizeError {
                width,
                height,
                format,
                expected,
                actual: data.len(),
            });
        }
        Ok(ImageView {
            width,
            height,
            format,
            data,
        })
    }
}

/// An owned frame travelling through the pipeline.
#[derive(Debug, Clone)]
pub struct Frame {
    /// Sequence number assigned by the source (monotonic, gaps mean frames lost upstream).
    pub seq: u64,
    /// Capture time, nanoseconds since the UNIX epoch (camera or recording clock).
    pub capture_ns: u64,
    /// Host receive time, nanoseconds since the UNIX epoch.
    pub receive_ns: u64,
    pub width: u32,
    pub height: u32,
    pub format: PixelFormat,
    pub data: Vec<u8>,
    /// Ground truth, for synthetic frames.
    pub truth: Option<Arc<GroundTruth>>,
}

/// Along the rows, ahead and behind, within which a plant counts for
/// [`GroundTruth::no_crop`], metres.
pub const NO_CROP_RANGE_M: f64 = 3.0;

/// Ground truth of one synthetic image (computed by [`GroundTruth::of_scene`] in
/// [`crate::synth`]).
///
/// The row normals are those of the ideal row lines (plants without position error) in the
/// plane through the camera centre; rows whose plants are displaced across the row still
/// list the ideal line's normal. Vectors are unit vectors in the calibration's
/// OCamCalib camera frame (x down the image rows, y along the columns, z back out of the lens).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
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
    /// Lateral offset of the camera from the nearest row, metres: world y of the camera
    /// minus world y of that row, in (−spacing/2, spacing/2].
    pub lateral_offset_m: f64,
    /// The camera's world y (row i runs along y = i·`row_spacing_m`), metres.
    #[serde(default)]
    pub camera_lateral_m: f64,
    pub row_spacing_m: f64,
    pub plant_distance_m: f64,
    /// Curvature of row 0 (the field's, 1/m, positive bending left; 0: straight rows). The
    /// rows are concentric: the line at world y bends by `c / (1 − c·y)`. In a curved field
    /// the row normals are those of the rows' tangent lines at the camera.
    #[serde(default)]
    pub curvature_per_m: f64,
    /// Distance along the rows from the camera to where they end (the last plant), metres;
    /// negative once past it; `None` when the scene sets no end (`rows_end_m`).
    #[serde(default)]
    pub end_of_rows_m: Option<f64>,
    /// No plant grows within [`NO_CROP_RANGE_M`] along the rows of the camera, ahead or
    /// behind (an empty stretch, the headland): nothing in view should be called a row.
    #[serde(default)]
    pub no_crop: bool,
    /// Noise settings used to render the image.
    pub noise: NoiseTruth,
    /// Plane normal of every row visible in the image (sign free).
    pub row_normals: Vec<[f64; 3]>,
    /// For each entry of `row_normals`: the row's position across the rows relative to the
    /// camera (world y of the row minus world y of the camera), metres.
    #[serde(default)]
    pub row_lateral_m: Vec<f64>,
    /// Seed the image was rendered from.
    pub seed: u64,
}

/// The noise settings recorded with the ground truth.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
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

impl Frame {
    /// The frame's pixels as a view (checked).
    pub fn view(&self) -> Result<ImageView<'_>, FrameSizeError> {
        ImageView::new(self.width, self.height, self.format, &self.data)
    }
}

/// Nanoseconds since the UNIX epoch, now.
pub fn now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn view_checks_length() {
        let data = vec![0u8; 12];
        assert!(ImageView::new(2, 2, PixelFormat::Rgb8, &data).is_ok());
        let e = ImageView::new(3, 2, PixelFormat::Rgb8, &data).unwrap_err();
        assert_eq!(e.expected, 18);
    }
}
