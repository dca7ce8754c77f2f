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
//! from one network pass on the largest scale's patch.

use crate::error::TrackError;
use crate::features::cnn_config::{
    ChannelOrder, CnnConfig, CnnDevice, InputSizePolicy, LayerNorm, MAX_INPUT_SIZE,
};
use crate::features::{FeatureExtractor, FeatureMap, LayerInfo};
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

/// One layer's last map, as returned by the network.
#[derive(Debug, Clone, Default)]
struct LayerMap {
    h: usize,
    w: usize,
    data: Vec<f32>,
    /// Multiplier applied while resampling (gain over RMS, or gain).
    factor: f32,
}

/// CNN feature extractor over an ONNX model (see the module doc).
pub struct CnnExtractor {
    cfg: Arc<CnnConfig>,
    session: Arc<Mutex<Session>>,
    layers: Vec<LayerInfo>,
    input: Vec<f32>,
    maps: Vec<LayerMap>,
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
        let layers = cfg
            .layers
            .iter()
            .map(|l| LayerInfo {
                name: l.output.clone(),
                channels: l.channels,
                weight: l.weight,
            })
            .collect();
        let mut ex = Self {
            cfg: Arc::new(cfg.clone()),
            session: Arc::new(Mutex::new(session)),
            layers,
            input: Vec::new(),
            maps: vec![LayerMap::default(); cfg.layers.len()],
            rows: Vec::new(),
            cols: Vec::new(),
            tmp: Vec::new(),
        };
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

    /// Layer `l`'s last raw map as `(channels, h, w, values)`.
    pub fn layer_map(&self, l: usize) -> Option<(usize, usize, usize, &[f32])> {
        let m = self.maps.get(l)?;
        let c = self.layers.get(l)?.channels;
        Some((c, m.h, m.w, &m.data))
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

    /// Runs the network on `patch`.
    fn run_patch(&mut self, patch: &Patch) -> Result<(), CnnError> {
        self.prepare_input(patch);
        self.run_prepared(patch.side)
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
            for c in 0..info.channels {
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

    fn extract_scales(
        &mut self,
        patch: &Patch,
        fractions: &[f32],
        outs: &mut [&mut FeatureMap],
    ) -> Result<(), TrackError> {
        self.run_patch(patch)?;
        for (f, out) in fractions.iter().zip(outs.iter_mut()) {
            self.resample_into(f.clamp(f32::MIN_POSITIVE, 1.0), out);
        }
        Ok(())
    }

    fn extract(
        &mut self,
        patch: &Patch,
        _cell: usize,
        out: &mut FeatureMap,
    ) -> Result<(), TrackError> {
        self.run_patch(patch)?;
        self.resample_into(1.0, out);
        Ok(())
    }

    fn boxed_clone(&self) -> Box<dyn FeatureExtractor> {
        Box::new(Self {
            cfg: Arc::clone(&self.cfg),
            session: Arc::clone(&self.session),
            layers: self.layers.clone(),
            input: Vec::new(),
            maps: self.maps.clone(),
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
