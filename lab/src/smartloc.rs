//! The smartLoc dataset's text format (TU Chemnitz; Reisdorf et al., "The Problem of
//! Comparable GNSS Results – An Approach for a Uniform Dataset with Low-Cost and Reference
//! Data", 2016): one measurement per line, a type tag first.
//!
//! * `pseudorange3 t ρ var x y z id system elevation cn0` — pseudorange (m, atmosphere and
//!   satellite clock already removed), its variance (m²), the satellite's ECEF position (m),
//!   its number, its system (1 GPS, 2 SBAS, 4 GLONASS, 8 Galileo, 16 QZSS, 32 BeiDou),
//!   elevation (°) and C/N0 (dB-Hz);
//! * `odom3 t vx vy vz wx wy wz var_vx var_vy var_vz var_wx var_wy var_wz` — vehicle speed
//!   (m/s) and turn rate (rad/s) in the vehicle axes, with variances;
//! * `point3 t x y z c11 … c33` — reference position, ECEF (m), with a 3×3 covariance.
//!
//! Times are seconds from the start of the drive, written from single-precision floats
//! (`0.29999995231628` for 0.3 s): they are rounded to the millisecond the data are sampled on.
//!
//! Besides the parser, the construction of Sextant's samples from the data, shared by
//! `sextant import smartloc` and `sextant experiment hybrid-berlin` (so that the live and the
//! offline run fuse the same samples): [`drive_samples`] (GPS pseudoranges as the tight
//! coupling's per-satellite observations, each epoch's least-squares fix for the loose one, the
//! start fix of the alignment in motion, the odometer), on the time base of a scenario whose
//! `reference` trajectory is [`reference_spline`] (t = 0 at the reference's first point).

use drivers_sim::reference_trajectory::{
    ReferenceError, ReferencePoint, ReferenceSettings, ReferenceTrajectory,
};
use drivers_sim::scenario::{Scenario, Trajectory};
use drivers_sim::truth::TruthGenerator;
use fusion::earth::WGS84;
use fusion::gnss_ls::{self, FLAG_PSEUDORANGE, LsSettings, Observations};
use msgs::{GnssSample, GnssSatellite, Header, MAX_SATELLITES, OdometerSample};
use nalgebra::Vector3;
use std::path::Path;
use std::sync::Arc;

/// smartLoc system code of GPS.
pub const SYSTEM_GPS: u32 = 1;
/// Speed of light, m/s.
const C_M_S: f64 = 299_792_458.0;

/// One satellite's pseudorange of an epoch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pseudorange {
    /// Pseudorange, m (atmosphere and satellite clock removed).
    pub pseudorange_m: f64,
    /// Its variance, m².
    pub variance_m2: f64,
    /// Satellite position, ECEF, m.
    pub sat_pos_ecef_m: [f64; 3],
    /// Satellite number within its system.
    pub id: u32,
    /// System code (1 GPS, 2 SBAS, 4 GLONASS, 8 Galileo, 16 QZSS, 32 BeiDou).
    pub system: u32,
    /// Elevation, degrees.
    pub elevation_deg: f64,
    /// Carrier-to-noise density, dB-Hz.
    pub cn0_dbhz: f64,
}

/// The pseudoranges of one epoch.
#[derive(Debug, Clone, PartialEq)]
pub struct Epoch {
    /// Time from the start of the drive, ms.
    pub t_ms: i64,
    /// Its pseudoranges in file order.
    pub pseudoranges: Vec<Pseudorange>,
}

/// One odometry sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Odometry {
    /// Time from the start of the drive, ms.
    pub t_ms: i64,
    /// Forward speed, m/s.
    pub speed_m_s: f64,
    /// Variance of the forward speed, (m/s)².
    pub speed_variance_m2_s2: f64,
    /// Turn rate about the vertical axis, rad/s.
    pub yaw_rate_rad_s: f64,
}

/// One reference position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferencePosition {
    /// Time from the start of the drive, ms.
    pub t_ms: i64,
    /// Position, ECEF, m.
    pub r_e_m: [f64; 3],
}

/// The content of a smartLoc input file (pseudoranges and odometry) or ground-truth file.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SmartLoc {
    /// Pseudorange epochs in time order (lines of equal time grouped).
    pub epochs: Vec<Epoch>,
    /// Odometry in time order.
    pub odometry: Vec<Odometry>,
    /// Reference positions in time order.
    pub reference: Vec<ReferencePosition>,
}

/// Why a smartLoc file could not be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("line {line}: {reason}")]
pub struct SmartLocError {
    /// 1-based line number.
    pub line: usize,
    /// What is wrong.
    pub reason: String,
}

/// Parse smartLoc text (input or ground-truth file, or both concatenated). Lines of other
/// types and blank lines are skipped; each type's times must not decrease.
pub fn parse(text: &str) -> Result<SmartLoc, SmartLocError> {
    let mut out = SmartLoc::default();
    for (i, line) in text.lines().enumerate() {
        let err = |reason: String| SmartLocError {
            line: i + 1,
            reason,
        };
        let mut words = line.split_whitespace();
        let Some(tag) = words.next() else {
            continue;
        };
        let need = match tag {
            "pseudorange3" => 10,
            "odom3" => 13,
            "point3" => 4,
            _ => continue,
        };
        let mut v = Vec::with_capacity(need);
        for w in words.take(need) {
            let x: f64 = w
                .parse()
                .map_err(|_| err(format!("{tag}: `{w}` is not a number")))?;
            if !x.is_finite() {
                return Err(err(format!("{tag}: `{w}` is not finite")));
            }
            v.push(x);
        }
        if v.len() < need {
            return Err(err(format!(
                "{tag}: {} numbers, expected at least {need}",
                v.len()
            )));
        }
        if !(0.0..1e7).contains(&v[0]) {
            return Err(err(format!("{tag}: time {} s out of range", v[0])));
        }
        let t_ms = (v[0] * 1e3).round() as i64;
        let decreasing = |last: Option<i64>| {
            if last.is_some_and(|l| t_ms < l) {
                Err(err(format!("{tag}: time {} s goes backwards", v[0])))
            } else {
                Ok(())
            }
        };
        match tag {
            "pseudorange3" => {
                decreasing(out.epochs.last().map(|e| e.t_ms))?;
                if v[2] <= 0.0 {
                    return Err(err(format!(
                        "pseudorange3: variance {} is not positive",
                        v[2]
                    )));
                }
                let small = |x: f64, what: &str| {
                    if (0.0..4_294_967_296.0).contains(&x) && x.fract() == 0.0 {
                        Ok(x as u32)
                    } else {
                        Err(err(format!(
                            "pseudorange3: {what} {x} is not a whole number"
                        )))
                    }
                };
                let p = Pseudorange {
                    pseudorange_m: v[1],
                    variance_m2: v[2],
                    sat_pos_ecef_m: [v[3], v[4], v[5]],
                    id: small(v[6], "satellite id")?,
                    system: small(v[7], "system")?,
                    elevation_deg: v[8],
                    cn0_dbhz: v[9],
                };
                match out.epochs.last_mut() {
                    Some(e) if e.t_ms == t_ms => e.pseudoranges.push(p),
                    _ => out.epochs.push(Epoch {
                        t_ms,
                        pseudoranges: vec![p],
                    }),
                }
            }
            "odom3" => {
                decreasing(out.odometry.last().map(|o| o.t_ms))?;
                out.odometry.push(Odometry {
                    t_ms,
                    speed_m_s: v[1],
                    speed_variance_m2_s2: v[7],
                    yaw_rate_rad_s: v[6],
                });
            }
            _ => {
                decreasing(out.reference.last().map(|o| o.t_ms))?;
                out.reference.push(ReferencePosition {
                    t_ms,
                    r_e_m: [v[1], v[2], v[3]],
                });
            }
        }
    }
    Ok(out)
}

impl SmartLoc {
    /// Count times from the reference's first point (the `reference` trajectory's t = 0):
    /// earlier pseudoranges and odometry are dropped. Returns that point's time in the file,
    /// ms; None when there is no reference.
    pub fn from_reference_start(&mut self) -> Option<i64> {
        let t0 = self.reference.first()?.t_ms;
        self.epochs.retain(|e| e.t_ms >= t0);
        self.epochs.iter_mut().for_each(|e| e.t_ms -= t0);
        self.odometry.retain(|o| o.t_ms >= t0);
        self.odometry.iter_mut().for_each(|o| o.t_ms -= t0);
        self.reference.iter_mut().for_each(|r| r.t_ms -= t0);
        Some(t0)
    }

    /// Standstill intervals: runs of at least two consecutive zero odometer speeds, s.
    pub fn standstill_s(&self) -> Vec<[f64; 2]> {
        let mut out = Vec::new();
        let mut start: Option<(i64, i64)> = None;
        for o in &self.odometry {
            if o.speed_m_s == 0.0 {
                start = Some(start.map_or((o.t_ms, o.t_ms), |(a, _)| (a, o.t_ms)));
            } else if let Some((a, b)) = start.take()
                && b > a
            {
                out.push([a as f64 * 1e-3, b as f64 * 1e-3]);
            }
        }
        if let Some((a, b)) = start
            && b > a
        {
            out.push([a as f64 * 1e-3, b as f64 * 1e-3]);
        }
        out
    }

    /// The reference positions as the points of a `reference` trajectory.
    pub fn reference_points(&self) -> Vec<ReferencePoint> {
        self.reference
            .iter()
            .map(|r| ReferencePoint {
                t_s: r.t_ms as f64 * 1e-3,
                r_e_m: Vector3::from(r.r_e_m),
            })
            .collect()
    }
}

/// The trajectory the simulated IMU follows: the spline through the reference (times from its
/// first point, [`SmartLoc::from_reference_start`]), standing still where the odometer reads
/// zero ([`SmartLoc::standstill_s`]).
pub fn reference_spline(data: &SmartLoc) -> Result<ReferenceTrajectory, ReferenceError> {
    ReferenceTrajectory::new(
        &data.reference_points(),
        &data.standstill_s(),
        &ReferenceSettings::default(),
    )
}

/// Why a scenario could not be made to follow the drive.
#[derive(Debug, thiserror::Error)]
pub enum DriveScenarioError {
    /// The scenario file could not be read.
    #[error("{}: {source}", path.display())]
    Io {
        /// The scenario file.
        path: std::path::PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The scenario is invalid or its trajectory is not of kind `reference`.
    #[error(transparent)]
    Scenario(#[from] drivers_sim::SimError),
    /// The scenario's trajectory is not of kind `reference`.
    #[error("{}: the trajectory is not of kind `reference`", .0.display())]
    NotReference(std::path::PathBuf),
}

/// The scenario of `path` following `spline` (its own trajectory file, if any, is not read)
/// for `duration_s`, starting at `start_utc` (`YYYY-MM-DDTHH:MM:SS[.fff]`; None: the file's).
pub fn drive_scenario(
    path: &Path,
    spline: Arc<ReferenceTrajectory>,
    duration_s: f64,
    start_utc: Option<&str>,
) -> Result<Scenario, DriveScenarioError> {
    let text = std::fs::read_to_string(path).map_err(|source| DriveScenarioError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut spec = Scenario::parse(&text, path)?;
    let Trajectory::Reference(r) = &mut spec.trajectory else {
        return Err(DriveScenarioError::NotReference(path.to_path_buf()));
    };
    r.spline = Some(spline);
    spec.scenario.duration_s = duration_s;
    if let Some(t) = start_utc {
        spec.scenario.start_utc = t.to_string();
    }
    let dir = path
        .parent()
        .unwrap_or(Path::new("."))
        .join(spec.scenario.sensors_dir.as_deref().unwrap_or("../sensors"));
    Ok(Scenario::validate(spec, path, &dir)?)
}

/// The GPS pseudoranges of an epoch as a receiver sample at `time_ns` (no fix yet): each
/// satellite's pseudorange with σ from the data's variance, its C/N0 and its position rotated
/// into the ECEF frame of reception ([`sagnac`]). Other systems are left out: the navigator's
/// clock model has one receiver clock bias, GLONASS pseudoranges carry another.
pub fn gps_sample(e: &Epoch, time_ns: i64, seq: u64) -> GnssSample {
    let mut s = GnssSample {
        header: Header {
            time_ns,
            seq,
            ..Default::default()
        },
        ..Default::default()
    };
    let mut n = 0;
    for p in e
        .pseudoranges
        .iter()
        .filter(|p| p.system == SYSTEM_GPS)
        .take(MAX_SATELLITES)
    {
        s.satellites[n] = GnssSatellite {
            prn: p.id,
            flags: FLAG_PSEUDORANGE,
            pseudorange_m: p.pseudorange_m,
            cn0_dbhz: p.cn0_dbhz,
            sigma_pseudorange_m: p.variance_m2.sqrt(),
            sat_pos_ecef_m: sagnac(p.sat_pos_ecef_m, p.pseudorange_m),
            ..Default::default()
        };
        n += 1;
    }
    s.n_satellites = n as u32;
    s
}

/// The satellite position rotated by the Earth's turn during the signal's flight
/// (`R_z(ω_e·ρ/c)`), as the navigator's measurement model expects (`msgs::GnssSatellite`).
/// The smartLoc positions are at transmission in the ECEF frame of transmission: at the
/// reference position the rotation shrinks the spread of the high satellites' range residuals
/// from 15.9 m to 5.5 m (median over the shipped slice; test `sagnac_rotation_is_needed` of
/// the hybrid-berlin experiment).
pub fn sagnac(r: [f64; 3], pseudorange_m: f64) -> [f64; 3] {
    let th = WGS84.omega_ie_rad_s * pseudorange_m / C_M_S;
    let (s, c) = th.sin_cos();
    [c * r[0] + s * r[1], -s * r[0] + c * r[1], r[2]]
}

/// Weighted least-squares fix of a sample's pseudoranges.
pub fn wls(s: &GnssSample) -> Option<gnss_ls::GnssFix> {
    let obs = Observations::from_sample(s).ok()?;
    gnss_ls::solve(&obs, &LsSettings::default()).ok()
}

/// Put a least-squares fix into a sample (position only: no Doppler, so no velocity).
pub fn set_fix(s: &mut GnssSample, fix: &gnss_ls::GnssFix) {
    let p = &fix.position;
    s.fix_valid = 1;
    s.pos_ecef_m = p.r_e_m.into();
    s.pdop = p.dop.pdop;
    for r in 0..3 {
        for c in 0..3 {
            s.pos_cov_ecef_m2[3 * r + c] = p.cov_r_e_m2[(r, c)];
        }
    }
}

/// The state the navigation starts from: the reference's first epoch with an assumed
/// accuracy, standing in for a transfer alignment from the reference INS (the data have no
/// Doppler, so no GNSS velocity exists for the alignment in motion).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StartFix {
    /// Position, ECEF, m.
    pub r_e_m: Vector3<f64>,
    /// Velocity, ECEF, m/s.
    pub v_e_m_s: Vector3<f64>,
    /// Assumed 1-σ of each position axis, m.
    pub position_sigma_m: f64,
    /// Assumed 1-σ of each velocity axis, m/s.
    pub velocity_sigma_m_s: f64,
}

/// Default assumed 1-σ of the reference position the navigation starts from, m.
pub const START_POSITION_SIGMA_M: f64 = 0.5;
/// Default assumed 1-σ of the reference velocity the navigation starts from, m/s.
pub const START_VELOCITY_SIGMA_M_S: f64 = 0.1;

impl StartFix {
    /// The scenario's truth at its epoch (on the drive's spline: the reference's first point)
    /// with the default assumed accuracy.
    pub fn of_scenario(scn: &Scenario) -> Self {
        let truth0 = *TruthGenerator::new(scn).current();
        Self {
            r_e_m: truth0.r_e_m,
            v_e_m_s: truth0.v_e_m_s(),
            position_sigma_m: START_POSITION_SIGMA_M,
            velocity_sigma_m_s: START_VELOCITY_SIGMA_M_S,
        }
    }

    /// Make `s` carry this start as its fix (position and velocity, diagonal covariances).
    pub fn apply(&self, s: &mut GnssSample) {
        s.fix_valid = 1;
        s.pos_ecef_m = self.r_e_m.into();
        s.vel_ecef_m_s = self.v_e_m_s.into();
        let (sp, sv) = (
            self.position_sigma_m.powi(2),
            self.velocity_sigma_m_s.powi(2),
        );
        s.pos_cov_ecef_m2 = [sp, 0.0, 0.0, 0.0, sp, 0.0, 0.0, 0.0, sp];
        s.vel_cov_ecef_m2_s2 = [sv, 0.0, 0.0, 0.0, sv, 0.0, 0.0, 0.0, sv];
    }
}

/// Why the drive's samples could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DriveSamplesError {
    /// No pseudorange epoch in the span.
    #[error("no pseudorange epoch in the data")]
    NoEpoch,
    /// The first pseudorange epoch is not at the reference's first point, where the start
    /// fix belongs.
    #[error("the first pseudorange epoch is {0} s after the reference's first point")]
    FirstEpochLate(f64),
}

/// Sextant's samples of a drive.
#[derive(Debug, Clone, Default)]
pub struct DriveSamples {
    /// One sample per pseudorange epoch: its GPS pseudoranges ([`gps_sample`]) with the
    /// epoch's least-squares fix when there is one (`fix_valid` 0 otherwise); the first
    /// carries the start fix instead.
    pub gnss: Vec<GnssSample>,
    /// Odometer: each speed over the interval from the previous sample (distance = speed ×
    /// interval, the data's speed being the one at the sample's time).
    pub odometer: Vec<OdometerSample>,
    /// GPS pseudoranges in `gnss`.
    pub gps_pseudoranges: usize,
    /// Epochs without a least-squares fix (fewer than four GPS pseudoranges, or no solution).
    pub epochs_without_fix: usize,
}

/// The samples of `data` (times from the reference's first point) on the time base whose
/// t = 0 is GPS time `epoch_ns`, up to `end_s`; the first GNSS sample carries `start`.
pub fn drive_samples(
    data: &SmartLoc,
    epoch_ns: i64,
    end_s: f64,
    start: &StartFix,
) -> Result<DriveSamples, DriveSamplesError> {
    let t_ns = |t_ms: i64| epoch_ns + t_ms * 1_000_000;
    let mut out = DriveSamples::default();
    for (seq, e) in data
        .epochs
        .iter()
        .filter(|e| e.t_ms as f64 * 1e-3 <= end_s)
        .enumerate()
    {
        let mut s = gps_sample(e, t_ns(e.t_ms), seq as u64);
        out.gps_pseudoranges += s.n_satellites as usize;
        match wls(&s) {
            Some(fix) => set_fix(&mut s, &fix),
            None => out.epochs_without_fix += 1,
        }
        out.gnss.push(s);
    }
    let first = out.gnss.first_mut().ok_or(DriveSamplesError::NoEpoch)?;
    if first.header.time_ns != epoch_ns {
        return Err(DriveSamplesError::FirstEpochLate(
            (first.header.time_ns - epoch_ns) as f64 * 1e-9,
        ));
    }
    start.apply(first);
    out.odometer = data
        .odometry
        .windows(2)
        .filter(|w| w[1].t_ms as f64 * 1e-3 <= end_s)
        .enumerate()
        .map(|(seq, w)| {
            let dt_s = (w[1].t_ms - w[0].t_ms) as f64 * 1e-3;
            OdometerSample {
                header: Header {
                    time_ns: t_ns(w[1].t_ms),
                    seq: seq as u64,
                    ..Default::default()
                },
                dt_s,
                distance_m: w[1].speed_m_s * dt_s,
                speed_m_s: w[1].speed_m_s,
            }
        })
        .filter(|o| o.dt_s > 0.0)
        .collect();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_three_line_types() {
        let text = "odom3 0 5.85 0 0 0 0 -0.0059 0.0025 0.0009 0.0009 4e-06 4e-06 4e-06   \n\
                    pseudorange3 0 19949087.65 25 14567933.9 2809850.9 21875628.0 12 1 85.1 49\n\
                    pseudorange3 0 19713469.01 64 18145814.9 11532054.1 13684003.6 320 4 58.1 40\n\
                    pseudorange3 0.29999995231628 19949074.96 25 1.4e7 2.8e6 2.18e7 12 1 85.1 49\n\
                    point3 0.29999995231628 3785106.68 899901.70 5037235.49 0 0 0 0 0 0 0 0 0\n";
        let s = parse(text).expect("parse");
        assert_eq!(s.epochs.len(), 2);
        assert_eq!(s.epochs[0].pseudoranges.len(), 2);
        assert_eq!(s.epochs[1].t_ms, 300);
        assert_eq!(s.epochs[0].pseudoranges[1].system, 4);
        assert_eq!(s.epochs[0].pseudoranges[1].id, 320);
        assert_eq!(s.odometry[0].speed_m_s, 5.85);
        assert_eq!(s.odometry[0].speed_variance_m2_s2, 0.0025);
        assert_eq!(s.reference[0].t_ms, 300);
        assert_eq!(s.reference[0].r_e_m[0], 3785106.68);
    }

    #[test]
    fn bad_lines_are_named() {
        let e = parse("point3 0 1 2\n").unwrap_err();
        assert_eq!(e.line, 1);
        let e = parse("point3 1 1 2 3\npoint3 0.5 1 2 3\n").unwrap_err();
        assert!(e.reason.contains("backwards"), "{e}");
        let e = parse("pseudorange3 0 2e7 0 1 2 3 12 1 40 40\n").unwrap_err();
        assert!(e.reason.contains("variance"), "{e}");
        let e = parse("pseudorange3 0 2e7 4 1 2 3 1.5 1 40 40\n").unwrap_err();
        assert!(e.reason.contains("whole"), "{e}");
        assert!(parse("odom3 0 x 0 0 0 0 0 0 0 0 0 0 0\n").is_err());
        assert!(parse("other 1 2\n\n").expect("skipped").epochs.is_empty());
    }

    proptest::proptest! {
        /// Any text: an error or a result, never a panic.
        #[test]
        fn never_panics(text in "(pseudorange3|odom3|point3|[a-z]{0,3})( [-0-9.e]{0,8}){0,15}\n{0,2}") {
            let _ = parse(&text);
        }
    }
}
