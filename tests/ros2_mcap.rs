//! omnirow's MCAP recordings read by rosbags (pure-Python ROS 2 bag library, independent of
//! omnirow and of the `mcap` crate): the `sensor_msgs/msg/Image` channel's schema has ROS 2
//! Jazzy's type hash, and every frame decodes as ROS 2 CDR into exactly the frame recorded
//! (tests/ros2/check_mcap.py). Needs the venv from scripts/ci-python-env.sh: fails without it
//! when `CI=true`, skips with the reason otherwise.

#[path = "ros2/venv.rs"]
mod venv;

use omnirow::frame::{Frame, PixelFormat};
use omnirow::record::{RecordOptions, Recorder};
use serde_json::Value;
use std::process::Command;

const DIR: &str = env!("CARGO_MANIFEST_DIR");

fn frame(seq: u64, width: u32, height: u32, format: PixelFormat) -> Frame {
    let n = (width * height) as usize * format.bytes_per_pixel();
    Frame {
        seq,
        capture_ns: 1_700_000_000_000_000_000 + seq * 66_666_667,
        receive_ns: 1_700_000_000_010_000_000 + seq * 66_666_667,
        width,
        height,
        format,
        data: (0..n).map(|i| (i as u64 * 31 + seq * 7) as u8).collect(),
        truth: None,
    }
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

#[test]
fn rosbags_decodes_recorded_frames_as_ros2_images() {
    let Some(venv) = venv::venv("rosbags") else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("omnirow-ros2-mcap-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let frames = vec![
        frame(0, 5, 3, PixelFormat::Mono8), // odd width: step 5, no padding
        frame(1, 4, 2, PixelFormat::Rgb8),
        frame(2, 6, 4, PixelFormat::BayerRggb8),
        frame(3, 2448, 2050, PixelFormat::BayerRggb8), // the GC2450C's full frame, 5 MB
    ];
    let mut rec = Recorder::new(RecordOptions {
        dir: dir.clone(),
        reserve_bytes: 0,
        frame_id: "test_cam".into(),
        ..RecordOptions::default()
    })
    .unwrap();
    for f in &frames {
        rec.write_frame(f).unwrap();
    }
    rec.finish().unwrap();
    let path = rec.files()[0].clone();

    let out = Command::new(venv.join("bin/python"))
        .arg(format!("{DIR}/tests/ros2/check_mcap.py"))
        .arg(&path)
        .args(["--min-images", &frames.len().to_string()])
        .output()
        .expect("run tests/ros2/check_mcap.py");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "check_mcap.py rejected {}:\n{}\n{stdout}",
        path.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let lines: Vec<Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{l:?}: {e}")))
        .collect();
    let images: Vec<&Value> = lines.iter().filter(|v| v.get("topic").is_some()).collect();
    assert_eq!(images.len(), frames.len());
    for (f, m) in frames.iter().zip(&images) {
        assert_eq!(m["topic"], "/omnirow/image_raw");
        let stamp = [
            m["stamp"][0].as_u64().unwrap(),
            m["stamp"][1].as_u64().unwrap(),
        ];
        assert_eq!(
            stamp,
            [f.capture_ns / 1_000_000_000, f.capture_ns % 1_000_000_000]
        );
        assert_eq!(m["frame_id"], "test_cam");
        assert_eq!(m["width"].as_u64(), Some(f.width as u64));
        assert_eq!(m["height"].as_u64(), Some(f.height as u64));
        assert_eq!(m["encoding"], f.format.ros_encoding());
        let step = f.width as u64 * f.format.bytes_per_pixel() as u64;
        assert_eq!(m["step"].as_u64(), Some(step));
        assert_eq!(m["data_len"].as_u64(), Some(f.data.len() as u64));
        assert_eq!(m["data_head_hex"], hex(&f.data[..f.data.len().min(64)]));
        if f.data.len() <= 4096 {
            assert_eq!(m["data_hex"], hex(&f.data), "frame {}", f.seq);
        }
    }
    let summary = &lines.last().unwrap()["summary"];
    assert_eq!(summary["errors"].as_array().map(Vec::len), Some(0));
    // rosbags 0.11.9 refuses files with non-ROS schema encodings (the estimate channel's
    // `jsonschema`); the checker works around it and says so. Shown, not hidden.
    for w in summary["warnings"].as_array().into_iter().flatten() {
        eprintln!("check_mcap.py warning: {w}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_checker_rejects_what_ros2_would_reject() {
    let Some(venv) = venv::venv("rosbags") else {
        return;
    };
    let out = Command::new(venv.join("bin/python"))
        .arg(format!("{DIR}/tests/ros2/check_mcap.py"))
        .arg("--self-test")
        .output()
        .expect("run tests/ros2/check_mcap.py --self-test");
    assert!(
        out.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("self-test: ok"));
}

/// With `record.json_channels = "ros2_string"` every channel is a ROS 2 type, so rosbags'
/// own high-level reader opens the file as it is (no tolerance) and decodes the estimates.
#[test]
fn ros2_string_recordings_open_in_rosbags_unchanged() {
    use omnirow::estimate::{Estimate, Status};
    use omnirow::record::JsonChannels;
    let Some(venv) = venv::venv("rosbags") else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("omnirow-ros2-string-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mut rec = Recorder::new(RecordOptions {
        dir: dir.clone(),
        reserve_bytes: 0,
        json_channels: JsonChannels::Ros2String,
        ..RecordOptions::default()
    })
    .unwrap();
    for i in 0..3 {
        let f = frame(i, 8, 6, PixelFormat::Mono8);
        rec.write_frame(&f).unwrap();
        let mut e = Estimate::empty(&f, Status::NoRows);
        e.quality = 0.25 * i as f64;
        rec.write_estimate(&e).unwrap();
    }
    rec.finish().unwrap();
    let path = rec.files()[0].clone();
    let script = r#"
import json, sys
from pathlib import Path
from rosbags.highlevel import AnyReader
with AnyReader([Path(sys.argv[1])]) as r:
    for con, t, raw in r.messages():
        m = r.deserialize(raw, con.msgtype)
        if con.msgtype == "std_msgs/msg/String":
            print(json.dumps({"topic": con.topic, "json": json.loads(m.data)}))
        else:
            print(json.dumps({"topic": con.topic, "type": con.msgtype, "size": [m.width, m.height]}))
"#;
    let out = Command::new(venv.join("bin/python"))
        .args(["-c", script])
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "rosbags could not read {}:\n{}",
        path.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let lines: Vec<Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let images = lines
        .iter()
        .filter(|v| v["topic"] == "/omnirow/image_raw")
        .count();
    assert_eq!(images, 3);
    let est: Vec<&Value> = lines
        .iter()
        .filter(|v| v["topic"] == "/omnirow/estimate")
        .collect();
    assert_eq!(est.len(), 3);
    for (i, e) in est.iter().enumerate() {
        assert_eq!(e["json"]["seq"].as_u64(), Some(i as u64));
        assert_eq!(e["json"]["status"], "no_rows");
        assert_eq!(e["json"]["quality"].as_f64(), Some(0.25 * i as f64));
    }
    let _ = std::fs::remove_dir_all(&dir);
}
