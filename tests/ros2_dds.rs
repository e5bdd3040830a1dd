//! omnirow's ROS 2 topics checked by an independent DDS implementation (issue 7 §2).
//!
//! The peer is Eclipse Cyclone DDS from the `cyclonedds` PyPI wheel (C library + Python
//! binding), installed with `scripts/ci-python-env.sh` into `.venv-ci` (or the venv named by
//! `OMNIROW_CI_VENV`). tests/ros2/subscribe.py declares the ROS 2 message types as IDL itself
//! and prints what it decodes; `ddsls -j` (same wheel) lists the publications seen through DDS
//! discovery. All traffic stays on loopback: RustDDS is limited to 127.0.0.1, Cyclone to `lo`
//! without multicast (tests/ros2/cyclonedds-loopback.xml). Each test uses its own DDS domain.
//!
//! Without the venv the tests fail when `CI=true` and are skipped, saying why, otherwise.
#![cfg(feature = "ros2")]

use omnirow::frame::{ImageView, PixelFormat};
use omnirow::ros2::{
    Reliability, Ros2Config, Ros2Publisher, RosEstimate, RosGuidance, RosStatus, TrackedRow,
};
use serde_json::Value;
use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::net::{IpAddr, Ipv4Addr};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

const DIR: &str = env!("CARGO_MANIFEST_DIR");
const BASE_NS: u64 = 1_700_000_000_000_000_000;
const FRAME_NS: u64 = 50_000_000;

#[path = "ros2/venv.rs"]
mod venv;

#[path = "support/node.rs"]
mod run_node;

/// The venv with cyclonedds and its `ddsls`.
fn venv() -> Option<PathBuf> {
    let dir = venv::venv("cyclonedds")?;
    assert!(
        dir.join("bin/ddsls").is_file(),
        "{} has cyclonedds but no ddsls",
        dir.display()
    );
    Some(dir)
}

/// A DDS domain of its own for each test (and each concurrent test run on this machine).
fn domain(k: u16) -> u16 {
    100 + (std::process::id() % 26) as u16 * 5 + k
}

/// An estimate from a datagram on the test's UDP port, or None for anything else: the test
/// domains' RTPS ports (7400 + 250 * domain + ...) fall in the ephemeral range, so DDS discovery
/// traffic to a peer port can land on the socket the kernel gave this test.
fn estimate_datagram(bytes: &[u8]) -> Option<omnirow::estimate::Estimate> {
    if bytes.starts_with(b"RTPS") {
        return None;
    }
    Some(serde_json::from_slice(bytes).expect("a datagram that is neither RTPS nor an estimate"))
}

fn config(domain: u16) -> Ros2Config {
    Ros2Config {
        enabled: true,
        domain_id: Some(domain),
        networks: vec![IpAddr::V4(Ipv4Addr::LOCALHOST)],
        frame_id: "test_base".to_string(),
        image_frame_id: "test_cam".to_string(),
        ..Ros2Config::default()
    }
}

/// The subscriber process and its decoded samples, line by line.
struct Subscriber {
    child: Child,
    lines: mpsc::Receiver<Value>,
}

impl Subscriber {
    fn start(venv: &Path, domain: u16, args: &[&str]) -> Subscriber {
        let mut child = Command::new(venv.join("bin/python"))
            .arg(format!("{DIR}/tests/ros2/subscribe.py"))
            .args(["--domain", &domain.to_string()])
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start tests/ros2/subscribe.py");
        let out = child.stdout.take().unwrap();
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                let v: Value = serde_json::from_str(&line)
                    .unwrap_or_else(|e| panic!("subscribe.py printed {line:?}: {e}"));
                if tx.send(v).is_err() {
                    break;
                }
            }
        });
        let ready = rx
            .recv_timeout(Duration::from_secs(30))
            .expect("subscribe.py never said it was ready");
        assert_eq!(ready["ready"], true, "{ready}");
        Subscriber { child, lines: rx }
    }

    /// Exit status if it has exited.
    fn done(&mut self) -> Option<i32> {
        self.child
            .try_wait()
            .unwrap()
            .map(|s| s.code().unwrap_or(-1))
    }

    /// Waits for exit (at most `timeout`) and returns the exit code and every sample.
    fn finish(mut self, timeout: Duration) -> (i32, Vec<Value>) {
        let t0 = Instant::now();
        let code = loop {
            if let Some(c) = self.done() {
                break c;
            }
            if t0.elapsed() > timeout {
                let _ = self.child.kill();
                let _ = self.child.wait();
                break -1;
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        let mut samples = Vec::new();
        while let Ok(v) = self.lines.recv_timeout(Duration::from_millis(500)) {
            samples.push(v);
        }
        (code, samples)
    }
}

impl Drop for Subscriber {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// What frame `i` publishes: heading, tilt and quality that differ from frame to frame.
fn estimate(i: u64) -> (u64, f64, f64, f64) {
    let x = i as f64;
    (
        BASE_NS + i * FRAME_NS,
        0.4 * (0.7 * x).sin(),
        0.06 * (0.3 * x).cos(),
        0.3 + 0.6 * ((x * 0.5).sin() * 0.5 + 0.5),
    )
}

/// Frame `i`'s row guidance: tracked (offset, heading, curvature and covariance differing
/// from frame to frame), except every seventh frame, which is lost (no `row_*` sample).
fn guidance(i: u64) -> RosGuidance<'static> {
    let x = i as f64;
    let lost = i % 7 == 3;
    let (sd_e, sd_h) = (0.01 + 0.001 * x, 0.002 + 0.0001 * x);
    let tracked = TrackedRow {
        lateral_offset_m: 0.2 * (0.9 * x).sin(),
        heading_rad: 0.1 * (0.4 * x).cos(),
        curvature_per_m: 0.03 * (0.2 * x).sin(),
        row_spacing_m: 0.5 + 0.001 * x,
        row_index: (i % 3) as i64 - 1,
        covariance: [
            [sd_e * sd_e, 0.3 * sd_e * sd_h, 0.0, 0.0],
            [0.3 * sd_e * sd_h, sd_h * sd_h, 0.0, 0.0],
            [0.0, 0.0, 1e-6, 0.0],
            [0.0, 0.0, 0.0, 1e-6],
        ],
    };
    RosGuidance {
        tracking: if lost {
            "lost"
        } else if i % 7 == 4 {
            "reacquired"
        } else if i % 5 == 0 {
            "coasting"
        } else {
            "tracking"
        },
        mode: "between_rows",
        tracked: (!lost).then_some(tracked),
        roll_rad: (i % 2 == 0).then_some(0.001 * x),
        end_of_row_m: None,
        crop: "rows",
        warnings: &[],
    }
}

/// Frame `i`'s pixels: an 8×4 RGB image whose bytes depend on `i`.
fn pixels(i: u64) -> Vec<u8> {
    (0..8 * 4 * 3)
        .map(|k| (k as u64 * 7 + i * 13) as u8)
        .collect()
}

fn status(i: u64) -> RosStatus<'static> {
    RosStatus {
        frames_in: 10 * i + 3,
        frames_out: 10 * i,
        dropped: 3,
        latency_p50_ms: 12.5,
        latency_p99_ms: 27.25,
        estimate_status: "degraded",
        source_state: "running",
        camera_state: Some("streaming"),
        hardware_id: "test camera 42",
    }
}

/// Publishes frame after frame (every 50 ms) until `until` says stop or 40 s pass.
fn drive(p: &mut Ros2Publisher, mut until: impl FnMut() -> bool) -> u64 {
    let t0 = Instant::now();
    let mut i = 0;
    while !until() && t0.elapsed() < Duration::from_secs(40) {
        let (ns, h, t, q) = estimate(i);
        let e = RosEstimate {
            capture_ns: ns,
            heading_rad: Some(h),
            tilt_rad: Some(t),
            quality: q,
            status: "ok",
            guidance: Some(guidance(i)),
        };
        assert!(p.publish_estimate(&e).unwrap());
        let px = pixels(i);
        let view = ImageView::new(8, 4, PixelFormat::Rgb8, &px).unwrap();
        p.publish_frame(&view, ns).unwrap();
        if i % 5 == 0 {
            p.publish_status_at(&status(i), Some(&guidance(i)), ns)
                .unwrap();
        }
        i += 1;
        std::thread::sleep(Duration::from_millis(50));
    }
    i
}

fn stamp_ns(msg: &Value) -> u64 {
    let s = &msg["header"]["stamp"];
    s[0].as_u64().unwrap() * 1_000_000_000 + s[1].as_u64().unwrap()
}

fn frame_index(msg: &Value) -> u64 {
    let ns = stamp_ns(msg);
    assert!(
        ns >= BASE_NS && (ns - BASE_NS) % FRAME_NS == 0,
        "stamp {ns}"
    );
    (ns - BASE_NS) / FRAME_NS
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(f).collect()
}

/// Yaw of a quaternion [x, y, z, w] (ZYX).
fn yaw(q: &[f64]) -> f64 {
    (2.0 * (q[3] * q[2] + q[0] * q[1])).atan2(1.0 - 2.0 * (q[1] * q[1] + q[2] * q[2]))
}

/// `row_pose` of a frame tracked as `t` (tool point at base_link's origin): base_link at the
/// offset across the rows frame, yawed by the heading error (−heading), the filter's offset
/// and heading (co)variances in the y and yaw slots (the cross term's sign flipped with the
/// yaw), everything else unobserved.
fn check_row_pose(m: &Value, t: &TrackedRow, frame_id: &str) {
    assert_eq!(m["header"]["frame_id"], frame_id);
    let p = floats(&m["pose"]["position"]);
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs().max(1e-3);
    assert!(
        p[0] == 0.0 && close(p[1], t.lateral_offset_m) && p[2] == 0.0,
        "{m} vs {t:?}"
    );
    let q = floats(&m["pose"]["orientation"]);
    assert!((yaw(&q) + t.heading_rad).abs() < 1e-12, "{m} vs {t:?}");
    assert!(q[0] == 0.0 && q[1] == 0.0, "a planar pose: {q:?}");
    let c = floats(&m["covariance"]);
    let p = &t.covariance;
    assert!(close(c[7], p[0][0]) && close(c[35], p[1][1]), "{c:?}");
    assert!(close(c[11], -p[0][1]) && close(c[31], -p[0][1]), "{c:?}");
    for i in [0, 2, 3, 4] {
        assert_eq!(c[i * 7], 1.0e6, "{c:?}");
    }
}

/// `row_path`: the followed line in base_link, from abeam of the robot 5 m ahead every 0.5 m
/// (the defaults), an arc of the tracked curvature; written out here independently: a point
/// `s` along the line in the rows frame, then into base_link (origin `offset` left of the
/// line, turned by −heading).
fn check_row_path(m: &Value, t: &TrackedRow, frame_id: &str) {
    assert_eq!(m["header"]["frame_id"], frame_id);
    let poses = m["poses"].as_array().unwrap();
    assert_eq!(poses.len(), 11);
    let (e, h, k) = (t.lateral_offset_m, t.heading_rad, t.curvature_per_m);
    for (j, ps) in poses.iter().enumerate() {
        assert_eq!(ps["header"], m["header"]);
        let s = 0.5 * j as f64;
        let (xr, yr) = if k == 0.0 {
            (s, 0.0)
        } else {
            ((k * s).sin() / k, (1.0 - (k * s).cos()) / k)
        };
        let want = [
            h.cos() * xr - h.sin() * (yr - e),
            h.sin() * xr + h.cos() * (yr - e),
        ];
        let p = floats(&ps["pose"]["position"]);
        assert!(
            (p[0] - want[0]).abs() < 1e-9 && (p[1] - want[1]).abs() < 1e-9 && p[2] == 0.0,
            "pose {j}: {p:?} vs {want:?}"
        );
        let q = floats(&ps["pose"]["orientation"]);
        assert!((yaw(&q) - (h + k * s)).abs() < 1e-9, "pose {j}: {q:?}");
    }
}

/// `row_offset` and `row_heading_error` (float32, no stamp): in the order received, each the
/// offset (heading error = −heading) of a later tracked frame than the one before.
fn check_row_follow(k: &HashMap<String, Vec<Value>>, tracked: &[TrackedRow]) {
    let bits = |kind: &str| -> Vec<u32> {
        k[kind]
            .iter()
            .map(|m| m["bits"].as_u64().unwrap() as u32)
            .collect()
    };
    for (kind, want) in [
        (
            "row_offset",
            tracked
                .iter()
                .map(|t| (t.lateral_offset_m as f32).to_bits())
                .collect::<Vec<u32>>(),
        ),
        (
            "row_heading_error",
            tracked
                .iter()
                .map(|t| (-t.heading_rad as f32).to_bits())
                .collect(),
        ),
    ] {
        let got = bits(kind);
        let mut from = 0;
        for g in &got {
            let at = want[from..]
                .iter()
                .position(|w| w == g)
                .unwrap_or_else(|| panic!("{kind} {} is no later frame's", f32::from_bits(*g)));
            from += at + 1;
        }
    }
}

fn by_kind(samples: &[Value]) -> HashMap<String, Vec<Value>> {
    let mut m: HashMap<String, Vec<Value>> = HashMap::new();
    for s in samples {
        m.entry(s["kind"].as_str().unwrap().to_string())
            .or_default()
            .push(s["msg"].clone());
    }
    m
}

#[test]
fn cyclone_dds_decodes_every_topic_as_published() {
    let Some(venv) = venv() else { return };
    let d = domain(0);
    let sub = Subscriber::start(
        &venv,
        d,
        &[
            "--want",
            "orientation=8",
            "--want",
            "heading_tilt=8",
            "--want",
            "diagnostics=2",
            "--want",
            "image_raw=3",
            "--want",
            "discovery=1",
            "--want",
            "row_pose=8",
            "--want",
            "row_path=3",
            "--want",
            "row_offset=8",
            "--want",
            "row_heading_error=8",
            "--timeout",
            "40",
        ],
    );
    let mut cfg = config(d);
    cfg.image_rate_hz = 5.0; // every fourth frame at 20 frames per second
    let mut p = Ros2Publisher::new(&cfg).unwrap();
    assert_eq!(p.node_name(), "/omnirow/omnirow");
    assert_eq!(p.domain_id(), d);
    let mut sub = sub;
    let frames = drive(&mut p, || sub.done().is_some());
    let (code, samples) = sub.finish(Duration::from_secs(5));
    assert_eq!(code, 0, "subscriber failed after {frames} frames");
    let counts = p.counts();
    assert!(counts.orientation >= 8 && counts.images >= 3, "{counts:?}");
    let k = by_kind(&samples);

    // sensor_msgs/Imu: the row direction in the robot frame, read back from the quaternion
    // (Rᵀ·x̂), is the published heading and tilt; covariances as documented.
    for m in &k["orientation"] {
        let i = frame_index(m);
        let (_, h, t, q) = estimate(i);
        assert_eq!(m["header"]["frame_id"], "test_base");
        let o: Vec<f64> = m["orientation"].as_array().unwrap().iter().map(f).collect();
        let (x, y, z, w) = (o[0], o[1], o[2], o[3]);
        assert!(((x * x + y * y + z * z + w * w) - 1.0).abs() < 1e-12);
        // First column of R (robot → rows frame) transposed = first row of R.
        let d = [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ];
        let want = [t.cos() * h.cos(), t.cos() * h.sin(), t.sin()];
        for a in 0..3 {
            assert!(
                (d[a] - want[a]).abs() < 1e-9,
                "frame {i}: {d:?} vs {want:?}"
            );
        }
        let cov: Vec<f64> = m["orientation_covariance"]
            .as_array()
            .unwrap()
            .iter()
            .map(f)
            .collect();
        let sigma = 1.0f64.to_radians() / q;
        assert_eq!(cov[0], 1.0e6, "roll unobserved");
        assert!((cov[4] - sigma * sigma).abs() < 1e-15, "{cov:?}");
        assert!((cov[8] - sigma * sigma).abs() < 1e-15, "{cov:?}");
        assert_eq!(f(&m["angular_velocity_covariance"][0]), -1.0);
        assert_eq!(f(&m["linear_acceleration_covariance"][0]), -1.0);
    }

    // geometry_msgs/Vector3Stamped: heading, tilt, quality unchanged, bit for bit.
    for m in &k["heading_tilt"] {
        let (_, h, t, q) = estimate(frame_index(m));
        assert_eq!(m["header"]["frame_id"], "test_base");
        let v: Vec<f64> = m["vector_bits"]
            .as_array()
            .unwrap()
            .iter()
            .map(|b| f64::from_bits(b.as_u64().unwrap()))
            .collect();
        assert_eq!(v, vec![h, t, q]);
    }

    // sensor_msgs/Image: the frame's bytes, at the reduced rate.
    let mut image_frames = Vec::new();
    for m in &k["image_raw"] {
        let i = frame_index(m);
        image_frames.push(i);
        assert_eq!(m["header"]["frame_id"], "test_cam");
        assert_eq!(
            (m["width"].as_u64(), m["height"].as_u64()),
            (Some(8), Some(4))
        );
        assert_eq!(m["encoding"], "rgb8");
        assert_eq!(m["step"].as_u64(), Some(24));
        assert_eq!(m["is_bigendian"].as_u64(), Some(0));
        let hex: String = pixels(i).iter().map(|b| format!("{b:02x}")).collect();
        assert_eq!(m["data_hex"].as_str().unwrap(), hex, "frame {i}");
    }
    assert!(
        image_frames.iter().all(|i| i % 4 == 0),
        "5 Hz of 20 Hz capture time is every fourth frame: {image_frames:?}"
    );

    // diagnostic_msgs/DiagnosticArray on /diagnostics.
    for m in &k["diagnostics"] {
        let i = frame_index(m);
        let s = &m["status"][0];
        assert_eq!(s["level"].as_u64(), Some(1), "degraded is WARN");
        assert_eq!(s["name"], "omnirow: pipeline");
        assert_eq!(s["hardware_id"], "test camera 42");
        let v = &s["values"];
        assert_eq!(v["frames_in"], (10 * i + 3).to_string());
        assert_eq!(v["frames_out"], (10 * i).to_string());
        assert_eq!(v["dropped"], "3");
        assert_eq!(v["latency_p50_ms"], "12.50");
        assert_eq!(v["latency_p99_ms"], "27.25");
        assert_eq!(v["source_state"], "running");
        assert_eq!(v["camera_state"], "streaming");
        assert_eq!(v["estimate_status"], "degraded");
    }

    // The guidance's status beside the pipeline's.
    for m in &k["diagnostics"] {
        let g = guidance(frame_index(m));
        let s = &m["status"][1];
        assert_eq!(s["name"], "omnirow: guidance");
        assert_eq!(s["values"]["tracking"], g.tracking);
        let level = match g.tracking {
            "lost" => 2,
            "coasting" => 1,
            _ => 0,
        };
        assert_eq!(s["level"].as_u64(), Some(level), "{s}");
        match g.tracked {
            Some(t) => assert_eq!(
                s["values"]["lateral_offset_m"],
                format!("{:.4}", t.lateral_offset_m)
            ),
            None => assert!(s["values"].get("lateral_offset_m").is_none(), "{s}"),
        }
    }

    // The row guidance: row_pose and row_path per frame; no sample for a lost frame.
    for m in &k["row_pose"] {
        let i = frame_index(m);
        let t = guidance(i)
            .tracked
            .unwrap_or_else(|| panic!("frame {i} is lost"));
        check_row_pose(m, &t, "rows");
    }
    for m in &k["row_path"] {
        let i = frame_index(m);
        let t = guidance(i)
            .tracked
            .unwrap_or_else(|| panic!("frame {i} is lost"));
        check_row_path(m, &t, "test_base");
    }
    // row_offset / row_heading_error have no stamp: their values, in order, are those of the
    // tracked frames.
    let tracked: Vec<TrackedRow> = (0..frames).filter_map(|i| guidance(i).tracked).collect();
    check_row_follow(&k, &tracked);

    // ros_discovery_info: the node is announced the way `ros2 node list` reads it.
    let nodes: Vec<&Value> = k["discovery"]
        .iter()
        .flat_map(|m| m["nodes"].as_array().unwrap())
        .collect();
    assert!(
        nodes
            .iter()
            .any(|n| n["namespace"] == "/omnirow" && n["name"] == "omnirow"),
        "{nodes:?}"
    );
}

#[test]
fn ddsls_sees_the_publications_and_ros_discovery_names_their_writers() {
    let Some(venv) = venv() else { return };
    let d = domain(1);
    let mut cfg = config(d);
    cfg.image_rate_hz = 1.0;
    let mut p = Ros2Publisher::new(&cfg).unwrap();
    let disc = Subscriber::start(&venv, d, &["--want", "discovery=1", "--timeout", "30"]);
    let ddsls = Command::new(venv.join("bin/ddsls"))
        .args([
            "-j",
            "-i",
            &d.to_string(),
            "-t",
            "dcpspublication",
            "-r",
            "6",
        ])
        .env(
            "CYCLONEDDS_URI",
            format!("file://{DIR}/tests/ros2/cyclonedds-loopback.xml"),
        )
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start ddsls");
    // Keep the topics alive (and discovery going) while ddsls watches.
    let t0 = Instant::now();
    drive(&mut p, || t0.elapsed() > Duration::from_secs(7));
    let out = ddsls.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "ddsls failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: Value = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "ddsls -j printed no JSON ({e}): {}",
            String::from_utf8_lossy(&out.stdout)
        )
    });
    // topic name -> (type name, writer GUID as 32 hex digits)
    let mut seen: HashMap<String, (String, String)> = HashMap::new();
    for ev in json.as_array().unwrap() {
        if ev["type"] != "PUBLICATION" || ev["event"] != "new" {
            continue;
        }
        for v in ev["value"].as_array().unwrap() {
            let guid: String = v["key"].as_str().unwrap().replace('-', "");
            seen.insert(
                v["topic_name"].as_str().unwrap().to_string(),
                (v["type_name"].as_str().unwrap().to_string(), guid),
            );
        }
    }
    let (code, samples) = disc.finish(Duration::from_secs(30));
    assert_eq!(code, 0, "no ros_discovery_info sample");
    let k = by_kind(&samples);
    let node = k["discovery"]
        .iter()
        .flat_map(|m| m["nodes"].as_array().unwrap().clone())
        .find(|n| n["namespace"] == "/omnirow" && n["name"] == "omnirow")
        .expect("node /omnirow/omnirow in ros_discovery_info");
    let writers: Vec<String> = node["writers"]
        .as_array()
        .unwrap()
        .iter()
        .map(|g| g.as_str().unwrap().to_string())
        .collect();

    let topics = p.topics();
    assert_eq!(topics.len(), 8);
    for t in &topics {
        let (ty, guid) = seen
            .get(&t.dds_name)
            .unwrap_or_else(|| panic!("ddsls does not list {}: {seen:?}", t.dds_name));
        assert_eq!(ty, &t.dds_type, "type of {}", t.dds_name);
        assert!(
            writers.contains(guid),
            "writer {guid} of {} is not in the node's ros_discovery_info writers {writers:?}",
            t.dds_name
        );
    }
    let names: Vec<&str> = topics.iter().map(|t| t.dds_name.as_str()).collect();
    assert_eq!(
        names,
        [
            "rt/omnirow/orientation",
            "rt/omnirow/heading_tilt",
            "rt/omnirow/row_pose",
            "rt/omnirow/row_path",
            "rt/omnirow/row_offset",
            "rt/omnirow/row_heading_error",
            "rt/diagnostics",
            "rt/omnirow/image_raw"
        ]
    );
}

#[test]
fn reliability_is_what_the_config_says() {
    let Some(venv) = venv() else { return };
    // Best effort (the default): a best-effort reader gets samples, a reliable one is not
    // matched at all (DDS request/offer rules), both listening at the same time. The row
    // topics are reliable by default: a reliable reader (ROS 2's default QoS, as row-follow
    // controllers subscribe) and the best-effort one are both served.
    let d = domain(2);
    let be = Subscriber::start(
        &venv,
        d,
        &[
            "--want",
            "orientation=3",
            "--want",
            "row_offset=3",
            "--timeout",
            "30",
        ],
    );
    let rel = Subscriber::start(
        &venv,
        d,
        &["--want", "orientation=1", "--reliable", "--timeout", "8"],
    );
    let rel_rows = Subscriber::start(
        &venv,
        d,
        &[
            "--want",
            "row_offset=3",
            "--want",
            "row_pose=3",
            "--reliable",
            "--timeout",
            "30",
        ],
    );
    let mut p = Ros2Publisher::new(&config(d)).unwrap();
    let mut be = be;
    let t0 = Instant::now();
    drive(&mut p, || {
        be.done().is_some() && t0.elapsed() > Duration::from_secs(9)
    });
    let (code, _) = be.finish(Duration::from_secs(5));
    assert_eq!(
        code, 0,
        "best-effort reader got nothing from a best-effort writer"
    );
    // Its "timed out" message on stderr is the expected outcome.
    let (code, samples) = rel.finish(Duration::from_secs(5));
    assert_eq!(
        code, 1,
        "a reliable reader matched a best-effort writer: {samples:?}"
    );
    let (code, _) = rel_rows.finish(Duration::from_secs(5));
    assert_eq!(code, 0, "a reliable reader got no row guidance");
    drop(p);

    // Reliable configured: the reliable reader is served.
    let d = domain(3);
    let mut cfg = config(d);
    cfg.qos.reliability = Reliability::Reliable;
    let rel = Subscriber::start(
        &venv,
        d,
        &["--want", "orientation=3", "--reliable", "--timeout", "30"],
    );
    let mut p = Ros2Publisher::new(&cfg).unwrap();
    let mut rel = rel;
    drive(&mut p, || rel.done().is_some());
    let (code, _) = rel.finish(Duration::from_secs(5));
    assert_eq!(
        code, 0,
        "reliable reader got nothing from a reliable writer"
    );
}

mod node {
    //! The ROS 2 publisher in the node's real pipeline: source thread, detector worker,
    //! publisher thread, with `node_publisher` as the node calls it.
    use super::*;
    use omnirow::detect::{Detection, VanishingPoint};
    use omnirow::frame::Frame;
    use omnirow::pipeline::{Pipeline, PipelineOptions, Processor};
    use omnirow::source::{Poll, Source, SourceError, SourceState};

    /// 16×1 mono8 frames every 50 ms; the first 8 bytes are the frame index.
    struct Paced {
        next: u64,
    }

    fn frame_pixels(i: u64) -> Vec<u8> {
        let mut p = i.to_le_bytes().to_vec();
        p.extend((0..8u8).map(|k| k.wrapping_mul(29).wrapping_add(i as u8)));
        p
    }

    impl Source for Paced {
        fn describe(&self) -> String {
            "paced test source".into()
        }
        fn poll(&mut self, _t: Duration) -> Result<Poll, SourceError> {
            std::thread::sleep(Duration::from_millis(50));
            let i = self.next;
            self.next += 1;
            Ok(Poll::Frame(Frame {
                seq: i,
                capture_ns: BASE_NS + i * FRAME_NS,
                receive_ns: omnirow::frame::now_ns(),
                width: 16,
                height: 1,
                format: PixelFormat::Mono8,
                data: frame_pixels(i),
                truth: None,
            }))
        }
        fn state(&self) -> SourceState {
            SourceState::Streaming
        }
    }

    /// Answers frame i with `estimate(i)`'s heading, tilt and quality.
    struct Known;

    impl Processor for Known {
        fn process(
            &mut self,
            view: &ImageView,
            out: &mut Detection,
        ) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
            let i = u64::from_le_bytes(view.data[..8].try_into()?);
            let (_, h, t, q) = estimate(i);
            out.rows.clear();
            out.vanishing_point = Some(VanishingPoint {
                direction: nalgebra::Vector3::x(),
                inliers: 2,
                residual_rad: 0.0,
            });
            out.heading_rad = Some(h);
            out.tilt_rad = Some(t);
            out.quality = q;
            Ok(())
        }
    }

    #[test]
    fn the_pipeline_publishes_estimates_frames_and_status_through_ros2() {
        let Some(venv) = venv() else { return };
        let d = domain(4);
        let mut sub = Subscriber::start(
            &venv,
            d,
            &[
                "--want",
                "heading_tilt=6",
                "--want",
                "orientation=6",
                "--want",
                "image_raw=2",
                "--want",
                "diagnostics=2",
                "--timeout",
                "40",
            ],
        );
        let mut cfg = config(d);
        cfg.image_rate_hz = 5.0;
        let p = omnirow::ros2::node_publisher(&cfg, "paced test source", [0.0; 2], None)
            .unwrap()
            .expect("enabled");
        let pipeline = Pipeline::start(
            Box::new(Paced { next: 0 }),
            vec![Box::new(Known)],
            vec![p],
            None,
            PipelineOptions {
                max_duration: Some(Duration::from_secs(45)),
                ..PipelineOptions::default()
            },
        )
        .unwrap();
        let t0 = Instant::now();
        while sub.done().is_none() && t0.elapsed() < Duration::from_secs(45) {
            std::thread::sleep(Duration::from_millis(50));
        }
        pipeline.request_stop();
        let status = pipeline.join().unwrap();
        let (code, samples) = sub.finish(Duration::from_secs(5));
        assert_eq!(code, 0, "subscriber failed; pipeline status {status:?}");
        let k = by_kind(&samples);
        for m in &k["heading_tilt"] {
            let (_, h, t, q) = estimate(frame_index(m));
            let v: Vec<f64> = m["vector_bits"]
                .as_array()
                .unwrap()
                .iter()
                .map(|b| f64::from_bits(b.as_u64().unwrap()))
                .collect();
            assert_eq!(v, vec![h, t, q]);
        }
        for m in &k["orientation"] {
            let (_, h, t, _) = estimate(frame_index(m));
            let o: Vec<f64> = m["orientation"].as_array().unwrap().iter().map(f).collect();
            let (x, y, z, w) = (o[0], o[1], o[2], o[3]);
            let dy = 2.0 * (x * y - w * z);
            let dx = 1.0 - 2.0 * (y * y + z * z);
            assert!((dy.atan2(dx) - h).abs() < 1e-9, "heading of frame {m}");
            let dz = 2.0 * (x * z + w * y);
            assert!((dz.asin() - t).abs() < 1e-9, "tilt of frame {m}");
        }
        for m in &k["image_raw"] {
            let i = frame_index(m);
            let hex: String = frame_pixels(i).iter().map(|b| format!("{b:02x}")).collect();
            assert_eq!(m["data_hex"].as_str().unwrap(), hex);
            assert_eq!(m["encoding"], "mono8");
        }
        for m in &k["diagnostics"] {
            let s = &m["status"][0];
            assert_eq!(s["hardware_id"], "paced test source");
            assert_eq!(s["values"]["source_state"], "streaming");
            assert_eq!(s["values"]["estimate_status"], "ok");
            assert_eq!(s["level"].as_u64(), Some(0));
            let fin: u64 = s["values"]["frames_in"].as_str().unwrap().parse().unwrap();
            assert!(fin > 0);
        }
    }
}

/// The whole node: `omnirow run` with `[ros2] enabled = true` on the synthetic drive. Cyclone
/// decodes `heading_tilt` and `orientation`; each sample must carry exactly the estimate the
/// node also sent over UDP for the same capture stamp, and that estimate must match the
/// synthetic ground truth.
#[test]
fn omnirow_run_publishes_its_estimates_on_ros2() {
    use omnirow::estimate::{Estimate, Status};
    let Some(venv) = venv() else { return };
    let d = domain(5);
    let mut sub = Subscriber::start(
        &venv,
        d,
        &[
            "--want",
            "heading_tilt=8",
            "--want",
            "orientation=8",
            "--want",
            "diagnostics=2",
            "--want",
            "row_pose=8",
            "--want",
            "row_path=4",
            "--want",
            "row_offset=8",
            "--want",
            "row_heading_error=8",
            "--timeout",
            "60",
        ],
    );
    let dir = run_node::tmpdir("ros2");
    let cfg = run_node::small_config(
        &dir,
        &format!(
            "[ros2]\nenabled = true\ndomain_id = {d}\nnetworks = [\"127.0.0.1\"]\nframe_id = \"test_base\"\n\n[ros2.qos]\nreliability = \"reliable\"\ndepth = 50\n"
        ),
    );
    let (sock, addr) = run_node::udp();
    let child = run_node::bin()
        .args([
            "run",
            "--duration",
            "70",
            "--no-print",
            "--udp",
            &addr,
            "--config",
        ])
        .arg(&cfg)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut estimates: HashMap<u64, Estimate> = HashMap::new();
    let mut buf = vec![0u8; 65536];
    let t0 = Instant::now();
    while sub.done().is_none() && t0.elapsed() < Duration::from_secs(70) {
        if let Ok(n) = sock.recv(&mut buf) {
            if let Some(e) = estimate_datagram(&buf[..n]) {
                estimates.insert(e.capture_ns, e);
            }
        }
    }
    run_node::sigterm(&child);
    // Datagrams still on their way.
    while let Ok(n) = sock.recv(&mut buf) {
        if let Some(e) = estimate_datagram(&buf[..n]) {
            estimates.insert(e.capture_ns, e);
        }
    }
    let (code, samples) = sub.finish(Duration::from_secs(5));
    let out = child.wait_with_output().unwrap();
    let log = String::from_utf8_lossy(&out.stderr);
    assert_eq!(code, 0, "subscriber failed; node log:\n{log}");
    assert!(out.status.success(), "node failed:\n{log}");
    let k = by_kind(&samples);
    let mut checked = 0;
    for m in &k["heading_tilt"] {
        assert_eq!(m["header"]["frame_id"], "test_base");
        let e = estimates
            .get(&stamp_ns(m))
            .unwrap_or_else(|| panic!("no UDP estimate with the stamp of {m}"));
        let v: Vec<f64> = m["vector_bits"]
            .as_array()
            .unwrap()
            .iter()
            .map(|b| f64::from_bits(b.as_u64().unwrap()))
            .collect();
        if e.status != Status::Ok {
            continue;
        }
        let (h, t) = (e.heading_rad.unwrap(), e.tilt_rad.unwrap());
        // serde_json's default float parsing may be one ULP off; DDS carries the bits.
        assert!(
            (v[0] - h).abs() < 1e-12 && (v[1] - t).abs() < 1e-12,
            "ROS 2 and UDP disagree for {m}: {h} {t}"
        );
        assert!((v[2] - e.quality).abs() < 1e-12);
        let truth = e
            .truth
            .as_ref()
            .expect("synthetic frames carry their truth");
        assert!(
            run_node::heading_err(h, truth.heading_rad).to_degrees() < 1.0,
            "{e:?}"
        );
        assert!((t - truth.tilt_rad).abs().to_degrees() < 1.0, "{e:?}");
        checked += 1;
    }
    assert!(
        checked >= 6,
        "only {checked} heading_tilt samples with status ok"
    );
    for m in &k["orientation"] {
        let e = &estimates[&stamp_ns(m)];
        let Some(h) = e.heading_rad else { continue };
        let o: Vec<f64> = m["orientation"].as_array().unwrap().iter().map(f).collect();
        let (x, y, z, w) = (o[0], o[1], o[2], o[3]);
        let yaw = (2.0 * (x * y - w * z)).atan2(1.0 - 2.0 * (y * y + z * z));
        assert!((yaw - h).abs() < 1e-9, "orientation {m} vs heading {h}");
    }
    let s = &k["diagnostics"][0]["status"][0];
    assert!(
        s["hardware_id"].as_str().unwrap().contains("synthetic"),
        "{s}"
    );
    check_run_guidance(&k, &estimates);
}

/// The row guidance topics of `omnirow run` against the guidance in the estimate the node sent
/// over UDP for the same frame, and against the synthetic drive's truth (signs included).
fn check_run_guidance(
    k: &HashMap<String, Vec<Value>>,
    estimates: &HashMap<u64, omnirow::estimate::Estimate>,
) {
    let tracked_of = |m: &Value| -> (TrackedRow, &omnirow::estimate::Estimate, &'static str) {
        let e = estimates
            .get(&stamp_ns(m))
            .unwrap_or_else(|| panic!("no UDP estimate with the stamp of {m}"));
        let g = e.guidance.as_ref().expect("the node runs row guidance");
        let r = RosGuidance::from(g);
        let t = r
            .tracked
            .unwrap_or_else(|| panic!("a row sample for a frame without a tracked estimate"));
        (t, e, g.tracking.name())
    };
    let mut signs = 0;
    for m in &k["row_pose"] {
        let (t, e, tracking) = tracked_of(m);
        check_row_pose(m, &t, "rows");
        if tracking != "tracking" {
            continue;
        }
        // Against the truth: the camera (at base_link's origin) is `path_offset_m` left of
        // its inter-row path's centre line, and the rows' heading is the truth's, so the
        // pose's y is that offset (modulo a spacing: the followed path) and its yaw −heading.
        let truth = e
            .truth
            .as_ref()
            .expect("synthetic frames carry their truth");
        let y = f(&m["pose"]["position"][1]);
        let s = truth.row_spacing_m;
        let want = truth.path_offset_m(truth.path());
        let d = (y - want) - ((y - want) / s).round() * s;
        assert!(d.abs() < 0.02, "row_pose y {y} vs truth offset {want}");
        if want.abs() > 0.03 {
            assert_eq!(y.signum(), want.signum(), "offset sign: {y} vs {want}");
            signs += 1;
        }
        let yaw_err = yaw(&floats(&m["pose"]["orientation"])) + truth.heading_rad;
        assert!(
            yaw_err.abs() < 1f64.to_radians(),
            "row_pose yaw vs truth: {yaw_err}"
        );
    }
    // The drive weaves ±10 cm: many frames are off the centre line by more than 3 cm.
    assert!(
        signs >= 3,
        "only {signs} row_pose offsets away from the centre line"
    );
    for m in &k["row_path"] {
        let (t, _, _) = tracked_of(m);
        check_row_path(m, &t, "test_base");
    }
    let mut by_time: Vec<&omnirow::estimate::Estimate> = estimates.values().collect();
    by_time.sort_by_key(|e| e.capture_ns);
    let tracked: Vec<TrackedRow> = by_time
        .iter()
        .filter_map(|e| RosGuidance::from(e.guidance.as_ref()?).tracked)
        .collect();
    check_row_follow(k, &tracked);
    let g = k["diagnostics"]
        .iter()
        .flat_map(|m| m["status"].as_array().unwrap())
        .find(|s| s["name"] == "omnirow: guidance")
        .expect("a guidance status on /diagnostics");
    let level = match g["values"]["tracking"].as_str().unwrap() {
        "lost" => 2,
        "coasting" => 1,
        _ => 0,
    };
    assert!(g["level"].as_u64().unwrap() >= level, "{g}");
}

/// Row guidance's odometry input: a Cyclone DDS peer publishes `nav_msgs/Odometry` on `/odom`
/// as a robot's wheel odometry would (ROS 2's default QoS: reliable); the node's subscription
/// hands its speed and yaw rate to the feed guidance reads, stamped on arrival.
#[test]
fn odometry_from_a_ros2_peer_reaches_guidance() {
    use omnirow::guidance::{Guidance, GuidanceOptions, OdometryFeed};
    use std::sync::Arc;
    let Some(venv) = venv() else { return };
    let d = domain(6);
    let cfg = Ros2Config {
        odometry_topic: "/odom".to_string(),
        ..config(d)
    };
    let mut p = Ros2Publisher::new(&cfg).unwrap();
    let feed = Arc::new(OdometryFeed::new());
    p.subscribe_odometry(&cfg, feed.clone()).unwrap();
    let mut peer = Command::new(venv.join("bin/python"))
        .arg(format!("{DIR}/tests/ros2/publish_odometry.py"))
        .args(["--domain", &d.to_string(), "--topic", "rt/odom"])
        .args(["--speed", "1.25", "--yaw-rate", "0.1", "--seconds", "60"])
        .stdout(Stdio::null())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("start tests/ros2/publish_odometry.py");
    let t0 = Instant::now();
    let mut read = 0;
    while read < 5 && t0.elapsed() < Duration::from_secs(45) {
        read += p.poll_odometry();
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = peer.kill();
    let _ = peer.wait();
    assert!(read >= 5, "odometry samples read: {read}");
    assert_eq!(p.counts().odometry_in, read as u64);
    let o = feed.latest().expect("a sample in the feed");
    assert_eq!((o.speed_mps, o.yaw_rate_rps), (1.25, 0.1));
    let age = omnirow::frame::now_ns().abs_diff(o.stamp_ns);
    assert!(age < 5_000_000_000, "stamped {age} ns ago");
    // guidance reading the feed predicts with it, and ignores it once stale (0.5 s)
    let mut g = Guidance::new(GuidanceOptions::default(), Default::default())
        .unwrap()
        .with_odometry_feed(feed.clone());
    let m = g.motion_at(o.stamp_ns + 100_000_000);
    assert!(m.from_odometry, "{m:?}");
    assert_eq!((m.speed_mps, m.yaw_rate_rps), (Some(1.25), Some(0.1)));
    let m = g.motion_at(o.stamp_ns + 2_000_000_000);
    assert!(!m.from_odometry && m.speed_mps.is_none(), "{m:?}");
}
