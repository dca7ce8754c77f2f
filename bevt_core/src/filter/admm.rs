//! Enhanced background learning: the ADMM solver of ALGORITHM.md §4.
//!
//! Minimises `½‖y − Σ_d (B x_d) ⋆ w_d‖² + Σ_d ‖p ⊙ w_d‖²` by splitting the filter into a
//! frequency-domain variable `ĝ` (closed-form Sherman–Morrison solve per frequency bin, no
//! D×D inverse) and a spatial variable `h` that carries the penalty and the crop `B` to
//! the target-sized support. The learned filter is `ĝ`.
//!
//! Optional temporal regularisation (STRCF, Li et al. CVPR 2018; AutoTrack, Li et al. CVPR
//! 2020): `+ θ/2 Σ_d ‖ĝ_d − ĝ_prev,d‖²` (in the units of μ, as theirs), `ĝ_prev` the filter
//! the previous training produced. It only changes the `ĝ` subproblem: `μ` becomes `μ + θ`
//! and `ĥ` becomes `(μĥ + θĝ_prev)/(μ + θ)`. The first training of a track has no previous
//! filter and no temporal term.
//!
//! All spectra are half spectra in the layout of [`crate::fft`]; `T = H·W`.

use crate::config::AdmmConfig;
use crate::fft::Fft2;
use crate::geometry::GridSize;
use nalgebra::DMatrix;
use rustfft::num_complex::{Complex32, Complex64};
use serde::{Deserialize, Serialize};

/// How the spatial penalty enters the `h`-subproblem.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PenaltyKind {
    /// Reference MATLAB: `h = inv(2RᵀR/T + μI) · IFFT2(μĝ + l̂)`, `R` the penalty window
    /// taken as a matrix (the paper's stated simplification).
    Matrix,
    /// A diagonal spatial penalty (eq. 8 with `p` diagonal) at magnitude κ
    /// ([`AdmmConfig::spatial_weight`]): `h = IFFT2(μĝ + l̂) / (κp² + μ)`. The literal
    /// eq. 8 is κ = 2/T, which cannot act against μ ≥ 1 (2p²/T ≤ 1.25e-3 on the support).
    Elementwise,
    /// Plain BACF: `h = T/(μT + λ) · IFFT2(μĝ + l̂)`.
    None,
}

/// The filter support: rows `r0..r1`, columns `c0..c1` of the grid (the `Bᵀ` crop).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CropBox {
    /// First row.
    pub r0: usize,
    /// One past the last row.
    pub r1: usize,
    /// First column.
    pub c0: usize,
    /// One past the last column.
    pub c1: usize,
}

impl CropBox {
    /// The `small.h × small.w` box centred at `(⌊H/2⌋, ⌊W/2⌋)`: rows start at
    /// `⌊H/2⌋ − ⌊small.h/2⌋`, as the reference's `get_subwindow_no_window`.
    pub fn centred(grid: GridSize, small: GridSize) -> Self {
        let bh = small.h.clamp(1, grid.h);
        let bw = small.w.clamp(1, grid.w);
        let r0 = (grid.h / 2).saturating_sub(bh / 2).min(grid.h - bh);
        let c0 = (grid.w / 2).saturating_sub(bw / 2).min(grid.w - bw);
        Self {
            r0,
            r1: r0 + bh,
            c0,
            c1: c0 + bw,
        }
    }
}

/// The solver takes its parameters straight from the `admm` section (the penalty window
/// keys shape the window the caller builds, not the solver).
impl AdmmConfig {
    /// The μ used in each iteration: `μ₀ = mu_init`, `μ_{i+1} = min(β·μ_i, μ_max)`.
    pub fn mu_schedule(&self) -> Vec<f32> {
        let mut mu = self.mu_init;
        (0..self.iterations)
            .map(|_| {
                let m = mu;
                mu = (self.beta * mu).min(self.mu_max);
                m
            })
            .collect()
    }
}

#[derive(Debug, Clone)]
enum PenaltyData {
    /// Rows `r0..r1` of each iteration's `P_i` (`(r1 − r0) × H`, row-major).
    Matrix(Vec<Vec<f32>>),
    /// `1 / (2p²/T + μ_i)` on the crop box, per iteration (box row-major).
    Elementwise(Vec<Vec<f32>>),
    /// `T / (μ_i T + λ)` per iteration.
    Scalar(Vec<f32>),
}

/// ADMM trainer for one feature layer; owns all its buffers.
#[derive(Debug, Clone)]
pub struct AdmmSolver {
    grid: GridSize,
    bins: usize,
    channels: usize,
    mus: Vec<f32>,
    penalty: PenaltyData,
    crop: CropBox,
    h_f: Vec<Complex32>,
    l_f: Vec<Complex32>,
    s_xx: Vec<f64>,
    s_lx: Vec<Complex64>,
    s_hx: Vec<Complex64>,
    coef: Vec<Complex32>,
    tmp_f: Vec<Complex32>,
    spat: Vec<f32>,
    spat2: Vec<f32>,
    temporal: f32,
    /// The previous training's filter, when `temporal > 0` (empty otherwise).
    g_prev: Vec<Complex32>,
    /// `(μĥ + θĝ_prev)/(μ + θ)`: what the `ĝ` step pulls towards.
    pull: Vec<Complex32>,
    /// A previous filter exists (the track has been trained before).
    primed: bool,
}

impl AdmmSolver {
    /// Prepares a solver for `channels` channels on `grid`, with penalty window `reg`
    /// (row-major, `grid` sized) and filter support `crop`. The `matrix` penalty needs a
    /// square grid; on a non-square grid it falls back to `elementwise`.
    pub fn new(
        grid: GridSize,
        bins: usize,
        channels: usize,
        params: &AdmmConfig,
        reg: &[f32],
        crop: CropBox,
    ) -> Self {
        let t = grid.len() as f64;
        let mus = params.mu_schedule();
        let penalty = match params.penalty {
            PenaltyKind::Matrix if grid.h == grid.w => {
                let n = grid.h;
                let r = DMatrix::<f64>::from_fn(n, n, |i, j| reg[i * n + j] as f64);
                let rtr = r.transpose() * &r * (2.0 / t);
                PenaltyData::Matrix(
                    mus.iter()
                        .map(|&mu| {
                            let a = &rtr + DMatrix::<f64>::identity(n, n) * mu as f64;
                            // 2RᵀR/T + μI is symmetric positive definite for μ > 0.
                            let p = a
                                .cholesky()
                                .map(|c| c.inverse())
                                .unwrap_or_else(|| DMatrix::identity(n, n) / mu as f64);
                            let mut rows = Vec::with_capacity((crop.r1 - crop.r0) * n);
                            for i in crop.r0..crop.r1 {
                                rows.extend((0..n).map(|k| p[(i, k)] as f32));
                            }
                            rows
                        })
                        .collect(),
                )
            }
            PenaltyKind::Matrix | PenaltyKind::Elementwise => {
                // The matrix form on a non-square grid falls back to the literal eq. 8.
                let kappa = if params.penalty == PenaltyKind::Elementwise {
                    params.spatial_weight as f64
                } else {
                    2.0 / t
                };
                PenaltyData::Elementwise(
                    mus.iter()
                        .map(|&mu| {
                            let mut v =
                                Vec::with_capacity((crop.r1 - crop.r0) * (crop.c1 - crop.c0));
                            for r in crop.r0..crop.r1 {
                                for c in crop.c0..crop.c1 {
                                    let p = reg[r * grid.w + c] as f64;
                                    v.push((1.0 / (kappa * p * p + mu as f64)) as f32);
                                }
                            }
                            v
                        })
                        .collect(),
                )
            }
            PenaltyKind::None => PenaltyData::Scalar(
                mus.iter()
                    .map(|&mu| (t / (mu as f64 * t + params.lambda as f64)) as f32)
                    .collect(),
            ),
        };
        let n = channels * bins;
        Self {
            grid,
            bins,
            channels,
            mus,
            penalty,
            crop,
            h_f: vec![Complex32::default(); n],
            l_f: vec![Complex32::default(); n],
            s_xx: vec![0.0; bins],
            s_lx: vec![Complex64::default(); bins],
            s_hx: vec![Complex64::default(); bins],
            coef: vec![Complex32::default(); bins],
            tmp_f: vec![Complex32::default(); bins],
            spat: vec![0.0; grid.len()],
            spat2: vec![0.0; grid.len()],
            temporal: params.temporal,
            g_prev: if params.temporal > 0.0 {
                vec![Complex32::default(); n]
            } else {
                Vec::new()
            },
            pull: if params.temporal > 0.0 {
                vec![Complex32::default(); n]
            } else {
                Vec::new()
            },
            primed: false,
        }
    }

    /// The filter support.
    pub fn crop(&self) -> CropBox {
        self.crop
    }

    /// Trains a filter `g_f` (`channels × bins`) on the appearance model `xf` and label `yf`.
    /// Starts from `ĝ = ĥ = l̂ = 0`, as the reference does every frame. With a temporal
    /// weight, the filter `g_f` holds on entry (the previous training's, or one the caller
    /// restored) is the `ĝ_prev` it is pulled towards.
    pub fn train(
        &mut self,
        fft: &mut Fft2,
        xf: &[Complex32],
        yf: &[Complex32],
        g_f: &mut [Complex32],
    ) {
        self.train_iterations(fft, xf, yf, g_f, self.mus.len());
    }

    /// [`Self::train`] stopped after `iterations` g-updates (for tests and ablations).
    ///
    /// Each iteration sums over the channels once (`g_coef`); everything after that
    /// is per channel and runs a channel at a time: its ĝ-update, then (unless this is the
    /// last iteration) its h-step and its l-update `l̂ += (ĝ − ĥ)μ`. A channel's three
    /// updates read only that channel's ĝ, ĥ, l̂ and the per-bin coefficient, so running
    /// them channel by channel instead of each over all channels does the same operations
    /// on the same values; the channel's spectra stay in L1/L2 between them instead of
    /// being streamed from memory once per update (3 × 437 KB at 42 channels).
    pub fn train_iterations(
        &mut self,
        fft: &mut Fft2,
        xf: &[Complex32],
        yf: &[Complex32],
        g_f: &mut [Complex32],
        iterations: usize,
    ) {
        let (bins, d) = (self.bins, self.channels);
        let t = self.grid.len() as f32;
        let theta = if self.temporal > 0.0 && self.primed {
            self.g_prev.copy_from_slice(g_f);
            self.temporal
        } else {
            0.0
        };
        self.primed = true;
        let iterations = iterations.min(self.mus.len());
        // The iterations start from ĥ = l̂ = 0. Only what is read before it is written is
        // cleared (three full spectra were 1.9 MB of stores a frame at 42 channels on a 60 × 60
        // grid). Without the temporal term the first iteration takes both zeros as constants:
        // its g-step as `g_update_first`, its h-step and l-update as `+ 0` (the same
        // operations on a +0 as reading a cleared l̂); the h-step then writes ĥ whole and
        // the l-update l̂ whole. The temporal path's first g-step sums over l̂ and its pull
        // reads ĥ, so there both are cleared. ĝ is written whole by the first g-step.
        if theta > 0.0 {
            self.l_f.iter_mut().for_each(|v| *v = Complex32::default());
            self.h_f.iter_mut().for_each(|v| *v = Complex32::default());
        }
        if iterations == 0 {
            g_f.iter_mut().for_each(|v| *v = Complex32::default());
        }
        self.s_xx.iter_mut().for_each(|v| *v = 0.0);
        for x in xf.chunks_exact(bins).take(d) {
            for (s, v) in self.s_xx.iter_mut().zip(x) {
                *s += f64::from(v.norm_sqr());
            }
        }
        for it in 0..iterations {
            let mu = self.mus[it];
            // l̂ and ĥ are still the zeros they start from (constants, not read).
            let first = theta == 0.0 && it == 0;
            let m = if theta > 0.0 {
                // ĝ step with μ + θ, pulled towards (μĥ + θĝ_prev)/(μ + θ): the pull is
                // complete before the first h-step below overwrites a channel of ĥ.
                let m = mu + theta;
                for ((p, h), g) in self.pull.iter_mut().zip(&self.h_f).zip(&self.g_prev) {
                    *p = (h * mu + g * theta) / m;
                }
                m
            } else {
                mu
            };
            self.g_coef(xf, yf, m, t, first, theta > 0.0);
            let inv_m = 1.0 / m;
            // The final h- and l-updates cannot change the returned ĝ: skip them.
            let update = it + 1 < iterations;
            for ch in 0..d {
                let o = ch * bins;
                let (g, x) = (&mut g_f[o..o + bins], &xf[o..o + bins]);
                if first {
                    g_update_first(g, x, &self.coef, inv_m);
                } else {
                    let h = if theta > 0.0 { &self.pull } else { &self.h_f };
                    g_update(
                        g,
                        x,
                        &self.l_f[o..o + bins],
                        &h[o..o + bins],
                        &self.coef,
                        inv_m,
                    );
                }
                if update {
                    self.h_step(fft, g, ch, it, mu, first);
                }
            }
        }
    }

    /// Channel sums and per-bin coefficient of the closed-form `ĝ` subproblem
    /// `(x̂x̂ᴴ/T + μI)ĝ = ŷx̂/T − l̂ + μĥ` (ĥ the pull with the temporal term), for
    /// [`g_update`].
    ///
    /// Sherman–Morrison gives `ĝ = ŷx̂/(Tμ) − l̂/μ + ĥ − x̂(S_xx ŷ/(Tμ) − S_lx/μ + S_hx)/b`
    /// with `b = S_xx + Tμ`; its two `ŷ` terms cancel to `ŷx̂/b`, which in `f32` loses about
    /// `6e-8 · S_xx/(Tμ)` relative accuracy (0.12 at a ratio of 1e6, reached by CNN
    /// activations). The algebraically identical form used here has no cancelling terms:
    ///
    /// `ĝ = x̂ · (ŷ + S_lx/μ − S_hx) / b − l̂/μ + ĥ`,
    ///
    /// with the channel sums `S_·` and the per-bin coefficient computed in `f64`.
    fn g_coef(
        &mut self,
        xf: &[Complex32],
        yf: &[Complex32],
        mu: f32,
        t: f32,
        lh_zero: bool,
        pulled: bool,
    ) {
        let bins = self.bins;
        if lh_zero {
            // Sums of products with ĥ = l̂ = 0: exactly zero (the accumulators stay +0).
            self.s_lx.iter_mut().for_each(|v| *v = Complex64::default());
            self.s_hx.iter_mut().for_each(|v| *v = Complex64::default());
        } else {
            channel_sums(
                xf,
                &self.l_f,
                if pulled { &self.pull } else { &self.h_f },
                bins,
                self.channels,
                &mut self.s_lx,
                &mut self.s_hx,
            );
        }
        let mu64 = f64::from(mu);
        let tmu = f64::from(t) * mu64;
        for k in 0..bins {
            let b = self.s_xx[k] + tmu;
            let c = (c64(yf[k]) + self.s_lx[k] / mu64 - self.s_hx[k]) / b;
            self.coef[k] = Complex32::new(c.re as f32, c.im as f32);
        }
    }

    /// Channel `ch`'s spatial penalty solve, crop to the support, back to the frequency
    /// domain into its ĥ, then its l-update `l̂ += (ĝ − ĥ)μ` (`g` is its fresh ĝ). With
    /// `l_zero` its l̂ is not read but taken as the constant +0 it would have been cleared to.
    fn h_step(
        &mut self,
        fft: &mut Fft2,
        g: &[Complex32],
        ch: usize,
        it: usize,
        mu: f32,
        l_zero: bool,
    ) {
        let bins = self.bins;
        let w = self.grid.w;
        let CropBox { r0, r1, c0, c1 } = self.crop;
        let zero = Complex32::default();
        let o = ch * bins;
        {
            let l = &self.l_f[o..o + bins];
            if l_zero {
                for (t, g) in self.tmp_f.iter_mut().zip(g) {
                    *t = g * mu + zero;
                }
            } else {
                for ((t, g), l) in self.tmp_f.iter_mut().zip(g).zip(l) {
                    *t = g * mu + l;
                }
            }
        }
        // Only the box `r0..r1 × c0..c1` of `spat2` is ever written (the rest stays
        // zero from construction) and only its rows are transformed back.
        match &self.penalty {
            PenaltyData::Matrix(ps) => {
                for r in r0..r1 {
                    self.spat2[r * w + c0..r * w + c1]
                        .iter_mut()
                        .for_each(|v| *v = 0.0);
                }
                let h = self.grid.h;
                fft.inverse(&self.tmp_f, &mut self.spat);
                let p = &ps[it];
                for r in r0..r1 {
                    let prow = &p[(r - r0) * h..(r - r0 + 1) * h];
                    let (head, tail) = self.spat2.split_at_mut(r * w);
                    let _ = head;
                    let out = &mut tail[c0..c1];
                    for (k, &pk) in prow.iter().enumerate() {
                        let src = &self.spat[k * w + c0..k * w + c1];
                        for (o, s) in out.iter_mut().zip(src) {
                            *o += pk * s;
                        }
                    }
                }
            }
            PenaltyData::Elementwise(ws) => {
                fft.inverse_rows(&self.tmp_f, r0, r1, &mut self.spat);
                let bw = c1 - c0;
                let wv = &ws[it];
                for r in r0..r1 {
                    for c in c0..c1 {
                        self.spat2[r * w + c] = self.spat[r * w + c] * wv[(r - r0) * bw + c - c0];
                    }
                }
            }
            PenaltyData::Scalar(s) => {
                fft.inverse_rows(&self.tmp_f, r0, r1, &mut self.spat);
                let s = s[it];
                for r in r0..r1 {
                    for c in c0..c1 {
                        self.spat2[r * w + c] = self.spat[r * w + c] * s;
                    }
                }
            }
        }
        let h = &mut self.h_f[o..o + bins];
        fft.forward_rows(&self.spat2, r0, r1, h);
        let l = &mut self.l_f[o..o + bins];
        if l_zero {
            for ((l, g), h) in l.iter_mut().zip(g).zip(&*h) {
                *l = zero + (g - h) * mu;
            }
        } else {
            for ((l, g), h) in l.iter_mut().zip(g).zip(&*h) {
                *l += (g - h) * mu;
            }
        }
    }
}

/// Bins per block of [`channel_sums`]: the block's sums stay in a few KiB of stack.
const SUM_BLOCK: usize = 64;

/// `ĝ = x̂ · coef − l̂ · inv_mu + ĥ`, channel by channel (`coef` per bin): the last line of
/// [`AdmmSolver::g_coef`]'s closed form.
#[multiversion::multiversion(targets("x86_64+avx2+fma"))] // AVX2 + FMA clone, chosen at run time
fn g_update(
    g_f: &mut [Complex32],
    xf: &[Complex32],
    l_f: &[Complex32],
    h_f: &[Complex32],
    coef: &[Complex32],
    inv_mu: f32,
) {
    let bins = coef.len();
    for (((g, x), l), h) in g_f
        .chunks_exact_mut(bins)
        .zip(xf.chunks_exact(bins))
        .zip(l_f.chunks_exact(bins))
        .zip(h_f.chunks_exact(bins))
    {
        for k in 0..bins {
            g[k] = x[k] * coef[k] - l[k] * inv_mu + h[k];
        }
    }
}

/// [`g_update`] with `l̂ = ĥ = 0` as constants (the first g-step), without reading the two
/// spectra: `x̂ · coef − 0 · inv_mu + 0`, the same operations on the same values, so the same
/// bits (the last `+ 0` turns a −0 into +0 as adding a zero ĥ did).
#[multiversion::multiversion(targets("x86_64+avx2+fma"))] // AVX2 + FMA clone, chosen at run time
fn g_update_first(g_f: &mut [Complex32], xf: &[Complex32], coef: &[Complex32], inv_mu: f32) {
    let bins = coef.len();
    let zero = Complex32::default();
    for (g, x) in g_f.chunks_exact_mut(bins).zip(xf.chunks_exact(bins)) {
        for k in 0..bins {
            g[k] = x[k] * coef[k] - zero * inv_mu + zero;
        }
    }
}

/// `S_lx = Σ_d conj(x̂_d) l̂_d` and `S_hx = Σ_d conj(x̂_d) ĥ_d` per bin, in `f64`, summed
/// over the channels in order (`d = 0, 1, …`) exactly as `Complex64` arithmetic does, but a
/// block of bins at a time in split real/imaginary accumulators so the loop vectorises.
#[multiversion::multiversion(targets("x86_64+avx2+fma"))] // AVX2 + FMA clone, chosen at run time
fn channel_sums(
    xf: &[Complex32],
    l_f: &[Complex32],
    h_f: &[Complex32],
    bins: usize,
    channels: usize,
    s_lx: &mut [Complex64],
    s_hx: &mut [Complex64],
) {
    let mut k0 = 0;
    while k0 < bins {
        let n = SUM_BLOCK.min(bins - k0);
        let mut lr = [0.0f64; SUM_BLOCK];
        let mut li = [0.0f64; SUM_BLOCK];
        let mut hr = [0.0f64; SUM_BLOCK];
        let mut hi = [0.0f64; SUM_BLOCK];
        for ch in 0..channels {
            let o = ch * bins + k0;
            let (x, l, h) = (&xf[o..o + n], &l_f[o..o + n], &h_f[o..o + n]);
            for j in 0..n {
                // conj(x)·v with conj(x) = (a, b), b = −Im x: (a·vr − b·vi, a·vi + b·vr),
                // the operation order of `Complex64`'s product.
                let (a, b) = (f64::from(x[j].re), -f64::from(x[j].im));
                let (vr, vi) = (f64::from(l[j].re), f64::from(l[j].im));
                lr[j] += a * vr - b * vi;
                li[j] += a * vi + b * vr;
                let (vr, vi) = (f64::from(h[j].re), f64::from(h[j].im));
                hr[j] += a * vr - b * vi;
                hi[j] += a * vi + b * vr;
            }
        }
        for j in 0..n {
            s_lx[k0 + j] = Complex64::new(lr[j], li[j]);
            s_hx[k0 + j] = Complex64::new(hr[j], hi[j]);
        }
        k0 += n;
    }
}

/// Widens a single-precision complex value.
fn c64(v: Complex32) -> Complex64 {
    Complex64::new(f64::from(v.re), f64::from(v.im))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::label::{gaussian_label, reg_window};
    use crate::geometry::Size2;
    use nalgebra::Complex;

    fn lcg(seed: &mut u64) -> f32 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*seed >> 33) as f32 / (1u64 << 31) as f32) - 0.5
    }

    /// `ĝ` of one bin solved directly in `f64`: `(x xᴴ/T + μI) g = ŷ x/T − l + μ h`.
    fn direct_solve(
        x: &[Complex32],
        y: Complex32,
        l: &[Complex32],
        h: &[Complex32],
        mu: f64,
        t: f64,
    ) -> Vec<Complex<f64>> {
        let d = x.len();
        let x: Vec<Complex<f64>> = x.iter().map(|v| c64(*v)).collect();
        let a = DMatrix::<Complex<f64>>::from_fn(d, d, |i, j| {
            x[i] * x[j].conj() / t
                + if i == j {
                    Complex::new(mu, 0.0)
                } else {
                    Complex::new(0.0, 0.0)
                }
        });
        let y = c64(y);
        let rhs = nalgebra::DVector::<Complex<f64>>::from_fn(d, |i, _| {
            y * x[i] / t - c64(l[i]) + c64(h[i]) * mu
        });
        let sol = a.lu().solve(&rhs).unwrap();
        sol.iter().copied().collect()
    }

    /// Runs one g-step on random spectra whose `S_xx/(Tμ)` is about `ratio`, and returns the
    /// largest per-bin error against [`direct_solve`], relative to `‖g‖ + ‖l‖/μ + ‖h‖`.
    fn g_step_error(seed: u64, ratio: f64, with_lh: bool) -> f64 {
        let (d, bins, t, mu) = (5usize, 7usize, 36.0f32, 3.0f32);
        let mut s = seed;
        let mut c = || Complex32::new(lcg(&mut s), lcg(&mut s));
        let mut xf: Vec<Complex32> = (0..d * bins).map(|_| c()).collect();
        let yf: Vec<Complex32> = (0..bins).map(|_| c()).collect();
        let lh_scale = if with_lh { 1.0 } else { 0.0 };
        let lf: Vec<Complex32> = (0..d * bins).map(|_| c() * lh_scale).collect();
        let hf: Vec<Complex32> = (0..d * bins).map(|_| c() * lh_scale).collect();
        // Scale every bin's x so that S_xx / (Tμ) = ratio exactly (in f64).
        for k in 0..bins {
            let sxx: f64 = (0..d).map(|j| f64::from(xf[j * bins + k].norm_sqr())).sum();
            let f = (ratio * f64::from(t * mu) / sxx).sqrt() as f32;
            for j in 0..d {
                xf[j * bins + k] *= f;
            }
        }
        let grid = GridSize { h: 6, w: 6 };
        let params = AdmmConfig {
            iterations: 1,
            mu_init: mu,
            beta: 10.0,
            mu_max: 1e4,
            lambda: 0.01,
            penalty: PenaltyKind::None,
            spatial_weight: 0.0,
            temporal: 0.0,
            ..AdmmConfig::default()
        };
        let reg = vec![1.0; 36];
        let mut solver =
            AdmmSolver::new(grid, bins, d, &params, &reg, CropBox::centred(grid, grid));
        solver.l_f.copy_from_slice(&lf);
        solver.h_f.copy_from_slice(&hf);
        for (k, s) in solver.s_xx.iter_mut().enumerate() {
            *s = (0..d).map(|j| f64::from(xf[j * bins + k].norm_sqr())).sum();
        }
        let mut g = vec![Complex32::default(); d * bins];
        solver.g_coef(&xf, &yf, mu, t, !with_lh, false);
        if with_lh {
            g_update(&mut g, &xf, &lf, &hf, &solver.coef, 1.0 / mu);
        } else {
            g_update_first(&mut g, &xf, &solver.coef, 1.0 / mu);
        }
        let mut worst = 0.0f64;
        for k in 0..bins {
            let col = |v: &[Complex32]| (0..d).map(|j| v[j * bins + k]).collect::<Vec<_>>();
            let (x, l, h) = (col(&xf), col(&lf), col(&hf));
            let sol = direct_solve(&x, yf[k], &l, &h, f64::from(mu), f64::from(t));
            let norm = |v: &mut dyn Iterator<Item = Complex<f64>>| {
                v.map(|z| z.norm_sqr()).sum::<f64>().sqrt()
            };
            let scale = norm(&mut sol.iter().copied())
                + norm(&mut l.iter().map(|v| c64(*v))) / f64::from(mu)
                + norm(&mut h.iter().map(|v| c64(*v)));
            let err = norm(&mut (0..d).map(|i| c64(g[i * bins + k]) - sol[i]));
            worst = worst.max(err / scale);
        }
        worst
    }

    #[test]
    fn blocked_channel_sums_equal_complex64_sums_bit_for_bit() {
        // 150 bins: two full blocks and a partial one.
        let (d, bins) = (7usize, 150usize);
        let mut seed = 11;
        let mut c = || Complex32::new(lcg(&mut seed) * 3e3, lcg(&mut seed) * 1e-2);
        let xf: Vec<Complex32> = (0..d * bins).map(|_| c()).collect();
        let lf: Vec<Complex32> = (0..d * bins).map(|_| c()).collect();
        let hf: Vec<Complex32> = (0..d * bins).map(|_| c()).collect();
        let mut s_lx = vec![Complex64::new(9.0, 9.0); bins];
        let mut s_hx = s_lx.clone();
        channel_sums(&xf, &lf, &hf, bins, d, &mut s_lx, &mut s_hx);
        for k in 0..bins {
            let (mut wl, mut wh) = (Complex64::default(), Complex64::default());
            for j in 0..d {
                let xc = c64(xf[j * bins + k].conj());
                wl += xc * c64(lf[j * bins + k]);
                wh += xc * c64(hf[j * bins + k]);
            }
            for (got, want) in [(s_lx[k], wl), (s_hx[k], wh)] {
                assert_eq!(got.re.to_bits(), want.re.to_bits(), "bin {k}");
                assert_eq!(got.im.to_bits(), want.im.to_bits(), "bin {k}");
            }
        }
    }

    #[test]
    fn g_step_equals_a_direct_per_bin_solve() {
        assert!(g_step_error(7, 1.0, true) < 1e-6);
    }

    proptest::proptest! {
        /// The regime of CNN activations and large feature gains: the Sherman–Morrison form
        /// with cancelling ŷ terms was off by 0.12 at a ratio of 1e6 in f32.
        #[test]
        fn g_step_stays_accurate_for_s_xx_over_t_mu_from_1_to_1e8(
            exponent in 0.0f64..8.0,
            seed in 1u64..1_000_000,
            with_lh in proptest::bool::ANY,
        ) {
            let err = g_step_error(seed, 10f64.powf(exponent), with_lh);
            proptest::prop_assert!(err < 2e-6, "ratio 1e{exponent}: relative error {err}");
        }
    }

    /// `½‖y − Σ_d x_d ⋆ h_d‖²` (spatial, via Parseval) for a filter that honours the crop,
    /// plus the elementwise penalty `Σ‖p ⊙ h‖²`.
    fn objective(
        fft: &mut Fft2,
        xf: &[Complex32],
        yf: &[Complex32],
        hf: &[Complex32],
        reg: &[f32],
        d: usize,
    ) -> f64 {
        let bins = fft.spectrum_len();
        let grid = fft.grid();
        let mut resp = vec![Complex32::default(); bins];
        for j in 0..d {
            for k in 0..bins {
                resp[k] += hf[j * bins + k].conj() * xf[j * bins + k];
            }
        }
        let mut diff = vec![Complex32::default(); bins];
        for k in 0..bins {
            diff[k] = yf[k] - resp[k];
        }
        let mut e = vec![0.0f32; grid.len()];
        fft.inverse(&diff, &mut e);
        let data: f64 = e.iter().map(|v| (*v as f64).powi(2)).sum::<f64>() * 0.5;
        let mut pen = 0.0f64;
        let mut hs = vec![0.0f32; grid.len()];
        for j in 0..d {
            fft.inverse(&hf[j * bins..(j + 1) * bins], &mut hs);
            pen += hs
                .iter()
                .zip(reg)
                .map(|(h, p)| ((h * p) as f64).powi(2))
                .sum::<f64>();
        }
        data + pen
    }

    #[test]
    fn admm_objective_decreases_with_iterations() {
        let grid = GridSize { h: 24, w: 24 };
        let d = 4;
        let mut fft = Fft2::new(grid);
        let bins = fft.spectrum_len();
        let mut s = 11u64;
        let mut xs = vec![0.0f32; grid.len()];
        let mut xf = vec![Complex32::default(); d * bins];
        for j in 0..d {
            for v in xs.iter_mut() {
                *v = lcg(&mut s);
            }
            fft.forward(&xs, &mut xf[j * bins..(j + 1) * bins]);
        }
        let mut y = vec![0.0; grid.len()];
        gaussian_label(grid, 1.0, &mut y);
        let mut yf = vec![Complex32::default(); bins];
        fft.forward(&y, &mut yf);
        let reg = reg_window(grid, Size2 { w: 32.0, h: 32.0 }, 4, 0.1, 0.8);
        let params = AdmmConfig {
            iterations: 6,
            mu_init: 1.0,
            beta: 10.0,
            mu_max: 1e4,
            lambda: 0.01,
            penalty: PenaltyKind::Elementwise,
            spatial_weight: 2.0 / 576.0,
            temporal: 0.0,
            ..AdmmConfig::default()
        };
        let crop = CropBox::centred(grid, GridSize { h: 8, w: 8 });
        let mut solver = AdmmSolver::new(grid, bins, d, &params, &reg, crop);
        let mut g = vec![Complex32::default(); d * bins];
        let zero = vec![Complex32::default(); d * bins];
        let mut last = objective(&mut fft, &xf, &yf, &zero, &reg, d);
        // Evaluate the feasible (cropped) version of each iterate: project g to the support.
        let mut hs = vec![0.0f32; grid.len()];
        let mut proj = vec![Complex32::default(); d * bins];
        for it in [1, 2, 4, 6] {
            solver.train_iterations(&mut fft, &xf, &yf, &mut g, it);
            for j in 0..d {
                fft.inverse(&g[j * bins..(j + 1) * bins], &mut hs);
                for r in 0..grid.h {
                    for c in 0..grid.w {
                        if r < crop.r0 || r >= crop.r1 || c < crop.c0 || c >= crop.c1 {
                            hs[r * grid.w + c] = 0.0;
                        }
                    }
                }
                fft.forward(&hs, &mut proj[j * bins..(j + 1) * bins]);
            }
            let e = objective(&mut fft, &xf, &yf, &proj, &reg, d);
            assert!(e < last, "iteration {it}: {e} !< {last}");
            last = e;
        }
    }

    /// Fraction of the learned filter's spatial energy where the penalty window exceeds its
    /// target-edge value (outside the target's inscribed ellipse).
    fn energy_outside_target(penalty: PenaltyKind, kappa: f32) -> f64 {
        let grid = GridSize { h: 32, w: 32 };
        let d = 4;
        let mut fft = Fft2::new(grid);
        let bins = fft.spectrum_len();
        let mut s = 5u64;
        let mut xs = vec![0.0f32; grid.len()];
        let mut xf = vec![Complex32::default(); d * bins];
        for j in 0..d {
            for v in xs.iter_mut() {
                *v = lcg(&mut s);
            }
            fft.forward(&xs, &mut xf[j * bins..(j + 1) * bins]);
        }
        let mut y = vec![0.0; grid.len()];
        gaussian_label(grid, 1.5, &mut y);
        let mut yf = vec![Complex32::default(); bins];
        fft.forward(&y, &mut yf);
        let (min, edge) = (0.1, 0.8);
        let reg = reg_window(grid, Size2 { w: 48.0, h: 48.0 }, 4, min, edge);
        let params = AdmmConfig {
            iterations: 3,
            mu_init: 1.0,
            beta: 20.0,
            mu_max: 1e4,
            lambda: 0.01,
            penalty,
            spatial_weight: kappa,
            temporal: 0.0,
            ..AdmmConfig::default()
        };
        let crop = CropBox::centred(grid, GridSize { h: 12, w: 12 });
        let mut solver = AdmmSolver::new(grid, bins, d, &params, &reg, crop);
        let mut g = vec![Complex32::default(); d * bins];
        solver.train(&mut fft, &xf, &yf, &mut g);
        let (mut outside, mut total) = (0.0f64, 0.0f64);
        let mut hs = vec![0.0f32; grid.len()];
        for j in 0..d {
            fft.inverse(&g[j * bins..(j + 1) * bins], &mut hs);
            for (h, p) in hs.iter().zip(&reg) {
                let e = (*h as f64).powi(2);
                total += e;
                if *p > edge {
                    outside += e;
                }
            }
        }
        outside / total
    }

    #[test]
    fn elementwise_penalty_moves_filter_energy_into_the_target() {
        let t = 32.0 * 32.0;
        let none = energy_outside_target(PenaltyKind::None, 0.0);
        // The literal eq. 8 (κ = 2/T) is numerically the unpenalised filter.
        let literal = energy_outside_target(PenaltyKind::Elementwise, 2.0 / t);
        assert!((literal - none).abs() < 1e-2 * none, "{literal} vs {none}");
        eprintln!("energy outside the target: none {none:.4}, eq. 8 literal {literal:.4}");
        // At a magnitude that matters the energy outside the target falls, more with κ.
        let k10 = energy_outside_target(PenaltyKind::Elementwise, 10.0);
        let k100 = energy_outside_target(PenaltyKind::Elementwise, 100.0);
        assert!(k10 < 0.9 * none, "κ=10: {k10} vs none {none}");
        eprintln!("κ=10 {k10:.4}, κ=100 {k100:.4}");
        assert!(k100 < k10, "κ=100: {k100} vs κ=10 {k10}");
    }

    /// Two random `d`-channel feature spectra and a Gaussian label's spectrum on `grid` (the
    /// LCG seeded with `seed`), with the planned transform.
    fn two_samples_and_label(
        grid: GridSize,
        d: usize,
        seed: u64,
    ) -> (Fft2, Vec<Complex32>, Vec<Complex32>, Vec<Complex32>) {
        let mut fft = Fft2::new(grid);
        let bins = fft.spectrum_len();
        let mut s = seed;
        let mut sample = |fft: &mut Fft2| {
            let mut xs = vec![0.0f32; grid.len()];
            let mut xf = vec![Complex32::default(); d * bins];
            for j in 0..d {
                xs.iter_mut().for_each(|v| *v = lcg(&mut s));
                fft.forward(&xs, &mut xf[j * bins..(j + 1) * bins]);
            }
            xf
        };
        let (x1, x2) = (sample(&mut fft), sample(&mut fft));
        let mut y = vec![0.0; grid.len()];
        gaussian_label(grid, 1.0, &mut y);
        let mut yf = vec![Complex32::default(); bins];
        fft.forward(&y, &mut yf);
        (fft, x1, x2, yf)
    }

    /// The solver keeps its spectra between frames and clears only what the next training
    /// reads before writing: a solver that trained on other data (and a ĝ buffer full of
    /// it) gives a fresh solver's bits, for every iteration count, with and without the
    /// temporal term's first frame.
    #[test]
    fn a_reused_solver_gives_a_fresh_solvers_bits() {
        let grid = GridSize { h: 20, w: 24 };
        let d = 3;
        let (mut fft, xa, xb, yf) = two_samples_and_label(grid, d, 5);
        let bins = fft.spectrum_len();
        let reg = reg_window(grid, Size2 { w: 30.0, h: 26.0 }, 4, 0.1, 0.8);
        for (penalty, iterations) in [
            (PenaltyKind::Elementwise, 3),
            (PenaltyKind::Elementwise, 1),
            (PenaltyKind::Elementwise, 0),
            (PenaltyKind::Matrix, 3),
        ] {
            let params = AdmmConfig {
                iterations,
                penalty,
                ..AdmmConfig::default()
            };
            let crop = CropBox::centred(grid, GridSize { h: 6, w: 7 });
            let mut fresh = AdmmSolver::new(grid, bins, d, &params, &reg, crop);
            let mut want = vec![Complex32::default(); d * bins];
            fresh.train(&mut fft, &xb, &yf, &mut want);
            let mut reused = AdmmSolver::new(grid, bins, d, &params, &reg, crop);
            let mut got = vec![Complex32::default(); d * bins];
            reused.train(&mut fft, &xa, &yf, &mut got);
            reused.train(&mut fft, &xb, &yf, &mut got);
            let same = got
                .iter()
                .zip(&want)
                .all(|(a, b)| a.re.to_bits() == b.re.to_bits() && a.im.to_bits() == b.im.to_bits());
            assert!(same, "{penalty:?}, {iterations} iterations: state leaked");
            assert!(
                iterations == 0 || want.iter().any(|v| v.norm_sqr() > 0.0),
                "a trained filter"
            );
        }
    }

    /// The solver as of eb06111, kept as the bit reference for the fused one: every
    /// iteration runs the g-step over all channels, then the h-step over all channels, then
    /// the l-update as a pass of its own, and l̂ is cleared before the first iteration.
    fn reference_train(
        s: &mut AdmmSolver,
        fft: &mut Fft2,
        xf: &[Complex32],
        yf: &[Complex32],
        g_f: &mut [Complex32],
        iterations: usize,
    ) {
        let (bins, d) = (s.bins, s.channels);
        let t = s.grid.len() as f32;
        let theta = if s.temporal > 0.0 && s.primed {
            s.g_prev.copy_from_slice(g_f);
            s.temporal
        } else {
            0.0
        };
        s.primed = true;
        let iterations = iterations.min(s.mus.len());
        s.l_f.iter_mut().for_each(|v| *v = Complex32::default());
        if theta > 0.0 {
            s.h_f.iter_mut().for_each(|v| *v = Complex32::default());
        }
        if iterations == 0 {
            g_f.iter_mut().for_each(|v| *v = Complex32::default());
        }
        s.s_xx.iter_mut().for_each(|v| *v = 0.0);
        for x in xf.chunks_exact(bins).take(d) {
            for (sx, v) in s.s_xx.iter_mut().zip(x) {
                *sx += f64::from(v.norm_sqr());
            }
        }
        for it in 0..iterations {
            let mu = s.mus[it];
            if theta > 0.0 {
                let m = mu + theta;
                for ((p, h), g) in s.pull.iter_mut().zip(&s.h_f).zip(&s.g_prev) {
                    *p = (h * mu + g * theta) / m;
                }
                std::mem::swap(&mut s.h_f, &mut s.pull);
                reference_g_step(s, xf, yf, g_f, m, t, false);
                std::mem::swap(&mut s.h_f, &mut s.pull);
            } else {
                reference_g_step(s, xf, yf, g_f, mu, t, it == 0);
            }
            if it + 1 < iterations {
                reference_h_step(s, fft, g_f, it, mu);
                for ((l, g), h) in s.l_f.iter_mut().zip(g_f.iter()).zip(&s.h_f) {
                    *l += (g - h) * mu;
                }
            }
        }
    }

    /// The g-step of [`reference_train`], over all channels at once.
    fn reference_g_step(
        s: &mut AdmmSolver,
        xf: &[Complex32],
        yf: &[Complex32],
        g_f: &mut [Complex32],
        mu: f32,
        t: f32,
        lh_zero: bool,
    ) {
        let bins = s.bins;
        if lh_zero {
            s.s_lx.iter_mut().for_each(|v| *v = Complex64::default());
            s.s_hx.iter_mut().for_each(|v| *v = Complex64::default());
        } else {
            channel_sums(
                xf,
                &s.l_f,
                &s.h_f,
                bins,
                s.channels,
                &mut s.s_lx,
                &mut s.s_hx,
            );
        }
        let mu64 = f64::from(mu);
        let tmu = f64::from(t) * mu64;
        for k in 0..bins {
            let b = s.s_xx[k] + tmu;
            let c = (c64(yf[k]) + s.s_lx[k] / mu64 - s.s_hx[k]) / b;
            s.coef[k] = Complex32::new(c.re as f32, c.im as f32);
        }
        if lh_zero {
            g_update_first(g_f, xf, &s.coef, 1.0 / mu);
        } else {
            g_update(g_f, xf, &s.l_f, &s.h_f, &s.coef, 1.0 / mu);
        }
    }

    /// The h-step of [`reference_train`], over all channels at once, through
    /// [`Fft2::inverse`] / [`Fft2::inverse_rows`] from a spectrum of its own.
    fn reference_h_step(s: &mut AdmmSolver, fft: &mut Fft2, g_f: &[Complex32], it: usize, mu: f32) {
        let bins = s.bins;
        let w = s.grid.w;
        let CropBox { r0, r1, c0, c1 } = s.crop;
        let mut spat = vec![0.0f32; s.grid.len()];
        let mut spat2 = vec![0.0f32; s.grid.len()];
        for ch in 0..s.channels {
            let g = &g_f[ch * bins..(ch + 1) * bins];
            let l = &s.l_f[ch * bins..(ch + 1) * bins];
            for ((t, g), l) in s.tmp_f.iter_mut().zip(g).zip(l) {
                *t = g * mu + l;
            }
            match &s.penalty {
                PenaltyData::Matrix(ps) => {
                    for r in r0..r1 {
                        spat2[r * w + c0..r * w + c1]
                            .iter_mut()
                            .for_each(|v| *v = 0.0);
                    }
                    let h = s.grid.h;
                    fft.inverse(&s.tmp_f, &mut spat);
                    let p = &ps[it];
                    for r in r0..r1 {
                        let prow = &p[(r - r0) * h..(r - r0 + 1) * h];
                        let out = &mut spat2[r * w + c0..r * w + c1];
                        for (k, &pk) in prow.iter().enumerate() {
                            let src = &spat[k * w + c0..k * w + c1];
                            for (o, s) in out.iter_mut().zip(src) {
                                *o += pk * s;
                            }
                        }
                    }
                }
                PenaltyData::Elementwise(ws) => {
                    fft.inverse_rows(&s.tmp_f, r0, r1, &mut spat);
                    let bw = c1 - c0;
                    let wv = &ws[it];
                    for r in r0..r1 {
                        for c in c0..c1 {
                            spat2[r * w + c] = spat[r * w + c] * wv[(r - r0) * bw + c - c0];
                        }
                    }
                }
                PenaltyData::Scalar(sc) => {
                    fft.inverse_rows(&s.tmp_f, r0, r1, &mut spat);
                    let sc = sc[it];
                    for r in r0..r1 {
                        for c in c0..c1 {
                            spat2[r * w + c] = spat[r * w + c] * sc;
                        }
                    }
                }
            }
            fft.forward_rows(&spat2, r0, r1, &mut s.h_f[ch * bins..(ch + 1) * bins]);
        }
    }

    /// The trainer's filter has the bits of [`reference_train`]'s for 0–3 iterations, every
    /// penalty, square and non-square grids (even and odd widths), without and with the
    /// temporal term (whose first training has no previous filter; the second and third
    /// are pulled), on solvers that keep their state across trainings.
    #[test]
    fn fused_training_gives_the_unfused_reference_bits() {
        let bits = |v: &[Complex32]| -> Vec<(u32, u32)> {
            v.iter().map(|z| (z.re.to_bits(), z.im.to_bits())).collect()
        };
        let mut cases = 0;
        for (grid, seed) in [
            (GridSize { h: 20, w: 24 }, 3u64),
            (GridSize { h: 18, w: 18 }, 7),
            (GridSize { h: 15, w: 17 }, 13),
        ] {
            let d = 5;
            let (mut fft, xa, xb, yf) = two_samples_and_label(grid, d, seed);
            let bins = fft.spectrum_len();
            // A third sample: arbitrary complex values, not a real map's spectrum.
            let mut s = seed ^ 0x5eed;
            let xc: Vec<Complex32> = (0..d * bins)
                .map(|_| Complex32::new(lcg(&mut s) * 40.0, lcg(&mut s) * 40.0))
                .collect();
            let reg = reg_window(grid, Size2 { w: 30.0, h: 26.0 }, 4, 0.1, 0.8);
            let crop = CropBox::centred(grid, GridSize { h: 6, w: 7 });
            for penalty in [
                PenaltyKind::Matrix,
                PenaltyKind::Elementwise,
                PenaltyKind::None,
            ] {
                for temporal in [0.0, 15.0] {
                    for iterations in 0..=3 {
                        let params = AdmmConfig {
                            iterations: 3,
                            penalty,
                            temporal,
                            ..AdmmConfig::default()
                        };
                        let mut fused = AdmmSolver::new(grid, bins, d, &params, &reg, crop);
                        let mut reference = fused.clone();
                        let mut got = vec![Complex32::default(); d * bins];
                        let mut want = got.clone();
                        for (n, x) in [&xa, &xb, &xc].into_iter().enumerate() {
                            fused.train_iterations(&mut fft, x, &yf, &mut got, iterations);
                            reference_train(
                                &mut reference,
                                &mut fft,
                                x,
                                &yf,
                                &mut want,
                                iterations,
                            );
                            assert!(
                                bits(&got) == bits(&want),
                                "{grid:?} {penalty:?} θ {temporal} {iterations} it., training {n}"
                            );
                            assert!(iterations == 0 || want.iter().any(|v| v.norm_sqr() > 0.0));
                            cases += 1;
                        }
                    }
                }
            }
        }
        assert_eq!(cases, 3 * 3 * 2 * 4 * 3);
    }

    #[test]
    fn temporal_term_pulls_the_filter_towards_the_previous_one() {
        let grid = GridSize { h: 16, w: 16 };
        let d = 3;
        let (mut fft, x1, x2, yf) = two_samples_and_label(grid, d, 11);
        let bins = fft.spectrum_len();
        let reg = reg_window(grid, Size2 { w: 24.0, h: 24.0 }, 4, 0.1, 0.8);
        let crop = CropBox::centred(grid, GridSize { h: 6, w: 6 });
        let train = |theta: f32, fft: &mut Fft2| {
            let params = AdmmConfig {
                iterations: 3,
                mu_init: 1.0,
                beta: 20.0,
                mu_max: 1e4,
                lambda: 0.01,
                penalty: PenaltyKind::Elementwise,
                spatial_weight: 10.0,
                temporal: theta,
                ..AdmmConfig::default()
            };
            let mut solver = AdmmSolver::new(grid, bins, d, &params, &reg, crop);
            let mut g = vec![Complex32::default(); d * bins];
            solver.train(fft, &x1, &yf, &mut g);
            let first = g.clone();
            solver.train(fft, &x2, &yf, &mut g);
            (first, g)
        };
        let dist = |a: &[Complex32], b: &[Complex32]| {
            a.iter()
                .zip(b)
                .map(|(u, v)| f64::from((u - v).norm_sqr()))
                .sum::<f64>()
                .sqrt()
        };
        let (first0, second0) = train(0.0, &mut fft);
        let (first_t, second_t) = train(15.0, &mut fft);
        // No previous filter on the first training: the temporal term does nothing there.
        assert!(dist(&first0, &first_t) < 1e-6 * dist(&first0, &second0));
        // On the second it pulls the filter towards the first.
        let (free, pulled) = (dist(&second0, &first0), dist(&second_t, &first_t));
        eprintln!("distance to the previous filter: theta 0 {free:.4e}, theta 15 {pulled:.4e}");
        assert!(pulled < 0.5 * free, "{pulled} vs {free}");
    }

    #[test]
    fn crop_box_is_centred_like_the_reference() {
        let c = CropBox::centred(GridSize { h: 60, w: 60 }, GridSize { h: 10, w: 7 });
        assert_eq!((c.r0, c.r1, c.c0, c.c1), (25, 35, 27, 34));
    }

    #[test]
    fn mu_schedule_grows_by_beta_and_saturates() {
        let p = AdmmConfig {
            iterations: 5,
            mu_init: 1.0,
            beta: 20.0,
            mu_max: 10000.0,
            lambda: 0.01,
            penalty: PenaltyKind::Matrix,
            spatial_weight: 0.0,
            temporal: 0.0,
            ..AdmmConfig::default()
        };
        assert_eq!(p.mu_schedule(), vec![1.0, 20.0, 400.0, 8000.0, 10000.0]);
    }
}
