//! Reading an ONNX model: the protobuf wire format decoded by hand for the messages and
//! fields an inference graph needs (`ModelProto` → `GraphProto` → nodes, attributes,
//! initialisers, inputs and outputs; `onnx.proto` of ONNX 1.x gives the field numbers).
//! Unknown fields are skipped, as protobuf requires.
//!
//! Input is untrusted: every length is checked against the bytes that remain before
//! anything is allocated for it, so memory follows the file's size (bounded by the caller),
//! never what a field declares; nesting is bounded; an initialiser's values must match its
//! dimensions; external data (weights in another file) is refused.

use std::collections::HashMap;

/// Deepest message nesting accepted (a model needs 6: model, graph, value info, type,
/// tensor type, shape dimension).
const MAX_DEPTH: usize = 16;

/// A decoding error: what was wrong, in words.
pub type Error = String;

/// A tensor's values, as stored.
#[derive(Debug, Clone, PartialEq)]
pub enum Data {
    /// `FLOAT` (1).
    F32(Vec<f32>),
    /// `INT64` (7), also `INT32` (6) widened.
    I64(Vec<i64>),
}

/// A constant tensor (an initialiser or a tensor attribute).
#[derive(Debug, Clone, PartialEq)]
pub struct Tensor {
    /// Dimensions (empty: a scalar).
    pub dims: Vec<usize>,
    /// Values, `dims`' product of them.
    pub data: Data,
}

impl Tensor {
    /// Number of values of `dims`, or `None` on overflow.
    pub fn count(dims: &[usize]) -> Option<usize> {
        dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d))
    }

    /// The values as f32 (integers converted).
    pub fn to_f32(&self) -> Vec<f32> {
        match &self.data {
            Data::F32(v) => v.clone(),
            Data::I64(v) => v.iter().map(|&x| x as f32).collect(),
        }
    }

    /// The values as i64 (`None` for floats).
    pub fn as_i64(&self) -> Option<&[i64]> {
        match &self.data {
            Data::I64(v) => Some(v),
            Data::F32(_) => None,
        }
    }
}

/// A node attribute's value.
#[derive(Debug, Clone, PartialEq)]
pub enum Attr {
    /// `FLOAT`.
    Float(f32),
    /// `INT`.
    Int(i64),
    /// `STRING` (lossy UTF-8).
    Str(String),
    /// `TENSOR`.
    Tensor(Tensor),
    /// `FLOATS`.
    Floats(Vec<f32>),
    /// `INTS`.
    Ints(Vec<i64>),
    /// Another type (graphs, sparse tensors, type protos): kept only as present.
    Other,
}

/// One operator application.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Node {
    /// Node name (may be empty).
    pub name: String,
    /// Operator, e.g. `Conv`.
    pub op_type: String,
    /// Operator set domain (empty: the default ONNX domain).
    pub domain: String,
    /// Input value names (an empty name: an omitted optional input).
    pub inputs: Vec<String>,
    /// Output value names.
    pub outputs: Vec<String>,
    /// Attributes by name.
    pub attrs: HashMap<String, Attr>,
}

/// A graph input or output: its name and its dimensions as declared (`None`: symbolic or
/// unknown).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ValueInfo {
    /// Value name.
    pub name: String,
    /// Declared dimensions, `None` for a symbolic one; empty when no shape is declared.
    pub dims: Vec<Option<usize>>,
}

/// The inference graph of a model.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Model {
    /// Nodes in file order.
    pub nodes: Vec<Node>,
    /// Initialisers (constant tensors) by name.
    pub initializers: HashMap<String, Tensor>,
    /// Graph inputs (initialisers listed as inputs included).
    pub inputs: Vec<ValueInfo>,
    /// Graph outputs.
    pub outputs: Vec<ValueInfo>,
    /// Version of the default-domain operator set (0 when not declared).
    pub opset: i64,
}

/// A protobuf reader over a byte slice.
struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
    depth: usize,
}

/// One field's payload.
enum Value<'a> {
    Varint(u64),
    Fixed64,
    Bytes(&'a [u8]),
    Fixed32(u32),
}

impl<'a> Reader<'a> {
    fn new(buf: &'a [u8], depth: usize) -> Result<Self, Error> {
        if depth > MAX_DEPTH {
            return Err(format!("messages nested deeper than {MAX_DEPTH}"));
        }
        Ok(Self { buf, pos: 0, depth })
    }

    fn varint(&mut self) -> Result<u64, Error> {
        let mut v = 0u64;
        for i in 0..10 {
            let b = *self
                .buf
                .get(self.pos)
                .ok_or_else(|| "truncated varint".to_string())?;
            self.pos += 1;
            v |= u64::from(b & 0x7f) << (7 * i);
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err("varint longer than 10 bytes".into())
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], Error> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.buf.len())
            .ok_or_else(|| {
                format!(
                    "field of {n} bytes where {} remain",
                    self.buf.len() - self.pos
                )
            })?;
        let s = &self.buf[self.pos..end];
        self.pos = end;
        Ok(s)
    }

    /// The next field's number and payload, or `None` at the end.
    fn field(&mut self) -> Result<Option<(u64, Value<'a>)>, Error> {
        if self.pos >= self.buf.len() {
            return Ok(None);
        }
        let key = self.varint()?;
        let (num, wire) = (key >> 3, key & 7);
        let v = match wire {
            0 => Value::Varint(self.varint()?),
            1 => {
                self.take(8)?;
                Value::Fixed64
            }
            2 => {
                let n = usize::try_from(self.varint()?).map_err(|_| "length too large")?;
                Value::Bytes(self.take(n)?)
            }
            5 => Value::Fixed32(u32::from_le_bytes(
                self.take(4)?.try_into().unwrap_or([0; 4]),
            )),
            w => return Err(format!("field {num}: unsupported wire type {w}")),
        };
        Ok(Some((num, v)))
    }

    fn sub(&self, b: &'a [u8]) -> Result<Reader<'a>, Error> {
        Reader::new(b, self.depth + 1)
    }
}

fn bytes<'a>(v: Value<'a>, what: &str) -> Result<&'a [u8], Error> {
    match v {
        Value::Bytes(b) => Ok(b),
        _ => Err(format!("{what}: expected a length-delimited field")),
    }
}

fn string(v: Value<'_>, what: &str) -> Result<String, Error> {
    Ok(String::from_utf8_lossy(bytes(v, what)?).into_owned())
}

fn int(v: Value<'_>, what: &str) -> Result<i64, Error> {
    match v {
        Value::Varint(x) => Ok(x as i64),
        _ => Err(format!("{what}: expected a varint")),
    }
}

/// A repeated int64 field, packed or not, appended to `out`.
fn ints(v: Value<'_>, out: &mut Vec<i64>, what: &str) -> Result<(), Error> {
    match v {
        Value::Varint(x) => out.push(x as i64),
        Value::Bytes(b) => {
            let mut r = Reader::new(b, 0)?;
            while r.pos < b.len() {
                out.push(r.varint()? as i64);
            }
        }
        _ => return Err(format!("{what}: expected varints")),
    }
    Ok(())
}

/// A repeated float field, packed or not, appended to `out`.
fn floats(v: Value<'_>, out: &mut Vec<f32>, what: &str) -> Result<(), Error> {
    match v {
        Value::Fixed32(x) => out.push(f32::from_bits(x)),
        Value::Bytes(b) => {
            if b.len() % 4 != 0 {
                return Err(format!("{what}: packed floats of {} bytes", b.len()));
            }
            out.extend(
                b.chunks_exact(4)
                    .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])),
            );
        }
        _ => return Err(format!("{what}: expected floats")),
    }
    Ok(())
}

/// Decodes a `ModelProto`.
///
/// # Errors
/// What is malformed or unsupported, in words.
pub fn parse(buf: &[u8]) -> Result<Model, Error> {
    let mut r = Reader::new(buf, 0)?;
    let mut model = Model::default();
    let mut graph = None;
    while let Some((num, v)) = r.field()? {
        match num {
            7 => graph = Some(bytes(v, "graph")?),
            8 => {
                let mut s = r.sub(bytes(v, "opset_import")?)?;
                let (mut domain, mut version) = (String::new(), 0);
                while let Some((n, v)) = s.field()? {
                    match n {
                        1 => domain = string(v, "opset domain")?,
                        2 => version = int(v, "opset version")?,
                        _ => {}
                    }
                }
                if domain.is_empty() || domain == "ai.onnx" {
                    model.opset = version;
                }
            }
            _ => {}
        }
    }
    let graph = graph.ok_or("no graph: not an ONNX model")?;
    let mut g = r.sub(graph)?;
    while let Some((num, v)) = g.field()? {
        match num {
            1 => model.nodes.push(node(&g, bytes(v, "node")?)?),
            5 => {
                let (name, t) = tensor(&g, bytes(v, "initializer")?)?;
                model.initializers.insert(name, t);
            }
            11 => model.inputs.push(value_info(&g, bytes(v, "input")?)?),
            12 => model.outputs.push(value_info(&g, bytes(v, "output")?)?),
            _ => {}
        }
    }
    if model.nodes.is_empty() {
        return Err("the graph has no nodes".into());
    }
    Ok(model)
}

fn node(parent: &Reader<'_>, b: &[u8]) -> Result<Node, Error> {
    let mut r = parent.sub(b)?;
    let mut n = Node::default();
    while let Some((num, v)) = r.field()? {
        match num {
            1 => n.inputs.push(string(v, "node input")?),
            2 => n.outputs.push(string(v, "node output")?),
            3 => n.name = string(v, "node name")?,
            4 => n.op_type = string(v, "op_type")?,
            5 => {
                let (name, a) = attribute(&r, bytes(v, "attribute")?)?;
                n.attrs.insert(name, a);
            }
            7 => n.domain = string(v, "node domain")?,
            _ => {}
        }
    }
    if n.op_type.is_empty() {
        return Err(format!("node `{}` has no op_type", n.name));
    }
    Ok(n)
}

fn attribute(parent: &Reader<'_>, b: &[u8]) -> Result<(String, Attr), Error> {
    let mut r = parent.sub(b)?;
    let mut name = String::new();
    let (mut f, mut i, mut s, mut t) = (None, None, None, None);
    let (mut fs, mut is) = (Vec::new(), Vec::new());
    let mut ty = 0;
    while let Some((num, v)) = r.field()? {
        match num {
            1 => name = string(v, "attribute name")?,
            2 => {
                let mut x = Vec::new();
                floats(v, &mut x, "attribute f")?;
                f = x.last().copied();
            }
            3 => i = Some(int(v, "attribute i")?),
            4 => s = Some(string(v, "attribute s")?),
            5 => t = Some(tensor(&r, bytes(v, "attribute t")?)?.1),
            7 => floats(v, &mut fs, "attribute floats")?,
            8 => ints(v, &mut is, "attribute ints")?,
            20 => ty = int(v, "attribute type")?,
            _ => {}
        }
    }
    // AttributeType: FLOAT 1, INT 2, STRING 3, TENSOR 4, FLOATS 6, INTS 7. Files from old
    // exporters may leave the type out: then the field that is present decides.
    let a = match ty {
        1 => Attr::Float(f.unwrap_or(0.0)),
        2 => Attr::Int(i.unwrap_or(0)),
        3 => Attr::Str(s.unwrap_or_default()),
        4 => Attr::Tensor(t.ok_or_else(|| format!("attribute `{name}`: no tensor"))?),
        6 => Attr::Floats(fs),
        7 => Attr::Ints(is),
        0 => match (f, i, s, t) {
            (Some(f), ..) => Attr::Float(f),
            (_, Some(i), ..) => Attr::Int(i),
            (_, _, Some(s), _) => Attr::Str(s),
            (_, _, _, Some(t)) => Attr::Tensor(t),
            _ if !fs.is_empty() => Attr::Floats(fs),
            _ => Attr::Ints(is),
        },
        _ => Attr::Other,
    };
    Ok((name, a))
}

fn tensor(parent: &Reader<'_>, b: &[u8]) -> Result<(String, Tensor), Error> {
    let mut r = parent.sub(b)?;
    let mut name = String::new();
    let mut dims = Vec::new();
    let mut dtype = 0;
    let mut raw: Option<&[u8]> = None;
    let (mut fdata, mut idata) = (Vec::new(), Vec::new());
    while let Some((num, v)) = r.field()? {
        match num {
            1 => ints(v, &mut dims, "tensor dims")?,
            2 => dtype = int(v, "tensor data_type")?,
            4 => floats(v, &mut fdata, "float_data")?,
            5 | 7 => ints(v, &mut idata, "int_data")?,
            8 => name = string(v, "tensor name")?,
            9 => raw = Some(bytes(v, "raw_data")?),
            13 | 14 => {
                return Err(format!(
                    "tensor `{name}`: external data (weights in another file) is not supported"
                ))
            }
            _ => {}
        }
    }
    let dims: Vec<usize> = dims
        .iter()
        .map(|&d| usize::try_from(d).map_err(|_| format!("tensor `{name}`: dimension {d}")))
        .collect::<Result<_, _>>()?;
    let count = Tensor::count(&dims).ok_or_else(|| format!("tensor `{name}`: too many values"))?;
    let wrong = |have: usize| format!("tensor `{name}`: {have} values for dimensions {dims:?}");
    let data = match dtype {
        1 => {
            let v = match raw {
                Some(b) => {
                    if b.len() != count.saturating_mul(4) {
                        return Err(wrong(b.len() / 4));
                    }
                    b.chunks_exact(4)
                        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                        .collect()
                }
                None => fdata,
            };
            if v.len() != count {
                return Err(wrong(v.len()));
            }
            Data::F32(v)
        }
        6 | 7 => {
            let width = if dtype == 7 { 8 } else { 4 };
            let v: Vec<i64> = match raw {
                Some(b) => {
                    if b.len() != count.saturating_mul(width) {
                        return Err(wrong(b.len() / width));
                    }
                    b.chunks_exact(width)
                        .map(|c| {
                            if width == 8 {
                                i64::from_le_bytes(c.try_into().unwrap_or([0; 8]))
                            } else {
                                i64::from(i32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                            }
                        })
                        .collect()
                }
                None => idata,
            };
            if v.len() != count {
                return Err(wrong(v.len()));
            }
            Data::I64(v)
        }
        t => {
            return Err(format!(
                "tensor `{name}`: data type {t} is not supported (float and int32 / int64 are)"
            ))
        }
    };
    Ok((name, Tensor { dims, data }))
}

fn value_info(parent: &Reader<'_>, b: &[u8]) -> Result<ValueInfo, Error> {
    let mut r = parent.sub(b)?;
    let mut vi = ValueInfo::default();
    while let Some((num, v)) = r.field()? {
        match num {
            1 => vi.name = string(v, "value name")?,
            2 => {
                // TypeProto.tensor_type (1) → TypeProto.Tensor.shape (2) → dim (1).
                let mut ty = r.sub(bytes(v, "type")?)?;
                while let Some((n, v)) = ty.field()? {
                    if n != 1 {
                        continue;
                    }
                    let mut tt = ty.sub(bytes(v, "tensor_type")?)?;
                    while let Some((n, v)) = tt.field()? {
                        if n != 2 {
                            continue;
                        }
                        let mut shape = tt.sub(bytes(v, "shape")?)?;
                        while let Some((n, v)) = shape.field()? {
                            if n != 1 {
                                continue;
                            }
                            let mut dim = shape.sub(bytes(v, "dim")?)?;
                            let mut d = None;
                            while let Some((n, v)) = dim.field()? {
                                if n == 1 {
                                    d = usize::try_from(int(v, "dim_value")?).ok();
                                }
                            }
                            vi.dims.push(d);
                        }
                    }
                }
            }
            _ => {}
        }
    }
    Ok(vi)
}

#[cfg(test)]
mod tests {
    use super::*;

    static BACKBONE: &[u8] =
        include_bytes!("../../../models/nanotrack/nanotrackv2_backbone_sim_dyn.onnx");
    static HEAD: &[u8] = include_bytes!("../../../models/nanotrack/nanotrackv2_head_sim.onnx");

    #[test]
    fn reads_the_embedded_models() {
        let b = parse(BACKBONE).unwrap();
        assert_eq!(b.nodes.len(), 92);
        assert_eq!(b.opset, 14);
        assert_eq!(b.inputs[0].name, "input");
        assert_eq!(b.inputs[0].dims, vec![Some(1), Some(3), None, None]);
        assert_eq!(b.outputs[0].name, "output");
        let conv = &b.nodes[0];
        assert_eq!(conv.op_type, "Conv");
        assert_eq!(conv.attrs["strides"], Attr::Ints(vec![2, 2]));
        assert_eq!(conv.attrs["group"], Attr::Int(1));
        let w = &b.initializers[&conv.inputs[1]];
        assert_eq!(w.dims, vec![16, 3, 3, 3]);
        let h = parse(HEAD).unwrap();
        assert_eq!(h.nodes.len(), 65);
        let names: Vec<_> = h.outputs.iter().map(|o| o.name.as_str()).collect();
        assert_eq!(names, ["output1", "output2"]);
        assert_eq!(
            h.inputs[1].dims,
            vec![Some(1), Some(48), Some(16), Some(16)]
        );
    }

    /// Prefixes of a model (every 997th length) and single-byte corruptions of its first 512
    /// bytes (where the graph's structure is) are errors or models, never panics or
    /// allocations beyond the input.
    #[test]
    fn truncated_and_corrupted_files_are_errors_not_panics() {
        for len in (0..HEAD.len()).step_by(997) {
            let _ = parse(&HEAD[..len]);
        }
        assert!(parse(&HEAD[..HEAD.len() / 2]).is_err());
        let mut buf = HEAD.to_vec();
        for i in 0..512 {
            let old = buf[i];
            for x in [0x00, 0xff, 0x80, 0x0a] {
                buf[i] = x;
                let _ = parse(&buf);
            }
            buf[i] = old;
        }
        assert!(parse(b"").is_err());
        assert!(parse(b"not a model at all").is_err());
    }

    /// A length prefix larger than the file is refused before any allocation.
    #[test]
    fn a_huge_declared_length_is_refused() {
        // Field 7 (graph), wire type 2, length 2^62.
        let mut m = vec![(7 << 3) | 2];
        let mut n: u64 = 1 << 62;
        while n >= 0x80 {
            m.push((n as u8 & 0x7f) | 0x80);
            n >>= 7;
        }
        m.push(n as u8);
        let e = parse(&m).unwrap_err();
        assert!(e.contains("bytes where"), "{e}");
    }

    /// An initialiser whose values do not match its dimensions is refused.
    #[test]
    fn values_must_match_dimensions() {
        // TensorProto: dims [1000000000, 1000000000], FLOAT, raw_data of 4 bytes.
        let mut t = vec![0x0a, 0x0a];
        for _ in 0..2 {
            t.extend([0x80, 0x94, 0xeb, 0xdc, 0x03]);
        }
        t.extend([0x10, 0x01, 0x4a, 0x04, 0, 0, 0, 0]);
        let r = Reader::new(&t, 0).unwrap();
        let e = tensor(&r, &t).unwrap_err();
        assert!(e.contains("values for dimensions"), "{e}");
    }
}
