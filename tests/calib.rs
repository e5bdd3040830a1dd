//! The camera model against the real OCamCalib calibrations in ../shared/calib and the real
//! checkerboard data in ../shared/real, and `omnirow calib` run as a binary.

use nalgebra::{Matrix3, Vector3};
use omnirow::camera::{Calibration, OcamModel};
use std::path::{Path, PathBuf};
use std::process::Command;

fn shared(rel: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared")
        .join(rel);
    if p.exists() {
        Some(p)
    } else {
        println!(
            "skipped: {} is absent (no ../shared beside the checkout)",
            p.display()
        );
        None
    }
}

fn shared_calibs() -> Vec<PathBuf> {
    let Some(dir) = shared("calib") else {
        return Vec::new();
    };
    let mut v: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "txt"))
        .collect();
    v.sort();
    v
}

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_omnirow"))
}

/// Every pixel of the valid field (inside the image, where the model is monotone): pixel → ray
/// → pixel within 0.01 px. Prints the worst per file.
#[test]
fn round_trip_over_whole_valid_field_of_every_shared_calibration() {
    let files = shared_calibs();
    for f in &files {
        let cal = Calibration::load(f).unwrap();
        let (worst, at) = cal.worst_round_trip_px(1);
        println!(
            "{}: worst round trip {worst:.2e} px at row {} col {}",
            f.file_name().unwrap().to_string_lossy(),
            at[0],
            at[1]
        );
        assert!(worst < 0.01, "{}: {worst} px", f.display());
    }
    // The shipped calibrations too.
    for f in [
        "config/calib/fisheye185_gc2450c.toml",
        "config/calib/pal_gc2450c.toml",
    ] {
        let cal = Calibration::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join(f)).unwrap();
        let (worst, _) = cal.worst_round_trip_px(3);
        println!("{f}: worst round trip {worst:.2e} px");
        assert!(worst < 0.01, "{f}: {worst}");
    }
}

/// The published inverse polynomial agrees with our refined world2cam where it is valid
/// (inside the inscribed circle), except the 33-coefficient file whose printed coefficients
/// lose precision (FORMAT.md: 0.32 px).
#[test]
fn published_inverse_polynomial_agrees_inside_inscribed_circle() {
    for f in shared_calibs() {
        let cal = Calibration::load(&f).unwrap();
        let m = &cal.model;
        let r_in = cal.inscribed_radius_px().min(m.rho_valid_max() * 0.95);
        let mut worst: f64 = 0.0;
        for i in 0..2000 {
            let a = i as f64 * 0.618_033_988_7 * std::f64::consts::TAU;
            let r = r_in * ((i % 50) as f64 / 50.0);
            let (row, col) = (m.xc + r * a.sin(), m.yc + r * a.cos());
            let ray = m.cam2world(row, col);
            let p = m.world2cam_invpol(&ray);
            worst = worst.max((p[0] - row).hypot(p[1] - col));
        }
        let name = f.file_name().unwrap().to_string_lossy().to_string();
        println!("{name}: published invpol vs exact inverse, worst {worst:.4} px");
        let limit = if m.invpol.len() == 33 { 0.5 } else { 0.02 };
        assert!(worst < limit, "{name}: {worst}");
    }
}

#[test]
fn rescaled_shared_calibrations_agree_with_full_resolution() {
    for f in shared_calibs() {
        let cal = Calibration::load(&f).unwrap();
        let half = cal.rescaled(2.0).unwrap();
        let (h, w) = half.size();
        for r in (0..h).step_by(37) {
            for c in (0..w).step_by(41) {
                let a = half.model.cam2world(r as f64, c as f64);
                let b = cal
                    .model
                    .cam2world(2.0 * r as f64 + 0.5, 2.0 * c as f64 + 0.5);
                assert!((a - b).norm() < 1e-12, "{}: ({r},{c})", f.display());
                if let (Some(p), Some(q)) = (half.model.world2cam(&a), cal.model.world2cam(&a)) {
                    assert!((2.0 * p[0] + 0.5 - q[0]).abs() < 1e-6);
                    assert!((2.0 * p[1] + 0.5 - q[1]).abs() < 1e-6);
                }
            }
        }
    }
}

/// Real checkerboard corners reproject through our model with the fitted board poses, and the
/// board's vanishing points land where ../shared/real says.
#[test]
fn real_checkerboards_reproject_and_vanishing_points_match() {
    let Some(json) = shared("real/checkerboard_corners_and_poses.json") else {
        return;
    };
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(json).unwrap()).unwrap();
    for set in v["sets"].as_array().unwrap() {
        let calib = shared(set["calib_file"].as_str().unwrap()).unwrap();
        let model = OcamModel::load(&calib).unwrap();
        for img in set["images"].as_array().unwrap() {
            let r = &img["R_board_to_cam"];
            let rot = Matrix3::from_fn(|i, j| r[i][j].as_f64().unwrap());
            let t = Vector3::from_fn(|i, _| img["t_board_to_cam_mm"][i].as_f64().unwrap());
            let corners = img["corners_row_col_0based"].as_array().unwrap();
            let board = img["board_xy_mm"].as_array().unwrap();
            let mut sq = 0.0;
            for (c, b) in corners.iter().zip(board) {
                let p = rot * Vector3::new(b[0].as_f64().unwrap(), b[1].as_f64().unwrap(), 0.0) + t;
                let px = model
                    .world2cam(&p)
                    .expect("corner inside the model's range");
                sq += (px[0] - c[0].as_f64().unwrap()).powi(2)
                    + (px[1] - c[1].as_f64().unwrap()).powi(2);
            }
            let rms = (sq / corners.len() as f64).sqrt();
            let published = img["rms_px"].as_f64().unwrap();
            assert!(
                (rms - published).abs() < 0.05,
                "{}: rms {rms} vs {published}",
                img["image"]
            );
            for (key, col, sign) in [
                ("vp_board_x_plus_row_col", 0, 1.0),
                ("vp_board_x_minus_row_col", 0, -1.0),
                ("vp_board_y_plus_row_col", 1, 1.0),
                ("vp_board_y_minus_row_col", 1, -1.0),
            ] {
                if let Some(vp) = img[key].as_array() {
                    let dir: Vector3<f64> = rot.column(col) * sign;
                    // The published points were projected with the published inverse
                    // polynomial; our exact inverse agrees to within its fit error.
                    let (vr, vc) = (vp[0].as_f64().unwrap(), vp[1].as_f64().unwrap());
                    let px = model.world2cam_invpol(&dir);
                    let d = (px[0] - vr).hypot(px[1] - vc);
                    assert!(d < 0.02, "{} {key}: {d} px", img["image"]);
                    let Some(px) = model.world2cam(&dir) else {
                        panic!(
                            "{} {key}: exact inverse has no pixel for {dir:?}, theta range {:?}",
                            img["image"],
                            model.theta_range()
                        );
                    };
                    let d = (px[0] - vr).hypot(px[1] - vc);
                    assert!(d < 0.5, "{} {key}: exact inverse {d} px away", img["image"]);
                }
            }
        }
    }
}

#[test]
fn calib_show_prints_every_shared_file() {
    for f in shared_calibs() {
        let out = bin().args(["calib", "show"]).arg(&f).output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let s = String::from_utf8(out.stdout).unwrap();
        for key in [
            "image size",
            "centre",
            "inscribed",
            "mask",
            "horizon",
            "round trip",
        ] {
            assert!(s.contains(key), "{}: missing {key} in\n{s}", f.display());
        }
    }
}

#[test]
fn bad_calibration_files_name_file_line_and_problem() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("bad_calibs");
    std::fs::create_dir_all(&dir).unwrap();
    let good = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("config/calib/fisheye185_gc2450c.toml"),
    )
    .unwrap();
    let ocam = Calibration::load(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("config/calib/fisheye185_gc2450c.toml"),
    )
    .unwrap()
    .model
    .to_ocamcalib_text();
    let lines: Vec<&str> = ocam.lines().collect();
    let cases: Vec<(&str, String, &str)> = vec![
        ("empty.txt", String::new(), "direct polynomial"),
        ("truncated.txt", lines[..7].join("\n"), "centre"),
        (
            "nonnumeric.txt",
            ocam.replacen("-6", "-x6", 1),
            "not a number",
        ),
        ("count.txt", ocam.replacen("8 ", "9 ", 1), "announces 9"),
        (
            "affine.txt",
            ocam.replace("\n1 0 0\n", "\n1 1 1\n"),
            "singular",
        ),
        ("size.txt", ocam.replace("2050 2448", "2050"), "expected 2"),
        ("unknown.toml", format!("{good}\nbogus = 1\n"), "bogus"),
        (
            "type.toml",
            good.replace("height = 2050", "height = \"tall\""),
            "line 1",
        ),
    ];
    for (name, text, needle) in cases {
        let path = dir.join(name);
        std::fs::write(&path, &text).unwrap();
        let out = bin().args(["calib", "show"]).arg(&path).output().unwrap();
        assert!(!out.status.success(), "{name} was accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains(name),
            "{name}: error does not name the file: {err}"
        );
        if needle == "line 1" {
            assert!(err.contains(&format!("{name}:1:")), "{name}: {err}");
        } else {
            assert!(
                err.contains(needle),
                "{name}: expected '{needle}' in: {err}"
            );
        }
        assert!(!err.contains("panicked"), "{name}: {err}");
    }
    let out = bin()
        .args(["calib", "show", "/nonexistent/calib.txt"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/calib.txt"));
}

#[test]
fn shipped_calibrations_are_what_the_generator_writes() {
    for (lens, file) in [
        ("fisheye185", "fisheye185_gc2450c.toml"),
        ("pal", "pal_gc2450c.toml"),
    ] {
        let out = bin().args(["calib", "ideal", lens]).output().unwrap();
        assert!(out.status.success());
        let shipped = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("config/calib")
                .join(file),
        )
        .unwrap();
        assert!(
            String::from_utf8_lossy(&out.stdout) == shipped,
            "config/calib/{file} is stale: regenerate with `omnirow calib ideal {lens}`"
        );
    }
}

#[test]
fn ideal_lens_for_a_size_it_cannot_fit_is_an_error() {
    let out = bin()
        .args(["calib", "ideal", "pal", "--height", "4", "--width", "96"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("96x4") && err.contains("16..=20000"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn example_calibration_is_valid_and_documented() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let example = Calibration::load(&root.join("config/calibration.example.toml")).unwrap();
    let shipped = Calibration::load(&root.join("config/calib/fisheye185_gc2450c.toml")).unwrap();
    assert_eq!(example, shipped);
    let text = std::fs::read_to_string(root.join("config/calibration.example.toml")).unwrap();
    for key in [
        "height",
        "width",
        "centre",
        "affine",
        "ss",
        "invpol",
        "inner_radius_px",
        "outer_radius_px",
        "roll_deg",
        "pitch_deg",
        "yaw_deg",
        "height_m",
        "position_m",
    ] {
        let line = text
            .lines()
            .position(|l| l.starts_with(&format!("{key} ")))
            .unwrap();
        let lines: Vec<&str> = text.lines().collect();
        let commented = lines[line.saturating_sub(4)..line]
            .iter()
            .any(|l| l.starts_with('#'));
        assert!(commented, "{key} has no comment above it");
    }
}
