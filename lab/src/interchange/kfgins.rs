//! The KF-GINS text formats (Niu et al., "KF-GINS: an open-sourced software for GNSS/INS
//! integrated navigation", GPS Solutions 29:202, 2025; its README "Data format"), shared by the
//! i2Nav open GNSS/INS datasets. Whitespace- or comma-separated numbers, one epoch per line:
//!
//! | file | columns |
//! |---|---|
//! | IMU increments | GPS seconds of week; Δθ x, y, z [rad]; Δv x, y, z [m/s] (extra columns ignored) |
//! | GNSS positions | seconds of week; latitude, longitude [deg]; ellipsoidal height [m]; σ north, east, down [m] |
//! | result / reference trajectory | GPS week; seconds of week; latitude, longitude [deg]; height [m]; v north, east, down [m/s]; roll, pitch, yaw [deg] (z-y-x) |
//!
//! Frames: the IMU axes are x forward, y right, z down (KF-GINS README §2.1), Sextant's body
//! frame, so increments pass unrotated. Δθ and Δv at time t are integrated over the interval
//! that ends at t (KF-GINS takes the interval from consecutive times, as Sextant's
//! `ImuSample.dt_s`). The GNSS position file may also have 13 columns: KF-GINS then reads the
//! standard deviations from columns 8–10 and ignores columns 5–7 and 11–13, and so does this
//! reader. A GNSS row becomes a fix with the NED covariance diag(σ²) rotated into ECEF and no
//! velocity (zero velocity covariance: the filter does not use a velocity it is not given).
//!
//! Reading: blank lines and lines starting with `#` or `%` are skipped; every other line must
//! have the file's columns as finite numbers in strictly increasing time, else the error names
//! the file, line and column. The IMU and GNSS files carry no week: it is given, or taken from
//! the reference trajectory; a seconds-of-week value more than half a week below the previous
//! one is a week rollover.
//!
//! Writing: times with nine decimals (exact to the nanosecond), every other value as the
//! shortest text that reads back to the same `f64` bits; angles in degrees are the radians
//! times 180/π, and a fix's ECEF position goes through `ecef_to_geodetic` and back, so a
//! position comes back to the precision of that conversion (< 0.1 mm by its contract), not
//! bit for bit. Only valid fixes are written; their ECEF covariance loses its off-diagonal NED
//! terms.

use super::kfgins_yaml::{KFGINS_CONFIG_FILE, config_text, imu_rate_hz, start_from_truth};
use super::text::{self, TextError, WeekTracker, format_f64, format_seconds_ns, number};
use super::{Counts, InterchangeError, Streams};
use fusion::attitude::{q_n_b_from_rpy, quat_to_wire};
use fusion::earth::{self, Geodetic, WGS84};
use fusion::time::GpsTime;
use msgs::{GnssSample, Header, ImuSample, NavSolution, TruthSample};
use nalgebra::{Matrix3, Vector3};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Columns of the IMU file used (time, Δθ, Δv).
pub const IMU_COLUMNS: usize = 7;
/// Columns of the GNSS position file (or [`GNSS_COLUMNS_WITH_VELOCITY`]).
pub const GNSS_COLUMNS: usize = 7;
/// Columns of the GNSS file variant KF-GINS also reads.
pub const GNSS_COLUMNS_WITH_VELOCITY: usize = 13;
/// Columns of the result / reference-trajectory file.
pub const TRAJECTORY_COLUMNS: usize = 11;

/// File names `sextant export kfgins` writes in its output directory.
pub const IMU_FILE: &str = "imu.txt";
/// GNSS positions.
pub const GNSS_FILE: &str = "gnss.txt";
/// The recording's truth as a reference trajectory.
pub const TRUTH_FILE: &str = "truth.nav";
/// The recording's solutions in the result format.
pub const NAV_FILE: &str = "nav.nav";
/// The recording's embedded filter configuration.
pub const FILTER_FILE: &str = "filter.toml";

/// The data lines of a KF-GINS text: (line number from 1, fields).
fn rows(text: &str) -> impl Iterator<Item = (u64, Vec<&str>)> {
    text.lines().enumerate().filter_map(|(i, l)| {
        let l = l.trim();
        if l.is_empty() || l.starts_with('#') || l.starts_with('%') {
            return None;
        }
        let fields = l
            .split([' ', '\t', ','])
            .filter(|f| !f.is_empty())
            .collect();
        Some((i as u64 + 1, fields))
    })
}

fn need_columns(path: &Path, line: u64, fields: &[&str], n: usize) -> Result<(), TextError> {
    if fields.len() < n {
        return Err(TextError::new(
            path,
            line,
            fields.len() + 1,
            format!("{} columns, {n} expected", fields.len()),
        ));
    }
    Ok(())
}

fn seconds_of_week(path: &Path, line: u64, column: usize, tok: &str) -> Result<i64, TextError> {
    match text::parse_seconds_ns(tok) {
        Some(ns) if ns < text::NS_PER_WEEK => Ok(ns),
        _ => Err(TextError::new(
            path,
            line,
            column,
            format!("{tok:?} is not a time of week in [0, 604800) s"),
        )),
    }
}

fn vec3(path: &Path, line: u64, fields: &[&str], first: usize) -> Result<[f64; 3], TextError> {
    let mut v = [0.0; 3];
    for (k, x) in v.iter_mut().enumerate() {
        *x = number(path, line, first + k + 1, fields[first + k])?;
    }
    Ok(v)
}

/// Strictly increasing times: the error when `t` is not after `last`.
pub fn check_increasing(
    path: &Path,
    line: u64,
    last: Option<i64>,
    t: i64,
) -> Result<(), TextError> {
    match last {
        Some(l) if t <= l => Err(TextError::new(
            path,
            line,
            1,
            format!(
                "time {} s is not after the previous row's {} s",
                format_seconds_ns(t),
                format_seconds_ns(l)
            ),
        )),
        _ => Ok(()),
    }
}

/// One IMU row as read: line, GPS ns, Δθ (rad), Δv (m/s), interval (s) if the file gives it.
pub type ImuRow = (u64, i64, [f64; 3], [f64; 3], Option<f64>);

/// IMU samples from increments at strictly increasing times: `rows` are (line, GPS ns, Δθ rad,
/// Δv m/s, interval s if the file gives it). Without a given interval, sample k's is
/// `t_k − t_(k−1)` and the first sample's that of the second (an interval of a single sample
/// is unknown: error).
pub fn imu_samples(path: &Path, rows: &[ImuRow]) -> Result<Vec<ImuSample>, TextError> {
    let mut out = Vec::with_capacity(rows.len());
    for (k, &(line, t, dtheta, dv, dt)) in rows.iter().enumerate() {
        check_increasing(path, line, k.checked_sub(1).map(|j| rows[j].1), t)?;
        let dt_s = match dt {
            Some(dt) if dt > 0.0 => dt,
            Some(dt) => {
                return Err(TextError::new(
                    path,
                    line,
                    0,
                    format!("interval {dt} s is not positive"),
                ));
            }
            None if k > 0 => (t - rows[k - 1].1) as f64 / 1e9,
            None => match rows.get(1) {
                Some(next) if next.1 > t => (next.1 - t) as f64 / 1e9,
                Some(next) => {
                    return Err(check_increasing(path, next.0, Some(t), next.1).unwrap_err());
                }
                None => {
                    return Err(TextError::new(
                        path,
                        line,
                        0,
                        "a single IMU sample: its interval is unknown",
                    ));
                }
            },
        };
        out.push(ImuSample {
            header: Header {
                time_ns: t,
                ..Default::default()
            },
            dt_s,
            delta_angle_rad: dtheta,
            delta_velocity_m_s: dv,
            ..Default::default()
        });
    }
    Ok(out)
}

/// A GNSS fix at `t` from a geodetic position (rad, m) with 1-σ north, east, down (m): ECEF
/// position, covariance `C_e_n · diag(σ²) · C_n_e`, no velocity.
pub fn gnss_fix(t: GpsTime, g: &Geodetic, sigma_ned_m: [f64; 3]) -> GnssSample {
    let c_e_n = earth::c_e_n(g.lat_rad, g.lon_rad);
    let d = Matrix3::from_diagonal(&Vector3::from(sigma_ned_m).map(|s| s * s));
    let cov = c_e_n * d * c_e_n.transpose();
    gnss_fix_ecef(t, &earth::geodetic_to_ecef(&WGS84, g), &cov)
}

/// A GNSS fix at `t` from an ECEF position (m) and its covariance (m²), no velocity.
pub fn gnss_fix_ecef(t: GpsTime, r_e_m: &Vector3<f64>, cov_e_m2: &Matrix3<f64>) -> GnssSample {
    let mut s = GnssSample {
        header: Header {
            time_ns: t.ns,
            ..Default::default()
        },
        fix_valid: 1,
        pos_ecef_m: [r_e_m.x, r_e_m.y, r_e_m.z],
        ..Default::default()
    };
    for r in 0..3 {
        for c in 0..3 {
            s.pos_cov_ecef_m2[3 * r + c] = cov_e_m2[(r, c)];
        }
    }
    s
}

/// 1-σ north, east, down (m) of a fix's ECEF position covariance at its position.
pub fn sigma_ned_m(s: &GnssSample) -> (Geodetic, [f64; 3]) {
    let g = earth::ecef_to_geodetic(&WGS84, &Vector3::from(s.pos_ecef_m));
    let c_e_n = earth::c_e_n(g.lat_rad, g.lon_rad);
    let p = Matrix3::from_row_slice(&s.pos_cov_ecef_m2);
    let p_n = c_e_n.transpose() * p * c_e_n;
    (g, [0, 1, 2].map(|k| p_n[(k, k)].max(0.0).sqrt()))
}

/// A reference-trajectory sample at `t`: geodetic position (rad, m), NED velocity (m/s) and
/// roll, pitch, heading (rad, z-y-x).
pub fn truth_sample(
    t: GpsTime,
    g: &Geodetic,
    v_ned_m_s: [f64; 3],
    rph_rad: [f64; 3],
) -> TruthSample {
    let r = earth::geodetic_to_ecef(&WGS84, g);
    TruthSample {
        header: Header {
            time_ns: t.ns,
            ..Default::default()
        },
        lat_rad: g.lat_rad,
        lon_rad: g.lon_rad,
        height_m: g.height_m,
        pos_ecef_m: [r.x, r.y, r.z],
        vel_ned_m_s: v_ned_m_s,
        q_ned_body: quat_to_wire(&q_n_b_from_rpy(rph_rad[0], rph_rad[1], rph_rad[2])),
        roll_pitch_heading_rad: rph_rad,
        ..Default::default()
    }
}

/// Read an IMU increment file; the first row is in the week `weeks` gives.
pub fn read_imu(
    path: &Path,
    text: &str,
    mut weeks: WeekTracker,
) -> Result<Vec<ImuSample>, TextError> {
    let mut parsed = Vec::new();
    for (line, f) in rows(text) {
        need_columns(path, line, &f, IMU_COLUMNS)?;
        let t = weeks.time(seconds_of_week(path, line, 1, f[0])?);
        parsed.push((
            line,
            t.ns,
            vec3(path, line, &f, 1)?,
            vec3(path, line, &f, 4)?,
            None,
        ));
    }
    imu_samples(path, &parsed)
}

/// Read a GNSS position file (7 or 13 columns).
pub fn read_gnss(
    path: &Path,
    text: &str,
    mut weeks: WeekTracker,
) -> Result<Vec<GnssSample>, TextError> {
    let mut out: Vec<GnssSample> = Vec::new();
    for (line, f) in rows(text) {
        let sigma_at = match f.len() {
            GNSS_COLUMNS => 4,
            GNSS_COLUMNS_WITH_VELOCITY => 7,
            n => {
                return Err(TextError::new(
                    path,
                    line,
                    n.min(GNSS_COLUMNS) + 1,
                    format!("{n} columns, 7 or 13 expected"),
                ));
            }
        };
        let t = weeks.time(seconds_of_week(path, line, 1, f[0])?);
        check_increasing(path, line, out.last().map(|s| s.header.time_ns), t.ns)?;
        let [lat, lon, h] = vec3(path, line, &f, 1)?;
        let sigma = vec3(path, line, &f, sigma_at)?;
        if let Some(k) = sigma.iter().position(|s| *s <= 0.0) {
            return Err(TextError::new(
                path,
                line,
                sigma_at + k + 1,
                "standard deviation must be positive",
            ));
        }
        if !(-90.0..=90.0).contains(&lat) {
            return Err(TextError::new(path, line, 2, "latitude outside ±90°"));
        }
        let g = Geodetic {
            lat_rad: lat.to_radians(),
            lon_rad: lon.to_radians(),
            height_m: h,
        };
        out.push(gnss_fix(t, &g, sigma));
    }
    Ok(out)
}

/// Read a result / reference-trajectory file (GPS week in its first column).
pub fn read_trajectory(path: &Path, text: &str) -> Result<Vec<TruthSample>, TextError> {
    let mut out: Vec<TruthSample> = Vec::new();
    for (line, f) in rows(text) {
        need_columns(path, line, &f, TRAJECTORY_COLUMNS)?;
        let week = number(path, line, 1, f[0])?;
        if week < 0.0 || week.fract() != 0.0 || week > 1e5 {
            return Err(TextError::new(
                path,
                line,
                1,
                format!("{:?} is not a GPS week", f[0]),
            ));
        }
        let sow = seconds_of_week(path, line, 2, f[1])?;
        let t = GpsTime::from_ns(week as i64 * text::NS_PER_WEEK + sow);
        check_increasing(path, line, out.last().map(|s| s.header.time_ns), t.ns)?;
        let [lat, lon, h] = vec3(path, line, &f, 2)?;
        if !(-90.0..=90.0).contains(&lat) {
            return Err(TextError::new(path, line, 3, "latitude outside ±90°"));
        }
        let v = vec3(path, line, &f, 5)?;
        let rph = vec3(path, line, &f, 8)?.map(f64::to_radians);
        let g = Geodetic {
            lat_rad: lat.to_radians(),
            lon_rad: lon.to_radians(),
            height_m: h,
        };
        out.push(truth_sample(t, &g, v, rph));
    }
    Ok(out)
}

/// What `sextant import kfgins` reads.
#[derive(Debug, Clone, Default)]
pub struct ImportFiles {
    /// IMU increment file.
    pub imu: Option<PathBuf>,
    /// GNSS position file.
    pub gnss: Option<PathBuf>,
    /// Reference trajectory (recorded as the truth, for `sextant report`).
    pub truth: Option<PathBuf>,
    /// GPS week of the first row of the IMU and GNSS files (else from the trajectory).
    pub week: Option<i64>,
}

fn read_text(path: &Path) -> Result<String, InterchangeError> {
    sextant_rinex::read_text(path).map_err(|e| InterchangeError::Io {
        path: path.to_path_buf(),
        source: std::io::Error::other(e.to_string()),
    })
}

/// Read the files of `files` (plain or `.gz`) into streams.
pub fn read_files(files: &ImportFiles) -> Result<Streams, InterchangeError> {
    let mut s = Streams::default();
    if let Some(p) = &files.truth {
        s.truth = read_trajectory(p, &read_text(p)?)?;
    }
    let weeks = |path: &Path| match (files.week, s.truth.first()) {
        (Some(w), _) => Ok(WeekTracker::with_week(w)),
        (None, Some(t)) => Ok(WeekTracker::near(GpsTime::from_ns(t.header.time_ns))),
        (None, None) => Err(InterchangeError::NoWeek {
            path: path.to_path_buf(),
        }),
    };
    if let Some(p) = &files.imu {
        s.imu = read_imu(p, &read_text(p)?, weeks(p)?)?;
    }
    if let Some(p) = &files.gnss {
        s.gnss = read_gnss(p, &read_text(p)?, weeks(p)?)?;
    }
    Ok(s)
}

/// Import KF-GINS files into a recording at `out` with the filter configuration of `config`
/// (default: the built-in one).
pub fn import(
    files: &ImportFiles,
    config: Option<&Path>,
    out: &Path,
) -> Result<Counts, InterchangeError> {
    let streams = read_files(files)?;
    let filter = super::filter_config(config)?;
    let mut meta = BTreeMap::from([("format".to_string(), "kf-gins".to_string())]);
    for (k, p) in [
        ("imu", &files.imu),
        ("gnss", &files.gnss),
        ("truth", &files.truth),
    ] {
        if let Some(p) = p {
            meta.insert(k.into(), p.display().to_string());
        }
    }
    let written = super::write_recording(out, &streams, &filter, meta)?;
    let mut c = streams.counts();
    c.files
        .push(format!("recording: {} ({written} messages)", out.display()));
    Ok(c)
}

/// The IMU file of samples (the triad's increments; redundant channels are not carried).
pub fn format_imu(imu: &[ImuSample]) -> String {
    let mut t = String::with_capacity(imu.len() * 120);
    for s in imu {
        let (_, sow) = text::week_and_sow_ns(GpsTime::from_ns(s.header.time_ns));
        let _ = write!(t, "{}", format_seconds_ns(sow));
        for x in s.delta_angle_rad.iter().chain(&s.delta_velocity_m_s) {
            let _ = write!(t, " {}", format_f64(*x));
        }
        t.push('\n');
    }
    t
}

/// The GNSS position file of the valid fixes.
pub fn format_gnss(gnss: &[GnssSample]) -> String {
    let mut t = String::new();
    for s in gnss.iter().filter(|s| s.fix_valid != 0) {
        let (_, sow) = text::week_and_sow_ns(GpsTime::from_ns(s.header.time_ns));
        let (g, sigma) = sigma_ned_m(s);
        let _ = writeln!(
            t,
            "{} {} {} {} {} {} {}",
            format_seconds_ns(sow),
            format_f64(g.lat_rad.to_degrees()),
            format_f64(g.lon_rad.to_degrees()),
            format_f64(g.height_m),
            format_f64(sigma[0]),
            format_f64(sigma[1]),
            format_f64(sigma[2]),
        );
    }
    t
}

fn trajectory_line(t: &mut String, time_ns: i64, g: [f64; 3], v: [f64; 3], rph: [f64; 3]) {
    let (week, sow) = text::week_and_sow_ns(GpsTime::from_ns(time_ns));
    let _ = write!(t, "{week} {}", format_seconds_ns(sow));
    let vals = [g[0].to_degrees(), g[1].to_degrees(), g[2]]
        .into_iter()
        .chain(v)
        .chain(rph.map(f64::to_degrees));
    for x in vals {
        let _ = write!(t, " {}", format_f64(x));
    }
    t.push('\n');
}

/// The reference-trajectory file of truth samples.
pub fn format_truth(truth: &[TruthSample]) -> String {
    let mut t = String::new();
    for s in truth {
        trajectory_line(
            &mut t,
            s.header.time_ns,
            [s.lat_rad, s.lon_rad, s.height_m],
            s.vel_ned_m_s,
            s.roll_pitch_heading_rad,
        );
    }
    t
}

/// The result file of navigation solutions.
pub fn format_nav(nav: &[NavSolution]) -> String {
    let mut t = String::new();
    for s in nav {
        trajectory_line(
            &mut t,
            s.header.time_ns,
            [s.lat_rad, s.lon_rad, s.height_m],
            s.vel_ned_m_s,
            s.roll_pitch_heading_rad,
        );
    }
    t
}

/// Write a recording out as KF-GINS files in `dir` ([`IMU_FILE`], [`GNSS_FILE`], and when the
/// recording has them [`TRUTH_FILE`], [`NAV_FILE`], [`FILTER_FILE`] and KF-GINS's own
/// configuration for these files, [`KFGINS_CONFIG_FILE`]).
pub fn export(recording: &Path, dir: &Path) -> Result<Counts, InterchangeError> {
    let (s, filter) = super::read_streams(recording)?;
    std::fs::create_dir_all(dir).map_err(InterchangeError::io(dir))?;
    let mut c = s.counts();
    c.gnss = s.gnss.iter().filter(|g| g.fix_valid != 0).count();
    // KF-GINS starts where Sextant's navigation started, else at the truth's first pose within
    // the IMU file (KF-GINS refuses a start before its first IMU epoch).
    let kfgins = filter
        .as_deref()
        .and_then(|text| crate::config::parse_navigator_config(text, recording).ok())
        .and_then(|cfg| {
            let first_imu_ns = s.imu.first()?.header.time_ns;
            let start = s.nav.first().copied().or_else(|| {
                s.truth
                    .iter()
                    .find(|t| t.header.time_ns >= first_imu_ns)
                    .map(|t| start_from_truth(t, &cfg))
            })?;
            Some(config_text(&cfg, imu_rate_hz(&s.imu)?, &start))
        });
    let files = [
        (
            KFGINS_CONFIG_FILE,
            kfgins.is_some(),
            kfgins.unwrap_or_default(),
        ),
        (IMU_FILE, !s.imu.is_empty(), format_imu(&s.imu)),
        (GNSS_FILE, !s.gnss.is_empty(), format_gnss(&s.gnss)),
        (TRUTH_FILE, !s.truth.is_empty(), format_truth(&s.truth)),
        (NAV_FILE, !s.nav.is_empty(), format_nav(&s.nav)),
        (FILTER_FILE, filter.is_some(), filter.unwrap_or_default()),
    ];
    for (name, wanted, body) in files {
        if wanted {
            let p = dir.join(name);
            std::fs::write(&p, body).map_err(InterchangeError::io(&p))?;
            c.files.push(p.display().to_string());
        }
    }
    if let Some(t) = c.first_time_ns {
        c.files.push(format!(
            "GPS week of the first epoch: {} (import with --week)",
            text::week_and_sow_ns(GpsTime::from_ns(t)).0
        ));
    }
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const P: &str = "f.txt";

    #[test]
    fn imu_rows_become_increments_with_intervals_from_the_times() {
        let text =
            "# comment\n456300.000 1e-5 2e-5 3e-5 0.01 0.02 -0.049\n\n456300.005,1,2,3,4,5,6\n";
        let imu = read_imu(Path::new(P), text, WeekTracker::with_week(2200)).unwrap();
        assert_eq!(imu.len(), 2);
        assert_eq!(
            imu[0].header.time_ns,
            (2200 * 604_800 + 456_300) * 1_000_000_000
        );
        assert_eq!(imu[0].dt_s, 0.005);
        assert_eq!(imu[1].dt_s, 0.005);
        assert_eq!(imu[0].delta_velocity_m_s, [0.01, 0.02, -0.049]);
    }

    #[test]
    fn errors_name_file_line_and_column() {
        let e = read_imu(
            Path::new(P),
            "1.0 0 0 0 0 0 0\n2.0 0 0 x 0 0 0\n",
            WeekTracker::with_week(1),
        )
        .unwrap_err();
        assert_eq!((e.line, e.column), (2, 4), "{e}");
        assert_eq!(
            e.to_string(),
            "f.txt: line 2, column 4: \"x\" is not a number"
        );
        let e = read_gnss(
            Path::new(P),
            "1 30 114 20 0.1 0.1\n",
            WeekTracker::with_week(1),
        )
        .unwrap_err();
        assert_eq!((e.line, e.column), (1, 7), "{e}");
        let e = read_gnss(
            Path::new(P),
            "2 30 114 20 0.1 0.1 0.2\n1 30 114 20 0.1 0.1 0.2\n",
            WeekTracker::with_week(1),
        )
        .unwrap_err();
        assert_eq!((e.line, e.column), (2, 1), "{e}");
    }

    /// A fix written and read back: the same position to the precision of the degree
    /// conversion (≈ 1e-16 relative of the latitude, i.e. well under a micrometre on the
    /// Earth's radius) and the same NED standard deviations.
    #[test]
    fn gnss_fix_round_trips_through_the_text() {
        let g = Geodetic {
            lat_rad: 30.4447858054f64.to_radians(),
            lon_rad: 114.4718661162f64.to_radians(),
            height_m: 21.095,
        };
        let t = GpsTime::from_ns(2200 * text::NS_PER_WEEK + 456_250_000_000_000);
        let fix = gnss_fix(t, &g, [0.010, 0.009, 0.019]);
        let back = read_gnss(
            Path::new(P),
            &format_gnss(&[fix]),
            WeekTracker::with_week(2200),
        )
        .unwrap();
        assert_eq!(back[0].header.time_ns, t.ns);
        let d = Vector3::from(back[0].pos_ecef_m) - Vector3::from(fix.pos_ecef_m);
        assert!(d.norm() < 1e-6, "{d}");
        let (_, s) = sigma_ned_m(&back[0]);
        for (a, b) in s.iter().zip([0.010, 0.009, 0.019]) {
            assert!((a - b).abs() < 1e-12 * b, "{a} vs {b}");
        }
    }

    proptest! {
        #[test]
        fn arbitrary_text_never_panics(s in "\\PC{0,200}") {
            let w = WeekTracker::with_week(2000);
            let _ = read_imu(Path::new(P), &s, w);
            let _ = read_gnss(Path::new(P), &s, w);
            let _ = read_trajectory(Path::new(P), &s);
        }

        /// Mutated valid rows: an error, if any, names a line of the text and a column at
        /// most one past its fields.
        #[test]
        fn mutated_rows_give_located_errors(
            cut in 0usize..60,
            junk in "[0-9a-z ,.\\-eE\\t]{0,6}",
        ) {
            let valid = "2200 456300.000 30.44 114.47 20.9 0.1 -0.2 0.0 0.85 -2.03 185.7\n2200 456300.005 30.44 114.47 20.9 0.1 -0.2 0.0 0.85 -2.03 185.7\n";
            let cut = cut.min(valid.len());
            let text = format!("{}{}{}", &valid[..cut], junk, &valid[cut..]);
            if let Err(e) = read_trajectory(Path::new(P), &text) {
                let line = text.lines().nth(e.line as usize - 1);
                prop_assert!(line.is_some(), "{e}");
                let n = line.unwrap().split([' ', '\t', ',']).filter(|f| !f.is_empty()).count();
                prop_assert!(e.column <= n + 1, "{e}");
            }
        }
    }
}
