//! The HTTP service's `/overlay.png`: the latest frame with the detector's overlay (rows,
//! vanishing point: [`crate::detect::overlay`]) and, on top, the line the row guidance
//! follows, encoded as PNG.
//!
//! Owns finding the followed line on the ground from the published guidance
//! ([`followed_lines`]: a plain result, no image) and drawing it through the calibration
//! ([`draw_followed`]). In `between_rows` mode the followed line is the centre line of the
//! inter-row path (solid) and the two rows bounding the path are drawn dashed; in `over_row`
//! mode the followed row is drawn solid. All in [`FOLLOWED_COLOUR`]. Nothing is drawn while
//! the guidance has no estimate (`lost`) or the frame gave no rows on the ground (the
//! guidance is coasting on its prediction): the page says which.

use crate::camera::Calibration;
use crate::guidance::{GuidanceEstimate, Mode};
use crate::status::Latest;
use nalgebra::{Rotation3, Vector3};

/// Colour of the followed line (cyan: distinct from the rows' red, blue, magenta and orange,
/// the vanishing point's yellow and the crop's green).
pub const FOLLOWED_COLOUR: [u8; 3] = [0, 230, 255];

/// A line on the ground, base_link coordinates, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundLine {
    /// A point of the line.
    pub point_m: Vector3<f64>,
    /// Unit direction, forward.
    pub direction: Vector3<f64>,
}

/// What the overlay draws for the guidance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Followed {
    /// The line the lateral offset is measured from.
    pub line: GroundLine,
    /// `between_rows`: the rows either side of the followed path (right, left).
    pub sides: Option<[GroundLine; 2]>,
}

/// The followed line of `g` on the ground: at `−lateral_offset_m` across the rows from the
/// tool point (the offset is the tool point's, positive when it is left of the line). The
/// direction across the rows comes from this frame's rows on the ground, so `None` when the
/// guidance has no offset or the frame gave fewer than two rows at distinct positions.
pub fn followed_lines(g: &GuidanceEstimate) -> Option<Followed> {
    let offset = g.lateral_offset_m.filter(|v| v.is_finite())?;
    // The pair of rows farthest apart gives the direction across the rows best.
    let (mut a, mut b) = (g.rows.first()?, g.rows.first()?);
    for r in &g.rows {
        if r.lateral_m < a.lateral_m {
            a = r;
        }
        if r.lateral_m > b.lateral_m {
            b = r;
        }
    }
    let span = b.lateral_m - a.lateral_m;
    if span.is_nan() || span <= 1e-6 {
        return None;
    }
    let left = (Vector3::from(b.point_m) - Vector3::from(a.point_m)) / span;
    let direction = Vector3::from(a.direction).try_normalize(1e-9)?;
    let at = |lateral: f64| GroundLine {
        point_m: Vector3::from(a.point_m) + left * (lateral - a.lateral_m),
        direction,
    };
    let centre = -offset;
    let sides = match (g.mode, g.row_spacing_m) {
        (Mode::BetweenRows, Some(s)) if s.is_finite() && s > 0.0 => {
            Some([at(centre - s / 2.0), at(centre + s / 2.0)])
        }
        _ => None,
    };
    Some(Followed {
        line: at(centre),
        sides,
    })
}

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
    let camera_from_robot = cal.mounting.robot_from_camera().inverse();
    let camera_m = Vector3::from(cal.mounting.position_m);
    let thick = (w.max(h) / 800).max(1);
    let mut drawn = draw_line(
        rgb,
        (w, h),
        cal,
        &camera_from_robot,
        camera_m,
        &f.line,
        None,
        thick,
    );
    for side in f.sides.iter().flatten() {
        drawn += draw_line(
            rgb,
            (w, h),
            cal,
            &camera_from_robot,
            camera_m,
            side,
            Some(24),
            thick,
        );
    }
    drawn
}

/// Samples the ground line evenly in the angle under which the camera sees it (so that the
/// curve is continuous up to the vanishing points) and paints each sample's pixel; `dash`
/// leaves every other run of that many samples out. Returns the samples painted.
#[allow(clippy::too_many_arguments)]
fn draw_line(
    rgb: &mut [u8],
    (w, h): (usize, usize),
    cal: &Calibration,
    camera_from_robot: &Rotation3<f64>,
    camera_m: Vector3<f64>,
    line: &GroundLine,
    dash: Option<usize>,
    thick: usize,
) -> usize {
    let to_point = line.point_m - camera_m;
    // The line's point nearest the camera and its distance: t = dist · tan θ.
    let foot = to_point - line.direction * to_point.dot(&line.direction);
    let dist = foot.norm();
    if dist.is_nan() || dist <= 1e-6 {
        return 0;
    }
    let steps = 4 * (w + h);
    let half = std::f64::consts::FRAC_PI_2;
    // Twice as wide as the detector's rows, so that it stands out among them.
    let rad = thick as isize;
    let mut drawn = 0;
    for i in 1..steps {
        if dash.is_some_and(|d| (i / d) % 2 == 1) {
            continue;
        }
        let theta = -half + std::f64::consts::PI * i as f64 / steps as f64;
        let ray = camera_from_robot * (foot + line.direction * (dist * theta.tan()));
        let Some(p) = cal.ray_to_pixel_in_fov(&ray.normalize()) else {
            continue;
        };
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
    }
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
    use crate::guidance::{GroundRow, TrackState};

    /// Guidance seen by a level camera 1 m above base_link's origin (also the tool point),
    /// rows 0.5 m apart along x at y = −0.4 + 0.5·k: the inter-row paths' centre lines lie at
    /// y = −0.15 + 0.5·k, the nearest at −0.15, so the tool point is 0.15 m left of it.
    fn guidance(mode: Mode, offset: f64) -> GuidanceEstimate {
        let rows = (-2..=2)
            .map(|k| {
                let y = -0.4 + 0.5 * k as f64;
                GroundRow {
                    index: k,
                    lateral_m: y,
                    point_m: [0.0, y, -1.0],
                    direction: [1.0, 0.0, 0.0],
                }
            })
            .collect();
        GuidanceEstimate {
            mode,
            tracking: TrackState::Tracking,
            lateral_offset_m: Some(offset),
            row_spacing_m: Some(0.5),
            rows,
            ..GuidanceEstimate::default()
        }
    }

    #[test]
    fn followed_line_lies_at_minus_the_offset_with_rows_either_side() {
        let f = followed_lines(&guidance(Mode::BetweenRows, 0.15)).unwrap();
        assert!((f.line.point_m - Vector3::new(0.0, -0.15, -1.0)).norm() < 1e-12);
        assert!((f.line.direction - Vector3::x()).norm() < 1e-12);
        let [right, left] = f.sides.unwrap();
        assert!((right.point_m.y + 0.4).abs() < 1e-12 && (left.point_m.y - 0.1).abs() < 1e-12);
        // over a row: the row itself, no sides
        let f = followed_lines(&guidance(Mode::OverRow, -0.1)).unwrap();
        assert!((f.line.point_m.y - 0.1).abs() < 1e-12);
        assert!(f.sides.is_none());
    }

    #[test]
    fn nothing_is_followed_without_an_offset_or_rows() {
        let mut g = guidance(Mode::BetweenRows, 0.1);
        g.rows.truncate(1);
        assert!(followed_lines(&g).is_none());
        let lost = GuidanceEstimate::default();
        assert!(followed_lines(&lost).is_none());
        let mut nan = guidance(Mode::BetweenRows, f64::NAN);
        nan.tracking = TrackState::Coasting;
        assert!(followed_lines(&nan).is_none());
    }

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
