//! The synthetic field: parallel crop rows rendered through any calibration, with ground truth.
//!
//! Owns the paper's section III-B reproduced and extended: the field model (rows, plants with
//! four leaves, weeds), the camera pose over it, the renderer (supersampled, greyscale or
//! colour or Bayer), the three kinds of noise, and the ground truth of every image.
//!
//! Typical use: [`render`] for one image, or a [`Renderer`] built once per calibration and a
//! [`Scene`] per image for many. Everything follows from [`SynthOptions`] and a `u64` seed.

mod bayer;
mod field;
mod noise;
mod options;
mod pose;
mod protocol;
mod render;
mod rng;
mod scene;
mod style;
mod truth;

pub use bayer::mosaic;
pub use field::{Cover, Field, PlantShape};
pub use noise::{gaussian_blur, salt_and_pepper};
pub use options::{Style, SynthOptions};
pub use pose::Pose;
pub use protocol::{random_scene, Protocol};
pub use render::Renderer;
pub use rng::Rng;
pub use scene::Scene;
pub use style::{Palette, Texture};
pub use truth::{GroundTruth, NoiseTruth};

use crate::camera::Calibration;
use crate::frame::PixelFormat;

/// An error building or rendering a synthetic image.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    #[error("synthetic field option {name} = {value}: {reason}")]
    InvalidOption {
        name: &'static str,
        value: String,
        reason: String,
    },
    #[error("calibration cannot be rendered: {0}")]
    Calibration(String),
    #[error("image buffer holds {actual} bytes, the image needs {expected}")]
    BufferSize { expected: usize, actual: usize },
}

/// A rendered synthetic image.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SynthImage {
    pub width: u32,
    pub height: u32,
    pub format: PixelFormat,
    /// Row-major pixels without padding.
    pub data: Vec<u8>,
}

/// Renders one image of `options` through `cal` from `seed`, with its ground truth.
/// (For many images through one calibration, keep a [`Renderer`].)
pub fn render(
    cal: &Calibration,
    options: &SynthOptions,
    seed: u64,
) -> Result<(SynthImage, GroundTruth), SynthError> {
    let scene = Scene::new(options, seed, &cal.mounting)?;
    let mut renderer = Renderer::new(cal)?;
    let mut data = vec![0u8; renderer.buffer_len(options.style)];
    renderer.render_into(&scene, &mut data)?;
    let (width, height) = renderer.size();
    let truth = GroundTruth::of_scene(&scene, cal);
    Ok((
        SynthImage {
            width,
            height,
            format: options.style.pixel_format(),
            data,
        },
        truth,
    ))
}
