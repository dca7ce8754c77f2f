//! # bevt_node: the two programs around the BEVT tracker
//!
//! Everything that touches files and the outside world, over the pure [`bevt_core`], grouped
//! by the program it serves:
//! - [`node`]: the live ROS 2 node (`bevt_node`): its logic without DDS ([`node::app`]), the
//!   ros2-client layer ([`node::ros`]), start-up parameters ([`node::node_params`]) and the
//!   DDS synthetic camera / ground station used by the demo, tests and benchmark
//!   ([`node::sim`]).
//! - [`tool`]: the offline `bevt` tool: datasets and annotation files ([`tool::dataset`]),
//!   one-pass evaluation ([`tool::runner`]), result files and tables ([`tool::report`]),
//!   precision/success plots ([`tool::plots`]).
//! - Shared by both: [`convert`] (ROS messages ↔ frames, boxes and detections) and
//!   [`params`] (the tracker's YAML configuration and `key=value` overrides), both read
//!   through [`yaml`] (size and nesting bounded before parsing).
//!
//! The binaries (`src/bin/`) are thin command-line layers: `bevt_node.rs` (the node),
//! `bevt.rs` (the tool), `bevt_latency.rs` (the node's latency benchmark).
#![deny(missing_docs)]

pub mod convert;
pub mod node;
pub mod params;
pub mod tool;
pub mod yaml;
