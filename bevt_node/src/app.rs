//! The tracking node's logic, independent of DDS: what to do with each camera frame,
//! re-initialisation request, stop request and timer tick, and what to publish.
//!
//! [`NodeCore`] is driven by the ROS layer (`ros.rs`) and, in tests, directly with
//! recorded or synthetic messages. It keeps a short ring buffer of recent frames so an
//! operator's box, drawn on a frame that reached the ground station late, initialises on
//! *that* frame; the newer buffered frames are then tracked through (fast-forward) so the
//! published track is current. A bad request is answered `success = false` with the
//! reason, and the current track is kept.

use crate::convert::{
    detections_from_output, frame_from_compressed, frame_from_image, PixelBuffer,
};
use bevt_core::{BBox, BevtTracker, Frame, PixelFormat, TrackOutput, Tracker, TrackerSpec};
use bevt_msgs::bevt::{ReinitRequest, ReinitResponse, TrackStatus};
use bevt_msgs::builtin_interfaces::Time;
use bevt_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus, KeyValue};
use bevt_msgs::sensor_msgs::{CompressedImage, Image};
use bevt_msgs::std_msgs::Header;
use bevt_msgs::std_srvs::TriggerResponse;
use bevt_msgs::vision_msgs::Detection2DArray;
use std::collections::VecDeque;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// Line thickness of the debug image's box, pixels.
const DEBUG_LINE_PX: i64 = 2;

/// Settings of the node logic.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeSettings {
    /// `class_id` of published hypotheses.
    pub class_id: String,
    /// Recent frames kept for delayed re-initialisation.
    pub reinit_buffer_frames: usize,
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
            stale_timeout: Duration::from_secs(2),
            node_name: "bevt_node".into(),
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
}

impl CameraMsg<'_> {
    fn header(&self) -> &Header {
        match self {
            CameraMsg::Raw(m) => &m.header,
            CameraMsg::Compressed(m) => &m.header,
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

/// An owned copy of a frame for the ring buffer.
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
    pixels: PixelBuffer,
    track_id: u32,
    frames_processed: u32,
    frames_dropped: u32,
    last_output: Option<TrackOutput>,
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

fn now_stamp() -> Time {
    let d = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap_or_default();
    Time::from_nanos(d.as_nanos().min(i64::MAX as u128) as i64)
}

impl NodeCore {
    /// A node with no target.
    pub fn new(spec: TrackerSpec, settings: NodeSettings) -> Self {
        Self {
            tracker: BevtTracker::new(spec.clone()),
            spec,
            settings,
            buffer: VecDeque::new(),
            pixels: PixelBuffer::default(),
            track_id: 0,
            frames_processed: 0,
            frames_dropped: 0,
            last_output: None,
            last_header: Header::default(),
            last_image_at: None,
            state: TrackStatus::STATE_IDLE,
            reason: "waiting for an initial box (reinit service or init topic)".into(),
        }
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
        let conv = match msg {
            CameraMsg::Raw(m) => frame_from_image(m, &mut self.pixels),
            CameraMsg::Compressed(m) => frame_from_compressed(m, &mut self.pixels),
        };
        let frame = match conv {
            Ok(f) => f,
            Err(e) => {
                // The frame is unusable; the track (if any) is kept for the next one.
                self.state = TrackStatus::STATE_ERROR;
                self.reason = e.to_string();
                return self.outputs(&header, None, received);
            }
        };
        let slot = if self.buffer.len() >= self.settings.reinit_buffer_frames.max(1) {
            self.buffer.pop_front()
        } else {
            None
        };
        let mut data = slot.map(|b| b.data).unwrap_or_default();
        data.clear();
        data.extend_from_slice(frame.data());
        self.buffer.push_back(Buffered {
            header: header.clone(),
            width: frame.width(),
            height: frame.height(),
            stride: frame.stride(),
            format: frame.format(),
            data,
        });
        self.frames_processed = self.frames_processed.saturating_add(1);
        let out = if self.tracker.is_initialized() {
            let r = self.tracker.update(&frame);
            match r {
                Ok(o) => {
                    self.state = if o.learned {
                        TrackStatus::STATE_TRACKING
                    } else {
                        TrackStatus::STATE_LOW_CONSENSUS
                    };
                    self.reason = if o.learned {
                        String::new()
                    } else {
                        format!(
                            "consensus {:.3} <= {:.2}: frame not learned",
                            o.consensus, self.spec.verify.threshold_low
                        )
                    };
                    self.last_output = Some(o);
                    Some(o)
                }
                Err(bevt_core::TrackError::FrameMismatch { expected, got }) => {
                    self.tracker.reset();
                    self.last_output = None;
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
                req.frame_id, newest.header.frame_id
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
        for f in self.buffer.iter().skip(index + 1) {
            let Some(frame) = f.frame() else { continue };
            match fresh.update(&frame) {
                Ok(o) => last = Some(o),
                Err(e) => return fail(format!("fast-forward failed: {e}; current track kept")),
            }
        }
        let forwarded = self.buffer.len() - 1 - index;
        self.tracker = fresh;
        self.track_id = self.track_id.wrapping_add(1);
        let out = last.unwrap_or(TrackOutput {
            bbox: b,
            consensus: 1.0,
            learned: true,
            peak: 0.0,
            scale: 1.0,
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
            self.reason = format!("camera stale: no image for {:.1} s", silent.as_secs_f32());
            let header = self.last_header.clone();
            return Some(self.outputs(&header, None, now).status);
        }
        None
    }

    /// The newest frame with the current box drawn (green: learned, yellow: low consensus)
    /// and a consensus bar above it (its length is the consensus score × box width), in the
    /// camera's own encoding. `None` before the first usable frame.
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
            TrackStatus::STATE_TRACKING | TrackStatus::STATE_IDLE => DiagnosticStatus::OK,
            TrackStatus::STATE_LOW_CONSENSUS => DiagnosticStatus::WARN,
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
                frame_id: self.last_header.frame_id.clone(),
            },
            status: vec![DiagnosticStatus {
                level,
                name: format!("{}: tracker", self.settings.node_name),
                message: if self.reason.is_empty() {
                    "tracking".into()
                } else {
                    self.reason.clone()
                },
                hardware_id: self.last_header.frame_id.clone(),
                values: vec![
                    kv("state", self.state.to_string()),
                    kv("track_id", self.track_id.to_string()),
                    kv("frames_processed", self.frames_processed.to_string()),
                    kv("frames_dropped", self.frames_dropped.to_string()),
                    kv(
                        "consensus",
                        o.map_or("-".into(), |o| format!("{:.3}", o.consensus)),
                    ),
                    kv("buffered_frames", self.buffer.len().to_string()),
                ],
            }],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bevt_core::eval::synth::SynthParams;
    use bevt_core::TrackerConfig;

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
