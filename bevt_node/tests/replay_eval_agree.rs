//! `bevt replay` reproduces `bevt eval`: a dev sequence's original JPEG bytes recorded as
//! `sensor_msgs/CompressedImage` (`format: jpeg`) and replayed through the node logic give
//! eval's boxes on every frame, to 0.01 px, once both are read in one convention: replay's
//! `--init` and CSV are 0-based image pixels (the node's, as its `reinit` service),
//! annotation files and eval's result files 1-based (the UAV123/OTB toolkit's).
//!
//! Needs `../shared` (the dev set); skipped with the reason when absent, except under
//! `CI=true`, where CI provides it.

use crate::common;
use bevt_msgs::builtin_interfaces::Time;
use bevt_msgs::sensor_msgs::CompressedImage;
use bevt_msgs::std_msgs::Header;
use std::path::{Path, PathBuf};
use std::process::Command;

const SEQUENCE: &str = "wakeboard7";
const TOPIC: &str = "/camera/image_raw/compressed";

fn dev_set() -> Option<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/datasets/uav123_10fps_dev");
    root.join("sequences.json").is_file().then_some(root)
}

fn rows(text: &str, skip: usize) -> Vec<[f64; 4]> {
    text.lines()
        .skip(skip)
        .map(|l| {
            let f: Vec<f64> = l.split(',').filter_map(|v| v.trim().parse().ok()).collect();
            [f[0], f[1], f[2], f[3]]
        })
        .collect()
}

#[test]
fn a_replayed_jpeg_recording_gives_the_boxes_of_bevt_eval() {
    let Some(root) = dev_set() else {
        let ci = std::env::var("CI").is_ok_and(|v| v == "true" || v == "1");
        assert!(!ci, "CI provides ../shared, but the dev set is absent");
        println!(
            "SKIPPED a_replayed_jpeg_recording_gives_the_boxes_of_bevt_eval: ../shared absent"
        );
        return;
    };
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(root.join("sequences.json")).unwrap())
            .unwrap();
    let seq = manifest["sequences"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["name"] == SEQUENCE)
        .expect("the sequence");
    let (start, end, nz) = (
        seq["start_frame"].as_u64().unwrap(),
        seq["end_frame"].as_u64().unwrap(),
        seq["nz"].as_u64().unwrap() as usize,
    );
    let dir = std::env::temp_dir().join(format!("bevt_agree_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // The recording: every frame's original JPEG bytes, 10 Hz.
    let bag = dir.join("flight.mcap");
    let mut rec = common::Recording::create(&bag, TOPIC, "sensor_msgs/msg/CompressedImage");
    for (i, n) in (start..=end).enumerate() {
        let file = root
            .join(seq["img_dir"].as_str().unwrap())
            .join(format!("{n:0nz$}.{}", seq["ext"].as_str().unwrap()));
        let t = 1_700_000_000_000_000_000i64 + i as i64 * 100_000_000;
        let msg = CompressedImage {
            header: Header {
                stamp: Time::from_nanos(t),
                frame_id: "cam".into(),
            },
            format: "jpeg".into(),
            data: std::fs::read(file).unwrap(),
        };
        rec.write(t, &msg);
    }
    rec.finish();
    // eval: its result file, 1-based like the annotation.
    let out = Command::new(env!("CARGO_BIN_EXE_bevt"))
        .args([
            "eval",
            "--dataset",
            root.to_str().unwrap(),
            "--sequences",
            SEQUENCE,
        ])
        .args([
            "--threads",
            "1",
            "--out",
            dir.join("eval").to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let eval = rows(
        &std::fs::read_to_string(dir.join("eval").join(format!("{SEQUENCE}.txt"))).unwrap(),
        0,
    );
    // replay: initialised on the first annotated box, converted to 0-based pixels.
    let anno = std::fs::read_to_string(root.join(seq["anno"].as_str().unwrap())).unwrap();
    let first = rows(&anno, 0)[0];
    let init = format!(
        "{},{},{},{}",
        first[0] - 1.0,
        first[1] - 1.0,
        first[2],
        first[3]
    );
    let csv = dir.join("replay.csv");
    let out = Command::new(env!("CARGO_BIN_EXE_bevt"))
        .args(["replay", "--bag", bag.to_str().unwrap(), "--topic", TOPIC])
        .args(["--init", &init, "--threads", "1"])
        .args(["--out", dir.join("replay.mcap").to_str().unwrap()])
        .args(["--csv", csv.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let replay: Vec<[f64; 4]> = std::fs::read_to_string(&csv)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<f64> = l
                .split(',')
                .skip(1)
                .take(4)
                .map(|v| v.parse().unwrap())
                .collect();
            [f[0] + 1.0, f[1] + 1.0, f[2], f[3]]
        })
        .collect();
    assert_eq!(replay.len(), eval.len());
    let mut worst = 0.0f64;
    for (i, (r, e)) in replay.iter().zip(&eval).enumerate() {
        for k in 0..4 {
            let d = (r[k] - e[k]).abs();
            worst = worst.max(d);
            // eval's file keeps 2 decimals, the CSV 3.
            assert!(d <= 0.01, "frame {}: replay {r:?} vs eval {e:?}", i + 1);
        }
    }
    println!(
        "{SEQUENCE}: {} frames, replay = eval to {worst:.4} px",
        replay.len()
    );
    let _ = std::fs::remove_dir_all(&dir);
}
