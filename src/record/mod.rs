//! Recording: frames and estimates into MCAP files that ROS 2 tools and Foxglove open.
//!
//! Owns the [`Recorder`]: frames go on `/omnirow/image_raw` as `sensor_msgs/msg/Image` in CDR
//! (schema: the ROS 2 message definition, encoding `ros2msg`), estimates on
//! `/omnirow/estimate` as JSON, and synthetic ground truth on `/omnirow/ground_truth` as JSON
//! (with a JSON schema, which Foxglove plots field by field; or, with [`JsonChannels::Ros2String`],
//! the same JSON text inside `std_msgs/msg/String`, so that every channel is ROS 2 and rosbags
//! and `ros2 bag` open the file, as they refuse non-ROS channels).
//! Every frame closes its chunk and hands it to the OS; the file is synced to disk at least
//! every `sync_interval`, so a power cut loses at most that much. Files rotate by size or
//! duration, and recording stops (detection goes on) when free space would fall below the
//! reserve, and resumes into a new file once space is back. [`salvage`] reads files that were
//! damaged afterwards. Each file carries the calibration as the attachment `calibration.toml`. [`image_msg`] holds the CDR and Foxglove image codecs.
//! With frames, JSON channels and a calibration, each estimate is also drawn over its image
//! as Foxglove image annotations on `/omnirow/image_annotations` ([`annotations`]).

pub mod annotations;
mod config;
pub mod image_msg;
pub mod salvage;

pub(crate) use config::RawRecord;

use crate::camera::Calibration;
use crate::estimate::Estimate;
use crate::frame::Frame;
use annotations::Annotator;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Topic of the image channel.
pub const IMAGE_TOPIC: &str = "/omnirow/image_raw";
/// Topic of the estimate channel.
pub const ESTIMATE_TOPIC: &str = "/omnirow/estimate";
/// Topic of the ground-truth channel (synthetic frames only).
pub const TRUTH_TOPIC: &str = "/omnirow/ground_truth";

/// How often a recording stopped at the disk reserve looks whether space came back.
const RESUME_CHECK_EVERY: Duration = Duration::from_secs(5);
/// Free space above the reserve needed to resume.
const RESUME_MARGIN: u64 = 64 << 20;

/// Name of the attachment holding the calibration (omnirow TOML).
pub const CALIBRATION_ATTACHMENT: &str = "calibration.toml";

/// A JSON schema (draft 2020-12, as Foxglove reads it) for the estimate channel.
pub const ESTIMATE_JSON_SCHEMA: &str = r#"{"title":"omnirow.Estimate","type":"object","properties":{"schema_version":{"type":"integer"},"seq":{"type":"integer"},"capture_ns":{"type":"integer"},"receive_ns":{"type":"integer"},"publish_ns":{"type":"integer"},"latency_ms":{"type":"number"},"detector_ms":{"type":"number"},"status":{"type":"string","enum":["ok","degraded","no_rows","no_vanishing_point","camera_lost","error"]},"heading_rad":{"type":["number","null"]},"tilt_rad":{"type":["number","null"]},"vanishing_point":{"type":["array","null"],"items":{"type":"number"}},"rows":{"type":"array","items":{"type":"object","properties":{"normal":{"type":"array","items":{"type":"number"}},"method":{"type":"string"},"support":{"type":"integer"},"width_rad":{"type":"number"}}}},"quality":{"type":"number"},"error":{"type":"string"},"truth":{"type":"object"},"guidance":{"type":["object","null"]}}}"#;

/// How the estimate and ground-truth channels are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JsonChannels {
    /// JSON messages with a JSON schema (`jsonschema`/`json`): Foxglove plots every field.
    #[default]
    Json,
    /// The same JSON text as `std_msgs/msg/String` in CDR (`ros2msg`/`cdr`): every channel
    /// of the file is then a ROS 2 type, as rosbags and `ros2 bag` require.
    Ros2String,
}

/// ROS 2 message definition of `std_msgs/msg/String`.
pub const ROS2_STRING_SCHEMA: &str = "string data\n";

/// Encodes `text` as a CDR `std_msgs/msg/String` (little-endian encapsulation, length with
/// the terminating NUL) into `out`.
pub fn encode_ros2_string(out: &mut Vec<u8>, text: &[u8]) {
    out.clear();
    out.extend_from_slice(&[0, 1, 0, 0]);
    out.extend_from_slice(&(text.len() as u32 + 1).to_le_bytes());
    out.extend_from_slice(text);
    out.push(0);
}

/// The text of a CDR `std_msgs/msg/String`, or `None` if `data` is not one.
pub fn decode_ros2_string(data: &[u8]) -> Option<&[u8]> {
    let little = match data.get(..2)? {
        [0, 1] => true,
        [0, 0] => false,
        _ => return None,
    };
    let len: [u8; 4] = data.get(4..8)?.try_into().ok()?;
    let len = if little {
        u32::from_le_bytes(len)
    } else {
        u32::from_be_bytes(len)
    } as usize;
    let body = data.get(8..8usize.checked_add(len)?)?;
    match body.split_last() {
        Some((0, text)) => Some(text),
        _ => None,
    }
}

/// Errors of the recorder.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("recording directory {path}: {source}")]
    Dir {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("recording {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("recording {path}: MCAP: {source}")]
    Mcap {
        path: PathBuf,
        source: mcap::McapError,
    },
}

/// What to record and how.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordOptions {
    /// Directory the files go into (created if missing).
    pub dir: PathBuf,
    /// File name prefix; files are `<prefix>_<UTC time>_<index>.mcap`.
    pub prefix: String,
    /// Start a new file when the current one reaches this size (0: never).
    pub rotate_bytes: u64,
    /// Start a new file after this long (zero: never).
    pub rotate_after: Duration,
    /// Stop recording when the free space of the file system would fall below this.
    pub reserve_bytes: u64,
    /// Sync the file to disk at least this often.
    pub sync_interval: Duration,
    /// Record the frames (false: estimates only).
    pub frames: bool,
    /// `frame_id` written into the image headers.
    pub frame_id: String,
    /// The calibration the frames go with (omnirow TOML), attached to every file as
    /// `calibration.toml` so that a recording replays with its own calibration.
    pub calibration_toml: Option<String>,
    /// Encoding of the estimate and ground-truth channels.
    pub json_channels: JsonChannels,
    /// Draw each estimate over its frame as Foxglove image annotations (`record.annotations`,
    /// default true) when `annotate` gives the calibration.
    pub annotations: bool,
    /// The calibration the estimates are drawn through as Foxglove image annotations
    /// ([`annotations`]), at any uniform scale of the frames' size; `None`, or frames not
    /// recorded, or [`JsonChannels::Ros2String`] (no ROS 2 message for them): no annotations
    /// channel.
    pub annotate: Option<Calibration>,
}

impl Default for RecordOptions {
    fn default() -> Self {
        RecordOptions {
            dir: PathBuf::from("/var/lib/omnirow"),
            prefix: "omnirow".into(),
            rotate_bytes: 4 << 30,
            rotate_after: Duration::from_secs(600),
            reserve_bytes: 1 << 30,
            sync_interval: Duration::from_secs(1),
            frames: true,
            frame_id: "omnirow_camera".into(),
            calibration_toml: None,
            json_channels: JsonChannels::Json,
            annotations: true,
            annotate: None,
        }
    }
}

/// The recorder's state, for the status summary and /metrics.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum RecordState {
    Recording(PathBuf),
    /// Stopped because the disk reserve was reached (detection goes on).
    StoppedDiskFull,
    /// Stopped after an I/O error (detection goes on).
    Failed(String),
    #[default]
    Closed,
}

struct OpenFile {
    path: PathBuf,
    writer: mcap::Writer<BufWriter<File>>,
    opened: Instant,
    bytes: u64,
    image_ch: u16,
    estimate_ch: u16,
    truth_ch: u16,
    /// The annotations channel, when annotations are written.
    annotations_ch: Option<u16>,
    image_seq: u32,
    estimate_seq: u32,
}

/// The recorder's state as other threads see it (the node's exit code), updated by the
/// recorder whenever it changes, with the first failure kept.
#[derive(Debug, Clone, Default)]
pub struct RecordHealth(std::sync::Arc<std::sync::Mutex<(RecordState, Option<String>)>>);

impl RecordHealth {
    pub fn get(&self) -> RecordState {
        self.lock().0.clone()
    }

    /// Why the recording failed or never started, if it ever did (even if it resumed).
    pub fn failure(&self) -> Option<String> {
        self.lock().1.clone()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, (RecordState, Option<String>)> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn set(&self, s: &RecordState) {
        let mut g = self.lock();
        let why = match s {
            RecordState::StoppedDiskFull => {
                Some("stopped: free space reached the disk reserve (record.reserve_mb)".into())
            }
            RecordState::Failed(why) => Some(format!("failed: {why}")),
            RecordState::Recording(_) | RecordState::Closed => None,
        };
        if g.1.is_none() {
            g.1 = why;
        }
        g.0 = s.clone();
    }
}

/// Writes frames and estimates into rotating MCAP files.
pub struct Recorder {
    opts: RecordOptions,
    file: Option<OpenFile>,
    state: RecordState,
    health: RecordHealth,
    files: Vec<PathBuf>,
    next_index: u32,
    scratch: Vec<u8>,
    last_sync: Instant,
    last_space_check: Instant,
    since_space_check: u64,
    frames_written: u64,
    bytes_written: u64,
    /// Draws estimates over the last recorded frame's size (built from `opts.annotate` when
    /// that size changes); `None` until a frame is recorded or when the calibration does not
    /// scale to the frames.
    annotator: Option<Annotator>,
    /// The frame size `annotator` was last built for (or refused).
    annotated_size: (u32, u32),
    annotation_json: String,
}

impl Recorder {
    /// Creates the directory if needed and opens the first file.
    pub fn new(opts: RecordOptions) -> Result<Self, RecordError> {
        std::fs::create_dir_all(&opts.dir).map_err(|source| RecordError::Dir {
            path: opts.dir.clone(),
            source,
        })?;
        let mut r = Recorder::idle(opts);
        if r.space_ok(0)? {
            r.open()?;
        } else {
            tracing::error!(dir = %r.opts.dir.display(), reserve_mb = r.opts.reserve_bytes >> 20,
                "not recording: free space is below the reserve; detection goes on");
            r.set_state(RecordState::StoppedDiskFull);
        }
        Ok(r)
    }

    /// A recorder that could not start (`why`): it records nothing, and says so in its state.
    pub fn failed(opts: RecordOptions, why: String) -> Self {
        let mut r = Recorder::idle(opts);
        r.set_state(RecordState::Failed(why));
        r
    }

    fn idle(opts: RecordOptions) -> Self {
        Recorder {
            opts,
            file: None,
            state: RecordState::Closed,
            health: RecordHealth::default(),
            files: Vec::new(),
            next_index: 0,
            scratch: Vec::new(),
            last_sync: Instant::now(),
            last_space_check: Instant::now(),
            since_space_check: 0,
            frames_written: 0,
            bytes_written: 0,
            annotator: None,
            annotated_size: (0, 0),
            annotation_json: String::new(),
        }
    }

    /// The state, shared with other threads.
    pub fn health(&self) -> RecordHealth {
        self.health.clone()
    }

    fn set_state(&mut self, s: RecordState) {
        self.health.set(&s);
        self.state = s;
    }

    pub fn state(&self) -> &RecordState {
        &self.state
    }

    /// Every file written so far (including the open one).
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }

    pub fn frames_written(&self) -> u64 {
        self.frames_written
    }

    pub fn bytes_written(&self) -> u64 {
        self.bytes_written
    }

    fn open(&mut self) -> Result<(), RecordError> {
        let stamp = utc_stamp(crate::frame::now_ns());
        let path = self.opts.dir.join(format!(
            "{}_{}_{:03}.mcap",
            self.opts.prefix, stamp, self.next_index
        ));
        self.next_index += 1;
        let io = |source| RecordError::Io {
            path: path.clone(),
            source,
        };
        let mc = |source| RecordError::Mcap {
            path: path.clone(),
            source,
        };
        let f = File::create(&path).map_err(io)?;
        let opts = mcap::WriteOptions::new()
            .compression(None)
            .profile("ros2")
            .library(concat!("omnirow-", env!("CARGO_PKG_VERSION")))
            .chunk_size(Some(1 << 20));
        let mut writer = opts
            .create(BufWriter::with_capacity(1 << 20, f))
            .map_err(mc)?;
        // The calibration first, before any chunk, where a replay looks for it.
        if let Some(cal) = &self.opts.calibration_toml {
            let now = crate::frame::now_ns();
            writer
                .attach(&mcap::Attachment {
                    log_time: now,
                    create_time: now,
                    name: CALIBRATION_ATTACHMENT.into(),
                    media_type: "application/toml".into(),
                    data: std::borrow::Cow::Borrowed(cal.as_bytes()),
                })
                .map_err(mc)?;
        }
        let none = BTreeMap::new();
        let img_schema = writer
            .add_schema(
                "sensor_msgs/msg/Image",
                "ros2msg",
                image_msg::ROS2_IMAGE_SCHEMA.as_bytes(),
            )
            .map_err(mc)?;
        let mut meta = BTreeMap::new();
        meta.insert("offered_qos_profiles".to_string(), String::new());
        let image_ch = writer
            .add_channel(img_schema, IMAGE_TOPIC, "cdr", &meta)
            .map_err(mc)?;
        let (estimate_ch, truth_ch) = match self.opts.json_channels {
            JsonChannels::Json => {
                let est_schema = writer
                    .add_schema(
                        "omnirow.Estimate",
                        "jsonschema",
                        ESTIMATE_JSON_SCHEMA.as_bytes(),
                    )
                    .map_err(mc)?;
                let truth_schema = writer
                    .add_schema(
                        "omnirow.GroundTruth",
                        "jsonschema",
                        br#"{"title":"omnirow.GroundTruth","type":"object"}"#,
                    )
                    .map_err(mc)?;
                (
                    writer
                        .add_channel(est_schema, ESTIMATE_TOPIC, "json", &none)
                        .map_err(mc)?,
                    writer
                        .add_channel(truth_schema, TRUTH_TOPIC, "json", &none)
                        .map_err(mc)?,
                )
            }
            JsonChannels::Ros2String => {
                let schema = writer
                    .add_schema(
                        "std_msgs/msg/String",
                        "ros2msg",
                        ROS2_STRING_SCHEMA.as_bytes(),
                    )
                    .map_err(mc)?;
                (
                    writer
                        .add_channel(schema, ESTIMATE_TOPIC, "cdr", &meta)
                        .map_err(mc)?,
                    writer
                        .add_channel(schema, TRUTH_TOPIC, "cdr", &meta)
                        .map_err(mc)?,
                )
            }
        };
        let annotations_ch = match (&self.opts.annotate, self.opts.json_channels) {
            (Some(_), JsonChannels::Json) if self.opts.frames && self.opts.annotations => {
                let schema = writer
                    .add_schema(
                        annotations::ANNOTATIONS_SCHEMA_NAME,
                        "jsonschema",
                        annotations::ANNOTATIONS_JSON_SCHEMA.as_bytes(),
                    )
                    .map_err(mc)?;
                Some(
                    writer
                        .add_channel(schema, annotations::ANNOTATIONS_TOPIC, "json", &none)
                        .map_err(mc)?,
                )
            }
            _ => None,
        };
        // The schemas and channels in a chunk of their own: damage to the first frame's chunk
        // does not take the definitions every later frame needs.
        writer.flush().map_err(mc)?;
        tracing::info!(file = %path.display(), "recording");
        self.files.push(path.clone());
        self.set_state(RecordState::Recording(path.clone()));
        self.file = Some(OpenFile {
            path,
            writer,
            opened: Instant::now(),
            bytes: 0,
            image_ch,
            estimate_ch,
            truth_ch,
            annotations_ch,
            image_seq: 0,
            estimate_seq: 0,
        });
        Ok(())
    }

    /// Free space on the recording file system is at least `reserve + extra` bytes.
    fn space_ok(&mut self, extra: u64) -> Result<bool, RecordError> {
        self.last_space_check = Instant::now();
        self.since_space_check = 0;
        let free = free_bytes(&self.opts.dir).map_err(|source| RecordError::Dir {
            path: self.opts.dir.clone(),
            source,
        })?;
        Ok(free >= self.opts.reserve_bytes.saturating_add(extra))
    }

    /// Records a frame (and its ground truth, if any). A recording that has stopped ignores it.
    pub fn write_frame(&mut self, frame: &Frame) -> Result<(), RecordError> {
        if !self.opts.frames {
            return Ok(());
        }
        let need = frame.data.len() as u64 + 1024;
        self.before_write(need)?;
        self.annotate_size(frame.height, frame.width);
        let Some(f) = self.file.as_mut() else {
            return Ok(());
        };
        let mc = |source| RecordError::Mcap {
            path: f.path.clone(),
            source,
        };
        if let Some(t) = &frame.truth {
            let mut json = serde_json::to_vec(&**t).unwrap_or_default();
            if self.opts.json_channels == JsonChannels::Ros2String {
                encode_ros2_string(&mut self.scratch, &json);
                std::mem::swap(&mut json, &mut self.scratch);
            }
            let header = mcap::records::MessageHeader {
                channel_id: f.truth_ch,
                sequence: f.image_seq,
                log_time: frame.receive_ns,
                publish_time: frame.capture_ns,
            };
            f.writer
                .write_to_known_channel(&header, &json)
                .map_err(mc)?;
            f.bytes += json.len() as u64 + 40;
        }
        image_msg::encode_ros2_image(
            &mut self.scratch,
            frame.capture_ns,
            &self.opts.frame_id,
            frame.width,
            frame.height,
            frame.format,
            &frame.data,
        );
        let header = mcap::records::MessageHeader {
            channel_id: f.image_ch,
            sequence: f.image_seq,
            log_time: frame.receive_ns,
            publish_time: frame.capture_ns,
        };
        f.image_seq = f.image_seq.wrapping_add(1);
        f.writer
            .write_to_known_channel(&header, &self.scratch)
            .map_err(mc)?;
        // Close the chunk so the frame is complete on disk once the OS writes it back.
        f.writer.flush().map_err(mc)?;
        f.bytes += self.scratch.len() as u64 + 100;
        self.bytes_written += self.scratch.len() as u64;
        self.frames_written += 1;
        self.after_write()
    }

    /// Records an estimate. A recording that has stopped ignores it.
    pub fn write_estimate(&mut self, e: &Estimate) -> Result<(), RecordError> {
        self.before_write(4096)?;
        let Some(f) = self.file.as_mut() else {
            return Ok(());
        };
        let text = e.to_json();
        let json = match self.opts.json_channels {
            JsonChannels::Json => text.into_bytes(),
            JsonChannels::Ros2String => {
                let mut v = Vec::with_capacity(text.len() + 9);
                encode_ros2_string(&mut v, text.as_bytes());
                v
            }
        };
        let header = mcap::records::MessageHeader {
            channel_id: f.estimate_ch,
            sequence: f.estimate_seq,
            log_time: e.publish_ns.max(e.receive_ns),
            publish_time: e.capture_ns,
        };
        f.estimate_seq = f.estimate_seq.wrapping_add(1);
        f.writer
            .write_to_known_channel(&header, &json)
            .map_err(|source| RecordError::Mcap {
                path: f.path.clone(),
                source,
            })?;
        f.bytes += json.len() as u64 + 40;
        self.bytes_written += json.len() as u64;
        if let (Some(ch), Some(a)) = (f.annotations_ch, self.annotator.as_mut()) {
            a.write_json(e, &mut self.annotation_json);
            let header = mcap::records::MessageHeader {
                channel_id: ch,
                ..header
            };
            f.writer
                .write_to_known_channel(&header, self.annotation_json.as_bytes())
                .map_err(|source| RecordError::Mcap {
                    path: f.path.clone(),
                    source,
                })?;
            f.bytes += self.annotation_json.len() as u64 + 40;
            self.bytes_written += self.annotation_json.len() as u64;
        }
        self.after_write()
    }

    /// Keeps the annotator at the recorded frames' size: the calibration rescaled to it. A
    /// size the calibration does not scale to (a region of interest cut off-centre) leaves the
    /// annotations out, with a warning.
    fn annotate_size(&mut self, height: u32, width: u32) {
        let Some(cal) = self
            .opts
            .annotate
            .as_ref()
            .filter(|_| self.opts.annotations)
        else {
            return;
        };
        if self.annotated_size == (height, width) {
            return;
        }
        self.annotated_size = (height, width);
        self.annotator = match cal.rescaled_to(height, width) {
            Ok(c) => Some(Annotator::new(c)),
            Err(e) => {
                tracing::warn!("recording: no image annotations for {width}x{height} frames: {e}");
                None
            }
        };
    }

    /// Rotation and the disk reserve, checked before each write.
    fn before_write(&mut self, need: u64) -> Result<(), RecordError> {
        if self.file.is_none() {
            return self.maybe_resume(need);
        }
        // Check free space every 64 MB written or every second, whichever comes first.
        self.since_space_check += need;
        let due = self.last_space_check.elapsed() >= Duration::from_secs(1)
            || self.since_space_check >= 64 << 20;
        if due && !self.space_ok(need)? {
            self.close_file()?;
            tracing::error!(
                dir = %self.opts.dir.display(),
                reserve_mb = self.opts.reserve_bytes >> 20,
                "recording stopped: free space reached the reserve; detection goes on"
            );
            self.set_state(RecordState::StoppedDiskFull);
            return Ok(());
        }
        let f = self.file.as_ref().expect("checked above");
        let by_size = self.opts.rotate_bytes > 0 && f.bytes + need > self.opts.rotate_bytes;
        let by_time =
            !self.opts.rotate_after.is_zero() && f.opened.elapsed() >= self.opts.rotate_after;
        if (by_size || by_time) && f.bytes > 0 {
            self.close_file()?;
            self.open()?;
        }
        Ok(())
    }

    /// Stopped at the disk reserve: every few seconds, look again, and record into a new file
    /// once the free space is back above the reserve (with a margin, so that it does not
    /// flap).
    fn maybe_resume(&mut self, need: u64) -> Result<(), RecordError> {
        if self.state != RecordState::StoppedDiskFull
            || self.last_space_check.elapsed() < RESUME_CHECK_EVERY
        {
            return Ok(());
        }
        if self.space_ok(need.saturating_add(RESUME_MARGIN))? {
            self.open()?;
            tracing::warn!(
                dir = %self.opts.dir.display(),
                "recording resumed: free space is above the reserve again"
            );
        }
        Ok(())
    }

    fn after_write(&mut self) -> Result<(), RecordError> {
        if self.last_sync.elapsed() >= self.opts.sync_interval {
            self.sync()?;
        }
        Ok(())
    }

    /// Closes the current chunk and syncs the file's data to disk.
    pub fn sync(&mut self) -> Result<(), RecordError> {
        self.last_sync = Instant::now();
        let Some(f) = self.file.as_mut() else {
            return Ok(());
        };
        let path = f.path.clone();
        f.writer.flush().map_err(|source| RecordError::Mcap {
            path: path.clone(),
            source,
        })?;
        // The mcap writer owns the BufWriter; flushing the chunk flushed it to the File.
        sync_path(&path).map_err(|source| RecordError::Io { path, source })
    }

    fn close_file(&mut self) -> Result<(), RecordError> {
        if let Some(mut f) = self.file.take() {
            let summary = f.writer.finish().map_err(|source| RecordError::Mcap {
                path: f.path.clone(),
                source,
            })?;
            let inner = f.writer.into_inner();
            let file = inner.into_inner().map_err(|e| RecordError::Io {
                path: f.path.clone(),
                source: e.into_error(),
            })?;
            file.sync_all().map_err(|source| RecordError::Io {
                path: f.path.clone(),
                source,
            })?;
            let n = summary.stats.map(|s| s.message_count).unwrap_or_default();
            tracing::info!(file = %f.path.display(), messages = n, "recording closed");
        }
        Ok(())
    }

    /// Writes the summary of the open file, syncs it and closes it. Idempotent.
    pub fn finish(&mut self) -> Result<(), RecordError> {
        let r = self.close_file();
        if matches!(self.state, RecordState::Recording(_)) {
            self.set_state(RecordState::Closed);
        }
        r
    }

    /// Marks the recorder failed after an error (the caller logs it); no more writes.
    pub fn fail(&mut self, why: String) {
        let _ = self.close_file();
        self.set_state(RecordState::Failed(why));
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        if let Err(e) = self.finish() {
            tracing::error!("closing the recording: {e}");
        }
    }
}

/// fsync of a file's data through a second handle (the writer keeps its own).
fn sync_path(path: &Path) -> std::io::Result<()> {
    File::options().write(true).open(path)?.sync_data()
}

/// Free bytes for an unprivileged user on the file system holding `dir` (statvfs).
pub fn free_bytes(dir: &Path) -> std::io::Result<u64> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(dir.as_os_str().as_bytes())
        .map_err(|_| std::io::Error::other("path contains NUL"))?;
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: `c` is a valid NUL-terminated path and `st` a valid out-pointer.
    let rc = unsafe { libc::statvfs(c.as_ptr(), &mut st) };
    if rc != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(st.f_bavail as u64 * st.f_frsize as u64)
}

/// `YYYYmmddTHHMMSSZ` from ns since the epoch (civil-from-days, proleptic Gregorian).
fn utc_stamp(ns: u64) -> String {
    let secs = ns / 1_000_000_000;
    let (days, sod) = ((secs / 86_400) as i64, secs % 86_400);
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}{m:02}{d:02}T{:02}{:02}{:02}Z",
        sod / 3600,
        sod % 3600 / 60,
        sod % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ros2_string_round_trips_and_rejects_garbage() {
        let mut v = Vec::new();
        encode_ros2_string(&mut v, br#"{"seq":3}"#);
        assert_eq!(&v[..8], &[0, 1, 0, 0, 10, 0, 0, 0]);
        assert_eq!(decode_ros2_string(&v), Some(&br#"{"seq":3}"#[..]));
        encode_ros2_string(&mut v, b"");
        assert_eq!(decode_ros2_string(&v), Some(&b""[..]));
        assert_eq!(decode_ros2_string(&v[..7]), None);
        assert_eq!(decode_ros2_string(&[0, 1, 0, 0, 255, 255, 255, 255]), None);
        assert_eq!(
            decode_ros2_string(&[0, 1, 0, 0, 2, 0, 0, 0, b'a', b'b']),
            None
        );
        assert_eq!(decode_ros2_string(&[7, 7, 0, 0]), None);
    }

    #[test]
    fn utc_stamp_known_dates() {
        assert_eq!(utc_stamp(0), "19700101T000000Z");
        assert_eq!(utc_stamp(1_700_000_000 * 1_000_000_000), "20231114T221320Z");
        assert_eq!(utc_stamp(951_782_400 * 1_000_000_000), "20000229T000000Z");
    }

    fn frame(seq: u64) -> Frame {
        Frame {
            seq,
            capture_ns: 1_000 + seq,
            receive_ns: 2_000 + seq,
            width: 64,
            height: 32,
            format: crate::frame::PixelFormat::Mono8,
            data: vec![seq as u8; 64 * 32],
            truth: None,
        }
    }

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("omnirow-rec-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn rotates_by_size_into_complete_files() {
        let d = dir("rotate");
        let mut r = Recorder::new(RecordOptions {
            dir: d.clone(),
            rotate_bytes: 5 * 64 * 32,
            reserve_bytes: 0,
            calibration_toml: Some("not checked here".into()),
            ..RecordOptions::default()
        })
        .unwrap();
        for i in 0..12 {
            r.write_frame(&frame(i)).unwrap();
        }
        r.finish().unwrap();
        assert!(r.files().len() >= 3, "{:?}", r.files());
        let mut seen = 0;
        for f in r.files() {
            let bytes = std::fs::read(f).unwrap();
            let summary = mcap::Summary::read(&bytes).unwrap().expect("summary");
            assert_eq!(summary.attachment_indexes.len(), 1, "calibration attached");
            for m in mcap::MessageStream::new(&bytes).unwrap() {
                let m = m.unwrap();
                let img = image_msg::decode_ros2_image(&m.data).unwrap();
                assert_eq!(img.data[0], seen as u8, "frames in order, none lost");
                seen += 1;
            }
        }
        assert_eq!(seen, 12);
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn disk_reserve_stops_recording_without_error() {
        let d = dir("reserve");
        let mut r = Recorder::new(RecordOptions {
            dir: d.clone(),
            reserve_bytes: u64::MAX / 2,
            ..RecordOptions::default()
        })
        .unwrap();
        assert_eq!(r.state(), &RecordState::StoppedDiskFull);
        r.write_frame(&frame(0)).unwrap();
        assert_eq!(r.frames_written(), 0);
        assert!(r.files().is_empty());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn recording_resumes_when_space_comes_back_and_the_failure_is_kept() {
        let d = dir("resume");
        let mut r = Recorder::new(RecordOptions {
            dir: d.clone(),
            reserve_bytes: u64::MAX / 2,
            ..RecordOptions::default()
        })
        .unwrap();
        let health = r.health();
        assert_eq!(health.get(), RecordState::StoppedDiskFull);
        r.write_frame(&frame(0)).unwrap();
        assert!(r.files().is_empty(), "not before the check interval");
        // Space comes back (a smaller reserve) and the interval passes.
        r.opts.reserve_bytes = 0;
        r.last_space_check = Instant::now() - RESUME_CHECK_EVERY;
        r.write_frame(&frame(1)).unwrap();
        assert_eq!(r.files().len(), 1);
        assert_eq!(r.frames_written(), 1);
        assert!(matches!(health.get(), RecordState::Recording(_)));
        r.finish().unwrap();
        assert_eq!(health.get(), RecordState::Closed);
        let why = health.failure().expect("the stop is remembered");
        assert!(why.contains("reserve"), "{why}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn free_bytes_of_tmp() {
        assert!(free_bytes(&std::env::temp_dir()).unwrap() > 0);
        assert!(free_bytes(Path::new("/definitely/not/here")).is_err());
    }
}
