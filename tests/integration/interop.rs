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
const FRAMES: usize = 60;
/// Camera rate of the peer.
const RATE_HZ: f64 = 10.0;

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
fn write_frames(dir: &Path) -> Vec<Option<BBox>> {
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
            println!("SKIPPED an_independent_cyclone_dds_peer_drives_the_node: no Python environment ({e})");
            return;
        }
    };
    let dir = temp_dir("interop");
    let truth = write_frames(&dir);
    let domain = 200 + (std::process::id() % 30) as u16;
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
    let mut reinit_ok = false;
    let (mut n, mut good) = (0usize, 0usize);
    for line in stdout.lines() {
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        if let Some(r) = v.get("reinit") {
            reinit_ok = r["success"].as_bool() == Some(true);
            println!("reinit: {r}");
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
            let bb = BBox::new(b[0], b[1], b[2], b[3]);
            n += 1;
            // 20 px at full resolution = 10 px here.
            if bb.center().distance(&t.center()) <= 10.0 {
                good += 1;
            }
        }
    }
    println!("interop: {n} detections matched to frames, {good} within 10 px (20 px full-size)");
    assert!(reinit_ok, "reinit over Cyclone DDS failed:\n{stdout}");
    assert!(n >= FRAMES / 2, "only {n} detections for {FRAMES} frames");
    assert!(
        good * 10 >= n * 9,
        "{good}/{n} within the precision threshold"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
