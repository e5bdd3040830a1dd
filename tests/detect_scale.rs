//! The detector's angular scales follow the calibration (issue 13 §1): one scene rendered
//! through two forward-looking pinhole cameras with the same field of view, whose focal
//! lengths and resolutions differ 4× (1280×960 at f = 1200 px, and the same calibration
//! rescaled to 320×240 at f = 300 px), gives the same rows and vanishing point, within a
//! tolerance proportional to the coarser camera's pixel angle: both fields of view have the
//! same extent, so both cameras get the same angular options. With angles 4× finer on the
//! fine camera (the same in pixels as the coarse camera's), it loses rows.

use nalgebra::Vector3;
use omnirow::camera::Calibration;
use omnirow::detect::{Detection, Detector, DetectorOptions, Method, Row};
use omnirow::frame::GroundTruth;
use omnirow::frame::ImageView;
use omnirow::sphere::axis_angle;
use omnirow::synth::{Renderer, Scene, Style, SynthOptions};

/// 1280×960, f = 1200 px, looking 35° below the horizon.
const FINE: &str = "[pinhole]\nwidth = 1280\nheight = 960\nfx = 1200.0\nfy = 1200.0\ncx = 639.5\ncy = 479.5\n\n[mounting]\npitch_deg = -55.0\n";

/// The coarse camera's pixel angle (radians): 1 / f.
const COARSE_PIXEL_RAD: f64 = 1.0 / 300.0;

fn detect(cal: &Calibration, scene: &Scene, opts: &DetectorOptions) -> Detection {
    let mut renderer = Renderer::new(cal).unwrap();
    let style = scene.options.style;
    let mut data = vec![0u8; renderer.buffer_len(style)];
    renderer.render_into(scene, &mut data).unwrap();
    let (w, h) = renderer.size();
    let view = ImageView::new(w, h, style.pixel_format(), &data).unwrap();
    let mut d = Detector::new(cal, opts.clone()).unwrap();
    let mut out = Detection::default();
    d.process(&view, &mut out).unwrap();
    out
}

/// The published row nearest (angle between normals, either sign) to `n`.
fn nearest(rows: &[Row], n: &Vector3<f64>) -> Option<(f64, Vector3<f64>)> {
    rows.iter()
        .map(|r| (axis_angle(&r.normal, n), r.normal))
        .min_by(|a, b| a.0.total_cmp(&b.0))
}

/// Per scene: the true rows both cameras found (within `tol` of the truth), the largest angle
/// between the two cameras' normals of those rows, and the angle between their vanishing
/// points (radians); the rows only one of them found.
struct Comparison {
    both: usize,
    only_one: usize,
    worst_row: f64,
    vp: f64,
}

fn compare(method: Method, fine_angle_scale: Option<f64>, seed: u64) -> Comparison {
    let fine = Calibration::parse_toml(FINE, std::path::Path::new("fine.toml")).unwrap();
    let coarse = fine.rescaled(4.0).unwrap();
    assert_eq!((coarse.model.width, coarse.model.height), (320, 240));
    let opts = SynthOptions {
        style: Style::Colour,
        yaw_deg: 3.0 * seed as f64 - 5.0,
        lateral_m: 0.07 * seed as f64,
        height_m: 1.0,
        ..Default::default()
    };
    let scene = Scene::new(&opts, seed, &fine.mounting).unwrap();
    let truth = GroundTruth::of_scene(&scene, &coarse);
    let base = DetectorOptions {
        method,
        ..Default::default()
    };
    // The fine image has 16 times the pixels: it keeps 16 times the points, the same share
    // of its vegetation (a fixed budget would keep only the brightest rows).
    let mut fine_opts = DetectorOptions {
        angle_scale: fine_angle_scale,
        ..base.clone()
    };
    fine_opts.threshold.target_points = Some(fine_opts.threshold.target_points() * 16);
    let a = detect(&fine, &scene, &fine_opts);
    let b = detect(&coarse, &scene, &base);
    let tol = 3.0 * COARSE_PIXEL_RAD;
    let (mut both, mut only_one, mut worst_row) = (0, 0, 0.0f64);
    for n in &truth.row_normals {
        let n = Vector3::from(*n);
        let fa = nearest(&a.rows, &n).filter(|f| f.0 < tol);
        let fb = nearest(&b.rows, &n).filter(|f| f.0 < tol);
        match (fa, fb) {
            (Some(fa), Some(fb)) => {
                both += 1;
                worst_row = worst_row.max(axis_angle(&fa.1, &fb.1));
            }
            (None, None) => {}
            _ => only_one += 1,
        }
    }
    let vp = match (a.vanishing_point, b.vanishing_point) {
        (Some(x), Some(y)) => axis_angle(&x.direction, &y.direction),
        _ => f64::INFINITY,
    };
    Comparison {
        both,
        only_one,
        worst_row,
        vp,
    }
}

#[test]
fn one_scene_through_two_lenses_4x_apart_gives_the_same_rows_and_vanishing_point() {
    for method in [Method::Hough, Method::Combined] {
        for seed in 1..=3 {
            let c = compare(method, None, seed);
            let what = format!(
                "{} seed {seed}: {} rows found by both, {} by one, rows {:.2} px, VP {:.2} px apart",
                method.name(),
                c.both,
                c.only_one,
                c.worst_row / COARSE_PIXEL_RAD,
                c.vp / COARSE_PIXEL_RAD
            );
            eprintln!("{what}");
            assert!(c.both >= 3 && c.only_one == 0, "{what}");
            assert!(c.worst_row < 3.0 * COARSE_PIXEL_RAD, "{what}");
            assert!(c.vp < 1.0 * COARSE_PIXEL_RAD, "{what}");
        }
    }
}

#[test]
fn angles_that_follow_the_pixel_size_lose_rows_through_the_fine_lens() {
    // The coarse camera's factor, and a fine camera whose angles are 4 times finer (the same
    // in pixels): its Hough cells and first bands are narrower than the rows.
    let coarse = Calibration::parse_toml(FINE, std::path::Path::new("fine.toml"))
        .unwrap()
        .rescaled(4.0)
        .unwrap();
    let (_, sc) = omnirow::detect::options::resolve(&coarse, &DetectorOptions::default()).unwrap();
    let mut lost = 0;
    for seed in 1..=3 {
        let c = compare(Method::Hough, Some(sc.factor / 4.0), seed);
        eprintln!(
            "angles / 4, seed {seed}: {} rows found by both, {} by one, VP {:.2} px apart",
            c.both,
            c.only_one,
            c.vp / COARSE_PIXEL_RAD
        );
        lost += c.only_one;
    }
    assert!(
        lost > 0,
        "the fine lens found the same rows with angles 4 times finer"
    );
}
