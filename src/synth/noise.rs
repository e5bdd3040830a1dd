//! The paper's background noise: salt and pepper of a given density, then Gaussian smoothing.
//!
//! Owns [`salt_and_pepper`] (each pixel, with probability `density`, becomes black or white,
//! all channels alike, drawn from the seed) and [`Blur`] (separable Gaussian smoothing in
//! 16.16 fixed point, clamped at the borders, on up to `threads` threads, with its scratch
//! buffers kept from image to image).

use super::rng::Rng;
use std::sync::Mutex;

/// Replaces each pixel, with probability `density`, by black or white (equally likely).
pub fn salt_and_pepper(img: &mut [u8], channels: usize, density: f64, seed: u64) {
    if density <= 0.0 {
        return;
    }
    let mut rng = Rng::stream(seed, 4);
    // Compare 32-bit draws against a threshold; the next bit picks salt or pepper.
    let threshold = (density.clamp(0.0, 1.0) * 4_294_967_296.0) as u64;
    for px in img.chunks_exact_mut(channels) {
        let r = rng.next_u64();
        if (r >> 32) < threshold {
            px.fill(if r & 1 == 1 { 255 } else { 0 });
        }
    }
}

/// Normalised Gaussian kernel of standard deviation `sigma` (radius ⌈3σ⌉), 16.16 fixed point.
fn kernel(sigma: f64) -> Vec<u32> {
    let radius = (3.0 * sigma).ceil().max(0.0) as usize;
    let w: Vec<f64> = (0..=2 * radius)
        .map(|i| {
            let x = i as f64 - radius as f64;
            (-x * x / (2.0 * sigma * sigma)).exp()
        })
        .collect();
    let sum: f64 = w.iter().sum();
    let mut k: Vec<u32> = w
        .iter()
        .map(|v| (v / sum * 65536.0).round() as u32)
        .collect();
    // Make the weights sum to exactly 1.0 so that flat areas stay flat.
    let total: u32 = k.iter().sum();
    k[radius] = (k[radius] as i64 + 65536 - total as i64) as u32;
    k
}

/// Separable Gaussian smoothing with its scratch buffers, reused from image to image.
#[derive(Debug, Clone, Default)]
pub struct Blur {
    sigma: f64,
    kernel: Vec<u32>,
    /// The image after the horizontal pass.
    tmp: Vec<u8>,
    /// Per thread: a row padded at both ends (clamped), and an accumulator row.
    rows: Vec<(Vec<u8>, Vec<u32>)>,
}

impl Blur {
    pub fn new() -> Self {
        Self::default()
    }

    /// Smooths `img` (width×height×channels) in place with a Gaussian of `sigma` pixels
    /// (clamped at the borders) on up to `threads` threads. Does nothing for sigma ≤ 0.
    pub fn apply(
        &mut self,
        img: &mut [u8],
        width: usize,
        height: usize,
        channels: usize,
        sigma: f64,
        threads: usize,
    ) {
        if sigma <= 0.0 || width == 0 || height == 0 {
            return;
        }
        debug_assert_eq!(img.len(), width * height * channels);
        if sigma != self.sigma || self.kernel.is_empty() {
            self.kernel = kernel(sigma);
            self.sigma = sigma;
        }
        let k = &self.kernel;
        let radius = k.len() / 2;
        let row_bytes = width * channels;
        let pad = radius * channels;
        self.tmp.resize(img.len(), 0);
        self.rows.resize_with(threads.max(1), Default::default);
        for (padded, acc) in &mut self.rows {
            padded.resize(row_bytes + 2 * pad, 0);
            acc.resize(row_bytes, 0);
        }
        // Horizontal pass: img -> tmp.
        {
            let src: &[u8] = img;
            let bands = Mutex::new(self.tmp.chunks_mut(row_bytes).enumerate());
            let work = |(padded, acc): &mut (Vec<u8>, Vec<u32>)| loop {
                let next = bands.lock().map(|mut it| it.next()).unwrap_or(None);
                let Some((r, out)) = next else { break };
                let row = &src[r * row_bytes..(r + 1) * row_bytes];
                padded[pad..pad + row_bytes].copy_from_slice(row);
                for i in 0..radius {
                    let (l, rr) = (i * channels, pad + row_bytes + i * channels);
                    padded.copy_within(pad..pad + channels, l);
                    padded.copy_within(pad + row_bytes - channels..pad + row_bytes, rr);
                }
                acc.fill(32768);
                for (i, &kv) in k.iter().enumerate() {
                    let src = &padded[i * channels..i * channels + row_bytes];
                    for (a, &v) in acc.iter_mut().zip(src) {
                        *a += kv * v as u32;
                    }
                }
                for (o, &a) in out.iter_mut().zip(acc.iter()) {
                    *o = (a >> 16) as u8;
                }
            };
            run_each(&mut self.rows, &work);
        }
        // Vertical pass: tmp -> img.
        {
            let src: &[u8] = &self.tmp;
            let bands = Mutex::new(img.chunks_mut(row_bytes).enumerate());
            let work = |(_, acc): &mut (Vec<u8>, Vec<u32>)| loop {
                let next = bands.lock().map(|mut it| it.next()).unwrap_or(None);
                let Some((r, out)) = next else { break };
                acc.fill(32768);
                for (i, &kv) in k.iter().enumerate() {
                    let rr = (r + i).saturating_sub(radius).min(height - 1);
                    let row = &src[rr * row_bytes..(rr + 1) * row_bytes];
                    for (a, &v) in acc.iter_mut().zip(row) {
                        *a += kv * v as u32;
                    }
                }
                for (o, &a) in out.iter_mut().zip(acc.iter()) {
                    *o = (a >> 16) as u8;
                }
            };
            run_each(&mut self.rows, &work);
        }
    }
}

/// Runs `work` once per scratch item, each on its own thread (the first on this one).
pub(crate) fn run_each<T: Send>(items: &mut [T], work: &(dyn Fn(&mut T) + Sync)) {
    match items {
        [] => {}
        [only] => work(only),
        [first, rest @ ..] => std::thread::scope(|s| {
            for item in rest {
                s.spawn(move || work(item));
            }
            work(first);
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn density_is_as_asked() {
        for density in [0.1, 0.5] {
            let mut img = vec![128u8; 200_000];
            salt_and_pepper(&mut img, 1, density, 11);
            let changed = img.iter().filter(|&&v| v != 128).count() as f64 / img.len() as f64;
            assert!((changed - density).abs() < 0.01, "{changed} vs {density}");
            let white = img.iter().filter(|&&v| v == 255).count() as f64 / img.len() as f64;
            assert!((white - density / 2.0).abs() < 0.01);
        }
    }

    #[test]
    fn blur_keeps_flat_areas_and_spreads_a_dot() {
        let (w, h) = (21, 21);
        let mut blur = Blur::new();
        let mut img = vec![100u8; w * h];
        blur.apply(&mut img, w, h, 1, 1.5, 2);
        assert!(img.iter().all(|&v| v == 100));
        let mut img = vec![0u8; w * h * 3];
        img[(10 * w + 10) * 3 + 1] = 255;
        blur.apply(&mut img, w, h, 3, 1.0, 2);
        let g = |r: usize, c: usize| img[(r * w + c) * 3 + 1];
        assert!(g(10, 10) > g(10, 11) && g(10, 11) > g(10, 12));
        assert_eq!(g(9, 10), g(10, 9));
        assert_eq!(img[(10 * w + 10) * 3], 0, "channels stay separate");
        // borders are clamped: a dot in the corner keeps most of its mass nearby
        let mut img = vec![0u8; w * h];
        img[0] = 255;
        blur.apply(&mut img, w, h, 1, 1.0, 1);
        assert!(
            img[0] > 70 && img[1] > 30 && img[w].abs_diff(img[1]) <= 1,
            "{:?}",
            (&img[..3], img[w], img[2 * w])
        );
    }

    #[test]
    fn blur_matches_a_direct_convolution() {
        let (w, h) = (37, 23);
        let mut rng = Rng::new(2);
        let orig: Vec<u8> = (0..w * h).map(|_| rng.below(256) as u8).collect();
        let mut img = orig.clone();
        Blur::new().apply(&mut img, w, h, 1, 1.3, 2);
        let sigma: f64 = 1.3;
        let rad = 4isize;
        let g = |d: isize| (-(d * d) as f64 / (2.0 * sigma * sigma)).exp();
        let norm: f64 = (-rad..=rad).map(g).sum::<f64>();
        for r in 0..h as isize {
            for c in 0..w as isize {
                let mut acc = 0.0;
                for dr in -rad..=rad {
                    for dc in -rad..=rad {
                        let rr = (r + dr).clamp(0, h as isize - 1) as usize;
                        let cc = (c + dc).clamp(0, w as isize - 1) as usize;
                        acc += g(dr) * g(dc) * orig[rr * w + cc] as f64;
                    }
                }
                let want = acc / (norm * norm);
                let got = img[r as usize * w + c as usize] as f64;
                assert!((got - want).abs() <= 1.01, "({r},{c}) {got} vs {want}");
            }
        }
    }
}
