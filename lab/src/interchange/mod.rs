//! Log interchange: other tools' text logs into Sextant recordings and Sextant's recordings out
//! to them, so that Sextant runs on other datasets and other filters run on Sextant's.
//!
//! - [`kfgins`]: the text formats of KF-GINS (i2Nav, Wuhan University) and of the open GNSS/INS
//!   datasets that share them: IMU increments, GNSS positions with standard deviations, the
//!   navigation-result / reference-trajectory file.
//! - [`csv_log`]: CSV files of any layout, described by a small TOML file (columns, units,
//!   frames, time base).
//! - [`text`]: what the formats share (errors naming file, line and column; exact decimal
//!   seconds; GPS weeks; floats written with the shortest text that reads back bit for bit).
//!
//! In between sits [`Streams`], the samples of each channel in time order. A recording is
//! written from it with the inputs merged by time of validity and, at equal times, in
//! [`msgs::Channel`] order (aiding before the IMU sample of the same instant, the truth after
//! it) — the order the offline simulator emits — and read back into it by [`read_streams`].

pub mod csv_log;
pub mod kfgins;
pub mod kfgins_yaml;
pub mod text;

use crate::recorder::{
    CONFIG_KEY_FILTER_TOML, CONFIG_METADATA_NAME, OFFLINE_BATCH, OFFLINE_QUEUE, Record, Recorder,
    RecorderError, RecorderOptions,
};
use crate::recording::{Recording, RecordingError};
use fusion::navigator::NavigatorConfig;
use msgs::{BaroSample, GnssSample, ImuSample, NavSolution, OdometerSample, TruthSample};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub use text::TextError;

/// Metadata record name of an import's provenance (the one `sextant import rinex` writes).
pub use crate::import_rinex::IMPORT_METADATA_NAME;

/// Errors of log import and export.
#[derive(Debug, thiserror::Error)]
pub enum InterchangeError {
    /// A file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A value of a text file cannot be read.
    #[error(transparent)]
    Text(#[from] TextError),
    /// A CSV description (TOML) is invalid or does not match its CSV files.
    #[error("{}: {message}", path.display())]
    Description {
        /// The description or the CSV file it describes.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// Times of validity given as seconds of week need the GPS week.
    #[error(
        "{}: times are seconds of the GPS week; give the week (--week, or a reference trajectory file, which carries it)",
        path.display()
    )]
    NoWeek {
        /// The file.
        path: PathBuf,
    },
    /// Nothing to import.
    #[error("no samples to import")]
    Empty,
    /// The filter configuration could not be loaded or serialized.
    #[error("filter configuration: {0}")]
    Config(String),
    /// The recording could not be written.
    #[error(transparent)]
    Recorder(#[from] RecorderError),
    /// The recording could not be read.
    #[error(transparent)]
    Recording(#[from] RecordingError),
}

impl InterchangeError {
    /// An I/O error on `path`.
    pub fn io(path: &Path) -> impl FnOnce(std::io::Error) -> Self + '_ {
        move |source| Self::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// The samples of a log, per channel, each in time order.
#[derive(Debug, Clone, Default)]
pub struct Streams {
    /// IMU increments (body frame x forward, y right, z down).
    pub imu: Vec<ImuSample>,
    /// GNSS fixes (ECEF).
    pub gnss: Vec<GnssSample>,
    /// Odometer.
    pub odometer: Vec<OdometerSample>,
    /// Barometer.
    pub baro: Vec<BaroSample>,
    /// Reference trajectory (evaluation only).
    pub truth: Vec<TruthSample>,
    /// Navigation solutions (export only: a recording's solutions are recomputed by replay).
    pub nav: Vec<NavSolution>,
    /// Star-tracker samples of a recording: no interchange format carries them.
    pub star_tracker_skipped: u64,
}

/// Counts of a log import or export.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct Counts {
    /// IMU samples.
    pub imu: usize,
    /// GNSS fixes.
    pub gnss: usize,
    /// Odometer samples.
    pub odometer: usize,
    /// Barometer samples.
    pub baro: usize,
    /// Reference-trajectory samples.
    pub truth: usize,
    /// Navigation solutions.
    pub nav: usize,
    /// Star-tracker samples of the recording that no format carries (export).
    pub star_tracker_skipped: u64,
    /// First and last time of validity, GPS ns.
    pub first_time_ns: Option<i64>,
    /// Last time of validity, GPS ns.
    pub last_time_ns: Option<i64>,
    /// Files read or written.
    pub files: Vec<String>,
}

impl Streams {
    /// How many samples of each kind, and the time span.
    pub fn counts(&self) -> Counts {
        let times = self
            .imu
            .iter()
            .map(|s| s.header.time_ns)
            .chain(self.gnss.iter().map(|s| s.header.time_ns))
            .chain(self.odometer.iter().map(|s| s.header.time_ns))
            .chain(self.baro.iter().map(|s| s.header.time_ns))
            .chain(self.truth.iter().map(|s| s.header.time_ns));
        let (mut first, mut last) = (None::<i64>, None::<i64>);
        for t in times {
            first = Some(first.map_or(t, |f| f.min(t)));
            last = Some(last.map_or(t, |l| l.max(t)));
        }
        Counts {
            imu: self.imu.len(),
            gnss: self.gnss.len(),
            odometer: self.odometer.len(),
            baro: self.baro.len(),
            truth: self.truth.len(),
            nav: self.nav.len(),
            star_tracker_skipped: self.star_tracker_skipped,
            first_time_ns: first,
            last_time_ns: last,
            files: Vec::new(),
        }
    }

    /// The inputs and the truth as records, merged by time of validity, ties in
    /// [`msgs::Channel`] order; each sample's `seq` is its index in its channel and its
    /// `send_mono_ns` its time of validity (an imported log has no reception clock).
    pub fn records(&self) -> Vec<Record> {
        let mut out: Vec<Record> = Vec::new();
        fn push<T: Copy>(
            out: &mut Vec<Record>,
            v: &[T],
            header: impl Fn(&mut T) -> &mut msgs::Header,
            wrap: impl Fn(T) -> Record,
        ) {
            for (k, s) in v.iter().enumerate() {
                let mut s = *s;
                let h = header(&mut s);
                h.seq = k as u64;
                h.send_mono_ns = h.time_ns.max(0) as u64;
                out.push(wrap(s));
            }
        }
        push(&mut out, &self.imu, |s| &mut s.header, Record::Imu);
        push(
            &mut out,
            &self.gnss,
            |s| &mut s.header,
            |s| Record::Gnss(Box::new(s)),
        );
        push(
            &mut out,
            &self.odometer,
            |s| &mut s.header,
            Record::Odometer,
        );
        push(&mut out, &self.baro, |s| &mut s.header, Record::Baro);
        push(&mut out, &self.truth, |s| &mut s.header, Record::Truth);
        // A stable sort keeps each channel's file order among equal times.
        out.sort_by_key(|r| (record_time_ns(r), r.channel()));
        out
    }
}

/// Time of validity of a record, GPS ns.
pub fn record_time_ns(r: &Record) -> i64 {
    match r {
        Record::Imu(s) => s.header.time_ns,
        Record::StarTracker(s) => s.header.time_ns,
        Record::Gnss(s) => s.header.time_ns,
        Record::Odometer(s) => s.header.time_ns,
        Record::Baro(s) => s.header.time_ns,
        Record::Truth(s) => s.header.time_ns,
        Record::Nav(s) => s.header.time_ns,
        Record::Status(s) => s.header.time_ns,
        Record::SensorAlive(s) => s.header.time_ns,
    }
}

/// The filter configuration to embed: from a filter tuning or system configuration file, or
/// the default one.
pub fn filter_config(path: Option<&Path>) -> Result<NavigatorConfig, InterchangeError> {
    match path {
        Some(p) => crate::replay::load_filter_config(p)
            .map_err(|e| InterchangeError::Config(e.to_string())),
        None => Ok(NavigatorConfig::default()),
    }
}

/// Write `streams` as a recording at `out` with the filter configuration `filter` embedded
/// (so that `sextant replay --offline` runs it) and `provenance` under
/// [`IMPORT_METADATA_NAME`]. Returns the number of messages written.
pub fn write_recording(
    out: &Path,
    streams: &Streams,
    filter: &NavigatorConfig,
    provenance: BTreeMap<String, String>,
) -> Result<u64, InterchangeError> {
    let records = streams.records();
    if !records.iter().any(|r| !matches!(r, Record::Truth(_))) {
        return Err(InterchangeError::Empty);
    }
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(InterchangeError::io(dir))?;
    }
    let filter_toml =
        toml::to_string(filter).map_err(|e| InterchangeError::Config(e.to_string()))?;
    let config_meta = BTreeMap::from([(CONFIG_KEY_FILTER_TOML.to_string(), filter_toml)]);
    let recorder = Recorder::start(
        out,
        &RecorderOptions {
            metadata: vec![
                (CONFIG_METADATA_NAME.to_string(), config_meta),
                (IMPORT_METADATA_NAME.to_string(), provenance),
            ],
            queue_capacity: OFFLINE_QUEUE,
            ..Default::default()
        },
    )?;
    // A log has no reception clock: 0 makes the recorder's publish time the log time.
    let pb = crate::progress::steps(true, records.len() as u64, "writing the recording");
    let mut batch = recorder.batched(OFFLINE_BATCH);
    for (k, r) in records.into_iter().enumerate() {
        batch.record(r, 0);
        if k % 4096 == 0 {
            pb.set_position(k as u64);
        }
    }
    drop(batch);
    pb.finish_and_clear();
    Ok(recorder.finish()?.written)
}

/// The samples of a recording, per channel, and its embedded filter configuration (TOML text)
/// if any. A recording cut short (crash) gives what could be read.
pub fn read_streams(path: &Path) -> Result<(Streams, Option<String>), InterchangeError> {
    let rec = Recording::open(path)?;
    let filter = rec
        .metadata()
        .get(CONFIG_METADATA_NAME)
        .and_then(|m| m.get(CONFIG_KEY_FILTER_TOML))
        .cloned();
    let mut s = Streams::default();
    let pb = crate::progress::bytes(true, crate::progress::file_len(path), "reading");
    let mut n = 0u64;
    for entry in rec {
        let e = match entry {
            Ok(e) => e,
            Err(err) => {
                tracing::warn!("{}: read up to the error: {err}", path.display());
                break;
            }
        };
        n += 1;
        if n.is_multiple_of(4096) {
            pb.set_position(e.offset);
        }
        let Some(r) = e.record else { continue };
        match r {
            Record::Imu(x) => s.imu.push(x),
            Record::Gnss(x) => s.gnss.push(*x),
            Record::Odometer(x) => s.odometer.push(x),
            Record::Baro(x) => s.baro.push(x),
            Record::Truth(x) => s.truth.push(x),
            Record::Nav(x) => s.nav.push(x),
            Record::StarTracker(_) => s.star_tracker_skipped += 1,
            Record::Status(_) | Record::SensorAlive(_) => {}
        }
    }
    pb.finish_and_clear();
    Ok((s, filter))
}

/// Figures of an import or export as a terminal table.
pub fn format_counts(what: &str, c: &Counts) -> String {
    let mut t = format!(
        "| {what} | IMU | GNSS | odometer | baro | truth | solutions |\n|---|---|---|---|---|---|---|\n| samples | {} | {} | {} | {} | {} | {} |\n",
        c.imu, c.gnss, c.odometer, c.baro, c.truth, c.nav
    );
    if let (Some(a), Some(b)) = (c.first_time_ns, c.last_time_ns) {
        t.push_str(&format!(
            "time span: GPS {} s to {} s ({:.3} s)\n",
            text::format_seconds_ns(a),
            text::format_seconds_ns(b),
            (b - a) as f64 * 1e-9
        ));
    }
    if c.star_tracker_skipped > 0 {
        t.push_str(&format!(
            "star-tracker samples not exported (no format carries them): {}\n",
            c.star_tracker_skipped
        ));
    }
    for f in &c.files {
        t.push_str(&format!("{f}\n"));
    }
    t
}
