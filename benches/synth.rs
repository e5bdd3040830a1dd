//! Speed of the synthetic field renderer: a full 2448x2050 GC2450C frame per style, through
//! the ideal fisheye and PAL lenses (setup excluded: the Renderer is built once).

use criterion::{criterion_group, criterion_main, Criterion};
use omnirow::camera::{ideal_fisheye, ideal_pal};
use omnirow::synth::{Renderer, Scene, Style, SynthOptions};

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("synth_render_2448x2050");
    g.sample_size(10);
    for (lens, cal) in [
        ("fisheye185", ideal_fisheye(2050, 2448).unwrap()),
        ("pal", ideal_pal(2050, 2448).unwrap()),
    ] {
        let mut renderer = Renderer::new(&cal).expect("ideal lens renders");
        for style in [Style::Grey, Style::Colour, Style::Bayer] {
            let opts = SynthOptions {
                style,
                yaw_deg: 10.0,
                pitch_deg: 3.0,
                noise: 0.1,
                ..Default::default()
            };
            let scene = Scene::new(&opts, 1, &cal.mounting).expect("valid options");
            let mut out = vec![0u8; renderer.buffer_len(style)];
            g.bench_function(format!("{lens}/{style:?}"), |b| {
                b.iter(|| renderer.render_into(&scene, &mut out).expect("render"))
            });
        }
    }
    g.finish();
    let mut g = c.benchmark_group("synth_setup_2448x2050");
    g.sample_size(10);
    let cal = ideal_fisheye(2050, 2448).unwrap();
    g.bench_function("renderer_new", |b| {
        b.iter(|| Renderer::new(&cal).expect("renderer"))
    });
    g.bench_function("scene_table2_worst_field", |b| {
        let opts = SynthOptions {
            plant_distance_m: 0.03,
            along_sd_m: 0.02,
            across_sd_m: 0.02,
            weeds: 300,
            ..Default::default()
        };
        b.iter(|| Scene::new(&opts, 1, &cal.mounting).expect("scene"))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
