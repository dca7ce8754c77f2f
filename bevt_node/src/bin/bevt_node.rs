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
use bevt_node::node::console;
use bevt_node::node::node_params::{launch_from_args, wants_help, Launch, USAGE};
use bevt_node::node::ros;
use bevt_node::node::sim::{spawn_camera, GroundStation};
use bevt_node::tool::replay::state_name;
use ros2_client::log::LogLevel;
use std::collections::BTreeMap;
use std::ops::Bound;
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

/// The demo's script, announced before it starts: what happens when, and what to expect.
fn demo_script(seq: &SynthParams, duration: Duration) -> String {
    let (from, to) = seq.hidden.unwrap_or((0, 0));
    let secs = |frames: usize| frames as f64 / DEMO_RATE_HZ;
    let mut s = format!(
        "script: at t=1 s the ground station sends the initial box; at t={:.0} s the target \
         leaves the view for {:.0} s (scripted, not a failure) and comes back {:.0} px to the \
         left at t={:.0} s: the node should report it lost, then re-acquire it. The camera \
         repeats its {:.0} s flight.",
        secs(from),
        secs(to - from),
        -DEMO_REAPPEAR_OFFSET.0,
        secs(to),
        secs(seq.frames)
    );
    if duration.as_secs_f64() < secs(to) + 1.0 {
        s.push_str(&format!(
            "\n(with --duration {:.1} the demo ends before the target comes back)",
            duration.as_secs_f64()
        ));
    }
    s
}

/// The header of the demo's once-per-second lines, and what each column means.
const DEMO_COLUMNS: &str = "\
columns: t = camera time, s; state = the last /track_status state; x y w h = the published \
box (top-left corner and size), px; confidence = the node's confidence that the box is on the \
target, 0..1; error = distance from the box centre to the true centre, px
 t (s)  state               x       y      w      h  confidence  error vs truth";

/// One once-per-second line of the demo; `detection` is (box, confidence).
fn demo_row(t: f64, state: &str, detection: Option<(bevt_core::BBox, f32)>, error: &str) -> String {
    match detection {
        Some((b, c)) => format!(
            "{t:6.1}  {state:<13} {:7.1} {:7.1} {:6.1} {:6.1}  {c:10.3}  {error}",
            b.x, b.y, b.w, b.h
        ),
        None => format!("{t:6.1}  {state:<13}{:>42}  {error}", "(no box published)"),
    }
}

/// Frame numbers of the camera's stamps, counted as they appear in its truth log.
#[derive(Default)]
struct FrameClock {
    /// Stamp (ns) -> frame number since the camera started; the newest entries only.
    frames: BTreeMap<i64, usize>,
    /// Frames seen.
    seen: usize,
}

impl FrameClock {
    /// Most stamps remembered.
    const KEEP: usize = 2_000;

    /// Numbers the stamps the log gained since the last call.
    fn update(&mut self, log: &BTreeMap<i64, bevt_core::BBox>) {
        let after = match self.frames.keys().next_back() {
            Some(&l) => Bound::Excluded(l),
            None => Bound::Unbounded,
        };
        for &k in log.range((after, Bound::Unbounded)).map(|(k, _)| k) {
            self.frames.insert(k, self.seen);
            self.seen += 1;
        }
        while self.frames.len() > Self::KEEP {
            self.frames.pop_first();
        }
    }

    /// Frame number of the frame stamped `stamp`.
    fn frame_of(&self, stamp: i64) -> Option<usize> {
        self.frames.get(&stamp).copied()
    }
}

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
    println!("{}", demo_script(&seq, launch.demo_duration));
    let core = NodeCore::new(launch.tracker.clone(), launch.node.clone());
    let ros_settings = launch.ros.clone();
    let node_stop = stop.clone();
    let node = std::thread::Builder::new()
        .name("bevt-node".into())
        .spawn(move || ros::run(core, &ros_settings, node_stop, |_| {}))?;
    let (camera, truth) = spawn_camera(&launch.ros, seq.clone(), DEMO_RATE_HZ, stop.clone())?;
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
    println!("{DEMO_COLUMNS}");
    // The duration is range-checked at start-up; the addition is checked all the same.
    let end = Instant::now()
        .checked_add(launch.demo_duration)
        .context("--duration is too long")?;
    let mut next_print = Instant::now() + Duration::from_secs(1);
    let mut last = None;
    let mut status = None;
    let mut clock = FrameClock::default();
    let mut was_visible = true;
    let (hide_from, hide_to) = DEMO_HIDDEN_FRAMES;
    let camera_time = |frame: usize| frame as f64 / DEMO_RATE_HZ;
    while Instant::now() < end && !stop.load(Ordering::Relaxed) {
        if let Ok(log) = truth.lock() {
            clock.update(&log);
        }
        // Announce the scripted moments as the camera reaches them.
        let newest = clock.seen.saturating_sub(1);
        let visible = seq.visible(newest % seq.frames);
        if visible != was_visible {
            let t = camera_time(newest);
            if visible {
                println!(
                    "{t:6.1}  >>> scripted: the target is back in view, {:.0} px left of where it \
                     left; expect 'reacquired', then 'tracking'",
                    -DEMO_REAPPEAR_OFFSET.0
                );
            } else {
                println!(
                    "{t:6.1}  >>> scripted: the target leaves the view now for {:.0} s; expect \
                     'uncertain', then 'lost' (no box published)",
                    camera_time(hide_to - hide_from)
                );
            }
            was_visible = visible;
        }
        if let Some(d) = gs.take_detections().into_iter().last() {
            last = Some(d);
        }
        for s in gs.take_status() {
            // Print every state change with its reason as it arrives.
            let changed = status
                .as_ref()
                .is_none_or(|p: &bevt_msgs::bevt::TrackStatus| p.state != s.state);
            if changed {
                let t = clock
                    .frame_of(s.header.stamp.as_nanos())
                    .map_or(camera_time(newest), camera_time);
                let reason = if s.reason.is_empty() {
                    String::new()
                } else {
                    format!(" ({})", s.reason)
                };
                println!("{t:6.1}  state -> {}{reason}", state_name(s.state));
            }
            status = Some(s);
        }
        if Instant::now() >= next_print {
            next_print += Duration::from_secs(1);
            let state = status.as_ref().map_or("-", |s| state_name(s.state));
            let t = camera_time(newest);
            let line = match &last {
                Some(d) if !d.detections.is_empty() => {
                    let b = bbox_from_detection(&d.detections[0]);
                    let stamp = d.header.stamp.as_nanos();
                    let frame = clock.frame_of(stamp);
                    let hidden = frame.is_some_and(|f| !seq.visible(f % seq.frames));
                    let error = match truth.lock().ok().and_then(|l| l.get(&stamp).copied()) {
                        _ if hidden => "target out of view (scripted)".to_string(),
                        Some(t) => format!("{:.1} px", b.center().distance(&t.center())),
                        None => "?".to_string(),
                    };
                    let score = d.detections[0]
                        .results
                        .first()
                        .map_or(f32::NAN, |r| r.hypothesis.score as f32);
                    demo_row(
                        frame.map_or(t, camera_time),
                        state,
                        Some((b, score)),
                        &error,
                    )
                }
                Some(_) if !was_visible => {
                    demo_row(t, state, None, "target out of view (scripted)")
                }
                Some(_) => demo_row(t, state, None, "target in view, not re-acquired yet"),
                None => demo_row(t, state, None, "waiting for the first box"),
            };
            println!("{line}");
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
    // Start-up lines in the node's log format (severity, time, node name), under its
    // `--log-level` like every later line.
    let (threshold, node_name) = (launch.ros.log_level, launch.ros.node_name.clone());
    let log = |level: LogLevel, text: &str| console::log(level, threshold, &node_name, text);
    // An unsecured node says so as a warning; a secured one names its enclave.
    let security = &launch.ros.security;
    match security.warning(launch.ros.domain_id) {
        Some(w) => log(LogLevel::Warn, &w),
        None => log(LogLevel::Info, &security.startup_line(launch.ros.domain_id)),
    }
    if launch.demo {
        return demo(launch, stop);
    }
    log(
        LogLevel::Info,
        &format!(
            "domain {}, namespace {}, interfaces {:?}, services {:?}, camera input {}",
            launch.ros.domain_id,
            launch.ros.namespace,
            launch.ros.networks,
            launch.ros.service_mapping,
            launch.ros.image_transport.name()
        ),
    );
    let core = NodeCore::new(launch.tracker.clone(), launch.node.clone());
    ros::run(core, &launch.ros, stop, |_| {})?;
    Ok(())
}

fn main() -> ExitCode {
    // A dead thread must not leave a silent node: any panic ends the process non-zero.
    bevt_node::node::console::exit_on_any_panic("bevt_node");
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("bevt_node: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod demo_tests {
    use super::*;
    use bevt_core::BBox;

    /// Right edge (exclusive char index) of the word `w` in `line`.
    fn right_edge(line: &str, w: &str) -> usize {
        line.find(w).map(|i| i + w.len()).unwrap()
    }

    #[test]
    fn rows_line_up_under_the_labelled_columns() {
        let header = DEMO_COLUMNS.lines().last().unwrap();
        let b = BBox::new(-14.25, 155.0, 129.5, 97.125);
        let row = demo_row(9.2, "reacquired", Some((b, 0.789)), "0.2 px");
        assert_eq!(
            row,
            "   9.2  reacquired      -14.2   155.0  129.5   97.1       0.789  0.2 px"
        );
        // Each number ends under its label.
        for (label, value) in [
            ("t (s)", "9.2"),
            (" x", "-14.2"),
            (" y", "155.0"),
            (" w", "129.5"),
            (" h", "97.1"),
            ("confidence", "0.789"),
        ] {
            assert_eq!(
                right_edge(header, label),
                right_edge(&row, value),
                "{label}\n{header}\n{row}"
            );
        }
        assert_eq!(header.find("state"), row.find("reacquired"));
        assert_eq!(header.find("error"), row.find("0.2 px"));
        let none = demo_row(6.2, "lost", None, "target out of view (scripted)");
        assert_eq!(header.find("error"), none.find("target out"), "{none}");
        // The legend names every column and its unit.
        for w in ["t = camera time, s", "x y w h", "px", "confidence", "error"] {
            assert!(DEMO_COLUMNS.contains(w), "{w}");
        }
    }

    #[test]
    fn the_script_announces_the_scripted_loss() {
        let seq = SynthParams {
            frames: 300,
            hidden: Some(DEMO_HIDDEN_FRAMES),
            ..SynthParams::default()
        };
        let s = demo_script(&seq, Duration::from_secs(10));
        for w in [
            "at t=5 s the target leaves the view for 2 s",
            "150 px to the left at t=7 s",
            "report it lost, then re-acquire it",
        ] {
            assert!(s.contains(w), "{w:?} in {s}");
        }
        assert!(!s.contains("ends before"), "{s}");
        assert!(demo_script(&seq, Duration::from_secs(6)).contains("ends before the target"));
    }

    #[test]
    fn the_frame_clock_numbers_stamps_as_they_arrive() {
        let b = BBox::new(0.0, 0.0, 1.0, 1.0);
        let mut log: BTreeMap<i64, BBox> = (0..3).map(|i| (100 + i * 50, b)).collect();
        let mut c = FrameClock::default();
        c.update(&log);
        log.pop_first();
        log.insert(250, b);
        c.update(&log);
        assert_eq!(c.seen, 4);
        assert_eq!(c.frame_of(100), Some(0));
        assert_eq!(c.frame_of(250), Some(3));
        assert_eq!(c.frame_of(251), None);
    }
}
