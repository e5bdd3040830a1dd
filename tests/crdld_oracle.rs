//! The ceiling of the CRDLD metric (issue 13), ignored by default:
//! `cargo test --release --test crdld_oracle -- --ignored --nocapture`.
//!
//! The oracle publishes, for every labelled row, the straight line fitted to it (over the
//! whole row, and over its near half only) and scores it with `omnirow eval real`'s metric
//! at f = 300 px (a run's missed rows are sorted by `omnirow eval real` itself: its
//! `label_fits`, docs/real.md). The images are read from `CRDLD` (a folder), else
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
}
