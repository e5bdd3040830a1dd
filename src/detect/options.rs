//! The detector's options: everything the detector can be told ([`DetectorOptions`], one
//! section per stage, each stage's struct beside its code), the combined method's own
//! ([`CombinedOptions`]) and the binning of full-resolution input ([`Binning`]).
//!
//! Owns the options' shape and defaults only; [`super::scale`] fills the angular options
//! left absent from the calibration, and [`super::detector::Detector`] checks and uses them.

use super::edge::EdgeOptions;
use super::hough::HoughOptions;
use super::mask::MaskOptions;
use super::pencil::PencilOptions;
use super::refit::RefitOptions;
use super::smooth::SmoothOptions;
use super::strips::StripsOptions;
use super::threshold::ThresholdOptions;
use super::vanishing::VanishingOptions;
use super::vegetation::VegetationOptions;
use super::Method;
use serde::{Deserialize, Serialize};

/// Whether full-resolution Mono8/RGB8 input is binned 2×2 before detection.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Binning {
    /// Bin when the image has more than `auto_bin_above_px` pixels (and even sides).
    #[default]
    Auto,
    Off,
    Half,
}

/// Everything the detector can be told.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DetectorOptions {
    /// The row-detection method. Default `auto`: the one for the calibration's lens
    /// (strips for a forward-looking perspective camera's narrow field of view, combined
    /// for an omnidirectional lens; [`Method::Auto`]).
    pub method: Method,
    /// Largest expected tilt of the robot (degrees): bounds the sky mask and the search for
    /// the vanishing point.
    pub max_tilt_deg: f64,
    /// The factor every angular option left absent is its reference value times (the
    /// Hough and vanishing cells, the refinement's, merge, inlier, spread and pairing
    /// angles): absent, the calibration's field of view's extent over the GC2450C's, at
    /// most 1, so that those scales are a fixed share of the field of view
    /// ([`super::scale`]). 1 keeps the values in degrees that fit the GC2450C.
    pub angle_scale: Option<f64>,
    pub binning: Binning,
    pub auto_bin_above_px: u64,
    pub vegetation: VegetationOptions,
    pub mask: MaskOptions,
    pub smooth: SmoothOptions,
    pub threshold: ThresholdOptions,
    pub hough: HoughOptions,
    pub refit: RefitOptions,
    /// The edge method; it reads the detector's smoothed vegetation image at the working
    /// resolution (so by default it neither smooths again nor downsamples).
    pub edge: EdgeOptions,
    pub combined: CombinedOptions,
    pub pencil: PencilOptions,
    pub strips: StripsOptions,
    pub vanishing: VanishingOptions,
}

/// Options of the combined method (paper II-F).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CombinedOptions {
    /// The paper's w (eq. 5): edge rows vote for the vanishing point with w·support, Hough
    /// rows with (1−w)·support. Within (0, 1); default 0.7 as in the paper.
    pub edge_weight: f64,
    /// After the vote, refit the vanishing point over its inlier rows with each method
    /// weighted by the precision its rows show on the image and each row robustly (see
    /// [`super::combine`]); applies to the combined and the edge method. Default true.
    pub precision_weighting: bool,
    /// The smallest per-method scatter (mrad) the precision weighting assumes. Default 0.02.
    pub precision_floor_mrad: f64,
    /// After the eq. 5 vote, also find the vanishing point of each method's rows alone, and
    /// take whichever of the three candidates both methods' rows agree with best (see
    /// [`super::combine::consensus_score`]): another candidate replaces the vote's only when
    /// it scores higher and passes through at least two Hough rows and three rows in all
    /// (edge rows count only where they agree with the Hough rows' structure). The final
    /// inlier rows are then those of either method consistent with the chosen candidate.
    /// The vote is dominated by whichever method's support is larger (Hough accumulator
    /// weight outnumbers edge points), so on a noisy image where the Hough rows are few and
    /// bent, many edge boundaries agreeing with some Hough rows would otherwise be outvoted.
    /// Default true.
    pub consensus: bool,
    /// In the final fit of the combined method, replace the edge method's two boundary
    /// lines of a crop row by their centre line where a Hough row lies between them (see
    /// [`super::combine::pair_edge_rows`]); the centre lines are weighted as a class of
    /// their own, by their own measured scatter, beside the Hough and the unpaired edge rows.
    /// The boundaries' errors largely cancel in the centre line. Default true.
    pub pair_edge_rows: bool,
    /// The largest angle (degrees, around the vanishing point) between a Hough row and an
    /// edge boundary paired with it. Default 5 (the half-width of a crop row seen from the
    /// camera is a few degrees; neighbouring rows are farther apart). Absent: derived from
    /// the calibration's field of view (5° at the GC2450C's; [`super::scale`]).
    pub pair_max_deg: Option<f64>,
    /// The combined method reports only the edge rows consistent with its vanishing point
    /// (within `vanishing.inlier_deg`); the Hough rows are all reported, as by the Hough
    /// method. The edge method's boundaries of sparse rows are mostly stray plant outlines,
    /// which would otherwise count as wrong rows. Default true.
    pub reject_edge_outliers: bool,
}

/// The pairing angle (degrees) at the reference angular resolution.
pub const REFERENCE_PAIR_MAX_DEG: f64 = 5.0;

impl CombinedOptions {
    /// The pairing angle (degrees) in force (the option, else the reference value).
    pub fn pair_max_deg(&self) -> f64 {
        self.pair_max_deg.unwrap_or(REFERENCE_PAIR_MAX_DEG)
    }
}

impl Default for CombinedOptions {
    fn default() -> Self {
        CombinedOptions {
            edge_weight: 0.7,
            precision_weighting: true,
            precision_floor_mrad: 0.02,
            consensus: true,
            pair_edge_rows: true,
            pair_max_deg: None,
            reject_edge_outliers: true,
        }
    }
}

impl Default for DetectorOptions {
    fn default() -> Self {
        DetectorOptions {
            method: Method::Auto,
            max_tilt_deg: 15.0,
            angle_scale: None,
            binning: Binning::Auto,
            auto_bin_above_px: 1_600_000,
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
