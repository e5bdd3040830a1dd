//! Per-row distance of detected row normals from the plane perpendicular to the true vanishing
//! point (signed, mrad), per method, on one synthetic image: shows whether a method's rows are
//! biased. `cargo run --release --example edge_residuals -- [fisheye|pal] [seed]`
use nalgebra::Vector3;
use omnirow::camera::{ideal_fisheye, ideal_pal};
use omnirow::detect::{Detection, Detector, DetectorOptions, Method};
use omnirow::frame::ImageView;
use omnirow::synth::{random_scene, render, Protocol};
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let (h, w) = (1025, 1224);
    let cal = if a.get(1).map(String::as_str) == Some("pal") {
        ideal_pal(h, w).unwrap()
    } else {
        ideal_fisheye(h, w).unwrap()
    };
    let seed: u64 = a.get(2).and_then(|s| s.parse().ok()).unwrap_or(1);
    let (img, truth) = render(&cal, &random_scene(seed, Protocol::Table1), seed).unwrap();
    let view = ImageView::new(img.width, img.height, img.format, &img.data).unwrap();
    let vp = Vector3::from(truth.vp_along);
    for m in [Method::Hough, Method::Edge] {
        let base: DetectorOptions = std::env::var("OMNIROW_DETECTOR")
            .map(|t| toml::from_str(&t).unwrap())
            .unwrap_or_default();
        let mut d = Detector::new(&cal, DetectorOptions { method: m, ..base }).unwrap();
        let mut out = Detection::default();
        d.process(&view, &mut out).unwrap();
        let mut v: Vec<(f64, u32)> = out
            .rows
            .iter()
            .map(|r| (r.normal.dot(&vp).asin() * 1e3, r.support))
            .filter(|x| x.0.abs() < 17.0)
            .collect();
        v.sort_by_key(|x| std::cmp::Reverse(x.1));
        let e = out
            .vanishing_point
            .map(|p| omnirow::sphere::axis_angle(&p.direction, &vp) * 1e3);
        println!(
            "{}: vp err {:?} mrad; rows within 1 deg (mrad, support):",
            m.name(),
            e
        );
        for (x, s) in v.iter().take(25) {
            print!(" ({x:.2},{s})");
        }
        println!();
    }
}
