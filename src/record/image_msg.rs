//! Image messages on the wire: `sensor_msgs/msg/Image` in CDR (written and read), and
//! `foxglove.RawImage` / `foxglove_msgs/msg/RawImage` (read, as protobuf, JSON or CDR).
//!
//! CDR here is XCDR1 little-endian with its 4-byte encapsulation header, as ROS 2 (rmw) and
//! rosbag2 write it: primitives aligned to their size relative to the end of the header,
//! strings as a u32 length including the terminating NUL.

use crate::frame::PixelFormat;

/// The ROS 2 message definition of `sensor_msgs/msg/Image` with its dependencies, in the
/// concatenated form rosbag2 stores as an MCAP schema (encoding `ros2msg`).
pub const ROS2_IMAGE_SCHEMA: &str = "\
# This message contains an uncompressed image
# (0, 0) is at top-left corner of image

std_msgs/Header header # Header timestamp should be acquisition time of image

uint32 height                # image height, that is, number of rows
uint32 width                 # image width, that is, number of columns

string encoding       # Encoding of pixels -- channel meaning, ordering, size

uint8 is_bigendian    # is this data bigendian?
uint32 step           # Full row length in bytes
uint8[] data          # actual matrix data, size is (step * rows)

================================================================================
MSG: std_msgs/Header
# Standard metadata for higher-level stamped data types.

builtin_interfaces/Time stamp
string frame_id

================================================================================
MSG: builtin_interfaces/Time
# This message communicates ROS Time defined here:
# https://design.ros2.org/articles/clock_and_time.html

int32 sec
uint32 nanosec
";

/// Errors decoding an image message.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum ImageMsgError {
    #[error("message truncated at byte {0}")]
    Truncated(usize),
    #[error("unsupported CDR representation {0:#06x} (only little-endian plain CDR)")]
    Representation(u16),
    #[error("unsupported image encoding `{0}` (supported: mono8, 8UC1, rgb8, bgr8, bayer_rggb8, bayer_bggr8, bayer_gbrg8, bayer_grbg8)")]
    Encoding(String),
    #[error("image {width}x{height} `{encoding}` with step {step} needs {need} bytes, message has {have}")]
    Size {
        width: u32,
        height: u32,
        encoding: String,
        step: u32,
        need: usize,
        have: usize,
    },
    #[error("malformed message: {0}")]
    Malformed(String),
}

/// A decoded image message, borrowing its pixel bytes from the message.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageMsg<'a> {
    pub stamp_ns: u64,
    pub frame_id: String,
    pub width: u32,
    pub height: u32,
    pub encoding: String,
    pub step: u32,
    pub data: &'a [u8],
}

/// Appends a `sensor_msgs/msg/Image` in CDR to `out` (cleared first).
pub fn encode_ros2_image(
    out: &mut Vec<u8>,
    stamp_ns: u64,
    frame_id: &str,
    width: u32,
    height: u32,
    format: PixelFormat,
    data: &[u8],
) {
    out.clear();
    out.reserve(64 + frame_id.len() + data.len());
    let mut w = CdrWriter { out };
    w.out.extend_from_slice(&[0x00, 0x01, 0x00, 0x00]);
    w.i32((stamp_ns / 1_000_000_000) as i32);
    w.u32((stamp_ns % 1_000_000_000) as u32);
    w.string(frame_id);
    w.u32(height);
    w.u32(width);
    w.string(format.ros_encoding());
    w.u8(0);
    w.u32(width * format.bytes_per_pixel() as u32);
    w.u32(data.len() as u32);
    w.out.extend_from_slice(data);
}

/// Decodes a `sensor_msgs/msg/Image` in CDR.
pub fn decode_ros2_image(msg: &[u8]) -> Result<ImageMsg<'_>, ImageMsgError> {
    let mut r = CdrReader::new(msg)?;
    let sec = r.i32()?;
    let nsec = r.u32()?;
    let frame_id = r.string()?;
    let height = r.u32()?;
    let width = r.u32()?;
    let encoding = r.string()?;
    let _bigendian = r.u8()?;
    let step = r.u32()?;
    let data = r.bytes()?;
    Ok(ImageMsg {
        stamp_ns: stamp(sec as i64, nsec),
        frame_id,
        width,
        height,
        encoding,
        step,
        data,
    })
}

/// Decodes a `foxglove_msgs/msg/RawImage` in CDR (ROS 2 flavour of foxglove.RawImage).
pub fn decode_foxglove_cdr(msg: &[u8]) -> Result<ImageMsg<'_>, ImageMsgError> {
    let mut r = CdrReader::new(msg)?;
    let sec = r.i32()?;
    let nsec = r.u32()?;
    let frame_id = r.string()?;
    let width = r.u32()?;
    let height = r.u32()?;
    let encoding = r.string()?;
    let step = r.u32()?;
    let data = r.bytes()?;
    Ok(ImageMsg {
        stamp_ns: stamp(sec as i64, nsec),
        frame_id,
        width,
        height,
        encoding,
        step,
        data,
    })
}

/// Decodes a `foxglove.RawImage` in protobuf (timestamp = 1, width = 2, height = 3,
/// encoding = 4, step = 5, data = 6, frame_id = 7).
pub fn decode_foxglove_protobuf(msg: &[u8]) -> Result<ImageMsg<'_>, ImageMsgError> {
    let mut img = ImageMsg {
        stamp_ns: 0,
        frame_id: String::new(),
        width: 0,
        height: 0,
        encoding: String::new(),
        step: 0,
        data: &[],
    };
    let mut p = Proto { buf: msg, pos: 0 };
    while p.pos < msg.len() {
        let key = p.varint()?;
        let (field, wire) = (key >> 3, key & 7);
        match (field, wire) {
            (1, 2) => {
                let ts = p.len_delimited()?;
                let mut q = Proto { buf: ts, pos: 0 };
                let (mut secs, mut nanos) = (0i64, 0u32);
                while q.pos < ts.len() {
                    let k = q.varint()?;
                    match (k >> 3, k & 7) {
                        (1, 0) => secs = q.varint()? as i64,
                        (2, 0) => nanos = q.varint()? as u32,
                        (_, w) => q.skip(w)?,
                    }
                }
                img.stamp_ns = stamp(secs, nanos);
            }
            (2, 5) => img.width = p.fixed32()?,
            (3, 5) => img.height = p.fixed32()?,
            (4, 2) => img.encoding = utf8(p.len_delimited()?)?,
            (5, 5) => img.step = p.fixed32()?,
            (6, 2) => img.data = p.len_delimited()?,
            (7, 2) => img.frame_id = utf8(p.len_delimited()?)?,
            (_, w) => p.skip(w)?,
        }
    }
    Ok(img)
}

/// A decoded `foxglove.RawImage` in JSON owns its pixels (they arrive base64-encoded).
pub fn decode_foxglove_json(msg: &[u8]) -> Result<(ImageMsg<'static>, Vec<u8>), ImageMsgError> {
    #[derive(serde::Deserialize)]
    struct Time {
        sec: i64,
        nsec: u32,
    }
    #[derive(serde::Deserialize)]
    struct Raw {
        timestamp: Option<Time>,
        #[serde(default)]
        frame_id: String,
        width: u32,
        height: u32,
        encoding: String,
        step: u32,
        data: String,
    }
    let raw: Raw =
        serde_json::from_slice(msg).map_err(|e| ImageMsgError::Malformed(e.to_string()))?;
    let data = base64_decode(&raw.data).map_err(ImageMsgError::Malformed)?;
    Ok((
        ImageMsg {
            stamp_ns: raw.timestamp.map(|t| stamp(t.sec, t.nsec)).unwrap_or(0),
            frame_id: raw.frame_id,
            width: raw.width,
            height: raw.height,
            encoding: raw.encoding,
            step: raw.step,
            data: &[],
        },
        data,
    ))
}

impl ImageMsg<'_> {
    /// Converts the pixels to one of omnirow's formats, into `out` (resized): mono8/8UC1 and
    /// rgb8 and bayer_rggb8 are copied (row padding removed), bgr8 is swapped to RGB, and the
    /// other Bayer patterns are demosaiced per 2×2 quad into RGB.
    pub fn to_pixels(&self, out: &mut Vec<u8>) -> Result<PixelFormat, ImageMsgError> {
        let (w, h) = (self.width as usize, self.height as usize);
        let (bpp, kind) = match self.encoding.as_str() {
            "mono8" | "8UC1" => (1, Kind::Copy(PixelFormat::Mono8)),
            "rgb8" | "8UC3" => (3, Kind::Copy(PixelFormat::Rgb8)),
            "bgr8" => (3, Kind::Bgr),
            "bayer_rggb8" => (1, Kind::Copy(PixelFormat::BayerRggb8)),
            "bayer_bggr8" => (1, Kind::Bayer([1, 1])),
            "bayer_gbrg8" => (1, Kind::Bayer([1, 0])),
            "bayer_grbg8" => (1, Kind::Bayer([0, 1])),
            other => return Err(ImageMsgError::Encoding(other.to_string())),
        };
        let step = if self.step == 0 {
            w * bpp
        } else {
            self.step as usize
        };
        let need = if h == 0 { 0 } else { step * (h - 1) + w * bpp };
        if step < w * bpp || self.data.len() < need || w == 0 || h == 0 {
            return Err(ImageMsgError::Size {
                width: self.width,
                height: self.height,
                encoding: self.encoding.clone(),
                step: self.step,
                need: need.max(1),
                have: self.data.len(),
            });
        }
        let row = |r: usize| &self.data[r * step..r * step + w * bpp];
        match kind {
            Kind::Copy(fmt) => {
                out.clear();
                for r in 0..h {
                    out.extend_from_slice(row(r));
                }
                Ok(fmt)
            }
            Kind::Bgr => {
                out.clear();
                for r in 0..h {
                    for p in row(r).chunks_exact(3) {
                        out.extend_from_slice(&[p[2], p[1], p[0]]);
                    }
                }
                Ok(PixelFormat::Rgb8)
            }
            Kind::Bayer(red_at) => {
                // Red sits at (red_at[0], red_at[1]) of each 2×2 quad, blue diagonally
                // opposite, greens on the other two.
                out.clear();
                out.resize(w * h * 3, 0);
                for qr in (0..h & !1).step_by(2) {
                    for qc in (0..w & !1).step_by(2) {
                        let px = |dr: usize, dc: usize| self.data[(qr + dr) * step + qc + dc];
                        let red = px(red_at[0], red_at[1]);
                        let blue = px(1 - red_at[0], 1 - red_at[1]);
                        let green = ((px(red_at[0], 1 - red_at[1]) as u16
                            + px(1 - red_at[0], red_at[1]) as u16)
                            / 2) as u8;
                        for (dr, dc) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                            let i = 3 * ((qr + dr) * w + qc + dc);
                            out[i..i + 3].copy_from_slice(&[red, green, blue]);
                        }
                    }
                }
                Ok(PixelFormat::Rgb8)
            }
        }
    }
}

enum Kind {
    Copy(PixelFormat),
    Bgr,
    /// Position (row, col) of red in the 2×2 quad.
    Bayer([usize; 2]),
}

fn stamp(sec: i64, nsec: u32) -> u64 {
    (sec.max(0) as u64) * 1_000_000_000 + nsec as u64
}

fn utf8(b: &[u8]) -> Result<String, ImageMsgError> {
    String::from_utf8(b.to_vec())
        .map_err(|_| ImageMsgError::Malformed("string is not UTF-8".into()))
}

struct CdrWriter<'a> {
    out: &'a mut Vec<u8>,
}

impl CdrWriter<'_> {
    fn align(&mut self, n: usize) {
        while (self.out.len() - 4) % n != 0 {
            self.out.push(0);
        }
    }
    fn u8(&mut self, v: u8) {
        self.out.push(v);
    }
    fn u32(&mut self, v: u32) {
        self.align(4);
        self.out.extend_from_slice(&v.to_le_bytes());
    }
    fn i32(&mut self, v: i32) {
        self.align(4);
        self.out.extend_from_slice(&v.to_le_bytes());
    }
    fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.out.extend_from_slice(s.as_bytes());
        self.out.push(0);
    }
}

struct CdrReader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> CdrReader<'a> {
    fn new(buf: &'a [u8]) -> Result<Self, ImageMsgError> {
        if buf.len() < 4 {
            return Err(ImageMsgError::Truncated(buf.len()));
        }
        let rep = u16::from_be_bytes([buf[0], buf[1]]);
        // 0x0001 = CDR_LE, 0x0003 = PL_CDR_LE (same layout for final types' plain members).
        if rep != 0x0001 {
            return Err(ImageMsgError::Representation(rep));
        }
        Ok(CdrReader { buf, pos: 4 })
    }
    fn take(&mut self, n: usize) -> Result<&'a [u8], ImageMsgError> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.buf.len())
            .ok_or(ImageMsgError::Truncated(self.buf.len()))?;
        let s = &self.buf[self.pos..end];
        self.pos = end;
        Ok(s)
    }
    fn align(&mut self, n: usize) -> Result<(), ImageMsgError> {
        let pad = (n - (self.pos - 4) % n) % n;
        self.take(pad).map(|_| ())
    }
    fn u8(&mut self) -> Result<u8, ImageMsgError> {
        Ok(self.take(1)?[0])
    }
    fn u32(&mut self) -> Result<u32, ImageMsgError> {
        self.align(4)?;
        let b = self.take(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
    fn i32(&mut self) -> Result<i32, ImageMsgError> {
        Ok(self.u32()? as i32)
    }
    fn string(&mut self) -> Result<String, ImageMsgError> {
        let n = self.u32()? as usize;
        let b = self.take(n)?;
        let b = b.strip_suffix(&[0]).unwrap_or(b);
        utf8(b)
    }
    fn bytes(&mut self) -> Result<&'a [u8], ImageMsgError> {
        let n = self.u32()? as usize;
        self.take(n)
    }
}

struct Proto<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Proto<'a> {
    fn varint(&mut self) -> Result<u64, ImageMsgError> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let b = *self
                .buf
                .get(self.pos)
                .ok_or(ImageMsgError::Truncated(self.pos))?;
            self.pos += 1;
            v |= ((b & 0x7f) as u64) << shift;
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err(ImageMsgError::Malformed(
            "varint longer than 10 bytes".into(),
        ))
    }
    fn take(&mut self, n: usize) -> Result<&'a [u8], ImageMsgError> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.buf.len())
            .ok_or(ImageMsgError::Truncated(self.buf.len()))?;
        let s = &self.buf[self.pos..end];
        self.pos = end;
        Ok(s)
    }
    fn fixed32(&mut self) -> Result<u32, ImageMsgError> {
        let b = self.take(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
    fn len_delimited(&mut self) -> Result<&'a [u8], ImageMsgError> {
        let n = self.varint()? as usize;
        self.take(n)
    }
    fn skip(&mut self, wire: u64) -> Result<(), ImageMsgError> {
        match wire {
            0 => self.varint().map(|_| ()),
            1 => self.take(8).map(|_| ()),
            2 => self.len_delimited().map(|_| ()),
            5 => self.take(4).map(|_| ()),
            w => Err(ImageMsgError::Malformed(format!("protobuf wire type {w}"))),
        }
    }
}

/// Standard base64 (RFC 4648, with or without padding).
fn base64_decode(s: &str) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(s.len() / 4 * 3);
    let (mut acc, mut bits) = (0u32, 0u32);
    for (i, c) in s.bytes().enumerate() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            b'=' => break,
            _ => return Err(format!("invalid base64 character at {i}")),
        };
        acc = (acc << 6) | v as u32;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ros2_image_round_trip() {
        let data: Vec<u8> = (0..30).collect();
        let mut buf = Vec::new();
        encode_ros2_image(
            &mut buf,
            1_700_000_000_123_456_789,
            "cam",
            5,
            2,
            PixelFormat::Rgb8,
            &data,
        );
        // Header, then sec at offset 4, nsec at 8, frame_id length at 12.
        assert_eq!(&buf[..4], &[0, 1, 0, 0]);
        assert_eq!(u32::from_le_bytes(buf[12..16].try_into().unwrap()), 4);
        let m = decode_ros2_image(&buf).unwrap();
        assert_eq!(m.stamp_ns, 1_700_000_000_123_456_789);
        assert_eq!((m.width, m.height, m.step), (5, 2, 15));
        assert_eq!(m.encoding, "rgb8");
        assert_eq!(m.frame_id, "cam");
        let mut px = Vec::new();
        assert_eq!(m.to_pixels(&mut px).unwrap(), PixelFormat::Rgb8);
        assert_eq!(px, data);
        // Every truncation is an error, never a panic.
        for n in 0..buf.len() {
            assert!(decode_ros2_image(&buf[..n]).is_err(), "prefix {n}");
        }
    }

    #[test]
    fn padded_rows_and_bayer_patterns() {
        let m = ImageMsg {
            stamp_ns: 0,
            frame_id: String::new(),
            width: 2,
            height: 2,
            encoding: "bayer_bggr8".into(),
            step: 3,
            data: &[10, 20, 99, 30, 40, 99],
        };
        let mut px = Vec::new();
        assert_eq!(m.to_pixels(&mut px).unwrap(), PixelFormat::Rgb8);
        // BGGR: blue 10 at (0,0), red 40 at (1,1), greens 20 and 30.
        assert_eq!(&px[..3], &[40, 25, 10]);
        let bad = ImageMsg {
            step: 1,
            ..m.clone()
        };
        assert!(matches!(
            bad.to_pixels(&mut px),
            Err(ImageMsgError::Size { .. })
        ));
        let unknown = ImageMsg {
            encoding: "mono16".into(),
            ..m
        };
        assert!(matches!(
            unknown.to_pixels(&mut px),
            Err(ImageMsgError::Encoding(_))
        ));
    }

    #[test]
    fn foxglove_protobuf_and_json() {
        // timestamp {1: 5, 2: 7}, width 2, height 1, encoding "mono8", step 2, data [1, 2].
        let mut m = vec![0x0a, 4, 0x08, 5, 0x10, 7];
        m.extend_from_slice(&[0x15, 2, 0, 0, 0, 0x1d, 1, 0, 0, 0]);
        m.extend_from_slice(&[0x22, 5]);
        m.extend_from_slice(b"mono8");
        m.extend_from_slice(&[0x2d, 2, 0, 0, 0, 0x32, 2, 1, 2, 0x3a, 1, b'f']);
        let img = decode_foxglove_protobuf(&m).unwrap();
        assert_eq!(img.stamp_ns, 5_000_000_007);
        assert_eq!((img.width, img.height, img.step), (2, 1, 2));
        assert_eq!(img.data, &[1, 2]);
        assert_eq!(img.frame_id, "f");
        assert!(decode_foxglove_protobuf(&m[..m.len() - 2]).is_err());

        let json = br#"{"timestamp":{"sec":1,"nsec":2},"frame_id":"x","width":2,"height":1,"encoding":"mono8","step":2,"data":"AQI="}"#;
        let (img, data) = decode_foxglove_json(json).unwrap();
        assert_eq!(img.stamp_ns, 1_000_000_002);
        assert_eq!(data, vec![1, 2]);
    }

    #[test]
    fn base64_matches_known_vectors() {
        assert_eq!(base64_decode("Zm9vYmFy").unwrap(), b"foobar");
        assert_eq!(base64_decode("Zm9vYg==").unwrap(), b"foob");
        assert!(base64_decode("Zm9*").is_err());
    }
}
