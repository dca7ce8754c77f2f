//! NanoTrack v2 as a learned re-detection verifier (`redetection.verifier: nanotrack`),
//! run in pure Rust by [`crate::nn`] (no ONNX Runtime, no cargo feature).
//!
//! The tracking-trained Siamese network scores a search region against a template taken on
//! the initial frame: the backbone turns a 127×127 template crop (context side
//! `sz = √((w+p)(h+p))`, `p = (w+h)/2`, as OpenCV's `TrackerNano` crops) into `[1,48,8,8]`
//! and a 255×255 search crop (side `2·sz`) into `[1,48,16,16]`; the head returns
//! classification logits `[1,2,16,16]` (background, foreground) and box distances
//! `[1,4,16,16]` (left, top, right, bottom in crop pixels from grid point
//! `(j − 8)·16 + 127`). A region's hit is the grid point with the largest foreground logit
//! margin (no cosine window: the whole frame is searched), with its regressed box. Crops
//! are the region resized bilinearly, as OpenCV's `resize(INTER_LINEAR)` makes NanoTrack's
//! training crops and `TrackerNano`'s ([`crate::image::sample_bilinear`]; RGB planes, raw
//! 0–255; grey frames are replicated into the three planes; outside the frame the border is
//! replicated, where `TrackerNano` fills with the mean colour).
//!
//! The models: empty `redetection.verifier_backbone` / `verifier_head` mean the NanoTrack v2
//! files embedded in this crate (`models/nanotrack/`, see its README for origin, licence and
//! sha256), so the default needs no file at run time; a path loads that file instead. Each
//! network is planned once per input size (backbone: 127 and 255) and run single-threaded.
//! The head is planned as its two branches, each alone: the classification branch (the
//! scores) and the box regression branch. They share no node after the inputs, so together
//! they compute what the whole head does, bit for bit (tested); a search that needs only the
//! score ([`Verifier::search_above`]: the drift check, a lost-state window below the bar)
//! skips the regression branch, about half the head.
//!
//! With the cargo feature `cnn`, `redetection.verifier: nanotrack_ort` runs the same models
//! (same crops, scoring and acceptance) on ONNX Runtime instead (`NanoVerifier::new_ort`),
//! one thread (docs/benchmarks.md has the per-pass figures), at the price of the shared
//! library.

use crate::error::TrackError;
use crate::geometry::Point2;
use crate::image::{sample_bilinear, Frame, Patch};
use crate::nn;
use crate::redetect::{context_side, Scored, Verifier, VerifierHit};
use std::path::Path;
use std::sync::{Arc, Mutex, OnceLock, PoisonError};
use thiserror::Error;

/// Template crop side, pixels.
pub const TEMPLATE_SIDE: usize = 127;
/// Search crop side, pixels.
pub const SEARCH_SIDE: usize = 255;
/// Feature channels of the backbone.
pub const CHANNELS: usize = 48;
/// Template feature side (127 / 16).
pub const TEMPLATE_CELLS: usize = 8;
/// Search feature and score-map side (255 / 16).
pub const SEARCH_CELLS: usize = 16;
/// Backbone stride, crop pixels.
const STRIDE: f32 = 16.0;
/// Crop coordinate of grid point 8 (the crop centre as NanoTrack counts it).
const GRID_CENTRE: f32 = 127.0;
/// Largest model file read from disk (the shipped ones are 1.0 and 0.7 MB).
pub const MAX_MODEL_BYTES: u64 = 64 << 20;

/// The embedded NanoTrack v2 backbone (`models/nanotrack/nanotrackv2_backbone_sim_dyn.onnx`).
static EMBEDDED_BACKBONE: &[u8] =
    include_bytes!("../../../models/nanotrack/nanotrackv2_backbone_sim_dyn.onnx");
/// The embedded NanoTrack v2 head (`models/nanotrack/nanotrackv2_head_sim.onnx`).
static EMBEDDED_HEAD: &[u8] = include_bytes!("../../../models/nanotrack/nanotrackv2_head_sim.onnx");

/// Name of an embedded model in messages.
const EMBEDDED: &str = "<embedded NanoTrack v2>";

/// What can be wrong with the verifier's models; each message names the config key.
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum NanoError {
    /// The model file does not exist.
    #[error("{key}: {path}: no such file")]
    ModelMissing {
        /// Config key (`redetection.verifier_backbone` or `verifier_head`).
        key: &'static str,
        /// The path.
        path: String,
    },
    /// The file could not be read or is too large.
    #[error("{key}: cannot read {path}: {reason}")]
    Read {
        /// Config key.
        key: &'static str,
        /// The path.
        path: String,
        /// Why.
        reason: String,
    },
    /// The file is not an ONNX model this verifier can run (parse or analysis failed, a
    /// named input or output is missing, or an input of the expected shape is refused).
    #[error("{key}: {path} is not a usable NanoTrack v2 ONNX model: {reason}")]
    Model {
        /// Config key.
        key: &'static str,
        /// The path (or the embedded model's name).
        path: String,
        /// Parser / optimiser message.
        reason: String,
    },
    /// An output has another shape than NanoTrack v2's.
    #[error("{key}: {path}: output `{name}` has shape {shape:?}; expected {expected:?}")]
    Shape {
        /// Config key.
        key: &'static str,
        /// The path.
        path: String,
        /// Output name.
        name: &'static str,
        /// Its shape.
        shape: Vec<usize>,
        /// NanoTrack v2's.
        expected: Vec<usize>,
    },
    /// An output contains NaN or infinity.
    #[error("{key}: {path}: output `{name}` contains a non-finite value (NaN or infinity)")]
    NonFinite {
        /// Config key.
        key: &'static str,
        /// The path.
        path: String,
        /// Output name.
        name: &'static str,
    },
    /// ONNX Runtime could not be loaded (`nanotrack_ort` only).
    #[error("redetection.verifier: nanotrack_ort: {0}")]
    Runtime(String),
    /// Inference failed.
    #[error("{key}: {path}: inference failed: {reason}")]
    Run {
        /// Config key.
        key: &'static str,
        /// The path.
        path: String,
        /// Runtime message.
        reason: String,
    },
}

impl From<NanoError> for TrackError {
    fn from(e: NanoError) -> Self {
        TrackError::Feature(format!("redetection.verifier: {e}"))
    }
}

/// Config key of the backbone path.
const BACKBONE_KEY: &str = "redetection.verifier_backbone";
/// Config key of the head path.
const HEAD_KEY: &str = "redetection.verifier_head";

/// One planned network and where it came from (shared between verifiers).
struct Planned {
    plan: Arc<nn::Plan>,
    key: &'static str,
    path: String,
}

/// The planned networks of one (backbone, head) pair: the backbone at both input sizes
/// and the head's two branches (see the module doc).
struct Plans {
    template: Planned,
    search: Planned,
    cls: Planned,
    reg: Planned,
    /// The parsed models, for planning other search sizes on first use.
    models: Models,
    /// Backbone and head plans for search maps of other sides than 16 cells
    /// ([`NanoVerifier::score_maps_sized`]), planned on first use and shared.
    sized: Mutex<Vec<(usize, Arc<SizedPlans>)>>,
}

/// The parsed backbone and head and the names they go by.
struct Models {
    backbone: nn::onnx::Model,
    backbone_name: String,
    head: nn::onnx::Model,
    head_name: String,
}

/// The backbone for a `16·cells − 1` pixel search crop and the head's two branches on its
/// `cells × cells` features.
struct SizedPlans {
    search: Planned,
    cls: Planned,
    reg: Planned,
    /// Both branches computed only for the [`CENTRE_RADIUS`] window around the map's centre
    /// ([`nn::window`]); `None` for a head that cannot be windowed (the whole maps then).
    centre: Option<(Planned, Planned)>,
}

/// The grid points around a search map's centre that [`NanoVerifier::centre_maps_sized`]
/// computes: `(2·CENTRE_RADIUS + 1)²`, those `crate::box_refine` reads at the filter's
/// position.
pub const CENTRE_RADIUS: usize = 1;

/// Largest side, in grid points, of the sized search maps (a 511-pixel crop): the plans'
/// buffers stay within a few tens of MB whatever the configuration asks.
pub const MAX_SIZED_CELLS: usize = 32;

impl Plans {
    /// The plans for search maps of `cells × cells` (planned once per process and size).
    fn sized(&self, cells: usize) -> Result<Arc<SizedPlans>, NanoError> {
        let mut cache = self.sized.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some((_, p)) = cache.iter().find(|(c, _)| *c == cells) {
            return Ok(Arc::clone(p));
        }
        let m = &self.models;
        let side = STRIDE_PX * cells - 1;
        let search = Planned::new(
            &m.backbone,
            BACKBONE_KEY,
            &m.backbone_name,
            &[("input", &[1, 3, side, side])],
            &["output"],
        )?;
        let t = TEMPLATE_CELLS;
        let head = head_for_cells(&m.head, cells);
        let head_plan = |outputs: &[&str]| {
            Planned::new(
                &head,
                HEAD_KEY,
                &m.head_name,
                &[
                    ("input1", &[1, CHANNELS, t, t]),
                    ("input2", &[1, CHANNELS, cells, cells]),
                ],
                outputs,
            )
        };
        // The centre window of both branches, when the head's layers after its channel
        // attention are local (NanoTrack v2's are) and the window needs them whole before
        // the attention. Any planning error of the windowed graphs falls back to the whole
        // maps: they are an optimisation, never a requirement.
        let c = cells / 2;
        let span = nn::window::Span {
            lo: c.saturating_sub(CENTRE_RADIUS),
            hi: c + CENTRE_RADIUS,
        };
        let side = 2 * CENTRE_RADIUS + 1;
        let windowed = |output: &'static str, planes: usize| {
            let w = nn::window::windowed(&head, output, cells, span)?;
            let inputs: [(&str, &[usize]); 2] = [
                ("input1", &[1, CHANNELS, t, t]),
                ("input2", &[1, CHANNELS, cells, cells]),
            ];
            let p = Planned::new(&w, HEAD_KEY, &m.head_name, &inputs, &[output]).ok()?;
            // Another head whose window plans to other shapes than the maps' would fail
            // every run: it gets the whole maps instead.
            let want: &[usize] = &[1, planes, side, side];
            p.plan.output_shapes().eq([want]).then_some(p)
        };
        let centre = windowed("output1", 2).zip(windowed("output2", 4));
        let p = Arc::new(SizedPlans {
            search,
            cls: head_plan(&["output1"])?,
            reg: head_plan(&["output2"])?,
            centre,
        });
        // A process uses one or two sizes; the bound keeps a misuse from growing it.
        if cache.len() >= MAX_CACHED_PLANS {
            cache.remove(0);
        }
        cache.push((cells, Arc::clone(&p)));
        Ok(p)
    }
}

/// NanoTrack v2's head for `cells × cells` search features. The head is convolutional
/// but for two things its ONNX file fixes to 16×16: the declared shape of `input2` and the
/// shape `[1, −1, 16, 16]` its pixel-wise correlations are reshaped to. Both are given
/// `cells` here; every other node works on any size (its channel attention pools over
/// whatever map it gets). Another model is returned unchanged and fails to plan if it
/// cannot take the size.
fn head_for_cells(head: &nn::onnx::Model, cells: usize) -> nn::onnx::Model {
    let mut h = head.clone();
    let side = SEARCH_CELLS as i64;
    for t in h.initializers.values_mut() {
        if let nn::onnx::Data::I64(v) = &mut t.data {
            if v.as_slice() == [1, -1, side, side] {
                v[2] = cells as i64;
                v[3] = cells as i64;
            }
        }
    }
    for i in h.inputs.iter_mut().filter(|i| i.name == "input2") {
        if let [_, _, hh, ww] = i.dims.as_mut_slice() {
            *hh = Some(cells);
            *ww = Some(cells);
        }
    }
    h
}

/// The backbone's stride in crop pixels: a `16·n − 1` pixel crop gives `n × n` features
/// whose grid point `j` sits at crop pixel `16·j − 1` (NanoTrack's 255 → 16 and 127 → 8).
const STRIDE_PX: usize = 16;

/// Run buffers for one [`SizedPlans`].
struct SizedNets {
    cells: usize,
    search: Net,
    cls: Net,
    reg: Net,
    /// The centre window's branches (see [`SizedPlans`]).
    centre: Option<(Net, Net)>,
}

/// Plans by `(verifier_backbone, verifier_head)` as configured (empty: embedded). Every
/// tracker of the process (each sequence of an evaluation, each node restart of the
/// tracker) shares them and keeps only its own buffers. A model file is therefore read
/// once per process and path.
type PlanCache = Mutex<Vec<((String, String), Arc<Plans>)>>;

/// The process's [`PlanCache`].
fn plan_cache() -> &'static PlanCache {
    static CACHE: OnceLock<PlanCache> = OnceLock::new();
    CACHE.get_or_init(|| Mutex::new(Vec::new()))
}

/// At most this many (backbone, head) pairs stay planned (a process uses one).
const MAX_CACHED_PLANS: usize = 4;

/// One planned network: its buffers, and where it came from.
struct Net {
    runner: nn::Runner,
    key: &'static str,
    path: String,
}

impl Net {
    /// Buffers for `p`.
    fn new(p: &Planned) -> Self {
        Self {
            runner: nn::Runner::new(Arc::clone(&p.plan)),
            key: p.key,
            path: p.path.clone(),
        }
    }
}

impl Planned {
    /// Plans `model` for `inputs` (names and shapes) and `outputs` (names).
    fn new(
        model: &nn::onnx::Model,
        key: &'static str,
        path: &str,
        inputs: &[(&str, &[usize])],
        outputs: &[&str],
    ) -> Result<Self, NanoError> {
        let plan = nn::Plan::new(model, inputs, outputs).map_err(|reason| NanoError::Model {
            key,
            path: path.to_string(),
            reason,
        })?;
        Ok(Self {
            plan: Arc::new(plan),
            key,
            path: path.to_string(),
        })
    }
}

impl Net {
    /// Runs on `inputs` (`(shape, data)`), returning each output's data checked against
    /// `expected` (`(name, shape)`) and for finite values.
    fn run(
        &mut self,
        inputs: &[(&[usize], &[f32])],
        expected: &[(&'static str, &[usize])],
    ) -> Result<Vec<Vec<f32>>, NanoError> {
        self.check_shapes(expected)?;
        let data: Vec<&[f32]> = inputs.iter().map(|(_, d)| *d).collect();
        let outputs = self.runner.run(&data).map_err(|reason| NanoError::Run {
            key: self.key,
            path: self.path.clone(),
            reason,
        })?;
        Self::finite(self.key, &self.path, &outputs, expected)
    }

    /// [`Self::run`] on a network of one input, lent to it instead of copied into it
    /// ([`nn::Runner::run_exchanging`]): `input` is given back unchanged.
    fn run_lending(
        &mut self,
        input: &mut Vec<f32>,
        expected: &[(&'static str, &[usize])],
    ) -> Result<Vec<Vec<f32>>, NanoError> {
        self.check_shapes(expected)?;
        let outputs = self
            .runner
            .run_exchanging(input)
            .map_err(|reason| NanoError::Run {
                key: self.key,
                path: self.path.clone(),
                reason,
            })?;
        Self::finite(self.key, &self.path, &outputs, expected)
    }

    /// The plan's output shapes against `expected`, checked before a run.
    fn check_shapes(&self, expected: &[(&'static str, &[usize])]) -> Result<(), NanoError> {
        let shapes = self.runner.plan().output_shapes();
        if shapes.len() != expected.len() {
            return Err(NanoError::Run {
                key: self.key,
                path: self.path.clone(),
                reason: format!("{} outputs; expected {}", shapes.len(), expected.len()),
            });
        }
        for (shape, &(name, want)) in shapes.zip(expected) {
            if shape != want {
                return Err(NanoError::Shape {
                    key: self.key,
                    path: self.path.clone(),
                    name,
                    shape: shape.to_vec(),
                    expected: want.to_vec(),
                });
            }
        }
        Ok(())
    }

    /// Each output copied out, refused when a value is not finite.
    fn finite(
        key: &'static str,
        path: &str,
        outputs: &[&[f32]],
        expected: &[(&'static str, &[usize])],
    ) -> Result<Vec<Vec<f32>>, NanoError> {
        let mut out = Vec::with_capacity(expected.len());
        for (value, &(name, _)) in outputs.iter().zip(expected) {
            if value.iter().any(|v| !v.is_finite()) {
                return Err(NanoError::NonFinite {
                    key,
                    path: path.to_string(),
                    name,
                });
            }
            out.push(value.to_vec());
        }
        Ok(out)
    }
}

/// The ONNX model at `path` (empty: `embedded`), parsed, and the name it goes by.
fn load(
    key: &'static str,
    path: &str,
    embedded: &'static [u8],
) -> Result<(nn::onnx::Model, String), NanoError> {
    let (bytes, name) = if path.is_empty() {
        (std::borrow::Cow::Borrowed(embedded), EMBEDDED.to_string())
    } else {
        let p = Path::new(path);
        if !p.is_file() {
            return Err(NanoError::ModelMissing {
                key,
                path: path.to_string(),
            });
        }
        let read_err = |reason: String| NanoError::Read {
            key,
            path: path.to_string(),
            reason,
        };
        let len = std::fs::metadata(p)
            .map_err(|e| read_err(e.to_string()))?
            .len();
        if len > MAX_MODEL_BYTES {
            return Err(read_err(format!(
                "{len} bytes; at most {MAX_MODEL_BYTES} accepted"
            )));
        }
        let bytes = std::fs::read(p).map_err(|e| read_err(e.to_string()))?;
        (std::borrow::Cow::Owned(bytes), path.to_string())
    };
    let model = nn::onnx::parse(&bytes).map_err(|reason| NanoError::Model {
        key,
        path: name.clone(),
        reason,
    })?;
    Ok((model, name))
}

/// The networks' runtime.
enum Backend {
    /// [`nn`] plans: backbone at 127 and at 255, the head's two branches.
    Native {
        template: Box<Net>,
        search: Box<Net>,
        cls: Box<Net>,
        reg: Box<Net>,
        /// The plans (for [`Plans::sized`]).
        plans: Arc<Plans>,
        /// Buffers for the last other search size asked for.
        sized: Option<Box<SizedNets>>,
    },
    /// ONNX Runtime sessions (cargo feature `cnn`).
    #[cfg(feature = "cnn")]
    Ort(Box<ort_backend::OrtNets>),
}

impl Backend {
    /// Where the backbone and the head came from.
    fn paths(&self) -> (&str, &str) {
        match self {
            Backend::Native { search, cls, .. } => (&search.path, &cls.path),
            #[cfg(feature = "cnn")]
            Backend::Ort(o) => (&o.backbone_path, &o.head_path),
        }
    }
}

/// One network's node times ([`NanoVerifier::node_times`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NetTimes {
    /// `template`, `search`, `cls`, `reg`, or those of the last other search size (`search
    /// at N cells`, …, and its centre window's `cls at N cells, centre`, …).
    pub name: String,
    /// Runs since the timing started.
    pub runs: u64,
    /// Per node in plan order: what it computes, and its time over those runs (ns).
    pub nodes: Vec<(String, u64)>,
}

/// NanoTrack v2 backbone + head (see the module doc).
pub struct NanoVerifier {
    backend: Backend,
    template: Vec<f32>,
    input: Vec<f32>,
    search: Vec<f32>,
    patch: Patch,
}

impl std::fmt::Debug for NanoVerifier {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NanoVerifier")
            .field("backbone", &self.backend.paths().0)
            .field("head", &self.backend.paths().1)
            .field("template", &!self.template.is_empty())
            .finish()
    }
}

impl NanoVerifier {
    /// The native networks, named: `template`, `search`, `cls`, `reg`, and those of the last
    /// other search size (`… at N cells`, its centre window's branches `…, centre`). None on
    /// ONNX Runtime.
    fn native_nets(&mut self) -> Vec<(String, &mut Net)> {
        let (template, search, cls, reg, sized) = match &mut self.backend {
            Backend::Native {
                template,
                search,
                cls,
                reg,
                sized,
                ..
            } => (template, search, cls, reg, sized),
            #[cfg(feature = "cnn")]
            Backend::Ort(_) => return Vec::new(),
        };
        let mut nets = vec![
            ("template".to_string(), &mut **template),
            ("search".to_string(), &mut **search),
            ("cls".to_string(), &mut **cls),
            ("reg".to_string(), &mut **reg),
        ];
        if let Some(z) = sized {
            let c = z.cells;
            nets.push((format!("search at {c} cells"), &mut z.search));
            nets.push((format!("cls at {c} cells"), &mut z.cls));
            nets.push((format!("reg at {c} cells"), &mut z.reg));
            if let Some((cls, reg)) = &mut z.centre {
                nets.push((format!("cls at {c} cells, centre"), cls));
                nets.push((format!("reg at {c} cells, centre"), reg));
            }
        }
        nets
    }

    /// Starts timing every node of the native networks' runs from now on (from zero), or
    /// stops ([`nn::Runner::time_steps`]): a diagnostic, off by default. It applies to the
    /// networks built so far: those of a search size first asked for later start untimed.
    pub fn time_nodes(&mut self, on: bool) {
        for (_, net) in self.native_nets() {
            net.runner.time_steps(on);
        }
    }

    /// Per native network its node times ([`NetTimes`]). Empty on ONNX Runtime; no nodes
    /// while not timing.
    pub fn node_times(&mut self) -> Vec<NetTimes> {
        self.native_nets()
            .into_iter()
            .map(|(name, net)| {
                let (runs, nodes) = net.runner.step_times();
                NetTimes { name, runs, nodes }
            })
            .collect()
    }

    /// Loads both models (an empty path: the embedded NanoTrack v2 file), optimises the
    /// backbone for 127×127 and 255×255 inputs and the head, and checks them on a grey
    /// template and search crop — once per process and `(backbone, head)`: later verifiers
    /// share the optimised plans (a model file is read once per process and path) and only make their own run states.
    ///
    /// # Errors
    /// A [`NanoError`] naming the key and the model problem.
    pub fn new(backbone: &str, head: &str) -> Result<Self, NanoError> {
        let id = (backbone.to_string(), head.to_string());
        let cached = plan_cache()
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .iter()
            .find(|(k, _)| *k == id)
            .map(|(_, p)| Arc::clone(p));
        if let Some(plans) = cached {
            // Checked when they were first optimised.
            return Ok(Self::on(Self::native_backend(&plans)));
        }
        let plans = Arc::new(Self::optimise(backbone, head)?);
        let v = Self::checked(Self::native_backend(&plans))?;
        let mut cache = plan_cache().lock().unwrap_or_else(PoisonError::into_inner);
        if !cache.iter().any(|(k, _)| *k == id) {
            if cache.len() >= MAX_CACHED_PLANS {
                cache.remove(0);
            }
            cache.push((id, plans));
        }
        Ok(v)
    }

    /// Loads both models and optimises the backbone for 127×127 and 255×255 inputs and the
    /// head.
    fn optimise(backbone: &str, head: &str) -> Result<Plans, NanoError> {
        let (bb, bb_name) = load(BACKBONE_KEY, backbone, EMBEDDED_BACKBONE)?;
        let (hd, hd_name) = load(HEAD_KEY, head, EMBEDDED_HEAD)?;
        let backbone_plan = |side: usize| {
            Planned::new(
                &bb,
                BACKBONE_KEY,
                &bb_name,
                &[("input", &[1, 3, side, side])],
                &["output"],
            )
        };
        let template = backbone_plan(TEMPLATE_SIDE)?;
        let search = backbone_plan(SEARCH_SIDE)?;
        let (t, x) = (TEMPLATE_CELLS, SEARCH_CELLS);
        let head_plan = |outputs: &[&str]| {
            Planned::new(
                &hd,
                HEAD_KEY,
                &hd_name,
                &[
                    ("input1", &[1, CHANNELS, t, t]),
                    ("input2", &[1, CHANNELS, x, x]),
                ],
                outputs,
            )
        };
        let (cls, reg) = (head_plan(&["output1"])?, head_plan(&["output2"])?);
        Ok(Plans {
            template,
            search,
            cls,
            reg,
            models: Models {
                backbone: bb,
                backbone_name: bb_name,
                head: hd,
                head_name: hd_name,
            },
            sized: Mutex::new(Vec::new()),
        })
    }

    /// Fresh buffers for `plans`.
    fn native_backend(plans: &Arc<Plans>) -> Backend {
        Backend::Native {
            template: Box::new(Net::new(&plans.template)),
            search: Box::new(Net::new(&plans.search)),
            cls: Box::new(Net::new(&plans.cls)),
            reg: Box::new(Net::new(&plans.reg)),
            plans: Arc::clone(plans),
            sized: None,
        }
    }

    /// The same models on ONNX Runtime (`runtime`, or `ORT_DYLIB_PATH` when empty; an empty
    /// model path: the embedded file), one thread, all graph optimisations.
    ///
    /// # Errors
    /// A [`NanoError`] naming the runtime or model problem.
    #[cfg(feature = "cnn")]
    pub fn new_ort(runtime: &str, backbone: &str, head: &str) -> Result<Self, NanoError> {
        let nets = ort_backend::OrtNets::new(runtime, backbone, head)?;
        Self::checked(Backend::Ort(Box::new(nets)))
    }

    /// The verifier on `backend`, without a template.
    fn on(backend: Backend) -> Self {
        Self {
            backend,
            template: Vec::new(),
            input: Vec::new(),
            search: Vec::new(),
            patch: Patch::default(),
        }
    }

    /// The verifier on `backend`, checked on a grey template and search crop.
    fn checked(backend: Backend) -> Result<Self, NanoError> {
        let mut v = Self::on(backend);
        v.input = vec![128.0; 3 * TEMPLATE_SIDE * TEMPLATE_SIDE];
        v.template = v.run_backbone(TEMPLATE_SIDE)?;
        v.input = vec![128.0; 3 * SEARCH_SIDE * SEARCH_SIDE];
        v.search = v.run_backbone(SEARCH_SIDE)?;
        v.run_head()?;
        v.template.clear();
        Ok(v)
    }

    /// The backbone on `input`, a `[1,3,side,side]` RGB tensor (raw 0–255), `side` 127 or
    /// 255: the `[1,48,side/16,side/16]` features (for tests and benchmarks).
    ///
    /// # Errors
    /// [`NanoError::Run`] for another side or input length, or an output error.
    pub fn backbone(&mut self, input: &[f32], side: usize) -> Result<Vec<f32>, NanoError> {
        if (side != TEMPLATE_SIDE && side != SEARCH_SIDE) || input.len() != 3 * side * side {
            return Err(NanoError::Run {
                key: BACKBONE_KEY,
                path: self.backend.paths().0.to_string(),
                reason: format!(
                    "input of {} values for side {side}; sides 127 and 255 are planned",
                    input.len()
                ),
            });
        }
        self.input.clear();
        self.input.extend_from_slice(input);
        self.run_backbone(side)
    }

    /// The head on a template feature `[1,48,8,8]` and a search feature `[1,48,16,16]`:
    /// per grid point the foreground logit margin and the four box distances,
    /// `(margins[256], loc[4·256])` (for tests and benchmarks).
    ///
    /// # Errors
    /// [`NanoError::Run`] for wrong lengths, or an output error.
    pub fn head(
        &mut self,
        template: &[f32],
        search: &[f32],
    ) -> Result<(Vec<f32>, Vec<f32>), NanoError> {
        let (t, x) = (TEMPLATE_CELLS, SEARCH_CELLS);
        if template.len() != CHANNELS * t * t || search.len() != CHANNELS * x * x {
            return Err(NanoError::Run {
                key: HEAD_KEY,
                path: self.backend.paths().1.to_string(),
                reason: format!(
                    "features of {} and {} values; expected {} and {}",
                    template.len(),
                    search.len(),
                    CHANNELS * t * t,
                    CHANNELS * x * x
                ),
            });
        }
        let (kept_t, kept_s) = (
            std::mem::replace(&mut self.template, template.to_vec()),
            std::mem::replace(&mut self.search, search.to_vec()),
        );
        let r = self.run_head();
        self.template = kept_t;
        self.search = kept_s;
        r
    }

    /// Samples the square of side `region` at `center` into `self.input` (`out`², RGB).
    fn crop(&mut self, frame: &Frame<'_>, center: Point2, region: f32, out: usize) {
        let planes = frame.format().planes();
        if self.patch.side != out || self.patch.planes != planes {
            self.patch = Patch::new(out, planes);
        }
        // OpenCV's INTER_LINEAR resize of the region, as NanoTrack's training crops were
        // made: reads four pixels per output pixel, where the sampler's box average read the
        // whole region (6.6 % of the tracking thread on large targets against 3.4 %).
        sample_bilinear(frame, center, region, &mut self.patch);
        let n = out * out;
        if planes == 3 {
            // The patch's three planes are the input as it is: exchanged, not copied (the
            // patch's next crop writes every value of the buffer it gets back).
            std::mem::swap(&mut self.input, &mut self.patch.data);
            return;
        }
        self.input.resize(3 * n, 0.0);
        for p in 0..3 {
            let src = self.patch.plane(if planes >= 3 { p } else { 0 });
            self.input[p * n..(p + 1) * n].copy_from_slice(src);
        }
    }

    /// Backbone on `self.input` (`[1,3,side,side]`, side 127 or 255): the
    /// `[1,48,side/16,side/16]` features.
    fn run_backbone(&mut self, side: usize) -> Result<Vec<f32>, NanoError> {
        let (template, search) = match &mut self.backend {
            Backend::Native {
                template, search, ..
            } => (template, search),
            #[cfg(feature = "cnn")]
            Backend::Ort(o) => return o.backbone(&self.input, side),
        };
        let (net, cells) = if side == TEMPLATE_SIDE {
            (template, TEMPLATE_CELLS)
        } else {
            (search, SEARCH_CELLS)
        };
        // The crop is lent to the network, not copied into it (`[1, 3, side, side]`).
        let mut out =
            net.run_lending(&mut self.input, &[("output", &[1, CHANNELS, cells, cells])])?;
        Ok(out.swap_remove(0))
    }

    /// Head on the template and `self.search`: per grid point the foreground logit margin
    /// and the four box distances, `(margins[256], loc[4·256])` (both branches).
    fn run_head(&mut self) -> Result<(Vec<f32>, Vec<f32>), NanoError> {
        let (margins, loc) = self.run_head_if(|_| true)?;
        let loc = loc.ok_or_else(|| NanoError::Run {
            key: HEAD_KEY,
            path: self.backend.paths().1.to_string(),
            reason: "the regression branch did not run".to_string(),
        })?;
        Ok((margins, loc))
    }

    /// The head's classification branch on the template and `self.search` (the margins),
    /// then its regression branch (the box distances) only when `want_box(&margins)`; on
    /// ONNX Runtime the whole head runs and the distances are always returned.
    fn run_head_if(
        &mut self,
        want_box: impl FnOnce(&[f32]) -> bool,
    ) -> Result<(Vec<f32>, Option<Vec<f32>>), NanoError> {
        let (t, x) = (TEMPLATE_CELLS, SEARCH_CELLS);
        let (cls, reg) = match &mut self.backend {
            Backend::Native { cls, reg, .. } => (cls, reg),
            #[cfg(feature = "cnn")]
            Backend::Ort(o) => {
                let (cls, loc) = o.head(&self.template, &self.search)?;
                let margins = margins_of(&cls);
                return Ok((margins, Some(loc)));
            }
        };
        let inputs: [(&[usize], &[f32]); 2] = [
            (&[1, CHANNELS, t, t], &self.template),
            (&[1, CHANNELS, x, x], &self.search),
        ];
        let logits = cls
            .run(&inputs, &[("output1", &[1, 2, x, x])])?
            .swap_remove(0);
        let margins = margins_of(&logits);
        if !want_box(&margins) {
            return Ok((margins, None));
        }
        let loc = reg
            .run(&inputs, &[("output2", &[1, 4, x, x])])?
            .swap_remove(0);
        Ok((margins, Some(loc)))
    }
}

/// Planes of `w × w` values (a window of the maps) placed at rows and columns `lo..lo + w`
/// of `cells × cells` planes whose other values are NaN.
fn embed(window: &[f32], w: usize, cells: usize, lo: usize) -> Vec<f32> {
    let planes = window.len() / (w * w);
    let mut out = vec![f32::NAN; planes * cells * cells];
    for (p, plane) in window.chunks_exact(w * w).enumerate() {
        for (r, row) in plane.chunks_exact(w).enumerate() {
            let at = (p * cells + lo + r) * cells + lo;
            out[at..at + w].copy_from_slice(row);
        }
    }
    out
}

/// Per grid point the foreground logit margin (foreground − background) of the head's
/// classification output `[1, 2, n, n]` (background plane first).
fn margins_of(logits: &[f32]) -> Vec<f32> {
    let (bg, fg) = logits.split_at(logits.len() / 2);
    fg.iter().zip(bg).map(|(f, b)| f - b).collect()
}

/// The grid point with the largest margin and that margin (`None` for no points).
fn best_point(margins: &[f32]) -> Option<(usize, f32)> {
    margins
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map(|(i, &m)| (i, m))
}

/// The hit of grid point `i` (score `score`, box distances `loc`) of the search crop of
/// side `side` at `center` of `frame`.
fn hit_at(
    frame: &Frame<'_>,
    center: Point2,
    side: f32,
    i: usize,
    score: f32,
    loc: &[f32],
) -> VerifierHit {
    hit_at_cells(frame, center, side, SEARCH_CELLS, (i, score), loc)
}

/// [`hit_at`] on maps of `cells × cells` points from a crop of `16·cells − 1` pixels (the
/// crop centre at grid point `cells / 2`, the head's distances in the same crop pixels).
fn hit_at_cells(
    frame: &Frame<'_>,
    center: Point2,
    side: f32,
    cells: usize,
    (i, score): (usize, f32),
    loc: &[f32],
) -> VerifierHit {
    let n = cells * cells;
    let (j, k) = (i / cells, i % cells);
    let half = (cells / 2) as f32;
    let gx = (k as f32 - half) * STRIDE + GRID_CENTRE;
    let gy = (j as f32 - half) * STRIDE + GRID_CENTRE;
    let (l, t, r, b) = (loc[i], loc[n + i], loc[2 * n + i], loc[3 * n + i]);
    let px = side / (STRIDE_PX * cells - 1) as f32;
    let fw = frame.width() as f32;
    let fh = frame.height() as f32;
    let pos = Point2 {
        x: (center.x + (gx + 0.5 * (r - l) - GRID_CENTRE) * px).clamp(0.0, fw),
        y: (center.y + (gy + 0.5 * (b - t) - GRID_CENTRE) * px).clamp(0.0, fh),
    };
    VerifierHit {
        pos,
        w: ((l + r) * px).max(1.0),
        h: ((t + b) * px).max(1.0),
        score,
    }
}

/// The head's per-point foreground logit margins `[256]` and box distances `[4·256]`.
pub type HeadMaps = (Vec<f32>, Vec<f32>);

impl NanoVerifier {
    /// The head's maps on the square search crop of side `side` at `center` against the
    /// template of [`Verifier::set_template`]: per grid point of the 16×16 map the
    /// foreground logit margin and the four box distances `(margins[256], loc[4·256])`
    /// (left, top, right, bottom in 255-pixel crop units from grid point
    /// `(j − 8)·16 + 127`); `None` without a template or for a degenerate side. What
    /// [`crate::box_refine`] post-processes NanoTrack's way.
    ///
    /// # Errors
    /// A network error.
    pub fn score_maps(
        &mut self,
        frame: &Frame<'_>,
        center: Point2,
        side: f32,
    ) -> Result<Option<HeadMaps>, TrackError> {
        if !self.search_features(frame, center, side)? {
            return Ok(None);
        }
        Ok(Some(self.run_head()?))
    }

    /// [`NanoVerifier::score_maps`] on a smaller search crop: the square of side `side` at
    /// `center` resampled to `16·cells − 1` pixels (`cells` even, 4 to 16; 16 is
    /// [`NanoVerifier::score_maps`] itself), giving `cells × cells` maps whose centre
    /// point is the crop centre, in the same crop-pixel units (the backbone's stride is 16
    /// whatever the crop). The backbone's cost goes with the crop's area: what
    /// [`crate::box_refine`] needs around a position the filter already found. The other
    /// sizes are planned on first use (once per process) and run on [`crate::nn`] only.
    ///
    /// # Errors
    /// A network error; `cells` odd or out of range, or the ONNX Runtime backend with
    /// `cells` other than 16.
    pub fn score_maps_sized(
        &mut self,
        frame: &Frame<'_>,
        center: Point2,
        side: f32,
        cells: usize,
    ) -> Result<Option<HeadMaps>, TrackError> {
        self.maps_sized(frame, center, side, cells, false)
    }

    /// [`NanoVerifier::score_maps_sized`] where only the `(2·CENTRE_RADIUS + 1)²` grid
    /// points around the maps' centre are wanted: those points carry the same values, bit
    /// for bit, every other point is NaN (not computed). The head's two towers then compute
    /// only what those points depend on (`nn::window`: about half their work at 12
    /// cells). A head that cannot be windowed (another model's) and 16 cells give the
    /// whole maps.
    ///
    /// # Errors
    /// As [`NanoVerifier::score_maps_sized`].
    pub fn centre_maps_sized(
        &mut self,
        frame: &Frame<'_>,
        center: Point2,
        side: f32,
        cells: usize,
    ) -> Result<Option<HeadMaps>, TrackError> {
        self.maps_sized(frame, center, side, cells, true)
    }

    /// [`NanoVerifier::score_maps_sized`] (`centre`: [`NanoVerifier::centre_maps_sized`]);
    /// 16 cells are [`NanoVerifier::score_maps`] in both.
    fn maps_sized(
        &mut self,
        frame: &Frame<'_>,
        center: Point2,
        side: f32,
        cells: usize,
        centre: bool,
    ) -> Result<Option<HeadMaps>, TrackError> {
        if cells == SEARCH_CELLS {
            return self.score_maps(frame, center, side);
        }
        let Some(feat) = self.sized_features(frame, center, side, cells)? else {
            return Ok(None);
        };
        let Backend::Native { sized: Some(n), .. } = &mut self.backend else {
            return Ok(None);
        };
        let t = TEMPLATE_CELLS;
        let inputs: [(&[usize], &[f32]); 2] = [
            (&[1, CHANNELS, t, t], &self.template),
            (&[1, CHANNELS, cells, cells], &feat),
        ];
        if let Some((cls, reg)) = n.centre.as_mut().filter(|_| centre) {
            let w = 2 * CENTRE_RADIUS + 1; // the shapes checked when planned
            let logits = cls
                .run(&inputs, &[("output1", &[1, 2, w, w])])?
                .swap_remove(0);
            let loc = reg
                .run(&inputs, &[("output2", &[1, 4, w, w])])?
                .swap_remove(0);
            let lo = cells / 2 - CENTRE_RADIUS;
            return Ok(Some((
                embed(&margins_of(&logits), w, cells, lo),
                embed(&loc, w, cells, lo),
            )));
        }
        let logits = n
            .cls
            .run(&inputs, &[("output1", &[1, 2, cells, cells])])?
            .swap_remove(0);
        let loc = n
            .reg
            .run(&inputs, &[("output2", &[1, 4, cells, cells])])?
            .swap_remove(0);
        let margins = margins_of(&logits);
        Ok(Some((margins, loc)))
    }

    /// Plans the networks for search maps of `cells × cells` now (once per process and
    /// size: later verifiers share them), so that the first pass of that size does not:
    /// what [`crate::BevtTracker::check_models`] calls at start-up. Nothing to do for 16
    /// cells (planned with the verifier) or on ONNX Runtime (which refuses other sizes at
    /// the pass).
    ///
    /// # Errors
    /// `cells` odd or out of range (as the pass would say), or a planning error.
    pub fn plan_cells(&mut self, cells: usize) -> Result<(), TrackError> {
        if cells == SEARCH_CELLS {
            return Ok(());
        }
        Self::check_cells(self.backend.paths().0, cells)?;
        match &self.backend {
            Backend::Native { plans, .. } => {
                plans.sized(cells)?;
            }
            #[cfg(feature = "cnn")]
            Backend::Ort(_) => {}
        }
        Ok(())
    }

    /// `cells` even, 4 to [`MAX_SIZED_CELLS`], else the error naming the backbone's path.
    fn check_cells(path: &str, cells: usize) -> Result<(), NanoError> {
        if !(4..=MAX_SIZED_CELLS).contains(&cells) || !cells.is_multiple_of(2) {
            return Err(NanoError::Run {
                key: BACKBONE_KEY,
                path: path.to_string(),
                reason: format!(
                    "search maps of {cells} cells; an even number from 4 to {MAX_SIZED_CELLS} is supported"
                ),
            });
        }
        Ok(())
    }

    /// The backbone's features of the square of side `side` at `center` resampled to
    /// `16·cells − 1` pixels (`cells` even, 4 to [`MAX_SIZED_CELLS`], not 16), on the sized
    /// plans (planned on first use, once per process and size); `None` without a template
    /// or for a degenerate side.
    fn sized_features(
        &mut self,
        frame: &Frame<'_>,
        center: Point2,
        side: f32,
        cells: usize,
    ) -> Result<Option<Vec<f32>>, TrackError> {
        let path = self.backend.paths().0.to_string();
        Self::check_cells(&path, cells)?;
        if self.template.is_empty() || !(side.is_finite() && side > 0.0) {
            return Ok(None);
        }
        let (plans, nets) = match &mut self.backend {
            Backend::Native { plans, sized, .. } => (plans, sized),
            #[cfg(feature = "cnn")]
            Backend::Ort(_) => {
                return Err(NanoError::Run {
                    key: BACKBONE_KEY,
                    path,
                    reason: format!(
                        "search maps of {cells} cells need the pure-Rust networks (ONNX Runtime plans 16)"
                    ),
                }
                .into())
            }
        };
        if nets.as_ref().is_none_or(|n| n.cells != cells) {
            let p = plans.sized(cells)?;
            *nets = Some(Box::new(SizedNets {
                cells,
                search: Net::new(&p.search),
                cls: Net::new(&p.cls),
                reg: Net::new(&p.reg),
                centre: p.centre.as_ref().map(|(c, r)| (Net::new(c), Net::new(r))),
            }));
        }
        let out = STRIDE_PX * cells - 1;
        self.crop(frame, center, side, out);
        let Backend::Native { sized: Some(n), .. } = &mut self.backend else {
            return Ok(None);
        };
        // The crop is lent to the network, not copied into it (`[1, 3, out, out]`: 438 KB a
        // tracked frame for the learned box's 191-pixel crop), as `run_backbone` lends its.
        let feat = n
            .search
            .run_lending(&mut self.input, &[("output", &[1, CHANNELS, cells, cells])])?
            .swap_remove(0);
        Ok(Some(feat))
    }

    /// [`Verifier::search_above`] on a search crop of `16·cells − 1` pixels (the square of
    /// side `side` at `center`; `cells` even, 4 to [`MAX_SIZED_CELLS`]; 16 is
    /// [`Verifier::search_above`] itself): the classification branch on the whole
    /// `cells × cells` map, the regression branch only when its best point reaches `bar`.
    /// A larger crop covers more of the frame in one pass, its cost going with its area.
    ///
    /// # Errors
    /// A network error; `cells` odd or out of range, or the ONNX Runtime backend with
    /// `cells` other than 16.
    pub fn search_above_sized(
        &mut self,
        frame: &Frame<'_>,
        center: Point2,
        side: f32,
        bar: f32,
        cells: usize,
    ) -> Result<Option<Scored>, TrackError> {
        if cells == SEARCH_CELLS {
            return self.search_above(frame, center, side, bar);
        }
        let Some(feat) = self.sized_features(frame, center, side, cells)? else {
            return Ok(None);
        };
        let Backend::Native { sized: Some(n), .. } = &mut self.backend else {
            return Ok(None);
        };
        let t = TEMPLATE_CELLS;
        let inputs: [(&[usize], &[f32]); 2] = [
            (&[1, CHANNELS, t, t], &self.template),
            (&[1, CHANNELS, cells, cells], &feat),
        ];
        let logits = n
            .cls
            .run(&inputs, &[("output1", &[1, 2, cells, cells])])?
            .swap_remove(0);
        let margins = margins_of(&logits);
        let Some((i, score)) = best_point(&margins) else {
            return Ok(None);
        };
        if score < bar {
            return Ok(Some(Scored::Below(score)));
        }
        let loc = n
            .reg
            .run(&inputs, &[("output2", &[1, 4, cells, cells])])?
            .swap_remove(0);
        let hit = hit_at_cells(frame, center, side, cells, (i, score), &loc);
        Ok(Some(Scored::Hit(hit)))
    }

    /// Whether the last sized maps' plans include the windowed centre branches (`None`:
    /// no sized maps yet, or ONNX Runtime). For tests.
    #[cfg(test)]
    fn backend_centre_windowed(&self) -> Option<bool> {
        match &self.backend {
            Backend::Native { sized, .. } => sized.as_ref().map(|n| n.centre.is_some()),
            #[cfg(feature = "cnn")]
            Backend::Ort(_) => None,
        }
    }

    /// True once a template is set.
    pub fn has_template(&self) -> bool {
        !self.template.is_empty()
    }

    /// The backbone's features of the square search crop of side `side` at `center` into
    /// `self.search`; false (nothing run) without a template or for a degenerate side.
    fn search_features(
        &mut self,
        frame: &Frame<'_>,
        center: Point2,
        side: f32,
    ) -> Result<bool, TrackError> {
        if self.template.is_empty() || !(side.is_finite() && side > 0.0) {
            return Ok(false);
        }
        self.crop(frame, center, side, SEARCH_SIDE);
        self.search = self.run_backbone(SEARCH_SIDE)?;
        Ok(true)
    }
}

impl Verifier for NanoVerifier {
    fn set_template(
        &mut self,
        frame: &Frame<'_>,
        center: Point2,
        w: f32,
        h: f32,
    ) -> Result<(), TrackError> {
        let side = context_side(w, h);
        self.template.clear();
        if !(side.is_finite() && side > 0.0) {
            return Ok(());
        }
        self.crop(frame, center, side, TEMPLATE_SIDE);
        self.template = self.run_backbone(TEMPLATE_SIDE)?;
        Ok(())
    }

    fn search(
        &mut self,
        frame: &Frame<'_>,
        center: Point2,
        side: f32,
    ) -> Result<Option<VerifierHit>, TrackError> {
        if !self.search_features(frame, center, side)? {
            return Ok(None);
        }
        let (margins, loc) = self.run_head()?;
        Ok(best_point(&margins).map(|(i, score)| hit_at(frame, center, side, i, score, &loc)))
    }

    fn search_above(
        &mut self,
        frame: &Frame<'_>,
        center: Point2,
        side: f32,
        bar: f32,
    ) -> Result<Option<Scored>, TrackError> {
        if !self.search_features(frame, center, side)? {
            return Ok(None);
        }
        let reaches = |m: &[f32]| best_point(m).is_some_and(|(_, s)| s >= bar);
        let (margins, loc) = self.run_head_if(reaches)?;
        let Some((i, score)) = best_point(&margins) else {
            return Ok(None);
        };
        Ok(Some(match loc {
            Some(loc) if score >= bar => Scored::Hit(hit_at(frame, center, side, i, score, &loc)),
            _ => Scored::Below(score),
        }))
    }

    fn search_above_cells(
        &mut self,
        frame: &Frame<'_>,
        center: Point2,
        side: f32,
        bar: f32,
        cells: usize,
    ) -> Result<Option<Scored>, TrackError> {
        self.search_above_sized(frame, center, side, bar, cells)
    }

    fn prepare_cells(&mut self, cells: usize) -> Result<(), TrackError> {
        self.plan_cells(cells)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::PixelFormat;

    /// The head as one network (how it ran before its branches were planned apart): the
    /// template and search features' margins and box distances.
    fn whole_head(template: &[f32], search: &[f32]) -> (Vec<f32>, Vec<f32>) {
        let (hd, name) = load(HEAD_KEY, "", EMBEDDED_HEAD).unwrap();
        let (t, x) = (TEMPLATE_CELLS, SEARCH_CELLS);
        let plan = Planned::new(
            &hd,
            HEAD_KEY,
            &name,
            &[
                ("input1", &[1, CHANNELS, t, t]),
                ("input2", &[1, CHANNELS, x, x]),
            ],
            &["output1", "output2"],
        )
        .unwrap();
        let mut net = Net::new(&plan);
        let mut out = net
            .run(
                &[
                    (&[1, CHANNELS, t, t], template),
                    (&[1, CHANNELS, x, x], search),
                ],
                &[("output1", &[1, 2, x, x]), ("output2", &[1, 4, x, x])],
            )
            .unwrap();
        let loc = out.swap_remove(1);
        let cls = out.swap_remove(0);
        (margins_of(&cls), loc)
    }

    fn bits(v: &[f32]) -> Vec<u32> {
        v.iter().map(|f| f.to_bits()).collect()
    }

    /// The head's two branches, planned and run apart (what every search runs), give the
    /// whole head's margins and box distances bit for bit: on a textured template against
    /// a search crop whose centre it is, and against a flat one.
    #[test]
    fn head_branches_run_apart_equal_the_whole_head_bit_for_bit() {
        let mut v = NanoVerifier::new("", "").unwrap();
        let side = SEARCH_SIDE;
        let textured: Vec<f32> = (0..3 * side * side)
            .map(|i| ((i % 251) as f32 / 251.0) * 255.0)
            .collect();
        let c = TEMPLATE_SIDE;
        let o = (side - c) / 2;
        let crop: Vec<f32> = (0..3)
            .flat_map(|p| (0..c).flat_map(move |r| (0..c).map(move |k| (p, r, k))))
            .map(|(p, r, k)| textured[(p * side + r + o) * side + k + o])
            .collect();
        let zf = v.backbone(&crop, TEMPLATE_SIDE).unwrap();
        for search in [textured.clone(), vec![128.0; textured.len()]] {
            let xf = v.backbone(&search, SEARCH_SIDE).unwrap();
            let (margins, loc) = v.head(&zf, &xf).unwrap();
            let (w_margins, w_loc) = whole_head(&zf, &xf);
            assert_eq!(bits(&margins), bits(&w_margins), "margins");
            assert_eq!(bits(&loc), bits(&w_loc), "box distances");
        }
    }
    /// The head for other search sizes differs from the file in the reshape to the map's
    /// side and the declared search input only; at 16 cells it is the file's model.
    #[test]
    fn the_head_for_other_sizes_changes_only_the_map_side() {
        let (head, _) = load(HEAD_KEY, "", EMBEDDED_HEAD).unwrap();
        assert_eq!(head_for_cells(&head, SEARCH_CELLS), head);
        let h12 = head_for_cells(&head, 12);
        assert_eq!(h12.nodes, head.nodes);
        let changed: Vec<_> = head
            .initializers
            .iter()
            .filter(|(k, t)| h12.initializers[*k] != **t)
            .map(|(k, _)| k.clone())
            .collect();
        assert_eq!(changed.len(), 1, "{changed:?}");
        assert_eq!(
            h12.initializers[&changed[0]].data,
            nn::onnx::Data::I64(vec![1, -1, 12, 12])
        );
        let input2 = |m: &nn::onnx::Model| {
            m.inputs
                .iter()
                .find(|i| i.name == "input2")
                .map(|i| i.dims.clone())
        };
        assert_eq!(
            input2(&h12),
            Some(vec![Some(1), Some(48), Some(12), Some(12)])
        );
    }

    /// Frame `i` of the default synthetic sequence: its RGB pixels, its size, and the target's
    /// centre and size.
    fn synth(i: usize) -> (Vec<u8>, (usize, usize), Point2, (f32, f32)) {
        let seq = crate::eval::synth::SynthParams::default();
        let f = seq.frame(i);
        let t = (f.truth.center(), (f.truth.w, f.truth.h));
        (f.rgb, (seq.width, seq.height), t.0, t.1)
    }

    /// Planning a size ahead (what the start-up check does) refuses what the pass refuses,
    /// with the same words, and leaves the size planned for every later verifier.
    #[test]
    fn sizes_planned_ahead_are_checked_and_shared() {
        let mut v = NanoVerifier::new("", "").unwrap();
        for bad in [3, 2, 34] {
            let e = v.plan_cells(bad).unwrap_err().to_string();
            assert!(e.contains(&format!("search maps of {bad} cells")), "{e}");
        }
        v.plan_cells(16).unwrap();
        v.plan_cells(10).unwrap();
        fn plans_of(v: &NanoVerifier) -> &Arc<Plans> {
            match &v.backend {
                Backend::Native { plans, .. } => plans,
                #[cfg(feature = "cnn")]
                Backend::Ort(_) => panic!("the native backend"),
            }
        }
        let plans = plans_of(&v);
        let planned = plans.sized.lock().unwrap().iter().any(|(c, _)| *c == 10);
        assert!(planned, "10 cells not planned");
        // Another verifier of the same models shares them.
        let w = NanoVerifier::new("", "").unwrap();
        assert!(Arc::ptr_eq(plans, plans_of(&w)));
    }

    /// A smaller search crop (12 cells, 191 pixels) still finds a textured target at its
    /// centre and regresses a box of about its size, like the 255-pixel one; odd or
    /// out-of-range sides are errors, a degenerate crop side gives nothing.
    #[test]
    fn smaller_search_maps_find_the_target_at_the_crop_centre() {
        let (px, size, c, (w, h)) = synth(0);
        let frame = Frame::packed(&px, size.0, size.1, PixelFormat::Rgb8).unwrap();
        let mut v = NanoVerifier::new("", "").unwrap();
        assert!(
            v.score_maps_sized(&frame, c, 100.0, 12).unwrap().is_none(),
            "no template"
        );
        v.set_template(&frame, c, w, h).unwrap();
        let s_z = context_side(w, h);
        for cells in [16usize, 12] {
            let side = s_z * (16 * cells - 1) as f32 / TEMPLATE_SIDE as f32;
            let (margins, loc) = v.score_maps_sized(&frame, c, side, cells).unwrap().unwrap();
            assert_eq!(
                (margins.len(), loc.len()),
                (cells * cells, 4 * cells * cells)
            );
            let (best, _) = best_point(&margins).unwrap();
            let (j, k) = (best / cells, best % cells);
            let mid = cells / 2;
            assert!(
                j.abs_diff(mid) <= 1 && k.abs_diff(mid) <= 1,
                "{cells} cells: best point ({j}, {k})"
            );
            // The centre point's box, in frame pixels, against the target's.
            let (n, i) = (cells * cells, mid * cells + mid);
            let px = s_z / TEMPLATE_SIDE as f32;
            let (bw, bh) = (
                (loc[i] + loc[2 * n + i]) * px,
                (loc[n + i] + loc[3 * n + i]) * px,
            );
            assert!(
                (bw / w - 1.0).abs() < 0.35 && (bh / h - 1.0).abs() < 0.35,
                "{cells} cells: box {bw} x {bh} for a {w} x {h} target"
            );
        }
        for bad in [3usize, 11, 34] {
            assert!(v.score_maps_sized(&frame, c, 100.0, bad).is_err(), "{bad}");
        }
        assert!(v
            .score_maps_sized(&frame, c, f32::NAN, 12)
            .unwrap()
            .is_none());
    }

    /// Larger tiles (`redetection.verifier_tile_cells`): a crop of 24 or 32 cells whose
    /// centre is several cells off the target finds it where it is, with a box of about its
    /// size, as NanoTrack's own crop centred on it does; the score alone (bar +∞) is the
    /// hit's score; odd or out-of-range sides are errors.
    #[test]
    fn larger_tiles_find_an_off_centre_target_where_it_is() {
        let (px, size, c, (w, h)) = synth(0);
        let frame = Frame::packed(&px, size.0, size.1, PixelFormat::Rgb8).unwrap();
        let mut v = NanoVerifier::new("", "").unwrap();
        v.set_template(&frame, c, w, h).unwrap();
        let search = 2.0 * context_side(w, h);
        let Some(Scored::Hit(own)) = v.search_above(&frame, c, search, 0.0).unwrap() else {
            panic!("NanoTrack's crop on the target finds no hit");
        };
        for cells in [24usize, 32] {
            let side = search * (16 * cells - 1) as f32 / SEARCH_SIDE as f32;
            // The crop centre 5 cells left of and 3 cells below the target (crop pixels at
            // the network's resolution: 16 a cell).
            let k = side / (16 * cells - 1) as f32;
            let at = Point2 {
                x: c.x - 80.0 * k,
                y: c.y + 48.0 * k,
            };
            let Some(Scored::Hit(h_)) = v.search_above_sized(&frame, at, side, 0.0, cells).unwrap()
            else {
                panic!("{cells} cells: no hit");
            };
            let off = ((h_.pos.x - c.x).powi(2) + (h_.pos.y - c.y).powi(2)).sqrt();
            assert!(
                off < 0.25 * w.min(h),
                "{cells} cells: hit at {:?}, target at {c:?}",
                h_.pos
            );
            assert!(
                (h_.w / w - 1.0).abs() < 0.35 && (h_.h / h - 1.0).abs() < 0.35,
                "{cells} cells: box {} x {} for a {w} x {h} target",
                h_.w,
                h_.h
            );
            assert!(
                h_.score > 0.5 * own.score,
                "{cells}: {} against {}",
                h_.score,
                own.score
            );
            let below = v
                .search_above_sized(&frame, at, side, f32::INFINITY, cells)
                .unwrap();
            assert_eq!(below, Some(Scored::Below(h_.score)), "{cells} cells");
        }
        assert_eq!(
            v.search_above_sized(&frame, c, search, 0.0, 16).unwrap(),
            Some(Scored::Hit(own)),
            "16 cells is NanoTrack's crop"
        );
        for bad in [7usize, 34] {
            assert!(
                v.search_above_sized(&frame, c, search, 0.0, bad).is_err(),
                "{bad}"
            );
        }
    }

    /// The centre maps are the whole maps' values at the `(2·CENTRE_RADIUS + 1)²` points
    /// around the centre, bit for bit, and NaN elsewhere, at every size the learned box can
    /// ask for (NanoTrack v2's head is windowed at each: none falls back to the whole maps
    /// unseen); at 16 cells they are the whole maps.
    /// The node timer (`verifier_passes nodes`): off, no nodes; on, each network counts
    /// the runs made since and names its nodes by what they compute; the times sum to more
    /// than nothing; the results are the untimed run's bits; off again, nothing.
    #[test]
    fn timing_the_nodes_names_them_and_counts_the_runs() {
        let (px0, size, c0, (w, h)) = synth(0);
        let frame = Frame::packed(&px0, size.0, size.1, PixelFormat::Rgb8).unwrap();
        let mut v = NanoVerifier::new("", "").unwrap();
        v.set_template(&frame, c0, w, h).unwrap();
        let side = 2.0 * context_side(w, h);
        let untimed = v.score_maps_sized(&frame, c0, side, SEARCH_CELLS).unwrap();
        let nodes = |v: &mut NanoVerifier, net: &str| {
            let all = v.node_times();
            all.into_iter()
                .find(|n| n.name == net)
                .map(|n| (n.runs, n.nodes))
        };
        assert_eq!(nodes(&mut v, "search").map(|n| n.1.len()), Some(0));
        v.time_nodes(true);
        let timed = v.score_maps_sized(&frame, c0, side, SEARCH_CELLS).unwrap();
        assert_eq!(format!("{untimed:?}"), format!("{timed:?}"));
        v.score_maps_sized(&frame, c0, side, SEARCH_CELLS).unwrap();
        let Some((runs, search)) = nodes(&mut v, "search") else {
            panic!("no search network")
        };
        assert_eq!(runs, 2);
        assert!(search.len() > 30, "{} nodes", search.len());
        assert_eq!(search[0].0, "conv 3×3/2 by rows, 3 → 16 on 255×255");
        assert!(search
            .iter()
            .any(|n| n.0 == "conv depthwise 5×5/1, 240 → 240 on 16×16"));
        assert!(search.iter().map(|n| n.1).sum::<u64>() > 0);
        assert_eq!(nodes(&mut v, "template").map(|n| n.0), Some(0));
        // Another search size's networks are listed once built, and timed from then on.
        let small = side * (16 * 12 - 1) as f32 / (16 * SEARCH_CELLS - 1) as f32;
        v.score_maps_sized(&frame, c0, small, 12).unwrap();
        v.time_nodes(true);
        v.score_maps_sized(&frame, c0, small, 12).unwrap();
        assert_eq!(nodes(&mut v, "search at 12 cells").map(|n| n.0), Some(1));
        assert_eq!(nodes(&mut v, "search").map(|n| n.0), Some(0));
        v.time_nodes(false);
        assert_eq!(nodes(&mut v, "search"), Some((0, Vec::new())));
    }

    #[test]
    fn centre_maps_are_the_whole_maps_bits_at_the_centre() {
        let (px0, size, c0, (w, h)) = synth(0);
        let frame0 = Frame::packed(&px0, size.0, size.1, PixelFormat::Rgb8).unwrap();
        let (px, _, c, _) = synth(3);
        let frame = Frame::packed(&px, size.0, size.1, PixelFormat::Rgb8).unwrap();
        let mut v = NanoVerifier::new("", "").unwrap();
        v.set_template(&frame0, c0, w, h).unwrap();
        let bits = |v: &[f32]| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        let s_z = context_side(w, h);
        // Off the target too: the values must agree wherever the crop is.
        let off = Point2 {
            x: c.x + 17.0,
            y: c.y - 9.0,
        };
        for cells in [4usize, 6, 8, 10, 12, 14, 16] {
            let side = s_z * (16 * cells - 1) as f32 / TEMPLATE_SIDE as f32;
            for at in [c, off] {
                let whole = v
                    .score_maps_sized(&frame, at, side, cells)
                    .unwrap()
                    .unwrap();
                let centre = v
                    .centre_maps_sized(&frame, at, side, cells)
                    .unwrap()
                    .unwrap();
                if cells == SEARCH_CELLS {
                    assert_eq!(bits(&centre.0), bits(&whole.0));
                    assert_eq!(bits(&centre.1), bits(&whole.1));
                    continue;
                }
                let (lo, hi) = (cells / 2 - CENTRE_RADIUS, cells / 2 + CENTRE_RADIUS);
                for (mine, all) in [(&centre.0, &whole.0), (&centre.1, &whole.1)] {
                    assert_eq!(mine.len(), all.len(), "{cells} cells");
                    for (i, (m, a)) in mine.iter().zip(all.iter()).enumerate() {
                        let (j, k) = ((i / cells) % cells, i % cells);
                        if (lo..=hi).contains(&j) && (lo..=hi).contains(&k) {
                            assert_eq!(m.to_bits(), a.to_bits(), "{cells} cells, point {i}");
                        } else {
                            assert!(m.is_nan(), "{cells} cells, point {i} computed");
                        }
                    }
                }
                let n = v.backend_centre_windowed();
                assert_eq!(n, Some(true), "{cells} cells: the head was not windowed");
            }
        }
    }
}

/// The ONNX Runtime backend (cargo feature `cnn`, `redetection.verifier: nanotrack_ort`).
#[cfg(feature = "cnn")]
mod ort_backend {
    use super::{
        NanoError, BACKBONE_KEY, CHANNELS, EMBEDDED, EMBEDDED_BACKBONE, EMBEDDED_HEAD, HEAD_KEY,
        SEARCH_CELLS, TEMPLATE_CELLS,
    };
    use crate::features::cnn::load_runtime;
    use ort::session::builder::GraphOptimizationLevel;
    use ort::session::Session;
    use ort::value::TensorRef;
    use std::path::Path;

    /// Backbone and head sessions.
    pub(super) struct OrtNets {
        backbone: Session,
        head: Session,
        pub(super) backbone_path: String,
        pub(super) head_path: String,
    }

    /// A one-thread session of the file at `path` (empty: `embedded`).
    fn session(
        env: &ort::environment::Environment,
        key: &'static str,
        path: &str,
        embedded: &[u8],
    ) -> Result<(Session, String), NanoError> {
        let name = if path.is_empty() { EMBEDDED } else { path };
        let err = |reason: String| NanoError::Model {
            key,
            path: name.to_string(),
            reason,
        };
        if !path.is_empty() && !Path::new(path).is_file() {
            return Err(NanoError::ModelMissing {
                key,
                path: path.to_string(),
            });
        }
        let mut b = Session::builder(env)
            .map_err(|e| err(e.to_string()))?
            .with_optimization_level(GraphOptimizationLevel::All)
            .map_err(|e| err(e.to_string()))?
            .with_intra_threads(1)
            .map_err(|e| err(e.to_string()))?
            .with_inter_threads(1)
            .map_err(|e| err(e.to_string()))?;
        let s = if path.is_empty() {
            b.commit_from_memory(embedded)
        } else {
            b.commit_from_file(path)
        }
        .map_err(|e| err(e.to_string()))?;
        Ok((s, name.to_string()))
    }

    /// The named output of `outputs`, checked to be `expected` and finite.
    fn output(
        outputs: &ort::session::SessionOutputs<'_>,
        key: &'static str,
        path: &str,
        name: &'static str,
        expected: &[usize],
    ) -> Result<Vec<f32>, NanoError> {
        let run = |reason: String| NanoError::Run {
            key,
            path: path.to_string(),
            reason,
        };
        let value = outputs
            .get(name)
            .ok_or_else(|| run(format!("no output `{name}`")))?;
        let (shape, data) = value
            .try_extract_tensor::<f32>()
            .map_err(|e| run(format!("{name}: {e}")))?;
        let dims: Vec<usize> = shape.iter().map(|&d| d.max(0) as usize).collect();
        if dims != expected {
            return Err(NanoError::Shape {
                key,
                path: path.to_string(),
                name,
                shape: dims,
                expected: expected.to_vec(),
            });
        }
        if data.iter().any(|v| !v.is_finite()) {
            return Err(NanoError::NonFinite {
                key,
                path: path.to_string(),
                name,
            });
        }
        Ok(data.to_vec())
    }

    impl OrtNets {
        pub(super) fn new(runtime: &str, backbone: &str, head: &str) -> Result<Self, NanoError> {
            let env = load_runtime(runtime).map_err(|e| NanoError::Runtime(e.to_string()))?;
            let (backbone, backbone_path) =
                session(&env, BACKBONE_KEY, backbone, EMBEDDED_BACKBONE)?;
            let (head, head_path) = session(&env, HEAD_KEY, head, EMBEDDED_HEAD)?;
            Ok(Self {
                backbone,
                head,
                backbone_path,
                head_path,
            })
        }

        /// Backbone on a `[1,3,side,side]` input.
        pub(super) fn backbone(
            &mut self,
            input: &[f32],
            side: usize,
        ) -> Result<Vec<f32>, NanoError> {
            let run = |reason: String| NanoError::Run {
                key: BACKBONE_KEY,
                path: self.backbone_path.clone(),
                reason,
            };
            let cells = if side == super::TEMPLATE_SIDE {
                TEMPLATE_CELLS
            } else {
                SEARCH_CELLS
            };
            let t = TensorRef::from_array_view(([1usize, 3, side, side], input))
                .map_err(|e| run(e.to_string()))?;
            let outputs = self
                .backbone
                .run(ort::inputs!["input" => t])
                .map_err(|e| run(e.to_string()))?;
            output(
                &outputs,
                BACKBONE_KEY,
                &self.backbone_path,
                "output",
                &[1, CHANNELS, cells, cells],
            )
        }

        /// Head on the template and search features: raw `(cls, loc)`.
        pub(super) fn head(
            &mut self,
            template: &[f32],
            search: &[f32],
        ) -> Result<(Vec<f32>, Vec<f32>), NanoError> {
            let run = |reason: String| NanoError::Run {
                key: HEAD_KEY,
                path: self.head_path.clone(),
                reason,
            };
            let (t, x) = (TEMPLATE_CELLS, SEARCH_CELLS);
            let z = TensorRef::from_array_view(([1usize, CHANNELS, t, t], template))
                .map_err(|e| run(e.to_string()))?;
            let s = TensorRef::from_array_view(([1usize, CHANNELS, x, x], search))
                .map_err(|e| run(e.to_string()))?;
            let outputs = self
                .head
                .run(ort::inputs!["input1" => z, "input2" => s])
                .map_err(|e| run(e.to_string()))?;
            let cls = output(
                &outputs,
                HEAD_KEY,
                &self.head_path,
                "output1",
                &[1, 2, x, x],
            )?;
            let loc = output(
                &outputs,
                HEAD_KEY,
                &self.head_path,
                "output2",
                &[1, 4, x, x],
            )?;
            Ok((cls, loc))
        }
    }
}
