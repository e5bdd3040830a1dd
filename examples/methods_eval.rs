//! Scores the Hough, edge and combined methods on synthetic images (both shipped lenses) and
//! checks the edge method's rows against the ground truth.
//!
//! `cargo run --release --example methods_eval -- [table1|table2] [images per lens] [first seed]`
//!
//! Images are rendered at 1224×1025 (the working resolution the detector uses for a binned
//! 2448×2050 GC2450C frame). A vanishing point counts as a failure when it is missing or more
//! than 1° from the truth (the paper's Table II criterion).

use nalgebra::Vector3;
use omnirow::camera::{ideal_fisheye, ideal_pal};
use omnirow::detect::{Detection, Detector, DetectorOptions, Method};
use omnirow::frame::ImageView;
use omnirow::sphere::axis_angle;
use omnirow::synth::{random_scene, render, Protocol};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let protocol = match args.get(1).map(String::as_str) {
        Some("table2") => Protocol::Table2,
        _ => Protocol::Table1,
    };
    let n: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(10);
    let seed0: u64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(1);
    let (h, w) = (1025u32, 1224u32);
    println!("protocol {protocol:?}, {n} images per lens, seeds {seed0}..");
    println!("| lens | method | found | failures (>1° or none) | mean err mrad | max err mrad | median ms |");
    println!("|---|---|---|---|---|---|---|");
    let mut edge_lines = Vec::new();
    for (lens, cal) in [
        ("fisheye", ideal_fisheye(h, w).unwrap()),
        ("pal", ideal_pal(h, w).unwrap()),
    ] {
        let mut dets: Vec<(Method, Detector)> = [Method::Hough, Method::Edge, Method::Combined]
            .into_iter()
            .map(|m| {
                // OMNIROW_DETECTOR: detector options as TOML, to try settings.
                let base: DetectorOptions = std::env::var("OMNIROW_DETECTOR")
                    .map(|t| toml::from_str(&t).unwrap())
                    .unwrap_or_default();
                let d = Detector::new(&cal, DetectorOptions { method: m, ..base }).unwrap();
                (m, d)
            })
            .collect();
        let mut stats: Vec<(usize, usize, Vec<f64>, Vec<f64>)> = vec![(0, 0, vec![], vec![]); 3];
        let (mut truth_rows, mut truth_with_two, mut truth_with_one, mut edge_rows, mut edge_good) =
            (0, 0, 0, 0, 0);
        for seed in seed0..seed0 + n {
            let opts = random_scene(seed, protocol);
            let (img, truth) = render(&cal, &opts, seed).unwrap();
            let view = ImageView::new(img.width, img.height, img.format, &img.data).unwrap();
            let vp = Vector3::from(truth.vp_along);
            for (k, (m, d)) in dets.iter_mut().enumerate() {
                let mut out = Detection::default();
                let t = std::time::Instant::now();
                d.process(&view, &mut out).unwrap();
                let ms = t.elapsed().as_secs_f64() * 1e3;
                stats[k].3.push(ms);
                match out.vanishing_point {
                    Some(v) => {
                        stats[k].0 += 1;
                        let e = axis_angle(&v.direction, &vp);
                        if e > 1f64.to_radians() {
                            stats[k].1 += 1;
                        } else {
                            stats[k].2.push(e * 1e3);
                        }
                    }
                    None => stats[k].1 += 1,
                }
                if *m == Method::Edge {
                    // Boundaries per true row: edge rows through the true vanishing point
                    // within 0.06 rad of a true row's plane.
                    let normals: Vec<Vector3<f64>> = truth
                        .row_normals
                        .iter()
                        .map(|n| Vector3::from(*n))
                        .collect();
                    let mut hits = vec![0usize; normals.len()];
                    for r in &out.rows {
                        edge_rows += 1;
                        if r.normal.dot(&vp).abs() > 0.005 {
                            continue;
                        }
                        if let Some((i, a)) = normals
                            .iter()
                            .enumerate()
                            .map(|(i, n)| (i, axis_angle(n, &r.normal)))
                            .min_by(|a, b| a.1.total_cmp(&b.1))
                        {
                            if a < 0.06 {
                                hits[i] += 1;
                                edge_good += 1;
                            }
                        }
                    }
                    truth_rows += normals.len();
                    truth_with_one += hits.iter().filter(|&&h| h >= 1).count();
                    truth_with_two += hits.iter().filter(|&&h| h >= 2).count();
                }
            }
        }
        for (k, (m, _)) in dets.iter().enumerate() {
            let (found, fail, errs, ms) = &mut stats[k];
            ms.sort_by(f64::total_cmp);
            let mean = errs.iter().sum::<f64>() / errs.len().max(1) as f64;
            let max = errs.iter().cloned().fold(0.0, f64::max);
            println!(
                "| {lens} | {} | {found}/{n} | {fail} | {mean:.3} | {max:.3} | {:.1} |",
                m.name(),
                ms[ms.len() / 2]
            );
        }
        edge_lines.push(format!(
            "{lens}: edge rows {edge_rows}, of which through the VP and near a true row {edge_good} ({:.0}%); true rows {truth_rows}, with >=1 edge row {truth_with_one}, with >=2 (both boundaries) {truth_with_two}",
            100.0 * edge_good as f64 / edge_rows.max(1) as f64
        ));
    }
    for l in edge_lines {
        println!("{l}");
    }
}
