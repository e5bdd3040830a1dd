//! The paper's background noise: salt and pepper of a given density, then Gaussian smoothing.
//!
//! Owns [`salt_and_pepper`] (each pixel, with probability `density`, becomes black or white,
//! all channels alike, drawn from the seed) and [`gaussian_blur`] (separable, clamped at the
//! borders, on up to `threads` threads, into a caller-owned scratch buffer).

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

/// Smooths `img` (width×height×channels) in place with a Gaussian of `sigma` pixels, using
/// `tmp` (same length) as scratch. Does nothing for sigma ≤ 0.
pub fn gaussian_blur(
    img: &mut [u8],
    tmp: &mut [u8],
    width: usize,
    height: usize,
    channels: usize,
    sigma: f64,
    threads: usize,
) {
    if sigma <= 0.0 || width == 0 || height == 0 {
        return;
    }
    let k = kernel(sigma);
    let radius = (k.len() / 2) as isize;
    let row_bytes = width * channels;
    // Horizontal pass: img -> tmp.
    {
        let src: &[u8] = img;
        let bands = Mutex::new(tmp.chunks_mut(row_bytes).enumerate());
        let work = || loop {
            let next = bands.lock().map(|mut it| it.next()).unwrap_or(None);
            let Some((r, out)) = next else { break };
            let row = &src[r * row_bytes..(r + 1) * row_bytes];
            for c in 0..width {
                for ch in 0..channels {
                    let mut acc = 0u32;
                    for (i, &kv) in k.iter().enumerate() {
                        let cc = (c as isize + i as isize - radius).clamp(0, width as isize - 1)
                            as usize;
                        acc += kv * row[cc * channels + ch] as u32;
                    }
                    out[c * channels + ch] = ((acc + 32768) >> 16) as u8;
                }
            }
        };
        run(threads, &work);
    }
    // Vertical pass: tmp -> img.
    {
        let src: &[u8] = tmp;
        let bands = Mutex::new(img.chunks_mut(row_bytes).enumerate());
        let work = || loop {
            let next = bands.lock().map(|mut it| it.next()).unwrap_or(None);
            let Some((r, out)) = next else { break };
            for (x, o) in out.iter_mut().enumerate() {
                let mut acc = 0u32;
                for (i, &kv) in k.iter().enumerate() {
                    let rr =
                        (r as isize + i as isize - radius).clamp(0, height as isize - 1) as usize;
                    acc += kv * src[rr * row_bytes + x] as u32;
                }
                *o = ((acc + 32768) >> 16) as u8;
            }
        };
        run(threads, &work);
    }
}

fn run(threads: usize, work: &(dyn Fn() + Sync)) {
    if threads <= 1 {
        work();
    } else {
        std::thread::scope(|s| {
            for _ in 1..threads {
                s.spawn(work);
            }
            work();
        });
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
        let mut img = vec![100u8; w * h];
        let mut tmp = vec![0u8; w * h];
        gaussian_blur(&mut img, &mut tmp, w, h, 1, 1.5, 2);
        assert!(img.iter().all(|&v| v == 100));
        let mut img = vec![0u8; w * h * 3];
        img[(10 * w + 10) * 3 + 1] = 255;
        let mut tmp = vec![0u8; w * h * 3];
        gaussian_blur(&mut img, &mut tmp, w, h, 3, 1.0, 2);
        let g = |r: usize, c: usize| img[(r * w + c) * 3 + 1];
        assert!(g(10, 10) > g(10, 11) && g(10, 11) > g(10, 12));
        assert_eq!(g(9, 10), g(10, 9));
        assert_eq!(img[(10 * w + 10) * 3], 0, "channels stay separate");
    }
}
