use std::{
  collections::{btree_map::Entry, BTreeMap},
  fmt, iter,
  time::Duration,
};

use enumflags2::BitFlags;
use bytes::{Bytes, BytesMut};
#[allow(unused_imports)]
use log::{debug, error, info, trace, warn};

use crate::{
  dds::ddsdata::DDSData,
  messages::submessages::{
    elements::serialized_payload::SerializedPayload,
    submessages::{DATAFRAG_Flags, DataFrag},
  },
  structure::{
    cache_change::ChangeKind,
    sequence_number::{FragmentNumber, SequenceNumber},
    time::Timestamp,
  },
};

/// Limits on the reassembly of fragmented samples (RTPS DATA_FRAG
/// submessages).
///
/// A DATA_FRAG declares the size of the whole sample (up to 4 GiB), and anyone
/// who can send a UDP datagram to a receive socket can send one. A reader
/// therefore refuses samples declared larger than its maximum, stores only the
/// fragments that actually arrived, keeps a bounded number of incomplete
/// samples and bytes (evicting incomplete samples beyond that), and drops an
/// incomplete sample that received nothing for `assembly_timeout`, on a timer.
/// Set with [`DomainParticipantBuilder::fragment_limits`](crate::DomainParticipantBuilder::fragment_limits).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FragmentLimits {
  /// Largest sample a user-topic reader reassembles, in bytes of serialized
  /// payload (including its 4-byte encapsulation header). Fragments of a
  /// sample declared larger are dropped.
  pub max_sample_size: usize,
  /// Largest sample a built-in (discovery) reader reassembles, bytes.
  pub max_builtin_sample_size: usize,
  /// Most incomplete samples one reader keeps, all writers together.
  pub max_assemblies_per_reader: usize,
  /// Most bytes of incomplete samples one user-topic reader keeps, all writers
  /// together (the fragments received plus a bookkeeping charge per stored
  /// run). Should be at least `max_sample_size`, or the largest samples can
  /// never complete.
  pub max_assembly_bytes_per_reader: usize,
  /// Same as `max_assembly_bytes_per_reader`, for a built-in reader.
  pub max_builtin_assembly_bytes_per_reader: usize,
  /// Most bytes of incomplete samples all readers of the participant keep
  /// together. A reader over it evicts its own incomplete samples (the new one
  /// too, if need be), so the total is bounded however many readers there are.
  pub max_assembly_bytes_per_participant: usize,
  /// An incomplete sample that received no fragment for this long is dropped.
  /// Checked on a timer, so a stale sample lives at most twice this long even
  /// if no further traffic arrives.
  pub assembly_timeout: Duration,
}

impl FragmentLimits {
  /// Default [`max_sample_size`](Self::max_sample_size): 256 MiB.
  pub const DEFAULT_MAX_SAMPLE_SIZE: usize = 256 * 1024 * 1024;
  /// Default [`max_builtin_sample_size`](Self::max_builtin_sample_size):
  /// 256 KiB. Discovery samples are a few KiB.
  pub const DEFAULT_MAX_BUILTIN_SAMPLE_SIZE: usize = 256 * 1024;
  /// Default [`max_assemblies_per_reader`](Self::max_assemblies_per_reader).
  pub const DEFAULT_MAX_ASSEMBLIES_PER_READER: usize = 256;
  /// Default [`assembly_timeout`](Self::assembly_timeout): 10 s.
  pub const DEFAULT_ASSEMBLY_TIMEOUT: Duration = Duration::from_secs(10);
  /// Room in [`max_assembly_bytes_per_participant`](Self::max_assembly_bytes_per_participant)
  /// beyond one user reader's budget, for the built-in readers: 16 MiB.
  pub const BUILTIN_PARTICIPANT_ROOM: usize = 16 * 1024 * 1024;

  /// Limits with the given maximum user sample size; the per-reader byte
  /// budget is twice that, the participant's that plus
  /// [`BUILTIN_PARTICIPANT_ROOM`](Self::BUILTIN_PARTICIPANT_ROOM), everything
  /// else is default.
  pub fn with_max_sample_size(max_sample_size: usize) -> Self {
    let per_reader = max_sample_size.saturating_mul(2);
    Self {
      max_sample_size,
      max_assembly_bytes_per_reader: per_reader,
      max_assembly_bytes_per_participant: per_reader.saturating_add(Self::BUILTIN_PARTICIPANT_ROOM),
      ..Self::default()
    }
  }

  /// The limits that apply to one reader.
  pub(crate) fn for_reader(&self, builtin: bool) -> ReaderFragmentLimits {
    ReaderFragmentLimits {
      max_sample_size: if builtin {
        self.max_builtin_sample_size
      } else {
        self.max_sample_size
      },
      max_assemblies: self.max_assemblies_per_reader,
      max_bytes: if builtin {
        self.max_builtin_assembly_bytes_per_reader
      } else {
        self.max_assembly_bytes_per_reader
      },
      max_participant_bytes: self.max_assembly_bytes_per_participant,
      timeout: self.assembly_timeout,
    }
  }
}

impl Default for FragmentLimits {
  fn default() -> Self {
    Self {
      max_sample_size: Self::DEFAULT_MAX_SAMPLE_SIZE,
      max_builtin_sample_size: Self::DEFAULT_MAX_BUILTIN_SAMPLE_SIZE,
      max_assemblies_per_reader: Self::DEFAULT_MAX_ASSEMBLIES_PER_READER,
      max_assembly_bytes_per_reader: 2 * Self::DEFAULT_MAX_SAMPLE_SIZE,
      max_builtin_assembly_bytes_per_reader: 4 * Self::DEFAULT_MAX_BUILTIN_SAMPLE_SIZE,
      max_assembly_bytes_per_participant: 2 * Self::DEFAULT_MAX_SAMPLE_SIZE
        + Self::BUILTIN_PARTICIPANT_ROOM,
      assembly_timeout: Self::DEFAULT_ASSEMBLY_TIMEOUT,
    }
  }
}

/// [`FragmentLimits`] resolved for one reader (user or built-in).
#[derive(Clone, Copy, Debug)]
pub(crate) struct ReaderFragmentLimits {
  pub max_sample_size: usize,
  pub max_assemblies: usize,
  pub max_bytes: usize,
  pub max_participant_bytes: usize,
  pub timeout: Duration,
}

/// Bytes of incomplete samples held by all readers of a participant (they all
/// live on its event-loop thread).
pub(crate) type FragmentPool = std::rc::Rc<std::cell::Cell<usize>>;

// Bytes charged against the per-reader budget for each stored run of
// fragments (map node and `Bytes` handle) and for each incomplete sample, so
// that floods of tiny fragments are bounded too.
const RUN_OVERHEAD: usize = 64;
const ASSEMBLY_OVERHEAD: usize = 256;

// This is for the assembly of a single object.
//
// Only the fragments that arrived are stored (as runs, copied out of the
// receive buffer), never a buffer of the size the DATA_FRAG declares: that
// size is sender-controlled. The sample is concatenated when complete.
struct AssemblyBuffer {
  data_size: usize,
  fragment_size: usize,
  fragment_count: usize,
  // Received fragments as non-overlapping runs:
  // first fragment (0-based) -> (number of fragments, their bytes).
  runs: BTreeMap<usize, (usize, Bytes)>,
  received_fragments: usize,
  // Memory accounted to this buffer (received bytes + overheads).
  charged_bytes: usize,

  created_time: Timestamp,
  modified_time: Timestamp,
}

impl AssemblyBuffer {
  pub fn new(datafrag: &DataFrag, max_sample_size: usize) -> Option<Self> {
    let data_size: usize = datafrag.data_size.try_into().ok()?;
    let fragment_size = usize::from(datafrag.fragment_size);
    debug!("new AssemblyBuffer data_size={data_size} frag_size={fragment_size}");

    if data_size > max_sample_size {
      debug!("Cannot create AssemblyBuffer: data_size={data_size} exceeds {max_sample_size}");
      return None;
    }
    if fragment_size == 0 || fragment_size > data_size {
      debug!("Cannot create AssemblyBuffer: fragment_size={fragment_size} data_size={data_size}");
      return None;
    }

    let now = Timestamp::now();
    Some(Self {
      data_size,
      fragment_size,
      fragment_count: data_size.div_ceil(fragment_size),
      runs: BTreeMap::new(),
      received_fragments: 0,
      charged_bytes: ASSEMBLY_OVERHEAD,
      created_time: now,
      modified_time: now,
    })
  }

  // The not-yet-received fragment ranges within `first..end` (0-based, end
  // exclusive).
  fn gaps_within(&self, first: usize, end: usize) -> Vec<(usize, usize)> {
    let mut gaps = Vec::new();
    let mut cursor = first;
    // Runs do not overlap, so only the last run starting at or before `first`
    // can reach into the range from the left.
    let from = self
      .runs
      .range(..=first)
      .next_back()
      .map_or(first, |(s, _)| *s);
    for (&s, &(n, _)) in self.runs.range(from..end) {
      if s > cursor {
        gaps.push((cursor, s));
      }
      cursor = cursor.max(s + n);
      if cursor >= end {
        break;
      }
    }
    if cursor < end {
      gaps.push((cursor, end));
    }
    gaps
  }

  /// Returns `false` if the fragment run is invalid or out of bounds.
  pub fn insert_frags(&mut self, datafrag: &DataFrag) -> bool {
    // A writer keeps the fragment size (and of course the data size) of a
    // sample constant: RTPS spec v2.5 Section 8.4.14.1.1.
    if usize::from(datafrag.fragment_size) != self.fragment_size
      || usize::try_from(datafrag.data_size).ok() != Some(self.data_size)
    {
      debug!(
        "insert_frags: fragment_size={} data_size={} differ from the sample's {} {}",
        datafrag.fragment_size, datafrag.data_size, self.fragment_size, self.data_size
      );
      return false;
    }
    let frag_size = self.fragment_size;
    let frags_in_submessage = usize::from(datafrag.fragments_in_submessage);
    if frags_in_submessage == 0 {
      debug!("insert_frags: fragments_in_submessage is zero");
      return false;
    }
    let fragment_starting_num: usize = match u32::from(datafrag.fragment_starting_num).try_into() {
      Ok(n) if n >= 1 => n,
      _ => {
        debug!(
          "insert_frags: invalid fragment_starting_num {:?}",
          datafrag.fragment_starting_num
        );
        return false;
      }
    };
    let first = fragment_starting_num - 1;
    let end = first + frags_in_submessage;
    if end > self.fragment_count {
      debug!(
        "insert_frags: fragment span out of bounds: start={fragment_starting_num} \
         count={frags_in_submessage} total={}",
        self.fragment_count
      );
      return false;
    }

    // Every fragment is `frag_size` bytes except the last one of the sample.
    // The payload may carry submessage padding after the last fragment.
    let from_byte = first * frag_size;
    let to_before_byte = std::cmp::min(end * frag_size, self.data_size);
    let expected = to_before_byte - from_byte;
    if datafrag.serialized_payload.len() < expected {
      debug!(
        "insert_frags: DATAFRAG too small: fragments {fragment_starting_num}+{frags_in_submessage} \
         of {} need {expected} bytes, payload has {}",
        self.fragment_count,
        datafrag.serialized_payload.len(),
      );
      return false;
    }

    let gaps = self.gaps_within(first, end);
    if !gaps.is_empty() {
      // Copy: a slice would keep the whole receive buffer chunk alive.
      let bytes = Bytes::copy_from_slice(&datafrag.serialized_payload[..expected]);
      self.charged_bytes += bytes.len();
      for (a, b) in gaps {
        let lo = (a - first) * frag_size;
        let hi = std::cmp::min((b - first) * frag_size, expected);
        self.runs.insert(a, (b - a, bytes.slice(lo..hi)));
        self.received_fragments += b - a;
        self.charged_bytes += RUN_OVERHEAD;
      }
    }
    self.modified_time = Timestamp::now();
    true
  }

  pub fn is_complete(&self) -> bool {
    self.received_fragments == self.fragment_count
  }

  // The reassembled sample; `None` unless complete.
  fn into_bytes(mut self) -> Option<Bytes> {
    if !self.is_complete() {
      return None;
    }
    let bytes = if self.runs.len() == 1 {
      self.runs.pop_first().map(|(_, (_, b))| b)?
    } else {
      let mut buf = BytesMut::with_capacity(self.data_size);
      for (_, b) in self.runs.values() {
        buf.extend_from_slice(b);
      }
      buf.freeze()
    };
    (bytes.len() == self.data_size).then_some(bytes)
  }

  fn missing_frags(&self) -> Vec<(usize, usize)> {
    self.gaps_within(0, self.fragment_count)
  }
}

// Upper bound on the number of concurrent (incomplete) reassembly buffers kept
// per writer. Fragments belonging to one sample normally arrive back-to-back,
// so only a handful of samples are ever mid-reassembly at once; this cap is far
// above that. Its purpose is to bound memory when samples never complete, e.g.
// under best-effort overload where fragments are dropped: without it, one
// incomplete `AssemblyBuffer` (a full sample-sized allocation) accrues per lost
// sample and is only reclaimed by a 10 s idle timeout, growing to gigabytes.
// When exceeded we evict the oldest (lowest sequence number) buffer, which
// under best effort is lost anyway and under reliable will be re-requested.
// (The per-reader limits of `FragmentLimits` apply on top of this.)
const MAX_ASSEMBLY_BUFFERS: usize = 128;

// Assembles fragments from a single (remote) Writer
// So there is only one sequence of SNs
pub(crate) struct FragmentAssembler {
  assembly_buffers: BTreeMap<SequenceNumber, AssemblyBuffer>,
  // Whether the owning reader is Reliable. This decides which buffer to drop
  // when `MAX_ASSEMBLY_BUFFERS` is exceeded (see `new_datafrag`).
  reliable: bool,
}

impl fmt::Debug for FragmentAssembler {
  fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
    f.debug_struct("FragmentAssembler - fields omitted")
      // insert field printing here, if you really need it.
      .finish()
  }
}

impl FragmentAssembler {
  pub fn new(reliable: bool) -> Self {
    debug!("new FragmentAssembler. reliable = {reliable}");
    Self {
      assembly_buffers: BTreeMap::new(),
      reliable,
    }
  }

  // Returns completed DDSData, when complete, and disposes the assembly buffer.
  // Samples declared larger than `max_sample_size` are not assembled.
  pub fn new_datafrag(
    &mut self,
    datafrag: &DataFrag,
    flags: BitFlags<DATAFRAG_Flags>,
    max_sample_size: usize,
  ) -> Option<DDSData> {
    let writer_sn = datafrag.writer_sn;

    let sn = datafrag.writer_sn;
    match self.assembly_buffers.entry(sn) {
      Entry::Vacant(v) => {
        let Some(buf) = AssemblyBuffer::new(datafrag, max_sample_size) else {
          debug!("new_datafrag: no AssemblyBuffer for {sn:?}");
          return None;
        };
        v.insert(buf);
      }
      Entry::Occupied(_) => {}
    }

    let Some(assembly_buffer) = self.assembly_buffers.get_mut(&sn) else {
      error!("new_datafrag: AssemblyBuffer missing for {sn:?}");
      return None;
    };

    if !assembly_buffer.insert_frags(datafrag) {
      debug!("new_datafrag: rejected invalid DATAFRAG for {sn:?}");
      if assembly_buffer.received_fragments == 0 {
        self.assembly_buffers.remove(&sn);
      }
      return None;
    }

    if assembly_buffer.is_complete() {
      debug!("new_datafrag: COMPLETED FRAGMENT");
      if let Some(assembly_buffer) = self.assembly_buffers.remove(&writer_sn) {
        // Return what we have assembled.
        let Some(bytes) = assembly_buffer.into_bytes() else {
          error!("new_datafrag: reassembled sample has the wrong size");
          return None;
        };
        let serialized_data_or_key = SerializedPayload::from_bytes(&bytes).map_or_else(
          |e| {
            error!("Deserializing SerializedPayload from DATAFRAG: {:?}", e);
            None
          },
          Some,
        )?;
        let dds_data = if flags.contains(DATAFRAG_Flags::Key) {
          DDSData::new_disposed_by_key(ChangeKind::NotAliveDisposed, serialized_data_or_key)
        } else {
          // it is data
          DDSData::new(serialized_data_or_key)
        };
        Some(dds_data) // completed data from fragments
      } else {
        error!("Assembly buffer mysteriously lost");
        None
      }
    } else {
      debug!("new_dataFrag: FRAGMENT NOT COMPLETED YET");
      // Bound memory: never keep more than MAX_ASSEMBLY_BUFFERS incomplete
      // reassemblies.
      //
      // Which one to evict depends on reliability:
      //  * Reliable: the reader delivers strictly in order, so it must complete the
      //    LOWEST sequence number first; that buffer is exactly the one blocking
      //    progress. Dropping it would livelock, because a writer that bursts many
      //    large samples ahead (e.g. Connext) would make the reader perpetually evict
      //    the very sample it is waiting for. So evict the HIGHEST (newest) sequence
      //    number instead; the writer keeps unacked samples in its history and
      //    re-sends them once we catch up.
      //  * Best effort: there is no retransmission, so a low incomplete buffer is
      //    lost anyway. Evict the OLDEST (lowest SN) to free room for newer samples
      //    that may still complete.
      while self.assembly_buffers.len() > MAX_ASSEMBLY_BUFFERS {
        let evicted = if self.reliable {
          self.assembly_buffers.pop_last()
        } else {
          self.assembly_buffers.pop_first()
        };
        if evicted.is_none() {
          break;
        }
      }
      None
    }
  }

  pub fn garbage_collect_before(&mut self, expire_before: Timestamp) {
    self.assembly_buffers.retain(|sn, ab| {
      let retain = ab.modified_time >= expire_before;
      if !retain {
        info!("AssemblyBuffer dropping {sn:?}");
      }
      retain
    });
  }

  /// Number of incomplete samples.
  pub fn assembly_count(&self) -> usize {
    self.assembly_buffers.len()
  }

  /// Bytes accounted to the incomplete samples.
  pub fn charged_bytes(&self) -> usize {
    self
      .assembly_buffers
      .values()
      .map(|ab| ab.charged_bytes)
      .sum()
  }

  /// The (creation time, SN) of the newest or the oldest incomplete sample.
  pub fn created_extreme(&self, newest: bool) -> Option<(Timestamp, SequenceNumber)> {
    let it = self
      .assembly_buffers
      .iter()
      .map(|(sn, ab)| (ab.created_time, *sn));
    if newest {
      it.max()
    } else {
      it.min()
    }
  }

  /// Drops an incomplete sample.
  pub fn evict(&mut self, sn: SequenceNumber) {
    self.assembly_buffers.remove(&sn);
  }

  pub fn is_empty(&self) -> bool {
    self.assembly_buffers.is_empty()
  }

  // pub fn partially_received_sequence_numbers_iterator(&self) -> Box<dyn
  // Iterator<Item=SequenceNumber>> {   // Since we should only know about SNs
  // via DATAFRAG messages   // and AssemblyBuffers are removed immediately on
  // completion,   // the list should be just the list of current
  // AssemblyBuffers   self.assembly_buffers.keys()
  // }

  pub fn is_partially_received(&self, sn: SequenceNumber) -> bool {
    self.assembly_buffers.contains_key(&sn)
    // assembly buffers map contains a key (SN) if and only if we have some
    // frags but not all
  }

  pub fn missing_frags_for(
    &self,
    seq: SequenceNumber,
  ) -> Box<dyn '_ + Iterator<Item = FragmentNumber>> {
    match self.assembly_buffers.get(&seq) {
      None => Box::new(iter::empty()),
      Some(ab) => {
        let iter = ab
          .missing_frags()
          .into_iter()
          .flat_map(|(a, b)| a..b)
          .filter_map(|f| u32::try_from(f + 1).ok().map(FragmentNumber::new));
        Box::new(iter)
      }
    }
  }
}

#[cfg(test)]
mod tests {
  use bytes::Bytes;

  use super::AssemblyBuffer;
  use crate::{
    messages::submessages::submessages::DataFrag, structure::sequence_number::FragmentNumber,
  };

  // Build a DATAFRAG submessage carrying the contiguous run of `k` fragments
  // starting at 1-based `start`, with the given payload bytes.
  fn datafrag(start: u32, k: u16, frag_size: u16, data_size: u32, payload: Vec<u8>) -> DataFrag {
    DataFrag {
      fragment_starting_num: FragmentNumber::new(start),
      fragments_in_submessage: k,
      fragment_size: frag_size,
      data_size,
      serialized_payload: Bytes::from(payload),
      ..Default::default()
    }
  }

  // A DATAFRAG that packs K > 1 fragments in one submessage must reassemble the
  // same bytes as one-fragment-per-submessage would. This exercises the
  // adaptive-packing writer path against the (unchanged) receiver.
  #[test]
  fn reassemble_multi_fragment_datafrag() {
    let frag_size = 1024u16;
    let data_size = 2600u32; // 3 fragments: 1024, 1024, 552
    let whole: Vec<u8> = (0..data_size as usize).map(|i| (i % 251) as u8).collect();

    // First submessage packs fragments 1 and 2 (K = 2, 2048 payload bytes).
    let first = datafrag(1, 2, frag_size, data_size, whole[0..2048].to_vec());
    let mut ab = AssemblyBuffer::new(&first, usize::MAX).expect("valid first fragment");
    assert!(!ab.is_complete());
    assert!(ab.insert_frags(&first));
    assert!(!ab.is_complete(), "still missing the tail fragment");

    // Trailing submessage carries the shorter final fragment 3 (552 bytes).
    let tail = datafrag(3, 1, frag_size, data_size, whole[2048..2600].to_vec());
    assert!(ab.insert_frags(&tail));
    assert!(ab.is_complete(), "all fragments received");
    assert_eq!(
      &ab.into_bytes().expect("complete")[..],
      &whole[..],
      "reassembled bytes must match the original sample"
    );
  }

  // A single DATAFRAG carrying the whole sample in one multi-fragment run.
  #[test]
  fn reassemble_single_submessage_all_fragments() {
    let frag_size = 512u16;
    let data_size = 1500u32; // 3 fragments: 512, 512, 476
    let whole: Vec<u8> = (0..data_size as usize).map(|i| (i % 97) as u8).collect();

    let all = datafrag(1, 3, frag_size, data_size, whole.clone());
    let mut ab = AssemblyBuffer::new(&all, usize::MAX).expect("valid fragment set");
    assert!(ab.insert_frags(&all));
    assert!(ab.is_complete());
    assert_eq!(&ab.into_bytes().expect("complete")[..], &whole[..]);
  }

  // Malformed span (starting at last fragment but claiming multiple fragments)
  // must not panic and must not falsely complete reassembly.
  #[test]
  fn reject_fragment_span_beyond_total() {
    let frag_size = 256u16;
    let data_size = 512u32; // 2 fragments total
    let bad = datafrag(2, 2, frag_size, data_size, vec![0u8; 256]);
    let mut ab = AssemblyBuffer::new(&bad, usize::MAX).expect("buffer for valid data_size");
    assert!(!ab.insert_frags(&bad));
    assert!(!ab.is_complete());
  }

  #[test]
  fn fragment_assembler_rejects_span_beyond_total() {
    use enumflags2::BitFlags;

    use super::FragmentAssembler;
    use crate::messages::submessages::submessages::DATAFRAG_Flags;

    let frag_size = 256u16;
    let data_size = 512u32;
    let bad = datafrag(2, 2, frag_size, data_size, vec![0u8; 256]);
    let mut fa = FragmentAssembler::new(true);
    assert!(fa
      .new_datafrag(&bad, BitFlags::<DATAFRAG_Flags>::empty(), usize::MAX)
      .is_none());
  }

  // A DATAFRAG declaring a sample larger than the limit allocates nothing
  // (issue: one ~100-byte packet declaring 4 GiB made the reader allocate
  // 4 GiB).
  #[test]
  fn declared_size_over_limit_is_refused() {
    use enumflags2::BitFlags;

    use super::FragmentAssembler;
    use crate::messages::submessages::submessages::DATAFRAG_Flags;

    for data_size in [1u32 << 30, u32::MAX] {
      let huge = datafrag(1, 1, 1024, data_size, vec![0u8; 1024]);
      assert!(AssemblyBuffer::new(&huge, 64 << 20).is_none());
      let mut fa = FragmentAssembler::new(false);
      assert!(fa
        .new_datafrag(&huge, BitFlags::<DATAFRAG_Flags>::empty(), 64 << 20)
        .is_none());
      assert!(fa.is_empty());
    }
  }

  // Within the limit, memory follows the fragments that arrived, not the
  // declared size.
  #[test]
  fn memory_follows_received_fragments() {
    let frag_size = 1024u16;
    let data_size = 60u32 << 20; // 60 MiB declared
    let one = datafrag(7, 1, frag_size, data_size, vec![1u8; 1024]);
    let mut ab = AssemblyBuffer::new(&one, 64 << 20).expect("within limit");
    assert!(ab.insert_frags(&one));
    assert!(ab.charged_bytes < 4096, "charged {}", ab.charged_bytes);
    assert!(!ab.is_complete());
    let missing: usize = ab.missing_frags().iter().map(|(a, b)| b - a).sum();
    assert_eq!(missing, ab.fragment_count - 1);
  }

  // A run shorter than its fragments claim is refused (it would be delivered
  // zero-filled); submessage padding after the last fragment is accepted.
  #[test]
  fn short_runs_are_refused_and_padding_accepted() {
    let short = datafrag(1, 2, 256, 600, vec![0u8; 300]);
    let mut ab = AssemblyBuffer::new(&short, usize::MAX).expect("valid");
    assert!(!ab.insert_frags(&short));
    let padded = datafrag(3, 1, 256, 600, vec![9u8; 88 + 3]);
    assert!(ab.insert_frags(&padded));
    assert_eq!(ab.received_fragments, 1);
  }

  // Overlapping and repeated runs store each fragment once and reassemble the
  // original bytes.
  #[test]
  fn overlapping_runs_reassemble_once() {
    let frag_size = 100u16;
    let data_size = 450u32; // 5 fragments
    let whole: Vec<u8> = (0..data_size as usize).map(|i| (i % 211) as u8).collect();
    let mut ab = AssemblyBuffer::new(
      &datafrag(2, 2, frag_size, data_size, whole[100..300].to_vec()),
      usize::MAX,
    )
    .expect("valid");
    for (start, k) in [(2u32, 2u16), (2, 2), (1, 3), (3, 3)] {
      let from = (start as usize - 1) * 100;
      let to = std::cmp::min(from + k as usize * 100, data_size as usize);
      assert!(ab.insert_frags(&datafrag(
        start,
        k,
        frag_size,
        data_size,
        whole[from..to].to_vec()
      )));
    }
    assert_eq!(ab.received_fragments, 5);
    assert!(ab.is_complete());
    assert_eq!(&ab.into_bytes().expect("complete")[..], &whole[..]);
  }

  // A different fragment or data size for the same sample is refused.
  #[test]
  fn inconsistent_sizes_are_refused() {
    let a = datafrag(1, 1, 256, 1000, vec![0u8; 256]);
    let mut ab = AssemblyBuffer::new(&a, usize::MAX).expect("valid");
    assert!(!ab.insert_frags(&datafrag(2, 1, 128, 1000, vec![0u8; 128])));
    assert!(!ab.insert_frags(&datafrag(2, 1, 256, 2000, vec![0u8; 256])));
  }
}
