//! Settings of one synthetic image: the field, the camera pose over it, the noise, the style.
//!
//! Owns [`SynthOptions`] (serde, unknown keys rejected), [`Style`], and their validation. Every
//! length is in metres, every angle in degrees; the defaults are a 1 m high camera over rows
//! 0.5 m apart with a plant every 0.15 m, no noise, greyscale.

use serde::{Deserialize, Serialize};

/// How the image looks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Style {
    /// The paper's: bright plants on a dark background, one grey byte per pixel (Mono8).
    #[default]
    Grey,
    /// Green plants on textured brown soil, sky above the horizon (Rgb8).
    Colour,
    /// The colour image as the GC2450C delivers it raw: an RGGB Bayer mosaic (BayerRggb8).
    Bayer,
    /// The second, independently designed appearance (src/synth/appearance.rs): leaf-cluster
    /// plants, supersampled, uneven light, lens blur, Bayer mosaic demosaiced, JPEG (Rgb8).
    Leafy,
}

impl Style {
    /// The pixel format of images in this style.
    pub fn pixel_format(self) -> crate::frame::PixelFormat {
        use crate::frame::PixelFormat;
        match self {
            Style::Grey => PixelFormat::Mono8,
            Style::Colour | Style::Leafy => PixelFormat::Rgb8,
            Style::Bayer => PixelFormat::BayerRggb8,
        }
    }
}

/// Settings of one synthetic image.
///
/// World frame: ground plane z = 0, rows along +X through y = i·`row_spacing_m`, the camera at
/// (`along_m`, `lateral_m`, `height_m`). Robot attitude relative to the rows:
/// R_world_robot = Rz(yaw)·Ry(pitch)·Rx(roll).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SynthOptions {
    /// Robot yaw relative to the rows (about world up), degrees.
    pub yaw_deg: f64,
    /// Robot pitch (about its left axis; positive pitches the nose down), degrees.
    pub pitch_deg: f64,
    /// Robot roll (about its forward axis), degrees.
    pub roll_deg: f64,
    /// Camera height above the ground, metres.
    pub height_m: f64,
    /// Camera position across the rows (world y), metres; row 0 runs along y = 0.
    pub lateral_m: f64,
    /// Camera position along the rows (world x), metres; plant 0 of every row is at x = 0.
    pub along_m: f64,
    /// Distance between neighbouring rows, metres.
    pub row_spacing_m: f64,
    /// Distance between neighbouring plants in a row, metres.
    pub plant_distance_m: f64,
    /// Length of each of a plant's four leaves (stem to tip), metres.
    pub leaf_length_m: f64,
    /// Width of each leaf, metres.
    pub leaf_width_m: f64,
    /// The field's rows run from x = −this to x = +this, metres.
    pub field_half_length_m: f64,
    /// The field holds the rows with |y| ≤ this, metres.
    pub field_half_width_m: f64,
    /// Curvature of the rows, 1/m (0: straight rows). Positive bends them to the left (REP
    /// 103) as the robot drives forward: the rows are concentric circles about the centre
    /// (`along_m`, 1/curvature), row 0 (y = 0) of radius 1/|curvature|, row i of curvature
    /// `c / (1 − c·i·spacing)`. The field is laid out in the
    /// robot's tangent frame: the rows run along +X at the camera's `along_m` (so `yaw_deg`,
    /// `lateral_m` and the truth's row lines are relative to the rows' tangents there), and
    /// `along_m` is arc length along row 0. Rows farther than 0.8/|curvature| across are left
    /// out (they would wrap round the centre).
    pub curvature_per_m: f64,
    /// Where the rows end (the headland beyond is bare ground), metres along the rows (world
    /// x; arc length along row 0 in a curved field); `None`: at `field_half_length_m`.
    pub rows_end_m: Option<f64>,
    /// An empty stretch across every row, [from, to] metres along the rows: no plant grows
    /// there (a gap in the crop, a track, a bare patch).
    pub gap_m: Option<[f64; 2]>,
    /// Background noise: salt-and-pepper density (0..1) before the Gaussian smoothing.
    pub noise: f64,
    /// Standard deviation of the Gaussian smoothing that follows the salt and pepper, pixels.
    pub noise_blur_px: f64,
    /// Standard deviation of each plant's position error along its row, metres.
    pub along_sd_m: f64,
    /// Standard deviation of each plant's position error across its row, metres (bends rows).
    pub across_sd_m: f64,
    /// Number of weeds: plants at uniformly random positions.
    pub weeds: usize,
    /// Weeds are scattered over the square of this half-size around the camera, metres.
    pub weed_area_half_m: f64,
    /// Image style (and with it the pixel format).
    pub style: Style,
    /// Supersampling: samples per pixel along each axis where a pixel needs them.
    pub samples: u32,
    /// A row is listed in the ground truth when it is visible over at least this image length,
    /// pixels, apart from its neighbours by at least `min_row_separation_px`.
    pub min_row_length_px: f64,
    /// Smallest distance, pixels, from the neighbouring rows for a row point to count as seen.
    pub min_row_separation_px: f64,
}

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions {
            yaw_deg: 0.0,
            pitch_deg: 0.0,
            roll_deg: 0.0,
            height_m: 1.0,
            lateral_m: 0.25,
            along_m: 0.0,
            row_spacing_m: 0.5,
            plant_distance_m: 0.15,
            leaf_length_m: 0.04,
            leaf_width_m: 0.015,
            field_half_length_m: 150.0,
            field_half_width_m: 150.0,
            curvature_per_m: 0.0,
            rows_end_m: None,
            gap_m: None,
            noise: 0.0,
            noise_blur_px: 1.0,
            along_sd_m: 0.0,
            across_sd_m: 0.0,
            weeds: 0,
            weed_area_half_m: 10.0,
            style: Style::Grey,
            samples: 4,
            min_row_length_px: 30.0,
            min_row_separation_px: 2.0,
        }
    }
}

/// The most plants a field may hold (rows × plants per row), to bound memory and time.
pub const MAX_PLANTS: f64 = 2.0e7;

impl SynthOptions {
    /// Checks every setting; the error names the setting and what is wrong.
    pub fn validate(&self) -> Result<(), super::SynthError> {
        let bad = |name: &'static str, value: f64, reason: &str| {
            Err(super::SynthError::InvalidOption {
                name,
                value: value.to_string(),
                reason: reason.to_string(),
            })
        };
        for (name, v) in [("yaw_deg", self.yaw_deg), ("roll_deg", self.roll_deg)] {
            if !(v.is_finite() && v.abs() <= 180.0) {
                return bad(name, v, "must be an angle within ±180 degrees");
            }
        }
        if !(self.pitch_deg.is_finite() && self.pitch_deg.abs() < 90.0) {
            return bad(
                "pitch_deg",
                self.pitch_deg,
                "must be within ±90 degrees (exclusive)",
            );
        }
        if !(self.height_m.is_finite() && self.height_m > 0.0 && self.height_m <= 100.0) {
            return bad("height_m", self.height_m, "must be in (0, 100] metres");
        }
        for (name, v) in [("lateral_m", self.lateral_m), ("along_m", self.along_m)] {
            if !(v.is_finite() && v.abs() <= 1000.0) {
                return bad(name, v, "must be within ±1000 metres");
            }
        }
        for (name, v) in [
            ("row_spacing_m", self.row_spacing_m),
            ("plant_distance_m", self.plant_distance_m),
            ("leaf_length_m", self.leaf_length_m),
            ("leaf_width_m", self.leaf_width_m),
            ("field_half_length_m", self.field_half_length_m),
            ("field_half_width_m", self.field_half_width_m),
            ("weed_area_half_m", self.weed_area_half_m),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= 10_000.0) {
                return bad(name, v, "must be a positive length up to 10 km");
            }
        }
        if !(self.curvature_per_m.is_finite() && self.curvature_per_m.abs() <= 0.2) {
            return bad(
                "curvature_per_m",
                self.curvature_per_m,
                "must be within ±0.2 per metre (radius 5 m or more)",
            );
        }
        if let Some(e) = self.rows_end_m {
            if !(e.is_finite() && e.abs() <= 10_000.0) {
                return bad("rows_end_m", e, "must be within ±10 km");
            }
        }
        if let Some([a, b]) = self.gap_m {
            if !(a.is_finite() && b.is_finite() && a < b && a.abs().max(b.abs()) <= 10_000.0) {
                return bad(
                    "gap_m",
                    b - a,
                    "must be [from, to] with from < to, within ±10 km",
                );
            }
        }
        if self.plant_distance_m < 0.005 {
            return bad(
                "plant_distance_m",
                self.plant_distance_m,
                "must be at least 0.005 m",
            );
        }
        if self.leaf_width_m > self.leaf_length_m * 2.0 {
            return bad(
                "leaf_width_m",
                self.leaf_width_m,
                "must not exceed twice the leaf length",
            );
        }
        let plants = (2.0 * self.field_half_length_m / self.plant_distance_m + 1.0)
            * (2.0 * self.field_half_width_m / self.row_spacing_m + 1.0);
        if plants > MAX_PLANTS && (self.along_sd_m > 0.0 || self.across_sd_m > 0.0) {
            return bad(
                "plant_distance_m",
                self.plant_distance_m,
                &format!(
                    "with plant position noise the field would hold {plants:.0} plants (at most {MAX_PLANTS:.0}); make the field smaller or the plants sparser"
                ),
            );
        }
        if !(self.noise.is_finite() && (0.0..=1.0).contains(&self.noise)) {
            return bad("noise", self.noise, "must be a density in [0, 1]");
        }
        if !(self.noise_blur_px.is_finite() && (0.0..=20.0).contains(&self.noise_blur_px)) {
            return bad(
                "noise_blur_px",
                self.noise_blur_px,
                "must be in [0, 20] pixels",
            );
        }
        for (name, v) in [
            ("along_sd_m", self.along_sd_m),
            ("across_sd_m", self.across_sd_m),
        ] {
            if !(v.is_finite() && (0.0..=10.0).contains(&v)) {
                return bad(name, v, "must be a standard deviation in [0, 10] metres");
            }
        }
        if self.weeds > 1_000_000 {
            return bad("weeds", self.weeds as f64, "at most 1000000 weeds");
        }
        if !(1..=16).contains(&self.samples) {
            return bad("samples", self.samples as f64, "must be 1..=16 per axis");
        }
        for (name, v) in [
            ("min_row_length_px", self.min_row_length_px),
            ("min_row_separation_px", self.min_row_separation_px),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(name, v, "must be a non-negative number of pixels");
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_unknown_keys_rejected() {
        SynthOptions::default().validate().unwrap();
        let o: SynthOptions = serde_json::from_str(r#"{"yaw_deg": 12.5}"#).unwrap();
        assert_eq!(o.yaw_deg, 12.5);
        assert_eq!(o.height_m, 1.0);
        let e = serde_json::from_str::<SynthOptions>(r#"{"yaw": 1}"#).unwrap_err();
        assert!(e.to_string().contains("yaw"), "{e}");
    }

    #[test]
    fn invalid_settings_are_named() {
        let o = SynthOptions {
            noise: 1.5,
            ..Default::default()
        };
        let e = o.validate().unwrap_err().to_string();
        assert!(e.contains("noise") && e.contains("1.5"), "{e}");
        let o = SynthOptions {
            height_m: -1.0,
            ..Default::default()
        };
        assert!(o.validate().unwrap_err().to_string().contains("height_m"));
        let o = SynthOptions {
            pitch_deg: 90.0,
            ..Default::default()
        };
        assert!(o.validate().unwrap_err().to_string().contains("pitch_deg"));
    }
}
