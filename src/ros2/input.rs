//! What the ROS 2 publisher needs from the node, and nothing more: the seam between the
//! pipeline's own estimate and status types and the ROS 2 messages.
//!
//! Owns [`RosEstimate`] (one frame's answer) and [`RosStatus`] (the once-a-second summary).
//! Both borrow, so mapping the node's types onto them costs no allocation.

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
