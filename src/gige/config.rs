//! The `[gige]` configuration: which camera, how to set it up, and how to run its stream.
//!
//! Plain serde data with `deny_unknown_fields`, parsed and validated without libaravis so that
//! a configuration can be checked on any build. Every field has a default that suits the
//! Prosilica GC2450C on a dedicated jumbo-frame link.

use serde::{Deserialize, Serialize};
use std::time::Duration;

/// A setting that is either the camera's automatic mode or a fixed value.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum AutoOr<T> {
    /// The string `"auto"`.
    Auto(AutoWord),
    Fixed(T),
}

/// The literal word `auto`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AutoWord {
    Auto,
}

impl<T: Copy> AutoOr<T> {
    /// The fixed value, or None for auto.
    pub fn fixed(&self) -> Option<T> {
        match self {
            AutoOr::Auto(_) => None,
            AutoOr::Fixed(v) => Some(*v),
        }
    }
}

/// Pixel formats omnirow accepts from a camera (GenICam names).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum GigePixelFormat {
    /// 8-bit Bayer, R at (0,0): the GC2450C's colour format.
    BayerRG8,
    /// 8-bit grey.
    Mono8,
}

impl GigePixelFormat {
    /// The GenICam `PixelFormat` enumeration entry.
    pub fn genicam_name(self) -> &'static str {
        match self {
            GigePixelFormat::BayerRG8 => "BayerRG8",
            GigePixelFormat::Mono8 => "Mono8",
        }
    }

    /// The frame format the pipeline sees.
    pub fn frame_format(self) -> crate::frame::PixelFormat {
        match self {
            GigePixelFormat::BayerRG8 => crate::frame::PixelFormat::BayerRggb8,
            GigePixelFormat::Mono8 => crate::frame::PixelFormat::Mono8,
        }
    }
}

/// Region of interest on the sensor, in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Roi {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

/// The GigE Vision stream channel settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StreamConfig {
    /// GVSP packet size in bytes: `"auto"` negotiates the largest the path carries (needs the
    /// link's MTU raised to 9000 for jumbo frames), a number fixes it.
    pub packet_size: AutoOr<u32>,
    /// Prosilica `StreamBytesPerSecond` (bandwidth limit); set only when the camera has the
    /// feature. None leaves the camera's value.
    pub stream_bytes_per_second: Option<u64>,
    /// Receive socket buffer: `"auto"` sizes it to one frame, a number fixes it in bytes.
    /// Either way the kernel caps it at `net.core.rmem_max` (see udev/README.md).
    pub socket_buffer: AutoOr<u32>,
    /// Ask the camera to resend missing packets.
    pub packet_resend: bool,
    /// Use Aravis's packet socket (faster; needs CAP_NET_RAW; receives nothing on loopback
    /// when run as root, so the tests turn it off).
    pub packet_socket: bool,
    /// Aravis packet timeout, ms (None: Aravis's default).
    pub packet_timeout_ms: Option<u32>,
    /// Aravis frame retention, ms (None: Aravis's default).
    pub frame_retention_ms: Option<u32>,
}

impl Default for StreamConfig {
    fn default() -> Self {
        StreamConfig {
            packet_size: AutoOr::Auto(AutoWord::Auto),
            stream_bytes_per_second: None,
            socket_buffer: AutoOr::Auto(AutoWord::Auto),
            packet_resend: true,
            packet_socket: true,
            packet_timeout_ms: None,
            frame_retention_ms: None,
        }
    }
}

/// How one GigE Vision camera is opened, configured and streamed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GigeConfig {
    /// Serial number, user id, IP address, MAC address or Aravis device id; None: the first
    /// camera found.
    pub camera: Option<String>,
    pub pixel_format: GigePixelFormat,
    /// None: the full sensor.
    pub roi: Option<Roi>,
    /// Exposure: `"auto"` (continuous) or a fixed time in microseconds. None: as the camera is.
    pub exposure_us: Option<AutoOr<f64>>,
    /// Gain: `"auto"` (continuous) or a fixed gain in dB. None: as the camera is.
    pub gain_db: Option<AutoOr<f64>>,
    /// Frame rate in Hz. None: as the camera is.
    pub frame_rate: Option<f64>,
    /// Number of preallocated stream buffers.
    pub buffers: u32,
    /// How long one pop waits for a frame, ms. None: max(1000, 3 frame periods).
    pub pop_timeout_ms: Option<u64>,
    /// Consecutive pop timeouts after which the camera counts as lost.
    pub lost_after_timeouts: u32,
    /// First reconnect delay, ms; doubles after each failure up to `reconnect_max_ms`.
    pub reconnect_initial_ms: u64,
    pub reconnect_max_ms: u64,
    /// Try SCHED_FIFO for the acquisition and stream threads (needs CAP_SYS_NICE).
    pub realtime: bool,
    /// SCHED_FIFO priority (1..=99).
    pub realtime_priority: i32,
    pub stream: StreamConfig,
}

impl Default for GigeConfig {
    fn default() -> Self {
        GigeConfig {
            camera: None,
            pixel_format: GigePixelFormat::BayerRG8,
            roi: None,
            exposure_us: None,
            gain_db: None,
            frame_rate: None,
            buffers: 8,
            pop_timeout_ms: None,
            lost_after_timeouts: 3,
            reconnect_initial_ms: 250,
            reconnect_max_ms: 5000,
            realtime: true,
            realtime_priority: 20,
            stream: StreamConfig::default(),
        }
    }
}

/// A configuration value that cannot work.
#[derive(Debug, thiserror::Error, PartialEq)]
#[error("gige.{key}: {problem}")]
pub struct GigeConfigError {
    pub key: &'static str,
    pub problem: String,
}

impl GigeConfig {
    /// Parses a TOML table holding exactly the `[gige]` keys, and validates it.
    pub fn from_toml(text: &str) -> Result<Self, GigeConfigParseError> {
        let cfg: GigeConfig = toml::from_str(text).map_err(GigeConfigParseError::Toml)?;
        cfg.validate().map_err(GigeConfigParseError::Invalid)?;
        Ok(cfg)
    }

    /// Checks the values that serde cannot: ranges and consistency.
    pub fn validate(&self) -> Result<(), GigeConfigError> {
        let bad = |key, problem: String| Err(GigeConfigError { key, problem });
        if self.buffers < 2 {
            return bad(
                "buffers",
                format!(
                    "{} < 2: the stream needs at least two buffers",
                    self.buffers
                ),
            );
        }
        if self.buffers > 256 {
            return bad("buffers", format!("{} > 256", self.buffers));
        }
        if let Some(r) = self.roi {
            if r.width == 0 || r.height == 0 {
                return bad("roi", format!("empty region {}x{}", r.width, r.height));
            }
        }
        if let Some(AutoOr::Fixed(e)) = self.exposure_us {
            if !(e.is_finite() && e > 0.0) {
                return bad("exposure_us", format!("{e} is not a positive time"));
            }
        }
        if let Some(AutoOr::Fixed(g)) = self.gain_db {
            if !g.is_finite() {
                return bad("gain_db", format!("{g} is not a number"));
            }
        }
        if let Some(f) = self.frame_rate {
            if !(f.is_finite() && f > 0.0) {
                return bad("frame_rate", format!("{f} is not a positive rate"));
            }
        }
        if self.pop_timeout_ms == Some(0) {
            return bad("pop_timeout_ms", "0 ms".into());
        }
        if self.lost_after_timeouts == 0 {
            return bad("lost_after_timeouts", "0: must be at least 1".into());
        }
        if self.reconnect_initial_ms == 0 || self.reconnect_max_ms < self.reconnect_initial_ms {
            return bad(
                "reconnect_initial_ms",
                format!(
                    "need 0 < reconnect_initial_ms ({}) <= reconnect_max_ms ({})",
                    self.reconnect_initial_ms, self.reconnect_max_ms
                ),
            );
        }
        if !(1..=99).contains(&self.realtime_priority) {
            return bad(
                "realtime_priority",
                format!("{} not in 1..=99", self.realtime_priority),
            );
        }
        if let AutoOr::Fixed(p) = self.stream.packet_size {
            // GVSP headers take 36 bytes on IPv4; the size register is 16 bits.
            if !(576..=65_500).contains(&p) {
                return bad("stream.packet_size", format!("{p} not in 576..=65500"));
            }
        }
        if self.stream.stream_bytes_per_second == Some(0) {
            return bad("stream.stream_bytes_per_second", "0".into());
        }
        if let AutoOr::Fixed(s) = self.stream.socket_buffer {
            if s < 65_536 || s > i32::MAX as u32 {
                return bad("stream.socket_buffer", format!("{s} not in 65536..=2^31-1"));
            }
        }
        Ok(())
    }

    /// The pop timeout actually used: the configured one, or max(1 s, 3 frame periods).
    pub fn effective_pop_timeout(&self) -> Duration {
        if let Some(ms) = self.pop_timeout_ms {
            return Duration::from_millis(ms);
        }
        let period_ms = self.frame_rate.map(|f| 1000.0 / f).unwrap_or(0.0);
        Duration::from_millis((3.0 * period_ms).max(1000.0).ceil() as u64)
    }

    /// Upper bound on the time from the last frame to state `camera_lost` when the camera
    /// goes silent: `lost_after_timeouts` pop timeouts (Aravis's control-lost signal, from
    /// its heartbeat, usually fires earlier).
    pub fn loss_detection_bound(&self) -> Duration {
        self.effective_pop_timeout() * self.lost_after_timeouts
    }
}

/// Error reading a `[gige]` table.
#[derive(Debug, thiserror::Error)]
pub enum GigeConfigParseError {
    #[error("gige config: {0}")]
    Toml(toml::de::Error),
    #[error(transparent)]
    Invalid(GigeConfigError),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid() {
        GigeConfig::default().validate().unwrap();
        let c = GigeConfig::from_toml("").unwrap();
        assert_eq!(c, GigeConfig::default());
    }

    #[test]
    fn full_table_parses() {
        let c = GigeConfig::from_toml(
            r#"
camera = "02-2141A-06123"
pixel_format = "Mono8"
roi = { x = 0, y = 2, width = 2448, height = 2048 }
exposure_us = 8000.0
gain_db = "auto"
frame_rate = 15.0
buffers = 6
[stream]
packet_size = 8228
stream_bytes_per_second = 115000000
socket_buffer = "auto"
packet_resend = false
packet_socket = false
"#,
        )
        .unwrap();
        assert_eq!(c.pixel_format, GigePixelFormat::Mono8);
        assert_eq!(c.exposure_us, Some(AutoOr::Fixed(8000.0)));
        assert_eq!(c.gain_db, Some(AutoOr::Auto(AutoWord::Auto)));
        assert_eq!(c.stream.packet_size.fixed(), Some(8228));
        assert!(c.stream.socket_buffer.fixed().is_none());
        assert!(!c.stream.packet_socket);
        assert_eq!(c.roi.unwrap().y, 2);
    }

    #[test]
    fn unknown_key_is_named() {
        let e = GigeConfig::from_toml("camra = \"x\"")
            .unwrap_err()
            .to_string();
        assert!(e.contains("camra"), "{e}");
        let e = GigeConfig::from_toml("[stream]\npacket_sise = 9000")
            .unwrap_err()
            .to_string();
        assert!(e.contains("packet_sise"), "{e}");
    }

    #[test]
    fn bad_values_are_named() {
        for (text, key) in [
            ("buffers = 1", "buffers"),
            ("frame_rate = -3.0", "frame_rate"),
            ("exposure_us = 0.0", "exposure_us"),
            ("[stream]\npacket_size = 100", "stream.packet_size"),
            (
                "reconnect_initial_ms = 10\nreconnect_max_ms = 5",
                "reconnect_initial_ms",
            ),
        ] {
            let e = GigeConfig::from_toml(text).unwrap_err().to_string();
            assert!(e.contains(key), "{text}: {e}");
        }
        let e = GigeConfig::from_toml("pixel_format = \"RGB8\"")
            .unwrap_err()
            .to_string();
        assert!(e.contains("pixel_format") || e.contains("RGB8"), "{e}");
        let e = GigeConfig::from_toml("exposure_us = \"manual\"")
            .unwrap_err()
            .to_string();
        assert!(e.contains("exposure_us"), "{e}");
    }

    #[test]
    fn pop_timeout_follows_frame_rate() {
        let mut c = GigeConfig::default();
        assert_eq!(c.effective_pop_timeout(), Duration::from_millis(1000));
        c.frame_rate = Some(1.0);
        assert_eq!(c.effective_pop_timeout(), Duration::from_millis(3000));
        c.pop_timeout_ms = Some(200);
        assert_eq!(c.loss_detection_bound(), Duration::from_millis(600));
    }
}
