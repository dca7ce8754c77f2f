//! Shared helpers of the integration tests: locating `../shared`, temporary folders,
//! running the tracker over a synthetic sequence.
#![allow(clippy::expect_used)] // test-support crate: a failed setup should abort the test

pub mod fuzz;
pub mod scenes;

use bevt_core::eval::synth::SynthParams;
use bevt_core::{BBox, BevtTracker, Frame, PixelFormat, TrackOutput, Tracker, TrackerConfig};
use std::path::{Path, PathBuf};

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
    track_synthetic_passes(seq, cfg, init)
        .into_iter()
        .map(|(o, b, _)| (o, b))
        .collect()
}

/// [`track_synthetic`] with the learned verifier's search passes of each frame
/// ([`Tracker::verifier_passes`]; 0 without a verifier).
pub fn track_synthetic_passes(
    seq: &SynthParams,
    cfg: TrackerConfig,
    init: BBox,
) -> Vec<(TrackOutput, BBox, u64)> {
    let spec = cfg.validate().expect("valid config");
    let mut t = BevtTracker::new(spec);
    let f0 = seq.frame(0);
    t.init(
        &Frame::packed(&f0.rgb, seq.width, seq.height, PixelFormat::Rgb8).expect("frame"),
        init,
    )
    .expect("init");
    let mut before = t.verifier_passes().unwrap_or(0);
    (1..seq.frames)
        .map(|i| {
            let f = seq.frame(i);
            let fr =
                Frame::packed(&f.rgb, seq.width, seq.height, PixelFormat::Rgb8).expect("frame");
            let out = t.update(&fr).expect("update");
            let now = t.verifier_passes().unwrap_or(0);
            let passes = now - before;
            before = now;
            (out, f.truth, passes)
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

/// `m` (rgb8) as a PNG `sensor_msgs/CompressedImage` with the same header.
pub fn png_image(m: &bevt_msgs::sensor_msgs::Image) -> bevt_msgs::sensor_msgs::CompressedImage {
    let mut data = Vec::new();
    image::RgbImage::from_raw(m.width, m.height, m.data.clone())
        .expect("an rgb8 image")
        .write_to(
            &mut std::io::Cursor::new(&mut data),
            image::ImageFormat::Png,
        )
        .expect("PNG encoding");
    bevt_msgs::sensor_msgs::CompressedImage {
        header: m.header.clone(),
        format: "png".into(),
        data,
    }
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

/// A DDS domain id that no other test of any concurrently running test process holds.
///
/// Every DDS test takes its domain here, so two test files (or two `cargo test` runs) can
/// never meet on one domain. A claim is a file `bevt_dds_domains/<id>` in the temporary
/// folder holding the claiming process id; it lasts for the process, and a claim whose
/// process has ended is taken over. Domains 10..=232 are handed out (below 10 is left to
/// people's own ROS graphs on the same machine; 232 is the highest id RTPS port numbers
/// allow).
pub fn dds_domain() -> u16 {
    use std::io::Write;
    static NEXT: std::sync::atomic::AtomicU16 = std::sync::atomic::AtomicU16::new(0);
    const FIRST: u16 = 10;
    const LAST: u16 = 232;
    let dir = std::env::temp_dir().join("bevt_dds_domains");
    std::fs::create_dir_all(&dir).expect("create the domain claim folder");
    let me = std::process::id();
    let span = LAST - FIRST + 1;
    // Start each process at a different place so that claims rarely collide.
    let start = (me % u32::from(span)) as u16;
    loop {
        let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        assert!(n < span, "all DDS domains {FIRST}..={LAST} are claimed");
        let id = FIRST + (start + n) % span;
        let path = dir.join(id.to_string());
        let claim = || {
            std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&path)
                .and_then(|mut f| write!(f, "{me}"))
        };
        if claim().is_ok() {
            return id;
        }
        let owner: Option<u32> = std::fs::read_to_string(&path)
            .ok()
            .and_then(|s| s.trim().parse().ok());
        let alive = owner.is_some_and(|p| Path::new(&format!("/proc/{p}")).exists());
        if !alive && std::fs::remove_file(&path).is_ok() && claim().is_ok() {
            return id;
        }
    }
}

/// Whether this is a CI run (`CI=true`), where every component `.ci/run` installs is
/// present, so a test that would skip for want of one must fail instead.
pub fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true" || v == "1")
}

/// Skips the calling test with `reason` (printed in the normal test output), except under
/// `CI=true`, where the missing component is a CI defect and the test fails.
///
/// Call as `return skip("test_name", reason)` from a test whose prerequisite is missing.
#[track_caller]
#[allow(clippy::panic)] // failing the test is the point under CI
pub fn skip(test: &str, reason: impl std::fmt::Display) {
    if in_ci() {
        panic!("{test}: would skip under CI=true, where .ci/run installs what it needs: {reason}");
    }
    // Straight to the process's stderr: the test harness captures `print!` / `eprint!` of a
    // passing test, and a skip must show in the normal output of `cargo test`.
    use std::io::Write as _;
    let _ = writeln!(std::io::stderr(), "SKIPPED {test}: {reason}");
}
