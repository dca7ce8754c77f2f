//! Per-pass time of the NanoTrack v2 re-detection verifier: backbone on a 255×255 search
//! crop, backbone on a 127×127 template crop, head. On bevt_core::nn (every build); with
//! the `cnn` feature and `ORT_DYLIB_PATH` set, also the same models under ONNX Runtime (one
//! thread, all graph optimisations), in the same run, for the nn/ort ratio:
//!
//! `cargo bench -p bevt_core --bench verifier`
//! `ORT_DYLIB_PATH=$(bash scripts/onnxruntime.sh) cargo bench -p bevt_core --features cnn --bench verifier`
#![allow(missing_docs, clippy::unwrap_used, clippy::expect_used)]

use bevt_core::redetect::nano::{NanoVerifier, CHANNELS, SEARCH_SIDE, TEMPLATE_SIDE};
use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;
use std::time::Duration;

/// The models' reference input (models/nanotrack/README.md) for a `side`² crop.
fn input(side: usize) -> Vec<f32> {
    (0..3 * side * side)
        .map(|i| ((i % 251) as f32 / 251.0) * 255.0)
        .collect()
}

fn passes(c: &mut Criterion) {
    let mut v = NanoVerifier::new("", "").unwrap();
    let (x, z) = (input(SEARCH_SIDE), input(TEMPLATE_SIDE));
    let zf = v.backbone(&z, TEMPLATE_SIDE).unwrap();
    let xf = v.backbone(&x, SEARCH_SIDE).unwrap();
    assert_eq!(xf.len(), CHANNELS * 256);
    c.bench_function("nn_backbone_255", |b| {
        b.iter(|| black_box(v.backbone(black_box(&x), SEARCH_SIDE).unwrap()))
    });
    c.bench_function("nn_backbone_127", |b| {
        b.iter(|| black_box(v.backbone(black_box(&z), TEMPLATE_SIDE).unwrap()))
    });
    c.bench_function("nn_head", |b| {
        b.iter(|| black_box(v.head(black_box(&zf), black_box(&xf)).unwrap()))
    });
    #[cfg(feature = "cnn")]
    ort_passes(c, &x, &z, &zf, &xf);
}

#[cfg(feature = "cnn")]
fn ort_passes(c: &mut Criterion, x: &[f32], z: &[f32], zf: &[f32], xf: &[f32]) {
    use ort::session::builder::GraphOptimizationLevel;
    use ort::session::Session;
    use ort::value::TensorRef;
    if std::env::var(bevt_core::features::cnn::ORT_DYLIB_ENV).is_err() {
        println!("ONNX Runtime rows skipped: ORT_DYLIB_PATH is not set (scripts/onnxruntime.sh)");
        return;
    }
    let env = bevt_core::features::cnn::load_runtime("").unwrap();
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/nanotrack");
    let session = |file: &str| {
        Session::builder(&env)
            .unwrap()
            .with_optimization_level(GraphOptimizationLevel::All)
            .unwrap()
            .with_intra_threads(1)
            .unwrap()
            .with_inter_threads(1)
            .unwrap()
            .commit_from_file(root.join(file))
            .unwrap()
    };
    let mut bb = session("nanotrackv2_backbone_sim_dyn.onnx");
    let mut hd = session("nanotrackv2_head_sim.onnx");
    let mut backbone = |data: &[f32], side: usize| {
        let t = TensorRef::from_array_view(([1usize, 3, side, side], data)).unwrap();
        let out = bb.run(ort::inputs!["input" => t]).unwrap();
        out["output"]
            .try_extract_tensor::<f32>()
            .unwrap()
            .1
            .to_vec()
    };
    // Same numbers as bevt_core::nn (the verifier's outputs do not depend on the backend).
    let ort_xf = backbone(x, SEARCH_SIDE);
    let diff = ort_xf
        .iter()
        .zip(xf)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    println!("backbone 255: max |ort - nn| = {diff:e}");
    c.bench_function("ort_backbone_255", |b| {
        b.iter(|| black_box(backbone(black_box(x), SEARCH_SIDE)))
    });
    c.bench_function("ort_backbone_127", |b| {
        b.iter(|| black_box(backbone(black_box(z), TEMPLATE_SIDE)))
    });
    c.bench_function("ort_head", |b| {
        b.iter(|| {
            let zt = TensorRef::from_array_view(([1usize, CHANNELS, 8, 8], zf)).unwrap();
            let xt = TensorRef::from_array_view(([1usize, CHANNELS, 16, 16], xf)).unwrap();
            let out = hd
                .run(ort::inputs!["input1" => zt, "input2" => xt])
                .unwrap();
            black_box(out["output1"].try_extract_tensor::<f32>().unwrap().1[0])
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .sample_size(20)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(4));
    targets = passes
}
criterion_main!(benches);
