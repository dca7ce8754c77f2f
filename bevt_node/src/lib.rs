//! # bevt_node: drivers of the BEVT tracker
//!
//! Everything that touches files and the outside world, over the pure [`bevt_core`]:
//! - [`params`]: YAML configuration files and `key=value` overrides.
//! - [`dataset`]: UAV123-style datasets (the `sequences.json` manifest, the official
//!   UAV123 / UAV123_10fps download layout, plain OTB-style folders) and annotation files.
//! - [`runner`]: one-pass evaluation of a sequence (frames decoded on a prefetch thread,
//!   tracking timed alone), partial results kept on failure.
//! - [`report`]: result files, `summary.json`, console tables, comparisons with other
//!   trackers' result folders and per-attribute scores.
//! - [`plots`]: precision and success plots (PNG).
//!
//! The `bevt` binary (`src/bin/bevt.rs`) is a thin command-line layer over these.
#![deny(missing_docs)]

pub mod app;
pub mod convert;
pub mod dataset;
pub mod node_params;
pub mod params;
pub mod plots;
pub mod report;
pub mod ros;
pub mod runner;
pub mod sim;
