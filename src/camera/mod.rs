//! The omnidirectional camera: a calibrated lens model plus what omnirow needs around it.
//!
//! Owns [`Calibration`]: Scaramuzza's Taylor model ([`OcamModel`], read from OCamCalib's
//! `calib_results.txt` or from omnirow's TOML calibration), the lens's field-of-view mask
//! (a circle for a fisheye, an annulus for a catadioptric lens), and the camera's mounting
//! rotation on the robot. Also the ideal lens models omnirow ships (an equidistant 185°
//! fisheye and a panoramic annular lens for the GC2450C's 2448×2050 sensor), so that it runs
//! with no files at all.

pub mod camera_info;
mod ideal;
mod ocam;
mod pinhole;

pub use ideal::{ideal_fisheye, ideal_pal, IdealLens, IDEAL_SIDE_PX};
pub use ocam::{CalibError, OcamModel, MAX_IMAGE_SIDE};
pub use pinhole::{ConversionError, DistortionModel, Pinhole, PinholeToml};

use nalgebra::{Rotation3, Vector3};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The lens's field of view in the image: pixels whose distance from the centre lies in
/// `[inner, outer]` (pixels, in the calibration's own resolution) see the scene.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FovMask {
    /// Inner radius in pixels (0 for a fisheye; the blind disc of a catadioptric lens).
    pub inner_radius_px: f64,
    /// Outer radius in pixels (the rim of the lens's image circle).
    pub outer_radius_px: f64,
}

impl FovMask {
    /// Checks that 0 ≤ inner < outer.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.inner_radius_px >= 0.0
            && self.outer_radius_px > self.inner_radius_px
            && self.outer_radius_px.is_finite())
        {
            return Err(format!(
                "mask radii must satisfy 0 <= inner < outer, got inner {} outer {}",
                self.inner_radius_px, self.outer_radius_px
            ));
        }
        Ok(())
    }
}

/// The camera's mounting on the robot: a rotation applied after the default pose, the
/// camera's position in base_link and its height above the ground.
///
/// Default (angles zero): the camera looks straight down, the top of the image towards the
/// robot's front. Robot frame as ROS REP 103: x forward, y left, z up. The rotation from
/// camera to robot is `Rz(yaw) · Ry(pitch) · Rx(roll) · R0`, with R0 the default pose.
/// The height (default 1 m) and position (default the base_link origin) place the rows on the
/// ground for row guidance (see docs/guidance.md); the detector needs neither.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Mounting {
    pub roll_deg: f64,
    pub pitch_deg: f64,
    pub yaw_deg: f64,
    /// Height of the camera's centre (single effective viewpoint) above the ground, metres.
    pub height_m: f64,
    /// The camera's centre in base_link (x forward, y left, z up), metres.
    pub position_m: [f64; 3],
}

impl Default for Mounting {
    fn default() -> Self {
        Mounting {
            roll_deg: 0.0,
            pitch_deg: 0.0,
            yaw_deg: 0.0,
            height_m: 1.0,
            position_m: [0.0; 3],
        }
    }
}

impl Mounting {
    /// Checks the angles (degrees within ±360), the height (0 < h ≤ 20 m) and the position
    /// (finite, within 50 m of base_link).
    pub fn validate(&self) -> Result<(), String> {
        for (k, v) in [
            ("roll_deg", self.roll_deg),
            ("pitch_deg", self.pitch_deg),
            ("yaw_deg", self.yaw_deg),
        ] {
            if !v.is_finite() || v.abs() > 360.0 {
                return Err(format!("{k} = {v} is not an angle in degrees within ±360"));
            }
        }
        if !(self.height_m > 0.0 && self.height_m <= 20.0) {
            return Err(format!(
                "height_m = {} is not a camera height above the ground in metres (0 < h <= 20)",
                self.height_m
            ));
        }
        if let Some(v) = self
            .position_m
            .iter()
            .find(|v| !v.is_finite() || v.abs() > 50.0)
        {
            return Err(format!(
                "position_m = {:?}: {v} is not a position in metres within ±50 of base_link",
                self.position_m
            ));
        }
        Ok(())
    }

    /// The default pose: OCamCalib camera axes expressed in the robot frame.
    /// Camera x (image down) = robot −x, camera y (image right) = robot −y, camera z = robot z (up).
    pub fn default_rotation() -> Rotation3<f64> {
        Rotation3::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI)
    }

    /// Rotation that takes camera-frame vectors to robot-frame vectors.
    pub fn robot_from_camera(&self) -> Rotation3<f64> {
        Rotation3::from_euler_angles(
            self.roll_deg.to_radians(),
            self.pitch_deg.to_radians(),
            self.yaw_deg.to_radians(),
        ) * Self::default_rotation()
    }
}

/// A calibrated omnidirectional camera as omnirow uses it.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    pub model: OcamModel,
    /// The field-of-view mask; `None` when it must be found from the image.
    pub mask: Option<FovMask>,
    pub mounting: Mounting,
}

/// omnirow's TOML calibration file (see config/calibration.example.toml).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationToml {
    /// Image size in pixels: height (rows), width (columns).
    pub height: u32,
    pub width: u32,
    /// Centre (row, column), 0-based.
    pub centre: [f64; 2],
    /// Affine parameters c, d, e.
    pub affine: [f64; 3],
    /// Direct polynomial, ascending powers.
    pub ss: Vec<f64>,
    /// Inverse polynomial, ascending powers.
    pub invpol: Vec<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask: Option<FovMask>,
    #[serde(default)]
    pub mounting: Mounting,
}

impl Calibration {
    /// Wraps a model with no mask and the default mounting.
    pub fn from_model(model: OcamModel) -> Self {
        Calibration {
            model,
            mask: None,
            mounting: Mounting::default(),
        }
    }

    /// Loads an OCamCalib `calib_results.txt` or an omnirow TOML calibration (by extension
    /// `.toml`, or by content when the file starts like TOML).
    pub fn load(path: &Path) -> Result<Self, CalibError> {
        let text = std::fs::read_to_string(path).map_err(|source| CalibError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let is_toml = path.extension().is_some_and(|e| e == "toml")
            || text
                .lines()
                .map(str::trim)
                .find(|l| !l.is_empty() && !l.starts_with('#'))
                .is_some_and(|l| l.contains('=') || l.starts_with('['));
        if is_toml {
            Self::parse_toml(&text, path)
        } else {
            Ok(Self::from_model(OcamModel::parse(&text, path)?))
        }
    }

    /// Parses omnirow's TOML calibration: the Taylor model's keys, or a `[pinhole]` table
    /// (a perspective camera, converted to the Taylor model).
    pub fn parse_toml(text: &str, path: &Path) -> Result<Self, CalibError> {
        let raw: CalibrationToml = if pinhole::is_pinhole_toml(text) {
            pinhole::parse_toml(text, path)?.0
        } else {
            toml::from_str(text).map_err(|e| toml_error(text, path, e))?
        };
        let invalid = |problem: String| CalibError::Invalid {
            path: path.to_path_buf(),
            problem,
        };
        let model = OcamModel::new(
            raw.ss,
            raw.invpol,
            (raw.centre[0], raw.centre[1]),
            (raw.affine[0], raw.affine[1], raw.affine[2]),
            (raw.height, raw.width),
        )
        .map_err(invalid)?;
        if let Some(m) = &raw.mask {
            m.validate().map_err(|p| invalid(format!("[mask]: {p}")))?;
        }
        raw.mounting
            .validate()
            .map_err(|p| invalid(format!("[mounting] {p}")))?;
        Ok(Calibration {
            model,
            mask: raw.mask,
            mounting: raw.mounting,
        })
    }

    /// The calibration as omnirow TOML.
    pub fn to_toml(&self) -> String {
        toml::to_string(&self.raw_toml()).unwrap_or_default()
    }

    /// The calibration as the TOML file's keys.
    fn raw_toml(&self) -> CalibrationToml {
        let m = &self.model;
        CalibrationToml {
            height: m.height,
            width: m.width,
            centre: [m.xc, m.yc],
            affine: [m.c, m.d, m.e],
            ss: m.ss.clone(),
            invpol: m.invpol.clone(),
            mask: self.mask,
            mounting: self.mounting,
        }
    }

    /// Image height and width of the calibration.
    pub fn size(&self) -> (u32, u32) {
        (self.model.height, self.model.width)
    }

    /// The same camera at an image size smaller (or larger) by a uniform factor.
    /// Errors when the size is not a uniform scaling of the calibration's.
    pub fn rescaled_to(&self, height: u32, width: u32) -> Result<Self, String> {
        let (h, w) = self.size();
        if (h, w) == (height, width) {
            return Ok(self.clone());
        }
        let fh = h as f64 / height as f64;
        let fw = w as f64 / width as f64;
        if (fh - fw).abs() > 1e-9 {
            return Err(format!(
                "image {height}x{width} is not the calibration's {h}x{w} scaled by one factor ({fh:.4} rows, {fw:.4} columns)"
            ));
        }
        self.rescaled(fh)
    }

    /// The same camera with every pixel quantity divided by `factor` (2 = half resolution).
    pub fn rescaled(&self, factor: f64) -> Result<Self, String> {
        Ok(self.with_model(self.model.rescaled(factor)?, factor))
    }

    /// The same camera through an image reduced by an integer factor, cropping the pixels
    /// past the last whole block (see [`OcamModel::reduced_cropped`]).
    pub fn reduced_cropped(&self, factor: u32) -> Result<Self, String> {
        Ok(self.with_model(self.model.reduced_cropped(factor)?, factor as f64))
    }

    /// This calibration with `model`, a rescaling of its own by `factor`, and its mask's
    /// radii scaled with it.
    fn with_model(&self, model: OcamModel, factor: f64) -> Self {
        Calibration {
            model,
            mask: self.mask.map(|m| FovMask {
                inner_radius_px: m.inner_radius_px / factor,
                outer_radius_px: m.outer_radius_px / factor,
            }),
            mounting: self.mounting,
        }
    }

    /// Distance (pixels) of pixel (row, col) from the image centre.
    #[inline]
    pub fn radius_px(&self, row: f64, col: f64) -> f64 {
        (row - self.model.xc).hypot(col - self.model.yc)
    }

    /// True when pixel (row, col) is inside the image and inside the mask (if any).
    #[inline]
    pub fn pixel_in_fov(&self, row: f64, col: f64) -> bool {
        let m = &self.model;
        if !(row >= -0.5
            && col >= -0.5
            && row < m.height as f64 - 0.5
            && col < m.width as f64 - 0.5)
        {
            return false;
        }
        match &self.mask {
            Some(mask) => {
                let r = self.radius_px(row, col);
                r >= mask.inner_radius_px && r <= mask.outer_radius_px
            }
            None => true,
        }
    }

    /// The pixel (row, col) of a direction (either sign): the sign whose pixel lies inside
    /// the field of view, else inside the image, else `None`. A vanishing point, whose sign
    /// is free, drawn or scored in the image.
    pub fn direction_to_pixel(&self, dir: &Vector3<f64>) -> Option<[f64; 2]> {
        for d in [*dir, -*dir] {
            if let Some(p) = self.ray_to_pixel_in_fov(&d) {
                return Some(p);
            }
        }
        let (h, w) = (self.model.height as f64, self.model.width as f64);
        [*dir, -*dir].iter().find_map(|d| {
            self.model
                .world2cam(d)
                .filter(|p| p[0] >= -0.5 && p[1] >= -0.5 && p[0] < h - 0.5 && p[1] < w - 0.5)
        })
    }

    /// Whether a ray (camera frame) is inside the lens's field of view: the model describes
    /// it, it lands on the sensor, and inside the mask. Returns the pixel when it is.
    #[inline]
    pub fn ray_to_pixel_in_fov(&self, ray: &Vector3<f64>) -> Option<[f64; 2]> {
        let p = self.model.world2cam(ray)?;
        self.pixel_in_fov(p[0], p[1]).then_some(p)
    }

    /// Whether a ray (camera frame) is inside the lens's field of view.
    pub fn ray_in_fov(&self, ray: &Vector3<f64>) -> bool {
        self.ray_to_pixel_in_fov(ray).is_some()
    }

    /// Radius (pixels) of the inscribed circle: centre to the nearest image border.
    pub fn inscribed_radius_px(&self) -> f64 {
        let m = &self.model;
        let (h, w) = (m.height as f64 - 1.0, m.width as f64 - 1.0);
        m.xc.min(m.yc).min(h - m.xc).min(w - m.yc)
    }

    /// Radius (pixels, along the column axis) of the horizon: rays 90° from the optical axis.
    pub fn horizon_radius_px(&self) -> Option<f64> {
        self.model
            .rho_of_theta(0.0)
            .map(|rho| self.radius_of_rho(rho))
    }

    /// Pixel radius of an ideal radius rho along the column axis (affine applied).
    fn radius_of_rho(&self, rho: f64) -> f64 {
        let m = &self.model;
        (rho * m.d).hypot(rho)
    }

    /// Worst pixel → ray → pixel round-trip error (pixels) over a grid of pixels inside the
    /// field of view (or the model's valid range when there is no mask), and where it occurs.
    pub fn worst_round_trip_px(&self, step: usize) -> (f64, [f64; 2]) {
        let m = &self.model;
        let mut worst = (0.0, [m.xc, m.yc]);
        for row in (0..m.height as usize).step_by(step.max(1)) {
            for col in (0..m.width as usize).step_by(step.max(1)) {
                let (r, c) = (row as f64, col as f64);
                if !self.pixel_in_fov(r, c) || !self.pixel_in_model_range(r, c) {
                    continue;
                }
                let ray = m.cam2world(r, c);
                if let Some(p) = m.world2cam(&ray) {
                    let err = (p[0] - r).hypot(p[1] - c);
                    if err > worst.0 {
                        worst = (err, [r, c]);
                    }
                } else {
                    return (f64::INFINITY, [r, c]);
                }
            }
        }
        worst
    }

    /// True when pixel (row, col) lies within the radius where the model is monotone.
    pub fn pixel_in_model_range(&self, row: f64, col: f64) -> bool {
        let ray = self.model.cam2world(row, col);
        let norm = ray.x.hypot(ray.y);
        let theta = ray.z.atan2(norm);
        let (lo, hi) = self.model.theta_range();
        theta >= lo && theta <= hi
    }
}

/// A TOML parse error as a calibration error naming the file and the line.
fn toml_error(text: &str, path: &Path, e: toml::de::Error) -> CalibError {
    let line = e
        .span()
        .map(|s| text[..s.start.min(text.len())].matches('\n').count() + 1)
        .unwrap_or(1);
    CalibError::Parse {
        path: path.to_path_buf(),
        line,
        problem: e.message().to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_mounting_looks_down_top_forward() {
        let r = Mounting::default().robot_from_camera();
        // optical axis (-z camera) points down in the robot frame
        assert!((r * Vector3::new(0.0, 0.0, -1.0) - Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-12);
        // image up (-x camera) points forward
        assert!((r * Vector3::new(-1.0, 0.0, 0.0) - Vector3::new(1.0, 0.0, 0.0)).norm() < 1e-12);
        // image right (+y camera) points to the robot's right (-y robot)
        assert!((r * Vector3::new(0.0, 1.0, 0.0) - Vector3::new(0.0, -1.0, 0.0)).norm() < 1e-12);
    }

    #[test]
    fn toml_round_trip_and_errors() {
        let cal = ideal_fisheye(2050, 2448).unwrap();
        let text = cal.to_toml();
        let back = Calibration::parse_toml(&text, Path::new("c.toml")).unwrap();
        assert_eq!(back.model.ss, cal.model.ss);
        assert_eq!(back.mask, cal.mask);
        let bad = text.replace("height", "heigth");
        let e = Calibration::parse_toml(&bad, Path::new("c.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("c.toml:1") && e.contains("heigth"), "{e}");
        let bad = format!("{text}\n[extra]\nx = 1\n");
        let e = Calibration::parse_toml(&bad, Path::new("c.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("extra"), "{e}");
    }

    #[test]
    fn mounting_height_and_position_keys() {
        let cal = ideal_fisheye(2050, 2448).unwrap();
        let text = cal.to_toml();
        assert!(text.contains("height_m = 1.0"), "{text}");
        let back = Calibration::parse_toml(&text, Path::new("c.toml")).unwrap();
        assert_eq!(back.mounting, Mounting::default());
        // a file without the new keys keeps the defaults
        let old = text
            .lines()
            .filter(|l| !l.starts_with("height_m") && !l.starts_with("position_m"))
            .collect::<Vec<_>>()
            .join("\n");
        let back = Calibration::parse_toml(&old, Path::new("c.toml")).unwrap();
        assert_eq!(back.mounting.height_m, 1.0);
        for (good, bad, key) in [
            ("height_m = 1.0", "height_m = 0.0", "height_m"),
            ("height_m = 1.0", "height_m = -1.0", "height_m"),
            (
                "position_m = [0.0, 0.0, 0.0]",
                "position_m = [0.0, 100.0, 0.0]",
                "position_m",
            ),
        ] {
            assert!(text.contains(good), "{text}");
            let t = text.replace(good, bad);
            let e = Calibration::parse_toml(&t, Path::new("c.toml"))
                .unwrap_err()
                .to_string();
            assert!(e.contains(key) && e.contains("[mounting]"), "{e}");
        }
    }

    #[test]
    fn fov_test_for_rays() {
        let cal = ideal_fisheye(2050, 2448).unwrap();
        assert!(cal.ray_in_fov(&Vector3::new(0.0, 0.0, -1.0)));
        assert!(!cal.ray_in_fov(&Vector3::new(0.0, 0.0, 1.0)));
        // 91 degrees off axis is inside a 185 degree fisheye
        let a = 91f64.to_radians();
        assert!(cal.ray_in_fov(&Vector3::new(a.sin(), 0.0, -a.cos())));
        let a = 95f64.to_radians();
        assert!(!cal.ray_in_fov(&Vector3::new(a.sin(), 0.0, -a.cos())));
        let pal = ideal_pal(2050, 2448).unwrap();
        let a = 10f64.to_radians();
        assert!(!pal.ray_in_fov(&Vector3::new(a.sin(), 0.0, -a.cos())));
        let a = 60f64.to_radians();
        assert!(pal.ray_in_fov(&Vector3::new(a.sin(), 0.0, -a.cos())));
    }

    #[test]
    fn rescale_to_half() {
        let cal = ideal_pal(2050, 2448).unwrap();
        let half = cal.rescaled_to(1025, 1224).unwrap();
        assert_eq!(half.size(), (1025, 1224));
        let m = half.mask.unwrap();
        assert!((m.outer_radius_px * 2.0 - cal.mask.unwrap().outer_radius_px).abs() < 1e-9);
        assert!(cal.rescaled_to(1000, 1224).is_err());
    }
}
