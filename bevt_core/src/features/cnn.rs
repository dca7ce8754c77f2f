//! CNN features through ONNX Runtime (cargo feature `cnn`): the paper's feature mode.
//!
//! [`CnnExtractor`] turns a search patch into the input tensor its [`CnnConfig`] describes
//! (size, channel order, value range, normalisation), runs the network once, and resamples
//! each configured output bilinearly to the tracker's cell grid: one layer, one filter
//! (ALGORITHM.md §2). Each layer is normalised per frame (RMS) and scaled by its gain.
//!
//! The ONNX Runtime library is loaded at run time (`ort`'s `load-dynamic`) from
//! `features.cnn.runtime` or `ORT_DYLIB_PATH`; it is loaded once per process. Everything
//! that can be wrong with the runtime or the model is a [`CnnError`] from
//! [`CnnExtractor::new`], which also runs the network once on a grey image to check what
//! the model really returns. This is the only module of the core that reads files.
//!
//! Speed: the session is built once and shared by clones of the extractor; input and map
//! buffers are reused; [`FeatureExtractor::extract_scales`] gives every scale of a frame
//! from one network pass on the largest scale's patch. A layer with `project: N` is
//! projected onto its N principal directions (ECO's channel projection), learned on each
//! track's first patch ([`FeatureExtractor::begin_track`]) from the layer's uncentred second
//! moments (so the kept share of the feature energy is maximal), and applied on the
//! network's own grid before resampling.
//!
//! Fusion: with `features.cnn.hog`, HOG (+ gray) (+ colour names) of the same search patch,
//! resampled to `grid · cell_size` pixels, is appended as one more layer with its own filter
//! and weight.

use crate::error::TrackError;
use crate::features::cnn_config::{
    ChannelOrder, CnnConfig, CnnDevice, CnnHogConfig, InputSizePolicy, LayerNorm, MAX_INPUT_SIZE,
};
use crate::features::{FeatureExtractor, FeatureMap, Hog, LayerInfo};
use crate::geometry::GridSize;
use crate::image::Patch;
use ort::environment::Environment;
use ort::session::builder::GraphOptimizationLevel;
use ort::session::Session;
use ort::value::TensorRef;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, PoisonError};
use thiserror::Error;

/// Environment variable naming the ONNX Runtime library when the config does not.
pub const ORT_DYLIB_ENV: &str = "ORT_DYLIB_PATH";
/// Grey level (0–255) of the image the network is checked on at init.
const PROBE_GREY: f32 = 128.0;
/// Smallest RMS a layer is divided by (an all-zero map stays zero instead of NaN).
const MIN_RMS: f32 = 1e-12;

/// What can be wrong with the CNN backend; each message names the config key to fix.
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum CnnError {
    /// Neither `features.cnn.runtime` nor `ORT_DYLIB_PATH` names a runtime.
    #[error(
        "features.cnn.runtime: no ONNX Runtime library given: set features.cnn.runtime or \
         ORT_DYLIB_PATH (scripts/onnxruntime.sh fetches libonnxruntime.so.1.31.1)"
    )]
    NoRuntime,
    /// The runtime library file does not exist.
    #[error("features.cnn.runtime: {path}: no such file (scripts/onnxruntime.sh fetches it)")]
    RuntimeMissing {
        /// The path.
        path: String,
    },
    /// The library could not be loaded, is not ONNX Runtime, or is too old (< 1.20).
    #[error("features.cnn.runtime: cannot use {path} as ONNX Runtime (>= 1.20 needed): {reason}")]
    Runtime {
        /// The path.
        path: String,
        /// Loader message.
        reason: String,
    },
    /// A different runtime library is already loaded in this process.
    #[error(
        "features.cnn.runtime: ONNX Runtime is already loaded from {loaded} in this process; \
         cannot also load {requested}"
    )]
    RuntimeConflict {
        /// The library in use.
        loaded: String,
        /// The one requested now.
        requested: String,
    },
    /// The model file does not exist.
    #[error("features.cnn.model: {path}: no such file")]
    ModelMissing {
        /// The path.
        path: String,
    },
    /// ONNX Runtime could not build a session from the model.
    #[error("features.cnn.model: cannot load {path}: {reason}")]
    Model {
        /// The path.
        path: String,
        /// Runtime message.
        reason: String,
    },
    /// The model has no input of the configured name or it is not `[N, 3, H, W]`.
    #[error("features.cnn.input: {reason}")]
    Input {
        /// What is wrong.
        reason: String,
    },
    /// A configured output is not in the model.
    #[error("features.cnn.layers: the model has no output `{name}` (it has: {available})")]
    NoOutput {
        /// The configured name.
        name: String,
        /// The model's outputs.
        available: String,
    },
    /// An output is not a rank-4 `[1, C, h, w]` float tensor.
    #[error("features.cnn.layers: output `{name}` has shape {shape:?}; expected [1, C, h, w]")]
    Rank {
        /// Output name.
        name: String,
        /// Its shape (−1 = dynamic).
        shape: Vec<i64>,
    },
    /// An output's channel count differs from the config.
    #[error("features.cnn.layers: output `{name}` has {got} channels; the config says {expected}")]
    Channels {
        /// Output name.
        name: String,
        /// Channels in the model.
        got: i64,
        /// Channels in the config.
        expected: usize,
    },
    /// The model does not accept the configured input size.
    #[error("features.cnn.input_size: the model rejects a {size}x{size} input: {reason}")]
    InputSize {
        /// Input side, pixels.
        size: usize,
        /// Why.
        reason: String,
    },
    /// The device cannot be used.
    #[error("features.cnn.device: {0}")]
    Device(String),
    /// An output contains NaN or infinity.
    #[error("network output `{name}` contains a non-finite value (NaN or infinity)")]
    NonFinite {
        /// Output name.
        name: String,
    },
    /// Inference failed.
    #[error("ONNX Runtime inference failed: {0}")]
    Run(String),
}

impl From<CnnError> for TrackError {
    fn from(e: CnnError) -> Self {
        TrackError::Feature(e.to_string())
    }
}

/// The process-wide runtime: the library path it was loaded from and its environment.
static RUNTIME: Mutex<Option<(PathBuf, Environment)>> = Mutex::new(None);

/// Loads ONNX Runtime from `configured` (or `ORT_DYLIB_PATH` when empty), once per process.
///
/// # Errors
/// [`CnnError::NoRuntime`], [`CnnError::RuntimeMissing`], [`CnnError::Runtime`] (not ONNX
/// Runtime, or older than 1.20), [`CnnError::RuntimeConflict`].
pub fn load_runtime(configured: &str) -> Result<Environment, CnnError> {
    let path = if configured.is_empty() {
        match std::env::var(ORT_DYLIB_ENV) {
            Ok(p) if !p.is_empty() => PathBuf::from(p),
            _ => return Err(CnnError::NoRuntime),
        }
    } else {
        PathBuf::from(configured)
    };
    if !path.is_file() {
        return Err(CnnError::RuntimeMissing {
            path: path.display().to_string(),
        });
    }
    let canonical = path.canonicalize().unwrap_or_else(|_| path.clone());
    let mut guard = RUNTIME.lock().unwrap_or_else(PoisonError::into_inner);
    if let Some((loaded, env)) = guard.as_ref() {
        return if *loaded == canonical {
            Ok(env.clone())
        } else {
            Err(CnnError::RuntimeConflict {
                loaded: loaded.display().to_string(),
                requested: canonical.display().to_string(),
            })
        };
    }
    let runtime_err = |reason: String| CnnError::Runtime {
        path: canonical.display().to_string(),
        reason,
    };
    let env = ort::init_from(&canonical)
        .map_err(|e| runtime_err(e.to_string()))?
        .with_name("bevt")
        .build()
        .map_err(|e| runtime_err(e.to_string()))?;
    *guard = Some((canonical, env.clone()));
    Ok(env)
}

/// Bilinear taps of one output coordinate: `v = (1−w)·src[i0] + w·src[i1]`.
#[derive(Debug, Clone, Copy, Default)]
struct Tap {
    i0: usize,
    i1: usize,
    w: f32,
}

/// Taps mapping `n` output cells onto the centred fraction `fraction` of `src_n` source
/// cells (half-pixel centres, as MATLAB's `imresize` and `align_corners = false`).
fn taps(n: usize, src_n: usize, fraction: f32, out: &mut Vec<Tap>) {
    out.clear();
    let last = src_n.saturating_sub(1);
    for j in 0..n {
        let u = 0.5 + (j as f32 + 0.5 - n as f32 / 2.0) / n as f32 * fraction;
        let x = (u * src_n as f32 - 0.5).clamp(0.0, last as f32);
        let i0 = (x.floor() as usize).min(last);
        let i1 = (i0 + 1).min(last);
        out.push(Tap {
            i0,
            i1,
            w: x - i0 as f32,
        });
    }
}

/// One layer's last map, as returned by the network (or projected).
#[derive(Debug, Clone, Default)]
struct LayerMap {
    /// Channels of `data` (the network's, or the projection's after [`CnnExtractor::project_maps`]).
    c: usize,
    h: usize,
    w: usize,
    data: Vec<f32>,
    /// Multiplier applied while resampling (gain over RMS, or gain).
    factor: f32,
}

/// A learned channel projection: `rows × cols` row-major (`rows` principal directions of
/// `cols` channels), and the share of the layer's energy it kept on the patch it was
/// learned on.
#[derive(Debug, Clone, Default)]
struct Projection {
    rows: usize,
    cols: usize,
    matrix: Vec<f32>,
    energy: f32,
}

impl Projection {
    /// The `rows` leading eigenvectors of the uncentred second-moment matrix of `data`
    /// (`cols` channels of `n` values each).
    fn learn(data: &[f32], cols: usize, n: usize, rows: usize) -> Result<Self, CnnError> {
        let mut m = nalgebra::DMatrix::<f64>::zeros(cols, cols);
        for i in 0..cols {
            let a = &data[i * n..(i + 1) * n];
            for j in 0..=i {
                let b = &data[j * n..(j + 1) * n];
                let v: f64 = a
                    .iter()
                    .zip(b)
                    .map(|(x, y)| f64::from(*x) * f64::from(*y))
                    .sum();
                m[(i, j)] = v;
                m[(j, i)] = v;
            }
        }
        let trace = m.trace();
        let eig = m.symmetric_eigen();
        let mut order: Vec<usize> = (0..cols).collect();
        order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
        let mut matrix = Vec::with_capacity(rows * cols);
        let mut kept = 0.0;
        for &k in order.iter().take(rows) {
            kept += eig.eigenvalues[k].max(0.0);
            let v = eig.eigenvectors.column(k);
            // Sign fixed (largest component positive), so a projection is reproducible.
            let big = v
                .iter()
                .copied()
                .fold(0.0f64, |a, x| if x.abs() > a.abs() { x } else { a });
            let sign = if big < 0.0 { -1.0 } else { 1.0 };
            matrix.extend(v.iter().map(|x| (x * sign) as f32));
        }
        if matrix.len() != rows * cols || matrix.iter().any(|v| !v.is_finite()) {
            return Err(CnnError::Run(
                "features.cnn.layers[].project: the channel projection is not finite".to_string(),
            ));
        }
        Ok(Self {
            rows,
            cols,
            matrix,
            energy: if trace > 0.0 {
                (kept / trace) as f32
            } else {
                1.0
            },
        })
    }

    /// `out[k] = Σ_c matrix[k][c] · data[c]` over `n` values per channel.
    fn apply(&self, data: &[f32], n: usize, out: &mut Vec<f32>) {
        out.clear();
        out.resize(self.rows * n, 0.0);
        for (k, dst) in out.chunks_exact_mut(n).enumerate() {
            let row = &self.matrix[k * self.cols..(k + 1) * self.cols];
            for (c, &p) in row.iter().enumerate() {
                let src = &data[c * n..(c + 1) * n];
                for (d, s) in dst.iter_mut().zip(src) {
                    *d += p * s;
                }
            }
        }
    }
}

/// The HOG layer of a fused extractor and its buffers.
#[derive(Debug, Clone)]
struct HogLayer {
    cfg: CnnHogConfig,
    hog: Hog,
    patch: Patch,
    feat: FeatureMap,
}

/// Resamples the centred `fraction` of `src` bilinearly (half-pixel centres) onto `dst`
/// (side `dst.side`, planes taken from `src`).
fn resize_centred(
    src: &Patch,
    fraction: f32,
    dst: &mut Patch,
    rows: &mut Vec<Tap>,
    cols: &mut Vec<Tap>,
) {
    let side = dst.side;
    dst.planes = src.planes;
    dst.data.resize(side * side * src.planes, 0.0);
    taps(side, src.side, fraction, rows);
    taps(side, src.side, fraction, cols);
    let n = src.side;
    for p in 0..src.planes {
        let s = src.plane(p);
        let d = &mut dst.data[p * side * side..(p + 1) * side * side];
        for (r, rt) in rows.iter().enumerate() {
            let a = &s[rt.i0 * n..(rt.i0 + 1) * n];
            let b = &s[rt.i1 * n..(rt.i1 + 1) * n];
            for (o, ct) in d[r * side..(r + 1) * side].iter_mut().zip(cols.iter()) {
                let top = (1.0 - ct.w) * a[ct.i0] + ct.w * a[ct.i1];
                let bot = (1.0 - ct.w) * b[ct.i0] + ct.w * b[ct.i1];
                *o = (1.0 - rt.w) * top + rt.w * bot;
            }
        }
    }
}

/// CNN feature extractor over an ONNX model (see the module doc).
pub struct CnnExtractor {
    cfg: Arc<CnnConfig>,
    session: Arc<Mutex<Session>>,
    layers: Vec<LayerInfo>,
    input: Vec<f32>,
    maps: Vec<LayerMap>,
    /// Per layer: its learned projection (layers with `project: N` only).
    proj: Vec<Option<Projection>>,
    /// HOG fused as one more layer (`features.cnn.hog`).
    hog: Option<HogLayer>,
    rows: Vec<Tap>,
    cols: Vec<Tap>,
    tmp: Vec<f32>,
}

impl std::fmt::Debug for CnnExtractor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CnnExtractor")
            .field("model", &self.cfg.model)
            .field("layers", &self.layers)
            .finish()
    }
}

/// Shape of an outlet as a list (−1 = dynamic), or `None` when it is not a tensor.
fn outlet_shape(t: &ort::value::ValueType) -> Option<Vec<i64>> {
    t.tensor_shape().map(|s| s.iter().copied().collect())
}

impl CnnExtractor {
    /// Loads the runtime and the model, checks the input and every configured output, and
    /// runs the network once on a grey image of the configured input size.
    ///
    /// # Errors
    /// A [`CnnError`] naming what is wrong: runtime, model file, input, output names, rank,
    /// channel count, input size, device, or non-finite outputs.
    pub fn new(cfg: &CnnConfig) -> Result<Self, CnnError> {
        let env = load_runtime(&cfg.runtime)?;
        let model = Path::new(&cfg.model);
        if !model.is_file() {
            return Err(CnnError::ModelMissing {
                path: cfg.model.clone(),
            });
        }
        let model_err = |reason: String| CnnError::Model {
            path: cfg.model.clone(),
            reason,
        };
        let builder = Session::builder(&env)
            .map_err(|e| model_err(e.to_string()))?
            .with_optimization_level(GraphOptimizationLevel::All)
            .map_err(|e| model_err(e.to_string()))?
            .with_intra_threads(cfg.intra_threads)
            .map_err(|e| model_err(e.to_string()))?
            .with_inter_threads(1)
            .map_err(|e| model_err(e.to_string()))?;
        let mut builder = match cfg.device {
            CnnDevice::Cpu => builder,
            CnnDevice::Cuda => with_cuda(builder)?,
        };
        let session = builder
            .commit_from_file(model)
            .map_err(|e| model_err(e.to_string()))?;
        Self::check_io(&session, cfg)?;
        let hog = cfg.hog.map(|h| HogLayer {
            hog: Hog::with_colornames(cfg.cell_size, h.grayscale, h.colornames),
            cfg: h,
            patch: Patch::default(),
            feat: FeatureMap::default(),
        });
        let mut ex = Self {
            cfg: Arc::new(cfg.clone()),
            session: Arc::new(Mutex::new(session)),
            layers: Vec::new(),
            input: Vec::new(),
            maps: vec![LayerMap::default(); cfg.layers.len()],
            proj: vec![None; cfg.layers.len()],
            hog,
            rows: Vec::new(),
            cols: Vec::new(),
            tmp: Vec::new(),
        };
        ex.layers = ex.layer_info();
        let side = cfg.input_size;
        let grey = vec![PROBE_GREY; 3 * side * side];
        ex.input = grey.clone();
        ex.run_prepared(side).map_err(|e| match e {
            CnnError::Run(reason) => CnnError::InputSize { size: side, reason },
            other => other,
        })?;
        Ok(ex)
    }

    /// The input name exists and is a `[N, 3, H, W]` tensor whose fixed dimensions agree with
    /// the config; every output exists, is rank 4 and has the configured channel count.
    fn check_io(session: &Session, cfg: &CnnConfig) -> Result<(), CnnError> {
        let names = |o: &[ort::value::Outlet]| {
            o.iter()
                .map(|x| x.name().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        };
        let input = session
            .inputs()
            .iter()
            .find(|i| i.name() == cfg.input)
            .ok_or_else(|| CnnError::Input {
                reason: format!(
                    "the model has no input `{}` (it has: {})",
                    cfg.input,
                    names(session.inputs())
                ),
            })?;
        let shape = outlet_shape(input.dtype()).unwrap_or_default();
        if shape.len() != 4 || !(shape[1] == 3 || shape[1] < 0) {
            return Err(CnnError::Input {
                reason: format!(
                    "input `{}` has shape {shape:?}; expected [N, 3, H, W]",
                    cfg.input
                ),
            });
        }
        let fixed = shape[2] > 0 || shape[3] > 0;
        match cfg.input_size_policy {
            InputSizePolicy::Patch if fixed => {
                return Err(CnnError::InputSize {
                    size: cfg.input_size,
                    reason: format!(
                        "input_size_policy `patch` needs dynamic H and W; the input is {shape:?}"
                    ),
                })
            }
            InputSizePolicy::Fixed
                if fixed
                    && (shape[2] != cfg.input_size as i64 || shape[3] != cfg.input_size as i64) =>
            {
                return Err(CnnError::InputSize {
                    size: cfg.input_size,
                    reason: format!("the model's input is fixed at {shape:?}"),
                })
            }
            _ => {}
        }
        for l in &cfg.layers {
            let out = session
                .outputs()
                .iter()
                .find(|o| o.name() == l.output)
                .ok_or_else(|| CnnError::NoOutput {
                    name: l.output.clone(),
                    available: names(session.outputs()),
                })?;
            let shape = outlet_shape(out.dtype()).unwrap_or_default();
            if shape.len() != 4 {
                return Err(CnnError::Rank {
                    name: l.output.clone(),
                    shape,
                });
            }
            if shape[1] > 0 && shape[1] != l.channels as i64 {
                return Err(CnnError::Channels {
                    name: l.output.clone(),
                    got: shape[1],
                    expected: l.channels,
                });
            }
        }
        Ok(())
    }

    /// The configuration.
    pub fn config(&self) -> &CnnConfig {
        &self.cfg
    }

    /// The layers the tracker sees: the network's (projected channel counts), then HOG.
    fn layer_info(&self) -> Vec<LayerInfo> {
        let mut v: Vec<LayerInfo> = self
            .cfg
            .layers
            .iter()
            .map(|l| LayerInfo {
                name: l.output.clone(),
                channels: l.out_channels(),
                weight: l.weight,
            })
            .collect();
        if let Some(h) = &self.hog {
            v.extend(h.hog.layers().iter().map(|l| LayerInfo {
                weight: h.cfg.weight,
                ..l.clone()
            }));
        }
        v
    }

    /// Channels of the network's layers after projection (HOG excluded).
    fn cnn_channels(&self) -> usize {
        self.cfg.layers.iter().map(|l| l.out_channels()).sum()
    }

    /// Share of layer `l`'s energy its learned projection kept on the patch it was learned
    /// on, or `None` when the layer has no (learned) projection.
    pub fn projection_energy(&self, l: usize) -> Option<f32> {
        self.proj.get(l)?.as_ref().map(|p| p.energy)
    }

    /// Learns every configured projection from the last raw maps (see [`Self::run_prepared`]).
    ///
    /// # Errors
    /// [`CnnError::Run`] when a map is not the network's raw map or the projection is not finite.
    pub fn learn_projections(&mut self) -> Result<(), CnnError> {
        for ((l, map), proj) in self
            .cfg
            .layers
            .iter()
            .zip(&self.maps)
            .zip(self.proj.iter_mut())
        {
            if l.project == 0 {
                continue;
            }
            if map.c != l.channels {
                return Err(CnnError::Run(format!(
                    "layer `{}`: a projection is learned from the network's {} channels, not {}",
                    l.output, l.channels, map.c
                )));
            }
            *proj = Some(Projection::learn(
                &map.data,
                map.c,
                map.h * map.w,
                l.project,
            )?);
        }
        Ok(())
    }

    /// Projects every layer with `project: N` onto its N learned directions (the projection
    /// stage), learning them first from these maps if they are not learned yet.
    ///
    /// # Errors
    /// As [`Self::learn_projections`].
    pub fn project_maps(&mut self) -> Result<(), CnnError> {
        let needs = self
            .cfg
            .layers
            .iter()
            .zip(&self.proj)
            .any(|(l, p)| l.project > 0 && p.is_none());
        if needs {
            self.learn_projections()?;
        }
        for (map, proj) in self.maps.iter_mut().zip(&self.proj) {
            if let Some(p) = proj {
                if map.c == p.cols {
                    p.apply(&map.data, map.h * map.w, &mut self.tmp);
                    std::mem::swap(&mut map.data, &mut self.tmp);
                    map.c = p.rows;
                }
            }
        }
        Ok(())
    }

    /// Runs the network on a raw NCHW input (`[1, 3, side, side]`, already normalised) and
    /// keeps the layers' maps; for checking a model against reference values.
    ///
    /// # Errors
    /// [`CnnError`] for a wrong input length, a runtime failure or bad outputs.
    pub fn run_raw(&mut self, input: &[f32], side: usize) -> Result<(), CnnError> {
        if side == 0 || side > MAX_INPUT_SIZE || input.len() != 3 * side * side {
            return Err(CnnError::Run(format!(
                "input of {} values is not [1, 3, {side}, {side}]",
                input.len()
            )));
        }
        self.input.clear();
        self.input.extend_from_slice(input);
        self.run_prepared(side)
    }

    /// Layer `l`'s last map as `(channels, h, w, values)` (raw after [`Self::run_prepared`],
    /// projected after [`Self::project_maps`]).
    pub fn layer_map(&self, l: usize) -> Option<(usize, usize, usize, &[f32])> {
        let m = self.maps.get(l)?;
        Some((m.c, m.h, m.w, &m.data))
    }

    /// Fills the input tensor from `patch`: plane order, `value_scale`, mean and std (the
    /// preprocessing stage; public for the stage benchmark).
    pub fn prepare_input(&mut self, patch: &Patch) {
        let side = patch.side;
        let n = side * side;
        let c = &self.cfg;
        self.input.resize(3 * n, 0.0);
        let order = match c.channel_order {
            ChannelOrder::Rgb => [0, 1, 2],
            ChannelOrder::Bgr => [2, 1, 0],
        };
        for (p, &src_plane) in order.iter().enumerate() {
            let src = patch.plane(if patch.planes >= 3 { src_plane } else { 0 });
            let (scale, mean, inv_std) = (c.value_scale, c.mean[p], 1.0 / c.std[p]);
            for (d, s) in self.input[p * n..(p + 1) * n].iter_mut().zip(src) {
                *d = (s * scale - mean) * inv_std;
            }
        }
    }

    /// Runs the network on the prepared input (`[1, 3, side, side]`, see
    /// [`Self::prepare_input`]), copies every layer's map, checks shape and finiteness, and
    /// sets each layer's normalisation factor.
    ///
    /// # Errors
    /// [`CnnError`] for a runtime failure or bad outputs.
    pub fn run_prepared(&mut self, side: usize) -> Result<(), CnnError> {
        if side == 0 || self.input.len() != 3 * side * side {
            return Err(CnnError::Run(format!(
                "the prepared input has {} values, not 3·{side}²",
                self.input.len()
            )));
        }
        let Self {
            cfg,
            session,
            input,
            maps,
            ..
        } = self;
        let tensor = TensorRef::from_array_view(([1usize, 3, side, side], &input[..]))
            .map_err(|e| CnnError::Run(e.to_string()))?;
        let mut session = session.lock().unwrap_or_else(PoisonError::into_inner);
        let outputs = session
            .run(ort::inputs![cfg.input.as_str() => tensor])
            .map_err(|e| CnnError::Run(e.to_string()))?;
        for (l, map) in cfg.layers.iter().zip(maps.iter_mut()) {
            let value = outputs
                .get(l.output.as_str())
                .ok_or_else(|| CnnError::NoOutput {
                    name: l.output.clone(),
                    available: String::new(),
                })?;
            let (shape, data) = value
                .try_extract_tensor::<f32>()
                .map_err(|_| CnnError::Rank {
                    name: l.output.clone(),
                    shape: Vec::new(),
                })?;
            let dims: Vec<i64> = shape.iter().copied().collect();
            if dims.len() != 4 || dims[0] != 1 {
                return Err(CnnError::Rank {
                    name: l.output.clone(),
                    shape: dims,
                });
            }
            if dims[1] != l.channels as i64 {
                return Err(CnnError::Channels {
                    name: l.output.clone(),
                    got: dims[1],
                    expected: l.channels,
                });
            }
            if data.iter().any(|v| !v.is_finite()) {
                return Err(CnnError::NonFinite {
                    name: l.output.clone(),
                });
            }
            map.c = l.channels;
            map.h = usize::try_from(dims[2]).unwrap_or(0);
            map.w = usize::try_from(dims[3]).unwrap_or(0);
            if map.h == 0 || map.w == 0 || data.len() != l.channels * map.h * map.w {
                return Err(CnnError::Rank {
                    name: l.output.clone(),
                    shape: dims,
                });
            }
            map.data.clear();
            map.data.extend_from_slice(data);
            map.factor = match l.norm {
                LayerNorm::None => l.gain,
                LayerNorm::Rms => {
                    let ms = map
                        .data
                        .iter()
                        .map(|v| f64::from(*v) * f64::from(*v))
                        .sum::<f64>()
                        / map.data.len() as f64;
                    l.gain / (ms.sqrt() as f32).max(MIN_RMS)
                }
            };
        }
        Ok(())
    }

    /// Runs the network on `patch` and projects its maps.
    fn run_patch(&mut self, patch: &Patch) -> Result<(), CnnError> {
        self.prepare_input(patch);
        self.run_prepared(patch.side)?;
        self.project_maps()
    }

    /// HOG of the centred `fraction` of `patch` at `out`'s grid and `cell`, times its gain,
    /// into `out`'s channels after the network's.
    fn hog_into(
        &mut self,
        patch: &Patch,
        fraction: f32,
        cell: usize,
        out: &mut FeatureMap,
    ) -> Result<(), TrackError> {
        let ch0 = self.cnn_channels();
        let Some(h) = self.hog.as_mut() else {
            return Ok(());
        };
        let side = out.grid.w.max(out.grid.h) * cell;
        if h.patch.side != side {
            h.patch = Patch::new(side, patch.planes);
        }
        resize_centred(
            patch,
            fraction,
            &mut h.patch,
            &mut self.rows,
            &mut self.cols,
        );
        let hc = h.hog.channels();
        if h.feat.grid != out.grid || h.feat.channels != hc {
            h.feat = FeatureMap::new(out.grid, hc);
        }
        h.hog.extract(&h.patch, cell, &mut h.feat)?;
        let n = out.grid.len();
        let dst = out
            .data
            .get_mut(ch0 * n..(ch0 + hc) * n)
            .ok_or_else(|| TrackError::Feature("feature map too small for the HOG layer".into()))?;
        let g = h.cfg.gain;
        for (d, s) in dst.iter_mut().zip(&h.feat.data) {
            *d = g * s;
        }
        Ok(())
    }

    /// Resamples every layer's centred `fraction` of the last maps to `out`'s grid,
    /// channel-stacked, times each layer's normalisation factor (the resampling stage).
    pub fn resample_into(&mut self, fraction: f32, out: &mut FeatureMap) {
        let GridSize { h: gh, w: gw } = out.grid;
        let n = gh * gw;
        let mut ch0 = 0;
        for (map, info) in self.maps.iter().zip(&self.layers) {
            taps(gh, map.h, fraction, &mut self.rows);
            taps(gw, map.w, fraction, &mut self.cols);
            self.tmp.resize(map.w, 0.0);
            let plane = map.h * map.w;
            for c in 0..info.channels.min(map.c) {
                let src = &map.data[c * plane..(c + 1) * plane];
                let dst = &mut out.data[(ch0 + c) * n..(ch0 + c + 1) * n];
                for (r, rt) in self.rows.iter().enumerate() {
                    let a = &src[rt.i0 * map.w..(rt.i0 + 1) * map.w];
                    let b = &src[rt.i1 * map.w..(rt.i1 + 1) * map.w];
                    let (wa, wb) = ((1.0 - rt.w) * map.factor, rt.w * map.factor);
                    for ((t, x), y) in self.tmp.iter_mut().zip(a).zip(b) {
                        *t = wa * x + wb * y;
                    }
                    let row = &mut dst[r * gw..(r + 1) * gw];
                    for (o, ct) in row.iter_mut().zip(&self.cols) {
                        *o = (1.0 - ct.w) * self.tmp[ct.i0] + ct.w * self.tmp[ct.i1];
                    }
                }
            }
            ch0 += info.channels;
        }
    }
}

#[cfg(feature = "cuda")]
fn with_cuda(
    b: ort::session::builder::SessionBuilder,
) -> Result<ort::session::builder::SessionBuilder, CnnError> {
    b.with_execution_providers([ort::ep::CUDA::default().build().error_on_failure()])
        .map_err(|e| CnnError::Device(format!("cannot register the CUDA execution provider: {e}")))
}

#[cfg(not(feature = "cuda"))]
fn with_cuda(
    _b: ort::session::builder::SessionBuilder,
) -> Result<ort::session::builder::SessionBuilder, CnnError> {
    Err(CnnError::Device(
        "`cuda` requested but bevt_core was built without the `cuda` cargo feature".to_string(),
    ))
}

impl FeatureExtractor for CnnExtractor {
    fn layers(&self) -> &[LayerInfo] {
        &self.layers
    }

    fn cell_size(&self) -> usize {
        self.cfg.cell_size
    }

    fn allows_smaller_cells(&self) -> bool {
        false
    }

    fn input_side(&self, patch_side: usize) -> usize {
        match self.cfg.input_size_policy {
            InputSizePolicy::Fixed => self.cfg.input_size,
            InputSizePolicy::Patch => patch_side.min(MAX_INPUT_SIZE),
        }
    }

    fn single_pass_scales(&self) -> bool {
        self.cfg.single_pass_scales
    }

    fn train_from_detection(&self) -> bool {
        self.cfg.train_from_detection
    }

    fn set_input_planes(&mut self, planes: usize) {
        if let Some(h) = self.hog.as_mut() {
            h.hog.set_input_planes(planes);
        }
        self.layers = self.layer_info();
    }

    fn learns_per_track(&self) -> bool {
        self.cfg.layers.iter().any(|l| l.project > 0)
    }

    fn begin_track(&mut self, patch: &Patch) -> Result<(), TrackError> {
        if !self.learns_per_track() {
            return Ok(());
        }
        self.prepare_input(patch);
        self.run_prepared(patch.side)?;
        self.learn_projections()?;
        Ok(())
    }

    fn extract_scales(
        &mut self,
        patch: &Patch,
        fractions: &[f32],
        outs: &mut [&mut FeatureMap],
    ) -> Result<(), TrackError> {
        self.run_patch(patch)?;
        for (f, out) in fractions.iter().zip(outs.iter_mut()) {
            let f = f.clamp(f32::MIN_POSITIVE, 1.0);
            self.resample_into(f, out);
            let cell = self.cfg.cell_size;
            self.hog_into(patch, f, cell, out)?;
        }
        Ok(())
    }

    fn extract(
        &mut self,
        patch: &Patch,
        cell: usize,
        out: &mut FeatureMap,
    ) -> Result<(), TrackError> {
        if out.channels != self.channels() || out.data.len() != out.grid.len() * out.channels {
            return Err(TrackError::Feature(format!(
                "feature map has {} channels, the CNN layers give {}",
                out.channels,
                self.channels()
            )));
        }
        self.run_patch(patch)?;
        self.resample_into(1.0, out);
        self.hog_into(patch, 1.0, cell, out)
    }

    fn boxed_clone(&self) -> Box<dyn FeatureExtractor> {
        Box::new(Self {
            cfg: Arc::clone(&self.cfg),
            session: Arc::clone(&self.session),
            layers: self.layers.clone(),
            input: Vec::new(),
            maps: self.maps.clone(),
            proj: self.proj.clone(),
            hog: self.hog.clone(),
            rows: Vec::new(),
            cols: Vec::new(),
            tmp: Vec::new(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn taps_of_the_full_fraction_follow_half_pixel_centres() {
        let mut t = Vec::new();
        taps(4, 2, 1.0, &mut t);
        // Output centres at 0.125, 0.375, 0.625, 0.875 of the source: x = u·2 − 0.5.
        assert_eq!((t[0].i0, t[0].i1, t[0].w), (0, 1, 0.0));
        assert_eq!((t[1].i0, t[1].i1), (0, 1));
        assert!((t[1].w - 0.25).abs() < 1e-6);
        assert_eq!((t[3].i0, t[3].i1, t[3].w), (1, 1, 0.0));
    }

    #[test]
    fn taps_of_a_fraction_stay_centred() {
        let mut t = Vec::new();
        taps(3, 9, 1.0 / 3.0, &mut t);
        // The middle third of 9 cells is cells 3..6; its centres are 3, 4, 5.
        let xs: Vec<f32> = t.iter().map(|t| t.i0 as f32 + t.w).collect();
        for (x, e) in xs.iter().zip([3.0, 4.0, 5.0]) {
            assert!((x - e).abs() < 1e-5, "{xs:?}");
        }
    }

    #[test]
    fn no_runtime_is_an_error_not_a_panic() {
        let e = load_runtime("/nonexistent/libonnxruntime.so.1.31.1").unwrap_err();
        assert!(matches!(e, CnnError::RuntimeMissing { .. }), "{e}");
    }
}
