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

use crate::config::cnn_spec;
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

fn refuse(name: &str, value: impl ToString) -> ConfigError {
    let k = cnn_spec(name);
    ConfigError::OutOfRange {
        field: k.name,
        value: value.to_string(),
        expected: k.constraints(),
    }
}

fn int_key(name: &str, v: usize) -> Result<(), ConfigError> {
    cnn_spec(name).check_int(v)
}

fn float_key(name: &str, v: f32) -> Result<(), ConfigError> {
    cnn_spec(name).check_float(v)
}

/// A constraint the table states only in words ([`crate::config::KeySpec::cross`]).
fn cross_key(ok: bool, name: &str, value: impl ToString) -> Result<(), ConfigError> {
    if ok {
        Ok(())
    } else {
        Err(refuse(name, value))
    }
}

impl CnnConfig {
    /// Checks every field against [`crate::config::CNN_KEYS`] (ranges), then the
    /// constraints the table states in words (the model itself is checked when it is
    /// loaded).
    ///
    /// # Errors
    /// [`ConfigError`] naming the offending `features.cnn.*` key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        cross_key(!self.model.is_empty(), "features.cnn.model", "(empty)")?;
        cross_key(!self.input.is_empty(), "features.cnn.input", "(empty)")?;
        int_key("features.cnn.input_size", self.input_size)?;
        float_key("features.cnn.value_scale", self.value_scale)?;
        cnn_spec("features.cnn.mean").check_list(&self.mean)?;
        cnn_spec("features.cnn.std").check_list(&self.std)?;
        cross_key(
            self.std.iter().all(|v| *v > 0.0),
            "features.cnn.std",
            format!("{:?}", self.std),
        )?;
        int_key("features.cnn.cell_size", self.cell_size)?;
        int_key("features.cnn.layers", self.layers.len())?;
        for l in &self.layers {
            cross_key(
                !l.output.is_empty(),
                "features.cnn.layers[].output",
                "(empty)",
            )?;
            int_key("features.cnn.layers[].channels", l.channels)?;
            float_key("features.cnn.layers[].weight", l.weight)?;
            float_key("features.cnn.layers[].gain", l.gain)?;
            int_key("features.cnn.layers[].project", l.project)?;
            cross_key(
                l.project <= l.channels && (l.project == 0 || l.channels <= MAX_PROJECTED_CHANNELS),
                "features.cnn.layers[].project",
                l.project,
            )?;
        }
        if let Some(h) = &self.hog {
            float_key("features.cnn.hog.weight", h.weight)?;
            float_key("features.cnn.hog.gain", h.gain)?;
        }
        int_key("features.cnn.intra_threads", self.intra_threads)?;
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
                assert_eq!(field, "features.cnn.layers[].channels")
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
                assert_eq!(field, "features.cnn.layers[].project")
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

    /// Every key the table names is a field of the section (and every field is in the
    /// table), and the ranges that bound allocations agree with the constants the
    /// extractor allocates by.
    #[test]
    fn the_table_matches_the_section() {
        use crate::config::{Range, CNN_KEYS};
        let mut c = nanotrack();
        c.hog = Some(CnnHogConfig::default());
        let v = serde_norway::to_value(&c).unwrap();
        let mut fields = vec![];
        let serde_norway::Value::Mapping(m) = &v else {
            panic!("{v:?}")
        };
        for (k, val) in m {
            let k = k.as_str().unwrap();
            fields.push(format!("features.cnn.{k}"));
            let sub = match (k, val) {
                ("layers", serde_norway::Value::Sequence(s)) => Some(("layers[]", &s[0])),
                ("hog", x) => Some(("hog", x)),
                _ => None,
            };
            if let Some((prefix, serde_norway::Value::Mapping(sm))) = sub {
                for sk in sm.keys() {
                    fields.push(format!("features.cnn.{prefix}.{}", sk.as_str().unwrap()));
                }
            }
        }
        let mut table: Vec<String> = CNN_KEYS.iter().map(|k| k.name.to_string()).collect();
        fields.sort();
        table.sort();
        assert_eq!(fields, table);
        let bound = |name: &str| cnn_spec(name).range;
        assert_eq!(
            bound("features.cnn.input_size"),
            Range::Int(16, MAX_INPUT_SIZE as u64)
        );
        assert_eq!(
            bound("features.cnn.layers"),
            Range::Int(1, MAX_LAYERS as u64)
        );
        assert_eq!(
            bound("features.cnn.layers[].channels"),
            Range::Int(1, MAX_LAYER_CHANNELS as u64)
        );
        assert_eq!(
            bound("features.cnn.intra_threads"),
            Range::Int(1, MAX_INTRA_THREADS as u64)
        );
    }

    /// A value out of the table's range is refused naming the key and the range in the
    /// table's words.
    #[test]
    fn refusals_quote_the_table() {
        let mut c = nanotrack();
        c.mean = [0.0, f32::NAN, 0.0];
        let e = c.validate().unwrap_err().to_string();
        assert!(
            e.contains("features.cnn.mean") && e.contains("3 values in"),
            "{e}"
        );
        let mut c = nanotrack();
        c.layers[0].gain = 2e6;
        let e = c.validate().unwrap_err().to_string();
        assert!(
            e.contains("features.cnn.layers[].gain") && e.contains("(0, 1e6]"),
            "{e}"
        );
        let mut c = nanotrack();
        c.layers = vec![c.layers[0].clone(); MAX_LAYERS + 1];
        let e = c.validate().unwrap_err().to_string();
        assert!(
            e.contains("features.cnn.layers") && e.contains("1..=8 layers"),
            "{e}"
        );
        let mut c = nanotrack();
        c.intra_threads = 0;
        assert!(c.validate().is_err());
        let mut c = nanotrack();
        c.input = String::new();
        let e = c.validate().unwrap_err().to_string();
        assert!(
            e.contains("features.cnn.input") && e.contains("non-empty"),
            "{e}"
        );
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
