//! The detector's hot path allocates nothing once warmed up (a counting global allocator).

mod common;

use omnirow::camera::ideal_fisheye;
use omnirow::detect::{Detection, Detector, DetectorOptions};
use omnirow::frame::{ImageView, PixelFormat};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

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

/// The tests count every thread's allocations: one runs at a time.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

#[test]
fn process_allocates_nothing_after_warm_up() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let cal = ideal_fisheye(400, 480).unwrap();
    let frames: Vec<_> = (0..4)
        .map(|i| {
            common::render_rows(
                &cal,
                0.3 * i as f64 - 0.4,
                0.02,
                3,
                0.75,
                0.05,
                1.0,
                0.1,
                0.02,
                i,
            )
        })
        .collect();
    // Bayer input too: the same frames as RGGB mosaics with green plants.
    let bayer: Vec<Vec<u8>> = frames
        .iter()
        .map(|f| {
            let w = f.width as usize;
            f.data
                .iter()
                .enumerate()
                .map(|(i, &v)| {
                    let (r, c) = (i / w, i % w);
                    if (r + c) % 2 == 1 {
                        v
                    } else {
                        v / 4
                    }
                })
                .collect()
        })
        .collect();
    for (format, datas, threads) in [
        (
            PixelFormat::Mono8,
            frames.iter().map(|f| f.data.clone()).collect::<Vec<_>>(),
            1,
        ),
        (PixelFormat::BayerRggb8, bayer.clone(), 1),
        // the frame's parts on two threads (the pool is built before the first frame)
        (PixelFormat::BayerRggb8, bayer, 2),
    ] {
        let mut det = Detector::new(&cal, DetectorOptions::default()).unwrap();
        det.set_threads(threads).unwrap();
        let pool = det.pool();
        let mut out = Detection::default();
        let views: Vec<ImageView> = datas
            .iter()
            .map(|d| ImageView::new(cal.model.width, cal.model.height, format, d).unwrap())
            .collect();
        for v in &views {
            det.process(v, &mut out).unwrap();
        }
        // frame after frame, as the node's worker does: on the detector's threads when it
        // has them
        let frames = || {
            ALLOCS.store(0, Ordering::SeqCst);
            COUNTING.store(true, Ordering::SeqCst);
            let mut found = 0;
            for _ in 0..40 {
                for v in &views {
                    det.process(v, &mut out).unwrap();
                    found += out.vanishing_point.is_some() as usize;
                }
            }
            COUNTING.store(false, Ordering::SeqCst);
            found
        };
        let found = on_pool(pool, frames);
        assert_eq!(
            ALLOCS.load(Ordering::SeqCst),
            0,
            "{format:?}, {threads} threads: allocations in the hot path"
        );
        assert!(
            found >= 120,
            "{format:?}: the frames have rows; found a VP in {found} of 160"
        );
    }
}

/// `f` on the detector's threads when it has them (as the node's worker runs), else here.
fn on_pool<R: Send>(
    pool: Option<std::sync::Arc<rayon::ThreadPool>>,
    f: impl FnOnce() -> R + Send,
) -> R {
    match pool {
        Some(p) => p.install(f),
        None => f(),
    }
}

/// The strips method (a forward-looking 640×480 pinhole, RGB frames of the synthetic field)
/// on one thread and on two: the search's candidates split across the threads allocate
/// nothing either once warm.
#[test]
fn strips_allocate_nothing_after_warm_up() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    use omnirow::synth::{Renderer, Scene, Style, SynthOptions};
    let toml = "[pinhole]\nwidth = 640\nheight = 480\nfx = 375.0\nfy = 375.0\ncx = 319.5\n\
                cy = 239.5\n\n[mounting]\npitch_deg = -55.0\n";
    let cal =
        omnirow::camera::Calibration::parse_toml(toml, std::path::Path::new("640.toml")).unwrap();
    let mut r = Renderer::new(&cal).unwrap();
    let datas: Vec<Vec<u8>> = [(-3.0, 0.05), (2.0, -0.1), (6.0, 0.15)]
        .iter()
        .map(|&(yaw_deg, lateral_m)| {
            let opts = SynthOptions {
                style: Style::Colour,
                yaw_deg,
                lateral_m,
                height_m: 1.0,
                ..Default::default()
            };
            let scene = Scene::new(&opts, 3, &cal.mounting).unwrap();
            let mut data = vec![0u8; r.buffer_len(Style::Colour)];
            r.render_into(&scene, &mut data).unwrap();
            data
        })
        .collect();
    let views: Vec<ImageView> = datas
        .iter()
        .map(|d| ImageView::new(640, 480, PixelFormat::Rgb8, d).unwrap())
        .collect();
    for threads in [1, 2] {
        let mut det = Detector::new(&cal, DetectorOptions::default()).unwrap();
        assert_eq!(det.options().method, omnirow::detect::Method::Strips);
        det.set_threads(threads).unwrap();
        let mut out = Detection::default();
        let pool = det.pool();
        let found = on_pool(pool, || {
            for v in &views {
                det.process(v, &mut out).unwrap();
            }
            ALLOCS.store(0, Ordering::SeqCst);
            COUNTING.store(true, Ordering::SeqCst);
            let mut found = 0;
            for _ in 0..10 {
                for v in &views {
                    det.process(v, &mut out).unwrap();
                    found += out.vanishing_point.is_some() as usize;
                }
            }
            COUNTING.store(false, Ordering::SeqCst);
            found
        });
        assert_eq!(
            ALLOCS.load(Ordering::SeqCst),
            0,
            "strips, {threads} threads: allocations in the hot path"
        );
        assert_eq!(
            found, 30,
            "strips, {threads} threads: a vanishing point in every frame"
        );
    }
}
