//! The acquisition path with Aravis's in-process "Fake" interface (no network, no process):
//! frames stream through, and buffers that Aravis reports short never reach the sink. Also: a
//! camera that is not there never stops the source.
#![cfg(feature = "camera")]

use omnirow::frame::PixelFormat;
use omnirow::gige::aravis::glib::prelude::Cast;
use omnirow::gige::aravis::glib::translate::ToGlibPtr;
use omnirow::gige::aravis::prelude::*;
use omnirow::gige::{
    aravis, aravis_sys, enable_interface, CameraState, FrameSink, GigeConfig, GigePixelFormat,
    GigeSource, OnConnect, Roi,
};
use std::ffi::c_void;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

const W: u32 = 1024;
const H: u32 = 768;

/// A deterministic 8-bit Bayer RGGB mosaic: plant-like stripes on a textured background.
fn injected_image() -> Vec<u8> {
    let mut v = Vec::with_capacity((W * H) as usize);
    for r in 0..H {
        for c in 0..W {
            let stripe = ((c as i64 - r as i64 / 3).rem_euclid(96) < 20) as u32;
            let green_site = (r + c) % 2 == 1;
            let base = (r * 7 + c * 13) % 61;
            let v8 = if stripe == 1 && green_site {
                200 + base % 50
            } else {
                40 + base
            };
            v.push(v8 as u8);
        }
    }
    v
}

/// Fill-pattern callback: copies the injected image into the fake camera's buffer.
unsafe extern "C" fn fill(
    buffer: *mut aravis_sys::ArvBuffer,
    data: *mut c_void,
    _exposure_us: u32,
    _gain: u32,
    _format: aravis_sys::ArvPixelFormat,
) {
    // SAFETY: `data` is the leaked image (lives for the whole process); Aravis hands a valid
    // buffer that the fake camera checked to hold at least width x height bytes, which is the
    // image's size (the test configures that region).
    let img: &Vec<u8> = &*(data as *const Vec<u8>);
    let w = aravis_sys::arv_buffer_get_image_width(buffer).max(0) as usize;
    let h = aravis_sys::arv_buffer_get_image_height(buffer).max(0) as usize;
    let mut size = 0usize;
    let dst = aravis_sys::arv_buffer_get_data(buffer, &mut size);
    if !dst.is_null() && w * h == img.len() {
        std::ptr::copy_nonoverlapping(img.as_ptr(), dst, img.len());
    }
}

/// The fake camera of the current session (a leaked reference), set by the connect hook.
static FAKE_CAMERA: AtomicUsize = AtomicUsize::new(0);

/// Two phases. (1) The fake camera's built-in pattern streams through the source with the
/// configured geometry. (2) An image is injected with the fake camera's fill-pattern callback:
/// libaravis 0.8.26 then reports the buffer's received size as 0 bytes, because only its
/// built-in pattern sets that private field (`received_size`) and there is no public setter.
/// Those buffers look exactly like short frames from a real camera, and must be counted as
/// incomplete and never reach the sink. (So with this libaravis an injected image cannot
/// travel the whole path to a published estimate.)
#[test]
fn fake_camera_streams_and_short_buffers_never_reach_the_sink() {
    // RUST_LOG=omnirow=debug shows every dropped buffer.
    let _ = tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_test_writer()
        .try_init();
    enable_interface("Fake");
    let image: &'static Vec<u8> = Box::leak(Box::new(injected_image()));
    let hook: OnConnect = Box::new(move |camera: &aravis::Camera| {
        let device = camera.device().expect("device");
        let fake = device
            .downcast::<aravis::FakeDevice>()
            .expect("the Fake interface's device")
            .fake_camera()
            .expect("its fake camera");
        let raw: *mut aravis_sys::ArvFakeCamera = fake.to_glib_none().0;
        std::mem::forget(fake); // keep a reference: the test thread uses the pointer later
        FAKE_CAMERA.store(raw as usize, Ordering::Release);
    });
    let buffers = 4;
    let cfg = GigeConfig {
        camera: Some("Fake_1".into()),
        pixel_format: GigePixelFormat::BayerRG8,
        roi: Some(Roi {
            x: 0,
            y: 0,
            width: W,
            height: H,
        }),
        frame_rate: Some(30.0),
        buffers,
        realtime: false,
        ..GigeConfig::default()
    };
    let (tx, rx) = crossbeam_channel::bounded(8);
    let src = GigeSource::start_with(cfg, FrameSink::Channel(tx), Some(hook)).unwrap();
    let next = || {
        rx.recv_timeout(Duration::from_secs(10))
            .unwrap_or_else(|e| {
                panic!(
                    "no frame from the fake camera ({e}): {:?}",
                    src.counters().snapshot()
                )
            })
    };
    // Built-in pattern: complete frames of the configured geometry.
    for _ in 0..3 * buffers {
        let f = next();
        assert_eq!(
            (f.width, f.height, f.format),
            (W, H, PixelFormat::BayerRggb8)
        );
        assert!(f.data.iter().any(|&b| b != f.data[0]), "flat image");
        assert!(f.capture_ns > 0 && f.receive_ns >= f.capture_ns);
        src.recycler().recycle(f.data);
    }
    let raw = FAKE_CAMERA.load(Ordering::Acquire) as *mut aravis_sys::ArvFakeCamera;
    assert!(!raw.is_null());
    // SAFETY: `raw` is a fake camera we hold a reference to; the callback data is a leaked
    // Vec that lives for the whole process; Aravis guards the pattern with its own mutex.
    unsafe {
        aravis_sys::arv_fake_camera_set_fill_pattern(
            raw,
            Some(fill),
            image as *const Vec<u8> as *mut c_void,
        )
    };
    // Frames already in the channel may carry the built-in pattern; none may carry the
    // injected image, which arrives with 0 received bytes.
    let incomplete_before = src.counters().snapshot().incomplete;
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(2) {
        if let Ok(f) = rx.recv_timeout(Duration::from_millis(100)) {
            assert!(f.data != *image, "a short buffer reached the sink");
            src.recycler().recycle(f.data);
        }
    }
    let s = src.counters().snapshot();
    println!("after injection: {s:?}");
    assert!(
        s.incomplete >= incomplete_before + 20,
        "short buffers not counted as incomplete: {s:?}"
    );
    assert_eq!(s.state, CameraState::Streaming);
    assert_eq!(s.missing, 0);
    assert!(s.frame_allocations <= 8, "{s:?}");
    src.stop();
}

#[test]
fn absent_camera_keeps_the_source_trying() {
    let cfg = GigeConfig {
        camera: Some("no-such-camera-omnirow-test".into()),
        reconnect_initial_ms: 50,
        reconnect_max_ms: 100,
        realtime: false,
        ..GigeConfig::default()
    };
    let (tx, _rx) = crossbeam_channel::bounded(1);
    let src = GigeSource::start(cfg, FrameSink::Channel(tx)).unwrap();
    let c = src.counters();
    let t0 = Instant::now();
    while c.snapshot().connect_failures < 3 && t0.elapsed() < Duration::from_secs(20) {
        std::thread::sleep(Duration::from_millis(20));
    }
    let s = c.snapshot();
    assert!(s.connect_failures >= 3, "{s:?}");
    assert_eq!(s.state, CameraState::Connecting);
    assert!(src.is_running());
    let t = Instant::now();
    src.stop();
    assert!(
        t.elapsed() < Duration::from_secs(3),
        "stop took {:?}",
        t.elapsed()
    );
}
