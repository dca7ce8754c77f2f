//! The node's parameters as ROS users expect them: the `rcl_interfaces` parameter services
//! (`ros2 param list/get/set/describe/dump`) and `/parameter_events`.
//!
//! Every start-up parameter of [`crate::node::node_params::NODE_KEYS`] and every tracker
//! key of [`bevt_core::config::TRACKER_KEYS`] (`tracker.<section>.<key>`) is declared with
//! its value and, from its table, its description, range and liveness. A set is checked
//! exactly as at start-up (same ranges, same messages) and then:
//! - **live** parameters take effect at once: the node keys and tracker keys whose table
//!   row says so (rate limit, fast-forward, stale timeout, diagnostics period, debug-image
//!   rate, class id; thresholds, learning rates, per-frame budgets), on the running track;
//! - every other parameter is **read-only** while running (its descriptor says so): the
//!   set is refused with the reason and the old value stays.
//!
//! The services are served by the node's worker loop (see [`crate::node::ros`]) with the
//! node's service mapping, not by ros2-client's spinner, whose services use the Fast DDS
//! mapping only and describe no parameter.

use crate::node::app::NodeSettings;
use crate::node::node_params::{launch_from_args, NODE_KEYS};
use crate::node::ros::RosSettings;
use bevt_core::config::{Kind, TRACKER_KEYS};
use bevt_core::{TrackerConfig, TrackerSpec};
use ros2_client::parameters::raw;
use ros2_client::rcl_interfaces::{
    DescribeParametersRequest, DescribeParametersResponse, GetParameterTypesRequest,
    GetParameterTypesResponse, GetParametersRequest, GetParametersResponse, ListParametersRequest,
    ListParametersResponse, ListParametersResult, SetParametersAtomicallyResponse,
    SetParametersRequest, SetParametersResponse,
};
use ros2_client::{Name, Publisher, Server, ServiceMapping, ServiceTypeName};
use serde_norway::{Number, Value};
use std::collections::BTreeMap;
use std::time::Duration;

/// Prefix of the tracker keys.
const TRACKER: &str = "tracker.";

/// Bytes in a MiB.
const MIB: usize = 1 << 20;

/// A parameter value (the ROS types the node uses).
#[derive(Debug, Clone, PartialEq)]
pub enum ParamValue {
    /// `bool`.
    Bool(bool),
    /// `integer`.
    Integer(i64),
    /// `double`.
    Double(f64),
    /// `string`.
    String(String),
    /// `double[]`.
    DoubleArray(Vec<f64>),
    /// `string[]`.
    StringArray(Vec<String>),
}

impl ParamValue {
    /// The `rcl_interfaces/ParameterType` code.
    pub fn type_code(&self) -> u8 {
        match self {
            Self::Bool(_) => raw::ParameterType::BOOL,
            Self::Integer(_) => raw::ParameterType::INTEGER,
            Self::Double(_) => raw::ParameterType::DOUBLE,
            Self::String(_) => raw::ParameterType::STRING,
            Self::DoubleArray(_) => raw::ParameterType::DOUBLE_ARRAY,
            Self::StringArray(_) => raw::ParameterType::STRING_ARRAY,
        }
    }

    fn type_name(code: u8) -> &'static str {
        match code {
            raw::ParameterType::BOOL => "bool",
            raw::ParameterType::INTEGER => "integer",
            raw::ParameterType::DOUBLE => "double",
            raw::ParameterType::STRING => "string",
            raw::ParameterType::BYTE_ARRAY => "byte array",
            raw::ParameterType::BOOL_ARRAY => "bool array",
            raw::ParameterType::INTEGER_ARRAY => "integer array",
            raw::ParameterType::DOUBLE_ARRAY => "double array",
            raw::ParameterType::STRING_ARRAY => "string array",
            _ => "not set",
        }
    }

    /// The wire form.
    pub fn to_raw(&self) -> raw::ParameterValue {
        ros2_client::ParameterValue::from(self.clone()).into()
    }

    /// `v` as a value of type `like`, or why not (an integer is accepted for a double, as
    /// `ros2 param set x 2` sends one).
    fn from_raw(v: &raw::ParameterValue, like: &ParamValue) -> Result<ParamValue, String> {
        let got = ros2_client::ParameterValue::from(v.clone());
        use ros2_client::ParameterValue as P;
        Ok(match (got, like) {
            (P::Boolean(b), Self::Bool(_)) => Self::Bool(b),
            (P::Integer(i), Self::Integer(_)) => Self::Integer(i),
            (P::Integer(i), Self::Double(_)) => Self::Double(i as f64),
            (P::Double(d), Self::Double(_)) => Self::Double(d),
            (P::String(s), Self::String(_)) => Self::String(s),
            (P::DoubleArray(a), Self::DoubleArray(_)) => Self::DoubleArray(a),
            (P::IntegerArray(a), Self::DoubleArray(_)) => {
                Self::DoubleArray(a.into_iter().map(|i| i as f64).collect())
            }
            (P::StringArray(a), Self::StringArray(_)) => Self::StringArray(a),
            _ => {
                return Err(format!(
                    "wrong type: {} given, {} expected",
                    Self::type_name(v.ptype),
                    Self::type_name(like.type_code())
                ))
            }
        })
    }

    /// The value as a YAML scalar or sequence (for the start-up parser).
    fn to_yaml(&self) -> Value {
        match self {
            Self::Bool(b) => Value::Bool(*b),
            Self::Integer(i) => Value::Number(Number::from(*i)),
            Self::Double(d) => Value::Number(Number::from(*d)),
            Self::String(s) => Value::String(s.clone()),
            Self::DoubleArray(a) => {
                Value::Sequence(a.iter().map(|d| Value::Number(Number::from(*d))).collect())
            }
            Self::StringArray(a) => Value::Sequence(a.iter().cloned().map(Value::String).collect()),
        }
    }
}

impl From<ParamValue> for ros2_client::ParameterValue {
    fn from(v: ParamValue) -> Self {
        match v {
            ParamValue::Bool(b) => Self::Boolean(b),
            ParamValue::Integer(i) => Self::Integer(i),
            ParamValue::Double(d) => Self::Double(d),
            ParamValue::String(s) => Self::String(s),
            ParamValue::DoubleArray(a) => Self::DoubleArray(a),
            ParamValue::StringArray(a) => Self::StringArray(a),
        }
    }
}

/// One declared parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct Declared {
    /// Current value.
    pub value: ParamValue,
    /// What it is.
    pub description: String,
    /// The accepted values in words (the range start-up checks).
    pub constraints: String,
    /// Numeric range `(from, to)` when the constraint is a simple interval.
    pub range: Option<(f64, f64)>,
    /// Takes effect while running.
    pub live: bool,
}

impl Declared {
    /// The `rcl_interfaces/ParameterDescriptor` of parameter `name`.
    pub fn descriptor(&self, name: &str) -> raw::ParameterDescriptor {
        let (mut fp, mut int) = (Vec::new(), Vec::new());
        match (&self.value, self.range) {
            (ParamValue::Integer(_), Some((lo, hi))) => int.push(raw::IntegerRange {
                from_value: lo as i64,
                to_value: hi as i64,
                step: 0,
            }),
            (ParamValue::Double(_) | ParamValue::DoubleArray(_), Some((lo, hi))) => {
                fp.push(raw::FloatingPointRange {
                    from_value: lo,
                    to_value: hi,
                    step: 0.0,
                })
            }
            _ => {}
        }
        let when = if self.live {
            "Takes effect at once."
        } else {
            "Read-only while running: set it at start-up (-p name:=value or --params-file)."
        };
        raw::ParameterDescriptor {
            name: name.to_string(),
            r#type: self.value.type_code(),
            description: format!("{} {when}", self.description),
            additional_constraints: self.constraints.clone(),
            read_only: !self.live,
            dynamic_typing: false,
            floating_point_range: fp,
            integer_range: int,
        }
    }
}

/// What an accepted set changed, for the caller to apply.
#[derive(Debug, Clone, PartialEq)]
pub enum Change {
    /// Node logic settings ([`crate::node::app::NodeCore::set_live_settings`]).
    Node(NodeSettings),
    /// `debug_image_rate_hz` (Hz, 0 = off).
    DebugImageRate(f64),
    /// `diagnostics_period_s`.
    DiagnosticsPeriod(Duration),
    /// The tracker ([`crate::node::app::NodeCore::retune`]).
    Tracker(Box<TrackerSpec>),
}

/// The node's declared parameters and their current values.
#[derive(Debug, Clone)]
pub struct NodeParams {
    params: BTreeMap<String, Declared>,
    ros: RosSettings,
    node: NodeSettings,
    tracker: TrackerConfig,
}

impl NodeParams {
    /// The parameters of a node started with these settings.
    pub fn new(ros: &RosSettings, node: &NodeSettings, tracker: &TrackerConfig) -> Self {
        let mut p = Self {
            params: BTreeMap::new(),
            ros: ros.clone(),
            node: node.clone(),
            tracker: tracker.clone(),
        };
        p.declare_node();
        p.declare_tracker();
        p
    }

    fn node_value(&self, name: &str) -> Option<ParamValue> {
        let (r, n) = (&self.ros, &self.node);
        Some(match name {
            "domain_id" => ParamValue::Integer(i64::from(r.domain_id)),
            "network_interfaces" => {
                ParamValue::StringArray(r.networks.iter().map(|a| a.to_string()).collect())
            }
            "dds_max_sample_bytes" => ParamValue::Integer(r.max_sample_bytes as i64),
            "service_mapping" => ParamValue::String(
                match r.service_mapping {
                    ServiceMapping::Cyclone => "cyclone",
                    _ => "enhanced",
                }
                .into(),
            ),
            "image_transport" => ParamValue::String(r.image_transport.name().into()),
            "max_image_width" => ParamValue::Integer(i64::from(n.image_limits.max_width)),
            "max_image_height" => ParamValue::Integer(i64::from(n.image_limits.max_height)),
            "max_image_pixels" => ParamValue::Integer(n.image_limits.max_pixels as i64),
            "reinit_buffer_frames" => ParamValue::Integer(n.reinit_buffer_frames as i64),
            "reinit_buffer_mb" => ParamValue::Integer((n.reinit_buffer_bytes / MIB) as i64),
            "reinit_max_fast_forward" => ParamValue::Integer(n.reinit_max_fast_forward as i64),
            "reinit_rate_hz" => ParamValue::Double(n.reinit_rate_hz),
            "reinit_burst" => ParamValue::Integer(i64::from(n.reinit_burst)),
            "stale_timeout_s" => ParamValue::Double(n.stale_timeout.as_secs_f64()),
            "diagnostics_period_s" => ParamValue::Double(r.diagnostics_period.as_secs_f64()),
            "debug_image_rate_hz" => ParamValue::Double(r.debug_image_rate_hz),
            "class_id" => ParamValue::String(n.class_id.clone()),
            "use_sim_time" => ParamValue::Bool(false),
            _ => return None,
        })
    }

    fn declare_node(&mut self) {
        for k in NODE_KEYS.iter().filter(|k| k.served) {
            let Some(value) = self.node_value(k.name) else {
                continue;
            };
            self.params.insert(
                k.name.to_string(),
                Declared {
                    value,
                    description: k.doc.to_string(),
                    constraints: k.constraints(),
                    range: k.bounds(),
                    live: k.live,
                },
            );
        }
    }

    fn declare_tracker(&mut self) {
        let Ok(tree) = serde_norway::to_value(&self.tracker) else {
            return;
        };
        let mut leaves = Vec::new();
        flatten("", &tree, &mut leaves);
        for (key, v) in leaves {
            let Some(value) = param_of_yaml(&v) else {
                continue;
            };
            let declared = match TRACKER_KEYS.iter().find(|k| k.name == key) {
                Some(k) => Declared {
                    value,
                    description: k.doc.to_string(),
                    constraints: k.constraints(),
                    range: match k.kind {
                        Kind::Int | Kind::Float => k.range.bounds(),
                        _ => None,
                    },
                    live: k.live,
                },
                // The keys of a `features.cnn` section (a CNN preset).
                None => Declared {
                    value,
                    description: format!(
                        "CNN feature key {key} (docs/configuration.md, features.cnn)."
                    ),
                    constraints: String::new(),
                    range: None,
                    live: false,
                },
            };
            self.params.insert(format!("{TRACKER}{key}"), declared);
        }
    }

    /// Every declared parameter.
    pub fn declared(&self) -> &BTreeMap<String, Declared> {
        &self.params
    }

    /// `list_parameters`, with rclcpp's semantics: no prefixes = names with fewer than
    /// `depth` dots (0 = any); else names equal to a prefix or under `prefix.` within
    /// `depth` more levels; `prefixes` = the namespaces (up to the last dot) listed.
    pub fn list(&self, prefixes: &[String], depth: u64) -> ListParametersResult {
        let within = |s: &str| depth == 0 || (s.matches('.').count() as u64) < depth;
        let mut out = ListParametersResult {
            names: Vec::new(),
            prefixes: Vec::new(),
        };
        for name in self.params.keys() {
            let all = prefixes.is_empty() && within(name);
            let under = prefixes.iter().any(|p| {
                name == p
                    || name
                        .strip_prefix(p.as_str())
                        .and_then(|r| r.strip_prefix('.'))
                        .is_some_and(|r| within(&format!(".{r}")))
            });
            if all || under {
                out.names.push(name.clone());
                if let Some((ns, _)) = name.rsplit_once('.') {
                    if !out.prefixes.iter().any(|p| p == ns) {
                        out.prefixes.push(ns.to_string());
                    }
                }
            }
        }
        out
    }

    /// `get_parameters`: NOT_SET for unknown names.
    pub fn get(&self, names: &[String]) -> Vec<raw::ParameterValue> {
        names
            .iter()
            .map(|n| match self.params.get(n) {
                Some(d) => d.value.to_raw(),
                None => ros2_client::ParameterValue::NotSet.into(),
            })
            .collect()
    }

    /// `get_parameter_types`: NOT_SET for unknown names.
    pub fn types(&self, names: &[String]) -> Vec<u8> {
        names
            .iter()
            .map(|n| {
                self.params
                    .get(n)
                    .map_or(raw::ParameterType::NOT_SET, |d| d.value.type_code())
            })
            .collect()
    }

    /// `describe_parameters`: unknown names get an empty descriptor with that name.
    pub fn describe(&self, names: &[String]) -> Vec<raw::ParameterDescriptor> {
        names
            .iter()
            .map(|n| match self.params.get(n) {
                Some(d) => d.descriptor(n),
                None => raw::ParameterDescriptor {
                    name: n.clone(),
                    r#type: raw::ParameterType::NOT_SET,
                    description: "not a parameter of this node".into(),
                    additional_constraints: String::new(),
                    read_only: true,
                    dynamic_typing: false,
                    floating_point_range: Vec::new(),
                    integer_range: Vec::new(),
                },
            })
            .collect()
    }

    /// Checks a set without applying it: the new value and what it changes, or why it is
    /// refused.
    ///
    /// # Errors
    /// The reason: unknown parameter, wrong type, read-only while running, out of range.
    pub fn check(
        &self,
        name: &str,
        v: &raw::ParameterValue,
    ) -> Result<(ParamValue, Change), String> {
        let d = self
            .params
            .get(name)
            .ok_or_else(|| format!("{name} is not a parameter of this node"))?;
        let value = ParamValue::from_raw(v, &d.value)?;
        if !d.live {
            return Err(format!(
                "{name} is read-only while running (it shapes what the node builds at start-up); \
                 restart the node with -p {name}:=VALUE. Value kept: {}",
                yaml_text(&d.value.to_yaml())
            ));
        }
        if let Some(key) = name.strip_prefix(TRACKER) {
            let spec = self.tracker_with(key, &value)?;
            return Ok((value, Change::Tracker(Box::new(spec))));
        }
        // The start-up parser checks it: same ranges, same messages.
        let arg = format!("{name}:={}", yaml_text(&value.to_yaml()));
        let launch = launch_from_args(&["--ros-args".into(), "-p".into(), arg], |_| None)
            .map_err(|e| e.to_string())?;
        let mut node = self.node.clone();
        let change = match name {
            "debug_image_rate_hz" => Change::DebugImageRate(launch.ros.debug_image_rate_hz),
            "diagnostics_period_s" => Change::DiagnosticsPeriod(launch.ros.diagnostics_period),
            "class_id" => {
                node.class_id = launch.node.class_id;
                Change::Node(node)
            }
            "reinit_max_fast_forward" => {
                node.reinit_max_fast_forward = launch.node.reinit_max_fast_forward;
                Change::Node(node)
            }
            "reinit_rate_hz" => {
                node.reinit_rate_hz = launch.node.reinit_rate_hz;
                Change::Node(node)
            }
            "reinit_burst" => {
                node.reinit_burst = launch.node.reinit_burst;
                Change::Node(node)
            }
            "stale_timeout_s" => {
                node.stale_timeout = launch.node.stale_timeout;
                Change::Node(node)
            }
            _ => return Err(format!("{name} cannot be changed while running")),
        };
        Ok((value, change))
    }

    /// Records an applied set (after the caller applied `change`).
    pub fn commit(&mut self, name: &str, value: ParamValue, change: &Change) {
        match change {
            Change::Node(n) => self.node = n.clone(),
            Change::DebugImageRate(r) => self.ros.debug_image_rate_hz = *r,
            Change::DiagnosticsPeriod(p) => self.ros.diagnostics_period = *p,
            Change::Tracker(spec) => self.tracker = spec.config.clone(),
        }
        if let Some(d) = self.params.get_mut(name) {
            d.value = value;
        }
    }

    /// The tracker configuration with `key` set to `value`, validated.
    fn tracker_with(&self, key: &str, value: &ParamValue) -> Result<TrackerSpec, String> {
        config_with(&self.tracker, key, value.to_yaml())?
            .validate()
            .map_err(|e| e.to_string())
    }
}

/// `cfg` with the dotted `key` set to `v` (not validated).
fn config_with(cfg: &TrackerConfig, key: &str, v: Value) -> Result<TrackerConfig, String> {
    let mut tree = serde_norway::to_value(cfg).map_err(|e| e.to_string())?;
    crate::yaml::set_dotted(&mut tree, key, v).map_err(|e| format!("tracker.{e}"))?;
    serde_norway::from_value(tree).map_err(|e| format!("tracker.{key}: {e}"))
}

/// The value of the dotted tracker `key` (`admm.iterations`) in `cfg`.
pub fn tracker_value(cfg: &TrackerConfig, key: &str) -> Option<Value> {
    crate::yaml::get_dotted(serde_norway::to_value(cfg).ok()?, key)
}

/// Leaves of a YAML tree by dotted name.
fn flatten(prefix: &str, v: &Value, out: &mut Vec<(String, Value)>) {
    match v {
        Value::Mapping(m) => {
            for (k, v) in m {
                let Some(k) = k.as_str() else { continue };
                let name = if prefix.is_empty() {
                    k.to_string()
                } else {
                    format!("{prefix}.{k}")
                };
                flatten(&name, v, out);
            }
        }
        other => out.push((prefix.to_string(), other.clone())),
    }
}

/// A float as written in the configuration: `f32` values widened to `f64` lose their
/// short form (0.013 -> 0.013000000268…); the shortest `f32` text is taken back.
fn short_f64(d: f64) -> f64 {
    let f = d as f32;
    if f64::from(f) == d {
        f.to_string().parse().unwrap_or(d)
    } else {
        d
    }
}

fn param_of_yaml(v: &Value) -> Option<ParamValue> {
    Some(match v {
        Value::Bool(b) => ParamValue::Bool(*b),
        Value::Number(n) if n.is_i64() || n.is_u64() => ParamValue::Integer(n.as_i64()?),
        Value::Number(n) => ParamValue::Double(short_f64(n.as_f64()?)),
        Value::String(s) => ParamValue::String(s.clone()),
        Value::Sequence(s) => ParamValue::DoubleArray(
            s.iter()
                .map(|x| x.as_f64().map(short_f64))
                .collect::<Option<_>>()?,
        ),
        _ => return None,
    })
}

/// YAML text of a value (one line).
fn yaml_text(v: &Value) -> String {
    match v {
        Value::Number(n) => {
            // `2.0`, not `2`, so that doubles stay doubles.
            match n.as_f64() {
                Some(f) if !(n.is_i64() || n.is_u64()) && f.fract() == 0.0 && f.is_finite() => {
                    format!("{f:.1}")
                }
                _ => n.to_string(),
            }
        }
        Value::Sequence(s) => format!(
            "[{}]",
            s.iter().map(yaml_text).collect::<Vec<_>>().join(", ")
        ),
        other => serde_norway::to_string(other)
            .map(|s| s.trim().to_string())
            .unwrap_or_default(),
    }
}

/// The six `rcl_interfaces` parameter services of the node and its `/parameter_events`
/// writer.
pub struct ParamServers {
    fqn: String,
    get: Server<GetParametersRequest, GetParametersResponse>,
    types: Server<GetParameterTypesRequest, GetParameterTypesResponse>,
    set: Server<SetParametersRequest, SetParametersResponse>,
    set_atomically: Server<SetParametersRequest, SetParametersAtomicallyResponse>,
    list: Server<ListParametersRequest, ListParametersResponse>,
    describe: Server<DescribeParametersRequest, DescribeParametersResponse>,
    events: Publisher<raw::ParameterEvent>,
}

/// Most requests per service read per turn of the worker loop.
const MAX_PARAM_REQUESTS_PER_TURN: usize = 100;
/// Names (or parameters) answered per turn of the worker loop, over all parameter services,
/// in multiples of the declared parameters: request work is budgeted so that a flood of
/// requests never starves the camera (the rest waits for the next turn, 10 ms later).
const NAME_BUDGET_PER_TURN_IN_DECLARED: usize = 4;
/// History depth of the parameter services' request readers and reply writers: requests
/// beyond it that no turn has read yet are dropped by DDS, and replies that the requester
/// never reads do not pile up (a 1000-deep history of replies to 100,000-name requests held
/// over a gigabyte).
pub const PARAM_SERVICE_HISTORY_DEPTH: usize = 8;

/// The QoS of the parameter services: reliable, keep last [`PARAM_SERVICE_HISTORY_DEPTH`].
pub fn param_service_qos() -> ros2_client::QosProfile {
    ros2_client::QosProfile::publisher_default().history(ros2_client::qos::History::KeepLast {
        depth: PARAM_SERVICE_HISTORY_DEPTH,
    })
}

/// The request work left in one turn of the worker loop, and the names one request may
/// carry.
struct TurnBudget {
    left: usize,
    cap: usize,
}

impl TurnBudget {
    /// Charges a request of `n` names to the budget; false (with a log line) when it names
    /// more than the declared parameters and gets an empty reply.
    fn admit(&mut self, service: &str, n: usize, log: &mut Vec<(bool, String)>) -> bool {
        self.left = self.left.saturating_sub(n.clamp(1, self.cap));
        if n > self.cap {
            log.push((
                false,
                format!(
                    "{service}: a request of {n} names refused (more than the {} declared parameters): empty reply",
                    self.cap
                ),
            ));
            false
        } else {
            true
        }
    }
}

impl ParamServers {
    /// Creates the services of the node `node` (fully qualified `fqn`, e.g. `/bevt_node`)
    /// with `mapping` and QoS `qos`.
    ///
    /// # Errors
    /// The entity that could not be created and why.
    pub fn new(
        ctx: &ros2_client::Context,
        node: &mut ros2_client::Node,
        fqn: &str,
        mapping: ServiceMapping,
        qos: &ros2_client::QosProfile,
    ) -> Result<Self, String> {
        let name = |s: &str| Name::new(fqn, s).map_err(|e| format!("{fqn}/{s}: {e:?}"));
        let ty = |s: &str| ServiceTypeName::new("rcl_interfaces", s);
        let err = |what: &'static str| move |e: ros2_client::CreateError| format!("{what}: {e:?}");
        Ok(Self {
            fqn: fqn.to_string(),
            get: node
                .create_server(
                    mapping,
                    &name("get_parameters")?,
                    &ty("GetParameters"),
                    qos.clone(),
                    qos.clone(),
                )
                .map_err(err("get_parameters"))?,
            types: node
                .create_server(
                    mapping,
                    &name("get_parameter_types")?,
                    &ty("GetParameterTypes"),
                    qos.clone(),
                    qos.clone(),
                )
                .map_err(err("get_parameter_types"))?,
            set: node
                .create_server(
                    mapping,
                    &name("set_parameters")?,
                    &ty("SetParameters"),
                    qos.clone(),
                    qos.clone(),
                )
                .map_err(err("set_parameters"))?,
            set_atomically: node
                .create_server(
                    mapping,
                    &name("set_parameters_atomically")?,
                    &ty("SetParametersAtomically"),
                    qos.clone(),
                    qos.clone(),
                )
                .map_err(err("set_parameters_atomically"))?,
            list: node
                .create_server(
                    mapping,
                    &name("list_parameters")?,
                    &ty("ListParameters"),
                    qos.clone(),
                    qos.clone(),
                )
                .map_err(err("list_parameters"))?,
            describe: node
                .create_server(
                    mapping,
                    &name("describe_parameters")?,
                    &ty("DescribeParameters"),
                    qos.clone(),
                    qos.clone(),
                )
                .map_err(err("describe_parameters"))?,
            events: node
                .create_publisher(&ctx.get_parameter_events_topic(), None)
                .map_err(err("/parameter_events publisher"))?,
        })
    }

    /// Answers the requests that arrived. `apply` puts an accepted change into effect (or
    /// says why it cannot); accepted changes are published on `/parameter_events`.
    /// Returns one log line per set parameter, with whether it was accepted.
    pub fn serve(
        &self,
        params: &mut NodeParams,
        mut apply: impl FnMut(&Change) -> Result<(), String>,
    ) -> Vec<(bool, String)> {
        let mut log = Vec::new();
        // No request may name more than the declared parameters: its reply would be an
        // amplifier. Larger ones get an empty reply, logged.
        let cap = params.declared().len().max(1);
        let mut budget = TurnBudget {
            left: cap * NAME_BUDGET_PER_TURN_IN_DECLARED,
            cap,
        };
        for _ in 0..MAX_PARAM_REQUESTS_PER_TURN {
            if budget.left == 0 {
                break;
            }
            let Ok(Some((id, r))) = self.get.receive_request() else {
                break;
            };
            let values = if budget.admit("get_parameters", r.names.len(), &mut log) {
                params.get(&r.names)
            } else {
                Vec::new()
            };
            let _ = self.get.send_response(id, GetParametersResponse { values });
        }
        for _ in 0..MAX_PARAM_REQUESTS_PER_TURN {
            if budget.left == 0 {
                break;
            }
            let Ok(Some((id, r))) = self.types.receive_request() else {
                break;
            };
            let values = if budget.admit("get_parameter_types", r.names.len(), &mut log) {
                params.types(&r.names)
            } else {
                Vec::new()
            };
            let _ = self
                .types
                .send_response(id, GetParameterTypesResponse { values });
        }
        for _ in 0..MAX_PARAM_REQUESTS_PER_TURN {
            if budget.left == 0 {
                break;
            }
            let Ok(Some((id, r))) = self.list.receive_request() else {
                break;
            };
            let result = if budget.admit("list_parameters", r.prefixes.len(), &mut log) {
                params.list(&r.prefixes, r.depth)
            } else {
                ListParametersResult {
                    names: Vec::new(),
                    prefixes: Vec::new(),
                }
            };
            let _ = self
                .list
                .send_response(id, ListParametersResponse { result });
        }
        for _ in 0..MAX_PARAM_REQUESTS_PER_TURN {
            if budget.left == 0 {
                break;
            }
            let Ok(Some((id, r))) = self.describe.receive_request() else {
                break;
            };
            let values = if budget.admit("describe_parameters", r.names.len(), &mut log) {
                params.describe(&r.names)
            } else {
                Vec::new()
            };
            let _ = self
                .describe
                .send_response(id, DescribeParametersResponse { values });
        }
        for _ in 0..MAX_PARAM_REQUESTS_PER_TURN {
            if budget.left == 0 {
                break;
            }
            let Ok(Some((id, r))) = self.set.receive_request() else {
                break;
            };
            if !budget.admit("set_parameters", r.parameter.len(), &mut log) {
                let _ = self.set.send_response(
                    id,
                    SetParametersResponse {
                        results: Vec::new(),
                    },
                );
                continue;
            }
            let mut results = Vec::new();
            let mut changed = Vec::new();
            for p in r.parameter {
                let outcome = params
                    .check(&p.name, &p.value)
                    .and_then(|(v, c)| apply(&c).map(|()| (v, c)));
                match outcome {
                    Ok((v, c)) => {
                        log.push((
                            true,
                            format!("parameter {} set to {}", p.name, yaml_text(&v.to_yaml())),
                        ));
                        params.commit(&p.name, v.clone(), &c);
                        changed.push((p.name, v));
                        results.push(raw::SetParametersResult {
                            successful: true,
                            reason: String::new(),
                        });
                    }
                    Err(reason) => {
                        log.push((false, format!("parameter {} not set: {reason}", p.name)));
                        results.push(raw::SetParametersResult {
                            successful: false,
                            reason,
                        });
                    }
                }
            }
            self.publish(changed);
            let _ = self
                .set
                .send_response(id, SetParametersResponse { results });
        }
        for _ in 0..MAX_PARAM_REQUESTS_PER_TURN {
            if budget.left == 0 {
                break;
            }
            let Ok(Some((id, r))) = self.set_atomically.receive_request() else {
                break;
            };
            if !budget.admit("set_parameters_atomically", r.parameter.len(), &mut log) {
                let _ = self.set_atomically.send_response(
                    id,
                    SetParametersAtomicallyResponse {
                        result: raw::SetParametersResult {
                            successful: false,
                            reason: format!("more parameters than the {cap} declared"),
                        },
                    },
                );
                continue;
            }
            // All checked first, in order, each against the values the earlier ones set
            // (on a copy), then all applied.
            let mut trial = params.clone();
            let checked: Result<Vec<_>, String> = r
                .parameter
                .iter()
                .map(|p| {
                    let (v, c) = trial.check(&p.name, &p.value)?;
                    trial.commit(&p.name, v.clone(), &c);
                    Ok((p.name.clone(), v, c))
                })
                .collect();
            let result = match checked {
                Ok(all) => {
                    let mut changed = Vec::new();
                    let mut failed = None;
                    for (name, v, c) in all {
                        match apply(&c) {
                            Ok(()) => {
                                params.commit(&name, v.clone(), &c);
                                changed.push((name, v));
                            }
                            Err(e) => {
                                failed = Some(format!("{name}: {e}"));
                                break;
                            }
                        }
                    }
                    self.publish(changed);
                    failed.map_or(Ok(()), Err)
                }
                Err(e) => Err(e),
            };
            log.push(match &result {
                Ok(()) => (
                    true,
                    format!("{} parameter(s) set atomically", r.parameter.len()),
                ),
                Err(e) => (false, format!("parameters not set atomically: {e}")),
            });
            let _ = self.set_atomically.send_response(
                id,
                SetParametersAtomicallyResponse {
                    result: ros2_client::parameters::SetParametersResult::from(result).into(),
                },
            );
        }
        log
    }

    fn publish(&self, changed: Vec<(String, ParamValue)>) {
        if !changed.is_empty() {
            let _ = self.events.publish(event(&self.fqn, changed));
        }
    }
}

/// The `rcl_interfaces/ParameterEvent` of changed parameters.
pub fn event(node_fqn: &str, changed: Vec<(String, ParamValue)>) -> raw::ParameterEvent {
    raw::ParameterEvent {
        stamp: ros2_client::builtin_interfaces::Time::now(),
        node: node_fqn.to_string(),
        new_parameters: Vec::new(),
        changed_parameters: changed
            .into_iter()
            .map(|(name, v)| raw::Parameter {
                name,
                value: v.to_raw(),
            })
            .collect(),
        deleted_parameters: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> NodeParams {
        let l = launch_from_args(&[], |_| None).unwrap();
        NodeParams::new(&l.ros, &l.node, &l.tracker.config)
    }

    fn double(d: f64) -> raw::ParameterValue {
        ros2_client::ParameterValue::Double(d).into()
    }

    #[test]
    fn every_parameter_is_declared_with_a_description_and_tracker_numbers_with_a_range() {
        let p = params();
        let d = p.declared();
        for name in NODE_KEYS.iter().filter(|k| k.served).map(|k| k.name) {
            assert!(d.contains_key(name), "{name} not declared");
        }
        let tracker: Vec<_> = d.keys().filter(|k| k.starts_with(TRACKER)).collect();
        assert!(tracker.len() > 50, "{} tracker keys", tracker.len());
        for (name, decl) in d {
            assert!(
                decl.description.len() > 5 && !decl.description.contains("README"),
                "{name}: no description"
            );
            let numeric = matches!(decl.value, ParamValue::Integer(_) | ParamValue::Double(_));
            if numeric && name != "domain_id" && name != "dds_max_sample_bytes" {
                assert!(!decl.constraints.is_empty(), "{name}: no range");
            }
        }
        let pad = &d["tracker.window.padding"];
        assert_eq!(pad.value, ParamValue::Double(1.2));
        assert_eq!(pad.range, Some((1.0, 3.0)));
        assert!(!pad.live);
        let rate = &d["tracker.learning.rate"];
        assert_eq!(rate.value, ParamValue::Double(0.013), "f32 shown short");
        assert!(rate.live);
        let hz = &d["reinit_rate_hz"];
        assert_eq!(hz.range, Some((0.01, 100.0)), "{}", hz.constraints);
        let desc = p.describe(&["tracker.admm.iterations".into()]);
        assert_eq!(
            desc[0].integer_range.len(),
            1,
            "{:?}",
            desc[0].integer_range
        );
        assert!(desc[0].read_only);
        assert!(d["tracker.admm.penalty"].constraints.contains("matrix"));
    }

    #[test]
    fn live_sets_are_checked_as_at_start_up_and_others_are_refused_with_the_reason() {
        let mut p = params();
        let (v, change) = p
            .check("tracker.track_state.lost_threshold", &double(0.9))
            .unwrap();
        let Change::Tracker(spec) = &change else {
            panic!("{change:?}")
        };
        assert_eq!(spec.config.track_state.lost_threshold, 0.9);
        p.commit("tracker.track_state.lost_threshold", v, &change);
        assert_eq!(
            p.get(&["tracker.track_state.lost_threshold".into()])[0].double_value,
            0.9
        );
        let e = p
            .check("tracker.track_state.lost_threshold", &double(2.0))
            .unwrap_err();
        assert!(e.contains("[0, 1]"), "{e}");
        let e = p.check("tracker.window.padding", &double(1.5)).unwrap_err();
        assert!(e.contains("read-only while running"), "{e}");
        assert!(e.contains("1.2"), "{e}");
        let e = p.check("domain_id", &ros2_client::ParameterValue::Integer(3).into());
        assert!(e.unwrap_err().contains("read-only"));
        let e = p
            .check(
                "reinit_rate_hz",
                &ros2_client::ParameterValue::String("x".into()).into(),
            )
            .unwrap_err();
        assert!(e.contains("wrong type"), "{e}");
        let e = p.check("reinit_rate_hz", &double(1e9)).unwrap_err();
        assert!(e.contains("0.01..=100"), "{e}");
        assert!(p.check("bogus", &double(1.0)).is_err());
        // An integer is taken for a double (`ros2 param set ... 2`).
        let (v, change) = p
            .check(
                "reinit_rate_hz",
                &ros2_client::ParameterValue::Integer(2).into(),
            )
            .unwrap();
        assert_eq!(v, ParamValue::Double(2.0));
        assert!(matches!(change, Change::Node(ref n) if n.reinit_rate_hz == 2.0));
        let (_, change) = p.check("debug_image_rate_hz", &double(0.0)).unwrap();
        assert_eq!(change, Change::DebugImageRate(0.0));
    }

    #[test]
    fn the_shipped_parameters_file_lists_the_node_table_with_its_defaults() {
        let text = include_str!("../../../config/node.yaml");
        let file = crate::node::node_params::params_from_file(text, "bevt_node").unwrap();
        let p = params();
        let d = p.declared();
        let mut listed = Vec::new();
        for (k, v) in &file {
            if k.starts_with(TRACKER) {
                continue;
            }
            assert!(
                NODE_KEYS.iter().any(|n| n.name == k),
                "{k} is not in NODE_KEYS"
            );
            let value = match v {
                Value::Sequence(s) => ParamValue::StringArray(
                    s.iter().map(|x| x.as_str().unwrap().to_string()).collect(),
                ),
                other => param_of_yaml(other).unwrap(),
            };
            assert_eq!(
                value, d[k].value,
                "config/node.yaml: {k} is not the default"
            );
            listed.push(k.as_str());
        }
        // domain_id is unset by default (ROS_DOMAIN_ID), use_sim_time is not supported.
        for k in NODE_KEYS
            .iter()
            .filter(|k| k.served && !["domain_id", "use_sim_time"].contains(&k.name))
        {
            assert!(
                listed.contains(&k.name),
                "{} missing from config/node.yaml",
                k.name
            );
        }
    }

    #[test]
    fn list_follows_rclcpp() {
        let p = params();
        let all = p.list(&[], 0);
        assert!(all.names.contains(&"tracker.admm.iterations".to_string()));
        assert!(all.prefixes.contains(&"tracker.admm".to_string()));
        let top = p.list(&[], 1);
        assert!(top.names.contains(&"class_id".to_string()));
        assert!(top.names.iter().all(|n| !n.contains('.')));
        let admm = p.list(&["tracker.admm".into()], 0);
        assert!(admm.names.iter().all(|n| n.starts_with("tracker.admm.")));
        assert!(!admm.names.is_empty());
    }
}
