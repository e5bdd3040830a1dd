//! `omnirow run` on the synthetic drive over a photograph's ground (`[source.synthetic]
//! photo`, `photo_labels`) and through a calibration file (`[camera] calibration`): the real
//! binary, its printed estimates checked against the drive's ground truth, and the errors of
//! a photograph or a size that cannot serve.

use omnirow::estimate::{Estimate, Status};
use omnirow::guidance::TrackState;
use std::path::Path;

#[path = "support/node.rs"]
mod node;
use node::*;

/// CRDLD in ../shared (testing-only data), or None with a message when it is absent.
fn crdld() -> Option<&'static Path> {
    let root = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/real-fields/crdld"
    ));
    if root.join("image").is_dir() && root.join("label").is_dir() {
        Some(root)
    } else {
        eprintln!("skipping: {} is absent", root.display());
        None
    }
}

/// `omnirow run --config cfg --frames N --print`: the estimates it printed and its log.
fn run_printed(cfg: &Path, frames: u32) -> (Vec<Estimate>, String) {
    let out = run_ok(
        bin()
            .args(["run", "--frames", &frames.to_string(), "--print"])
            .arg("--config")
            .arg(cfg),
    );
    let est: Vec<Estimate> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).expect("one JSON estimate a line"))
        .collect();
    assert_eq!(est.len(), frames as usize);
    (est, String::from_utf8_lossy(&out.stderr).into_owned())
}

/// The log's `source: …` line.
fn source_line(log: &str) -> String {
    log.lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter_map(|v| v["fields"]["message"].as_str().map(str::to_string))
        .find(|m| m.starts_with("source: "))
        .unwrap_or_else(|| panic!("no `source:` line in the log:\n{log}"))
}

/// The node over CRDLD photograph 3's ground through the ideal fisheye, with row guidance at
/// CRDLD's 0.5 m spacing: every frame after the first tracks the path the drive is in, the
/// heading within 0.5° of the truth and the offset within 6 cm (mean within 3 cm).
#[test]
fn the_node_runs_over_a_photographs_ground() {
    let Some(root) = crdld() else { return };
    let dir = tmpdir("photo");
    let cfg = dir.join("omnirow.toml");
    std::fs::write(
        &cfg,
        format!(
            "[source.synthetic]\nphoto = {:?}\nphoto_labels = {:?}\n\n[guidance]\nenabled = true\nrow_spacing_m = 0.5\n\n[http]\nenabled = false\n",
            root.join("image/3.jpg"),
            root.join("label")
        ),
    )
    .unwrap();
    let (est, log) = run_printed(&cfg, 30);
    assert!(source_line(&log).contains("a photograph's ground"), "{log}");
    check_against_truth(&est);
    let mut offsets = Vec::new();
    for e in &est[1..] {
        let g = e.guidance.as_ref().expect("guidance is on");
        let t = e.truth.as_ref().unwrap();
        assert_eq!(e.status, Status::Ok, "frame {}", e.seq);
        assert_eq!(t.row_spacing_m, 0.5);
        assert_eq!(g.tracking, TrackState::Tracking, "frame {}: {g:?}", e.seq);
        assert_eq!(g.row_index, Some(t.path()), "frame {}", e.seq);
        let dh = (g.heading_rad.unwrap() - t.heading_rad).to_degrees();
        assert!(dh.abs() < 0.5, "frame {}: heading off by {dh:.3}°", e.seq);
        let off = g.lateral_offset_m.unwrap() - t.path_offset_m(t.path());
        assert!(
            off.abs() < 0.06,
            "frame {}: offset off by {off:.3} m",
            e.seq
        );
        offsets.push(off.abs());
    }
    let mean = offsets.iter().sum::<f64>() / offsets.len() as f64;
    assert!(mean < 0.03, "offset error mean {mean:.4} m");
}

/// A calibration file renders the drive through itself: the pinhole at its own 512×512, an
/// OCamCalib fisheye at its own 1600×1600, and the ideal PAL written at 800×640 rescaled to
/// the drive's written 400×320; the detector then measures the truth's heading and tilt (it
/// used to take the file's calibration for frames rendered through the ideal fisheye).
#[test]
fn a_calibration_file_is_what_the_drive_renders_through() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tmpdir("calib");
    let pal = dir.join("pal_800x640.toml");
    let out = run_ok(bin().args(["calib", "ideal", "pal", "--height", "640", "--width", "800"]));
    std::fs::write(&pal, &out.stdout).unwrap();
    for (name, calib, size, frames, expect) in [
        (
            "pinhole",
            root.join("config/calib/pinhole_512_f300.toml"),
            "",
            10,
            "512x512",
        ),
        (
            "ocamcalib",
            root.join("config/calib/ocamcalib/fisheye_komatsu_185deg_1600x1600.txt"),
            "",
            4,
            "1600x1600",
        ),
        ("pal", pal, "width = 400\nheight = 320\n", 10, "400x320"),
    ] {
        let cfg = dir.join(format!("{name}.toml"));
        std::fs::write(
            &cfg,
            format!(
                "[source.synthetic]\nfps = 30.0\n{size}\n[camera]\ncalibration = {calib:?}\n\n[http]\nenabled = false\n"
            ),
        )
        .unwrap();
        let (est, log) = run_printed(&cfg, frames);
        let line = source_line(&log);
        assert!(line.contains(&format!("({expect},")), "{name}: {line}");
        check_against_truth(&est);
    }
}

/// `omnirow run` on the configuration `text`, which must fail before any estimate: its
/// stderr.
fn refused(dir: &Path, text: &str) -> String {
    let cfg = dir.join("omnirow.toml");
    std::fs::write(&cfg, format!("{text}\n[http]\nenabled = false\n")).unwrap();
    let out = bin()
        .args(["run", "--frames", "3", "--print", "--config"])
        .arg(&cfg)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "{err}");
    assert!(out.stdout.is_empty(), "no estimate before the error");
    err
}

/// A photograph that does not exist, and a drive size that is no uniform scale of the
/// calibration's, stop the node before it starts with an error naming them.
#[test]
fn a_missing_photograph_or_a_wrong_size_is_named() {
    let dir = tmpdir("missing");
    let photo = dir.join("no-such-field.jpg");
    let err = refused(
        &dir,
        &format!(
            "[source.synthetic]\nphoto = {photo:?}\nphoto_labels = {:?}\n",
            dir.path()
        ),
    );
    assert!(err.contains("source.synthetic.photo"), "{err}");
    assert!(err.contains(&photo.display().to_string()), "{err}");
    assert!(err.contains("cannot read the photograph"), "{err}");

    let calib = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config/calib/ocamcalib/fisheye_komatsu_185deg_1600x1600.txt");
    let err = refused(
        &dir,
        &format!(
            "[source.synthetic]\nwidth = 612\nheight = 512\n[camera]\ncalibration = {calib:?}\n"
        ),
    );
    assert!(
        err.contains("source.synthetic.width = 612, height = 512"),
        "{err}"
    );
    assert!(err.contains("scaled by one factor"), "{err}");
}
