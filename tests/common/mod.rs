//! Test helpers: a minimal renderer of straight rows on a flat field through any calibration,
//! independent of the detector (and of `omnirow synth`), with its ground truth.

#![allow(dead_code)]

use nalgebra::Vector3;
use omnirow::camera::Calibration;

/// A rendered greyscale test image and the true row direction (camera frame).
pub struct Rendered {
    pub width: u32,
    pub height: u32,
    pub data: Vec<u8>,
    pub vp: Vector3<f64>,
    pub heading_rad: f64,
    pub tilt_rad: f64,
}

/// Renders rows (bright strips `half_width_m` wide, `spacing_m` apart, the camera
/// `height_m` above the field, `offset_m` from the nearest row) with heading and tilt
/// (radians, robot frame as omnirow reports them), plus salt noise of `noise` density.
#[allow(clippy::too_many_arguments)]
pub fn render_rows(
    cal: &Calibration,
    heading: f64,
    tilt: f64,
    rows: i32,
    spacing_m: f64,
    half_width_m: f64,
    height_m: f64,
    offset_m: f64,
    noise: f64,
    seed: u64,
) -> Rendered {
    let (h, w) = (cal.model.height as usize, cal.model.width as usize);
    let mut data = vec![0u8; h * w];
    let robot_from_camera = cal.mounting.robot_from_camera();
    let d_robot = Vector3::new(
        tilt.cos() * heading.cos(),
        tilt.cos() * heading.sin(),
        tilt.sin(),
    );
    let d = robot_from_camera.inverse() * d_robot;
    let up_robot = Vector3::z();
    let l = up_robot.cross(&d_robot).normalize();
    let n_robot = d_robot.cross(&l).normalize(); // field normal, upwards
    let (l, n) = (
        robot_from_camera.inverse() * l,
        robot_from_camera.inverse() * n_robot,
    );
    let mut paint = |p: [f64; 2]| {
        let (r, c) = (p[0].round(), p[1].round());
        if r >= 0.0 && c >= 0.0 && (r as usize) < h && (c as usize) < w {
            data[r as usize * w + c as usize] = 230;
        }
    };
    for k in -rows..=rows {
        let lateral = k as f64 * spacing_m - offset_m;
        let base = -n * height_m + l * lateral;
        // t along the row: steps small enough to leave no gaps in the image
        let mut t = -200.0;
        while t < 200.0 {
            let centre = base + d * t;
            let dist = centre.norm();
            let step = (dist * 0.0015).max(0.002);
            let across = (2.0 * half_width_m / (dist * 0.0015)).clamp(2.0, 400.0) as usize;
            for i in 0..=across {
                let s = -half_width_m + 2.0 * half_width_m * i as f64 / across as f64;
                let p = centre + l * s;
                if let Some(px) = cal.ray_to_pixel_in_fov(&p) {
                    paint(px);
                }
            }
            t += step;
        }
    }
    let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
    for v in data.iter_mut() {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        if ((s >> 11) as f64 / (1u64 << 53) as f64) < noise {
            *v = 255;
        }
    }
    Rendered {
        width: w as u32,
        height: h as u32,
        data,
        vp: d,
        heading_rad: heading,
        tilt_rad: tilt,
    }
}

/// Sign-invariant angle between two axes.
pub fn axis_angle(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.cross(b).norm().atan2(a.dot(b).abs())
}
