//! The kernels of [`super::Plan`]'s steps: plain loops over row-major f32 buffers, matrix
//! products through nalgebra (which hands f32 products larger than 5 × 5 to the
//! `matrixmultiply` crate's blocked kernels, AVX / FMA chosen at run time), depthwise
//! convolutions through [`crate::redetect::dwconv`].

use nalgebra::{DMatrixView, DMatrixViewMut};

/// `c[m×n] = alpha · a[m×k] · b[k×n] + beta · c`, each operand given by its slice and its
/// `(row stride, column stride)` in elements (`c` row-major, contiguous).
///
/// The slices must hold the strided matrices (the callers size them at plan time).
#[allow(clippy::too_many_arguments)]
pub(super) fn gemm(
    (m, k, n): (usize, usize, usize),
    a: &[f32],
    (ras, cas): (usize, usize),
    b: &[f32],
    (rbs, cbs): (usize, usize),
    (alpha, beta): (f32, f32),
    c: &mut [f32],
) {
    if m == 0 || n == 0 {
        return;
    }
    if m <= SMALL || n <= SMALL || k <= SMALL {
        // nalgebra computes these itself, and its loop indexes strided (row-major) views
        // out of bounds (a debug assertion in nalgebra 0.34.2); a plain loop instead.
        for (i, row) in c.chunks_exact_mut(n).take(m).enumerate() {
            if beta == 0.0 {
                row.fill(0.0);
            } else if beta != 1.0 {
                row.iter_mut().for_each(|v| *v *= beta);
            }
            for p in 0..k {
                let w = alpha * a[i * ras + p * cas];
                let start = p * rbs;
                if cbs == 1 {
                    let br = &b[start..start + n];
                    row.iter_mut().zip(br).for_each(|(v, &x)| *v += w * x);
                } else {
                    for (j, v) in row.iter_mut().enumerate() {
                        *v += w * b[start + j * cbs];
                    }
                }
            }
        }
        return;
    }
    let mut cv = DMatrixViewMut::from_slice_with_strides_mut(c, m, n, n, 1);
    let av = DMatrixView::from_slice_with_strides(a, m, k, ras, cas);
    let bv = DMatrixView::from_slice_with_strides(b, k, n, rbs, cbs);
    cv.gemm(alpha, &av, &bv, beta);
}

/// Largest dimension nalgebra multiplies itself (its `SMALL_DIM`); larger products go to
/// `matrixmultiply`.
const SMALL: usize = 5;

/// An elementwise function of one input.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Unary {
    /// `max(x, 0)`.
    Relu,
    /// `1 / (1 + e^−x)`.
    Sigmoid,
    /// `e^x`.
    Exp,
    /// `max(0, min(1, αx + β))`.
    HardSigmoid(f32, f32),
    /// `x · max(0, min(1, x/6 + 1/2))`.
    HardSwish,
    /// `min(max(x, lo), hi)`.
    Clip(f32, f32),
}

/// `y = f(x)`.
#[multiversion::multiversion(targets("x86_64+avx2+fma"))] // AVX2 clone, chosen at run time
pub(super) fn unary(f: Unary, x: &[f32], y: &mut [f32]) {
    let it = y.iter_mut().zip(x);
    match f {
        Unary::Relu => it.for_each(|(y, &x)| *y = x.max(0.0)),
        Unary::Sigmoid => it.for_each(|(y, &x)| *y = 1.0 / (1.0 + (-x).exp())),
        Unary::Exp => it.for_each(|(y, &x)| *y = x.exp()),
        Unary::HardSigmoid(a, b) => it.for_each(|(y, &x)| *y = (a * x + b).clamp(0.0, 1.0)),
        Unary::HardSwish => {
            let (a, b) = (1.0 / 6.0, 0.5);
            it.for_each(|(y, &x)| *y = x * (a * x + b).clamp(0.0, 1.0));
        }
        Unary::Clip(lo, hi) => it.for_each(|(y, &x)| *y = x.max(lo).min(hi)),
    }
}

/// `y = f(y)` (an activation fused into the step that wrote `y`).
#[multiversion::multiversion(targets("x86_64+avx2+fma"))]
pub(super) fn unary_in_place(f: Unary, y: &mut [f32]) {
    match f {
        Unary::Relu => y.iter_mut().for_each(|y| *y = y.max(0.0)),
        Unary::Sigmoid => y.iter_mut().for_each(|y| *y = 1.0 / (1.0 + (-*y).exp())),
        Unary::Exp => y.iter_mut().for_each(|y| *y = y.exp()),
        Unary::HardSigmoid(a, b) => y.iter_mut().for_each(|y| *y = (a * *y + b).clamp(0.0, 1.0)),
        Unary::HardSwish => {
            let (a, b) = (1.0 / 6.0, 0.5);
            y.iter_mut()
                .for_each(|y| *y *= (a * *y + b).clamp(0.0, 1.0));
        }
        Unary::Clip(lo, hi) => y.iter_mut().for_each(|y| *y = y.max(lo).min(hi)),
    }
}

/// An elementwise function of two inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Binary {
    /// `a + b`.
    Add,
    /// `a − b`.
    Sub,
    /// `a · b`.
    Mul,
    /// `a / b`.
    Div,
}

impl Binary {
    #[inline(always)]
    fn f(self, a: f32, b: f32) -> f32 {
        match self {
            Binary::Add => a + b,
            Binary::Sub => a - b,
            Binary::Mul => a * b,
            Binary::Div => a / b,
        }
    }
}

/// A broadcast binary operation, its dimensions merged where both operands allow (see
/// [`Broadcast::new`]).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Broadcast {
    /// Output dimensions (merged), the last one innermost.
    dims: Vec<usize>,
    /// Strides of `a` per merged dimension (0: broadcast).
    sa: Vec<usize>,
    /// Strides of `b`.
    sb: Vec<usize>,
}

/// Row-major strides of `shape` aligned right to `rank` dimensions, 0 where `shape` has
/// size 1 or lacks the dimension (numpy broadcasting).
fn broadcast_strides(shape: &[usize], out: &[usize]) -> Vec<usize> {
    let rank = out.len();
    let mut s = vec![0; rank];
    let mut acc = 1;
    for (i, &d) in shape.iter().enumerate().rev() {
        let o = rank - (shape.len() - i);
        s[o] = if d == 1 { 0 } else { acc };
        acc *= d;
    }
    s
}

impl Broadcast {
    /// The output shape of `a ∘ b` under numpy broadcasting, and the operation, or `None`
    /// when the shapes do not broadcast.
    pub(super) fn new(a: &[usize], b: &[usize]) -> Option<(Vec<usize>, Self)> {
        let rank = a.len().max(b.len());
        let dim = |s: &[usize], i: usize| {
            if i + s.len() >= rank {
                s[i + s.len() - rank]
            } else {
                1
            }
        };
        let mut out = Vec::with_capacity(rank);
        for i in 0..rank {
            let (x, y) = (dim(a, i), dim(b, i));
            out.push(match (x, y) {
                _ if x == y => x,
                (1, y) => y,
                (x, 1) => x,
                _ => return None,
            });
        }
        let (sa, sb) = (broadcast_strides(a, &out), broadcast_strides(b, &out));
        // Merge dimension i into i + 1 when both operands step through them as one.
        let (mut dims, mut ma, mut mb) = (Vec::new(), Vec::new(), Vec::new());
        for i in 0..rank {
            if out[i] == 1 {
                continue;
            }
            if let (Some(&d), Some(&pa), Some(&pb)) = (dims.last(), ma.last(), mb.last()) {
                if pa == sa[i] * out[i] && pb == sb[i] * out[i] {
                    let last = dims.len() - 1;
                    dims[last] = d * out[i];
                    ma[last] = sa[i];
                    mb[last] = sb[i];
                    continue;
                }
            }
            dims.push(out[i]);
            ma.push(sa[i]);
            mb.push(sb[i]);
        }
        if dims.is_empty() {
            dims.push(1);
            ma.push(0);
            mb.push(0);
        }
        Some((
            out,
            Self {
                dims,
                sa: ma,
                sb: mb,
            },
        ))
    }

    /// `y = a ∘ b`.
    pub(super) fn apply(&self, op: Binary, a: &[f32], b: &[f32], y: &mut [f32]) {
        let last = self.dims.len() - 1;
        let inner = self.dims[last];
        let (ia, ib) = (self.sa[last], self.sb[last]);
        let mut idx = vec![0usize; last];
        for row in y.chunks_exact_mut(inner) {
            let oa: usize = idx.iter().zip(&self.sa).map(|(i, s)| i * s).sum();
            let ob: usize = idx.iter().zip(&self.sb).map(|(i, s)| i * s).sum();
            match (ia, ib) {
                (1, 1) => {
                    let it = row
                        .iter_mut()
                        .zip(&a[oa..oa + inner])
                        .zip(&b[ob..ob + inner]);
                    it.for_each(|((y, &a), &b)| *y = op.f(a, b));
                }
                (1, 0) => {
                    let s = b[ob];
                    let it = row.iter_mut().zip(&a[oa..oa + inner]);
                    it.for_each(|(y, &a)| *y = op.f(a, s));
                }
                (0, 1) => {
                    let s = a[oa];
                    let it = row.iter_mut().zip(&b[ob..ob + inner]);
                    it.for_each(|(y, &b)| *y = op.f(s, b));
                }
                _ => {
                    for (j, y) in row.iter_mut().enumerate() {
                        *y = op.f(a[oa + j * ia], b[ob + j * ib]);
                    }
                }
            }
            // Next outer index, last dimension fastest.
            for d in (0..last).rev() {
                idx[d] += 1;
                if idx[d] < self.dims[d] {
                    break;
                }
                idx[d] = 0;
            }
        }
    }
}

/// Geometry of a convolution over one batch item.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct ConvShape {
    /// Input channels, height, width.
    pub(super) c: usize,
    pub(super) h: usize,
    pub(super) w: usize,
    /// Output channels, height, width.
    pub(super) m: usize,
    pub(super) oh: usize,
    pub(super) ow: usize,
    /// Kernel height and width.
    pub(super) kh: usize,
    pub(super) kw: usize,
    /// Strides (vertical, horizontal).
    pub(super) sh: usize,
    pub(super) sw: usize,
    /// Zero padding above and left.
    pub(super) pt: usize,
    pub(super) pl: usize,
    /// Groups.
    pub(super) groups: usize,
}

/// `col[(ci·kh + ky)·kw + kx][oy·ow + ox]` = the input value under tap `(ky, kx)` of output
/// `(oy, ox)` for input channel `ci` of `x` (`cg` planes), zero outside.
pub(super) fn im2col(s: &ConvShape, cg: usize, x: &[f32], col: &mut [f32]) {
    let plane = s.oh * s.ow;
    for ci in 0..cg {
        let src = &x[ci * s.h * s.w..(ci + 1) * s.h * s.w];
        for ky in 0..s.kh {
            for kx in 0..s.kw {
                let row = ((ci * s.kh + ky) * s.kw + kx) * plane;
                let dst = &mut col[row..row + plane];
                // Output columns whose input column ox·sw + kx − pl lies in [0, w).
                let first = s.pl.saturating_sub(kx).div_ceil(s.sw).min(s.ow);
                let end = (s.w + s.pl)
                    .checked_sub(kx)
                    .map_or(0, |v| v.div_ceil(s.sw))
                    .clamp(first, s.ow);
                for (oy, out) in dst.chunks_exact_mut(s.ow).enumerate() {
                    let y = (oy * s.sh + ky).checked_sub(s.pt).filter(|&y| y < s.h);
                    let Some(y) = y else {
                        out.fill(0.0);
                        continue;
                    };
                    out[..first].fill(0.0);
                    out[end..].fill(0.0);
                    if first < end {
                        let x0 = first * s.sw + kx - s.pl;
                        let line = &src[y * s.w + x0..];
                        let taps = line.iter().step_by(s.sw);
                        for (o, &v) in out[first..end].iter_mut().zip(taps) {
                            *o = v;
                        }
                    }
                }
            }
        }
    }
}

/// Fills each of `y`'s `rows` rows of `len` values with its bias.
pub(super) fn fill_bias(y: &mut [f32], bias: &[f32], len: usize) {
    for (row, &b) in y.chunks_exact_mut(len).zip(bias) {
        row.fill(b);
    }
}

/// `y[i] = mean of x's i-th run of `len` values`.
pub(super) fn mean_pool(x: &[f32], len: usize, y: &mut [f32]) {
    for (y, run) in y.iter_mut().zip(x.chunks_exact(len)) {
        *y = run.iter().sum::<f32>() / len as f32;
    }
}

/// `y` = `x` (of `shape`) with its dimensions permuted by `perm`.
pub(super) fn transpose(x: &[f32], shape: &[usize], perm: &[usize], y: &mut [f32]) {
    let rank = shape.len();
    let mut xs = vec![1usize; rank];
    for i in (0..rank.saturating_sub(1)).rev() {
        xs[i] = xs[i + 1] * shape[i + 1];
    }
    let out: Vec<usize> = perm.iter().map(|&p| shape[p]).collect();
    let src: Vec<usize> = perm.iter().map(|&p| xs[p]).collect();
    let mut idx = vec![0usize; rank];
    for v in y.iter_mut() {
        *v = x[idx.iter().zip(&src).map(|(i, s)| i * s).sum::<usize>()];
        for d in (0..rank).rev() {
            idx[d] += 1;
            if idx[d] < out[d] {
                break;
            }
            idx[d] = 0;
        }
    }
}
