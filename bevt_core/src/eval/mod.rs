//! Evaluation helpers: OPE metrics and synthetic sequences with ground truth.

pub mod lost;
pub mod metrics;
pub mod synth;
