//! Experiment `hybrid-berlin`: **real GNSS and odometer in an urban canyon, simulated IMU** —
//! the smartLoc dataset's Berlin Potsdamer Platz drive (TU Chemnitz, CC BY-SA 4.0; a 60 s
//! slice is in `tests/data/smartloc-berlin/` and embedded in the binary, the whole 283 s drive
//! is read with `sextant experiment hybrid-berlin --data DIR`).
//!
//! What is real: every GPS pseudorange (atmosphere and satellite clock removed by the data's
//! authors, satellite positions given) with its multipath, non-line-of-sight and diffraction
//! errors; the wheel odometer's speed; and the reference, a NovAtel GNSS/INS trajectory.
//! What is simulated: a tactical-grade IMU (`config/sensors/tactical.toml`) flown along the
//! `reference` trajectory kind of the simulator (a C² spline through the NovAtel positions,
//! standing where the real odometer reads zero; `sextant_drivers_sim::reference_trajectory`),
//! and one star-tracker sample for the attitude at the start. GLONASS is left out: the
//! navigator's clock model has one receiver clock bias, and GLONASS pseudoranges carry another
//! (the inter-system bias), so GPS only.
//!
//! Initialisation: the car moves at t = 0, so the navigator starts with its alignment in
//! motion (`fusion::navigator`, motion_align): the attitude from the one simulated star-tracker
//! sample (standing in for a transfer alignment from the reference INS, whose attitude the
//! data do not carry), the position and velocity from the reference's first epoch with an
//! assumed reference accuracy of `init_position_sigma_m` / `init_velocity_sigma_m_s` (the
//! pseudoranges have no Doppler, so no GNSS velocity exists). After that only the real
//! pseudoranges (tight coupling) or Sextant's own least-squares fix of them (loose) and the
//! real odometer speed aid the simulated IMU.
//!
//! Runs: tight coupling without any gate (every pseudorange fused), with the navigator's χ²
//! innovation gate (per pseudorange, 99.9 %), and with the gate after a receiver-style
//! snapshot fault detection and exclusion (FDE: the epoch's weighted least-squares χ² test at
//! 99.9 %, then Baarda's w-test excluding the worst satellite, repeated while at least six
//! satellites remain); loose coupling through the least-squares fix of all satellites with the
//! gate; the gated tight and loose runs again with the time-correlated GNSS error model
//! (`fusion::ekf::correlated`, the urban class's correlation time
//! [`URBAN_ERROR_CORRELATION_TIME_S`]: each pseudorange or fix fused with the variance
//! inflation that makes a Gauss–Markov error consistent with the filter's averaging); and the
//! IMU with the odometer alone (no GNSS after the start), the dead-reckoning
//! baseline — optimistic here, since the simulated IMU moves exactly along the reference. Figures against the NovAtel reference at its epochs after `converge_s`: horizontal
//! error p50/p95/max, vertical RMS, position NEES (3 dof) and its share above χ²₃(0.99), the
//! GNSS NIS per degree of freedom; beside them the epoch-by-epoch least-squares fixes (all
//! satellites, and after FDE) and the spline's own distance from the reference.

use super::consistency::filter_config;
use super::plot::{Chart, Line, color, line_chart};
use super::{ExperimentError, fmt_f64, measurement, progress_bar, scenario_file};
use crate::smartloc::{self, DriveSamples, SmartLoc, StartFix};
use drivers_sim::offline::{OfflineSim, run_navigator};
use drivers_sim::reference_trajectory::ReferenceTrajectory;
use drivers_sim::scenario::Scenario;
use fusion::earth::{self, WGS84};
use fusion::gnss_ls::{self, LsSettings, Observations};
use fusion::navigator::{Navigator, NavigatorConfig};
use msgs::{Channel, GnssSample, GnssSatellite, OdometerSample, Record};
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

/// The shipped slice (150–210 s of the drive), CC BY-SA 4.0: `tests/data/smartloc-berlin/`.
const SLICE_INPUT_GZ: &[u8] = include_bytes!(
    "../../../tests/data/smartloc-berlin/Berlin_Potsdamer_Platz_Input_150-210s.txt.gz"
);
/// Its reference trajectory.
const SLICE_GT_GZ: &[u8] =
    include_bytes!("../../../tests/data/smartloc-berlin/Berlin_Potsdamer_Platz_GT_150-210s.txt.gz");
/// File names of the whole drive in a `--data` directory.
const INPUT_NAME: &str = "Berlin_Potsdamer_Platz_Input.txt.gz";
const GT_NAME: &str = "Berlin_Potsdamer_Platz_GT.txt.gz";
/// χ²₃ 99 % quantile.
const CHI2_3_99: f64 = 11.344_866_730_144_373;
/// Probability of the FDE's global test and w-test.
const FDE_PROBABILITY: f64 = 0.999;

/// The directory `sextant experiment hybrid-berlin --data DIR` names (set once).
static DATA_DIR: OnceLock<PathBuf> = OnceLock::new();

/// Read the whole drive from `dir` (its `Berlin_Potsdamer_Platz_Input.txt.gz` and
/// `…_GT.txt.gz`) instead of the shipped slice. False when already set.
pub fn use_data_dir(dir: PathBuf) -> bool {
    DATA_DIR.set(dir).is_ok()
}

/// Settings of the experiment.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Directory of the whole drive's files; None: the one given to [`use_data_dir`], else the
    /// shipped slice.
    pub data_dir: Option<PathBuf>,
    /// Length of the run from the reference's first epoch, s; None: all of the data.
    pub duration_s: Option<f64>,
    /// Time after which the statistics start, s.
    pub converge_s: f64,
    /// Scenario file name in `config/scenarios`.
    pub scenario: String,
    /// Assumed 1-σ accuracy of the reference position the navigation starts from, m.
    pub init_position_sigma_m: f64,
    /// Assumed 1-σ accuracy of the reference velocity the navigation starts from, m/s.
    pub init_velocity_sigma_m_s: f64,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            data_dir: None,
            duration_s: None,
            converge_s: 10.0,
            scenario: "berlin_reference.toml".into(),
            init_position_sigma_m: 0.5,
            init_velocity_sigma_m_s: 0.1,
        }
    }
}

/// Error statistics of one position series against the reference.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct Errors {
    /// Epochs in the statistics.
    pub epochs: usize,
    /// Horizontal error median, m.
    #[serde(deserialize_with = "super::nan_if_null")]
    pub horizontal_p50_m: f64,
    /// Horizontal error 95th percentile, m.
    #[serde(deserialize_with = "super::nan_if_null")]
    pub horizontal_p95_m: f64,
    /// Largest horizontal error, m.
    #[serde(deserialize_with = "super::nan_if_null")]
    pub horizontal_max_m: f64,
    /// Vertical error RMS, m.
    #[serde(deserialize_with = "super::nan_if_null")]
    pub vertical_rms_m: f64,
}

/// One filter run.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Run {
    /// What the run fuses and how (`tight, no gate`, …).
    pub name: String,
    /// Errors against the reference after `converge_s`.
    pub errors: Errors,
    /// Mean position NEES (3 dof) against the reference.
    #[serde(deserialize_with = "super::nan_if_null")]
    pub position_nees_mean: f64,
    /// Share of epochs with position NEES above χ²₃(0.99).
    #[serde(deserialize_with = "super::nan_if_null")]
    pub position_nees_above_99: f64,
    /// Share of epochs whose horizontal error is inside 3 of the filter's own horizontal σ
    /// (the larger semi-axis).
    #[serde(deserialize_with = "super::nan_if_null")]
    pub inside_3_sigma: f64,
    /// GNSS NIS per degree of freedom over the run.
    #[serde(deserialize_with = "super::nan_if_null")]
    pub gnss_nis_per_dof: f64,
    /// GNSS measurements rejected by the χ² gate.
    pub gnss_rejected: u64,
    /// Odometer NIS per degree of freedom.
    #[serde(deserialize_with = "super::nan_if_null")]
    pub odometer_nis_per_dof: f64,
    /// Time from the first epoch to the first navigating solution, s.
    #[serde(deserialize_with = "super::nan_if_null")]
    pub first_solution_s: f64,
}

/// Figures of the experiment.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Summary {
    /// What is real and what is simulated.
    pub data: String,
    /// Where the data came from (the shipped slice or the files read).
    pub source: String,
    /// Run length, s.
    pub duration_s: f64,
    /// Statistics start, s.
    pub converge_s: f64,
    /// IMU grade and rate.
    pub imu: String,
    /// The simulated IMU's world effects that were on (truth only; empty: the matched world).
    #[serde(default)]
    pub world_effects: Vec<String>,
    /// GNSS epochs in the run.
    pub epochs: usize,
    /// Mean GPS pseudoranges per epoch.
    pub mean_gps_satellites: f64,
    /// Epochs with fewer than four GPS pseudoranges (no least-squares fix).
    pub epochs_without_fix: usize,
    /// Satellites the snapshot FDE excluded over the run.
    pub fde_excluded: usize,
    /// Standstill intervals taken from the odometer, s.
    pub standstill_s: Vec<[f64; 2]>,
    /// Reference points left out of the spline as outliers (glitches of the reference).
    pub reference_outliers: usize,
    /// The spline (the IMU's truth) against the reference points: horizontal p50/p95/max, m.
    pub spline_vs_reference_m: [f64; 3],
    /// Least-squares fixes of all GPS satellites, epoch by epoch.
    pub wls_all: Errors,
    /// Least-squares fixes after the snapshot FDE.
    pub wls_fde: Errors,
    /// The filter runs.
    pub runs: Vec<Run>,
}

experiment!(
    /// Experiment `hybrid-berlin`; see the module documentation.
    HybridBerlin,
    "hybrid-berlin",
    "Real GPS pseudoranges and odometer of an urban-canyon drive (smartLoc, Berlin Potsdamer Platz) with a simulated tactical IMU on a spline through the NovAtel reference: tight and loose coupling, with and without χ² gating and satellite exclusion"
);

/// The drive's data with times from the reference's first epoch.
struct Drive {
    data: SmartLoc,
    source: String,
}

fn read_gz(path: &Path) -> Result<String, ExperimentError> {
    let raw = std::fs::read(path).map_err(|source| ExperimentError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    sextant_rinex::decode_text(&raw, true).map_err(|source| ExperimentError::Io {
        path: path.to_path_buf(),
        source,
    })
}

fn load(settings: &Settings) -> Result<Drive, ExperimentError> {
    let dir = settings.data_dir.as_ref().or(DATA_DIR.get());
    let (input, gt, source) = match dir {
        Some(d) => (
            read_gz(&d.join(INPUT_NAME))?,
            read_gz(&d.join(GT_NAME))?,
            format!("{} ({INPUT_NAME}, {GT_NAME})", d.display()),
        ),
        None => {
            let text = |raw: &[u8], name: &str| {
                sextant_rinex::decode_text(raw, true)
                    .map_err(|e| measurement(format!("{name}: {e}")))
            };
            (
                text(SLICE_INPUT_GZ, "shipped input slice")?,
                text(SLICE_GT_GZ, "shipped reference slice")?,
                "shipped slice tests/data/smartloc-berlin/ (150–210 s of the drive)".into(),
            )
        }
    };
    let mut data = smartloc::parse(&input).map_err(|e| measurement(format!("input: {e}")))?;
    data.reference = smartloc::parse(&gt)
        .map_err(|e| measurement(format!("reference: {e}")))?
        .reference;
    data.from_reference_start()
        .ok_or_else(|| measurement("the reference file has no point3 line"))?;
    Ok(Drive { data, source })
}

/// Snapshot fault detection and exclusion ([`fusion::gnss_ls::solve_excluding_faults`] at
/// [`FDE_PROBABILITY`], while at least six satellites remain): the excluded satellites are
/// removed from `s`. Returns the excluded count.
fn exclude_faults(s: &mut GnssSample) -> usize {
    let Ok(obs) = Observations::from_sample(s) else {
        return 0;
    };
    let Ok(screened) =
        gnss_ls::solve_excluding_faults(&obs, &LsSettings::default(), FDE_PROBABILITY, 5)
    else {
        return 0;
    };
    let n = s.n_satellites as usize;
    let kept: Vec<GnssSatellite> = s.satellites[..n]
        .iter()
        .filter(|sat| screened.kept.as_slice().iter().any(|o| o.prn == sat.prn))
        .copied()
        .collect();
    s.satellites[..n].fill(GnssSatellite::default());
    s.satellites[..kept.len()].copy_from_slice(&kept);
    s.n_satellites = kept.len() as u32;
    screened.excluded
}

/// Horizontal error of `p` against `reference` (north/east at the reference), m, and up.
fn ne_up(p: &Vector3<f64>, reference: &Vector3<f64>) -> (f64, f64) {
    let g = earth::ecef_to_geodetic(&WGS84, reference);
    let ned = earth::c_e_n(g.lat_rad, g.lon_rad).transpose() * (p - reference);
    (ned.x.hypot(ned.y), -ned.z)
}

/// Nearest-rank percentile of sorted values.
fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((p * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1]
}

fn errors(hv: &[(f64, f64)]) -> Errors {
    let mut h: Vec<f64> = hv.iter().map(|x| x.0).collect();
    h.sort_by(f64::total_cmp);
    let n = hv.len().max(1) as f64;
    Errors {
        epochs: hv.len(),
        horizontal_p50_m: percentile(&h, 0.5),
        horizontal_p95_m: percentile(&h, 0.95),
        horizontal_max_m: h.last().copied().unwrap_or(f64::NAN),
        vertical_rms_m: if hv.is_empty() {
            f64::NAN
        } else {
            (hv.iter().map(|x| x.1 * x.1).sum::<f64>() / n).sqrt()
        },
    }
}

/// One filter configuration of the experiment.
#[derive(Debug, Clone, Copy)]
struct Case {
    name: &'static str,
    /// Any GNSS after the start (false: IMU and odometer only).
    gnss: bool,
    tight: bool,
    gate: bool,
    fde: bool,
    /// `gnss.error_correlation_time_s` of the run: 0 fuses the pseudoranges (or the fix) as
    /// white noise, > 0 with the time-correlated error model (`fusion::ekf::correlated`).
    correlation_time_s: f64,
}

/// Correlation time of the pseudorange errors of a receiver driving in an urban canyon, s,
/// for the runs with the time-correlated error model: there code multipath and reflections
/// (non-line-of-sight) dominate the error, and the published bounds of a raw code multipath
/// Gauss–Markov correlation time are 10–900 s (Joerger & Pervan's error models for GNSS
/// integrity monitoring, NAVIGATION, Journal of the ION); the upper bound is taken, as
/// a longer correlation time is the conservative side (more inflation). An engineer's class
/// value, not fitted to this drive.
const URBAN_ERROR_CORRELATION_TIME_S: f64 = 900.0;

const CASES: [Case; 7] = [
    Case {
        name: "no GNSS (IMU + odo)",
        gnss: false,
        tight: false,
        gate: true,
        fde: false,
        correlation_time_s: 0.0,
    },
    Case {
        name: "tight, no gate",
        gnss: true,
        tight: true,
        gate: false,
        fde: false,
        correlation_time_s: 0.0,
    },
    Case {
        name: "tight, χ² gate",
        gnss: true,
        tight: true,
        gate: true,
        fde: false,
        correlation_time_s: 0.0,
    },
    Case {
        name: "tight, gate + FDE",
        gnss: true,
        tight: true,
        gate: true,
        fde: true,
        correlation_time_s: 0.0,
    },
    Case {
        name: "loose (WLS fix), gate",
        gnss: true,
        tight: false,
        gate: true,
        fde: false,
        correlation_time_s: 0.0,
    },
    Case {
        name: "tight, gate, GM error",
        gnss: true,
        tight: true,
        gate: true,
        fde: false,
        correlation_time_s: URBAN_ERROR_CORRELATION_TIME_S,
    },
    Case {
        name: "loose, gate, GM error",
        gnss: true,
        tight: false,
        gate: true,
        fde: false,
        correlation_time_s: URBAN_ERROR_CORRELATION_TIME_S,
    },
];

/// The filter configuration: the shipped tuning with the tactical grade's error model (from
/// the scenario's resolved IMU grade), the odometer's white noise from the data's own
/// variance, no baro; the star tracker only for the alignment in motion (the stream carries
/// one sample); the coupling and the gate of the case; the region's gravity class where the
/// scenario's world has a gravity field.
fn config(
    case: &Case,
    scn: &Scenario,
    odo_sigma_m_s: f64,
) -> Result<NavigatorConfig, ExperimentError> {
    let g = &scn.imu.gyro;
    let a = &scn.imu.accel;
    let f = toml::Value::Float;
    let mut o: Vec<(&str, toml::Value)> = vec![
        ("updates.baro", toml::Value::Boolean(false)),
        ("imu.gyro_bias_deg_h", f(g.bias_deg_h)),
        ("imu.arw_deg_sqrt_h", f(g.arw_deg_per_rt_h)),
        ("imu.gyro_bias_rw_deg_h_sqrt_h", f(g.bias_rw_deg_h_per_rt_h)),
        ("imu.gyro_scale_ppm", f(g.scale_factor_ppm)),
        ("imu.accel_bias_ug", f(a.bias_ug)),
        ("imu.vrw_ug_sqrt_hz", f(a.vrw_ug_per_rt_hz)),
        ("imu.accel_bias_rw_ug_sqrt_h", f(a.bias_rw_ug_per_rt_h)),
        ("imu.accel_scale_ppm", f(a.scale_factor_ppm)),
        (
            "imu.misalignment_arcsec",
            f(g.misalignment_arcsec.max(a.misalignment_arcsec)),
        ),
        ("aiding.odometer_sigma_m_s", f(odo_sigma_m_s)),
        ("gate_probability", f(if case.gate { 0.999 } else { 1.0 })),
    ];
    if case.correlation_time_s > 0.0 {
        o.push(("gnss.error_correlation_time_s", f(case.correlation_time_s)));
    }
    if case.tight {
        o.push(("gnss_mode", toml::Value::String("tight".into())));
    }
    // The simulated IMU moves in the world's gravity field.
    super::consistency::with_gravity_class(scn, filter_config(&o)?)
}

/// What one run produces for the plots: (t, horizontal error, 3·σ_h) at the reference epochs.
#[derive(Debug, Clone, Default)]
struct Series {
    points: Vec<(f64, f64, f64)>,
}

#[allow(clippy::too_many_arguments)]
fn one_run(
    case: &Case,
    settings: &Settings,
    scn: &Scenario,
    gnss: &[GnssSample],
    odometer: &[OdometerSample],
    reference: &[(f64, Vector3<f64>)],
    duration_s: f64,
    odo_sigma_m_s: f64,
) -> Result<(Run, Series), ExperimentError> {
    let cfg = config(case, scn, odo_sigma_m_s)?;
    let mut nav = Navigator::new(cfg).map_err(|e| measurement(format!("navigator: {e}")))?;
    let sim = OfflineSim::with_channels(scn, &[Channel::Imu, Channel::StarTracker, Channel::Truth]);
    let epoch = sim.epoch_ns();
    let end_ns = epoch + (duration_s * 1e9).round() as i64;
    // One star-tracker sample, the first: the attitude of the alignment in motion.
    let mut star_seen = false;
    let sim = sim.filter(move |r| match r {
        Record::StarTracker(_) => !std::mem::replace(&mut star_seen, true),
        _ => true,
    });
    let mut real: Vec<Record> = gnss
        .iter()
        .filter(|g| g.header.time_ns <= end_ns)
        .map(|g| Record::Gnss(Box::new(*g)))
        .chain(
            odometer
                .iter()
                .filter(|o| o.header.time_ns <= end_ns)
                .map(|o| Record::Odometer(*o)),
        )
        .collect();
    real.sort_by_key(|r| (r.time_ns(), r.channel()));
    let mut real = real.into_iter().peekable();
    let mut sim = sim.peekable();
    let stream = std::iter::from_fn(|| match (real.peek(), sim.peek()) {
        (Some(a), Some(b)) => {
            if (a.time_ns(), a.channel()) <= (b.time_ns(), b.channel()) {
                real.next()
            } else {
                sim.next()
            }
        }
        (Some(_), None) => real.next(),
        (None, _) => sim.next(),
    });
    // The estimate at every compared truth epoch: (t, position, covariance).
    let mut track: Vec<(f64, Vector3<f64>, Matrix3<f64>)> = Vec::new();
    let mut first_solution_s = f64::NAN;
    run_navigator(stream, epoch, &mut nav, |p| {
        if first_solution_s.is_nan() {
            first_solution_s = p.t_s;
        }
        track.push((p.t_s, p.pos_true_e_m - p.pos_err_e_m, p.pos_cov_e_m2));
    })
    .map_err(|e| measurement(format!("{}: {e}", case.name)))?;
    // Against the reference at its epochs: the estimate interpolated linearly between the
    // two compared epochs around (20 ms apart: the interpolation error a·dt²/8 ≤ 0.2 mm).
    let mut hv = Vec::new();
    let mut nees = Vec::new();
    let mut inside = 0usize;
    let mut series = Series::default();
    for &(t, r_ref) in reference {
        if t < settings.converge_s || t > duration_s {
            continue;
        }
        let i = track.partition_point(|x| x.0 < t);
        if i == 0 || i >= track.len() {
            continue;
        }
        let (a, b) = (&track[i - 1], &track[i]);
        let w = (t - a.0) / (b.0 - a.0);
        let est = a.1 + (b.1 - a.1) * w;
        let cov = if w < 0.5 { a.2 } else { b.2 };
        let (h, v) = ne_up(&est, &r_ref);
        hv.push((h, v));
        let e = est - r_ref;
        if let Some(inv) = cov.try_inverse() {
            nees.push((e.transpose() * inv * e)[(0, 0)]);
        }
        let g = earth::ecef_to_geodetic(&WGS84, &r_ref);
        let c_n_e = earth::c_e_n(g.lat_rad, g.lon_rad).transpose();
        let p_ned = c_n_e * cov * c_n_e.transpose();
        let ph = p_ned.fixed_view::<2, 2>(0, 0).into_owned();
        let sigma_major = ph.symmetric_eigenvalues().max().max(0.0).sqrt();
        if h <= 3.0 * sigma_major {
            inside += 1;
        }
        series.points.push((t, h, 3.0 * sigma_major));
    }
    let health = nav.health();
    let gh = health[msgs::SensorId::Gnss as usize];
    let oh = health[msgs::SensorId::Odometer as usize];
    let run = Run {
        name: case.name.into(),
        errors: errors(&hv),
        position_nees_mean: nees.iter().sum::<f64>() / nees.len().max(1) as f64,
        position_nees_above_99: nees.iter().filter(|&&x| x > CHI2_3_99).count() as f64
            / nees.len().max(1) as f64,
        inside_3_sigma: inside as f64 / hv.len().max(1) as f64,
        gnss_nis_per_dof: gh.nis_sum / gh.nis_dof_sum.max(1) as f64,
        gnss_rejected: gh.rejected_gate,
        odometer_nis_per_dof: oh.nis_sum / oh.nis_dof_sum.max(1) as f64,
        first_solution_s,
    };
    Ok((run, series))
}

/// The scenario: the shipped file with the spline through the reference as its trajectory.
fn scenario(
    settings: &Settings,
    spline: Arc<ReferenceTrajectory>,
    duration_s: f64,
) -> Result<Scenario, ExperimentError> {
    smartloc::drive_scenario(&scenario_file(&settings.scenario), spline, duration_s, None)
        .map_err(measurement)
}

/// Measure into `out_dir` (plots) and return the summary.
pub fn measure(
    settings: &Settings,
    out_dir: &Path,
    progress: bool,
) -> Result<Summary, ExperimentError> {
    let drive = load(settings)?;
    let data = &drive.data;
    let still = data.standstill_s();
    let points = data.reference_points();
    let spline = smartloc::reference_spline(data)
        .map_err(|e| measurement(format!("reference trajectory: {e}")))?;
    let end_s = spline.end_s();
    let duration_s = settings.duration_s.unwrap_or(end_s).min(end_s);
    if duration_s.is_nan() || duration_s <= settings.converge_s {
        return Err(measurement(format!(
            "duration {duration_s} s must exceed converge_s {} s",
            settings.converge_s
        )));
    }
    // The spline against the reference points it smooths.
    let mut dev: Vec<f64> = points
        .iter()
        .filter(|p| p.t_s <= duration_s)
        .map(|p| ne_up(&spline.position_ecef_m(p.t_s), &p.r_e_m).0)
        .collect();
    dev.sort_by(f64::total_cmp);
    let spline_vs_reference_m = [
        percentile(&dev, 0.5),
        percentile(&dev, 0.95),
        dev.last().copied().unwrap_or(f64::NAN),
    ];
    let spline = Arc::new(spline);
    let scn = scenario(settings, spline.clone(), duration_s)?;
    let epoch = scn.epoch_gps().ns;
    // The start: the reference's first epoch as the fix of the first sample (position and
    // velocity with the assumed reference accuracy): the alignment in motion's input.
    let start = StartFix {
        position_sigma_m: settings.init_position_sigma_m,
        velocity_sigma_m_s: settings.init_velocity_sigma_m_s,
        ..StartFix::of_scenario(&scn)
    };
    // GNSS samples: all satellites (with their fix for the loose run), as `sextant import
    // smartloc` writes them, and after FDE; the odometer.
    let DriveSamples {
        gnss: all,
        odometer,
        gps_pseudoranges: n_sats,
        epochs_without_fix: without_fix,
    } = smartloc::drive_samples(data, epoch, duration_s, &start).map_err(measurement)?;
    let mut excluded = 0usize;
    let mut fde: Vec<GnssSample> = data
        .epochs
        .iter()
        .filter(|e| e.t_ms as f64 * 1e-3 <= duration_s)
        .enumerate()
        .map(|(seq, e)| {
            let mut f = smartloc::gps_sample(e, epoch + e.t_ms * 1_000_000, seq as u64);
            excluded += exclude_faults(&mut f);
            if let Some(fix) = smartloc::wls(&f) {
                smartloc::set_fix(&mut f, &fix);
            }
            f
        })
        .collect();
    if let Some(first) = fde.first_mut() {
        start.apply(first);
    }
    let epochs = all.len();
    // The data's own odometer variance (one value throughout the smartLoc files).
    let odo_sigma_m_s = data
        .odometry
        .first()
        .map_or(0.05, |o| o.speed_variance_m2_s2.sqrt());
    let reference: Vec<(f64, Vector3<f64>)> = points.iter().map(|p| (p.t_s, p.r_e_m)).collect();
    let wls_errors = |samples: &[GnssSample]| {
        let hv: Vec<(f64, f64)> = samples
            .iter()
            .skip(1) // the first carries the reference itself
            .filter(|s| s.fix_valid == 1)
            .filter_map(|s| {
                let t = (s.header.time_ns - epoch) as f64 * 1e-9;
                let r = reference.iter().find(|(tr, _)| (tr - t).abs() < 5e-4)?.1;
                (t >= settings.converge_s).then(|| ne_up(&Vector3::from(s.pos_ecef_m), &r))
            })
            .collect();
        errors(&hv)
    };
    let wls_all = wls_errors(&all);
    let wls_fde = wls_errors(&fde);

    let pb = progress_bar(progress, CASES.len() as u64, "hybrid-berlin runs");
    let results: Vec<Result<(Run, Series), ExperimentError>> = CASES
        .par_iter()
        .map(|case| {
            let gnss = match (case.gnss, case.fde) {
                // Only the start's sample (the reference), for the alignment in motion.
                (false, _) => &all[..1],
                (true, true) => &fde[..],
                (true, false) => &all[..],
            };
            let r = one_run(
                case,
                settings,
                &scn,
                gnss,
                &odometer,
                &reference,
                duration_s,
                odo_sigma_m_s,
            );
            pb.inc(1);
            r
        })
        .collect();
    pb.finish_and_clear();
    let mut runs = Vec::new();
    let mut series = Vec::new();
    for r in results {
        let (run, s) = r?;
        runs.push(run);
        series.push(s);
    }
    let wls_series: Vec<(f64, f64)> = all
        .iter()
        .skip(1)
        .filter(|s| s.fix_valid == 1)
        .filter_map(|s| {
            let t = (s.header.time_ns - epoch) as f64 * 1e-9;
            let r = reference.iter().find(|(tr, _)| (tr - t).abs() < 5e-4)?.1;
            Some((t, ne_up(&Vector3::from(s.pos_ecef_m), &r).0))
        })
        .collect();
    plots(out_dir, &runs, &series, &wls_series)?;
    Ok(Summary {
        data: "REAL GPS pseudoranges and REAL odometer (smartLoc, Berlin Potsdamer Platz urban \
               canyon) with a SIMULATED tactical IMU on a spline through the NovAtel reference; \
               errors against that reference"
            .into(),
        source: drive.source,
        duration_s,
        converge_s: settings.converge_s,
        imu: format!("{} at {} Hz", scn.spec.imu.grade, scn.spec.imu.rate_hz),
        world_effects: super::world_effects(&scn),
        epochs,
        mean_gps_satellites: n_sats as f64 / epochs.max(1) as f64,
        epochs_without_fix: without_fix,
        fde_excluded: excluded,
        standstill_s: still,
        reference_outliers: spline.rejected_s().len(),
        spline_vs_reference_m,
        wls_all,
        wls_fde,
        runs,
    })
}

fn plots(
    out_dir: &Path,
    runs: &[Run],
    series: &[Series],
    wls: &[(f64, f64)],
) -> Result<(), ExperimentError> {
    let mut lines: Vec<Line> = runs
        .iter()
        .zip(series)
        .enumerate()
        .map(|(i, (r, s))| {
            Line::solid(
                r.name.clone(),
                s.points.iter().map(|p| (p.0, p.1)).collect(),
                color(i),
            )
        })
        .collect();
    lines.push(Line::dashed("WLS fix (all GPS)", wls.to_vec(), color(runs.len())).with_markers());
    line_chart(
        &out_dir.join("horizontal_error.png"),
        &Chart {
            title: "hybrid-berlin: horizontal error against the NovAtel reference (real GPS + \
                    odometer, simulated IMU)",
            x_label: "time since the reference's first epoch, s",
            y_label: "horizontal error, m (log scale)",
            log_x: false,
            log_y: true,
            lines: &lines,
        },
    )?;
    // The gated tight run against its own 3σ.
    if let Some((r, s)) = runs
        .iter()
        .zip(series)
        .find(|(r, _)| r.name == CASES[2].name)
    {
        let lines = vec![
            Line::solid(
                format!("{} error", r.name),
                s.points.iter().map(|p| (p.0, p.1)).collect(),
                color(1),
            ),
            Line::dashed(
                "3σ (horizontal major semi-axis)",
                s.points.iter().map(|p| (p.0, p.2)).collect(),
                color(3),
            ),
        ];
        line_chart(
            &out_dir.join("error_vs_3sigma.png"),
            &Chart::linear(
                "hybrid-berlin: tight coupling with the χ² gate, error and its own 3σ",
                "time since the reference's first epoch, s",
                "m",
                &lines,
            ),
        )?;
    }
    Ok(())
}

/// The summary as a table.
pub fn table(s: &Summary) -> String {
    let f2 = |x: f64| fmt_f64(x, 2, false);
    let mut t = format!(
        "hybrid-berlin: {}\ndata: {}\n{} s from the reference's first epoch, statistics after \
         {} s; IMU {}; {} GPS epochs, {:.1} GPS pseudoranges per epoch, {} without a fix; \
         FDE excluded {}; standing still (odometer zero) {} s\nspline (IMU truth) vs \
         reference, horizontal: p50 {} m, p95 {} m, max {} m ({} reference points left out \
         as outliers)\n",
        s.data,
        s.source,
        fmt_f64(s.duration_s, 1, false),
        fmt_f64(s.converge_s, 0, false),
        s.imu,
        s.epochs,
        s.mean_gps_satellites,
        s.epochs_without_fix,
        s.fde_excluded,
        s.standstill_s
            .iter()
            .map(|w| format!("{:.1}–{:.1}", w[0], w[1]))
            .collect::<Vec<_>>()
            .join(", "),
        f2(s.spline_vs_reference_m[0]),
        f2(s.spline_vs_reference_m[1]),
        f2(s.spline_vs_reference_m[2]),
        s.reference_outliers,
    );
    t += &format!("the IMU: {}\n", super::world_line(&s.world_effects));
    t += "solution                H p50   H p95   H max   V RMS   NEES mean  >χ²99  in 3σ  \
          GNSS NIS/dof  rejected  odo NIS/dof\n";
    for (name, e) in [
        ("WLS fix, all GPS", &s.wls_all),
        ("WLS fix after FDE", &s.wls_fde),
    ] {
        let _ = writeln!(
            t,
            "{name:<22} {:>6} {:>7} {:>7} {:>7}",
            f2(e.horizontal_p50_m),
            f2(e.horizontal_p95_m),
            f2(e.horizontal_max_m),
            f2(e.vertical_rms_m)
        );
    }
    for r in &s.runs {
        let e = &r.errors;
        let _ = writeln!(
            t,
            "{:<22} {:>6} {:>7} {:>7} {:>7} {:>10} {:>5.1}% {:>5.1}% {:>13} {:>9} {:>12}",
            r.name,
            f2(e.horizontal_p50_m),
            f2(e.horizontal_p95_m),
            f2(e.horizontal_max_m),
            f2(e.vertical_rms_m),
            f2(r.position_nees_mean),
            100.0 * r.position_nees_above_99,
            100.0 * r.inside_3_sigma,
            f2(r.gnss_nis_per_dof),
            r.gnss_rejected,
            f2(r.odometer_nis_per_dof),
        );
    }
    t += "(errors in m against the NovAtel reference at its epochs; NEES: 3-D position, 3 for a \
          consistent filter; in 3σ: share of epochs whose horizontal error is inside 3 of the \
          filter's own horizontal σ)\n";
    t
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiments::test_dir;
    use crate::smartloc::{SYSTEM_GPS, sagnac};

    /// Median over the slice's epochs of the spread (median absolute deviation) of
    /// `ρ − |s − r_ref|` over the GPS satellites above 30° elevation, at the reference
    /// position: the common clock bias drops out, what is left is the pseudoranges' error
    /// plus any error of the satellite positions' convention.
    fn residual_spread_m(rotate: bool) -> f64 {
        let drive = load(&Settings::default()).expect("slice");
        let mut mads = Vec::new();
        for e in &drive.data.epochs {
            let Some(r) = drive.data.reference.iter().find(|r| r.t_ms == e.t_ms) else {
                continue;
            };
            let r = Vector3::from(r.r_e_m);
            let mut res: Vec<f64> = e
                .pseudoranges
                .iter()
                .filter(|p| p.system == SYSTEM_GPS && p.elevation_deg > 30.0)
                .map(|p| {
                    let s = if rotate {
                        sagnac(p.sat_pos_ecef_m, p.pseudorange_m)
                    } else {
                        p.sat_pos_ecef_m
                    };
                    p.pseudorange_m - (Vector3::from(s) - r).norm()
                })
                .collect();
            if res.len() < 3 {
                continue;
            }
            res.sort_by(f64::total_cmp);
            let med = res[res.len() / 2];
            let mut dev: Vec<f64> = res.iter().map(|x| (x - med).abs()).collect();
            dev.sort_by(f64::total_cmp);
            mads.push(dev[dev.len() / 2]);
        }
        mads.sort_by(f64::total_cmp);
        percentile(&mads, 0.5)
    }

    /// The live bench's filter (`config/hybrid_berlin_filter.toml`, what `sextant run --config
    /// config/hybrid_berlin.toml` fuses the played-in real samples with) is the configuration
    /// of this experiment's "tight, χ² gate" run, so the live and the offline figures compare.
    #[test]
    fn the_live_bench_filter_is_the_gated_tight_run() {
        let settings = Settings::default();
        let drive = load(&settings).expect("slice");
        let spline = Arc::new(smartloc::reference_spline(&drive.data).expect("spline"));
        let end_s = spline.end_s();
        let scn = scenario(&settings, spline, end_s).expect("scenario");
        let odo_sigma_m_s = drive.data.odometry[0].speed_variance_m2_s2.sqrt();
        let offline = config(&CASES[2], &scn, odo_sigma_m_s).expect("config");
        let path =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/hybrid_berlin_filter.toml");
        let live = crate::config::load_navigator_config(&path).expect("live filter");
        assert_eq!(live, offline);
    }

    /// The smartLoc satellite positions are in the ECEF frame of transmission: rotated into
    /// the frame of reception the high satellites' ranges agree to a few metres at the
    /// reference (measured 5.5 m median spread), unrotated they scatter by the Sagnac term's
    /// spread between satellites (up to ω_e·ρ/c·|s| ≈ 35 m; measured 15.9 m).
    #[test]
    fn sagnac_rotation_is_needed() {
        let (with, without) = (residual_spread_m(true), residual_spread_m(false));
        eprintln!(
            "pseudorange spread at the reference: rotated {with:.2} m, as given {without:.2} m"
        );
        assert!(
            2.0 * with < without,
            "rotated {with} m, as given {without} m"
        );
    }

    /// The shipped slice end to end (≈ 2 s in release). Bounds:
    ///
    /// * the spline the IMU flies is within 10 cm of 95 % of the reference points (the rest
    ///   holds the reference's glitches, which it leaves out, e.g. one point 0.39 m off the
    ///   track in the slice): the
    ///   path spline passes through nodes at most 0.5 m apart, off the points between them by
    ///   the interpolation error h²·κ/8 ≤ 1.6 mm on the drive's ≥ 20 m radii plus the
    ///   reference's own centimetre jitter, which it smooths;
    /// * every run navigates from the first epoch (alignment in motion at t = 0);
    /// * with the χ² gate (tight, tight + FDE, loose), the horizontal error's 95th percentile is
    ///   below the least-squares fixes' of the same pseudoranges: between two pseudorange epochs
    ///   the IMU and odometer carry the position to centimetres (0.2–0.3 s), so the filter's
    ///   estimate is a weighted average over many epochs' pseudorange information, while a fix
    ///   has one epoch's; the canyon's reflections change within metres of travel (seconds at
    ///   5 m/s), so the 60 s hold tens of independent epochs, and an average of independent
    ///   errors has a smaller spread than each of them. (Without the gate a large reflected
    ///   range is averaged in at its nominal weight: no bound is claimed for that run.)
    #[test]
    fn real_gnss_and_odometer_with_a_simulated_imu_in_berlin() {
        let dir = test_dir("hybrid-berlin");
        std::fs::create_dir_all(&dir).unwrap();
        let s = measure(&Settings::default(), &dir, false).expect("runs");
        let table = table(&s);
        eprintln!("{table}");
        assert_eq!(s.epochs, 298, "{table}");
        assert_eq!(s.epochs_without_fix, 0, "{table}");
        assert!(s.spline_vs_reference_m[1] < 0.1, "{table}");
        assert_eq!(s.runs.len(), CASES.len());
        for r in &s.runs {
            assert!(r.first_solution_s < 0.1, "{}: {table}", r.name);
            assert!(r.errors.epochs > 200, "{}: {table}", r.name);
            assert!(r.position_nees_mean.is_finite(), "{}: {table}", r.name);
        }
        let wls_p95 = s.wls_all.horizontal_p95_m;
        for name in [CASES[2].name, CASES[3].name, CASES[4].name] {
            let r = s.runs.iter().find(|r| r.name == name).expect("run");
            assert!(
                r.errors.horizontal_p95_m < wls_p95,
                "{name}: p95 {} m vs the fixes' {wls_p95} m\n{table}",
                r.errors.horizontal_p95_m
            );
        }
        assert!(dir.join("horizontal_error.png").is_file());
        assert!(dir.join("error_vs_3sigma.png").is_file());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
