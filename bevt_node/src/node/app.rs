//! The tracking node's logic, independent of DDS: what to do with each camera frame,
//! re-initialisation request, stop request and timer tick, and what to publish.
//!
//! [`NodeCore`] is driven by the ROS layer (`ros.rs`) and, in tests, directly with
//! recorded or synthetic messages. It keeps a short ring buffer of recent frames so an
//! operator's box, drawn on a frame that reached the ground station late, initialises on
//! *that* frame; the newer buffered frames are then tracked through (fast-forward) so the
//! published track is current. A bad request is answered `success = false` with the
//! reason, and the current track is kept.
//!
//! Bounds (all from [`NodeSettings`]): a camera frame over [`ImageLimits`] is an error
//! that is neither decoded nor buffered and leaves the track as it is; the ring buffer
//! holds at most `reinit_buffer_frames` frames and `reinit_buffer_bytes` bytes and gives
//! memory back after large frames; a request fast-forwards through at most
//! `reinit_max_fast_forward` frames; requests are admitted by a token bucket
//! ([`ReinitGate`]: `reinit_rate_hz`, `reinit_burst`), and the ROS layer serves at most one
//! admitted request per camera frame, answering the others at once with the reason.

use crate::convert::{
    clip, detections_from_output, frame_from_compressed, frame_from_compressed_view,
    frame_from_image, frame_from_image_view, ImageLimits, PixelBuffer,
};
use bevt_core::{
    BBox, BevtTracker, Frame, PixelFormat, TrackOutput, TrackState, Tracker, TrackerSpec,
};
use bevt_msgs::bevt::{ReinitRequest, ReinitResponse, TrackStatus};
use bevt_msgs::builtin_interfaces::Time;
use bevt_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus, KeyValue};
use bevt_msgs::sensor_msgs::{CompressedImage, CompressedImageView, Image, ImageView};
use bevt_msgs::std_msgs::Header;
use bevt_msgs::std_srvs::TriggerResponse;
use bevt_msgs::vision_msgs::Detection2DArray;
use std::collections::VecDeque;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// Line thickness of the debug image's box, pixels.
const DEBUG_LINE_PX: i64 = 2;
/// A recycled ring-buffer slot is reused when its capacity exceeds the frame by at most
/// 1/`SLOT_SLACK`; otherwise it is freed and an exact one allocated.
const SLOT_SLACK: usize = 4;

/// Settings of the node logic. Ranges are checked where they are loaded
/// ([`crate::node::node_params`]); values outside them are clamped here so nothing panics.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeSettings {
    /// `class_id` of published hypotheses.
    pub class_id: String,
    /// Recent frames kept for delayed re-initialisation.
    pub reinit_buffer_frames: usize,
    /// Most bytes of pixels the re-initialisation buffer holds (older frames are dropped
    /// first).
    pub reinit_buffer_bytes: usize,
    /// Most buffered frames one request tracks through to reach the newest frame; older
    /// requests track through an evenly spaced subset of them.
    pub reinit_max_fast_forward: usize,
    /// Re-initialisation requests admitted per second (steady rate).
    pub reinit_rate_hz: f64,
    /// Requests admitted at once after a quiet period (token-bucket depth).
    pub reinit_burst: u32,
    /// Largest camera frame accepted.
    pub image_limits: ImageLimits,
    /// No image for this long while tracking: the status says the camera is stale.
    pub stale_timeout: Duration,
    /// Name used in diagnostics.
    pub node_name: String,
}

impl Default for NodeSettings {
    fn default() -> Self {
        Self {
            class_id: "target".into(),
            reinit_buffer_frames: 30,
            reinit_buffer_bytes: 256 << 20,
            reinit_max_fast_forward: 5,
            reinit_rate_hz: 1.0,
            reinit_burst: 3,
            image_limits: ImageLimits::default(),
            stale_timeout: Duration::from_secs(2),
            node_name: "bevt_node".into(),
        }
    }
}

/// Admission of re-initialisation requests: a token bucket of `burst` tokens refilled at
/// `rate_hz`. Each request takes a token or is refused with the reason.
#[derive(Debug, Clone)]
pub struct ReinitGate {
    rate_hz: f64,
    burst: f64,
    tokens: f64,
    last: Option<Instant>,
}

impl ReinitGate {
    /// A full bucket.
    pub fn new(rate_hz: f64, burst: u32) -> Self {
        let burst = f64::from(burst.max(1));
        Self {
            rate_hz: if rate_hz.is_finite() {
                rate_hz.max(0.0)
            } else {
                0.0
            },
            burst,
            tokens: burst,
            last: None,
        }
    }

    /// A new rate and depth for a running gate: the tokens already spent stay spent (a
    /// live change must not refill the bucket, or changing it would lift the limit).
    pub fn retune(&mut self, rate_hz: f64, burst: u32) {
        let fresh = Self::new(rate_hz, burst);
        self.rate_hz = fresh.rate_hz;
        self.burst = fresh.burst;
        self.tokens = self.tokens.min(self.burst);
    }

    /// Takes a token at `now`.
    ///
    /// # Errors
    /// The refusal message (rate limit and when the next token is due).
    pub fn admit(&mut self, now: Instant) -> Result<(), String> {
        if let Some(last) = self.last {
            let dt = now.saturating_duration_since(last).as_secs_f64();
            self.tokens = (self.tokens + dt * self.rate_hz).min(self.burst);
        }
        self.last = Some(now);
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            Ok(())
        } else {
            let wait = if self.rate_hz > 0.0 {
                (1.0 - self.tokens) / self.rate_hz
            } else {
                f64::INFINITY
            };
            Err(format!(
                "refused: rate limit of {} requests/s (burst {}) exceeded, next accepted in {wait:.2} s; current track kept",
                self.rate_hz, self.burst
            ))
        }
    }
}

/// A camera message.
#[derive(Debug, Clone, Copy)]
pub enum CameraMsg<'a> {
    /// `sensor_msgs/Image`.
    Raw(&'a Image),
    /// `sensor_msgs/CompressedImage`.
    Compressed(&'a CompressedImage),
    /// `sensor_msgs/Image` borrowed from a serialised message (`bevt replay`).
    RawView(&'a ImageView<'a>),
    /// `sensor_msgs/CompressedImage` borrowed from a serialised message (`bevt replay`).
    CompressedView(&'a CompressedImageView<'a>),
}

impl CameraMsg<'_> {
    fn header(&self) -> &Header {
        match self {
            CameraMsg::Raw(m) => &m.header,
            CameraMsg::Compressed(m) => &m.header,
            CameraMsg::RawView(m) => &m.header,
            CameraMsg::CompressedView(m) => &m.header,
        }
    }
}

/// What to publish after a frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameOutputs {
    /// `detections` (empty while idle).
    pub detections: Detection2DArray,
    /// `track_status`.
    pub status: TrackStatus,
}

/// An owned, packed copy of a frame for the ring buffer.
#[derive(Debug, Clone)]
struct Buffered {
    header: Header,
    width: usize,
    height: usize,
    stride: usize,
    format: PixelFormat,
    data: Vec<u8>,
}

impl Buffered {
    /// Packed copy of `frame` into `slot` (a recycled buffer), which is replaced when it
    /// would keep much more capacity than this frame needs.
    fn copy(header: Header, frame: &Frame<'_>, slot: Option<Vec<u8>>) -> Self {
        let (w, h) = (frame.width(), frame.height());
        let row = w * frame.format().bytes_per_pixel();
        let need = row * h;
        let mut data = slot
            .filter(|d| d.capacity() >= need && d.capacity() <= need + need / SLOT_SLACK)
            .unwrap_or_else(|| Vec::with_capacity(need));
        data.clear();
        let (src, stride) = (frame.data(), frame.stride());
        for r in 0..h {
            data.extend_from_slice(&src[r * stride..r * stride + row]);
        }
        Self {
            header,
            width: w,
            height: h,
            stride: row,
            format: frame.format(),
            data,
        }
    }

    /// Bytes held.
    fn bytes(&self) -> usize {
        self.data.capacity()
    }

    fn frame(&self) -> Option<Frame<'_>> {
        Frame::new(
            &self.data,
            self.width,
            self.height,
            self.stride,
            self.format,
        )
        .ok()
    }
}

/// The node logic.
pub struct NodeCore {
    spec: TrackerSpec,
    settings: NodeSettings,
    tracker: BevtTracker,
    buffer: VecDeque<Buffered>,
    buffer_bytes: usize,
    gate: ReinitGate,
    pixels: PixelBuffer,
    track_id: u32,
    frames_processed: u32,
    frames_dropped: u32,
    last_output: Option<TrackOutput>,
    /// `STATE_LOST` means the tracker lost the target (not a dropped track or stale camera).
    target_lost: bool,
    last_header: Header,
    last_image_at: Option<Instant>,
    state: u8,
    reason: String,
}

impl std::fmt::Debug for NodeCore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NodeCore")
            .field("state", &self.state)
            .field("track_id", &self.track_id)
            .field("buffered", &self.buffer.len())
            .finish()
    }
}

/// `track_status` state and reason of one tracked frame.
fn status_of(o: &TrackOutput) -> (u8, String) {
    match o.state {
        // Tracking with a reason: unconfident, but the verifier confirmed the target.
        TrackState::Tracking if !matches!(o.reason, bevt_core::StateReason::Confident) => {
            (TrackStatus::STATE_TRACKING, o.reason.to_string())
        }
        TrackState::Tracking if o.learned => (TrackStatus::STATE_TRACKING, String::new()),
        TrackState::Tracking => (
            TrackStatus::STATE_LOW_CONSENSUS,
            format!(
                "verification: frame not learned (consensus {:.3}, confidence {:.2})",
                o.consensus, o.confidence
            ),
        ),
        TrackState::Uncertain => (TrackStatus::STATE_UNCERTAIN, o.reason.to_string()),
        TrackState::Lost => (TrackStatus::STATE_LOST, o.reason.to_string()),
        TrackState::Reacquired => (TrackStatus::STATE_REACQUIRED, o.reason.to_string()),
    }
}

fn now_stamp() -> Time {
    let d = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap_or_default();
    Time::from_nanos(d.as_nanos().min(i64::MAX as u128) as i64)
}

/// Offsets (1-based, past the request's frame) of the buffered frames a request tracks
/// through: all `newer` when they are at most `max`, else `max` evenly spaced ones ending
/// with the newest.
fn fast_forward_steps(newer: usize, max: usize) -> Vec<usize> {
    if newer <= max {
        (1..=newer).collect()
    } else {
        (1..=max).map(|k| (k * newer).div_ceil(max)).collect()
    }
}

impl NodeCore {
    /// A node with no target.
    pub fn new(spec: TrackerSpec, settings: NodeSettings) -> Self {
        Self {
            tracker: BevtTracker::new(spec.clone()),
            spec,
            gate: ReinitGate::new(settings.reinit_rate_hz, settings.reinit_burst),
            settings,
            buffer: VecDeque::new(),
            buffer_bytes: 0,
            pixels: PixelBuffer::default(),
            track_id: 0,
            frames_processed: 0,
            frames_dropped: 0,
            last_output: None,
            target_lost: false,
            last_header: Header::default(),
            last_image_at: None,
            state: TrackStatus::STATE_IDLE,
            reason: "waiting for an initial box (reinit service or init topic)".into(),
        }
    }

    /// The node settings in use.
    pub fn settings(&self) -> &NodeSettings {
        &self.settings
    }

    /// The tracker specification in use (for new tracks too).
    pub fn spec(&self) -> &TrackerSpec {
        &self.spec
    }

    /// Takes the settings that may change while running ([`crate::node::param_services`]
    /// says which): `class_id`, `reinit_max_fast_forward`, `reinit_rate_hz`,
    /// `reinit_burst`, `stale_timeout`. The others (buffer, image limits, name) keep their
    /// start-up values. A new rate or burst keeps the tokens already spent.
    pub fn set_live_settings(&mut self, s: &NodeSettings) {
        if s.reinit_rate_hz != self.settings.reinit_rate_hz
            || s.reinit_burst != self.settings.reinit_burst
        {
            self.gate.retune(s.reinit_rate_hz, s.reinit_burst);
        }
        self.settings.class_id.clone_from(&s.class_id);
        self.settings.reinit_max_fast_forward = s.reinit_max_fast_forward;
        self.settings.reinit_rate_hz = s.reinit_rate_hz;
        self.settings.reinit_burst = s.reinit_burst;
        self.settings.stale_timeout = s.stale_timeout;
    }

    /// Takes a tracker specification that differs in live keys only (`bevt_core::config::live_keys`):
    /// the running track uses it from the next frame, and new tracks are built with it.
    ///
    /// # Errors
    /// [`bevt_core::ConfigError::NotLive`] when other keys differ; nothing changes.
    pub fn retune(&mut self, spec: TrackerSpec) -> Result<(), bevt_core::ConfigError> {
        self.tracker.retune(spec.clone())?;
        self.spec = spec;
        Ok(())
    }

    /// Adds frames the transport skipped because a newer one had arrived.
    pub fn add_dropped(&mut self, n: u32) {
        self.frames_dropped = self.frames_dropped.saturating_add(n);
    }

    /// Current state (a `TrackStatus::STATE_*`).
    pub fn state(&self) -> u8 {
        self.state
    }

    /// Processes one camera frame.
    pub fn on_image(&mut self, msg: CameraMsg<'_>, received: Instant) -> FrameOutputs {
        self.last_image_at = Some(received);
        let header = msg.header().clone();
        self.last_header = header.clone();
        // Convert (zero-copy where possible) and keep an owned copy for the ring buffer.
        let limits = self.settings.image_limits;
        let conv = match msg {
            CameraMsg::Raw(m) => frame_from_image(m, &mut self.pixels, &limits),
            CameraMsg::Compressed(m) => frame_from_compressed(m, &mut self.pixels, &limits),
            CameraMsg::RawView(m) => frame_from_image_view(m, &mut self.pixels, &limits),
            CameraMsg::CompressedView(m) => {
                frame_from_compressed_view(m, &mut self.pixels, &limits)
            }
        };
        let frame = match conv {
            Ok(f) => f,
            Err(e) => {
                // The frame is unusable (over a limit, truncated, malformed): it is not
                // buffered and the track (if any) is kept for the next one.
                self.state = TrackStatus::STATE_ERROR;
                self.reason = e.to_string();
                return self.outputs(&header, None, received);
            }
        };
        // Make room within the frame count and the byte budget, oldest first; recycle
        // the last slot dropped.
        let need = frame.width() * frame.height() * frame.format().bytes_per_pixel();
        let mut slot = None;
        while !self.buffer.is_empty()
            && (self.buffer.len() >= self.settings.reinit_buffer_frames.max(1)
                || self.buffer_bytes + need > self.settings.reinit_buffer_bytes)
        {
            if let Some(old) = self.buffer.pop_front() {
                self.buffer_bytes -= old.bytes();
                slot = Some(old.data);
            }
        }
        if need <= self.settings.reinit_buffer_bytes {
            let b = Buffered::copy(header.clone(), &frame, slot);
            self.buffer_bytes += b.bytes();
            self.buffer.push_back(b);
        }
        self.frames_processed = self.frames_processed.saturating_add(1);
        let out = if self.tracker.is_initialized() {
            let r = self.tracker.update(&frame);
            match r {
                Ok(o) => {
                    (self.state, self.reason) = status_of(&o);
                    self.target_lost = o.state == TrackState::Lost;
                    self.last_output = Some(o);
                    Some(o)
                }
                Err(bevt_core::TrackError::FrameMismatch { expected, got }) => {
                    self.tracker.reset();
                    self.last_output = None;
                    self.target_lost = false;
                    self.state = TrackStatus::STATE_LOST;
                    self.reason = format!(
                        "image changed from {expected} to {got}: track reset, re-initialise"
                    );
                    None
                }
                Err(e) => {
                    self.state = TrackStatus::STATE_ERROR;
                    self.reason = e.to_string();
                    None
                }
            }
        } else {
            if self.state == TrackStatus::STATE_ERROR {
                self.state = TrackStatus::STATE_IDLE;
                self.reason = "waiting for an initial box (reinit service or init topic)".into();
            }
            None
        };
        self.outputs(&header, out.as_ref(), received)
    }

    fn outputs(
        &self,
        header: &Header,
        out: Option<&TrackOutput>,
        received: Instant,
    ) -> FrameOutputs {
        let latency = Self::latency_ms(header, received);
        let b = out.map(|o| o.bbox).unwrap_or_default();
        let status = TrackStatus {
            header: header.clone(),
            state: self.state,
            reason: self.reason.clone(),
            x: b.x,
            y: b.y,
            width: b.w,
            height: b.h,
            consensus: out.map_or(0.0, |o| o.consensus),
            confidence: out.map_or(0.0, |o| o.confidence),
            learned: out.is_some_and(|o| o.learned),
            peak: out.map_or(0.0, |o| o.peak),
            scale: out.map_or(0.0, |o| o.scale),
            latency_ms: latency,
            frames_processed: self.frames_processed,
            frames_dropped: self.frames_dropped,
            track_id: self.track_id,
        };
        FrameOutputs {
            detections: detections_from_output(header, out, self.track_id, &self.settings.class_id),
            status,
        }
    }

    /// Image stamp to now when the stamp is a plausible wall-clock time, else arrival to now.
    fn latency_ms(header: &Header, received: Instant) -> f32 {
        let since_arrival = received.elapsed().as_secs_f32() * 1e3;
        if header.stamp.is_zero() {
            return since_arrival;
        }
        let d = now_stamp().as_nanos() - header.stamp.as_nanos();
        if (0..60_000_000_000).contains(&d) {
            d as f32 / 1e6
        } else {
            since_arrival
        }
    }

    /// Admission of a re-initialisation request arriving at `now` (token bucket, see
    /// [`ReinitGate`]). A refused request must be answered with the returned response.
    ///
    /// # Errors
    /// The refusal (`success = false` with the reason).
    pub fn admit_reinit(&mut self, now: Instant) -> Result<(), ReinitResponse> {
        self.gate.admit(now).map_err(|message| ReinitResponse {
            success: false,
            message,
        })
    }

    /// Handles a re-initialisation request; on success also returns the outputs for the
    /// newest buffered frame (after fast-forwarding).
    pub fn on_reinit(&mut self, req: &ReinitRequest) -> (ReinitResponse, Option<FrameOutputs>) {
        let fail = |message: String| {
            (
                ReinitResponse {
                    success: false,
                    message,
                },
                None,
            )
        };
        let b = BBox::new(
            req.x as f32,
            req.y as f32,
            req.width as f32,
            req.height as f32,
        );
        if !b.is_finite() || b.w <= 0.0 || b.h <= 0.0 {
            return fail(format!(
                "invalid box x={} y={} w={} h={}: must be finite with positive size; current track kept",
                req.x, req.y, req.width, req.height
            ));
        }
        let Some(newest) = self.buffer.back() else {
            return fail("no camera frame received yet; current track kept".into());
        };
        if !req.frame_id.is_empty() && req.frame_id != newest.header.frame_id {
            return fail(format!(
                "frame_id {:?} does not match the camera's {:?}; current track kept",
                clip(&req.frame_id),
                clip(&newest.header.frame_id)
            ));
        }
        let index = if req.stamp.is_zero() {
            self.buffer.len() - 1
        } else {
            match self.buffer.iter().position(|f| f.header.stamp == req.stamp) {
                Some(i) => i,
                None => {
                    let (o, n) = (
                        self.buffer
                            .front()
                            .map(|f| f.header.stamp)
                            .unwrap_or_default(),
                        newest.header.stamp,
                    );
                    return fail(format!(
                        "no buffered frame has stamp {}.{:09} (buffer holds {} frames, {}.{:09} .. {}.{:09}); current track kept",
                        req.stamp.sec, req.stamp.nanosec, self.buffer.len(), o.sec, o.nanosec, n.sec, n.nanosec
                    ));
                }
            }
        };
        // Initialise a fresh tracker so a failure leaves the current track untouched.
        let mut fresh = BevtTracker::new(self.spec.clone());
        let Some(frame) = self.buffer[index].frame() else {
            return fail("buffered frame is unusable; current track kept".into());
        };
        if let Err(e) = fresh.init(&frame, b) {
            return fail(format!("{e}; current track kept"));
        }
        let mut last = None;
        let newer = self.buffer.len() - 1 - index;
        let steps = fast_forward_steps(newer, self.settings.reinit_max_fast_forward);
        for k in &steps {
            let Some(frame) = self.buffer[index + k].frame() else {
                continue;
            };
            match fresh.update(&frame) {
                Ok(o) => last = Some(o),
                Err(e) => return fail(format!("fast-forward failed: {e}; current track kept")),
            }
        }
        let forwarded = if steps.len() == newer {
            format!("{newer}")
        } else {
            format!("{} of the {newer}", steps.len())
        };
        self.tracker = fresh;
        self.track_id = self.track_id.wrapping_add(1);
        let out = last.unwrap_or(TrackOutput {
            bbox: b,
            consensus: 1.0,
            learned: true,
            peak: 0.0,
            scale: 1.0,
            confidence: 1.0,
            state: bevt_core::TrackState::Tracking,
            reason: bevt_core::StateReason::Confident,
        });
        self.last_output = Some(out);
        self.state = TrackStatus::STATE_TRACKING;
        self.reason = String::new();
        let stamp = self.buffer[index].header.stamp;
        let header = self.buffer[self.buffer.len() - 1].header.clone();
        let outputs = self.outputs(&header, Some(&out), Instant::now());
        (
            ReinitResponse {
                success: true,
                message: format!(
                    "tracking (track {}) from the frame stamped {}.{:09}, fast-forwarded through {forwarded} newer frames",
                    self.track_id, stamp.sec, stamp.nanosec
                ),
            },
            Some(outputs),
        )
    }

    /// Stops tracking.
    pub fn on_stop(&mut self) -> TriggerResponse {
        let was = self.tracker.is_initialized();
        self.tracker.reset();
        self.last_output = None;
        self.state = TrackStatus::STATE_IDLE;
        self.reason = "stopped by request".into();
        TriggerResponse {
            success: true,
            message: if was {
                "tracking stopped".into()
            } else {
                "was not tracking".into()
            },
        }
    }

    /// Periodic check: while tracking, a camera silent for longer than the stale timeout is
    /// reported (the track is kept and resumes with the next frame).
    pub fn on_tick(&mut self, now: Instant) -> Option<TrackStatus> {
        let last = self.last_image_at?;
        let silent = now.saturating_duration_since(last);
        if self.tracker.is_initialized() && silent > self.settings.stale_timeout {
            self.state = TrackStatus::STATE_LOST;
            self.target_lost = false;
            self.reason = format!("camera stale: no image for {:.1} s", silent.as_secs_f32());
            let header = self.last_header.clone();
            return Some(self.outputs(&header, None, now).status);
        }
        None
    }

    /// The newest frame with the current box drawn (green: the frame was learned, yellow:
    /// not learned, i.e. `STATE_LOW_CONSENSUS` or a state that does not learn) and a bar above
    /// it whose length is the consensus score C × box width (C is reported; by default the
    /// learning gate and the track state use the confidence), in the camera's own encoding.
    /// `None` before the first usable frame.
    pub fn debug_image(&self) -> Option<Image> {
        let f = self.buffer.back()?;
        let (encoding, bpp) = match f.format {
            PixelFormat::Rgb8 => ("rgb8", 3),
            PixelFormat::Bgr8 => ("bgr8", 3),
            PixelFormat::Rgba8 => ("rgba8", 4),
            PixelFormat::Bgra8 => ("bgra8", 4),
            PixelFormat::Mono8 => ("mono8", 1),
        };
        let mut data = f.data.clone();
        if let (Some(o), true) = (self.last_output, self.tracker.is_initialized()) {
            let rgb = if o.learned {
                [40u8, 220, 40]
            } else {
                [240, 200, 0]
            };
            let px: Vec<u8> = match f.format {
                PixelFormat::Rgb8 => rgb.to_vec(),
                PixelFormat::Bgr8 => vec![rgb[2], rgb[1], rgb[0]],
                PixelFormat::Rgba8 => vec![rgb[0], rgb[1], rgb[2], 255],
                PixelFormat::Bgra8 => vec![rgb[2], rgb[1], rgb[0], 255],
                PixelFormat::Mono8 => vec![255],
            };
            let (w, h, stride) = (f.width as i64, f.height as i64, f.stride);
            let mut put = |x: i64, y: i64| {
                if (0..w).contains(&x) && (0..h).contains(&y) {
                    let i = y as usize * stride + x as usize * bpp;
                    data[i..i + bpp].copy_from_slice(&px);
                }
            };
            let b = o.bbox;
            let (x0, y0) = (b.x.round() as i64, b.y.round() as i64);
            let (x1, y1) = ((b.x + b.w).round() as i64, (b.y + b.h).round() as i64);
            for t in 0..DEBUG_LINE_PX {
                for x in x0..=x1 {
                    put(x, y0 + t);
                    put(x, y1 - t);
                }
                for y in y0..=y1 {
                    put(x0 + t, y);
                    put(x1 - t, y);
                }
            }
            let bar = x0 + ((x1 - x0) as f32 * o.consensus.clamp(0.0, 1.0)).round() as i64;
            for y in (y0 - 3 * DEBUG_LINE_PX)..(y0 - DEBUG_LINE_PX) {
                for x in x0..bar {
                    put(x, y);
                }
            }
        }
        Some(Image {
            header: f.header.clone(),
            height: f.height as u32,
            width: f.width as u32,
            encoding: encoding.into(),
            is_bigendian: 0,
            step: f.stride as u32,
            data,
        })
    }

    /// `/diagnostics` content for the node.
    pub fn diagnostics(&self) -> DiagnosticArray {
        let level = match self.state {
            TrackStatus::STATE_TRACKING
            | TrackStatus::STATE_IDLE
            | TrackStatus::STATE_REACQUIRED => DiagnosticStatus::OK,
            TrackStatus::STATE_LOW_CONSENSUS | TrackStatus::STATE_UNCERTAIN => {
                DiagnosticStatus::WARN
            }
            // The target is lost while the tracker still runs: WARN; a dropped track: STALE.
            TrackStatus::STATE_LOST if self.target_lost => DiagnosticStatus::WARN,
            TrackStatus::STATE_LOST => DiagnosticStatus::STALE,
            _ => DiagnosticStatus::ERROR,
        };
        let kv = |k: &str, v: String| KeyValue {
            key: k.into(),
            value: v,
        };
        let o = self.last_output;
        DiagnosticArray {
            header: Header {
                stamp: now_stamp(),
                frame_id: clip(&self.last_header.frame_id),
            },
            status: vec![DiagnosticStatus {
                level,
                name: format!("{}: tracker", self.settings.node_name),
                message: if self.reason.is_empty() {
                    "tracking".into()
                } else {
                    self.reason.clone()
                },
                hardware_id: clip(&self.last_header.frame_id),
                values: vec![
                    kv("state", self.state.to_string()),
                    kv("track_id", self.track_id.to_string()),
                    kv("frames_processed", self.frames_processed.to_string()),
                    kv("frames_dropped", self.frames_dropped.to_string()),
                    kv(
                        "consensus",
                        o.map_or("-".into(), |o| format!("{:.3}", o.consensus)),
                    ),
                    kv(
                        "confidence",
                        o.map_or("-".into(), |o| format!("{:.3}", o.confidence)),
                    ),
                    kv("buffered_frames", self.buffer.len().to_string()),
                    kv("buffered_bytes", self.buffer_bytes.to_string()),
                ],
            }],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bevt_core::eval::synth::SynthParams;
    use bevt_core::{StateReason, TrackerConfig};

    /// Every state reason of issue 20 reaches `TrackStatus` with the state the tracker
    /// reported and its sentence: a confirmed low-confidence frame is tracking with its
    /// reason (not "low consensus"), a drift is uncertain, a drift loss lost.
    #[test]
    fn status_of_maps_the_drift_and_confirmation_reasons() {
        let o = |state, reason, learned| TrackOutput {
            bbox: BBox {
                x: 0.0,
                y: 0.0,
                w: 10.0,
                h: 10.0,
            },
            consensus: 0.5,
            learned,
            peak: 0.1,
            scale: 1.0,
            confidence: 0.3,
            state,
            reason,
        };
        let confirmed = StateReason::Confirmed {
            confidence: 0.27,
            score: 7.3,
            head: false,
        };
        for learned in [true, false] {
            let (s, r) = status_of(&o(TrackState::Tracking, confirmed, learned));
            assert_eq!(s, TrackStatus::STATE_TRACKING);
            assert_eq!(r, confirmed.to_string());
            assert!(r.contains("the verifier finds the target"), "{r}");
        }
        let off = StateReason::OffTarget {
            score: 2.3,
            threshold: 4.0,
        };
        let (s, r) = status_of(&o(TrackState::Uncertain, off, true));
        assert_eq!(
            (s, r.starts_with("drift:")),
            (TrackStatus::STATE_UNCERTAIN, true)
        );
        let drifted = StateReason::Drifted {
            score: 1.7,
            threshold: 4.0,
            frames: 5,
        };
        let (s, r) = status_of(&o(TrackState::Lost, drifted, false));
        assert_eq!(s, TrackStatus::STATE_LOST);
        assert!(r.contains("drifted off") && r.contains("5 frames"), "{r}");
        let (s, r) = status_of(&o(TrackState::Tracking, StateReason::Confident, true));
        assert_eq!((s, r.as_str()), (TrackStatus::STATE_TRACKING, ""));
        let (s, _) = status_of(&o(TrackState::Tracking, StateReason::Confident, false));
        assert_eq!(s, TrackStatus::STATE_LOW_CONSENSUS);
    }

    fn image(seq: &SynthParams, t: usize) -> (Image, BBox) {
        let f = seq.frame(t);
        (
            Image {
                header: Header {
                    stamp: Time {
                        sec: 100 + t as i32,
                        nanosec: 0,
                    },
                    frame_id: "cam".into(),
                },
                height: seq.height as u32,
                width: seq.width as u32,
                encoding: "rgb8".into(),
                is_bigendian: 0,
                step: (seq.width * 3) as u32,
                data: f.rgb,
            },
            f.truth,
        )
    }

    fn core() -> NodeCore {
        NodeCore::new(
            TrackerConfig::default().validate().unwrap(),
            NodeSettings::default(),
        )
    }

    fn req(b: BBox, stamp: Time) -> ReinitRequest {
        crate::convert::reinit_request(b, stamp, "")
    }

    #[test]
    fn idle_until_initialised_then_tracks() {
        let seq = SynthParams::default();
        let mut n = core();
        let (m, t0) = image(&seq, 0);
        let o = n.on_image(CameraMsg::Raw(&m), Instant::now());
        assert_eq!(o.status.state, TrackStatus::STATE_IDLE);
        assert!(o.detections.detections.is_empty());
        let (r, _) = n.on_reinit(&req(t0, Time::default()));
        assert!(r.success, "{}", r.message);
        for t in 1..10 {
            let (m, truth) = image(&seq, t);
            let o = n.on_image(CameraMsg::Raw(&m), Instant::now());
            assert_eq!(o.status.state, TrackStatus::STATE_TRACKING);
            let b = crate::convert::bbox_from_detection(&o.detections.detections[0]);
            assert!(b.center().distance(&truth.center()) < 3.0);
            assert_eq!(o.detections.header.stamp, m.header.stamp);
        }
    }

    #[test]
    fn delayed_reinit_lands_on_the_stamped_frame_and_fast_forwards() {
        let seq = SynthParams::default();
        let mut n = core();
        for t in 0..12 {
            let (m, _) = image(&seq, t);
            n.on_image(CameraMsg::Raw(&m), Instant::now());
        }
        // The operator drew the box on frame 3 (its truth), which arrived late.
        let truth3 = seq.truth(3);
        let (r, out) = n.on_reinit(&req(
            truth3,
            Time {
                sec: 103,
                nanosec: 0,
            },
        ));
        assert!(r.success, "{}", r.message);
        assert!(r.message.contains("8 newer frames"), "{}", r.message);
        let out = out.unwrap();
        let b = crate::convert::bbox_from_detection(&out.detections.detections[0]);
        // The published box is on the newest frame (11), not on frame 3.
        assert!(b.center().distance(&seq.truth(11).center()) < 3.0);
        assert!(b.center().distance(&truth3.center()) > 10.0);
    }

    #[test]
    fn bad_requests_fail_with_a_reason_and_keep_the_track() {
        let seq = SynthParams::default();
        let mut n = core();
        let (m, t0) = image(&seq, 0);
        let (r, _) = n.on_reinit(&req(t0, Time::default()));
        assert!(!r.success && r.message.contains("no camera frame"));
        n.on_image(CameraMsg::Raw(&m), Instant::now());
        assert!(n.on_reinit(&req(t0, Time::default())).0.success);
        let id = n.track_id;
        for (b, stamp, why) in [
            (
                BBox::new(f32::NAN, 0.0, 10.0, 10.0),
                Time::default(),
                "invalid box",
            ),
            (
                BBox::new(0.0, 0.0, 0.0, 10.0),
                Time::default(),
                "invalid box",
            ),
            (
                BBox::new(-500.0, -500.0, 20.0, 20.0),
                Time::default(),
                "outside",
            ),
            (t0, Time { sec: 5, nanosec: 0 }, "no buffered frame"),
        ] {
            let (r, out) = n.on_reinit(&req(b, stamp));
            assert!(!r.success && r.message.contains(why), "{}", r.message);
            assert!(r.message.contains("current track kept"));
            assert!(out.is_none());
        }
        let mut wrong = req(t0, Time::default());
        wrong.frame_id = "other".into();
        assert!(!n.on_reinit(&wrong).0.success);
        assert_eq!(n.track_id, id);
        let (m1, _) = image(&seq, 1);
        assert_eq!(
            n.on_image(CameraMsg::Raw(&m1), Instant::now()).status.state,
            TrackStatus::STATE_TRACKING
        );
    }

    #[test]
    fn bad_images_report_errors_and_resolution_changes_reset_the_track() {
        let seq = SynthParams::default();
        let mut n = core();
        let (m, t0) = image(&seq, 0);
        n.on_image(CameraMsg::Raw(&m), Instant::now());
        n.on_reinit(&req(t0, Time::default()));
        let mut bad = m.clone();
        bad.data.truncate(10);
        let o = n.on_image(CameraMsg::Raw(&bad), Instant::now());
        assert_eq!(o.status.state, TrackStatus::STATE_ERROR);
        assert!(
            o.status.reason.contains("data has 10 bytes"),
            "{}",
            o.status.reason
        );
        let mut enc = m.clone();
        enc.encoding = "32FC1".into();
        let o = n.on_image(CameraMsg::Raw(&enc), Instant::now());
        assert!(o.status.reason.contains("32FC1"));
        // Still tracking afterwards.
        let (m1, _) = image(&seq, 1);
        assert_eq!(
            n.on_image(CameraMsg::Raw(&m1), Instant::now()).status.state,
            TrackStatus::STATE_TRACKING
        );
        // A resolution change resets to lost with the reason.
        let small = SynthParams {
            width: 160,
            height: 120,
            ..SynthParams::default()
        };
        let (s, _) = image(&small, 2);
        let o = n.on_image(CameraMsg::Raw(&s), Instant::now());
        assert_eq!(o.status.state, TrackStatus::STATE_LOST);
        assert!(
            o.status.reason.contains("320x240 rgb8 to 160x120 rgb8"),
            "{}",
            o.status.reason
        );
        let o = n.on_image(CameraMsg::Raw(&s), Instant::now());
        assert_eq!(o.status.state, TrackStatus::STATE_LOST);
    }

    #[test]
    fn debug_image_draws_the_box_in_the_camera_encoding() {
        let seq = SynthParams::default();
        let mut n = core();
        assert!(n.debug_image().is_none());
        let (m, t0) = image(&seq, 0);
        n.on_image(CameraMsg::Raw(&m), Instant::now());
        // Idle: the frame comes back unchanged.
        assert_eq!(n.debug_image().unwrap().data, m.data);
        n.on_reinit(&req(t0, Time::default()));
        let d = n.debug_image().unwrap();
        assert_eq!(
            (d.width, d.height, d.encoding.as_str(), d.step),
            (m.width, m.height, "rgb8", m.step)
        );
        let (x, y) = (t0.x.round() as usize, (t0.y + t0.h / 2.0).round() as usize);
        let i = y * m.step as usize + x * 3;
        assert_eq!(
            &d.data[i..i + 3],
            &[40, 220, 40],
            "left edge of the box is green"
        );
        assert_eq!(d.header.stamp, m.header.stamp);
    }

    fn compressed_jpeg_declaring(w: u16, h: u16, stamp: Time) -> CompressedImage {
        let mut jpg = Vec::new();
        image::RgbImage::from_pixel(16, 16, image::Rgb([9, 9, 9]))
            .write_to(
                &mut std::io::Cursor::new(&mut jpg),
                image::ImageFormat::Jpeg,
            )
            .unwrap();
        let sof = jpg.windows(2).position(|p| p == [0xFF, 0xC0]).unwrap();
        jpg[sof + 5..sof + 7].copy_from_slice(&h.to_be_bytes());
        jpg[sof + 7..sof + 9].copy_from_slice(&w.to_be_bytes());
        CompressedImage {
            header: Header {
                stamp,
                frame_id: "cam".into(),
            },
            format: "jpeg".into(),
            data: jpg,
        }
    }

    #[test]
    fn oversized_frames_are_errors_that_keep_the_track_and_are_not_buffered() {
        let seq = SynthParams::default();
        let mut n = core();
        let (m, t0) = image(&seq, 0);
        n.on_image(CameraMsg::Raw(&m), Instant::now());
        assert!(n.on_reinit(&req(t0, Time::default())).0.success);
        let id = n.track_id;
        let (buffered, bytes) = (n.buffer.len(), n.buffer_bytes);
        let bomb = compressed_jpeg_declaring(16000, 16000, Time { sec: 7, nanosec: 0 });
        let raw_bomb = Image {
            width: 5000,
            height: 1,
            step: 5000,
            encoding: "mono8".into(),
            data: vec![0; 5000],
            ..m.clone()
        };
        for o in [
            n.on_image(CameraMsg::Compressed(&bomb), Instant::now()),
            n.on_image(CameraMsg::Raw(&raw_bomb), Instant::now()),
        ] {
            assert_eq!(o.status.state, TrackStatus::STATE_ERROR);
            assert!(
                o.status.reason.contains("max_image_width"),
                "{}",
                o.status.reason
            );
            assert_eq!((n.buffer.len(), n.buffer_bytes), (buffered, bytes));
            assert_eq!(n.track_id, id);
            assert!(n.tracker.is_initialized(), "the track was reset");
        }
        let (m1, truth) = image(&seq, 1);
        let o = n.on_image(CameraMsg::Raw(&m1), Instant::now());
        assert_eq!(
            o.status.state,
            TrackStatus::STATE_TRACKING,
            "{}",
            o.status.reason
        );
        let b = crate::convert::bbox_from_detection(&o.detections.detections[0]);
        assert!(b.center().distance(&truth.center()) < 3.0);
    }

    #[test]
    fn the_ring_buffer_keeps_its_byte_budget_and_gives_memory_back() {
        let big = SynthParams {
            width: 640,
            height: 480,
            ..SynthParams::default()
        };
        let small = SynthParams {
            width: 160,
            height: 120,
            ..SynthParams::default()
        };
        let frame_bytes = |p: &SynthParams| p.width * p.height * 3;
        let budget = 3 * frame_bytes(&big) + frame_bytes(&big) / 2;
        let mut n = NodeCore::new(
            TrackerConfig::default().validate().unwrap(),
            NodeSettings {
                reinit_buffer_bytes: budget,
                ..NodeSettings::default()
            },
        );
        for t in 0..6 {
            let (m, _) = image(&big, t);
            n.on_image(CameraMsg::Raw(&m), Instant::now());
            assert!(n.buffer_bytes <= budget);
        }
        assert_eq!(n.buffer.len(), 3, "the budget holds 3 big frames");
        // Small frames replace the big ones and no slot keeps a big capacity.
        for t in 0..30 {
            let (m, _) = image(&small, t);
            n.on_image(CameraMsg::Raw(&m), Instant::now());
        }
        assert_eq!(n.buffer.len(), 30);
        let per_slot = frame_bytes(&small) + frame_bytes(&small) / SLOT_SLACK;
        assert!(n.buffer.iter().all(|b| b.bytes() <= per_slot));
        assert_eq!(
            n.buffer_bytes,
            n.buffer.iter().map(|b| b.bytes()).sum::<usize>()
        );
        // A padded raw frame (step > width × 3) is buffered packed.
        let (mut m, _) = image(&small, 31);
        let row = small.width * 3;
        let step = row + 64;
        let mut padded = vec![0u8; step * small.height];
        for r in 0..small.height {
            padded[r * step..r * step + row].copy_from_slice(&m.data[r * row..(r + 1) * row]);
        }
        m.step = step as u32;
        m.data = padded;
        n.on_image(CameraMsg::Raw(&m), Instant::now());
        assert_eq!(n.buffer.back().unwrap().data.len(), frame_bytes(&small));
    }

    #[test]
    fn fast_forward_is_bounded_and_still_lands_on_the_target() {
        assert_eq!(fast_forward_steps(3, 10), vec![1, 2, 3]);
        assert_eq!(fast_forward_steps(25, 10).len(), 10);
        assert_eq!(fast_forward_steps(25, 10).last(), Some(&25));
        assert_eq!(fast_forward_steps(0, 10), Vec::<usize>::new());
        let seq = SynthParams::default();
        let mut n = core();
        for t in 0..30 {
            let (m, _) = image(&seq, t);
            n.on_image(CameraMsg::Raw(&m), Instant::now());
        }
        let (r, out) = n.on_reinit(&req(
            seq.truth(4),
            Time {
                sec: 104,
                nanosec: 0,
            },
        ));
        assert!(r.success, "{}", r.message);
        assert!(
            r.message.contains("5 of the 25 newer frames"),
            "{}",
            r.message
        );
        let b = crate::convert::bbox_from_detection(&out.unwrap().detections.detections[0]);
        assert!(b.center().distance(&seq.truth(29).center()) < 5.0);
    }

    #[test]
    fn a_live_rate_change_does_not_refill_the_bucket() {
        let mut n = core();
        let t = Instant::now();
        while n.admit_reinit(t).is_ok() {}
        // The same limits set again, and a larger burst: still empty at the same instant.
        let mut s = n.settings.clone();
        n.set_live_settings(&s);
        assert!(
            n.admit_reinit(t).is_err(),
            "the same settings refilled the bucket"
        );
        s.reinit_burst += 10;
        s.reinit_rate_hz *= 2.0;
        n.set_live_settings(&s);
        assert!(
            n.admit_reinit(t).is_err(),
            "a new burst refilled the bucket"
        );
        // The new rate applies: 1 s at 2 Hz earns two requests.
        let t1 = t + Duration::from_secs(1);
        assert_eq!((0..10).filter(|_| n.admit_reinit(t1).is_ok()).count(), 2);
    }

    #[test]
    fn the_gate_admits_a_burst_then_the_steady_rate() {
        let mut g = ReinitGate::new(2.0, 5);
        let t = Instant::now();
        let admitted = (0..200).filter(|_| g.admit(t).is_ok()).count();
        assert_eq!(admitted, 5);
        let e = g.admit(t).unwrap_err();
        assert!(
            e.contains("rate limit") && e.contains("current track kept"),
            "{e}"
        );
        // One second later: two more.
        let t1 = t + Duration::from_secs(1);
        assert_eq!((0..10).filter(|_| g.admit(t1).is_ok()).count(), 2);
        // A long quiet period refills only up to the burst.
        let t2 = t1 + Duration::from_secs(3600);
        assert_eq!((0..10).filter(|_| g.admit(t2).is_ok()).count(), 5);
        // Non-finite or zero rates never refill and never panic.
        let mut z = ReinitGate::new(f64::NAN, 1);
        assert!(z.admit(t).is_ok());
        assert!(z.admit(t2).is_err());
        let mut n = core();
        let refused = (0..200)
            .filter_map(|_| n.admit_reinit(t).err())
            .collect::<Vec<_>>();
        assert_eq!(refused.len(), 197);
        assert!(refused
            .iter()
            .all(|r| !r.success && r.message.contains("rate limit")));
    }

    #[test]
    fn long_frame_ids_are_clipped_in_replies_and_diagnostics() {
        let seq = SynthParams::default();
        let mut n = core();
        let (mut m, t0) = image(&seq, 0);
        m.header.frame_id = "c".repeat(10_000);
        n.on_image(CameraMsg::Raw(&m), Instant::now());
        let mut r = req(t0, Time::default());
        r.frame_id = "f".repeat(10_000);
        let (resp, _) = n.on_reinit(&r);
        assert!(!resp.success);
        assert!(resp.message.len() < 400, "{} bytes", resp.message.len());
        let d = n.diagnostics();
        assert!(d.status[0].hardware_id.len() < 100);
        assert!(d.header.frame_id.len() < 100);
        let mut bad = m.clone();
        bad.encoding = "e".repeat(10_000);
        let o = n.on_image(CameraMsg::Raw(&bad), Instant::now());
        assert!(o.status.reason.len() < 400);
        assert!(n.diagnostics().status[0].message.len() < 400);
    }

    #[test]
    fn lost_target_warns_publishes_no_detection_and_reinit_clears_it() {
        let seq = SynthParams {
            frames: 60,
            hidden: Some((10, 60)),
            ..SynthParams::default()
        };
        let mut n = core();
        let (m, t0) = image(&seq, 0);
        n.on_image(CameraMsg::Raw(&m), Instant::now());
        assert!(n.on_reinit(&req(t0, Time::default())).0.success);
        let mut lost = None;
        for t in 1..seq.frames {
            let (m, _) = image(&seq, t);
            let o = n.on_image(CameraMsg::Raw(&m), Instant::now());
            if o.status.state == TrackStatus::STATE_LOST {
                lost = Some(o);
                break;
            }
            assert_eq!(o.detections.detections.len(), 1);
        }
        let o = lost.expect("never lost");
        assert!(o.detections.detections.is_empty());
        assert!(
            o.status.reason.starts_with("target lost: confidence"),
            "{}",
            o.status.reason
        );
        assert_eq!(n.diagnostics().status[0].level, DiagnosticStatus::WARN);
        let (r, out) = n.on_reinit(&req(t0, Time::default()));
        assert!(r.success, "{}", r.message);
        let out = out.unwrap();
        assert_eq!(out.status.state, TrackStatus::STATE_TRACKING);
        assert_eq!(out.detections.detections.len(), 1);
        assert_eq!(n.diagnostics().status[0].level, DiagnosticStatus::OK);
    }

    #[test]
    fn stale_camera_is_reported_and_stop_goes_idle() {
        let seq = SynthParams::default();
        let mut n = core();
        let (m, t0) = image(&seq, 0);
        let t = Instant::now();
        n.on_image(CameraMsg::Raw(&m), t);
        assert!(
            n.on_tick(t + Duration::from_secs(5)).is_none(),
            "not tracking: nothing to report"
        );
        n.on_reinit(&req(t0, Time::default()));
        assert!(n.on_tick(t + Duration::from_millis(500)).is_none());
        let s = n.on_tick(t + Duration::from_secs(5)).unwrap();
        assert_eq!(s.state, TrackStatus::STATE_LOST);
        assert!(s.reason.contains("camera stale"));
        assert_eq!(n.diagnostics().status[0].level, DiagnosticStatus::STALE);
        assert!(n.on_stop().success);
        assert_eq!(n.state(), TrackStatus::STATE_IDLE);
    }
}
