//! `omnirow detect` run for real on rendered images: the JSON contract, errors per image,
//! automatic rescaling, --mask-radius, --overlay, and the answer's accuracy.

mod common;

use common::{axis_angle, render_rows};
use nalgebra::Vector3;
use omnirow::camera::{ideal_fisheye, ideal_pal, Calibration};
use std::path::{Path, PathBuf};
use std::process::Command;

#[path = "support/scratch.rs"]
mod scratch;

fn tmpdir(name: &str) -> scratch::Scratch {
    scratch::Scratch::new("detect-cli", name)
}

fn save_png(path: &Path, w: u32, h: u32, data: &[u8]) {
    image::save_buffer(path, data, w, h, image::ExtendedColorType::L8).unwrap();
}

fn run(args: &[&str]) -> (i32, Vec<serde_json::Value>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_omnirow"))
        .args(args)
        .output()
        .unwrap();
    let stdout = String::from_utf8(out.stdout).unwrap();
    let lines = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("bad JSON line {l}: {e}")))
        .collect();
    (
        out.status.code().unwrap_or(-1),
        lines,
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn vec3(v: &serde_json::Value) -> Vector3<f64> {
    let a = v.as_array().unwrap();
    Vector3::new(
        a[0].as_f64().unwrap(),
        a[1].as_f64().unwrap(),
        a[2].as_f64().unwrap(),
    )
}

fn write_calib(dir: &Path, cal: &Calibration, name: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, cal.to_toml()).unwrap();
    p
}

#[test]
fn contract_fields_order_errors_and_rescaling() {
    let dir = tmpdir("contract");
    let cal = ideal_fisheye(512, 612).unwrap();
    let calib = write_calib(&dir, &cal, "fisheye.toml");
    let a = render_rows(&cal, 0.2, 0.03, 3, 0.75, 0.05, 1.0, 0.2, 0.01, 1);
    let pa = dir.join("a.png");
    save_png(&pa, a.width, a.height, &a.data);
    // the same field at half resolution: the calibration is rescaled to it
    let half = cal.rescaled(2.0).unwrap();
    let b = render_rows(&half, -0.4, -0.05, 3, 0.75, 0.05, 1.0, 0.3, 0.01, 2);
    let pb = dir.join("b.png");
    save_png(&pb, b.width, b.height, &b.data);
    let bad = dir.join("not-an-image.png");
    std::fs::write(&bad, b"garbage").unwrap();
    let missing = dir.join("missing.png");
    // a size that is not a uniform scale of the calibration
    let pc = dir.join("c.png");
    save_png(&pc, 100, 100, &[0u8; 10000]);
    let ov = dir.join("overlay");
    let (code, lines, stderr) = run(&[
        "detect",
        "--calib",
        calib.to_str().unwrap(),
        "--overlay",
        ov.to_str().unwrap(),
        pa.to_str().unwrap(),
        bad.to_str().unwrap(),
        pb.to_str().unwrap(),
        missing.to_str().unwrap(),
        pc.to_str().unwrap(),
    ]);
    assert_eq!(code, 1, "{stderr}");
    assert_eq!(lines.len(), 5);
    // input order, paths as given
    let names: Vec<&str> = lines.iter().map(|l| l["image"].as_str().unwrap()).collect();
    assert_eq!(
        names,
        [&pa, &bad, &pb, &missing, &pc].map(|p| p.to_str().unwrap())
    );
    for i in [1, 3, 4] {
        let obj = lines[i].as_object().unwrap();
        assert_eq!(obj.len(), 2, "{obj:?}");
        assert!(!obj["error"].as_str().unwrap().is_empty());
    }
    assert!(lines[4]["error"].as_str().unwrap().contains("100x100"));
    // exact field names and order
    let raw = String::from_utf8(
        Command::new(env!("CARGO_BIN_EXE_omnirow"))
            .args([
                "detect",
                "--calib",
                calib.to_str().unwrap(),
                pa.to_str().unwrap(),
            ])
            .output()
            .unwrap()
            .stdout,
    )
    .unwrap();
    let keys: Vec<&str> = [
        "image",
        "method",
        "vanishing_point",
        "vanishing_point_px",
        "heading_rad",
        "tilt_rad",
        "rows",
        "quality",
        "elapsed_ms",
    ]
    .to_vec();
    let mut pos = 0;
    for k in &keys {
        let at = raw[pos..]
            .find(&format!("\"{k}\":"))
            .unwrap_or_else(|| panic!("{k} in {raw}"));
        pos += at;
    }
    for (line, truth) in [(&lines[0], &a), (&lines[2], &b)] {
        let obj = line.as_object().unwrap();
        assert_eq!(obj.keys().len(), keys.len());
        // combined is the default method
        assert_eq!(line["method"], "combined");
        let vp = vec3(&line["vanishing_point"]);
        assert!((vp.norm() - 1.0).abs() < 1e-9);
        let err = axis_angle(&vp, &truth.vp);
        assert!(err < 2e-3, "vp error {err} rad: {line}");
        assert!((line["heading_rad"].as_f64().unwrap() - truth.heading_rad).abs() < 3e-3);
        assert!((line["tilt_rad"].as_f64().unwrap() - truth.tilt_rad).abs() < 3e-3);
        let rows = line["rows"].as_array().unwrap();
        assert!(rows.len() >= 3, "{line}");
        // crop rows' centre lines (the Hough rows), the edge method's boundaries giving
        // widths: never a boundary as a row
        let widths: Vec<f64> = rows
            .iter()
            .map(|r| r["width_rad"].as_f64().unwrap())
            .collect();
        assert!(widths.iter().filter(|&&w| w > 0.0).count() >= 2, "{line}");
        for r in rows {
            assert_eq!(r["method"], "hough", "{r}");
            assert!(r["support"].as_u64().unwrap() > 0);
            assert!((vec3(&r["normal"]).norm() - 1.0).abs() < 1e-9);
            let w = r["width_rad"].as_f64().unwrap();
            assert!((0.0..0.2).contains(&w), "{r}");
        }
        let q = line["quality"].as_f64().unwrap();
        assert!(q > 0.0 && q <= 1.0);
        assert!(line["elapsed_ms"].as_f64().unwrap() > 0.0);
        let px = line["vanishing_point_px"].as_array().unwrap();
        assert_eq!(px.len(), 2);
    }
    // the vanishing point's pixel is where the calibration projects the direction
    let px = lines[0]["vanishing_point_px"].as_array().unwrap();
    let vp = vec3(&lines[0]["vanishing_point"]);
    let p = [vp, -vp]
        .iter()
        .filter_map(|d| cal.ray_to_pixel_in_fov(d))
        .next()
        .unwrap();
    assert!((px[0].as_f64().unwrap() - p[0]).abs() < 1e-6);
    // overlays written for the images that worked
    assert!(ov.join("a.png").exists() && ov.join("b.png").exists());
    let img = image::open(ov.join("a.png")).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (a.width, a.height));
    assert!(img.pixels().any(|p| p.0 == [255, 32, 32]));
}

#[test]
fn pal_lens_mask_radius_override_and_methods() {
    let dir = tmpdir("pal");
    let cal = ideal_pal(512, 612).unwrap();
    let mut no_mask = cal.clone();
    no_mask.mask = None;
    let calib = write_calib(&dir, &no_mask, "pal-nomask.toml");
    let r = render_rows(&cal, 1.0, 0.0, 3, 0.75, 0.05, 1.0, 0.1, 0.01, 3);
    let p = dir.join("pal.png");
    save_png(&p, r.width, r.height, &r.data);
    let m = cal.mask.unwrap();
    let radii = format!("{},{}", m.inner_radius_px, m.outer_radius_px);
    let (code, lines, stderr) = run(&[
        "detect",
        "--calib",
        calib.to_str().unwrap(),
        "--mask-radius",
        &radii,
        p.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    let err = axis_angle(&vec3(&lines[0]["vanishing_point"]), &r.vp);
    assert!(err < 2e-3, "{err}: {}", lines[0]);
    // without the override and without a mask in the calibration: found from the image
    let (code, lines, stderr) = run(&[
        "detect",
        "--calib",
        calib.to_str().unwrap(),
        p.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(lines[0]["vanishing_point"].is_array(), "{}", lines[0]);
    // a mask that leaves nothing: an error for the image, not a crash
    let (code, lines, _) = run(&[
        "detect",
        "--calib",
        calib.to_str().unwrap(),
        "--mask-radius",
        "2000,3000",
        p.to_str().unwrap(),
    ]);
    assert_eq!(code, 1);
    assert!(lines[0]["error"]
        .as_str()
        .unwrap()
        .contains("field of view"));
    // bad --mask-radius is a usage error
    let out = Command::new(env!("CARGO_BIN_EXE_omnirow"))
        .args([
            "detect",
            "--calib",
            calib.to_str().unwrap(),
            "--mask-radius",
            "5",
            p.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(!out.status.success());
    // every method finds the vanishing point; rows carry their method's name
    for m in ["hough", "edge", "combined"] {
        let (code, lines, stderr) = run(&[
            "detect",
            "--calib",
            calib.to_str().unwrap(),
            "--mask-radius",
            &radii,
            "--method",
            m,
            p.to_str().unwrap(),
        ]);
        assert_eq!(code, 0, "{stderr}");
        assert_eq!(lines[0]["method"], m);
        let err = axis_angle(&vec3(&lines[0]["vanishing_point"]), &r.vp);
        assert!(err < 2e-3, "{m}: {err}: {}", lines[0]);
        let rows = lines[0]["rows"].as_array().unwrap();
        // the combined method publishes the Hough centre lines
        let want: &[&str] = match m {
            "combined" => &["hough"],
            one => &[one],
        };
        for w in want {
            assert!(
                rows.iter().any(|row| row["method"] == *w),
                "{m}: {}",
                lines[0]
            );
        }
        assert!(rows
            .iter()
            .all(|row| want.contains(&row["method"].as_str().unwrap())));
    }
    // options from a node configuration's [detector]; --method still wins over it
    let conf = dir.join("tuned.toml");
    std::fs::write(
        &conf,
        "[detector]\nmethod = \"edge\"\n[detector.hough]\nmax_rows = 2\n",
    )
    .unwrap();
    let args = |method: Option<&'static str>| {
        let mut a = vec![
            "detect".to_string(),
            "--calib".into(),
            calib.to_str().unwrap().into(),
            "--mask-radius".into(),
            radii.clone(),
            "--config".into(),
            conf.to_str().unwrap().into(),
        ];
        if let Some(m) = method {
            a.extend(["--method".to_string(), m.to_string()]);
        }
        a.push(p.to_str().unwrap().into());
        a
    };
    let a = args(None);
    let (code, lines, stderr) = run(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(lines[0]["method"], "edge");
    let a = args(Some("hough"));
    let (code, lines, stderr) = run(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(lines[0]["method"], "hough");
    assert!(
        lines[0]["rows"].as_array().unwrap().len() <= 2,
        "{}",
        lines[0]
    );
    std::fs::write(&conf, "[detector.hough]\nmax_rowz = 2\n").unwrap();
    let a = args(None);
    let out = Command::new(env!("CARGO_BIN_EXE_omnirow"))
        .args(&a)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("tuned.toml:2") && err.contains("max_rowz"),
        "{err}"
    );
    // a hostile point budget is refused by name, not an allocation that aborts
    std::fs::write(
        &conf,
        "[detector.threshold]\ntarget_points = 1000000000000\n",
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_omnirow"))
        .args(args(None))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("threshold.target_points"), "{err}");
}

#[test]
fn real_images_give_sane_json() {
    let root = shared_dir();
    let sets = [
        (
            "calib/fisheye_komatsu_185deg_1600x1600.txt",
            "real/fisheye_komatsu_185deg",
        ),
        (
            "calib/fisheye_ocamcalib_sample_ladybug_1024x768.txt",
            "real/ocamcalib_sample_fisheye_ladybug",
        ),
        (
            "calib/catadioptric_ocamcalib_sample_vmr_1024x768.txt",
            "real/ocamcalib_sample_catadioptric_vmr",
        ),
    ];
    for (calib, folder) in sets {
        let (c, f) = (root.join(calib), root.join(folder));
        if !c.exists() || !f.exists() {
            eprintln!(
                "skipping {folder}: {} or {} is absent",
                c.display(),
                f.display()
            );
            continue;
        }
        let mut images: Vec<String> = std::fs::read_dir(&f)
            .unwrap()
            .map(|e| e.unwrap().path().to_string_lossy().into_owned())
            .filter(|p| p.ends_with(".jpg"))
            .collect();
        images.sort();
        let mut args = vec![
            "detect".to_string(),
            "--calib".into(),
            c.to_string_lossy().into_owned(),
        ];
        args.extend(images.iter().cloned());
        let argv: Vec<&str> = args.iter().map(String::as_str).collect();
        let (code, lines, stderr) = run(&argv);
        assert_eq!(code, 0, "{folder}: {stderr}");
        assert_eq!(lines.len(), images.len());
        for l in &lines {
            assert!(l.get("error").is_none(), "{l}");
            let q = l["quality"].as_f64().unwrap();
            assert!((0.0..=1.0).contains(&q));
            if l["vanishing_point"].is_array() {
                assert!((vec3(&l["vanishing_point"]).norm() - 1.0).abs() < 1e-9);
                assert!(
                    l["heading_rad"].as_f64().unwrap().abs() <= std::f64::consts::FRAC_PI_2 + 1e-9
                );
            } else {
                assert!(l["heading_rad"].is_null() && l["tilt_rad"].is_null());
            }
        }
    }
}

/// ../shared relative to the crate root, or `OMNIROW_SHARED_DIR` when set (for worktrees
/// that live elsewhere).
fn shared_dir() -> std::path::PathBuf {
    std::env::var_os("OMNIROW_SHARED_DIR")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../shared")).to_path_buf()
        })
}
