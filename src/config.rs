//! The node's TOML configuration (config/omnirow.toml documents every key).
//!
//! Owns parsing (serde with `deny_unknown_fields`, every value kept with its position) and
//! validation of the raw file into the typed [`Config`]. An unknown key, a wrong type or an
//! impossible value is a [`ConfigError`] naming the file, the line and the key; all problems
//! found by validation are reported at once. Every key is optional: a missing key takes the
//! default that `config/omnirow.toml` shows.

use crate::camera::IdealLens;
use crate::detect::DetectorOptions;
use crate::gige::GigeConfig;
use crate::guidance::{GuidanceConfig, GuidanceOptions};
use crate::pipeline::PipelineOptions;
use crate::record::RecordOptions;
use crate::ros2::Ros2Config;
use crate::source::synthetic::SyntheticDriveOptions;
use crate::source::Rate;
use serde::Deserialize;
use std::fmt;
use std::net::{Ipv4Addr, SocketAddr};
use std::path::{Path, PathBuf};
use std::time::Duration;
use toml::Spanned;

/// One problem in a configuration file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    /// 1-based line (0 when the problem has no position).
    pub line: usize,
    /// The dotted key, e.g. `pipeline.frame_queue`.
    pub key: String,
    pub message: String,
}

/// A configuration that cannot be used: every problem found, with its line and key.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfigError {
    pub file: String,
    pub problems: Vec<Problem>,
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, p) in self.problems.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            if p.line > 0 {
                write!(f, "{}:{}: `{}`: {}", self.file, p.line, p.key, p.message)?;
            } else {
                write!(f, "{}: `{}`: {}", self.file, p.key, p.message)?;
            }
        }
        Ok(())
    }
}

impl std::error::Error for ConfigError {}

// ---------------------------------------------------------------------------------------
// Typed configuration.

/// Where frames come from.
#[derive(Debug, Clone, PartialEq)]
pub enum SourceConfig {
    /// The synthetic drive (`[source.synthetic]`).
    Synthetic(SyntheticDriveOptions),
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

/// When estimates are printed on stdout.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StdoutMode {
    /// When stdout is a terminal.
    Auto,
    Always,
    Never,
}

/// Log format on stderr.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LogFormat {
    Human,
    Json,
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

/// The whole, validated configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    pub source: SourceConfig,
    pub max_frames: Option<u64>,
    pub max_duration: Option<Duration>,
    pub calibration: CalibrationChoice,
    pub frame_id: String,
    pub pipeline: PipelineOptions,
    pub workers: usize,
    pub udp: Vec<SocketAddr>,
    pub multicast_ttl: u32,
    pub multicast_loop: bool,
    pub multicast_interface: Ipv4Addr,
    pub stdout: StdoutMode,
    pub http: Option<SocketAddr>,
    /// Recording, when `[record] enabled = true`.
    pub record: Option<RecordOptions>,
    /// The `[record]` settings whether enabled or not (what `omnirow record` uses).
    pub record_options: RecordOptions,
    pub log_format: LogFormat,
    pub log_level: String,
    /// The detector's options (`[detector]`, see `omnirow detect`).
    pub detector: DetectorOptions,
    /// ROS 2 publishing (`[ros2]`, docs/ros2.md); off unless `enabled = true`.
    pub ros2: Ros2Config,
    /// Row guidance (`[guidance]`, docs/guidance.md); `None` with `enabled = false`.
    pub guidance: Option<GuidanceOptions>,
}

impl Default for Config {
    fn default() -> Self {
        Config::parse("", "<defaults>").expect("the empty configuration is valid")
    }
}

// ---------------------------------------------------------------------------------------
// Raw configuration: what the file says, with positions.

type S<T> = Option<Spanned<T>>;

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    source: Option<RawSource>,
    camera: Option<RawCamera>,
    pipeline: Option<RawPipeline>,
    publish: Option<RawPublish>,
    http: Option<RawHttp>,
    record: Option<RawRecord>,
    log: Option<RawLog>,
    detector: Option<DetectorOptions>,
    gige: Option<GigeConfig>,
    ros2: Option<Ros2Config>,
    guidance: Option<GuidanceConfig>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSource {
    kind: S<SourceKind>,
    max_frames: S<u64>,
    max_duration_s: S<f64>,
    replay: Option<RawReplay>,
    synthetic: Option<RawSynthetic>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawReplay {
    path: S<String>,
    rate: S<RateKind>,
    speed: S<f64>,
    #[serde(rename = "loop")]
    looping: S<bool>,
    topic: S<String>,
    fps: S<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSynthetic {
    fps: S<f64>,
    width: S<u32>,
    height: S<u32>,
    lens: S<IdealLens>,
    colour: S<bool>,
    seed: S<u64>,
    speed_mps: S<f64>,
    heading_amplitude_deg: S<f64>,
    pitch_amplitude_deg: S<f64>,
    offset_amplitude_m: S<f64>,
    period_s: S<f64>,
    cross_at_s: S<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCamera {
    calibration: S<String>,
    frame_id: S<String>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPipeline {
    frame_queue: S<i64>,
    estimate_queue: S<i64>,
    record_queue: S<i64>,
    workers: S<i64>,
    min_quality: S<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPublish {
    udp: S<Vec<Spanned<String>>>,
    multicast_ttl: S<i64>,
    multicast_loop: S<bool>,
    multicast_interface: S<String>,
    stdout: S<StdoutMode>,
    status_interval_s: S<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawHttp {
    enabled: S<bool>,
    listen: S<String>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRecord {
    enabled: S<bool>,
    dir: S<String>,
    prefix: S<String>,
    frames: S<bool>,
    rotate_mb: S<i64>,
    rotate_s: S<f64>,
    reserve_mb: S<i64>,
    sync_interval_ms: S<i64>,
    json_channels: S<crate::record::JsonChannels>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLog {
    format: S<LogFormat>,
    level: S<String>,
}

/// Collects validation problems with the line of each key.
struct Check<'a> {
    text: &'a str,
    problems: Vec<Problem>,
}

impl Check<'_> {
    fn line(&self, offset: usize) -> usize {
        line_of(self.text, offset)
    }

    fn bad<T>(&mut self, key: &str, v: &Spanned<T>, message: impl Into<String>) {
        self.problems.push(Problem {
            line: self.line(v.span().start),
            key: key.into(),
            message: message.into(),
        });
    }

    /// The value, or the default when absent.
    fn get<T: Clone>(&self, v: &S<T>, default: T) -> T {
        v.as_ref().map(|s| s.get_ref().clone()).unwrap_or(default)
    }

    /// A number in `lo..=hi`.
    fn range<T>(&mut self, key: &str, v: &S<T>, default: T, lo: T, hi: T) -> T
    where
        T: Copy + PartialOrd + fmt::Display,
    {
        match v {
            None => default,
            Some(s) => {
                let x = *s.get_ref();
                // `!(lo <= x && x <= hi)` also rejects NaN.
                if !(lo <= x && x <= hi) {
                    self.bad(key, s, format!("{x} is out of range ({lo} ..= {hi})"));
                    default
                } else {
                    x
                }
            }
        }
    }

    fn addr(&mut self, key: &str, v: &Spanned<String>) -> Option<SocketAddr> {
        match v.get_ref().parse::<SocketAddr>() {
            Ok(a) => Some(a),
            Err(_) => {
                self.bad(
                    key,
                    v,
                    format!(
                        "`{}` is not an address:port (e.g. 127.0.0.1:7447 or [::1]:7447)",
                        v.get_ref()
                    ),
                );
                None
            }
        }
    }
}

/// The 1-based line of the first `[name]` or `[name.…]` header (0 when absent): nested tables
/// parsed as whole structs carry no positions, so their problems point at their header.
fn header_line(text: &str, name: &str) -> usize {
    text.lines()
        .position(|l| {
            let t = l.trim_start();
            t.strip_prefix('[')
                .and_then(|r| r.trim_start().strip_prefix(name))
                .is_some_and(|r| r.trim_start().starts_with([']', '.']))
        })
        .map_or(0, |i| i + 1)
}

fn line_of(text: &str, offset: usize) -> usize {
    text.as_bytes()[..offset.min(text.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// The dotted key written on `line` (1-based), with the table header above it.
fn key_at_line(text: &str, line: usize) -> String {
    let mut table = String::new();
    for (i, l) in text.lines().enumerate() {
        let t = l.trim();
        if i + 1 == line {
            if t.starts_with('[') {
                return t.trim_matches(|c| c == '[' || c == ']').trim().to_string();
            }
            let key = t.split('=').next().unwrap_or("").trim().trim_matches('"');
            return if table.is_empty() {
                key.to_string()
            } else {
                format!("{table}.{key}")
            };
        }
        if t.starts_with('[') && !t.starts_with("[[") {
            table = t
                .split(']')
                .next()
                .unwrap_or("")
                .trim_start_matches('[')
                .trim()
                .to_string();
        }
    }
    String::new()
}

impl Config {
    /// Reads and validates a configuration file.
    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|e| ConfigError {
            file: path.display().to_string(),
            problems: vec![Problem {
                line: 0,
                key: String::new(),
                message: format!("cannot read: {e}"),
            }],
        })?;
        Config::parse(&text, &path.display().to_string())
    }

    /// Parses and validates configuration text; `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<Config, ConfigError> {
        let raw: RawConfig = toml::from_str(text).map_err(|e| {
            let line = e.span().map(|s| line_of(text, s.start)).unwrap_or(0);
            let message = e.message().trim().to_string();
            ConfigError {
                file: file.to_string(),
                problems: vec![Problem {
                    line,
                    key: if line > 0 {
                        key_at_line(text, line)
                    } else {
                        String::new()
                    },
                    message,
                }],
            }
        })?;
        let mut c = Check {
            text,
            problems: Vec::new(),
        };
        let cfg = validate(raw, &mut c);
        if c.problems.is_empty() {
            Ok(cfg)
        } else {
            Err(ConfigError {
                file: file.to_string(),
                problems: c.problems,
            })
        }
    }
}

fn validate(raw: RawConfig, c: &mut Check) -> Config {
    let src = raw.source.unwrap_or_default();
    let rep = src.replay.unwrap_or_default();
    let syn = src.synthetic.unwrap_or_default();
    let cam = raw.camera.unwrap_or_default();
    let pip = raw.pipeline.unwrap_or_default();
    let publ = raw.publish.unwrap_or_default();
    let http = raw.http.unwrap_or_default();
    let rec = raw.record.unwrap_or_default();
    let log = raw.log.unwrap_or_default();

    let kind = c.get(&src.kind, SourceKind::Synthetic);
    let max_frames = c.get(&src.max_frames, 0);
    let max_duration_s = c.range("source.max_duration_s", &src.max_duration_s, 0.0, 0.0, 1e9);

    let source = match kind {
        SourceKind::Synthetic => {
            let width = c.range("source.synthetic.width", &syn.width, 612, 32, 8192);
            let height = c.range("source.synthetic.height", &syn.height, 512, 32, 8192);
            for (k, v, x) in [
                ("source.synthetic.width", &syn.width, width),
                ("source.synthetic.height", &syn.height, height),
            ] {
                if let Some(s) = v {
                    if x % 2 != 0 {
                        c.bad(k, s, format!("{x} must be even (Bayer quads)"));
                    }
                }
            }
            SourceConfig::Synthetic(SyntheticDriveOptions {
                fps: c.range("source.synthetic.fps", &syn.fps, 15.0, 0.1, 1000.0),
                width,
                height,
                lens: c.get(&syn.lens, IdealLens::Fisheye185),
                colour: c.get(&syn.colour, true),
                seed: c.get(&syn.seed, 1),
                speed_mps: c.range("source.synthetic.speed_mps", &syn.speed_mps, 1.0, 0.0, 20.0),
                heading_amplitude_deg: c.range(
                    "source.synthetic.heading_amplitude_deg",
                    &syn.heading_amplitude_deg,
                    8.0,
                    0.0,
                    45.0,
                ),
                pitch_amplitude_deg: c.range(
                    "source.synthetic.pitch_amplitude_deg",
                    &syn.pitch_amplitude_deg,
                    3.0,
                    0.0,
                    15.0,
                ),
                offset_amplitude_m: c.range(
                    "source.synthetic.offset_amplitude_m",
                    &syn.offset_amplitude_m,
                    0.1,
                    0.0,
                    5.0,
                ),
                period_s: c.range("source.synthetic.period_s", &syn.period_s, 20.0, 0.1, 1e6),
                cross_at_s: c.range(
                    "source.synthetic.cross_at_s",
                    &syn.cross_at_s,
                    0.0,
                    0.0,
                    1e6,
                ),
                render_threads: 0,
            })
        }
        SourceKind::Replay => {
            let path = match &rep.path {
                Some(p) if !p.get_ref().is_empty() => PathBuf::from(p.get_ref()),
                Some(p) => {
                    c.bad(
                        "source.replay.path",
                        p,
                        "must name an MCAP file or an image folder",
                    );
                    PathBuf::new()
                }
                None => {
                    let k = src.kind.as_ref().expect("kind = replay was given");
                    c.bad(
                        "source.kind",
                        k,
                        "`replay` needs source.replay.path (an MCAP file or an image folder)",
                    );
                    PathBuf::new()
                }
            };
            let speed = c.range("source.replay.speed", &rep.speed, 1.0, 0.001, 1000.0);
            if let (Some(s), Some(RateKind::Max)) =
                (&rep.speed, rep.rate.as_ref().map(|r| *r.get_ref()))
            {
                c.bad(
                    "source.replay.speed",
                    s,
                    "has no effect with rate = \"max\" (remove one of them)",
                );
            }
            SourceConfig::Replay(ReplayConfig {
                path,
                rate: match c.get(&rep.rate, RateKind::Recorded) {
                    RateKind::Recorded => Rate::Recorded(speed),
                    RateKind::Max => Rate::Max,
                },
                looping: c.get(&rep.looping, false),
                topic: rep
                    .topic
                    .as_ref()
                    .map(|t| t.get_ref().clone())
                    .filter(|t| !t.is_empty()),
                fps: c.range("source.replay.fps", &rep.fps, 15.0, 0.01, 1000.0),
            })
        }
        SourceKind::Camera => SourceConfig::Camera(raw.gige.clone().unwrap_or_default()),
    };
    if let Some(g) = &raw.gige {
        if let Err(e) = g.validate() {
            c.problems.push(Problem {
                line: header_line(c.text, "gige"),
                key: format!("gige.{}", e.key),
                message: e.problem,
            });
        }
    }
    let ros2 = raw.ros2.clone().unwrap_or_default();
    if let Err(e) = ros2.validate() {
        c.problems.push(Problem {
            line: header_line(c.text, "ros2"),
            key: format!("ros2.{}", e.key),
            message: e.problem,
        });
    }

    let guidance = match raw.guidance.clone().unwrap_or_default().options() {
        Ok(g) => g,
        Err(message) => {
            let key = message.split(' ').next().unwrap_or_default();
            c.problems.push(Problem {
                line: header_line(c.text, "guidance"),
                key: format!("guidance.{key}"),
                message,
            });
            None
        }
    };

    let calibration = match &cam.calibration {
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

    let frame_queue = c.range("pipeline.frame_queue", &pip.frame_queue, 2, 1, 64);
    let estimate_queue = c.range("pipeline.estimate_queue", &pip.estimate_queue, 8, 1, 1024);
    let record_queue = c.range("pipeline.record_queue", &pip.record_queue, 4, 1, 256);
    let workers = c.range("pipeline.workers", &pip.workers, 2, 1, 8);
    let status_interval_s = c.range(
        "publish.status_interval_s",
        &publ.status_interval_s,
        1.0,
        0.05,
        3600.0,
    );
    let pipeline = PipelineOptions {
        frame_queue: frame_queue as usize,
        estimate_queue: estimate_queue as usize,
        record_queue: record_queue as usize,
        min_quality: c.range("pipeline.min_quality", &pip.min_quality, 0.3, 0.0, 1.0),
        max_frames: (max_frames > 0).then_some(max_frames),
        max_duration: (max_duration_s > 0.0).then(|| Duration::from_secs_f64(max_duration_s)),
        status_interval: Duration::from_secs_f64(status_interval_s),
        ..PipelineOptions::default()
    };

    let mut udp = Vec::new();
    if let Some(list) = &publ.udp {
        for a in list.get_ref() {
            if let Some(a) = c.addr("publish.udp", a) {
                udp.push(a);
            }
        }
    }
    let multicast_interface = match &publ.multicast_interface {
        None => Ipv4Addr::UNSPECIFIED,
        Some(s) => s.get_ref().parse().unwrap_or_else(|_| {
            c.bad(
                "publish.multicast_interface",
                s,
                format!("`{}` is not an IPv4 address", s.get_ref()),
            );
            Ipv4Addr::UNSPECIFIED
        }),
    };

    let http_addr = if c.get(&http.enabled, true) {
        match &http.listen {
            None => Some(SocketAddr::from(([127, 0, 0, 1], 8347))),
            Some(s) => c.addr("http.listen", s),
        }
    } else {
        None
    };

    // Checked whether or not [record] is enabled: `omnirow record` uses these settings too.
    let record_options = {
        let sync_ms = c.range(
            "record.sync_interval_ms",
            &rec.sync_interval_ms,
            1000,
            10,
            60_000,
        );
        let prefix = c.get(&rec.prefix, "omnirow".to_string());
        if let Some(p) = &rec.prefix {
            if prefix.is_empty() || prefix.contains('/') {
                c.bad(
                    "record.prefix",
                    p,
                    "must be a non-empty file name part without '/'",
                );
            }
        }
        RecordOptions {
            dir: PathBuf::from(c.get(&rec.dir, "/var/lib/omnirow".to_string())),
            prefix,
            rotate_bytes: c.range("record.rotate_mb", &rec.rotate_mb, 4096, 0, 1 << 30) as u64
                * (1 << 20),
            rotate_after: Duration::from_secs_f64(c.range(
                "record.rotate_s",
                &rec.rotate_s,
                600.0,
                0.0,
                1e7,
            )),
            reserve_bytes: c.range("record.reserve_mb", &rec.reserve_mb, 1024, 0, 1 << 30) as u64
                * (1 << 20),
            sync_interval: Duration::from_millis(sync_ms as u64),
            frames: c.get(&rec.frames, true),
            frame_id: c.get(&cam.frame_id, "omnirow_camera".to_string()),
            calibration_toml: None,
            json_channels: c.get(&rec.json_channels, crate::record::JsonChannels::Json),
        }
    };
    let record = c.get(&rec.enabled, false).then(|| record_options.clone());

    let log_level = c.get(&log.level, "info".to_string());
    if let Some(s) = &log.level {
        if tracing_subscriber::EnvFilter::try_new(s.get_ref()).is_err() {
            c.bad(
                "log.level",
                s,
                format!(
                    "`{}` is not a level or filter (e.g. info, debug, omnirow=debug)",
                    s.get_ref()
                ),
            );
        }
    }

    let detector = match &raw.detector {
        None => DetectorOptions::default(),
        Some(o) => {
            let line = header_line(c.text, "detector");
            let mut bad = |key: &str, message: String| {
                c.problems.push(Problem {
                    line,
                    key: key.into(),
                    message,
                })
            };
            let checks = [
                o.hough.validate(),
                o.mask.validate(),
                o.vanishing.validate(),
            ];
            for e in checks.into_iter().filter_map(Result::err) {
                bad("detector", e.to_string());
            }
            if !(o.max_tilt_deg.is_finite() && (0.0..=45.0).contains(&o.max_tilt_deg)) {
                bad(
                    "detector.max_tilt_deg",
                    format!("{} is out of range (0 ..= 45)", o.max_tilt_deg),
                );
            }
            o.clone()
        }
    };

    Config {
        source,
        max_frames: (max_frames > 0).then_some(max_frames),
        max_duration: (max_duration_s > 0.0).then(|| Duration::from_secs_f64(max_duration_s)),
        calibration,
        frame_id: c.get(&cam.frame_id, "omnirow_camera".to_string()),
        pipeline,
        workers: workers as usize,
        udp,
        multicast_ttl: c.range("publish.multicast_ttl", &publ.multicast_ttl, 1, 0, 255) as u32,
        multicast_loop: c.get(&publ.multicast_loop, true),
        multicast_interface,
        stdout: c.get(&publ.stdout, StdoutMode::Auto),
        http: http_addr,
        record,
        record_options,
        log_format: c.get(&log.format, LogFormat::Human),
        log_level,
        detector,
        ros2,
        guidance,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(text: &str) -> ConfigError {
        Config::parse(text, "t.toml").unwrap_err()
    }

    #[test]
    fn shipped_config_is_valid_and_defaults_match_it() {
        let text = include_str!("../config/omnirow.toml");
        let cfg = Config::parse(text, "config/omnirow.toml").unwrap();
        // The shipped file also sends UDP to the local host; everything else is the default.
        let d = Config {
            udp: cfg.udp.clone(),
            ..Config::default()
        };
        assert_eq!(cfg, d);
    }

    #[test]
    fn unknown_key_names_key_and_line() {
        let e = err("[pipeline]\nframe_queue = 2\nframe_qeue = 3\n");
        assert_eq!(e.problems[0].line, 3);
        assert_eq!(e.problems[0].key, "pipeline.frame_qeue");
        assert!(
            e.to_string()
                .starts_with("t.toml:3: `pipeline.frame_qeue`: unknown field"),
            "{e}"
        );
        let e = err("\n[sauce]\nkind = 1\n");
        assert_eq!(e.problems[0].line, 2, "{e}");
    }

    #[test]
    fn wrong_type_names_key_and_line() {
        let e = err("[source]\n\n[source.synthetic]\nfps = \"fast\"\n");
        assert_eq!(e.problems[0].line, 4, "{e}");
        assert_eq!(e.problems[0].key, "source.synthetic.fps");
        assert!(e.problems[0].message.contains("invalid type"), "{e}");
    }

    #[test]
    fn impossible_values_all_reported() {
        let e = err("[pipeline]\nframe_queue = 0\nworkers = 99\n[publish]\nudp = [\"127.0.0.1:7447\", \"nowhere\"]\n[source.synthetic]\nwidth = 33\n");
        let keys: Vec<(usize, &str)> = e
            .problems
            .iter()
            .map(|p| (p.line, p.key.as_str()))
            .collect();
        assert_eq!(
            keys,
            vec![
                (7, "source.synthetic.width"),
                (2, "pipeline.frame_queue"),
                (3, "pipeline.workers"),
                (5, "publish.udp"),
            ]
        );
        let e = err("[source]\nkind = \"replay\"\n");
        assert_eq!(
            (e.problems[0].line, e.problems[0].key.as_str()),
            (2, "source.kind")
        );
        let e = err("[source]\nkind = \"kamera\"\n");
        assert!(e.problems[0].message.contains("unknown variant"), "{e}");
        let e = err("[detector]\nmax_tilt_deg = 99.0\n");
        assert_eq!(
            (e.problems[0].line, e.problems[0].key.as_str()),
            (1, "detector.max_tilt_deg"),
            "{e}"
        );
        let e = err("[detector.hough]\nphi_bins = 1\n");
        assert_eq!(e.problems[0].key, "detector", "{e}");
        let e = err("[detector]\nmethd = \"hough\"\n");
        assert_eq!(
            (e.problems[0].line, e.problems[0].key.as_str()),
            (2, "detector.methd"),
            "{e}"
        );
        let e = err("[pipeline]\nmin_quality = nan\n");
        assert_eq!(e.problems[0].key, "pipeline.min_quality");
    }

    #[test]
    fn camera_source_takes_the_gige_table() {
        let cfg = Config::parse(
            "[source]\nkind = \"camera\"\n[gige]\ncamera = \"02-2623A\"\npixel_format = \"Mono8\"\n[gige.stream]\npacket_socket = false\n",
            "t.toml",
        )
        .unwrap();
        let SourceConfig::Camera(g) = cfg.source else {
            panic!("not the camera: {:?}", cfg.source)
        };
        assert_eq!(g.camera.as_deref(), Some("02-2623A"));
        assert_eq!(g.pixel_format, crate::gige::GigePixelFormat::Mono8);
        assert!(!g.stream.packet_socket);
        // Without [gige], the camera's defaults (first camera found, BayerRG8).
        let cfg = Config::parse("[source]\nkind = \"camera\"\n", "t.toml").unwrap();
        assert_eq!(cfg.source, SourceConfig::Camera(GigeConfig::default()));
    }

    #[test]
    fn guidance_section() {
        assert!(Config::default().guidance.is_some());
        let cfg = Config::parse(
            "[guidance]\nmode = \"over_row\"\nrow_spacing_m = 0.75\n",
            "t.toml",
        )
        .unwrap();
        assert_eq!(cfg.guidance.unwrap().row_spacing_m, Some(0.75));
        let e = err("[log]\nlevel = \"info\"\n[guidance]\nmin_rows = 1\n");
        assert_eq!(e.problems[0].key, "guidance.min_rows");
        assert_eq!(e.problems[0].line, 3);
        assert!(Config::parse("[guidance]\nenabled = false\n", "t.toml")
            .unwrap()
            .guidance
            .is_none());
    }

    #[test]
    fn gige_and_ros2_problems_name_key_and_line() {
        let e = err("[source]\nkind = \"camera\"\n\n[gige]\nbuffers = 1\n");
        assert_eq!(
            (e.problems[0].line, e.problems[0].key.as_str()),
            (4, "gige.buffers"),
            "{e}"
        );
        let e = err("[gige.stream]\npacket_sise = 9000\n");
        assert_eq!(
            (e.problems[0].line, e.problems[0].key.as_str()),
            (2, "gige.stream.packet_sise"),
            "{e}"
        );
        let e = err("[log]\nlevel = \"info\"\n[ros2]\nenabled = true\nnamespace = \"omnirow\"\n");
        assert_eq!(
            (e.problems[0].line, e.problems[0].key.as_str()),
            (3, "ros2.namespace"),
            "{e}"
        );
        let e = err("[ros2]\ndomain = 3\n");
        assert_eq!(
            (e.problems[0].line, e.problems[0].key.as_str()),
            (2, "ros2.domain"),
            "{e}"
        );
        let cfg = Config::parse("[ros2]\nenabled = true\ndomain_id = 7\n", "t.toml").unwrap();
        assert!(cfg.ros2.enabled);
        assert_eq!(cfg.ros2.domain_id, Some(7));
    }

    #[test]
    fn header_line_matches_whole_table_names() {
        let t = "[gigex]\na = 1\n[ gige . stream ]\n[gige]\n";
        assert_eq!(header_line(t, "gige"), 3);
        assert_eq!(header_line(t, "ros2"), 0);
    }
}
