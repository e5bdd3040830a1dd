//! `omnirow eval` run as a binary on a handful of images: it writes the tables, the plots and
//! the raw outcomes, and the numbers in them are consistent.

use std::path::Path;
use std::process::Command;

#[test]
fn eval_writes_tables_plots_and_outcomes() {
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("eval_cli");
    let _ = std::fs::remove_dir_all(&out);
    let run = Command::new(env!("CARGO_BIN_EXE_omnirow"))
        .args([
            "eval",
            "--quick",
            "--images",
            "2",
            "--table2-images",
            "1",
            "--distance-images",
            "1",
            "--methods",
            "hough",
            "--seed",
            "7",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    let md = std::fs::read_to_string(out.join("README.md")).unwrap();
    for needle in [
        "## Table I",
        "## Figures 8 and 9",
        "## Table II",
        "## Speed",
        "| hough |",
    ] {
        assert!(md.contains(needle), "missing {needle} in\n{md}");
    }
    for lens in ["fisheye185", "pal"] {
        let png = image::open(out.join(format!("detection_rate_{lens}.png"))).unwrap();
        assert_eq!((png.width(), png.height()), (640, 420));
    }
    let lines: Vec<serde_json::Value> = std::fs::read_to_string(out.join("outcomes.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    // 2 Table I images + 3 distances x 2 lenses x 1 + 2 lenses x 1 Table II image, one method.
    assert_eq!(lines.len(), 2 + 6 + 2);
    for l in &lines {
        assert_eq!(l["method"], "hough");
        assert!(l["rows_correct"].as_u64().unwrap() <= l["rows_found"].as_u64().unwrap());
        if let Some(e) = l["vp_error_rad"].as_f64() {
            assert!((0.0..=std::f64::consts::FRAC_PI_2).contains(&e));
        }
    }
    // The Table I row counts the images it was given.
    assert!(
        md.contains("| hough | 2/2 |")
            || md.contains("| hough | 1/2 |")
            || md.contains("| hough | 0/2 |"),
        "{md}"
    );
}

#[test]
fn eval_rejects_unknown_methods_and_bad_lenses() {
    let run = Command::new(env!("CARGO_BIN_EXE_omnirow"))
        .args(["eval", "--quick", "--methods", "magic"])
        .output()
        .unwrap();
    assert!(!run.status.success());
    assert!(String::from_utf8_lossy(&run.stderr).contains("unknown method 'magic'"));
    let run = Command::new(env!("CARGO_BIN_EXE_omnirow"))
        .args(["eval", "--quick", "--lens", "/nonexistent/lens.txt"])
        .output()
        .unwrap();
    assert!(!run.status.success());
    assert!(String::from_utf8_lossy(&run.stderr).contains("/nonexistent/lens.txt"));
}
