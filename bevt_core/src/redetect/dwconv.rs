//! A depthwise 2-D convolution for the NanoTrack verifier's tract plans, written so that the
//! compiler vectorises it on any target (SSE2 on x86_64, NEON on aarch64; no
//! `target-cpu`, no `unsafe`).
//!
//! tract 0.23.9 runs a depthwise convolution (`Conv` with one group per channel) zone by
//! zone around each output point (`DepthWise::eval`, with a SIMD inner kernel on x86_64);
//! in NanoTrack v2's backbone those eight nodes were 35.7 M of a 255×255 pass's 62.6 M
//! instructions (callgrind), mostly bookkeeping around short runs. Here a channel is
//! computed kernel row by kernel row over the whole output plane at once:
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
//! The sums run in another order than tract's, so results agree to rounding (tested:
//! against a naive reference here, against tract's own plan in `nano.rs`, relative
//! difference under 1e-6 on the backbone's output).
//!
//! [`rewrite`] replaces, in a decluttered [`TypedModel`], every `Conv` node that this op
//! can compute (f32, one group per channel, channel multiplier 1, 2-D, `NCHW` or `CHW`,
//! `OIHW` kernel, no dilation, constant kernel and bias) with a [`DepthwiseConv`]; the
//! others keep tract's.

use std::sync::Arc;
use tract_onnx::prelude::{
    tvec, DatumType, IntoTValue, OutletId, TValue, TVec, Tensor, TractResult, TypedFact,
    TypedModel, TypedModelPatch,
};
use tract_onnx::tract_core::internal::{
    as_op, op_as_typed_op, op_out_of_plan, EvalContext, EvalOp, Op, StaticName, TypedOp, Validation,
};
use tract_onnx::tract_core::ops::cnn::{Conv, KernelFormat};
use tract_onnx::tract_core::ops::nn::DataFormat;

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
                    dst.copy_from_slice(row);
                } else {
                    for (d, &v) in dst.iter_mut().zip(row[r..].iter().step_by(sw)) {
                        *d = v;
                    }
                }
            }
        }
        // 2. Kernel row by kernel row over the wide output, which starts at the bias.
        let wide = &mut scratch.wide[..span];
        wide.fill(bias[c]);
        let kernel = &weights[c * taps..(c + 1) * taps];
        for ky in 0..g.k_h {
            let w = &kernel[ky * g.k_w..(ky + 1) * g.k_w];
            let row_starts = &starts[ky * g.k_w..(ky + 1) * g.k_w];
            let src = |kx: usize| &scratch.phases[row_starts[kx]..row_starts[kx] + span];
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
        }
        // 3. The valid columns.
        let out = &mut output[c * g.out_plane()..(c + 1) * g.out_plane()];
        for oy in 0..g.out_h {
            out[oy * g.out_w..(oy + 1) * g.out_w]
                .copy_from_slice(&wide[oy * wq..oy * wq + g.out_w]);
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

/// tract operator running [`depthwise`] with constant weights and bias on one input, a
/// `[n, c, h, w]` (or `[c, h, w]`) f32 tensor.
#[derive(Debug, Clone)]
pub struct DepthwiseConv {
    geometry: Geometry,
    batch: usize,
    out_shape: TVec<usize>,
    weights: Arc<Vec<f32>>,
    bias: Arc<Vec<f32>>,
}

impl PartialEq for DepthwiseConv {
    fn eq(&self, other: &Self) -> bool {
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        self.geometry == other.geometry
            && self.batch == other.batch
            && self.out_shape == other.out_shape
            && bits(&self.weights) == bits(&other.weights)
            && bits(&self.bias) == bits(&other.bias)
    }
}

impl Eq for DepthwiseConv {}

impl DepthwiseConv {
    /// The op's geometry.
    pub fn geometry(&self) -> &Geometry {
        &self.geometry
    }
}

impl Op for DepthwiseConv {
    fn name(&self) -> StaticName {
        "BevtDepthwiseConv".into()
    }

    fn info(&self) -> TractResult<Vec<String>> {
        Ok(vec![format!("{:?}", self.geometry)])
    }

    fn validation(&self) -> Validation {
        Validation::Rounding
    }

    op_as_typed_op!();
}

impl EvalOp for DepthwiseConv {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        let [input] = &*inputs else {
            anyhow_bail(format!("{} inputs; expected 1", inputs.len()))?
        };
        let view = input.try_as_plain_ram()?;
        let data = view.as_slice::<f32>()?;
        let g = &self.geometry;
        let (per_in, per_out) = (g.channels * g.in_plane(), g.channels * g.out_plane());
        if data.len() != self.batch * per_in {
            anyhow_bail(format!(
                "input of {} values; expected {}",
                data.len(),
                self.batch * per_in
            ))?;
        }
        // Written in place: every value is overwritten, the zeroing is tract's only safe
        // allocation (converting a Vec or an ndarray copies it).
        let mut t = Tensor::zero::<f32>(&self.out_shape)?;
        {
            let mut view = t.try_as_plain_ram_mut()?;
            let out = view.as_slice_mut::<f32>()?;
            let mut scratch = Scratch::default();
            for n in 0..self.batch {
                let ok = depthwise(
                    g,
                    &data[n * per_in..(n + 1) * per_in],
                    &self.weights,
                    &self.bias,
                    &mut out[n * per_out..(n + 1) * per_out],
                    &mut scratch,
                );
                if !ok {
                    anyhow_bail("inconsistent depthwise geometry".to_string())?;
                }
            }
        }
        Ok(tvec!(t.into_tvalue()))
    }
}

/// A tract error carrying `msg`.
fn anyhow_bail<T>(msg: String) -> TractResult<T> {
    Err(tract_onnx::prelude::TractError::msg(msg))
}

impl TypedOp for DepthwiseConv {
    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        let [input] = inputs else {
            return anyhow_bail(format!("{} inputs; expected 1", inputs.len()));
        };
        if input.datum_type != DatumType::F32 {
            return anyhow_bail(format!("input {:?}; expected f32", input.datum_type));
        }
        Ok(tvec!(TypedFact::dt_shape(
            DatumType::F32,
            self.out_shape.as_slice()
        )))
    }

    as_op!();
}

/// The [`DepthwiseConv`] computing `conv` on `model`'s `inputs`, or `None` when this op
/// cannot (see the module doc).
fn replacement(
    model: &TypedModel,
    conv: &Conv,
    inputs: &[OutletId],
) -> TractResult<Option<DepthwiseConv>> {
    let spec = &conv.pool_spec;
    let channels = spec.input_channels;
    if conv.q_params.is_some()
        || inputs.len() != 3
        || conv.group != channels
        || spec.output_channels != channels
        || spec.kernel_shape.len() != 2
        || spec.dilations().iter().any(|&d| d != 1)
        || conv.kernel_fmt != KernelFormat::OIHW
        || !matches!(spec.data_format, DataFormat::NCHW | DataFormat::CHW)
    {
        return Ok(None);
    }
    let data = model.outlet_fact(inputs[0])?;
    let Some(shape) = data.shape.as_concrete() else {
        return Ok(None);
    };
    let (batch, c, h, w) = match (spec.data_format, shape) {
        (DataFormat::NCHW, &[n, c, h, w]) => (n, c, h, w),
        (DataFormat::CHW, &[c, h, w]) => (1, c, h, w),
        _ => return Ok(None),
    };
    if data.datum_type != DatumType::F32 || c != channels {
        return Ok(None);
    }
    let (k_h, k_w) = (spec.kernel_shape[0], spec.kernel_shape[1]);
    let (Some(kernel), Some(bias)) = (
        model.outlet_fact(inputs[1])?.konst.clone(),
        model.outlet_fact(inputs[2])?.konst.clone(),
    ) else {
        return Ok(None);
    };
    if kernel.datum_type() != DatumType::F32
        || kernel.shape() != [channels, 1, k_h, k_w]
        || bias.datum_type() != DatumType::F32
        || !(bias.len() == channels || bias.len() == 1)
    {
        return Ok(None);
    }
    let weights = kernel.try_as_plain_ram()?.as_slice::<f32>()?.to_vec();
    let bias_view = bias.try_as_plain_ram()?;
    let b = bias_view.as_slice::<f32>()?;
    let bias = if b.len() == 1 {
        vec![b[0]; channels]
    } else {
        b.to_vec()
    };
    let pads = spec.computed_padding(&[h, w]);
    let strides = spec.strides();
    let Some(geometry) = Geometry::new(
        channels,
        (h, w),
        (k_h, k_w),
        (strides[0], strides[1]),
        (pads[0].pad_before, pads[0].pad_after),
        (pads[1].pad_before, pads[1].pad_after),
    ) else {
        return Ok(None);
    };
    if geometry.out_h != pads[0].convoluted || geometry.out_w != pads[1].convoluted {
        return Ok(None);
    }
    let out_shape: TVec<usize> = match spec.data_format {
        DataFormat::NCHW => tvec![batch, c, geometry.out_h, geometry.out_w],
        _ => tvec![c, geometry.out_h, geometry.out_w],
    };
    Ok(Some(DepthwiseConv {
        geometry,
        batch,
        out_shape,
        weights: Arc::new(weights),
        bias: Arc::new(bias),
    }))
}

/// Replaces every depthwise `Conv` of `model` (decluttered, before `optimize`) that
/// [`DepthwiseConv`] can compute; returns how many were replaced.
///
/// # Errors
/// A tract error from reading the model or applying a patch.
pub fn rewrite(model: &mut TypedModel) -> TractResult<usize> {
    let mut replaced = 0;
    for id in model.eval_order()? {
        let node = model.node(id);
        let Some(conv) = node.op_as::<Conv>() else {
            continue;
        };
        let Some(op) = replacement(model, conv, &node.inputs)? else {
            continue;
        };
        // Same output fact as the Conv's, or leave it.
        let before = model.outlet_fact(OutletId::new(id, 0))?;
        if before.shape.as_concrete() != Some(op.out_shape.as_slice()) {
            continue;
        }
        let patch = TypedModelPatch::replace_single_op(model, node, &node.inputs[..1], op)?;
        patch.apply(model)?;
        replaced += 1;
    }
    Ok(replaced)
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
