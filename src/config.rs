//! The node's TOML configuration (config/omnirow.toml documents every key).
//!
//! Owns the file-level concerns: reading the file, parsing it (serde with
//! `deny_unknown_fields` in every section, every value kept with its span), composing the
//! sections into the typed [`Config`], and reporting problems. Each section's raw struct and
//! checks live with the code it configures — `[source]` and `[camera]` in [`crate::source`],
//! `[pipeline]` in [`crate::pipeline`], `[publish]` and `[http]` in [`crate::publish`],
//! `[record]` in [`crate::record`], `[log]` in [`crate::logging`]; `[detector]`, `[gige]` and
//! `[ros2]` are typed structs that check themselves. An unknown key, a wrong type or an
//! impossible value is a [`ConfigError`] naming the file, the line and the key, positioned by
//! the TOML parser's spans; all problems found by the checks are reported at once. Every key
//! is optional: a missing key takes the default that `config/omnirow.toml` shows.

use crate::check::Check;
use crate::detect::DetectorOptions;
use crate::gige::GigeConfig;
use crate::guidance::{GuidanceConfig, GuidanceOptions};
use crate::logging::{LogFormat, RawLog};
use crate::pipeline::{PipelineOptions, RawPipeline};
use crate::publish::http::RawHttp;
use crate::publish::stdout::StdoutMode;
use crate::publish::RawPublish;
use crate::record::{RawRecord, RecordOptions};
use crate::ros2::Ros2Config;
use crate::source::{CalibrationChoice, RawCamera, RawSource, SourceConfig};
use serde::Deserialize;
use std::fmt;
use std::net::{Ipv4Addr, SocketAddr};
use std::path::Path;
use std::time::Duration;
use toml_edit::{ImDocument, Item, Table, Value};

/// One problem in a configuration file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    /// 1-based line (0 when the problem has no position).
    pub line: usize,
    /// The dotted key, e.g. `pipeline.frame_queue` (empty when the file cannot be read or
    /// parsed as TOML).
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
            write!(f, "{}", self.file)?;
            if p.line > 0 {
                write!(f, ":{}", p.line)?;
            }
            if !p.key.is_empty() {
                write!(f, ": `{}`", p.key)?;
            }
            write!(f, ": {}", p.message)?;
        }
        Ok(())
    }
}

impl std::error::Error for ConfigError {}

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
    /// Threads of each detector worker (`[pipeline] threads`).
    pub threads: usize,
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

/// The file as written: one raw struct per section.
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

impl Config {
    /// The per-frame step as this configuration sets it: `[detector]`, `[guidance]` and
    /// `[pipeline]`'s `narrow_search`, `min_quality` and `threads` (what `omnirow run`'s
    /// pipeline runs; `omnirow sim` and `omnirow eval guidance` take it).
    pub fn perception(&self) -> crate::perception::PerceptionOptions {
        crate::perception::PerceptionOptions {
            detector: self.detector.clone(),
            guidance: self.guidance,
            narrow_search: self.pipeline.narrow_search.is_some(),
            min_quality: self.pipeline.min_quality,
            threads: self.threads,
        }
    }

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
        let error = |problems| ConfigError {
            file: file.to_string(),
            problems,
        };
        // The document with the span of every key, value and table; the serde structs keep
        // the spans of values only.
        let doc = ImDocument::parse(text).ok();
        let tables = doc.as_ref().map(ImDocument::as_table);
        if let Some(t) = tables {
            let removed = removed_detector_keys(t, text);
            if !removed.is_empty() {
                return Err(error(removed));
            }
        }
        let raw: RawConfig = toml::from_str(text).map_err(|e| {
            let at = e.span().map(|s| s.start);
            error(vec![Problem {
                line: at.map_or(0, |at| line_number(text, at)),
                key: match (tables, at) {
                    (Some(t), Some(at)) => key_at(t, at),
                    _ => String::new(),
                },
                message: e.message().trim().to_string(),
            }])
        })?;
        let mut c = Check::default();
        let cfg = compose(raw, tables, &mut c);
        let problems: Vec<Problem> = c
            .into_findings()
            .into_iter()
            .map(|f| Problem {
                line: f.at.map_or(0, |at| line_number(text, at)),
                key: f.key,
                message: f.message,
            })
            .collect();
        if problems.is_empty() {
            Ok(cfg)
        } else {
            Err(error(problems))
        }
    }
}

/// Checks every section and composes the configuration; `tables` (the parsed document)
/// positions the problems of the sections that check themselves at their table.
fn compose(raw: RawConfig, tables: Option<&Table>, c: &mut Check) -> Config {
    let at = |name: &str| tables.and_then(|t| table_start(t, name));
    let publish = raw.publish.unwrap_or_default();
    let source = raw
        .source
        .unwrap_or_default()
        .validate(raw.gige.as_ref(), c);
    if let Some(Err(e)) = raw.gige.as_ref().map(GigeConfig::validate) {
        c.bad_at(format!("gige.{}", e.key), at("gige"), e.problem);
    }
    let ros2 = raw.ros2.unwrap_or_default();
    if let Err(e) = ros2.validate() {
        c.bad_at(format!("ros2.{}", e.key), at("ros2"), e.problem);
    }
    let guidance = raw
        .guidance
        .unwrap_or_default()
        .options()
        .unwrap_or_else(|message| {
            let key = message.split(' ').next().unwrap_or_default();
            c.bad_at(format!("guidance.{key}"), at("guidance"), message);
            None
        });
    let (calibration, frame_id) = raw.camera.unwrap_or_default().validate(c);
    let (mut pipeline, workers, threads) = raw
        .pipeline
        .unwrap_or_default()
        .validate(&publish.status_interval_s, c);
    pipeline.max_frames = source.max_frames;
    pipeline.max_duration = source.max_duration;
    let (udp, stdout) = publish.validate(c);
    let http = raw.http.unwrap_or_default().validate(c);
    let (record, record_options) = raw.record.unwrap_or_default().validate(frame_id.clone(), c);
    let (log_format, log_level) = raw.log.unwrap_or_default().validate(c);
    let detector = match raw.detector {
        None => DetectorOptions::default(),
        Some(o) => {
            check_detector(&o, at("detector"), c);
            o
        }
    };
    Config {
        source: source.source,
        max_frames: source.max_frames,
        max_duration: source.max_duration,
        calibration,
        frame_id,
        pipeline,
        workers,
        threads,
        udp: udp.destinations,
        multicast_ttl: udp.multicast_ttl,
        multicast_loop: udp.multicast_loop,
        multicast_interface: udp.multicast_interface,
        stdout,
        http,
        record: record.then(|| record_options.clone()),
        record_options,
        log_format,
        log_level,
        detector,
        ros2,
        guidance,
    }
}

/// The detector's own checks, positioned at `[detector]`.
fn check_detector(o: &DetectorOptions, at: Option<usize>, c: &mut Check) {
    if !(o.max_tilt_deg.is_finite() && (0.0..=45.0).contains(&o.max_tilt_deg)) {
        c.bad_at(
            "detector.max_tilt_deg".into(),
            at,
            format!("{} is out of range (0 ..= 45)", o.max_tilt_deg),
        );
    } else if let Err(e) = o.validate() {
        c.bad_at("detector".into(), at, e.to_string());
    }
}

/// The keys under `[detector]` that this version no longer reads
/// ([`crate::detect::options::is_removed`]), each with its line.
fn removed_detector_keys(root: &Table, text: &str) -> Vec<Problem> {
    fn walk(item: &Item, path: &mut Vec<String>, text: &str, found: &mut Vec<Problem>) {
        let Some(t) = item.as_table_like() else {
            return;
        };
        for (name, child) in t.iter() {
            path.push(name.to_string());
            let dotted = path.join(".");
            if crate::detect::options::is_removed(&dotted) {
                let at = t
                    .get_key_value(name)
                    .and_then(|(k, _)| k.span())
                    .map(|s| s.start);
                found.push(Problem {
                    line: at.map_or(0, |at| line_number(text, at)),
                    key: format!("detector.{dotted}"),
                    message: "this option was removed: its behaviour is fixed now \
                              (`omnirow config detector` lists the options there are; \
                              docs/detector.md)"
                        .into(),
                });
            } else {
                walk(child, path, text, found);
            }
            path.pop();
        }
    }
    let mut found = Vec::new();
    if let Some(d) = root.get("detector") {
        walk(d, &mut Vec::new(), text, &mut found);
    }
    found
}

/// The 1-based line of a byte offset the parser reported.
fn line_number(text: &str, offset: usize) -> usize {
    text.as_bytes()[..offset.min(text.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// Where table `name` starts (the offset of its first header, or of the first header under
/// it: nested tables parsed whole by serde carry no positions of their own).
fn table_start(root: &Table, name: &str) -> Option<usize> {
    fn first(item: &Item) -> Option<usize> {
        let own = item.span().map(|s| s.start);
        let nested = match item {
            Item::Table(t) => t.iter().filter_map(|(_, i)| first(i)).min(),
            Item::ArrayOfTables(a) => a.iter().filter_map(|t| t.span()).map(|s| s.start).min(),
            _ => None,
        };
        own.into_iter().chain(nested).min()
    }
    let (key, item) = root.get_key_value(name)?;
    first(item).or_else(|| key.span().map(|s| s.start))
}

/// The dotted key of the innermost key or value at byte `offset`, or of the table whose
/// header holds it (empty when there is none).
fn key_at(root: &Table, offset: usize) -> String {
    let mut path = Vec::new();
    if find_in_table(root, offset, &mut path) {
        path.join(".")
    } else {
        String::new()
    }
}

fn holds(span: Option<std::ops::Range<usize>>, offset: usize) -> bool {
    span.is_some_and(|s| s.contains(&offset))
}

fn find_in_table(table: &Table, offset: usize, path: &mut Vec<String>) -> bool {
    for (name, item) in table.iter() {
        path.push(name.to_string());
        let inside = match item {
            Item::Table(t) => find_in_table(t, offset, path),
            Item::ArrayOfTables(a) => a.iter().any(|t| find_in_table(t, offset, path)),
            Item::Value(v) => find_in_value(v, offset, path),
            Item::None => false,
        };
        if inside
            || holds(table.key(name).and_then(|k| k.span()), offset)
            || holds(item.span(), offset)
        {
            return true;
        }
        path.pop();
    }
    false
}

fn find_in_value(value: &Value, offset: usize, path: &mut Vec<String>) -> bool {
    let Value::InlineTable(t) = value else {
        return false;
    };
    for (name, v) in t.iter() {
        path.push(name.to_string());
        if find_in_value(v, offset, path)
            || holds(t.key(name).and_then(|k| k.span()), offset)
            || holds(v.span(), offset)
        {
            return true;
        }
        path.pop();
    }
    false
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
    fn removed_detector_options_are_named_with_their_line() {
        let e = err("[detector]\nmethod = \"hough\"\n[detector.refit]\nnear_reach_m = 1.0\nperspective = true\n\n[detector.hough]\nphi_bins = 60\n");
        let found: Vec<(usize, &str)> = e
            .problems
            .iter()
            .map(|p| (p.line, p.key.as_str()))
            .collect();
        assert_eq!(
            found,
            [
                (5, "detector.refit.perspective"),
                (8, "detector.hough.phi_bins")
            ],
            "{e}"
        );
        assert!(e.to_string().contains("was removed"), "{e}");
        // dotted and inline spellings too
        let e = err("[detector]\nrefit.wedge = true\nhough = { nms_radius = 3 }\n");
        let keys: Vec<&str> = e.problems.iter().map(|p| p.key.as_str()).collect();
        assert_eq!(
            keys,
            ["detector.refit.wedge", "detector.hough.nms_radius"],
            "{e}"
        );
        // every removed key is refused by name, and none is still an option
        for k in crate::detect::options::removed_keys() {
            let (table, key) = k.rsplit_once('.').unwrap_or(("", &k));
            let text = if table.is_empty() {
                format!("[detector]\n{key} = 1\n")
            } else {
                format!("[detector.{table}]\n{key} = 1\n")
            };
            let e = err(&text);
            assert_eq!(e.problems[0].key, format!("detector.{k}"), "{e}");
        }
    }

    #[test]
    fn wrong_type_names_key_and_line() {
        let e = err("[source]\n\n[source.synthetic]\nfps = \"fast\"\n");
        assert_eq!(e.problems[0].line, 4, "{e}");
        assert_eq!(e.problems[0].key, "source.synthetic.fps");
        assert!(e.problems[0].message.contains("invalid type"), "{e}");
    }

    #[test]
    fn a_photographs_ground_takes_both_keys_and_its_options() {
        let cfg = Config::parse(
            "[source.synthetic]\nphoto = \"f/3.jpg\"\nphoto_labels = \"f/label\"\nphoto_focal_px = 300.0\nphoto_band_spacings = 3\n",
            "t.toml",
        )
        .unwrap();
        let SourceConfig::Synthetic(s) = cfg.source else {
            panic!("the synthetic source")
        };
        let p = s.photo.expect("the photograph");
        assert_eq!(p.image, std::path::PathBuf::from("f/3.jpg"));
        assert_eq!(p.labels, std::path::PathBuf::from("f/label"));
        assert_eq!(p.options.rectify.focal_px, Some(300.0));
        assert_eq!(p.options.max_band_spacings, 3);
        // the defaults of `omnirow synth --images`
        assert_eq!(p.options.max_sampling_m, 0.02);
        assert_eq!(p.options.rectify.row_spacing_m, 0.5);
        assert!(!s.size_given);
        let SourceConfig::Synthetic(s) = Config::default().source else {
            panic!("the synthetic source")
        };
        assert_eq!(s.photo, None);
    }

    #[test]
    fn a_photograph_without_its_labels_or_of_a_wrong_type_is_named() {
        let e = err("[source.synthetic]\nfps = 10.0\nphoto = \"f/3.jpg\"\n");
        assert_eq!(
            (e.problems[0].line, e.problems[0].key.as_str()),
            (3, "source.synthetic.photo"),
            "{e}"
        );
        assert!(e.problems[0].message.contains("photo_labels"), "{e}");
        let e = err("[source.synthetic]\nphoto_labels = \"f/label\"\n");
        assert_eq!(e.problems[0].key, "source.synthetic.photo_labels", "{e}");
        assert!(
            e.problems[0].message.contains("source.synthetic.photo"),
            "{e}"
        );
        let e = err("[source.synthetic]\nphoto = 3\nphoto_labels = \"l\"\n");
        assert_eq!(
            (e.problems[0].line, e.problems[0].key.as_str()),
            (2, "source.synthetic.photo"),
            "{e}"
        );
        assert!(e.problems[0].message.contains("invalid type"), "{e}");
        let e = err("[source.synthetic]\nphoto = \"a.jpg\"\nphoto_labels = \"l\"\nphoto_band_spacings = 0\nphoto_focal_px = -5.0\n");
        let keys: Vec<&str> = e.problems.iter().map(|p| p.key.as_str()).collect();
        assert_eq!(
            keys,
            [
                "source.synthetic.photo_band_spacings",
                "source.synthetic.photo_focal_px"
            ],
            "{e}"
        );
        // an option without the photograph, and a drive the photograph cannot show
        let e = err("[source.synthetic]\nphoto_focal_px = 300.0\n");
        assert_eq!(e.problems[0].key, "source.synthetic.photo_focal_px", "{e}");
        let e = err(
            "[source.synthetic]\ncurvature_per_m = 0.05\nphoto = \"a.jpg\"\nphoto_labels = \"l\"\n",
        );
        assert_eq!(
            (e.problems[0].line, e.problems[0].key.as_str()),
            (3, "source.synthetic.photo"),
            "{e}"
        );
        assert!(e.problems[0].message.contains("curvature_per_m"), "{e}");
    }

    #[test]
    fn impossible_values_all_reported() {
        let e = err("[pipeline]\nframe_queue = 0\nworkers = 99\nthreads = 0\n[publish]\nudp = [\"127.0.0.1:7447\", \"nowhere\"]\n[source.synthetic]\nwidth = 33\n");
        let keys: Vec<(usize, &str)> = e
            .problems
            .iter()
            .map(|p| (p.line, p.key.as_str()))
            .collect();
        assert_eq!(
            keys,
            vec![
                (8, "source.synthetic.width"),
                (2, "pipeline.frame_queue"),
                (3, "pipeline.workers"),
                (4, "pipeline.threads"),
                (6, "publish.udp"),
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
        let e = err("[detector.hough]\nmax_rows = 0\n");
        assert_eq!(e.problems[0].key, "detector", "{e}");
        assert!(e.to_string().contains("hough.max_rows"), "{e}");
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
    fn tables_start_at_their_first_header() {
        let t = "[gigex]\na = 1\n[ gige . stream ]\n[gige]\n";
        let doc = ImDocument::parse(t).unwrap();
        let line = |name| table_start(doc.as_table(), name).map_or(0, |at| line_number(t, at));
        assert_eq!(line("gige"), 3);
        assert_eq!(line("ros2"), 0);
    }

    #[test]
    fn keys_are_found_from_spans() {
        let t = "[source]\n\n[source.synthetic]\nfps = 1\n[log]\nlevel = { a = 1 }\n";
        let doc = ImDocument::parse(t).unwrap();
        let at = |needle: &str| t.find(needle).unwrap();
        assert_eq!(key_at(doc.as_table(), at("fps")), "source.synthetic.fps");
        assert_eq!(
            key_at(doc.as_table(), at("1\n[log")),
            "source.synthetic.fps"
        );
        assert_eq!(key_at(doc.as_table(), at("a = 1")), "log.level.a");
        assert_eq!(key_at(doc.as_table(), at("log]")), "log");
        assert_eq!(key_at(doc.as_table(), t.len()), "");
    }
}
