//! YAML read within bounds: every YAML the programs read (a `--config` file, a node
//! parameters file, a bag's `metadata.yaml`, `--set` / `-p` values) is checked for size and
//! nesting depth by a linear scan before the parser sees it. A deeply nested file of a few
//! hundred kilobytes kept the parser busy for over a minute with no message; now it is
//! refused at once, naming the file and the limit.

use serde::de::DeserializeOwned;
use std::path::Path;

/// Largest YAML document read, bytes (our configuration files are a few kilobytes).
pub const MAX_YAML_BYTES: u64 = 1 << 20;
/// Deepest nesting of mappings and sequences accepted (ours nest 4 levels).
pub const MAX_YAML_DEPTH: usize = 32;

/// Reads a YAML file of at most [`MAX_YAML_BYTES`] (checked before reading it).
///
/// # Errors
/// The file cannot be read, or is too large.
pub fn read_file(path: &Path) -> Result<String, String> {
    let len = std::fs::metadata(path)
        .map_err(|e| format!("{}: {e}", path.display()))?
        .len();
    if len > MAX_YAML_BYTES {
        return Err(format!(
            "{}: {len} bytes, more than the {MAX_YAML_BYTES} a YAML file may have",
            path.display()
        ));
    }
    std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))
}

/// The deepest nesting of `text`: flow collections (`[`, `{` outside quotes and comments)
/// on top of block structure (indentation levels, and `- ` sequence entries that open a
/// level on the same line). An upper bound of what the parser will nest, found in one pass.
pub fn nesting_depth(text: &str) -> usize {
    let mut deepest = 0usize;
    let mut indents: Vec<usize> = Vec::new();
    let mut flow = 0usize;
    for line in text.lines() {
        let content = line.trim_start_matches(' ');
        if flow == 0 {
            if content.is_empty() || content.starts_with('#') {
                continue;
            }
            let mut indent = line.len() - content.len();
            while indents.last().is_some_and(|&i| i > indent) {
                indents.pop();
            }
            if indents.last() != Some(&indent) {
                indents.push(indent);
            }
            // "- - - x": each dash opens a sequence level on this line.
            let mut rest = content;
            while let Some(r) = rest
                .strip_prefix("- ")
                .or_else(|| rest.strip_prefix('-').filter(|r| r.is_empty()))
            {
                indent += 2;
                indents.push(indent);
                rest = r.trim_start_matches(' ');
            }
            deepest = deepest.max(indents.len());
        }
        let (mut single, mut double) = (false, false);
        let mut prev = ' ';
        for c in content.chars() {
            match c {
                '\'' if !double => single = !single,
                '"' if !single && prev != '\\' => double = !double,
                '#' if !single && !double && (prev == ' ' || prev == '\t') => break,
                '[' | '{' if !single && !double => {
                    flow += 1;
                    deepest = deepest.max(indents.len() + flow);
                }
                ']' | '}' if !single && !double => flow = flow.saturating_sub(1),
                _ => {}
            }
            prev = c;
        }
    }
    deepest
}

/// Parses `text` (from `origin`, for messages) after the size and depth checks.
///
/// # Errors
/// Too large, too deep, or not valid for `T` (the parser's message).
pub fn parse<T: DeserializeOwned>(text: &str, origin: &str) -> Result<T, String> {
    if text.len() as u64 > MAX_YAML_BYTES {
        return Err(format!(
            "{origin}: {} bytes of YAML, more than {MAX_YAML_BYTES}",
            text.len()
        ));
    }
    let depth = nesting_depth(text);
    if depth > MAX_YAML_DEPTH {
        return Err(format!(
            "{origin}: YAML nested {depth} levels deep, more than {MAX_YAML_DEPTH}"
        ));
    }
    serde_norway::from_str(text).map_err(|e| format!("{origin}: {e}"))
}

/// Sets the dotted `key` (`admm.iterations`) of a YAML tree to `v`, creating the sections on
/// the way. The one implementation behind `bevt --set`, the node's `-p tracker.*` and its
/// parameter services.
///
/// # Errors
/// A part of the path is a value, not a section (the error names the key).
pub fn set_dotted(
    tree: &mut serde_norway::Value,
    key: &str,
    v: serde_norway::Value,
) -> Result<(), String> {
    let mut node = tree;
    let mut parts = key.split('.').peekable();
    while let Some(part) = parts.next() {
        let map = node
            .as_mapping_mut()
            .ok_or_else(|| format!("{key}: not a section"))?;
        let k = serde_norway::Value::String(part.to_string());
        if parts.peek().is_none() {
            map.insert(k, v);
            return Ok(());
        }
        node = map
            .entry(k)
            .or_insert_with(|| serde_norway::Value::Mapping(Default::default()));
    }
    Ok(())
}

/// The value of the dotted `key` in a YAML tree.
pub fn get_dotted(mut tree: serde_norway::Value, key: &str) -> Option<serde_norway::Value> {
    for part in key.split('.') {
        tree = tree.as_mapping_mut()?.remove(part)?;
    }
    Some(tree)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_norway::Value;
    use std::time::{Duration, Instant};

    #[test]
    fn dotted_keys_are_set_and_read_through_sections() {
        let mut tree: Value = parse("admm:\n  iterations: 2\nthreads: 1\n", "t").unwrap();
        set_dotted(&mut tree, "admm.iterations", Value::from(5)).unwrap();
        set_dotted(&mut tree, "scale_filter.step", Value::from(1.5)).unwrap();
        assert_eq!(
            get_dotted(tree.clone(), "admm.iterations"),
            Some(Value::from(5))
        );
        assert_eq!(
            get_dotted(tree.clone(), "scale_filter.step"),
            Some(Value::from(1.5))
        );
        assert_eq!(get_dotted(tree.clone(), "threads"), Some(Value::from(1)));
        assert_eq!(get_dotted(tree.clone(), "admm.missing"), None);
        assert_eq!(get_dotted(tree.clone(), "threads.x"), None);
        let e = set_dotted(&mut tree, "threads.x", Value::from(1)).unwrap_err();
        assert_eq!(e, "threads.x: not a section");
    }

    #[test]
    fn real_files_pass_and_their_depth_is_small() {
        for text in [
            include_str!("../../config/bevt.yaml"),
            include_str!("../../config/node.yaml"),
            include_str!("../../config/cnn_fusion.yaml"),
            "a: [1, [2, 3], {b: 'x]'}]  # [[[[ in a comment\n",
        ] {
            assert!(nesting_depth(text) <= 6, "{}", nesting_depth(text));
            parse::<Value>(text, "t").unwrap();
        }
    }

    #[test]
    fn deep_documents_are_refused_at_once_naming_the_limit() {
        let flow = format!("{}{}", "[".repeat(200_000), "]".repeat(200_000));
        let mut block = String::new();
        for i in 0..300 {
            block.push_str(&" ".repeat(i));
            block.push_str("k:\n");
        }
        let dashes = format!("{}x\n", "- ".repeat(100_000));
        for (name, text) in [("flow", flow), ("block", block), ("dashes", dashes)] {
            let start = Instant::now();
            let e = parse::<Value>(&text, name).unwrap_err();
            assert!(start.elapsed() < Duration::from_secs(1), "{name}: slow");
            assert!(e.contains("more than 32") && e.contains(name), "{e}");
        }
        let big = format!("a: '{}'\n", "x".repeat(2 << 20));
        assert!(parse::<Value>(&big, "big").unwrap_err().contains("bytes"));
    }

    #[test]
    fn a_file_larger_than_the_limit_is_not_read() {
        let p = std::env::temp_dir().join(format!("bevt_yaml_{}.yaml", std::process::id()));
        std::fs::write(&p, vec![b'#'; (MAX_YAML_BYTES + 1) as usize]).unwrap();
        let e = read_file(&p).unwrap_err();
        assert!(e.contains("more than the 1048576"), "{e}");
        let _ = std::fs::remove_file(&p);
    }
}
