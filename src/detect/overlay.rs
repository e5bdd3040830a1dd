//! Overlay: the image with the detected rows drawn as their great circles projected through
//! the calibration, and the vanishing point marked (the paper's figures 6–7: Hough rows red,
//! edge rows blue).
//!
//! Owns drawing into a caller-owned RGB8 buffer; used by `omnirow detect --overlay` and by
//! the node's /overlay.png.

use super::{DetectError, Detection, Method};
use crate::camera::Calibration;
use crate::frame::{ImageView, PixelFormat};
use crate::sphere::any_perpendicular;
use nalgebra::Vector3;

/// Colour of a row found by each method.
pub fn method_colour(m: Method) -> [u8; 3] {
    match m {
        Method::Hough => [255, 32, 32],
        Method::Edge => [40, 90, 255],
        Method::Combined => [255, 0, 255],
        Method::Pencil => [255, 160, 0],
    }
}

/// Colour of the vanishing-point mark.
pub const VP_COLOUR: [u8; 3] = [255, 230, 0];

/// Draws `det` over `view` into `rgb` (resized to width × height × 3). `cal` must describe
/// the image at its own resolution (e.g. [`Detector::view_calibration`](super::Detector::view_calibration)).
pub fn draw_overlay(
    view: &ImageView,
    cal: &Calibration,
    det: &Detection,
    rgb: &mut Vec<u8>,
) -> Result<(), DetectError> {
    let (w, h) = (view.width as usize, view.height as usize);
    if (cal.model.height, cal.model.width) != (view.height, view.width) {
        return Err(DetectError::Image {
            height: view.height,
            width: view.width,
            problem: format!(
                "overlay: the calibration is for {}x{}",
                cal.model.height, cal.model.width
            ),
        });
    }
    rgb.resize(w * h * 3, 0);
    match view.format {
        PixelFormat::Rgb8 => rgb.copy_from_slice(view.data),
        PixelFormat::Mono8 => {
            for (o, &v) in rgb.chunks_exact_mut(3).zip(view.data) {
                o.fill(v);
            }
        }
        PixelFormat::BayerRggb8 => {
            for r in 0..h {
                for c in 0..w {
                    let v = super::vegetation::brightness_at(view, r, c);
                    rgb[3 * (r * w + c)..3 * (r * w + c) + 3].fill(v);
                }
            }
        }
    }
    // Dim the background so the lines stand out.
    for v in rgb.iter_mut() {
        *v = (*v as u16 * 3 / 4) as u8;
    }
    let thick = (w.max(h) / 800).max(1) as isize;
    let put = |rgb: &mut Vec<u8>, p: [f64; 2], col: [u8; 3], rad: isize| {
        let (r0, c0) = (p[0].round() as isize, p[1].round() as isize);
        for dr in -rad..=rad {
            for dc in -rad..=rad {
                let (r, c) = (r0 + dr, c0 + dc);
                if r >= 0 && c >= 0 && (r as usize) < h && (c as usize) < w {
                    let i = 3 * (r as usize * w + c as usize);
                    rgb[i..i + 3].copy_from_slice(&col);
                }
            }
        }
    };
    // Sample each great circle finely enough for a continuous curve.
    let steps = 4 * (w + h);
    for row in &det.rows {
        let n = row.normal;
        let u = any_perpendicular(&n);
        let v = n.cross(&u);
        let col = method_colour(row.method);
        for i in 0..steps {
            let t = i as f64 * std::f64::consts::TAU / steps as f64;
            let ray: Vector3<f64> = u * t.cos() + v * t.sin();
            if let Some(p) = cal.ray_to_pixel_in_fov(&ray) {
                put(rgb, p, col, thick / 2);
            }
        }
    }
    if let Some(vp) = det.vanishing_point {
        for d in [vp.direction, -vp.direction] {
            if let Some(p) = cal.model.world2cam(&d) {
                let s = 6 * thick;
                for k in -s..=s {
                    put(rgb, [p[0] + k as f64, p[1] + k as f64], VP_COLOUR, thick);
                    put(rgb, [p[0] + k as f64, p[1] - k as f64], VP_COLOUR, thick);
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::ideal_fisheye;
    use crate::detect::{Row, VanishingPoint};

    #[test]
    fn draws_rows_and_vp() {
        let cal = ideal_fisheye(120, 160);
        let data = vec![100u8; 120 * 160];
        let view = ImageView::new(160, 120, PixelFormat::Mono8, &data).unwrap();
        let det = Detection {
            rows: vec![Row {
                normal: Vector3::new(0.0, 1.0, 0.0),
                method: Method::Hough,
                support: 10,
            }],
            vanishing_point: Some(VanishingPoint {
                direction: Vector3::new(-1.0, 0.0, 0.0),
                inliers: 2,
                residual_rad: 0.0,
            }),
            ..Default::default()
        };
        let mut rgb = Vec::new();
        draw_overlay(&view, &cal, &det, &mut rgb).unwrap();
        // the row (normal along y) is the vertical image line through the centre column
        let c = cal.model.yc.round() as usize;
        let i = 3 * (60 * 160 + c);
        assert_eq!(&rgb[i..i + 3], &method_colour(Method::Hough));
        // the background is dimmed grey
        assert_eq!(&rgb[0..3], &[75, 75, 75]);
        // the VP (image top, along -x) is marked
        assert!(rgb.chunks_exact(3).any(|p| p == VP_COLOUR));
    }
}
