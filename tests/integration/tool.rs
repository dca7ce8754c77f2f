//! `bevt eval` (the same function the command line calls) on a small dataset written by the
//! test: results, summary, failure isolation, partial results, progress, plots, exit codes.

use bevt_core::eval::synth::SynthParams;
use bevt_core::TrackerConfig;
use bevt_node::tool::dataset::{open_dataset, parse_annotation};
use bevt_node::tool::eval::{
    eval, parse_compare, plot_series, EvalOptions, SequenceProgress, EXIT_SEQUENCE_FAILED,
};
use bevt_node::tool::plots::plot_curves;
use bevt_tests::temp_dir;
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

fn options(root: &Path, out: &Path, sequences: &[&str]) -> EvalOptions {
    EvalOptions {
        tracker: TrackerConfig::default().validate().unwrap(),
        dataset: root.to_path_buf(),
        out: out.to_path_buf(),
        sequences: sequences.iter().map(|s| s.to_string()).collect(),
        plots: false,
        compare: Vec::new(),
        name: "BEVT-rs".into(),
        progress: false,
    }
}

#[test]
fn failures_are_isolated_reported_and_partial_results_kept() {
    let root = temp_dir("ds");
    write_dataset(&root);
    assert_eq!(open_dataset(&root).unwrap().layout, "manifest");

    // `bevt eval --sequences good`: exit code 0, one progress bar of its 8 frames.
    let first = temp_dir("out_good");
    let r = eval(&options(&root, &first, &["good"])).unwrap();
    assert_eq!(r.exit_code(), 0);
    assert!(r.plots.is_empty());
    let bar = |name: &str, position: u64, length: u64| SequenceProgress {
        name: name.into(),
        position,
        length,
    };
    assert_eq!(r.progress, [bar("good", 8, 8)]);

    // Everything, compared with the first run's folder under another name, with plots.
    let out = temp_dir("out");
    let mut o = options(&root, &out, &[]);
    o.plots = true;
    o.compare = vec![parse_compare(&format!("self={}", first.display())).unwrap()];
    let r = eval(&o).unwrap();
    assert_eq!(r.exit_code(), EXIT_SEQUENCE_FAILED);
    // Each bar is as long as its sequence; the corrupt one stopped at its 5th frame and the
    // unreadable one never started.
    assert_eq!(
        r.progress,
        [
            bar("good", 8, 8),
            bar("corrupt", 4, 8),
            bar("badanno", 0, 0)
        ]
    );
    let s = &r.summary;

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
    let first_box = (a[0].unwrap(), g[0].unwrap());
    assert!(
        (first_box.0.x - first_box.1.x).abs() < 0.01
            && (first_box.0.y - first_box.1.y).abs() < 0.01
    );
    let partial = std::fs::read_to_string(out.join("corrupt.txt")).unwrap();
    assert_eq!(partial.lines().count(), 4);

    // The peer (our own files) scores the same; the attribute table lists SV only.
    assert!((s.compare[0].overall.auc - s.overall.auc).abs() < 1e-3);
    assert_eq!(s.attributes.len(), 1);
    assert_eq!(s.attributes[0].attribute, "SV");

    // Both plots, each with a legend row per tracker in the image.
    assert_eq!(
        r.plots,
        [out.join("precision.png"), out.join("success.png")]
    );
    for p in &r.plots {
        let img = image::open(p).unwrap();
        assert!(img.width() > img.height(), "{}", p.display());
    }
    let legend = plot_curves(
        &out.join("check.png"),
        "t",
        "x",
        "y",
        1.0,
        &plot_series("BEVT-rs", s, true),
    )
    .unwrap();
    let names: Vec<&str> = legend.entries.iter().map(|e| e.label.as_str()).collect();
    assert_eq!(names.len(), 2, "{names:?}");
    assert!(
        names.iter().any(|n| n.starts_with("BEVT-rs [")),
        "{names:?}"
    );
    assert!(names.iter().any(|n| n.starts_with("self [")), "{names:?}");

    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(json["overall"]["failed"], 2);

    // Usage errors are errors (exit code 1 in `bevt`), not failed sequences.
    assert!(parse_compare("no-equals-sign").is_err());
    assert!(parse_compare(&format!("x={}", root.join("missing").display())).is_err());
    assert!(eval(&options(&root, &out, &["nosuchsequence"])).is_err());
    let _ = std::fs::remove_dir_all(&root);
    let _ = std::fs::remove_dir_all(&out);
    let _ = std::fs::remove_dir_all(&first);
}
