//! Where the Hough method's precision goes on each appearance: for Table I's scenes (the
//! seeds `omnirow eval` uses, both ideal lenses at half resolution), drawn by the first
//! renderer and by `leafy`, the vanishing point's error and, per detected row matched to a
//! true row, the component of its normal along the true vanishing point (the part of a row's
//! error that moves the vanishing point), before the refit on the image (`hough` refinement
//! only) and after it.
//!
//! `cargo run --release --example leafy_rows -- [images] [seed]`; detector options (TOML of
//! the `[detector]` section) from the environment variable `OMNIROW_DETECTOR`.
use nalgebra::Vector3;
use omnirow::camera::IdealLens;
use omnirow::detect::{Detection, Detector, DetectorOptions, Method};
use omnirow::frame::ImageView;
use omnirow::sphere::axis_angle;
use omnirow::synth::{random_scene, render, Protocol, Style, SynthOptions};

/// Sums of one appearance and stage.
#[derive(Default)]
struct Tally {
    vp_err: Vec<f64>,
    row_along: Vec<f64>,
}

impl Tally {
    fn line(&self, name: &str) -> String {
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        let rms = mean(&self.row_along.iter().map(|x| x * x).collect::<Vec<_>>()).sqrt();
        let mut abs: Vec<f64> = self.row_along.iter().map(|x| x.abs()).collect();
        abs.sort_by(f64::total_cmp);
        let median = abs.get(abs.len() / 2).copied().unwrap_or(f64::NAN);
        format!(
            "{name:<22} vp mean {:.4} mrad (n {}) | rows along-vp rms {:.3} median |.| {:.3} mrad (n {})",
            mean(&self.vp_err),
            self.vp_err.len(),
            rms,
            median,
            self.row_along.len()
        )
    }
}

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let images: usize = a.get(1).and_then(|s| s.parse().ok()).unwrap_or(10);
    let seed0: u64 = a.get(2).and_then(|s| s.parse().ok()).unwrap_or(1);
    let base: DetectorOptions = std::env::var("OMNIROW_DETECTOR")
        .map(|t| toml::from_str(&t).expect("OMNIROW_DETECTOR: detector TOML"))
        .unwrap_or_default();
    let lenses: Vec<_> = [IdealLens::Fisheye185, IdealLens::Pal]
        .into_iter()
        .map(|l| l.calibration(2050, 2448).unwrap().rescaled(2.0).unwrap())
        .collect();
    let stages = [("refine", false), ("refit", true)];
    let mut tallies: Vec<Vec<Tally>> = (0..2)
        .map(|_| (0..stages.len()).map(|_| Tally::default()).collect())
        .collect();
    for i in 0..images {
        let seed = seed0.wrapping_mul(1_000_003).wrapping_add(i as u64);
        let cal = &lenses[i % lenses.len()];
        for (si, style) in [None, Some(Style::Leafy)].into_iter().enumerate() {
            let scene = random_scene(seed, Protocol::Table1);
            let opts = SynthOptions {
                style: style.unwrap_or(scene.style),
                ..scene
            };
            let (img, truth) = render(cal, &opts, seed).unwrap();
            let view = ImageView::new(img.width, img.height, img.format, &img.data).unwrap();
            let vp = Vector3::from(truth.vp_along);
            for (k, &(_, refit)) in stages.iter().enumerate() {
                let mut o = DetectorOptions {
                    method: Method::Hough,
                    ..base.clone()
                };
                o.refit.enabled = refit && base.refit.enabled;
                let mut d = Detector::new(cal, o).unwrap();
                let mut out = Detection::default();
                d.process(&view, &mut out).unwrap();
                let t = &mut tallies[si][k];
                if let Some(p) = out.vanishing_point {
                    t.vp_err.push(axis_angle(&p.direction, &vp) * 1e3);
                }
                for r in &out.rows {
                    let near = truth
                        .row_normals
                        .iter()
                        .map(|n| axis_angle(&r.normal, &Vector3::from(*n)))
                        .fold(f64::INFINITY, f64::min);
                    if near < 5e-3 {
                        t.row_along.push(r.normal.dot(&vp).asin() * 1e3);
                    }
                }
            }
        }
    }
    for (si, name) in ["first", "leafy"].iter().enumerate() {
        for (k, (stage, _)) in stages.iter().enumerate() {
            println!("{}", tallies[si][k].line(&format!("{name} {stage}")));
        }
    }
}
