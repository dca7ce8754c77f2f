//! Per-stage timings of one CNN-mode frame with a preset (default
//! `config/cnn_mobilenetv2.yaml`; another with `BEVT_CNN_PRESET=config/cnn_nanotrack.yaml`):
//! its network, layers, projection, grid (60×60 cells), scale estimator (one translation
//! patch and the scale filter, or one patch per search scale), plus a whole `update` on
//! 1280×720 frames. Needs the `cnn` feature and ONNX Runtime:
//!
//! `ORT_DYLIB_PATH=$(bash scripts/onnxruntime.sh) cargo bench -p bevt_core --features cnn --bench cnn_stages`
#![allow(missing_docs, clippy::unwrap_used, clippy::expect_used)]

use bevt_core::config::ScaleEstimator;
use bevt_core::eval::synth::SynthParams;
use bevt_core::features::cnn::{CnnExtractor, ORT_DYLIB_ENV};
use bevt_core::features::{FeatureExtractor, FeatureMap};
use bevt_core::fft::Fft2;
use bevt_core::filter::admm::{AdmmSolver, CropBox};
use bevt_core::filter::label::reg_window;
use bevt_core::filter::peak::{subpixel_peak, NewtonScratch};
use bevt_core::filter::response::{fused_response, LayerSlot};
use bevt_core::image::{Patch, Sampler};
use bevt_core::scale_filter::ScaleFilter;
use bevt_core::{BevtTracker, Frame, GridSize, PixelFormat, Size2, Tracker, TrackerConfig};
use criterion::{criterion_group, criterion_main, Criterion};
use rustfft::num_complex::Complex32;
use std::hint::black_box;
use std::path::PathBuf;

const GRID: usize = 60;

/// The preset's configuration, its model path resolved against the preset's folder.
fn preset() -> (String, TrackerConfig) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let rel = std::env::var("BEVT_CNN_PRESET")
        .unwrap_or_else(|_| "config/cnn_mobilenetv2.yaml".to_string());
    let path = root.join(&rel);
    let text = std::fs::read_to_string(&path).unwrap();
    let mut cfg: TrackerConfig = serde_norway::from_str(&text).unwrap();
    let cnn = cfg.features.cnn.as_mut().expect("a CNN preset");
    cnn.model = path
        .parent()
        .unwrap()
        .join(&cnn.model)
        .display()
        .to_string();
    (rel, cfg)
}

fn stages(c: &mut Criterion) {
    if std::env::var(ORT_DYLIB_ENV).is_err() {
        println!("SKIPPED cnn_stages: {ORT_DYLIB_ENV} is not set (scripts/onnxruntime.sh)");
        return;
    }
    let (name, tc) = preset();
    let spec = tc.validate().unwrap();
    let cfg = tc.features.cnn.clone().unwrap();
    let scales = match tc.detection.scale_estimator {
        ScaleEstimator::Search => tc.detection.number_of_scales,
        ScaleEstimator::Filter => 1,
    };
    println!("cnn_stages: preset {name}, {scales} translation patch(es) per frame");
    let mut ex = CnnExtractor::new(&cfg).unwrap();
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
    ex.begin_track(&patch).unwrap();
    let channels = ex.channels();
    let raw: usize = cfg.layers.iter().map(|l| l.channels).sum();

    c.bench_function(
        &format!("cnn preprocessing: sample {side}x{side} + normalise, 1 pass"),
        |b| {
            b.iter(|| {
                sampler.prepare(&frame, center, region, region, side);
                sampler.sample(center, region, &mut patch);
                ex.prepare_input(&patch);
            })
        },
    );
    c.bench_function(&format!("cnn network: {side}x{side}, 1 pass"), |b| {
        b.iter(|| ex.run_prepared(side).unwrap())
    });
    c.bench_function(
        // The projection consumes the raw maps, so it is timed with the network pass:
        // projection = this minus the network line.
        &format!("cnn network + projection: {raw} -> {channels} channels, 1 pass"),
        |b| {
            b.iter(|| {
                ex.run_prepared(side).unwrap();
                ex.project_maps().unwrap();
            })
        },
    );
    let grid = GridSize { h: GRID, w: GRID };
    let mut feat = FeatureMap::new(grid, channels);
    c.bench_function(
        &format!("cnn resampling: {channels} ch -> 60x60, 1 patch"),
        |b| b.iter(|| ex.resample_into(1.0, black_box(&mut feat))),
    );
    let mut fft = Fft2::new(grid);
    let bins = fft.spectrum_len();
    let mut xf = vec![Complex32::default(); channels * bins];
    c.bench_function(
        &format!("cnn FFT: {channels} channels 60x60, {scales} patch(es)"),
        |b| {
            b.iter(|| {
                for _ in 0..scales {
                    for d in 0..channels {
                        fft.forward(feat.channel(d), &mut xf[d * bins..(d + 1) * bins]);
                    }
                }
            })
        },
    );
    let base = Size2 { w: 40.0, h: 32.0 };
    let reg = reg_window(grid, base, 4, 0.1, 0.8);
    let crop = CropBox::centred(grid, GridSize { h: 8, w: 10 });
    let mut solvers: Vec<(std::ops::Range<usize>, AdmmSolver)> = Vec::new();
    let mut start = 0;
    for l in ex.layers() {
        let r = start..start + l.channels;
        solvers.push((
            r,
            AdmmSolver::new(grid, bins, l.channels, &spec.config.admm, &reg, crop),
        ));
        start += l.channels;
    }
    let y = vec![Complex32::new(1.0, 0.0); bins];
    let mut g = vec![Complex32::default(); channels * bins];
    c.bench_function(
        &format!(
            "cnn ADMM: {channels} channels in {} layers, 60x60, {} iterations",
            solvers.len(),
            tc.admm.iterations
        ),
        |b| {
            b.iter(|| {
                for (r, s) in solvers.iter_mut() {
                    s.train(
                        &mut fft,
                        &xf[r.start * bins..r.end * bins],
                        &y,
                        &mut g[r.start * bins..r.end * bins],
                    );
                }
            })
        },
    );
    let mut start = 0;
    let layers: Vec<LayerSlot> = ex
        .layers()
        .iter()
        .map(|l| {
            start += l.channels;
            LayerSlot {
                channels: start - l.channels..start,
                weight: l.weight,
            }
        })
        .collect();
    let mut resp_f = vec![Complex32::default(); bins];
    let mut resp = vec![0.0; grid.len()];
    let mut newton = NewtonScratch::default();
    c.bench_function(
        &format!("cnn detection: fusion + IFFT + Newton, {scales} patch(es)"),
        |b| {
            b.iter(|| {
                for _ in 0..scales {
                    fused_response(&g, &xf, &layers, bins, &mut resp_f);
                    fft.inverse(&resp_f, &mut resp);
                    black_box(subpixel_peak(&resp, &resp_f, grid, 50, &mut newton));
                }
            })
        },
    );
    if tc.detection.scale_estimator == ScaleEstimator::Filter {
        let mut sf = ScaleFilter::new(&spec.config.scale_filter, 3).unwrap();
        let size = f0.truth.size();
        sf.train(&frame, center, size).unwrap();
        c.bench_function("cnn scale filter: estimate + train", |b| {
            b.iter(|| {
                black_box(sf.estimate(&frame, center, size).unwrap());
                sf.train(&frame, center, size).unwrap();
            })
        });
    }

    let mut tracker = BevtTracker::try_new(spec).unwrap();
    tracker.init(&frame, f0.truth).unwrap();
    let frames: Vec<Vec<u8>> = (1..seq.frames).map(|i| seq.frame(i).rgb).collect();
    let mut i = 0;
    c.bench_function(&format!("cnn whole update ({name}), 1280x720"), |b| {
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
