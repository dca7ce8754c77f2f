//! Start-up configuration of the ROS node: `ros2 run`-compatible arguments
//! (`--ros-args --params-file FILE -p name:=value -r from:=to -r __ns:=/ns -r __node:=name`),
//! the standard parameters-file format (`bevt_node: ros__parameters: {...}` or `/**:`), and
//! the `ROS_DOMAIN_ID` / `ROS_LOCALHOST_ONLY` environment variables (which ros2-client
//! itself ignores), and DDS Security as ROS 2 configures it (`--enclave`/`-e`,
//! `ROS_SECURITY_ENABLE`, `ROS_SECURITY_STRATEGY`, `ROS_SECURITY_KEYSTORE`,
//! `ROS_SECURITY_ENCLAVE_OVERRIDE`; see [`crate::node::security`]).
//!
//! Parameters (see `config/node.yaml`, where each one's range is given): `domain_id`,
//! `network_interfaces` (IPv4 addresses the node listens and sends on; `["0.0.0.0"]` = all;
//! `[]` is an error; default loopback only), `dds_max_sample_bytes`, `service_mapping`
//! (`enhanced` | `cyclone`), `max_image_width`, `max_image_height`, `max_image_pixels`,
//! `reinit_buffer_frames`, `reinit_buffer_mb`, `reinit_max_fast_forward`,
//! `reinit_rate_hz`, `reinit_burst`, `stale_timeout_s`, `diagnostics_period_s`,
//! `debug_image_rate_hz` (0 = off), `class_id`, `security_keystore` (a keystore path:
//! security on, strategy Enforce), `security_enclave` (default `/`; `--enclave` wins), and
//! every tracker key as
//! `tracker.<section>.<key>` (as in `config/bevt.yaml`, ranges in
//! `TrackerConfig::validate`). Every number has a range that bounds the work and memory
//! it implies ([`NODE_KEYS`]); unknown parameters and values outside a range stop start-up
//! with a message naming the parameter and its range.

use crate::node::app::NodeSettings;
use crate::node::ros::RosSettings;
use crate::node::security::{SecurityError, SecurityOptions, Strategy};
use crate::params::load_config;
use bevt_core::TrackerSpec;
use ros2_client::ServiceMapping;
use serde_norway::Value;
use std::collections::BTreeMap;
use std::net::IpAddr;
use std::time::Duration;
use thiserror::Error;

/// A start-up error.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum LaunchError {
    /// Bad command line.
    #[error("command line: {0}")]
    Args(String),
    /// Bad parameters file or parameter.
    #[error("parameter {name}: {reason}")]
    Param {
        /// Parameter name.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// Tracker configuration error.
    #[error("tracker parameters: {0}")]
    Tracker(#[from] crate::params::ParamsError),
    /// DDS Security is enforced but not usable.
    #[error("{0}")]
    Security(#[from] SecurityError),
    /// A model the tracker configuration names cannot be loaded.
    #[error("tracker models: {0}")]
    Models(String),
}

/// Everything the node needs to start.
#[derive(Debug, Clone)]
pub struct Launch {
    /// ROS layer settings.
    pub ros: RosSettings,
    /// Node logic settings.
    pub node: NodeSettings,
    /// Tracker specification.
    pub tracker: TrackerSpec,
    /// Run the built-in demo (synthetic camera + ground station).
    pub demo: bool,
    /// Demo duration.
    pub demo_duration: Duration,
}

/// What a node parameter holds (its ROS type).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NodeType {
    /// `bool`.
    Bool,
    /// `integer`.
    Integer,
    /// `double`.
    Double,
    /// `string`.
    String,
    /// `string[]`.
    StringArray,
}

impl NodeType {
    /// The type's name in the documentation.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Bool => "bool",
            Self::Integer => "integer",
            Self::Double => "double",
            Self::String => "string",
            Self::StringArray => "string[]",
        }
    }
}

/// The values a node parameter accepts, as far as a range can say.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum NodeRange {
    /// Any value of its type that the code accepts (see [`NodeKey::cross`]).
    Any,
    /// Integers `lo..=hi`.
    Int(u64, u64),
    /// Finite reals `lo..=hi`.
    Real(f64, f64),
    /// 0 (off) or a finite real `lo..=hi`.
    OffOr(f64, f64),
    /// Text of `lo..=hi` characters.
    Chars(u64, u64),
    /// One of these names.
    Choice(&'static [&'static str]),
    /// Exactly this value.
    Fixed(&'static str),
}

/// One node parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NodeKey {
    /// Name (`-p name:=value`).
    pub name: &'static str,
    /// ROS type.
    pub ty: NodeType,
    /// The range the start-up check enforces from this table.
    pub range: NodeRange,
    /// Other conditions, checked by code, in words ("" when none).
    pub cross: &'static str,
    /// Unit ("" when none).
    pub unit: &'static str,
    /// Takes effect while running (`ros2 param set`).
    pub live: bool,
    /// Declared by the parameter services (the `security_*` ones are start-up only).
    pub served: bool,
    /// The default in words when it is not simply the value of a node started without
    /// parameters ("" = that value).
    pub default: &'static str,
    /// What it does.
    pub doc: &'static str,
}

impl NodeKey {
    /// The range in words ("0.01..=100 Hz").
    pub fn range_words(&self) -> String {
        self.range_words_in(self.unit)
    }

    /// [`Self::range_words`] with the unit written as `unit` ("" = none).
    pub fn range_words_in(&self, unit_text: &str) -> String {
        let unit = |s: String| {
            if unit_text.is_empty() {
                s
            } else {
                format!("{s} {unit_text}")
            }
        };
        match self.range {
            NodeRange::Any => String::new(),
            NodeRange::Int(lo, hi) => unit(format!("{lo}..={hi}")),
            NodeRange::Real(lo, hi) => unit(format!("{lo}..={hi}")),
            NodeRange::OffOr(lo, hi) => unit(format!("0 (off) or {lo}..={hi}")),
            NodeRange::Chars(lo, hi) => format!("{lo}..={hi} characters"),
            NodeRange::Choice(c) => c.join(" | "),
            NodeRange::Fixed(v) => v.to_string(),
        }
    }

    /// The accepted values in words: the range and the other conditions.
    pub fn constraints(&self) -> String {
        self.constraints_in(self.unit)
    }

    /// [`Self::constraints`] with the unit written as `unit` ("" = none).
    pub fn constraints_in(&self, unit: &str) -> String {
        match (self.range_words_in(unit), self.cross) {
            (w, "") => w,
            (w, c) if w.is_empty() => c.to_string(),
            (w, c) => format!("{w}; {c}"),
        }
    }

    /// `(from, to)` for a ROS `IntegerRange` / `FloatingPointRange`.
    pub fn bounds(&self) -> Option<(f64, f64)> {
        match self.range {
            NodeRange::Int(lo, hi) => Some((lo as f64, hi as f64)),
            NodeRange::Real(lo, hi) => Some((lo, hi)),
            _ => None,
        }
    }
}

/// The node parameter `name`.
///
/// # Panics
/// When `name` is not in [`NODE_KEYS`] (a test runs every lookup the start-up makes).
#[allow(clippy::panic)]
pub fn node_key(name: &str) -> &'static NodeKey {
    match NODE_KEYS.iter().find(|k| k.name == name) {
        Some(k) => k,
        None => panic!("node parameter {name} is not in NODE_KEYS"),
    }
}

/// The integer range of `name` in the table.
fn int_range(name: &str) -> (u64, u64) {
    match node_key(name).range {
        NodeRange::Int(lo, hi) | NodeRange::Chars(lo, hi) => (lo, hi),
        _ => (0, u64::MAX),
    }
}

/// The real range of `name` in the table.
fn real_range(name: &str) -> (f64, f64) {
    match node_key(name).range {
        NodeRange::Real(lo, hi) | NodeRange::OffOr(lo, hi) => (lo, hi),
        _ => (f64::MIN, f64::MAX),
    }
}

const LIVE: bool = true;
const FIXED: bool = false;

const fn nk(
    name: &'static str,
    ty: NodeType,
    range: NodeRange,
    unit: &'static str,
    live: bool,
    doc: &'static str,
) -> NodeKey {
    NodeKey {
        name,
        ty,
        range,
        cross: "",
        unit,
        live,
        served: true,
        default: "",
        doc,
    }
}

/// Every node parameter (besides the tracker keys, `tracker.<section>.<key>`).
#[rustfmt::skip]
pub static NODE_KEYS: &[NodeKey] = &[
    NodeKey { default: "unset: `ROS_DOMAIN_ID`, else 0",
        ..nk("domain_id", NodeType::Integer, NodeRange::Int(0, 232), "", FIXED,
        "DDS domain (ROS_DOMAIN_ID when unset).") },
    NodeKey { cross: "IPv4 addresses; [\"0.0.0.0\"] alone = all interfaces; [] is an error; ROS_LOCALHOST_ONLY=1 sets loopback",
        ..nk("network_interfaces", NodeType::StringArray, NodeRange::Any, "", FIXED,
        "IPv4 addresses DDS listens and sends on; [\"0.0.0.0\"] = all interfaces.") },
    NodeKey { cross: ">= 4 B × max_image_pixels + 65536 B",
        ..nk("dds_max_sample_bytes", NodeType::Integer, NodeRange::Int(64 << 10, 512 << 20), "B", FIXED,
        "Largest DDS sample reassembled from fragments, bytes: at least the largest image message.") },
    nk("service_mapping", NodeType::String, NodeRange::Choice(&["enhanced", "cyclone"]), "", FIXED,
        "Service wire mapping: enhanced (Fast DDS, rmw_fastrtps) or cyclone (rmw_cyclonedds)."),
    nk("image_transport", NodeType::String, NodeRange::Choice(&["raw", "compressed", "both"]), "", FIXED,
        "Camera input subscribed, as image_transport's parameter: raw (image_raw), compressed (image_raw/compressed) or both (a camera publishing both then delivers every frame twice)."),
    nk("max_image_width", NodeType::Integer, NodeRange::Int(16, 32768), "px", FIXED,
        "Widest camera frame accepted, pixels (larger frames are refused before decoding)."),
    nk("max_image_height", NodeType::Integer, NodeRange::Int(16, 32768), "px", FIXED,
        "Tallest camera frame accepted, pixels."),
    nk("max_image_pixels", NodeType::Integer, NodeRange::Int(256, 64 << 20), "px", FIXED,
        "Most pixels of a camera frame accepted (bounds decoder memory)."),
    nk("reinit_buffer_frames", NodeType::Integer, NodeRange::Int(1, 1000), "frames", FIXED,
        "Recent frames kept for delayed re-initialisation."),
    NodeKey { cross: ">= 4 B × max_image_pixels",
        ..nk("reinit_buffer_mb", NodeType::Integer, NodeRange::Int(1, 4096), "MiB", FIXED,
        "Memory of the re-initialisation buffer, MiB.") },
    nk("reinit_max_fast_forward", NodeType::Integer, NodeRange::Int(0, 100), "frames", LIVE,
        "Most buffered frames one re-initialisation tracks through to the newest."),
    nk("reinit_rate_hz", NodeType::Double, NodeRange::Real(0.01, 100.0), "Hz", LIVE,
        "Re-initialisation requests admitted per second (token bucket refill)."),
    nk("reinit_burst", NodeType::Integer, NodeRange::Int(1, 100), "requests", LIVE,
        "Re-initialisation requests admitted at once (token bucket depth)."),
    nk("stale_timeout_s", NodeType::Double, NodeRange::Real(0.05, 3600.0), "s", LIVE,
        "No image for this long while tracking: the status says the camera is stale, seconds."),
    nk("diagnostics_period_s", NodeType::Double, NodeRange::Real(0.01, 3600.0), "s", LIVE,
        "Period of /diagnostics, seconds."),
    nk("debug_image_rate_hz", NodeType::Double, NodeRange::OffOr(0.01, 100.0), "Hz", LIVE,
        "Rate of the debug_image topic (the frame with the box drawn), Hz; 0 = off."),
    NodeKey { cross: "no control characters",
        ..nk("class_id", NodeType::String, NodeRange::Chars(1, 256), "", LIVE,
        "class_id of the published detections.") },
    nk("use_sim_time", NodeType::Bool, NodeRange::Fixed("false"), "", FIXED,
        "Not supported: the node stamps with wall-clock time (always false)."),
    NodeKey { served: false, default: "unset", cross: "a keystore directory",
        ..nk("security_keystore", NodeType::String, NodeRange::Any, "", FIXED,
        "DDS Security on, strategy Enforce (docs/security.md); unset: the ROS_SECURITY_* variables. Start-up only, not served as a ROS parameter.") },
    NodeKey { served: false, default: "`/`", cross: "an enclave path",
        ..nk("security_enclave", NodeType::String, NodeRange::Any, "", FIXED,
        "Identity in the keystore; --enclave wins. Start-up only, not served as a ROS parameter.") },
];

/// `bevt_node --demo --duration`: seconds (a command-line option, not a parameter).
const DEMO_DURATION_S: (f64, f64) = (0.1, 86400.0);

/// Bytes in a MiB.
const MIB: u64 = 1 << 20;

/// `v` as a number of seconds within `range`.
fn seconds(name: &str, v: f64, range: (f64, f64)) -> Result<Duration, LaunchError> {
    let v = float_in(name, v, range, "s")?;
    Duration::try_from_secs_f64(v).map_err(|e| param_err(name, e.to_string()))
}

fn float_in(name: &str, v: f64, (lo, hi): (f64, f64), unit: &str) -> Result<f64, LaunchError> {
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        Err(param_err(
            name,
            format!("{v} is outside {lo}..={hi} {unit}"),
        ))
    }
}

fn int_in(name: &str, v: &Value, (lo, hi): (u64, u64)) -> Result<u64, LaunchError> {
    v.as_u64()
        .filter(|n| (lo..=hi).contains(n))
        .ok_or_else(|| param_err(name, format!("expected an integer {lo}..={hi}")))
}

fn param_err(name: &str, reason: impl Into<String>) -> LaunchError {
    LaunchError::Param {
        // The name may come from a request: clipped and escaped before it is echoed.
        name: crate::node::console::printable(name, crate::node::console::MAX_NAME_CHARS),
        reason: reason.into(),
    }
}

/// Flattens a YAML mapping into dotted names.
fn flatten(prefix: &str, v: &Value, out: &mut BTreeMap<String, Value>) {
    match v {
        Value::Mapping(m) => {
            for (k, v) in m {
                let k = match k {
                    Value::String(s) => s.clone(),
                    other => format!("{other:?}"),
                };
                let name = if prefix.is_empty() {
                    k
                } else {
                    format!("{prefix}.{k}")
                };
                flatten(&name, v, out);
            }
        }
        other => {
            out.insert(prefix.to_string(), other.clone());
        }
    }
}

/// Reads `ros__parameters` for `node_name` (or `/**`) from a parameters file's text.
pub fn params_from_file(
    text: &str,
    node_name: &str,
) -> Result<BTreeMap<String, Value>, LaunchError> {
    let doc: Value =
        crate::yaml::parse(text, "--params-file").map_err(|e| param_err("--params-file", e))?;
    let mut out = BTreeMap::new();
    let Value::Mapping(top) = &doc else {
        return Err(param_err(
            "--params-file",
            "expected `node_name: ros__parameters: {...}`",
        ));
    };
    for (k, v) in top {
        let key = k.as_str().unwrap_or_default().trim_start_matches('/');
        if key == "**" || key == node_name || key.ends_with(&format!("/{node_name}")) {
            let params = v
                .get("ros__parameters")
                .ok_or_else(|| param_err(key, "missing ros__parameters"))?;
            flatten("", params, &mut out);
        }
    }
    Ok(out)
}

/// What `bevt_node --help` prints.
pub const USAGE: &str = "\
bevt_node: the BEVT-rs ROS 2 tracking node (pure Rust: ros2-client over RustDDS)

Usage:
  ros2 run bevt_node bevt_node [--ros-args ARGS...]
  bevt_node --demo [--duration SECONDS]
  bevt_node --help | -h

Node options:
  --demo              run with an in-process synthetic camera and a simulated ground station
                      that initialises the track; prints the track once per second
  --duration S        how long the demo runs (default 10 s)
  -h, --help          print this and exit

ROS arguments (after --ros-args, as rcl takes them):
  --params-file FILE  a ROS 2 parameters file (bevt_node: ros__parameters: ...); repeatable
  -p NAME:=VALUE      one parameter (node parameters and tracker.* keys); repeatable
  -r FROM:=TO         a topic remap, or __ns:=/ns, __node:=name; repeatable
  -e, --enclave PATH  the DDS Security enclave (with ROS_SECURITY_ENABLE=true)
  --log-level LEVEL   lowest severity logged (console and /rosout): debug, info (default),
                      warn, error or fatal; also NODE_NAME:=LEVEL

Environment: ROS_DOMAIN_ID, ROS_SECURITY_ENABLE, ROS_SECURITY_STRATEGY,
ROS_SECURITY_KEYSTORE, ROS_SECURITY_ENCLAVE_OVERRIDE.
Parameters, topics and services: docs/ros.md and docs/configuration.md.
";

/// Whether the command line asks for the usage text: `-h` or `--help` among the node's own
/// arguments (before `--ros-args`).
pub fn wants_help(args: &[String]) -> bool {
    args.iter()
        .take_while(|a| a.as_str() != "--ros-args")
        .any(|a| a == "-h" || a == "--help")
}

/// The command line, parsed but not yet interpreted.
#[derive(Default)]
struct CommandLine {
    demo: bool,
    demo_duration: Option<Duration>,
    /// `--params-file` paths, in order.
    files: Vec<String>,
    /// `-p name:=value`, in order.
    sets: Vec<(String, String)>,
    /// `-r from:=to`, in order.
    remaps: Vec<(String, String)>,
    /// `--enclave PATH` (or `-e`).
    enclave: Option<String>,
    /// `--log-level [LOGGER:=]LEVEL`, in order.
    log_levels: Vec<(Option<String>, ros2_client::log::LogLevel)>,
}

/// Splits the arguments into the node's own (`--demo`, `--duration`) and the
/// `--ros-args` ones.
fn parse_command_line(args: &[String]) -> Result<CommandLine, LaunchError> {
    let mut cl = CommandLine::default();
    let mut it = args.iter();
    let mut ros = false;
    while let Some(a) = it.next() {
        let mut next = |what: &str| {
            it.next()
                .cloned()
                .ok_or_else(|| LaunchError::Args(format!("{what} needs a value")))
        };
        match a.as_str() {
            "--ros-args" => ros = true,
            "--" => ros = false,
            "--demo" if !ros => cl.demo = true,
            "--duration" if !ros => {
                let v = next("--duration")?;
                let s: f64 = v
                    .parse()
                    .map_err(|_| LaunchError::Args(format!("--duration {v:?}: not a number")))?;
                cl.demo_duration = Some(seconds("--duration", s, DEMO_DURATION_S)?);
            }
            "--params-file" if ros => cl.files.push(next("--params-file")?),
            "-p" | "--param" if ros => {
                let v = next("-p")?;
                let (k, val) = v
                    .split_once(":=")
                    .ok_or_else(|| LaunchError::Args(format!("-p {v:?}: expected name:=value")))?;
                cl.sets.push((k.to_string(), val.to_string()));
            }
            "-r" | "--remap" if ros => {
                let v = next("-r")?;
                let (k, val) = v
                    .split_once(":=")
                    .ok_or_else(|| LaunchError::Args(format!("-r {v:?}: expected from:=to")))?;
                cl.remaps.push((k.to_string(), val.to_string()));
            }
            "--log-level" if ros => {
                let v = next("--log-level")?;
                cl.log_levels
                    .push(crate::node::console::parse_log_level(&v).map_err(LaunchError::Args)?);
            }
            "--enclave" | "-e" if ros => cl.enclave = Some(next("--enclave")?),
            other => return Err(LaunchError::Args(format!("unknown argument {other:?}"))),
        }
    }
    Ok(cl)
}

/// Reads the parameters files in order, then the `-p` overrides on top.
fn collect_params(
    files: &[String],
    sets: Vec<(String, String)>,
    node_name: &str,
) -> Result<BTreeMap<String, Value>, LaunchError> {
    let mut params = BTreeMap::new();
    for f in files {
        let text = crate::yaml::read_file(std::path::Path::new(f))
            .map_err(|e| param_err("--params-file", e))?;
        params.extend(params_from_file(&text, node_name)?);
    }
    for (k, v) in sets {
        let val: Value = crate::yaml::parse(&v, "value").map_err(|e| param_err(&k, e))?;
        params.insert(k, val);
    }
    Ok(params)
}

/// `ROS_DOMAIN_ID` and `ROS_LOCALHOST_ONLY` (parameters override them).
fn apply_env(
    env: impl Fn(&str) -> Option<String>,
    ros_settings: &mut RosSettings,
) -> Result<(), LaunchError> {
    if let Some(d) = env("ROS_DOMAIN_ID").filter(|s| !s.trim().is_empty()) {
        ros_settings.domain_id = d
            .trim()
            .parse()
            .ok()
            .filter(|v: &u16| *v <= 232)
            .ok_or_else(|| {
                param_err("ROS_DOMAIN_ID", format!("{d:?} is not a domain id 0..=232"))
            })?;
    }
    if env("ROS_LOCALHOST_ONLY").as_deref() == Some("1") {
        ros_settings.networks = vec![IpAddr::from([127, 0, 0, 1])];
    }
    Ok(())
}

/// Takes the `security_keystore` and `security_enclave` parameters out of `params`: a
/// keystore named in the configuration turns security on with strategy Enforce.
fn apply_security_params(
    params: &mut BTreeMap<String, Value>,
    security: &mut SecurityOptions,
) -> Result<(), LaunchError> {
    let mut text = |k: &str| -> Result<Option<String>, LaunchError> {
        params
            .remove(k)
            .map(|v| {
                v.as_str()
                    .filter(|s| !s.is_empty())
                    .map(str::to_string)
                    .ok_or_else(|| param_err(k, "expected a non-empty path"))
            })
            .transpose()
    };
    if let Some(ks) = text("security_keystore")? {
        security.enable = true;
        security.strategy = Strategy::Enforce;
        security.keystore = Some(ks.into());
    }
    if let Some(e) = text("security_enclave")? {
        security.enclave = e;
    }
    Ok(())
}

/// The `network_interfaces` parameter: IPv4 addresses, not empty, `0.0.0.0` alone.
fn parse_networks(k: &str, v: &Value) -> Result<Vec<IpAddr>, LaunchError> {
    let list = v
        .as_sequence()
        .ok_or_else(|| param_err(k, "expected a list of addresses"))?;
    let networks: Vec<IpAddr> = list
        .iter()
        .map(|a| {
            a.as_str()
                .and_then(|s| s.parse::<IpAddr>().ok())
                .filter(IpAddr::is_ipv4)
                .ok_or_else(|| param_err(k, format!("{a:?} is not an IPv4 address")))
        })
        .collect::<Result<_, _>>()?;
    if networks.is_empty() {
        return Err(param_err(
            k,
            "empty: list the addresses to listen on (\"0.0.0.0\" = all interfaces)",
        ));
    }
    if networks.len() > 1 && networks.iter().any(IpAddr::is_unspecified) {
        return Err(param_err(
            k,
            "0.0.0.0 (all interfaces) cannot be combined with other addresses",
        ));
    }
    Ok(networks)
}

/// Applies one node parameter to the settings; `tracker.*` ones are collected as
/// `key=value` overrides for [`load_config`].
fn apply_param(
    k: &str,
    v: &Value,
    ros_settings: &mut RosSettings,
    node: &mut NodeSettings,
    tracker_sets: &mut Vec<String>,
) -> Result<(), LaunchError> {
    let as_f64 = || v.as_f64().ok_or_else(|| param_err(k, "expected a number"));
    match k {
        "domain_id" => {
            ros_settings.domain_id = u16::try_from(int_in(k, v, int_range(k))?)
                .map_err(|e| param_err(k, e.to_string()))?
        }
        "network_interfaces" => ros_settings.networks = parse_networks(k, v)?,
        "dds_max_sample_bytes" => {
            ros_settings.max_sample_bytes = int_in(k, v, int_range(k))? as usize
        }
        "service_mapping" => {
            ros_settings.service_mapping = match v.as_str() {
                Some("enhanced") => ServiceMapping::Enhanced,
                Some("cyclone") => ServiceMapping::Cyclone,
                _ => {
                    return Err(param_err(
                        k,
                        format!("expected {}", node_key(k).range_words()),
                    ))
                }
            }
        }
        "image_transport" => {
            ros_settings.image_transport = v
                .as_str()
                .and_then(crate::node::ros::ImageTransport::parse)
                .ok_or_else(|| param_err(k, format!("expected {}", node_key(k).range_words())))?
        }
        "max_image_width" => node.image_limits.max_width = int_in(k, v, int_range(k))? as u32,
        "max_image_height" => node.image_limits.max_height = int_in(k, v, int_range(k))? as u32,
        "max_image_pixels" => node.image_limits.max_pixels = int_in(k, v, int_range(k))?,
        "reinit_buffer_frames" => node.reinit_buffer_frames = int_in(k, v, int_range(k))? as usize,
        "reinit_buffer_mb" => {
            node.reinit_buffer_bytes = (int_in(k, v, int_range(k))? * MIB) as usize
        }
        "reinit_max_fast_forward" => {
            node.reinit_max_fast_forward = int_in(k, v, int_range(k))? as usize
        }
        "reinit_rate_hz" => {
            node.reinit_rate_hz = float_in(k, as_f64()?, real_range(k), node_key(k).unit)?
        }
        "reinit_burst" => node.reinit_burst = int_in(k, v, int_range(k))? as u32,
        "stale_timeout_s" => node.stale_timeout = seconds(k, as_f64()?, real_range(k))?,
        "diagnostics_period_s" => {
            ros_settings.diagnostics_period = seconds(k, as_f64()?, real_range(k))?
        }
        "debug_image_rate_hz" => {
            let r = as_f64()?;
            ros_settings.debug_image_rate_hz = if r == 0.0 {
                0.0
            } else {
                float_in(k, r, real_range(k), "Hz (or 0 = off)")?
            };
        }
        "class_id" => {
            let c = v
                .as_str()
                .ok_or_else(|| param_err(k, "expected a string"))?;
            let (lo, hi) = int_range(k);
            if !(lo..=hi).contains(&(c.chars().count() as u64)) {
                return Err(param_err(k, format!("expected {lo}..={hi} characters")));
            }
            if c.chars().any(char::is_control) {
                return Err(param_err(
                    k,
                    "control characters (newlines, escapes) are not allowed",
                ));
            }
            node.class_id = c.to_string();
        }
        name if name.starts_with("tracker.") => {
            let text = serde_norway::to_string(v).map_err(|e| param_err(k, e.to_string()))?;
            tracker_sets.push(format!("{}={}", &name["tracker.".len()..], text.trim()));
        }
        _ => return Err(param_err(k, "unknown parameter")),
    }
    Ok(())
}

/// Checks that one largest frame fits the re-initialisation buffer and one largest raw
/// image message fits a DDS sample.
fn check_size_limits(ros_settings: &RosSettings, node: &NodeSettings) -> Result<(), LaunchError> {
    let frame_bytes = node
        .image_limits
        .max_pixels
        .saturating_mul(crate::convert::MAX_FRAME_BYTES_PER_PIXEL);
    if (node.reinit_buffer_bytes as u64) < frame_bytes {
        return Err(param_err(
            "reinit_buffer_mb",
            format!(
                "{} MiB cannot hold one largest frame ({} MiB = 4 bytes × max_image_pixels {})",
                node.reinit_buffer_bytes as u64 / MIB,
                frame_bytes.div_ceil(MIB),
                node.image_limits.max_pixels
            ),
        ));
    }
    let message_bytes = frame_bytes.saturating_add(crate::node::ros::SAMPLE_OVERHEAD_BYTES as u64);
    if (ros_settings.max_sample_bytes as u64) < message_bytes {
        return Err(param_err(
            "dds_max_sample_bytes",
            format!(
                "{} bytes cannot hold one largest image message ({message_bytes} = 4 bytes × \
                 max_image_pixels {} + {} KiB)",
                ros_settings.max_sample_bytes,
                node.image_limits.max_pixels,
                crate::node::ros::SAMPLE_OVERHEAD_BYTES / 1024
            ),
        ));
    }
    Ok(())
}

/// Builds the launch configuration from arguments (without the program name) and the
/// environment lookup `env`.
///
/// # Errors
/// [`LaunchError`] naming the argument or parameter at fault.
pub fn launch_from_args(
    args: &[String],
    env: impl Fn(&str) -> Option<String>,
) -> Result<Launch, LaunchError> {
    let cl = parse_command_line(args)?;
    let mut ros_settings = RosSettings::default();
    let mut node = NodeSettings::default();
    let mut topic_remaps = Vec::new();
    for (from, to) in cl.remaps {
        match from.as_str() {
            "__ns" => ros_settings.namespace = to,
            "__node" | "__name" => ros_settings.node_name = to,
            _ => topic_remaps.push((from, to)),
        }
    }
    ros_settings.remaps = topic_remaps;
    node.node_name = ros_settings.node_name.clone();
    // As rcl: a bare level sets the default logger (the node's); `NAME:=LEVEL` sets the logger
    // of that name, which here is only the node's own (it has no other loggers).
    for (logger, level) in cl.log_levels {
        if logger.is_none_or(|l| l == ros_settings.node_name) {
            ros_settings.log_level = level;
        }
    }
    let mut params = collect_params(&cl.files, cl.sets, &ros_settings.node_name)?;
    // Environment first, parameters override it.
    let mut security = SecurityOptions::from_env(&env, None);
    apply_security_params(&mut params, &mut security)?;
    if let Some(e) = cl.enclave {
        security.enclave = e;
    }
    apply_env(env, &mut ros_settings)?;
    let mut tracker_sets = Vec::new();
    for (k, v) in &params {
        apply_param(k, v, &mut ros_settings, &mut node, &mut tracker_sets)?;
    }
    check_size_limits(&ros_settings, &node)?;
    let tracker = load_config(None, &tracker_sets)?;
    // A bad model path must stop start-up, not refuse every later initialisation.
    bevt_core::BevtTracker::check_models(&tracker)
        .map_err(|e| LaunchError::Models(e.to_string()))?;
    if cl.demo && security.enable {
        return Err(LaunchError::Args(
            "--demo runs unsecured (its in-process camera and ground station have no DDS \
             identities): unset ROS_SECURITY_ENABLE and security_keystore"
                .into(),
        ));
    }
    ros_settings.security = security.resolve()?;
    Ok(Launch {
        ros: ros_settings,
        node,
        tracker,
        demo: cl.demo,
        demo_duration: cl.demo_duration.unwrap_or(Duration::from_secs(10)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(s: &str) -> Vec<String> {
        s.split_whitespace().map(String::from).collect()
    }

    #[test]
    fn log_level_sets_the_node_threshold_and_refuses_unknown_levels() {
        use ros2_client::log::LogLevel;
        let none = |_: &str| None;
        let l = launch_from_args(&args("--ros-args --log-level warn"), none).unwrap();
        assert_eq!(l.ros.log_level, LogLevel::Warn);
        assert_eq!(
            launch_from_args(&args("--ros-args"), none)
                .unwrap()
                .ros
                .log_level,
            LogLevel::Info
        );
        // A named logger: the node's own name applies, another logger's does not.
        let l = launch_from_args(
            &args(
                "--ros-args -r __node:=tracker --log-level tracker:=error --log-level rcl:=debug",
            ),
            none,
        )
        .unwrap();
        assert_eq!(l.ros.log_level, LogLevel::Error);
        let e = launch_from_args(&args("--ros-args --log-level loud"), none).unwrap_err();
        assert!(e.to_string().contains("--log-level"), "{e}");
        assert!(launch_from_args(&args("--ros-args --log-level"), none).is_err());
    }

    #[test]
    fn a_bad_verifier_model_stops_start_up_naming_its_key() {
        let dir = std::env::temp_dir().join(format!("bevt_models_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let not_onnx = dir.join("not_onnx.onnx");
        std::fs::write(&not_onnx, b"this is not a network").unwrap();
        for (key, path) in [
            ("verifier_backbone", dir.join("missing.onnx")),
            ("verifier_head", not_onnx.clone()),
        ] {
            let args = vec![
                "--ros-args".to_string(),
                "-p".to_string(),
                format!("tracker.redetection.{key}:={}", path.display()),
            ];
            let e = launch_from_args(&args, |_| None).err().unwrap().to_string();
            assert!(e.contains(&format!("redetection.{key}")), "{e}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn hostile_names_and_class_ids_are_clipped_escaped_or_refused() {
        let args = |p: &str| vec!["--ros-args".to_string(), "-p".to_string(), p.to_string()];
        let long = format!("{}:=1", "n".repeat(120_000));
        let e = launch_from_args(&args(&long), |_| None)
            .err()
            .unwrap()
            .to_string();
        assert!(e.len() < 400, "{} characters echoed", e.len());
        assert!(
            e.contains("more characters") && e.contains("unknown parameter"),
            "{e}"
        );
        let e = launch_from_args(&args("bad\nname:=1"), |_| None)
            .err()
            .unwrap()
            .to_string();
        assert!(!e.contains('\n'), "{e}");
        // A double-quoted YAML value carries a real newline (as a set_parameters string does).
        let e = launch_from_args(&args("class_id:=\"a\\n[INFO] forged\""), |_| None)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("control characters"), "{e}");
    }

    #[test]
    fn enclave_argument_security_parameters_and_environment_are_applied() {
        use crate::node::security::DdsSecurity;
        // Off by default, with the reason for the warning.
        let l = launch_from_args(&[], |_| None).unwrap();
        assert!(matches!(l.ros.security, DdsSecurity::Off { .. }));
        // `--enclave` and `-e` are ROS arguments only.
        assert!(matches!(
            launch_from_args(&args("--enclave /bevt_node"), |_| None),
            Err(LaunchError::Args(_))
        ));
        let enforce = |k: &str| match k {
            "ROS_SECURITY_ENABLE" => Some("true".to_string()),
            "ROS_SECURITY_STRATEGY" => Some("Enforce".to_string()),
            _ => None,
        };
        let e = launch_from_args(&args("--ros-args --enclave /bevt_node"), enforce).unwrap_err();
        assert!(e.to_string().contains("SECURITY ERROR"), "{e}");
        // The parameter names the keystore: security on, Enforce, even without the variables;
        // `-e` picks the enclave over `security_enclave`.
        let e = launch_from_args(
            &args("--ros-args -p security_keystore:=/nonexistent -p security_enclave:=/x -e /bevt_node"),
            |_| None,
        )
        .unwrap_err();
        let want = if cfg!(feature = "security") {
            "/nonexistent/enclaves/bevt_node"
        } else {
            "without the `security` cargo feature"
        };
        assert!(e.to_string().contains(want), "{e}");
        assert!(launch_from_args(&args("--ros-args -p security_keystore:=3"), |_| None).is_err());
        // The demo has no identities.
        assert!(matches!(
            launch_from_args(&args("--demo"), enforce),
            Err(LaunchError::Args(_))
        ));
    }

    #[test]
    fn ros_args_params_remaps_and_env_are_applied() {
        let dir = std::env::temp_dir().join(format!("bevt_params_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("p.yaml");
        std::fs::write(
            &f,
            "bevt_node:\n  ros__parameters:\n    domain_id: 7\n    service_mapping: cyclone\n    tracker:\n      admm:\n        penalty: none\n",
        )
        .unwrap();
        let a = args(&format!(
            "--ros-args --params-file {} -p reinit_buffer_frames:=5 -p tracker.detection.number_of_scales:=3 -r __ns:=/drone -r image_raw:=/cam/image",
            f.display()
        ));
        let l = launch_from_args(&a, |k| (k == "ROS_DOMAIN_ID").then(|| "3".to_string())).unwrap();
        assert_eq!(l.ros.domain_id, 7, "the parameter overrides ROS_DOMAIN_ID");
        assert_eq!(l.ros.service_mapping, ServiceMapping::Cyclone);
        assert_eq!(l.ros.namespace, "/drone");
        assert_eq!(
            l.ros.remaps,
            vec![("image_raw".to_string(), "/cam/image".to_string())]
        );
        assert_eq!(l.node.reinit_buffer_frames, 5);
        assert_eq!(l.tracker.config.detection.number_of_scales, 3);
        assert_eq!(
            l.tracker.config.admm.penalty,
            bevt_core::filter::admm::PenaltyKind::None
        );
        let l = launch_from_args(&[], |k| (k == "ROS_DOMAIN_ID").then(|| "3".to_string())).unwrap();
        assert_eq!(l.ros.domain_id, 3);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn unknown_and_invalid_parameters_are_named() {
        let none = |_: &str| None;
        for (a, what) in [
            ("--ros-args -p colour:=red", "colour"),
            ("--ros-args -p domain_id:=999", "domain_id"),
            ("--ros-args -p service_mapping:=basic", "service_mapping"),
            (
                "--ros-args -p network_interfaces:=[nonsense]",
                "network_interfaces",
            ),
            (
                "--ros-args -p tracker.admm.iterations:=0",
                "admm.iterations",
            ),
            ("--bogus", "--bogus"),
            ("--ros-args -p", "-p"),
        ] {
            let e = launch_from_args(&args(a), none).unwrap_err().to_string();
            assert!(e.contains(what), "{a}: {e}");
        }
        let e = launch_from_args(&[], |k| (k == "ROS_DOMAIN_ID").then(|| "x".into())).unwrap_err();
        assert!(e.to_string().contains("ROS_DOMAIN_ID"));
    }

    /// `config/node.yaml` names every parameter of the table (set, or commented out when its
    /// default is "unset"), and each line's comment states the range the table enforces, so
    /// the file's hand-written comments cannot drift from the checks.
    #[test]
    fn the_shipped_parameters_file_states_the_table_ranges() {
        let text = include_str!("../../../config/node.yaml");
        let num = |v: f64| format!("{v}");
        for k in NODE_KEYS.iter().filter(|k| k.name != "use_sim_time") {
            let line = text
                .lines()
                .find(|l| {
                    let l = l.trim_start().trim_start_matches("# ");
                    l.strip_prefix(k.name).is_some_and(|r| r.starts_with(':'))
                })
                .unwrap_or_else(|| panic!("{} is not in config/node.yaml", k.name));
            let comment = line
                .split_once(" # ")
                .map(|(_, c)| c)
                .unwrap_or_else(|| panic!("{}: no comment", k.name));
            let want: Vec<String> = match k.range {
                NodeRange::Int(lo, hi) | NodeRange::Chars(lo, hi) => vec![format!("{lo}..={hi}")],
                NodeRange::Real(lo, hi) | NodeRange::OffOr(lo, hi) => {
                    vec![format!("{}..={}", num(lo), num(hi))]
                }
                NodeRange::Choice(c) => c.iter().map(|c| c.to_string()).collect(),
                NodeRange::Any | NodeRange::Fixed(_) => vec![],
            };
            for w in want {
                assert!(
                    comment.contains(&w),
                    "config/node.yaml, {}: the comment does not state `{w}` (NODE_KEYS): {line}",
                    k.name
                );
            }
        }
    }

    #[test]
    fn the_shipped_parameters_file_loads() {
        let text = include_str!("../../../config/node.yaml");
        let p = params_from_file(text, "bevt_node").unwrap();
        assert!(
            !p.contains_key("domain_id"),
            "domain_id set by default would override ROS_DOMAIN_ID"
        );
        let dir = std::env::temp_dir().join(format!("bevt_params2_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("node.yaml");
        std::fs::write(&f, text).unwrap();
        let l = launch_from_args(
            &args(&format!("--ros-args --params-file {}", f.display())),
            |_| None,
        )
        .unwrap();
        assert_eq!(l.tracker.config, bevt_core::TrackerConfig::default());
        assert_eq!(
            l.node,
            NodeSettings::default(),
            "node.yaml states the defaults"
        );
        let env = |k: &str| (k == "ROS_DOMAIN_ID").then(|| "17".to_string());
        let l = launch_from_args(
            &args(&format!("--ros-args --params-file {}", f.display())),
            env,
        )
        .unwrap();
        assert_eq!(l.ros.domain_id, 17, "ROS_DOMAIN_ID is honoured");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn every_number_out_of_range_is_refused_by_name_without_panicking() {
        let none = |_: &str| None;
        let params = [
            "max_image_width",
            "max_image_height",
            "max_image_pixels",
            "reinit_buffer_frames",
            "reinit_buffer_mb",
            "reinit_max_fast_forward",
            "reinit_rate_hz",
            "reinit_burst",
            "stale_timeout_s",
            "diagnostics_period_s",
            "debug_image_rate_hz",
            "domain_id",
            "tracker.window.padding",
            "tracker.window.search_area_scale",
            "tracker.window.filter_max_area",
            "tracker.features.hog_cell_size",
            "tracker.detection.number_of_scales",
            "tracker.detection.newton_iterations",
            "tracker.detection.scale_penalty",
            "tracker.admm.iterations",
            "tracker.threads",
        ];
        for p in params {
            for v in [
                "1e20", "1e19", "1e300", "1e-300", "-1", ".nan", ".inf", "-.inf", "1000000",
            ] {
                // Values a parameter legitimately takes are skipped.
                let ok = matches!(
                    (p, v),
                    ("debug_image_rate_hz", "-1") | ("tracker.detection.newton_iterations", "-1")
                ) || (v == "1000000" && p == "max_image_pixels");
                let r = launch_from_args(&args(&format!("--ros-args -p {p}:={v}")), none);
                if ok {
                    continue;
                }
                let e = r.map(|_| ()).unwrap_err().to_string();
                let short = p.trim_start_matches("tracker.");
                assert!(e.contains(short), "{p}:={v}: {e}");
            }
        }
        for d in ["1e300", "1e20", "1e19", "1e-300", "nan", "inf", "-1", "0"] {
            let e = launch_from_args(&args(&format!("--demo --duration {d}")), none).unwrap_err();
            assert!(e.to_string().contains("--duration"), "{d}: {e}");
        }
        let l = launch_from_args(&args("--demo --duration 2.5"), none).unwrap();
        assert_eq!(l.demo_duration, Duration::from_millis(2500));
        // A buffer too small for one largest frame is refused.
        let e = launch_from_args(
            &args("--ros-args -p reinit_buffer_mb:=16 -p max_image_pixels:=16777216"),
            none,
        )
        .unwrap_err();
        assert!(e.to_string().contains("reinit_buffer_mb"), "{e}");
        let l = launch_from_args(
            &args("--ros-args -p debug_image_rate_hz:=0 -p reinit_rate_hz:=0.5 -p stale_timeout_s:=3600"),
            none,
        )
        .unwrap();
        assert_eq!(l.node.reinit_rate_hz, 0.5);
        assert_eq!(l.node.stale_timeout, Duration::from_secs(3600));
    }

    #[test]
    fn network_interfaces_and_max_sample_size_are_checked() {
        let none = |_: &str| None;
        for a in [
            "--ros-args -p network_interfaces:=[]",
            "--ros-args -p network_interfaces:=[::1]",
            "--ros-args -p network_interfaces:=[0.0.0.0,127.0.0.1]",
        ] {
            let e = launch_from_args(&args(a), none).unwrap_err().to_string();
            assert!(e.contains("network_interfaces"), "{a}: {e}");
        }
        for a in [
            "--ros-args -p dds_max_sample_bytes:=1000",
            "--ros-args -p dds_max_sample_bytes:=1099511627776",
            // Smaller than one largest image message.
            "--ros-args -p dds_max_sample_bytes:=67108864",
        ] {
            let e = launch_from_args(&args(a), none).unwrap_err().to_string();
            assert!(e.contains("dds_max_sample_bytes"), "{a}: {e}");
        }
        let l = launch_from_args(
            &args(
                "--ros-args -p network_interfaces:=[0.0.0.0] -p dds_max_sample_bytes:=1048576 -p max_image_pixels:=65536",
            ),
            none,
        )
        .unwrap();
        assert_eq!(l.ros.networks, vec![IpAddr::from([0, 0, 0, 0])]);
        assert_eq!(l.ros.max_sample_bytes, 1 << 20);
        let l = launch_from_args(&[], none).unwrap();
        assert_eq!(l.ros.networks, vec![IpAddr::from([127, 0, 0, 1])]);
        assert_eq!(
            l.ros.max_sample_bytes,
            crate::node::ros::DEFAULT_MAX_SAMPLE_BYTES
        );
    }

    #[test]
    fn the_node_table_ranges_are_what_start_up_enforces_at_both_ends() {
        let none = |_: &str| None;
        // Refused by the table's range (not by a condition between parameters).
        let refused = |k: &NodeKey, v: String| {
            let words = match k.range {
                NodeRange::Int(lo, hi) | NodeRange::Chars(lo, hi) => format!("{lo}..={hi}"),
                NodeRange::Real(lo, hi) | NodeRange::OffOr(lo, hi) => format!("{lo}..={hi}"),
                _ => k.range_words(),
            };
            launch_from_args(&args(&format!("--ros-args -p {}:={v}", k.name)), none)
                .err()
                .map(|e| e.to_string())
                .is_some_and(|e| {
                    e.contains(&format!("parameter {}:", k.name)) && e.contains(&words)
                })
        };
        let mut checked = 0;
        for k in NODE_KEYS {
            let (inside, outside): (Vec<String>, Vec<String>) = match k.range {
                NodeRange::Int(lo, hi) => {
                    let mut out = vec![(hi + 1).to_string()];
                    if lo > 0 {
                        out.push((lo - 1).to_string());
                    }
                    (vec![lo.to_string(), hi.to_string()], out)
                }
                NodeRange::Real(lo, hi) | NodeRange::OffOr(lo, hi) => (
                    vec![format!("{lo:?}"), format!("{hi:?}")],
                    vec![
                        format!("{:?}", lo * 0.99),
                        format!("{:?}", hi * 1.01),
                        ".nan".into(),
                    ],
                ),
                NodeRange::Chars(lo, hi) => (
                    vec!["x".repeat(lo as usize), "x".repeat(hi as usize)],
                    vec!["x".repeat(hi as usize + 1)],
                ),
                NodeRange::Choice(c) => (
                    c.iter().map(|c| c.to_string()).collect(),
                    vec!["bogus".into()],
                ),
                NodeRange::Any | NodeRange::Fixed(_) => continue,
            };
            for v in outside {
                assert!(refused(k, v.clone()), "{} = {v} accepted", k.name);
            }
            for v in inside {
                assert!(!refused(k, v.clone()), "{} = {v} refused", k.name);
            }
            checked += 1;
        }
        assert!(checked >= 14, "{checked}");
    }
}
