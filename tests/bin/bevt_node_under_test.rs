//! The ROS 2 node as a separate process, for tests that measure its memory or inspect its
//! sockets (an in-process node shares the test's memory and sockets).
//!
//! `bevt_node_under_test [--ros-args ...]` takes `bevt_node`'s arguments and runs the same
//! launch path (`launch_from_args`, `NodeCore`, `ros::run`) until its standard input
//! closes, so it never outlives the test that started it.

use bevt_node::node::app::NodeCore;
use bevt_node::node::node_params::{launch_from_args, wants_help, USAGE};
use bevt_node::node::ros;
use std::io::Read;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if wants_help(&args) {
        print!("bevt_node_under_test: bevt_node for tests (runs until its standard input closes)\n\n{USAGE}");
        return ExitCode::SUCCESS;
    }
    let launch = match launch_from_args(&args, |k| std::env::var(k).ok()) {
        Ok(l) => l,
        Err(e) => {
            eprintln!("bevt_node_under_test: {e}");
            return ExitCode::FAILURE;
        }
    };
    bevt_node::node::console::exit_on_any_panic("bevt_node_under_test");
    // Fault injection for the supervision tests (never set by the node itself).
    match std::env::var("BEVT_TEST_FAULT").as_deref() {
        Ok("reception_ends") => ros::inject_fault(ros::InjectedFault::ReceptionEnds),
        Ok("reception_panics") => ros::inject_fault(ros::InjectedFault::ReceptionPanics),
        Ok("worker_panics") => ros::inject_fault(ros::InjectedFault::WorkerPanics),
        Ok("other_thread_panics") => {
            // A stand-in for a thread the node does not own (RustDDS's event loop): the
            // process-wide hook catches a panic in any thread.
            let _ = std::thread::Builder::new()
                .name("dds-event-loop-stand-in".into())
                .spawn(|| {
                    std::thread::sleep(std::time::Duration::from_secs(2));
                    let v: Vec<u8> = Vec::new();
                    // Indexing past the end: a panic, as a defect in another thread would.
                    std::hint::black_box(v[std::hint::black_box(3)])
                });
        }
        Ok(other) => {
            eprintln!("bevt_node_under_test: unknown BEVT_TEST_FAULT {other:?}");
            return ExitCode::FAILURE;
        }
        Err(_) => {}
    }
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    let watcher = std::thread::Builder::new()
        .name("stdin-watch".into())
        .spawn(move || {
            let mut sink = [0u8; 64];
            let mut stdin = std::io::stdin();
            while matches!(stdin.read(&mut sink), Ok(n) if n > 0) {}
            s.store(true, Ordering::Relaxed);
        });
    if let Err(e) = watcher {
        eprintln!("bevt_node_under_test: cannot watch stdin: {e}");
        return ExitCode::FAILURE;
    }
    eprintln!(
        "bevt_node_under_test: {}",
        launch.ros.security.startup_line(launch.ros.domain_id)
    );
    let core = NodeCore::new(launch.tracker.clone(), launch.node.clone());
    match ros::run(core, &launch.ros, stop, |_| {}) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("bevt_node_under_test: {e}");
            ExitCode::FAILURE
        }
    }
}
