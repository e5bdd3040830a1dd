//! Overlay: the image with the detected rows drawn as their great circles projected through
//! the calibration, and the vanishing point marked (the paper's figures 6–7: Hough rows red,
//! edge rows blue).
//!
//! Owns drawing into a caller-owned RGB8 buffer; used by `omnirow detect --overlay` and by
//! the node's /overlay.png.

use super::types::{DetectError, Detection, Method};
use crate::camera::Calibration;
use crate::frame::{ImageView, PixelFormat};
use crate::sphere::any_perpendicular;
use nalgebra::Vector3;

/// Colour of a row found by each method.
pub fn method_colour(m: Method) -> [u8; 3] {
    match m {
        Method::Hough => [255, 32, 32],
        Method::Edge => [40, 90, 255],
        Method::Combined | Method::Auto => [255, 0, 255],
        Method::Pencil => [255, 160, 0],
        Method::Strips => [0, 200, 255],
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
        PixelFormat::BayerRggb8 => demosaic_rggb(view, rgb),
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

/// Demosaics Bayer RGGB `view` into `rgb` (w × h × 3) by 2×2 quads: each pixel gets its
/// quad's red, mean green and blue (an odd last row or column reuses its neighbour's).
fn demosaic_rggb(view: &ImageView, rgb: &mut [u8]) {
    let (w, h, d) = (view.width as usize, view.height as usize, view.data);
    for r0 in (0..h).step_by(2) {
        let r1 = (r0 + 1).min(h - 1);
        for c0 in (0..w).step_by(2) {
            let c1 = (c0 + 1).min(w - 1);
            let red = d[r0 * w + c0];
            let green = (d[r0 * w + c1] as u16 + d[r1 * w + c0] as u16).div_ceil(2) as u8;
            let blue = d[r1 * w + c1];
            for r in r0..=r1 {
                for c in c0..=c1 {
                    rgb[3 * (r * w + c)..3 * (r * w + c) + 3].copy_from_slice(&[red, green, blue]);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::ideal_fisheye;
    use crate::detect::{Row, VanishingPoint};

    #[test]
    fn draws_rows_and_vp() {
        let cal = ideal_fisheye(120, 160).unwrap();
        let data = vec![100u8; 120 * 160];
        let view = ImageView::new(160, 120, PixelFormat::Mono8, &data).unwrap();
        let det = Detection {
            rows: vec![Row {
                normal: Vector3::new(0.0, 1.0, 0.0),
                method: Method::Hough,
                support: 10,
                width_rad: 0.0,
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

    #[test]
    fn bayer_is_drawn_in_colour() {
        // 3x3 RGGB: quad (0,0) is green vegetation, the odd last column and row reuse it.
        #[rustfmt::skip]
        let data = [
            40, 200, 10,
            190, 30, 20,
            50, 60, 70,
        ];
        let view = ImageView::new(3, 3, PixelFormat::BayerRggb8, &data).unwrap();
        let mut rgb = vec![0; 27];
        demosaic_rggb(&view, &mut rgb);
        assert_eq!(&rgb[0..3], &[40, 195, 30]);
        assert_eq!(&rgb[3..6], &[40, 195, 30]);
        // quad (0,2): R 10, G (10 + 20) / 2 rounded, B 20 (column 2 is its own neighbour)
        assert_eq!(&rgb[6..9], &[10, 15, 20]);
        // quad (2,0): row 2 is its own neighbour: R 50, G (60 + 50) / 2, B 60
        assert_eq!(&rgb[18..21], &[50, 55, 60]);
    }
}
