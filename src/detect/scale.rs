//! The detector's scales for one calibration: how large the field of view is and how many
//! working-image pixels one radian of the sphere spans there, the angular options derived from
//! them, and each option's angle in pixels (or pixel length in degrees).
//!
//! Owns [`angular_resolution`] (pixels per radian at the image centre and the median over the
//! field of view at the detector's working resolution, and the field of view's extent),
//! [`angle_factor`] (the factor every angular scale's reference value is multiplied by for a
//! calibration) and [`scaled_bins`]. The stages derive their angular scales from the factor;
//! [`super::options::resolve`] picks it (the `angle_scale` option, else derived) and
//! [`super::options::scales_report`] prints the values in force (`omnirow config detector
//! --calib FILE`).
//!
//! The reference values (2° Hough cells, 1° vanishing cells and inlier band, …) were tuned on
//! the GC2450C's lenses, whose fields of view span 6.56 sr (an extent, the square root, of
//! [`REFERENCE_EXTENT_RAD`]). A calibration whose field of view has the extent `e` gets the
//! factor `e / REFERENCE_EXTENT_RAD`, rounded to an eighth of an octave (a 9 % step, so that
//! both GC2450C lenses and any recalibration of them keep exactly the reference values the
//! synthetic tables were measured with) and at most 1. The angular scales are thus a fixed
//! share of the field of view: the same in pixels for one image read with two focal-length
//! guesses (the image, not the angles, holds the rows), and the same in angle for one lens at
//! two resolutions (a 4× finer image of the same scene gives the same rows). Scales that
//! follow the pixel size instead (measured: CRDLD at f = 300 and 900 px gave the same scores
//! either way) make a finer image of the same lens split its wide rows into narrow cells and
//! lose them (tests/detect_scale.rs).

use super::vegetation::Binning;
use crate::camera::Calibration;

/// The field of view's extent (radians, the square root of its solid angle) at which the
/// angular options' reference values hold: the GC2450C's ideal fisheye (2.562) and PAL (2.556).
pub const REFERENCE_EXTENT_RAD: f64 = 2.56;

/// The factor is rounded to this fraction of an octave.
const FACTOR_STEPS_PER_OCTAVE: f64 = 8.0;

/// Angular resolution of a calibration at the detector's working resolution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AngularResolution {
    /// Working image size (width, height) and the reduction from the calibration's size.
    pub width: u32,
    pub height: u32,
    pub factor: u32,
    /// Pixels per radian at the principal point.
    pub centre_px_per_rad: f64,
    /// Median over the field of view (a grid of about 4000 pixels) of the pixels per radian
    /// (one over the square root of each pixel's solid angle).
    pub median_px_per_rad: f64,
    /// The field of view's angular extent (radians): the square root of its solid angle
    /// (the masked pixels' solid angles summed). The same for any resolution of one lens.
    pub extent_rad: f64,
}

/// The angular resolution of `cal` (at its own size, binned as `binning` would bin an RGB or
/// mono image of that size).
pub fn angular_resolution(
    cal: &Calibration,
    binning: Binning,
) -> Result<AngularResolution, String> {
    let (h, w) = (cal.model.height, cal.model.width);
    let bin = binning.bins(w, h);
    let factor = if bin { 2 } else { 1 };
    let work = if bin { cal.rescaled(2.0)? } else { cal.clone() };
    let m = &work.model;
    let px_per_rad = |r: f64, c: f64| -> Option<f64> {
        let dr = m.cam2world(r + 0.5, c) - m.cam2world(r - 0.5, c);
        let dc = m.cam2world(r, c + 0.5) - m.cam2world(r, c - 0.5);
        let omega = dr.cross(&dc).norm();
        (omega > 0.0 && omega.is_finite()).then(|| 1.0 / omega.sqrt())
    };
    let centre = px_per_rad(m.xc, m.yc).ok_or("no pixel size at the principal point")?;
    let (wh, ww) = (m.height as usize, m.width as usize);
    let step = ((wh * ww) as f64 / 4000.0).sqrt().max(1.0) as usize;
    let mut v: Vec<f64> = Vec::new();
    let mut solid = 0.0;
    // Over the field of view; over the whole image when the mask leaves no pixel (the
    // detector then reports the mask for each image).
    for use_mask in [true, false] {
        for r in (step / 2..wh).step_by(step) {
            for c in (step / 2..ww).step_by(step) {
                let (rf, cf) = (r as f64, c as f64);
                if use_mask && work.mask.is_some_and(|_| !work.pixel_in_fov(rf, cf)) {
                    continue;
                }
                if let Some(p) = px_per_rad(rf, cf) {
                    v.push(p);
                    // the sample stands for step × step pixels (fewer at the far edges)
                    let rows = step.min(wh - (r - step / 2)) as f64;
                    let cols = step.min(ww - (c - step / 2)) as f64;
                    solid += rows * cols / (p * p);
                }
            }
        }
        if !v.is_empty() {
            break;
        }
    }
    if v.is_empty() {
        return Err("no pixel of the image has a ray".into());
    }
    v.sort_unstable_by(f64::total_cmp);
    Ok(AngularResolution {
        width: m.width,
        height: m.height,
        factor,
        centre_px_per_rad: centre,
        median_px_per_rad: v[v.len() / 2],
        extent_rad: solid.sqrt(),
    })
}

/// The factor the angular options' reference values are multiplied by for a field of view
/// of `a`'s extent: `extent / REFERENCE_EXTENT_RAD`, rounded to an eighth of an octave, at
/// most 1.
pub fn angle_factor(a: &AngularResolution) -> f64 {
    let k = a.extent_rad / REFERENCE_EXTENT_RAD;
    let steps = (k.log2() * FACTOR_STEPS_PER_OCTAVE).round();
    2f64.powf(steps / FACTOR_STEPS_PER_OCTAVE).min(1.0)
}

/// An accumulator's cells for `reference` cells at the reference angular resolution and
/// angular scales `angle_factor` times their reference values: rounded, at least 4.
pub fn scaled_bins(reference: usize, angle_factor: f64) -> usize {
    ((reference as f64 / angle_factor).round() as usize).max(4)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::ideal_fisheye;

    #[test]
    fn resolution_scales_with_the_image() {
        let big = ideal_fisheye(1200, 1200).unwrap();
        let small = ideal_fisheye(300, 300).unwrap();
        let (a, b) = (
            angular_resolution(&big, Binning::Auto).unwrap(),
            angular_resolution(&small, Binning::Auto).unwrap(),
        );
        assert_eq!((a.factor, b.factor), (1, 1));
        let r = a.median_px_per_rad / b.median_px_per_rad;
        assert!((r - 4.0).abs() < 0.1, "{a:?} {b:?}");
        // the same lens at two resolutions: the same extent, the same factor
        assert!((a.extent_rad - b.extent_rad).abs() < 0.01, "{a:?} {b:?}");
        assert_eq!(angle_factor(&a), angle_factor(&b));
    }

    #[test]
    fn binning_halves_the_resolution() {
        let cal = ideal_fisheye(2050, 2448).unwrap();
        let a = angular_resolution(&cal, Binning::Auto).unwrap();
        assert_eq!((a.factor, a.width, a.height), (2, 1224, 1025));
        let b = angular_resolution(&cal, Binning::Off).unwrap();
        let r = b.centre_px_per_rad / a.centre_px_per_rad;
        assert!((r - 2.0).abs() < 0.01, "{a:?} {b:?}");
    }

    #[test]
    fn bins_scale_inversely_with_the_factor_and_never_vanish() {
        assert_eq!(scaled_bins(90, 1.0), 90);
        assert_eq!(scaled_bins(90, 0.5), 180);
        assert_eq!(scaled_bins(90, 100.0), 4);
    }
}
