//! Gaussian smoothing of an 8-bit image (paper II-D: "a Gaussian smooth filter is applied to
//! reduce noise"), separable, in fixed point, into caller-owned buffers.
//!
//! Owns the kernel (built once from σ) and the two passes: horizontal into a 16-bit
//! intermediate, vertical back to 8 bits. Borders replicate the edge pixel. No allocation
//! once the caller's buffers have their size.

use super::bands;
use super::types::DetectError;
use multiversion::multiversion;
use rayon::ThreadPool;
use serde::{Deserialize, Serialize};
use std::ops::Range;

/// Options of the Gaussian filter.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SmoothOptions {
    /// Standard deviation in working-image pixels; 0 disables smoothing (a copy).
    pub sigma_px: f64,
}

impl Default for SmoothOptions {
    fn default() -> Self {
        SmoothOptions { sigma_px: 0.8 }
    }
}

/// A separable Gaussian filter in 8.8 fixed point.
#[derive(Debug, Clone, PartialEq)]
pub struct Gaussian {
    /// Weights for offsets −radius..=radius, summing to 256.
    kernel: Vec<u32>,
    radius: usize,
}

impl SmoothOptions {
    pub fn validate(&self) -> Result<(), DetectError> {
        let s = self.sigma_px;
        if s.is_finite() && (0.0..=20.0).contains(&s) {
            Ok(())
        } else {
            Err(DetectError::Options(format!(
                "smooth.sigma_px = {s} must be within 0..=20"
            )))
        }
    }
}

impl Gaussian {
    pub fn new(opts: &SmoothOptions) -> Result<Self, DetectError> {
        opts.validate()?;
        let s = opts.sigma_px;
        if s < 0.05 {
            return Ok(Gaussian {
                kernel: vec![256],
                radius: 0,
            });
        }
        let radius = (2.5 * s).ceil() as usize;
        let raw: Vec<f64> = (0..=2 * radius)
            .map(|i| {
                let x = i as f64 - radius as f64;
                (-0.5 * x * x / (s * s)).exp()
            })
            .collect();
        let sum: f64 = raw.iter().sum();
        let mut kernel: Vec<u32> = raw
            .iter()
            .map(|v| (v / sum * 256.0).round() as u32)
            .collect();
        // Make the weights sum to exactly 256 (adjust the centre), keeping the kernel symmetric.
        let total: i64 = kernel.iter().map(|&v| v as i64).sum();
        let c = kernel[radius] as i64 + 256 - total;
        kernel[radius] = c.max(0) as u32;
        Ok(Gaussian { kernel, radius })
    }

    pub fn radius(&self) -> usize {
        self.radius
    }

    /// Smooths `src` (width × height) into `dst` using `tmp` as the intermediate (8-bit,
    /// rounded). `tmp` is resized (allocating only when it grows); `dst` must have the size
    /// of `src`. Both passes accumulate 16-bit sums tap by tap over runs of pixels, which the
    /// compiler vectorises.
    pub fn apply(
        &self,
        src: &[u8],
        width: usize,
        height: usize,
        tmp: &mut Vec<u8>,
        dst: &mut [u8],
    ) -> Result<(), DetectError> {
        self.apply_on(src, width, height, tmp, dst, None)
    }

    /// [`Self::apply`] with each pass's rows in bands on `pool`'s threads
    /// ([`super::bands`]) when there is one: the same image.
    pub fn apply_on(
        &self,
        src: &[u8],
        width: usize,
        height: usize,
        tmp: &mut Vec<u8>,
        dst: &mut [u8],
        pool: Option<&ThreadPool>,
    ) -> Result<(), DetectError> {
        let n = width * height;
        if src.len() != n || dst.len() != n {
            return Err(DetectError::Buffer(format!(
                "smooth: image {width}x{height} needs {n} pixels, source has {}, destination {}",
                src.len(),
                dst.len()
            )));
        }
        if self.radius == 0 || width == 0 || height == 0 {
            dst.copy_from_slice(src);
            return Ok(());
        }
        tmp.resize(n, 0);
        let k = &self.kernel;
        bands::rows(pool, tmp, width, &|rows, t: &mut [u8]| {
            horizontal(k, &src[rows.start * width..rows.end * width], width, t)
        });
        let tmp = &tmp[..];
        bands::rows(pool, dst, width, &|rows, d: &mut [u8]| {
            vertical(k, tmp, width, height, rows, d)
        });
        Ok(())
    }
}

/// The horizontal pass of [`Gaussian::apply`] (`kernel`: 2·radius + 1 weights summing to
/// 256): each row of `src` smoothed along itself into `tmp`, borders replicated.
#[multiversion(targets("x86_64+avx2"))]
fn horizontal(kernel: &[u32], src: &[u8], width: usize, tmp: &mut [u8]) {
    let r = kernel.len() / 2;
    let kw16 = |j: usize| kernel[j] as u16;
    let border = |srow: &[u8], x: usize| -> u8 {
        let mut acc = 128u32;
        for (j, &kw) in kernel.iter().enumerate() {
            let xx = (x as isize + j as isize - r as isize).clamp(0, width as isize - 1);
            acc += kw * srow[xx as usize] as u32;
        }
        (acc >> 8).min(255) as u8
    };
    for (srow, trow) in src.chunks_exact(width).zip(tmp.chunks_exact_mut(width)) {
        if width <= 2 * r {
            for (x, t) in trow.iter_mut().enumerate() {
                *t = border(srow, x);
            }
            continue;
        }
        for (x, t) in trow.iter_mut().enumerate().take(r) {
            *t = border(srow, x);
        }
        for (x, t) in trow.iter_mut().enumerate().skip(width - r) {
            *t = border(srow, x);
        }
        let mut x0 = r;
        while x0 < width - r {
            let len = CHUNK.min(width - r - x0);
            let mut acc = [128u16; CHUNK];
            let acc = &mut acc[..len];
            // The kernel is symmetric: each pair of taps is one multiply (the same sums).
            for j in 0..r {
                let w = kw16(j);
                let s1 = &srow[x0 - r + j..x0 - r + j + len];
                let s2 = &srow[x0 + r - j..x0 + r - j + len];
                for ((a, &u), &v) in acc.iter_mut().zip(s1).zip(s2) {
                    *a += w * (u as u16 + v as u16);
                }
            }
            let w = kw16(r);
            for (a, &v) in acc.iter_mut().zip(&srow[x0..x0 + len]) {
                *a += w * v as u16;
            }
            for (t, &a) in trow[x0..x0 + len].iter_mut().zip(acc.iter()) {
                *t = (a >> 8) as u8;
            }
            x0 += len;
        }
    }
}

/// The vertical pass of [`Gaussian::apply`]: the columns of `tmp` smoothed into the rows
/// `rows` of the image, which `dst` holds.
#[multiversion(targets("x86_64+avx2"))]
fn vertical(
    kernel: &[u32],
    tmp: &[u8],
    width: usize,
    height: usize,
    rows: Range<usize>,
    dst: &mut [u8],
) {
    let r = kernel.len() / 2;
    let kw16 = |j: usize| kernel[j] as u16;
    let y0 = rows.start;
    for y in rows {
        let drow = &mut dst[(y - y0) * width..(y - y0 + 1) * width];
        let mut x0 = 0;
        while x0 < width {
            let len = CHUNK.min(width - x0);
            let mut acc = [128u16; CHUNK];
            let acc = &mut acc[..len];
            let row = |j: usize| {
                let yy =
                    (y as isize + j as isize - r as isize).clamp(0, height as isize - 1) as usize;
                &tmp[yy * width + x0..yy * width + x0 + len]
            };
            for j in 0..r {
                let w = kw16(j);
                for ((a, &u), &v) in acc.iter_mut().zip(row(j)).zip(row(2 * r - j)) {
                    *a += w * (u as u16 + v as u16);
                }
            }
            let w = kw16(r);
            for (a, &t) in acc.iter_mut().zip(row(r)) {
                *a += w * t as u16;
            }
            for (d, &a) in drow[x0..x0 + len].iter_mut().zip(acc.iter()) {
                *d = (a >> 8) as u8;
            }
            x0 += len;
        }
    }
}

/// Pixels per run of the passes' 16-bit sums.
const CHUNK: usize = 256;

#[cfg(test)]
mod tests {
    use super::*;

    /// Each output pixel summed tap by tap with replicated borders: the definition.
    fn by_definition(g: &Gaussian, src: &[u8], width: usize, height: usize) -> Vec<u8> {
        let r = g.radius as isize;
        let pass = |img: &[u8], along_rows: bool| -> Vec<u8> {
            let mut out = vec![0u8; img.len()];
            for y in 0..height as isize {
                for x in 0..width as isize {
                    let mut acc = 128u32;
                    for (j, &w) in g.kernel.iter().enumerate() {
                        let d = j as isize - r;
                        let (yy, xx) = if along_rows {
                            (y, (x + d).clamp(0, width as isize - 1))
                        } else {
                            ((y + d).clamp(0, height as isize - 1), x)
                        };
                        acc += w * img[yy as usize * width + xx as usize] as u32;
                    }
                    out[y as usize * width + x as usize] = (acc >> 8).min(255) as u8;
                }
            }
            out
        };
        pass(&pass(src, true), false)
    }

    #[test]
    fn bands_on_threads_are_the_whole_image_to_the_bit() {
        let pool = |n| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap()
        };
        for (sigma, width, height) in [(1.5, 300, 211), (3.0, 97, 64), (0.8, 40, 9)] {
            let g = Gaussian::new(&SmoothOptions { sigma_px: sigma }).unwrap();
            let src = crate::detect::noise_bytes(0x51 ^ width as u64, width * height);
            let (mut tmp, mut want) = (Vec::new(), vec![0u8; width * height]);
            g.apply(&src, width, height, &mut tmp, &mut want).unwrap();
            for n in [2, 3] {
                let mut got = vec![0u8; width * height];
                g.apply_on(&src, width, height, &mut tmp, &mut got, Some(&pool(n)))
                    .unwrap();
                assert_eq!(got, want, "sigma {sigma}, {width}x{height}, {n} threads");
            }
        }
    }

    #[test]
    fn the_passes_are_the_definition_to_the_bit() {
        for (sigma, width, height) in [(0.8, 300, 41), (1.5, 613, 17), (3.0, 40, 9)] {
            let g = Gaussian::new(&SmoothOptions { sigma_px: sigma }).unwrap();
            let src =
                crate::detect::noise_bytes(0x9e37_79b9_7f4a_7c15 ^ width as u64, width * height);
            let (mut tmp, mut dst) = (Vec::new(), vec![0u8; width * height]);
            g.apply(&src, width, height, &mut tmp, &mut dst).unwrap();
            assert_eq!(dst, by_definition(&g, &src, width, height), "sigma {sigma}");
        }
    }

    #[test]
    fn constant_image_stays_constant() {
        let g = Gaussian::new(&SmoothOptions { sigma_px: 1.5 }).unwrap();
        let src = vec![77u8; 20 * 13];
        let mut dst = vec![0u8; 20 * 13];
        let mut tmp = Vec::new();
        g.apply(&src, 20, 13, &mut tmp, &mut dst).unwrap();
        assert!(dst.iter().all(|&v| v == 77), "{dst:?}");
    }

    #[test]
    fn impulse_spreads_symmetrically_and_keeps_mass() {
        let g = Gaussian::new(&SmoothOptions { sigma_px: 0.8 }).unwrap();
        let (w, h) = (15, 15);
        let mut src = vec![0u8; w * h];
        src[7 * w + 7] = 255;
        let mut dst = vec![0u8; w * h];
        let mut tmp = Vec::new();
        g.apply(&src, w, h, &mut tmp, &mut dst).unwrap();
        let at = |r: usize, c: usize| dst[r * w + c];
        assert!(at(7, 7) > at(7, 8) && at(7, 8) > at(7, 9));
        assert_eq!(at(7, 6), at(7, 8));
        assert_eq!(at(6, 7), at(8, 7));
        assert_eq!(at(6, 7), at(7, 6));
        let mass: u32 = dst.iter().map(|&v| v as u32).sum();
        assert!((240..=270).contains(&mass), "{mass}");
        // sigma 0 copies
        let g0 = Gaussian::new(&SmoothOptions { sigma_px: 0.0 }).unwrap();
        g0.apply(&src, w, h, &mut tmp, &mut dst).unwrap();
        assert_eq!(dst, src);
    }

    #[test]
    fn narrow_images_and_bad_sizes() {
        let g = Gaussian::new(&SmoothOptions { sigma_px: 2.0 }).unwrap();
        let src = vec![9u8; 3 * 2];
        let mut dst = vec![0u8; 6];
        let mut tmp = Vec::new();
        g.apply(&src, 3, 2, &mut tmp, &mut dst).unwrap();
        assert!(dst.iter().all(|&v| v == 9));
        assert!(g.apply(&src, 4, 2, &mut tmp, &mut dst).is_err());
        assert!(Gaussian::new(&SmoothOptions { sigma_px: -1.0 }).is_err());
    }
}
