//! Tracker configuration from YAML files plus `key.path=value` overrides, validated once.

use bevt_core::{TrackerConfig, TrackerSpec};
use std::path::Path;
use thiserror::Error;

/// The shipped default configuration (`config/bevt.yaml`), embedded so the tools work
/// without any file.
pub const DEFAULT_CONFIG_YAML: &str = include_str!("../../config/bevt.yaml");

/// Errors of configuration loading.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ParamsError {
    /// The file cannot be read.
    #[error("cannot read config {path}: {source}")]
    Io {
        /// The path.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The YAML is malformed or has unknown keys / wrong types.
    #[error("invalid config {origin}: {reason}")]
    Parse {
        /// File name or `--set` argument.
        origin: String,
        /// Parser message.
        reason: String,
    },
    /// A value is out of range.
    #[error("invalid config: {0}")]
    Invalid(#[from] bevt_core::ConfigError),
}

/// Loads `path` (or the embedded default), applies `overrides` (`admm.penalty=none`, values
/// parsed as YAML scalars) and validates.
///
/// # Errors
/// [`ParamsError`] naming the file, the override or the field at fault.
pub fn load_config(path: Option<&Path>, overrides: &[String]) -> Result<TrackerSpec, ParamsError> {
    let (origin, text) = match path {
        Some(p) => (
            p.display().to_string(),
            crate::yaml::read_file(p).map_err(|reason| ParamsError::Parse {
                origin: p.display().to_string(),
                reason,
            })?,
        ),
        None => (
            "(embedded default)".to_string(),
            DEFAULT_CONFIG_YAML.to_string(),
        ),
    };
    let parse_err = |origin: &str, e: &dyn std::fmt::Display| ParamsError::Parse {
        origin: origin.to_string(),
        reason: e.to_string(),
    };
    let mut value: serde_norway::Value = if text.trim().is_empty() {
        serde_norway::Value::Mapping(Default::default())
    } else {
        crate::yaml::parse(&text, &origin).map_err(|e| parse_err(&origin, &e))?
    };
    if let Some(dir) = path.and_then(Path::parent) {
        resolve_cnn_paths(&mut value, dir);
    }
    for o in overrides {
        let (key, raw) = o
            .split_once('=')
            .ok_or_else(|| parse_err(o, &"expected key.path=value"))?;
        let v: serde_norway::Value = crate::yaml::parse(raw, o).map_err(|e| parse_err(o, &e))?;
        crate::yaml::set_dotted(&mut value, key, v).map_err(|e| parse_err(o, &e))?;
        // A wrong type is reported against the override that introduced it (the parser's
        // message does not name the key).
        serde_norway::from_value::<TrackerConfig>(value.clone()).map_err(|e| parse_err(o, &e))?;
    }
    let cfg: TrackerConfig = serde_norway::from_value(value).map_err(|e| parse_err(&origin, &e))?;
    Ok(cfg.validate()?)
}

/// Makes the relative file paths of `features.cnn` (`model`, `runtime`) and of the
/// re-detection verifier (`redetection.verifier_backbone`, `verifier_head`) in a config file
/// relative to the file's folder, so presets work from any working directory. Paths given by
/// `--set` overrides stay relative to the working directory.
fn resolve_cnn_paths(value: &mut serde_norway::Value, dir: &Path) {
    if let Some(r) = value
        .get_mut("redetection")
        .and_then(|r| r.as_mapping_mut())
    {
        for key in ["verifier_backbone", "verifier_head"] {
            if let Some(v) = r.get_mut(key) {
                if let Some(p) = v
                    .as_str()
                    .filter(|p| !p.is_empty() && Path::new(p).is_relative())
                {
                    *v = serde_norway::Value::String(dir.join(p).display().to_string());
                }
            }
        }
    }
    let Some(cnn) = value
        .get_mut("features")
        .and_then(|f| f.get_mut("cnn"))
        .and_then(|c| c.as_mapping_mut())
    else {
        return;
    };
    for key in ["model", "runtime"] {
        if let Some(v) = cnn.get_mut(key) {
            if let Some(p) = v
                .as_str()
                .filter(|p| !p.is_empty() && Path::new(p).is_relative())
            {
                *v = serde_norway::Value::String(dir.join(p).display().to_string());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bevt_core::filter::admm::PenaltyKind;

    #[test]
    fn embedded_default_is_the_core_default() {
        let s = load_config(None, &[]).unwrap();
        assert_eq!(s.config, TrackerConfig::default());
    }

    #[test]
    fn overrides_set_nested_keys_and_are_validated() {
        let s = load_config(None, &["admm.penalty=none".into(), "threads=2".into()]).unwrap();
        assert_eq!(s.config.admm.penalty, PenaltyKind::None);
        assert_eq!(s.config.threads, 2);
        assert!(matches!(
            load_config(None, &["admm.iterations=0".into()]),
            Err(ParamsError::Invalid(_))
        ));
        assert!(matches!(
            load_config(None, &["admm.bogus=1".into()]),
            Err(ParamsError::Parse { .. })
        ));
        assert!(matches!(
            load_config(None, &["noequals".into()]),
            Err(ParamsError::Parse { .. })
        ));
        let e = load_config(None, &["features.hog_cell_size=1e20".into()]).unwrap_err();
        assert!(e.to_string().contains("features.hog_cell_size"), "{e}");
    }

    #[test]
    fn cnn_paths_in_a_file_resolve_against_its_folder() {
        let dir = std::env::temp_dir().join(format!("bevt_params_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("c.yaml");
        std::fs::write(
            &file,
            "features:\n  kind: cnn\n  cnn:\n    model: ../m/x.onnx\n    runtime: /abs/lib.so\n",
        )
        .unwrap();
        let s = load_config(Some(&file), &[]).unwrap();
        let cnn = s.config.features.cnn.unwrap();
        assert_eq!(Path::new(&cnn.model), dir.join("../m/x.onnx"));
        assert_eq!(cnn.runtime, "/abs/lib.so");
        let s = load_config(Some(&file), &["features.cnn.model=y.onnx".into()]).unwrap();
        assert_eq!(s.config.features.cnn.unwrap().model, "y.onnx");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn missing_file_is_a_clear_error() {
        let e = load_config(Some(Path::new("/nonexistent/bevt.yaml")), &[]).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/bevt.yaml"));
    }
}
