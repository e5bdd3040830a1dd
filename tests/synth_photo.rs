//! `omnirow synth --images DIR --labels DIR`: the ground textured from labelled photographs,
//! run as a user would: photographs generated here (the synthetic field through a forward
//! pinhole, labelled from its truth), rejections named, and, where the CRDLD photographs are
//! at ../shared, a few of them rendered through the ideal fisheye and their rows detected.

use nalgebra::Vector3;
use omnirow::camera::Calibration;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bin(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_omnirow"))
        .args(args)
        .output()
        .unwrap()
}

fn text(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn tmp_dir(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("synth_photo_{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn pinhole_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("config/calib/pinhole_512_f300.toml")
}

/// JSON labels of the rows of a truth file: each listed row's centre line, where the image
/// ray is perpendicular to its normal, on every 4th scan line of the image's lower part
/// (below row `from`); the `keep` rows with the most points.
fn labels_of_truth(
    cal: &Calibration,
    truth: &serde_json::Value,
    from: usize,
    keep: usize,
) -> String {
    let (h, w) = cal.size();
    let mut rows = Vec::new();
    for n in truth["row_normals"].as_array().unwrap() {
        let n: Vec<f64> = n
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let n = Vector3::new(n[0], n[1], n[2]);
        let mut xy = Vec::new();
        for r in (from..h as usize).step_by(4) {
            let f = |c: usize| n.dot(&cal.model.cam2world(r as f64, c as f64));
            for c in 0..w as usize - 1 {
                let (a, b) = (f(c), f(c + 1));
                if a == 0.0 || a.signum() != b.signum() {
                    xy.push(format!("[{:.3}, {r}]", c as f64 + a / (a - b)));
                }
            }
        }
        if xy.len() >= 12 {
            rows.push((xy.len(), format!("{{\"xy\": [{}]}}", xy.join(", "))));
        }
    }
    rows.sort_by_key(|r| std::cmp::Reverse(r.0));
    let rows: Vec<String> = rows.into_iter().take(keep).map(|r| r.1).collect();
    format!("{{\"rows\": [{}]}}\n", rows.join(", "))
}

/// Three photographs of the synthetic field through the forward pinhole: two fully labelled,
/// and (the third) with only two rows labelled.
fn photographs(dir: &Path) -> (PathBuf, PathBuf) {
    let cal = Calibration::load(&pinhole_path()).unwrap();
    let (images, labels) = (dir.join("image"), dir.join("label"));
    std::fs::create_dir_all(&images).unwrap();
    std::fs::create_dir_all(&labels).unwrap();
    for (i, yaw, keep) in [(0, "4", 99), (1, "-7", 99), (2, "2", 2)] {
        let (png, json) = (
            images.join(format!("{i}.png")),
            dir.join(format!("{i}.json")),
        );
        let out = bin(&[
            "synth",
            "--calib",
            text(&pinhole_path()),
            "--style",
            "colour",
            "--plant-distance-m",
            "0.05",
            "--yaw-deg",
            yaw,
            "--seed",
            &i.to_string(),
            "--out",
            text(&png),
            "--truth",
            text(&json),
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let truth: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        let l = labels_of_truth(&cal, &truth, 200, keep);
        std::fs::write(labels.join(format!("{i}.json")), l).unwrap();
    }
    (images, labels)
}

#[test]
fn generated_photographs_render_and_rejections_are_named() {
    let dir = tmp_dir("generated");
    let (images, labels) = photographs(&dir);
    let ground = ["--images", text(&images), "--labels", text(&labels)];
    let focal = ["--photo-focal-px", "300"];
    // The survey: two accepted, the third rejected for its two rows.
    let out = bin(&[&["synth", "--photo-survey"][..], &ground, &focal].concat());
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("0.png: accepted") && stdout.contains("1.png: accepted"),
        "{stdout}"
    );
    assert!(
        stdout.contains("2.png: rejected: 2 labelled rows"),
        "{stdout}"
    );
    assert!(
        stdout.contains("accepted 2 of 3 photographs; rejected: 1 too few rows"),
        "{stdout}"
    );
    // Rendered through the fisheye at a pose, with the truth written as always.
    let (png, json) = (dir.join("fish.png"), dir.join("fish.json"));
    let render = [
        "synth",
        "--lens",
        "fisheye185",
        "--image-height",
        "200",
        "--image-width",
        "240",
        "--style",
        "colour",
        "--yaw-deg",
        "9",
        "--out",
        text(&png),
        "--truth",
        text(&json),
    ];
    let out = bin(&[&render[..], &ground, &focal, &["--photo-index", "1"]].concat());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("ground from") && stderr.contains("1.png"),
        "{stderr}"
    );
    let img = image::open(&png).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (240, 200));
    // Green plants from the photograph inside the image circle.
    let green = img
        .pixels()
        .filter(|p| p[1] as i32 > p[0] as i32 + 20)
        .count();
    assert!(green > 500, "{green}");
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert!((truth["heading_rad"].as_f64().unwrap() + 9f64.to_radians()).abs() < 1e-9);
    assert!(truth["row_normals"].as_array().unwrap().len() >= 4);
    // The rejected photograph by index: its reason; an index beyond the folder: the count.
    let out = bin(&[&render[..], &ground, &focal, &["--photo-index", "2"]].concat());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("2.png: rejected: 2 labelled rows"),
        "{stderr}"
    );
    let out = bin(&[&render[..], &ground, &["--photo-index", "7"]].concat());
    assert!(String::from_utf8_lossy(&out.stderr).contains("holds 3 photographs"));
    // None fits (a resolution no photograph reaches): every rejection listed with its reason.
    let out = bin(&[
        &render[..],
        &ground,
        &focal,
        &["--photo-max-sampling-m", "0.0005"],
    ]
    .concat());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("no photograph in"), "{stderr}");
    assert!(
        stderr.contains("2 too little resolution, 1 too few rows"),
        "{stderr}"
    );
    assert!(stderr.contains("0.png: too little resolution"), "{stderr}");
    // Options the texture cannot show are errors naming them.
    let out = bin(&[&render[..], &ground, &focal, &["--weeds", "3"]].concat());
    assert!(String::from_utf8_lossy(&out.stderr).contains("weeds"));
}

/// ../shared relative to the crate root.
fn crdld() -> PathBuf {
    Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/real-fields/crdld"
    ))
    .to_path_buf()
}

#[test]
fn crdld_photographs_through_the_fisheye_show_their_rows_to_the_detector() {
    let root = crdld();
    if !root.join("image").is_dir() || !root.join("label").is_dir() {
        eprintln!("skipping: {} is absent", root.display());
        return;
    }
    let dir = tmp_dir("crdld");
    let (images, labels) = (root.join("image"), root.join("label"));
    let ground = ["--images", text(&images), "--labels", text(&labels)];
    let out = bin(&[&["synth", "--photo-survey"][..], &ground].concat());
    assert!(out.status.success());
    let survey = String::from_utf8_lossy(&out.stdout).into_owned();
    let accepted: Vec<usize> = survey
        .lines()
        .filter(|l| !l.starts_with("accepted"))
        .enumerate()
        .filter(|(_, l)| l.contains(": accepted:"))
        .map(|(i, _)| i)
        .take(3)
        .collect();
    assert_eq!(accepted.len(), 3, "{survey}");
    let calib = dir.join("fisheye.toml");
    let cal = omnirow::camera::ideal_fisheye(300, 360).unwrap();
    std::fs::write(&calib, cal.to_toml()).unwrap();
    for (k, &i) in accepted.iter().enumerate() {
        let yaw = ["-10", "5", "14"][k];
        let (png, json) = (dir.join(format!("{i}.png")), dir.join(format!("{i}.json")));
        let args = [
            "synth",
            "--lens",
            "fisheye185",
            "--image-height",
            "300",
            "--image-width",
            "360",
            "--style",
            "colour",
            "--yaw-deg",
            yaw,
            "--photo-index",
            &i.to_string(),
            "--out",
            text(&png),
            "--truth",
            text(&json),
        ];
        let out = bin(&[&args[..], &ground].concat());
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let out = bin(&["detect", "--calib", text(&calib), text(&png)]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let det: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let truth: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        let (h, t) = (
            det["heading_rad"].as_f64().unwrap(),
            truth["heading_rad"].as_f64().unwrap(),
        );
        assert!(
            (h - t).abs() < 1f64.to_radians(),
            "photo {i}: heading {h} vs {t}"
        );
        // Rows detected where the truth has them: within half a degree of a true row.
        let normal = |v: &serde_json::Value| {
            let a: Vec<f64> = v
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect();
            Vector3::new(a[0], a[1], a[2])
        };
        let truths: Vec<Vector3<f64>> = truth["row_normals"]
            .as_array()
            .unwrap()
            .iter()
            .map(normal)
            .collect();
        let on_truth = det["rows"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| {
                let n = normal(&r["normal"]);
                truths
                    .iter()
                    .any(|t| n.angle(t).min(n.angle(&-t)) < 0.5f64.to_radians())
            })
            .count();
        assert!(
            on_truth >= 3,
            "photo {i}: {on_truth} rows on the truth; {det}"
        );
    }
}
