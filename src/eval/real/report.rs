//! The report of `omnirow eval real`: the summary and the worst images as Markdown, the
//! outcomes as JSON lines, and overlays of the worst images (labels green, published rows in
//! their method's colour, the labels' vanishing point as a green cross and the detector's in
//! yellow).

use super::{labels, Decoded, RealEvalOptions, RealOutcome, RealResults};
use crate::detect::overlay::draw_overlay;
use crate::detect::{Detection, Method, Row, VanishingPoint};
use crate::eval::report::ReportError;
use crate::eval::stats::quantile;
use nalgebra::Vector3;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Colour of the labelled rows and of the labels' vanishing point in the overlays.
pub const LABEL_COLOUR: [u8; 3] = [40, 230, 40];

/// The figures of a run (docs/real.md defines each).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Summary {
    pub images: usize,
    /// Images with an error (unreadable image or label, detector error).
    pub errors: usize,
    /// Images with a row-position score (labels with a row spacing).
    pub scored: usize,
    /// Images where the detector published no row / no vanishing point.
    pub no_rows: usize,
    pub no_vp: usize,
    pub labelled: usize,
    pub inside: usize,
    pub matched: usize,
    pub recall: f64,
    pub precision: f64,
    pub score_mean: f64,
    pub score_median: f64,
    /// Images with a vanishing-point error, and its median, mean and 90th percentile (px).
    pub vp_n: usize,
    pub vp_median_px: f64,
    pub vp_mean_px: f64,
    pub vp_p90_px: f64,
    pub ms_median: f64,
    pub ms_p90: f64,
    /// Labelled rows not found (of images with a score), by how near the closest published
    /// row came: within tolerance on under 0.3 of the row's scan lines, 0.3–0.6, and 0.6 up
    /// to the found fraction ...
    pub missed: [usize; 3],
    /// ... and of the last, those whose misses lie mostly in the top, middle, bottom third.
    pub nearly_missed_where: [usize; 3],
    /// The ceilings (docs/real.md, "Ceilings"): each labelled row's own best great circle,
    /// the best through the detector's vanishing point, the best through the labels'.
    pub ceilings: [CeilingFigures; 3],
    /// The images where the strips' measure was read at both points (`vp_agreement`), and
    /// of those whose vanishing point is more than [`FAR_VP_PX`] off: how many, those where
    /// the measure prefers the detector's point, and those where the search missed a higher
    /// summit near the labels'.
    pub vp_read: usize,
    pub far_vp: [usize; 3],
}

/// A vanishing point this far from the labels' (pixels) counts as far off in the report's
/// "search or measure" table.
pub const FAR_VP_PX: f64 = 20.0;

/// One ceiling over the scored images where it exists: those images, their labelled rows,
/// the rows the ceiling finds and those the detector found there.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CeilingFigures {
    pub images: usize,
    pub labelled: usize,
    pub found: usize,
    pub detector_found: usize,
}

impl CeilingFigures {
    fn of<'a>(outcomes: impl Iterator<Item = (&'a RealOutcome, Option<usize>)>) -> Self {
        let mut f = CeilingFigures::default();
        for (o, found) in outcomes {
            if let Some(found) = found {
                f.images += 1;
                f.labelled += o.labelled_rows;
                f.found += found;
                f.detector_found += o.matched_rows;
            }
        }
        f
    }
}

impl Summary {
    pub fn of(outcomes: &[RealOutcome]) -> Self {
        let ok: Vec<&RealOutcome> = outcomes.iter().filter(|o| o.error.is_none()).collect();
        let scores: Vec<f64> = ok.iter().filter_map(|o| o.score).collect();
        let vp: Vec<f64> = ok.iter().filter_map(|o| o.vp_error_px).collect();
        let ms: Vec<f64> = ok.iter().map(|o| o.detect_ms).collect();
        let labelled = ok
            .iter()
            .filter(|o| o.score.is_some())
            .map(|o| o.labelled_rows)
            .sum();
        let inside = ok.iter().map(|o| o.inside_rows).sum();
        let matched = ok.iter().map(|o| o.matched_rows).sum();
        let ratio = |a: usize, b: usize| if b > 0 { a as f64 / b as f64 } else { f64::NAN };
        let (mut missed, mut nearly_missed_where) = ([0; 3], [0; 3]);
        let scored_fits = ok.iter().filter(|o| o.score.is_some());
        for f in scored_fits.flat_map(|o| &o.label_fits).filter(|f| !f.found) {
            let bin = if f.within < 0.3 {
                0
            } else if f.within < 0.6 {
                1
            } else {
                2
            };
            missed[bin] += 1;
            if let (2, Some(t)) = (bin, f.worst_third()) {
                nearly_missed_where[t] += 1;
            }
        }
        let scored = || ok.iter().copied().filter(|o| o.score.is_some());
        let ceilings = [
            CeilingFigures::of(scored().map(|o| (o, Some(o.ceiling.free)))),
            CeilingFigures::of(scored().map(|o| (o, o.ceiling.detected_vp))),
            CeilingFigures::of(scored().map(|o| (o, o.ceiling.labels_vp))),
        ];
        let vp_read = ok.iter().filter(|o| o.vp_agreement.is_some()).count();
        let mut far_vp = [0; 3];
        let far = ok
            .iter()
            .filter(|o| o.vp_error_px.is_some_and(|e| e > FAR_VP_PX));
        for a in far.filter_map(|o| o.vp_agreement) {
            far_vp[0] += 1;
            far_vp[if a.search_missed() { 2 } else { 1 }] += 1;
        }
        Summary {
            images: outcomes.len(),
            errors: outcomes.len() - ok.len(),
            scored: scores.len(),
            no_rows: ok.iter().filter(|o| o.published_rows == 0).count(),
            no_vp: ok.iter().filter(|o| o.vanishing_point.is_none()).count(),
            labelled,
            inside,
            matched,
            recall: ratio(matched, labelled),
            precision: ratio(matched, inside),
            score_mean: mean(&scores),
            score_median: quantile(&scores, 0.5),
            vp_n: vp.len(),
            vp_median_px: quantile(&vp, 0.5),
            vp_mean_px: mean(&vp),
            vp_p90_px: quantile(&vp, 0.9),
            ms_median: quantile(&ms, 0.5),
            ms_p90: quantile(&ms, 0.9),
            missed,
            nearly_missed_where,
            ceilings,
            vp_read,
            far_vp,
        }
    }
}

fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

/// Indices of the `n` worst outcomes: errors first, then the lowest scores.
pub fn worst(outcomes: &[RealOutcome], n: usize) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..outcomes.len()).collect();
    let key = |o: &RealOutcome| match (&o.error, o.score) {
        (Some(_), _) => -1.0,
        (None, Some(s)) => s,
        (None, None) => 2.0,
    };
    idx.sort_by(|&a, &b| key(&outcomes[a]).total_cmp(&key(&outcomes[b])));
    idx.truncate(n);
    idx
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map(|x| format!("{x:.digits$}"))
        .unwrap_or_else(|| "–".into())
}

/// The Markdown report: the summary table, then the worst images.
pub fn markdown(r: &RealResults, command: &str, worst_n: usize) -> String {
    let s = Summary::of(&r.outcomes);
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# omnirow eval real\n\nProduced by `{command}` (method {}{}). Metrics: docs/real.md.\n",
        r.method.name(),
        if r.requested == Method::Auto && r.method != Method::Auto {
            ", by auto for this calibration"
        } else {
            ""
        }
    );
    let _ = writeln!(
        md,
        "| images | errors | scored | labelled rows | found | recall | published in band | precision | score mean | score median | no rows | no VP |\n|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    let _ = writeln!(
        md,
        "| {} | {} | {} | {} | {} | {:.3} | {} | {:.3} | {:.3} | {:.3} | {} | {} |\n",
        s.images,
        s.errors,
        s.scored,
        s.labelled,
        s.matched,
        s.recall,
        s.inside,
        s.precision,
        s.score_mean,
        s.score_median,
        s.no_rows,
        s.no_vp
    );
    let _ = writeln!(
        md,
        "| VP error: images | median (px) | mean (px) | 90th percentile (px) | detector median (ms) | detector p90 (ms) |\n|---|---|---|---|---|---|"
    );
    let _ = writeln!(
        md,
        "| {} | {:.1} | {:.1} | {:.1} | {:.2} | {:.2} |\n",
        s.vp_n, s.vp_median_px, s.vp_mean_px, s.vp_p90_px, s.ms_median, s.ms_p90
    );
    let [m0, m1, m2] = s.missed;
    let [top, middle, bottom] = s.nearly_missed_where;
    let _ = writeln!(
        md,
        "Labelled rows not found, by the share of their scan lines on which the nearest published row lies within tolerance (`label_fits` in outcomes.jsonl; docs/real.md):\n\n| under 0.3 | 0.3 to 0.6 | 0.6 and over | of those, misses mostly in the top third | middle third | bottom third |\n|---|---|---|---|---|---|"
    );
    let _ = writeln!(md, "| {m0} | {m1} | {m2} | {top} | {middle} | {bottom} |\n");
    let _ = writeln!(
        md,
        "What the rows could at best find (docs/real.md, \"Ceilings\"): every labelled row published as the great circle that fits it best, free or through a vanishing point, on the scored images where that point exists; beside it the detector's recall on the same images:\n\n| rows | images | labelled rows | found | recall | the detector's recall there |\n|---|---|---|---|---|---|"
    );
    let names = [
        "each row's own best circle",
        "best through the detector's vanishing point",
        "best through the labels' vanishing point",
    ];
    for (name, c) in names.iter().zip(&s.ceilings) {
        let ratio = |a: usize| {
            if c.labelled > 0 {
                format!("{:.3}", a as f64 / c.labelled as f64)
            } else {
                "–".into()
            }
        };
        let _ = writeln!(
            md,
            "| {name} | {} | {} | {} | {} | {} |",
            c.images,
            c.labelled,
            c.found,
            ratio(c.found),
            ratio(c.detector_found)
        );
    }
    md.push('\n');
    if s.vp_read > 0 {
        let [n, measure, search] = s.far_vp;
        let _ = writeln!(
            md,
            "Whose fault a far-off vanishing point is: the strips' measure (docs/real.md, \"Search or measure\"; `vp_agreement` in outcomes.jsonl) at the summit nearest the labels' point against the search's answer, on the images where both were read:\n\n| images | more than {FAR_VP_PX} px off | the measure prefers the detector's point | the search missed a higher summit |\n|---|---|---|---|\n| {} | {n} | {measure} | {search} |\n",
            s.vp_read
        );
    }
    let _ = writeln!(
        md,
        "## The {worst_n} worst images\n\nOverlays in `overlays/`: labelled rows green, published rows in their method's colour, the labels' vanishing point a green cross, the detector's yellow.\n\n| image | score | labelled | found | published in band | published | VP error (px) | error |\n|---|---|---|---|---|---|---|---|"
    );
    for i in worst(&r.outcomes, worst_n) {
        let o = &r.outcomes[i];
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {} | {} |",
            o.image,
            opt(o.score, 3),
            o.labelled_rows,
            o.matched_rows,
            o.inside_rows,
            o.published_rows,
            opt(o.vp_error_px, 1),
            o.error.as_deref().unwrap_or("")
        );
    }
    md
}

/// Writes README.md, outcomes.jsonl and the worst images' overlays into `dir`; returns the
/// files written.
pub fn write(
    r: &RealResults,
    opts: &RealEvalOptions,
    dir: &Path,
    command: &str,
    worst_n: usize,
) -> Result<Vec<PathBuf>, ReportError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| ReportError { path, source }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let md = dir.join("README.md");
    std::fs::write(&md, markdown(r, command, worst_n)).map_err(io(&md))?;
    let jl = dir.join("outcomes.jsonl");
    let mut lines = String::new();
    for o in &r.outcomes {
        lines.push_str(&serde_json::to_string(o).map_err(|e| io(&jl)(e.into()))?);
        lines.push('\n');
    }
    std::fs::write(&jl, lines).map_err(io(&jl))?;
    let mut written = vec![md, jl];
    let ov = dir.join("overlays");
    std::fs::create_dir_all(&ov).map_err(io(&ov))?;
    for i in worst(&r.outcomes, worst_n) {
        let o = &r.outcomes[i];
        let stem = Path::new(&o.image)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| format!("image-{i}"));
        let file = ov.join(format!("{stem}.png"));
        // An image that cannot be drawn (unreadable) has its error in the table already.
        if let Ok(rgb) = overlay(r, opts, o) {
            rgb.save(&file)
                .map_err(|e| io(&file)(std::io::Error::other(e)))?;
            written.push(file);
        }
    }
    Ok(written)
}

/// The overlay of one outcome: the detection drawn by the detector's overlay, the labels on top.
fn overlay(
    r: &RealResults,
    opts: &RealEvalOptions,
    o: &RealOutcome,
) -> Result<image::RgbImage, String> {
    let img = Decoded::open(Path::new(&o.image))?;
    let view = img.view()?;
    let cal = opts.calibration.rescaled_to(img.height, img.width)?;
    let det = Detection {
        rows: o
            .rows
            .iter()
            .map(|n| Row {
                normal: Vector3::from(*n),
                method: r.method,
                support: 0,
                width_rad: 0.0,
            })
            .collect(),
        vanishing_point: o.vanishing_point.map(|d| VanishingPoint {
            direction: Vector3::from(d),
            inliers: 0,
            residual_rad: 0.0,
        }),
        ..Default::default()
    };
    let mut rgb = Vec::new();
    draw_overlay(&view, &cal, &det, &mut rgb).map_err(|e| e.to_string())?;
    let mut out = image::RgbImage::from_raw(img.width, img.height, rgb)
        .ok_or_else(|| "overlay buffer size".to_string())?;
    if let Some(label) = &o.label {
        let rows = labels::load(
            Path::new(label),
            img.height as usize,
            img.width as usize,
            &opts.tracing,
        )
        .map_err(|e| e.to_string())?;
        for p in rows.iter().flat_map(|c| c.points().collect::<Vec<_>>()) {
            put(&mut out, p, LABEL_COLOUR);
        }
    }
    if let Some(p) = o.vp_labels_px {
        for k in -8..=8 {
            let k = k as f64;
            put(&mut out, [p[0] + k, p[1]], LABEL_COLOUR);
            put(&mut out, [p[0], p[1] + k], LABEL_COLOUR);
        }
    }
    Ok(out)
}

fn put(img: &mut image::RgbImage, p: [f64; 2], colour: [u8; 3]) {
    let (r, c) = (p[0].round(), p[1].round());
    if r >= 0.0 && c >= 0.0 && (r as u32) < img.height() && (c as u32) < img.width() {
        img.put_pixel(c as u32, r as u32, image::Rgb(colour));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn outcome(score: Option<f64>, error: Option<&str>) -> RealOutcome {
        let mut o = RealOutcome::new(Path::new("x.jpg"));
        o.score = score;
        o.error = error.map(String::from);
        o.labelled_rows = 3;
        o.inside_rows = 2;
        o.matched_rows = 2;
        o.published_rows = 2;
        o
    }

    #[test]
    fn summary_pools_rows_and_skips_errors() {
        let v = vec![
            outcome(Some(0.5), None),
            outcome(Some(1.0), None),
            outcome(None, Some("bad")),
        ];
        let s = Summary::of(&v);
        assert_eq!((s.images, s.errors, s.scored), (3, 1, 2));
        assert_eq!((s.labelled, s.matched, s.inside), (6, 4, 4));
        assert!((s.recall - 4.0 / 6.0).abs() < 1e-12);
        assert_eq!(s.precision, 1.0);
        assert_eq!(s.score_mean, 0.75);
        assert_eq!(worst(&v, 2), vec![2, 0]);
    }

    #[test]
    fn far_vanishing_points_are_put_down_to_the_search_or_the_measure() {
        let with = |err: f64, labels: f64, away: f64| {
            let mut o = outcome(Some(0.5), None);
            o.vp_error_px = Some(err);
            o.vp_agreement = Some(super::super::VpAgreement {
                search: 1.0,
                labels,
                labels_summit_from_search_px: away,
            });
            o
        };
        let mut near_without = outcome(Some(0.5), None);
        near_without.vp_error_px = Some(50.0);
        let v = vec![
            with(5.0, 2.0, 40.0),  // near the labels: not counted
            with(30.0, 2.0, 40.0), // a higher summit elsewhere: the search missed it
            with(30.0, 0.5, 40.0), // lower: the measure prefers the detector's point
            with(30.0, 1.01, 1.0), // the search's own summit, climbed to from the labels'
            near_without,          // no agreement read: not counted
        ];
        let s = Summary::of(&v);
        assert_eq!((s.vp_read, s.far_vp), (4, [3, 2, 1]));
        let r = RealResults {
            outcomes: v,
            method: Method::Strips,
            requested: Method::Auto,
        };
        let md = markdown(&r, "omnirow eval real", 2);
        assert!(md.contains("| 4 | 3 | 2 | 1 |"), "{md}");
    }
}
