//! The node for real: `omnirow run` and `omnirow record` as processes, read through real UDP
//! and TCP sockets and a real Unix datagram socket (systemd notify), stopped with SIGTERM.

use omnirow::estimate::Estimate;
use std::io::Read;
use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

#[path = "support/node.rs"]
mod node;
use node::*;

#[test]
fn synthetic_drive_publishes_udp_estimates_matching_truth() {
    let dir = tmpdir("synthetic");
    let cfg = small_config(&dir, "");
    let (sock, addr) = udp();
    let mut child = bin()
        .args([
            "run",
            "--frames",
            "30",
            "--no-print",
            "--udp",
            &addr,
            "--config",
        ])
        .arg(&cfg)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let est = collect(&sock, &mut child, Duration::from_secs(60));
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    assert_eq!(est.len(), 30, "every frame published once");
    for (i, e) in est.iter().enumerate() {
        assert_eq!(e.seq, i as u64, "in frame order");
        assert_eq!(e.schema_version, 2);
        assert!(e.latency_ms >= e.detector_ms && e.latency_ms < 1000.0);
        assert!(e.capture_ns > 0 && e.receive_ns >= e.capture_ns);
    }
    check_against_truth(&est);
}

#[test]
fn record_replay_twice_identical_and_truncated_replay() {
    let dir = tmpdir("replay");
    let cfg = small_config(&dir, "");
    let file = record(&dir, &cfg, 12);
    let file = &file;
    let replay = |path: &Path| replay(path, &cfg);
    let (a, _) = replay(file);
    let (b, _) = replay(file);
    assert_eq!(a.len(), 12);
    // Identical estimates, apart from the host's own clock.
    assert_eq!(strip_clock(&a), strip_clock(&b));
    // The ground truth travelled through the recording.
    check_against_truth(&a);

    // Cut the recording at 60%: every complete frame before the cut, with a warning.
    let bytes = std::fs::read(file).unwrap();
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 6 / 10]).unwrap();
    let (c, log) = replay(&cut);
    assert!(log.contains("recording cut short"), "{log}");
    assert!(
        c.len() >= 5 && c.len() < 12,
        "{} frames before the cut",
        c.len()
    );
    assert_eq!(strip_clock(&c), strip_clock(&a[..c.len()]));
}

#[test]
fn two_workers_with_the_narrowed_search_replay_identically() {
    // Each frame's search is narrowed by the prediction made after the frame two before it,
    // whichever worker finishes first: the estimates do not depend on timing.
    let dir = tmpdir("replay2");
    let cfg = small_config(
        &dir,
        "[pipeline]\nworkers = 2\nthreads = 1\nnarrow_search = true\n",
    );
    let file = record(&dir, &cfg, 30);
    let runs: Vec<Vec<Estimate>> = (0..3).map(|_| replay(&file, &cfg).0).collect();
    assert_eq!(runs[0].len(), 30);
    let tracked = runs[0]
        .iter()
        .filter(|e| {
            e.guidance
                .as_ref()
                .and_then(|g| g.lateral_offset_m)
                .is_some()
        })
        .count();
    assert!(tracked >= 25, "only {tracked} of 30 frames tracked");
    for r in &runs[1..] {
        assert_eq!(strip_clock(r), strip_clock(&runs[0]));
    }
    check_against_truth(&runs[0]);
}

/// Records `frames` frames of the synthetic source as `cfg` sets it into `dir/rec`; the file.
fn record(dir: &Path, cfg: &Path, frames: u32) -> PathBuf {
    let rec_dir = dir.join("rec");
    let out = bin()
        .args(["record", "--out"])
        .arg(&rec_dir)
        .args(["--frames", &frames.to_string(), "--no-print", "--config"])
        .arg(cfg)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let files: Vec<PathBuf> = std::fs::read_dir(&rec_dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(files.len(), 1);
    files.into_iter().next().unwrap()
}

/// Replays `path` as fast as possible with `cfg`: the estimates (over UDP) and the log.
fn replay(path: &Path, cfg: &Path) -> (Vec<Estimate>, String) {
    let (sock, addr) = udp();
    let mut child = bin()
        .args([
            "run",
            "--rate",
            "max",
            "--no-print",
            "--udp",
            &addr,
            "--replay",
        ])
        .arg(path)
        .args(["--config"])
        .arg(cfg)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let est = collect(&sock, &mut child, Duration::from_secs(60));
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    (est, String::from_utf8_lossy(&out.stderr).into_owned())
}

/// The estimates without what depends on the host's clock.
fn strip_clock(v: &[Estimate]) -> Vec<Estimate> {
    v.iter()
        .map(|e| Estimate {
            receive_ns: 0,
            publish_ns: 0,
            latency_ms: 0.0,
            detector_ms: 0.0,
            stage_ms: [0.0; 4],
            ..e.clone()
        })
        .collect()
}

#[test]
fn slow_detector_drops_oldest_frames_and_counts_them() {
    let dir = tmpdir("drops");
    let cfg = small_config(&dir, "");
    let rec_dir = dir.join("rec");
    let st = bin()
        .args(["record", "--out"])
        .arg(&rec_dir)
        .args(["--frames", "20", "--no-print", "--config"])
        .arg(&cfg)
        .stderr(Stdio::null())
        .status()
        .unwrap();
    assert!(st.success());
    let file = std::fs::read_dir(&rec_dir)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    // Replay at 50× the recorded rate into one worker behind a one-frame queue.
    let (sock, addr) = udp();
    let mut child = bin()
        .args([
            "run",
            "--rate",
            "50",
            "--workers",
            "1",
            "--frame-queue",
            "1",
            "--no-print",
        ])
        .args(["--udp", &addr, "--replay"])
        .arg(&file)
        .arg("--config")
        .arg(&cfg)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let est = collect(&sock, &mut child, Duration::from_secs(60));
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    let f = finished_fields(&String::from_utf8_lossy(&out.stderr));
    let (fin, fout, dropped) = (
        f["frames_in"].as_u64().unwrap(),
        f["frames_out"].as_u64().unwrap(),
        f["dropped"].as_u64().unwrap(),
    );
    assert_eq!(fin, 20);
    assert!(
        dropped > 0,
        "frames arrive faster than one worker detects: {f}"
    );
    assert_eq!(fout + dropped, fin);
    assert_eq!(est.len() as u64, fout);
    // The newest frame always wins: the last frame is never the one dropped.
    assert_eq!(est.last().unwrap().seq, 19);
}

#[test]
fn systemd_notify_protocol() {
    let dir = tmpdir("notify");
    let sock_path = dir.join("notify.sock");
    let server = UnixDatagram::bind(&sock_path).unwrap();
    server
        .set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let cfg = small_config(&dir, "[publish]\nstatus_interval_s = 0.2\n");
    let mut child = bin()
        .args(["run", "--no-print", "--duration", "2.5", "--config"])
        .arg(&cfg)
        .env("NOTIFY_SOCKET", &sock_path)
        .env("WATCHDOG_USEC", "400000")
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut msgs = Vec::new();
    let mut buf = [0u8; 4096];
    let t0 = Instant::now();
    loop {
        if let Ok(n) = server.recv(&mut buf) {
            msgs.push(String::from_utf8_lossy(&buf[..n]).into_owned());
            continue;
        }
        if child.try_wait().unwrap().is_some() {
            break;
        }
        assert!(t0.elapsed() < Duration::from_secs(60));
    }
    assert!(child.wait().unwrap().success());
    let first_ready = msgs
        .iter()
        .position(|m| m.starts_with("READY=1"))
        .expect("READY=1");
    assert_eq!(msgs.iter().filter(|m| m.starts_with("READY=1")).count(), 1);
    let watchdogs = msgs.iter().filter(|m| *m == "WATCHDOG=1").count();
    // 2.5 s at one WATCHDOG per 200 ms (half of WATCHDOG_USEC).
    assert!(watchdogs >= 6, "{watchdogs} watchdog messages: {msgs:?}");
    let status = msgs
        .iter()
        .find(|m| m.starts_with("STATUS=streaming"))
        .expect("a STATUS with the state");
    assert!(status.contains(" fps"), "{status}");
    let stopping = msgs
        .iter()
        .position(|m| m.starts_with("STOPPING=1"))
        .expect("STOPPING=1");
    assert!(first_ready < stopping);
    assert_eq!(
        stopping,
        msgs.len() - 1,
        "STOPPING is the last message: {msgs:?}"
    );
}

#[test]
fn sigterm_stops_within_two_seconds_with_a_complete_recording() {
    let dir = tmpdir("sigterm");
    let cfg = small_config(&dir, "");
    let rec_dir = dir.join("rec");
    let (sock, addr) = udp();
    let mut child = bin()
        .args(["record", "--out"])
        .arg(&rec_dir)
        .args(["--no-print", "--udp", &addr, "--config"])
        .arg(&cfg)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Let it run until frames flow, then SIGTERM.
    let mut buf = vec![0u8; 65536];
    let mut published = Vec::new();
    while published.len() < 10 {
        if let Ok(n) = sock.recv(&mut buf) {
            published.push(serde_json::from_slice::<Estimate>(&buf[..n]).unwrap());
        }
    }
    sigterm(&child);
    let t = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if let Ok(n) = sock.recv(&mut buf) {
            published.push(serde_json::from_slice::<Estimate>(&buf[..n]).unwrap());
        }
        assert!(
            t.elapsed() < Duration::from_secs(2),
            "no exit within 2 s of SIGTERM"
        );
    };
    assert!(status.success(), "exit 0 after SIGTERM");
    while let Ok(n) = sock.recv(&mut buf) {
        published.push(serde_json::from_slice::<Estimate>(&buf[..n]).unwrap());
    }
    let mut stderr = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    let f = finished_fields(&stderr);

    // The recording is complete: summary present, every frame and estimate readable.
    let file = std::fs::read_dir(&rec_dir)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let bytes = std::fs::read(&file).unwrap();
    let summary = mcap::Summary::read(&bytes)
        .unwrap()
        .expect("the MCAP summary was written");
    let stats = summary.stats.expect("statistics in the summary");
    let mut images = 0u64;
    let mut estimates = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        match m.channel.topic.as_str() {
            "/omnirow/image_raw" => {
                let img = omnirow::record::image_msg::decode_ros2_image(&m.data).unwrap();
                assert_eq!((img.width, img.height), (408, 342));
                assert_eq!(img.data.len(), 408 * 342);
                images += 1;
            }
            "/omnirow/estimate" => {
                estimates.push(serde_json::from_slice::<Estimate>(&m.data).unwrap())
            }
            _ => {}
        }
    }
    assert!(stats.message_count >= images + estimates.len() as u64);
    assert_eq!(
        images,
        f["frames_in"].as_u64().unwrap(),
        "every frame recorded"
    );
    assert_eq!(f["record_dropped"].as_u64().unwrap(), 0);
    // Every published estimate is in the recording, in order.
    assert_eq!(estimates.len(), published.len());
    for (r, p) in estimates.iter().zip(&published) {
        assert_eq!((r.seq, r.heading_rad), (p.seq, p.heading_rad));
    }
}
