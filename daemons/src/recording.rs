//! The one reader of Sextant recordings: [`Recording::open`] walks an MCAP file record by record
//! (no summary or index needed, so a file cut short by a crash reads up to its last complete
//! chunk) and yields typed [`Entry`]s — the recorder's [`Record`] enum with log time, publish
//! time, sequence and topic — in file order, which is the order the fusion daemon pushed its
//! inputs into the engine (see [`crate::recorder`] for the layout).
//!
//! Corruption and truncation are typed errors naming the byte offset of the record that could
//! not be read and what was wrong ([`RecordingError`]). Every record before it has been yielded
//! already: the iterator yields `Ok` entries, then at most one `Err`, then ends. A chunk is
//! released only after it decompressed completely and its CRC matched, so a flipped byte never
//! produces a plausible but wrong record.
//!
//! The configuration the fusion ran with is the MCAP metadata record
//! [`crate::recorder::CONFIG_METADATA_NAME`], read by `open` (it precedes every chunk), and so
//! is the time base of log and publish times ([`crate::recorder::TIME_METADATA_NAME`]; a file
//! without it is of the earlier convention, [`TimeBase::GpsMonotonic`]). Readers that need a
//! time of validity take it from the message's own header (GPS time, the same in every
//! convention); [`Entry::receive_mono_ns`] gives the reception time on CLOCK_MONOTONIC in
//! either convention.
//!
//! A recording of several segments (`recording.mcap`, `recording.part2.mcap`, …; see
//! [`crate::recorder`]) reads as one stream: when a file ends complete and the next segment
//! exists, the iterator goes on in it ([`segments_of`] lists them). A file cut short ends the
//! stream there, as it always did.

use msgs::{Record, RecordKind};
use std::collections::{BTreeMap, HashMap, HashSet, VecDeque};
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The 8 magic bytes at the start and end of an MCAP file.
pub const MCAP_MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// Largest record accepted, bytes: far above any chunk the recorder writes (1 MiB uncompressed
/// by default), small enough that a corrupted length never makes us allocate the address space.
const MAX_RECORD_LEN: u64 = 1 << 30;

/// Errors of the recording reader. `offset` is the byte offset in the file of the record that
/// could not be read (for a record inside a chunk: the offset of the chunk).
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// The file could not be opened or read.
    #[error("cannot read recording {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file does not start with the MCAP magic.
    #[error("{path} is not an MCAP file: {detail}")]
    NotMcap {
        /// The file.
        path: PathBuf,
        /// What was found.
        detail: String,
    },
    /// The file ends in the middle of a record or before the footer (crash, copy cut short).
    #[error("{path} is truncated at byte offset {offset}: {detail}")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Offset of the incomplete record.
        offset: u64,
        /// What was expected.
        detail: String,
    },
    /// A record is malformed (bad length, opcode, CRC, compression, JSON or protobuf, unknown
    /// channel).
    #[error("{path} is corrupt at byte offset {offset}: {detail}")]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// Offset of the malformed record (or of the chunk containing it).
        offset: u64,
        /// What was wrong.
        detail: String,
    },
    /// The reading thread of [`Recording::read_ahead`] could not be started.
    #[error("cannot start the recording's reading thread: {0}")]
    Thread(String),
}

impl RecordingError {
    /// The byte offset named by the error, if any.
    pub fn offset(&self) -> Option<u64> {
        match self {
            Self::Truncated { offset, .. } | Self::Corrupt { offset, .. } => Some(*offset),
            Self::Io { .. } | Self::NotMcap { .. } | Self::Thread(_) => None,
        }
    }
}

/// The time base of a recording's MCAP log and publish times.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimeBase {
    /// MCAP's and Foxglove's convention: log_time = Unix ns (UTC) of the time of validity,
    /// publish_time = Unix ns (UTC wall clock) of reception, or = log_time when not known.
    Unix {
        /// CLOCK_REALTIME − CLOCK_MONOTONIC of the recording, ns.
        unix_minus_monotonic_ns: i64,
    },
    /// Recordings written before it (no [`crate::recorder::TIME_METADATA_NAME`] record):
    /// log_time = GPS ns of validity, publish_time = CLOCK_MONOTONIC ns of reception (0 when
    /// not known).
    GpsMonotonic,
}

impl TimeBase {
    /// The time base stated by a recording's metadata records.
    pub fn from_metadata(metadata: &BTreeMap<String, BTreeMap<String, String>>) -> Self {
        use crate::recorder::{
            TIME_CONVENTION_UNIX, TIME_KEY_CONVENTION, TIME_KEY_UNIX_MINUS_MONOTONIC,
            TIME_METADATA_NAME,
        };
        let Some(m) = metadata.get(TIME_METADATA_NAME) else {
            return Self::GpsMonotonic;
        };
        if m.get(TIME_KEY_CONVENTION).map(String::as_str) != Some(TIME_CONVENTION_UNIX) {
            return Self::GpsMonotonic;
        }
        Self::Unix {
            unix_minus_monotonic_ns: m
                .get(TIME_KEY_UNIX_MINUS_MONOTONIC)
                .and_then(|v| v.parse().ok())
                .unwrap_or(0),
        }
    }

    /// CLOCK_MONOTONIC reception time of a message with these log and publish times, ns; 0
    /// when the recording does not know it.
    pub fn receive_mono_ns(&self, log_time_ns: u64, publish_time_ns: u64) -> u64 {
        match *self {
            Self::GpsMonotonic => publish_time_ns,
            Self::Unix {
                unix_minus_monotonic_ns,
            } => {
                if publish_time_ns == log_time_ns {
                    return 0;
                }
                let mono = i128::from(publish_time_ns) - i128::from(unix_minus_monotonic_ns);
                u64::try_from(mono).unwrap_or(0)
            }
        }
    }
}

/// One message of a recording.
#[derive(Debug, Clone)]
pub struct Entry {
    /// Byte offset of the message record, or of the chunk containing it, counted over the
    /// recording's segments (the sizes of the earlier segments plus the offset in this one):
    /// the reader's progress through [`recording_len`] bytes.
    pub offset: u64,
    /// MCAP log time, ns: the time of validity as Unix time (UTC), or GPS time in recordings
    /// of [`TimeBase::GpsMonotonic`].
    pub log_time_ns: u64,
    /// MCAP publish time, ns: the UTC wall time at which the daemon received or produced the
    /// message, or CLOCK_MONOTONIC in recordings of [`TimeBase::GpsMonotonic`].
    pub publish_time_ns: u64,
    /// CLOCK_MONOTONIC when the daemon received or produced the message, ns (0 when not
    /// known), whatever the time base.
    pub receive_mono_ns: u64,
    /// MCAP sequence (low 32 bits of the header's sequence number).
    pub sequence: u32,
    /// The topic.
    pub topic: Arc<str>,
    /// The decoded message; `None` for topics that are views of others (Foxglove schemas) or
    /// unknown to this version.
    pub record: Option<Record>,
}

#[derive(Debug, Clone)]
struct ChannelInfo {
    topic: Arc<str>,
    /// `None` for a topic that holds no [`Record`] (Foxglove views, non-finite inputs, topics
    /// of other versions).
    kind: Option<RecordKind>,
    /// The channel's message encoding: protobuf (true) or JSON.
    protobuf: bool,
}

/// Everything [`Recording::read_to_end`] could read.
#[derive(Debug, Default)]
pub struct ReadOutcome {
    /// The entries read, in file order.
    pub entries: Vec<Entry>,
    /// The error that stopped reading, if the file is truncated or corrupt.
    pub error: Option<RecordingError>,
}

/// A recording opened for reading; iterate it for its entries.
pub struct Recording {
    path: PathBuf,
    reader: BufReader<File>,
    file_len: u64,
    offset: u64,
    metadata: BTreeMap<String, BTreeMap<String, String>>,
    /// Time base, from the metadata (read before any message).
    time_base: TimeBase,
    channels: HashMap<u16, ChannelInfo>,
    schemas: HashMap<u16, String>,
    pending: VecDeque<Entry>,
    done: bool,
    /// An error met while reading the leading metadata, reported by the iterator.
    deferred: Option<RecordingError>,
    /// Footer seen and the end magic verified.
    complete: bool,
    /// File offsets of the chunks read from the data section, checked against the summary's
    /// chunk index: a chunk whose opcode was damaged into another valid record type would
    /// otherwise vanish without a word.
    chunks_read: HashSet<u64>,
    /// The recording's first file (the stem of its segments).
    first_path: PathBuf,
    /// Number of the segment read now (1: the first file).
    segment: usize,
    /// Total size of the segments before the one read now, bytes.
    segments_before_len: u64,
    /// Read this file only ([`Recording::open_file`]).
    single_file: bool,
}

/// Size of the recording whose first file is `first`, over all its segments, bytes.
pub fn recording_len(first: &Path) -> u64 {
    segments_of(first)
        .iter()
        .filter_map(|p| std::fs::metadata(p).ok())
        .map(|m| m.len())
        .sum()
}

/// The segments of the recording whose first file is `first`: `first`, then
/// `recording.part2.mcap`, `recording.part3.mcap`, … as long as they exist.
pub fn segments_of(first: &Path) -> Vec<PathBuf> {
    let mut v = vec![first.to_path_buf()];
    for n in 2.. {
        let p = crate::recorder::segment_path(first, n);
        if !p.is_file() {
            break;
        }
        v.push(p);
    }
    v
}

impl std::fmt::Debug for Recording {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recording")
            .field("path", &self.path)
            .field("offset", &self.offset)
            .finish_non_exhaustive()
    }
}

enum Step {
    /// A record was consumed (maybe queuing entries).
    Continue,
    /// The footer and end magic were read: the file is complete.
    End,
}

impl Recording {
    /// Open `path`, check the magic and read the metadata records that precede the data.
    pub fn open(path: &Path) -> Result<Self, RecordingError> {
        let io = |source| RecordingError::Io {
            path: path.to_path_buf(),
            source,
        };
        let file = File::open(path).map_err(io)?;
        let file_len = file.metadata().map_err(io)?.len();
        let mut reader = BufReader::with_capacity(1 << 16, file);
        let mut magic = [0u8; 8];
        let n = read_up_to(&mut reader, &mut magic).map_err(io)?;
        if n < 8 || &magic != MCAP_MAGIC {
            return Err(RecordingError::NotMcap {
                path: path.to_path_buf(),
                detail: format!(
                    "the first {n} bytes are {:02x?}, not the MCAP magic",
                    &magic[..n]
                ),
            });
        }
        let mut rec = Self {
            path: path.to_path_buf(),
            reader,
            file_len,
            offset: 8,
            metadata: BTreeMap::new(),
            time_base: TimeBase::GpsMonotonic,
            channels: HashMap::new(),
            schemas: HashMap::new(),
            pending: VecDeque::new(),
            done: false,
            deferred: None,
            complete: false,
            chunks_read: HashSet::new(),
            first_path: path.to_path_buf(),
            segment: 1,
            segments_before_len: 0,
            single_file: false,
        };
        // Header and metadata precede every chunk: read them now, stop at the first other
        // record. An error here is reported by the iterator, like any other.
        loop {
            match rec.peek_header() {
                Ok(Some((opcode, _))) if opcode == op::HEADER || opcode == op::METADATA => {
                    if let Err(e) = rec.step() {
                        rec.deferred = Some(e);
                        break;
                    }
                }
                Ok(_) => break,
                Err(e) => {
                    rec.deferred = Some(e);
                    break;
                }
            }
        }
        rec.time_base = TimeBase::from_metadata(&rec.metadata);
        Ok(rec)
    }

    /// The time base of the log and publish times.
    pub fn time_base(&self) -> TimeBase {
        self.time_base
    }

    /// The file being read (the first segment until the reader moves on to the next).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Like [`Recording::open`], but the iterator ends with this file, never going on into the
    /// recording's next segment (a reader that takes the segments one by one).
    pub fn open_file(path: &Path) -> Result<Self, RecordingError> {
        let mut r = Self::open(path)?;
        r.single_file = true;
        Ok(r)
    }

    /// Continue in the next segment, when the file just finished complete and it exists:
    /// its channels and schemas replace the finished file's; the first file's metadata and
    /// time base stay (every segment carries the same).
    fn next_segment(&mut self) -> Option<Result<(), RecordingError>> {
        let next = crate::recorder::segment_path(&self.first_path, self.segment + 1);
        if self.single_file || !next.is_file() {
            return None;
        }
        let r = match Recording::open(&next) {
            Ok(r) => r,
            Err(e) => return Some(Err(e)),
        };
        self.segment += 1;
        self.segments_before_len += self.file_len;
        self.path = r.path;
        self.reader = r.reader;
        self.file_len = r.file_len;
        self.offset = r.offset;
        self.channels = r.channels;
        self.schemas = r.schemas;
        self.pending = r.pending;
        self.deferred = r.deferred;
        self.complete = false;
        self.chunks_read = r.chunks_read;
        Some(Ok(()))
    }

    /// Metadata records read so far (all of them once `open` returned, for Sextant files).
    pub fn metadata(&self) -> &BTreeMap<String, BTreeMap<String, String>> {
        &self.metadata
    }

    /// True once the footer and the closing magic have been read (a finished recording).
    pub fn is_complete(&self) -> bool {
        self.complete
    }

    /// Read every remaining entry; a truncated or corrupt file gives what was readable and the
    /// error.
    pub fn read_to_end(mut self) -> ReadOutcome {
        let mut out = ReadOutcome::default();
        for e in &mut self {
            match e {
                Ok(e) => out.entries.push(e),
                Err(e) => out.error = Some(e),
            }
        }
        out
    }

    fn truncated(&self, offset: u64, detail: String) -> RecordingError {
        RecordingError::Truncated {
            path: self.path.clone(),
            offset,
            detail,
        }
    }

    fn corrupt(&self, offset: u64, detail: impl Into<String>) -> RecordingError {
        RecordingError::Corrupt {
            path: self.path.clone(),
            offset,
            detail: detail.into(),
        }
    }

    /// Opcode and length of the next record without consuming it; `None` at the end of file.
    fn peek_header(&mut self) -> Result<Option<(u8, u64)>, RecordingError> {
        let at = self.offset;
        let Some((op, len)) = self.read_record_header()? else {
            return Ok(None);
        };
        self.reader
            .seek(SeekFrom::Start(at))
            .map_err(|source| RecordingError::Io {
                path: self.path.clone(),
                source,
            })?;
        self.offset = at;
        Ok(Some((op, len)))
    }

    fn read_record_header(&mut self) -> Result<Option<(u8, u64)>, RecordingError> {
        let at = self.offset;
        if at == self.file_len {
            return Ok(None);
        }
        let mut h = [0u8; 9];
        let n = read_up_to(&mut self.reader, &mut h).map_err(|source| RecordingError::Io {
            path: self.path.clone(),
            source,
        })?;
        if n < 9 {
            return Err(self.truncated(
                at,
                format!(
                    "{n} bytes left where a 9-byte record header (opcode, length) was expected"
                ),
            ));
        }
        self.offset += 9;
        let len = u64::from_le_bytes(h[1..9].try_into().unwrap_or([0; 8]));
        Ok(Some((h[0], len)))
    }

    /// Consume one top-level record.
    fn step(&mut self) -> Result<Step, RecordingError> {
        let at = self.offset;
        let Some((opcode, len)) = self.read_record_header()? else {
            return Err(self.truncated(
                at,
                "end of file without a footer and closing magic (recording not finished)".into(),
            ));
        };
        let known = (op::HEADER..=op::DATA_END).contains(&opcode);
        let left = self.file_len - self.offset;
        if len > left {
            // A length beyond the file is a cut-short file when opcode and length are plausible,
            // otherwise a corrupted header.
            if known && len <= MAX_RECORD_LEN {
                return Err(self.truncated(
                    at,
                    format!(
                        "record opcode 0x{opcode:02x} of {len} bytes, only {left} bytes left in the file"
                    ),
                ));
            }
            return Err(self.corrupt(
                at,
                format!("record opcode 0x{opcode:02x} claims {len} bytes, only {left} left"),
            ));
        }
        if !known {
            return Err(self.corrupt(at, format!("unknown record opcode 0x{opcode:02x}")));
        }
        if len > MAX_RECORD_LEN {
            return Err(self.corrupt(at, format!("record length {len} bytes is implausible")));
        }
        let mut body = vec![0u8; len as usize];
        self.reader
            .read_exact(&mut body)
            .map_err(|source| RecordingError::Io {
                path: self.path.clone(),
                source,
            })?;
        self.offset += len;
        let what = |e: String| format!("record opcode 0x{opcode:02x} ({len} bytes): {e}");
        match opcode {
            op::FOOTER => {
                let mut c = Cur::new(&body);
                c.u64()
                    .and_then(|_| c.u64())
                    .and_then(|_| c.u32())
                    .map_err(|e| self.corrupt(at, what(e)))?;
                let mut magic = [0u8; 8];
                let n = read_up_to(&mut self.reader, &mut magic).map_err(|source| {
                    RecordingError::Io {
                        path: self.path.clone(),
                        source,
                    }
                })?;
                let end = self.offset;
                if n < 8 {
                    return Err(self.truncated(end, "closing magic cut short".into()));
                }
                if &magic != MCAP_MAGIC {
                    return Err(self.corrupt(end, "bad closing magic after the footer"));
                }
                self.offset += 8;
                if self.offset != self.file_len {
                    return Err(self.corrupt(
                        self.offset,
                        format!(
                            "{} bytes after the closing magic",
                            self.file_len - self.offset
                        ),
                    ));
                }
                self.complete = true;
                return Ok(Step::End);
            }
            op::HEADER => {
                let mut c = Cur::new(&body);
                c.string()
                    .and_then(|_| c.string())
                    .map_err(|e| self.corrupt(at, what(e)))?;
            }
            op::METADATA => {
                let mut c = Cur::new(&body);
                let name = c.string().map_err(|e| self.corrupt(at, what(e)))?;
                let map = c.map().map_err(|e| self.corrupt(at, what(e)))?;
                self.metadata.insert(name, map);
            }
            op::CHUNK => {
                let data = self
                    .decompress_chunk(&body)
                    .map_err(|e| self.corrupt(at, what(e)))?;
                // Decode the whole chunk before releasing any of it (its CRC was checked): a
                // bad message takes back the chunk's entries decoded before it. Decoded
                // straight into the queue, as an entry is ≈ 0.6 kB to move.
                let released = self.pending.len();
                let mut p = 0usize;
                while p < data.len() {
                    let decoded = inner_record(&data, p)
                        .and_then(|(iop, ibody, next)| Ok((self.inner(iop, ibody, at)?, next)));
                    match decoded {
                        Ok((entry, next)) => {
                            self.pending.extend(entry);
                            p = next;
                        }
                        Err(e) => {
                            self.pending.truncate(released);
                            return Err(
                                self.corrupt(at, format!("chunk, uncompressed offset {p}: {e}"))
                            );
                        }
                    }
                }
                self.chunks_read.insert(at);
            }
            op::CHUNK_INDEX => {
                let mut c = Cur::new(&body);
                let chunk_at = c
                    .u64()
                    .and_then(|_| c.u64())
                    .and_then(|_| c.u64())
                    .map_err(|e| self.corrupt(at, what(e)))?;
                if !self.chunks_read.contains(&chunk_at) {
                    return Err(self.corrupt(
                        at,
                        format!(
                            "the summary's chunk index lists a chunk at offset {chunk_at} that the data section does not hold as a chunk (its messages were not read)"
                        ),
                    ));
                }
            }
            op::SCHEMA | op::CHANNEL | op::MESSAGE => {
                if let Some(e) = self
                    .inner(opcode, &body, at)
                    .map_err(|e| self.corrupt(at, what(e)))?
                {
                    self.pending.push_back(e);
                }
            }
            // Indexes, attachments, statistics, summary offsets, data end: nothing we need.
            _ => {}
        }
        Ok(Step::Continue)
    }

    /// Decompress and CRC-check a chunk record's body.
    fn decompress_chunk(&self, body: &[u8]) -> Result<Vec<u8>, String> {
        let mut c = Cur::new(body);
        let _start = c.u64()?;
        let _end = c.u64()?;
        let uncompressed_size = c.u64()?;
        let crc = c.u32()?;
        let compression = c.string()?;
        let compressed_size = c.u64()?;
        let data = c.bytes(compressed_size)?;
        if uncompressed_size > MAX_CHUNK_LEN {
            return Err(format!(
                "chunk claims {uncompressed_size} bytes uncompressed (limit {MAX_CHUNK_LEN})"
            ));
        }
        let out = match compression.as_str() {
            "" => data.to_vec(),
            "zstd" => zstd::bulk::decompress(data, uncompressed_size as usize)
                .map_err(|e| format!("zstd: {e}"))?,
            other => return Err(format!("unsupported chunk compression {other:?}")),
        };
        if out.len() as u64 != uncompressed_size {
            return Err(format!(
                "chunk decompressed to {} bytes, header says {uncompressed_size}",
                out.len()
            ));
        }
        if crc != 0 {
            let calc = crc32fast::hash(&out);
            if calc != crc {
                return Err(format!(
                    "chunk CRC mismatch: stored 0x{crc:08x}, computed 0x{calc:08x}"
                ));
            }
        }
        Ok(out)
    }

    /// Handle a schema, channel or message record (top level or inside a chunk at `at`).
    fn inner(&mut self, opcode: u8, body: &[u8], at: u64) -> Result<Option<Entry>, String> {
        let mut c = Cur::new(body);
        match opcode {
            op::SCHEMA => {
                let id = c.u16()?;
                let name = c.string()?;
                let _encoding = c.string()?;
                let n = c.u32()?;
                c.bytes(u64::from(n))?;
                self.schemas.insert(id, name);
                Ok(None)
            }
            op::CHANNEL => {
                let id = c.u16()?;
                let schema_id = c.u16()?;
                let topic = c.string()?;
                let encoding = c.string()?;
                let _meta = c.map()?;
                if schema_id != 0 && !self.schemas.contains_key(&schema_id) {
                    return Err(format!(
                        "channel {topic} refers to unknown schema {schema_id}"
                    ));
                }
                let kind = RecordKind::from_topic(&topic);
                let protobuf = match encoding.as_str() {
                    msgs::protobuf::ENCODING => true,
                    "json" => false,
                    // A topic of ours in an encoding this version cannot read is an error;
                    // any other topic is a view (or a later version's) and is passed over.
                    other if kind.is_some() => {
                        return Err(format!(
                            "channel {topic} has message encoding {other:?} (this version reads protobuf and json)"
                        ));
                    }
                    _ => false,
                };
                self.channels.insert(
                    id,
                    ChannelInfo {
                        topic: topic.into(),
                        kind,
                        protobuf,
                    },
                );
                Ok(None)
            }
            op::MESSAGE => {
                let channel_id = c.u16()?;
                let sequence = c.u32()?;
                let log_time_ns = c.u64()?;
                let publish_time_ns = c.u64()?;
                let data = c.rest();
                let Some(ch) = self.channels.get(&channel_id) else {
                    return Err(format!("message on unknown channel id {channel_id}"));
                };
                let (topic, kind) = (ch.topic.clone(), ch.kind);
                let record = match kind {
                    None => None,
                    Some(k) if ch.protobuf => Some(
                        Record::from_protobuf(k, data)
                            .map_err(|e| format!("message on topic {topic}: bad protobuf: {e}"))?,
                    ),
                    Some(k) => Some(
                        Record::from_json(k, data)
                            .map_err(|e| format!("message on topic {topic}: bad JSON: {e}"))?,
                    ),
                };
                Ok(Some(Entry {
                    offset: self.segments_before_len + at,
                    log_time_ns,
                    publish_time_ns,
                    receive_mono_ns: self.time_base.receive_mono_ns(log_time_ns, publish_time_ns),
                    sequence,
                    topic,
                    record,
                }))
            }
            // Anything else inside a chunk is not allowed by the MCAP spec.
            other => Err(format!("record opcode 0x{other:02x} inside a chunk")),
        }
    }
}

/// MCAP opcodes (spec: https://mcap.dev/spec).
mod op {
    pub const HEADER: u8 = 0x01;
    pub const FOOTER: u8 = 0x02;
    pub const SCHEMA: u8 = 0x03;
    pub const CHANNEL: u8 = 0x04;
    pub const MESSAGE: u8 = 0x05;
    pub const CHUNK: u8 = 0x06;
    pub const CHUNK_INDEX: u8 = 0x08;
    pub const METADATA: u8 = 0x0C;
    pub const DATA_END: u8 = 0x0F;
}

/// Largest uncompressed chunk accepted, bytes (the recorder's default is 1 MiB).
const MAX_CHUNK_LEN: u64 = 256 << 20;

/// The record at `p` of a chunk's uncompressed data: opcode, body, offset of the next record.
fn inner_record(data: &[u8], p: usize) -> Result<(u8, &[u8], usize), String> {
    let left = data.len() - p;
    if left < 9 {
        return Err(format!(
            "{left} bytes left where a record header was expected"
        ));
    }
    let opcode = data[p];
    let mut c = Cur::new(&data[p + 1..p + 9]);
    let len = c.u64()?;
    if len > (left - 9) as u64 {
        return Err(format!(
            "record opcode 0x{opcode:02x} claims {len} bytes, {} left in the chunk",
            left - 9
        ));
    }
    let start = p + 9;
    let end = start + len as usize;
    Ok((opcode, &data[start..end], end))
}

/// Bounds-checked little-endian cursor over a record body (MCAP's primitive types).
struct Cur<'a> {
    b: &'a [u8],
    p: usize,
}

impl<'a> Cur<'a> {
    fn new(b: &'a [u8]) -> Self {
        Self { b, p: 0 }
    }
    fn bytes(&mut self, n: u64) -> Result<&'a [u8], String> {
        let left = self.b.len() - self.p;
        if n > left as u64 {
            return Err(format!(
                "field of {n} bytes at body offset {}, only {left} left",
                self.p
            ));
        }
        let s = &self.b[self.p..self.p + n as usize];
        self.p += n as usize;
        Ok(s)
    }
    fn u16(&mut self) -> Result<u16, String> {
        let b = self.bytes(2)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }
    fn u32(&mut self) -> Result<u32, String> {
        let b = self.bytes(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
    fn u64(&mut self) -> Result<u64, String> {
        let b = self.bytes(8)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(u64::from_le_bytes(a))
    }
    fn string(&mut self) -> Result<String, String> {
        let n = self.u32()?;
        let at = self.p;
        let b = self.bytes(u64::from(n))?;
        String::from_utf8(b.to_vec())
            .map_err(|_| format!("string at body offset {at} is not UTF-8"))
    }
    fn map(&mut self) -> Result<BTreeMap<String, String>, String> {
        let n = self.u32()?;
        let body = self.bytes(u64::from(n))?;
        let mut c = Cur::new(body);
        let mut m = BTreeMap::new();
        while c.p < body.len() {
            let k = c.string()?;
            let v = c.string()?;
            m.insert(k, v);
        }
        Ok(m)
    }
    fn rest(&mut self) -> &'a [u8] {
        let s = &self.b[self.p..];
        self.p = self.b.len();
        s
    }
}

impl Iterator for Recording {
    type Item = Result<Entry, RecordingError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(e) = self.pending.pop_front() {
                return Some(Ok(e));
            }
            if let Some(e) = self.deferred.take() {
                self.done = true;
                return Some(Err(e));
            }
            if self.done {
                return None;
            }
            match self.step() {
                Ok(Step::Continue) => {}
                Ok(Step::End) => match self.next_segment() {
                    Some(Ok(())) => {}
                    Some(Err(e)) => {
                        self.done = true;
                        return Some(Err(e));
                    }
                    None => self.done = true,
                },
                Err(e) => {
                    self.done = true;
                    return Some(Err(e));
                }
            }
        }
    }
}

/// Read into `buf` until it is full or the reader is exhausted; the number of bytes read.
fn read_up_to(r: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

/// Entries read ahead per hand-over between the reading thread and the caller: large enough
/// that the hand-over costs little per entry, small enough to keep the memory in flight small
/// (a few MB with the queue's depth).
const READ_AHEAD_BATCH: usize = 512;
/// Batches in flight between the reading thread and the caller.
const READ_AHEAD_DEPTH: usize = 4;

type Batch = Vec<Result<Entry, RecordingError>>;

/// A recording read on a thread of its own ([`Recording::read_ahead`]): decompressing and
/// decoding overlap the caller's work on the entries (`sextant replay --offline`'s filter).
/// The same entries in the same order as iterating the [`Recording`] itself, in bounded memory.
pub struct ReadAhead {
    rx: Option<std::sync::mpsc::Receiver<Batch>>,
    batch: std::vec::IntoIter<Result<Entry, RecordingError>>,
    thread: Option<std::thread::JoinHandle<Recording>>,
}

impl Recording {
    /// Read the rest of the recording on a thread of its own; iterate the returned reader, then
    /// take the recording back with [`ReadAhead::into_recording`] (e.g. for
    /// [`Recording::is_complete`]).
    pub fn read_ahead(mut self) -> ReadAhead {
        let (tx, rx) = std::sync::mpsc::sync_channel::<Batch>(READ_AHEAD_DEPTH);
        let thread = std::thread::Builder::new()
            .name("recording-reader".into())
            .spawn(move || {
                loop {
                    let batch: Batch = self.by_ref().take(READ_AHEAD_BATCH).collect();
                    // An empty batch is the end; a caller that stopped listening ends it too.
                    if batch.is_empty() || tx.send(batch).is_err() {
                        return self;
                    }
                }
            });
        match thread {
            Ok(t) => ReadAhead {
                rx: Some(rx),
                batch: Vec::new().into_iter(),
                thread: Some(t),
            },
            // No thread to be had: an error entry, rather than reading nothing in silence.
            Err(e) => ReadAhead {
                rx: None,
                batch: vec![Err(RecordingError::Thread(e.to_string()))].into_iter(),
                thread: None,
            },
        }
    }
}

impl Iterator for ReadAhead {
    type Item = Result<Entry, RecordingError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(e) = self.batch.next() {
                return Some(e);
            }
            let rx = self.rx.as_ref()?;
            match rx.recv() {
                Ok(b) => self.batch = b.into_iter(),
                Err(_) => {
                    self.rx = None;
                    return None;
                }
            }
        }
    }
}

impl ReadAhead {
    /// Stop reading (if not at the end) and return the recording, where the reading thread left
    /// it; `None` when the reading thread could not be started or panicked.
    pub fn into_recording(mut self) -> Option<Recording> {
        self.rx = None;
        self.thread.take().and_then(|t| t.join().ok())
    }
}

/// Open `path` and read all of it: the entries readable and the error that stopped reading.
/// Only a file that cannot be opened or is not MCAP at all is an `Err`.
pub fn read_all(path: &Path) -> Result<ReadOutcome, RecordingError> {
    Ok(Recording::open(path)?.read_to_end())
}

#[cfg(test)]
#[allow(clippy::field_reassign_with_default)]
mod tests {
    use super::*;
    use crate::recorder::{Recorder, RecorderOptions};
    use msgs::{ImuSample, NavSolution, SensorAliveEvent};
    use proptest::prelude::*;

    fn tmp(name: &str) -> PathBuf {
        let d =
            std::env::temp_dir().join(format!("sextant-recording-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d.join("recording.mcap")
    }

    /// A small recording with several chunks (64 kB chunk size) and the config metadata, the
    /// views of every solution.
    fn make_recording(name: &str) -> (PathBuf, Vec<Record>) {
        make_recording_in(name, crate::recorder::RecordingEncoding::default())
    }

    fn make_recording_in(
        name: &str,
        encoding: crate::recorder::RecordingEncoding,
    ) -> (PathBuf, Vec<Record>) {
        let path = tmp(name);
        let mut meta = BTreeMap::new();
        meta.insert("filter_toml".to_string(), "x = 1\n".to_string());
        let opts = RecorderOptions {
            chunk_size_bytes: 16 * 1024,
            metadata: vec![(crate::recorder::CONFIG_METADATA_NAME.into(), meta)],
            encoding,
            view_rate_hz: 0.0,
            ..Default::default()
        };
        let rec = Recorder::start(&path, &opts).unwrap();
        let mut records = Vec::new();
        for k in 1..=300i64 {
            let mut imu = ImuSample::default();
            imu.header.time_ns = k * 5_000_000;
            imu.header.seq = k as u64;
            // Values that need all 17 significant digits to round-trip.
            imu.delta_angle_rad = [0.1 / k as f64, -1.0 / 3.0, std::f64::consts::PI * k as f64];
            records.push(Record::Imu(imu));
            if k % 50 == 0 {
                records.push(Record::SensorAlive(SensorAliveEvent {
                    header: imu.header,
                    sensor: 2,
                    alive: k % 100 == 0,
                }));
            }
            let mut nav = NavSolution::default();
            nav.header = imu.header;
            nav.q_ned_body = [1.0, 0.0, 0.0, 0.0];
            nav.pos_ecef_m = [6378137.0 + 1e-9 * k as f64, 0.1, 0.2];
            records.push(Record::Nav(nav));
        }
        for r in &records {
            assert!(rec.record(r.clone(), 7));
        }
        let st = rec.finish().unwrap();
        assert_eq!(st.dropped, 0);
        (path, records)
    }

    fn same(a: &Record, b: &Record) -> bool {
        format!("{a:?}") == format!("{b:?}")
    }

    #[test]
    fn reads_back_every_record_bit_exact_with_metadata() {
        for encoding in [
            crate::recorder::RecordingEncoding::Protobuf,
            crate::recorder::RecordingEncoding::Json,
        ] {
            reads_back_bit_exact(encoding);
        }
    }

    fn reads_back_bit_exact(encoding: crate::recorder::RecordingEncoding) {
        let (path, records) = make_recording_in(&format!("roundtrip-{encoding:?}"), encoding);
        let rec = Recording::open(&path).unwrap();
        assert_eq!(
            rec.metadata()[crate::recorder::CONFIG_METADATA_NAME]["filter_toml"],
            "x = 1\n"
        );
        let out = rec.read_to_end();
        assert!(out.error.is_none(), "{:?}", out.error);
        let got: Vec<_> = out
            .entries
            .iter()
            .filter_map(|e| e.record.clone())
            .collect();
        assert_eq!(got.len(), records.len());
        for (a, b) in got.iter().zip(&records) {
            assert!(same(a, b), "{a:?} != {b:?}");
            if let (Record::Imu(a), Record::Imu(b)) = (a, b) {
                for i in 0..3 {
                    assert_eq!(
                        a.delta_angle_rad[i].to_bits(),
                        b.delta_angle_rad[i].to_bits()
                    );
                }
            }
        }
        // Foxglove views are entries without a record.
        assert_eq!(out.entries.len(), records.len() + 3 * 300);
        // Unix ns of GPS 5 ms (TAI − UTC = TAI − GPS at the GPS epoch); reception time 7 ns on
        // CLOCK_MONOTONIC comes back through the time base.
        assert_eq!(
            out.entries[0].log_time_ns,
            315_964_800_000_000_000 + 5_000_000
        );
        assert_eq!(out.entries[0].receive_mono_ns, 7);
    }

    #[test]
    fn not_mcap_and_missing_file_are_errors_naming_the_file() {
        let p = tmp("notmcap");
        std::fs::write(&p, b"hello world, not mcap").unwrap();
        let e = Recording::open(&p).unwrap_err().to_string();
        assert!(
            e.contains(&p.display().to_string()) && e.contains("not an MCAP"),
            "{e}"
        );
        let e = Recording::open(Path::new("/nonexistent/x.mcap"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("/nonexistent/x.mcap"), "{e}");
    }

    /// Number of records readable from `bytes` written to a file, and the error.
    fn read_bytes(path: &Path, bytes: &[u8]) -> Result<ReadOutcome, RecordingError> {
        std::fs::write(path, bytes).unwrap();
        read_all(path)
    }

    #[test]
    fn truncation_at_every_record_boundary_and_inside_keeps_the_prefix() {
        let (path, records) = make_recording("trunc");
        let full = std::fs::read(&path).unwrap();
        let cut = path.with_file_name("cut.mcap");
        let mut last = 0usize;
        // Every 97th offset plus the very last bytes: never a panic; an error naming an offset
        // within the file; the number of records read never decreases as the cut moves on.
        let mut offsets: Vec<usize> = (8..full.len()).step_by(97).collect();
        offsets.extend(full.len() - 9..full.len());
        for len in offsets {
            let out = read_bytes(&cut, &full[..len]).unwrap();
            let e = out.error.expect("truncated file must report an error");
            let off = e.offset().expect("offset");
            assert!(off <= len as u64, "{e}");
            assert!(e.to_string().contains("offset"), "{e}");
            let n = out.entries.iter().filter(|e| e.record.is_some()).count();
            assert!(n >= last, "cut at {len}: {n} records < {last}");
            // The prefix read is exactly the first n records written.
            for (a, b) in out
                .entries
                .iter()
                .filter_map(|e| e.record.as_ref())
                .zip(&records)
            {
                assert!(same(a, b));
            }
            last = n;
        }
        // Cut just before the summary: the whole data section is there.
        assert_eq!(last, records.len());
    }

    /// A chunk whose opcode is damaged into another valid record type (a message index) would
    /// be skipped as an index; the summary's chunk index (or the next chunk's unknown channel)
    /// exposes it, so the loss is an error naming an offset, never silent.
    #[test]
    fn chunk_damaged_into_an_index_record_is_an_error_not_a_silent_loss() {
        let (path, records) = make_recording("chunk-op");
        let full = std::fs::read(&path).unwrap();
        let mut at = 8usize;
        let mut chunks = Vec::new();
        while at + 9 <= full.len() && full[at] != op::DATA_END {
            if full[at] == op::CHUNK {
                chunks.push(at);
            }
            at += 9 + u64::from_le_bytes(full[at + 1..at + 9].try_into().unwrap()) as usize;
        }
        assert!(chunks.len() >= 3, "fixture has {} chunks", chunks.len());
        for &c in &chunks {
            let mut bytes = full.clone();
            bytes[c] = 0x07;
            let out = read_bytes(&path.with_file_name("chunk-op-damaged.mcap"), &bytes).unwrap();
            let n = out.entries.iter().filter(|e| e.record.is_some()).count();
            assert!(n < records.len());
            // Either the chunk index names it or, when it held a channel definition, the next
            // chunk's messages on that channel do.
            let e = out.error.expect("a hidden chunk must be reported");
            assert!(e.offset().unwrap() >= c as u64, "{e}");
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]
        /// Flipping any byte never panics; either the flip is harmless (padding, an index) and
        /// reading completes, or reading stops with an error naming an offset at or before the
        /// flipped byte's record, and every record returned is one that was written, in order.
        #[test]
        fn flipped_bytes_never_panic_and_never_invent_records(pos_frac in 0.0f64..1.0, bits in 1u8..=255) {
            let (path, records) = FIXTURE.get_or_init(|| make_recording("flip")).clone();
            let mut bytes = std::fs::read(&path).unwrap();
            let pos = 8 + ((bytes.len() - 8) as f64 * pos_frac) as usize;
            let pos = pos.min(bytes.len() - 1);
            bytes[pos] ^= bits;
            let p = path.with_file_name(format!("flip-{pos}-{bits}.mcap"));
            let out = read_bytes(&p, &bytes);
            let _ = std::fs::remove_file(&p);
            let out = match out { Ok(o) => o, Err(e) => { prop_assert!(e.to_string().contains("MCAP")); return Ok(()); } };
            if let Some(e) = &out.error {
                // The offset names where reading broke down: the flipped record itself, or
                // (a flipped length field) the misaligned record after it.
                prop_assert!(e.offset().is_some(), "{}", e);
                prop_assert!(e.offset().unwrap() <= bytes.len() as u64, "{} (flip at {})", e, pos);
            }
            // Every record returned was written, in order (a damaged chunk may be skipped, so
            // the records read are a subsequence); log/publish times live in the CRC-checked
            // chunk too, so each one is intact.
            let got: Vec<_> = out.entries.iter().filter_map(|e| e.record.as_ref()).collect();
            let mut written = records.iter();
            for a in &got {
                prop_assert!(written.any(|b| same(a, b)), "flip at {}: {:?} was not written (or is out of order)", pos, a);
            }
            // Nothing is lost without an error: a complete read returns every record.
            if out.error.is_none() {
                prop_assert_eq!(got.len(), records.len(), "flip at {}: records lost without an error", pos);
            }
        }
    }

    static FIXTURE: std::sync::OnceLock<(PathBuf, Vec<Record>)> = std::sync::OnceLock::new();
}
