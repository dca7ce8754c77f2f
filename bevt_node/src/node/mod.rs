//! The live ROS 2 tracking node: decisions in [`app`], DDS in [`ros`], start-up arguments in
//! [`node_params`] (its table of parameters, [`node_params::NODE_KEYS`]; `docs/configuration.md`
//! from it in [`param_doc`]), its console log lines in [`console`], and the synthetic camera and ground
//! station its tests talk to in [`sim`].

pub mod app;
pub mod console;
pub mod node_params;
pub mod param_doc;
pub mod param_services;
pub mod ros;
pub mod security;
pub mod sim;
