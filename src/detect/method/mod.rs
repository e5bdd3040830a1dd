//! The row-detection methods behind one trait, and the choice of method for a lens.
//!
//! A method turns a frame's prepared points ([`Frame`]: the kept points, the preparer with
//! its smoothed image and refit, the vanishing-point stage) into rows, optionally within a
//! window around the tracker's predicted vanishing point, in two steps around the vote for
//! the vanishing point that the detector runs between them: [`RowMethod::rows`] (the rows
//! and their weights in the vote) and [`RowMethod::finish`] (the method's own refinement of
//! rows and vanishing point once the vote has spoken). A step two methods share is a stage
//! both call (the Hough transform, the edge detector, the refit, the polish, the centre
//! lines), never one method calling into another.
//!
//! The methods: [`hough`] and [`edge`], the paper's two components; [`combined`], the
//! paper's combination (eq. 5), the choice for omnidirectional lenses; [`strips`], the
//! choice for forward-looking perspective cameras; [`pencil`], the choice for a narrow
//! camera looking down. [`choose`] is the rule behind `method = "auto"`.

pub mod combined;
pub mod edge;
pub mod hough;
pub mod pencil;
pub mod strips;

use super::hough::{HoughResult, HoughRows};
use super::prepare::{PrepareResult, Preparer, Refitter};
use super::types::{DetectError, Detection, Method, Points};
use super::vanishing::VanishingStage;
use crate::camera::Mounting;
use nalgebra::Vector3;
use rayon::ThreadPool;
use std::any::Any;

/// What a method works on in one frame.
pub struct Frame<'a> {
    /// The points the preparation kept.
    pub points: &'a Points,
    /// The preparation, with the frame's smoothed vegetation image and the refit on it.
    pub prep: &'a mut Preparer,
    /// What the preparation did (whether its setup was rebuilt for this image).
    pub prepared: PrepareResult,
    /// The vanishing-point stage (its window already set to the frame's).
    pub vanish: &'a mut VanishingStage,
    /// The window around a predicted vanishing point the rows must pass through (unit
    /// direction, camera frame; half-width, radians), if any.
    pub window: Option<(Vector3<f64>, f64)>,
    /// The frame's detection: the method's rows (cleared before it runs), then the vote's
    /// vanishing point and quality, then the method's final answer.
    pub out: &'a mut Detection,
    /// Each row's weight in the vote for the vanishing point (one per row).
    pub weights: &'a mut Vec<f64>,
    /// False when the method already ran on these points (the full search after a narrowed
    /// one): evidence that does not depend on the window (the edge detector's boundaries)
    /// is kept from that run.
    pub fresh: bool,
    /// The threads the frame's independent parts may run on (`None`: this thread alone,
    /// [`join`]).
    pub pool: Option<&'a ThreadPool>,
}

/// Runs `a` and `b`, at once on `pool` when there is one, else one after the other on this
/// thread; their results either way (the same, since they share no state).
pub fn join<A, B, RA, RB>(pool: Option<&ThreadPool>, a: A, b: B) -> (RA, RB)
where
    A: FnOnce() -> RA + Send,
    B: FnOnce() -> RB + Send,
    RA: Send,
    RB: Send,
{
    match pool {
        Some(p) => p.join(a, b),
        None => (a(), b()),
    }
}

/// A row-detection method. As `Any`, a method can be reached as its own type for its
/// diagnostics ([`super::Detector::method_as`]).
pub trait RowMethod: Any + Send + std::fmt::Debug {
    /// Whether the method's search can be narrowed to a window around a predicted
    /// vanishing point; one that cannot always searches everywhere.
    fn narrows(&self) -> bool {
        true
    }

    /// The frame's rows into `frame.out.rows` (cleared by the caller), and each row's
    /// weight in the vote for the vanishing point into `frame.weights`.
    fn rows(&mut self, frame: &mut Frame<'_>) -> Result<(), DetectError>;

    /// After the vote (`frame.out` holds its vanishing point and quality): the method's own
    /// refinement of the rows and the vanishing point.
    fn finish(&mut self, frame: &mut Frame<'_>) -> Result<(), DetectError>;
}

/// Fields of view narrower than this extent (radians, the square root of the solid angle:
/// about a 115° × 115° perspective view) are a perspective camera's.
pub const NARROW_EXTENT_RAD: f64 = 2.0;

/// The method `auto` stands for on a field of view of extent `extent_rad` (the square
/// root of its solid angle, [`crate::detect::scale::AngularResolution`]), mounted as `m`: the
/// strips method for a narrow field of view looking forward (a perspective camera seeing
/// the rows converge ahead, where the strips' peaks lined up through the vanishing point
/// hold on real crop images: docs/real.md), the Hough method for a narrow one looking
/// down (the strips need a horizon), and the paper's combined method for an
/// omnidirectional lens, which sees the rows all around.
pub fn choose(extent_rad: f64, m: &Mounting) -> Method {
    if extent_rad >= NARROW_EXTENT_RAD {
        Method::Combined
    } else if super::strips::looks_forward(m) {
        Method::Strips
    } else {
        Method::Pencil
    }
}

/// The Hough transform's rows of the kept points into `out.rows`, refitted on the image's
/// pixels in wedges towards the vanishing point of the rows as found: the stage the Hough
/// and the combined methods share.
pub fn hough_rows(
    transform: &mut HoughRows,
    points: &Points,
    window: Option<(Vector3<f64>, f64)>,
    vanish: &mut VanishingStage,
    refitter: Option<Refitter<'_>>,
    out: &mut Detection,
) -> Result<HoughResult, DetectError> {
    transform.set_window(window.as_ref().map(|(v, w)| (v, *w)));
    let found = transform.find_rows(&points.rays, &points.weights, &mut out.rows)?;
    // A first vanishing point from the rows shapes the refit's bands.
    vanish.run(None, out)?;
    let vp = out.vanishing_point.map(|v| v.direction);
    if let Some(mut r) = refitter {
        r.refit(&mut out.rows, transform.bands(), vp.as_ref())?;
    }
    Ok(found)
}
