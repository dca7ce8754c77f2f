//! `bevt_node`: the ROS 2 tracking node (`ros2 run bevt_node bevt_node --ros-args ...`).
//!
//! `bevt_node --demo [--duration S]` runs the node with an in-process synthetic camera and a
//! simulated ground station that initialises the track on a frame it received late, and
//! prints the track once per second.

use anyhow::{Context as _, Result};
use bevt_core::eval::synth::SynthParams;
use bevt_msgs::builtin_interfaces::Time;
use bevt_node::convert::bbox_from_detection;
use bevt_node::convert::reinit_request;
use bevt_node::node::app::NodeCore;
use bevt_node::node::node_params::{launch_from_args, wants_help, Launch, USAGE};
use bevt_node::node::ros;
use bevt_node::node::sim::{spawn_camera, GroundStation};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// How late the demo's operator box is: the frame it was drawn on is this old.
const DEMO_OPERATOR_DELAY: Duration = Duration::from_millis(400);
/// Demo camera rate.
const DEMO_RATE_HZ: f64 = 20.0;
/// Demo frames in which the target is out of view (5 s to 7 s at 20 Hz).
const DEMO_HIDDEN_FRAMES: (usize, usize) = (100, 140);
/// Where the demo target reappears, relative to its path, pixels.
const DEMO_REAPPEAR_OFFSET: (f32, f32) = (-150.0, 0.0);

fn demo(launch: Launch, stop: Arc<AtomicBool>) -> Result<()> {
    let seq = SynthParams {
        width: 640,
        height: 360,
        frames: 300,
        target: (64.0, 48.0),
        path_amplitude: (120.0, 60.0),
        // The target leaves the view for 2 s and comes back 150 px to the left, so the
        // demo shows the lost state and the re-detection (issue 8).
        hidden: Some(DEMO_HIDDEN_FRAMES),
        reappear_offset: DEMO_REAPPEAR_OFFSET,
        ..SynthParams::default()
    };
    println!(
        "bevt_node demo: synthetic {}x{} camera at {DEMO_RATE_HZ} Hz on domain {}; a ground station initialises on a frame {} ms old",
        seq.width,
        seq.height,
        launch.ros.domain_id,
        DEMO_OPERATOR_DELAY.as_millis()
    );
    let core = NodeCore::new(launch.tracker.clone(), launch.node.clone());
    let ros_settings = launch.ros.clone();
    let node_stop = stop.clone();
    let node = std::thread::Builder::new()
        .name("bevt-node".into())
        .spawn(move || ros::run(core, &ros_settings, node_stop, |_| {}))?;
    let (camera, truth) = spawn_camera(&launch.ros, seq, DEMO_RATE_HZ, stop.clone())?;
    let gs = GroundStation::new(&launch.ros)?;
    std::thread::sleep(Duration::from_secs(1));
    // The operator drew the box on an older frame: pick the frame ~400 ms old.
    let (stamp, b) = {
        let log = truth
            .lock()
            .map_err(|_| anyhow::anyhow!("truth log poisoned"))?;
        let target =
            log.keys().next_back().copied().unwrap_or(0) - DEMO_OPERATOR_DELAY.as_nanos() as i64;
        log.range(target..)
            .next()
            .map(|(k, v)| (*k, *v))
            .context("the camera published nothing")?
    };
    let req = reinit_request(b, Time::from_nanos(stamp), "");
    match gs.reinit(&req, Duration::from_secs(5)) {
        Some(r) => println!(
            "ground station: reinit -> success={} ({})",
            r.success, r.message
        ),
        None => println!("ground station: reinit timed out"),
    }
    // The duration is range-checked at start-up; the addition is checked all the same.
    let end = Instant::now()
        .checked_add(launch.demo_duration)
        .context("--duration is too long")?;
    let mut next_print = Instant::now() + Duration::from_secs(1);
    let mut last = None;
    let mut status = None;
    while Instant::now() < end && !stop.load(Ordering::Relaxed) {
        if let Some(d) = gs.take_detections().into_iter().last() {
            last = Some(d);
        }
        for s in gs.take_status() {
            // Print every state change with its reason as it arrives.
            let changed = status
                .as_ref()
                .is_none_or(|p: &bevt_msgs::bevt::TrackStatus| p.state != s.state);
            if changed && !s.reason.is_empty() {
                println!("track_status: state {} ({})", s.state, s.reason);
            }
            status = Some(s);
        }
        if Instant::now() >= next_print {
            next_print += Duration::from_secs(1);
            match &last {
                Some(d) if !d.detections.is_empty() => {
                    let b = bbox_from_detection(&d.detections[0]);
                    let t = truth
                        .lock()
                        .ok()
                        .and_then(|l| l.get(&d.header.stamp.as_nanos()).copied());
                    let err = t.map_or("?".to_string(), |t| {
                        format!("{:.1} px", b.center().distance(&t.center()))
                    });
                    println!(
                        "track {}: box {:7.1} {:7.1} {:5.1} {:5.1}  confidence {:.3}  error vs truth {err}",
                        d.detections[0].id, b.x, b.y, b.w, b.h, d.detections[0].results[0].hypothesis.score
                    );
                }
                Some(_) => println!("no detection (target lost)"),
                None => println!("no detection yet"),
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    stop.store(true, Ordering::Relaxed);
    let _ = camera.join();
    match node.join() {
        Ok(r) => r?,
        Err(_) => anyhow::bail!("the node thread panicked"),
    }
    Ok(())
}

fn run() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if wants_help(&args) {
        print!("{USAGE}");
        return Ok(());
    }
    let launch = launch_from_args(&args, |k| std::env::var(k).ok())?;
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    ctrlc::set_handler(move || s.store(true, Ordering::Relaxed))
        .context("cannot install the SIGINT/SIGTERM handler")?;
    eprintln!(
        "bevt_node: {}",
        launch.ros.security.startup_line(launch.ros.domain_id)
    );
    if launch.demo {
        return demo(launch, stop);
    }
    eprintln!(
        "bevt_node: domain {}, namespace {}, interfaces {:?}, services {:?}",
        launch.ros.domain_id, launch.ros.namespace, launch.ros.networks, launch.ros.service_mapping
    );
    let core = NodeCore::new(launch.tracker.clone(), launch.node.clone());
    ros::run(core, &launch.ros, stop, |_| {})?;
    Ok(())
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("bevt_node: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
