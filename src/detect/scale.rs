//! The detector's scales for one calibration: how many working-image pixels one radian of the
//! sphere spans where the rows are, and each option's angle in pixels (or pixel length in
//! degrees) at that resolution.
//!
//! Owns [`angular_resolution`] (pixels per radian at the image centre and the median over the
//! field of view, at the detector's working resolution) and [`scales_report`], the lines
//! `omnirow config detector --calib FILE` prints, so that a user sees what the options in
//! degrees (Hough cells, vanishing-point bins and bands) and in pixels (the pencil method, the
//! smoothing, the refit's margin) mean for their lens.

use super::detector::{Binning, DetectorOptions};
use crate::camera::Calibration;
use std::fmt::Write;

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
}

/// The angular resolution of `cal` (at its own size, binned as `opts` would bin an RGB or
/// mono image of that size).
pub fn angular_resolution(
    cal: &Calibration,
    opts: &DetectorOptions,
) -> Result<AngularResolution, String> {
    let (h, w) = (cal.model.height, cal.model.width);
    let even = w % 2 == 0 && h % 2 == 0;
    let bin = match opts.binning {
        Binning::Off => false,
        Binning::Half => true,
        Binning::Auto => w as u64 * h as u64 > opts.auto_bin_above_px && even,
    };
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
    for r in (step / 2..wh).step_by(step) {
        for c in (step / 2..ww).step_by(step) {
            let (rf, cf) = (r as f64, c as f64);
            if work.mask.is_some_and(|_| !work.pixel_in_fov(rf, cf)) {
                continue;
            }
            if let Some(p) = px_per_rad(rf, cf) {
                v.push(p);
            }
        }
    }
    if v.is_empty() {
        return Err("no pixel of the field of view".into());
    }
    v.sort_unstable_by(f64::total_cmp);
    Ok(AngularResolution {
        width: m.width,
        height: m.height,
        factor,
        centre_px_per_rad: centre,
        median_px_per_rad: v[v.len() / 2],
    })
}

/// The options' scales for `cal`, as TOML comment lines: each angular option in pixels and
/// each pixel option in degrees, at the median angular resolution.
pub fn scales_report(cal: &Calibration, opts: &DetectorOptions) -> Result<String, String> {
    let a = angular_resolution(cal, opts)?;
    let p = a.median_px_per_rad;
    let px = |deg: f64| deg.to_radians() * p;
    let deg = |px: f64| (px / p).to_degrees();
    let h = &opts.hough;
    let v = &opts.vanishing;
    let pe = &opts.pencil;
    let mut s = String::new();
    let mut line = |t: String| {
        let _ = writeln!(s, "# {t}");
    };
    line(format!(
        "working image {}x{} (reduced {}x from the calibration's {}x{})",
        a.width, a.height, a.factor, cal.model.width, cal.model.height
    ));
    line(format!(
        "angular resolution: {:.1} px/rad at the centre, {:.1} px/rad median over the field of view",
        a.centre_px_per_rad, p
    ));
    line("angular options, in pixels at the median resolution:".into());
    for (name, d) in [
        ("hough cell along phi", 180.0 / h.phi_bins as f64),
        ("hough cell along theta", 180.0 / h.theta_bins as f64),
        ("hough.min_tolerance_deg", h.min_tolerance_deg),
        ("hough.merge_angle_deg", h.merge_angle_deg),
        ("vanishing azimuth cell", 180.0 / v.azimuth_bins as f64),
        ("vanishing.elevation_bin_deg", v.elevation_bin_deg),
        ("vanishing.inlier_deg", v.inlier_deg),
        ("vanishing.min_spread_deg", v.min_spread_deg),
        ("combined.pair_max_deg", opts.combined.pair_max_deg),
        ("pencil.polish_max_band_deg", pe.polish_max_band_deg),
    ] {
        line(format!("  {name:<28} {d:>7.3} deg = {:>7.2} px", px(d)));
    }
    line("pixel options, in degrees at the median resolution:".into());
    for (name, l) in [
        ("smooth.sigma_px", opts.smooth.sigma_px),
        ("refit.margin_px", opts.refit.margin_px),
        ("pencil.bin_px", pe.bin_px),
        ("pencil.reference_px", pe.reference_px),
        ("pencil.search_step_px", pe.search_step_px),
        ("pencil.min_separation_px", pe.min_separation_px),
        ("pencil.smooth_px", pe.smooth_px),
    ] {
        line(format!("  {name:<28} {l:>7.2} px = {:>7.3} deg", deg(l)));
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::ideal_fisheye;

    #[test]
    fn resolution_scales_with_the_image() {
        let opts = DetectorOptions::default();
        let big = ideal_fisheye(1200, 1200).unwrap();
        let small = ideal_fisheye(300, 300).unwrap();
        let (a, b) = (
            angular_resolution(&big, &opts).unwrap(),
            angular_resolution(&small, &opts).unwrap(),
        );
        assert_eq!((a.factor, b.factor), (1, 1));
        let r = a.median_px_per_rad / b.median_px_per_rad;
        assert!((r - 4.0).abs() < 0.1, "{a:?} {b:?}");
        let text = scales_report(&big, &opts).unwrap();
        assert!(text.contains("hough cell along phi"), "{text}");
        assert!(text.lines().all(|l| l.starts_with('#')), "{text}");
    }

    #[test]
    fn binning_halves_the_resolution() {
        let opts = DetectorOptions::default();
        let cal = ideal_fisheye(2050, 2448).unwrap();
        let a = angular_resolution(&cal, &opts).unwrap();
        assert_eq!((a.factor, a.width, a.height), (2, 1224, 1025));
        let off = DetectorOptions {
            binning: Binning::Off,
            ..Default::default()
        };
        let b = angular_resolution(&cal, &off).unwrap();
        let r = b.centre_px_per_rad / a.centre_px_per_rad;
        assert!((r - 2.0).abs() < 0.01, "{a:?} {b:?}");
    }
}
