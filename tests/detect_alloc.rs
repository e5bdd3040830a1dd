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

#[test]
fn process_allocates_nothing_after_warm_up() {
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
        let mut frames = || {
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
        let found = match pool {
            Some(p) => p.install(frames),
            None => frames(),
        };
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
