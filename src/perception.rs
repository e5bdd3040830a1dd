//! The per-frame perception step: a frame in, its estimate out.
//!
//! Owns the two halves of a frame's perception and their composition. [`Measurement`] is
//! what can run on several frames at once: the detector and, with row guidance, the rows'
//! fit on the ground ([`RowFit`]); the node's pipeline runs one per worker. [`Tracking`] is
//! what must see the frames in order: row guidance (the tracker) and the prior its
//! prediction gives the next frames' detector ([`NarrowSearch`]); the pipeline's publisher
//! runs it. [`Perception`] runs both, one frame after the other, as `omnirow eval guidance`
//! and `omnirow eval real --track` do. The step's thresholds live here: the quality below
//! which an estimate is `degraded` ([`DEFAULT_MIN_QUALITY`], `[pipeline] min_quality`) and
//! the prior's window ([`NarrowSearch`], `[pipeline] narrow_*`).

use crate::camera::{Calibration, Mounting};
use crate::detect::{DetectError, Detection, Detector, DetectorOptions, DetectorPrior};
use crate::estimate::Estimate;
use crate::frame::Frame;
use crate::guidance::{Guidance, GuidanceError, GuidanceOptions, RowFit, RowFitOptions};
use std::time::Instant;

/// Estimates whose quality is below this are `degraded` unless configured otherwise
/// (`[pipeline] min_quality`).
pub const DEFAULT_MIN_QUALITY: f64 = 0.3;

/// An error of the perception step: the detector's, or row guidance's configuration.
#[derive(Debug, thiserror::Error)]
pub enum PerceptionError {
    #[error("detector: {0}")]
    Detect(#[from] DetectError),
    #[error("guidance: {0}")]
    Guidance(#[from] GuidanceError),
    #[error("frame {seq}: {problem}")]
    Frame { seq: u64, problem: String },
}

/// How the tracker's prediction becomes the detector's prior: the vanishing point of the
/// predicted heading and the last frame's tilt, in a window of `sigmas` times the heading's
/// standard deviation, at least `min_window_rad` (the tilt is not tracked and moves with
/// the ground). While the tracker is lost there is no prior.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NarrowSearch {
    pub mounting: Mounting,
    pub min_window_rad: f64,
    pub sigmas: f64,
}

impl NarrowSearch {
    /// The defaults (`[pipeline]`): a window of 4 σ of the heading, at least 2°.
    pub fn new(mounting: Mounting) -> Self {
        NarrowSearch {
            mounting,
            min_window_rad: 2f64.to_radians(),
            sigmas: 4.0,
        }
    }

    /// The prior for the frames after `est` (guidance applied), or `None`. `tilt_rad`: the
    /// last tilt the detector measured.
    pub fn prior(&self, est: &Estimate, tilt_rad: f64) -> Option<DetectorPrior> {
        let g = est.guidance.as_ref()?;
        if !g.tracking.has_estimate() {
            return None;
        }
        let heading = g.heading_rad?;
        let sd = g.covariance?[1][1].max(0.0).sqrt();
        let window = (self.sigmas * sd)
            .max(self.min_window_rad)
            .min(crate::detect::prior::MAX_WINDOW_RAD);
        (heading.is_finite() && window.is_finite())
            .then(|| DetectorPrior::from_heading_tilt(heading, tilt_rad, window, &self.mounting))
    }
}

/// The half of the step that frames can go through in any order: the detector and, with
/// row guidance, the rows' fit on the ground.
#[derive(Debug)]
pub struct Measurement {
    detector: Detector,
    row_fit: Option<RowFit>,
    min_quality: f64,
    /// The last rows' fit's time, milliseconds.
    row_fit_ms: f64,
}

impl Measurement {
    /// The detector for `cal` with `detector` options, each frame's independent parts on
    /// `threads` threads, pinned to cores from the `pin_from`-th allowed CPU on when given
    /// ([`Detector::set_pinned_threads`]); `row_fit`: also fit the rows on the ground (for
    /// row guidance); estimates below `min_quality` are `degraded`.
    pub fn new(
        cal: &Calibration,
        detector: DetectorOptions,
        threads: usize,
        pin_from: Option<usize>,
        row_fit: bool,
        min_quality: f64,
    ) -> Result<Self, DetectError> {
        let mut d = Detector::new(cal, detector)?;
        match pin_from {
            Some(first) => d.set_pinned_threads(threads, first)?,
            None => d.set_threads(threads)?,
        }
        Ok(Measurement {
            detector: d,
            row_fit: row_fit.then(|| RowFit::new(cal.mounting, RowFitOptions::default())),
            min_quality,
            row_fit_ms: 0.0,
        })
    }

    /// Detects in `frame` (narrowed by `prior` when there is one) into `det`, and returns
    /// the frame's estimate with the rows' fit on the ground: everything but guidance.
    pub fn measure(
        &mut self,
        frame: &Frame,
        prior: Option<&DetectorPrior>,
        det: &mut Detection,
    ) -> Result<Estimate, PerceptionError> {
        let t = Instant::now();
        let view = frame.view().map_err(|e| PerceptionError::Frame {
            seq: frame.seq,
            problem: e.to_string(),
        })?;
        self.detector.process_with_prior(&view, prior, det)?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let mut est = Estimate::from_detection(frame, det, ms, self.min_quality);
        est.row_fit = self.row_fit(det);
        est.stage_ms = self.stage_ms();
        Ok(est)
    }

    /// Detects in `frame`'s `view` into `det` (the detector alone).
    pub fn detect(
        &mut self,
        view: &crate::frame::ImageView,
        prior: Option<&DetectorPrior>,
        det: &mut Detection,
    ) -> Result<(), DetectError> {
        self.detector.process_with_prior(view, prior, det)
    }

    /// The rows' fit on the ground from the points of the image just detected into `det`,
    /// when the rows are fitted.
    pub fn row_fit(&mut self, det: &Detection) -> Option<crate::guidance::RowFitMeasurement> {
        let t = Instant::now();
        let fit = self
            .row_fit
            .as_mut()?
            .measure_detection(det, self.detector.points());
        self.row_fit_ms = t.elapsed().as_secs_f64() * 1e3;
        fit
    }

    pub fn detector(&self) -> &Detector {
        &self.detector
    }

    /// Where the last frame's time went, milliseconds ([`crate::estimate::STAGES`]).
    pub fn stage_ms(&self) -> [f64; 4] {
        let t = self.detector.last_times();
        let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
        [ms(t.prepare), ms(t.rows), ms(t.vanishing), self.row_fit_ms]
    }
}

/// The half of the step that must see the frames in order: row guidance, and the prior its
/// prediction gives the next frames.
#[derive(Debug)]
pub struct Tracking {
    guidance: Guidance,
    narrow: Option<NarrowSearch>,
    /// The last tilt the detector measured (the tracker does not track it).
    tilt_rad: f64,
}

impl Tracking {
    /// Row guidance, and with `narrow` the prior for the next frames.
    pub fn new(guidance: Guidance, narrow: Option<NarrowSearch>) -> Self {
        Tracking {
            guidance,
            narrow,
            tilt_rad: 0.0,
        }
    }

    /// Folds the next frame's estimate into the tracker (its `guidance` object filled in);
    /// the prior for the frames after it.
    pub fn track(&mut self, est: &mut Estimate) -> Option<DetectorPrior> {
        est.apply_guidance(&mut self.guidance);
        let n = self.narrow.as_ref()?;
        if let Some(t) = est.tilt_rad {
            self.tilt_rad = t;
        }
        n.prior(est, self.tilt_rad)
    }
}

/// What the whole step is told.
#[derive(Debug, Clone, PartialEq)]
pub struct PerceptionOptions {
    pub detector: DetectorOptions,
    /// Row guidance (`None`: the detector's estimate alone).
    pub guidance: Option<GuidanceOptions>,
    /// With guidance, narrow each frame's search by the tracker's prediction (on by default,
    /// as in the node: `[pipeline] narrow_search`).
    pub narrow_search: bool,
    pub min_quality: f64,
    /// Threads each frame's independent parts run on ([`Detector::set_threads`]).
    pub threads: usize,
}

impl Default for PerceptionOptions {
    fn default() -> Self {
        PerceptionOptions {
            detector: DetectorOptions::default(),
            guidance: Some(GuidanceOptions::default()),
            narrow_search: true,
            min_quality: DEFAULT_MIN_QUALITY,
            threads: 1,
        }
    }
}

/// The whole step, one frame after the other.
#[derive(Debug)]
pub struct Perception {
    measurement: Measurement,
    tracking: Option<Tracking>,
    prior: Option<DetectorPrior>,
    det: Detection,
    opts: PerceptionOptions,
    mounting: Mounting,
}

impl Perception {
    pub fn new(cal: &Calibration, opts: &PerceptionOptions) -> Result<Self, PerceptionError> {
        Ok(Perception {
            measurement: Measurement::new(
                cal,
                opts.detector.clone(),
                opts.threads,
                None,
                opts.guidance.is_some(),
                opts.min_quality,
            )?,
            tracking: tracking(opts, &cal.mounting)?,
            prior: None,
            det: Detection::default(),
            opts: opts.clone(),
            mounting: cal.mounting,
        })
    }

    /// Starts a new sequence of frames: a fresh tracker and rows' fit, no prior; the
    /// detector (and its setup for the image size) stays.
    pub fn reset(&mut self) -> Result<(), PerceptionError> {
        self.tracking = tracking(&self.opts, &self.mounting)?;
        if self.opts.guidance.is_some() {
            self.measurement.row_fit = Some(RowFit::new(self.mounting, RowFitOptions::default()));
        }
        self.prior = None;
        Ok(())
    }

    /// The next frame's estimate, guidance included.
    pub fn process(&mut self, frame: &Frame) -> Result<Estimate, PerceptionError> {
        let mut est = self
            .measurement
            .measure(frame, self.prior.as_ref(), &mut self.det)?;
        if let Some(t) = self.tracking.as_mut() {
            self.prior = t.track(&mut est);
        }
        Ok(est)
    }

    /// The last frame's detection.
    pub fn detection(&self) -> &Detection {
        &self.det
    }

    pub fn detector(&self) -> &Detector {
        &self.measurement.detector
    }

    pub fn detector_mut(&mut self) -> &mut Detector {
        &mut self.measurement.detector
    }
}

/// The tracking half `opts` asks for, for a camera mounted as `mounting`.
fn tracking(
    opts: &PerceptionOptions,
    mounting: &Mounting,
) -> Result<Option<Tracking>, PerceptionError> {
    let Some(g) = &opts.guidance else {
        return Ok(None);
    };
    Ok(Some(Tracking::new(
        Guidance::new(*g, *mounting)?,
        opts.narrow_search.then(|| NarrowSearch::new(*mounting)),
    )))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::PriorOutcome;
    use crate::estimate::Status;
    use crate::source::synthetic::SyntheticDrive;

    fn drive() -> SyntheticDrive {
        let weaving = crate::eval::guidance::scenarios(306, 256, 1.0).remove(0);
        SyntheticDrive::new(weaving.drive).unwrap()
    }

    #[test]
    fn the_step_tracks_and_narrows_its_own_search() {
        let mut d = drive();
        let cal = d.calibration().clone();
        let opts = PerceptionOptions {
            narrow_search: true,
            ..Default::default()
        };
        let mut p = Perception::new(&cal, &opts).unwrap();
        for seq in 0..6 {
            let est = p.process(&d.frame_at(seq).unwrap()).unwrap();
            assert_eq!(est.status, Status::Ok, "frame {seq}");
            let g = est.guidance.expect("guidance on every frame");
            // the tracker starts on two agreeing frames
            assert_eq!(g.lateral_offset_m.is_some(), seq > 0, "frame {seq}");
            assert!(est.row_fit.is_some(), "frame {seq}");
            // every stage's time is measured
            assert!(
                est.stage_ms.iter().all(|&ms| ms > 0.0),
                "{:?}",
                est.stage_ms
            );
        }
        // once the tracker has an estimate, the detector searches in its window
        assert_eq!(p.detector().last_prior(), PriorOutcome::Accepted);
        // a new sequence starts without a prior
        p.reset().unwrap();
        p.process(&d.frame_at(0).unwrap()).unwrap();
        assert_eq!(p.detector().last_prior(), PriorOutcome::None);
    }

    #[test]
    fn without_guidance_the_estimate_is_the_detectors_and_its_quality_threshold_holds() {
        let mut d = drive();
        let cal = d.calibration().clone();
        let frame = d.frame_at(0).unwrap();
        let plain = PerceptionOptions {
            guidance: None,
            ..Default::default()
        };
        let est = Perception::new(&cal, &plain)
            .unwrap()
            .process(&frame)
            .unwrap();
        assert!(est.guidance.is_none() && est.row_fit.is_none());
        assert_eq!(est.status, Status::Ok);
        let strict = PerceptionOptions {
            min_quality: 1.0,
            ..plain
        };
        let est = Perception::new(&cal, &strict)
            .unwrap()
            .process(&frame)
            .unwrap();
        assert_eq!(est.status, Status::Degraded, "quality {}", est.quality);
    }

    #[test]
    fn a_degraded_frame_still_measures_for_guidance() {
        // every frame below the (impossible) minimum quality: published `degraded`, yet
        // its vanishing point and rows go to guidance, which tracks on them
        let mut d = drive();
        let cal = d.calibration().clone();
        let opts = PerceptionOptions {
            min_quality: 1.0,
            ..Default::default()
        };
        let mut p = Perception::new(&cal, &opts).unwrap();
        for seq in 0..4 {
            let est = p.process(&d.frame_at(seq).unwrap()).unwrap();
            assert_eq!(est.status, Status::Degraded, "frame {seq}");
            let g = est.guidance.expect("guidance on every frame");
            assert!(g.frame.is_some(), "frame {seq}: measured");
            if seq == 0 {
                continue; // the tracker starts on the second frame
            }
            let truth = est.truth.as_ref().unwrap();
            let off = g.lateral_offset_m.expect("an offset");
            let path = truth.path();
            assert!(
                (off - truth.path_offset_m(path)).abs() < 0.03,
                "frame {seq}: {off}"
            );
        }
    }
}
