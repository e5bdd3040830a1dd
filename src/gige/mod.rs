//! GigE Vision acquisition: the Prosilica GC2450C (or any GenICam camera) through Aravis.
//!
//! Owns the camera source of the node: the `[gige]` configuration ([`GigeConfig`]), the live
//! counters and camera state ([`GigeCounters`]), the camera-to-host clock mapping
//! ([`CameraClock`]), the recycling of frame buffers ([`FramePool`]), and — with the cargo
//! feature `camera`, which links libaravis 0.8 — discovery ([`list_cameras`]), configuration,
//! real-time scheduling, and the acquisition thread ([`GigeSource`]) that survives packet loss
//! and camera loss. Frames leave as [`crate::frame::Frame`] through a channel or a callback.
//!
//! Without the feature the configuration, counters, clock and pool still build, so a
//! configuration can be checked on any machine.

mod clock;
mod config;
mod counters;
mod pool;

pub use clock::{CameraClock, CameraClockOptions};
pub use config::{
    AutoOr, AutoWord, GigeConfig, GigeConfigError, GigeConfigParseError, GigePixelFormat, Roi,
    StreamConfig,
};
pub use counters::{block_id_step, CameraState, GigeCounters, GigeSnapshot};
pub use pool::{FramePool, Recycler, Taken};

#[cfg(feature = "camera")]
mod acquire;
#[cfg(feature = "camera")]
mod device;
#[cfg(feature = "camera")]
pub mod rt;

#[cfg(feature = "camera")]
pub use acquire::{FrameSink, GigeSource, OnConnect};
/// The Aravis bindings, for code that needs the camera object (e.g. an [`OnConnect`] hook).
#[cfg(feature = "camera")]
pub use aravis;
/// The raw libaravis bindings, for what the safe bindings lack (e.g. the fake camera's fill
/// pattern).
#[cfg(feature = "camera")]
pub use aravis_sys;
#[cfg(feature = "camera")]
pub use device::{enable_interface, list_cameras, matches, CameraInfo, SessionInfo};

/// Errors of the GigE source.
#[derive(Debug, thiserror::Error)]
pub enum GigeError {
    #[error(transparent)]
    Config(#[from] GigeConfigError),
    #[error("{}", not_found_message(.wanted, .found))]
    NotFound {
        wanted: Option<String>,
        found: Vec<String>,
    },
    #[error("camera does not offer pixel format {wanted}; it offers: {}", .offered.join(", "))]
    PixelFormatUnavailable {
        wanted: String,
        offered: Vec<String>,
    },
    #[error("camera rejected {what}: asked for {wanted}, got {got}")]
    Rejected {
        what: String,
        wanted: String,
        got: String,
    },
    #[error("Aravis: {what}: {message}")]
    Aravis { what: String, message: String },
    #[error("cannot start the acquisition thread: {0}")]
    Spawn(std::io::Error),
}

fn not_found_message(wanted: &Option<String>, found: &[String]) -> String {
    let list = if found.is_empty() {
        "no camera found".to_string()
    } else {
        format!("cameras found: {}", found.join("; "))
    };
    match wanted {
        Some(w) => format!("camera {w:?} not found or not answering ({list})"),
        None => format!("no camera to open ({list})"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_say_what_is_wrong() {
        let e = GigeError::PixelFormatUnavailable {
            wanted: "BayerRG8".into(),
            offered: vec!["Mono8".into(), "Mono16".into()],
        };
        assert_eq!(
            e.to_string(),
            "camera does not offer pixel format BayerRG8; it offers: Mono8, Mono16"
        );
        let e = GigeError::NotFound {
            wanted: Some("123".into()),
            found: vec![],
        };
        assert!(e.to_string().contains("\"123\" not found"), "{e}");
        assert!(e.to_string().contains("no camera found"), "{e}");
    }
}
