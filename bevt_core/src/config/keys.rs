//! The one table of tracker keys: [`TRACKER_KEYS`].
//!
//! Each key's name, kind, accepted range or choices, unit, liveness and description is
//! written here once. From it come [`crate::TrackerConfig::validate`]'s range checks, the
//! live-key set of [`crate::BevtTracker::retune`], the node's `ros2 param describe`
//! descriptors and `docs/configuration.md`. Defaults are `TrackerConfig::default()` (equal
//! to `config/bevt.yaml`, a test checks it). Constraints between keys that a range cannot
//! state are code in `validate()`; the table only names them in words ([`KeySpec::cross`]).
//!
//! The descriptions users see are the table's [`KeySpec::doc`]; the doc comments of the
//! `*Config` fields are for Rust readers and are not read by anything. A change to what a
//! key does goes in both (no test can compare them without parsing source).

use crate::error::ConfigError;
use std::fmt::Write as _;

mod cnn_table;
pub use cnn_table::{cnn_spec, CNN_KEYS};

/// What a key holds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Kind {
    /// `true` / `false`.
    Bool,
    /// A non-negative integer.
    Int,
    /// A real number (`f32`).
    Float,
    /// A list of reals.
    FloatList,
    /// One of these names (the YAML spelling of an enum).
    Choice(&'static [&'static str]),
    /// A file path (text).
    Path,
    /// A name (text): a model's input or output.
    Text,
    /// An optional section of its own (`features.cnn`).
    Section,
}

impl Kind {
    /// The type's name in the documentation.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Bool => "bool",
            Self::Int => "integer",
            Self::Float => "float",
            Self::FloatList => "float list",
            Self::Choice(_) => "enum",
            Self::Path => "path",
            Self::Text => "string",
            Self::Section => "section",
        }
    }
}

/// The values a key accepts, as far as a range can say.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Range {
    /// Any value of its kind (booleans, choices, paths).
    Any,
    /// Integers `lo..=hi`.
    Int(u64, u64),
    /// Finite reals from `lo` to `hi` (`hi` may be infinite: no upper end); an open end is
    /// excluded.
    Float {
        /// Lower end.
        lo: f64,
        /// Upper end.
        hi: f64,
        /// `lo` itself is refused.
        open_lo: bool,
        /// `hi` itself is refused.
        open_hi: bool,
    },
    /// `min_len..=max_len` finite reals, each in `[lo, hi]`.
    List {
        /// Fewest values.
        min_len: usize,
        /// Most values.
        max_len: usize,
        /// Smallest value.
        lo: f64,
        /// Largest value.
        hi: f64,
    },
}

/// One tracker key.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KeySpec {
    /// Dotted name, as in `config/bevt.yaml` (`admm.iterations`).
    pub name: &'static str,
    /// What it holds.
    pub kind: Kind,
    /// The range `validate()` enforces from this table.
    pub range: Range,
    /// Constraints involving other keys, in words ("" when none); checked by code in
    /// `validate()`.
    pub cross: &'static str,
    /// Unit of the value ("" when none).
    pub unit: &'static str,
    /// Taken by a running tracker at once ([`crate::BevtTracker::retune`]); otherwise it
    /// shapes what is built at initialisation and needs a new track.
    pub live: bool,
    /// What it does.
    pub doc: &'static str,
}

/// A number as the table writes it: `1e6`, not `1000000`.
fn num(v: f64) -> String {
    let a = v.abs();
    if a >= 1e4 && a.log10().fract() == 0.0 {
        format!("{}1e{}", if v < 0.0 { "-" } else { "" }, a.log10() as i32)
    } else {
        format!("{v}")
    }
}

impl Range {
    /// The range in words, with `unit` ("1..=16 px", "(0, 1]", ">= 0").
    pub fn words(&self, unit: &str) -> String {
        let mut s = match *self {
            Self::Any => return String::new(),
            Self::Int(lo, hi) => format!("{lo}..={hi}"),
            Self::Float {
                lo,
                hi,
                open_lo,
                open_hi,
            } => {
                if hi.is_infinite() {
                    format!("{} {}", if open_lo { ">" } else { ">=" }, num(lo))
                } else {
                    format!(
                        "{}{}, {}{}",
                        if open_lo { "(" } else { "[" },
                        num(lo),
                        num(hi),
                        if open_hi { ")" } else { "]" }
                    )
                }
            }
            Self::List {
                min_len,
                max_len,
                lo,
                hi,
            } if min_len == max_len => format!("{min_len} values in [{}, {}]", num(lo), num(hi)),
            Self::List {
                min_len,
                max_len,
                lo,
                hi,
            } => format!(
                "{min_len} to {max_len} factors in [{}, {}]",
                num(lo),
                num(hi)
            ),
        };
        if !unit.is_empty() {
            let _ = write!(s, " {unit}");
        }
        s
    }

    /// `(from, to)` for a ROS `IntegerRange` / `FloatingPointRange`: both ends finite.
    pub fn bounds(&self) -> Option<(f64, f64)> {
        match *self {
            Self::Int(lo, hi) => Some((lo as f64, hi as f64)),
            Self::Float { lo, hi, .. } if hi.is_finite() => Some((lo, hi)),
            _ => None,
        }
    }

    /// Whether a real is inside.
    pub fn contains_f64(&self, v: f64) -> bool {
        match *self {
            Self::Any => true,
            Self::Int(lo, hi) => v.fract() == 0.0 && v >= lo as f64 && v <= hi as f64,
            Self::Float {
                lo,
                hi,
                open_lo,
                open_hi,
            } => {
                v.is_finite()
                    && if open_lo { v > lo } else { v >= lo }
                    && if open_hi { v < hi } else { v <= hi }
            }
            Self::List { lo, hi, .. } => v.is_finite() && v >= lo && v <= hi,
        }
    }
}

impl KeySpec {
    /// The accepted values in words: the range (with the unit) and the constraints on
    /// other keys.
    pub fn constraints(&self) -> String {
        self.constraints_in(self.unit)
    }

    /// [`Self::constraints`] with the range's unit written as `unit` ("" = none).
    pub fn constraints_in(&self, unit: &str) -> String {
        let words = match self.kind {
            Kind::Choice(c) => format!(
                "one of {}",
                c.iter()
                    .map(|c| format!("`{c}`"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            _ => self.range.words(unit),
        };
        match (words.is_empty(), self.cross.is_empty()) {
            (_, true) => words,
            (true, false) => self.cross.to_string(),
            (false, false) => format!("{words}, {}", self.cross),
        }
    }

    fn refuse(&self, value: impl ToString) -> ConfigError {
        ConfigError::OutOfRange {
            field: self.name,
            value: value.to_string(),
            expected: self.range.words(self.unit),
        }
    }

    /// Checks an integer value against the range.
    ///
    /// # Errors
    /// [`ConfigError::OutOfRange`] naming the key and its range.
    pub fn check_int(&self, v: usize) -> Result<(), ConfigError> {
        let ok = match self.range {
            Range::Int(lo, hi) => (lo..=hi).contains(&(v as u64)),
            _ => true,
        };
        if ok {
            Ok(())
        } else {
            Err(self.refuse(v))
        }
    }

    /// Checks a real value against the range.
    ///
    /// # Errors
    /// [`ConfigError::OutOfRange`] naming the key and its range.
    pub fn check_float(&self, v: f32) -> Result<(), ConfigError> {
        if self.range.contains_f64(f64::from(v)) {
            Ok(())
        } else {
            Err(self.refuse(v))
        }
    }

    /// Checks a list of reals against the range (its length and every value).
    ///
    /// # Errors
    /// [`ConfigError::OutOfRange`] naming the key and its range.
    pub fn check_list(&self, v: &[f32]) -> Result<(), ConfigError> {
        let ok = match self.range {
            Range::List {
                min_len, max_len, ..
            } => {
                (min_len..=max_len).contains(&v.len())
                    && v.iter().all(|x| self.range.contains_f64(f64::from(*x)))
            }
            _ => true,
        };
        if ok {
            Ok(())
        } else {
            Err(self.refuse(format!("{v:?}")))
        }
    }
}

/// The spec of key `name`.
///
/// # Panics
/// When `name` is not in [`TRACKER_KEYS`] (a test runs every lookup `validate()` makes).
#[allow(clippy::panic)]
pub fn spec(name: &str) -> &'static KeySpec {
    match TRACKER_KEYS.iter().find(|k| k.name == name) {
        Some(k) => k,
        None => panic!("tracker key {name} is not in TRACKER_KEYS"),
    }
}

/// The keys a running tracker takes at once.
pub fn live_keys() -> impl Iterator<Item = &'static str> {
    TRACKER_KEYS.iter().filter(|k| k.live).map(|k| k.name)
}

const LIVE: bool = true;
const FIXED: bool = false;

const fn int(lo: u64, hi: u64) -> Range {
    Range::Int(lo, hi)
}
/// `[lo, hi]`.
const fn closed(lo: f64, hi: f64) -> Range {
    Range::Float {
        lo,
        hi,
        open_lo: false,
        open_hi: false,
    }
}
/// `(lo, hi]`.
const fn above(lo: f64, hi: f64) -> Range {
    Range::Float {
        lo,
        hi,
        open_lo: true,
        open_hi: false,
    }
}
/// `(lo, hi)`.
const fn open(lo: f64, hi: f64) -> Range {
    Range::Float {
        lo,
        hi,
        open_lo: true,
        open_hi: true,
    }
}
/// `n..=m` factors in `[0.25, 4]`.
const fn factors(min_len: usize, max_len: usize) -> Range {
    Range::List {
        min_len,
        max_len,
        lo: 0.25,
        hi: 4.0,
    }
}

const fn key(
    name: &'static str,
    kind: Kind,
    range: Range,
    unit: &'static str,
    live: bool,
    doc: &'static str,
) -> KeySpec {
    KeySpec {
        name,
        kind,
        range,
        cross: "",
        unit,
        live,
        doc,
    }
}

const fn cross(k: KeySpec, cross: &'static str) -> KeySpec {
    KeySpec { cross, ..k }
}

use Kind::{Bool, Float, FloatList, Int, Path};

/// Every tracker key, in `config/bevt.yaml` order.
#[rustfmt::skip]
pub static TRACKER_KEYS: &[KeySpec] = &[
    // features
    key("features.kind", Kind::Choice(&["hog", "cnn"]), Range::Any, "", FIXED,
        "Feature type: Felzenszwalb HOG (31 channels), optionally + grayscale and colour names (the fast default), or CNN layers from an ONNX model (`features.cnn`, cargo feature `cnn`: the paper's mode)."),
    cross(key("features.hog_cell_size", Int, int(1, 16), "px", FIXED,
        "HOG cell size, pixels (ref 4). Smaller cells are chosen for small targets."),
        "grid side × cell <= 512 px"),
    key("features.grayscale", Bool, Range::Any, "", FIXED,
        "Append a grayscale channel (cell-mean luminance) to HOG."),
    key("features.colornames", Bool, Range::Any, "", FIXED,
        "Append the 10 colour-name channels (cell means of the embedded `w2crs` table) to HOG. Colour frames only: on mono8 frames the group is left out for the whole track."),
    key("features.gain", Float, above(0.0, 1e4), "", FIXED,
        "Gain on every feature value (applied with the Hann window). It sets the balance of the data term against the ADMM penalty μ, and so the scale of the responses that consensus verification compares (1 = the reference)."),
    cross(key("features.cnn", Kind::Section, Range::Any, "", FIXED,
        "CNN features (required when `kind` is `cnn`; see `config/cnn_*.yaml`)."),
        "required when features.kind is cnn"),
    // window
    key("window.search_area_scale", Float, closed(1.0, 10.0), "× √(w·h)", FIXED,
        "Search square side as a multiple of `sqrt(w·h)` (ref 5). Frame pixels read per scale grow with its square."),
    key("window.padding", Float, closed(1.0, 3.0), "", FIXED,
        "Extra factor on the patch side (ref 1.2)."),
    cross(key("window.filter_max_area", Float, closed(16.0, 65536.0), "cells²", FIXED,
        "Largest filter area, cells² (ref 50² = 2500); larger searches are downscaled."),
        "sqrt(window.filter_max_area) · window.padding <= 128 cells"),
    key("window.cell_selection_thresh", Float, above(0.0, 1.0), "", FIXED,
        "Choose a smaller cell when the search area is below this fraction of `filter_max_area` (ref 0.75² = 0.5625)."),
    key("window.output_sigma_factor", Float, above(0.0, 1.0), "× √(target cells)", FIXED,
        "Label σ as a fraction of `sqrt(target cells)` (ref 1/16)."),
    // admm
    key("admm.iterations", Int, int(1, 20), "", FIXED,
        "Iterations per training (ref 3)."),
    key("admm.mu_init", Float, above(0.0, 1e6), "", FIXED,
        "Initial μ (ref 1)."),
    key("admm.beta", Float, closed(1.0, 1000.0), "", FIXED,
        "μ growth β (ref run_BEVT.m: 20; a comment there says 10)."),
    cross(key("admm.mu_max", Float, above(0.0, 1e9), "", FIXED,
        "Largest μ (ref 10000)."),
        ">= admm.mu_init"),
    key("admm.lambda", Float, closed(0.0, 1e6), "", FIXED,
        "Ridge λ of the `none` penalty (BACF 0.01)."),
    key("admm.penalty", Kind::Choice(&["matrix", "elementwise", "none"]), Range::Any, "", FIXED,
        "Penalty form: `matrix` (reference), `elementwise` (a diagonal spatial penalty, the paper's eq. 8 at the magnitude `spatial_weight`), `none` (BACF)."),
    key("admm.spatial_weight", Float, closed(0.0, 1e6), "", FIXED,
        "Magnitude κ of the `elementwise` penalty: its h-step divides by `κ·p² + μ`, `p` the penalty window (0.1 at the target centre, 0.8 at its edge). The literal eq. 8 is κ = 2/T (T = grid cells, ~1/1800): no effect against μ ≥ 1. κ = 100 weighs the target edge ~64× the first μ (in the spirit of SRDCF/STRCF weights). Unitless."),
    key("admm.temporal", Float, closed(0.0, 1e6), "units of μ", FIXED,
        "Weight θ of the temporal regularisation `θ/2‖ĝ − ĝ_prev‖²` (STRCF/AutoTrack; in the units of μ; 0 = none, the reference)."),
    key("admm.reg_window_min", Float, closed(0.0, 1e6), "", FIXED,
        "Penalty window minimum at the target centre (ref 0.1)."),
    cross(key("admm.reg_window_edge", Float, closed(0.0, 1e6), "", FIXED,
        "Penalty window value at the target edge (ref 0.8)."),
        ">= admm.reg_window_min"),
    // detection
    key("detection.scale_estimator", Kind::Choice(&["search", "filter"]), Range::Any, "", FIXED,
        "`search` (reference: the translation filter on `number_of_scales` patches) or `filter` (one patch, separate scale filter)."),
    cross(key("detection.number_of_scales", Int, int(1, 33), "", FIXED,
        "Scales tried per frame by `search` (ref 5; checked whatever the estimator)."),
        "number_of_scales · patch side² <= 2 M pixels per frame"),
    key("detection.scale_step", Float, open(1.0, 2.0), "", FIXED,
        "Ratio between neighbouring scales (ref 1.01)."),
    key("detection.newton_iterations", Int, int(0, 100), "", LIVE,
        "Newton iterations of the sub-cell peak (ref 50; stops early once converged)."),
    key("detection.scale_penalty", Float, above(0.0, 1.0), "", FIXED,
        "Multiplies the peak of a scale `k` steps from the current one by `penalty^k` before the scales compete (1 = the reference: no penalty). Damps scale jitter from noise."),
    // scale_filter
    key("scale_filter.scales", Int, int(3, 65), "", FIXED,
        "Scales sampled per frame (fDSST 17)."),
    cross(key("scale_filter.interpolated_scales", Int, int(3, 257), "", FIXED,
        "Scales after Fourier interpolation (fDSST 33), ≥ `scales`."),
        ">= scale_filter.scales"),
    key("scale_filter.step", Float, open(1.0, 1.5), "", FIXED,
        "Ratio between neighbouring interpolated scales (fDSST 1.02)."),
    key("scale_filter.learning_rate", Float, above(0.0, 1.0), "per frame", FIXED,
        "Learning rate of the scale model (fDSST 0.025)."),
    key("scale_filter.sigma_factor", Float, above(0.0, 10.0), "× interpolated_scales", FIXED,
        "Scale label σ as a fraction of `interpolated_scales` (fDSST 1/16)."),
    key("scale_filter.lambda", Float, closed(0.0, f64::INFINITY), "", FIXED,
        "Ridge of the detection denominator (fDSST 0.01)."),
    cross(key("scale_filter.sample_side", Int, int(2, 256), "px", FIXED,
        "Side of each (square) scale sample, pixels (fDSST: area 32·16 = 512 px²)."),
        ">= 2 · scale_filter.cell_size"),
    key("scale_filter.cell_size", Int, int(1, 16), "px", FIXED,
        "HOG cell of the scale samples, pixels (fDSST 4)."),
    key("scale_filter.padding", Float, closed(1.0, 4.0), "× target box", FIXED,
        "Each scale sample covers the target box times this factor (fDSST 1: the box only)."),
    key("scale_filter.colornames", Bool, Range::Any, "", FIXED,
        "Append the 10 colour-name channels per cell to the scale samples' fHOG (colour frames only; fDSST: fHOG only)."),
    // learning
    key("learning.rate", Float, closed(0.0, 1.0), "per frame", LIVE,
        "Base rate η (ref 0.013)."),
    key("learning.reinforced_rate", Float, closed(0.0, 1.0), "per frame", LIVE,
        "Reinforced rate when consensus ≥ `threshold_high` (ref 0.019)."),
    key("learning.training_sample", Kind::Choice(&["fresh", "shifted"]), Range::Any, "", FIXED,
        "`fresh` (reference: a new patch at the new position) or `shifted` (the detection sample shifted in the Fourier domain, half the feature work)."),
    // verification
    key("verification.enabled", Bool, Range::Any, "", LIVE,
        "Off: learn every frame at the base rate (ablation)."),
    key("verification.score", Kind::Choice(&["reference", "confidence"]), Range::Any, "", FIXED,
        "The score that gates learning: `confidence` (the per-frame confidence, default) or `reference` (the consensus `C` with `threshold_low`/`threshold_high`, paper fidelity)."),
    key("verification.norm", Kind::Choice(&["spectral", "frobenius_sq"]), Range::Any, "", FIXED,
        "`spectral` (reference) or `frobenius_sq` (paper)."),
    key("verification.threshold_low", Float, closed(0.0, 1.0), "", LIVE,
        "At or below: do not learn (ref 0.20)."),
    cross(key("verification.threshold_high", Float, closed(0.0, 1.0), "", LIVE,
        "At or above: learn with the reinforced rate (ref 0.50)."),
        ">= verification.threshold_low"),
    key("verification.response_model_rate", Float, closed(0.0, 1.0), "per frame", LIVE,
        "Rate γ of the ideal response model (ref 0.013)."),
    key("verification.gate_low", Float, closed(0.0, 10.0), "× reference level", LIVE,
        "`score: confidence`: a frame whose score is below this fraction of the running reference level is not learned (a sudden drop, e.g. an occlusion)."),
    cross(key("verification.gate_high", Float, closed(0.0, 10.0), "× reference level", LIVE,
        "`score: confidence`: at or above this fraction of the reference, learn at the reinforced rate (below it, the base rate)."),
        ">= verification.gate_low"),
    key("verification.max_consecutive_skips", Int, int(0, 10_000), "frames", LIVE,
        "`score: confidence`: frames skipped in a row after which one frame is learned at the base rate anyway, so verification never locks the tracker out of learning."),
    // confidence
    key("confidence.measure", Kind::Choice(&["peak", "psr", "peak_psr"]), Range::Any, "", FIXED,
        "`peak_psr` (r·q), `peak` (r: peak over the initial filter's in-sample peak) or `psr` (q: peak-to-sidelobe ratio); absolute, no running reference."),
    key("confidence.half_score", Float, above(0.0, 1e6), "", LIVE,
        "Score at which the confidence is 0.5 (`peak_psr`: 5; `peak`: about 0.5; `psr`: about 8); confidence = score / (score + half_score)."),
    key("confidence.warmup_frames", Int, int(1, 10_000), "frames", FIXED,
        "Frames (after the initial one) whose mean is the learning gate's first reference level; no frame of the warm-up is skipped."),
    key("confidence.reference_rate", Float, closed(0.0, 1.0), "per frame", LIVE,
        "Running-average rate of the gate's reference level, per frame (0–1)."),
    key("confidence.psr_exclusion_cells", Int, int(0, 64), "cells", FIXED,
        "Half-side of the square around the peak left out of the PSR sidelobe, cells."),
    // track_state
    key("track_state.lost_threshold", Float, closed(0.0, 1.0), "", LIVE,
        "Confidence below this is unconfident (0–1; 0 = never)."),
    key("track_state.lost_frames", Int, int(1, 10_000), "frames", LIVE,
        "Unconfident frames in a row that make the target lost."),
    key("track_state.drift_check_frames", Int, int(0, 10_000), "frames", LIVE,
        "Drift check: every this many confident frames the learned verifier scores the box against the first frame's template (0 = off; off without `redetection.verifier`). 15: one pass (about 27 ms on the 2-core dev VM) every 15 frames costs about 9 % of a 21 ms frame, near the 10 % budget; checks every 4 frames cost 24 %."),
    key("track_state.drift_calm_frames", Int, int(0, 10_000), "frames", LIVE,
        "The drift check's interval while the track is calm: the last check scored at least `redetection.verifier_threshold` (the bar a re-acquisition must pass) and the learning gate has refused no frame since (the filter's score holding its recent level); any other check result, a refused frame or a state other than `tracking` returns to `drift_check_frames` (at most `drift_check_frames`, as the default 0: never lengthened). Off by default: on the dev set 30 saves 48 of 770 verifier passes with every frame's state unchanged, but the model a drift loss goes back to is up to 30 frames old instead of 15, which moves car14's and wakeboard4's boxes after their drift losses (P@20 0.962 → 0.957, 0.893 → 0.880), and leave-one-sequence-out on accuracy keeps it off in both folds that differ (docs/benchmarks.md)."),
    key("track_state.drift_threshold", Float, closed(-100.0, 100.0), "logit margin", LIVE,
        "Verifier score below which a drift check makes a confident frame uncertain (reason: drift). 4.0: below the re-acquisition bar (`redetection.verifier_threshold` 5.0), so a box the verifier would nearly accept is not a drift; on the dev set, boxes on the target score 5.3 or more (5th percentile per sequence), boxes off it in car14 and wakeboard4 4.1 or less (95th), and leave-one-sequence-out picks 4.0 for 6 of 7 folds."),
    key("track_state.drift_recheck_frames", Int, int(0, 10_000), "frames", LIVE,
        "After a failed drift check, the next check this many confident frames later (instead of `drift_check_frames`); failing it too makes the track lost on drift: the model and re-detection template go back to the last agreeing check's, and re-detection starts from the box (0 = a failed check never makes the track lost). 3: a second opinion on other frames (the box moves, the camera too) within a third of a second at 10 fps, before the learned filter has taken in much more of what it drifted onto. Not fitted: on the dev set 1 and 2 let wakeboard4 be lost on a box half on the target for 57 frames (flag precision 0.59, 0.49), 3 and 5 do not (0.94, 0.98), and leave-one-sequence-out does not single out a value (docs/states.md)."),
    key("track_state.verify_low_confidence", Bool, Range::Any, "", LIVE,
        "Ask the verifier on a low-confidence (`uncertain`) frame: a hit at or above `redetection.verifier_threshold` (the bar a re-acquisition must pass) at the box (its centre inside the box, one cell of the verifier's score map to spare; a hit elsewhere in its region, twice the target's context, does not count) reports the frame `tracking` (reason: confirmed) and publishes the confidence raised to `lost_threshold`; the unconfident frame still counts towards `lost_frames`. Off without a verifier."),
    key("track_state.drift_anchor", Bool, Range::Any, "", LIVE,
        "Let the first frame's filter (frozen at initialisation, never learned) answer a periodic drift check: when its confidence on the frame's detection features reaches `redetection.reacquire_threshold` (the bar a filter window needs to be a re-acquisition candidate) with its peak within 3 cells of the live filter's (what a re-detection search counts as the same place), the check agrees without a verifier pass. Re-checks after a failed check, the check at once on the first confident frame after any other state (a re-acquisition, an uncertain frame) and low-confidence confirmations always ask the verifier; so does a periodic check the frozen filter does not confirm (a target that changed since the first frame, a box on background). Off: every check is a verifier pass. On the dev set it answers 50 of the 96 periodic checks (the five sequences without a loss: 80 passes → 39; 770 → 720 in all) with every box and state byte-identical; no periodic check failed there: the 5 failed checks (car14, wakeboard4) were checks at once after an uncertain frame and re-checks, which it never answers, and its confidence on them was 0.27–0.38, below the 0.5 bar (docs/states.md)."),
    key("track_state.drift_head", Bool, Range::Any, "", LIVE,
        "Let the learned box's head pass of the frame (`box_refine`: NanoTrack's network and first-frame template, as the verifier's, on a crop at the box) answer what it can without a verifier pass: a periodic drift check agrees, and a low-confidence frame is confirmed (reason: confirmed), when the head's largest foreground logit margin at the box (the 3 × 3 grid points around the crop centre) reaches `redetection.verifier_threshold` (the bar a re-acquisition must pass). It never disputes a box: below the bar, and on frames the head did not run, the verifier is asked as before; re-checks after a failed check and the check at once after any other state always ask the verifier. Off: every check and confirmation is a verifier pass. On the dev set every box is the same, one good frame more is confirmed (flags precision 0.961 → 0.974, recall 0.961), 758 → 716 verifier passes; under the look-alike perturbation flags precision 0.722 → 0.901 (the verifier's best hit in its wider region can be the look-alike; the head reads at the box), under zoom recall 0.640 → 0.629 (docs/states.md)."),
    // redetection
    key("redetection.enabled", Bool, Range::Any, "", FIXED,
        "Search the frame for a lost target; off: only the window at the last known position is searched (with the same confirmation), at the scale of the loss."),
    key("redetection.windows_per_frame", Int, int(1, 256), "windows", LIVE,
        "Search windows evaluated per lost frame (the time bound; one window costs about one scale of a normal frame)."),
    key("redetection.scales", FloatList, factors(1, 8), "× scale at the loss", FIXED,
        "Scales tried, relative to the target scale when it was lost."),
    key("redetection.tile_stride", Float, closed(0.1, 1.0), "window sides", FIXED,
        "Distance between tile centres, fraction of the search-window side."),
    key("redetection.reacquire_threshold", Float, closed(0.0, 1.0), "", LIVE,
        "Confidence at or above which a window is a candidate (0–1)."),
    key("redetection.reacquire_relative", Float, closed(0.0, 1.0), "", LIVE,
        "A candidate's score must also reach this fraction of the learning gate's reference level frozen on the last confident frame (0–1; 0 = off): a look-alike that the frozen filter scores far below the target it was tracking is not taken, whatever its absolute confidence."),
    key("redetection.reacquire_frames", Int, int(1, 10_000), "frames", LIVE,
        "Frames in a row a candidate must stay confident before the track is taken back."),
    cross(key("redetection.proposals", Int, int(0, 256), "windows", FIXED,
        "Of `windows_per_frame`, how many go to whole-frame template-match proposals each lost frame (0 = none: only the tile walk)."),
        "<= redetection.windows_per_frame"),
    key("redetection.verifier", Kind::Choice(&["none", "nanotrack", "nanotrack_ort"]), Range::Any, "", FIXED,
        "A learned verifier that searches the frame while lost, besides the filter (`none`; `nanotrack`: NanoTrack v2 run in pure Rust, in every build; `nanotrack_ort`: the same on ONNX Runtime, cargo feature `cnn`)."),
    key("redetection.verifier_backbone", Path, Range::Any, "", FIXED,
        "The verifier's backbone (ONNX; NanoTrack v2, any input size); empty: the NanoTrack v2 backbone embedded in the library."),
    key("redetection.verifier_head", Path, Range::Any, "", FIXED,
        "The verifier's correlation head (ONNX); empty: the embedded NanoTrack v2 head."),
    key("redetection.verifier_windows", Int, int(1, 256), "passes", FIXED,
        "Verifier network passes per lost frame (the time bound of the verifier; one pass is one backbone run on a 255×255 search crop plus one head run)."),
    key("redetection.verifier_scales", FloatList, factors(1, 8), "× scale at the loss", FIXED,
        "Scales of the verifier's whole-frame tiles, relative to the target scale when it was lost."),
    key("redetection.verifier_threshold", Float, closed(-100.0, 100.0), "logit margin", FIXED,
        "Foreground logit margin (head classification, foreground − background) at or above which a verifier hit is a candidate."),
    key("redetection.verifier_filter_check", Bool, Range::Any, "", FIXED,
        "A verifier candidate takes the track back only when the frozen filter (the last confident frames' model), evaluated there once, would make it a candidate too (`reacquire_threshold` and `reacquire_relative`); otherwise it is dropped and the search goes on. Two witnesses that fail differently: the verifier (first frame, never learns) takes a look-alike of the target's shape and colours, the filter's relative bound does not (`tests/integration/verifier.rs`); the filter alone misses a target that re-enters where its windows are not (the verifier's tiles find it). Off by default: on the dev set it also refuses car14's real target after its 20-frame loss (never re-acquired; P@20 / AUC 0.893 / 0.570 against 0.979 / 0.603), the frozen filter's relative bound being too strict once the target's appearance has changed."),
    key("redetection.verifier_filter_hint", Bool, Range::Any, "", FIXED,
        "On a lost frame, the verifier's first tile pass goes to the frozen filter's most confident window of that frame (its position and scale) instead of the next tile of the walk, unless a verifier candidate is being followed (then that candidate's one pass is the frame's). The filter points, the verifier checks: the verifier alone decides, with the same bar and confirmation, and a lost frame spends the same `verifier_windows`. Off by default: on the dev set it re-acquires wakeboard4 12 frames sooner with a quarter fewer passes (568 against 758; P@20 0.976 → 0.983, bad frames 76 → 55), and under 5 of the 7 synthetic perturbations it leaves fewer bad frames with 9–59 % fewer passes, but the states flag the failures that remain less precisely: flags precision on the dev set 0.948 → 0.791 (issue 20 asks for 0.9), lower under 5 of the 7 perturbations (docs/states.md)."),
    cross(key("redetection.verifier_proposals", Int, int(0, 16), "passes", FIXED,
        "Of `verifier_windows`, how many of a lost frame's verifier passes go first to the best whole-frame template-match proposals (the re-detection template matched over the whole frame at the scale of the loss, as for the filter's `proposals`), after the filter's hint if taken and before the tile walk; 0 = the tile walk alone. A lost frame spends the same `verifier_windows`; the verifier alone decides, with the same bar and confirmation. Off by default: with 2 on the dev set wakeboard4 is re-acquired 15 frames sooner and the passes fall 678 → 491 (P@20 / AUC 0.978 / 0.700 → 0.986 / 0.702; 0.85× → 0.88× TrackerNano), zoom=1.5 leaves 108 fewer bad frames with 57 % fewer passes, but the flags' precision falls 0.971 → 0.871 (issue 20 asks for 0.9) and where the target's shape changed the stale template points at background (aspect=1.4: AUC 0.601 → 0.551; docs/states.md)."),
        "<= redetection.verifier_windows"),
    key("redetection.verifier_tile_cells", Int, int(8, 32), "grid points", FIXED,
        "Side of the verifier's whole-frame tiles, even: a tile is a crop of 16·n − 1 pixels at NanoTrack's resolution (16: NanoTrack's 255-pixel search crop; larger: more of the frame per pass, the pass's cost going with the crop's area, the tiles' spacing with their side). Candidates, the filter's hint and proposals keep the 16-cell crop. Other than 16 needs `verifier: nanotrack`. 16 by default: NanoTrack's head finds the target more often in a 24-cell crop (`scripts/verifier_tile_probe.py`: 0.62 of the dev set's crops holding it against 0.47, false hits per area the same), but with `verifier_windows: 7` (the default's cost per lost frame) the selection protocol gains under 6 of its 10 perturbations and loses under 3 (aspect 0.601 → 0.520, shake 8 s2 0.514 → 0.483), its mean of ten 0.532 against 0.535, 10 % fewer pass-equivalents over the 11 conditions and the flags' precision lower under 7 (dev set 0.971 → 0.877); fewer windows lengthen the dev set's losses (docs/benchmarks.md)."),
    key("redetection.filter_search", Kind::Choice(&["auto", "always"]), Range::Any, "", FIXED,
        "Whether the frozen filter sweeps the frame while lost (whole-frame proposals and the tile walk, within `windows_per_frame`) or only follows the last position and its candidate. `auto`: it sweeps only when no verifier searches (`verifier: none`) or the verifier takes its hint (`verifier_filter_hint`); with the verifier's 16 passes a frame sweeping the frame in a few frames, the filter's 2–3 tiles a frame add time and no re-acquisition (dev set and 7 perturbations: every frame's state the same under 7 of 8 conditions, the flags' precision the same or higher under 7 (blur: 0.996 → 0.995, and its recall 0.554 → 0.463), the confidence's ROC-AUC higher under 7; 1.14× the default's pooled fps; docs/states.md). `always`: it sweeps beside the verifier too (the default before 2026-11-28)."),
    // box_refine
    key("box_refine.mode", Kind::Choice(&["none", "nanotrack", "nanotrack_ort"]), Range::Any, "", FIXED,
        "`none`: the box is the filter's (first frame's aspect, scale filter); `nanotrack`: NanoTrack v2's head regresses the box on a search crop at the filter's position every `interval` tracked frames (pure Rust, one backbone and one head pass per run; docs/algorithm.md \"Box refinement\"); `nanotrack_ort`: the same on ONNX Runtime (cargo feature `cnn`). The networks are `redetection.verifier_backbone` / `verifier_head`."),
    key("box_refine.min_score", Float, closed(0.0, 1.0), "probability", FIXED,
        "Head foreground probability (mean over the grid points read) at or above which its box is taken (else the prior is kept)."),
    key("box_refine.max_offset", Float, closed(0.0, 10.0), "target sizes", FIXED,
        "Largest distance between the head's and the filter's box centres, in target sizes (√(w·h)), for the head's box to be taken."),
    key("box_refine.min_side", Float, closed(0.0, 1e4), "px", FIXED,
        "Targets whose shorter side is below this keep the prior box (the head does not run; the initial box is not calibrated)."),
    key("box_refine.center_weight", Float, closed(0.0, 1.0), "", FIXED,
        "Weight of the head's centre against the filter's when the head's box is taken (0: the filter's centre, so precision is `mode: none`'s; 1: the head's)."),
    key("box_refine.report_center", Float, closed(0.0, 1.0), "", FIXED,
        "Weight of the head's centre in the reported box only, when its box is taken (0: the track's centre; 1: the head's). The filter's track, its learning and the lost-state search keep their own centre (unlike `center_weight`); the offset is held between head runs (`interval`) and dropped when the head refuses its box or the track is lost."),
    key("box_refine.penalty_k", Float, closed(0.0, 10.0), "", FIXED,
        "NanoTrack's scale/aspect-change penalty k: score × exp(−k·(r·s − 1))."),
    key("box_refine.window_influence", Float, closed(0.0, 1.0), "", FIXED,
        "NanoTrack's cosine-window weight on the penalised score map."),
    key("box_refine.size_rate", Float, closed(0.0, 1.0), "", FIXED,
        "NanoTrack's size learning rate (times the chosen point's penalised score)."),
    key("box_refine.read", Kind::Choice(&["filter", "peak"]), Range::Any, "", FIXED,
        "Where the head's box is read: `filter`, the score-weighted box of the 3×3 grid points at the filter's position (the filter localises, the head sizes: ATOM/DiMP's division of labour; a look-alike elsewhere in the crop cannot take the box); `peak`, NanoTrack's arg-max of the penalised score map with its cosine window."),
    key("box_refine.min_iou", Float, closed(0.0, 1.0), "IoU", FIXED,
        "Smallest IoU between the head's box and the filter's (the filter's centre, the current box size) for the head's box to be taken (0: no IoU gate)."),
    key("box_refine.max_change", Float, closed(0.0, 1.0), "fraction per frame", FIXED,
        "Largest relative change of the box's width or height the head makes in one frame (0.1: at most ×1.1 or ÷1.1; the fastest real size or aspect change on the dev set is about 3 % a frame at 10 fps)."),
    key("box_refine.feed_scale", Bool, Range::Any, "", FIXED,
        "The head's size also sets the filter's scale (its window, the scale filter's next estimate, the scale kept at a loss); `false`: it sets only the reported box, and the filter tracks as with `mode: none`."),
    key("box_refine.prior", Kind::Choice(&["box", "filter"]), Range::Any, "", FIXED,
        "What the head's box is blended into each frame: `box`, the previous box moved by the scale filter's change (the head's corrections accumulate: NanoTrack's smoothing, the box converges to the head's); `filter`, the filter's own box (first frame's aspect, the scale filter's size): a per-frame fusion of two size estimates, a biased head moving the box by at most its rate."),
    key("box_refine.calibrate", Bool, Range::Any, "", FIXED,
        "Calibrate the head to the initial box: the given box defines the target's extent, and the per-side ratio of it to the head's box on the initial frame (within ×/÷1.5) scales every later head box, removing the head's per-object bias (a building with its surroundings). Needs an initial box whose shorter side is at least `min_side`; otherwise the head's boxes are taken as they are."),
    key("box_refine.interval", Int, int(1, 1000), "frames", FIXED,
        "Run the head every this many tracked frames (1: every frame); between runs the box follows the scale filter with the last correction (the cost bound)."),
    key("box_refine.search_cells", Int, int(4, 16), "grid points", FIXED,
        "Side of the head's search map, even: the crop is 16·n − 1 pixels at NanoTrack's pixels per target pixel (16: NanoTrack's 255-pixel search; smaller: a tighter context around the filter's position, the backbone's cost going with the crop's area). Other than 16 needs `mode: nanotrack`."),
    // motion
    key("motion.camera", Bool, Range::Any, "", FIXED,
        "Camera motion compensation: each frame's search is centred where the scene's shift since the previous frame (phase correlation of coarse grey copies of the whole frames) plus the target's own motion in the scene put the target, instead of at its last position. For small targets under camera jerks (a 47 px search window around an 11 × 8 px target). While the target is lost, the lost search's followed position and candidates move the same way. Off by default: with the learned box, under the eval's `shake` it gains 0.10–0.20 AUC on the dev set; unshaken it does not gain (0.697 → 0.656, 0.677 with `min_move: 0.1`, chosen in 1 of 7 leave-one-out folds), and it loses under aspect (−0.05 gated) and zoom (−0.02 gated), an 11 × 8 px target lost (docs/results.md \"Camera motion compensation\")."),
    key("motion.min_peak", Float, closed(0.0, 1.0), "correlation peak", FIXED,
        "Phase-correlation peak a frame's scene shift needs to be used (1: a pure shift; noise alone peaks near 0.04 on the 128-cell grid); below it the frame's shift is taken as none (texture-poor water or sky, a scene cut)."),
    key("motion.own", Kind::Choice(&["camera", "tracker"]), Range::Any, "", FIXED,
        "The target's own motion in the scene: `camera`, the camera's smooth motion reversed (a camera that follows its target; only the camera's jerks move the search, and a static target under a steady pan is searched as without compensation); `tracker`, the running mean of what the tracker measured on confident frames less the scene's shift (any target, but its errors feed the next search)."),
    key("motion.own_rate", Float, closed(0.0, 1.0), "per frame", FIXED,
        "Running-mean rate of the own motion (0: none, the search follows the scene's shift alone)."),
    key("motion.min_move", Float, closed(0.0, 1.0), "× search window side", FIXED,
        "A tracked frame's search is moved only when the prediction moves it by at least this fraction of the search window's side (0: always). Small moves are within the filter's own reach and carry the shift's noise; at 0.1 the unshaken dev set is 0.938 / 0.590 with flags precision 0.964 (0.946 / 0.560 and 0.639 at 0), but under `shake=16,seed=1` 0.884 / 0.563 against 0.982 / 0.607 (docs/results.md \"Camera motion compensation\"). The lost search always moves."),
    // threads
    key("threads", Int, int(1, 256), "threads", FIXED,
        "Worker threads for the per-scale work of one frame (1 = sequential). Work runs on the caller's rayon pool; the core spawns no threads itself. With the scale filter (the default) there is one patch per frame, so it gains nothing."),
];
