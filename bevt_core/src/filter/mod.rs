//! Correlation-filter mathematics: label, windows, ADMM training, responses, peaks.
//! Free functions and small solver structs; no tracker state.

pub mod admm;
pub mod label;
pub mod peak;
pub mod response;
pub mod shift;
