//! The synthetic field: parallel crop rows rendered through any calibration, with ground truth.
//!
//! Owns the paper's section III-B reproduced and extended: the field model (rows, plants with
//! four leaves, weeds), the camera pose over it, the renderer (supersampled, greyscale or
//! colour or Bayer), the three kinds of noise, and the ground truth of every image; and a
//! second, independently designed appearance (`leafy`, in `appearance`) for the same scenes;
//! and in place of the synthetic plants, a ground textured from a real labelled photograph
//! ([`photo`], chosen by the scene's [`Ground`]).
//!
//! Typical use: [`render`] for one image, or a [`Renderer`] built once per calibration and a
//! [`Scene`] per image for many. Everything follows from [`SynthOptions`] and a `u64` seed.

mod appearance;
mod bayer;
mod field;
mod noise;
mod options;
pub mod photo;
mod pose;
mod protocol;
mod render;
mod rng;
mod scene;
mod style;
mod truth;

pub use bayer::mosaic;
pub use field::{Cover, Field, PlantShape};
pub use noise::{salt_and_pepper, Blur};
pub use options::{Style, SynthOptions};
pub use pose::Pose;
pub use protocol::{random_scene, Protocol};
pub use render::Renderer;
pub use rng::Rng;
pub use scene::{Ground, Scene};
pub use style::{Palette, Texture};
// The truth of every image; frames carry it, so it is defined with them.
pub use crate::frame::{GroundTruth, NoiseTruth};

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

impl SynthImage {
    /// The image as a pipeline frame carrying its ground truth, stamped now.
    pub fn into_frame(self, seq: u64, truth: GroundTruth) -> crate::frame::Frame {
        let now = crate::frame::now_ns();
        crate::frame::Frame {
            seq,
            capture_ns: now,
            receive_ns: now,
            width: self.width,
            height: self.height,
            format: self.format,
            data: self.data,
            truth: Some(std::sync::Arc::new(truth)),
        }
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::ideal_pal;

    #[test]
    fn render_gives_an_image_in_the_style_format_and_its_truth() {
        let cal = ideal_pal(128, 154).unwrap();
        let opts = SynthOptions {
            style: Style::Bayer,
            yaw_deg: 5.0,
            ..Default::default()
        };
        let (img, truth) = render(&cal, &opts, 21).unwrap();
        assert_eq!((img.width, img.height), (154, 128));
        assert_eq!(img.format, PixelFormat::BayerRggb8);
        assert_eq!(img.data.len(), 154 * 128);
        assert_eq!(truth.seed, 21);
        let frame = img.into_frame(3, truth);
        assert!(frame.view().is_ok());
        assert_eq!(frame.truth.as_ref().unwrap().seed, 21);
        let bad = SynthOptions {
            row_spacing_m: 0.0,
            ..Default::default()
        };
        let e = render(&cal, &bad, 1).unwrap_err().to_string();
        assert!(e.contains("row_spacing_m"), "{e}");
    }
}
