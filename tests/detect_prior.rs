//! The detector narrowed by a prior on the vanishing point (issue 14 §2): with the true
//! vanishing point's window it finds the same vanishing point as the full search, within a
//! small fraction of a pixel, and takes the narrowed answer; with a window that holds no
//! vanishing point it falls back to the full search and gives exactly its answer.

use nalgebra::Vector3;
use omnirow::camera::Calibration;
use omnirow::detect::{Detection, Detector, DetectorOptions, DetectorPrior, Method, PriorOutcome};
use omnirow::frame::{GroundTruth, ImageView};
use omnirow::sphere::axis_angle;
use omnirow::synth::{Renderer, Scene, Style, SynthOptions};

/// 640×480, f = 375 px, looking 35° below the horizon.
const CAL: &str = "[pinhole]\nwidth = 640\nheight = 480\nfx = 375.0\nfy = 375.0\ncx = 319.5\ncy = 239.5\n\n[mounting]\npitch_deg = -55.0\n";

fn scene(seed: u64) -> (Calibration, Vec<u8>, Vector3<f64>) {
    let cal = Calibration::parse_toml(CAL, std::path::Path::new("cal.toml")).unwrap();
    let opts = SynthOptions {
        style: Style::Colour,
        yaw_deg: 3.0 * seed as f64 - 5.0,
        lateral_m: 0.05 * seed as f64,
        height_m: 1.0,
        ..Default::default()
    };
    let scene = Scene::new(&opts, seed, &cal.mounting).unwrap();
    let truth = GroundTruth::of_scene(&scene, &cal);
    let mut r = Renderer::new(&cal).unwrap();
    let mut data = vec![0u8; r.buffer_len(Style::Colour)];
    r.render_into(&scene, &mut data).unwrap();
    (cal, data, Vector3::from(truth.vp_along))
}

fn run(det: &mut Detector, data: &[u8], prior: Option<&DetectorPrior>) -> Detection {
    let view = ImageView::new(640, 480, Style::Colour.pixel_format(), data).unwrap();
    let mut out = Detection::default();
    det.process_with_prior(&view, prior, &mut out).unwrap();
    out
}

#[test]
fn a_true_prior_is_taken_and_a_wrong_one_falls_back_to_the_full_search() {
    for method in [Method::Combined, Method::Hough, Method::Strips] {
        for seed in 1..4 {
            let (cal, data, truth) = scene(seed);
            let opts = DetectorOptions {
                method,
                ..Default::default()
            };
            let mut det = Detector::new(&cal, opts).unwrap();
            let full = run(&mut det, &data, None);
            assert_eq!(det.last_prior(), PriorOutcome::None);
            let vp_full = full
                .vanishing_point
                .expect("full search finds the rows")
                .direction;
            let err_full = axis_angle(&vp_full, &truth);
            // A window of 2° around the truth: the narrowed answer, as good as the full one
            // (0.3 mrad is a ninth of a pixel at f = 375 px).
            let prior = DetectorPrior {
                vanishing_point: truth,
                window_rad: 2f64.to_radians(),
            };
            let narrowed = run(&mut det, &data, Some(&prior));
            assert_eq!(
                det.last_prior(),
                PriorOutcome::Accepted,
                "{method:?} seed {seed}"
            );
            let vp = narrowed.vanishing_point.unwrap().direction;
            let err = axis_angle(&vp, &truth);
            assert!(
                err < err_full + 3e-4 && axis_angle(&vp, &vp_full) < 3e-4,
                "{method:?} seed {seed}: narrowed {err} full {err_full}"
            );
            // A window 12° away holds no rows' vanishing point: exactly the full answer.
            let wrong = DetectorPrior {
                vanishing_point: nalgebra::Rotation3::from_axis_angle(
                    &Vector3::z_axis(),
                    12f64.to_radians(),
                ) * truth,
                window_rad: 2f64.to_radians(),
            };
            let fallback = run(&mut det, &data, Some(&wrong));
            assert_eq!(
                det.last_prior(),
                PriorOutcome::FullSearch,
                "{method:?} seed {seed}"
            );
            assert_eq!(fallback, full, "{method:?} seed {seed}");
            // No prior again: the full search, unchanged by the windows before.
            assert_eq!(run(&mut det, &data, None), full);
        }
    }
}

#[test]
fn a_bad_prior_is_an_error_naming_it() {
    let (cal, data, _) = scene(1);
    let mut det = Detector::new(&cal, DetectorOptions::default()).unwrap();
    let view = ImageView::new(640, 480, Style::Colour.pixel_format(), &data).unwrap();
    let mut out = Detection::default();
    let bad = DetectorPrior {
        vanishing_point: Vector3::new(f64::NAN, 0.0, 1.0),
        window_rad: 0.03,
    };
    let e = det
        .process_with_prior(&view, Some(&bad), &mut out)
        .unwrap_err();
    assert!(e.to_string().contains("prior"), "{e}");
}
