//! A dense 2-D convolution with few input channels (a network's first convolution, its
//! "stem") for the NanoTrack verifier's tract plans, written so that the compiler
//! vectorises it on any target (SSE2 on x86_64, NEON on aarch64; no `target-cpu`, no
//! `unsafe`).
//!
//! NanoTrack v2's backbone starts with a 3 → 16 channel 3×3 convolution of stride 2 on the
//! 255×255 (or 127×127) RGB crop. tract 0.23.9 runs it as a `DirectSpatialConv`: four output
//! channels along each output row with an AVX2 kernel, but every run's last points, and the
//! padded border, one output value at a time through a scalar loop over the 27 taps, which
//! was most of its 7.7 M instructions per 255×255 pass (callgrind). Here:
//!
//! 1. the input is copied once into zero-padded planes split by stride phase (for stride 2,
//!    even and odd rows and columns go to four sub-planes per input channel), so that every
//!    kernel tap reads a *contiguous* run of one sub-plane, whatever the input layout
//!    (channel-first or channel-last);
//! 2. each output row is computed in chunks of [`CHUNK`] = 32 columns: per output channel
//!    the 32 sums live in eight 4-wide registers while the loop walks the taps (one
//!    broadcast weight, eight loads, multiplies and adds per tap), so the accumulators
//!    never go through memory and every column, border ones included, takes the same
//!    vectorised path (the columns past the output's width are computed and dropped);
//! 3. each chunk is written to the output in its layout.
//!
//! The sums run in another order than tract's, so results agree to rounding (tested:
//! against a naive reference here, against tract's own plan in `nano.rs`).
//!
//! [`rewrite`] replaces, in a decluttered [`TypedModel`], every `Conv` node that this op
//! computes (f32, one group, at most [`MAX_INPUT_CHANNELS`] input channels, a kernel larger
//! than 1×1, 2-D, any of tract's data and kernel formats, no dilation, constant kernel and
//! bias); the others keep tract's.

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

/// Output columns computed together (eight 4-wide registers of sums).
pub const CHUNK: usize = 32;

/// Most input channels [`rewrite`] takes (a first convolution's colour planes; wider
/// dense convolutions are 1×1 in NanoTrack and run as tract's matrix products).
pub const MAX_INPUT_CHANNELS: usize = 4;

/// The shape of one convolution (one batch item).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Geometry {
    /// Input channels.
    pub in_c: usize,
    /// Output channels.
    pub out_c: usize,
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
    /// The output size for `pad_after`, or `None` when the kernel does not fit the padded
    /// input or a size is zero.
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
    /// than the padded input, padding as wide as the kernel).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        (in_c, out_c): (usize, usize),
        (in_h, in_w): (usize, usize),
        (k_h, k_w): (usize, usize),
        (stride_h, stride_w): (usize, usize),
        (pad_top, pad_bottom): (usize, usize),
        (pad_left, pad_right): (usize, usize),
    ) -> Option<Self> {
        if in_c == 0 || out_c == 0 || pad_top >= k_h.max(1) || pad_left >= k_w.max(1) {
            return None;
        }
        let out_h = Self::output(in_h, k_h, stride_h, pad_top, pad_bottom)?;
        let out_w = Self::output(in_w, k_w, stride_w, pad_left, pad_right)?;
        Some(Self {
            in_c,
            out_c,
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

    /// Taps of one output value (`in_c · k_h · k_w`).
    pub fn taps(&self) -> usize {
        self.in_c * self.k_h * self.k_w
    }

    /// Values of the input (one batch item).
    pub fn in_len(&self) -> usize {
        self.in_c * self.in_h * self.in_w
    }

    /// Values of the output (one batch item).
    pub fn out_len(&self) -> usize {
        self.out_c * self.out_h * self.out_w
    }

    /// Chunks of [`CHUNK`] columns per output row.
    fn chunks(&self) -> usize {
        self.out_w.div_ceil(CHUNK)
    }

    /// Rows of a stride-phase sub-plane: those the taps read.
    fn phase_h(&self) -> usize {
        ((self.out_h - 1) * self.stride_h + self.k_h).div_ceil(self.stride_h)
    }

    /// Columns of a stride-phase sub-plane: those the taps of every chunk read, the
    /// columns past the output's width included.
    fn phase_w(&self) -> usize {
        self.chunks() * CHUNK + (self.k_w - 1) / self.stride_w
    }
}

/// Where the channels are in a tensor (one batch item).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Layout {
    /// `[C, H, W]`.
    ChannelFirst,
    /// `[H, W, C]`.
    ChannelLast,
}

impl Layout {
    /// Element strides `(channel, row, column)` of a `channels × h × w` tensor.
    fn strides(self, channels: usize, h: usize, w: usize) -> (usize, usize, usize) {
        match self {
            Layout::ChannelFirst => (h * w, w, 1),
            Layout::ChannelLast => (1, w * channels, channels),
        }
    }
}

/// A convolution's constant weights, ready for [`conv`]: per output channel, each tap's
/// weight broadcast to four lanes, taps in `(input channel, ky, kx)` order.
#[derive(Debug, Clone, PartialEq)]
pub struct Weights {
    geometry: Geometry,
    splat: Vec<[f32; 4]>,
    bias: Vec<f32>,
}

impl Weights {
    /// The weights of `g` from an `OIHW` kernel (`out_c × in_c × k_h × k_w`) and one bias per
    /// output channel; `None` for wrong lengths.
    pub fn new(g: &Geometry, oihw: &[f32], bias: &[f32]) -> Option<Self> {
        if oihw.len() != g.out_c * g.taps() || bias.len() != g.out_c {
            return None;
        }
        Some(Self {
            geometry: *g,
            splat: oihw.iter().map(|&w| [w; 4]).collect(),
            bias: bias.to_vec(),
        })
    }

    /// The geometry they were made for.
    pub fn geometry(&self) -> &Geometry {
        &self.geometry
    }
}

/// Reusable buffers of [`conv`].
#[derive(Debug, Default)]
pub struct Scratch {
    phases: Vec<f32>,
}

/// The convolution of `input` (one batch item of `w`'s geometry, in `layout`) into `output`
/// (same layout), zero padding. Returns `false` (and leaves `output` alone) when a slice
/// has the wrong length.
pub fn conv(
    w: &Weights,
    layout: Layout,
    input: &[f32],
    output: &mut [f32],
    scratch: &mut Scratch,
) -> bool {
    let g = &w.geometry;
    if input.len() != g.in_len() || output.len() != g.out_len() {
        return false;
    }
    let (sh, sw) = (g.stride_h, g.stride_w);
    let (hq, wq) = (g.phase_h(), g.phase_w());
    let sub = hq * wq;
    // Sub-plane of input channel c, row phase a, column phase b.
    let plane = |c: usize, a: usize, b: usize| ((c * sh + a) * sw + b) * sub;
    scratch.phases.clear();
    scratch.phases.resize(g.in_c * sh * sw * sub, 0.0);
    // 1. Padded, phase-split copy: padded row py = y + pad_top goes to row phase py % sh,
    //    row py / sh; likewise columns. Rows and columns no tap reads are skipped.
    let (cs, ys, xs) = layout.strides(g.in_c, g.in_h, g.in_w);
    let x_end = g.in_w.min((wq * sw).saturating_sub(g.pad_left));
    for c in 0..g.in_c {
        for y in 0..g.in_h {
            let py = y + g.pad_top;
            if py / sh >= hq {
                break;
            }
            let row_base = plane(c, py % sh, 0) + (py / sh) * wq;
            let src = c * cs + y * ys;
            if xs == 1 && sw == 2 {
                // Pairs of input columns split to the two column phases at once.
                let row = &input[src..src + x_end];
                let (c0, c1) = (g.pad_left / 2, g.pad_left.div_ceil(2));
                let pairs = x_end / 2;
                let (lo, hi) = scratch.phases.split_at_mut(row_base + sub);
                let (first, second) = (&mut lo[row_base..row_base + wq], &mut hi[..wq]);
                let (even, odd) = if g.pad_left.is_multiple_of(2) {
                    (&mut first[c0..c0 + pairs], &mut second[c1..c1 + pairs])
                } else {
                    (&mut second[c0..c0 + pairs], &mut first[c1..c1 + pairs])
                };
                for ((e, o), p) in even.iter_mut().zip(odd.iter_mut()).zip(row.chunks_exact(2)) {
                    *e = p[0];
                    *o = p[1];
                }
                if x_end % 2 == 1 {
                    let px = g.pad_left + x_end - 1;
                    scratch.phases[row_base + (px % 2) * sub + px / 2] = row[x_end - 1];
                }
            } else if xs == 1 && sw == 1 {
                let first = row_base + g.pad_left;
                scratch.phases[first..first + x_end].copy_from_slice(&input[src..src + x_end]);
            } else {
                for x in 0..x_end {
                    let px = x + g.pad_left;
                    scratch.phases[row_base + (px % sw) * sub + px / sw] = input[src + x * xs];
                }
            }
        }
    }
    // 2. and 3. Per output row and chunk: the run each tap reads, then every output
    //    channel's sums, written out in the layout.
    let taps = g.taps();
    let (ocs, oys, oxs) = layout.strides(g.out_c, g.out_h, g.out_w);
    let phases = &scratch.phases;
    let mut runs: Vec<&[f32; CHUNK]> = Vec::with_capacity(taps);
    let mut sums = [0.0f32; CHUNK];
    for oy in 0..g.out_h {
        for chunk in 0..g.chunks() {
            let x0 = chunk * CHUNK;
            runs.clear();
            for t in 0..taps {
                let (c, ky, kx) = (t / (g.k_h * g.k_w), t / g.k_w % g.k_h, t % g.k_w);
                let s = plane(c, ky % sh, kx % sw) + (oy + ky / sh) * wq + x0 + kx / sw;
                // In bounds by the phase planes' size; checked all the same.
                match phases.get(s..s + CHUNK).map(<&[f32; CHUNK]>::try_from) {
                    Some(Ok(run)) => runs.push(run),
                    _ => return false,
                }
            }
            let n = CHUNK.min(g.out_w - x0);
            for (o, &b) in w.bias.iter().enumerate() {
                chunk_sums(&runs, &w.splat[o * taps..(o + 1) * taps], b, &mut sums);
                let first = o * ocs + oy * oys + x0 * oxs;
                if oxs == 1 {
                    output[first..first + n].copy_from_slice(&sums[..n]);
                } else {
                    for (i, &v) in sums[..n].iter().enumerate() {
                        output[first + i * oxs] = v;
                    }
                }
            }
        }
    }
    true
}

/// One output channel's [`CHUNK`] sums: `bias + Σₜ weights[t] · runs[t][i]`, the taps
/// three at a time (the sums stay in registers; the weights are pre-broadcast, so a tap is
/// a load, a multiply and an add per four columns).
fn chunk_sums(runs: &[&[f32; CHUNK]], weights: &[[f32; 4]], bias: f32, sums: &mut [f32; CHUNK]) {
    let mut acc = [bias; CHUNK];
    let mut r3 = runs.chunks_exact(3);
    let mut w3 = weights.chunks_exact(3);
    for (r, w) in (&mut r3).zip(&mut w3) {
        tap(&mut acc, r[0], &w[0]);
        tap(&mut acc, r[1], &w[1]);
        tap(&mut acc, r[2], &w[2]);
    }
    for (r, w) in r3.remainder().iter().zip(w3.remainder()) {
        tap(&mut acc, r, w);
    }
    *sums = acc;
}

/// `acc[i] += w · x[i]`, four columns at a time.
#[inline(always)]
fn tap(acc: &mut [f32; CHUNK], x: &[f32; CHUNK], w: &[f32; 4]) {
    for (a, x) in acc.chunks_exact_mut(4).zip(x.chunks_exact(4)) {
        for k in 0..4 {
            a[k] += w[k] * x[k];
        }
    }
}

/// tract operator running [`conv`] with constant weights and bias on one input, an f32
/// tensor in `NCHW`, `CHW`, `NHWC` or `HWC`.
#[derive(Debug, Clone)]
pub struct StemConv {
    weights: Arc<Weights>,
    layout: Layout,
    batch: usize,
    out_shape: TVec<usize>,
}

impl PartialEq for StemConv {
    fn eq(&self, other: &Self) -> bool {
        let bits = |w: &Weights| {
            (w.splat.iter().flatten().chain(&w.bias))
                .map(|x| x.to_bits())
                .collect::<Vec<_>>()
        };
        self.weights.geometry == other.weights.geometry
            && self.layout == other.layout
            && self.batch == other.batch
            && self.out_shape == other.out_shape
            && bits(&self.weights) == bits(&other.weights)
    }
}

impl Eq for StemConv {}

impl StemConv {
    /// The op's geometry.
    pub fn geometry(&self) -> &Geometry {
        &self.weights.geometry
    }

    /// The op's data layout.
    pub fn layout(&self) -> Layout {
        self.layout
    }
}

impl Op for StemConv {
    fn name(&self) -> StaticName {
        "BevtStemConv".into()
    }

    fn info(&self) -> TractResult<Vec<String>> {
        Ok(vec![format!(
            "{:?} {:?}",
            self.weights.geometry, self.layout
        )])
    }

    fn validation(&self) -> Validation {
        Validation::Rounding
    }

    op_as_typed_op!();
}

/// A tract error carrying `msg`.
fn bail<T>(msg: String) -> TractResult<T> {
    Err(tract_onnx::prelude::TractError::msg(msg))
}

impl EvalOp for StemConv {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        let [input] = &*inputs else {
            return bail(format!("{} inputs; expected 1", inputs.len()));
        };
        let view = input.try_as_plain_ram()?;
        let data = view.as_slice::<f32>()?;
        let g = &self.weights.geometry;
        let (per_in, per_out) = (g.in_len(), g.out_len());
        if data.len() != self.batch * per_in {
            return bail(format!(
                "input of {} values; expected {}",
                data.len(),
                self.batch * per_in
            ));
        }
        // Every value is overwritten; the zeroing is tract's only safe allocation.
        let mut t = Tensor::zero::<f32>(&self.out_shape)?;
        {
            let mut view = t.try_as_plain_ram_mut()?;
            let out = view.as_slice_mut::<f32>()?;
            let mut scratch = Scratch::default();
            for n in 0..self.batch {
                let ok = conv(
                    &self.weights,
                    self.layout,
                    &data[n * per_in..(n + 1) * per_in],
                    &mut out[n * per_out..(n + 1) * per_out],
                    &mut scratch,
                );
                if !ok {
                    return bail("inconsistent stem convolution geometry".to_string());
                }
            }
        }
        Ok(tvec!(t.into_tvalue()))
    }
}

impl TypedOp for StemConv {
    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        let [input] = inputs else {
            return bail(format!("{} inputs; expected 1", inputs.len()));
        };
        if input.datum_type != DatumType::F32 {
            return bail(format!("input {:?}; expected f32", input.datum_type));
        }
        Ok(tvec!(TypedFact::dt_shape(
            DatumType::F32,
            self.out_shape.as_slice()
        )))
    }

    as_op!();
}

/// `kernel` (shape `shape` in `format`) reordered to `OIHW` for `out_c × in_c × k_h × k_w`,
/// or `None` when the shape does not match.
fn to_oihw(
    kernel: &[f32],
    shape: &[usize],
    format: KernelFormat,
    (out_c, in_c, k_h, k_w): (usize, usize, usize, usize),
) -> Option<Vec<f32>> {
    let expected: [usize; 4] = match format {
        KernelFormat::OIHW => [out_c, in_c, k_h, k_w],
        KernelFormat::HWIO => [k_h, k_w, in_c, out_c],
        KernelFormat::OHWI => [out_c, k_h, k_w, in_c],
    };
    if shape != expected || kernel.len() != out_c * in_c * k_h * k_w {
        return None;
    }
    let mut out = Vec::with_capacity(kernel.len());
    for o in 0..out_c {
        for i in 0..in_c {
            for y in 0..k_h {
                for x in 0..k_w {
                    out.push(
                        kernel[match format {
                            KernelFormat::OIHW => ((o * in_c + i) * k_h + y) * k_w + x,
                            KernelFormat::HWIO => ((y * k_w + x) * in_c + i) * out_c + o,
                            KernelFormat::OHWI => ((o * k_h + y) * k_w + x) * in_c + i,
                        }],
                    );
                }
            }
        }
    }
    Some(out)
}

/// The [`StemConv`] computing `conv` on `model`'s `inputs`, or `None` when this op cannot
/// (see the module doc).
fn replacement(
    model: &TypedModel,
    conv: &Conv,
    inputs: &[OutletId],
) -> TractResult<Option<StemConv>> {
    let spec = &conv.pool_spec;
    let (in_c, out_c) = (spec.input_channels, spec.output_channels);
    if conv.q_params.is_some()
        || inputs.len() != 3
        || conv.group != 1
        || in_c == 0
        || in_c > MAX_INPUT_CHANNELS
        || spec.kernel_shape.len() != 2
        || spec.kernel_shape.iter().product::<usize>() < 2
        || spec.dilations().iter().any(|&d| d != 1)
    {
        return Ok(None);
    }
    let data = model.outlet_fact(inputs[0])?;
    let Some(shape) = data.shape.as_concrete() else {
        return Ok(None);
    };
    let (layout, batch, c, h, w) = match (spec.data_format, shape) {
        (DataFormat::NCHW, &[n, c, h, w]) => (Layout::ChannelFirst, n, c, h, w),
        (DataFormat::CHW, &[c, h, w]) => (Layout::ChannelFirst, 1, c, h, w),
        (DataFormat::NHWC, &[n, h, w, c]) => (Layout::ChannelLast, n, c, h, w),
        (DataFormat::HWC, &[h, w, c]) => (Layout::ChannelLast, 1, c, h, w),
        _ => return Ok(None),
    };
    if data.datum_type != DatumType::F32 || c != in_c {
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
        || bias.datum_type() != DatumType::F32
        || !(bias.len() == out_c || bias.len() == 1)
    {
        return Ok(None);
    }
    let kernel_view = kernel.try_as_plain_ram()?;
    let Some(oihw) = to_oihw(
        kernel_view.as_slice::<f32>()?,
        kernel.shape(),
        conv.kernel_fmt,
        (out_c, in_c, k_h, k_w),
    ) else {
        return Ok(None);
    };
    let bias_view = bias.try_as_plain_ram()?;
    let b = bias_view.as_slice::<f32>()?;
    let bias = if b.len() == 1 {
        vec![b[0]; out_c]
    } else {
        b.to_vec()
    };
    let pads = spec.computed_padding(&[h, w]);
    let strides = spec.strides();
    let Some(geometry) = Geometry::new(
        (in_c, out_c),
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
    let Some(weights) = Weights::new(&geometry, &oihw, &bias) else {
        return Ok(None);
    };
    let (oh, ow) = (geometry.out_h, geometry.out_w);
    let out_shape: TVec<usize> = match spec.data_format {
        DataFormat::NCHW => tvec![batch, out_c, oh, ow],
        DataFormat::CHW => tvec![out_c, oh, ow],
        DataFormat::NHWC => tvec![batch, oh, ow, out_c],
        DataFormat::HWC => tvec![oh, ow, out_c],
    };
    Ok(Some(StemConv {
        weights: Arc::new(weights),
        layout,
        batch,
        out_shape,
    }))
}

/// Replaces every `Conv` of `model` (decluttered, before `optimize`) that [`StemConv`] can
/// compute; returns how many were replaced.
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
        if before.datum_type != DatumType::F32
            || before.shape.as_concrete() != Some(op.out_shape.as_slice())
        {
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

    /// Straightforward convolution, zero padding, channel-first `OIHW`, in f64.
    fn naive(g: &Geometry, input: &[f32], oihw: &[f32], bias: &[f32]) -> Vec<f32> {
        let mut out = vec![0.0; g.out_len()];
        for o in 0..g.out_c {
            for oy in 0..g.out_h {
                for ox in 0..g.out_w {
                    let mut s = f64::from(bias[o]);
                    for c in 0..g.in_c {
                        for ky in 0..g.k_h {
                            for kx in 0..g.k_w {
                                let y = (oy * g.stride_h + ky) as isize - g.pad_top as isize;
                                let x = (ox * g.stride_w + kx) as isize - g.pad_left as isize;
                                if y < 0 || x < 0 || y >= g.in_h as isize || x >= g.in_w as isize {
                                    continue;
                                }
                                let v = input[(c * g.in_h + y as usize) * g.in_w + x as usize];
                                let k = oihw[((o * g.in_c + c) * g.k_h + ky) * g.k_w + kx];
                                s += f64::from(v) * f64::from(k);
                            }
                        }
                    }
                    out[(o * g.out_h + oy) * g.out_w + ox] = s as f32;
                }
            }
        }
        out
    }

    /// `chw` (`channels × h × w`) reordered to `[h, w, channels]`.
    fn to_hwc(chw: &[f32], channels: usize, h: usize, w: usize) -> Vec<f32> {
        let mut out = vec![0.0; chw.len()];
        for c in 0..channels {
            for p in 0..h * w {
                out[p * channels + c] = chw[c * h * w + p];
            }
        }
        out
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

    /// Largest `|conv − naive|` for `g` in both layouts (every output written: the buffers
    /// start as NaN).
    fn worst_against_naive(g: &Geometry, seed: u32, scratch: &mut Scratch) -> f32 {
        let input = values(g.in_len(), seed);
        let oihw = values(g.out_c * g.taps(), seed + 1000);
        let bias = values(g.out_c, seed + 2000);
        let want = naive(g, &input, &oihw, &bias);
        let Some(w) = Weights::new(g, &oihw, &bias) else {
            panic!("{g:?}: weights refused")
        };
        let mut got = vec![f32::NAN; want.len()];
        assert!(conv(&w, Layout::ChannelFirst, &input, &mut got, scratch));
        let mut got_last = vec![f32::NAN; want.len()];
        let input_last = to_hwc(&input, g.in_c, g.in_h, g.in_w);
        assert!(conv(
            &w,
            Layout::ChannelLast,
            &input_last,
            &mut got_last,
            scratch
        ));
        let want_last = to_hwc(&want, g.out_c, g.out_h, g.out_w);
        got.iter()
            .zip(&want)
            .chain(got_last.iter().zip(&want_last))
            .map(|(a, b)| (a - b).abs())
            .fold(
                0.0f32,
                |m, d| if d.is_nan() { f32::INFINITY } else { m.max(d) },
            )
    }

    #[test]
    fn matches_a_naive_reference_on_odd_sizes_strides_kernels_padding_and_layouts() {
        let mut scratch = Scratch::default();
        let mut cases = 0;
        for &(h, w) in &[(7, 9), (13, 5), (1, 6), (5, 1), (11, 70), (33, 31)] {
            for &(k_h, k_w) in &[(3usize, 3usize), (1, 3), (5, 2)] {
                for &s in &[1, 2, 3] {
                    for &(pt, pb, pl, pr) in &[
                        (0, 0, 0, 0),
                        (k_h / 2, k_h / 2, k_w / 2, k_w / 2),
                        (k_h / 2, 0, 0, k_w / 2),
                        (k_h - 1, k_h - 1, k_w.saturating_sub(2), k_w - 1),
                    ] {
                        for &(in_c, out_c) in &[(3, 16), (1, 5), (4, 3)] {
                            let Some(g) = Geometry::new(
                                (in_c, out_c),
                                (h, w),
                                (k_h, k_w),
                                (s, s),
                                (pt, pb),
                                (pl, pr),
                            ) else {
                                continue;
                            };
                            let worst = worst_against_naive(&g, cases, &mut scratch);
                            assert!(worst <= 1e-5, "{g:?}: {worst}");
                            cases += 1;
                        }
                    }
                }
            }
        }
        // Every size, kernel, stride and channel count with at least the unpadded and
        // "same" padding, minus those a 1-wide input cannot take.
        assert!(cases > 400, "{cases} cases");
    }

    #[test]
    fn the_verifiers_first_convolution_matches_the_reference() {
        // NanoTrack v2's: 3 → 16, 3×3, stride 2, padding 1, on both crop sizes; mixed
        // strides on a wide input (several chunks, a partial last one).
        let mut scratch = Scratch::default();
        for (i, &side) in [255usize, 127].iter().enumerate() {
            let Some(g) = Geometry::new((3, 16), (side, side), (3, 3), (2, 2), (1, 1), (1, 1))
            else {
                panic!("valid geometry refused")
            };
            assert_eq!((g.out_h, g.out_w), (side.div_ceil(2), side.div_ceil(2)));
            let worst = worst_against_naive(&g, i as u32, &mut scratch);
            assert!(worst <= 1e-5, "{side}: {worst}");
        }
        let Some(g) = Geometry::new((2, 3), (9, 100), (3, 5), (2, 1), (1, 1), (2, 2)) else {
            panic!("valid geometry refused")
        };
        let worst = worst_against_naive(&g, 7, &mut scratch);
        assert!(worst <= 1e-5, "{worst}");
    }

    #[test]
    fn kernel_formats_are_reordered_to_oihw() {
        let (o, i, h, w) = (2, 3, 2, 3);
        let oihw: Vec<f32> = (0..o * i * h * w).map(|v| v as f32).collect();
        let at = |a: usize, b: usize, y: usize, x: usize| oihw[((a * i + b) * h + y) * w + x];
        let mut hwio = vec![0.0; oihw.len()];
        let mut ohwi = vec![0.0; oihw.len()];
        for a in 0..o {
            for b in 0..i {
                for y in 0..h {
                    for x in 0..w {
                        hwio[((y * w + x) * i + b) * o + a] = at(a, b, y, x);
                        ohwi[((a * h + y) * w + x) * i + b] = at(a, b, y, x);
                    }
                }
            }
        }
        let dims = (o, i, h, w);
        let f = KernelFormat::OIHW;
        assert_eq!(to_oihw(&oihw, &[o, i, h, w], f, dims), Some(oihw.clone()));
        let f = KernelFormat::HWIO;
        assert_eq!(to_oihw(&hwio, &[h, w, i, o], f, dims), Some(oihw.clone()));
        let f = KernelFormat::OHWI;
        assert_eq!(to_oihw(&ohwi, &[o, h, w, i], f, dims), Some(oihw.clone()));
        assert_eq!(to_oihw(&ohwi, &[o, i, h, w], f, dims), None);
    }

    #[test]
    fn wrong_lengths_and_impossible_geometries_are_refused() {
        let new = |c, k, s, p| Geometry::new(c, (4, 4), k, s, p, (1, 1));
        assert!(new((0, 1), (3, 3), (1, 1), (1, 1)).is_none());
        assert!(new((1, 0), (3, 3), (1, 1), (1, 1)).is_none());
        assert!(new((1, 1), (3, 3), (0, 1), (1, 1)).is_none());
        assert!(new((1, 1), (3, 3), (1, 1), (3, 0)).is_none());
        assert!(new((1, 1), (7, 3), (1, 1), (0, 0)).is_none());
        let Some(g) = new((2, 3), (3, 3), (1, 1), (1, 1)) else {
            panic!("valid geometry refused")
        };
        assert!(Weights::new(&g, &[0.0; 53], &[0.0; 3]).is_none());
        assert!(Weights::new(&g, &[0.0; 54], &[0.0; 2]).is_none());
        let Some(w) = Weights::new(&g, &[0.5; 54], &[0.0; 3]) else {
            panic!("valid weights refused")
        };
        let mut out = vec![7.0; 48];
        let mut s = Scratch::default();
        for layout in [Layout::ChannelFirst, Layout::ChannelLast] {
            assert!(!conv(&w, layout, &[0.0; 31], &mut out, &mut s));
            assert!(!conv(&w, layout, &[0.0; 33], &mut out, &mut s));
            assert!(!conv(&w, layout, &[0.0; 32], &mut out[..47], &mut s));
        }
        assert!(out.iter().all(|&v| v == 7.0));
        assert!(conv(&w, Layout::ChannelFirst, &[1.0; 32], &mut out, &mut s));
        assert!(out.iter().all(|&v| v != 7.0));
    }
}
