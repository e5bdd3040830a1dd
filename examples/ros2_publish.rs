//! Publishes synthetic estimates on omnirow's ROS 2 topics, without the node: for checking a
//! ROS 2 setup (`ros2 topic echo /omnirow/heading_tilt`) before a camera is connected.
//!
//! Heading sways ±20° with a 10 s period, tilt ±2°, and the row guidance weaves ±10 cm about
//! the path centre (`row_pose`, `row_path`, `row_offset`, `row_heading_error`), at 15 frames
//! per second, with a status on `/diagnostics` once a second and a 64×48 test pattern on
//! `image_raw` at 1 Hz.
//!
//! ```sh
//! cargo run --release --features ros2 --example ros2_publish -- [--seconds N] [--domain D] [--loopback]
//! ```

use anyhow::{bail, Context};
use omnirow::frame::{ImageView, PixelFormat};
use omnirow::ros2::{Ros2Config, Ros2Publisher, RosEstimate, RosGuidance, RosStatus, TrackedRow};
use std::net::{IpAddr, Ipv4Addr};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

fn main() -> anyhow::Result<()> {
    omnirow::cli::init_logging();
    let mut cfg = Ros2Config {
        enabled: true,
        image_rate_hz: 1.0,
        ..Ros2Config::default()
    };
    let mut seconds = 30.0f64;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--seconds" => seconds = args.next().context("--seconds N")?.parse()?,
            "--domain" => cfg.domain_id = Some(args.next().context("--domain D")?.parse()?),
            "--loopback" => cfg.networks = vec![IpAddr::V4(Ipv4Addr::LOCALHOST)],
            other => bail!("unknown argument {other:?}"),
        }
    }
    let mut p = Ros2Publisher::new(&cfg)?;
    println!(
        "node {} in domain {} publishing:",
        p.node_name(),
        p.domain_id()
    );
    for t in p.topics() {
        println!("  {} [{}]", t.name, t.ros_type);
    }

    let (w, h) = (64u32, 48u32);
    let mut pixels = vec![0u8; (w * h) as usize];
    let t0 = Instant::now();
    let mut next_status = t0;
    let mut frame = 0u64;
    while t0.elapsed().as_secs_f64() < seconds {
        let now_ns = SystemTime::now().duration_since(UNIX_EPOCH)?.as_nanos() as u64;
        let s = t0.elapsed().as_secs_f64();
        let phase = 2.0 * std::f64::consts::PI * s / 10.0;
        let heading = 20f64.to_radians() * phase.sin();
        // The robot weaves ±10 cm about the path centre, turned against the rows' heading.
        let tracked = TrackedRow {
            lateral_offset_m: 0.1 * phase.cos(),
            heading_rad: heading,
            curvature_per_m: 0.0,
            row_spacing_m: 0.5,
            row_index: 0,
            covariance: [
                [1e-5, 0.0, 0.0, 0.0],
                [0.0, 1e-6, 0.0, 0.0],
                [0.0, 0.0, 1e-6, 0.0],
                [0.0, 0.0, 0.0, 1e-6],
            ],
        };
        let guidance = RosGuidance {
            tracking: "tracking",
            mode: "between_rows",
            tracked: Some(tracked),
            roll_rad: None,
            end_of_row_m: None,
            crop: "rows",
            warnings: &[],
        };
        p.publish_estimate(&RosEstimate {
            capture_ns: now_ns,
            heading_rad: Some(heading),
            tilt_rad: Some(2f64.to_radians() * phase.cos()),
            quality: 0.9,
            status: "ok",
            guidance: Some(guidance),
        })?;
        for (i, px) in pixels.iter_mut().enumerate() {
            *px = ((i as u64 % w as u64) * 4 + frame) as u8;
        }
        p.publish_frame(&ImageView::new(w, h, PixelFormat::Mono8, &pixels)?, now_ns)?;
        if Instant::now() >= next_status {
            p.publish_status(
                &RosStatus {
                    frames_in: frame + 1,
                    frames_out: frame + 1,
                    estimate_status: "ok",
                    source_state: "synthetic",
                    hardware_id: "ros2_publish example",
                    ..RosStatus::default()
                },
                Some(&guidance),
            )?;
            next_status += Duration::from_secs(1);
        }
        frame += 1;
        std::thread::sleep(Duration::from_millis(66));
    }
    println!("published {:?}", p.counts());
    Ok(())
}
