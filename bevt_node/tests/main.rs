//! The programs of `bevt_node` as a user runs them (one test binary: each integration test
//! binary links the whole tracker and DDS stack, so one link instead of three).
#![allow(clippy::unwrap_used, clippy::expect_used)] // a failed setup aborts the test

mod common;
mod help;
mod replay_eval_agree;
mod replay_safety;
