//! The renderer: a scene seen through a calibrated omnidirectional camera.
//!
//! Owns [`Renderer`]. Setup (once per calibration) computes the unit ray of every pixel
//! corner and the field-of-view mask; a render then, for every pixel inside the mask, turns
//! its four corner rays into the world, and samples the pixel's footprint on the ground:
//! 2×2 samples where the footprint is small against a leaf and they all agree, else n×n
//! (`samples`), so that far rows merge into solid lines as through real optics. Rays above
//! the horizon see sky. Pixels outside the mask are black. Then the background noise
//! (salt and pepper, then Gaussian smoothing), and for the Bayer style the RGGB mosaic.
//! Rendering runs on up to `threads` threads over bands of rows and allocates nothing once
//! the scratch buffers exist.

use super::field::Cover;
use super::noise;
use super::options::Style;
use super::scene::Scene;
use super::SynthError;
use crate::camera::Calibration;
use nalgebra::{Matrix3, Vector3};
use std::sync::Mutex;

/// Rows per work item handed to a thread.
const BAND_ROWS: usize = 8;

/// Renders scenes through one calibration.
#[derive(Debug, Clone)]
pub struct Renderer {
    cal: Calibration,
    width: usize,
    height: usize,
    /// Unit rays (camera frame) at pixel corners (row − ½, col − ½), (height+1)×(width+1).
    corners: Vec<[f32; 3]>,
    /// Per pixel: inside the field of view.
    inside: Vec<bool>,
    threads: usize,
    /// RGB scratch image for the Bayer style.
    rgb: Vec<u8>,
    /// Scratch for the Gaussian smoothing.
    tmp: Vec<u8>,
}

/// Sample class, to decide whether a pixel's first samples agree.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Class {
    Sky,
    Soil,
    Plant,
}

impl Renderer {
    /// Prepares rendering through `cal` (heavy: one ray per pixel corner). Uses the
    /// calibration's mask, or where it has none, the range over which its model is valid.
    /// Renders on as many threads as the machine offers.
    pub fn new(cal: &Calibration) -> Result<Self, SynthError> {
        let (h, w) = cal.size();
        let (h, w) = (h as usize, w as usize);
        if h * w > 64_000_000 {
            return Err(SynthError::Calibration(format!(
                "image {w}x{h} is too large to render (at most 64 megapixels)"
            )));
        }
        let m = &cal.model;
        let mut corners = Vec::with_capacity((h + 1) * (w + 1));
        for r in 0..=h {
            for c in 0..=w {
                let ray = m.cam2world(r as f64 - 0.5, c as f64 - 0.5);
                corners.push([ray.x as f32, ray.y as f32, ray.z as f32]);
            }
        }
        let mut inside = Vec::with_capacity(h * w);
        for r in 0..h {
            for c in 0..w {
                let (rf, cf) = (r as f64, c as f64);
                let ok = cal.pixel_in_fov(rf, cf)
                    && (cal.mask.is_some() || cal.pixel_in_model_range(rf, cf));
                inside.push(ok);
            }
        }
        if !inside.iter().any(|&b| b) {
            return Err(SynthError::Calibration(
                "no pixel of the calibration lies inside its field of view".into(),
            ));
        }
        let threads = std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
            .clamp(1, 16);
        Ok(Renderer {
            cal: cal.clone(),
            width: w,
            height: h,
            corners,
            inside,
            threads,
            rgb: Vec::new(),
            tmp: Vec::new(),
        })
    }

    /// Sets the number of threads a render uses (at least 1).
    pub fn with_threads(mut self, threads: usize) -> Self {
        self.threads = threads.max(1);
        self
    }

    pub fn calibration(&self) -> &Calibration {
        &self.cal
    }

    /// Image width and height in pixels.
    pub fn size(&self) -> (u32, u32) {
        (self.width as u32, self.height as u32)
    }

    /// Bytes an image of `style` needs.
    pub fn buffer_len(&self, style: Style) -> usize {
        self.width * self.height * style.pixel_format().bytes_per_pixel()
    }

    /// Renders `scene` into `out` (row-major, `buffer_len(scene.options.style)` bytes, in the
    /// style's pixel format).
    pub fn render_into(&mut self, scene: &Scene, out: &mut [u8]) -> Result<(), SynthError> {
        let style = scene.options.style;
        let expected = self.buffer_len(style);
        if out.len() != expected {
            return Err(SynthError::BufferSize {
                expected,
                actual: out.len(),
            });
        }
        let (w, h) = (self.width, self.height);
        let mut rgb = std::mem::take(&mut self.rgb);
        let mut tmp = std::mem::take(&mut self.tmp);
        let channels = if style == Style::Grey { 1 } else { 3 };
        let target: &mut [u8] = if style == Style::Bayer {
            rgb.resize(w * h * 3, 0);
            &mut rgb
        } else {
            out
        };
        self.shade(scene, target, channels);
        if scene.options.noise > 0.0 {
            noise::salt_and_pepper(target, channels, scene.options.noise, scene.seed);
            tmp.resize(target.len(), 0);
            noise::gaussian_blur(
                target,
                &mut tmp,
                w,
                h,
                channels,
                scene.options.noise_blur_px,
                self.threads,
            );
            // The mask is applied after the smoothing, as in the paper.
            for (px, &ins) in target.chunks_exact_mut(channels).zip(&self.inside) {
                if !ins {
                    px.fill(0);
                }
            }
        }
        if style == Style::Bayer {
            super::bayer::mosaic(&rgb, out, w, h);
        }
        self.rgb = rgb;
        self.tmp = tmp;
        Ok(())
    }

    /// Shades every pixel into `out` (grey or RGB).
    fn shade(&self, scene: &Scene, out: &mut [u8], channels: usize) {
        let rot = scene.pose.world_from_camera.matrix().clone_owned();
        let row_bytes = self.width * channels;
        let bands = Mutex::new(out.chunks_mut(row_bytes * BAND_ROWS).enumerate());
        let work = || loop {
            let next = bands.lock().map(|mut it| it.next()).unwrap_or(None);
            let Some((b, band)) = next else { break };
            for (j, row) in band.chunks_mut(row_bytes).enumerate() {
                self.shade_row(scene, &rot, b * BAND_ROWS + j, row, channels);
            }
        };
        if self.threads <= 1 {
            work();
        } else {
            std::thread::scope(|s| {
                for _ in 1..self.threads {
                    s.spawn(work);
                }
                work();
            });
        }
    }

    fn shade_row(
        &self,
        scene: &Scene,
        rot: &Matrix3<f64>,
        r: usize,
        out: &mut [u8],
        channels: usize,
    ) {
        let w = self.width;
        let cw = w + 1;
        let world = |i: usize| {
            let v = self.corners[i];
            rot * Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64)
        };
        let o = &scene.options;
        let n = o.samples as usize;
        // Footprints smaller than this (metres) need only 2×2 samples when those agree.
        let fine = 0.5 * o.leaf_width_m.min(o.leaf_length_m);
        let c0 = scene.pose.centre;
        for col in 0..w {
            let px = &mut out[col * channels..(col + 1) * channels];
            if !self.inside[r * w + col] {
                px.fill(0);
                continue;
            }
            let d00 = world(r * cw + col);
            let d01 = world(r * cw + col + 1);
            let d10 = world((r + 1) * cw + col);
            let d11 = world((r + 1) * cw + col + 1);
            let ground = |d: &Vector3<f64>| {
                (d.z < 0.0).then(|| {
                    let t = c0.z / -d.z;
                    [c0.x + t * d.x, c0.y + t * d.y]
                })
            };
            // Footprint on the ground (metres, the longer diagonal) when all of the pixel
            // sees the ground; a pixel that no plant reaches is plain soil.
            let mut footprint = f64::INFINITY;
            if let (Some(a), Some(b), Some(c), Some(d)) =
                (ground(&d00), ground(&d01), ground(&d10), ground(&d11))
            {
                let diag1 = (a[0] - d[0]).powi(2) + (a[1] - d[1]).powi(2);
                let diag2 = (b[0] - c[0]).powi(2) + (b[1] - c[1]).powi(2);
                footprint = diag1.max(diag2).sqrt();
                let x0 = a[0].min(b[0]).min(c[0]).min(d[0]);
                let x1 = a[0].max(b[0]).max(c[0]).max(d[0]);
                let y0 = a[1].min(b[1]).min(c[1]).min(d[1]);
                let y1 = a[1].max(b[1]).max(c[1]).max(d[1]);
                if scene.field.is_bare(x0, x1, y0, y1) {
                    let p = &scene.palette;
                    if channels == 1 {
                        px[0] = p.grey_soil.round() as u8;
                    } else {
                        let (cx, cy) = (0.25 * (x0 + x1) * 2.0, 0.25 * (y0 + y1) * 2.0);
                        let rgb = p.soil_rgb(scene.texture.filtered(cx, cy, footprint));
                        for k in 0..3 {
                            px[k] = rgb[k].round().clamp(0.0, 255.0) as u8;
                        }
                    }
                    continue;
                }
            }
            let sample = |u: f64, v: f64| -> (Class, [f32; 3]) {
                let d = (d00 * (1.0 - v) + d01 * v) * (1.0 - u) + (d10 * (1.0 - v) + d11 * v) * u;
                shade_ray(scene, &c0, &d, footprint)
            };
            let small = footprint < fine;
            let mut acc = [0.0f32; 3];
            let mut done = false;
            if small || n <= 2 {
                let mut first = None;
                let mut agree = true;
                for (u, v) in [(0.25, 0.25), (0.25, 0.75), (0.75, 0.25), (0.75, 0.75)] {
                    let (cls, c) = sample(u, v);
                    agree &= *first.get_or_insert(cls) == cls;
                    for k in 0..3 {
                        acc[k] += c[k] * 0.25;
                    }
                }
                done = agree || n <= 2;
            }
            if !done {
                acc = [0.0; 3];
                let inv = 1.0 / (n * n) as f32;
                for i in 0..n {
                    let u = (i as f64 + 0.5) / n as f64;
                    for j in 0..n {
                        let v = (j as f64 + 0.5) / n as f64;
                        let (_, c) = sample(u, v);
                        for k in 0..3 {
                            acc[k] += c[k] * inv;
                        }
                    }
                }
            }
            if channels == 1 {
                px[0] = acc[0].round().clamp(0.0, 255.0) as u8;
            } else {
                for k in 0..3 {
                    px[k] = acc[k].round().clamp(0.0, 255.0) as u8;
                }
            }
        }
    }
}

/// Colour (grey in channel 0 for the grey style) of the world ray `d` from `centre`.
#[inline]
fn shade_ray(
    scene: &Scene,
    centre: &Vector3<f64>,
    d: &Vector3<f64>,
    footprint: f64,
) -> (Class, [f32; 3]) {
    let p = &scene.palette;
    let grey = scene.options.style == Style::Grey;
    if d.z >= 0.0 {
        if grey {
            return (Class::Sky, [p.grey_soil; 3]);
        }
        let s = (d.z / d.norm()) as f32;
        return (Class::Sky, p.sky_rgb(s));
    }
    let t = centre.z / -d.z;
    let (x, y) = (centre.x + t * d.x, centre.y + t * d.y);
    match scene.field.cover_at(x, y) {
        Cover::Plant { edge } => {
            if grey {
                (Class::Plant, [p.grey_plant; 3])
            } else {
                (Class::Plant, p.leaf_rgb(edge as f32))
            }
        }
        Cover::Soil => {
            if grey {
                (Class::Soil, [p.grey_soil; 3])
            } else {
                (
                    Class::Soil,
                    p.soil_rgb(scene.texture.filtered(x, y, footprint)),
                )
            }
        }
    }
}
