//! The strips method: the crop rows of a forward-looking perspective camera, found as the
//! vegetation's peaks along horizontal strips of a virtual perspective image, lined up through
//! a searched vanishing point, on the teeth of the rows' evenly spaced comb; each row is then
//! fitted its own line.
//!
//! The method owns, one file each:
//! - the virtual image (`virtual_image.rs`): the camera's own perspective image (an ideal
//!   pinhole on the optical axis at the calibration's angular resolution there), turned so that
//!   its strips run along the horizon that the mounting implies. Every length is in its pixels,
//!   so the same scene through any focal length gives the same rows;
//! - the strips' peaks (`peaks.rs`): each strip's vegetation profile across the image,
//!   smoothed; its peaks, by their prominence, are where crop rows cross the strip;
//! - the agreement (`agreement.rs`): seen from a candidate vanishing point (a_v, p_v) — along
//!   and below the horizon — a peak at (a, p) lies at u = (a − a_v)/(p − p_v) in the pencil of
//!   lines through it. For crop rows on flat ground u is proportional to the row's lateral
//!   position over the camera's height, so at the rows' vanishing point the peaks of one row
//!   share one u in every strip. The agreement is a kernel sum over the pairs of peaks from
//!   different strips, each peak's width in u its pixel uncertainty over its depth;
//! - the search (`search.rs`): the vanishing point of the highest agreement within the
//!   heading and tilt limits (or a prior's window), a coarse grid climbed to 1 px, a near tie
//!   between nearby summits broken by the comb's strength;
//! - the comb (`comb.rs`, `fourier.rs`): the period and phase of the peaks' u (their strongest
//!   Fourier component), read on the peaks again with each strip straightened about the
//!   vanishing point. Each tooth with peaks in enough strips is a row, placed at the centre of
//!   its own peaks; peaks between the teeth (weeds, plant edges, shadows) are not rows;
//! - each row's own line (`own_line.rs`): fitted to the straightened peaks on its tooth and
//!   anchored at the vanishing point, since real rows do not all meet in one point.
//!
//! The detector then polishes the rows on the image's pixels within a band
//! ([`REFERENCE_POLISH_MAX_BAND_DEG`] times the calibration's angle factor).

mod agreement;
mod comb;
mod fourier;
mod own_line;
mod peaks;
mod search;
#[cfg(test)]
mod testing;
mod virtual_image;

use super::pose::RobotAxes;
use super::types::{DetectError, Points, Row};
use crate::camera::Mounting;
use agreement::Sight;
use nalgebra::Vector3;
use peaks::Peak;
use rayon::ThreadPool;
use serde::{Deserialize, Serialize};

/// The share of the working image's pixels the threshold keeps as points for this method
/// (its target when `threshold.target_points` is absent): the strips' profiles need the rows'
/// whole vegetation, pale plants included, not only its brightest few per cent.
pub const KEPT_SHARE: f64 = 0.23;

/// The threshold's floor for this method (when `threshold.min_level` is absent): low enough
/// to keep faint and shadowed plants (2G − R − B from 16 on the halved excess-green image),
/// which a sparse field needs to fill its share.
pub const KEPT_MIN_LEVEL: u8 = 7;

/// The polish's widest band around a row (degrees) at the reference angular resolution; the
/// detector uses it times the calibration's angle factor. Twice the pencil's, since the
/// strips' rows lie on their own peaks and only need room to reach the row's centre, and no
/// wider, since a wide band lets the refit pull a row off its own line.
pub const REFERENCE_POLISH_MAX_BAND_DEG: f64 = 6.0;

/// Options of the strips method (the `[detector.strips]` section of the configuration).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StripsOptions {
    /// Largest heading of the rows from the robot's forward axis searched (degrees): raise it
    /// when the robot may drive at a steeper angle to the rows, lower it to keep other
    /// structures at the side (a hedge, a headland) out of the search.
    pub max_heading_deg: f64,
    /// At most this many rows are reported, the best supported: raise it when the camera
    /// sees more rows at once.
    pub max_rows: usize,
    /// Shortest comb period searched: the rows' spacing over the camera's height, about;
    /// lower it for rows unusually close together for the mounting's height.
    pub comb_min_period: f64,
    /// Longest comb period searched (as `comb_min_period`): raise it for rows unusually far
    /// apart for the mounting's height.
    pub comb_max_period: f64,
}

impl Default for StripsOptions {
    fn default() -> Self {
        StripsOptions {
            max_heading_deg: 25.0,
            max_rows: 16,
            comb_min_period: 0.075,
            comb_max_period: 0.75,
        }
    }
}

impl StripsOptions {
    /// Checks each option's range; the error names a bad option and the range it must lie in.
    pub fn validate(&self) -> Result<(), DetectError> {
        let bad = |what: String| Err(DetectError::Options(format!("strips.{what}")));
        if !(self.max_heading_deg.is_finite() && (0.0..80.0).contains(&self.max_heading_deg)) {
            return bad(format!(
                "max_heading_deg = {} must be within [0, 80)",
                self.max_heading_deg
            ));
        }
        if !(self.comb_min_period.is_finite()
            && self.comb_min_period > 0.0
            && self.comb_min_period < self.comb_max_period
            && self.comb_max_period <= 100.0)
        {
            return bad(format!(
                "comb_min_period = {}, comb_max_period = {}: need 0 < min < max <= 100",
                self.comb_min_period, self.comb_max_period
            ));
        }
        if !(1..=256).contains(&self.max_rows) {
            return bad(format!(
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
    /// The points in the virtual image (along, below, weight).
    pts: Vec<[f64; 3]>,
    /// The strips' profiles, one row of bins per strip, and one profile smoothed.
    hist: Vec<f64>,
    smooth: Vec<f64>,
    /// The profiles' smoothing kernel.
    kernel: Vec<f64>,
    scratch: Vec<f64>,
    /// The strips' peaks, in the strips' order (deepest last).
    peaks: Vec<Peak>,
    /// The search's grid of agreements.
    grid: Vec<f64>,
    /// The strongest peaks, on which the search's coarse grid is read.
    strong: Vec<Peak>,
    /// The prior's vanishing point (unit) and window half-angle, when narrowed.
    prior: Option<(Vector3<f64>, f64)>,
    /// The grid's local maxima (agreement, column, row), best first; in the search, once
    /// climbed, its summits (agreement, along, below).
    starts: Vec<(f64, f64, f64)>,
    /// This thread's scratch for the agreement (the peaks below the last candidate, for
    /// the pair sums and the comb), and the other threads' in a parallel search.
    sight: Sight,
    sights: Vec<Sight>,
    /// A batch of candidates (along, below) and their agreements.
    cand: Vec<[f64; 2]>,
    vals: Vec<f64>,
    /// The search grid's cells in a batch.
    cells: Vec<usize>,
    /// The comb's teeth that are rows: u, weight and the number of peaks on them.
    teeth: Vec<[f64; 3]>,
    /// Each strip's centre (below) and the extent of its points (along from, to).
    spans: Vec<[f64; 3]>,
    last: StripsResult,
}

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
        if !looks_forward(mounting) {
            return Err(DetectError::Options(format!(
                "method strips needs a forward-looking camera: the robot's forward axis is \
                 {:.0}° from the optical axis with this mounting (pitch_deg {}, roll_deg {}, \
                 yaw_deg {}); use hough, combined or auto",
                (-axes.fwd.z).clamp(-1.0, 1.0).acos().to_degrees(),
                mounting.pitch_deg,
                mounting.roll_deg,
                mounting.yaw_deg
            )));
        }
        let Some(e_p) = virtual_image::below_horizon(&axes) else {
            return Err(DetectError::Options(
                "method strips: the mounting's horizon is not in the image".into(),
            ));
        };
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
            kernel: peaks::smoothing_kernel(),
            scratch: Vec::new(),
            peaks: Vec::new(),
            grid: Vec::new(),
            strong: Vec::new(),
            prior: None,
            starts: Vec::new(),
            sight: Sight::default(),
            sights: Vec::new(),
            cand: Vec::new(),
            vals: Vec::new(),
            cells: Vec::new(),
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

    /// Finds the rows among the points (unit rays, weights, each pixel's angular size)
    /// into `rows` (cleared first). Returns the vanishing point's direction, or `None` when
    /// the points hold no rows.
    pub fn find(
        &mut self,
        points: &Points,
        rows: &mut Vec<Row>,
    ) -> Result<Option<Vector3<f64>>, DetectError> {
        self.find_on(points, rows, None)
    }

    /// [`Self::find`] with the search's candidates evaluated on `pool`'s threads when there
    /// is one: the same rows and vanishing point.
    pub fn find_on(
        &mut self,
        points: &Points,
        rows: &mut Vec<Row>,
        pool: Option<&ThreadPool>,
    ) -> Result<Option<Vector3<f64>>, DetectError> {
        points.check("strips")?;
        let (rays, weights, pixel_rad) = (&points.rays, &points.weights, &points.pixel_rad);
        rows.clear();
        self.last = StripsResult::default();
        if !self.set_scale(rays, pixel_rad) {
            return Ok(None);
        }
        self.collect_points(rays, weights);
        // the search on the strips' peaks as they are, the comb on them straightened
        self.read_peaks(None);
        self.last.peaks = self.peaks.len();
        let Some((av, pv, agreement)) = self.search(pool) else {
            return Ok(None);
        };
        self.read_peaks(Some((av, pv)));
        self.last.vanishing_px = Some([av, pv]);
        self.last.agreement = agreement;
        self.comb_rows(av, pv, rows);
        Ok(Some(self.to_ray(av, pv)))
    }
}

/// Whether a camera mounted as `m` looks forward enough for the strips method: the
/// robot's forward axis within about 78° of the optical axis (the camera looks along −z).
pub fn looks_forward(m: &Mounting) -> bool {
    -RobotAxes::new(m).fwd.z >= 0.2
}

#[cfg(test)]
mod tests {
    use super::testing::*;
    use super::*;
    use crate::detect::Method;
    use nalgebra::Rotation3;

    #[test]
    fn rows_and_vanishing_point_of_a_flat_field() {
        let m = forward_camera();
        let fld = field(300.0, 512.0, &m, 0.5, 0.1, 5f64.to_radians());
        let (_, vp, rows) = detect(&fld, &m);
        let vp = vp.expect("a vanishing point");
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
    fn the_same_field_through_focal_lengths_4x_apart_gives_the_same_rows() {
        let m = forward_camera();
        let narrow = field(1200.0, 2048.0, &m, 0.5, -0.15, -3f64.to_radians());
        let wide = field(300.0, 512.0, &m, 0.5, -0.15, -3f64.to_radians());
        let (mut a, mut b) = (Vec::new(), Vec::new());
        let opts = StripsOptions::default();
        let va = StripsRows::new(opts, 15.0, &m)
            .unwrap()
            .find(&narrow.points(), &mut a)
            .unwrap()
            .unwrap();
        let vb = StripsRows::new(opts, 15.0, &m)
            .unwrap()
            .find(&wide.points(), &mut b)
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

    #[test]
    fn a_camera_looking_down_is_refused_by_name() {
        let e = StripsRows::new(StripsOptions::default(), 15.0, &Mounting::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("strips") && e.contains("forward-looking"), "{e}");
    }

    #[test]
    fn bad_options_are_named() {
        let d = StripsOptions::default();
        for (o, name, text) in [
            (
                StripsOptions {
                    max_heading_deg: 80.0,
                    ..d
                },
                "max_heading_deg",
                "max_heading_deg = 80 must be within [0, 80)",
            ),
            (
                StripsOptions {
                    max_heading_deg: f64::NAN,
                    ..d
                },
                "max_heading_deg",
                "must be within [0, 80)",
            ),
            (
                StripsOptions { max_rows: 0, ..d },
                "max_rows",
                "max_rows = 0 must be within 1..=256",
            ),
            (
                StripsOptions { max_rows: 257, ..d },
                "max_rows",
                "must be within 1..=256",
            ),
            (
                StripsOptions {
                    comb_min_period: 0.0,
                    ..d
                },
                "comb_min_period",
                "need 0 < min < max <= 100",
            ),
            (
                StripsOptions {
                    comb_max_period: f64::NAN,
                    ..d
                },
                "comb_max_period",
                "need 0 < min < max <= 100",
            ),
            (
                StripsOptions {
                    comb_min_period: 0.5,
                    comb_max_period: 0.5,
                    ..d
                },
                "comb_max_period = 0.5",
                "need 0 < min < max <= 100",
            ),
        ] {
            let e = o.validate().unwrap_err().to_string();
            assert!(e.contains("strips.") && e.contains(name), "{e}");
            assert!(e.contains(text), "{e}");
        }
        assert!(d.validate().is_ok());
    }

    #[test]
    fn the_configuration_takes_only_the_four_options() {
        let o: StripsOptions = toml::from_str("max_rows = 12\ncomb_max_period = 1.0\n").unwrap();
        assert_eq!((o.max_rows, o.comb_max_period), (12, 1.0));
        assert_eq!(o.max_heading_deg, StripsOptions::default().max_heading_deg);
        for fixed in ["strip_px = 11.0", "search_blur = 0.0", "own_lines = true"] {
            let e = toml::from_str::<StripsOptions>(fixed).unwrap_err();
            assert!(e.to_string().contains("unknown field"), "{fixed}: {e}");
        }
    }

    #[test]
    fn no_points_no_rows_and_mismatched_buffers_are_an_error() {
        let m = forward_camera();
        let mut s = StripsRows::new(StripsOptions::default(), 15.0, &m).unwrap();
        let mut rows = vec![];
        assert_eq!(s.find(&Points::default(), &mut rows).unwrap(), None);
        assert!(rows.is_empty());
        let mismatched = Points {
            rays: vec![[0.0, 0.0, -1.0]],
            ..Points::default()
        };
        assert!(s.find(&mismatched, &mut rows).is_err());
    }
}
