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
            vertical(k, tmp, 0, width, height, rows, d)
        });
        Ok(())
    }

    /// The rows `rows` of an image `width` × `height` smoothed into `dst` (which holds just
    /// them), in strips of [`STRIP`] rows, each smoothed as soon as the rows it reads are
    /// there, so that its source rows are still in the cache: `fill(r, out)` writes the
    /// source image's rows `r` into `out` (each row once: the band's own rows into `src`,
    /// which holds just them, the rows beyond the band that the filter reaches into
    /// `scratch`'s), and `done(r, smoothed)` is handed each strip once it is smoothed. The
    /// rows are [`Self::apply`]'s to the bit. Allocates only while `scratch` grows.
    #[allow(clippy::too_many_arguments)]
    pub fn apply_band(
        &self,
        width: usize,
        height: usize,
        rows: Range<usize>,
        src: &mut [u8],
        dst: &mut [u8],
        scratch: &mut BandScratch,
        mut fill: impl FnMut(Range<usize>, &mut [u8]),
        mut done: impl FnMut(Range<usize>, &[u8]),
    ) -> Result<(), DetectError> {
        let n = rows.len() * width;
        if rows.end > height || src.len() != n || dst.len() != n {
            return Err(DetectError::Buffer(format!(
                "smooth: rows {rows:?} of a {width}x{height} image need {n} pixels, source has {}, destination {}",
                src.len(),
                dst.len()
            )));
        }
        let (k, r, w) = (&self.kernel[..], self.radius, width);
        let (y0, y1) = (rows.start, rows.end);
        // The horizontal pass's rows [first, next) of the image.
        let window = &mut scratch.window;
        window.resize((STRIP + 2 * r) * w, 0);
        scratch.halo.resize(r * w, 0);
        let mut first = y0.saturating_sub(r);
        let mut next = first;
        let mut s0 = y0;
        while s0 < y1 {
            let s1 = (s0 + STRIP).min(y1);
            let (lo, hi) = (s0.saturating_sub(r), (s1 + r).min(height));
            if lo > first {
                window.copy_within((lo - first) * w..(next - first) * w, 0);
                first = lo;
            }
            while next < hi {
                // The band's own rows, or those above or below it.
                let (a, b) = match next {
                    y if y < y0 => (y, y0),
                    y if y < y1 => (y, y1.min(hi)),
                    y => (y, hi),
                };
                let from: &mut [u8] = if (y0..y1).contains(&a) {
                    &mut src[(a - y0) * w..(b - y0) * w]
                } else {
                    &mut scratch.halo[..(b - a) * w]
                };
                fill(a..b, from);
                horizontal(k, from, w, &mut window[(a - first) * w..(b - first) * w]);
                next = b;
            }
            let out = &mut dst[(s0 - y0) * w..(s1 - y0) * w];
            vertical(
                k,
                &window[..(next - first) * w],
                first,
                w,
                height,
                s0..s1,
                out,
            );
            done(s0..s1, out);
            s0 = s1;
        }
        Ok(())
    }
}

/// Rows per strip of [`Gaussian::apply_band`]: a strip's source, its passes and the mask
/// beside it stay within a core's cache.
pub const STRIP: usize = 32;

/// A band's scratch for [`Gaussian::apply_band`] (grown on first use).
#[derive(Debug, Clone, Default)]
pub struct BandScratch {
    /// The horizontal pass's rows a strip reads.
    window: Vec<u8>,
    /// Source rows beyond the band.
    halo: Vec<u8>,
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

/// The vertical pass of [`Gaussian::apply`]: the columns of `tmp` (the horizontal pass's
/// rows from row `first` of the image on) smoothed into the rows `rows` of the image, which
/// `dst` holds.
#[multiversion(targets("x86_64+avx2"))]
fn vertical(
    kernel: &[u32],
    tmp: &[u8],
    first: usize,
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
                let yy = (y as isize + j as isize - r as isize).clamp(0, height as isize - 1)
                    as usize
                    - first;
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

    /// `g.apply_band` over the bands `cuts` of `src` (each filled from `src` itself), with
    /// the strips each band hands on.
    fn by_bands(
        g: &Gaussian,
        src: &[u8],
        width: usize,
        height: usize,
        cuts: &[usize],
    ) -> (Vec<u8>, Vec<Range<usize>>) {
        let (mut veg, mut dst) = (vec![0u8; src.len()], vec![0u8; src.len()]);
        let mut strips = Vec::new();
        let mut scratch = BandScratch::default();
        let mut filled = vec![0u32; height];
        for b in cuts.windows(2) {
            let rows = b[0]..b[1];
            let span = rows.start * width..rows.end * width;
            g.apply_band(
                width,
                height,
                rows,
                &mut veg[span.clone()],
                &mut dst[span],
                &mut scratch,
                |r, out| {
                    out.copy_from_slice(&src[r.start * width..r.end * width]);
                    for y in r {
                        filled[y] += 1;
                    }
                },
                |r, out| {
                    assert_eq!(
                        out,
                        &dst_of(g, src, width, height)[r.start * width..r.end * width]
                    );
                    strips.push(r);
                },
            )
            .unwrap();
        }
        // every row of a band filled once, and the band's neighbours' rows it reaches
        let r = g.radius;
        for (y, &n) in filled.iter().enumerate() {
            let reached = cuts
                .windows(2)
                .filter(|b| y + r >= b[0] && y < b[1] + r)
                .count() as u32;
            assert_eq!(n, reached, "row {y} filled {n} times");
        }
        assert_eq!(veg, src, "the band's own rows are filled in place");
        (dst, strips)
    }

    fn dst_of(g: &Gaussian, src: &[u8], width: usize, height: usize) -> Vec<u8> {
        let (mut tmp, mut dst) = (Vec::new(), vec![0u8; width * height]);
        g.apply(src, width, height, &mut tmp, &mut dst).unwrap();
        dst
    }

    #[test]
    fn bands_filled_strip_by_strip_are_the_whole_image_to_the_bit() {
        for (sigma, width, height) in [
            (0.8, 300, 211),
            (1.5, 97, 100),
            (3.0, 40, 9),
            (0.0, 33, 70),
            (2.0, 3, 40),
        ] {
            let g = Gaussian::new(&SmoothOptions { sigma_px: sigma }).unwrap();
            let src = crate::detect::noise_bytes(0x77 ^ width as u64, width * height);
            let want = dst_of(&g, &src, width, height);
            let mut cuts_list = vec![vec![0, height], vec![0, height / 2, height]];
            cuts_list.push(vec![0, 1, 2, STRIP + 1, height.max(STRIP + 1)]);
            cuts_list.push((0..=height).collect());
            for cuts in cuts_list {
                if cuts.windows(2).any(|b| b[0] > b[1]) || cuts.last() != Some(&height) {
                    continue;
                }
                let (got, strips) = by_bands(&g, &src, width, height, &cuts);
                assert_eq!(got, want, "sigma {sigma}, {width}x{height}, bands {cuts:?}");
                let rows: usize = strips.iter().map(|r| r.len()).sum();
                assert_eq!(rows, height);
                assert!(strips.iter().all(|r| r.len() <= STRIP));
            }
        }
        // bad sizes are named
        let g = Gaussian::new(&SmoothOptions { sigma_px: 1.0 }).unwrap();
        let (mut a, mut b) = (vec![0u8; 10], vec![0u8; 10]);
        let e = g.apply_band(
            5,
            3,
            1..4,
            &mut a,
            &mut b,
            &mut BandScratch::default(),
            |_, _| {},
            |_, _| {},
        );
        assert!(e.is_err());
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
