//! Output files that never destroy a user's file.
//!
//! - [`refuse_overwriting_inputs`]: an output that is the same file as an input (by device
//!   and inode, so hard links and symbolic links count; for a bag directory, every file in
//!   it) or as another output is refused before anything is opened for writing.
//! - [`Staged`]: an output is written to a new file beside its target
//!   (`<stem>.partial-<pid>.<ext>`, created with `create_new`, so nothing existing is
//!   touched) and renamed over the target only when the run succeeds; a failed run leaves
//!   the earlier output untouched and either removes the partial file or, when it holds
//!   computed results, keeps it under its own name.

use std::fs::{File, OpenOptions};
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

/// The identity of an existing file: (device, inode).
type FileId = (u64, u64);

/// The identity of an existing file.
fn identity(path: &Path) -> Option<FileId> {
    std::fs::metadata(path).ok().map(|m| (m.dev(), m.ino()))
}

/// Every file an input stands for: the file itself, SQLite's companions of a `.db3`
/// (`-wal`, `-shm`, `-journal`), and for a directory every file in it (a rosbag2
/// directory is flat: metadata.yaml and its storage files).
fn input_files(input: &Path) -> Vec<PathBuf> {
    let mut out = vec![input.to_path_buf()];
    if input.is_dir() {
        if let Ok(entries) = std::fs::read_dir(input) {
            out.extend(entries.flatten().map(|e| e.path()));
        }
    }
    let mut companions = Vec::new();
    for f in &out {
        for suffix in ["-wal", "-shm", "-journal"] {
            let mut name = f.as_os_str().to_os_string();
            name.push(suffix);
            companions.push(PathBuf::from(name));
        }
    }
    out.extend(companions);
    out
}

/// Where `path` points once its directory is resolved (the file itself need not exist).
fn resolved(path: &Path) -> PathBuf {
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    match (parent.canonicalize(), path.file_name()) {
        (Ok(dir), Some(name)) => dir.join(name),
        _ => path.to_path_buf(),
    }
}

/// Refuses outputs that would overwrite an input or each other.
///
/// `outputs` are `(option name, path)`; `inputs` are files or directories read by the run.
///
/// # Errors
/// A message naming the option, the path and the input it is.
pub fn refuse_overwriting_inputs(
    outputs: &[(&str, &Path)],
    inputs: &[&Path],
) -> Result<(), String> {
    let mut input_ids = Vec::new();
    for input in inputs {
        for f in input_files(input) {
            if let Some(id) = identity(&f) {
                input_ids.push((id, f));
            }
        }
    }
    let mut seen: Vec<(&str, PathBuf, Option<FileId>)> = Vec::new();
    for (name, path) in outputs {
        if path.is_dir() {
            return Err(format!("{name} {}: is a directory", path.display()));
        }
        let id = identity(path);
        if let Some(id) = id {
            if let Some((_, f)) = input_ids.iter().find(|(i, _)| *i == id) {
                return Err(format!(
                    "{name} {} is the input {}: refusing to overwrite a recording",
                    path.display(),
                    f.display()
                ));
            }
        }
        let at = resolved(path);
        for (other, other_at, other_id) in &seen {
            if *other_at == at || (id.is_some() && id == *other_id) {
                return Err(format!(
                    "{name} {} is the same file as {other}: give each output its own file",
                    path.display()
                ));
            }
        }
        seen.push((name, at, id));
    }
    Ok(())
}

/// An output being written beside its target, renamed over it on [`Staged::commit`].
#[derive(Debug)]
pub struct Staged {
    target: PathBuf,
    partial: PathBuf,
}

impl Staged {
    /// Creates the partial file beside `target` (a new file: nothing existing is opened).
    ///
    /// # Errors
    /// Why it cannot be created (no such directory, permissions, ...).
    pub fn create(target: &Path) -> Result<(Self, File), String> {
        static SERIAL: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let stem = target
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "output".into());
        let ext = target
            .extension()
            .map(|e| format!(".{}", e.to_string_lossy()))
            .unwrap_or_default();
        let dir = target.parent().unwrap_or(Path::new(""));
        let serial = SERIAL.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let name = match serial {
            0 => format!("{stem}.partial-{}{ext}", std::process::id()),
            n => format!("{stem}.partial-{}-{n}{ext}", std::process::id()),
        };
        let partial = dir.join(name);
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&partial)
            .map_err(|e| format!("cannot create {}: {e}", partial.display()))?;
        Ok((
            Self {
                target: target.to_path_buf(),
                partial,
            },
            file,
        ))
    }

    /// The file being written.
    pub fn partial(&self) -> &Path {
        &self.partial
    }

    /// Renames the finished file over the target.
    ///
    /// # Errors
    /// Why the rename failed (the partial file is then kept, and named in the message).
    pub fn commit(self) -> Result<PathBuf, String> {
        std::fs::rename(&self.partial, &self.target).map_err(|e| {
            format!(
                "cannot rename {} to {}: {e} (the output is kept as {})",
                self.partial.display(),
                self.target.display(),
                self.partial.display()
            )
        })?;
        Ok(self.target)
    }

    /// A failed run: removes the partial file, or keeps it (and returns its path) when it
    /// holds results worth keeping.
    pub fn abandon(self, keep: bool) -> Option<PathBuf> {
        if keep {
            Some(self.partial)
        } else {
            let _ = std::fs::remove_file(&self.partial);
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("bevt_outputs_{}_{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn an_output_that_is_an_input_is_refused_by_identity() {
        let d = dir("identity");
        let bag = d.join("bag");
        std::fs::create_dir_all(&bag).unwrap();
        let db3 = bag.join("bag_0.db3");
        std::fs::write(&db3, b"recording").unwrap();
        std::fs::write(bag.join("metadata.yaml"), b"meta").unwrap();
        // The file inside the bag directory, by another spelling and by a hard link.
        let other_spelling = bag.join("..").join("bag").join("bag_0.db3");
        let link = d.join("link.db3");
        std::fs::hard_link(&db3, &link).unwrap();
        for (opt, out) in [
            ("--csv", &other_spelling),
            ("--out", &link),
            ("--out", &bag.join("metadata.yaml")),
        ] {
            let e = refuse_overwriting_inputs(&[(opt, out)], &[&bag]).unwrap_err();
            assert!(e.contains("refusing to overwrite"), "{e}");
            assert!(e.contains(opt), "{e}");
        }
        // The WAL of a bare .db3 is an input too.
        let wal = d.join("link.db3-wal");
        std::fs::write(&wal, b"wal").unwrap();
        assert!(refuse_overwriting_inputs(&[("--out", &wal)], &[&link]).is_err());
        // A new file beside the bag is fine.
        refuse_overwriting_inputs(&[("--out", &d.join("out.mcap"))], &[&bag]).unwrap();
        assert_eq!(std::fs::read(&db3).unwrap(), b"recording");
    }

    #[test]
    fn two_outputs_on_one_file_are_refused() {
        let d = dir("two");
        let a = d.join("out.mcap");
        let b = d.join(".").join("out.mcap");
        let e = refuse_overwriting_inputs(&[("--out", &a), ("--csv", &b)], &[]).unwrap_err();
        assert!(e.contains("same file as --out"), "{e}");
        let e = refuse_overwriting_inputs(&[("--out", &d)], &[]).unwrap_err();
        assert!(e.contains("is a directory"), "{e}");
    }

    #[test]
    fn a_staged_output_replaces_the_target_only_when_committed() {
        let d = dir("staged");
        let target = d.join("out.csv");
        std::fs::write(&target, b"earlier good output").unwrap();
        let (s, mut f) = Staged::create(&target).unwrap();
        std::io::Write::write_all(&mut f, b"new").unwrap();
        let partial = s.partial().to_path_buf();
        assert!(partial.exists());
        assert_eq!(s.abandon(false), None);
        assert!(!partial.exists());
        assert_eq!(std::fs::read(&target).unwrap(), b"earlier good output");
        let (s, mut f) = Staged::create(&target).unwrap();
        std::io::Write::write_all(&mut f, b"new").unwrap();
        drop(f);
        s.commit().unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
    }
}
