//! The edge path allocates nothing once warmed up: a counting global allocator checks that a
//! second run on a frame of the same size makes no allocation, for Canny alone and for the
//! whole edge method.

use nalgebra::Vector3;
use omnirow::camera::{ideal_fisheye, Calibration};
use omnirow::detect::edge::{Canny, CannyParams, EdgeDetector, EdgeParams};

/// Standalone on an unsmoothed full-size image: smooth, and halve it as the detector would.
fn standalone() -> EdgeParams {
    EdgeParams {
        canny: CannyParams {
            sigma: 1.4,
            ..Default::default()
        },
        downsample: 2,
        ..Default::default()
    }
}
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        System.realloc(ptr, layout, new_size)
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Bright bands along rows converging to one vanishing point, with a little texture.
fn frame(cal: &Calibration) -> (Vec<u8>, Vec<u8>) {
    let m = &cal.model;
    let (w, h) = (m.width as usize, m.height as usize);
    let along = Vector3::new(0.9, 0.3, -0.2).normalize();
    let side = along.cross(&Vector3::z()).normalize();
    let plane = |a: f64| {
        along
            .cross(&(side * a.sin() + Vector3::z() * a.cos()))
            .normalize()
    };
    let bounds: Vec<_> = (-3..=3)
        .map(|k| {
            let a = 0.3 * k as f64;
            (plane(a - 0.04), plane(a + 0.04))
        })
        .collect();
    let mut img = vec![0u8; w * h];
    let mut mask = vec![0u8; w * h];
    let mut x = 12345u32;
    for r in 0..h {
        for c in 0..w {
            let p = m.cam2world(r as f64, c as f64);
            x = x.wrapping_mul(1664525).wrapping_add(1013904223);
            let band = bounds.iter().any(|(a, b)| a.dot(&p) * b.dot(&p) < 0.0);
            img[r * w + c] = if band { 180 } else { 40 } + (x >> 28) as u8;
            mask[r * w + c] = cal.pixel_in_fov(r as f64, c as f64) as u8;
        }
    }
    (img, mask)
}

#[test]
fn second_run_allocates_nothing() {
    let (w, h) = (640usize, 512usize);
    let cal = ideal_fisheye(h as u32, w as u32).unwrap();
    let (img, mask) = frame(&cal);
    let mut edges = vec![0u8; w * h];

    let mut canny = Canny::new(standalone().canny).unwrap();
    let first = canny.process(&img, w, h, &mask, &mut edges).unwrap();
    assert!(first.edge_pixels > 1000, "{first:?}");
    let before = ALLOCATIONS.load(Ordering::SeqCst);
    let second = canny.process(&img, w, h, &mask, &mut edges).unwrap();
    let canny_allocs = ALLOCATIONS.load(Ordering::SeqCst) - before;
    assert_eq!(first, second);
    assert_eq!(canny_allocs, 0, "Canny allocated on its second run");

    let mut det = EdgeDetector::new(&cal, w, h, standalone()).unwrap();
    let mut rows = Vec::new();
    let first = det.process(&img, &mask, &mut rows).unwrap();
    assert!(rows.len() >= 6, "{first:?}");
    let before = ALLOCATIONS.load(Ordering::SeqCst);
    let second = det.process(&img, &mask, &mut rows).unwrap();
    let edge_allocs = ALLOCATIONS.load(Ordering::SeqCst) - before;
    assert_eq!(first, second);
    assert_eq!(
        edge_allocs, 0,
        "the edge method allocated on its second run"
    );
}
