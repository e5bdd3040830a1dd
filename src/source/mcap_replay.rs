//! Replay of MCAP recordings: ours, and any MCAP whose images are `sensor_msgs/msg/Image`
//! (CDR) or `foxglove.RawImage` (protobuf, JSON, or `foxglove_msgs/msg/RawImage` in CDR), in
//! mono8, rgb8, bgr8 or 8-bit Bayer.
//!
//! Streams the file from start to end (never loads it whole), paced by the images' capture
//! stamps (the log time where an image has none). Damage does not end a replay: the file is
//! read through [`crate::record::salvage`], which skips a damaged chunk and goes on with the
//! next intact one; each skipped region is logged once with its offset and the frames it held.
//! A file cut short (power loss on the robot) replays every intact frame before the cut and
//! then ends with a warning. Ground truth recorded on `/omnirow/ground_truth` travels with its
//! frame again.

use super::{wait_due, Pacer, Poll, Rate, Source, SourceError, SourceState};
use crate::frame::{Frame, PixelFormat};
use crate::gige::{FramePool, Recycler};
use crate::record::image_msg::{self, ImageMsg};
use crate::record::salvage::{Damage, Event, Salvage, SalvageError};
use crate::record::TRUTH_TOPIC;
use crate::synth::GroundTruth;
use mcap::records::Record;
use std::collections::{HashMap, HashSet, VecDeque};
use std::fs::File;
use std::path::{Path, PathBuf};
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

/// Idle pixel buffers a replay keeps for reuse: one for the frame it holds back until it is
/// due, one queued, one in the detector and one the pipeline keeps as the latest.
const REPLAY_BUFFERS: usize = 4;

/// Replays the images of an MCAP file.
pub struct McapReplay {
    opts: McapReplayOptions,
    reader: Salvage<File>,
    schemas: HashMap<u16, (String, String)>,
    /// Channel ids defined so far.
    defined: HashSet<u16>,
    image_channel: Option<(u16, Codec)>,
    truth_channel: Option<u16>,
    /// The truth channel holds JSON inside `std_msgs/msg/String` (record.json_channels).
    truth_in_string: bool,
    truths: VecDeque<(u64, Arc<GroundTruth>)>,
    pacer: Pacer,
    pending: Option<(u64, Frame)>,
    seq: u64,
    frames_this_pass: u64,
    state: SourceState,
    /// Pixel buffers the pipeline gave back: each frame is decoded into one, so a replay
    /// in steady state touches no fresh pages (and the detector's cores are not kept busy
    /// faulting them in while it runs).
    buffers: FramePool,
    calibration: Option<crate::camera::Calibration>,
}

impl McapReplay {
    /// Opens the file (errors name it).
    pub fn open(opts: McapReplayOptions) -> Result<Self, SourceError> {
        let reader = open_salvage(&opts.path)?;
        let calibration = recorded_calibration(&opts.path)?;
        Ok(McapReplay {
            pacer: Pacer::new(opts.rate),
            opts,
            reader,
            schemas: HashMap::new(),
            defined: HashSet::new(),
            image_channel: None,
            truth_channel: None,
            truth_in_string: false,
            truths: VecDeque::new(),
            pending: None,
            seq: 0,
            frames_this_pass: 0,
            state: SourceState::Starting,
            buffers: FramePool::new(REPLAY_BUFFERS),
            calibration,
        })
    }

    fn rewind(&mut self) -> Result<(), SourceError> {
        self.reader = open_salvage(&self.opts.path)?;
        self.schemas.clear();
        self.defined.clear();
        self.image_channel = None;
        self.truth_channel = None;
        self.truths.clear();
        self.pacer.next_pass();
        self.frames_this_pass = 0;
        Ok(())
    }

    /// Reads records until the next image of the replayed channel: `(pace time, frame)`, or
    /// `None` at the end of the file (clean or cut short). Damaged regions are skipped and
    /// logged once each.
    fn next_image(&mut self) -> Result<Option<(u64, Frame)>, SourceError> {
        let path = &self.opts.path;
        loop {
            let event = self
                .reader
                .next_event()
                .map_err(|e| salvage_error(path, e))?;
            let record = match event {
                None => {
                    if self.image_channel.is_none() && !self.reader.report().is_clean() {
                        tracing::warn!(
                            file = %path.display(),
                            "no image channel survived: the recording is cut short or damaged before its channel definitions"
                        );
                        return Ok(None);
                    }
                    if self.image_channel.is_none() {
                        return Err(SourceError::Invalid {
                            path: path.clone(),
                            problem: format!(
                                "no image channel{} (supported: sensor_msgs/msg/Image in CDR, foxglove.RawImage)",
                                self.opts
                                    .topic
                                    .as_ref()
                                    .map(|t| format!(" on topic {t}"))
                                    .unwrap_or_default()
                            ),
                        });
                    }
                    if !self.reader.report().complete {
                        tracing::warn!(
                            file = %path.display(),
                            frames = self.frames_this_pass,
                            at_byte = self.reader.report().file_len,
                            "recording cut short (no summary at its end): replayed every intact frame before the cut"
                        );
                    }
                    return Ok(None);
                }
                Some(Event::ChunkEnd) => continue,
                Some(Event::Damage(d)) => {
                    log_damage(path, d, self.image_channel.map(|(id, _)| id));
                    continue;
                }
                Some(Event::Record(r)) => r,
            };
            match record {
                Record::Schema { header, .. } => {
                    self.schemas
                        .insert(header.id, (header.name, header.encoding));
                }
                Record::Channel(ch) => {
                    self.defined.insert(ch.id);
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
                            ("foxglove_msgs/msg/RawImage", "cdr") => Some(Codec::FoxgloveCdr),
                            ("foxglove.RawImage", "protobuf") => Some(Codec::FoxgloveProtobuf),
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
                            return Err(SourceError::Invalid {
                                path: path.clone(),
                                problem: format!(
                                    "topic {} carries {name} ({enc}, messages {}), not an image type omnirow reads",
                                    ch.topic, ch.message_encoding
                                ),
                            });
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
                    // A buffer the pipeline gave back (grown, not allocated, when it is
                    // too small): the frame's pixels, or back to the pool.
                    let (mut pixels, _) = self.buffers.take(0);
                    if self.image_channel.is_none()
                        && self.opts.topic.is_none()
                        && !self.defined.contains(&header.channel_id)
                        && decode(Codec::Ros2Image, &data, &mut pixels).is_ok()
                    {
                        // The channel definitions were lost to damage (and no intact summary
                        // lends them): an undefined channel whose messages decode as
                        // sensor_msgs/msg/Image is the image channel.
                        tracing::warn!(
                            file = %path.display(),
                            channel = header.channel_id,
                            "channel definitions lost to damage: replaying the undefined channel whose messages are sensor_msgs/msg/Image"
                        );
                        self.image_channel = Some((header.channel_id, Codec::Ros2Image));
                    }
                    let Some((_, codec)) = self
                        .image_channel
                        .filter(|(id, _)| *id == header.channel_id)
                    else {
                        self.buffers.give_back(pixels);
                        continue;
                    };
                    match decode(codec, &data, &mut pixels) {
                        Ok((stamp, w, h, format)) => {
                            let capture_ns = if stamp > 0 { stamp } else { header.log_time };
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
                                data: pixels,
                                truth,
                            };
                            self.seq += 1;
                            self.frames_this_pass += 1;
                            // Paced by the capture clock (the camera's frame rate).
                            return Ok(Some((capture_ns, frame)));
                        }
                        Err(e) => {
                            self.buffers.give_back(pixels);
                            tracing::warn!(
                                file = %path.display(),
                                message = header.sequence,
                                "image message skipped: {e}"
                            )
                        }
                    }
                }
                _ => {}
            }
        }
    }
}

/// Logs a skipped region once: where, why, and the frames it held.
fn log_damage(path: &Path, d: &Damage, image_channel: Option<u16>) {
    let frames = match image_channel.and_then(|c| d.held_on(c)) {
        Some(n) => n.to_string(),
        None => "unknown".into(),
    };
    if d.cut_short {
        tracing::warn!(
            file = %path.display(),
            offset = d.offset,
            bytes = d.len,
            frames_lost = %frames,
            "recording cut short: the last {} bytes are incomplete ({})",
            d.len,
            d.reason
        );
    } else {
        tracing::warn!(
            file = %path.display(),
            offset = d.offset,
            bytes = d.len,
            frames_lost = %frames,
            "damaged region skipped ({}); replay goes on with the next intact chunk",
            d.reason
        );
    }
}

fn salvage_error(path: &Path, e: SalvageError) -> SourceError {
    match e {
        SalvageError::Io(source) => SourceError::Io {
            path: path.to_path_buf(),
            source,
        },
        e => SourceError::Invalid {
            path: path.to_path_buf(),
            problem: e.to_string(),
        },
    }
}

/// Opens `path` for salvage reading.
fn open_salvage(path: &Path) -> Result<Salvage<File>, SourceError> {
    let file = File::open(path).map_err(|source| SourceError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    Salvage::new(file).map_err(|e| salvage_error(path, e))
}

/// The calibration attached to a recording (`calibration.toml`, written before the first
/// chunk), if any. Reads only up to the end of the first intact chunk or message.
pub fn recorded_calibration(
    path: &std::path::Path,
) -> Result<Option<crate::camera::Calibration>, SourceError> {
    let mut reader = match open_salvage(path) {
        Ok(r) => r,
        Err(SourceError::Io { source, .. }) => {
            return Err(SourceError::Io {
                path: path.to_path_buf(),
                source,
            })
        }
        Err(_) => return Ok(None),
    };
    loop {
        match reader.next_event() {
            Ok(Some(Event::Record(Record::Attachment { header, data, .. })))
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
            Ok(Some(Event::ChunkEnd | Event::Record(Record::Message { .. }))) | Ok(None) => {
                return Ok(None)
            }
            Ok(Some(_)) => {}
            Err(SalvageError::Io(source)) => {
                return Err(SourceError::Io {
                    path: path.to_path_buf(),
                    source,
                })
            }
            Err(_) => return Ok(None),
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

    fn recycler(&self) -> Option<Recycler> {
        Some(self.buffers.recycler())
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

    /// `n` frames recorded into a fresh `dir`: the file and the frames.
    fn recorded(dir: &Path, n: u64) -> (PathBuf, Vec<Frame>) {
        let _ = std::fs::remove_dir_all(dir);
        let mut rec = Recorder::new(RecordOptions {
            dir: dir.to_path_buf(),
            reserve_bytes: 0,
            ..RecordOptions::default()
        })
        .unwrap();
        let src = frames(n);
        for f in &src {
            rec.write_frame(f).unwrap();
        }
        rec.finish().unwrap();
        (rec.files()[0].clone(), src)
    }

    #[test]
    fn frames_are_decoded_into_the_buffers_given_back() {
        let dir = std::env::temp_dir().join(format!("omnirow-mcap-pool-{}", std::process::id()));
        let (path, src) = recorded(&dir, 6);
        let mut replay = McapReplay::open(McapReplayOptions {
            path,
            rate: Rate::Max,
            looping: false,
            topic: None,
        })
        .unwrap();
        let recycler = replay.recycler().expect("a replay recycles its buffers");
        let mut next = || loop {
            match replay.poll(Duration::from_millis(10)).unwrap() {
                Poll::Frame(f) => return Some(f),
                Poll::Idle => {}
                Poll::End => return None,
            }
        };
        // Frames 0 and 1 come in fresh buffers; frame 0's, given back, holds frame 2's
        // pixels.
        let first = next().unwrap();
        let second = next().unwrap();
        let at = first.data.as_ptr();
        recycler.recycle(first.data);
        let third = next().unwrap();
        assert_eq!(third.data.as_ptr(), at);
        for (a, b) in src[1..].iter().zip([&second, &third]) {
            assert_eq!((a.seq, a.format, &a.data), (b.seq, b.format, &b.data));
        }
        let rest: Vec<Frame> = std::iter::from_fn(next).collect();
        assert_eq!(rest.len(), 3);
        for (a, b) in src[3..].iter().zip(&rest) {
            assert_eq!(a.data, b.data);
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn record_then_replay_and_truncated_recordings() {
        let dir = std::env::temp_dir().join(format!("omnirow-mcap-{}", std::process::id()));
        let (path, src) = recorded(&dir, 5);
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
