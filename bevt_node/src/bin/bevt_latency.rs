//! Latency benchmark of the ROS node (not a test): a synthetic camera publishes
//! 1280×720 rgb8 frames at 30 Hz over DDS on loopback, the node tracks, and a ground
//! station measures image stamp → detection arrival. Prints p50/p90/p99/max and the
//! frames the node dropped to stay current.
//!
//! `cargo run --release -p bevt_node --bin bevt_latency -- [SECONDS] [RATE_HZ] [DOMAIN]`

use anyhow::{Context as _, Result};
use bevt_core::eval::synth::SynthParams;
use bevt_core::TrackerConfig;
use bevt_msgs::builtin_interfaces::Time;
use bevt_node::convert::reinit_request;
use bevt_node::node::app::{NodeCore, NodeSettings};
use bevt_node::node::ros::{run, ImageTransport, RosSettings};
use bevt_node::node::sim::{spawn_camera_as, wall_stamp, GroundStation};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.iter().any(|a| a == "-h" || a == "--help") {
        println!("bevt_latency: latency of the ROS 2 node over DDS on loopback (a benchmark, not a test)\n\nUsage: bevt_latency [SECONDS (20)] [RATE_HZ (30)] [DOMAIN (77)] [raw | jpeg (raw)]\n\nA synthetic camera publishes 1280x720 frames at RATE_HZ for SECONDS, rgb8 on image_raw or JPEG\n(quality 90) on image_raw/compressed, the node subscribed to that input (image_transport);\nthe node tracks; a ground station measures image stamp -> detection arrival and prints\np50/p90/p99/max.");
        return Ok(());
    }
    let seconds: f64 = args
        .first()
        .map_or(Ok(20.0), |s| s.parse())
        .context("SECONDS")?;
    let rate: f64 = args
        .get(1)
        .map_or(Ok(30.0), |s| s.parse())
        .context("RATE_HZ")?;
    let domain: u16 = args
        .get(2)
        .map_or(Ok(77), |s| s.parse())
        .context("DOMAIN")?;
    let jpeg = match args.get(3).map(String::as_str) {
        None | Some("raw") => false,
        Some("jpeg") => true,
        Some(other) => anyhow::bail!("the input is raw or jpeg, not {other}"),
    };
    let settings = RosSettings {
        domain_id: domain,
        image_transport: if jpeg {
            ImageTransport::Compressed
        } else {
            ImageTransport::Raw
        },
        ..RosSettings::default()
    };
    let stop = Arc::new(AtomicBool::new(false));
    let core = NodeCore::new(
        TrackerConfig::default().validate()?,
        NodeSettings::default(),
    );
    let (s2, st2) = (settings.clone(), stop.clone());
    let node = std::thread::Builder::new()
        .name("bevt-node".into())
        .spawn(move || run(core, &s2, st2, |_| {}))?;
    let seq = SynthParams {
        width: 1280,
        height: 720,
        frames: 150,
        target: (128.0, 96.0),
        path_amplitude: (240.0, 120.0),
        ..SynthParams::default()
    };
    let seq_frames = seq.frames;
    let input = if jpeg { "JPEG" } else { "rgb8" };
    println!("rendering and publishing 1280x720 {input} at {rate} Hz on domain {domain} for {seconds} s ...");
    let (camera, truth) = spawn_camera_as(&settings, seq, rate, stop.clone(), jpeg.then_some(90))?;
    let gs = GroundStation::new(&settings)?;
    // Measure only once the camera has rendered its whole loop (rendering competes for the
    // CPU) and discovery has settled.
    let frames = seq_frames;
    let ready = Instant::now() + Duration::from_secs(120);
    while truth.lock().map(|l| l.len()).unwrap_or(0) < frames + 10 {
        anyhow::ensure!(Instant::now() < ready, "the camera is not publishing");
        std::thread::sleep(Duration::from_millis(50));
    }
    let (stamp, b) = {
        let log = truth
            .lock()
            .map_err(|_| anyhow::anyhow!("truth log poisoned"))?;
        log.iter()
            .next_back()
            .map(|(k, v)| (*k, *v))
            .context("no frame published")?
    };
    let req = reinit_request(b, Time::from_nanos(stamp), "");
    let r = gs
        .reinit(&req, Duration::from_secs(10))
        .context("reinit not answered")?;
    anyhow::ensure!(r.success, "reinit failed: {}", r.message);
    let _ = gs.take_detections();
    let mut lat = Vec::new();
    let mut dropped = 0u32;
    let mut processed = (u32::MAX, 0u32);
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    while Instant::now() < end {
        for d in gs.take_detections() {
            let now = wall_stamp().as_nanos();
            lat.push((now - d.header.stamp.as_nanos()) as f64 / 1e6);
        }
        for s in gs.take_status() {
            dropped = dropped.max(s.frames_dropped);
            processed = (
                processed.0.min(s.frames_processed),
                processed.1.max(s.frames_processed),
            );
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    stop.store(true, Ordering::Relaxed);
    let _ = camera.join();
    let _ = node.join();
    anyhow::ensure!(!lat.is_empty(), "no detection received");
    lat.sort_by(f64::total_cmp);
    let q = |p: f64| lat[((lat.len() - 1) as f64 * p).round() as usize];
    let published = (seconds * rate).round();
    println!(
        "detections received: {} in {seconds} s (camera ~{published} frames); node frames processed {}..{}, dropped (total) {dropped}",
        lat.len(),
        processed.0,
        processed.1
    );
    println!(
        "latency image stamp -> detection received, ms: p50 {:.1}  p90 {:.1}  p99 {:.1}  max {:.1}",
        q(0.5),
        q(0.9),
        q(0.99),
        lat[lat.len() - 1]
    );
    Ok(())
}
