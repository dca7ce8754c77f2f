//! A convolutional network planned for a window of its output maps: [`windowed`] rewrites
//! the nodes between the outputs and the last node that needs its whole input map so that
//! each computes only the grid points the window depends on (its receptive field), value for
//! value what the whole network computes there.
//!
//! Why: the learned box (`crate::box_refine`, `read: filter`) reads NanoTrack's head at the
//! 3 × 3 grid points around the crop centre, but the head's two towers of six depthwise
//! 3 × 3 and pointwise layers computed all 12 × 12 points: a 3 × 3 window needs 11 × 11 points
//! of the second layer, 9 × 9 of the third … 3 × 3 of the sixth, about half the towers' work.
//!
//! Only nodes whose output at a grid point depends on a fixed neighbourhood of their input
//! are windowed: element-wise unary operators and convolutions of stride 1 without
//! dilation (any kernel, any groups). A convolution's window is cut out of its input's by
//! changing its padding: zero padding only where the whole map had it, so every output
//! value is the same sum of the same products in the same order (the same bits; the tests
//! compare bit for bit). Anything else between the outputs and the nodes that need their
//! whole input (a pooling, a reshape, a broadcast product) makes [`windowed`] refuse.

use super::onnx::{Attr, Model, Node};
use std::collections::HashMap;

/// Grid rows (and columns: windows are square) `lo..=hi` of an `n × n` map.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Span {
    /// First row.
    pub lo: usize,
    /// Last row (inclusive).
    pub hi: usize,
}

impl Span {
    fn union(self, o: Span) -> Span {
        Span {
            lo: self.lo.min(o.lo),
            hi: self.hi.max(o.hi),
        }
    }
}

/// Element-wise operators of one spatial input (the others, e.g. `Clip`'s bounds, are
/// scalars).
const UNARY: &[&str] = &[
    "Relu",
    "Clip",
    "Sigmoid",
    "Exp",
    "HardSigmoid",
    "HardSwish",
    "Identity",
];

/// A convolution's square kernel side and its padding before and after (rows and columns
/// alike), when it can be windowed: stride 1, no dilation, explicit padding, square kernel
/// from a constant, the same padding on both axes.
fn conv_geometry(model: &Model, n: &Node) -> Option<(usize, usize, usize)> {
    let ints = |name: &str| match n.attrs.get(name) {
        Some(Attr::Ints(v)) => Some(Some(v.clone())),
        None => Some(None),
        _ => None,
    };
    if let Some(Attr::Str(a)) = n.attrs.get("auto_pad") {
        if a != "NOTSET" {
            return None;
        }
    }
    let k = model.initializers.get(n.inputs.get(1)?)?;
    let [_, _, kh, kw] = k.dims.as_slice() else {
        return None;
    };
    if kh != kw {
        return None;
    }
    let ones = |v: Option<Vec<i64>>| v.is_none_or(|v| v.iter().all(|&s| s == 1));
    if !ones(ints("strides")?) || !ones(ints("dilations")?) {
        return None;
    }
    let pads = ints("pads")?.unwrap_or(vec![0; 4]);
    let [pt, pl, pb, pr] = pads.as_slice() else {
        return None;
    };
    if pt != pl || pb != pr || *pt < 0 || *pb < 0 {
        return None;
    }
    Some((*kh, usize::try_from(*pt).ok()?, usize::try_from(*pb).ok()?))
}

/// `model` with `output` (a map of `n × n` grid points, as every spatial map between it and
/// the nodes that need a whole map) computed only over `span × span`: a
/// `[.., span.len(), span.len()]` output whose values are, bit for bit, the whole network's
/// at those points. `None` when a node on the way cannot be windowed (see the module doc),
/// or `span` does not lie in the map.
pub fn windowed<'m>(model: &'m Model, output: &'m str, n: usize, span: Span) -> Option<Model> {
    if span.lo > span.hi || span.hi >= n {
        return None;
    }
    let full = Span { lo: 0, hi: n - 1 };
    // Backwards (ONNX lists nodes in topological order): the points each value must have.
    let mut need: HashMap<&'m str, Span> = HashMap::from([(output, span)]);
    let mut plan: Vec<Option<(usize, usize, usize)>> = vec![None; model.nodes.len()];
    for (i, node) in model.nodes.iter().enumerate().rev() {
        let [out] = node.outputs.as_slice() else {
            if node.outputs.iter().any(|o| need.contains_key(o.as_str())) {
                // Several outputs: only needed whole.
                if node
                    .outputs
                    .iter()
                    .any(|o| need.get(o.as_str()) != Some(&full))
                {
                    return None;
                }
                for x in &node.inputs {
                    need.insert(x, full);
                }
            }
            continue;
        };
        let Some(&w) = need.get(out.as_str()) else {
            continue;
        };
        let mut ask = |x: &'m str, s: Span| {
            let e = need.entry(x).or_insert(s);
            *e = e.union(s);
        };
        if w == full {
            for x in &node.inputs {
                ask(x, full);
            }
            continue;
        }
        let x = node.inputs.first()?;
        if UNARY.contains(&node.op_type.as_str()) && node.domain.is_empty() {
            ask(x, w);
        } else if node.op_type == "Conv" && node.domain.is_empty() {
            let (k, pt, pb) = conv_geometry(model, node)?;
            // Output row o reads input rows o − pt .. o − pt + k − 1 (outside: padding).
            let lo = w.lo.saturating_sub(pt);
            let hi = (w.hi + k - 1).checked_sub(pt)?.min(n - 1);
            if w.hi + k - 1 > pt + n - 1 + pb {
                return None;
            }
            ask(x, Span { lo, hi });
            plan[i] = Some((k, pt, pb));
        } else {
            return None;
        }
    }
    // Forwards: every windowed node's input must be exactly the window asked of it (no
    // second consumer widened it), so that the node's padding can be cut to size.
    let mut out = model.clone();
    for (i, node) in out.nodes.iter_mut().enumerate() {
        let Some(&w) = node.outputs.first().and_then(|o| need.get(o.as_str())) else {
            continue;
        };
        if w == full {
            continue;
        }
        // A graph input comes whole: only a node that reads all of it can take it.
        let is_graph_input = model.inputs.iter().any(|v| v.name == node.inputs[0]);
        let inw = need.get(node.inputs[0].as_str()).copied()?;
        if is_graph_input && inw != full {
            return None;
        }
        match plan[i] {
            None => {
                // Element-wise: the same points in and out.
                if inw != w {
                    return None;
                }
            }
            Some((k, pt, pb)) => {
                // Padding before: the rows the window's first output reads above the input
                // window; after: below it (both zero where the whole map had no padding).
                let before = (inw.lo + pt).checked_sub(w.lo)?;
                let after = (w.hi + k - 1).checked_sub(inw.hi + pt)?;
                if before > pt || after > pb {
                    return None;
                }
                let (b, a) = (before as i64, after as i64);
                node.attrs
                    .insert("pads".into(), Attr::Ints(vec![b, b, a, a]));
            }
        }
    }
    Some(out)
}
