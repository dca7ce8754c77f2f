//! A synthetic camera and a simulated ground station over DDS, for the demo, the
//! integration tests and the latency benchmark: the same code a real deployment's
//! peers would run, with exact ground truth.

use crate::node::ros::{
    camera_qos, context, output_qos, ros_name, service_qos, RosError, RosSettings,
};
use bevt_core::eval::synth::SynthParams;
use bevt_core::BBox;
use bevt_msgs::bevt::{ReinitRequest, ReinitResponse, TrackStatus};
use bevt_msgs::builtin_interfaces::Time;
use bevt_msgs::sensor_msgs::Image;
use bevt_msgs::std_msgs::Header;
use bevt_msgs::vision_msgs::Detection2DArray;
use bevt_msgs::RosType;
use ros2_client::{
    Client, Context, MessageTypeName, Node, NodeName, NodeOptions, RmwRequestId, ServiceTypeName,
    Subscription,
};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// Ground truth by image stamp (nanoseconds).
pub type TruthLog = Arc<Mutex<BTreeMap<i64, BBox>>>;

/// Truth entries kept.
const TRUTH_KEEP: usize = 10_000;

/// The wall clock as a ROS stamp (what the synthetic camera stamps frames with).
pub fn wall_stamp() -> Time {
    let d = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap_or_default();
    Time::from_nanos(d.as_nanos().min(i64::MAX as u128) as i64)
}

fn node(ctx: &Context, name: &str) -> Result<Node, RosError> {
    let n = NodeName::new("/", name).map_err(|e| RosError::Name(name.into(), format!("{e:?}")))?;
    ctx.new_node(n, NodeOptions::new())
        .map_err(|e| RosError::Create {
            what: format!("node {name}"),
            reason: format!("{e:?}"),
        })
}

/// Publishes a synthetic sequence as `sensor_msgs/Image` (rgb8) at `rate_hz` on the node's
/// `image_raw` (as resolved by `settings`) until `stop`, looping over the sequence.
/// Every frame's stamp (wall clock) and true box go into the returned log.
///
/// # Errors
/// [`RosError`] when DDS entities cannot be created.
pub fn spawn_camera(
    settings: &RosSettings,
    seq: SynthParams,
    rate_hz: f64,
    stop: Arc<AtomicBool>,
) -> Result<(std::thread::JoinHandle<()>, TruthLog), RosError> {
    spawn_camera_as(settings, seq, rate_hz, stop, None)
}

/// [`spawn_camera`], publishing `sensor_msgs/CompressedImage` JPEG of this quality (1..=100)
/// on `image_raw/compressed` instead when `jpeg_quality` is set. Frames are encoded once,
/// when first rendered, so the camera's own cost does not grow.
///
/// # Errors
/// [`RosError`] when DDS entities cannot be created.
pub fn spawn_camera_as(
    settings: &RosSettings,
    seq: SynthParams,
    rate_hz: f64,
    stop: Arc<AtomicBool>,
    jpeg_quality: Option<u8>,
) -> Result<(std::thread::JoinHandle<()>, TruthLog), RosError> {
    let ctx = context(settings)?;
    let mut cam = node(&ctx, "bevt_sim_camera")?;
    let create = |what: &'static str| {
        move |e: ros2_client::CreateError| RosError::Create {
            what: what.into(),
            reason: format!("{e:?}"),
        }
    };
    // The node's input name, resolved in its namespace (absolute).
    let (publisher, jpeg_publisher) = match jpeg_quality {
        None => {
            let abs = ros_name(settings, crate::node::ros::names::IMAGE)?;
            let topic = cam
                .create_topic(
                    &abs,
                    MessageTypeName::new(Image::PACKAGE, Image::NAME),
                    &camera_qos(),
                )
                .map_err(create("camera topic"))?;
            let p = cam
                .create_publisher::<Image>(&topic, Some(camera_qos()))
                .map_err(create("camera publisher"))?;
            (Some(p), None)
        }
        Some(_) => {
            let abs = ros_name(settings, crate::node::ros::names::IMAGE_COMPRESSED)?;
            let topic = cam
                .create_topic(
                    &abs,
                    MessageTypeName::new("sensor_msgs", "CompressedImage"),
                    &camera_qos(),
                )
                .map_err(create("camera topic"))?;
            let p = cam
                .create_publisher::<bevt_msgs::sensor_msgs::CompressedImage>(
                    &topic,
                    Some(camera_qos()),
                )
                .map_err(create("camera publisher"))?;
            (None, Some(p))
        }
    };
    let mut jpegs: Vec<Vec<u8>> = Vec::new();
    let log: TruthLog = Arc::default();
    let log2 = log.clone();
    let period = Duration::from_secs_f64(1.0 / rate_hz.max(0.1));
    let handle = std::thread::Builder::new()
        .name("bevt-sim-camera".into())
        .spawn(move || {
            let _keep = (ctx, cam);
            // Frames are rendered on first use and reused when the sequence loops.
            let mut frames: Vec<bevt_core::eval::synth::SynthFrame> =
                Vec::with_capacity(seq.frames);
            let mut next = Instant::now();
            let mut t = 0usize;
            while !stop.load(Ordering::Relaxed) {
                let i = t % seq.frames.max(1);
                if i == frames.len() {
                    frames.push(seq.frame(i));
                }
                let f = &frames[i];
                let stamp = wall_stamp();
                if let Ok(mut l) = log2.lock() {
                    l.insert(stamp.as_nanos(), f.truth);
                    while l.len() > TRUTH_KEEP {
                        l.pop_first();
                    }
                }
                let header = Header {
                    stamp,
                    frame_id: "sim_camera".into(),
                };
                if let Some(publisher) = &publisher {
                    let _ = publisher.publish(Image {
                        header,
                        height: seq.height as u32,
                        width: seq.width as u32,
                        encoding: "rgb8".into(),
                        is_bigendian: 0,
                        step: (seq.width * 3) as u32,
                        data: f.rgb.clone(),
                    });
                } else if let (Some(publisher), Some(q)) = (&jpeg_publisher, jpeg_quality) {
                    if i == jpegs.len() {
                        let mut data = Vec::new();
                        let _ = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut data, q)
                            .encode(
                                &f.rgb,
                                seq.width as u32,
                                seq.height as u32,
                                image::ExtendedColorType::Rgb8,
                            );
                        jpegs.push(data);
                    }
                    let _ = publisher.publish(bevt_msgs::sensor_msgs::CompressedImage {
                        header,
                        format: "jpeg".into(),
                        data: jpegs[i].clone(),
                    });
                }
                t += 1;
                next += period;
                let now = Instant::now();
                if next > now {
                    std::thread::sleep(next - now);
                } else {
                    next = now;
                }
            }
        })
        .map_err(|e| RosError::Create {
            what: "camera thread".into(),
            reason: e.to_string(),
        })?;
    Ok((handle, log))
}

/// A ground station: calls `reinit` and watches `detections`.
pub struct GroundStation {
    _ctx: Context,
    _node: Node,
    client: Client<ReinitRequest, ReinitResponse>,
    detections: Subscription<Detection2DArray>,
    status: Subscription<TrackStatus>,
    /// Earlier attempts of a [`Self::reinit`] call that was answered through another
    /// attempt: their late replies are not handed to [`Self::take_reinit_replies`].
    superseded: Mutex<Vec<RmwRequestId>>,
}

/// First wait for a `reinit` reply before the request is sent again; doubled per attempt.
const REINIT_RETRY_FIRST: Duration = Duration::from_secs(2);
/// Longest wait between two attempts of one `reinit` call.
const REINIT_RETRY_MAX: Duration = Duration::from_secs(4);
/// Superseded request ids remembered (oldest forgotten first).
const MAX_SUPERSEDED: usize = 64;

impl GroundStation {
    /// Connects to the node described by `settings`.
    ///
    /// # Errors
    /// [`RosError`] when DDS entities cannot be created.
    pub fn new(settings: &RosSettings) -> Result<Self, RosError> {
        let ctx = context(settings)?;
        let mut n = node(&ctx, "bevt_sim_ground_station")?;
        let abs = |rel: &str| ros_name(settings, rel);
        let sq = output_qos();
        let client = n
            .create_client::<ReinitRequest, ReinitResponse>(
                settings.service_mapping,
                &abs(crate::node::ros::names::REINIT)?,
                &ServiceTypeName::new("bevt_msgs", "Reinit"),
                service_qos(),
                service_qos(),
            )
            .map_err(|e| RosError::Create {
                what: "reinit client".into(),
                reason: format!("{e:?}"),
            })?;
        let topic = n
            .create_topic(
                &abs(crate::node::ros::names::DETECTIONS)?,
                MessageTypeName::new(Detection2DArray::PACKAGE, Detection2DArray::NAME),
                &sq,
            )
            .map_err(|e| RosError::Create {
                what: "detections topic".into(),
                reason: format!("{e:?}"),
            })?;
        let detections = n
            .create_subscription::<Detection2DArray>(&topic, Some(sq.clone()))
            .map_err(|e| RosError::Create {
                what: "detections subscription".into(),
                reason: format!("{e:?}"),
            })?;
        let st = n
            .create_topic(
                &abs(crate::node::ros::names::TRACK_STATUS)?,
                MessageTypeName::new(TrackStatus::PACKAGE, TrackStatus::NAME),
                &sq,
            )
            .map_err(|e| RosError::Create {
                what: "status topic".into(),
                reason: format!("{e:?}"),
            })?;
        let status = n
            .create_subscription::<TrackStatus>(&st, Some(sq))
            .map_err(|e| RosError::Create {
                what: "status subscription".into(),
                reason: format!("{e:?}"),
            })?;
        Ok(Self {
            _ctx: ctx,
            _node: n,
            client,
            detections,
            status,
            superseded: Mutex::new(Vec::new()),
        })
    }

    /// Calls `reinit`, sending the request again until `timeout` (the first requests may be
    /// lost while discovery completes), with a doubling wait between attempts so a slow
    /// node is not sent duplicates. A reply to any attempt answers the call; the other
    /// attempts' late replies are dropped. `None` on timeout.
    ///
    /// Each attempt is a separate request: a node slower than the wait may serve two.
    pub fn reinit(&self, req: &ReinitRequest, timeout: Duration) -> Option<ReinitResponse> {
        let end = Instant::now() + timeout;
        let mut sent: Vec<RmwRequestId> = Vec::new();
        let mut wait = REINIT_RETRY_FIRST;
        let mut answer = None;
        'attempts: while Instant::now() < end {
            let Ok(id) = self.client.send_request(req.clone()) else {
                std::thread::sleep(Duration::from_millis(50));
                continue;
            };
            sent.push(id);
            let retry = Instant::now() + wait;
            wait = (wait * 2).min(REINIT_RETRY_MAX);
            while Instant::now() < retry.min(end) {
                match self.client.receive_response() {
                    Ok(Some((rid, resp))) if sent.contains(&rid) => {
                        sent.retain(|s| *s != rid);
                        answer = Some(resp);
                        break 'attempts;
                    }
                    _ => std::thread::sleep(Duration::from_millis(5)),
                }
            }
        }
        let mut superseded = self.superseded.lock().unwrap_or_else(|e| e.into_inner());
        superseded.extend(sent);
        let excess = superseded.len().saturating_sub(MAX_SUPERSEDED);
        superseded.drain(..excess);
        answer
    }

    /// Starts a track on the newest frame the camera published (its truth box and stamp),
    /// as an operator clicking the live picture would: a refusal that only says the node
    /// does not have that frame (yet, or any more) is answered by asking again on the then
    /// newest frame, until `timeout`. Such refusals are expected, not faults: the node
    /// keeps a bounded buffer of recent frames, and on a loaded machine the first request
    /// can wait for DDS matching longer than the buffer spans. Any other answer, success
    /// or refusal, is returned; `None` when no answer came in time.
    pub fn start_track_on_newest(
        &self,
        truth: &TruthLog,
        timeout: Duration,
    ) -> Option<ReinitResponse> {
        let end = Instant::now() + timeout;
        let mut last = None;
        while Instant::now() < end {
            let newest = truth
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .iter()
                .next_back()
                .map(|(k, b)| (*k, *b));
            let Some((stamp, b)) = newest else {
                std::thread::sleep(Duration::from_millis(50));
                continue;
            };
            let req = crate::convert::reinit_request(b, Time::from_nanos(stamp), "");
            let left = end.saturating_duration_since(Instant::now());
            let Some(r) = self.reinit(&req, left) else {
                break;
            };
            let transient = r.message.contains("no buffered frame")
                || r.message.contains("no camera frame received yet");
            if r.success || !transient {
                return Some(r);
            }
            last = Some(r);
            std::thread::sleep(Duration::from_millis(100));
        }
        last
    }

    /// Sends one `reinit` request without waiting (for bursts); false when it could not be
    /// sent. Replies are read with [`Self::take_reinit_replies`].
    pub fn send_reinit(&self, req: &ReinitRequest) -> bool {
        self.client.send_request(req.clone()).is_ok()
    }

    /// `reinit` replies received so far (non-blocking).
    pub fn take_reinit_replies(&self) -> Vec<ReinitResponse> {
        let mut superseded = self.superseded.lock().unwrap_or_else(|e| e.into_inner());
        let mut out = Vec::new();
        while let Ok(Some((id, r))) = self.client.receive_response() {
            if let Some(i) = superseded.iter().position(|s| *s == id) {
                superseded.swap_remove(i);
            } else {
                out.push(r);
            }
        }
        out
    }

    /// Track statuses received so far (non-blocking).
    pub fn take_status(&self) -> Vec<TrackStatus> {
        let mut out = Vec::new();
        while let Ok(Some((d, _))) = self.status.take() {
            out.push(d);
        }
        out
    }

    /// Detections received so far (non-blocking).
    pub fn take_detections(&self) -> Vec<Detection2DArray> {
        let mut out = Vec::new();
        while let Ok(Some((d, _))) = self.detections.take() {
            out.push(d);
        }
        out
    }
}

/// A hand-driven peer that publishes arbitrary camera messages and `init` boxes (for
/// tests of bad input and of the topic interfaces).
pub struct RawPeer {
    _ctx: Context,
    _node: Node,
    image: ros2_client::Publisher<Image>,
    compressed: ros2_client::Publisher<bevt_msgs::sensor_msgs::CompressedImage>,
    init: ros2_client::Publisher<bevt_msgs::vision_msgs::Detection2D>,
}

impl RawPeer {
    /// Connects to the node described by `settings`.
    ///
    /// # Errors
    /// [`RosError`] when DDS entities cannot be created.
    pub fn new(settings: &RosSettings) -> Result<Self, RosError> {
        use bevt_msgs::sensor_msgs::CompressedImage;
        let ctx = context(settings)?;
        let mut n = node(&ctx, "bevt_sim_raw_peer")?;
        let err = |what: &str| {
            let what = what.to_string();
            move |e: ros2_client::CreateError| RosError::Create {
                what: what.clone(),
                reason: format!("{e:?}"),
            }
        };
        let cq = camera_qos();
        let oq = output_qos();
        let t = n
            .create_topic(
                &ros_name(settings, crate::node::ros::names::IMAGE)?,
                MessageTypeName::new(Image::PACKAGE, Image::NAME),
                &cq,
            )
            .map_err(err("image topic"))?;
        let image = n
            .create_publisher::<Image>(&t, Some(cq.clone()))
            .map_err(err("image publisher"))?;
        let t = n
            .create_topic(
                &ros_name(settings, crate::node::ros::names::IMAGE_COMPRESSED)?,
                MessageTypeName::new(CompressedImage::PACKAGE, CompressedImage::NAME),
                &cq,
            )
            .map_err(err("compressed topic"))?;
        let compressed = n
            .create_publisher::<CompressedImage>(&t, Some(cq.clone()))
            .map_err(err("compressed publisher"))?;
        let t = n
            .create_topic(
                &ros_name(settings, crate::node::ros::names::INIT)?,
                MessageTypeName::new("vision_msgs", "Detection2D"),
                &oq,
            )
            .map_err(err("init topic"))?;
        let init = n
            .create_publisher::<bevt_msgs::vision_msgs::Detection2D>(&t, Some(oq))
            .map_err(err("init publisher"))?;
        Ok(Self {
            _ctx: ctx,
            _node: n,
            image,
            compressed,
            init,
        })
    }

    /// Publishes an image (any content, valid or not).
    pub fn image(&self, m: Image) {
        let _ = self.image.publish(m);
    }

    /// Publishes a compressed image.
    pub fn compressed(&self, m: bevt_msgs::sensor_msgs::CompressedImage) {
        let _ = self.compressed.publish(m);
    }

    /// Publishes an initial box on the `init` topic.
    pub fn init(&self, d: bevt_msgs::vision_msgs::Detection2D) {
        let _ = self.init.publish(d);
    }
}
