//! The offline `bevt` tool: dataset readers ([`dataset`]), the evaluation runner
//! ([`runner`]), result files and tables ([`report`]) and plots ([`plots`]).

pub mod dataset;
pub mod plots;
pub mod report;
pub mod runner;
