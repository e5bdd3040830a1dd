//! The per-frame estimate: what the node publishes for every frame.
//!
//! Owns [`Estimate`], the versioned JSON document that goes out over UDP, stdout and into
//! recordings (schema in docs/node.md), its [`Status`], and the conversion from a detector
//! [`Detection`](crate::detect::Detection) plus the frame's timestamps. Vectors are unit vectors
//! in the calibration's OCamCalib camera frame; angles are radians; times are nanoseconds since
//! the UNIX epoch. Schema version 2 adds `guidance` (see [`crate::guidance`] and
//! docs/guidance.md): the robot's metric pose relative to the rows, present when the node runs
//! row guidance; every version 1 field is unchanged.

use crate::detect::{Detection, Method};
use crate::frame::Frame;
use crate::guidance::{Guidance, GuidanceEstimate, RowFitMeasurement};
use serde::{Deserialize, Serialize};

/// The version of the [`Estimate`] JSON schema. Bumped on any incompatible change.
pub const SCHEMA_VERSION: u32 = 2;

/// What kind of answer an estimate carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// A vanishing point with quality at or above the configured minimum.
    Ok,
    /// A vanishing point, but with quality below the configured minimum.
    Degraded,
    /// Fewer than two rows found: no vanishing point.
    NoRows,
    /// Two or more rows, but no vanishing point consistent with them.
    NoVanishingPoint,
    /// The source delivers no frames (camera gone); the estimate carries no measurement.
    CameraLost,
    /// The detector failed on this frame (the `error` field says why).
    Error,
}

impl Status {
    pub fn name(self) -> &'static str {
        match self {
            Status::Ok => "ok",
            Status::Degraded => "degraded",
            Status::NoRows => "no_rows",
            Status::NoVanishingPoint => "no_vanishing_point",
            Status::CameraLost => "camera_lost",
            Status::Error => "error",
        }
    }
}

/// One detected row in an estimate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RowEstimate {
    /// Unit normal of the row's plane (sign free).
    pub normal: [f64; 3],
    pub method: Method,
    pub support: u32,
    /// The crop row's width, the angle between its boundaries around the vanishing point
    /// (radians; 0 where not measured: only the edge and combined methods measure it).
    /// Absent in estimates recorded before 2026-12-03 (read as 0).
    #[serde(default)]
    pub width_rad: f64,
}

/// Ground truth carried by synthetic frames, so the output can be checked live.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthEstimate {
    pub heading_rad: f64,
    pub tilt_rad: f64,
    /// Direction along the rows (sign free).
    pub vanishing_point: [f64; 3],
    pub lateral_offset_m: f64,
    /// The camera's position across the rows (world y; row i runs along y = i·spacing),
    /// metres: continuous, unlike `lateral_offset_m` (schema 2).
    #[serde(default)]
    pub camera_lateral_m: f64,
    /// The field's row spacing, metres (schema 2).
    #[serde(default)]
    pub row_spacing_m: f64,
    /// Curvature of row 0, 1/m, positive bending left (schema 2; 0: straight rows): the line
    /// at world y bends by `c / (1 − c·y)` ([`Self::path_curvature_per_m`]).
    #[serde(default)]
    pub curvature_per_m: f64,
    /// Distance along the rows to where they end, metres (negative once past; `None`: no
    /// end in the scene) (schema 2).
    #[serde(default)]
    pub end_of_rows_m: Option<f64>,
    /// No plant within 3 m along the rows, ahead or behind (schema 2).
    #[serde(default)]
    pub no_crop: bool,
}

impl TruthEstimate {
    /// Offset of the camera from the centre line of the inter-row path `path` (the path
    /// between rows `path` and `path + 1`), metres, positive to the left.
    pub fn path_offset_m(&self, path: i64) -> f64 {
        self.camera_lateral_m - (path as f64 + 0.5) * self.row_spacing_m
    }

    /// Curvature of the centre line of the inter-row path `path`, 1/m, positive bending left.
    pub fn path_curvature_per_m(&self, path: i64) -> f64 {
        let c = self.curvature_per_m;
        c / (1.0 - c * (path as f64 + 0.5) * self.row_spacing_m)
    }

    /// The inter-row path the camera is in.
    pub fn path(&self) -> i64 {
        (self.camera_lateral_m / self.row_spacing_m).floor() as i64
    }
}

/// The per-frame estimate, as published (one JSON object).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Estimate {
    /// [`SCHEMA_VERSION`].
    pub schema_version: u32,
    /// The frame's sequence number (from the source; gaps mean frames dropped or lost).
    pub seq: u64,
    /// Capture time of the frame (camera or recording clock), ns since the UNIX epoch.
    pub capture_ns: u64,
    /// Host time the frame was received, ns since the UNIX epoch.
    pub receive_ns: u64,
    /// Host time the estimate was published, ns since the UNIX epoch.
    pub publish_ns: u64,
    /// End-to-end latency on the host: publish time minus receive time, milliseconds.
    pub latency_ms: f64,
    /// The detector's own time for this frame, milliseconds.
    pub detector_ms: f64,
    pub status: Status,
    /// Heading of the rows, counter-clockwise from the robot's forward axis (REP 103).
    pub heading_rad: Option<f64>,
    /// Elevation of the row direction in the robot frame.
    pub tilt_rad: Option<f64>,
    /// Unit direction along the rows, OCamCalib camera frame (sign free).
    pub vanishing_point: Option<[f64; 3]>,
    pub rows: Vec<RowEstimate>,
    /// 0..=1; 0 without a vanishing point.
    pub quality: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub truth: Option<TruthEstimate>,
    /// Row guidance (schema 2), when the node runs it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub guidance: Option<GuidanceEstimate>,
    /// The rows' curvature measured from this frame's points by the detector worker
    /// ([`crate::pipeline::Processor::row_fit`]), on its way to row guidance in the
    /// publisher; not published itself (guidance's `frame.curvature_per_m` is).
    #[serde(skip)]
    pub row_fit: Option<RowFitMeasurement>,
    /// The edge boundaries' plane normals behind the rows ([`Detection::boundaries`]), on
    /// their way to row guidance, which measures on them beside the rows; not published.
    #[serde(skip)]
    pub boundary_normals: Vec<[f64; 3]>,
    /// Where the frame's time went, milliseconds, stage by stage ([`STAGES`]); not
    /// published: the node's metrics summarise it.
    #[serde(skip)]
    pub stage_ms: [f64; 4],
}

/// The stages of a frame's time in [`Estimate::stage_ms`]: the detector's preparation
/// (vegetation, smoothing, threshold), its method's rows (and their refit), the vote for the
/// vanishing point with the method's finishing steps, and the rows' fit on the ground for
/// guidance.
pub const STAGES: [&str; 4] = ["prepare", "rows", "vanishing", "row_fit"];

impl Estimate {
    /// Builds the estimate of `frame` from the detector's answer. `publish_ns` is filled in
    /// by [`Estimate::stamp_published`].
    pub fn from_detection(
        frame: &Frame,
        det: &Detection,
        detector_ms: f64,
        min_quality: f64,
    ) -> Estimate {
        let status = match (&det.vanishing_point, det.rows.len()) {
            (Some(_), _) if det.quality >= min_quality => Status::Ok,
            (Some(_), _) => Status::Degraded,
            (None, n) if n < 2 => Status::NoRows,
            (None, _) => Status::NoVanishingPoint,
        };
        let mut e = Estimate::empty(frame, status);
        e.detector_ms = detector_ms;
        e.heading_rad = det.heading_rad;
        e.tilt_rad = det.tilt_rad;
        e.vanishing_point = det.vanishing_point.map(|v| v.direction.into());
        e.rows = det
            .rows
            .iter()
            .map(|r| RowEstimate {
                normal: r.normal.into(),
                method: r.method,
                support: r.support,
                width_rad: r.width_rad,
            })
            .collect();
        e.quality = det.quality;
        e.boundary_normals = det.boundaries.iter().map(|r| r.normal.into()).collect();
        e
    }

    /// An estimate for `frame` with no measurement (used for errors).
    pub fn empty(frame: &Frame, status: Status) -> Estimate {
        Estimate {
            schema_version: SCHEMA_VERSION,
            seq: frame.seq,
            capture_ns: frame.capture_ns,
            receive_ns: frame.receive_ns,
            publish_ns: 0,
            latency_ms: 0.0,
            detector_ms: 0.0,
            status,
            heading_rad: None,
            tilt_rad: None,
            vanishing_point: None,
            rows: Vec::new(),
            quality: 0.0,
            error: None,
            truth: frame.truth.as_ref().map(|t| TruthEstimate {
                heading_rad: t.heading_rad,
                tilt_rad: t.tilt_rad,
                vanishing_point: t.vp_along,
                lateral_offset_m: t.lateral_offset_m,
                camera_lateral_m: t.camera_lateral_m,
                row_spacing_m: t.row_spacing_m,
                curvature_per_m: t.curvature_per_m,
                end_of_rows_m: t.end_of_rows_m,
                no_crop: t.no_crop,
            }),
            guidance: None,
            row_fit: None,
            boundary_normals: Vec::new(),
            stage_ms: [0.0; 4],
        }
    }

    /// An estimate saying the source delivers nothing (no frame): `seq` is the last frame's.
    pub fn camera_lost(last_seq: u64, now_ns: u64) -> Estimate {
        Estimate {
            schema_version: SCHEMA_VERSION,
            seq: last_seq,
            capture_ns: 0,
            receive_ns: now_ns,
            publish_ns: now_ns,
            latency_ms: 0.0,
            detector_ms: 0.0,
            status: Status::CameraLost,
            heading_rad: None,
            tilt_rad: None,
            vanishing_point: None,
            rows: Vec::new(),
            quality: 0.0,
            error: None,
            truth: None,
            guidance: None,
            row_fit: None,
            boundary_normals: Vec::new(),
            stage_ms: [0.0; 4],
        }
    }

    /// Runs row guidance on this estimate (frames in capture order): a frame with a
    /// vanishing point (`ok` or `degraded`) measures, and the comb's fit and the tracker's
    /// gate judge the measurement; any other only advances the tracker.
    pub fn apply_guidance(&mut self, guidance: &mut Guidance) {
        let vp = match self.status {
            Status::Ok | Status::Degraded => self.vanishing_point,
            _ => None,
        };
        let mut out = self.guidance.take().unwrap_or_default();
        guidance.update(
            self.capture_ns,
            vp,
            self.rows
                .iter()
                .map(|r| r.normal)
                .chain(self.boundary_normals.iter().copied()),
            self.row_fit.as_ref(),
            &mut out,
        );
        self.guidance = Some(out);
    }

    /// Sets the publish time and the end-to-end latency.
    pub fn stamp_published(&mut self, now_ns: u64) {
        self.publish_ns = now_ns;
        self.latency_ms = now_ns.saturating_sub(self.receive_ns) as f64 / 1e6;
    }

    /// The estimate as one line of JSON (no trailing newline).
    pub fn to_json(&self) -> String {
        // Serialising plain data with finite or null floats cannot fail; non-finite floats
        // become null in serde_json.
        serde_json::to_string(self).unwrap_or_else(|e| format!("{{\"error\":\"{e}\"}}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::{Row, VanishingPoint};
    use crate::frame::PixelFormat;
    use nalgebra::Vector3;

    fn frame() -> Frame {
        Frame {
            seq: 7,
            capture_ns: 1_000,
            receive_ns: 2_000_000,
            width: 2,
            height: 1,
            format: PixelFormat::Mono8,
            data: vec![0, 0],
            truth: None,
        }
    }

    #[test]
    fn status_follows_detection() {
        let f = frame();
        let mut d = Detection::default();
        assert_eq!(
            Estimate::from_detection(&f, &d, 1.0, 0.5).status,
            Status::NoRows
        );
        let row = Row {
            normal: Vector3::x(),
            method: Method::Hough,
            support: 10,
            width_rad: 0.0,
        };
        d.rows = vec![row, row];
        assert_eq!(
            Estimate::from_detection(&f, &d, 1.0, 0.5).status,
            Status::NoVanishingPoint
        );
        d.vanishing_point = Some(VanishingPoint {
            direction: Vector3::y(),
            inliers: 2,
            residual_rad: 0.0,
        });
        d.quality = 0.4;
        assert_eq!(
            Estimate::from_detection(&f, &d, 1.0, 0.5).status,
            Status::Degraded
        );
        d.quality = 0.9;
        d.rows[1].width_rad = 0.05;
        let e = Estimate::from_detection(&f, &d, 1.0, 0.5);
        assert_eq!(e.status, Status::Ok);
        assert_eq!(e.vanishing_point, Some([0.0, 1.0, 0.0]));
        assert_eq!((e.rows[0].width_rad, e.rows[1].width_rad), (0.0, 0.05));
    }

    #[test]
    fn rows_recorded_without_a_width_read_as_zero() {
        let r: RowEstimate =
            serde_json::from_str(r#"{"normal":[1,0,0],"method":"hough","support":3}"#).unwrap();
        assert_eq!(r.width_rad, 0.0);
        let text = serde_json::to_string(&RowEstimate {
            width_rad: 0.1,
            ..r
        })
        .unwrap();
        assert!(text.contains("\"width_rad\":0.1"), "{text}");
    }

    #[test]
    fn json_round_trip_and_latency() {
        let mut e = Estimate::empty(&frame(), Status::NoRows);
        e.stamp_published(5_000_000);
        assert!((e.latency_ms - 3.0).abs() < 1e-9);
        let text = e.to_json();
        assert!(text.contains("\"status\":\"no_rows\""));
        assert!(text.contains("\"schema_version\":2"));
        assert!(!text.contains("truth"));
        let back: Estimate = serde_json::from_str(&text).unwrap();
        assert_eq!(back, e);
    }
}
