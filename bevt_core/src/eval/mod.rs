//! Evaluation helpers: OPE metrics, synthetic sequences with ground truth, synthetic
//! perturbations of real sequences and leave-one-sequence-out selection.

pub mod lost;
pub mod metrics;
pub mod perturb;
pub mod select;
pub mod synth;
