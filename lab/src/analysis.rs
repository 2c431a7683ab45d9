//! Analysis of a recording: messages per channel, drops (recorder drops, sequence-number gaps),
//! error of the solution against the truth (matched by identical time of validity), errors during
//! and after GNSS outages, and IMU-to-solution latency. Used by `sextant run` and, later,
//! `sextant report`.
//!
//! Read through [`crate::recording`]; a recording cut short by a crash is read up to its last
//! complete chunk (`Summary::recording_truncated` tells).

use crate::foxglove::{NedOrigin, ned_offset};
use crate::recorder::Record;
use crate::recording::{Recording, RecordingError};
use crate::scenario::TimeWindow;
use crate::stats::{max_abs, percentile, rms};
use msgs::{NavMode, NavSolution, Status, TruthSample};
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

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
    /// fix against the truth sample of its time tag (the IMU's position, which is the
    /// antenna's when the scenario has no lever arm), to set beside the solution's.
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

impl Series {
    /// Append one solution matched with the truth sample of its time of validity: `t_s` s
    /// since `t0_ns`, its NED position error `e_ned_m` (solution − truth, m) and attitude error
    /// angle (deg), and both positions as north/east from `origin` (when there is one).
    pub(crate) fn push_matched(
        &mut self,
        t_s: f64,
        e_ned_m: &[f64; 3],
        attitude_deg: f64,
        nav: &NavSolution,
        truth: &TruthSample,
        origin: Option<&NedOrigin>,
    ) {
        self.t_s.push(t_s);
        self.horizontal_m.push(e_ned_m[0].hypot(e_ned_m[1]));
        self.vertical_m.push(-e_ned_m[2]);
        self.attitude_deg.push(attitude_deg);
        if let Some(o) = origin {
            let tn = ned_offset(o.r_e, o.lat_rad, o.lon_rad, truth.pos_ecef_m);
            let nn = ned_offset(o.r_e, o.lat_rad, o.lon_rad, nav.pos_ecef_m);
            self.truth_ne_m.push((tn[0], tn[1]));
            self.nav_ne_m.push((nn[0], nn[1]));
        }
    }
}

/// Analyse the recording at `path` with the GNSS outage windows of its scenario.
pub fn analyze_recording(path: &Path, outages: &[TimeWindow]) -> Result<Summary, AnalysisError> {
    analyze(path, outages).map(|a| a.summary)
}

/// Like [`analyze_recording`], with the time series for plots.
pub fn analyze(path: &Path, outages: &[TimeWindow]) -> Result<Analysis, AnalysisError> {
    analyze_with_progress(path, outages, false)
}

/// [`analyze`] with a progress bar over the file on stderr when `progress` (see
/// [`crate::progress`]): the analysis at the end of `sextant run` and `replay`.
pub fn analyze_with_progress(
    path: &Path,
    outages: &[TimeWindow],
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
    let mut s = Summary {
        recording: path.display().to_string(),
        ..Default::default()
    };
    let mut last_seq: HashMap<String, u64> = HashMap::new();
    let mut truth: HashMap<i64, TruthSample> = HashMap::new();
    let mut first_truth: Option<TruthSample> = None;
    let mut navs: Vec<NavSolution> = Vec::new();
    let mut fixes: Vec<(i64, [f64; 3])> = Vec::new();
    let mut last_status: Option<Status> = None;
    let (mut t_min, mut t_max) = (i64::MAX, i64::MIN);
    let mut n = 0u64;
    for m in rec {
        let m = match m {
            Ok(m) => m,
            Err(e) => {
                tracing::warn!("{}: reading stopped: {e}", path.display());
                s.recording_truncated = true;
                break;
            }
        };
        n += 1;
        if n.is_multiple_of(4096) {
            pb.set_position(m.offset);
        }
        *s.messages_per_channel
            .entry(m.topic.to_string())
            .or_insert(0) += 1;
        let Some(record) = m.record else {
            continue;
        };
        let Some(ch) = record.channel() else {
            continue;
        };
        let topic = ch.name().to_string();
        let h = *record.header();
        if h.time_ns > 0 {
            t_min = t_min.min(h.time_ns);
            t_max = t_max.max(h.time_ns);
        }
        let gaps = s
            .sequence_gaps_per_channel
            .entry(topic.clone())
            .or_insert(0);
        if let Some(prev) = last_seq.insert(topic.clone(), h.seq) {
            if h.seq > prev + 1 {
                *gaps += h.seq - prev - 1;
            } else if h.seq <= prev {
                *s.sequence_restarts_per_channel
                    .entry(topic.clone())
                    .or_insert(0) += 1;
            }
        }
        match record {
            Record::Truth(t) => {
                first_truth.get_or_insert(t);
                truth.insert(t.header.time_ns, t);
            }
            Record::Nav(n) => navs.push(n),
            Record::Gnss(g) if g.fix_valid == 1 => fixes.push((g.header.time_ns, g.pos_ecef_m)),
            Record::Status(st) => last_status = Some(*st),
            _ => {}
        }
    }
    pb.finish_and_clear();
    if let Some(st) = &last_status {
        s.records_dropped = st.records_dropped;
        s.final_mode = Some(
            NavMode::from_u32(st.mode)
                .map(|m| m.name().to_string())
                .unwrap_or_else(|| format!("unknown({})", st.mode)),
        );
    }
    s.solutions = navs.len() as u64;
    if t_max > t_min {
        s.recorded_time_span_s = (t_max - t_min) as f64 * 1e-9;
    }
    if let (Some(a), Some(b)) = (navs.first(), navs.last()) {
        s.duration_s = (b.header.time_ns - a.header.time_ns) as f64 * 1e-9;
    } else if t_max > t_min {
        s.duration_s = (t_max - t_min) as f64 * 1e-9;
    }

    let t0_ns = first_truth
        .map(|t| t.header.time_ns)
        .or_else(|| navs.first().map(|n| n.header.time_ns))
        .unwrap_or(0);
    let mut series = Series {
        t0_ns,
        outages_s: outages
            .iter()
            .map(|w| {
                (
                    (w.start_ns - t0_ns) as f64 * 1e-9,
                    (w.end_ns - t0_ns) as f64 * 1e-9,
                )
            })
            .collect(),
        ..Default::default()
    };
    let origin = first_truth.as_ref().map(ned_origin);
    let mut t_ns = Vec::new();
    let mut latency_us = Vec::new();
    for n in &navs {
        if n.header.send_mono_ns > 0 && n.imu_send_mono_ns > 0 {
            latency_us.push(n.header.send_mono_ns.saturating_sub(n.imu_send_mono_ns) as f64 * 1e-3);
        }
        let Some(t) = truth.get(&n.header.time_ns) else {
            continue;
        };
        let e = position_error_ned_m(n, t);
        let att = attitude_error_rad(t.q_ned_body, n.q_ned_body).to_degrees();
        if !(e.iter().all(|x| x.is_finite()) && att.is_finite()) {
            continue;
        }
        t_ns.push(n.header.time_ns);
        let t_s = (n.header.time_ns - t0_ns) as f64 * 1e-9;
        series.push_matched(t_s, &e, att, n, t, origin.as_ref());
    }
    s.solutions_matched_with_truth = t_ns.len() as u64;
    let (mut fix_h, mut fix_v) = (Vec::new(), Vec::new());
    for (t, pos) in &fixes {
        if let Some(tr) = truth.get(t) {
            let e = ned_offset(tr.pos_ecef_m, tr.lat_rad, tr.lon_rad, *pos);
            if e.iter().all(|x| x.is_finite()) {
                fix_h.push(e[0].hypot(e[1]));
                fix_v.push(e[2]);
            }
        }
    }
    s.gnss_fix_horizontal_error_rms_m = rms(&fix_h);
    s.gnss_fix_vertical_error_rms_m = rms(&fix_v);
    s.horizontal_error_rms_m = rms(&series.horizontal_m);
    s.horizontal_error_max_m = max_abs(&series.horizontal_m);
    s.vertical_error_rms_m = rms(&series.vertical_m);
    s.vertical_error_max_m = max_abs(&series.vertical_m);
    s.attitude_error_rms_deg = rms(&series.attitude_deg);
    s.attitude_error_max_deg = max_abs(&series.attitude_deg);
    s.latency_p50_us = percentile(&latency_us, 50.0);
    s.latency_p99_us = percentile(&latency_us, 99.0);
    s.latency_max_us = max_abs(&latency_us);

    let mut all_during = Vec::new();
    let mut all_after = Vec::new();
    for w in outages {
        let after = TimeWindow {
            start_ns: w.end_ns,
            end_ns: w.end_ns + (AFTER_OUTAGE_S * 1e9) as i64,
        };
        let during: Vec<f64> = t_ns
            .iter()
            .zip(&series.horizontal_m)
            .filter(|(t, _)| w.contains(**t))
            .map(|(_, e)| *e)
            .collect();
        let after_v: Vec<f64> = t_ns
            .iter()
            .zip(&series.horizontal_m)
            .filter(|(t, _)| after.contains(**t))
            .map(|(_, e)| *e)
            .collect();
        s.gnss_outages.push(OutageSummary {
            start_s: (w.start_ns - t0_ns) as f64 * 1e-9,
            end_s: (w.end_ns - t0_ns) as f64 * 1e-9,
            horizontal_error_max_m: max_abs(&during),
            after_outage_horizontal_error_rms_m: rms(&after_v),
        });
        all_during.extend(during);
        all_after.extend(after_v);
    }
    s.outage_horizontal_error_max_m = max_abs(&all_during);
    s.after_outage_horizontal_error_rms_m = rms(&all_after);
    Ok(Analysis { summary: s, series })
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
            "solutions (matched with truth)".into(),
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
        "latency p50 / p99 / max [µs]".into(),
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
