//! The ROS 2 layer over `ros2-client` (pure Rust, RustDDS): names, QoS and threads in one
//! place; all decisions are in [`crate::node::app::NodeCore`].
//!
//! Threads: `bevt-dds-rx` receives camera messages and keeps only the newest one in a
//! slot (counting the ones it replaces as dropped); the calling thread runs the tracker
//! on the newest frame, answers services, reads the `init` topic and publishes. The
//! tracker therefore never falls behind the camera, and DDS reception never waits for it.
//!
//! Re-initialisation requests (service and `init` topic) are read every turn of the
//! worker loop and admitted by the node's rate limit; a refused request is answered at
//! once with the reason. Each turn then processes the newest camera frame, if any, and
//! serves at most one admitted request, so requests never starve the camera.

use crate::node::app::{CameraMsg, FrameOutputs, NodeCore};
use crate::node::param_services::{Change, NodeParams, ParamServers};
use crate::node::security::DdsSecurity;
use bevt_msgs::bevt::{ReinitRequest, ReinitResponse, TrackStatus};
use bevt_msgs::diagnostic_msgs::DiagnosticArray;
use bevt_msgs::sensor_msgs::{CompressedImage, Image};
use bevt_msgs::std_srvs::{TriggerRequest, TriggerResponse};
use bevt_msgs::vision_msgs::{Detection2D, Detection2DArray};
use bevt_msgs::RosType;
use futures::StreamExt;
use ros2_client::dds::rustdds::{DomainParticipantBuilder, FragmentLimits};
use ros2_client::{
    Context, MessageTypeName, Name, Node, NodeName, NodeOptions, Publisher, QosProfile, Server,
    ServiceMapping, ServiceTypeName, Subscription,
};
use std::net::IpAddr;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};
use thiserror::Error;

/// Topic and service names, relative to the node's namespace unless they start with `/`.
pub mod names {
    /// Raw camera images in.
    pub const IMAGE: &str = "image_raw";
    /// Compressed camera images in: `<raw topic>/compressed` when [`IMAGE`] is remapped
    /// (image_transport's naming; see [`super::ros_name`]).
    pub const IMAGE_COMPRESSED: &str = "image_raw/compressed";
    /// Initial boxes in (`vision_msgs/Detection2D`, header stamp = the frame's).
    pub const INIT: &str = "init";
    /// Boxes out.
    pub const DETECTIONS: &str = "detections";
    /// Status out.
    pub const TRACK_STATUS: &str = "track_status";
    /// Diagnostics out.
    pub const DIAGNOSTICS: &str = "/diagnostics";
    /// Frames with the box drawn out (throttled, best effort; off unless configured).
    pub const DEBUG_IMAGE: &str = "debug_image";
    /// Re-initialisation service.
    pub const REINIT: &str = "reinit";
    /// Stop service.
    pub const STOP: &str = "stop";
}

/// How long the worker waits for a frame before serving requests and timers again.
const WORKER_WAIT: Duration = Duration::from_millis(10);
/// Most requests (service and topic each) read from DDS per turn of the worker loop.
const MAX_REQUESTS_PER_TURN: usize = 1000;
/// History depth of the request and reply readers/writers of the services: a burst this
/// large is read, and answered, without DDS dropping any of it.
pub const SERVICE_HISTORY_DEPTH: usize = 1000;
/// Admitted re-initialisation requests waiting for their turn, at most; admission (the
/// token bucket) keeps far fewer than this.
const MAX_PENDING_REQUESTS: usize = 64;

/// Longest timer period (diagnostics, debug image): longer settings are refused at load;
/// this only keeps the timer arithmetic total.
const MAX_PERIOD: Duration = Duration::from_secs(3600);

/// `now + period`, checked: never panics, whatever the period.
fn later(now: Instant, period: Duration) -> Instant {
    now.checked_add(period.min(MAX_PERIOD)).unwrap_or(now)
}

/// An admitted re-initialisation request waiting to be served.
enum PendingReinit {
    /// From the service: answered when served.
    Service(ros2_client::RmwRequestId, ReinitRequest),
    /// From the `init` topic: logged when served.
    Topic(ReinitRequest),
}

/// Room for an image message's fields besides its pixels (header, strings), bytes.
pub const SAMPLE_OVERHEAD_BYTES: usize = 64 * 1024;

/// Default [`RosSettings::max_sample_bytes`]: a 4096×4096 rgba8 image (16 MP, 64 MiB)
/// plus [`SAMPLE_OVERHEAD_BYTES`].
pub const DEFAULT_MAX_SAMPLE_BYTES: usize = 4096 * 4096 * 4 + SAMPLE_OVERHEAD_BYTES;

/// Errors of the ROS layer.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum RosError {
    /// A topic or service name is invalid.
    #[error("invalid ROS name {0:?}: {1}")]
    Name(String, String),
    /// DDS entity creation failed.
    #[error("cannot create {what}: {reason}")]
    Create {
        /// The entity.
        what: String,
        /// DDS error.
        reason: String,
    },
    /// A thread of the node ended while the node was running.
    #[error("the {thread} thread ended unexpectedly: {reason}")]
    ThreadEnded {
        /// The thread's name.
        thread: &'static str,
        /// Why (its panic message, or that it returned).
        reason: String,
    },
}

/// Faults a test binary injects to check that no thread of the node dies silently. The
/// node never sets one itself; nothing received from the network can.
#[doc(hidden)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InjectedFault {
    /// The reception thread returns as if its subscriptions had ended.
    ReceptionEnds,
    /// The reception thread panics.
    ReceptionPanics,
    /// The worker panics after its first tracked frame.
    WorkerPanics,
}

static INJECTED_FAULT: std::sync::OnceLock<InjectedFault> = std::sync::OnceLock::new();

/// Sets the fault of this process (tests only; see [`InjectedFault`]).
#[doc(hidden)]
pub fn inject_fault(fault: InjectedFault) {
    let _ = INJECTED_FAULT.set(fault);
}

/// Panics with the injected fault's name (tests only).
#[allow(clippy::panic)] // the point of an injected fault
fn injected_panic(what: &str) -> ! {
    panic!("injected fault: {what}")
}

/// Name of the reception thread.
const RECEPTION_THREAD: &str = "bevt-dds-rx";

/// The message of a thread's panic payload.
fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic without a message".into())
}

/// Settings of the ROS layer.
#[derive(Debug, Clone, PartialEq)]
pub struct RosSettings {
    /// Node name.
    pub node_name: String,
    /// Node namespace (`/` for none).
    pub namespace: String,
    /// DDS domain.
    pub domain_id: u16,
    /// Network interfaces (IPv4 addresses) DDS listens and sends on; `0.0.0.0` = all
    /// interfaces; empty is an error. Default loopback only.
    pub networks: Vec<IpAddr>,
    /// Largest DDS sample (serialized message, bytes) the node reassembles from
    /// fragments: at least the largest image message it accepts.
    pub max_sample_bytes: usize,
    /// Service wire mapping: `Enhanced` for Fast DDS peers, `Cyclone` for rmw_cyclonedds.
    pub service_mapping: ServiceMapping,
    /// Name remappings `from → to` (exact match on the names in [`names`]).
    pub remaps: Vec<(String, String)>,
    /// Diagnostics period.
    pub diagnostics_period: Duration,
    /// `debug_image` rate, Hz (0 = not published).
    pub debug_image_rate_hz: f64,
    /// Which camera input is subscribed (`image_transport`).
    pub image_transport: ImageTransport,
    /// DDS Security: off, or the enclave whose files secure the participant
    /// ([`crate::node::security`]).
    pub security: DdsSecurity,
    /// Lowest severity logged to the console and `/rosout` (`--ros-args --log-level`).
    pub log_level: ros2_client::log::LogLevel,
}

impl Default for RosSettings {
    fn default() -> Self {
        Self {
            node_name: "bevt_node".into(),
            namespace: "/".into(),
            domain_id: 0,
            networks: vec![IpAddr::from([127, 0, 0, 1])],
            max_sample_bytes: DEFAULT_MAX_SAMPLE_BYTES,
            service_mapping: ServiceMapping::Enhanced,
            remaps: Vec::new(),
            diagnostics_period: Duration::from_secs(1),
            debug_image_rate_hz: 0.0,
            image_transport: ImageTransport::Raw,
            security: DdsSecurity::default(),
            log_level: ros2_client::log::LogLevel::Info,
        }
    }
}

/// The camera input the node subscribes to, as image_transport's `image_transport`
/// parameter chooses it for a subscriber (default `raw`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageTransport {
    /// `image_raw` (`sensor_msgs/Image`) only.
    Raw,
    /// `image_raw/compressed` (`sensor_msgs/CompressedImage`) only.
    Compressed,
    /// Both: for a setup where some cameras publish raw and others compressed on the same
    /// name. A camera that publishes both delivers every frame twice.
    Both,
}

impl ImageTransport {
    /// The parameter's spelling.
    pub fn name(self) -> &'static str {
        match self {
            Self::Raw => "raw",
            Self::Compressed => "compressed",
            Self::Both => "both",
        }
    }

    /// From the parameter's spelling.
    pub fn parse(s: &str) -> Option<Self> {
        [Self::Raw, Self::Compressed, Self::Both]
            .into_iter()
            .find(|t| t.name() == s)
    }

    fn raw(self) -> bool {
        matches!(self, Self::Raw | Self::Both)
    }

    fn compressed(self) -> bool {
        matches!(self, Self::Compressed | Self::Both)
    }
}

/// Resolves a name like `image_raw/compressed` or `/diagnostics` (after remapping) to an
/// absolute name in the node's namespace. (Resolving here, rather than leaving relative
/// names to ros2-client, avoids its `rt//name` for nodes in the root namespace.)
///
/// The compressed input follows the raw one as image_transport subscribers do:
/// [`names::IMAGE_COMPRESSED`] resolves to the raw topic's name + `/compressed`, so
/// `-r image_raw:=/camera/image_raw` moves it to `/camera/image_raw/compressed`; a remap
/// of `image_raw/compressed` itself takes precedence.
pub fn ros_name(settings: &RosSettings, name: &str) -> Result<Name, RosError> {
    let remapped = |name: &str| {
        settings
            .remaps
            .iter()
            .find(|(from, _)| from == name)
            .map(|(_, to)| to.clone())
    };
    let name = match remapped(name) {
        Some(to) => to,
        None if name == names::IMAGE_COMPRESSED => match remapped(names::IMAGE) {
            Some(raw) => format!("{}/compressed", raw.trim_end_matches('/')),
            None => name.to_string(),
        },
        None => name.to_string(),
    };
    let full = if name.starts_with('/') {
        name.clone()
    } else {
        format!("{}/{}", settings.namespace.trim_end_matches('/'), name)
    };
    let (ns, base) = full.rsplit_once('/').unwrap_or(("", &full));
    Name::new(if ns.is_empty() { "/" } else { ns }, base)
        .map_err(|e| RosError::Name(name.clone(), format!("{e:?}")))
}

/// How often the node announces itself to discovery (SPDP; RustDDS's default is 10 s).
/// ROS 2's default discovery range (`SUBNET`) has Fast DDS peers announce by multicast
/// only, which a node listening on loopback (the default `network_interfaces`) never
/// hears: such a peer finds the node only when the node's announcement, also sent by
/// unicast to the same-host well-known ports, reaches it. At 10 s a `ros2 topic list`
/// usually missed the node; at 1 s it costs 12 datagrams of ~400 bytes a second on
/// loopback (and one multicast datagram where multicast is used). The lease the node
/// advertises stays 50 s.
pub const SPDP_ANNOUNCE_PERIOD: Duration = Duration::from_secs(1);

/// A DDS context that listens and sends only on `settings.networks` (`0.0.0.0`: all
/// interfaces) and reassembles samples of at most `settings.max_sample_bytes`.
pub fn context(settings: &RosSettings) -> Result<Context, RosError> {
    if settings.networks.is_empty() {
        return Err(RosError::Create {
            what: format!("DDS participant on domain {}", settings.domain_id),
            reason: "no network interfaces: list the addresses to listen on (0.0.0.0 = all)".into(),
        });
    }
    // An address the host does not have would fail deep in RustDDS as "Could not find free
    // ParticipantId": name the address and the parameter instead.
    for a in &settings.networks {
        if a.is_unspecified() {
            continue;
        }
        if let Err(e) = std::net::UdpSocket::bind((*a, 0)) {
            return Err(RosError::Create {
                what: format!("DDS participant on domain {}", settings.domain_id),
                reason: format!(
                    "network_interfaces: {a} is not an address of this host ({e}); list this host's addresses, or 0.0.0.0 for all"
                ),
            });
        }
    }
    // Discovery samples are small: RustDDS's built-in limits stay.
    #[cfg_attr(not(feature = "security"), allow(unused_mut))]
    let mut b = DomainParticipantBuilder::new(settings.domain_id)
        .with_only_networks(settings.networks.clone())
        .fragment_limits(FragmentLimits::with_max_sample_size(
            settings.max_sample_bytes,
        ))
        .spdp_period(SPDP_ANNOUNCE_PERIOD);
    if let DdsSecurity::Enclave(dir) = &settings.security {
        #[cfg(feature = "security")]
        {
            // RustDDS's built-in authentication (PKI-DH), access control (permissions and
            // governance) and cryptographic (AES-GCM-GMAC) plugins, from the enclave's files
            // under the names `ros2 security` gives them. The keys are unencrypted PEM, as
            // sros2 writes them, so there is no password.
            b = b.builtin_security(
                ros2_client::dds::rustdds::DomainParticipantSecurityConfigFiles::with_ros_default_names(
                    dir,
                    String::new(),
                ),
            );
        }
        #[cfg(not(feature = "security"))]
        return Err(RosError::Create {
            what: format!("secured DDS participant (enclave {})", dir.display()),
            reason: "this build has no DDS Security (cargo feature `security`)".into(),
        });
    }
    let dp = b.build().map_err(|e| RosError::Create {
        what: format!("DDS participant on domain {}", settings.domain_id),
        reason: format!("{e:?}"),
    })?;
    Context::from_domain_participant(dp).map_err(|e| RosError::Create {
        what: "ROS context".into(),
        reason: format!("{e:?}"),
    })
}

fn create_err(what: &str) -> impl Fn(ros2_client::CreateError) -> RosError + '_ {
    move |e| RosError::Create {
        what: what.to_string(),
        reason: format!("{e:?}"),
    }
}

/// The QoS of camera input: best effort, keep last 1 (matches reliable and best-effort
/// cameras).
pub fn camera_qos() -> QosProfile {
    QosProfile::subscription_default()
}

/// The QoS of outputs: reliable, keep last 10.
pub fn output_qos() -> QosProfile {
    QosProfile::publisher_default().history(ros2_client::qos::History::KeepLast { depth: 10 })
}

/// The QoS of service requests and replies: reliable, keep last
/// [`SERVICE_HISTORY_DEPTH`].
pub fn service_qos() -> QosProfile {
    QosProfile::publisher_default().history(ros2_client::qos::History::KeepLast {
        depth: SERVICE_HISTORY_DEPTH,
    })
}

fn type_of<T: RosType>() -> MessageTypeName {
    MessageTypeName::new(T::PACKAGE, T::NAME)
}

/// The newest camera message, and how many were replaced before the worker took one.
#[derive(Default)]
struct Slot {
    newest: Mutex<Option<Incoming>>,
    ready: Condvar,
    dropped: AtomicU32,
}

enum Incoming {
    Raw(Image, Instant),
    Compressed(CompressedImage, Instant),
    Error(String),
}

impl Slot {
    fn put(&self, item: Incoming) {
        if let Ok(mut g) = self.newest.lock() {
            if g.replace(item).is_some() {
                self.dropped.fetch_add(1, Ordering::Relaxed);
            }
            self.ready.notify_one();
        }
    }

    fn take(&self, wait: Duration) -> Option<Incoming> {
        let g = self.newest.lock().ok()?;
        let (mut g, _) = self
            .ready
            .wait_timeout_while(g, wait, |v| v.is_none())
            .ok()?;
        g.take()
    }
}

/// The node's DDS entities except the camera subscriptions (those belong to the
/// reception thread: [`CameraSubscriptions`]).
struct Endpoints {
    node: Node,
    sub_init: Subscription<Detection2D>,
    pub_det: Publisher<Detection2DArray>,
    pub_status: Publisher<TrackStatus>,
    pub_diag: Publisher<DiagnosticArray>,
    /// Present once `debug_image_rate_hz` has been > 0 (at start-up or set while running).
    pub_debug: Option<Publisher<Image>>,
    srv_reinit: Server<ReinitRequest, ReinitResponse>,
    srv_stop: Server<TriggerRequest, TriggerResponse>,
    /// The `rcl_interfaces` parameter services and `/parameter_events`.
    params: ParamServers,
}

/// The QoS of the debug image: reliable, keep last 1. Reliable matches both reliable
/// subscribers (RViz's and rclpy's default, which a best-effort publisher would not match)
/// and best-effort ones, and lets a reliable subscriber have lost fragments of a ~1 MB
/// image re-sent (NACK_FRAG): on loopback a best-effort burst of ~17 datagrams overflows a
/// default-sized (208 KiB) receive buffer, and only 2 of ~20 images reached an rclpy
/// subscriber. Keep last 1 bounds what is held for re-sending to one image.
pub fn debug_image_qos() -> QosProfile {
    QosProfile::publisher_default().history(ros2_client::qos::History::KeepLast { depth: 1 })
}

/// The `debug_image` publisher.
fn debug_publisher(node: &mut Node, settings: &RosSettings) -> Result<Publisher<Image>, RosError> {
    let cq = debug_image_qos();
    let t = node
        .create_topic(
            &ros_name(settings, names::DEBUG_IMAGE)?,
            type_of::<Image>(),
            &cq,
        )
        .map_err(create_err("debug image topic"))?;
    node.create_publisher::<Image>(&t, Some(cq))
        .map_err(create_err("debug image publisher"))
}

/// The camera subscriptions (those `image_transport` asks for), handed to the reception
/// thread.
struct CameraSubscriptions {
    raw: Option<Subscription<Image>>,
    compressed: Option<Subscription<CompressedImage>>,
}

/// Creates the node and all its topics, subscriptions, publishers and services.
fn create_endpoints(settings: &RosSettings) -> Result<(Endpoints, CameraSubscriptions), RosError> {
    let ctx = context(settings)?;
    let node_name = NodeName::new(&settings.namespace, &settings.node_name)
        .map_err(|e| RosError::Name(settings.node_name.clone(), format!("{e:?}")))?;
    let mut node: Node = ctx
        .new_node(
            node_name,
            // The parameter services are the node's own (ParamServers): ros2-client's
            // need its spinner, use the Fast DDS mapping only and describe nothing.
            NodeOptions::new()
                .enable_rosout(true)
                .start_parameter_services(false),
        )
        .map_err(|e| RosError::Create {
            what: "node".into(),
            reason: format!("{e:?}"),
        })?;
    let topic = |node: &Node, name: &str, ty: MessageTypeName, qos: &QosProfile| {
        node.create_topic(&ros_name(settings, name)?, ty, qos)
            .map_err(|e| RosError::Create {
                what: format!("topic {name}"),
                reason: format!("{e:?}"),
            })
    };
    let cq = camera_qos();
    let oq = output_qos();
    let t_img = topic(&node, names::IMAGE, type_of::<Image>(), &cq)?;
    let t_cmp = topic(
        &node,
        names::IMAGE_COMPRESSED,
        type_of::<CompressedImage>(),
        &cq,
    )?;
    let t_init = topic(
        &node,
        names::INIT,
        MessageTypeName::new("vision_msgs", "Detection2D"),
        &oq,
    )?;
    let t_det = topic(&node, names::DETECTIONS, type_of::<Detection2DArray>(), &oq)?;
    let t_status = topic(&node, names::TRACK_STATUS, type_of::<TrackStatus>(), &oq)?;
    let t_diag = topic(&node, names::DIAGNOSTICS, type_of::<DiagnosticArray>(), &oq)?;
    let pub_debug = if settings.debug_image_rate_hz > 0.0 {
        Some(debug_publisher(&mut node, settings)?)
    } else {
        None
    };
    // Only the configured input is subscribed: a camera publishing both would otherwise
    // hand every frame over twice (and the compressed one through a decoder).
    let sub_img = if settings.image_transport.raw() {
        Some(
            node.create_subscription::<Image>(&t_img, Some(cq.clone()))
                .map_err(create_err("image subscription"))?,
        )
    } else {
        None
    };
    let sub_cmp = if settings.image_transport.compressed() {
        Some(
            node.create_subscription::<CompressedImage>(&t_cmp, Some(cq.clone()))
                .map_err(create_err("compressed image subscription"))?,
        )
    } else {
        None
    };
    let sub_init = node
        .create_subscription::<Detection2D>(&t_init, Some(oq.clone()))
        .map_err(create_err("init subscription"))?;
    let pub_det = node
        .create_publisher::<Detection2DArray>(&t_det, Some(oq.clone()))
        .map_err(create_err("detections publisher"))?;
    let pub_status = node
        .create_publisher::<TrackStatus>(&t_status, Some(oq.clone()))
        .map_err(create_err("status publisher"))?;
    let pub_diag = node
        .create_publisher::<DiagnosticArray>(&t_diag, Some(oq.clone()))
        .map_err(create_err("diagnostics publisher"))?;
    let sq = service_qos();
    let srv_reinit = node
        .create_server::<ReinitRequest, ReinitResponse>(
            settings.service_mapping,
            &ros_name(settings, names::REINIT)?,
            &ServiceTypeName::new("bevt_msgs", "Reinit"),
            sq.clone(),
            sq.clone(),
        )
        .map_err(create_err("reinit service"))?;
    let srv_stop = node
        .create_server::<TriggerRequest, TriggerResponse>(
            settings.service_mapping,
            &ros_name(settings, names::STOP)?,
            &ServiceTypeName::new("std_srvs", "Trigger"),
            sq.clone(),
            sq.clone(),
        )
        .map_err(create_err("stop service"))?;
    let fqn = format!(
        "{}/{}",
        settings.namespace.trim_end_matches('/'),
        settings.node_name
    );
    let params = ParamServers::new(
        &ctx,
        &mut node,
        &fqn,
        settings.service_mapping,
        &crate::node::param_services::param_service_qos(),
    )
    .map_err(|reason| RosError::Create {
        what: "parameter services".into(),
        reason,
    })?;
    let endpoints = Endpoints {
        node,
        sub_init,
        pub_det,
        pub_status,
        pub_diag,
        pub_debug,
        srv_reinit,
        srv_stop,
        params,
    };
    let camera = CameraSubscriptions {
        raw: sub_img,
        compressed: sub_cmp,
    };
    Ok((endpoints, camera))
}

/// Starts the reception thread `bevt-dds-rx`: it puts every camera message into the
/// returned slot (newest frame wins) until `shutdown` is set.
fn spawn_reception(
    camera: CameraSubscriptions,
    shutdown: Arc<AtomicBool>,
) -> Result<(Arc<Slot>, std::thread::JoinHandle<()>), RosError> {
    let slot = Arc::new(Slot::default());
    let rx_slot = slot.clone();
    let handle = std::thread::Builder::new()
        .name(RECEPTION_THREAD.into())
        .spawn(move || {
            match INJECTED_FAULT.get() {
                Some(InjectedFault::ReceptionEnds) => return,
                Some(InjectedFault::ReceptionPanics) => injected_panic("the reception thread"),
                _ => {}
            }
            futures::executor::block_on(async move {
                // An input that is not subscribed is a stream that never yields.
                let raw = match &camera.raw {
                    Some(sub) => sub
                        .async_stream()
                        .map(|r| match r {
                            Ok((m, _)) => Incoming::Raw(m, Instant::now()),
                            Err(e) => {
                                Incoming::Error(format!("cannot read an image message: {e:?}"))
                            }
                        })
                        .left_stream(),
                    None => futures::stream::pending().right_stream(),
                };
                let cmp = match &camera.compressed {
                    Some(sub) => sub
                        .async_stream()
                        .map(|r| match r {
                            Ok((m, _)) => Incoming::Compressed(m, Instant::now()),
                            Err(e) => Incoming::Error(format!(
                                "cannot read a compressed image message: {e:?}"
                            )),
                        })
                        .left_stream(),
                    None => futures::stream::pending().right_stream(),
                };
                let mut both = std::pin::pin!(futures::stream::select(raw, cmp));
                while let Some(item) = both.next().await {
                    if shutdown.load(Ordering::Relaxed) {
                        break;
                    }
                    rx_slot.put(item);
                }
            })
        })
        .map_err(|e| RosError::Create {
            what: "reception thread".into(),
            reason: e.to_string(),
        })?;
    Ok((slot, handle))
}

/// The worker loop's state: the node logic, its DDS endpoints, the admitted requests
/// waiting for their turn and the timers.
struct Worker<'a> {
    core: NodeCore,
    ep: Endpoints,
    settings: &'a RosSettings,
    pending: std::collections::VecDeque<PendingReinit>,
    /// Refusals since the last log line (a flood of requests is not a flood of logs).
    refused: u32,
    last_refusal: String,
    next_diag: Instant,
    next_debug: Instant,
    /// The stamp of the last debug image published: a frame is drawn once, so the debug
    /// image stops when the camera does instead of repeating its last frame.
    last_debug_stamp: Option<bevt_msgs::builtin_interfaces::Time>,
    debug_period: Duration,
    /// `debug_image_rate_hz` now (0 = off).
    debug_rate_hz: f64,
    /// `diagnostics_period_s` now.
    diagnostics_period: Duration,
    /// The declared parameters and their current values.
    params: NodeParams,
}

impl Worker<'_> {
    fn log(&self, level: ros2_client::log::LogLevel, text: &str) {
        if level < self.settings.log_level {
            return;
        }
        let text = &crate::node::console::printable(text, crate::node::console::MAX_LOG_CHARS);
        ros2_client::rosout!(self.ep.node, level, "{}", text);
        crate::node::console::log(level, level, &self.settings.node_name, text);
    }

    fn publish(&self, o: &FrameOutputs) {
        // A failed publish (no memory, shut down) is logged by RustDDS; the node continues.
        let _ = self.ep.pub_det.publish(o.detections.clone());
        let _ = self.ep.pub_status.publish(o.status.clone());
    }

    /// Admits a request by the queue bound and the node's rate limit, or says why not.
    fn admit(&mut self) -> Result<(), ReinitResponse> {
        let len = self.pending.len();
        if len >= MAX_PENDING_REQUESTS {
            return Err(ReinitResponse {
                success: false,
                message: format!("refused: {len} requests already waiting; current track kept"),
            });
        }
        self.core.admit_reinit(Instant::now())
    }

    /// Step 1 of a turn: reads every request that arrived (reinit service, `init` topic,
    /// stop service); refuses at once what the rate limit refuses.
    fn read_requests(&mut self) {
        for _ in 0..MAX_REQUESTS_PER_TURN {
            let Ok(Some((id, req))) = self.ep.srv_reinit.receive_request() else {
                break;
            };
            match self.admit() {
                Ok(()) => self.pending.push_back(PendingReinit::Service(id, req)),
                Err(resp) => {
                    // Each refusal is answered; the log gets one summary per period.
                    self.refused = self.refused.saturating_add(1);
                    self.last_refusal = resp.message.clone();
                    let _ = self.ep.srv_reinit.send_response(id, resp);
                }
            }
        }
        for _ in 0..MAX_REQUESTS_PER_TURN {
            let Ok(Some((det, _))) = self.ep.sub_init.take() else {
                break;
            };
            let b = crate::convert::bbox_from_detection(&det);
            let req = crate::convert::reinit_request(b, det.header.stamp, &det.header.frame_id);
            match self.admit() {
                Ok(()) => self.pending.push_back(PendingReinit::Topic(req)),
                Err(resp) => {
                    self.refused = self.refused.saturating_add(1);
                    self.last_refusal = resp.message;
                }
            }
        }
        for _ in 0..MAX_REQUESTS_PER_TURN {
            let Ok(Some((id, _))) = self.ep.srv_stop.receive_request() else {
                break;
            };
            let resp = self.core.on_stop();
            self.log(
                ros2_client::log::LogLevel::Info,
                &format!("stop: {}", resp.message),
            );
            let _ = self.ep.srv_stop.send_response(id, resp);
        }
    }

    /// Step 1b: answers the parameter services; accepted changes take effect at once.
    fn serve_params(&mut self) {
        let settings = self.settings;
        let core = &mut self.core;
        let (diag, period, rate) = (
            &mut self.diagnostics_period,
            &mut self.debug_period,
            &mut self.debug_rate_hz,
        );
        let (node, pub_debug) = (&mut self.ep.node, &mut self.ep.pub_debug);
        let lines = self.ep.params.serve(&mut self.params, |change| {
            match change {
                Change::Node(n) => core.set_live_settings(n),
                Change::Tracker(spec) => {
                    core.retune((**spec).clone()).map_err(|e| e.to_string())?
                }
                Change::DiagnosticsPeriod(p) => *diag = *p,
                Change::DebugImageRate(r) => {
                    if *r > 0.0 && pub_debug.is_none() {
                        *pub_debug =
                            Some(debug_publisher(node, settings).map_err(|e| e.to_string())?);
                    }
                    *rate = *r;
                    *period = Duration::try_from_secs_f64(1.0 / r).unwrap_or(MAX_PERIOD);
                }
            }
            Ok(())
        });
        for (ok, l) in lines {
            let level = if ok {
                ros2_client::log::LogLevel::Info
            } else {
                ros2_client::log::LogLevel::Warn
            };
            self.log(level, &l);
        }
    }

    /// Step 2: tracks the newest camera frame, if one arrived within [`WORKER_WAIT`].
    fn track_newest(&mut self, slot: &Slot, observe: &mut impl FnMut(&FrameOutputs)) {
        match slot.take(WORKER_WAIT) {
            Some(Incoming::Raw(m, t)) => {
                self.core
                    .add_dropped(slot.dropped.swap(0, Ordering::Relaxed));
                let o = self.core.on_image(CameraMsg::Raw(&m), t);
                self.publish(&o);
                observe(&o);
            }
            Some(Incoming::Compressed(m, t)) => {
                self.core
                    .add_dropped(slot.dropped.swap(0, Ordering::Relaxed));
                let o = self.core.on_image(CameraMsg::Compressed(&m), t);
                self.publish(&o);
                observe(&o);
            }
            Some(Incoming::Error(e)) => {
                self.log(ros2_client::log::LogLevel::Warn, &crate::convert::clip(&e))
            }
            None => {}
        }
    }

    /// Step 3: serves at most one admitted request per turn (bounded work: see
    /// `NodeCore::on_reinit`).
    fn serve_one_request(&mut self, observe: &mut impl FnMut(&FrameOutputs)) {
        let Some(p) = self.pending.pop_front() else {
            return;
        };
        let (req, source) = match &p {
            PendingReinit::Service(_, r) => (r, "reinit"),
            PendingReinit::Topic(r) => (r, "init topic"),
        };
        let (resp, out) = self.core.on_reinit(req);
        let level = if resp.success {
            ros2_client::log::LogLevel::Info
        } else {
            ros2_client::log::LogLevel::Warn
        };
        self.log(level, &format!("{source}: {}", resp.message));
        if let Some(o) = out {
            self.publish(&o);
            observe(&o);
        }
        if let PendingReinit::Service(id, _) = p {
            let _ = self.ep.srv_reinit.send_response(id, resp);
        }
    }

    /// Step 4: the timers: the debug image, then status, diagnostics and the summary of
    /// refused requests once per diagnostics period.
    fn run_timers(&mut self, now: Instant) {
        if let (Some(p), true) = (&self.ep.pub_debug, self.debug_rate_hz > 0.0) {
            if now >= self.next_debug {
                if let Some(img) = self.core.debug_image() {
                    if self.last_debug_stamp != Some(img.header.stamp) {
                        self.next_debug = later(now, self.debug_period);
                        self.last_debug_stamp = Some(img.header.stamp);
                        let _ = p.publish(img);
                    }
                }
            }
        }
        if now >= self.next_diag {
            self.next_diag = later(now, self.diagnostics_period);
            if self.refused > 0 {
                self.log(
                    ros2_client::log::LogLevel::Warn,
                    &format!(
                        "{} re-initialisation request(s) refused, the last: {}",
                        self.refused, self.last_refusal
                    ),
                );
                self.refused = 0;
            }
            if let Some(s) = self.core.on_tick(now) {
                let _ = self.ep.pub_status.publish(s);
            }
            let _ = self.ep.pub_diag.publish(self.core.diagnostics());
        }
    }
}

/// Runs the node until `shutdown` is set. `observe` sees every output set (for logs/tests).
///
/// # Errors
/// [`RosError`] when DDS entities cannot be created.
pub fn run(
    core: NodeCore,
    settings: &RosSettings,
    shutdown: Arc<AtomicBool>,
    mut observe: impl FnMut(&FrameOutputs),
) -> Result<(), RosError> {
    let (ep, camera) = create_endpoints(settings)?;
    let debug_period =
        Duration::try_from_secs_f64(1.0 / settings.debug_image_rate_hz).unwrap_or(MAX_PERIOD);
    let (slot, reception) = spawn_reception(camera, shutdown.clone())?;
    let params = NodeParams::new(settings, core.settings(), &core.spec().config);
    let mut w = Worker {
        params,
        debug_rate_hz: settings.debug_image_rate_hz,
        diagnostics_period: settings.diagnostics_period,
        core,
        ep,
        settings,
        pending: Default::default(),
        refused: 0,
        last_refusal: String::new(),
        next_diag: Instant::now(),
        next_debug: Instant::now(),
        last_debug_stamp: None,
        debug_period,
    };
    w.log(
        ros2_client::log::LogLevel::Info,
        "started: waiting for images and an initial box",
    );
    let mut tracked_any = false;
    while !shutdown.load(Ordering::Relaxed) {
        // A reception thread that ended while running would leave a node that publishes
        // nothing: stop with the reason, so the process exits non-zero and is restarted.
        if reception.is_finished() && !shutdown.load(Ordering::Relaxed) {
            let reason = match reception.join() {
                Ok(()) => "it returned (its subscriptions ended)".to_string(),
                Err(p) => format!("it panicked: {}", panic_message(p.as_ref())),
            };
            let e = RosError::ThreadEnded {
                thread: RECEPTION_THREAD,
                reason,
            };
            w.log(ros2_client::log::LogLevel::Fatal, &e.to_string());
            return Err(e);
        }
        w.read_requests();
        w.serve_params();
        w.track_newest(&slot, &mut |o: &FrameOutputs| {
            tracked_any = true;
            observe(o)
        });
        if tracked_any && INJECTED_FAULT.get() == Some(&InjectedFault::WorkerPanics) {
            injected_panic("the worker");
        }
        w.serve_one_request(&mut observe);
        w.run_timers(Instant::now());
    }
    w.log(ros2_client::log::LogLevel::Info, "shutting down");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_interface_address_the_host_lacks_is_named_with_its_parameter() {
        // 192.0.2.1 is TEST-NET-1 (RFC 5737): never an address of this host. Binding to it
        // fails locally; no packet is sent.
        let s = RosSettings {
            networks: vec![IpAddr::from([192, 0, 2, 1])],
            ..RosSettings::default()
        };
        let e = context(&s).err().expect("refused").to_string();
        assert!(e.contains("network_interfaces: 192.0.2.1"), "{e}");
        assert!(!e.contains("ParticipantId"), "{e}");
    }

    #[test]
    fn names_resolve_remaps_and_namespaces() {
        let mut s = RosSettings::default();
        assert!(ros_name(&s, names::IMAGE).is_ok());
        assert!(ros_name(&s, names::IMAGE_COMPRESSED).is_ok());
        assert!(ros_name(&s, names::DIAGNOSTICS).is_ok());
        s.remaps
            .push(("image_raw".into(), "/camera/color/image_raw".into()));
        let n = ros_name(&s, names::IMAGE).unwrap();
        let node = NodeName::new("/drone", "bevt_node").unwrap();
        assert_eq!(n.to_dds_name("rt", &node, ""), "rt/camera/color/image_raw");
        let root = NodeName::new("/", "bevt_node").unwrap();
        assert_eq!(
            ros_name(&s, names::DETECTIONS)
                .unwrap()
                .to_dds_name("rt", &root, ""),
            "rt/detections"
        );
        s.namespace = "/drone".into();
        let d = ros_name(&s, names::DETECTIONS).unwrap();
        assert_eq!(d.to_dds_name("rt", &node, ""), "rt/drone/detections");
        // The compressed input follows the remapped raw topic (image_transport).
        let c = ros_name(&s, names::IMAGE_COMPRESSED).unwrap();
        assert_eq!(
            c.to_dds_name("rt", &node, ""),
            "rt/camera/color/image_raw/compressed"
        );
        s.remaps.push(("detections".into(), "bad name!".into()));
        assert!(ros_name(&s, names::DETECTIONS).is_err());
    }

    #[test]
    fn the_compressed_input_follows_the_raw_topic_as_image_transport_does() {
        let node = NodeName::new("/drone", "bevt_node").unwrap();
        let dds = |s: &RosSettings| {
            ros_name(s, names::IMAGE_COMPRESSED)
                .unwrap()
                .to_dds_name("rt", &node, "")
        };
        let mut s = RosSettings::default();
        assert_eq!(dds(&s), "rt/image_raw/compressed");
        s.remaps
            .push(("image_raw".into(), "/camera/image_raw".into()));
        assert_eq!(dds(&s), "rt/camera/image_raw/compressed");
        // A relative remap stays in the namespace.
        s.namespace = "/drone".into();
        s.remaps = vec![("image_raw".into(), "cam/image".into())];
        assert_eq!(dds(&s), "rt/drone/cam/image/compressed");
        // An explicit remap of the compressed topic wins.
        s.remaps
            .push(("image_raw/compressed".into(), "/jpeg/stream".into()));
        assert_eq!(dds(&s), "rt/jpeg/stream");
        // The raw topic itself is unaffected by the compressed rule.
        assert_eq!(
            ros_name(&s, names::IMAGE)
                .unwrap()
                .to_dds_name("rt", &node, ""),
            "rt/drone/cam/image"
        );
    }
}
