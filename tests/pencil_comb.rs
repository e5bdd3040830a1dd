//! The pencil method with the rows' comb on a synthetic perspective scene: a pinhole camera
//! (640×480, f = 400 px, 35° below the horizon) over evenly spaced rows with weeds between
//! them, rendered with a roll of the camera about the rows (which bends the comb in tan ψ,
//! src/detect/comb.rs). Every published row lies on a true row (no false rows), most true
//! rows in view are found, and the vanishing point is right.

use nalgebra::Vector3;
use omnirow::camera::Calibration;
use omnirow::detect::{Detection, Detector, DetectorOptions, Method};
use omnirow::frame::{GroundTruth, ImageView};
use omnirow::sphere::axis_angle;
use omnirow::synth::{Renderer, Scene, Style, SynthOptions};

const CAMERA: &str = "[pinhole]\nwidth = 640\nheight = 480\nfx = 400.0\nfy = 400.0\ncx = 319.5\ncy = 239.5\n\n[mounting]\npitch_deg = -55.0\n";

/// One pixel's angle at the image centre (radians).
const PIXEL_RAD: f64 = 1.0 / 400.0;

struct Outcome {
    true_in_view: usize,
    found: usize,
    false_rows: usize,
    vp_px: f64,
}

fn run(seed: u64) -> Outcome {
    let cal = Calibration::parse_toml(CAMERA, std::path::Path::new("camera.toml")).unwrap();
    let opts = SynthOptions {
        style: Style::Colour,
        yaw_deg: 2.0 * seed as f64 - 4.0,
        roll_deg: 3.0,
        lateral_m: 0.05 * seed as f64,
        height_m: 1.0,
        weeds: 400,
        ..Default::default()
    };
    let scene = Scene::new(&opts, seed, &cal.mounting).unwrap();
    let truth = GroundTruth::of_scene(&scene, &cal);
    let mut renderer = Renderer::new(&cal).unwrap();
    let mut data = vec![0u8; renderer.buffer_len(Style::Colour)];
    renderer.render_into(&scene, &mut data).unwrap();
    let (w, h) = renderer.size();
    let view = ImageView::new(w, h, Style::Colour.pixel_format(), &data).unwrap();
    let det_opts = DetectorOptions {
        method: Method::Pencil,
        ..Default::default()
    };
    let mut d = Detector::new(&cal, det_opts).unwrap();
    let mut out = Detection::default();
    d.process(&view, &mut out).unwrap();
    let tol = 3.0 * PIXEL_RAD;
    let truths: Vec<Vector3<f64>> = truth
        .row_normals
        .iter()
        .map(|n| Vector3::from(*n))
        .collect();
    let on_truth = |n: &Vector3<f64>| truths.iter().any(|t| axis_angle(t, n) < tol);
    let found = truths
        .iter()
        .filter(|t| out.rows.iter().any(|r| axis_angle(&r.normal, t) < tol))
        .count();
    let false_rows = out.rows.iter().filter(|r| !on_truth(&r.normal)).count();
    let vp_px = match (out.vanishing_point, Some(truth.vp_along)) {
        (Some(v), Some(t)) => axis_angle(&v.direction, &Vector3::from(t)) / PIXEL_RAD,
        _ => f64::INFINITY,
    };
    Outcome {
        true_in_view: truths.len(),
        found,
        false_rows,
        vp_px,
    }
}

#[test]
fn the_pencil_with_its_comb_finds_the_true_rows_and_no_false_ones() {
    for seed in 1..=3 {
        let o = run(seed);
        let what = format!(
            "seed {seed}: {} true rows in view; {} found, {} false, VP {:.2} px",
            o.true_in_view, o.found, o.false_rows, o.vp_px
        );
        eprintln!("{what}");
        assert!(o.found >= 4, "{what}");
        assert_eq!(o.false_rows, 0, "{what}");
        assert!(o.vp_px < 2.0, "{what}");
    }
}
