//! The whole per-frame step of the node (src/perception.rs): the detector, the rows' fit on
//! the ground and row guidance with its tracker, on full-resolution 2448×2050 Bayer RGGB
//! frames of the default synthetic drive (the GC2450C's frames through the ideal 185°
//! fisheye; `auto` runs the combined method), on one thread and on two. The detector's own benches
//! (`detector`, `edge`) time it alone; this one shows what a frame costs the node.
//!
//! `cargo bench --bench step`

use criterion::{criterion_group, criterion_main, Criterion};
use omnirow::config::Config;
use omnirow::frame::Frame;
use omnirow::perception::{Perception, PerceptionOptions};
use omnirow::source::synthetic::SyntheticDrive;
use omnirow::source::SourceConfig;
use std::time::Duration;

/// Eight consecutive frames of the drive at full resolution (a second of it at 15 fps spans
/// 15 frames: the tracker sees the robot move).
fn frames() -> (SyntheticDrive, Vec<Frame>) {
    let text = "[source.synthetic]\nwidth = 2448\nheight = 2050\nfps = 15.0\n";
    let SourceConfig::Synthetic(s) = Config::parse(text, "bench.toml").unwrap().source else {
        unreachable!("a synthetic source")
    };
    let mut drive = SyntheticDrive::new(s.drive).unwrap();
    let frames = (0..8).map(|seq| drive.frame_at(seq).unwrap()).collect();
    (drive, frames)
}

fn bench(c: &mut Criterion) {
    let (drive, frames) = frames();
    let cal = drive.calibration().clone();
    let mut g = c.benchmark_group("step_bayer_2448x2050");
    g.sample_size(20).measurement_time(Duration::from_secs(6));
    for (name, narrow, threads) in [
        ("full_search", false, 1),
        ("narrowed", true, 1),
        ("full_search_2_threads", false, 2),
        ("narrowed_2_threads", true, 2),
    ] {
        let opts = PerceptionOptions {
            narrow_search: narrow,
            threads,
            ..PerceptionOptions::default()
        };
        let mut step = Perception::new(&cal, &opts).unwrap();
        for f in &frames {
            step.process(f).unwrap();
        }
        let mut i = 0;
        g.bench_function(name, |b| {
            b.iter(|| {
                i = (i + 1) % frames.len();
                step.process(&frames[i]).unwrap()
            })
        });
        let est = step.process(&frames[0]).unwrap();
        eprintln!(
            "step {name}: last frame's stages (ms) {:?}, status {:?}",
            est.stage_ms, est.status
        );
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
