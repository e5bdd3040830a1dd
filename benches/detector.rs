//! Detector speed on a full GC2450C frame (2448×2050), greyscale and Bayer input: each stage
//! and the whole Hough path. Run: `cargo bench --bench detector`. Prints the breakdown.

#[path = "../tests/common/mod.rs"]
mod common;

use criterion::{criterion_group, criterion_main, Criterion};
use omnirow::camera::ideal_fisheye;
use omnirow::detect::hough::HoughRows;
use omnirow::detect::mask::build_mask;
use omnirow::detect::smooth::Gaussian;
use omnirow::detect::threshold::keep_brightest;
use omnirow::detect::vegetation::vegetation_image;
use omnirow::detect::{Detection, Detector, DetectorOptions, GreyImage, Points};
use omnirow::frame::{ImageView, PixelFormat};
use std::time::{Duration, Instant};

fn frames() -> (omnirow::camera::Calibration, Vec<u8>, Vec<u8>) {
    let cal = ideal_fisheye(2050, 2448);
    let r = common::render_rows(&cal, 0.15, 0.02, 4, 0.75, 0.06, 1.0, 0.2, 0.05, 42);
    let w = r.width as usize;
    let bayer = r
        .data
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            let (row, col) = (i / w, i % w);
            // green plants on dark soil: G sites bright, R and B dimmer
            if (row + col) % 2 == 1 {
                v
            } else {
                v / 3 + 20
            }
        })
        .collect();
    (cal, r.data, bayer)
}

fn bench(c: &mut Criterion) {
    let (cal, mono, bayer) = frames();
    let opts = DetectorOptions::default();
    for (name, format, data) in [
        ("mono8", PixelFormat::Mono8, &mono),
        ("bayer_rggb8", PixelFormat::BayerRggb8, &bayer),
    ] {
        let view = ImageView::new(2448, 2050, format, data).unwrap();
        let mut g = c.benchmark_group(format!("detector_{name}_2448x2050"));
        g.sample_size(20).measurement_time(Duration::from_secs(4));
        // Whole Hough path.
        let mut det = Detector::new(&cal, opts.clone()).unwrap();
        let mut out = Detection::default();
        det.process(&view, &mut out).unwrap();
        g.bench_function("whole", |b| {
            b.iter(|| det.process(&view, &mut out).unwrap())
        });
        // Stages on the same buffers.
        let mut veg = GreyImage::default();
        g.bench_function("vegetation", |b| {
            b.iter(|| vegetation_image(&view, &opts.vegetation, true, &mut veg).unwrap())
        });
        let gauss = Gaussian::new(&opts.smooth).unwrap();
        let mut tmp = Vec::new();
        let mut sm = veg.clone();
        g.bench_function("smooth", |b| {
            b.iter(|| {
                gauss
                    .apply(&veg.data, veg.width, veg.height, &mut tmp, &mut sm.data)
                    .unwrap()
            })
        });
        let work = cal.rescaled(2.0).unwrap();
        let (mut mask, mut rays) = (Vec::new(), Vec::new());
        build_mask(
            &work,
            &opts.mask,
            opts.max_tilt_deg,
            None,
            &mut mask,
            &mut rays,
        )
        .unwrap();
        let mut kept = Vec::new();
        g.bench_function("threshold", |b| {
            b.iter(|| keep_brightest(&sm.data, &mask, &opts.threshold, &mut kept).unwrap())
        });
        let mut points = Points::default();
        let mut prep = omnirow::detect::Preparer::new(&cal, &opts).unwrap();
        prep.run(&view, &mut points).unwrap();
        g.bench_function("prepare", |b| {
            b.iter(|| prep.run(&view, &mut points).unwrap())
        });
        let mut hough = HoughRows::new(opts.hough).unwrap();
        let mut rows = Vec::new();
        g.bench_function("hough", |b| {
            b.iter(|| {
                rows.clear();
                hough
                    .find_rows(&points.rays, &points.weights, &mut rows)
                    .unwrap()
            })
        });
        let mut vs = omnirow::detect::VanishingStage::new(&cal, &opts).unwrap();
        let mut d2 = Detection {
            rows: rows.clone(),
            ..Default::default()
        };
        g.bench_function("vanishing", |b| b.iter(|| vs.run(None, &mut d2).unwrap()));
        g.finish();
        // Breakdown from the detector's own stage timer (median of 30 frames).
        let times: Vec<_> = (0..30)
            .map(|_| {
                det.process(&view, &mut out).unwrap();
                det.last_times()
            })
            .collect();
        let med = |f: &dyn Fn(&omnirow::detect::detector::StageTimes) -> Duration| {
            let mut v: Vec<f64> = times.iter().map(|t| f(t).as_secs_f64() * 1e3).collect();
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let t0 = Instant::now();
        det.process(&view, &mut out).unwrap();
        let one = t0.elapsed();
        println!(
            "{name} 2448x2050 breakdown (median ms): prepare {:.2}, hough {:.2}, vanishing {:.3}, total {:.2} (one more frame {:.2} ms); {} points, {} rows, VP {}",
            med(&|t| t.prepare),
            med(&|t| t.hough),
            med(&|t| t.vanishing),
            med(&|t| t.total()),
            one.as_secs_f64() * 1e3,
            det.points().rays.len(),
            out.rows.len(),
            if out.vanishing_point.is_some() { "found" } else { "none" },
        );
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
