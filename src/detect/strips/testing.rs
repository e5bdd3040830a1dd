//! Test fields for the strips method: flat fields of crop rows seen by a pinhole camera,
//! and the measures of how far rows found lie from the true ones.

use super::{StripsOptions, StripsRows};
use crate::camera::Mounting;
use crate::detect::types::{Points, Row};
use nalgebra::{Rotation3, Vector3};

/// The strips method with its defaults (tilt within 15°) on `fld` seen from `m`: the method
/// after the search, the vanishing point and the rows.
pub fn detect(fld: &Field, m: &Mounting) -> (StripsRows, Option<Vector3<f64>>, Vec<Row>) {
    let mut s = StripsRows::new(StripsOptions::default(), 15.0, m).unwrap();
    let mut rows = Vec::new();
    let vp = s.find(&fld.points(), &mut rows).unwrap();
    (s, vp, rows)
}

/// A flat field seen by a pinhole of focal length `f` (pixels) on a `size`² image,
/// mounted as `m`, the rows `spacing` apart turned by `heading` (radians): plant points
/// along each row (a deterministic scatter across its width), as rays, weights and pixel
/// sizes; and the rows' true plane normals in the camera frame.
pub struct Field {
    pub rays: Vec<[f32; 3]>,
    pub weights: Vec<f32>,
    pub pixel_rad: Vec<f32>,
    pub normals: Vec<Vector3<f64>>,
}

impl Field {
    /// The field's points as the detector hands them to a method.
    pub fn points(&self) -> Points {
        Points {
            rays: self.rays.clone(),
            weights: self.weights.clone(),
            pixel_rad: self.pixel_rad.clone(),
        }
    }
}

pub fn field(f: f64, size: f64, m: &Mounting, spacing: f64, offset: f64, heading: f64) -> Field {
    let ys: Vec<f64> = (-8..=8).map(|k| offset + k as f64 * spacing).collect();
    field_at(f, size, m, &ys, heading)
}

/// As [`field`], the rows at lateral positions `ys` (metres).
pub fn field_at(f: f64, size: f64, m: &Mounting, ys: &[f64], heading: f64) -> Field {
    let cam_from_robot = m.robot_from_camera().inverse();
    let yaw = Rotation3::from_axis_angle(&Vector3::z_axis(), heading);
    let h = m.height_m;
    let mut fld = Field {
        rays: vec![],
        weights: vec![],
        pixel_rad: vec![],
        normals: vec![],
    };
    let mut rnd = uniform(12345);
    for &y in ys {
        let a = cam_from_robot * (yaw * Vector3::new(2.0, y, -h));
        let b = cam_from_robot * (yaw * Vector3::new(12.0, y, -h));
        fld.normals.push(a.cross(&b).normalize());
        for _ in 0..3000 {
            // forward distances spread like the image's rows (denser far away)
            let x = 1.0 / (1.0 - rnd() * (1.0 - 1.0 / 40.0));
            let p = cam_from_robot * (yaw * Vector3::new(x, y + (rnd() - 0.5) * 0.08, -h));
            fld.see(&p, f, size);
        }
    }
    fld
}

impl Field {
    /// Adds the point `p` (camera frame) when a pinhole of focal length `f` on a
    /// `size`² image sees it.
    pub fn see(&mut self, p: &Vector3<f64>, f: f64, size: f64) {
        let r = p.normalize();
        if -r.z <= 0.05 {
            return;
        }
        let (row, col) = (r.x / -r.z * f, r.y / -r.z * f);
        if row.abs() > size / 2.0 || col.abs() > size / 2.0 {
            return;
        }
        self.rays.push([r.x as f32, r.y as f32, r.z as f32]);
        self.weights.push(1.0);
        self.pixel_rad.push(((-r.z).powf(1.5) / f) as f32);
    }
}

/// A deterministic uniform generator on [0, 1) from `seed`.
pub fn uniform(mut seed: u64) -> impl FnMut() -> f64 {
    move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    }
}

pub fn forward_camera() -> Mounting {
    Mounting {
        pitch_deg: -47.0,
        ..Mounting::default()
    }
}

/// The angle (radians) from `n` to the nearest of `truth`'s normals.
pub fn nearest(n: &Vector3<f64>, truth: &[Vector3<f64>]) -> f64 {
    truth
        .iter()
        .map(|t| n.dot(t).abs().min(1.0).acos())
        .fold(f64::MAX, f64::min)
}

/// The centre line of the row at lateral `y` (metres) turned by `heading`, as a pinhole
/// of focal length `f` on a `size`² image mounted as `m` sees it: its rays from 1 m to
/// `reach` metres ahead.
pub fn centre_line(
    f: f64,
    size: f64,
    m: &Mounting,
    y: f64,
    heading: f64,
    reach: f64,
) -> Vec<Vector3<f64>> {
    let cam_from_robot = m.robot_from_camera().inverse();
    let yaw = Rotation3::from_axis_angle(&Vector3::z_axis(), heading);
    (0..400)
        .map(|i| 1.0 + i as f64 * (reach - 1.0) / 399.0)
        .map(|x| (cam_from_robot * (yaw * Vector3::new(x, y, -m.height_m))).normalize())
        .filter(|r| {
            let (row, col) = (r.x / -r.z * f, r.y / -r.z * f);
            -r.z > 0.05 && row.abs() <= size / 2.0 && col.abs() <= size / 2.0
        })
        .collect()
}

/// The largest distance (pixels, at `f`) of `line`'s rays from the great circle `n`.
pub fn off_line_px(n: &Vector3<f64>, line: &[Vector3<f64>], f: f64) -> f64 {
    let n = n.normalize();
    line.iter()
        .map(|r| n.dot(r).abs().min(1.0).asin() / (-r.z).powi(2) * f)
        .fold(0.0, f64::max)
}

/// The field of a `forward_camera` with 0.5 m rows turned by 5°, and 4000 weeds scattered
/// over 20 m × 8 m.
pub fn weedy_field() -> (Mounting, Field) {
    let m = forward_camera();
    let mut fld = field(300.0, 512.0, &m, 0.5, 0.1, 5f64.to_radians());
    let mut rnd = uniform(7);
    let cam_from_robot = m.robot_from_camera().inverse();
    for _ in 0..4000 {
        let (x, y) = (1.0 + 20.0 * rnd(), 8.0 * (rnd() - 0.5));
        fld.see(
            &(cam_from_robot * Vector3::new(x, y, -m.height_m)),
            300.0,
            512.0,
        );
    }
    (m, fld)
}
