//! The detector's scales for one calibration: how large the field of view is and how many
//! working-image pixels one radian of the sphere spans there, the angular options derived from
//! them, and each option's angle in pixels (or pixel length in degrees).
//!
//! Owns [`angular_resolution`] (pixels per radian at the image centre and the median over the
//! field of view at the detector's working resolution, and the field of view's extent),
//! [`resolve`] (every angular option left absent set to its reference value times the
//! calibration's factor) and [`scales_report`], the lines `omnirow config detector --calib
//! FILE` prints with the values in force.
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

use super::hough::{REFERENCE_BINS, REFERENCE_MERGE_ANGLE_DEG, REFERENCE_MIN_TOLERANCE_DEG};
use super::options::{Binning, DetectorOptions, REFERENCE_PAIR_MAX_DEG};
use super::vanishing::{
    REFERENCE_AZIMUTH_BINS, REFERENCE_ELEVATION_BIN_DEG, REFERENCE_INLIER_DEG,
    REFERENCE_MIN_SPREAD_DEG,
};
use super::{DetectError, Method};
use crate::camera::Calibration;
use std::fmt::Write;

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

/// How [`resolve`] derived the options' scales.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scales {
    pub resolution: AngularResolution,
    /// The factor in force (the `angle_scale` option, else [`angle_factor`]).
    pub factor: f64,
    /// Whether the factor came from the calibration (no `angle_scale` option).
    pub derived: bool,
}

/// Fields of view narrower than this extent (radians, the square root of the solid angle:
/// about a 115° × 115° perspective view) get the strips method under `method = "auto"`
/// (the pencil when the mounting does not look forward), wider ones the combined method.
/// Forward-looking perspective cameras see the rows converge in front of them, where the
/// strips' peaks lined up through the vanishing point hold on real crop images; the
/// omnidirectional lenses see them all around and keep the paper's combined method
/// (docs/real.md).
pub const NARROW_EXTENT_RAD: f64 = 2.0;

/// The method `auto` stands for on a field of view of `a`'s extent, mounted as `m`.
pub fn auto_method(a: &AngularResolution, m: &crate::camera::Mounting) -> Method {
    if a.extent_rad >= NARROW_EXTENT_RAD {
        Method::Combined
    } else if super::strips::looks_forward(m) {
        Method::Strips
    } else {
        Method::Pencil
    }
}

/// `opts` with every angular option left absent set for `cal`: its reference value times
/// the factor (`opts.angle_scale`, else derived from the calibration's field of view),
/// accumulator sizes rounded to whole cells. Options given explicitly are kept.
pub fn resolve(
    cal: &Calibration,
    opts: &DetectorOptions,
) -> Result<(DetectorOptions, Scales), DetectError> {
    if let Some(f) = opts.angle_scale {
        if !(f.is_finite() && (0.01..=100.0).contains(&f)) {
            return Err(DetectError::Options(format!(
                "angle_scale = {f} must be within 0.01..=100"
            )));
        }
    }
    let resolution = angular_resolution(cal, opts).map_err(|e| {
        DetectError::Calibration(format!("angular resolution at the working size: {e}"))
    })?;
    let factor = opts
        .angle_scale
        .unwrap_or_else(|| angle_factor(&resolution));
    let bins = |reference: usize| ((reference as f64 / factor).round() as usize).max(4);
    let angle = |reference: f64| reference * factor;
    let mut o = opts.clone();
    if o.method == Method::Auto {
        o.method = auto_method(&resolution, &cal.mounting);
    }
    if o.method == Method::Strips {
        let pixels = resolution.width as f64 * resolution.height as f64;
        let share = ((super::strips::KEPT_SHARE * pixels).round() as usize).max(1);
        o.threshold.target_points.get_or_insert(share);
        o.threshold
            .min_level
            .get_or_insert(super::strips::KEPT_MIN_LEVEL);
    }
    let h = &mut o.hough;
    h.phi_bins.get_or_insert(bins(REFERENCE_BINS));
    h.theta_bins.get_or_insert(bins(REFERENCE_BINS));
    h.min_tolerance_deg
        .get_or_insert(angle(REFERENCE_MIN_TOLERANCE_DEG));
    h.merge_angle_deg
        .get_or_insert(angle(REFERENCE_MERGE_ANGLE_DEG));
    let v = &mut o.vanishing;
    v.azimuth_bins.get_or_insert(bins(REFERENCE_AZIMUTH_BINS));
    v.elevation_bin_deg
        .get_or_insert(angle(REFERENCE_ELEVATION_BIN_DEG));
    v.inlier_deg.get_or_insert(angle(REFERENCE_INLIER_DEG));
    v.min_spread_deg
        .get_or_insert(angle(REFERENCE_MIN_SPREAD_DEG));
    o.combined
        .pair_max_deg
        .get_or_insert(angle(REFERENCE_PAIR_MAX_DEG));
    o.pencil
        .polish_max_band_deg
        .get_or_insert(angle(super::pencil::REFERENCE_POLISH_MAX_BAND_DEG));
    o.edge
        .merge
        .max_angle_rad
        .get_or_insert(angle(super::edge::merge::REFERENCE_MAX_ANGLE_RAD));
    Ok((
        o,
        Scales {
            resolution,
            factor,
            derived: opts.angle_scale.is_none(),
        },
    ))
}

/// The options' scales for `cal`, as TOML comment lines: the angular resolution, the factor
/// of the angular options, each angular option in force in degrees and pixels and each pixel
/// option in degrees, at the median resolution.
pub fn scales_report(cal: &Calibration, opts: &DetectorOptions) -> Result<String, DetectError> {
    let auto = opts.method == Method::Auto;
    let (opts, sc) = resolve(cal, opts)?;
    let a = sc.resolution;
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
    line(format!(
        "field of view: {:.3} sr, an extent of {:.3} rad",
        a.extent_rad * a.extent_rad,
        a.extent_rad
    ));
    line(format!(
        "method {}{}",
        opts.method.name(),
        if auto {
            let side = if a.extent_rad < NARROW_EXTENT_RAD {
                "below"
            } else {
                "at least"
            };
            format!(
                " (auto: the field of view's extent {:.3} rad is {side} {NARROW_EXTENT_RAD} rad{})",
                a.extent_rad,
                match opts.method {
                    Method::Strips => ", the camera looks forward",
                    Method::Pencil => ", the camera does not look forward",
                    _ => "",
                }
            )
        } else {
            " (the configuration's)".into()
        }
    ));
    line(format!(
        "angle_scale {:.4} ({}): angular options absent from the configuration are their \
         reference value (at an extent of {REFERENCE_EXTENT_RAD} rad) times it",
        sc.factor,
        if sc.derived {
            "derived from the calibration"
        } else {
            "the configuration's"
        }
    ));
    line("angular options in force, in pixels at the median resolution:".into());
    for (name, d) in [
        ("hough cell along phi", 180.0 / h.phi_bins() as f64),
        ("hough cell along theta", 180.0 / h.theta_bins() as f64),
        ("hough.min_tolerance_deg", h.min_tolerance_deg()),
        ("hough.merge_angle_deg", h.merge_angle_deg()),
        ("vanishing azimuth cell", 180.0 / v.azimuth_bins() as f64),
        ("vanishing.elevation_bin_deg", v.elevation_bin_deg()),
        ("vanishing.inlier_deg", v.inlier_deg()),
        ("vanishing.min_spread_deg", v.min_spread_deg()),
        ("combined.pair_max_deg", opts.combined.pair_max_deg()),
        ("pencil.polish_max_band_deg", pe.polish_max_band_deg()),
        (
            "edge.merge.max_angle_rad",
            opts.edge.merge.max_angle_rad().to_degrees(),
        ),
    ] {
        line(format!("  {name:<28} {d:>7.3} deg = {:>7.2} px", px(d)));
    }
    line("pixel options, in degrees at the median resolution:".into());
    for (name, l) in [
        ("smooth.sigma_px", opts.smooth.sigma_px),
        ("refit.margin_px", opts.refit.margin_px),
        ("edge.split.tolerance_px", opts.edge.split.tolerance_px),
        (
            "edge.merge.max_residual_px",
            opts.edge.merge.max_residual_px,
        ),
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
    #[test]
    fn the_gc2450c_keeps_the_reference_values_and_finer_lenses_get_finer_angles() {
        let defaults = DetectorOptions::default();
        for cal in [
            ideal_fisheye(2050, 2448).unwrap(),
            crate::camera::ideal_pal(2050, 2448).unwrap(),
        ] {
            let (o, sc) = resolve(&cal, &defaults).unwrap();
            assert_eq!(sc.factor, 1.0, "{sc:?}");
            assert_eq!((o.hough.phi_bins, o.hough.theta_bins), (Some(90), Some(90)));
            assert_eq!(o.hough.min_tolerance_deg, Some(0.15));
            assert_eq!(o.vanishing.azimuth_bins, Some(180));
            assert_eq!(o.vanishing.inlier_deg, Some(1.0));
            assert_eq!(o.combined.pair_max_deg, Some(5.0));
        }
        // The same lens at twice the resolution (unbinned), or at a quarter: the same angles.
        let fine = DetectorOptions {
            binning: Binning::Off,
            ..Default::default()
        };
        let (_, sc) = resolve(&ideal_fisheye(2050, 2448).unwrap(), &fine).unwrap();
        assert_eq!(sc.factor, 1.0, "{sc:?}");
        let (_, sc) = resolve(&ideal_fisheye(512, 612).unwrap(), &defaults).unwrap();
        assert_eq!(sc.factor, 1.0, "{sc:?}");
        // A narrower lens: finer angles, in proportion to its field of view's extent.
        let narrow = |f: f64| {
            let text = format!(
                "[pinhole]\nwidth = 512\nheight = 512\nfx = {f}\nfy = {f}\ncx = 255.5\ncy = 255.5\n"
            );
            let cal = Calibration::parse_toml(&text, std::path::Path::new("p.toml")).unwrap();
            resolve(&cal, &defaults).unwrap()
        };
        let ((o3, s3), (o9, s9)) = (narrow(300.0), narrow(900.0));
        // 1.740 sr and 0.300 sr: extents 1.319 and 0.547 rad
        assert!((s3.resolution.extent_rad - 1.319).abs() < 0.01, "{s3:?}");
        assert!((s9.resolution.extent_rad - 0.547).abs() < 0.01, "{s9:?}");
        let r = s3.factor / s9.factor;
        assert!((r - 1.319 / 0.547).abs() < 0.25, "{s3:?} {s9:?}");
        assert_eq!(o3.hough.phi_bins, Some((90.0 / s3.factor).round() as usize));
        assert_eq!(o9.vanishing.inlier_deg, Some(s9.factor));
        assert_eq!(o9.edge.merge.max_angle_rad, Some(0.005 * s9.factor));
    }

    #[test]
    fn the_strips_keep_a_share_of_the_image_above_their_floor_and_other_methods_a_fixed_count() {
        let text = "[pinhole]\nwidth = 640\nheight = 480\nfx = 300.0\nfy = 300.0\n\
                    cx = 319.5\ncy = 239.5\n[mounting]\npitch_deg = -47.0\n";
        let cal = Calibration::parse_toml(text, std::path::Path::new("p.toml")).unwrap();
        let (o, _) = resolve(&cal, &DetectorOptions::default()).unwrap();
        assert_eq!(o.method, Method::Strips);
        let share = super::super::strips::KEPT_SHARE;
        assert_eq!(
            o.threshold.target_points,
            Some((share * 640.0 * 480.0).round() as usize)
        );
        assert_eq!(
            o.threshold.min_level,
            Some(super::super::strips::KEPT_MIN_LEVEL)
        );
        assert_ne!(
            super::super::strips::KEPT_MIN_LEVEL,
            super::super::threshold::DEFAULT_MIN_LEVEL
        );
        // an explicit target, or another method, keeps its own
        let explicit: DetectorOptions =
            toml::from_str("[threshold]\ntarget_points = 5000\nmin_level = 12\n").unwrap();
        let (o, _) = resolve(&cal, &explicit).unwrap();
        assert_eq!(o.threshold.target_points, Some(5000));
        assert_eq!(o.threshold.min_level, Some(12));
        let hough = DetectorOptions {
            method: Method::Hough,
            ..Default::default()
        };
        let (o, _) = resolve(&cal, &hough).unwrap();
        assert_eq!(o.threshold.target_points, None);
        assert_eq!(
            o.threshold.target_points(),
            super::super::threshold::DEFAULT_TARGET_POINTS
        );
        assert_eq!(
            o.threshold.min_level(),
            super::super::threshold::DEFAULT_MIN_LEVEL
        );
    }

    #[test]
    fn explicit_options_override_the_derived_ones() {
        let cal = ideal_fisheye(2050, 2448).unwrap();
        let opts: DetectorOptions = toml::from_str(
            "angle_scale = 0.5\n[hough]\nphi_bins = 60\n[vanishing]\ninlier_deg = 2.0\n",
        )
        .unwrap();
        let (o, _) = resolve(&cal, &opts).unwrap();
        assert_eq!(o.hough.phi_bins, Some(60));
        assert_eq!(o.hough.theta_bins, Some(180));
        assert_eq!(o.vanishing.inlier_deg, Some(2.0));
        assert_eq!(o.vanishing.min_spread_deg, Some(1.0));
        let scaled = DetectorOptions {
            angle_scale: Some(0.25),
            ..Default::default()
        };
        let (o, sc) = resolve(&cal, &scaled).unwrap();
        assert!(!sc.derived);
        assert_eq!(o.hough.phi_bins, Some(360));
        assert_eq!(o.vanishing.min_spread_deg, Some(0.5));
        for bad in [0.0, -1.0, f64::NAN, 1e3] {
            let o = DetectorOptions {
                angle_scale: Some(bad),
                ..Default::default()
            };
            let e = resolve(&cal, &o).unwrap_err().to_string();
            assert!(e.contains("angle_scale"), "{e}");
        }
    }
}
