//! The Gaussian regression target, the cosine (Hann) window and the spatial
//! regularisation window (ALGORITHM.md §§2–4).

use crate::fft::signed_freq;
use crate::geometry::{GridSize, Size2};

/// Gaussian label on `grid` with its peak at index (0, 0) (circularly shifted):
/// `y(r, c) = exp(−(r'² + c'²) / (2σ²))`, `r'`, `c'` the signed circular offsets.
pub fn gaussian_label(grid: GridSize, sigma: f32, out: &mut [f32]) {
    let s2 = 2.0 * sigma * sigma;
    for r in 0..grid.h {
        let rr = signed_freq(r, grid.h);
        for c in 0..grid.w {
            let cc = signed_freq(c, grid.w);
            out[r * grid.w + c] = (-(rr * rr + cc * cc) / s2).exp();
        }
    }
}

/// Label bandwidth σ (cells): `sqrt(⌊w/cell⌋·⌊h/cell⌋) · factor` for the base target size.
pub fn label_sigma(base_target: Size2, cell: usize, factor: f32) -> f32 {
    let c = cell as f32;
    ((base_target.w / c).floor() * (base_target.h / c).floor())
        .max(1.0)
        .sqrt()
        * factor
}

/// MATLAB's symmetric `hann(n)`: `0.5·(1 − cos(2πk/(n−1)))` (1 for `n = 1`).
pub fn hann(n: usize) -> Vec<f32> {
    if n == 1 {
        return vec![1.0];
    }
    (0..n)
        .map(|k| {
            0.5 * (1.0 - (2.0 * std::f64::consts::PI * k as f64 / (n - 1) as f64).cos()) as f32
        })
        .collect()
}

/// 2-D Hann window `hann(h) · hann(w)ᵀ`, row-major.
pub fn hann2d(grid: GridSize) -> Vec<f32> {
    let a = hann(grid.h);
    let b = hann(grid.w);
    a.iter()
        .flat_map(|&u| b.iter().map(move |&v| u * v))
        .collect()
}

/// Quadratic bowl regulariser on the grid, centred on the grid centre:
/// `(edge − min)·((r/ρ_r)² + (c/ρ_c)²) + min`, `r, c ∈ −(n−1)/2 … (n−1)/2`,
/// `ρ = 0.5 · base_target / cell`.
pub fn reg_window(
    grid: GridSize,
    base_target: Size2,
    cell: usize,
    min: f32,
    edge: f32,
) -> Vec<f32> {
    let rho_r = (0.5 * base_target.h / cell as f32).max(1e-3);
    let rho_c = (0.5 * base_target.w / cell as f32).max(1e-3);
    let mut out = vec![0.0; grid.len()];
    for r in 0..grid.h {
        let rr = r as f32 - (grid.h as f32 - 1.0) / 2.0;
        for c in 0..grid.w {
            let cc = c as f32 - (grid.w as f32 - 1.0) / 2.0;
            out[r * grid.w + c] =
                (edge - min) * ((rr / rho_r).powi(2) + (cc / rho_c).powi(2)) + min;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn label_peaks_at_origin_and_is_circularly_symmetric() {
        let g = GridSize { h: 10, w: 10 };
        let mut y = vec![0.0; 100];
        gaussian_label(g, 1.5, &mut y);
        assert_eq!(y[0], 1.0);
        assert!((y[1] - y[9]).abs() < 1e-6);
        assert!((y[10] - y[90]).abs() < 1e-6);
        assert!(y.iter().all(|&v| v <= 1.0 && v > 0.0));
    }

    #[test]
    fn hann_matches_matlab_symmetric_window() {
        let h = hann(5);
        let want = [0.0, 0.5, 1.0, 0.5, 0.0];
        for (a, b) in h.iter().zip(want) {
            assert!((a - b).abs() < 1e-6);
        }
    }

    #[test]
    fn reg_window_is_min_at_centre_and_grows_outward() {
        let g = GridSize { h: 11, w: 11 };
        let w = reg_window(g, Size2 { w: 8.0, h: 8.0 }, 1, 0.1, 0.8);
        assert!((w[5 * 11 + 5] - 0.1).abs() < 1e-6);
        assert!(w[0] > w[5 * 11 + 3]);
    }

    #[test]
    fn sigma_uses_floored_cell_sizes() {
        let s = label_sigma(Size2 { w: 41.0, h: 17.0 }, 4, 1.0 / 16.0);
        assert!((s - (10.0f32 * 4.0).sqrt() / 16.0).abs() < 1e-6);
    }
}
