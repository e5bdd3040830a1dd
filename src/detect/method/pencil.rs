//! The pencil method for a narrow camera looking down: rows as the peaks of the
//! vegetation's profile across the pencil of great circles through the vanishing point that
//! makes them sharpest ([`crate::detect::pencil`]), then polished on the image's pixels
//! ([`Polish`]).
//!
//! Owns [`PencilMethod`]: the candidate vanishing points (the profile's sharpest, and the
//! combined method's answer on the same points), the rows read off the profile at each, and
//! the choice among them: the candidate whose contrast times the rows' agreement on a
//! vanishing point is highest.

use super::combined::CombinedMethod;
use super::{Frame, RowMethod};
use crate::camera::Mounting;
use crate::detect::pencil::{
    Candidate, PencilOptions, PencilResult, PencilRows, REFERENCE_POLISH_MAX_BAND_DEG,
};
use crate::detect::polish::Polish;
use crate::detect::types::{DetectError, Detection, Method, Row};
use std::any::Any;

/// The pencil method.
#[derive(Debug)]
pub struct PencilMethod {
    pencil: PencilRows,
    seed: Option<Box<CombinedMethod>>,
    seed_weights: Vec<f64>,
    candidates: Vec<Candidate>,
    best_rows: Vec<Row>,
    polish: Polish,
    /// The polish's widest band around a row (radians).
    max_band_rad: f64,
    last: PencilResult,
}

impl PencilMethod {
    pub fn new(
        opts: PencilOptions,
        seed: Option<CombinedMethod>,
        max_tilt_deg: f64,
        mounting: &Mounting,
        angle_factor: f64,
    ) -> Result<Self, DetectError> {
        Ok(PencilMethod {
            pencil: PencilRows::new(opts, max_tilt_deg, mounting)?,
            seed: seed.map(Box::new),
            seed_weights: Vec::with_capacity(128),
            candidates: Vec::with_capacity(16),
            best_rows: Vec::with_capacity(64),
            polish: Polish::default(),
            max_band_rad: (REFERENCE_POLISH_MAX_BAND_DEG * angle_factor).to_radians(),
            last: PencilResult::default(),
        })
    }

    /// What the search found in the last frame.
    pub fn last(&self) -> PencilResult {
        self.last
    }

    fn seed(&mut self, frame: &mut Frame<'_>, out: &mut Detection) -> Result<(), DetectError> {
        let Some(c) = self.seed.as_mut() else {
            return Ok(());
        };
        c.rows(frame, out, &mut self.seed_weights)?;
        frame.vanish.run(Some(&self.seed_weights), out)?;
        c.finish(frame, out, &self.seed_weights)
    }
}

impl RowMethod for PencilMethod {
    fn method(&self) -> Method {
        Method::Pencil
    }

    fn narrows(&self) -> bool {
        false
    }

    fn rows(
        &mut self,
        frame: &mut Frame<'_>,
        out: &mut Detection,
        weights: &mut Vec<f64>,
    ) -> Result<(), DetectError> {
        self.seed(frame, out)?;
        let seed = out.vanishing_point.map(|v| v.direction);
        out.rows.clear();
        out.boundaries.clear();
        let p = frame.points;
        let scales = self.pencil.prepare(&p.rays, &p.weights, &p.pixel_rad)?;
        self.pencil
            .candidates(&p.rays, &p.weights, seed.as_slice(), &mut self.candidates);
        let mut best: Option<(f64, usize)> = None;
        for k in 0..self.candidates.len() {
            let c = self.candidates[k];
            out.rows.clear();
            self.pencil
                .read_rows(&c.direction, &p.rays, &p.weights, &mut out.rows);
            let r = frame.vanish.run(None, out)?;
            let comb = self
                .pencil
                .last_comb()
                .map_or(0.0, |c| c.comb.contrast)
                .max(0.05);
            let score = c.contrast * r.quality * comb.powf(self.pencil.options().comb_power);
            if best.map_or(true, |b| score > b.0) {
                best = Some((score, k));
                self.best_rows.clear();
                self.best_rows.extend_from_slice(&out.rows);
            }
        }
        out.rows.clear();
        self.last = PencilResult {
            scales,
            evaluated: self.pencil.evaluated(),
            ..PencilResult::default()
        };
        if let Some((_, k)) = best {
            let c = self.candidates[k];
            out.rows.extend_from_slice(&self.best_rows);
            self.last.direction = Some(c.direction);
            self.last.contrast = c.contrast;
            self.last.rows = out.rows.len();
        }
        weights.clear();
        weights.extend(out.rows.iter().map(|r| r.support as f64));
        Ok(())
    }

    fn finish(
        &mut self,
        frame: &mut Frame<'_>,
        out: &mut Detection,
        _weights: &[f64],
    ) -> Result<(), DetectError> {
        if self.pencil.options().polish {
            self.polish
                .run(frame.prep, frame.vanish, out, self.max_band_rad)?;
        }
        Ok(())
    }

    fn as_any(&self) -> &dyn Any {
        self
    }

    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}
