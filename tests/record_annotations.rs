//! `omnirow record` writes Foxglove image annotations beside the frames: one
//! `foxglove.ImageAnnotations` message per estimate, stamped with its image's header stamp,
//! whose drawings lie where the estimate says (checked by taking the pixels back to rays
//! through the recording's own calibration, not by drawing again), and a recording with them
//! still checks clean and replays.

#[path = "support/node.rs"]
mod node;

use nalgebra::Vector3;
use node::{bin, first_file, run_ok, small_config, tmpdir};
use omnirow::camera::Calibration;
use omnirow::estimate::Estimate;
use omnirow::guidance::followed::followed_lines;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn record(dir: &Path, extra: &str, frames: u32) -> PathBuf {
    let cfg = small_config(dir, extra);
    let rec = dir.join("rec");
    run_ok(
        bin()
            .args(["record", "--out"])
            .arg(&rec)
            .args(["--no-print", "--frames", &frames.to_string(), "--config"])
            .arg(&cfg),
    );
    first_file(&rec)
}

/// Pixel (Foxglove x, y) back to a unit ray in the camera frame.
fn ray(cal: &Calibration, p: &Value) -> Vector3<f64> {
    let (x, y) = (p["x"].as_f64().unwrap(), p["y"].as_f64().unwrap());
    cal.model.cam2world(y - 0.5, x - 0.5).normalize()
}

fn colour(c: &Value) -> [u8; 3] {
    let ch = |k: &str| (c[k].as_f64().unwrap() * 255.0).round() as u8;
    [ch("r"), ch("g"), ch("b")]
}

struct Recorded {
    cal: Calibration,
    image_stamps: BTreeMap<u64, u64>,
    estimates: Vec<(u64, Estimate)>,
    annotations: Vec<(u64, Value)>,
    schema: Option<(String, String, String)>,
}

fn read(file: &Path) -> Recorded {
    let bytes = std::fs::read(file).unwrap();
    let mut cal = None;
    for a in mcap::read::LinearReader::new(&bytes).unwrap() {
        if let mcap::records::Record::Attachment { header, data, .. } = a.unwrap() {
            if header.name == "calibration.toml" {
                let text = String::from_utf8(data.into_owned()).unwrap();
                cal = Some(Calibration::parse_toml(&text, file).unwrap());
            }
        }
    }
    let mut r = Recorded {
        cal: cal.expect("the calibration attachment"),
        image_stamps: BTreeMap::new(),
        estimates: Vec::new(),
        annotations: Vec::new(),
        schema: None,
    };
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        match m.channel.topic.as_str() {
            "/omnirow/image_raw" => {
                let img = omnirow::record::image_msg::decode_ros2_image(&m.data).unwrap();
                r.image_stamps.insert(m.publish_time, img.stamp_ns);
            }
            "/omnirow/estimate" => r
                .estimates
                .push((m.publish_time, serde_json::from_slice(&m.data).unwrap())),
            "/omnirow/image_annotations" => {
                let s = m.channel.schema.as_ref().unwrap();
                r.schema = Some((
                    s.name.clone(),
                    s.encoding.clone(),
                    m.channel.message_encoding.clone(),
                ));
                r.annotations
                    .push((m.publish_time, serde_json::from_slice(&m.data).unwrap()));
            }
            _ => {}
        }
    }
    r
}

#[test]
fn annotations_draw_each_estimate_where_it_lies() {
    let dir = tmpdir("annotations");
    let file = record(&dir, "", 8);
    let r = read(&file);
    assert_eq!(
        r.schema,
        Some((
            "foxglove.ImageAnnotations".into(),
            "jsonschema".into(),
            "json".into()
        ))
    );
    assert_eq!(r.annotations.len(), r.estimates.len(), "one per estimate");
    assert_eq!(r.estimates.len(), 8);
    let (h, w) = r.cal.size();
    let mut followed_checked = 0;
    for ((t, e), (ta, a)) in r.estimates.iter().zip(&r.annotations) {
        assert_eq!(t, ta);
        // Stamped as the image: Foxglove pairs them by it.
        let stamp = r.image_stamps[t];
        let sec = a["timestamp"]["sec"].as_u64().unwrap();
        let nsec = a["timestamp"]["nsec"].as_u64().unwrap();
        assert_eq!(sec * 1_000_000_000 + nsec, stamp);
        let strips = a["points"].as_array().unwrap();
        let row_colours: Vec<_> = e
            .rows
            .iter()
            .map(|row| omnirow::detect::overlay::method_colour(row.method))
            .collect();
        let mut row_points = 0;
        let mut followed = Vec::new();
        for s in strips {
            assert_eq!(s["type"], 3, "line strips");
            let pts = s["points"].as_array().unwrap();
            assert!(pts.len() >= 2);
            for p in pts {
                let (x, y) = (p["x"].as_f64().unwrap(), p["y"].as_f64().unwrap());
                assert!((0.0..=w as f64).contains(&x) && (0.0..=h as f64).contains(&y));
            }
            let c = colour(&s["outline_color"]);
            if row_colours.contains(&c) {
                // On one of the estimate's rows' great circles.
                for p in pts {
                    let v = ray(&r.cal, p);
                    let off = e
                        .rows
                        .iter()
                        .map(|row| Vector3::from(row.normal).dot(&v).abs())
                        .fold(f64::INFINITY, f64::min);
                    assert!(off < 2e-3, "a row strip's point {off} rad off every row");
                    row_points += 1;
                }
            } else {
                assert_eq!(c, omnirow::publish::overlay::FOLLOWED_COLOUR);
                followed.extend(pts.iter().cloned());
            }
        }
        assert!(
            row_points > 20 * e.rows.len(),
            "{row_points} points for {} rows",
            e.rows.len()
        );
        // The vanishing point: a circle on its direction (either sign).
        let vp = Vector3::from(e.vanishing_point.unwrap());
        let circles = a["circles"].as_array().unwrap();
        assert!(!circles.is_empty());
        for c in circles {
            let v = ray(&r.cal, &c["position"]);
            assert!(v.cross(&vp).norm() < 2e-3, "circle off the vanishing point");
        }
        let text = a["texts"][0]["text"].as_str().unwrap();
        assert!(text.starts_with(e.status.name()), "{text}");
        // The followed line and the rows beside it: every point's ray lies in the plane
        // through the camera and one of those lines on the ground.
        let g = e.guidance.as_ref().unwrap();
        let Some(f) = followed_lines(g) else {
            assert!(followed.is_empty());
            continue;
        };
        assert!(text.contains("offset"), "{text}");
        let robot_from_camera = r.cal.mounting.robot_from_camera();
        let camera_m = Vector3::from(r.cal.mounting.position_m);
        let planes: Vec<_> = std::iter::once(f.line)
            .chain(f.sides.iter().flatten().copied())
            .map(|l| (l.point_m - camera_m).cross(&l.direction).normalize())
            .collect();
        assert!(followed.len() > 20, "{} followed points", followed.len());
        for p in &followed {
            let d = robot_from_camera * ray(&r.cal, p);
            let off = planes
                .iter()
                .map(|n| n.dot(&d).abs())
                .fold(f64::INFINITY, f64::min);
            assert!(off < 2e-3, "a followed point {off} rad off the lines");
        }
        followed_checked += 1;
    }
    assert!(
        followed_checked >= 4,
        "{followed_checked} frames with a followed line"
    );

    // The recording with annotations checks clean and replays.
    run_ok(bin().args(["recording", "check"]).arg(&file));
    let out = run_ok(
        bin()
            .args(["run", "--replay"])
            .arg(&file)
            .args(["--rate", "max", "--print", "--config"])
            .arg(dir.join("omnirow.toml")),
    );
    assert_eq!(String::from_utf8_lossy(&out.stdout).lines().count(), 8);
}

#[test]
fn annotations_can_be_turned_off_and_ros2_string_recordings_have_none() {
    for (name, extra) in [
        ("off", "[record]\nannotations = false\n"),
        ("ros2", "[record]\njson_channels = \"ros2_string\"\n"),
    ] {
        let dir = tmpdir(name);
        let file = record(&dir, extra, 2);
        let bytes = std::fs::read(&file).unwrap();
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        assert!(
            summary
                .channels
                .values()
                .all(|c| c.topic != "/omnirow/image_annotations"),
            "{name}"
        );
    }
}
