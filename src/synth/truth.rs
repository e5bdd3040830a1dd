//! Ground truth of a synthetic image: what the detector should find, computed from the scene
//! ([`GroundTruth`] itself is a [`crate::frame`] type, as frames carry it).

use super::scene::Scene;
use crate::camera::Calibration;
use crate::frame::{GroundTruth, NoiseTruth, NO_CROP_RANGE_M};
use crate::sphere::{axis_angle, distance_to_great_circle};
use nalgebra::Vector3;

impl GroundTruth {
    /// The ground truth of `scene` seen through `cal` (at the calibration's resolution).
    ///
    /// A row is listed when its centre line (the ideal line, whatever the plants' position
    /// errors) is seen over at least `min_row_length_px` of image length at points that lie
    /// inside the field of view and at least `min_row_separation_px` from the great circles of
    /// the neighbouring rows (farther rows merge into one blur and cannot be told apart).
    pub fn of_scene(scene: &Scene, cal: &Calibration) -> GroundTruth {
        let o = &scene.options;
        let pose = &scene.pose;
        let s = o.row_spacing_m;
        // ties (camera midway) go to the row at lower y, so the offset lies in (-s/2, s/2]
        let lateral = o.lateral_m - (o.lateral_m / s - 0.5).ceil() * s;
        let (rows, lateral_m): (Vec<_>, Vec<_>) = visible_rows(scene, cal)
            .into_iter()
            .map(|(i, n)| ([n.x, n.y, n.z], i as f64 * s - o.lateral_m))
            .unzip();
        let v = |a: Vector3<f64>| [a.x, a.y, a.z];
        GroundTruth {
            vp_along: v(pose.vp_along()),
            vp_across: v(pose.vp_across()),
            yaw_rad: o.yaw_deg.to_radians(),
            pitch_rad: o.pitch_deg.to_radians(),
            roll_rad: o.roll_deg.to_radians(),
            heading_rad: pose.heading(),
            tilt_rad: pose.tilt(),
            height_m: o.height_m,
            lateral_offset_m: lateral,
            camera_lateral_m: o.lateral_m,
            row_spacing_m: s,
            plant_distance_m: o.plant_distance_m,
            curvature_per_m: o.curvature_per_m,
            end_of_rows_m: o.rows_end_m.map(|_| scene.field.rows_end() - o.along_m),
            no_crop: !scene.field.crop_within(o.along_m, NO_CROP_RANGE_M),
            noise: NoiseTruth {
                background_density: o.noise,
                along_row_sd_m: o.along_sd_m,
                across_row_sd_m: o.across_sd_m,
                weeds: o.weeds,
            },
            row_normals: rows,
            row_lateral_m: lateral_m,
            seed: scene.seed,
        }
    }
}

/// Angle (radians) one pixel spans at pixel `p`: the larger of its row and column steps.
fn pixel_angle(cal: &Calibration, p: [f64; 2]) -> f64 {
    let m = &cal.model;
    let r0 = m.cam2world(p[0], p[1]);
    let a = axis_angle(&r0, &m.cam2world(p[0] + 1.0, p[1]));
    let b = axis_angle(&r0, &m.cam2world(p[0], p[1] + 1.0));
    a.max(b)
}

/// The smallest angle a pixel spans anywhere in the field of view (sampled on a grid).
fn min_pixel_angle(cal: &Calibration) -> f64 {
    let (h, w) = cal.size();
    let mut best = f64::INFINITY;
    let n = 48;
    for i in 0..=n {
        for j in 0..=n {
            let (r, c) = (
                (h as f64 - 2.0) * i as f64 / n as f64,
                (w as f64 - 2.0) * j as f64 / n as f64,
            );
            if cal.pixel_in_fov(r, c) && cal.pixel_in_model_range(r, c) {
                best = best.min(pixel_angle(cal, [r, c]));
            }
        }
    }
    if best.is_finite() {
        best
    } else {
        1e-3
    }
}

/// Rows (index, unit normal in the camera frame) seen and resolvable in the image.
fn visible_rows(scene: &Scene, cal: &Calibration) -> Vec<(i64, Vector3<f64>)> {
    let o = &scene.options;
    let pose = &scene.pose;
    let field = &scene.field;
    let s = field.row_spacing();
    let c = pose.centre;
    let h = c.z;
    let ang_min = min_pixel_angle(cal);
    let (row_lo, row_hi) = (*field.rows().start(), *field.rows().end());
    let x_lo = *field.plant_indices().start() as f64 * field.plant_distance();
    let x_hi = *field.plant_indices().end() as f64 * field.plant_distance();
    let normal = |i: i64| pose.line_normal(&Vector3::new(0.0, i as f64 * s, 0.0), &Vector3::x());
    let dist = |i: i64| (i as f64 * s - c.y).hypot(h);
    // The separation of neighbouring rows peaks where they pass closest to the camera, at
    // about h·s / (D_i·D_j); rows that cannot reach the separation anywhere are skipped.
    let need = o.min_row_separation_px * ang_min;
    let step = 2.0 * ang_min;
    let mut out = Vec::new();
    for i in row_lo..=row_hi {
        let d_i = dist(i);
        let best_sep = [i - 1, i + 1]
            .iter()
            .filter(|j| (row_lo..=row_hi).contains(*j))
            .map(|&j| h * s / (d_i * dist(j)))
            .fold(f64::INFINITY, f64::min);
        if best_sep.min(1.0).asin() < need * 0.9 {
            continue;
        }
        let Some(n_i) = normal(i) else { continue };
        let neighbours: Vec<Vector3<f64>> = [i - 1, i + 1]
            .iter()
            .filter(|j| (row_lo..=row_hi).contains(*j))
            .filter_map(|&j| normal(j))
            .collect();
        // Points along the line at equal angles seen from the camera.
        let y = i as f64 * s;
        let steps = (std::f64::consts::PI / step).ceil() as usize;
        let mut length = 0.0;
        let mut prev: Option<[f64; 2]> = None;
        for k in 1..steps {
            let psi = -std::f64::consts::FRAC_PI_2 + std::f64::consts::PI * k as f64 / steps as f64;
            let x = c.x + d_i * psi.tan();
            let seen = if x < x_lo || x > x_hi {
                None
            } else {
                pose.direction_to(&Vector3::new(x, y, 0.0)).and_then(|q| {
                    let p = cal.ray_to_pixel_in_fov(&q)?;
                    let sep = neighbours
                        .iter()
                        .map(|n| distance_to_great_circle(n, &q))
                        .fold(f64::INFINITY, f64::min);
                    (sep >= o.min_row_separation_px * pixel_angle(cal, p)).then_some(p)
                })
            };
            if let (Some(a), Some(b)) = (prev, seen) {
                length += (a[0] - b[0]).hypot(a[1] - b[1]);
            }
            prev = seen;
        }
        if length >= o.min_row_length_px {
            out.push((i, n_i));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::ideal_fisheye;
    use crate::synth::{Renderer, SynthOptions};
    use proptest::prelude::*;

    fn scene(opts: &SynthOptions, cal: &Calibration) -> Scene {
        Scene::new(opts, 5, &cal.mounting).unwrap()
    }

    #[test]
    fn plant_centres_lie_on_the_listed_great_circles_and_are_rendered_bright() {
        check_plants_on_rows(&ideal_fisheye(2050, 2448).unwrap().rescaled(2.0).unwrap());
        check_plants_on_rows(
            &crate::camera::ideal_pal(2050, 2448)
                .unwrap()
                .rescaled(2.0)
                .unwrap(),
        );
    }

    fn check_plants_on_rows(cal: &Calibration) {
        let cal = cal.clone();
        let opts = SynthOptions {
            yaw_deg: 12.0,
            pitch_deg: -4.0,
            roll_deg: 2.0,
            ..Default::default()
        };
        let sc = scene(&opts, &cal);
        let truth = GroundTruth::of_scene(&sc, &cal);
        assert!(truth.row_normals.len() >= 6, "{}", truth.row_normals.len());
        let mut renderer = Renderer::new(&cal).unwrap();
        let mut img = vec![0u8; renderer.buffer_len(opts.style)];
        renderer.render_into(&sc, &mut img).unwrap();
        let (_, w) = cal.size();
        let mut checked = 0;
        let mut bright = 0;
        for (n, lat) in truth.row_normals.iter().zip(&truth.row_lateral_m) {
            let n = Vector3::from(*n);
            let y = opts.lateral_m + lat;
            assert!((y / opts.row_spacing_m - (y / opts.row_spacing_m).round()).abs() < 1e-9);
            for k in -40..=40 {
                let p = Vector3::new(k as f64 * opts.plant_distance_m, y, 0.0);
                let q = sc.pose.direction_to(&p).unwrap();
                let Some(px) = cal.ray_to_pixel_in_fov(&q) else {
                    continue;
                };
                let ray = cal.model.cam2world(px[0], px[1]);
                assert!(
                    n.dot(&ray).abs() < 2e-4,
                    "row {lat}, plant {k}: {}",
                    n.dot(&ray)
                );
                checked += 1;
                // Plants within 1.5 m of the camera are several pixels wide: the pixel at the
                // stem is plant-bright.
                if (p - sc.pose.centre).norm() < 1.5 {
                    let v = img[px[0].round() as usize * w as usize + px[1].round() as usize];
                    assert!(v > 150, "plant {k} of row {lat} at {px:?} is {v}");
                    bright += 1;
                }
            }
        }
        assert!(checked > 200 && bright > 10, "{checked} {bright}");
        // and half-way between rows, near the camera, is soil
        let mid = Vector3::new(1.0, opts.lateral_m, 0.0);
        let px = cal
            .ray_to_pixel_in_fov(&sc.pose.direction_to(&mid).unwrap())
            .unwrap();
        let v = img[px[0].round() as usize * w as usize + px[1].round() as usize];
        assert!(v < 60, "{v}");
    }

    #[test]
    fn truth_is_deterministic_and_serialises() {
        let cal = ideal_fisheye(512, 612).unwrap();
        let opts = SynthOptions {
            yaw_deg: -20.0,
            across_sd_m: 0.01,
            weeds: 10,
            field_half_length_m: 40.0,
            field_half_width_m: 40.0,
            ..Default::default()
        };
        let a = GroundTruth::of_scene(&scene(&opts, &cal), &cal);
        let b = GroundTruth::of_scene(&scene(&opts, &cal), &cal);
        assert_eq!(a, b);
        let json = serde_json::to_string(&a).unwrap();
        assert_eq!(json, serde_json::to_string(&b).unwrap());
        let back: GroundTruth = serde_json::from_str(&json).unwrap();
        assert_eq!(back.row_normals.len(), a.row_normals.len());
        for (x, y) in back.row_normals.iter().zip(&a.row_normals) {
            assert!((Vector3::from(*x) - Vector3::from(*y)).norm() < 1e-15);
        }
        assert_eq!(a.noise.weeds, 10);
        assert_eq!(a.noise.across_row_sd_m, 0.01);
        assert!((a.heading_rad - 20f64.to_radians()).abs() < 1e-12);
        assert!((a.lateral_offset_m - 0.25).abs() < 1e-12);
    }

    #[test]
    fn the_rows_nearest_the_camera_are_listed_and_far_ones_are_not() {
        let cal = ideal_fisheye(1025, 1224).unwrap();
        let t = GroundTruth::of_scene(&scene(&SynthOptions::default(), &cal), &cal);
        for lat in [-0.25, 0.25, -0.75, 0.75, 2.25] {
            assert!(
                t.row_lateral_m.iter().any(|l| (l - lat).abs() < 1e-9),
                "{lat} missing from {:?}",
                t.row_lateral_m
            );
        }
        assert!(t.row_lateral_m.iter().all(|l| l.abs() < 40.0));
        // symmetric about the camera, which sits midway between two rows
        let left = t.row_lateral_m.iter().filter(|l| **l < 0.0).count();
        assert_eq!(left * 2, t.row_lateral_m.len());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]
        #[test]
        fn normals_are_perpendicular_to_the_row_direction_and_contain_the_plants(
            yaw in -45.0f64..45.0, pitch in -15.0f64..15.0, roll in -10.0f64..10.0,
            lateral in -1.0f64..1.0, height in 0.3f64..3.0,
        ) {
            let cal = ideal_fisheye(256, 306).unwrap();
            let opts = SynthOptions {
                yaw_deg: yaw, pitch_deg: pitch, roll_deg: roll, lateral_m: lateral,
                height_m: height, ..Default::default()
            };
            let sc = scene(&opts, &cal);
            let t = GroundTruth::of_scene(&sc, &cal);
            let vp = Vector3::from(t.vp_along);
            prop_assert!(vp.dot(&Vector3::from(t.vp_across)).abs() < 1e-12);
            prop_assert!(!t.row_normals.is_empty());
            for (n, lat) in t.row_normals.iter().zip(&t.row_lateral_m) {
                let n = Vector3::from(*n);
                prop_assert!((n.norm() - 1.0).abs() < 1e-12);
                prop_assert!(n.dot(&vp).abs() < 1e-12);
                for x in [-3.0, 0.0, 7.5] {
                    let q = sc.pose.direction_to(&Vector3::new(x, lateral + lat, 0.0)).unwrap();
                    prop_assert!(n.dot(&q).abs() < 1e-12);
                }
            }
            // heading and tilt describe the row direction in the robot frame
            let d = sc.pose.world_from_robot.inverse_transform_vector(&Vector3::x());
            let d = if d.x < 0.0 { -d } else { d };
            prop_assert!((t.heading_rad - d.y.atan2(d.x)).abs() < 1e-12);
            prop_assert!((t.tilt_rad.sin() - d.z).abs() < 1e-12);
        }
    }
}
