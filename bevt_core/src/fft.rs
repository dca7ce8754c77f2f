//! 2-D real FFTs on the feature grid, planned once and run without allocation.
//!
//! Spectra are Hermitian half spectra stored **column-major**: `W/2 + 1` frequency columns
//! `kx`, each a contiguous run of `H` rows `ky` (`spec[kx * H + ky]`). The forward
//! transform is unnormalised and the inverse divides by `H·W`, as MATLAB's `fft2`/`ifft2`,
//! so the formulas of ALGORITHM.md carry over unchanged.

use crate::geometry::GridSize;
use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::{num_complex::Complex32, Fft, FftPlanner};
use std::fmt;
use std::sync::Arc;

/// A planned 2-D real FFT of a fixed grid with its scratch buffers.
#[derive(Clone)]
pub struct Fft2 {
    grid: GridSize,
    wc: usize,
    r2c: Arc<dyn RealToComplex<f32>>,
    c2r: Arc<dyn ComplexToReal<f32>>,
    col_fwd: Arc<dyn Fft<f32>>,
    col_inv: Arc<dyn Fft<f32>>,
    row_real: Vec<f32>,
    row_spec: Vec<Complex32>,
    tmp: Vec<Complex32>,
    scratch_r: Vec<Complex32>,
    scratch_c: Vec<Complex32>,
}

impl fmt::Debug for Fft2 {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Fft2").field("grid", &self.grid).finish()
    }
}

impl Fft2 {
    /// Plans transforms for an `h × w` grid (both ≥ 1).
    pub fn new(grid: GridSize) -> Self {
        let mut rp = RealFftPlanner::<f32>::new();
        let mut cp = FftPlanner::<f32>::new();
        let r2c = rp.plan_fft_forward(grid.w);
        let c2r = rp.plan_fft_inverse(grid.w);
        let col_fwd = cp.plan_fft_forward(grid.h);
        let col_inv = cp.plan_fft_inverse(grid.h);
        let wc = grid.w / 2 + 1;
        let scratch_r =
            vec![Complex32::default(); r2c.get_scratch_len().max(c2r.get_scratch_len())];
        let scratch_c = vec![
            Complex32::default();
            col_fwd
                .get_inplace_scratch_len()
                .max(col_inv.get_inplace_scratch_len())
        ];
        Self {
            grid,
            wc,
            r2c,
            c2r,
            col_fwd,
            col_inv,
            row_real: vec![0.0; grid.w],
            row_spec: vec![Complex32::default(); wc],
            tmp: vec![Complex32::default(); wc * grid.h],
            scratch_r,
            scratch_c,
        }
    }

    /// The spatial grid.
    pub fn grid(&self) -> GridSize {
        self.grid
    }

    /// Number of complex bins of a half spectrum: `(W/2 + 1) · H`.
    pub fn spectrum_len(&self) -> usize {
        self.wc * self.grid.h
    }

    /// Number of frequency columns `W/2 + 1`.
    pub fn spectrum_cols(&self) -> usize {
        self.wc
    }

    /// Forward transform of a row-major `H × W` real map into `spec` (column-major half
    /// spectrum, see the module doc).
    pub fn forward(&mut self, input: &[f32], spec: &mut [Complex32]) {
        self.forward_rows(input, 0, self.grid.h, spec);
    }

    /// Forward transform of a map that is zero outside rows `r0..r1` (only those rows of
    /// `input` are read): the pruned transform used for cropped filters.
    pub fn forward_rows(&mut self, input: &[f32], r0: usize, r1: usize, spec: &mut [Complex32]) {
        let (h, w, wc) = (self.grid.h, self.grid.w, self.wc);
        debug_assert!(input.len() >= h * w && spec.len() >= wc * h);
        let (r0, r1) = (r0.min(h), r1.min(h));
        for r in r0..r1.max(r0) {
            self.row_real.copy_from_slice(&input[r * w..(r + 1) * w]);
            // Lengths are fixed at planning time, so the transform cannot fail.
            let _ = self.r2c.process_with_scratch(
                &mut self.row_real,
                &mut self.row_spec,
                &mut self.scratch_r,
            );
            for (kx, v) in self.row_spec.iter().enumerate() {
                spec[kx * h + r] = *v;
            }
        }
        // The rows outside `r0..r1` are zero: runs of each frequency column.
        for col in spec[..wc * h].chunks_exact_mut(h) {
            col[..r0].fill(Complex32::default());
            col[r1.max(r0)..].fill(Complex32::default());
        }
        self.col_fwd
            .process_with_scratch(&mut spec[..wc * h], &mut self.scratch_c);
    }

    /// Inverse transform (divided by `H·W`) into a row-major real map.
    pub fn inverse(&mut self, spec: &[Complex32], out: &mut [f32]) {
        self.inverse_rows(spec, 0, self.grid.h, out);
    }

    /// Inverse transform computing only rows `r0..r1` of `out` (other rows are left as they
    /// were).
    pub fn inverse_rows(&mut self, spec: &[Complex32], r0: usize, r1: usize, out: &mut [f32]) {
        let (h, w, wc) = (self.grid.h, self.grid.w, self.wc);
        debug_assert!(out.len() >= h * w && spec.len() >= wc * h);
        self.tmp.copy_from_slice(&spec[..wc * h]);
        self.col_inv
            .process_with_scratch(&mut self.tmp, &mut self.scratch_c);
        let norm = 1.0 / (h * w) as f32;
        for r in r0..r1.min(h) {
            for kx in 0..wc {
                self.row_spec[kx] = self.tmp[kx * h + r];
            }
            // A real map's row spectrum has real DC (and Nyquist) bins; rounding leaves tiny
            // imaginary parts there, which the real inverse must not see.
            self.row_spec[0].im = 0.0;
            if w % 2 == 0 {
                self.row_spec[wc - 1].im = 0.0;
            }
            let _ = self.c2r.process_with_scratch(
                &mut self.row_spec,
                &mut self.row_real,
                &mut self.scratch_r,
            );
            for (o, v) in out[r * w..(r + 1) * w].iter_mut().zip(&self.row_real) {
                *o = v * norm;
            }
        }
    }
}

/// Signed frequency of bin `k` of an `n`-point DFT: `0, 1, …, ⌈(n−1)/2⌉, −⌊(n−1)/2⌋, …, −1`.
pub fn signed_freq(k: usize, n: usize) -> f32 {
    let pos = n.saturating_sub(1).div_ceil(2);
    if k <= pos {
        k as f32
    } else {
        k as f32 - n as f32
    }
}

/// `fftshift` of a row-major `h × w` map into `out`: index (0,0) moves to (⌊h/2⌋, ⌊w/2⌋).
pub fn fftshift(input: &[f32], grid: GridSize, out: &mut [f32]) {
    let (h, w) = (grid.h, grid.w);
    let (sh, sw) = (h / 2, w / 2);
    for r in 0..h {
        let rr = (r + sh) % h;
        for c in 0..w {
            out[rr * w + (c + sw) % w] = input[r * w + c];
        }
    }
}

/// Shifts the map behind a half spectrum (layout of [`Fft2`]) by `(dy, dx)` cells, circularly
/// and with sub-cell precision: afterwards `x'(r, c) = x(r + dy, c + dx)`, i.e.
/// `X'(k) = X(k) · exp(i2π(k_y dy / H + k_x dx / W))` with signed `k_y`.
pub fn shift_spectrum(spec: &mut [Complex32], grid: GridSize, dy: f32, dx: f32) {
    let (h, w) = (grid.h, grid.w);
    let wc = w / 2 + 1;
    let two_pi = std::f64::consts::TAU;
    for kx in 0..wc {
        let ax = two_pi * kx as f64 * f64::from(dx) / w as f64;
        for ky in 0..h {
            let sky = if ky <= h / 2 {
                ky as f64
            } else {
                ky as f64 - h as f64
            };
            let a = ax + two_pi * sky * f64::from(dy) / h as f64;
            let rot = Complex32::new(a.cos() as f32, a.sin() as f32);
            if let Some(v) = spec.get_mut(kx * h + ky) {
                *v *= rot;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn naive_dft(x: &[f32], h: usize, w: usize, ky: usize, kx: usize) -> Complex32 {
        let mut acc = (0.0f64, 0.0f64);
        for r in 0..h {
            for c in 0..w {
                let ph = -2.0
                    * std::f64::consts::PI
                    * ((ky * r) as f64 / h as f64 + (kx * c) as f64 / w as f64);
                acc.0 += x[r * w + c] as f64 * ph.cos();
                acc.1 += x[r * w + c] as f64 * ph.sin();
            }
        }
        Complex32::new(acc.0 as f32, acc.1 as f32)
    }

    #[test]
    fn forward_matches_a_naive_dft() {
        let (h, w) = (6, 7);
        let x: Vec<f32> = (0..h * w).map(|i| ((i * 37) % 11) as f32 - 5.0).collect();
        let mut f = Fft2::new(GridSize { h, w });
        let mut s = vec![Complex32::default(); f.spectrum_len()];
        f.forward(&x, &mut s);
        for kx in 0..f.spectrum_cols() {
            for ky in 0..h {
                let want = naive_dft(&x, h, w, ky, kx);
                assert!((s[kx * h + ky] - want).norm() < 1e-3, "{ky} {kx}");
            }
        }
    }

    #[test]
    fn pruned_forward_equals_full_forward_on_zero_rows() {
        let (h, w) = (8, 8);
        let mut x = vec![0.0f32; h * w];
        for r in 2..5 {
            for c in 0..w {
                x[r * w + c] = (r * c) as f32;
            }
        }
        let mut f = Fft2::new(GridSize { h, w });
        let mut a = vec![Complex32::default(); f.spectrum_len()];
        let mut b = a.clone();
        f.forward(&x, &mut a);
        f.forward_rows(&x, 2, 5, &mut b);
        for (p, q) in a.iter().zip(&b) {
            assert!((p - q).norm() < 1e-4);
        }
    }

    #[test]
    fn fftshift_moves_origin_to_centre() {
        let g = GridSize { h: 4, w: 5 };
        let mut x = vec![0.0; 20];
        x[0] = 1.0;
        let mut y = vec![0.0; 20];
        fftshift(&x, g, &mut y);
        assert_eq!(y[2 * 5 + 2], 1.0);
    }

    #[test]
    fn signed_frequencies_follow_the_matlab_convention() {
        let v: Vec<f32> = (0..6).map(|k| signed_freq(k, 6)).collect();
        assert_eq!(v, vec![0.0, 1.0, 2.0, 3.0, -2.0, -1.0]);
        let v: Vec<f32> = (0..5).map(|k| signed_freq(k, 5)).collect();
        assert_eq!(v, vec![0.0, 1.0, 2.0, -2.0, -1.0]);
    }

    #[test]
    fn shift_spectrum_moves_a_peak_by_whole_cells() {
        let grid = GridSize { h: 8, w: 10 };
        let mut fft = Fft2::new(grid);
        let mut x = vec![0.0f32; grid.len()];
        x[3 * 10 + 4] = 1.0;
        let mut spec = vec![Complex32::default(); fft.spectrum_len()];
        fft.forward(&x, &mut spec);
        shift_spectrum(&mut spec, grid, 2.0, -3.0);
        let mut y = vec![0.0f32; grid.len()];
        fft.inverse(&spec, &mut y);
        // x'(r, c) = x(r + 2, c − 3): the peak moves from (3, 4) to (1, 7).
        assert!((y[10 + 7] - 1.0).abs() < 1e-5, "{y:?}");
        assert!(y.iter().map(|v| v.abs()).sum::<f32>() < 1.0 + 1e-3);
    }

    proptest! {
        #[test]
        fn inverse_of_forward_is_identity(h in 1usize..20, w in 1usize..20, seed in 0u32..1000) {
            let x: Vec<f32> = (0..h * w)
                .map(|i| (((i as u32).wrapping_mul(2654435761) ^ seed) % 1000) as f32 / 100.0 - 5.0)
                .collect();
            let mut f = Fft2::new(GridSize { h, w });
            let mut s = vec![Complex32::default(); f.spectrum_len()];
            f.forward(&x, &mut s);
            let mut y = vec![0.0; h * w];
            f.inverse(&s, &mut y);
            for (a, b) in x.iter().zip(&y) {
                prop_assert!((a - b).abs() < 1e-3, "{} vs {}", a, b);
            }
        }
    }
}
