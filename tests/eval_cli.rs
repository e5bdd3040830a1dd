//! `omnirow eval` run as a binary on a handful of images: it writes the tables, the plots and
//! the raw outcomes, and the numbers in them are consistent.

use std::path::Path;
use std::process::{Command, Output};

/// Runs the binary.
fn omnirow(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_omnirow"))
        .args(args)
        .output()
        .unwrap()
}

/// Runs the binary, which must succeed; its standard output.
fn omnirow_ok(args: &[&str]) -> String {
    let run = omnirow(args);
    assert!(
        run.status.success(),
        "omnirow {args:?}: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    String::from_utf8(run.stdout).unwrap()
}

/// The outcomes.jsonl an eval wrote into `dir`, a value per line.
fn outcomes(dir: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(dir.join("outcomes.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn eval_writes_tables_plots_and_outcomes() {
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("eval_cli");
    let _ = std::fs::remove_dir_all(&out);
    omnirow_ok(&[
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
        out.to_str().unwrap(),
    ]);
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
    for file in [
        "detection_rate_fisheye185.png",
        "detection_rate_pal.png",
        "table1.png",
        "table2.png",
    ] {
        let png = image::open(out.join(file)).unwrap();
        assert_eq!((png.width(), png.height()), omnirow::eval::chart::SIZE);
    }
    assert!(md.contains("](table1.png)") && md.contains("](table2.png)"));
    let lines = outcomes(&out);
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
    let run = omnirow(&["eval", "--quick", "--methods", "magic"]);
    assert!(!run.status.success());
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("invalid value 'magic'"), "{err}");
    assert!(err.contains("hough"), "{err}");
    let run = omnirow(&["eval", "--quick", "--lens", "/nonexistent/lens.txt"]);
    assert!(!run.status.success());
    assert!(String::from_utf8_lossy(&run.stderr).contains("/nonexistent/lens.txt"));
    // thread counts outside 1..=16 are named
    for args in [
        &["eval", "guidance", "--threads", "0"][..],
        &[
            "eval",
            "real",
            "--images",
            ".",
            "--labels",
            ".",
            "--calib",
            "x",
            "--threads",
            "17",
        ],
    ] {
        let run = omnirow(args);
        assert!(!run.status.success(), "{args:?}");
        let err = String::from_utf8_lossy(&run.stderr);
        assert!(err.contains("--threads"), "{args:?}: {err}");
    }
}

/// The seed in outcomes.jsonl renders the Table II image again with `omnirow synth`, and
/// `omnirow detect` on it gives the vanishing point the evaluation scored, as the report says.
#[test]
fn table2_outcomes_reproduce_with_synth_and_detect() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("eval_cli_reproduce");
    let _ = std::fs::remove_dir_all(&dir);
    let out = dir.join("eval");
    omnirow_ok(&[
        "eval",
        "--quick",
        "--images",
        "0",
        "--distance-images",
        "0",
        "--table2-images",
        "1",
        "--methods",
        "hough,combined",
        "--seed",
        "11",
        "--out",
        out.to_str().unwrap(),
    ]);
    let md = std::fs::read_to_string(out.join("README.md")).unwrap();
    // The image-by-image comparison has one "passes / fails" cell per lens.
    assert!(md.contains("| against | fisheye185 | pal |"), "{md}");
    let against = md
        .lines()
        .find(|l| l.starts_with("| hough |") && l.contains(" / "))
        .unwrap_or_else(|| panic!("no comparison row in\n{md}"));
    assert_eq!(against.matches(" / ").count(), 2, "{against}");
    assert!(!md.contains("both fail"), "edge was not run:\n{md}");
    let lines = outcomes(&out);
    assert_eq!(lines.len(), 4);
    for o in lines.iter().filter(|o| o["method"] == "hough") {
        let lens = o["lens"].as_str().unwrap();
        let seed = o["seed"].as_u64().unwrap().to_string();
        assert!(
            o["noise"].as_f64().unwrap() > 0.0 && o["weeds"].is_u64(),
            "{o}"
        );
        let png = dir.join(format!("{lens}.png"));
        let truth = dir.join(format!("{lens}.json"));
        omnirow_ok(&[
            "synth",
            "--lens",
            lens,
            "--random",
            "table2",
            "--seed",
            &seed,
            "--scale",
            "0.5",
            "--out",
            png.to_str().unwrap(),
            "--truth",
            truth.to_str().unwrap(),
        ]);
        let calib = format!(
            "{}/config/calib/{lens}_gc2450c.toml",
            env!("CARGO_MANIFEST_DIR")
        );
        let det: serde_json::Value = serde_json::from_str(&omnirow_ok(&[
            "detect",
            "--calib",
            &calib,
            "--method",
            "hough",
            png.to_str().unwrap(),
        ]))
        .unwrap();
        let truth: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&truth).unwrap()).unwrap();
        let v = |x: &serde_json::Value| -> Vec<f64> {
            x.as_array()
                .unwrap()
                .iter()
                .map(|c| c.as_f64().unwrap())
                .collect()
        };
        let (a, b) = (v(&det["vanishing_point"]), v(&truth["vp_along"]));
        let dot: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
        let err = dot.abs().min(1.0).acos();
        let scored = o["vp_error_rad"].as_f64().unwrap();
        assert!(
            (err - scored).abs() < 1e-6,
            "{lens} seed {seed}: detect gives {err}, eval scored {scored}"
        );
    }
}

/// `--config` scores the detector with a configuration's `[detector]` options, and a bad
/// configuration is an error naming the file and the key.
#[test]
fn eval_scores_a_configurations_detector() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("eval_cli_config");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let one_row = dir.join("one_row.toml");
    std::fs::write(&one_row, "[detector.hough]\nmax_rows = 1\n").unwrap();
    let out = dir.join("eval");
    omnirow_ok(&[
        "eval",
        "--quick",
        "--images",
        "2",
        "--distance-images",
        "0",
        "--table2-images",
        "0",
        "--methods",
        "hough",
        "--config",
        one_row.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let found: Vec<u64> = outcomes(&out)
        .iter()
        .map(|o| o["rows_found"].as_u64().unwrap())
        .collect();
    assert_eq!(found, vec![1, 1], "max_rows = 1 was not applied");
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "[detector.hough]\nmax_rowz = 1\n").unwrap();
    let run = omnirow(&["eval", "--quick", "--config", bad.to_str().unwrap()]);
    assert!(!run.status.success());
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        err.contains("bad.toml") && err.contains("max_rowz"),
        "{err}"
    );
}

#[test]
fn eval_leafy_reports_table1_on_the_second_appearance() {
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("eval_cli_leafy");
    let _ = std::fs::remove_dir_all(&out);
    omnirow_ok(&[
        "eval",
        "--quick",
        "--images",
        "2",
        "--distance-images",
        "0",
        "--table2-images",
        "0",
        "--methods",
        "hough",
        "--leafy",
        "--out",
        out.to_str().unwrap(),
    ]);
    let lines = outcomes(&out);
    let leafy: Vec<_> = lines
        .iter()
        .filter(|o| o["experiment"] == "table1leafy")
        .collect();
    assert_eq!((lines.len(), leafy.len()), (4, 2));
    // The same scenes (seeds) as Table I's.
    let seeds = |e: &str| -> Vec<u64> {
        lines
            .iter()
            .filter(|o| o["experiment"] == e)
            .map(|o| o["seed"].as_u64().unwrap())
            .collect()
    };
    assert_eq!(seeds("table1"), seeds("table1leafy"));
    let md = std::fs::read_to_string(out.join("README.md")).unwrap();
    assert!(
        md.contains("### Table I on the second appearance model"),
        "{md}"
    );
}

/// ../shared/real-fields/crdld beside the repository, when present.
fn crdld() -> Option<std::path::PathBuf> {
    let root = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/real-fields/crdld"
    ))
    .to_path_buf();
    if root.join("image").is_dir() && root.join("label").is_dir() {
        Some(root)
    } else {
        eprintln!("skipping: {} is absent", root.display());
        None
    }
}

/// `eval guidance` over two photographs' grounds through a calibration: a row per
/// photograph and one pooling both, an offset on every frame; a drive a photograph cannot
/// show (curved rows) is refused naming why.
#[test]
fn eval_guidance_runs_over_photographs_through_a_calibration() {
    let Some(root) = crdld() else { return };
    let calib = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/config/calib/fisheye185_gc2450c.toml"
    );
    let (images, labels) = (root.join("image"), root.join("label"));
    let out = std::env::temp_dir().join(format!("omnirow-eval-photo-{}", std::process::id()));
    let common = [
        "eval",
        "guidance",
        "--calib",
        calib,
        "--scale",
        "0.5",
        "--images",
        images.to_str().unwrap(),
        "--labels",
        labels.to_str().unwrap(),
        "--seconds",
        "0.4",
        "--out",
        out.to_str().unwrap(),
    ];
    let md = omnirow_ok(&[&common[..], &["--photos", "2", "--drives", "weaving"]].concat());
    let rows: Vec<&str> = md.lines().filter(|l| l.starts_with("| weaving")).collect();
    assert_eq!(rows.len(), 3, "{md}");
    assert!(rows[0].starts_with("| weaving@"), "{md}");
    assert!(
        rows[2].starts_with("| weaving (2 photographs) | 12 |"),
        "{md}"
    );
    let run = omnirow(&[&common[..], &["--drives", "curved_r20"]].concat());
    assert!(!run.status.success());
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("curvature_per_m"), "{err}");
    // --photos needs photographs; --scale a calibration
    for args in [
        &["eval", "guidance", "--photos", "2"][..],
        &["eval", "guidance", "--scale", "0.5"],
    ] {
        let run = omnirow(args);
        assert!(!run.status.success(), "{args:?}");
    }
    std::fs::remove_dir_all(&out).ok();
}
