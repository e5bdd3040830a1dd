//! The strips method: crop rows of a forward-looking camera as the vegetation's peaks along
//! horizontal strips, linked through the vanishing point that lines them up best, and read
//! off as the teeth of the rows' evenly spaced comb.
//!
//! Owns the virtual image the method works in, the strips' peaks, the search for the
//! vanishing point and the comb. The points (unit rays) are taken to the camera's own
//! perspective image (pixels of an ideal pinhole on the optical axis, at the calibration's
//! angular resolution), turned so that the strips run along the horizon that the mounting
//! implies. Each strip (`strip_px` high) gives its vegetation profile across the image;
//! the profile's peaks are where a crop row crosses the strip. For a vanishing point
//! (a_v, p_v) — along and below the horizon — a peak at (a, p) lies at u = (a − a_v)/(p − p_v)
//! in the pencil of lines through it: for crop rows on flat ground, u is proportional to the
//! row's lateral position over the camera's height, so at the right vanishing point the
//! peaks of one row share one u in every strip, and the rows' u are evenly spaced. The search
//! maximises the agreement of the strips' peaks in u (a kernel sum over pairs from different
//! strips, each peak's width in u its pixel uncertainty over its depth below the vanishing
//! point) within the expected heading and tilt; the comb's period and phase then come from
//! the peaks' u (the strongest Fourier component), read on the peaks again with each strip
//! straightened about that point, and each tooth seen in at least `min_strips` strips (fewer
//! when its line leaves the image early) is a row through the vanishing point. Peaks between
//! the teeth (weeds, plant edges, shadows) are not rows. Every length is in pixels of that
//! virtual image, so the same scene through any focal length gives the same rows.

use super::pose::RobotAxes;
use super::{DetectError, Method, Row};
use crate::camera::Mounting;
use multiversion::multiversion;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Options of the strips method. Lengths are pixels of the camera's perspective image at
/// its angular resolution near the optical axis.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StripsOptions {
    /// Height of one strip along the image's vertical (across the horizon).
    pub strip_px: f64,
    /// The share of the working image's pixels kept as points (the threshold's target when
    /// `threshold.target_points` is absent): the strips' profiles need the rows' whole
    /// vegetation, pale plants included, not only its brightest few per cent.
    pub kept_share: f64,
    /// The threshold's floor for this method (`threshold.min_level` when that is absent): 7
    /// (10 until 2026-12-06) keeps faint and shadowed plants (2G − R − B from 16 on the
    /// halved excess-green image), which a sparse field needs to fill its share
    /// (docs/real.md).
    pub kept_min_level: u8,
    /// Gaussian smoothing (sigma) of a strip's profile before its peaks are read: about a
    /// plant's half-width.
    pub smooth_px: f64,
    /// A local maximum is a peak when it stands at least this fraction of the strip's
    /// highest above the strip's median.
    pub peak_fraction: f64,
    /// Uncertainty (sigma) of a peak's position, the kernel's width in the search.
    pub peak_sigma_px: f64,
    /// Step of the coarse grid of candidate vanishing points (then halved to 1 px).
    pub search_step_px: f64,
    /// How many of the coarse grid's best local maxima are refined to 1 px. The highest
    /// summit they climb to is the answer, unless the comb breaks a near tie
    /// (`search_comb_power`).
    pub search_starts: usize,
    /// The climbed summits within `search_comb_reach_px` of the highest are ranked by their
    /// agreement times the comb's strength there (the peaks' strongest Fourier component in
    /// u, 0..1) to this power; 0 ranks by the agreement alone. Crop rows are evenly spaced on
    /// the ground, so of two nearby summits that the pairs' agreement nearly ties — on real
    /// fields the near field's big plants line up from a point above the rows' as well as
    /// from theirs — the rows' own is the one from which the peaks form the stronger comb.
    /// The power is small: the comb only breaks ties (0.25: a summit needs a comb 2× as
    /// strong to beat one 19 % higher).
    pub search_comb_power: f64,
    /// How far from the highest summit (virtual image pixels) another may win by its comb:
    /// farther summits are other structures (a hedge, tramlines seen from the side), whose
    /// lines can look evenly spaced too.
    pub search_comb_reach_px: f64,
    /// The grid is first evaluated at twice its step, and then in full only within one
    /// coarse step of that coarser grid's this many best local maxima (0: the whole grid).
    pub search_regions: usize,
    /// The share (0..1] of the peaks, the strongest, that the first, coarser grid is
    /// evaluated with when `search_regions` > 0; the regions around its best maxima and the
    /// climb to 1 px then use all of them. 1: all peaks throughout. 0.5 costs about a
    /// quarter of the coarse grid's pairs (measured on CRDLD: docs/real.md).
    pub search_coarse_share: f64,
    /// At each step of the search, the peaks' uncertainty is widened by this times the
    /// step (0: `peak_sigma_px` at every step).
    pub search_blur: f64,
    /// Largest heading of the rows from the robot's forward axis searched (degrees).
    pub max_heading_deg: f64,
    /// Peaks nearer the horizon than this (below the candidate vanishing point) take no
    /// part: there the rows merge.
    pub min_depth_px: f64,
    /// A tooth of the comb is a row when peaks lie on it in at least this many strips.
    pub min_strips: usize,
    /// A tooth whose line leaves the points early (an outer row leaving the image by its
    /// side) cannot have peaks in `min_strips` strips: it needs only this share of the
    /// strips its line crosses inside their points (below `min_depth_px`), rounded up, but
    /// at least `min_strips_floor` and at most `min_strips`.
    pub min_strips_share: f64,
    /// The fewest strips a tooth ever needs (see `min_strips_share`).
    pub min_strips_floor: usize,
    /// Shortest and longest comb period searched, in u (lateral over depth in the pencil:
    /// row spacing over the camera's height, about).
    pub comb_min_period: f64,
    pub comb_max_period: f64,
    /// Periods tried between the two, geometrically spaced.
    pub comb_periods: usize,
    /// A peak is on a tooth within this fraction of the period.
    pub comb_band: f64,
    /// At most this many rows are reported (the best supported).
    pub max_rows: usize,
    /// Refit the rows on the image's pixels near each, and the vanishing point on them (as
    /// the pencil's polish).
    pub polish: bool,
    /// The polish's widest band around a row (degrees; a quarter of the angle to its nearest
    /// neighbour otherwise). Derived from the calibration when absent: the reference value
    /// times `angle_scale` (docs/detector.md).
    pub polish_max_band_deg: Option<f64>,
    /// A row is placed at the weighted mean u of the peaks within `comb_band` of it,
    /// re-centred this many times starting from its tooth (0: on the comb's tooth). Real
    /// rows are not evenly spaced (tramlines, drilling units, a wandering drill), and the
    /// polish moves a row only within its band.
    pub recentre_rounds: usize,
    /// A peak's height is its prominence within this many pixels on either side (how far it
    /// stands above the higher of the lowest points left and right of it) instead of its
    /// height above the strip's median (0). Rows inside dense canopy stand above their
    /// valleys but not above a median that the canopy raised.
    pub prominence_px: f64,
    /// Before the comb, the strips' peaks are read again with each strip's points
    /// straightened about the vanishing point found (each moved along its line through that
    /// point to the strip's centre line), so that a row crossing a strip at a slant is one
    /// sharp peak rather than a smear `strip_px` × its slope wide. The search itself keeps
    /// the first peaks (climbing on the straightened ones lost rows: docs/real.md).
    pub straighten: bool,
    /// Each row is fitted its own straight line (in the virtual image) to the straightened
    /// peaks on its tooth (those within `comb_band` of it in u), each peak counting once as
    /// every scan line of a labelled row does, with the vanishing point as one more point
    /// weighing `own_line_anchor` times all of them; otherwise (false) the row is its
    /// tooth's line through the vanishing point. Real rows do not all meet in one point
    /// (rows bend, rise and fall with the ground; a drill wanders), and a row's line through
    /// a common point a few pixels off misses its far field (docs/real.md).
    pub own_lines: bool,
    /// The vanishing point's weight in a row's own line, as a share of the row's peaks: the
    /// far field, where the rows merge, then follows the common point, and the near field
    /// the row's own peaks.
    pub own_line_anchor: f64,
    /// The row's line is fitted again without the peaks farther from the first fit than
    /// this many `peak_sigma_px` (a weed or a neighbouring plant on the tooth's band);
    /// 0 keeps every peak.
    pub own_line_reject: f64,
}

impl Default for StripsOptions {
    fn default() -> Self {
        StripsOptions {
            strip_px: 11.0,
            kept_share: 0.23,
            kept_min_level: 7,
            smooth_px: 2.5,
            peak_fraction: 0.15,
            peak_sigma_px: 4.0,
            search_step_px: 8.0,
            search_starts: 3,
            search_comb_power: 0.25,
            search_comb_reach_px: 100.0,
            search_regions: 6,
            search_coarse_share: 1.0,
            search_blur: 0.0,
            max_heading_deg: 25.0,
            min_depth_px: 12.0,
            min_strips: 7,
            min_strips_share: 0.8,
            min_strips_floor: 6,
            comb_min_period: 0.075,
            comb_max_period: 0.75,
            comb_periods: 160,
            comb_band: 0.2,
            max_rows: 16,
            polish: true,
            polish_max_band_deg: None,
            recentre_rounds: 2,
            prominence_px: 15.0,
            straighten: true,
            own_lines: true,
            own_line_anchor: 0.3,
            own_line_reject: 2.0,
        }
    }
}

/// The share of the working image's pixels the threshold keeps for this method.
pub const KEPT_SHARE: f64 = 0.23;
/// The threshold's floor for this method.
pub const KEPT_MIN_LEVEL: u8 = 7;

/// The strips polish's widest band (degrees) at the reference angular resolution: twice the
/// pencil's, since the strips' rows lie on their own peaks and only need room to reach the
/// row's centre, and no wider, since a wide band lets the refit pull a row off its own
/// line (16 until 2026-12-06; measured on CRDLD: docs/real.md).
pub const REFERENCE_POLISH_MAX_BAND_DEG: f64 = 6.0;

impl StripsOptions {
    /// The polish's widest band (degrees) in force (the option, else the reference value).
    pub fn polish_max_band_deg(&self) -> f64 {
        self.polish_max_band_deg
            .unwrap_or(REFERENCE_POLISH_MAX_BAND_DEG)
    }

    pub fn validate(&self) -> Result<(), DetectError> {
        let bad = |what: &str| Err(DetectError::Options(format!("strips.{what}")));
        let pos = |v: f64| v.is_finite() && v > 0.0;
        if !(pos(self.strip_px) && self.strip_px <= 1000.0) {
            return bad(&format!(
                "strip_px = {} must be within (0, 1000]",
                self.strip_px
            ));
        }
        if !(self.kept_share.is_finite() && self.kept_share > 0.0 && self.kept_share <= 1.0) {
            return bad(&format!(
                "kept_share = {} must be within (0, 1]",
                self.kept_share
            ));
        }
        if !(pos(self.smooth_px) && self.smooth_px <= 100.0) {
            return bad(&format!(
                "smooth_px = {} must be within (0, 100]",
                self.smooth_px
            ));
        }
        if !(self.peak_fraction.is_finite() && (0.0..1.0).contains(&self.peak_fraction)) {
            return bad(&format!(
                "peak_fraction = {} must be within [0, 1)",
                self.peak_fraction
            ));
        }
        if !(pos(self.peak_sigma_px) && self.peak_sigma_px <= 100.0) {
            return bad(&format!(
                "peak_sigma_px = {} must be within (0, 100]",
                self.peak_sigma_px
            ));
        }
        for (name, v) in [
            ("own_line_anchor", self.own_line_anchor),
            ("own_line_reject", self.own_line_reject),
        ] {
            if !(v.is_finite() && (0.0..=100.0).contains(&v)) {
                return bad(&format!("{name} = {v} must be within [0, 100]"));
            }
        }
        if !(self.search_step_px.is_finite() && (1.0..=200.0).contains(&self.search_step_px)) {
            return bad(&format!(
                "search_step_px = {} must be within 1..=200",
                self.search_step_px
            ));
        }
        if !(self.search_blur.is_finite() && (0.0..=10.0).contains(&self.search_blur)) {
            return bad(&format!(
                "search_blur = {} must be within 0..=10",
                self.search_blur
            ));
        }
        if !(1..=64).contains(&self.search_starts) {
            return bad(&format!(
                "search_starts = {} must be within 1..=64",
                self.search_starts
            ));
        }
        if !(self.search_comb_power.is_finite() && (0.0..=4.0).contains(&self.search_comb_power)) {
            return bad(&format!(
                "search_comb_power = {} must be within 0..=4",
                self.search_comb_power
            ));
        }
        if !(pos(self.search_comb_reach_px) && self.search_comb_reach_px <= 10000.0) {
            return bad(&format!(
                "search_comb_reach_px = {} must be within (0, 10000]",
                self.search_comb_reach_px
            ));
        }
        if !(pos(self.search_coarse_share) && self.search_coarse_share <= 1.0) {
            return bad(&format!(
                "search_coarse_share = {} must be within (0, 1]",
                self.search_coarse_share
            ));
        }
        if self.search_regions > 1024 {
            return bad(&format!(
                "search_regions = {} must be within 0..=1024",
                self.search_regions
            ));
        }
        if !(self.max_heading_deg.is_finite() && (0.0..80.0).contains(&self.max_heading_deg)) {
            return bad(&format!(
                "max_heading_deg = {} must be within [0, 80)",
                self.max_heading_deg
            ));
        }
        if !(pos(self.min_depth_px) && self.min_depth_px <= 1000.0) {
            return bad(&format!(
                "min_depth_px = {} must be within (0, 1000]",
                self.min_depth_px
            ));
        }
        if !(2..=1000).contains(&self.min_strips) {
            return bad(&format!(
                "min_strips = {} must be within 2..=1000",
                self.min_strips
            ));
        }
        if !(2..=self.min_strips).contains(&self.min_strips_floor) {
            return bad(&format!(
                "min_strips_floor = {} must be within 2..=min_strips ({})",
                self.min_strips_floor, self.min_strips
            ));
        }
        if !(self.min_strips_share.is_finite()
            && self.min_strips_share > 0.0
            && self.min_strips_share <= 1.0)
        {
            return bad(&format!(
                "min_strips_share = {} must be within (0, 1]",
                self.min_strips_share
            ));
        }
        if !(pos(self.comb_min_period)
            && self.comb_min_period < self.comb_max_period
            && self.comb_max_period <= 100.0)
        {
            return bad(&format!(
                "comb_min_period = {}, comb_max_period = {}: need 0 < min < max <= 100",
                self.comb_min_period, self.comb_max_period
            ));
        }
        if !(2..=10_000).contains(&self.comb_periods) {
            return bad(&format!(
                "comb_periods = {} must be within 2..=10000",
                self.comb_periods
            ));
        }
        if !(self.comb_band > 0.0 && self.comb_band <= 0.5) {
            return bad(&format!(
                "comb_band = {} must be within (0, 0.5]",
                self.comb_band
            ));
        }
        let b = self.polish_max_band_deg();
        if !(b.is_finite() && b > 0.0 && b <= 45.0) {
            return bad(&format!("polish_max_band_deg = {b} must be within (0, 45]"));
        }
        if !(self.prominence_px.is_finite() && (0.0..=1000.0).contains(&self.prominence_px)) {
            return bad(&format!(
                "prominence_px = {} must be within 0..=1000",
                self.prominence_px
            ));
        }
        if self.recentre_rounds > 16 {
            return bad(&format!(
                "recentre_rounds = {} must be within 0..=16",
                self.recentre_rounds
            ));
        }
        if !(1..=256).contains(&self.max_rows) {
            return bad(&format!(
                "max_rows = {} must be within 1..=256",
                self.max_rows
            ));
        }
        Ok(())
    }
}

/// What the strips method found in the last image.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StripsResult {
    /// Peaks read off the strips.
    pub peaks: usize,
    /// The vanishing point (virtual image: along, below the horizon, pixels) and its
    /// agreement score; `None` when there was too little to search.
    pub vanishing_px: Option<[f64; 2]>,
    pub agreement: f64,
    /// The comb's period (in u) and its strength (0..1, the peaks' Fourier amplitude).
    pub period: f64,
    pub comb_strength: f64,
    /// Candidate vanishing points evaluated.
    pub evaluated: usize,
}

/// A peak of a strip: along the horizon, below it (pixels), its height, its strip.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Peak {
    a: f64,
    p: f64,
    w: f64,
    strip: u32,
}

/// The peaks seen from a candidate vanishing point, in columns sorted by u: u, the square
/// of the kernel's width in u, weight and strip.
#[derive(Debug, Clone, Default)]
struct SeenColumns {
    u: Vec<f64>,
    s2: Vec<f64>,
    w: Vec<f64>,
    strip: Vec<u32>,
}

impl SeenColumns {
    fn clear(&mut self) {
        self.u.clear();
        self.s2.clear();
        self.w.clear();
        self.strip.clear();
    }

    fn push(&mut self, u: f64, s: f64, w: f64, strip: u32) {
        self.u.push(u);
        self.s2.push(s * s);
        self.w.push(w);
        self.strip.push(strip);
    }

    fn len(&self) -> usize {
        self.u.len()
    }

    /// The peaks within `band` of `u`.
    fn within(&self, u: f64, band: f64) -> std::ops::Range<usize> {
        let lo = self.u.partition_point(|&x| x < u - band);
        let hi = self.u.partition_point(|&x| x <= u + band);
        lo..hi
    }

    /// Σ over the pairs of peaks from different strips of wᵢwⱼ·K(Δu / √(sᵢ² + sⱼ²)) and the
    /// peaks' total weight; K the triweight kernel with a standard deviation of 1.
    fn pair_sum(&self) -> (f64, f64) {
        pair_sum(&self.u, &self.s2, &self.w, &self.strip)
    }
}

/// [`SeenColumns::pair_sum`] on the columns. Compiled also for AVX2 (four lanes in one
/// register), chosen at run time; the same operations in the same order either way.
#[multiversion(targets("x86_64+avx2"))]
fn pair_sum(u: &[f64], s2: &[f64], w: &[f64], strip: &[u32]) -> (f64, f64) {
    let s2_max = s2.iter().fold(0.0f64, |m, &x| m.max(x));
    let (mut num, mut total) = (0.0, 0.0);
    let mut end = 0;
    for i in 0..u.len() {
        let (xu, xs2, xw) = (u[i], s2[i], w[i]);
        total += xw;
        // every pair within the kernel's support lies before `end` (a pair beyond the
        // support adds an exact zero, so `end` only has to be far enough)
        let reach = 3.0 * (xs2 + s2_max).sqrt();
        end = end.max(i + 1);
        while end < u.len() && u[end] - xu <= reach {
            end += 1;
        }
        num += xw * pairs(u, s2, w, strip, i, end);
    }
    (num, total)
}

/// Σ over the peaks `i+1..end` of wⱼ·K(Δu / √(sᵢ² + sⱼ²)) for those from another strip
/// than peak `i`; K the triweight kernel with a standard deviation of 1. Branch-free in
/// four lanes: a pair outside the kernel's support or within one strip adds zero.
#[inline(always)]
fn pairs(u: &[f64], s2: &[f64], w: &[f64], strip: &[u32], i: usize, end: usize) -> f64 {
    let (xu, xs2, xstrip) = (u[i], s2[i], strip[i]);
    let r = i + 1..end;
    let (u, s2, w, st) = (&u[r.clone()], &s2[r.clone()], &w[r.clone()], &strip[r]);
    let term = |u: f64, s2: f64, w: f64, st: u32| {
        let du = u - xu;
        let k = 1.0 - du * du / (9.0 * (xs2 + s2));
        let k = if k > 0.0 { k } else { 0.0 };
        let w = if st != xstrip { w } else { 0.0 };
        w * k * k * k
    };
    let mut acc = [0.0f64; 4];
    let lanes = u
        .chunks_exact(4)
        .zip(s2.chunks_exact(4))
        .zip(w.chunks_exact(4))
        .zip(st.chunks_exact(4));
    for (((u, s2), w), st) in lanes {
        for l in 0..4 {
            acc[l] += term(u[l], s2[l], w[l], st[l]);
        }
    }
    let full = u.len() / 4 * 4;
    for j in full..u.len() {
        acc[0] += term(u[j], s2[j], w[j], st[j]);
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3])
}

/// The strips method's state: the virtual image's frame, its search window and the
/// buffers reused from image to image.
#[derive(Debug, Clone)]
pub struct StripsRows {
    opts: StripsOptions,
    max_tilt: f64,
    axes: RobotAxes,
    /// Unit image directions (row, column) of "below the horizon" and "along it".
    e_p: [f64; 2],
    e_a: [f64; 2],
    /// Pixels per radian of the virtual image (the last image's).
    scale: f64,
    pts: Vec<[f64; 3]>,
    hist: Vec<f64>,
    smooth: Vec<f64>,
    kernel: Vec<f64>,
    scratch: Vec<f64>,
    peaks: Vec<Peak>,
    /// The strongest peaks, for the coarse grid (`search_coarse_share`).
    coarse_peaks: Vec<Peak>,
    /// The coarse search's grid of agreements and the local maxima refined from it.
    grid: Vec<f64>,
    /// The prior's vanishing point (unit) and window half-angle, when narrowed.
    prior: Option<(Vector3<f64>, f64)>,
    /// The grid's local maxima (agreement, column, row), best first; in the search, once
    /// climbed, its summits (agreement, along, below).
    starts: Vec<(f64, f64, f64)>,
    /// The peaks below the last candidate, for the agreement's pair sums and the comb.
    columns: SeenColumns,
    /// The sort keys of the peaks below a candidate (u, then the peak's index).
    keys: Vec<u64>,
    /// The comb's teeth that are rows: u, weight and the number of peaks on them.
    teeth: Vec<[f64; 3]>,
    /// Each strip's centre (below) and the extent of its points (along from, to).
    spans: Vec<[f64; 3]>,
    last: StripsResult,
}

/// The eight neighbours of a grid point, in steps.
const NEIGHBOURS: [(f64, f64); 8] = [
    (-1.0, -1.0),
    (0.0, -1.0),
    (1.0, -1.0),
    (-1.0, 0.0),
    (1.0, 0.0),
    (-1.0, 1.0),
    (0.0, 1.0),
    (1.0, 1.0),
];

/// The most rounds of halving steps [`StripsRows::agreement_near`] climbs (each moves the
/// point less than `search_step_px` along each axis).
const CLIMB_ROUNDS: usize = 8;

/// The most strips and profile bins an image may have (a hostile calibration or image
/// cannot make the buffers grow without bound).
const MAX_STRIPS: usize = 4096;
const MAX_BINS: usize = 16384;

impl StripsRows {
    /// `max_tilt_deg`: the vanishing point is searched within ± this angle of the robot's
    /// horizontal plane; the mounting says where that plane and the robot's forward axis are.
    pub fn new(
        opts: StripsOptions,
        max_tilt_deg: f64,
        mounting: &Mounting,
    ) -> Result<Self, DetectError> {
        opts.validate()?;
        let axes = RobotAxes::new(mounting);
        let (fwd, up) = (axes.fwd, axes.up);
        if !looks_forward(mounting) {
            return Err(DetectError::Options(format!(
                "method strips needs a forward-looking camera: the robot's forward axis is \
                 {:.0}° from the optical axis with this mounting (pitch_deg {}, roll_deg {}, \
                 yaw_deg {}); use hough, combined or auto",
                (-fwd.z).clamp(-1.0, 1.0).acos().to_degrees(),
                mounting.pitch_deg,
                mounting.roll_deg,
                mounting.yaw_deg
            )));
        }
        // image directions of "down towards the ground" and "along the horizon" at the
        // nominal vanishing point
        let eps: f64 = 1e-3;
        let p0 = project(&fwd, 1.0);
        let p1 = project(&(fwd * eps.cos() - up * eps.sin()), 1.0);
        let (Some(p0), Some(p1)) = (p0, p1) else {
            return Err(DetectError::Options(
                "method strips: the mounting's horizon is not in the image".into(),
            ));
        };
        let d = [p1[0] - p0[0], p1[1] - p0[1]];
        let n = (d[0] * d[0] + d[1] * d[1]).sqrt();
        if n <= 0.0 {
            return Err(DetectError::Options(
                "method strips: the mounting's horizon is not in the image".into(),
            ));
        }
        let e_p = [d[0] / n, d[1] / n];
        Ok(StripsRows {
            opts,
            max_tilt: max_tilt_deg.to_radians(),
            axes,
            e_p,
            e_a: [-e_p[1], e_p[0]],
            scale: 0.0,
            pts: Vec::new(),
            hist: Vec::new(),
            smooth: Vec::new(),
            kernel: Vec::new(),
            scratch: Vec::new(),
            peaks: Vec::new(),
            coarse_peaks: Vec::new(),
            grid: Vec::new(),
            prior: None,
            starts: Vec::new(),
            columns: SeenColumns::default(),
            keys: Vec::new(),
            teeth: Vec::new(),
            spans: Vec::new(),
            last: StripsResult::default(),
        })
    }

    pub fn options(&self) -> &StripsOptions {
        &self.opts
    }

    /// What the last image gave.
    pub fn last(&self) -> StripsResult {
        self.last
    }

    /// (along, below) of a ray in the virtual image, pixels; `None` behind the camera.
    fn to_virtual(&self, r: &Vector3<f64>) -> Option<[f64; 2]> {
        let q = project(r, self.scale)?;
        Some([
            q[0] * self.e_a[0] + q[1] * self.e_a[1],
            q[0] * self.e_p[0] + q[1] * self.e_p[1],
        ])
    }

    /// The ray of a virtual image point (along, below).
    fn to_ray(&self, a: f64, p: f64) -> Vector3<f64> {
        let row = a * self.e_a[0] + p * self.e_p[0];
        let col = a * self.e_a[1] + p * self.e_p[1];
        Vector3::new(row / self.scale, col / self.scale, -1.0).normalize()
    }

    /// Finds the rows among the points (unit rays, weights, each pixel's angular size)
    /// into `rows` (cleared first). Returns the vanishing point's direction, or `None` when
    /// the points hold no rows.
    pub fn find(
        &mut self,
        rays: &[[f32; 3]],
        weights: &[f32],
        pixel_rad: &[f32],
        rows: &mut Vec<Row>,
    ) -> Result<Option<Vector3<f64>>, DetectError> {
        if rays.len() != weights.len() || rays.len() != pixel_rad.len() {
            return Err(DetectError::Buffer(format!(
                "strips: {} rays, {} weights, {} pixel sizes",
                rays.len(),
                weights.len(),
                pixel_rad.len()
            )));
        }
        rows.clear();
        self.last = StripsResult::default();
        if !self.set_scale(rays, pixel_rad) {
            return Ok(None);
        }
        self.collect_points(rays, weights);
        self.read_peaks(None);
        self.last.peaks = self.peaks.len();
        let Some((av, pv, agreement)) = self.search() else {
            return Ok(None);
        };
        if self.opts.straighten {
            self.read_peaks(Some((av, pv)));
        }
        self.last.vanishing_px = Some([av, pv]);
        self.last.agreement = agreement;
        self.comb_rows(av, pv, rows);
        Ok(Some(self.to_ray(av, pv)))
    }

    /// The virtual image's pixels per unit of the ideal image plane (its focal length): the
    /// median over the points of cos^1.5 θ / (angular size of the point's pixel), θ the
    /// point's angle from the optical axis — exact for a pinhole camera, whose pixel at θ
    /// spans a solid angle of cos³θ / f². False when there are no points.
    fn set_scale(&mut self, rays: &[[f32; 3]], pixel_rad: &[f32]) -> bool {
        let stride = pixel_rad.len().div_ceil(512).max(1);
        self.scratch.clear();
        self.scratch.extend(
            rays.iter()
                .zip(pixel_rad)
                .step_by(stride)
                .filter(|(r, a)| **a > 0.0 && a.is_finite() && -r[2] > 0.05)
                .map(|(r, &a)| (-r[2] as f64).powf(1.5) / a as f64),
        );
        if self.scratch.is_empty() {
            return false;
        }
        let mid = self.scratch.len() / 2;
        let (_, m, _) = self.scratch.select_nth_unstable_by(mid, f64::total_cmp);
        self.scale = *m;
        self.scale.is_finite()
    }

    /// The points in front of the camera in the virtual image (along, below, weight).
    fn collect_points(&mut self, rays: &[[f32; 3]], weights: &[f32]) {
        self.pts.clear();
        for (r, &w) in rays.iter().zip(weights) {
            if w.is_nan() || w <= 0.0 {
                continue;
            }
            let v = Vector3::new(r[0] as f64, r[1] as f64, r[2] as f64);
            if let Some([a, p]) = self.to_virtual(&v) {
                self.pts.push([a, p, w as f64]);
            }
        }
    }

    /// Each strip's profile across the image, smoothed, and its peaks into `self.peaks`;
    /// with `about` (a vanishing point, along and below), each point first moved along its
    /// line through that point to its strip's centre line.
    fn read_peaks(&mut self, about: Option<(f64, f64)>) {
        self.peaks.clear();
        let (mut p0, mut p1) = (f64::MAX, f64::MIN);
        for &[_, p, _] in &self.pts {
            p0 = p0.min(p);
            p1 = p1.max(p);
        }
        let sh = self.opts.strip_px;
        let centre = |s: usize| p0 + (s as f64 + 0.5) * sh;
        // the point's strip and its position along it, straightened about `about` (a point
        // less than a strip below that point stays: its line is too steep to follow)
        let place = |a: f64, p: f64| {
            let s = ((p - p0) / sh) as usize;
            let Some((av, pv)) = about else {
                return (s, a);
            };
            let (d, dc) = (p - pv, centre(s) - pv);
            if d >= sh && dc >= 0.5 * sh {
                (s, av + (a - av) * dc / d)
            } else {
                (s, a)
            }
        };
        let (mut a0, mut a1) = (f64::MAX, f64::MIN);
        for &[a, p, _] in &self.pts {
            let (_, a) = place(a, p);
            a0 = a0.min(a);
            a1 = a1.max(a);
        }
        if self.pts.len() < 2 || a1 <= a0 || p1 <= p0 {
            return;
        }
        let strips = (((p1 - p0) / sh).floor() as usize + 1).min(MAX_STRIPS);
        let bins = ((a1 - a0).floor() as usize + 1).min(MAX_BINS);
        self.hist.clear();
        self.hist.resize(strips * bins, 0.0);
        for &[a, p, w] in &self.pts {
            let (s, a) = place(a, p);
            let b = (a - a0) as usize;
            if s < strips && b < bins {
                self.hist[s * bins + b] += w;
            }
        }
        self.make_kernel();
        self.spans.clear();
        for s in 0..strips {
            let row = &self.hist[s * bins..(s + 1) * bins];
            let lo = row.iter().position(|&x| x > 0.0);
            let hi = row.iter().rposition(|&x| x > 0.0);
            if let (Some(lo), Some(hi)) = (lo, hi) {
                self.spans
                    .push([centre(s), a0 + lo as f64, a0 + hi as f64 + 1.0]);
            }
            self.strip_peaks(s, bins, a0, centre(s));
        }
    }

    fn make_kernel(&mut self) {
        let sigma = self.opts.smooth_px;
        let half = (3.0 * sigma).ceil() as usize;
        self.kernel.clear();
        for i in 0..=2 * half {
            let x = i as f64 - half as f64;
            self.kernel.push((-0.5 * x * x / (sigma * sigma)).exp());
        }
        let sum: f64 = self.kernel.iter().sum();
        for k in &mut self.kernel {
            *k /= sum;
        }
    }

    /// The peaks of strip `s` (its centre `p` below the horizon).
    fn strip_peaks(&mut self, s: usize, bins: usize, a0: f64, p: f64) {
        let row = &self.hist[s * bins..(s + 1) * bins];
        if row.iter().all(|&x| x == 0.0) {
            return;
        }
        smooth_profile(row, &self.kernel, &mut self.smooth);
        self.scratch.clear();
        self.scratch.extend_from_slice(&self.smooth);
        let mid = self.scratch.len() / 2;
        let median = *self.scratch.select_nth_unstable_by(mid, f64::total_cmp).1;
        let win = self.opts.prominence_px.round() as usize;
        let sm = &self.smooth;
        let is_max = |i: usize| sm[i] > sm[i - 1] && sm[i] >= sm[i + 1];
        let height = |i: usize| {
            if win == 0 {
                sm[i] - median
            } else {
                prominence(sm, i, win)
            }
        };
        let top = if win == 0 {
            sm.iter().fold(0.0f64, |m, &x| m.max(x - median))
        } else {
            (1..bins.saturating_sub(1))
                .filter(|&i| is_max(i))
                .map(height)
                .fold(0.0f64, f64::max)
        };
        if top <= 0.0 {
            return;
        }
        let floor = self.opts.peak_fraction * top;
        for i in 1..bins.saturating_sub(1) {
            let (l, c, r) = (sm[i - 1], sm[i], sm[i + 1]);
            let h = if is_max(i) { height(i) } else { 0.0 };
            if h > 0.0 && h >= floor {
                // the parabola through the three bins for the peak's sub-pixel position
                let den = l - 2.0 * c + r;
                let off = if den < 0.0 {
                    (0.5 * (l - r) / den).clamp(-0.5, 0.5)
                } else {
                    0.0
                };
                self.peaks.push(Peak {
                    a: a0 + i as f64 + 0.5 + off,
                    p,
                    w: h,
                    strip: s as u32,
                });
            }
        }
    }

    /// The candidate vanishing points' window in the virtual image: the box around the
    /// directions within the heading and tilt limits.
    fn window(&self) -> Option<[f64; 4]> {
        let h = self.opts.max_heading_deg.to_radians();
        let t = self.max_tilt;
        let (mut a0, mut a1, mut p0, mut p1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for (az, el) in [
            (-h, -t),
            (-h, 0.0),
            (-h, t),
            (0.0, -t),
            (0.0, t),
            (h, -t),
            (h, 0.0),
            (h, t),
        ] {
            let [a, p] = self.to_virtual(&self.axes.direction(az, el))?;
            a0 = a0.min(a);
            a1 = a1.max(a);
            p0 = p0.min(p);
            p1 = p1.max(p);
        }
        Some([a0, a1, p0, p1])
    }

    /// The vanishing point whose pencil lines the strips' peaks up best: a coarse grid over
    /// the window (or the prior's box within it, [`Self::set_window`]), then halving steps
    /// from its `search_starts` best points, and of the summits they reach the highest or a
    /// nearby one with a stronger comb ([`pick_summit`]). (along, below, agreement). With a
    /// prior, `None` also when the box's best lies on an edge the box adds to the window:
    /// the agreement still rises beyond it, so the rows' vanishing point is outside the
    /// prior's window.
    fn search(&mut self) -> Option<(f64, f64, f64)> {
        if self.peaks.len() < 4 {
            return None;
        }
        let full = self.window()?;
        let (bx, step, regions) = match self.prior_box() {
            None => (full, self.opts.search_step_px, self.opts.search_regions),
            Some(b) => {
                let bx = [
                    b[0].max(full[0]),
                    b[1].min(full[1]),
                    b[2].max(full[2]),
                    b[3].min(full[3]),
                ];
                if bx[0] > bx[1] || bx[2] > bx[3] {
                    return None;
                }
                // a small box: its whole grid, fine enough to have an inside
                let side = (bx[1] - bx[0]).min(bx[3] - bx[2]);
                (bx, (side / 8.0).clamp(1.0, self.opts.search_step_px), 0)
            }
        };
        let [a0, a1, p0, p1] = bx;
        let na = ((a1 - a0) / step).ceil() as usize + 1;
        let np = ((p1 - p0) / step).ceil() as usize + 1;
        if na * np > 1_000_000 {
            return None;
        }
        self.fill_grid(a0, p0, na, np, step, regions);
        // the grid's best local maxima, each refined by halving steps
        self.grid_maxima(na, np, 1);
        self.starts.truncate(self.opts.search_starts);
        if let (Some(&(_, i, j)), true) = (self.starts.first(), bx != full) {
            let (i, j) = (i as usize, j as usize);
            let edge = (i == 0 && bx[0] > full[0])
                || (i + 1 == na && bx[1] < full[1])
                || (j == 0 && bx[2] > full[2])
                || (j + 1 == np && bx[3] < full[3]);
            if edge {
                return None;
            }
        }
        // each start climbed, in place: (agreement, along, below)
        for k in 0..self.starts.len() {
            let (e, i, j) = self.starts[k];
            self.starts[k] = self.refine((e, a0 + i * step, p0 + j * step), step);
        }
        let summits = std::mem::take(&mut self.starts);
        let (power, reach) = (self.opts.search_comb_power, self.opts.search_comb_reach_px);
        let best = pick_summit(&summits, power, reach, |a, p| {
            self.comb_at(a, p).map_or(0.0, |c| c.0.max(0.0))
        });
        self.starts = summits;
        best.filter(|b| b.0 > 0.0).map(|b| (b.1, b.2, b.0))
    }

    /// The peaks' comb seen from (a, p) ([`Self::comb`], with `self.columns` filled for
    /// it, the kernel of the comb's rows); `None` when no peak lies below the point.
    fn comb_at(&mut self, a: f64, p: f64) -> Option<(f64, f64, f64)> {
        self.see(a, p, self.opts.peak_sigma_px);
        (self.columns.len() > 0).then(|| self.comb())
    }

    /// A grid point (agreement, along, below) climbed by halving steps from `step` / 2
    /// down to 1 px.
    fn refine(&mut self, mut here: (f64, f64, f64), step: f64) -> (f64, f64, f64) {
        let mut st = 0.5 * step;
        while st >= 1.0 {
            let (_, ca, cp) = here;
            let sig = self.sigma_at(st);
            if self.opts.search_blur > 0.0 {
                here.0 = self.agreement(ca, cp, sig);
            }
            for (da, dp) in NEIGHBOURS {
                let (a, p) = (ca + da * st, cp + dp * st);
                let e = self.agreement(a, p, sig);
                if e > here.0 {
                    here = (e, a, p);
                }
            }
            st *= 0.5;
        }
        here
    }

    /// The prior's window (set by [`Self::set_window`]) as a box in the virtual image
    /// (along from, to, below from, to): around the projections of the directions `w` from
    /// its vanishing point. `None` without a prior or when the window leaves the image
    /// plane.
    fn prior_box(&self) -> Option<[f64; 4]> {
        let (vp, w) = self.prior?;
        let vp = if vp.z < 0.0 { vp } else { -vp };
        let e1 = crate::sphere::any_perpendicular(&vp);
        let e2 = vp.cross(&e1);
        let (sw, cw) = w.sin_cos();
        let [mut a0, mut p0] = self.to_virtual(&vp)?;
        let (mut a1, mut p1) = (a0, p0);
        for (x, y) in NEIGHBOURS {
            let n = (x * x + y * y).sqrt();
            let d = vp * cw + (e1 * x + e2 * y) * (sw / n);
            let [a, p] = self.to_virtual(&d)?;
            a0 = a0.min(a);
            a1 = a1.max(a);
            p0 = p0.min(p);
            p1 = p1.max(p);
        }
        Some([a0, a1, p0, p1])
    }

    /// The agreement at the summit nearest a vanishing direction `dir` (sign free), on the
    /// last image's peaks as the search read them: climbed from its point in the virtual
    /// image by the search's own halving steps, again while the climb moves (at most
    /// `CLIMB_ROUNDS` rounds). Asks, after [`Self::find`], whether a vanishing point known
    /// from elsewhere (the labels') would have beaten the search's answer
    /// ([`StripsResult::agreement`]): higher and elsewhere, the search missed it; lower, or
    /// the search's own summit, the measure prefers the search's. Returns the agreement and
    /// the summit's distance from the search's answer (virtual image pixels; infinite
    /// without one). `None` before the first image, when the last image gave too few peaks
    /// (its points may then not have been read), or when the direction has no point in the
    /// virtual image. Leaves [`Self::last`] as it was.
    pub fn agreement_near(&mut self, dir: &Vector3<f64>) -> Option<(f64, f64)> {
        if self.last.peaks < 4 {
            return None;
        }
        let d = if dir.z < 0.0 { *dir } else { -*dir };
        let [mut a, mut p] = self.to_virtual(&d)?;
        let last = self.last;
        // the same points as the search's: the same peaks, at least four of them
        self.read_peaks(None);
        let sig = self.sigma_at(1.0);
        let mut here = (self.agreement(a, p, sig), a, p);
        for _ in 0..CLIMB_ROUNDS {
            here = self.refine(here, self.opts.search_step_px);
            if (here.1, here.2) == (a, p) {
                break;
            }
            (a, p) = (here.1, here.2);
        }
        self.last = last;
        let away = last
            .vanishing_px
            .map_or(f64::INFINITY, |[va, vp]| (here.1 - va).hypot(here.2 - vp));
        Some((here.0, away))
    }

    /// Narrows the next searches to a prior's window (`vp` the expected vanishing point,
    /// sign free; `w` the window's half-angle, radians), or widens them again (`None`).
    pub fn set_window(&mut self, window: Option<(&Vector3<f64>, f64)>) {
        self.prior = window.map(|(vp, w)| (vp.normalize(), w));
    }

    /// The agreement on the grid of `na` × `np` candidates `step` apart from (a0, p0) into
    /// `self.grid`. With `regions` > 0 only where it can hold the grid's best: every other
    /// candidate first (a grid twice as coarse), then the full grid within one coarse step
    /// of that coarse grid's `regions` best local maxima; the candidates not evaluated are
    /// NaN, and so neither a maximum nor higher than one.
    fn fill_grid(&mut self, a0: f64, p0: f64, na: usize, np: usize, step: f64, regions: usize) {
        let sig = self.sigma_at(step);
        self.grid.clear();
        self.grid.resize(na * np, f64::NAN);
        let stride = if regions == 0 { 1 } else { 2 };
        // the coarse grid with only the strongest peaks: swapped in, and out again below
        let share = self.opts.search_coarse_share;
        let coarse = regions > 0 && share < 1.0 && self.keep_strongest(share);
        if coarse {
            std::mem::swap(&mut self.peaks, &mut self.coarse_peaks);
        }
        for j in (0..np).step_by(stride) {
            for i in (0..na).step_by(stride) {
                self.grid[j * na + i] =
                    self.agreement(a0 + i as f64 * step, p0 + j as f64 * step, sig);
            }
        }
        if regions == 0 {
            return;
        }
        self.grid_maxima(na, np, 2);
        self.starts.truncate(regions);
        if coarse {
            // the regions are evaluated with all peaks, and only they are candidates
            std::mem::swap(&mut self.peaks, &mut self.coarse_peaks);
            self.grid.fill(f64::NAN);
        }
        for k in 0..self.starts.len() {
            let (_, ci, cj) = self.starts[k];
            let (ci, cj) = (ci as usize, cj as usize);
            for j in cj.saturating_sub(2)..(cj + 3).min(np) {
                for i in ci.saturating_sub(2)..(ci + 3).min(na) {
                    if self.grid[j * na + i].is_nan() {
                        self.grid[j * na + i] =
                            self.agreement(a0 + i as f64 * step, p0 + j as f64 * step, sig);
                    }
                }
            }
        }
    }

    /// Fills `self.coarse_peaks` with the `share` of the peaks that weigh most (all those as
    /// heavy as the lightest of them), in the peaks' order; false when that is all of them.
    fn keep_strongest(&mut self, share: f64) -> bool {
        let n = self.peaks.len();
        let keep = ((n as f64 * share).ceil() as usize).clamp(1, n.max(1));
        if keep >= n {
            return false;
        }
        self.scratch.clear();
        self.scratch.extend(self.peaks.iter().map(|k| k.w));
        let (_, floor, _) = self
            .scratch
            .select_nth_unstable_by(keep - 1, |a, b| b.total_cmp(a));
        let floor = *floor;
        self.coarse_peaks.clear();
        let strong = self.peaks.iter().filter(|k| k.w >= floor);
        self.coarse_peaks.extend(strong);
        self.coarse_peaks.len() < n
    }

    /// The local maxima (agreement, column, row) of the `na` × `np` grid read every
    /// `stride`-th point, into `self.starts`, best first.
    fn grid_maxima(&mut self, na: usize, np: usize, stride: usize) {
        self.starts.clear();
        for j in (0..np).step_by(stride) {
            for i in (0..na).step_by(stride) {
                let e = self.grid[j * na + i];
                if e > 0.0 && !self.higher_near(i, j, na, np, stride as i64, e) {
                    self.starts.push((e, i as f64, j as f64));
                }
            }
        }
        self.starts.sort_unstable_by(|x, y| y.0.total_cmp(&x.0));
    }

    /// Whether a grid neighbour `reach` cells from (i, j) (one of the eight directions) is
    /// higher than `e`.
    fn higher_near(&self, i: usize, j: usize, na: usize, np: usize, reach: i64, e: f64) -> bool {
        NEIGHBOURS.iter().any(|&(di, dj)| {
            let (x, y) = (i as i64 + di as i64 * reach, j as i64 + dj as i64 * reach);
            x >= 0
                && y >= 0
                && (x as usize) < na
                && (y as usize) < np
                && self.grid[y as usize * na + x as usize] > e
        })
    }

    /// The peaks' position uncertainty for a search at grid step `step`: `peak_sigma_px`
    /// widened by `search_blur` × the step, so that a coarse grid sees the broad basin
    /// around the best point rather than missing its narrow summit.
    fn sigma_at(&self, step: f64) -> f64 {
        let o = &self.opts;
        o.peak_sigma_px.hypot(o.search_blur * step)
    }

    /// Fills `self.columns` with the peaks below the candidate (a, p), sorted by u; returns
    /// the share of the peaks' count that is there.
    fn see(&mut self, a: f64, p: f64, sig: f64) -> f64 {
        let min_d = self.opts.min_depth_px;
        // the peaks are in the strips' order, deepest last: those below are the last ones
        let first = self.peaks.partition_point(|k| k.p - p <= min_d);
        let peaks = &self.peaks;
        let key = |k: usize| sort_key((peaks[k].a - a) / (peaks[k].p - p), k);
        self.keys.clear();
        self.keys.extend((first..peaks.len()).map(key));
        // sorting 8-byte keys is faster than sorting the peaks themselves
        self.keys.sort_unstable();
        self.columns.clear();
        for &k in &self.keys {
            let k = &peaks[(k & 0xffff_ffff) as usize];
            let d = k.p - p;
            self.columns.push((k.a - a) / d, sig / d, k.w, k.strip);
        }
        self.columns.len() as f64 / self.peaks.len().max(1) as f64
    }

    /// How well the peaks agree in u seen from (a, p): Σ over pairs of peaks from different
    /// strips of wᵢwⱼ·K(Δu / √(sᵢ² + sⱼ²)), over (Σw)², times the share of the peaks below
    /// the point. K is the triweight kernel with a standard deviation of 1.
    fn agreement(&mut self, a: f64, p: f64, sig: f64) -> f64 {
        self.last.evaluated += 1;
        let share = self.see(a, p, sig);
        if self.columns.len() < 4 {
            return 0.0;
        }
        let (num, total) = self.columns.pair_sum();
        if total <= 0.0 {
            return 0.0;
        }
        num / (total * total) * share
    }

    /// The strongest comb of the peaks' u in `self.columns` (filled by `see`): (amplitude,
    /// period, phase), the amplitude their Fourier component's over their total weight.
    /// Periods from `comb_min_period` to `comb_max_period`.
    fn comb(&mut self) -> (f64, f64, f64) {
        let o = &self.opts;
        let c = &self.columns;
        let total: f64 = c.w.iter().sum();
        let ratio = (o.comb_max_period / o.comb_min_period).powf(1.0 / (o.comb_periods - 1) as f64);
        let mut period = o.comb_min_period;
        let mut best = (0.0, period, 0.0);
        if total <= 0.0 {
            return best;
        }
        for _ in 0..o.comb_periods {
            let f = std::f64::consts::TAU / period;
            let (c, s) = fourier(&c.u, &c.w, f);
            let amp = c.hypot(s) / total;
            if amp > best.0 {
                best = (amp, period, s.atan2(c) / f);
            }
            period *= ratio;
        }
        best
    }

    /// How many strips a tooth at `u` of the pencil through (a, p) needs peaks in to be a row:
    /// `min_strips_share` of the strips its line crosses inside their points (below
    /// `min_depth_px`), rounded up, within `min_strips_floor..=min_strips`.
    fn need(&self, a: f64, p: f64, u: f64) -> usize {
        let o = &self.opts;
        let crossed = self
            .spans
            .iter()
            .filter(|&&[sp, lo, hi]| {
                let d = sp - p;
                let x = a + u * d;
                d > o.min_depth_px && (lo..=hi).contains(&x)
            })
            .count();
        let share = (o.min_strips_share * crossed as f64).ceil() as usize;
        share.clamp(o.min_strips_floor, o.min_strips)
    }

    /// The comb of the peaks' u seen from (a, p) and its teeth as rows into `rows`.
    fn comb_rows(&mut self, a: f64, p: f64, rows: &mut Vec<Row>) {
        let Some((amp, period, phase)) = self.comb_at(a, p) else {
            return;
        };
        let o = self.opts;
        self.last.period = period;
        self.last.comb_strength = amp;
        let c = &self.columns;
        let (u0, u1) = (c.u[0], c.u[c.len() - 1]);
        let k0 = ((u0 - phase) / period).floor() as i64;
        let k1 = ((u1 - phase) / period).ceil() as i64;
        if k1 - k0 > 4096 {
            return;
        }
        let vp = self.to_ray(a, p);
        self.teeth.clear();
        for k in k0..=k1 {
            let m = phase + k as f64 * period;
            let band = o.comb_band * period;
            let on = c.within(m, band);
            let seen = distinct_strips(&c.strip[on.clone()]);
            if seen >= o.min_strips || (seen >= o.min_strips_floor && seen >= self.need(a, p, m)) {
                let w: f64 = c.w[on.clone()].iter().sum();
                let mut at = m;
                for _ in 0..o.recentre_rounds {
                    let on = c.within(at, band);
                    let sw: f64 = c.w[on.clone()].iter().sum();
                    if sw > 0.0 {
                        let wu = c.w[on.clone()].iter().zip(&c.u[on]);
                        at = wu.map(|(w, u)| w * u).sum::<f64>() / sw;
                    }
                }
                self.teeth.push([at, w, on.len() as f64]);
            }
        }
        // the best-supported teeth, at most max_rows, reported in order across the image
        if self.teeth.len() > o.max_rows {
            self.teeth.sort_unstable_by(|x, y| y[1].total_cmp(&x[1]));
            self.teeth.truncate(o.max_rows);
        }
        let depth = 100.0_f64.max(2.0 * o.min_depth_px);
        for &[m, _, support] in &self.teeth {
            let pencil = vp.cross(&self.to_ray(a + m * depth, p + depth));
            let n = match self.own_line(a, p, m, o.comb_band * period) {
                Some(n) if n.dot(&pencil) < 0.0 => -n,
                Some(n) => n,
                None => pencil,
            };
            let norm = n.norm();
            if norm > 0.0 {
                rows.push(Row {
                    normal: n / norm,
                    method: Method::Strips,
                    support: support as u32,
                    width_rad: 0.0,
                });
            }
        }
    }

    /// The great circle (unnormalised normal) of the row on the tooth at `u` of the pencil
    /// through (a, p), `band` the tooth's half-width in u, fitted its own line
    /// (`own_lines`): [`Self::line_fit`] over the peaks whose u lies within `band` of the
    /// tooth, then again without those farther than `own_line_reject` × `peak_sigma_px`
    /// from that line. `None` when the option is off or too few strips hold peaks: the
    /// row is then its tooth's line.
    fn own_line(&self, a: f64, p: f64, u: f64, band: f64) -> Option<Vector3<f64>> {
        let o = &self.opts;
        if !o.own_lines {
            return None;
        }
        let on = |k: &Peak| {
            let d = k.p - p;
            d > o.min_depth_px && ((k.a - a) / d - u).abs() <= band
        };
        let (mut c0, mut c1) = self.line_fit(a, p, on)?;
        if o.own_line_reject > 0.0 {
            let lim = o.own_line_reject * o.peak_sigma_px;
            let (b0, b1) = (c0, c1);
            let near = |k: &Peak| on(k) && (k.a - (b0 + b1 * (k.p - p))).abs() <= lim;
            (c0, c1) = self.line_fit(a, p, near)?;
        }
        let (d1, d2) = (o.min_depth_px.max(1.0), 100.0_f64.max(4.0 * o.min_depth_px));
        let n = self
            .to_ray(c0 + c1 * d1, p + d1)
            .cross(&self.to_ray(c0 + c1 * d2, p + d2));
        (n.norm() > 0.0).then_some(n)
    }

    /// The line a = c₀ + c₁·d (d = depth below p) fitted by least squares to the peaks `on`
    /// (weight 1 each, as every scan line of a labelled row counts once) and to the point
    /// (a, p) itself (d = 0, weight `own_line_anchor` × their count): (c₀, c₁). `None` when
    /// they lie in fewer than `min_strips_floor` strips (at least 3).
    fn line_fit(&self, a: f64, p: f64, on: impl Fn(&Peak) -> bool) -> Option<(f64, f64)> {
        let o = &self.opts;
        let (mut n, mut sd, mut sa, mut strips) = (0.0, 0.0, 0.0, 0usize);
        let mut last = u32::MAX;
        for k in self.peaks.iter().filter(|k| on(k)) {
            n += 1.0;
            sd += k.p - p;
            sa += k.a;
            // the peaks are in the strips' order
            if k.strip != last {
                (last, strips) = (k.strip, strips + 1);
            }
        }
        if strips < o.min_strips_floor.max(3) {
            return None;
        }
        let wv = o.own_line_anchor * n;
        let (dm, am) = (sd / (n + wv), (sa + wv * a) / (n + wv));
        let (mut sdd, mut sda) = (wv * dm * dm, -wv * dm * (a - am));
        for k in self.peaks.iter().filter(|k| on(k)) {
            let dd = k.p - p - dm;
            sdd += dd * dd;
            sda += dd * (k.a - am);
        }
        if sdd <= 0.0 {
            return None;
        }
        let c1 = sda / sdd;
        Some((am - c1 * dm, c1))
    }
}

/// `row` convolved with the odd-length `kernel` into `out` (cleared first), the kernel cut
/// at the row's ends: out[i] = Σ over j within the kernel's reach of i and inside the row of
/// row[j]·kernel[j + half − i], summed in increasing j. Where the kernel lies wholly inside
/// the row, eight outputs at a time (each summed in the same order, so the same to the bit).
fn smooth_profile(row: &[f64], kernel: &[f64], out: &mut Vec<f64>) {
    const LANES: usize = 8;
    let (bins, half) = (row.len(), kernel.len() / 2);
    let cut = |i: usize| {
        let (lo, hi) = (
            i.saturating_sub(half),
            (i + half).min(bins.saturating_sub(1)),
        );
        let mut acc = 0.0;
        for (j, x) in row.iter().enumerate().take(hi + 1).skip(lo) {
            acc += x * kernel[j + half - i];
        }
        acc
    };
    out.clear();
    // outputs half..inner_end in blocks of eight have the whole kernel inside the row
    let inner = bins.saturating_sub(2 * half);
    let inner_end = half + inner / LANES * LANES;
    out.extend((0..half.min(bins)).map(cut));
    for i0 in (half..inner_end).step_by(LANES) {
        let mut acc = [0.0f64; LANES];
        for (t, &k) in kernel.iter().enumerate() {
            let x = &row[i0 - half + t..i0 - half + t + LANES];
            for l in 0..LANES {
                acc[l] += x[l] * k;
            }
        }
        out.extend_from_slice(&acc);
    }
    out.extend((out.len()..bins).map(cut));
}

/// Σ wᵢ·cos(f·uᵢ) and Σ wᵢ·sin(f·uᵢ): the Fourier component at angular frequency `f` of
/// peaks at `u` weighing `w` (the same length). Summed in four lanes, with [`sin_cos`] where
/// every |f·u| ≤ 10⁶ (so that the loop vectorises), the C library's beyond.
fn fourier(u: &[f64], w: &[f64], f: f64) -> (f64, f64) {
    let reach = u.iter().fold(0.0f64, |m, &x| m.max(x.abs())) * f.abs();
    if reach.is_nan() || reach > 1e6 {
        return u.iter().zip(w).fold((0.0, 0.0), |(c, s), (&x, &w)| {
            let (sn, cs) = (f * x).sin_cos();
            (c + w * cs, s + w * sn)
        });
    }
    let (mut c, mut s) = ([0.0f64; 4], [0.0f64; 4]);
    for (u, w) in u.chunks_exact(4).zip(w.chunks_exact(4)) {
        for l in 0..4 {
            let (sn, cs) = sin_cos(f * u[l]);
            c[l] += w[l] * cs;
            s[l] += w[l] * sn;
        }
    }
    let full = u.len() / 4 * 4;
    for (&x, &w) in u[full..].iter().zip(&w[full..]) {
        let (sn, cs) = sin_cos(f * x);
        c[0] += w * cs;
        s[0] += w * sn;
    }
    ((c[0] + c[1]) + (c[2] + c[3]), (s[0] + s[1]) + (s[2] + s[3]))
}

/// sin and cos of `x` for |x| ≤ 10⁶, within a few units in the last place of the C
/// library's: range reduction by a three-part π/2, then fdlibm's kernel polynomials on
/// |r| ≤ π/4. Branch-free, so that loops over it vectorise.
#[inline(always)]
fn sin_cos(x: f64) -> (f64, f64) {
    // Rounded to the nearest integer by the addition's own rounding: q = x / (π/2).
    const ROUND: f64 = 6_755_399_441_055_744.0; // 1.5 · 2^52
    let t = x * std::f64::consts::FRAC_2_PI + ROUND;
    // The quadrant's low bits (32-bit lanes vectorise where 64-bit compares do not).
    let quadrant = t.to_bits() as u32;
    let q = t - ROUND;
    // π/2 in three parts, the first two of 33 bits, so that q times them is exact.
    const P1: f64 = 1.5707963267341256;
    const P2: f64 = 6.077100506303966e-11;
    const P3: f64 = 2.0222662487959506e-21;
    let r = ((x - q * P1) - q * P2) - q * P3;
    let z = r * r;
    let sin = r + r
        * z
        * (-0.16666666666666632
            + z * (0.00833333333332249
                + z * (-0.0001984126982985795
                    + z * (2.7557313707070068e-6
                        + z * (-2.5050760253406863e-8 + z * 1.58969099521155e-10)))));
    let cos = 1.0 - 0.5 * z
        + z * z
            * (0.0416666666666666
                + z * (-0.001388888888887411
                    + z * (2.480158728947673e-5
                        + z * (-2.7557314351390663e-7
                            + z * (2.087572321298175e-9 + z * -1.1359647557788195e-11)))));
    // Swapped in odd quadrants, negated in the second half-turn (sin) or the middle two
    // quadrants (cos); as products with 0 and ±1, which are exact.
    let odd = (quadrant & 1) as f64;
    let s = odd * cos + (1.0 - odd) * sin;
    let c = odd * sin + (1.0 - odd) * cos;
    let s_sign = 1.0 - 2.0 * ((quadrant >> 1) & 1) as f64;
    let c_sign = 1.0 - 2.0 * ((quadrant.wrapping_add(1) >> 1) & 1) as f64;
    (s * s_sign, c * c_sign)
}

/// Whether a camera mounted as `m` looks forward enough for the strips method: the
/// robot's forward axis within about 78° of the optical axis (the camera looks along −z).
pub fn looks_forward(m: &Mounting) -> bool {
    -RobotAxes::new(m).fwd.z >= 0.2
}

/// How far `sm[i]` stands above the higher of the lowest values within `win` bins on its
/// left and on its right (the profile's ends bound a side with fewer bins).
fn prominence(sm: &[f64], i: usize, win: usize) -> f64 {
    let low = |xs: &[f64]| xs.iter().fold(f64::INFINITY, |m, &x| m.min(x));
    let left = low(&sm[i.saturating_sub(win)..i]);
    let right = low(&sm[(i + 1).min(sm.len())..(i + 1 + win).min(sm.len())]);
    let base = left.max(right);
    if base.is_finite() {
        sm[i] - base
    } else {
        0.0
    }
}

/// A key that sorts as `u` (rounded to f32, which orders all but near-equal values the
/// same) with the index `i` (below 2³²) in its low half.
fn sort_key(u: f64, i: usize) -> u64 {
    let b = (u as f32).to_bits();
    let ordered = if b >> 31 == 1 { !b } else { b | 0x8000_0000 };
    ((ordered as u64) << 32) | (i as u64 & 0xffff_ffff)
}

/// The search's answer among the climbed `summits` (agreement, along, below): the highest,
/// or one within `reach` of it whose agreement times `strength(along, below)` (0..1) to the
/// `power` is larger. With power 0, or one summit, the highest (the first of equals);
/// `strength` is read only for summits that could win. `None` without summits.
fn pick_summit(
    summits: &[(f64, f64, f64)],
    power: f64,
    reach: f64,
    mut strength: impl FnMut(f64, f64) -> f64,
) -> Option<(f64, f64, f64)> {
    let top = summits
        .iter()
        .copied()
        .reduce(|b, x| if x.0 > b.0 { x } else { b })?;
    if power == 0.0 || summits.len() < 2 {
        return Some(top);
    }
    let mut best = (top, top.0 * strength(top.1, top.2).powf(power));
    for &x in summits {
        // a strength is at most 1: a summit no higher than the best score cannot win
        let near = (x.1 - top.1).hypot(x.2 - top.2) <= reach;
        if x == top || !near || x.0 <= best.1 {
            continue;
        }
        let score = x.0 * strength(x.1, x.2).powf(power);
        if score > best.1 {
            best = (x, score);
        }
    }
    Some(best.0)
}

/// How many different strips the peaks come from.
fn distinct_strips(on: &[u32]) -> usize {
    let mut n = 0;
    for (i, x) in on.iter().enumerate() {
        if on[..i].iter().all(|y| y != x) {
            n += 1;
        }
    }
    n
}

/// A ray's point in the camera's perspective image (row, column), `scale` pixels per unit
/// of the ideal image plane; `None` behind the camera (it looks along −z).
fn project(r: &Vector3<f64>, scale: f64) -> Option<[f64; 2]> {
    let z = -r.z;
    if z <= 1e-6 {
        return None;
    }
    Some([r.x / z * scale, r.y / z * scale])
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    /// A flat field seen by a pinhole of focal length `f` (pixels) on a `size`² image,
    /// mounted as `m`, the rows `spacing` apart turned by `heading` (radians): plant points
    /// along each row (a deterministic scatter across its width), as rays, weights and pixel
    /// sizes; and the rows' true plane normals in the camera frame.
    struct Field {
        rays: Vec<[f32; 3]>,
        weights: Vec<f32>,
        pixel_rad: Vec<f32>,
        normals: Vec<Vector3<f64>>,
    }

    fn field(f: f64, size: f64, m: &Mounting, spacing: f64, offset: f64, heading: f64) -> Field {
        let ys: Vec<f64> = (-8..=8).map(|k| offset + k as f64 * spacing).collect();
        field_at(f, size, m, &ys, heading)
    }

    /// As [`field`], the rows at lateral positions `ys` (metres).
    fn field_at(f: f64, size: f64, m: &Mounting, ys: &[f64], heading: f64) -> Field {
        let cam_from_robot = m.robot_from_camera().inverse();
        let yaw = Rotation3::from_axis_angle(&Vector3::z_axis(), heading);
        let h = m.height_m;
        let mut fld = Field {
            rays: vec![],
            weights: vec![],
            pixel_rad: vec![],
            normals: vec![],
        };
        let mut rnd = uniform(12345);
        for &y in ys {
            let a = cam_from_robot * (yaw * Vector3::new(2.0, y, -h));
            let b = cam_from_robot * (yaw * Vector3::new(12.0, y, -h));
            fld.normals.push(a.cross(&b).normalize());
            for _ in 0..3000 {
                // forward distances spread like the image's rows (denser far away)
                let x = 1.0 / (1.0 - rnd() * (1.0 - 1.0 / 40.0));
                let p = cam_from_robot * (yaw * Vector3::new(x, y + (rnd() - 0.5) * 0.08, -h));
                fld.see(&p, f, size);
            }
        }
        fld
    }

    impl Field {
        /// Adds the point `p` (camera frame) when a pinhole of focal length `f` on a
        /// `size`² image sees it.
        fn see(&mut self, p: &Vector3<f64>, f: f64, size: f64) {
            let r = p.normalize();
            if -r.z <= 0.05 {
                return;
            }
            let (row, col) = (r.x / -r.z * f, r.y / -r.z * f);
            if row.abs() > size / 2.0 || col.abs() > size / 2.0 {
                return;
            }
            self.rays.push([r.x as f32, r.y as f32, r.z as f32]);
            self.weights.push(1.0);
            self.pixel_rad.push(((-r.z).powf(1.5) / f) as f32);
        }
    }

    /// A deterministic uniform generator on [0, 1) from `seed`.
    fn uniform(mut seed: u64) -> impl FnMut() -> f64 {
        move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// Two climbs to one summit end within this many pixels of each other.
    const SAME_SUMMIT_TEST_PX: f64 = 3.0;

    fn forward_camera() -> Mounting {
        Mounting {
            pitch_deg: -47.0,
            ..Mounting::default()
        }
    }

    /// The angle (radians) from `n` to the nearest of `truth`'s normals.
    fn nearest(n: &Vector3<f64>, truth: &[Vector3<f64>]) -> f64 {
        truth
            .iter()
            .map(|t| n.dot(t).abs().min(1.0).acos())
            .fold(f64::MAX, f64::min)
    }

    /// The centre line of the row at lateral `y` (metres) turned by `heading`, as a pinhole
    /// of focal length `f` on a `size`² image mounted as `m` sees it: its rays from 1 m to
    /// `reach` metres ahead.
    fn centre_line(
        f: f64,
        size: f64,
        m: &Mounting,
        y: f64,
        heading: f64,
        reach: f64,
    ) -> Vec<Vector3<f64>> {
        let cam_from_robot = m.robot_from_camera().inverse();
        let yaw = Rotation3::from_axis_angle(&Vector3::z_axis(), heading);
        (0..400)
            .map(|i| 1.0 + i as f64 * (reach - 1.0) / 399.0)
            .map(|x| (cam_from_robot * (yaw * Vector3::new(x, y, -m.height_m))).normalize())
            .filter(|r| {
                let (row, col) = (r.x / -r.z * f, r.y / -r.z * f);
                -r.z > 0.05 && row.abs() <= size / 2.0 && col.abs() <= size / 2.0
            })
            .collect()
    }

    /// The largest distance (pixels, at `f`) of `line`'s rays from the great circle `n`.
    fn off_line_px(n: &Vector3<f64>, line: &[Vector3<f64>], f: f64) -> f64 {
        let n = n.normalize();
        line.iter()
            .map(|r| n.dot(r).abs().min(1.0).asin() / (-r.z).powi(2) * f)
            .fold(0.0, f64::max)
    }

    /// A peak seen from a candidate: u, the kernel's width in u, weight and strip.
    #[derive(Debug, Clone, Copy, PartialEq)]
    struct Seen {
        u: f64,
        s: f64,
        w: f64,
        strip: u32,
    }

    fn columns(seen: &[Seen]) -> SeenColumns {
        let mut c = SeenColumns::default();
        for x in seen {
            c.push(x.u, x.s, x.w, x.strip);
        }
        c
    }

    #[test]
    fn the_lanes_pair_sum_is_the_pairs_sum_over_the_kernels_support() {
        let mut r = uniform(17);
        let mut seen: Vec<Seen> = (0..203)
            .map(|_| Seen {
                u: 4.0 * r() - 2.0,
                s: 0.01 + 0.2 * r(),
                w: r(),
                strip: (r() * 12.0) as u32,
            })
            .collect();
        seen.sort_by(|x, y| x.u.total_cmp(&y.u));
        let c = columns(&seen);
        let pairs = |c: &SeenColumns, i, end| pairs(&c.u, &c.s2, &c.w, &c.strip, i, end);
        let direct = |i: usize, end: usize| -> f64 {
            let x = seen[i];
            seen[i + 1..end]
                .iter()
                .filter(|y| y.strip != x.strip)
                .map(|y| {
                    let z2 = (y.u - x.u).powi(2) / (x.s * x.s + y.s * y.s);
                    y.w * (1.0 - z2 / 9.0).max(0.0).powi(3)
                })
                .sum()
        };
        let mut nonzero = 0;
        for i in 0..seen.len() {
            for end in [seen.len(), (i + 7).min(seen.len())] {
                let (lanes, want) = (pairs(&c, i, end), direct(i, end));
                assert!(
                    (lanes - want).abs() <= 1e-12 * (1.0 + want),
                    "{i}: {lanes} {want}"
                );
                nonzero += usize::from(want > 0.0);
            }
        }
        assert!(nonzero > 300, "{nonzero}");
        // a pair within one strip adds nothing however close
        let c = columns(&[
            seen[0],
            Seen {
                u: seen[0].u,
                ..seen[0]
            },
        ]);
        assert_eq!(pairs(&c, 0, 2), 0.0);
    }

    #[test]
    fn rows_and_vanishing_point_of_a_flat_field() {
        let m = forward_camera();
        let fld = field(300.0, 512.0, &m, 0.5, 0.1, 5f64.to_radians());
        let mut s = StripsRows::new(StripsOptions::default(), 15.0, &m).unwrap();
        let mut rows = Vec::new();
        let vp = s
            .find(&fld.rays, &fld.weights, &fld.pixel_rad, &mut rows)
            .unwrap()
            .expect("a vanishing point");
        let cam_from_robot = m.robot_from_camera().inverse();
        let yaw = Rotation3::from_axis_angle(&Vector3::z_axis(), 5f64.to_radians());
        let truth = cam_from_robot * (yaw * Vector3::x());
        let err = vp.dot(&truth).abs().min(1.0).acos();
        // the search's last step is one pixel: 3.3 mrad at f = 300 px
        assert!(err < 2.5 / 300.0, "vanishing point {err} rad off");
        assert!(rows.len() >= 4, "{} rows", rows.len());
        for r in &rows {
            assert_eq!(r.method, Method::Strips);
            let e = nearest(&r.normal, &fld.normals);
            assert!(
                e < 2.5 / 300.0,
                "row {:?} is {e} rad from every true row",
                r.normal
            );
        }
        // one row per true row: no two published rows on the same one
        for (i, a) in rows.iter().enumerate() {
            for b in &rows[i + 1..] {
                assert!(a.normal.dot(&b.normal).abs() < 0.9999, "duplicate rows");
            }
        }
    }

    #[test]
    fn the_agreement_near_a_point_climbs_to_its_summit_and_leaves_the_result() {
        let m = forward_camera();
        let fld = field(300.0, 512.0, &m, 0.5, 0.1, 5f64.to_radians());
        let mut s = StripsRows::new(StripsOptions::default(), 15.0, &m).unwrap();
        let ray = Vector3::new(0.0, 0.0, -1.0);
        assert_eq!(s.agreement_near(&ray), None, "no image yet");
        let mut rows = Vec::new();
        let vp = s
            .find(&fld.rays, &fld.weights, &fld.pixel_rad, &mut rows)
            .unwrap()
            .expect("a vanishing point");
        let found = s.last();
        // from the answer and from 5 px beside it: the search's own summit
        for (da, dp) in [(0.0, 0.0), (5.0, -4.0)] {
            let [a, p] = found.vanishing_px.unwrap();
            let start = s.to_ray(a + da, p + dp);
            let (e, away) = s.agreement_near(&start).unwrap();
            assert!(away <= SAME_SUMMIT_TEST_PX, "{away} px from the answer");
            assert!((e / found.agreement - 1.0).abs() < 0.02, "{e} {found:?}");
        }
        assert_eq!(s.last(), found, "the result stays the search's");
        // the point of a direction 20° above the rows': a lower summit of its own
        let up = Rotation3::from_axis_angle(&Vector3::x_axis(), 20f64.to_radians()) * vp;
        let (e, away) = s.agreement_near(&up).unwrap();
        assert!(e < 0.5 * found.agreement, "{e} {found:?}");
        assert!(away > 50.0, "{away}");
        // the next image starts from its own peaks: the same answer again
        s.find(&fld.rays, &fld.weights, &fld.pixel_rad, &mut rows)
            .unwrap();
        assert_eq!(s.last(), found);
    }

    #[test]
    fn a_row_turned_off_the_common_point_gets_its_own_line() {
        // five rows 0.5 m apart, the middle one laid 0.6° off the others (a drill that
        // wandered): it does not pass through their vanishing point
        let m = forward_camera();
        let mut fld = field_at(300.0, 512.0, &m, &[-1.0, -0.5, 0.5, 1.0], 0.0);
        let turned = field_at(300.0, 512.0, &m, &[0.0], 0.6f64.to_radians());
        fld.rays.extend(&turned.rays);
        fld.weights.extend(&turned.weights);
        fld.pixel_rad.extend(&turned.pixel_rad);
        // the row up to 10 m ahead, where the robot steers
        let line = centre_line(300.0, 512.0, &m, 0.0, 0.6f64.to_radians(), 10.0);
        let run = |own_lines: bool| {
            let opts = StripsOptions {
                own_lines,
                ..Default::default()
            };
            let mut s = StripsRows::new(opts, 15.0, &m).unwrap();
            let mut rows = Vec::new();
            s.find(&fld.rays, &fld.weights, &fld.pixel_rad, &mut rows)
                .unwrap()
                .expect("a vanishing point");
            let off = rows
                .iter()
                .map(|r| off_line_px(&r.normal, &line, 300.0))
                .fold(f64::MAX, f64::min);
            (rows.len(), off)
        };
        let (n_pencil, pencil) = run(false);
        let (n_own, own) = run(true);
        assert_eq!((n_pencil, n_own), (5, 5));
        // its own line strays half as far (4.0 and 1.9 px at worst when written): its far
        // end is held near the common point by the anchor
        assert!(own < 2.5, "own line {own} px off");
        assert!(pencil > 1.8 * own, "pencil {pencil} px, own {own} px");
    }

    /// The field of [`rows_and_vanishing_point_of_a_flat_field`] with scattered weeds: its
    /// vanishing point found with `opts`, and the candidates evaluated.
    fn search_with(
        opts: StripsOptions,
        window: Option<(&Vector3<f64>, f64)>,
    ) -> (Vector3<f64>, usize) {
        let m = forward_camera();
        let mut fld = field(300.0, 512.0, &m, 0.5, 0.1, 5f64.to_radians());
        let mut rnd = uniform(7);
        let cam_from_robot = m.robot_from_camera().inverse();
        for _ in 0..4000 {
            let (x, y) = (1.0 + 20.0 * rnd(), 8.0 * (rnd() - 0.5));
            fld.see(
                &(cam_from_robot * Vector3::new(x, y, -m.height_m)),
                300.0,
                512.0,
            );
        }
        let mut s = StripsRows::new(opts, 15.0, &m).unwrap();
        s.set_window(window);
        let mut rows = Vec::new();
        let vp = s
            .find(&fld.rays, &fld.weights, &fld.pixel_rad, &mut rows)
            .unwrap()
            .expect("a vanishing point");
        (vp, s.last().evaluated)
    }

    #[test]
    fn the_coarse_grid_finds_the_full_grids_vanishing_point_for_a_third_of_the_work() {
        let full = StripsOptions {
            search_regions: 0,
            ..StripsOptions::default()
        };
        let (vp_full, n_full) = search_with(full, None);
        let (vp, n) = search_with(StripsOptions::default(), None);
        assert!(
            vp.dot(&vp_full).abs() > 1.0 - 1e-12,
            "{vp:?} against {vp_full:?}"
        );
        assert!(3 * n < n_full, "{n} candidates evaluated against {n_full}");
    }

    #[test]
    fn the_coarse_grid_on_the_strongest_half_of_the_peaks_finds_the_same_point() {
        let half = StripsOptions {
            search_coarse_share: 0.5,
            ..StripsOptions::default()
        };
        let (vp_half, _) = search_with(half, None);
        let (vp, _) = search_with(StripsOptions::default(), None);
        // within a pixel of the virtual image (f = 300 px)
        let angle = vp_half.angle(&vp);
        assert!(angle < 1.0 / 300.0, "{angle} rad apart");
    }

    #[test]
    fn the_strongest_share_of_the_peaks_keeps_their_order_and_ties() {
        let mut s = StripsRows::new(StripsOptions::default(), 15.0, &forward_camera()).unwrap();
        let peak = |w: f64, strip: u32| Peak {
            a: 0.0,
            p: strip as f64,
            w,
            strip,
        };
        s.peaks = vec![
            peak(1.0, 0),
            peak(5.0, 1),
            peak(3.0, 2),
            peak(3.0, 3),
            peak(0.5, 4),
        ];
        assert!(s.keep_strongest(0.4));
        let strips: Vec<u32> = s.coarse_peaks.iter().map(|k| k.strip).collect();
        assert_eq!(
            strips,
            [1, 2, 3],
            "the 40 % and the peak tied with the lightest of them"
        );
        assert!(s.keep_strongest(0.2));
        assert_eq!(s.coarse_peaks.len(), 1);
        assert!(!s.keep_strongest(1.0), "all of them is no coarse set");
        s.peaks.clear();
        assert!(!s.keep_strongest(0.5), "no peaks");
    }

    #[test]
    fn the_comb_breaks_only_near_ties_and_only_nearby() {
        // (agreement, along, below); the comb's strength by position
        let summits = [(1.0, 0.0, 0.0), (0.95, 30.0, -40.0), (0.97, 300.0, 0.0)];
        let comb = |a: f64, _p: f64| if a == 0.0 { 0.5 } else { 1.0 };
        let pick = |power, reach| pick_summit(&summits, power, reach, comb).unwrap();
        // the agreement alone: the highest
        assert_eq!(pick(0.0, 100.0), summits[0]);
        // 0.95 × 1 > 1 × 0.5^0.25 = 0.84: the nearby summit with the stronger comb wins
        assert_eq!(pick(0.25, 100.0), summits[1]);
        // out of reach it cannot, however strong its comb
        assert_eq!(pick(0.25, 40.0), summits[0]);
        // a summit far below the highest never wins: 0.5 × 1 < 1 × 0.5^0.25
        let low = [(1.0, 0.0, 0.0), (0.5, 10.0, 0.0)];
        assert_eq!(pick_summit(&low, 0.25, 100.0, comb).unwrap(), low[0]);
        // its comb is not even read: a strength is at most 1
        let mut read = vec![];
        pick_summit(&low, 0.25, 100.0, |a, p| {
            read.push((a, p));
            comb(a, p)
        });
        assert_eq!(read, [(0.0, 0.0)]);
        // one summit, or none
        assert_eq!(pick_summit(&low[..1], 0.25, 100.0, comb), Some(low[0]));
        assert_eq!(pick_summit(&[], 0.25, 100.0, comb), None);
    }

    #[test]
    fn a_window_narrows_the_search_and_a_window_beside_the_rows_finds_nothing() {
        let (vp_full, n_full) = search_with(StripsOptions::default(), None);
        let w = 2f64.to_radians();
        let (vp, n) = search_with(StripsOptions::default(), Some((&vp_full, w)));
        // the same summit, found on a finer grid: within the last step's pixel
        assert!(vp.dot(&vp_full).abs().min(1.0).acos() < 1.5 / 300.0);
        assert!(5 * n < n_full, "{n} candidates evaluated against {n_full}");
        // a window 8° to the side: the agreement rises towards its edge, so no answer
        let m = forward_camera();
        let side = m.robot_from_camera().inverse()
            * (Rotation3::from_axis_angle(&Vector3::z_axis(), 13f64.to_radians()) * Vector3::x());
        let fld = field(300.0, 512.0, &m, 0.5, 0.1, 5f64.to_radians());
        let mut s = StripsRows::new(StripsOptions::default(), 15.0, &m).unwrap();
        s.set_window(Some((&side, w)));
        let mut rows = Vec::new();
        let got = s
            .find(&fld.rays, &fld.weights, &fld.pixel_rad, &mut rows)
            .unwrap();
        assert!(
            got.is_none() && rows.is_empty(),
            "{got:?}, {} rows",
            rows.len()
        );
        // widened again: the full search's answer on the same points
        s.set_window(None);
        let again = s
            .find(&fld.rays, &fld.weights, &fld.pixel_rad, &mut rows)
            .unwrap();
        let full = StripsRows::new(StripsOptions::default(), 15.0, &m)
            .unwrap()
            .find(&fld.rays, &fld.weights, &fld.pixel_rad, &mut rows)
            .unwrap()
            .expect("a vanishing point");
        assert!(again.is_some_and(|v| v.dot(&full).abs() > 1.0 - 1e-9));
        assert!(full.dot(&vp_full).abs().min(1.0).acos() < 2.5 / 300.0);
    }

    #[test]
    fn rows_spaced_unevenly_lie_on_their_own_peaks_not_on_the_comb() {
        // 0.5 m rows, each shifted by up to 0.09 m (under the comb's band of a quarter
        // period): the comb's evenly spaced teeth miss them, their own peaks do not (the rows
        // through the vanishing point: their own lines would find them either way)
        let m = forward_camera();
        let shift = [0.0, 0.09, -0.07, 0.05, -0.09, 0.08, -0.04, 0.07, -0.08];
        let ys: Vec<f64> = (-4..=4)
            .zip(shift)
            .map(|(k, d)| 0.1 + k as f64 * 0.5 + d)
            .collect();
        let fld = field_at(300.0, 512.0, &m, &ys, 3f64.to_radians());
        let worst = |rounds: usize| {
            let opts = StripsOptions {
                recentre_rounds: rounds,
                own_lines: false,
                ..StripsOptions::default()
            };
            let mut s = StripsRows::new(opts, 15.0, &m).unwrap();
            let mut rows = Vec::new();
            s.find(&fld.rays, &fld.weights, &fld.pixel_rad, &mut rows)
                .unwrap()
                .expect("a vanishing point");
            assert!(rows.len() >= 4, "{} rows", rows.len());
            rows.iter()
                .map(|r| nearest(&r.normal, &fld.normals))
                .fold(0.0f64, f64::max)
        };
        let (on_peaks, on_teeth) = (worst(StripsOptions::default().recentre_rounds), worst(0));
        assert!(
            on_peaks < 4.0 / 300.0,
            "a row {on_peaks} rad from every true row"
        );
        assert!(
            on_teeth > 2.0 * on_peaks,
            "the comb's teeth alone were as close ({on_teeth} rad): the test shows nothing"
        );
    }

    #[test]
    fn rows_beside_dense_canopy_stand_out_by_their_prominence() {
        // 0.5 m rows; on the left of y = -0.3 m (REP 103: y to the left) a carpet of
        // vegetation between them, denser than the rows' own plants a little way out: it
        // raises every strip's median above the bare right side's rows
        let m = forward_camera();
        let ys: Vec<f64> = (-4..=4).map(|k| 0.1 + k as f64 * 0.5).collect();
        let mut fld = field_at(300.0, 512.0, &m, &ys, 0.0);
        let cam_from_robot = m.robot_from_camera().inverse();
        let mut rnd = uniform(777);
        for _ in 0..200_000 {
            let x = 1.0 / (1.0 - rnd() * (1.0 - 1.0 / 40.0));
            let y = -0.3 + rnd() * 6.0;
            fld.see(
                &(cam_from_robot * Vector3::new(x, y, -m.height_m)),
                300.0,
                512.0,
            );
        }
        // the true rows right of the carpet that each option finds (within 4 px-angles)
        let bare: Vec<Vector3<f64>> = ys
            .iter()
            .zip(&fld.normals)
            .filter(|(y, _)| **y < -0.3)
            .map(|(_, n)| *n)
            .collect();
        let found = |prominence_px: f64| {
            let opts = StripsOptions {
                prominence_px,
                ..StripsOptions::default()
            };
            let mut s = StripsRows::new(opts, 15.0, &m).unwrap();
            let mut rows = Vec::new();
            s.find(&fld.rays, &fld.weights, &fld.pixel_rad, &mut rows)
                .unwrap();
            bare.iter()
                .filter(|t| {
                    rows.iter()
                        .any(|r| nearest(&r.normal, &[**t]) < 4.0 / 300.0)
                })
                .count()
        };
        let (by_prominence, by_median) =
            (found(StripsOptions::default().prominence_px), found(0.0));
        assert_eq!(by_prominence, bare.len(), "rows beside the canopy found");
        assert!(
            by_median < by_prominence,
            "the median found {by_median}: the test shows nothing"
        );
    }

    #[test]
    fn the_same_field_through_focal_lengths_4x_apart_gives_the_same_rows() {
        let m = forward_camera();
        let narrow = field(1200.0, 2048.0, &m, 0.5, -0.15, -3f64.to_radians());
        let wide = field(300.0, 512.0, &m, 0.5, -0.15, -3f64.to_radians());
        let (mut a, mut b) = (Vec::new(), Vec::new());
        let opts = StripsOptions::default();
        let va = StripsRows::new(opts, 15.0, &m)
            .unwrap()
            .find(&narrow.rays, &narrow.weights, &narrow.pixel_rad, &mut a)
            .unwrap()
            .unwrap();
        let vb = StripsRows::new(opts, 15.0, &m)
            .unwrap()
            .find(&wide.rays, &wide.weights, &wide.pixel_rad, &mut b)
            .unwrap()
            .unwrap();
        let d = va.dot(&vb).abs().min(1.0).acos();
        assert!(d < 2.5 / 300.0, "vanishing points {d} rad apart");
        assert!(
            a.len() >= 4 && b.len() >= 4,
            "{} and {} rows",
            a.len(),
            b.len()
        );
        let truth = narrow.normals;
        for r in a.iter().chain(&b) {
            let e = nearest(&r.normal, &truth);
            assert!(e < 2.5 / 300.0, "a row {e} rad from every true row");
        }
    }

    /// How many rows the strips method with `opts` publishes on `fld`, each asserted to lie
    /// on a true row (`what` names the options in the message).
    fn true_rows(fld: &Field, m: &Mounting, opts: StripsOptions, what: &str) -> usize {
        let mut rows = Vec::new();
        StripsRows::new(opts, 15.0, m)
            .unwrap()
            .find(&fld.rays, &fld.weights, &fld.pixel_rad, &mut rows)
            .unwrap()
            .expect("a vanishing point");
        for r in &rows {
            let e = nearest(&r.normal, &fld.normals);
            assert!(e < 2.5 / 300.0, "{what}: a row {e} rad off");
        }
        rows.len()
    }

    #[test]
    fn rows_slanting_across_the_strips_are_found_once_straightened() {
        let m = forward_camera();
        let fld = field(300.0, 512.0, &m, 0.5, 0.2, 2f64.to_radians());
        let found = |straighten: bool| {
            let opts = StripsOptions {
                straighten,
                ..Default::default()
            };
            true_rows(&fld, &m, opts, &format!("straighten {straighten}"))
        };
        // the outer rows cross each strip at a slant: 8 rows found before, 14 straightened
        let (sheared, straight) = (found(false), found(true));
        assert!(
            straight >= sheared + 4,
            "{straight} rows straightened, {sheared} not"
        );
    }

    #[test]
    fn rows_leaving_the_image_early_need_fewer_strips() {
        let m = forward_camera();
        let fld = field(300.0, 512.0, &m, 0.75, 0.1, -4f64.to_radians());
        let found = |min_strips_floor: usize| {
            let opts = StripsOptions {
                min_strips_floor,
                ..Default::default()
            };
            true_rows(&fld, &m, opts, &format!("floor {min_strips_floor}"))
        };
        // the outer rows leave the image by their sides: 10 rows found needing `min_strips`
        // (7) strips, 12 with the default floor of 6, 12 with a floor of 5
        let (all, default, five) = (
            found(StripsOptions::default().min_strips),
            found(StripsOptions::default().min_strips_floor),
            found(5),
        );
        assert!(
            all < default && default <= five,
            "{all}, {default} and {five} rows with floors of min_strips, the default and 5"
        );
    }

    #[test]
    fn scattered_points_give_no_rows_between_the_teeth() {
        // rows plus uniform weeds: every published row is a true row
        let m = forward_camera();
        let mut fld = field(300.0, 512.0, &m, 0.6, 0.0, 0.0);
        let mut seed = 99u64;
        for _ in 0..6000 {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
            let row = ((seed >> 33) % 512) as f64 - 256.0;
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
            let col = ((seed >> 33) % 512) as f64 - 256.0;
            let r = Vector3::new(row / 300.0, col / 300.0, -1.0).normalize();
            fld.rays.push([r.x as f32, r.y as f32, r.z as f32]);
            fld.weights.push(1.0);
            fld.pixel_rad.push(((-r.z).powf(1.5) / 300.0) as f32);
        }
        let mut s = StripsRows::new(StripsOptions::default(), 15.0, &m).unwrap();
        let mut rows = Vec::new();
        s.find(&fld.rays, &fld.weights, &fld.pixel_rad, &mut rows)
            .unwrap();
        assert!(rows.len() >= 3);
        // each published row lies on a true row where that row is in the image
        let lines: Vec<_> = (-8..=8)
            .map(|k| centre_line(300.0, 512.0, &m, k as f64 * 0.6, 0.0, 40.0))
            .filter(|l| l.len() >= 2)
            .collect();
        for r in &rows {
            let off = lines
                .iter()
                .map(|l| off_line_px(&r.normal, l, 300.0))
                .fold(f64::MAX, f64::min);
            assert!(off < 2.5, "a row {off} px from every true row");
        }
    }

    #[test]
    fn a_camera_looking_down_is_refused_by_name() {
        let e = StripsRows::new(StripsOptions::default(), 15.0, &Mounting::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("strips") && e.contains("forward-looking"), "{e}");
    }

    #[test]
    fn the_profile_smoothed_in_blocks_is_the_cut_convolution_to_the_bit() {
        let mut next = uniform(9);
        let mut out = Vec::new();
        for bins in [0, 1, 2, 5, 16, 17, 33, 40, 257] {
            for half in [0, 1, 3, 8] {
                let row: Vec<f64> = (0..bins)
                    .map(|_| if next() < 0.3 { 0.0 } else { next() * 100.0 })
                    .collect();
                let kernel: Vec<f64> = (0..2 * half + 1).map(|_| next()).collect();
                smooth_profile(&row, &kernel, &mut out);
                assert_eq!(out.len(), bins);
                for (i, &o) in out.iter().enumerate() {
                    let mut want = 0.0;
                    for (j, x) in row.iter().enumerate() {
                        if j + half >= i && j <= i + half {
                            want += x * kernel[j + half - i];
                        }
                    }
                    assert_eq!(o.to_bits(), want.to_bits(), "bins {bins} half {half} i {i}");
                }
            }
        }
    }

    #[test]
    fn sin_cos_is_the_c_librarys_to_a_few_ulp() {
        let mut next = uniform(17);
        let mut worst = 0.0f64;
        for k in 0..200_000 {
            // every scale from 10⁻⁶ to 10⁶, both signs, and the quadrants' boundaries
            let x = match k % 3 {
                0 => (next() - 0.5) * 10f64.powf(12.0 * next() - 6.0) * 2.0,
                1 => (k as f64 - 100_000.0) * std::f64::consts::FRAC_PI_4,
                _ => (next() - 0.5) * 2000.0,
            };
            let (s, c) = sin_cos(x);
            let (s0, c0) = x.sin_cos();
            worst = worst.max((s - s0).abs()).max((c - c0).abs());
        }
        assert!(worst < 4.0 * f64::EPSILON, "worst error {worst:e}");
    }

    #[test]
    fn fourier_sums_are_the_c_librarys_and_far_arguments_fall_back_to_it() {
        let mut next = uniform(5);
        for n in [0, 1, 3, 4, 7, 250] {
            let u: Vec<f64> = (0..n).map(|_| (next() - 0.5) * 6.0).collect();
            let w: Vec<f64> = (0..n).map(|_| next()).collect();
            // ordinary frequencies, and one that takes the arguments beyond 10⁶
            for f in [8.4, 83.7, 2e6] {
                let (c, s) = fourier(&u, &w, f);
                let (c0, s0) = u.iter().zip(&w).fold((0.0, 0.0), |(c, s), (&x, &w)| {
                    let (sn, cs) = (f * x).sin_cos();
                    (c + w * cs, s + w * sn)
                });
                let tol = 1e-13 * (1.0 + n as f64);
                assert!((c - c0).abs() < tol && (s - s0).abs() < tol, "n {n} f {f}");
            }
        }
    }

    #[test]
    fn bad_options_are_named() {
        for (o, key) in [
            (
                StripsOptions {
                    search_comb_power: -1.0,
                    ..StripsOptions::default()
                },
                "search_comb_power",
            ),
            (
                StripsOptions {
                    search_comb_reach_px: 0.0,
                    ..StripsOptions::default()
                },
                "search_comb_reach_px",
            ),
            (
                StripsOptions {
                    own_line_anchor: -0.1,
                    ..StripsOptions::default()
                },
                "own_line_anchor",
            ),
            (
                StripsOptions {
                    own_line_reject: f64::INFINITY,
                    ..StripsOptions::default()
                },
                "own_line_reject",
            ),
            (
                StripsOptions {
                    strip_px: 0.0,
                    ..StripsOptions::default()
                },
                "strip_px",
            ),
            (
                StripsOptions {
                    comb_max_period: f64::NAN,
                    ..StripsOptions::default()
                },
                "comb_max_period",
            ),
            (
                StripsOptions {
                    min_strips: 1,
                    ..StripsOptions::default()
                },
                "min_strips",
            ),
            (
                StripsOptions {
                    min_strips_floor: 9,
                    ..StripsOptions::default()
                },
                "min_strips_floor",
            ),
            (
                StripsOptions {
                    min_strips_share: 0.0,
                    ..StripsOptions::default()
                },
                "min_strips_share",
            ),
            (
                StripsOptions {
                    kept_share: 0.0,
                    ..StripsOptions::default()
                },
                "kept_share",
            ),
            (
                StripsOptions {
                    search_regions: 100_000,
                    ..StripsOptions::default()
                },
                "search_regions",
            ),
            (
                StripsOptions {
                    search_coarse_share: 0.0,
                    ..StripsOptions::default()
                },
                "search_coarse_share",
            ),
            (
                StripsOptions {
                    search_coarse_share: 1.5,
                    ..StripsOptions::default()
                },
                "search_coarse_share",
            ),
        ] {
            let e = o.validate().unwrap_err().to_string();
            assert!(e.contains(key), "{e}");
        }
    }

    #[test]
    fn no_points_no_rows_and_mismatched_buffers_are_an_error() {
        let m = forward_camera();
        let mut s = StripsRows::new(StripsOptions::default(), 15.0, &m).unwrap();
        let mut rows = vec![];
        assert_eq!(s.find(&[], &[], &[], &mut rows).unwrap(), None);
        assert!(rows.is_empty());
        assert!(s.find(&[[0.0, 0.0, -1.0]], &[], &[], &mut rows).is_err());
    }
}
