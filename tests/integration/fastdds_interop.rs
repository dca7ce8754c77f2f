//! Interoperability with ROS 2's default middleware: a C++ peer on eProsima Fast DDS 2.9
//! (tests/fastdds/peer.cpp, built by scripts/fastdds-peer.sh from Debian's packages)
//! publishes frames of a real dev sequence (downscaled 2x; the synthetic sequence when
//! `../shared` is absent) with ROS 2's DDS type names, calls `reinit` with the Fast DDS
//! (rmw_fastrtps_cpp) request/reply mapping, the node's default, and reads `detections`
//! and `track_status`; the boxes are scored against the ground truth here as in
//! [`crate::interop`].

use crate::interop::{score, write_frames, FRAMES, HIT_PX, RATE_HZ};
use bevt_core::TrackerConfig;
use bevt_node::node::app::{NodeCore, NodeSettings};
use bevt_node::node::ros::{run, RosSettings};
use bevt_tests::temp_dir;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Builds the peer (once; the script installs nothing when called from here, `.ci/run`
/// installs the packages); `Err` says why it cannot be built here.
fn fastdds_peer() -> Result<PathBuf, String> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/fastdds-peer.sh");
    let out = Command::new("bash")
        .arg(&script)
        .arg("--no-install")
        .output()
        .map_err(|e| format!("cannot run {}: {e}", script.display()))?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        let last = err.lines().rev().take(3).collect::<Vec<_>>();
        return Err(format!(
            "{} failed: {}",
            script.display(),
            last.into_iter().rev().collect::<Vec<_>>().join(" / ")
        ));
    }
    Ok(PathBuf::from(
        String::from_utf8_lossy(&out.stdout).trim().to_string(),
    ))
}

#[test]
fn a_fast_dds_peer_with_the_rmw_fastrtps_mapping_drives_the_node() {
    let peer = match fastdds_peer() {
        Ok(p) => p,
        Err(e) => {
            bevt_tests::skip(
                "a_fast_dds_peer_with_the_rmw_fastrtps_mapping_drives_the_node",
                e,
            );
            return;
        }
    };
    let dir = temp_dir("fastdds");
    let truth = write_frames(&dir);
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("meta.json")).unwrap()).unwrap();
    let domain = bevt_tests::dds_domain();
    // The node's default settings: Enhanced (Fast DDS) service mapping.
    let settings = RosSettings {
        domain_id: domain,
        ..RosSettings::default()
    };
    assert_eq!(
        settings.service_mapping,
        ros2_client::ServiceMapping::Enhanced
    );
    let stop = Arc::new(AtomicBool::new(false));
    let core = NodeCore::new(
        TrackerConfig::default().validate().unwrap(),
        NodeSettings::default(),
    );
    let (s2, st2) = (settings.clone(), stop.clone());
    let node = std::thread::spawn(move || run(core, &s2, st2, |_| {}).unwrap());
    let init = &meta["init"];
    let out = Command::new(&peer)
        .arg(domain.to_string())
        .arg(&dir)
        .arg(RATE_HZ.to_string())
        .arg(meta["width"].to_string())
        .arg(meta["height"].to_string())
        .arg(meta["count"].to_string())
        .args((0..4).map(|i| init[i].to_string()))
        .output()
        .unwrap();
    stop.store(true, Ordering::Relaxed);
    let _ = node.join();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "Fast DDS peer failed ({}):\n{stdout}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    let scored = score(&stdout, &truth);
    let reinit = scored.reinit.clone().unwrap_or_default();
    assert_eq!(
        reinit["success"].as_bool(),
        Some(true),
        "reinit over Fast DDS failed:\n{stdout}"
    );
    // The reply named the client's reply reader, as rmw_fastrtps_cpp's server does.
    assert_eq!(
        reinit["related_guid"], reinit["reply_reader_guid"],
        "the reply's related sample identity is not the client's:\n{stdout}"
    );
    // Track status: the frames after the reinit are tracked, under one track id.
    let statuses: Vec<serde_json::Value> = stdout
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter_map(|v| v.get("status").cloned())
        .filter(|s| s["frame"].as_i64().is_some_and(|f| f > 0))
        .collect();
    let tracking = statuses
        .iter()
        .filter(|s| matches!(s["state"].as_u64(), Some(1 | 2 | 5)) && s["track_id"] == 1)
        .count();
    let (n, good) = (scored.n, scored.good);
    println!(
        "interop (Fast DDS): {n} detections matched to frames, {good} within {HIT_PX} px \
         (20 px full-size); centre error mean {:.1} px, max {:.1} px; {} statuses, {tracking} \
         tracking",
        scored.mean_err,
        scored.max_err,
        statuses.len()
    );
    assert!(n >= FRAMES / 2, "only {n} detections for {FRAMES} frames");
    assert!(
        good * 10 >= n * 9,
        "{good}/{n} within the precision threshold"
    );
    assert!(
        tracking >= FRAMES / 2,
        "only {tracking} track statuses in a tracking state:\n{stdout}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
