//! A frame's independent parts on two threads give exactly the rows and vanishing point of
//! one thread (`Detector::set_threads`, `[pipeline] threads`): every method on synthetic
//! fields through both ideal lenses (the paper's two protocols, colour and grey) and on a
//! forward-looking pinhole.

use omnirow::camera::{ideal_fisheye, ideal_pal, Calibration};
use omnirow::detect::{Detection, Detector, DetectorOptions, Method};
use omnirow::frame::ImageView;
use omnirow::synth::{random_scene, render, Protocol, Style};

fn detections(cal: &Calibration, method: Method, threads: usize, seeds: &[u64]) -> Vec<Detection> {
    let opts = DetectorOptions {
        method,
        ..Default::default()
    };
    let mut det = Detector::new(cal, opts).unwrap();
    det.set_threads(threads).unwrap();
    seeds
        .iter()
        .map(|&seed| {
            let protocol = if seed % 2 == 0 {
                Protocol::Table1
            } else {
                Protocol::Table2
            };
            let mut scene = random_scene(seed, protocol);
            if seed % 3 == 0 {
                scene.style = Style::Colour;
            }
            let (img, _) = render(cal, &scene, seed).unwrap();
            let view = ImageView::new(img.width, img.height, img.format, &img.data).unwrap();
            let mut out = Detection::default();
            det.process(&view, &mut out).unwrap();
            out
        })
        .collect()
}

#[test]
fn two_threads_find_what_one_does() {
    let pinhole = Calibration::parse_toml(
        "[pinhole]\nwidth = 640\nheight = 480\nfx = 375.0\nfy = 375.0\ncx = 319.5\ncy = 239.5\n\
         [mounting]\npitch_deg = -55.0\n",
        std::path::Path::new("pinhole.toml"),
    )
    .unwrap();
    let lenses = [
        ("fisheye", ideal_fisheye(512, 612).unwrap()),
        ("pal", ideal_pal(512, 612).unwrap()),
        ("pinhole", pinhole),
    ];
    let seeds = [1, 2, 3, 4, 5, 6];
    for (name, cal) in &lenses {
        for method in [Method::Auto, Method::Combined, Method::Hough, Method::Edge] {
            let one = detections(cal, method, 1, &seeds);
            let two = detections(cal, method, 2, &seeds);
            assert_eq!(one, two, "{name}, {method:?}");
            let found = one.iter().filter(|d| d.vanishing_point.is_some()).count();
            assert!(
                found >= 3 || method == Method::Edge,
                "{name}, {method:?}: {found} of 6"
            );
        }
    }
}
