//! The row detector: from one image to rows, their vanishing point, and heading and tilt.
//!
//! Owns the result types every stage shares ([`Row`], [`VanishingPoint`], [`Detection`]).
//! The stages (mask, vegetation, Hough, edge, vanishing point, pose) live in their own files.

pub mod edge;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Which method found a row (or produced a detection).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    Hough,
    Edge,
    Combined,
}

/// A row: the great circle where its plane cuts the unit sphere.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Row {
    /// Unit normal of the row's plane, OCamCalib camera frame. Sign is free.
    pub normal: Vector3<f64>,
    pub method: Method,
    /// Number of image points that support the row.
    pub support: u32,
}

/// The common vanishing point of the rows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VanishingPoint {
    /// Unit direction along the rows, OCamCalib camera frame. Sign is free.
    pub direction: Vector3<f64>,
    /// Number of rows consistent with it.
    pub inliers: usize,
    /// RMS angular distance (radians) of the inlier normals from the plane perpendicular
    /// to the direction.
    pub residual_rad: f64,
}

/// The detector's answer for one image.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Detection {
    pub rows: Vec<Row>,
    pub vanishing_point: Option<VanishingPoint>,
    /// Heading (radians, counter-clockwise from the robot's forward axis) of the rows.
    pub heading_rad: Option<f64>,
    /// Elevation (radians) of the row direction in the robot frame.
    pub tilt_rad: Option<f64>,
    /// Quality in 0..=1 (0 when there is no vanishing point).
    pub quality: f64,
}
