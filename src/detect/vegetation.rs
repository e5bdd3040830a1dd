//! Vegetation image: from the camera's pixels to one 8-bit channel where plants are bright.
//!
//! Owns the colour-to-vegetation step of the paper's section III-C ("the green parts of the
//! image are used"): RGB input becomes the excess-green index 2G − R − B (clamped at zero and
//! halved so that it fits a byte); Bayer RGGB input is read as 2×2 quads (R, two G, B) and
//! gives the same index at half resolution; greyscale input is used as is (plants bright, as
//! in the paper's synthetic images). Optional 2×2 binning brings a full-resolution frame to
//! half resolution, so the calibration must then be rescaled by 2 (a half-resolution pixel
//! (r, c) is centred at full-resolution (2r + 0.5, 2c + 0.5), which
//! [`Calibration::rescaled`](crate::camera::Calibration::rescaled) does).

use super::bands;
use super::types::{DetectError, GreyImage};
use crate::frame::{ImageView, PixelFormat};
use multiversion::multiversion;
use rayon::ThreadPool;
use serde::{Deserialize, Serialize};
use std::ops::Range;

/// Whether full-resolution Mono8/RGB8 input is binned 2×2 before detection.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Binning {
    /// Bin when the image has more than [`AUTO_BIN_ABOVE_PX`] pixels (and even sides).
    #[default]
    Auto,
    Off,
    Half,
}

/// `binning = "auto"` bins images of more than this many pixels (a GC2450C frame).
pub const AUTO_BIN_ABOVE_PX: u64 = 1_600_000;

impl Binning {
    /// Whether an image of `width`×`height` pixels is binned 2×2.
    pub fn bins(self, width: u32, height: u32) -> bool {
        let even = width % 2 == 0 && height % 2 == 0;
        match self {
            Binning::Off => false,
            Binning::Half => true,
            Binning::Auto => width as u64 * height as u64 > AUTO_BIN_ABOVE_PX && even,
        }
    }
}

/// Which index turns colour into vegetation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VegetationIndex {
    /// Excess green, unless the colour image carries no colour (R = G = B, e.g. a greyscale
    /// picture saved as RGB): then brightness.
    #[default]
    Auto,
    /// Excess green 2G − R − B, clamped at 0, halved: 0..=255.
    ExcessGreen,
    /// Brightness (R + 2G + B) / 4: for colour images whose plants are simply bright.
    Luma,
    /// Excess green of the chromatic coordinates, 2g − r − b with r = R / (R + G + B) etc.
    /// (Woebbecke et al. 1995), scaled so that 1 is 255: independent of the illumination's
    /// brightness, so a plant in a shadow is as green as one in the sun.
    ChromaticExcessGreen,
    /// Excess green minus excess red of the chromatic coordinates, (2g − r − b) − (1.4r − g)
    /// (Meyer & Neto 2008), scaled so that 1 is 255: also rejects reddish soil and straw.
    ExcessGreenMinusRed,
}

/// Options of the vegetation step.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VegetationOptions {
    pub index: VegetationIndex,
}

/// What the vegetation step produced.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VegetationResult {
    /// Size reduction from the input image (1 or 2).
    pub factor: u32,
    pub width: usize,
    pub height: usize,
}

/// The working-image size for an input size, format and binning choice: Bayer input is
/// always read by quads (factor 2). Errors when a factor-2 image cannot be formed.
pub fn working_factor(
    width: u32,
    height: u32,
    format: PixelFormat,
    bin2: bool,
) -> Result<u32, DetectError> {
    let factor = if format == PixelFormat::BayerRggb8 || bin2 {
        2
    } else {
        1
    };
    if factor == 2 && (width % 2 != 0 || height % 2 != 0) {
        return Err(DetectError::Image {
            height,
            width,
            problem: format!(
                "{} needs an even width and height (2x2 quads)",
                if format == PixelFormat::BayerRggb8 {
                    "Bayer input"
                } else {
                    "2x2 binning"
                }
            ),
        });
    }
    Ok(factor)
}

#[inline]
fn exg(r: i32, g2: i32, b: i32) -> u8 {
    // g2 is 2G; result (2G - R - B) / 2 clamped to 0..=255.
    ((g2 - r - b).max(0) >> 1).min(255) as u8
}

/// Added to R + G + B before dividing: near-black pixels (noise, deep shadow) have no
/// reliable chromaticity and must not become vegetation.
const CHROMA_DARK: i32 = 24;

#[inline]
fn chroma_exg(r: i32, g2: i32, b: i32) -> u8 {
    // 255 (2G − R − B) / (R + G + B + k), from g2 = 2G.
    let num = 255 * (g2 - r - b).max(0);
    let den = 2 * (r + b) + g2 + 2 * CHROMA_DARK;
    ((2 * num / den).min(255)) as u8
}

#[inline]
fn exg_exr(r: i32, g2: i32, b: i32) -> u8 {
    // 255 (3G − 2.4R − B) / (R + G + B + k) = 255 (15 g2 − 24 r − 10 b) / (10 (2R + g2 + 2B + 2k)).
    let num = 255 * (15 * g2 - 24 * r - 10 * b).max(0);
    let den = 10 * (2 * (r + b) + g2 + 2 * CHROMA_DARK);
    ((2 * num / den).min(255)) as u8
}

#[inline]
fn luma(r: i32, g2: i32, b: i32) -> u8 {
    ((r + g2 + b + 2) >> 2).min(255) as u8
}

/// Whether RGB bytes carry colour: the mean of |R − G| + |G − B| over about 4096 pixels
/// spread through the image is at least 1.
fn has_colour(rgb: &[u8]) -> bool {
    let n = rgb.len() / 3;
    let step = (n / 4096).max(1);
    let (mut sum, mut count) = (0u64, 0u64);
    for p in rgb.chunks_exact(3).step_by(step) {
        sum += (p[0] as i32 - p[1] as i32).unsigned_abs() as u64
            + (p[1] as i32 - p[2] as i32).unsigned_abs() as u64;
        count += 1;
    }
    count > 0 && sum >= count
}

/// Computes the vegetation image of `view` into `out` (resized as needed, which allocates only
/// when it grows). `bin2` asks for 2×2 binning of Mono8/Rgb8 input; Bayer input is always
/// read by quads.
pub fn vegetation_image(
    view: &ImageView,
    opts: &VegetationOptions,
    bin2: bool,
    out: &mut GreyImage,
) -> Result<VegetationResult, DetectError> {
    vegetation_image_on(view, opts, bin2, out, None)
}

/// [`vegetation_image`] with its rows in bands on `pool`'s threads ([`super::bands`]) when
/// there is one: the same image.
pub fn vegetation_image_on(
    view: &ImageView,
    opts: &VegetationOptions,
    bin2: bool,
    out: &mut GreyImage,
    pool: Option<&ThreadPool>,
) -> Result<VegetationResult, DetectError> {
    let veg = Vegetation::new(view, opts, bin2)?;
    let (ow, oh) = veg.size();
    out.resize(ow, oh);
    bands::rows(pool, &mut out.data, ow, &|rows, o: &mut [u8]| {
        veg.rows(rows, o)
    });
    Ok(VegetationResult {
        factor: veg.factor as u32,
        width: ow,
        height: oh,
    })
}

/// The vegetation image of one input image, row by row: [`Vegetation::rows`] computes any
/// rows of it, each exactly as [`vegetation_image`] does, so a stage can compute them band
/// by band, or strip by strip, where it reads them.
pub struct Vegetation<'a> {
    d: &'a [u8],
    /// The input's width (pixels).
    w: usize,
    factor: usize,
    ow: usize,
    oh: usize,
    /// `None`: Mono8 (copied, or binned 2×2).
    layout: Option<Colour>,
    index: VegetationIndex,
}

impl<'a> Vegetation<'a> {
    /// Checks `view` (its bytes, and even sides where it is read by quads) and chooses the
    /// index (`auto`: excess green, or brightness for an RGB image without colour).
    pub fn new(
        view: &ImageView<'a>,
        opts: &VegetationOptions,
        bin2: bool,
    ) -> Result<Self, DetectError> {
        let (w, h) = (view.width as usize, view.height as usize);
        let expected = w * h * view.format.bytes_per_pixel();
        if view.data.len() != expected {
            return Err(DetectError::Image {
                height: view.height,
                width: view.width,
                problem: format!(
                    "{:?} needs {expected} bytes, has {}",
                    view.format,
                    view.data.len()
                ),
            });
        }
        let factor = working_factor(view.width, view.height, view.format, bin2)? as usize;
        let d = view.data;
        let index = match opts.index {
            VegetationIndex::Auto if view.format == PixelFormat::Rgb8 && !has_colour(d) => {
                VegetationIndex::Luma
            }
            VegetationIndex::Auto => VegetationIndex::ExcessGreen,
            other => other,
        };
        let layout = match (view.format, factor) {
            (PixelFormat::Mono8, _) => None,
            (PixelFormat::Rgb8, 1) => Some(Colour::Rgb),
            (PixelFormat::Rgb8, _) => Some(Colour::RgbBinned),
            (PixelFormat::BayerRggb8, _) => Some(Colour::Bayer),
        };
        Ok(Vegetation {
            d,
            w,
            factor,
            ow: w / factor,
            oh: h / factor,
            layout,
            index,
        })
    }

    /// The vegetation image's width and height.
    pub fn size(&self) -> (usize, usize) {
        (self.ow, self.oh)
    }

    /// The vegetation image's rows `rows` into `out`, which holds just them.
    pub fn rows(&self, rows: Range<usize>, out: &mut [u8]) {
        let (d, w, oh) = (self.d, self.w, self.oh);
        let Some(layout) = self.layout else {
            if self.factor == 1 {
                return out.copy_from_slice(&d[rows.start * w..rows.end * w]);
            }
            return mono_binned(d, w, self.ow, rows, out);
        };
        // One instance per index, so that each inner loop inlines its index rather than
        // calling it through a pointer for every pixel.
        let (r, o) = (rows, out);
        match self.index {
            VegetationIndex::Luma => colour(layout, d, w, r, oh, o, luma),
            VegetationIndex::ChromaticExcessGreen => colour(layout, d, w, r, oh, o, chroma_exg),
            VegetationIndex::ExcessGreenMinusRed => colour(layout, d, w, r, oh, o, exg_exr),
            VegetationIndex::Auto | VegetationIndex::ExcessGreen => {
                colour(layout, d, w, r, oh, o, exg)
            }
        }
    }
}

/// Mono8 input binned 2×2 (output rows `rows` into `out`, which holds just them): column
/// pairs of the two rows summed first (contiguous, vectorised), then the pairs of sums, in
/// runs that fit a stack buffer.
#[multiversion(targets("x86_64+avx2"))]
fn mono_binned(d: &[u8], w: usize, ow: usize, rows: Range<usize>, out: &mut [u8]) {
    const RUN: usize = 256;
    let mut sums = [0u16; 2 * RUN];
    let r0 = rows.start;
    for r in rows {
        let a = &d[2 * r * w..2 * r * w + 2 * ow];
        let b = &d[(2 * r + 1) * w..(2 * r + 1) * w + 2 * ow];
        let o = &mut out[(r - r0) * ow..(r - r0 + 1) * ow];
        for ((o, a), b) in o
            .chunks_mut(RUN)
            .zip(a.chunks(2 * RUN))
            .zip(b.chunks(2 * RUN))
        {
            let t = &mut sums[..a.len()];
            for ((t, &x), &y) in t.iter_mut().zip(a).zip(b) {
                *t = x as u16 + y as u16;
            }
            for (v, p) in o.iter_mut().zip(t.chunks_exact(2)) {
                *v = ((p[0] + p[1] + 2) >> 2) as u8;
            }
        }
    }
}

/// How colour input is read into the vegetation image.
#[derive(Debug, Clone, Copy)]
enum Colour {
    /// RGB, pixel by pixel.
    Rgb,
    /// RGB binned 2×2.
    RgbBinned,
    /// Bayer RGGB, by quads.
    Bayer,
}

/// The vegetation index `f` (R, 2G, B → byte) of colour input (`w` wide, `oh` output rows)
/// for the output rows `rows` into `out` (which holds just them): RGB pixel by pixel or
/// binned 2×2, Bayer by quads.
#[multiversion(targets("x86_64+avx2"))]
fn colour(
    layout: Colour,
    d: &[u8],
    w: usize,
    rows: Range<usize>,
    oh: usize,
    out: &mut [u8],
    f: impl Fn(i32, i32, i32) -> u8,
) {
    let r0 = rows.start;
    match layout {
        Colour::Rgb => {
            let d = &d[r0 * w * 3..rows.end * w * 3];
            for (o, p) in out.iter_mut().zip(d.chunks_exact(3)) {
                *o = f(p[0] as i32, 2 * p[1] as i32, p[2] as i32);
            }
        }
        Colour::RgbBinned => {
            let ow = w / 2;
            for r in rows {
                let a = &d[2 * r * w * 3..(2 * r + 1) * w * 3];
                let b = &d[(2 * r + 1) * w * 3..(2 * r + 2) * w * 3];
                let o = &mut out[(r - r0) * ow..(r - r0 + 1) * ow];
                for (c, v) in o.iter_mut().enumerate() {
                    let i = 6 * c;
                    let sum = |k: usize| -> i32 {
                        a[i + k] as i32
                            + a[i + 3 + k] as i32
                            + b[i + k] as i32
                            + b[i + 3 + k] as i32
                    };
                    // Means of the four pixels: R = sum/4 etc.; 2G - R - B = (2 sG - sR - sB) / 4.
                    let (sr, sg, sb) = (sum(0), sum(1), sum(2));
                    *v = f((sr + 2) >> 2, (2 * sg + 2) >> 2, (sb + 2) >> 2);
                }
            }
        }
        // The quad's two greens are centred on it, but its red sits half a pixel up and
        // left and its blue half a pixel down and right: read as they are, every edge whose
        // red and blue contrasts differ (plant against soil) shifts, which moves a row's
        // fitted centre line by a fraction of a pixel that does not average out. Red and
        // blue are interpolated (bilinearly, from the four nearest samples of each, clamped
        // at the borders) to the quad's centre.
        Colour::Bayer => bayer_centred(d, w, rows, oh, out, f),
    }
}

/// The vegetation index `f` of each quad of a Bayer RGGB image (`w` wide, `oh` quad rows)
/// in the quad rows `rows` into `out` (which holds just them), with red and blue
/// interpolated bilinearly to the quad's centre from the four nearest samples of each
/// (clamped at the borders).
fn bayer_centred(
    d: &[u8],
    w: usize,
    rows: Range<usize>,
    oh: usize,
    out: &mut [u8],
    f: impl Fn(i32, i32, i32) -> u8,
) {
    let ow = w / 2;
    let r0 = rows.start;
    for r in rows {
        let a = &d[2 * r * w..2 * r * w + w];
        let b = &d[(2 * r + 1) * w..(2 * r + 1) * w + w];
        // Red of the next quad row, blue of the previous one.
        let an = &d[2 * (r + 1).min(oh - 1) * w..][..w];
        let bp = &d[(2 * r.saturating_sub(1) + 1) * w..][..w];
        let o = &mut out[(r - r0) * ow..(r - r0 + 1) * ow];
        let quad = |c: usize| {
            let (cn, cp) = (2 * (c + 1).min(ow - 1), 2 * c.saturating_sub(1) + 1);
            let (c0, c1) = (2 * c, 2 * c + 1);
            let red16 = 9 * a[c0] as i32 + 3 * (a[cn] as i32 + an[c0] as i32) + an[cn] as i32;
            let blue16 = 9 * b[c1] as i32 + 3 * (b[cp] as i32 + bp[c1] as i32) + bp[cp] as i32;
            let g2 = a[c1] as i32 + b[c0] as i32;
            f((red16 + 8) >> 4, g2, (blue16 + 8) >> 4)
        };
        o[0] = quad(0);
        if ow > 1 {
            o[ow - 1] = quad(ow - 1);
        }
        if ow > 2 {
            // Inner quads 1..ow-1, without clamping, pairwise over slices (so that the loop
            // vectorises): quad c reads columns 2c-1 ..= 2c+2.
            let n = ow - 2;
            let it = o[1..ow - 1]
                .iter_mut()
                .zip(a[2..2 * n + 2].chunks_exact(2))
                .zip(a[4..2 * n + 4].chunks_exact(2))
                .zip(an[2..2 * n + 2].chunks_exact(2))
                .zip(an[4..2 * n + 4].chunks_exact(2))
                .zip(b[1..2 * n + 1].chunks_exact(2))
                .zip(b[3..2 * n + 3].chunks_exact(2))
                .zip(bp[1..2 * n + 1].chunks_exact(2))
                .zip(bp[3..2 * n + 3].chunks_exact(2));
            for ((((((((v, a0), a1), an0), an1), b0), b1), bp0), bp1) in it {
                // a0: this quad's top (R, G), a1: the next quad's; b0: the previous quad's
                // bottom B and this quad's bottom G, b1: this quad's B; an*, bp*: the same
                // in the next and previous quad rows.
                let red16 = 9 * a0[0] as i32 + 3 * (a1[0] as i32 + an0[0] as i32) + an1[0] as i32;
                let blue16 = 9 * b1[0] as i32 + 3 * (b0[0] as i32 + bp1[0] as i32) + bp0[0] as i32;
                let g2 = a0[1] as i32 + b0[1] as i32;
                *v = f((red16 + 8) >> 4, g2, (blue16 + 8) >> 4);
            }
        }
    }
}

/// Brightness of input pixel (row, col) whatever the format (Bayer: mean of its quad).
/// Used to find the lens's image circle. Coordinates must be inside the image.
#[inline]
pub fn brightness_at(view: &ImageView, row: usize, col: usize) -> u8 {
    let w = view.width as usize;
    let d = view.data;
    match view.format {
        PixelFormat::Mono8 => d[row * w + col],
        PixelFormat::Rgb8 => {
            let i = 3 * (row * w + col);
            luma(d[i] as i32, 2 * d[i + 1] as i32, d[i + 2] as i32)
        }
        PixelFormat::BayerRggb8 => {
            let (r0, c0) = (row & !1, col & !1);
            let (r1, c1) = ((r0 + 1).min(view.height as usize - 1), (c0 + 1).min(w - 1));
            let s = d[r0 * w + c0] as u32
                + d[r0 * w + c1] as u32
                + d[r1 * w + c0] as u32
                + d[r1 * w + c1] as u32;
            ((s + 2) >> 2) as u8
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bands_on_threads_are_the_whole_image() {
        let pool = |n| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap()
        };
        let (w, h) = (90usize, 134usize);
        for format in [
            PixelFormat::Mono8,
            PixelFormat::Rgb8,
            PixelFormat::BayerRggb8,
        ] {
            let data = crate::detect::noise_bytes(7, w * h * format.bytes_per_pixel());
            let view = ImageView::new(w as u32, h as u32, format, &data).unwrap();
            for (index, bin2) in [
                (VegetationIndex::ExcessGreen, false),
                (VegetationIndex::ExcessGreen, true),
                (VegetationIndex::ChromaticExcessGreen, true),
                (VegetationIndex::Luma, false),
            ] {
                let opts = VegetationOptions { index };
                let mut want = GreyImage::default();
                let a = vegetation_image(&view, &opts, bin2, &mut want).unwrap();
                for n in [2, 3] {
                    let mut got = GreyImage::default();
                    let b =
                        vegetation_image_on(&view, &opts, bin2, &mut got, Some(&pool(n))).unwrap();
                    assert_eq!(
                        (a, &got.data),
                        (b, &want.data),
                        "{format:?} {index:?} {bin2}"
                    );
                }
            }
        }
    }

    #[test]
    fn rgb_excess_green() {
        // green plant, brown soil, blue sky, white
        let data = [40, 200, 30, 120, 80, 50, 60, 90, 220, 255, 255, 255];
        let view = ImageView::new(4, 1, PixelFormat::Rgb8, &data).unwrap();
        let mut out = GreyImage::default();
        let r = vegetation_image(&view, &VegetationOptions::default(), false, &mut out).unwrap();
        assert_eq!((r.factor, r.width, r.height), (1, 4, 1));
        assert_eq!(out.data, vec![165, 0, 0, 0]);
    }

    #[test]
    fn chromatic_indices_do_not_depend_on_brightness() {
        // A plant in the sun and the same plant at a third of the light; reddish soil.
        let data = [60, 180, 45, 20, 60, 15, 150, 110, 80];
        let view = ImageView::new(3, 1, PixelFormat::Rgb8, &data).unwrap();
        let mut out = GreyImage::default();
        for index in [
            VegetationIndex::ChromaticExcessGreen,
            VegetationIndex::ExcessGreenMinusRed,
        ] {
            vegetation_image(&view, &VegetationOptions { index }, false, &mut out).unwrap();
            let (sun, shade) = (out.data[0] as i32, out.data[1] as i32);
            assert!(
                sun > 60 && (sun - shade).abs() * 5 < sun,
                "{index:?}: {:?}",
                out.data
            );
            assert_eq!(out.data[2], 0, "{index:?}: soil");
        }
        // Plain excess green loses two thirds of the shaded plant.
        vegetation_image(&view, &VegetationOptions::default(), false, &mut out).unwrap();
        assert!(out.data[1] * 2 < out.data[0], "{:?}", out.data);
        // Black stays black.
        let black = [0u8, 0, 0];
        let view = ImageView::new(1, 1, PixelFormat::Rgb8, &black).unwrap();
        let index = VegetationIndex::ChromaticExcessGreen;
        vegetation_image(&view, &VegetationOptions { index }, false, &mut out).unwrap();
        assert_eq!(out.data, vec![0]);
    }

    #[test]
    fn grey_pictures_in_rgb_use_brightness() {
        let data = [90u8, 90, 90, 200, 200, 200];
        let view = ImageView::new(2, 1, PixelFormat::Rgb8, &data).unwrap();
        let mut out = GreyImage::default();
        vegetation_image(&view, &VegetationOptions::default(), false, &mut out).unwrap();
        assert_eq!(out.data, vec![90, 200]);
        let opts = VegetationOptions {
            index: VegetationIndex::ExcessGreen,
        };
        vegetation_image(&view, &opts, false, &mut out).unwrap();
        assert_eq!(out.data, vec![0, 0]);
    }

    #[test]
    fn bayer_quads_give_half_resolution_exg() {
        // 4x2 Bayer: quad 0 green plant (R 40, G 200/190, B 30), quad 1 soil. Red and blue
        // are interpolated to each quad's centre: quad 0's red is (9·40 + 3·120 + 3·40 +
        // 120) / 16 = 60, so its ExG is (390 − 60 − 30) / 2 = 150; quad 1's blue is 45.
        #[rustfmt::skip]
        let data = [
            40, 200, 120, 80,
            190, 30, 80, 50,
        ];
        let view = ImageView::new(4, 2, PixelFormat::BayerRggb8, &data).unwrap();
        let mut out = GreyImage::default();
        let r = vegetation_image(&view, &VegetationOptions::default(), false, &mut out).unwrap();
        assert_eq!((r.factor, r.width, r.height), (2, 2, 1));
        assert_eq!(out.data, vec![150, 0]);
        let odd = [0u8; 6];
        let view = ImageView::new(3, 2, PixelFormat::BayerRggb8, &odd).unwrap();
        let e = vegetation_image(&view, &VegetationOptions::default(), false, &mut out)
            .unwrap_err()
            .to_string();
        assert!(e.contains("even"), "{e}");
    }

    #[test]
    fn bayer_red_and_blue_are_centred_on_the_quad() {
        // Reference: bilinear red and blue at each quad's centre, clamped at the borders.
        let (w, h) = (12usize, 6usize);
        let data: Vec<u8> = (0..w * h).map(|i| ((i * 37 + 11) % 251) as u8).collect();
        let view = ImageView::new(w as u32, h as u32, PixelFormat::BayerRggb8, &data).unwrap();
        let mut out = GreyImage::default();
        vegetation_image(&view, &VegetationOptions::default(), false, &mut out).unwrap();
        let (ow, oh) = (w / 2, h / 2);
        let px = |r: usize, c: usize| data[r * w + c] as i32;
        for r in 0..oh {
            for c in 0..ow {
                let (rn, cn) = ((r + 1).min(oh - 1), (c + 1).min(ow - 1));
                let (rp, cp) = (r.saturating_sub(1), c.saturating_sub(1));
                let red = 9 * px(2 * r, 2 * c)
                    + 3 * (px(2 * r, 2 * cn) + px(2 * rn, 2 * c))
                    + px(2 * rn, 2 * cn);
                let blue = 9 * px(2 * r + 1, 2 * c + 1)
                    + 3 * (px(2 * r + 1, 2 * cp + 1) + px(2 * rp + 1, 2 * c + 1))
                    + px(2 * rp + 1, 2 * cp + 1);
                let g2 = px(2 * r, 2 * c + 1) + px(2 * r + 1, 2 * c);
                let want = exg((red + 8) >> 4, g2, (blue + 8) >> 4);
                assert_eq!(out.data[r * ow + c], want, "quad ({r}, {c})");
            }
        }
    }

    #[test]
    fn mono_binning_and_rgb_binning_agree_with_means() {
        let data = [10u8, 20, 30, 40, 50, 60, 70, 80];
        let view = ImageView::new(4, 2, PixelFormat::Mono8, &data).unwrap();
        let mut out = GreyImage::default();
        vegetation_image(&view, &VegetationOptions::default(), true, &mut out).unwrap();
        assert_eq!(
            out.data,
            vec![(10 + 20 + 50 + 60) / 4, (30 + 40 + 70 + 80) / 4]
        );
        vegetation_image(&view, &VegetationOptions::default(), false, &mut out).unwrap();
        assert_eq!(out.data, data.to_vec());
        // RGB 2x2 of one plant colour bins to that colour's index.
        let px = [40u8, 200, 30];
        let rgb: Vec<u8> = px.iter().copied().cycle().take(12).collect();
        let view = ImageView::new(2, 2, PixelFormat::Rgb8, &rgb).unwrap();
        vegetation_image(&view, &VegetationOptions::default(), true, &mut out).unwrap();
        assert_eq!(out.data, vec![165]);
    }

    #[test]
    fn mono_binning_is_the_rounded_mean_of_each_quad() {
        // a width that is not a multiple of any run or lane count
        let (w, h) = (614, 42);
        let data = crate::detect::noise_bytes(0x2545_f491_4f6c_dd1d, w * h);
        let view = ImageView::new(w as u32, h as u32, PixelFormat::Mono8, &data).unwrap();
        let mut out = GreyImage::default();
        vegetation_image(&view, &VegetationOptions::default(), true, &mut out).unwrap();
        let (ow, oh) = (w / 2, h / 2);
        assert_eq!((out.width, out.height), (ow, oh));
        for r in 0..oh {
            for c in 0..ow {
                let at = |y: usize, x: usize| data[y * w + x] as u32;
                let q = at(2 * r, 2 * c)
                    + at(2 * r, 2 * c + 1)
                    + at(2 * r + 1, 2 * c)
                    + at(2 * r + 1, 2 * c + 1);
                assert_eq!(out.data[r * ow + c] as u32, (q + 2) >> 2, "({r}, {c})");
            }
        }
    }

    #[test]
    fn brightness_of_each_format() {
        let rgb = [10u8, 20, 30];
        let v = ImageView::new(1, 1, PixelFormat::Rgb8, &rgb).unwrap();
        assert_eq!(brightness_at(&v, 0, 0), 20);
        let bay = [10u8, 20, 30, 40];
        let v = ImageView::new(2, 2, PixelFormat::BayerRggb8, &bay).unwrap();
        assert_eq!(brightness_at(&v, 1, 1), 25);
    }
}
