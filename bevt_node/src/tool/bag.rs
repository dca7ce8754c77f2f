//! rosbag2 recordings read without ROS: a bag directory (`metadata.yaml` with `.mcap` or
//! `.db3` files) or a bare `.mcap` file. The messages of one topic are handed out in
//! recorded order with their serialised bytes borrowed from the reader's buffer (MCAP:
//! the decompressed chunk; SQLite: the row's blob), so nothing is copied per message.
//!
//! Sizes read from a file are bounded before anything is allocated from them: an MCAP
//! record or chunk larger than [`BagLimits::max_record_bytes`] is an error.

use mcap::records::Record;
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use serde_norway::Value;
use std::collections::{BTreeMap, HashMap};
use std::io::Read;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Why a bag cannot be read.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum BagError {
    /// The path is neither a bag directory nor an `.mcap` / `.db3` file.
    #[error("{path}: {reason}")]
    Open {
        /// The path given.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The topic is not in the bag.
    #[error("topic {topic:?} is not in the bag; its topics: {available}")]
    NoSuchTopic {
        /// The topic asked for.
        topic: String,
        /// `name (type)` of each topic that exists, or `none`.
        available: String,
    },
    /// A file of the bag is corrupt or truncated.
    #[error("{path}: {reason}")]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// What the reader found.
        reason: String,
    },
}

/// Bounds on what a bag may make the reader allocate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BagLimits {
    /// Largest MCAP record or chunk (compressed or not), bytes.
    pub max_record_bytes: usize,
}

impl Default for BagLimits {
    /// 1 GiB: a chunk holding one 16-megapixel rgba8 image (64 MiB) with room to spare.
    fn default() -> Self {
        Self {
            max_record_bytes: 1 << 30,
        }
    }
}

/// A topic of the bag.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicInfo {
    /// Topic name.
    pub name: String,
    /// ROS type, e.g. `sensor_msgs/msg/Image`.
    pub msg_type: String,
    /// Messages recorded, when the bag says.
    pub count: Option<u64>,
}

/// One message of the topic being read.
#[derive(Debug, Clone, Copy)]
pub struct BagMessage<'a> {
    /// Receive time recorded by rosbag2, ns.
    pub log_time: u64,
    /// The topic's ROS type.
    pub msg_type: &'a str,
    /// Serialised message: CDR with its 4-byte encapsulation header.
    pub data: &'a [u8],
}

/// Storage format of a bag's files.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Storage {
    /// MCAP (rosbag2's default since ROS 2 Iron).
    Mcap,
    /// SQLite 3 (`.db3`).
    Sqlite,
}

/// An opened bag: its files in order and, when `metadata.yaml` lists them, its topics.
#[derive(Debug, Clone)]
pub struct Bag {
    /// The files, in recording order.
    pub files: Vec<PathBuf>,
    /// Their storage format.
    pub storage: Storage,
    /// Topics from `metadata.yaml` (None for a bare file).
    pub topics: Option<Vec<TopicInfo>>,
    limits: BagLimits,
}

fn open_err(path: &Path, reason: impl Into<String>) -> BagError {
    BagError::Open {
        path: path.to_path_buf(),
        reason: reason.into(),
    }
}

fn storage_of(path: &Path) -> Option<Storage> {
    match path.extension().and_then(|e| e.to_str()) {
        Some("mcap") => Some(Storage::Mcap),
        Some("db3") => Some(Storage::Sqlite),
        _ => None,
    }
}

/// Opens a bag directory or a bare `.mcap` / `.db3` file.
///
/// # Errors
/// [`BagError::Open`] when the path is not a bag, or its `metadata.yaml` is unreadable.
pub fn open_bag(path: &Path, limits: BagLimits) -> Result<Bag, BagError> {
    if path.is_file() {
        let storage = storage_of(path).ok_or_else(|| {
            open_err(
                path,
                "not a bag: expected a bag directory, an .mcap or a .db3 file",
            )
        })?;
        return Ok(Bag {
            files: vec![path.to_path_buf()],
            storage,
            topics: None,
            limits,
        });
    }
    if !path.is_dir() {
        return Err(open_err(path, "no such file or directory"));
    }
    let meta = path.join("metadata.yaml");
    if meta.is_file() {
        return open_with_metadata(path, &meta, limits);
    }
    // No metadata: every .mcap or .db3 file of the directory, by name.
    let mut files: Vec<PathBuf> = std::fs::read_dir(path)
        .map_err(|e| open_err(path, e.to_string()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| storage_of(p).is_some())
        .collect();
    files.sort();
    let storage = files
        .first()
        .and_then(|f| storage_of(f))
        .ok_or_else(|| open_err(path, "no metadata.yaml and no .mcap or .db3 file"))?;
    if files.iter().any(|f| storage_of(f) != Some(storage)) {
        return Err(open_err(path, "mixes .mcap and .db3 files"));
    }
    Ok(Bag {
        files,
        storage,
        topics: None,
        limits,
    })
}

fn open_with_metadata(dir: &Path, meta: &Path, limits: BagLimits) -> Result<Bag, BagError> {
    let text = std::fs::read_to_string(meta).map_err(|e| open_err(meta, e.to_string()))?;
    let doc: Value = serde_norway::from_str(&text).map_err(|e| open_err(meta, e.to_string()))?;
    let info = doc
        .get("rosbag2_bagfile_information")
        .ok_or_else(|| open_err(meta, "no rosbag2_bagfile_information"))?;
    let storage = match info.get("storage_identifier").and_then(Value::as_str) {
        Some("mcap") => Storage::Mcap,
        Some("sqlite3") => Storage::Sqlite,
        other => {
            return Err(open_err(
                meta,
                format!("storage_identifier {other:?}: only mcap and sqlite3 are read"),
            ))
        }
    };
    let files: Vec<PathBuf> = info
        .get("relative_file_paths")
        .and_then(Value::as_sequence)
        .ok_or_else(|| open_err(meta, "no relative_file_paths"))?
        .iter()
        .map(|v| {
            v.as_str()
                .map(|s| dir.join(s))
                .ok_or_else(|| open_err(meta, "a relative_file_paths entry is not a string"))
        })
        .collect::<Result<_, _>>()?;
    if let Some(missing) = files.iter().find(|f| !f.is_file()) {
        return Err(open_err(
            meta,
            format!("lists {}, which does not exist", missing.display()),
        ));
    }
    let topics = info
        .get("topics_with_message_count")
        .and_then(Value::as_sequence)
        .map(|list| {
            list.iter()
                .filter_map(|t| {
                    let m = t.get("topic_metadata")?;
                    Some(TopicInfo {
                        name: m.get("name")?.as_str()?.to_string(),
                        msg_type: m.get("type")?.as_str()?.to_string(),
                        count: t.get("message_count").and_then(Value::as_u64),
                    })
                })
                .collect()
        });
    Ok(Bag {
        files,
        storage,
        topics,
        limits,
    })
}

/// `name (type), ...` of `topics`, or `none`.
pub fn list_topics(topics: &[TopicInfo]) -> String {
    if topics.is_empty() {
        return "none".into();
    }
    topics
        .iter()
        .map(|t| format!("{} ({})", t.name, t.msg_type))
        .collect::<Vec<_>>()
        .join(", ")
}

impl Bag {
    /// The topic's entry in `metadata.yaml`, or [`BagError::NoSuchTopic`] when the bag lists
    /// its topics and this one is not among them. `Ok(None)` when the bag has no list.
    ///
    /// # Errors
    /// [`BagError::NoSuchTopic`].
    pub fn check_topic(&self, topic: &str) -> Result<Option<&TopicInfo>, BagError> {
        match &self.topics {
            None => Ok(None),
            Some(list) => match list.iter().find(|t| t.name == topic) {
                Some(t) => Ok(Some(t)),
                None => Err(BagError::NoSuchTopic {
                    topic: topic.to_string(),
                    available: list_topics(list),
                }),
            },
        }
    }

    /// Hands every message of `topic` to `f`, in recorded order, until `f` breaks. Returns
    /// the number of messages handed out.
    ///
    /// # Errors
    /// [`BagError::NoSuchTopic`] (listing the topics found) when no file has the topic;
    /// [`BagError::Corrupt`] when a file is truncated or corrupt: the messages before the
    /// damage have been handed out.
    pub fn read_topic(
        &self,
        topic: &str,
        mut f: impl FnMut(BagMessage<'_>) -> ControlFlow<()>,
    ) -> Result<u64, BagError> {
        self.check_topic(topic)?;
        let mut seen: BTreeMap<String, TopicInfo> = BTreeMap::new();
        let mut found = false;
        let mut count = 0u64;
        for file in &self.files {
            let flow = match self.storage {
                Storage::Mcap => read_mcap(file, topic, self.limits, &mut seen, &mut f),
                Storage::Sqlite => read_sqlite(file, topic, &mut seen, &mut f),
            }?;
            found |= flow.found;
            count += flow.count;
            if flow.stopped {
                break;
            }
        }
        if !found {
            return Err(BagError::NoSuchTopic {
                topic: topic.to_string(),
                available: list_topics(&seen.into_values().collect::<Vec<_>>()),
            });
        }
        Ok(count)
    }
}

/// What reading one file did.
struct FileRead {
    found: bool,
    stopped: bool,
    count: u64,
}

fn corrupt(path: &Path, reason: impl std::fmt::Display) -> BagError {
    BagError::Corrupt {
        path: path.to_path_buf(),
        reason: reason.to_string(),
    }
}

fn read_mcap(
    path: &Path,
    topic: &str,
    limits: BagLimits,
    seen: &mut BTreeMap<String, TopicInfo>,
    f: &mut impl FnMut(BagMessage<'_>) -> ControlFlow<()>,
) -> Result<FileRead, BagError> {
    let mut file = std::fs::File::open(path).map_err(|e| open_err(path, e.to_string()))?;
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default().with_record_length_limit(limits.max_record_bytes),
    );
    let mut schemas: HashMap<u16, String> = HashMap::new();
    // Channel id -> (topic, type) of the channels seen so far.
    let mut channels: HashMap<u16, (String, String)> = HashMap::new();
    let mut wanted: Option<(u16, String)> = None;
    let mut out = FileRead {
        found: false,
        stopped: false,
        count: 0,
    };
    while let Some(event) = reader.next_event() {
        match event.map_err(|e| corrupt(path, e))? {
            LinearReadEvent::ReadRequest(n) => {
                let buf = reader.insert(n);
                let got = loop {
                    match file.read(buf) {
                        Ok(k) => break k,
                        Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                        Err(e) => return Err(corrupt(path, e)),
                    }
                };
                reader.notify_read(got);
            }
            LinearReadEvent::Record { opcode, data } => {
                match mcap::parse_record(opcode, data).map_err(|e| corrupt(path, e))? {
                    Record::Schema { header, .. } => {
                        schemas.insert(header.id, header.name);
                    }
                    Record::Channel(c) => {
                        let ty = schemas.get(&c.schema_id).cloned().unwrap_or_default();
                        seen.entry(c.topic.clone()).or_insert_with(|| TopicInfo {
                            name: c.topic.clone(),
                            msg_type: ty.clone(),
                            count: None,
                        });
                        if c.topic == topic && c.message_encoding == "cdr" {
                            out.found = true;
                            wanted = Some((c.id, ty.clone()));
                        }
                        channels.insert(c.id, (c.topic, ty));
                    }
                    Record::Message { header, data } => {
                        let Some((id, ty)) = &wanted else { continue };
                        if header.channel_id != *id {
                            continue;
                        }
                        out.count += 1;
                        let msg = BagMessage {
                            log_time: header.log_time,
                            msg_type: ty,
                            data: &data,
                        };
                        if f(msg).is_break() {
                            out.stopped = true;
                            return Ok(out);
                        }
                    }
                    // The summary repeats schemas and channels; nothing else matters here.
                    Record::DataEnd(_) => break,
                    _ => {}
                }
            }
        }
    }
    Ok(out)
}

fn read_sqlite(
    path: &Path,
    topic: &str,
    seen: &mut BTreeMap<String, TopicInfo>,
    f: &mut impl FnMut(BagMessage<'_>) -> ControlFlow<()>,
) -> Result<FileRead, BagError> {
    use rusqlite::{Connection, OpenFlags};
    let err = |e: rusqlite::Error| corrupt(path, e);
    let conn = Connection::open_with_flags(
        path,
        OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX,
    )
    .map_err(err)?;
    let mut out = FileRead {
        found: false,
        stopped: false,
        count: 0,
    };
    let mut wanted: Option<(i64, String)> = None;
    {
        let mut q = conn
            .prepare("SELECT id, name, type, serialization_format FROM topics")
            .map_err(err)?;
        let mut rows = q.query([]).map_err(err)?;
        while let Some(r) = rows.next().map_err(err)? {
            let (id, name, ty, fmt): (i64, String, String, String) = (
                r.get(0).map_err(err)?,
                r.get(1).map_err(err)?,
                r.get(2).map_err(err)?,
                r.get(3).map_err(err)?,
            );
            if name == topic && fmt == "cdr" {
                wanted = Some((id, ty.clone()));
            }
            seen.entry(name.clone()).or_insert(TopicInfo {
                name,
                msg_type: ty,
                count: None,
            });
        }
    }
    let Some((id, ty)) = wanted else {
        return Ok(out);
    };
    out.found = true;
    let mut q = conn
        .prepare("SELECT timestamp, data FROM messages WHERE topic_id = ?1 ORDER BY timestamp, id")
        .map_err(err)?;
    let mut rows = q.query([id]).map_err(err)?;
    while let Some(r) = rows.next().map_err(err)? {
        let t: i64 = r.get(0).map_err(err)?;
        let data = r
            .get_ref(1)
            .map_err(err)?
            .as_blob()
            .map_err(|e| corrupt(path, e))?;
        out.count += 1;
        let msg = BagMessage {
            log_time: u64::try_from(t).unwrap_or(0),
            msg_type: &ty,
            data,
        };
        if f(msg).is_break() {
            out.stopped = true;
            break;
        }
    }
    Ok(out)
}
