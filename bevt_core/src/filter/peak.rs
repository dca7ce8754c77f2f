//! Peak finding: integer arg-max, then Newton's method on the response's Fourier series
//! (the reference's `resp_newton`), for sub-cell translation.

use crate::fft::signed_freq;
use crate::geometry::GridSize;
use rustfft::num_complex::Complex32;
use std::f32::consts::PI;

/// Newton steps smaller than this (radians of phase) end the iteration: further steps
/// cannot move the peak measurably.
const NEWTON_TOLERANCE: f32 = 1e-6;

/// A response peak.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Peak {
    /// Row displacement, cells, in `[−H/2, H/2)`.
    pub dy: f32,
    /// Column displacement, cells, in `[−W/2, W/2)`.
    pub dx: f32,
    /// Response value at the peak.
    pub score: f32,
}

/// Scratch for [`subpixel_peak`].
#[derive(Debug, Clone, Default)]
pub struct NewtonScratch {
    a0: Vec<Complex32>,
    a1: Vec<Complex32>,
    a2: Vec<Complex32>,
    ex: Vec<Complex32>,
}

/// Integer arg-max of a row-major map: `(row, col, value)`. NaNs are ignored.
pub fn argmax(map: &[f32], grid: GridSize) -> (usize, usize, f32) {
    let mut best = (0usize, f32::NEG_INFINITY);
    for (i, &v) in map[..grid.len()].iter().enumerate() {
        if v > best.1 {
            best = (i, v);
        }
    }
    if !best.1.is_finite() {
        return (0, 0, 0.0);
    }
    (best.0 / grid.w, best.0 % grid.w, best.1)
}

/// Displacement, cells, of index `i` of an `n`-long unshifted response axis from the
/// window centre (index 0), wrapped into `[−(n−1)/2, n/2]`: the integer peak
/// [`subpixel_peak`] starts from.
pub fn displacement(i: usize, n: usize) -> f32 {
    let half = n.saturating_sub(1) / 2;
    ((i + half) % n.max(1)) as f32 - half as f32
}

/// Sub-cell peak of a response given spatially (`resp`, row-major, as `ifft2`) and as its
/// half spectrum (`resp_f`, layout of [`crate::fft`]).
///
/// Starts at the integer maximum and runs at most `iterations` Newton steps on
/// `f(y, x) = (1/T)·Re Σ R(k_y, k_x) e^{i(k_y y + k_x x)}`; if the result does not score
/// higher than the start, the start is kept.
pub fn subpixel_peak(
    resp: &[f32],
    resp_f: &[Complex32],
    grid: GridSize,
    iterations: usize,
    scratch: &mut NewtonScratch,
) -> Peak {
    let (h, w) = (grid.h, grid.w);
    let wc = w / 2 + 1;
    let (row, col, init_score) = argmax(resp, grid);
    let y0 = 2.0 * PI * displacement(row, h) / h as f32;
    let x0 = 2.0 * PI * displacement(col, w) / w as f32;
    scratch.a0.resize(h, Complex32::default());
    scratch.a1.resize(h, Complex32::default());
    scratch.a2.resize(h, Complex32::default());
    scratch.ex.resize(wc, Complex32::default());
    let t = grid.len() as f32;
    let (mut y, mut x) = (y0, x0);
    let eval = |y: f32, x: f32, s: &mut NewtonScratch, derivs: bool| {
        for (kx, e) in s.ex.iter_mut().enumerate() {
            // Half-spectrum weight: interior columns stand for themselves and their mirror.
            let wgt = if kx == 0 || (w % 2 == 0 && kx == wc - 1) {
                1.0
            } else {
                2.0
            };
            *e = Complex32::from_polar(wgt, kx as f32 * x);
        }
        for ky in 0..h {
            s.a0[ky] = Complex32::default();
            s.a1[ky] = Complex32::default();
            s.a2[ky] = Complex32::default();
        }
        for kx in 0..wc {
            let e = s.ex[kx];
            let kxf = kx as f32;
            let colf = &resp_f[kx * h..(kx + 1) * h];
            if derivs {
                for ky in 0..h {
                    let v = colf[ky] * e;
                    s.a0[ky] += v;
                    s.a1[ky] += v * kxf;
                    s.a2[ky] += v * (kxf * kxf);
                }
            } else {
                for ky in 0..h {
                    s.a0[ky] += colf[ky] * e;
                }
            }
        }
        let mut f = 0.0f32;
        let (mut gy, mut gx, mut gyy, mut gxx, mut gxy) = (0.0f32, 0.0, 0.0, 0.0, 0.0);
        for ky in 0..h {
            let k = signed_freq(ky, h);
            let ey = Complex32::from_polar(1.0, k * y);
            let v0 = ey * s.a0[ky];
            f += v0.re;
            if derivs {
                let v1 = ey * s.a1[ky];
                let v2 = ey * s.a2[ky];
                gy -= k * v0.im;
                gyy -= k * k * v0.re;
                gx -= v1.im;
                gxx -= v2.re;
                gxy -= k * v1.re;
            }
        }
        (f / t, [gy, gx, gyy, gxx, gxy])
    };
    for _ in 0..iterations {
        let (_, [gy, gx, gyy, gxx, gxy]) = eval(y, x, scratch, true);
        let det = gyy * gxx - gxy * gxy;
        if det == 0.0 || !det.is_finite() {
            break;
        }
        let sy = (gxx * gy - gxy * gx) / det;
        let sx = (gyy * gx - gxy * gy) / det;
        if !sy.is_finite() || !sx.is_finite() {
            break;
        }
        y -= sy;
        x -= sx;
        if sy.abs() < NEWTON_TOLERANCE && sx.abs() < NEWTON_TOLERANCE {
            break;
        }
    }
    let (score, _) = eval(y, x, scratch, false);
    let (y, x, score) = if score.is_finite() && score >= init_score {
        (y, x, score)
    } else {
        (y0, x0, init_score)
    };
    let unwrap = |p: f32, n: usize| ((p + PI).rem_euclid(2.0 * PI) - PI) / (2.0 * PI) * n as f32;
    Peak {
        dy: unwrap(y, h),
        dx: unwrap(x, w),
        score,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fft::Fft2;
    use proptest::prelude::*;

    /// A smooth periodic peak (Gaussian, σ in cells) centred at a sub-cell offset.
    fn synthetic(grid: GridSize, cy: f32, cx: f32, sigma: f32) -> Vec<f32> {
        let mut m = vec![0.0; grid.len()];
        for r in 0..grid.h {
            for c in 0..grid.w {
                let mut acc = 0.0;
                for wy in -1i32..=1 {
                    for wx in -1i32..=1 {
                        let dy = r as f32 - cy + (wy * grid.h as i32) as f32;
                        let dx = c as f32 - cx + (wx * grid.w as i32) as f32;
                        acc += (-(dy * dy + dx * dx) / (2.0 * sigma * sigma)).exp();
                    }
                }
                m[r * grid.w + c] = acc;
            }
        }
        m
    }

    proptest! {
        #[test]
        fn newton_recovers_a_known_subcell_shift(dy in -8.0f32..8.0, dx in -8.0f32..8.0) {
            let grid = GridSize { h: 40, w: 40 };
            let m = synthetic(grid, dy.rem_euclid(40.0), dx.rem_euclid(40.0), 2.0);
            let mut fft = Fft2::new(grid);
            let mut f = vec![Complex32::default(); fft.spectrum_len()];
            fft.forward(&m, &mut f);
            let p = subpixel_peak(&m, &f, grid, 50, &mut NewtonScratch::default());
            prop_assert!((p.dy - dy).abs() < 0.05, "dy {} vs {}", p.dy, dy);
            prop_assert!((p.dx - dx).abs() < 0.05, "dx {} vs {}", p.dx, dx);
            prop_assert!(p.score >= 0.99);
        }
    }

    #[test]
    fn flat_response_keeps_the_integer_peak() {
        let grid = GridSize { h: 8, w: 8 };
        let m = vec![0.0; 64];
        let f = vec![Complex32::default(); 8 * 5];
        let p = subpixel_peak(&m, &f, grid, 50, &mut NewtonScratch::default());
        assert_eq!((p.dy, p.dx, p.score), (0.0, 0.0, 0.0));
    }

    #[test]
    fn argmax_ignores_nan() {
        let g = GridSize { h: 1, w: 3 };
        assert_eq!(argmax(&[f32::NAN, 2.0, 1.0], g), (0, 1, 2.0));
    }
}
