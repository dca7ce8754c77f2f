//! The offline `bevt` tool: dataset readers ([`dataset`]), the evaluation runner
//! ([`runner`]) and `bevt eval` itself ([`eval`]), leave-one-sequence-out selection over
//! finished evaluations (`bevt select`, [`select`]), result files and tables ([`report`]),
//! plots ([`plots`]), and the replay of recorded flights ([`bag`] reads rosbag2 recordings,
//! [`replay`] runs the node logic over them and writes MCAP for Foxglove); [`pipe`] keeps
//! `bevt ... | head` quiet; [`outputs`] keeps every run from overwriting its inputs or an
//! earlier good output.

pub mod bag;
pub mod dataset;
pub mod eval;
pub mod outputs;
pub mod pipe;
pub mod plots;
pub mod replay;
pub mod report;
pub mod runner;
pub mod select;
