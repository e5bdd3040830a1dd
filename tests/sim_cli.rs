//! Runs `omnirow sim` as a user would: the closed loop on a small synthetic field stays in
//! its path, writes its frames and plots, and bad input gives a clear error. (That the loop
//! is really closed — a flipped controller leaves the path — is the library's test
//! `sim::tests::with_the_steering_sign_flipped_the_robot_leaves_its_path`.)

use std::path::PathBuf;
use std::process::{Command, Output};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_omnirow"))
}

fn tmp_dir(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("sim_cli_{name}"));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The ideal 185° fisheye at 306×256 as a calibration file.
fn small_calib(dir: &std::path::Path) -> PathBuf {
    let out = bin()
        .args([
            "calib",
            "ideal",
            "fisheye185",
            "--height",
            "256",
            "--width",
            "306",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let p = dir.join("fisheye_306x256.toml");
    std::fs::write(&p, &out.stdout).unwrap();
    p
}

/// The JSON summary: the last line on stdout.
fn summary(out: &Output) -> serde_json::Value {
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}\n{stdout}",
        String::from_utf8_lossy(&out.stderr)
    );
    let last = stdout.lines().last().expect("a summary line");
    serde_json::from_str(last).unwrap_or_else(|e| panic!("{e}: {last}"))
}

#[test]
fn the_robot_stays_in_its_path_and_the_run_is_written() {
    let dir = tmp_dir("ok");
    let calib = small_calib(&dir);
    let out_dir = dir.join("out");
    let _ = std::fs::remove_dir_all(&out_dir);
    let out = bin()
        .arg("sim")
        .arg("--calib")
        .arg(&calib)
        .args(["--speed-mps", "1.5", "--distance-m", "8"])
        .args(["--start-offset-m", "0.1", "--start-heading-deg", "5"])
        .args(["--seed", "2", "--latency-ms", "70", "--json"])
        .arg("--out")
        .arg(&out_dir)
        .output()
        .unwrap();
    let s = summary(&out);
    for key in [
        "frames",
        "frames_without_guidance",
        "distance_m",
        "cross_track_mean_m",
        "cross_track_std_m",
        "cross_track_max_m",
        "heading_error_p99_deg",
        "row_changes",
    ] {
        assert!(s.get(key).is_some(), "{key} missing: {s}");
    }
    assert_eq!(s["row_changes"], 0, "{s}");
    assert!(s["cross_track_max_m"].as_f64().unwrap() < 0.05, "{s}");
    assert!(s["cross_track_std_m"].as_f64().unwrap() < 0.02, "{s}");
    assert!(s["distance_m"].as_f64().unwrap() > 7.8, "{s}");
    // 8 m at 1.5 m/s, 15 fps
    let frames = s["frames"].as_u64().unwrap();
    assert!((79..=81).contains(&frames), "{s}");
    assert!(s["frames_without_guidance"].as_u64().unwrap() < 5, "{s}");
    // every frame on a line of frames.jsonl, with the truth, the estimate and the command
    let jsonl = std::fs::read_to_string(out_dir.join("frames.jsonl")).unwrap();
    assert_eq!(jsonl.lines().count() as u64, frames);
    let first: serde_json::Value = serde_json::from_str(jsonl.lines().next().unwrap()).unwrap();
    for key in [
        "t",
        "pose",
        "cross_track_m",
        "heading_error_deg",
        "estimate",
        "command_curvature_per_m",
    ] {
        assert!(first.get(key).is_some(), "{key} missing: {first}");
    }
    assert!((first["cross_track_m"].as_f64().unwrap() - 0.1).abs() < 1e-9);
    for png in ["path.png", "heading.png"] {
        let img = image::open(out_dir.join(png)).unwrap();
        assert!(img.width() > 100, "{png}");
    }
}

#[test]
fn stanley_on_an_ackermann_robot_follows_curved_rows_and_stops_at_their_end() {
    let out = bin()
        .args(["sim", "--lens", "fisheye185"])
        .args(["--image-height", "256", "--image-width", "306"])
        .args(["--controller", "stanley", "--robot", "ackermann"])
        .args(["--curvature-per-m", "0.05", "--rows-end-m", "6"])
        .args([
            "--distance-m",
            "20",
            "--latency-ms",
            "70",
            "--settle-m",
            "3",
        ])
        .arg("--json")
        .output()
        .unwrap();
    let s = summary(&out);
    assert_eq!(s["row_changes"], 0, "{s}");
    assert_eq!(s["reached_rows_end"], true, "{s}");
    assert!(s["distance_m"].as_f64().unwrap() < 6.5, "{s}");
    assert!(s["cross_track_max_m"].as_f64().unwrap() < 0.05, "{s}");
}

#[test]
fn the_human_table_without_json() {
    let out = bin()
        .args(["sim", "--lens", "fisheye185"])
        .args(["--image-height", "256", "--image-width", "306"])
        .args(["--distance-m", "2", "--latency-ms", "50"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("row changes"), "{stdout}");
    assert!(stdout.contains("cross-track"), "{stdout}");
    assert!(!stdout.trim_start().starts_with('{'), "{stdout}");
}

#[test]
fn bad_input_is_a_clear_error() {
    let dir = tmp_dir("bad");
    let missing = dir.join("no_such_calib.toml");
    let out = bin()
        .arg("sim")
        .arg("--calib")
        .arg(&missing)
        .arg("--json")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no_such_calib.toml"), "{err}");
    assert!(out.stdout.is_empty());

    let calib = small_calib(&dir);
    for (args, expect) in [
        (vec!["--speed-mps=-1"], "speed"),
        (vec!["--scale", "0"], "--scale"),
        (vec!["--controller", "bang-bang"], "bang-bang"),
        (vec!["--curvature-per-m", "0.5"], "curvature_per_m"),
        (vec!["--no-such-option"], "--no-such-option"),
    ] {
        let out = bin()
            .arg("sim")
            .arg("--calib")
            .arg(&calib)
            .args(&args)
            .output()
            .unwrap();
        assert!(!out.status.success(), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(expect), "{args:?}: {err}");
    }

    // neither a calibration nor a lens
    let out = bin().args(["sim", "--json"]).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--calib") || err.contains("--lens"), "{err}");

    // a configuration with an unknown key is refused, naming it
    let cfg = dir.join("bad.toml");
    std::fs::write(&cfg, "[guidance]\nno_such_key = 1\n").unwrap();
    let out = bin()
        .arg("sim")
        .arg("--calib")
        .arg(&calib)
        .arg("--config")
        .arg(&cfg)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no_such_key"), "{err}");
}

/// The loop over a ground textured from a real photograph (../shared's CRDLD, skipped when
/// absent), with the field's row spacing configured: the robot keeps its path.
#[test]
fn the_loop_runs_over_a_photographs_ground() {
    let root = std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/real-fields/crdld"
    ));
    if !root.join("image").is_dir() || !root.join("label").is_dir() {
        eprintln!("skipping: {} is absent", root.display());
        return;
    }
    let dir = tmp_dir("photo");
    let cfg = dir.join("spacing.toml");
    std::fs::write(&cfg, "[guidance]\nrow_spacing_m = 0.5\n").unwrap();
    let out = bin()
        .arg("sim")
        .args([
            "--lens",
            "fisheye185",
            "--image-height",
            "512",
            "--image-width",
            "612",
        ])
        .arg("--config")
        .arg(&cfg)
        .arg("--images")
        .arg(root.join("image"))
        .arg("--labels")
        .arg(root.join("label"))
        .args(["--speed-mps", "1.5", "--distance-m", "8", "--settle-m", "4"])
        .args(["--start-offset-m", "0.05", "--latency-ms", "70", "--json"])
        .output()
        .unwrap();
    let s = summary(&out);
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("the ground from"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(s["row_changes"], 0, "{s}");
    assert!(s["cross_track_max_m"].as_f64().unwrap() < 0.1, "{s}");
    assert!(s["frames_without_guidance"].as_u64().unwrap() < 5, "{s}");
}
