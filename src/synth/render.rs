//! The renderer: a scene seen through a calibrated omnidirectional camera.
//!
//! Owns [`Renderer`]. Setup (once per calibration) computes the unit ray of every pixel
//! corner, the field-of-view mask, and each row's span of pixels inside it. A render then
//! turns each band of rows' corner rays into the world and onto the ground once, and for
//! every pixel inside the mask samples its footprint: a footprint no plant reaches is plain
//! soil; a footprint small against a leaf takes 2×2 samples and keeps them when they agree;
//! any other pixel takes n×n samples (`samples`), so that far rows merge into solid lines
//! as through real optics. Rays above the horizon see sky; pixels outside the mask are
//! black. Then the background noise (salt and pepper, then Gaussian smoothing), and for the
//! Bayer style the RGGB mosaic. With a photograph's ground ([`Ground::Photo`]) every pixel
//! takes its samples (2×2 where all of the pixel sees the ground, else n×n) from the
//! texture at the footprint's scale instead. Rendering runs on up to `threads` threads over bands of rows
//! and allocates nothing once its scratch buffers exist.

use super::field::Cover;
use super::noise::{self, run_each, Blur};
use super::options::Style;
use super::photo::PhotoGround;
use super::scene::{Ground, Scene};
use super::SynthError;
use crate::camera::Calibration;
use nalgebra::{Matrix3, Vector3};
use std::sync::Mutex;

/// Rows per work item handed to a thread.
const BAND_ROWS: usize = 8;

/// What setup computes once per calibration.
#[derive(Debug, Clone)]
struct Geometry {
    cal: Calibration,
    width: usize,
    height: usize,
    /// Unit rays (camera frame) at pixel corners (row − ½, col − ½), (height+1)×(width+1).
    corners: Vec<[f32; 3]>,
    /// Per pixel: inside the field of view.
    inside: Vec<bool>,
    /// Per image row: the columns `lo..hi` that hold every pixel inside the field of view
    /// (empty when none).
    spans: Vec<(usize, usize)>,
}

/// A pixel corner seen in the world: its ray and, when the ray hits the ground, the point.
#[derive(Debug, Clone, Copy, Default)]
struct Corner {
    dir: Vector3<f64>,
    /// Ground point (x, y) and distance along the ray; valid when `hits`.
    ground: [f64; 2],
    t: f64,
    hits: bool,
}

/// Renders scenes through one calibration.
#[derive(Debug, Clone)]
pub struct Renderer {
    geo: Geometry,
    threads: usize,
    /// Per thread: the corners of one band of rows.
    bands: Vec<Vec<Corner>>,
    /// RGB scratch image for the Bayer style.
    rgb: Vec<u8>,
    blur: Blur,
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
        let mut inside = Vec::with_capacity(h * w);
        let mut spans = Vec::with_capacity(h);
        // The mask test of Calibration::pixel_in_fov, on squared radii (every pixel centre
        // lies on the sensor).
        let (xc, yc) = (cal.model.xc, cal.model.yc);
        let radii2 = cal
            .mask
            .map(|m| (m.inner_radius_px.powi(2), m.outer_radius_px.powi(2)));
        for r in 0..h {
            let (mut lo, mut hi) = (w, 0);
            let dr2 = (r as f64 - xc).powi(2);
            for c in 0..w {
                let ok = match radii2 {
                    Some((lo2, hi2)) => {
                        let r2 = dr2 + (c as f64 - yc).powi(2);
                        r2 >= lo2 && r2 <= hi2
                    }
                    None => cal.pixel_in_model_range(r as f64, c as f64),
                };
                if ok {
                    lo = lo.min(c);
                    hi = c + 1;
                }
                inside.push(ok);
            }
            spans.push(if lo < hi { (lo, hi) } else { (0, 0) });
        }
        if spans.iter().all(|s| s.0 == s.1) {
            return Err(SynthError::Calibration(
                "no pixel of the calibration lies inside its field of view".into(),
            ));
        }
        // Corner rays, only where a pixel inside the mask needs them.
        let m = &cal.model;
        let mut corners = vec![[0.0f32; 3]; (h + 1) * (w + 1)];
        for r in 0..=h {
            let (a, b) = (spans[r.saturating_sub(1)], spans[r.min(h - 1)]);
            let (lo, hi) = (a.0.min(b.0), a.1.max(b.1));
            for c in lo..=hi.min(w) {
                let ray = m.cam2world(r as f64 - 0.5, c as f64 - 0.5);
                corners[r * (w + 1) + c] = [ray.x as f32, ray.y as f32, ray.z as f32];
            }
        }
        let threads = std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
            .clamp(1, 16);
        Ok(Renderer {
            geo: Geometry {
                cal: cal.clone(),
                width: w,
                height: h,
                corners,
                inside,
                spans,
            },
            threads,
            bands: Vec::new(),
            rgb: Vec::new(),
            blur: Blur::new(),
        })
    }

    /// Sets the number of threads a render uses (at least 1).
    pub fn with_threads(mut self, threads: usize) -> Self {
        self.threads = threads.max(1);
        self
    }

    pub fn calibration(&self) -> &Calibration {
        &self.geo.cal
    }

    /// Image width and height in pixels.
    pub fn size(&self) -> (u32, u32) {
        (self.geo.width as u32, self.geo.height as u32)
    }

    /// Bytes an image of `style` needs.
    pub fn buffer_len(&self, style: Style) -> usize {
        self.geo.width * self.geo.height * style.pixel_format().bytes_per_pixel()
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
        let (w, h) = (self.geo.width, self.geo.height);
        if style == Style::Leafy {
            if matches!(scene.ground, Ground::Photo(_)) {
                return Err(SynthError::InvalidOption {
                    name: "style",
                    value: "leafy".into(),
                    reason: "is not supported with a photograph's ground".into(),
                });
            }
            let g = &self.geo;
            return super::appearance::render_leafy(
                scene,
                &g.corners,
                &g.inside,
                (w, h),
                self.threads,
                out,
            );
        }
        let channels = if style == Style::Grey { 1 } else { 3 };
        let target: &mut [u8] = if style == Style::Bayer {
            self.rgb.resize(w * h * 3, 0);
            &mut self.rgb
        } else {
            out
        };
        self.bands.resize_with(self.threads, Vec::new);
        for b in &mut self.bands {
            b.resize((BAND_ROWS + 1) * (w + 1), Corner::default());
        }
        shade(&self.geo, scene, target, channels, &mut self.bands);
        if scene.options.noise > 0.0 {
            noise::salt_and_pepper(target, channels, scene.options.noise, scene.seed);
            self.blur.apply(
                target,
                w,
                h,
                channels,
                scene.options.noise_blur_px,
                self.threads,
            );
            // The mask is applied after the smoothing, as in the paper.
            for (px, &ins) in target.chunks_exact_mut(channels).zip(&self.geo.inside) {
                if !ins {
                    px.fill(0);
                }
            }
        }
        if style == Style::Bayer {
            super::bayer::mosaic(&self.rgb, out, w, h);
        }
        Ok(())
    }
}

/// Shades every pixel into `out` (grey or RGB), one band of rows at a time per thread.
fn shade(
    geo: &Geometry,
    scene: &Scene,
    out: &mut [u8],
    channels: usize,
    scratch: &mut [Vec<Corner>],
) {
    let rot = scene.pose.world_from_camera.matrix().clone_owned();
    let row_bytes = geo.width * channels;
    let bands = Mutex::new(out.chunks_mut(row_bytes * BAND_ROWS).enumerate());
    let work = |corners: &mut Vec<Corner>| loop {
        let next = bands.lock().map(|mut it| it.next()).unwrap_or(None);
        let Some((b, band)) = next else { break };
        let r0 = b * BAND_ROWS;
        let rows = band.len() / row_bytes;
        corners_of_band(geo, scene, &rot, r0, rows, corners);
        for (j, row) in band.chunks_mut(row_bytes).enumerate() {
            match &scene.ground {
                Ground::Synthetic => shade_row(geo, scene, corners, r0 + j, j, row, channels),
                Ground::Photo(photo) => {
                    shade_row_photo(geo, scene, photo, corners, r0 + j, j, row, channels)
                }
            }
        }
    };
    run_each(scratch, &work);
}

/// World rays and ground points of the corners of rows `r0 .. r0 + rows` (inside spans).
fn corners_of_band(
    geo: &Geometry,
    scene: &Scene,
    rot: &Matrix3<f64>,
    r0: usize,
    rows: usize,
    out: &mut [Corner],
) {
    let (w, h) = (geo.width, geo.height);
    let cw = w + 1;
    let c0 = scene.pose.centre;
    for j in 0..=rows {
        let r = r0 + j;
        let (a, b) = (geo.spans[r.saturating_sub(1)], geo.spans[r.min(h - 1)]);
        let (lo, hi) = (a.0.min(b.0), a.1.max(b.1).min(w));
        if lo >= hi {
            continue;
        }
        for c in lo..=hi {
            let v = geo.corners[r * cw + c];
            let dir = rot * Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64);
            let hits = dir.z < 0.0;
            let t = if hits { c0.z / -dir.z } else { 0.0 };
            out[j * cw + c] = Corner {
                dir,
                ground: [c0.x + t * dir.x, c0.y + t * dir.y],
                t,
                hits,
            };
        }
    }
}

/// Rounds a channel value to a byte.
#[inline]
fn to_byte(v: f32) -> u8 {
    (v + 0.5).clamp(0.0, 255.0) as u8
}

fn shade_row(
    geo: &Geometry,
    scene: &Scene,
    corners: &[Corner],
    r: usize,
    j: usize,
    out: &mut [u8],
    channels: usize,
) {
    let w = geo.width;
    let cw = w + 1;
    let o = &scene.options;
    let n = o.samples as usize;
    // Footprints smaller than this (metres) need only 2×2 samples when those agree.
    let fine = 0.5 * o.leaf_width_m.min(o.leaf_length_m);
    let c0 = scene.pose.centre;
    let (lo, hi) = geo.spans[r];
    out[..lo * channels].fill(0);
    out[hi * channels..].fill(0);
    for col in lo..hi {
        let px = &mut out[col * channels..(col + 1) * channels];
        if !geo.inside[r * w + col] {
            px.fill(0);
            continue;
        }
        let k00 = &corners[j * cw + col];
        let k01 = &corners[j * cw + col + 1];
        let k10 = &corners[(j + 1) * cw + col];
        let k11 = &corners[(j + 1) * cw + col + 1];
        // Footprint on the ground (metres, the longer diagonal) when all of the pixel
        // sees the ground; a pixel that no plant reaches is plain soil.
        let mut footprint = f64::INFINITY;
        let all_ground = k00.hits && k01.hits && k10.hits && k11.hits;
        if all_ground {
            let (a, b, c, d) = (k00.ground, k01.ground, k10.ground, k11.ground);
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
                    px[0] = to_byte(p.grey_soil);
                } else {
                    let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
                    let rgb = p.soil_rgb(scene.texture.filtered(cx, cy, footprint));
                    for k in 0..3 {
                        px[k] = to_byte(rgb[k]);
                    }
                }
                continue;
            }
        }
        let (d00, d01, d10, d11) = (k00.dir, k01.dir, k10.dir, k11.dir);
        // Where the depth hardly changes across the pixel the ground mapping is affine to
        // well under a thousandth of the footprint: interpolate on the ground directly.
        let t_lo = k00.t.min(k01.t).min(k10.t).min(k11.t);
        let t_hi = k00.t.max(k01.t).max(k10.t).max(k11.t);
        let affine = all_ground && t_hi < t_lo * 1.02;
        let (g00, g01, g10, g11) = (k00.ground, k01.ground, k10.ground, k11.ground);
        let sample = |u: f64, v: f64| -> (Class, [f32; 3]) {
            if affine {
                let lerp = |k: usize| {
                    (g00[k] * (1.0 - v) + g01[k] * v) * (1.0 - u)
                        + (g10[k] * (1.0 - v) + g11[k] * v) * u
                };
                shade_ground(scene, lerp(0), lerp(1), footprint)
            } else {
                let d = (d00 * (1.0 - v) + d01 * v) * (1.0 - u) + (d10 * (1.0 - v) + d11 * v) * u;
                shade_ray(scene, &c0, &d, footprint)
            }
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
                for jj in 0..n {
                    let v = (jj as f64 + 0.5) / n as f64;
                    let (_, c) = sample(u, v);
                    for k in 0..3 {
                        acc[k] += c[k] * inv;
                    }
                }
            }
        }
        if channels == 1 {
            px[0] = to_byte(acc[0]);
        } else {
            for k in 0..3 {
                px[k] = to_byte(acc[k]);
            }
        }
    }
}

/// Shades image row `r` (band row `j`) with a photograph's ground: each pixel the mean of
/// 2×2 samples of the texture at the footprint's scale where all of it sees the ground, else
/// of n×n samples (ground or sky).
#[allow(clippy::too_many_arguments)]
fn shade_row_photo(
    geo: &Geometry,
    scene: &Scene,
    photo: &PhotoGround,
    corners: &[Corner],
    r: usize,
    j: usize,
    out: &mut [u8],
    channels: usize,
) {
    let (w, cw) = (geo.width, geo.width + 1);
    let c0 = scene.pose.centre;
    let (lo, hi) = geo.spans[r];
    out[..lo * channels].fill(0);
    out[hi * channels..].fill(0);
    for col in lo..hi {
        let px = &mut out[col * channels..(col + 1) * channels];
        if !geo.inside[r * w + col] {
            px.fill(0);
            continue;
        }
        let k = [
            &corners[j * cw + col],
            &corners[j * cw + col + 1],
            &corners[(j + 1) * cw + col],
            &corners[(j + 1) * cw + col + 1],
        ];
        let all_ground = k.iter().all(|c| c.hits);
        let footprint = if all_ground {
            let (a, b, c, d) = (k[0].ground, k[1].ground, k[2].ground, k[3].ground);
            let diag1 = (a[0] - d[0]).powi(2) + (a[1] - d[1]).powi(2);
            let diag2 = (b[0] - c[0]).powi(2) + (b[1] - c[1]).powi(2);
            diag1.max(diag2).sqrt()
        } else {
            f64::INFINITY
        };
        // The texture's pyramid filters the ground at the footprint's scale: 2×2 samples
        // suffice where all of the pixel sees the ground; the horizon's edge takes n×n.
        let n = if all_ground {
            2
        } else {
            scene.options.samples as usize
        };
        let size = footprint / n as f64;
        let mut acc = [0.0f32; 3];
        let inv = 1.0 / (n * n) as f32;
        for i in 0..n {
            let u = (i as f64 + 0.5) / n as f64;
            for jj in 0..n {
                let v = (jj as f64 + 0.5) / n as f64;
                let d = (k[0].dir * (1.0 - v) + k[1].dir * v) * (1.0 - u)
                    + (k[2].dir * (1.0 - v) + k[3].dir * v) * u;
                let c = photo_ray(scene, photo, &c0, &d, size);
                for k in 0..3 {
                    acc[k] += c[k] * inv;
                }
            }
        }
        for (o, a) in px.iter_mut().zip(acc) {
            *o = to_byte(a);
        }
    }
}

/// Colour (grey in all channels for the grey style) of the world ray `d` from `centre` over
/// a photograph's ground, the texture averaged over `size` metres.
#[inline]
fn photo_ray(
    scene: &Scene,
    photo: &PhotoGround,
    centre: &Vector3<f64>,
    d: &Vector3<f64>,
    size: f64,
) -> [f32; 3] {
    let p = &scene.palette;
    let grey = scene.options.style == Style::Grey;
    if d.z >= 0.0 {
        return if grey {
            [p.grey_soil; 3]
        } else {
            p.sky_rgb((d.z / d.norm()) as f32)
        };
    }
    let t = centre.z / -d.z;
    let g = photo.colour(centre.x + t * d.x, centre.y + t * d.y, size);
    if grey {
        [0.299 * g[0] + 0.587 * g[1] + 0.114 * g[2]; 3]
    } else {
        g
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
    shade_ground(scene, centre.x + t * d.x, centre.y + t * d.y, footprint)
}

/// Colour (grey in channel 0 for the grey style) of ground point (x, y).
#[inline]
fn shade_ground(scene: &Scene, x: f64, y: f64, footprint: f64) -> (Class, [f32; 3]) {
    let p = &scene.palette;
    let grey = scene.options.style == Style::Grey;
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{ideal_fisheye, ideal_pal};
    use crate::synth::SynthOptions;

    fn render(cal: &Calibration, opts: &SynthOptions, seed: u64) -> Vec<u8> {
        let scene = Scene::new(opts, seed, &cal.mounting).unwrap();
        let mut r = Renderer::new(cal).unwrap().with_threads(2);
        let mut out = vec![0u8; r.buffer_len(opts.style)];
        r.render_into(&scene, &mut out).unwrap();
        out
    }

    #[test]
    fn deterministic_and_thread_count_independent() {
        let cal = ideal_fisheye(256, 306).unwrap();
        let opts = SynthOptions {
            noise: 0.2,
            weeds: 30,
            along_sd_m: 0.01,
            across_sd_m: 0.01,
            style: Style::Colour,
            field_half_length_m: 30.0,
            field_half_width_m: 30.0,
            ..Default::default()
        };
        let a = render(&cal, &opts, 9);
        assert_eq!(a, render(&cal, &opts, 9));
        let scene = Scene::new(&opts, 9, &cal.mounting).unwrap();
        let mut one = Renderer::new(&cal).unwrap().with_threads(1);
        let mut b = vec![0u8; a.len()];
        one.render_into(&scene, &mut b).unwrap();
        assert_eq!(a, b);
        assert_ne!(a, render(&cal, &opts, 10));
    }

    #[test]
    fn mask_is_black_and_pal_has_an_annulus() {
        for (cal, inner) in [
            (ideal_fisheye(256, 306).unwrap(), false),
            (ideal_pal(256, 306).unwrap(), true),
        ] {
            let img = render(&cal, &SynthOptions::default(), 1);
            let (h, w) = cal.size();
            let m = cal.mask.unwrap();
            let at = |r: f64, c: f64| img[r as usize * w as usize + c as usize];
            // corners of the sensor are outside the image circle
            assert_eq!(at(0.0, 0.0), 0);
            assert_eq!(at(h as f64 - 1.0, w as f64 - 1.0), 0);
            let (xc, yc) = (cal.model.xc.round(), cal.model.yc.round());
            if inner {
                assert_eq!(at(xc, yc), 0, "blind centre of the PAL");
            } else {
                assert!(at(xc, yc) > 0);
            }
            // a ring just inside the outer radius sees the ground: soil grey or brighter
            let r = m.outer_radius_px - 3.0;
            assert!(at(xc, yc + r) >= 30 && at(xc, yc - r) >= 30);
        }
    }

    #[test]
    fn background_noise_has_the_asked_density() {
        let cal = ideal_fisheye(256, 306).unwrap();
        for density in [0.1, 0.4] {
            let opts = SynthOptions {
                noise: density,
                noise_blur_px: 0.0,
                ..Default::default()
            };
            let img = render(&cal, &opts, 3);
            let clean = render(&cal, &SynthOptions::default(), 3);
            let (mut inside, mut changed) = (0usize, 0usize);
            let (_, w) = cal.size();
            for (i, (&a, &b)) in img.iter().zip(&clean).enumerate() {
                let (r, c) = ((i / w as usize) as f64, (i % w as usize) as f64);
                if cal.pixel_in_fov(r, c) {
                    inside += 1;
                    // the clean image holds only soil, plant, and mixtures: never 0 or 255
                    assert!(b > 0 && b < 255);
                    changed += (a == 0 || a == 255) as usize;
                }
            }
            let f = changed as f64 / inside as f64;
            assert!((f - density).abs() < 0.02, "{f} vs {density}");
        }
    }

    #[test]
    fn bayer_is_the_mosaic_of_the_colour_image() {
        let cal = ideal_pal(256, 306).unwrap();
        let colour = SynthOptions {
            style: Style::Colour,
            noise: 0.1,
            ..Default::default()
        };
        let rgb = render(&cal, &colour, 4);
        let raw = render(
            &cal,
            &SynthOptions {
                style: Style::Bayer,
                ..colour.clone()
            },
            4,
        );
        let (h, w) = cal.size();
        let mut expect = vec![0u8; (h * w) as usize];
        crate::synth::mosaic(&rgb, &mut expect, w as usize, h as usize);
        assert_eq!(raw, expect);
        // the colour image really is colour: plants green, sky blue somewhere
        let green = rgb.chunks_exact(3).filter(|p| p[1] > p[0] + 15).count();
        let blue = rgb.chunks_exact(3).filter(|p| p[2] > p[0] + 15).count();
        assert!(blue > 20, "{blue}");
        assert!(green > 20, "{green}");
    }

    #[test]
    fn far_rows_are_anti_aliased() {
        // Looking along the rows near the horizon, pixels hold partial coverage (grey levels
        // between soil and plant), not just the two levels.
        let cal = ideal_fisheye(512, 612).unwrap();
        let opts = SynthOptions {
            plant_distance_m: 0.03,
            ..Default::default()
        };
        let img = render(&cal, &opts, 1);
        let mid = img.iter().filter(|&&v| v > 45 && v < 200).count();
        assert!(mid > 500, "{mid}");
    }

    #[test]
    fn wrong_buffer_size_is_an_error() {
        let cal = ideal_fisheye(64, 80).unwrap();
        let scene = Scene::new(&SynthOptions::default(), 1, &cal.mounting).unwrap();
        let mut r = Renderer::new(&cal).unwrap();
        let mut out = vec![0u8; 10];
        let e = r.render_into(&scene, &mut out).unwrap_err().to_string();
        assert!(e.contains("5120") && e.contains("10"), "{e}");
    }
}
