//! The HTTP service's `/overlay.png`: the latest frame with the detector's overlay (rows,
//! vanishing point: [`crate::detect::overlay`]) and, on top, the line the row guidance
//! follows, encoded as PNG.
//!
//! Owns drawing the followed line ([`crate::guidance::followed`] finds it on the ground and
//! samples it through the calibration) into the image ([`draw_followed`]). In `between_rows` mode the followed line is the centre line of the
//! inter-row path (solid) and the two rows bounding the path are drawn dashed; in `over_row`
//! mode the followed row is drawn solid. All in [`FOLLOWED_COLOUR`]. Nothing is drawn while
//! the guidance has no estimate (`lost`) or the frame gave no rows on the ground (the
//! guidance is coasting on its prediction): the page says which.

use crate::camera::Calibration;
/// The followed line's colour, defined with the followed line itself.
pub use crate::guidance::followed::FOLLOWED_COLOUR;
use crate::guidance::followed::{followed_lines, sample_ground_line, GroundLine};
use crate::guidance::GuidanceEstimate;
use crate::status::Latest;

/// Draws `g`'s followed line (solid) and the rows either side of a followed path (dashed)
/// into `rgb` (width × height × 3, the image `cal` describes). Returns how many samples of the
/// lines landed in the image.
pub fn draw_followed(rgb: &mut [u8], cal: &Calibration, g: &GuidanceEstimate) -> usize {
    let Some(f) = followed_lines(g) else {
        return 0;
    };
    let (w, h) = (cal.model.width as usize, cal.model.height as usize);
    if rgb.len() != w * h * 3 {
        return 0;
    }
    let thick = (w.max(h) / 800).max(1);
    let mut drawn = draw_line(rgb, (w, h), cal, &f.line, None, thick);
    for side in f.sides.iter().flatten() {
        drawn += draw_line(rgb, (w, h), cal, side, Some(24), thick);
    }
    drawn
}

/// Paints the samples of a ground line ([`sample_ground_line`]) `thick` pixels around each;
/// `dash` leaves every other run of that many samples out. Returns the samples painted.
fn draw_line(
    rgb: &mut [u8],
    (w, h): (usize, usize),
    cal: &Calibration,
    line: &GroundLine,
    dash: Option<usize>,
    thick: usize,
) -> usize {
    let rad = thick as isize;
    let mut drawn = 0;
    sample_ground_line(cal, line, 4 * (w + h), |i, p| {
        if dash.is_some_and(|d| (i / d) % 2 == 1) {
            return;
        }
        let (r0, c0) = (p[0].round() as isize, p[1].round() as isize);
        for r in (r0 - rad)..=(r0 + rad) {
            for c in (c0 - rad)..=(c0 + rad) {
                if r >= 0 && c >= 0 && (r as usize) < h && (c as usize) < w {
                    let k = 3 * (r as usize * w + c as usize);
                    rgb[k..k + 3].copy_from_slice(&FOLLOWED_COLOUR);
                }
            }
        }
        drawn += 1;
    });
    drawn
}

/// The overlay of the latest frame as PNG: the detector's rows and vanishing point, then the
/// followed line, over the frame in colour. `cal` is the camera's calibration at any uniform
/// scale of the frame's size.
pub fn overlay_png(cal: &Calibration, l: &Latest) -> Result<Vec<u8>, String> {
    let view = l.frame.view().map_err(|e| e.to_string())?;
    let view_cal = if cal.size() == (view.height, view.width) {
        cal.clone()
    } else {
        cal.rescaled_to(view.height, view.width)?
    };
    let mut rgb = Vec::new();
    crate::detect::overlay::draw_overlay(&view, &view_cal, &l.detection, &mut rgb)
        .map_err(|e| e.to_string())?;
    if let Some(g) = &l.estimate.guidance {
        draw_followed(&mut rgb, &view_cal, g);
    }
    let mut png = Vec::new();
    let enc = image::codecs::png::PngEncoder::new_with_quality(
        &mut png,
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::Sub,
    );
    use image::ImageEncoder;
    enc.write_image(
        &rgb,
        view.width,
        view.height,
        image::ExtendedColorType::Rgb8,
    )
    .map_err(|e| e.to_string())?;
    Ok(png)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::ideal_fisheye;
    use crate::guidance::followed::tests::guidance;
    use crate::guidance::Mode;
    use nalgebra::Vector3;

    #[test]
    fn followed_line_is_drawn_where_the_camera_sees_it() {
        let cal = ideal_fisheye(240, 320).unwrap();
        let mut rgb = vec![0u8; 240 * 320 * 3];
        let g = guidance(Mode::BetweenRows, 0.15);
        let drawn = draw_followed(&mut rgb, &cal, &g);
        assert!(drawn > 100, "{drawn} samples drawn");
        // The centre line's point 1 m ahead, seen through the default (downward) mounting.
        let m = cal.mounting.robot_from_camera().inverse();
        for (y, solid) in [(-0.15, true), (-0.4, false), (0.1, false)] {
            let ray = m * Vector3::new(1.0, y, -1.0).normalize();
            let p = cal.ray_to_pixel_in_fov(&ray).unwrap();
            let near = |dr: isize, dc: isize| {
                let (r, c) = (p[0].round() as isize + dr, p[1].round() as isize + dc);
                let k = 3 * (r as usize * 320 + c as usize);
                rgb[k..k + 3] == FOLLOWED_COLOUR
            };
            let hit = (-1..=1).any(|dr| (-1..=1).any(|dc| near(dr, dc)));
            // a dashed side may have a gap exactly there; the solid line has none
            assert!(hit || !solid, "no followed line at y = {y}");
        }
        let painted = rgb
            .chunks_exact(3)
            .filter(|p| *p == FOLLOWED_COLOUR)
            .count();
        assert!(painted > 200, "{painted} pixels");
        // a frame without guidance rows: nothing drawn
        let mut blank = vec![0u8; 240 * 320 * 3];
        assert_eq!(
            draw_followed(&mut blank, &cal, &GuidanceEstimate::default()),
            0
        );
        assert!(blank.iter().all(|&v| v == 0));
    }
}
