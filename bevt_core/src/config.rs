//! Tracker configuration: user-facing [`TrackerConfig`] (serde, strict) validated once into
//! a [`TrackerSpec`] that the rest of the core trusts.
//!
//! `TrackerConfig::default()` equals `config/bevt.yaml` (a test checks it). Every number of
//! ALGORITHM.md is a field here; where the paper and the reference MATLAB differ the choice
//! is an enum, and its default is documented on the field.

use crate::confidence::{ConfidenceMeasure, ConfidenceParams};
use crate::consensus::{ConsensusNorm, GateParams, VerificationScore, VerifyParams};
use crate::error::ConfigError;
use crate::features::cnn_config::CnnConfig;
use crate::filter::admm::{AdmmParams, PenaltyKind};
use crate::redetect::RedetectParams;
use crate::scale_filter::ScaleFilterParams;
use crate::track_state::StateParams;
use serde::{Deserialize, Serialize};

/// Which features the tracker uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FeatureKind {
    /// Felzenszwalb HOG (31 channels), optionally + grayscale: the fast default.
    Hog,
    /// CNN layers from an ONNX model (`features.cnn`, cargo feature `cnn`): the paper's mode.
    Cnn,
}

/// Feature settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FeatureConfig {
    /// Feature type.
    pub kind: FeatureKind,
    /// HOG cell size, pixels (ref 4). Smaller cells are chosen for small targets.
    pub hog_cell_size: usize,
    /// Append a grayscale channel (cell-mean luminance) to HOG.
    pub grayscale: bool,
    /// Append the 10 colour-name channels (cell means of the embedded `w2crs` table) to
    /// HOG. Colour frames only: on mono8 frames the group is left out for the whole track.
    pub colornames: bool,
    /// Gain on every feature value (applied with the Hann window). It sets the balance of
    /// the data term against the ADMM penalty μ, and so the scale of the responses that
    /// consensus verification compares (1 = the reference).
    pub gain: f32,
    /// CNN features (required when `kind` is `cnn`; see `config/cnn_*.yaml`).
    pub cnn: Option<CnnConfig>,
}

impl Default for FeatureConfig {
    fn default() -> Self {
        Self {
            kind: FeatureKind::Hog,
            hog_cell_size: 4,
            grayscale: true,
            colornames: true,
            gain: 1.0,
            cnn: None,
        }
    }
}

/// Search-window geometry (ALGORITHM.md §1, §3).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WindowConfig {
    /// Search square side as a multiple of `sqrt(w·h)` (ref 5).
    pub search_area_scale: f32,
    /// Extra factor on the patch side (ref 1.2).
    pub padding: f32,
    /// Largest filter area, cells² (ref 50² = 2500); larger searches are downscaled.
    pub filter_max_area: f32,
    /// Choose a smaller cell when the search area is below this fraction of
    /// `filter_max_area` (ref 0.75² = 0.5625).
    pub cell_selection_thresh: f32,
    /// Label σ as a fraction of `sqrt(target cells)` (ref 1/16).
    pub output_sigma_factor: f32,
}

impl Default for WindowConfig {
    fn default() -> Self {
        Self {
            search_area_scale: 5.0,
            padding: 1.2,
            filter_max_area: 2500.0,
            cell_selection_thresh: 0.5625,
            output_sigma_factor: 1.0 / 16.0,
        }
    }
}

/// ADMM training (ALGORITHM.md §4).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AdmmConfig {
    /// Iterations per training (ref 3).
    pub iterations: usize,
    /// Initial μ (ref 1).
    pub mu_init: f32,
    /// μ growth β (ref run_BEVT.m: 20; a comment there says 10).
    pub beta: f32,
    /// Largest μ (ref 10000).
    pub mu_max: f32,
    /// Ridge λ of the `none` penalty (BACF 0.01).
    pub lambda: f32,
    /// Penalty form: `matrix` (reference), `elementwise` (a diagonal spatial penalty, the
    /// paper's eq. 8 at the magnitude `spatial_weight`), `none` (BACF).
    pub penalty: PenaltyKind,
    /// Magnitude κ of the `elementwise` penalty: its h-step divides by `κ·p² + μ`, `p` the
    /// penalty window (0.1 at the target centre, 0.8 at its edge). The literal eq. 8 is
    /// κ = 2/T (T = grid cells, ~1/1800): no effect against μ ≥ 1. κ = 100 weighs
    /// the target edge ~64× the first μ (in the spirit of SRDCF/STRCF weights). Unitless.
    pub spatial_weight: f32,
    /// Weight θ of the temporal regularisation `θ/2‖ĝ − ĝ_prev‖²` (STRCF/AutoTrack; in the
    /// units of μ; 0 = none, the reference).
    pub temporal: f32,
    /// Penalty window minimum at the target centre (ref 0.1).
    pub reg_window_min: f32,
    /// Penalty window value at the target edge (ref 0.8).
    pub reg_window_edge: f32,
}

impl Default for AdmmConfig {
    fn default() -> Self {
        Self {
            iterations: 3,
            mu_init: 1.0,
            beta: 20.0,
            mu_max: 10000.0,
            lambda: 0.01,
            penalty: PenaltyKind::Elementwise,
            spatial_weight: 10.0,
            temporal: 0.0,
            reg_window_min: 0.1,
            reg_window_edge: 0.8,
        }
    }
}

/// How the target scale is estimated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ScaleEstimator {
    /// The reference: translation filter evaluated on `number_of_scales` patches, the best
    /// peak wins (ALGORITHM.md §5).
    Search,
    /// One translation patch, then a separate 1-D scale filter (fDSST style, section
    /// `scale_filter`).
    Filter,
}

/// The separate scale filter (`detection.scale_estimator: filter`), fDSST style.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ScaleFilterConfig {
    /// Scales sampled per frame (fDSST 17).
    pub scales: usize,
    /// Scales after Fourier interpolation (fDSST 33), ≥ `scales`.
    pub interpolated_scales: usize,
    /// Ratio between neighbouring interpolated scales (fDSST 1.02).
    pub step: f32,
    /// Learning rate of the scale model (fDSST 0.025).
    pub learning_rate: f32,
    /// Scale label σ as a fraction of `interpolated_scales` (fDSST 1/16).
    pub sigma_factor: f32,
    /// Ridge of the detection denominator (fDSST 0.01).
    pub lambda: f32,
    /// Side of each (square) scale sample, pixels (fDSST: area 32·16 = 512 px²).
    pub sample_side: usize,
    /// HOG cell of the scale samples, pixels (fDSST 4).
    pub cell_size: usize,
    /// Each scale sample covers the target box times this factor (fDSST 1: the box only).
    pub padding: f32,
    /// Append the 10 colour-name channels per cell to the scale samples' fHOG (colour frames
    /// only; fDSST: fHOG only).
    pub colornames: bool,
}

impl Default for ScaleFilterConfig {
    fn default() -> Self {
        Self {
            scales: 17,
            interpolated_scales: 33,
            // fDSST's 1.02 and 0.025 were set for 25–30 fps video; at UAV123's 10 fps the
            // per-frame scale change is ~3× larger and the model's time constant (1/η
            // frames) 3× longer in seconds: η = 1 − 0.975³ ≈ 0.075 keeps fDSST's ~1.3 s,
            // and the step 1.03 (measured against 1.025 / 1.035 / 1.04, README "Ablation")
            // widens the range to ×/÷1.6.
            step: 1.03,
            learning_rate: 0.075,
            sigma_factor: 1.0 / 16.0,
            lambda: 0.01,
            sample_side: 24,
            cell_size: 4,
            padding: 1.0,
            colornames: true,
        }
    }
}

/// Detection and scale search (ALGORITHM.md §5).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DetectionConfig {
    /// `search` (reference: the translation filter on `number_of_scales` patches) or
    /// `filter` (one patch, separate scale filter).
    pub scale_estimator: ScaleEstimator,
    /// Scales tried per frame by `search` (ref 5).
    pub number_of_scales: usize,
    /// Ratio between neighbouring scales (ref 1.01).
    pub scale_step: f32,
    /// Newton iterations of the sub-cell peak (ref 50; stops early once converged).
    pub newton_iterations: usize,
    /// Multiplies the peak of a scale `k` steps from the current one by `penalty^k` before
    /// the scales compete (1 = the reference: no penalty). Damps scale jitter from noise.
    pub scale_penalty: f32,
}

impl Default for DetectionConfig {
    fn default() -> Self {
        Self {
            scale_estimator: ScaleEstimator::Filter,
            number_of_scales: 5,
            scale_step: 1.01,
            newton_iterations: 50,
            scale_penalty: 1.0,
        }
    }
}

/// Where the training sample of a learned frame comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrainingSample {
    /// The reference: a new patch at the new position and scale (features and FFT again).
    Fresh,
    /// The winning detection sample, circularly shifted by the detected displacement in
    /// the Fourier domain (as ECO): no second patch, its scale is the detection scale.
    Shifted,
}

/// Appearance-model learning rates (ALGORITHM.md §6).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LearningConfig {
    /// Base rate η (ref 0.013).
    pub rate: f32,
    /// Reinforced rate when consensus ≥ `threshold_high` (ref 0.019).
    pub reinforced_rate: f32,
    /// `fresh` (reference: a new patch at the new position) or `shifted` (the detection
    /// sample shifted in the Fourier domain, half the feature work).
    pub training_sample: TrainingSample,
}

impl Default for LearningConfig {
    fn default() -> Self {
        Self {
            rate: 0.013,
            reinforced_rate: 0.019,
            training_sample: TrainingSample::Shifted,
        }
    }
}

/// Multi-frame consensus verification (ALGORITHM.md §6).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VerificationConfig {
    /// Off: learn every frame at the base rate (ablation).
    pub enabled: bool,
    /// The score that gates learning: `confidence` (the per-frame confidence, default) or
    /// `reference` (the consensus `C` with `threshold_low`/`threshold_high`, paper fidelity).
    pub score: VerificationScore,
    /// `spectral` (reference) or `frobenius_sq` (paper).
    pub norm: ConsensusNorm,
    /// At or below: do not learn (ref 0.20).
    pub threshold_low: f32,
    /// At or above: learn with the reinforced rate (ref 0.50).
    pub threshold_high: f32,
    /// Rate γ of the ideal response model (ref 0.013).
    pub response_model_rate: f32,
    /// `score: confidence`: a frame whose score is below this fraction of the running
    /// reference level is not learned (a sudden drop, e.g. an occlusion).
    pub gate_low: f32,
    /// `score: confidence`: at or above this fraction of the reference, learn at the
    /// reinforced rate (below it, the base rate).
    pub gate_high: f32,
    /// `score: confidence`: frames skipped in a row after which one frame is learned at the
    /// base rate anyway, so verification never locks the tracker out of learning.
    pub max_consecutive_skips: usize,
}

impl Default for VerificationConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            score: VerificationScore::Confidence,
            norm: ConsensusNorm::Spectral,
            threshold_low: 0.2,
            threshold_high: 0.5,
            response_model_rate: 0.013,
            gate_low: 0.3,
            gate_high: 0.5,
            max_consecutive_skips: 5,
        }
    }
}

/// Per-frame confidence (see [`crate::confidence`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ConfidenceConfig {
    /// `peak_psr` (r·q), `peak` (r: peak over the initial filter's in-sample peak) or `psr`
    /// (q: peak-to-sidelobe ratio); absolute, no running reference.
    pub measure: ConfidenceMeasure,
    /// Score at which the confidence is 0.5 (`peak_psr`: 5; `peak`: about 0.5; `psr`: about
    /// 8); confidence = score / (score + half_score).
    pub half_score: f32,
    /// Frames (after the initial one) whose mean is the learning gate's first reference
    /// level; no frame of the warm-up is skipped.
    pub warmup_frames: usize,
    /// Running-average rate of the gate's reference level, per frame (0–1).
    pub reference_rate: f32,
    /// Half-side of the square around the peak left out of the PSR sidelobe, cells.
    pub psr_exclusion_cells: usize,
}

impl Default for ConfidenceConfig {
    fn default() -> Self {
        Self {
            measure: ConfidenceMeasure::PeakPsr,
            half_score: 5.0,
            warmup_frames: 10,
            reference_rate: 0.1,
            psr_exclusion_cells: 2,
        }
    }
}

/// Track state machine (see [`crate::track_state`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackStateConfig {
    /// Confidence below this is unconfident (0–1).
    pub lost_threshold: f32,
    /// Unconfident frames in a row that make the target lost.
    pub lost_frames: usize,
}

impl Default for TrackStateConfig {
    fn default() -> Self {
        Self {
            lost_threshold: 0.3,
            lost_frames: 12,
        }
    }
}

/// Re-detection while lost (see [`crate::redetect`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RedetectionConfig {
    /// Search the frame for a lost target; off: only the window at the last known position
    /// is searched (with the same confirmation), at the scale of the loss.
    pub enabled: bool,
    /// Search windows evaluated per lost frame (the time bound; one window costs about one
    /// scale of a normal frame).
    pub windows_per_frame: usize,
    /// Scales tried, relative to the target scale when it was lost.
    pub scales: Vec<f32>,
    /// Distance between tile centres, fraction of the search-window side.
    pub tile_stride: f32,
    /// Confidence at or above which a window is a candidate (0–1).
    pub reacquire_threshold: f32,
    /// A candidate's score must also reach this fraction of the learning gate's reference
    /// level frozen on the last confident frame (0–1; 0 = off): a look-alike that the frozen
    /// filter scores far below the target it was tracking is not taken, whatever its
    /// absolute confidence.
    pub reacquire_relative: f32,
    /// Frames in a row a candidate must stay confident before the track is taken back.
    pub reacquire_frames: usize,
    /// Of `windows_per_frame`, how many go to whole-frame template-match proposals each lost
    /// frame (0 = none: only the tile walk).
    pub proposals: usize,
    /// A learned verifier that searches the frame while lost, besides the filter
    /// (`none`; `nanotrack`: NanoTrack v2 run in pure Rust, in every build; `nanotrack_ort`:
    /// the same on ONNX Runtime, cargo feature `cnn`).
    pub verifier: VerifierKind,
    /// The verifier's backbone (ONNX; NanoTrack v2, any input size); empty: the NanoTrack v2
    /// backbone embedded in the library.
    pub verifier_backbone: String,
    /// The verifier's correlation head (ONNX); empty: the embedded NanoTrack v2 head.
    pub verifier_head: String,
    /// Verifier network passes per lost frame (the time bound of the verifier; one pass
    /// is one backbone run on a 255×255 search crop plus one head run).
    pub verifier_windows: usize,
    /// Scales of the verifier's whole-frame tiles, relative to the target scale when it was
    /// lost.
    pub verifier_scales: Vec<f32>,
    /// Foreground logit margin (head classification, foreground − background) at or above
    /// which a verifier hit is a candidate.
    pub verifier_threshold: f32,
}

/// The learned re-detection verifier (`redetection.verifier`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VerifierKind {
    /// No verifier: the frozen filter decides alone.
    None,
    /// NanoTrack v2's backbone and head, template from the initial frame (the default).
    #[default]
    Nanotrack,
    /// The same networks on ONNX Runtime (cargo feature `cnn` and the runtime, from
    /// `features.cnn.runtime` or `ORT_DYLIB_PATH`): same outputs, ~4× faster per pass than
    /// tract in a release build here (README "Speed"); what the CNN presets use.
    NanotrackOrt,
}

impl Default for RedetectionConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            windows_per_frame: 8,
            scales: vec![1.0, 0.8, 1.25],
            tile_stride: 0.5,
            reacquire_threshold: 0.5,
            reacquire_relative: 0.5,
            reacquire_frames: 3,
            proposals: 4,
            verifier: VerifierKind::Nanotrack,
            verifier_backbone: String::new(),
            verifier_head: String::new(),
            verifier_windows: 16,
            verifier_scales: vec![1.0, 0.7],
            verifier_threshold: 5.0,
        }
    }
}

/// Everything the tracker can be told. See `config/bevt.yaml` for the annotated defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackerConfig {
    /// Features.
    pub features: FeatureConfig,
    /// Window geometry.
    pub window: WindowConfig,
    /// ADMM training.
    pub admm: AdmmConfig,
    /// Detection and scale.
    pub detection: DetectionConfig,
    /// The separate scale filter (used when `detection.scale_estimator: filter`).
    pub scale_filter: ScaleFilterConfig,
    /// Learning rates.
    pub learning: LearningConfig,
    /// Consensus verification and the learning gate.
    pub verification: VerificationConfig,
    /// Per-frame confidence.
    pub confidence: ConfidenceConfig,
    /// Track state machine.
    pub track_state: TrackStateConfig,
    /// Re-detection while lost.
    pub redetection: RedetectionConfig,
    /// Worker threads for the per-scale work of one frame (1 = sequential). Work runs on
    /// the caller's rayon pool; the core spawns no threads itself.
    pub threads: usize,
}

impl Default for TrackerConfig {
    fn default() -> Self {
        Self {
            features: FeatureConfig::default(),
            window: WindowConfig::default(),
            admm: AdmmConfig::default(),
            detection: DetectionConfig::default(),
            scale_filter: ScaleFilterConfig::default(),
            learning: LearningConfig::default(),
            verification: VerificationConfig::default(),
            confidence: ConfidenceConfig::default(),
            track_state: TrackStateConfig::default(),
            redetection: RedetectionConfig::default(),
            threads: 1,
        }
    }
}

/// The keys a running tracker takes at once ([`crate::BevtTracker::retune`]): thresholds,
/// rates and per-frame budgets, read on every frame. Every other key shapes what is built
/// at initialisation (window, features, filter, scales, buffers) and takes effect only for
/// a new tracker.
pub const LIVE_KEYS: &[&str] = &[
    "learning.rate",
    "learning.reinforced_rate",
    "verification.enabled",
    "verification.threshold_low",
    "verification.threshold_high",
    "verification.response_model_rate",
    "verification.gate_low",
    "verification.gate_high",
    "verification.max_consecutive_skips",
    "confidence.half_score",
    "confidence.reference_rate",
    "track_state.lost_threshold",
    "track_state.lost_frames",
    "redetection.windows_per_frame",
    "redetection.reacquire_threshold",
    "redetection.reacquire_frames",
    "redetection.reacquire_relative",
    "detection.newton_iterations",
];

impl TrackerConfig {
    /// A copy of `self` with the [`LIVE_KEYS`] of `other`: equal to `other` exactly when
    /// the two differ in live keys only.
    pub fn with_live_keys_of(&self, other: &TrackerConfig) -> TrackerConfig {
        let mut c = self.clone();
        c.learning.rate = other.learning.rate;
        c.learning.reinforced_rate = other.learning.reinforced_rate;
        let (v, o) = (&mut c.verification, &other.verification);
        v.enabled = o.enabled;
        v.threshold_low = o.threshold_low;
        v.threshold_high = o.threshold_high;
        v.response_model_rate = o.response_model_rate;
        v.gate_low = o.gate_low;
        v.gate_high = o.gate_high;
        v.max_consecutive_skips = o.max_consecutive_skips;
        c.confidence.half_score = other.confidence.half_score;
        c.confidence.reference_rate = other.confidence.reference_rate;
        c.track_state = other.track_state.clone();
        let (r, o) = (&mut c.redetection, &other.redetection);
        r.windows_per_frame = o.windows_per_frame;
        r.reacquire_threshold = o.reacquire_threshold;
        r.reacquire_frames = o.reacquire_frames;
        r.reacquire_relative = o.reacquire_relative;
        c.detection.newton_iterations = other.detection.newton_iterations;
        c
    }
}

/// The documentation of every configuration key, by dotted name (`window.padding`): the
/// doc comment of its field in this file (for `ros2 param describe` on the node). Keys of
/// sections defined elsewhere (`features.cnn`) get the section's comment.
pub fn key_docs() -> Vec<(String, String)> {
    const SOURCE: &str = include_str!("config.rs");
    /// A field: name, type, doc.
    type Field<'a> = (&'a str, &'a str, String);
    // struct name -> fields, in file order.
    let mut structs: Vec<(&str, Vec<Field<'_>>)> = Vec::new();
    let mut current: Option<usize> = None;
    let mut doc: Vec<&str> = Vec::new();
    for line in SOURCE.lines() {
        let t = line.trim();
        if let Some(name) = t
            .strip_prefix("pub struct ")
            .and_then(|r| r.strip_suffix(" {"))
        {
            structs.push((name, Vec::new()));
            current = Some(structs.len() - 1);
            doc.clear();
        } else if line.starts_with('}') {
            current = None;
            doc.clear();
        } else if let Some(d) = t.strip_prefix("///") {
            doc.push(d.trim());
        } else if t.starts_with("#[") {
            // attributes between a doc comment and its field
        } else if let (Some(i), Some((field, ty))) = (
            current,
            t.strip_prefix("pub ").and_then(|r| r.split_once(':')),
        ) {
            let ty = ty.trim().trim_end_matches(',');
            structs[i].1.push((field, ty, doc.join(" ")));
            doc.clear();
        } else {
            doc.clear();
        }
    }
    let fields_of = |name: &str| structs.iter().find(|(n, _)| *n == name).map(|(_, f)| f);
    let mut out = Vec::new();
    for (section, ty, doc) in fields_of("TrackerConfig").into_iter().flatten() {
        match fields_of(ty) {
            Some(fields) => {
                for (field, _, d) in fields {
                    out.push((format!("{section}.{field}"), d.clone()));
                }
            }
            None => out.push((section.to_string(), doc.clone())),
        }
    }
    out
}

/// A validated configuration: what the tracker is built from.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackerSpec {
    /// The validated configuration.
    pub config: TrackerConfig,
    /// ADMM parameters.
    pub admm: AdmmParams,
    /// Verification parameters.
    pub verify: VerifyParams,
    /// Learning gate of `verification.score: confidence`.
    pub gate: GateParams,
    /// Confidence parameters.
    pub confidence: ConfidenceParams,
    /// State machine parameters.
    pub states: StateParams,
    /// Re-detection parameters.
    pub redetect: RedetectParams,
    /// Scale-filter parameters.
    pub scale_filter: ScaleFilterParams,
}

/// Largest number of re-detection scales.
const MAX_REDETECT_SCALES: usize = 8;
/// Largest re-detection budget, windows per lost frame.
const MAX_WINDOWS_PER_FRAME: usize = 256;
/// Largest gate threshold, fraction of the reference level.
const MAX_GATE: f32 = 10.0;
/// Largest `confidence.half_score`.
const MAX_HALF_SCORE: f32 = 1e6;
/// Largest frame count of the state and confidence windows.
const MAX_FRAMES_KEY: usize = 10_000;

fn unit(v: f32) -> bool {
    v.is_finite() && (0.0..=1.0).contains(&v)
}

fn check(
    ok: bool,
    field: &'static str,
    value: impl ToString,
    expected: &'static str,
) -> Result<(), ConfigError> {
    if ok {
        Ok(())
    } else {
        Err(ConfigError::OutOfRange {
            field,
            value: value.to_string(),
            expected,
        })
    }
}

/// Largest `window.search_area_scale` (ref 5).
const MAX_SEARCH_AREA_SCALE: f32 = 10.0;
/// Largest `window.padding` (ref 1.2).
const MAX_PADDING: f32 = 3.0;
/// Largest feature grid side, cells (ref 60).
const MAX_GRID_SIDE: usize = 128;
/// Largest patch side, pixels (ref 240).
const MAX_PATCH_SIDE: usize = 512;
/// Most patch pixels sampled per frame over all scales (ref 5 · 240² ≈ 0.29 M).
const MAX_PATCH_PIXELS: usize = 2 << 20;
/// Most ADMM iterations per training (ref 3); each costs FFTs of every channel.
const MAX_ADMM_ITERATIONS: usize = 20;
/// Largest `admm.mu_init`, `admm.lambda` and penalty-window value.
const MAX_ADMM_VALUE: f32 = 1e6;
/// Largest `admm.mu_max` (ref 1e4).
const MAX_ADMM_MU: f32 = 1e9;
/// Largest `admm.beta` (ref 20).
const MAX_ADMM_BETA: f32 = 1000.0;
/// Most Newton iterations of the sub-cell peak (ref 50).
const MAX_NEWTON_ITERATIONS: usize = 100;

fn finite_pos(v: f32) -> bool {
    v.is_finite() && v > 0.0
}

impl TrackerConfig {
    /// Checks every field once and derives the solver parameters.
    ///
    /// # Errors
    /// [`ConfigError`] naming the first offending field.
    pub fn validate(&self) -> Result<TrackerSpec, ConfigError> {
        let f = &self.features;
        check(
            (1..=16).contains(&f.hog_cell_size),
            "features.hog_cell_size",
            f.hog_cell_size,
            "1..=16 pixels",
        )?;
        check(
            f.gain.is_finite() && f.gain > 0.0 && f.gain <= 1e4,
            "features.gain",
            f.gain,
            "(0, 1e4]",
        )?;
        if f.kind == FeatureKind::Cnn {
            f.cnn
                .as_ref()
                .ok_or_else(|| {
                    ConfigError::Inconsistent(
                        "features.kind is cnn but the features.cnn section is missing".to_string(),
                    )
                })?
                .validate()?;
        }
        let w = &self.window;
        // Work per frame grows with search_area_scale² (frame pixels read per scale).
        check(
            (1.0..=MAX_SEARCH_AREA_SCALE).contains(&w.search_area_scale),
            "window.search_area_scale",
            w.search_area_scale,
            "1..=10",
        )?;
        check(
            (1.0..=MAX_PADDING).contains(&w.padding),
            "window.padding",
            w.padding,
            "1..=3",
        )?;
        check(
            finite_pos(w.filter_max_area)
                && w.filter_max_area >= 16.0
                && w.filter_max_area <= 65536.0,
            "window.filter_max_area",
            w.filter_max_area,
            "16..=65536 cells²",
        )?;
        check(
            finite_pos(w.cell_selection_thresh) && w.cell_selection_thresh <= 1.0,
            "window.cell_selection_thresh",
            w.cell_selection_thresh,
            "(0, 1]",
        )?;
        check(
            finite_pos(w.output_sigma_factor) && w.output_sigma_factor <= 1.0,
            "window.output_sigma_factor",
            w.output_sigma_factor,
            "(0, 1]",
        )?;
        // Memory and work of one frame: the feature grid is at most
        // round(sqrt(filter_max_area) · padding) cells a side, the patch that many cells of
        // hog_cell_size pixels, and one patch is sampled per scale.
        let grid_side = (w.filter_max_area.sqrt() * w.padding).round() + 1.0;
        check(
            grid_side <= MAX_GRID_SIDE as f32,
            "window.filter_max_area",
            format!(
                "{} (grid side sqrt(filter_max_area) · padding = {grid_side} cells)",
                w.filter_max_area
            ),
            "sqrt(window.filter_max_area) · window.padding <= 128 cells",
        )?;
        let patch_side = grid_side * f.hog_cell_size as f32;
        check(
            patch_side <= MAX_PATCH_SIDE as f32,
            "features.hog_cell_size",
            format!(
                "{} (patch side grid side · hog_cell_size = {patch_side} px)",
                f.hog_cell_size
            ),
            "grid side (sqrt(window.filter_max_area) · window.padding) · features.hog_cell_size <= 512 px",
        )?;
        let patch_pixels = patch_side * patch_side * self.detection.number_of_scales as f32;
        check(
            patch_pixels <= MAX_PATCH_PIXELS as f32,
            "detection.number_of_scales",
            format!(
                "{} ({patch_pixels} patch pixels per frame)",
                self.detection.number_of_scales
            ),
            "number_of_scales · patch side² <= 2 M pixels per frame",
        )?;
        let a = &self.admm;
        check(
            (1..=MAX_ADMM_ITERATIONS).contains(&a.iterations),
            "admm.iterations",
            a.iterations,
            "1..=20",
        )?;
        check(
            finite_pos(a.mu_init) && a.mu_init <= MAX_ADMM_VALUE,
            "admm.mu_init",
            a.mu_init,
            "(0, 1e6]",
        )?;
        check(
            (1.0..=MAX_ADMM_BETA).contains(&a.beta),
            "admm.beta",
            a.beta,
            "1..=1000",
        )?;
        check(
            finite_pos(a.mu_max) && a.mu_max >= a.mu_init && a.mu_max <= MAX_ADMM_MU,
            "admm.mu_max",
            a.mu_max,
            "admm.mu_init..=1e9",
        )?;
        check(
            (0.0..=MAX_ADMM_VALUE).contains(&a.lambda),
            "admm.lambda",
            a.lambda,
            "0..=1e6",
        )?;
        check(
            (0.0..=MAX_ADMM_VALUE).contains(&a.reg_window_min),
            "admm.reg_window_min",
            a.reg_window_min,
            "0..=1e6",
        )?;
        check(
            a.reg_window_edge >= a.reg_window_min && a.reg_window_edge <= MAX_ADMM_VALUE,
            "admm.reg_window_edge",
            a.reg_window_edge,
            "admm.reg_window_min..=1e6",
        )?;
        check(
            a.spatial_weight.is_finite() && a.spatial_weight >= 0.0 && a.spatial_weight <= 1e6,
            "admm.spatial_weight",
            a.spatial_weight,
            "[0, 1e6]",
        )?;
        check(
            a.temporal.is_finite() && a.temporal >= 0.0 && a.temporal <= MAX_ADMM_VALUE,
            "admm.temporal",
            a.temporal,
            "[0, 1e6]",
        )?;
        let d = &self.detection;
        check(
            d.number_of_scales >= 1 && d.number_of_scales <= 33,
            "detection.number_of_scales",
            d.number_of_scales,
            "1..=33",
        )?;
        check(
            d.scale_step.is_finite() && d.scale_step > 1.0 && d.scale_step < 2.0,
            "detection.scale_step",
            d.scale_step,
            "(1, 2)",
        )?;
        // Each Newton iteration evaluates the response spectrum once (O(grid cells)).
        check(
            d.newton_iterations <= MAX_NEWTON_ITERATIONS,
            "detection.newton_iterations",
            d.newton_iterations,
            "0..=100",
        )?;
        check(
            d.scale_penalty.is_finite() && d.scale_penalty > 0.0 && d.scale_penalty <= 1.0,
            "detection.scale_penalty",
            d.scale_penalty,
            "(0, 1]",
        )?;
        let sf = &self.scale_filter;
        check(
            (3..=65).contains(&sf.scales),
            "scale_filter.scales",
            sf.scales,
            "3..=65",
        )?;
        check(
            sf.interpolated_scales >= sf.scales && sf.interpolated_scales <= 257,
            "scale_filter.interpolated_scales",
            sf.interpolated_scales,
            "scale_filter.scales..=257",
        )?;
        check(
            sf.step.is_finite() && sf.step > 1.0 && sf.step < 1.5,
            "scale_filter.step",
            sf.step,
            "(1, 1.5)",
        )?;
        check(
            sf.learning_rate.is_finite() && sf.learning_rate > 0.0 && sf.learning_rate <= 1.0,
            "scale_filter.learning_rate",
            sf.learning_rate,
            "(0, 1]",
        )?;
        check(
            finite_pos(sf.sigma_factor) && sf.sigma_factor <= 10.0,
            "scale_filter.sigma_factor",
            sf.sigma_factor,
            "(0, 10]",
        )?;
        check(
            sf.lambda.is_finite() && sf.lambda >= 0.0,
            "scale_filter.lambda",
            sf.lambda,
            ">= 0",
        )?;
        check(
            (1..=16).contains(&sf.cell_size),
            "scale_filter.cell_size",
            sf.cell_size,
            "1..=16 pixels",
        )?;
        check(
            sf.sample_side >= 2 * sf.cell_size && sf.sample_side <= 256,
            "scale_filter.sample_side",
            sf.sample_side,
            "2·scale_filter.cell_size..=256 pixels",
        )?;
        check(
            sf.padding.is_finite() && (1.0..=4.0).contains(&sf.padding),
            "scale_filter.padding",
            sf.padding,
            "[1, 4]",
        )?;
        let l = &self.learning;
        check(
            l.rate.is_finite() && (0.0..=1.0).contains(&l.rate),
            "learning.rate",
            l.rate,
            "[0, 1]",
        )?;
        check(
            l.reinforced_rate.is_finite() && (0.0..=1.0).contains(&l.reinforced_rate),
            "learning.reinforced_rate",
            l.reinforced_rate,
            "[0, 1]",
        )?;
        let v = &self.verification;
        check(
            v.threshold_low.is_finite() && (0.0..=1.0).contains(&v.threshold_low),
            "verification.threshold_low",
            v.threshold_low,
            "[0, 1]",
        )?;
        check(
            v.threshold_high.is_finite() && (0.0..=1.0).contains(&v.threshold_high),
            "verification.threshold_high",
            v.threshold_high,
            "[0, 1]",
        )?;
        if v.threshold_high < v.threshold_low {
            return Err(ConfigError::Inconsistent(format!(
                "verification.threshold_high ({}) is below threshold_low ({})",
                v.threshold_high, v.threshold_low
            )));
        }
        check(
            v.response_model_rate.is_finite() && (0.0..=1.0).contains(&v.response_model_rate),
            "verification.response_model_rate",
            v.response_model_rate,
            "[0, 1]",
        )?;
        check(
            v.gate_low.is_finite() && (0.0..=MAX_GATE).contains(&v.gate_low),
            "verification.gate_low",
            v.gate_low,
            "[0, 10] (fraction of the reference level)",
        )?;
        check(
            v.gate_high.is_finite() && v.gate_high >= v.gate_low && v.gate_high <= MAX_GATE,
            "verification.gate_high",
            v.gate_high,
            "[verification.gate_low, 10]",
        )?;
        check(
            v.max_consecutive_skips <= MAX_FRAMES_KEY,
            "verification.max_consecutive_skips",
            v.max_consecutive_skips,
            "0..=10000 frames",
        )?;
        let c = &self.confidence;
        check(
            (1..=MAX_FRAMES_KEY).contains(&c.warmup_frames),
            "confidence.warmup_frames",
            c.warmup_frames,
            "1..=10000 frames",
        )?;
        check(
            unit(c.reference_rate),
            "confidence.reference_rate",
            c.reference_rate,
            "[0, 1] per frame",
        )?;
        check(
            c.half_score.is_finite() && c.half_score > 0.0 && c.half_score <= MAX_HALF_SCORE,
            "confidence.half_score",
            c.half_score,
            "(0, 1e6]",
        )?;
        check(
            c.psr_exclusion_cells <= 64,
            "confidence.psr_exclusion_cells",
            c.psr_exclusion_cells,
            "0..=64 cells",
        )?;
        let t = &self.track_state;
        check(
            unit(t.lost_threshold),
            "track_state.lost_threshold",
            t.lost_threshold,
            "[0, 1]",
        )?;
        check(
            (1..=MAX_FRAMES_KEY).contains(&t.lost_frames),
            "track_state.lost_frames",
            t.lost_frames,
            "1..=10000 frames",
        )?;
        let r = &self.redetection;
        check(
            (1..=MAX_WINDOWS_PER_FRAME).contains(&r.windows_per_frame),
            "redetection.windows_per_frame",
            r.windows_per_frame,
            "1..=256 windows",
        )?;
        check(
            !r.scales.is_empty()
                && r.scales.len() <= MAX_REDETECT_SCALES
                && r.scales
                    .iter()
                    .all(|s| s.is_finite() && (0.25..=4.0).contains(s)),
            "redetection.scales",
            format!("{:?}", r.scales),
            "1 to 8 factors in [0.25, 4]",
        )?;
        check(
            r.tile_stride.is_finite() && (0.1..=1.0).contains(&r.tile_stride),
            "redetection.tile_stride",
            r.tile_stride,
            "[0.1, 1] window sides",
        )?;
        check(
            unit(r.reacquire_threshold),
            "redetection.reacquire_threshold",
            r.reacquire_threshold,
            "[0, 1]",
        )?;
        check(
            unit(r.reacquire_relative),
            "redetection.reacquire_relative",
            r.reacquire_relative,
            "[0, 1]",
        )?;
        check(
            (1..=MAX_FRAMES_KEY).contains(&r.reacquire_frames),
            "redetection.reacquire_frames",
            r.reacquire_frames,
            "1..=10000 frames",
        )?;
        check(
            r.proposals <= r.windows_per_frame,
            "redetection.proposals",
            r.proposals,
            "0..=windows_per_frame",
        )?;
        check(
            (1..=MAX_WINDOWS_PER_FRAME).contains(&r.verifier_windows),
            "redetection.verifier_windows",
            r.verifier_windows,
            "1..=256 passes",
        )?;
        check(
            !r.verifier_scales.is_empty()
                && r.verifier_scales.len() <= MAX_REDETECT_SCALES
                && r.verifier_scales
                    .iter()
                    .all(|s| s.is_finite() && (0.25..=4.0).contains(s)),
            "redetection.verifier_scales",
            format!("{:?}", r.verifier_scales),
            "1 to 8 factors in [0.25, 4]",
        )?;
        check(
            r.verifier_threshold.is_finite() && r.verifier_threshold.abs() <= 100.0,
            "redetection.verifier_threshold",
            r.verifier_threshold,
            "a logit margin in [-100, 100]",
        )?;
        check(
            (1..=256).contains(&self.threads),
            "threads",
            self.threads,
            "1..=256",
        )?;
        Ok(TrackerSpec {
            config: self.clone(),
            admm: AdmmParams {
                iterations: a.iterations,
                mu_init: a.mu_init,
                beta: a.beta,
                mu_max: a.mu_max,
                lambda: a.lambda,
                penalty: a.penalty,
                spatial_weight: a.spatial_weight,
                temporal: a.temporal,
            },
            scale_filter: ScaleFilterParams {
                scales: sf.scales,
                interpolated_scales: sf.interpolated_scales,
                step: sf.step,
                learning_rate: sf.learning_rate,
                sigma_factor: sf.sigma_factor,
                lambda: sf.lambda,
                sample_side: sf.sample_side,
                cell: sf.cell_size,
                padding: sf.padding,
                colornames: sf.colornames,
            },
            verify: VerifyParams {
                norm: v.norm,
                threshold_low: v.threshold_low,
                threshold_high: v.threshold_high,
                rate: l.rate,
                reinforced_rate: l.reinforced_rate,
            },
            gate: GateParams {
                skip_below: v.gate_low,
                reinforce_from: v.gate_high,
                rate: l.rate,
                reinforced_rate: l.reinforced_rate,
                max_consecutive_skips: v.max_consecutive_skips,
            },
            confidence: ConfidenceParams {
                measure: c.measure,
                half_score: c.half_score,
                warmup_frames: c.warmup_frames,
                reference_rate: c.reference_rate,
                psr_exclusion: c.psr_exclusion_cells,
            },
            states: StateParams {
                lost_threshold: t.lost_threshold,
                lost_frames: t.lost_frames,
            },
            redetect: RedetectParams {
                enabled: r.enabled,
                windows_per_frame: r.windows_per_frame,
                scales: r.scales.clone(),
                tile_stride: r.tile_stride,
                reacquire_threshold: r.reacquire_threshold,
                reacquire_relative: r.reacquire_relative,
                reacquire_frames: r.reacquire_frames,
                proposals: r.proposals,
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_config_is_valid() {
        TrackerConfig::default().validate().unwrap();
    }

    #[test]
    fn bad_values_name_their_field() {
        let mut c = TrackerConfig::default();
        c.admm.iterations = 0;
        match c.validate() {
            Err(ConfigError::OutOfRange { field, .. }) => assert_eq!(field, "admm.iterations"),
            other => panic!("{other:?}"),
        }
        let mut c = TrackerConfig::default();
        c.detection.scale_step = f32::NAN;
        assert!(c.validate().is_err());
        for (set, key) in [
            (
                (|c: &mut TrackerConfig| c.admm.spatial_weight = -1.0) as fn(&mut TrackerConfig),
                "admm.spatial_weight",
            ),
            (|c| c.admm.temporal = f32::NAN, "admm.temporal"),
            (|c| c.admm.temporal = -1.0, "admm.temporal"),
            (|c| c.scale_filter.scales = 1, "scale_filter.scales"),
            (
                |c| c.scale_filter.interpolated_scales = 5,
                "scale_filter.interpolated_scales",
            ),
            (|c| c.scale_filter.step = 1.0, "scale_filter.step"),
            (|c| c.scale_filter.padding = 0.5, "scale_filter.padding"),
            (
                |c| c.scale_filter.learning_rate = 0.0,
                "scale_filter.learning_rate",
            ),
            (
                |c| c.scale_filter.sigma_factor = f32::NAN,
                "scale_filter.sigma_factor",
            ),
            (|c| c.scale_filter.lambda = -0.1, "scale_filter.lambda"),
            (|c| c.scale_filter.cell_size = 0, "scale_filter.cell_size"),
            (
                |c| c.scale_filter.sample_side = 6,
                "scale_filter.sample_side",
            ),
        ] {
            let mut c = TrackerConfig::default();
            set(&mut c);
            match c.validate() {
                Err(ConfigError::OutOfRange { field, .. }) => assert_eq!(field, key),
                other => panic!("{key}: {other:?}"),
            }
        }
        let mut c = TrackerConfig::default();
        c.verification.threshold_high = 0.1;
        assert!(matches!(c.validate(), Err(ConfigError::Inconsistent(_))));
        for (field, edit) in [
            (
                "verification.gate_high",
                (|c: &mut TrackerConfig| c.verification.gate_high = 0.1) as fn(&mut TrackerConfig),
            ),
            ("confidence.warmup_frames", |c| {
                c.confidence.warmup_frames = 0
            }),
            ("confidence.reference_rate", |c| {
                c.confidence.reference_rate = f32::NAN
            }),
            ("track_state.lost_frames", |c| c.track_state.lost_frames = 0),
            ("track_state.lost_threshold", |c| {
                c.track_state.lost_threshold = 1.5
            }),
            ("redetection.windows_per_frame", |c| {
                c.redetection.windows_per_frame = 0
            }),
            ("redetection.scales", |c| c.redetection.scales.clear()),
            ("redetection.scales", |c| {
                c.redetection.scales = vec![1.0, 9.0]
            }),
            ("redetection.tile_stride", |c| {
                c.redetection.tile_stride = 0.0
            }),
            ("redetection.proposals", |c| {
                c.redetection.proposals = c.redetection.windows_per_frame + 1
            }),
            ("redetection.reacquire_frames", |c| {
                c.redetection.reacquire_frames = 0
            }),
            ("redetection.reacquire_relative", |c| {
                c.redetection.reacquire_relative = -0.1
            }),
            ("redetection.reacquire_relative", |c| {
                c.redetection.reacquire_relative = f32::NAN
            }),
        ] {
            let mut c = TrackerConfig::default();
            edit(&mut c);
            match c.validate() {
                Err(ConfigError::OutOfRange { field: f, .. }) => assert_eq!(f, field),
                other => panic!("{field}: {other:?}"),
            }
        }
    }

    #[test]
    fn values_implying_unbounded_work_or_memory_are_refused_by_name() {
        type Set = fn(&mut TrackerConfig, f32);
        let cases: [(&str, Set); 9] = [
            ("window.padding", |c, v| c.window.padding = v),
            ("window.search_area_scale", |c, v| {
                c.window.search_area_scale = v
            }),
            ("window.filter_max_area", |c, v| {
                c.window.filter_max_area = v
            }),
            ("window.output_sigma_factor", |c, v| {
                c.window.output_sigma_factor = v
            }),
            ("admm.mu_init", |c, v| c.admm.mu_init = v),
            ("admm.beta", |c, v| c.admm.beta = v),
            ("admm.lambda", |c, v| c.admm.lambda = v),
            ("detection.scale_penalty", |c, v| {
                c.detection.scale_penalty = v
            }),
            ("features.gain", |c, v| c.features.gain = v),
        ];
        for (name, set) in cases {
            for v in [1e30, 1e20, 1e7, f32::NAN, f32::INFINITY, -1.0, -1e-30] {
                let mut c = TrackerConfig::default();
                set(&mut c, v);
                let e = c.validate().map(|_| ()).unwrap_err().to_string();
                assert!(e.contains(name), "{name} = {v}: {e}");
            }
        }
        for (v, set) in [
            (1000.0, (|c, v| c.window.padding = v) as Set),
            (1000.0, |c, v| c.window.search_area_scale = v),
            (65536.0, |c, v| c.window.search_area_scale = v),
        ] {
            let mut c = TrackerConfig::default();
            set(&mut c, v);
            assert!(c.validate().is_err(), "{v}");
        }
        // Combinations: the grid, the patch and the per-frame patch pixels are bounded.
        let mut c = TrackerConfig::default();
        c.window.filter_max_area = 65536.0;
        c.window.padding = 3.0;
        assert!(c
            .validate()
            .unwrap_err()
            .to_string()
            .contains("filter_max_area"));
        let mut c = TrackerConfig::default();
        c.window.filter_max_area = 10000.0;
        c.features.hog_cell_size = 16;
        assert!(c
            .validate()
            .unwrap_err()
            .to_string()
            .contains("hog_cell_size"));
        let mut c = TrackerConfig::default();
        c.window.filter_max_area = 6400.0;
        c.detection.number_of_scales = 33;
        assert!(c
            .validate()
            .unwrap_err()
            .to_string()
            .contains("number_of_scales"));
        let mut c = TrackerConfig::default();
        c.detection.newton_iterations = 101;
        assert!(c.validate().is_err());
        let mut c = TrackerConfig::default();
        c.admm.iterations = 21;
        assert!(c.validate().is_err());
        // The largest accepted values still validate.
        let mut c = TrackerConfig::default();
        c.window.search_area_scale = 10.0;
        c.window.padding = 2.0;
        c.detection.newton_iterations = 100;
        c.admm.iterations = 20;
        c.validate().unwrap();
    }

    #[test]
    fn default_equals_the_shipped_yaml() {
        let text = include_str!("../../config/bevt.yaml");
        let c: TrackerConfig = serde_norway::from_str(text).unwrap();
        assert_eq!(c, TrackerConfig::default());
    }

    #[test]
    fn default_is_the_reference_plus_the_fast_mode_and_issue_8() {
        let text = include_str!("../../config/bevt_reference.yaml");
        let mut c: TrackerConfig = serde_norway::from_str(text).unwrap();
        assert_ne!(c, TrackerConfig::default());
        // The fast-mode additions (README "Ablation").
        c.features.colornames = true;
        c.detection.scale_estimator = ScaleEstimator::Filter;
        c.learning.training_sample = TrainingSample::Shifted;
        c.admm.penalty = PenaltyKind::Elementwise;
        // The scale filter for 10 fps footage, with colour names in its samples (README
        // "Ablation"); the reference file keeps fDSST's values.
        c.scale_filter.step = 1.03;
        c.scale_filter.learning_rate = 0.075;
        c.scale_filter.colornames = true;
        // Issue 8: the confidence gate, the lost state and re-detection.
        c.verification.score = VerificationScore::Confidence;
        c.track_state = TrackStateConfig::default();
        c.redetection = RedetectionConfig::default();
        assert_eq!(c, TrackerConfig::default());
        // Issue 9: the NanoTrack verifier, embedded models (no file at run time).
        let r = &TrackerConfig::default().redetection;
        assert_eq!(r.verifier, VerifierKind::Nanotrack);
        assert!(r.verifier_backbone.is_empty() && r.verifier_head.is_empty());
    }

    #[test]
    fn reference_yaml_keeps_the_reference() {
        let text = include_str!("../../config/bevt_reference.yaml");
        let c: TrackerConfig = serde_norway::from_str(text).unwrap();
        c.validate().unwrap();
        assert!(!c.features.colornames);
        assert_eq!(c.detection.scale_estimator, ScaleEstimator::Search);
        assert_eq!(c.detection.number_of_scales, 5);
        assert_eq!(c.detection.scale_step, 1.01);
        assert_eq!(c.admm.penalty, PenaltyKind::Matrix);
        assert_eq!(c.learning.training_sample, TrainingSample::Fresh);
        assert_eq!(
            (c.learning.rate, c.learning.reinforced_rate),
            (0.013, 0.019)
        );
        let v = &c.verification;
        assert!(v.enabled);
        assert_eq!(v.norm, ConsensusNorm::Spectral);
        assert_eq!(v.score, VerificationScore::Reference);
        assert_eq!((v.threshold_low, v.threshold_high), (0.2, 0.5));
        assert!(!c.redetection.enabled);
        assert_eq!(c.redetection.verifier, VerifierKind::None);
        assert_eq!(c.track_state.lost_threshold, 0.0);
    }

    #[test]
    fn missing_keys_take_defaults_and_unknown_keys_are_rejected() {
        let c: TrackerConfig = serde_norway::from_str("admm:\n  iterations: 2\n").unwrap();
        assert_eq!(c.admm.iterations, 2);
        assert_eq!(c.detection, DetectionConfig::default());
        assert!(serde_norway::from_str::<TrackerConfig>("admm:\n  iteratons: 2\n").is_err());
        assert!(serde_norway::from_str::<TrackerConfig>("admm:\n  penalty: bogus\n").is_err());
        assert!(
            serde_norway::from_str::<TrackerConfig>("detection:\n  scale_estimator: dsst\n")
                .is_err()
        );
        assert!(serde_norway::from_str::<TrackerConfig>("features:\n  colornames: 3\n").is_err());
        assert!(
            serde_norway::from_str::<TrackerConfig>("learning:\n  training_sample: new\n").is_err()
        );
        assert!(serde_norway::from_str::<TrackerConfig>("scale_filter:\n  scals: 3\n").is_err());
        let e = serde_norway::from_str::<TrackerConfig>("scale_filter:\n  colornames: 3\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("colornames"), "{e}");
    }

    #[test]
    fn yaml_round_trips() {
        let mut c = TrackerConfig::default();
        c.admm.penalty = PenaltyKind::Elementwise;
        c.verification.norm = ConsensusNorm::FrobeniusSq;
        c.detection.scale_estimator = ScaleEstimator::Filter;
        c.features.colornames = !c.features.colornames;
        c.learning.training_sample = TrainingSample::Shifted;
        let s = serde_norway::to_string(&c).unwrap();
        let d: TrackerConfig = serde_norway::from_str(&s).unwrap();
        assert_eq!(c, d);
    }
}
