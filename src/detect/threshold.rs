//! Adaptive threshold that keeps about N points (paper II-D: "the threshold is tuned to allow
//! a certain number of points to be selected", so that the Hough transform's cost is bounded
//! whatever the image).
//!
//! Owns the choice of the level from a histogram of the masked pixels and the collection of
//! the kept pixels into a caller-owned list. Pixels above the level are all kept; pixels
//! exactly at the level are thinned evenly so that the total stays near N even when many
//! pixels share one value (a saturated image).

use super::types::DetectError;
use rayon::ThreadPool;
use serde::{Deserialize, Serialize};

/// Options of the adaptive threshold.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ThresholdOptions {
    /// About how many points to keep. When absent: [`DEFAULT_TARGET_POINTS`], or, for the
    /// strips method, [`super::strips::KEPT_SHARE`] of the working image's pixels (resolved
    /// with the calibration, `omnirow config detector` shows the value in force).
    pub target_points: Option<usize>,
    /// Pixels at or below this value are never kept (background). When absent:
    /// [`DEFAULT_MIN_LEVEL`], or, for the strips method, [`super::strips::KEPT_MIN_LEVEL`]
    /// (resolved with the calibration, as `target_points` is).
    pub min_level: Option<u8>,
}

/// The points kept when `target_points` is absent (and the method is not the strips).
pub const DEFAULT_TARGET_POINTS: usize = 15_000;

/// The floor in force when `min_level` is absent (and the method is not the strips).
pub const DEFAULT_MIN_LEVEL: u8 = 10;

/// The most points a configuration may ask for (more than a 5-megapixel sensor has: a
/// hostile value cannot make the buffers sized for it exhaust the memory).
pub const MAX_TARGET_POINTS: usize = 50_000_000;

impl ThresholdOptions {
    /// The target in force.
    pub fn target_points(&self) -> usize {
        self.target_points.unwrap_or(DEFAULT_TARGET_POINTS)
    }

    /// The floor in force.
    pub fn min_level(&self) -> u8 {
        self.min_level.unwrap_or(DEFAULT_MIN_LEVEL)
    }

    pub fn validate(&self) -> Result<(), DetectError> {
        let n = self.target_points();
        if !(1..=MAX_TARGET_POINTS).contains(&n) {
            return Err(DetectError::Options(format!(
                "threshold.target_points = {n} must be within 1..={MAX_TARGET_POINTS}"
            )));
        }
        Ok(())
    }
}

/// The threshold's outcome.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ThresholdResult {
    /// Pixels with a value above `level` were kept, and every `stride`-th pixel at `level`.
    pub level: u8,
    pub stride: u32,
    /// Number of pixels kept.
    pub kept: usize,
    /// Number of valid (unmasked) pixels above `min_level`.
    pub candidates: usize,
    /// Median value of the valid pixels (the background, in a field image).
    pub median: u8,
}

/// Chooses the level from the histogram of `image` over pixels whose `mask` byte is non-zero,
/// then writes the indices of the kept pixels into `out` (cleared first; allocates only if its
/// capacity is below N). Keeps between N/2 and N pixels when there are at least N candidates.
pub fn keep_brightest(
    image: &[u8],
    mask: &[u8],
    opts: &ThresholdOptions,
    out: &mut Vec<u32>,
) -> Result<ThresholdResult, DetectError> {
    keep_brightest_on(image, mask, opts, out, None)
}

/// [`keep_brightest`] with the image's two halves counted and scanned at once on `pool`'s
/// threads when there is one (`spare` holds the second half's kept pixels before they join
/// `out`): the same pixels in the same order.
pub fn keep_brightest_on(
    image: &[u8],
    mask: &[u8],
    opts: &ThresholdOptions,
    out: &mut Vec<u32>,
    pool: Option<(&ThreadPool, &mut Vec<u32>)>,
) -> Result<ThresholdResult, DetectError> {
    same_size(image, mask)?;
    opts.validate()?;
    if image.len() > u32::MAX as usize {
        return Err(DetectError::Buffer("threshold: image too large".into()));
    }
    // the halves split at a block's start, so that each scans the blocks the whole would
    let mid = (image.len() / 2) / BLOCK * BLOCK;
    let halves = pool.filter(|_| mid > 0);
    let counts = match &halves {
        Some((pool, _)) => {
            let ((h1, v1), (h2, v2)) = pool.join(
                || {
                    (
                        histogram(&image[..mid], &mask[..mid]),
                        valid_pixels(&mask[..mid]),
                    )
                },
                || {
                    (
                        histogram(&image[mid..], &mask[mid..]),
                        valid_pixels(&mask[mid..]),
                    )
                },
            );
            Counts {
                hist: std::array::from_fn(|i| h1[i] + h2[i]),
                valid: v1 + v2,
                first: Some((mid, h1)),
            }
        }
        None => Counts {
            hist: histogram(image, mask),
            valid: valid_pixels(mask),
            first: None,
        },
    };
    keep_counted(image, mask, opts, &counts, out, halves)
}

/// The image and its mask have one byte per pixel each.
fn same_size(image: &[u8], mask: &[u8]) -> Result<(), DetectError> {
    if image.len() != mask.len() {
        return Err(DetectError::Buffer(format!(
            "threshold: image has {} pixels, mask {}",
            image.len(),
            mask.len()
        )));
    }
    Ok(())
}

/// What [`keep_counted`] chooses the level from: the image's histogram as [`histogram`]
/// counts it, its number of valid pixels ([`valid_pixels`]), and, to scan it in two parts,
/// where the second starts and the first's histogram.
#[derive(Debug, Clone)]
pub struct Counts {
    pub hist: [u32; 256],
    pub valid: u64,
    pub first: Option<(usize, [u32; 256])>,
}

/// [`keep_brightest_on`] from the image's [`Counts`] (counted where the image was made):
/// the level chosen from them, then the kept pixels collected, in the two parts at once on
/// `pool`'s threads when the counts split the image and there is a pool (`spare` holds the
/// second part's before they join `out`): the same pixels in the same order either way.
pub fn keep_counted(
    image: &[u8],
    mask: &[u8],
    opts: &ThresholdOptions,
    counts: &Counts,
    out: &mut Vec<u32>,
    pool: Option<(&ThreadPool, &mut Vec<u32>)>,
) -> Result<ThresholdResult, DetectError> {
    same_size(image, mask)?;
    if let Some((mid, _)) = counts.first.filter(|(mid, _)| *mid > image.len()) {
        return Err(DetectError::Buffer(format!(
            "threshold: the second part starts at pixel {mid} of {}",
            image.len()
        )));
    }
    opts.validate()?;
    if image.len() > u32::MAX as usize {
        return Err(DetectError::Buffer("threshold: image too large".into()));
    }
    out.clear();
    let (hist, valid) = (&counts.hist, counts.valid);
    let median = median(hist, image.len() as u64 - valid, valid);
    let lo = opts.min_level() as usize + 1;
    let candidates: u64 = hist[lo.min(256)..].iter().map(|&c| c as u64).sum();
    let (level, stride) = choose_level(hist, opts.target_points() as u64, lo, candidates);
    let level_u8 = level.min(255) as u8;
    let level_ok = level_u8 as usize >= lo;
    let at = |s: usize, e: usize| Scan {
        image: &image[s..e],
        mask: &mask[s..e],
        first: s as u32,
        level: level_u8,
        level_ok,
        stride,
    };
    match (pool, &counts.first) {
        (Some((pool, spare)), Some((mid, first))) => {
            // the second part starts where the first leaves the count of pixels at the level
            let phase = phase_after(first[level_u8 as usize] as u64, stride);
            spare.clear();
            pool.join(
                || at(0, *mid).collect(0, out),
                || at(*mid, image.len()).collect(phase, spare),
            );
            out.extend_from_slice(spare);
        }
        _ => at(0, image.len()).collect(0, out),
    }
    Ok(ThresholdResult {
        level: level_u8,
        stride,
        kept: out.len(),
        candidates: candidates as usize,
        median,
    })
}

/// Pixels are visited in blocks of this many, so that blocks the mask leaves out whole (a
/// lens's image circle leaves a third of the frame black) are passed over.
const BLOCK: usize = 64;

/// The histogram of `image` where `mask` is set; masked pixels land in bin 0 (mask bytes are
/// 0 or 0xFF). Four histograms are interleaved so that runs of equal values do not serialise
/// on one counter, and blocks the mask leaves out whole are only counted into bin 0.
pub fn histogram(image: &[u8], mask: &[u8]) -> [u32; 256] {
    let mut hists = [[0u32; 256]; 4];
    let mut outside = 0u32;
    for (vb, mb) in image.chunks(BLOCK).zip(mask.chunks(BLOCK)) {
        if mb.iter().fold(0u8, |a, &m| a | m) == 0 {
            outside += mb.len() as u32;
            continue;
        }
        let mut chunks = vb.chunks_exact(4).zip(mb.chunks_exact(4));
        for (v, m) in &mut chunks {
            hists[0][(v[0] & m[0]) as usize] += 1;
            hists[1][(v[1] & m[1]) as usize] += 1;
            hists[2][(v[2] & m[2]) as usize] += 1;
            hists[3][(v[3] & m[3]) as usize] += 1;
        }
        let tail = vb.len() / 4 * 4;
        for (&v, &m) in vb[tail..].iter().zip(&mb[tail..]) {
            hists[0][(v & m) as usize] += 1;
        }
    }
    hists[0][0] += outside;
    let mut hist = [0u32; 256];
    for (i, h) in hist.iter_mut().enumerate() {
        *h = hists[0][i] + hists[1][i] + hists[2][i] + hists[3][i];
    }
    hist
}

/// The number of valid (unmasked) pixels, counted in runs with 32-bit lanes, which vectorise
/// four times wider than 64-bit ones.
pub fn valid_pixels(mask: &[u8]) -> u64 {
    mask.chunks(1 << 20)
        .map(|c| c.iter().map(|&m| (m & 1) as u32).sum::<u32>() as u64)
        .sum()
}

/// The median of the `valid` pixels in `hist`, where the `masked` pixels sit in bin 0 with
/// the valid zeros.
fn median(hist: &[u32; 256], masked: u64, valid: u64) -> u8 {
    let mut acc = 0u64;
    let half = masked + valid / 2;
    for (v, &c) in hist.iter().enumerate() {
        acc += c as u64;
        if acc > half {
            return v as u8;
        }
    }
    0
}

/// The level and the stride that keep about `n` pixels. The level descends from 255 until
/// the pixels at or above it reach `n`; when the `candidates` (the pixels at `lo` or above)
/// are fewer, the level is `lo` and all are kept. Of the pixels at the level, every
/// stride-th is kept (`u32::MAX`: none).
fn choose_level(hist: &[u32; 256], n: u64, lo: usize, candidates: u64) -> (usize, u32) {
    let mut above: u64 = 0; // pixels with value > level
    let mut level = 255usize;
    while level >= lo {
        let at = hist[level] as u64;
        if above + at >= n {
            break;
        }
        above += at;
        level -= 1;
    }
    if level < lo {
        // Fewer than N candidates: keep them all.
        level = lo;
        above = candidates - hist[lo.min(255)] as u64;
    }
    let at_level = if level <= 255 { hist[level] as u64 } else { 0 };
    let want_at = n.saturating_sub(above).min(at_level);
    let stride = if want_at == 0 {
        u32::MAX
    } else {
        at_level.div_ceil(want_at).max(1) as u32
    };
    (level, stride)
}

/// How many pixels at the level [`Scan::collect`] still passes over before it keeps one,
/// after `count` pixels at the level starting from 0: it keeps the first, then every
/// `stride`-th.
fn phase_after(count: u64, stride: u32) -> u32 {
    let stride = stride as u64;
    ((stride - count % stride) % stride) as u32
}

/// A run of pixels to keep from: the image's and the mask's bytes from index `first`, the
/// level, whether pixels at it may be kept, and every how many of them is.
struct Scan<'a> {
    image: &'a [u8],
    mask: &'a [u8],
    first: u32,
    level: u8,
    level_ok: bool,
    stride: u32,
}

impl Scan<'_> {
    /// Appends to `out` the indices of the valid pixels above the level, and, when
    /// `level_ok`, every `stride`-th pixel at it (in index order); `phase`: how many pixels
    /// at the level to pass over before the first kept one.
    fn collect(&self, mut phase: u32, out: &mut Vec<u32>) {
        let (level, level_ok, stride) = (self.level, self.level_ok, self.stride);
        // Scan in blocks, skipping (with a vectorised maximum) blocks with nothing to keep.
        let blocks = self.image.chunks(BLOCK).zip(self.mask.chunks(BLOCK));
        for (b, (vb, mb)) in blocks.enumerate() {
            let max = vb.iter().zip(mb).fold(0u8, |a, (&v, &m)| a.max(v & m));
            if max < level {
                continue;
            }
            // Every pixel's index is written and the end moves past the kept ones: whether
            // a pixel is kept changes from pixel to pixel at a plant's edge, and branches on
            // it mispredicted.
            let start = out.len();
            out.resize(start + vb.len(), 0);
            let mut end = start;
            let base = self.first + (b * BLOCK) as u32;
            for (k, (&v, &m)) in vb.iter().zip(mb).enumerate() {
                let v = v & m;
                let at = (v == level) & level_ok;
                let take_at = at & (phase == 0);
                out[end] = base + k as u32;
                end += ((v > level) | take_at) as usize;
                phase = match (at, phase) {
                    (false, p) => p,
                    (true, 0) => stride - 1,
                    (true, p) => p - 1,
                };
            }
            out.truncate(end);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn a_target_of_none_or_too_many_points_is_named() {
        let (image, mask) = (vec![50u8; 16], vec![0xFFu8; 16]);
        for n in [0, MAX_TARGET_POINTS + 1] {
            let opts = ThresholdOptions {
                target_points: Some(n),
                min_level: Some(10),
            };
            let e = keep_brightest(&image, &mask, &opts, &mut Vec::new())
                .unwrap_err()
                .to_string();
            assert!(e.contains("threshold.target_points"), "{e}");
        }
    }

    #[test]
    fn keeps_the_brightest_and_respects_mask() {
        let image: Vec<u8> = (0..=255u8).collect();
        let mut mask = vec![0xFFu8; 256];
        mask[255] = 0;
        let mut out = Vec::new();
        let opts = ThresholdOptions {
            target_points: Some(10),
            min_level: Some(10),
        };
        let r = keep_brightest(&image, &mask, &opts, &mut out).unwrap();
        assert_eq!(r.kept, 10);
        assert_eq!(out, (245..255).collect::<Vec<u32>>());
        assert_eq!(r.level, 245);
        assert_eq!(r.median, 127);
    }

    #[test]
    fn the_halves_on_two_threads_keep_the_same_pixels() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let mut spare = Vec::new();
        // noise, a masked band and long runs of one value (ties thinned across the halves)
        for seed in 0..40u64 {
            let n = 64 * (20 + seed as usize * 7) + seed as usize;
            let mut image = crate::detect::noise_bytes(seed, n);
            for v in image.iter_mut().skip(n / 3).take(n / 4) {
                *v = 200;
            }
            let mask: Vec<u8> = (0..n)
                .map(|i| if (i / 97) % 5 == 1 { 0 } else { 0xFF })
                .collect();
            for target in [1, 37, 300, n] {
                let opts = ThresholdOptions {
                    target_points: Some(target.min(MAX_TARGET_POINTS)),
                    min_level: Some(10),
                };
                let (mut want, mut got) = (Vec::new(), Vec::new());
                let a = keep_brightest(&image, &mask, &opts, &mut want).unwrap();
                let b =
                    keep_brightest_on(&image, &mask, &opts, &mut got, Some((&pool, &mut spare)))
                        .unwrap();
                assert_eq!((a, &got), (b, &want), "seed {seed}, target {target}");
            }
        }
        // ties: every stride-th pixel at the level, counted on across the halves
        let (image, mask) = (vec![200u8; 1000], vec![0xFFu8; 1000]);
        let opts = ThresholdOptions {
            target_points: Some(70),
            min_level: Some(10),
        };
        let mut got = Vec::new();
        let r =
            keep_brightest_on(&image, &mask, &opts, &mut got, Some((&pool, &mut spare))).unwrap();
        assert_eq!(r.stride, 15);
        assert!(got.windows(2).all(|w| w[1] - w[0] == 15), "{got:?}");
    }

    #[test]
    fn counts_split_anywhere_keep_the_same_pixels() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let n = 5000;
        let mut image = crate::detect::noise_bytes(7, n);
        for v in image.iter_mut().skip(1000).take(1500) {
            *v = 180;
        }
        let mask: Vec<u8> = (0..n)
            .map(|i| if i % 300 < 40 { 0 } else { 0xFF })
            .collect();
        let whole = Counts {
            hist: histogram(&image, &mask),
            valid: valid_pixels(&mask),
            first: None,
        };
        for target in [1, 100, 900, 4000] {
            let opts = ThresholdOptions {
                target_points: Some(target),
                min_level: Some(10),
            };
            let mut want = Vec::new();
            let t = keep_brightest(&image, &mask, &opts, &mut want).unwrap();
            let (mut got, mut spare) = (Vec::new(), Vec::new());
            assert_eq!(
                keep_counted(&image, &mask, &opts, &whole, &mut got, None).unwrap(),
                t
            );
            assert_eq!(got, want);
            // split at any pixel, a block's start or not, the ends included
            for mid in [0, 1, 63, 64, 1234, 2500, n] {
                let counts = Counts {
                    first: Some((mid, histogram(&image[..mid], &mask[..mid]))),
                    ..whole.clone()
                };
                let r = keep_counted(
                    &image,
                    &mask,
                    &opts,
                    &counts,
                    &mut got,
                    Some((&pool, &mut spare)),
                );
                assert_eq!(
                    (r.unwrap(), &got),
                    (t, &want),
                    "target {target}, split at {mid}"
                );
            }
        }
        let past = Counts {
            first: Some((n + 1, [0; 256])),
            ..whole
        };
        assert!(keep_counted(
            &image,
            &mask,
            &ThresholdOptions::default(),
            &past,
            &mut Vec::new(),
            None
        )
        .is_err());
    }

    #[test]
    fn the_phase_after_some_pixels_at_the_level() {
        // kept: the 1st, the (stride + 1)-th, …; the phase counts down to the next kept
        for stride in [1u32, 2, 3, 10] {
            let mut phase = 0u32;
            for count in 0..40u64 {
                assert_eq!(
                    phase_after(count, stride),
                    phase,
                    "{count} at stride {stride}"
                );
                phase = if phase == 0 { stride - 1 } else { phase - 1 };
            }
        }
        assert_eq!(phase_after(5, u32::MAX), u32::MAX - 5);
    }

    #[test]
    fn ties_are_thinned_evenly() {
        let image = vec![200u8; 1000];
        let mask = vec![0xFFu8; 1000];
        let mut out = Vec::new();
        let opts = ThresholdOptions {
            target_points: Some(100),
            min_level: Some(10),
        };
        let r = keep_brightest(&image, &mask, &opts, &mut out).unwrap();
        assert_eq!(r.stride, 10);
        assert_eq!(out.len(), 100);
        assert!(out.windows(2).all(|w| w[1] - w[0] == 10));
    }

    #[test]
    fn background_only_keeps_nothing() {
        let image = vec![5u8; 100];
        let mask = vec![0xFFu8; 100];
        let mut out = vec![1, 2, 3];
        let r = keep_brightest(&image, &mask, &ThresholdOptions::default(), &mut out).unwrap();
        assert_eq!(r.kept, 0);
        assert!(out.is_empty());
        assert!(
            keep_brightest(&image, &mask[..5], &ThresholdOptions::default(), &mut out).is_err()
        );
    }

    proptest! {
        #[test]
        fn masked_runs_count_as_masked(seed in 0u64..1000, n in 1usize..2000) {
            // runs of masked and valid pixels, long enough to leave whole blocks out
            let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
            let mut next = move || { s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407); s >> 33 };
            let mut image = Vec::new();
            let mut mask = Vec::new();
            while image.len() < 6000 {
                let (len, m) = (1 + next() as usize % 300, if next() % 2 == 0 { 0 } else { 0xFF });
                for _ in 0..len {
                    image.push((next() >> 23) as u8);
                    mask.push(m);
                }
            }
            let mut out = Vec::new();
            let opts = ThresholdOptions { target_points: Some(n), min_level: Some(10) };
            let r = keep_brightest(&image, &mask, &opts, &mut out).unwrap();
            let mut valid: Vec<u8> = image.iter().zip(&mask).filter(|p| *p.1 != 0).map(|p| *p.0).collect();
            valid.sort_unstable();
            if !valid.is_empty() {
                prop_assert_eq!(r.median, valid[valid.len() / 2]);
            }
            prop_assert_eq!(r.candidates, valid.iter().filter(|&&v| v > 10).count());
            for &i in &out { prop_assert!(mask[i as usize] != 0 && image[i as usize] >= r.level); }
            let above = valid.iter().filter(|&&v| v > r.level).count();
            prop_assert!(out.len() >= above);
            // the kept pixels by definition: all above the level, every stride-th at it
            let (mut expect, mut at) = (Vec::new(), 0u32);
            for (i, (&v, &m)) in image.iter().zip(&mask).enumerate() {
                let v = v & m;
                if v > r.level {
                    expect.push(i as u32);
                } else if v == r.level && v > 10 {
                    if at % r.stride == 0 {
                        expect.push(i as u32);
                    }
                    at += 1;
                }
            }
            prop_assert_eq!(out, expect);
        }

        #[test]
        fn kept_count_is_near_target(seed in 0u64..1000, n in 1usize..500) {
            // pseudo-random image
            let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
            let image: Vec<u8> = (0..4000).map(|_| { s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407); (s >> 56) as u8 }).collect();
            let mask = vec![0xFFu8; image.len()];
            let mut out = Vec::new();
            let opts = ThresholdOptions { target_points: Some(n), min_level: Some(10) };
            let r = keep_brightest(&image, &mask, &opts, &mut out).unwrap();
            let cand = image.iter().filter(|&&v| v > 10).count();
            prop_assert_eq!(r.candidates, cand);
            if cand >= n {
                prop_assert!(out.len() >= n / 2 && out.len() <= n, "kept {} for {}", out.len(), n);
            } else {
                prop_assert_eq!(out.len(), cand);
            }
            // everything kept is at least the level, everything above the level is kept
            for &i in &out { prop_assert!(image[i as usize] >= r.level); }
            let above = image.iter().filter(|&&v| v > r.level).count();
            prop_assert!(out.len() >= above);
        }
    }
}
