//! Labelled crop rows: the two label formats `omnirow eval real` reads, and the scan-line
//! curves the scoring works on.
//!
//! Owns reading a label file into [`ScanCurve`]s: a mask image of centre lines (as in CRDLD:
//! white polylines on black, thresholded) traced scan line by scan line from the bottom of the
//! image up, or a JSON file of polylines in pixel coordinates. A row is a curve that crosses
//! each image row (scan line) of its extent once, as crop rows do in a forward-looking camera.

use std::path::{Path, PathBuf};

/// An error reading a label file. Names the file and what is wrong with it.
#[derive(Debug, thiserror::Error)]
pub enum LabelError {
    #[error("{path}: cannot read the label file: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: cannot decode the label mask: {source}")]
    Decode {
        path: PathBuf,
        #[source]
        source: image::ImageError,
    },
    #[error("{path}: {problem}")]
    Invalid { path: PathBuf, problem: String },
}

/// A labelled row as the scoring sees it: its column at every image row (scan line) from
/// `first_row` to `first_row + cols.len() - 1`.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanCurve {
    pub first_row: usize,
    /// Column (pixels, 0-based, pixel centres at integers) at each scan line.
    pub cols: Vec<f64>,
}

impl ScanCurve {
    /// The scan line after the last.
    pub fn end_row(&self) -> usize {
        self.first_row + self.cols.len()
    }

    /// The curve's column at scan line `row`, when the curve spans it.
    pub fn col_at(&self, row: usize) -> Option<f64> {
        row.checked_sub(self.first_row)
            .and_then(|i| self.cols.get(i))
            .copied()
    }

    /// The curve as a polyline of (row, col) points, one per scan line.
    pub fn points(&self) -> impl Iterator<Item = [f64; 2]> + '_ {
        self.cols
            .iter()
            .enumerate()
            .map(|(i, &c)| [(self.first_row + i) as f64, c])
    }

    /// A polyline of (row, col) vertices sampled at every scan line it spans (linear between
    /// vertices), clipped to `height` rows. Errors when the polyline turns back in rows: a
    /// crop row crosses each scan line once.
    pub fn from_polyline(points: &[[f64; 2]], height: usize) -> Result<Self, String> {
        if points.len() < 2 {
            return Err(format!(
                "a row needs at least 2 points, this one has {}",
                points.len()
            ));
        }
        if let Some(p) = points
            .iter()
            .find(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            return Err(format!("point {p:?} is not a pair of finite numbers"));
        }
        let ascending = points.last().map(|p| p[0]) >= points.first().map(|p| p[0]);
        let mut pts = points.to_vec();
        if !ascending {
            pts.reverse();
        }
        if let Some(w) = pts.windows(2).find(|w| w[1][0] < w[0][0]) {
            return Err(format!(
                "the polyline turns back at ({}, {}): a row must cross each image row once",
                w[1][0], w[1][1]
            ));
        }
        let lo = pts[0][0].ceil().max(0.0);
        let hi = pts[pts.len() - 1][0].floor().min(height as f64 - 1.0);
        if hi < lo {
            return Err(format!(
                "the row spans no whole image row within the image's {height} rows"
            ));
        }
        let (first, last) = (lo as usize, hi as usize);
        let mut cols = Vec::with_capacity(last - first + 1);
        let mut seg = 0;
        for r in first..=last {
            let y = r as f64;
            while seg + 2 < pts.len() && pts[seg + 1][0] < y {
                seg += 1;
            }
            let (a, b) = (pts[seg], pts[seg + 1]);
            let t = if b[0] > a[0] {
                ((y - a[0]) / (b[0] - a[0])).clamp(0.0, 1.0)
            } else {
                0.5
            };
            cols.push(a[1] + t * (b[1] - a[1]));
        }
        Ok(ScanCurve {
            first_row: first,
            cols,
        })
    }
}

/// How centre lines are traced in a mask image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MaskTracing {
    /// Pixels at or above this value are on a line (CRDLD: 128, its masks being JPEG).
    pub threshold: u8,
    /// A run of line pixels on a scan line wider than this is two or more lines merging
    /// (near the vanishing point) or a row too flat to trace: the rows entering it end there.
    pub max_run_px: usize,
    /// A run continues a row when its centre lies within this many pixels of the row's
    /// extrapolated column.
    pub link_px: f64,
    /// A row missing from more than this many consecutive scan lines ends.
    pub max_gap_rows: usize,
    /// Rows spanning fewer scan lines are dropped (specks, stubs above a merge).
    pub min_rows: usize,
}

impl Default for MaskTracing {
    fn default() -> Self {
        MaskTracing {
            threshold: 128,
            max_run_px: 20,
            link_px: 4.0,
            max_gap_rows: 6,
            min_rows: 24,
        }
    }
}

/// A row being traced up the mask.
struct Track {
    /// (scan line, column) of the run centres, bottom first.
    pts: Vec<(usize, f64)>,
    open: bool,
    /// Started next to where rows merged: a stub of merged lines, not a row of its own.
    tainted: bool,
}

impl Track {
    /// The column the track is expected at on scan line `row`: a line through its last
    /// few centres.
    fn predict(&self, row: usize) -> f64 {
        let n = self.pts.len();
        let k = n.min(12);
        let recent = &self.pts[n - k..];
        let &(r1, c1) = recent.last().expect("a track has a point");
        if k < 4 {
            return c1;
        }
        let (r0, c0) = recent[0];
        let slope = (c1 - c0) / (r1 as f64 - r0 as f64);
        c1 + slope * (row as f64 - r1 as f64)
    }
}

/// Traces the centre lines of a mask (row-major, `width` × `height`, one byte a pixel) from
/// the bottom scan line up: each run of line pixels is a row's crossing; runs link to the
/// row whose extrapolated column is nearest; rows end where they merge with another.
pub fn trace_mask(data: &[u8], width: usize, height: usize, opts: &MaskTracing) -> Vec<ScanCurve> {
    let mut tracks: Vec<Track> = Vec::new();
    // Where rows ended by merging: (scan line, column).
    let mut merges: Vec<(usize, f64)> = Vec::new();
    let mut runs: Vec<(usize, usize)> = Vec::new();
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for row in (0..height).rev() {
        runs.clear();
        let line = &data[row * width..(row + 1) * width];
        let mut start = None;
        for (c, &v) in line.iter().enumerate() {
            match (v >= opts.threshold, start) {
                (true, None) => start = Some(c),
                (false, Some(s)) => {
                    runs.push((s, c - 1));
                    start = None;
                }
                _ => {}
            }
        }
        if let Some(s) = start {
            runs.push((s, width - 1));
        }
        // Which open tracks each run could continue.
        pairs.clear();
        let mut claimed = vec![0usize; runs.len()];
        for (t, track) in tracks.iter().enumerate().filter(|(_, t)| t.open) {
            let p = track.predict(row);
            for (k, &(s, e)) in runs.iter().enumerate() {
                let (lo, hi) = (s as f64 - opts.link_px, e as f64 + opts.link_px);
                if p >= lo && p <= hi {
                    claimed[k] += 1;
                    pairs.push(((p - (s + e) as f64 / 2.0).abs(), k, t));
                }
            }
        }
        pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut run_used = vec![false; runs.len()];
        let mut track_used = vec![false; tracks.len()];
        for &(_, k, t) in &pairs {
            if run_used[k] || track_used[t] {
                continue;
            }
            let (s, e) = runs[k];
            let merged = e + 1 - s > opts.max_run_px || claimed[k] > 1;
            if merged {
                // Every row entering this run ends here.
                for &(_, k2, t2) in pairs.iter().filter(|p| p.1 == k) {
                    tracks[t2].open = false;
                    track_used[t2] = true;
                    merges.push((row, tracks[t2].predict(row)));
                    let _ = k2;
                }
                run_used[k] = true;
                continue;
            }
            run_used[k] = true;
            track_used[t] = true;
            tracks[t].pts.push((row, (s + e) as f64 / 2.0));
        }
        for (k, &(s, e)) in runs.iter().enumerate() {
            if run_used[k] || e + 1 - s > opts.max_run_px {
                continue;
            }
            let c = (s + e) as f64 / 2.0;
            let tainted = merges.iter().any(|&(mr, mc)| {
                mr <= row + 2 * opts.max_gap_rows
                    && (mc - c).abs() <= opts.max_run_px as f64 + opts.link_px
            });
            tracks.push(Track {
                pts: vec![(row, c)],
                open: true,
                tainted,
            });
        }
        for t in tracks.iter_mut().filter(|t| t.open) {
            let last = t.pts.last().expect("a track has a point").0;
            if last - row > opts.max_gap_rows {
                t.open = false;
            }
        }
    }
    tracks
        .into_iter()
        .filter(|t| !t.tainted)
        .filter_map(|t| curve_of_track(&t.pts, opts.min_rows))
        .collect()
}

/// A track's centres (bottom first) as a scan curve, gaps filled linearly; `None` when it
/// spans fewer than `min_rows` scan lines.
fn curve_of_track(pts: &[(usize, f64)], min_rows: usize) -> Option<ScanCurve> {
    let (first, last) = (pts.last()?.0, pts.first()?.0);
    if last + 1 - first < min_rows {
        return None;
    }
    let mut cols = vec![f64::NAN; last + 1 - first];
    for &(r, c) in pts {
        cols[r - first] = c;
    }
    // Fill the scan lines a gap skipped.
    let mut prev = 0;
    for i in 1..cols.len() {
        if cols[i].is_nan() {
            continue;
        }
        if i > prev + 1 {
            let (a, b) = (cols[prev], cols[i]);
            for (j, c) in cols.iter_mut().enumerate().take(i).skip(prev + 1) {
                *c = a + (b - a) * (j - prev) as f64 / (i - prev) as f64;
            }
        }
        prev = i;
    }
    Some(ScanCurve {
        first_row: first,
        cols,
    })
}

/// The JSON label format: `{"rows": [{"xy": [[x, y], ...]}, ...]}`, x the column and y the
/// image row of each polyline vertex (0-based, pixel centres at integers).
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct JsonLabels {
    rows: Vec<JsonRow>,
}

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct JsonRow {
    xy: Vec<[f64; 2]>,
}

/// Reads the JSON label format for an image `height` rows high.
pub fn parse_json(text: &str, height: usize, path: &Path) -> Result<Vec<ScanCurve>, LabelError> {
    let invalid = |problem: String| LabelError::Invalid {
        path: path.to_path_buf(),
        problem,
    };
    let raw: JsonLabels =
        serde_json::from_str(text).map_err(|e| invalid(format!("line {}: {e}", e.line())))?;
    raw.rows
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let pts: Vec<[f64; 2]> = r.xy.iter().map(|&[x, y]| [y, x]).collect();
            ScanCurve::from_polyline(&pts, height).map_err(|p| invalid(format!("rows[{i}]: {p}")))
        })
        .collect()
}

/// Reads a label file for an image of `height` × `width`: `.json` polylines, else a mask
/// image of the same size whose centre lines are traced with `tracing`.
pub fn load(
    path: &Path,
    height: usize,
    width: usize,
    tracing: &MaskTracing,
) -> Result<Vec<ScanCurve>, LabelError> {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
    {
        let text = std::fs::read_to_string(path).map_err(|source| LabelError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        return parse_json(&text, height, path);
    }
    let img = image::ImageReader::open(path)
        .map_err(|source| LabelError::Io {
            path: path.to_path_buf(),
            source,
        })?
        .with_guessed_format()
        .map_err(|source| LabelError::Io {
            path: path.to_path_buf(),
            source,
        })?
        .decode()
        .map_err(|source| LabelError::Decode {
            path: path.to_path_buf(),
            source,
        })?
        .to_luma8();
    if (img.height() as usize, img.width() as usize) != (height, width) {
        return Err(LabelError::Invalid {
            path: path.to_path_buf(),
            problem: format!(
                "the mask is {}x{}, the image {height}x{width} (height x width)",
                img.height(),
                img.width()
            ),
        });
    }
    Ok(trace_mask(img.as_raw(), width, height, tracing))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A line from one (row, col) point to another.
    type Line = ((f64, f64), (f64, f64));

    /// A mask with 6 px wide straight lines.
    fn mask(w: usize, h: usize, lines: &[Line]) -> Vec<u8> {
        let mut m = vec![0u8; w * h];
        for &((r0, c0), (r1, c1)) in lines {
            for r in 0..h {
                let y = r as f64;
                if y < r0.min(r1) || y > r0.max(r1) {
                    continue;
                }
                let c = c0 + (c1 - c0) * (y - r0) / (r1 - r0);
                for col in 0..w {
                    if (col as f64 - c).abs() <= 2.6 {
                        m[r * w + col] = 230;
                    }
                }
            }
        }
        m
    }

    #[test]
    fn traces_converging_lines_and_stops_where_they_merge() {
        // Three rows converging towards (20, 100): they touch below it.
        let (w, h) = (200, 200);
        let vp = (20.0, 100.0);
        let lines = [
            ((199.0, 20.0), vp),
            ((199.0, 100.0), vp),
            ((199.0, 180.0), vp),
        ];
        let m = mask(w, h, &lines);
        let rows = trace_mask(&m, w, h, &MaskTracing::default());
        assert_eq!(rows.len(), 3, "{rows:?}");
        for (curve, &((r0, c0), (r1, c1))) in rows.iter().zip(&lines) {
            assert_eq!(curve.end_row(), 200);
            // The traced centre is on the drawn line wherever the row was traced.
            for [r, c] in curve.points() {
                let expect = c0 + (c1 - c0) * (r - r0) / (r1 - r0);
                assert!((c - expect).abs() < 0.8, "row {r}: {c} vs {expect}");
            }
        }
        // The rows are traced until they come within a few pixels of each other, and
        // what is above (merged lines) is no row.
        for r in &rows {
            assert!((30..70).contains(&r.first_row), "{}", r.first_row);
        }
    }

    #[test]
    fn polyline_sampling_and_errors() {
        let c = ScanCurve::from_polyline(&[[10.0, 5.0], [20.0, 15.0], [30.0, 15.0]], 100).unwrap();
        assert_eq!(c.first_row, 10);
        assert_eq!(c.end_row(), 31);
        assert_eq!(c.col_at(15), Some(10.0));
        assert_eq!(c.col_at(25), Some(15.0));
        assert_eq!(c.col_at(9), None);
        // Given top to bottom or bottom to top: the same curve.
        let r = ScanCurve::from_polyline(&[[30.0, 15.0], [20.0, 15.0], [10.0, 5.0]], 100).unwrap();
        assert_eq!(r, c);
        assert!(ScanCurve::from_polyline(&[[1.0, 1.0]], 100).is_err());
        let e =
            ScanCurve::from_polyline(&[[10.0, 0.0], [30.0, 0.0], [20.0, 0.0]], 100).unwrap_err();
        assert!(e.contains("turns back"), "{e}");
        // Clipped to the image.
        let c = ScanCurve::from_polyline(&[[-10.0, 0.0], [200.0, 0.0]], 100).unwrap();
        assert_eq!((c.first_row, c.end_row()), (0, 100));
    }

    #[test]
    fn json_labels_and_their_errors() {
        let p = Path::new("l.json");
        let rows = parse_json(r#"{"rows": [{"xy": [[5, 10], [15, 20]]}]}"#, 50, p).unwrap();
        assert_eq!(rows.len(), 1);
        assert_eq!(rows[0].col_at(10), Some(5.0));
        assert_eq!(rows[0].col_at(20), Some(15.0));
        let e = parse_json(r#"{"rows": [{"points": []}]}"#, 50, p)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("l.json: line 1") && e.contains("points"),
            "{e}"
        );
        let e = parse_json(r#"{"rows": [{"xy": [[5, 10]]}]}"#, 50, p)
            .unwrap_err()
            .to_string();
        assert!(e.contains("rows[0]") && e.contains("2 points"), "{e}");
    }
}
