//! The parameter services are no memory amplifier: 20 `describe_parameters` requests of
//! 100,000 names each, whose replies are never read, raise the node process's peak RSS by at
//! most twice the bytes sent (the received fragments and the reassembled requests) and leave
//! its boxes coming at the camera rate.

use bevt_core::eval::synth::SynthParams;
use bevt_node::node::ros::{context, RosSettings};
use bevt_node::node::sim::{spawn_camera, GroundStation};
use ros2_client::rcl_interfaces::{DescribeParametersRequest, DescribeParametersResponse};
use ros2_client::{Name, NodeName, NodeOptions, ServiceTypeName};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// (VmRSS, VmHWM) of a process, KiB.
fn memory(pid: u32) -> (u64, u64) {
    let s = std::fs::read_to_string(format!("/proc/{pid}/status")).expect("status");
    let field = |name: &str| -> u64 {
        s.lines()
            .find_map(|l| l.strip_prefix(name))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
            .expect("a memory field")
    };
    (field("VmRSS:"), field("VmHWM:"))
}

#[test]
fn a_flood_of_huge_describe_requests_leaves_memory_and_boxes_alone() {
    const REQUESTS: usize = 20;
    const NAMES: usize = 100_000;
    let domain = bevt_tests::dds_domain();
    let settings = RosSettings {
        domain_id: domain,
        ..RosSettings::default()
    };
    let mut node = Command::new(env!("CARGO_BIN_EXE_bevt_node_under_test"))
        .args(["--ros-args", "-p", &format!("domain_id:={domain}")])
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start the node");
    let pid = node.id();
    let stop = Arc::new(AtomicBool::new(false));
    let seq = SynthParams {
        frames: 400,
        ..SynthParams::default()
    };
    let (camera, truth) = spawn_camera(&settings, seq, 20.0, stop.clone()).expect("camera");
    let gs = GroundStation::new(&settings).expect("ground station");
    std::thread::sleep(Duration::from_secs(2));
    let r = gs
        .start_track_on_newest(&truth, Duration::from_secs(30))
        .expect("reinit answered");
    assert!(r.success, "{}", r.message);
    // Steady state: 3 s of tracking.
    std::thread::sleep(Duration::from_secs(3));
    let _ = gs.take_detections();
    let (steady, _) = memory(pid);
    // The flood: a client that never reads its replies.
    let ctx = context(&settings).expect("context");
    let mut client_node = ctx
        .new_node(
            NodeName::new("/", "flooder").expect("name"),
            NodeOptions::new(),
        )
        .expect("node");
    let client = client_node
        .create_client::<DescribeParametersRequest, DescribeParametersResponse>(
            settings.service_mapping,
            &Name::new("/bevt_node", "describe_parameters").expect("name"),
            &ServiceTypeName::new("rcl_interfaces", "DescribeParameters"),
            bevt_node::node::ros::service_qos(),
            bevt_node::node::ros::service_qos(),
        )
        .expect("client");
    std::thread::sleep(Duration::from_secs(2));
    let names: Vec<String> = (0..NAMES)
        .map(|i| format!("tracker.no.such.key{i}"))
        .collect();
    // What the flood sends, in CDR: the sequence length, then per name its length, its bytes
    // and a NUL, padded to 4.
    let request_bytes: u64 = 4 + names
        .iter()
        .map(|n| (4 + n.len() as u64 + 1).div_ceil(4) * 4)
        .sum::<u64>();
    let flood_kib = REQUESTS as u64 * request_bytes / 1024;
    for _ in 0..REQUESTS {
        client
            .send_request(DescribeParametersRequest {
                names: names.clone(),
            })
            .expect("send");
    }
    // Boxes keep coming while the node digests the flood.
    let wall_ns = || {
        let t = bevt_node::node::sim::wall_stamp();
        i64::from(t.sec) * 1_000_000_000 + i64::from(t.nanosec)
    };
    let _ = gs.take_detections(); // the boxes of before the window
    let window_start = wall_ns();
    let start = Instant::now();
    let (mut last_box, mut longest_gap, mut boxes) = (Instant::now(), Duration::ZERO, 0);
    while start.elapsed() < Duration::from_secs(10) {
        let d = gs.take_detections();
        let now = Instant::now();
        if d.iter().any(|a| !a.detections.is_empty()) {
            boxes += d.len();
            longest_gap = longest_gap.max(now - last_box);
            last_box = now;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    longest_gap = longest_gap.max(Instant::now() - last_box);
    let window_end = wall_ns();
    // What the camera (a thread of this process, on the same cores) published in the same
    // window: on a machine loaded by other work it is starved too, and a pause of its
    // publishing is a pause of boxes that says nothing about the node.
    let (published, camera_gap) = {
        let log = truth.lock().expect("truth");
        let stamps: Vec<i64> = log
            .range(window_start..window_end)
            .map(|(k, _)| *k)
            .collect();
        let gap = stamps
            .windows(2)
            .map(|w| w[1] - w[0])
            .chain([
                stamps
                    .first()
                    .map_or(window_end - window_start, |f| f - window_start),
                stamps.last().map_or(0, |l| window_end - l),
            ])
            .max()
            .unwrap_or(0);
        (stamps.len(), Duration::from_nanos(gap.max(0) as u64))
    };
    let (rss, peak) = memory(pid);
    println!(
        "param flood: {flood_kib} KiB sent; steady RSS {steady} KiB, after {rss} KiB, peak {peak} KiB; {boxes} boxes in 10 s \
         ({published} frames published), longest gap {longest_gap:?} (the camera's {camera_gap:?})"
    );
    stop.store(true, Ordering::Relaxed);
    let _ = camera.join();
    drop(node.stdin.take());
    let _ = node.wait();
    // The bound follows from what was sent, not from the process's own size: the steady RSS
    // differs between builds and hosts (75-82 MiB) while the flood's bytes do not (a bound of
    // twice the steady RSS failed in CI at 154,640 KiB against 2 x 75,112 for an increase the
    // same as here). Before the services were bounded (a reply per name, 1000 unread replies
    // kept) the same flood held 1,285 MB, about 20 times what was sent.
    assert!(
        peak <= steady + 2 * flood_kib,
        "peak RSS {peak} KiB: more than the steady {steady} KiB plus twice the {flood_kib} KiB sent"
    );
    // The node may pause no more than 2 s beyond the camera's own longest pause, and
    // answer at least 3 of 4 published frames (quiet: 20 Hz, 200 frames, ~200 boxes).
    assert!(
        longest_gap <= Duration::from_secs(2) + camera_gap,
        "boxes stopped for {longest_gap:?} (the camera's longest pause {camera_gap:?})"
    );
    assert!(
        published >= 100 && 4 * boxes >= 3 * published,
        "{boxes} boxes for {published} frames published in 10 s at 20 Hz"
    );
}
