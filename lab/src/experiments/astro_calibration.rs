//! Paper 000 experiment (astro-inertial navigation: IMU / star-tracker basis alignment), in
//! simulation: `sextant experiment astro-calibration`.
//!
//! The paper's stand: site φ = 55.655°, λ = 37.534°, levelled, star tracker at the zenith;
//! 10 night records of 16 000 s at 1 Hz; tracker error ≤ 0.005°, inertial vertical error
//! ≤ 0.03°; a boresight misalignment of a few tenths of a degree; the first 600 s calibrate.
//! Here each record is `config/scenarios/astro_stand.toml` with seed 1..10 (record k starts
//! k − 1 days after the file's start), simulated by the drivers' own sensor models
//! ([`drivers_sim::sensors::StarTrackerSim`] with real IAU 2006/2000A precession–nutation, and
//! [`drivers_sim::imu::ImuErrorModel`]). The stand is static, so the truth is one constant
//! [`drivers_sim::truth::TruthPoint`]; the IMU's true increments over an interval dt are then
//! exactly `ω_ib·dt` and `f·dt` (what the 1 ms truth grid integrates to — a drivers-sim test
//! holds the two equal), which lets a 16 000 s record run in well under a second.
//!
//! Per second the inertial vertical is levelled from the mean specific force of that second
//! (`fusion::alignment::level`); the heading, needed by stage 1 only, is gyrocompassed once from
//! the first 600 s. Per record this runs, and evaluates on the samples after the 600 s window:
//! - without calibration (identity mounting matrix, the paper's mode 1);
//! - the paper's three stages ([`fusion::boresight::three_stage`]) over the first 600 s;
//! - Gauss–Newton least squares over the same 600 s, and over the whole record;
//! - the paper's three stages with the celestial rotation reduced to Earth rotation only
//!   (sidereal time, as the paper; and ERA) — what ignoring precession–nutation costs.

use super::plot::{Chart, Line, color, finite_points, line_chart};
use super::{
    Experiment, ExperimentError, fmt_f64, fmt_opt, mean_of_finite, nan_if_null, progress_bar,
};
use drivers_sim::imu::ImuErrorModel;
use drivers_sim::scenario::Scenario;
use drivers_sim::sensors::StarTrackerSim;
use drivers_sim::truth::{Increments, TruthGenerator};
use fusion::astro_fix::CelestialModel;
use fusion::boresight::{
    self, BoresightSample, FixErrors, LeastSquaresSettings, Site, ThreeStageSettings,
};
use fusion::time::{GpsTime, NS_PER_S};
use nalgebra::{Matrix3, Vector2, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The paper's table: per record (latitude error deg, m, calibrated deg, m, longitude error
/// deg, m, calibrated deg, m), then the mean over the records.
pub const PAPER_TABLE: [[f64; 8]; 11] = [
    [
        0.5707, 63416.0, 0.017, 1889.0, 0.6548, 45589.0, 0.0162, 1128.0,
    ],
    [
        0.5112, 56805.0, 0.0144, 1600.0, 0.6628, 46146.0, 0.0279, 1943.0,
    ],
    [
        0.5522, 61360.0, 0.0198, 2200.0, 0.5315, 37005.0, 0.0272, 1894.0,
    ],
    [
        0.5688, 63205.0, 0.0170, 1889.0, 0.6305, 43897.0, 0.0269, 1873.0,
    ],
    [
        0.6731, 74795.0, 0.0180, 2000.0, 0.5763, 40124.0, 0.0387, 2694.0,
    ],
    [
        0.4975, 55282.0, 0.0200, 2222.0, 0.6167, 42937.0, 0.0251, 1748.0,
    ],
    [
        0.5991, 66572.0, 0.0216, 2400.0, 0.5544, 38599.0, 0.0371, 2583.0,
    ],
    [
        0.6367, 70750.0, 0.0201, 2233.0, 0.5871, 40876.0, 0.0376, 2618.0,
    ],
    [
        0.5502, 61138.0, 0.0198, 2200.0, 0.6055, 42157.0, 0.0326, 2270.0,
    ],
    [
        0.5515, 61283.0, 0.0217, 2411.0, 0.5231, 36420.0, 0.0216, 1504.0,
    ],
    [
        0.5711, 63461.0, 0.0189, 2100.0, 0.5942, 41370.0, 0.0301, 2096.0,
    ],
];

/// Size of the experiment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// Number of records (seeds 1..=records).
    pub records: usize,
    /// Length of each record, s.
    pub duration_s: f64,
    /// Calibration window, s.
    pub window_s: f64,
    /// Length of the online run of the navigator (Kalman filter with boresight states) over
    /// the same record, s; 0 = no online run.
    pub online_s: f64,
}

impl Default for Settings {
    /// The full experiment: [`Settings::paper`].
    fn default() -> Self {
        Self::paper()
    }
}

impl Settings {
    /// The paper's: 10 records of 16 000 s, 600 s window.
    pub fn paper() -> Self {
        Self {
            records: 10,
            duration_s: 16_000.0,
            window_s: 600.0,
            online_s: 3600.0,
        }
    }
}

/// Path of the scenario file.
pub fn scenario_path() -> PathBuf {
    crate::shipped_config::scenario("astro_stand.toml")
}

fn measurement(e: impl std::fmt::Display) -> ExperimentError {
    ExperimentError::Measurement(e.to_string())
}

/// The scenario of record `k` (1-based): seed k, start shifted by k − 1 days.
pub fn record_scenario(k: usize) -> Result<Scenario, ExperimentError> {
    let path = scenario_path();
    let text = std::fs::read_to_string(&path).map_err(|source| ExperimentError::Io {
        path: path.clone(),
        source,
    })?;
    let mut table: toml::Table = toml::from_str(&text).map_err(measurement)?;
    let base = Scenario::from_toml_str(&text, &path).map_err(measurement)?;
    let start = GpsTime::from_utc_datetime(&base.start)
        .add_ns((k as i64 - 1) * 86_400 * NS_PER_S)
        .to_utc();
    let meta = table
        .get_mut("scenario")
        .and_then(toml::Value::as_table_mut)
        .ok_or_else(|| measurement("astro_stand.toml: no [scenario]"))?;
    meta.insert(
        "start_utc".into(),
        toml::Value::String(format!(
            "{:04}-{:02}-{:02}T{:02}:{:02}:{:02}",
            start.year, start.month, start.day, start.hour, start.minute, start.second
        )),
    );
    meta.insert("seed".into(), toml::Value::Integer(k as i64));
    let text = toml::to_string(&table).map_err(measurement)?;
    Scenario::from_toml_str(&text, &path).map_err(measurement)
}

/// One simulated record, ready for calibration.
#[derive(Debug, Clone)]
pub struct Record {
    /// 1 Hz samples (star tracker + IMU vertical + gyrocompass heading), from t = 1 s.
    pub samples: Vec<BoresightSample>,
    /// True κ, rad.
    pub kappa_true_rad: Vector3<f64>,
    /// Site.
    pub site: Site,
    /// Mean error of the IMU's roll and pitch over the calibration window, rad.
    pub vertical_error_window_rad: Vector2<f64>,
    /// Mean error of the IMU's roll and pitch over the rest of the record, rad.
    pub vertical_error_after_rad: Vector2<f64>,
    /// Gyrocompass heading error, rad.
    pub heading_error_rad: f64,
    /// Star-tracker noise across / about the optical axis, rad (from the scenario's grade).
    pub tracker_sigma_rad: (f64, f64),
    /// White tilt noise of one 1-s levelling, rad (accelerometer VRW over 1 s / g).
    pub tilt_sigma_rad: f64,
}

/// Simulate record `k` of `duration_s` (see the module comment).
pub fn simulate(k: usize, duration_s: f64, window_s: f64) -> Result<Record, ExperimentError> {
    let scn = record_scenario(k)?;
    let truth = *TruthGenerator::new(&scn).current();
    let mut tracker = StarTrackerSim::new(&scn);
    let mut imu = ImuErrorModel::new(&scn);
    let epoch = scn.epoch_gps();
    let imu_per_s = scn.spec.imu.rate_hz.round() as usize;
    let dt = 1.0 / imu_per_s as f64;
    let inc = Increments {
        dt_s: dt,
        delta_angle_b_rad: truth.w_ib_b_rad_s * dt,
        delta_velocity_b_m_s: truth.f_b_m_s2 * dt,
        distance_x_m: 0.0,
        odometer_distance_m: 0.0,
        // A constant rate: no tangential term, the centripetal one of the Earth's rate.
        delta_rate_b_rad_s: nalgebra::Vector3::zeros(),
        rate_outer_b_rad2_s: truth.w_ib_b_rad_s * truth.w_ib_b_rad_s.transpose() * dt,
    };
    let n = duration_s.floor() as usize;
    let mut f_mean = Vec::with_capacity(n);
    let mut w_mean = Vec::with_capacity(n);
    for sec in 0..n {
        let (mut dv, mut da) = (Vector3::zeros(), Vector3::zeros());
        for j in 1..=imu_per_s {
            let t_end = sec as f64 + j as f64 * dt;
            let e = imu.next_interval(t_end, dt);
            let (a, v) = imu.corrupt(&e, &inc);
            da += a;
            dv += v;
        }
        f_mean.push(dv);
        w_mean.push(da);
    }
    let win = (window_s.floor() as usize).min(n).max(1);
    let f_win: Vector3<f64> = f_mean[..win].iter().sum::<Vector3<f64>>() / win as f64;
    let w_win: Vector3<f64> = w_mean[..win].iter().sum::<Vector3<f64>>() / win as f64;
    let (r_win, p_win) = fusion::alignment::level(&f_win);
    let heading = fusion::alignment::gyrocompass(&w_win, r_win, p_win);
    let rph_true = truth.roll_pitch_heading_rad;
    // The head's time tag (`[world.star_tracker] latency_s`): the sample stamped t is the sky
    // seen at t − latency, as the driver's source makes it. The calibration uses the stamp.
    let latency_ns = scn.spec.world.map_or(0, |w| w.star_tracker_latency_ns());
    let mut samples = Vec::with_capacity(n);
    let (mut ew, mut ea) = (Vector2::zeros(), Vector2::zeros());
    for (sec, f) in f_mean.iter().enumerate() {
        let t_s = (sec + 1) as f64;
        let time = epoch.add_ns((sec as i64 + 1) * NS_PER_S);
        let st = tracker.sample(t_s - latency_ns as f64 * 1e-9, time.ns - latency_ns, &truth);
        let c_s_i = fusion::attitude::quat_from_wire(&st.q_sensor_icrf)
            .to_rotation_matrix()
            .into_inner();
        let (roll, pitch) = fusion::alignment::level(f);
        let err = Vector2::new(roll - rph_true.x, pitch - rph_true.y);
        if sec < win {
            ew += err;
        } else {
            ea += err;
        }
        samples.push(BoresightSample {
            time,
            c_s_i,
            roll_rad: roll,
            pitch_rad: pitch,
            heading_rad: heading,
        });
    }
    let kd = scn.spec.star_tracker.mounting_kappa_deg;
    let arcsec = std::f64::consts::PI / 180.0 / 3600.0;
    Ok(Record {
        samples,
        kappa_true_rad: Vector3::new(kd[0].to_radians(), kd[1].to_radians(), kd[2].to_radians()),
        site: Site {
            lat_rad: scn.spec.site.lat_deg.to_radians(),
            lon_rad: scn.spec.site.lon_deg.to_radians(),
        },
        vertical_error_window_rad: ew / win as f64,
        vertical_error_after_rad: ea / (n - win).max(1) as f64,
        heading_error_rad: fusion_wrap(heading - rph_true.z),
        tracker_sigma_rad: (
            scn.star_tracker.sigma_cross_arcsec * arcsec,
            scn.star_tracker.sigma_roll_arcsec * arcsec,
        ),
        // VRW in µg/√Hz is the white error of a 1-s mean specific force in µg, i.e. a tilt of
        // vrw·1e-6 rad (f/g with g ≈ 1 g).
        tilt_sigma_rad: scn.imu.accel.vrw_ug_per_rt_hz * 1e-6,
    })
}

fn fusion_wrap(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
}

/// The navigator's online boresight estimate over the first `online_s` of record `k`: the
/// full filter (IMU, star tracker, GNSS; the stand's configuration,
/// [`drivers_sim::stand::boresight_filter_config`], installed for the stand's world) fed by the simulated drivers'
/// time-ordered stream ([`drivers_sim::offline`]). Returns κ̂ and the σ the navigator
/// reports, rad.
fn online_estimate(
    k: usize,
    online_s: f64,
) -> Result<(Vector3<f64>, Vector3<f64>), ExperimentError> {
    use drivers_sim::offline::{OfflineSim, run_navigator};
    use fusion::navigator::Navigator;
    use msgs::Channel;
    let scn = record_scenario(k)?;
    let sim = OfflineSim::with_channels(&scn, &[Channel::Imu, Channel::StarTracker, Channel::Gnss])
        .with_duration_s(online_s);
    let epoch = sim.epoch_ns();
    // Installed for the stand's world as an engineer would (the star tracker's time tag and
    // slow error class, the receiver's error correlation, the region's gravity class):
    // `config/filter.toml`'s values, never the world's.
    let config =
        super::consistency::installed(&scn, drivers_sim::stand::boresight_filter_config(&scn))?;
    let mut nav = Navigator::new(config).map_err(measurement)?;
    run_navigator(sim, epoch, &mut nav, |_| {}).map_err(measurement)?;
    if !nav.is_navigating() {
        return Err(measurement(format!(
            "record {k}: the navigator never started navigating"
        )));
    }
    Ok(nav.boresight_rad())
}

/// Figures of one calibration method on one record.
#[derive(Debug, Clone, Copy)]
struct MethodResult {
    kappa_rad: Vector3<f64>,
    errors: FixErrors,
}

/// One calibration method on one record: its κ and the errors of the astro fixes after the
/// calibration window with it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MethodFigures {
    /// κ1..κ3, deg.
    pub kappa_deg: [f64; 3],
    /// κ − true κ, deg.
    pub kappa_error_deg: Vec<f64>,
    /// Error of the mounting's tilt (x, y), deg.
    pub mounting_tilt_error_deg: [f64; 2],
    /// Mean |latitude error|, deg.
    pub lat_error_mean_abs_deg: f64,
    /// Mean |latitude error|, m.
    pub lat_error_mean_abs_m: f64,
    /// Mean |longitude error|, deg.
    pub lon_error_mean_abs_deg: f64,
    /// Mean |longitude error|, m.
    pub lon_error_mean_abs_m: f64,
    /// Mean latitude error, deg.
    pub lat_error_mean_deg: f64,
    /// Mean longitude error, deg.
    pub lon_error_mean_deg: f64,
    /// RMS horizontal error of a single fix, m.
    pub horizontal_error_rms_m: f64,
    /// Horizontal error of the mean fix, m.
    pub mean_fix_error_m: f64,
}

impl MethodFigures {
    fn of(m: &MethodResult, kappa_true: &Vector3<f64>) -> Self {
        let tilt_err =
            boresight::mounting_tilt_rad(&m.kappa_rad) - boresight::mounting_tilt_rad(kappa_true);
        Self {
            kappa_deg: [
                m.kappa_rad.x.to_degrees(),
                m.kappa_rad.y.to_degrees(),
                m.kappa_rad.z.to_degrees(),
            ],
            kappa_error_deg: degrees(&(m.kappa_rad - kappa_true)),
            mounting_tilt_error_deg: [tilt_err.x.to_degrees(), tilt_err.y.to_degrees()],
            lat_error_mean_abs_deg: m.errors.mean_abs_dlat_rad.to_degrees(),
            lat_error_mean_abs_m: m.errors.mean_abs_north_m,
            lon_error_mean_abs_deg: m.errors.mean_abs_dlon_rad.to_degrees(),
            lon_error_mean_abs_m: m.errors.mean_abs_east_m,
            lat_error_mean_deg: m.errors.mean_dlat_rad.to_degrees(),
            lon_error_mean_deg: m.errors.mean_dlon_rad.to_degrees(),
            horizontal_error_rms_m: m.errors.rms_horizontal_m,
            mean_fix_error_m: m.errors.mean_fix_error_m,
        }
    }
}

/// The components of `v`, deg.
fn degrees(v: &Vector3<f64>) -> Vec<f64> {
    v.iter().map(|v| v.to_degrees()).collect()
}

/// The 3-stage calibration with one celestial model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ThreeStageFigures {
    /// κ and the fix errors.
    #[serde(flatten)]
    pub result: MethodFigures,
    /// Mean fix error in the window after stage 1, m.
    pub stage1_window_error_m: f64,
    /// Descent steps of stage 3.
    pub stage3_iterations: usize,
    /// Mean fix error in the window after stage 3, m.
    pub stage3_window_error_m: f64,
    /// Stage 3 stopped below the threshold.
    pub stage3_reached_threshold: bool,
}

/// The 3-stage calibration per celestial model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ByCelestialModel {
    /// IAU 2006/2000A.
    pub full: ThreeStageFigures,
    /// Earth rotation only, GMST (the paper's).
    pub gmst_only: ThreeStageFigures,
    /// Earth rotation only, ERA.
    pub era_only: ThreeStageFigures,
}

/// Stage 3 alone from the identity matrix.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DescentFigures {
    /// κ and the fix errors.
    pub result: MethodFigures,
    /// Descent steps.
    pub iterations: usize,
    /// Mean fix error in the window at the start, m.
    pub window_error_start_m: f64,
    /// Mean fix error in the window at the end, m.
    pub window_error_end_m: f64,
    /// It stopped below the threshold.
    pub reached_threshold: bool,
}

/// The least-squares estimator's own figures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EstimatorFigures {
    /// σ of κ1..κ3, deg.
    pub kappa_sigma_deg: Vec<f64>,
    /// σ of the mounting's tilt (x, y), deg.
    pub mounting_tilt_sigma_deg: [f64; 2],
    /// χ² per degree of freedom of the residuals.
    pub chi2_per_dof: f64,
    /// Gauss–Newton iterations.
    pub iterations: usize,
    /// Samples used.
    pub samples: usize,
}

impl EstimatorFigures {
    fn of(r: &boresight::LeastSquaresResult) -> Self {
        Self {
            kappa_sigma_deg: degrees(&r.sigma_rad()),
            mounting_tilt_sigma_deg: [
                r.tilt_covariance_rad2[(0, 0)].sqrt().to_degrees(),
                r.tilt_covariance_rad2[(1, 1)].sqrt().to_degrees(),
            ],
            chi2_per_dof: r.chi2_per_dof,
            iterations: r.iterations,
            samples: r.samples,
        }
    }
}

/// A least-squares calibration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LeastSquaresFigures {
    /// κ and the fix errors.
    pub result: MethodFigures,
    /// The estimator's figures.
    pub estimator: EstimatorFigures,
}

/// The navigator's online boresight estimate over the start of one record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OnlineRecord {
    /// Length of the online run, s.
    pub duration_s: f64,
    /// κ̂, deg.
    pub kappa_deg: Vec<f64>,
    /// The σ the navigator reports, deg.
    pub kappa_sigma_deg: Vec<f64>,
    /// κ̂ − true κ, deg.
    pub kappa_error_deg: Vec<f64>,
    /// κ̂ − the 3-stage κ, deg.
    pub kappa_minus_three_stage_deg: Vec<f64>,
    /// Mounting tilt of κ̂ − that of the 3-stage κ (x, y), deg.
    pub mounting_tilt_minus_three_stage_deg: [f64; 2],
    /// Mounting tilt of κ̂ − the true one (x, y), deg.
    pub mounting_tilt_error_deg: [f64; 2],
}

/// One simulated record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordFigures {
    /// The online filter's estimate (absent when not run).
    pub online_filter: Option<OnlineRecord>,
    /// Record number, 1-based.
    pub record: usize,
    /// Its seed.
    pub seed: usize,
    /// 1 Hz samples.
    pub samples: usize,
    /// Samples after the calibration window (evaluated).
    pub evaluated_samples: usize,
    /// True κ, deg.
    pub kappa_true_deg: [f64; 3],
    /// Mean error of the IMU's roll and pitch over the window, deg.
    pub imu_vertical_error_window_deg: [f64; 2],
    /// The same over the rest of the record, deg.
    pub imu_vertical_error_after_window_deg: [f64; 2],
    /// The window's vertical error as the mounting tilt it makes up for (x, y), deg.
    pub vertical_error_absorbed_as_mounting_tilt_deg: [f64; 2],
    /// Gyrocompass heading error, deg.
    pub gyrocompass_heading_error_deg: f64,
    /// Without calibration (κ = 0).
    pub uncalibrated: MethodFigures,
    /// The 3-stage calibration, full celestial model.
    pub three_stage: ThreeStageFigures,
    /// The 3-stage calibration per celestial model.
    pub three_stage_by_celestial_model: ByCelestialModel,
    /// Stage 3 alone from the identity.
    pub descent_from_identity: DescentFigures,
    /// Least squares over the window.
    pub least_squares_window: LeastSquaresFigures,
    /// Least squares over every sample.
    pub least_squares_all_samples: LeastSquaresFigures,
}

/// Fix errors of a method averaged over the records (undefined ones left out).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MeanErrors {
    /// Mean |latitude error|, deg.
    #[serde(deserialize_with = "nan_if_null")]
    pub lat_error_mean_abs_deg: f64,
    /// Mean |latitude error|, m.
    #[serde(deserialize_with = "nan_if_null")]
    pub lat_error_mean_abs_m: f64,
    /// Mean |longitude error|, deg.
    #[serde(deserialize_with = "nan_if_null")]
    pub lon_error_mean_abs_deg: f64,
    /// Mean |longitude error|, m.
    #[serde(deserialize_with = "nan_if_null")]
    pub lon_error_mean_abs_m: f64,
    /// RMS horizontal error of a single fix, m.
    #[serde(deserialize_with = "nan_if_null")]
    pub horizontal_error_rms_m: f64,
    /// Horizontal error of the mean fix, m.
    #[serde(deserialize_with = "nan_if_null")]
    pub mean_fix_error_m: f64,
}

impl MeanErrors {
    /// The means over `records` of the method that `method` selects.
    fn over(records: &[RecordFigures], method: impl Fn(&RecordFigures) -> &MethodFigures) -> Self {
        let mean =
            |f: fn(&MethodFigures) -> f64| mean_of_finite(records.iter().map(|r| f(method(r))));
        Self {
            lat_error_mean_abs_deg: mean(|m| m.lat_error_mean_abs_deg),
            lat_error_mean_abs_m: mean(|m| m.lat_error_mean_abs_m),
            lon_error_mean_abs_deg: mean(|m| m.lon_error_mean_abs_deg),
            lon_error_mean_abs_m: mean(|m| m.lon_error_mean_abs_m),
            horizontal_error_rms_m: mean(|m| m.horizontal_error_rms_m),
            mean_fix_error_m: mean(|m| m.mean_fix_error_m),
        }
    }
}

impl From<&MethodFigures> for MeanErrors {
    /// One record's figures (for a table row).
    fn from(m: &MethodFigures) -> Self {
        Self {
            lat_error_mean_abs_deg: m.lat_error_mean_abs_deg,
            lat_error_mean_abs_m: m.lat_error_mean_abs_m,
            lon_error_mean_abs_deg: m.lon_error_mean_abs_deg,
            lon_error_mean_abs_m: m.lon_error_mean_abs_m,
            horizontal_error_rms_m: m.horizontal_error_rms_m,
            mean_fix_error_m: m.mean_fix_error_m,
        }
    }
}

/// The means over the records per method.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Means {
    /// Without calibration.
    pub uncalibrated: MeanErrors,
    /// 3-stage, full celestial model.
    pub three_stage: MeanErrors,
    /// 3-stage, GMST only.
    pub three_stage_gmst_only: MeanErrors,
    /// 3-stage, ERA only.
    pub three_stage_era_only: MeanErrors,
    /// Stage 3 alone from the identity.
    pub descent_from_identity: MeanErrors,
    /// Least squares over the window.
    pub least_squares_window: MeanErrors,
    /// Least squares over every sample.
    pub least_squares_all_samples: MeanErrors,
}

/// RMS over the records of the online κ errors over the RMS of the σ the filter reports,
/// with the χ² band of a consistent filter.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OnlineConsistency {
    /// RMS error / RMS σ.
    pub error_rms_over_sigma_rms: f64,
    /// Errors in the statistic.
    pub samples: u32,
    /// Its 95 % band, `[√(χ²₀.₀₂₅(n)/n), √(χ²₀.₉₇₅(n)/n)]`.
    pub band95: [f64; 2],
}

/// The online filter over the records.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OnlineFigures {
    /// RMS of the κ1 errors, deg.
    pub kappa1_error_rms_deg: f64,
    /// Mean σ of κ1, deg.
    pub kappa1_sigma_mean_deg: f64,
    /// RMS of the κ2 errors, deg.
    pub kappa2_error_rms_deg: f64,
    /// Mean σ of κ2, deg.
    pub kappa2_sigma_mean_deg: f64,
    /// RMS of the κ3 errors, deg.
    pub kappa3_error_rms_deg: f64,
    /// Mean σ of κ3, deg.
    pub kappa3_sigma_mean_deg: f64,
    /// κ1 (about the vertical).
    pub kappa1_consistency: OnlineConsistency,
    /// κ2.
    pub kappa2_consistency: OnlineConsistency,
    /// κ3.
    pub kappa3_consistency: OnlineConsistency,
    /// κ2 and κ3 together (the mounting tilt).
    pub kappa_tilt_consistency: OnlineConsistency,
}

/// The online filter over the records: empty when it was not run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct OnlineSummary {
    /// The figures, if the filter ran.
    #[serde(flatten)]
    pub figures: Option<OnlineFigures>,
}

/// One row of the paper's table (errors of the mean fix per record).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PaperRow {
    /// Latitude error, deg.
    pub lat_error_deg: f64,
    /// Latitude error, m.
    pub lat_error_m: f64,
    /// Latitude error after calibration, deg.
    pub lat_error_calibrated_deg: f64,
    /// Latitude error after calibration, m.
    pub lat_error_calibrated_m: f64,
    /// Longitude error, deg.
    pub lon_error_deg: f64,
    /// Longitude error, m.
    pub lon_error_m: f64,
    /// Longitude error after calibration, deg.
    pub lon_error_calibrated_deg: f64,
    /// Longitude error after calibration, m.
    pub lon_error_calibrated_m: f64,
}

/// The settings of the run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SettingsFigures {
    /// Records.
    pub records: usize,
    /// Length of each, s.
    pub record_duration_s: f64,
    /// Calibration window, s.
    pub calibration_window_s: f64,
    /// Sample rate, Hz.
    pub sample_rate_hz: f64,
    /// The scenario file.
    pub scenario: String,
    /// Stage 3's descent step, deg.
    pub descent_step_deg: f64,
    /// Stage 3's threshold, m.
    pub threshold_m: f64,
    /// What is evaluated.
    pub evaluation: String,
}

/// The figures of `astro-calibration` (`summary.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// `"astro-calibration"`.
    pub experiment: String,
    /// The scenario's world effects that were on (truth only; empty: the matched world).
    #[serde(default)]
    pub world_effects: Vec<String>,
    /// The paper reproduced.
    pub paper: String,
    /// The settings.
    pub settings: SettingsFigures,
    /// Means over the records per method.
    pub mean: Means,
    /// Mean fix error uncalibrated / 3-stage.
    #[serde(deserialize_with = "nan_if_null")]
    pub improvement_factor_three_stage: f64,
    /// The online filter over the records.
    pub online_filter: OnlineSummary,
    /// The paper's table: 10 records and their mean.
    pub paper_table: Vec<PaperRow>,
    /// The paper's mean row.
    pub paper_mean: Option<PaperRow>,
    /// Per record.
    pub records: Vec<RecordFigures>,
}

experiment!(
    /// `sextant experiment astro-calibration`.
    AstroCalibration,
    "astro-calibration",
    "Paper 000: star-tracker / IMU boresight calibration"
);

/// One plotted series: its name and (time min, north m, east m) points.
type Series = (String, Vec<(f64, f64, f64)>);

/// Results of one record.
struct RecordResult {
    summary: RecordFigures,
    /// (t min, north m, east m) of the 3-stage calibration per celestial model, 60 s means.
    series: Vec<Series>,
}

fn evaluate(k: usize, settings: &Settings) -> Result<RecordResult, ExperimentError> {
    let rec = simulate(k, settings.duration_s, settings.window_s)?;
    let s = &rec.samples;
    let win_end = s
        .iter()
        .position(|x| x.time.seconds_since(s[0].time) > settings.window_s)
        .unwrap_or(s.len());
    if win_end + 1 >= s.len() {
        return Err(measurement(format!(
            "record of {} s leaves nothing after the {} s window",
            settings.duration_s, settings.window_s
        )));
    }
    let three = ThreeStageSettings {
        window_s: settings.window_s,
        ..Default::default()
    };
    let eop = fusion::celestial::EarthOrientation::default();
    let models = [
        CelestialModel::Full(eop),
        CelestialModel::GmstOnly { dut1_s: 0.0 },
        CelestialModel::EraOnly { dut1_s: 0.0 },
    ];
    let err = |e: fusion::astro_fix::AstroError| measurement(format!("record {k}: {e}"));
    let mut by_model = Vec::new();
    let mut series = Vec::new();
    let mut full_c_e_i: Vec<Matrix3<f64>> = Vec::new();
    let mut three_full = None;
    for model in &models {
        let c_e_i = boresight::c_e_i_of(s, model);
        let r = boresight::three_stage(s, &c_e_i, &rec.site, &three).map_err(err)?;
        let kappa = r.kappa_rad();
        let e = boresight::fix_errors(&s[win_end..], &c_e_i[win_end..], &rec.site, &kappa)
            .map_err(err)?;
        // 60 s means of the calibrated fixes for the plot.
        let c_s_b = boresight::c_s_b_of_kappa(&kappa);
        let (m_lat, m_lon) = rec.site.metres_per_rad();
        let mut pts = Vec::new();
        for chunk in (0..s.len()).collect::<Vec<_>>().chunks(60) {
            let (mut n_m, mut e_m) = (0.0, 0.0);
            for &i in chunk {
                let f = fusion::astro_fix::astro_fix_unchecked(
                    &s[i].c_s_i,
                    s[i].roll_rad,
                    s[i].pitch_rad,
                    &c_s_b,
                    &c_e_i[i],
                );
                n_m += (f.lat_rad - rec.site.lat_rad) * m_lat;
                e_m += fusion_wrap(f.lon_rad - rec.site.lon_rad) * m_lon;
            }
            let c = chunk.len() as f64;
            let t_min = s[chunk[chunk.len() / 2]].time.seconds_since(s[0].time) / 60.0;
            pts.push((t_min, n_m / c, e_m / c));
        }
        series.push((model.name().to_string(), pts));
        let m = MethodResult {
            kappa_rad: kappa,
            errors: e,
        };
        by_model.push((model.name(), r, m));
        if matches!(model, CelestialModel::Full(_)) {
            full_c_e_i = c_e_i;
            three_full = Some(r);
        }
    }
    let Some(three_full) = three_full else {
        return Err(measurement("no full-model calibration"));
    };
    let c_e_i = &full_c_e_i;
    let uncal = MethodResult {
        kappa_rad: Vector3::zeros(),
        errors: boresight::fix_errors(
            &s[win_end..],
            &c_e_i[win_end..],
            &rec.site,
            &Vector3::zeros(),
        )
        .map_err(err)?,
    };
    let ls_settings = LeastSquaresSettings {
        sigma_tracker_cross_rad: rec.tracker_sigma_rad.0,
        sigma_tracker_roll_rad: rec.tracker_sigma_rad.1,
        sigma_tilt_rad: rec.tilt_sigma_rad,
        kappa_prior_rad: three_full.initial.kappa_rad,
        sigma_prior_rad: 1f64.to_radians(),
        max_iterations: 20,
    };
    // Stage 3 alone from the identity matrix (the paper's mode-1 matrix): the descent stops
    // as soon as the window's error is below the threshold, so its result sits just under it.
    let descent = boresight::refine_fixed_step(
        &s[..win_end],
        &c_e_i[..win_end],
        &rec.site,
        &Vector3::zeros(),
        &three,
    )
    .map_err(err)?;
    let descent_m = MethodResult {
        kappa_rad: descent.kappa_rad,
        errors: boresight::fix_errors(
            &s[win_end..],
            &c_e_i[win_end..],
            &rec.site,
            &descent.kappa_rad,
        )
        .map_err(err)?,
    };
    let ls_win =
        boresight::least_squares(&s[..win_end], &c_e_i[..win_end], &rec.site, &ls_settings)
            .map_err(err)?;
    let ls_all = boresight::least_squares(s, c_e_i, &rec.site, &ls_settings).map_err(err)?;
    let eval = |kappa: &Vector3<f64>| {
        boresight::fix_errors(&s[win_end..], &c_e_i[win_end..], &rec.site, kappa).map_err(err)
    };
    let ls_win_m = MethodResult {
        kappa_rad: ls_win.kappa_rad,
        errors: eval(&ls_win.kappa_rad)?,
    };
    let ls_all_m = MethodResult {
        kappa_rad: ls_all.kappa_rad,
        errors: eval(&ls_all.kappa_rad)?,
    };
    let kt = &rec.kappa_true_rad;
    // The vertical error a static calibration absorbs: the IMU reports roll γ + δγ, pitch
    // θ + δθ, so its down vector in body axes is off by (−δθ, δγ, 0); the fitted mounting makes
    // up for it, `M̂·ẑ ≈ M·ẑ + (δθ, −δγ)` (tilt components, rad). Compared below with the
    // estimators' tilt errors.
    let absorbed = Vector2::new(
        rec.vertical_error_window_rad.y,
        -rec.vertical_error_window_rad.x,
    );
    let three_stage = |name: &str| -> Result<ThreeStageFigures, ExperimentError> {
        let (_, r, m) = by_model
            .iter()
            .find(|(n, _, _)| *n == name)
            .ok_or_else(|| measurement(format!("no {name} calibration")))?;
        Ok(ThreeStageFigures {
            result: MethodFigures::of(m, kt),
            stage1_window_error_m: r.initial_errors.mean_fix_error_m,
            stage3_iterations: r.refinement.iterations,
            stage3_window_error_m: r.refinement.error_m,
            stage3_reached_threshold: r.refinement.reached_threshold,
        })
    };
    let by_celestial_model = ByCelestialModel {
        full: three_stage("full")?,
        gmst_only: three_stage("gmst_only")?,
        era_only: three_stage("era_only")?,
    };
    let online = if settings.online_s > 0.0 {
        let (kappa, sigma) = online_estimate(k, settings.online_s)?;
        let d_tool = boresight::mounting_tilt_rad(&kappa)
            - boresight::mounting_tilt_rad(&three_full.kappa_rad());
        let d_true = boresight::mounting_tilt_rad(&kappa) - boresight::mounting_tilt_rad(kt);
        Some(OnlineRecord {
            duration_s: settings.online_s,
            kappa_deg: degrees(&kappa),
            kappa_sigma_deg: degrees(&sigma),
            kappa_error_deg: degrees(&(kappa - kt)),
            kappa_minus_three_stage_deg: degrees(&(kappa - three_full.kappa_rad())),
            mounting_tilt_minus_three_stage_deg: [d_tool.x.to_degrees(), d_tool.y.to_degrees()],
            mounting_tilt_error_deg: [d_true.x.to_degrees(), d_true.y.to_degrees()],
        })
    } else {
        None
    };
    let pair = |v: &Vector2<f64>| [v.x.to_degrees(), v.y.to_degrees()];
    let summary = RecordFigures {
        online_filter: online,
        record: k,
        seed: k,
        samples: s.len(),
        evaluated_samples: s.len() - win_end,
        kappa_true_deg: [kt.x.to_degrees(), kt.y.to_degrees(), kt.z.to_degrees()],
        imu_vertical_error_window_deg: pair(&rec.vertical_error_window_rad),
        imu_vertical_error_after_window_deg: pair(&rec.vertical_error_after_rad),
        vertical_error_absorbed_as_mounting_tilt_deg: pair(&absorbed),
        gyrocompass_heading_error_deg: rec.heading_error_rad.to_degrees(),
        uncalibrated: MethodFigures::of(&uncal, kt),
        three_stage: by_celestial_model.full.clone(),
        three_stage_by_celestial_model: by_celestial_model,
        descent_from_identity: DescentFigures {
            result: MethodFigures::of(&descent_m, kt),
            iterations: descent.iterations,
            window_error_start_m: descent.start_error_m,
            window_error_end_m: descent.error_m,
            reached_threshold: descent.reached_threshold,
        },
        least_squares_window: LeastSquaresFigures {
            result: MethodFigures::of(&ls_win_m, kt),
            estimator: EstimatorFigures::of(&ls_win),
        },
        least_squares_all_samples: LeastSquaresFigures {
            result: MethodFigures::of(&ls_all_m, kt),
            estimator: EstimatorFigures::of(&ls_all),
        },
    };
    Ok(RecordResult { summary, series })
}

/// The measurement with `settings` into the existing `out_dir` (plots); returns the summary
/// ([`Experiment::run_with`] writes it to `summary.json`).
fn measure(
    settings: &Settings,
    out_dir: &Path,
    progress: bool,
) -> Result<Summary, ExperimentError> {
    let bar = progress_bar(
        progress,
        settings.records as u64,
        "astro-calibration records",
    );
    let results: Vec<Result<RecordResult, ExperimentError>> = (1..=settings.records)
        .into_par_iter()
        .map(|k| {
            let r = evaluate(k, settings);
            bar.inc(1);
            r
        })
        .collect();
    bar.finish_and_clear();
    let results: Vec<RecordResult> = results.into_iter().collect::<Result<_, _>>()?;
    let records: Vec<RecordFigures> = results.iter().map(|r| r.summary.clone()).collect();
    let means = Means {
        uncalibrated: MeanErrors::over(&records, |r| &r.uncalibrated),
        three_stage: MeanErrors::over(&records, |r| &r.three_stage.result),
        three_stage_gmst_only: MeanErrors::over(&records, |r| {
            &r.three_stage_by_celestial_model.gmst_only.result
        }),
        three_stage_era_only: MeanErrors::over(&records, |r| {
            &r.three_stage_by_celestial_model.era_only.result
        }),
        descent_from_identity: MeanErrors::over(&records, |r| &r.descent_from_identity.result),
        least_squares_window: MeanErrors::over(&records, |r| &r.least_squares_window.result),
        least_squares_all_samples: MeanErrors::over(&records, |r| {
            &r.least_squares_all_samples.result
        }),
    };
    let paper_rows: Vec<PaperRow> = PAPER_TABLE
        .iter()
        .map(|r| PaperRow {
            lat_error_deg: r[0],
            lat_error_m: r[1],
            lat_error_calibrated_deg: r[2],
            lat_error_calibrated_m: r[3],
            lon_error_deg: r[4],
            lon_error_m: r[5],
            lon_error_calibrated_deg: r[6],
            lon_error_calibrated_m: r[7],
        })
        .collect();
    let uncal_h = means.uncalibrated.mean_fix_error_m;
    let cal_h = means.three_stage.mean_fix_error_m;
    let summary = Summary {
        experiment: AstroCalibration::NAME.into(),
        world_effects: super::world_effects(&record_scenario(1)?),
        paper: "000 (astro-inertial basis alignment)".into(),
        settings: SettingsFigures {
            records: settings.records,
            record_duration_s: settings.duration_s,
            calibration_window_s: settings.window_s,
            sample_rate_hz: 1.0,
            scenario: "config/scenarios/astro_stand.toml".into(),
            descent_step_deg: boresight::PAPER_STEP_RAD.to_degrees(),
            threshold_m: boresight::PAPER_THRESHOLD_M,
            evaluation: "astro fixes of the samples after the calibration window".into(),
        },
        mean: means,
        improvement_factor_three_stage: uncal_h / cal_h,
        online_filter: OnlineSummary {
            figures: online_figures(&records),
        },
        paper_mean: paper_rows.last().copied(),
        paper_table: paper_rows,
        records,
    };
    plots(out_dir, &results, &summary)?;
    Ok(summary)
}

/// The online filter over the records (`None` when it did not run on every record).
///
/// Consistency of the online σ over the records: for a consistent filter each κ error
/// over its σ is N(0, 1) and independent between records (independent seeds) and
/// between κ2, κ3 (independent north/east accelerometer biases), so
/// n·(RMS error / RMS σ)² ≈ χ²(n) with n the number of errors; its 95 % band is
/// [√(χ²₀.₀₂₅(n)/n), √(χ²₀.₉₇₅(n)/n)] (10 records: [0.57, 1.43] per axis, [0.69, 1.31]
/// for κ2 and κ3 together). κ1 (about the vertical) is reported the same way.
fn online_figures(records: &[RecordFigures]) -> Option<OnlineFigures> {
    let online: Vec<&OnlineRecord> = records
        .iter()
        .map(|r| r.online_filter.as_ref())
        .collect::<Option<_>>()?;
    if online.is_empty() {
        return None;
    }
    // Error and σ of κ_{j+1} per record, deg (undefined ones left out).
    let finite = |v: &[f64], j: usize| v.get(j).copied().filter(|x| x.is_finite());
    let errors = |j: usize| -> Vec<f64> {
        online
            .iter()
            .filter_map(|o| finite(&o.kappa_error_deg, j))
            .collect()
    };
    let rms = |j: usize| {
        let e = errors(j);
        (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt()
    };
    let sigma_mean =
        |j: usize| mean_of_finite(online.iter().filter_map(|o| finite(&o.kappa_sigma_deg, j)));
    let ratio = |axes: &[usize]| -> Option<OnlineConsistency> {
        let (mut e2, mut s2, mut n) = (0.0, 0.0, 0u32);
        for o in &online {
            for &j in axes {
                let e = finite(&o.kappa_error_deg, j)?;
                let s = finite(&o.kappa_sigma_deg, j)?;
                e2 += e * e;
                s2 += s * s;
                n += 1;
            }
        }
        let nf = f64::from(n);
        Some(OnlineConsistency {
            error_rms_over_sigma_rms: (e2 / s2).sqrt(),
            samples: n,
            band95: [
                (fusion::ekf::chi2_quantile(n, 0.025) / nf).sqrt(),
                (fusion::ekf::chi2_quantile(n, 0.975) / nf).sqrt(),
            ],
        })
    };
    Some(OnlineFigures {
        kappa1_error_rms_deg: rms(0),
        kappa1_sigma_mean_deg: sigma_mean(0),
        kappa2_error_rms_deg: rms(1),
        kappa2_sigma_mean_deg: sigma_mean(1),
        kappa3_error_rms_deg: rms(2),
        kappa3_sigma_mean_deg: sigma_mean(2),
        kappa1_consistency: ratio(&[0])?,
        kappa2_consistency: ratio(&[1])?,
        kappa3_consistency: ratio(&[2])?,
        kappa_tilt_consistency: ratio(&[1, 2])?,
    })
}

fn plots(
    out_dir: &Path,
    results: &[RecordResult],
    summary: &Summary,
) -> Result<(), ExperimentError> {
    if let Some(first) = results.first() {
        let mut lines = Vec::new();
        for (i, (name, pts)) in first.series.iter().enumerate() {
            lines.push(Line::solid(
                format!("{name}: north"),
                pts.iter().map(|p| (p.0, p.1)).collect(),
                color(i),
            ));
            lines.push(Line::dashed(
                format!("{name}: east"),
                pts.iter().map(|p| (p.0, p.2)).collect(),
                color(i),
            ));
        }
        line_chart(
            &out_dir.join("astro_calibration_record1_error_vs_time.png"),
            &Chart::linear(
                "Record 1: astro-fix error after the 3-stage calibration (60 s means)",
                "time since start [min]",
                "position error [m]",
                &lines,
            ),
        )?;
    }
    let per = |f: fn(&RecordFigures) -> f64| -> Vec<(f64, f64)> {
        finite_points(
            summary
                .records
                .iter()
                .enumerate()
                .map(|(i, r)| ((i + 1) as f64, f(r))),
        )
    };
    let paper = |col: usize| -> Vec<(f64, f64)> {
        PAPER_TABLE[..10]
            .iter()
            .enumerate()
            .map(|(i, r)| ((i + 1) as f64, r[col]))
            .collect()
    };
    let mk = |label: &str, points: Vec<(f64, f64)>, i: usize, dashed: bool| {
        let line = if dashed {
            Line::dashed(label, points, color(i))
        } else {
            Line::solid(label, points, color(i))
        };
        line.with_markers()
    };
    line_chart(
        &out_dir.join("astro_calibration_per_record.png"),
        &Chart {
            title: "Latitude / longitude error per record: Sextant vs paper 000",
            x_label: "record",
            y_label: "mean |error| [m]",
            log_x: false,
            log_y: true,
            lines: &[
                mk(
                    "uncalibrated, latitude",
                    per(|r| r.uncalibrated.lat_error_mean_abs_m),
                    0,
                    false,
                ),
                mk(
                    "uncalibrated, longitude",
                    per(|r| r.uncalibrated.lon_error_mean_abs_m),
                    1,
                    false,
                ),
                mk(
                    "3-stage, latitude",
                    per(|r| r.three_stage.result.lat_error_mean_abs_m),
                    2,
                    false,
                ),
                mk(
                    "3-stage, longitude",
                    per(|r| r.three_stage.result.lon_error_mean_abs_m),
                    3,
                    false,
                ),
                mk(
                    "3-stage, Earth rotation only (paper), latitude",
                    per(|r| {
                        r.three_stage_by_celestial_model
                            .gmst_only
                            .result
                            .lat_error_mean_abs_m
                    }),
                    4,
                    false,
                ),
                mk("paper, calibrated latitude", paper(3), 2, true),
                mk("paper, calibrated longitude", paper(7), 3, true),
                mk("paper, uncalibrated latitude", paper(1), 0, true),
            ],
        },
    )?;
    Ok(())
}

/// The table: per record, latitude and longitude errors without and with the 3-stage
/// calibration (degrees and metres), the means, the paper's means beside them, and the other
/// estimators.
pub fn table(summary: &Summary) -> String {
    let f = |x: f64, d: usize| fmt_f64(x, d, false);
    let mut out = String::new();
    out.push_str(
        "Paper 000 — astro position fix errors, mean |error| over each record after the 600 s window\n",
    );
    out.push_str(&super::world_line(&summary.world_effects));
    out.push('\n');
    out.push_str(&format!(
        "{:>6} | {:>8} {:>8} | {:>8} {:>6} | {:>8} {:>8} | {:>8} {:>6} | {:>6} {:>6}\n",
        "record",
        "Δφ [°]",
        "Δφ [m]",
        "Δφc [°]",
        "Δφc[m]",
        "Δλ [°]",
        "Δλ [m]",
        "Δλc [°]",
        "Δλc[m]",
        "LS φ[m]",
        "LS λ[m]"
    ));
    let row = |label: String, uncal: &MeanErrors, three: &MeanErrors, ls: &MeanErrors| {
        format!(
            "{:>6} | {:>8} {:>8} | {:>8} {:>6} | {:>8} {:>8} | {:>8} {:>6} | {:>6} {:>6}\n",
            label,
            f(uncal.lat_error_mean_abs_deg, 4),
            f(uncal.lat_error_mean_abs_m, 0),
            f(three.lat_error_mean_abs_deg, 5),
            f(three.lat_error_mean_abs_m, 0),
            f(uncal.lon_error_mean_abs_deg, 4),
            f(uncal.lon_error_mean_abs_m, 0),
            f(three.lon_error_mean_abs_deg, 5),
            f(three.lon_error_mean_abs_m, 0),
            f(ls.lat_error_mean_abs_m, 0),
            f(ls.lon_error_mean_abs_m, 0),
        )
    };
    for r in &summary.records {
        out.push_str(&row(
            r.record.to_string(),
            &(&r.uncalibrated).into(),
            &(&r.three_stage.result).into(),
            &(&r.least_squares_window.result).into(),
        ));
    }
    let m = &summary.mean;
    out.push_str(&row(
        "mean".into(),
        &m.uncalibrated,
        &m.three_stage,
        &m.least_squares_window,
    ));
    let p = summary.paper_mean.as_ref();
    let pf = |x: fn(&PaperRow) -> f64, d: usize| fmt_opt(p.map(x), d, false);
    out.push_str(&format!(
        "{:>6} | {:>8} {:>8} | {:>8} {:>6} | {:>8} {:>8} | {:>8} {:>6} |\n",
        "paper",
        pf(|p| p.lat_error_deg, 4),
        pf(|p| p.lat_error_m, 0),
        pf(|p| p.lat_error_calibrated_deg, 4),
        pf(|p| p.lat_error_calibrated_m, 0),
        pf(|p| p.lon_error_deg, 4),
        pf(|p| p.lon_error_m, 0),
        pf(|p| p.lon_error_calibrated_deg, 4),
        pf(|p| p.lon_error_calibrated_m, 0),
    ));
    out.push_str("\nMean horizontal error of the mean fix [m] by method (celestial model):\n");
    for (label, e) in [
        ("uncalibrated (full)", &m.uncalibrated),
        ("3-stage (full IAU 2006/2000A)", &m.three_stage),
        (
            "3-stage (Earth rotation only, GMST: the paper)",
            &m.three_stage_gmst_only,
        ),
        (
            "3-stage (Earth rotation only, ERA)",
            &m.three_stage_era_only,
        ),
        (
            "stage 3 only, from the identity (full)",
            &m.descent_from_identity,
        ),
        (
            "least squares, 600 s window (full)",
            &m.least_squares_window,
        ),
        (
            "least squares, all samples (full)",
            &m.least_squares_all_samples,
        ),
    ] {
        out.push_str(&format!(
            "  {:<48} mean fix {:>9} m   RMS single fix {:>9} m\n",
            label,
            f(e.mean_fix_error_m, 1),
            f(e.horizontal_error_rms_m, 1),
        ));
    }
    let recs = &summary.records;
    if recs.iter().any(|r| r.online_filter.is_some()) {
        out.push_str(
            "\nOnline boresight estimate of the Kalman filter vs the calibration tool (3-stage), per record [°]:\n",
        );
        out.push_str(&format!(
            "{:>6} | {:>8} {:>8} {:>8} | {:>8} {:>8} {:>8} | {:>8} {:>8} {:>8} | {:>8} {:>8}\n",
            "record",
            "κ1 filt",
            "κ2 filt",
            "κ3 filt",
            "σ1",
            "σ2",
            "σ3",
            "κ1 tool",
            "κ2 tool",
            "κ3 tool",
            "tilt Δx",
            "tilt Δy"
        ));
        for r in recs {
            let o = r.online_filter.as_ref();
            let at =
                |v: Option<&[f64]>, j: usize| fmt_opt(v.and_then(|v| v.get(j).copied()), 4, false);
            let kappa = o.map(|o| o.kappa_deg.as_slice());
            let sigma = o.map(|o| o.kappa_sigma_deg.as_slice());
            let tool = Some(&r.three_stage.result.kappa_deg[..]);
            let tilt = o.map(|o| &o.mounting_tilt_minus_three_stage_deg[..]);
            out.push_str(&format!(
                "{:>6} | {:>8} {:>8} {:>8} | {:>8} {:>8} {:>8} | {:>8} {:>8} {:>8} | {:>8} {:>8}\n",
                r.record,
                at(kappa, 0),
                at(kappa, 1),
                at(kappa, 2),
                at(sigma, 0),
                at(sigma, 1),
                at(sigma, 2),
                at(tool, 0),
                at(tool, 1),
                at(tool, 2),
                at(tilt, 0),
                at(tilt, 1),
            ));
        }
        let kt = &recs[0].kappa_true_deg;
        out.push_str(&format!(
            "  true κ [°]: {} {} {}\n",
            f(kt[0], 4),
            f(kt[1], 4),
            f(kt[2], 4),
        ));
        let online = summary.online_filter.figures.as_ref();
        for (label, c) in [
            ("κ1", online.map(|o| o.kappa1_consistency)),
            ("κ2", online.map(|o| o.kappa2_consistency)),
            ("κ3", online.map(|o| o.kappa3_consistency)),
            ("κ2+κ3", online.map(|o| o.kappa_tilt_consistency)),
        ] {
            out.push_str(&format!(
                "  filter {:<6} RMS error / RMS σ over {:>2} errors: {} (χ² 95 % band {} – {})\n",
                label,
                fmt_opt(c.map(|c| f64::from(c.samples)), 0, false),
                fmt_opt(c.map(|c| c.error_rms_over_sigma_rms), 2, false),
                fmt_opt(c.map(|c| c.band95[0]), 2, false),
                fmt_opt(c.map(|c| c.band95[1]), 2, false),
            ));
        }
    }
    out.push_str(&format!(
        "  improvement uncalibrated / 3-stage: {}×\n",
        f(summary.improvement_factor_three_stage, 1)
    ));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reduced run (3 records of 2 400 s, online filter over 400 s): the calibration must cut
    /// the error at least 10×.
    /// Physics: uncalibrated, the error is the mounting tilt R·|(κ2, κ3)| ≈ 6.37e6 · 0.57° ≈
    /// 63 km; calibrated, what remains is the change of the IMU's vertical after the window
    /// (bias random walk 20 µg/√h over ≈ 0.5 h ≈ 14 µg ≈ 90 m, temperature 10 µg/°C · 0.25 °C
    /// ≈ 2.5 µg ≈ 16 m) plus averaged noise: hundreds of metres at most, ≫ 10× below.
    #[test]
    fn reduced_run_calibration_is_ten_times_better() {
        let dir = super::super::test_dir("astro-calibration");
        let settings = Settings {
            records: 3,
            duration_s: 2400.0,
            window_s: 600.0,
            online_s: 400.0,
        };
        let t0 = std::time::Instant::now();
        let s = AstroCalibration::run_with(&settings, &dir, false).expect("run");
        let d = s.mean.descent_from_identity.mean_fix_error_m;
        // The descent alone stops just under the 1852 m threshold in the window; after it the
        // error is that plus the vertical's drift: between a few hundred m and ≈ 2.5 km.
        assert!(d > 300.0 && d < 2500.0, "descent from identity {d} m");
        eprintln!("{}\n{:.1} s", table(&s), t0.elapsed().as_secs_f64());
        let uncal = s.mean.uncalibrated.mean_fix_error_m;
        let cal = s.mean.three_stage.mean_fix_error_m;
        let ls = s.mean.least_squares_window.mean_fix_error_m;
        assert!(
            uncal > 50_000.0 && uncal < 80_000.0,
            "uncalibrated {uncal} m"
        );
        assert!(cal * 10.0 < uncal, "3-stage {cal} m vs {uncal} m");
        assert!(ls * 10.0 < uncal, "LS {ls} m vs {uncal} m");
        assert_eq!(s.records.len(), 3);
        for r in &s.records {
            for (key, ls) in [
                ("least_squares_window", &r.least_squares_window),
                ("least_squares_all_samples", &r.least_squares_all_samples),
            ] {
                let it = ls.estimator.iterations;
                assert!(
                    it < 20,
                    "{key}: Gauss–Newton did not converge ({it} iterations)"
                );
            }
        }
        // The filter's mounting tilt agrees with the tool's: both see the same stars and the
        // same accelerometer-bias tilt of the vertical; bound 0.01° (the filter's own σ).
        for r in &s.records {
            let online = r.online_filter.as_ref().expect("online");
            for d in online.mounting_tilt_minus_three_stage_deg {
                assert!(d.abs() < 0.01, "filter − tool tilt {d}°");
            }
        }
        assert!(dir.join("summary.json").exists());
        assert!(dir.join("astro_calibration_per_record.png").exists());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
