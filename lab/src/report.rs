//! Post-analysis of a recording (`sextant report REC.mcap --out DIR`): errors against the truth
//! when the recording has it (RMS, maximum and 95th percentile of |e| per axis N/E/D, horizontal,
//! 3-D, velocity, attitude), the filter's consistency (fraction of errors inside ±3σ of its own
//! covariance), innovation statistics per sensor (NIS against its degrees of freedom, with the
//! χ² 95 % interval), rejections, mode changes, sensor dead/alive events and dropouts (gaps
//! longer than twice a channel's median period); PNG plots (trajectory, error with ±3σ
//! envelope, biases, boresight, NIS), `REPORT.md` and `summary.json`.
//!
//! Reads through [`crate::recording`]: a truncated or corrupt recording is analysed up to the
//! error, which the report names (with its byte offset).

use crate::analysis::{self, Series};
use crate::experiments::plot::{Chart, Line, color, line_chart};
use crate::recorder::Record;
use crate::recording::{Recording, RecordingError};
use crate::stats::{max_abs, percentile, rms};
use msgs::{MAX_SENSORS, NavMode, NavSolution, SensorId, Status, TruthSample};
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
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
    /// 95th percentile of the absolute value.
    pub p95: Option<f64>,
    /// Fraction of samples with |error| ≤ 3σ of the filter's own covariance (≈ 0.997 for a
    /// consistent filter with Gaussian errors); `None` where no σ applies.
    pub within_3sigma_fraction: Option<f64>,
}

fn stats(e: &[f64], sigma: Option<&[f64]>) -> ErrorStats {
    let abs: Vec<f64> = e.iter().map(|x| x.abs()).collect();
    ErrorStats {
        rms: rms(e),
        max: max_abs(e),
        p95: percentile(&abs, 95.0),
        within_3sigma_fraction: sigma.filter(|s| !s.is_empty()).map(|s| {
            let n = e
                .iter()
                .zip(s)
                .filter(|(x, s)| x.abs() <= 3.0 * **s)
                .count();
            n as f64 / e.len().max(1) as f64
        }),
    }
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
    /// Median period of the channel (time of validity), s.
    pub period_s: Option<f64>,
    /// Gaps longer than twice the period.
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
    /// Mode changes of the solution.
    pub mode_changes: Vec<ModeChange>,
    /// Sensor dead/alive events.
    pub alive_events: Vec<AliveEvent>,
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

/// Time series for the plots (decimated to at most `MAX_POINTS`).
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

const MAX_POINTS: usize = 4000;

/// Analyse `path` and write `summary.json`, `REPORT.md` and the plots into `out_dir`.
pub fn report(path: &Path, out_dir: &Path) -> Result<ReportSummary, ReportError> {
    let werr = |p: &Path, e: &dyn std::fmt::Display| ReportError::Write {
        path: p.to_path_buf(),
        detail: e.to_string(),
    };
    std::fs::create_dir_all(out_dir).map_err(|e| werr(out_dir, &e))?;
    let mut rec = Recording::open(path)?;
    let mut s = ReportSummary {
        recording: path.display().to_string(),
        ..Default::default()
    };
    let mut truth: HashMap<i64, TruthSample> = HashMap::new();
    let mut first_truth: Option<TruthSample> = None;
    let mut navs: Vec<NavSolution> = Vec::new();
    let mut statuses: Vec<Status> = Vec::new();
    let mut times: [Vec<i64>; MAX_SENSORS] = Default::default();
    let mut alive: Vec<(i64, u32, bool)> = Vec::new();
    let mut t_start = i64::MAX;
    let (mut sextant_records, mut foreign) = (0u64, 0u64);
    let mut foreign_topics: Vec<String> = Vec::new();
    let pb = crate::progress::bytes(true, crate::progress::file_len(path), "report");
    let mut n = 0u64;
    for e in &mut rec {
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
            Record::Imu(_) => times[SensorId::Imu as usize].push(t),
            Record::StarTracker(_) => times[SensorId::StarTracker as usize].push(t),
            Record::Gnss(_) => times[SensorId::Gnss as usize].push(t),
            Record::Odometer(_) => times[SensorId::Odometer as usize].push(t),
            Record::Baro(_) => times[SensorId::Baro as usize].push(t),
            Record::Truth(tr) => {
                first_truth.get_or_insert(tr);
                truth.insert(t, tr);
            }
            Record::Nav(n) => navs.push(n),
            Record::Status(st) => statuses.push(*st),
            Record::SensorAlive(ev) => alive.push((t, ev.sensor, ev.alive)),
        }
    }
    pb.finish_and_clear();
    s.recording_complete = rec.is_complete();
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
    s.solutions = navs.len() as u64;
    if let (Some(a), Some(b)) = (navs.first(), navs.last()) {
        s.navigation_duration_s = (b.header.time_ns - a.header.time_ns) as f64 * 1e-9;
        s.final_gyro_bias_deg_h = Some(b.gyro_bias_rad_s.map(|x| x / DEG_H));
        s.final_accel_bias_ug = Some(b.accel_bias_m_s2.map(|x| x / G * 1e6));
        s.final_boresight_arcsec = Some(b.boresight_rad.map(|x| x / ARCSEC));
        s.final_boresight_sigma_arcsec = Some(b.boresight_sigma_rad.map(|x| x / ARCSEC));
    }

    // Mode changes.
    let mode_name = |m: u32| {
        NavMode::from_u32(m)
            .map(|m| m.name().to_string())
            .unwrap_or_else(|| format!("unknown({m})"))
    };
    let mut prev: Option<u32> = None;
    for n in &navs {
        if prev != Some(n.mode) {
            s.mode_changes.push(ModeChange {
                time_s: secs(n.header.time_ns),
                from: prev.map(mode_name).unwrap_or_else(|| "none".into()),
                to: mode_name(n.mode),
            });
            prev = Some(n.mode);
        }
    }
    for (t, sensor, a) in &alive {
        s.alive_events.push(AliveEvent {
            // Decisions before the first IMU sample carry filter time 0: report them at 0.
            time_s: if *t > 0 { secs(*t) } else { 0.0 },
            sensor: SensorId::ALL
                .get(*sensor as usize)
                .map(|x| x.name().to_string())
                .unwrap_or_else(|| sensor.to_string()),
            alive: *a,
        });
    }

    // Errors against truth.
    let mut p = Plots::default();
    let stride = (navs.len() / MAX_POINTS).max(1);
    let origin = first_truth.as_ref().map(analysis::ned_origin);
    let mut series = Series {
        t0_ns: t_start,
        ..Default::default()
    };
    let mut pos: [Vec<f64>; 3] = Default::default();
    let mut pos_sig: [Vec<f64>; 3] = Default::default();
    let mut vel: [Vec<f64>; 3] = Default::default();
    let mut att: [Vec<f64>; 3] = Default::default();
    let mut att_sig: [Vec<f64>; 3] = Default::default();
    let (mut hor, mut d3, mut ang) = (Vec::new(), Vec::new(), Vec::new());
    for (k, n) in navs.iter().enumerate() {
        if k % stride == 0 {
            p.nav_t.push(secs(n.header.time_ns));
            for i in 0..3 {
                p.gyro[i].push(n.gyro_bias_rad_s[i] / DEG_H);
                p.accel[i].push(n.accel_bias_m_s2[i] / G * 1e6);
                p.bore[i].push(n.boresight_rad[i] / ARCSEC);
                p.bore_sig[i].push(3.0 * n.boresight_sigma_rad[i] / ARCSEC);
            }
        }
        let Some(t) = truth.get(&n.header.time_ns) else {
            continue;
        };
        let e = analysis::position_error_ned_m(n, t);
        let a = attitude_error_ned_rad(t.q_ned_body, n.q_ned_body);
        if !(e.iter().chain(&a).all(|x| x.is_finite())) {
            continue;
        }
        for i in 0..3 {
            pos[i].push(e[i]);
            pos_sig[i].push(n.pos_sigma_ned_m[i]);
            vel[i].push(n.vel_ned_m_s[i] - t.vel_ned_m_s[i]);
            att[i].push(a[i].to_degrees());
            att_sig[i].push(n.att_sigma_ned_rad[i].to_degrees());
        }
        hor.push(e[0].hypot(e[1]));
        d3.push((e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt());
        ang.push(analysis::attitude_error_rad(t.q_ned_body, n.q_ned_body).to_degrees());
        if pos[0].len() % stride == 1 || stride == 1 {
            p.t.push(secs(n.header.time_ns));
            for i in 0..3 {
                p.err[i].push(e[i]);
                p.sig[i].push(3.0 * n.pos_sigma_ned_m[i]);
                p.att[i].push(a[i].to_degrees());
                p.att_sig[i].push(3.0 * n.att_sigma_ned_rad[i].to_degrees());
            }
            let att_deg = *ang.last().unwrap_or(&0.0);
            series.push_matched(secs(n.header.time_ns), &e, att_deg, n, t, origin.as_ref());
        }
    }
    if !hor.is_empty() {
        s.truth_errors = Some(TruthErrors {
            solutions_matched: hor.len() as u64,
            position_north_m: stats(&pos[0], Some(&pos_sig[0])),
            position_east_m: stats(&pos[1], Some(&pos_sig[1])),
            position_down_m: stats(&pos[2], Some(&pos_sig[2])),
            position_horizontal_m: stats(&hor, None),
            position_3d_m: stats(&d3, None),
            velocity_north_m_s: stats(&vel[0], None),
            velocity_east_m_s: stats(&vel[1], None),
            velocity_down_m_s: stats(&vel[2], None),
            attitude_north_deg: stats(&att[0], Some(&att_sig[0])),
            attitude_east_deg: stats(&att[1], Some(&att_sig[1])),
            attitude_down_deg: stats(&att[2], Some(&att_sig[2])),
            attitude_angle_deg: stats(&ang, None),
        });
    }
    let tstride = (truth.len() / MAX_POINTS).max(1);
    let mut tkeys: Vec<&i64> = truth.keys().collect();
    tkeys.sort();
    for (k, t) in tkeys.iter().enumerate() {
        if k % tstride == 0 {
            let tr = &truth[*t];
            p.truth_t.push(secs(**t));
            for i in 0..3 {
                p.truth_gyro[i].push(tr.gyro_bias_rad_s[i] / DEG_H);
                p.truth_accel[i].push(tr.accel_bias_m_s2[i] / G * 1e6);
            }
        }
    }

    // Per sensor: health and NIS from the last status, dropouts from the recorded times.
    let last = statuses.last().copied().unwrap_or_default();
    s.records_dropped = last.records_dropped;
    s.recorder_errors = last.recorder_errors;
    for sensor in SensorId::ALL {
        let i = sensor as usize;
        let h = last.sensors[i];
        let mut r = SensorReport {
            sensor: sensor.name().to_string(),
            samples_recorded: times[i].len() as u64,
            received: h.received,
            fused: h.fused,
            rejected_gate: h.rejected_gate,
            rejected_invalid: h.rejected_invalid,
            dropped_late: h.dropped_late,
            deadline_misses: h.deadline_misses,
            nis_updates: h.nis_count,
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
        let mut dt: Vec<f64> = times[i]
            .windows(2)
            .map(|w| (w[1] - w[0]) as f64 * 1e-9)
            .filter(|d| *d > 0.0)
            .collect();
        if let Some(period) = percentile(&dt, 50.0) {
            r.period_s = Some(period);
            for w in times[i].windows(2) {
                let gap = (w[1] - w[0]) as f64 * 1e-9;
                if gap > 2.0 * period {
                    r.dropouts += 1;
                    if s.dropouts.len() < 200 {
                        s.dropouts.push(Dropout {
                            channel: sensor.name().to_string(),
                            start_s: secs(w[0]),
                            gap_s: gap,
                        });
                    }
                }
            }
            dt.sort_by(f64::total_cmp);
            r.longest_gap_s = dt.last().copied();
        }
        s.sensors.push(r);
        // NIS per dof between consecutive statuses (windowed innovation consistency).
        for w in statuses.windows(2) {
            let t = w[1].header.time_ns;
            let (a, b) = (w[0].sensors[i], w[1].sensors[i]);
            let dof = b.nis_dof_sum.saturating_sub(a.nis_dof_sum);
            if dof > 0 {
                p.nis[i].push((secs(t), (b.nis_sum - a.nis_sum) / dof as f64));
            }
        }
    }

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
            &Chart {
                title,
                x_label: "time since start [s]",
                y_label,
                log_x: false,
                log_y: false,
                lines: &lines,
            },
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
    for c in &s.mode_changes {
        m.push_str(&format!("- {:.2} s: {} → {}\n", c.time_s, c.from, c.to));
    }
    m.push_str("\n## Sensor dead/alive events\n\n");
    if s.alive_events.is_empty() {
        m.push_str("None.\n");
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
    row("mode changes", s.mode_changes.len().to_string());
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
}
