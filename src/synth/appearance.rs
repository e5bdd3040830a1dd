//! The second appearance model, `leafy`: the same field, pose and rows as every style, drawn
//! by a renderer designed apart from the first so that the detector's precision can be
//! checked against an appearance it was not tuned on.
//!
//! Owns [`render_leafy`]. Each plant is a rosette of 3–7 leaves of random length, width and
//! direction (drawn per plant from the seed, the plant's size varying too), each leaf an
//! ellipse shaded lighter along its midrib; weeds are smaller, yellower rosettes. The soil is
//! fractal value noise between a dark and a light earth with pale stones; the sky a gradient.
//! Every pixel is supersampled (3×3 where a leaf may reach it); then uneven lighting (a
//! smooth random illumination field and a vignette), sensor noise, a lens blur, an RGGB Bayer
//! mosaic demosaiced back bilinearly, and a JPEG round trip (quality 80). The output is Rgb8.
//! Unlike the first renderer it allocates its scratch images per render.

use super::field::Field;
use super::noise::Blur;
use super::rng::{splitmix64, Rng};
use super::scene::Scene;
use super::SynthError;
use nalgebra::{Matrix3, Vector3};
use std::sync::Mutex;

/// Subsamples per side where a leaf may cover part of the pixel.
const SUPERSAMPLE: usize = 3;
/// Rows of pixels handed to a thread at a time.
const BAND: usize = 8;
/// JPEG quality of the final round trip.
const JPEG_QUALITY: u8 = 80;
/// Lens blur, pixels (Gaussian sigma).
const BLUR_PX: f64 = 0.8;

/// A hash of three integers to 64 uniform bits.
#[inline]
fn hash(seed: u64, a: i64, b: i64) -> u64 {
    let mut s = seed ^ (a as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    s = splitmix64(&mut s) ^ (b as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    splitmix64(&mut s)
}

/// Uniform in [0, 1) from the top bits of `h`, and the next value of the stream.
#[inline]
fn unit(h: &mut u64) -> f64 {
    let v = splitmix64(h);
    (v >> 11) as f64 / (1u64 << 53) as f64
}

/// One leaf: an ellipse on the ground, with its colour.
#[derive(Debug, Clone, Copy)]
struct Leaf {
    centre: [f64; 2],
    /// Unit direction of the long axis.
    dir: [f64; 2],
    half_len: f64,
    half_wid: f64,
    rgb: [f32; 3],
}

impl Leaf {
    /// The leaf's colour at (x, y) if it covers the point.
    #[inline]
    fn shade(&self, x: f64, y: f64) -> Option<[f32; 3]> {
        let (dx, dy) = (x - self.centre[0], y - self.centre[1]);
        let u = (dx * self.dir[0] + dy * self.dir[1]) / self.half_len;
        let v = (-dx * self.dir[1] + dy * self.dir[0]) / self.half_wid;
        let r2 = u * u + v * v;
        if r2 > 1.0 {
            return None;
        }
        // Lighter along the midrib, darker towards the rim and the tip.
        let f = (1.08 - 0.35 * (v * v) as f32 - 0.15 * (u.max(0.0) * u.max(0.0)) as f32).max(0.4);
        Some([self.rgb[0] * f, self.rgb[1] * f, self.rgb[2] * f])
    }
}

/// The leaves of the rosette at `stem`, drawn from `h`; `scale` sets the plant's size
/// (the scene's leaf length), `weed` its kind.
fn rosette(stem: [f64; 2], mut h: u64, scale: f64, weed: bool, out: &mut Vec<Leaf>) {
    out.clear();
    let size = if weed {
        0.45 + 0.4 * unit(&mut h)
    } else {
        0.6 + 0.8 * unit(&mut h)
    };
    let n = 3 + (unit(&mut h) * 5.0) as usize;
    let phase = unit(&mut h) * std::f64::consts::TAU;
    // The plant's green: from a deep to a pale green, weeds yellower.
    let g = unit(&mut h) as f32;
    let base = if weed {
        [120.0 + 30.0 * g, 150.0 + 20.0 * g, 45.0]
    } else {
        [50.0 + 50.0 * g, 120.0 + 55.0 * g, 35.0 + 30.0 * g]
    };
    for j in 0..n {
        let a = phase + std::f64::consts::TAU * (j as f64 + 0.6 * (unit(&mut h) - 0.5)) / n as f64;
        let len = scale * size * (0.6 + 0.6 * unit(&mut h));
        let wid = len * (0.22 + 0.3 * unit(&mut h));
        let b = (0.85 + 0.3 * unit(&mut h)) as f32;
        let dir = [a.cos(), a.sin()];
        out.push(Leaf {
            centre: [stem[0] + 0.45 * len * dir[0], stem[1] + 0.45 * len * dir[1]],
            dir,
            half_len: 0.5 * len,
            half_wid: 0.5 * wid,
            rgb: [base[0] * b, base[1] * b, base[2] * b],
        });
    }
}

/// Rosettes recently drawn, by plant: neighbouring samples meet the same plants, and drawing
/// a rosette (hashes, sines) costs more than looking it up. Direct-mapped, one per thread.
struct Rosettes {
    slots: Vec<Option<CachedRosette>>,
}

/// A plant (row, k) and its leaves.
type CachedRosette = ((i64, i64), Vec<Leaf>);

/// Slots of the rosette cache (a power of two).
const CACHE_SLOTS: usize = 512;

impl Rosettes {
    fn new() -> Self {
        Rosettes {
            slots: vec![None; CACHE_SLOTS],
        }
    }

    /// The leaves of plant (`row`, `k`) at `stem`.
    fn get(&mut self, seed: u64, row: i64, k: i64, stem: [f64; 2], scale: f64) -> &[Leaf] {
        let slot = (hash(0, row, k) as usize) & (CACHE_SLOTS - 1);
        let entry = &mut self.slots[slot];
        if entry.as_ref().map(|e| e.0) != Some((row, k)) {
            let mut leaves = entry.take().map(|e| e.1).unwrap_or_default();
            rosette(stem, hash(seed, row, k), scale, false, &mut leaves);
            *entry = Some(((row, k), leaves));
        }
        &entry.as_ref().expect("filled above").1
    }
}

/// The largest reach of a rosette from its stem, in units of the leaf length.
const REACH: f64 = 1.4 * 1.2;

/// Smooth value noise at (x, y) in lattice units, about [-1, 1].
#[inline]
fn value_noise(seed: u64, x: f64, y: f64) -> f64 {
    let (fx, fy) = (x.floor(), y.floor());
    let (tx, ty) = (x - fx, y - fy);
    let (sx, sy) = (tx * tx * (3.0 - 2.0 * tx), ty * ty * (3.0 - 2.0 * ty));
    let (ix, iy) = (fx as i64, fy as i64);
    let at = |a: i64, b: i64| {
        let mut h = hash(seed, a, b);
        2.0 * unit(&mut h) - 1.0
    };
    let top = at(ix, iy) * (1.0 - sx) + at(ix + 1, iy) * sx;
    let bot = at(ix, iy + 1) * (1.0 - sx) + at(ix + 1, iy + 1) * sx;
    top * (1.0 - sy) + bot * sy
}

/// What the renderer draws the scene with.
struct Look<'a> {
    field: &'a Field,
    seed: u64,
    leaf_length: f64,
    /// Weeds bucketed on a grid of `cell` metres: (cell x, cell y) → stems.
    weeds: std::collections::HashMap<(i64, i64), Vec<[f64; 2]>>,
    cell: f64,
}

impl Look<'_> {
    /// The colour of the topmost leaf over (x, y), if any.
    fn leaf_at(
        &self,
        x: f64,
        y: f64,
        cache: &mut Rosettes,
        leaves: &mut Vec<Leaf>,
    ) -> Option<[f32; 3]> {
        let reach = REACH * self.leaf_length;
        let mut hit = None;
        self.field.plants_near(x, y, reach, |row, k, stem| {
            if hit.is_none() {
                let plant = cache.get(self.seed, row, k, stem, self.leaf_length);
                hit = plant.iter().rev().find_map(|l| l.shade(x, y));
            }
        });
        if hit.is_some() {
            return hit;
        }
        let (cx, cy) = (
            (x / self.cell).floor() as i64,
            (y / self.cell).floor() as i64,
        );
        for dx in -1..=1 {
            for dy in -1..=1 {
                for (i, &stem) in self
                    .weeds
                    .get(&(cx + dx, cy + dy))
                    .into_iter()
                    .flatten()
                    .enumerate()
                {
                    let h = hash(
                        self.seed ^ 0x5eed,
                        (stem[0] * 1e4) as i64,
                        i as i64 + (stem[1] * 1e4) as i64,
                    );
                    rosette(stem, h, self.leaf_length, true, leaves);
                    if let Some(c) = leaves.iter().rev().find_map(|l| l.shade(x, y)) {
                        return Some(c);
                    }
                }
            }
        }
        None
    }

    /// Soil colour at (x, y) seen with a footprint of `size` metres: octaves finer than the
    /// footprint fade out; pale stones where they are large enough to see.
    fn soil(&self, x: f64, y: f64, size: f64) -> [f32; 3] {
        let mut n = 0.0;
        for (k, (freq, amp)) in [(6.0, 0.5), (17.0, 0.28), (50.0, 0.15), (140.0, 0.1)]
            .into_iter()
            .enumerate()
        {
            let fade = (1.0 - size * freq / 2.0).clamp(0.0, 1.0);
            if fade > 0.0 {
                n += amp
                    * fade
                    * value_noise(self.seed.wrapping_add(k as u64 * 77), x * freq, y * freq);
            }
        }
        let t = (0.5 + 0.9 * n).clamp(0.0, 1.0) as f32;
        let (dark, light) = ([78.0f32, 60.0, 47.0], [158.0f32, 128.0, 98.0]);
        let mut c = [0.0f32; 3];
        for i in 0..3 {
            c[i] = dark[i] + (light[i] - dark[i]) * t;
        }
        if size < 0.01 {
            let g = 0.04;
            let (ix, iy) = ((x / g).floor() as i64, (y / g).floor() as i64);
            let mut h = hash(self.seed ^ 0x570e, ix, iy);
            if unit(&mut h) < 0.05 {
                let (sx, sy) = (
                    (ix as f64 + unit(&mut h)) * g,
                    (iy as f64 + unit(&mut h)) * g,
                );
                let r = 0.004 + 0.006 * unit(&mut h);
                if (x - sx).hypot(y - sy) < r {
                    return [175.0, 168.0, 158.0];
                }
            }
        }
        c
    }
}

/// Renders `scene` in the leafy look into `out` (Rgb8, `w`·`h`·3 bytes): `corners` are the
/// camera-frame rays at the pixel corners ((h+1)×(w+1)), `inside` the pixels in the field of
/// view.
pub fn render_leafy(
    scene: &Scene,
    corners: &[[f32; 3]],
    inside: &[bool],
    (w, h): (usize, usize),
    threads: usize,
    out: &mut [u8],
) -> Result<(), SynthError> {
    if out.len() != w * h * 3 {
        return Err(SynthError::BufferSize {
            expected: w * h * 3,
            actual: out.len(),
        });
    }
    let cell = 0.25;
    let mut weeds: std::collections::HashMap<(i64, i64), Vec<[f64; 2]>> = Default::default();
    for &s in scene.field.weeds() {
        weeds
            .entry(((s[0] / cell).floor() as i64, (s[1] / cell).floor() as i64))
            .or_default()
            .push(s);
    }
    let look = Look {
        field: &scene.field,
        seed: scene.seed,
        leaf_length: scene.options.leaf_length_m,
        weeds,
        cell,
    };
    let rot = scene.pose.world_from_camera.matrix().clone_owned();
    let mut lin = vec![0.0f32; w * h * 3];
    let bands = Mutex::new(lin.chunks_mut(w * 3 * BAND).enumerate());
    std::thread::scope(|s| {
        for _ in 0..threads.max(1) {
            s.spawn(|| {
                let mut leaves = Vec::with_capacity(8);
                let mut cache = Rosettes::new();
                loop {
                    let next = bands.lock().map(|mut b| b.next()).unwrap_or(None);
                    let Some((b, band)) = next else { break };
                    for (j, row) in band.chunks_mut(w * 3).enumerate() {
                        let r = b * BAND + j;
                        shade_row(
                            scene,
                            &look,
                            &rot,
                            corners,
                            inside,
                            w,
                            r,
                            row,
                            (&mut cache, &mut leaves),
                        );
                    }
                }
            });
        }
    });
    finish(scene.seed, &lin, inside, w, h, threads, out)
}

/// Shades image row `r` into `row` (linear RGB, 0..255).
#[allow(clippy::too_many_arguments)]
fn shade_row(
    scene: &Scene,
    look: &Look,
    rot: &Matrix3<f64>,
    corners: &[[f32; 3]],
    inside: &[bool],
    w: usize,
    r: usize,
    row: &mut [f32],
    (cache, leaves): (&mut Rosettes, &mut Vec<Leaf>),
) {
    let c0 = scene.pose.centre;
    let cw = w + 1;
    let world = |k: [f32; 3]| rot * Vector3::new(k[0] as f64, k[1] as f64, k[2] as f64);
    let ground = |d: &Vector3<f64>| {
        (d.z < 0.0).then(|| {
            let t = c0.z / -d.z;
            [c0.x + t * d.x, c0.y + t * d.y]
        })
    };
    for col in 0..w {
        let px = &mut row[col * 3..col * 3 + 3];
        if !inside[r * w + col] {
            px.fill(0.0);
            continue;
        }
        let k = [
            world(corners[r * cw + col]),
            world(corners[r * cw + col + 1]),
            world(corners[(r + 1) * cw + col]),
            world(corners[(r + 1) * cw + col + 1]),
        ];
        let g = [ground(&k[0]), ground(&k[1]), ground(&k[2]), ground(&k[3])];
        // The pixel's footprint on the ground, when all of it sees the ground.
        let footprint = match (g[0], g[3], g[1], g[2]) {
            (Some(a), Some(d), Some(b), Some(c)) => {
                ((a[0] - d[0]).hypot(a[1] - d[1])).max((b[0] - c[0]).hypot(b[1] - c[1]))
            }
            _ => f64::INFINITY,
        };
        let n = if footprint.is_finite() && !near_plants(look, &g, footprint) {
            1
        } else {
            SUPERSAMPLE
        };
        let mut acc = [0.0f32; 3];
        for i in 0..n {
            let u = (i as f64 + 0.5) / n as f64;
            for j in 0..n {
                let v = (j as f64 + 0.5) / n as f64;
                let d =
                    (k[0] * (1.0 - v) + k[1] * v) * (1.0 - u) + (k[2] * (1.0 - v) + k[3] * v) * u;
                let c = match ground(&d) {
                    None => {
                        let s = (d.z / d.norm()).clamp(0.0, 1.0) as f32;
                        [200.0 - 90.0 * s, 212.0 - 60.0 * s, 228.0 - 10.0 * s]
                    }
                    Some(p) => look
                        .leaf_at(p[0], p[1], cache, leaves)
                        .unwrap_or_else(|| look.soil(p[0], p[1], footprint.min(1.0) / n as f64)),
                };
                for ch in 0..3 {
                    acc[ch] += c[ch];
                }
            }
        }
        let inv = 1.0 / (n * n) as f32;
        for ch in 0..3 {
            px[ch] = acc[ch] * inv;
        }
    }
}

/// Whether a plant or a weed may reach into the pixel whose corners hit the ground at `g`.
fn near_plants(look: &Look, g: &[Option<[f64; 2]>; 4], footprint: f64) -> bool {
    let (mut cx, mut cy, mut n) = (0.0, 0.0, 0.0);
    for p in g.iter().flatten() {
        cx += p[0];
        cy += p[1];
        n += 1.0;
    }
    let (cx, cy) = (cx / n, cy / n);
    let reach = REACH * look.leaf_length + footprint;
    if look.field.any_plant_near(cx, cy, reach) {
        return true;
    }
    let (ix, iy) = (
        (cx / look.cell).floor() as i64,
        (cy / look.cell).floor() as i64,
    );
    let cells = (reach / look.cell).ceil() as i64 + 1;
    if ((2 * cells + 1) * (2 * cells + 1)) as usize > look.field.weeds().len() {
        let r = reach + look.cell;
        return look
            .field
            .weeds()
            .iter()
            .any(|w| (w[0] - cx).abs() <= r && (w[1] - cy).abs() <= r);
    }
    (-cells..=cells)
        .any(|dx| (-cells..=cells).any(|dy| look.weeds.contains_key(&(ix + dx, iy + dy))))
}

/// Lighting, sensor noise, lens blur, Bayer mosaic and demosaicing, JPEG: from the linear
/// image `lin` to `out`.
fn finish(
    seed: u64,
    lin: &[f32],
    inside: &[bool],
    w: usize,
    h: usize,
    threads: usize,
    out: &mut [u8],
) -> Result<(), SynthError> {
    let mut rng = Rng::stream(seed, 11);
    // A smooth illumination field over the image (clouds, the robot's shadow's edge) and
    // a vignette, 0.55..1.25 of the scene's light.
    let amp = 0.15 + 0.2 * rng.uniform();
    let lseed = rng.next_u64();
    let (hc, wc) = (h as f64 / 2.0, w as f64 / 2.0);
    let diag2 = hc * hc + wc * wc;
    let mut img = vec![0u8; w * h * 3];
    for r in 0..h {
        for c in 0..w {
            let (y, x) = (r as f64 / h as f64 * 3.0, c as f64 / w as f64 * 3.0);
            let light = (1.0
                + amp * value_noise(lseed, x, y)
                + 0.5 * amp * value_noise(lseed ^ 1, 2.3 * x, 2.3 * y))
                * (1.0 - 0.25 * ((r as f64 - hc).powi(2) + (c as f64 - wc).powi(2)) / diag2);
            let i = 3 * (r * w + c);
            for ch in 0..3 {
                let noise = 2.5 * rng.normal();
                img[i + ch] = (lin[i + ch] as f64 * light + noise)
                    .round()
                    .clamp(0.0, 255.0) as u8;
            }
        }
    }
    let mut blur = Blur::new();
    blur.apply(&mut img, w, h, 3, BLUR_PX, threads);
    let mut raw = vec![0u8; w * h];
    super::bayer::mosaic(&img, &mut raw, w, h);
    demosaic(&raw, w, h, &mut img);
    let mut jpeg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, JPEG_QUALITY)
        .encode(&img, w as u32, h as u32, image::ExtendedColorType::Rgb8)
        .map_err(|e| SynthError::Calibration(format!("leafy: JPEG encoding: {e}")))?;
    let back = image::load_from_memory_with_format(&jpeg, image::ImageFormat::Jpeg)
        .map_err(|e| SynthError::Calibration(format!("leafy: JPEG decoding: {e}")))?
        .to_rgb8();
    out.copy_from_slice(back.as_raw());
    for (px, &ins) in out.chunks_exact_mut(3).zip(inside) {
        if !ins {
            px.fill(0);
        }
    }
    Ok(())
}

/// Bilinear demosaicing of an RGGB mosaic into RGB: each missing channel the mean of its
/// nearest samples of that colour (mirrored at the borders).
pub fn demosaic(raw: &[u8], w: usize, h: usize, rgb: &mut [u8]) {
    // Mirrored at the borders, which keeps each neighbour's colour.
    let mirror = |i: isize, n: usize| -> usize {
        let n = n as isize;
        (if i < 0 {
            -i
        } else if i >= n {
            2 * n - 2 - i
        } else {
            i
        })
        .clamp(0, n - 1) as usize
    };
    let at = |r: isize, c: isize| -> u32 { raw[mirror(r, h) * w + mirror(c, w)] as u32 };
    // Colour of the mosaic at (r, c): 0 red, 1 green, 2 blue (RGGB).
    let colour = |r: usize, c: usize| match (r % 2, c % 2) {
        (0, 0) => 0,
        (1, 1) => 2,
        _ => 1,
    };
    for r in 0..h {
        for c in 0..w {
            let (ri, ci) = (r as isize, c as isize);
            let own = colour(r, c);
            let cross = (at(ri - 1, ci) + at(ri + 1, ci) + at(ri, ci - 1) + at(ri, ci + 1) + 2) / 4;
            let diag = (at(ri - 1, ci - 1)
                + at(ri - 1, ci + 1)
                + at(ri + 1, ci - 1)
                + at(ri + 1, ci + 1)
                + 2)
                / 4;
            let horiz = (at(ri, ci - 1) + at(ri, ci + 1)).div_ceil(2);
            let vert = (at(ri - 1, ci) + at(ri + 1, ci)).div_ceil(2);
            let v = raw[r * w + c] as u32;
            let px = match own {
                0 => [v, cross, diag],
                2 => [diag, cross, v],
                // Green on a red row: red left and right, blue above and below.
                _ if r % 2 == 0 => [horiz, v, vert],
                _ => [vert, v, horiz],
            };
            let i = 3 * (r * w + c);
            for ch in 0..3 {
                rgb[i + ch] = px[ch] as u8;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn demosaic_restores_flat_colour() {
        let (w, h) = (8, 6);
        let rgb: Vec<u8> = (0..w * h).flat_map(|_| [200u8, 120, 40]).collect();
        let mut raw = vec![0u8; w * h];
        crate::synth::mosaic(&rgb, &mut raw, w, h);
        let mut back = vec![0u8; w * h * 3];
        demosaic(&raw, w, h, &mut back);
        assert_eq!(back, rgb);
    }

    #[test]
    fn leafy_images_are_deterministic_colour_and_masked() {
        use crate::synth::{Renderer, Style, SynthOptions};
        let cal = crate::camera::ideal_fisheye(128, 160).unwrap();
        let opts = SynthOptions {
            style: Style::Leafy,
            weeds: 20,
            leaf_length_m: 0.08,
            ..Default::default()
        };
        let scene = Scene::new(&opts, 3, &cal.mounting).unwrap();
        let render = |threads: usize| {
            let mut r = Renderer::new(&cal).unwrap().with_threads(threads);
            let mut out = vec![0u8; r.buffer_len(Style::Leafy)];
            r.render_into(&scene, &mut out).unwrap();
            out
        };
        let a = render(2);
        assert_eq!(a.len(), 128 * 160 * 3);
        assert_eq!(a, render(1));
        // Outside the image circle: black; inside: green plants on brown soil.
        assert_eq!(&a[0..3], &[0, 0, 0]);
        let green = a
            .chunks_exact(3)
            .filter(|p| p[1] as i32 > p[0] as i32 + 15 && p[1] as i32 > p[2] as i32 + 15)
            .count();
        let soil = a.chunks_exact(3).filter(|p| p[0] > p[2] + 15).count();
        assert!(green > 50 && soil > 2000, "{green} {soil}");
    }

    #[test]
    fn rosettes_vary_and_cover_their_stem() {
        let mut a = Vec::new();
        let mut b = Vec::new();
        rosette([0.0, 0.0], 1, 0.1, false, &mut a);
        rosette([0.0, 0.0], 2, 0.1, false, &mut b);
        assert!((3..=7).contains(&a.len()));
        assert_ne!(
            a.iter().map(|l| l.half_len).collect::<Vec<_>>(),
            b.iter().map(|l| l.half_len).collect::<Vec<_>>()
        );
        // Every leaf starts at the stem, so the stem is green.
        assert!(a.iter().any(|l| l.shade(0.0, 0.0).is_some()));
        // Nothing beyond the rosette's reach.
        assert!(a.iter().all(|l| l.shade(REACH * 0.1 + 1e-3, 0.0).is_none()));
    }
}
