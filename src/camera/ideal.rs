//! Ideal lens models, fitted into Scaramuzza's Taylor form so they are ordinary calibrations.
//!
//! Owns the calibrations omnirow ships for the GC2450C's sensor (or any size): an equidistant
//! 185° fisheye (angle from the axis proportional to the radius) and a panoramic annular lens
//! seeing 30°–100° from the axis. Both are deterministic functions of the image size.

use super::{CalibError, Calibration, FovMask, Mounting, OcamModel};
use std::ops::RangeInclusive;

/// Image sides (pixels) an ideal lens can be made for: below 16 px the image circle has no
/// room for the fitted polynomials; above 20000 px no sensor exists.
pub const IDEAL_SIDE_PX: RangeInclusive<u32> = 16..=20000;

/// The ideal lenses omnirow ships (in configuration files: `fisheye185`, `pal`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum IdealLens {
    /// Equidistant 185° fisheye whose image circle fits the sensor's height.
    Fisheye185,
    /// Panoramic annular lens, 30°..100° from the axis, outer rim fitting the sensor's height.
    Pal,
}

impl IdealLens {
    /// The lens's calibration for an image of `height` × `width` pixels; an error names the
    /// size when a side is outside [`IDEAL_SIDE_PX`].
    pub fn calibration(self, height: u32, width: u32) -> Result<Calibration, CalibError> {
        match self {
            IdealLens::Fisheye185 => ideal_fisheye(height, width),
            IdealLens::Pal => ideal_pal(height, width),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            IdealLens::Fisheye185 => "fisheye185",
            IdealLens::Pal => "pal",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "fisheye185" | "fisheye" => Some(IdealLens::Fisheye185),
            "pal" | "catadioptric" => Some(IdealLens::Pal),
            _ => None,
        }
    }
}

/// Fits the direct polynomial f(rho) = -rho / tan(alpha(rho)) with ss[1] = 0 over [0, rho_max].
pub(super) fn fit_direct(alpha: impl Fn(f64) -> f64, rho_max: f64, degree: usize) -> Vec<f64> {
    // Unknowns: a0, a2, a3, ..., a_degree in the normalised variable u = rho / rho_max.
    let n = 600;
    let cols = degree; // a0 plus a2..a_degree
    let mut a = nalgebra::DMatrix::<f64>::zeros(n, cols);
    let mut b = nalgebra::DVector::<f64>::zeros(n);
    for i in 0..n {
        let u = i as f64 / (n - 1) as f64;
        let rho = u * rho_max;
        // f = -rho * cos/sin; the limit -1/alpha'(0) at rho = 0 is taken by a tiny offset.
        let rho_eff = rho.max(1e-6 * rho_max);
        let al = alpha(rho_eff);
        let f = -rho_eff * al.cos() / al.sin();
        a[(i, 0)] = 1.0;
        for k in 2..=degree {
            a[(i, k - 1)] = u.powi(k as i32);
        }
        b[i] = f;
    }
    let x = a
        .svd(true, true)
        .solve(&b, 1e-15)
        .expect("least squares on a full-rank design matrix");
    let mut ss = vec![0.0; degree + 1];
    ss[0] = x[0];
    for k in 2..=degree {
        ss[k] = x[k - 1] / rho_max.powi(k as i32);
    }
    ss
}

/// Refuses image sizes the ideal lenses cannot be fitted to.
fn check_size(lens: &str, height: u32, width: u32) -> Result<(), CalibError> {
    if IDEAL_SIDE_PX.contains(&height) && IDEAL_SIDE_PX.contains(&width) {
        return Ok(());
    }
    Err(CalibError::Invalid {
        path: format!("ideal {lens} lens").into(),
        problem: format!(
            "image {width}x{height}: each side must be {}..={} pixels",
            IDEAL_SIDE_PX.start(),
            IDEAL_SIDE_PX.end()
        ),
    })
}

fn finish(ss: Vec<f64>, fit_rho: f64, height: u32, width: u32, mask: FovMask) -> Calibration {
    let centre = ((height as f64 - 1.0) / 2.0, (width as f64 - 1.0) / 2.0);
    // A first model with a placeholder inverse gives the valid range; then fit the inverse.
    let probe = OcamModel::new(
        ss.clone(),
        vec![1.0],
        centre,
        (1.0, 0.0, 0.0),
        (height, width),
    )
    .expect("ideal direct polynomial is valid");
    let invpol = OcamModel::fit_invpol(&ss, probe.rho_valid_max().min(fit_rho), 12);
    let model = OcamModel::new(ss, invpol, centre, (1.0, 0.0, 0.0), (height, width))
        .expect("ideal model is valid");
    Calibration {
        model,
        mask: Some(mask),
        mounting: Mounting::default(),
    }
}

/// An equidistant 185° fisheye whose image circle (radius at 92.5°) fits the sensor's height.
/// An error when a side is outside [`IDEAL_SIDE_PX`].
pub fn ideal_fisheye(height: u32, width: u32) -> Result<Calibration, CalibError> {
    check_size("fisheye185", height, width)?;
    let rim = (height.min(width) as f64 - 1.0) / 2.0 - 2.0;
    let half_fov = 92.5f64.to_radians();
    let k = half_fov / rim; // radians per pixel
    let ss = fit_direct(|rho| k * rho, rim * 1.08, 7);
    Ok(finish(
        ss,
        rim * 1.08,
        height,
        width,
        FovMask {
            inner_radius_px: 0.0,
            outer_radius_px: rim,
        },
    ))
}

/// A panoramic annular lens seeing from 30° to 100° off the axis (10° above the horizon),
/// the outer rim fitting the sensor's height, the inner blind disc at a third of it.
/// An error when a side is outside [`IDEAL_SIDE_PX`].
pub fn ideal_pal(height: u32, width: u32) -> Result<Calibration, CalibError> {
    check_size("pal", height, width)?;
    let rim = (height.min(width) as f64 - 1.0) / 2.0 - 2.0;
    let inner = rim / 3.1;
    let (a_in, a_out) = (30f64.to_radians(), 100f64.to_radians());
    // alpha(rho) = p rho + q rho^2 through (inner, a_in) and (rim, a_out)
    let q = (a_out - a_in * rim / inner) / (rim * rim - inner * rim);
    let p = (a_in - q * inner * inner) / inner;
    debug_assert!(p > 0.0);
    let ss = fit_direct(|rho| p * rho + q * rho * rho, rim * 1.05, 7);
    Ok(finish(
        ss,
        rim * 1.05,
        height,
        width,
        FovMask {
            inner_radius_px: inner,
            outer_radius_px: rim,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fisheye_angles() {
        let cal = ideal_fisheye(2050, 2448).unwrap();
        let rim = cal.mask.unwrap().outer_radius_px;
        let a = cal.model.angle_at_radius(rim).to_degrees();
        assert!((a - 92.5).abs() < 0.3, "{a}");
        let a = cal.model.angle_at_radius(rim / 2.0).to_degrees();
        assert!((a - 46.25).abs() < 0.3, "{a}");
        let (worst, _) = cal.worst_round_trip_px(16);
        assert!(worst < 0.01, "{worst}");
    }

    #[test]
    fn pal_angles() {
        let cal = ideal_pal(2050, 2448).unwrap();
        let m = cal.mask.unwrap();
        let a = cal.model.angle_at_radius(m.inner_radius_px).to_degrees();
        assert!((a - 30.0).abs() < 0.5, "{a}");
        let a = cal.model.angle_at_radius(m.outer_radius_px).to_degrees();
        assert!((a - 100.0).abs() < 0.5, "{a}");
        let (worst, _) = cal.worst_round_trip_px(16);
        assert!(worst < 0.01, "{worst}");
    }

    /// Every size in the range gives a model whose rays round-trip; every size outside it is
    /// an error naming the size (a 96x4 PNG through `detect` once panicked here).
    #[test]
    fn sizes_inside_the_range_fit_and_outside_are_refused() {
        for lens in [IdealLens::Fisheye185, IdealLens::Pal] {
            for (h, w) in [(16, 16), (16, 97), (17, 40), (40, 17), (33, 33), (64, 301)] {
                let cal = lens.calibration(h, w).unwrap();
                let (worst, _) = cal.worst_round_trip_px(8);
                assert!(worst < 0.05, "{} {w}x{h}: {worst}", lens.name());
            }
            for (h, w) in [(4, 96), (0, 0), (15, 200), (200, 15), (20_001, 64)] {
                let err = lens.calibration(h, w).unwrap_err().to_string();
                assert!(err.contains(&format!("{w}x{h}")), "{err}");
                assert!(err.contains("16..=20000"), "{err}");
            }
        }
    }
}
