//! CSV logs of any column layout, described by a small TOML file: which file holds which
//! sensor, which named columns hold which quantity, in which units and axes, and what the time
//! column counts. Every CSV file has a header row naming its columns; `#` starts a comment
//! line; fields may be quoted (RFC 4180, crate `csv`).
//!
//! ```toml
//! [time]
//! column = "time"              # the time column of every file (default "time")
//! base = "gps-week-seconds"    # or "gps-seconds" (since 1980-01-06), "unix-seconds" (UTC)
//! week = 2200                  # GPS week of the first row, for gps-week-seconds
//!
//! [imu]
//! file = "imu.csv"             # relative to the description
//! kind = "increments"          # Δθ [angle], Δv [m/s]; or "rates": ω [angle/s], f [m/s²] × interval
//! frame = "frd"                # column axes: frd (x forward, y right, z down = Sextant's body
//!                              # frame) or flu (x forward, y left, z up)
//! angle_unit = "rad"           # or "deg"
//! gyro = ["dtheta_x", "dtheta_y", "dtheta_z"]
//! accel = ["dvel_x", "dvel_y", "dvel_z"]
//! dt = "dt"                    # optional interval column [s]; else from consecutive times
//!
//! [gnss]
//! file = "gnss.csv"
//! position = "geodetic"        # lat, lon [angle_unit], ellipsoidal height [m]; or "ecef" [m]
//! angle_unit = "deg"
//! columns = ["lat", "lon", "height"]
//! sigma_ned = ["sn", "se", "sd"]                       # 1-σ [m], or instead:
//! # cov_ecef = ["cxx", "cxy", "cxz", "cyy", "cyz", "czz"]  # [m²] (or all nine, row-major)
//! # velocity_ecef = ["vx", "vy", "vz"]                   # optional [m/s], with
//! # vel_cov_ecef = ["vcxx", "vcxy", "vcxz", "vcyy", "vcyz", "vczz"]  # [m²/s²]
//! # valid = "fix_valid"        # optional: rows with 0 are invalid fixes
//! # pdop = "pdop"              # optional
//!
//! [odometer]                   # optional: forward speed [m/s]; dt, distance optional
//! file = "odometer.csv"
//! speed = "speed"
//!
//! [baro]                       # optional: static pressure [Pa], temperature [°C] optional
//! file = "baro.csv"
//! pressure = "pressure"
//!
//! [truth]                      # optional reference trajectory: geodetic position, NED
//! file = "truth.csv"           # velocity [m/s], roll, pitch, heading [angle_unit]
//! angle_unit = "deg"
//! position = ["lat", "lon", "height"]
//! velocity_ned = ["vn", "ve", "vd"]
//! attitude = ["roll", "pitch", "heading"]
//! ```
//!
//! `sextant export csv` writes such a description with the files: GPS seconds with nine
//! decimals, ECEF positions and full covariances, and every number as the shortest text that
//! reads back to the same bits, so that a recording's inputs (IMU triad, GNSS fix, odometer,
//! baro) come back bit for bit and `replay --offline` gives the same solution.

use super::kfgins::{check_increasing, gnss_fix_ecef, imu_samples, truth_sample};
use super::text::{self, TextError, WeekTracker, format_f64, format_seconds_ns};
use super::{Counts, InterchangeError, Streams};
use fusion::earth::{self, Geodetic, WGS84};
use fusion::time::GpsTime;
use msgs::{BaroSample, GnssSample, Header, OdometerSample};
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// What the time column counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TimeBase {
    /// GPS seconds of week; the week of the first row is `time.week`.
    GpsWeekSeconds,
    /// GPS seconds since the GPS epoch 1980-01-06T00:00:00.
    GpsSeconds,
    /// POSIX seconds (UTC since 1970-01-01, leap seconds not counted).
    UnixSeconds,
}

/// The time section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeSpec {
    /// Name of the time column in every file.
    #[serde(default = "default_time_column")]
    pub column: String,
    /// What it counts.
    pub base: TimeBase,
    /// GPS week of the first row (`gps-week-seconds` only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub week: Option<i64>,
}

fn default_time_column() -> String {
    "time".into()
}

/// Angle unit of angle columns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum AngleUnit {
    /// Radians.
    #[default]
    Rad,
    /// Degrees.
    Deg,
}

impl AngleUnit {
    fn to_rad(self, x: f64) -> f64 {
        match self {
            Self::Rad => x,
            Self::Deg => x.to_radians(),
        }
    }
}

/// Axes of the IMU columns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ImuFrame {
    /// x forward, y right, z down (Sextant's body frame).
    #[default]
    Frd,
    /// x forward, y left, z up (a rotation of π about x from front-right-down).
    Flu,
}

/// What the IMU columns hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ImuKind {
    /// Δθ and Δv over the interval ending at the row's time.
    #[default]
    Increments,
    /// Mean angular rate and specific force over that interval.
    Rates,
}

/// The IMU section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImuSpec {
    /// CSV file, relative to the description.
    pub file: PathBuf,
    /// Increments or rates.
    #[serde(default)]
    pub kind: ImuKind,
    /// Axes of the columns.
    #[serde(default)]
    pub frame: ImuFrame,
    /// Unit of the gyro columns' angles.
    #[serde(default)]
    pub angle_unit: AngleUnit,
    /// Gyro columns x, y, z.
    pub gyro: [String; 3],
    /// Accelerometer columns x, y, z.
    pub accel: [String; 3],
    /// Interval column, s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dt: Option<String>,
}

/// How a GNSS position is given.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PositionKind {
    /// Latitude, longitude (`angle_unit`), ellipsoidal height (m), WGS-84.
    Geodetic,
    /// ECEF x, y, z (m).
    Ecef,
}

/// The GNSS section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GnssSpec {
    /// CSV file.
    pub file: PathBuf,
    /// Geodetic or ECEF.
    pub position: PositionKind,
    /// Unit of latitude and longitude.
    #[serde(default)]
    pub angle_unit: AngleUnit,
    /// The three position columns.
    pub columns: [String; 3],
    /// 1-σ north, east, down columns, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_ned: Option<[String; 3]>,
    /// ECEF covariance columns, m²: the upper triangle xx, xy, xz, yy, yz, zz, or all nine
    /// row by row.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cov_ecef: Option<Vec<String>>,
    /// ECEF velocity columns, m/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity_ecef: Option<[String; 3]>,
    /// ECEF velocity covariance columns, m²/s² (6 or 9, as `cov_ecef`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vel_cov_ecef: Option<Vec<String>>,
    /// Fix-valid column (0 = invalid).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub valid: Option<String>,
    /// PDOP column.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pdop: Option<String>,
}

/// The odometer section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OdometerSpec {
    /// CSV file.
    pub file: PathBuf,
    /// Forward speed column, m/s.
    pub speed: String,
    /// Interval column, s (else from consecutive times).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dt: Option<String>,
    /// Distance column, m (else speed × interval).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distance: Option<String>,
}

/// The barometer section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BaroSpec {
    /// CSV file.
    pub file: PathBuf,
    /// Static pressure column, Pa.
    pub pressure: String,
    /// Temperature column, °C (else 15 °C, the standard atmosphere's sea-level value).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub temperature: Option<String>,
}

/// The reference-trajectory section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TruthSpec {
    /// CSV file.
    pub file: PathBuf,
    /// Unit of latitude, longitude and attitude angles.
    #[serde(default)]
    pub angle_unit: AngleUnit,
    /// Latitude, longitude, ellipsoidal height columns.
    pub position: [String; 3],
    /// NED velocity columns, m/s.
    pub velocity_ned: [String; 3],
    /// Roll, pitch, heading columns (z-y-x).
    pub attitude: [String; 3],
}

/// A CSV log description.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Description {
    /// Time column and base.
    pub time: TimeSpec,
    /// IMU file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub imu: Option<ImuSpec>,
    /// GNSS file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gnss: Option<GnssSpec>,
    /// Odometer file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub odometer: Option<OdometerSpec>,
    /// Barometer file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub baro: Option<BaroSpec>,
    /// Reference trajectory file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub truth: Option<TruthSpec>,
}

/// A CSV file read: its path, its column names and its data rows (line number, fields).
#[derive(Debug)]
pub struct Table {
    path: PathBuf,
    names: Vec<String>,
    rows: Vec<(u64, Vec<String>)>,
}

impl Table {
    /// Parse CSV text (header row first) of `path`.
    pub fn parse(path: &Path, text: &str) -> Result<Self, TextError> {
        let mut r = csv::ReaderBuilder::new()
            .comment(Some(b'#'))
            .trim(csv::Trim::All)
            .from_reader(text.as_bytes());
        let located = |e: csv::Error| {
            let line = e.position().map_or(0, |p| p.line());
            let column = match e.kind() {
                csv::ErrorKind::UnequalLengths { len, .. } => *len as usize + 1,
                _ => 0,
            };
            TextError::new(path, line, column, e.to_string())
        };
        let names = r
            .headers()
            .map_err(located)?
            .iter()
            .map(str::to_string)
            .collect();
        let mut rows = Vec::new();
        for rec in r.records() {
            let rec = rec.map_err(located)?;
            let line = rec.position().map_or(0, |p| p.line());
            rows.push((line, rec.iter().map(str::to_string).collect()));
        }
        Ok(Self {
            path: path.to_path_buf(),
            names,
            rows,
        })
    }

    /// The index of column `name`, or the error naming the file and the columns it has.
    pub fn column(&self, name: &str) -> Result<usize, InterchangeError> {
        self.names
            .iter()
            .position(|n| n == name)
            .ok_or_else(|| InterchangeError::Description {
                path: self.path.clone(),
                message: format!("no column {name:?} (columns: {})", self.names.join(", ")),
            })
    }

    fn columns<const N: usize>(&self, names: &[String; N]) -> Result<[usize; N], InterchangeError> {
        let mut out = [0; N];
        for (o, n) in out.iter_mut().zip(names) {
            *o = self.column(n)?;
        }
        Ok(out)
    }

    fn value(&self, line: u64, fields: &[String], col: usize) -> Result<f64, TextError> {
        text::number(&self.path, line, col + 1, &fields[col])
    }

    fn values<const N: usize>(
        &self,
        line: u64,
        fields: &[String],
        cols: &[usize; N],
    ) -> Result<[f64; N], TextError> {
        let mut out = [0.0; N];
        for (o, c) in out.iter_mut().zip(cols) {
            *o = self.value(line, fields, *c)?;
        }
        Ok(out)
    }
}

/// Reads the time column in the description's base.
struct Clock {
    base: TimeBase,
    weeks: Option<WeekTracker>,
}

impl Clock {
    fn new(spec: &TimeSpec, path: &Path) -> Result<Self, InterchangeError> {
        let weeks = match (spec.base, spec.week) {
            (TimeBase::GpsWeekSeconds, Some(w)) => Some(WeekTracker::with_week(w)),
            (TimeBase::GpsWeekSeconds, None) => {
                return Err(InterchangeError::NoWeek {
                    path: path.to_path_buf(),
                });
            }
            _ => None,
        };
        Ok(Self {
            base: spec.base,
            weeks,
        })
    }

    fn time(
        &mut self,
        path: &Path,
        line: u64,
        col: usize,
        tok: &str,
    ) -> Result<GpsTime, TextError> {
        let bad =
            |what: &str| TextError::new(path, line, col + 1, format!("{tok:?} is not {what}"));
        let ns = text::parse_seconds_ns(tok);
        Ok(match (self.base, ns, self.weeks.as_mut()) {
            (TimeBase::GpsWeekSeconds, Some(ns), Some(w)) if ns < text::NS_PER_WEEK => w.time(ns),
            (TimeBase::GpsWeekSeconds, _, _) => return Err(bad("a time of week in [0, 604800) s")),
            (TimeBase::GpsSeconds, Some(ns), _) => GpsTime::from_ns(ns),
            (TimeBase::UnixSeconds, Some(ns), _) => text::gps_from_unix_ns(ns),
            _ => return Err(bad("a time in seconds")),
        })
    }
}

/// A data row with its time: (line, fields, time of validity).
type TimedRow<'a> = (u64, &'a [String], GpsTime);

/// Row iteration with the time read and checked increasing.
fn timed_rows<'a>(
    table: &'a Table,
    spec: &TimeSpec,
) -> Result<Vec<TimedRow<'a>>, InterchangeError> {
    let tcol = table.column(&spec.column)?;
    let mut clock = Clock::new(spec, &table.path)?;
    let mut out: Vec<TimedRow> = Vec::with_capacity(table.rows.len());
    for (line, f) in &table.rows {
        let t = clock.time(&table.path, *line, tcol, &f[tcol])?;
        check_increasing(&table.path, *line, out.last().map(|r| r.2.ns), t.ns)?;
        out.push((*line, f.as_slice(), t));
    }
    Ok(out)
}

/// Column indices of a covariance given as its upper triangle (6) or all nine, row-major.
fn cov_columns(t: &Table, names: &[String]) -> Result<Vec<usize>, InterchangeError> {
    if names.len() != 6 && names.len() != 9 {
        return Err(InterchangeError::Description {
            path: t.path.clone(),
            message: format!("a covariance needs 6 or 9 columns, not {}", names.len()),
        });
    }
    names.iter().map(|n| t.column(n)).collect()
}

/// A row-major 3×3 covariance from the values of [`cov_columns`].
fn cov_row_major(
    t: &Table,
    line: u64,
    f: &[String],
    cols: &[usize],
) -> Result<[f64; 9], TextError> {
    let mut v = Vec::with_capacity(9);
    for c in cols {
        v.push(t.value(line, f, *c)?);
    }
    Ok(match v.len() {
        9 => std::array::from_fn(|k| v[k]),
        _ => [v[0], v[1], v[2], v[1], v[3], v[4], v[2], v[4], v[5]],
    })
}

/// Read the files a description names into streams (`dir`: the description's directory).
pub fn read_described(
    desc: &Description,
    dir: &Path,
    load: &dyn Fn(&Path) -> Result<String, InterchangeError>,
) -> Result<Streams, InterchangeError> {
    let table = |file: &Path| -> Result<Table, InterchangeError> {
        let p = dir.join(file);
        Ok(Table::parse(&p, &load(&p)?)?)
    };
    let mut s = Streams::default();
    if let Some(spec) = &desc.imu {
        let t = table(&spec.file)?;
        let (g, a) = (t.columns(&spec.gyro)?, t.columns(&spec.accel)?);
        let dtc = spec.dt.as_ref().map(|c| t.column(c)).transpose()?;
        let mut rows = Vec::with_capacity(t.rows.len());
        let timed = timed_rows(&t, &desc.time)?;
        for (k, (line, f, time)) in timed.iter().enumerate() {
            let mut w = t.values(*line, f, &g)?.map(|x| spec.angle_unit.to_rad(x));
            let mut v = t.values(*line, f, &a)?;
            if spec.frame == ImuFrame::Flu {
                for x in [&mut w, &mut v] {
                    x[1] = -x[1];
                    x[2] = -x[2];
                }
            }
            let dt = dtc.map(|c| t.value(*line, f, c)).transpose()?;
            if spec.kind == ImuKind::Rates {
                let dt_s = match dt {
                    Some(d) => d,
                    None if k > 0 => (time.ns - timed[k - 1].2.ns) as f64 / 1e9,
                    None => match timed.get(1) {
                        Some(n) => (n.2.ns - time.ns) as f64 / 1e9,
                        None => 0.0,
                    },
                };
                w = w.map(|x| x * dt_s);
                v = v.map(|x| x * dt_s);
            }
            rows.push((*line, time.ns, w, v, dt));
        }
        s.imu = imu_samples(&t.path, &rows)?;
    }
    if let Some(spec) = &desc.gnss {
        let t = table(&spec.file)?;
        let pos = t.columns(&spec.columns)?;
        let sig = spec.sigma_ned.as_ref().map(|c| t.columns(c)).transpose()?;
        let cov = spec
            .cov_ecef
            .as_ref()
            .map(|c| cov_columns(&t, c))
            .transpose()?;
        let vel = spec
            .velocity_ecef
            .as_ref()
            .map(|c| t.columns(c))
            .transpose()?;
        let vcov = spec
            .vel_cov_ecef
            .as_ref()
            .map(|c| cov_columns(&t, c))
            .transpose()?;
        let valid = spec.valid.as_ref().map(|c| t.column(c)).transpose()?;
        let pdop = spec.pdop.as_ref().map(|c| t.column(c)).transpose()?;
        if sig.is_some() == cov.is_some() {
            return Err(InterchangeError::Description {
                path: t.path.clone(),
                message: "[gnss] needs exactly one of sigma_ned and cov_ecef".into(),
            });
        }
        for (line, f, time) in timed_rows(&t, &desc.time)? {
            if let Some(c) = valid
                && t.value(line, f, c)? == 0.0
            {
                s.gnss.push(GnssSample {
                    header: Header {
                        time_ns: time.ns,
                        ..Default::default()
                    },
                    ..Default::default()
                });
                continue;
            }
            let p = t.values(line, f, &pos)?;
            let r_e = match spec.position {
                PositionKind::Ecef => Vector3::from(p),
                PositionKind::Geodetic => earth::geodetic_to_ecef(
                    &WGS84,
                    &Geodetic {
                        lat_rad: spec.angle_unit.to_rad(p[0]),
                        lon_rad: spec.angle_unit.to_rad(p[1]),
                        height_m: p[2],
                    },
                ),
            };
            let p_e = match (&cov, &sig) {
                (Some(c), _) => Matrix3::from_row_slice(&cov_row_major(&t, line, f, c)?),
                (None, Some(c)) => {
                    let sg = t.values(line, f, c)?;
                    let g = earth::ecef_to_geodetic(&WGS84, &r_e);
                    let c_e_n = earth::c_e_n(g.lat_rad, g.lon_rad);
                    c_e_n
                        * Matrix3::from_diagonal(&Vector3::from(sg).map(|x| x * x))
                        * c_e_n.transpose()
                }
                (None, None) => unreachable!("checked above"),
            };
            let mut g = gnss_fix_ecef(time, &r_e, &p_e);
            if let Some(c) = &vel {
                g.vel_ecef_m_s = t.values(line, f, c)?;
            }
            if let Some(c) = &vcov {
                g.vel_cov_ecef_m2_s2 = cov_row_major(&t, line, f, c)?;
            }
            if let Some(c) = pdop {
                g.pdop = t.value(line, f, c)?;
            }
            s.gnss.push(g);
        }
    }
    if let Some(spec) = &desc.odometer {
        let t = table(&spec.file)?;
        let sc = t.column(&spec.speed)?;
        let dtc = spec.dt.as_ref().map(|c| t.column(c)).transpose()?;
        let dc = spec.distance.as_ref().map(|c| t.column(c)).transpose()?;
        let timed = timed_rows(&t, &desc.time)?;
        for (k, (line, f, time)) in timed.iter().enumerate() {
            let speed = t.value(*line, f, sc)?;
            let dt = match dtc {
                Some(c) => t.value(*line, f, c)?,
                None if k > 0 => (time.ns - timed[k - 1].2.ns) as f64 / 1e9,
                None => timed
                    .get(1)
                    .map_or(0.0, |n| (n.2.ns - time.ns) as f64 / 1e9),
            };
            let distance = match dc {
                Some(c) => t.value(*line, f, c)?,
                None => speed * dt,
            };
            s.odometer.push(OdometerSample {
                header: Header {
                    time_ns: time.ns,
                    ..Default::default()
                },
                dt_s: dt,
                distance_m: distance,
                speed_m_s: speed,
            });
        }
    }
    if let Some(spec) = &desc.baro {
        let t = table(&spec.file)?;
        let pc = t.column(&spec.pressure)?;
        let tc = spec.temperature.as_ref().map(|c| t.column(c)).transpose()?;
        for (line, f, time) in timed_rows(&t, &desc.time)? {
            s.baro.push(BaroSample {
                header: Header {
                    time_ns: time.ns,
                    ..Default::default()
                },
                pressure_pa: t.value(line, f, pc)?,
                temperature_c: tc.map(|c| t.value(line, f, c)).transpose()?.unwrap_or(15.0),
            });
        }
    }
    if let Some(spec) = &desc.truth {
        let t = table(&spec.file)?;
        let (pc, vc, ac) = (
            t.columns(&spec.position)?,
            t.columns(&spec.velocity_ned)?,
            t.columns(&spec.attitude)?,
        );
        for (line, f, time) in timed_rows(&t, &desc.time)? {
            let p = t.values(line, f, &pc)?;
            let g = Geodetic {
                lat_rad: spec.angle_unit.to_rad(p[0]),
                lon_rad: spec.angle_unit.to_rad(p[1]),
                height_m: p[2],
            };
            let rph = t.values(line, f, &ac)?.map(|x| spec.angle_unit.to_rad(x));
            s.truth
                .push(truth_sample(time, &g, t.values(line, f, &vc)?, rph));
        }
    }
    Ok(s)
}

/// Parse a description's TOML text (`path` for messages).
pub fn parse_description(path: &Path, text: &str) -> Result<Description, InterchangeError> {
    toml::from_str(text).map_err(|e| InterchangeError::Description {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

fn load(path: &Path) -> Result<String, InterchangeError> {
    sextant_rinex::read_text(path).map_err(|e| InterchangeError::Io {
        path: path.to_path_buf(),
        source: std::io::Error::other(e.to_string()),
    })
}

/// Import the CSV files of the description at `desc_path` into a recording at `out`.
pub fn import(
    desc_path: &Path,
    config: Option<&Path>,
    out: &Path,
) -> Result<Counts, InterchangeError> {
    let desc = parse_description(desc_path, &load(desc_path)?)?;
    let dir = desc_path.parent().unwrap_or(Path::new("."));
    let streams = read_described(&desc, dir, &load)?;
    let filter = super::filter_config(config)?;
    let meta = BTreeMap::from([
        ("format".to_string(), "csv".to_string()),
        ("description".to_string(), desc_path.display().to_string()),
    ]);
    let written = super::write_recording(out, &streams, &filter, meta)?;
    let mut c = streams.counts();
    c.files
        .push(format!("recording: {} ({written} messages)", out.display()));
    Ok(c)
}

/// The description `sextant export csv` writes.
pub fn export_description(s: &Streams) -> Description {
    let names = |p: &str, axes: &[&str]| axes.iter().map(|a| format!("{p}{a}")).collect::<Vec<_>>();
    let arr3 = |v: Vec<String>| -> [String; 3] { [v[0].clone(), v[1].clone(), v[2].clone()] };
    let nine = ["xx", "xy", "xz", "yx", "yy", "yz", "zx", "zy", "zz"];
    Description {
        time: TimeSpec {
            column: "time".into(),
            base: TimeBase::GpsSeconds,
            week: None,
        },
        imu: (!s.imu.is_empty()).then(|| ImuSpec {
            file: "imu.csv".into(),
            kind: ImuKind::Increments,
            frame: ImuFrame::Frd,
            angle_unit: AngleUnit::Rad,
            gyro: arr3(names("dtheta_", &["x", "y", "z"])),
            accel: arr3(names("dvel_", &["x", "y", "z"])),
            dt: Some("dt".into()),
        }),
        gnss: (!s.gnss.is_empty()).then(|| GnssSpec {
            file: "gnss.csv".into(),
            position: PositionKind::Ecef,
            angle_unit: AngleUnit::Rad,
            columns: arr3(names("", &["x", "y", "z"])),
            sigma_ned: None,
            cov_ecef: Some(names("c", &nine)),
            velocity_ecef: Some(arr3(names("v", &["x", "y", "z"]))),
            vel_cov_ecef: Some(names("vc", &nine)),
            valid: Some("fix_valid".into()),
            pdop: Some("pdop".into()),
        }),
        odometer: (!s.odometer.is_empty()).then(|| OdometerSpec {
            file: "odometer.csv".into(),
            speed: "speed".into(),
            dt: Some("dt".into()),
            distance: Some("distance".into()),
        }),
        baro: (!s.baro.is_empty()).then(|| BaroSpec {
            file: "baro.csv".into(),
            pressure: "pressure".into(),
            temperature: Some("temperature".into()),
        }),
        truth: (!s.truth.is_empty()).then(|| TruthSpec {
            file: "truth.csv".into(),
            angle_unit: AngleUnit::Rad,
            position: arr3(vec!["lat".into(), "lon".into(), "height".into()]),
            velocity_ned: arr3(names("v", &["n", "e", "d"])),
            attitude: arr3(vec!["roll".into(), "pitch".into(), "heading".into()]),
        }),
    }
}

fn csv_text(header: &[&str], rows: impl Iterator<Item = (i64, Vec<f64>)>) -> String {
    let mut t = header.join(",");
    t.push('\n');
    for (time, vals) in rows {
        t.push_str(&format_seconds_ns(time));
        for v in vals {
            t.push(',');
            t.push_str(&format_f64(v));
        }
        t.push('\n');
    }
    t
}

/// The CSV files of `s` as [`export_description`] describes them: (file name, text).
pub fn export_files(s: &Streams) -> Vec<(&'static str, String)> {
    let mut out = Vec::new();
    if !s.imu.is_empty() {
        let rows = s.imu.iter().map(|x| {
            let mut v = vec![x.dt_s];
            v.extend(x.delta_angle_rad);
            v.extend(x.delta_velocity_m_s);
            (x.header.time_ns, v)
        });
        out.push((
            "imu.csv",
            csv_text(
                &[
                    "time", "dt", "dtheta_x", "dtheta_y", "dtheta_z", "dvel_x", "dvel_y", "dvel_z",
                ],
                rows,
            ),
        ));
    }
    if !s.gnss.is_empty() {
        let rows = s.gnss.iter().map(|g| {
            let mut v = vec![g.fix_valid as f64];
            v.extend(g.pos_ecef_m);
            v.extend(g.pos_cov_ecef_m2);
            v.extend(g.vel_ecef_m_s);
            v.extend(g.vel_cov_ecef_m2_s2);
            v.push(g.pdop);
            (g.header.time_ns, v)
        });
        let h = [
            "time",
            "fix_valid",
            "x",
            "y",
            "z",
            "cxx",
            "cxy",
            "cxz",
            "cyx",
            "cyy",
            "cyz",
            "czx",
            "czy",
            "czz",
            "vx",
            "vy",
            "vz",
            "vcxx",
            "vcxy",
            "vcxz",
            "vcyx",
            "vcyy",
            "vcyz",
            "vczx",
            "vczy",
            "vczz",
            "pdop",
        ];
        out.push(("gnss.csv", csv_text(&h, rows)));
    }
    if !s.odometer.is_empty() {
        let rows = s
            .odometer
            .iter()
            .map(|o| (o.header.time_ns, vec![o.dt_s, o.distance_m, o.speed_m_s]));
        out.push((
            "odometer.csv",
            csv_text(&["time", "dt", "distance", "speed"], rows),
        ));
    }
    if !s.baro.is_empty() {
        let rows = s
            .baro
            .iter()
            .map(|b| (b.header.time_ns, vec![b.pressure_pa, b.temperature_c]));
        out.push((
            "baro.csv",
            csv_text(&["time", "pressure", "temperature"], rows),
        ));
    }
    if !s.truth.is_empty() {
        out.push((
            "truth.csv",
            trajectory_csv(s.truth.iter().map(|x| {
                (
                    x.header.time_ns,
                    [x.lat_rad, x.lon_rad, x.height_m],
                    x.vel_ned_m_s,
                    x.roll_pitch_heading_rad,
                )
            })),
        ));
    }
    if !s.nav.is_empty() {
        out.push((
            "nav.csv",
            trajectory_csv(s.nav.iter().map(|x| {
                (
                    x.header.time_ns,
                    [x.lat_rad, x.lon_rad, x.height_m],
                    x.vel_ned_m_s,
                    x.roll_pitch_heading_rad,
                )
            })),
        ));
    }
    out
}

type TrajectoryRow = (i64, [f64; 3], [f64; 3], [f64; 3]);

fn trajectory_csv(rows: impl Iterator<Item = TrajectoryRow>) -> String {
    csv_text(
        &[
            "time", "lat", "lon", "height", "vn", "ve", "vd", "roll", "pitch", "heading",
        ],
        rows.map(|(t, p, v, a)| (t, p.into_iter().chain(v).chain(a).collect())),
    )
}

/// Write a recording out as described CSV in `dir`: `description.toml`, the CSV files, the
/// solutions as `nav.csv` (trajectory columns, not read back) and `filter.toml`.
pub fn export(recording: &Path, dir: &Path) -> Result<Counts, InterchangeError> {
    let (s, filter) = super::read_streams(recording)?;
    std::fs::create_dir_all(dir).map_err(InterchangeError::io(dir))?;
    let desc = toml::to_string(&export_description(&s))
        .map_err(|e| InterchangeError::Config(e.to_string()))?;
    let mut files = export_files(&s);
    files.push(("description.toml", desc));
    if let Some(f) = filter {
        files.push(("filter.toml", f));
    }
    let mut c = s.counts();
    for (name, body) in files {
        let p = dir.join(name);
        std::fs::write(&p, body).map_err(InterchangeError::io(&p))?;
        c.files.push(p.display().to_string());
    }
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn memory(
        files: Vec<(&'static str, String)>,
    ) -> impl Fn(&Path) -> Result<String, InterchangeError> {
        move |p: &Path| {
            files
                .iter()
                .find(|(n, _)| Path::new(n) == p)
                .map(|(_, t)| t.clone())
                .ok_or_else(|| InterchangeError::Io {
                    path: p.to_path_buf(),
                    source: std::io::ErrorKind::NotFound.into(),
                })
        }
    }

    const DESC: &str = r#"
[time]
base = "gps-week-seconds"
week = 2200
[imu]
file = "imu.csv"
kind = "rates"
frame = "flu"
angle_unit = "deg"
gyro = ["wx", "wy", "wz"]
accel = ["ax", "ay", "az"]
[gnss]
file = "gnss.csv"
position = "geodetic"
angle_unit = "deg"
columns = ["lat", "lon", "h"]
sigma_ned = ["sn", "se", "sd"]
"#;

    #[test]
    fn rates_in_flu_degrees_become_frd_increments() {
        let d = parse_description(Path::new("d.toml"), DESC).unwrap();
        let load = memory(vec![
            (
                "imu.csv",
                "time,wx,wy,wz,ax,ay,az\n10.0,1,2,3,0,0,9.8\n10.01,1,2,3,0,0,9.8\n".into(),
            ),
            (
                "gnss.csv",
                "time,lat,lon,h,sn,se,sd\n10,52.5,13.4,40,1,1,2\n".into(),
            ),
        ]);
        let s = read_described(&d, Path::new(""), &load).unwrap();
        let w = s.imu[1].delta_angle_rad;
        let dt = 0.01;
        assert!((s.imu[1].dt_s - dt).abs() < 1e-15);
        assert!((w[0] - 1f64.to_radians() * dt).abs() < 1e-15);
        assert!((w[1] + 2f64.to_radians() * dt).abs() < 1e-15);
        assert!((s.imu[1].delta_velocity_m_s[2] + 9.8 * dt).abs() < 1e-15);
        assert_eq!(s.gnss.len(), 1);
        let (_, sig) = super::super::kfgins::sigma_ned_m(&s.gnss[0]);
        assert!((sig[2] - 2.0).abs() < 1e-12);
    }

    #[test]
    fn missing_columns_and_bad_values_are_named() {
        let d = parse_description(Path::new("d.toml"), DESC).unwrap();
        let load = memory(vec![
            ("imu.csv", "time,wx,wy,wz,ax,ay\n".into()),
            ("gnss.csv", "time,lat,lon,h,sn,se,sd\n".into()),
        ]);
        let e = read_described(&d, Path::new(""), &load)
            .unwrap_err()
            .to_string();
        assert!(e.contains("imu.csv") && e.contains("\"az\""), "{e}");
        let load = memory(vec![
            (
                "imu.csv",
                "time,wx,wy,wz,ax,ay,az\n1,0,0,0,0,0,0\n2,0,0,0,0,zz,0\n".into(),
            ),
            ("gnss.csv", "time,lat,lon,h,sn,se,sd\n".into()),
        ]);
        let e = read_described(&d, Path::new(""), &load)
            .unwrap_err()
            .to_string();
        assert_eq!(e, "imu.csv: line 3, column 6: \"zz\" is not a number");
        let e = parse_description(Path::new("d.toml"), "[time]\nbase = \"tai\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("d.toml: "), "{e}");
    }

    proptest! {
        #[test]
        fn arbitrary_csv_never_panics(s in "\\PC{0,200}") {
            let d = parse_description(Path::new("d.toml"), DESC).unwrap();
            let text = format!("time,wx,wy,wz,ax,ay,az\n{s}");
            let load = memory(vec![("imu.csv", text), ("gnss.csv", s.clone())]);
            let _ = read_described(&d, Path::new(""), &load);
        }

        #[test]
        fn arbitrary_description_never_panics(s in "\\PC{0,200}") {
            let _ = parse_description(Path::new("d.toml"), &s);
        }
    }
}
