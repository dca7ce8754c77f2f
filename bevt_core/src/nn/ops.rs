//! The kernels of [`super::Plan`]'s steps: plain loops over row-major f32 buffers; one-group
//! convolutions by [`rows_product`] (8 × 8 outputs summed in registers, the weights packed
//! once at plan time, AVX2 / FMA chosen at run time); `MatMul`, `Gemm` and grouped
//! convolutions through nalgebra (which hands f32 products larger than 5 × 5 to the
//! `matrixmultiply` crate's blocked kernels); depthwise convolutions through
//! [`crate::redetect::dwconv`].

use crate::redetect::dwconv::copy_short;
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
    if computes_itself(m, k, n) {
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

/// Whether [`gemm`] computes an `m × k` by `k × n` product in its own loop (a dimension of
/// at most [`SMALL`]) rather than through nalgebra.
pub(super) fn computes_itself(m: usize, k: usize, n: usize) -> bool {
    m <= SMALL || n <= SMALL || k <= SMALL
}

/// An elementwise function of one input.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Unary {
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

impl Unary {
    /// `f(x)`: the one formula every kernel applies.
    #[inline(always)]
    pub(super) fn eval(self, x: f32) -> f32 {
        match self {
            Unary::Relu => x.max(0.0),
            Unary::Sigmoid => 1.0 / (1.0 + (-x).exp()),
            Unary::Exp => x.exp(),
            Unary::HardSigmoid(a, b) => (a * x + b).clamp(0.0, 1.0),
            Unary::HardSwish => x * (x * (1.0 / 6.0) + 0.5).clamp(0.0, 1.0),
            Unary::Clip(lo, hi) => x.max(lo).min(hi),
        }
    }
}

/// `y = f(x)`.
#[multiversion::multiversion(targets("x86_64+avx2+fma"))] // AVX2 clone, chosen at run time
pub(super) fn unary(f: Unary, x: &[f32], y: &mut [f32]) {
    // One loop per function, so that each is vectorised with the function inlined.
    let it = y.iter_mut().zip(x);
    match f {
        Unary::Relu => it.for_each(|(y, &x)| *y = Unary::Relu.eval(x)),
        Unary::Sigmoid => it.for_each(|(y, &x)| *y = Unary::Sigmoid.eval(x)),
        Unary::Exp => it.for_each(|(y, &x)| *y = Unary::Exp.eval(x)),
        Unary::HardSigmoid(..) | Unary::Clip(..) | Unary::HardSwish => {
            it.for_each(|(y, &x)| *y = f.eval(x));
        }
    }
}

/// `y = f(y)` (an activation fused into the step that wrote `y`).
#[multiversion::multiversion(targets("x86_64+avx2+fma"))]
pub(super) fn unary_in_place(f: Unary, y: &mut [f32]) {
    apply_in_place(f, y);
}

/// [`unary_in_place`]'s loops, inlined into the kernels that store activated values.
#[inline(always)]
fn apply_in_place(f: Unary, y: &mut [f32]) {
    // One loop per function, so that each is vectorised with the function inlined.
    match f {
        Unary::Relu => y.iter_mut().for_each(|y| *y = Unary::Relu.eval(*y)),
        Unary::Sigmoid => y.iter_mut().for_each(|y| *y = Unary::Sigmoid.eval(*y)),
        Unary::Exp => y.iter_mut().for_each(|y| *y = Unary::Exp.eval(*y)),
        Unary::HardSigmoid(..) | Unary::Clip(..) | Unary::HardSwish => {
            y.iter_mut().for_each(|y| *y = f.eval(*y));
        }
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

/// Which operand of a broadcast product scales whole planes: `Some(true)` when `a` holds
/// `channels` planes of `plane` values and `b` one factor per plane (`[1, C, H, W] ·
/// [1, C, 1, 1]`, a squeeze-excitation layer's channel scale), `Some(false)` the other way
/// round, `None` for any other broadcast.
pub(super) fn plane_scale(bc: &Broadcast, channels: usize, plane: usize) -> Option<bool> {
    if bc.dims != [channels, plane] || plane == 1 {
        return None;
    }
    match (bc.sa.as_slice(), bc.sb.as_slice()) {
        ([p, 1], [1, 0]) if *p == plane => Some(true),
        ([1, 0], [p, 1]) if *p == plane => Some(false),
        _ => None,
    }
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

    /// `y = act(a ∘ b)`, the activation applied to each row of the innermost dimension as
    /// it is written (while in cache).
    pub(super) fn apply(
        &self,
        op: Binary,
        a: &[f32],
        b: &[f32],
        act: Option<Unary>,
        y: &mut [f32],
    ) {
        broadcast_rows(self, op, a, b, act, y);
    }
}

/// [`Broadcast::apply`]'s loops, compiled for the baseline and with AVX2 + FMA (chosen at
/// run time), once per operation so that each loop vectorises with it inlined.
#[multiversion::multiversion(targets("x86_64+avx2+fma"))]
fn broadcast_rows(
    bc: &Broadcast,
    op: Binary,
    a: &[f32],
    b: &[f32],
    act: Option<Unary>,
    y: &mut [f32],
) {
    match op {
        Binary::Add => bc.rows(|a, b| Binary::Add.f(a, b), a, b, act, y),
        Binary::Sub => bc.rows(|a, b| Binary::Sub.f(a, b), a, b, act, y),
        Binary::Mul => bc.rows(|a, b| Binary::Mul.f(a, b), a, b, act, y),
        Binary::Div => bc.rows(|a, b| Binary::Div.f(a, b), a, b, act, y),
    }
}

impl Broadcast {
    /// The loops of [`Self::apply`], `f` the operation.
    #[inline(always)]
    fn rows(
        &self,
        f: impl Fn(f32, f32) -> f32,
        a: &[f32],
        b: &[f32],
        act: Option<Unary>,
        y: &mut [f32],
    ) {
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
                    it.for_each(|((y, &a), &b)| *y = f(a, b));
                }
                (1, 0) => {
                    let s = b[ob];
                    let it = row.iter_mut().zip(&a[oa..oa + inner]);
                    it.for_each(|(y, &a)| *y = f(a, s));
                }
                (0, 1) => {
                    let s = a[oa];
                    let it = row.iter_mut().zip(&b[ob..ob + inner]);
                    it.for_each(|(y, &b)| *y = f(s, b));
                }
                _ => {
                    for (j, y) in row.iter_mut().enumerate() {
                        *y = f(a[oa + j * ia], b[ob + j * ib]);
                    }
                }
            }
            if let Some(f) = act {
                apply_in_place(f, row);
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

/// `out[ox]` = the input value of plane `src` under tap `(ky, kx)` of output `(oy, ox)`,
/// zero outside (`out` holds one output row).
#[inline(always)] // into each clone of `im2col` and `im2col_row`
fn tap_row(s: &ConvShape, src: &[f32], (ky, kx): (usize, usize), oy: usize, out: &mut [f32]) {
    let y = (oy * s.sh + ky).checked_sub(s.pt).filter(|&y| y < s.h);
    let Some(y) = y else {
        out.fill(0.0);
        return;
    };
    // Output columns whose input column ox·sw + kx − pl lies in [0, w).
    let first = s.pl.saturating_sub(kx).div_ceil(s.sw).min(s.ow);
    let end = (s.w + s.pl)
        .checked_sub(kx)
        .map_or(0, |v| v.div_ceil(s.sw))
        .clamp(first, s.ow);
    out[..first].fill(0.0);
    out[end..].fill(0.0);
    if first < end {
        let x0 = first * s.sw + kx - s.pl;
        let line = &src[y * s.w + x0..(y + 1) * s.w];
        let out = &mut out[first..end];
        if s.sw == 1 {
            out.copy_from_slice(&line[..out.len()]);
        } else if let Some((last, head)) = out.split_last_mut().filter(|_| s.sw == 2) {
            // Every other value: a loop the compiler vectorises with shuffles.
            for (o, pair) in head.iter_mut().zip(line.chunks_exact(2)) {
                *o = pair[0];
            }
            *last = line[2 * head.len()];
        } else {
            for (o, taps) in out.iter_mut().zip(line.chunks(s.sw)) {
                *o = taps[0];
            }
        }
    }
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
                for (oy, out) in dst.chunks_exact_mut(s.ow).enumerate() {
                    tap_row(s, src, (ky, kx), oy, out);
                }
            }
        }
    }
}

/// [`im2col`] of output row `oy` alone: `col[(ci·kh + ky)·kw + kx][ox]`, all `s.c` channels.
#[multiversion::multiversion(targets("x86_64+avx2+fma"))] // AVX2 clone: the stride-2 rows' shuffles 8 wide
pub(super) fn im2col_row(s: &ConvShape, x: &[f32], oy: usize, col: &mut [f32]) {
    let mut rows = col.chunks_exact_mut(s.ow);
    for src in x.chunks_exact(s.h * s.w).take(s.c) {
        for ky in 0..s.kh {
            for kx in 0..s.kw {
                if let Some(out) = rows.next() {
                    tap_row(s, src, (ky, kx), oy, out);
                }
            }
        }
    }
}

/// Output channels per block of [`rows_product`]'s packed weights on the AVX-512 kernels, the
/// baseline and aarch64 ([`block_rows`]).
pub(super) const BLOCK_M: usize = 8;
/// Output columns per step of [`rows_product`].
const BLOCK_N: usize = 8;
/// Output columns per step of [`rows_product`]'s AVX2 clone.
const WIDE_N: usize = 16;
/// Rows of a packed block on CPUs with AVX2 and without the AVX-512 kernel: 6 × 16 sums in
/// 12 of AVX2's 16 registers.
const AVX2_BLOCK_M: usize = 6;
/// The most rows of a block ([`block_rows`]): the sums of [`rows_product_narrow`]'s last columns.
const TAIL_ROWS: usize = if BLOCK_M > AVX2_BLOCK_M {
    BLOCK_M
} else {
    AVX2_BLOCK_M
};

/// Columns of the input a 1 × 1 convolution copies together for [`rows_product`]: about
/// 16 KB of input (`k` rows), in whole blocks of 32 (the AVX-512 kernel's widest step), at
/// least one block (at most 32 KB for NanoTrack's widest input, 240 channels: within a
/// 48 KB L1 cache) and at most 256. Its planes' rows lie a power of two apart (64 × 64
/// values: 16 KB), where reading them in place maps every row to the same cache set.
pub(super) fn tile_cols(k: usize) -> usize {
    const BLOCK: usize = 4 * BLOCK_N;
    ((4096 / k.max(1)) / BLOCK * BLOCK).clamp(BLOCK, 256)
}

/// A 1 × 1 convolution of one batch item: `y[i][j] = act(Σ_p w[i][p] · x[p][j] + bias[i])`
/// over planes of `plane` values, by [`rows_product`] on tiles of [`tile_cols`] columns
/// copied into `tile` (at least `k · tile_cols(k)` values).
///
/// With `scale` (one factor per input plane and an activation `g`), `g(x[p][j] · scale[p])`
/// in place of `x[p][j]`, computed as the tile is copied: what a channel-scaling `Mul` step
/// (with `g` fused in) before it would have written, the same values bit for bit (the same
/// product, then [`Unary::eval`]), without writing and reading that product's planes.
#[allow(clippy::too_many_arguments)]
pub(super) fn pointwise(
    (m, k, plane): (usize, usize, usize),
    wp: &[f32],
    x: &[f32],
    scale: Option<(&[f32], Option<Unary>)>,
    bias: &[f32],
    act: Option<Unary>,
    y: &mut [f32],
    tile: &mut [f32],
) {
    let nt = tile_cols(k);
    for j in (0..plane).step_by(nt) {
        let cols = nt.min(plane - j);
        for (p, t) in tile.chunks_exact_mut(cols).take(k).enumerate() {
            let src = &x[p * plane + j..p * plane + j + cols];
            match scale {
                Some((s, g)) => scale_copy(t, src, s[p], g),
                None => copy_short(t, src),
            }
        }
        rows_product((m, k, cols), wp, tile, cols, bias, act, &mut y[j..], plane);
    }
}

/// `dst[i] = g(src[i] · s)`: [`Broadcast::apply`]'s product and activation, on one row
/// (loops the compiler vectorises; AVX2 clone chosen at run time).
#[multiversion::multiversion(targets("x86_64+avx2+fma"))]
fn scale_copy(dst: &mut [f32], src: &[f32], s: f32, g: Option<Unary>) {
    for (d, &v) in dst.iter_mut().zip(src) {
        *d = Binary::Mul.f(v, s);
    }
    if let Some(g) = g {
        apply_in_place(g, dst);
    }
}

/// Rows of a block of [`pack_rows`]' packing on this CPU: [`AVX2_BLOCK_M`] where
/// [`rows_product`] runs on the AVX2 clone of its narrow kernel (AVX2 and FMA, no AVX-512
/// kernel), [`BLOCK_M`] elsewhere (the AVX-512 kernels, the baseline and aarch64).
/// Worked out once per process: the packing of every plan and the kernel that reads it
/// agree, and a product call costs one load, not a CPU detection.
pub(crate) fn block_rows() -> usize {
    static ROWS: std::sync::OnceLock<usize> = std::sync::OnceLock::new();
    *ROWS.get_or_init(|| {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
            && pulp::x86::V4::try_new().is_none()
        {
            return AVX2_BLOCK_M;
        }
        BLOCK_M
    })
}

/// A row-major `m × k` matrix packed for [`rows_product`]: per block of [`block_rows`] rows,
/// `k` groups of that many values (column `p` of the block's rows), zeros past row `m`.
pub(crate) fn pack_rows(w: &[f32], m: usize, k: usize) -> Vec<f32> {
    let bm = block_rows();
    let blocks = m.div_ceil(bm);
    let mut out = vec![0.0; blocks * k * bm];
    for (i, row) in w.chunks_exact(k).take(m).enumerate() {
        let block = &mut out[(i / bm) * k * bm..];
        for (p, &v) in row.iter().enumerate() {
            block[p * bm + i % bm] = v;
        }
    }
    out
}

/// `y[i·ys + j] = act(Σ_p w[i][p] · x[p·xs + j] + bias[i])` for `i < m`, `j < n`: a matrix
/// product whose right operand's rows lie `xs` apart (a tile of a 1 × 1 convolution's input
/// planes, or one output row's im2col), the bias and an activation applied as each value is
/// stored. `wp` is `w` packed by [`pack_rows`].
///
/// Each sum runs over `p` in order from zero, then adds the bias. Blocks of outputs are
/// summed in registers (6 × 16 in the AVX2 clone, 8 × 8 otherwise), each of `x`'s values
/// loaded once for the block's broadcast weights; `x`'s rows are read where they lie
/// (`pointwise` copies a 1 × 1 convolution's into tiles first).
///
/// On x86-64 CPUs with AVX-512 every column goes to [`wide`]'s kernel (8 × 32 outputs in
/// registers, then 8 × 16 for an odd block, then the last columns in masked registers; the
/// same operations per output in the same order); elsewhere to this one.
#[allow(clippy::too_many_arguments)]
pub(crate) fn rows_product(
    (m, k, n): (usize, usize, usize),
    wp: &[f32],
    x: &[f32],
    xs: usize,
    bias: &[f32],
    act: Option<Unary>,
    y: &mut [f32],
    ys: usize,
) {
    #[cfg(target_arch = "x86_64")]
    let done = wide::rows_product((m, k, n), wp, x, xs, bias, act, y, ys);
    #[cfg(not(target_arch = "x86_64"))]
    let done = 0;
    if done < n {
        rows_product_narrow(
            (m, k, n - done),
            wp,
            &x[done..],
            xs,
            bias,
            act,
            &mut y[done..],
            ys,
        );
    }
}

/// [`rows_product`] with 6 × 16 (AVX2 + FMA clone, 6-row packing) or 8 × 8 (the baseline,
/// aarch64) outputs in registers.
#[allow(clippy::too_many_arguments)]
#[multiversion::multiversion(targets("x86_64+avx2+fma"))]
fn rows_product_narrow(
    (m, k, n): (usize, usize, usize),
    wp: &[f32],
    x: &[f32],
    xs: usize,
    bias: &[f32],
    act: Option<Unary>,
    y: &mut [f32],
    ys: usize,
) {
    if k == 0 {
        // No input: the bias alone (plans refuse empty tensors; the kernel stays total).
        for i in 0..m {
            let v = act.map_or(bias[i], |f| f.eval(bias[i]));
            y[i * ys..i * ys + n].fill(v);
        }
        return;
    }
    // A fused multiply-add (one rounding) where the CPU has one: the AVX2 + FMA clone and
    // every aarch64 CPU; the x86-64 baseline clone (CPUs without FMA) multiplies and adds,
    // since glibc's software `fmaf` would be tens of times slower. The two give other last
    // bits (dispatch_tests pins both).
    let fused = cfg!(target_arch = "aarch64")
        || multiversion::target::target_cfg_f!(target_feature = "fma");
    let madd = |w: f32, x: f32, a: f32| if fused { w.mul_add(x, a) } else { a + w * x };
    // The AVX2 clone (where no AVX-512 kernel runs: [`block_rows`]) takes 16 columns of a
    // 6-row block at a time: 6 × 16 sums in 12 of AVX2's 16 registers, 2 loads of `x` and 6
    // broadcast weights per 12 multiply-adds. The 8 × 8 block takes 1 and 8 per 8: Zen 3
    // issues two 256-bit loads a cycle, so it was bound by its loads (4.5 cycles for the two
    // FMA pipes' 4), and 8 sums only just cover the multiply-add's latency. The last 8 to 15
    // columns take 6 × 8; the baseline clone (SSE2) and aarch64 keep 8 × 8 on 8-row blocks.
    // Every output's sum runs over `p` in order.
    // The activation as each block is stored (one function a loop, inlined, so the stores
    // stay vectorised): `f(sum + bias)`, what activating the finished rows afterwards gave,
    // without reading them back.
    let shape = (m, k, n);
    // (Read here: the macro answers for the clone it is expanded in.)
    let avx2 = multiversion::target::target_cfg_f!(target_feature = "avx2");
    match act {
        None => narrow_blocks(shape, wp, (x, xs), bias, (y, ys), (&madd, avx2), &|v| v),
        Some(Unary::Relu) => {
            narrow_blocks(shape, wp, (x, xs), bias, (y, ys), (&madd, avx2), &|v| {
                Unary::Relu.eval(v)
            })
        }
        Some(Unary::HardSwish) => {
            narrow_blocks(shape, wp, (x, xs), bias, (y, ys), (&madd, avx2), &|v| {
                Unary::HardSwish.eval(v)
            })
        }
        Some(f) => narrow_blocks(shape, wp, (x, xs), bias, (y, ys), (&madd, avx2), &|v| {
            f.eval(v)
        }),
    }
}

/// [`rows_product_narrow`]'s blocks, each output stored as `g(sum + bias)`. Inlined into each
/// clone of the caller, once per activation.
#[inline(always)]
fn narrow_blocks(
    (m, k, n): (usize, usize, usize),
    wp: &[f32],
    (x, xs): (&[f32], usize),
    bias: &[f32],
    (y, ys): (&mut [f32], usize),
    (madd, avx2): (&impl Fn(f32, f32, f32) -> f32, bool),
    g: &impl Fn(f32) -> f32,
) {
    let bm = block_rows();
    let six = bm == AVX2_BLOCK_M;
    let wide = six && avx2;
    let full_wide = if wide { n - n % WIDE_N } else { 0 };
    let full = n - (n - full_wide) % BLOCK_N;
    for (b, wb) in wp.chunks_exact(k * bm).enumerate() {
        let i0 = b * bm;
        let rows = bm.min(m.saturating_sub(i0));
        let (block, bias) = ((wb, bm), &bias[i0..]);
        let at = |j: usize| (i0 * ys + j, ys);
        for j in (0..full_wide).step_by(WIDE_N) {
            // A last block of at most 4 rows (16 outputs of the first convolution: 6, 6, 4)
            // sums only those: the same sums, without the two rows the packing pads.
            if rows <= 4 {
                let acc = block_sums::<4, WIDE_N>(madd, block, x, xs, j);
                store_block(&acc, rows, bias, y, at(j), g);
                continue;
            }
            let acc = block_sums::<AVX2_BLOCK_M, WIDE_N>(madd, block, x, xs, j);
            store_block(&acc, rows, bias, y, at(j), g);
        }
        for j in (full_wide..full).step_by(BLOCK_N) {
            if six {
                let acc = block_sums::<AVX2_BLOCK_M, BLOCK_N>(madd, block, x, xs, j);
                store_block(&acc, rows, bias, y, at(j), g);
            } else {
                let acc = block_sums::<BLOCK_M, BLOCK_N>(madd, block, x, xs, j);
                store_block(&acc, rows, bias, y, at(j), g);
            }
        }
        // The last columns (fewer than 8) one at a time, the block's rows side by side: each
        // row's sum over `p` in order as before, but the rows' chains of multiply-adds in
        // flight together. Row after row, each sum waited on its own multiply-adds' latency:
        // the head's read points (n = 9, 17, 25: one column left each) and the excitation
        // layers' pooled vectors (n = 1) spent 15 % of this kernel's time here.
        for j in full..n {
            let mut acc = [0.0f32; TAIL_ROWS];
            let acc = &mut acc[..rows];
            for (p, w) in wb.chunks_exact(bm).enumerate() {
                let v = x[p * xs + j];
                for (a, &w) in acc.iter_mut().zip(w) {
                    *a = madd(w, v, *a);
                }
            }
            for (i, (a, &b)) in acc.iter().zip(bias).enumerate() {
                y[(i0 + i) * ys + j] = g(a + b);
            }
        }
    }
}

/// [`rows_product_narrow`]'s `R × N` sums from a packed block `wb` of `bm ≥ R` rows and
/// column `j` of `x`: each `Σ_p madd(w, x, ·)` over `p` in order from zero, in registers. The
/// row's values are copied into an array first: read from the slice, the same loop was
/// vectorised across the wrong dimension (shuffles, 4× slower). Inlined into each clone of
/// the caller.
#[inline(always)]
fn block_sums<const R: usize, const N: usize>(
    madd: &impl Fn(f32, f32, f32) -> f32,
    (wb, bm): (&[f32], usize),
    x: &[f32],
    xs: usize,
    j: usize,
) -> [[f32; N]; R] {
    let mut acc = [[0.0f32; N]; R];
    for (p, w) in wb.chunks_exact(bm).enumerate() {
        let mut xv = [0.0f32; N];
        xv.copy_from_slice(&x[p * xs + j..p * xs + j + N]);
        for (a, &w) in acc.iter_mut().zip(&w[..R]) {
            for l in 0..N {
                a[l] = madd(w, xv[l], a[l]);
            }
        }
    }
    acc
}

/// The first `rows` of `acc` plus their `bias` into `y` from `at`, rows `ys` apart.
#[inline(always)]
fn store_block<const R: usize, const N: usize>(
    acc: &[[f32; N]; R],
    rows: usize,
    bias: &[f32],
    y: &mut [f32],
    (at, ys): (usize, usize),
    g: &impl Fn(f32) -> f32,
) {
    for (i, (a, &b)) in acc.iter().zip(bias).enumerate().take(rows) {
        for (y, &a) in y[at + i * ys..at + i * ys + N].iter_mut().zip(a) {
            *y = g(a + b);
        }
    }
}

/// [`rows_product`]'s AVX-512 kernel, in safe code through pulp's `x86::V4`.
#[cfg(target_arch = "x86_64")]
mod wide {
    use super::{apply_in_place, ConvShape, Unary, BLOCK_M};
    use crate::redetect::dwconv::{wide16::Taps2, Window};
    use pulp::x86::V4;
    use pulp::{f32x16, Simd};

    /// Output columns per step.
    const N: usize = 16;

    /// [`super::rows_product`], returning how many columns were done: all `n` (0 on a CPU
    /// without AVX-512, or when `k` is 0).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn rows_product(
        (m, k, n): (usize, usize, usize),
        wp: &[f32],
        x: &[f32],
        xs: usize,
        bias: &[f32],
        act: Option<Unary>,
        y: &mut [f32],
        ys: usize,
    ) -> usize {
        let full = n - n % N;
        let Some(simd) = V4::try_new().filter(|_| k > 0 && n > 0) else {
            return 0;
        };
        simd.vectorize(
            #[inline(always)]
            || {
                let load = |at: usize| -> f32x16 {
                    let (arrays, _) = pulp::as_arrays::<N, f32>(&x[at..at + N]);
                    pulp::cast(arrays[0])
                };
                let store = |y: &mut [f32], at: usize, a: f32x16, b: f32| {
                    let v = simd.add_f32s(a, simd.splat_f32s(b));
                    y[at..at + N].copy_from_slice(&pulp::cast::<f32x16, [f32; N]>(v));
                };
                // Columns in pairs of blocks first: 8 × 32 outputs in 16 registers, two
                // loads of `x` and 8 broadcast weights per 16 multiply-adds (one block alone
                // takes 9 loads per 8); every output's sum runs over `p` in the same order.
                let pairs = full - full % (2 * N);
                for (b, wb) in wp.chunks_exact(k * BLOCK_M).enumerate() {
                    let i0 = b * BLOCK_M;
                    let rows = BLOCK_M.min(m.saturating_sub(i0));
                    for j in (0..pairs).step_by(2 * N) {
                        let mut lo = [simd.splat_f32s(0.0); BLOCK_M];
                        let mut hi = [simd.splat_f32s(0.0); BLOCK_M];
                        for (p, w) in wb.chunks_exact(BLOCK_M).enumerate() {
                            let (xl, xh) = (load(p * xs + j), load(p * xs + j + N));
                            for ((l, h), &w) in lo.iter_mut().zip(hi.iter_mut()).zip(w) {
                                let w = simd.splat_f32s(w);
                                *l = simd.mul_add_e_f32s(w, xl, *l);
                                *h = simd.mul_add_e_f32s(w, xh, *h);
                            }
                        }
                        for (i, (l, h)) in lo.iter().zip(&hi).enumerate().take(rows) {
                            let at = (i0 + i) * ys + j;
                            store(y, at, *l, bias[i0 + i]);
                            store(y, at + N, *h, bias[i0 + i]);
                        }
                    }
                    for j in (pairs..full).step_by(N) {
                        let mut acc = [simd.splat_f32s(0.0); BLOCK_M];
                        for (p, w) in wb.chunks_exact(BLOCK_M).enumerate() {
                            let xv = load(p * xs + j);
                            // a + w · x fused, as in the AVX2 + FMA clone.
                            for (a, &w) in acc.iter_mut().zip(w) {
                                *a = simd.mul_add_e_f32s(simd.splat_f32s(w), xv, *a);
                            }
                        }
                        for (i, a) in acc.iter().enumerate().take(rows) {
                            store(y, (i0 + i) * ys + j, *a, bias[i0 + i]);
                        }
                    }
                    // The last `n − full` columns (fewer than 16): masked loads that fill the
                    // other lanes with zeros, masked stores; each output as above.
                    if full < n {
                        let mut acc = [simd.splat_f32s(0.0); BLOCK_M];
                        for (p, w) in wb.chunks_exact(BLOCK_M).enumerate() {
                            let xv = simd.partial_load_f32s(&x[p * xs + full..p * xs + n]);
                            for (a, &w) in acc.iter_mut().zip(w) {
                                *a = simd.mul_add_e_f32s(simd.splat_f32s(w), xv, *a);
                            }
                        }
                        for (i, a) in acc.iter().enumerate().take(rows) {
                            let v = simd.add_f32s(*a, simd.splat_f32s(bias[i0 + i]));
                            let at = (i0 + i) * ys;
                            simd.partial_store_f32s(&mut y[at + full..at + n], v);
                        }
                    }
                    if let Some(f) = act {
                        for i in i0..i0 + rows {
                            apply_in_place(f, &mut y[i * ys..i * ys + n]);
                        }
                    }
                }
            },
        );
        n
    }

    /// A one-group `K × K` convolution at stride 2 (NanoTrack's first layer: 3 × 3 from the
    /// RGB crop) straight from the input planes, one output row at a time: per 16-output
    /// block and 8 output channels, `Σ_p w[i][p] · x_p` fused-multiply-added over the taps
    /// `p = (c·K + ky)·K + kx` in order from zero, then the bias, then `act` on the stored
    /// row: what [`super::im2col_row`] and [`rows_product`] compute (the same bits), without
    /// writing the im2col rows. Each kernel row's taps are the even and odd lanes of two
    /// loads from the input row ([`Taps2`], `windows` from
    /// [`crate::redetect::dwconv::place_s2`]), zeros outside the input. `false` (nothing
    /// done) for another geometry or mismatched sizes.
    pub(super) fn conv_s2<const K: usize>(
        s: &ConvShape,
        (x, wp, bias): (&[f32], &[f32], &[f32]),
        (act, y): (Option<Unary>, &mut [f32]),
        windows: &[Window],
    ) -> bool {
        let (k, plane) = (s.c * K * K, s.oh * s.ow);
        let (across, pairs) = (s.ow.div_ceil(N), K.div_ceil(2));
        let Some(simd) = V4::try_new() else {
            return false;
        };
        if (s.kh, s.kw, s.sh, s.sw, s.groups) != (K, K, 2, 2, 1)
            || s.w < 2 * N
            || x.len() != s.c * s.h * s.w
            || y.len() != s.m * plane
            || bias.len() != s.m
            || wp.len() != s.m.div_ceil(BLOCK_M) * k * BLOCK_M
            || windows.len() != across * pairs
            || k == 0
        {
            return false;
        }
        simd.vectorize(
            #[inline(always)]
            || {
                let zero = simd.splat_f32s(0.0);
                for oy in 0..s.oh {
                    let rows: [Option<usize>; K] = std::array::from_fn(|ky| {
                        (2 * oy + ky).checked_sub(s.pt).filter(|&r| r < s.h)
                    });
                    for (b, win) in windows.chunks_exact(pairs).enumerate() {
                        let (x0, n) = (b * N, (s.ow - b * N).min(N));
                        let taps_of = Taps2::<K>::new(win);
                        for (blk, wb) in wp.chunks_exact(k * BLOCK_M).enumerate() {
                            let i0 = blk * BLOCK_M;
                            let mut acc = [zero; BLOCK_M];
                            let mut ws = wb.chunks_exact(BLOCK_M);
                            for src in x.chunks_exact(s.h * s.w) {
                                for &r in &rows {
                                    let row = r.and_then(|r| src.get(r * s.w..(r + 1) * s.w));
                                    let taps = row.map_or([zero; K], |row| taps_of.row(simd, row));
                                    for tap in taps {
                                        let Some(w) = ws.next() else {
                                            continue;
                                        };
                                        for (a, &w) in acc.iter_mut().zip(w) {
                                            *a = simd.mul_add_e_f32s(simd.splat_f32s(w), tap, *a);
                                        }
                                    }
                                }
                            }
                            let rows_here = BLOCK_M.min(s.m - i0);
                            for (i, a) in acc.iter().enumerate().take(rows_here) {
                                let v = simd.add_f32s(*a, simd.splat_f32s(bias[i0 + i]));
                                let at = (i0 + i) * plane + oy * s.ow + x0;
                                if let Some(d) = y.get_mut(at..at + n) {
                                    simd.partial_store_f32s(d, v);
                                }
                            }
                        }
                    }
                    if let Some(f) = act {
                        for i in 0..s.m {
                            let at = i * plane + oy * s.ow;
                            apply_in_place(f, &mut y[at..at + s.ow]);
                        }
                    }
                }
            },
        );
        true
    }
}

/// [`wide::conv_s2`] for 3 × 3 kernels where the CPU has AVX-512: `false` (nothing done,
/// the caller takes [`im2col_row`] and [`rows_product`]) elsewhere or for other shapes.
#[allow(clippy::too_many_arguments)]
pub(super) fn conv_s2(
    s: &ConvShape,
    wp: &[f32],
    x: &[f32],
    bias: &[f32],
    act: Option<Unary>,
    y: &mut [f32],
    scratch: &mut crate::redetect::dwconv::Scratch,
) -> bool {
    #[cfg(target_arch = "x86_64")]
    if s.kh == 3 && s.kw == 3 && s.sh == 2 && s.sw == 2 && s.w >= 32 {
        let windows = scratch.windows_s2(s.w, s.ow, 3, s.pl);
        return wide::conv_s2::<3>(s, (x, wp, bias), (act, y), windows);
    }
    let _ = (s, wp, x, bias, act, y, scratch);
    false
}

/// Fills each of `y`'s `rows` rows of `len` values with its bias.
pub(super) fn fill_bias(y: &mut [f32], bias: &[f32], len: usize) {
    for (row, &b) in y.chunks_exact_mut(len).zip(bias) {
        row.fill(b);
    }
}

/// `y[i] = mean of x's i-th run of `len` values`.
///
/// Summed in 8 interleaved partial sums (lane `i` takes the values at `i` mod 8), added
/// pairwise at the end, so that the loop vectorises.
#[multiversion::multiversion(targets("x86_64+avx2+fma"))]
pub(super) fn mean_pool(x: &[f32], len: usize, y: &mut [f32]) {
    for (y, run) in y.iter_mut().zip(x.chunks_exact(len)) {
        let mut lanes = [0.0f32; 8];
        let mut chunks = run.chunks_exact(8);
        for c in &mut chunks {
            for (l, &v) in lanes.iter_mut().zip(c) {
                *l += v;
            }
        }
        for (l, &v) in lanes.iter_mut().zip(chunks.remainder()) {
            *l += v;
        }
        let [a, b, c, d, e, f, g, h] = lanes;
        *y = (((a + e) + (b + f)) + ((c + g) + (d + h))) / len as f32;
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Every activation applied as the product stores its blocks gives what activating the
    /// finished rows afterwards gives, bit for bit: wide blocks, 8-column blocks and the last
    /// columns, full and short row blocks.
    #[test]
    fn products_activated_as_stored_equal_activated_afterwards() {
        let acts = [
            Unary::Relu,
            Unary::HardSwish,
            Unary::HardSigmoid(0.2, 0.5),
            Unary::Clip(-0.5, 0.75),
            Unary::Sigmoid,
            Unary::Exp,
        ];
        for (m, k, n) in [(16, 27, 37), (7, 5, 16), (12, 3, 9), (1, 40, 1), (6, 8, 24)] {
            let x: Vec<f32> = (0..k * n)
                .map(|i| ((i * 31 % 53) as f32 - 26.0) * 0.11)
                .collect();
            let w: Vec<f32> = (0..m * k)
                .map(|i| ((i * 17 % 29) as f32 - 14.0) * 0.07)
                .collect();
            let bias: Vec<f32> = (0..m).map(|i| i as f32 * 0.3 - 1.0).collect();
            let wp = pack_rows(&w, m, k);
            let mut plain = vec![f32::NAN; m * n];
            rows_product((m, k, n), &wp, &x, n, &bias, None, &mut plain, n);
            for f in acts {
                let mut want = plain.clone();
                unary_in_place(f, &mut want);
                let mut got = vec![f32::NAN; m * n];
                rows_product((m, k, n), &wp, &x, n, &bias, Some(f), &mut got, n);
                let bits = |v: &[f32]| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&got), bits(&want), "{m} x {k} x {n}, {f:?}");
            }
        }
    }

    /// The AVX-512 kernel's columns equal the 8-column kernel's bit for bit, over shapes with
    /// partial row blocks, a rest of columns (its masked tail) and strided rows. On a CPU without AVX-512 the
    /// wide kernel does no column (checked too), and the comparison covers nothing more than
    /// the narrow kernel against itself: `dispatch_tests` pins both on fixed input.
    #[test]
    fn the_wide_kernel_gives_the_narrow_kernels_bits() {
        let mut seed = 11u32;
        let mut rnd = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32 - 0.5
        };
        #[cfg(target_arch = "x86_64")]
        let avx512 = std::arch::is_x86_feature_detected!("avx512f");
        #[cfg(not(target_arch = "x86_64"))]
        let avx512 = false;
        for (m, k, n, xs) in [
            (8, 27, 128, 128),
            (11, 29, 21, 21),
            (96, 96, 40, 40),
            (13, 17, 80, 90),
            (3, 5, 33, 50),
        ] {
            let w: Vec<f32> = (0..m * k).map(|_| rnd()).collect();
            let x: Vec<f32> = (0..k * xs).map(|_| rnd()).collect();
            let bias: Vec<f32> = (0..m).map(|_| rnd()).collect();
            let wp = pack_rows(&w, m, k);
            for act in [None, Some(Unary::HardSwish)] {
                let mut both = vec![0.0; m * n];
                rows_product((m, k, n), &wp, &x, xs, &bias, act, &mut both, n);
                let mut narrow = vec![0.0; m * n];
                rows_product_narrow((m, k, n), &wp, &x, xs, &bias, act, &mut narrow, n);
                let bits = |v: &[f32]| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&both), bits(&narrow), "{m}×{k} by {k}×{n}, {act:?}");
                #[cfg(target_arch = "x86_64")]
                {
                    let done = wide::rows_product((m, k, n), &wp, &x, xs, &bias, act, &mut both, n);
                    assert_eq!(done, if avx512 { n } else { 0 });
                }
            }
        }
        println!("AVX-512 kernel ran: {avx512}");
    }

    /// Every path of [`rows_product`] (the AVX2 clone's 6 × 16 and 6 × 8 blocks of 6-row
    /// packing, the 8 × 8 blocks, the AVX-512 kernel, the last columns one at a time; the
    /// host's [`block_rows`] decides which) gives each output as one sum over `p`
    /// in order from zero, then the bias, then the activation: the scalar sum here, bit for
    /// bit. Fused where the kernel fuses (the AVX2 + FMA clone, aarch64), otherwise a
    /// multiply then an add. Shapes with partial row blocks (of 6 and of 8), columns that
    /// end inside a 16-, an 8-column block and a single column, and strided rows.
    #[test]
    fn the_product_sums_each_output_in_order() {
        #[cfg(target_arch = "x86_64")]
        let fused = std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma");
        #[cfg(not(target_arch = "x86_64"))]
        let fused = cfg!(target_arch = "aarch64");
        let mut seed = 5u32;
        let mut rnd = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32 - 0.5
        };
        for (m, k, n, xs) in [
            (8, 27, 127, 127),
            (16, 72, 256, 4096),
            (3, 5, 33, 50),
            (5, 9, 16, 16),
            (13, 17, 57, 64),
            (24, 1, 40, 40),
            (11, 29, 21, 21),
        ] {
            let w: Vec<f32> = (0..m * k).map(|_| rnd()).collect();
            let x: Vec<f32> = (0..k * xs).map(|_| rnd()).collect();
            let bias: Vec<f32> = (0..m).map(|_| rnd()).collect();
            let wp = pack_rows(&w, m, k);
            for act in [None, Some(Unary::Relu), Some(Unary::HardSwish)] {
                let ys = n + 3;
                let mut y = vec![f32::NAN; m * ys];
                rows_product((m, k, n), &wp, &x, xs, &bias, act, &mut y, ys);
                for i in 0..m {
                    for j in 0..n {
                        let mut a = 0.0f32;
                        for p in 0..k {
                            let (w, x) = (w[i * k + p], x[p * xs + j]);
                            a = if fused { w.mul_add(x, a) } else { a + w * x };
                        }
                        let v = a + bias[i];
                        let v = act.map_or(v, |f| f.eval(v));
                        let got = y[i * ys + j];
                        assert_eq!(
                            got.to_bits(),
                            v.to_bits(),
                            "{m}×{k} by {k}×{n}, ({i}, {j}), {act:?}"
                        );
                    }
                    assert!(
                        y[i * ys + n..(i + 1) * ys].iter().all(|v| v.is_nan()),
                        "past row {i}"
                    );
                }
            }
        }
    }

    /// The stride-2 convolution read from the input rows ([`conv_s2`], where the CPU has
    /// AVX-512) against the im2col rows and [`rows_product`] the runner takes otherwise: the
    /// same bits on NanoTrack's first layer (3 → 16 channels on 255 and 127 px crops) and on
    /// ragged shapes (a partial channel block, rows ending mid-block, every padding a 3 × 3
    /// kernel takes), with and without an activation. On a CPU without AVX-512 it must
    /// refuse (nothing to compare).
    #[test]
    fn the_stride_2_rows_give_the_im2col_rows_bits() {
        #[cfg(target_arch = "x86_64")]
        let avx512 = std::arch::is_x86_feature_detected!("avx512f");
        #[cfg(not(target_arch = "x86_64"))]
        let avx512 = false;
        let mut seed = 5u32;
        let mut rnd = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32 - 0.5
        };
        let mut cases = 0;
        let mut scratch = crate::redetect::dwconv::Scratch::default();
        for (c, m, h, w, (pt, pb), (pl, pr)) in [
            (3, 16, 255, 255, (1, 1), (1, 1)),
            (3, 16, 127, 127, (1, 1), (1, 1)),
            (2, 5, 40, 33, (0, 0), (0, 0)),
            (1, 11, 9, 64, (2, 2), (2, 2)),
            (4, 8, 33, 47, (0, 2), (2, 0)),
        ] {
            let (oh, ow) = ((h + pt + pb - 3) / 2 + 1, (w + pl + pr - 3) / 2 + 1);
            let s = ConvShape {
                c,
                h,
                w,
                m,
                oh,
                ow,
                kh: 3,
                kw: 3,
                sh: 2,
                sw: 2,
                pt,
                pl,
                groups: 1,
            };
            let k = c * 9;
            let wts: Vec<f32> = (0..m * k).map(|_| rnd()).collect();
            let x: Vec<f32> = (0..c * h * w).map(|_| rnd()).collect();
            let bias: Vec<f32> = (0..m).map(|_| rnd()).collect();
            let wp = pack_rows(&wts, m, k);
            for act in [None, Some(Unary::Relu), Some(Unary::HardSwish)] {
                let plane = oh * ow;
                let mut want = vec![f32::NAN; m * plane];
                let mut col = vec![0.0; k * ow];
                for oy in 0..oh {
                    im2col_row(&s, &x, oy, &mut col);
                    let yo = &mut want[oy * ow..];
                    rows_product((m, k, ow), &wp, &col, ow, &bias, act, yo, plane);
                }
                let mut got = vec![f32::NAN; m * plane];
                let done = conv_s2(&s, &wp, &x, &bias, act, &mut got, &mut scratch);
                assert_eq!(done, avx512, "{c}×{h}×{w}: ran {done}");
                if !done {
                    continue;
                }
                let bits = |v: &[f32]| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(
                    bits(&got),
                    bits(&want),
                    "{c}×{h}×{w} → {m}, pads {pt} {pl}, {act:?}"
                );
                cases += 1;
            }
        }
        if avx512 {
            assert_eq!(cases, 15);
        }
    }
}
