//! Runs `omnirow synth` as a user would: images and ground truth on disk, errors on bad input.

use std::path::PathBuf;
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_omnirow"))
}

fn tmp_dir(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("synth_cli_{name}"));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn writes_png_and_truth() {
    let dir = tmp_dir("ok");
    for (lens, style, channels) in [
        ("fisheye185", "grey", 1),
        ("pal", "colour", 3),
        ("pal", "bayer", 1),
    ] {
        let png = dir.join(format!("{lens}_{style}.png"));
        let json = dir.join(format!("{lens}_{style}.json"));
        let out = bin()
            .args(["synth", "--lens", lens, "--style", style, "--scale", "0.5"])
            .args([
                "--seed",
                "7",
                "--yaw-deg",
                "-12",
                "--pitch-deg",
                "3",
                "--noise",
                "0.1",
            ])
            .args([
                "--weeds",
                "20",
                "--along-sd-m",
                "0.01",
                "--across-sd-m",
                "0.01",
            ])
            .arg("--out")
            .arg(&png)
            .arg("--truth")
            .arg(&json)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{stderr}");
        assert!(
            stderr.contains("synth:") && stderr.contains("rows"),
            "{stderr}"
        );
        let img = image::open(&png).unwrap();
        assert_eq!((img.width(), img.height()), (1224, 1025));
        assert_eq!(img.color().channel_count(), channels);
        let truth: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        assert_eq!(truth["seed"], 7);
        assert!((truth["yaw_rad"].as_f64().unwrap() + 12f64.to_radians()).abs() < 1e-12);
        assert!((truth["heading_rad"].as_f64().unwrap() - 12f64.to_radians()).abs() < 0.01);
        assert_eq!(truth["noise"]["weeds"], 20);
        assert_eq!(truth["noise"]["background_density"], 0.1);
        let rows = truth["row_normals"].as_array().unwrap();
        assert!(rows.len() >= 4, "{}", rows.len());
        assert_eq!(rows.len(), truth["row_lateral_m"].as_array().unwrap().len());
        let vp = truth["vp_along"].as_array().unwrap();
        assert_eq!(vp.len(), 3);
    }
}

#[test]
fn same_seed_same_image_and_random_protocols() {
    let dir = tmp_dir("seed");
    let run = |name: &str, extra: &[&str]| {
        let png = dir.join(format!("{name}.png"));
        let json = dir.join(format!("{name}.json"));
        let out = bin()
            .args(["synth", "--scale", "0.5", "--seed", "3"])
            .args(extra)
            .arg("--out")
            .arg(&png)
            .arg("--truth")
            .arg(&json)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        (
            std::fs::read(png).unwrap(),
            std::fs::read_to_string(json).unwrap(),
        )
    };
    let a = run("a", &["--random", "table2"]);
    let b = run("b", &["--random", "table2"]);
    assert_eq!(a, b);
    let c = run("c", &["--random", "table1"]);
    assert_ne!(a.1, c.1);
    let t: serde_json::Value = serde_json::from_str(&c.1).unwrap();
    assert_eq!(t["noise"]["background_density"], 0.1);
    assert_eq!(t["plant_distance_m"], 0.03);
}

#[test]
fn options_file_and_small_built_in_lens() {
    let dir = tmp_dir("opts");
    let opts = dir.join("scene.toml");
    std::fs::write(
        &opts,
        "yaw_deg = 7.5\nleaf_length_m = 0.05\nstyle = \"colour\"\n",
    )
    .unwrap();
    let png = dir.join("s.png");
    let json = dir.join("s.json");
    let out = bin()
        .args([
            "synth",
            "--lens",
            "pal",
            "--image-height",
            "200",
            "--image-width",
            "240",
        ])
        .args(["--pitch-deg", "2", "--options"])
        .arg(&opts)
        .arg("--out")
        .arg(&png)
        .arg("--truth")
        .arg(&json)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let img = image::open(&png).unwrap();
    assert_eq!(
        (img.width(), img.height(), img.color().channel_count()),
        (240, 200, 3)
    );
    let t: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert!((t["yaw_rad"].as_f64().unwrap() - 7.5f64.to_radians()).abs() < 1e-12);
    assert!((t["pitch_rad"].as_f64().unwrap() - 2f64.to_radians()).abs() < 1e-12);
}

#[test]
fn bad_arguments_fail_clearly() {
    let dir = tmp_dir("bad");
    let png = dir.join("x.png");
    let cases: &[(&[&str], &str)] = &[
        (&["--noise", "2"], "noise"),
        (&["--height-m", "0"], "height_m"),
        (&["--scale", "0.3"], "scale"),
        (&["--scale", "0"], "--scale 0: must be a positive factor"),
        (&["--style", "sepia"], "sepia"),
        (
            &["--calib", "/nonexistent/calib.txt"],
            "/nonexistent/calib.txt",
        ),
    ];
    for (args, needle) in cases {
        let out = bin()
            .arg("synth")
            .args(*args)
            .arg("--out")
            .arg(&png)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert!(stderr.contains(needle), "{args:?}: {stderr}");
    }
    let out = bin()
        .args(["synth", "--out"])
        .arg(dir.join("x.jpg"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains(".png"));
    // an options file with an unknown key names the file and the key
    let opts = dir.join("bad.toml");
    std::fs::write(&opts, "leaf_length_m = 0.05\nyaw = 3\n").unwrap();
    let out = bin()
        .args([
            "synth",
            "--image-height",
            "64",
            "--image-width",
            "80",
            "--options",
        ])
        .arg(&opts)
        .arg("--out")
        .arg(&png)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("bad.toml") && stderr.contains("yaw"),
        "{stderr}"
    );
    // missing --out
    let out = bin().args(["synth"]).output().unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--out"));
}
