//! Rendering with a photograph's ground allocates nothing once warmed up (a counting global
//! allocator): the texture is built once, each frame only samples it.

use omnirow::camera::ideal_fisheye;
use omnirow::synth::photo::{Photo, PhotoGround, PhotoOptions, RectifyOptions};
use omnirow::synth::{Renderer, Scene, Style, SynthOptions};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;

struct Counting;
static COUNTING: AtomicBool = AtomicBool::new(false);
static ALLOCS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.load(Ordering::Relaxed) {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if COUNTING.load(Ordering::Relaxed) {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// A 320×240 "photograph": a level pinhole (f 250) 1 m high looking 40° down along five
/// green rows 0.5 m apart on brown soil, drawn pixel by pixel, and the rows' centre lines.
fn photograph() -> (Vec<u8>, Vec<Vec<[f64; 2]>>) {
    let (w, h, f) = (320usize, 240usize, 250.0);
    let (cx, cy, pitch) = (159.5, 119.5, 40f64.to_radians());
    // Ground point of pixel (r, c): camera x right, y down, z forward, pitched down.
    let ground = |r: f64, c: f64| -> Option<(f64, f64)> {
        let (x, y) = ((c - cx) / f, (r - cy) / f);
        let down = y * pitch.cos() + pitch.sin();
        let fwd = pitch.cos() - y * pitch.sin();
        (down > 1e-6).then(|| (fwd / down, -x / down))
    };
    let mut data = vec![0u8; w * h * 3];
    for r in 0..h {
        for c in 0..w {
            let green = ground(r as f64, c as f64).is_some_and(|(_, y)| {
                let d = y / 0.5 - (y / 0.5).round();
                d.abs() < 0.12
            });
            let px = if green { [60, 160, 50] } else { [120, 90, 60] };
            data[(r * w + c) * 3..][..3].copy_from_slice(&px);
        }
    }
    // Row k at y = k·0.5: its image column on each scan line (where the ground point lies
    // on it), by bisection along the scan line.
    let rows = (-2..=2)
        .map(|k| {
            (60..h)
                .filter_map(|r| {
                    let y_at = |c: f64| ground(r as f64, c).map(|g| g.1);
                    let (mut lo, mut hi) = (-2000.0, 2000.0);
                    let target = k as f64 * 0.5;
                    for _ in 0..60 {
                        let mid = 0.5 * (lo + hi);
                        if y_at(mid)? > target {
                            lo = mid;
                        } else {
                            hi = mid;
                        }
                    }
                    let c = 0.5 * (lo + hi);
                    (0.0..w as f64 - 1.0).contains(&c).then_some([r as f64, c])
                })
                .collect()
        })
        .collect();
    (data, rows)
}

#[test]
fn rendering_a_photo_ground_allocates_nothing_after_warm_up() {
    let (data, rows) = photograph();
    let photo = Photo {
        width: 320,
        height: 240,
        channels: 3,
        data: &data,
    };
    let opts = PhotoOptions {
        rectify: RectifyOptions {
            focal_px: Some(250.0),
            ..Default::default()
        },
        ..Default::default()
    };
    let ground = Arc::new(PhotoGround::new(&photo, &rows, &opts).unwrap());
    assert!((ground.rectification().camera_height_m - 1.0).abs() < 0.01);
    let cal = ideal_fisheye(200, 240).unwrap();
    for style in [Style::Grey, Style::Colour, Style::Bayer] {
        let scenes: Vec<Scene> = (0..3)
            .map(|i| {
                let o = SynthOptions {
                    style,
                    yaw_deg: 5.0 * i as f64,
                    noise: 0.05,
                    ..Default::default()
                };
                Scene::new(&o, i, &cal.mounting)
                    .unwrap()
                    .with_photo_ground(ground.clone())
                    .unwrap()
            })
            .collect();
        let mut renderer = Renderer::new(&cal).unwrap().with_threads(1);
        let mut out = vec![0u8; renderer.buffer_len(style)];
        renderer.render_into(&scenes[0], &mut out).unwrap();
        ALLOCS.store(0, Ordering::Relaxed);
        COUNTING.store(true, Ordering::Relaxed);
        for s in &scenes {
            renderer.render_into(s, &mut out).unwrap();
        }
        COUNTING.store(false, Ordering::Relaxed);
        assert_eq!(ALLOCS.load(Ordering::Relaxed), 0, "{style:?}");
        // The photograph's green rows reach the image.
        if style == Style::Colour {
            let green = out.chunks_exact(3).filter(|p| p[1] > p[0] + 40).count();
            assert!(green > 1000, "{green}");
        }
    }
}
