//! `bevt eval` (the same function the command line calls) on a small dataset written by the
//! test: results, summary, failure isolation, partial results, progress, plots, exit codes.

use bevt_core::eval::synth::SynthParams;
use bevt_core::TrackerConfig;
use bevt_node::tool::dataset::{open_dataset, parse_annotation};
use bevt_node::tool::eval::{
    eval, parse_compare, plot_series, EvalOptions, SequenceProgress, EXIT_SEQUENCE_FAILED,
};
use bevt_node::tool::plots::plot_curves;
use bevt_node::tool::runner::Decode;
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
        perturb: None,
        decode: Decode::Ahead,
    }
}

/// The models are loaded and checked before any sequence runs (not inside the first
/// sequence's timed `init`): a bad model path stops the run at once with its key, no
/// sequence run and no results written.
#[test]
fn a_bad_model_stops_the_run_before_any_sequence() {
    let root = temp_dir("ds_badmodel");
    write_dataset(&root);
    let out = temp_dir("out_badmodel");
    let _ = std::fs::remove_dir_all(&out);
    let mut o = options(&root, &out, &["good"]);
    let mut cfg = TrackerConfig::default();
    cfg.redetection.verifier_backbone = root.join("no_such_backbone.onnx").display().to_string();
    o.tracker = cfg.validate().unwrap();
    let e = format!("{:#}", eval(&o).unwrap_err());
    assert!(
        e.contains("redetection.verifier_backbone") && e.contains("no_such_backbone.onnx"),
        "{e}"
    );
    assert!(!out.join("good.txt").exists() && !out.join("summary.json").exists());
}

/// `--decode inline` decodes on the tracking thread between the timed calls: the same
/// boxes as decoding ahead, with and without a perturbation, the failures reported alike,
/// and `summary.json` says where the frames were decoded (the fps depend on it).
#[test]
fn decoding_inline_gives_the_same_boxes_and_says_so() {
    use bevt_core::eval::perturb::Perturbation;
    let root = temp_dir("ds_decode");
    write_dataset(&root);
    for perturb in [None, Some("shake=6,seed=2")] {
        let mut results = Vec::new();
        for decode in [Decode::Ahead, Decode::Inline] {
            let out = temp_dir(&format!(
                "out_decode_{}_{}",
                decode.name(),
                perturb.is_some()
            ));
            let mut o = options(&root, &out, &[]);
            o.decode = decode;
            o.perturb = perturb.map(|p| Perturbation::parse(p).unwrap());
            let r = eval(&o).unwrap();
            assert_eq!(r.exit_code(), EXIT_SEQUENCE_FAILED);
            assert_eq!(r.summary.decode, decode.name());
            let json = std::fs::read_to_string(out.join("summary.json")).unwrap();
            assert!(
                json.contains(&format!("\"decode\": \"{}\"", decode.name())),
                "{json}"
            );
            let errors: Vec<_> = r
                .summary
                .sequences
                .iter()
                .map(|s| s.error.clone())
                .collect();
            let good = std::fs::read_to_string(out.join("good.txt")).unwrap();
            results.push((good, errors));
        }
        assert_eq!(results[0], results[1], "perturb {perturb:?}");
        // The corrupt frame is reported by name either way.
        assert!(
            results[1]
                .1
                .iter()
                .flatten()
                .any(|e| e.contains("000005.png")),
            "{:?}",
            results[1].1
        );
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

/// `bevt eval --perturb`: frames and truth move together, so a tracker that follows the
/// frames scores as well as on the original, the result's initial box is the transformed
/// one, the summary records the perturbation, and two runs are identical.
#[test]
fn perturbed_evaluation_moves_the_truth_with_the_frames() {
    use bevt_core::eval::perturb::Perturbation;
    let root = temp_dir("ds_perturb");
    write_dataset(&root);
    let anno = std::fs::read_to_string(root.join("anno/good.txt")).unwrap();
    let a0 = parse_annotation(&anno, Path::new("a")).unwrap()[0].unwrap();
    // tiny=0.5: the 240x180 frames become 120x90 and every box is halved. Were the truth
    // left as it was, the centre error would be ~75 px on every frame (P@20 0).
    let out = temp_dir("out_tiny");
    let mut o = options(&root, &out, &["good"]);
    o.perturb = Some(Perturbation::parse("tiny=0.5").unwrap());
    let r = eval(&o).unwrap();
    assert_eq!(r.exit_code(), 0);
    assert_eq!(r.summary.perturb.as_deref(), Some("tiny=0.5"));
    assert!(
        r.summary.sequences[0].precision_20 > 0.99,
        "{:?}",
        r.summary.sequences[0]
    );
    let res = std::fs::read_to_string(out.join("good.txt")).unwrap();
    let g0 = parse_annotation(&res, Path::new("g")).unwrap()[0].unwrap();
    assert_eq!(
        (g0.x, g0.y, g0.w, g0.h),
        (a0.x * 0.5, a0.y * 0.5, a0.w * 0.5, a0.h * 0.5)
    );
    let json = std::fs::read_to_string(out.join("summary.json")).unwrap();
    assert!(json.contains("\"perturb\": \"tiny=0.5\""), "{json}");

    // A strong shake: still tracked (the truth shakes with the frame), and repeatable.
    let spec = Perturbation::parse("shake=10,seed=4").unwrap();
    let mut outs = Vec::new();
    for k in 0..2 {
        let out = temp_dir(&format!("out_shake{k}"));
        let mut o = options(&root, &out, &["good"]);
        o.perturb = Some(spec);
        let r = eval(&o).unwrap();
        assert!(
            r.summary.sequences[0].precision_20 > 0.99,
            "{:?}",
            r.summary.sequences[0]
        );
        outs.push(std::fs::read_to_string(out.join("good.txt")).unwrap());
    }
    assert_eq!(outs[0], outs[1]);
    // tiny=0.1 leaves a 4x3 px target, which the tracker refuses: the sequence fails with
    // the reason, nothing panics.
    let out = temp_dir("out_tiny_bad");
    let mut o = options(&root, &out, &["good"]);
    o.perturb = Some(Perturbation::parse("tiny=0.1").unwrap());
    let r = eval(&o).unwrap();
    assert_eq!(r.exit_code(), EXIT_SEQUENCE_FAILED);
    let e = r.summary.sequences[0].error.as_deref().unwrap();
    assert!(
        e.contains("init on frame 1") && e.contains("smaller than the minimum"),
        "{e}"
    );
}

/// Writes a `summary.json` as `bevt eval` does, with the given (name, auc, p20) rows
/// (`None` = a failed sequence).
fn write_summary_json(dir: &Path, rows: &[(&str, Option<(f64, f64)>)], perturb: Option<&str>) {
    std::fs::create_dir_all(dir).unwrap();
    let seqs: Vec<serde_json::Value> = rows
        .iter()
        .map(|(n, s)| match s {
            Some((auc, p)) => serde_json::json!({"name": n, "status": "ok", "auc": auc,
                "precision_20": p, "success_50": auc / 2.0, "fps": 10.0}),
            None => serde_json::json!({"name": n, "status": "failed", "error": "frame 5: broken",
                "auc": null, "precision_20": null, "success_50": null}),
        })
        .collect();
    let mut s = serde_json::json!({"tracker": "x", "sequences": seqs});
    if let Some(p) = perturb {
        s["perturb"] = serde_json::json!(p);
    }
    std::fs::write(dir.join("summary.json"), s.to_string()).unwrap();
}

#[test]
fn select_chooses_on_the_other_sequences_and_refuses_bad_folders() {
    use bevt_node::tool::select::{render, select, Criterion, SelectOptions};
    let root = temp_dir("select");
    // steady: 0.5 everywhere; spiky: best on s0 only; mild: a little better on s1, s2.
    let steady = root.join("steady");
    let spiky = root.join("spiky");
    let mild = root.join("mild");
    write_summary_json(
        &steady,
        &[
            ("s0", Some((0.5, 0.9))),
            ("s1", Some((0.5, 0.9))),
            ("s2", Some((0.5, 0.9))),
        ],
        None,
    );
    write_summary_json(
        &spiky,
        &[
            ("s0", Some((0.9, 1.0))),
            ("s1", Some((0.3, 0.6))),
            ("s2", Some((0.3, 0.6))),
        ],
        None,
    );
    write_summary_json(
        &mild,
        &[
            ("s0", Some((0.2, 0.4))),
            ("s1", Some((0.6, 1.0))),
            ("s2", Some((0.6, 1.0))),
        ],
        None,
    );
    let opts = |v: &[(&str, &Path)]| SelectOptions {
        variants: v
            .iter()
            .map(|(n, d)| (n.to_string(), d.to_path_buf()))
            .collect(),
        criterion: Criterion::Auc,
        sequences: Vec::new(),
    };
    let r = select(&opts(&[
        ("steady", &steady),
        ("spiky", &spiky),
        ("mild", &mild),
    ]))
    .unwrap();
    // Hold out s0: mild (0.6 on s1, s2) is chosen and scores 0.2; s1 and s2: spiky (0.6),
    // scoring 0.3. LOSO mean 0.8 / 3 while steady and spiky tie at 0.5 on the full set.
    let chosen: Vec<usize> = r.loso.folds.iter().map(|f| f.chosen).collect();
    assert_eq!(chosen, [2, 1, 1]);
    assert!((r.loso.loso_mean - 0.8 / 3.0).abs() < 1e-12);
    assert!((r.loso_mean_of(Criterion::P20) - (0.4 + 0.6 + 0.6) / 3.0).abs() < 1e-12);
    let text = render(&r);
    assert!(
        text.contains("| s0 | mild | 0.600 | 0.200 | 0.400 | 0.100 | 0.900 |"),
        "{text}"
    );
    assert!(
        text.contains("| **LOSO mean** | | | **0.267** | **0.533**"),
        "{text}"
    );
    assert!(
        text.contains("| steady (full-set choice) | 0.500 | 0.900 | 0.250 | 0 of 3 |"),
        "{text}"
    );
    assert!(text.contains("optimism +0.233"), "{text}");
    // By P@20 the folds choose differently: holding out s1, steady (0.9 on s0, s2) beats
    // spiky (0.8) and mild (0.7).
    let mut o = opts(&[("steady", &steady), ("spiky", &spiky), ("mild", &mild)]);
    o.criterion = Criterion::P20;
    let r = select(&o).unwrap();
    assert_eq!(r.loso.folds[0].chosen, 2);
    assert_eq!(r.loso.folds[1].chosen, 0);

    // Bad folders: each a clear error naming the variant.
    let err = |v: &[(&str, &Path)], seqs: &[&str]| {
        let mut o = opts(v);
        o.sequences = seqs.iter().map(|s| s.to_string()).collect();
        format!("{:#}", select(&o).unwrap_err())
    };
    let empty = root.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let e = err(&[("steady", &steady), ("none", &empty)], &[]);
    assert!(
        e.contains("none: cannot read") && e.contains("summary.json"),
        "{e}"
    );
    let junk = root.join("junk");
    std::fs::create_dir_all(&junk).unwrap();
    std::fs::write(junk.join("summary.json"), "{\"sequences\": 3}").unwrap();
    let e = err(&[("junk", &junk)], &[]);
    assert!(
        e.contains("junk:") && e.contains("not a `bevt eval` summary"),
        "{e}"
    );
    let failed = root.join("failed");
    write_summary_json(
        &failed,
        &[
            ("s0", Some((0.5, 0.9))),
            ("s1", None),
            ("s2", Some((0.5, 0.9))),
        ],
        None,
    );
    let e = err(&[("steady", &steady), ("failed", &failed)], &[]);
    assert!(
        e.contains("failed: sequence s1 failed in that run (frame 5: broken)"),
        "{e}"
    );
    // ... which --sequences can leave out.
    let mut o = opts(&[("steady", &steady), ("failed", &failed)]);
    o.sequences = vec!["s0".into(), "s2".into()];
    assert_eq!(select(&o).unwrap().loso.folds.len(), 2);
    let more = root.join("more");
    write_summary_json(
        &more,
        &[
            ("s0", Some((0.5, 0.9))),
            ("s1", Some((0.5, 0.9))),
            ("s2", Some((0.5, 0.9))),
            ("s3", Some((0.5, 0.9))),
        ],
        None,
    );
    let e = err(&[("steady", &steady), ("more", &more)], &[]);
    assert!(e.contains("more has sequences steady has not (s3)"), "{e}");
    let e = err(&[("more", &more), ("steady", &steady)], &[]);
    assert!(e.contains("steady has no sequence \"s3\""), "{e}");
    let e = err(&[("steady", &steady)], &["s0"]);
    assert!(e.contains("at least 2 sequences"), "{e}");
    let e = err(&[("steady", &steady), ("steady", &spiky)], &[]);
    assert!(e.contains("variant \"steady\" is given twice"), "{e}");
    let shaken = root.join("shaken");
    write_summary_json(
        &shaken,
        &[
            ("s0", Some((0.5, 0.9))),
            ("s1", Some((0.5, 0.9))),
            ("s2", Some((0.5, 0.9))),
        ],
        Some("shake=8"),
    );
    let e = err(&[("steady", &steady), ("shaken", &shaken)], &[]);
    assert!(
        e.contains("shaken was run with perturbation shake=8 but steady with none"),
        "{e}"
    );
    assert!(Criterion::parse("iou").is_err());
}

/// `scripts/speed-rounds.sh` and `scripts/nanotrack_peer.py` (the speed measurement of issues
/// 19 and 20) refuse bad arguments with a clear message before they build, install, load
/// opencv or write anything.
#[test]
fn the_speed_scripts_refuse_bad_arguments_before_any_work() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    let tmp = temp_dir("speed_scripts");
    write_dataset(&tmp);
    let rounds_dirs = || {
        std::fs::read_dir(root.join("target"))
            .map(|d| {
                d.filter_map(Result::ok)
                    .filter(|e| e.file_name().to_string_lossy().starts_with("speed-rounds."))
                    .count()
            })
            .unwrap_or(0)
    };
    let before = rounds_dirs();
    let data = tmp.to_str().unwrap();
    let missing = tmp.join("no_such_dataset");
    for (args, says) in [
        (vec!["0"], "ROUNDS must be a positive integer, got '0'"),
        (
            vec!["five"],
            "ROUNDS must be a positive integer, got 'five'",
        ),
        (vec!["-3"], "ROUNDS must be a positive integer"),
        (vec!["101"], "at most 100 rounds"),
        (
            vec!["2", missing.to_str().unwrap()],
            "sequences.json missing",
        ),
        (
            vec!["2", "DECODE=thread"],
            "DECODE must be 'inline' or 'ahead'",
        ),
    ] {
        // `NAME=VALUE` arguments go to the environment.
        let (env, args): (Vec<&str>, Vec<&str>) = args.into_iter().partition(|a| a.contains('='));
        let out = std::process::Command::new("bash")
            .arg(root.join("scripts/speed-rounds.sh"))
            .args(&args)
            .envs(env.iter().filter_map(|e| e.split_once('=')))
            // Were an argument let through, the run would stop at once on this binary
            // (another message) instead of building and measuring for an hour.
            .env("BEVT", tmp.join("no_such_bevt"))
            .output()
            .expect("bash runs");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
    }
    // `WITHOUT` names sequences of the dataset and leaves one at least; unset, it leaves out
    // wakeboard4 only where there is one (this dataset has none: the run goes on to `BEVT`).
    for (without, says) in [
        (
            Some("good,nope"),
            "WITHOUT names sequences not in the dataset: ['nope']",
        ),
        (Some("good,corrupt,badanno"), "WITHOUT leaves no sequence"),
        (None, "no_such_bevt is not an executable"),
    ] {
        let mut cmd = std::process::Command::new("bash");
        cmd.arg(root.join("scripts/speed-rounds.sh"))
            .args(["2", data])
            .env("BEVT", tmp.join("no_such_bevt"));
        match without {
            Some(w) => cmd.env("WITHOUT", w),
            None => cmd.env_remove("WITHOUT"),
        };
        let out = cmd.output().expect("bash runs");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{without:?}: {err}");
        assert!(err.contains(says), "{without:?}: {err}");
    }
    assert_eq!(
        rounds_dirs(),
        before,
        "a refused run left a results directory"
    );
    // The peer: checked against the manifest before opencv is imported (the test's python3
    // need not have it) and before its output folder exists.
    let out_dir = tmp.join("peer_out");
    for (args, says) in [
        (
            vec!["--sequences", "good,nope"],
            "not in the manifest: ['nope']",
        ),
        (vec!["--sequences", ","], "(empty list)"),
        (vec!["--sequences"], "needs a comma-separated list"),
    ] {
        let mut cmd = std::process::Command::new("python3");
        cmd.arg(root.join("scripts/nanotrack_peer.py")).args(&args);
        if args.len() > 1 {
            cmd.args([data, out_dir.to_str().unwrap()]);
        }
        let out = cmd.output().expect("python3 runs");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
        assert!(!out_dir.exists(), "{args:?} created the output folder");
    }
    let _ = std::fs::remove_dir_all(&tmp);
}

/// `scripts/speed-rounds.sh --summarise` reads a run's folder back: the means and per-round
/// ratios, each sequence's pooled fps beside TrackerNano's, and the ratio without wakeboard4
/// (issue 19's targets are with and without it) from each round's own sums, here on three
/// rounds whose figures are worked out by hand; a `WITHOUT` naming a sequence no round ran, or
/// leaving none, is refused, as is a folder that holds no run.
#[test]
fn the_speed_summary_reads_the_rounds_with_and_without_wakeboard4() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    let dir = temp_dir("speed_summary");
    // Per round: (default seconds on `a`, TrackerNano seconds on `a`); wakeboard4 takes the
    // default 2.0 s and TrackerNano 1.0 s every round; 100 frames each.
    let rounds = [(1.0, 1.25), (0.625, 1.0), (0.5, 1.0)];
    let mut fps = String::new();
    for (r, (da, na)) in rounds.iter().enumerate() {
        let lines = format!(
            "default 100 {da} a\nrules_off 100 {da} a\nnano 100 {na} a\n\
             nano 100 1.0 wakeboard4\ndefault 100 2.0 wakeboard4\nrules_off 100 2.0 wakeboard4\n"
        );
        std::fs::write(dir.join(format!("round_{}.txt", r + 1)), lines).unwrap();
        let (d, n) = (200.0 / (da + 2.0), 200.0 / (na + 1.0));
        fps.push_str(&format!("{d:.1} {d:.1} {n:.1}\n"));
    }
    std::fs::write(dir.join("fps.txt"), fps).unwrap();
    let summarise = |without: Option<&str>, folder: &Path| {
        let mut cmd = std::process::Command::new("bash");
        cmd.arg(root.join("scripts/speed-rounds.sh"))
            .arg("--summarise")
            .arg(folder);
        match without {
            Some(w) => cmd.env("WITHOUT", w),
            None => cmd.env_remove("WITHOUT"),
        };
        let out = cmd.output().expect("bash runs");
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (code, out, err) = summarise(None, &dir);
    assert_eq!(code, Some(0), "{err}");
    // With wakeboard4: 66.7, 76.2, 80.0 against 88.9, 100.0, 100.0.
    assert!(
        out.contains("default against TrackerNano: 0.77x of the means"),
        "{out}"
    );
    // a: 300 frames in 2.125 s against 3.25 s; wakeboard4: 6.0 s against 3.0 s.
    assert!(
        out.contains("a                   141.2          92.3   1.53x"),
        "{out}"
    );
    assert!(
        out.contains("wakeboard4           50.0         100.0   0.50x"),
        "{out}"
    );
    // Without it, round by round: 100 / 80, 160 / 100, 200 / 100.
    assert!(
        out.contains(
            "default against TrackerNano without wakeboard4: 1.64x of the means \
             (153.3 against 93.3 fps); per round median 1.60x, 1.25-2.00x"
        ),
        "{out}"
    );
    let (code, out, _) = summarise(Some(""), &dir);
    assert_eq!(code, Some(0));
    assert!(
        !out.contains("without wakeboard4") && !out.contains("sequence "),
        "{out}"
    );
    for (without, says) in [
        ("nope", "WITHOUT names nope, which no round ran"),
        ("a,wakeboard4", "WITHOUT leaves no sequence"),
    ] {
        let (code, _, err) = summarise(Some(without), &dir);
        assert_eq!(code, Some(2), "{without}: {err}");
        assert!(err.contains(says), "{without}: {err}");
    }
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let (code, _, err) = summarise(None, &empty);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("--summarise needs the folder of an earlier run"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The selection protocol's scripts (docs/results.md#selection-protocol): `protocol-runs.sh`
/// refuses a bad label or job count before it builds or writes anything; `rule3.py` reads a
/// challenger against the rounding band (the lowest of the incumbent and its rounding variants
/// per condition, and of their means of the ten): inside it passes, a mean below it or one
/// condition more than 0.02 under it is refused, and missing or unfinished runs are an error;
/// and the rounding variants' patches still apply to this tree (a stale patch would make the
/// band a measurement of nothing).
#[test]
fn the_protocol_scripts_read_the_rounding_band_and_refuse_bad_input() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    let tmp = temp_dir("protocol_scripts");
    for (label, jobs, says) in [
        ("", "2", "LABEL must be"),
        ("a/b", "2", "LABEL must be"),
        ("../up", "2", "LABEL must be"),
        ("..", "2", "LABEL must be"),
        (".", "2", "LABEL must be"),
        ("-x", "2", "LABEL must be"),
        ("ok_label", "0", "JOBS must be a positive integer"),
    ] {
        let out = std::process::Command::new("bash")
            .arg(root.join("scripts/protocol-runs.sh"))
            .arg(label)
            .env("JOBS", jobs)
            // Were an argument let through, the run would stop at once on this binary
            // (another message) instead of building and running for an hour.
            .env("BEVT", tmp.join("no_such_bevt"))
            .output()
            .expect("bash runs");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{label:?}: {err}");
        assert!(err.contains(says), "{label:?}: {err}");
    }

    // A label's runs are of one binary, one argument list and one dataset: a run that leaves
    // no complete summary fails, and a second call with another binary or other arguments is
    // refused instead of mixing its conditions with the first's.
    let data = tmp.join("data");
    std::fs::create_dir_all(&data).unwrap();
    std::fs::write(
        data.join("sequences.json"),
        r#"{"sequences": [{"name": "s1"}]}"#,
    )
    .unwrap();
    let fake = |name: &str, body: &str| {
        let p = tmp.join(name);
        std::fs::write(&p, format!("#!/bin/sh\n# {body}\nexit 0\n")).unwrap();
        let mut perm = std::fs::metadata(&p).unwrap().permissions();
        std::os::unix::fs::PermissionsExt::set_mode(&mut perm, 0o755);
        std::fs::set_permissions(&p, perm).unwrap();
        p
    };
    let (bin_a, bin_b) = (fake("bevt_a", "a"), fake("bevt_b", "b"));
    let label = format!("test_signature_{}", std::process::id());
    let held = root.join("target/protocol").join(&label);
    let call = |bin: &Path, extra: &[&str]| {
        std::process::Command::new("bash")
            .arg(root.join("scripts/protocol-runs.sh"))
            .arg(&label)
            .args(extra)
            .env("BEVT", bin)
            .env("DATASET", &data)
            .output()
            .expect("bash runs")
    };
    let out = call(&bin_a, &[]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("FAILED: no complete summary"), "{err}");
    for (bin, extra) in [
        (&bin_b, &[][..]),
        (&bin_a, &["--set", "admm.iterations=2"][..]),
    ] {
        let out = call(bin, extra);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{extra:?}: {err}");
        assert!(
            err.contains("holds runs of another binary, arguments or dataset"),
            "{extra:?}: {err}"
        );
    }
    let _ = std::fs::remove_dir_all(&held);

    // Runs as protocol-runs.sh leaves them: LABEL/CONDITION/summary.json.
    let conditions = [
        "none",
        "shake16s1",
        "shake16s2",
        "shake8s2",
        "tiny_shake",
        "tiny",
        "zoom",
        "aspect",
        "light",
        "lookalike",
        "blur",
    ];
    let write = |label: &str, auc: &dyn Fn(&str) -> f64| {
        for c in conditions {
            let dir = tmp.join("runs").join(label).join(c);
            std::fs::create_dir_all(&dir).unwrap();
            let a = auc(c);
            let s = serde_json::json!({
                "overall": {"auc": a, "precision_20": 0.97},
                "sequences": [{"name": "s1", "status": "ok", "auc": a}],
            });
            std::fs::write(dir.join("summary.json"), s.to_string()).unwrap();
        }
    };
    write("inc", &|_| 0.60);
    // The null variant: zoom 0.10 lower, blur 0.01 higher (mean of the ten 0.591).
    write("null", &|c| match c {
        "zoom" => 0.50,
        "blur" => 0.61,
        _ => 0.60,
    });
    // Inside the band: zoom at the band's floor minus 0.015, the mean above the floor's.
    write("inside", &|c| match c {
        "zoom" => 0.485,
        "light" => 0.64,
        _ => 0.60,
    });
    // One condition beyond it: aspect 0.03 under its floor (0.60).
    write("beyond", &|c| if c == "aspect" { 0.57 } else { 0.60 });
    // Every condition within 0.02 of its floor but the mean of the ten below the band's.
    write("mean_low", &|c| if c == "none" { 0.60 } else { 0.585 });
    // A run still going: its blur summary holds no sequence yet (a low mean of none).
    write("partial", &|_| 0.60);
    let blur = serde_json::json!({
        "overall": {"auc": 0.2, "precision_20": 0.9},
        "sequences": [],
    });
    std::fs::write(tmp.join("runs/partial/blur/summary.json"), blur.to_string()).unwrap();
    let rule3 = |challenger: &str| {
        std::process::Command::new("python3")
            .arg(root.join("scripts/rule3.py"))
            .args(["--root", tmp.join("runs").to_str().unwrap()])
            .args(["--incumbent", "inc", "--null", "null", challenger])
            .output()
            .expect("python3 runs")
    };
    // (challenger, exit code, what its output says): inside the band it passes, though the
    // plain rule of before refuses it (zoom −0.115 against the incumbent alone); one
    // condition beyond the band, or the mean of the ten below it, is refused; runs that do
    // not exist are an error on stderr.
    for (challenger, code, says) in [
        (
            "inside",
            Some(0),
            &[
                "| zoom | 0.600 | 0.500 | 0.500–0.600 | 0.485 |",
                "inside: rule 3 above the rounding floor passes",
                "refused: zoom -0.115",
            ][..],
        ),
        (
            "beyond",
            Some(1),
            &["REFUSED: aspect 0.570 < floor 0.600"][..],
        ),
        (
            "mean_low",
            Some(1),
            &["REFUSED: mean of ten 0.585 < 0.591"][..],
        ),
        (
            "never_run",
            Some(1),
            &["run scripts/protocol-runs.sh never_run first"][..],
        ),
        (
            "partial",
            Some(1),
            &["0 of 1 sequences, missing ['s1'] (still running or cut short)"][..],
        ),
    ] {
        let out = rule3(challenger);
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        assert_eq!(out.status.code(), code, "{challenger}: {text}");
        for s in says {
            assert!(text.contains(s), "{challenger}: no '{s}' in {text}");
        }
    }

    // The rounding variants apply to this tree (CI's clean clone is a git checkout).
    let patches: Vec<_> = std::fs::read_dir(root.join("scripts/rounding-floor"))
        .expect("scripts/rounding-floor")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "patch"))
        .collect();
    assert_eq!(patches.len(), 3, "{patches:?}");
    for p in patches {
        let out = std::process::Command::new("git")
            .current_dir(root)
            .args(["apply", "--check"])
            .arg(&p)
            .output()
            .expect("git runs");
        assert!(
            out.status.success(),
            "{}: {}",
            p.display(),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let _ = std::fs::remove_dir_all(&tmp);
}
