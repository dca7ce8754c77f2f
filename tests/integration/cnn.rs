//! CNN features (cargo feature `cnn`): the feature path end to end on the tiny test models,
//! the shipped models against their reference values, and every bad input as a clear error
//! at init. Needs ONNX Runtime (`ORT_DYLIB_PATH`, see scripts/onnxruntime.sh): skipped with
//! a printed reason without it.

use bevt_core::config::{FeatureKind, ScaleEstimator, TrainingSample};
use bevt_core::eval::synth::SynthParams;
use bevt_core::features::cnn::{CnnError, CnnExtractor, ORT_DYLIB_ENV};
use bevt_core::features::cnn_config::{
    CnnConfig, CnnHogConfig, CnnLayerConfig, InputSizePolicy, LayerNorm,
};
use bevt_core::features::{FeatureExtractor, FeatureMap, Hog};
use bevt_core::image::Patch;
use bevt_core::{BevtTracker, Frame, GridSize, PixelFormat, TrackError, Tracker, TrackerConfig};
use std::path::PathBuf;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn model(rel: &str) -> String {
    repo().join("models").join(rel).display().to_string()
}

/// The runtime path, or `None` after printing why the test is skipped.
fn runtime(test: &str) -> Option<String> {
    match std::env::var(ORT_DYLIB_ENV) {
        Ok(p) if std::path::Path::new(&p).is_file() => Some(p),
        _ => {
            bevt_tests::skip(
                test,
                format!("{ORT_DYLIB_ENV} does not name an ONNX Runtime library (run scripts/onnxruntime.sh)"),
            );
            None
        }
    }
}

fn layer(output: &str, channels: usize, weight: f32) -> CnnLayerConfig {
    CnnLayerConfig {
        output: output.to_string(),
        channels,
        weight,
        gain: 1.0,
        norm: LayerNorm::Rms,
        project: 0,
    }
}

fn tiny(rt: &str) -> CnnConfig {
    CnnConfig {
        model: model("test/tiny_cnn.onnx"),
        runtime: rt.to_string(),
        input_size: 32,
        cell_size: 4,
        layers: vec![layer("s2", 4, 1.0), layer("s4", 6, 0.5)],
        ..CnnConfig::default()
    }
}

#[test]
fn tiny_model_features_have_the_configured_layers_and_are_finite() {
    let Some(rt) = runtime("tiny_model_features_have_the_configured_layers_and_are_finite") else {
        return;
    };
    let mut ex = CnnExtractor::new(&tiny(&rt)).unwrap();
    assert_eq!(ex.channels(), 10);
    assert_eq!(ex.layers()[1].weight, 0.5);
    assert_eq!(ex.input_side(40), 32);
    let mut patch = Patch::new(32, 3);
    for (i, v) in patch.data.iter_mut().enumerate() {
        *v = ((i * 37) % 256) as f32;
    }
    let grid = GridSize { h: 8, w: 8 };
    let mut out = FeatureMap::new(grid, 10);
    ex.extract(&patch, 4, &mut out).unwrap();
    assert!(out.data.iter().all(|v| v.is_finite()));
    // RMS normalisation: each layer's raw map has RMS 1 after the gain of 1, and
    // bilinear resampling keeps it of that order.
    let n = grid.len();
    for (range, name) in [(0..4, "s2"), (4..10, "s4")] {
        let vals = &out.data[range.start * n..range.end * n];
        let rms = (vals.iter().map(|v| v * v).sum::<f32>() / vals.len() as f32).sqrt();
        assert!(rms > 0.3 && rms < 3.0, "{name}: rms {rms}");
    }
    // One pass for several scales equals separate resampling of the same pass at fraction 1.
    let mut a = FeatureMap::new(grid, 10);
    let mut b = FeatureMap::new(grid, 10);
    ex.extract_scales(&patch, &[1.0, 0.5], &mut [&mut a, &mut b])
        .unwrap();
    assert_eq!(a.data, out.data);
    assert_ne!(b.data, out.data);
}

#[test]
fn tiny_model_tracks_a_synthetic_target_end_to_end() {
    let Some(rt) = runtime("tiny_model_tracks_a_synthetic_target_end_to_end") else {
        return;
    };
    // Every way of getting the features: a pass per scale, one pass for all scales, and the
    // training sample shifted from the detection features.
    for (single_pass, from_detection) in [(false, false), (true, false), (false, true)] {
        let mut cfg = TrackerConfig::default();
        // The 5-scale search and fresh training patches (as the CNN presets), so every
        // scale and both training paths go through the network.
        cfg.detection.scale_estimator = ScaleEstimator::Search;
        cfg.learning.training_sample = TrainingSample::Fresh;
        cfg.features.kind = FeatureKind::Cnn;
        cfg.features.cnn = Some(CnnConfig {
            input_size_policy: InputSizePolicy::Patch,
            single_pass_scales: single_pass,
            train_from_detection: from_detection,
            ..tiny(&rt)
        });
        let seq = SynthParams {
            frames: 8,
            ..SynthParams::default()
        };
        let mut t = BevtTracker::try_new(cfg.validate().unwrap()).unwrap();
        let f0 = seq.frame(0);
        t.init(
            &Frame::packed(&f0.rgb, seq.width, seq.height, PixelFormat::Rgb8).unwrap(),
            f0.truth,
        )
        .unwrap();
        for i in 1..seq.frames {
            let f = seq.frame(i);
            let out = t
                .update(&Frame::packed(&f.rgb, seq.width, seq.height, PixelFormat::Rgb8).unwrap())
                .unwrap();
            assert!(out.bbox.is_finite() && out.consensus > 0.0 && out.consensus <= 1.0);
            assert!(out.learned);
            // Random weights track poorly; the path must run and stay near the target.
            let err = out.bbox.center().distance(&f.truth.center());
            assert!(
                err < seq.width as f32 / 2.0,
                "single pass {single_pass}, from detection {from_detection}, frame {i}: centre error {err}"
            );
        }
    }
}

/// A patch of side `side` with a deterministic texture.
fn textured_patch(side: usize) -> Patch {
    let mut patch = Patch::new(side, 3);
    for (i, v) in patch.data.iter_mut().enumerate() {
        let (r, c) = ((i / side) % side, i % side);
        *v = (((r * 7 + c * 13) % 64) as f32 * 3.0 + ((i * 37) % 41) as f32).min(255.0);
    }
    patch
}

#[test]
fn projection_keeps_the_leading_energy_in_fewer_channels() {
    let Some(rt) = runtime("projection_keeps_the_leading_energy_in_fewer_channels") else {
        return;
    };
    let mut cfg = tiny(&rt);
    cfg.layers[0].project = 2; // s2: 4 -> 2
    cfg.layers[1].project = 3; // s4: 6 -> 3
    let mut ex = CnnExtractor::new(&cfg).unwrap();
    assert_eq!(ex.channels(), 5);
    assert_eq!(ex.layers()[0].channels, 2);
    assert_eq!(ex.layers()[1].channels, 3);
    assert!(ex.learns_per_track());
    assert_eq!(ex.projection_energy(0), None);
    let patch = textured_patch(32);
    ex.begin_track(&patch).unwrap();
    // Raw maps of this patch, then the projected ones.
    ex.prepare_input(&patch);
    ex.run_prepared(32).unwrap();
    let raw: Vec<(usize, f64)> = (0..2)
        .map(|l| {
            let (c, _, _, d) = ex.layer_map(l).unwrap();
            (c, d.iter().map(|v| f64::from(*v).powi(2)).sum())
        })
        .collect();
    assert_eq!((raw[0].0, raw[1].0), (4, 6));
    ex.project_maps().unwrap();
    for (l, (kept, of)) in [(2usize, 4usize), (3, 6)].into_iter().enumerate() {
        let (c, _, _, d) = ex.layer_map(l).unwrap();
        assert_eq!(c, kept);
        let energy = ex.projection_energy(l).unwrap();
        // PCA keeps at least the average share and at most everything.
        assert!(
            energy >= kept as f32 / of as f32 - 1e-4 && energy <= 1.0 + 1e-4,
            "layer {l}: energy {energy}"
        );
        // Orthonormal directions: the projected energy is exactly the kept share.
        let proj: f64 = d.iter().map(|v| f64::from(*v).powi(2)).sum();
        let share = proj / raw[l].1;
        assert!(
            (share - f64::from(energy)).abs() < 1e-3,
            "layer {l}: projected share {share}, learned {energy}"
        );
    }
    // The extractor path gives the projected channel count on the grid.
    let grid = GridSize { h: 8, w: 8 };
    let mut out = FeatureMap::new(grid, 5);
    ex.extract(&patch, 4, &mut out).unwrap();
    assert!(out.data.iter().all(|v| v.is_finite()));
    assert!(out.data.iter().any(|v| *v != 0.0));
    // A map with the unprojected channel count is refused, not silently filled.
    let mut wrong = FeatureMap::new(grid, 10);
    assert!(ex.extract(&patch, 4, &mut wrong).is_err());
}

#[test]
fn fused_hog_layer_is_hog_of_the_same_patch_with_its_own_weight() {
    let Some(rt) = runtime("fused_hog_layer_is_hog_of_the_same_patch_with_its_own_weight") else {
        return;
    };
    let hog_cfg = CnnHogConfig {
        weight: 0.7,
        gain: 2.0,
        grayscale: true,
        colornames: false,
    };
    let cfg = CnnConfig {
        input_size_policy: InputSizePolicy::Patch,
        hog: Some(hog_cfg),
        ..tiny(&rt)
    };
    let mut ex = CnnExtractor::new(&cfg).unwrap();
    assert_eq!(ex.layers().len(), 3);
    assert_eq!(ex.layers()[2].channels, 32); // 31 HOG + gray
    assert_eq!(ex.layers()[2].weight, 0.7);
    assert_eq!(ex.channels(), 42);
    // The patch is grid * cell pixels: the HOG layer sees it unresampled.
    let patch = textured_patch(32);
    let grid = GridSize { h: 8, w: 8 };
    let mut out = FeatureMap::new(grid, 42);
    ex.extract(&patch, 4, &mut out).unwrap();
    let mut hog = Hog::new(4, true);
    let mut alone = FeatureMap::new(grid, 32);
    hog.extract(&patch, 4, &mut alone).unwrap();
    let n = grid.len();
    let fused = &out.data[10 * n..];
    assert!(alone.data.iter().any(|v| *v > 0.0));
    for (f, a) in fused.iter().zip(&alone.data) {
        assert!((f - 2.0 * a).abs() < 1e-5, "{f} vs 2 x {a}");
    }
    // The network's channels are what the extractor without HOG gives.
    let mut plain = CnnExtractor::new(&CnnConfig {
        input_size_policy: InputSizePolicy::Patch,
        ..tiny(&rt)
    })
    .unwrap();
    let mut cnn_only = FeatureMap::new(grid, 10);
    plain.extract(&patch, 4, &mut cnn_only).unwrap();
    assert_eq!(&out.data[..10 * n], &cnn_only.data[..]);
    // Colour names join the HOG layer on colour input and leave it on mono8.
    let mut cn = CnnExtractor::new(&CnnConfig {
        hog: Some(CnnHogConfig {
            colornames: true,
            ..hog_cfg
        }),
        ..tiny(&rt)
    })
    .unwrap();
    assert_eq!(cn.channels(), 52);
    cn.set_input_planes(1);
    assert_eq!(cn.channels(), 42);
}

#[test]
fn tiny_model_with_the_scale_filter_follows_a_growing_target() {
    use bevt_core::config::{ScaleEstimator, TrainingSample};
    let Some(rt) = runtime("tiny_model_with_the_scale_filter_follows_a_growing_target") else {
        return;
    };
    // x1.5 over 60 frames (as the HOG fast-mode test); one network pass per frame, the
    // scale from the scale filter only.
    let seq = SynthParams {
        width: 480,
        height: 360,
        frames: 60,
        target: (60.0, 48.0),
        scale_rate: 1.007,
        ..SynthParams::default()
    };
    for project in [0, 3] {
        let mut cfg = TrackerConfig::default();
        cfg.features.kind = FeatureKind::Cnn;
        // The random-weight layers alone locate the target only roughly; the fused HOG
        // layer (its own filter) keeps the position, so the scale filter's samples are on
        // the target.
        let mut cnn = CnnConfig {
            input_size_policy: InputSizePolicy::Patch,
            hog: Some(CnnHogConfig::default()),
            ..tiny(&rt)
        };
        cnn.layers[1].project = project;
        cfg.features.cnn = Some(cnn);
        cfg.detection.scale_estimator = ScaleEstimator::Filter;
        cfg.learning.training_sample = TrainingSample::Shifted;
        // Random weights give no meaningful confidence: learn every frame, never lost.
        cfg.verification.score = bevt_core::consensus::VerificationScore::Reference;
        cfg.track_state.lost_threshold = 0.0;
        let mut t = BevtTracker::try_new(cfg.validate().unwrap()).unwrap();
        let f0 = seq.frame(0);
        t.init(
            &Frame::packed(&f0.rgb, seq.width, seq.height, PixelFormat::Rgb8).unwrap(),
            f0.truth,
        )
        .unwrap();
        let mut last = None;
        let mut learned = 0;
        for i in 1..seq.frames {
            let f = seq.frame(i);
            let out = t
                .update(&Frame::packed(&f.rgb, seq.width, seq.height, PixelFormat::Rgb8).unwrap())
                .unwrap();
            learned += usize::from(out.learned);
            last = Some((out, f.truth));
        }
        let (out, truth) = last.unwrap();
        let grown = out.bbox.w / f0.truth.w;
        let truth_grown = truth.w / f0.truth.w;
        assert!(truth_grown > 1.45, "{truth_grown}");
        assert!(
            (grown / truth_grown - 1.0).abs() < 0.08,
            "project {project}: box grew x{grown}, the target x{truth_grown}; {learned} frames \
             learned, last {out:?}"
        );
        let err = out.bbox.center().distance(&truth.center());
        assert!(err < 10.0, "project {project}: centre error {err}");
    }
}

/// Mean and first element of layer `l` after running `input`.
fn stats(ex: &mut CnnExtractor, input: &[f32], side: usize, l: usize) -> (usize, usize, f64, f32) {
    ex.run_raw(input, side).unwrap();
    let (_, h, w, data) = ex.layer_map(l).unwrap();
    let mean = data.iter().map(|v| f64::from(*v)).sum::<f64>() / data.len() as f64;
    (h, w, mean, data[0])
}

#[test]
fn shipped_nanotrack_backbone_matches_its_reference_values() {
    let Some(rt) = runtime("shipped_nanotrack_backbone_matches_its_reference_values") else {
        return;
    };
    let cfg = CnnConfig {
        model: model("nanotrack/nanotrackv2_backbone_sim_dyn.onnx"),
        runtime: rt,
        ..CnnConfig::default()
    };
    let mut ex = CnnExtractor::new(&cfg).unwrap();
    let side = 255;
    let x: Vec<f32> = (0..3 * side * side)
        .map(|i| ((i % 251) as f32 / 251.0) * 255.0)
        .collect();
    let (h, w, mean, first) = stats(&mut ex, &x, side, 0);
    assert_eq!((h, w), (16, 16));
    assert!((mean - -0.310945).abs() < 1e-4, "mean {mean}");
    assert!((first - -5.593468).abs() < 1e-3, "first {first}");
    // The top-left 127×127 crop of the same input.
    let c = 127;
    let crop: Vec<f32> = (0..3)
        .flat_map(|p| (0..c).flat_map(move |r| (0..c).map(move |col| (p, r, col))))
        .map(|(p, r, col)| x[(p * side + r) * side + col])
        .collect();
    let (h, w, mean, _) = stats(&mut ex, &crop, c, 0);
    assert_eq!((h, w), (8, 8));
    assert!((mean - -0.230320).abs() < 1e-4, "mean {mean}");
}

#[test]
fn shipped_mobilenetv2_matches_its_reference_values() {
    let Some(rt) = runtime("shipped_mobilenetv2_matches_its_reference_values") else {
        return;
    };
    let names = [
        ("feat_s4", 144, 0.174402, 0.210024),
        ("feat_s8", 192, 0.109475, 0.331683),
        ("feat_s16", 576, 0.023427, 0.0),
        ("bneck_s4", 24, -0.096171, -0.385293),
        ("bneck_s8", 32, -0.245705, 1.240075),
        ("bneck_s16", 96, 0.027485, 0.328400),
    ];
    let cfg = CnnConfig {
        model: model("mobilenetv2/mobilenetv2_features.onnx"),
        runtime: rt,
        input_size: 224,
        layers: names.iter().map(|(n, c, _, _)| layer(n, *c, 1.0)).collect(),
        ..CnnConfig::default()
    };
    let mut ex = CnnExtractor::new(&cfg).unwrap();
    let side = 224;
    let x: Vec<f32> = (0..3 * side * side)
        .map(|i| ((i % 251) as f32 / 251.0 - 0.5) * 2.0)
        .collect();
    for (l, (name, _, mean_ref, first_ref)) in names.iter().enumerate() {
        let (_, _, mean, first) = stats(&mut ex, &x, side, l);
        assert!((mean - mean_ref).abs() < 1e-4, "{name}: mean {mean}");
        assert!((first - first_ref).abs() < 1e-3, "{name}: first {first}");
    }
}

/// The error `CnnExtractor::new` gives for `cfg`.
fn init_error(cfg: &CnnConfig) -> CnnError {
    CnnExtractor::new(cfg).expect_err("the config was accepted")
}

#[test]
fn bad_models_and_configs_are_clear_errors_at_init() {
    let Some(rt) = runtime("bad_models_and_configs_are_clear_errors_at_init") else {
        return;
    };
    let base = tiny(&rt);
    let e = init_error(&CnnConfig {
        model: model("test/missing.onnx"),
        ..base.clone()
    });
    assert!(matches!(e, CnnError::ModelMissing { .. }), "{e}");
    assert!(e.to_string().contains("features.cnn.model"), "{e}");

    let e = init_error(&CnnConfig {
        layers: vec![layer("nope", 4, 1.0)],
        ..base.clone()
    });
    assert!(matches!(e, CnnError::NoOutput { .. }), "{e}");
    assert!(e.to_string().contains("s2, s4"), "{e}");

    let e = init_error(&CnnConfig {
        layers: vec![layer("s2", 5, 1.0)],
        ..base.clone()
    });
    assert!(
        matches!(
            e,
            CnnError::Channels {
                got: 4,
                expected: 5,
                ..
            }
        ),
        "{e}"
    );

    let e = init_error(&CnnConfig {
        model: model("test/tiny_rank3.onnx"),
        ..base.clone()
    });
    assert!(matches!(e, CnnError::Rank { .. }), "{e}");

    let e = init_error(&CnnConfig {
        model: model("test/tiny_fixed.onnx"),
        input_size: 48,
        ..base.clone()
    });
    assert!(matches!(e, CnnError::InputSize { size: 48, .. }), "{e}");
    let e = init_error(&CnnConfig {
        model: model("test/tiny_fixed.onnx"),
        input_size_policy: InputSizePolicy::Patch,
        ..base.clone()
    });
    assert!(matches!(e, CnnError::InputSize { .. }), "{e}");
    // The fixed model at its own size is fine.
    CnnExtractor::new(&CnnConfig {
        model: model("test/tiny_fixed.onnx"),
        ..base.clone()
    })
    .unwrap();

    let e = init_error(&CnnConfig {
        model: model("test/tiny_nan.onnx"),
        ..base.clone()
    });
    assert!(matches!(e, CnnError::NonFinite { .. }), "{e}");

    let e = init_error(&CnnConfig {
        input: "image".to_string(),
        ..base.clone()
    });
    assert!(matches!(e, CnnError::Input { .. }), "{e}");

    // A model whose input size is wrong for the network (too small for two stride-2 convs
    // is still fine; a non-ONNX file is not).
    let e = init_error(&CnnConfig {
        model: repo().join("models/test/README.md").display().to_string(),
        ..base.clone()
    });
    assert!(matches!(e, CnnError::Model { .. }), "{e}");

    let e = init_error(&CnnConfig {
        runtime: "/nonexistent/libonnxruntime.so.1.31.1".to_string(),
        ..base.clone()
    });
    assert!(matches!(e, CnnError::RuntimeMissing { .. }), "{e}");

    #[cfg(not(feature = "cuda"))]
    {
        let e = init_error(&CnnConfig {
            device: bevt_core::features::cnn_config::CnnDevice::Cuda,
            ..base.clone()
        });
        assert!(matches!(e, CnnError::Device(_)), "{e}");
    }
}

#[test]
fn tracker_reports_a_bad_cnn_model_at_init_and_never_falls_back_to_hog() {
    let Some(rt) = runtime("tracker_reports_a_bad_cnn_model_at_init_and_never_falls_back_to_hog")
    else {
        return;
    };
    let mut cfg = TrackerConfig::default();
    cfg.features.kind = FeatureKind::Cnn;
    cfg.features.cnn = Some(CnnConfig {
        model: model("test/missing.onnx"),
        ..tiny(&rt)
    });
    let spec = cfg.validate().unwrap();
    assert!(matches!(
        BevtTracker::try_new(spec.clone()),
        Err(TrackError::Feature(_))
    ));
    let mut t = BevtTracker::new(spec);
    let seq = SynthParams::default();
    let f0 = seq.frame(0);
    let e = t
        .init(
            &Frame::packed(&f0.rgb, seq.width, seq.height, PixelFormat::Rgb8).unwrap(),
            f0.truth,
        )
        .unwrap_err();
    assert!(e.to_string().contains("features.cnn.model"), "{e}");
    assert!(!t.is_initialized());
}

#[test]
fn cnn_presets_parse_and_validate() {
    use bevt_core::config::{ScaleEstimator, TrainingSample, VerifierKind};
    let defaults = TrackerConfig::default();
    for p in [
        "cnn_fusion",
        "cnn_nanotrack",
        "cnn_mobilenetv2",
        "cnn_vgg19",
    ] {
        let path = repo().join("config").join(format!("{p}.yaml"));
        let spec = bevt_node::params::load_config(Some(&path), &[]).unwrap();
        let c = &spec.config;
        // The presets omit every non-feature key that equals the default (no drift).
        assert_eq!(c.window, defaults.window, "{p}");
        // The CNN numbers were measured with the reference's matrix penalty (pinned).
        assert_eq!(
            c.admm.penalty,
            bevt_core::filter::admm::PenaltyKind::Matrix,
            "{p}"
        );
        let mut admm = c.admm.clone();
        admm.penalty = defaults.admm.penalty;
        assert_eq!(admm, defaults.admm, "{p}");
        assert_eq!(c.confidence, defaults.confidence, "{p}");
        let one_pass = matches!(p, "cnn_fusion" | "cnn_nanotrack");
        // The one-pass presets add the NanoTrack re-detection verifier with the shipped
        // models; every other re-detection key is the default's.
        let mut redetection = c.redetection.clone();
        if one_pass {
            assert_eq!(redetection.verifier, VerifierKind::NanotrackOrt, "{p}");
            for m in [&redetection.verifier_backbone, &redetection.verifier_head] {
                assert!(std::path::Path::new(m).is_file(), "{p}: {m} is not shipped");
            }
            redetection.verifier = defaults.redetection.verifier;
            redetection.verifier_backbone = defaults.redetection.verifier_backbone.clone();
            redetection.verifier_head = defaults.redetection.verifier_head.clone();
        }
        assert_eq!(redetection, defaults.redetection, "{p}");
        assert_eq!(
            c.detection.scale_estimator == ScaleEstimator::Filter,
            one_pass,
            "{p}"
        );
        assert_eq!(
            c.learning.training_sample == TrainingSample::Shifted,
            one_pass,
            "{p}"
        );
        let cnn = spec.config.features.cnn.unwrap();
        assert_eq!(cnn.hog.is_some(), p == "cnn_fusion", "{p}");
        assert_eq!(spec.config.features.kind, FeatureKind::Cnn);
        if p != "cnn_vgg19" {
            assert!(
                std::path::Path::new(&cnn.model).is_file(),
                "{p}: {} is not shipped",
                cnn.model
            );
        }
    }
}

/// Set in the child process of [`a_file_that_is_not_onnx_runtime_is_an_error_at_init`].
const CHILD_ENV: &str = "BEVT_CNN_TEST_CHILD";

/// ONNX Runtime is loaded once per process, so this runs in a fresh child process of the
/// test binary, where no runtime is loaded yet.
#[test]
fn a_file_that_is_not_onnx_runtime_is_an_error_at_init() {
    let not_a_runtime = repo().join("models/test/README.md").display().to_string();
    if std::env::var(CHILD_ENV).is_ok() {
        let e = init_error(&CnnConfig {
            runtime: not_a_runtime,
            ..tiny("")
        });
        assert!(matches!(e, CnnError::Runtime { .. }), "{e}");
        assert!(e.to_string().contains("features.cnn.runtime"), "{e}");
        println!("child: {e}");
        return;
    }
    let out = std::process::Command::new(std::env::current_exe().unwrap())
        .args([
            "cnn::a_file_that_is_not_onnx_runtime_is_an_error_at_init",
            "--exact",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(CHILD_ENV, "1")
        .env_remove(ORT_DYLIB_ENV)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("1 passed"), "{stdout}");
    assert!(stdout.contains("child: features.cnn.runtime"), "{stdout}");
}

/// `redetection.verifier: nanotrack_ort` runs the embedded NanoTrack v2 on ONNX Runtime:
/// its backbone and head outputs equal the pure-Rust engine's (bevt_core::nn; to 1e-3 on
/// the reference input), and the far re-entry is re-acquired on the same frame as in pure
/// Rust (61, returning on 50).
#[test]
fn nanotrack_ort_verifier_matches_the_pure_rust_one() {
    use bevt_core::redetect::nano::NanoVerifier;
    let Some(rt) = runtime("nanotrack_ort_verifier_matches_the_pure_rust_one") else {
        return;
    };
    let mut o = NanoVerifier::new_ort(&rt, "", "").unwrap();
    let mut t = NanoVerifier::new("", "").unwrap();
    let side = 255;
    let x: Vec<f32> = (0..3 * side * side)
        .map(|i| ((i % 251) as f32 / 251.0) * 255.0)
        .collect();
    let z: Vec<f32> = x[..3 * 127 * 127].to_vec();
    let max_diff = |a: &[f32], b: &[f32]| {
        assert_eq!(a.len(), b.len());
        a.iter()
            .zip(b)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0f32, f32::max)
    };
    let (xo, xt) = (o.backbone(&x, 255).unwrap(), t.backbone(&x, 255).unwrap());
    let (zo, zt) = (o.backbone(&z, 127).unwrap(), t.backbone(&z, 127).unwrap());
    let (d_x, d_z) = (max_diff(&xo, &xt), max_diff(&zo, &zt));
    let ((mo, lo), (mt, lt)) = (o.head(&zo, &xo).unwrap(), t.head(&zo, &xo).unwrap());
    let (d_m, d_l) = (max_diff(&mo, &mt), max_diff(&lo, &lt));
    println!("max |ort - nn|: backbone {d_x:e} / {d_z:e}, head {d_m:e} / {d_l:e}");
    assert!(d_x < 1e-3 && d_z < 1e-3 && d_m < 1e-3 && d_l < 1e-2);
    // Wrong runtime: a clear error naming the key.
    let e = NanoVerifier::new_ort(&model("nanotrack/README.md"), "", "").unwrap_err();
    assert!(e.to_string().contains("nanotrack_ort"), "{e}");

    let seq = bevt_tests::scenes::far_reentry();
    let mut cfg = TrackerConfig::default();
    cfg.redetection.proposals = 0;
    cfg.redetection.verifier = bevt_core::config::VerifierKind::NanotrackOrt;
    let r = bevt_tests::track_synthetic(&seq, cfg, seq.truth(0));
    let back = (50..seq.frames).find(|&t| r[t - 1].0.state == bevt_core::TrackState::Reacquired);
    assert_eq!(back, Some(61));
}
