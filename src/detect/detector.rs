//! The detector: one image in; rows, their vanishing point, heading and tilt out.
//!
//! Owns [`Detector`], which runs a frame through the stages in order: the preparation
//! ([`Preparer`]: vegetation, smoothing, threshold → the kept points), the method's rows
//! ([`RowMethod::rows`]), the vote for their vanishing point ([`VanishingStage`], paper
//! II-E), the method's finishing steps ([`RowMethod::finish`]), and heading and tilt from
//! the vanishing point ([`heading_tilt`]). With a prior from the tracker the rows and the
//! vanishing point are first sought in its window, and everywhere when that finds nothing
//! there. Every buffer is the detector's: the hot path allocates nothing once warmed up.

use super::method::combined::CombinedMethod;
use super::method::edge::EdgeMethod;
use super::method::hough::HoughMethod;
use super::method::pencil::PencilMethod;
use super::method::strips::StripsMethod;
use super::method::{Frame, RowMethod};
use super::options::{resolve, DetectorOptions};
use super::pose::heading_tilt;
use super::prepare::{PrepareResult, Preparer};
use super::prior::DetectorPrior;
use super::types::{DetectError, Detection, Method, Points};
use super::vanishing::{VanishingParams, VanishingStage};
use crate::camera::{Calibration, Mounting};
use crate::frame::ImageView;
use nalgebra::Vector3;
use rayon::ThreadPool;
use std::any::Any;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// What a prior on the vanishing point did in the last image
/// ([`Detector::process_with_prior`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PriorOutcome {
    /// No prior: the full search ran.
    #[default]
    None,
    /// The narrowed search found a vanishing point inside the prior's window.
    Accepted,
    /// The narrowed search found none inside the window; the full search ran after it.
    FullSearch,
}

/// Time spent in each stage of the last image.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StageTimes {
    /// Vegetation, smoothing, threshold.
    pub prepare: Duration,
    /// The method's rows (the Hough transform, the edge detector, the strips' search, and
    /// the rows' refit), a narrowed search's included.
    pub rows: Duration,
    /// The vote for the vanishing point and the method's finishing steps.
    pub vanishing: Duration,
}

impl StageTimes {
    pub fn total(&self) -> Duration {
        self.prepare + self.rows + self.vanishing
    }
}

/// The whole detector.
#[derive(Debug)]
pub struct Detector {
    opts: DetectorOptions,
    mounting: Mounting,
    prep: Preparer,
    method: Box<dyn RowMethod>,
    vanish: VanishingStage,
    points: Points,
    /// The rows' weights in the vote.
    weights: Vec<f64>,
    times: StageTimes,
    last_prepare: PrepareResult,
    last_prior: PriorOutcome,
    /// The threads a frame's independent parts run on ([`Detector::set_threads`]).
    pool: Option<Arc<ThreadPool>>,
}

impl Detector {
    /// A detector for images of `cal` (at its size; another size scales it). The options
    /// are resolved for the calibration ([`resolve`]); [`Detector::options`] gives the
    /// values in force.
    pub fn new(cal: &Calibration, opts: DetectorOptions) -> Result<Self, DetectError> {
        let (opts, scales) = resolve(cal, &opts)?;
        let factor = scales.factor;
        let vanishing = VanishingParams::new(&opts.vanishing, factor);
        let capacity = opts.threshold.target_points() + 1;
        Ok(Detector {
            method: build_method(cal, &opts, factor)?,
            prep: Preparer::new(cal, &opts.prepare())?,
            vanish: VanishingStage::new(vanishing, opts.max_tilt_deg, &cal.mounting)?,
            mounting: cal.mounting,
            points: Points {
                rays: Vec::with_capacity(capacity),
                weights: Vec::with_capacity(capacity),
                pixel_rad: Vec::with_capacity(capacity),
            },
            opts,
            weights: Vec::with_capacity(128),
            times: StageTimes::default(),
            last_prepare: PrepareResult::default(),
            last_prior: PriorOutcome::None,
            pool: None,
        })
    }

    /// Runs each frame's independent parts on `threads` threads (built once, here): the
    /// preparation's row-by-row stages in bands and its threshold in halves, the combined
    /// method's Hough rows beside its edge detector, the strips' search candidates shared
    /// out. 1 (the default): every part on
    /// the calling thread. The answers are the same either way. A caller that runs frame
    /// after frame runs its loop on the threads themselves ([`Self::pool`]'s `install`):
    /// each frame then starts there without handing itself over, which allocates.
    pub fn set_threads(&mut self, threads: usize) -> Result<(), DetectError> {
        self.build_pool(threads, None)
    }

    /// [`Self::set_threads`] with each thread pinned to its own core: thread `i` to the
    /// process's allowed CPUs ([`crate::affinity::allowed_cpus`]) taken in turn from the
    /// `first` on. A node runs its frames so (`[pipeline] pin_threads`): unpinned, a thread
    /// woken after the idle gap between frames can land on its waker's core and the frame
    /// then runs on one. A thread that cannot be pinned runs unpinned, with a warning.
    pub fn set_pinned_threads(&mut self, threads: usize, first: usize) -> Result<(), DetectError> {
        self.build_pool(threads, Some(first))
    }

    fn build_pool(&mut self, threads: usize, pin_from: Option<usize>) -> Result<(), DetectError> {
        let allowed = crate::affinity::allowed_cpus();
        self.pool = match threads {
            0 | 1 => None,
            n => Some(Arc::new(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .thread_name(|i| format!("detector-{i}"))
                    .start_handler(move |i| {
                        let Some(first) = pin_from else { return };
                        let Some(cpu) = crate::affinity::cpu_for(&allowed, first, i) else {
                            tracing::warn!(
                                "detector-{i}: the allowed CPUs could not be read; not pinned"
                            );
                            return;
                        };
                        if let Err(e) = crate::affinity::pin_current_thread(cpu) {
                            tracing::warn!("detector-{i}: not pinned to CPU {cpu}: {e}");
                        }
                    })
                    .build()
                    .map_err(|e| DetectError::Buffer(format!("{n} detector threads: {e}")))?,
            )),
        };
        Ok(())
    }

    /// The options in force: `auto` resolved to the method that runs, the scales derived
    /// from the calibration written out.
    pub fn options(&self) -> &DetectorOptions {
        &self.opts
    }

    /// Detects rows, the vanishing point, heading and tilt in one image, into `out`.
    pub fn process(&mut self, view: &ImageView, out: &mut Detection) -> Result<(), DetectError> {
        self.process_with_prior(view, None, out)
    }

    /// As [`Detector::process`], narrowed by a `prior` on the vanishing point when there is
    /// one ([`super::prior`]): the method's rows are sought only where rows through the
    /// prior's window are, and the vanishing point there. When that gives no vanishing point
    /// inside the window, the full search runs on the same prepared points, so the answer is
    /// never worse than without a prior. [`Detector::last_prior`] tells which happened.
    pub fn process_with_prior(
        &mut self,
        view: &ImageView,
        prior: Option<&DetectorPrior>,
        out: &mut Detection,
    ) -> Result<(), DetectError> {
        // On the pool's threads when there are any: the frame's parts then join within it.
        match self.pool.clone() {
            Some(pool) => pool.install(|| self.process_here(view, prior, out)),
            None => self.process_here(view, prior, out),
        }
    }

    /// [`Self::process_with_prior`] on the calling thread.
    fn process_here(
        &mut self,
        view: &ImageView,
        prior: Option<&DetectorPrior>,
        out: &mut Detection,
    ) -> Result<(), DetectError> {
        let window = prior
            .map(|p| p.validate().map(|v| (v, p.window_rad)))
            .transpose()?;
        let t0 = Instant::now();
        let pool = self.pool.as_deref();
        self.last_prepare = self.prep.run_on(view, &mut self.points, pool)?;
        self.times.prepare = t0.elapsed();
        self.last_prior = PriorOutcome::None;
        let Some((vp, w)) = window.filter(|_| self.method.narrows()) else {
            return self.detect_prepared(out, None, true);
        };
        self.vanish.set_window(Some((&vp, w)));
        let narrowed = self.detect_prepared(out, Some((vp, w)), true);
        self.vanish.set_window(None);
        narrowed?;
        let inside = out
            .vanishing_point
            .is_some_and(|v| crate::sphere::axis_angle(&v.direction, &vp) <= w);
        if inside {
            self.last_prior = PriorOutcome::Accepted;
            return Ok(());
        }
        // The full search; the narrowed attempt's time counts in the rows' stage.
        let spent = self.times.rows + self.times.vanishing;
        self.detect_prepared(out, None, false)?;
        self.times.rows += spent;
        self.last_prior = PriorOutcome::FullSearch;
        Ok(())
    }

    /// Everything after the preparation: the method's rows (within `window`), the vote for
    /// their vanishing point, the method's finishing steps, heading and tilt. `fresh` false:
    /// the method ran on these points before.
    fn detect_prepared(
        &mut self,
        out: &mut Detection,
        window: Option<(Vector3<f64>, f64)>,
        fresh: bool,
    ) -> Result<(), DetectError> {
        out.rows.clear();
        out.boundaries.clear();
        let mut frame = Frame {
            points: &self.points,
            prep: &mut self.prep,
            prepared: self.last_prepare,
            vanish: &mut self.vanish,
            window,
            fresh,
            out,
            weights: &mut self.weights,
            pool: self.pool.as_deref(),
        };
        let t1 = Instant::now();
        self.method.rows(&mut frame)?;
        let t2 = Instant::now();
        frame.vanish.run(Some(frame.weights), frame.out)?;
        self.method.finish(&mut frame)?;
        let ht = out
            .vanishing_point
            .map(|v| heading_tilt(&v.direction, &self.mounting));
        out.heading_rad = ht.map(|h| h.heading_rad);
        out.tilt_rad = ht.map(|h| h.tilt_rad);
        self.times.rows = t2 - t1;
        self.times.vanishing = t2.elapsed();
        Ok(())
    }

    /// The threads of [`Self::set_threads`], when more than one.
    pub fn pool(&self) -> Option<Arc<ThreadPool>> {
        self.pool.clone()
    }

    /// What the prior did in the last image.
    pub fn last_prior(&self) -> PriorOutcome {
        self.last_prior
    }

    /// The method that runs, as its own type (`None` for another), for its diagnostics.
    pub fn method_as<M: RowMethod>(&self) -> Option<&M> {
        let method: &dyn Any = &*self.method;
        method.downcast_ref()
    }

    /// As [`Self::method_as`], mutably.
    pub fn method_as_mut<M: RowMethod>(&mut self) -> Option<&mut M> {
        let method: &mut dyn Any = &mut *self.method;
        method.downcast_mut()
    }

    pub fn preparer(&self) -> &Preparer {
        &self.prep
    }

    pub fn preparer_mut(&mut self) -> &mut Preparer {
        &mut self.prep
    }

    /// The points kept from the last image.
    pub fn points(&self) -> &Points {
        &self.points
    }

    pub fn last_times(&self) -> StageTimes {
        self.times
    }

    /// The calibration at the last image's resolution.
    pub fn view_calibration(&self) -> Option<&Calibration> {
        self.prep.view_calibration()
    }
}

/// The method `opts.method` (resolved: not `auto`) for `cal`, its angular scales at
/// `angle_factor` times their reference values.
fn build_method(
    cal: &Calibration,
    opts: &DetectorOptions,
    angle_factor: f64,
) -> Result<Box<dyn RowMethod>, DetectError> {
    Ok(match opts.method {
        Method::Hough => Box::new(HoughMethod::new(&opts.hough, angle_factor)?),
        Method::Edge => Box::new(EdgeMethod::new(
            &opts.edge,
            opts.refit.near_reach_m > 0.0,
            angle_factor,
        )?),
        Method::Combined => Box::new(CombinedMethod::new(
            &opts.combined,
            &opts.hough,
            &opts.edge,
            angle_factor,
        )?),
        Method::Pencil => Box::new(PencilMethod::new(
            opts.pencil,
            opts.max_tilt_deg,
            &cal.mounting,
        )?),
        Method::Strips => Box::new(StripsMethod::new(
            opts.strips,
            opts.max_tilt_deg,
            &cal.mounting,
            angle_factor,
        )?),
        Method::Auto => {
            return Err(DetectError::Options(
                "method auto must be resolved for the calibration first".into(),
            ))
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::ideal_fisheye;
    use crate::frame::PixelFormat;

    #[test]
    fn auto_is_default_and_resolves_by_the_lens() {
        assert_eq!(DetectorOptions::default().method, Method::Auto);
        // an omnidirectional lens keeps the paper's combined method
        let fisheye = ideal_fisheye(100, 120).unwrap();
        let d = Detector::new(&fisheye, DetectorOptions::default()).unwrap();
        assert_eq!(d.options().method, Method::Combined);
        assert!(d.method_as::<CombinedMethod>().is_some());
        // a forward-looking perspective camera gets the strips
        let pinhole = crate::camera::Calibration::parse_toml(
            include_str!("../../config/calib/pinhole_512_f300.toml"),
            std::path::Path::new("pinhole_512_f300.toml"),
        )
        .unwrap();
        let d = Detector::new(&pinhole, DetectorOptions::default()).unwrap();
        assert_eq!(d.options().method, Method::Strips);
        assert!(d.method_as::<StripsMethod>().is_some());
        assert!(d.method_as::<CombinedMethod>().is_none());
        // an explicit method is kept whatever the lens
        let hough = DetectorOptions {
            method: Method::Hough,
            ..Default::default()
        };
        let d = Detector::new(&pinhole, hough).unwrap();
        assert_eq!(d.options().method, Method::Hough);
    }

    #[test]
    fn bad_options_are_named() {
        let cal = ideal_fisheye(100, 120).unwrap();
        for (text, key) in [
            ("[combined]\nedge_weight = 1.0\n", "edge_weight"),
            ("[combined]\nedge_weight = -0.5\n", "edge_weight"),
            ("[hough]\nmax_rows = 0\n", "hough.max_rows"),
            ("max_tilt_deg = 90.0\n", "max_tilt_deg"),
            ("[vanishing]\ninlier_deg = 45.0\n", "vanishing.inlier_deg"),
            ("[refit]\nnear_reach_m = -1.0\n", "refit.near_reach_m"),
        ] {
            let o: DetectorOptions = toml::from_str(text).unwrap();
            let e = Detector::new(&cal, o).unwrap_err().to_string();
            assert!(e.contains(key), "{text}: {e}");
        }
        let o: DetectorOptions =
            toml::from_str("method = \"edge\"\n[combined]\nedge_weight = 0.5\n").unwrap();
        assert_eq!(o.method, Method::Edge);
        assert_eq!(o.combined.edge_weight, 0.5);
    }

    #[test]
    fn rejects_images_not_a_uniform_scale_of_the_calibration() {
        let cal = ideal_fisheye(100, 120).unwrap();
        let mut d = Detector::new(&cal, DetectorOptions::default()).unwrap();
        let data = vec![0u8; 100 * 100];
        let v = ImageView::new(100, 100, PixelFormat::Mono8, &data).unwrap();
        let mut out = Detection::default();
        let e = d.process(&v, &mut out).unwrap_err().to_string();
        assert!(e.contains("not the calibration"), "{e}");
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn pinned_threads_each_keep_one_cpu_in_turn() {
        let allowed = crate::affinity::allowed_cpus();
        let cal = ideal_fisheye(100, 120).unwrap();
        let mut d = Detector::new(&cal, DetectorOptions::default()).unwrap();
        d.set_pinned_threads(2, 1).unwrap();
        let mut got = d
            .pool()
            .unwrap()
            .broadcast(|b| (b.index(), crate::affinity::current_thread_cpus()));
        got.sort();
        let want: Vec<_> = (0..2)
            .map(|i| (i, vec![crate::affinity::cpu_for(&allowed, 1, i).unwrap()]))
            .collect();
        assert_eq!(got, want);
        // unpinned threads keep the process's CPUs
        d.set_threads(2).unwrap();
        let got = d
            .pool()
            .unwrap()
            .broadcast(|_| crate::affinity::current_thread_cpus());
        assert_eq!(got, vec![allowed.clone(), allowed]);
    }

    #[test]
    fn options_reject_unknown_and_removed_keys() {
        let e = toml::from_str::<DetectorOptions>("max_tilt_deg = 10\nbogus = 1\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("bogus"), "{e}");
        let e = toml::from_str::<DetectorOptions>("[hough]\nphi_bins = 60\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("phi_bins"), "{e}");
        let o: DetectorOptions = toml::from_str("[hough]\nmax_rows = 6\n").unwrap();
        assert_eq!(o.hough.max_rows, 6);
    }
}
