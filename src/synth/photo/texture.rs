//! The rectified photograph as a ground texture: a rectangle of the ground in texels, tiled
//! over the whole plane by mirroring, with a mip pyramid so that distant ground is averaged
//! rather than aliased.
//!
//! Owns [`MirrorTexture`]: built once from a colour function over its rectangle, sampled in
//! metres with a footprint (trilinear between the two pyramid levels nearest the footprint).
//! Mirroring at every edge keeps the texture continuous at the seams, and keeps rows at
//! k·spacing when the rectangle's sides across the rows lie on rows or midway between them.

/// A ground rectangle of texels, mirrored over the plane.
#[derive(Debug, Clone, PartialEq)]
pub struct MirrorTexture {
    /// The rectangle's corner (x0, y0) and sides (metres): texel (i, j) of level 0 covers
    /// x0 + [i, i + 1)·texel, y0 + [j, j + 1)·texel.
    origin: [f64; 2],
    extent: [f64; 2],
    texel_m: f64,
    /// Level l: (columns along x, rows along y, RGB texels row-major by y).
    levels: Vec<(usize, usize, Vec<[u8; 3]>)>,
}

impl MirrorTexture {
    /// Builds the texture over `cols` × `rows` texels of `texel_m` from `(x0, y0)`, each texel
    /// the colour `colour(x, y)` gives at its centre.
    pub fn new(
        origin: [f64; 2],
        cols: usize,
        rows: usize,
        texel_m: f64,
        mut colour: impl FnMut(f64, f64) -> [u8; 3],
    ) -> Self {
        let (cols, rows) = (cols.max(1), rows.max(1));
        let mut base = Vec::with_capacity(cols * rows);
        for j in 0..rows {
            let y = origin[1] + (j as f64 + 0.5) * texel_m;
            for i in 0..cols {
                base.push(colour(origin[0] + (i as f64 + 0.5) * texel_m, y));
            }
        }
        let mut levels = vec![(cols, rows, base)];
        while let Some((w, h, prev)) = levels.last().filter(|l| l.0 > 1 || l.1 > 1) {
            let (nw, nh) = (w.div_ceil(2), h.div_ceil(2));
            let mut next = Vec::with_capacity(nw * nh);
            for j in 0..nh {
                for i in 0..nw {
                    let mut acc = [0u32; 3];
                    for (dj, di) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                        let (a, b) = ((2 * i + di).min(w - 1), (2 * j + dj).min(h - 1));
                        let t = prev[b * w + a];
                        for k in 0..3 {
                            acc[k] += t[k] as u32;
                        }
                    }
                    next.push(acc.map(|v| ((v + 2) / 4) as u8));
                }
            }
            levels.push((nw, nh, next));
        }
        MirrorTexture {
            origin,
            extent: [cols as f64 * texel_m, rows as f64 * texel_m],
            texel_m,
            levels,
        }
    }

    /// Texels of the finest level (columns along x, rows along y).
    pub fn size(&self) -> (usize, usize) {
        (self.levels[0].0, self.levels[0].1)
    }

    /// The finest level's texel size, metres.
    pub fn texel_m(&self) -> f64 {
        self.texel_m
    }

    /// The rectangle's corner and sides, metres.
    pub fn rectangle(&self) -> ([f64; 2], [f64; 2]) {
        (self.origin, self.extent)
    }

    /// Colour (linear 0..255) at ground point (x, y), averaged over about `size` metres.
    #[inline]
    pub fn sample(&self, x: f64, y: f64, size: f64) -> [f32; 3] {
        let u = mirror(x - self.origin[0], self.extent[0]);
        let v = mirror(y - self.origin[1], self.extent[1]);
        let last = self.levels.len() - 1;
        let lod = (size / self.texel_m).max(1.0).log2().min(last as f64);
        let l0 = lod as usize;
        let t = (lod - l0 as f64) as f32;
        let a = self.bilinear(l0, u, v);
        if t <= 0.0 || l0 == last {
            return a;
        }
        let b = self.bilinear(l0 + 1, u, v);
        [
            a[0] + (b[0] - a[0]) * t,
            a[1] + (b[1] - a[1]) * t,
            a[2] + (b[2] - a[2]) * t,
        ]
    }

    /// Bilinear sample of level `l` at (u, v) metres inside the rectangle.
    #[inline]
    fn bilinear(&self, l: usize, u: f64, v: f64) -> [f32; 3] {
        let (w, h, ref t) = self.levels[l];
        let size = self.texel_m * (1u64 << l) as f64;
        let (fu, fv) = (u / size - 0.5, v / size - 0.5);
        let (iu, iv) = (fu.floor(), fv.floor());
        let (tu, tv) = ((fu - iu) as f32, (fv - iv) as f32);
        let clamp = |i: f64, n: usize| (i.max(0.0) as usize).min(n - 1);
        let (u0, u1) = (clamp(iu, w), clamp(iu + 1.0, w));
        let (v0, v1) = (clamp(iv, h), clamp(iv + 1.0, h));
        let (p00, p01, p10, p11) = (
            t[v0 * w + u0],
            t[v0 * w + u1],
            t[v1 * w + u0],
            t[v1 * w + u1],
        );
        let mut out = [0.0f32; 3];
        for k in 0..3 {
            let top = p00[k] as f32 * (1.0 - tu) + p01[k] as f32 * tu;
            let bot = p10[k] as f32 * (1.0 - tu) + p11[k] as f32 * tu;
            out[k] = top * (1.0 - tv) + bot * tv;
        }
        out
    }
}

/// `t` folded into [0, len] by mirroring at 0 and len (period 2·len).
#[inline]
fn mirror(t: f64, len: f64) -> f64 {
    let m = t.rem_euclid(2.0 * len);
    if m > len {
        2.0 * len - m
    } else {
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stripes() -> MirrorTexture {
        // 1 m × 0.5 m at 1 cm: red rises along x, green is a stripe across y = 0.1 .. 0.2.
        MirrorTexture::new([2.0, -0.25], 100, 50, 0.01, |x, y| {
            let g = if (-0.15..-0.05).contains(&y) { 200 } else { 0 };
            [((x - 2.0) * 250.0) as u8, g, 10]
        })
    }

    #[test]
    fn mirrored_tiling_is_continuous_and_keeps_the_stripes() {
        let t = stripes();
        assert_eq!(t.size(), (100, 50));
        assert_eq!(t.levels.len(), 8);
        // Inside: the colour function at texel centres.
        let c = t.sample(2.505, -0.095, 0.0);
        assert!((c[0] - 126.0).abs() < 1.5 && c[1] == 200.0, "{c:?}");
        // Mirrored along x at 3 m: the same on both sides of the seam.
        let (a, b) = (t.sample(2.99, 0.0, 0.0), t.sample(3.01, 0.0, 0.0));
        assert!((a[0] - b[0]).abs() < 0.5, "{a:?} {b:?}");
        // Period 2 m along x and 1 m across.
        for (x, y) in [(2.3, -0.1), (2.71, 0.04)] {
            let p = t.sample(x, y, 0.0);
            let close = |q: [f32; 3]| (0..3).all(|k| (p[k] - q[k]).abs() < 1e-3);
            assert!(close(t.sample(x + 2.0, y, 0.0)));
            assert!(close(t.sample(x - 4.0, y + 1.0, 0.0)));
            // mirrored across the side at y = 0.25: the stripe reappears at 0.55 .. 0.65
            assert!(close(t.sample(x, 0.5 - y, 0.0)));
        }
        assert_eq!(t.sample(2.5, 0.6, 0.0)[1], 200.0);
    }

    #[test]
    fn large_footprints_average() {
        let t = stripes();
        // A footprint as large as the whole texture: about the mean green (a fifth of it is 200;
        // odd level sizes repeat their last texel).
        let c = t.sample(2.5, 0.0, 2.0);
        assert!((c[1] - 40.0).abs() < 10.0, "{c:?}");
        // A footprint of one texel: the texel itself.
        assert_eq!(t.sample(2.505, -0.095, 0.01)[1], 200.0);
    }
}
