//! Row guidance through the real binary: `omnirow run` on the synthetic drive publishes
//! schema-2 estimates whose `guidance` offset and heading match the frames' ground truth, and
//! configuration mistakes in `[guidance]` or `[mounting]` are named.

use omnirow::estimate::Estimate;
use omnirow::guidance::{headland, CropState, TrackState};
use std::process::Stdio;
use std::time::Duration;

#[path = "support/node.rs"]
mod node;
use node::*;

/// Runs the synthetic drive for `frames` frames with `extra` configuration; the estimates.
fn drive(name: &str, frames: u32, extra: &str) -> Vec<Estimate> {
    let dir = tmpdir(name);
    let cfg = small_config(&dir, extra);
    run_config(&cfg, frames, Duration::from_secs(120))
}

/// Runs `omnirow run` on the configuration `cfg` for `frames` frames; the estimates it sent
/// over UDP, one per frame.
fn run_config(cfg: &std::path::Path, frames: u32, timeout: Duration) -> Vec<Estimate> {
    let (sock, addr) = udp();
    let mut child = bin()
        .args([
            "run",
            "--frames",
            &frames.to_string(),
            "--no-print",
            "--udp",
        ])
        .arg(&addr)
        .arg("--config")
        .arg(cfg)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let est = collect(&sock, &mut child, timeout);
    assert!(child.wait_with_output().unwrap().status.success());
    assert_eq!(est.len(), frames as usize);
    est
}

#[test]
fn published_offset_and_heading_match_the_drive_truth() {
    let est = drive("truth", 45, "");
    let mut errs = Vec::new();
    // the tracker starts on two agreeing frames: the first has no estimate
    let first = est[0].guidance.as_ref().unwrap();
    assert_eq!(first.tracking, TrackState::Lost);
    for e in &est[1..] {
        assert_eq!(e.schema_version, 2);
        let g = e.guidance.as_ref().expect("guidance on by default");
        let t = e.truth.as_ref().unwrap();
        // the drive stays in the inter-row path it starts in: between rows 0 and 1
        assert_eq!(t.path(), 0);
        assert_eq!(g.tracking, TrackState::Tracking, "frame {}", e.seq);
        assert_eq!(g.row_index, Some(0));
        let off = g.lateral_offset_m.unwrap();
        errs.push((off - t.path_offset_m(0)).abs());
        let dh = g.heading_rad.unwrap() - t.heading_rad;
        assert!(
            dh.abs() < 0.2f64.to_radians(),
            "frame {}: heading off by {dh}",
            e.seq
        );
        assert!((g.row_spacing_m.unwrap() - t.row_spacing_m).abs() < 0.01);
        // straight rows: the curvature stays near 0 (radius beyond 200 m)
        assert!(
            g.curvature_per_m.unwrap().abs() < 0.005,
            "frame {}: {g:?}",
            e.seq
        );
        assert!(!g.rows.is_empty());
        assert!(g.warnings.is_empty(), "{:?}", g.warnings);
        let p = g.covariance.unwrap();
        assert!(p[0][0] > 0.0 && p[0][0].sqrt() < 0.02, "{p:?}");
    }
    errs.sort_by(f64::total_cmp);
    let mean = errs.iter().sum::<f64>() / errs.len() as f64;
    let max = errs[errs.len() - 1];
    // issue 14's targets: mean <= 1 cm, p99 <= 3 cm (here: the largest of 45)
    assert!(mean < 0.01 && max < 0.03, "mean {mean} max {max}");
}

#[test]
fn curvature_of_a_curved_drive_matches_its_radius() {
    // rows bending left with a 20 m radius (row 0), the robot weaving between rows 0 and 1
    let dir = tmpdir("curved");
    let cfg = dir.join("omnirow.toml");
    std::fs::write(
        &cfg,
        "[source.synthetic]\nwidth = 408\nheight = 342\nfps = 30.0\nseed = 5\ncurvature_per_m = 0.05\n\n[http]\nenabled = false\n",
    )
    .unwrap();
    let est = run_config(&cfg, 30, Duration::from_secs(120));
    // the tracker starts on two agreeing frames: the first has no estimate
    let first = est[0].guidance.as_ref().unwrap();
    assert_eq!(first.tracking, TrackState::Lost);
    for e in &est[1..] {
        let g = e.guidance.as_ref().unwrap();
        let t = e.truth.as_ref().unwrap();
        assert_eq!(t.curvature_per_m, 0.05);
        assert_eq!(g.tracking, TrackState::Tracking, "frame {}", e.seq);
        // the followed line is the centre of path 0: 0.25 m left of row 0
        let truth = t.path_curvature_per_m(0);
        assert!((truth - 0.05 / (1.0 - 0.05 * 0.25)).abs() < 1e-12);
        let k = g.curvature_per_m.unwrap();
        // issue 14's target: within 10% for radii of 20 m and more
        assert!(
            (k / truth - 1.0).abs() < 0.1,
            "frame {}: {k} vs {truth}",
            e.seq
        );
        let f = g.frame.unwrap().curvature_per_m.unwrap();
        assert!((f / truth - 1.0).abs() < 0.1, "frame {}: {f}", e.seq);
        // the filter's curvature variance comes from the measurements
        let p = g.covariance.unwrap();
        assert!(p[2][2].sqrt() < 0.005, "{p:?}");
    }
}

#[test]
fn wrong_camera_height_is_reported_with_the_likely_height() {
    // the drive's camera is 1 m high; the calibration says 1.25 m, the field 0.5 m rows
    let dir = tmpdir("height");
    let cal = omnirow::camera::ideal_fisheye(342, 408).unwrap();
    let text = cal.to_toml().replace("height_m = 1.0", "height_m = 1.25");
    let cal_path = dir.join("cal.toml");
    std::fs::write(&cal_path, text).unwrap();
    let extra = format!(
        "[camera]\ncalibration = \"{}\"\n[guidance]\nrow_spacing_m = 0.5\n",
        cal_path.display()
    );
    let cfg = small_config(&dir, &extra);
    let out = bin()
        .args(["run", "--frames", "20", "--print", "--config"])
        .arg(&cfg)
        .output()
        .unwrap();
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("spacing_differs_from_configured") && stderr.contains("suggest 1.0"),
        "{stderr}"
    );
    let last: Estimate =
        serde_json::from_str(String::from_utf8_lossy(&out.stdout).lines().last().unwrap()).unwrap();
    let g = last.guidance.unwrap();
    assert!(g
        .warnings
        .contains(&omnirow::guidance::Warning::SpacingDiffersFromConfigured));
}

#[test]
fn guidance_and_mounting_mistakes_are_named() {
    let dir = tmpdir("badcfg");
    let cfg = small_config(&dir, "[guidance]\nmode = \"over_row\"\nmin_rows = 1\n");
    let out = bin().args(["config", "check"]).arg(&cfg).output().unwrap();
    assert!(!out.status.success());
    let text = String::from_utf8_lossy(&out.stderr) + String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("guidance.min_rows"), "{text}");

    let cal = omnirow::camera::ideal_fisheye(342, 408).unwrap();
    let cal_path = dir.join("cal.toml");
    std::fs::write(
        &cal_path,
        cal.to_toml().replace("height_m = 1.0", "height_m = -2.0"),
    )
    .unwrap();
    let extra = format!("[camera]\ncalibration = \"{}\"\n", cal_path.display());
    let cfg = small_config(&dir, &extra);
    let out = bin()
        .args(["run", "--frames", "2", "--no-print", "--config"])
        .arg(&cfg)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("height_m") && stderr.contains("cal.toml"),
        "{stderr}"
    );
}

#[test]
fn crossing_to_the_next_path_is_followed_without_a_jump() {
    // 30 fps, the robot crosses one spacing to its left between 1 s and 5 s
    let dir = tmpdir("crossing");
    let cfg = dir.join("omnirow.toml");
    std::fs::write(
        &cfg,
        "[source.synthetic]\nwidth = 408\nheight = 342\nfps = 30.0\nseed = 5\ncross_at_s = 1.0\n\n[http]\nenabled = false\n",
    )
    .unwrap();
    let est = run_config(&cfg, 180, Duration::from_secs(180));
    let mut last: Option<f64> = None;
    let mut worst = 0.0f64;
    // the tracker starts on two agreeing frames: the first has no estimate
    let first = est[0].guidance.as_ref().unwrap();
    assert_eq!(first.tracking, TrackState::Lost);
    for e in &est[1..] {
        let g = e.guidance.as_ref().unwrap();
        let t = e.truth.as_ref().unwrap();
        assert_ne!(g.tracking, TrackState::Lost, "frame {}", e.seq);
        let off = g.lateral_offset_m.unwrap();
        // the followed line stays the centre of path 0, where the drive started
        worst = worst.max((off - t.path_offset_m(0)).abs());
        if let Some(prev) = last {
            assert!(
                (off - prev).abs() < 0.05,
                "frame {}: jump {prev} -> {off}",
                e.seq
            );
        }
        last = Some(off);
    }
    assert!(worst < 0.03, "worst offset error {worst}");
    let first = est[1].guidance.as_ref().unwrap();
    let end = est[179].guidance.as_ref().unwrap();
    assert_eq!(est[179].truth.as_ref().unwrap().path(), 1);
    assert_eq!((first.row_index, end.row_index), (Some(0), Some(-1)));
    assert!(end.lateral_offset_m.unwrap() > 0.35);
}

/// Runs the synthetic drive (408×342, 10 fps, 1 m/s) with `keys` added to
/// `[source.synthetic]`; the estimates.
fn drive_with(name: &str, frames: u32, keys: &str) -> Vec<Estimate> {
    let dir = tmpdir(name);
    let cfg = dir.join("omnirow.toml");
    std::fs::write(
        &cfg,
        format!("[source.synthetic]\nwidth = 408\nheight = 342\nfps = 10.0\nseed = 5\n{keys}\n[http]\nenabled = false\n"),
    )
    .unwrap();
    run_config(&cfg, frames, Duration::from_secs(120))
}

#[test]
fn end_of_the_rows_is_reported_and_the_headland_is_no_crop() {
    // the rows end 2.5 m ahead of the start; the robot drives 3.4 m past their end
    let est = drive_with("headland", 60, "rows_end_m = 2.5\n");
    let mut reported = 0;
    for e in &est {
        let g = e.guidance.as_ref().unwrap();
        let t = e.truth.as_ref().unwrap();
        let truth = t.end_of_rows_m.unwrap();
        if let Some(end) = g.end_of_row_m {
            // issue 14's target: within 0.5 m once within 5 m
            assert!(
                (end - truth).abs() < 0.5,
                "frame {}: {end} vs {truth}",
                e.seq
            );
            reported += 1;
        } else if truth > 0.3 && e.seq + 1 >= u64::from(headland::CONFIRM_FRAMES) {
            // (the first frames confirm it: one frame does not make an end of the rows)
            panic!("frame {}: the end {truth} m ahead not reported", e.seq);
        }
        if t.no_crop {
            assert_ne!(g.crop, CropState::Rows, "frame {}", e.seq);
        }
        // a frame that measured nothing claims no row (the published crop follows a frame
        // later: one frame does not flip it)
        if g.frame.is_none() {
            assert!(g.rows.is_empty());
        }
    }
    assert!(reported >= 30, "{reported}");
    // 3 m past the end nothing is taken for a row
    let last = est.last().unwrap().guidance.as_ref().unwrap();
    assert_ne!(last.crop, CropState::Rows);
}

#[test]
fn an_empty_stretch_claims_no_rows_and_the_rows_after_it_are_followed() {
    // no plant from 1.5 m to 8.5 m along: the robot crosses the whole stretch
    let est = drive_with("gap", 100, "gap_start_m = 1.5\ngap_length_m = 7.0\n");
    let mut empty = 0;
    for e in &est {
        let g = e.guidance.as_ref().unwrap();
        let t = e.truth.as_ref().unwrap();
        assert!(t.end_of_rows_m.is_none());
        if t.no_crop {
            assert_ne!(g.crop, CropState::Rows, "frame {}", e.seq);
            empty += 1;
        }
        // whatever is measured is the real rows (far ones inside the stretch, measured less
        // well): the offset from the nearest path centre within a fifth of the spacing
        if let Some(f) = &g.frame {
            let err = f.lateral_offset_m - t.path_offset_m(0);
            let wrapped = err - (err / 0.5).round() * 0.5;
            assert!(wrapped.abs() < 0.1, "frame {}: {f:?} vs {t:?}", e.seq);
        }
        if g.tracking != TrackState::Lost && e.seq > 90 {
            let off = g.lateral_offset_m.unwrap();
            assert!(
                (off - t.path_offset_m(t.path())).abs() < 0.03,
                "frame {}: {off}",
                e.seq
            );
        }
    }
    assert!(empty >= 10, "{empty}");
    let end = est.last().unwrap().guidance.as_ref().unwrap();
    assert_eq!(end.crop, CropState::Rows);
    assert!(matches!(end.tracking, TrackState::Tracking));
}

#[test]
fn eval_guidance_writes_its_table_and_plots() {
    let dir = tmpdir("evalg");
    let out = bin()
        .args([
            "eval",
            "guidance",
            "--seconds",
            "0.4",
            "--width",
            "306",
            "--height",
            "256",
            "--out",
        ])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let table = String::from_utf8_lossy(&out.stdout);
    for drive in ["weaving", "crossing", "curved_r20", "headland"] {
        assert!(table.contains(&format!("| {drive} | 6 |")), "{table}");
        assert!(dir.join(format!("guidance_{drive}.png")).is_file());
    }
    assert_eq!(
        std::fs::read_to_string(dir.join("README.md")).unwrap(),
        table
    );
    // every frame of every drive, in order, with its truth
    let frames = std::fs::read_to_string(dir.join("frames.jsonl")).unwrap();
    let frames: Vec<serde_json::Value> = frames
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(frames.len(), 4 * 6, "{frames:?}");
    assert_eq!(frames[6]["drive"], "crossing");
    assert!(frames[7]["frame"]["time_s"].as_f64().unwrap() > 0.0);
    assert!(frames[7]["frame"]["truth_offset_m"].is_f64());
    let bad = bin()
        .args(["eval", "guidance", "--seconds", "0"])
        .output()
        .unwrap();
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("--seconds"));
}
