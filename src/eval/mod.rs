//! The paper's evaluation reproduced: Table I (vanishing-point accuracy), figures 8 and 9
//! (row detection rate against plant distance) and Table II (pass/fail per method and lens),
//! plus speed per method, on synthetic images with ground truth; and row guidance on synthetic
//! drives ([`guidance`]).
//!
//! Owns the protocols, the scoring against ground truth, and the Markdown tables and PNG
//! charts (drawn with plotters, [`chart`]) `omnirow eval` writes.

pub mod chart;
pub mod guidance;
pub mod real;
pub mod report;
mod run;
pub mod stats;

pub use run::{
    run, score, AccuracyRow, EvalError, EvalOptions, EvalResults, Experiment, FailureCell, Lens,
    Outcome,
};
