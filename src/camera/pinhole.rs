//! Perspective cameras as omnirow reads them: a pinhole (focal lengths, principal point)
//! with optional lens distortion as ROS `camera_info` describes it (`plumb_bob`:
//! k1 k2 p1 p2 k3; `equidistant` fisheye: k1 k2 k3 k4), converted into Scaramuzza's Taylor
//! model so that every stage downstream sees an ordinary [`Calibration`].
//!
//! Owns the `[pinhole]` table of omnirow's TOML calibration, the forward camera model
//! (ray → pixel, distortion included), the conversion (the radial part fitted as the Taylor
//! model's direct polynomial, fx ≠ fy carried by its affine term; tangential distortion has no
//! Taylor counterpart) and the conversion's error in pixels over the image.

use super::ideal::fit_direct;
use super::{
    toml_error, CalibError, Calibration, CalibrationToml, FovMask, Mounting, OcamModel,
    MAX_IMAGE_SIDE,
};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Lens distortion, as ROS `camera_info`'s `distortion_model` and `D` give it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DistortionModel {
    /// No distortion (`d` empty or all zero).
    #[default]
    None,
    /// Brown–Conrady, OpenCV's default: d = [k1, k2, p1, p2, k3] (fewer: the rest zero).
    PlumbBob,
    /// Kannala–Brandt fisheye (OpenCV's `fisheye`): d = [k1, k2, k3, k4].
    Equidistant,
}

/// A perspective camera: pixel (u = column, v = row), 0-based, pixel centres at integers
/// (OpenCV and ROS's convention).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pinhole {
    pub width: u32,
    pub height: u32,
    /// Focal lengths in pixels along the columns (fx) and the rows (fy).
    pub fx: f64,
    pub fy: f64,
    /// Principal point: column (cx) and row (cy).
    pub cx: f64,
    pub cy: f64,
    #[serde(default)]
    pub distortion_model: DistortionModel,
    /// Distortion coefficients in the order of `distortion_model`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub d: Vec<f64>,
}

/// How far the Taylor model lands from the pinhole's own pixels, over the image.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ConversionError {
    pub max_px: f64,
    pub rms_px: f64,
    /// Where the largest error is (row, col).
    pub worst_at: [f64; 2],
    /// Pixels compared (a grid over the image).
    pub samples: usize,
}

/// Degrees of the direct polynomial tried for a distorted lens (the best fit is kept).
const DIRECT_DEGREES: [usize; 5] = [6, 8, 10, 12, 14];

impl Pinhole {
    /// Checks the numbers; names the first bad one.
    pub fn validate(&self) -> Result<(), String> {
        if self.width == 0 || self.height == 0 {
            return Err(format!(
                "[pinhole] image size {}x{} is empty",
                self.width, self.height
            ));
        }
        if self.width > MAX_IMAGE_SIDE || self.height > MAX_IMAGE_SIDE {
            return Err(format!(
                "[pinhole] image size {}x{} has a side over {MAX_IMAGE_SIDE} pixels",
                self.width, self.height
            ));
        }
        for (k, v) in [("fx", self.fx), ("fy", self.fy)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!(
                    "[pinhole] {k} = {v} must be a positive number of pixels"
                ));
            }
        }
        for (k, v) in [("cx", self.cx), ("cy", self.cy)] {
            if !v.is_finite() {
                return Err(format!("[pinhole] {k} = {v} is not a number"));
            }
        }
        if let Some(v) = self.d.iter().find(|v| !v.is_finite()) {
            return Err(format!("[pinhole] d contains {v}, not a number"));
        }
        let max = match self.distortion_model {
            DistortionModel::None => 0,
            DistortionModel::PlumbBob => 5,
            DistortionModel::Equidistant => 4,
        };
        let nonzero = self.d.iter().any(|&v| v != 0.0);
        if self.d.len() > max && (nonzero || max > 0) {
            return Err(format!(
                "[pinhole] d has {} coefficients, distortion_model {:?} takes at most {max}",
                self.d.len(),
                self.distortion_model
            ));
        }
        Ok(())
    }

    /// Coefficient `i` of `d`, zero when absent.
    fn k(&self, i: usize) -> f64 {
        self.d.get(i).copied().unwrap_or(0.0)
    }

    /// Radial distortion of a ray at `angle` from the axis: the distorted radius in the
    /// normalised image plane (1 = one focal length). `None` past 90° for a pinhole.
    fn distorted_radius(&self, angle: f64) -> Option<f64> {
        match self.distortion_model {
            DistortionModel::Equidistant => {
                let t2 = angle * angle;
                Some(
                    angle
                        * (1.0
                            + t2 * (self.k(0)
                                + t2 * (self.k(1) + t2 * (self.k(2) + t2 * self.k(3))))),
                )
            }
            _ if angle >= std::f64::consts::FRAC_PI_2 => None,
            DistortionModel::None => Some(angle.tan()),
            DistortionModel::PlumbBob => {
                let r = angle.tan();
                let r2 = r * r;
                Some(r * (1.0 + r2 * (self.k(0) + r2 * (self.k(1) + r2 * self.k(4)))))
            }
        }
    }

    /// Ray (OCamCalib camera frame: x down the rows, y along the columns, z back out of the
    /// lens) → pixel (row, col), with the full distortion (tangential included).
    pub fn project(&self, ray: &Vector3<f64>) -> Option<[f64; 2]> {
        // OpenCV's frame: x along the columns, y down the rows, z forward.
        let (x, y, z) = (ray.y, ray.x, -ray.z);
        let r = x.hypot(y);
        if r == 0.0 {
            return (z > 0.0).then_some([self.cy, self.cx]);
        }
        let angle = r.atan2(z);
        let rd = self.distorted_radius(angle)?;
        let (ux, uy) = (x / r, y / r);
        let (mut xd, mut yd) = (ux * rd, uy * rd);
        if self.distortion_model == DistortionModel::PlumbBob {
            // Tangential terms on the undistorted normalised point.
            let t = angle.tan();
            let (xn, yn) = (ux * t, uy * t);
            let r2 = t * t;
            let (p1, p2) = (self.k(2), self.k(3));
            xd += 2.0 * p1 * xn * yn + p2 * (r2 + 2.0 * xn * xn);
            yd += p1 * (r2 + 2.0 * yn * yn) + 2.0 * p2 * xn * yn;
        }
        Some([self.fy * yd + self.cy, self.fx * xd + self.cx])
    }

    /// The angle from the axis whose distorted radius is `rd`, on the monotone part of the
    /// radial distortion up to `max_angle`.
    fn angle_of_radius(&self, rd: f64, max_angle: f64) -> f64 {
        let (mut lo, mut hi) = (0.0, max_angle);
        for _ in 0..80 {
            let mid = 0.5 * (lo + hi);
            if self.distorted_radius(mid).unwrap_or(f64::INFINITY) < rd {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    /// The largest angle from the axis up to which the radial distortion keeps growing.
    fn monotone_angle(&self) -> f64 {
        let limit = match self.distortion_model {
            DistortionModel::Equidistant => std::f64::consts::PI,
            _ => std::f64::consts::FRAC_PI_2 - 1e-6,
        };
        let n = 20_000;
        let mut prev = 0.0;
        for i in 1..=n {
            let a = limit * i as f64 / n as f64;
            match self.distorted_radius(a) {
                Some(r) if r > prev => prev = r,
                _ => return limit * (i - 1) as f64 / n as f64,
            }
        }
        limit
    }

    /// The camera as a Taylor-model calibration (with `mask` and `mounting`), and how far the
    /// Taylor model lands from the pinhole's own pixels over the image. Without a mask, a
    /// plumb_bob or undistorted camera sees its whole image.
    pub fn to_calibration(
        &self,
        mask: Option<FovMask>,
        mounting: Mounting,
    ) -> Result<(Calibration, ConversionError), String> {
        self.validate()?;
        let (h, w) = (self.height as f64, self.width as f64);
        // OCamCalib's ideal coordinates are in units of fx: x = (row − cy)·fx/fy, y = col − cx.
        let aspect = self.fy / self.fx;
        let corner_rho = [
            (0.0, 0.0),
            (0.0, w - 1.0),
            (h - 1.0, 0.0),
            (h - 1.0, w - 1.0),
        ]
        .iter()
        .map(|&(r, c)| ((r - self.cy) / aspect).hypot(c - self.cx))
        .fold(0.0, f64::max)
        .max(1.0);
        let radial = match self.distortion_model {
            DistortionModel::None => false,
            DistortionModel::PlumbBob => [0usize, 1, 4].iter().any(|&i| self.k(i) != 0.0),
            DistortionModel::Equidistant => true,
        };
        let corner_px = [
            (0.0, 0.0),
            (0.0, w - 1.0),
            (h - 1.0, 0.0),
            (h - 1.0, w - 1.0),
        ]
        .iter()
        .map(|&(r, c)| (r - self.cy).hypot(c - self.cx))
        .fold(0.0, f64::max);
        let mask = mask.or_else(|| {
            (self.distortion_model != DistortionModel::Equidistant).then_some(FovMask {
                inner_radius_px: 0.0,
                outer_radius_px: corner_px + 1.0,
            })
        });
        let build = |ss: Vec<f64>| -> Result<(Calibration, ConversionError), String> {
            let centre = (self.cy, self.cx);
            let affine = (aspect, 0.0, 0.0);
            let size = (self.height, self.width);
            let probe = OcamModel::new(ss.clone(), vec![1.0], centre, affine, size)?;
            let invpol = OcamModel::fit_invpol(&ss, probe.rho_valid_max().min(corner_rho), 12);
            let cal = Calibration {
                model: OcamModel::new(ss, invpol, centre, affine, size)?,
                mask,
                mounting,
            };
            let err = self.conversion_error(&cal);
            Ok((cal, err))
        };
        if !radial {
            return build(vec![-self.fx, 0.0]);
        }
        let max_angle = self.monotone_angle();
        let rho_max =
            corner_rho.min(self.fx * self.distorted_radius(max_angle).unwrap_or(f64::INFINITY));
        // The degree whose model lands closest to the pinhole's pixels.
        let mut best: Option<(Calibration, ConversionError)> = None;
        let mut last_problem = String::new();
        for degree in DIRECT_DEGREES {
            let ss = fit_direct(
                |rho| self.angle_of_radius(rho / self.fx, max_angle),
                rho_max,
                degree,
            );
            match build(ss) {
                Ok(c) => {
                    let better = match &best {
                        Some(b) => c.1.max_px < b.1.max_px,
                        None => true,
                    };
                    if better {
                        best = Some(c);
                    }
                }
                Err(p) => last_problem = p,
            }
        }
        best.ok_or_else(|| {
            format!("[pinhole] the distortion gives no usable Taylor model: {last_problem}")
        })
    }

    /// Pixel → Taylor ray → pinhole pixel over a grid of about 200 × 200 pixels.
    pub fn conversion_error(&self, cal: &Calibration) -> ConversionError {
        let step = (self.width.max(self.height) as usize / 200).max(1);
        let mut e = ConversionError::default();
        let mut sum2 = 0.0;
        for row in (0..self.height as usize).step_by(step) {
            for col in (0..self.width as usize).step_by(step) {
                let (r, c) = (row as f64, col as f64);
                if !cal.pixel_in_fov(r, c) || !cal.pixel_in_model_range(r, c) {
                    continue;
                }
                let Some(p) = self.project(&cal.model.cam2world(r, c)) else {
                    continue;
                };
                let d = (p[0] - r).hypot(p[1] - c);
                sum2 += d * d;
                e.samples += 1;
                if d > e.max_px {
                    e.max_px = d;
                    e.worst_at = [r, c];
                }
            }
        }
        e.rms_px = (sum2 / e.samples.max(1) as f64).sqrt();
        e
    }
}

/// omnirow's TOML calibration in its perspective form: a `[pinhole]` table instead of the
/// Taylor model's keys, plus the same `[mask]` and `[mounting]`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PinholeToml {
    pub pinhole: Pinhole,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask: Option<FovMask>,
    #[serde(default)]
    pub mounting: Mounting,
}

/// Whether a TOML calibration is in the perspective form (has a `[pinhole]` table).
pub fn is_pinhole_toml(text: &str) -> bool {
    text.parse::<toml::Table>()
        .is_ok_and(|t| t.contains_key("pinhole"))
}

/// Reads the perspective form and converts it: the Taylor form's keys, for the checks every
/// calibration goes through, and the conversion's error.
pub(super) fn parse_toml(
    text: &str,
    path: &Path,
) -> Result<(CalibrationToml, ConversionError), CalibError> {
    let raw: PinholeToml = toml::from_str(text).map_err(|e| toml_error(text, path, e))?;
    let (cal, err) = raw
        .pinhole
        .to_calibration(raw.mask, raw.mounting)
        .map_err(|problem| CalibError::Invalid {
            path: path.to_path_buf(),
            problem,
        })?;
    Ok((cal.raw_toml(), err))
}

impl PinholeToml {
    /// The perspective form as TOML text.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(model: DistortionModel, d: Vec<f64>) -> Pinhole {
        Pinhole {
            width: 640,
            height: 480,
            fx: 500.0,
            fy: 520.0,
            cx: 318.0,
            cy: 242.0,
            distortion_model: model,
            d,
        }
    }

    #[test]
    fn undistorted_pinhole_is_exact() {
        let p = cam(DistortionModel::None, vec![]);
        let (cal, err) = p.to_calibration(None, Mounting::default()).unwrap();
        assert_eq!(cal.model.ss, vec![-500.0, 0.0]);
        assert!(err.max_px < 1e-9, "{err:?}");
        assert!(err.samples > 10_000);
        // The whole image is in the field of view.
        assert!(cal.pixel_in_fov(0.0, 0.0) && cal.pixel_in_fov(479.0, 639.0));
        // A ray 10 px right of the principal point at fx = 500.
        let ray = cal.model.cam2world(242.0, 328.0);
        assert!((ray.y / -ray.z - 10.0 / 500.0).abs() < 1e-12);
        let ray = cal.model.cam2world(252.0, 318.0);
        assert!((ray.x / -ray.z - 10.0 / 520.0).abs() < 1e-12);
    }

    #[test]
    fn radial_distortion_fits_to_a_hundredth_of_a_pixel() {
        let p = cam(DistortionModel::PlumbBob, vec![-0.28, 0.07, 0.0, 0.0, 0.0]);
        let (_, err) = p.to_calibration(None, Mounting::default()).unwrap();
        assert!(err.max_px < 0.01, "{err:?}");
        let f = cam(
            DistortionModel::Equidistant,
            vec![0.02, -0.01, 0.003, -0.0005],
        );
        let (_, err) = f.to_calibration(None, Mounting::default()).unwrap();
        assert!(err.max_px < 0.01, "{err:?}");
    }

    #[test]
    fn tangential_distortion_is_the_residual() {
        let p = cam(
            DistortionModel::PlumbBob,
            vec![-0.28, 0.07, 0.001, -0.0005, 0.0],
        );
        let (_, err) = p.to_calibration(None, Mounting::default()).unwrap();
        // p1, p2 of 1e-3 move the corners by about a pixel: the Taylor model cannot follow.
        assert!(err.max_px > 0.3 && err.max_px < 5.0, "{err:?}");
        assert!(err.rms_px < err.max_px);
    }

    #[test]
    fn bad_numbers_are_named() {
        let mut p = cam(DistortionModel::None, vec![]);
        p.fx = 0.0;
        let e = p.to_calibration(None, Mounting::default()).unwrap_err();
        assert!(e.contains("fx"), "{e}");
        let p = cam(DistortionModel::Equidistant, vec![0.1; 5]);
        let e = p.validate().unwrap_err();
        assert!(e.contains("at most 4"), "{e}");
        let p = cam(DistortionModel::PlumbBob, vec![f64::NAN]);
        assert!(p.validate().unwrap_err().contains("not a number"));
    }

    #[test]
    fn an_absurd_image_size_is_refused_before_any_work() {
        // Found by the calibration_toml fuzz target: a height of 666 666 512 pixels parsed,
        // and checking the model's round trip over it took minutes.
        let text = "[pinhole]\nwidth = 512\nheight = 666666512\nfx = 300.0\nfy = 600.0\n\
                    cx = 255.5\ncy = 255.5\n";
        let e = Calibration::parse_toml(text, Path::new("big.toml")).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("big.toml") && msg.contains("666666512"),
            "{msg}"
        );
        let mut p = cam(DistortionModel::None, vec![]);
        p.width = MAX_IMAGE_SIDE;
        assert!(p.validate().is_ok());
        p.width = MAX_IMAGE_SIDE + 1;
        assert!(p.validate().unwrap_err().contains("over 20000"));
    }
}
