//! The one integration-test binary: modules by topic.
#![allow(clippy::unwrap_used, clippy::expect_used)] // setup helpers outside #[test] fns

mod bad_input;
#[cfg(feature = "cnn")]
mod cnn;
mod dds_hardening;
mod fastdds_interop;
mod fuzz;
mod interop;
mod lost;
mod node;
mod node_limits;
mod param_flood;
mod rclpy_interop;
mod real_data;
mod replay;
mod ros_tools;
mod security;
mod supervision;
mod synthetic;
mod tool;
mod verifier;
