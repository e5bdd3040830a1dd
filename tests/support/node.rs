//! Running the real `omnirow` binary in integration tests: the command with JSON logs, a
//! scratch directory, a UDP socket that receives the published estimates, checks against the
//! ground truth the synthetic drive carries, and SIGTERM. Included by the tests that start the
//! node (`#[path = "support/node.rs"] mod node;`).
#![allow(dead_code)]

use omnirow::estimate::{Estimate, Status};
use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::{Duration, Instant};

pub fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_omnirow"));
    c.env("OMNIROW_LOG_FORMAT", "json").env("RUST_LOG", "info");
    c
}

#[path = "scratch.rs"]
mod scratch;
pub use scratch::Scratch;

/// The test's scratch directory (removed when the test passes).
pub fn tmpdir(name: &str) -> Scratch {
    Scratch::new("node", name)
}

/// A small, fast synthetic drive (the detector's accuracy is guarded elsewhere).
pub fn small_config(dir: &Path, extra: &str) -> PathBuf {
    let p = dir.join("omnirow.toml");
    std::fs::write(
        &p,
        format!(
            "[source.synthetic]\nwidth = 408\nheight = 342\nfps = 30.0\nseed = 5\n\n[http]\nenabled = false\n\n{extra}"
        ),
    )
    .unwrap();
    p
}

pub fn udp() -> (UdpSocket, String) {
    let s = UdpSocket::bind("127.0.0.1:0").unwrap();
    s.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let a = s.local_addr().unwrap().to_string();
    (s, a)
}

/// Reads estimates from `sock` until `child` exits (plus a grace period for late datagrams).
pub fn collect(sock: &UdpSocket, child: &mut Child, limit: Duration) -> Vec<Estimate> {
    let t0 = Instant::now();
    let mut out = Vec::new();
    let mut buf = vec![0u8; 65536];
    let mut exited_at = None;
    loop {
        if let Ok(n) = sock.recv(&mut buf) {
            out.push(serde_json::from_slice(&buf[..n]).expect("a datagram is one JSON estimate"));
            continue;
        }
        if exited_at.is_none() && child.try_wait().unwrap().is_some() {
            exited_at = Some(Instant::now());
        }
        if exited_at.is_some_and(|t| t.elapsed() > Duration::from_millis(300)) {
            return out;
        }
        if t0.elapsed() > limit {
            let _ = child.kill();
            panic!("the node did not finish within {limit:?}");
        }
    }
}

/// The angle between two headings, treating a row direction and its opposite alike.
pub fn heading_err(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(std::f64::consts::PI);
    d.min(std::f64::consts::PI - d)
}

/// Checks published heading and tilt against the ground truth carried in each estimate.
pub fn check_against_truth(est: &[Estimate]) {
    let ok: Vec<&Estimate> = est.iter().filter(|e| e.status == Status::Ok).collect();
    assert!(
        ok.len() * 10 >= est.len() * 8,
        "at least 80% of the frames give an estimate ({} of {})",
        ok.len(),
        est.len()
    );
    for e in ok {
        let t = e
            .truth
            .as_ref()
            .expect("synthetic frames carry their ground truth");
        let dh = heading_err(e.heading_rad.unwrap(), t.heading_rad).to_degrees();
        let dt = (e.tilt_rad.unwrap() - t.tilt_rad).abs().to_degrees();
        assert!(dh < 1.0, "seq {}: heading off by {dh:.3}°", e.seq);
        assert!(dt < 1.0, "seq {}: tilt off by {dt:.3}°", e.seq);
    }
}

/// The final "finished" log line's fields (JSON logs).
pub fn finished_fields(stderr: &str) -> serde_json::Value {
    stderr
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .find(|v| v["fields"]["message"] == "finished")
        .map(|v| v["fields"].clone())
        .unwrap_or_else(|| panic!("no `finished` line in the log:\n{stderr}"))
}

pub fn sigterm(child: &Child) {
    // SAFETY: sending a signal to our own child process.
    let rc = unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    assert_eq!(rc, 0);
}

/// Runs `cmd` to its end and returns its output; a failed run fails the test with its stderr.
pub fn run_ok(cmd: &mut Command) -> std::process::Output {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{:?} failed: {}",
        cmd,
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// The first file in `dir` (a recording's folder holds one file per rotation).
pub fn first_file(dir: &Path) -> PathBuf {
    std::fs::read_dir(dir)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path()
}
