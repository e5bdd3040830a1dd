//! The end of the rows and the crop around the robot, filtered over frames with the robot's
//! motion.
//!
//! Owns [`Headland`]. One frame's row fit says where the rows end (the last plant seen, none
//! after it: [`RowFitMeasurement::end_of_rows_m`]) and whether plants grow near the robot
//! ([`RowFitMeasurement::crop_near`]); a frame can be wrong (a plant missed, a weed taken for
//! one, an empty stretch whose far side is not yet in view). The end is tracked as a distance
//! along the rows with its rate (a two-state Kalman filter, `[end, rate]`): the rate is the
//! robot's speed when known (odometry, or the configured speed), else it is estimated from the
//! end's own motion. A frame's end updates the track within a gate; a frame that sees the rows
//! go on past the tracked end (plants after it, an empty stretch rather than the end) counts
//! against it, and [`DROP_FRAMES`] of those in a row drop it. The end is published once
//! [`CONFIRM_FRAMES`] frames agreed, while within [`END_RANGE_M`](super::rowfit::END_RANGE_M). The crop changes only
//! when [`CROP_FRAMES`] frames in a row say so, so one frame does not flip it. Fixed-size
//! state: an update allocates nothing.

use super::rowfit::RowFitMeasurement;
use super::CropState;

/// Frames whose end agrees with the track before it is published.
pub const CONFIRM_FRAMES: u32 = 3;
/// Frames in a row that contradict the tracked end before it is dropped.
pub const DROP_FRAMES: u32 = 4;
/// Frames in a row that must say a new crop state before it is published.
pub const CROP_FRAMES: u32 = 2;
/// Longest time the end is predicted without any frame measuring the rows, seconds.
const COAST_S: f64 = 2.0;
/// Gate on a frame's end around the prediction: at least this, metres (0.2 m bins).
const GATE_M: f64 = 0.6;
/// Standard deviation of one frame's end, metres (the bins are 0.2 m).
const MEASURE_SD_M: f64 = 0.15;
/// Random walk of the end's rate, (m/s)/√s, and of the end itself, m/√s.
const RATE_WALK: f64 = 0.3;
const END_WALK: f64 = 0.05;
/// Standard deviation of the rate when the speed is known, m/s, and when it is not.
const KNOWN_RATE_SD: f64 = 0.05;
const UNKNOWN_RATE_SD: f64 = 1.0;

/// The tracked end of the rows: distance along the rows from the camera's foot point, its rate.
#[derive(Debug, Clone, Copy, PartialEq)]
struct EndTrack {
    end_m: f64,
    rate: f64,
    /// Covariance of (end, rate).
    p: [[f64; 2]; 2],
    agreed: u32,
    contradicted: u32,
    /// Capture time of the last frame that measured the rows, ns.
    seen_ns: u64,
}

/// The end of the rows and the crop state over frames.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Headland {
    end: Option<EndTrack>,
    t_ns: u64,
    crop: Option<CropState>,
    candidate: CropState,
    candidate_frames: u32,
}

impl Headland {
    pub fn new() -> Self {
        Headland::default()
    }

    /// Folds in one frame at capture time `t_ns`: its crop (as the frame alone says it), its
    /// row fit (`None` when the frame measured no rows) and the robot's forward speed when
    /// known (m/s). Returns the confirmed end of the rows (metres from the camera's foot
    /// point, published by the caller within [`END_RANGE_M`](super::rowfit::END_RANGE_M)) and the published crop.
    pub fn update(
        &mut self,
        t_ns: u64,
        frame_crop: CropState,
        fit: Option<&RowFitMeasurement>,
        speed_mps: Option<f64>,
    ) -> (Option<f64>, CropState) {
        let dt = if self.t_ns == 0 || t_ns <= self.t_ns {
            0.0
        } else {
            ((t_ns - self.t_ns) as f64 / 1e9).min(10.0)
        };
        self.t_ns = t_ns;
        self.predict(dt, speed_mps);
        let measured_rows = frame_crop != CropState::NoCrop;
        if let Some(fit) = fit.filter(|_| measured_rows) {
            self.measure(t_ns, fit.end_of_rows_m, speed_mps);
        }
        if let Some(e) = &self.end {
            if t_ns.saturating_sub(e.seen_ns) as f64 / 1e9 > COAST_S {
                self.end = None;
            }
        }
        let end = self
            .end
            .filter(|e| e.agreed >= CONFIRM_FRAMES)
            .map(|e| e.end_m);
        (end, self.crop(frame_crop))
    }

    fn predict(&mut self, dt: f64, speed_mps: Option<f64>) {
        let Some(e) = &mut self.end else {
            return;
        };
        if let Some(v) = speed_mps {
            // the known speed, as a measurement of the rate
            let r = KNOWN_RATE_SD * KNOWN_RATE_SD;
            let s = e.p[1][1] + r;
            let k = [e.p[0][1] / s, e.p[1][1] / s];
            let y = -v - e.rate;
            e.end_m += k[0] * y;
            e.rate += k[1] * y;
            e.p = joseph(e.p, k, 1, r);
        }
        if dt > 0.0 {
            e.end_m += e.rate * dt;
            let [[a, b], [_, d]] = e.p;
            // F = [[1, dt], [0, 1]]; Q on both
            let a2 = a + 2.0 * dt * b + dt * dt * d + END_WALK * END_WALK * dt;
            let b2 = b + dt * d;
            let d2 = d + RATE_WALK * RATE_WALK * dt;
            e.p = [[a2, b2], [b2, d2]];
        }
    }

    /// A frame that measured the rows: its end (`None`: the rows go on past the bins' reach
    /// or the frame saw them resume after an empty stretch).
    fn measure(&mut self, t_ns: u64, end: Option<f64>, speed_mps: Option<f64>) {
        match (&mut self.end, end) {
            (Some(e), Some(m)) => {
                let r = MEASURE_SD_M * MEASURE_SD_M;
                let s = e.p[0][0] + r;
                let y = m - e.end_m;
                if y.abs() <= GATE_M.max(3.0 * s.sqrt()) {
                    let k = [e.p[0][0] / s, e.p[1][0] / s];
                    e.end_m += k[0] * y;
                    e.rate += k[1] * y;
                    e.p = joseph(e.p, k, 0, r);
                    e.agreed += 1;
                    e.contradicted = 0;
                    e.seen_ns = t_ns;
                } else {
                    self.contradict(t_ns, Some(m), speed_mps);
                }
            }
            (Some(_), None) => self.contradict(t_ns, None, speed_mps),
            (None, Some(m)) => self.end = Some(Self::start(t_ns, m, speed_mps)),
            (None, None) => {}
        }
    }

    /// A frame disagrees with the tracked end: after [`DROP_FRAMES`] in a row the track is
    /// dropped (and restarted from this frame's end when it has one).
    fn contradict(&mut self, t_ns: u64, end: Option<f64>, speed_mps: Option<f64>) {
        let Some(e) = &mut self.end else {
            return;
        };
        e.contradicted += 1;
        if e.contradicted >= DROP_FRAMES {
            self.end = end.map(|m| Self::start(t_ns, m, speed_mps));
        }
    }

    fn start(t_ns: u64, end_m: f64, speed_mps: Option<f64>) -> EndTrack {
        let (rate, rate_sd) = match speed_mps {
            Some(v) => (-v, KNOWN_RATE_SD),
            None => (0.0, UNKNOWN_RATE_SD),
        };
        EndTrack {
            end_m,
            rate,
            p: [[MEASURE_SD_M * MEASURE_SD_M, 0.0], [0.0, rate_sd * rate_sd]],
            agreed: 1,
            contradicted: 0,
            seen_ns: t_ns,
        }
    }

    /// The published crop: a new state once [`CROP_FRAMES`] frames in a row said it (the
    /// first frame's at once).
    fn crop(&mut self, frame_crop: CropState) -> CropState {
        let Some(published) = self.crop else {
            self.crop = Some(frame_crop);
            return frame_crop;
        };
        if frame_crop == published {
            self.candidate_frames = 0;
            return published;
        }
        if frame_crop == self.candidate {
            self.candidate_frames += 1;
        } else {
            self.candidate = frame_crop;
            self.candidate_frames = 1;
        }
        if self.candidate_frames >= CROP_FRAMES {
            self.crop = Some(frame_crop);
            self.candidate_frames = 0;
            return frame_crop;
        }
        published
    }
}

/// The Joseph-form covariance update of a 2-state filter measured in state `i` with gain `k`
/// and measurement variance `r`.
fn joseph(p: [[f64; 2]; 2], k: [f64; 2], i: usize, r: f64) -> [[f64; 2]; 2] {
    // A = I − K·H, H = e_i
    let mut a = [[1.0, 0.0], [0.0, 1.0]];
    a[0][i] -= k[0];
    a[1][i] -= k[1];
    let mut out = [[0.0; 2]; 2];
    for (r_, row) in out.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            let mut sum = 0.0;
            for m in 0..2 {
                for n in 0..2 {
                    sum += a[r_][m] * p[m][n] * a[c][n];
                }
            }
            *v = sum + k[r_] * k[c] * r;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT: u64 = 66_666_667;

    fn fit(end: Option<f64>, near: bool) -> RowFitMeasurement {
        RowFitMeasurement {
            curvature_per_m: Some(0.0),
            sd_per_m: 0.001,
            points: 1000,
            end_of_rows_m: end,
            crop_near: near,
            shift_m: 0.0,
            turn: 0.0,
            shift_sd_m: 0.0,
        }
    }

    /// Drives at 1 m/s towards an end first seen 7 m ahead, each frame's end off by the
    /// given error; the published ends and their truths.
    fn approach(speed: Option<f64>, error: impl Fn(u64) -> Option<f64>) -> Vec<(f64, Option<f64>)> {
        let mut h = Headland::new();
        (0..150u64)
            .map(|i| {
                let truth = 7.0 - i as f64 / 15.0;
                let m = error(i).map(|e| truth + e);
                let (end, _) = h.update(1 + i * DT, CropState::Rows, Some(&fit(m, true)), speed);
                (truth, end.filter(|e| e.abs() <= 5.0))
            })
            .collect()
    }

    #[test]
    fn the_end_is_confirmed_then_followed_with_the_motion() {
        for speed in [Some(1.0), None] {
            // noisy by ±0.2 m, and every seventh frame misses the end
            let out = approach(speed, |i| {
                (i % 7 != 3).then_some(if i % 2 == 0 { 0.2 } else { -0.2 })
            });
            for (truth, end) in &out {
                // (within a bin of the range's edge the filtered end may lie just outside)
                if truth.abs() <= 4.8 {
                    let e = end.unwrap_or_else(|| panic!("{speed:?}: missed at {truth}"));
                    assert!((e - truth).abs() < 0.25, "{speed:?}: {e} vs {truth}");
                } else if truth.abs() > 5.2 {
                    assert!(end.is_none());
                }
            }
        }
    }

    #[test]
    fn an_empty_stretch_seen_to_resume_drops_the_end() {
        // a far empty stretch looks like the end until its far side comes into view
        let out = approach(Some(1.0), |i| (i < 20).then_some(0.0));
        for (i, (_, end)) in out.iter().enumerate() {
            if i >= 20 + DROP_FRAMES as usize {
                assert!(end.is_none(), "frame {i}: {end:?}");
            }
        }
        // one wrong frame does not drop it
        let out = approach(Some(1.0), |i| (i != 60).then_some(0.0));
        assert!(out.iter().skip(40).all(|(_, e)| e.is_some()));
    }

    #[test]
    fn a_single_frame_does_not_flip_the_crop() {
        let mut h = Headland::new();
        let mut t = 1;
        let mut step = |c: CropState| {
            t += DT;
            h.update(t, c, Some(&fit(None, c == CropState::Rows)), Some(1.0))
                .1
        };
        assert_eq!(step(CropState::Rows), CropState::Rows);
        assert_eq!(step(CropState::EmptyStretch), CropState::Rows);
        assert_eq!(step(CropState::Rows), CropState::Rows);
        assert_eq!(step(CropState::EmptyStretch), CropState::Rows);
        assert_eq!(step(CropState::EmptyStretch), CropState::EmptyStretch);
        assert_eq!(step(CropState::NoCrop), CropState::EmptyStretch);
        assert_eq!(step(CropState::NoCrop), CropState::NoCrop);
    }

    #[test]
    fn without_rows_the_end_coasts_then_goes() {
        let mut h = Headland::new();
        let mut last = None;
        for i in 0..10u64 {
            let truth = 3.0 - i as f64 / 15.0;
            last = h
                .update(
                    1 + i * DT,
                    CropState::Rows,
                    Some(&fit(Some(truth), true)),
                    Some(1.0),
                )
                .0;
        }
        assert!((last.unwrap() - (3.0 - 9.0 / 15.0)).abs() < 0.05);
        // no rows measured: predicted with the speed
        let (end, crop) = h.update(1 + 24 * DT, CropState::NoCrop, None, Some(1.0));
        assert!((end.unwrap() - (3.0 - 24.0 / 15.0)).abs() < 0.1, "{end:?}");
        assert_eq!(crop, CropState::Rows);
        let (end, _) = h.update(1 + 60 * DT, CropState::NoCrop, None, Some(1.0));
        assert!(end.is_none());
    }
}
