//! The agreement of the strips' peaks seen from a candidate vanishing point (a_v, p_v): each
//! peak at (a, p) below it lies at u = (a − a_v)/(p − p_v) in the pencil of lines through the
//! point, with a width in u of its position's uncertainty over its depth p − p_v. The
//! agreement is Σ over the pairs of peaks from different strips of wᵢwⱼ·K(Δu / √(sᵢ² + sⱼ²)),
//! over (Σw)², times the share of the peaks below the point; K is the triweight kernel with a
//! standard deviation of 1. At the rows' vanishing point the peaks of one row share one u in
//! every strip, and the agreement peaks.

use super::peaks::Peak;
use super::StripsRows;
use multiversion::multiversion;
use rayon::ThreadPool;

/// Uncertainty (sigma, pixels) of a peak's position: the kernel's width in the agreement.
pub(super) const PEAK_SIGMA_PX: f64 = 4.0;

/// The share of the peaks, the most prominent, on which the search's coarse grid reads the
/// agreement ([`StripsRows::keep_strong_peaks`]): its pairs are the pairs that rank the
/// coarse grid's maxima, and the weakest third's are most of the rest (a weak peak pairs with
/// every peak within the kernel's reach as a strong one does). On CRDLD (500 images, both
/// focal-length guesses) the same scores as all the peaks at 0.8× the detector's time; the
/// strongest half loses rows (docs/detector.md, "Where the strips' time goes").
pub(super) const COARSE_PEAKS_SHARE: f64 = 2.0 / 3.0;

/// Peaks nearer the horizon than this (pixels below the candidate vanishing point) take no
/// part in the agreement, the comb or the rows' lines: there the rows merge.
pub(super) const MIN_DEPTH_PX: f64 = 12.0;

/// The peaks seen from a candidate vanishing point, in columns sorted by u: u, the square
/// of the kernel's width in u, weight and strip.
#[derive(Debug, Clone, Default)]
pub(super) struct SeenColumns {
    pub(super) u: Vec<f64>,
    s2: Vec<f64>,
    pub(super) w: Vec<f64>,
    pub(super) strip: Vec<u32>,
    /// The strips again as f64, so that every lane of the pair sum is 64 bits wide.
    strip_f: Vec<f64>,
}

impl SeenColumns {
    fn clear(&mut self) {
        self.u.clear();
        self.s2.clear();
        self.w.clear();
        self.strip.clear();
        self.strip_f.clear();
    }

    fn push(&mut self, u: f64, s: f64, w: f64, strip: u32) {
        self.u.push(u);
        self.s2.push(s * s);
        self.w.push(w);
        self.strip.push(strip);
        self.strip_f.push(strip as f64);
    }

    pub(super) fn len(&self) -> usize {
        self.u.len()
    }

    /// The peaks within `band` of `u`.
    pub(super) fn within(&self, u: f64, band: f64) -> std::ops::Range<usize> {
        let lo = self.u.partition_point(|&x| x < u - band);
        let hi = self.u.partition_point(|&x| x <= u + band);
        lo..hi
    }

    /// Σ over the pairs of peaks from different strips of wᵢwⱼ·K(Δu / √(sᵢ² + sⱼ²)) and the
    /// peaks' total weight; K the triweight kernel with a standard deviation of 1.
    fn pair_sum(&self) -> (f64, f64) {
        pair_sum(&self.u, &self.s2, &self.w, &self.strip_f)
    }
}

/// One thread's scratch for the agreement at candidates: the peaks seen from the last one.
#[derive(Debug, Clone, Default)]
pub(super) struct Sight {
    /// The peaks below the last candidate, for the agreement's pair sums and the comb.
    pub(super) columns: SeenColumns,
    /// The sort keys of the peaks below a candidate (u, then the peak's index).
    keys: Vec<u64>,
}

impl Sight {
    /// Fills `self.columns` with the `peaks` below the candidate (a, p), sorted by u;
    /// returns the share of the peaks' count that is there.
    pub(super) fn see(&mut self, peaks: &[Peak], a: f64, p: f64) -> f64 {
        // the peaks are in the strips' order, deepest last: those below are the last ones
        let first = peaks.partition_point(|k| k.p - p <= MIN_DEPTH_PX);
        let key = |k: usize| sort_key((peaks[k].a - a) / (peaks[k].p - p), k);
        self.keys.clear();
        self.keys.extend((first..peaks.len()).map(key));
        // sorting 8-byte keys is faster than sorting the peaks themselves
        self.keys.sort_unstable();
        self.columns.clear();
        for &k in &self.keys {
            let k = &peaks[(k & 0xffff_ffff) as usize];
            let d = k.p - p;
            self.columns
                .push((k.a - a) / d, PEAK_SIGMA_PX / d, k.w, k.strip);
        }
        self.columns.len() as f64 / peaks.len().max(1) as f64
    }

    /// The agreement of the `peaks` seen from (a, p) (see the module's doc); 0 with fewer
    /// than four peaks below the point. A function of the peaks and the point alone.
    pub(super) fn agreement(&mut self, peaks: &[Peak], a: f64, p: f64) -> f64 {
        let share = self.see(peaks, a, p);
        if self.columns.len() < 4 {
            return 0.0;
        }
        let (num, total) = self.columns.pair_sum();
        if total <= 0.0 {
            return 0.0;
        }
        num / (total * total) * share
    }
}

impl StripsRows {
    /// Fills `self.sight.columns` with the peaks below the candidate (a, p), sorted by u;
    /// returns the share of the peaks' count that is there.
    pub(super) fn see(&mut self, a: f64, p: f64) -> f64 {
        self.sight.see(&self.peaks, a, p)
    }

    /// The agreement of the peaks seen from (a, p) (see the module's doc); 0 with fewer than
    /// four peaks below the point. Counts the candidate in [`super::StripsResult::evaluated`].
    pub(super) fn agreement(&mut self, a: f64, p: f64) -> f64 {
        self.last.evaluated += 1;
        self.sight.agreement(&self.peaks, a, p)
    }

    /// The agreements at the candidates `self.cand` (along, below) into `self.vals`, the
    /// candidates split across `pool`'s threads (each with its own [`Sight`]) when there is
    /// one: the same values as one after the other, since each is a function of the peaks
    /// and its point alone. On the strong peaks alone ([`Self::keep_strong_peaks`]) with
    /// `strong`. Counts the candidates in [`super::StripsResult::evaluated`].
    pub(super) fn agreements(&mut self, pool: Option<&ThreadPool>, strong: bool) {
        let n = self.cand.len();
        self.last.evaluated += n;
        self.vals.clear();
        self.vals.resize(n, 0.0);
        let threads = pool.map_or(1, |p| p.current_num_threads());
        let parts = threads.min(n / MIN_CANDIDATES_PER_THREAD).max(1);
        while self.sights.len() + 1 < parts {
            self.sights.push(Sight::default());
        }
        let peaks = if strong { &self.strong } else { &self.peaks };
        match pool {
            Some(pool) if parts > 1 => split(
                pool,
                peaks,
                &self.cand,
                &mut self.vals,
                &mut self.sight,
                &mut self.sights[..parts - 1],
            ),
            _ => evaluate(peaks, &self.cand, &mut self.vals, &mut self.sight),
        }
    }
}

impl StripsRows {
    /// The peaks the coarse grid reads into `self.strong`: the strongest
    /// [`COARSE_PEAKS_SHARE`] of them by prominence, in the strips' order.
    pub(super) fn keep_strong_peaks(&mut self) {
        self.strong.clear();
        if self.peaks.is_empty() {
            return;
        }
        self.scratch.clear();
        self.scratch.extend(self.peaks.iter().map(|k| k.w));
        let n = self.scratch.len();
        let weakest = ((1.0 - COARSE_PEAKS_SHARE) * n as f64) as usize;
        let (_, &mut cut, _) = self
            .scratch
            .select_nth_unstable_by(weakest.min(n - 1), f64::total_cmp);
        self.strong
            .extend(self.peaks.iter().filter(|k| k.w >= cut).copied());
    }
}

/// Candidates per thread below which [`StripsRows::agreements`] uses fewer threads: a
/// candidate costs some microseconds, handing work to another thread about as much.
const MIN_CANDIDATES_PER_THREAD: usize = 4;

/// The agreements at `cand` into `vals`, on this thread.
fn evaluate(peaks: &[Peak], cand: &[[f64; 2]], vals: &mut [f64], sight: &mut Sight) {
    for (c, v) in cand.iter().zip(vals.iter_mut()) {
        *v = sight.agreement(peaks, c[0], c[1]);
    }
}

/// The agreements at `cand` into `vals`, in `rest.len() + 1` contiguous parts on `pool`'s
/// threads, `first` and `rest` their scratch.
fn split(
    pool: &ThreadPool,
    peaks: &[Peak],
    cand: &[[f64; 2]],
    vals: &mut [f64],
    first: &mut Sight,
    rest: &mut [Sight],
) {
    // the first `half` parts here with `first` and `rest[..half - 1]`, the others beside
    let parts = rest.len() + 1;
    let half = parts / 2;
    if half == 0 {
        return evaluate(peaks, cand, vals, first);
    }
    let k = cand.len() * half / parts;
    let (ca, cb) = cand.split_at(k);
    let (va, vb) = vals.split_at_mut(k);
    let (ra, rb) = rest.split_at_mut(half - 1);
    let Some((fb, rb)) = rb.split_first_mut() else {
        return evaluate(peaks, cand, vals, first);
    };
    pool.join(
        || split(pool, peaks, ca, va, first, ra),
        || split(pool, peaks, cb, vb, fb, rb),
    );
}

/// [`SeenColumns::pair_sum`] on the columns. Compiled also for AVX2 (four lanes in one
/// register), chosen at run time; the same operations in the same order either way.
#[multiversion(targets("x86_64+avx2"))]
fn pair_sum(u: &[f64], s2: &[f64], w: &[f64], strip: &[f64]) -> (f64, f64) {
    let s2_max = s2.iter().fold(0.0f64, |m, &x| m.max(x));
    let (mut num, mut total) = (0.0, 0.0);
    let mut end = 0;
    for i in 0..u.len() {
        let (xu, xs2, xw) = (u[i], s2[i], w[i]);
        total += xw;
        // every pair within the kernel's support lies before `end` (a pair beyond the
        // support adds an exact zero, so `end` only has to be far enough)
        let reach = 3.0 * (xs2 + s2_max).sqrt();
        end = end.max(i + 1);
        while end < u.len() && u[end] - xu <= reach {
            end += 1;
        }
        num += xw * pairs(u, s2, w, strip, i, end);
    }
    (num, total)
}

/// Σ over the peaks `i+1..end` of wⱼ·K(Δu / √(sᵢ² + sⱼ²)) for those from another strip
/// than peak `i`; K the triweight kernel with a standard deviation of 1. Branch-free in
/// four lanes: a pair outside the kernel's support or within one strip adds zero.
#[inline(always)]
fn pairs(u: &[f64], s2: &[f64], w: &[f64], strip: &[f64], i: usize, end: usize) -> f64 {
    let (xu, xs2, xstrip) = (u[i], s2[i], strip[i]);
    let r = i + 1..end;
    let (u, s2, w, st) = (&u[r.clone()], &s2[r.clone()], &w[r.clone()], &strip[r]);
    let term = |u: f64, s2: f64, w: f64, st: f64| {
        let du = u - xu;
        let k = 1.0 - du * du / (9.0 * (xs2 + s2));
        let k = if k > 0.0 { k } else { 0.0 };
        let w = if st != xstrip { w } else { 0.0 };
        w * k * k * k
    };
    let mut acc = [0.0f64; 4];
    let lanes = u
        .chunks_exact(4)
        .zip(s2.chunks_exact(4))
        .zip(w.chunks_exact(4))
        .zip(st.chunks_exact(4));
    for (((u, s2), w), st) in lanes {
        for l in 0..4 {
            acc[l] += term(u[l], s2[l], w[l], st[l]);
        }
    }
    let full = u.len() / 4 * 4;
    for j in full..u.len() {
        acc[0] += term(u[j], s2[j], w[j], st[j]);
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3])
}

/// A key that sorts as `u` (rounded to f32, which orders all but near-equal values the
/// same) with the index `i` (below 2³²) in its low half.
fn sort_key(u: f64, i: usize) -> u64 {
    let b = (u as f32).to_bits();
    let ordered = if b >> 31 == 1 { !b } else { b | 0x8000_0000 };
    ((ordered as u64) << 32) | (i as u64 & 0xffff_ffff)
}

#[cfg(test)]
mod tests {
    use super::super::testing::uniform;
    use super::*;

    /// A peak seen from a candidate: u, the kernel's width in u, weight and strip.
    #[derive(Debug, Clone, Copy, PartialEq)]
    struct Seen {
        u: f64,
        s: f64,
        w: f64,
        strip: u32,
    }

    fn columns(seen: &[Seen]) -> SeenColumns {
        let mut c = SeenColumns::default();
        for x in seen {
            c.push(x.u, x.s, x.w, x.strip);
        }
        c
    }

    #[test]
    fn the_lanes_pair_sum_is_the_pairs_sum_over_the_kernels_support() {
        let mut r = uniform(17);
        let mut seen: Vec<Seen> = (0..203)
            .map(|_| Seen {
                u: 4.0 * r() - 2.0,
                s: 0.01 + 0.2 * r(),
                w: r(),
                strip: (r() * 12.0) as u32,
            })
            .collect();
        seen.sort_by(|x, y| x.u.total_cmp(&y.u));
        let c = columns(&seen);
        let pairs = |c: &SeenColumns, i, end| pairs(&c.u, &c.s2, &c.w, &c.strip_f, i, end);
        let direct = |i: usize, end: usize| -> f64 {
            let x = seen[i];
            seen[i + 1..end]
                .iter()
                .filter(|y| y.strip != x.strip)
                .map(|y| {
                    let z2 = (y.u - x.u).powi(2) / (x.s * x.s + y.s * y.s);
                    y.w * (1.0 - z2 / 9.0).max(0.0).powi(3)
                })
                .sum()
        };
        let mut nonzero = 0;
        for i in 0..seen.len() {
            for end in [seen.len(), (i + 7).min(seen.len())] {
                let (lanes, want) = (pairs(&c, i, end), direct(i, end));
                assert!(
                    (lanes - want).abs() <= 1e-12 * (1.0 + want),
                    "{i}: {lanes} {want}"
                );
                nonzero += usize::from(want > 0.0);
            }
        }
        assert!(nonzero > 300, "{nonzero}");
        // a pair within one strip adds nothing however close
        let c = columns(&[
            seen[0],
            Seen {
                u: seen[0].u,
                ..seen[0]
            },
        ]);
        assert_eq!(pairs(&c, 0, 2), 0.0);
    }

    #[test]
    fn the_coarse_grid_reads_the_strongest_two_thirds_of_the_peaks_in_their_order() {
        use super::super::testing::forward_camera;
        use super::super::StripsOptions;
        let mut s = StripsRows::new(StripsOptions::default(), 15.0, &forward_camera()).unwrap();
        s.keep_strong_peaks();
        assert!(s.strong.is_empty());
        let mut r = uniform(5);
        s.peaks = (0..90)
            .map(|i| Peak {
                a: 100.0 * r(),
                p: (i / 9) as f64 * 11.0,
                w: r(),
                strip: (i / 9) as u32,
            })
            .collect();
        s.keep_strong_peaks();
        assert_eq!(s.strong.len(), 60);
        let weakest_kept = s.strong.iter().map(|k| k.w).fold(f64::MAX, f64::min);
        let dropped = s.peaks.iter().filter(|k| k.w < weakest_kept).count();
        assert_eq!(dropped, 30);
        // a subsequence of the peaks: the strips' order, deepest last
        let mut rest = s.peaks.iter();
        assert!(s.strong.iter().all(|k| rest.any(|x| x == k)));
    }

    #[test]
    fn keys_sort_as_their_u_then_their_index() {
        let us = [-3.5, -0.0, 0.0, 1e-9, 2.0, -1e30, 7.25];
        let mut keys: Vec<u64> = us
            .iter()
            .enumerate()
            .map(|(i, &u)| sort_key(u, i))
            .collect();
        keys.sort_unstable();
        let order: Vec<usize> = keys.iter().map(|k| (k & 0xffff_ffff) as usize).collect();
        assert_eq!(order, [5, 0, 1, 2, 3, 4, 6]);
    }
}
