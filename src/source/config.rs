//! `[source]` and `[camera]` of the node's configuration: where frames come from, how long the
//! node runs, and which calibration and frame id the frames go with.
//!
//! Owns the raw sections (every value with its span), their checks, and the typed
//! [`SourceConfig`] and [`CalibrationChoice`] the node is assembled from. The synthetic
//! drive's own keys (`[source.synthetic]`) are checked in [`super::synthetic`], the camera's
//! (`[gige]`) in [`crate::gige`].

use super::synthetic::{RawSynthetic, SyntheticConfig};
use super::Rate;
use crate::camera::IdealLens;
use crate::check::{Check, Raw};
use crate::gige::GigeConfig;
use serde::Deserialize;
use std::path::PathBuf;
use std::time::Duration;

/// Where frames come from.
#[derive(Debug, Clone, PartialEq)]
pub enum SourceConfig {
    /// The synthetic drive (`[source.synthetic]`), through `[camera] calibration` when it
    /// names a file or an ideal lens.
    Synthetic(SyntheticConfig),
    Replay(ReplayConfig),
    /// A GigE Vision camera through Aravis, configured by `[gige]` (needs the `camera`
    /// feature at run time; the configuration is checked on every build).
    Camera(GigeConfig),
}

/// Replay of a recording or an image folder.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayConfig {
    pub path: PathBuf,
    pub rate: Rate,
    pub looping: bool,
    pub topic: Option<String>,
    /// Frame rate of image folders (they carry no timestamps).
    pub fps: f64,
}

/// Which calibration the detector uses.
#[derive(Debug, Clone, PartialEq)]
pub enum CalibrationChoice {
    /// The source's own (the synthetic lens), or the ideal fisheye for replays.
    Auto,
    Ideal(IdealLens),
    File(PathBuf),
}

/// `[source]`, checked: the source and the limits of the run.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SourceSettings {
    pub source: SourceConfig,
    /// Stop after this many frames.
    pub max_frames: Option<u64>,
    /// Stop after this long.
    pub max_duration: Option<Duration>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
enum SourceKind {
    Synthetic,
    Replay,
    Camera,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
enum RateKind {
    Recorded,
    Max,
}

/// `[source]` as written.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSource {
    kind: Raw<SourceKind>,
    max_frames: Raw<u64>,
    max_duration_s: Raw<f64>,
    replay: Option<RawReplay>,
    synthetic: Option<RawSynthetic>,
}

/// `[source.replay]` as written.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawReplay {
    path: Raw<String>,
    rate: Raw<RateKind>,
    speed: Raw<f64>,
    #[serde(rename = "loop")]
    looping: Raw<bool>,
    topic: Raw<String>,
    fps: Raw<f64>,
}

/// `[camera]` as written.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawCamera {
    calibration: Raw<String>,
    frame_id: Raw<String>,
}

impl RawSource {
    /// Checks `[source]`; a camera source takes `gige` (`[gige]`, checked by itself).
    pub(crate) fn validate(self, gige: Option<&GigeConfig>, c: &mut Check) -> SourceSettings {
        let kind = c.get(&self.kind, SourceKind::Synthetic);
        let max_frames = c.get(&self.max_frames, 0);
        let max_duration_s = c.range("source.max_duration_s", &self.max_duration_s, 0.0, 0.0, 1e9);
        let source = match kind {
            SourceKind::Synthetic => {
                SourceConfig::Synthetic(self.synthetic.unwrap_or_default().validate(c))
            }
            SourceKind::Replay => {
                let replay = self.replay.unwrap_or_default();
                SourceConfig::Replay(replay.validate(self.kind.as_ref(), c))
            }
            SourceKind::Camera => SourceConfig::Camera(gige.cloned().unwrap_or_default()),
        };
        SourceSettings {
            source,
            max_frames: (max_frames > 0).then_some(max_frames),
            max_duration: (max_duration_s > 0.0).then(|| Duration::from_secs_f64(max_duration_s)),
        }
    }
}

impl RawReplay {
    /// Checks `[source.replay]`; `kind` is the `source.kind = "replay"` that asked for it.
    fn validate(self, kind: Option<&toml::Spanned<SourceKind>>, c: &mut Check) -> ReplayConfig {
        let path = match (&self.path, kind) {
            (Some(p), _) if !p.get_ref().is_empty() => PathBuf::from(p.get_ref()),
            (Some(p), _) => {
                c.bad(
                    "source.replay.path",
                    p,
                    "must name an MCAP file or an image folder",
                );
                PathBuf::new()
            }
            (None, Some(k)) => {
                c.bad(
                    "source.kind",
                    k,
                    "`replay` needs source.replay.path (an MCAP file or an image folder)",
                );
                PathBuf::new()
            }
            (None, None) => PathBuf::new(),
        };
        let speed = c.range("source.replay.speed", &self.speed, 1.0, 0.001, 1000.0);
        if let (Some(s), Some(RateKind::Max)) =
            (&self.speed, self.rate.as_ref().map(|r| *r.get_ref()))
        {
            c.bad(
                "source.replay.speed",
                s,
                "has no effect with rate = \"max\" (remove one of them)",
            );
        }
        ReplayConfig {
            path,
            rate: match c.get(&self.rate, RateKind::Recorded) {
                RateKind::Recorded => Rate::Recorded(speed),
                RateKind::Max => Rate::Max,
            },
            looping: c.get(&self.looping, false),
            topic: self
                .topic
                .as_ref()
                .map(|t| t.get_ref().clone())
                .filter(|t| !t.is_empty()),
            fps: c.range("source.replay.fps", &self.fps, 15.0, 0.01, 1000.0),
        }
    }
}

impl RawCamera {
    /// Checks `[camera]`: the calibration choice and the frame id.
    pub(crate) fn validate(self, c: &mut Check) -> (CalibrationChoice, String) {
        let calibration = match &self.calibration {
            None => CalibrationChoice::Auto,
            Some(s) => match s.get_ref().as_str() {
                "" | "auto" => CalibrationChoice::Auto,
                "ideal:fisheye185" => CalibrationChoice::Ideal(IdealLens::Fisheye185),
                "ideal:pal" => CalibrationChoice::Ideal(IdealLens::Pal),
                other if other.starts_with("ideal:") => {
                    c.bad(
                        "camera.calibration",
                        s,
                        format!("unknown ideal lens `{other}` (ideal:fisheye185 or ideal:pal)"),
                    );
                    CalibrationChoice::Auto
                }
                path => CalibrationChoice::File(PathBuf::from(path)),
            },
        };
        (
            calibration,
            c.get(&self.frame_id, "omnirow_camera".to_string()),
        )
    }
}
