//! Detector speed on a full GC2450C frame (2448×2050), greyscale and Bayer input: each stage
//! and the whole Hough path, also narrowed by a prior on the vanishing point (issue 14); and
//! on a 640×480 perspective frame (issue 13: the cost scales with the image), the default
//! detector and the Hough method, each with and without the prior.
//! Run: `cargo bench --bench detector`. Prints the breakdown.

#[path = "../tests/common/mod.rs"]
mod common;

use criterion::{criterion_group, criterion_main, Criterion};
use omnirow::camera::ideal_fisheye;
use omnirow::detect::hough::{HoughParams, HoughRows};
use omnirow::detect::mask::build_mask;
use omnirow::detect::smooth::Gaussian;
use omnirow::detect::threshold::keep_brightest;
use omnirow::detect::vanishing::{VanishingParams, VanishingStage};
use omnirow::detect::vegetation::vegetation_image;
use omnirow::detect::{
    Detection, Detector, DetectorOptions, DetectorPrior, GreyImage, Method, Points, PriorOutcome,
};
use omnirow::frame::{ImageView, PixelFormat};
use std::time::Duration;

fn frames() -> (omnirow::camera::Calibration, Vec<u8>, Vec<u8>) {
    let cal = ideal_fisheye(2050, 2448).unwrap();
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
    let opts = DetectorOptions {
        method: Method::Hough,
        ..Default::default()
    };
    for (name, format, data) in [
        ("mono8", PixelFormat::Mono8, &mono),
        ("bayer_rggb8", PixelFormat::BayerRggb8, &bayer),
    ] {
        let view = ImageView::new(2448, 2050, format, data).unwrap();
        let mut g = c.benchmark_group(format!("detector_{name}_2448x2050"));
        g.sample_size(10).measurement_time(Duration::from_secs(3));
        // Whole Hough path.
        let mut det = Detector::new(&cal, opts.clone()).unwrap();
        let mut out = Detection::default();
        det.process(&view, &mut out).unwrap();
        g.bench_function("whole", |b| {
            b.iter(|| det.process(&view, &mut out).unwrap())
        });
        // Narrowed by the tracker's kind of prior: the last vanishing point, a 2° window.
        let prior = narrow_prior(&out);
        det.process_with_prior(&view, Some(&prior), &mut out)
            .unwrap();
        assert_eq!(det.last_prior(), PriorOutcome::Accepted);
        g.bench_function("whole_narrowed", |b| {
            b.iter(|| {
                det.process_with_prior(&view, Some(&prior), &mut out)
                    .unwrap()
            })
        });
        for (label, p) in [("full", None), ("narrowed", Some(&prior))] {
            let a = thread_cpu_ns();
            for _ in 0..20 {
                det.process_with_prior(&view, p, &mut out).unwrap();
            }
            if let (Some(a), Some(b)) = (a, thread_cpu_ns()) {
                let t = det.last_times();
                println!(
                    "{name} 2448x2050 {label}: {:.2} ms CPU per frame ({:?}, {} rows; last frame: prepare {:.2} ms, hough + refit {:.2} ms wall)",
                    (b - a) as f64 / 20.0 / 1e6,
                    det.last_prior(),
                    out.rows.len(),
                    t.prepare.as_secs_f64() * 1e3,
                    t.rows.as_secs_f64() * 1e3,
                );
            }
        }
        // Stages on the same buffers.
        let mut veg = GreyImage::default();
        // Filled once here so that each stage has its input even when a filter skips the
        // stages before it.
        vegetation_image(&view, &opts.vegetation, true, &mut veg).unwrap();
        g.bench_function("vegetation", |b| {
            b.iter(|| vegetation_image(&view, &opts.vegetation, true, &mut veg).unwrap())
        });
        let gauss = Gaussian::new(&opts.smooth).unwrap();
        let mut tmp = Vec::new();
        let mut sm = veg.clone();
        gauss
            .apply(&veg.data, veg.width, veg.height, &mut tmp, &mut sm.data)
            .unwrap();
        g.bench_function("smooth", |b| {
            b.iter(|| {
                gauss
                    .apply(&veg.data, veg.width, veg.height, &mut tmp, &mut sm.data)
                    .unwrap()
            })
        });
        let work = cal.rescaled(2.0).unwrap();
        let (mut mask, mut rays, mut solid) = (Vec::new(), Vec::new(), Vec::new());
        build_mask(
            &work,
            &opts.mask,
            opts.max_tilt_deg,
            &mut mask,
            &mut rays,
            &mut solid,
        )
        .unwrap();
        let mut kept = Vec::new();
        g.bench_function("threshold", |b| {
            b.iter(|| keep_brightest(&sm.data, &mask, &opts.threshold, &mut kept).unwrap())
        });
        let mut points = Points::default();
        let mut prep = omnirow::detect::Preparer::new(&cal, &opts.prepare()).unwrap();
        prep.run(&view, &mut points).unwrap();
        g.bench_function("prepare", |b| {
            b.iter(|| prep.run(&view, &mut points).unwrap())
        });
        let mut hough = HoughRows::new(HoughParams::new(&opts.hough, 1.0)).unwrap();
        let mut rows = Vec::new();
        g.bench_function("hough", |b| {
            b.iter(|| {
                rows.clear();
                hough
                    .find_rows(&points.rays, &points.weights, &mut rows)
                    .unwrap()
            })
        });
        let bands = hough.bands().to_vec();
        let mut rows2 = rows.clone();
        // The detector refits with the first vanishing point of the Hough rows.
        let vp0 = out.vanishing_point.map(|v| v.direction);
        g.bench_function("refit", |b| {
            b.iter(|| prep.refit(&mut rows2, &bands, vp0.as_ref()).unwrap())
        });
        let mut vs =
            VanishingStage::new(VanishingParams::default(), opts.max_tilt_deg, &cal.mounting)
                .unwrap();
        let mut d2 = Detection {
            rows: rows.clone(),
            ..Default::default()
        };
        g.bench_function("vanishing", |b| b.iter(|| vs.run(None, &mut d2).unwrap()));
        g.finish();
        // Breakdown: the detector's own stage timer (wall clock, median of 30 frames) and
        // this thread's CPU time per frame (/proc/thread-self/schedstat), which a busy
        // machine does not inflate.
        let mut times = Vec::new();
        let cpu0 = thread_cpu_ns();
        for _ in 0..30 {
            det.process(&view, &mut out).unwrap();
            times.push(det.last_times());
        }
        let cpu_ms = thread_cpu_ns()
            .zip(cpu0)
            .map(|(b, a)| (b - a) as f64 / 30.0 / 1e6);
        let med = |f: &dyn Fn(&omnirow::detect::StageTimes) -> Duration| {
            let mut v: Vec<f64> = times.iter().map(|t| f(t).as_secs_f64() * 1e3).collect();
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        println!(
            "{name} 2448x2050 breakdown (median wall ms): prepare {:.2}, hough + refit {:.2}, vanishing {:.3}, total {:.2}; CPU per frame {}; {} points, {} rows, VP {}",
            med(&|t| t.prepare),
            med(&|t| t.rows),
            med(&|t| t.vanishing),
            med(&|t| t.total()),
            cpu_ms.map_or("unavailable".to_string(), |c| format!("{c:.2} ms")),
            det.points().rays.len(),
            out.rows.len(),
            if out.vanishing_point.is_some() { "found" } else { "none" },
        );
        // Per-stage CPU time.
        let stage_cpu = |label: &str, f: &mut dyn FnMut()| {
            let a = thread_cpu_ns();
            for _ in 0..20 {
                f();
            }
            if let (Some(a), Some(b)) = (a, thread_cpu_ns()) {
                println!(
                    "  {name} {label}: {:.2} ms CPU",
                    (b - a) as f64 / 20.0 / 1e6
                );
            }
        };
        stage_cpu("vegetation", &mut || {
            vegetation_image(&view, &opts.vegetation, true, &mut veg).unwrap();
        });
        stage_cpu("smooth", &mut || {
            gauss
                .apply(&veg.data, veg.width, veg.height, &mut tmp, &mut sm.data)
                .unwrap();
        });
        stage_cpu("threshold", &mut || {
            keep_brightest(&sm.data, &mask, &opts.threshold, &mut kept).unwrap();
        });
        stage_cpu("prepare", &mut || {
            prep.run(&view, &mut points).unwrap();
        });
        stage_cpu("hough", &mut || {
            rows.clear();
            hough
                .find_rows(&points.rays, &points.weights, &mut rows)
                .unwrap();
        });
        stage_cpu("refit", &mut || {
            prep.refit(&mut rows2, &bands, vp0.as_ref()).unwrap();
        });
        stage_cpu("vanishing", &mut || {
            vs.run(None, &mut d2).unwrap();
        });
        stage_cpu("whole", &mut || {
            det.process(&view, &mut out).unwrap();
        });
    }
}

/// The prior the pipeline hands the detector while tracking: the last vanishing point in a
/// window of 2° (`pipeline.narrow_min_window_deg`).
fn narrow_prior(last: &Detection) -> DetectorPrior {
    DetectorPrior {
        vanishing_point: last.vanishing_point.expect("rows found").direction,
        window_rad: 2f64.to_radians(),
    }
}

/// A 640×480 perspective camera (f = 375 px, 35° below the horizon) and a colour field
/// through it.
fn small_frame() -> (omnirow::camera::Calibration, Vec<u8>) {
    use omnirow::synth::{Renderer, Scene, Style, SynthOptions};
    let toml = "[pinhole]\nwidth = 640\nheight = 480\nfx = 375.0\nfy = 375.0\ncx = 319.5\n\
                cy = 239.5\n\n[mounting]\npitch_deg = -55.0\n";
    let cal =
        omnirow::camera::Calibration::parse_toml(toml, std::path::Path::new("640.toml")).unwrap();
    let opts = SynthOptions {
        style: Style::Colour,
        yaw_deg: 4.0,
        lateral_m: 0.1,
        height_m: 1.0,
        ..Default::default()
    };
    let scene = Scene::new(&opts, 3, &cal.mounting).unwrap();
    let mut r = Renderer::new(&cal).unwrap();
    let mut data = vec![0u8; r.buffer_len(Style::Colour)];
    r.render_into(&scene, &mut data).unwrap();
    (cal, data)
}

/// The default detector (`auto`: the strips method for this perspective lens; also on two
/// threads), the combined and the Hough method on a 640×480 RGB frame, each with and without
/// the prior (the pencil and the strips ignore it); prints each one's thread CPU time per
/// frame.
fn bench_small(c: &mut Criterion) {
    let (cal, data) = small_frame();
    let view = ImageView::new(640, 480, PixelFormat::Rgb8, &data).unwrap();
    let mut g = c.benchmark_group("detector_640x480");
    g.sample_size(20).measurement_time(Duration::from_secs(3));
    for method in [Method::Auto, Method::Combined, Method::Hough] {
        let opts = DetectorOptions {
            method,
            ..Default::default()
        };
        let mut det = Detector::new(&cal, opts.clone()).unwrap();
        let mut out = Detection::default();
        det.process(&view, &mut out).unwrap();
        let prior = narrow_prior(&out);
        let name = method.name();
        g.bench_function(name, |b| b.iter(|| det.process(&view, &mut out).unwrap()));
        if method == Method::Auto {
            let mut two = Detector::new(&cal, opts.clone()).unwrap();
            two.set_threads(2).unwrap();
            two.process(&view, &mut out).unwrap();
            g.bench_function(format!("{name}_2_threads"), |b| {
                b.iter(|| two.process(&view, &mut out).unwrap())
            });
        }
        g.bench_function(format!("{name}_narrowed"), |b| {
            b.iter(|| {
                det.process_with_prior(&view, Some(&prior), &mut out)
                    .unwrap()
            })
        });
        for (label, p) in [("full", None), ("narrowed", Some(&prior))] {
            let a = thread_cpu_ns();
            for _ in 0..30 {
                det.process_with_prior(&view, p, &mut out).unwrap();
            }
            if let (Some(a), Some(b)) = (a, thread_cpu_ns()) {
                println!(
                    "640x480 {name} {label}: {:.2} ms CPU per frame ({:?}, {} rows)",
                    (b - a) as f64 / 30.0 / 1e6,
                    det.last_prior(),
                    out.rows.len()
                );
            }
        }
    }
    g.finish();
}

/// CPU time of the calling thread, nanoseconds (Linux).
fn thread_cpu_ns() -> Option<u64> {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

criterion_group!(benches, bench_small, bench);
criterion_main!(benches);
