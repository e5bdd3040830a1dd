//! Fuzz omnirow's TOML calibration parser. Run: `cargo +nightly fuzz run calibration_toml`.
#![no_main]
use libfuzzer_sys::fuzz_target;
use omnirow::camera::Calibration;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        if let Ok(c) = Calibration::parse_toml(text, Path::new("fuzz.toml")) {
            let _ = c.worst_round_trip_px(64);
        }
    }
});
