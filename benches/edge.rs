//! Speed of the edge method on a full GC2450C frame (2448×2050), one core: Canny alone and
//! the whole edge path (Canny, chains, split, merge), for both shipped lenses.
//!
//! Run: `cargo bench --bench edge`.

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::Vector3;
use omnirow::camera::{ideal_fisheye, ideal_pal, Calibration};
use omnirow::detect::edge::{Canny, CannyOptions, EdgeDetector, EdgeOptions};

/// Standalone on an unsmoothed full-size image: smooth, and halve it as the detector would.
fn standalone() -> EdgeOptions {
    EdgeOptions {
        canny: CannyOptions {
            sigma: 1.4,
            ..Default::default()
        },
        downsample: 2,
        ..Default::default()
    }
}
use std::hint::black_box;

const W: usize = 2448;
const H: usize = 2050;

/// Seven bright rows converging to one vanishing point on textured soil, and the lens mask.
fn frame(cal: &Calibration) -> (Vec<u8>, Vec<u8>) {
    let m = &cal.model;
    let along = Vector3::new(0.9, 0.3, -0.1).normalize();
    let side = along.cross(&Vector3::z()).normalize();
    let plane = |a: f64| {
        along
            .cross(&(side * a.sin() + Vector3::z() * a.cos()))
            .normalize()
    };
    let bounds: Vec<_> = (-3..=3)
        .map(|k| {
            let a = 0.3 * k as f64;
            (plane(a - 0.03), plane(a + 0.03))
        })
        .collect();
    let mut img = vec![0u8; W * H];
    let mut mask = vec![0u8; W * H];
    let mut x = 12345u32;
    for r in 0..H {
        for c in 0..W {
            let p = m.cam2world(r as f64, c as f64);
            x = x.wrapping_mul(1664525).wrapping_add(1013904223);
            let band = bounds.iter().any(|(a, b)| a.dot(&p) * b.dot(&p) < 0.0);
            img[r * W + c] = if band { 170 } else { 40 } + (x >> 27) as u8;
            mask[r * W + c] = cal.pixel_in_fov(r as f64, c as f64) as u8;
        }
    }
    (img, mask)
}

fn bench(c: &mut Criterion) {
    for (name, cal) in [
        ("fisheye", ideal_fisheye(H as u32, W as u32)),
        ("pal", ideal_pal(H as u32, W as u32)),
    ] {
        let (img, mask) = frame(&cal);
        let mut g = c.benchmark_group(format!("edge_{name}_2448x2050"));
        g.sample_size(20);
        let mut canny = Canny::new(standalone().canny).unwrap();
        let mut edges = vec![0u8; W * H];
        g.bench_function("canny", |b| {
            b.iter(|| {
                canny
                    .process(black_box(&img), W, H, &mask, &mut edges)
                    .unwrap()
            })
        });
        let mut det = EdgeDetector::new(&cal, W, H, standalone()).unwrap();
        let mut rows = Vec::new();
        let res = det.process(&img, &mask, &mut rows).unwrap();
        eprintln!("{name}: {res:?}, {} rows", rows.len());
        g.bench_function("edge_method", |b| {
            b.iter(|| det.process(black_box(&img), &mask, &mut rows).unwrap())
        });
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
