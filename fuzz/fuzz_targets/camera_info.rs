//! Fuzz the ROS `camera_info` YAML conversion (`omnirow calib from-camera-info`): any text is
//! parsed as camera_calibration's file or a CameraInfo message, and a parsed camera is
//! converted into omnirow's Taylor calibration. Either gives a calibration or an error naming
//! the problem; never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
use omnirow::camera::{camera_info, Mounting};
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(pinhole) = camera_info::parse(text, Path::new("fuzz.yaml")) {
        if let Ok((cal, _)) = pinhole.to_calibration(None, Mounting::default()) {
            let _ = cal.worst_round_trip_px(16);
        }
    }
});
