//! The line the row guidance follows, on the ground and in the image.
//!
//! Owns finding the followed line on the ground from a published [`GuidanceEstimate`]
//! ([`followed_lines`]: a plain result, no image) and sampling a line on the ground into the
//! image through the calibration ([`sample_ground_line`]), evenly in the angle under which
//! the camera sees it. The HTTP overlay draws the samples into pixels; recordings write them
//! as Foxglove image annotations. In `between_rows` mode the followed line is the centre line
//! of the inter-row path and the two rows bounding the path are its sides; in `over_row` mode
//! the followed row itself.

use super::{GuidanceEstimate, Mode};
use crate::camera::Calibration;
use nalgebra::Vector3;

/// Colour of the followed line wherever it is drawn (the HTTP overlay, Foxglove annotations):
/// cyan, distinct from the rows' red, blue, magenta and orange, the vanishing point's yellow
/// and the crop's green.
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

/// Samples the ground line `line` (base_link) in `steps` steps evenly in the angle under
/// which the camera of `cal` sees it, from one end of the line to the other (so that the
/// curve is continuous up to its vanishing points), and calls `f(i, pixel)` for each sample
/// `i` that falls in the field of view (`pixel` = [row, column], 0-based, pixel centres at
/// integers). Returns how many samples did. Nothing when the camera lies on the line.
pub fn sample_ground_line(
    cal: &Calibration,
    line: &GroundLine,
    steps: usize,
    mut f: impl FnMut(usize, [f64; 2]),
) -> usize {
    let camera_from_robot = cal.mounting.robot_from_camera().inverse();
    let to_point = line.point_m - Vector3::from(cal.mounting.position_m);
    // The line's point nearest the camera and its distance: t = dist · tan θ.
    let foot = to_point - line.direction * to_point.dot(&line.direction);
    let dist = foot.norm();
    if dist.is_nan() || dist <= 1e-6 {
        return 0;
    }
    let half = std::f64::consts::FRAC_PI_2;
    let mut seen = 0;
    for i in 1..steps {
        let theta = -half + std::f64::consts::PI * i as f64 / steps as f64;
        let ray = camera_from_robot * (foot + line.direction * (dist * theta.tan()));
        if let Some(p) = cal.ray_to_pixel_in_fov(&ray.normalize()) {
            f(i, p);
            seen += 1;
        }
    }
    seen
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::camera::ideal_fisheye;
    use crate::guidance::{GroundRow, TrackState};

    /// Guidance seen by a level camera 1 m above base_link's origin (also the tool point),
    /// rows 0.5 m apart along x at y = −0.4 + 0.5·k: the inter-row paths' centre lines lie at
    /// y = −0.15 + 0.5·k, the nearest at −0.15, so the tool point is 0.15 m left of it.
    pub(crate) fn guidance(mode: Mode, offset: f64) -> GuidanceEstimate {
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
    fn samples_of_a_ground_line_project_where_its_points_do() {
        let cal = ideal_fisheye(240, 320).unwrap();
        let f = followed_lines(&guidance(Mode::BetweenRows, 0.15)).unwrap();
        let mut pts = Vec::new();
        let n = sample_ground_line(&cal, &f.line, 400, |_, p| pts.push(p));
        assert_eq!(n, pts.len());
        assert!(n > 100, "{n} samples in view");
        // the line's point 1 m ahead is among them (within a sample's spacing)
        let m = cal.mounting.robot_from_camera().inverse();
        let ray = m * Vector3::new(1.0, -0.15, -1.0).normalize();
        let p = cal.ray_to_pixel_in_fov(&ray).unwrap();
        let nearest = pts
            .iter()
            .map(|q| ((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2)).sqrt())
            .fold(f64::INFINITY, f64::min);
        assert!(nearest < 2.0, "nearest sample {nearest} px away");
        // a line through the camera itself has no projection
        let through = GroundLine {
            point_m: Vector3::from(cal.mounting.position_m),
            direction: Vector3::x(),
        };
        assert_eq!(sample_ground_line(&cal, &through, 400, |_, _| ()), 0);
    }
}
