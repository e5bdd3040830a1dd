//! The row tracker: a Kalman filter over frames on the robot's offset from the followed line,
//! the rows' heading, their curvature and their spacing.
//!
//! Owns [`Tracker`], its [`TrackerOptions`], the per-frame [`Measurement`] it takes and the
//! [`TrackState`] it reports. State `x = [e, ψ, κ, s]`: `e` the lateral offset of the
//! reference point from the followed line (metres, positive when the robot is left of it,
//! REP 103), `ψ` the rows' heading in the robot frame (radians, counter-clockwise), `κ` the
//! followed line's curvature (1/m, positive when it bends to the left as the robot drives
//! forward), `s` the row spacing (metres). Motion model at speed `v` (configured; 0 when
//! unknown, then the process noise carries the motion; [`Tracker::set_motion`] gives the
//! odometry's): `ė = −v·sin ψ`, `ψ̇ = v·κ − ω` with the robot's yaw rate `ω` when odometry
//! gives it (otherwise its turning is process noise), `κ̇ = ṡ = 0`.
//!
//! A frame measures the offset only modulo the spacing (from the nearest comb line); the
//! tracker unwraps it to the multiple nearest its prediction, so the followed line keeps its
//! identity however far the robot drifts (no jump to the neighbouring row). Measurements
//! whose innovation fails a χ² gate are rejected as outliers. The filter starts (and
//! restarts after `lost`) only on two consecutive measurements that agree on the nearest
//! line ([`START_AGREEMENT`]): one frame's comb can miss by most of a spacing, and the line
//! the filter starts on is the one it then follows. Fixed-size matrices on the stack: an
//! update allocates nothing.

use nalgebra::{Matrix3, Matrix3x4, Matrix4, Vector3, Vector4};
use serde::{Deserialize, Serialize};

/// The tracker's state, published with every estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrackState {
    /// This frame's measurement updated the filter.
    Tracking,
    /// No usable measurement this frame: the prediction only, for at most the coasting time.
    Coasting,
    /// No usable measurement for longer than the coasting time (or never): no estimate.
    Lost,
    /// The first measurement after `lost`: the filter restarted from it (the followed line
    /// is the nearest one again).
    Reacquired,
}

impl TrackState {
    pub fn name(self) -> &'static str {
        match self {
            TrackState::Tracking => "tracking",
            TrackState::Coasting => "coasting",
            TrackState::Lost => "lost",
            TrackState::Reacquired => "reacquired",
        }
    }

    /// Whether the state carries an estimate.
    pub fn has_estimate(self) -> bool {
        !matches!(self, TrackState::Lost)
    }
}

/// Settings of the tracker (the `[guidance]` configuration's, validated there).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerOptions {
    /// Forward speed, m/s, when known (0: unknown).
    pub speed_mps: f64,
    /// Process noise: random-walk rates of offset (m/√s), heading (rad/√s), curvature
    /// (1/m/√s) and spacing (m/√s).
    pub offset_rate_sd: f64,
    pub heading_rate_sd: f64,
    pub curvature_rate_sd: f64,
    pub spacing_rate_sd: f64,
    /// Standard deviation of the curvature when the filter starts, 1/m.
    pub initial_curvature_sd: f64,
    /// χ² gate on the innovation of (offset, heading, spacing); 3 degrees of freedom. The
    /// curvature has its own gate at the same tail probability (1 degree of freedom).
    pub gate_chi2: f64,
    /// Longest time without a usable measurement before `lost`, seconds.
    pub coast_s: f64,
}

impl Default for TrackerOptions {
    fn default() -> Self {
        TrackerOptions {
            speed_mps: 0.0,
            offset_rate_sd: 0.05,
            heading_rate_sd: 0.05,
            curvature_rate_sd: 0.002,
            spacing_rate_sd: 0.001,
            initial_curvature_sd: 0.05,
            // χ²(3) at 99.9 %
            gate_chi2: 16.27,
            coast_s: 1.0,
        }
    }
}

/// Two consecutive measurements start the filter when their offsets differ by less than
/// this share of the spacing (the same nearest line) and their headings by less than
/// [`START_HEADING_RAD`].
pub const START_AGREEMENT: f64 = 0.25;
/// See [`START_AGREEMENT`]: 3°.
pub const START_HEADING_RAD: f64 = 0.0524;

/// One frame's single-image answer, as the tracker takes it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// Offset from the nearest followed-kind line, metres, in (−s/2, s/2].
    pub offset_m: f64,
    pub offset_sd_m: f64,
    pub heading_rad: f64,
    pub heading_sd_rad: f64,
    pub spacing_m: f64,
    pub spacing_sd_m: f64,
    /// The followed line's curvature and its standard deviation, 1/m, when the frame
    /// measured it (folded in after the rest, with its own gate).
    pub curvature: Option<(f64, f64)>,
}

/// Whether two consecutive measurements agree enough to start the filter on ([`START_AGREEMENT`]).
fn starts_together(a: &Measurement, b: &Measurement) -> bool {
    (a.offset_m - b.offset_m).abs() < START_AGREEMENT * b.spacing_m
        && (a.heading_rad - b.heading_rad).abs() < START_HEADING_RAD
}

/// The tracked estimate after a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tracked {
    pub state: TrackState,
    /// `[e, ψ, κ, s]` and its covariance (`None` when lost).
    pub x: Option<Vector4<f64>>,
    pub p: Option<Matrix4<f64>>,
    /// This frame's measurement was rejected by the gate.
    pub rejected: bool,
}

/// The Kalman filter over frames.
#[derive(Debug, Clone, PartialEq)]
pub struct Tracker {
    opts: TrackerOptions,
    x: Vector4<f64>,
    p: Matrix4<f64>,
    state: TrackState,
    /// Capture time of the filter's state and of the last accepted measurement, ns.
    t_ns: u64,
    last_accept_ns: u64,
    rejected_total: u64,
    /// Speed (m/s) and yaw rate (rad/s) for the next prediction, when given
    /// ([`Self::set_motion`]); otherwise the configured speed and no yaw rate.
    motion: Option<(f64, f64)>,
    /// While lost: the last frame's measurement, which the next must agree with to start.
    pending: Option<Measurement>,
}

impl Tracker {
    pub fn new(opts: TrackerOptions) -> Self {
        Tracker {
            opts,
            x: Vector4::zeros(),
            p: Matrix4::identity(),
            state: TrackState::Lost,
            t_ns: 0,
            last_accept_ns: 0,
            rejected_total: 0,
            motion: None,
            pending: None,
        }
    }

    /// The robot's forward speed (m/s) and yaw rate (rad/s, counter-clockwise) for the
    /// predictions from now on (e.g. from odometry); `None` returns to the configured speed.
    pub fn set_motion(&mut self, motion: Option<(f64, f64)>) {
        self.motion = motion;
    }

    pub fn state(&self) -> TrackState {
        self.state
    }

    /// Measurements rejected by the gate since the start.
    pub fn rejected_total(&self) -> u64 {
        self.rejected_total
    }

    /// Advances the filter to capture time `t_ns` and folds in `m` when there is one.
    pub fn update(&mut self, t_ns: u64, m: Option<&Measurement>) -> Tracked {
        let was_lost = self.state == TrackState::Lost;
        if was_lost {
            let agreed = match (self.pending.take(), m) {
                (Some(p), Some(m)) => starts_together(&p, m),
                _ => false,
            };
            self.pending = m.copied();
            return match m {
                Some(m) if agreed => {
                    self.pending = None;
                    self.start(t_ns, m);
                    self.state = if self.last_accept_ns == 0 {
                        TrackState::Tracking
                    } else {
                        TrackState::Reacquired
                    };
                    self.last_accept_ns = t_ns.max(1);
                    self.tracked(false)
                }
                _ => self.tracked(false),
            };
        }
        let dt = (t_ns.saturating_sub(self.t_ns) as f64 / 1e9).min(10.0);
        if t_ns > self.t_ns {
            self.predict(dt);
            self.t_ns = t_ns;
        }
        let mut rejected = false;
        if let Some(m) = m {
            if self.correct(m) {
                self.last_accept_ns = t_ns.max(1);
                self.state = TrackState::Tracking;
                return self.tracked(false);
            }
            rejected = true;
            self.rejected_total += 1;
        }
        let coasted = t_ns.saturating_sub(self.last_accept_ns) as f64 / 1e9;
        // past the coasting time, or too unsure of the offset to know which line it follows
        let ambiguous = self.p[(0, 0)].sqrt() > self.x[3] / 4.0;
        self.state = if coasted > self.opts.coast_s || ambiguous {
            TrackState::Lost
        } else {
            TrackState::Coasting
        };
        self.tracked(rejected)
    }

    fn tracked(&self, rejected: bool) -> Tracked {
        let live = self.state.has_estimate();
        Tracked {
            state: self.state,
            x: live.then_some(self.x),
            p: live.then_some(self.p),
            rejected,
        }
    }

    fn start(&mut self, t_ns: u64, m: &Measurement) {
        let (k, k_sd) = m
            .curvature
            .filter(|(_, sd)| *sd < self.opts.initial_curvature_sd)
            .unwrap_or((0.0, self.opts.initial_curvature_sd));
        self.x = Vector4::new(m.offset_m, m.heading_rad, k, m.spacing_m);
        self.p = Matrix4::from_diagonal(&Vector4::new(
            m.offset_sd_m.powi(2),
            m.heading_sd_rad.powi(2),
            k_sd.powi(2),
            m.spacing_sd_m.powi(2).max(1e-8),
        ));
        self.t_ns = t_ns;
    }

    /// χ²(1) with the same tail probability as `gate_chi2` has for χ²(3), through the
    /// Wilson–Hilferty cube-root normal approximation (χ²(k)/k ≈ (1 − 2/9k + z·√(2/9k))³).
    fn gate_chi2_1(&self) -> f64 {
        let g = self.opts.gate_chi2;
        let z = ((g / 3.0).cbrt() - (1.0 - 2.0 / 27.0)) / (2.0f64 / 27.0).sqrt();
        (1.0 - 2.0 / 9.0 + z * (2.0f64 / 9.0).sqrt())
            .max(0.0)
            .powi(3)
    }

    /// Gates and folds in a curvature measurement `k` with standard deviation `sd`; false
    /// when the gate rejects it.
    fn correct_curvature(&mut self, k: f64, sd: f64) -> bool {
        let s = self.p[(2, 2)] + sd * sd;
        let y = k - self.x[2];
        if !(s > 0.0 && y * y / s <= self.gate_chi2_1()) {
            return false;
        }
        let gain = self.p.column(2) / s;
        self.x += gain * y;
        // Joseph form with H = e₂ᵀ: (I − K·H)·P·(I − K·H)ᵀ + K·r·Kᵀ
        let mut ikh = Matrix4::<f64>::identity();
        for i in 0..4 {
            ikh[(i, 2)] -= gain[i];
        }
        self.p = ikh * self.p * ikh.transpose() + gain * gain.transpose() * (sd * sd);
        true
    }

    fn predict(&mut self, dt: f64) {
        let o = &self.opts;
        let (v, w) = self.motion.unwrap_or((o.speed_mps, 0.0));
        let psi = self.x[1];
        self.x[0] -= v * dt * psi.sin();
        self.x[1] += (v * self.x[2] - w) * dt;
        let mut f = Matrix4::identity();
        f[(0, 1)] = -v * dt * psi.cos();
        f[(1, 2)] = v * dt;
        let q = Matrix4::from_diagonal(&Vector4::new(
            o.offset_rate_sd.powi(2) * dt,
            o.heading_rate_sd.powi(2) * dt,
            o.curvature_rate_sd.powi(2) * dt,
            o.spacing_rate_sd.powi(2) * dt,
        ));
        self.p = f * self.p * f.transpose() + q;
    }

    /// Gates and folds in `m`; false when the gate rejects it.
    fn correct(&mut self, m: &Measurement) -> bool {
        let s = self.x[3];
        // the measured offset is known modulo the spacing: unwrap it next to the prediction
        let e = m.offset_m + s * ((self.x[0] - m.offset_m) / s).round();
        let z = Vector3::new(e, m.heading_rad, m.spacing_m);
        let mut h = Matrix3x4::zeros();
        h[(0, 0)] = 1.0;
        h[(1, 1)] = 1.0;
        h[(2, 3)] = 1.0;
        let r = Matrix3::from_diagonal(&Vector3::new(
            m.offset_sd_m.powi(2),
            m.heading_sd_rad.powi(2),
            m.spacing_sd_m.powi(2).max(1e-8),
        ));
        let y = z - h * self.x;
        let sm = h * self.p * h.transpose() + r;
        let Some(si) = sm.try_inverse() else {
            return false;
        };
        let d2 = (y.transpose() * si * y)[(0, 0)];
        if d2.is_nan() || d2 > self.opts.gate_chi2 {
            return false;
        }
        let k = self.p * h.transpose() * si;
        self.x += k * y;
        // Joseph form keeps P symmetric and positive
        let ikh = Matrix4::identity() - k * h;
        self.p = ikh * self.p * ikh.transpose() + k * r * k.transpose();
        if let Some((k, sd)) = m.curvature {
            self.correct_curvature(k, sd);
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn meas(e: f64, psi: f64) -> Measurement {
        Measurement {
            offset_m: e,
            offset_sd_m: 0.005,
            heading_rad: psi,
            heading_sd_rad: 0.002,
            spacing_m: 0.5,
            spacing_sd_m: 0.003,
            curvature: None,
        }
    }

    fn wrap(e: f64, s: f64) -> f64 {
        e - (e / s - 0.5).ceil() * s
    }

    #[test]
    fn drift_over_a_whole_spacing_keeps_the_followed_line() {
        let mut t = Tracker::new(TrackerOptions::default());
        let dt = 66_666_667u64;
        // the robot drifts 0.8 m to the left over 8 s: the measurement wraps twice
        let mut last = None;
        for i in 0..120u64 {
            let e = 0.1 * i as f64 / 15.0;
            let r = t.update(1 + i * dt, Some(&meas(wrap(e, 0.5), 0.0)));
            if i == 0 {
                // one measurement does not start the filter
                assert_eq!(r.state, TrackState::Lost);
                continue;
            }
            assert_eq!(r.state, TrackState::Tracking, "frame {i}: {:?}", r.state);
            let x = r.x.unwrap();
            assert!((x[0] - e).abs() < 0.01, "frame {i}: {} vs {e}", x[0]);
            last = Some(x[0]);
        }
        assert!(last.unwrap() > 0.75);
    }

    #[test]
    fn coasts_then_lost_then_reacquired() {
        let o = TrackerOptions {
            coast_s: 0.5,
            ..TrackerOptions::default()
        };
        let mut t = Tracker::new(o);
        assert_eq!(t.update(1, None).state, TrackState::Lost);
        assert_eq!(t.update(2, Some(&meas(0.1, 0.0))).state, TrackState::Lost);
        assert_eq!(
            t.update(3, Some(&meas(0.1, 0.0))).state,
            TrackState::Tracking
        );
        let s = 1_000_000_000u64;
        let r = t.update(s / 5, None);
        assert_eq!(r.state, TrackState::Coasting);
        // the covariance grows while coasting
        assert!(r.p.unwrap()[(0, 0)] > 0.005f64.powi(2));
        assert_eq!(t.update(s, None).state, TrackState::Lost);
        assert!(t.update(s + 1, None).x.is_none());
        // a measurement the next one disagrees with (another line) starts nothing
        assert_eq!(
            t.update(2 * s - 2, Some(&meas(0.2, 0.01))).state,
            TrackState::Lost
        );
        assert_eq!(
            t.update(2 * s - 1, Some(&meas(-0.2, 0.01))).state,
            TrackState::Lost
        );
        let r = t.update(2 * s, Some(&meas(-0.2, 0.01)));
        assert_eq!(r.state, TrackState::Reacquired);
        assert!((r.x.unwrap()[0] + 0.2).abs() < 1e-12);
        assert_eq!(
            t.update(2 * s + 1, Some(&meas(-0.2, 0.01))).state,
            TrackState::Tracking
        );
    }

    #[test]
    fn outlier_rejected_by_the_gate() {
        let mut t = Tracker::new(TrackerOptions::default());
        let dt = 66_666_667u64;
        for i in 0..30u64 {
            t.update(1 + i * dt, Some(&meas(0.05, 0.0)));
        }
        // a heading 10° off in one frame: rejected, the estimate coasts on
        let r = t.update(1 + 30 * dt, Some(&meas(0.05, 0.17)));
        assert!(r.rejected);
        assert_eq!(r.state, TrackState::Coasting);
        assert!(r.x.unwrap()[1].abs() < 1e-3);
        assert_eq!(t.rejected_total(), 1);
        let r = t.update(1 + 31 * dt, Some(&meas(0.05, 0.0)));
        assert_eq!(r.state, TrackState::Tracking);
    }

    #[test]
    fn filter_reduces_noise_and_covariance_matches() {
        // a fixed pose measured with noise of sd 2 cm (as on a rough field): the filtered
        // error is smaller, and the filter's standard deviation says by how much
        let mut t = Tracker::new(TrackerOptions::default());
        let mut rng = crate::synth::Rng::new(7);
        let dt = 66_666_667u64;
        let (mut se_raw, mut se_f, mut var_p, mut n) = (0.0, 0.0, 0.0, 0.0);
        for i in 0..600u64 {
            let noise = 0.02 * rng.normal();
            let m = Measurement {
                offset_sd_m: 0.02,
                ..meas(0.1 + noise, 0.0)
            };
            let r = t.update(1 + i * dt, Some(&m));
            if i >= 30 {
                se_raw += noise * noise;
                se_f += (r.x.unwrap()[0] - 0.1).powi(2);
                var_p += r.p.unwrap()[(0, 0)];
                n += 1.0;
            }
        }
        let (raw, filtered, claimed) = (se_raw / n, se_f / n, var_p / n);
        assert!(filtered < 0.75 * raw, "{filtered} vs {raw}");
        assert!(
            claimed > 0.5 * filtered && claimed < 2.0 * filtered,
            "{claimed} vs {filtered}"
        );
    }

    #[test]
    fn motion_model_predicts_the_offset_at_known_speed() {
        let o = TrackerOptions {
            speed_mps: 1.0,
            ..TrackerOptions::default()
        };
        let mut t = Tracker::new(o);
        t.update(0, Some(&meas(0.0, 0.05)));
        t.update(1, Some(&meas(0.0, 0.05)));
        // heading +0.05: the rows run to the left of the nose, the robot moves right of them
        let r = t.update(1 + 200_000_000, None);
        let x = r.x.unwrap();
        assert!((x[0] + 0.2 * 0.05f64.sin()).abs() < 1e-9, "{}", x[0]);
        // odometry: 2 m/s turning left at 0.1 rad/s; the rows turn right in the robot frame
        t.set_motion(Some((2.0, 0.1)));
        let before = x;
        let x = t.update(1 + 300_000_000, None).x.unwrap();
        assert!(
            (x[0] - (before[0] - 0.2 * before[1].sin())).abs() < 1e-9,
            "{}",
            x[0]
        );
        assert!((x[1] - (before[1] + 0.1 * (2.0 * before[2] - 0.1))).abs() < 1e-9);
    }

    #[test]
    fn curvature_measurements_converge_and_outliers_are_gated() {
        let mut t = Tracker::new(TrackerOptions::default());
        let dt = 66_666_667u64;
        let mut rng = crate::synth::Rng::new(3);
        let mut last = 0.0;
        for i in 0..60u64 {
            let m = Measurement {
                curvature: Some((0.02 + 0.004 * rng.normal(), 0.004)),
                ..meas(0.05, 0.0)
            };
            let r = t.update(1 + i * dt, Some(&m));
            if i == 0 {
                continue;
            }
            assert_eq!(r.state, TrackState::Tracking);
            last = r.x.unwrap()[2];
        }
        assert!((last - 0.02).abs() < 0.002, "{last}");
        let sd = t.p[(2, 2)].sqrt();
        assert!(sd < 0.004, "{sd}");
        // a wild curvature is refused; the frame's offset is still taken
        let m = Measurement {
            curvature: Some((0.3, 0.004)),
            ..meas(0.05, 0.0)
        };
        let r = t.update(1 + 60 * dt, Some(&m));
        assert_eq!(r.state, TrackState::Tracking);
        assert!((r.x.unwrap()[2] - 0.02).abs() < 0.003);
        // the χ²(1) gate matches χ²(3)'s 99.9 % tail: about 10.8
        assert!((t.gate_chi2_1() - 10.83).abs() < 0.3, "{}", t.gate_chi2_1());
    }
}
