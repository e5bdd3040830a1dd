//! Per-frame CPU time (this thread's, CLOCK_THREAD_CPUTIME_ID, so that other load on the
//! machine does not count) of the whole detector per method on a synthetic 2448×2050 frame
//! (Table I protocol), with the combined detector's stage breakdown. Complements
//! `cargo bench --bench edge`, whose wall-clock figures are only meaningful on an idle machine.
//!
//! `cargo run --release --example detector_cpu_time -- [frames]`
//!
//! `OMNIROW_DETECTOR`: detector options as TOML (e.g. `[combined]` settings), to compare
//! settings in one run.
use omnirow::camera::{ideal_fisheye, ideal_pal};
use omnirow::detect::{Detection, Detector, DetectorOptions, Method};
use omnirow::frame::ImageView;
use omnirow::synth::{random_scene, render, Protocol};

fn cpu_ns() -> Option<f64> {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes one timespec through a valid pointer.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    (rc == 0).then_some(ts.tv_sec as f64 * 1e9 + ts.tv_nsec as f64)
}

fn main() {
    let frames: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(15);
    println!("| lens | method | median CPU ms | p90 CPU ms | prepare | hough | edge | vanishing |");
    println!("|---|---|---|---|---|---|---|---|");
    for (lens, cal) in [
        ("fisheye", ideal_fisheye(2050, 2448).unwrap()),
        ("pal", ideal_pal(2050, 2448).unwrap()),
    ] {
        let (img, _) = render(&cal, &random_scene(7, Protocol::Table1), 7).unwrap();
        let view = ImageView::new(img.width, img.height, img.format, &img.data).unwrap();
        for method in [Method::Hough, Method::Edge, Method::Combined] {
            let base: DetectorOptions = std::env::var("OMNIROW_DETECTOR")
                .map(|t| toml::from_str(&t).unwrap())
                .unwrap_or_default();
            let mut det = Detector::new(&cal, DetectorOptions { method, ..base }).unwrap();
            let mut out = Detection::default();
            det.process(&view, &mut out).unwrap();
            let mut t = Vec::new();
            let mut stages = [Vec::new(), Vec::new(), Vec::new(), Vec::new()];
            for _ in 0..frames {
                let (Some(a), _) = (cpu_ns(), ()) else {
                    eprintln!("no thread CPU clock");
                    return;
                };
                det.process(&view, &mut out).unwrap();
                let b = cpu_ns().unwrap_or(a);
                t.push((b - a) / 1e6);
                let s = det.last_times();
                for (v, d) in stages
                    .iter_mut()
                    .zip([s.prepare, s.hough, s.edge, s.vanishing])
                {
                    v.push(d.as_secs_f64() * 1e3);
                }
            }
            t.sort_by(f64::total_cmp);
            // Stage shares of the CPU time, from their wall-clock proportions.
            let wall: Vec<f64> = stages.iter().map(|v| v.iter().sum::<f64>()).collect();
            let total: f64 = wall.iter().sum();
            let med = t[t.len() / 2];
            let share = |i: usize| med * wall[i] / total.max(1e-9);
            println!(
                "| {lens} | {} | {med:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} |",
                method.name(),
                t[(t.len() * 9) / 10],
                share(0),
                share(1),
                share(2),
                share(3)
            );
        }
    }
}
