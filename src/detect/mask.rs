//! Which pixels may carry rows (paper II-C and III-C): the lens's field of view and the sky.
//!
//! Owns two things. (1) The field-of-view mask: the calibration's circle or annulus (already
//! rescaled with it), shrunk by a margin; or, when the calibration has none, the lens's image
//! circle found from the image itself ([`find_fov`]: the radial profile of brightness from the
//! centre, dark outside the rim and, for a catadioptric lens, inside the blind disc). (2) The
//! sky: rays whose elevation in the robot frame (through the mounting rotation) exceeds the
//! largest expected tilt cannot see the ground, so they carry no rows. (On colour images the
//! vegetation index already rejects a blue or grey sky; this geometric test also works on
//! greyscale input.)
//! The per-pixel ray table the Hough stage needs is built in the same pass.

use super::types::DetectError;
use crate::camera::{Calibration, FovMask};
use crate::frame::ImageView;
use serde::{Deserialize, Serialize};

/// Options of the mask.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MaskOptions {
    /// Pixels (working resolution) removed inside the field-of-view rim (and outside the blind disc).
    pub fov_margin_px: f64,
    /// Whether to mask the sky.
    pub sky: bool,
}

impl Default for MaskOptions {
    fn default() -> Self {
        MaskOptions {
            fov_margin_px: 2.0,
            sky: true,
        }
    }
}

impl MaskOptions {
    pub fn validate(&self) -> Result<(), DetectError> {
        if !(self.fov_margin_px.is_finite() && self.fov_margin_px >= 0.0) {
            return Err(DetectError::Options(format!(
                "mask.fov_margin_px = {} must be >= 0",
                self.fov_margin_px
            )));
        }
        Ok(())
    }
}

/// What the mask pass produced.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MaskResult {
    /// Pixels that may carry rows.
    pub valid: usize,
    /// Pixels removed as sky.
    pub sky: usize,
}

/// Builds the mask of a working image described by `cal` (its size, its field-of-view mask
/// if any, its mounting; rays higher than `max_tilt_deg` above the robot's horizontal plane
/// are sky) into `mask` (0xFF = use, 0 = ignore), the unit ray of every
/// pixel into `rays` (camera frame, f32; zero for masked pixels) and the solid angle each
/// pixel covers into `solid` (relative to the image centre's pixel; zero for masked
/// pixels), so that sums over pixels become integrals over the sphere whatever the lens's
/// mapping. Buffers are resized.
pub fn build_mask(
    cal: &Calibration,
    opts: &MaskOptions,
    max_tilt_deg: f64,
    mask: &mut Vec<u8>,
    rays: &mut Vec<[f32; 3]>,
    solid: &mut Vec<f32>,
) -> Result<MaskResult, DetectError> {
    opts.validate()?;
    if !(max_tilt_deg.is_finite() && (0.0..=80.0).contains(&max_tilt_deg)) {
        return Err(DetectError::Options(format!(
            "max_tilt_deg = {max_tilt_deg} must be within 0..=80"
        )));
    }
    let (h, w) = (cal.model.height as usize, cal.model.width as usize);
    // Tables of the whole working image, read every frame: on huge pages where there are.
    reset_huge(mask, w * h, 0);
    reset_huge(rays, w * h, [0.0; 3]);
    reset_huge(solid, w * h, 0.0);
    let res = fill_tables(cal, opts, max_tilt_deg, mask, rays, solid);
    if res.valid == 0 {
        return Err(DetectError::Mask(format!(
            "no pixel of the {h}x{w} image is inside the field of view (mask {:?}, sky above {} deg)",
            cal.mask, max_tilt_deg
        )));
    }
    Ok(res)
}

/// Empties `v` and fills it with `len` copies of `value`, on huge pages where there are.
fn reset_huge<T: Clone>(v: &mut Vec<T>, len: usize, value: T) {
    v.clear();
    crate::memory::reserve_huge(v, len);
    v.resize(len, value);
}

/// The radii (pixels) between which the field of view is used: the calibration's mask shrunk
/// by the margin, or everything when it has none.
fn fov_radii(fov: Option<FovMask>, margin_px: f64) -> (f64, f64) {
    match fov {
        Some(m) => (
            if m.inner_radius_px > 0.0 {
                m.inner_radius_px + margin_px
            } else {
                0.0
            },
            m.outer_radius_px - margin_px,
        ),
        None => (0.0, f64::INFINITY),
    }
}

/// Writes the mask, ray and solid-angle tables (already zeroed and sized) pixel by pixel:
/// a pixel is used when it lies within the field of view's radii, its ray is within the lens's range of elevations, and it is not sky.
fn fill_tables(
    cal: &Calibration,
    opts: &MaskOptions,
    max_tilt_deg: f64,
    mask: &mut [u8],
    rays: &mut [[f32; 3]],
    solid: &mut [f32],
) -> MaskResult {
    let (h, w) = (cal.model.height as usize, cal.model.width as usize);
    let model = &cal.model;
    let omega = |r: f64, c: f64| -> f64 {
        let dr = model.cam2world(r + 0.5, c) - model.cam2world(r - 0.5, c);
        let dc = model.cam2world(r, c + 0.5) - model.cam2world(r, c - 0.5);
        dr.cross(&dc).norm()
    };
    let omega0 = omega(model.xc, model.yc).max(1e-300);
    let rot = cal.mounting.robot_from_camera();
    let sin_tilt = max_tilt_deg.to_radians().sin();
    let (tlo, thi) = cal.model.theta_range();
    let (inner, outer) = fov_radii(cal.mask, opts.fov_margin_px);
    let mut res = MaskResult::default();
    for r in 0..h {
        for c in 0..w {
            let i = r * w + c;
            let rad = cal.radius_px(r as f64, c as f64);
            if rad < inner || rad > outer {
                continue;
            }
            let ray = cal.model.cam2world(r as f64, c as f64);
            let theta = ray.z.atan2(ray.x.hypot(ray.y));
            if !(theta >= tlo && theta <= thi) {
                continue;
            }
            if opts.sky && (rot * ray).z > sin_tilt {
                res.sky += 1;
                continue;
            }
            mask[i] = 0xFF;
            rays[i] = [ray.x as f32, ray.y as f32, ray.z as f32];
            solid[i] = (omega(r as f64, c as f64) / omega0) as f32;
            res.valid += 1;
        }
    }
    res
}

/// Finds the lens's image circle (and a catadioptric lens's blind disc) from an image.
///
/// On circles around the calibration's centre `(row, col)` (image pixels), the brightness
/// varies with the angle wherever the lens sees the scene, and is flat (dark, or a uniform
/// glow of stray light) outside the image circle. The rim is the radius beyond which every
/// circle is flat; when the scene reaches the image corners, the circle is larger than the
/// sensor. A blind disc is a flat dark region around the centre. Radii in image pixels.
pub fn find_fov(view: &ImageView, centre: (f64, f64)) -> Result<FovMask, DetectError> {
    let err = |problem: String| DetectError::Image {
        height: view.height,
        width: view.width,
        problem,
    };
    if view.width < 8 || view.height < 8 {
        return Err(err("too small to find the lens's image circle".into()));
    }
    let max_r = corner_radius(view, centre);
    let stats = radial_stats(view, centre, max_r);
    let mut sds: Vec<f64> = stats.iter().flatten().map(|s| s.1).collect();
    if sds.is_empty() {
        return Err(err("no pixels around the calibration's centre".into()));
    }
    sds.sort_by(f64::total_cmp);
    let textured = sds[sds.len() * 3 / 4];
    if textured < 8.0 {
        return Err(err(format!(
            "image has no texture to find the lens's image circle in (angular deviation {textured:.1})"
        )));
    }
    let flat_sd = (0.2 * textured).max(4.0);
    let outer = rim_radius(&stats, max_r, flat_sd);
    let inner = blind_disc_radius(&stats, outer, flat_sd);
    let m = FovMask {
        inner_radius_px: inner,
        outer_radius_px: outer,
    };
    m.validate().map_err(err)?;
    Ok(m)
}

/// The distance (pixels, rounded up) from `centre` to the farthest corner of the image.
fn corner_radius(view: &ImageView, (cr, cc): (f64, f64)) -> usize {
    let (h, w) = (view.height as f64, view.width as f64);
    [
        (0.0, 0.0),
        (0.0, w - 1.0),
        (h - 1.0, 0.0),
        (h - 1.0, w - 1.0),
    ]
    .iter()
    .map(|&(r, c): &(f64, f64)| (r - cr).hypot(c - cc))
    .fold(0.0, f64::max)
    .ceil() as usize
}

/// Per radius 0..=`max_r` around `centre`: the mean and standard deviation of the brightness
/// over 720 angles, of the samples inside the image (`None` when fewer than 8 are).
fn radial_stats(view: &ImageView, (cr, cc): (f64, f64), max_r: usize) -> Vec<Option<(f64, f64)>> {
    const ANGLES: usize = 720;
    let (h, w) = (view.height as f64, view.width as f64);
    let dirs: Vec<(f64, f64)> = (0..ANGLES)
        .map(|k| (k as f64 * std::f64::consts::TAU / ANGLES as f64).sin_cos())
        .collect();
    (0..=max_r)
        .map(|rad| {
            let (mut s, mut s2, mut n) = (0.0, 0.0, 0u32);
            for &(sa, ca) in &dirs {
                let r = (cr + rad as f64 * sa).round();
                let c = (cc + rad as f64 * ca).round();
                if r >= 0.0 && c >= 0.0 && r < h && c < w {
                    let v = super::vegetation::brightness_at(view, r as usize, c as usize) as f64;
                    s += v;
                    s2 += v * v;
                    n += 1;
                }
            }
            (n >= 8).then(|| {
                let m = s / n as f64;
                (m, (s2 / n as f64 - m * m).max(0.0).sqrt())
            })
        })
        .collect()
}

/// The rim: scanning inwards, the first radius textured (deviation at least `flat_sd`) for
/// three radii in a row (a lone textured radius in the dark is noise), plus half a pixel.
/// Textured within 2% of the corners: the circle is larger than the sensor, and the rim is
/// `max_r`.
fn rim_radius(stats: &[Option<(f64, f64)>], max_r: usize, flat_sd: f64) -> f64 {
    let band = (max_r / 50).max(3);
    let textured_at = |r: usize| stats[r].is_some_and(|(_, sd)| sd >= flat_sd);
    let first = (2..=max_r)
        .rev()
        .find(|&r| textured_at(r) && textured_at(r - 1) && textured_at(r - 2));
    match first {
        Some(r) if r + band <= max_r => r as f64 + 0.5,
        _ => max_r as f64,
    }
}

/// A blind disc's radius: the flat radii (deviation below `flat_sd`) darker than half the
/// mean brightness inside the rim, from the centre out; 0 when they end within 3% of the rim
/// radius `outer` (no disc).
fn blind_disc_radius(stats: &[Option<(f64, f64)>], outer: f64, flat_sd: f64) -> f64 {
    let inside_mean = {
        let v: Vec<f64> = stats
            .iter()
            .take(outer as usize)
            .flatten()
            .map(|s| s.0)
            .collect();
        v.iter().sum::<f64>() / v.len().max(1) as f64
    };
    let mut inner = 0.0;
    for (rad, s) in stats.iter().enumerate().take(outer as usize) {
        match s {
            Some((m, sd)) if *sd < flat_sd && *m < 0.5 * inside_mean => {}
            _ => {
                if rad as f64 > 0.03 * outer {
                    inner = rad as f64 - 0.5;
                }
                break;
            }
        }
    }
    inner
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{ideal_pal, Mounting};
    use crate::frame::PixelFormat;

    fn ring_image(h: u32, w: u32, inner: f64, outer: f64) -> Vec<u8> {
        let (cr, cc) = ((h as f64 - 1.0) / 2.0, (w as f64 - 1.0) / 2.0);
        let mut d = vec![0u8; (h * w) as usize];
        for r in 0..h as usize {
            for c in 0..w as usize {
                let rad = (r as f64 - cr).hypot(c as f64 - cc);
                if rad >= inner && rad <= outer {
                    // textured but lit
                    d[r * w as usize + c] = 90 + ((r * 7 + c * 13) % 60) as u8;
                }
            }
        }
        d
    }

    #[test]
    fn finds_circle_and_annulus() {
        let (h, w) = (200u32, 240u32);
        let centre = ((h as f64 - 1.0) / 2.0, (w as f64 - 1.0) / 2.0);
        let d = ring_image(h, w, 0.0, 90.0);
        let v = ImageView::new(w, h, PixelFormat::Mono8, &d).unwrap();
        let m = find_fov(&v, centre).unwrap();
        assert_eq!(m.inner_radius_px, 0.0);
        assert!((m.outer_radius_px - 90.0).abs() < 1.5, "{m:?}");
        let d = ring_image(h, w, 30.0, 95.0);
        let v = ImageView::new(w, h, PixelFormat::Mono8, &d).unwrap();
        let m = find_fov(&v, centre).unwrap();
        assert!((m.inner_radius_px - 30.0).abs() < 1.5, "{m:?}");
        assert!((m.outer_radius_px - 95.0).abs() < 1.5, "{m:?}");
        // circle larger than the sensor: the scene reaches the corners
        let d = ring_image(h, w, 0.0, 1000.0);
        let v = ImageView::new(w, h, PixelFormat::Mono8, &d).unwrap();
        let m = find_fov(&v, centre).unwrap();
        assert!(m.outer_radius_px >= 155.0, "{m:?}");
        // all dark: an error, not a guess
        let d = vec![0u8; (h * w) as usize];
        let v = ImageView::new(w, h, PixelFormat::Mono8, &d).unwrap();
        assert!(find_fov(&v, centre).is_err());
    }

    #[test]
    fn mask_follows_fov_and_sky() {
        let cal = ideal_pal(100, 120).unwrap();
        let mut mask = Vec::new();
        let mut rays = Vec::new();
        let mut solid = Vec::new();
        let r = build_mask(
            &cal,
            &MaskOptions::default(),
            15.0,
            &mut mask,
            &mut rays,
            &mut solid,
        )
        .unwrap();
        assert!(r.valid > 0);
        let m = cal.mask.unwrap();
        for row in 0..100 {
            for col in 0..120 {
                let rad = cal.radius_px(row as f64, col as f64);
                let i = row * 120 + col;
                if rad < m.inner_radius_px || rad > m.outer_radius_px {
                    assert_eq!(mask[i], 0);
                }
                if rad > m.inner_radius_px + 3.0 && rad < m.outer_radius_px - 3.0 {
                    assert_eq!(mask[i], 0xFF, "{row} {col}");
                    let ray = cal.model.cam2world(row as f64, col as f64);
                    assert!((ray.x as f32 - rays[i][0]).abs() < 1e-6);
                }
            }
        }
        // A camera pitched 60 deg up sees sky in part of its field: those pixels are masked.
        let mut tilted = cal.clone();
        tilted.mounting = Mounting {
            pitch_deg: -60.0,
            ..Default::default()
        };
        let r2 = build_mask(
            &tilted,
            &MaskOptions::default(),
            15.0,
            &mut mask,
            &mut rays,
            &mut solid,
        )
        .unwrap();
        assert!(r2.sky > 0 && r2.valid < r.valid, "{r2:?} vs {r:?}");
        let rot = tilted.mounting.robot_from_camera();
        for (i, &m) in mask.iter().enumerate() {
            if m != 0 {
                let ray =
                    nalgebra::Vector3::new(rays[i][0] as f64, rays[i][1] as f64, rays[i][2] as f64);
                assert!((rot * ray).z <= 15f64.to_radians().sin() + 1e-6);
            }
        }
    }
}
