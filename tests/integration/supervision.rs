//! A thread that dies never leaves a silent node: the node process logs which thread died
//! and why, and exits non-zero (70 for a panic, 1 for a thread that returned), so that a
//! launch respawn or a service manager restarts it. Faults are injected through
//! `BEVT_TEST_FAULT`, read only by the test binary `bevt_node_under_test`.

use bevt_core::eval::synth::SynthParams;
use bevt_node::node::ros::RosSettings;
use bevt_node::node::sim::spawn_camera;
use std::io::Read;
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// How long a faulty node may take to end (start-up, discovery, the first frame).
const DEADLINE: Duration = Duration::from_secs(30);

/// Runs the node with `fault` (and a synthetic camera on its domain when `camera`), and
/// returns its exit code and standard error once it has ended by itself.
fn run_with_fault(fault: &str, camera: bool) -> (Option<i32>, String) {
    let domain = bevt_tests::dds_domain();
    let mut child = Command::new(env!("CARGO_BIN_EXE_bevt_node_under_test"))
        .args([
            "--ros-args",
            "-p",
            &format!("domain_id:={domain}"),
            "-p",
            "network_interfaces:=[127.0.0.1]",
        ])
        .env("BEVT_TEST_FAULT", fault)
        // Kept open: the node under test stops when its stdin closes, so an end before the
        // deadline is the fault's doing.
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start bevt_node_under_test");
    let stop = Arc::new(AtomicBool::new(false));
    let cam = camera.then(|| {
        let settings = RosSettings {
            domain_id: domain,
            ..RosSettings::default()
        };
        spawn_camera(&settings, SynthParams::default(), 20.0, stop.clone())
            .expect("camera")
            .0
    });
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().expect("wait") {
            break Some(s);
        }
        if start.elapsed() > DEADLINE {
            let _ = child.kill();
            break None;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    stop.store(true, Ordering::Relaxed);
    if let Some(c) = cam {
        let _ = c.join();
    }
    let mut err = String::new();
    if let Some(mut e) = child.stderr.take() {
        let _ = e.read_to_string(&mut err);
    }
    assert!(
        status.is_some(),
        "{fault}: the node kept running silently\n{err}"
    );
    (status.and_then(|s| s.code()), err)
}

#[test]
fn a_reception_thread_that_returns_ends_the_node_with_the_reason() {
    let (code, err) = run_with_fault("reception_ends", false);
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("[FATAL]") && err.contains("bevt-dds-rx thread ended unexpectedly"),
        "{err}"
    );
}

#[test]
fn a_panic_in_the_reception_thread_ends_the_node() {
    let (code, err) = run_with_fault("reception_panics", false);
    assert_eq!(code, Some(70), "{err}");
    assert!(
        err.contains("thread 'bevt-dds-rx' died: injected fault"),
        "{err}"
    );
}

#[test]
fn a_panic_in_the_worker_ends_the_node() {
    let (code, err) = run_with_fault("worker_panics", true);
    assert_eq!(code, Some(70), "{err}");
    assert!(err.contains("died: injected fault: the worker"), "{err}");
}

#[test]
fn a_panic_in_a_thread_the_node_does_not_own_ends_the_node() {
    let (code, err) = run_with_fault("other_thread_panics", false);
    assert_eq!(code, Some(70), "{err}");
    assert!(
        err.contains("thread 'dds-event-loop-stand-in' died: index out of bounds"),
        "{err}"
    );
}
