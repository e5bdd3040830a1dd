//! Row guidance: the robot's metric pose relative to the crop rows, frame after frame.
//!
//! Owns [`Guidance`], which turns the detector's rows and vanishing point into what a steering
//! controller takes: each row as a line on the ground ([`ground`]), the rows' comb with its
//! spacing and each row's index ([`comb`]), the lateral offset of a tool point from the followed
//! line (`between_rows`: the centre of an inter-row path; `over_row`: a row), the heading, the
//! roll when enough rows are seen, and a Kalman filter over frames that keeps the followed
//! line's identity ([`tracker`]). Also its options ([`GuidanceOptions`]), the published
//! [`GuidanceEstimate`] and the configuration warnings it raises when the camera's height or
//! mounting look wrong. Sign conventions (REP 103 and ISOBUS) are in docs/guidance.md.
//! Buffers are kept between frames: an update allocates nothing once warmed up.

pub mod comb;
pub mod config;
pub mod followed;
pub mod ground;
pub mod headland;
pub mod motion;
pub mod rowfit;
pub mod tracker;

pub use comb::{fit_comb, fit_comb_with_roll, Comb, CombOptions};
pub use config::GuidanceConfig;
pub use ground::GroundFrame;
pub use headland::Headland;
pub use motion::{Motion, MotionAt, Odometry, OdometryFeed};
pub use rowfit::{RowFit, RowFitMeasurement, RowFitOptions};
pub use tracker::{Measurement, TrackState, Tracked, Tracker, TrackerOptions};

use crate::camera::Mounting;
use nalgebra::{Rotation3, Vector3};
use serde::{Deserialize, Serialize};

/// An invalid guidance setting.
#[derive(Debug, thiserror::Error)]
pub enum GuidanceError {
    #[error("invalid guidance option: {0}")]
    Options(String),
}

/// Which line the robot follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// The robot drives in an inter-row path: offset from the path's centre line.
    #[default]
    BetweenRows,
    /// The robot straddles a row: offset from that row.
    OverRow,
}

/// Settings of row guidance (the `[guidance]` configuration's, validated by [`Self::validate`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GuidanceOptions {
    pub mode: Mode,
    /// The field's row spacing when known, metres; checked against the measured one.
    pub row_spacing_m: Option<f64>,
    /// Use `row_spacing_m` as is (not estimated; needs `row_spacing_m`).
    pub fixed_spacing: bool,
    /// Plausible spacings when estimated, metres.
    pub min_spacing_m: f64,
    pub max_spacing_m: f64,
    /// The point (base_link x, y, metres, at base_link's z = 0) whose offset from the
    /// followed line is published (a tool, or the base_link origin).
    pub tool_point_m: [f64; 2],
    /// Estimate the roll about the rows from the comb (needs two rows on each side and five
    /// in all), searching up to this many degrees; 0 (the default) leaves it off: one
    /// frame's comb of real plants suggests rolls that are not there.
    pub max_roll_deg: f64,
    /// Fewest rows on the comb for a measurement.
    pub min_rows: usize,
    /// Floors of the per-frame measurement errors: a row's lateral position (metres) and the
    /// heading (radians).
    pub row_sd_m: f64,
    pub heading_sd_rad: f64,
    /// Relative difference between the measured and the configured spacing (or between the
    /// spacing at opposite offsets) above which a configuration warning is raised.
    pub spacing_tolerance: f64,
    /// Odometry older than this (against the frame's capture time) is ignored, seconds: the
    /// configured `speed_mps` is used instead.
    pub odometry_max_age_s: f64,
    pub tracker: TrackerOptions,
}

impl Default for GuidanceOptions {
    fn default() -> Self {
        GuidanceOptions {
            mode: Mode::BetweenRows,
            row_spacing_m: None,
            fixed_spacing: false,
            min_spacing_m: 0.2,
            max_spacing_m: 2.0,
            tool_point_m: [0.0, 0.0],
            max_roll_deg: 0.0,
            min_rows: 2,
            row_sd_m: 0.003,
            heading_sd_rad: 0.1f64.to_radians(),
            spacing_tolerance: 0.04,
            odometry_max_age_s: 0.5,
            tracker: TrackerOptions::default(),
        }
    }
}

impl GuidanceOptions {
    /// Checks every setting; the message names the key.
    pub fn validate(&self) -> Result<(), GuidanceError> {
        let bad = |m: String| Err(GuidanceError::Options(m));
        let pos = |k: &str, v: f64| -> Result<(), GuidanceError> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(GuidanceError::Options(format!(
                    "{k} = {v} must be a positive number"
                )))
            }
        };
        pos("min_spacing_m", self.min_spacing_m)?;
        pos("max_spacing_m", self.max_spacing_m)?;
        if self.min_spacing_m >= self.max_spacing_m {
            return bad(format!(
                "min_spacing_m = {} must be below max_spacing_m = {}",
                self.min_spacing_m, self.max_spacing_m
            ));
        }
        if let Some(s) = self.row_spacing_m {
            if !(s >= self.min_spacing_m && s <= self.max_spacing_m) {
                return bad(format!(
                    "row_spacing_m = {s} must lie within min_spacing_m..max_spacing_m ({}..{})",
                    self.min_spacing_m, self.max_spacing_m
                ));
            }
        } else if self.fixed_spacing {
            return bad("fixed_spacing = true needs row_spacing_m".into());
        }
        if !self.tool_point_m.iter().all(|v| v.abs() <= 50.0) {
            return bad(format!(
                "tool_point_m = {:?} must lie within 50 m of base_link",
                self.tool_point_m
            ));
        }
        if !(self.max_roll_deg >= 0.0 && self.max_roll_deg <= 30.0) {
            return bad(format!(
                "max_roll_deg = {} must lie in 0..=30",
                self.max_roll_deg
            ));
        }
        if self.min_rows < 2 {
            return bad(format!("min_rows = {} must be at least 2", self.min_rows));
        }
        pos("row_sd_m", self.row_sd_m)?;
        pos("heading_sd_rad", self.heading_sd_rad)?;
        pos("spacing_tolerance", self.spacing_tolerance)?;
        if !(self.odometry_max_age_s > 0.0 && self.odometry_max_age_s <= 60.0) {
            return bad(format!(
                "odometry_max_age_s = {} must lie in (0, 60]",
                self.odometry_max_age_s
            ));
        }
        let t = &self.tracker;
        if !(t.speed_mps.is_finite() && t.speed_mps >= 0.0 && t.speed_mps <= 50.0) {
            return bad(format!("speed_mps = {} must lie in 0..=50", t.speed_mps));
        }
        pos("offset_rate_sd", t.offset_rate_sd)?;
        pos("heading_rate_sd", t.heading_rate_sd)?;
        pos("curvature_rate_sd", t.curvature_rate_sd)?;
        pos("spacing_rate_sd", t.spacing_rate_sd)?;
        pos("initial_curvature_sd", t.initial_curvature_sd)?;
        pos("gate_chi2", t.gate_chi2)?;
        pos("coast_s", t.coast_s)?;
        Ok(())
    }
}

/// A configuration warning: the rows disagree with the configured geometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Warning {
    /// The measured spacing differs from `row_spacing_m`: the camera height is likely wrong
    /// (the lateral scale is proportional to it).
    SpacingDiffersFromConfigured,
    /// The measured spacing changes with the robot's offset: the camera's roll (mounting) or
    /// the lens calibration is likely wrong.
    SpacingVariesWithOffset,
    /// The rows rise or fall steeply in the robot frame: the mounting pitch is likely wrong
    /// (or the field is steep).
    RowsTilted,
    /// The rows are not evenly spaced on the ground: a roll or a wrong calibration.
    UnevenComb,
}

impl Warning {
    pub fn name(self) -> &'static str {
        match self {
            Warning::SpacingDiffersFromConfigured => "spacing_differs_from_configured",
            Warning::SpacingVariesWithOffset => "spacing_varies_with_offset",
            Warning::RowsTilted => "rows_tilted",
            Warning::UnevenComb => "uneven_comb",
        }
    }

    const ALL: [Warning; 4] = [
        Warning::SpacingDiffersFromConfigured,
        Warning::SpacingVariesWithOffset,
        Warning::RowsTilted,
        Warning::UnevenComb,
    ];
}

/// What crop a frame shows around the robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CropState {
    /// Rows measured, with plants on them within 3 m along (ahead or behind).
    Rows,
    /// Rows measured farther away, but no plant on them within 3 m along, ahead or behind:
    /// an empty stretch, or the headland once past the rows' end.
    EmptyStretch,
    /// No crop visible: nothing in this frame is taken for a row (bare ground, the
    /// headland, a covered camera); `rows` is empty and `frame` null.
    #[default]
    NoCrop,
}

impl CropState {
    pub fn name(self) -> &'static str {
        match self {
            CropState::Rows => "rows",
            CropState::EmptyStretch => "empty_stretch",
            CropState::NoCrop => "no_crop",
        }
    }
}

/// One detected row as a line on the ground, base_link coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GroundRow {
    /// The row's comb index: 0 the comb line nearest the camera, positive to the left.
    pub index: i64,
    /// Lateral position of the row relative to the tool point, across the rows, metres,
    /// positive to the left.
    pub lateral_m: f64,
    /// The line's point nearest the camera's foot point, base_link, metres.
    pub point_m: [f64; 3],
    /// Unit direction of the line, base_link, pointing forward.
    pub direction: [f64; 3],
}

/// This frame's single-image answer (before the filter).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FrameGuidance {
    /// Offset of the tool point from the nearest line of the followed kind, metres, in
    /// (−s/2, s/2], positive when the robot is left of it.
    pub lateral_offset_m: f64,
    pub heading_rad: f64,
    pub row_spacing_m: f64,
    /// Curvature of the nearest line of the followed kind, 1/m, positive bending left, from
    /// the rows' points on the ground; `None` when the frame's points did not give one.
    #[serde(default)]
    pub curvature_per_m: Option<f64>,
    /// Weighted RMS distance of the rows from the comb, metres.
    pub comb_rms_m: f64,
    pub rows_used: usize,
}

/// The guidance part of a published estimate (schema version 2).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GuidanceEstimate {
    pub mode: Mode,
    pub tracking: TrackState,
    /// Offset of the tool point from the followed line, metres, positive when the robot is
    /// left of it (REP 103; ISOBUS cross-track is its negative). Continuous in the followed
    /// line's frame: it grows past half a spacing when the robot drifts to another line.
    pub lateral_offset_m: Option<f64>,
    /// The rows' heading in the robot frame, counter-clockwise from forward, radians.
    pub heading_rad: Option<f64>,
    /// Curvature of the followed line, 1/m, positive when it bends to the left.
    pub curvature_per_m: Option<f64>,
    pub row_spacing_m: Option<f64>,
    /// Roll about the rows (REP 103 sense, right side down positive), radians; `None` when
    /// unobserved (too few rows on either side).
    pub roll_rad: Option<f64>,
    /// The followed line's index relative to the line nearest the tool point (0: the robot is
    /// nearest the line it follows; −1: it follows the line to its right).
    pub row_index: Option<i64>,
    /// Distance ahead along the rows from base_link's origin to where the rows end (the last
    /// plant), metres, once within [`rowfit::END_RANGE_M`] (5.5 m; `None`: not seen ending there).
    pub end_of_row_m: Option<f64>,
    /// What crop the frame shows around the robot.
    #[serde(default)]
    pub crop: CropState,
    /// Filter covariance of (offset, heading, curvature, spacing), row-major.
    pub covariance: Option<[[f64; 4]; 4]>,
    /// This frame's own measurement, `None` when the frame gave none.
    pub frame: Option<FrameGuidance>,
    /// The frame's measurement was rejected as an outlier.
    pub rejected: bool,
    /// The rows on the ground (empty when the frame gave no measurement: nothing claims to
    /// be a row).
    pub rows: Vec<GroundRow>,
    pub warnings: Vec<Warning>,
}

impl Default for GuidanceEstimate {
    fn default() -> Self {
        GuidanceEstimate {
            mode: Mode::BetweenRows,
            tracking: TrackState::Lost,
            lateral_offset_m: None,
            heading_rad: None,
            curvature_per_m: None,
            row_spacing_m: None,
            roll_rad: None,
            row_index: None,
            end_of_row_m: None,
            crop: CropState::NoCrop,
            covariance: None,
            frame: None,
            rejected: false,
            rows: Vec::new(),
            warnings: Vec::new(),
        }
    }
}

/// Running statistics behind the configuration warnings.
#[derive(Debug, Clone, Default, PartialEq)]
struct Consistency {
    /// Exponentially weighted sums for the regression of the measured spacing on the offset.
    n: f64,
    sx: f64,
    sy: f64,
    sxx: f64,
    sxy: f64,
    /// Exponential averages of the measured spacing and of the comb's relative RMS.
    spacing: Option<f64>,
    uneven: Option<f64>,
    active: [bool; 4],
}

impl Consistency {
    const FORGET: f64 = 0.995;
    const AVERAGE: f64 = 0.05;

    fn add(&mut self, offset: f64, spacing: Option<f64>, rel_rms: f64) {
        if let Some(s) = spacing {
            let f = Self::FORGET;
            self.n = self.n * f + 1.0;
            self.sx = self.sx * f + offset;
            self.sy = self.sy * f + s;
            self.sxx = self.sxx * f + offset * offset;
            self.sxy = self.sxy * f + offset * s;
            self.spacing = Some(match self.spacing {
                Some(a) => a + Self::AVERAGE * (s - a),
                None => s,
            });
        }
        self.uneven = Some(match self.uneven {
            Some(a) => a + Self::AVERAGE * (rel_rms - a),
            None => rel_rms,
        });
    }

    /// Slope of the spacing against the offset, when the offsets spread enough.
    fn slope(&self, spacing: f64) -> Option<f64> {
        if self.n < 30.0 {
            return None;
        }
        let vx = self.sxx / self.n - (self.sx / self.n).powi(2);
        let cxy = self.sxy / self.n - self.sx / self.n * self.sy / self.n;
        (vx > (0.1 * spacing).powi(2)).then(|| cxy / vx)
    }
}

/// Row guidance for one camera: per-frame ground geometry and the tracker.
#[derive(Debug, Clone, PartialEq)]
pub struct Guidance {
    opts: GuidanceOptions,
    mounting: Mounting,
    robot_from_camera: Rotation3<f64>,
    normals: Vec<Vector3<f64>>,
    ys: Vec<f64>,
    index: Vec<Option<i64>>,
    tracker: Tracker,
    consistency: Consistency,
    tilted: bool,
    /// The spacing last tracked: the comb's first guess when none is configured (a few far
    /// rows, as at an empty stretch's end, otherwise fit a comb of twice the spacing).
    spacing_hint: Option<f64>,
    /// The end of the rows and the crop over frames.
    headland: Headland,
    /// Odometry and the configured speed.
    motion: Motion,
    /// From the camera's foot point to base_link's origin along the rows, metres (the last
    /// measured frame's).
    end_shift_m: f64,
    /// Where odometry arrives from another thread (ROS 2), when subscribed.
    feed: Option<std::sync::Arc<OdometryFeed>>,
}

impl Guidance {
    /// Sets up guidance for a camera with `mounting` (its height and position included).
    pub fn new(opts: GuidanceOptions, mounting: Mounting) -> Result<Self, GuidanceError> {
        opts.validate()?;
        mounting
            .validate()
            .map_err(|e| GuidanceError::Options(format!("camera mounting: {e}")))?;
        Ok(Guidance {
            opts,
            mounting,
            robot_from_camera: mounting.robot_from_camera(),
            normals: Vec::with_capacity(64),
            ys: Vec::with_capacity(64),
            index: Vec::with_capacity(64),
            tracker: Tracker::new(opts.tracker),
            consistency: Consistency::default(),
            tilted: false,
            spacing_hint: None,
            headland: Headland::new(),
            motion: Motion::new(opts.tracker.speed_mps, opts.odometry_max_age_s),
            end_shift_m: 0.0,
            feed: None,
        })
    }

    pub fn options(&self) -> &GuidanceOptions {
        &self.opts
    }

    /// Keeps an odometry sample for the frames captured within `odometry_max_age_s` of it;
    /// false (and ignored) when it is not finite.
    pub fn set_odometry(&mut self, odom: Odometry) -> bool {
        self.motion.set(odom)
    }

    /// The robot's motion guidance predicts with for a frame captured at `t_ns`: fresh
    /// odometry (from the feed too), else the configured speed, else unknown.
    pub fn motion_at(&mut self, t_ns: u64) -> MotionAt {
        if let Some(o) = self.feed.as_ref().and_then(|f| f.latest()) {
            self.motion.set(o);
        }
        self.motion.at(t_ns)
    }

    /// Reads odometry from `feed` (filled by another thread, e.g. the ROS 2 subscription)
    /// before every frame.
    pub fn with_odometry_feed(mut self, feed: std::sync::Arc<OdometryFeed>) -> Self {
        self.feed = Some(feed);
        self
    }

    /// Folds in one frame, in capture order: its capture time, the rows' vanishing point and
    /// the rows' plane normals (camera frame; `vp` `None` when the frame has no usable
    /// vanishing point), and the curvature the frame's points gave ([`RowFit`], run
    /// where the points are). Writes the published guidance into `out` (its buffers reused).
    pub fn update(
        &mut self,
        t_ns: u64,
        vp: Option<[f64; 3]>,
        normals: impl IntoIterator<Item = [f64; 3]>,
        curvature: Option<&RowFitMeasurement>,
        out: &mut GuidanceEstimate,
    ) {
        out.mode = self.opts.mode;
        out.rows.clear();
        out.warnings.clear();
        out.frame = None;
        out.roll_rad = None;
        out.end_of_row_m = None;
        let motion = self.motion_at(t_ns);
        self.tracker.set_motion(motion.from_odometry.then(|| {
            (
                motion.speed_mps.unwrap_or(0.0),
                motion.yaw_rate_rps.unwrap_or(0.0),
            )
        }));
        let measured = vp.and_then(|vp| self.measure(&Vector3::from(vp), normals, curvature, out));
        let frame_crop = match (&measured, curvature) {
            (None, _) => CropState::NoCrop,
            (Some(_), Some(f)) if !f.crop_near => CropState::EmptyStretch,
            (Some(_), _) => CropState::Rows,
        };
        let fit = curvature.filter(|_| measured.is_some());
        let (end, crop) = self
            .headland
            .update(t_ns, frame_crop, fit, motion.speed_mps);
        out.crop = crop;
        // from the camera's foot point to base_link's origin, along the rows
        out.end_of_row_m = end
            .map(|e| e + self.end_shift_m)
            .filter(|e| e.abs() <= rowfit::END_RANGE_M);
        let m = measured.map(|(m, _)| m);
        let r = self.tracker.update(t_ns, m.as_ref());
        out.tracking = r.state;
        out.rejected = r.rejected;
        match (r.x, r.p) {
            (Some(x), Some(p)) => {
                out.lateral_offset_m = Some(x[0]);
                out.heading_rad = Some(x[1]);
                out.curvature_per_m = Some(x[2]);
                out.row_spacing_m = Some(x[3]);
                out.row_index = Some(-(x[0] / x[3]).round() as i64);
                if r.state != TrackState::Coasting {
                    self.spacing_hint = Some(x[3]);
                }
                out.covariance = Some(p.transpose().into());
            }
            _ => {
                out.lateral_offset_m = None;
                out.heading_rad = None;
                out.curvature_per_m = None;
                out.row_spacing_m = None;
                out.row_index = None;
                out.covariance = None;
            }
        }
        if let Some((m, info)) = measured {
            if r.rejected {
                out.rows.clear();
            } else {
                self.consistency.add(
                    m.offset_m,
                    info.measured_spacing_m,
                    info.rms_m / m.spacing_m,
                );
            }
            self.tilted = info.tilt_rad.abs() > Self::MAX_TILT_RAD;
        }
        self.warn(out);
    }

    /// Largest tilt of the rows in the robot frame before [`Warning::RowsTilted`], radians.
    const MAX_TILT_RAD: f64 = 0.1745;

    /// This frame's measurement: the comb on the ground, the offset of the tool point from the
    /// nearest line of the followed kind, the heading. Fills `out.frame` and `out.rows`.
    fn measure(
        &mut self,
        vp: &Vector3<f64>,
        normals: impl IntoIterator<Item = [f64; 3]>,
        fit: Option<&RowFitMeasurement>,
        out: &mut GuidanceEstimate,
    ) -> Option<(Measurement, FrameInfo)> {
        let o = &self.opts;
        let frame = GroundFrame::with_rotation(vp, &self.robot_from_camera, &self.mounting, 0.0)?;
        self.normals.clear();
        for n in normals {
            let n = self.robot_from_camera * Vector3::from(n);
            if n.iter().all(|v| v.is_finite()) {
                self.normals.push(n);
            }
        }
        if self.normals.len() < o.min_rows {
            return None;
        }
        self.ys.clear();
        self.ys.resize(self.normals.len(), 0.0);
        self.index.clear();
        self.index.resize(self.normals.len(), None);
        let copts = CombOptions {
            spacing_m: o.row_spacing_m.or(self.spacing_hint),
            fixed_spacing: o.fixed_spacing,
            min_spacing_m: o.min_spacing_m,
            max_spacing_m: o.max_spacing_m,
            height_m: self.mounting.height_m,
            min_row_sd_m: o.row_sd_m,
        };
        let (comb, g, roll) = fit_comb_with_roll(
            &frame,
            &self.normals,
            o.max_roll_deg.to_radians(),
            &copts,
            &mut self.ys,
            &mut self.index,
        )?;
        if comb.rows_used < o.min_rows {
            return None;
        }
        let s = comb.spacing_m;
        let tool = Vector3::new(o.tool_point_m[0], o.tool_point_m[1], 0.0);
        // the comb's line nearest the camera, relative to the tool point
        let c = comb.offset_m - g.point_lateral_m(&tool);
        let line = match o.mode {
            Mode::OverRow => c,
            Mode::BetweenRows => c + s / 2.0,
        };
        let wrap = |e: f64| e - (e / s - 0.5).ceil() * s;
        let straight = wrap(-line);
        // the followed kind's nearest line (left of the camera's foot point) is the chord of
        // a curved row: measured at the tool point on the fitted arc instead
        let tool_lateral = g.point_lateral_m(&tool);
        let tool_along = g.along.dot(&(tool - g.camera_m));
        let fit = fit.filter(|m| m.curvature_per_m.is_some());
        let offset = match fit {
            Some(m) => wrap(straight - m.arc_shift_m(tool_lateral - straight, tool_along)),
            None => straight,
        };
        let curvature = fit.and_then(|m| Some((m.at_lateral(tool_lateral - offset)?, m.sd_per_m)));
        let heading = g.heading_rad();
        self.end_shift_m = g.along.dot(&g.camera_m);
        let dir = g.along - g.up * g.along.dot(&g.up);
        let dir = dir / dir.norm();
        for (y, k) in self.ys.iter().zip(&self.index) {
            if let Some(k) = k {
                let p = g.line_point_m(*y);
                out.rows.push(GroundRow {
                    index: *k,
                    lateral_m: y - g.point_lateral_m(&tool),
                    point_m: p.into(),
                    direction: dir.into(),
                });
            }
        }
        out.roll_rad = roll;
        out.frame = Some(FrameGuidance {
            lateral_offset_m: offset,
            heading_rad: heading,
            row_spacing_m: s,
            curvature_per_m: curvature.map(|c| c.0),
            comb_rms_m: comb.rms_m,
            rows_used: comb.rows_used,
        });
        let spacing_sd = if o.fixed_spacing {
            1e-4
        } else {
            comb.spacing_sd_m.max(1e-4)
        };
        Some((
            Measurement {
                offset_m: offset,
                // the arc's shift under the camera adds its own uncertainty: large across
                // an empty stretch, where the arcs are extrapolated from rows farther away
                offset_sd_m: comb
                    .offset_sd_m
                    .max(o.row_sd_m / 2.0)
                    .hypot(fit.map_or(0.0, |m| m.shift_sd_m)),
                heading_rad: heading,
                heading_sd_rad: o.heading_sd_rad,
                spacing_m: s,
                spacing_sd_m: spacing_sd,
                curvature,
            },
            FrameInfo {
                measured_spacing_m: comb.measured_spacing_m,
                rms_m: comb.rms_m,
                tilt_rad: frame.along.z.asin(),
            },
        ))
    }

    /// Sets the configuration warnings in `out`, logging each when it first appears.
    fn warn(&mut self, out: &mut GuidanceEstimate) {
        let o = &self.opts;
        let c = &self.consistency;
        let h = self.mounting.height_m;
        let mut on = [false; 4];
        let mut detail = [String::new(), String::new(), String::new(), String::new()];
        if let (Some(cfg), Some(avg)) = (o.row_spacing_m, c.spacing) {
            if (avg / cfg - 1.0).abs() > o.spacing_tolerance {
                on[0] = true;
                if !c.active[0] {
                    detail[0] = format!(
                        "measured row spacing {avg:.3} m, configured {cfg:.3} m: is the camera height {h:.3} m right? The rows suggest {:.3} m",
                        h * cfg / avg
                    );
                }
            }
        }
        let spacing = c.spacing.unwrap_or(o.row_spacing_m.unwrap_or(0.5));
        if let Some(slope) = c.slope(spacing) {
            if slope.abs() > o.spacing_tolerance {
                on[1] = true;
                if !c.active[1] {
                    detail[1] = format!(
                        "the measured row spacing changes by {:.1}% over one spacing of offset: check the camera's roll in [mounting] and the lens calibration",
                        slope * 100.0
                    );
                }
            }
        }
        if self.tilted {
            on[2] = true;
            if !c.active[2] {
                detail[2] = format!(
                    "the rows rise more than {:.0}° in the robot frame: check the camera's pitch in [mounting]",
                    Self::MAX_TILT_RAD.to_degrees()
                );
            }
        }
        if c.uneven.is_some_and(|u| u > 0.1) {
            on[3] = true;
            if !c.active[3] {
                detail[3] = "the rows are not evenly spaced on the ground: check the camera's roll in [mounting], the height and the lens calibration".into();
            }
        }
        for (i, w) in Warning::ALL.iter().enumerate() {
            if on[i] {
                out.warnings.push(*w);
                if !detail[i].is_empty() {
                    tracing::warn!(warning = w.name(), "guidance: {}", detail[i]);
                }
            }
        }
        self.consistency.active = on;
    }
}

/// What a frame's measurement says beyond the tracker's input.
#[derive(Debug, Clone, Copy)]
struct FrameInfo {
    measured_spacing_m: Option<f64>,
    rms_m: f64,
    tilt_rad: f64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::Pose;
    use proptest::prelude::*;

    /// The vanishing point and the normals (camera frame) of rows k·`s` (k in `ks`) seen by a
    /// camera at world (0, `cam_y`, `h`) on a robot with yaw, pitch, roll.
    fn view(
        yaw: f64,
        pitch: f64,
        roll: f64,
        cam_y: f64,
        h: f64,
        s: f64,
        ks: std::ops::RangeInclusive<i64>,
    ) -> ([f64; 3], Vec<[f64; 3]>) {
        let pose = Pose::new(
            yaw,
            pitch,
            roll,
            &Mounting::default(),
            Vector3::new(0.0, cam_y, h),
        );
        let normals = ks
            .filter_map(|k| pose.line_normal(&Vector3::new(0.0, k as f64 * s, 0.0), &Vector3::x()))
            .map(Into::into)
            .collect();
        (pose.vp_along().into(), normals)
    }

    fn wrap(e: f64, s: f64) -> f64 {
        e - (e / s - 0.5).ceil() * s
    }

    proptest! {
        /// One exact frame: the offset from the path centre (or the row), the heading and the
        /// spacing come back whatever the yaw, pitch and position across the rows.
        #[test]
        fn single_frame_exact(
            yaw in -0.3f64..0.3, pitch in -0.1f64..0.1, cam_y in -1.0f64..1.0,
            over_row in proptest::bool::ANY,
        ) {
            let mode = if over_row { Mode::OverRow } else { Mode::BetweenRows };
            let opts = GuidanceOptions { mode, max_roll_deg: 0.0, ..GuidanceOptions::default() };
            let mut g = Guidance::new(opts, Mounting::default()).unwrap();
            let (vp, normals) = view(yaw, pitch, 0.0, cam_y, 1.0, 0.5, -6..=6);
            let mut out = GuidanceEstimate::default();
            // the same frame twice: two agreeing measurements start the tracker
            g.update(1, Some(vp), normals.clone(), None, &mut out);
            g.update(2, Some(vp), normals, None, &mut out);
            let f = out.frame.unwrap();
            let line = if over_row { 0.0 } else { 0.25 };
            let truth = wrap(cam_y - line, 0.5);
            prop_assert!((f.lateral_offset_m - truth).abs() < 1e-6, "{} vs {}", f.lateral_offset_m, truth);
            prop_assert!((f.heading_rad + yaw).abs() < 1e-9);
            prop_assert!((f.row_spacing_m - 0.5).abs() < 1e-6);
            prop_assert_eq!(out.tracking, TrackState::Tracking);
            prop_assert!((out.lateral_offset_m.unwrap() - truth).abs() < 1e-6);
            // the rows on the ground, relative to the tool point (the origin)
            for r in &out.rows {
                let y = r.index as f64 * 0.5 + wrap(-cam_y, 0.5);
                prop_assert!((r.lateral_m - y).abs() < 1e-6, "{:?}", r);
            }
        }
    }

    #[test]
    fn tool_point_ahead_and_aside() {
        // robot yawed 0.2 rad, camera at the origin; a tool 1 m ahead and 0.1 m left
        let opts = GuidanceOptions {
            mode: Mode::OverRow,
            tool_point_m: [1.0, 0.1],
            max_roll_deg: 0.0,
            ..GuidanceOptions::default()
        };
        let mut g = Guidance::new(opts, Mounting::default()).unwrap();
        let yaw: f64 = 0.2;
        let (vp, normals) = view(yaw, 0.0, 0.0, 0.1, 1.0, 0.5, -5..=5);
        let mut out = GuidanceEstimate::default();
        g.update(1, Some(vp), normals, None, &mut out);
        // the tool's world y: camera y + R(yaw)·(1, 0.1)
        let tool_y = 0.1 + yaw.sin() * 1.0 + yaw.cos() * 0.1;
        let f = out.frame.unwrap();
        assert!(
            (f.lateral_offset_m - wrap(tool_y, 0.5)).abs() < 1e-9,
            "{f:?}"
        );
    }

    #[test]
    fn roll_estimated_and_offset_kept() {
        let roll = 1.5f64.to_radians();
        let searched = GuidanceOptions {
            max_roll_deg: 5.0,
            ..GuidanceOptions::default()
        };
        let mut g = Guidance::new(searched, Mounting::default()).unwrap();
        let (vp, normals) = view(0.0, 0.0, roll, 0.3, 1.0, 0.5, -5..=5);
        let mut out = GuidanceEstimate::default();
        g.update(1, Some(vp), normals, None, &mut out);
        let r = out.roll_rad.unwrap();
        assert!((r - roll).abs() < 1e-4, "{r}");
        let f = out.frame.unwrap();
        assert!((f.lateral_offset_m - 0.05).abs() < 2e-4, "{f:?}");
        // without the roll estimate the offset is biased by about h·roll
        let opts = GuidanceOptions {
            max_roll_deg: 0.0,
            ..GuidanceOptions::default()
        };
        let mut g = Guidance::new(opts, Mounting::default()).unwrap();
        g.update(
            1,
            Some(vp),
            view(0.0, 0.0, roll, 0.3, 1.0, 0.5, -5..=5).1,
            None,
            &mut out,
        );
        assert!(out.roll_rad.is_none());
        assert!((out.frame.unwrap().lateral_offset_m - 0.05).abs() > 0.01);
    }

    #[test]
    fn the_end_is_published_from_the_first_frame_it_is_5_m_ahead() {
        // 1 m/s at 15 fps towards the rows' end, 7 m ahead at first; each frame measures it
        // at the far edge of its 0.2 m bin, as the row fit does, so the track runs a little
        // high as the end crosses 5 m
        let mut g = Guidance::new(GuidanceOptions::default(), Mounting::default()).unwrap();
        let mut out = GuidanceEstimate::default();
        let (vp, normals) = view(0.0, 0.0, 0.0, 0.3, 1.0, 0.5, -5..=5);
        let mut due = 0;
        for i in 0..100u64 {
            let truth = 7.0 - i as f64 / 15.0;
            let fit = RowFitMeasurement {
                curvature_per_m: None,
                sd_per_m: 0.0,
                points: 1000,
                end_of_rows_m: Some((truth / 0.2 - 1e-9).ceil() * 0.2),
                crop_near: true,
                shift_m: 0.0,
                turn: 0.0,
                shift_sd_m: 0.0,
            };
            g.update(
                1 + i * 66_666_667,
                Some(vp),
                normals.iter().copied(),
                Some(&fit),
                &mut out,
            );
            if (0.3..=5.0).contains(&truth) {
                due += 1;
                let e = out.end_of_row_m;
                assert!(
                    e.is_some_and(|e| (e - truth).abs() <= 0.5),
                    "frame {i}: end {truth:.3} m ahead, published {e:?}"
                );
            }
        }
        assert!(due > 60, "{due}");
    }

    #[test]
    fn no_rows_claims_nothing_and_coasts() {
        let mut g = Guidance::new(GuidanceOptions::default(), Mounting::default()).unwrap();
        let mut out = GuidanceEstimate::default();
        let (vp, normals) = view(0.0, 0.0, 0.0, 0.3, 1.0, 0.5, -5..=5);
        g.update(1, Some(vp), normals.clone(), None, &mut out);
        g.update(2, Some(vp), normals, None, &mut out);
        assert!(!out.rows.is_empty());
        g.update(100_000_000, None, [], None, &mut out);
        assert_eq!(out.tracking, TrackState::Coasting);
        assert!(out.rows.is_empty() && out.frame.is_none());
        assert!(out.lateral_offset_m.is_some());
        g.update(2_000_000_000, Some(vp), [[1.0, 0.0, 0.0]], None, &mut out);
        assert_eq!(out.tracking, TrackState::Lost);
        assert!(out.lateral_offset_m.is_none() && out.rows.is_empty());
    }

    #[test]
    fn wrong_height_warns_with_the_likely_height() {
        // the camera is 1.2 m high, the configuration says 1.0 m, rows 0.5 m apart
        let opts = GuidanceOptions {
            row_spacing_m: Some(0.5),
            ..GuidanceOptions::default()
        };
        let mut g = Guidance::new(opts, Mounting::default()).unwrap();
        let mut out = GuidanceEstimate::default();
        for i in 0..10u64 {
            let (vp, normals) = view(0.0, 0.0, 0.0, 0.3, 1.2, 0.5, -5..=5);
            g.update(1 + i * 66_000_000, Some(vp), normals, None, &mut out);
        }
        assert_eq!(out.warnings, vec![Warning::SpacingDiffersFromConfigured]);
        // right height: no warning
        let mut g = Guidance::new(opts, Mounting::default()).unwrap();
        for i in 0..10u64 {
            let (vp, normals) = view(0.0, 0.0, 0.0, 0.3, 1.0, 0.5, -5..=5);
            g.update(1 + i * 66_000_000, Some(vp), normals, None, &mut out);
        }
        assert!(out.warnings.is_empty(), "{:?}", out.warnings);
    }

    #[test]
    fn options_errors_name_the_key() {
        let bad = GuidanceOptions {
            fixed_spacing: true,
            ..GuidanceOptions::default()
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("row_spacing_m"));
        let bad = GuidanceOptions {
            min_rows: 1,
            ..GuidanceOptions::default()
        };
        assert!(bad.validate().unwrap_err().to_string().contains("min_rows"));
        let mut bad = GuidanceOptions::default();
        bad.tracker.coast_s = 0.0;
        assert!(bad.validate().unwrap_err().to_string().contains("coast_s"));
    }
}
