//! The NanoTrack v2 re-detection verifier (`redetection.verifier: nanotrack`), run in pure
//! Rust by bevt_core::nn in every build: the embedded backbone against its reference values, the
//! head's outputs, bad model files as clear errors, and the verifier's behaviour on the
//! lost-state scenes of `bevt_tests::scenes`.

use bevt_core::config::VerifierKind;
use bevt_core::redetect::nano::{NanoError, NanoVerifier, CHANNELS, SEARCH_CELLS};
use bevt_core::{BevtTracker, Frame, PixelFormat, TrackState, Tracker, TrackerConfig};
use std::path::PathBuf;

fn model(rel: &str) -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../models")
        .join(rel)
        .display()
        .to_string()
}

const BACKBONE: &str = "nanotrack/nanotrackv2_backbone_sim_dyn.onnx";
const HEAD: &str = "nanotrack/nanotrackv2_head_sim.onnx";

/// Mean (f64) and first element.
fn stats(data: &[f32]) -> (f64, f32) {
    let mean = data.iter().map(|v| f64::from(*v)).sum::<f64>() / data.len() as f64;
    (mean, data[0])
}

/// The README's reference input `x[i] = ((i % 251)/251)·255` over `[1,3,255,255]` and its
/// top-left 127×127 crop.
fn reference_inputs() -> (Vec<f32>, Vec<f32>) {
    let side = 255;
    let x: Vec<f32> = (0..3 * side * side)
        .map(|i| ((i % 251) as f32 / 251.0) * 255.0)
        .collect();
    let c = 127;
    let crop = (0..3)
        .flat_map(|p| (0..c).flat_map(move |r| (0..c).map(move |col| (p, r, col))))
        .map(|(p, r, col)| x[(p * side + r) * side + col])
        .collect();
    (x, crop)
}

/// The embedded backbone under bevt_core::nn reproduces ONNX Runtime 1.31.1's reference values
/// (models/nanotrack/README.md): means to 1e-4, the first element to 1e-3 (f32 sums in
/// another order; the two runtimes agree to ~1e-5 here).
#[test]
fn embedded_nanotrack_backbone_matches_its_reference_values_in_pure_rust() {
    let mut v = NanoVerifier::new("", "").unwrap();
    let (x, crop) = reference_inputs();
    let out = v.backbone(&x, 255).unwrap();
    assert_eq!(out.len(), CHANNELS * 16 * 16);
    let (mean, first) = stats(&out);
    println!("255: mean {mean:.6}, first {first:.6}");
    assert!((mean - -0.310945).abs() < 1e-4, "mean {mean}");
    assert!((first - -5.593468).abs() < 1e-3, "first {first}");
    let out = v.backbone(&crop, 127).unwrap();
    assert_eq!(out.len(), CHANNELS * 8 * 8);
    let (mean, _) = stats(&out);
    println!("127: mean {mean:.6}");
    assert!((mean - -0.230320).abs() < 1e-4, "mean {mean}");
    // Other sides are not planned: an error, not a panic.
    assert!(v.backbone(&x[..3 * 100 * 100], 100).is_err());
}

/// The head on the reference features: one margin and four distances per grid point, all
/// finite; a template scored against a search crop that contains it (the template crop is
/// the search crop's centre) peaks near the centre of the score map.
#[test]
fn head_outputs_have_nanotrack_shapes_and_peak_on_the_template() {
    // Explicit paths load from disk (the same files as the embedded ones).
    let mut v = NanoVerifier::new(&model(BACKBONE), &model(HEAD)).unwrap();
    let (x, _) = reference_inputs();
    let side = 255;
    // A textured search crop whose centre 127×127 is the template crop.
    let search: Vec<f32> = (0..3 * side * side)
        .map(|i| {
            let (r, c) = ((i / side) % side, i % side);
            let inside = (64..191).contains(&r) && (64..191).contains(&c);
            if inside {
                x[i]
            } else {
                128.0
            }
        })
        .collect();
    let template: Vec<f32> = (0..3)
        .flat_map(|p| (64..191).flat_map(move |r| (64..191).map(move |c| (p, r, c))))
        .map(|(p, r, c)| search[(p * side + r) * side + c])
        .collect();
    let zf = v.backbone(&template, 127).unwrap();
    let xf = v.backbone(&search, 255).unwrap();
    let (margins, loc) = v.head(&zf, &xf).unwrap();
    let n = SEARCH_CELLS * SEARCH_CELLS;
    assert_eq!((margins.len(), loc.len()), (n, 4 * n));
    assert!(margins.iter().chain(&loc).all(|v| v.is_finite()));
    let best = (0..n)
        .max_by(|&a, &b| margins[a].total_cmp(&margins[b]))
        .unwrap();
    let (j, k) = (best / SEARCH_CELLS, best % SEARCH_CELLS);
    println!("peak at ({j}, {k}), margin {}", margins[best]);
    assert!(
        (6..=10).contains(&j) && (6..=10).contains(&k),
        "peak at ({j}, {k})"
    );
    assert!(v.head(&zf[1..], &xf).is_err());
}

/// Missing, corrupt, non-ONNX and wrong-network model files are clear errors naming the
/// key and the file, never panics.
#[test]
fn bad_verifier_model_files_are_clear_errors() {
    let dir = std::env::temp_dir().join(format!("bevt_verifier_bad_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let write = |name: &str, bytes: &[u8]| {
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p.display().to_string()
    };
    let good = std::fs::read(model(BACKBONE)).unwrap();
    let truncated = write("truncated.onnx", &good[..good.len() / 2]);
    let text = write("text.onnx", b"this is not an ONNX model\n");
    let empty = write("empty.onnx", b"");
    let cases: Vec<(String, String, &str)> = vec![
        (
            dir.join("none.onnx").display().to_string(),
            String::new(),
            "no such file",
        ),
        (truncated.clone(), String::new(), "truncated.onnx"),
        (text.clone(), String::new(), "text.onnx"),
        (empty.clone(), String::new(), "empty.onnx"),
        // The head given as the backbone: no input `input`.
        (model(HEAD), String::new(), "nanotrackv2_head_sim.onnx"),
        // The backbone given as the head.
        (
            String::new(),
            model(BACKBONE),
            "nanotrackv2_backbone_sim_dyn.onnx",
        ),
        (String::new(), truncated, "truncated.onnx"),
    ];
    for (backbone, head, needle) in cases {
        let e = NanoVerifier::new(&backbone, &head).unwrap_err();
        let msg = e.to_string();
        println!("{msg}");
        let key = if head.is_empty() {
            "redetection.verifier_backbone"
        } else {
            "redetection.verifier_head"
        };
        assert!(msg.contains(key) && msg.contains(needle), "{msg}");
        if needle == "no such file" {
            assert!(matches!(e, NanoError::ModelMissing { .. }), "{e:?}");
        } else {
            assert!(matches!(e, NanoError::Model { .. }), "{e:?}");
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Frame of the first `reacquired` state at or after frame 50, tracking `seq` with `cfg`.
fn reacquired_at(
    seq: &bevt_core::eval::synth::SynthParams,
    cfg: TrackerConfig,
) -> (
    Option<usize>,
    Vec<(bevt_core::TrackOutput, bevt_core::BBox)>,
) {
    let r = bevt_tests::track_synthetic(seq, cfg, seq.truth(0));
    let back = (50..seq.frames).find(|&t| r[t - 1].0.state == TrackState::Reacquired);
    (back, r)
}

/// The target re-acquired by frame 75 (it returns on 50) and kept from then on: centre
/// error under 8 px on every later frame.
fn assert_kept_from(r: &[(bevt_core::TrackOutput, bevt_core::BBox)], back: usize) {
    assert!(back <= 75, "re-acquired at frame {back}");
    for (t, (o, truth)) in r.iter().enumerate().skip(back - 1) {
        let e = o.bbox.center().distance(&truth.center());
        assert!(e < 8.0, "frame {}: centre error {e}", t + 1);
    }
}

/// `redetection.verifier: nanotrack` with the embedded NanoTrack v2 backbone and head: the
/// target re-entering far away is re-acquired by the verifier's whole-frame tiles alone (the
/// filter's proposals off) within 25 frames of its return (the tiles cycle over the frame in
/// ~30 lost frames here), where without the verifier it is not re-acquired at all. The
/// passes it spends: at most `verifier_windows` on a lost frame, and one on each frame its
/// candidate is being confirmed (the tiles are not swept while the candidate holds).
#[test]
fn nanotrack_verifier_reacquires_a_far_reentry_the_filter_alone_misses() {
    let seq = bevt_tests::scenes::far_reentry();
    let mut cfg = TrackerConfig::default();
    cfg.redetection.proposals = 0;
    cfg.redetection.verifier = VerifierKind::None;
    let (back, _) = reacquired_at(&seq, cfg.clone());
    assert!(
        back.is_none_or(|t| t > 60),
        "without the verifier: {back:?}"
    );
    cfg.redetection.verifier = VerifierKind::Nanotrack;
    cfg.redetection.verifier_backbone = String::new();
    cfg.redetection.verifier_head = String::new();
    let windows = cfg.redetection.verifier_windows as u64;
    let confirm = cfg.redetection.reacquire_frames;
    let run = bevt_tests::track_synthetic_passes(&seq, cfg, seq.truth(0));
    let passes: Vec<u64> = run.iter().map(|x| x.2).collect();
    let r: Vec<_> = run.into_iter().map(|(o, b, _)| (o, b)).collect();
    let back = (50..seq.frames).find(|&t| r[t - 1].0.state == TrackState::Reacquired);
    println!("verifier: re-acquired at {back:?}");
    let back = back.expect("the verifier never re-acquired the target");
    assert_kept_from(&r, back);
    for t in 1..back {
        if r[t - 1].0.state == TrackState::Lost {
            assert!(
                passes[t - 1] <= windows,
                "frame {t}: {} passes",
                passes[t - 1]
            );
        }
    }
    // The candidate's first frame swept the tiles; the frames confirming it follow it alone.
    let first = back + 1 - confirm;
    assert!(
        passes[first - 1] > 1,
        "frame {first}: {}",
        passes[first - 1]
    );
    for t in first + 1..=back {
        assert_eq!(passes[t - 1], 1, "frame {t} confirms the candidate");
    }
}

/// A verifier whose head file is missing is a clear error at init, naming the key.
#[test]
fn nanotrack_verifier_with_a_missing_head_is_an_error() {
    let mut cfg = TrackerConfig::default();
    cfg.redetection.verifier = VerifierKind::Nanotrack;
    cfg.redetection.verifier_backbone = model(BACKBONE);
    cfg.redetection.verifier_head = model("nanotrack/no_such_head.onnx");
    let seq = bevt_tests::scenes::far_reentry();
    let f0 = seq.frame(0);
    let mut t = BevtTracker::new(cfg.validate().unwrap());
    let frame = Frame::packed(&f0.rgb, seq.width, seq.height, PixelFormat::Rgb8).unwrap();
    let err = t.init(&frame, seq.truth(0)).unwrap_err().to_string();
    assert!(
        err.contains("redetection.verifier_head") && err.contains("no_such_head"),
        "{err}"
    );
}

/// The look-alike of `lost.rs` (the target's size, rim and colours, another texture; shown
/// at (120, 250) while the target is hidden, frames 30–49) with the NanoTrack verifier.
fn look_alike_run(filter_check: bool) -> (Vec<(bevt_core::TrackOutput, bevt_core::BBox)>, usize) {
    let seq = bevt_tests::scenes::with_look_alike();
    let mut cfg = TrackerConfig::default();
    cfg.redetection.verifier_filter_check = filter_check;
    cfg.redetection.verifier = VerifierKind::Nanotrack;
    cfg.redetection.verifier_backbone = model(BACKBONE);
    cfg.redetection.verifier_head = model(HEAD);
    let r = bevt_tests::track_synthetic(&seq, cfg, seq.truth(0));
    for (t, (o, _)) in r.iter().enumerate() {
        println!(
            "{} {} {:.2} {}",
            t + 1,
            o.state.name(),
            o.confidence,
            o.reason
        );
    }
    (r, seq.frames)
}

/// Frame `t` (1-based) reports a box on the look-alike.
fn on_look_alike(r: &[(bevt_core::TrackOutput, bevt_core::BBox)], t: usize) -> bool {
    let c = r[t - 1].0.bbox.center();
    (c.x - 120.0).abs() < 20.0 && (c.y - 250.0).abs() < 20.0
}

/// What a ground station needs: whatever the tracker does while the target is hidden, the
/// real target is re-acquired after it reappears (frame 50) and kept to the end.
#[test]
fn after_a_look_alike_the_target_is_reacquired_and_kept() {
    let (r, frames) = look_alike_run(false);
    let back = (50..=frames)
        .find(|&t| r[t - 1].0.state == TrackState::Reacquired && !on_look_alike(&r, t))
        .expect("the target was never re-acquired");
    assert_kept_from(&r, back);
}

/// The wanted behaviour: the look-alike is never reported as the target (no `tracking` or
/// `reacquired` frame with the box on it). Known defect with the default configuration,
/// so this test is ignored: NanoTrack's verifier scores the look-alike like the target, it
/// is re-acquired at frame 45 and reported `tracking` on frames 46–49 before the target
/// returns. The drift check (`tracker/drift.rs`) cannot catch it: it asks the same
/// verifier. `redetection.verifier_filter_check` fixes it (next test) but is off by
/// default: on the dev set it also refuses the real target after a long loss (issue 20,
/// `docs/states.md`). Run it with `--ignored`.
#[test]
#[ignore = "known defect: the NanoTrack verifier takes the look-alike (issue 20)"]
fn the_look_alike_is_never_reported_as_the_target() {
    assert_look_alike_never_claimed(&look_alike_run(false).0);
}

/// With `redetection.verifier_filter_check` a verifier candidate also needs the frozen
/// filter's agreement: the filter's relative bound refuses the look-alike (`lost.rs`), so
/// it is never reported as the target, and the real target is still re-acquired after
/// it returns (frame 50) and kept.
#[test]
fn with_the_filter_check_the_look_alike_is_never_reported_as_the_target() {
    let (r, frames) = look_alike_run(true);
    assert_look_alike_never_claimed(&r);
    let back = (50..=frames)
        .find(|&t| r[t - 1].0.state == TrackState::Reacquired)
        .expect("the target was never re-acquired");
    assert_kept_from(&r, back);
}

fn assert_look_alike_never_claimed(r: &[(bevt_core::TrackOutput, bevt_core::BBox)]) {
    // `r[t - 1]` is frame t: frames 1..=r.len() (frame 0 is the initialisation).
    let claimed: Vec<usize> = (1..=r.len())
        .filter(|&t| {
            matches!(
                r[t - 1].0.state,
                TrackState::Tracking | TrackState::Reacquired
            ) && on_look_alike(r, t)
        })
        .collect();
    assert!(
        claimed.is_empty(),
        "the look-alike was reported as the target on frames {claimed:?}"
    );
}

/// Verifiers of one process share the optimised plans: a second verifier of the same files
/// gives bit-identical features without reading the file again (it is gone by then), and
/// a failed load is not cached (the next attempt reads the file anew).
#[test]
fn verifiers_share_optimised_plans_within_a_process() {
    let dir = std::env::temp_dir().join(format!("bevt_verifier_cache_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("backbone.onnx");
    let p = path.display().to_string();
    // Not there yet: an error, and nothing is cached for the path.
    assert!(matches!(
        NanoVerifier::new(&p, ""),
        Err(NanoError::ModelMissing { .. })
    ));
    std::fs::copy(model(BACKBONE), &path).unwrap();
    let (x, _) = reference_inputs();
    let first = NanoVerifier::new(&p, "")
        .unwrap()
        .backbone(&x, 255)
        .unwrap();
    std::fs::remove_file(&path).unwrap();
    let mut again = NanoVerifier::new(&p, "").expect("the plans of a loaded path are kept");
    assert_eq!(again.backbone(&x, 255).unwrap(), first);
    // The embedded files are the same network: the same features.
    let embedded = NanoVerifier::new("", "")
        .unwrap()
        .backbone(&x, 255)
        .unwrap();
    assert_eq!(embedded, first);
    // Another path is still checked.
    let other = dir.join("other.onnx").display().to_string();
    assert!(NanoVerifier::new(&other, "").is_err());
    std::fs::remove_dir_all(&dir).ok();
}

/// The drift check's calm interval (`track_state.drift_calm_frames`): on a visible target
/// whose checks score at least the re-acquisition bar, the checks come every
/// `drift_calm_frames` instead of every `drift_check_frames` (fewer passes, every frame
/// still `tracking`); once the target is hidden, the learning gate's refusals end the calm,
/// so the hidden target is flagged within `drift_check_frames` (plus the verifier's one
/// frame of latency), where a check left at the calm interval would come later.
#[test]
fn the_calm_drift_check_comes_back_as_soon_as_the_filter_falls() {
    use bevt_core::eval::synth::SynthParams;
    const HIDE: usize = 40;
    let visible = SynthParams {
        frames: 91,
        ..SynthParams::default()
    };
    let mut cfg = TrackerConfig::default();
    cfg.track_state.lost_threshold = 0.0;
    cfg.track_state.drift_check_frames = 15;
    // Every check a verifier pass, so that the passes show when the checks ran (the frozen
    // first-frame filter and the learned box's head would answer the calm target's checks
    // without one).
    cfg.track_state.drift_anchor = false;
    cfg.track_state.drift_head = false;
    let checks = |cfg: &TrackerConfig, seq: &SynthParams| {
        let run = bevt_tests::track_synthetic_passes(seq, cfg.clone(), seq.truth(0));
        let at: Vec<usize> = (1..=run.len()).filter(|&t| run[t - 1].2 > 0).collect();
        (run, at)
    };
    cfg.track_state.drift_calm_frames = 0;
    let (run, every15) = checks(&cfg, &visible);
    assert!(run.iter().all(|x| x.0.state == TrackState::Tracking));
    assert_eq!(every15, vec![1, 16, 31, 46, 61, 76], "{every15:?}");
    cfg.track_state.drift_calm_frames = 30;
    let (run, calm) = checks(&cfg, &visible);
    assert!(run.iter().all(|x| x.0.state == TrackState::Tracking));
    assert_eq!(calm, vec![1, 31, 61], "{calm:?}");

    let hidden = SynthParams {
        frames: 70,
        hidden: Some((HIDE, 70)),
        ..SynthParams::default()
    };
    let (run, at) = checks(&cfg, &hidden);
    let flagged = (1..=run.len())
        .find(|&t| run[t - 1].0.state != TrackState::Tracking)
        .expect("the hidden target was never flagged");
    assert!(
        (HIDE..=HIDE + 16).contains(&flagged),
        "flagged on frame {flagged}, checks on {at:?}"
    );
}
