//! The per-frame kernels that have AVX2 + FMA clones chosen at run time (`multiversion`,
//! docs/benchmarks.md) give pinned bits on fixed input: on a CPU with AVX2 the clones run,
//! on one without (or under `qemu-x86_64 -cpu Nehalem`) the baseline versions do, and
//! both must give the same bits, the claim that lets the clones leave every box unchanged.
//! One exception, by choice: the networks' matrix product fuses its multiply-adds where the
//! CPU has FMA (every x86-64 CPU with AVX2, every aarch64 CPU), so on x86-64 CPUs without
//! it the networks' last bits differ (docs/benchmarks.md, "fused multiply-adds").
//! `nn`'s matrix product also has an AVX-512 kernel (pulp's `x86::V4`) for whole blocks of
//! 16 columns, and the depthwise kernel AVX-512 blocks (3 × 3 and 5 × 5 kernels summed in
//! registers, other kernels' rows of 3 and 5 taps): on a CPU with AVX-512
//! their bits are the ones pinned below for the product and the depthwise convolutions.
//! x86-64 only: other architectures compile the baseline versions alone.

use crate::features::hog::Hog;
use crate::features::{FeatureExtractor, FeatureMap};
use crate::filter::response::{fused_response, LayerSlot};
use crate::geometry::GridSize;
use crate::image::{Frame, Patch, PixelFormat, Sampler};
use crate::nn::ops::{pack_rows, rows_product, Unary};
use crate::redetect::dwconv::{depthwise, Geometry, Scratch};
use crate::Point2;
use rustfft::num_complex::Complex32;

/// FNV-1a over the values' bits.
fn fnv(values: &[f32], mut h: u64) -> u64 {
    for v in values {
        for b in v.to_bits().to_le_bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}

/// A deterministic pseudo-random sequence in `[0, 1)`.
fn lcg(seed: &mut u64) -> f32 {
    *seed = seed
        .wrapping_mul(6_364_136_223_846_793_005)
        .wrapping_add(1_442_695_040_888_963_407);
    (*seed >> 40) as f32 / (1u64 << 24) as f32
}

/// The bits of the sampler (down- and upscaling), fHOG with grey and colour names, the
/// depthwise kernel (3×3 stride 1 and 5×5 stride 2), the fused response and the networks'
/// matrix product on fixed input.
fn kernel_bits() -> Vec<u64> {
    let (w, h) = (320usize, 180usize);
    let data: Vec<u8> = (0..w * h * 3)
        .map(|i| {
            let (p, c) = (i / 3, i % 3);
            let (x, y) = (p % w, p / w);
            ((x * 7 + y * 13 + c * 50) ^ (x * y / 17)) as u8
        })
        .collect();
    let frame = Frame::packed(&data, w, h, PixelFormat::Rgb8).expect("a valid frame");
    let mut out = Vec::new();
    let mut sampler = Sampler::default();
    let center = Point2 { x: 150.3, y: 88.7 };
    let mut hog = Hog::with_colornames(4, true, true);
    for (region, side) in [(120.0f32, 48usize), (40.0, 96)] {
        sampler.prepare(&frame, center, region, region * 1.2, side);
        let mut patch = Patch::new(side, 3);
        sampler.sample_rect(center, region * 1.1, region, &mut patch);
        out.push(fnv(&patch.data, 0xcbf2_9ce4_8422_2325));
        let g = side / 4;
        let mut f = FeatureMap::new(GridSize { h: g, w: g }, hog.channels());
        hog.extract(&patch, 4, &mut f).expect("a valid grid");
        out.push(fnv(&f.data, 0xcbf2_9ce4_8422_2325));
    }
    let mut seed = 7u64;
    for (k, stride, pad) in [(3usize, 1usize, 1usize), (5, 2, 2)] {
        let (c, n) = (6usize, 21usize);
        let g = Geometry::new(c, (n, n), (k, k), (stride, stride), (pad, pad), (pad, pad))
            .expect("a valid geometry");
        let input: Vec<f32> = (0..c * n * n).map(|_| lcg(&mut seed) - 0.5).collect();
        let weights: Vec<f32> = (0..c * k * k).map(|_| lcg(&mut seed) - 0.5).collect();
        let bias: Vec<f32> = (0..c).map(|_| lcg(&mut seed)).collect();
        let mut output = vec![0.0; c * g.out_plane()];
        assert!(depthwise(
            &g,
            &input,
            &weights,
            &bias,
            &mut output,
            &mut Scratch::default()
        ));
        out.push(fnv(&output, 0xcbf2_9ce4_8422_2325));
    }
    let (bins, d) = (37usize, 5usize);
    let mut c = || Complex32::new(lcg(&mut seed) - 0.5, lcg(&mut seed) - 0.5);
    let g_f: Vec<Complex32> = (0..d * bins).map(|_| c()).collect();
    let x_f: Vec<Complex32> = (0..d * bins).map(|_| c()).collect();
    let layers = [
        LayerSlot {
            channels: 0..2,
            weight: 0.7,
        },
        LayerSlot {
            channels: 2..5,
            weight: 1.3,
        },
    ];
    let mut resp = vec![Complex32::default(); bins];
    fused_response(&g_f, &x_f, &layers, bins, &mut resp);
    let flat: Vec<f32> = resp.iter().flat_map(|v| [v.re, v.im]).collect();
    out.push(fnv(&flat, 0xcbf2_9ce4_8422_2325));
    // The networks' one-group convolutions: 11 output channels (a partial block), 29 inputs,
    // 21 columns (whole blocks and a rest), a ReLU applied as it stores.
    let (m, k, n) = (11usize, 29usize, 21usize);
    let w: Vec<f32> = (0..m * k).map(|_| lcg(&mut seed) - 0.5).collect();
    let x: Vec<f32> = (0..k * n).map(|_| lcg(&mut seed) - 0.5).collect();
    let bias: Vec<f32> = (0..m).map(|_| lcg(&mut seed) - 0.5).collect();
    let mut y = vec![0.0; m * n];
    let wp = pack_rows(&w, m, k);
    rows_product((m, k, n), &wp, &x, n, &bias, Some(Unary::Relu), &mut y, n);
    out.push(fnv(&y, 0xcbf2_9ce4_8422_2325));
    out
}

/// Pinned on 2026-11-27 from the AMD host's run with the AVX2 clones, and equal under
/// `qemu-x86_64 -cpu Nehalem` (no AVX: the baseline versions), docs/benchmarks.md. The last
/// value is the networks' product as it runs on a CPU with FMA (fused multiply-adds in the
/// AVX2 + FMA clone and the AVX-512 kernel, since 2026-11-29); without FMA it is
/// [`PRODUCT_UNFUSED`].
const PINNED: [u64; 8] = [
    0x9bd72564e9887679, // sampler, 120 px region to 48 px
    0x1cae2f33cb65cb49, // fHOG + grey + colour names of it
    0xdce991673a7e2c9a, // sampler, 40 px region to 96 px
    0x4ac540f685bd3400, // fHOG + grey + colour names of it
    0x9731de3210aa1b6a, // depthwise 3×3, stride 1
    0xbabe173a1e42fe34, // depthwise 5×5, stride 2
    0x7fbef409158440f6, // fused response
    0xfc6daa557ec3e3f1, // nn's rows_product, 11 × 29 by 29 × 21, ReLU, fused
];

/// nn's rows_product on the x86-64 baseline (a CPU without FMA: a multiply, then an add),
/// pinned on 2026-11-27 as above.
const PRODUCT_UNFUSED: u64 = 0xa5465843eb25a6cf;

#[test]
fn the_cloned_kernels_give_the_pinned_bits_with_and_without_avx2() {
    let avx2 =
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma");
    let avx512 = std::arch::is_x86_feature_detected!("avx512f");
    let mut want = PINNED;
    if !avx2 {
        want[7] = PRODUCT_UNFUSED;
    }
    assert_eq!(
        kernel_bits(),
        want,
        "AVX2 + FMA clones running: {avx2}, AVX-512 product kernel: {avx512}"
    );
}
