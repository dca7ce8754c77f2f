//! Soak benchmark of the ROS 2 node (issue 11; a benchmark, not a test).
//!
//! The node runs as its own process (`bevt_node_under_test`, the node's launch path; it
//! stops when its standard input closes), so its memory in `/proc/<pid>/status` is its own.
//! This process is the outside world on a private DDS domain (default `224 + pid % 7`) on
//! loopback, in a namespace of its own (`/bevt_soak_<pid>`, printed at the start) so that
//! only this run's node is counted (a status whose counters go backwards, or more
//! detections than frames processed, is reported as a second node):
//! - a synthetic camera publishing 1280×720 rgb8 frames at 30 Hz (a looping synthetic
//!   sequence with exact truth), of which a configurable share is replaced by hostile
//!   messages (bad encodings, step/size mismatches, truncated data, huge declared sizes,
//!   truncated JPEG and PNG, a PNG declaring 60000×60000, an unknown compressed format);
//! - a ground station that calls `reinit` on the current truth every `--reinit-period`
//!   seconds and, half a period later, sends an invalid request (NaN or empty box) that
//!   must be refused, and that receives detections and track statuses.
//!
//! Every minute it prints one row: the node's RSS min/max (sampled every second),
//! frames processed and dropped by the node, detection latency (image stamp → detection
//! received) p50/p90/p99/max, hostile messages sent and refused, reinit calls answered,
//! and the 1-minute load average of the machine (latency reflects the load). At the end:
//! the whole run's figures and hostile messages per kind. Exits non-zero if the node
//! died, a hostile message was accepted, an invalid reinit was accepted, or no detection
//! arrived.
//!
//! `cargo build --release -p bevt_tests --bins && target/release/bevt_soak --duration 3600`
//! (`scripts/soak.sh` does this and keeps the output).

use anyhow::{bail, Context as _, Result};
use bevt_core::eval::synth::SynthParams;
use bevt_core::BBox;
use bevt_msgs::bevt::{ReinitRequest, TrackStatus};
use bevt_msgs::builtin_interfaces::Time;
use bevt_msgs::sensor_msgs::{CompressedImage, Image};
use bevt_msgs::std_msgs::Header;
use bevt_node::convert::reinit_request;
use bevt_node::node::ros::RosSettings;
use bevt_node::node::sim::{wall_stamp, GroundStation, RawPeer};
use clap::Parser;
use std::collections::BTreeMap;
use std::io::Write as _;
use std::net::{IpAddr, Ipv4Addr};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Prefix of the frame id of hostile messages (followed by the kind).
const HOSTILE_PREFIX: &str = "hostile:";
/// Frames of the looping synthetic sequence (rendered once, 2.7 MB each).
const SEQ_FRAMES: usize = 120;
/// Longest wait for the node to start and answer the first reinit.
const STARTUP: Duration = Duration::from_secs(120);

/// Soak benchmark of the node: camera, hostile messages and periodic reinit for a duration.
#[derive(Parser, Debug)]
#[command(name = "bevt_soak")]
struct Args {
    /// Seconds of measurement (after start-up).
    #[arg(long, default_value_t = 600.0)]
    duration: f64,
    /// Camera rate, Hz.
    #[arg(long, default_value_t = 30.0)]
    rate: f64,
    /// Frame width, pixels.
    #[arg(long, default_value_t = 1280)]
    width: usize,
    /// Frame height, pixels.
    #[arg(long, default_value_t = 720)]
    height: usize,
    /// Share of camera messages replaced by hostile ones, [0, 1).
    #[arg(long, default_value_t = 0.05)]
    hostile_share: f64,
    /// Seconds between two valid reinit calls (an invalid one goes half-way between).
    #[arg(long, default_value_t = 30.0)]
    reinit_period: f64,
    /// Seconds per report row.
    #[arg(long, default_value_t = 60.0)]
    row_period: f64,
    /// DDS domain (default `224 + pid % 7`, in 224..=230: above the integration tests'
    /// 1..=221, and different between two soak runs started close together).
    #[arg(long)]
    domain: Option<u16>,
    /// Node namespace (default `/bevt_soak_<pid>`): the camera, `reinit`, detections and
    /// statuses are this namespace's topics, so another node on the same domain neither
    /// sees the soak camera nor is counted.
    #[arg(long)]
    namespace: Option<String>,
    /// The node executable (default: `bevt_node_under_test` beside this one).
    #[arg(long)]
    node: Option<PathBuf>,
    /// Also write the rows as CSV here.
    #[arg(long)]
    csv: Option<PathBuf>,
}

/// The kinds of hostile camera messages, sent in turn.
const HOSTILE_KINDS: [&str; 10] = [
    "bad_encoding",
    "step_too_small",
    "data_truncated",
    "huge_declared_size",
    "zero_size",
    "yuv422_odd_width",
    "jpeg_truncated",
    "png_truncated",
    "png_huge_header",
    "unknown_format",
];

/// Pre-built hostile messages (raw or compressed), one per kind.
enum Hostile {
    Raw(Image),
    Compressed(CompressedImage),
}

fn header(kind: &str) -> Header {
    Header {
        stamp: wall_stamp(),
        frame_id: format!("{HOSTILE_PREFIX}{kind}"),
    }
}

/// The hostile messages, built from one good frame `rgb` (`w`×`h`).
fn hostile_messages(rgb: &[u8], w: usize, h: usize) -> Result<Vec<(&'static str, Hostile)>> {
    let raw = |kind: &'static str, f: &dyn Fn(&mut Image)| {
        let mut m = Image {
            header: header(kind),
            height: h as u32,
            width: w as u32,
            encoding: "rgb8".into(),
            is_bigendian: 0,
            step: (w * 3) as u32,
            data: rgb.to_vec(),
        };
        f(&mut m);
        (kind, Hostile::Raw(m))
    };
    let jpeg = {
        let mut out = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 80)
            .encode(rgb, w as u32, h as u32, image::ExtendedColorType::Rgb8)
            .context("encode JPEG")?;
        out.truncate(out.len() / 2);
        out
    };
    let png = |pw: usize, ph: usize| -> Result<Vec<u8>> {
        let mut out = Vec::new();
        image::ImageEncoder::write_image(
            image::codecs::png::PngEncoder::new(&mut out),
            &rgb[..pw * ph * 3],
            pw as u32,
            ph as u32,
            image::ExtendedColorType::Rgb8,
        )
        .context("encode PNG")?;
        Ok(out)
    };
    let png_truncated = {
        let mut p = png(w.min(320), h.min(180))?;
        p.truncate(p.len() * 2 / 3);
        p
    };
    let png_huge = {
        // A valid small PNG whose IHDR (bytes 16..24) declares 60000×60000; the CRC is
        // left wrong on purpose (either check must refuse it).
        let mut p = png(16, 16)?;
        p[16..20].copy_from_slice(&60_000u32.to_be_bytes());
        p[20..24].copy_from_slice(&60_000u32.to_be_bytes());
        p
    };
    let compressed = |kind: &'static str, format: &str, data: Vec<u8>| {
        (
            kind,
            Hostile::Compressed(CompressedImage {
                header: header(kind),
                format: format.into(),
                data,
            }),
        )
    };
    Ok(vec![
        raw("bad_encoding", &|m| m.encoding = "yuv9000".into()),
        raw("step_too_small", &|m| m.step = (w * 3 - 7) as u32),
        raw("data_truncated", &|m| m.data.truncate(m.data.len() / 3)),
        raw("huge_declared_size", &|m| {
            m.width = 1 << 20;
            m.height = 1 << 20;
            m.step = 3 << 20;
            m.data.truncate(4096);
        }),
        raw("zero_size", &|m| {
            m.width = 0;
            m.height = 0;
            m.step = 0;
            m.data.clear();
        }),
        raw("yuv422_odd_width", &|m| {
            m.encoding = "yuv422".into();
            m.width = (w - 1) as u32;
            m.step = (2 * (w - 1)) as u32;
            m.data.truncate(2 * (w - 1) * h);
        }),
        compressed("jpeg_truncated", "jpeg", jpeg),
        compressed("png_truncated", "png", png_truncated),
        compressed("png_huge_header", "png", png_huge),
        compressed(
            "unknown_format",
            "rgb8; webp compressed",
            rgb[..4096].to_vec(),
        ),
    ])
}

/// Stamps (ns) of the hostile messages sent, by kind.
type SentLog = Arc<Mutex<BTreeMap<i64, &'static str>>>;

/// Camera counters shared with the main thread.
#[derive(Default)]
struct CameraCounts {
    good: AtomicU64,
    hostile: AtomicU64,
}

/// What the camera thread shares with the main thread.
#[derive(Default, Clone)]
struct CameraShared {
    stop: Arc<AtomicBool>,
    /// Truth of the good frames by stamp (ns).
    truth: Arc<Mutex<BTreeMap<i64, BBox>>>,
    sent: SentLog,
    counts: Arc<CameraCounts>,
}

/// The camera thread: good frames at `rate` with every `1/share`-th replaced by the next
/// hostile kind.
fn spawn_camera(
    peer: RawPeer,
    seq: SynthParams,
    rate: f64,
    share: f64,
    shared: CameraShared,
    camera_frame: String,
) -> Result<std::thread::JoinHandle<()>> {
    let CameraShared {
        stop,
        truth,
        sent,
        counts,
    } = shared;
    let frames: Vec<_> = (0..seq.frames).map(|i| seq.frame(i)).collect();
    let hostile = hostile_messages(&frames[0].rgb, seq.width, seq.height)?;
    let period = Duration::from_secs_f64(1.0 / rate.max(0.1));
    Ok(std::thread::Builder::new()
        .name("soak-camera".into())
        .spawn(move || {
            let mut next = Instant::now();
            let (mut t, mut credit, mut k) = (0usize, 0.0f64, 0usize);
            while !stop.load(Ordering::Relaxed) {
                credit += share;
                let stamp = wall_stamp();
                if credit >= 1.0 {
                    credit -= 1.0;
                    let (kind, msg) = &hostile[k % hostile.len()];
                    k += 1;
                    if let Ok(mut s) = sent.lock() {
                        s.insert(stamp.as_nanos(), kind);
                    }
                    match msg {
                        Hostile::Raw(m) => {
                            let mut m = m.clone();
                            m.header.stamp = stamp;
                            peer.image(m);
                        }
                        Hostile::Compressed(m) => {
                            let mut m = m.clone();
                            m.header.stamp = stamp;
                            peer.compressed(m);
                        }
                    }
                    counts.hostile.fetch_add(1, Ordering::Relaxed);
                } else {
                    let f = &frames[t % frames.len()];
                    t += 1;
                    if let Ok(mut l) = truth.lock() {
                        l.insert(stamp.as_nanos(), f.truth);
                        while l.len() > 4 * SEQ_FRAMES {
                            l.pop_first();
                        }
                    }
                    peer.image(Image {
                        header: Header {
                            stamp,
                            frame_id: camera_frame.clone(),
                        },
                        height: seq.height as u32,
                        width: seq.width as u32,
                        encoding: "rgb8".into(),
                        is_bigendian: 0,
                        step: (seq.width * 3) as u32,
                        data: f.rgb.clone(),
                    });
                    counts.good.fetch_add(1, Ordering::Relaxed);
                }
                next += period;
                let now = Instant::now();
                if next > now {
                    std::thread::sleep(next - now);
                } else {
                    next = now;
                }
            }
        })?)
}

/// The node process; its standard input is closed (it stops) and it is reaped on drop.
struct NodeProcess(Child);

impl NodeProcess {
    fn spawn(exe: &PathBuf, settings: &RosSettings) -> Result<Self> {
        let child = Command::new(exe)
            .args([
                "--ros-args",
                "-p",
                &format!("domain_id:={}", settings.domain_id),
                "-p",
                "network_interfaces:=[127.0.0.1]",
                "-r",
                &format!("__ns:={}", settings.namespace),
                "-r",
                &format!("__node:={}", settings.node_name),
            ])
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .with_context(|| format!("start {}", exe.display()))?;
        Ok(Self(child))
    }

    fn alive(&mut self) -> bool {
        matches!(self.0.try_wait(), Ok(None))
    }

    /// `VmRSS` in KiB.
    fn rss_kib(&self) -> Option<u64> {
        let s = std::fs::read_to_string(format!("/proc/{}/status", self.0.id())).ok()?;
        s.lines()
            .find_map(|l| l.strip_prefix("VmRSS:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
    }

    /// User + system CPU time, clock ticks (`/proc/<pid>/stat` fields 14 and 15).
    fn cpu_ticks(&self) -> Option<u64> {
        let s = std::fs::read_to_string(format!("/proc/{}/stat", self.0.id())).ok()?;
        // Fields after the command name (which is in parentheses and may hold spaces).
        let rest = &s[s.rfind(')')? + 2..];
        let f: Vec<&str> = rest.split_whitespace().collect();
        Some(f.get(11)?.parse::<u64>().ok()? + f.get(12)?.parse::<u64>().ok()?)
    }
}

impl Drop for NodeProcess {
    fn drop(&mut self) {
        drop(self.0.stdin.take());
        let end = Instant::now() + Duration::from_secs(10);
        while self.alive() && Instant::now() < end {
            std::thread::sleep(Duration::from_millis(50));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn load_avg_1min() -> f64 {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next().and_then(|v| v.parse().ok()))
        .unwrap_or(f64::NAN)
}

/// Figures of one report period (or of the whole run).
#[derive(Default, Clone)]
struct Period {
    rss_min: u64,
    rss_max: u64,
    latencies: Vec<f32>,
    processed: (Option<u32>, u32),
    dropped: (Option<u32>, u32),
    good_sent: u64,
    hostile_sent: u64,
    hostile_refused: u64,
    hostile_accepted: u64,
    reinit_sent: u64,
    reinit_ok: u64,
    bad_reinit_sent: u64,
    bad_reinit_refused: u64,
    load: Vec<f64>,
    cpu_ticks: u64,
    /// Statuses whose counters went backwards (a second node publishing in the namespace).
    foreign: u64,
}

impl Period {
    fn rss(&mut self, kib: u64) {
        self.rss_min = if self.rss_min == 0 {
            kib
        } else {
            self.rss_min.min(kib)
        };
        self.rss_max = self.rss_max.max(kib);
    }

    fn counters(&mut self, s: &TrackStatus) {
        if s.frames_processed < self.processed.1 || s.frames_dropped < self.dropped.1 {
            self.foreign += 1;
        }
        self.processed = (
            Some(
                self.processed
                    .0
                    .map_or(s.frames_processed, |p| p.min(s.frames_processed)),
            ),
            self.processed.1.max(s.frames_processed),
        );
        self.dropped = (
            Some(
                self.dropped
                    .0
                    .map_or(s.frames_dropped, |p| p.min(s.frames_dropped)),
            ),
            self.dropped.1.max(s.frames_dropped),
        );
    }

    fn pct(&mut self) -> [f32; 4] {
        self.latencies.sort_by(f32::total_cmp);
        let l = &self.latencies;
        if l.is_empty() {
            return [f32::NAN; 4];
        }
        let q = |p: f64| l[((l.len() - 1) as f64 * p).round() as usize];
        [q(0.5), q(0.9), q(0.99), l[l.len() - 1]]
    }

    fn add(&mut self, o: &Period) {
        if o.rss_min > 0 {
            self.rss(o.rss_min);
            self.rss(o.rss_max);
        }
        self.latencies.extend_from_slice(&o.latencies);
        if let Some(p) = o.processed.0 {
            self.processed.0 = Some(self.processed.0.map_or(p, |q| q.min(p)));
        }
        self.processed.1 = self.processed.1.max(o.processed.1);
        if let Some(p) = o.dropped.0 {
            self.dropped.0 = Some(self.dropped.0.map_or(p, |q| q.min(p)));
        }
        self.dropped.1 = self.dropped.1.max(o.dropped.1);
        self.good_sent += o.good_sent;
        self.hostile_sent += o.hostile_sent;
        self.hostile_refused += o.hostile_refused;
        self.hostile_accepted += o.hostile_accepted;
        self.reinit_sent += o.reinit_sent;
        self.reinit_ok += o.reinit_ok;
        self.bad_reinit_sent += o.bad_reinit_sent;
        self.bad_reinit_refused += o.bad_reinit_refused;
        self.load.extend_from_slice(&o.load);
        self.cpu_ticks += o.cpu_ticks;
        self.foreign += o.foreign;
    }
}

const HEADER: &str = "| t (min) | RSS min MiB | RSS max MiB | processed | dropped | detections | p50 ms | p90 ms | p99 ms | max ms | hostile sent/refused | reinit ok/sent | bad reinit refused/sent | node CPU % | load 1m |";

fn row(label: &str, p: &mut Period, secs: f64) -> String {
    let [p50, p90, p99, max] = p.pct();
    let delta = |(a, b): (Option<u32>, u32)| a.map_or(0, |a| b.saturating_sub(a));
    let load = if p.load.is_empty() {
        f64::NAN
    } else {
        p.load.iter().sum::<f64>() / p.load.len() as f64
    };
    format!(
        "| {label} | {:.1} | {:.1} | {} | {} | {} | {p50:.1} | {p90:.1} | {p99:.1} | {max:.1} | {}/{} | {}/{} | {}/{} | {:.0} | {load:.2} |",
        p.rss_min as f64 / 1024.0,
        p.rss_max as f64 / 1024.0,
        delta(p.processed),
        delta(p.dropped),
        p.latencies.len(),
        p.hostile_sent,
        p.hostile_refused,
        p.reinit_ok,
        p.reinit_sent,
        p.bad_reinit_refused,
        p.bad_reinit_sent,
        // Clock ticks are 100 per second on Linux.
        p.cpu_ticks as f64 / secs.max(1e-9),
    )
}

fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("bevt_soak: error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> Result<()> {
    let a = Args::parse();
    anyhow::ensure!(
        (0.0..1.0).contains(&a.hostile_share),
        "--hostile-share must be in [0, 1)"
    );
    anyhow::ensure!(
        a.duration > 0.0 && a.rate > 0.0 && a.reinit_period > 0.0 && a.row_period > 0.0,
        "durations and rates must be positive"
    );
    anyhow::ensure!(
        (64..=4096).contains(&a.width) && (64..=4096).contains(&a.height),
        "--width/--height must be in 64..=4096"
    );
    let exe = match &a.node {
        Some(p) => p.clone(),
        None => std::env::current_exe()?
            .parent()
            .context("no folder of the executable")?
            .join("bevt_node_under_test"),
    };
    let pid = std::process::id();
    let domain = a.domain.unwrap_or(224 + (pid % 7) as u16);
    anyhow::ensure!(domain <= 232, "--domain must be in 0..=232");
    let namespace = a
        .namespace
        .clone()
        .unwrap_or_else(|| format!("/bevt_soak_{pid}"));
    let settings = RosSettings {
        domain_id: domain,
        namespace,
        node_name: format!("bevt_soak_node_{pid}"),
        networks: vec![IpAddr::V4(Ipv4Addr::LOCALHOST)],
        ..RosSettings::default()
    };
    // Frame id of the good camera frames (unique to this run as well).
    let camera_frame = format!("soak_camera_{pid}");
    let mut csv = match &a.csv {
        Some(p) => Some(std::fs::File::create(p).with_context(|| format!("{}", p.display()))?),
        None => None,
    };
    let mut node = NodeProcess::spawn(&exe, &settings)?;
    println!(
        "bevt_soak: node {} (pid {}), {}x{} rgb8 at {} Hz, {:.1} % hostile, reinit every {} s, {} s, domain {}, namespace {}, node name {}",
        exe.display(),
        node.0.id(),
        a.width,
        a.height,
        a.rate,
        a.hostile_share * 100.0,
        a.reinit_period,
        a.duration,
        settings.domain_id,
        settings.namespace,
        settings.node_name
    );
    let seq = SynthParams {
        width: a.width,
        height: a.height,
        frames: SEQ_FRAMES,
        target: (128.0, 96.0),
        path_amplitude: (240.0, 120.0),
        ..SynthParams::default()
    };
    let shared = CameraShared::default();
    let (stop, truth, sent, counts) = (
        shared.stop.clone(),
        shared.truth.clone(),
        shared.sent.clone(),
        shared.counts.clone(),
    );
    let peer = RawPeer::new(&settings)?;
    let gs = GroundStation::new(&settings)?;
    let camera = spawn_camera(
        peer,
        seq,
        a.rate,
        a.hostile_share,
        shared,
        camera_frame.clone(),
    )?;
    let newest_truth =
        || -> Option<(i64, BBox)> { truth.lock().ok()?.iter().next_back().map(|(k, v)| (*k, *v)) };
    // Start-up: the node answers a first reinit.
    let ready = Instant::now() + STARTUP;
    let first = loop {
        anyhow::ensure!(node.alive(), "the node exited during start-up");
        anyhow::ensure!(Instant::now() < ready, "the node did not answer reinit");
        std::thread::sleep(Duration::from_millis(500));
        let Some((stamp, b)) = newest_truth() else {
            continue;
        };
        if let Some(r) = gs.reinit(
            &reinit_request(b, Time::from_nanos(stamp), ""),
            Duration::from_secs(5),
        ) {
            break r;
        }
    };
    anyhow::ensure!(first.success, "first reinit failed: {}", first.message);
    let _ = gs.take_detections();
    let _ = gs.take_status();
    let _ = gs.take_reinit_replies();
    if let Ok(mut s) = sent.lock() {
        s.clear();
    }
    println!("{HEADER}");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    if let Some(f) = csv.as_mut() {
        writeln!(f, "t_min,rss_min_kib,rss_max_kib,processed,dropped,detections,p50_ms,p90_ms,p99_ms,max_ms,hostile_sent,hostile_refused,hostile_accepted,reinit_sent,reinit_ok,bad_reinit_sent,bad_reinit_refused,node_cpu_ticks,load1")?;
    }
    let start = Instant::now();
    let end = start + Duration::from_secs_f64(a.duration);
    let reinit_period = Duration::from_secs_f64(a.reinit_period);
    let mut next_reinit = start + reinit_period;
    let mut next_bad = start + reinit_period / 2;
    let mut next_sample = start;
    let row_period = Duration::from_secs_f64(a.row_period);
    let mut next_row = start + row_period;
    let mut row_start = start;
    let mut cur = Period::default();
    let mut total = Period::default();
    let (mut good0, mut hostile0) = (
        counts.good.load(Ordering::Relaxed),
        counts.hostile.load(Ordering::Relaxed),
    );
    let mut cpu0 = node.cpu_ticks().unwrap_or(0);
    // Reinit requests in flight: valid (true) or invalid (false), oldest first.
    let mut in_flight: std::collections::VecDeque<bool> = Default::default();
    let mut per_kind: BTreeMap<&'static str, (u64, u64, u64)> = BTreeMap::new();
    let mut accepted_examples: Vec<String> = Vec::new();
    let mut bad_accepted: Vec<String> = Vec::new();
    let mut rows = 0u32;
    let mut died = false;
    let mut bad_variant = 0u32;
    let mut last_seen: Option<i64> = None;
    while Instant::now() < end {
        let now = Instant::now();
        if now >= next_sample {
            next_sample += Duration::from_secs(1);
            if !node.alive() {
                died = true;
                break;
            }
            if let Some(r) = node.rss_kib() {
                cur.rss(r);
            }
            cur.load.push(load_avg_1min());
        }
        if now >= next_reinit {
            next_reinit += reinit_period;
            // As an operator would: a box on the newest frame the node processed (its
            // detection came back), so the frame is in the node's buffer (frames the node
            // skipped for a newer one are not).
            let on = last_seen.and_then(|t| Some((t, *truth.lock().ok()?.get(&t)?)));
            if let Some((stamp, b)) = on {
                if gs.send_reinit(&reinit_request(b, Time::from_nanos(stamp), "")) {
                    cur.reinit_sent += 1;
                    in_flight.push_back(true);
                }
            }
        }
        if now >= next_bad {
            next_bad += reinit_period;
            bad_variant += 1;
            let req = match bad_variant % 3 {
                0 => ReinitRequest {
                    x: 10.0,
                    y: 10.0,
                    width: f64::NAN,
                    height: 20.0,
                    ..ReinitRequest::default()
                },
                1 => ReinitRequest {
                    x: 10.0,
                    y: 10.0,
                    width: 0.0,
                    height: 0.0,
                    ..ReinitRequest::default()
                },
                _ => ReinitRequest {
                    x: 1e12,
                    y: -1e12,
                    width: 1e15,
                    height: 4.0,
                    ..ReinitRequest::default()
                },
            };
            if gs.send_reinit(&req) {
                cur.bad_reinit_sent += 1;
                in_flight.push_back(false);
            }
        }
        // Replies come back in request order (one server, served in turn).
        for r in gs.take_reinit_replies() {
            match in_flight.pop_front() {
                Some(true) if r.success => cur.reinit_ok += 1,
                Some(true) => eprintln!("reinit refused: {}", r.message),
                Some(false) if !r.success => cur.bad_reinit_refused += 1,
                Some(false) => bad_accepted.push(r.message),
                None => {}
            }
        }
        let got = wall_stamp().as_nanos();
        for d in gs.take_detections() {
            if d.header.frame_id == camera_frame {
                cur.latencies
                    .push((got - d.header.stamp.as_nanos()) as f32 / 1e6);
                last_seen = Some(d.header.stamp.as_nanos());
            }
        }
        for s in gs.take_status() {
            cur.counters(&s);
            if let Some(kind) = s.header.frame_id.strip_prefix(HOSTILE_PREFIX) {
                let e = per_kind.entry(leak_kind(kind)).or_default();
                if s.state == TrackStatus::STATE_ERROR {
                    cur.hostile_refused += 1;
                    e.1 += 1;
                } else {
                    cur.hostile_accepted += 1;
                    e.2 += 1;
                    if accepted_examples.len() < 10 {
                        accepted_examples.push(format!("{kind}: state {} ({})", s.state, s.reason));
                    }
                }
            }
        }
        if now >= next_row {
            next_row += row_period;
            rows += 1;
            let (g, h) = (
                counts.good.load(Ordering::Relaxed),
                counts.hostile.load(Ordering::Relaxed),
            );
            cur.good_sent = g - good0;
            cur.hostile_sent = h - hostile0;
            (good0, hostile0) = (g, h);
            let cpu = node.cpu_ticks().unwrap_or(cpu0);
            cur.cpu_ticks = cpu.saturating_sub(cpu0);
            cpu0 = cpu;
            let secs = now.duration_since(row_start).as_secs_f64();
            row_start = now;
            let line = row(&minutes(rows as f64 * a.row_period), &mut cur, secs);
            println!("{line}");
            if let Some(f) = csv.as_mut() {
                let [p50, p90, p99, max] = cur.pct();
                let delta = |(a, b): (Option<u32>, u32)| a.map_or(0, |a| b.saturating_sub(a));
                writeln!(
                    f,
                    "{:.2},{},{},{},{},{},{p50:.2},{p90:.2},{p99:.2},{max:.2},{},{},{},{},{},{},{},{},{:.2}",
                    rows as f64 * a.row_period / 60.0,
                    cur.rss_min,
                    cur.rss_max,
                    delta(cur.processed),
                    delta(cur.dropped),
                    cur.latencies.len(),
                    cur.hostile_sent,
                    cur.hostile_refused,
                    cur.hostile_accepted,
                    cur.reinit_sent,
                    cur.reinit_ok,
                    cur.bad_reinit_sent,
                    cur.bad_reinit_refused,
                    cur.cpu_ticks,
                    cur.load.iter().sum::<f64>() / cur.load.len().max(1) as f64
                )?;
                f.flush()?;
            }
            let _ = std::io::stdout().flush();
            total.add(&cur);
            cur = Period::default();
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    stop.store(true, Ordering::Relaxed);
    let _ = camera.join();
    let secs = start.elapsed().as_secs_f64();
    cur.good_sent = counts.good.load(Ordering::Relaxed) - good0;
    cur.hostile_sent = counts.hostile.load(Ordering::Relaxed) - hostile0;
    cur.cpu_ticks = node.cpu_ticks().unwrap_or(cpu0).saturating_sub(cpu0);
    total.add(&cur);
    let line = row("all", &mut total, secs);
    println!("{line}");
    if let Ok(s) = sent.lock() {
        let mut by_kind: BTreeMap<&str, u64> = BTreeMap::new();
        for k in s.values() {
            *by_kind.entry(k).or_default() += 1;
        }
        for (k, n) in by_kind {
            per_kind.entry(k).or_default().0 = n;
        }
    }
    println!("hostile messages by kind: sent / refused with an error status / accepted (unanswered ones were superseded by a newer frame before the node read them)");
    for (k, (n, r, acc)) in &per_kind {
        println!("  {k:20} {n:6} / {r:6} / {acc:6}");
    }
    println!(
        "camera published {} good + {} hostile messages in {secs:.0} s; node frames processed {}..{}, dropped {}..{}",
        total.good_sent,
        total.hostile_sent,
        total.processed.0.unwrap_or(0),
        total.processed.1,
        total.dropped.0.unwrap_or(0),
        total.dropped.1
    );
    let delta_processed = total
        .processed
        .0
        .map_or(0, |p| total.processed.1.saturating_sub(p));
    println!(
        "isolation: {} statuses with counters going backwards, {} detections for {} frames the node counted as processed and {} reinit accepted{}",
        total.foreign,
        total.latencies.len(),
        delta_processed,
        total.reinit_ok,
        // Each accepted reinit also publishes a detection (the reinit frame's) that the
        // processed counter does not count.
        if total.foreign > 0
            || total.latencies.len() as u64 > u64::from(delta_processed) + total.reinit_ok + 2
        {
            " -- WARNING: a second node answered in this namespace"
        } else {
            " (only this run's node answered)"
        }
    );
    if died {
        bail!("the node process exited during the soak");
    }
    if !accepted_examples.is_empty() {
        bail!("hostile messages were accepted: {accepted_examples:?}");
    }
    if !bad_accepted.is_empty() {
        bail!("invalid reinit requests were accepted: {bad_accepted:?}");
    }
    anyhow::ensure!(!total.latencies.is_empty(), "no detection received");
    drop(node);
    Ok(())
}

/// `secs` as minutes: whole ones bare, else with two decimals.
fn minutes(secs: f64) -> String {
    let m = secs / 60.0;
    if m.fract().abs() < 1e-9 {
        format!("{m:.0}")
    } else {
        format!("{m:.2}")
    }
}

/// The static name of a hostile kind received back in a frame id.
fn leak_kind(kind: &str) -> &'static str {
    HOSTILE_KINDS
        .iter()
        .find(|k| **k == kind)
        .copied()
        .unwrap_or("unknown")
}
