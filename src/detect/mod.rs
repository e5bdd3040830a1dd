//! The row detector: from one image to the crop rows, their vanishing point, and the
//! robot's heading and tilt relative to them.
//!
//! A frame runs through [`Detector`] in order: the preparation ([`prepare`]: the vegetation
//! index, smoothing, the threshold → the kept points), a method's rows ([`method`]: hough,
//! edge, combined, pencil, strips, behind one trait), the vote for their vanishing point
//! ([`vanishing`]), the method's finishing steps, and heading and tilt ([`pose`]).
//!
//! The files are layered: [`types`] at the bottom (the results, the method list, the
//! error) and [`bands`] (rows across the threads); the stages, each in its own file or folder ([`vegetation`], [`mask`],
//! [`smooth`], [`threshold`], [`hough`] — the row Hough transform, [`edge`] — the edge
//! detector, [`refit`] with [`sections`], [`vanishing`], [`pose`], [`prior`], [`centre`],
//! [`chords`], [`combine`], [`strips`], [`scale`]); then [`prepare`], then the stages built
//! on it ([`polish`], [`boundaries`]); then the methods ([`method`]); then [`options`] (the
//! `[detector]` configuration and its resolution for a calibration); [`detector`] on top.
//! Each depends only on the layers below it. [`overlay`] draws a detection.

pub mod bands;
pub mod boundaries;
pub mod centre;
pub mod chords;
pub mod comb;
pub mod combine;
pub mod detector;
pub mod edge;
pub mod hough;
pub mod mask;
pub mod method;
pub mod options;
pub mod overlay;
pub mod pencil;
pub mod polish;
pub mod pose;
pub mod prepare;
pub mod prior;
pub mod refit;
pub mod scale;
pub mod sections;
pub mod smooth;
pub mod strips;
pub mod threshold;
pub mod types;
pub mod vanishing;
pub mod vegetation;

pub use detector::{Detector, PriorOutcome, StageTimes};
pub use options::DetectorOptions;
pub use prepare::Preparer;
pub use prior::DetectorPrior;
#[cfg(test)]
pub(crate) use types::noise_bytes;
pub use types::{DetectError, Detection, GreyImage, Method, Points, Row, VanishingPoint};
