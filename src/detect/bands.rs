//! An image's rows split into bands across the detector's threads.
//!
//! Owns [`rows`]: a row-by-row stage (the vegetation index, each pass of the smoothing)
//! writes its output rows in contiguous bands, one per thread of the detector's pool, at
//! once; each band is computed exactly as the whole would be, so the image is the same with
//! any number of threads. Nothing is allocated: the bands are slices of the output and the
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
    let parts = pool.map_or(1, |p| p.current_num_threads());
    let parts = parts.min(height / MIN_ROWS).max(1);
    match pool {
        Some(pool) if parts > 1 => split(pool, out, width, 0..height, parts, f),
        _ => f(0..height, out),
    }
}

/// `f` over the rows `rows` of the image whose rows `out` holds, in `parts` bands.
fn split<F>(
    pool: &ThreadPool,
    out: &mut [u8],
    width: usize,
    rows: Range<usize>,
    parts: usize,
    f: &F,
) where
    F: Fn(Range<usize>, &mut [u8]) + Sync,
{
    if parts < 2 {
        return f(rows, out);
    }
    let half = parts / 2;
    let mid = rows.start + rows.len() * half / parts;
    let (a, b) = out.split_at_mut((mid - rows.start) * width);
    pool.join(
        || split(pool, a, width, rows.start..mid, half, f),
        || split(pool, b, width, mid..rows.end, parts - half, f),
    );
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
