//! The edge and combined methods on rendered synthetic fields (both shipped lenses), fixed
//! seeds, loose margins: the edge method finds both boundaries of the rows and publishes
//! their centre lines with the rows' widths, the combined method publishes the Hough centre
//! lines (never a boundary), and every method finds the vanishing point.

use nalgebra::Vector3;
use omnirow::camera::{ideal_fisheye, ideal_pal, Calibration};
use omnirow::detect::{Detection, Detector, DetectorOptions, Method, Row};
use omnirow::frame::ImageView;
use omnirow::sphere::axis_angle;
use omnirow::synth::{random_scene, render, GroundTruth, Protocol, SynthImage};

fn scene(cal: &Calibration, seed: u64) -> (SynthImage, GroundTruth) {
    render(cal, &random_scene(seed, Protocol::Table1), seed).unwrap()
}

fn detect(cal: &Calibration, method: Method, img: &SynthImage) -> Detection {
    detect_with_boundaries(cal, method, img).0
}

/// The detection and the edge method's boundaries behind it.
fn detect_with_boundaries(
    cal: &Calibration,
    method: Method,
    img: &SynthImage,
) -> (Detection, Vec<Row>) {
    let mut d = Detector::new(
        cal,
        DetectorOptions {
            method,
            ..Default::default()
        },
    )
    .unwrap();
    let view = ImageView::new(img.width, img.height, img.format, &img.data).unwrap();
    let mut out = Detection::default();
    d.process(&view, &mut out).unwrap();
    let boundaries = out.boundaries.clone();
    (out, boundaries)
}

fn check_lens(name: &str, cal: Calibration, seed: u64) {
    let (img, truth) = scene(&cal, seed);
    let vp = Vector3::from(truth.vp_along);
    let normals: Vec<Vector3<f64>> = truth
        .row_normals
        .iter()
        .map(|n| Vector3::from(*n))
        .collect();

    // Edge boundaries: most of the support lies on rows through the true vanishing point
    // (within about two pixels' angle at this resolution), close to a true row (a boundary
    // is a few centimetres from the row's centre line).
    let (edge, boundaries) = detect_with_boundaries(&cal, Method::Edge, &img);
    let mut hits = vec![0usize; normals.len()];
    let (mut on, mut total) = (0u32, 0u32);
    for r in &boundaries {
        total += r.support;
        if r.normal.dot(&vp).abs() > 0.012 {
            continue;
        }
        let (i, a) = nearest(&normals, &r.normal);
        if a < 0.06 {
            hits[i] += 1;
            on += r.support;
        }
    }
    let both = hits.iter().filter(|&&h| h >= 2).count();
    eprintln!(
        "{name} seed {seed}: {} edge boundaries, {:.0}% of support on true rows, {} of {} true rows with two boundaries",
        boundaries.len(),
        100.0 * on as f64 / total.max(1) as f64,
        both,
        normals.len()
    );
    // Published: centre lines, each nearer a true row than its boundaries are, with a
    // width; at least one per row whose two boundaries were found, less one.
    assert!(edge.rows.iter().all(|r| r.method == Method::Edge));
    let mut centred = vec![false; normals.len()];
    for r in &edge.rows {
        let (i, a) = nearest(&normals, &r.normal);
        assert!(
            a < 0.03 && r.width_rad > 0.0 && r.width_rad < 0.2,
            "{name}: a published edge row {a:.4} rad from the nearest true row, width {:.4}",
            r.width_rad
        );
        centred[i] = true;
    }
    let centred = centred.iter().filter(|&&c| c).count();
    eprintln!(
        "{name} seed {seed}: {} edge centre lines on {centred} true rows",
        edge.rows.len()
    );
    assert!(
        centred >= 4 && 4 * centred >= 3 * both,
        "{name}: centre lines on {centred} true rows, {both} rows with two boundaries"
    );
    assert!(
        on * 2 > total,
        "{name}: only {on} of {total} edge points on true rows"
    );
    assert!(
        both >= 4,
        "{name}: both boundaries of only {both} rows ({hits:?})"
    );

    // Every method finds the vanishing point within 3 mrad.
    for (m, det) in [
        (Method::Edge, edge),
        (Method::Hough, detect(&cal, Method::Hough, &img)),
        (Method::Combined, detect(&cal, Method::Combined, &img)),
    ] {
        let v = det
            .vanishing_point
            .unwrap_or_else(|| panic!("{name} {}: no vanishing point", m.name()));
        let e = axis_angle(&v.direction, &vp);
        eprintln!(
            "{name} seed {seed} {}: vp error {:.3} mrad",
            m.name(),
            e * 1e3
        );
        assert!(e < 3e-3, "{name} {}: vp error {e} rad", m.name());
        if m == Method::Combined {
            // the Hough centre lines, several with their width from the boundaries
            assert!(det.rows.iter().all(|r| r.method == Method::Hough));
            assert!(det.rows.iter().filter(|r| r.width_rad > 0.0).count() >= 2);
        }
    }
}

/// The true row nearest a normal, and the angle between them.
fn nearest(normals: &[Vector3<f64>], n: &Vector3<f64>) -> (usize, f64) {
    normals
        .iter()
        .enumerate()
        .map(|(i, t)| (i, axis_angle(t, n)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap()
}

#[test]
fn fisheye_rows_and_vanishing_point() {
    check_lens("fisheye", ideal_fisheye(512, 612).unwrap(), 11);
}

#[test]
fn pal_rows_and_vanishing_point() {
    check_lens("pal", ideal_pal(512, 612).unwrap(), 12);
}

/// Table I protocol (paper IV-A), fixed seeds, on full 2448×2050 GC2450C frames (binned by the
/// detector to its 1224×1025 working resolution, as `omnirow eval` runs it): the edge method
/// finds every vanishing point with a modest error, and the combined method is accurate and
/// no worse than the better single method (loose margins; the full figures come from
/// `omnirow eval`). Images rendered directly at 1224×1025 are not used here: without the
/// binning's averaging their row boundaries are aliased, and the combined method's pairing of
/// boundaries into centre lines gains nothing there (20 images per lens with
/// `examples/methods_eval.rs`: combined 0.104/0.088 mrad against Hough 0.107/0.081).
#[test]
fn table1_quick_edge_and_combined() {
    for (name, cal) in [
        ("fisheye", ideal_fisheye(2050, 2448).unwrap()),
        ("pal", ideal_pal(2050, 2448).unwrap()),
    ] {
        let mut errs = [Vec::new(), Vec::new(), Vec::new()];
        let methods = [Method::Hough, Method::Edge, Method::Combined];
        for seed in 1..=4 {
            let (img, truth) = scene(&cal, seed);
            let vp = Vector3::from(truth.vp_along);
            for (k, m) in methods.iter().enumerate() {
                let det = detect(&cal, *m, &img);
                let e = det
                    .vanishing_point
                    .map_or(f64::INFINITY, |v| axis_angle(&v.direction, &vp));
                errs[k].push(e * 1e3);
            }
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let [hough, edge, comb] = [mean(&errs[0]), mean(&errs[1]), mean(&errs[2])];
        eprintln!(
            "{name}: mean VP error hough {hough:.3} edge {edge:.3} combined {comb:.3} mrad; {errs:?}"
        );
        // Measured (seeds 1-4): fisheye hough 0.012, edge 0.093, combined 0.020 mrad; pal
        // 0.033, 0.099, 0.029. Four images per lens are too few to rank the Hough and combined
        // methods, now equally accurate (`omnirow eval` on 100 images: see the README); the
        // guard is that combining does not undo the Hough method's accuracy.
        assert!(edge < 0.25, "{name} edge: {errs:?}");
        assert!(
            errs[2].iter().all(|&e| e < 0.1),
            "{name} combined: {errs:?}"
        );
        assert!(comb < 0.04, "{name} combined: {errs:?}");
        assert!(
            comb <= 2.0 * hough.min(edge),
            "{name}: combined {comb} far worse than the better single method ({hough}, {edge})"
        );
    }
}

/// Table II protocol (paper IV-A, heavy noise), fixed seeds, at 1224×1025: the combined
/// method fails on no more images than either single method on each lens (the full figures
/// come from `omnirow eval`; a failure is a vanishing point missing or more than 1° off).
#[test]
fn table2_quick_combined_fails_least() {
    let methods = [Method::Hough, Method::Edge, Method::Combined];
    let mut sums = [0usize; 3];
    for (name, cal) in [
        ("fisheye", ideal_fisheye(1025, 1224).unwrap()),
        ("pal", ideal_pal(1025, 1224).unwrap()),
    ] {
        let mut dets: Vec<Detector> = methods
            .iter()
            .map(|&m| {
                Detector::new(
                    &cal,
                    DetectorOptions {
                        method: m,
                        ..Default::default()
                    },
                )
                .unwrap()
            })
            .collect();
        let mut fails = [0usize; 3];
        for seed in 1..=12 {
            let (img, truth) = render(&cal, &random_scene(seed, Protocol::Table2), seed).unwrap();
            let view = ImageView::new(img.width, img.height, img.format, &img.data).unwrap();
            let vp = Vector3::from(truth.vp_along);
            for (k, d) in dets.iter_mut().enumerate() {
                let mut out = Detection::default();
                d.process(&view, &mut out).unwrap();
                let e = out
                    .vanishing_point
                    .map_or(f64::INFINITY, |v| axis_angle(&v.direction, &vp));
                fails[k] += (e > 1f64.to_radians()) as usize;
            }
        }
        eprintln!("{name}: Table II failures of 12 (hough, edge, combined) {fails:?}");
        assert!(
            fails[2] <= fails[0].min(fails[1]),
            "{name}: combined fails more than a single method: {fails:?}"
        );
        // The protocol is hard: the edge method fails on most images.
        assert!(fails[1] >= 6, "{name}: {fails:?}");
        for k in 0..3 {
            sums[k] += fails[k];
        }
    }
    assert!(sums[2] <= sums[0] && sums[0] < sums[1], "{sums:?}");
}
