//! Sub-cell circular shifts of feature spectra (the Fourier shift theorem), so a training
//! sample can be taken from the detection sample instead of a fresh patch (as ECO's
//! `shift_sample`).

use crate::fft::signed_freq;
use crate::geometry::GridSize;
use rustfft::num_complex::Complex32;

/// Writes into `phase` (one value per bin of a half spectrum in the layout of
/// [`crate::fft`]: `W/2 + 1` columns of `H` rows) the factors
/// `exp(2πi·(k_y·dy/H + k_x·dx/W))` that turn the spectrum of `x(r, c)` into that of
/// `x(r + dy, c + dx)` (circularly; `dy`, `dx` in cells, fractional allowed).
pub fn shift_phase(grid: GridSize, dy: f32, dx: f32, phase: &mut [Complex32]) {
    let (h, w) = (grid.h, grid.w);
    let wc = w / 2 + 1;
    let tau = std::f32::consts::TAU;
    for (kx, col) in phase.chunks_exact_mut(h).take(wc).enumerate() {
        let ax = tau * kx as f32 * dx / w as f32;
        for (ky, p) in col.iter_mut().enumerate() {
            let a = ax + tau * signed_freq(ky, h) * dy / h as f32;
            *p = Complex32::new(a.cos(), a.sin());
        }
    }
}

/// `out[d] = x[d] ⊙ phase` for every channel `d` (spectra of `phase.len()` bins each).
pub fn apply_phase(x: &[Complex32], phase: &[Complex32], out: &mut [Complex32]) {
    let bins = phase.len().max(1);
    for (o, s) in out.chunks_exact_mut(bins).zip(x.chunks_exact(bins)) {
        for ((o, s), p) in o.iter_mut().zip(s).zip(phase) {
            *o = s * p;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fft::Fft2;

    #[test]
    fn integer_shift_equals_a_circular_roll() {
        let grid = GridSize { h: 6, w: 8 };
        let mut fft = Fft2::new(grid);
        let bins = fft.spectrum_len();
        let x: Vec<f32> = (0..48).map(|i| ((i * 37) % 11) as f32).collect();
        let mut xf = vec![Complex32::default(); bins];
        fft.forward(&x, &mut xf);
        let mut phase = vec![Complex32::default(); bins];
        shift_phase(grid, 2.0, -3.0, &mut phase);
        let mut yf = vec![Complex32::default(); bins];
        apply_phase(&xf, &phase, &mut yf);
        let mut y = vec![0.0; 48];
        fft.inverse(&yf, &mut y);
        for r in 0..6 {
            for c in 0..8 {
                let want = x[((r + 2) % 6) * 8 + (c + 8 - 3) % 8];
                assert!((y[r * 8 + c] - want).abs() < 1e-3, "{r} {c}");
            }
        }
    }
}
