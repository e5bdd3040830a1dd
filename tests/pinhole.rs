//! Perspective cameras: `omnirow calib from-camera-info` on ROS camera_info files (its
//! conversion error printed and bounded), the written `[pinhole]` TOML read back, and bad input
//! named clearly.

use nalgebra::Vector3;
use omnirow::camera::{Calibration, DistortionModel, Pinhole, PinholeToml};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn omnirow(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_omnirow"))
        .args(args)
        .output()
        .unwrap()
}

fn dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A camera_calibration file for a 640×480 camera with distortion `model` and `d`.
fn camera_info(model: &str, d: &[f64]) -> String {
    format!(
        "image_width: 640\nimage_height: 480\ncamera_name: front\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: [420.0, 0, 322.5, 0, 424.0, 236.0, 0, 0, 1]\ndistortion_model: {model}\ndistortion_coefficients:\n  rows: 1\n  cols: {}\n  data: {d:?}\nrectification_matrix:\n  rows: 3\n  cols: 3\n  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]\n",
        d.len()
    )
}

/// Converts `yaml`; the written TOML's path and the printed conversion line's max error (px).
fn convert(d: &Path, yaml: &str) -> (PathBuf, f64, String) {
    let input = d.join("camera_info.yaml");
    std::fs::write(&input, yaml).unwrap();
    let out = d.join("camera.toml");
    let run = omnirow(&[
        "calib",
        "from-camera-info",
        input.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&run.stdout).into_owned();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let max: f64 = stdout
        .split("max ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no max error in {stdout}"));
    (out, max, stdout)
}

/// Largest distance between the calibration's pixel of a ray and the pinhole's own, over rays
/// through a grid of pixels.
fn worst_reprojection(cal: &Calibration, p: &Pinhole) -> f64 {
    let mut worst = 0.0f64;
    for row in (0..480).step_by(16) {
        for col in (0..640).step_by(16) {
            let ray: Vector3<f64> = cal.model.cam2world(row as f64, col as f64);
            let q = p.project(&ray).unwrap();
            worst = worst.max((q[0] - row as f64).hypot(q[1] - col as f64));
        }
    }
    worst
}

#[test]
fn plumb_bob_radial_converts_within_a_hundredth_of_a_pixel() {
    let d = dir("pinhole_plumb_bob");
    let (toml, max, line) = convert(
        &d,
        &camera_info("plumb_bob", &[-0.3, 0.09, 0.0, 0.0, -0.01]),
    );
    assert!(max < 0.01, "{line}");
    assert!(!line.contains("tangential"), "{line}");
    // The file reads back as the same camera, and its Taylor model lands on the pinhole's pixels.
    let text = std::fs::read_to_string(&toml).unwrap();
    let raw: PinholeToml = toml::from_str(
        &text
            .lines()
            .filter(|l| !l.starts_with('#'))
            .collect::<Vec<_>>()
            .join("\n"),
    )
    .unwrap();
    assert_eq!(raw.pinhole.distortion_model, DistortionModel::PlumbBob);
    assert_eq!((raw.pinhole.fx, raw.pinhole.cy), (420.0, 236.0));
    let cal = Calibration::load(&toml).unwrap();
    assert_eq!(cal.size(), (480, 640));
    assert!(worst_reprojection(&cal, &raw.pinhole) < 0.01);
    // Pixel -> ray -> pixel through the Taylor model is exact.
    assert!(cal.worst_round_trip_px(8).0 < 1e-9);
    // `calib show` prints the conversion too.
    let show = omnirow(&["calib", "show", toml.to_str().unwrap()]);
    let s = String::from_utf8_lossy(&show.stdout);
    assert!(
        s.contains("conversion") && s.contains("image size      480 x 640"),
        "{s}"
    );
}

#[test]
fn tangential_distortion_is_reported_as_the_residual() {
    let d = dir("pinhole_tangential");
    let (_, max, line) = convert(
        &d,
        &camera_info("plumb_bob", &[-0.3, 0.09, 0.002, -0.001, 0.0]),
    );
    assert!(line.contains("tangential"), "{line}");
    assert!(max > 0.5 && max < 10.0, "{line}");
}

#[test]
fn equidistant_fisheye_converts() {
    let d = dir("pinhole_equidistant");
    let (toml, max, line) = convert(
        &d,
        &camera_info("equidistant", &[0.05, -0.01, 0.002, -0.0003]),
    );
    assert!(max < 0.02, "{line}");
    let cal = Calibration::load(&toml).unwrap();
    assert_eq!(cal.size(), (480, 640));
    // Without a mask in camera_info, a fisheye's image circle is found from each image.
    assert_eq!(cal.mask, None);
}

#[test]
fn undistorted_pinhole_toml_round_trips() {
    let text = "[pinhole]\nwidth = 320\nheight = 240\nfx = 250.0\nfy = 260.0\ncx = 160.0\ncy = 119.5\n\n[mounting]\npitch_deg = -60.0\n";
    let cal = Calibration::parse_toml(text, Path::new("p.toml")).unwrap();
    assert_eq!(cal.model.ss, vec![-250.0, 0.0]);
    assert_eq!((cal.model.xc, cal.model.yc), (119.5, 160.0));
    assert!((cal.model.c - 260.0 / 250.0).abs() < 1e-15);
    assert_eq!(cal.mounting.pitch_deg, -60.0);
    // Its Taylor form written out and read back is the same camera.
    let back = Calibration::parse_toml(&cal.to_toml(), Path::new("t.toml")).unwrap();
    assert_eq!(back.model.ss, cal.model.ss);
    assert_eq!(back.mask, cal.mask);
    // A ray 26 px below the principal point at fy = 260 is 0.1 below the axis.
    let ray = cal.model.cam2world(145.5, 160.0);
    assert!((ray.x / -ray.z - 0.1).abs() < 1e-12);
}

#[test]
fn bad_input_is_named() {
    let d = dir("pinhole_bad");
    let run = |yaml: &str, out: &str| {
        let input = d.join("in.yaml");
        std::fs::write(&input, yaml).unwrap();
        let r = omnirow(&[
            "calib",
            "from-camera-info",
            input.to_str().unwrap(),
            "--out",
            d.join(out).to_str().unwrap(),
        ]);
        assert!(!r.status.success());
        String::from_utf8_lossy(&r.stderr).into_owned()
    };
    let e = run(&camera_info("rational_polynomial", &[0.1; 8]), "c.toml");
    assert!(
        e.contains("in.yaml") && e.contains("rational_polynomial"),
        "{e}"
    );
    let e = run("image_width: 640\nimage_height: [\n", "c.toml");
    assert!(e.contains("in.yaml:"), "{e}");
    let e = run(&camera_info("plumb_bob", &[0.0; 5]), "c.yaml");
    assert!(e.contains("c.yaml") && e.contains(".toml"), "{e}");
    let e = run(
        &camera_info("plumb_bob", &[0.0; 5]).replace("420.0", "-420.0"),
        "c.toml",
    );
    assert!(e.contains("fx"), "{e}");
    // A [pinhole] table with an unknown key: the file, the line and the key.
    let toml = d.join("bad.toml");
    std::fs::write(&toml, "[pinhole]\nwidth = 320\nheight = 240\nfx = 250.0\nfy = 250.0\ncx = 160.0\ncy = 120.0\nfocal = 3\n").unwrap();
    let e = Calibration::load(&toml).unwrap_err().to_string();
    assert!(e.contains("bad.toml:8") && e.contains("focal"), "{e}");
}
