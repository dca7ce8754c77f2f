//! Per-stage timings of one tracking frame (HOG mode, a 60×60-cell grid, the size every
//! target with cell 4 is normalised to), plus a whole `update` on 1280×720 frames.
//!
//! `cargo bench -p bevt_core --bench stages`
#![allow(missing_docs, clippy::unwrap_used, clippy::expect_used)]

use bevt_core::consensus::{consensus_score, ConsensusNorm};
use bevt_core::eval::synth::SynthParams;
use bevt_core::features::colornames::{cell_colornames, CN_CHANNELS};
use bevt_core::features::{FeatureExtractor, FeatureMap, Hog};
use bevt_core::fft::Fft2;
use bevt_core::filter::admm::{AdmmSolver, CropBox};
use bevt_core::filter::label::reg_window;
use bevt_core::filter::peak::{subpixel_peak, NewtonScratch};
use bevt_core::filter::response::{fused_response, LayerSlot};
use bevt_core::filter::shift::{apply_phase, shift_phase};
use bevt_core::image::{Patch, Sampler};
use bevt_core::scale_filter::ScaleFilter;
use bevt_core::{BevtTracker, Frame, GridSize, PixelFormat, Size2, Tracker, TrackerConfig};
use criterion::{criterion_group, criterion_main, Criterion};
use rustfft::num_complex::Complex32;
use std::hint::black_box;

const GRID: usize = 60;
const CELL: usize = 4;
const CHANNELS: usize = 32;
const SCALES: usize = 5;

fn hd_sequence() -> SynthParams {
    SynthParams {
        width: 1280,
        height: 720,
        frames: 40,
        target: (160.0, 128.0),
        path_amplitude: (200.0, 120.0),
        ..SynthParams::default()
    }
}

fn stages(c: &mut Criterion) {
    let seq = hd_sequence();
    let f0 = seq.frame(0);
    let frame = Frame::packed(&f0.rgb, seq.width, seq.height, PixelFormat::Rgb8).unwrap();
    let grid = GridSize { h: GRID, w: GRID };
    let side = GRID * CELL;
    let center = f0.truth.center();
    let region = 5.0 * 1.2 * (f0.truth.w * f0.truth.h).sqrt();

    let mut sampler = Sampler::default();
    let mut patch = Patch::new(side, 3);
    c.bench_function("sample: 5 scale patches 240x240 from 1280x720", |b| {
        b.iter(|| {
            sampler.prepare(&frame, center, region * 0.98, region * 1.02, side);
            for k in 0..SCALES {
                sampler.sample(center, region * (0.98 + 0.01 * k as f32), &mut patch);
            }
            black_box(&patch);
        })
    });

    let mut hog = Hog::new(CELL, true);
    let mut feat = FeatureMap::new(grid, hog.channels());
    c.bench_function("features: fHOG+gray, 5 scales", |b| {
        b.iter(|| {
            for _ in 0..SCALES {
                hog.extract(&patch, CELL, &mut feat).unwrap();
            }
            black_box(&feat);
        })
    });

    let mut hog_only = Hog::new(CELL, false);
    let mut hog_feat = FeatureMap::new(grid, hog_only.channels());
    c.bench_function("features: fHOG alone, one patch", |b| {
        b.iter(|| {
            hog_only.extract(&patch, CELL, &mut hog_feat).unwrap();
            black_box(&hog_feat);
        })
    });
    let mut cn = vec![0.0f32; CN_CHANNELS * grid.len()];
    c.bench_function("features: colour names (10 channels), one patch", |b| {
        b.iter(|| {
            cell_colornames(&patch, CELL, GRID, GRID, &mut cn);
            black_box(&cn);
        })
    });

    let mut fft = Fft2::new(grid);
    let bins = fft.spectrum_len();
    let mut xf = vec![Complex32::default(); CHANNELS * bins];
    c.bench_function("fft: 32 channels x 5 scales forward", |b| {
        b.iter(|| {
            for _ in 0..SCALES {
                for d in 0..CHANNELS {
                    fft.forward(feat.channel(d), &mut xf[d * bins..(d + 1) * bins]);
                }
            }
            black_box(&xf);
        })
    });

    let spec = TrackerConfig::default().validate().unwrap();
    let mut y = vec![0.0; grid.len()];
    bevt_core::filter::label::gaussian_label(grid, 0.8, &mut y);
    let mut yf = vec![Complex32::default(); bins];
    fft.forward(&y, &mut yf);
    let base = Size2 { w: 40.0, h: 32.0 };
    let reg = reg_window(grid, base, CELL, 0.1, 0.8);
    let crop = CropBox::centred(grid, GridSize { h: 8, w: 10 });
    let mut g = vec![Complex32::default(); CHANNELS * bins];
    for (name, penalty) in [
        ("matrix", bevt_core::filter::admm::PenaltyKind::Matrix),
        (
            "elementwise",
            bevt_core::filter::admm::PenaltyKind::Elementwise,
        ),
        ("none", bevt_core::filter::admm::PenaltyKind::None),
    ] {
        let mut params = spec.config.admm.clone();
        params.penalty = penalty;
        let mut solver = AdmmSolver::new(grid, bins, CHANNELS, &params, &reg, crop);
        c.bench_function(
            &format!("admm: train 32 channels, 3 iterations, {name}"),
            |b| {
                b.iter(|| {
                    solver.train(&mut fft, &xf, &yf, &mut g);
                    black_box(&g);
                })
            },
        );
    }

    let layers = vec![LayerSlot {
        channels: 0..CHANNELS,
        weight: 1.0,
    }];
    let mut rf = vec![Complex32::default(); bins];
    let mut resp = vec![0.0; grid.len()];
    let mut newton = NewtonScratch::default();
    c.bench_function("detection: response + ifft + Newton peak, 5 scales", |b| {
        b.iter(|| {
            for _ in 0..SCALES {
                fused_response(&g, &xf, &layers, bins, &mut rf);
                fft.inverse(&rf, &mut resp);
                black_box(subpixel_peak(&resp, &rf, grid, 50, &mut newton));
            }
        })
    });

    let mut phase = vec![Complex32::default(); bins];
    let mut shifted = vec![Complex32::default(); CHANNELS * bins];
    c.bench_function("training sample: Fourier shift of 32 channels", |b| {
        b.iter(|| {
            shift_phase(grid, 1.3, -0.7, &mut phase);
            apply_phase(&xf, &phase, &mut shifted);
            black_box(&shifted);
        })
    });

    let sf_params = spec.config.scale_filter.clone();
    let mut sf = ScaleFilter::new(&sf_params, 3).unwrap();
    let size = f0.truth.size();
    sf.train(&frame, center, size).unwrap();
    c.bench_function(
        "scale filter: estimate + train (17 samples, 33 scales)",
        |b| {
            b.iter(|| {
                black_box(sf.estimate(&frame, center, size).unwrap());
                sf.train(&frame, center, size).unwrap();
            })
        },
    );

    let other: Vec<f32> = resp.iter().rev().copied().collect();
    let mut scratch = Vec::new();
    c.bench_function("verification: spectral-norm consensus", |b| {
        b.iter(|| {
            black_box(consensus_score(
                &resp,
                &other,
                grid,
                ConsensusNorm::Spectral,
                &mut scratch,
            ))
        })
    });

    // A whole update on HD frames (features + FFT + detection + verification + training),
    // with the default configuration and with the reference one.
    let frames: Vec<_> = (0..seq.frames).map(|i| seq.frame(i)).collect();
    let reference: TrackerConfig =
        serde_norway::from_str(include_str!("../../config/bevt_reference.yaml")).unwrap();
    for (name, spec) in [
        ("default", spec.clone()),
        ("reference", reference.validate().unwrap()),
    ] {
        let mut tracker = BevtTracker::new(spec);
        tracker.init(&frame, f0.truth).unwrap();
        let mut i = 1;
        c.bench_function(
            &format!("update: one frame, 1280x720, {name} config"),
            |b| {
                b.iter(|| {
                    let f = &frames[i];
                    let fr =
                        Frame::packed(&f.rgb, seq.width, seq.height, PixelFormat::Rgb8).unwrap();
                    black_box(tracker.update(&fr).unwrap());
                    i = if i + 1 < frames.len() { i + 1 } else { 1 };
                })
            },
        );
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30).measurement_time(std::time::Duration::from_secs(3));
    targets = stages
}
criterion_main!(benches);
