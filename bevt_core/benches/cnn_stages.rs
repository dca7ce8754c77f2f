//! Per-stage timings of one CNN-mode frame with the NanoTrack v2 backbone preset
//! (`config/cnn_nanotrack.yaml`: 255×255 input, 48 channels, a 60×60-cell grid, 5 scales),
//! plus a whole `update` on 1280×720 frames. Needs the `cnn` feature and ONNX Runtime:
//!
//! `ORT_DYLIB_PATH=$(bash scripts/onnxruntime.sh) cargo bench -p bevt_core --features cnn --bench cnn_stages`
#![allow(missing_docs, clippy::unwrap_used, clippy::expect_used)]

use bevt_core::config::FeatureKind;
use bevt_core::eval::synth::SynthParams;
use bevt_core::features::cnn::{CnnExtractor, ORT_DYLIB_ENV};
use bevt_core::features::cnn_config::CnnConfig;
use bevt_core::features::{FeatureExtractor, FeatureMap};
use bevt_core::fft::Fft2;
use bevt_core::filter::admm::{AdmmSolver, CropBox};
use bevt_core::filter::label::reg_window;
use bevt_core::filter::peak::{subpixel_peak, NewtonScratch};
use bevt_core::filter::response::{fused_response, LayerSlot};
use bevt_core::image::{Patch, Sampler};
use bevt_core::{BevtTracker, Frame, GridSize, PixelFormat, Size2, Tracker, TrackerConfig};
use criterion::{criterion_group, criterion_main, Criterion};
use rustfft::num_complex::Complex32;
use std::hint::black_box;

const GRID: usize = 60;
const SCALES: usize = 5;

fn preset() -> CnnConfig {
    CnnConfig {
        model: concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../models/nanotrack/nanotrackv2_backbone_sim_dyn.onnx"
        )
        .to_string(),
        ..CnnConfig::default()
    }
}

fn stages(c: &mut Criterion) {
    if std::env::var(ORT_DYLIB_ENV).is_err() {
        println!("SKIPPED cnn_stages: {ORT_DYLIB_ENV} is not set (scripts/onnxruntime.sh)");
        return;
    }
    let cfg = preset();
    let mut ex = CnnExtractor::new(&cfg).unwrap();
    let channels = ex.channels();
    let seq = SynthParams {
        width: 1280,
        height: 720,
        frames: 40,
        target: (160.0, 128.0),
        path_amplitude: (200.0, 120.0),
        ..SynthParams::default()
    };
    let f0 = seq.frame(0);
    let frame = Frame::packed(&f0.rgb, seq.width, seq.height, PixelFormat::Rgb8).unwrap();
    let center = f0.truth.center();
    let region = 5.0 * 1.2 * (f0.truth.w * f0.truth.h).sqrt();
    let side = cfg.input_size;
    let mut sampler = Sampler::default();
    let mut patch = Patch::new(side, 3);
    sampler.prepare(&frame, center, region, region, side);
    sampler.sample(center, region, &mut patch);

    c.bench_function(
        "cnn preprocessing: sample 255x255 + normalise, 1 pass",
        |b| {
            b.iter(|| {
                sampler.prepare(&frame, center, region, region, side);
                sampler.sample(center, region, &mut patch);
                ex.prepare_input(&patch);
            })
        },
    );
    c.bench_function("cnn network: NanoTrack backbone 255x255, 1 pass", |b| {
        b.iter(|| ex.run_prepared(side).unwrap())
    });
    let grid = GridSize { h: GRID, w: GRID };
    let mut feat = FeatureMap::new(grid, channels);
    c.bench_function("cnn resampling: 48x16x16 -> 48x60x60, 1 scale", |b| {
        b.iter(|| ex.resample_into(1.0, black_box(&mut feat)))
    });
    let mut fft = Fft2::new(grid);
    let bins = fft.spectrum_len();
    let mut xf = vec![Complex32::default(); channels * bins];
    c.bench_function("cnn FFT: 48 channels 60x60, 5 scales", |b| {
        b.iter(|| {
            for _ in 0..SCALES {
                for d in 0..channels {
                    fft.forward(feat.channel(d), &mut xf[d * bins..(d + 1) * bins]);
                }
            }
        })
    });
    let spec = TrackerConfig::default().validate().unwrap();
    let base = Size2 { w: 40.0, h: 32.0 };
    let reg = reg_window(grid, base, 4, 0.1, 0.8);
    let crop = CropBox::centred(grid, GridSize { h: 8, w: 10 });
    let mut solver = AdmmSolver::new(grid, bins, channels, &spec.admm, &reg, crop);
    let y = vec![Complex32::new(1.0, 0.0); bins];
    let mut g = vec![Complex32::default(); channels * bins];
    c.bench_function(
        "cnn ADMM: 48 channels 60x60, 3 iterations, matrix penalty",
        |b| b.iter(|| solver.train(&mut fft, &xf, &y, &mut g)),
    );
    let layers = vec![LayerSlot {
        channels: 0..channels,
        weight: 1.0,
    }];
    let mut resp_f = vec![Complex32::default(); bins];
    let mut resp = vec![0.0; grid.len()];
    let mut newton = NewtonScratch::default();
    c.bench_function("cnn detection: fusion + IFFT + Newton, 5 scales", |b| {
        b.iter(|| {
            for _ in 0..SCALES {
                fused_response(&g, &xf, &layers, bins, &mut resp_f);
                fft.inverse(&resp_f, &mut resp);
                black_box(subpixel_peak(&resp, &resp_f, grid, 50, &mut newton));
            }
        })
    });

    let mut tc = TrackerConfig::default();
    tc.features.kind = FeatureKind::Cnn;
    tc.features.gain = 0.3;
    tc.features.cnn = Some(cfg);
    let mut tracker = BevtTracker::try_new(tc.validate().unwrap()).unwrap();
    tracker.init(&frame, f0.truth).unwrap();
    let frames: Vec<Vec<u8>> = (1..seq.frames).map(|i| seq.frame(i).rgb).collect();
    let mut i = 0;
    c.bench_function("cnn whole update (cnn_nanotrack preset), 1280x720", |b| {
        b.iter(|| {
            let f = Frame::packed(
                &frames[i % frames.len()],
                seq.width,
                seq.height,
                PixelFormat::Rgb8,
            )
            .unwrap();
            i += 1;
            black_box(tracker.update(&f).unwrap());
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = stages
}
criterion_main!(benches);
