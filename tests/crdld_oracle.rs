//! The ceiling of the CRDLD metric and the classes of a run's misses (issue 13), ignored by
//! default: `cargo test --release --test crdld_oracle -- --ignored --nocapture`.
//!
//! The oracle publishes, for every labelled row, the straight line fitted to it (over the
//! whole row, and over its near half only) and scores it with `omnirow eval real`'s metric
//! at f = 300 px. With `OUTCOMES=path/outcomes.jsonl` (a run of `omnirow eval real` on CRDLD
//! at f = 300 px) it also sorts that run's missed labelled rows into: not found (no published
//! row within ¼ spacing on half of the row's scan lines), off (within ¼ spacing on 50–90 %
//! of them; and how many of those miss mostly in the far half), and counts the false rows
//! inside the labelled band. The images are read from `CRDLD` (a folder), else
//! ../shared/real-fields/crdld; the test skips with a message when they are absent.
use nalgebra::Vector3;
use omnirow::camera::Calibration;
use omnirow::eval::real::{labels, ImageScore, ProjectedRow, ScanCurve, ScoreOptions};
use std::path::Path;

fn line_normal(cal: &Calibration, l: &ScanCurve, frac_lo: f64) -> Vector3<f64> {
    // x = a + b y least squares over the part of the row from frac_lo (0 = top) to the bottom.
    let pts: Vec<[f64; 2]> = l.points().collect();
    let n = pts.len();
    let start = ((n as f64) * frac_lo) as usize;
    let p = &pts[start..];
    let m = p.len() as f64;
    let (sy, sx) = p.iter().fold((0.0, 0.0), |a, q| (a.0 + q[0], a.1 + q[1]));
    let (my, mx) = (sy / m, sx / m);
    let (mut syy, mut sxy) = (0.0, 0.0);
    for q in p {
        syy += (q[0] - my).powi(2);
        sxy += (q[0] - my) * (q[1] - mx);
    }
    let b = if syy > 0.0 { sxy / syy } else { 0.0 };
    let (y0, y1) = (pts[0][0], pts[n - 1][0]);
    let r0 = cal.model.cam2world(y0, mx + b * (y0 - my));
    let r1 = cal.model.cam2world(y1, mx + b * (y1 - my));
    r0.cross(&r1).normalize()
}

/// The labelled rows of CRDLD image `name` (512 × 512).
fn load_labels(d: &Path, name: &str) -> Vec<ScanCurve> {
    labels::load(
        &d.join(format!("label/{name}.jpg")),
        512,
        512,
        &Default::default(),
    )
    .unwrap()
}

#[test]
#[ignore]
fn oracle_and_classes() {
    let d = std::env::var("CRDLD").map_or_else(
        |_| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/real-fields/crdld"),
        std::path::PathBuf::from,
    );
    if !d.join("label").is_dir() {
        eprintln!("skipped: no CRDLD labels at {} (set CRDLD)", d.display());
        return;
    }
    let cal = Calibration::load(Path::new(&format!(
        "{}/config/calib/pinhole_512_f300.toml",
        env!("CARGO_MANIFEST_DIR")
    )))
    .unwrap();
    let opts = ScoreOptions::default();
    for frac in [0.0, 0.5] {
        // frac: the fit starts this far down the row (0 = the whole row, 0.5 = its near half).
        let (mut lab, mut found, mut inside, mut sc, mut ns) = (0, 0, 0, 0.0, 0);
        for i in 0..500 {
            let l = load_labels(&d, &i.to_string());
            let rows: Vec<ProjectedRow> = l
                .iter()
                .map(|c| ProjectedRow::project(&cal, &line_normal(&cal, c, frac)))
                .collect();
            let s = ImageScore::compute(&l, &rows, &opts);
            if let Some(x) = s.score {
                lab += s.labelled;
                found += s.matched;
                inside += s.inside;
                sc += x;
                ns += 1;
            }
        }
        println!(
            "oracle fit from {frac}: recall {:.3} precision {:.3} score {:.3}",
            found as f64 / lab as f64,
            found as f64 / inside as f64,
            sc / ns as f64
        );
    }
    // Classes of the detector's misses from an outcomes.jsonl.
    let Ok(out) = std::env::var("OUTCOMES") else {
        return;
    };
    let text = std::fs::read_to_string(out).unwrap();
    let (mut lab, mut notfound, mut off, mut found, mut falses, mut inside) = (0, 0, 0, 0, 0, 0);
    let mut off_far = 0;
    for line in text.lines() {
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        let img = v["image"].as_str().unwrap();
        let name = Path::new(img).file_stem().unwrap().to_str().unwrap();
        let l = load_labels(&d, name);
        let rows: Vec<ProjectedRow> = v["rows"]
            .as_array()
            .unwrap()
            .iter()
            .map(|n| {
                let a = n.as_array().unwrap();
                ProjectedRow::project(
                    &cal,
                    &Vector3::new(
                        a[0].as_f64().unwrap(),
                        a[1].as_f64().unwrap(),
                        a[2].as_f64().unwrap(),
                    ),
                )
            })
            .collect();
        let s = ImageScore::compute(&l, &rows, &opts);
        let Some(sp) = omnirow::eval::real::score::spacings(&l) else {
            continue;
        };
        lab += s.labelled;
        found += s.matched;
        inside += s.inside;
        falses += s.inside.saturating_sub(s.matched);
        for (li, c) in l.iter().enumerate() {
            if s.matches[li].is_some() {
                continue;
            }
            // best within-fraction over published rows, and where the misses lie
            let mut best = (0.0, 0.0);
            for p in &rows {
                let (mut w, mut n, mut wtop) = (0usize, 0usize, 0usize);
                let npts = c.cols.len();
                for (k, ([r, col], &g)) in c.points().zip(&sp[li]).enumerate() {
                    n += 1;
                    match p.nearest_col(r as usize, col) {
                        Some(x) if (x - col).abs() <= 0.25 * g => w += 1,
                        _ => {
                            if k < npts / 2 {
                                wtop += 1
                            }
                        }
                    }
                }
                let f = w as f64 / n.max(1) as f64;
                if f > best.0 {
                    best = (f, wtop as f64 / (n - w).max(1) as f64);
                }
            }
            if best.0 >= 0.5 {
                off += 1;
                if best.1 > 0.5 {
                    off_far += 1;
                }
            } else {
                notfound += 1;
            }
        }
    }
    println!("labelled {lab} found {found} not-found(<50% lines) {notfound} off(50-90% lines) {off} (of which misses mostly far half {off_far}); inside {inside} false-inside {falses}");
}
