//! Post-analysis of a recording (`sextant report REC.mcap --out DIR`): errors against the truth
//! when the recording has it (RMS, maximum and 95th percentile of |e| per axis N/E/D, horizontal,
//! 3-D, velocity, attitude), the filter's consistency (fraction of errors inside ±3σ of its own
//! covariance), innovation statistics per sensor (NIS against its degrees of freedom, with the
//! χ² 95 % interval), rejections, mode changes, sensor dead/alive events and dropouts (gaps
//! longer than twice a channel's nominal period); PNG plots (trajectory, error with ±3σ
//! envelope, biases, boresight, NIS), `REPORT.md` and `summary.json`.
//!
//! Reads through [`crate::recording`] (the segments of a recording as one stream): a truncated
//! or corrupt recording is analysed up to the error, which the report names (with its byte
//! offset).
//!
//! # Bounded memory
//!
//! The recording is read once, front to back, and nothing is kept per message (measured on the
//! default scenario: 39 MB of peak resident memory for 1 h, 45 MB for a day, where keeping
//! every message took 452 MB for 1 h; `docs/RESULTS.md`). What is exact and what is not:
//!
//! - **Exact**: counts, solutions matched, RMS and maximum of every error, the fraction within
//!   ±3σ, NIS per dof and the other figures of the last status, final estimates, navigation
//!   duration, mode changes and dead/alive events (the first [`MAX_LISTED_EVENTS`] of each
//!   listed, the totals complete), dropouts for the threshold used (count and longest gap
//!   complete, the first 200 listed).
//! - **Solution ↔ truth matching** by identical time of validity, both streams time ordered
//!   but interleaved in arrival order (a crashed recording is read by the same non-seeking
//!   scan): unmatched solutions and truth samples wait in the reorder window of `sextant run`'s
//!   analysis (`analysis::MATCH_WINDOW_NS`, 60 s of time of validity) and are dropped beyond
//!   it. The recorder writes both within milliseconds, so every pair is found (the same count
//!   as a whole-file join); a truth at another rate than the solutions just leaves the
//!   solutions between its samples unmatched, as before.
//! - **95th percentiles**: from [`StreamingPercentiles::relative`] histograms (≈ 35 000 bins,
//!   0.4 MB per figure), within [`P95_RELATIVE_RESOLUTION`] (0.1 %) of the exact percentile of
//!   the values, within 1e-6 (m, m/s, deg) below 1e-6, exact when the values it is read from
//!   are equal.
//! - **Nominal period of a channel** (the dropout threshold is twice it): the median of its first
//!   [`PERIOD_SAMPLES`] periods (65 536: 65 s of a 1 kHz IMU, 18 h of a 1 Hz receiver) instead
//!   of the median of all of them: the same on a channel of constant rate and on every channel
//!   shorter than that (all periods taken). The dropouts are then exact for that threshold.
//! - **Plots**: from series thinned as they grow (`analysis::Thinned`): between 4 000 and
//!   8 000 points evenly spaced over the recording (every point of a shorter one); the NIS plot
//!   keeps the status' cumulative sums, so a thinned point is the NIS per dof over a longer
//!   window, not a sampled one.

use crate::analysis::{self, MATCH_WINDOW_NS, Matched, Series, Thinned, Window};
use crate::experiments::plot::{Chart, Line, color, line_chart};
use crate::recorder::Record;
use crate::recording::{Recording, RecordingError};
use crate::stats::{RmsMax, StreamingPercentiles, percentile};
use msgs::{MAX_SENSORS, NavMode, NavSolution, SensorId, Status, TruthSample};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Errors of the report.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// The recording could not be opened.
    #[error(transparent)]
    Recording(#[from] RecordingError),
    /// The file is a readable MCAP but holds no Sextant message (another program's recording,
    /// or an empty one): there is nothing to report on.
    #[error(
        "{path} holds no Sextant message ({messages} messages on other topics{topics}): not a Sextant recording, or an empty one"
    )]
    NotSextant {
        /// The file.
        path: PathBuf,
        /// Messages it holds on topics Sextant does not know.
        messages: u64,
        /// `: a, b, …` — the first of those topics, or empty.
        topics: String,
    },
    /// Writing an output file failed.
    #[error("cannot write {path}: {detail}")]
    Write {
        /// The file.
        path: PathBuf,
        /// What failed.
        detail: String,
    },
}

/// RMS, maximum and 95th percentile of the absolute value of one error component.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq)]
pub struct ErrorStats {
    /// Root mean square.
    pub rms: Option<f64>,
    /// Largest absolute value.
    pub max: Option<f64>,
    /// 95th percentile of the absolute value: within [`P95_RELATIVE_RESOLUTION`] of it
    /// (streaming estimate, see the module documentation).
    pub p95: Option<f64>,
    /// Fraction of samples with |error| ≤ 3σ of the filter's own covariance (≈ 0.997 for a
    /// consistent filter with Gaussian errors); `None` where no σ applies.
    pub within_3sigma_fraction: Option<f64>,
}

/// Errors of the solution against truth.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct TruthErrors {
    /// Solutions matched with a truth sample of identical time of validity.
    pub solutions_matched: u64,
    /// North position error, m.
    pub position_north_m: ErrorStats,
    /// East position error, m.
    pub position_east_m: ErrorStats,
    /// Down position error, m.
    pub position_down_m: ErrorStats,
    /// Horizontal position error, m.
    pub position_horizontal_m: ErrorStats,
    /// 3-D position error, m.
    pub position_3d_m: ErrorStats,
    /// North velocity error, m/s.
    pub velocity_north_m_s: ErrorStats,
    /// East velocity error, m/s.
    pub velocity_east_m_s: ErrorStats,
    /// Down velocity error, m/s.
    pub velocity_down_m_s: ErrorStats,
    /// Attitude error about north (rotation vector of q_est ⊗ q_true⁻¹ in NED), deg.
    pub attitude_north_deg: ErrorStats,
    /// Attitude error about east, deg.
    pub attitude_east_deg: ErrorStats,
    /// Attitude error about down (heading), deg.
    pub attitude_down_deg: ErrorStats,
    /// Attitude error angle, deg.
    pub attitude_angle_deg: ErrorStats,
}

/// Innovation and health figures of one sensor (from the last status).
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct SensorReport {
    /// Sensor name.
    pub sensor: String,
    /// Samples recorded on its channel.
    pub samples_recorded: u64,
    /// Samples received by the filter.
    pub received: u64,
    /// Samples fused.
    pub fused: u64,
    /// Rejected by the innovation gate.
    pub rejected_gate: u64,
    /// Rejected as malformed.
    pub rejected_invalid: u64,
    /// Dropped as too late.
    pub dropped_late: u64,
    /// Deadline misses.
    pub deadline_misses: u32,
    /// Updates with a NIS.
    pub nis_updates: u64,
    /// Mean NIS per update.
    pub nis_mean: Option<f64>,
    /// Mean measurement dimension per update (the expected mean NIS).
    pub nis_dof_mean: Option<f64>,
    /// Σ NIS / Σ dof: 1 for a consistent filter.
    pub nis_over_dof: Option<f64>,
    /// 95 % interval of Σ NIS / Σ dof for a consistent filter: Σ NIS ~ χ²(Σ dof), so the ratio
    /// has mean 1 and standard deviation √(2/Σ dof).
    pub nis_over_dof_95_interval: Option<[f64; 2]>,
    /// Nominal period of the channel (time of validity), s: the median of its first
    /// [`PERIOD_SAMPLES`] periods (of all of them in a shorter channel).
    pub period_s: Option<f64>,
    /// Gaps longer than twice that period (every one counted).
    pub dropouts: u64,
    /// Longest gap, s.
    pub longest_gap_s: Option<f64>,
}

/// A change of navigation mode.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ModeChange {
    /// Time since the start of the recording, s.
    pub time_s: f64,
    /// Previous mode.
    pub from: String,
    /// New mode.
    pub to: String,
}

/// A gap in a sensor channel.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Dropout {
    /// Channel.
    pub channel: String,
    /// Start (last sample before the gap), s since the start of the recording.
    pub start_s: f64,
    /// Length of the gap, s.
    pub gap_s: f64,
}

/// A sensor dead/alive decision of the daemon.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct AliveEvent {
    /// Time (filter time) since the start, s.
    pub time_s: f64,
    /// Sensor.
    pub sensor: String,
    /// Alive (true) or silent beyond its deadline (false).
    pub alive: bool,
}

/// The figures of a report (`summary.json`).
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct ReportSummary {
    /// The recording.
    pub recording: String,
    /// Footer read: the recording was finished.
    pub recording_complete: bool,
    /// The error that stopped reading (truncation or corruption, with its byte offset).
    pub recording_error: Option<String>,
    /// Span of the solution's time of validity, s.
    pub navigation_duration_s: f64,
    /// Solutions recorded.
    pub solutions: u64,
    /// Errors against the truth (absent without truth).
    pub truth_errors: Option<TruthErrors>,
    /// Per sensor.
    pub sensors: Vec<SensorReport>,
    /// Mode changes of the solution (at most the first [`MAX_LISTED_EVENTS`] listed).
    pub mode_changes: Vec<ModeChange>,
    /// Mode changes of the solution, all of them.
    pub mode_changes_total: u64,
    /// Sensor dead/alive events (at most the first [`MAX_LISTED_EVENTS`] listed).
    pub alive_events: Vec<AliveEvent>,
    /// Sensor dead/alive events, all of them.
    pub alive_events_total: u64,
    /// Dropouts (at most the first 200 listed; the count per sensor is complete).
    pub dropouts: Vec<Dropout>,
    /// Final gyro bias estimate, deg/h (body x, y, z).
    pub final_gyro_bias_deg_h: Option<[f64; 3]>,
    /// Final accelerometer bias estimate, µg.
    pub final_accel_bias_ug: Option<[f64; 3]>,
    /// Final boresight estimate κ1..κ3, arcsec.
    pub final_boresight_arcsec: Option<[f64; 3]>,
    /// Final boresight 1σ, arcsec.
    pub final_boresight_sigma_arcsec: Option<[f64; 3]>,
    /// Records the recorder dropped (last status).
    pub records_dropped: u64,
    /// Recorder write errors (last status).
    pub recorder_errors: u64,
    /// Plots written.
    pub plots: Vec<String>,
}

const G: f64 = 9.80665;
const DEG_H: f64 = std::f64::consts::PI / 180.0 / 3600.0;
const ARCSEC: f64 = std::f64::consts::PI / 180.0 / 3600.0;

/// Rotation vector (NED, rad) of q_est ⊗ q_true⁻¹ for attitudes `q_ned_body` = [w, x, y, z]:
/// the small rotation that takes the true body-to-NED attitude to the estimate.
pub fn attitude_error_ned_rad(q_true: [f64; 4], q_est: [f64; 4]) -> [f64; 3] {
    let [w, x, y, z] = q_true;
    let mut e = analysis::q_mul(q_est, [w, -x, -y, -z]);
    if e[0] < 0.0 {
        e = e.map(|c| -c);
    }
    let v = (e[1] * e[1] + e[2] * e[2] + e[3] * e[3]).sqrt();
    if v < 1e-300 {
        return [0.0; 3];
    }
    let angle = 2.0 * v.atan2(e[0]);
    [e[1] / v * angle, e[2] / v * angle, e[3] / v * angle]
}

/// Time series for the plots, built from the thinned series at the end.
#[derive(Debug, Default)]
struct Plots {
    t: Vec<f64>,
    err: [Vec<f64>; 3],
    sig: [Vec<f64>; 3],
    att: [Vec<f64>; 3],
    att_sig: [Vec<f64>; 3],
    nav_t: Vec<f64>,
    gyro: [Vec<f64>; 3],
    accel: [Vec<f64>; 3],
    truth_t: Vec<f64>,
    truth_gyro: [Vec<f64>; 3],
    truth_accel: [Vec<f64>; 3],
    bore: [Vec<f64>; 3],
    bore_sig: [Vec<f64>; 3],
    nis: [Vec<(f64, f64)>; MAX_SENSORS],
}

/// Each plotted series holds between `MAX_POINTS` and twice as many points (all of them when
/// there are fewer), evenly spaced over the recording ([`Thinned`]).
const MAX_POINTS: usize = 4000;

/// Dropouts listed in `summary.json` and `REPORT.md` (the count per sensor is complete).
const MAX_LISTED_DROPOUTS: usize = 200;

/// Mode changes and dead/alive events listed (their totals are complete).
pub const MAX_LISTED_EVENTS: usize = 10_000;

/// Periods of a channel whose median is its nominal period ([`SensorReport::period_s`]).
pub const PERIOD_SAMPLES: usize = 65_536;

/// Relative resolution of the 95th percentiles (see [`StreamingPercentiles::relative`]).
pub const P95_RELATIVE_RESOLUTION: f64 = 1e-3;

/// Below this |error| (m, m/s or deg) a 95th percentile is within this value instead of
/// within [`P95_RELATIVE_RESOLUTION`]; above [`P95_MAX`], exact.
const P95_MIN: f64 = 1e-6;
const P95_MAX: f64 = 1e9;

/// RMS, maximum, 95th percentile and ±3σ count of one error component, in bounded memory.
struct ErrorAcc {
    rms_max: RmsMax,
    abs: StreamingPercentiles,
    within_3sigma: u64,
    with_sigma: bool,
}

impl ErrorAcc {
    fn new(with_sigma: bool) -> Self {
        Self {
            rms_max: RmsMax::default(),
            abs: StreamingPercentiles::relative(P95_RELATIVE_RESOLUTION, P95_MIN, P95_MAX),
            within_3sigma: 0,
            with_sigma,
        }
    }

    /// One error and the filter's 1σ of it (counted only for components with a σ).
    fn push(&mut self, e: f64, sigma: f64) {
        self.rms_max.push(e);
        self.abs.push(e.abs());
        if e.abs() <= 3.0 * sigma {
            self.within_3sigma += 1;
        }
    }

    fn stats(&mut self) -> ErrorStats {
        ErrorStats {
            rms: self.rms_max.rms(),
            max: self.rms_max.max_abs(),
            p95: self.abs.percentile(95.0),
            within_3sigma_fraction: self
                .with_sigma
                .then(|| self.within_3sigma as f64 / self.rms_max.count().max(1) as f64),
        }
    }
}

/// One matched solution of the error plots: time of validity, NED position error and its 3σ
/// (m), attitude error about N/E/D and its 3σ (deg).
#[derive(Debug, Clone, Copy)]
struct ErrorPoint {
    t_ns: i64,
    err_m: [f64; 3],
    sig3_m: [f64; 3],
    att_deg: [f64; 3],
    att_sig3_deg: [f64; 3],
}

/// One solution of the estimate plots: gyro bias (deg/h), accelerometer bias (µg), boresight
/// and its 3σ (arcsec).
#[derive(Debug, Clone, Copy)]
struct EstimatePoint {
    t_ns: i64,
    gyro_deg_h: [f64; 3],
    accel_ug: [f64; 3],
    bore_arcsec: [f64; 3],
    bore_sig3_arcsec: [f64; 3],
}

/// One truth sample of the bias plots.
#[derive(Debug, Clone, Copy)]
struct TruthPoint {
    t_ns: i64,
    gyro_deg_h: [f64; 3],
    accel_ug: [f64; 3],
}

/// One status's cumulative innovation sums per sensor: NIS per dof between two kept statuses
/// is the difference of their sums, so thinning the statuses widens the window of a plotted
/// point without losing an update.
#[derive(Debug, Clone, Copy)]
struct NisPoint {
    t_ns: i64,
    nis_sum: [f64; MAX_SENSORS],
    dof_sum: [u64; MAX_SENSORS],
}

impl NisPoint {
    fn of(st: &Status) -> Self {
        Self {
            t_ns: st.header.time_ns,
            nis_sum: std::array::from_fn(|i| st.sensors[i].nis_sum),
            dof_sum: std::array::from_fn(|i| st.sensors[i].nis_dof_sum),
        }
    }
}

/// Errors against the truth, accumulated over the matched solutions.
struct TruthAcc {
    pos: [ErrorAcc; 3],
    horizontal: ErrorAcc,
    d3: ErrorAcc,
    vel: [ErrorAcc; 3],
    att: [ErrorAcc; 3],
    angle: ErrorAcc,
    plot: Thinned<ErrorPoint>,
}

impl TruthAcc {
    fn new() -> Self {
        Self {
            pos: std::array::from_fn(|_| ErrorAcc::new(true)),
            horizontal: ErrorAcc::new(false),
            d3: ErrorAcc::new(false),
            vel: std::array::from_fn(|_| ErrorAcc::new(false)),
            att: std::array::from_fn(|_| ErrorAcc::new(true)),
            angle: ErrorAcc::new(false),
            plot: Thinned::new(MAX_POINTS),
        }
    }

    /// A solution matched with the truth sample of its time of validity; false when its
    /// errors are not finite (not counted).
    fn solution(&mut self, n: &NavSolution, t: &TruthSample) -> bool {
        let e = analysis::position_error_ned_m(n, t);
        let a = attitude_error_ned_rad(t.q_ned_body, n.q_ned_body);
        if !(e.iter().chain(&a).all(|x| x.is_finite())) {
            return false;
        }
        for i in 0..3 {
            self.pos[i].push(e[i], n.pos_sigma_ned_m[i]);
            self.vel[i].push(n.vel_ned_m_s[i] - t.vel_ned_m_s[i], 0.0);
            self.att[i].push(a[i].to_degrees(), n.att_sigma_ned_rad[i].to_degrees());
        }
        self.horizontal.push(e[0].hypot(e[1]), 0.0);
        self.d3
            .push((e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt(), 0.0);
        self.angle.push(
            analysis::attitude_error_rad(t.q_ned_body, n.q_ned_body).to_degrees(),
            0.0,
        );
        self.plot.push_with(|| ErrorPoint {
            t_ns: n.header.time_ns,
            err_m: e,
            sig3_m: n.pos_sigma_ned_m.map(|s| 3.0 * s),
            att_deg: a.map(f64::to_degrees),
            att_sig3_deg: n.att_sigma_ned_rad.map(|s| 3.0 * s.to_degrees()),
        });
        true
    }

    fn errors(&mut self) -> Option<TruthErrors> {
        let matched = self.horizontal.rms_max.count();
        (matched > 0).then(|| TruthErrors {
            solutions_matched: matched,
            position_north_m: self.pos[0].stats(),
            position_east_m: self.pos[1].stats(),
            position_down_m: self.pos[2].stats(),
            position_horizontal_m: self.horizontal.stats(),
            position_3d_m: self.d3.stats(),
            velocity_north_m_s: self.vel[0].stats(),
            velocity_east_m_s: self.vel[1].stats(),
            velocity_down_m_s: self.vel[2].stats(),
            attitude_north_deg: self.att[0].stats(),
            attitude_east_deg: self.att[1].stats(),
            attitude_down_deg: self.att[2].stats(),
            attitude_angle_deg: self.angle.stats(),
        })
    }
}

/// One sensor channel's sample times, in bounded memory: the first [`PERIOD_SAMPLES`] periods
/// are held until their median fixes the nominal period; from then on each gap is checked
/// against twice that period as it arrives.
#[derive(Debug, Default)]
struct ChannelTimes {
    samples: u64,
    /// Times held while the period is not yet known.
    head: Vec<i64>,
    /// Positive periods among `head`.
    head_periods: usize,
    /// Nominal period, s.
    period_s: Option<f64>,
    last_ns: Option<i64>,
    dropouts: u64,
    /// The first [`MAX_LISTED_DROPOUTS`]: (time of the last sample before the gap, gap s).
    listed: Vec<(i64, f64)>,
    longest_gap_s: Option<f64>,
}

impl ChannelTimes {
    fn sample(&mut self, t_ns: i64) {
        self.samples += 1;
        if self.period_s.is_some() {
            self.gap(t_ns);
            return;
        }
        if let Some(&prev) = self.head.last()
            && t_ns > prev
        {
            self.head_periods += 1;
        }
        self.head.push(t_ns);
        if self.head_periods >= PERIOD_SAMPLES {
            self.fix_period();
        }
    }

    /// The median of the held periods becomes the nominal period; the held gaps are checked.
    fn fix_period(&mut self) {
        let dt: Vec<f64> = self
            .head
            .windows(2)
            .map(|w| (w[1] - w[0]) as f64 * 1e-9)
            .filter(|d| *d > 0.0)
            .collect();
        let Some(period) = percentile(&dt, 50.0) else {
            return;
        };
        self.period_s = Some(period);
        let head = std::mem::take(&mut self.head);
        self.last_ns = head.first().copied();
        for &t in &head[1..] {
            self.gap(t);
        }
    }

    /// The next sample once the period is known.
    fn gap(&mut self, t_ns: i64) {
        let (Some(prev), Some(period)) = (self.last_ns, self.period_s) else {
            return;
        };
        self.last_ns = Some(t_ns);
        let gap = (t_ns - prev) as f64 * 1e-9;
        if gap > 0.0 {
            self.longest_gap_s = Some(self.longest_gap_s.map_or(gap, |g| g.max(gap)));
        }
        if gap > 2.0 * period {
            self.dropouts += 1;
            if self.listed.len() < MAX_LISTED_DROPOUTS {
                self.listed.push((prev, gap));
            }
        }
    }
}

/// Analyse `path` and write `summary.json`, `REPORT.md` and the plots into `out_dir`.
pub fn report(path: &Path, out_dir: &Path) -> Result<ReportSummary, ReportError> {
    let werr = |p: &Path, e: &dyn std::fmt::Display| ReportError::Write {
        path: p.to_path_buf(),
        detail: e.to_string(),
    };
    std::fs::create_dir_all(out_dir).map_err(|e| werr(out_dir, &e))?;
    let rec = Recording::open(path)?;
    let mut s = ReportSummary {
        recording: path.display().to_string(),
        ..Default::default()
    };
    let mut first_truth: Option<TruthSample> = None;
    let mut window = Window::default();
    let mut truth_acc = TruthAcc::new();
    let mut matched = Matched::with_series_points(&[], MAX_POINTS);
    let mut truth_plot: Thinned<TruthPoint> = Thinned::new(MAX_POINTS);
    let mut nav_plot: Thinned<EstimatePoint> = Thinned::new(MAX_POINTS);
    let mut nis_plot: Thinned<NisPoint> = Thinned::new(MAX_POINTS);
    let mut first_nav_ns: Option<i64> = None;
    let mut last_nav: Option<NavSolution> = None;
    let mut last_status: Option<Status> = None;
    let mut channels: [ChannelTimes; MAX_SENSORS] = Default::default();
    // (time of validity, from, to); (time, sensor, alive).
    let mut modes: Vec<(i64, Option<u32>, u32)> = Vec::new();
    let mut alive: Vec<(i64, u32, bool)> = Vec::new();
    let mut t_start = i64::MAX;
    let (mut sextant_records, mut foreign) = (0u64, 0u64);
    let mut foreign_topics: Vec<String> = Vec::new();
    let pb = crate::progress::bytes(true, crate::progress::file_len(path), "report");
    let mut n = 0u64;
    // Decompressing and decoding on a thread of their own, the statistics here.
    let mut entries = rec.read_ahead();
    for e in &mut entries {
        let e = match e {
            Ok(e) => e,
            Err(err) => {
                tracing::warn!("report: {err}");
                s.recording_error = Some(err.to_string());
                break;
            }
        };
        n += 1;
        if n.is_multiple_of(4096) {
            pb.set_position(e.offset);
        }
        let Some(r) = e.record else {
            foreign += 1;
            if foreign_topics.len() < 5 && !foreign_topics.iter().any(|t| **t == *e.topic) {
                foreign_topics.push(e.topic.to_string());
            }
            continue;
        };
        sextant_records += 1;
        let t = r.header().time_ns;
        if t > 0 {
            t_start = t_start.min(t);
        }
        match r {
            Record::Imu(_) => channels[SensorId::Imu as usize].sample(t),
            Record::StarTracker(_) => channels[SensorId::StarTracker as usize].sample(t),
            Record::Gnss(_) => channels[SensorId::Gnss as usize].sample(t),
            Record::Odometer(_) => channels[SensorId::Odometer as usize].sample(t),
            Record::Baro(_) => channels[SensorId::Baro as usize].sample(t),
            Record::Truth(tr) => {
                let origin = *first_truth.get_or_insert(tr);
                truth_plot.push_with(|| TruthPoint {
                    t_ns: t,
                    gyro_deg_h: tr.gyro_bias_rad_s.map(|x| x / DEG_H),
                    accel_ug: tr.accel_bias_m_s2.map(|x| x / G * 1e6),
                });
                let (navs, _fixes) = window.truth(tr);
                for nav in &navs {
                    if truth_acc.solution(nav, &tr) {
                        matched.solution(nav, &tr, &origin);
                    }
                }
            }
            Record::Nav(nav) => {
                first_nav_ns.get_or_insert(t);
                let prev_mode = last_nav.as_ref().map(|p| p.mode);
                if prev_mode != Some(nav.mode) {
                    if modes.len() < MAX_LISTED_EVENTS {
                        modes.push((t, prev_mode, nav.mode));
                    }
                    s.mode_changes_total += 1;
                }
                last_nav = Some(nav);
                s.solutions += 1;
                nav_plot.push_with(|| EstimatePoint {
                    t_ns: t,
                    gyro_deg_h: nav.gyro_bias_rad_s.map(|x| x / DEG_H),
                    accel_ug: nav.accel_bias_m_s2.map(|x| x / G * 1e6),
                    bore_arcsec: nav.boresight_rad.map(|x| x / ARCSEC),
                    bore_sig3_arcsec: nav.boresight_sigma_rad.map(|x| 3.0 * x / ARCSEC),
                });
                window.nav(&nav, |nav, tr| {
                    if let Some(origin) = &first_truth
                        && truth_acc.solution(nav, tr)
                    {
                        matched.solution(nav, tr, origin);
                    }
                });
            }
            Record::Status(st) => {
                nis_plot.push_with(|| NisPoint::of(&st));
                last_status = Some(*st);
            }
            Record::SensorAlive(ev) => {
                if alive.len() < MAX_LISTED_EVENTS {
                    alive.push((t, ev.sensor, ev.alive));
                }
                s.alive_events_total += 1;
            }
        }
        if t > 0 {
            window.evict_before(t - MATCH_WINDOW_NS);
        }
    }
    pb.finish_and_clear();
    s.recording_complete = entries.into_recording().is_some_and(|r| r.is_complete());
    if sextant_records == 0 {
        return Err(ReportError::NotSextant {
            path: path.to_path_buf(),
            messages: foreign,
            topics: if foreign_topics.is_empty() {
                String::new()
            } else {
                format!(": {}", foreign_topics.join(", "))
            },
        });
    }
    if t_start == i64::MAX {
        t_start = 0;
    }
    let secs = |t: i64| (t - t_start) as f64 * 1e-9;
    if let (Some(a), Some(b)) = (first_nav_ns, &last_nav) {
        s.navigation_duration_s = (b.header.time_ns - a) as f64 * 1e-9;
        s.final_gyro_bias_deg_h = Some(b.gyro_bias_rad_s.map(|x| x / DEG_H));
        s.final_accel_bias_ug = Some(b.accel_bias_m_s2.map(|x| x / G * 1e6));
        s.final_boresight_arcsec = Some(b.boresight_rad.map(|x| x / ARCSEC));
        s.final_boresight_sigma_arcsec = Some(b.boresight_sigma_rad.map(|x| x / ARCSEC));
    }

    // Mode changes and dead/alive events.
    let mode_name = |m: u32| {
        NavMode::from_u32(m)
            .map(|m| m.name().to_string())
            .unwrap_or_else(|| format!("unknown({m})"))
    };
    s.mode_changes = modes
        .iter()
        .map(|&(t, from, to)| ModeChange {
            time_s: secs(t),
            from: from.map(mode_name).unwrap_or_else(|| "none".into()),
            to: mode_name(to),
        })
        .collect();
    s.alive_events = alive
        .iter()
        .map(|&(t, sensor, a)| AliveEvent {
            // Decisions before the first IMU sample carry filter time 0: report them at 0.
            time_s: if t > 0 { secs(t) } else { 0.0 },
            sensor: SensorId::ALL
                .get(sensor as usize)
                .map(|x| x.name().to_string())
                .unwrap_or_else(|| sensor.to_string()),
            alive: a,
        })
        .collect();

    // Errors against truth.
    s.truth_errors = truth_acc.errors();
    let mut p = Plots::default();
    let mut errs = truth_acc.plot.into_points();
    errs.sort_by_key(|e| e.t_ns);
    for e in &errs {
        p.t.push(secs(e.t_ns));
        for i in 0..3 {
            p.err[i].push(e.err_m[i]);
            p.sig[i].push(e.sig3_m[i]);
            p.att[i].push(e.att_deg[i]);
            p.att_sig[i].push(e.att_sig3_deg[i]);
        }
    }
    for e in nav_plot.points() {
        p.nav_t.push(secs(e.t_ns));
        for i in 0..3 {
            p.gyro[i].push(e.gyro_deg_h[i]);
            p.accel[i].push(e.accel_ug[i]);
            p.bore[i].push(e.bore_arcsec[i]);
            p.bore_sig[i].push(e.bore_sig3_arcsec[i]);
        }
    }
    let mut truths = truth_plot.into_points();
    truths.sort_by_key(|e| e.t_ns);
    for e in &truths {
        p.truth_t.push(secs(e.t_ns));
        for i in 0..3 {
            p.truth_gyro[i].push(e.gyro_deg_h[i]);
            p.truth_accel[i].push(e.accel_ug[i]);
        }
    }
    // The series of `sextant run`'s plots (trajectory, horizontal/vertical/attitude error),
    // its times from the first truth sample moved to the report's start.
    let series = match &first_truth {
        Some(o) => matched.series.into_series(secs(o.header.time_ns), t_start),
        None => Series {
            t0_ns: t_start,
            ..Default::default()
        },
    };

    // Per sensor: health and NIS from the last status, dropouts from the recorded times.
    let last = last_status.unwrap_or_default();
    s.records_dropped = last.records_dropped;
    s.recorder_errors = last.recorder_errors;
    let mut nis_points = nis_plot.into_points();
    if let Some(st) = &last_status
        && nis_points
            .last()
            .is_some_and(|p| p.t_ns != st.header.time_ns)
    {
        nis_points.push(NisPoint::of(st));
    }
    let mut dropouts: Vec<Dropout> = Vec::new();
    for sensor in SensorId::ALL {
        let i = sensor as usize;
        let h = last.sensors[i];
        let ch = &mut channels[i];
        if ch.period_s.is_none() {
            ch.fix_period();
        }
        let mut r = SensorReport {
            sensor: sensor.name().to_string(),
            samples_recorded: ch.samples,
            received: h.received,
            fused: h.fused,
            rejected_gate: h.rejected_gate,
            rejected_invalid: h.rejected_invalid,
            dropped_late: h.dropped_late,
            deadline_misses: h.deadline_misses,
            nis_updates: h.nis_count,
            period_s: ch.period_s,
            dropouts: ch.dropouts,
            longest_gap_s: ch.longest_gap_s,
            ..Default::default()
        };
        if h.nis_count > 0 && h.nis_dof_sum > 0 {
            let dof = h.nis_dof_sum as f64;
            r.nis_mean = Some(h.nis_sum / h.nis_count as f64);
            r.nis_dof_mean = Some(dof / h.nis_count as f64);
            r.nis_over_dof = Some(h.nis_sum / dof);
            let sd = (2.0 / dof).sqrt();
            r.nis_over_dof_95_interval = Some([1.0 - 1.96 * sd, 1.0 + 1.96 * sd]);
        }
        for &(t, gap) in &ch.listed {
            if dropouts.len() < MAX_LISTED_DROPOUTS {
                dropouts.push(Dropout {
                    channel: sensor.name().to_string(),
                    start_s: secs(t),
                    gap_s: gap,
                });
            }
        }
        s.sensors.push(r);
        // NIS per dof between consecutive (kept) statuses: windowed innovation consistency.
        for w in nis_points.windows(2) {
            let dof = w[1].dof_sum[i].saturating_sub(w[0].dof_sum[i]);
            if dof > 0 {
                p.nis[i].push((
                    secs(w[1].t_ns),
                    (w[1].nis_sum[i] - w[0].nis_sum[i]) / dof as f64,
                ));
            }
        }
    }
    s.dropouts = dropouts;

    // Plots.
    let mut files = Vec::new();
    match crate::plots::write_plots(out_dir, &series) {
        Ok(f) => files.extend(f),
        Err(e) => tracing::warn!("{e}"),
    }
    files.extend(write_report_plots(out_dir, &p));
    s.plots = files
        .iter()
        .filter_map(|f| f.file_name().map(|n| n.to_string_lossy().to_string()))
        .collect();

    let json = out_dir.join("summary.json");
    let text = serde_json::to_string_pretty(&s).map_err(|e| werr(&json, &e))?;
    std::fs::write(&json, text).map_err(|e| werr(&json, &e))?;
    let md = out_dir.join("REPORT.md");
    std::fs::write(&md, markdown(&s)).map_err(|e| werr(&md, &e))?;
    Ok(s)
}

fn line(label: &str, t: &[f64], y: &[f64], color: plotters::style::RGBColor, dashed: bool) -> Line {
    Line {
        label: label.to_string(),
        points: t.iter().copied().zip(y.iter().copied()).collect(),
        color,
        dashed,
        markers: false,
    }
}

fn write_report_plots(dir: &Path, p: &Plots) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut draw = |name: &str, title: &str, y_label: &str, lines: Vec<Line>| {
        if lines.iter().all(|l| l.points.is_empty()) {
            return;
        }
        let path = dir.join(name);
        match line_chart(
            &path,
            &Chart::linear(title, "time since start [s]", y_label, &lines),
        ) {
            Ok(()) => out.push(path),
            Err(e) => tracing::warn!("plot {}: {e}", path.display()),
        }
    };
    for (i, axis) in ["north", "east", "down"].into_iter().enumerate() {
        let neg: Vec<f64> = p.sig[i].iter().map(|x| -x).collect();
        draw(
            &format!("error_{axis}_3sigma.png"),
            &format!("{axis} position error and ±3σ of the filter"),
            "error [m]",
            vec![
                line("error", &p.t, &p.err[i], color(0), false),
                line("+3σ", &p.t, &p.sig[i], color(1), true),
                line("−3σ", &p.t, &neg, color(1), true),
            ],
        );
    }
    let neg: Vec<f64> = p.att_sig[2].iter().map(|x| -x).collect();
    draw(
        "heading_error_3sigma.png",
        "attitude error about down (heading) and ±3σ",
        "error [deg]",
        vec![
            line("error", &p.t, &p.att[2], color(0), false),
            line("+3σ", &p.t, &p.att_sig[2], color(1), true),
            line("−3σ", &p.t, &neg, color(1), true),
        ],
    );
    let mut gyro = Vec::new();
    let mut accel = Vec::new();
    let mut bore = Vec::new();
    for (i, axis) in ["x", "y", "z"].into_iter().enumerate() {
        gyro.push(line(
            &format!("estimate {axis}"),
            &p.nav_t,
            &p.gyro[i],
            color(i),
            false,
        ));
        gyro.push(line(
            &format!("truth {axis}"),
            &p.truth_t,
            &p.truth_gyro[i],
            color(i),
            true,
        ));
        accel.push(line(
            &format!("estimate {axis}"),
            &p.nav_t,
            &p.accel[i],
            color(i),
            false,
        ));
        accel.push(line(
            &format!("truth {axis}"),
            &p.truth_t,
            &p.truth_accel[i],
            color(i),
            true,
        ));
        bore.push(line(
            &format!("κ{}", i + 1),
            &p.nav_t,
            &p.bore[i],
            color(i),
            false,
        ));
        bore.push(line(
            &format!("3σ κ{}", i + 1),
            &p.nav_t,
            &p.bore_sig[i],
            color(i),
            true,
        ));
    }
    draw(
        "gyro_bias.png",
        "gyro bias: estimate and truth",
        "bias [deg/h]",
        gyro,
    );
    draw(
        "accel_bias.png",
        "accelerometer bias: estimate and truth",
        "bias [µg]",
        accel,
    );
    draw(
        "boresight.png",
        "star-tracker boresight estimate and 3σ",
        "angle [arcsec]",
        bore,
    );
    let mut nis = Vec::new();
    for s in SensorId::ALL {
        let v = &p.nis[s as usize];
        if !v.is_empty() {
            nis.push(Line {
                label: s.name().to_string(),
                points: v.clone(),
                color: color(s as usize),
                dashed: false,
                markers: true,
            });
        }
    }
    if let (Some(a), Some(b)) = (p.nav_t.first(), p.nav_t.last()) {
        nis.push(Line {
            label: "consistent (1)".into(),
            points: vec![(*a, 1.0), (*b, 1.0)],
            color: plotters::style::RGBColor(0, 0, 0),
            dashed: true,
            markers: false,
        });
    }
    draw(
        "nis.png",
        "innovations: NIS per degree of freedom between statuses",
        "NIS / dof",
        nis,
    );
    out
}

fn f(v: Option<f64>, prec: usize) -> String {
    v.map(|x| format!("{x:.prec$}"))
        .unwrap_or_else(|| "—".into())
}

/// The report as Markdown.
pub fn markdown(s: &ReportSummary) -> String {
    let mut m = String::new();
    m.push_str(&format!("# Sextant report: `{}`\n\n", s.recording));
    if let Some(e) = &s.recording_error {
        m.push_str(&format!(
            "**The recording is incomplete:** {e}. Everything before that point is analysed.\n\n"
        ));
    }
    m.push_str(&format!(
        "Navigation {:.1} s, {} solutions. Recorder: {} records dropped, {} write errors.\n\n",
        s.navigation_duration_s, s.solutions, s.records_dropped, s.recorder_errors
    ));
    m.push_str("## Errors against truth\n\n");
    match &s.truth_errors {
        None => m.push_str("The recording has no truth.\n\n"),
        Some(t) => {
            m.push_str(&format!(
                "{} solutions matched with truth.\n\n",
                t.solutions_matched
            ));
            m.push_str("| error | RMS | max | 95 % | within ±3σ |\n|---|---|---|---|---|\n");
            let rows: [(&str, &ErrorStats, usize); 12] = [
                ("position north [m]", &t.position_north_m, 3),
                ("position east [m]", &t.position_east_m, 3),
                ("position down [m]", &t.position_down_m, 3),
                ("position horizontal [m]", &t.position_horizontal_m, 3),
                ("position 3-D [m]", &t.position_3d_m, 3),
                ("velocity north [m/s]", &t.velocity_north_m_s, 4),
                ("velocity east [m/s]", &t.velocity_east_m_s, 4),
                ("velocity down [m/s]", &t.velocity_down_m_s, 4),
                ("attitude north [deg]", &t.attitude_north_deg, 5),
                ("attitude east [deg]", &t.attitude_east_deg, 5),
                ("attitude down/heading [deg]", &t.attitude_down_deg, 5),
                ("attitude angle [deg]", &t.attitude_angle_deg, 5),
            ];
            for (name, e, p) in rows {
                m.push_str(&format!(
                    "| {name} | {} | {} | {} | {} |\n",
                    f(e.rms, p),
                    f(e.max, p),
                    f(e.p95, p),
                    e.within_3sigma_fraction
                        .map(|x| format!("{:.1} %", 100.0 * x))
                        .unwrap_or_else(|| "—".into())
                ));
            }
            m.push('\n');
        }
    }
    m.push_str("## Sensors\n\nNIS/dof is Σ NIS / Σ measurement dimension over all updates: 1 for a consistent filter, inside the χ² 95 % interval shown.\n\n");
    m.push_str("| sensor | recorded | fused | gated | invalid | late | deadline misses | updates | NIS/dof | 95 % interval | period [s] | dropouts | longest gap [s] |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for r in &s.sensors {
        m.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
            r.sensor,
            r.samples_recorded,
            r.fused,
            r.rejected_gate,
            r.rejected_invalid,
            r.dropped_late,
            r.deadline_misses,
            r.nis_updates,
            f(r.nis_over_dof, 3),
            r.nis_over_dof_95_interval
                .map(|[a, b]| format!("{a:.3}–{b:.3}"))
                .unwrap_or_else(|| "—".into()),
            f(r.period_s, 4),
            r.dropouts,
            f(r.longest_gap_s, 3),
        ));
    }
    m.push_str("\n## Mode changes\n\n");
    if s.mode_changes_total > s.mode_changes.len() as u64 {
        m.push_str(&format!(
            "The first {} of {} listed.\n\n",
            s.mode_changes.len(),
            s.mode_changes_total
        ));
    }
    for c in &s.mode_changes {
        m.push_str(&format!("- {:.2} s: {} → {}\n", c.time_s, c.from, c.to));
    }
    m.push_str("\n## Sensor dead/alive events\n\n");
    if s.alive_events.is_empty() {
        m.push_str("None.\n");
    } else if s.alive_events_total > s.alive_events.len() as u64 {
        m.push_str(&format!(
            "The first {} of {} listed.\n\n",
            s.alive_events.len(),
            s.alive_events_total
        ));
    }
    for e in &s.alive_events {
        m.push_str(&format!(
            "- {:.2} s: {} {}\n",
            e.time_s,
            e.sensor,
            if e.alive {
                "alive"
            } else {
                "silent beyond its deadline"
            }
        ));
    }
    m.push_str("\n## Dropouts (gaps > 2 periods)\n\n");
    if s.dropouts.is_empty() {
        m.push_str("None.\n");
    }
    for d in &s.dropouts {
        m.push_str(&format!(
            "- {} at {:.2} s: {:.3} s\n",
            d.channel, d.start_s, d.gap_s
        ));
    }
    if let (Some(g), Some(a)) = (s.final_gyro_bias_deg_h, s.final_accel_bias_ug) {
        m.push_str(&format!(
            "\n## Final estimates\n\n- gyro bias [deg/h]: {:.4}, {:.4}, {:.4}\n- accelerometer bias [µg]: {:.1}, {:.1}, {:.1}\n",
            g[0], g[1], g[2], a[0], a[1], a[2]
        ));
    }
    if let (Some(b), Some(bs)) = (s.final_boresight_arcsec, s.final_boresight_sigma_arcsec) {
        m.push_str(&format!(
            "- boresight κ1..κ3 [arcsec]: {:.2} ± {:.2}, {:.2} ± {:.2}, {:.2} ± {:.2}\n",
            b[0], bs[0], b[1], bs[1], b[2], bs[2]
        ));
    }
    m.push_str("\n## Plots\n\n");
    for p in &s.plots {
        m.push_str(&format!("![{p}]({p})\n"));
    }
    m
}

/// The key figures as a text table.
pub fn format_table(s: &ReportSummary) -> String {
    let mut t = String::new();
    let mut row = |k: &str, v: String| t.push_str(&format!("{k:<44} {v}\n"));
    row("recording", s.recording.clone());
    if let Some(e) = &s.recording_error {
        row("recording incomplete", e.clone());
    }
    row(
        "navigation [s] / solutions",
        format!("{:.1} / {}", s.navigation_duration_s, s.solutions),
    );
    if let Some(e) = &s.truth_errors {
        for (name, x, p) in [
            ("position N RMS / max / 95% [m]", &e.position_north_m, 3),
            ("position E RMS / max / 95% [m]", &e.position_east_m, 3),
            ("position D RMS / max / 95% [m]", &e.position_down_m, 3),
            (
                "horizontal RMS / max / 95% [m]",
                &e.position_horizontal_m,
                3,
            ),
            (
                "attitude angle RMS / max / 95% [deg]",
                &e.attitude_angle_deg,
                4,
            ),
            ("heading RMS / max / 95% [deg]", &e.attitude_down_deg, 4),
        ] {
            row(
                name,
                format!("{} / {} / {}", f(x.rms, p), f(x.max, p), f(x.p95, p)),
            );
        }
    }
    for r in &s.sensors {
        row(
            &format!("{} fused / gated / NIS per dof", r.sensor),
            format!(
                "{} / {} / {}",
                r.fused,
                r.rejected_gate,
                f(r.nis_over_dof, 3)
            ),
        );
    }
    row("mode changes", s.mode_changes_total.to_string());
    row(
        "dropouts",
        s.sensors
            .iter()
            .map(|r| r.dropouts)
            .sum::<u64>()
            .to_string(),
    );
    row("records dropped", s.records_dropped.to_string());
    t
}

/// Keep the map type in the public API stable for callers that group dropouts.
pub fn dropouts_per_channel(s: &ReportSummary) -> BTreeMap<String, u64> {
    s.sensors
        .iter()
        .map(|r| (r.sensor.clone(), r.dropouts))
        .collect()
}

#[cfg(test)]
#[allow(clippy::field_reassign_with_default)]
mod tests {
    use super::*;
    use crate::recorder::{Recorder, RecorderOptions, SensorAliveEvent};
    use msgs::ImuSample;

    /// WGS-84 ECEF of geodetic (lat, lon, h) — independent of the code under test.
    fn ecef(lat: f64, lon: f64, h: f64) -> [f64; 3] {
        let a = 6378137.0;
        let f = 1.0 / 298.257223563;
        let e2 = f * (2.0 - f);
        let n = a / (1.0 - e2 * lat.sin().powi(2)).sqrt();
        [
            (n + h) * lat.cos() * lon.cos(),
            (n + h) * lat.cos() * lon.sin(),
            (n * (1.0 - e2) + h) * lat.sin(),
        ]
    }

    /// Synthetic recording with known errors: the solution is 1 m north and 0.5 m up of the
    /// truth with σ = 0.4 m, and 0.01 rad off in heading; the IMU has a 1 s gap.
    #[test]
    fn known_errors_nis_and_dropouts_are_reported_exactly() {
        let dir = std::env::temp_dir().join(format!("sextant-report-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("recording.mcap");
        let rec = Recorder::start(&path, &RecorderOptions::default()).unwrap();
        let (lat, lon) = (0.8f64, 0.3f64);
        // Meridian radius of curvature: 1 m north = 1/(M+h) rad of latitude.
        let a = 6378137.0;
        let e2 = (1.0 / 298.257223563) * (2.0 - 1.0 / 298.257223563);
        let m = a * (1.0 - e2) / (1.0 - e2 * lat.sin().powi(2)).powf(1.5);
        let t0 = 1_400_000_000_000_000_000i64;
        let mut ev = SensorAliveEvent::default();
        ev.sensor = 2;
        ev.alive = true;
        rec.record(Record::SensorAlive(ev), 0);
        let yaw = 0.01f64;
        for k in 0..1000i64 {
            let t = t0 + k * 5_000_000;
            // IMU gap: samples 400..=599 missing (1 s at 200 Hz → one gap of 1.005 s).
            if !(400..600).contains(&k) {
                let mut imu = ImuSample::default();
                imu.header.time_ns = t;
                rec.record(Record::Imu(imu), 0);
            }
            let mut tr = TruthSample::default();
            tr.header.time_ns = t;
            tr.lat_rad = lat;
            tr.lon_rad = lon;
            tr.pos_ecef_m = ecef(lat, lon, 100.0);
            tr.q_ned_body = [1.0, 0.0, 0.0, 0.0];
            rec.record(Record::Truth(tr), 0);
            let mut n = NavSolution::default();
            n.header.time_ns = t;
            n.mode = NavMode::GnssInertial as u32;
            n.pos_ecef_m = ecef(lat + 1.0 / (m + 100.0), lon, 100.5);
            n.pos_sigma_ned_m = [0.4, 0.4, 0.4];
            n.att_sigma_ned_rad = [0.001, 0.001, 0.001];
            n.q_ned_body = [(yaw / 2.0).cos(), 0.0, 0.0, (yaw / 2.0).sin()];
            rec.record(Record::Nav(n), 0);
        }
        let mut st = Status::default();
        st.header.time_ns = t0 + 5_000_000_000;
        st.sensors[2].nis_sum = 30.0;
        st.sensors[2].nis_count = 10;
        st.sensors[2].nis_dof_sum = 60;
        st.sensors[2].fused = 10;
        rec.record(Record::Status(Box::new(st)), 0);
        rec.finish().unwrap();

        let out = dir.join("report");
        let s = report(&path, &out).unwrap();
        assert!(s.recording_complete && s.recording_error.is_none());
        let e = s.truth_errors.as_ref().unwrap();
        assert_eq!(e.solutions_matched, 1000);
        // North 1 m (the curvature of 1 m is below 1e-7 m), down −0.5 m.
        let close = |x: Option<f64>, v: f64, tol: f64| (x.unwrap() - v).abs() < tol;
        assert!(close(e.position_north_m.rms, 1.0, 1e-6), "{e:?}");
        assert!(close(e.position_north_m.max, 1.0, 1e-6));
        assert!(close(e.position_north_m.p95, 1.0, 1e-6));
        assert!(close(e.position_east_m.max, 0.0, 1e-6));
        assert!(close(e.position_down_m.rms, 0.5, 1e-6));
        assert!(close(e.position_3d_m.rms, 1.25f64.sqrt(), 1e-6));
        // |1 m| ≤ 3·0.4 m always; heading 0.01 rad = 0.573° > 3·0.057°: never within 3σ.
        assert_eq!(e.position_north_m.within_3sigma_fraction, Some(1.0));
        assert!(close(e.attitude_down_deg.rms, yaw.to_degrees(), 1e-9));
        assert_eq!(e.attitude_down_deg.within_3sigma_fraction, Some(0.0));
        assert!(close(e.attitude_angle_deg.max, yaw.to_degrees(), 1e-9));
        // NIS: 30 over 60 dof = 0.5, 95 % interval 1 ± 1.96·√(2/60).
        let g = &s.sensors[SensorId::Gnss as usize];
        assert_eq!(g.nis_over_dof, Some(0.5));
        assert_eq!(g.nis_dof_mean, Some(6.0));
        let half = 1.96 * (2.0f64 / 60.0).sqrt();
        let iv = g.nis_over_dof_95_interval.unwrap();
        assert!((iv[0] - (1.0 - half)).abs() < 1e-12 && (iv[1] - (1.0 + half)).abs() < 1e-12);
        // Dropouts: exactly one IMU gap of 201 periods.
        let imu = &s.sensors[SensorId::Imu as usize];
        assert_eq!(imu.period_s, Some(0.005));
        assert_eq!(imu.dropouts, 1);
        assert!(close(imu.longest_gap_s, 1.005, 1e-9));
        assert_eq!(s.dropouts.len(), 1);
        assert_eq!(s.mode_changes.len(), 1);
        assert_eq!(s.alive_events.len(), 1);
        for f in [
            "summary.json",
            "REPORT.md",
            "error_north_3sigma.png",
            "nis.png",
            "trajectory.png",
        ] {
            assert!(out.join(f).exists(), "{f} missing (plots: {:?})", s.plots);
        }
        let md = std::fs::read_to_string(out.join("REPORT.md")).unwrap();
        assert!(
            md.contains("| position north [m] | 1.000 | 1.000 | 1.000 | 100.0 % |"),
            "{md}"
        );
    }

    /// A recording longer than the period window, truth at a quarter of the solution rate and
    /// written 0.3 s late (out of order with the solutions), errors that vary: the streaming
    /// report against a whole-file computation of the same figures — RMS, maximum, ±3σ
    /// fraction and matches exact, the 95th percentile within its relative resolution,
    /// dropouts before and after the period is fixed.
    #[test]
    fn streaming_report_agrees_with_a_whole_file_computation() {
        let dir = std::env::temp_dir().join(format!("sextant-report-s-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("recording.mcap");
        let rec = Recorder::start(&path, &RecorderOptions::default()).unwrap();
        let put = |r: Record| {
            while !rec.record(r.clone(), 0) {
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
        };
        let (lat, lon) = (0.8f64, 0.3f64);
        let t0 = 1_400_000_000_000_000_000i64;
        let dt = 5_000_000i64;
        let n_epochs = (PERIOD_SAMPLES as i64) + 15_000;
        // IMU gaps: one while the period is being learnt, one after it is fixed.
        let gaps = [
            (1_000i64, 1_010i64),
            (PERIOD_SAMPLES as i64 + 5_000, PERIOD_SAMPLES as i64 + 5_400),
        ];
        let mut late: std::collections::VecDeque<TruthSample> = Default::default();
        let mut north: Vec<f64> = Vec::new();
        let mut within = 0u64;
        for k in 0..n_epochs {
            let t = t0 + k * dt;
            if !gaps.iter().any(|(a, b)| (*a..*b).contains(&k)) {
                let mut imu = ImuSample::default();
                imu.header.time_ns = t;
                put(Record::Imu(imu));
            }
            // A north error of varying size, a σ that sometimes covers it.
            let e_n = 0.3 * (k as f64 * 0.37).sin() + 1e-4 * (k % 1000) as f64;
            let sigma = 0.05 + 0.1 * ((k % 7) as f64 / 7.0);
            let mut n = NavSolution::default();
            n.header.time_ns = t;
            n.mode = NavMode::GnssInertial as u32;
            let r = ecef(lat, lon, 100.0);
            let nv = [-lat.sin() * lon.cos(), -lat.sin() * lon.sin(), lat.cos()];
            n.pos_ecef_m = std::array::from_fn(|i| r[i] + e_n * nv[i]);
            n.pos_sigma_ned_m = [sigma; 3];
            n.att_sigma_ned_rad = [0.001; 3];
            n.q_ned_body = [1.0, 0.0, 0.0, 0.0];
            put(Record::Nav(n));
            if k % 4 == 0 {
                let mut tr = TruthSample::default();
                tr.header.time_ns = t;
                tr.lat_rad = lat;
                tr.lon_rad = lon;
                tr.pos_ecef_m = r;
                tr.q_ned_body = [1.0, 0.0, 0.0, 0.0];
                late.push_back(tr);
                north.push(e_n);
                if e_n.abs() <= 3.0 * sigma {
                    within += 1;
                }
            }
            // Truth 0.3 s (60 epochs) behind the solutions in the file.
            while late
                .front()
                .is_some_and(|tr| tr.header.time_ns <= t - 60 * dt)
            {
                put(Record::Truth(late.pop_front().unwrap()));
            }
        }
        for tr in late {
            put(Record::Truth(tr));
        }
        rec.finish().unwrap();

        let s = report(&path, &dir.join("report")).unwrap();
        let e = s.truth_errors.as_ref().unwrap();
        assert_eq!(e.solutions_matched, north.len() as u64);
        let pn = &e.position_north_m;
        let rel = |a: f64, b: f64| (a - b).abs() / b.abs();
        // Same numbers; the ECEF round trip costs ~1e-9 m.
        assert!(
            rel(pn.rms.unwrap(), crate::stats::rms(&north).unwrap()) < 1e-7,
            "{pn:?}"
        );
        assert!((pn.max.unwrap() - crate::stats::max_abs(&north).unwrap()).abs() < 1e-7);
        assert_eq!(
            pn.within_3sigma_fraction,
            Some(within as f64 / north.len() as f64)
        );
        let abs: Vec<f64> = north.iter().map(|x| x.abs()).collect();
        let p95 = percentile(&abs, 95.0).unwrap();
        assert!(
            rel(pn.p95.unwrap(), p95) <= P95_RELATIVE_RESOLUTION + 1e-7,
            "{} vs {p95}",
            pn.p95.unwrap()
        );
        // Dropouts: both gaps, exact, the period learnt from the first periods.
        let imu = &s.sensors[SensorId::Imu as usize];
        assert_eq!(imu.period_s, Some(0.005));
        assert_eq!(imu.dropouts, 2);
        assert_eq!(imu.samples_recorded, (n_epochs - 410) as u64);
        assert!((imu.longest_gap_s.unwrap() - 401.0 * 0.005).abs() < 1e-12);
        let starts: Vec<f64> = s.dropouts.iter().map(|d| d.start_s).collect();
        assert_eq!(starts.len(), 2);
        assert!((starts[0] - 999.0 * 0.005).abs() < 1e-9, "{starts:?}");
        assert!((starts[1] - (PERIOD_SAMPLES as f64 + 4_999.0) * 0.005).abs() < 1e-9);
        assert_eq!(s.solutions, n_epochs as u64);
        assert_eq!(s.mode_changes_total, 1);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
