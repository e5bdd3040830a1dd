//! The virtual image the strips method works in: the camera's own perspective image, the
//! pixels of an ideal pinhole on the optical axis at the calibration's angular resolution
//! there, turned so that its rows run along the horizon the mounting implies. A point of it is
//! (along, below): along the horizon, and below it towards the ground.

use super::StripsRows;
use crate::detect::pose::RobotAxes;
use nalgebra::Vector3;

impl StripsRows {
    /// (along, below) of a ray in the virtual image, pixels; `None` behind the camera.
    pub(super) fn to_virtual(&self, r: &Vector3<f64>) -> Option<[f64; 2]> {
        let q = project(r, self.scale)?;
        Some([
            q[0] * self.e_a[0] + q[1] * self.e_a[1],
            q[0] * self.e_p[0] + q[1] * self.e_p[1],
        ])
    }

    /// The ray of a virtual image point (along, below).
    pub(super) fn to_ray(&self, a: f64, p: f64) -> Vector3<f64> {
        let row = a * self.e_a[0] + p * self.e_p[0];
        let col = a * self.e_a[1] + p * self.e_p[1];
        Vector3::new(row / self.scale, col / self.scale, -1.0).normalize()
    }

    /// The virtual image's pixels per unit of the ideal image plane (its focal length): the
    /// median over the points of cos^1.5 θ / (angular size of the point's pixel), θ the
    /// point's angle from the optical axis — exact for a pinhole camera, whose pixel at θ
    /// spans a solid angle of cos³θ / f². False when there are no points.
    pub(super) fn set_scale(&mut self, rays: &[[f32; 3]], pixel_rad: &[f32]) -> bool {
        let stride = pixel_rad.len().div_ceil(512).max(1);
        self.scratch.clear();
        self.scratch.extend(
            rays.iter()
                .zip(pixel_rad)
                .step_by(stride)
                .filter(|(r, a)| **a > 0.0 && a.is_finite() && -r[2] > 0.05)
                .map(|(r, &a)| (-r[2] as f64).powf(1.5) / a as f64),
        );
        if self.scratch.is_empty() {
            return false;
        }
        let mid = self.scratch.len() / 2;
        let (_, m, _) = self.scratch.select_nth_unstable_by(mid, f64::total_cmp);
        self.scale = *m;
        self.scale.is_finite()
    }

    /// The points in front of the camera in the virtual image (along, below, weight) into
    /// `self.pts`.
    pub(super) fn collect_points(&mut self, rays: &[[f32; 3]], weights: &[f32]) {
        self.pts.clear();
        for (r, &w) in rays.iter().zip(weights) {
            if w.is_nan() || w <= 0.0 {
                continue;
            }
            let v = Vector3::new(r[0] as f64, r[1] as f64, r[2] as f64);
            if let Some([a, p]) = self.to_virtual(&v) {
                self.pts.push([a, p, w as f64]);
            }
        }
    }
}

/// The image direction (row, column), unit, of "below the horizon": from the robot's
/// forward direction towards the ground, where the mounting puts the nominal vanishing point.
/// `None` when the horizon is not in the image.
pub(super) fn below_horizon(axes: &RobotAxes) -> Option<[f64; 2]> {
    let (fwd, up) = (axes.fwd, axes.up);
    let eps: f64 = 1e-3;
    let p0 = project(&fwd, 1.0)?;
    let p1 = project(&(fwd * eps.cos() - up * eps.sin()), 1.0)?;
    let d = [p1[0] - p0[0], p1[1] - p0[1]];
    let n = (d[0] * d[0] + d[1] * d[1]).sqrt();
    if n <= 0.0 {
        return None;
    }
    Some([d[0] / n, d[1] / n])
}

/// A ray's point in the camera's perspective image (row, column), `scale` pixels per unit
/// of the ideal image plane; `None` behind the camera (it looks along −z).
fn project(r: &Vector3<f64>, scale: f64) -> Option<[f64; 2]> {
    let z = -r.z;
    if z <= 1e-6 {
        return None;
    }
    Some([r.x / z * scale, r.y / z * scale])
}
