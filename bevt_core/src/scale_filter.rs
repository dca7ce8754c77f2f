//! A separate one-dimensional scale filter (DSST, Danelljan et al. BMVC 2014, in its fast
//! form fDSST, TPAMI 2017), used when `detection.scale_estimator: filter`.
//!
//! Translation is then detected on one patch per frame; this filter estimates the scale
//! at the new position from `n` small samples of the target at scales `a^e`
//! (`e = (k − ⌊n/2⌋)·m/n`, `a` the interpolated step), each resized to a `side × side`
//! pixel patch and described by fHOG (31 channels per cell; with `colornames`, plus the 10
//! colour-name channels per cell for colour frames). With `x_k ∈ ℝ^d` the feature vector of
//! scale `k`:
//!
//! - **Model**: `u ← (1−η)u + ηx` (`d × n`); a `d × n` orthonormal basis `P` of `u`'s
//!   columns (modified Gram–Schmidt, the QR of fDSST) compresses every sample to `n × n`.
//! - **Training**: `Â = ŷ · conj(FFT_k(w ⊙ Pᵀu))` per compressed row, and
//!   `B̂ ← (1−η)B̂ + η Σ_rows |FFT_k(w ⊙ P_xᵀx)|²` (`P_x` the basis of the new sample, as
//!   fDSST), `y` a Gaussian over the scale index (σ = `m · sigma_factor`), `w` a Hann
//!   window over the scales.
//! - **Detection**: `R̂ = Σ_rows Â ⊙ FFT_k(w ⊙ Pᵀz) / (B̂ + λ)`, zero-padded from `n` to
//!   `m` frequencies (fDSST's `resizeDFT`), inverse transformed; the arg-max over the `m`
//!   interpolated scales, refined by the vertex of a parabola through it and its
//!   neighbours, is the scale change.
//!
//! Differences from fDSST: each sample (the target box at that scale, aspect ratio clamped
//! to 3) is stretched onto a square `side × side` patch (fDSST keeps the aspect), resampled
//! by area averaging like the translation patches. Everything is allocated at construction;
//! [`ScaleFilter::estimate`] and [`ScaleFilter::train`] allocate nothing.

use crate::config::ScaleFilterConfig;
use crate::error::TrackError;
use crate::features::{FeatureExtractor, FeatureMap, Hog};
use crate::filter::label::hann;
use crate::geometry::{GridSize, Point2, Size2};
use crate::image::{Frame, Patch, Sampler, MAX_SAMPLE_ASPECT};
use rustfft::num_complex::Complex32;
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;

/// Smallest norm of a basis vector before it is treated as linearly dependent.
const BASIS_EPS: f32 = 1e-12;

/// The one-dimensional scale filter and all its buffers.
pub struct ScaleFilter {
    n: usize,
    m: usize,
    d: usize,
    lr: f32,
    lambda: f32,
    step: f32,
    cell: usize,
    padding: f32,
    /// Relative sample scales `a^{e_k}`, `k = 0..n`.
    sample_factors: Vec<f32>,
    /// Relative interpolated scales, `j = 0..m`.
    interp_factors: Vec<f32>,
    window: Vec<f32>,
    ysf: Vec<Complex32>,
    hog: Hog,
    patch: Patch,
    feat: FeatureMap,
    sampler: Sampler,
    /// Samples, scale-major: `xs[k·d..(k+1)·d]`.
    xs: Vec<f32>,
    /// Model `u`, scale-major.
    model: Vec<f32>,
    /// Orthonormal basis rows (`n × d`) of the model and of the last training sample.
    basis: Vec<f32>,
    basis_den: Vec<f32>,
    /// Compressed spectra, row-major `n × n` (row = basis vector, column = scale).
    proj_f: Vec<Complex32>,
    num_f: Vec<Complex32>,
    den_f: Vec<f32>,
    resp_f: Vec<Complex32>,
    interp: Vec<Complex32>,
    fft_n: Arc<dyn Fft<f32>>,
    ifft_m: Arc<dyn Fft<f32>>,
    scratch: Vec<Complex32>,
    trained: bool,
}

impl std::fmt::Debug for ScaleFilter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ScaleFilter")
            .field("scales", &self.n)
            .field("interpolated_scales", &self.m)
            .field("dim", &self.d)
            .field("trained", &self.trained)
            .finish()
    }
}

/// Lanes of the dot product's partial sums (a multiple of the SIMD width, so the loop
/// vectorises: a single running float sum cannot be reordered by the compiler).
const LANES: usize = 8;

/// `Σ a_i·b_i` with [`LANES`] independent partial sums.
#[multiversion::multiversion(targets("x86_64+avx2+fma"))] // AVX2 + FMA clone, chosen at run time
fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [0.0f32; LANES];
    let (ca, cb) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let tail: f32 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for l in 0..LANES {
            acc[l] += x[l] * y[l];
        }
    }
    acc.iter().sum::<f32>() + tail
}

/// [`dot`] of `q` with each of `xs` (each as long as `q`): the same sums in the same order, so
/// the same bits, but four independent chains of additions where one [`dot`] waits on its
/// own (one accumulator, the adds' latency), and one load of `q` for four products. The
/// scale filter's projections and bases are some 1,200 dots a frame.
fn dot4(q: &[f32], xs: [&[f32]; 4]) -> [f32; 4] {
    let n = q.len();
    let m = n - n % LANES;
    let xs = xs.map(|x| &x[..n]);
    let acc = dot4_lanes(&q[..m], xs.map(|x| &x[..m]));
    let mut out = [0.0; 4];
    for ((o, s), x) in out.iter_mut().zip(&acc).zip(&xs) {
        let tail: f32 = q[m..].iter().zip(&x[m..]).map(|(a, b)| a * b).sum();
        *o = s.iter().sum::<f32>() + tail;
    }
    out
}

/// [`dot4`]'s [`LANES`] partial sums over whole chunks (`q.len()` a multiple of [`LANES`], each
/// of `xs` as long): on AVX2 one 8-lane register a sum (pulp's `x86::V3`, safe code; left to
/// the compiler, the same loop stayed scalar with its sums on the stack, 2.6× the time of single
/// [`dot`]s in the tracker's profile), else the lanes as arrays.
fn dot4_lanes(q: &[f32], xs: [&[f32]; 4]) -> [[f32; LANES]; 4] {
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = pulp::x86::V3::try_new() {
        use pulp::{f32x8, Simd};
        return simd.vectorize(
            #[inline(always)]
            || {
                let (qa, _) = pulp::as_arrays::<LANES, f32>(q);
                let xa = xs.map(|x| pulp::as_arrays::<LANES, f32>(x).0);
                let mut acc = [simd.splat_f32s(0.0); 4];
                for (i, a) in qa.iter().enumerate() {
                    let a: f32x8 = pulp::cast(*a);
                    for (s, x) in acc.iter_mut().zip(&xa) {
                        // A multiply, then an add: `dot`'s two roundings, not a fused one.
                        *s = simd.add_f32s(*s, simd.mul_f32s(a, pulp::cast(x[i])));
                    }
                }
                acc.map(pulp::cast)
            },
        );
    }
    lanes_as_arrays(q, xs)
}

/// [`dot4_lanes`] without AVX2.
fn lanes_as_arrays(q: &[f32], xs: [&[f32]; 4]) -> [[f32; LANES]; 4] {
    let mut acc = [[0.0f32; LANES]; 4];
    for (i, a) in q.chunks_exact(LANES).enumerate() {
        for (s, x) in acc.iter_mut().zip(&xs) {
            for l in 0..LANES {
                s[l] += a[l] * x[i * LANES + l];
            }
        }
    }
    acc
}

/// `⌊n/2⌋`-centred exponents `(k − ⌊n/2⌋)` scaled by `s`.
fn exponents(n: usize, s: f32) -> impl Iterator<Item = f32> {
    let mid = (n / 2) as f32;
    (0..n).map(move |k| (k as f32 - mid) * s)
}

impl ScaleFilter {
    /// A filter for colour or grey patches of `planes` planes.
    ///
    /// # Errors
    /// [`TrackError::Feature`] when `sample_side` gives fewer than 2×2 HOG cells.
    pub fn new(p: &ScaleFilterConfig, planes: usize) -> Result<Self, TrackError> {
        let (n, m) = (p.scales.max(1), p.interpolated_scales.max(p.scales).max(1));
        let cell = p.cell_size.max(1);
        let cells = p.sample_side / cell;
        if cells < 2 {
            return Err(TrackError::Feature(format!(
                "scale sample side {} px gives fewer than 2 cells of {cell} px",
                p.sample_side
            )));
        }
        let grid = GridSize { h: cells, w: cells };
        let mut hog = Hog::with_colornames(cell, false, p.colornames);
        hog.set_input_planes(planes);
        let channels = hog.channels();
        let d = grid.len() * channels;
        let ratio = m as f32 / n as f32;
        let sample_factors = exponents(n, ratio).map(|e| p.step.powf(e)).collect();
        // Interpolated scales and the label in circularly shifted order (index 0 = no
        // change), as fDSST: the zero-padded DFT keeps index 0 fixed.
        let shifted = |len: usize, s: f32| {
            let e: Vec<f32> = exponents(len, s).collect();
            (0..len).map(move |j| e[(j + len / 2) % len])
        };
        let interp_factors = shifted(m, 1.0).map(|e| p.step.powf(e)).collect();
        // Label: Gaussian over the scale exponent (in interpolated steps).
        let sigma = m as f32 * p.sigma_factor;
        let mut planner = FftPlanner::<f32>::new();
        let fft_n = planner.plan_fft_forward(n);
        let ifft_m = planner.plan_fft_inverse(m);
        let mut ysf: Vec<Complex32> = shifted(n, ratio)
            .map(|e| Complex32::new((-0.5 * e * e / (sigma * sigma)).exp(), 0.0))
            .collect();
        let scratch_len = fft_n
            .get_inplace_scratch_len()
            .max(ifft_m.get_inplace_scratch_len());
        let mut scratch = vec![Complex32::default(); scratch_len];
        fft_n.process_with_scratch(&mut ysf, &mut scratch);
        Ok(Self {
            n,
            m,
            d,
            lr: p.learning_rate,
            lambda: p.lambda,
            step: p.step,
            cell,
            padding: p.padding,
            sample_factors,
            interp_factors,
            window: hann(n),
            ysf,
            hog,
            patch: Patch::new(cells * cell, planes),
            feat: FeatureMap::new(grid, channels),
            sampler: Sampler::default(),
            xs: vec![0.0; n * d],
            model: vec![0.0; n * d],
            basis: vec![0.0; n * d],
            basis_den: vec![0.0; n * d],
            proj_f: vec![Complex32::default(); n * n],
            num_f: vec![Complex32::default(); n * n],
            den_f: vec![0.0; n],
            resp_f: vec![Complex32::default(); n],
            interp: vec![Complex32::default(); m],
            fft_n,
            ifft_m,
            scratch,
            trained: false,
        })
    }

    /// Scale exponent step: the ratio of neighbouring interpolated scales.
    pub fn interpolated_factors(&self) -> &[f32] {
        &self.interp_factors
    }

    /// Whether [`Self::train`] has run since construction or [`Self::reset`].
    pub fn is_trained(&self) -> bool {
        self.trained
    }

    /// Forgets the model.
    pub fn reset(&mut self) {
        self.trained = false;
    }

    /// Samples the `n` scales around `center`; `size` is the target box in frame pixels at
    /// the current scale (its aspect ratio clamped to [`MAX_SAMPLE_ASPECT`]), stretched onto
    /// the square sample.
    fn sample(&mut self, frame: &Frame<'_>, center: Point2, size: Size2) -> Result<(), TrackError> {
        let out_side = self.patch.side;
        let lo = self.sample_factors.first().copied().unwrap_or(1.0);
        let hi = self.sample_factors.last().copied().unwrap_or(1.0);
        let (w, h) = (
            size.w.max(size.h / MAX_SAMPLE_ASPECT) * self.padding,
            size.h.max(size.w / MAX_SAMPLE_ASPECT) * self.padding,
        );
        self.sampler
            .prepare(frame, center, w.min(h) * lo, w.max(h) * hi, out_side);
        let cell = self.cell;
        for (k, &f) in self.sample_factors.iter().enumerate() {
            self.sampler
                .sample_rect(center, w * f, h * f, &mut self.patch);
            self.hog.extract(&self.patch, cell, &mut self.feat)?;
            self.xs[k * self.d..(k + 1) * self.d].copy_from_slice(&self.feat.data);
        }
        Ok(())
    }

    /// Orthonormal basis (rows) of the `n` scale-major vectors in `src`, by modified
    /// Gram–Schmidt; dependent vectors get a zero row.
    ///
    /// Right-looking: once a row is normalised, its component is removed from every later
    /// row, four rows a [`dot4`]. Each row still loses the components of rows `0, 1, …` in
    /// turn, each measured on the row as it then is, so the basis is that of the left-looking
    /// loop bit for bit (`orthonormalise_is_the_left_looking_loop_bit_for_bit`).
    fn orthonormalise(src: &[f32], d: usize, basis: &mut [f32]) {
        basis.copy_from_slice(src);
        if d == 0 {
            return;
        }
        let n = src.len() / d;
        for j in 0..n {
            let (head, later) = basis[j * d..n * d].split_at_mut(d);
            let norm = dot(head, head).sqrt();
            let inv = if norm > BASIS_EPS { 1.0 / norm } else { 0.0 };
            head.iter_mut().for_each(|x| *x *= inv);
            let q = &*head;
            let remove = |v: &mut [f32], c: f32| {
                for (x, a) in v.iter_mut().zip(q) {
                    *x -= c * a;
                }
            };
            let mut fours = later.chunks_exact_mut(4 * d);
            for group in fours.by_ref() {
                let (v0, r) = group.split_at_mut(d);
                let (v1, r) = r.split_at_mut(d);
                let (v2, v3) = r.split_at_mut(d);
                let c = dot4(q, [v0, v1, v2, v3]);
                for (v, c) in [v0, v1, v2, v3].into_iter().zip(c) {
                    remove(v, c);
                }
            }
            for v in fours.into_remainder().chunks_exact_mut(d) {
                let c = dot(q, v);
                remove(v, c);
            }
        }
    }

    /// `proj_f[i][k] = FFT_k(w_k · ⟨basis_i, src_k⟩)`.
    fn project(&mut self, use_den_basis: bool, src_is_model: bool) {
        let (n, d) = (self.n, self.d);
        let basis = if use_den_basis {
            &self.basis_den
        } else {
            &self.basis
        };
        let src = if src_is_model { &self.model } else { &self.xs };
        let x = |k: usize| &src[k * d..(k + 1) * d];
        for i in 0..n {
            let q = &basis[i * d..(i + 1) * d];
            let row = &mut self.proj_f[i * n..(i + 1) * n];
            // Four scales a [`dot4`] (the same bits as one at a time), the rest one by one.
            let fours = n - n % 4;
            for k in (0..fours).step_by(4) {
                let p = dot4(q, [x(k), x(k + 1), x(k + 2), x(k + 3)]);
                for (j, p) in p.into_iter().enumerate() {
                    row[k + j] = Complex32::new(p * self.window[k + j], 0.0);
                }
            }
            for k in fours..n {
                row[k] = Complex32::new(dot(q, x(k)) * self.window[k], 0.0);
            }
            self.fft_n.process_with_scratch(row, &mut self.scratch);
        }
    }

    /// Scale change at `center` for a target of `size` frame pixels at the current scale
    /// (multiply the current scale by it); 1 before training.
    ///
    /// # Errors
    /// [`TrackError::Feature`] if feature extraction fails.
    pub fn estimate(
        &mut self,
        frame: &Frame<'_>,
        center: Point2,
        size: Size2,
    ) -> Result<f32, TrackError> {
        if !self.trained {
            return Ok(1.0);
        }
        self.sample(frame, center, size)?;
        self.project(false, false);
        let n = self.n;
        for k in 0..n {
            let mut acc = Complex32::default();
            for i in 0..n {
                acc += self.num_f[i * n + k] * self.proj_f[i * n + k];
            }
            self.resp_f[k] = acc / (self.den_f[k] + self.lambda);
        }
        // Zero-pad the spectrum from n to m frequencies (fDSST resizeDFT): the first
        // ⌈n/2⌉ and the last ⌊(n−1)/2⌋ coefficients, scaled by m/n.
        let m = self.m;
        let scaling = m as f32 / n as f32;
        let head = n.div_ceil(2);
        let tail = (n - 1) / 2;
        self.interp
            .iter_mut()
            .for_each(|v| *v = Complex32::default());
        for k in 0..head {
            self.interp[k] = self.resp_f[k] * scaling;
        }
        for k in 0..tail {
            self.interp[m - tail + k] = self.resp_f[n - tail + k] * scaling;
        }
        self.ifft_m
            .process_with_scratch(&mut self.interp, &mut self.scratch);
        // Peak of the real response; index 0 is "no change".
        let (best, _) =
            self.interp
                .iter()
                .enumerate()
                .fold((0, f32::NEG_INFINITY), |acc, (j, v)| {
                    if v.re > acc.1 {
                        (j, v.re)
                    } else {
                        acc
                    }
                });
        // Sub-step refinement: the vertex of the parabola through the peak and its two
        // neighbours (the interpolated grid is 2 % coarse; a steady 2.4 %/frame change
        // would otherwise lag by the rounding every frame).
        let at = |j: usize| self.interp[j % m].re;
        let (a, b, c) = (at(best + m - 1), at(best), at(best + 1));
        let den = a - 2.0 * b + c;
        // At the far end of the range the neighbour wraps to the other end: no refinement.
        let edge = best == m / 2 || best == m / 2 + 1;
        let offset = if den < 0.0 && !edge {
            (0.5 * (a - c) / den).clamp(-0.5, 0.5)
        } else {
            0.0
        };
        Ok(self.interp_factors[best] * self.step.powf(offset))
    }

    /// Updates the scale model with samples at `center` and `size` (as
    /// [`Self::estimate`]); the first call initialises it.
    ///
    /// # Errors
    /// [`TrackError::Feature`] if feature extraction fails.
    pub fn train(
        &mut self,
        frame: &Frame<'_>,
        center: Point2,
        size: Size2,
    ) -> Result<(), TrackError> {
        self.sample(frame, center, size)?;
        let (n, d) = (self.n, self.d);
        if self.trained {
            let lr = self.lr;
            for (u, x) in self.model.iter_mut().zip(&self.xs) {
                *u = (1.0 - lr) * *u + lr * x;
            }
        } else {
            self.model.copy_from_slice(&self.xs);
        }
        Self::orthonormalise(&self.model, d, &mut self.basis);
        Self::orthonormalise(&self.xs, d, &mut self.basis_den);
        // Numerator from the compressed model.
        self.project(false, true);
        for i in 0..n {
            for k in 0..n {
                self.num_f[i * n + k] = self.ysf[k] * self.proj_f[i * n + k].conj();
            }
        }
        // Denominator from the compressed new sample.
        self.project(true, false);
        for k in 0..n {
            let e: f32 = (0..n).map(|i| self.proj_f[i * n + k].norm_sqr()).sum();
            self.den_f[k] = if self.trained {
                (1.0 - self.lr) * self.den_f[k] + self.lr * e
            } else {
                e
            };
        }
        self.trained = true;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::synth::SynthParams;
    use crate::image::PixelFormat;

    fn params() -> ScaleFilterConfig {
        ScaleFilterConfig {
            scales: 17,
            interpolated_scales: 33,
            step: 1.02,
            learning_rate: 0.025,
            sigma_factor: 1.0 / 16.0,
            lambda: 0.01,
            sample_side: 24,
            cell_size: 4,
            padding: 1.0,
            colornames: false,
        }
    }

    #[test]
    fn basis_is_orthonormal() {
        let (n, d) = (5, 40);
        let src: Vec<f32> = (0..n * d)
            .map(|i| ((i * 7919) % 97) as f32 / 97.0)
            .collect();
        let mut b = vec![0.0; n * d];
        ScaleFilter::orthonormalise(&src, d, &mut b);
        for i in 0..n {
            for j in 0..n {
                let dot: f32 = (0..d).map(|t| b[i * d + t] * b[j * d + t]).sum();
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((dot - want).abs() < 1e-4, "{i} {j} {dot}");
            }
        }
    }

    /// Values of many magnitudes and both signs, so that any change in the order of the
    /// additions shows in the last bits.
    fn awkward(len: usize, seed: u64) -> Vec<f32> {
        let mut s = seed;
        (0..len)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let m = ((s >> 40) as f32 / (1u64 << 24) as f32) - 0.5;
                m * 2f32.powi(((s >> 20) % 24) as i32 - 12)
            })
            .collect()
    }

    #[test]
    fn dot4_is_four_dots_bit_for_bit() {
        // Lengths with and without a tail after the 8-lane chunks, and shorter than a chunk.
        for len in [0, 3, 8, 13, 64, 1476, 1477] {
            let q = awkward(len, 1);
            let xs: Vec<Vec<f32>> = (2..6).map(|s| awkward(len, s)).collect();
            let x4 = [&xs[0][..], &xs[1], &xs[2], &xs[3]];
            let got = dot4(&q, x4);
            for (g, x) in got.iter().zip(&xs) {
                assert_eq!(g.to_bits(), dot(&q, x).to_bits(), "length {len}");
            }
            // The path for CPUs without AVX2 sums the same lanes.
            let m = len - len % LANES;
            let chunks = x4.map(|x| &x[..m]);
            let bits = |a: [[f32; LANES]; 4]| a.map(|l| l.map(f32::to_bits));
            let (simd, arrays) = (
                dot4_lanes(&q[..m], chunks),
                lanes_as_arrays(&q[..m], chunks),
            );
            assert_eq!(bits(simd), bits(arrays), "length {len}");
        }
    }

    #[test]
    fn orthonormalise_is_the_left_looking_loop_bit_for_bit() {
        // The loop before the rows went four at a time: each row against the finished rows
        // before it, then normalised.
        fn left_looking(src: &[f32], d: usize, basis: &mut [f32]) {
            basis.copy_from_slice(src);
            for j in 0..src.len() / d {
                let (done, rest) = basis.split_at_mut(j * d);
                let v = &mut rest[..d];
                for q in done.chunks_exact(d) {
                    let c = dot(q, v);
                    for (x, a) in v.iter_mut().zip(q) {
                        *x -= c * a;
                    }
                }
                let norm = dot(v, v).sqrt();
                let inv = if norm > BASIS_EPS { 1.0 / norm } else { 0.0 };
                v.iter_mut().for_each(|x| *x *= inv);
            }
        }
        // 17 rows (the default; 4 groups of 4 and one left), 1 to 9 rows, a dependent row.
        for (n, d) in [(17, 1476), (17, 37), (1, 20), (5, 13), (8, 40), (9, 7)] {
            let mut src = awkward(n * d, (n * d) as u64);
            if n > 3 {
                // Row 3 repeats row 1: a zero row in both.
                let (a, b) = src.split_at_mut(3 * d);
                b[..d].copy_from_slice(&a[d..2 * d]);
            }
            let (mut want, mut got) = (vec![0.0; n * d], vec![0.0; n * d]);
            left_looking(&src, d, &mut want);
            ScaleFilter::orthonormalise(&src, d, &mut got);
            let same = want
                .iter()
                .zip(&got)
                .all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(same, "{n} rows of {d}");
        }
    }

    #[test]
    fn unchanged_target_gives_no_scale_change() {
        let seq = SynthParams {
            width: 320,
            height: 240,
            scale_rate: 1.0,
            ..SynthParams::default()
        };
        let f = seq.frame(0);
        let frame = Frame::packed(&f.rgb, seq.width, seq.height, PixelFormat::Rgb8).unwrap();
        let mut sf = ScaleFilter::new(&params(), 3).unwrap();
        let c = f.truth.center();
        let size = f.truth.size();
        assert_eq!(sf.estimate(&frame, c, size).unwrap(), 1.0);
        sf.train(&frame, c, size).unwrap();
        let s = sf.estimate(&frame, c, size).unwrap();
        assert!((s - 1.0).abs() < 2e-3, "{s}");
    }

    /// Final scale estimate and truth after a ×2 change over 30 frames (frame 0 → 29), the
    /// position given, the scale left to the filter.
    fn track_doubling(p: &ScaleFilterConfig) -> (f32, f32) {
        let frames = 30;
        let seq = SynthParams {
            width: 480,
            height: 360,
            frames,
            target: (40.0, 32.0),
            scale_rate: 2f32.powf(1.0 / (frames - 1) as f32),
            path_amplitude: (30.0, 20.0),
            ..SynthParams::default()
        };
        let mut sf = ScaleFilter::new(p, 3).unwrap();
        let size0 = seq.frame(0).truth.size();
        let at = |s: f32| Size2 {
            w: size0.w * s,
            h: size0.h * s,
        };
        let mut scale = 1.0f32;
        for t in 0..frames {
            let f = seq.frame(t);
            let frame = Frame::packed(&f.rgb, seq.width, seq.height, PixelFormat::Rgb8).unwrap();
            let c = f.truth.center();
            scale *= sf.estimate(&frame, c, at(scale)).unwrap();
            sf.train(&frame, c, at(scale)).unwrap();
        }
        let truth = seq.truth(frames - 1).w / seq.target.0;
        assert!((truth - 2.0).abs() < 1e-3);
        (scale, truth)
    }

    #[test]
    fn recovers_a_doubling_of_scale_over_30_frames() {
        let (scale, truth) = track_doubling(&params());
        let err = (scale / truth - 1.0).abs();
        assert!(err < 0.03, "estimated ×{scale}, true ×{truth}");
    }

    #[test]
    fn recovers_a_doubling_with_colour_names_in_the_samples() {
        let p = ScaleFilterConfig {
            colornames: true,
            ..params()
        };
        let (scale, truth) = track_doubling(&p);
        let err = (scale / truth - 1.0).abs();
        assert!(err < 0.03, "estimated ×{scale}, true ×{truth}");
    }

    #[test]
    fn colour_names_add_ten_channels_per_cell_on_colour_frames_only() {
        let p = ScaleFilterConfig {
            colornames: true,
            ..params()
        };
        let cells = (p.sample_side / p.cell_size).pow(2);
        assert_eq!(ScaleFilter::new(&params(), 3).unwrap().d, cells * 31);
        assert_eq!(ScaleFilter::new(&p, 3).unwrap().d, cells * 41);
        // mono8: no colour, the group is left out.
        assert_eq!(ScaleFilter::new(&p, 1).unwrap().d, cells * 31);
    }

    #[test]
    fn too_small_sample_is_an_error() {
        let p = ScaleFilterConfig {
            sample_side: 4,
            ..params()
        };
        assert!(ScaleFilter::new(&p, 3).is_err());
    }
}
