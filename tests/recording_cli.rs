//! `omnirow recording check` and `repair`, and the exit code of `omnirow record`, run as the
//! real binary. A repaired file holds every intact frame, checks clean, replays, and opens in
//! rosbags (the independent ROS 2 reader; needs the venv from scripts/ci-python-env.sh: fails
//! without it when `CI=true`, skips that part otherwise).

#[path = "ros2/venv.rs"]
mod venv;

#[path = "support/node.rs"]
mod node;

use node::{bin, small_config, tmpdir};
use omnirow::estimate::{Estimate, Status};
use omnirow::frame::{Frame, PixelFormat};
use omnirow::record::{JsonChannels, RecordOptions, Recorder};
use serde_json::Value;
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const DIR: &str = env!("CARGO_MANIFEST_DIR");

fn frame(seq: u64) -> Frame {
    Frame {
        seq,
        capture_ns: 1_700_000_000_000_000_000 + seq * 66_666_667,
        receive_ns: 1_700_000_000_010_000_000 + seq * 66_666_667,
        width: 32,
        height: 24,
        format: PixelFormat::Mono8,
        data: (0..32 * 24)
            .map(|i| (i as u64 * 13 + seq * 5) as u8)
            .collect(),
        truth: None,
    }
}

/// A 20-frame recording (ROS 2 strings for the estimates, so rosbags opens it unchanged).
fn recording(dir: &Path) -> PathBuf {
    let mut rec = Recorder::new(RecordOptions {
        dir: dir.join("rec"),
        reserve_bytes: 0,
        json_channels: JsonChannels::Ros2String,
        calibration_toml: Some(
            omnirow::camera::IdealLens::Fisheye185
                .calibration(24, 32)
                .unwrap()
                .to_toml(),
        ),
        ..RecordOptions::default()
    })
    .unwrap();
    for i in 0..20 {
        let f = frame(i);
        rec.write_frame(&f).unwrap();
        rec.write_estimate(&Estimate::empty(&f, Status::NoRows))
            .unwrap();
    }
    rec.finish().unwrap();
    rec.files()[0].clone()
}

/// The byte ranges of the file's chunks and the frame count of each (from its summary).
fn chunks(bytes: &[u8]) -> Vec<(usize, usize, usize)> {
    let summary = mcap::Summary::read(bytes).unwrap().unwrap();
    summary
        .chunk_indexes
        .iter()
        .map(|c| {
            let frames = summary
                .stream_chunk(bytes, c)
                .unwrap()
                .filter(|m| m.as_ref().unwrap().channel.topic == "/omnirow/image_raw")
                .count();
            let s = c.chunk_start_offset as usize;
            (s, s + c.chunk_length as usize, frames)
        })
        .collect()
}

fn check_json(path: &Path) -> (i32, Value) {
    let out = bin()
        .args(["recording", "check", "--json"])
        .arg(path)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    let v = serde_json::from_str(text.trim())
        .unwrap_or_else(|e| panic!("{e}: {text}\n{}", String::from_utf8_lossy(&out.stderr)));
    (out.status.code().unwrap(), v)
}

#[test]
fn check_reports_damage_and_repair_keeps_every_intact_frame() {
    let dir = tmpdir("recording-cli");
    let path = recording(&dir);
    let (code, v) = check_json(&path);
    assert_eq!(code, 0, "{v}");
    assert_eq!(v["intact"], true);
    assert_eq!(v["frames"], 20);
    assert_eq!(v["summary"], "intact");
    assert!((v["span_s"].as_f64().unwrap() - 19.0 * 0.066_666_667).abs() < 0.01);

    // Damage frames 3 and 11 and cut the summary off.
    let bytes = std::fs::read(&path).unwrap();
    let ch = chunks(&bytes);
    let framed: Vec<_> = ch.iter().filter(|c| c.2 == 1).collect();
    let mut bad = bytes.clone();
    for k in [3, 11] {
        let (s, e, _) = framed[k];
        bad[(s + e) / 2] ^= 0xa5;
    }
    let summary_start = mcap::read::footer(&bytes).unwrap().summary_start as usize;
    bad.truncate(summary_start);
    let damaged = dir.join("damaged.mcap");
    std::fs::write(&damaged, &bad).unwrap();

    let (code, v) = check_json(&damaged);
    assert_eq!(code, 1, "damaged: exit 1 ({v})");
    assert_eq!(v["intact"], false);
    assert_eq!(v["complete"], false);
    assert_eq!(v["frames"], 18);
    assert_eq!(v["chunks_damaged"], 2);
    let regions = v["damage"].as_array().unwrap();
    assert_eq!(regions.len(), 2, "{v}");
    for (r, k) in regions.iter().zip([3, 11]) {
        assert_eq!(r["offset"].as_u64(), Some(framed[k].0 as u64));
        assert_eq!(
            r["frames"], 1,
            "the message index after the chunk says what it held"
        );
    }
    // The text form names the file, the damage and its offset.
    let out = bin()
        .args(["recording", "check"])
        .arg(&damaged)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("damaged.mcap: damaged"), "{text}");
    assert!(
        text.contains(&format!("skipped bytes {}..", framed[3].0)),
        "{text}"
    );
    assert!(text.contains("CRC"), "{text}");

    // Repair: a complete file with the 18 intact frames, every estimate of the intact chunks,
    // and the calibration attachment.
    let repaired = dir.join("repaired.mcap");
    let out = bin()
        .args(["recording", "repair"])
        .arg(&damaged)
        .arg(&repaired)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (code, v) = check_json(&repaired);
    assert_eq!(code, 0, "the repaired file is intact: {v}");
    assert_eq!(v["frames"], 18);
    assert_eq!(v["summary"], "intact");
    let fixed = std::fs::read(&repaired).unwrap();
    let summary = mcap::Summary::read(&fixed).unwrap().unwrap();
    assert_eq!(summary.attachment_indexes.len(), 1, "calibration kept");
    let stamps: Vec<u64> = mcap::MessageStream::new(&fixed)
        .unwrap()
        .map(|m| m.unwrap())
        .filter(|m| m.channel.topic == "/omnirow/image_raw")
        .map(|m| m.publish_time)
        .collect();
    let want: Vec<u64> = (0..20)
        .filter(|i| *i != 3 && *i != 11)
        .map(|i| frame(i).capture_ns)
        .collect();
    assert_eq!(stamps, want);
    // Never over an existing file.
    let out = bin()
        .args(["recording", "repair"])
        .arg(&damaged)
        .arg(&repaired)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("exists"));
    // Not an MCAP: exit 2, named.
    let junk = dir.join("junk.mcap");
    std::fs::write(&junk, b"definitely not").unwrap();
    let (code, v) = check_json(&junk);
    assert_eq!(code, 2);
    assert!(v["error"].as_str().unwrap().contains("junk.mcap"), "{v}");

    // rosbags opens the repaired file and decodes every frame as a ROS 2 image.
    if let Some(venv) = venv::venv("rosbags") {
        let out = Command::new(venv.join("bin/python"))
            .arg(format!("{DIR}/tests/ros2/check_mcap.py"))
            .arg(&repaired)
            .args(["--min-images", "18"])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "rosbags rejected the repaired file:\n{}\n{}",
            String::from_utf8_lossy(&out.stderr),
            String::from_utf8_lossy(&out.stdout)
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

fn http_get(addr: &str, path: &str) -> Option<String> {
    let mut s = TcpStream::connect(addr).ok()?;
    s.set_read_timeout(Some(Duration::from_secs(5))).ok()?;
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"
    )
    .ok()?;
    let mut buf = String::new();
    s.read_to_string(&mut buf).ok()?;
    Some(buf)
}

#[test]
fn record_that_cannot_record_keeps_detecting_and_exits_nonzero() {
    let dir = tmpdir("record-fails");
    // Free space below the reserve (1 PiB), and a directory that cannot be created (under a
    // regular file: refused even to root).
    std::fs::write(dir.join("file"), b"").unwrap();
    let cases = [
        (
            "[record]\nreserve_mb = 1073741824\n",
            dir.join("rec"),
            "stopped",
        ),
        ("", dir.join("file/rec"), "failed"),
    ];
    for (extra, out_dir, state) in cases {
        let port = TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let addr = format!("127.0.0.1:{port}");
        let cfg = small_config(&dir, extra);
        let child = bin()
            .args(["record", "--out"])
            .arg(&out_dir)
            .args(["--duration", "4", "--no-print", "--http", &addr, "--config"])
            .arg(&cfg)
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // While it runs: healthy (detecting), and saying the recording is not.
        let t0 = Instant::now();
        let (health, metrics) = loop {
            if let (Some(h), Some(m)) = (http_get(&addr, "/healthz"), http_get(&addr, "/metrics")) {
                if m.contains("omnirow_last_seq") {
                    break (h, m);
                }
            }
            assert!(
                t0.elapsed() < Duration::from_secs(30),
                "no frame within 30 s"
            );
            std::thread::sleep(Duration::from_millis(100));
        };
        let body = health.split("\r\n\r\n").nth(1).unwrap();
        let h: Value = serde_json::from_str(body).unwrap();
        assert_eq!(h["healthy"], true, "{h}");
        assert!(h["recording"].as_str().unwrap().starts_with(state), "{h}");
        assert!(metrics.contains("omnirow_recording_failed 1"), "{metrics}");
        assert!(metrics.contains("omnirow_recording 0"), "{metrics}");
        let out = child.wait_with_output().unwrap();
        let log = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{log}");
        assert!(log.contains(&format!("the recording {state}")), "{log}");
        let frames_in = metrics
            .lines()
            .find_map(|l| l.strip_prefix("omnirow_frames_in_total "))
            .unwrap();
        assert!(frames_in.parse::<f64>().unwrap() >= 1.0);
    }
    let _ = std::fs::remove_dir_all(&dir);
}
