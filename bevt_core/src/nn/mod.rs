//! A small pure-Rust inference engine for the convolutional networks the tracker embeds
//! (NanoTrack v2's backbone and head, the re-detection verifier): an ONNX file is read
//! ([`onnx`]), and [`Plan::new`] turns it, for fixed input shapes and the outputs asked
//! for, into a list of steps over buffers sized once (tensors whose steps do not overlap
//! share one, so a pass stays in cache); a [`Runner`] owns the buffers and runs the steps.
//! Single-threaded and allocation-free per run.
//!
//! Operators: `Conv` (any groups; one group, 1 × 1 or not, through our own blocked product
//! `ops::rows_product` with the bias and activation applied as it stores, depthwise
//! through [`crate::redetect::dwconv`], other groupings through im2col and a matrix
//! product), `Gemm`,
//! `MatMul`, `Relu`, `Sigmoid`, `Exp`, `HardSigmoid`, `HardSwish`, `Clip`, `Add`, `Sub`,
//! `Mul`, `Div` (numpy broadcasting), `GlobalAveragePool`, `Reshape`, `Flatten`,
//! `Transpose`, `Identity`, `Constant`. Another operator, a computed convolution kernel or a
//! dilation is a clear error at plan time. Only the nodes the requested outputs depend on
//! are planned, so one head can be planned as its classification branch alone, and
//! `window::windowed` rewrites a network so that its local layers compute only the output
//! points a caller reads (the learned box's 3 × 3 of NanoTrack's head), the same bits.
//!
//! Why not tract (what ran these networks before): it was the largest part of the build
//! (tract-core, -linalg, -data and the ONNX import, about half of a cold release build's
//! unit-seconds) for two small networks that use the operators above; docs/benchmarks.md
//! has the measured build and per-pass figures.

pub mod onnx;
pub(crate) mod ops;
pub(crate) mod window;

use crate::redetect::dwconv;
use onnx::{Attr, Data, Model, Node, Tensor};
use ops::{Binary, Broadcast, ConvShape, Unary};
use std::collections::HashMap;

/// Largest number of f32 values a plan's buffers may hold together (256 MB): a model
/// cannot make the process allocate more, whatever its shapes declare.
pub const MAX_PLAN_VALUES: usize = 64 << 20;

/// A value while planning: a constant, or a buffer of the runner and its shape.
#[derive(Debug, Clone)]
enum Val {
    Const(Tensor),
    Buf { slot: usize, shape: Vec<usize> },
}

/// How a convolution is computed.
#[derive(Debug, Clone)]
enum ConvKind {
    /// 1 × 1, stride 1, no padding, one group: a matrix product of the weights (packed by
    /// [`ops::pack_rows`]) and the input planes.
    Pointwise,
    /// One group per channel, one output per group.
    Depthwise(dwconv::Geometry),
    /// One group, any kernel: per output row, im2col of that row then a matrix product
    /// with the weights packed by [`ops::pack_rows`].
    Rows,
    /// Several groups: im2col then a matrix product, per group.
    General,
}

/// One step of a plan.
#[derive(Debug, Clone)]
enum Step {
    Conv {
        x: usize,
        y: usize,
        batch: usize,
        shape: ConvShape,
        kind: ConvKind,
        weights: Vec<f32>,
        bias: Vec<f32>,
        /// An activation fused in (applied to the output in place).
        act: Option<Unary>,
        /// [`ConvKind::Pointwise`] only: the buffer of one factor per input channel that
        /// multiplies `x`'s planes, and the activation then applied to the products: a
        /// channel-scaling `Mul` step fused in (see `Builder::conv`).
        scale: Option<(usize, Option<Unary>)>,
    },
    Unary {
        x: usize,
        y: usize,
        f: Unary,
    },
    Binary {
        a: usize,
        b: usize,
        y: usize,
        op: Binary,
        bc: Broadcast,
        act: Option<Unary>,
    },
    /// `y[batch][m×n] = α · a[batch][m×k] · b[batch][k×n] + bias` (strided operands).
    MatMul {
        a: usize,
        b: usize,
        y: usize,
        batch: usize,
        mkn: (usize, usize, usize),
        a_strides: (usize, usize, usize),
        b_strides: (usize, usize, usize),
        alpha: f32,
        /// β · C, broadcast to `[m, n]` (Gemm's third input), copied into `y` first.
        bias: Option<Vec<f32>>,
        act: Option<Unary>,
    },
    MeanPool {
        x: usize,
        y: usize,
        len: usize,
    },
    Transpose {
        x: usize,
        y: usize,
        shape: Vec<usize>,
        perm: Vec<usize>,
    },
}

impl Step {
    /// What the step computes, for the per-node timings ([`Runner::step_times`]).
    fn label(&self) -> String {
        match self {
            Step::Conv { shape: s, kind, .. } => {
                let what = match kind {
                    ConvKind::Pointwise => "1 × 1".to_string(),
                    ConvKind::Depthwise(_) => format!("depthwise {}×{}/{}", s.kh, s.kw, s.sh),
                    ConvKind::Rows => format!("{}×{}/{} by rows", s.kh, s.kw, s.sh),
                    ConvKind::General => format!("{}×{}/{} grouped", s.kh, s.kw, s.sh),
                };
                format!("conv {what}, {} → {} on {}×{}", s.c, s.m, s.h, s.w)
            }
            Step::Unary { f, .. } => format!("{f:?}"),
            Step::Binary { op, .. } => format!("{op:?}"),
            Step::MatMul { mkn, .. } => format!("matmul {mkn:?}"),
            Step::MeanPool { len, .. } => format!("mean pool of {len}"),
            Step::Transpose { shape, .. } => format!("transpose {shape:?}"),
        }
    }

    /// The slots the step reads and writes (a read operand may repeat).
    fn refs(&self) -> [Option<usize>; 4] {
        match *self {
            Step::Conv { x, y, scale, .. } => [Some(x), Some(y), scale.map(|(s, _)| s), None],
            Step::Unary { x, y, .. }
            | Step::MeanPool { x, y, .. }
            | Step::Transpose { x, y, .. } => [Some(x), Some(y), None, None],
            Step::Binary { a, b, y, .. } | Step::MatMul { a, b, y, .. } => {
                [Some(a), Some(b), Some(y), None]
            }
        }
    }
}

/// A network planned for fixed input shapes (see the module doc). Shared between runners.
#[derive(Debug, Clone)]
pub struct Plan {
    steps: Vec<Step>,
    /// Length of each slot (a tensor's values; 0 for a product fused away).
    slots: Vec<usize>,
    /// The buffer each slot lives in: slots whose steps do not overlap share one
    /// ([`Plan::share_buffers`]).
    buffer: Vec<usize>,
    /// Length of each buffer: the longest slot it holds.
    buffer_len: Vec<usize>,
    /// Buffers holding constants, filled when a runner is made.
    init: Vec<(usize, Vec<f32>)>,
    inputs: Vec<(String, usize, Vec<usize>)>,
    outputs: Vec<(String, usize, Vec<usize>)>,
    /// Largest im2col buffer a step needs.
    col_len: usize,
}

/// A planning error: what is wrong or unsupported, in words.
pub type Error = String;

fn attr_int(n: &Node, name: &str, default: i64) -> Result<i64, Error> {
    match n.attrs.get(name) {
        None => Ok(default),
        Some(Attr::Int(i)) => Ok(*i),
        Some(a) => Err(format!("{}: attribute {name} is {a:?}, not an int", who(n))),
    }
}

fn attr_float(n: &Node, name: &str, default: f32) -> Result<f32, Error> {
    match n.attrs.get(name) {
        None => Ok(default),
        Some(Attr::Float(f)) => Ok(*f),
        Some(a) => Err(format!(
            "{}: attribute {name} is {a:?}, not a float",
            who(n)
        )),
    }
}

fn attr_ints(n: &Node, name: &str) -> Result<Option<Vec<i64>>, Error> {
    match n.attrs.get(name) {
        None => Ok(None),
        Some(Attr::Ints(v)) => Ok(Some(v.clone())),
        Some(a) => Err(format!("{}: attribute {name} is {a:?}, not ints", who(n))),
    }
}

/// A node as messages name it.
fn who(n: &Node) -> String {
    if n.name.is_empty() {
        format!("{} node", n.op_type)
    } else {
        format!("{} node `{}`", n.op_type, n.name)
    }
}

fn to_usize(v: &[i64], what: &str) -> Result<Vec<usize>, Error> {
    v.iter()
        .map(|&x| usize::try_from(x).map_err(|_| format!("{what}: {x} is not a size")))
        .collect()
}

/// The plan under construction.
struct Builder {
    vals: HashMap<String, Val>,
    /// How many times each value is read (by the planned nodes and as an output).
    uses: HashMap<String, usize>,
    /// The value the last step wrote (by name: a reshaped alias of it does not count).
    last_out: Option<String>,
    plan: Plan,
    total: usize,
}

impl Builder {
    fn slot(&mut self, shape: &[usize]) -> Result<usize, Error> {
        let n = Tensor::count(shape).ok_or("a tensor size overflows")?;
        if n == 0 {
            return Err(format!("a tensor of shape {shape:?} holds no value"));
        }
        self.total = self.total.saturating_add(n);
        if self.total > MAX_PLAN_VALUES {
            return Err(format!(
                "the network's tensors need more than {MAX_PLAN_VALUES} values at these input \
                 sizes (the bound on a plan's memory)"
            ));
        }
        self.plan.slots.push(n);
        Ok(self.plan.slots.len() - 1)
    }

    /// A buffer holding `v` (a constant is copied into one, filled when a runner is made).
    fn buf(&mut self, v: &Val) -> Result<(usize, Vec<usize>), Error> {
        match v {
            Val::Buf { slot, shape } => Ok((*slot, shape.clone())),
            Val::Const(t) => {
                let slot = self.slot(&t.dims)?;
                self.plan.init.push((slot, t.to_f32()));
                Ok((slot, t.dims.clone()))
            }
        }
    }

    fn get(&self, n: &Node, i: usize) -> Result<Option<Val>, Error> {
        match n.inputs.get(i).filter(|s| !s.is_empty()) {
            None => Ok(None),
            Some(name) => self
                .vals
                .get(name)
                .cloned()
                .map(Some)
                .ok_or_else(|| format!("{}: input `{name}` is not defined before it", who(n))),
        }
    }

    fn need(&self, n: &Node, i: usize) -> Result<Val, Error> {
        self.get(n, i)?
            .ok_or_else(|| format!("{}: input {i} is missing", who(n)))
    }

    fn constant(&self, n: &Node, i: usize, what: &str) -> Result<Option<Tensor>, Error> {
        match self.get(n, i)? {
            None => Ok(None),
            Some(Val::Const(t)) => Ok(Some(t)),
            Some(Val::Buf { .. }) => Err(format!(
                "{}: its {what} (input {i}) must be a constant of the model",
                who(n)
            )),
        }
    }

    fn out(&mut self, n: &Node, shape: Vec<usize>) -> Result<usize, Error> {
        let slot = self.slot(&shape)?;
        let name = n
            .outputs
            .first()
            .ok_or_else(|| format!("{}: no output", who(n)))?;
        self.vals.insert(name.clone(), Val::Buf { slot, shape });
        self.last_out = Some(name.clone());
        Ok(slot)
    }

    /// Fuses activation `f` of node `n` into the last step when that step wrote `n`'s input
    /// and nothing else reads it (not another node, not an output): the activation then runs
    /// in place on the step's output, saving a buffer and a pass over it. Returns whether it
    /// did.
    fn fuse(&mut self, n: &Node, f: Unary) -> bool {
        let (Some(input), Some(output)) = (n.inputs.first(), n.outputs.first()) else {
            return false;
        };
        if self.uses.get(input.as_str()).copied().unwrap_or(0) != 1
            || self.last_out.as_ref() != Some(input)
        {
            return false;
        }
        let Some(Val::Buf { slot, shape }) = self.vals.get(input).cloned() else {
            return false;
        };
        let written = match self.plan.steps.last_mut() {
            Some(Step::Conv { y, act, .. })
            | Some(Step::Binary { y, act, .. })
            | Some(Step::MatMul { y, act, .. }) => (*y == slot && act.is_none()).then_some(act),
            _ => None,
        };
        let Some(act) = written else {
            return false;
        };
        *act = Some(f);
        self.vals.insert(output.clone(), Val::Buf { slot, shape });
        true
    }

    fn node(&mut self, n: &Node) -> Result<(), Error> {
        if !n.domain.is_empty() && n.domain != "ai.onnx" {
            return Err(format!(
                "{}: operator domain `{}` is not supported",
                who(n),
                n.domain
            ));
        }
        match n.op_type.as_str() {
            "Conv" => self.conv(n),
            "Relu" | "Sigmoid" | "Exp" | "HardSigmoid" | "HardSwish" | "Clip" => {
                let f = match n.op_type.as_str() {
                    "Relu" => Unary::Relu,
                    "Sigmoid" => Unary::Sigmoid,
                    "Exp" => Unary::Exp,
                    "HardSwish" => Unary::HardSwish,
                    "HardSigmoid" => Unary::HardSigmoid(
                        attr_float(n, "alpha", 0.2)?,
                        attr_float(n, "beta", 0.5)?,
                    ),
                    _ => {
                        let bound = |i: usize, attr: &str, d: f32| -> Result<f32, Error> {
                            match self.constant(n, i, attr)? {
                                Some(t) if t.dims.iter().product::<usize>() == 1 => {
                                    Ok(t.to_f32()[0])
                                }
                                Some(t) => Err(format!("{}: {attr} of shape {:?}", who(n), t.dims)),
                                None => attr_float(n, attr, d),
                            }
                        };
                        Unary::Clip(
                            bound(1, "min", f32::NEG_INFINITY)?,
                            bound(2, "max", f32::INFINITY)?,
                        )
                    }
                };
                if self.fuse(n, f) {
                    return Ok(());
                }
                let (x, shape) = self.buf(&self.need(n, 0)?)?;
                let y = self.out(n, shape)?;
                self.plan.steps.push(Step::Unary { x, y, f });
                Ok(())
            }
            "Add" | "Sub" | "Mul" | "Div" => {
                let op = match n.op_type.as_str() {
                    "Add" => Binary::Add,
                    "Sub" => Binary::Sub,
                    "Mul" => Binary::Mul,
                    _ => Binary::Div,
                };
                let (a, sa) = self.buf(&self.need(n, 0)?)?;
                let (b, sb) = self.buf(&self.need(n, 1)?)?;
                let (shape, bc) = Broadcast::new(&sa, &sb).ok_or_else(|| {
                    format!("{}: shapes {sa:?} and {sb:?} do not broadcast", who(n))
                })?;
                let y = self.out(n, shape)?;
                self.plan.steps.push(Step::Binary {
                    a,
                    b,
                    y,
                    op,
                    bc,
                    act: None,
                });
                Ok(())
            }
            "GlobalAveragePool" => {
                let (x, s) = self.buf(&self.need(n, 0)?)?;
                if s.len() < 3 {
                    return Err(format!("{}: input of rank {}", who(n), s.len()));
                }
                let len = s[2..].iter().product::<usize>().max(1);
                let mut shape = s[..2].to_vec();
                shape.resize(s.len(), 1);
                let y = self.out(n, shape)?;
                self.plan.steps.push(Step::MeanPool { x, y, len });
                Ok(())
            }
            "Reshape" | "Flatten" | "Identity" => self.reshape(n),
            "Transpose" => {
                let (x, shape) = self.buf(&self.need(n, 0)?)?;
                let perm = match attr_ints(n, "perm")? {
                    Some(p) => to_usize(&p, "perm")?,
                    None => (0..shape.len()).rev().collect(),
                };
                let mut seen = vec![false; shape.len()];
                for &p in &perm {
                    if p >= shape.len() || std::mem::replace(&mut seen[p], true) {
                        return Err(format!(
                            "{}: perm {perm:?} for rank {}",
                            who(n),
                            shape.len()
                        ));
                    }
                }
                if perm.len() != shape.len() {
                    return Err(format!(
                        "{}: perm {perm:?} for rank {}",
                        who(n),
                        shape.len()
                    ));
                }
                let out = perm.iter().map(|&p| shape[p]).collect();
                let y = self.out(n, out)?;
                self.plan.steps.push(Step::Transpose { x, y, shape, perm });
                Ok(())
            }
            "MatMul" | "Gemm" => self.matmul(n),
            "Constant" => {
                let t = match n.attrs.get("value") {
                    Some(Attr::Tensor(t)) => t.clone(),
                    Some(Attr::Float(f)) => Tensor {
                        dims: vec![],
                        data: Data::F32(vec![*f]),
                    },
                    Some(Attr::Int(i)) => Tensor {
                        dims: vec![],
                        data: Data::I64(vec![*i]),
                    },
                    _ => return Err(format!("{}: only `value` constants are supported", who(n))),
                };
                let name = n.outputs.first().ok_or("Constant without output")?;
                self.vals.insert(name.clone(), Val::Const(t));
                Ok(())
            }
            op => Err(format!("{}: operator `{op}` is not supported", who(n))),
        }
    }

    /// `Reshape`, `Flatten`, `Identity`: the same values under another shape (a buffer is
    /// shared, a constant stays constant).
    fn reshape(&mut self, n: &Node) -> Result<(), Error> {
        let x = self.need(n, 0)?;
        let shape_of = |v: &Val| match v {
            Val::Const(t) => t.dims.clone(),
            Val::Buf { shape, .. } => shape.clone(),
        };
        let old = shape_of(&x);
        let count = Tensor::count(&old).ok_or("size overflow")?;
        let new = match n.op_type.as_str() {
            "Identity" => old.clone(),
            "Flatten" => {
                let axis = attr_int(n, "axis", 1)?;
                let r = old.len() as i64;
                let axis = if axis < 0 { axis + r } else { axis };
                if !(0..=r).contains(&axis) {
                    return Err(format!("{}: axis {axis} for rank {r}", who(n)));
                }
                let a = axis as usize;
                vec![old[..a].iter().product(), old[a..].iter().product()]
            }
            _ => {
                let spec = self
                    .constant(n, 1, "shape")?
                    .ok_or_else(|| format!("{}: no shape", who(n)))?;
                let spec = spec
                    .as_i64()
                    .ok_or_else(|| format!("{}: shape is not int64", who(n)))?
                    .to_vec();
                let allow_zero = attr_int(n, "allowzero", 0)? != 0;
                let mut out = Vec::with_capacity(spec.len());
                let mut infer = None;
                for (i, &d) in spec.iter().enumerate() {
                    out.push(match d {
                        -1 if infer.is_none() => {
                            infer = Some(i);
                            1
                        }
                        0 if !allow_zero => *old.get(i).ok_or_else(|| {
                            format!("{}: shape {spec:?} copies a missing dimension", who(n))
                        })?,
                        d if d >= 0 => d as usize,
                        _ => return Err(format!("{}: shape {spec:?}", who(n))),
                    });
                }
                if let Some(i) = infer {
                    let rest: usize = out.iter().product();
                    if rest == 0 || count % rest != 0 {
                        return Err(format!("{}: {old:?} cannot become {spec:?}", who(n)));
                    }
                    out[i] = count / rest;
                }
                out
            }
        };
        if Tensor::count(&new) != Some(count) {
            return Err(format!("{}: {old:?} cannot become {new:?}", who(n)));
        }
        let v = match x {
            Val::Const(t) => Val::Const(Tensor {
                dims: new,
                data: t.data,
            }),
            Val::Buf { slot, .. } => Val::Buf { slot, shape: new },
        };
        let name = n.outputs.first().ok_or("no output")?;
        self.vals.insert(name.clone(), v);
        Ok(())
    }

    fn conv(&mut self, n: &Node) -> Result<(), Error> {
        let (mut x, xs) = self.buf(&self.need(n, 0)?)?;
        let w = self
            .constant(n, 1, "kernel")?
            .ok_or_else(|| format!("{}: no kernel", who(n)))?;
        let bias = self.constant(n, 2, "bias")?;
        let bad = |what: String| format!("{}: {what}", who(n));
        if xs.len() != 4 || w.dims.len() != 4 {
            return Err(bad(format!(
                "input {xs:?} and kernel {:?}: only 2-D convolutions are supported",
                w.dims
            )));
        }
        let groups = usize::try_from(attr_int(n, "group", 1)?).map_err(|_| bad("group".into()))?;
        let (batch, c, h, wd) = (xs[0], xs[1], xs[2], xs[3]);
        let (m, cg, kh, kw) = (w.dims[0], w.dims[1], w.dims[2], w.dims[3]);
        if groups == 0 || c % groups != 0 || m % groups != 0 || c / groups != cg {
            return Err(bad(format!(
                "{c} input channels, kernel {:?}, {groups} groups do not fit",
                w.dims
            )));
        }
        if let Some(k) = attr_ints(n, "kernel_shape")? {
            if to_usize(&k, "kernel_shape")? != [kh, kw] {
                return Err(bad(format!(
                    "kernel_shape {k:?} against kernel {:?}",
                    w.dims
                )));
            }
        }
        if let Some(d) = attr_ints(n, "dilations")? {
            if d.iter().any(|&d| d != 1) {
                return Err(bad(format!("dilations {d:?}: only 1 is supported")));
            }
        }
        let strides = to_usize(&attr_ints(n, "strides")?.unwrap_or(vec![1, 1]), "strides")?;
        if strides.len() != 2 || strides.contains(&0) {
            return Err(bad(format!("strides {strides:?}")));
        }
        let (sh, sw) = (strides[0], strides[1]);
        let auto = match n.attrs.get("auto_pad") {
            Some(Attr::Str(s)) => s.clone(),
            _ => "NOTSET".into(),
        };
        let (pt, pl, pb, pr) = match auto.as_str() {
            "NOTSET" => {
                let p = to_usize(&attr_ints(n, "pads")?.unwrap_or(vec![0; 4]), "pads")?;
                if p.len() != 4 {
                    return Err(bad(format!("pads {p:?}")));
                }
                (p[0], p[1], p[2], p[3])
            }
            "VALID" => (0, 0, 0, 0),
            "SAME_UPPER" | "SAME_LOWER" => {
                let total = |len: usize, k: usize, s: usize| {
                    ((len.div_ceil(s) - 1) * s + k).saturating_sub(len)
                };
                let (th, tw) = (total(h, kh, sh), total(wd, kw, sw));
                if auto == "SAME_UPPER" {
                    (th / 2, tw / 2, th - th / 2, tw - tw / 2)
                } else {
                    (th - th / 2, tw - tw / 2, th / 2, tw / 2)
                }
            }
            a => return Err(bad(format!("auto_pad {a}"))),
        };
        let out = |len: usize, k: usize, s: usize, a: usize, b: usize| {
            let padded = len.checked_add(a)?.checked_add(b)?;
            (len > 0 && padded >= k && k > 0).then(|| (padded - k) / s + 1)
        };
        // Padding wider than the kernel reads only zeros, and a stride beyond the padded input
        // yields one output: both are refused, which keeps every index arithmetic small.
        if pt.max(pb) > kh || pl.max(pr) > kw || sh > h + pt + pb || sw > wd + pl + pr {
            return Err(bad(format!(
                "pads {:?} for a {kh}×{kw} kernel or strides {strides:?} for a {h}×{wd} input: \
                 padding at most the kernel and strides at most the padded input are supported",
                [pt, pl, pb, pr]
            )));
        }
        let (oh, ow) = match (out(h, kh, sh, pt, pb), out(wd, kw, sw, pl, pr)) {
            (Some(oh), Some(ow)) => (oh, ow),
            _ => return Err(bad(format!("kernel {kh}×{kw} does not fit input {h}×{wd}"))),
        };
        let bias = match bias {
            Some(b) if b.dims.iter().product::<usize>() == m => b.to_f32(),
            Some(b) => return Err(bad(format!("bias of shape {:?} for {m} outputs", b.dims))),
            None => vec![0.0; m],
        };
        let shape = ConvShape {
            c,
            h,
            w: wd,
            m,
            oh,
            ow,
            kh,
            kw,
            sh,
            sw,
            pt,
            pl,
            groups,
        };
        let kind =
            if groups == 1 && kh == 1 && kw == 1 && sh == 1 && sw == 1 && pt + pl + pb + pr == 0 {
                ConvKind::Pointwise
            } else if groups == 1 {
                ConvKind::Rows
            } else if groups == c && m == c && cg == 1 {
                match dwconv::Geometry::new(c, (h, wd), (kh, kw), (sh, sw), (pt, pb), (pl, pr)) {
                    Some(g) if g.out_h == oh && g.out_w == ow => ConvKind::Depthwise(g),
                    _ => ConvKind::General,
                }
            } else {
                ConvKind::General
            };
        let col = match kind {
            ConvKind::General => Some(Tensor::count(&[cg, kh, kw, oh, ow])),
            ConvKind::Rows => Some(Tensor::count(&[cg, kh, kw, ow])),
            ConvKind::Pointwise => Some(Tensor::count(&[c, ops::tile_cols(c)])),
            _ => None,
        };
        if let Some(col) = col {
            let col = col.ok_or("size overflow")?;
            self.total = self.total.saturating_add(col);
            if self.total > MAX_PLAN_VALUES {
                return Err(bad("im2col buffer beyond the plan's memory bound".into()));
            }
            self.plan.col_len = self.plan.col_len.max(col);
        }
        // A 1 × 1 convolution whose input is the product the last step computed of `c` planes
        // and one factor per plane (a squeeze-excitation layer's output, `x · s` with `s` of
        // shape [1, C, 1, 1], its activation fused in or none), read by nothing else: the
        // factors and the activation are applied as the convolution copies its input tiles
        // (`ops::pointwise`), the same values bit for bit, and the product's planes are
        // neither written nor read again. (Every tensor has a slot of its own, so the last
        // step writing `x` means it computed this input.)
        let mut scale = None;
        if matches!(kind, ConvKind::Pointwise) && batch == 1 {
            let once = self.uses.get(n.inputs[0].as_str()).copied().unwrap_or(0) == 1;
            if let Some(&Step::Binary {
                a,
                b,
                y,
                op: Binary::Mul,
                ref bc,
                act,
            }) = self.plan.steps.last()
            {
                if once && y == x {
                    if let Some(a_planes) = ops::plane_scale(bc, c, h * wd) {
                        let (planes, factors) = if a_planes { (a, b) } else { (b, a) };
                        self.plan.steps.pop();
                        // Nothing writes or reads the product now: its slot holds nothing
                        // and leaves the plan's memory bound.
                        let freed = std::mem::take(&mut self.plan.slots[y]);
                        self.total = self.total.saturating_sub(freed);
                        x = planes;
                        scale = Some((factors, act));
                    }
                }
            }
        }
        let y = self.out(n, vec![batch, m, oh, ow])?;
        let weights = match kind {
            ConvKind::Pointwise | ConvKind::Rows => ops::pack_rows(&w.to_f32(), m, cg * kh * kw),
            _ => w.to_f32(),
        };
        self.plan.steps.push(Step::Conv {
            x,
            y,
            batch,
            shape,
            kind,
            weights,
            bias,
            act: None,
            scale,
        });
        Ok(())
    }

    /// `MatMul` (batched, equal batch dimensions or a 2-D right operand) and `Gemm`.
    fn matmul(&mut self, n: &Node) -> Result<(), Error> {
        let bad = |what: String| format!("{}: {what}", who(n));
        let (a, sa) = self.buf(&self.need(n, 0)?)?;
        let b_val = self.need(n, 1)?;
        let sb = match &b_val {
            Val::Const(t) => t.dims.clone(),
            Val::Buf { shape, .. } => shape.clone(),
        };
        let gemm = n.op_type == "Gemm";
        if sa.len() < 2 || sb.len() < 2 || (gemm && (sa.len() != 2 || sb.len() != 2)) {
            return Err(bad(format!("operands {sa:?} and {sb:?}")));
        }
        let (ta, tb) = if gemm {
            (
                attr_int(n, "transA", 0)? != 0,
                attr_int(n, "transB", 0)? != 0,
            )
        } else {
            (false, false)
        };
        let ra = sa.len();
        let rb = sb.len();
        let (ar, ac) = (sa[ra - 2], sa[ra - 1]);
        let (br, bc) = (sb[rb - 2], sb[rb - 1]);
        let (m, k) = if ta { (ac, ar) } else { (ar, ac) };
        let (k2, nn) = if tb { (bc, br) } else { (br, bc) };
        if k != k2 || m == 0 || nn == 0 {
            return Err(bad(format!("operands {sa:?} and {sb:?} do not multiply")));
        }
        let batch_a = &sa[..ra - 2];
        let batch_b = &sb[..rb - 2];
        let batch: usize = batch_a.iter().product();
        let b_step = if batch_b.is_empty() || batch_b.iter().product::<usize>() == 1 {
            0
        } else if batch_b == batch_a {
            br * bc
        } else {
            return Err(bad(format!("batch dimensions of {sa:?} and {sb:?}")));
        };
        let a_strides = if ta {
            (1, ac, ar * ac)
        } else {
            (ac, 1, ar * ac)
        };
        // A constant right operand read across its rows (`transB`, as the squeeze-and-
        // excitation layers' weights come from PyTorch) in a product that `ops::gemm`
        // computes in its own loop (the excitation's one row of pooled values) is transposed
        // once here, so that the loop reads it along its rows, vectorised, instead of one
        // strided value at a time: each output the same multiply-adds in the same order.
        let (b, b_strides) = match &b_val {
            Val::Const(t) if tb && rb == 2 && ops::computes_itself(m, k, nn) => {
                let v = t.to_f32();
                let mut tr = vec![0.0; v.len()];
                for (j, row) in v.chunks_exact(bc).enumerate() {
                    for (p, &x) in row.iter().enumerate() {
                        tr[p * br + j] = x;
                    }
                }
                let slot = self.slot(&[bc, br])?;
                self.plan.init.push((slot, tr));
                (slot, (br, 1, b_step))
            }
            _ => {
                let (b, _) = self.buf(&b_val)?;
                (b, if tb { (1, bc, b_step) } else { (bc, 1, b_step) })
            }
        };
        let (alpha, bias) = if gemm {
            let alpha = attr_float(n, "alpha", 1.0)?;
            let beta = attr_float(n, "beta", 1.0)?;
            let bias = match self.get(n, 2)? {
                None => None,
                Some(Val::Const(t)) => {
                    let (shape, bcast) = Broadcast::new(&[m, nn], &t.dims)
                        .filter(|(s, _)| *s == [m, nn])
                        .ok_or_else(|| bad(format!("C of shape {:?} for [{m}, {nn}]", t.dims)))?;
                    let zeros = vec![0.0; m * nn];
                    let mut c = vec![0.0; m * nn];
                    let scaled: Vec<f32> = t.to_f32().iter().map(|v| beta * v).collect();
                    debug_assert_eq!(shape, [m, nn]);
                    bcast.apply(Binary::Add, &zeros, &scaled, None, &mut c);
                    Some(c)
                }
                Some(Val::Buf { .. }) => {
                    return Err(bad("a computed C is not supported".into()));
                }
            };
            (alpha, bias)
        } else {
            (1.0, None)
        };
        let mut shape = batch_a.to_vec();
        shape.extend([m, nn]);
        let y = self.out(n, shape)?;
        self.plan.steps.push(Step::MatMul {
            a,
            b,
            y,
            batch,
            mkn: (m, k, nn),
            a_strides,
            b_strides,
            alpha,
            bias,
            act: None,
        });
        Ok(())
    }
}

impl Plan {
    /// Plans `model` for `inputs` (name and shape; every other graph input must be an
    /// initialiser) and `outputs` (names), in that order.
    ///
    /// # Errors
    /// An unknown input or output, a shape that contradicts the model's declaration, an
    /// unsupported operator or attribute, shapes that do not fit, or tensors beyond
    /// [`MAX_PLAN_VALUES`].
    pub fn new(
        model: &Model,
        inputs: &[(&str, &[usize])],
        outputs: &[&str],
    ) -> Result<Self, Error> {
        let mut b = Builder {
            vals: HashMap::new(),
            uses: HashMap::new(),
            last_out: None,
            plan: Plan {
                steps: Vec::new(),
                slots: Vec::new(),
                buffer: Vec::new(),
                buffer_len: Vec::new(),
                init: Vec::new(),
                inputs: Vec::new(),
                outputs: Vec::new(),
                col_len: 0,
            },
            total: 0,
        };
        for (name, t) in &model.initializers {
            b.vals.insert(name.clone(), Val::Const(t.clone()));
        }
        for &(name, shape) in inputs {
            let decl = model
                .inputs
                .iter()
                .find(|i| i.name == name)
                .ok_or_else(|| format!("the model has no input `{name}`"))?;
            let fits = decl.dims.is_empty()
                || (decl.dims.len() == shape.len()
                    && decl
                        .dims
                        .iter()
                        .zip(shape)
                        .all(|(d, &s)| d.is_none_or(|d| d == s)));
            if !fits || shape.contains(&0) {
                return Err(format!(
                    "input `{name}`: shape {shape:?} where the model declares {:?}",
                    decl.dims
                ));
            }
            let slot = b.slot(shape)?;
            b.vals.insert(
                name.to_string(),
                Val::Buf {
                    slot,
                    shape: shape.to_vec(),
                },
            );
            b.plan.inputs.push((name.to_string(), slot, shape.to_vec()));
        }
        // The nodes the outputs depend on (ONNX lists nodes in topological order).
        let mut wanted: std::collections::HashSet<&str> = outputs.iter().copied().collect();
        let mut keep = vec![false; model.nodes.len()];
        for (i, n) in model.nodes.iter().enumerate().rev() {
            if n.outputs.iter().any(|o| wanted.contains(o.as_str())) {
                keep[i] = true;
                wanted.extend(n.inputs.iter().map(String::as_str));
            }
        }
        let kept = || {
            model
                .nodes
                .iter()
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|(n, _)| n)
        };
        for name in kept()
            .flat_map(|n| &n.inputs)
            .map(String::as_str)
            .chain(outputs.iter().copied())
        {
            *b.uses.entry(name.to_string()).or_default() += 1;
        }
        for n in kept() {
            b.node(n)?;
        }
        for &name in outputs {
            let v = b
                .vals
                .get(name)
                .cloned()
                .ok_or_else(|| format!("the model has no output `{name}`"))?;
            let (slot, shape) = b.buf(&v)?;
            b.plan.outputs.push((name.to_string(), slot, shape));
        }
        b.plan.share_buffers();
        Ok(b.plan)
    }

    /// Puts slots whose lifetimes do not overlap into the same buffer, so that a pass
    /// writes into memory that an earlier step of the same pass used and the cache still
    /// holds, instead of a buffer of its own per tensor (NanoTrack's backbone on a 255-px
    /// crop: 7.6 MB of buffers, more than a core's L2 cache, so each step's output was
    /// fetched from L3 or memory before being written). A slot lives from the first step
    /// that references it to the last; constants, inputs and outputs keep buffers of their
    /// own (filled once, handed in by exchange, read after the run). Each slot takes the
    /// smallest free buffer that holds it, else the largest free one grown to it, else a new
    /// one. Steps see a slot as the first `slots[s]` values of its buffer, so every step
    /// computes what it did with a buffer per slot, the same bits.
    fn share_buffers(&mut self) {
        let n = self.slots.len();
        let mut own = vec![false; n];
        for &(s, _) in &self.init {
            own[s] = true;
        }
        for (_, s, _) in self.inputs.iter().chain(&self.outputs) {
            own[*s] = true;
        }
        let (mut first, mut last) = (vec![usize::MAX; n], vec![0; n]);
        for (i, step) in self.steps.iter().enumerate() {
            for s in step.refs().into_iter().flatten() {
                first[s] = first[s].min(i);
                last[s] = last[s].max(i);
            }
        }
        let mut buffer = vec![usize::MAX; n];
        let mut buffer_len = Vec::new();
        for s in 0..n {
            if own[s] || first[s] == usize::MAX {
                buffer[s] = buffer_len.len();
                buffer_len.push(self.slots[s]);
            }
        }
        // Buffers free to take, the most recently freed last.
        let mut free: Vec<usize> = Vec::new();
        for i in 0..self.steps.len() {
            let refs = self.steps[i].refs();
            for s in refs.into_iter().flatten() {
                if buffer[s] != usize::MAX {
                    continue;
                }
                let need = self.slots[s];
                let fits = free
                    .iter()
                    .enumerate()
                    .filter(|(_, &b)| buffer_len[b] >= need)
                    .min_by_key(|(k, &b)| (buffer_len[b], usize::MAX - k))
                    .map(|(k, _)| k);
                let largest = || {
                    free.iter()
                        .enumerate()
                        .max_by_key(|(k, &b)| (buffer_len[b], *k))
                        .map(|(k, _)| k)
                };
                buffer[s] = match fits.or_else(largest) {
                    Some(k) => {
                        let b = free.remove(k);
                        buffer_len[b] = buffer_len[b].max(need);
                        b
                    }
                    None => {
                        buffer_len.push(need);
                        buffer_len.len() - 1
                    }
                };
            }
            for s in refs.into_iter().flatten() {
                if last[s] == i && !own[s] && !free.contains(&buffer[s]) {
                    free.push(buffer[s]);
                }
            }
        }
        self.buffer = buffer;
        self.buffer_len = buffer_len;
    }

    /// Values the plan's buffers hold together (at most the slots' sum, [`MAX_PLAN_VALUES`]).
    pub fn buffer_values(&self) -> usize {
        self.buffer_len.iter().sum()
    }

    /// Shapes of the outputs, in the order asked for.
    pub fn output_shapes(&self) -> impl ExactSizeIterator<Item = &[usize]> {
        self.outputs.iter().map(|(_, _, s)| s.as_slice())
    }
}

/// Slot `s`'s values in the buffers of `plan`.
fn view<'a>(bufs: &'a [Vec<f32>], plan: &Plan, s: usize) -> &'a [f32] {
    &bufs[plan.buffer[s]][..plan.slots[s]]
}

/// The buffers of one plan and what runs it.
#[derive(Debug)]
pub struct Runner {
    plan: std::sync::Arc<Plan>,
    bufs: Vec<Vec<f32>>,
    col: Vec<f32>,
    dw: dwconv::Scratch,
    /// Nanoseconds spent in each step over the timed runs, empty while not timing
    /// ([`Runner::time_steps`]), and the number of timed runs.
    step_ns: Vec<u64>,
    runs: u64,
}

impl Runner {
    /// Buffers for `plan`, constants filled in.
    pub fn new(plan: std::sync::Arc<Plan>) -> Self {
        let mut bufs: Vec<Vec<f32>> = plan.buffer_len.iter().map(|&n| vec![0.0; n]).collect();
        for (slot, data) in &plan.init {
            bufs[plan.buffer[*slot]].copy_from_slice(data);
        }
        let col = vec![0.0; plan.col_len];
        Self {
            plan,
            bufs,
            step_ns: Vec::new(),
            runs: 0,
            col,
            dw: dwconv::Scratch::default(),
        }
    }

    /// Every step in order, timed when [`Self::time_steps`] is on.
    fn run_steps(&mut self, plan: &Plan) {
        if self.step_ns.len() != plan.steps.len() {
            for step in &plan.steps {
                self.step(step);
            }
            return;
        }
        self.runs += 1;
        for (i, step) in plan.steps.iter().enumerate() {
            let t0 = std::time::Instant::now();
            self.step(step);
            let ns = u64::try_from(t0.elapsed().as_nanos()).unwrap_or(u64::MAX);
            self.step_ns[i] = self.step_ns[i].saturating_add(ns);
        }
    }

    /// Starts timing each step of the runs from now on (from zero), or stops and forgets
    /// the times. Off by default: a diagnostic (`verifier_passes nodes`, the per-node table
    /// of docs/benchmarks.md), one clock read a step while on.
    pub fn time_steps(&mut self, on: bool) {
        self.step_ns = if on {
            vec![0; self.plan.steps.len()]
        } else {
            Vec::new()
        };
        self.runs = 0;
    }

    /// The timed runs so far ([`Self::time_steps`]) and, per step in plan order, what it
    /// computes and its time over those runs in nanoseconds; no steps while not timing.
    pub fn step_times(&self) -> (u64, Vec<(String, u64)>) {
        let steps = self.plan.steps.iter().map(Step::label);
        (self.runs, steps.zip(self.step_ns.iter().copied()).collect())
    }

    /// The plan this runner runs.
    pub fn plan(&self) -> &Plan {
        &self.plan
    }

    /// Runs the plan on `inputs` (in the plan's order, each of its shape's length) and
    /// returns the outputs (in the order asked for at plan time).
    ///
    /// # Errors
    /// A wrong number of inputs or a wrong length.
    pub fn run(&mut self, inputs: &[&[f32]]) -> Result<Vec<&[f32]>, Error> {
        let plan = std::sync::Arc::clone(&self.plan);
        if inputs.len() != plan.inputs.len() {
            return Err(format!(
                "{} inputs; the plan has {}",
                inputs.len(),
                plan.inputs.len()
            ));
        }
        for ((name, slot, shape), data) in plan.inputs.iter().zip(inputs) {
            let buf = &mut self.bufs[plan.buffer[*slot]];
            if buf.len() != data.len() {
                return Err(format!(
                    "input `{name}`: {} values for shape {shape:?}",
                    data.len()
                ));
            }
            buf.copy_from_slice(data);
        }
        self.run_steps(&plan);
        Ok(self.outputs())
    }

    /// The outputs' values after a run (each output has a buffer of its own length).
    fn outputs(&self) -> Vec<&[f32]> {
        let plan = &self.plan;
        plan.outputs
            .iter()
            .map(|(_, slot, _)| self.bufs[plan.buffer[*slot]].as_slice())
            .collect()
    }

    /// [`Self::run`] on a plan of one input, taken by exchange instead of copied: `input`
    /// is the input's buffer during the run and is given back unchanged (steps only read a
    /// plan's inputs: every step writes a new buffer). A network input of a few hundred KB
    /// (a 255-px crop is 780 KB) is then not copied once a pass. Where the input is also an
    /// output, it is copied as [`Self::run`] does.
    ///
    /// # Errors
    /// A plan of more than one input, or a wrong length.
    pub fn run_exchanging(&mut self, input: &mut Vec<f32>) -> Result<Vec<&[f32]>, Error> {
        let plan = std::sync::Arc::clone(&self.plan);
        let slot = match plan.inputs.as_slice() {
            [(_, slot, _)] => *slot,
            other => return Err(format!("{} inputs; the plan has 1", other.len())),
        };
        if plan.outputs.iter().any(|(_, s, _)| *s == slot) {
            return self.run(&[input.as_slice()]);
        }
        let slot = plan.buffer[slot];
        if self.bufs[slot].len() != input.len() {
            let (name, _, shape) = &plan.inputs[0];
            return Err(format!(
                "input `{name}`: {} values for shape {shape:?}",
                input.len()
            ));
        }
        std::mem::swap(&mut self.bufs[slot], input);
        self.run_steps(&plan);
        std::mem::swap(&mut self.bufs[slot], input);
        Ok(self.outputs())
    }

    /// Slot `x`'s values to read and slot `y`'s to write (in different buffers: a step's
    /// slots are all live during it, so [`Plan::share_buffers`] gave them different ones).
    fn pair(&mut self, x: usize, y: usize) -> (&[f32], &mut [f32]) {
        let (bx, by) = (self.plan.buffer[x], self.plan.buffer[y]);
        let (nx, ny) = (self.plan.slots[x], self.plan.slots[y]);
        if bx < by {
            let (lo, hi) = self.bufs.split_at_mut(by);
            (&lo[bx][..nx], &mut hi[0][..ny])
        } else {
            let (lo, hi) = self.bufs.split_at_mut(bx);
            (&hi[0][..nx], &mut lo[by][..ny])
        }
    }

    /// Slot `s`'s values.
    fn view(&self, s: usize) -> &[f32] {
        view(&self.bufs, &self.plan, s)
    }

    /// Takes slot `y`'s buffer out (to be written while other slots are read; put back
    /// with [`Self::put`]).
    fn take(&mut self, y: usize) -> Vec<f32> {
        std::mem::take(&mut self.bufs[self.plan.buffer[y]])
    }

    fn put(&mut self, y: usize, buf: Vec<f32>) {
        let b = self.plan.buffer[y];
        self.bufs[b] = buf;
    }

    fn step(&mut self, step: &Step) {
        match step {
            Step::Conv {
                x,
                y,
                batch,
                shape: s,
                kind,
                weights,
                bias,
                act,
                scale,
            } => {
                // Take the output out so that the input and the factors can be borrowed.
                let mut out = self.take(*y);
                let (xb, yb) = (
                    view(&self.bufs, &self.plan, *x),
                    &mut out[..self.plan.slots[*y]],
                );
                let scale = scale.map(|(s, f)| (view(&self.bufs, &self.plan, s), f));
                let (in_len, out_len) = (s.c * s.h * s.w, s.m * s.oh * s.ow);
                let plane = s.oh * s.ow;
                for i in 0..*batch {
                    let xi = &xb[i * in_len..(i + 1) * in_len];
                    let yi = &mut yb[i * out_len..(i + 1) * out_len];
                    match kind {
                        ConvKind::Depthwise(g) => {
                            let ok = dwconv::depthwise(g, xi, weights, bias, yi, &mut self.dw);
                            debug_assert!(ok, "depthwise geometry checked at plan time");
                        }
                        ConvKind::Pointwise => {
                            let (mkn, col) = ((s.m, s.c, plane), &mut self.col);
                            ops::pointwise(mkn, weights, xi, scale, bias, *act, yi, col);
                            continue; // the activation is applied
                        }
                        ConvKind::Rows => {
                            // At stride 2 straight from the input rows where it can.
                            if ops::conv_s2(s, weights, xi, bias, *act, yi, &mut self.dw) {
                                continue; // the activation is applied
                            }
                            let k = s.c * s.kh * s.kw;
                            let col = &mut self.col[..k * s.ow];
                            for oy in 0..s.oh {
                                ops::im2col_row(s, xi, oy, col);
                                let yo = &mut yi[oy * s.ow..];
                                ops::rows_product(
                                    (s.m, k, s.ow),
                                    weights,
                                    col,
                                    s.ow,
                                    bias,
                                    *act,
                                    yo,
                                    plane,
                                );
                            }
                            continue; // the activation is applied
                        }
                        ConvKind::General => {
                            let (cg, mg) = (s.c / s.groups, s.m / s.groups);
                            let kk = cg * s.kh * s.kw;
                            let col = &mut self.col[..kk * plane];
                            ops::fill_bias(yi, bias, plane);
                            for g in 0..s.groups {
                                let xg = &xi[g * cg * s.h * s.w..(g + 1) * cg * s.h * s.w];
                                ops::im2col(s, cg, xg, col);
                                let wg = &weights[g * mg * kk..(g + 1) * mg * kk];
                                let yg = &mut yi[g * mg * plane..(g + 1) * mg * plane];
                                ops::gemm(
                                    (mg, kk, plane),
                                    wg,
                                    (kk, 1),
                                    col,
                                    (plane, 1),
                                    (1.0, 1.0),
                                    yg,
                                );
                            }
                        }
                    }
                    if let Some(f) = act {
                        ops::unary_in_place(*f, yi);
                    }
                }
                self.put(*y, out);
            }
            Step::Unary { x, y, f } => {
                let (xb, yb) = self.pair(*x, *y);
                ops::unary(*f, xb, yb);
            }
            Step::Binary {
                a,
                b,
                y,
                op,
                bc,
                act,
            } => {
                // Take the output out so that both operands can be borrowed (they may be
                // the same buffer).
                let mut out = self.take(*y);
                let yb = &mut out[..self.plan.slots[*y]];
                bc.apply(*op, self.view(*a), self.view(*b), *act, yb);
                self.put(*y, out);
            }
            Step::MatMul {
                a,
                b,
                y,
                batch,
                mkn: (m, k, n),
                a_strides: (ar, ac, ab),
                b_strides: (br, bc, bb),
                alpha,
                bias,
                act,
            } => {
                let mut whole = self.take(*y);
                let out = &mut whole[..self.plan.slots[*y]];
                let (av, bv) = (self.view(*a), self.view(*b));
                for i in 0..*batch {
                    let yi = &mut out[i * m * n..(i + 1) * m * n];
                    let beta = match bias {
                        Some(c) => {
                            yi.copy_from_slice(c);
                            1.0
                        }
                        None => 0.0,
                    };
                    let ai = &av[i * ab..];
                    let bi = &bv[i * bb..];
                    ops::gemm(
                        (*m, *k, *n),
                        ai,
                        (*ar, *ac),
                        bi,
                        (*br, *bc),
                        (*alpha, beta),
                        yi,
                    );
                }
                if let Some(f) = act {
                    ops::unary_in_place(*f, out);
                }
                self.put(*y, whole);
            }
            Step::MeanPool { x, y, len } => {
                let (xb, yb) = self.pair(*x, *y);
                ops::mean_pool(xb, *len, yb);
            }
            Step::Transpose { x, y, shape, perm } => {
                let (xb, yb) = self.pair(*x, *y);
                ops::transpose(xb, shape, perm, yb);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ints(v: &[i64]) -> Attr {
        Attr::Ints(v.to_vec())
    }

    fn f32s(dims: &[usize], seed: u32) -> Tensor {
        let n = dims.iter().product::<usize>();
        let mut s = seed.wrapping_mul(2_654_435_761).max(1);
        let data = (0..n)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 17;
                s ^= s << 5;
                (s % 2001) as f32 / 1000.0 - 1.0
            })
            .collect();
        Tensor {
            dims: dims.to_vec(),
            data: Data::F32(data),
        }
    }

    fn node(op: &str, inputs: &[&str], output: &str, attrs: &[(&str, Attr)]) -> Node {
        Node {
            name: output.to_string(),
            op_type: op.to_string(),
            domain: String::new(),
            inputs: inputs.iter().map(|s| s.to_string()).collect(),
            outputs: vec![output.to_string()],
            attrs: attrs
                .iter()
                .map(|(k, v)| (k.to_string(), v.clone()))
                .collect(),
        }
    }

    fn model(nodes: Vec<Node>, inits: Vec<(&str, Tensor)>, inputs: &[&str]) -> Model {
        Model {
            nodes,
            initializers: inits.into_iter().map(|(k, v)| (k.to_string(), v)).collect(),
            inputs: inputs
                .iter()
                .map(|n| onnx::ValueInfo {
                    name: n.to_string(),
                    dims: vec![],
                })
                .collect(),
            outputs: vec![],
            opset: 14,
        }
    }

    fn run(m: &Model, inputs: &[(&str, &[usize], &[f32])], out: &str) -> Vec<f32> {
        let io: Vec<(&str, &[usize])> = inputs.iter().map(|(n, s, _)| (*n, *s)).collect();
        let plan = Plan::new(m, &io, &[out]).unwrap();
        let mut r = Runner::new(std::sync::Arc::new(plan));
        let data: Vec<&[f32]> = inputs.iter().map(|(_, _, d)| *d).collect();
        r.run(&data).unwrap()[0].to_vec()
    }

    /// Direct convolution, f64 sums, zero padding.
    #[allow(clippy::too_many_arguments)]
    fn naive_conv(
        x: &[f32],
        (_, h, w): (usize, usize, usize),
        k: &Tensor,
        bias: &[f32],
        groups: usize,
        (sh, sw): (usize, usize),
        (pt, pl, pb, pr): (usize, usize, usize, usize),
    ) -> Vec<f32> {
        let kw_ = k.to_f32();
        let (m, cg, kh, kw) = (k.dims[0], k.dims[1], k.dims[2], k.dims[3]);
        let oh = (h + pt + pb - kh) / sh + 1;
        let ow = (w + pl + pr - kw) / sw + 1;
        let mg = m / groups;
        let mut y = vec![0.0; m * oh * ow];
        for o in 0..m {
            let g = o / mg;
            for oy in 0..oh {
                for ox in 0..ow {
                    let mut s = f64::from(bias[o]);
                    for ci in 0..cg {
                        let cin = g * cg + ci;
                        for ky in 0..kh {
                            for kx in 0..kw {
                                let yy = (oy * sh + ky) as isize - pt as isize;
                                let xx = (ox * sw + kx) as isize - pl as isize;
                                if yy < 0 || xx < 0 || yy >= h as isize || xx >= w as isize {
                                    continue;
                                }
                                let v = x[(cin * h + yy as usize) * w + xx as usize];
                                let wv = kw_[((o * cg + ci) * kh + ky) * kw + kx];
                                s += f64::from(v) * f64::from(wv);
                            }
                        }
                    }
                    y[(o * oh + oy) * ow + ox] = s as f32;
                }
            }
        }
        y
    }

    fn worst(a: &[f32], b: &[f32]) -> f32 {
        assert_eq!(a.len(), b.len());
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f32::max)
    }

    /// Each convolution path (pointwise matrix product, depthwise kernel, im2col for dense
    /// and grouped kernels, with strides and asymmetric padding) against a direct f64 sum.
    #[test]
    fn convolutions_match_a_direct_sum_on_every_path() {
        // (c, h, w, m, groups, kh, kw, strides, pads [t, l, b, r])
        #[allow(clippy::type_complexity)] // one row per case, read as a table
        let cases: &[(
            usize,
            usize,
            usize,
            usize,
            usize,
            usize,
            usize,
            [i64; 2],
            [i64; 4],
        )] = &[
            (5, 7, 9, 6, 1, 1, 1, [1, 1], [0, 0, 0, 0]),
            (6, 9, 8, 6, 6, 3, 3, [2, 2], [1, 1, 1, 1]),
            (4, 11, 10, 4, 4, 5, 5, [1, 1], [2, 2, 2, 2]),
            (3, 13, 12, 8, 1, 3, 3, [2, 2], [1, 1, 1, 1]),
            (4, 7, 9, 6, 2, 3, 2, [1, 2], [0, 1, 2, 0]),
            (3, 6, 6, 4, 1, 1, 1, [2, 1], [1, 0, 0, 1]),
            // Several blocks of output channels and columns, with a partial one of each.
            (17, 9, 10, 20, 1, 1, 1, [1, 1], [0, 0, 0, 0]),
            (3, 20, 35, 19, 1, 3, 3, [2, 2], [1, 1, 1, 1]),
        ];
        for (i, &(c, h, w, m, groups, kh, kw, strides, pads)) in cases.iter().enumerate() {
            let k = f32s(&[m, c / groups, kh, kw], i as u32 + 1);
            let b = f32s(&[m], i as u32 + 50);
            let x = f32s(&[1, c, h, w], i as u32 + 99).to_f32();
            let mdl = model(
                vec![node(
                    "Conv",
                    &["x", "k", "b"],
                    "y",
                    &[
                        ("group", Attr::Int(groups as i64)),
                        ("strides", ints(&strides)),
                        ("pads", ints(&pads)),
                        ("kernel_shape", ints(&[kh as i64, kw as i64])),
                    ],
                )],
                vec![("k", k.clone()), ("b", b.clone())],
                &["x"],
            );
            let got = run(&mdl, &[("x", &[1, c, h, w], &x)], "y");
            let p = |j: usize| pads[j] as usize;
            let want = naive_conv(
                &x,
                (c, h, w),
                &k,
                &b.to_f32(),
                groups,
                (strides[0] as usize, strides[1] as usize),
                (p(0), p(1), p(2), p(3)),
            );
            let d = worst(&got, &want);
            assert!(d < 1e-5, "case {i}: {d}");
        }
    }

    /// A constant `transB` operand, transposed at plan time for `ops::gemm`'s own loop, gives
    /// the bits of the same operand given as an input (read strided), for one row (the
    /// squeeze-and-excitation layers' shape), for a few rows, and for a product large enough
    /// for nalgebra (not transposed).
    #[test]
    fn a_transposed_constant_gives_the_strided_operands_bits() {
        for (m, k, n) in [(1, 24, 96), (3, 7, 5), (6, 4, 5), (8, 9, 10)] {
            let x = f32s(&[m, k], 21).to_f32();
            let w = f32s(&[n, k], 22);
            let gemm = |b: &str| {
                node(
                    "Gemm",
                    &["x", b],
                    "g",
                    &[("transB", Attr::Int(1)), ("alpha", Attr::Float(0.5))],
                )
            };
            let constant = model(vec![gemm("w")], vec![("w", w.clone())], &["x"]);
            let input = model(vec![gemm("wi")], vec![], &["x", "wi"]);
            let a = run(&constant, &[("x", &[m, k], &x)], "g");
            let wv = w.to_f32();
            let b = run(&input, &[("x", &[m, k], &x), ("wi", &[n, k], &wv)], "g");
            let bits = |v: &[f32]| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&a), bits(&b), "{m} × {k} by ({n} × {k})ᵀ");
            let want: Vec<f32> = (0..m * n)
                .map(|i| {
                    0.5 * (0..k)
                        .map(|p| x[i / n * k + p] * wv[i % n * k + p])
                        .sum::<f32>()
                })
                .collect();
            assert!(worst(&a, &want) < 1e-5, "{m} × {k} by ({n} × {k})ᵀ");
        }
    }

    /// Gemm (transB, α, β, a broadcast C), batched MatMul after a Transpose, broadcast Mul
    /// and Add, a Reshape with 0 and −1, the pooling and the activations, against direct
    /// formulas.
    #[test]
    fn the_other_operators_match_their_formulas() {
        let x = f32s(&[2, 3, 4], 7).to_f32();
        let wt = f32s(&[5, 4], 8);
        let cb = f32s(&[5], 9);
        let mdl = model(
            vec![
                node("Reshape", &["x", "s"], "x2", &[]),
                node(
                    "Gemm",
                    &["x2", "w", "c"],
                    "g",
                    &[
                        ("transB", Attr::Int(1)),
                        ("alpha", Attr::Float(0.5)),
                        ("beta", Attr::Float(2.0)),
                    ],
                ),
                node("HardSwish", &["g"], "h", &[]),
            ],
            vec![
                ("w", wt.clone()),
                ("c", cb.clone()),
                (
                    "s",
                    Tensor {
                        dims: vec![2],
                        data: Data::I64(vec![-1, 4]),
                    },
                ),
            ],
            &["x"],
        );
        let got = run(&mdl, &[("x", &[2, 3, 4], &x)], "h");
        let (w, c) = (wt.to_f32(), cb.to_f32());
        let mut want = Vec::new();
        for r in 0..6 {
            for o in 0..5 {
                let dot: f32 = (0..4).map(|k| x[r * 4 + k] * w[o * 4 + k]).sum();
                let g = 0.5 * dot + 2.0 * c[o];
                want.push(g * (g / 6.0 + 0.5).clamp(0.0, 1.0));
            }
        }
        assert!(worst(&got, &want) < 1e-5);

        // [2,3,4] → Transpose(0,2,1) [2,4,3] · [2,3,4] → [2,4,4]; × a [4,1] column; pooled.
        let y = f32s(&[2, 3, 4], 11).to_f32();
        let col = f32s(&[4, 1], 12);
        let mdl = model(
            vec![
                node("Transpose", &["x"], "xt", &[("perm", ints(&[0, 2, 1]))]),
                node("MatMul", &["xt", "y"], "p", &[]),
                node("Mul", &["p", "col"], "q", &[]),
                node("Reshape", &["q", "s"], "q4", &[]),
                node("GlobalAveragePool", &["q4"], "avg", &[]),
                node("Sigmoid", &["avg"], "sg", &[]),
                node("Add", &["sg", "q4"], "out", &[]),
            ],
            vec![
                ("col", col.clone()),
                (
                    "s",
                    Tensor {
                        dims: vec![4],
                        data: Data::I64(vec![0, 0, 2, 2]),
                    },
                ),
            ],
            &["x", "y"],
        );
        let got = run(&mdl, &[("x", &[2, 3, 4], &x), ("y", &[2, 3, 4], &y)], "out");
        let colv = col.to_f32();
        let mut q = [0.0f32; 2 * 4 * 4];
        for bt in 0..2 {
            for i in 0..4 {
                for j in 0..4 {
                    let s: f32 = (0..3)
                        .map(|k| x[bt * 12 + k * 4 + i] * y[bt * 12 + k * 4 + j])
                        .sum();
                    q[(bt * 4 + i) * 4 + j] = s * colv[i];
                }
            }
        }
        let mut want = Vec::new();
        for ch in 0..8 {
            let avg = q[ch * 4..ch * 4 + 4].iter().sum::<f32>() / 4.0;
            let sg = 1.0 / (1.0 + (-avg).exp());
            want.extend(q[ch * 4..ch * 4 + 4].iter().map(|v| sg + v));
        }
        assert!(worst(&got, &want) < 1e-5, "{}", worst(&got, &want));
    }

    /// An activation is fused into the step that wrote its input only when nothing else
    /// reads that value: `relu(conv) + conv` keeps the convolution's own values for the sum,
    /// and `relu(conv)` alone equals the formula (fused).
    /// A tower like NanoTrack's head (depthwise 3 × 3 and pointwise convolutions with
    /// activations, a dense 3 × 3 one last) on 6 × 6 maps.
    fn tower() -> Model {
        let p1 = [("pads", ints(&[1, 1, 1, 1]))];
        let dw = |c: i64| [("pads", ints(&[1, 1, 1, 1])), ("group", Attr::Int(c))];
        model(
            vec![
                node("Conv", &["x", "k1", "b1"], "d1", &dw(4)),
                node("Clip", &["d1", "lo", "hi"], "c1", &[]),
                node("Conv", &["c1", "k2", "b2"], "p1", &[]),
                node("Conv", &["p1", "k3", "b3"], "d2", &dw(6)),
                node("Relu", &["d2"], "r2", &[]),
                node("Conv", &["r2", "k4", "b4"], "p2", &[]),
                node("Conv", &["p2", "k5", "b5"], "d3", &dw(6)),
                node("Conv", &["d3", "k6", "b6"], "y", &p1),
                node("Exp", &["y"], "e", &[]),
            ],
            vec![
                ("k1", f32s(&[4, 1, 3, 3], 1)),
                ("b1", f32s(&[4], 2)),
                (
                    "lo",
                    Tensor {
                        dims: vec![],
                        data: Data::F32(vec![0.0]),
                    },
                ),
                (
                    "hi",
                    Tensor {
                        dims: vec![],
                        data: Data::F32(vec![0.8]),
                    },
                ),
                ("k2", f32s(&[6, 4, 1, 1], 3)),
                ("b2", f32s(&[6], 4)),
                ("k3", f32s(&[6, 1, 3, 3], 5)),
                ("b3", f32s(&[6], 6)),
                ("k4", f32s(&[6, 6, 1, 1], 7)),
                ("b4", f32s(&[6], 8)),
                ("k5", f32s(&[6, 1, 3, 3], 9)),
                ("b5", f32s(&[6], 10)),
                ("k6", f32s(&[2, 6, 3, 3], 11)),
                ("b6", f32s(&[2], 12)),
            ],
            &["x"],
        )
    }

    /// A window of the output is the whole network's values there, bit for bit: at the
    /// centre, at both edges (where the layers keep their zero padding on one side only),
    /// one point, and the whole map (the model unchanged).
    #[test]
    fn a_windowed_network_gives_the_whole_networks_bits_in_its_window() {
        use window::{windowed, Span};
        let m = tower();
        let x = f32s(&[1, 4, 6, 6], 13).to_f32();
        let bits = |v: &[f32]| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        for out in ["y", "e"] {
            let whole = run(&m, &[("x", &[1, 4, 6, 6], &x)], out);
            for (lo, hi) in [(2, 3), (0, 1), (4, 5), (3, 3), (1, 4), (0, 5)] {
                let w = windowed(&m, out, 6, Span { lo, hi });
                let w = w.unwrap_or_else(|| panic!("{out} {lo}..={hi} not windowed"));
                let got = run(&w, &[("x", &[1, 4, 6, 6], &x)], out);
                let n = hi - lo + 1;
                let mut want = Vec::new();
                for c in 0..2 {
                    for r in lo..=hi {
                        want.extend_from_slice(
                            &whole[(c * 6 + r) * 6 + lo..(c * 6 + r) * 6 + hi + 1],
                        );
                    }
                }
                assert_eq!(got.len(), 2 * n * n, "{out} {lo}..={hi}");
                assert_eq!(bits(&got), bits(&want), "{out} {lo}..={hi}");
            }
        }
    }

    /// What cannot be windowed is refused, not computed wrongly: a window reaching the
    /// graph input before any layer needs its whole map, an operator that is not local
    /// (a reshape), a strided convolution, a span outside the map.
    #[test]
    fn a_window_through_what_is_not_local_is_refused() {
        use window::{windowed, Span};
        let m = tower();
        assert!(windowed(&m, "y", 6, Span { lo: 2, hi: 3 }).is_some());
        // A corner point needs only 5 × 5 of the input; from d2 on, one point 5 × 5 of x.
        assert!(windowed(&m, "y", 6, Span { lo: 0, hi: 0 }).is_none());
        assert!(windowed(&m, "d2", 6, Span { lo: 2, hi: 2 }).is_none());
        assert!(windowed(&m, "y", 6, Span { lo: 4, hi: 6 }).is_none());
        assert!(windowed(&m, "y", 6, Span { lo: 3, hi: 2 }).is_none());
        let mut r = m.clone();
        r.nodes[6] = node("Reshape", &["p2", "shape"], "d3", &[]);
        assert!(windowed(&r, "y", 6, Span { lo: 2, hi: 3 }).is_none());
        let mut s = m.clone();
        s.nodes[7].attrs.insert("strides".into(), ints(&[2, 2]));
        assert!(windowed(&s, "y", 6, Span { lo: 2, hi: 3 }).is_none());
    }

    #[test]
    fn a_convolution_by_rows_applies_its_fused_activation() {
        let (c, h, w, m) = (3, 19, 37, 11);
        let k = f32s(&[m, c, 3, 3], 7);
        let b = f32s(&[m], 8);
        let x = f32s(&[1, c, h, w], 9).to_f32();
        let attrs = [("strides", ints(&[2, 2])), ("pads", ints(&[1, 1, 1, 1]))];
        let mdl = model(
            vec![
                node("Conv", &["x", "k", "b"], "c", &attrs),
                node("HardSwish", &["c"], "y", &[]),
            ],
            vec![("k", k.clone()), ("b", b.clone())],
            &["x"],
        );
        let p = Plan::new(&mdl, &[("x", &[1, c, h, w])], &["y"]).unwrap();
        assert_eq!(p.steps.len(), 1, "fused");
        assert!(matches!(
            p.steps[0],
            Step::Conv {
                kind: ConvKind::Rows,
                ..
            }
        ));
        let got = run(&mdl, &[("x", &[1, c, h, w], &x)], "y");
        let conv = naive_conv(&x, (c, h, w), &k, &b.to_f32(), 1, (2, 2), (1, 1, 1, 1));
        let want: Vec<f32> = conv
            .iter()
            .map(|&v| v * (v / 6.0 + 0.5).clamp(0.0, 1.0))
            .collect();
        assert!(worst(&got, &want) < 1e-5);
        assert!(want.contains(&0.0) && want.iter().any(|&v| v > 1.0));
    }

    #[test]
    fn a_channel_scale_fuses_into_the_next_pointwise_convolution_bit_for_bit() {
        // A squeeze-excitation layer's output: planes times one factor per plane (either
        // operand order, with or without an activation after it), then a 1 × 1 convolution.
        // 43 × 29 planes: tiles of 32-column blocks and a masked tail.
        let (c, h, w, m) = (24, 43, 29, 40);
        let k = f32s(&[m, c, 1, 1], 11);
        let b = f32s(&[m], 12);
        let x = f32s(&[1, c, h, w], 13).to_f32();
        let s: Vec<f32> = f32s(&[1, c, 1, 1], 14)
            .to_f32()
            .iter()
            .map(|v| 1.0 / (1.0 + (-v).exp()))
            .collect();
        let bits = |v: &[f32]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
        for (planes_first, hardswish) in [(true, false), (false, false), (true, true)] {
            let mut nodes = vec![if planes_first {
                node("Mul", &["x", "s"], "p", &[])
            } else {
                node("Mul", &["s", "x"], "p", &[])
            }];
            let q = if hardswish {
                nodes.push(node("HardSwish", &["p"], "q", &[]));
                "q"
            } else {
                "p"
            };
            nodes.push(node("Conv", &[q, "k", "b"], "c", &[]));
            nodes.push(node("Relu", &["c"], "y", &[]));
            let mdl = model(nodes, vec![("k", k.clone()), ("b", b.clone())], &["x", "s"]);
            let io: [(&str, &[usize]); 2] = [("x", &[1, c, h, w]), ("s", &[1, c, 1, 1])];
            let fused = Plan::new(&mdl, &io, &["y"]).unwrap();
            assert_eq!(
                fused.steps.len(),
                1,
                "the Mul and the activations in the Conv"
            );
            assert!(matches!(
                fused.steps[0],
                Step::Conv {
                    kind: ConvKind::Pointwise,
                    scale: Some(_),
                    ..
                }
            ));
            // The convolution's input also an output: read twice, so it is computed apart.
            let apart = Plan::new(&mdl, &io, &["y", q]).unwrap();
            assert_eq!(apart.steps.len(), 2);
            // The fused product's planes take no memory: the plans' slots differ by them.
            let values = |p: &Plan| p.slots.iter().sum::<usize>();
            assert_eq!(values(&fused) + c * h * w, values(&apart));
            assert!(matches!(apart.steps[1], Step::Conv { scale: None, .. }));
            let mut rf = Runner::new(std::sync::Arc::new(fused));
            let mut ra = Runner::new(std::sync::Arc::new(apart));
            let got = rf.run(&[&x, &s]).unwrap()[0].to_vec();
            let outs = ra.run(&[&x, &s]).unwrap();
            let case = format!("planes first {planes_first}, HardSwish {hardswish}");
            assert_eq!(bits(&got), bits(outs[0]), "{case}");
            // And what the two steps compute: the products, then the convolution.
            let p: Vec<f32> = x
                .iter()
                .enumerate()
                .map(|(i, &v)| v * s[i / (h * w)])
                .map(|v| {
                    if hardswish {
                        Unary::HardSwish.eval(v)
                    } else {
                        v
                    }
                })
                .collect();
            assert_eq!(bits(outs[1]), bits(&p), "{case}");
            let conv = naive_conv(&p, (c, h, w), &k, &b.to_f32(), 1, (1, 1), (0, 0, 0, 0));
            let relu: Vec<f32> = conv.iter().map(|v| v.max(0.0)).collect();
            assert!(worst(&got, &relu) < 1e-5, "{case}");
        }
        // Factors per row or per value are not a channel scale: not fused.
        for sshape in [[1, 1, h, 1], [1, c, h, w]] {
            let mdl = model(
                vec![
                    node("Mul", &["x", "s"], "p", &[]),
                    node("Conv", &["p", "k", "b"], "y", &[]),
                ],
                vec![("k", k.clone()), ("b", b.clone())],
                &["x", "s"],
            );
            let io: [(&str, &[usize]); 2] = [("x", &[1, c, h, w]), ("s", &sshape)];
            let p = Plan::new(&mdl, &io, &["y"]).unwrap();
            assert_eq!(p.steps.len(), 2, "{sshape:?}");
        }
    }

    /// NanoTrack v2's backbone: each of its six squeeze-excitation layers scales the
    /// channels that a 1 × 1 convolution reads next (five with a HardSwish between), and
    /// every one of them is fused into that convolution.
    #[test]
    fn the_backbones_channel_scales_all_fuse() {
        static BACKBONE: &[u8] =
            include_bytes!("../../../models/nanotrack/nanotrackv2_backbone_sim_dyn.onnx");
        let m = onnx::parse(BACKBONE).unwrap();
        let muls = m.nodes.iter().filter(|n| n.op_type == "Mul").count();
        assert_eq!(muls, 6);
        let p = Plan::new(&m, &[("input", &[1, 3, 255, 255])], &["output"]).unwrap();
        let scaled = p
            .steps
            .iter()
            .filter(|s| matches!(s, Step::Conv { scale: Some(_), .. }))
            .count();
        let with_act = p
            .steps
            .iter()
            .filter(|s| {
                matches!(
                    s,
                    Step::Conv {
                        scale: Some((_, Some(_))),
                        ..
                    }
                )
            })
            .count();
        let left = p
            .steps
            .iter()
            .filter(|s| {
                matches!(
                    s,
                    Step::Binary {
                        op: Binary::Mul,
                        ..
                    }
                )
            })
            .count();
        assert_eq!((scaled, with_act, left), (6, 5, 0));
    }

    /// `plan` with a buffer of its own per slot (what every plan had before
    /// [`Plan::share_buffers`]).
    fn unshared(plan: &Plan) -> Plan {
        let mut p = plan.clone();
        p.buffer = (0..p.slots.len()).collect();
        p.buffer_len = p.slots.clone();
        p
    }

    /// No two slots that one step references share a buffer, and none shares with a
    /// slot that lives at the same time (from its first step to its last); constants,
    /// inputs and outputs have buffers of their own, each buffer holds its slots.
    fn assert_sharing_sound(p: &Plan) {
        let n = p.slots.len();
        let (mut first, mut last) = (vec![usize::MAX; n], vec![0; n]);
        for (i, step) in p.steps.iter().enumerate() {
            for s in step.refs().into_iter().flatten() {
                first[s] = first[s].min(i);
                last[s] = last[s].max(i);
            }
        }
        let own: Vec<usize> = p
            .init
            .iter()
            .map(|(s, _)| *s)
            .chain(p.inputs.iter().chain(&p.outputs).map(|(_, s, _)| *s))
            .collect();
        for s in 0..n {
            assert!(p.buffer_len[p.buffer[s]] >= p.slots[s], "slot {s}");
            for t in 0..n {
                if s == t || p.buffer[s] != p.buffer[t] {
                    continue;
                }
                assert!(!own.contains(&s), "slot {s} must have its own buffer");
                let apart = last[s] < first[t] || last[t] < first[s];
                assert!(apart, "slots {s} and {t} overlap in buffer {}", p.buffer[s]);
            }
        }
    }

    /// NanoTrack v2's backbone (255 and 127 px) and head (both branches) in shared buffers:
    /// the same output bits as with a buffer per slot, run after run (a step that read a
    /// value another slot left in its buffer would differ from the zeros of a fresh one),
    /// in under half the memory; and the sharing is sound.
    #[test]
    fn shared_buffers_give_the_bits_of_a_buffer_per_slot() {
        static BACKBONE: &[u8] =
            include_bytes!("../../../models/nanotrack/nanotrackv2_backbone_sim_dyn.onnx");
        static HEAD: &[u8] = include_bytes!("../../../models/nanotrack/nanotrackv2_head_sim.onnx");
        let (backbone, head) = (onnx::parse(BACKBONE).unwrap(), onnx::parse(HEAD).unwrap());
        let bits = |v: &[f32]| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        type Case<'a> = (&'a Model, Vec<(&'a str, Vec<usize>)>, &'a [&'a str]);
        let cases: [Case; 3] = [
            (
                &backbone,
                vec![("input", vec![1, 3, 255, 255])],
                &["output"],
            ),
            (
                &backbone,
                vec![("input", vec![1, 3, 127, 127])],
                &["output"],
            ),
            (
                &head,
                vec![
                    ("input1", vec![1, 48, 8, 8]),
                    ("input2", vec![1, 48, 16, 16]),
                ],
                &["output1", "output2"],
            ),
        ];
        for (seed, (model, inputs, outputs)) in (10u32..).zip(cases) {
            let io: Vec<(&str, &[usize])> =
                inputs.iter().map(|(n, s)| (*n, s.as_slice())).collect();
            let shared = Plan::new(model, &io, outputs).unwrap();
            assert_sharing_sound(&shared);
            let own = unshared(&shared);
            let case = format!("{inputs:?}");
            assert!(
                2 * shared.buffer_values() < own.buffer_values(),
                "{case}: {} values shared, {} apart",
                shared.buffer_values(),
                own.buffer_values()
            );
            let mut rs = Runner::new(std::sync::Arc::new(shared));
            let mut ro = Runner::new(std::sync::Arc::new(own));
            for run in 0..3u32 {
                let data: Vec<Vec<f32>> = inputs
                    .iter()
                    .enumerate()
                    .map(|(k, (_, shape))| f32s(shape, seed * 7 + run * 3 + k as u32).to_f32())
                    .collect();
                let refs: Vec<&[f32]> = data.iter().map(Vec::as_slice).collect();
                let got: Vec<Vec<u32>> = rs.run(&refs).unwrap().iter().map(|o| bits(o)).collect();
                let want: Vec<Vec<u32>> = ro.run(&refs).unwrap().iter().map(|o| bits(o)).collect();
                assert_eq!(got, want, "{case}, run {run}");
            }
        }
    }

    /// The smaller test networks' plans share soundly too (residual adds read a slot
    /// several steps after it was written, a product read twice, fused activations).
    #[test]
    fn buffer_sharing_keeps_live_slots_apart() {
        let k = f32s(&[2, 2, 1, 1], 3);
        let m = model(
            vec![
                node("Conv", &["x", "k"], "a", &[]),
                node("Relu", &["a"], "r", &[]),
                node("Conv", &["r", "k"], "b", &[]),
                node("Conv", &["b", "k"], "c", &[]),
                node("Add", &["c", "a"], "d", &[]),
                node("Conv", &["d", "k"], "e", &[]),
                node("Add", &["e", "d"], "y", &[]),
            ],
            vec![("k", k)],
            &["x"],
        );
        let p = Plan::new(&m, &[("x", &[1, 2, 6, 6])], &["y", "b"]).unwrap();
        assert_sharing_sound(&p);
        // `b` is an output; `c` can take `r`'s buffer (dead once `b` is computed).
        assert!(p.buffer_values() < unshared(&p).buffer_values());
        let x = f32s(&[1, 2, 6, 6], 5).to_f32();
        let bits = |v: &[f32]| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        let mut rs = Runner::new(std::sync::Arc::new(p.clone()));
        let mut ro = Runner::new(std::sync::Arc::new(unshared(&p)));
        for _ in 0..2 {
            let got: Vec<Vec<u32>> = rs.run(&[&x]).unwrap().iter().map(|o| bits(o)).collect();
            let want: Vec<Vec<u32>> = ro.run(&[&x]).unwrap().iter().map(|o| bits(o)).collect();
            assert_eq!(got, want);
        }
    }

    #[test]
    fn activations_fuse_only_into_values_read_once() {
        let k = f32s(&[3, 2, 1, 1], 3);
        let x = f32s(&[1, 2, 4, 4], 4).to_f32();
        let conv = || node("Conv", &["x", "k"], "c", &[]);
        let m = model(
            vec![
                conv(),
                node("Relu", &["c"], "r", &[]),
                node("Add", &["r", "c"], "y", &[]),
            ],
            vec![("k", k.clone())],
            &["x"],
        );
        let p = Plan::new(&m, &[("x", &[1, 2, 4, 4])], &["y"]).unwrap();
        assert_eq!(
            p.steps.len(),
            3,
            "not fused: the sum reads the convolution too"
        );
        let got = run(&m, &[("x", &[1, 2, 4, 4], &x)], "y");
        let c = naive_conv(&x, (2, 4, 4), &k, &[0.0; 3], 1, (1, 1), (0, 0, 0, 0));
        let want: Vec<f32> = c.iter().map(|v| v.max(0.0) + v).collect();
        assert!(worst(&got, &want) < 1e-5);
        let m = model(
            vec![conv(), node("Relu", &["c"], "y", &[])],
            vec![("k", k)],
            &["x"],
        );
        let p = Plan::new(&m, &[("x", &[1, 2, 4, 4])], &["y"]).unwrap();
        assert_eq!(p.steps.len(), 1, "fused");
        let got = run(&m, &[("x", &[1, 2, 4, 4], &x)], "y");
        let want: Vec<f32> = c.iter().map(|v| v.max(0.0)).collect();
        assert!(worst(&got, &want) < 1e-5);
    }

    /// Unsupported operators, missing inputs, shapes that do not fit and sizes beyond the
    /// memory bound are errors at plan time, naming the node.
    #[test]
    fn bad_graphs_are_errors_at_plan_time() {
        let plan = |m: &Model, shape: &[usize]| Plan::new(m, &[("x", shape)], &["y"]);
        let m = model(vec![node("LSTM", &["x"], "y", &[])], vec![], &["x"]);
        let e = plan(&m, &[1, 4]).unwrap_err();
        assert!(e.contains("`LSTM` is not supported"), "{e}");
        let m = model(vec![node("Relu", &["z"], "y", &[])], vec![], &["x"]);
        assert!(plan(&m, &[1, 4])
            .unwrap_err()
            .contains("`z` is not defined"));
        let m = model(
            vec![node("Add", &["x", "k"], "y", &[])],
            vec![("k", f32s(&[3], 1))],
            &["x"],
        );
        assert!(plan(&m, &[1, 4]).unwrap_err().contains("do not broadcast"));
        let k = f32s(&[4, 2, 3, 3], 1);
        let conv = node("Conv", &["x", "k"], "y", &[]);
        let m = model(vec![conv.clone()], vec![("k", k.clone())], &["x"]);
        assert!(plan(&m, &[1, 3, 8, 8]).unwrap_err().contains("do not fit"));
        assert!(plan(&m, &[1, 2, 2, 2])
            .unwrap_err()
            .contains("does not fit"));
        // Padding beyond the kernel, a stride beyond the input, an empty kernel.
        let padded = node("Conv", &["x", "k"], "y", &[("pads", ints(&[4, 0, 0, 0]))]);
        let m = model(vec![padded], vec![("k", f32s(&[4, 4, 3, 3], 1))], &["x"]);
        assert!(plan(&m, &[1, 4, 8, 8])
            .unwrap_err()
            .contains("at most the kernel"));
        let strided = node(
            "Conv",
            &["x", "k"],
            "y",
            &[("strides", ints(&[1 << 62, 1]))],
        );
        let m = model(vec![strided], vec![("k", f32s(&[4, 4, 3, 3], 1))], &["x"]);
        assert!(plan(&m, &[1, 4, 8, 8])
            .unwrap_err()
            .contains("at most the padded input"));
        let m = model(
            vec![conv.clone()],
            vec![("k", f32s(&[0, 4, 3, 3], 1))],
            &["x"],
        );
        assert!(plan(&m, &[1, 4, 8, 8])
            .unwrap_err()
            .contains("holds no value"));
        // A 4-channel 100k × 100k input: 4e10 values, refused before any allocation.
        let m = model(vec![conv], vec![("k", f32s(&[4, 4, 3, 3], 1))], &["x"]);
        let e = plan(&m, &[1, 4, 100_000, 100_000]).unwrap_err();
        assert!(e.contains("memory"), "{e}");
        assert!(Plan::new(&m, &[("nope", &[1])], &["y"]).is_err());
        assert!(Plan::new(&m, &[("x", &[1, 4, 8, 8])], &["missing"]).is_err());
        // The wrong input length at run time is an error, not a panic.
        let p = Plan::new(&m, &[("x", &[1, 4, 8, 8])], &["y"]).unwrap();
        let mut r = Runner::new(std::sync::Arc::new(p));
        assert!(r.run(&[&[0.0; 7]]).is_err());
        assert!(r.run(&[]).is_err());
    }

    #[test]
    fn a_lent_input_gives_the_copied_inputs_outputs_and_comes_back_unchanged() {
        // Two convolutions and a depthwise one between (each step writes a new buffer).
        let nodes = vec![
            node("Conv", &["x", "k1"], "a", &[("pads", ints(&[1, 1, 1, 1]))]),
            node(
                "Conv",
                &["a", "k2"],
                "b",
                &[("group", Attr::Int(4)), ("pads", ints(&[1, 1, 1, 1]))],
            ),
            node("Conv", &["b", "k3"], "y", &[]),
        ];
        let inits = vec![
            ("k1", f32s(&[4, 3, 3, 3], 1)),
            ("k2", f32s(&[4, 1, 3, 3], 2)),
            ("k3", f32s(&[2, 4, 1, 1], 3)),
        ];
        let m = model(nodes, inits, &["x"]);
        let p = std::sync::Arc::new(Plan::new(&m, &[("x", &[1, 3, 9, 9])], &["y", "a"]).unwrap());
        let x: Vec<f32> = (0..3 * 81)
            .map(|i| ((i * 37) % 23) as f32 / 7.0 - 1.5)
            .collect();
        let mut copied = Runner::new(std::sync::Arc::clone(&p));
        let want: Vec<Vec<f32>> = copied
            .run(&[&x])
            .unwrap()
            .iter()
            .map(|v| v.to_vec())
            .collect();
        let mut lent = Runner::new(p);
        for _ in 0..2 {
            let mut input = x.clone();
            let got: Vec<Vec<f32>> = lent
                .run_exchanging(&mut input)
                .unwrap()
                .iter()
                .map(|v| v.to_vec())
                .collect();
            let bits = |v: &[Vec<f32>]| v.iter().flatten().map(|f| f.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&got), bits(&want));
            assert_eq!(input, x, "the lent input comes back as it was");
        }
        // A wrong length is an error, the caller's buffer untouched.
        let mut short = vec![0.5; 7];
        assert!(lent.run_exchanging(&mut short).is_err());
        assert_eq!(short, vec![0.5; 7]);
        // A network whose output is its input: copied, and both still right.
        let id = model(vec![], vec![], &["x"]);
        let p = Plan::new(&id, &[("x", &[1, 2])], &["x"]).unwrap();
        let mut r = Runner::new(std::sync::Arc::new(p));
        let mut input = vec![1.0, 2.0];
        assert_eq!(r.run_exchanging(&mut input).unwrap(), vec![&[1.0, 2.0][..]]);
        assert_eq!(input, vec![1.0, 2.0]);
    }
}
