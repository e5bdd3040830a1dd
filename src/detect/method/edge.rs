//! The edge method (paper II-C): rows from the plants' boundary lines.
//!
//! Owns [`EdgeMethod`]: the frame's boundary lines ([`Boundaries`]), turned to their
//! tangents beside the robot on a curved field when that makes them agree better on a
//! vanishing point ([`ChordBend`]); after the vote, the vanishing point refitted robustly
//! ([`PrecisionRefit`]) and the boundaries paired into crop rows' centre lines
//! ([`CentreLines`]), each refitted on the image's pixels between its boundaries and turned
//! to where it passes the robot.

use super::{Frame, RowMethod};
use crate::detect::boundaries::Boundaries;
use crate::detect::centre::CentreLines;
use crate::detect::chords::ChordBend;
use crate::detect::combine::{PrecisionRefit, REFERENCE_PAIR_MAX_DEG};
use crate::detect::edge::EdgeOptions;
use crate::detect::refit::{turn_to_feet, NEAR_MIN_SIGMA};
use crate::detect::types::{DetectError, Detection, Row};
use crate::detect::vanishing::support_weights;

/// The edge rows turned by a bend are kept when this many times more of their support
/// passes through their vanishing point than the chords' did.
const BEND_GAIN: f64 = 1.25;

/// The edge method.
#[derive(Debug, Clone)]
pub struct EdgeMethod {
    boundaries: Boundaries,
    /// Whether a curved field's rows are turned to their tangents (`refit.near_reach_m`
    /// > 0).
    bend_rows: bool,
    bend: ChordBend,
    /// The rows before the bend, and a detection to vote on them.
    chord_rows: Vec<Row>,
    probe: Detection,
    refit: PrecisionRefit,
    inliers: Vec<bool>,
    centre: CentreLines,
    /// The centre lines' half-widths, as the refit's bands.
    centre_bands: Vec<f64>,
    /// The widest half-width of a crop row (radians).
    pair_max_rad: f64,
}

impl EdgeMethod {
    /// The method with the `[detector.edge]` options, its angular scales at
    /// `angle_factor` times their reference values; `bend_rows`: a curved field's rows are
    /// turned to their tangents beside the robot (`refit.near_reach_m` > 0).
    pub fn new(
        opts: &EdgeOptions,
        bend_rows: bool,
        angle_factor: f64,
    ) -> Result<Self, DetectError> {
        Ok(EdgeMethod {
            boundaries: Boundaries::new(opts, angle_factor)?,
            bend_rows,
            bend: ChordBend::default(),
            chord_rows: Vec::with_capacity(64),
            probe: Detection::default(),
            refit: PrecisionRefit::default(),
            inliers: Vec::with_capacity(128),
            centre: CentreLines::default(),
            centre_bands: Vec::with_capacity(64),
            pair_max_rad: (REFERENCE_PAIR_MAX_DEG * angle_factor).to_radians(),
        })
    }

    /// The rows, chords on one side of the robot on a curved field, turned to their
    /// tangents beside it before the vote ([`ChordBend::turn`]). Kept only when the turned
    /// rows agree on their vanishing point better than the chords did: a tilted robot on a
    /// straight field also makes the chords' headings, projected on the nominal ground,
    /// change with the distance ahead, but their great circles still meet.
    fn bend(&mut self, frame: &mut Frame<'_>) -> Result<(), DetectError> {
        if !self.bend_rows {
            return Ok(());
        }
        let robot_from_camera = frame.prep.calibration().mounting.robot_from_camera();
        let (Some(edge), rows) = self.boundaries.parts_mut() else {
            return Ok(());
        };
        self.chord_rows.clear();
        self.chord_rows.extend_from_slice(rows);
        let bent = self.bend.turn(
            rows,
            edge.sections(),
            edge.assignment(),
            &edge.chains().rays,
            &robot_from_camera,
            NEAR_MIN_SIGMA,
        );
        if bent.is_none() {
            return Ok(());
        }
        let chords = self.agreement(frame, true)?;
        let turned = self.agreement(frame, false)?;
        if turned <= BEND_GAIN * chords {
            self.boundaries.rows.clear();
            self.boundaries.rows.extend_from_slice(&self.chord_rows);
        }
        Ok(())
    }

    /// The share of the rows' support (the chords before the bend, or the turned rows)
    /// that passes through their vanishing point.
    fn agreement(&mut self, frame: &mut Frame<'_>, chords: bool) -> Result<f64, DetectError> {
        let probe = &mut self.probe;
        probe.rows.clear();
        probe.rows.extend_from_slice(if chords {
            &self.chord_rows
        } else {
            &self.boundaries.rows
        });
        frame.vanish.run(None, probe)?;
        let total: f64 = probe.rows.iter().map(|r| r.support as f64).sum();
        let inside: f64 = probe
            .rows
            .iter()
            .zip(frame.vanish.inliers())
            .filter(|(_, &i)| i)
            .map(|(r, _)| r.support as f64)
            .sum();
        Ok(if total > 0.0 { inside / total } else { 0.0 })
    }

    /// The centre lines, each the bisector of two boundaries, refitted on the image's
    /// pixels between them as the Hough rows are (the band: half the row's width at its
    /// foot), and the curved ones turned through their point beside the robot. A bisector of
    /// the boundaries' great circles is not the row's centre line: the boundaries are each
    /// off by their own edge's bias, and the angle halfway between two lines on the ground
    /// is not the line halfway between them.
    fn refit_centre_lines(&mut self, frame: &mut Frame<'_>) -> Result<(), DetectError> {
        let out = &mut *frame.out;
        let Some(vp) = out.vanishing_point.map(|v| v.direction) else {
            return Ok(());
        };
        self.centre_bands.clear();
        self.centre_bands
            .extend(out.rows.iter().map(|r| 0.5 * r.width_rad));
        frame
            .prep
            .refit(&mut out.rows, &self.centre_bands, Some(&vp))?;
        turn_to_feet(out, frame.prep.near_feet());
        Ok(())
    }
}

impl RowMethod for EdgeMethod {
    fn rows(&mut self, frame: &mut Frame<'_>) -> Result<(), DetectError> {
        if frame.fresh {
            let rebuilt = frame.prepared.setup_rebuilt;
            let Some((image, _)) = frame.prep.split() else {
                return Err(DetectError::Buffer(
                    "edge method: the preparer has no setup".into(),
                ));
            };
            self.boundaries.run(&image, rebuilt)?;
            self.bend(frame)?;
        }
        frame.out.rows.extend_from_slice(&self.boundaries.rows);
        support_weights(&frame.out.rows, frame.weights);
        Ok(())
    }

    fn finish(&mut self, frame: &mut Frame<'_>) -> Result<(), DetectError> {
        self.inliers.clear();
        self.inliers.extend_from_slice(frame.vanish.inliers());
        self.refit.run(frame.out, &self.inliers, None, &[]);
        let sin_tol = frame.vanish.params().inlier_deg.to_radians().sin();
        let p = frame.points;
        self.centre
            .publish_detection(frame.out, sin_tol, self.pair_max_rad, &p.rays, &p.weights);
        self.refit_centre_lines(frame)
    }
}
