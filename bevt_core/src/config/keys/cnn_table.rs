//! The keys of the optional `features.cnn` section: [`CNN_KEYS`].
//!
//! They are written in configuration files only (the node takes the whole section from its
//! tracker file, never as parameters, so they have no ROS descriptors). From this table come
//! `CnnConfig::validate`'s range checks and `docs/configuration.md`'s `features.cnn` table;
//! defaults are `CnnConfig::default()`. `layers[].x` is key `x` of every entry of the list.

use super::{above, cross, int, key, KeySpec, Kind, Range, FIXED};
use Kind::{Bool, Float, FloatList, Int, Path, Section, Text};

/// Per-plane means and divisors: three values, as a pixel scaled by `value_scale` can be.
const PLANES: Range = Range::List {
    min_len: 3,
    max_len: 3,
    lo: -1e6,
    hi: 1e6,
};

/// Every `features.cnn` key, in `CnnConfig` order.
#[rustfmt::skip]
pub static CNN_KEYS: &[KeySpec] = &[
    cross(key("features.cnn.model", Path, Range::Any, "", FIXED,
        "ONNX model file."),
        "required (non-empty)"),
    key("features.cnn.runtime", Path, Range::Any, "", FIXED,
        "ONNX Runtime shared library; empty = `ORT_DYLIB_PATH` (`scripts/onnxruntime.sh` fetches it)."),
    cross(key("features.cnn.input", Text, Range::Any, "", FIXED,
        "Name of the model's `[1, 3, H, W]` float32 input."),
        "non-empty"),
    key("features.cnn.input_size_policy", Kind::Choice(&["fixed", "patch"]), Range::Any, "", FIXED,
        "`fixed`: the patch is resampled to `input_size`; `patch`: fed at its own resolution (the model must accept dynamic H, W; capped at 512 px as the tracker's patch side)."),
    key("features.cnn.input_size", Int, int(16, 512), "px", FIXED,
        "Input side for the `fixed` policy (bounds the input buffer allocated from configuration)."),
    key("features.cnn.channel_order", Kind::Choice(&["rgb", "bgr"]), Range::Any, "", FIXED,
        "Colour plane order of the input."),
    key("features.cnn.value_scale", Float, above(0.0, 1e6), "", FIXED,
        "Pixel values (0–255) are multiplied by this first: 1 keeps 0–255, 1/255 gives 0–1."),
    key("features.cnn.mean", FloatList, PLANES, "", FIXED,
        "Per-plane mean subtracted after `value_scale`, in input order."),
    cross(key("features.cnn.std", FloatList, PLANES, "", FIXED,
        "Per-plane divisor applied after the mean, in input order."),
        "each > 0"),
    key("features.cnn.cell_size", Int, int(1, 32), "px", FIXED,
        "Patch pixels per feature cell (the grid stride; reference 4); the network's maps are resampled bilinearly to the grid."),
    key("features.cnn.layers", Section, int(1, 8), "layers", FIXED,
        "The outputs used, each with its own filter (keys `layers[].*`)."),
    cross(key("features.cnn.layers[].output", Text, Range::Any, "", FIXED,
        "Output name in the ONNX graph."),
        "required (non-empty)"),
    key("features.cnn.layers[].channels", Int, int(1, 4096), "", FIXED,
        "Channels the output must have (required; checked against the model at init)."),
    key("features.cnn.layers[].weight", Float, above(0.0, 1e6), "", FIXED,
        "Weight of this layer's response in the fused response (reference: shallow 1, middle 0.5, deep 0.25)."),
    key("features.cnn.layers[].gain", Float, above(0.0, 1e6), "", FIXED,
        "Gain on the layer's (normalised) values: sets the data term against the ADMM μ."),
    key("features.cnn.layers[].norm", Kind::Choice(&["rms", "none"]), Range::Any, "", FIXED,
        "Per-frame RMS normalisation before the gain (pytracking's `normalize_power = 2`), or raw activations."),
    cross(key("features.cnn.layers[].project", Int, int(0, 4096), "channels", FIXED,
        "Channels after a PCA projection learned on each track's first frame (ECO style); 0 = none."),
        "<= the layer's channels; 0 when channels > 1024 (the PCA is C × C)"),
    key("features.cnn.intra_threads", Int, int(1, 64), "threads", FIXED,
        "ONNX Runtime intra-op threads (1 = one core; the tracker's own `threads` is separate)."),
    key("features.cnn.device", Kind::Choice(&["cpu", "cuda"]), Range::Any, "", FIXED,
        "Execution provider; `cuda` needs the cargo feature `cuda` and never falls back to CPU."),
    key("features.cnn.single_pass_scales", Bool, Range::Any, "", FIXED,
        "One network pass on the largest scale's patch per frame, the other scales' maps resampled from it (5-scale search only)."),
    key("features.cnn.train_from_detection", Bool, Range::Any, "", FIXED,
        "Train on the winning scale's detection features shifted onto the new position (one pass per frame fewer, as ECO) instead of a fresh pass."),
    key("features.cnn.hog", Section, Range::Any, "", FIXED,
        "HOG (+ gray) (+ colour names) of the same patch fused as one more layer at the CNN's cell size (keys `hog.*`; absent = CNN layers only)."),
    key("features.cnn.hog.weight", Float, above(0.0, 1e6), "", FIXED,
        "Response weight of the HOG layer."),
    key("features.cnn.hog.gain", Float, above(0.0, 1e6), "", FIXED,
        "Gain on the HOG values, on top of `features.gain`."),
    key("features.cnn.hog.grayscale", Bool, Range::Any, "", FIXED,
        "Append the grayscale channel."),
    key("features.cnn.hog.colornames", Bool, Range::Any, "", FIXED,
        "Append the 10 colour-name channels (colour frames only)."),
];

/// The spec of `features.cnn` key `name`.
///
/// # Panics
/// When `name` is not in [`CNN_KEYS`] (a test runs every lookup `CnnConfig::validate` makes).
#[allow(clippy::panic)]
pub fn cnn_spec(name: &str) -> &'static KeySpec {
    match CNN_KEYS.iter().find(|k| k.name == name) {
        Some(k) => k,
        None => panic!("features.cnn key {name} is not in CNN_KEYS"),
    }
}
