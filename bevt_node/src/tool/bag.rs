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
    let text = crate::yaml::read_file(meta).map_err(|e| open_err(meta, e))?;
    let doc: Value = crate::yaml::parse(&text, "metadata.yaml").map_err(|e| open_err(meta, e))?;
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

/// Most bytes asked of the source at once: the reader's buffer grows with the bytes that
/// arrive, not with a length the file declares (a record declaring 1 GiB in a 100-byte file
/// costs 1 MiB, then an error).
const READ_PIECE: usize = 1 << 20;

fn read_mcap(
    path: &Path,
    topic: &str,
    limits: BagLimits,
    seen: &mut BTreeMap<String, TopicInfo>,
    f: &mut impl FnMut(BagMessage<'_>) -> ControlFlow<()>,
) -> Result<FileRead, BagError> {
    let file = std::fs::File::open(path).map_err(|e| open_err(path, e.to_string()))?;
    read_mcap_from(file, path, topic, limits, seen, f)
}

/// Hands every message of `topic` in the MCAP stream `data` to `f` (as
/// [`Bag::read_topic`] does for a file; the fuzz target `bag_reader` reads through here).
/// Returns the number of messages handed out.
///
/// # Errors
/// As [`Bag::read_topic`], the path being `<memory>`.
pub fn read_mcap_bytes(
    data: &[u8],
    topic: &str,
    limits: BagLimits,
    mut f: impl FnMut(BagMessage<'_>) -> ControlFlow<()>,
) -> Result<u64, BagError> {
    let mut seen = BTreeMap::new();
    let r = read_mcap_from(
        data,
        Path::new("<memory>"),
        topic,
        limits,
        &mut seen,
        &mut f,
    )?;
    if !r.found {
        return Err(BagError::NoSuchTopic {
            topic: topic.to_string(),
            available: list_topics(&seen.into_values().collect::<Vec<_>>()),
        });
    }
    Ok(r.count)
}

/// The records of a file being read: schemas and channels seen, the wanted channel.
struct McapState<'t> {
    topic: &'t str,
    schemas: HashMap<u16, String>,
    wanted: Option<(u16, String)>,
    out: FileRead,
}

impl McapState<'_> {
    /// Handles one record (of the file or of a chunk); `Break` when `f` stopped or the data
    /// section ended.
    fn record(
        &mut self,
        path: &Path,
        opcode: u8,
        data: &[u8],
        limits: BagLimits,
        seen: &mut BTreeMap<String, TopicInfo>,
        f: &mut impl FnMut(BagMessage<'_>) -> ControlFlow<()>,
    ) -> Result<ControlFlow<()>, BagError> {
        use mcap::records::op;
        // Only the records read here are parsed: mcap 0.26's parser of the others can panic
        // on a malformed record (an attachment cut before its CRC slices out of bounds;
        // found by the bag_reader fuzz target).
        if ![
            op::SCHEMA,
            op::CHANNEL,
            op::MESSAGE,
            op::CHUNK,
            op::DATA_END,
        ]
        .contains(&opcode)
        {
            return Ok(ControlFlow::Continue(()));
        }
        match mcap::parse_record(opcode, data).map_err(|e| corrupt(path, e))? {
            Record::Schema { header, .. } => {
                self.schemas.insert(header.id, header.name);
            }
            Record::Channel(c) => {
                let ty = self.schemas.get(&c.schema_id).cloned().unwrap_or_default();
                seen.entry(c.topic.clone()).or_insert_with(|| TopicInfo {
                    name: c.topic.clone(),
                    msg_type: ty.clone(),
                    count: None,
                });
                if c.topic == self.topic && c.message_encoding == "cdr" {
                    self.out.found = true;
                    self.wanted = Some((c.id, ty));
                }
            }
            Record::Message { header, data } => {
                let Some((id, ty)) = &self.wanted else {
                    return Ok(ControlFlow::Continue(()));
                };
                if header.channel_id != *id {
                    return Ok(ControlFlow::Continue(()));
                }
                self.out.count += 1;
                let msg = BagMessage {
                    log_time: header.log_time,
                    msg_type: ty,
                    data: &data,
                };
                if f(msg).is_break() {
                    self.out.stopped = true;
                    return Ok(ControlFlow::Break(()));
                }
            }
            Record::Chunk { header, data } => {
                let records =
                    decompress_chunk(&header, &data, limits).map_err(|e| corrupt(path, e))?;
                let mut rest: &[u8] = &records;
                // Records inside a chunk: opcode (1 byte), length (u64 LE), body.
                while !rest.is_empty() {
                    let (&op, after) = rest
                        .split_first()
                        .ok_or_else(|| corrupt(path, "chunk record cut short"))?;
                    let (len, body) = after
                        .split_first_chunk::<8>()
                        .ok_or_else(|| corrupt(path, "chunk record length cut short"))?;
                    let len = usize::try_from(u64::from_le_bytes(*len))
                        .ok()
                        .filter(|&n| n <= body.len())
                        .ok_or_else(|| {
                            corrupt(path, "a record in a chunk is longer than the chunk")
                        })?;
                    let (data, next) = body.split_at(len);
                    if op == mcap::records::op::CHUNK {
                        return Err(corrupt(path, "a chunk inside a chunk"));
                    }
                    if self.record(path, op, data, limits, seen, f)?.is_break() {
                        return Ok(ControlFlow::Break(()));
                    }
                    rest = next;
                }
            }
            // The summary repeats schemas and channels; nothing else matters here.
            Record::DataEnd(_) => return Ok(ControlFlow::Break(())),
            _ => {}
        }
        Ok(ControlFlow::Continue(()))
    }
}

/// The records of a chunk, decompressed. The declared uncompressed size is checked against
/// the limit and against what the compressed data really yields; the output buffer grows
/// with the bytes decompressed, never to the declared size up front.
fn decompress_chunk<'a>(
    header: &mcap::records::ChunkHeader,
    data: &'a [u8],
    limits: BagLimits,
) -> Result<std::borrow::Cow<'a, [u8]>, String> {
    let declared = header.uncompressed_size;
    let want = usize::try_from(declared)
        .ok()
        .filter(|&n| n <= limits.max_record_bytes)
        .ok_or_else(|| {
            format!(
                "a chunk declares {declared} bytes uncompressed, over the limit of {}",
                limits.max_record_bytes
            )
        })?;
    let bounded = |mut r: Box<dyn Read + 'a>| -> Result<Vec<u8>, String> {
        let mut out = Vec::new();
        let mut piece = vec![0u8; 64 * 1024];
        loop {
            let n = match r.read(&mut piece) {
                Ok(0) => break,
                Ok(n) => n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(format!("{} chunk: {e}", header.compression)),
            };
            if out.len() + n > want {
                return Err(format!(
                    "a {} chunk decompresses to more than the {want} bytes it declares",
                    header.compression
                ));
            }
            out.extend_from_slice(&piece[..n]);
        }
        if out.len() != want {
            return Err(format!(
                "a {} chunk decompresses to {} bytes, it declares {want}",
                header.compression,
                out.len()
            ));
        }
        Ok(out)
    };
    match header.compression.as_str() {
        "" if data.len() == want => Ok(std::borrow::Cow::Borrowed(data)),
        "" => Err(format!(
            "an uncompressed chunk holds {} bytes, it declares {want}",
            data.len()
        )),
        "zstd" => {
            let d = zstd::stream::read::Decoder::with_buffer(data)
                .map_err(|e| format!("zstd chunk: {e}"))?;
            bounded(Box::new(d)).map(std::borrow::Cow::Owned)
        }
        "lz4" => {
            let d = lz4::Decoder::new(data).map_err(|e| format!("lz4 chunk: {e}"))?;
            bounded(Box::new(d)).map(std::borrow::Cow::Owned)
        }
        other => Err(format!(
            "chunk compression {other:?}: only zstd and lz4 are read"
        )),
    }
}

fn read_mcap_from(
    mut src: impl Read,
    path: &Path,
    topic: &str,
    limits: BagLimits,
    seen: &mut BTreeMap<String, TopicInfo>,
    f: &mut impl FnMut(BagMessage<'_>) -> ControlFlow<()>,
) -> Result<FileRead, BagError> {
    // Chunks come whole (their compressed bytes are read as they arrive) and are
    // decompressed here, bounded: mcap's own chunk reader sizes its output buffer from the
    // record length a chunk declares.
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_record_length_limit(limits.max_record_bytes)
            .with_emit_chunks(true),
    );
    let mut st = McapState {
        topic,
        schemas: HashMap::new(),
        wanted: None,
        out: FileRead {
            found: false,
            stopped: false,
            count: 0,
        },
    };
    while let Some(event) = reader.next_event() {
        match event.map_err(|e| corrupt(path, e))? {
            LinearReadEvent::ReadRequest(n) => {
                let buf = reader.insert(n.min(READ_PIECE));
                let got = loop {
                    match src.read(buf) {
                        Ok(k) => break k,
                        Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                        Err(e) => return Err(corrupt(path, e)),
                    }
                };
                reader.notify_read(got);
            }
            LinearReadEvent::Record { opcode, data } => {
                if st.record(path, opcode, data, limits, seen, f)?.is_break() {
                    break;
                }
            }
        }
    }
    Ok(st.out)
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

#[cfg(test)]
mod tests {
    use super::*;

    const TOPIC: &str = "/cam";

    /// An MCAP stream of `n` messages of 100 bytes each on `TOPIC`.
    fn mcap(compression: Option<mcap::Compression>, n: u32) -> Vec<u8> {
        let mut out = std::io::Cursor::new(Vec::new());
        let mut w = mcap::WriteOptions::new()
            .compression(compression)
            .create(&mut out)
            .unwrap();
        let s = w
            .add_schema("sensor_msgs/msg/Image", "ros2msg", b"")
            .unwrap();
        let c = w.add_channel(s, TOPIC, "cdr", &BTreeMap::new()).unwrap();
        for i in 0..n {
            let h = mcap::records::MessageHeader {
                channel_id: c,
                sequence: i,
                log_time: u64::from(i),
                publish_time: u64::from(i),
            };
            w.write_to_known_channel(&h, &[i as u8; 100]).unwrap();
        }
        w.finish().unwrap();
        drop(w);
        out.into_inner()
    }

    /// Offset of the body of the first record with `opcode` (records walked from the magic).
    fn record_body(file: &[u8], opcode: u8) -> usize {
        let mut at = 8;
        loop {
            let len = u64::from_le_bytes(file[at + 1..at + 9].try_into().unwrap()) as usize;
            if file[at] == opcode {
                return at + 9;
            }
            at += 9 + len;
        }
    }

    fn read(file: &[u8]) -> Result<u64, BagError> {
        read_mcap_bytes(file, TOPIC, BagLimits::default(), |m| {
            assert_eq!(m.data.len(), 100);
            ControlFlow::Continue(())
        })
    }

    #[test]
    fn every_compression_reads_all_messages() {
        for c in [
            None,
            Some(mcap::Compression::Zstd),
            Some(mcap::Compression::Lz4),
        ] {
            assert_eq!(read(&mcap(c, 5)).unwrap(), 5, "{c:?}");
        }
    }

    #[test]
    fn a_record_declaring_a_huge_length_is_an_error_without_reading_it() {
        // A chunk declaring 1 GiB - 1 in a tiny stream: the reader may only buffer what
        // arrives (this test allocated ~1 GiB before the bounded reads).
        let mut f = mcap(None, 1);
        let at = record_body(&f, mcap::records::op::CHUNK) - 8;
        f[at..at + 8].copy_from_slice(&((1u64 << 30) - 1).to_le_bytes());
        let hwm = || -> Option<u64> {
            let s = std::fs::read_to_string("/proc/self/status").ok()?;
            s.lines()
                .find_map(|l| l.strip_prefix("VmHWM:"))?
                .trim()
                .trim_end_matches("kB")
                .trim()
                .parse()
                .ok()
        };
        let before = hwm();
        let e = read(&f).unwrap_err().to_string();
        assert!(e.contains("<memory>"), "{e}");
        // Peak RSS (Linux): the declared gigabyte was not allocated (other tests of this
        // process allocate far less than 512 MiB).
        if let (Some(a), Some(b)) = (before, hwm()) {
            assert!(b - a < 512 * 1024, "peak RSS rose {} KiB", b - a);
        }
    }

    #[test]
    fn a_chunk_lying_about_its_uncompressed_size_is_refused() {
        for (c, bigger) in [
            (Some(mcap::Compression::Zstd), true),
            (Some(mcap::Compression::Zstd), false),
            (Some(mcap::Compression::Lz4), true),
            (None, true),
        ] {
            let mut f = mcap(c, 3);
            let body = record_body(&f, mcap::records::op::CHUNK);
            let at = body + 16;
            let real = u64::from_le_bytes(f[at..at + 8].try_into().unwrap());
            let lie = if bigger { real + 1000 } else { real - 1 };
            f[at..at + 8].copy_from_slice(&lie.to_le_bytes());
            let e = read(&f).unwrap_err().to_string();
            assert!(e.contains("declares"), "{c:?} {bigger}: {e}");
        }
        // Over the limit: refused before decompressing.
        let mut f = mcap(Some(mcap::Compression::Zstd), 1);
        let at = record_body(&f, mcap::records::op::CHUNK) + 16;
        f[at..at + 8].copy_from_slice(&(1u64 << 40).to_le_bytes());
        let e = read(&f).unwrap_err().to_string();
        assert!(e.contains("over the limit"), "{e}");
    }

    #[test]
    fn records_not_read_are_not_parsed() {
        // An attachment record cut before its CRC (mcap's parser panics on it) between the
        // header and the data: skipped, the messages are read.
        let f = mcap(None, 2);
        let at = record_body(&f, mcap::records::op::CHUNK) - 9;
        let mut body = Vec::new();
        body.extend_from_slice(&[0u8; 16]); // log and create time
        body.extend_from_slice(&[1, 0, 0, 0, b'a']); // name
        body.extend_from_slice(&[0, 0, 0, 0]); // media type
        body.extend_from_slice(&0u64.to_le_bytes()); // data length, then no CRC
        let mut g = f[..at].to_vec();
        g.push(mcap::records::op::ATTACHMENT);
        g.extend_from_slice(&(body.len() as u64).to_le_bytes());
        g.extend_from_slice(&body);
        g.extend_from_slice(&f[at..]);
        assert_eq!(read(&g).unwrap(), 2);
    }

    #[test]
    fn a_record_longer_than_its_chunk_is_refused() {
        // Uncompressed chunk: the first record inside it declares 2^40 bytes.
        let mut f = mcap(None, 2);
        let body = record_body(&f, mcap::records::op::CHUNK);
        let clen = u32::from_le_bytes(f[body + 28..body + 32].try_into().unwrap()) as usize;
        let records = body + 32 + clen + 8;
        f[records + 1..records + 9].copy_from_slice(&(1u64 << 40).to_le_bytes());
        let e = read(&f).unwrap_err().to_string();
        assert!(e.contains("longer than the chunk"), "{e}");
    }
}
