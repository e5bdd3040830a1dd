//! One synthetic scene: the field, the camera pose over it, and the look, all from options
//! and a seed.
//!
//! Owns [`Scene`], the immutable input of the renderer and of the ground truth. Building it
//! draws every random quantity of the world (plant position errors, weeds, soil texture) from
//! the seed, so that the same options and seed always give the same image and truth.

use super::field::Field;
use super::options::SynthOptions;
use super::pose::Pose;
use super::style::{Palette, Texture};
use super::SynthError;
use crate::camera::Mounting;
use nalgebra::Vector3;

/// A field, a camera pose over it, and how it looks.
#[derive(Debug, Clone)]
pub struct Scene {
    pub options: SynthOptions,
    pub seed: u64,
    pub pose: Pose,
    pub field: Field,
    pub palette: Palette,
    pub texture: Texture,
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
        })
    }
}
