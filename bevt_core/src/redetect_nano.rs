//! NanoTrack v2 as a learned re-detection verifier (cargo feature `cnn`,
//! `redetection.verifier: nanotrack`).
//!
//! The tracking-trained Siamese network scores a search region against a template taken on
//! the initial frame: the backbone turns a 127×127 template crop (context side
//! `sz = √((w+p)(h+p))`, `p = (w+h)/2`, as OpenCV's `TrackerNano` crops) into `[1,48,8,8]`
//! and a 255×255 search crop (side `2·sz`) into `[1,48,16,16]`; the head returns
//! classification logits `[1,2,16,16]` (background, foreground) and box distances
//! `[1,4,16,16]` (left, top, right, bottom in crop pixels from grid point
//! `(j − 8)·16 + 127`). A region's hit is the grid point with the largest foreground logit
//! margin (no cosine window: the whole frame is searched), with its regressed box. Crops
//! are sampled with the tracker's [`Sampler`] (RGB planes, raw 0–255; grey frames are
//! replicated into the three planes; outside the frame the border is replicated, where
//! `TrackerNano` fills with the mean colour).

use crate::error::TrackError;
use crate::features::cnn::{load_runtime, CnnError};
use crate::geometry::Point2;
use crate::image::{Frame, Patch, Sampler};
use crate::redetect::{context_side, Verifier, VerifierHit};
use ort::session::builder::GraphOptimizationLevel;
use ort::session::Session;
use ort::value::TensorRef;
use std::path::Path;
use std::sync::{Arc, Mutex, PoisonError};

/// Template crop side, pixels.
pub const TEMPLATE_SIDE: usize = 127;
/// Search crop side, pixels.
pub const SEARCH_SIDE: usize = 255;
/// Feature channels of the backbone.
const CHANNELS: usize = 48;
/// Template feature side (127 / 16).
const TEMPLATE_CELLS: usize = 8;
/// Search feature and score-map side (255 / 16).
const SEARCH_CELLS: usize = 16;
/// Backbone stride, crop pixels.
const STRIDE: f32 = 16.0;
/// Crop coordinate of grid point 8 (the crop centre as NanoTrack counts it).
const GRID_CENTRE: f32 = 127.0;

/// NanoTrack v2 backbone + head (see the module doc).
pub struct NanoVerifier {
    backbone: Arc<Mutex<Session>>,
    head: Arc<Mutex<Session>>,
    template: Vec<f32>,
    input: Vec<f32>,
    search: Vec<f32>,
    sampler: Sampler,
    patch: Patch,
}

impl std::fmt::Debug for NanoVerifier {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NanoVerifier")
            .field("template", &!self.template.is_empty())
            .finish()
    }
}

fn session(env: &ort::environment::Environment, path: &str) -> Result<Session, CnnError> {
    let model = Path::new(path);
    if !model.is_file() {
        return Err(CnnError::ModelMissing {
            path: path.to_string(),
        });
    }
    let err = |reason: String| CnnError::Model {
        path: path.to_string(),
        reason,
    };
    Session::builder(env)
        .map_err(|e| err(e.to_string()))?
        .with_optimization_level(GraphOptimizationLevel::All)
        .map_err(|e| err(e.to_string()))?
        .with_intra_threads(1)
        .map_err(|e| err(e.to_string()))?
        .with_inter_threads(1)
        .map_err(|e| err(e.to_string()))?
        .commit_from_file(model)
        .map_err(|e| err(e.to_string()))
}

/// The named output of `outputs` as `(dims, data)`, checked to be `expected` and finite.
fn output<'a>(
    outputs: &'a ort::session::SessionOutputs<'_>,
    name: &str,
    expected: &[i64],
) -> Result<&'a [f32], CnnError> {
    let value = outputs.get(name).ok_or_else(|| CnnError::NoOutput {
        name: name.to_string(),
        available: String::new(),
    })?;
    let (shape, data) = value
        .try_extract_tensor::<f32>()
        .map_err(|e| CnnError::Run(format!("{name}: {e}")))?;
    let dims: Vec<i64> = shape.iter().copied().collect();
    if dims != expected {
        return Err(CnnError::Rank {
            name: name.to_string(),
            shape: dims,
        });
    }
    if data.iter().any(|v| !v.is_finite()) {
        return Err(CnnError::NonFinite {
            name: name.to_string(),
        });
    }
    Ok(data)
}

impl NanoVerifier {
    /// Loads the runtime (`runtime`, or `ORT_DYLIB_PATH` when empty) and both models, and
    /// checks them on a grey template and search crop.
    ///
    /// # Errors
    /// A [`CnnError`] naming the runtime or model problem.
    pub fn new(runtime: &str, backbone: &str, head: &str) -> Result<Self, CnnError> {
        let env = load_runtime(runtime)?;
        let mut v = Self {
            backbone: Arc::new(Mutex::new(session(&env, backbone)?)),
            head: Arc::new(Mutex::new(session(&env, head)?)),
            template: Vec::new(),
            input: Vec::new(),
            search: Vec::new(),
            sampler: Sampler::default(),
            patch: Patch::default(),
        };
        v.input = vec![128.0; 3 * TEMPLATE_SIDE * TEMPLATE_SIDE];
        v.template = v.run_backbone(TEMPLATE_SIDE, TEMPLATE_CELLS)?;
        v.input = vec![128.0; 3 * SEARCH_SIDE * SEARCH_SIDE];
        v.search = v.run_backbone(SEARCH_SIDE, SEARCH_CELLS)?;
        v.run_head()?;
        v.template.clear();
        Ok(v)
    }

    /// Samples the square of side `region` at `center` into `self.input` (`out`², RGB).
    fn crop(&mut self, frame: &Frame<'_>, center: Point2, region: f32, out: usize) {
        let planes = frame.format().planes();
        self.sampler.prepare(frame, center, region, region, out);
        if self.patch.side != out || self.patch.planes != planes {
            self.patch = Patch::new(out, planes);
        }
        self.sampler.sample(center, region, &mut self.patch);
        let n = out * out;
        self.input.resize(3 * n, 0.0);
        for p in 0..3 {
            let src = self.patch.plane(if planes >= 3 { p } else { 0 });
            self.input[p * n..(p + 1) * n].copy_from_slice(src);
        }
    }

    /// Backbone on `self.input` (`[1,3,side,side]`): the `[1,48,cells,cells]` features.
    fn run_backbone(&mut self, side: usize, cells: usize) -> Result<Vec<f32>, CnnError> {
        let tensor = TensorRef::from_array_view(([1usize, 3, side, side], &self.input[..]))
            .map_err(|e| CnnError::Run(e.to_string()))?;
        let mut s = self.backbone.lock().unwrap_or_else(PoisonError::into_inner);
        let outputs = s
            .run(ort::inputs!["input" => tensor])
            .map_err(|e| CnnError::Run(e.to_string()))?;
        let c = cells as i64;
        Ok(output(&outputs, "output", &[1, CHANNELS as i64, c, c])?.to_vec())
    }

    /// Head on the template and `self.search`: per grid point the foreground logit margin
    /// and the four box distances, `(margins[256], loc[4·256])`.
    fn run_head(&mut self) -> Result<(Vec<f32>, Vec<f32>), CnnError> {
        let (t, x) = (TEMPLATE_CELLS, SEARCH_CELLS);
        let z = TensorRef::from_array_view(([1usize, CHANNELS, t, t], &self.template[..]))
            .map_err(|e| CnnError::Run(e.to_string()))?;
        let s = TensorRef::from_array_view(([1usize, CHANNELS, x, x], &self.search[..]))
            .map_err(|e| CnnError::Run(e.to_string()))?;
        let mut h = self.head.lock().unwrap_or_else(PoisonError::into_inner);
        let outputs = h
            .run(ort::inputs!["input1" => z, "input2" => s])
            .map_err(|e| CnnError::Run(e.to_string()))?;
        let xs = x as i64;
        let cls = output(&outputs, "output1", &[1, 2, xs, xs])?;
        let loc = output(&outputs, "output2", &[1, 4, xs, xs])?;
        let n = x * x;
        let margins = (0..n).map(|i| cls[n + i] - cls[i]).collect();
        Ok((margins, loc.to_vec()))
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
        self.template = self.run_backbone(TEMPLATE_SIDE, TEMPLATE_CELLS)?;
        Ok(())
    }

    fn search(
        &mut self,
        frame: &Frame<'_>,
        center: Point2,
        side: f32,
    ) -> Result<Option<VerifierHit>, TrackError> {
        if self.template.is_empty() || !(side.is_finite() && side > 0.0) {
            return Ok(None);
        }
        self.crop(frame, center, side, SEARCH_SIDE);
        self.search = self.run_backbone(SEARCH_SIDE, SEARCH_CELLS)?;
        let (margins, loc) = self.run_head()?;
        let Some((i, &score)) = margins.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)) else {
            return Ok(None);
        };
        let n = SEARCH_CELLS * SEARCH_CELLS;
        let (j, k) = (i / SEARCH_CELLS, i % SEARCH_CELLS);
        let gx = (k as f32 - 8.0) * STRIDE + GRID_CENTRE;
        let gy = (j as f32 - 8.0) * STRIDE + GRID_CENTRE;
        let (l, t, r, b) = (loc[i], loc[n + i], loc[2 * n + i], loc[3 * n + i]);
        let px = side / SEARCH_SIDE as f32;
        let fw = frame.width() as f32;
        let fh = frame.height() as f32;
        let pos = Point2 {
            x: (center.x + (gx + 0.5 * (r - l) - GRID_CENTRE) * px).clamp(0.0, fw),
            y: (center.y + (gy + 0.5 * (b - t) - GRID_CENTRE) * px).clamp(0.0, fh),
        };
        Ok(Some(VerifierHit {
            pos,
            w: ((l + r) * px).max(1.0),
            h: ((t + b) * px).max(1.0),
            score,
        }))
    }
}
