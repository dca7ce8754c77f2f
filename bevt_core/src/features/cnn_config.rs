//! Configuration of CNN features (`features.cnn`), independent of the backbone.
//!
//! Always compiled, so every build parses and validates the same YAML; the extractor itself
//! (`crate::features::cnn`) needs the `cnn` cargo feature. A model is described by its
//! file, how a patch becomes its input tensor (size, channel order, value range and
//! normalisation) and which outputs are used, each as one layer with its own filter and
//! response weight (ALGORITHM.md §2).
//!
//! Paths: the library opens `model` and `runtime` as given (relative to the process's working
//! directory); the `bevt` tool and the node resolve relative paths in a config *file* against
//! that file's folder first, so the presets in `config/` name `../models/...`.

use crate::error::ConfigError;
use serde::{Deserialize, Serialize};

/// Largest network input side, pixels: bounds the input buffer allocated from config.
pub const MAX_INPUT_SIZE: usize = 512;
/// Largest channel count of one layer accepted from config.
pub const MAX_LAYER_CHANNELS: usize = 4096;
/// Most layers of one model.
pub const MAX_LAYERS: usize = 8;
/// Largest layer a PCA projection is learned for (its C × C eigenproblem runs at init).
pub const MAX_PROJECTED_CHANNELS: usize = 1024;
/// Largest intra-op thread count.
pub const MAX_INTRA_THREADS: usize = 64;

/// How the network's input size is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum InputSizePolicy {
    /// The search patch is resampled to `input_size × input_size` pixels (the reference
    /// resizes to VGG's 224; a fixed-shape model needs its own size).
    Fixed,
    /// The search patch is fed at its own resolution (`grid · cell_size` pixels): the input
    /// size then follows the target, and the model must accept dynamic height and width.
    Patch,
}

/// Order of the three colour planes in the network input.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ChannelOrder {
    /// Red, green, blue (torchvision models, NanoTrack).
    Rgb,
    /// Blue, green, red (Caffe/MatConvNet-style exports).
    Bgr,
}

/// Per-layer normalisation of a feature map before the Hann window.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LayerNorm {
    /// Raw activations times `gain`.
    None,
    /// Each frame's map divided by its root-mean-square value, then times `gain` (as
    /// pytracking's `normalize_power = 2`): responses no longer depend on the layer's
    /// activation scale or the image contrast.
    Rms,
}

/// Execution device of the network.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CnnDevice {
    /// ONNX Runtime's CPU provider.
    Cpu,
    /// ONNX Runtime's CUDA provider (cargo feature `cuda` and the runtime of
    /// `onnxruntime-gpu`); init fails when it cannot be registered, it never falls back.
    Cuda,
}

/// One network output used as a feature layer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CnnLayerConfig {
    /// Output name in the ONNX graph, e.g. `feat_s8`.
    pub output: String,
    /// Channels the output must have (checked at init against the model).
    pub channels: usize,
    /// Weight of this layer's response in the fused response (reference: shallow 1,
    /// middle 0.5, deep 0.25).
    #[serde(default = "one")]
    pub weight: f32,
    /// Gain on the layer's (normalised) values: sets the data term against the ADMM μ.
    #[serde(default = "one")]
    pub gain: f32,
    /// Normalisation of the layer's map.
    #[serde(default = "default_norm")]
    pub norm: LayerNorm,
    /// Channels after a PCA projection learned on each track's first frame (ECO style:
    /// FFTs, ADMM and detection then work on this many channels); 0 = no projection.
    #[serde(default)]
    pub project: usize,
}

impl CnnLayerConfig {
    /// Channels this layer gives the tracker: `project` when set, else `channels`.
    pub fn out_channels(&self) -> usize {
        if self.project > 0 {
            self.project
        } else {
            self.channels
        }
    }
}

/// HOG (+ gray) (+ colour names) fused with the CNN layers (`features.cnn.hog`): one more
/// layer with its own filter and response weight, computed on the same search patch at the
/// CNN's cell size.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CnnHogConfig {
    /// Weight of the HOG layer's response in the fused response.
    pub weight: f32,
    /// Gain on the HOG values (on top of `features.gain`, which scales every layer).
    pub gain: f32,
    /// Append a cell-mean grayscale channel.
    pub grayscale: bool,
    /// Append the 10 colour-name channels (colour frames only).
    pub colornames: bool,
}

impl Default for CnnHogConfig {
    fn default() -> Self {
        Self {
            weight: 1.0,
            gain: 1.0,
            grayscale: true,
            colornames: false,
        }
    }
}

fn one() -> f32 {
    1.0
}

fn default_norm() -> LayerNorm {
    LayerNorm::Rms
}

/// CNN feature settings (`features.cnn`); required when `features.kind` is `cnn`. Missing
/// keys take the NanoTrack v2 backbone's values (`config/cnn_nanotrack.yaml`), except
/// `model`, which must be given.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CnnConfig {
    /// ONNX model file (see the module doc for how relative paths resolve).
    pub model: String,
    /// ONNX Runtime shared library (`libonnxruntime.so.1.31.1`); empty = the
    /// `ORT_DYLIB_PATH` environment variable. `scripts/onnxruntime.sh` fetches it.
    pub runtime: String,
    /// Name of the model's image input (`[1, 3, H, W]`, float32).
    pub input: String,
    /// How the input size is chosen.
    pub input_size_policy: InputSizePolicy,
    /// Input side, pixels, for the `fixed` policy (16..=512; the `patch` policy is capped
    /// at 512 too, as the tracker's patch side).
    pub input_size: usize,
    /// Colour plane order of the input.
    pub channel_order: ChannelOrder,
    /// Pixel values (0–255) are multiplied by this first: 1 keeps 0–255, 1/255 gives 0–1.
    pub value_scale: f32,
    /// Per-plane mean subtracted after `value_scale`, in input order.
    pub mean: [f32; 3],
    /// Per-plane divisor applied after the mean, in input order (all > 0).
    pub std: [f32; 3],
    /// Pixels of the search patch per feature cell (the grid stride; reference 4). The
    /// network's maps are resampled bilinearly to the grid whatever its own stride.
    pub cell_size: usize,
    /// The outputs used, each its own filter.
    pub layers: Vec<CnnLayerConfig>,
    /// ONNX Runtime intra-op threads (1 = one core; the tracker's own `threads` is separate).
    pub intra_threads: usize,
    /// Execution device.
    pub device: CnnDevice,
    /// One network pass on the largest scale's patch per frame, the other scales' maps
    /// resampled from it (true), instead of one pass per scale (false: S passes per frame).
    pub single_pass_scales: bool,
    /// Train on the winning scale's detection features shifted onto the new position (one
    /// network pass per frame fewer, as ECO) instead of a fresh pass at the new position.
    pub train_from_detection: bool,
    /// HOG fused with the CNN layers as one more layer (absent = CNN layers only).
    pub hog: Option<CnnHogConfig>,
}

impl Default for CnnConfig {
    fn default() -> Self {
        Self {
            model: String::new(),
            runtime: String::new(),
            input: "input".to_string(),
            input_size_policy: InputSizePolicy::Fixed,
            input_size: 255,
            channel_order: ChannelOrder::Rgb,
            value_scale: 1.0,
            mean: [0.0; 3],
            std: [1.0; 3],
            cell_size: 4,
            layers: vec![CnnLayerConfig {
                output: "output".to_string(),
                channels: 48,
                weight: 1.0,
                gain: 1.0,
                norm: LayerNorm::Rms,
                project: 0,
            }],
            intra_threads: 1,
            device: CnnDevice::Cpu,
            single_pass_scales: false,
            train_from_detection: false,
            hog: None,
        }
    }
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
            expected: expected.to_string(),
        })
    }
}

impl CnnConfig {
    /// Range checks of every field (the model itself is checked when it is loaded).
    ///
    /// # Errors
    /// [`ConfigError`] naming the offending `features.cnn.*` key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        check(
            !self.model.is_empty(),
            "features.cnn.model",
            "(empty)",
            "a path to an ONNX file",
        )?;
        check(
            !self.input.is_empty(),
            "features.cnn.input",
            "(empty)",
            "the model's input name",
        )?;
        check(
            (16..=MAX_INPUT_SIZE).contains(&self.input_size),
            "features.cnn.input_size",
            self.input_size,
            "16..=512 pixels",
        )?;
        check(
            self.value_scale.is_finite() && self.value_scale > 0.0,
            "features.cnn.value_scale",
            self.value_scale,
            "> 0",
        )?;
        check(
            self.mean.iter().all(|v| v.is_finite()),
            "features.cnn.mean",
            format!("{:?}", self.mean),
            "finite values",
        )?;
        check(
            self.std.iter().all(|v| v.is_finite() && *v > 0.0),
            "features.cnn.std",
            format!("{:?}", self.std),
            "finite values > 0",
        )?;
        check(
            (1..=32).contains(&self.cell_size),
            "features.cnn.cell_size",
            self.cell_size,
            "1..=32 pixels",
        )?;
        check(
            (1..=MAX_LAYERS).contains(&self.layers.len()),
            "features.cnn.layers",
            self.layers.len(),
            "1..=8 layers",
        )?;
        for l in &self.layers {
            check(
                !l.output.is_empty(),
                "features.cnn.layers.output",
                "(empty)",
                "an output name",
            )?;
            check(
                (1..=MAX_LAYER_CHANNELS).contains(&l.channels),
                "features.cnn.layers.channels",
                l.channels,
                "1..=4096",
            )?;
            check(
                l.weight.is_finite() && l.weight > 0.0,
                "features.cnn.layers.weight",
                l.weight,
                "> 0",
            )?;
            check(
                l.gain.is_finite() && l.gain > 0.0 && l.gain <= 1e6,
                "features.cnn.layers.gain",
                l.gain,
                "(0, 1e6]",
            )?;
            check(
                l.project <= l.channels,
                "features.cnn.layers.project",
                l.project,
                "0 (no projection) or 1..=the layer's channels",
            )?;
            check(
                l.project == 0 || l.channels <= MAX_PROJECTED_CHANNELS,
                "features.cnn.layers.project",
                l.project,
                "0 for layers of more than 1024 channels (the PCA is C x C)",
            )?;
        }
        if let Some(h) = &self.hog {
            check(
                h.weight.is_finite() && h.weight > 0.0,
                "features.cnn.hog.weight",
                h.weight,
                "> 0",
            )?;
            check(
                h.gain.is_finite() && h.gain > 0.0 && h.gain <= 1e6,
                "features.cnn.hog.gain",
                h.gain,
                "(0, 1e6]",
            )?;
        }
        check(
            (1..=MAX_INTRA_THREADS).contains(&self.intra_threads),
            "features.cnn.intra_threads",
            self.intra_threads,
            "1..=64",
        )?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn nanotrack() -> CnnConfig {
        CnnConfig {
            model: "nanotrack.onnx".to_string(),
            ..CnnConfig::default()
        }
    }

    #[test]
    fn defaults_with_a_model_are_valid_and_without_one_are_not() {
        nanotrack().validate().unwrap();
        match CnnConfig::default().validate() {
            Err(ConfigError::OutOfRange { field, .. }) => assert_eq!(field, "features.cnn.model"),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn bad_values_name_their_key() {
        let mut c = nanotrack();
        c.layers[0].channels = 0;
        match c.validate() {
            Err(ConfigError::OutOfRange { field, .. }) => {
                assert_eq!(field, "features.cnn.layers.channels")
            }
            other => panic!("{other:?}"),
        }
        let mut c = nanotrack();
        c.std[1] = 0.0;
        assert!(c.validate().is_err());
        let mut c = nanotrack();
        c.layers.clear();
        assert!(c.validate().is_err());
        let mut c = nanotrack();
        c.input_size = 100_000;
        assert!(c.validate().is_err());
        let mut c = nanotrack();
        c.layers[0].project = 49;
        match c.validate() {
            Err(ConfigError::OutOfRange { field, .. }) => {
                assert_eq!(field, "features.cnn.layers.project")
            }
            other => panic!("{other:?}"),
        }
        c.layers[0].project = 48;
        c.validate().unwrap();
        assert_eq!(c.layers[0].out_channels(), 48);
        c.layers[0].project = 16;
        assert_eq!(c.layers[0].out_channels(), 16);
        let mut c = nanotrack();
        c.hog = Some(CnnHogConfig {
            weight: 0.0,
            ..CnnHogConfig::default()
        });
        match c.validate() {
            Err(ConfigError::OutOfRange { field, .. }) => {
                assert_eq!(field, "features.cnn.hog.weight")
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn layers_parse_with_defaults_and_reject_unknown_keys() {
        let c: CnnConfig =
            serde_norway::from_str("layers:\n  - output: feat_s8\n    channels: 192\n").unwrap();
        assert_eq!(c.layers[0].weight, 1.0);
        assert_eq!(c.layers[0].norm, LayerNorm::Rms);
        assert!(serde_norway::from_str::<CnnConfig>(
            "layers:\n  - output: x\n    channels: 1\n    wieght: 2\n"
        )
        .is_err());
        assert!(serde_norway::from_str::<CnnConfig>(
            "layers:\n  - output: x\n    channels: 8\n    projet: 2\n"
        )
        .is_err());
        assert!(serde_norway::from_str::<CnnConfig>("hog:\n  wieght: 2\n").is_err());
        let c: CnnConfig = serde_norway::from_str("hog:\n  weight: 0.5\n").unwrap();
        assert_eq!(
            c.hog,
            Some(CnnHogConfig {
                weight: 0.5,
                ..CnnHogConfig::default()
            })
        );
    }
}
