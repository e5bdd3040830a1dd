//! Runs the paper's experiments: renders the synthetic scenes, runs every method on each, and
//! scores the answers against the ground truth.

use super::stats::{quantile, Summary};
use crate::camera::{Calibration, IdealLens};
use crate::detect::{DetectError, Detection, Method};
use crate::detect::{Detector, DetectorOptions};
use crate::frame::ImageView;
use crate::sphere::axis_angle;
use crate::synth::{
    random_scene, GroundTruth, Protocol, Renderer, Scene, Style, SynthError, SynthOptions,
};
use nalgebra::Vector3;
use std::time::Instant;

/// An error running the evaluation.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error("lens {lens}: {source}")]
    Synth {
        lens: String,
        #[source]
        source: SynthError,
    },
    #[error("lens {lens}, method {method}: {source}")]
    Detect {
        lens: String,
        method: &'static str,
        #[source]
        source: DetectError,
    },
    #[error("evaluation option: {0}")]
    Options(String),
}

/// A lens to evaluate on.
#[derive(Debug, Clone)]
pub struct Lens {
    pub name: String,
    pub calibration: Calibration,
}

impl Lens {
    /// The two lenses the paper uses, as omnirow's ideal models of the GC2450C.
    pub fn builtin() -> Vec<Lens> {
        [IdealLens::Fisheye185, IdealLens::Pal]
            .into_iter()
            .map(|l| Lens {
                name: l.name().to_string(),
                calibration: l
                    .calibration(2050, 2448)
                    .expect("the GC2450C's sensor is an ideal lens size"),
            })
            .collect()
    }
}

/// What to run.
#[derive(Debug, Clone)]
pub struct EvalOptions {
    /// Images for Table I (alternating over the lenses).
    pub table1_images: usize,
    /// Table I's scenes again through the second appearance model (`Style::Leafy`).
    pub table1_leafy: bool,
    /// Images per lens for Table II.
    pub table2_images: usize,
    /// Images per lens and plant distance for figures 8 and 9.
    pub distance_images: usize,
    /// Plant distances (metres) for figures 8 and 9.
    pub plant_distances: Vec<f64>,
    pub seed: u64,
    pub lenses: Vec<Lens>,
    /// Resolution: 1 = the calibration's, 2 = half, ...
    pub scale: f64,
    pub methods: Vec<Method>,
    /// A vanishing point within this angle of the truth passes (the paper's Table II).
    pub pass_deg: f64,
    /// A found row is correct when its great circle passes within this angle of the true
    /// vanishing point and its normal is within `row_normal_deg` of a visible row's.
    pub row_vp_deg: f64,
    pub row_normal_deg: f64,
    /// Options for the detector (the method is set per run).
    pub detector: DetectorOptions,
}

impl EvalOptions {
    /// The full protocol: 100 images for Table I, 100 per lens for Table II, 10 per lens and
    /// plant distance for the figures, at full resolution.
    pub fn full(lenses: Vec<Lens>) -> Self {
        EvalOptions {
            table1_images: 100,
            table1_leafy: false,
            table2_images: 100,
            distance_images: 10,
            plant_distances: vec![0.03, 0.05, 0.1, 0.15, 0.2, 0.3, 0.4],
            seed: 1,
            lenses,
            scale: 1.0,
            methods: vec![Method::Edge, Method::Hough, Method::Combined],
            pass_deg: 1.0,
            row_vp_deg: 1.0,
            row_normal_deg: 3.0,
            detector: DetectorOptions::default(),
        }
    }

    /// A run of under a minute: few images at half resolution.
    pub fn quick(lenses: Vec<Lens>) -> Self {
        EvalOptions {
            table1_images: 8,
            table2_images: 6,
            distance_images: 2,
            plant_distances: vec![0.03, 0.15, 0.4],
            scale: 2.0,
            ..Self::full(lenses)
        }
    }
}

/// One method's answer on one image.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    pub experiment: Experiment,
    pub lens: usize,
    pub method: Method,
    /// The scene's seed: with the experiment's protocol it renders the image again
    /// (`omnirow synth --random table1|table2 --seed S`), and it pairs the methods' outcomes
    /// on the same image.
    pub seed: u64,
    pub plant_distance_m: f64,
    /// Background salt-and-pepper density of the scene.
    pub noise: f64,
    /// Weeds in the scene.
    pub weeds: usize,
    /// Angle between the found and the true vanishing point (radians), if one was found.
    pub vp_error_rad: Option<f64>,
    pub rows_found: usize,
    pub rows_correct: usize,
    pub detect_ms: f64,
}

/// Which experiment an outcome belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Experiment {
    Table1,
    /// Table I's scenes drawn by the second appearance model (`Style::Leafy`).
    Table1Leafy,
    Distance,
    Table2,
}

/// Every outcome of a run, with what produced it.
#[derive(Debug, Clone)]
pub struct EvalResults {
    pub outcomes: Vec<Outcome>,
    pub lens_names: Vec<String>,
    pub methods: Vec<Method>,
    pub plant_distances: Vec<f64>,
    pub pass_deg: f64,
}

/// Scores one detection against the truth.
pub fn score(
    det: &Detection,
    truth: &GroundTruth,
    opts: &EvalOptions,
) -> (Option<f64>, usize, usize) {
    let v = Vector3::from(truth.vp_along);
    let err = det.vanishing_point.map(|vp| axis_angle(&vp.direction, &v));
    let sin_vp = opts.row_vp_deg.to_radians().sin();
    let tol = opts.row_normal_deg.to_radians();
    let correct = det
        .rows
        .iter()
        .filter(|r| {
            r.normal.dot(&v).abs() < sin_vp
                && truth
                    .row_normals
                    .iter()
                    .any(|t| axis_angle(&r.normal, &Vector3::from(*t)) < tol)
        })
        .count();
    (err, det.rows.len(), correct)
}

struct LensRun {
    renderer: Renderer,
    detectors: Vec<Detector>,
    buffer: Vec<u8>,
    calibration: Calibration,
}

/// Runs the experiments. `progress(done, total)` is called after every image.
pub fn run(
    opts: &EvalOptions,
    mut progress: impl FnMut(usize, usize),
) -> Result<EvalResults, EvalError> {
    if opts.lenses.is_empty() || opts.methods.is_empty() {
        return Err(EvalError::Options(
            "no lens or no method to evaluate".into(),
        ));
    }
    let mut lenses = Vec::with_capacity(opts.lenses.len());
    for lens in &opts.lenses {
        let synth_err = |source| EvalError::Synth {
            lens: lens.name.clone(),
            source,
        };
        let cal = if opts.scale == 1.0 {
            lens.calibration.clone()
        } else {
            lens.calibration.rescaled(opts.scale).map_err(|e| {
                EvalError::Options(format!("lens {}: scale {}: {e}", lens.name, opts.scale))
            })?
        };
        let renderer = Renderer::new(&cal).map_err(synth_err)?;
        let mut detectors = Vec::with_capacity(opts.methods.len());
        for &method in &opts.methods {
            let d = Detector::new(
                &cal,
                DetectorOptions {
                    method,
                    ..opts.detector.clone()
                },
            )
            .map_err(|source| EvalError::Detect {
                lens: lens.name.clone(),
                method: method.name(),
                source,
            })?;
            detectors.push(d);
        }
        lenses.push(LensRun {
            renderer,
            detectors,
            buffer: Vec::new(),
            calibration: cal,
        });
    }
    // The plan: (experiment, lens, scene options, seed).
    let mut plan: Vec<(Experiment, usize, SynthOptions, u64)> = Vec::new();
    let nl = lenses.len();
    for i in 0..opts.table1_images {
        let seed = opts.seed.wrapping_mul(1_000_003).wrapping_add(i as u64);
        plan.push((
            Experiment::Table1,
            i % nl,
            random_scene(seed, Protocol::Table1),
            seed,
        ));
    }
    // The same scenes through the second appearance model.
    for i in 0..opts.table1_images * opts.table1_leafy as usize {
        let (_, l, scene, seed) = plan[i].clone();
        plan.push((
            Experiment::Table1Leafy,
            l,
            SynthOptions {
                style: Style::Leafy,
                ..scene
            },
            seed,
        ));
    }
    for (d, &dist) in opts.plant_distances.iter().enumerate() {
        for l in 0..nl {
            for i in 0..opts.distance_images {
                let seed = opts
                    .seed
                    .wrapping_mul(2_000_003)
                    .wrapping_add((d * 10_000 + l * 1000 + i) as u64);
                let mut o = random_scene(seed, Protocol::Table1);
                o.plant_distance_m = dist;
                o.along_m = o.along_m / 0.03 * dist;
                plan.push((Experiment::Distance, l, o, seed));
            }
        }
    }
    for l in 0..nl {
        for i in 0..opts.table2_images {
            let seed = opts
                .seed
                .wrapping_mul(3_000_017)
                .wrapping_add((l * 100_000 + i) as u64);
            plan.push((
                Experiment::Table2,
                l,
                random_scene(seed, Protocol::Table2),
                seed,
            ));
        }
    }
    let total = plan.len();
    let mut outcomes = Vec::with_capacity(total * opts.methods.len());
    let mut det = Detection::default();
    for (done, (experiment, l, scene_opts, seed)) in plan.into_iter().enumerate() {
        let lr = &mut lenses[l];
        let name = &opts.lenses[l].name;
        let synth_err = |source| EvalError::Synth {
            lens: name.clone(),
            source,
        };
        let scene = Scene::new(&scene_opts, seed, &lr.calibration.mounting).map_err(synth_err)?;
        lr.buffer
            .resize(lr.renderer.buffer_len(scene_opts.style), 0);
        lr.renderer
            .render_into(&scene, &mut lr.buffer)
            .map_err(synth_err)?;
        let truth = GroundTruth::of_scene(&scene, &lr.calibration);
        let (w, h) = lr.renderer.size();
        let view = ImageView::new(w, h, scene_opts.style.pixel_format(), &lr.buffer)
            .map_err(|e| EvalError::Options(e.to_string()))?;
        for (m, &method) in opts.methods.iter().enumerate() {
            let t = Instant::now();
            lr.detectors[m]
                .process(&view, &mut det)
                .map_err(|source| EvalError::Detect {
                    lens: name.clone(),
                    method: method.name(),
                    source,
                })?;
            let detect_ms = t.elapsed().as_secs_f64() * 1e3;
            let (vp_error_rad, rows_found, rows_correct) = score(&det, &truth, opts);
            outcomes.push(Outcome {
                experiment,
                lens: l,
                method,
                seed,
                plant_distance_m: scene_opts.plant_distance_m,
                noise: scene_opts.noise,
                weeds: scene_opts.weeds,
                vp_error_rad,
                rows_found,
                rows_correct,
                detect_ms,
            });
        }
        progress(done + 1, total);
    }
    Ok(EvalResults {
        outcomes,
        lens_names: opts.lenses.iter().map(|l| l.name.clone()).collect(),
        methods: opts.methods.clone(),
        plant_distances: opts.plant_distances.clone(),
        pass_deg: opts.pass_deg,
    })
}

/// Table I figures for one method: vanishing point found (within the pass angle) in how many
/// images, and the error statistics over those.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AccuracyRow {
    pub images: usize,
    pub found: usize,
    pub errors: Summary,
}

/// Table II: failures per lens.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FailureCell {
    pub images: usize,
    pub failures: usize,
}

impl EvalResults {
    fn select(&self, e: Experiment, method: Method) -> impl Iterator<Item = &Outcome> {
        self.outcomes
            .iter()
            .filter(move |o| o.experiment == e && o.method == method)
    }

    fn passes(&self, o: &Outcome) -> bool {
        o.vp_error_rad
            .is_some_and(|e| e <= self.pass_deg.to_radians())
    }

    /// Table I for a method.
    pub fn accuracy(&self, method: Method) -> AccuracyRow {
        self.accuracy_in(Experiment::Table1, method)
    }

    /// Table I's figures for one method on the images of `experiment`.
    pub fn accuracy_in(&self, experiment: Experiment, method: Method) -> AccuracyRow {
        let all: Vec<&Outcome> = self.select(experiment, method).collect();
        let errs: Vec<f64> = all
            .iter()
            .filter(|o| self.passes(o))
            .filter_map(|o| o.vp_error_rad)
            .collect();
        AccuracyRow {
            images: all.len(),
            found: errs.len(),
            errors: Summary::of(&errs),
        }
    }

    /// Detection rate (correct rows / rows found) per plant distance, for a lens and method.
    pub fn detection_rate(&self, lens: usize, method: Method) -> Vec<(f64, f64)> {
        self.plant_distances
            .iter()
            .map(|&d| {
                let (found, correct) = self
                    .select(Experiment::Distance, method)
                    .filter(|o| o.lens == lens && (o.plant_distance_m - d).abs() < 1e-12)
                    .fold((0, 0), |(f, c), o| (f + o.rows_found, c + o.rows_correct));
                let rate = if found == 0 {
                    0.0
                } else {
                    correct as f64 / found as f64
                };
                (d, rate)
            })
            .collect()
    }

    /// Table II cell.
    pub fn failures(&self, lens: usize, method: Method) -> FailureCell {
        let all: Vec<&Outcome> = self
            .select(Experiment::Table2, method)
            .filter(|o| o.lens == lens)
            .collect();
        FailureCell {
            images: all.len(),
            failures: all.iter().filter(|o| !self.passes(o)).count(),
        }
    }

    /// Table II images of a lens on which every one of `methods` fails: no per-image choice
    /// between their answers passes these, so they bound what combining those answers can
    /// gain without evidence neither method finds. `None` when a method was not run.
    pub fn all_fail(&self, lens: usize, methods: &[Method]) -> Option<usize> {
        if methods.iter().any(|m| !self.methods.contains(m)) {
            return None;
        }
        let mut failed: std::collections::HashMap<u64, usize> = std::collections::HashMap::new();
        for o in self.outcomes.iter().filter(|o| {
            o.experiment == Experiment::Table2 && o.lens == lens && methods.contains(&o.method)
        }) {
            if !self.passes(o) {
                *failed.entry(o.seed).or_default() += 1;
            }
        }
        Some(failed.values().filter(|&&n| n == methods.len()).count())
    }

    /// Table II images of a lens that `a` passes and `b` fails.
    pub fn passes_where_fails(&self, lens: usize, a: Method, b: Method) -> usize {
        let failed_b: std::collections::HashSet<u64> = self
            .select(Experiment::Table2, b)
            .filter(|o| o.lens == lens && !self.passes(o))
            .map(|o| o.seed)
            .collect();
        self.select(Experiment::Table2, a)
            .filter(|o| o.lens == lens && self.passes(o) && failed_b.contains(&o.seed))
            .count()
    }

    /// Median and 99th percentile of the detector's time per image (ms), over every image.
    pub fn speed(&self, method: Method) -> (f64, f64) {
        let t: Vec<f64> = self
            .outcomes
            .iter()
            .filter(|o| o.method == method)
            .map(|o| o.detect_ms)
            .collect();
        (quantile(&t, 0.5), quantile(&t, 0.99))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::{Row, VanishingPoint};

    fn truth() -> GroundTruth {
        let s = std::f64::consts::FRAC_1_SQRT_2;
        GroundTruth {
            vp_along: [1.0, 0.0, 0.0],
            vp_across: [0.0, 1.0, 0.0],
            yaw_rad: 0.0,
            pitch_rad: 0.0,
            roll_rad: 0.0,
            heading_rad: 0.0,
            tilt_rad: 0.0,
            height_m: 1.0,
            lateral_offset_m: 0.0,
            camera_lateral_m: 0.0,
            row_spacing_m: 0.5,
            plant_distance_m: 0.1,
            curvature_per_m: 0.0,
            end_of_rows_m: None,
            no_crop: false,
            noise: Default::default(),
            row_normals: vec![[0.0, 1.0, 0.0], [0.0, s, s]],
            row_lateral_m: vec![0.0, 0.5],
            seed: 0,
        }
    }

    #[test]
    fn scoring_counts_rows_through_the_vanishing_point_near_a_true_row() {
        let opts = EvalOptions::quick(Vec::new());
        let row = |n: [f64; 3]| Row {
            normal: Vector3::from(n).normalize(),
            method: Method::Hough,
            support: 10,
            width_rad: 0.0,
        };
        let det = Detection {
            rows: vec![
                row([0.0, 1.0, 0.01]), // near the first row, through the VP
                row([0.0, 0.7, 0.72]), // near the second
                row([0.0, 1.0, -0.5]), // through the VP but no such row
                row([0.3, 1.0, 0.0]),  // not through the VP
            ],
            vanishing_point: Some(VanishingPoint {
                direction: Vector3::new(1.0, 0.001, 0.0).normalize(),
                inliers: 2,
                residual_rad: 0.0,
            }),
            ..Default::default()
        };
        let (err, found, correct) = score(&det, &truth(), &opts);
        assert!((err.unwrap() - 0.001).abs() < 1e-6);
        assert_eq!((found, correct), (4, 2));
        let (err, found, correct) = score(&Detection::default(), &truth(), &opts);
        assert_eq!((err, found, correct), (None, 0, 0));
    }

    fn outcome(lens: usize, method: Method, seed: u64, err: Option<f64>) -> Outcome {
        Outcome {
            experiment: Experiment::Table2,
            lens,
            method,
            seed,
            plant_distance_m: 0.1,
            noise: 0.2,
            weeds: 0,
            vp_error_rad: err,
            rows_found: 0,
            rows_correct: 0,
            detect_ms: 1.0,
        }
    }

    #[test]
    fn table2_pairs_methods_by_image() {
        let (pass, fail) = (Some(0.001), Some(0.1));
        let (e, h, c) = (Method::Edge, Method::Hough, Method::Combined);
        let outcomes = vec![
            // Lens 0: image 1 both fail, combined passes; image 2 only hough fails;
            // image 3 all pass; image 4 both fail (edge finds no point), combined too.
            outcome(0, e, 1, fail),
            outcome(0, h, 1, fail),
            outcome(0, c, 1, pass),
            outcome(0, e, 2, pass),
            outcome(0, h, 2, fail),
            outcome(0, c, 2, fail),
            outcome(0, e, 3, pass),
            outcome(0, h, 3, pass),
            outcome(0, c, 3, pass),
            outcome(0, e, 4, None),
            outcome(0, h, 4, fail),
            outcome(0, c, 4, fail),
            // Lens 1 (same seed as lens 0's image 1, other outcomes): hough fails alone.
            outcome(1, e, 1, pass),
            outcome(1, h, 1, fail),
            outcome(1, c, 1, pass),
        ];
        let r = EvalResults {
            outcomes,
            lens_names: vec!["a".into(), "b".into()],
            methods: vec![e, h, c],
            plant_distances: Vec::new(),
            pass_deg: 1.0,
        };
        assert_eq!(r.all_fail(0, &[e, h]), Some(2));
        assert_eq!(r.all_fail(1, &[e, h]), Some(0));
        assert_eq!(r.all_fail(0, &[e, h, c]), Some(1));
        assert_eq!(r.passes_where_fails(0, c, h), 1);
        assert_eq!(r.passes_where_fails(0, h, c), 0);
        assert_eq!(r.passes_where_fails(0, e, c), 1);
        assert_eq!(r.passes_where_fails(1, c, h), 1);
        let only_hough = EvalResults {
            methods: vec![h],
            ..r
        };
        assert_eq!(only_hough.all_fail(0, &[e, h]), None);
    }
}
