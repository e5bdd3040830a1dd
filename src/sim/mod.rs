//! The closed steering loop on a synthetic field (`omnirow sim`, docs/sim.md).
//!
//! Owns the loop: a robot ([`robot`]) drives over a [`Ground`] ([`ground`]); each frame is
//! rendered at the robot's true pose, goes through the node's own per-frame step
//! ([`Perception::process`]: detector, rows' fit, guidance, tracker), and a steering
//! [`Controller`] ([`controller`]) turns the estimate's guidance into a curvature command,
//! which acts after the node's latency (the step's measured time for that frame, or a fixed
//! one). The truth (cross-track and heading error) comes from the robot's true pose relative
//! to the inter-row path it started in. Layer: above perception, guidance and synth, below
//! the command line.

pub mod controller;
pub mod ground;
pub mod robot;

pub use controller::{Controller, LineMeasurement};
pub use ground::{Ground, RowFrame, RowPose, SyntheticFieldOptions, SyntheticGround};
pub use robot::{Pose2, RobotModel};

use crate::frame::Frame;
use crate::perception::{Perception, PerceptionError};
use serde::Serialize;
use std::time::Instant;

/// An error of the simulation.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error("synthetic field: {0}")]
    Synth(#[from] crate::synth::SynthError),
    #[error("perception: {0}")]
    Perception(#[from] PerceptionError),
    #[error("{0}")]
    Options(String),
}

/// When a frame's command starts to act.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Latency {
    /// After the per-frame step's own measured time for that frame (wall clock).
    Measured,
    /// After this many seconds, every frame.
    Fixed { seconds: f64 },
}

/// The scenario and the loop's settings.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SimOptions {
    pub speed_mps: f64,
    /// The run ends after this distance along the rows, metres (or at the rows' end).
    pub distance_m: f64,
    pub fps: f64,
    /// The start: base_link this far left of the path's centre line, metres.
    pub start_offset_m: f64,
    /// The start: yaw relative to the rows, degrees, counter-clockwise.
    pub start_heading_deg: f64,
    pub robot: RobotModel,
    pub controller: Controller,
    pub latency: Latency,
    /// The summary's statistics leave out the first this many metres (the approach from the
    /// start offset).
    pub settle_m: f64,
}

impl SimOptions {
    pub fn validate(&self) -> Result<(), SimError> {
        let bad = |s: String| Err(SimError::Options(s));
        if !(self.speed_mps.is_finite() && self.speed_mps > 0.0 && self.speed_mps <= 20.0) {
            return bad(format!(
                "speed {} m/s must be in (0, 20] m/s",
                self.speed_mps
            ));
        }
        if !(self.distance_m.is_finite() && self.distance_m > 0.0 && self.distance_m <= 900.0) {
            return bad(format!(
                "distance {} m must be in (0, 900] metres",
                self.distance_m
            ));
        }
        if !(self.fps.is_finite() && self.fps >= 1.0 && self.fps <= 1000.0) {
            return bad(format!("frame rate {} must be in [1, 1000] fps", self.fps));
        }
        if !(self.start_offset_m.is_finite() && self.start_offset_m.abs() <= 5.0) {
            return bad(format!(
                "start offset {} m must be within ±5 m",
                self.start_offset_m
            ));
        }
        if !(self.start_heading_deg.is_finite() && self.start_heading_deg.abs() <= 45.0) {
            return bad(format!(
                "start heading {}° must be within ±45°",
                self.start_heading_deg
            ));
        }
        if let Latency::Fixed { seconds } = self.latency {
            if !(seconds.is_finite() && (0.0..=10.0).contains(&seconds)) {
                return bad(format!("latency {seconds} s must be in [0, 10] seconds"));
            }
        }
        if !(self.settle_m.is_finite() && self.settle_m >= 0.0) {
            return bad(format!("settle distance {} m must be ≥ 0", self.settle_m));
        }
        self.robot.validate().map_err(SimError::Options)?;
        self.controller.validate().map_err(SimError::Options)?;
        Ok(())
    }
}

/// The estimate's guidance as the controller saw it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SeenGuidance {
    pub offset_m: Option<f64>,
    pub heading_rad: Option<f64>,
    pub curvature_per_m: Option<f64>,
    pub quality: f64,
    pub tracking: Option<crate::guidance::TrackState>,
}

/// One frame of the loop (a line of frames.jsonl).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameRecord {
    pub seq: u64,
    /// Capture time, seconds from the start.
    pub t: f64,
    /// base_link's true pose in the world.
    pub pose: Pose2,
    /// base_link's true pose relative to the rows.
    pub rows: RowPose,
    /// True offset of the tool point from the followed path's centre line, metres,
    /// positive left (the published offset's sense).
    pub cross_track_m: f64,
    /// True yaw relative to the rows' tangent at the tool point, degrees, counter-clockwise
    /// (the published heading's negative).
    pub heading_error_deg: f64,
    /// The inter-row path the tool point is in (0: the one it started in).
    pub path: i64,
    pub estimate: SeenGuidance,
    /// The curvature command this frame gave (held from the previous frame when the
    /// estimate had no offset or heading), 1/m, and the yaw rate it gives, rad/s.
    pub command_curvature_per_m: f64,
    pub command_yaw_rate_rad_s: f64,
    pub held: bool,
    /// When the command acts, after the capture, seconds.
    pub latency_s: f64,
}

/// Why a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum End {
    /// The distance was driven.
    Distance,
    /// base_link reached the rows' end (the robot stops there).
    RowsEnd,
    /// The robot turned more than 60° from the rows: it has left them.
    LeftRows,
    /// Twice the time the distance takes, plus 10 s, went by (no headway: circling).
    Timeout,
}

/// The robot has left the rows when it is turned this far from them, radians (60°).
const LEFT_ROWS_RAD: f64 = std::f64::consts::FRAC_PI_3;

/// What a run came to.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Summary {
    pub frames: usize,
    pub frames_without_guidance: usize,
    /// Distance along the followed path's centre line, metres.
    pub distance_m: f64,
    /// Over the frames past `settle_m`: the cross-track error's mean, standard deviation,
    /// largest magnitude; the heading error's 99th percentile of its magnitude.
    pub cross_track_mean_m: f64,
    pub cross_track_std_m: f64,
    pub cross_track_max_m: f64,
    pub heading_error_p99_deg: f64,
    pub settle_m: f64,
    pub settled_frames: usize,
    /// The largest cross-track magnitude over every frame, the approach included.
    pub cross_track_max_all_m: f64,
    /// How many times the tool point's true inter-row path changed.
    pub row_changes: usize,
    /// The run stopped at the rows' end.
    pub reached_rows_end: bool,
    /// Why the run ended.
    pub end: End,
    /// Mean and largest latency applied, milliseconds.
    pub latency_mean_ms: f64,
    pub latency_max_ms: f64,
    /// Wall time of the run, seconds.
    pub wall_s: f64,
}

/// The closed loop: `ground` seen through `perception` (a camera mounted as `mounting`,
/// guidance measuring the offset of `tool_point_m`), the robot and controller as `o` says;
/// `each` sees every frame's record as it is made.
pub fn run(
    ground: &mut dyn Ground,
    perception: &mut Perception,
    mounting: &crate::camera::Mounting,
    tool_point_m: [f64; 2],
    o: &SimOptions,
    each: impl FnMut(&FrameRecord),
) -> Result<Summary, SimError> {
    let ctl = o.controller;
    run_steered(
        ground,
        perception,
        mounting,
        tool_point_m,
        o,
        &|m, v| ctl.command(m, v),
        each,
    )
}

/// [`run`] with another steering law than `o.controller`: `steer(measurement, speed)` gives
/// the curvature command (tests flip a controller's sign with it).
pub fn run_steered(
    ground: &mut dyn Ground,
    perception: &mut Perception,
    mounting: &crate::camera::Mounting,
    tool_point_m: [f64; 2],
    o: &SimOptions,
    steer: &dyn Fn(&LineMeasurement, f64) -> f64,
    mut each: impl FnMut(&FrameRecord),
) -> Result<Summary, SimError> {
    o.validate()?;
    let started = Instant::now();
    let rf = RowFrame {
        curvature_per_m: ground.curvature_per_m(),
    };
    let spacing = ground.row_spacing_m();
    // base_link starts in the centre of path 0 (between rows 0 and 1), offset and turned
    let mut pose = rf.to_world(&RowPose {
        along_m: 0.0,
        lateral_m: spacing / 2.0 + o.start_offset_m,
        yaw_rad: o.start_heading_deg.to_radians(),
    });
    let centre = spacing / 2.0;
    let path_of = |lateral: f64| ((lateral - centre) / spacing + 0.5).floor() as i64;
    let dt = 1.0 / o.fps;
    let (cx, cy) = (mounting.position_m[0], mounting.position_m[1]);
    let mut frame = Frame {
        seq: 0,
        capture_ns: 0,
        receive_ns: 0,
        width: 0,
        height: 0,
        format: crate::frame::PixelFormat::Mono8,
        data: Vec::new(),
        truth: None,
    };
    // the detector's one-off setup for the image size (its first frame takes it) is not the
    // node's latency: one frame at the start pose first, then a fresh tracker
    {
        let (qx, qy) = pose.point(cx, cy);
        let cam = rf.to_rows(&Pose2 {
            x: qx,
            y: qy,
            theta: pose.theta,
        });
        let (w, h, format) = ground.render(&cam, &mut frame.data)?;
        (frame.width, frame.height, frame.format) = (w, h, format);
        perception.process(&frame)?;
        perception.reset()?;
    }
    let mut command = 0.0f64; // curvature acting now
    let mut pending: Vec<(f64, f64)> = Vec::new(); // (time it acts, curvature)
    let mut last_cmd = 0.0f64;
    let mut path0 = None;
    let mut last_path = 0i64;
    let mut s = Summary {
        frames: 0,
        frames_without_guidance: 0,
        distance_m: 0.0,
        cross_track_mean_m: 0.0,
        cross_track_std_m: 0.0,
        cross_track_max_m: 0.0,
        heading_error_p99_deg: 0.0,
        settle_m: o.settle_m,
        settled_frames: 0,
        cross_track_max_all_m: 0.0,
        row_changes: 0,
        reached_rows_end: false,
        end: End::Distance,
        latency_mean_ms: 0.0,
        latency_max_ms: 0.0,
        wall_s: 0.0,
    };
    let (mut xt, mut he) = (Vec::new(), Vec::new());
    let mut latency_sum = 0.0;
    let end = ground.rows_end_m();
    // a robot that no longer makes headway (circling on a held command) ends the run
    let max_t = 2.0 * o.distance_m / o.speed_mps + 10.0;
    for seq in 0u64.. {
        let t = seq as f64 * dt;
        let base = rf.to_rows(&pose);
        // the tool point's path frame: where truth is measured
        let (tx, ty) = pose.point(tool_point_m[0], tool_point_m[1]);
        let tool = rf.to_rows(&Pose2 {
            x: tx,
            y: ty,
            theta: pose.theta,
        });
        let travelled = base.along_m * (1.0 - rf.curvature_per_m * centre);
        if travelled >= o.distance_m {
            break;
        }
        if let Some(e) = end {
            if base.along_m >= e {
                s.reached_rows_end = true;
                s.end = End::RowsEnd;
                break;
            }
        }
        if base.yaw_rad.abs() > LEFT_ROWS_RAD {
            s.end = End::LeftRows;
            break;
        }
        if t > max_t {
            s.end = End::Timeout;
            break;
        }
        s.distance_m = travelled;
        let p0 = *path0.get_or_insert_with(|| path_of(tool.lateral_m));
        let path = path_of(tool.lateral_m);
        if seq > 0 && path != last_path {
            s.row_changes += 1;
        }
        last_path = path;
        let cross = tool.lateral_m - (centre + p0 as f64 * spacing);
        // the camera's view
        let (qx, qy) = pose.point(cx, cy);
        let cam = rf.to_rows(&Pose2 {
            x: qx,
            y: qy,
            theta: pose.theta,
        });
        let (w, h, format) = ground.render(&cam, &mut frame.data)?;
        frame.seq = seq;
        frame.capture_ns = (t * 1e9) as u64 + 1;
        frame.receive_ns = frame.capture_ns;
        (frame.width, frame.height, frame.format) = (w, h, format);
        let step = Instant::now();
        let est = perception.process(&frame)?;
        let step_s = step.elapsed().as_secs_f64();
        let g = est.guidance.as_ref();
        let seen = SeenGuidance {
            offset_m: g.and_then(|g| g.lateral_offset_m),
            heading_rad: g.and_then(|g| g.heading_rad),
            curvature_per_m: g.and_then(|g| g.curvature_per_m),
            quality: est.quality,
            tracking: g.map(|g| g.tracking),
        };
        let held = match (seen.offset_m, seen.heading_rad) {
            (Some(e), Some(hd)) if e.is_finite() && hd.is_finite() => {
                let m = LineMeasurement {
                    offset_m: e,
                    heading_rad: hd,
                    curvature_per_m: seen
                        .curvature_per_m
                        .filter(|k| k.is_finite())
                        .unwrap_or(0.0),
                };
                last_cmd = steer(&m, o.speed_mps);
                false
            }
            _ => {
                s.frames_without_guidance += 1;
                true
            }
        };
        let latency = match o.latency {
            Latency::Measured => step_s,
            Latency::Fixed { seconds } => seconds,
        };
        latency_sum += latency;
        s.latency_max_ms = s.latency_max_ms.max(latency * 1e3);
        pending.push((t + latency, last_cmd));
        let rec = FrameRecord {
            seq,
            t,
            pose,
            rows: base,
            cross_track_m: cross,
            heading_error_deg: tool.yaw_rad.to_degrees(),
            path: path - p0,
            estimate: seen,
            command_curvature_per_m: last_cmd,
            command_yaw_rate_rad_s: o.robot.yaw_rate(o.speed_mps, last_cmd),
            held,
            latency_s: latency,
        };
        each(&rec);
        s.frames += 1;
        s.cross_track_max_all_m = s.cross_track_max_all_m.max(cross.abs());
        if travelled >= o.settle_m {
            xt.push(cross);
            he.push(tool.yaw_rad.to_degrees().abs());
        }
        command = drive(
            &mut pose,
            command,
            &mut pending,
            t,
            t + dt,
            &o.robot,
            o.speed_mps,
        );
    }
    s.settled_frames = xt.len();
    if !xt.is_empty() {
        let n = xt.len() as f64;
        let mean = xt.iter().sum::<f64>() / n;
        s.cross_track_mean_m = mean;
        s.cross_track_std_m = (xt.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
        s.cross_track_max_m = xt.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        he.sort_by(f64::total_cmp);
        s.heading_error_p99_deg = he[((he.len() - 1) as f64 * 0.99).round() as usize];
    }
    if s.frames > 0 {
        s.latency_mean_ms = latency_sum / s.frames as f64 * 1e3;
    }
    s.wall_s = started.elapsed().as_secs_f64();
    Ok(s)
}

/// Drives `pose` from time `from` to `to` at speed `v`, the curvature `command` acting until
/// each pending command's time (`pending`: (time it acts, curvature), those due by `to`
/// taken out); the command acting at `to`.
fn drive(
    pose: &mut Pose2,
    mut command: f64,
    pending: &mut Vec<(f64, f64)>,
    from: f64,
    to: f64,
    robot: &RobotModel,
    v: f64,
) -> f64 {
    let mut now = from;
    pending.sort_by(|a, b| a.0.total_cmp(&b.0));
    while let Some(&(at, k)) = pending.first() {
        if at > to {
            break;
        }
        if at > now {
            pose.integrate(v, robot.yaw_rate(v, command), at - now);
            now = at;
        }
        command = k;
        pending.remove(0);
    }
    pose.integrate(v, robot.yaw_rate(v, command), to - now);
    command
}

#[cfg(test)]
mod tests;
