//! Tracker configuration: user-facing [`TrackerConfig`] (serde, strict) validated once into
//! a [`TrackerSpec`] that the rest of the core trusts.
//!
//! `TrackerConfig::default()` equals `config/bevt.yaml` (a test checks it). Every number of
//! ALGORITHM.md is a field here; where the paper and the reference MATLAB differ the choice
//! is an enum, and its default is documented on the field.

use crate::confidence::ConfidenceMeasure;
use crate::consensus::{ConsensusNorm, GateParams, VerificationScore, VerifyParams};
use crate::error::ConfigError;
use crate::features::cnn_config::CnnConfig;
use crate::filter::admm::PenaltyKind;
use serde::{Deserialize, Serialize};

pub mod keys;
pub use keys::{cnn_spec, live_keys, KeySpec, Kind, Range, CNN_KEYS, TRACKER_KEYS};

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
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
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
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackStateConfig {
    /// Confidence below this is unconfident (0–1).
    pub lost_threshold: f32,
    /// Unconfident frames in a row that make the target lost.
    pub lost_frames: usize,
    /// Drift check: every this many confident frames the learned verifier
    /// (`redetection.verifier`) scores the box against the first frame's template; 0 = off
    /// (also off without a verifier). One pass costs about one tracked frame.
    pub drift_check_frames: usize,
    /// The drift check's interval while calm (the last check scored at least
    /// `redetection.verifier_threshold` and the learning gate refused no frame since);
    /// at most `drift_check_frames` = no lengthening.
    pub drift_calm_frames: usize,
    /// Verifier score (logit margin) below which a drift check makes the state uncertain.
    pub drift_threshold: f32,
    /// After a failed drift check, the next one this many confident frames later; failing
    /// it too makes the track lost on drift. 0: a failed check never makes it lost (it
    /// is re-checked every `drift_check_frames`).
    pub drift_recheck_frames: usize,
    /// Ask the verifier on an unconfident (`uncertain`) frame; a hit at or above
    /// `redetection.verifier_threshold` whose centre is at the box (inside it, one cell of
    /// the verifier's grid to spare) reports it `tracking` (reason: confirmed).
    pub verify_low_confidence: bool,
    /// Let the first frame's filter, frozen at initialisation, answer a periodic drift
    /// check: when its confidence on the frame reaches `redetection.reacquire_threshold`
    /// with its peak within 3 cells of the live filter's, the check agrees without a
    /// verifier pass. Re-checks, the check at once after any other state (a
    /// re-acquisition, an uncertain frame) and low-confidence confirmations always ask the
    /// verifier.
    pub drift_anchor: bool,
    /// Let the learned box's head pass of the frame (`box_refine`, the same network and
    /// first-frame template as the verifier) answer what it can: a periodic drift check
    /// agrees, and a low-confidence frame is confirmed, without a verifier pass when the
    /// head's foreground logit margin at the box reaches `redetection.verifier_threshold`.
    /// It never disputes a box: below the bar the verifier is asked as before.
    pub drift_head: bool,
}

impl Default for TrackStateConfig {
    fn default() -> Self {
        Self {
            lost_threshold: 0.3,
            lost_frames: 12,
            drift_check_frames: 15,
            drift_calm_frames: 0,
            drift_threshold: 4.0,
            drift_recheck_frames: 3,
            verify_low_confidence: true,
            drift_anchor: true,
            drift_head: true,
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
    /// A verifier candidate confirmed for `reacquire_frames` frames takes the track back
    /// only when the frozen filter, evaluated there, would make it a candidate too
    /// (`reacquire_threshold`, `reacquire_relative`). Off by default: it refuses a
    /// look-alike, but on the dev set also the real target after a long loss.
    pub verifier_filter_check: bool,
    /// On a lost frame the verifier's first tile pass goes to the frozen filter's most
    /// confident window of the frame (while no verifier candidate is being followed): the
    /// cheap witness points, the learned one checks there before walking its tiles on.
    /// Off by default: it re-acquires sooner with fewer passes, but the states flag the
    /// failures that remain less precisely (docs/states.md).
    pub verifier_filter_hint: bool,
    /// On a lost frame the verifier's first passes (after the filter's hint, if taken) go to
    /// the best whole-frame template-match proposals ([`crate::redetect::propose`], at the
    /// scale of the loss) before the tile walk: a cheap prior over the whole frame orders
    /// the expensive search. 0 = the tile walk alone.
    pub verifier_proposals: usize,
    /// Side of the verifier's whole-frame tiles in grid points, even: a tile is a square of
    /// `16·n − 1` pixels at NanoTrack's resolution (16: NanoTrack's 255-pixel search crop),
    /// so a larger tile covers more of the frame in one pass at a cost that goes with its
    /// area. Candidates, hints and proposals keep the 16-cell crop.
    pub verifier_tile_cells: usize,
    /// Whether the frozen filter sweeps the frame (whole-frame proposals and the tile walk,
    /// within `windows_per_frame`) while lost, or only follows the last position and its
    /// candidate: `auto` sweeps only when no verifier searches (`verifier: none`) or the
    /// verifier asks for the filter's hint (`verifier_filter_hint`); `always` sweeps beside
    /// the verifier too.
    pub filter_search: FilterSearch,
}

/// Whether the frozen filter sweeps the frame while lost (`redetection.filter_search`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FilterSearch {
    /// The filter sweeps only when no verifier does (or the verifier takes its hint); with
    /// a verifier it evaluates the last position and its candidate: two windows at most.
    #[default]
    Auto,
    /// The filter sweeps beside the verifier (up to `windows_per_frame` windows a frame).
    Always,
}

impl FilterSearch {
    /// Whether the filter sweeps, given whether a verifier searches the lost frames and
    /// whether it takes the filter's hint.
    pub fn sweeps(self, verifier: bool, hint: bool) -> bool {
        match self {
            FilterSearch::Always => true,
            FilterSearch::Auto => !verifier || hint,
        }
    }
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
    /// `features.cnn.runtime` or `ORT_DYLIB_PATH`): same outputs, faster per pass than the
    /// pure-Rust engine (docs/benchmarks.md); what the CNN presets use.
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
            verifier_filter_check: false,
            verifier_filter_hint: false,
            verifier_proposals: 0,
            verifier_tile_cells: 16,
            filter_search: FilterSearch::Auto,
        }
    }
}

/// The learned box on the filter (see [`crate::box_refine`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BoxRefineConfig {
    /// `none`: the box is the filter's (first frame's aspect, scale filter); `nanotrack`:
    /// NanoTrack v2's head regresses the box on a search crop at the filter's position each
    /// tracked frame (pure Rust); `nanotrack_ort`: the same on ONNX Runtime (cargo feature
    /// `cnn`). The networks are `redetection.verifier_backbone` / `verifier_head`.
    pub mode: BoxRefineMode,
    /// Head foreground probability at or above which its box is taken (else the prior is
    /// kept).
    pub min_score: f32,
    /// Largest distance between the head's and the filter's box centres, in target sizes
    /// (√(w·h)), for the head's box to be taken.
    pub max_offset: f32,
    /// Targets whose shorter side is below this (pixels) keep the prior box.
    pub min_side: f32,
    /// Weight of the head's centre against the filter's when the head's box is taken (0:
    /// the filter's centre, 1: the head's).
    pub center_weight: f32,
    /// Weight of the head's centre in the *reported* box when its box is taken (0: the
    /// track's centre; 1: the head's). Unlike `center_weight` the filter's track and the
    /// lost-state search keep their own centre; the offset is held between head runs and
    /// dropped when the head refuses or the track is lost.
    pub report_center: f32,
    /// NanoTrack's scale/aspect-change penalty `k`: score × exp(−k·(r·s − 1)).
    pub penalty_k: f32,
    /// NanoTrack's cosine-window weight on the penalised score map.
    pub window_influence: f32,
    /// NanoTrack's size learning rate (times the chosen point's penalised score).
    pub size_rate: f32,
    /// Where the head's box is read: `filter` (at the filter's position, ATOM/DiMP's
    /// division of labour) or `peak` (NanoTrack's penalised, windowed arg-max).
    pub read: BoxRead,
    /// Smallest IoU between the head's box and the filter's (filter centre, current box
    /// size) for the head's box to be taken (0: no IoU gate).
    pub min_iou: f32,
    /// Largest relative change of the box's width or height in one frame from the head
    /// (0.1: at most ×1.1 or ÷1.1).
    pub max_change: f32,
    /// The head's size also sets the filter's scale (its window and the scale filter's
    /// next estimate); `false`: it sets only the reported box.
    pub feed_scale: bool,
    /// What the head's box is blended into each frame: `box` (the previous box moved by
    /// the scale filter: the head's corrections accumulate, NanoTrack's smoothing) or
    /// `filter` (the filter's own box: a per-frame fusion of the two size estimates).
    pub prior: BoxPrior,
    /// Calibrate the head to the initial box: the per-side ratio of the given box to the
    /// head's box on the initial frame scales every later head box.
    pub calibrate: bool,
    /// Run the head every this many tracked frames (1: every frame); between runs the box
    /// follows the scale filter with the last correction.
    pub interval: usize,
    /// Side of the head's search map in grid points (even, 4 to 16): the crop is
    /// `16·search_cells − 1` pixels at NanoTrack's pixels per target pixel, so 16 is
    /// NanoTrack's 255-pixel search and smaller is a tighter context around the filter's
    /// position, the backbone's cost going with its area.
    pub search_cells: usize,
}

/// What [`crate::box_refine`] blends the head's box into.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BoxPrior {
    /// The previous box moved by the scale filter's change (corrections accumulate).
    #[default]
    Box,
    /// The filter's own box (first frame's aspect, the scale filter's size).
    Filter,
}

/// Where [`crate::box_refine`] reads the head's box.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BoxRead {
    /// The score-weighted box of the 3×3 grid points at the filter's position.
    #[default]
    Filter,
    /// NanoTrack's choice: the arg-max of the penalised score map with its cosine window.
    Peak,
}

/// The box refinement stage (`box_refine.mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BoxRefineMode {
    /// The filter's box.
    #[default]
    None,
    /// NanoTrack v2's head, in pure Rust ([`crate::nn`]).
    Nanotrack,
    /// NanoTrack v2's head on ONNX Runtime (cargo feature `cnn`).
    NanotrackOrt,
}

impl Default for BoxRefineConfig {
    fn default() -> Self {
        Self {
            mode: BoxRefineMode::Nanotrack,
            min_score: 0.5,
            max_offset: 0.5,
            min_side: 10.0,
            center_weight: 0.0,
            report_center: 1.0,
            penalty_k: 0.148,
            window_influence: 0.462,
            size_rate: 0.39,
            read: BoxRead::Filter,
            min_iou: 0.5,
            max_change: 0.1,
            feed_scale: false,
            prior: BoxPrior::Box,
            calibrate: true,
            search_cells: 12,
            interval: 1,
        }
    }
}

/// Camera motion compensation (see [`crate::motion`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MotionConfig {
    /// Centre each frame's search where the scene's shift since the previous frame (phase
    /// correlation of coarse whole frames) and the target's own motion put the target.
    pub camera: bool,
    /// Phase-correlation peak (0–1) a scene shift needs to be used; below it the frame's
    /// shift is taken as none.
    pub min_peak: f32,
    /// How the target's own motion in the scene is estimated.
    pub own: OwnMotion,
    /// Running-mean rate of the own motion, per frame (0: none).
    pub own_rate: f32,
    /// A tracked frame's search moves only when the prediction moves it by at least this
    /// fraction of the search window's side (0: always).
    pub min_move: f32,
}

/// How [`crate::motion`] estimates the target's own motion in the scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OwnMotion {
    /// The camera's smooth motion reversed (a camera that follows the target); only the
    /// camera's jerks move the search.
    #[default]
    Camera,
    /// What the tracker measured on confident frames, less the scene's shift.
    Tracker,
}

impl Default for MotionConfig {
    fn default() -> Self {
        Self {
            camera: false,
            min_peak: 0.1,
            own: OwnMotion::Camera,
            own_rate: 0.3,
            min_move: 0.0,
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
    /// The learned box on the filter.
    pub box_refine: BoxRefineConfig,
    /// Camera motion compensation.
    pub motion: MotionConfig,
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
            box_refine: BoxRefineConfig::default(),
            motion: MotionConfig::default(),
            threads: 1,
        }
    }
}

impl TrackerConfig {
    /// A copy of `self` with the live keys ([`keys::live_keys`]) of `other`: equal to
    /// `other` exactly when the two differ in live keys only. (A test checks that this copies
    /// exactly the keys the table marks live.)
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
        c.track_state = other.track_state;
        let (r, o) = (&mut c.redetection, &other.redetection);
        r.windows_per_frame = o.windows_per_frame;
        r.reacquire_threshold = o.reacquire_threshold;
        r.reacquire_frames = o.reacquire_frames;
        r.reacquire_relative = o.reacquire_relative;
        c.detection.newton_iterations = other.detection.newton_iterations;
        c
    }
}

/// A validated configuration: what the tracker is built from.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackerSpec {
    /// The validated configuration.
    pub config: TrackerConfig,
    /// Verification parameters.
    pub verify: VerifyParams,
    /// Learning gate of `verification.score: confidence`.
    pub gate: GateParams,
}

fn check(
    ok: bool,
    field: &'static str,
    value: impl ToString,
    expected: &str,
) -> Result<(), ConfigError> {
    if ok {
        Ok(())
    } else {
        Err(ConfigError::OutOfRange {
            field,
            value: value.to_string(),
            expected: expected.to_string(),
        })
    }
}

/// The table's range check of an integer key.
fn int_key(name: &str, v: usize) -> Result<(), ConfigError> {
    keys::spec(name).check_int(v)
}

/// The table's range check of a real key.
fn float_key(name: &str, v: f32) -> Result<(), ConfigError> {
    keys::spec(name).check_float(v)
}

/// A constraint between keys (code: the table states it only in words): `name` is
/// refused with the table's words for it.
fn cross_key(ok: bool, name: &str, value: impl ToString) -> Result<(), ConfigError> {
    let k = keys::spec(name);
    check(ok, k.name, value, k.cross)
}

/// Largest feature grid side, cells (ref 60).
const MAX_GRID_SIDE: usize = 128;
/// Largest patch side, pixels (ref 240).
const MAX_PATCH_SIDE: usize = 512;
/// Most patch pixels sampled per frame over all scales (ref 5 · 240² ≈ 0.29 M).
const MAX_PATCH_PIXELS: usize = 2 << 20;

impl TrackerConfig {
    /// Checks every field once (the ranges of [`TRACKER_KEYS`], then the constraints
    /// between keys) and derives the solver parameters.
    ///
    /// # Errors
    /// [`ConfigError`] naming the first offending field.
    pub fn validate(&self) -> Result<TrackerSpec, ConfigError> {
        let f = &self.features;
        int_key("features.hog_cell_size", f.hog_cell_size)?;
        float_key("features.gain", f.gain)?;
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
        float_key("window.search_area_scale", w.search_area_scale)?;
        float_key("window.padding", w.padding)?;
        float_key("window.filter_max_area", w.filter_max_area)?;
        float_key("window.cell_selection_thresh", w.cell_selection_thresh)?;
        float_key("window.output_sigma_factor", w.output_sigma_factor)?;
        // Memory and work of one frame: the feature grid is at most
        // round(sqrt(filter_max_area) · padding) cells a side, the patch that many cells of
        // hog_cell_size pixels, and one patch is sampled per scale.
        let grid_side = (w.filter_max_area.sqrt() * w.padding).round() + 1.0;
        cross_key(
            grid_side <= MAX_GRID_SIDE as f32,
            "window.filter_max_area",
            format!(
                "{} (grid side sqrt(filter_max_area) · padding = {grid_side} cells)",
                w.filter_max_area
            ),
        )?;
        let patch_side = grid_side * f.hog_cell_size as f32;
        cross_key(
            patch_side <= MAX_PATCH_SIDE as f32,
            "features.hog_cell_size",
            format!(
                "{} (patch side grid side · hog_cell_size = {patch_side} px)",
                f.hog_cell_size
            ),
        )?;
        let patch_pixels = patch_side * patch_side * self.detection.number_of_scales as f32;
        cross_key(
            patch_pixels <= MAX_PATCH_PIXELS as f32,
            "detection.number_of_scales",
            format!(
                "{} ({patch_pixels} patch pixels per frame)",
                self.detection.number_of_scales
            ),
        )?;
        let a = &self.admm;
        int_key("admm.iterations", a.iterations)?;
        float_key("admm.mu_init", a.mu_init)?;
        float_key("admm.beta", a.beta)?;
        float_key("admm.mu_max", a.mu_max)?;
        cross_key(a.mu_max >= a.mu_init, "admm.mu_max", a.mu_max)?;
        float_key("admm.lambda", a.lambda)?;
        float_key("admm.reg_window_min", a.reg_window_min)?;
        float_key("admm.reg_window_edge", a.reg_window_edge)?;
        cross_key(
            a.reg_window_edge >= a.reg_window_min,
            "admm.reg_window_edge",
            a.reg_window_edge,
        )?;
        float_key("admm.spatial_weight", a.spatial_weight)?;
        float_key("admm.temporal", a.temporal)?;
        let d = &self.detection;
        int_key("detection.number_of_scales", d.number_of_scales)?;
        float_key("detection.scale_step", d.scale_step)?;
        // Each Newton iteration evaluates the response spectrum once (O(grid cells)).
        int_key("detection.newton_iterations", d.newton_iterations)?;
        float_key("detection.scale_penalty", d.scale_penalty)?;
        let sf = &self.scale_filter;
        int_key("scale_filter.scales", sf.scales)?;
        int_key("scale_filter.interpolated_scales", sf.interpolated_scales)?;
        cross_key(
            sf.interpolated_scales >= sf.scales,
            "scale_filter.interpolated_scales",
            sf.interpolated_scales,
        )?;
        float_key("scale_filter.step", sf.step)?;
        float_key("scale_filter.learning_rate", sf.learning_rate)?;
        float_key("scale_filter.sigma_factor", sf.sigma_factor)?;
        float_key("scale_filter.lambda", sf.lambda)?;
        int_key("scale_filter.cell_size", sf.cell_size)?;
        int_key("scale_filter.sample_side", sf.sample_side)?;
        cross_key(
            sf.sample_side >= 2 * sf.cell_size,
            "scale_filter.sample_side",
            sf.sample_side,
        )?;
        float_key("scale_filter.padding", sf.padding)?;
        let l = &self.learning;
        float_key("learning.rate", l.rate)?;
        float_key("learning.reinforced_rate", l.reinforced_rate)?;
        let v = &self.verification;
        float_key("verification.threshold_low", v.threshold_low)?;
        float_key("verification.threshold_high", v.threshold_high)?;
        if v.threshold_high < v.threshold_low {
            return Err(ConfigError::Inconsistent(format!(
                "verification.threshold_high ({}) is below threshold_low ({})",
                v.threshold_high, v.threshold_low
            )));
        }
        float_key("verification.response_model_rate", v.response_model_rate)?;
        float_key("verification.gate_low", v.gate_low)?;
        float_key("verification.gate_high", v.gate_high)?;
        cross_key(
            v.gate_high >= v.gate_low,
            "verification.gate_high",
            v.gate_high,
        )?;
        int_key(
            "verification.max_consecutive_skips",
            v.max_consecutive_skips,
        )?;
        let c = &self.confidence;
        int_key("confidence.warmup_frames", c.warmup_frames)?;
        float_key("confidence.reference_rate", c.reference_rate)?;
        float_key("confidence.half_score", c.half_score)?;
        int_key("confidence.psr_exclusion_cells", c.psr_exclusion_cells)?;
        let t = &self.track_state;
        float_key("track_state.lost_threshold", t.lost_threshold)?;
        int_key("track_state.lost_frames", t.lost_frames)?;
        int_key("track_state.drift_check_frames", t.drift_check_frames)?;
        int_key("track_state.drift_calm_frames", t.drift_calm_frames)?;
        float_key("track_state.drift_threshold", t.drift_threshold)?;
        int_key("track_state.drift_recheck_frames", t.drift_recheck_frames)?;
        let r = &self.redetection;
        int_key("redetection.windows_per_frame", r.windows_per_frame)?;
        keys::spec("redetection.scales").check_list(&r.scales)?;
        float_key("redetection.tile_stride", r.tile_stride)?;
        float_key("redetection.reacquire_threshold", r.reacquire_threshold)?;
        float_key("redetection.reacquire_relative", r.reacquire_relative)?;
        int_key("redetection.reacquire_frames", r.reacquire_frames)?;
        int_key("redetection.proposals", r.proposals)?;
        cross_key(
            r.proposals <= r.windows_per_frame,
            "redetection.proposals",
            r.proposals,
        )?;
        int_key("redetection.verifier_windows", r.verifier_windows)?;
        int_key("redetection.verifier_proposals", r.verifier_proposals)?;
        cross_key(
            r.verifier_proposals <= r.verifier_windows,
            "redetection.verifier_proposals",
            r.verifier_proposals,
        )?;
        keys::spec("redetection.verifier_scales").check_list(&r.verifier_scales)?;
        int_key("redetection.verifier_tile_cells", r.verifier_tile_cells)?;
        check(
            r.verifier_tile_cells.is_multiple_of(2),
            "redetection.verifier_tile_cells",
            r.verifier_tile_cells,
            "even (the crop centre is a grid point only for an even side)",
        )?;
        if r.verifier_tile_cells != 16 && r.verifier == VerifierKind::NanotrackOrt {
            return Err(ConfigError::Inconsistent(
                "redetection.verifier_tile_cells other than 16 needs redetection.verifier nanotrack (the ONNX Runtime networks are planned for 16)".into(),
            ));
        }
        float_key("redetection.verifier_threshold", r.verifier_threshold)?;
        let b = &self.box_refine;
        float_key("box_refine.min_score", b.min_score)?;
        float_key("box_refine.max_offset", b.max_offset)?;
        float_key("box_refine.min_side", b.min_side)?;
        float_key("box_refine.center_weight", b.center_weight)?;
        float_key("box_refine.report_center", b.report_center)?;
        float_key("box_refine.penalty_k", b.penalty_k)?;
        float_key("box_refine.window_influence", b.window_influence)?;
        float_key("box_refine.size_rate", b.size_rate)?;
        float_key("box_refine.min_iou", b.min_iou)?;
        float_key("box_refine.max_change", b.max_change)?;
        int_key("box_refine.interval", b.interval)?;
        int_key("box_refine.search_cells", b.search_cells)?;
        check(
            b.search_cells.is_multiple_of(2),
            "box_refine.search_cells",
            b.search_cells,
            "even (the crop centre is a grid point only for an even side)",
        )?;
        if b.search_cells != 16 && b.mode == BoxRefineMode::NanotrackOrt {
            return Err(ConfigError::Inconsistent(
                "box_refine.search_cells other than 16 needs box_refine.mode nanotrack (the ONNX Runtime networks are planned for 16)".into(),
            ));
        }
        float_key("motion.min_peak", self.motion.min_peak)?;
        float_key("motion.own_rate", self.motion.own_rate)?;
        float_key("motion.min_move", self.motion.min_move)?;
        int_key("threads", self.threads)?;
        Ok(TrackerSpec {
            config: self.clone(),
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
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_norway::{Mapping, Number, Value};

    /// The value of the dotted `key`.
    fn key_value(c: &TrackerConfig, key: &str) -> Option<Value> {
        let mut v = serde_norway::to_value(c).ok()?;
        for part in key.split('.') {
            v = v.as_mapping_mut()?.remove(part)?;
        }
        Some(v)
    }

    /// `c` with the dotted `key` set to `v` (not validated), or the parser's error.
    fn with_key(c: &TrackerConfig, key: &str, v: Value) -> Result<TrackerConfig, String> {
        let mut tree = serde_norway::to_value(c).unwrap();
        let mut node = &mut tree;
        let parts: Vec<&str> = key.split('.').collect();
        for (i, part) in parts.iter().enumerate() {
            let map = node.as_mapping_mut().unwrap();
            let k = Value::String((*part).to_string());
            if i + 1 == parts.len() {
                map.insert(k, v);
                break;
            }
            node = map
                .entry(k)
                .or_insert_with(|| Value::Mapping(Mapping::new()));
        }
        serde_norway::from_value(tree).map_err(|e| e.to_string())
    }

    /// Dotted names of a YAML tree's leaves (a sequence is a leaf).
    fn leaves(prefix: &str, v: &Value, out: &mut Vec<String>) {
        match v {
            Value::Mapping(m) => {
                for (k, v) in m {
                    let k = k.as_str().unwrap();
                    let name = if prefix.is_empty() {
                        k.to_string()
                    } else {
                        format!("{prefix}.{k}")
                    };
                    leaves(&name, v, out);
                }
            }
            _ => out.push(prefix.to_string()),
        }
    }

    #[test]
    fn the_key_table_lists_every_key_of_the_configuration_once_in_order() {
        let mut keys = Vec::new();
        leaves(
            "",
            &serde_norway::to_value(TrackerConfig::default()).unwrap(),
            &mut keys,
        );
        let table: Vec<&str> = TRACKER_KEYS.iter().map(|k| k.name).collect();
        assert_eq!(keys, table);
        for k in TRACKER_KEYS {
            assert!(k.doc.len() > 10 && k.doc.ends_with('.'), "{}: doc", k.name);
            let v = key_value(&TrackerConfig::default(), k.name).unwrap();
            let fits = match (k.kind, &v) {
                (Kind::Bool, Value::Bool(_)) | (Kind::Path, Value::String(_)) => true,
                (Kind::Int, Value::Number(n)) => n.is_u64(),
                (Kind::Float, Value::Number(_)) | (Kind::FloatList, Value::Sequence(_)) => true,
                (Kind::Choice(c), Value::String(s)) => c.contains(&s.as_str()),
                (Kind::Section, Value::Null) => true,
                _ => false,
            };
            assert!(fits, "{}: {:?} holds {v:?}", k.name, k.kind);
        }
    }

    #[test]
    fn the_choices_of_the_table_are_the_parsers() {
        let d = TrackerConfig::default();
        for k in TRACKER_KEYS {
            let Kind::Choice(choices) = k.kind else {
                continue;
            };
            for c in choices {
                with_key(&d, k.name, Value::String((*c).into()))
                    .unwrap_or_else(|e| panic!("{}: {c}: {e}", k.name));
            }
            let e = with_key(&d, k.name, Value::String("bogus".into())).unwrap_err();
            // The parser names the bogus value and then exactly the table's choices.
            let expected = e.split_once("expected").unwrap().1;
            for c in choices {
                assert!(expected.contains(&format!("`{c}`")), "{}: {e}", k.name);
            }
            assert_eq!(
                expected.matches('`').count(),
                2 * choices.len(),
                "{}: {e}",
                k.name
            );
        }
    }

    /// `name` = `v` is refused by the table's range of `name`.
    fn refused_by_range(k: &KeySpec, v: Value) -> bool {
        let Ok(c) = with_key(&TrackerConfig::default(), k.name, v.clone()) else {
            return false;
        };
        matches!(c.validate(), Err(ConfigError::OutOfRange { field, expected, .. })
            if field == k.name && expected == k.range.words(k.unit))
    }

    fn number(v: f64) -> Value {
        Value::Number(Number::from(v))
    }

    #[test]
    fn every_range_of_the_table_is_enforced_at_both_ends() {
        let mut checked = 0;
        for k in TRACKER_KEYS {
            let (inside, outside): (Vec<Value>, Vec<Value>) = match k.range {
                Range::Any => continue,
                Range::Int(lo, hi) => {
                    let mut out = vec![Value::Number(Number::from(hi + 1))];
                    if lo > 0 {
                        out.push(Value::Number(Number::from(lo - 1)));
                    }
                    (
                        vec![
                            Value::Number(Number::from(lo)),
                            Value::Number(Number::from(hi)),
                        ],
                        out,
                    )
                }
                Range::Float {
                    lo,
                    hi,
                    open_lo,
                    open_hi,
                } => {
                    let step = |x: f64| (x.abs() * 1e-3).max(1e-3);
                    let (mut inside, mut outside) = (Vec::new(), vec![number(f64::NAN)]);
                    outside.push(number(lo - step(lo)));
                    if open_lo { &mut outside } else { &mut inside }.push(number(lo));
                    if hi.is_finite() {
                        outside.push(number(hi + step(hi)));
                        if open_hi { &mut outside } else { &mut inside }.push(number(hi));
                    } else {
                        outside.push(number(f64::INFINITY));
                    }
                    (inside, outside)
                }
                Range::List {
                    min_len,
                    max_len,
                    lo,
                    hi,
                } => {
                    let list = |n: usize, x: f64| Value::Sequence(vec![number(x); n]);
                    (
                        vec![list(min_len, lo), list(max_len, hi)],
                        vec![
                            list(min_len - 1, 1.0),
                            list(max_len + 1, 1.0),
                            list(min_len, lo * 0.99),
                            list(min_len, hi * 1.01),
                        ],
                    )
                }
            };
            for v in outside {
                assert!(
                    refused_by_range(k, v.clone()),
                    "{} = {v:?} accepted",
                    k.name
                );
            }
            for v in inside {
                // Accepted by the range (a constraint between keys may still refuse it).
                assert!(
                    !refused_by_range(k, v.clone()),
                    "{} = {v:?} refused",
                    k.name
                );
            }
            checked += 1;
        }
        assert!(checked > 50, "{checked}");
    }

    #[test]
    fn live_keys_are_exactly_those_the_table_marks_live() {
        let d = TrackerConfig::default();
        for k in TRACKER_KEYS {
            let v = key_value(&d, k.name).unwrap();
            let other = match (k.kind, &v) {
                (Kind::Bool, Value::Bool(b)) => Value::Bool(!b),
                (Kind::Int, Value::Number(n)) => {
                    Value::Number(Number::from(n.as_u64().unwrap() + 1))
                }
                (Kind::Float, Value::Number(n)) => number(n.as_f64().unwrap() * 0.5 + 0.01),
                (Kind::FloatList, _) => Value::Sequence(vec![number(1.0)]),
                (Kind::Choice(c), Value::String(s)) => {
                    Value::String(c.iter().find(|c| **c != s).unwrap().to_string())
                }
                (Kind::Path, _) => Value::String("x.onnx".into()),
                _ => continue,
            };
            let changed = with_key(&d, k.name, other).unwrap();
            assert_ne!(changed, d, "{}", k.name);
            assert_eq!(
                d.with_live_keys_of(&changed) == changed,
                k.live,
                "{}",
                k.name
            );
        }
        assert_eq!(live_keys().count(), 25);
    }

    #[test]
    fn the_filter_sweeps_beside_a_verifier_only_when_asked_or_hinted() {
        use FilterSearch::{Always, Auto};
        // (mode, a verifier searches, it takes the filter's hint) → the filter sweeps.
        for (mode, verifier, hint, sweeps) in [
            (Auto, true, false, false),
            (Auto, true, true, true),
            (Auto, false, false, true),
            (Auto, false, true, true),
            (Always, true, false, true),
            (Always, true, true, true),
            (Always, false, false, true),
        ] {
            assert_eq!(
                mode.sweeps(verifier, hint),
                sweeps,
                "{mode:?}, verifier {verifier}, hint {hint}"
            );
        }
        assert_eq!(RedetectionConfig::default().filter_search, Auto);
    }

    #[test]
    fn the_learned_box_search_takes_even_sides_and_the_pure_rust_networks() {
        let with = |cells: usize, mode: BoxRefineMode| {
            let mut c = TrackerConfig::default();
            c.box_refine.search_cells = cells;
            c.box_refine.mode = mode;
            c.validate()
        };
        for cells in [4, 8, 12, 16] {
            with(cells, BoxRefineMode::Nanotrack).unwrap();
        }
        for cells in [0, 2, 5, 11, 17, 18] {
            let e = with(cells, BoxRefineMode::Nanotrack)
                .unwrap_err()
                .to_string();
            assert!(e.contains("box_refine.search_cells"), "{cells}: {e}");
        }
        with(16, BoxRefineMode::NanotrackOrt).unwrap();
        let e = with(12, BoxRefineMode::NanotrackOrt)
            .unwrap_err()
            .to_string();
        assert!(e.contains("needs box_refine.mode nanotrack"), "{e}");
    }

    #[test]
    fn the_verifier_tiles_take_even_sides_up_to_32_and_the_pure_rust_networks() {
        let with = |cells: usize, verifier: VerifierKind| {
            let mut c = TrackerConfig::default();
            c.redetection.verifier_tile_cells = cells;
            c.redetection.verifier = verifier;
            c.validate()
        };
        for cells in [8, 16, 24, 32] {
            with(cells, VerifierKind::Nanotrack).unwrap();
        }
        for cells in [0, 6, 17, 23, 34, 1 << 20] {
            let e = with(cells, VerifierKind::Nanotrack)
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("redetection.verifier_tile_cells"),
                "{cells}: {e}"
            );
        }
        with(16, VerifierKind::NanotrackOrt).unwrap();
        let e = with(24, VerifierKind::NanotrackOrt)
            .unwrap_err()
            .to_string();
        assert!(e.contains("needs redetection.verifier nanotrack"), "{e}");
    }

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
            ("redetection.verifier_proposals", |c| {
                c.redetection.verifier_proposals = 17
            }),
            ("redetection.verifier_proposals", |c| {
                c.redetection.verifier_windows = 2;
                c.redetection.verifier_proposals = 3
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
        // Issue 19: the learned box on the filter (NanoTrack v2's head, its centre and size
        // in the reported box; the reference has the filter's box).
        assert_eq!(c.box_refine.mode, BoxRefineMode::None);
        c.box_refine = BoxRefineConfig::default();
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
