//! Replay of MCAP recordings: ours, and any MCAP whose images are `sensor_msgs/msg/Image`
//! (CDR) or `foxglove.RawImage` (protobuf, JSON, or `foxglove_msgs/msg/RawImage` in CDR), in
//! mono8, rgb8, bgr8 or 8-bit Bayer.
//!
//! Streams the file from start to end (never loads it whole), paced by the images' capture
//! stamps (the log time where an image has none). A file cut short (power loss on the robot) replays every complete frame before the
//! cut and then ends with a warning. Ground truth recorded on `/omnirow/ground_truth` travels
//! with its frame again.

use super::{wait_due, Pacer, Poll, Rate, Source, SourceError, SourceState};
use crate::frame::{Frame, PixelFormat};
use crate::record::image_msg::{self, ImageMsg};
use crate::record::TRUTH_TOPIC;
use crate::synth::GroundTruth;
use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
use std::collections::{HashMap, VecDeque};
use std::fs::File;
use std::io::Read;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

/// What to replay and how.
#[derive(Debug, Clone, PartialEq)]
pub struct McapReplayOptions {
    pub path: PathBuf,
    pub rate: Rate,
    /// Start again at the end.
    pub looping: bool,
    /// The image topic to replay; `None`: the first image channel in the file.
    pub topic: Option<String>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Codec {
    Ros2Image,
    FoxgloveCdr,
    FoxgloveProtobuf,
    FoxgloveJson,
}

/// Replays the images of an MCAP file.
pub struct McapReplay {
    opts: McapReplayOptions,
    file: File,
    reader: LinearReader,
    schemas: HashMap<u16, (String, String)>,
    image_channel: Option<(u16, Codec)>,
    truth_channel: Option<u16>,
    /// The truth channel holds JSON inside `std_msgs/msg/String` (record.json_channels).
    truth_in_string: bool,
    truths: VecDeque<(u64, Arc<GroundTruth>)>,
    pacer: Pacer,
    pending: Option<(u64, Frame)>,
    seq: u64,
    frames_this_pass: u64,
    bytes_read: u64,
    state: SourceState,
    scratch: Vec<u8>,
    calibration: Option<crate::camera::Calibration>,
}

impl McapReplay {
    /// Opens the file (errors name it).
    pub fn open(opts: McapReplayOptions) -> Result<Self, SourceError> {
        let mut file = File::open(&opts.path).map_err(|source| SourceError::Io {
            path: opts.path.clone(),
            source,
        })?;
        let mut magic = [0u8; 8];
        let n = read_retry(&mut file, &mut magic).map_err(|source| SourceError::Io {
            path: opts.path.clone(),
            source,
        })?;
        if n < 8 || magic != *mcap::MAGIC {
            return Err(SourceError::Invalid {
                path: opts.path.clone(),
                problem: "not an MCAP file (no MCAP magic at the start)".into(),
            });
        }
        drop(file);
        let calibration = recorded_calibration(&opts.path)?;
        let file = File::open(&opts.path).map_err(|source| SourceError::Io {
            path: opts.path.clone(),
            source,
        })?;
        Ok(McapReplay {
            pacer: Pacer::new(opts.rate),
            opts,
            file,
            reader: new_reader(),
            schemas: HashMap::new(),
            image_channel: None,
            truth_channel: None,
            truth_in_string: false,
            truths: VecDeque::new(),
            pending: None,
            seq: 0,
            frames_this_pass: 0,
            bytes_read: 0,
            state: SourceState::Starting,
            scratch: Vec::new(),
            calibration,
        })
    }

    fn invalid(&self, problem: String) -> SourceError {
        SourceError::Invalid {
            path: self.opts.path.clone(),
            problem,
        }
    }

    fn rewind(&mut self) -> Result<(), SourceError> {
        self.file = File::open(&self.opts.path).map_err(|source| SourceError::Io {
            path: self.opts.path.clone(),
            source,
        })?;
        self.reader = new_reader();
        self.schemas.clear();
        self.image_channel = None;
        self.truth_channel = None;
        self.truths.clear();
        self.pacer.reset();
        self.frames_this_pass = 0;
        self.bytes_read = 0;
        Ok(())
    }

    /// Reads records until the next image of the replayed channel: `(pace time, frame)`, or
    /// `None` at the end of the file (clean or cut short).
    fn next_image(&mut self) -> Result<Option<(u64, Frame)>, SourceError> {
        loop {
            let event = match self.reader.next_event() {
                None => {
                    if self.image_channel.is_none() {
                        return Err(self.invalid(format!(
                            "no image channel{} (supported: sensor_msgs/msg/Image in CDR, foxglove.RawImage)",
                            self.opts
                                .topic
                                .as_ref()
                                .map(|t| format!(" on topic {t}"))
                                .unwrap_or_default()
                        )));
                    }
                    return Ok(None);
                }
                Some(Err(e)) => {
                    tracing::warn!(
                        file = %self.opts.path.display(),
                        frames = self.frames_this_pass,
                        at_byte = self.bytes_read,
                        "recording cut short ({e}): replayed every complete frame before the cut"
                    );
                    return Ok(None);
                }
                Some(Ok(ev)) => ev,
            };
            match event {
                LinearReadEvent::ReadRequest(n) => {
                    let buf = self.reader.insert(n);
                    let got =
                        read_retry(&mut self.file, buf).map_err(|source| SourceError::Io {
                            path: self.opts.path.clone(),
                            source,
                        })?;
                    self.bytes_read += got as u64;
                    self.reader.notify_read(got);
                }
                LinearReadEvent::Record { opcode, data } => {
                    let record = match mcap::parse_record(opcode, data) {
                        Ok(r) => r,
                        Err(e) => {
                            let msg = format!("bad record (opcode {opcode:#x}): {e}");
                            tracing::warn!(file = %self.opts.path.display(), "{msg}; skipped");
                            continue;
                        }
                    };
                    match record {
                        Record::Schema { header, .. } => {
                            self.schemas
                                .insert(header.id, (header.name, header.encoding));
                        }
                        Record::Channel(ch) => {
                            if ch.topic == TRUTH_TOPIC {
                                self.truth_channel = Some(ch.id);
                                self.truth_in_string = ch.message_encoding == "cdr";
                                continue;
                            }
                            if self.image_channel.is_some() {
                                continue;
                            }
                            if let Some(t) = &self.opts.topic {
                                if *t != ch.topic {
                                    continue;
                                }
                            }
                            let schema = self.schemas.get(&ch.schema_id);
                            let codec = schema.and_then(|(name, _enc)| {
                                match (name.as_str(), ch.message_encoding.as_str()) {
                                    ("sensor_msgs/msg/Image", "cdr") => Some(Codec::Ros2Image),
                                    ("foxglove_msgs/msg/RawImage", "cdr") => {
                                        Some(Codec::FoxgloveCdr)
                                    }
                                    ("foxglove.RawImage", "protobuf") => {
                                        Some(Codec::FoxgloveProtobuf)
                                    }
                                    ("foxglove.RawImage", "json") => Some(Codec::FoxgloveJson),
                                    _ => None,
                                }
                            });
                            match codec {
                                Some(c) => {
                                    tracing::info!(topic = %ch.topic, codec = ?c, "replaying images");
                                    self.image_channel = Some((ch.id, c));
                                }
                                None if self.opts.topic.is_some() => {
                                    let (name, enc) = schema.cloned().unwrap_or_default();
                                    return Err(self.invalid(format!(
                                        "topic {} carries {name} ({enc}, messages {}), not an image type omnirow reads",
                                        ch.topic, ch.message_encoding
                                    )));
                                }
                                None => {}
                            }
                        }
                        Record::Message { header, data } => {
                            if Some(header.channel_id) == self.truth_channel {
                                let json = if self.truth_in_string {
                                    crate::record::decode_ros2_string(&data).unwrap_or(&[])
                                } else {
                                    &data[..]
                                };
                                match serde_json::from_slice::<GroundTruth>(json) {
                                    Ok(t) => {
                                        self.truths.push_back((header.publish_time, Arc::new(t)));
                                        if self.truths.len() > 64 {
                                            self.truths.pop_front();
                                        }
                                    }
                                    Err(e) => tracing::warn!("bad ground truth message: {e}"),
                                }
                                continue;
                            }
                            let Some((id, codec)) = self.image_channel else {
                                continue;
                            };
                            if header.channel_id != id {
                                continue;
                            }
                            match decode(codec, &data, &mut self.scratch) {
                                Ok((stamp, w, h, format)) => {
                                    let capture_ns =
                                        if stamp > 0 { stamp } else { header.log_time };
                                    let truth = self
                                        .truths
                                        .iter()
                                        .position(|(t, _)| *t == capture_ns)
                                        .and_then(|i| self.truths.remove(i))
                                        .map(|(_, t)| t);
                                    let frame = Frame {
                                        seq: self.seq,
                                        capture_ns,
                                        receive_ns: 0,
                                        width: w,
                                        height: h,
                                        format,
                                        data: std::mem::take(&mut self.scratch),
                                        truth,
                                    };
                                    self.seq += 1;
                                    self.frames_this_pass += 1;
                                    // Paced by the capture clock (the camera's frame rate).
                                    return Ok(Some((capture_ns, frame)));
                                }
                                Err(e) => tracing::warn!(
                                    file = %self.opts.path.display(),
                                    message = header.sequence,
                                    "image message skipped: {e}"
                                ),
                            }
                        }
                        _ => {}
                    }
                }
            }
        }
    }
}

/// The calibration attached to a recording (`calibration.toml`, written before the first
/// chunk), if any. Reads only up to the first chunk or message.
pub fn recorded_calibration(
    path: &std::path::Path,
) -> Result<Option<crate::camera::Calibration>, SourceError> {
    let io = |source| SourceError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut file = File::open(path).map_err(io)?;
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_emit_chunks(true)
            .with_record_length_limit(1 << 30),
    );
    while let Some(ev) = reader.next_event() {
        let Ok(ev) = ev else { return Ok(None) };
        match ev {
            LinearReadEvent::ReadRequest(n) => {
                let got = read_retry(&mut file, reader.insert(n)).map_err(io)?;
                reader.notify_read(got);
            }
            LinearReadEvent::Record { opcode, data } => match mcap::parse_record(opcode, data) {
                Ok(Record::Attachment { header, data, .. })
                    if header.name == crate::record::CALIBRATION_ATTACHMENT =>
                {
                    let text = String::from_utf8_lossy(&data);
                    let cal = crate::camera::Calibration::parse_toml(&text, path).map_err(|e| {
                        SourceError::Invalid {
                            path: path.to_path_buf(),
                            problem: format!("attached calibration: {e}"),
                        }
                    })?;
                    return Ok(Some(cal));
                }
                Ok(Record::Chunk { .. }) | Ok(Record::Message { .. }) | Err(_) => return Ok(None),
                Ok(_) => {}
            },
        }
    }
    Ok(None)
}

fn new_reader() -> LinearReader {
    LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_validate_chunk_crcs(true)
            .with_record_length_limit(1 << 30),
    )
}

fn read_retry(f: &mut File, buf: &mut [u8]) -> std::io::Result<usize> {
    loop {
        match f.read(buf) {
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            r => return r,
        }
    }
}

/// Decodes an image message into `out`: (stamp, width, height, format).
fn decode(
    codec: Codec,
    data: &[u8],
    out: &mut Vec<u8>,
) -> Result<(u64, u32, u32, PixelFormat), image_msg::ImageMsgError> {
    let owned;
    let msg: ImageMsg = match codec {
        Codec::Ros2Image => image_msg::decode_ros2_image(data)?,
        Codec::FoxgloveCdr => image_msg::decode_foxglove_cdr(data)?,
        Codec::FoxgloveProtobuf => image_msg::decode_foxglove_protobuf(data)?,
        Codec::FoxgloveJson => {
            let (m, bytes) = image_msg::decode_foxglove_json(data)?;
            owned = bytes;
            ImageMsg { data: &owned, ..m }
        }
    };
    let format = msg.to_pixels(out)?;
    Ok((msg.stamp_ns, msg.width, msg.height, format))
}

impl Source for McapReplay {
    fn describe(&self) -> String {
        format!("MCAP replay of {}", self.opts.path.display())
    }

    fn poll(&mut self, timeout: Duration) -> Result<Poll, SourceError> {
        if self.state == SourceState::Ended {
            return Ok(Poll::End);
        }
        if self.pending.is_none() {
            let next = match self.next_image()? {
                Some(f) => Some(f),
                None if self.opts.looping && self.frames_this_pass > 0 => {
                    self.rewind()?;
                    self.next_image()?
                }
                None => None,
            };
            match next {
                Some(f) => self.pending = Some(f),
                None => {
                    self.state = SourceState::Ended;
                    return Ok(Poll::End);
                }
            }
        }
        let t = self.pending.as_ref().map(|(t, _)| *t).unwrap_or(0);
        if wait_due(&mut self.pacer, t, timeout) {
            self.state = SourceState::Streaming;
            let (_, frame) = self.pending.take().expect("pending frame checked above");
            Ok(Poll::Frame(frame))
        } else {
            Ok(Poll::Idle)
        }
    }

    fn state(&self) -> SourceState {
        self.state
    }

    fn realtime(&self) -> bool {
        self.opts.rate != Rate::Max
    }

    fn calibration(&self) -> Option<&crate::camera::Calibration> {
        self.calibration.as_ref()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::{RecordOptions, Recorder};

    fn frames(n: u64) -> Vec<Frame> {
        (0..n)
            .map(|i| Frame {
                seq: i,
                capture_ns: 1_000_000_000 + i * 66_666_667,
                receive_ns: 2_000_000_000 + i * 66_666_667,
                width: 6,
                height: 4,
                format: if i % 2 == 0 {
                    PixelFormat::BayerRggb8
                } else {
                    PixelFormat::Rgb8
                },
                data: (0..if i % 2 == 0 { 24 } else { 72 })
                    .map(|k| (k as u64 * 7 + i) as u8)
                    .collect(),
                truth: None,
            })
            .collect()
    }

    fn replay_all(path: &std::path::Path) -> Vec<Frame> {
        let mut src = McapReplay::open(McapReplayOptions {
            path: path.to_path_buf(),
            rate: Rate::Max,
            looping: false,
            topic: None,
        })
        .unwrap();
        let mut out = Vec::new();
        loop {
            match src.poll(Duration::from_millis(10)).unwrap() {
                Poll::Frame(f) => out.push(f),
                Poll::Idle => {}
                Poll::End => return out,
            }
        }
    }

    #[test]
    fn record_then_replay_and_truncated_recordings() {
        let dir = std::env::temp_dir().join(format!("omnirow-mcap-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let mut rec = Recorder::new(RecordOptions {
            dir: dir.clone(),
            reserve_bytes: 0,
            ..RecordOptions::default()
        })
        .unwrap();
        let src = frames(5);
        for f in &src {
            rec.write_frame(f).unwrap();
        }
        rec.finish().unwrap();
        let path = rec.files()[0].clone();
        let back = replay_all(&path);
        assert_eq!(back.len(), 5);
        for (a, b) in src.iter().zip(&back) {
            assert_eq!((a.seq, a.capture_ns), (b.seq, b.capture_ns));
            assert_eq!((a.width, a.height, a.format), (b.width, b.height, b.format));
            assert_eq!(a.data, b.data);
        }
        // Cut the file anywhere: every frame whose chunk is complete comes back, never a
        // panic, never a wrong frame.
        let bytes = std::fs::read(&path).unwrap();
        let cut = dir.join("cut.mcap");
        let mut last = 0;
        for len in (200..bytes.len()).step_by(37) {
            std::fs::write(&cut, &bytes[..len]).unwrap();
            let got = replay_all(&cut);
            assert!(got.len() >= last, "more bytes never give fewer frames");
            last = got.len();
            for (a, b) in src.iter().zip(&got) {
                assert_eq!(a.data, b.data);
            }
        }
        assert!(
            last >= 4,
            "a file missing only its summary replays all frames ({last})"
        );
        // Not an MCAP at all: an error naming the file.
        std::fs::write(&cut, b"hello").unwrap();
        let e = McapReplay::open(McapReplayOptions {
            path: cut.clone(),
            rate: Rate::Max,
            looping: false,
            topic: None,
        })
        .err()
        .unwrap()
        .to_string();
        assert!(e.contains("cut.mcap"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
