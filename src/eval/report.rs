//! Writes an evaluation's results: Markdown tables beside the paper's figures, PNG plots of
//! the detection rate against plant distance, and the raw outcomes as JSON lines.

use super::chart::{Chart, Kind, Series};
use super::run::{EvalResults, Experiment};
use crate::camera::IdealLens;
use crate::detect::Method;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The paper's Table I: mean (mrad), max (mrad), variance (1e-8 rad²).
pub const PAPER_TABLE1: [(Method, f64, f64, f64); 3] = [
    (Method::Edge, 0.12, 1.8, 7.9),
    (Method::Hough, 0.036, 0.17, 0.13),
    (Method::Combined, 0.029, 0.35, 0.23),
];

/// The paper's Table II failures: fisheye, omni.
pub const PAPER_TABLE2: [(Method, usize, usize); 3] = [
    (Method::Edge, 30, 27),
    (Method::Hough, 18, 48),
    (Method::Combined, 15, 23),
];

/// An error writing the report.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {source}")]
pub struct ReportError {
    pub path: PathBuf,
    #[source]
    pub source: std::io::Error,
}

fn colour(m: Method) -> [u8; 3] {
    match m {
        Method::Edge => [30, 80, 220],
        Method::Hough => [220, 40, 40],
        Method::Combined | Method::Auto => [20, 150, 60],
        Method::Pencil => [230, 140, 0],
        Method::Strips => [0, 170, 230],
    }
}

/// Table I again on the same scenes drawn by the second appearance model, beside the first's
/// mean error (issue 13's target: within 1.5×).
fn table1_leafy(s: &mut String, r: &EvalResults) {
    if !r
        .outcomes
        .iter()
        .any(|o| o.experiment == Experiment::Table1Leafy)
    {
        return;
    }
    let _ = writeln!(
        s,
        "\n### Table I on the second appearance model\n\nThe same scenes drawn by the independently designed `leafy` renderer (leaf clusters of random shape and size, supersampled, uneven light, lens blur, Bayer mosaic demosaiced, JPEG; `omnirow synth --style leafy`).\n\n| method | found | mean error (1e-3 rad) | max error (1e-3 rad) | variance (1e-8 rad²) | mean / first appearance's |\n|---|---|---|---|---|---|"
    );
    for &m in &r.methods {
        let a = r.accuracy_in(Experiment::Table1Leafy, m);
        let first = r.accuracy(m).errors.mean;
        let _ = writeln!(
            s,
            "| {} | {}/{} | {:.4} | {:.3} | {:.3} | {:.2} |",
            m.name(),
            a.found,
            a.images,
            a.errors.mean * 1e3,
            a.errors.max * 1e3,
            a.errors.variance * 1e8,
            a.errors.mean / first
        );
    }
}

/// The Markdown report (all tables).
pub fn markdown(r: &EvalResults, command: &str) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# omnirow evaluation\n\nProduced by `{command}`.\n");
    let _ = writeln!(
        s,
        "## Table I: accuracy of the vanishing point\n\nAngle between the found and the true vanishing point, over the images where it was found within {}°. Paper's figures in brackets.\n",
        r.pass_deg
    );
    let _ = writeln!(
        s,
        "| method | found | mean error (1e-3 rad) | max error (1e-3 rad) | variance (1e-8 rad²) |\n|---|---|---|---|---|"
    );
    for &m in &r.methods {
        let a = r.accuracy(m);
        let paper = PAPER_TABLE1.iter().find(|p| p.0 == m);
        let p = |i: usize| {
            paper
                .map(|p| format!(" ({})", [p.1, p.2, p.3][i]))
                .unwrap_or_default()
        };
        let _ = writeln!(
            s,
            "| {} | {}/{} | {:.4}{} | {:.3}{} | {:.3}{} |",
            m.name(),
            a.found,
            a.images,
            a.errors.mean * 1e3,
            p(0),
            a.errors.max * 1e3,
            p(1),
            a.errors.variance * 1e8,
            p(2)
        );
    }
    if table1_chart(r).is_some() {
        let _ = writeln!(
            s,
            "\n![Table I: mean error, omnirow's beside the paper's](table1.png)"
        );
    }
    table1_leafy(&mut s, r);
    let _ = writeln!(
        s,
        "\n## Figures 8 and 9: detection rate against plant distance\n\nCorrect rows / rows found. A row is correct when its great circle passes within 1° of the true vanishing point and its normal lies within 3° of a visible row's.\n"
    );
    for (l, name) in r.lens_names.iter().enumerate() {
        let _ = write!(s, "**{name}**\n\n| plant distance (m) |");
        for &m in &r.methods {
            let _ = write!(s, " {} |", m.name());
        }
        let _ = write!(s, "\n|---|");
        for _ in &r.methods {
            let _ = write!(s, "---|");
        }
        let _ = writeln!(s);
        let rates: Vec<Vec<(f64, f64)>> =
            r.methods.iter().map(|&m| r.detection_rate(l, m)).collect();
        for (i, &d) in r.plant_distances.iter().enumerate() {
            let _ = write!(s, "| {d} |");
            for rate in &rates {
                let _ = write!(s, " {:.2} |", rate[i].1);
            }
            let _ = writeln!(s);
        }
        let _ = writeln!(
            s,
            "\n![detection rate, {name}](detection_rate_{name}.png)\n"
        );
    }
    let _ = writeln!(
        s,
        "## Table II: failures (vanishing point more than {}° from the truth, or none)\n\nRandom scenes under heavy noise, as the paper's \"a lot of failures\": background noise density 0.1..0.6, plant distance 0.03..0.25 m, plant position error along the row 0..0.05 m (sd) and across it (the row-distance error, which bends the rows) 0..0.05 m (sd), 0..800 weeds within ±5 m, yaw ±30°, pitch ±10°, roll ±3°. Paper's figures in brackets (fisheye, omni; its image count is not stated).\n",
        r.pass_deg
    );
    let _ = write!(s, "| method |");
    for name in &r.lens_names {
        let _ = write!(s, " {name} |");
    }
    let _ = writeln!(s, " sum |");
    let _ = write!(s, "|---|");
    for _ in &r.lens_names {
        let _ = write!(s, "---|");
    }
    let _ = writeln!(s, "---|");
    for &m in &r.methods {
        let _ = write!(s, "| {} |", m.name());
        let mut sum = (0, 0);
        for l in 0..r.lens_names.len() {
            let c = r.failures(l, m);
            sum.0 += c.failures;
            sum.1 += c.images;
            let _ = write!(s, " {}/{} |", c.failures, c.images);
        }
        let paper = PAPER_TABLE2
            .iter()
            .find(|p| p.0 == m)
            .map(|p| format!(" ({}, {})", p.1, p.2))
            .unwrap_or_default();
        let _ = writeln!(s, " {}/{}{} |", sum.0, sum.1, paper);
    }
    table2_bounds(r, &mut s);
    if table2_chart(r).is_some() {
        let _ = writeln!(
            s,
            "\n![Table II: failures per 100 images, omnirow's beside the paper's counts](table2.png)"
        );
    }
    let _ = writeln!(
        s,
        "\n## Speed\n\nDetector time per image (not counting rendering), over every image of the run.\n\n| method | median (ms) | p99 (ms) |\n|---|---|---|"
    );
    for &m in &r.methods {
        let (p50, p99) = r.speed(m);
        let _ = writeln!(s, "| {} | {p50:.1} | {p99:.1} |", m.name());
    }
    s
}

/// Table II's last row and notes: the images both single methods fail (what no choice
/// between their answers can pass), where the combined method differs from each, and how
/// to render any image again.
fn table2_bounds(r: &EvalResults, s: &mut String) {
    let n = r.lens_names.len();
    let floor: Option<Vec<usize>> = (0..n)
        .map(|l| r.all_fail(l, &[Method::Edge, Method::Hough]))
        .collect();
    if let Some(floor) = floor {
        let _ = write!(s, "| edge and hough both fail |");
        for f in &floor {
            let _ = write!(s, " {f} |");
        }
        let _ = writeln!(s, " {} |", floor.iter().sum::<usize>());
        let _ = writeln!(
            s,
            "\nThe last row is a floor for any combination that picks between the two methods' answers image by image: on those images neither answer passes, so only evidence that neither method finds alone can pass them."
        );
    }
    let singles: Vec<Method> = [Method::Hough, Method::Edge]
        .into_iter()
        .filter(|m| r.methods.contains(m))
        .collect();
    if r.methods.contains(&Method::Combined) && !singles.is_empty() {
        let _ = write!(
            s,
            "\nImage by image, combined against each method: images combined passes and the method fails / images combined fails and the method passes.\n\n| against |"
        );
        for name in &r.lens_names {
            let _ = write!(s, " {name} |");
        }
        let _ = write!(s, "\n|---|");
        for _ in 0..n {
            let _ = write!(s, "---|");
        }
        let _ = writeln!(s);
        for single in singles {
            let _ = write!(s, "| {} |", single.name());
            for l in 0..n {
                let _ = write!(
                    s,
                    " {} / {} |",
                    r.passes_where_fails(l, Method::Combined, single),
                    r.passes_where_fails(l, single, Method::Combined)
                );
            }
            let _ = writeln!(s);
        }
    }
    let _ = writeln!(
        s,
        "\nEvery image is in outcomes.jsonl with its seed, noise and weeds; `omnirow synth --lens LENS --random table2 --seed SEED --out image.png --truth truth.json` renders a Table II image again (`--calib FILE` for a calibration file, `--scale K` if the run used one; `--random table1` for Table I)."
    );
}

/// The detection-rate chart for one lens.
pub fn detection_chart(r: &EvalResults, lens: usize) -> Chart {
    Chart {
        title: format!("Detection rate, {}", r.lens_names[lens]),
        x_label: "plant distance (m)".into(),
        y_label: "correct / found".into(),
        x_range: None,
        y_range: Some((0.0, 1.0)),
        series: r
            .methods
            .iter()
            .map(|&m| Series {
                label: m.name().into(),
                colour: colour(m),
                points: r.detection_rate(lens, m),
                kind: Kind::Line,
            })
            .collect(),
        x_categories: Vec::new(),
    }
}

/// The methods of the run that the paper's tables have a figure for, in the run's order.
fn paper_methods(r: &EvalResults) -> Vec<Method> {
    r.methods
        .iter()
        .copied()
        .filter(|m| PAPER_TABLE1.iter().any(|p| p.0 == *m))
        .collect()
}

/// A y range from 0 with room above the highest point for the legend.
fn headroom<'a>(points: impl Iterator<Item = &'a (f64, f64)>) -> (f64, f64) {
    let top = points
        .map(|p| p.1)
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    (0.0, if top > 0.0 { top * 1.5 } else { 1.0 })
}

/// Table I as a chart: the mean angle between the found and the true vanishing point per
/// method, this run's (filled circles) beside the paper's (hollow triangles). `None` when the
/// run has no Table I images or no method the paper reports.
pub fn table1_chart(r: &EvalResults) -> Option<Chart> {
    let methods = paper_methods(r);
    if methods.is_empty() || methods.iter().all(|&m| r.accuracy(m).images == 0) {
        return None;
    }
    let at = |i: usize, dx: f64| i as f64 + dx;
    let ours: Vec<(f64, f64)> = methods
        .iter()
        .enumerate()
        .filter_map(|(i, &m)| {
            let a = r.accuracy(m);
            (a.found > 0).then(|| (at(i, -0.1), a.errors.mean * 1e3))
        })
        .collect();
    let paper: Vec<(f64, f64)> = methods
        .iter()
        .enumerate()
        .filter_map(|(i, &m)| {
            let p = PAPER_TABLE1.iter().find(|p| p.0 == m)?;
            Some((at(i, 0.1), p.1))
        })
        .collect();
    let y_range = Some(headroom(ours.iter().chain(&paper)));
    Some(Chart {
        title: "Table I: mean error of the vanishing point".into(),
        x_label: "method".into(),
        y_label: "mean error (1e-3 rad)".into(),
        x_range: None,
        y_range,
        x_categories: methods.iter().map(|m| m.name().to_string()).collect(),
        series: vec![
            Series {
                label: "omnirow".into(),
                colour: [30, 80, 220],
                points: ours,
                kind: Kind::Markers,
            },
            Series {
                label: "paper (Table I)".into(),
                colour: [20, 20, 20],
                points: paper,
                kind: Kind::Reference,
            },
        ],
    })
}

/// Table II as a chart: failures per method and lens, this run's scaled to 100 images per
/// lens (filled circles) beside the paper's counts (hollow triangles; the paper does not
/// state its image count). `None` when the run has no Table II images.
pub fn table2_chart(r: &EvalResults) -> Option<Chart> {
    let methods = paper_methods(r);
    let lenses = r.lens_names.len().min(2);
    if methods.is_empty()
        || (0..lenses).all(|l| methods.iter().all(|&m| r.failures(l, m).images == 0))
    {
        return None;
    }
    // The paper's lenses as omnirow's built-in models: the fisheye, then the catadioptric
    // ("omni"); the paper's figures are shown only beside those.
    let paper_lenses = [IdealLens::Fisheye185.name(), IdealLens::Pal.name()];
    let lens_colours = [[220, 40, 40], [30, 80, 220]];
    let mut series = Vec::new();
    for (l, &c) in lens_colours.iter().enumerate().take(lenses) {
        let name = &r.lens_names[l];
        let dx = if l == 0 { -0.12 } else { 0.12 };
        series.push(Series {
            label: format!("omnirow, {name} (per 100 images)"),
            colour: c,
            points: methods
                .iter()
                .enumerate()
                .filter_map(|(i, &m)| {
                    let f = r.failures(l, m);
                    (f.images > 0).then(|| {
                        (
                            i as f64 + dx - 0.04,
                            100.0 * f.failures as f64 / f.images as f64,
                        )
                    })
                })
                .collect(),
            kind: Kind::Markers,
        });
        if name != paper_lenses[l] {
            continue;
        }
        series.push(Series {
            label: format!("paper, {} (Table II)", ["fisheye", "omni"][l]),
            colour: c,
            points: methods
                .iter()
                .enumerate()
                .filter_map(|(i, &m)| {
                    let p = PAPER_TABLE2.iter().find(|p| p.0 == m)?;
                    Some((i as f64 + dx + 0.04, [p.1, p.2][l] as f64))
                })
                .collect(),
            kind: Kind::Reference,
        });
    }
    let y_range = Some(headroom(series.iter().flat_map(|s| &s.points)));
    Some(Chart {
        title: "Table II: failures under heavy noise".into(),
        x_label: "method".into(),
        y_label: "failures".into(),
        x_range: None,
        y_range,
        x_categories: methods.iter().map(|m| m.name().to_string()).collect(),
        series,
    })
}

/// Writes `README.md`, one PNG per lens and `outcomes.jsonl` into `dir`.
pub fn write(r: &EvalResults, dir: &Path, command: &str) -> Result<Vec<PathBuf>, ReportError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| ReportError { path, source }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let mut written = Vec::new();
    let md = dir.join("README.md");
    std::fs::write(&md, markdown(r, command)).map_err(io(&md))?;
    written.push(md);
    let mut charts: Vec<(String, Chart)> = r
        .lens_names
        .iter()
        .enumerate()
        .map(|(l, name)| (format!("detection_rate_{name}.png"), detection_chart(r, l)))
        .collect();
    charts.extend(table1_chart(r).map(|c| ("table1.png".to_string(), c)));
    charts.extend(table2_chart(r).map(|c| ("table2.png".to_string(), c)));
    for (file, chart) in charts {
        let png = dir.join(file);
        let other = |e: &dyn std::fmt::Display| ReportError {
            path: png.clone(),
            source: std::io::Error::other(e.to_string()),
        };
        chart
            .render()
            .map_err(|e| other(&e))?
            .save(&png)
            .map_err(|e| other(&e))?;
        written.push(png);
    }
    let jl = dir.join("outcomes.jsonl");
    let mut lines = String::new();
    for o in &r.outcomes {
        let v = serde_json::json!({
            "experiment": format!("{:?}", o.experiment).to_lowercase(),
            "lens": r.lens_names[o.lens],
            "method": o.method.name(),
            "seed": o.seed,
            "plant_distance_m": o.plant_distance_m,
            "noise": o.noise,
            "weeds": o.weeds,
            "vp_error_rad": o.vp_error_rad,
            "rows_found": o.rows_found,
            "rows_correct": o.rows_correct,
            "detect_ms": o.detect_ms,
        });
        lines.push_str(&v.to_string());
        lines.push('\n');
    }
    std::fs::write(&jl, lines).map_err(io(&jl))?;
    written.push(jl);
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::run::Outcome;

    fn outcome(experiment: Experiment, lens: usize, method: Method, err: f64) -> Outcome {
        Outcome {
            experiment,
            lens,
            method,
            seed: 1,
            plant_distance_m: 0.1,
            noise: 0.1,
            weeds: 0,
            vp_error_rad: Some(err),
            rows_found: 4,
            rows_correct: 4,
            detect_ms: 1.0,
        }
    }

    #[test]
    fn table_charts_put_the_papers_figures_beside_the_runs() {
        let mut outcomes = Vec::new();
        for l in 0..2 {
            outcomes.push(outcome(Experiment::Table1, l, Method::Hough, 2e-4));
            outcomes.push(outcome(Experiment::Table2, l, Method::Hough, 1e-4));
            // a failure: 10° off
            outcomes.push(outcome(Experiment::Table2, l, Method::Hough, 0.17));
        }
        let r = EvalResults {
            outcomes,
            lens_names: vec!["fisheye185".into(), "pal".into()],
            methods: vec![Method::Hough, Method::Pencil],
            plant_distances: vec![0.1],
            pass_deg: 1.0,
        };
        let t1 = table1_chart(&r).unwrap();
        // Pencil is not in the paper: one category
        assert_eq!(t1.x_categories, ["hough"]);
        assert_eq!(t1.series[0].kind, Kind::Markers);
        assert!((t1.series[0].points[0].1 - 0.2).abs() < 1e-9);
        assert_eq!(t1.series[1].kind, Kind::Reference);
        assert_eq!(t1.series[1].points[0].1, 0.036);
        let t2 = table2_chart(&r).unwrap();
        let y = |i: usize| t2.series[i].points[0].1;
        // one failure in two images per lens: 50 per 100; the paper's 18 and 48
        assert_eq!((y(0), y(1), y(2), y(3)), (50.0, 18.0, 50.0, 48.0));
        assert_eq!(t2.series[3].kind, Kind::Reference);
        // a lens of the user's own: no paper figure beside it
        let mut own = r.clone();
        own.lens_names[1] = "my_lens".into();
        assert_eq!(table2_chart(&own).unwrap().series.len(), 3);
        // no Table I images: no chart
        let none = EvalResults {
            outcomes: Vec::new(),
            ..r
        };
        assert!(table1_chart(&none).is_none() && table2_chart(&none).is_none());
    }
}
