//! Interoperability with an independent DDS implementation: a Python `cyclonedds` peer
//! (tests/interop/cyclone_peer.py, in the project-local venv) publishes frames of a real
//! dev sequence (downscaled 2x; the synthetic sequence when `../shared` is absent) to the
//! node, calls `reinit` with the rmw_cyclonedds service mapping, and records the
//! detections; the boxes are scored against the ground truth here.

use bevt_core::eval::synth::SynthParams;
use bevt_core::{BBox, TrackerConfig};
use bevt_node::node::app::{NodeCore, NodeSettings};
use bevt_node::node::ros::{run, RosSettings};
use bevt_tests::{dev_dataset, temp_dir};
use ros2_client::ServiceMapping;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Frames sent to the peer.
pub(crate) const FRAMES: usize = 60;
/// Camera rate of the peer.
pub(crate) const RATE_HZ: f64 = 10.0;
/// Centre error counted as a hit: 20 px at full resolution = 10 px on the 2x downscaled
/// frames (the synthetic sequence is not scaled; 10 px is stricter there).
pub(crate) const HIT_PX: f32 = 10.0;

pub(crate) fn python() -> Result<PathBuf, String> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/python-env.sh");
    let out = Command::new("bash")
        .arg(&script)
        .output()
        .map_err(|e| format!("cannot run {}: {e}", script.display()))?;
    if !out.status.success() {
        return Err(format!(
            "{} failed: {}",
            script.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    Ok(PathBuf::from(
        String::from_utf8_lossy(&out.stdout).trim().to_string(),
    ))
}

/// Writes raw rgb8 frames + meta.json; returns the ground truth per frame.
pub(crate) fn write_frames(dir: &Path) -> Vec<Option<BBox>> {
    let mut truth = Vec::new();
    let (w, h);
    if let Some(root) = dev_dataset() {
        let mut ds = bevt_node::tool::dataset::open_dataset(&root).unwrap();
        ds.select(&["building4".to_string()]).unwrap();
        let seq = ds.sequences[0].load().unwrap();
        let mut size = (0, 0);
        for (i, path) in seq.frames.iter().take(FRAMES).enumerate() {
            let img = image::open(path).unwrap().to_rgb8();
            let half = image::imageops::resize(
                &img,
                img.width() / 2,
                img.height() / 2,
                image::imageops::FilterType::Triangle,
            );
            size = (half.width() as usize, half.height() as usize);
            std::fs::write(dir.join(format!("frame_{i:05}.rgb")), half.as_raw()).unwrap();
            truth.push(seq.truth[i].map(|b| BBox::new(b.x / 2.0, b.y / 2.0, b.w / 2.0, b.h / 2.0)));
        }
        (w, h) = size;
        println!("interop: building4 (real dev frames, downscaled to {w}x{h})");
    } else {
        println!("interop: ../shared absent, using the synthetic sequence");
        let s = SynthParams::default();
        for i in 0..FRAMES {
            let f = s.frame(i);
            std::fs::write(dir.join(format!("frame_{i:05}.rgb")), &f.rgb).unwrap();
            truth.push(Some(f.truth));
        }
        (w, h) = (s.width, s.height);
    }
    let b = truth[0].unwrap();
    let meta = serde_json::json!({"width": w, "height": h, "count": truth.len(), "init": [b.x, b.y, b.w, b.h]});
    std::fs::write(dir.join("meta.json"), meta.to_string()).unwrap();
    truth
}

#[test]
fn an_independent_cyclone_dds_peer_drives_the_node() {
    let py = match python() {
        Ok(p) => p,
        Err(e) => {
            bevt_tests::skip(
                "an_independent_cyclone_dds_peer_drives_the_node",
                format!("no Python environment ({e})"),
            );
            return;
        }
    };
    let dir = temp_dir("interop");
    let truth = write_frames(&dir);
    let domain = bevt_tests::dds_domain();
    let settings = RosSettings {
        domain_id: domain,
        service_mapping: ServiceMapping::Cyclone,
        ..RosSettings::default()
    };
    let stop = Arc::new(AtomicBool::new(false));
    let core = NodeCore::new(
        TrackerConfig::default().validate().unwrap(),
        NodeSettings::default(),
    );
    let (s2, st2) = (settings.clone(), stop.clone());
    let node = std::thread::spawn(move || run(core, &s2, st2, |_| {}).unwrap());
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("interop/cyclone_peer.py");
    let out = Command::new(&py)
        .arg(&script)
        .arg(domain.to_string())
        .arg(&dir)
        .arg(RATE_HZ.to_string())
        .output()
        .unwrap();
    stop.store(true, Ordering::Relaxed);
    let _ = node.join();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "peer failed ({}):\n{stdout}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    let scored = score(&stdout, &truth);
    let reinit_ok = scored
        .reinit
        .as_ref()
        .is_some_and(|r| r["success"].as_bool() == Some(true));
    let (n, good) = (scored.n, scored.good);
    println!(
        "interop (Cyclone DDS): {n} detections matched to frames, {good} within {HIT_PX} px \
         (20 px full-size); centre error mean {:.1} px, max {:.1} px",
        scored.mean_err, scored.max_err
    );
    assert!(reinit_ok, "reinit over Cyclone DDS failed:\n{stdout}");
    assert!(n >= FRAMES / 2, "only {n} detections for {FRAMES} frames");
    assert!(
        good * 10 >= n * 9,
        "{good}/{n} within the precision threshold"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// What a peer's output says: the reinit reply and the detections scored against truth.
pub(crate) struct Scored {
    /// The peer's `{"reinit": ...}` object.
    pub reinit: Option<serde_json::Value>,
    /// Detections matched to a frame with ground truth.
    pub n: usize,
    /// Of those, within [`HIT_PX`] of the truth centre.
    pub good: usize,
    /// Largest centre error, pixels.
    pub max_err: f32,
    /// Mean centre error, pixels.
    pub mean_err: f32,
}

/// Scores the peer's JSON lines (`{"reinit": ..}`, `{"frame": i, "box": [x, y, w, h]}`;
/// other lines ignored) against the ground truth.
pub(crate) fn score(stdout: &str, truth: &[Option<BBox>]) -> Scored {
    let mut s = Scored {
        reinit: None,
        n: 0,
        good: 0,
        max_err: 0.0,
        mean_err: 0.0,
    };
    let mut sum = 0.0;
    for line in stdout.lines() {
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        if let Some(r) = v.get("reinit") {
            println!("reinit: {r}");
            s.reinit = Some(r.clone());
        } else if let Some(i) = v["frame"].as_i64() {
            let Some(Some(t)) = usize::try_from(i).ok().and_then(|i| truth.get(i)) else {
                continue;
            };
            let b: Vec<f32> = v["box"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap() as f32)
                .collect();
            let err = BBox::new(b[0], b[1], b[2], b[3])
                .center()
                .distance(&t.center());
            s.n += 1;
            sum += err;
            s.max_err = s.max_err.max(err);
            if err <= HIT_PX {
                s.good += 1;
            }
        }
    }
    if s.n > 0 {
        s.mean_err = sum / s.n as f32;
    }
    s
}
