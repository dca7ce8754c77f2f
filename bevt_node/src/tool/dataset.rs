//! Datasets and annotation files (the offline tool's input).
//!
//! Three layouts are recognised by [`open_dataset`]:
//! 1. **Manifest**: `DIR/sequences.json` listing each sequence's `img_dir`, `anno`,
//!    `start_frame`, `end_frame`, `nz`, `ext` and optional `attributes` (the layout of
//!    `shared/datasets/uav123_10fps_dev`).
//! 2. **UAV123 download**: `DIR/anno/UAV123_10fps/<name>.txt` (or `UAV123`, `UAV20L`) with
//!    frames in `DIR/data_seq/<same>/<folder>/%06d.jpg`. Sub-sequences such as `group2_2`
//!    take their folder and frame range from the dataset's `configSeqs` table.
//! 3. **OTB-style**: `DIR/<seq>/img/*.jpg|png` with `DIR/<seq>/groundtruth_rect.txt`.
//!
//! Annotation rows are `x,y,w,h` (comma, tab or space separated) in the MATLAB convention
//! (1-based, top-left corner); `NaN` rows mean the target is absent. They are converted
//! to 0-based once on load ([`parse_annotation`]) and back once on save
//! ([`format_annotation_row`]).

use bevt_core::BBox;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Errors of dataset discovery and annotation parsing.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum DatasetError {
    /// A file or directory could not be read.
    #[error("cannot read {path}: {error}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The I/O error, already in the message (not a `source()`, so that an error chain
        /// such as `bevt`'s `error: ...` does not print it twice).
        error: std::io::Error,
    },
    /// `sequences.json` is malformed.
    #[error("malformed manifest {path}: {reason}")]
    Manifest {
        /// The manifest path.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// An annotation line is not four numbers.
    #[error("{path}:{line}: {reason}")]
    Annotation {
        /// The annotation file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// The directory matches none of the known layouts.
    #[error("{0} is not a dataset: no sequences.json, anno/UAV123*/ or <seq>/groundtruth_rect.txt found")]
    UnknownLayout(PathBuf),
    /// A requested sequence is not in the dataset.
    #[error("sequence {0:?} is not in the dataset")]
    UnknownSequence(String),
    /// One sequence's entry cannot be used (the other sequences still can).
    #[error("sequence {name}: {reason}")]
    BadEntry {
        /// The sequence name.
        name: String,
        /// What is wrong.
        reason: String,
    },
}

/// Widest zero-padded frame number (`nz`) accepted: wider is certainly a mistake (and
/// the formatter cannot pad beyond 65535).
pub const MAX_NZ: usize = 32;

/// Largest frame number accepted (`start_frame`, `end_frame`).
pub const MAX_FRAME_NUMBER: usize = 1_000_000_000;

/// Checks a sequence name before it becomes a file name (`<out>/<name>.txt`): one plain
/// path component, no separators, not `.`/`..`, no control characters.
///
/// # Errors
/// The reason, for a name that could write outside the output folder.
pub fn check_sequence_name(name: &str) -> Result<(), String> {
    let bad = name.is_empty()
        || name == "."
        || name == ".."
        || name.starts_with('.')
        || name
            .chars()
            .any(|c| matches!(c, '/' | '\\' | ':') || c.is_control())
        || std::path::Path::new(name).is_absolute();
    if bad {
        Err(format!(
            "sequence name {:?} is not a plain file name (no separators, no leading dot)",
            crate::convert::clip(name)
        ))
    } else {
        Ok(())
    }
}

/// Names must be safe file names and unique (results are `<out>/<name>.txt`).
fn check_names<'a>(names: impl Iterator<Item = &'a str>, path: &Path) -> Result<(), DatasetError> {
    let mut seen = std::collections::BTreeSet::new();
    for n in names {
        let err = |reason: String| DatasetError::Manifest {
            path: path.to_path_buf(),
            reason,
        };
        check_sequence_name(n).map_err(err)?;
        if !seen.insert(n) {
            return Err(err(format!(
                "duplicate sequence name {:?}: results would overwrite each other",
                crate::convert::clip(n)
            )));
        }
    }
    Ok(())
}

/// Where one sequence's frames and annotation live; nothing is read until [`Self::load`].
#[derive(Debug, Clone, PartialEq)]
pub struct SequenceEntry {
    /// Sequence name (result files are `<name>.txt`).
    pub name: String,
    /// Annotation file.
    pub anno: PathBuf,
    /// Frame source.
    pub frames: FrameSource,
    /// UAV123 attributes: `Some(true/false)` when known, `None` when unknown.
    pub attributes: BTreeMap<String, Option<bool>>,
}

/// How to list a sequence's frames.
#[derive(Debug, Clone, PartialEq)]
pub enum FrameSource {
    /// Numbered files `dir/{n:0nz$}.ext` for `n = start..` (one per annotation row, up to `end`).
    Numbered {
        /// Image directory.
        dir: PathBuf,
        /// First frame number.
        start: usize,
        /// Last frame number, when known.
        end: Option<usize>,
        /// Zero-padded width of the number.
        nz: usize,
        /// File extension without the dot.
        ext: String,
    },
    /// Every image file of `dir`, sorted by name.
    Folder(PathBuf),
}

/// A loaded sequence: frame paths and 0-based ground truth (`None` = target absent).
#[derive(Debug, Clone, PartialEq)]
pub struct Sequence {
    /// Name.
    pub name: String,
    /// Frame image paths, one per annotation row.
    pub frames: Vec<PathBuf>,
    /// Ground truth per frame.
    pub truth: Vec<Option<BBox>>,
}

impl SequenceEntry {
    /// Reads the annotation and lists the frames.
    ///
    /// # Errors
    /// [`DatasetError`] when the annotation is unreadable or malformed or the frame folder
    /// cannot be listed.
    pub fn load(&self) -> Result<Sequence, DatasetError> {
        let text = std::fs::read_to_string(&self.anno).map_err(|e| DatasetError::Io {
            path: self.anno.clone(),
            error: e,
        })?;
        let truth = parse_annotation(&text, &self.anno)?;
        let frames = match &self.frames {
            FrameSource::Numbered {
                dir,
                start,
                end,
                nz,
                ext,
            } => {
                let bad = |reason: String| DatasetError::BadEntry {
                    name: self.name.clone(),
                    reason,
                };
                if *nz > MAX_NZ {
                    return Err(bad(format!("nz = {nz} exceeds {MAX_NZ} digits")));
                }
                if *start > MAX_FRAME_NUMBER || end.is_some_and(|e| e > MAX_FRAME_NUMBER) {
                    return Err(bad(format!(
                        "start_frame/end_frame exceed {MAX_FRAME_NUMBER}"
                    )));
                }
                let last = end.unwrap_or(start + truth.len().saturating_sub(1));
                let n = (last + 1).saturating_sub(*start).min(truth.len());
                (0..n)
                    .map(|i| dir.join(format!("{:0width$}.{ext}", start + i, width = nz)))
                    .collect()
            }
            FrameSource::Folder(dir) => {
                let mut files = list_images(dir)?;
                files.truncate(truth.len());
                files
            }
        };
        let mut truth = truth;
        truth.truncate(frames.len());
        Ok(Sequence {
            name: self.name.clone(),
            frames,
            truth,
        })
    }
}

fn list_images(dir: &Path) -> Result<Vec<PathBuf>, DatasetError> {
    let rd = std::fs::read_dir(dir).map_err(|e| DatasetError::Io {
        path: dir.to_path_buf(),
        error: e,
    })?;
    let mut files: Vec<PathBuf> = rd
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension().and_then(|e| e.to_str()).is_some_and(|e| {
                matches!(
                    e.to_ascii_lowercase().as_str(),
                    "jpg" | "jpeg" | "png" | "bmp"
                )
            })
        })
        .collect();
    files.sort();
    Ok(files)
}

/// Lists the image files of a folder, sorted by name (for `bevt track`).
///
/// # Errors
/// [`DatasetError::Io`] when the folder cannot be read.
pub fn image_files(dir: &Path) -> Result<Vec<PathBuf>, DatasetError> {
    list_images(dir)
}

/// Parses `x,y,w,h` rows (1-based, MATLAB convention) into 0-based boxes. Rows with any
/// `NaN` are `None`; blank lines are skipped only at the end of the file.
///
/// # Errors
/// [`DatasetError::Annotation`] naming the first malformed line.
pub fn parse_annotation(text: &str, path: &Path) -> Result<Vec<Option<BBox>>, DatasetError> {
    let lines: Vec<&str> = text.lines().collect();
    let last = lines
        .iter()
        .rposition(|l| !l.trim().is_empty())
        .map_or(0, |i| i + 1);
    let mut out = Vec::with_capacity(last);
    for (i, line) in lines[..last].iter().enumerate() {
        let err = |reason: String| DatasetError::Annotation {
            path: path.to_path_buf(),
            line: i + 1,
            reason,
        };
        let fields: Vec<&str> = line
            .split([',', '\t', ' ', ';'])
            .filter(|s| !s.is_empty())
            .collect();
        if fields.len() != 4 {
            return Err(err(format!(
                "expected 4 values x,y,w,h, found {:?}",
                line.trim()
            )));
        }
        let mut v = [0.0f32; 4];
        for (slot, f) in v.iter_mut().zip(&fields) {
            *slot = f
                .trim()
                .parse::<f32>()
                .map_err(|_| err(format!("{f:?} is not a number")))?;
        }
        if v.iter().any(|x| x.is_nan()) {
            out.push(None);
        } else if v.iter().any(|x| x.is_infinite()) {
            return Err(err("infinite value".into()));
        } else {
            out.push(Some(BBox::new(v[0] - 1.0, v[1] - 1.0, v[2], v[3])));
        }
    }
    Ok(out)
}

/// One result row in the annotation convention (1-based), `NaN,NaN,NaN,NaN` for `None`.
pub fn format_annotation_row(b: Option<&BBox>) -> String {
    match b {
        Some(b) if b.is_finite() => {
            format!("{:.2},{:.2},{:.2},{:.2}", b.x + 1.0, b.y + 1.0, b.w, b.h)
        }
        _ => "NaN,NaN,NaN,NaN".to_string(),
    }
}

#[derive(Deserialize)]
struct Manifest {
    sequences: Vec<ManifestSeq>,
    #[serde(default)]
    attribute_order: Vec<String>,
}

#[derive(Deserialize)]
struct ManifestSeq {
    name: String,
    img_dir: String,
    anno: String,
    #[serde(default = "one")]
    start_frame: usize,
    end_frame: Option<usize>,
    #[serde(default = "six")]
    nz: usize,
    #[serde(default = "jpg")]
    ext: String,
    #[serde(default)]
    attributes: BTreeMap<String, Option<bool>>,
}

fn one() -> usize {
    1
}
fn six() -> usize {
    6
}
fn jpg() -> String {
    "jpg".into()
}

/// A dataset: its sequences and the attribute names in display order.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    /// Root directory.
    pub root: PathBuf,
    /// Which layout was recognised.
    pub layout: &'static str,
    /// Sequences in dataset order.
    pub sequences: Vec<SequenceEntry>,
    /// Attribute names in display order (empty when the layout has none).
    pub attribute_order: Vec<String>,
}

impl Dataset {
    /// Keeps only the named sequences, in the given order.
    ///
    /// # Errors
    /// [`DatasetError::UnknownSequence`] for a name not in the dataset.
    pub fn select(&mut self, names: &[String]) -> Result<(), DatasetError> {
        check_names(names.iter().map(String::as_str), Path::new("--sequences"))?;
        let mut out = Vec::with_capacity(names.len());
        for n in names {
            let e = self
                .sequences
                .iter()
                .find(|s| &s.name == n)
                .ok_or_else(|| DatasetError::UnknownSequence(n.clone()))?;
            out.push(e.clone());
        }
        self.sequences = out;
        Ok(())
    }
}

/// Recognises the layout of `root` and lists its sequences.
///
/// # Errors
/// [`DatasetError`] when the directory is unreadable, the manifest malformed, or no
/// layout matches.
pub fn open_dataset(root: &Path) -> Result<Dataset, DatasetError> {
    let manifest = root.join("sequences.json");
    if manifest.is_file() {
        return open_manifest(root, &manifest);
    }
    for set in ["UAV123_10fps", "UAV123", "UAV20L"] {
        let anno = root.join("anno").join(set);
        if anno.is_dir() {
            return open_uav123(root, set, &anno);
        }
    }
    open_otb(root)
}

fn open_manifest(root: &Path, path: &Path) -> Result<Dataset, DatasetError> {
    let text = std::fs::read_to_string(path).map_err(|e| DatasetError::Io {
        path: path.to_path_buf(),
        error: e,
    })?;
    let m: Manifest = serde_json::from_str(&text).map_err(|e| DatasetError::Manifest {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    check_names(m.sequences.iter().map(|s| s.name.as_str()), path)?;
    // The manifest names files inside the dataset: an absolute path or a `..` would make
    // `bevt eval` read (and report on) any file of the machine.
    for seq in &m.sequences {
        for (field, rel) in [("anno", &seq.anno), ("img_dir", &seq.img_dir)] {
            let p = Path::new(rel);
            let escapes = p.is_absolute()
                || p.components().any(|c| {
                    !matches!(
                        c,
                        std::path::Component::Normal(_) | std::path::Component::CurDir
                    )
                });
            if escapes {
                return Err(DatasetError::Manifest {
                    path: path.to_path_buf(),
                    reason: format!(
                        "sequence {:?}: {field} {rel:?} is not a path inside the dataset (absolute or with '..')",
                        seq.name
                    ),
                });
            }
        }
    }
    let sequences = m
        .sequences
        .into_iter()
        .map(|s| SequenceEntry {
            anno: root.join(&s.anno),
            frames: FrameSource::Numbered {
                dir: root.join(&s.img_dir),
                start: s.start_frame,
                end: s.end_frame,
                nz: s.nz,
                ext: s.ext,
            },
            attributes: s.attributes,
            name: s.name,
        })
        .collect();
    Ok(Dataset {
        root: root.to_path_buf(),
        layout: "manifest",
        sequences,
        attribute_order: m.attribute_order,
    })
}

/// UAV123_10fps sub-sequences of one recording: (name, folder, first frame, last frame),
/// from the dataset's `configSeqs.m`. Sequences not listed use their own folder from frame 1.
const UAV123_10FPS_SPLITS: &[(&str, &str, usize, usize)] = &[
    ("bird1_1", "bird1", 1, 85),
    ("bird1_2", "bird1", 259, 493),
    ("bird1_3", "bird1", 525, 813),
    ("car1_1", "car1", 1, 251),
    ("car1_2", "car1", 251, 543),
    ("car1_3", "car1", 543, 877),
    ("car6_1", "car6", 1, 163),
    ("car6_2", "car6", 163, 603),
    ("car6_3", "car6", 603, 985),
    ("car6_4", "car6", 985, 1309),
    ("car6_5", "car6", 1309, 1621),
    ("car8_1", "car8", 1, 453),
    ("car8_2", "car8", 453, 859),
    ("car16_1", "car16", 1, 139),
    ("car16_2", "car16", 139, 665),
    ("group1_1", "group1", 1, 445),
    ("group1_2", "group1", 445, 839),
    ("group1_3", "group1", 839, 1309),
    ("group1_4", "group1", 1309, 1625),
    ("group2_1", "group2", 1, 303),
    ("group2_2", "group2", 303, 591),
    ("group2_3", "group2", 591, 895),
    ("group3_1", "group3", 1, 523),
    ("group3_2", "group3", 523, 943),
    ("group3_3", "group3", 943, 1457),
    ("group3_4", "group3", 1457, 1843),
    ("person2_1", "person2", 1, 397),
    ("person2_2", "person2", 397, 875),
    ("person4_1", "person4", 1, 501),
    ("person4_2", "person4", 501, 915),
    ("person5_1", "person5", 1, 293),
    ("person5_2", "person5", 293, 701),
    ("person7_1", "person7", 1, 417),
    ("person7_2", "person7", 417, 689),
    ("person8_1", "person8", 1, 359),
    ("person8_2", "person8", 359, 509),
    ("person12_1", "person12", 1, 201),
    ("person12_2", "person12", 201, 541),
    ("person14_1", "person14", 1, 283),
    ("person14_2", "person14", 283, 605),
    ("person14_3", "person14", 605, 975),
    ("person17_1", "person17", 1, 501),
    ("person17_2", "person17", 501, 783),
    ("person19_1", "person19", 1, 415),
    ("person19_2", "person19", 415, 931),
    ("person19_3", "person19", 931, 1453),
    ("truck4_1", "truck4", 1, 193),
    ("truck4_2", "truck4", 193, 421),
    ("uav1_1", "uav1", 1, 519),
    ("uav1_2", "uav1", 519, 793),
    ("uav1_3", "uav1", 825, 1157),
];

fn open_uav123(root: &Path, set: &str, anno_dir: &Path) -> Result<Dataset, DatasetError> {
    let mut names: Vec<String> = std::fs::read_dir(anno_dir)
        .map_err(|e| DatasetError::Io {
            path: anno_dir.to_path_buf(),
            error: e,
        })?
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let p = e.path();
            (p.extension().and_then(|x| x.to_str()) == Some("txt"))
                .then(|| p.file_stem().and_then(|s| s.to_str()).map(str::to_string))
                .flatten()
        })
        .collect();
    names.sort();
    let data = root.join("data_seq").join(set);
    let sequences = names
        .into_iter()
        .map(|name| {
            let split = if set == "UAV123_10fps" {
                UAV123_10FPS_SPLITS.iter().find(|s| s.0 == name)
            } else {
                None
            };
            let (folder, start, end) = match split {
                Some(&(_, f, s, e)) => (f.to_string(), s, Some(e)),
                None => (name.clone(), 1, None),
            };
            SequenceEntry {
                anno: anno_dir.join(format!("{name}.txt")),
                frames: FrameSource::Numbered {
                    dir: data.join(folder),
                    start,
                    end,
                    nz: 6,
                    ext: "jpg".into(),
                },
                attributes: BTreeMap::new(),
                name,
            }
        })
        .collect();
    Ok(Dataset {
        root: root.to_path_buf(),
        layout: "uav123",
        sequences,
        attribute_order: Vec::new(),
    })
}

fn open_otb(root: &Path) -> Result<Dataset, DatasetError> {
    let rd = std::fs::read_dir(root).map_err(|e| DatasetError::Io {
        path: root.to_path_buf(),
        error: e,
    })?;
    let mut sequences: Vec<SequenceEntry> = rd
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| p.join("groundtruth_rect.txt").is_file() && p.join("img").is_dir())
        .filter_map(|p| {
            let name = p.file_name()?.to_str()?.to_string();
            Some(SequenceEntry {
                anno: p.join("groundtruth_rect.txt"),
                frames: FrameSource::Folder(p.join("img")),
                attributes: BTreeMap::new(),
                name,
            })
        })
        .collect();
    if sequences.is_empty() {
        return Err(DatasetError::UnknownLayout(root.to_path_buf()));
    }
    sequences.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(Dataset {
        root: root.to_path_buf(),
        layout: "otb",
        sequences,
        attribute_order: Vec::new(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unreadable_dataset_is_explained_once() {
        let e = open_dataset(Path::new("/nonexistent/bevt/dataset")).unwrap_err();
        let chain = format!("{:#}", anyhow::Error::from(e));
        assert_eq!(
            chain.matches("No such file or directory").count(),
            1,
            "{chain}"
        );
        assert!(
            chain.starts_with("cannot read /nonexistent/bevt/dataset"),
            "{chain}"
        );
    }

    #[test]
    fn annotation_rows_convert_to_zero_based_and_nan_is_absent() {
        let t = "393,328,155,319\nNaN,NaN,NaN,NaN\n1\t2\t3\t4\n\n";
        let a = parse_annotation(t, Path::new("x.txt")).unwrap();
        assert_eq!(a.len(), 3);
        assert_eq!(a[0], Some(BBox::new(392.0, 327.0, 155.0, 319.0)));
        assert_eq!(a[1], None);
        assert_eq!(a[2], Some(BBox::new(0.0, 1.0, 3.0, 4.0)));
    }

    #[test]
    fn malformed_lines_name_the_line() {
        let e = parse_annotation("1,2,3,4\n1,2,3\n", Path::new("a.txt")).unwrap_err();
        assert!(e.to_string().contains("a.txt:2"), "{e}");
        let e = parse_annotation("1,2,x,4\n", Path::new("a.txt")).unwrap_err();
        assert!(e.to_string().contains("\"x\""), "{e}");
    }

    #[test]
    fn rows_round_trip_through_the_file_convention() {
        let b = BBox::new(392.0, 327.5, 155.0, 319.25);
        let row = format_annotation_row(Some(&b));
        let back = parse_annotation(&row, Path::new("r")).unwrap();
        assert_eq!(back[0], Some(b));
        assert_eq!(format_annotation_row(None), "NaN,NaN,NaN,NaN");
    }

    #[test]
    fn uav123_layout_uses_the_split_table() -> Result<(), Box<dyn std::error::Error>> {
        let dir = std::env::temp_dir().join(format!("bevt_uav_{}", std::process::id()));
        let anno = dir.join("anno/UAV123_10fps");
        std::fs::create_dir_all(&anno)?;
        std::fs::write(anno.join("group2_2.txt"), "1,1,10,10\n2,2,10,10\n")?;
        std::fs::write(anno.join("bike2.txt"), "1,1,10,10\n")?;
        let ds = open_dataset(&dir)?;
        assert_eq!(ds.layout, "uav123");
        let g = ds
            .sequences
            .iter()
            .find(|s| s.name == "group2_2")
            .unwrap()
            .load()?;
        assert_eq!(g.frames.len(), 2);
        assert!(g.frames[0].ends_with("data_seq/UAV123_10fps/group2/000303.jpg"));
        let b = ds
            .sequences
            .iter()
            .find(|s| s.name == "bike2")
            .unwrap()
            .load()?;
        assert!(b.frames[0].ends_with("data_seq/UAV123_10fps/bike2/000001.jpg"));
        std::fs::remove_dir_all(&dir)?;
        Ok(())
    }

    #[test]
    fn otb_layout_lists_sorted_images() -> Result<(), Box<dyn std::error::Error>> {
        let dir = std::env::temp_dir().join(format!("bevt_otb_{}", std::process::id()));
        let img = dir.join("Car/img");
        std::fs::create_dir_all(&img)?;
        for n in ["0002.jpg", "0001.jpg", "0003.jpg", "notes.txt"] {
            std::fs::write(img.join(n), b"")?;
        }
        std::fs::write(dir.join("Car/groundtruth_rect.txt"), "1,1,5,5\n1,1,5,5\n")?;
        let ds = open_dataset(&dir)?;
        let s = ds.sequences[0].load()?;
        assert_eq!(s.frames.len(), 2);
        assert!(s.frames[0].ends_with("0001.jpg"));
        std::fs::remove_dir_all(&dir)?;
        Ok(())
    }

    fn manifest(dir: &Path, seqs: &[(&str, usize)]) -> Result<(), Box<dyn std::error::Error>> {
        std::fs::create_dir_all(dir)?;
        let list: Vec<_> = seqs
            .iter()
            .map(|(n, nz)| {
                serde_json::json!({"name": n, "img_dir": "img", "anno": "a.txt", "nz": nz})
            })
            .collect();
        std::fs::write(
            dir.join("sequences.json"),
            serde_json::json!({ "sequences": list }).to_string(),
        )?;
        std::fs::write(dir.join("a.txt"), "1,1,10,10\n2,2,10,10\n")?;
        Ok(())
    }

    #[test]
    fn a_manifest_cannot_point_outside_the_dataset() -> Result<(), Box<dyn std::error::Error>> {
        let dir = std::env::temp_dir().join(format!("bevt_escape_{}", std::process::id()));
        for (img_dir, anno) in [
            ("img", "../../../etc/passwd"),
            ("img", "/etc/passwd"),
            ("../outside", "a.txt"),
            ("img/../../x", "a.txt"),
        ] {
            std::fs::create_dir_all(&dir)?;
            let seq = serde_json::json!({"name": "s", "img_dir": img_dir, "anno": anno});
            std::fs::write(
                dir.join("sequences.json"),
                serde_json::json!({ "sequences": [seq] }).to_string(),
            )?;
            match open_dataset(&dir) {
                Err(DatasetError::Manifest { reason, .. }) => {
                    assert!(reason.contains("not a path inside the dataset"), "{reason}");
                }
                other => panic!("{img_dir} {anno}: {other:?}"),
            }
        }
        // Inside is fine, "./" included.
        manifest(&dir, &[("ok", 4)])?;
        open_dataset(&dir)?;
        std::fs::remove_dir_all(&dir)?;
        Ok(())
    }

    #[test]
    fn a_huge_nz_fails_that_sequence_only() -> Result<(), Box<dyn std::error::Error>> {
        let dir = std::env::temp_dir().join(format!("bevt_nz_{}", std::process::id()));
        manifest(&dir, &[("wide", 65536), ("widest", usize::MAX), ("ok", 6)])?;
        let ds = open_dataset(&dir)?;
        for s in &ds.sequences[..2] {
            match s.load() {
                Err(DatasetError::BadEntry { name, reason }) => {
                    assert_eq!(name, s.name);
                    assert!(reason.contains("nz"), "{reason}");
                }
                other => panic!("{other:?}"),
            }
        }
        let ok = ds.sequences[2].load()?;
        assert!(ok.frames[0].ends_with("img/000001.jpg"));
        std::fs::remove_dir_all(&dir)?;
        Ok(())
    }

    #[test]
    fn unsafe_and_duplicate_sequence_names_are_refused() -> Result<(), Box<dyn std::error::Error>> {
        let dir = std::env::temp_dir().join(format!("bevt_names_{}", std::process::id()));
        for bad in [
            "../../x", "/tmp/abs", "a/b", "a\\b", "", "..", ".", ".hidden", "c:x",
        ] {
            manifest(&dir, &[("fine", 6), (bad, 6)])?;
            match open_dataset(&dir) {
                Err(DatasetError::Manifest { reason, .. }) => {
                    assert!(
                        reason.contains("not a plain file name"),
                        "{bad:?}: {reason}"
                    )
                }
                other => panic!("{bad:?}: {other:?}"),
            }
        }
        manifest(&dir, &[("twice", 6), ("other", 6), ("twice", 6)])?;
        let e = open_dataset(&dir).unwrap_err().to_string();
        assert!(e.contains("duplicate sequence name \"twice\""), "{e}");
        manifest(&dir, &[("a", 6), ("b", 6)])?;
        let mut ds = open_dataset(&dir)?;
        assert!(ds.clone().select(&["a".into(), "a".into()]).is_err());
        ds.select(&["b".into()])?;
        assert_eq!(ds.sequences.len(), 1);
        assert!(check_sequence_name("group2_2").is_ok());
        std::fs::remove_dir_all(&dir)?;
        Ok(())
    }

    #[test]
    fn unknown_layout_is_an_error() {
        let dir = std::env::temp_dir().join(format!("bevt_empty_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        assert!(matches!(
            open_dataset(&dir),
            Err(DatasetError::UnknownLayout(_))
        ));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
