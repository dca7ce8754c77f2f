//! A depthwise 2-D convolution (one group per channel, as in NanoTrack v2's backbone and
//! head), written so that the compiler vectorises it on any target (SSE2 / AVX2 on x86_64,
//! NEON on aarch64; no `target-cpu`, no `unsafe`); [`crate::nn`] runs every such `Conv`
//! node on it.
//!
//! Written when tract ran the verifier: tract 0.23.9 computed a depthwise convolution zone
//! by zone around each output point, and in NanoTrack v2's backbone those eight nodes were
//! 35.7 M of a 255×255 pass's 62.6 M instructions (callgrind), mostly bookkeeping around
//! short runs. Here a channel is computed kernel row by kernel row over the whole output
//! plane at once:
//!
//! 1. the channel's input plane is copied into a padded scratch plane split by stride
//!    phase (for stride 2, even and odd rows and columns go to four sub-planes), so that
//!    every kernel tap reads a *contiguous* run of one sub-plane; the padding is zeroed
//!    once per call, since every channel writes the same interior positions;
//! 2. the output is accumulated "wide": output row `oy` lives at `oy · wq` in a buffer whose
//!    rows are as wide as the sub-planes (`wq`), starting at the bias, so a kernel row of
//!    `k` taps is one loop `out[i] += Σ w_kx · src_kx[i]` over `(ho − 1) · wq + wo` values
//!    (the few extra columns between rows are computed and dropped); zipped slice
//!    iterators (kernel rows of 3 and 5 taps) let the compiler drop bounds checks and use
//!    4-wide SSE2 / NEON;
//! 3. the valid columns are copied to the output.
//!
//! Tested against a naive reference here; the networks' outputs against ONNX Runtime's
//! reference values (`tests/integration/verifier.rs`).

/// The shape of one depthwise convolution (one batch item).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Geometry {
    /// Channels (input = output).
    pub channels: usize,
    /// Input height.
    pub in_h: usize,
    /// Input width.
    pub in_w: usize,
    /// Kernel height.
    pub k_h: usize,
    /// Kernel width.
    pub k_w: usize,
    /// Vertical stride (≥ 1).
    pub stride_h: usize,
    /// Horizontal stride (≥ 1).
    pub stride_w: usize,
    /// Zero rows above the input.
    pub pad_top: usize,
    /// Zero columns left of the input.
    pub pad_left: usize,
    /// Output height.
    pub out_h: usize,
    /// Output width.
    pub out_w: usize,
}

impl Geometry {
    /// The output size for `pad_bottom` / `pad_right`, or `None` when the kernel does not
    /// fit the padded input or a size is zero.
    fn output(
        in_len: usize,
        k: usize,
        stride: usize,
        pad_before: usize,
        pad_after: usize,
    ) -> Option<usize> {
        let padded = in_len.checked_add(pad_before)?.checked_add(pad_after)?;
        if in_len == 0 || k == 0 || stride == 0 || padded < k {
            return None;
        }
        Some((padded - k) / stride + 1)
    }

    /// A geometry, or `None` for an impossible one (zero sizes or stride, a kernel larger
    /// than the padded input, padding wider than the kernel).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        channels: usize,
        (in_h, in_w): (usize, usize),
        (k_h, k_w): (usize, usize),
        (stride_h, stride_w): (usize, usize),
        (pad_top, pad_bottom): (usize, usize),
        (pad_left, pad_right): (usize, usize),
    ) -> Option<Self> {
        if channels == 0 || pad_top >= k_h.max(1) || pad_left >= k_w.max(1) {
            return None;
        }
        let out_h = Self::output(in_h, k_h, stride_h, pad_top, pad_bottom)?;
        let out_w = Self::output(in_w, k_w, stride_w, pad_left, pad_right)?;
        Some(Self {
            channels,
            in_h,
            in_w,
            k_h,
            k_w,
            stride_h,
            stride_w,
            pad_top,
            pad_left,
            out_h,
            out_w,
        })
    }

    /// Rows of a stride-phase sub-plane.
    fn phase_h(&self) -> usize {
        // Rows the taps read: (out_h − 1)·stride + k_h, split into stride phases.
        ((self.out_h - 1) * self.stride_h + self.k_h).div_ceil(self.stride_h)
    }

    /// Columns of a stride-phase sub-plane (the wide output's row pitch).
    fn phase_w(&self) -> usize {
        ((self.out_w - 1) * self.stride_w + self.k_w).div_ceil(self.stride_w)
    }

    /// Values of one channel's input plane.
    pub fn in_plane(&self) -> usize {
        self.in_h * self.in_w
    }

    /// Values of one channel's output plane.
    pub fn out_plane(&self) -> usize {
        self.out_h * self.out_w
    }
}

/// Reusable buffers of [`depthwise`].
#[derive(Debug, Default)]
pub struct Scratch {
    phases: Vec<f32>,
    wide: Vec<f32>,
}

/// Depthwise convolution of `input` (`channels` planes of `in_h × in_w`, row-major) with
/// `weights` (`channels` kernels of `k_h × k_w`) plus `bias` (one per channel) into `output`
/// (`channels` planes of `out_h × out_w`), zero padding. Returns `false` (and leaves
/// `output` alone) when a slice has the wrong length.
#[multiversion::multiversion(targets("x86_64+avx2+fma"))] // AVX2 + FMA clone, chosen at run time
pub fn depthwise(
    g: &Geometry,
    input: &[f32],
    weights: &[f32],
    bias: &[f32],
    output: &mut [f32],
    scratch: &mut Scratch,
) -> bool {
    let taps = g.k_h * g.k_w;
    if input.len() != g.channels * g.in_plane()
        || weights.len() != g.channels * taps
        || bias.len() != g.channels
        || output.len() != g.channels * g.out_plane()
    {
        return false;
    }
    let (hq, wq) = (g.phase_h(), g.phase_w());
    let (sh, sw) = (g.stride_h, g.stride_w);
    let sub = hq * wq;
    // Outputs computed per tap: the wide rows, the last one cut at out_w.
    let span = (g.out_h - 1) * wq + g.out_w;
    scratch.phases.resize(sh * sw * sub, 0.0);
    scratch.wide.resize(span, 0.0);
    let rows_read = hq * sh;
    let cols_read = wq * sw;
    // Padding and the columns and rows no tap reads stay zero for every channel: each
    // channel overwrites the same interior positions.
    scratch.phases.fill(0.0);
    // Input columns that land inside the read window.
    let x_end = g.in_w.min(cols_read.saturating_sub(g.pad_left));
    // Where each tap (ky, kx) starts reading: its phase sub-plane, shifted by ky / sh rows
    // and kx / sw columns.
    let starts: Vec<usize> = (0..taps)
        .map(|t| {
            let (ky, kx) = (t / g.k_w, t % g.k_w);
            ((ky % sh) * sw + kx % sw) * sub + (ky / sh) * wq + kx / sw
        })
        .collect();
    for c in 0..g.channels {
        let plane = &input[c * g.in_plane()..(c + 1) * g.in_plane()];
        // 1. Padded, phase-split copy. Padded row py = y + pad_top goes to phase py % sh,
        //    row py / sh; likewise columns: input columns x ≡ r (mod sw) land in column
        //    phase (pad_left + r) % sw, from column (pad_left + r) / sw on.
        for y in 0..g.in_h {
            let py = y + g.pad_top;
            if py >= rows_read {
                break;
            }
            let row = &plane[y * g.in_w..y * g.in_w + x_end];
            let base_y = (py % sh) * sw * sub + (py / sh) * wq;
            if sw == 2 {
                // Pairs of input columns split to the two column phases at once.
                let (c0, c1) = (g.pad_left / 2, g.pad_left.div_ceil(2));
                let pairs = x_end / 2;
                let (lo, hi) = scratch.phases.split_at_mut(base_y + sub);
                let (first, second) = (&mut lo[base_y..base_y + wq], &mut hi[..wq]);
                let (a, b) = if g.pad_left.is_multiple_of(2) {
                    (&mut first[c0..c0 + pairs], &mut second[c1..c1 + pairs])
                } else {
                    (&mut second[c0..c0 + pairs], &mut first[c1..c1 + pairs])
                };
                for ((a, b), p) in a.iter_mut().zip(b.iter_mut()).zip(row.chunks_exact(2)) {
                    *a = p[0];
                    *b = p[1];
                }
                if x_end % 2 == 1 {
                    let px = g.pad_left + x_end - 1;
                    scratch.phases[base_y + (px % 2) * sub + px / 2] = row[x_end - 1];
                }
                continue;
            }
            for r in 0..sw.min(x_end) {
                let px = g.pad_left + r;
                let first = base_y + (px % sw) * sub + px / sw;
                let n = (x_end - r).div_ceil(sw);
                let dst = &mut scratch.phases[first..first + n];
                if sw == 1 {
                    copy_short(dst, row);
                } else {
                    for (d, &v) in dst.iter_mut().zip(row[r..].iter().step_by(sw)) {
                        *d = v;
                    }
                }
            }
        }
        // 2. Kernel row by kernel row over the wide output, which starts at the bias; the
        //    last kernel row, 3., writes the valid columns straight to the output.
        let wide = &mut scratch.wide[..span];
        wide.fill(bias[c]);
        let kernel = &weights[c * taps..(c + 1) * taps];
        let out = &mut output[c * g.out_plane()..(c + 1) * g.out_plane()];
        for ky in 0..g.k_h {
            let w = &kernel[ky * g.k_w..(ky + 1) * g.k_w];
            let row_starts = &starts[ky * g.k_w..(ky + 1) * g.k_w];
            let src = |kx: usize| &scratch.phases[row_starts[kx]..row_starts[kx] + span];
            if ky + 1 == g.k_h && g.k_w == 3 {
                // 3. The valid columns, each the same `o + (w₀·a + w₁·b + w₂·c)` as `row3`'s
                //    (the same bits), without a pass over the wide buffer to copy them out.
                let s = [src(0), src(1), src(2)];
                for (oy, dst) in out.chunks_exact_mut(g.out_w).enumerate() {
                    let at = oy * wq..oy * wq + g.out_w;
                    let taps = [&s[0][at.clone()], &s[1][at.clone()], &s[2][at.clone()]];
                    row3_to(dst, &wide[at], taps, [w[0], w[1], w[2]]);
                }
                break;
            }
            match g.k_w {
                3 => row3(wide, [src(0), src(1), src(2)], [w[0], w[1], w[2]]),
                5 => row5(
                    wide,
                    [src(0), src(1), src(2), src(3), src(4)],
                    [w[0], w[1], w[2], w[3], w[4]],
                ),
                _ => {
                    for kx in 0..g.k_w {
                        let wk = w[kx];
                        for (o, &v) in wide.iter_mut().zip(src(kx)) {
                            *o += wk * v;
                        }
                    }
                }
            }
            if ky + 1 == g.k_h {
                // 3. The valid columns.
                for (oy, dst) in out.chunks_exact_mut(g.out_w).enumerate() {
                    copy_short(dst, &wide[oy * wq..oy * wq + g.out_w]);
                }
            }
        }
    }
    true
}

/// `wide[i] += w₀·s₀[i] + w₁·s₁[i] + w₂·s₂[i]` (one kernel row of three taps; the zipped
/// slice iterators let the compiler drop the bounds checks and vectorise).
#[inline(always)] // into each of `depthwise`' clones
fn row3(wide: &mut [f32], s: [&[f32]; 3], w: [f32; 3]) {
    for (((o, &a), &b), &c) in wide.iter_mut().zip(s[0]).zip(s[1]).zip(s[2]) {
        *o += w[0] * a + w[1] * b + w[2] * c;
    }
}

/// `dst[i] = acc[i] + (w₀·s₀[i] + w₁·s₁[i] + w₂·s₂[i])`: [`row3`]'s sum for one output row,
/// stored apart from the accumulator.
#[inline(always)]
fn row3_to(dst: &mut [f32], acc: &[f32], s: [&[f32]; 3], w: [f32; 3]) {
    let it = dst.iter_mut().zip(acc).zip(s[0]).zip(s[1]).zip(s[2]);
    for ((((d, &o), &a), &b), &c) in it {
        *d = o + (w[0] * a + w[1] * b + w[2] * c);
    }
}

/// `dst.copy_from_slice(src)` for the short rows of the networks' feature maps and tiles (8
/// to 256 values), in 8-value blocks the compiler keeps in registers: through
/// `copy_from_slice` each row was a call to the C library's `memmove`, whose call overhead
/// on rows this short was 5–8 % of a backbone pass (`perf`).
#[inline(always)]
pub(crate) fn copy_short(dst: &mut [f32], src: &[f32]) {
    let mut d = dst.chunks_exact_mut(8);
    let mut s = src.chunks_exact(8);
    for (d, s) in (&mut d).zip(&mut s) {
        let mut v = [0.0f32; 8];
        v.copy_from_slice(s);
        d.copy_from_slice(&v);
    }
    for (d, &s) in d.into_remainder().iter_mut().zip(s.remainder()) {
        *d = s;
    }
}

/// [`row3`] for a kernel row of five taps.
#[inline(always)]
fn row5(wide: &mut [f32], s: [&[f32]; 5], w: [f32; 5]) {
    let taps = wide
        .iter_mut()
        .zip(s[0])
        .zip(s[1])
        .zip(s[2])
        .zip(s[3])
        .zip(s[4]);
    for (((((o, &a), &b), &c), &d), &e) in taps {
        *o += w[0] * a + w[1] * b + w[2] * c + w[3] * d + w[4] * e;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Straightforward depthwise convolution, zero padding.
    fn naive(g: &Geometry, input: &[f32], weights: &[f32], bias: &[f32]) -> Vec<f32> {
        let mut out = vec![0.0; g.channels * g.out_plane()];
        for c in 0..g.channels {
            for oy in 0..g.out_h {
                for ox in 0..g.out_w {
                    let mut s = f64::from(bias[c]);
                    for ky in 0..g.k_h {
                        for kx in 0..g.k_w {
                            let y = (oy * g.stride_h + ky) as isize - g.pad_top as isize;
                            let x = (ox * g.stride_w + kx) as isize - g.pad_left as isize;
                            if y < 0 || x < 0 || y >= g.in_h as isize || x >= g.in_w as isize {
                                continue;
                            }
                            let v = input[c * g.in_plane() + y as usize * g.in_w + x as usize];
                            let k = weights[c * g.k_h * g.k_w + ky * g.k_w + kx];
                            s += f64::from(v) * f64::from(k);
                        }
                    }
                    out[c * g.out_plane() + oy * g.out_w + ox] = s as f32;
                }
            }
        }
        out
    }

    /// Largest `|depthwise − naive|` over the outputs of `g` (the kernel must accept the
    /// slices; every output is written, the buffer starting as NaN).
    fn worst_against_naive(
        g: &Geometry,
        input: &[f32],
        weights: &[f32],
        bias: &[f32],
        scratch: &mut Scratch,
    ) -> f32 {
        let want = naive(g, input, weights, bias);
        let mut got = vec![f32::NAN; want.len()];
        assert!(depthwise(g, input, weights, bias, &mut got, scratch));
        got.iter()
            .zip(&want)
            .map(|(a, b)| (a - b).abs())
            .fold(
                0.0f32,
                |m, d| if d.is_nan() { f32::INFINITY } else { m.max(d) },
            )
    }

    /// Deterministic values in [-1, 1).
    fn values(n: usize, seed: u32) -> Vec<f32> {
        let mut s = seed.wrapping_mul(2_654_435_761).wrapping_add(1);
        (0..n)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 17;
                s ^= s << 5;
                (s >> 8) as f32 / (1u32 << 23) as f32 - 1.0
            })
            .collect()
    }

    #[test]
    fn matches_a_naive_reference_on_odd_sizes_strides_kernels_and_padding() {
        let mut scratch = Scratch::default();
        let mut cases = 0;
        for &(h, w) in &[(7, 9), (13, 5), (16, 16), (1, 6), (5, 1), (11, 11)] {
            for &k in &[1usize, 3, 5] {
                for &s in &[1, 2, 3] {
                    for &(pt, pb, pl, pr) in &[
                        (0, 0, 0, 0),
                        (k / 2, k / 2, k / 2, k / 2),
                        (k / 2, 0, 0, k / 2),
                        (k - 1, k - 1, k.saturating_sub(2), k - 1),
                    ] {
                        let Some(g) = Geometry::new(3, (h, w), (k, k), (s, s), (pt, pb), (pl, pr))
                        else {
                            continue;
                        };
                        let input = values(3 * h * w, cases);
                        let weights = values(3 * k * k, cases + 1000);
                        let bias = values(3, cases + 2000);
                        let worst = worst_against_naive(&g, &input, &weights, &bias, &mut scratch);
                        assert!(worst <= 1e-5, "{g:?}: {worst}");
                        cases += 1;
                    }
                }
            }
        }
        // Every size, kernel and stride with at least the unpadded and "same" padding,
        // minus those a 1-wide input cannot take.
        assert!(cases > 150, "{cases} cases");
    }

    #[test]
    fn a_rectangular_kernel_and_mixed_strides_match_the_reference() {
        let g = Geometry::new(2, (9, 12), (3, 5), (2, 1), (1, 1), (2, 2));
        let Some(g) = g else {
            panic!("valid geometry refused")
        };
        let input = values(2 * 9 * 12, 7);
        let weights = values(2 * 15, 8);
        let bias = [0.25, -0.5];
        let worst = worst_against_naive(&g, &input, &weights, &bias, &mut Scratch::default());
        assert!(worst <= 1e-5, "{worst}");
    }

    #[test]
    fn wrong_lengths_and_impossible_geometries_are_refused() {
        assert!(Geometry::new(0, (4, 4), (3, 3), (1, 1), (1, 1), (1, 1)).is_none());
        assert!(Geometry::new(1, (2, 2), (5, 5), (1, 1), (0, 0), (0, 0)).is_none());
        assert!(Geometry::new(1, (4, 4), (3, 3), (0, 1), (1, 1), (1, 1)).is_none());
        assert!(Geometry::new(1, (4, 4), (3, 3), (1, 1), (3, 0), (1, 1)).is_none());
        let Some(g) = Geometry::new(1, (4, 4), (3, 3), (1, 1), (1, 1), (1, 1)) else {
            panic!("valid geometry refused")
        };
        let mut out = vec![7.0; 16];
        let mut s = Scratch::default();
        assert!(!depthwise(
            &g,
            &[0.0; 15],
            &[0.0; 9],
            &[0.0],
            &mut out,
            &mut s
        ));
        assert!(!depthwise(
            &g,
            &[0.0; 16],
            &[0.0; 8],
            &[0.0],
            &mut out,
            &mut s
        ));
        assert!(!depthwise(&g, &[0.0; 16], &[0.0; 9], &[], &mut out, &mut s));
        assert!(out.iter().all(|&v| v == 7.0));
    }
}
