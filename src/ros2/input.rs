//! What the ROS 2 publisher needs from the node, and nothing more: the seam between the
//! pipeline's own estimate and status types and the ROS 2 messages.
//!
//! Owns [`RosEstimate`] (one frame's answer, with its row guidance as [`RosGuidance`]) and
//! [`RosStatus`] (the once-a-second summary). They borrow or copy, so mapping the node's types
//! onto them costs no allocation.

use crate::guidance::Warning;

/// One frame's estimate, as the ROS 2 topics carry it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RosEstimate<'a> {
    /// Capture time of the frame, nanoseconds since the UNIX epoch: every header stamp.
    pub capture_ns: u64,
    /// Heading of the rows, radians, counter-clockwise from the robot's forward axis
    /// (as [`crate::detect::Detection::heading_rad`]).
    pub heading_rad: Option<f64>,
    /// Elevation of the row direction in the robot frame, radians
    /// (as [`crate::detect::Detection::tilt_rad`]).
    pub tilt_rad: Option<f64>,
    /// Detector quality in 0..=1.
    pub quality: f64,
    /// `ok`, `no_rows`, `degraded`, `camera_lost`, ...
    pub status: &'a str,
    /// Row guidance of this frame, when the node runs it (`None`: `[guidance]` disabled).
    pub guidance: Option<RosGuidance<'a>>,
}

/// One frame's row guidance (see [`crate::guidance::GuidanceEstimate`] for each field's
/// meaning and sign; REP 103 throughout).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RosGuidance<'a> {
    /// `tracking`, `coasting`, `lost` or `reacquired`.
    pub tracking: &'a str,
    /// `between_rows` or `over_row`.
    pub mode: &'a str,
    /// The tracked estimate; `None` when the tracker has none (`lost`).
    pub tracked: Option<TrackedRow>,
    /// Roll about the rows, radians, right side down positive; `None`: unobserved.
    pub roll_rad: Option<f64>,
    /// Distance ahead to the end of the rows, metres; `None`: not seen ending.
    pub end_of_row_m: Option<f64>,
    /// What crop is in view: `rows`, `empty_stretch` or `no_crop`.
    pub crop: &'a str,
    /// Configuration warnings: the rows disagree with the configured geometry.
    pub warnings: &'a [Warning],
}

/// The tracker's estimate of the followed line, for the tool point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackedRow {
    /// Offset of the tool point from the followed line, metres, positive when it is left of it.
    pub lateral_offset_m: f64,
    /// The rows' heading in the robot frame, counter-clockwise from forward, radians (the
    /// robot's yaw relative to the rows is its negative).
    pub heading_rad: f64,
    /// Curvature of the followed line, 1/m, positive when it bends to the left.
    pub curvature_per_m: f64,
    pub row_spacing_m: f64,
    /// The followed line's index relative to the line nearest the tool point.
    pub row_index: i64,
    /// Filter covariance of (offset, heading, curvature, spacing), row-major.
    pub covariance: [[f64; 4]; 4],
}

/// The node's once-a-second summary, published as `diagnostic_msgs/DiagnosticArray`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RosStatus<'a> {
    /// Frames the source delivered.
    pub frames_in: u64,
    /// Estimates published.
    pub frames_out: u64,
    /// Frames dropped (channel full, incomplete buffers, ...).
    pub dropped: u64,
    /// End-to-end latency, milliseconds, median and 99th percentile over the last period.
    pub latency_p50_ms: f64,
    pub latency_p99_ms: f64,
    /// Status of the latest estimate (`ok`, `no_rows`, `degraded`, `camera_lost`, ...).
    pub estimate_status: &'a str,
    /// The source's state, e.g. `running`, `finished`, `reconnecting`.
    pub source_state: &'a str,
    /// The camera's state when the source is a camera (`streaming`, `lost`, ...).
    pub camera_state: Option<&'a str>,
    /// The camera's identity (model and serial), or the recording's name.
    pub hardware_id: &'a str,
}
