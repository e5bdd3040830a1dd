//! Fuzz the OCamCalib text parser: any bytes parse or give an error, and a parsed model's
//! projections never panic. Run: `cargo +nightly fuzz run ocamcalib_parse` from the crate root.
#![no_main]
use libfuzzer_sys::fuzz_target;
use omnirow::camera::OcamModel;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        if let Ok(m) = OcamModel::parse(text, Path::new("fuzz.txt")) {
            let ray = m.cam2world(0.0, 0.0);
            let _ = m.world2cam(&ray);
            let _ = m.rescaled(2.0);
        }
    }
});
