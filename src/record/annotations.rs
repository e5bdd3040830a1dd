//! Foxglove image annotations in recordings: the detected rows, the vanishing point and the
//! line the row guidance follows, drawn over the recorded image in Foxglove's Image panel.
//!
//! Owns turning an [`Estimate`] into a `foxglove.ImageAnnotations` JSON message in the pixel
//! coordinates of the recorded image ([`Annotator::write_json`]): each row's great circle
//! projected through the calibration as line strips in its method's colour (split where it
//! leaves the field of view), the vanishing point as a circle at each of its two directions
//! that the lens sees, the followed line (and the rows either side of a followed inter-row
//! path) as cyan strips, and one line of text with the status, heading, tilt and lateral
//! offset. The message's timestamp is the frame's capture time, the image message's header
//! stamp, so Foxglove pairs them. Buffers are the annotator's and are reused frame to frame.

use crate::camera::Calibration;
use crate::detect::overlay::{method_colour, VP_COLOUR};
use crate::estimate::Estimate;
use crate::guidance::followed::{followed_lines, sample_ground_line, GroundLine, FOLLOWED_COLOUR};
use crate::sphere::any_perpendicular;
use nalgebra::Vector3;
use std::fmt::Write;

/// Topic of the annotations channel.
pub const ANNOTATIONS_TOPIC: &str = "/omnirow/image_annotations";

/// Schema name Foxglove recognises for image annotations in JSON.
pub const ANNOTATIONS_SCHEMA_NAME: &str = "foxglove.ImageAnnotations";

/// The JSON schema of the annotations channel (the subset of `foxglove.ImageAnnotations`
/// omnirow writes: circles, points annotations and texts).
pub const ANNOTATIONS_JSON_SCHEMA: &str = r##"{"title":"foxglove.ImageAnnotations","type":"object","$defs":{"time":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},"point2":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"}},"required":["x","y"]},"color":{"type":"object","properties":{"r":{"type":"number"},"g":{"type":"number"},"b":{"type":"number"},"a":{"type":"number"}}}},"properties":{"timestamp":{"$ref":"#/$defs/time"},"circles":{"type":"array","items":{"type":"object","properties":{"timestamp":{"$ref":"#/$defs/time"},"position":{"$ref":"#/$defs/point2"},"diameter":{"type":"number"},"thickness":{"type":"number"},"fill_color":{"$ref":"#/$defs/color"},"outline_color":{"$ref":"#/$defs/color"}}}},"points":{"type":"array","items":{"type":"object","properties":{"timestamp":{"$ref":"#/$defs/time"},"type":{"type":"integer","description":"0 UNKNOWN, 1 POINTS, 2 LINE_LOOP, 3 LINE_STRIP, 4 LINE_LIST"},"points":{"type":"array","items":{"$ref":"#/$defs/point2"}},"outline_color":{"$ref":"#/$defs/color"},"outline_colors":{"type":"array","items":{"$ref":"#/$defs/color"}},"fill_color":{"$ref":"#/$defs/color"},"thickness":{"type":"number"}}}},"texts":{"type":"array","items":{"type":"object","properties":{"timestamp":{"$ref":"#/$defs/time"},"position":{"$ref":"#/$defs/point2"},"text":{"type":"string"},"font_size":{"type":"number"},"text_color":{"$ref":"#/$defs/color"},"background_color":{"$ref":"#/$defs/color"}}}}}}"##;

/// `PointsAnnotationType::LINE_STRIP`.
const LINE_STRIP: u8 = 3;

/// Samples per great circle (0.5° apart).
const CIRCLE_SAMPLES: usize = 720;

/// Builds the annotations of estimates for images of one size.
#[derive(Debug, Clone)]
pub struct Annotator {
    cal: Calibration,
    /// A strip ends where consecutive samples are farther apart than this (pixels): where the
    /// curve leaves the field of view and comes back elsewhere.
    max_step_px: f64,
    /// A strip keeps a sample only this far (pixels) from the last one it kept (and its last
    /// sample): 1/160 of the image's larger side, 15 px on the GC2450C's full frame, so that a
    /// message stays near 150 points per row.
    min_step_px: f64,
    /// The current curve's samples in view: (sample index, Foxglove x, y).
    samples: Vec<(usize, [f64; 2])>,
}

impl Annotator {
    /// An annotator for images `cal` describes (at its own resolution).
    pub fn new(cal: Calibration) -> Self {
        let (h, w) = cal.size();
        Annotator {
            max_step_px: 0.1 * h.max(w) as f64,
            min_step_px: h.max(w) as f64 / 160.0,
            cal,
            samples: Vec::with_capacity(CIRCLE_SAMPLES + 1),
        }
    }

    /// The image size (height, width) the annotations are for.
    pub fn size(&self) -> (u32, u32) {
        self.cal.size()
    }

    /// Writes `e`'s annotations as a `foxglove.ImageAnnotations` JSON object into `out`
    /// (cleared first). Returns how many annotations (strips, circles, texts) it holds.
    pub fn write_json(&mut self, e: &Estimate, out: &mut String) -> usize {
        out.clear();
        let stamp = Stamp::of(e.capture_ns);
        let _ = write!(out, "{{\"timestamp\":{stamp},\"points\":[");
        let mut strips = 0;
        for row in &e.rows {
            self.sample_great_circle(&Vector3::from(row.normal));
            let style = Style {
                colour: Colour::of(method_colour(row.method), 1.0),
                thickness: 2.0,
            };
            strips += self.write_strips(stamp, style, strips, out);
        }
        if let Some(f) = e.guidance.as_ref().and_then(followed_lines) {
            self.sample_ground_line(&f.line);
            let style = Style {
                colour: Colour::of(FOLLOWED_COLOUR, 1.0),
                thickness: 4.0,
            };
            strips += self.write_strips(stamp, style, strips, out);
            for side in f.sides.iter().flatten() {
                self.sample_ground_line(side);
                let style = Style {
                    colour: Colour::of(FOLLOWED_COLOUR, 0.6),
                    thickness: 2.0,
                };
                strips += self.write_strips(stamp, style, strips, out);
            }
        }
        out.push_str("],\"circles\":[");
        let circles = self.write_vanishing_point(e, stamp, out);
        out.push_str("],\"texts\":[");
        write_text(e, stamp, out);
        out.push_str("]}");
        strips + circles + 1
    }

    /// Samples the great circle of normal `n` into `self.samples`.
    fn sample_great_circle(&mut self, n: &Vector3<f64>) {
        self.samples.clear();
        let Some(n) = n.try_normalize(1e-12) else {
            return;
        };
        let u = any_perpendicular(&n);
        let v = n.cross(&u);
        for i in 0..=CIRCLE_SAMPLES {
            let t = std::f64::consts::TAU * i as f64 / CIRCLE_SAMPLES as f64;
            if let Some(p) = self.cal.ray_to_pixel_in_fov(&(u * t.cos() + v * t.sin())) {
                self.samples.push((i, foxglove_xy(p)));
            }
        }
    }

    /// Samples a line on the ground (base_link) into `self.samples`.
    fn sample_ground_line(&mut self, line: &GroundLine) {
        self.samples.clear();
        let samples = &mut self.samples;
        sample_ground_line(&self.cal, line, CIRCLE_SAMPLES, |i, p| {
            samples.push((i, foxglove_xy(p)))
        });
    }

    /// Writes `self.samples` as line strips, split where a sample is missing or the curve
    /// jumps; `written` strips are already in the array. Returns how many it wrote.
    fn write_strips(&self, stamp: Stamp, style: Style, written: usize, out: &mut String) -> usize {
        let mut count = 0;
        let mut start = 0;
        for k in 1..=self.samples.len() {
            let breaks = k == self.samples.len() || {
                let ((i0, a), (i1, b)) = (self.samples[k - 1], self.samples[k]);
                i1 != i0 + 1 || (a[0] - b[0]).hypot(a[1] - b[1]) > self.max_step_px
            };
            if !breaks {
                continue;
            }
            let strip = &self.samples[start..k];
            start = k;
            if strip.len() < 2 {
                continue;
            }
            if written + count > 0 {
                out.push(',');
            }
            let _ = write!(
                out,
                "{{\"timestamp\":{stamp},\"type\":{LINE_STRIP},\"outline_color\":{},\"thickness\":{},\"points\":[",
                style.colour, style.thickness
            );
            let mut kept = strip[0].1;
            let _ = write!(out, "{{\"x\":{:.1},\"y\":{:.1}}}", kept[0], kept[1]);
            for (j, &(_, p)) in strip.iter().enumerate().skip(1) {
                let far = (p[0] - kept[0]).hypot(p[1] - kept[1]) >= self.min_step_px;
                if far || j + 1 == strip.len() {
                    let _ = write!(out, ",{{\"x\":{:.1},\"y\":{:.1}}}", p[0], p[1]);
                    kept = p;
                }
            }
            out.push_str("]}");
            count += 1;
        }
        count
    }

    /// The vanishing point as a circle at each of its two directions in view; returns how
    /// many.
    fn write_vanishing_point(&self, e: &Estimate, stamp: Stamp, out: &mut String) -> usize {
        let Some(vp) = e.vanishing_point else {
            return 0;
        };
        let (h, w) = self.cal.size();
        let diameter = 0.03 * h.max(w) as f64;
        let mut circles = 0;
        for sign in [1.0, -1.0] {
            let Some(p) = self.cal.ray_to_pixel_in_fov(&(Vector3::from(vp) * sign)) else {
                continue;
            };
            if circles > 0 {
                out.push(',');
            }
            let [x, y] = foxglove_xy(p);
            let _ = write!(
                out,
                "{{\"timestamp\":{stamp},\"position\":{{\"x\":{x:.2},\"y\":{y:.2}}},\"diameter\":{diameter:.1},\"thickness\":3,\"fill_color\":{},\"outline_color\":{}}}",
                Colour::of(VP_COLOUR, 0.0),
                Colour::of(VP_COLOUR, 1.0)
            );
            circles += 1;
        }
        circles
    }
}

/// One line of text at the image's top left: status, heading, tilt, lateral offset and the
/// guidance's tracking state.
fn write_text(e: &Estimate, stamp: Stamp, out: &mut String) {
    let _ = write!(
        out,
        "{{\"timestamp\":{stamp},\"position\":{{\"x\":8,\"y\":24}},\"font_size\":20,\"text_color\":{},\"background_color\":{},\"text\":\"{}",
        Colour::of([255, 255, 255], 1.0),
        Colour::of([0, 0, 0], 0.6),
        e.status.name()
    );
    let deg = |r: f64| r.to_degrees();
    if let Some(hd) = e.heading_rad.filter(|v| v.is_finite()) {
        let _ = write!(out, "  heading {:+.2}°", deg(hd));
    }
    if let Some(t) = e.tilt_rad.filter(|v| v.is_finite()) {
        let _ = write!(out, "  tilt {:+.2}°", deg(t));
    }
    if let Some(g) = &e.guidance {
        if let Some(o) = g.lateral_offset_m.filter(|v| v.is_finite()) {
            let _ = write!(out, "  offset {:+.3} m", o);
        }
        let _ = write!(out, "  {}", g.tracking.name());
    }
    out.push_str("\"}");
}

/// Image coordinates as Foxglove reads them: x along the columns, y down the rows, from the
/// top-left corner of the top-left pixel (omnirow's pixel centres are at integers).
fn foxglove_xy(p: [f64; 2]) -> [f64; 2] {
    [p[1] + 0.5, p[0] + 0.5]
}

#[derive(Debug, Clone, Copy)]
struct Style {
    colour: Colour,
    thickness: f64,
}

/// A `time` object: seconds and nanoseconds.
#[derive(Debug, Clone, Copy)]
struct Stamp(u64);

impl Stamp {
    fn of(ns: u64) -> Self {
        Stamp(ns)
    }
}

impl std::fmt::Display for Stamp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{{\"sec\":{},\"nsec\":{}}}",
            self.0 / 1_000_000_000,
            self.0 % 1_000_000_000
        )
    }
}

/// A `Color` object, channels 0..=1.
#[derive(Debug, Clone, Copy)]
struct Colour([f64; 4]);

impl Colour {
    fn of(rgb: [u8; 3], alpha: f64) -> Self {
        let c = |v: u8| v as f64 / 255.0;
        Colour([c(rgb[0]), c(rgb[1]), c(rgb[2]), alpha])
    }
}

impl std::fmt::Display for Colour {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [r, g, b, a] = self.0;
        write!(f, "{{\"r\":{r:.3},\"g\":{g:.3},\"b\":{b:.3},\"a\":{a:.2}}}")
    }
}
