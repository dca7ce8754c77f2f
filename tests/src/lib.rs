//! Shared helpers of the integration tests: locating `../shared`, temporary folders,
//! running the tracker over a synthetic sequence.
#![allow(clippy::expect_used)] // test-support crate: a failed setup should abort the test

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
