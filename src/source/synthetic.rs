//! The synthetic drive: the synthetic field rendered frame after frame while the robot drives
//! along the rows, with a slowly varying heading, pitch and lateral offset, at a given frame
//! rate. The node's embedded default source (no camera, no files).
//!
//! The field is the synthetic field of [`crate::synth`] (a fixed lattice of plants, so it
//! stays put while the robot moves); the renderer is built once and renders into a recycled
//! buffer. Each frame carries its [`GroundTruth`], so the published estimates can be checked
//! live. The frames go through an ideal lens of the options' size, or through a given
//! calibration ([`SyntheticDrive::through`]); the ground can be a photograph's
//! ([`SyntheticDrive::with_photo_ground`]: real plants, straight rows). Frames are due at `start + i / fps`; a renderer slower than that delivers late
//! frames rather than skipping any. Also owns `[source.synthetic]`'s keys and checks
//! ([`SyntheticConfig`]): the drive's, and the photograph's paths and options
//! ([`PhotoSource`]), which the node reads when it starts.

use super::{Poll, Source, SourceError, SourceState};
use crate::camera::{Calibration, IdealLens};
use crate::check::{Check, Raw};
use crate::frame::{now_ns, Frame};
use crate::synth::photo::{PhotoGround, PhotoOptions};
use crate::synth::{GroundTruth, Renderer, Scene, Style, SynthError, SynthOptions};
use serde::Deserialize;
use std::f64::consts::TAU;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};
use toml::Spanned;

/// Settings of the drive: `[source.synthetic]` of the node's configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct SyntheticDriveOptions {
    pub fps: f64,
    pub width: u32,
    pub height: u32,
    pub lens: IdealLens,
    /// Bayer RGGB colour frames (as the GC2450C delivers); false: the paper's grey style.
    pub colour: bool,
    pub seed: u64,
    pub speed_mps: f64,
    pub heading_amplitude_deg: f64,
    pub pitch_amplitude_deg: f64,
    pub offset_amplitude_m: f64,
    pub period_s: f64,
    /// When positive: at this time, seconds, the robot crosses to the next inter-row path on
    /// its left (one spacing, over [`CROSSING_S`]), its yaw following its sideways motion.
    pub cross_at_s: f64,
    /// Curvature of the rows, 1/m, positive bending left (0: straight): the robot drives
    /// along concentric rows (its yaw and offset relative to their tangents), see
    /// [`SynthOptions::curvature_per_m`].
    pub curvature_per_m: f64,
    /// When positive: the rows end this far along from the drive's start, metres (the
    /// robot drives on into the bare headland).
    pub rows_end_m: f64,
    /// When `gap_length_m` is positive: an empty stretch (no plant in any row) from
    /// `gap_start_m` along, metres.
    pub gap_start_m: f64,
    pub gap_length_m: f64,
    /// Render threads (0: as many as the machine has).
    pub render_threads: usize,
}

/// How long the crossing to the next inter-row path takes, seconds.
pub const CROSSING_S: f64 = 4.0;

/// `[source.synthetic]` as written.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSynthetic {
    fps: Raw<f64>,
    width: Raw<u32>,
    height: Raw<u32>,
    lens: Raw<IdealLens>,
    colour: Raw<bool>,
    seed: Raw<u64>,
    speed_mps: Raw<f64>,
    heading_amplitude_deg: Raw<f64>,
    pitch_amplitude_deg: Raw<f64>,
    offset_amplitude_m: Raw<f64>,
    period_s: Raw<f64>,
    cross_at_s: Raw<f64>,
    curvature_per_m: Raw<f64>,
    rows_end_m: Raw<f64>,
    gap_start_m: Raw<f64>,
    gap_length_m: Raw<f64>,
    photo: Raw<String>,
    photo_labels: Raw<String>,
    photo_focal_px: Raw<f64>,
    photo_band_spacings: Raw<usize>,
    photo_max_sampling_m: Raw<f64>,
    photo_row_spacing_m: Raw<f64>,
}

/// `[source.synthetic]`, checked: the drive, whether its size was written, and the
/// photograph whose ground it drives over.
#[derive(Debug, Clone, PartialEq)]
pub struct SyntheticConfig {
    pub drive: SyntheticDriveOptions,
    /// `width` or `height` was written: through a calibration file (`[camera] calibration`)
    /// the frames are then the calibration rescaled to that size, else the calibration's own.
    pub size_given: bool,
    pub photo: Option<PhotoSource>,
}

/// A labelled perspective photograph whose ground the drive renders (`photo`,
/// `photo_labels` and the `photo_*` options). It is read when the node starts.
#[derive(Debug, Clone, PartialEq)]
pub struct PhotoSource {
    pub image: PathBuf,
    /// The folder of its label: NAME.json polylines or a mask image NAME.png/.jpg.
    pub labels: PathBuf,
    pub options: PhotoOptions,
}

impl RawSynthetic {
    /// Checks `[source.synthetic]`: the drive's options and the photograph's.
    pub(crate) fn validate(self, c: &mut Check) -> SyntheticConfig {
        let size_given = self.width.is_some() || self.height.is_some();
        let drive = self.drive(c);
        let photo = self.photo(c);
        if let (Some(_), Some(p)) = (&photo, &self.photo) {
            for (key, set) in [
                ("curvature_per_m", drive.curvature_per_m != 0.0),
                ("rows_end_m", drive.rows_end_m > 0.0),
                ("gap_length_m", drive.gap_length_m > 0.0),
            ] {
                if set {
                    c.bad(
                        "source.synthetic.photo",
                        p,
                        format!("a photograph's ground has straight rows without an end or an empty stretch: remove source.synthetic.{key} or the photograph"),
                    );
                }
            }
        }
        SyntheticConfig {
            drive,
            size_given,
            photo,
        }
    }

    /// The photograph's keys: `photo` and `photo_labels` both or neither; the options only
    /// with them.
    fn photo(&self, c: &mut Check) -> Option<PhotoSource> {
        let path = |c: &mut Check, key: &str, v: &Spanned<String>| {
            if v.get_ref().is_empty() {
                c.bad(key, v, "must name a file or folder");
            }
            PathBuf::from(v.get_ref())
        };
        let (image, labels) = match (&self.photo, &self.photo_labels) {
            (Some(i), Some(l)) => (
                path(c, "source.synthetic.photo", i),
                path(c, "source.synthetic.photo_labels", l),
            ),
            (Some(i), None) => {
                c.bad(
                    "source.synthetic.photo",
                    i,
                    "needs source.synthetic.photo_labels (the folder of its label: NAME.json polylines or a mask NAME.png/.jpg)",
                );
                return None;
            }
            (None, Some(l)) => {
                c.bad(
                    "source.synthetic.photo_labels",
                    l,
                    "needs source.synthetic.photo (the photograph it labels)",
                );
                return None;
            }
            (None, None) => {
                self.photo_options_without_photo(c);
                return None;
            }
        };
        let d = PhotoOptions::default();
        let mut options = PhotoOptions {
            max_sampling_m: c.range(
                "source.synthetic.photo_max_sampling_m",
                &self.photo_max_sampling_m,
                d.max_sampling_m,
                0.001,
                1.0,
            ),
            max_band_spacings: c.range(
                "source.synthetic.photo_band_spacings",
                &self.photo_band_spacings,
                d.max_band_spacings,
                1,
                20,
            ),
            ..d
        };
        options.rectify.row_spacing_m = c.range(
            "source.synthetic.photo_row_spacing_m",
            &self.photo_row_spacing_m,
            options.rectify.row_spacing_m,
            0.05,
            5.0,
        );
        options.rectify.focal_px = self.photo_focal_px.as_ref().map(|_| {
            c.range(
                "source.synthetic.photo_focal_px",
                &self.photo_focal_px,
                1000.0,
                1.0,
                100_000.0,
            )
        });
        Some(PhotoSource {
            image,
            labels,
            options,
        })
    }

    /// A photograph's option written without a photograph is a mistake worth naming.
    fn photo_options_without_photo(&self, c: &mut Check) {
        let spans = [
            (
                "photo_focal_px",
                self.photo_focal_px.as_ref().map(Spanned::span),
            ),
            (
                "photo_band_spacings",
                self.photo_band_spacings.as_ref().map(Spanned::span),
            ),
            (
                "photo_max_sampling_m",
                self.photo_max_sampling_m.as_ref().map(Spanned::span),
            ),
            (
                "photo_row_spacing_m",
                self.photo_row_spacing_m.as_ref().map(Spanned::span),
            ),
        ];
        for (key, span) in spans {
            if let Some(s) = span {
                c.bad_at(
                    format!("source.synthetic.{key}"),
                    Some(s.start),
                    "applies to a photograph's ground: set source.synthetic.photo and photo_labels too".into(),
                );
            }
        }
    }

    /// The drive's own keys.
    fn drive(&self, c: &mut Check) -> SyntheticDriveOptions {
        let width = c.range("source.synthetic.width", &self.width, 612, 32, 8192);
        let height = c.range("source.synthetic.height", &self.height, 512, 32, 8192);
        for (k, v, x) in [
            ("source.synthetic.width", &self.width, width),
            ("source.synthetic.height", &self.height, height),
        ] {
            if let Some(s) = v {
                if x % 2 != 0 {
                    c.bad(k, s, format!("{x} must be even (Bayer quads)"));
                }
            }
        }
        SyntheticDriveOptions {
            fps: c.range("source.synthetic.fps", &self.fps, 15.0, 0.1, 1000.0),
            width,
            height,
            lens: c.get(&self.lens, IdealLens::Fisheye185),
            colour: c.get(&self.colour, true),
            seed: c.get(&self.seed, 1),
            speed_mps: c.range(
                "source.synthetic.speed_mps",
                &self.speed_mps,
                1.0,
                0.0,
                20.0,
            ),
            heading_amplitude_deg: c.range(
                "source.synthetic.heading_amplitude_deg",
                &self.heading_amplitude_deg,
                8.0,
                0.0,
                45.0,
            ),
            pitch_amplitude_deg: c.range(
                "source.synthetic.pitch_amplitude_deg",
                &self.pitch_amplitude_deg,
                3.0,
                0.0,
                15.0,
            ),
            offset_amplitude_m: c.range(
                "source.synthetic.offset_amplitude_m",
                &self.offset_amplitude_m,
                0.1,
                0.0,
                5.0,
            ),
            period_s: c.range("source.synthetic.period_s", &self.period_s, 20.0, 0.1, 1e6),
            cross_at_s: c.range(
                "source.synthetic.cross_at_s",
                &self.cross_at_s,
                0.0,
                0.0,
                1e6,
            ),
            curvature_per_m: c.range(
                "source.synthetic.curvature_per_m",
                &self.curvature_per_m,
                0.0,
                -0.2,
                0.2,
            ),
            rows_end_m: c.range(
                "source.synthetic.rows_end_m",
                &self.rows_end_m,
                0.0,
                0.0,
                10_000.0,
            ),
            gap_start_m: c.range(
                "source.synthetic.gap_start_m",
                &self.gap_start_m,
                0.0,
                0.0,
                10_000.0,
            ),
            gap_length_m: c.range(
                "source.synthetic.gap_length_m",
                &self.gap_length_m,
                0.0,
                0.0,
                1_000.0,
            ),
            render_threads: 0,
        }
    }
}

/// The robot's pose relative to the rows at time `t` seconds: (yaw°, pitch°, lateral m,
/// along m). Heading, pitch and offset are sinusoids with incommensurate phases; with
/// `cross_at_s` the lateral position also steps by one spacing (a smoothstep over
/// [`CROSSING_S`]) and the yaw turns with the sideways speed (atan(ẏ / v)).
pub fn drive_pose(o: &SyntheticDriveOptions, spacing_m: f64, t: f64) -> (f64, f64, f64, f64) {
    let w = TAU / o.period_s;
    let mut yaw = o.heading_amplitude_deg * (w * t).sin();
    let pitch = o.pitch_amplitude_deg * (0.73 * w * t + 1.0).sin();
    let mut lateral = spacing_m / 2.0 + o.offset_amplitude_m * (1.31 * w * t + 2.0).sin();
    if o.cross_at_s > 0.0 {
        let u = ((t - o.cross_at_s) / CROSSING_S).clamp(0.0, 1.0);
        lateral += spacing_m * u * u * (3.0 - 2.0 * u);
        let sideways = spacing_m * 6.0 * u * (1.0 - u) / CROSSING_S;
        yaw += sideways.atan2(o.speed_mps.max(0.1)).to_degrees();
    }
    (yaw, pitch, lateral, o.speed_mps * t)
}

/// The synthetic drive source.
pub struct SyntheticDrive {
    opts: SyntheticDriveOptions,
    base: SynthOptions,
    renderer: Renderer,
    cal: Calibration,
    start: Option<Instant>,
    start_ns: u64,
    seq: u64,
    state: SourceState,
    spare: Vec<u8>,
    photo: Option<Arc<PhotoGround>>,
}

impl SyntheticDrive {
    /// Builds the renderer (heavy, once) for the options' ideal lens at their size.
    pub fn new(opts: SyntheticDriveOptions) -> Result<Self, SynthError> {
        let cal = opts
            .lens
            .calibration(opts.height, opts.width)
            .map_err(|e| SynthError::Calibration(e.to_string()))?;
        Self::through(opts, cal)
    }

    /// The drive rendered through `cal` (its size; the options' lens, width and height are
    /// not used). Bayer frames need even sides: with an odd one, `colour` gives RGB frames.
    pub fn through(mut opts: SyntheticDriveOptions, cal: Calibration) -> Result<Self, SynthError> {
        (opts.height, opts.width) = cal.size();
        let whole_quads = opts.width % 2 == 0 && opts.height % 2 == 0;
        let mut renderer = Renderer::new(&cal)?;
        if opts.render_threads > 0 {
            renderer = renderer.with_threads(opts.render_threads);
        }
        let base = SynthOptions {
            style: match (opts.colour, whole_quads) {
                (true, true) => Style::Bayer,
                (true, false) => Style::Colour,
                (false, _) => Style::Grey,
            },
            plant_distance_m: 0.05,
            samples: 2,
            curvature_per_m: opts.curvature_per_m,
            rows_end_m: (opts.rows_end_m > 0.0).then_some(opts.rows_end_m),
            // the field reaches past the rows' end (the headland's bare ground beyond it is
            // part of the field), however far along it lies
            field_half_length_m: SynthOptions::default()
                .field_half_length_m
                .max(opts.rows_end_m + 60.0),
            gap_m: (opts.gap_length_m > 0.0)
                .then_some([opts.gap_start_m, opts.gap_start_m + opts.gap_length_m]),
            ..SynthOptions::default()
        };
        base.validate()?;
        Ok(SyntheticDrive {
            opts,
            base,
            renderer,
            cal,
            start: None,
            start_ns: 0,
            seq: 0,
            state: SourceState::Starting,
            spare: Vec::new(),
            photo: None,
        })
    }

    /// The drive over a photograph's ground: its real plants, tiled along and across the
    /// rows at its rectification's spacing. Only straight rows with neither an empty
    /// stretch nor an end: an error names the drive's option that does not fit.
    pub fn with_photo_ground(mut self, ground: Arc<PhotoGround>) -> Result<Self, SynthError> {
        self.base.row_spacing_m = ground.row_spacing_m();
        // the scene checks what a photograph's ground cannot show
        Scene::new(&self.base, self.opts.seed, &self.cal.mounting)?
            .with_photo_ground(ground.clone())?;
        self.photo = Some(ground);
        Ok(self)
    }

    /// The calibration the frames are rendered through (the detector should use it).
    pub fn calibration(&self) -> &Calibration {
        &self.cal
    }

    /// Frame `seq` of the drive (at `seq / fps` seconds, capture time counted from 0),
    /// rendered now whatever the clock: for evaluations that run the drive as fast as they
    /// can.
    pub fn frame_at(&mut self, seq: u64) -> Result<Frame, SynthError> {
        let t = seq as f64 / self.opts.fps;
        let (data, truth) = self.render(t)?;
        let (width, height) = self.renderer.size();
        Ok(Frame {
            seq,
            capture_ns: (t * 1e9) as u64 + 1,
            receive_ns: 0,
            width,
            height,
            format: self.base.style.pixel_format(),
            data,
            truth: Some(Arc::new(truth)),
        })
    }

    /// Hands a frame's buffer back for the next render.
    pub fn recycle(&mut self, data: Vec<u8>) {
        self.spare = data;
    }

    fn render(&mut self, t: f64) -> Result<(Vec<u8>, GroundTruth), SynthError> {
        let (yaw, pitch, lateral, along) = drive_pose(&self.opts, self.base.row_spacing_m, t);
        let o = SynthOptions {
            yaw_deg: yaw,
            pitch_deg: pitch,
            lateral_m: lateral,
            along_m: along,
            ..self.base.clone()
        };
        let mut scene = Scene::new(&o, self.opts.seed, &self.cal.mounting)?;
        if let Some(g) = &self.photo {
            scene = scene.with_photo_ground(g.clone())?;
        }
        let mut buf = std::mem::take(&mut self.spare);
        buf.resize(self.renderer.buffer_len(o.style), 0);
        self.renderer.render_into(&scene, &mut buf)?;
        Ok((buf, GroundTruth::of_scene(&scene, &self.cal)))
    }
}

impl Source for SyntheticDrive {
    fn describe(&self) -> String {
        let ground = if self.photo.is_some() {
            ", a photograph's ground"
        } else {
            ""
        };
        format!(
            "synthetic drive ({}x{}, {} fps, seed {}{ground})",
            self.opts.width, self.opts.height, self.opts.fps, self.opts.seed
        )
    }

    fn poll(&mut self, timeout: Duration) -> Result<Poll, SourceError> {
        let start = *self.start.get_or_insert_with(|| {
            self.start_ns = now_ns();
            Instant::now()
        });
        let t = self.seq as f64 / self.opts.fps;
        let due = start + Duration::from_secs_f64(t);
        let wait = due.saturating_duration_since(Instant::now());
        if wait > timeout {
            std::thread::sleep(timeout);
            return Ok(Poll::Idle);
        }
        std::thread::sleep(wait);
        let (data, truth) = self
            .render(t)
            .map_err(|e| SourceError::Other(format!("synthetic drive: {e}")))?;
        let (width, height) = self.renderer.size();
        let frame = Frame {
            seq: self.seq,
            capture_ns: self.start_ns + (t * 1e9) as u64,
            receive_ns: 0,
            width,
            height,
            format: self.base.style.pixel_format(),
            data,
            truth: Some(Arc::new(truth)),
        };
        self.seq += 1;
        self.state = SourceState::Streaming;
        Ok(Poll::Frame(frame))
    }

    fn state(&self) -> SourceState {
        self.state
    }

    fn calibration(&self) -> Option<&Calibration> {
        Some(&self.cal)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts() -> SyntheticDriveOptions {
        SyntheticDriveOptions {
            fps: 1000.0,
            width: 96,
            height: 80,
            lens: IdealLens::Fisheye185,
            colour: true,
            seed: 3,
            speed_mps: 1.0,
            heading_amplitude_deg: 8.0,
            pitch_amplitude_deg: 3.0,
            offset_amplitude_m: 0.1,
            period_s: 0.01,
            cross_at_s: 0.0,
            curvature_per_m: 0.0,
            rows_end_m: 0.0,
            gap_start_m: 0.0,
            gap_length_m: 0.0,
            render_threads: 1,
        }
    }

    #[test]
    fn frames_carry_truth_that_follows_the_drive() {
        let o = opts();
        let mut d = SyntheticDrive::new(o.clone()).unwrap();
        let mut headings = Vec::new();
        for i in 0..4u64 {
            let f = loop {
                if let Poll::Frame(f) = d.poll(Duration::from_millis(50)).unwrap() {
                    break f;
                }
            };
            assert_eq!(f.seq, i);
            assert_eq!((f.width, f.height), (96, 80));
            assert_eq!(f.data.len(), 96 * 80);
            let truth = f.truth.unwrap();
            let (yaw, ..) = drive_pose(&o, 0.5, i as f64 / o.fps);
            assert!(
                (truth.yaw_rad - yaw.to_radians()).abs() < 1e-9,
                "{} vs {}",
                truth.yaw_rad,
                yaw
            );
            headings.push(truth.heading_rad);
        }
        assert!(
            headings.windows(2).any(|w| w[0] != w[1]),
            "the heading varies"
        );
    }

    #[test]
    fn a_long_drive_stays_in_the_field_until_the_rows_end() {
        // rows ending 500 m along: the robot 300 s (300 m) in still sees crop, 510 m in not
        let o = SyntheticDriveOptions {
            fps: 1.0,
            rows_end_m: 500.0,
            ..opts()
        };
        let mut d = SyntheticDrive::new(o).unwrap();
        assert!(!d.frame_at(300).unwrap().truth.unwrap().no_crop);
        assert!(d.frame_at(510).unwrap().truth.unwrap().no_crop);
    }
}
