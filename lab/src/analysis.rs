//! Analysis of a recording: messages per channel, drops (recorder drops, sequence-number gaps),
//! error of the solution against the truth (matched by identical time of validity), errors during
//! and after GNSS outages, and IMU-to-solution latency. Used by `sextant run` and `replay`;
//! `sextant report` reuses its matching window and thinned series.
//!
//! Read through [`crate::recording`]; a recording cut short by a crash is read up to its last
//! complete chunk (`Summary::recording_truncated` tells). [`analyze_written`] analyses a
//! recording while it is written, from the recorder's tap (the same messages in the same
//! order, so the same figures), instead of reading it back afterwards.

use crate::foxglove::{NedOrigin, ned_offset};
use crate::recorder::{Record, Written};
use crate::recording::{Recording, RecordingError};
use crate::scenario::TimeWindow;
use crate::stats::{RmsMax, StreamingPercentiles};
use msgs::{NavMode, NavSolution, Status, TruthSample};
use serde::Serialize;
use std::collections::{BTreeMap, HashMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::mpsc::Receiver;

/// Errors of the analysis.
#[derive(Debug, thiserror::Error)]
pub enum AnalysisError {
    /// The recording could not be read.
    #[error("cannot read recording {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The recording is not MCAP.
    #[error("{path} is not a readable MCAP file: {detail}")]
    NotMcap {
        /// The file.
        path: PathBuf,
        /// The reader's message.
        detail: String,
    },
}

/// Error figures over one GNSS outage.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct OutageSummary {
    /// Start of the outage, s since the first truth (or solution) sample.
    pub start_s: f64,
    /// End of the outage, s since the first truth sample.
    pub end_s: f64,
    /// Largest horizontal error during the outage, m.
    pub horizontal_error_max_m: Option<f64>,
    /// RMS horizontal error in the 60 s after the outage, m.
    pub after_outage_horizontal_error_rms_m: Option<f64>,
}

/// The figures of one recording (written as `summary.json`).
#[derive(Debug, Clone, Serialize, PartialEq, Default)]
pub struct Summary {
    /// The recording analysed.
    pub recording: String,
    /// True when the recording ended early (crash): analysed up to its last complete chunk.
    pub recording_truncated: bool,
    /// Span of simulated time covered by the solution (alignment excluded; when there is no
    /// solution, by any message), s.
    pub duration_s: f64,
    /// Span of the time of validity over every message of the recording, s.
    pub recorded_time_span_s: f64,
    /// Messages per topic.
    pub messages_per_channel: BTreeMap<String, u64>,
    /// Missing sequence numbers per channel (publisher's sequence jumps).
    pub sequence_gaps_per_channel: BTreeMap<String, u64>,
    /// Sequence restarts per channel (a restarted driver starts again at 1).
    pub sequence_restarts_per_channel: BTreeMap<String, u64>,
    /// Records the recorder dropped (from the last status).
    pub records_dropped: u64,
    /// Navigation mode at the end (from the last status).
    pub final_mode: Option<String>,
    /// Solutions recorded.
    pub solutions: u64,
    /// Solutions matched with a truth sample of identical time of validity.
    pub solutions_matched_with_truth: u64,
    /// RMS horizontal position error, m.
    pub horizontal_error_rms_m: Option<f64>,
    /// Largest horizontal position error, m.
    pub horizontal_error_max_m: Option<f64>,
    /// RMS vertical position error, m.
    pub vertical_error_rms_m: Option<f64>,
    /// Largest vertical position error, m.
    pub vertical_error_max_m: Option<f64>,
    /// RMS attitude error angle, deg.
    pub attitude_error_rms_deg: Option<f64>,
    /// Largest attitude error angle, deg.
    pub attitude_error_max_deg: Option<f64>,
    /// RMS horizontal error of the GNSS receiver's own fixes over the same run, m: each valid
    /// fix against the antenna's true position at its time tag — the truth sample's (the
    /// IMU's) moved by the antenna's lever arm in the true attitude: the simulated world's in
    /// `sextant run`, else the one of the recording's filter configuration (the surveyed one;
    /// none when the recording carries no configuration) — to set beside the solution's.
    pub gnss_fix_horizontal_error_rms_m: Option<f64>,
    /// RMS vertical error of the receiver's own fixes, m.
    pub gnss_fix_vertical_error_rms_m: Option<f64>,
    /// Largest horizontal error during any GNSS outage, m.
    pub outage_horizontal_error_max_m: Option<f64>,
    /// RMS horizontal error in the 60 s after the GNSS outages, m.
    pub after_outage_horizontal_error_rms_m: Option<f64>,
    /// Per outage.
    pub gnss_outages: Vec<OutageSummary>,
    /// Median IMU-send-to-solution-send latency, µs.
    pub latency_p50_us: Option<f64>,
    /// 99th percentile of the latency, µs.
    pub latency_p99_us: Option<f64>,
    /// Largest latency, µs.
    pub latency_max_us: Option<f64>,
    /// Solutions the latency figures are over: every solution the fusion daemon computed when
    /// its status reports them (its own histogram, so they hold for a recording that keeps
    /// only some solutions), else the recorded solutions.
    pub latency_solutions: u64,
}

/// Time series behind the summary, for the plots.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Series {
    /// Time of each matched solution, s since `t0_ns`.
    pub t_s: Vec<f64>,
    /// Horizontal error, m.
    pub horizontal_m: Vec<f64>,
    /// Vertical error (solution − truth, up positive), m.
    pub vertical_m: Vec<f64>,
    /// Attitude error angle, deg.
    pub attitude_deg: Vec<f64>,
    /// Truth north/east from the first truth sample, m.
    pub truth_ne_m: Vec<(f64, f64)>,
    /// Solution north/east from the first truth sample, m.
    pub nav_ne_m: Vec<(f64, f64)>,
    /// Outage windows, s since `t0_ns`.
    pub outages_s: Vec<(f64, f64)>,
    /// Time origin, GPS ns.
    pub t0_ns: i64,
}

/// A summary and its series.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Analysis {
    /// The figures.
    pub summary: Summary,
    /// The series.
    pub series: Series,
}

/// Seconds after an outage over which the recovery RMS is computed.
pub const AFTER_OUTAGE_S: f64 = 60.0;

/// Hamilton product of quaternions `[w, x, y, z]`.
pub(crate) fn q_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    let [aw, ax, ay, az] = a;
    let [bw, bx, by, bz] = b;
    [
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ]
}

/// Angle of the rotation between two attitude quaternions `[w, x, y, z]`, rad.
pub fn attitude_error_rad(q_true: [f64; 4], q_est: [f64; 4]) -> f64 {
    let [w, x, y, z] = q_true;
    let e = q_mul([w, -x, -y, -z], q_est);
    let n = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2] + e[3] * e[3]).sqrt();
    if !(n.is_finite() && n > 0.0) {
        return f64::NAN;
    }
    let v = (e[1] * e[1] + e[2] * e[2] + e[3] * e[3]).sqrt() / n;
    2.0 * v.atan2((e[0] / n).abs())
}

/// Position error of a solution against truth in NED at the truth position, m.
pub fn position_error_ned_m(nav: &NavSolution, truth: &TruthSample) -> [f64; 3] {
    ned_offset(
        truth.pos_ecef_m,
        truth.lat_rad,
        truth.lon_rad,
        nav.pos_ecef_m,
    )
}

/// The origin of the plots' north/east coordinates: the first truth sample's position.
pub(crate) fn ned_origin(t: &TruthSample) -> NedOrigin {
    NedOrigin {
        r_e: t.pos_ecef_m,
        lat_rad: t.lat_rad,
        lon_rad: t.lon_rad,
    }
}

/// Analyse the recording at `path` with the GNSS outage windows of its scenario.
pub fn analyze_recording(path: &Path, outages: &[TimeWindow]) -> Result<Summary, AnalysisError> {
    analyze(path, outages).map(|a| a.summary)
}

/// Like [`analyze_recording`], with the time series for plots.
pub fn analyze(path: &Path, outages: &[TimeWindow]) -> Result<Analysis, AnalysisError> {
    analyze_with_progress(path, outages, None, false)
}

/// [`analyze`] with a progress bar over the file on stderr when `progress` (see
/// [`crate::progress`]): the analysis at the end of `sextant run` and `replay`. The receiver's
/// fixes are compared at `antenna_lever_arm_b_m` (body axes, m; `sextant run` gives its
/// world's), or when `None` at the lever arm of the filter configuration the recording embeds.
pub fn analyze_with_progress(
    path: &Path,
    outages: &[TimeWindow],
    antenna_lever_arm_b_m: Option<[f64; 3]>,
    progress: bool,
) -> Result<Analysis, AnalysisError> {
    let pb = crate::progress::bytes(progress, crate::progress::file_len(path), "analysis");
    let rec = Recording::open(path).map_err(|e| match e {
        RecordingError::Io { path, source } => AnalysisError::Read { path, source },
        other => AnalysisError::NotMcap {
            path: path.to_path_buf(),
            detail: other.to_string(),
        },
    })?;
    let antenna_lever_arm_b_m = antenna_lever_arm_b_m.unwrap_or_else(|| {
        crate::replay::embedded_filter_config(&rec).map_or([0.0; 3], |c| c.gnss.lever_arm_b_m)
    });
    let thinned = thinned_topics(rec.metadata());
    let mut a = Analyzer::new(path, outages, antenna_lever_arm_b_m, &thinned);
    // Decompressing and decoding on a thread of their own, the matching here.
    for (n, e) in rec.read_ahead().enumerate() {
        match e {
            Ok(e) => {
                if n % 4096 == 0 {
                    pb.set_position(e.offset);
                }
                a.add(&e.topic, e.record.as_ref());
            }
            Err(e) => {
                a.truncated(&e);
                break;
            }
        }
    }
    let a = a.finish();
    pb.finish_and_clear();
    Ok(a)
}

/// Analyse the recording at `path` from the messages its recorder hands to
/// [`crate::recorder::RecorderOptions::tap`] while it writes them (`tap` ends when the recorder
/// finishes): the same figures as [`analyze`] of the finished file, without reading it back.
/// Exact as long as the recorder lost nothing (a failed write loses from the file what the tap
/// still saw: analyse the file then). `antenna_lever_arm_b_m` is the GNSS antenna's lever arm
/// of the filter configuration the recording embeds (body axes, m), which [`analyze`] reads
/// from the file; `thinned` the topics the recorder keeps one message per interval of
/// ([`thinned_topics`] of the recording's metadata).
pub fn analyze_written(
    path: &Path,
    tap: Receiver<Vec<Written>>,
    outages: &[TimeWindow],
    antenna_lever_arm_b_m: [f64; 3],
    thinned: &[&str],
) -> Analysis {
    let mut a = Analyzer::new(path, outages, antenna_lever_arm_b_m, thinned);
    // By reference: a record is ≈ 0.5 kB, moving each out of its batch cost more than the
    // rest of the analysis of an IMU sample.
    for batch in tap {
        for w in &batch {
            a.add(w.topic, w.record.as_ref());
        }
    }
    a.finish()
}

/// The topics a recording keeps one message per interval of time of validity (its
/// `[recorder]` solution and truth rates, from its metadata): their sequence numbers skip by
/// design, so their gaps are not counted.
pub fn thinned_topics(metadata: &BTreeMap<String, BTreeMap<String, String>>) -> Vec<&'static str> {
    let (solution_hz, truth_hz, _) = crate::recorder::recorded_rates(metadata);
    let mut v = Vec::new();
    if solution_hz > 0.0 {
        v.push(msgs::Channel::Nav.name());
    }
    if truth_hz > 0.0 {
        v.push(msgs::Channel::Truth.name());
    }
    v
}

/// The analysis of a recording's messages, fed in file order ([`Analyzer::add`]): the state
/// of [`analyze`] and [`analyze_written`], which differ only in where the messages come from.
struct Analyzer<'a> {
    s: Summary,
    outages: &'a [TimeWindow],
    thinned: &'a [&'a str],
    last_seq: HashMap<&'static str, u64>,
    first_truth: Option<TruthSample>,
    last_status: Option<Status>,
    /// The final status of each earlier life of the fusion daemon (restarts).
    latency_lives: Vec<Status>,
    t_min: i64,
    t_max: i64,
    w: Window,
    m: Matched<'a>,
    first_nav_ns: Option<i64>,
    last_nav_ns: i64,
}

impl<'a> Analyzer<'a> {
    /// The analysis of the recording `path`; the receiver's fixes are compared at
    /// `antenna_lever_arm_b_m` (body axes, m); `thinned` as in [`analyze_written`].
    fn new(
        path: &Path,
        outages: &'a [TimeWindow],
        antenna_lever_arm_b_m: [f64; 3],
        thinned: &'a [&'a str],
    ) -> Self {
        let mut m = Matched::new(outages);
        m.antenna_lever_arm_b_m = antenna_lever_arm_b_m;
        Self {
            s: Summary {
                recording: path.display().to_string(),
                ..Default::default()
            },
            outages,
            thinned,
            last_seq: HashMap::new(),
            first_truth: None,
            last_status: None,
            latency_lives: Vec::new(),
            t_min: i64::MAX,
            t_max: i64::MIN,
            w: Window::default(),
            m,
            first_nav_ns: None,
            last_nav_ns: 0,
        }
    }

    /// The reading stopped at `e` (a cut or damaged file): the figures are of what came before.
    fn truncated(&mut self, e: &RecordingError) {
        tracing::warn!("{}: reading stopped: {e}", self.s.recording);
        self.s.recording_truncated = true;
    }

    /// The next message of the file: its topic, and its record when it is one of Sextant's.
    fn add(&mut self, topic: &str, record: Option<&Record>) {
        // Per record, by topic: counted without building a key string for every message.
        fn count<'m, V: Default>(map: &'m mut BTreeMap<String, V>, topic: &str) -> &'m mut V {
            if !map.contains_key(topic) {
                map.insert(topic.to_string(), V::default());
            }
            map.get_mut(topic).expect("inserted above")
        }
        let s = &mut self.s;
        *count(&mut s.messages_per_channel, topic) += 1;
        let Some(record) = record else {
            return;
        };
        let Some(ch) = record.channel() else {
            return;
        };
        let topic = ch.name();
        let h = *record.header();
        if h.time_ns > 0 {
            self.t_min = self.t_min.min(h.time_ns);
            self.t_max = self.t_max.max(h.time_ns);
        }
        let gaps = count(&mut s.sequence_gaps_per_channel, topic);
        if let Some(prev) = self.last_seq.insert(topic, h.seq) {
            if h.seq > prev + 1 && !self.thinned.contains(&topic) {
                *gaps += h.seq - prev - 1;
            } else if h.seq <= prev {
                *count(&mut s.sequence_restarts_per_channel, topic) += 1;
            }
        }
        let m = &mut self.m;
        match record {
            Record::Truth(t) => {
                let origin = *self.first_truth.get_or_insert(*t);
                let (navs, fixes) = self.w.truth(*t);
                for nav in &navs {
                    m.solution(nav, t, &origin);
                }
                for pos in &fixes {
                    m.fix(pos, t);
                }
            }
            Record::Nav(nav) => {
                s.solutions += 1;
                self.first_nav_ns.get_or_insert(nav.header.time_ns);
                self.last_nav_ns = nav.header.time_ns;
                if nav.header.send_mono_ns > 0 && nav.imu_send_mono_ns > 0 {
                    m.latency_us.push(
                        nav.header.send_mono_ns.saturating_sub(nav.imu_send_mono_ns) as f64 * 1e-3,
                    );
                }
                let first_truth = &self.first_truth;
                self.w.nav(nav, |nav, tr| {
                    if let Some(origin) = first_truth {
                        m.solution(nav, tr, origin)
                    }
                });
            }
            Record::Gnss(g) if g.fix_valid == 1 => {
                self.w
                    .fix(g.header.time_ns, g.pos_ecef_m, |pos, tr| m.fix(pos, tr))
            }
            Record::Status(st) => {
                // A restarted daemon counts from zero: keep the last report of each life.
                if let Some(prev) = &self.last_status
                    && st.latency_count < prev.latency_count
                {
                    self.latency_lives.push(*prev);
                }
                self.last_status = Some(**st);
            }
            _ => {}
        }
        if h.time_ns > 0 {
            self.w.evict_before(h.time_ns - MATCH_WINDOW_NS);
        }
    }

    /// The figures of the messages added.
    fn finish(self) -> Analysis {
        let Self {
            mut s,
            outages,
            last_status,
            mut latency_lives,
            t_min,
            t_max,
            mut m,
            first_truth,
            first_nav_ns,
            last_nav_ns,
            ..
        } = self;
        if let Some(st) = &last_status {
            s.records_dropped = st.records_dropped;
            s.final_mode = Some(
                NavMode::from_u32(st.mode)
                    .map(|m| m.name().to_string())
                    .unwrap_or_else(|| format!("unknown({})", st.mode)),
            );
        }
        if t_max > t_min {
            s.recorded_time_span_s = (t_max - t_min) as f64 * 1e-9;
        }
        if let Some(a) = first_nav_ns {
            s.duration_s = (last_nav_ns - a) as f64 * 1e-9;
        } else if t_max > t_min {
            s.duration_s = (t_max - t_min) as f64 * 1e-9;
        }
        let t0_ns = first_truth
            .map(|t| t.header.time_ns)
            .or(first_nav_ns)
            .unwrap_or(0);
        s.solutions_matched_with_truth = m.horizontal.count();
        s.gnss_fix_horizontal_error_rms_m = m.fix_horizontal.rms();
        s.gnss_fix_vertical_error_rms_m = m.fix_vertical.rms();
        s.horizontal_error_rms_m = m.horizontal.rms();
        s.horizontal_error_max_m = m.horizontal.max_abs();
        s.vertical_error_rms_m = m.vertical.rms();
        s.vertical_error_max_m = m.vertical.max_abs();
        s.attitude_error_rms_deg = m.attitude.rms();
        s.attitude_error_max_deg = m.attitude.max_abs();
        latency_lives.extend(last_status);
        let daemon_count: u64 = latency_lives.iter().map(|st| st.latency_count).sum();
        if daemon_count > 0 {
            // Several lives (a restart): their percentiles weighted by their counts, an
            // approximation of the percentile of the union; exact for one life.
            let weighted = |f: fn(&Status) -> f64| {
                latency_lives
                    .iter()
                    .map(|st| f(st) * st.latency_count as f64)
                    .sum::<f64>()
                    / daemon_count as f64
            };
            s.latency_p50_us = Some(weighted(|st| st.latency_p50_us));
            s.latency_p99_us = Some(weighted(|st| st.latency_p99_us));
            s.latency_max_us = latency_lives
                .iter()
                .map(|st| st.latency_max_us)
                .reduce(f64::max);
            s.latency_solutions = daemon_count;
        } else {
            s.latency_p50_us = m.latency_us.percentile(50.0);
            s.latency_p99_us = m.latency_us.percentile(99.0);
            s.latency_max_us = m.latency_us.max();
            s.latency_solutions = m.latency_us.count();
        }
        let (mut all_during, mut all_after) = (RmsMax::default(), RmsMax::default());
        for (w, (during, after)) in outages.iter().zip(&m.outages) {
            s.gnss_outages.push(OutageSummary {
                start_s: (w.start_ns - t0_ns) as f64 * 1e-9,
                end_s: (w.end_ns - t0_ns) as f64 * 1e-9,
                horizontal_error_max_m: during.max_abs(),
                after_outage_horizontal_error_rms_m: after.rms(),
            });
            all_during.merge(during);
            all_after.merge(after);
        }
        s.outage_horizontal_error_max_m = all_during.max_abs();
        s.after_outage_horizontal_error_rms_m = all_after.rms();
        let mut series = m.series.into_series(0.0, t0_ns);
        series.outages_s = outages
            .iter()
            .map(|w| {
                (
                    (w.start_ns - t0_ns) as f64 * 1e-9,
                    (w.end_ns - t0_ns) as f64 * 1e-9,
                )
            })
            .collect();
        Analysis { summary: s, series }
    }
}

/// How far (time of validity) a solution or fix and the truth sample of its time may lie apart
/// in the recording and still be matched, ns. The recorder writes records as they arrive; the
/// truth and the solution of one epoch arrive within milliseconds of wall time, so a minute
/// of simulated time is far beyond any real separation even at high speed-ups, and keeps the
/// analysis in bounded memory whatever the recording's length.
pub(crate) const MATCH_WINDOW_NS: i64 = 60_000_000_000;

/// Most points of the plotted series (the figures use every matched solution).
const MAX_SERIES_POINTS: usize = 40_000;

/// Solutions, fixes and truth samples waiting for their counterpart of the same time of
/// validity, over the last [`MATCH_WINDOW_NS`]: the matching of two time-ordered streams that
/// the recording interleaves in arrival order (a bounded reorder window; a solution whose truth
/// sample lies further away in the file, or that has none, is never matched).
#[derive(Default)]
pub(crate) struct Window {
    truth: BTreeMap<i64, TruthSample>,
    /// The solutions waiting, in arrival order: a recording's solutions come in time order
    /// (a restarted daemon's start over, earlier than its previous life's last ones), so the
    /// store is a queue searched by bisection that takes no allocation per solution. Most wait
    /// in vain: a recording's truth is usually thinned (10 Hz against solutions at the IMU's
    /// rate), and the window holds a minute of them.
    navs: VecDeque<NavSolution>,
    /// 0 when `navs` is in order of time of validity; else the index of its last solution
    /// earlier than the one before it (the queue is in order from there on).
    navs_disorder: usize,
    fixes: BTreeMap<i64, Vec<[f64; 3]>>,
}

impl Window {
    /// A truth sample: returns the solutions and fixes of its time that waited for it, and
    /// waits for later ones.
    pub(crate) fn truth(&mut self, t: TruthSample) -> (Vec<NavSolution>, Vec<[f64; 3]>) {
        let k = t.header.time_ns;
        self.truth.insert(k, t);
        let navs = if self.navs_disorder == 0 {
            let first = self.navs.partition_point(|n| n.header.time_ns < k);
            let n = self
                .navs
                .range(first..)
                .take_while(|n| n.header.time_ns == k)
                .count();
            self.navs.drain(first..first + n).collect()
        } else {
            let matched = (self.navs.iter())
                .filter(|n| n.header.time_ns == k)
                .copied()
                .collect();
            self.navs.retain(|n| n.header.time_ns != k);
            self.navs_disorder = (1..self.navs.len())
                .rev()
                .find(|&i| self.navs[i].header.time_ns < self.navs[i - 1].header.time_ns)
                .unwrap_or(0);
            matched
        };
        (navs, self.fixes.remove(&k).unwrap_or_default())
    }

    /// A solution: matched at once when its truth sample is there, else it waits (a copy).
    pub(crate) fn nav(
        &mut self,
        n: &NavSolution,
        on_match: impl FnOnce(&NavSolution, &TruthSample),
    ) {
        match self.truth.get(&n.header.time_ns) {
            Some(t) => on_match(n, t),
            None => {
                if self
                    .navs
                    .back()
                    .is_some_and(|b| b.header.time_ns > n.header.time_ns)
                {
                    self.navs_disorder = self.navs.len();
                }
                self.navs.push_back(*n);
            }
        }
    }

    /// A receiver fix of time `t_ns`: as [`Window::nav`].
    fn fix(&mut self, t_ns: i64, pos: [f64; 3], on_match: impl FnOnce(&[f64; 3], &TruthSample)) {
        match self.truth.get(&t_ns) {
            Some(t) => on_match(&pos, t),
            None => self.fixes.entry(t_ns).or_default().push(pos),
        }
    }

    /// Forget what is older than `t_ns` (it will find no counterpart any more).
    pub(crate) fn evict_before(&mut self, t_ns: i64) {
        // Called for every record: drop the few old entries from the front instead of
        // rebuilding each map (`split_off` moves what is kept into a new tree).
        fn drop_front<V>(map: &mut BTreeMap<i64, V>, t_ns: i64) {
            while map.first_key_value().is_some_and(|(&k, _)| k < t_ns) {
                map.pop_first();
            }
        }
        drop_front(&mut self.truth, t_ns);
        drop_front(&mut self.fixes, t_ns);
        // From the front, called for every record (a bisection each time would touch a
        // dozen solutions of the minute held). Out of order, solutions older than `t_ns` stay
        // behind a later one until that one goes (a restart's time step bounds what is held).
        let old = (self.navs.iter())
            .take_while(|n| n.header.time_ns < t_ns)
            .count();
        self.navs.drain(..old);
        self.navs_disorder = self.navs_disorder.saturating_sub(old);
    }
}

/// The figures accumulated over the matched pairs.
pub(crate) struct Matched<'a> {
    outage_windows: &'a [TimeWindow],
    /// The GNSS antenna's lever arm from the IMU, body axes, m: where a fix is compared.
    antenna_lever_arm_b_m: [f64; 3],
    horizontal: RmsMax,
    vertical: RmsMax,
    attitude: RmsMax,
    fix_horizontal: RmsMax,
    fix_vertical: RmsMax,
    /// Per outage: horizontal error during it, and in the [`AFTER_OUTAGE_S`] after it.
    outages: Vec<(RmsMax, RmsMax)>,
    latency_us: StreamingPercentiles,
    /// The plotted series (thinned).
    pub(crate) series: Thinned<SeriesPoint>,
}

impl<'a> Matched<'a> {
    fn new(outage_windows: &'a [TimeWindow]) -> Self {
        Self::with_series_points(outage_windows, MAX_SERIES_POINTS)
    }

    /// With a plotted series of between `max_points` and twice as many points.
    pub(crate) fn with_series_points(outage_windows: &'a [TimeWindow], max_points: usize) -> Self {
        Self {
            outage_windows,
            antenna_lever_arm_b_m: [0.0; 3],
            horizontal: RmsMax::default(),
            vertical: RmsMax::default(),
            attitude: RmsMax::default(),
            fix_horizontal: RmsMax::default(),
            fix_vertical: RmsMax::default(),
            outages: vec![Default::default(); outage_windows.len()],
            // 1 µs bins up to 100 ms: 1.2 MB, exact beyond.
            latency_us: StreamingPercentiles::new(1.0, 100_000),
            series: Thinned::new(max_points),
        }
    }

    /// A solution matched with the truth sample of its time; `origin` is the first truth
    /// sample (time and north/east origin of the series).
    pub(crate) fn solution(&mut self, n: &NavSolution, t: &TruthSample, origin: &TruthSample) {
        let e = position_error_ned_m(n, t);
        let att = attitude_error_rad(t.q_ned_body, n.q_ned_body).to_degrees();
        if !(e.iter().all(|x| x.is_finite()) && att.is_finite()) {
            return;
        }
        let h = e[0].hypot(e[1]);
        self.horizontal.push(h);
        self.vertical.push(-e[2]);
        self.attitude.push(att);
        let tv = n.header.time_ns;
        for (w, (during, after)) in self.outage_windows.iter().zip(&mut self.outages) {
            if w.contains(tv) {
                during.push(h);
            }
            let after_w = TimeWindow {
                start_ns: w.end_ns,
                end_ns: w.end_ns + (AFTER_OUTAGE_S * 1e9) as i64,
            };
            if after_w.contains(tv) {
                after.push(h);
            }
        }
        let t_s = (tv - origin.header.time_ns) as f64 * 1e-9;
        self.series
            .push_with(|| SeriesPoint::new(t_s, &e, att, n, t, Some(&ned_origin(origin))));
    }

    fn fix(&mut self, pos: &[f64; 3], tr: &TruthSample) {
        // The fix is the antenna's position: compare it with the antenna's, the lever arm
        // rotated into NED by the true attitude (the NED frame at the IMU and at the antenna
        // differ by the arm over the Earth's radius, 2e-7 rad: negligible).
        let arm_n = fusion::attitude::quat_from_wire(&tr.q_ned_body)
            * nalgebra::Vector3::from(self.antenna_lever_arm_b_m);
        let mut e = ned_offset(tr.pos_ecef_m, tr.lat_rad, tr.lon_rad, *pos);
        for (e, a) in e.iter_mut().zip(arm_n.iter()) {
            *e -= a;
        }
        if e.iter().all(|x| x.is_finite()) {
            self.fix_horizontal.push(e[0].hypot(e[1]));
            self.fix_vertical.push(e[2]);
        }
    }
}

/// A series thinned as it grows, in bounded memory: every `stride`-th point pushed is kept,
/// and when more than twice `max_points` are held every other one is dropped and the stride
/// doubles. So it holds all points while fewer than `2 × max_points + 1` were pushed, and
/// otherwise between `max_points` and `2 × max_points`, evenly spaced in push order (the first
/// point always kept, the last one not necessarily).
#[derive(Debug, Clone)]
pub(crate) struct Thinned<T> {
    points: Vec<T>,
    pushed: u64,
    stride: u64,
    max_points: usize,
}

impl<T> Thinned<T> {
    /// Empty, keeping at most `2 × max_points` points.
    pub(crate) fn new(max_points: usize) -> Self {
        Self {
            points: Vec::new(),
            pushed: 0,
            stride: 1,
            max_points: max_points.max(1),
        }
    }

    /// Take the next point; `point` is called only when it is kept.
    pub(crate) fn push_with(&mut self, point: impl FnOnce() -> T) {
        self.pushed += 1;
        if !(self.pushed - 1).is_multiple_of(self.stride) {
            return;
        }
        self.points.push(point());
        if self.points.len() > 2 * self.max_points {
            let mut k = 0usize;
            self.points.retain(|_| {
                k += 1;
                k % 2 == 1
            });
            self.stride *= 2;
        }
    }

    /// The points kept, in push order.
    pub(crate) fn points(&self) -> &[T] {
        &self.points
    }

    /// The points kept, in push order.
    pub(crate) fn into_points(self) -> Vec<T> {
        self.points
    }
}

/// One matched solution of the plotted [`Series`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct SeriesPoint {
    t_s: f64,
    horizontal_m: f64,
    vertical_m: f64,
    attitude_deg: f64,
    /// Truth and solution north/east from the origin, m.
    ne_m: Option<[(f64, f64); 2]>,
}

impl SeriesPoint {
    /// One solution matched with the truth sample of its time of validity: `t_s` s since the
    /// series' origin, its NED position error `e_ned_m` (solution − truth, m) and attitude
    /// error angle (deg), and both positions as north/east from `origin` (when there is one).
    fn new(
        t_s: f64,
        e_ned_m: &[f64; 3],
        attitude_deg: f64,
        nav: &NavSolution,
        truth: &TruthSample,
        origin: Option<&NedOrigin>,
    ) -> Self {
        Self {
            t_s,
            horizontal_m: e_ned_m[0].hypot(e_ned_m[1]),
            vertical_m: -e_ned_m[2],
            attitude_deg,
            ne_m: origin.map(|o| {
                let tn = ned_offset(o.r_e, o.lat_rad, o.lon_rad, truth.pos_ecef_m);
                let nn = ned_offset(o.r_e, o.lat_rad, o.lon_rad, nav.pos_ecef_m);
                [(tn[0], tn[1]), (nn[0], nn[1])]
            }),
        }
    }
}

impl Thinned<SeriesPoint> {
    /// The series in time order (pairs are matched as their second half arrives, nearly but
    /// not exactly in time order), times shifted by `shift_s`, origin `t0_ns`.
    pub(crate) fn into_series(self, shift_s: f64, t0_ns: i64) -> Series {
        let mut points = self.into_points();
        points.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
        let mut s = Series {
            t0_ns,
            ..Default::default()
        };
        for p in points {
            s.t_s.push(p.t_s + shift_s);
            s.horizontal_m.push(p.horizontal_m);
            s.vertical_m.push(p.vertical_m);
            s.attitude_deg.push(p.attitude_deg);
            if let Some([truth, nav]) = p.ne_m {
                s.truth_ne_m.push(truth);
                s.nav_ne_m.push(nav);
            }
        }
        s
    }
}

/// The summary as an aligned text table.
pub fn format_table(s: &Summary) -> String {
    fn opt(v: Option<f64>, prec: usize) -> String {
        v.map(|x| format!("{x:.prec$}"))
            .unwrap_or_else(|| "—".into())
    }
    let mut rows: Vec<(String, String)> = vec![
        ("recording".into(), s.recording.clone()),
        (
            "solution time span [s]".into(),
            format!("{:.1}", s.duration_s),
        ),
        (
            "recorded time span [s]".into(),
            format!("{:.1}", s.recorded_time_span_s),
        ),
        (
            "final mode".into(),
            s.final_mode.clone().unwrap_or_else(|| "—".into()),
        ),
        (
            "solutions recorded (matched with truth)".into(),
            format!("{} ({})", s.solutions, s.solutions_matched_with_truth),
        ),
        (
            "horizontal error RMS / max [m]".into(),
            format!(
                "{} / {}",
                opt(s.horizontal_error_rms_m, 3),
                opt(s.horizontal_error_max_m, 3)
            ),
        ),
        (
            "vertical error RMS / max [m]".into(),
            format!(
                "{} / {}",
                opt(s.vertical_error_rms_m, 3),
                opt(s.vertical_error_max_m, 3)
            ),
        ),
        (
            "GNSS receiver fix alone: horizontal / vertical RMS [m]".into(),
            format!(
                "{} / {}",
                opt(s.gnss_fix_horizontal_error_rms_m, 3),
                opt(s.gnss_fix_vertical_error_rms_m, 3)
            ),
        ),
        (
            "attitude error RMS / max [deg]".into(),
            format!(
                "{} / {}",
                opt(s.attitude_error_rms_deg, 4),
                opt(s.attitude_error_max_deg, 4)
            ),
        ),
    ];
    if !s.gnss_outages.is_empty() {
        rows.push((
            "GNSS outage: horizontal error max [m]".into(),
            opt(s.outage_horizontal_error_max_m, 3),
        ));
        rows.push((
            format!("after outage ({AFTER_OUTAGE_S:.0} s): horizontal RMS [m]"),
            opt(s.after_outage_horizontal_error_rms_m, 3),
        ));
    }
    rows.push((
        format!(
            "latency p50 / p99 / max [µs] ({} solutions)",
            s.latency_solutions
        ),
        format!(
            "{} / {} / {}",
            opt(s.latency_p50_us, 0),
            opt(s.latency_p99_us, 0),
            opt(s.latency_max_us, 0)
        ),
    ));
    rows.push(("records dropped".into(), s.records_dropped.to_string()));
    if s.recording_truncated {
        rows.push((
            "recording truncated".into(),
            "yes (read up to last complete chunk)".into(),
        ));
    }
    for (ch, n) in &s.messages_per_channel {
        let gaps = s.sequence_gaps_per_channel.get(ch).copied().unwrap_or(0);
        let restarts = s
            .sequence_restarts_per_channel
            .get(ch)
            .copied()
            .unwrap_or(0);
        let mut v = n.to_string();
        if gaps > 0 || restarts > 0 {
            v.push_str(&format!(" (gaps {gaps}, restarts {restarts})"));
        }
        rows.push((format!("messages {ch}"), v));
    }
    let w = rows
        .iter()
        .map(|(k, _)| k.chars().count())
        .max()
        .unwrap_or(0);
    let mut out = String::new();
    for (k, v) in rows {
        out.push_str(&format!("  {k:<w$}  {v}\n"));
    }
    out
}

#[cfg(test)]
#[allow(clippy::field_reassign_with_default)]
mod tests {
    use super::*;
    use crate::recorder::{Record, Recorder, RecorderOptions};

    #[test]
    fn attitude_error_of_a_known_rotation() {
        let a = 0.01f64;
        let q = [(a / 2.0).cos(), 0.0, 0.0, (a / 2.0).sin()];
        assert!((attitude_error_rad([1.0, 0.0, 0.0, 0.0], q) - a).abs() < 1e-12);
        // q and -q are the same attitude.
        let mq = [-q[0], -q[1], -q[2], -q[3]];
        assert!((attitude_error_rad([1.0, 0.0, 0.0, 0.0], mq) - a).abs() < 1e-12);
    }

    /// The matching window pairs each truth sample with the solutions of its time whichever
    /// comes first, across a restart whose solutions start over 30 s earlier, and holds no
    /// more than the window (plus the restart's step) of unmatched solutions.
    #[test]
    fn the_window_matches_across_arrival_orders_and_a_restart() {
        let nav = |t: i64| {
            let mut n = NavSolution::default();
            n.header.time_ns = t;
            n
        };
        let truth = |t: i64| {
            let mut tr = TruthSample::default();
            tr.header.time_ns = t;
            tr
        };
        let (mut w, mut matched, mut most) = (Window::default(), 0usize, 0usize);
        let ms = 1_000_000i64;
        // Solutions at 200 Hz; truth at 10 Hz, alternately before and after its solution.
        // Life 1: 0–200 s; life 2 (a restart) starts over at 170 s and runs to 400 s.
        let lives = [(0i64, 200_000i64), (170_000, 400_000)];
        for (start, end) in lives {
            for t_ms in (start..end).step_by(5) {
                let t = t_ms * ms;
                let due = t_ms % 100 == 0;
                let truth_first = t_ms % 200 == 0;
                if due && truth_first {
                    matched += w.truth(truth(t)).0.len();
                }
                w.nav(&nav(t), |n, tr| {
                    assert_eq!(n.header.time_ns, tr.header.time_ns);
                    matched += 1;
                });
                if due && !truth_first {
                    let (navs, _) = w.truth(truth(t));
                    assert!(navs.iter().all(|n| n.header.time_ns == t));
                    matched += navs.len();
                }
                w.evict_before(t - MATCH_WINDOW_NS);
                most = most.max(w.navs.len());
            }
        }
        // Every truth epoch of both lives; in life 2's first 30 s the truth of life 1 (same
        // times, still in the window) meets the solution first: one pair each, no more.
        assert_eq!(matched, 2000 + 2300);
        // A minute of 200 Hz solutions, plus the 30 s the restart stepped back.
        assert!(most <= (60 + 30) * 200 + 1, "{most}");
        assert_eq!(
            w.navs_disorder, 0,
            "in order again once life 1 has left the window"
        );
    }

    #[test]
    fn synthetic_recording_gives_known_errors() {
        let dir = std::env::temp_dir().join(format!("sextant-analysis-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("recording.mcap");
        let rec = Recorder::start(&path, &RecorderOptions::default()).unwrap();
        let t0 = 1_400_000_000_000_000_000i64;
        let (lat, lon) = (0.0f64, 0.0f64);
        for k in 0..200i64 {
            let t = t0 + k * 100_000_000; // 10 Hz, 20 s
            let mut tr = TruthSample::default();
            tr.header.time_ns = t;
            tr.header.seq = k as u64 + 1 + u64::from(k >= 100); // one gap
            tr.lat_rad = lat;
            tr.lon_rad = lon;
            tr.pos_ecef_m = [6_378_137.0, 0.0, 0.0];
            tr.q_ned_body = [1.0, 0.0, 0.0, 0.0];
            rec.record(Record::Truth(tr), 0);
            let mut n = NavSolution::default();
            n.header.time_ns = t;
            n.header.seq = k as u64 + 1;
            n.header.send_mono_ns = 1_000_000 + 250_000;
            n.imu_send_mono_ns = 1_000_000;
            // 3 m north (ECEF z at lat 0), 4 m east during [5 s, 10 s), 1 m up otherwise.
            let inside = (50..100).contains(&k);
            n.pos_ecef_m = if inside {
                [6_378_137.0, 4.0, 3.0]
            } else {
                [6_378_138.0, 0.0, 0.0]
            };
            n.q_ned_body = [(0.005f64).cos(), 0.0, 0.0, (0.005f64).sin()];
            rec.record(Record::Nav(n), 0);
        }
        rec.finish().unwrap();
        let outage = TimeWindow {
            start_ns: t0 + 5_000_000_000,
            end_ns: t0 + 10_000_000_000,
        };
        let a = analyze(&path, &[outage]).unwrap();
        let s = &a.summary;
        assert_eq!(s.solutions, 200);
        assert_eq!(s.solutions_matched_with_truth, 200);
        assert_eq!(s.messages_per_channel["truth"], 200);
        assert_eq!(s.messages_per_channel["nav/location_fix"], 200);
        assert_eq!(s.sequence_gaps_per_channel["truth"], 1);
        assert_eq!(s.sequence_gaps_per_channel["nav"], 0);
        assert!((s.horizontal_error_max_m.unwrap() - 5.0).abs() < 1e-6);
        assert!((s.outage_horizontal_error_max_m.unwrap() - 5.0).abs() < 1e-6);
        assert!(s.after_outage_horizontal_error_rms_m.unwrap() < 1e-6);
        assert!((s.vertical_error_max_m.unwrap() - 1.0).abs() < 1e-6);
        assert!((s.attitude_error_max_deg.unwrap() - 0.01f64.to_degrees()).abs() < 1e-9);
        assert!((s.latency_p50_us.unwrap() - 250.0).abs() < 1e-9);
        assert!((s.duration_s - 19.9).abs() < 1e-9);
        assert!(!s.recording_truncated);
        assert_eq!(a.series.outages_s, vec![(5.0, 10.0)]);
        let table = format_table(s);
        assert!(table.contains("horizontal error"));
    }

    /// The analysis of the recorder's tap is that of the finished file read back: the same
    /// messages in the same order (the records as decoded, the Foxglove views, the held-back
    /// untimed records), in both encodings, over a segment boundary.
    #[test]
    fn the_tapped_recording_analyses_like_the_file() {
        use crate::recorder::RecordingEncoding;
        use msgs::{GnssSample, SensorAliveEvent};
        for encoding in [RecordingEncoding::Protobuf, RecordingEncoding::Json] {
            let dir = std::env::temp_dir().join(format!(
                "sextant-analysis-tap-{}-{}",
                std::process::id(),
                encoding.name()
            ));
            std::fs::create_dir_all(&dir).unwrap();
            let path = dir.join("recording.mcap");
            let (tap, written) = std::sync::mpsc::sync_channel(16);
            let tapped = std::thread::scope(|scope| {
                let analysis = scope.spawn(|| analyze_written(&path, written, &[], [0.0; 3], &[]));
                let rec = Recorder::start(
                    &path,
                    &RecorderOptions {
                        encoding,
                        tap: Some(tap),
                        segment_duration: Some(std::time::Duration::from_secs(7)),
                        ..Default::default()
                    },
                )
                .unwrap();
                // Untimed first: held back by the recorder until the first timed record.
                rec.record(Record::Status(Box::default()), 5);
                rec.record(
                    Record::SensorAlive(SensorAliveEvent {
                        sensor: 2,
                        alive: true,
                        ..Default::default()
                    }),
                    6,
                );
                let t0 = 1_400_000_000_000_000_000i64;
                for k in 0..200i64 {
                    let t = t0 + k * 100_000_000;
                    let mut tr = TruthSample::default();
                    tr.header.time_ns = t;
                    tr.header.seq = k as u64 + 1 + u64::from(k >= 120);
                    tr.pos_ecef_m = [6_378_137.0, 0.0, 0.0];
                    tr.q_ned_body = [1.0, 0.0, 0.0, 0.0];
                    tr.vel_ned_m_s = [0.1 * k as f64, -0.0, 1e-300];
                    // The solution before its truth sample every other epoch: the window waits.
                    let mut n = NavSolution::default();
                    n.header.time_ns = t;
                    n.header.seq = k as u64 + 1;
                    n.header.send_mono_ns = 2_000_000 + 1_000 * k as u64;
                    n.imu_send_mono_ns = 2_000_000;
                    n.pos_ecef_m = [6_378_137.0 + 0.01 * k as f64, (k as f64).sin(), 3.0];
                    n.q_ned_body = [(0.005f64).cos(), 0.0, 0.0, (0.005f64).sin()];
                    if k % 2 == 0 {
                        rec.record(Record::Truth(tr), 0);
                        rec.record(Record::Nav(n), 0);
                    } else {
                        rec.record(Record::Nav(n), 0);
                        rec.record(Record::Truth(tr), 0);
                    }
                    if k % 10 == 0 {
                        let mut g = GnssSample::default();
                        g.header.time_ns = t;
                        g.header.seq = k as u64 / 10;
                        g.fix_valid = 1;
                        g.pos_ecef_m = [6_378_139.0, 1.0, -2.0];
                        rec.record(Record::Gnss(Box::new(g)), 7);
                        let mut st = Status::default();
                        st.header.time_ns = t;
                        st.mode = 2;
                        rec.record(Record::Status(Box::new(st)), 8);
                    }
                }
                let (stats, segments) = rec.finish_with_segments().unwrap();
                assert_eq!((stats.dropped, stats.errors), (0, 0));
                assert!(segments.len() >= 2, "{segments:?}");
                analysis.join().unwrap()
            });
            let read = analyze(&path, &[]).unwrap();
            assert_eq!(tapped.summary, read.summary, "{}", encoding.name());
            assert_eq!(tapped.series, read.series, "{}", encoding.name());
            // Not an empty comparison: everything was seen and matched.
            let s = &tapped.summary;
            assert_eq!(s.solutions, 200);
            assert_eq!(s.solutions_matched_with_truth, 200);
            assert_eq!(s.messages_per_channel["fusion/sensor_alive"], 1);
            assert_eq!(s.messages_per_channel["status/plot"], 21);
            assert_eq!(s.sequence_gaps_per_channel["truth"], 1);
            assert!(s.gnss_fix_horizontal_error_rms_m.is_some());
            assert!(s.latency_p99_us.is_some());
            std::fs::remove_dir_all(&dir).ok();
        }
    }

    /// A receiver fix is the antenna's position: its error is taken against the truth moved by
    /// the lever arm of the recording's filter configuration, in the true attitude (here a
    /// heading of 90°, so the arm's forward metre points east).
    #[test]
    fn fix_errors_are_taken_at_the_antenna() {
        use crate::recorder::{CONFIG_KEY_FILTER_TOML, CONFIG_METADATA_NAME};
        use fusion::navigator::NavigatorConfig;
        use msgs::GnssSample;
        let dir = std::env::temp_dir().join(format!("sextant-analysis-arm-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut cfg = NavigatorConfig::default();
        cfg.gnss.lever_arm_b_m = [1.0, 0.0, -2.0];
        let meta = BTreeMap::from([(
            CONFIG_KEY_FILTER_TOML.to_string(),
            toml::to_string(&cfg).unwrap(),
        )]);
        let with_config = dir.join("with.mcap");
        let without_config = dir.join("without.mcap");
        for (path, metadata) in [
            (&with_config, vec![(CONFIG_METADATA_NAME.to_string(), meta)]),
            (&without_config, vec![]),
        ] {
            let rec = Recorder::start(
                path,
                &RecorderOptions {
                    metadata,
                    ..Default::default()
                },
            )
            .unwrap();
            let h = std::f64::consts::FRAC_PI_4; // half of the 90° heading
            for k in 0..10i64 {
                let t = 1_400_000_000_000_000_000i64 + k * 1_000_000_000;
                let mut tr = TruthSample::default();
                tr.header.time_ns = t;
                tr.pos_ecef_m = [6_378_137.0, 0.0, 0.0];
                tr.q_ned_body = [h.cos(), 0.0, 0.0, h.sin()];
                rec.record(Record::Truth(tr), 0);
                // At (0°, 0°) north is ECEF z, east y, down −x: the arm [1, 0, −2] in a body
                // heading east is 1 m east and 2 m up.
                let mut g = GnssSample::default();
                g.header.time_ns = t;
                g.fix_valid = 1;
                g.pos_ecef_m = [6_378_139.0, 1.0, 0.0];
                rec.record(Record::Gnss(Box::new(g)), 0);
            }
            rec.finish().unwrap();
        }
        let s = analyze_recording(&with_config, &[]).unwrap();
        assert!(s.gnss_fix_horizontal_error_rms_m.unwrap() < 1e-6, "{s:?}");
        assert!(s.gnss_fix_vertical_error_rms_m.unwrap() < 1e-6, "{s:?}");
        // Without a configuration the fix is compared with the IMU's position.
        let s = analyze_recording(&without_config, &[]).unwrap();
        assert!(
            (s.gnss_fix_horizontal_error_rms_m.unwrap() - 1.0).abs() < 1e-6,
            "{s:?}"
        );
        assert!(
            (s.gnss_fix_vertical_error_rms_m.unwrap() - 2.0).abs() < 1e-6,
            "{s:?}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn garbage_is_a_clear_error() {
        let dir = std::env::temp_dir().join(format!("sextant-analysis-g-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("bad.mcap");
        std::fs::write(&path, b"not an mcap").unwrap();
        let e = analyze_recording(&path, &[]).unwrap_err().to_string();
        assert!(e.contains("bad.mcap"), "{e}");
    }
}
