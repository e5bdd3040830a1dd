//! The plants' boundary lines of a frame: the edge detector ([`super::edge`], paper II-C)
//! run on the preparation's smoothed vegetation image and mask.
//!
//! Owns [`Boundaries`]: the edge detector, set up for the working image (again whenever the
//! preparation's setup is rebuilt), and its rows, the boundary lines, of the last frame. The
//! stage the edge and the combined methods share.

use super::edge::{EdgeDetector, EdgeError, EdgeOptions, EdgeParams, REFERENCE_MAX_ANGLE_RAD};
use super::prepare::PreparedImage;
use super::types::{DetectError, Row};

impl From<EdgeError> for DetectError {
    fn from(e: EdgeError) -> Self {
        match e {
            EdgeError::Options(m) => DetectError::Options(format!("edge.{m}")),
            EdgeError::Calibration(m) => DetectError::Calibration(m),
            other => DetectError::Buffer(other.to_string()),
        }
    }
}

/// The edge detector of the frames and its last rows.
#[derive(Debug, Clone)]
pub struct Boundaries {
    params: EdgeParams,
    detector: Option<EdgeDetector>,
    /// The boundary lines of the last frame.
    pub rows: Vec<Row>,
}

impl Boundaries {
    /// The stage for the `[detector.edge]` options, its angular scales at `angle_factor`
    /// times their reference values.
    pub fn new(opts: &EdgeOptions, angle_factor: f64) -> Result<Self, DetectError> {
        let params = EdgeParams::from_options(opts, REFERENCE_MAX_ANGLE_RAD * angle_factor);
        params.validate()?;
        Ok(Boundaries {
            params,
            detector: None,
            rows: Vec::with_capacity(64),
        })
    }

    /// Finds the boundary lines on the preparation's last image (`rebuilt`: its setup was
    /// rebuilt for it).
    pub fn run(&mut self, image: &PreparedImage, rebuilt: bool) -> Result<(), DetectError> {
        self.rows.clear();
        let (smoothed, mask, cal) = (image.smoothed, image.mask, image.calibration);
        let (w, h) = (smoothed.width, smoothed.height);
        let stale = match &self.detector {
            None => true,
            Some(e) => rebuilt || e.size() != (w, h),
        };
        if stale {
            self.detector = Some(EdgeDetector::new(cal, w, h, self.params)?);
        }
        let Some(edge) = self.detector.as_mut() else {
            return Err(DetectError::Buffer("edge method: no setup".into()));
        };
        edge.process(&smoothed.data, mask, &mut self.rows)?;
        Ok(())
    }

    /// The edge detector (once it ran) beside the rows it found, the rows to change.
    pub fn parts_mut(&mut self) -> (Option<&EdgeDetector>, &mut Vec<Row>) {
        (self.detector.as_ref(), &mut self.rows)
    }
}
