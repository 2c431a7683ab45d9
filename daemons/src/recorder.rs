//! The recorder: an MCAP writer on its own thread, fed by the filter thread through a bounded
//! queue with `try_send`, so that a slow disk never blocks the filter. A record that does not fit
//! in the queue, or whose write fails, is counted in [`Recorder::dropped`] (reported as
//! `Status.records_dropped`), never silently lost.
//!
//! File layout:
//! - one channel per service, topic = channel name (`imu`, `star_tracker`, `gnss`, `odometer`,
//!   `baro`, `truth`, `nav`, `status`), message encoding `json`, schema encoding `jsonschema`
//!   with [`msgs::channel_schema`];
//! - the solution also on `nav/location_fix` (`foxglove.LocationFix`) and `nav/pose`
//!   (`foxglove.PoseInFrame`), see [`crate::foxglove`];
//! - **log_time = the message's time of validity, GPS ns** (not Unix time), so that a recording
//!   sorts by time of validity; **publish_time = CLOCK_MONOTONIC when the fusion daemon received
//!   (or, for its own outputs, produced) the message**, ns;
//! - MCAP message `sequence` = the header's sequence number (low 32 bits);
//! - inputs are recorded in the order they were pushed into the navigator, which is what offline
//!   replay needs to reproduce the live solution;
//! - zstd chunks, closed at the chunk size and at least every `flush_interval`, so that after a
//!   crash everything up to the last complete chunk is readable (read with
//!   `mcap::read::Options::IgnoreEndMagic`).
//!
//! A write that fails (full disk, I/O error) ends the current file: the MCAP writer's state is
//! undefined after an I/O error, and what reached the disk stays readable up to its last
//! complete chunk. The recorder then counts every record as dropped and, at most once per
//! [`RESUME_RETRY`], tries to open the next **segment** ([`segment_path`]:
//! `recording.part2.mcap`, `recording.part3.mcap`, …; each a complete MCAP with the metadata,
//! schemas and channels of the first), so that the recording resumes by itself when space
//! returns. [`Recorder::segments`] lists the files written.

use crate::foxglove;
use mcap::{WriteOptions, Writer};
use msgs::Channel;
/// What the recorder records: one message of any kind (see [`msgs::record`]).
pub use msgs::{Record, SENSOR_ALIVE_TOPIC, SensorAliveEvent};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Errors of the recorder.
#[derive(Debug, thiserror::Error)]
pub enum RecorderError {
    /// The output file could not be created.
    #[error("cannot create recording {path}: {source}")]
    Create {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The MCAP writer failed.
    #[error("MCAP error on {path}: {detail}")]
    Mcap {
        /// The file.
        path: PathBuf,
        /// The error.
        detail: String,
    },
    /// The writer thread could not be started or panicked.
    #[error("recorder thread: {0}")]
    Thread(String),
}

/// Topic of the records that hold a non-finite number (NaN, ±inf — bad input the filter
/// rejected). JSON has no encoding for them (serde_json would write `null`, which the channel's
/// schema and every reader reject), so such a record goes here instead of its own topic, as
/// `{"topic", "time_ns", "seq", "debug"}` with the whole message in Rust's `Debug` form, which
/// prints every float exactly (`NaN`, `inf`, shortest round-trip digits): nothing is lost and
/// the sensor topics stay schema-valid. Replay skips it; the filter rejected it anyway.
pub const NON_FINITE_TOPIC: &str = "fusion/non_finite_input";

/// JSON Schema of [`NON_FINITE_TOPIC`].
const NON_FINITE_SCHEMA: &str = r#"{"$schema":"https://json-schema.org/draft/2020-12/schema","title":"sextant::NonFiniteInput","type":"object","properties":{"topic":{"type":"string"},"time_ns":{"type":"integer"},"seq":{"type":"integer"},"debug":{"type":"string"}},"required":["topic","time_ns","seq","debug"]}"#;

/// Name of the MCAP metadata record holding the configuration the fusion ran with.
pub const CONFIG_METADATA_NAME: &str = "sextant/config";

/// Key (in [`CONFIG_METADATA_NAME`]) of the filter configuration, TOML as serialized from the
/// `NavigatorConfig` the engine was built with (authoritative for replay).
pub const CONFIG_KEY_FILTER_TOML: &str = "filter_toml";

/// An error with its sources (`MCAP I/O error: No space left on device (os error 28)`), so that
/// the operator sees the operating system's reason.
fn error_chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut src = e.source();
    while let Some(x) = src {
        let t = x.to_string();
        if !s.contains(&t) {
            s.push_str(": ");
            s.push_str(&t);
        }
        src = x.source();
    }
    s
}

/// Recorder settings.
#[derive(Debug, Clone)]
pub struct RecorderOptions {
    /// Queue capacity, records.
    pub queue_capacity: usize,
    /// Target uncompressed chunk size, bytes.
    pub chunk_size_bytes: u64,
    /// Close the current chunk at least this often.
    pub flush_interval: Duration,
    /// MCAP metadata records written first in the file (name, key/value map), e.g. the
    /// configuration under [`CONFIG_METADATA_NAME`].
    pub metadata: Vec<(String, BTreeMap<String, String>)>,
}

impl Default for RecorderOptions {
    fn default() -> Self {
        Self {
            queue_capacity: 16384,
            chunk_size_bytes: 1 << 20,
            flush_interval: Duration::from_secs(1),
            metadata: Vec::new(),
        }
    }
}

/// After a failed write, how often the recorder tries to open the next segment (wall time).
pub const RESUME_RETRY: Duration = Duration::from_secs(1);

/// The `n`-th segment of the recording `path` (n from 1): `path` itself, then
/// `<stem>.part<n>.<ext>` (`recording.mcap` → `recording.part2.mcap`), written after a failed
/// write once the disk accepts data again.
pub fn segment_path(path: &Path, n: usize) -> PathBuf {
    if n <= 1 {
        return path.to_path_buf();
    }
    let stem = path
        .file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    let name = match path.extension() {
        Some(ext) => format!("{stem}.part{n}.{}", ext.to_string_lossy()),
        None => format!("{stem}.part{n}"),
    };
    path.with_file_name(name)
}

#[derive(Default)]
struct Counters {
    written: AtomicU64,
    dropped: AtomicU64,
    errors: AtomicU64,
    /// Segments opened, in order.
    segments: Mutex<Vec<PathBuf>>,
}

impl Counters {
    fn add_segment(&self, path: &Path) {
        if let Ok(mut v) = self.segments.lock() {
            v.push(path.to_path_buf());
        }
    }
}

/// Totals of a finished recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RecorderStats {
    /// Messages written (including the Foxglove views of the solution).
    pub written: u64,
    /// Records dropped (queue full, write failed, or recording impossible).
    pub dropped: u64,
    /// Write errors (file could not be created, disk full, I/O error); each also drops records.
    pub errors: u64,
}

struct Item {
    record: Record,
    receive_mono_ns: u64,
}

/// Handle of the recorder thread, owned by the filter thread.
pub struct Recorder {
    tx: Option<SyncSender<Item>>,
    counters: Arc<Counters>,
    thread: Option<JoinHandle<Result<(), RecorderError>>>,
    path: PathBuf,
    failure: Option<String>,
}

struct Sink {
    writer: Writer<BufWriter<File>>,
    path: PathBuf,
    channels: BTreeMap<&'static str, u16>,
    location_fix: u16,
    pose: u16,
    ned_origin: Option<foxglove::NedOrigin>,
    sensor_alive: u16,
    non_finite: u16,
    buf: Vec<u8>,
    dirty: bool,
    /// Messages handed to the writer since the last successful flush: lost if the next flush
    /// fails (they sit in the in-memory chunk).
    unflushed: u64,
}

impl Sink {
    fn create(path: &Path, opts: &RecorderOptions) -> Result<Self, RecorderError> {
        let file = File::create(path).map_err(|source| RecorderError::Create {
            path: path.to_path_buf(),
            source,
        })?;
        Self::with_file(file, path, opts)
    }

    /// Open a further segment: a new file only (never one that exists), removed again when its
    /// header cannot be written (the disk is still full), so that failed attempts leave nothing.
    fn create_segment(path: &Path, opts: &RecorderOptions) -> Result<Self, RecorderError> {
        let file = File::options()
            .write(true)
            .create_new(true)
            .open(path)
            .map_err(|source| RecorderError::Create {
                path: path.to_path_buf(),
                source,
            })?;
        Self::with_file(file, path, opts).inspect_err(|_| {
            let _ = std::fs::remove_file(path);
        })
    }

    fn with_file(file: File, path: &Path, opts: &RecorderOptions) -> Result<Self, RecorderError> {
        let mcap_err = |e: mcap::McapError| RecorderError::Mcap {
            path: path.to_path_buf(),
            detail: error_chain(&e),
        };
        let mut writer = WriteOptions::new()
            .profile("")
            .library(concat!("sextant-daemons ", env!("CARGO_PKG_VERSION")))
            .compression(Some(mcap::Compression::Zstd))
            .compression_threads(0)
            .chunk_size(Some(opts.chunk_size_bytes))
            .create(BufWriter::new(file))
            .map_err(mcap_err)?;
        // Metadata first (top level, before any chunk), so that a reader has the configuration
        // before the first input.
        for (name, metadata) in &opts.metadata {
            writer
                .write_metadata(&mcap::records::Metadata {
                    name: name.clone(),
                    metadata: metadata.clone(),
                })
                .map_err(mcap_err)?;
        }
        let no_meta = BTreeMap::new();
        let mut channels = BTreeMap::new();
        for ch in Channel::ALL {
            let (name, schema) = msgs::channel_schema(ch);
            let sid = writer
                .add_schema(name, "jsonschema", schema.as_bytes())
                .map_err(mcap_err)?;
            let cid = writer
                .add_channel(sid, ch.name(), "json", &no_meta)
                .map_err(mcap_err)?;
            channels.insert(ch.name(), cid);
        }
        let sid = writer
            .add_schema(
                foxglove::LOCATION_FIX_SCHEMA,
                "jsonschema",
                foxglove::location_fix_schema().as_bytes(),
            )
            .map_err(mcap_err)?;
        let location_fix = writer
            .add_channel(sid, foxglove::LOCATION_FIX_TOPIC, "json", &no_meta)
            .map_err(mcap_err)?;
        let sid = writer
            .add_schema(
                foxglove::POSE_SCHEMA,
                "jsonschema",
                foxglove::pose_in_frame_schema().as_bytes(),
            )
            .map_err(mcap_err)?;
        let pose = writer
            .add_channel(sid, foxglove::POSE_TOPIC, "json", &no_meta)
            .map_err(mcap_err)?;
        let alive_schema = serde_json::to_string(&schemars::schema_for!(SensorAliveEvent))
            .map_err(|e| RecorderError::Mcap {
                path: path.to_path_buf(),
                detail: e.to_string(),
            })?;
        let sid = writer
            .add_schema(
                msgs::record::SENSOR_ALIVE_SCHEMA_NAME,
                "jsonschema",
                alive_schema.as_bytes(),
            )
            .map_err(mcap_err)?;
        let sensor_alive = writer
            .add_channel(sid, SENSOR_ALIVE_TOPIC, "json", &no_meta)
            .map_err(mcap_err)?;
        let sid = writer
            .add_schema(
                "sextant::NonFiniteInput",
                "jsonschema",
                NON_FINITE_SCHEMA.as_bytes(),
            )
            .map_err(mcap_err)?;
        let non_finite = writer
            .add_channel(sid, NON_FINITE_TOPIC, "json", &no_meta)
            .map_err(mcap_err)?;
        // Make the header, schemas and channels durable at once.
        writer.flush().map_err(mcap_err)?;
        Ok(Self {
            writer,
            path: path.to_path_buf(),
            channels,
            location_fix,
            pose,
            ned_origin: None,
            sensor_alive,
            non_finite,
            buf: Vec::with_capacity(16 * 1024),
            dirty: false,
            unflushed: 0,
        })
    }

    fn err(&self, e: impl std::error::Error) -> RecorderError {
        RecorderError::Mcap {
            path: self.path.clone(),
            detail: error_chain(&e),
        }
    }

    fn write_json(
        &mut self,
        channel_id: u16,
        seq: u64,
        time_ns: i64,
        receive_mono_ns: u64,
    ) -> Result<(), RecorderError> {
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: seq as u32,
            log_time: time_ns.max(0) as u64,
            publish_time: receive_mono_ns,
        };
        self.writer
            .write_to_known_channel(&header, &self.buf)
            .map_err(|e| self.err(e))?;
        self.dirty = true;
        self.unflushed += 1;
        Ok(())
    }

    /// Write one record; returns the number of messages written.
    fn write(&mut self, item: &Item) -> Result<u64, RecorderError> {
        let cid = match item.record.channel() {
            Some(ch) => *self
                .channels
                .get(ch.name())
                .ok_or_else(|| RecorderError::Mcap {
                    path: self.path.clone(),
                    detail: format!("no channel {}", ch.name()),
                })?,
            None => self.sensor_alive,
        };
        let h = *item.record.header();
        let mut buf = std::mem::take(&mut self.buf);
        let r = item.record.write_json(&mut buf);
        self.buf = buf;
        r.map_err(|e| self.err(e))?;
        // Our messages hold only numbers, so `null` can only be a non-finite float.
        if self.buf.windows(4).any(|w| w == b"null") {
            let topic = item.record.topic();
            self.buf.clear();
            serde_json::to_writer(
                &mut self.buf,
                &serde_json::json!({
                    "topic": topic,
                    "time_ns": h.time_ns,
                    "seq": h.seq,
                    "debug": format!("{:?}", item.record),
                }),
            )
            .map_err(|e| self.err(e))?;
            self.write_json(self.non_finite, h.seq, h.time_ns, item.receive_mono_ns)?;
            return Ok(1);
        }
        self.write_json(cid, h.seq, h.time_ns, item.receive_mono_ns)?;
        let mut n = 1;
        if let Record::Nav(nav) = &item.record {
            let origin = *self
                .ned_origin
                .get_or_insert_with(|| foxglove::NedOrigin::at(nav));
            self.buf.clear();
            serde_json::to_writer(&mut self.buf, &foxglove::location_fix(nav))
                .map_err(|e| self.err(e))?;
            self.write_json(self.location_fix, h.seq, h.time_ns, item.receive_mono_ns)?;
            self.buf.clear();
            serde_json::to_writer(&mut self.buf, &foxglove::pose_in_frame(nav, &origin))
                .map_err(|e| self.err(e))?;
            self.write_json(self.pose, h.seq, h.time_ns, item.receive_mono_ns)?;
            n += 2;
        }
        Ok(n)
    }

    fn flush(&mut self) -> Result<(), RecorderError> {
        if self.dirty {
            self.dirty = false;
            self.writer.flush().map_err(|e| self.err(e))?;
            self.unflushed = 0;
        }
        Ok(())
    }

    fn finish(mut self) -> Result<(), RecorderError> {
        self.writer.finish().map_err(|e| self.err(e))?;
        let path = self.path.clone();
        let io_err = |e: std::io::Error| RecorderError::Mcap {
            path: path.clone(),
            detail: e.to_string(),
        };
        let mut inner = self.writer.into_inner();
        std::io::Write::flush(&mut inner).map_err(io_err)?;
        inner.get_ref().sync_all().map_err(io_err)?;
        Ok(())
    }
}

/// Count a write failure: the failing record and every message still in the unflushed chunk
/// are lost. The sink is then abandoned (the MCAP writer's state is undefined after an I/O
/// error); everything that follows is counted as dropped until a new segment opens.
fn count_failure(counters: &Counters, lost: u64, e: &RecorderError) {
    counters.errors.fetch_add(1, Ordering::Relaxed);
    counters.dropped.fetch_add(lost, Ordering::Relaxed);
    tracing::error!(
        "recorder: {e}; recording interrupted, records are counted as dropped until a new segment can be written"
    );
}

/// Where the writer thread opens its next segment after a failure.
struct Resume {
    /// The recording's first segment.
    path: PathBuf,
    opts: RecorderOptions,
    /// Number of the next segment to try.
    next: usize,
    last_attempt: Instant,
    /// Records dropped when the current outage began (for the message on resuming).
    dropped_at_failure: u64,
    /// Segments are regular files next to the first: not when the recording is a device
    /// (`/dev/full`, a pipe), whose directory is no place for new files.
    enabled: bool,
}

impl Resume {
    /// Try the next free segment name, at most once per [`RESUME_RETRY`].
    fn attempt(&mut self, counters: &Counters) -> Option<Sink> {
        if !self.enabled || self.last_attempt.elapsed() < RESUME_RETRY {
            return None;
        }
        self.last_attempt = Instant::now();
        while segment_path(&self.path, self.next).exists() {
            self.next += 1;
        }
        let p = segment_path(&self.path, self.next);
        match Sink::create_segment(&p, &self.opts) {
            Ok(sink) => {
                self.next += 1;
                counters.add_segment(&p);
                let lost = counters.dropped.load(Ordering::Relaxed) - self.dropped_at_failure;
                tracing::warn!(
                    "recorder: recording resumed in {} ({lost} records dropped while it could not write)",
                    p.display()
                );
                Some(sink)
            }
            Err(e) => {
                tracing::debug!("recorder: still cannot write: {e}");
                None
            }
        }
    }
}

fn run(
    sink: Option<Sink>,
    rx: Receiver<Item>,
    counters: Arc<Counters>,
    mut resume: Resume,
) -> Result<(), RecorderError> {
    let flush_interval = resume.opts.flush_interval;
    let mut last_flush = Instant::now();
    let mut sink = sink;
    loop {
        if sink.is_none() {
            sink = resume.attempt(&counters);
        }
        match rx.recv_timeout(flush_interval) {
            Ok(item) => match sink.as_mut() {
                Some(sk) => match sk.write(&item) {
                    Ok(n) => {
                        counters.written.fetch_add(n, Ordering::Relaxed);
                    }
                    Err(e) => {
                        count_failure(&counters, 1 + sk.unflushed, &e);
                        resume.dropped_at_failure = counters.dropped.load(Ordering::Relaxed);
                        resume.last_attempt = Instant::now();
                        sink = None;
                    }
                },
                None => {
                    counters.dropped.fetch_add(1, Ordering::Relaxed);
                }
            },
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
        if last_flush.elapsed() >= flush_interval {
            last_flush = Instant::now();
            if let Some(sk) = sink.as_mut()
                && let Err(e) = sk.flush()
            {
                count_failure(&counters, sk.unflushed, &e);
                resume.dropped_at_failure = counters.dropped.load(Ordering::Relaxed);
                resume.last_attempt = Instant::now();
                sink = None;
            }
        }
    }
    // A failure to finish is one more failed write: counted (records lost, error), not
    // raised, so that the caller still gets the totals.
    if let Some(sk) = sink {
        let unflushed = sk.unflushed;
        if let Err(e) = sk.finish() {
            count_failure(&counters, unflushed, &e);
        }
    }
    Ok(())
}

impl Recorder {
    /// Create the MCAP file at `path` (header, schemas, channels) and start the writer thread.
    pub fn start(path: &Path, opts: &RecorderOptions) -> Result<Self, RecorderError> {
        let sink = Sink::create(path, opts)?;
        let counters = Arc::new(Counters::default());
        counters.add_segment(path);
        Self::spawn(Some(sink), counters, path, opts, None)
    }

    /// Like [`Recorder::start`], but when the recording cannot be created (unwritable path, full
    /// disk) log the error and return a recorder that counts every record as dropped and keeps
    /// trying to open a segment (`recording.part2.mcap`, …) once per [`RESUME_RETRY`], so that
    /// the fusion keeps navigating without a recording and records again when it can.
    /// [`Recorder::failure`] tells why it could not start.
    pub fn start_or_degrade(path: &Path, opts: &RecorderOptions) -> Self {
        let counters = Arc::new(Counters::default());
        let (sink, failure) = match Sink::create(path, opts) {
            Ok(sink) => {
                counters.add_segment(path);
                (Some(sink), None)
            }
            Err(e) => {
                tracing::error!(
                    "{e}; navigating without a recording (records counted as dropped) until a segment can be written"
                );
                counters.errors.fetch_add(1, Ordering::Relaxed);
                (None, Some(e.to_string()))
            }
        };
        match Self::spawn(sink, counters.clone(), path, opts, failure.clone()) {
            Ok(r) => r,
            Err(e) => {
                tracing::error!("{e}; navigating without a recording (records counted as dropped)");
                if failure.is_none() {
                    counters.errors.fetch_add(1, Ordering::Relaxed);
                }
                Self {
                    tx: None,
                    counters,
                    thread: None,
                    path: path.to_path_buf(),
                    failure: Some(failure.unwrap_or_else(|| e.to_string())),
                }
            }
        }
    }

    fn spawn(
        sink: Option<Sink>,
        counters: Arc<Counters>,
        path: &Path,
        opts: &RecorderOptions,
        failure: Option<String>,
    ) -> Result<Self, RecorderError> {
        let (tx, rx) = sync_channel(opts.queue_capacity);
        let c = counters.clone();
        let resume = Resume {
            path: path.to_path_buf(),
            opts: opts.clone(),
            next: 2,
            last_attempt: Instant::now(),
            dropped_at_failure: 0,
            enabled: std::fs::metadata(path).map_or(true, |m| m.is_file()),
        };
        let thread = std::thread::Builder::new()
            .name("recorder".into())
            .spawn(move || run(sink, rx, c, resume))
            .map_err(|e| RecorderError::Thread(e.to_string()))?;
        Ok(Self {
            tx: Some(tx),
            counters,
            thread: Some(thread),
            path: path.to_path_buf(),
            failure,
        })
    }

    /// Queue a record without blocking; a full queue counts a drop. Returns false when dropped.
    pub fn record(&self, record: Record, receive_mono_ns: u64) -> bool {
        let Some(tx) = &self.tx else {
            self.counters.dropped.fetch_add(1, Ordering::Relaxed);
            return false;
        };
        match tx.try_send(Item {
            record,
            receive_mono_ns,
        }) {
            Ok(()) => true,
            Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {
                self.counters.dropped.fetch_add(1, Ordering::Relaxed);
                false
            }
        }
    }

    /// Queue a record, waiting while the queue is full (offline tools, where losing a record is
    /// worse than waiting). Returns false when the recorder is not running (counted as dropped).
    pub fn record_blocking(&self, record: Record, receive_mono_ns: u64) -> bool {
        let sent = self.tx.as_ref().is_some_and(|tx| {
            tx.send(Item {
                record,
                receive_mono_ns,
            })
            .is_ok()
        });
        if !sent {
            self.counters.dropped.fetch_add(1, Ordering::Relaxed);
        }
        sent
    }

    /// Messages written so far.
    pub fn written(&self) -> u64 {
        self.counters.written.load(Ordering::Relaxed)
    }

    /// Records dropped so far.
    pub fn dropped(&self) -> u64 {
        self.counters.dropped.load(Ordering::Relaxed)
    }

    /// Write errors so far (creation failure, full disk, I/O error).
    pub fn errors(&self) -> u64 {
        self.counters.errors.load(Ordering::Relaxed)
    }

    /// Why the recording could not be created, when it could not.
    pub fn failure(&self) -> Option<&str> {
        self.failure.as_deref()
    }

    /// The recording's path (its first segment).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The segments opened so far, in order (the first is [`Recorder::path`] unless it could
    /// not be created).
    pub fn segments(&self) -> Vec<PathBuf> {
        self.counters
            .segments
            .lock()
            .map(|v| v.clone())
            .unwrap_or_default()
    }

    /// Write what is queued, finish the file (summary and index) and stop the thread.
    pub fn finish(mut self) -> Result<RecorderStats, RecorderError> {
        self.stop()
    }

    fn stop(&mut self) -> Result<RecorderStats, RecorderError> {
        self.tx = None;
        if let Some(t) = self.thread.take() {
            t.join()
                .map_err(|_| RecorderError::Thread("writer thread panicked".into()))??;
        }
        Ok(RecorderStats {
            written: self.written(),
            dropped: self.dropped(),
            errors: self.errors(),
        })
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        if self.thread.is_some()
            && let Err(e) = self.stop()
        {
            tracing::error!("recorder: {e}");
        }
    }
}

#[cfg(test)]
#[allow(clippy::field_reassign_with_default)]
mod tests {
    use super::*;
    use mcap::MessageStream;
    use msgs::{
        BaroSample, ImuSample, NavSolution, OdometerSample, StarTrackerSample, TruthSample,
    };

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("sextant-rec-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d.join("recording.mcap")
    }

    fn sample_records() -> Vec<Record> {
        let mut v = Vec::new();
        for k in 1..=5i64 {
            let mut imu = ImuSample::default();
            imu.header.time_ns = k * 5_000_000;
            imu.header.seq = k as u64;
            v.push(Record::Imu(imu));
            let mut nav = NavSolution::default();
            nav.header = imu.header;
            nav.q_ned_body = [1.0, 0.0, 0.0, 0.0];
            v.push(Record::Nav(nav));
        }
        v.push(Record::StarTracker(StarTrackerSample::default()));
        v.push(Record::Gnss(Box::default()));
        v.push(Record::Odometer(OdometerSample::default()));
        v.push(Record::Baro(BaroSample::default()));
        v.push(Record::Truth(TruthSample::default()));
        v.push(Record::Status(Box::default()));
        v
    }

    #[test]
    fn recording_reads_back_with_schemas_in_order() {
        let path = tmp("roundtrip");
        let rec = Recorder::start(&path, &RecorderOptions::default()).unwrap();
        let records = sample_records();
        for (i, r) in records.iter().enumerate() {
            assert!(rec.record(r.clone(), 1000 + i as u64));
        }
        let stats = rec.finish().unwrap();
        assert_eq!(stats.dropped, 0);
        assert_eq!(stats.written, records.len() as u64 + 2 * 5);

        let bytes = std::fs::read(&path).unwrap();
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        let topics: Vec<_> = summary.channels.values().map(|c| c.topic.clone()).collect();
        for ch in Channel::ALL {
            assert!(topics.iter().any(|t| t == ch.name()), "{topics:?}");
        }
        for c in summary.channels.values() {
            let s = c.schema.as_ref().expect("schema");
            assert_eq!(s.encoding, "jsonschema");
            assert_eq!(c.message_encoding, "json");
            let _: serde_json::Value = serde_json::from_slice(&s.data).unwrap();
        }
        let msgs: Vec<_> = MessageStream::new(&bytes)
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(msgs.len() as u64, stats.written);
        // Order of the sextant channels is the order of recording.
        let order: Vec<_> = msgs
            .iter()
            .filter(|m| Channel::from_name(&m.channel.topic).is_some())
            .map(|m| m.channel.topic.clone())
            .collect();
        let expected: Vec<_> = records.iter().map(|r| r.topic().to_string()).collect();
        assert_eq!(order, expected);
        // Messages validate against their schemas; log_time is GPS ns, publish_time receive.
        for m in &msgs {
            let schema: serde_json::Value =
                serde_json::from_slice(&m.channel.schema.as_ref().unwrap().data).unwrap();
            let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
            let validator = jsonschema::validator_for(&schema).unwrap();
            assert!(validator.is_valid(&v), "{}: {v}", m.channel.topic);
        }
        let first = &msgs[0];
        assert_eq!(first.channel.topic, "imu");
        assert_eq!(first.log_time, 5_000_000);
        assert_eq!(first.publish_time, 1000);
    }

    #[test]
    fn flushed_chunks_survive_a_crash() {
        let path = tmp("crash");
        let opts = RecorderOptions {
            flush_interval: Duration::from_millis(10),
            ..Default::default()
        };
        let rec = Recorder::start(&path, &opts).unwrap();
        for r in sample_records() {
            rec.record(r, 1);
        }
        // Wait for a flush, then "crash": forget the recorder so finish() never runs.
        let t0 = Instant::now();
        while rec.written() < 10 && t0.elapsed() < Duration::from_secs(5) {
            std::thread::sleep(Duration::from_millis(5));
        }
        std::thread::sleep(Duration::from_millis(100));
        let bytes = std::fs::read(&path).unwrap();
        let n = MessageStream::new_with_options(&bytes, mcap::read::Options::IgnoreEndMagic.into())
            .unwrap()
            .take_while(|m| m.is_ok())
            .count();
        assert!(n >= 10, "{n} messages readable");
        drop(rec);
    }

    #[test]
    fn full_queue_counts_drops_and_never_blocks() {
        let path = tmp("full");
        let opts = RecorderOptions {
            queue_capacity: 1,
            ..Default::default()
        };
        let rec = Recorder::start(&path, &opts).unwrap();
        let t0 = Instant::now();
        let mut dropped = 0;
        for _ in 0..10_000 {
            if !rec.record(Record::Gnss(Box::default()), 0) {
                dropped += 1;
            }
        }
        assert!(t0.elapsed() < Duration::from_secs(5));
        assert_eq!(rec.dropped(), dropped);
        let stats = rec.finish().unwrap();
        assert_eq!(stats.written + stats.dropped, 10_000);
        assert!(stats.dropped > 0);
    }

    #[test]
    fn unwritable_path_is_an_error_naming_it() {
        let e = Recorder::start(
            Path::new("/nonexistent-dir/x.mcap"),
            &RecorderOptions::default(),
        )
        .err()
        .unwrap()
        .to_string();
        assert!(e.contains("/nonexistent-dir/x.mcap"), "{e}");
    }
}
