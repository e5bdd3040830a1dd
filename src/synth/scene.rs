//! One synthetic scene: the field, the camera pose over it, and the look, all from options
//! and a seed.
//!
//! Owns [`Scene`], the immutable input of the renderer and of the ground truth. Building it
//! draws every random quantity of the world (plant position errors, weeds, soil texture) from
//! the seed, so that the same options and seed always give the same image and truth. The
//! ground is the synthetic plants or a texture from a photograph ([`Ground`]).

use super::field::Field;
use super::options::SynthOptions;
use super::photo::PhotoGround;
use super::pose::Pose;
use super::style::{Palette, Texture};
use super::SynthError;
use crate::camera::Mounting;
use nalgebra::Vector3;
use std::sync::Arc;

/// What covers the ground: the synthetic field's plants on soil, or a texture rectified from a
/// labelled photograph (its rows at the same lateral positions k·spacing as the field's, so
/// that the ground truth holds unchanged).
#[derive(Debug, Clone, Default)]
pub enum Ground {
    #[default]
    Synthetic,
    Photo(Arc<PhotoGround>),
}

/// A field, a camera pose over it, and how it looks.
#[derive(Debug, Clone)]
pub struct Scene {
    pub options: SynthOptions,
    pub seed: u64,
    pub pose: Pose,
    pub field: Field,
    pub palette: Palette,
    pub texture: Texture,
    pub ground: Ground,
}

impl Scene {
    /// Builds the scene of `options` for a camera with `mounting`, drawing from `seed`.
    pub fn new(options: &SynthOptions, seed: u64, mounting: &Mounting) -> Result<Self, SynthError> {
        options.validate()?;
        let o = options;
        let centre = Vector3::new(o.along_m, o.lateral_m, o.height_m);
        let pose = Pose::new(
            o.yaw_deg.to_radians(),
            o.pitch_deg.to_radians(),
            o.roll_deg.to_radians(),
            mounting,
            centre,
        );
        Ok(Scene {
            options: o.clone(),
            seed,
            pose,
            field: Field::new(o, seed, [o.along_m, o.lateral_m]),
            palette: Palette::default(),
            texture: Texture::new(seed),
            ground: Ground::Synthetic,
        })
    }

    /// The scene with the photograph's ground in place of the synthetic plants. Errors when
    /// an option describes what the texture cannot show: a row spacing other than the one
    /// the photograph was rectified at, curved rows, rows' end, a gap, plant position errors,
    /// weeds, or the `leafy` style.
    pub fn with_photo_ground(mut self, ground: Arc<PhotoGround>) -> Result<Self, SynthError> {
        let o = &self.options;
        let bad = |name: &'static str, value: String, reason: &str| {
            Err(SynthError::InvalidOption {
                name,
                value,
                reason: reason.to_string(),
            })
        };
        let s = ground.row_spacing_m();
        if (o.row_spacing_m - s).abs() > 1e-9 * s {
            return bad(
                "row_spacing_m",
                o.row_spacing_m.to_string(),
                &format!("must equal the photograph's rectification spacing {s} m"),
            );
        }
        let unsupported = [
            (
                "curvature_per_m",
                o.curvature_per_m != 0.0,
                o.curvature_per_m.to_string(),
            ),
            (
                "rows_end_m",
                o.rows_end_m.is_some(),
                format!("{:?}", o.rows_end_m),
            ),
            ("gap_m", o.gap_m.is_some(), format!("{:?}", o.gap_m)),
            ("along_sd_m", o.along_sd_m != 0.0, o.along_sd_m.to_string()),
            (
                "across_sd_m",
                o.across_sd_m != 0.0,
                o.across_sd_m.to_string(),
            ),
            ("weeds", o.weeds != 0, o.weeds.to_string()),
            ("style", o.style == super::Style::Leafy, "leafy".to_string()),
        ];
        if let Some((name, _, value)) = unsupported.into_iter().find(|u| u.1) {
            return bad(name, value, "is not supported with a photograph's ground");
        }
        self.ground = Ground::Photo(ground);
        Ok(self)
    }
}
