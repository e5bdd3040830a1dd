//! Mapping the camera's timestamp clock onto the host's UNIX-epoch clock.
//!
//! A GigE camera stamps each frame with its own free-running counter (reset at power-up), and
//! the host notes when the frame's first packet arrived. The difference host − camera is the
//! clock offset plus a transport delay that is never negative and jitters upwards. The
//! estimator follows the lower envelope of that difference: it jumps down at once to a smaller
//! difference and creeps up slowly otherwise, so it tracks the clocks' drift (tens of ppm, i.e.
//! seconds over a field day) without inheriting the transport jitter. Capture times then keep
//! the camera's exact frame spacing and stay comparable with host receive times.

/// Options of the offset estimator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraClockOptions {
    /// Fraction of an upward difference applied per frame (0..=1).
    pub rise_gain: f64,
    /// Largest clock drift followed upwards, in parts per million of the camera time elapsed
    /// since the previous frame: bounds how much transport jitter can leak in.
    pub max_drift_ppm: f64,
}

impl Default for CameraClockOptions {
    fn default() -> Self {
        CameraClockOptions {
            rise_gain: 1.0 / 64.0,
            max_drift_ppm: 200.0,
        }
    }
}

/// Lower-envelope estimate of host time − camera time.
#[derive(Debug, Clone)]
pub struct CameraClock {
    opts: CameraClockOptions,
    offset_ns: Option<i128>,
    last_camera_ns: u64,
}

impl CameraClock {
    pub fn new(opts: CameraClockOptions) -> Self {
        CameraClock {
            opts,
            offset_ns: None,
            last_camera_ns: 0,
        }
    }

    /// Forgets the offset (the camera's clock restarts when it reconnects).
    pub fn reset(&mut self) {
        self.offset_ns = None;
    }

    /// The current offset, host − camera, ns.
    pub fn offset_ns(&self) -> Option<i128> {
        self.offset_ns
    }

    /// Feeds one frame's camera timestamp and host arrival time (ns since the epoch) and
    /// returns its capture time on the host clock. A camera timestamp of 0 (cameras without a
    /// timestamp) yields the host time.
    pub fn capture_ns(&mut self, camera_ns: u64, host_ns: u64) -> u64 {
        if camera_ns == 0 {
            return host_ns;
        }
        let d = host_ns as i128 - camera_ns as i128;
        let off = match self.offset_ns {
            None => d,
            Some(o) if d < o => d,
            Some(o) => {
                let elapsed = camera_ns.saturating_sub(self.last_camera_ns) as f64;
                let rise = ((d - o) as f64 * self.opts.rise_gain)
                    .min(elapsed * self.opts.max_drift_ppm * 1e-6);
                o + rise as i128
            }
        };
        self.last_camera_ns = camera_ns;
        self.offset_ns = Some(off);
        (camera_ns as i128 + off).clamp(0, u64::MAX as i128) as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tiny deterministic generator (no dependency) for jitter.
    fn lcg(state: &mut u64) -> u64 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        *state >> 33
    }

    #[test]
    fn keeps_camera_spacing_and_ignores_jitter() {
        let mut clk = CameraClock::new(CameraClockOptions::default());
        let base_host = 1_700_000_000_000_000_000u64;
        let period = 66_666_667u64;
        let mut seed = 7;
        let mut prev = None;
        for k in 0..2000u64 {
            let cam = 5_000_000 + k * period;
            let jitter = lcg(&mut seed) % 3_000_000; // up to 3 ms transport delay
            let host = base_host + k * period + 1_000_000 + jitter;
            let cap = clk.capture_ns(cam, host);
            assert!(cap <= host, "capture after arrival at frame {k}");
            if let Some(p) = prev {
                let dt = cap as i64 - p as i64 - period as i64;
                if k > 200 {
                    // Raw arrival spacing jitters by up to 3 ms.
                    assert!(dt.abs() < 500_000, "spacing off by {dt} ns at {k}");
                }
            }
            prev = Some(cap);
            if k > 200 {
                // The capture time carries the minimum transport delay (1 ms) as a constant
                // bias plus a fraction of the jitter, never the jitter itself (up to 3 ms).
                let bias = cap as i64 - (base_host + k * period) as i64;
                assert!(
                    (1_000_000..=2_000_000).contains(&bias),
                    "bias {bias} at {k}"
                );
            }
        }
    }

    #[test]
    fn follows_drift_both_ways() {
        for ppm in [-50.0f64, 50.0] {
            let mut clk = CameraClock::new(CameraClockOptions::default());
            let period = 66_666_667u64;
            let mut worst = 0i64;
            for k in 0..60_000u64 {
                // One hour at 15 Hz.
                let cam = 1_000 + k * period;
                let host_clean = (k as f64 * period as f64 * (1.0 + ppm * 1e-6)) as u64;
                let host = 10_000_000_000 + host_clean + 500_000;
                let cap = clk.capture_ns(cam, host);
                if k > 1000 {
                    worst = worst.max((host as i64 - cap as i64 - 500_000).abs());
                }
            }
            // 180 ms of accumulated drift, tracked to within a millisecond.
            assert!(worst < 1_000_000, "{ppm} ppm: worst {worst} ns");
        }
    }

    #[test]
    fn zero_camera_time_uses_host() {
        let mut clk = CameraClock::new(CameraClockOptions::default());
        assert_eq!(clk.capture_ns(0, 42), 42);
        assert_eq!(clk.offset_ns(), None);
        clk.capture_ns(10, 100);
        clk.reset();
        assert_eq!(clk.offset_ns(), None);
    }
}
