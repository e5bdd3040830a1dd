//! An image's rows split into bands across the detector's threads.
//!
//! Owns [`rows`]: a row-by-row stage (the vegetation index, each pass of the smoothing)
//! writes its output rows in contiguous bands, one per thread of the detector's pool, at
//! once; each band is computed exactly as the whole would be, so the image is the same with
//! any number of threads. [`each`] does the same for a stage with several outputs and
//! scratch per band (the preparation's fused pass, [`super::prepare`]). Nothing is allocated: the bands are slices of the output and the
//! threads are joined, not spawned.

use rayon::ThreadPool;
use std::ops::Range;

/// Bands thinner than this many rows are not split further: handing a band to another
/// thread costs about as much as computing a few rows of a full-resolution frame.
pub const MIN_ROWS: usize = 32;

/// Calls `f(rows, out_rows)` over `out`, an image of `width`-byte rows, in as many bands as
/// `pool` has threads (at least [`MIN_ROWS`] rows each), at once; on this thread alone
/// without a pool. `out_rows` holds exactly the output rows `rows`.
pub fn rows<F>(pool: Option<&ThreadPool>, out: &mut [u8], width: usize, f: &F)
where
    F: Fn(Range<usize>, &mut [u8]) + Sync,
{
    let height = out.len().checked_div(width).unwrap_or(0);
    each(pool, height, Rows { out, width }, &|rows, band: Rows| {
        f(rows, band.out)
    });
}

/// What a band of rows is handed ([`each`]): the parts of its outputs and inputs that hold
/// its rows, and scratch of its own.
pub trait Band: Send + Sized {
    /// The bands it can be split into at most (one per scratch it holds).
    fn parts(&self) -> usize;
    /// Split after `rows` rows, the first part with `parts` of the scratches.
    fn split(self, rows: usize, parts: usize) -> (Self, Self);
}

/// Calls `f(rows, band)` over an image of `height` rows in as many bands as `pool` has
/// threads (at least [`MIN_ROWS`] rows each, at most `band.parts()`), at once, each with
/// its part of `band`; on this thread alone without a pool. Bands are split as [`rows`]
/// splits them. Returns the number of bands.
pub fn each<B, F>(pool: Option<&ThreadPool>, height: usize, band: B, f: &F) -> usize
where
    B: Band,
    F: Fn(Range<usize>, B) + Sync,
{
    let parts = pool.map_or(1, |p| p.current_num_threads());
    let parts = parts.min(height / MIN_ROWS).min(band.parts()).max(1);
    match pool {
        Some(pool) if parts > 1 => split_each(pool, band, 0..height, parts, f),
        _ => f(0..height, band),
    }
    parts
}

/// `f` over the rows `rows`, whose parts `band` holds, in `parts` bands.
fn split_each<B, F>(pool: &ThreadPool, band: B, rows: Range<usize>, parts: usize, f: &F)
where
    B: Band,
    F: Fn(Range<usize>, B) + Sync,
{
    if parts < 2 {
        return f(rows, band);
    }
    let half = parts / 2;
    let mid = rows.start + rows.len() * half / parts;
    let (a, b) = band.split(mid - rows.start, half);
    pool.join(
        || split_each(pool, a, rows.start..mid, half, f),
        || split_each(pool, b, mid..rows.end, parts - half, f),
    );
}

/// An image's rows as a [`Band`].
struct Rows<'a> {
    out: &'a mut [u8],
    width: usize,
}

impl Band for Rows<'_> {
    fn parts(&self) -> usize {
        usize::MAX
    }

    fn split(self, rows: usize, _: usize) -> (Self, Self) {
        let (a, b) = self.out.split_at_mut(rows * self.width);
        let width = self.width;
        (Rows { out: a, width }, Rows { out: b, width })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pool(n: usize) -> ThreadPool {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
    }

    /// Each output byte written from its own row and column, band by band.
    fn fill(pool: Option<&ThreadPool>, width: usize, height: usize) -> Vec<u8> {
        let mut out = vec![0u8; width * height];
        rows(pool, &mut out, width, &|r: Range<usize>, o: &mut [u8]| {
            assert_eq!(o.len(), r.len() * width, "a band holds its rows");
            for (k, y) in r.enumerate() {
                for x in 0..width {
                    o[k * width + x] = (y * 7 + x * 3) as u8;
                }
            }
        });
        out
    }

    #[test]
    fn bands_cover_every_row_once_whatever_the_threads() {
        let (w, h) = (37, 211);
        let want = fill(None, w, h);
        assert!(want
            .iter()
            .enumerate()
            .all(|(i, &v)| v == ((i / w) * 7 + (i % w) * 3) as u8));
        for n in [2, 3, 4, 7] {
            assert_eq!(fill(Some(&pool(n)), w, h), want, "{n} threads");
        }
        // thinner than two bands, and empty
        assert_eq!(fill(Some(&pool(4)), w, 40), fill(None, w, 40));
        assert!(fill(Some(&pool(2)), w, 0).is_empty());
    }

    /// Rows and as many scratch slots as bands may be made.
    struct Slots<'a>(Range<usize>, &'a mut [Vec<Range<usize>>]);

    impl Band for Slots<'_> {
        fn parts(&self) -> usize {
            self.1.len()
        }

        fn split(self, rows: usize, parts: usize) -> (Self, Self) {
            let mid = self.0.start + rows;
            let (a, b) = self.1.split_at_mut(parts);
            (Slots(self.0.start..mid, a), Slots(mid..self.0.end, b))
        }
    }

    #[test]
    fn each_band_has_its_rows_and_scratch_and_no_more_bands_than_scratches() {
        for (threads, slots, height, want) in [
            (4, 2, 200, 2),
            (2, 4, 200, 2),
            (3, 3, 70, 2),
            (1, 3, 200, 1),
        ] {
            let mut scratch = vec![Vec::new(); slots];
            let p = pool(threads);
            let seen = std::sync::Mutex::new(Vec::new());
            let n = each(
                Some(&p),
                height,
                Slots(0..height, &mut scratch),
                &|r, b: Slots| {
                    assert_eq!(r, b.0);
                    b.1[0].push(r.clone());
                    seen.lock().unwrap().push(r);
                },
            );
            assert_eq!(n, want, "{threads} threads, {slots} slots");
            let mut seen = seen.into_inner().unwrap();
            seen.sort_by_key(|r| r.start);
            assert_eq!(seen.len(), n);
            assert_eq!(seen.iter().map(|r| r.len()).sum::<usize>(), height);
            assert!(seen.windows(2).all(|w| w[0].end == w[1].start));
            let held: Vec<_> = scratch[..n].iter().map(|s| s[0].clone()).collect();
            assert_eq!(held, seen, "band k has scratch k");
        }
        assert_eq!(
            each(None, 10, Slots(0..10, &mut [Vec::new()]), &|_, _| {}),
            1
        );
    }

    #[test]
    fn bands_are_split_across_the_threads() {
        let p = pool(2);
        let seen = std::sync::Mutex::new(Vec::new());
        let mut out = vec![0u8; 10 * 200];
        rows(Some(&p), &mut out, 10, &|r: Range<usize>, _: &mut [u8]| {
            seen.lock().unwrap().push(r);
        });
        let mut seen = seen.into_inner().unwrap();
        seen.sort_by_key(|r| r.start);
        assert_eq!(seen, vec![0..100, 100..200]);
    }
}
