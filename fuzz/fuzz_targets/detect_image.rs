//! Fuzz images through `omnirow detect`: any bytes are decoded as `detect` decodes an image
//! file (PNG, JPEG, PNM) and detected with the ideal fisheye at the image's size; bytes that
//! are no image are detected as raw greyscale pixels. Either gives a detection or an error;
//! never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
use omnirow::camera::IdealLens;
use omnirow::detect::{Detection, Detector, DetectorOptions};
use omnirow::frame::{ImageView, PixelFormat};
use std::cell::RefCell;
use std::collections::HashMap;

/// Larger images only cost time: the detector's cost grows with the pixels, not its paths.
const MAX_SIDE: u32 = 160;

thread_local! {
    static DETECTORS: RefCell<HashMap<(u32, u32), Option<Detector>>> = RefCell::new(HashMap::new());
}

fn detect(width: u32, height: u32, format: PixelFormat, data: &[u8]) {
    let Ok(view) = ImageView::new(width, height, format, data) else {
        return;
    };
    DETECTORS.with(|d| {
        let mut d = d.borrow_mut();
        if d.len() > 64 {
            d.clear();
        }
        let det = d.entry((width, height)).or_insert_with(|| {
            // Sizes no ideal lens fits (a side under 16 px) are refused with an error.
            let cal = IdealLens::Fisheye185.calibration(height, width).ok()?;
            Detector::new(&cal, DetectorOptions::default()).ok()
        });
        if let Some(det) = det {
            let mut out = Detection::default();
            let _ = det.process(&view, &mut out);
        }
    });
}

fuzz_target!(|data: &[u8]| {
    let path = std::env::temp_dir().join(format!("omnirow-fuzz-{}.img", std::process::id()));
    let small = image::ImageReader::new(std::io::Cursor::new(data))
        .with_guessed_format()
        .ok()
        .and_then(|r| r.into_dimensions().ok())
        .is_some_and(|(w, h)| w <= MAX_SIDE && h <= MAX_SIDE);
    if small {
        std::fs::write(&path, data).expect("temporary file");
        let decoded = omnirow::cli::detect::decode(&path);
        let _ = std::fs::remove_file(&path);
        if let Ok(img) = decoded {
            detect(img.width, img.height, img.format, &img.data);
        }
        return;
    }
    // Raw greyscale: the first two bytes give the size, the rest the pixels.
    if data.len() >= 2 {
        let (w, h) = (u32::from(data[0] % 96) + 16, u32::from(data[1] % 96) + 16);
        let mut px = data[2..].to_vec();
        px.resize((w * h) as usize, 0);
        detect(w, h, PixelFormat::Mono8, &px);
    }
});
