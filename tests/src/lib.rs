//! Shared helpers of the integration tests: locating `../shared`, temporary folders,
//! running the tracker over a synthetic sequence.
#![allow(clippy::expect_used)] // test-support crate: a failed setup should abort the test

pub mod fuzz;
pub mod scenes;

use bevt_core::eval::synth::SynthParams;
use bevt_core::{BBox, BevtTracker, Frame, PixelFormat, TrackOutput, Tracker, TrackerConfig};
use std::path::PathBuf;

/// The dev dataset beside the project (`../shared/datasets/uav123_10fps_dev`), if present.
pub fn dev_dataset() -> Option<PathBuf> {
    let root =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/datasets/uav123_10fps_dev");
    root.join("sequences.json").is_file().then_some(root)
}

/// The peer baselines beside the project, if present.
pub fn baselines() -> Option<PathBuf> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/baselines");
    root.is_dir().then_some(root)
}

/// A fresh, empty temporary folder unique to this process and `name`.
pub fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("bevt_it_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    let _ = std::fs::create_dir_all(&d);
    d
}

/// Per-frame result of tracking a synthetic sequence: (output, truth).
pub fn track_synthetic(
    seq: &SynthParams,
    cfg: TrackerConfig,
    init: BBox,
) -> Vec<(TrackOutput, BBox)> {
    let spec = cfg.validate().expect("valid config");
    let mut t = BevtTracker::new(spec);
    let f0 = seq.frame(0);
    t.init(
        &Frame::packed(&f0.rgb, seq.width, seq.height, PixelFormat::Rgb8).expect("frame"),
        init,
    )
    .expect("init");
    (1..seq.frames)
        .map(|i| {
            let f = seq.frame(i);
            let fr =
                Frame::packed(&f.rgb, seq.width, seq.height, PixelFormat::Rgb8).expect("frame");
            (t.update(&fr).expect("update"), f.truth)
        })
        .collect()
}

/// Frame `t` of a synthetic sequence as a `sensor_msgs/Image` (rgb8, stamped now), with its
/// true box.
pub fn synth_image(seq: &SynthParams, t: usize) -> (bevt_msgs::sensor_msgs::Image, BBox) {
    let f = seq.frame(t);
    (
        bevt_msgs::sensor_msgs::Image {
            header: bevt_msgs::std_msgs::Header {
                stamp: bevt_node::node::sim::wall_stamp(),
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

/// Statuses the ground station receives within `timeout`, until one satisfies `want`.
pub fn wait_status(
    gs: &bevt_node::node::sim::GroundStation,
    timeout: std::time::Duration,
    want: impl Fn(&bevt_msgs::bevt::TrackStatus) -> bool,
) -> Option<bevt_msgs::bevt::TrackStatus> {
    let end = std::time::Instant::now() + timeout;
    while std::time::Instant::now() < end {
        if let Some(s) = gs.take_status().into_iter().find(|s| want(s)) {
            return Some(s);
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    None
}
