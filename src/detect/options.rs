//! The detector's options: the `[detector]` section of the node's configuration, what a
//! user tunes for a field, a lens and a robot ([`DetectorOptions`], one section per stage
//! or method, each section's struct beside its code), and their resolution for one
//! calibration ([`resolve`]: the method `auto` stands for, the angular scales' factor, the
//! threshold's target for the method).
//!
//! Every option has one line in [`OPTIONS`], which `omnirow config detector` prints above it;
//! the keys earlier versions had and no longer do are [`is_removed`], so that a
//! configuration still setting one is told so ([`crate::config`]).

use super::combine::REFERENCE_PAIR_MAX_DEG;
use super::edge::{EdgeOptions, REFERENCE_MAX_ANGLE_RAD};
use super::hough::{HoughOptions, HoughParams};
use super::mask::MaskOptions;
use super::method::combined::CombinedOptions;
use super::pencil::PencilOptions;
use super::prepare::PrepareOptions;
use super::refit::{RefitOptions, MARGIN_PX};
use super::scale::{angle_factor, angular_resolution, AngularResolution, REFERENCE_EXTENT_RAD};
use super::smooth::SmoothOptions;
use super::strips::{StripsOptions, KEPT_MIN_LEVEL, KEPT_SHARE, REFERENCE_POLISH_MAX_BAND_DEG};
use super::threshold::ThresholdOptions;
use super::types::{DetectError, Method};
use super::vanishing::{VanishingOptions, VanishingParams};
use super::vegetation::{Binning, VegetationOptions};
use crate::camera::Calibration;
use serde::{Deserialize, Serialize};
use std::fmt::Write;

/// Everything the detector can be told.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DetectorOptions {
    /// The row-detection method; `auto`: the one for the calibration's lens
    /// ([`super::method::choose`]).
    pub method: Method,
    /// Largest expected tilt of the robot (degrees): bounds the sky mask and the search for
    /// the vanishing point.
    pub max_tilt_deg: f64,
    /// The factor every angular scale is its reference value (tuned on the GC2450C's
    /// lenses) times; absent: the calibration's field of view's extent over the GC2450C's,
    /// at most 1 ([`super::scale`]).
    pub angle_scale: Option<f64>,
    pub binning: Binning,
    pub vegetation: VegetationOptions,
    pub mask: MaskOptions,
    pub smooth: SmoothOptions,
    pub threshold: ThresholdOptions,
    pub hough: HoughOptions,
    pub refit: RefitOptions,
    pub edge: EdgeOptions,
    pub combined: CombinedOptions,
    pub pencil: PencilOptions,
    pub strips: StripsOptions,
    pub vanishing: VanishingOptions,
}

impl Default for DetectorOptions {
    fn default() -> Self {
        DetectorOptions {
            method: Method::Auto,
            max_tilt_deg: 15.0,
            angle_scale: None,
            binning: Binning::Auto,
            vegetation: VegetationOptions::default(),
            mask: MaskOptions::default(),
            smooth: SmoothOptions::default(),
            threshold: ThresholdOptions::default(),
            hough: HoughOptions::default(),
            refit: RefitOptions::default(),
            edge: EdgeOptions::default(),
            combined: CombinedOptions::default(),
            pencil: PencilOptions::default(),
            strips: StripsOptions::default(),
            vanishing: VanishingOptions::default(),
        }
    }
}

/// Every option (dotted under `[detector]`) with one line saying what it does and when a
/// user would change it, in the order `omnirow config detector` prints them.
pub const OPTIONS: &[(&str, &str)] = &[
    ("method", "auto | hough | edge | combined | strips; auto: combined for an omnidirectional lens, strips for a forward-looking perspective camera, hough for one looking down"),
    ("max_tilt_deg", "the robot's largest pitch or roll (degrees): bounds the sky mask and the vanishing point's search; raise it on rough ground"),
    ("angle_scale", "angular scales (Hough cells, inlier band, …) as a factor of the GC2450C's; absent: from the calibration's field of view"),
    ("binning", "auto | off | half: bin 2×2 before detection (auto: above 1.6 Mpx); off for small plants on a large sensor"),
    ("vegetation.index", "auto | excess_green | luma | chromatic_excess_green | excess_green_minus_red: how colour becomes vegetation; chromatic indices for strong shadows, minus-red for reddish soil or straw"),
    ("mask.fov_margin_px", "pixels cut inside the lens's image circle; raise it when its rim shows edges"),
    ("mask.sky", "mask what lies above the horizon; false only when the camera never sees the sky"),
    ("smooth.sigma_px", "Gaussian blur (working pixels) before the threshold; raise it for a noisy sensor or speckled soil"),
    ("threshold.target_points", "about how many of the brightest vegetation pixels are kept; absent: 15000, or 23 % of the image for the strips method"),
    ("threshold.min_level", "vegetation level (0–255) at or below which a pixel is soil; absent: 10, or 7 for the strips method; raise it on weedy or mossy soil"),
    ("hough.max_rows", "the most rows the Hough method reports; raise it when the lens sees more rows (narrow spacing)"),
    ("hough.min_support", "kept points a Hough row needs; lower it for sparse or small plants, raise it when weeds make rows"),
    ("refit.near_reach_m", "metres ahead of and behind the camera within which a curved row is fitted where it passes the robot; 0 publishes each row's whole chord"),
    ("edge.min_support", "edge points a boundary line needs; lower it for small plants or a low resolution"),
    ("combined.edge_weight", "the paper's w: the edge method's share of the vote (0–1); lower it for ragged leafy rows"),
    ("pencil.max_heading_deg", "how far (degrees) the rows may turn from the robot's forward axis (pencil method)"),
    ("pencil.max_rows", "the most rows the pencil method reports"),
    ("pencil.min_separation_px", "rows closer than this (pixels near the robot) are one row: about the narrowest row spacing in the image"),
    ("pencil.comb_max_period_px", "widest row spacing (pixels across the rows near the robot) the pencil's comb searches"),
    ("strips.max_heading_deg", "how far (degrees) the rows may turn from the robot's forward axis; raise it for sharp turns into a row"),
    ("strips.max_rows", "the most rows the strips method reports"),
    ("strips.comb_min_period", "narrowest row spacing searched, as spacing over the camera's height (about); lower it for narrow rows or a high camera"),
    ("strips.comb_max_period", "widest row spacing searched, as spacing over the camera's height (about); raise it for wide rows or a low camera"),
    ("vanishing.inlier_deg", "how far (degrees) a row may pass from the vanishing point and count; absent: from the calibration; raise it for bent rows"),
];

/// Keys that earlier versions read and this one does not, by section under `[detector]`
/// (`""`: the section itself): fixed behaviour now, or experiments that did not win
/// (docs/detector.md, docs/real.md). A configuration that sets one is refused with the key
/// named as removed ([`is_removed`]).
const REMOVED: &[(&str, &str)] = &[
    ("", "auto_bin_above_px"),
    ("hough", "phi_bins theta_bins min_peak_fraction nms_radius refine_iterations min_tolerance_deg merge_angle_deg max_degeneracy vote_points"),
    ("refit", "enabled iterations background_fraction margin_px perspective full_sections wedge plateau_cap precision_weights sections section_bins section_huber section_power near_min_sigma"),
    ("edge", "mask_margin_px downsample canny chains split merge"),
    ("combined", "precision_weighting precision_floor_mrad consensus pair_edge_rows pair_max_deg reject_edge_outliers"),
    ("pencil", "bin_px reference_px search_step_px search_points smooth_px min_prominence min_peak_fraction refine_iterations max_tan candidates coverage_power polish polish_max_band_deg comb comb_min_contrast comb_weak_prominence comb_max_roll_deg comb_power seed_with_combined"),
    ("strips", "strip_px kept_share kept_min_level smooth_px peak_fraction peak_sigma_px search_step_px search_starts search_comb_power search_comb_reach_px search_regions search_coarse_share search_blur min_depth_px min_strips min_strips_share min_strips_floor comb_periods comb_band polish polish_max_band_deg recentre_rounds prominence_px straighten own_lines own_line_anchor own_line_reject"),
    ("vanishing", "azimuth_bins elevation_bin_deg min_spread_deg refine_iterations"),
];

/// Whether the dotted key under `[detector]` is one that earlier versions read
/// ([`REMOVED`]).
pub fn is_removed(key: &str) -> bool {
    let (section, name) = key.rsplit_once('.').unwrap_or(("", key));
    REMOVED
        .iter()
        .any(|(s, names)| *s == section && names.split(' ').any(|n| n == name))
}

/// Every removed key, dotted under `[detector]`.
pub fn removed_keys() -> impl Iterator<Item = String> {
    REMOVED.iter().flat_map(|(s, names)| {
        names.split(' ').map(move |n| match *s {
            "" => n.to_string(),
            s => format!("{s}.{n}"),
        })
    })
}

impl DetectorOptions {
    /// The options the preparation reads.
    pub fn prepare(&self) -> PrepareOptions {
        PrepareOptions {
            max_tilt_deg: self.max_tilt_deg,
            binning: self.binning,
            vegetation: self.vegetation,
            mask: self.mask,
            smooth: self.smooth,
            threshold: self.threshold,
            refit: self.refit,
        }
    }

    /// Checks every option that can be checked without a calibration; the error names the
    /// option and its allowed range.
    pub fn validate(&self) -> Result<(), DetectError> {
        if !(self.max_tilt_deg > 0.0 && self.max_tilt_deg <= 80.0) {
            return Err(DetectError::Options(format!(
                "max_tilt_deg = {} must be within (0, 80]",
                self.max_tilt_deg
            )));
        }
        if let Some(f) = self.angle_scale {
            if !(f.is_finite() && (0.01..=100.0).contains(&f)) {
                return Err(DetectError::Options(format!(
                    "angle_scale = {f} must be within 0.01..=100"
                )));
            }
        }
        self.mask.validate()?;
        self.smooth.validate()?;
        self.threshold.validate()?;
        self.hough.validate()?;
        self.refit.validate()?;
        self.combined.validate()?;
        self.pencil.validate()?;
        self.strips.validate()?;
        self.vanishing.validate()
    }
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

/// `opts` for `cal`: the method `auto` stands for, `angle_scale` (the option, else derived
/// from the calibration's field of view), the inlier band from it when absent, and the
/// threshold's target and floor for the strips method when absent. Options given
/// explicitly are kept.
pub fn resolve(
    cal: &Calibration,
    opts: &DetectorOptions,
) -> Result<(DetectorOptions, Scales), DetectError> {
    opts.validate()?;
    let resolution = angular_resolution(cal, opts.binning).map_err(|e| {
        DetectError::Calibration(format!("angular resolution at the working size: {e}"))
    })?;
    let factor = opts
        .angle_scale
        .unwrap_or_else(|| angle_factor(&resolution));
    let mut o = opts.clone();
    o.angle_scale = Some(factor);
    if o.method == Method::Auto {
        o.method = super::method::choose(resolution.extent_rad, &cal.mounting);
    }
    if o.method == Method::Strips {
        let pixels = resolution.width as f64 * resolution.height as f64;
        let share = ((KEPT_SHARE * pixels).round() as usize).max(1);
        o.threshold.target_points.get_or_insert(share);
        o.threshold.min_level.get_or_insert(KEPT_MIN_LEVEL);
    }
    o.vanishing.inlier_deg = Some(VanishingParams::new(&o.vanishing, factor).inlier_deg);
    Ok((
        o,
        Scales {
            resolution,
            factor,
            derived: opts.angle_scale.is_none(),
        },
    ))
}

/// The options' scales for `cal`, as TOML comment lines: the working image, the angular
/// resolution, the method and why, the factor of the angular scales, and each angular scale
/// in force in degrees and pixels (each pixel scale in degrees) at the median resolution.
pub fn scales_report(cal: &Calibration, opts: &DetectorOptions) -> Result<String, DetectError> {
    let (o, sc) = resolve(cal, opts)?;
    let a = sc.resolution;
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
        a.centre_px_per_rad, a.median_px_per_rad
    ));
    line(format!(
        "field of view: {:.3} sr, an extent of {:.3} rad",
        a.extent_rad * a.extent_rad,
        a.extent_rad
    ));
    line(method_line(&o, &a, opts.method == Method::Auto));
    line(format!(
        "angle_scale {:.4} ({}): angular scales are their reference value (at an extent of \
         {REFERENCE_EXTENT_RAD} rad) times it",
        sc.factor,
        if sc.derived {
            "derived from the calibration"
        } else {
            "the configuration's"
        }
    ));
    scale_lines(&o, &sc, &mut line);
    Ok(s)
}

/// The report's line on the method: the configuration's, or what `auto` chose and why.
fn method_line(o: &DetectorOptions, a: &AngularResolution, auto: bool) -> String {
    use super::method::NARROW_EXTENT_RAD;
    if !auto {
        return format!("method {} (the configuration's)", o.method.name());
    }
    let side = if a.extent_rad < NARROW_EXTENT_RAD {
        "below"
    } else {
        "at least"
    };
    let looks = match o.method {
        Method::Strips => ", the camera looks forward",
        Method::Pencil => ", the camera does not look forward",
        _ => "",
    };
    format!(
        "method {} (auto: the field of view's extent {:.3} rad is {side} {NARROW_EXTENT_RAD} rad{looks})",
        o.method.name(),
        a.extent_rad
    )
}

/// The report's lines on each scale in force, in degrees and in pixels.
fn scale_lines(o: &DetectorOptions, sc: &Scales, line: &mut impl FnMut(String)) {
    let p = sc.resolution.median_px_per_rad;
    let px = |deg: f64| deg.to_radians() * p;
    let deg = |px: f64| (px / p).to_degrees();
    let h = HoughParams::new(&o.hough, sc.factor);
    let v = VanishingParams::new(&o.vanishing, sc.factor);
    line("angular scales in force, in pixels at the median resolution:".into());
    for (name, d) in [
        ("hough cell", 180.0 / h.bins as f64),
        ("hough narrowest band", h.min_tolerance_deg),
        ("hough merge angle", h.merge_angle_deg),
        ("vanishing azimuth cell", 180.0 / v.azimuth_bins as f64),
        ("vanishing elevation cell", v.elevation_bin_deg),
        ("vanishing.inlier_deg", v.inlier_deg),
        ("vanishing smallest spread", v.min_spread_deg),
        ("crop row's widest half", REFERENCE_PAIR_MAX_DEG * sc.factor),
        (
            "strips polish band",
            REFERENCE_POLISH_MAX_BAND_DEG * sc.factor,
        ),
        (
            "edge merge angle",
            (REFERENCE_MAX_ANGLE_RAD * sc.factor).to_degrees(),
        ),
    ] {
        line(format!("  {name:<28} {d:>7.3} deg = {:>7.2} px", px(d)));
    }
    line("pixel scales, in degrees at the median resolution:".into());
    for (name, l) in [
        ("smooth.sigma_px", o.smooth.sigma_px),
        ("refit margin", MARGIN_PX),
    ] {
        line(format!("  {name:<28} {l:>7.2} px = {:>7.3} deg", deg(l)));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::ideal_fisheye;

    #[test]
    fn every_option_has_one_line_and_there_are_at_most_forty() {
        assert!(OPTIONS.len() <= 40, "{}", OPTIONS.len());
        // every key the defaults serialise, and the absent ones, are described
        let text = toml::to_string(&DetectorOptions::default()).unwrap();
        let table: toml::Table = toml::from_str(&text).unwrap();
        let mut keys = Vec::new();
        for (k, v) in &table {
            match v.as_table() {
                Some(t) => keys.extend(t.keys().map(|s| format!("{k}.{s}"))),
                None => keys.push(k.clone()),
            }
        }
        for k in [
            "angle_scale",
            "threshold.target_points",
            "threshold.min_level",
            "vanishing.inlier_deg",
        ] {
            keys.push(k.into());
        }
        let described: Vec<&str> = OPTIONS.iter().map(|o| o.0).collect();
        keys.sort();
        let mut sorted = described.clone();
        sorted.sort();
        assert_eq!(keys, sorted);
        for (k, doc) in OPTIONS {
            assert!(!doc.is_empty() && !doc.contains('\n'), "{k}");
            assert!(!is_removed(k), "{k}");
        }
    }

    #[test]
    fn the_gc2450c_keeps_the_reference_scales_and_finer_lenses_get_finer_ones() {
        let defaults = DetectorOptions::default();
        for cal in [
            ideal_fisheye(2050, 2448).unwrap(),
            crate::camera::ideal_pal(2050, 2448).unwrap(),
        ] {
            let (o, sc) = resolve(&cal, &defaults).unwrap();
            assert_eq!(sc.factor, 1.0, "{sc:?}");
            assert_eq!(o.method, Method::Combined);
            assert_eq!(HoughParams::new(&o.hough, sc.factor).bins, 90);
            assert_eq!(o.vanishing.inlier_deg, Some(1.0));
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
        assert_eq!(
            HoughParams::new(&o3.hough, s3.factor).bins,
            (90.0 / s3.factor).round() as usize
        );
        assert_eq!(o9.vanishing.inlier_deg, Some(s9.factor));
        assert_eq!(o9.angle_scale, Some(s9.factor));
    }

    #[test]
    fn the_strips_keep_a_share_of_the_image_above_their_floor_and_other_methods_a_fixed_count() {
        let text = "[pinhole]\nwidth = 640\nheight = 480\nfx = 300.0\nfy = 300.0\n\
                    cx = 319.5\ncy = 239.5\n[mounting]\npitch_deg = -47.0\n";
        let cal = Calibration::parse_toml(text, std::path::Path::new("p.toml")).unwrap();
        let (o, _) = resolve(&cal, &DetectorOptions::default()).unwrap();
        assert_eq!(o.method, Method::Strips);
        assert_eq!(
            o.threshold.target_points,
            Some((KEPT_SHARE * 640.0 * 480.0).round() as usize)
        );
        assert_eq!(o.threshold.min_level, Some(KEPT_MIN_LEVEL));
        assert_ne!(KEPT_MIN_LEVEL, super::super::threshold::DEFAULT_MIN_LEVEL);
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
        // the same lens looking straight down: the pencil method
        let mut down = cal.clone();
        down.mounting.pitch_deg = 0.0;
        assert_eq!(
            resolve(&down, &DetectorOptions::default())
                .unwrap()
                .0
                .method,
            Method::Pencil
        );
    }

    #[test]
    fn explicit_options_override_the_derived_ones() {
        let cal = ideal_fisheye(2050, 2448).unwrap();
        let opts: DetectorOptions =
            toml::from_str("angle_scale = 0.5\n[vanishing]\ninlier_deg = 2.0\n").unwrap();
        let (o, sc) = resolve(&cal, &opts).unwrap();
        assert!(!sc.derived);
        assert_eq!(sc.factor, 0.5);
        assert_eq!(o.vanishing.inlier_deg, Some(2.0));
        let v = VanishingParams::new(&o.vanishing, sc.factor);
        assert_eq!(v.min_spread_deg, 1.0);
        assert_eq!(HoughParams::new(&o.hough, sc.factor).bins, 180);
        for bad in [0.0, -1.0, f64::NAN, 1e3] {
            let o = DetectorOptions {
                angle_scale: Some(bad),
                ..Default::default()
            };
            let e = resolve(&cal, &o).unwrap_err().to_string();
            assert!(e.contains("angle_scale"), "{e}");
        }
    }

    #[test]
    fn the_report_gives_each_scale_in_pixels() {
        let big = ideal_fisheye(1200, 1200).unwrap();
        let text = scales_report(&big, &DetectorOptions::default()).unwrap();
        assert!(text.contains("hough cell"), "{text}");
        assert!(text.contains("method combined (auto"), "{text}");
        assert!(text.lines().all(|l| l.starts_with('#')), "{text}");
    }
}
