//! `docs/configuration.md`'s tables, generated from the two parameter tables:
//! [`bevt_core::config::TRACKER_KEYS`] (tracker keys, defaults from
//! `TrackerConfig::default()`) and [`crate::node::node_params::NODE_KEYS`] (node
//! parameters, defaults those of a node started without parameters). A test keeps the
//! document equal to them; `BEVT_BLESS=1 cargo test -p bevt_node --lib configuration_md`
//! rewrites it.

use crate::node::node_params::{launch_from_args, NodeRange, NODE_KEYS};
use crate::node::param_services::{tracker_value, NodeParams, ParamValue};
use bevt_core::config::{KeySpec, CNN_KEYS, TRACKER_KEYS};
use bevt_core::features::cnn_config::{CnnConfig, CnnHogConfig, CnnLayerConfig};
use bevt_core::TrackerConfig;
use serde_norway::Value;
use std::fmt::Write as _;

/// The line before the generated part of `docs/configuration.md`.
pub const BEGIN: &str = "<!-- BEGIN GENERATED from TRACKER_KEYS, CNN_KEYS and NODE_KEYS: edit the tables in the code, then BEVT_BLESS=1 cargo test -p bevt_node --lib configuration_md -->";
/// The line after it.
pub const END: &str = "<!-- END GENERATED -->";

/// Notes printed under a section's heading.
const SECTION_NOTES: &[(&str, &str)] = &[
    (
        "features",
        "`features.cnn` is a section of its own, see [below](#featurescnn).",
    ),
    (
        "scale_filter",
        "Used when `detection.scale_estimator: filter` (the default).",
    ),
    (
        "redetection",
        "`reacquire_threshold` and `reacquire_relative` are combined into the candidate threshold when \
         the target is lost (`tracker/lost.rs`, `enter`), so a change applies from the next loss.",
    ),
];

const HEADER: &str =
    "| key | type | default | range | unit | live | description |\n|---|---|---|---|---|---|---|\n";

fn cell(s: &str) -> String {
    s.replace('|', "\\|").replace('\n', " ")
}

/// A float as the configuration writes it (`0.013`, not `0.013000000268…`).
fn short(f: f64) -> String {
    let g = f as f32;
    if f64::from(g) == f {
        format!("{g:?}")
    } else {
        format!("{f:?}")
    }
}

fn yaml(v: &Value) -> String {
    match v {
        Value::Null => "absent".into(),
        Value::Bool(b) => b.to_string(),
        Value::Number(n) if n.is_u64() || n.is_i64() => n.to_string(),
        Value::Number(n) => n.as_f64().map(short).unwrap_or_default(),
        Value::String(s) if s.is_empty() => "`\"\"`".into(),
        Value::String(s) => format!("`{s}`"),
        Value::Sequence(s) => format!(
            "[{}]",
            s.iter()
                .map(|x| x.as_f64().map(short).unwrap_or_default())
                .collect::<Vec<_>>()
                .join(", ")
        ),
        other => format!("{other:?}"),
    }
}

fn param(v: &ParamValue) -> String {
    match v {
        ParamValue::Bool(b) => b.to_string(),
        ParamValue::Integer(i) => i.to_string(),
        ParamValue::Double(d) => format!("{d:?}"),
        ParamValue::String(s) => format!("`{s}`"),
        ParamValue::DoubleArray(a) => format!("{a:?}"),
        ParamValue::StringArray(a) => format!("`{a:?}`"),
    }
}

fn live(l: bool) -> &'static str {
    if l {
        "**yes**"
    } else {
        "no"
    }
}

/// One table row of a tracker or `features.cnn` key.
fn row(out: &mut String, k: &KeySpec, default: &str) {
    let constraints = k.constraints_in("");
    let _ = writeln!(
        out,
        "| `{}` | {} | {} | {} | {} | {} | {} |",
        k.name,
        k.kind.name(),
        cell(default),
        cell(if constraints.is_empty() {
            "–"
        } else {
            &constraints
        }),
        cell(if k.unit.is_empty() { "–" } else { k.unit }),
        live(k.live),
        cell(k.doc)
    );
}

/// The smallest layer entry the YAML accepts: its keys are the required ones.
const MINIMAL_LAYER: &str = "output: o\nchannels: 1\n";

/// The default of a `features.cnn` key, from `CnnConfig::default()` (a layer's, from the
/// smallest entry the YAML accepts; the HOG section's, from `CnnHogConfig::default()`).
fn cnn_default(name: &str) -> String {
    let Some(key) = name.strip_prefix("features.cnn.") else {
        return String::new();
    };
    let c = CnnConfig::default();
    let lookup = |v: Value, k: &str| -> String {
        match v.get(k) {
            Some(x) => yaml(x),
            None => String::new(),
        }
    };
    if let Some(field) = key.strip_prefix("layers[].") {
        let minimal: Value = serde_norway::from_str(MINIMAL_LAYER).unwrap_or(Value::Null);
        if minimal.get(field).is_some() {
            return "required".into();
        }
        return serde_norway::from_str::<CnnLayerConfig>(MINIMAL_LAYER)
            .ok()
            .and_then(|l| serde_norway::to_value(l).ok())
            .map(|v| lookup(v, field))
            .unwrap_or_default();
    }
    if let Some(field) = key.strip_prefix("hog.") {
        return serde_norway::to_value(CnnHogConfig::default())
            .map(|v| lookup(v, field))
            .unwrap_or_default();
    }
    if key == "layers" {
        return c
            .layers
            .iter()
            .map(|l| format!("`{}` ({} channels)", l.output, l.channels))
            .collect::<Vec<_>>()
            .join(", ");
    }
    serde_norway::to_value(&c)
        .map(|v| lookup(v, key))
        .unwrap_or_default()
}

/// The generated part of `docs/configuration.md` (between [`BEGIN`] and [`END`]).
pub fn configuration_tables() -> String {
    let mut out = String::new();
    let d = TrackerConfig::default();
    out.push_str("## Tracker keys\n");
    let mut section = "";
    for k in TRACKER_KEYS {
        let s = k.name.split_once('.').map_or(k.name, |(s, _)| s);
        if s != section {
            section = s;
            let _ = write!(out, "\n### `{s}`\n\n");
            if let Some((_, note)) = SECTION_NOTES.iter().find(|(n, _)| *n == s) {
                let _ = write!(out, "{note}\n\n");
            }
            out.push_str(HEADER);
        }
        let default = tracker_value(&d, k.name)
            .map(|v| yaml(&v))
            .unwrap_or_default();
        row(&mut out, k, &default);
    }
    out.push_str(
        "\n## `features.cnn`\n\n\
         Written in configuration files only (the node takes the section from its tracker file; \
         these keys are not node parameters). Defaults are `CnnConfig::default()`, the NanoTrack \
         v2 backbone's, except `model`, which must be given. The extractor needs the cargo \
         feature `cnn`; without it `kind: cnn` is an error at construction / `init`. \
         `layers[].x` is key `x` of every entry of `layers`.\n\n",
    );
    out.push_str(HEADER);
    for k in CNN_KEYS {
        row(&mut out, k, &cnn_default(k.name));
    }
    out.push_str(
        "\n## Node parameters\n\n\
         Standard ROS 2 parameters file (`bevt_node: ros__parameters:` or `/**:`), `-p name:=value`; \
         unknown parameters and out-of-range values stop start-up with the parameter and its range. \
         Every tracker key above is also a node parameter, `tracker.<section>.<key>`. All node \
         parameters below except `security_*` are served by the \
         [parameter services](ros.md#parameter-services-ros2-param).\n\n",
    );
    out.push_str(HEADER);
    let declared = launch_from_args(&[], |_| None)
        .map(|l| NodeParams::new(&l.ros, &l.node, &l.tracker.config))
        .ok();
    for k in NODE_KEYS {
        let default = if k.default.is_empty() {
            declared
                .as_ref()
                .and_then(|p| p.declared().get(k.name))
                .map(|d| param(&d.value))
                .unwrap_or_default()
        } else {
            k.default.to_string()
        };
        let constraints = k.constraints_in("");
        let _ = writeln!(
            out,
            "| `{}` | {} | {} | {} | {} | {} | {} |",
            k.name,
            k.ty.name(),
            cell(&default),
            cell(if constraints.is_empty() {
                "–"
            } else {
                &constraints
            }),
            cell(
                if k.unit.is_empty() || matches!(k.range, NodeRange::Chars(..)) {
                    "–"
                } else {
                    k.unit
                }
            ),
            if k.served {
                live(k.live)
            } else {
                "start-up only"
            },
            cell(k.doc)
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `docs/configuration.md` is what the tables say (CI runs this with `cargo test
    /// --workspace`). `BEVT_BLESS=1` rewrites the generated part instead.
    #[test]
    fn configuration_md_is_generated_from_the_tables() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/configuration.md");
        let text = std::fs::read_to_string(path).unwrap();
        let (head, rest) = text.split_once(BEGIN).expect("BEGIN marker");
        let (_, tail) = rest.split_once(END).expect("END marker");
        let want = format!("{head}{BEGIN}\n{}{END}{tail}", configuration_tables());
        if std::env::var("BEVT_BLESS").as_deref() == Ok("1") {
            std::fs::write(path, &want).unwrap();
            return;
        }
        assert!(
            text == want,
            "docs/configuration.md differs from the parameter tables: run \
             BEVT_BLESS=1 cargo test -p bevt_node --lib configuration_md"
        );
    }
}
