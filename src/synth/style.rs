//! How the field looks: the colours of soil, plants and sky, and the soil's texture.
//!
//! Owns [`Palette`] (the grey style's flat levels — bright plants on a dark background, as in
//! the paper — and the colour style's green leaves, brown textured soil, and blue sky
//! graded from the horizon to the zenith) and [`Texture`], a seeded, tileable value-noise
//! table sampled bilinearly at two scales so that the soil is not flat.

use super::field::floor_i;
use super::rng::Rng;

/// Texels per side of the texture table (a power of two).
const TEX_N: usize = 256;

/// Soil texture: value noise in a tileable table, sampled at two scales.
#[derive(Debug, Clone, PartialEq)]
pub struct Texture {
    table: Vec<f32>,
}

impl Texture {
    /// The texture for a seed: smoothed white noise, values roughly in [-1, 1].
    pub fn new(seed: u64) -> Self {
        let mut rng = Rng::stream(seed, 3);
        let raw: Vec<f32> = (0..TEX_N * TEX_N)
            .map(|_| rng.range(-1.0, 1.0) as f32)
            .collect();
        // One 3x3 box pass (wrapping) softens the noise into clods.
        let mut table = vec![0.0f32; TEX_N * TEX_N];
        for y in 0..TEX_N {
            for x in 0..TEX_N {
                let mut s = 0.0;
                for dy in [TEX_N - 1, 0, 1] {
                    for dx in [TEX_N - 1, 0, 1] {
                        s += raw[((y + dy) % TEX_N) * TEX_N + (x + dx) % TEX_N];
                    }
                }
                table[y * TEX_N + x] = s / 3.0;
            }
        }
        Texture { table }
    }

    /// Bilinear sample at texel coordinates (u, v), wrapping.
    #[inline]
    fn bilinear(&self, u: f64, v: f64) -> f32 {
        let (fu, fv) = (floor_i(u), floor_i(v));
        let (tu, tv) = ((u - fu as f64) as f32, (v - fv as f64) as f32);
        let mask = TEX_N as i64 - 1;
        let (iu, iv) = (fu & mask, fv & mask);
        let (iu1, iv1) = ((iu + 1) & mask, (iv + 1) & mask);
        let t = &self.table;
        let at = |a: i64, b: i64| t[(b as usize) * TEX_N + a as usize];
        let top = at(iu, iv) * (1.0 - tu) + at(iu1, iv) * tu;
        let bot = at(iu, iv1) * (1.0 - tu) + at(iu1, iv1) * tu;
        top * (1.0 - tv) + bot * tv
    }

    /// Texture value at ground point (x, y) metres: clods of ~4 cm and grains of ~1 cm.
    #[inline]
    pub fn at(&self, x: f64, y: f64) -> f32 {
        self.filtered(x, y, 0.0)
    }

    /// Texture value averaged over a footprint of `size` metres: each scale fades out as
    /// the footprint outgrows it (so that distant soil does not alias into speckle).
    #[inline]
    pub fn filtered(&self, x: f64, y: f64, size: f64) -> f32 {
        let fade = |scale: f64| (1.0 - size / scale).clamp(0.0, 1.0) as f32;
        let (a, b) = (0.65 * fade(0.08), 0.35 * fade(0.022));
        let mut v = 0.0;
        if a > 0.0 {
            v += a * self.bilinear(x * 25.0, y * 25.0);
        }
        if b > 0.0 {
            v += b * self.bilinear(y * 90.0 + 37.0, x * 90.0);
        }
        v
    }
}

/// The colours of the scene, linear 0..255 per channel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Palette {
    /// Grey style: background (soil, and sky, which the paper's images do not show).
    pub grey_soil: f32,
    /// Grey style: plants.
    pub grey_plant: f32,
    /// Colour style: soil base colour and the relative strength of its texture.
    pub soil: [f32; 3],
    pub soil_texture: f32,
    /// Colour style: leaf colour at the leaf's centre; edges are darker by `leaf_edge_dark`.
    pub leaf: [f32; 3],
    pub leaf_edge_dark: f32,
    /// Colour style: sky at the horizon and at the zenith.
    pub sky_horizon: [f32; 3],
    pub sky_zenith: [f32; 3],
}

impl Default for Palette {
    fn default() -> Self {
        Palette {
            grey_soil: 35.0,
            grey_plant: 215.0,
            soil: [118.0, 86.0, 60.0],
            soil_texture: 0.28,
            leaf: [78.0, 168.0, 52.0],
            leaf_edge_dark: 0.3,
            sky_horizon: [205.0, 218.0, 235.0],
            sky_zenith: [88.0, 138.0, 215.0],
        }
    }
}

impl Palette {
    /// Soil colour with texture value `t` (about -1..1).
    #[inline]
    pub fn soil_rgb(&self, t: f32) -> [f32; 3] {
        let f = 1.0 + self.soil_texture * t;
        [self.soil[0] * f, self.soil[1] * f, self.soil[2] * f]
    }

    /// Leaf colour at elliptic radius `edge` (0 centre, 1 edge).
    #[inline]
    pub fn leaf_rgb(&self, edge: f32) -> [f32; 3] {
        let f = 1.0 - self.leaf_edge_dark * edge * edge;
        [self.leaf[0] * f, self.leaf[1] * f, self.leaf[2] * f]
    }

    /// Sky colour at elevation sine `s` (0 horizon, 1 zenith).
    #[inline]
    pub fn sky_rgb(&self, s: f32) -> [f32; 3] {
        let t = s.clamp(0.0, 1.0).sqrt();
        let (h, z) = (self.sky_horizon, self.sky_zenith);
        [
            h[0] + (z[0] - h[0]) * t,
            h[1] + (z[1] - h[1]) * t,
            h[2] + (z[2] - h[2]) * t,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texture_is_deterministic_bounded_and_varied() {
        let a = Texture::new(5);
        assert_eq!(a, Texture::new(5));
        assert_ne!(a, Texture::new(6));
        let mut lo = f32::MAX;
        let mut hi = f32::MIN;
        for i in 0..1000 {
            let v = a.at(i as f64 * 0.013, i as f64 * -0.007 + 3.0);
            assert!(v.abs() <= 3.0);
            lo = lo.min(v);
            hi = hi.max(v);
        }
        assert!(hi - lo > 0.5);
        // wraps without a seam: continuous across the tile border
        let tile = TEX_N as f64 / 25.0;
        let d = (a.bilinear(TEX_N as f64 - 1e-9, 3.0) - a.bilinear(0.0, 3.0)).abs();
        assert!(d < 1e-4, "{d} {tile}");
    }
}
