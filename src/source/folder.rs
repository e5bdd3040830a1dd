//! Replay of a folder of images (PNG, JPEG, PGM/PPM), in file-name order.
//!
//! Image files carry no timestamps: frame `i` is captured at `i / fps` seconds (since the
//! epoch), so replays are deterministic. Greyscale images become Mono8 frames, everything
//! else RGB8. A file that cannot be decoded is skipped with a warning naming it.

use super::{wait_due, Pacer, Poll, Rate, Source, SourceError, SourceState};
use crate::frame::{Frame, PixelFormat};
use std::path::PathBuf;
use std::time::Duration;

/// What to replay and how.
#[derive(Debug, Clone, PartialEq)]
pub struct FolderOptions {
    pub dir: PathBuf,
    /// Nominal frame rate of the folder (the "recorded" rate).
    pub fps: f64,
    pub rate: Rate,
    pub looping: bool,
}

/// Replays the images of a folder.
pub struct FolderReplay {
    opts: FolderOptions,
    files: Vec<PathBuf>,
    next: usize,
    seq: u64,
    delivered_this_pass: u64,
    pacer: Pacer,
    pending: Option<Frame>,
    state: SourceState,
}

/// The image file extensions a folder replay reads.
pub const EXTENSIONS: [&str; 6] = ["png", "jpg", "jpeg", "pgm", "ppm", "pnm"];

impl FolderReplay {
    /// Lists the folder (errors name it; an empty folder is an error).
    pub fn open(opts: FolderOptions) -> Result<Self, SourceError> {
        let io = |source| SourceError::Io {
            path: opts.dir.clone(),
            source,
        };
        let mut files: Vec<PathBuf> = std::fs::read_dir(&opts.dir)
            .map_err(io)?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.extension()
                    .and_then(|e| e.to_str())
                    .is_some_and(|e| EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
            })
            .collect();
        files.sort();
        if files.is_empty() {
            return Err(SourceError::Invalid {
                path: opts.dir.clone(),
                problem: format!("no images ({}) in the folder", EXTENSIONS.join(", ")),
            });
        }
        Ok(FolderReplay {
            pacer: Pacer::new(opts.rate),
            opts,
            files,
            next: 0,
            seq: 0,
            delivered_this_pass: 0,
            pending: None,
            state: SourceState::Starting,
        })
    }

    fn load(&mut self) -> Option<Frame> {
        while self.next < self.files.len() {
            let path = &self.files[self.next];
            self.next += 1;
            let img = match image::open(path) {
                Ok(i) => i,
                Err(e) => {
                    tracing::warn!(file = %path.display(), "image skipped: {e}");
                    continue;
                }
            };
            let (format, data, w, h) = match img {
                image::DynamicImage::ImageLuma8(g) => (
                    PixelFormat::Mono8,
                    g.as_raw().clone(),
                    g.width(),
                    g.height(),
                ),
                other => {
                    let rgb = other.to_rgb8();
                    (
                        PixelFormat::Rgb8,
                        rgb.as_raw().clone(),
                        rgb.width(),
                        rgb.height(),
                    )
                }
            };
            let frame = Frame {
                seq: self.seq,
                capture_ns: (self.seq as f64 * 1e9 / self.opts.fps).round() as u64,
                receive_ns: 0,
                width: w,
                height: h,
                format,
                data,
                truth: None,
            };
            self.seq += 1;
            self.delivered_this_pass += 1;
            return Some(frame);
        }
        None
    }
}

impl Source for FolderReplay {
    fn describe(&self) -> String {
        format!(
            "folder replay of {} ({} images)",
            self.opts.dir.display(),
            self.files.len()
        )
    }

    fn poll(&mut self, timeout: Duration) -> Result<Poll, SourceError> {
        if self.state == SourceState::Ended {
            return Ok(Poll::End);
        }
        if self.pending.is_none() {
            let mut f = self.load();
            if f.is_none() && self.opts.looping && self.delivered_this_pass > 0 {
                self.next = 0;
                self.delivered_this_pass = 0;
                f = self.load();
            }
            match f {
                Some(f) => self.pending = Some(f),
                None => {
                    if self.seq == 0 {
                        return Err(SourceError::Invalid {
                            path: self.opts.dir.clone(),
                            problem: "none of the images could be decoded".into(),
                        });
                    }
                    self.state = SourceState::Ended;
                    return Ok(Poll::End);
                }
            }
        }
        let t = self.pending.as_ref().map(|f| f.capture_ns).unwrap_or(0);
        if wait_due(&mut self.pacer, t, timeout) {
            self.state = SourceState::Streaming;
            Ok(Poll::Frame(self.pending.take().expect("checked above")))
        } else {
            Ok(Poll::Idle)
        }
    }

    fn state(&self) -> SourceState {
        self.state
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folder_replays_in_name_order_and_skips_bad_files() {
        let dir = std::env::temp_dir().join(format!("omnirow-folder-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        image::GrayImage::from_pixel(4, 3, image::Luma([7]))
            .save(dir.join("b.png"))
            .unwrap();
        image::RgbImage::from_pixel(4, 3, image::Rgb([1, 2, 3]))
            .save(dir.join("a.png"))
            .unwrap();
        std::fs::write(dir.join("c.jpg"), b"not a jpeg").unwrap();
        std::fs::write(dir.join("notes.txt"), b"ignored").unwrap();
        let mut src = FolderReplay::open(FolderOptions {
            dir: dir.clone(),
            fps: 10.0,
            rate: Rate::Max,
            looping: false,
        })
        .unwrap();
        let t = Duration::from_millis(10);
        let Poll::Frame(a) = src.poll(t).unwrap() else {
            panic!("expected a frame")
        };
        assert_eq!((a.format, a.seq, a.capture_ns), (PixelFormat::Rgb8, 0, 0));
        let Poll::Frame(b) = src.poll(t).unwrap() else {
            panic!("expected a frame")
        };
        assert_eq!((b.format, b.capture_ns), (PixelFormat::Mono8, 100_000_000));
        assert!(matches!(src.poll(t).unwrap(), Poll::End));
        assert_eq!(src.state(), SourceState::Ended);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
