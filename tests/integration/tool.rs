//! The evaluation pipeline on a small dataset written by the test: results, summary,
//! failure isolation and partial results.

use bevt_core::eval::synth::SynthParams;
use bevt_core::{BevtTracker, TrackerConfig};
use bevt_node::tool::dataset::{open_dataset, parse_annotation};
use bevt_node::tool::report::{build_summary, summarize_run, write_result_file, write_summary};
use bevt_node::tool::runner::run_sequence;
use bevt_tests::temp_dir;
use std::collections::BTreeMap;
use std::path::Path;

/// Writes a manifest dataset with three sequences: `good`, `corrupt` (frame 4 is not an
/// image) and `badanno` (line 3 of its annotation is malformed).
fn write_dataset(root: &Path) {
    let seq = SynthParams {
        width: 240,
        height: 180,
        frames: 8,
        target: (40.0, 32.0),
        ..SynthParams::default()
    };
    let mut manifest = Vec::new();
    for name in ["good", "corrupt", "badanno"] {
        let dir = root.join("data_seq").join(name);
        std::fs::create_dir_all(&dir).unwrap();
        let mut anno = String::new();
        for i in 0..seq.frames {
            let f = seq.frame(i);
            let path = dir.join(format!("{:06}.png", i + 1));
            if name == "corrupt" && i == 4 {
                std::fs::write(&path, b"not a png").unwrap();
            } else {
                image::RgbImage::from_raw(seq.width as u32, seq.height as u32, f.rgb)
                    .unwrap()
                    .save(&path)
                    .unwrap();
            }
            let t = f.truth;
            if name == "badanno" && i == 2 {
                anno.push_str("12,oops,3\n");
            } else {
                anno.push_str(&format!("{},{},{},{}\n", t.x + 1.0, t.y + 1.0, t.w, t.h));
            }
        }
        std::fs::create_dir_all(root.join("anno")).unwrap();
        std::fs::write(root.join("anno").join(format!("{name}.txt")), anno).unwrap();
        manifest.push(serde_json::json!({
            "name": name, "img_dir": format!("data_seq/{name}"), "anno": format!("anno/{name}.txt"),
            "start_frame": 1, "end_frame": seq.frames, "nz": 6, "ext": "png",
            "attributes": {"SV": true, "LR": false}
        }));
    }
    let m = serde_json::json!({"attribute_order": ["SV", "LR"], "sequences": manifest});
    std::fs::write(
        root.join("sequences.json"),
        serde_json::to_string(&m).unwrap(),
    )
    .unwrap();
}

#[test]
fn failures_are_isolated_reported_and_partial_results_kept() {
    let root = temp_dir("ds");
    write_dataset(&root);
    let out = temp_dir("out");
    let ds = open_dataset(&root).unwrap();
    assert_eq!(ds.layout, "manifest");
    let spec = TrackerConfig::default().validate().unwrap();
    let mut summaries = Vec::new();
    let mut truths = BTreeMap::new();
    for e in &ds.sequences {
        let mut t = BevtTracker::new(spec.clone());
        let run = run_sequence(e, &mut t, |_, _| {});
        write_result_file(&out, &run).unwrap();
        truths.insert(run.name.clone(), run.truth.clone());
        summaries.push(summarize_run(&run));
    }
    // Compare against our own result folder under another name: identical scores.
    let peers = vec![("self".to_string(), out.clone())];
    let s = build_summary(
        "BEVT-rs",
        &ds,
        &summaries,
        &truths,
        &peers,
        serde_json::Value::Null,
    );
    write_summary(&out, &s).unwrap();

    let by = |n: &str| s.sequences.iter().find(|x| x.name == n).unwrap();
    assert_eq!(by("good").status, "ok");
    assert!(by("good").precision_20 > 0.99);
    assert_eq!(by("corrupt").status, "failed");
    assert!(
        by("corrupt").error.as_deref().unwrap().contains("frame 5"),
        "{:?}",
        by("corrupt").error
    );
    assert_eq!(by("corrupt").frames_tracked, 4);
    assert_eq!(by("badanno").status, "failed");
    assert!(by("badanno")
        .error
        .as_deref()
        .unwrap()
        .contains("badanno.txt:3"));
    assert_eq!(s.overall.sequences, 1);
    assert_eq!(s.overall.failed, 2);

    // Result files: complete for the good sequence, partial for the corrupt one, in the
    // 1-based annotation convention (the first row is the initial box as annotated).
    let good = std::fs::read_to_string(out.join("good.txt")).unwrap();
    assert_eq!(good.lines().count(), 8);
    let anno = std::fs::read_to_string(root.join("anno/good.txt")).unwrap();
    let a = parse_annotation(&anno, Path::new("a")).unwrap();
    let g = parse_annotation(&good, Path::new("g")).unwrap();
    let first = (a[0].unwrap(), g[0].unwrap());
    assert!((first.0.x - first.1.x).abs() < 0.01 && (first.0.y - first.1.y).abs() < 0.01);
    let partial = std::fs::read_to_string(out.join("corrupt.txt")).unwrap();
    assert_eq!(partial.lines().count(), 4);

    // The peer (our own files) scores the same; the attribute table lists SV only.
    assert!((s.compare[0].overall.auc - s.overall.auc).abs() < 1e-3);
    assert_eq!(s.attributes.len(), 1);
    assert_eq!(s.attributes[0].attribute, "SV");

    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(json["overall"]["failed"], 2);
    let _ = std::fs::remove_dir_all(&root);
    let _ = std::fs::remove_dir_all(&out);
}
