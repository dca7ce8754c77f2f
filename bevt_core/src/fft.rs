//! 2-D real FFTs on the feature grid, planned once and run without allocation.
//!
//! Spectra are Hermitian half spectra stored **column-major**: `W/2 + 1` frequency columns
//! `kx`, each a contiguous run of `H` rows `ky` (`spec[kx * H + ky]`). The forward
//! transform is unnormalised and the inverse divides by `H·W`, as MATLAB's `fft2`/`ifft2`,
//! so the formulas of ALGORITHM.md carry over unchanged.

use crate::geometry::GridSize;
use rustfft::{num_complex::Complex32, Fft, FftPlanner};
use std::fmt;
use std::sync::Arc;

/// `exp(−2πi·k/n)`, computed as the `realfft` crate computes its twiddles (in `f64`, then
/// rounded to `f32`), so the row transforms below give that crate's bits.
fn twiddle(k: usize, n: usize) -> Complex32 {
    let angle = -2f64 * std::f64::consts::PI / n as f64 * k as f64;
    Complex32::new(angle.cos() as f32, angle.sin() as f32)
}

/// How the real rows are transformed: all rows of a call in one batched complex FFT.
///
/// An even width `W` packs a row's pairs `(x₂ₘ, x₂ₘ₊₁)` into one complex value, transforms
/// the `W/2` values and untangles the half spectrum with one twiddle per bin pair (the
/// classic real-FFT algorithm, as `realfft` does it); an odd width transforms the row as
/// complex values with zero imaginary parts. Each row gets the operations `realfft`'s
/// one-row transform gives it, in the same order, so the bits are the same; what changes is
/// that rustfft is called once per map instead of once per row (at 60 × 60 cells the
/// per-row calls' own work was most of the row pass).
#[derive(Clone)]
enum RowPlan {
    Even {
        fwd: Arc<dyn Fft<f32>>,
        inv: Arc<dyn Fft<f32>>,
        /// `twiddle(k, W) / 2` and `conj(twiddle(k, W))` for `k` in `1..=(W/2 − 1)/2`.
        tw_fwd: Vec<Complex32>,
        tw_inv: Vec<Complex32>,
    },
    Odd {
        fwd: Arc<dyn Fft<f32>>,
        inv: Arc<dyn Fft<f32>>,
    },
}

/// A planned 2-D real FFT of a fixed grid with its scratch buffers.
#[derive(Clone)]
pub struct Fft2 {
    grid: GridSize,
    wc: usize,
    rows: RowPlan,
    /// Complex values per row in the row transforms (`W/2` even, `W` odd).
    row_len: usize,
    /// All rows in one call ([`batch_gives_one_row_bits`]), else a call per row.
    batch: bool,
    col_fwd: Arc<dyn Fft<f32>>,
    col_inv: Arc<dyn Fft<f32>>,
    rows_in: Vec<Complex32>,
    rows_out: Vec<Complex32>,
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
        let mut cp = FftPlanner::<f32>::new();
        let (rows, row_len, scratch_len) = if grid.w.is_multiple_of(2) {
            let f = grid.w / 2;
            let fwd = cp.plan_fft_forward(f);
            let inv = cp.plan_fft_inverse(f);
            let pairs = 1..=f.saturating_sub(1) / 2;
            let scratch = fwd
                .get_outofplace_scratch_len()
                .max(inv.get_outofplace_scratch_len());
            let plan = RowPlan::Even {
                tw_fwd: pairs.clone().map(|k| twiddle(k, grid.w) * 0.5).collect(),
                tw_inv: pairs.map(|k| twiddle(k, grid.w).conj()).collect(),
                fwd,
                inv,
            };
            (plan, f, scratch)
        } else {
            let fwd = cp.plan_fft_forward(grid.w);
            let inv = cp.plan_fft_inverse(grid.w);
            let scratch = fwd
                .get_inplace_scratch_len()
                .max(inv.get_inplace_scratch_len());
            (RowPlan::Odd { fwd, inv }, grid.w, scratch)
        };
        let col_fwd = cp.plan_fft_forward(grid.h);
        let col_inv = cp.plan_fft_inverse(grid.h);
        let wc = grid.w / 2 + 1;
        let scratch_c = vec![
            Complex32::default();
            col_fwd
                .get_inplace_scratch_len()
                .max(col_inv.get_inplace_scratch_len())
        ];
        Self {
            grid,
            wc,
            rows,
            row_len,
            batch: batch_gives_one_row_bits(),
            col_fwd,
            col_inv,
            rows_in: vec![Complex32::default(); row_len * grid.h],
            rows_out: vec![Complex32::default(); row_len * grid.h],
            tmp: vec![Complex32::default(); wc * grid.h],
            scratch_r: vec![Complex32::default(); scratch_len],
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
        self.forward_rows_windowed(input, None, r0, r1, spec);
    }

    /// [`Self::forward`] of `input` multiplied by `window` (a map of the same grid), the
    /// product formed as the rows are packed for their transforms: what multiplying the map
    /// in place and then transforming it gives, the same bits, without writing the windowed
    /// map and reading it back.
    pub fn forward_windowed(&mut self, input: &[f32], window: &[f32], spec: &mut [Complex32]) {
        self.forward_rows_windowed(input, Some(window), 0, self.grid.h, spec);
    }

    fn forward_rows_windowed(
        &mut self,
        input: &[f32],
        window: Option<&[f32]>,
        r0: usize,
        r1: usize,
        spec: &mut [Complex32],
    ) {
        let (h, w, wc) = (self.grid.h, self.grid.w, self.wc);
        debug_assert!(input.len() >= h * w && spec.len() >= wc * h);
        debug_assert!(window.is_none_or(|m| m.len() == h * w));
        let (r0, r1) = (r0.min(h), r1.min(h).max(r0.min(h)));
        let n = (r1 - r0) * self.row_len;
        if n > 0 {
            let src = &input[r0 * w..r1 * w];
            let (bin, bout) = (&mut self.rows_in[..n], &mut self.rows_out[..n]);
            match &self.rows {
                RowPlan::Even { fwd, tw_fwd, .. } => {
                    // (The tracker builds its window for the grid; in a release build one of
                    // another size would go unused rather than panic.)
                    if let Some(win) = window.and_then(|m| m.get(r0 * w..r1 * w)) {
                        for ((b, x), m) in bin
                            .iter_mut()
                            .zip(src.chunks_exact(2))
                            .zip(win.chunks_exact(2))
                        {
                            *b = Complex32::new(x[0] * m[0], x[1] * m[1]);
                        }
                    } else {
                        for (b, x) in bin.iter_mut().zip(src.chunks_exact(2)) {
                            *b = Complex32::new(x[0], x[1]);
                        }
                    }
                    rows_outofplace(&**fwd, self.batch, bin, bout, &mut self.scratch_r);
                    untangle_forward(bout, self.row_len, tw_fwd, &mut spec[..wc * h], h, r0);
                }
                RowPlan::Odd { fwd, .. } => {
                    if let Some(win) = window.and_then(|m| m.get(r0 * w..r1 * w)) {
                        for ((b, &x), &m) in bin.iter_mut().zip(src).zip(win) {
                            *b = Complex32::new(x * m, 0.0);
                        }
                    } else {
                        for (b, &x) in bin.iter_mut().zip(src) {
                            *b = Complex32::new(x, 0.0);
                        }
                    }
                    rows_inplace(&**fwd, self.batch, bin, &mut self.scratch_r);
                    for (kx, col) in spec[..wc * h].chunks_exact_mut(h).enumerate() {
                        for (o, row) in col[r0..r1].iter_mut().zip(bin.chunks_exact(w)) {
                            *o = row[kx];
                        }
                    }
                    for o in &mut spec[r0..r1] {
                        o.im = 0.0;
                    }
                }
            }
        }
        // The rows outside `r0..r1` are zero: runs of each frequency column.
        for col in spec[..wc * h].chunks_exact_mut(h) {
            col[..r0].fill(Complex32::default());
            col[r1..].fill(Complex32::default());
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
        let (r0, r1) = (r0.min(h), r1.min(h).max(r0.min(h)));
        let n = (r1 - r0) * self.row_len;
        if n == 0 {
            return;
        }
        // A real map's row spectrum has real DC (and Nyquist) bins; rounding leaves tiny
        // imaginary parts there, which the real inverse must not see.
        for v in &mut self.tmp[..h] {
            v.im = 0.0;
        }
        if w.is_multiple_of(2) {
            for v in &mut self.tmp[(wc - 1) * h..wc * h] {
                v.im = 0.0;
            }
        }
        let norm = 1.0 / (h * w) as f32;
        let dst = &mut out[r0 * w..r1 * w];
        let (bin, bout) = (&mut self.rows_in[..n], &mut self.rows_out[..n]);
        match &self.rows {
            RowPlan::Even { inv, tw_inv, .. } => {
                tangle_inverse(&self.tmp, h, r0, tw_inv, self.row_len, bin);
                rows_outofplace(&**inv, self.batch, bin, bout, &mut self.scratch_r);
                for (o, v) in dst.chunks_exact_mut(2).zip(bout.iter()) {
                    o[0] = v.re * norm;
                    o[1] = v.im * norm;
                }
            }
            RowPlan::Odd { inv, .. } => {
                // Each row: its half spectrum, then the other half as its mirror's conjugates.
                for (i, row) in bin.chunks_exact_mut(w).enumerate() {
                    let r = r0 + i;
                    for (kx, b) in row[..wc].iter_mut().enumerate() {
                        *b = self.tmp[kx * h + r];
                    }
                    for j in 1..=w / 2 {
                        row[w - j] = self.tmp[j * h + r].conj();
                    }
                }
                rows_inplace(&**inv, self.batch, bin, &mut self.scratch_r);
                for (o, v) in dst.iter_mut().zip(bin.iter()) {
                    *o = v.re * norm;
                }
            }
        }
    }
}

/// Whether rustfft transforms several rows in one call with the operations it gives one row.
/// Its AVX algorithms (chosen where the CPU has AVX and FMA, as its planner decides) do
/// each row on its own; its SSE and NEON algorithms pair two rows in one register and round
/// differently from one row alone (seen under `qemu-x86_64 -cpu Nehalem`). There the rows
/// are transformed one call each, as `realfft` does, so every host keeps its bits.
fn batch_gives_one_row_bits() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// `fft` out of place on each `fft.len()` run of `bin` into `bout`: one call, or one a run.
fn rows_outofplace(
    fft: &dyn Fft<f32>,
    batch: bool,
    bin: &mut [Complex32],
    bout: &mut [Complex32],
    scratch: &mut [Complex32],
) {
    if batch {
        fft.process_outofplace_with_scratch(bin, bout, scratch);
    } else {
        let n = fft.len();
        for (i, o) in bin.chunks_exact_mut(n).zip(bout.chunks_exact_mut(n)) {
            fft.process_outofplace_with_scratch(i, o, scratch);
        }
    }
}

/// `fft` in place on each `fft.len()` run of `buf`: one call, or one a run.
fn rows_inplace(fft: &dyn Fft<f32>, batch: bool, buf: &mut [Complex32], scratch: &mut [Complex32]) {
    if batch {
        fft.process_with_scratch(buf, scratch);
    } else {
        for row in buf.chunks_exact_mut(fft.len()) {
            fft.process_with_scratch(row, scratch);
        }
    }
}

/// The half spectra of real rows `r0..` from their packed transforms `out` (`f` values a
/// row, `x₂ₘ + i·x₂ₘ₊₁` transformed): bin `0` and `f` from the first value, bins `k` and
/// `f − k` from values `k` and `f − k` and `tw[k − 1]`, the middle bin (even `f`) conjugated.
/// Written a frequency column at a time, into `spec[kx · h + r]`.
fn untangle_forward(
    out: &[Complex32],
    f: usize,
    tw: &[Complex32],
    spec: &mut [Complex32],
    h: usize,
    r0: usize,
) {
    let rows = out.len() / f;
    let col = |kx: usize| kx * h + r0..kx * h + r0 + rows;
    for (s, o) in spec[col(0)].iter_mut().zip(out.chunks_exact(f)) {
        *s = Complex32::new(o[0].re + o[0].im, 0.0);
    }
    for (s, o) in spec[col(f)].iter_mut().zip(out.chunks_exact(f)) {
        *s = Complex32::new(o[0].re - o[0].im, 0.0);
    }
    for (i, t) in tw.iter().enumerate() {
        let k = i + 1;
        let (lo, hi) = spec.split_at_mut((f - k) * h);
        let a_col = &mut lo[k * h + r0..k * h + r0 + rows];
        let b_col = &mut hi[r0..r0 + rows];
        for ((o, a_out), b_out) in out.chunks_exact(f).zip(a_col).zip(b_col) {
            let sum = o[k] + o[f - k];
            let diff = o[k] - o[f - k];
            let re = sum.im * t.re + diff.re * t.im;
            let im = sum.im * t.im - diff.re * t.re;
            let half_sum_re = 0.5 * sum.re;
            let half_diff_im = 0.5 * diff.im;
            *a_out = Complex32::new(half_sum_re + re, half_diff_im + im);
            *b_out = Complex32::new(half_sum_re - re, im - half_diff_im);
        }
    }
    if f.is_multiple_of(2) {
        for (s, o) in spec[col(f / 2)].iter_mut().zip(out.chunks_exact(f)) {
            *s = Complex32::new(o[f / 2].re, -o[f / 2].im);
        }
    }
}

/// The packed inputs (`f` values a row) of the inverse row transforms of rows `r0..` of the
/// column-transformed half spectrum `tmp` (`tmp[kx · h + r]`, DC and Nyquist bins real):
/// the inverse of [`untangle_forward`] with `tw[k − 1] = conj(twiddle(k, 2f))`, scaled by 2.
fn tangle_inverse(
    tmp: &[Complex32],
    h: usize,
    r0: usize,
    tw: &[Complex32],
    f: usize,
    bin: &mut [Complex32],
) {
    for (i, row) in bin.chunks_exact_mut(f).enumerate() {
        let r = r0 + i;
        let x = |kx: usize| tmp[kx * h + r];
        let sum = x(0) + x(f);
        let diff = x(0) - x(f);
        row[0] = Complex32::new(sum.re - sum.im, diff.re - diff.im);
        for (j, t) in tw.iter().enumerate() {
            let k = j + 1;
            let sum = x(k) + x(f - k);
            let diff = x(k) - x(f - k);
            let re = sum.im * t.re + diff.re * t.im;
            let im = sum.im * t.im - diff.re * t.re;
            row[k] = Complex32::new(sum.re - re, diff.im - im);
            row[f - k] = Complex32::new(sum.re + re, -im - diff.im);
        }
        if f.is_multiple_of(2) {
            let c = x(f / 2);
            row[f / 2] = (c + c).conj();
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

    #[test]
    fn windowed_transform_is_the_transform_of_the_windowed_map_bit_for_bit() {
        // Even widths (rows packed in pairs) and odd ones (one value a bin).
        for (h, w) in [(6, 8), (5, 7), (12, 10), (9, 15)] {
            let grid = GridSize { h, w };
            let x: Vec<f32> = (0..h * w)
                .map(|i| ((i * 37 % 29) as f32 - 14.0) * 0.37)
                .collect();
            let win: Vec<f32> = (0..h * w)
                .map(|i| 0.1 + (i * 13 % 17) as f32 / 19.0)
                .collect();
            let windowed: Vec<f32> = x.iter().zip(&win).map(|(a, b)| a * b).collect();
            let mut fft = Fft2::new(grid);
            let n = fft.spectrum_len();
            let (mut a, mut b) = (vec![Complex32::default(); n], vec![Complex32::default(); n]);
            fft.forward_windowed(&x, &win, &mut a);
            fft.forward(&windowed, &mut b);
            let bits = |v: &[Complex32]| -> Vec<(u32, u32)> {
                v.iter().map(|c| (c.re.to_bits(), c.im.to_bits())).collect()
            };
            assert_eq!(bits(&a), bits(&b), "{h} x {w}");
            // And not the unwindowed map's.
            fft.forward(&x, &mut b);
            assert_ne!(bits(&a), bits(&b), "{h} x {w}");
        }
    }

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

    /// The transforms as they were computed before the rows were batched: `realfft`'s
    /// one-row transforms, a row at a time (the reference the batched rows must equal bit
    /// for bit).
    fn per_row_forward(x: &[f32], g: GridSize, r0: usize, r1: usize) -> Vec<Complex32> {
        use realfft::RealFftPlanner;
        let (h, w, wc) = (g.h, g.w, g.w / 2 + 1);
        let r2c = RealFftPlanner::<f32>::new().plan_fft_forward(w);
        let col = FftPlanner::<f32>::new().plan_fft_forward(h);
        let mut spec = vec![Complex32::default(); wc * h];
        let mut row_spec = vec![Complex32::default(); wc];
        for r in r0..r1 {
            let mut row = x[r * w..(r + 1) * w].to_vec();
            r2c.process(&mut row, &mut row_spec).unwrap();
            for (kx, v) in row_spec.iter().enumerate() {
                spec[kx * h + r] = *v;
            }
        }
        col.process(&mut spec);
        spec
    }

    fn per_row_inverse(spec: &[Complex32], g: GridSize, r0: usize, r1: usize) -> Vec<f32> {
        use realfft::RealFftPlanner;
        let (h, w, wc) = (g.h, g.w, g.w / 2 + 1);
        let c2r = RealFftPlanner::<f32>::new().plan_fft_inverse(w);
        let col = FftPlanner::<f32>::new().plan_fft_inverse(h);
        let mut tmp = spec.to_vec();
        col.process(&mut tmp);
        let norm = 1.0 / (h * w) as f32;
        let mut out = vec![f32::NAN; h * w];
        let mut row_spec = vec![Complex32::default(); wc];
        let mut row = vec![0.0; w];
        for r in r0..r1 {
            for (kx, v) in row_spec.iter_mut().enumerate() {
                *v = tmp[kx * h + r];
            }
            row_spec[0].im = 0.0;
            if w.is_multiple_of(2) {
                row_spec[wc - 1].im = 0.0;
            }
            c2r.process(&mut row_spec, &mut row).unwrap();
            for (o, v) in out[r * w..(r + 1) * w].iter_mut().zip(&row) {
                *o = v * norm;
            }
        }
        out
    }

    fn same_bits(a: &[f32], b: &[f32]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(p, q)| p.to_bits() == q.to_bits())
    }

    #[test]
    fn batched_rows_give_the_per_row_transforms_bits() {
        // Every width class: odd, W/2 odd, W/2 even (with and without a middle bin), the
        // tiny ones, and the dev set's grids (28, 41, 60).
        let cases = (1..=130).map(|w| (w, 3)).chain(
            [27, 28, 41, 60, 64]
                .into_iter()
                .flat_map(|w| [1, 2, 5, 28, 60].map(|h| (w, h))),
        );
        for (w, h) in cases {
            let g = GridSize { h, w };
            let x: Vec<f32> = (0..h * w)
                .map(|i| ((i as u32).wrapping_mul(2_654_435_761) % 2001) as f32 / 97.0 - 10.0)
                .collect();
            let mut fft = Fft2::new(g);
            let rows = [(0, h), (h / 3, h - h / 4), (h / 2, h / 2)];
            for (r0, r1) in rows {
                // Rows of `x` outside r0..r1 are not zero: neither transform may read them.
                let mut spec = vec![Complex32::new(7.0, 7.0); fft.spectrum_len()];
                fft.forward_rows(&x, r0, r1, &mut spec);
                let want = per_row_forward(&x, g, r0, r1);
                let flat =
                    |s: &[Complex32]| s.iter().flat_map(|v| [v.re, v.im]).collect::<Vec<_>>();
                assert!(
                    same_bits(&flat(&spec), &flat(&want)),
                    "forward {h}x{w} rows {r0}..{r1}"
                );
                let mut out = vec![f32::NAN; h * w];
                fft.inverse_rows(&spec, r0, r1, &mut out);
                let want = per_row_inverse(&spec, g, r0, r1);
                assert!(same_bits(&out, &want), "inverse {h}x{w} rows {r0}..{r1}");
            }
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
