//! Scoring one image's published rows against its labelled rows, in pixels, scan line by scan
//! line (as the crop-row metric CRDA does).
//!
//! Owns projecting a published row (a great circle) into the image through the calibration,
//! the local row spacing from the labels, matching published to labelled rows, the
//! row-position score, and the labels' common vanishing point. Every metric is defined in
//! docs/real.md.

use super::labels::ScanCurve;
use crate::camera::Calibration;
use crate::sphere::any_perpendicular;
use nalgebra::Vector3;

/// The metric's constants (docs/real.md).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScoreOptions {
    /// A published row finds a labelled row when it lies within this fraction of the local
    /// row spacing of it ...
    pub found_tolerance: f64,
    /// ... on at least this fraction of the labelled row's scan lines.
    pub found_fraction: f64,
    /// The row-position score of a scan line is max(0, 1 − (d / (sigma · spacing))²), CRDA's
    /// form and its σ.
    pub sigma: f64,
    /// A labelled row is straight (it takes part in the labels' vanishing point) when a line
    /// fits its centre to this RMS (pixels) ...
    pub straight_rms_px: f64,
    /// ... over at least this many scan lines.
    pub straight_min_rows: usize,
    /// The labels' vanishing point needs straight rows at least this far apart in angle.
    pub vp_min_angle_deg: f64,
}

impl Default for ScoreOptions {
    fn default() -> Self {
        ScoreOptions {
            found_tolerance: 0.25,
            found_fraction: 0.9,
            sigma: 0.1,
            straight_rms_px: 1.5,
            straight_min_rows: 40,
            vp_min_angle_deg: 3.0,
        }
    }
}

/// A published row in the image: where its great circle crosses each scan line, as
/// (scan line, column) sorted by scan line.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ProjectedRow {
    pub crossings: Vec<(usize, f64)>,
}

impl ProjectedRow {
    /// Projects the great circle with unit normal `normal` through `cal` (which describes the
    /// image at its own resolution): every scan line it crosses inside the field of view.
    pub fn project(cal: &Calibration, normal: &Vector3<f64>) -> Self {
        let (h, w) = (cal.model.height as usize, cal.model.width as usize);
        let u = any_perpendicular(normal);
        let v = normal.cross(&u);
        // About a pixel a step where the image is sharpest; jumps (the circle leaving the
        // field of view and coming back elsewhere) are not joined.
        let steps = 8 * (w + h);
        let max_jump = 0.05 * (w + h) as f64;
        let mut crossings = Vec::new();
        let mut prev: Option<[f64; 2]> = None;
        for i in 0..=steps {
            let t = i as f64 * std::f64::consts::TAU / steps as f64;
            let ray = u * t.cos() + v * t.sin();
            let p = cal.ray_to_pixel_in_fov(&ray);
            if let (Some(a), Some(b)) = (prev, p) {
                if (a[0] - b[0]).hypot(a[1] - b[1]) < max_jump {
                    push_crossings(a, b, h, &mut crossings);
                }
            }
            prev = p;
        }
        crossings.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
        crossings.dedup_by(|a, b| a.0 == b.0 && (a.1 - b.1).abs() < 0.5);
        ProjectedRow { crossings }
    }

    /// The column of the crossing on scan line `row` nearest to `col`.
    pub fn nearest_col(&self, row: usize, col: f64) -> Option<f64> {
        let i = self.crossings.partition_point(|c| c.0 < row);
        self.crossings[i..]
            .iter()
            .take_while(|c| c.0 == row)
            .map(|c| c.1)
            .min_by(|a, b| (a - col).abs().total_cmp(&(b - col).abs()))
    }
}

/// The scan lines segment a → b (row, col) crosses, each counted once: rows in [lo, hi).
fn push_crossings(a: [f64; 2], b: [f64; 2], h: usize, out: &mut Vec<(usize, f64)>) {
    let (a, b) = if a[0] <= b[0] { (a, b) } else { (b, a) };
    let lo = a[0].ceil().max(0.0);
    let hi = b[0].min(h as f64);
    let mut y = lo;
    while y < hi || (y == b[0] && y == a[0]) {
        let t = if b[0] > a[0] {
            (y - a[0]) / (b[0] - a[0])
        } else {
            0.0
        };
        out.push((y as usize, a[1] + t * (b[1] - a[1])));
        if b[0] == a[0] {
            break;
        }
        y += 1.0;
    }
}

/// The local row spacing (pixels, along the scan line) of each labelled row at each of its
/// scan lines: the mean gap to its neighbours on that scan line; where it has none, a
/// straight-line fit of all the image's gaps against the scan line. `None` when the image has
/// no two labelled rows on one scan line.
pub fn spacings(labels: &[ScanCurve]) -> Option<Vec<Vec<f64>>> {
    let end = labels.iter().map(ScanCurve::end_row).max().unwrap_or(0);
    let mut gaps: Vec<(f64, f64)> = Vec::new();
    let mut cols: Vec<f64> = Vec::new();
    for row in 0..end {
        cols.clear();
        cols.extend(labels.iter().filter_map(|l| l.col_at(row)));
        cols.sort_by(f64::total_cmp);
        gaps.extend(cols.windows(2).map(|w| (row as f64, w[1] - w[0])));
    }
    if gaps.is_empty() {
        return None;
    }
    let fallback = fit_gap(&gaps);
    Some(
        labels
            .iter()
            .map(|l| {
                l.points()
                    .map(|[r, c]| {
                        let row = r as usize;
                        let (mut left, mut right) = (f64::NEG_INFINITY, f64::INFINITY);
                        for o in labels.iter().filter_map(|o| o.col_at(row)) {
                            if o < c && o > left {
                                left = o;
                            }
                            if o > c && o < right {
                                right = o;
                            }
                        }
                        match (left.is_finite(), right.is_finite()) {
                            (true, true) => (right - left) / 2.0,
                            (true, false) => c - left,
                            (false, true) => right - c,
                            (false, false) => fallback(r),
                        }
                    })
                    .collect()
            })
            .collect(),
    )
}

/// gap(row) = a + b·row by least squares, floored at the smallest gap seen (a fit can reach
/// zero or below past the data).
fn fit_gap(gaps: &[(f64, f64)]) -> impl Fn(f64) -> f64 {
    let n = gaps.len() as f64;
    let (sx, sy) = gaps
        .iter()
        .fold((0.0, 0.0), |(sx, sy), &(x, y)| (sx + x, sy + y));
    let (mx, my) = (sx / n, sy / n);
    let (sxx, sxy) = gaps.iter().fold((0.0, 0.0), |(sxx, sxy), &(x, y)| {
        (sxx + (x - mx).powi(2), sxy + (x - mx) * (y - my))
    });
    let b = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    let floor = gaps.iter().map(|g| g.1).fold(f64::INFINITY, f64::min);
    move |row: f64| (my + b * (row - mx)).max(floor)
}

/// How one published row relates to one labelled row.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Pair {
    label: usize,
    published: usize,
    /// Fraction of the labelled scan lines where the published row is within tolerance.
    within: f64,
    /// Mean row-position score over the labelled scan lines.
    score: f64,
    /// The labelled scan lines where it is not within tolerance, by third (top first).
    misses: [usize; 3],
}

/// One image's scores.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ImageScore {
    pub labelled: usize,
    pub published: usize,
    /// Published rows that enter the band of the labelled rows (the others may be rows the
    /// labels leave out at the image borders: they count neither way).
    pub inside: usize,
    /// Labelled rows found, one published row each.
    pub matched: usize,
    /// Row-position score in 0..=1; `None` when the labels give no row spacing (fewer than
    /// two labelled rows on any scan line).
    pub score: Option<f64>,
    /// For each labelled row, the published row matched to it.
    pub matches: Vec<Option<usize>>,
    /// For each labelled row, how near the published rows came to it (the matched row, else
    /// the closest): why a row was not found.
    pub fits: Vec<LabelFit>,
}

/// How near the published rows came to one labelled row: the published row matched to it,
/// else the one within tolerance on the most of its scan lines (docs/real.md, "Why rows are
/// missed").
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct LabelFit {
    /// The labelled row was found.
    pub found: bool,
    /// The fraction of its scan lines on which that published row lies within tolerance (0
    /// when no row was published).
    pub within: f64,
    /// The scan lines where it does not (outside the tolerance or not crossed), in the top,
    /// middle and bottom third of the labelled row's extent: for a forward-looking camera the
    /// top third is the far field, towards the vanishing point.
    pub misses_top_middle_bottom: [usize; 3],
}

impl LabelFit {
    /// The third of the row (0 top, 1 middle, 2 bottom) holding most of the misses; `None`
    /// without misses.
    pub fn worst_third(&self) -> Option<usize> {
        let m = self.misses_top_middle_bottom;
        (m.iter().sum::<usize>() > 0).then(|| (0..3).rev().max_by_key(|&t| m[t]).unwrap_or(0))
    }
}

impl ImageScore {
    /// Scores `rows` (the published rows, projected) against `labels`.
    pub fn compute(labels: &[ScanCurve], rows: &[ProjectedRow], opts: &ScoreOptions) -> Self {
        let mut s = ImageScore {
            labelled: labels.len(),
            published: rows.len(),
            matches: vec![None; labels.len()],
            ..Default::default()
        };
        let Some(spacing) = spacings(labels) else {
            return s;
        };
        let mut pairs = Vec::with_capacity(labels.len() * rows.len());
        for (li, (l, sp)) in labels.iter().zip(&spacing).enumerate() {
            for (pi, p) in rows.iter().enumerate() {
                let (mut within, mut score, mut misses) = (0usize, 0.0, [0usize; 3]);
                let n = l.cols.len().max(1);
                for (k, ([r, c], &gap)) in l.points().zip(sp).enumerate() {
                    let third = (k * 3 / n).min(2);
                    let Some(x) = p.nearest_col(r as usize, c) else {
                        misses[third] += 1;
                        continue;
                    };
                    let d = (x - c).abs();
                    if d <= opts.found_tolerance * gap {
                        within += 1;
                    } else {
                        misses[third] += 1;
                    }
                    score += (1.0 - (d / (opts.sigma * gap)).powi(2)).max(0.0);
                }
                pairs.push(Pair {
                    label: li,
                    published: pi,
                    within: within as f64 / n as f64,
                    score: score / n as f64,
                    misses,
                });
            }
        }
        // Found: one published row per labelled row, the closest pairs first.
        pairs.sort_by(|a, b| {
            b.within
                .total_cmp(&a.within)
                .then(b.score.total_cmp(&a.score))
        });
        let mut used = vec![false; rows.len()];
        for p in pairs.iter().filter(|p| p.within >= opts.found_fraction) {
            if s.matches[p.label].is_none() && !used[p.published] {
                s.matches[p.label] = Some(p.published);
                used[p.published] = true;
            }
        }
        s.matched = s.matches.iter().flatten().count();
        s.fits = fits(labels, &pairs, &s.matches);
        // Position score: each labelled row against its best published row, one-to-one.
        pairs.sort_by(|a, b| b.score.total_cmp(&a.score));
        let mut label_done = vec![false; labels.len()];
        used.fill(false);
        let mut total = 0.0;
        for p in &pairs {
            if !label_done[p.label] && !used[p.published] {
                label_done[p.label] = true;
                used[p.published] = true;
                total += p.score;
            }
        }
        s.inside = rows
            .iter()
            .filter(|p| enters_band(p, labels, &spacing))
            .count();
        s.score = Some(total / s.labelled.max(s.inside).max(1) as f64);
        s
    }
}

/// Each labelled row's [`LabelFit`]: its matched row, else the one within tolerance on most
/// of its scan lines (then the best scored); `pairs` holds every label against every row.
fn fits(labels: &[ScanCurve], pairs: &[Pair], matches: &[Option<usize>]) -> Vec<LabelFit> {
    let fit = |(li, l): (usize, &ScanCurve)| {
        let of_label = pairs.iter().filter(|p| p.label == li);
        let best = match matches[li] {
            Some(pi) => of_label.clone().find(|p| p.published == pi),
            None => of_label.max_by(|a, b| {
                a.within
                    .total_cmp(&b.within)
                    .then(a.score.total_cmp(&b.score))
            }),
        };
        // with no row published, every scan line is a miss
        let n = l.cols.len();
        let none = [n.div_ceil(3), (n + 1) / 3, n / 3];
        LabelFit {
            found: matches[li].is_some(),
            within: best.map_or(0.0, |b| b.within),
            misses_top_middle_bottom: best.map_or(none, |b| b.misses),
        }
    };
    labels.iter().enumerate().map(fit).collect()
}

/// Whether a published row comes within half a row spacing of the band between the
/// outermost labelled rows on any labelled scan line.
fn enters_band(p: &ProjectedRow, labels: &[ScanCurve], spacing: &[Vec<f64>]) -> bool {
    p.crossings.iter().any(|&(row, x)| {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (l, sp) in labels.iter().zip(spacing) {
            if let Some(c) = l.col_at(row) {
                let half = sp[row - l.first_row] / 2.0;
                lo = lo.min(c - half);
                hi = hi.max(c + half);
            }
        }
        x >= lo && x <= hi
    })
}

/// The labels' common vanishing point (row, col): the least-squares intersection of the
/// lines fitted to the straight labelled rows, with the RMS distance (pixels) of those lines
/// from it. `None` with fewer than two straight rows or rows too close to parallel.
pub fn labels_vanishing_point(
    labels: &[ScanCurve],
    opts: &ScoreOptions,
) -> Option<([f64; 2], f64)> {
    // Each straight row as a unit normal n and offset k: n · (row, col) = k.
    let lines: Vec<([f64; 2], f64)> = labels
        .iter()
        .filter(|l| l.cols.len() >= opts.straight_min_rows)
        .filter_map(|l| {
            let pts: Vec<[f64; 2]> = l.points().collect();
            let n = pts.len() as f64;
            let (mr, mc) = pts
                .iter()
                .fold((0.0, 0.0), |(a, b), p| (a + p[0] / n, b + p[1] / n));
            let (srr, src) = pts.iter().fold((0.0, 0.0), |(a, b), p| {
                (a + (p[0] - mr).powi(2), b + (p[0] - mr) * (p[1] - mc))
            });
            let slope = src / srr; // col = mc + slope (row - mr)
            let rms = (pts
                .iter()
                .map(|p| (p[1] - mc - slope * (p[0] - mr)).powi(2))
                .sum::<f64>()
                / n)
                .sqrt();
            (rms <= opts.straight_rms_px).then(|| {
                let norm = slope.hypot(1.0);
                let nrm = [-slope / norm, 1.0 / norm];
                (nrm, nrm[0] * mr + nrm[1] * mc)
            })
        })
        .collect();
    if lines.len() < 2 {
        return None;
    }
    let (mut a, mut b, mut c, mut r0, mut r1) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(n, k) in &lines {
        a += n[0] * n[0];
        b += n[0] * n[1];
        c += n[1] * n[1];
        r0 += n[0] * k;
        r1 += n[1] * k;
    }
    let m = lines.len() as f64;
    // Smaller eigenvalue of the mean of n nᵀ: 1 − cos of the angle for two lines.
    let (ta, tb, tc) = (a / m, b / m, c / m);
    let min_eig = (ta + tc) / 2.0 - (((ta - tc) / 2.0).powi(2) + tb * tb).sqrt();
    if min_eig < (1.0 - opts.vp_min_angle_deg.to_radians().cos()) / 2.0 {
        return None;
    }
    let det = a * c - b * b;
    let p = [(c * r0 - b * r1) / det, (a * r1 - b * r0) / det];
    let rms = (lines
        .iter()
        .map(|&(n, k)| (n[0] * p[0] + n[1] * p[1] - k).powi(2))
        .sum::<f64>()
        / m)
        .sqrt();
    Some((p, rms))
}

/// The pixel (row, col) of a vanishing direction (either sign) in the image `cal` describes:
/// the sign whose pixel is in the field of view, else any the model can project (a vanishing
/// point outside the image still has a pixel position).
pub fn vanishing_pixel(cal: &Calibration, dir: &Vector3<f64>) -> Option<[f64; 2]> {
    cal.direction_to_pixel(dir)
        .or_else(|| [*dir, -*dir].iter().find_map(|d| cal.model.world2cam(d)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(first: usize, end: usize, f: impl Fn(f64) -> f64) -> ScanCurve {
        ScanCurve {
            first_row: first,
            cols: (first..end).map(|r| f(r as f64)).collect(),
        }
    }

    fn projected(first: usize, end: usize, f: impl Fn(f64) -> f64) -> ProjectedRow {
        ProjectedRow {
            crossings: (first..end).map(|r| (r, f(r as f64))).collect(),
        }
    }

    /// Three rows through (−100, 150), 100 px apart at the bottom (row 199).
    fn fan(offset: f64) -> Vec<Box<dyn Fn(f64) -> f64>> {
        [-100.0, 0.0, 100.0]
            .into_iter()
            .map(|dx| {
                Box::new(move |r: f64| 150.0 + (dx + offset) * (r + 100.0) / 299.0)
                    as Box<dyn Fn(f64) -> f64>
            })
            .collect()
    }

    #[test]
    fn perfect_rows_score_one_and_shifted_rows_less() {
        let labels: Vec<ScanCurve> = fan(0.0).into_iter().map(|f| line(50, 200, f)).collect();
        let exact: Vec<ProjectedRow> = fan(0.0).into_iter().map(|f| projected(0, 200, f)).collect();
        let o = ScoreOptions::default();
        let s = ImageScore::compute(&labels, &exact, &o);
        assert_eq!((s.labelled, s.published, s.inside, s.matched), (3, 3, 3, 3));
        assert!((s.score.unwrap() - 1.0).abs() < 1e-12);
        // Shifted by 5 % of the spacing: found, score 1 − 0.5² on every line.
        let shifted: Vec<ProjectedRow> =
            fan(5.0).into_iter().map(|f| projected(0, 200, f)).collect();
        let s = ImageScore::compute(&labels, &shifted, &o);
        assert_eq!(s.matched, 3);
        assert!((s.score.unwrap() - 0.75).abs() < 0.01, "{:?}", s.score);
        // Shifted by 30 %: none found; and an extra row inside the band lowers the score.
        let far: Vec<ProjectedRow> = fan(30.0)
            .into_iter()
            .map(|f| projected(0, 200, f))
            .collect();
        let s = ImageScore::compute(&labels, &far, &o);
        assert_eq!((s.matched, s.score), (0, Some(0.0)));
        let mut extra = exact.clone();
        extra.push(projected(0, 200, |r| 150.0 + 50.0 * (r + 100.0) / 299.0));
        // and one far outside the labelled band, which does not count
        extra.push(projected(0, 200, |_| 1000.0));
        let s = ImageScore::compute(&labels, &extra, &o);
        assert_eq!((s.published, s.inside, s.matched), (5, 4, 3));
        assert!((s.score.unwrap() - 0.75).abs() < 1e-12);
    }

    #[test]
    fn a_row_through_the_wrong_vanishing_point_misses_at_the_top() {
        let labels: Vec<ScanCurve> = fan(0.0).into_iter().map(|f| line(50, 200, f)).collect();
        // The outer rows through a point 12 px right of the labels' vanishing point (row
        // −100), each through its labelled row's foot on row 199: off by 6 px on row 50,
        // where the tolerance is ¼ of the 50 px spacing, and exact at the bottom: found.
        let tilted =
            |dx: f64| move |r: f64| 150.0 + dx * (r + 100.0) / 299.0 + 12.0 * (199.0 - r) / 299.0;
        let rows = vec![
            projected(0, 200, tilted(-100.0)),
            projected(0, 200, &fan(0.0)[1]),
            projected(0, 200, tilted(100.0)),
        ];
        let s = ImageScore::compute(&labels, &rows, &ScoreOptions::default());
        assert_eq!(s.matches, vec![Some(0), Some(1), Some(2)]);
        for f in &s.fits {
            assert!(
                f.found && f.within == 1.0 && f.worst_third().is_none(),
                "{f:?}"
            );
        }
        // Off by 40 px on row 50 and 0 on row 199: beyond the tolerance (¼ of a spacing
        // growing from 50 to 100 px) above row 128, so missed in the top third and part of
        // the middle one.
        let steep =
            |dx: f64| move |r: f64| 150.0 + dx * (r + 100.0) / 299.0 + 40.0 * (199.0 - r) / 149.0;
        let rows = vec![
            projected(0, 200, steep(-100.0)),
            projected(0, 200, &fan(0.0)[1]),
        ];
        let s = ImageScore::compute(&labels, &rows, &ScoreOptions::default());
        assert_eq!(s.matches, vec![None, Some(1), None]);
        let f = s.fits[0];
        assert!(!f.found && (f.within - 72.0 / 150.0).abs() < 1e-12, "{f:?}");
        assert_eq!(f.misses_top_middle_bottom, [50, 28, 0]);
        assert_eq!(f.worst_third(), Some(0));
        // No row near the third label: every scan line is a miss, in equal thirds.
        assert_eq!(s.fits[2].misses_top_middle_bottom, [50, 50, 50]);
        assert_eq!(s.fits[2].within, 0.0);
    }

    #[test]
    fn a_duplicate_finds_nothing_more() {
        let labels: Vec<ScanCurve> = fan(0.0).into_iter().map(|f| line(50, 200, f)).collect();
        let f = &fan(0.0)[1];
        let rows = vec![projected(0, 200, f), projected(0, 200, f)];
        let s = ImageScore::compute(&labels, &rows, &ScoreOptions::default());
        assert_eq!((s.matched, s.inside), (1, 2));
        assert_eq!(s.matches, vec![None, Some(0), None]);
    }

    #[test]
    fn one_labelled_row_has_no_spacing() {
        let labels = vec![line(0, 100, |_| 50.0)];
        let s = ImageScore::compute(
            &labels,
            &[projected(0, 100, |_| 50.0)],
            &ScoreOptions::default(),
        );
        assert_eq!(s.score, None);
        assert_eq!(s.matched, 0);
    }

    #[test]
    fn spacing_where_a_row_has_no_neighbour_comes_from_the_fit() {
        // Two rows 40 px apart on rows 100..200, one of them continuing alone to row 0.
        let labels = vec![line(0, 200, |_| 100.0), line(100, 200, |_| 140.0)];
        let sp = spacings(&labels).unwrap();
        assert_eq!(sp[0][150], 40.0);
        assert_eq!(sp[0][10], 40.0);
        assert_eq!(sp[1][0], 40.0);
    }

    #[test]
    fn labels_vanishing_point_is_the_rows_intersection() {
        let labels: Vec<ScanCurve> = fan(0.0).into_iter().map(|f| line(50, 200, f)).collect();
        let (p, rms) = labels_vanishing_point(&labels, &ScoreOptions::default()).unwrap();
        assert!(
            (p[0] + 100.0).abs() < 1e-6 && (p[1] - 150.0).abs() < 1e-6,
            "{p:?}"
        );
        assert!(rms < 1e-6);
        // Parallel rows have none, nor a single row.
        let par = vec![line(0, 100, |_| 10.0), line(0, 100, |_| 50.0)];
        assert!(labels_vanishing_point(&par, &ScoreOptions::default()).is_none());
        assert!(labels_vanishing_point(&labels[..1], &ScoreOptions::default()).is_none());
    }

    #[test]
    fn segment_crossings_count_each_scan_line_once() {
        let mut out = Vec::new();
        push_crossings([0.5, 10.0], [3.0, 20.0], 100, &mut out);
        push_crossings([3.0, 20.0], [5.0, 20.0], 100, &mut out);
        let rows: Vec<usize> = out.iter().map(|c| c.0).collect();
        assert_eq!(rows, vec![1, 2, 3, 4]);
        assert!((out[0].1 - 12.0).abs() < 1e-12);
    }
}
