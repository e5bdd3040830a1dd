//! Row guidance per frame: the comb on the ground (with the roll search) and the tracker, on
//! eleven rows of an exact synthetic view. Issue 14's target: at most 1 ms per frame.

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use nalgebra::Vector3;
use omnirow::camera::Mounting;
use omnirow::guidance::{
    Guidance, GuidanceEstimate, GuidanceOptions, Measurement, Tracker, TrackerOptions,
};
use omnirow::synth::Pose;

fn view(cam_y: f64) -> ([f64; 3], Vec<[f64; 3]>) {
    let pose = Pose::new(
        0.05,
        0.02,
        0.01,
        &Mounting::default(),
        Vector3::new(0.0, cam_y, 1.0),
    );
    let normals = (-5..=5)
        .filter_map(|k| pose.line_normal(&Vector3::new(0.0, k as f64 * 0.5, 0.0), &Vector3::x()))
        .map(Into::into)
        .collect();
    (pose.vp_along().into(), normals)
}

fn bench(c: &mut Criterion) {
    let frames: Vec<_> = (0..64).map(|i| view(0.2 + 0.002 * i as f64)).collect();
    let mut g = c.benchmark_group("guidance");
    for (name, roll) in [("frame_with_roll", 5.0), ("frame_without_roll", 0.0)] {
        let opts = GuidanceOptions {
            max_roll_deg: roll,
            ..GuidanceOptions::default()
        };
        let mut guidance = Guidance::new(opts, Mounting::default()).unwrap();
        let mut out = GuidanceEstimate::default();
        let mut i = 0u64;
        g.bench_function(name, |b| {
            b.iter(|| {
                let (vp, normals) = &frames[(i % 64) as usize];
                i += 1;
                guidance.update(
                    i * 66_666_667,
                    Some(*vp),
                    normals.iter().copied(),
                    None,
                    &mut out,
                );
                black_box(out.lateral_offset_m)
            })
        });
    }
    let mut tracker = Tracker::new(TrackerOptions::default());
    let mut i = 0u64;
    g.bench_function("tracker_only", |b| {
        b.iter(|| {
            i += 1;
            let m = Measurement {
                offset_m: 0.01 * ((i % 7) as f64 - 3.0),
                offset_sd_m: 0.005,
                heading_rad: 0.0,
                heading_sd_rad: 0.002,
                spacing_m: 0.5,
                spacing_sd_m: 0.003,
                curvature: Some((0.01, 0.005)),
            };
            black_box(tracker.update(i * 66_666_667, Some(&m)))
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
