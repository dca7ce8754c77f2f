//! `bevt replay`: the tracker over a recorded camera topic, offline and deterministic.
//!
//! Every image of the topic goes, in message order, through the node's own logic
//! ([`NodeCore`]: the same conversions, ring buffer, re-initialisation and status rules as
//! in flight), deserialised in place from the bag (the pixels are borrowed, not copied).
//! The initial box is a re-initialisation request stamped with the chosen frame, and
//! `--reinit-file` requests are served like a ground station's: stamped with the frame the
//! box was drawn on, arriving at a later bag time, admitted by the node's rate limit, the
//! newer buffered frames fast-forwarded.
//!
//! Out: an MCAP file (ros2 profile, `ros2msg` schemas, CDR, zstd chunks) with
//! `/detections` (`vision_msgs/msg/Detection2DArray`), `/track_status`
//! (`bevt_msgs/msg/TrackStatus`), `/track_annotations` (`foxglove_msgs/msg/ImageAnnotations`)
//! and optionally the images themselves; and optionally a CSV (stamp, box, score, state per
//! frame). An output that is the same file as an input (the bag, any file of a bag
//! directory) or as the other output is refused before anything is written. Both outputs
//! are written beside their targets as `<stem>.partial-<pid>.<ext>` and renamed over the
//! targets when the replay succeeds or is interrupted (SIGINT / SIGTERM through
//! [`ReplayOptions::stop`]: the files are finished and hold the frames processed); a
//! failed replay leaves earlier outputs untouched and keeps its partial files only when
//! they hold tracked frames ([`ReplayError::partial`]).
//!
//! Frames that cannot be used are counted by reason, as the node reports them: an
//! unsupported encoding, a step/size mismatch or an undecodable compressed image is an
//! `error` state (the track is kept); a frame whose stamp is not newer than the previous
//! one is skipped; a size change resets the track (`lost`). A replay in which no frame at
//! all could be used is an error naming the reason.

use crate::convert::{clip, reinit_request};
use crate::node::app::{CameraMsg, FrameOutputs, NodeCore, NodeSettings};
use crate::tool::bag::{open_bag, BagError, BagLimits, BagMessage};
use crate::tool::outputs::{refuse_overwriting_inputs, Staged};
use bevt_core::{BBox, TrackerSpec};
use bevt_msgs::bevt::TrackStatus;
use bevt_msgs::builtin_interfaces::Time;
use bevt_msgs::foxglove_msgs::{Color, ImageAnnotations, Point2, PointsAnnotation, TextAnnotation};
use bevt_msgs::ros2msg;
use bevt_msgs::sensor_msgs::{CompressedImageView, ImageView};
use bevt_msgs::std_msgs::Header;
use byteorder::{BigEndian, LittleEndian};
use serde::Serialize;
use std::collections::{BTreeMap, VecDeque};
use std::io::{BufWriter, Write};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use thiserror::Error;

/// ROS type of raw images.
pub const IMAGE_TYPE: &str = "sensor_msgs/msg/Image";
/// ROS type of compressed images.
pub const COMPRESSED_TYPE: &str = "sensor_msgs/msg/CompressedImage";
/// Output topic of the boxes.
pub const DETECTIONS_TOPIC: &str = "/detections";
/// Output topic of the status.
pub const STATUS_TOPIC: &str = "/track_status";
/// Output topic of the Foxglove overlay.
pub const ANNOTATIONS_TOPIC: &str = "/track_annotations";
/// CDR little-endian encapsulation header.
const CDR_LE: [u8; 4] = [0, 1, 0, 0];

/// Where the initial box applies.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum InitAt {
    /// The N-th message of the topic (0-based).
    Frame(u64),
    /// The first frame stamped at or after this time, ns.
    Time(i64),
}

/// A re-initialisation request of a `--reinit-file`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReinitEntry {
    /// Stamp of the frame the box was drawn on, ns (0 = the newest frame, as in the node).
    pub stamp: i64,
    /// Bag time at which the request reaches the node, ns (served after the last frame
    /// stamped at or before it).
    pub at: i64,
    /// The box.
    pub bbox: BBox,
}

/// What to replay and where to write.
#[derive(Debug, Clone)]
pub struct ReplayOptions {
    /// Bag directory or `.mcap` / `.db3` file.
    pub bag: PathBuf,
    /// Image topic.
    pub topic: String,
    /// Initial box.
    pub init: BBox,
    /// Where it applies.
    pub init_at: InitAt,
    /// Tracker.
    pub tracker: TrackerSpec,
    /// Node settings (image limits, ring buffer, rate limit).
    pub node: NodeSettings,
    /// Output MCAP.
    pub out: PathBuf,
    /// Output CSV.
    pub csv: Option<PathBuf>,
    /// Requests to serve during the replay, sorted by arrival.
    pub reinit: Vec<ReinitEntry>,
    /// Also write the images to the output (under the input topic's name).
    pub copy_images: bool,
    /// Set (by a SIGINT / SIGTERM handler) to stop after the current frame: the outputs are
    /// finished with what was processed and the summary says `interrupted`.
    pub stop: Option<Arc<AtomicBool>>,
}

/// Most distinct reasons kept in [`ReplaySummary::skipped`]; occurrences of further reasons
/// are counted under [`OTHER_REASONS`] (a bag of millions of distinct bad frames must not
/// hold millions of strings).
pub const MAX_SKIP_REASONS: usize = 64;
/// The key of [`ReplaySummary::skipped`] that counts reasons beyond [`MAX_SKIP_REASONS`].
pub const OTHER_REASONS: &str = "(other reasons)";

/// What a replay did.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct ReplaySummary {
    /// Messages read from the topic.
    pub messages: u64,
    /// Frames given to the node.
    pub frames: u64,
    /// Frames by state of their status (`tracking`, `lost`, `error`, ...).
    pub states: BTreeMap<String, u64>,
    /// Frames not given to the node or not usable, by reason.
    pub skipped: BTreeMap<String, u64>,
    /// Re-initialisation requests served with success (the initial box included).
    pub reinit_applied: u64,
    /// Requests refused or failed, with the node's answer.
    pub reinit_refused: Vec<String>,
    /// Wall time of the whole replay, s.
    pub seconds: f64,
    /// Stopped by [`ReplayOptions::stop`] before the end of the topic.
    pub interrupted: bool,
}

/// A replay that failed: the targets are untouched (earlier outputs stay as they were).
#[derive(Debug, Error)]
#[error("{reason}")]
pub struct ReplayError {
    /// Why it stopped.
    pub reason: String,
    /// What it did until then.
    pub summary: Box<ReplaySummary>,
    /// The partial outputs kept (finished files holding the frames processed) when the
    /// track had started; empty otherwise.
    pub partial: Vec<PathBuf>,
}

/// Parses a time given in seconds (`1700000000.123456789`, at most 9 decimals) exactly
/// into nanoseconds.
///
/// # Errors
/// A message naming the text.
pub fn parse_time_ns(text: &str) -> Result<i64, String> {
    let t = text.trim();
    let (int, frac) = t.split_once('.').unwrap_or((t, ""));
    let bad = || format!("{t:?} is not a time in seconds (e.g. 1700000000.25)");
    if int.is_empty() || !int.bytes().all(|b| b.is_ascii_digit()) || frac.len() > 9 {
        return Err(bad());
    }
    if !frac.bytes().all(|b| b.is_ascii_digit()) {
        return Err(bad());
    }
    let s: i64 = int.parse().map_err(|_| bad())?;
    let ns: i64 = if frac.is_empty() {
        0
    } else {
        format!("{frac:0<9}").parse().map_err(|_| bad())?
    };
    s.checked_mul(1_000_000_000)
        .and_then(|v| v.checked_add(ns))
        .ok_or_else(bad)
}

/// Parses `x,y,w,h`.
///
/// # Errors
/// A message naming the text.
pub fn parse_box(text: &str) -> Result<BBox, String> {
    let v: Vec<f32> = text
        .split(',')
        .map(|s| s.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("{text:?}: expected x,y,w,h"))?;
    match v[..] {
        [x, y, w, h] if [x, y, w, h].iter().all(|v| v.is_finite()) && w > 0.0 && h > 0.0 => {
            Ok(BBox::new(x, y, w, h))
        }
        _ => Err(format!(
            "{text:?}: expected x,y,w,h, finite, with a positive size"
        )),
    }
}

/// Reads a `--reinit-file`: one request per line, `stamp,x,y,w,h[,at]` with times in
/// seconds (`stamp` 0 = the newest frame; `at` defaults to `stamp`); `#` starts a comment.
/// The requests are returned sorted by `at`.
///
/// # Errors
/// A message naming the line.
pub fn parse_reinit_file(text: &str) -> Result<Vec<ReinitEntry>, String> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        if f.len() != 5 && f.len() != 6 {
            return Err(format!(
                "line {}: expected stamp,x,y,w,h[,at], got {:?}",
                i + 1,
                clip(line)
            ));
        }
        let err = |e: String| format!("line {}: {e}", i + 1);
        let stamp = parse_time_ns(f[0]).map_err(err)?;
        let bbox = parse_box(&f[1..5].join(",")).map_err(err)?;
        let at = match f.get(5) {
            Some(a) => parse_time_ns(a).map_err(err)?,
            None => stamp,
        };
        if stamp != 0 && at < stamp {
            return Err(format!(
                "line {}: arrives (at {at} ns) before the frame it was drawn on ({stamp} ns)",
                i + 1
            ));
        }
        out.push(ReinitEntry { stamp, at, bbox });
    }
    out.sort_by_key(|r| r.at);
    Ok(out)
}

/// State name of a `TrackStatus::STATE_*` (CSV and summary).
pub fn state_name(state: u8) -> &'static str {
    match state {
        TrackStatus::STATE_IDLE => "idle",
        TrackStatus::STATE_TRACKING => "tracking",
        TrackStatus::STATE_LOW_CONSENSUS => "low_consensus",
        TrackStatus::STATE_LOST => "lost",
        TrackStatus::STATE_ERROR => "error",
        TrackStatus::STATE_UNCERTAIN => "uncertain",
        TrackStatus::STATE_REACQUIRED => "reacquired",
        _ => "unknown",
    }
}

/// An image message deserialised in place.
enum View<'a> {
    Raw(ImageView<'a>),
    Compressed(CompressedImageView<'a>),
}

impl View<'_> {
    fn header(&self) -> &Header {
        match self {
            View::Raw(m) => &m.header,
            View::Compressed(m) => &m.header,
        }
    }
}

/// Deserialises an image message of type `ty` without copying its pixels.
fn decode_view<'a>(ty: &str, data: &'a [u8]) -> Result<View<'a>, String> {
    if data.len() < 4 {
        return Err("message shorter than its CDR header".into());
    }
    let (kind, body) = (data[1], &data[4..]);
    let cdr = |e: cdr_encoding::Error| format!("undecodable CDR: {e}");
    match (ty, kind) {
        (IMAGE_TYPE, 1) => cdr_encoding::from_bytes::<ImageView, LittleEndian>(body)
            .map(|(v, _)| View::Raw(v))
            .map_err(cdr),
        (IMAGE_TYPE, 0) => cdr_encoding::from_bytes::<ImageView, BigEndian>(body)
            .map(|(v, _)| View::Raw(v))
            .map_err(cdr),
        (COMPRESSED_TYPE, 1) => cdr_encoding::from_bytes::<CompressedImageView, LittleEndian>(body)
            .map(|(v, _)| View::Compressed(v))
            .map_err(cdr),
        (COMPRESSED_TYPE, 0) => cdr_encoding::from_bytes::<CompressedImageView, BigEndian>(body)
            .map(|(v, _)| View::Compressed(v))
            .map_err(cdr),
        (IMAGE_TYPE | COMPRESSED_TYPE, k) => Err(format!("unsupported CDR encapsulation {k}")),
        _ => Err(format!(
            "the topic's type is {ty}, not {IMAGE_TYPE} or {COMPRESSED_TYPE}"
        )),
    }
}

fn cdr_bytes<T: Serialize>(msg: &T) -> Result<Vec<u8>, String> {
    let mut out = CDR_LE.to_vec();
    out.extend(
        cdr_encoding::to_vec::<T, LittleEndian>(msg).map_err(|e| format!("CDR encoding: {e}"))?,
    );
    Ok(out)
}

/// Colour of the overlay by state: green tracking, amber unsure, red reacquired.
fn state_color(state: u8) -> Color {
    let (r, g, b) = match state {
        TrackStatus::STATE_TRACKING => (0.1, 0.9, 0.2),
        TrackStatus::STATE_REACQUIRED => (0.9, 0.2, 0.9),
        _ => (1.0, 0.7, 0.0),
    };
    Color { r, g, b, a: 1.0 }
}

/// The Foxglove overlay of one frame's outputs: the box and `track N  score` above it;
/// nothing when there is no detection.
pub fn annotations_of(o: &FrameOutputs) -> ImageAnnotations {
    let Some(d) = o.detections.detections.first() else {
        return ImageAnnotations::default();
    };
    let stamp = o.detections.header.stamp;
    let c = d.bbox.center.position;
    let (hw, hh) = (d.bbox.size_x / 2.0, d.bbox.size_y / 2.0);
    let color = state_color(o.status.state);
    let p = |x, y| Point2 { x, y };
    let score = d.results.first().map_or(0.0, |r| r.hypothesis.score);
    ImageAnnotations {
        circles: vec![],
        points: vec![PointsAnnotation {
            timestamp: stamp,
            r#type: PointsAnnotation::LINE_LOOP,
            points: vec![
                p(c.x - hw, c.y - hh),
                p(c.x + hw, c.y - hh),
                p(c.x + hw, c.y + hh),
                p(c.x - hw, c.y + hh),
            ],
            outline_color: color,
            outline_colors: vec![],
            fill_color: Color::default(),
            thickness: 2.0,
        }],
        texts: vec![TextAnnotation {
            timestamp: stamp,
            position: p(c.x - hw, c.y - hh - 4.0),
            text: format!("track {}  {score:.2}", d.id),
            font_size: 14.0,
            text_color: color,
            background_color: Color {
                r: 0.0,
                g: 0.0,
                b: 0.0,
                a: 0.5,
            },
        }],
    }
}

/// The output MCAP file and its channels.
struct McapOut {
    writer: mcap::Writer<BufWriter<std::fs::File>>,
    detections: u16,
    status: u16,
    annotations: u16,
    /// The copied image topic, created at its first message.
    images: Option<u16>,
    copy_images: Option<String>,
    sequence: u32,
}

impl McapOut {
    fn create(
        file: std::fs::File,
        path: &Path,
        copy_images: Option<String>,
    ) -> Result<Self, String> {
        let e = |e: mcap::McapError| format!("{}: {e}", path.display());
        let mut writer = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("bevt replay ", env!("CARGO_PKG_VERSION")))
            .compression(Some(mcap::Compression::Zstd))
            .create(BufWriter::new(file))
            .map_err(e)?;
        let meta = BTreeMap::new();
        let channel = |w: &mut mcap::Writer<_>, ty: &str, schema: &str, topic: &str| {
            let s = w.add_schema(ty, "ros2msg", schema.as_bytes()).map_err(e)?;
            w.add_channel(s, topic, "cdr", &meta).map_err(e)
        };
        let detections = channel(
            &mut writer,
            "vision_msgs/msg/Detection2DArray",
            ros2msg::DETECTION2D_ARRAY,
            DETECTIONS_TOPIC,
        )?;
        let status = channel(
            &mut writer,
            "bevt_msgs/msg/TrackStatus",
            ros2msg::TRACK_STATUS,
            STATUS_TOPIC,
        )?;
        let annotations = channel(
            &mut writer,
            "foxglove_msgs/msg/ImageAnnotations",
            ros2msg::IMAGE_ANNOTATIONS,
            ANNOTATIONS_TOPIC,
        )?;
        Ok(Self {
            writer,
            detections,
            status,
            annotations,
            images: None,
            copy_images,
            sequence: 0,
        })
    }

    fn put(&mut self, channel_id: u16, time: u64, data: &[u8]) -> Result<(), String> {
        self.sequence = self.sequence.wrapping_add(1);
        self.writer
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id,
                    sequence: self.sequence,
                    log_time: time,
                    publish_time: time,
                },
                data,
            )
            .map_err(|e| format!("writing the output: {e}"))
    }

    fn frame(&mut self, m: &BagMessage<'_>, o: &FrameOutputs) -> Result<(), String> {
        if let Some(topic) = self.copy_images.take() {
            let schema = if m.msg_type == IMAGE_TYPE {
                ros2msg::IMAGE
            } else {
                ros2msg::COMPRESSED_IMAGE
            };
            let e = |e: mcap::McapError| format!("writing the output: {e}");
            let s = self
                .writer
                .add_schema(m.msg_type, "ros2msg", schema.as_bytes())
                .map_err(e)?;
            self.images = Some(
                self.writer
                    .add_channel(s, &topic, "cdr", &BTreeMap::new())
                    .map_err(e)?,
            );
        }
        if let Some(id) = self.images {
            self.put(id, m.log_time, m.data)?;
        }
        self.put(self.detections, m.log_time, &cdr_bytes(&o.detections)?)?;
        self.put(self.status, m.log_time, &cdr_bytes(&o.status)?)?;
        self.put(
            self.annotations,
            m.log_time,
            &cdr_bytes(&annotations_of(o))?,
        )
    }

    fn finish(&mut self) -> Result<(), String> {
        self.writer
            .finish()
            .map(|_| ())
            .map_err(|e| format!("closing the output: {e}"))
    }
}

/// One CSV row: `stamp,x,y,w,h,score,state` (box empty when there is no detection).
fn csv_row(o: &FrameOutputs) -> String {
    let t = o.status.header.stamp;
    let stamp = format!("{}.{:09}", t.sec, t.nanosec);
    let state = state_name(o.status.state);
    match o.detections.detections.first() {
        Some(d) => {
            let b = crate::convert::bbox_from_detection(d);
            let score = d.results.first().map_or(0.0, |r| r.hypothesis.score);
            format!(
                "{stamp},{:.3},{:.3},{:.3},{:.3},{score:.4},{state}",
                b.x, b.y, b.w, b.h
            )
        }
        None => format!("{stamp},,,,,,{state}"),
    }
}

/// Counts one occurrence of `reason`, keeping at most [`MAX_SKIP_REASONS`] distinct ones.
fn count_reason(skipped: &mut BTreeMap<String, u64>, reason: String) {
    let key = if skipped.contains_key(&reason) || skipped.len() < MAX_SKIP_REASONS {
        reason
    } else {
        OTHER_REASONS.to_string()
    };
    *skipped.entry(key).or_insert(0) += 1;
}

/// The replay loop's state.
struct Run<'a> {
    opts: &'a ReplayOptions,
    core: NodeCore,
    mcap: McapOut,
    csv: Option<BufWriter<std::fs::File>>,
    summary: ReplaySummary,
    pending: VecDeque<ReinitEntry>,
    initialised: bool,
    last_stamp: Option<i64>,
    first_stamp: Option<i64>,
    t0: Instant,
    /// The first reason of an `error` state, for the all-frames-failed error.
    first_error: Option<String>,
    fatal: Option<String>,
    /// The last frame's status was a reset by a size change.
    in_reset: bool,
    progress: indicatif::ProgressBar,
}

impl Run<'_> {
    fn skip(&mut self, reason: String) {
        count_reason(&mut self.summary.skipped, reason);
    }

    /// The bag-clock instant of `ns` for the node's rate limit.
    fn instant_of(&self, ns: i64) -> Instant {
        let since = ns.saturating_sub(self.first_stamp.unwrap_or(ns)).max(0) as u64;
        self.t0 + Duration::from_nanos(since)
    }

    /// Serves the requests that have arrived by `stamp`; the outputs of the last one that
    /// succeeded replace the frame's.
    fn serve_requests(&mut self, index: u64, stamp: i64, out: &mut FrameOutputs) {
        let init_due = !self.initialised
            && match self.opts.init_at {
                InitAt::Frame(n) => index >= n,
                InitAt::Time(t) => stamp >= t,
            };
        if init_due {
            self.initialised = true;
            let req = reinit_request(self.opts.init, Time::from_nanos(stamp), "");
            match self.core.on_reinit(&req) {
                (r, Some(o)) if r.success => {
                    self.summary.reinit_applied += 1;
                    *out = o;
                }
                (r, _) => {
                    self.fatal = Some(format!("the initial box was refused: {}", r.message));
                }
            }
        }
        while self.pending.front().is_some_and(|r| r.at <= stamp) {
            let Some(r) = self.pending.pop_front() else {
                break;
            };
            let when = format!(
                "request at {}.{:09}",
                r.at / 1_000_000_000,
                r.at % 1_000_000_000
            );
            if let Err(resp) = self.core.admit_reinit(self.instant_of(r.at)) {
                self.summary
                    .reinit_refused
                    .push(format!("{when}: {}", resp.message));
                continue;
            }
            let req = reinit_request(r.bbox, Time::from_nanos(r.stamp), "");
            match self.core.on_reinit(&req) {
                (resp, Some(o)) if resp.success => {
                    self.initialised = true;
                    self.summary.reinit_applied += 1;
                    *out = o;
                }
                (resp, _) => self
                    .summary
                    .reinit_refused
                    .push(format!("{when}: {}", resp.message)),
            }
        }
    }

    fn on_message(&mut self, index: u64, m: &BagMessage<'_>) -> ControlFlow<()> {
        if self
            .opts
            .stop
            .as_ref()
            .is_some_and(|s| s.load(Ordering::Relaxed))
        {
            self.summary.interrupted = true;
            return ControlFlow::Break(());
        }
        self.summary.messages += 1;
        self.progress.inc(1);
        let view = match decode_view(m.msg_type, m.data) {
            Ok(v) => v,
            Err(e) if e.starts_with("the topic's type") => {
                self.fatal = Some(format!("{}: {e}", self.opts.topic));
                return ControlFlow::Break(());
            }
            Err(e) => {
                self.skip(e);
                return ControlFlow::Continue(());
            }
        };
        let stamp = view.header().stamp.as_nanos();
        if let Some(last) = self.last_stamp {
            if stamp <= last {
                self.skip("stamp not newer than the previous frame's (out of order)".into());
                return ControlFlow::Continue(());
            }
        }
        self.last_stamp = Some(stamp);
        self.first_stamp.get_or_insert(stamp);
        let msg = match &view {
            View::Raw(v) => CameraMsg::RawView(v),
            View::Compressed(v) => CameraMsg::CompressedView(v),
        };
        let mut out = self.core.on_image(msg, Instant::now());
        self.summary.frames += 1;
        if out.status.state == TrackStatus::STATE_ERROR {
            self.first_error.get_or_insert(out.status.reason.clone());
            self.skip(out.status.reason.clone());
        } else {
            self.serve_requests(index, stamp, &mut out);
        }
        // The node keeps the reason until the next initialisation: count the reset once.
        let reset = out.status.reason.starts_with("image changed");
        if reset && !self.in_reset {
            self.skip("image size or format changed: track reset".into());
        }
        self.in_reset = reset;
        *self
            .summary
            .states
            .entry(state_name(out.status.state).into())
            .or_insert(0) += 1;
        if let Err(e) = self.write(m, &out) {
            self.fatal = Some(e);
        }
        if self.fatal.is_some() {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    }

    fn write(&mut self, m: &BagMessage<'_>, out: &FrameOutputs) -> Result<(), String> {
        self.mcap.frame(m, out)?;
        if let Some(w) = &mut self.csv {
            writeln!(w, "{}", csv_row(out)).map_err(|e| format!("writing the CSV: {e}"))?;
        }
        Ok(())
    }

    /// Closes the outputs; the first error wins.
    fn close(&mut self) -> Result<(), String> {
        let m = self.mcap.finish();
        let c = match &mut self.csv {
            Some(w) => w.flush().map_err(|e| format!("writing the CSV: {e}")),
            None => Ok(()),
        };
        m.and(c)
    }
}

fn progress_bar(total: Option<u64>) -> indicatif::ProgressBar {
    use indicatif::{ProgressBar, ProgressStyle};
    match total {
        Some(n) => {
            let bar = ProgressBar::new(n);
            bar.set_style(
                ProgressStyle::with_template(
                    "replay [{bar:40}] {pos}/{len} frames, {per_sec}, eta {eta}",
                )
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
            );
            bar
        }
        None => {
            let bar = ProgressBar::new_spinner();
            bar.set_style(
                ProgressStyle::with_template("replay {spinner} {pos} frames, {per_sec}")
                    .unwrap_or_else(|_| ProgressStyle::default_spinner()),
            );
            bar
        }
    }
}

/// Replays `opts.topic` of `opts.bag` through the node logic.
///
/// # Errors
/// [`ReplayError`] when the bag cannot be read (missing topic, corrupt or truncated file),
/// the topic is empty or not an image topic, the initial box is refused, no frame could be
/// used, an output cannot be written, or an output is the same file as an input or as the
/// other output. The targets are then untouched; the error carries the summary so far and
/// the partial outputs kept.
pub fn replay(opts: &ReplayOptions, show_progress: bool) -> Result<ReplaySummary, ReplayError> {
    let started = Instant::now();
    let fail = |reason: String, summary: ReplaySummary| ReplayError {
        reason,
        summary: Box::new(summary),
        partial: Vec::new(),
    };
    let mut outputs = vec![("--out", opts.out.as_path())];
    if let Some(c) = &opts.csv {
        outputs.push(("--csv", c.as_path()));
    }
    refuse_overwriting_inputs(&outputs, &[opts.bag.as_path()])
        .map_err(|e| fail(e, ReplaySummary::default()))?;
    let bag = open_bag(&opts.bag, BagLimits::default())
        .map_err(|e| fail(e.to_string(), ReplaySummary::default()))?;
    let info = bag
        .check_topic(&opts.topic)
        .map_err(|e| fail(e.to_string(), ReplaySummary::default()))?;
    let total = info.and_then(|t| t.count);
    // Both outputs are staged beside their targets; nothing existing is opened for writing.
    let (mcap_file, mcap_staged) = match Staged::create(&opts.out) {
        Ok((s, f)) => (f, s),
        Err(e) => return Err(fail(e, ReplaySummary::default())),
    };
    let mut staged = vec![mcap_staged];
    let abandon_all = |staged: Vec<Staged>| {
        for s in staged {
            s.abandon(false);
        }
    };
    let csv = match &opts.csv {
        None => None,
        Some(p) => {
            let header = Staged::create(p).and_then(|(s, f)| {
                staged.push(s);
                let mut w = BufWriter::new(f);
                writeln!(w, "stamp,x,y,w,h,score,state")
                    .map_err(|e| format!("writing the CSV: {e}"))?;
                Ok(w)
            });
            match header {
                Ok(w) => Some(w),
                Err(e) => {
                    abandon_all(staged);
                    return Err(fail(e, ReplaySummary::default()));
                }
            }
        }
    };
    let mcap = match McapOut::create(
        mcap_file,
        &opts.out,
        opts.copy_images.then(|| opts.topic.clone()),
    ) {
        Ok(m) => m,
        Err(e) => {
            abandon_all(staged);
            return Err(fail(e, ReplaySummary::default()));
        }
    };
    let progress = if show_progress && total.is_none_or(|n| n > 100) {
        progress_bar(total)
    } else {
        indicatif::ProgressBar::hidden()
    };
    let mut run = Run {
        opts,
        core: NodeCore::new(opts.tracker.clone(), opts.node.clone()),
        mcap,
        csv,
        summary: ReplaySummary::default(),
        pending: opts.reinit.iter().copied().collect(),
        initialised: false,
        last_stamp: None,
        first_stamp: None,
        t0: Instant::now(),
        first_error: None,
        fatal: None,
        in_reset: false,
        progress,
    };
    let mut index = 0u64;
    let read = bag.read_topic(&opts.topic, |m| {
        let flow = run.on_message(index, &m);
        index += 1;
        flow
    });
    run.progress.finish_and_clear();
    let closed = run.close();
    let closed_ok = closed.is_ok();
    run.summary.seconds = started.elapsed().as_secs_f64();
    let summary = std::mem::take(&mut run.summary);
    let reason = match read {
        Err(e @ BagError::Corrupt { .. }) => Some(format!(
            "{e} (stopped after {} messages; the output holds them)",
            summary.messages
        )),
        Err(e) => Some(e.to_string()),
        Ok(_) if run.fatal.is_some() => run.fatal.take(),
        Ok(0) => Some(format!("topic {} has no messages", opts.topic)),
        Ok(_)
            if summary.frames == 0
                || summary.frames == summary.states.get("error").copied().unwrap_or(0) =>
        {
            Some(format!(
                "no frame of {} could be used: {}",
                opts.topic,
                run.first_error
                    .take()
                    .or_else(|| summary.skipped.keys().next().cloned())
                    .unwrap_or_else(|| "no usable frame".into())
            ))
        }
        Ok(_) if !run.initialised => Some(format!(
            "the initial frame ({:?}) was never reached: the topic has {} usable frames",
            opts.init_at, summary.frames
        )),
        Ok(_) => closed.err(),
    };
    drop(run);
    match reason {
        Some(r) => {
            // The targets stay as they were; the partial files are kept when they hold
            // tracked frames (finished and readable), removed otherwise.
            let keep = summary.reinit_applied > 0 && closed_ok;
            let partial = staged.into_iter().filter_map(|s| s.abandon(keep)).collect();
            Err(ReplayError {
                reason: r,
                summary: Box::new(summary),
                partial,
            })
        }
        None => {
            for s in staged {
                if let Err(e) = s.commit() {
                    return Err(fail(e, summary));
                }
            }
            Ok(summary)
        }
    }
}

/// Decodes one bag message (an `Image` or `CompressedImage`) into a frame in `buf`, as
/// `bevt replay` does before tracking; returns its width and height.
///
/// # Errors
/// Why the message is not a usable frame (its CDR, its type, its pixels).
pub fn decode_message(
    m: &BagMessage<'_>,
    buf: &mut crate::convert::PixelBuffer,
    limits: &crate::convert::ImageLimits,
) -> Result<(usize, usize), String> {
    decode_view(m.msg_type, m.data).and_then(|v| match &v {
        View::Raw(v) => crate::convert::frame_from_image_view(v, buf, limits)
            .map(|f| (f.width(), f.height()))
            .map_err(|e| e.to_string()),
        View::Compressed(v) => crate::convert::frame_from_compressed_view(v, buf, limits)
            .map(|f| (f.width(), f.height()))
            .map_err(|e| e.to_string()),
    })
}

/// Throughput of reading and decoding alone (no tracking, no output): frames decoded and
/// the wall time, s. Frames that fail to decode are counted in `skipped`.
///
/// # Errors
/// As [`replay`] for the bag.
pub fn decode_only(
    bag: &Path,
    topic: &str,
    node: &NodeSettings,
) -> Result<(u64, ReplaySummary), ReplayError> {
    let started = Instant::now();
    let fail = |e: BagError| ReplayError {
        reason: e.to_string(),
        summary: Box::default(),
        partial: Vec::new(),
    };
    let bag = open_bag(bag, BagLimits::default()).map_err(fail)?;
    let mut summary = ReplaySummary::default();
    let mut buf = crate::convert::PixelBuffer::default();
    let mut decoded = 0u64;
    let limits = node.image_limits;
    bag.read_topic(topic, |m| {
        summary.messages += 1;
        match decode_message(&m, &mut buf, &limits) {
            Ok(_) => decoded += 1,
            Err(e) => count_reason(&mut summary.skipped, e),
        }
        ControlFlow::Continue(())
    })
    .map_err(fail)?;
    summary.frames = decoded;
    summary.seconds = started.elapsed().as_secs_f64();
    Ok((decoded, summary))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distinct_skip_reasons_are_capped_and_the_rest_counted() {
        let mut m = BTreeMap::new();
        for i in 0..10 * MAX_SKIP_REASONS {
            count_reason(&mut m, format!("bad frame {i}"));
            count_reason(&mut m, "bad frame 0".into());
        }
        assert_eq!(m.len(), MAX_SKIP_REASONS + 1);
        assert_eq!(m["bad frame 0"], 10 * MAX_SKIP_REASONS as u64 + 1);
        assert_eq!(m[OTHER_REASONS], 9 * MAX_SKIP_REASONS as u64);
    }

    #[test]
    fn times_parse_exactly_and_bad_ones_are_named() {
        assert_eq!(
            parse_time_ns("1700000000.123456789"),
            Ok(1_700_000_000_123_456_789)
        );
        assert_eq!(parse_time_ns("2.5"), Ok(2_500_000_000));
        assert_eq!(parse_time_ns(" 7 "), Ok(7_000_000_000));
        for bad in ["", "1.2.3", "-1", "1e9", "1.0000000001", "abc", ".5"] {
            let e = parse_time_ns(bad).unwrap_err();
            assert!(e.contains("not a time"), "{bad}: {e}");
        }
    }

    #[test]
    fn reinit_files_parse_sort_and_reject_bad_lines() {
        let text = "# stamp,x,y,w,h,at\n5.0, 10,20,30,40, 5.4\n3.0,1,2,3,4\n\n0,1,1,8,8,9.0\n";
        let r = parse_reinit_file(text).unwrap();
        assert_eq!(r.len(), 3);
        assert_eq!((r[0].stamp, r[0].at), (3_000_000_000, 3_000_000_000));
        assert_eq!((r[1].stamp, r[1].at), (5_000_000_000, 5_400_000_000));
        assert_eq!(r[1].bbox, BBox::new(10.0, 20.0, 30.0, 40.0));
        assert_eq!((r[2].stamp, r[2].at), (0, 9_000_000_000));
        for (bad, what) in [
            ("1,2,3,4\n", "line 1: expected"),
            ("1.0,1,2,0,4\n", "positive size"),
            ("5.0,1,2,3,4,4.0\n", "before the frame"),
            ("x,1,2,3,4\n", "not a time"),
        ] {
            let e = parse_reinit_file(bad).unwrap_err();
            assert!(e.contains(what), "{bad:?}: {e}");
        }
    }

    #[test]
    fn non_image_types_and_short_messages_are_refused_by_name() {
        let e = decode_view("std_msgs/msg/String", &[0, 1, 0, 0, 0])
            .err()
            .unwrap();
        assert!(e.contains("std_msgs/msg/String"), "{e}");
        assert!(decode_view(IMAGE_TYPE, &[0, 1]).is_err());
        let e = decode_view(IMAGE_TYPE, &[0, 1, 0, 0, 9, 9]).err().unwrap();
        assert!(e.contains("undecodable CDR"), "{e}");
    }
}
