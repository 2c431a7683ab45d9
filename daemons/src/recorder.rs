//! The recorder: an MCAP writer on its own thread, fed by the filter thread through a bounded
//! queue with `try_send`, so that a slow disk never blocks the filter. A record that does not fit
//! in the queue, or whose write fails, is counted in [`Recorder::dropped`] (reported as
//! `Status.records_dropped`), never silently lost.
//!
//! File layout:
//! - one channel per service, topic = channel name (`imu`, `star_tracker`, `gnss`, `odometer`,
//!   `baro`, `truth`, `nav`, `status`), in the [`RecordingEncoding`] of the options: protobuf
//!   (the default; schema = the message's `FileDescriptorSet`, [`msgs::protobuf`]) or JSON
//!   (schema = [`msgs::channel_schema`]);
//! - the solution also on `nav/location_fix` (`foxglove.LocationFix`), `nav/pose`
//!   (`foxglove.PoseInFrame`) and `tf` (`foxglove.FrameTransforms`) at
//!   [`RecorderOptions::view_rate_hz`], the status also on `status/plot` (plain numbers), see
//!   [`crate::foxglove`];
//! - `nav` and `truth` at [`RecorderOptions::solution_rate_hz`] and
//!   [`RecorderOptions::truth_rate_hz`] (the first message of each interval of log time,
//!   [`RateGate`]; 0: every message), stated in the metadata record [`RATES_METADATA_NAME`];
//!   every input is recorded;
//! - times follow MCAP's and Foxglove's convention, Unix nanoseconds (UTC, leap seconds not
//!   counted), stated in the metadata record [`TIME_METADATA_NAME`]:
//!   - **log_time = the message's time of validity** (its header's GPS time converted to UTC
//!     through the leap-second table, [`fusion::time::GpsTime::unix_ns`]), so that a recording
//!     sorts and plots by time of validity and a simulated run shows at its simulated date. A
//!     message whose header carries no time yet (time 0: the daemon's status and sensor-alive
//!     events before the filter's first epoch) is logged at the time of the latest timed message
//!     before it or, before any, of the first one after it (held back until then, order kept),
//!     so that no channel starts in 1970; the header keeps its own time untouched;
//!   - **publish_time = the UTC wall time at which the fusion daemon received (or, for its own
//!     outputs, produced) the message**: its CLOCK_MONOTONIC reception time plus the offset
//!     CLOCK_REALTIME − CLOCK_MONOTONIC taken once when the recording starts and written in the
//!     metadata ([`TIME_KEY_UNIX_MINUS_MONOTONIC`]), so that the reception instant is both a
//!     wall time for MCAP tools and exactly recoverable on the monotonic clock the drivers stamp
//!     (`send_mono_ns`) for latency analysis; when no reception time is known (offline tools
//!     pass 0) publish_time = log_time, as the MCAP specification asks. Reception time and not
//!     the same conversion as log_time, because reception is what publish_time means and the
//!     only place the recording keeps it;
//!   - the Foxglove views' `timestamp` fields are the log time; GPS time stays in each
//!     Sextant message's own header;
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
//!
//! With [`RecorderOptions::segment_duration`] the recorder also starts the next segment when
//! the current file spans that much time of validity: an MCAP writer holds one chunk-index
//! entry per chunk until the file is finished (the summary section needs them), so one file's
//! writer memory grows with its length (≈ 1 MiB per hour of the default run); segments keep it
//! bounded over days. Each segment is complete on its own (its `nav/pose` and `tf` take their
//! NED origin at its first solution); readers of the recording take the segments in order as
//! one stream ([`crate::recording::segments_of`]).
//!
//! [`RecorderOptions::tap`] hands every message written, in file order and in batches of
//! [`TAP_BATCH`], to a consumer on another thread ([`Written`]): an offline tool analyses what
//! it records while it records it instead of reading the file back afterwards.

use crate::foxglove::{self, ToProtobuf};
use mcap::{WriteOptions, Writer};
use msgs::Channel;
use msgs::RecordKind;
/// What the recorder records: one message of any kind (see [`msgs::record`]).
pub use msgs::{Record, SENSOR_ALIVE_TOPIC, SensorAliveEvent};
use serde::Serialize;
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

/// The chunks' zstd level: −1, the first of zstd's fast levels. Most of a recording's bytes
/// are doubles near their entropy (noise, or counts whose zero low bits any level takes), so
/// the slower levels find little more: the default run's file rewritten at −1 is 14.9 MB
/// (0.038 s of compression CPU), at 1 14.5 MB (0.047 s), at 3 14.1 MB (0.076 s), at −3
/// 16.0 MB. The mcap crate takes the level as a `u32` and hands it to zstd
/// as an `i32`, so −1 is passed as its two's complement (a recording test fails if it ever
/// were not a valid level).
const ZSTD_LEVEL: i32 = -1;

/// Name of the MCAP metadata record stating the time base of `log_time` and `publish_time`.
/// Recordings without it were written before the convention: `log_time` = GPS ns and
/// `publish_time` = CLOCK_MONOTONIC ns (see [`crate::recording::TimeBase`]).
pub const TIME_METADATA_NAME: &str = "sextant/time";

/// Key (in [`TIME_METADATA_NAME`]) naming the convention; value [`TIME_CONVENTION_UNIX`].
pub const TIME_KEY_CONVENTION: &str = "convention";

/// The convention of this recorder: log_time = Unix ns (UTC) of the time of validity,
/// publish_time = Unix ns (UTC wall clock) of reception.
pub const TIME_CONVENTION_UNIX: &str =
    "log_time=unix_utc_of_validity;publish_time=unix_utc_of_reception";

/// Key (in [`TIME_METADATA_NAME`]) of CLOCK_REALTIME − CLOCK_MONOTONIC when the recording
/// started, ns (decimal): publish_time − this = the reception time on CLOCK_MONOTONIC.
pub const TIME_KEY_UNIX_MINUS_MONOTONIC: &str = "unix_minus_monotonic_ns";

/// CLOCK_REALTIME − CLOCK_MONOTONIC now, ns.
pub fn unix_minus_monotonic_ns() -> i64 {
    let unix_ns = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX));
    unix_ns.saturating_sub(i64::try_from(msgs::monotonic_ns()).unwrap_or(i64::MAX))
}

/// MCAP log time of a GPS time of validity: Unix ns (UTC), `None` for no time (≤ 0).
pub fn log_time_of(gps_ns: i64) -> Option<u64> {
    (gps_ns > 0).then(|| fusion::time::GpsTime::from_ns(gps_ns).unix_ns().max(0) as u64)
}

/// Name of the MCAP metadata record holding the configuration the fusion ran with.
pub const CONFIG_METADATA_NAME: &str = "sextant/config";

/// Key (in [`CONFIG_METADATA_NAME`]) of the filter configuration, TOML as serialized from the
/// `NavigatorConfig` the engine was built with (authoritative for replay).
pub const CONFIG_KEY_FILTER_TOML: &str = "filter_toml";

/// Name of the MCAP metadata record holding the checkpoint a restarted fusion daemon was
/// started from (absent after a cold start), so that offline replay starts its engine from
/// the same snapshot and reproduces the warm-started solutions bit for bit.
pub const WARM_START_METADATA_NAME: &str = "sextant/warm_start";

/// Key (in [`WARM_START_METADATA_NAME`]) of the snapshot, JSON of
/// `fusion::navigator::NavSnapshot` (shortest round-trip f64, so it parses back bit-exact).
pub const WARM_START_KEY_SNAPSHOT: &str = "snapshot_json";

/// Name of the MCAP metadata record holding the calibration memory a fusion daemon started
/// from (absent without one), so that offline replay loads the same prior.
pub const CALIBRATION_METADATA_NAME: &str = "sextant/calibration";

/// Key (in [`CALIBRATION_METADATA_NAME`]) of the remembered estimate, JSON of
/// `fusion::navigator::NavSnapshot`.
pub const CALIBRATION_KEY_SNAPSHOT: &str = "snapshot_json";

/// Key (in [`CALIBRATION_METADATA_NAME`]) of the wall-clock time from the save to the start,
/// s (shortest round-trip decimal).
pub const CALIBRATION_KEY_ELAPSED_S: &str = "elapsed_s";

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

/// How the recorder encodes messages (`[recorder] encoding`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RecordingEncoding {
    /// Protocol Buffers, the schema records holding each message's `FileDescriptorSet`
    /// ([`msgs::protobuf`]; the Foxglove views on Foxglove's own protobuf schemas): compact
    /// and exact (doubles as their 64 bits, NaN included). Foxglove and Python's
    /// `mcap-protobuf-support` decode it from the file alone.
    #[default]
    Protobuf,
    /// JSON with JSON Schemas: text a person can read, about four times larger, slower to
    /// write and read; a non-finite input goes to [`NON_FINITE_TOPIC`].
    Json,
}

impl RecordingEncoding {
    /// The MCAP message encoding (`protobuf` or `json`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Protobuf => msgs::protobuf::ENCODING,
            Self::Json => "json",
        }
    }
}

/// Recorder settings.
#[derive(Debug, Clone)]
pub struct RecorderOptions {
    /// Queue capacity: hand-overs (a record, or a batch of [`Recorder::batched`]) waiting for
    /// the writer; the live path's batches take at most `queue_capacity / LIVE_BATCH`.
    pub queue_capacity: usize,
    /// Target uncompressed chunk size, bytes.
    pub chunk_size_bytes: u64,
    /// Close the current chunk at least this often.
    pub flush_interval: Duration,
    /// MCAP metadata records written first in the file (name, key/value map), e.g. the
    /// configuration under [`CONFIG_METADATA_NAME`].
    pub metadata: Vec<(String, BTreeMap<String, String>)>,
    /// CLOCK_REALTIME − CLOCK_MONOTONIC, ns, that turns reception times into publish times;
    /// `None`: measured when the recorder starts. Set it to reproduce another recording's
    /// publish times (offline replay).
    pub unix_minus_monotonic_ns: Option<i64>,
    /// Start the next segment when the current file spans this much time of validity (log
    /// time); `None`: one file (see the module comment).
    pub segment_duration: Option<Duration>,
    /// The messages' encoding.
    pub encoding: RecordingEncoding,
    /// Rate of the solution's Foxglove views (`nav/location_fix`, `nav/pose`, `tf`), Hz of
    /// time of validity: the view of the first solution in each `1/view_rate_hz` interval of
    /// log time; 0: a view of every solution. The views are for display (the `nav` channel
    /// has its own rate, [`Self::solution_rate_hz`]); at the solution's own rate they would be
    /// a third of the file.
    pub view_rate_hz: f64,
    /// Rate of the `nav` channel, Hz of time of validity: the first solution of each
    /// `1/solution_rate_hz` interval of log time is written; 0: every solution. The inputs are
    /// always recorded in full, so offline replay recomputes every solution bit for bit and
    /// checks the recorded ones; the daemon's `Status` carries the latency of every solution.
    pub solution_rate_hz: f64,
    /// Rate of the simulator's `truth` channel, Hz of time of validity (first sample of each
    /// interval); 0: every sample. The filter never sees the truth: only the analysis does.
    pub truth_rate_hz: f64,
    /// Where to hand every message written, in file order, in batches of up to [`TAP_BATCH`]
    /// (see [`Written`]); `None`: nowhere. A batch goes when it is full, when the chunk is
    /// flushed and when the file ends. The recorder waits while the tap's queue is full
    /// (offline tools: the consumer keeps up or slows the recording down, nothing is skipped)
    /// and stops tapping once its receiver is gone. A message is tapped when the writer took
    /// it: a write failure later in the same chunk loses it from the file but not from the tap
    /// (the recorder counts the loss).
    pub tap: Option<SyncSender<Vec<Written>>>,
}

/// A message as written to the recording ([`RecorderOptions::tap`]): its topic and, for a
/// record of Sextant's own channels (`imu`, …, `nav`, `status`, `fusion/sensor_alive`), the
/// record itself, exactly as a reader decodes it from the file; `None` for the Foxglove views
/// derived from a record and for a JSON recording's non-finite placeholder.
#[derive(Debug, Clone, PartialEq)]
pub struct Written {
    /// The message's topic.
    pub topic: &'static str,
    /// The record, for Sextant's own channels.
    pub record: Option<Record>,
}

/// Most messages per batch handed to [`RecorderOptions::tap`]: one queue hand-over (and
/// wake-up of the consumer) per batch instead of per message.
pub const TAP_BATCH: usize = 512;

/// The tap of one file: the batch being filled, handed over when full and when dropped (the
/// file ends or is abandoned), so that nothing taken by the writer stays behind.
struct Tap {
    tx: SyncSender<Vec<Written>>,
    batch: Vec<Written>,
}

impl Tap {
    /// Queue `w`; false once the receiver is gone.
    fn push(&mut self, w: Written) -> bool {
        self.batch.push(w);
        self.batch.len() < TAP_BATCH || self.hand_over()
    }

    /// Hand the batch over; false once the receiver is gone.
    fn hand_over(&mut self) -> bool {
        if self.batch.is_empty() {
            return true;
        }
        let batch = std::mem::replace(&mut self.batch, Vec::with_capacity(TAP_BATCH));
        self.tx.send(batch).is_ok()
    }
}

impl Drop for Tap {
    fn drop(&mut self) {
        self.hand_over();
    }
}

/// Default of [`RecorderOptions::view_rate_hz`], Hz: smooth on a map and in a 3D view.
pub const DEFAULT_VIEW_RATE_HZ: f64 = 20.0;

/// Name of the MCAP metadata record stating the rates at which the recorder thinned its
/// derived channels (keys [`RATES_KEY_SOLUTION_HZ`], [`RATES_KEY_TRUTH_HZ`],
/// [`RATES_KEY_VIEW_HZ`]; decimal Hz, 0 = every message). Absent in recordings written before
/// the rates existed: they hold every solution and every truth sample.
pub const RATES_METADATA_NAME: &str = "sextant/rates";
/// Key (in [`RATES_METADATA_NAME`]) of [`RecorderOptions::solution_rate_hz`].
pub const RATES_KEY_SOLUTION_HZ: &str = "solution_rate_hz";
/// Key (in [`RATES_METADATA_NAME`]) of [`RecorderOptions::truth_rate_hz`].
pub const RATES_KEY_TRUTH_HZ: &str = "truth_rate_hz";
/// Key (in [`RATES_METADATA_NAME`]) of [`RecorderOptions::view_rate_hz`].
pub const RATES_KEY_VIEW_HZ: &str = "view_rate_hz";

/// Keeps the first message of each `1/rate` interval of time (intervals counted from time
/// zero, so that two recorders of the same stream keep the same messages), or every message
/// at rate 0: how the recorder thins the channels it does not need in full.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RateGate {
    /// Interval, ns (0: every message).
    period_ns: u64,
    /// Interval index of the last message kept.
    last_slot: Option<u64>,
}

impl RateGate {
    /// A gate at `rate_hz` (≤ 0 or not finite: every message).
    pub fn new(rate_hz: f64) -> Self {
        let period_ns = if rate_hz.is_finite() && rate_hz > 0.0 {
            (1e9 / rate_hz).round().max(1.0) as u64
        } else {
            0
        };
        Self {
            period_ns,
            last_slot: None,
        }
    }

    /// Whether the message at `time_ns` is kept (then its interval is taken).
    pub fn admit(&mut self, time_ns: u64) -> bool {
        if self.period_ns == 0 {
            return true;
        }
        let slot = time_ns / self.period_ns;
        if self.last_slot == Some(slot) {
            return false;
        }
        self.last_slot = Some(slot);
        true
    }
}

/// The rates of a recording's thinned channels, from its [`RATES_METADATA_NAME`] record
/// (solution, truth, views, Hz; 0 = every message). A recording without the record holds
/// every solution and truth sample and its views at [`DEFAULT_VIEW_RATE_HZ`].
pub fn recorded_rates(metadata: &BTreeMap<String, BTreeMap<String, String>>) -> (f64, f64, f64) {
    let Some(m) = metadata.get(RATES_METADATA_NAME) else {
        return (0.0, 0.0, DEFAULT_VIEW_RATE_HZ);
    };
    let get = |k: &str, default: f64| {
        m.get(k)
            .and_then(|v| v.parse::<f64>().ok())
            .filter(|v| v.is_finite() && *v >= 0.0)
            .unwrap_or(default)
    };
    (
        get(RATES_KEY_SOLUTION_HZ, 0.0),
        get(RATES_KEY_TRUTH_HZ, 0.0),
        get(RATES_KEY_VIEW_HZ, DEFAULT_VIEW_RATE_HZ),
    )
}

impl Default for RecorderOptions {
    fn default() -> Self {
        Self {
            queue_capacity: 16384,
            chunk_size_bytes: 1 << 20,
            flush_interval: Duration::from_secs(1),
            metadata: Vec::new(),
            unix_minus_monotonic_ns: None,
            segment_duration: None,
            encoding: RecordingEncoding::default(),
            view_rate_hz: DEFAULT_VIEW_RATE_HZ,
            solution_rate_hz: 0.0,
            truth_rate_hz: 0.0,
            tap: None,
        }
    }
}

impl RecorderOptions {
    /// These options with the clock offset fixed (measured now when not given).
    fn resolved(&self) -> Self {
        Self {
            unix_minus_monotonic_ns: Some(
                self.unix_minus_monotonic_ns
                    .unwrap_or_else(unix_minus_monotonic_ns),
            ),
            ..self.clone()
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

/// What the recorder thread is handed: one record (the live path) or a batch of them, in
/// order ([`RecordBatch`]: one send and at most one wake-up of the writer per batch).
// A record goes unboxed: the live path allocates nothing per record.
#[allow(clippy::large_enum_variant)]
enum Queued {
    One(Item),
    Batch(Vec<Item>),
}

/// Records per batch for an offline tool handing over every record of a file
/// ([`Recorder::batched`]): the writer thread is woken 256 times less often, and a batch of
/// the largest records (≈ 0.5 kB each) stays near 140 kB.
pub const OFFLINE_BATCH: usize = 256;

/// Queue capacity ([`RecorderOptions::queue_capacity`]) for an offline tool handing over
/// [`OFFLINE_BATCH`]es: the producer waits once the writer is 16 batches (4 096 records)
/// behind. The writer (encoding and compressing every record) is the slowest stage of a
/// replay; with the live path's deep queue the filter ran ahead, holding up to every record
/// of the file in memory, and the writer ran alone on one core after it had finished. Held
/// to a short queue it gets its core from the start: the default run's loosely coupled
/// replay takes 0.29 s instead of 0.33 s, its peak memory 60 MB instead of 120 MB.
pub const OFFLINE_QUEUE: usize = 16;

/// Records per hand-over on the live path ([`Recorder::record_live`]): at 1 kHz (an IMU sample
/// and its solution each millisecond) the writer thread is woken about 30 times a second
/// instead of 2 000, so that it competes less for the cores the filter and the drivers need.
pub const LIVE_BATCH: usize = 64;

/// Longest a record waits in the live batch before it is handed over, wall time (checked at
/// each of the daemon's wake-ups, [`Recorder::hand_over_live_if_due`]): the recording on disk
/// lags by up to this much more than the writer's own flush interval.
pub const LIVE_HOLD: Duration = Duration::from_millis(50);

/// The live path's batch and its vectors ([`Recorder::record_live`]). The writer thread hands
/// each drained vector back (`spare`; an offline [`RecordBatch`] takes them too), so that in
/// steady state no record costs an allocation; at most `max_vectors` exist, which bounds the
/// records in flight as the queue's capacity bounds single records (a writer that falls that
/// far behind makes records count as dropped).
struct LiveBatch {
    items: Vec<Item>,
    /// When the oldest record of `items` was queued.
    since: Option<Instant>,
    spare: Receiver<Vec<Item>>,
    vectors: usize,
    max_vectors: usize,
}

/// Records on their way to the recorder in batches ([`Recorder::batched`]).
pub struct RecordBatch<'a> {
    recorder: &'a Recorder,
    items: Vec<Item>,
    capacity: usize,
}

impl RecordBatch<'_> {
    /// Queue a record; a full batch is handed over, waiting while the recorder's queue is
    /// full (records of a batch the recorder cannot take are counted as dropped).
    pub fn record(&mut self, record: Record, receive_mono_ns: u64) {
        self.items.push(Item {
            record,
            receive_mono_ns,
        });
        if self.items.len() >= self.capacity {
            self.flush();
        }
    }

    /// Hand over the records queued so far.
    pub fn flush(&mut self) {
        if self.items.is_empty() {
            return;
        }
        // The next batch goes into a vector the writer has handed back when there is one (no
        // allocation, and no vector left waiting in the hand-back queue).
        let next = match self.recorder.live.spare.try_recv() {
            Ok(mut v) => {
                v.reserve(self.capacity);
                v
            }
            Err(_) => Vec::with_capacity(self.capacity),
        };
        let items = std::mem::replace(&mut self.items, next);
        let n = items.len() as u64;
        let sent = self
            .recorder
            .tx
            .as_ref()
            .is_some_and(|tx| tx.send(Queued::Batch(items)).is_ok());
        if !sent {
            self.recorder
                .counters
                .dropped
                .fetch_add(n, Ordering::Relaxed);
        }
    }
}

impl Drop for RecordBatch<'_> {
    fn drop(&mut self) {
        self.flush();
    }
}

/// Handle of the recorder thread, owned by the filter thread.
pub struct Recorder {
    tx: Option<SyncSender<Queued>>,
    live: LiveBatch,
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
    tf: u16,
    status_plot: u16,
    ned_origin: Option<foxglove::NedOrigin>,
    /// The sensors' mounts of the frame tree, from the filter configuration in the metadata.
    mounts: foxglove::SensorMounts,
    sensor_alive: u16,
    /// [`NON_FINITE_TOPIC`]'s channel (JSON recordings only).
    non_finite: Option<u16>,
    encoding: RecordingEncoding,
    /// Which solutions get their views written ([`RecorderOptions::view_rate_hz`]).
    view_gate: RateGate,
    /// Which solutions are written on `nav` ([`RecorderOptions::solution_rate_hz`]).
    nav_gate: RateGate,
    /// Which truth samples are written ([`RecorderOptions::truth_rate_hz`]).
    truth_gate: RateGate,
    /// CLOCK_REALTIME − CLOCK_MONOTONIC, ns (publish_time = reception + this).
    unix_minus_monotonic_ns: i64,
    buf: Vec<u8>,
    dirty: bool,
    /// Messages handed to the writer since the last successful flush: lost if the next flush
    /// fails (they sit in the in-memory chunk).
    unflushed: u64,
    /// Log time of the first message of this file, Unix ns.
    first_log_time: Option<u64>,
    /// [`RecorderOptions::tap`]; `None` once its receiver is gone.
    tap: Option<Tap>,
}

/// The channel ids of a recording file.
struct Channels {
    channels: BTreeMap<&'static str, u16>,
    location_fix: u16,
    pose: u16,
    tf: u16,
    status_plot: u16,
    sensor_alive: u16,
    non_finite: Option<u16>,
}

enum ChannelsError {
    Mcap(mcap::McapError),
    Schema(String),
}

impl From<mcap::McapError> for ChannelsError {
    fn from(e: mcap::McapError) -> Self {
        Self::Mcap(e)
    }
}

type McapWriter = Writer<BufWriter<File>>;

impl Channels {
    fn add(
        writer: &mut McapWriter,
        schema: (&str, &str, &[u8]),
        topic: &str,
        encoding: &str,
    ) -> Result<u16, mcap::McapError> {
        let (name, schema_encoding, data) = schema;
        let sid = writer.add_schema(name, schema_encoding, data)?;
        writer.add_channel(sid, topic, encoding, &BTreeMap::new())
    }

    /// JSON messages with JSON Schemas.
    fn json(writer: &mut McapWriter) -> Result<Self, ChannelsError> {
        const J: &str = "jsonschema";
        let mut channels = BTreeMap::new();
        for ch in Channel::ALL {
            let (name, schema) = msgs::channel_schema(ch);
            let cid = Self::add(writer, (name, J, schema.as_bytes()), ch.name(), "json")?;
            channels.insert(ch.name(), cid);
        }
        let alive_schema = serde_json::to_string(&schemars::schema_for!(SensorAliveEvent))
            .map_err(|e| ChannelsError::Schema(e.to_string()))?;
        let mut view = |name: &str, schema: &str, topic: &str| {
            Self::add(writer, (name, J, schema.as_bytes()), topic, "json")
        };
        Ok(Self {
            channels,
            location_fix: view(
                foxglove::LOCATION_FIX_SCHEMA,
                &foxglove::location_fix_schema(),
                foxglove::LOCATION_FIX_TOPIC,
            )?,
            pose: view(
                foxglove::POSE_SCHEMA,
                &foxglove::pose_in_frame_schema(),
                foxglove::POSE_TOPIC,
            )?,
            tf: view(
                foxglove::TF_SCHEMA,
                &foxglove::frame_transforms_schema(),
                foxglove::TF_TOPIC,
            )?,
            status_plot: view(
                foxglove::STATUS_PLOT_SCHEMA,
                &foxglove::status_plot_schema(),
                foxglove::STATUS_PLOT_TOPIC,
            )?,
            sensor_alive: view(
                msgs::record::SENSOR_ALIVE_SCHEMA_NAME,
                &alive_schema,
                SENSOR_ALIVE_TOPIC,
            )?,
            non_finite: Some(view(
                "sextant::NonFiniteInput",
                NON_FINITE_SCHEMA,
                NON_FINITE_TOPIC,
            )?),
        })
    }

    /// Protobuf messages with their descriptors; the views on Foxglove's protobuf schemas.
    fn protobuf(writer: &mut McapWriter) -> Result<Self, ChannelsError> {
        const P: &str = msgs::protobuf::ENCODING;
        let mut channels = BTreeMap::new();
        for ch in Channel::ALL {
            let (name, fds) = RecordKind::Channel(ch).protobuf_schema();
            let cid = Self::add(writer, (name, P, &fds), ch.name(), P)?;
            channels.insert(ch.name(), cid);
        }
        let (alive_name, alive_fds) = RecordKind::SensorAlive.protobuf_schema();
        let mut view = |(name, data): (&str, Vec<u8>), topic: &str| {
            Self::add(writer, (name, P, &data), topic, P)
        };
        Ok(Self {
            channels,
            location_fix: view(
                foxglove::LocationFix::protobuf_schema(),
                foxglove::LOCATION_FIX_TOPIC,
            )?,
            pose: view(
                foxglove::PoseInFrame::protobuf_schema(),
                foxglove::POSE_TOPIC,
            )?,
            tf: view(
                foxglove::FrameTransforms::protobuf_schema(),
                foxglove::TF_TOPIC,
            )?,
            status_plot: view(
                foxglove::StatusPlot::protobuf_schema(),
                foxglove::STATUS_PLOT_TOPIC,
            )?,
            sensor_alive: view((alive_name, alive_fds), SENSOR_ALIVE_TOPIC)?,
            non_finite: None,
        })
    }
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
            .compression_level(ZSTD_LEVEL as u32)
            .compression_threads(0)
            .chunk_size(Some(opts.chunk_size_bytes))
            .create(BufWriter::new(file))
            .map_err(mcap_err)?;
        // Metadata first (top level, before any chunk), so that a reader has the time base and
        // the configuration before the first input.
        let unix_minus_monotonic_ns = opts
            .unix_minus_monotonic_ns
            .unwrap_or_else(unix_minus_monotonic_ns);
        let time_meta = BTreeMap::from([
            (
                TIME_KEY_CONVENTION.to_string(),
                TIME_CONVENTION_UNIX.to_string(),
            ),
            (
                TIME_KEY_UNIX_MINUS_MONOTONIC.to_string(),
                unix_minus_monotonic_ns.to_string(),
            ),
        ]);
        let own = (TIME_METADATA_NAME.to_string(), time_meta);
        let rates = (
            RATES_METADATA_NAME.to_string(),
            BTreeMap::from([
                (
                    RATES_KEY_SOLUTION_HZ.to_string(),
                    opts.solution_rate_hz.to_string(),
                ),
                (
                    RATES_KEY_TRUTH_HZ.to_string(),
                    opts.truth_rate_hz.to_string(),
                ),
                (RATES_KEY_VIEW_HZ.to_string(), opts.view_rate_hz.to_string()),
            ]),
        );
        for (name, metadata) in [&own, &rates].into_iter().chain(
            opts.metadata
                .iter()
                .filter(|(name, _)| name != TIME_METADATA_NAME && name != RATES_METADATA_NAME),
        ) {
            writer
                .write_metadata(&mcap::records::Metadata {
                    name: name.clone(),
                    metadata: metadata.clone(),
                })
                .map_err(mcap_err)?;
        }
        let views = match opts.encoding {
            RecordingEncoding::Json => Channels::json(&mut writer),
            RecordingEncoding::Protobuf => Channels::protobuf(&mut writer),
        }
        .map_err(|e| match e {
            ChannelsError::Mcap(e) => mcap_err(e),
            ChannelsError::Schema(detail) => RecorderError::Mcap {
                path: path.to_path_buf(),
                detail,
            },
        })?;
        let Channels {
            channels,
            location_fix,
            pose,
            tf,
            status_plot,
            sensor_alive,
            non_finite,
        } = views;
        // Make the header, schemas and channels durable at once.
        writer.flush().map_err(mcap_err)?;
        Ok(Self {
            writer,
            path: path.to_path_buf(),
            channels,
            location_fix,
            pose,
            tf,
            status_plot,
            ned_origin: None,
            mounts: foxglove::SensorMounts::of_metadata(&opts.metadata),
            sensor_alive,
            non_finite,
            encoding: opts.encoding,
            view_gate: RateGate::new(opts.view_rate_hz),
            nav_gate: RateGate::new(opts.solution_rate_hz),
            truth_gate: RateGate::new(opts.truth_rate_hz),
            unix_minus_monotonic_ns,
            buf: Vec::with_capacity(16 * 1024),
            dirty: false,
            unflushed: 0,
            first_log_time: None,
            tap: opts.tap.clone().map(|tx| Tap {
                tx,
                batch: Vec::with_capacity(TAP_BATCH),
            }),
        })
    }

    fn err(&self, e: impl std::error::Error) -> RecorderError {
        RecorderError::Mcap {
            path: self.path.clone(),
            detail: error_chain(&e),
        }
    }

    /// Write the message in `self.buf` on `channel_id`.
    fn write_message(
        &mut self,
        channel_id: u16,
        seq: u64,
        log_time: u64,
        receive_mono_ns: u64,
    ) -> Result<(), RecorderError> {
        let publish_time = if receive_mono_ns == 0 {
            log_time
        } else {
            receive_mono_ns.saturating_add_signed(self.unix_minus_monotonic_ns)
        };
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: seq as u32,
            log_time,
            publish_time,
        };
        self.writer
            .write_to_known_channel(&header, &self.buf)
            .map_err(|e| self.err(e))?;
        self.dirty = true;
        self.unflushed += 1;
        Ok(())
    }

    /// Hand a message just written to the tap, if any (dropped with the tap when its receiver
    /// is gone).
    fn tap(&mut self, topic: &'static str, record: Option<Record>) {
        if let Some(tap) = &mut self.tap
            && !tap.push(Written { topic, record })
        {
            self.tap = None;
        }
    }

    /// Encode `view` into `self.buf` in the recording's encoding.
    fn encode_view<T: Serialize + ToProtobuf>(&mut self, view: &T) -> Result<(), RecorderError> {
        self.buf.clear();
        match self.encoding {
            RecordingEncoding::Json => {
                serde_json::to_writer(&mut self.buf, view).map_err(|e| self.err(e))
            }
            RecordingEncoding::Protobuf => {
                view.write_protobuf(&mut self.buf);
                Ok(())
            }
        }
    }

    /// Write one record at `log_time` (Unix ns); returns the number of messages written (0
    /// for a solution or truth sample the rates leave out).
    fn write(&mut self, item: &Item, log_time: u64) -> Result<u64, RecorderError> {
        let nav_kept = match &item.record {
            Record::Truth(_) if !self.truth_gate.admit(log_time) => return Ok(0),
            Record::Nav(_) => self.nav_gate.admit(log_time),
            _ => true,
        };
        // A JSON recording writes a non-finite record as its placeholder: no view of it.
        let (mut n, as_itself) = if nav_kept {
            self.write_record(item, log_time)?
        } else {
            (0, true)
        };
        if let Record::Nav(nav) = &item.record
            && as_itself
            && self.view_gate.admit(log_time)
        {
            let h = nav.header;
            let origin = *self
                .ned_origin
                .get_or_insert_with(|| foxglove::NedOrigin::at(nav));
            self.encode_view(&foxglove::location_fix(nav, log_time))?;
            self.write_message(self.location_fix, h.seq, log_time, item.receive_mono_ns)?;
            self.tap(foxglove::LOCATION_FIX_TOPIC, None);
            self.encode_view(&foxglove::pose_in_frame(nav, &origin, log_time))?;
            self.write_message(self.pose, h.seq, log_time, item.receive_mono_ns)?;
            self.tap(foxglove::POSE_TOPIC, None);
            let tf = foxglove::frame_transforms(nav, &origin, &self.mounts, log_time);
            self.encode_view(&tf)?;
            self.write_message(self.tf, h.seq, log_time, item.receive_mono_ns)?;
            self.tap(foxglove::TF_TOPIC, None);
            n += 3;
        }
        Ok(n)
    }

    /// Write the record itself (and the status's plot view); returns the messages written and
    /// whether the record went as itself (false: as [`NON_FINITE_TOPIC`]'s placeholder).
    fn write_record(&mut self, item: &Item, log_time: u64) -> Result<(u64, bool), RecorderError> {
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
        let r = match self.encoding {
            RecordingEncoding::Protobuf => {
                item.record.write_protobuf(&mut buf);
                Ok(())
            }
            RecordingEncoding::Json => item.record.write_json(&mut buf),
        };
        self.buf = buf;
        r.map_err(|e| self.err(e))?;
        // JSON only: our messages hold only numbers, so `null` can only be a non-finite float.
        if let Some(non_finite) = self.non_finite
            && self.buf.windows(4).any(|w| w == b"null")
        {
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
            self.write_message(non_finite, h.seq, log_time, item.receive_mono_ns)?;
            self.tap(NON_FINITE_TOPIC, None);
            return Ok((1, false));
        }
        self.write_message(cid, h.seq, log_time, item.receive_mono_ns)?;
        if self.tap.is_some() {
            self.tap(item.record.topic(), Some(item.record.clone()));
        }
        let mut n = 1;
        if let Record::Status(st) = &item.record {
            self.encode_view(&foxglove::status_plot(st, log_time))?;
            self.write_message(self.status_plot, h.seq, log_time, item.receive_mono_ns)?;
            self.tap(foxglove::STATUS_PLOT_TOPIC, None);
            n += 1;
        }
        Ok((n, true))
    }

    fn flush(&mut self) -> Result<(), RecorderError> {
        if self.dirty {
            self.dirty = false;
            self.writer.flush().map_err(|e| self.err(e))?;
            self.unflushed = 0;
        }
        if let Some(tap) = &mut self.tap
            && !tap.hand_over()
        {
            self.tap = None;
        }
        Ok(())
    }

    fn finish(self) -> Result<(), RecorderError> {
        self.write_end()?.sync()
    }

    /// Write the summary section and the end of the file and hand the file's bytes to the
    /// kernel; the writer (its chunk index and buffers) is freed. What is left is the `fsync`.
    /// Its rate gates.
    fn gates(&self) -> Gates {
        Gates {
            view: self.view_gate,
            nav: self.nav_gate,
            truth: self.truth_gate,
        }
    }

    /// Continue from another segment's rate gates.
    fn set_gates(&mut self, g: Gates) {
        self.view_gate = g.view;
        self.nav_gate = g.nav;
        self.truth_gate = g.truth;
    }

    fn write_end(mut self) -> Result<Unsynced, RecorderError> {
        self.writer.finish().map_err(|e| self.err(e))?;
        let path = self.path.clone();
        let mut inner = self.writer.into_inner();
        std::io::Write::flush(&mut inner).map_err(|e| RecorderError::Mcap {
            path: path.clone(),
            detail: e.to_string(),
        })?;
        let file = inner.into_inner().map_err(|e| RecorderError::Mcap {
            path: path.clone(),
            detail: e.error().to_string(),
        })?;
        Ok(Unsynced {
            file,
            path,
            unflushed: self.unflushed,
        })
    }
}

/// A finished segment whose bytes are written but not yet known to be on the disk.
struct Unsynced {
    file: File,
    path: PathBuf,
    /// Records of the segment's last chunk (lost if the `fsync` fails).
    unflushed: u64,
}

impl Unsynced {
    /// Wait until the file is on the disk.
    fn sync(self) -> Result<(), RecorderError> {
        self.file.sync_all().map_err(|e| RecorderError::Mcap {
            path: self.path.clone(),
            detail: e.to_string(),
        })
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

/// Give the memory the finished segment's writer freed (its chunk index: thousands of small
/// allocations) back to the system. glibc keeps freed memory in its arenas, and the next
/// segment's allocations interleave with the holes, so without this the resident set rose by
/// a step at most rotations (≈ 3.5 MiB over a simulated day, measured).
fn release_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim only returns free heap pages to the kernel; it touches no memory
    // that is in use and is safe to call from any thread at any time.
    unsafe {
        libc::malloc_trim(0);
    }
}

/// Wait until a finished segment is on the disk; a failure is a failed write, counted.
fn sync_segment(done: Unsynced, counters: &Counters) {
    let (path, unflushed) = (done.path.clone(), done.unflushed);
    match done.sync() {
        Ok(()) => tracing::info!("recorder: {} complete", path.display()),
        Err(e) => count_failure(counters, unflushed, &e),
    }
}

/// The thread that waits for the `fsync` of the segments the writer thread has rotated away
/// from. On a slow or busy disk the `fsync` of a file of hundreds of MB takes from
/// milliseconds to seconds; on the writer thread it would stall the queue the filter thread
/// feeds, and a full queue drops records. The writer finishes the segment's file itself (the
/// summary section is quick, and freeing the old segment's index before the next one grows
/// keeps the memory flat), hands the file over and writes the next segment at once.
struct Syncer {
    tx: Option<std::sync::mpsc::Sender<Unsynced>>,
    thread: Option<JoinHandle<()>>,
}

impl Syncer {
    /// Start the thread; `None` when the system refuses one (the writer then waits itself).
    fn start(counters: Arc<Counters>) -> Option<Self> {
        let (tx, rx) = std::sync::mpsc::channel::<Unsynced>();
        let thread = std::thread::Builder::new()
            .name("recorder-sync".into())
            .spawn(move || {
                for done in rx {
                    sync_segment(done, &counters);
                }
            })
            .map_err(|e| {
                tracing::warn!(
                    "recorder: no fsync thread ({e}); segments are synced on the writer thread"
                )
            })
            .ok()?;
        Some(Self {
            tx: Some(tx),
            thread: Some(thread),
        })
    }

    /// Hand a finished segment over; synced here when the thread is gone.
    fn sync(&self, done: Unsynced, counters: &Counters) {
        if let Some(tx) = &self.tx
            && let Err(std::sync::mpsc::SendError(done)) = tx.send(done)
        {
            sync_segment(done, counters);
        }
    }

    /// Wait until every segment handed over is on the disk.
    fn join(mut self) {
        self.tx = None;
        if let Some(t) = self.thread.take()
            && t.join().is_err()
        {
            tracing::error!("recorder: the fsync thread panicked");
        }
    }
}

/// A segment's rate gates ([`RateGate`]), carried into the next segment: a recording in
/// segments keeps the messages one file would (the first of each interval of time).
#[derive(Debug, Clone, Copy)]
struct Gates {
    view: RateGate,
    nav: RateGate,
    truth: RateGate,
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
    /// Waits for the `fsync` of rotated-away segments off the writer thread (started with
    /// the writer).
    syncer: Option<Syncer>,
    /// The gates of the last segment, for the next one.
    gates: Option<Gates>,
}

impl Resume {
    /// The current segment spans the configured duration: finish it (a failure to finish is
    /// a failed write, counted) and open the next one at once.
    fn rotate(&mut self, sink: Option<Sink>, counters: &Counters) -> Option<Sink> {
        if !self.enabled {
            // A device or pipe: no place for further files; it stays one stream.
            return sink;
        }
        let sk = sink?;
        self.gates = Some(sk.gates());
        let (done, unflushed) = (sk.path.clone(), sk.unflushed);
        match sk.write_end() {
            Ok(file) => match &self.syncer {
                Some(syncer) => syncer.sync(file, counters),
                None => sync_segment(file, counters),
            },
            Err(e) => count_failure(counters, unflushed, &e),
        }
        release_freed_memory();
        match self.open_next(counters) {
            Ok((sink, p)) => {
                tracing::info!(
                    "recorder: {} ends its time span, recording continues in {}",
                    done.display(),
                    p.display()
                );
                Some(sink)
            }
            Err(e) => {
                count_failure(counters, 0, &e);
                self.dropped_at_failure = counters.dropped.load(Ordering::Relaxed);
                self.last_attempt = Instant::now();
                None
            }
        }
    }

    /// Create the next free segment and list it.
    fn open_next(&mut self, counters: &Counters) -> Result<(Sink, PathBuf), RecorderError> {
        while segment_path(&self.path, self.next).exists() {
            self.next += 1;
        }
        let p = segment_path(&self.path, self.next);
        let mut sink = Sink::create_segment(&p, &self.opts)?;
        if let Some(g) = self.gates {
            sink.set_gates(g);
        }
        self.next += 1;
        counters.add_segment(&p);
        Ok((sink, p))
    }

    /// Try the next free segment name, at most once per [`RESUME_RETRY`].
    fn attempt(&mut self, counters: &Counters) -> Option<Sink> {
        if !self.enabled || self.last_attempt.elapsed() < RESUME_RETRY {
            return None;
        }
        self.last_attempt = Instant::now();
        match self.open_next(counters) {
            Ok((sink, p)) => {
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

/// Largest number of untimed records held back waiting for the first time of validity; beyond
/// it (a recorder fed no timed record for that long) they are written at their publish time.
const MAX_HELD_UNTIMED: usize = 4096;

/// The log times of the records, in recording order (see the module comment): a timed record
/// at its own time of validity, an untimed one at the latest time before it, or held back until
/// the first.
#[derive(Default)]
struct LogClock {
    /// Log time of the latest timed record, Unix ns.
    last: Option<u64>,
    /// Untimed records before the first timed one, in order.
    held: Vec<Item>,
}

/// Write one record to the sink at `log_time`, or count it dropped; a failed write abandons
/// the sink (see [`count_failure`]).
fn deliver(
    sink: &mut Option<Sink>,
    item: &Item,
    log_time: u64,
    counters: &Counters,
    resume: &mut Resume,
) {
    if let (Some(sk), Some(span)) = (sink.as_ref(), resume.opts.segment_duration)
        && sk
            .first_log_time
            .is_some_and(|t0| log_time >= t0.saturating_add(span.as_nanos() as u64))
    {
        *sink = resume.rotate(sink.take(), counters);
    }
    let Some(sk) = sink.as_mut() else {
        counters.dropped.fetch_add(1, Ordering::Relaxed);
        return;
    };
    sk.first_log_time.get_or_insert(log_time);
    match sk.write(item, log_time) {
        Ok(n) => {
            counters.written.fetch_add(n, Ordering::Relaxed);
        }
        Err(e) => {
            count_failure(counters, 1 + sk.unflushed, &e);
            resume.dropped_at_failure = counters.dropped.load(Ordering::Relaxed);
            resume.last_attempt = Instant::now();
            resume.gates = Some(sk.gates());
            *sink = None;
        }
    }
}

impl LogClock {
    /// Route `item` to the sink at its log time (writing the records held for it first).
    fn admit(
        &mut self,
        item: Item,
        sink: &mut Option<Sink>,
        counters: &Counters,
        resume: &mut Resume,
    ) {
        match log_time_of(item.record.header().time_ns) {
            Some(t) => {
                self.last = Some(t);
                for held in std::mem::take(&mut self.held) {
                    deliver(sink, &held, t, counters, resume);
                }
                deliver(sink, &item, t, counters, resume);
            }
            None => match self.last {
                Some(t) => deliver(sink, &item, t, counters, resume),
                None if self.held.len() < MAX_HELD_UNTIMED => self.held.push(item),
                None => {
                    let t = self.publish_fallback(&item, resume);
                    deliver(sink, &item, t, counters, resume);
                }
            },
        }
    }

    /// Log time of an untimed record when no time of validity ever came: its publish time (the
    /// wall time of reception), or 0 when that is unknown too.
    fn publish_fallback(&self, item: &Item, resume: &Resume) -> u64 {
        if item.receive_mono_ns == 0 {
            return 0;
        }
        let offset = resume.opts.unix_minus_monotonic_ns.unwrap_or(0);
        item.receive_mono_ns.saturating_add_signed(offset)
    }

    /// At the end: write the records still held (no timed record ever came).
    fn finish(&mut self, sink: &mut Option<Sink>, counters: &Counters, resume: &mut Resume) {
        for held in std::mem::take(&mut self.held) {
            let t = self.publish_fallback(&held, resume);
            deliver(sink, &held, t, counters, resume);
        }
    }
}

fn run(
    sink: Option<Sink>,
    rx: Receiver<Queued>,
    spare: SyncSender<Vec<Item>>,
    counters: Arc<Counters>,
    mut resume: Resume,
) -> Result<(), RecorderError> {
    let flush_interval = resume.opts.flush_interval;
    let mut last_flush = Instant::now();
    let mut sink = sink;
    let mut clock = LogClock::default();
    if resume.enabled && resume.opts.segment_duration.is_some() {
        resume.syncer = Syncer::start(counters.clone());
    }
    loop {
        if sink.is_none() {
            sink = resume.attempt(&counters);
        }
        match rx.recv_timeout(flush_interval) {
            Ok(Queued::One(item)) => clock.admit(item, &mut sink, &counters, &mut resume),
            Ok(Queued::Batch(mut items)) => {
                for item in items.drain(..) {
                    clock.admit(item, &mut sink, &counters, &mut resume);
                }
                // Back to whichever batch is filled next, live or offline (dropped when the
                // hand-back queue is full).
                let _ = spare.try_send(items);
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => {
                clock.finish(&mut sink, &counters, &mut resume);
                break;
            }
        }
        if last_flush.elapsed() >= flush_interval {
            last_flush = Instant::now();
            if let Some(sk) = sink.as_mut()
                && let Err(e) = sk.flush()
            {
                count_failure(&counters, sk.unflushed, &e);
                resume.dropped_at_failure = counters.dropped.load(Ordering::Relaxed);
                resume.last_attempt = Instant::now();
                resume.gates = Some(sk.gates());
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
    // The totals the caller reads next include the rotated segments' `fsync`.
    if let Some(syncer) = resume.syncer.take() {
        syncer.join();
    }
    Ok(())
}

impl LiveBatch {
    /// An empty batch for a queue of `queue_capacity` records, and the sender the writer
    /// thread hands drained vectors back with.
    fn new(queue_capacity: usize) -> (Self, SyncSender<Vec<Item>>) {
        let max_vectors = (queue_capacity / LIVE_BATCH).max(2);
        let (tx, rx) = sync_channel(max_vectors);
        let live = Self {
            items: Vec::new(),
            since: None,
            spare: rx,
            vectors: 0,
            max_vectors,
        };
        (live, tx)
    }

    /// Whether `items` can take a record: it has room, or a vector handed back (or a new one,
    /// while fewer than `max_vectors` exist) is put in place.
    fn ready(&mut self) -> bool {
        if self.items.capacity() > self.items.len() {
            return true;
        }
        if let Ok(v) = self.spare.try_recv() {
            self.items = v;
            return true;
        }
        if self.vectors < self.max_vectors {
            self.vectors += 1;
            self.items = Vec::with_capacity(LIVE_BATCH);
            return true;
        }
        false
    }
}

impl Recorder {
    /// Create the MCAP file at `path` (header, schemas, channels) and start the writer thread.
    pub fn start(path: &Path, opts: &RecorderOptions) -> Result<Self, RecorderError> {
        let opts = &opts.resolved();
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
        let opts = &opts.resolved();
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
                    live: LiveBatch::new(opts.queue_capacity).0,
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
        let (live, spare_tx) = LiveBatch::new(opts.queue_capacity);
        let c = counters.clone();
        let resume = Resume {
            path: path.to_path_buf(),
            opts: opts.clone(),
            next: 2,
            last_attempt: Instant::now(),
            dropped_at_failure: 0,
            enabled: std::fs::metadata(path).map_or(true, |m| m.is_file()),
            syncer: None,
            gates: None,
        };
        let thread = std::thread::Builder::new()
            .name("recorder".into())
            .spawn(move || run(sink, rx, spare_tx, c, resume))
            .map_err(|e| RecorderError::Thread(e.to_string()))?;
        Ok(Self {
            tx: Some(tx),
            live,
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
        match tx.try_send(Queued::One(Item {
            record,
            receive_mono_ns,
        })) {
            Ok(()) => true,
            Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {
                self.counters.dropped.fetch_add(1, Ordering::Relaxed);
                false
            }
        }
    }

    /// Queue a record on the live path: it joins the current batch, which is handed to the
    /// writer thread when it holds [`LIVE_BATCH`] records, when its oldest has waited
    /// [`LIVE_HOLD`] ([`Recorder::hand_over_live_if_due`]) or at [`Recorder::hand_over_live`]
    /// and the end. Never blocks and, once the writer has handed a few vectors back, never
    /// allocates. Records keep their order as long as every record goes this way (the daemon's
    /// all do). Returns false when the record is dropped (counted): no recorder, or the writer
    /// so far behind that every batch vector is in its queue.
    pub fn record_live(&mut self, record: Record, receive_mono_ns: u64) -> bool {
        if self.tx.is_none() || !self.live.ready() {
            self.counters.dropped.fetch_add(1, Ordering::Relaxed);
            return false;
        }
        if self.live.items.is_empty() {
            self.live.since = Some(Instant::now());
        }
        self.live.items.push(Item {
            record,
            receive_mono_ns,
        });
        if self.live.items.len() >= LIVE_BATCH {
            self.hand_over_live();
        }
        true
    }

    /// Hand the live batch over if its oldest record has waited [`LIVE_HOLD`] by `now`.
    pub fn hand_over_live_if_due(&mut self, now: Instant) {
        if self
            .live
            .since
            .is_some_and(|t| now.saturating_duration_since(t) >= LIVE_HOLD)
        {
            self.hand_over_live();
        }
    }

    /// Hand the live batch over now (one send; a full queue drops it, counted).
    pub fn hand_over_live(&mut self) {
        self.live.since = None;
        if self.live.items.is_empty() {
            return;
        }
        let items = std::mem::take(&mut self.live.items);
        let n = items.len() as u64;
        let Some(tx) = &self.tx else {
            self.counters.dropped.fetch_add(n, Ordering::Relaxed);
            return;
        };
        if let Err(TrySendError::Full(q) | TrySendError::Disconnected(q)) =
            tx.try_send(Queued::Batch(items))
        {
            self.counters.dropped.fetch_add(n, Ordering::Relaxed);
            if let Queued::Batch(mut v) = q {
                v.clear();
                self.live.items = v;
            }
        }
    }

    /// Queue a record, waiting while the queue is full (offline tools, where losing a record is
    /// worse than waiting). Returns false when the recorder is not running (counted as dropped).
    pub fn record_blocking(&self, record: Record, receive_mono_ns: u64) -> bool {
        let sent = self.tx.as_ref().is_some_and(|tx| {
            tx.send(Queued::One(Item {
                record,
                receive_mono_ns,
            }))
            .is_ok()
        });
        if !sent {
            self.counters.dropped.fetch_add(1, Ordering::Relaxed);
        }
        sent
    }

    /// A batching front of [`Recorder::record_blocking`] for offline tools that hand over
    /// every record of a file: `capacity` records per send, so that the writer thread is
    /// woken once per batch instead of once per record (a wake-up is a system call on each
    /// side). The records reach the writer in order; [`RecordBatch::flush`] (or dropping it)
    /// hands over the rest.
    pub fn batched(&self, capacity: usize) -> RecordBatch<'_> {
        let capacity = capacity.max(1);
        RecordBatch {
            recorder: self,
            items: Vec::with_capacity(capacity),
            capacity,
        }
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

    /// [`Recorder::finish`], with every segment written, in order (the last ones may have been
    /// opened while the queue drained).
    pub fn finish_with_segments(mut self) -> Result<(RecorderStats, Vec<PathBuf>), RecorderError> {
        let stats = self.stop()?;
        Ok((stats, self.segments()))
    }

    fn stop(&mut self) -> Result<RecorderStats, RecorderError> {
        self.hand_over_live();
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
    fn json_recording_reads_back_with_schemas_in_order() {
        reads_back_with_schemas_in_order(RecordingEncoding::Json);
    }

    #[test]
    fn protobuf_recording_reads_back_with_schemas_in_order() {
        reads_back_with_schemas_in_order(RecordingEncoding::Protobuf);
    }

    /// The views are written for the first solution of each `1/view_rate_hz` of log time;
    /// every solution stays on `nav`.
    #[test]
    fn views_follow_their_rate_and_every_solution_is_kept() {
        let path = tmp("views");
        let rec = Recorder::start(&path, &RecorderOptions::default()).unwrap();
        // 1 s of solutions at 200 Hz, starting 3 ms into a 50 ms interval of log time
        // (log time = GPS + 315 964 800 s − 19 s at the GPS epoch: whole seconds).
        for k in 0..200i64 {
            let mut nav = NavSolution::default();
            nav.header.time_ns = 3_000_000 + k * 5_000_000;
            nav.header.seq = k as u64 + 1;
            nav.q_ned_body = [1.0, 0.0, 0.0, 0.0];
            assert!(rec.record(Record::Nav(nav), 0));
        }
        rec.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let mut nav = Vec::new();
        let mut views: BTreeMap<String, Vec<u64>> = BTreeMap::new();
        for m in MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            if m.channel.topic == "nav" {
                nav.push(m.log_time);
            } else {
                views
                    .entry(m.channel.topic.clone())
                    .or_default()
                    .push(m.log_time);
            }
        }
        assert_eq!(nav.len(), 200);
        let t0 = 315_964_800_000_000_000u64 + 3_000_000;
        // Intervals [0, 50 ms), [50, 100 ms), …: the first solution of each is at 3 ms, then
        // 53 ms, 103 ms, …; 20 in one second.
        let expected: Vec<u64> = (0..20).map(|k| t0 + k * 50_000_000).collect();
        for topic in [
            foxglove::LOCATION_FIX_TOPIC,
            foxglove::POSE_TOPIC,
            foxglove::TF_TOPIC,
        ] {
            assert_eq!(views[topic], expected, "{topic}");
        }
    }

    /// With solution and truth rates, `nav` and `truth` hold the first message of each
    /// interval of log time, the inputs and the views are untouched, and the file states the
    /// rates for replay.
    #[test]
    fn solutions_and_truth_follow_their_rates_and_the_rates_are_stated() {
        let path = tmp("rates");
        let opts = RecorderOptions {
            solution_rate_hz: 10.0,
            truth_rate_hz: 4.0,
            view_rate_hz: 20.0,
            ..Default::default()
        };
        let rec = Recorder::start(&path, &opts).unwrap();
        // 1 s at 200 Hz from 3 ms: IMU, solution and (every 20 ms) truth.
        for k in 0..200i64 {
            let t = 3_000_000 + k * 5_000_000;
            let mut imu = ImuSample::default();
            imu.header.time_ns = t;
            assert!(rec.record(Record::Imu(imu), 0));
            let mut nav = NavSolution::default();
            nav.header.time_ns = t;
            nav.header.seq = k as u64 + 1;
            nav.q_ned_body = [1.0, 0.0, 0.0, 0.0];
            assert!(rec.record(Record::Nav(nav), 0));
            if k % 4 == 0 {
                let mut truth = TruthSample::default();
                truth.header.time_ns = t;
                assert!(rec.record(Record::Truth(truth), 0));
            }
        }
        rec.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let mut times: BTreeMap<String, Vec<u64>> = BTreeMap::new();
        for m in MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            times
                .entry(m.channel.topic.clone())
                .or_default()
                .push(m.log_time);
        }
        let t0 = 315_964_800_000_000_000u64 + 3_000_000;
        assert_eq!(times["imu"].len(), 200);
        // Solutions: intervals of 100 ms, the first of each at 3, 103, 203 … ms.
        let nav: Vec<u64> = (0..10).map(|k| t0 + k * 100_000_000).collect();
        assert_eq!(times["nav"], nav);
        // Truth every 20 ms from 3 ms, intervals of 250 ms: 3, 263 (the first ≥ 250), 503, 763.
        let truth: Vec<u64> = [0, 260, 500, 760]
            .iter()
            .map(|ms| t0 + ms * 1_000_000)
            .collect();
        assert_eq!(times["truth"], truth);
        assert_eq!(
            times[foxglove::POSE_TOPIC].len(),
            20,
            "views at their own rate"
        );
        let meta: BTreeMap<String, BTreeMap<String, String>> =
            mcap::read::LinearReader::new(&bytes)
                .unwrap()
                .filter_map(|r| match r.unwrap() {
                    mcap::records::Record::Metadata(m) => Some((m.name, m.metadata)),
                    _ => None,
                })
                .collect();
        assert_eq!(recorded_rates(&meta), (10.0, 4.0, 20.0));
        assert_eq!(
            recorded_rates(&BTreeMap::new()),
            (0.0, 0.0, DEFAULT_VIEW_RATE_HZ)
        );
    }

    #[test]
    fn a_rate_gate_keeps_the_first_message_of_each_interval() {
        let mut g = RateGate::new(10.0);
        let kept: Vec<u64> = [0u64, 5, 99, 100, 150, 250, 251, 1000]
            .into_iter()
            .filter(|ms| g.admit(ms * 1_000_000))
            .collect();
        assert_eq!(kept, [0, 100, 250, 1000]);
        let mut every = RateGate::new(0.0);
        assert!((0..5).all(|_| every.admit(7)));
        assert!(RateGate::new(f64::NAN).admit(1) && RateGate::new(-1.0).admit(1));
    }

    fn reads_back_with_schemas_in_order(encoding: RecordingEncoding) {
        let path = tmp(&format!("roundtrip-{encoding:?}"));
        let opts = RecorderOptions {
            encoding,
            view_rate_hz: 0.0,
            ..Default::default()
        };
        let rec = Recorder::start(&path, &opts).unwrap();
        let records = sample_records();
        for (i, r) in records.iter().enumerate() {
            assert!(rec.record(r.clone(), 1000 + i as u64));
        }
        let stats = rec.finish().unwrap();
        assert_eq!(stats.dropped, 0);
        // Each solution also as LocationFix, pose and frame tree; the status also as a plot.
        assert_eq!(stats.written, records.len() as u64 + 3 * 5 + 1);

        let bytes = std::fs::read(&path).unwrap();
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        let topics: Vec<_> = summary.channels.values().map(|c| c.topic.clone()).collect();
        for ch in Channel::ALL {
            assert!(topics.iter().any(|t| t == ch.name()), "{topics:?}");
        }
        for c in summary.channels.values() {
            let s = c.schema.as_ref().expect("schema");
            assert_eq!(c.message_encoding, encoding.name());
            match encoding {
                RecordingEncoding::Json => {
                    assert_eq!(s.encoding, "jsonschema");
                    let _: serde_json::Value = serde_json::from_slice(&s.data).unwrap();
                }
                RecordingEncoding::Protobuf => {
                    use prost::Message;
                    assert_eq!(s.encoding, "protobuf");
                    // The schema names a message its descriptor set declares.
                    let set = msgs::protobuf::prost_types::FileDescriptorSet::decode(&s.data[..])
                        .unwrap();
                    let (package, name) = s.name.rsplit_once('.').unwrap();
                    assert!(
                        set.file.iter().any(|f| f.package() == package
                            && f.message_type.iter().any(|m| m.name() == name)),
                        "{}",
                        s.name
                    );
                }
            }
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
        // JSON messages validate against their schemas; every record reads back equal.
        if encoding == RecordingEncoding::Json {
            for m in &msgs {
                let schema: serde_json::Value =
                    serde_json::from_slice(&m.channel.schema.as_ref().unwrap().data).unwrap();
                let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
                let validator = jsonschema::validator_for(&schema).unwrap();
                assert!(validator.is_valid(&v), "{}: {v}", m.channel.topic);
            }
        }
        let back: Vec<Record> = crate::recording::read_all(&path)
            .unwrap()
            .entries
            .into_iter()
            .filter_map(|e| e.record)
            .collect();
        assert_eq!(back, records);
        // log_time = Unix ns of the time of validity (GPS 5 ms after the GPS epoch, when
        // TAI − UTC was 19 s = TAI − GPS: Unix 315964800 s + 5 ms); publish_time = reception
        // (1000 ns on CLOCK_MONOTONIC) + the offset stated in the metadata.
        let first = &msgs[0];
        assert_eq!(first.channel.topic, "imu");
        assert_eq!(first.log_time, 315_964_800_000_000_000 + 5_000_000);
        let meta = mcap::read::Summary::read(&bytes).unwrap().unwrap();
        assert!(
            meta.metadata_indexes
                .iter()
                .any(|m| m.name == TIME_METADATA_NAME)
        );
        let base = crate::recording::Recording::open(&path)
            .unwrap()
            .time_base();
        let crate::recording::TimeBase::Unix {
            unix_minus_monotonic_ns,
        } = base
        else {
            panic!("{base:?}");
        };
        assert_eq!(first.publish_time as i64, 1000 + unix_minus_monotonic_ns);
        // The untimed status (header time 0) is logged at the latest time before it.
        let status = msgs.iter().find(|m| m.channel.topic == "status").unwrap();
        assert_eq!(status.log_time, 315_964_800_000_000_000 + 25_000_000);
    }

    /// With a segment duration, the recording is split at record boundaries into complete MCAP
    /// files, each spanning less than the duration; the reader takes them as one stream, in
    /// order, and `open_file` reads one alone.
    #[test]
    fn segments_split_the_recording_and_read_back_as_one() {
        let path = tmp("segments");
        for n in 2..=5 {
            let _ = std::fs::remove_file(segment_path(&path, n));
        }
        let span = Duration::from_secs(3);
        let opts = RecorderOptions {
            segment_duration: Some(span),
            ..Default::default()
        };
        let rec = Recorder::start(&path, &opts).unwrap();
        let t0 = fusion::time::GpsTime::from_utc(2025, 3, 20, 21, 0, 0.0).ns;
        // 10 s of IMU at 10 Hz: segments [0, 3), [3, 6), [6, 9), [9, 10) s.
        for k in 0..100u64 {
            let mut imu = ImuSample::default();
            imu.header.time_ns = t0 + k as i64 * 100_000_000;
            imu.header.seq = k + 1;
            assert!(rec.record(Record::Imu(imu), 0));
        }
        let (stats, segments) = rec.finish_with_segments().unwrap();
        assert_eq!((stats.written, stats.dropped, stats.errors), (100, 0, 0));
        assert_eq!(segments.len(), 4, "{segments:?}");
        assert_eq!(segments, crate::recording::segments_of(&path));
        let mut per_file = Vec::new();
        for p in &segments {
            // Each a complete MCAP (summary and footer), spanning less than the duration.
            let bytes = std::fs::read(p).unwrap();
            let stats = mcap::Summary::read(&bytes).unwrap().unwrap().stats.unwrap();
            assert!(stats.message_end_time - stats.message_start_time < span.as_nanos() as u64);
            let one: Vec<_> = crate::recording::Recording::open_file(p)
                .unwrap()
                .map(|e| e.unwrap().record.unwrap().header().seq)
                .collect();
            per_file.push(one.len());
        }
        assert_eq!(per_file, [30, 30, 30, 10]);
        let mut all = crate::recording::Recording::open(&path).unwrap();
        let seqs: Vec<u64> = (&mut all)
            .map(|e| e.unwrap().record.unwrap().header().seq)
            .collect();
        assert_eq!(seqs, (1..=100).collect::<Vec<_>>());
        assert!(all.is_complete());
        for p in segments {
            let _ = std::fs::remove_file(p);
        }
    }

    /// Records without a time of validity before the first timed one are held back and logged
    /// at its time, in order; those of a recorder that never sees a time go out at their
    /// publish time (reception), or at their log time 0 when none is known.
    #[test]
    fn untimed_records_before_the_first_time_take_it_in_order() {
        let path = tmp("untimed");
        let rec = Recorder::start(&path, &RecorderOptions::default()).unwrap();
        rec.record(Record::Status(Box::default()), 0);
        rec.record(Record::SensorAlive(SensorAliveEvent::default()), 0);
        let mut imu = ImuSample::default();
        imu.header.time_ns = fusion::time::GpsTime::from_utc(2025, 3, 20, 21, 0, 0.0).ns;
        rec.record(Record::Imu(imu), 0);
        rec.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let msgs: Vec<_> = MessageStream::new(&bytes)
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        let topics: Vec<_> = msgs.iter().map(|m| m.channel.topic.as_str()).collect();
        assert_eq!(
            topics,
            [
                "status",
                foxglove::STATUS_PLOT_TOPIC,
                SENSOR_ALIVE_TOPIC,
                "imu"
            ]
        );
        for m in &msgs {
            // 2025-03-20T21:00:00Z = Unix 1742504400 s; no reception time: publish = log.
            assert_eq!(m.log_time, 1_742_504_400_000_000_000, "{}", m.channel.topic);
            assert_eq!(m.publish_time, m.log_time);
        }

        let path = tmp("untimed-only");
        let rec = Recorder::start(&path, &RecorderOptions::default()).unwrap();
        rec.record(Record::Status(Box::default()), 5_000);
        rec.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let m = MessageStream::new(&bytes).unwrap().next().unwrap().unwrap();
        assert_eq!(m.log_time, m.publish_time);
        assert!(m.log_time > 1_742_504_400_000_000_000, "{}", m.log_time);
    }

    /// Batched records reach the file in the order they were queued, across batch boundaries
    /// and the partial batch handed over when the front is dropped, and are all counted.
    #[test]
    fn batched_records_keep_their_order_and_the_last_partial_batch() {
        let path = tmp("batched");
        let rec = Recorder::start(&path, &RecorderOptions::default()).unwrap();
        let t0 = fusion::time::GpsTime::from_utc(2025, 3, 20, 21, 0, 0.0).ns;
        {
            let mut out = rec.batched(4);
            for k in 0..10u64 {
                let mut imu = ImuSample::default();
                imu.header.time_ns = t0 + k as i64 * 5_000_000;
                imu.header.seq = k;
                out.record(Record::Imu(imu), 0);
            }
        }
        let stats = rec.finish().unwrap();
        assert_eq!((stats.written, stats.dropped), (10, 0));
        assert_eq!(sequences(&path), (0..10).collect::<Vec<u32>>());
    }

    /// The live path: records handed over 64 at a time keep their order, the partial batch
    /// goes when its oldest record has waited [`LIVE_HOLD`] and at the end, and the writer hands
    /// the vectors back, so that 3 000 records need only the first few.
    #[test]
    fn live_batches_keep_the_order_come_back_and_go_when_due() {
        let path = tmp("live");
        let mut rec = Recorder::start(&path, &RecorderOptions::default()).unwrap();
        let t0 = fusion::time::GpsTime::from_utc(2025, 3, 20, 21, 0, 0.0).ns;
        let imu = |k: u64| {
            let mut imu = ImuSample::default();
            imu.header.time_ns = t0 + k as i64 * 5_000_000;
            imu.header.seq = k;
            Record::Imu(imu)
        };
        for k in 0..3000u64 {
            assert!(rec.record_live(imu(k), 0));
            if k % 64 == 63 {
                // A full batch was handed over: give the writer time to hand it back.
                let t = Instant::now();
                while rec.written() < k + 1 && t.elapsed() < Duration::from_secs(5) {
                    std::thread::sleep(Duration::from_millis(1));
                }
            }
        }
        assert!(rec.live.vectors <= 3, "{} vectors", rec.live.vectors);
        // 3 000 = 46 full batches and 56 records waiting: not handed over before they are due.
        let written = rec.written();
        assert_eq!(written, 46 * 64);
        rec.hand_over_live_if_due(Instant::now());
        assert!(rec.live.since.is_some(), "handed over before it was due");
        rec.hand_over_live_if_due(Instant::now() + LIVE_HOLD);
        assert!(rec.live.items.is_empty());
        let t = Instant::now();
        while rec.written() < 3000 && t.elapsed() < Duration::from_secs(5) {
            std::thread::sleep(Duration::from_millis(1));
        }
        assert_eq!(rec.written(), 3000);
        for k in 3000..3010u64 {
            assert!(rec.record_live(imu(k), 0));
        }
        let stats = rec.finish().unwrap();
        assert_eq!((stats.written, stats.dropped), (3010, 0));
        assert_eq!(sequences(&path), (0..3010).collect::<Vec<u32>>());
    }

    /// The messages' sequence numbers in file order.
    fn sequences(path: &Path) -> Vec<u32> {
        let bytes = std::fs::read(path).unwrap();
        MessageStream::new(&bytes)
            .unwrap()
            .map(|m| m.unwrap().sequence)
            .collect()
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
