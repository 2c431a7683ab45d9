//! Experiment `hybrid-esbc`: **real GNSS, simulated inertial** — the hardware-in-the-loop
//! bench's own use case. One hour of the IGS station ESBC (Esbjerg, 2020-06-25 00:00–01:00 GPS
//! time, 30 s; `tests/data/rinex-esbc/`, embedded in the binary) is fixed epoch by epoch from its
//! raw GPS code (`sextant import rinex`: broadcast ephemerides, Klobuchar or the ionosphere-free
//! combination, Saastamoinen troposphere, 10° mask). A simulated IMU stands still at the
//! station's antenna reference point from the data's first epoch on (scenario
//! `config/scenarios/esbc_static.toml`, the site replaced by the RINEX header's position), and
//! the two streams are merged by time of validity and fed to the navigator, loosely (the
//! receiver's fix) and tightly (its corrected pseudoranges and Doppler).
//!
//! What is real: every GNSS measurement, its errors (ionosphere residual, troposphere, multipath,
//! orbit and clock, all correlated over minutes) and the reference, the station's published
//! coordinates (header `APPROX POSITION XYZ` + `ANTENNA: DELTA H`, the point a code solution
//! without a phase-centre model estimates). What is simulated: the IMU (its truth is static at
//! that reference point, so its errors are the simulator's). The filter's GNSS noise model is its
//! own (`config/filter.toml`): nothing is tuned to this data.
//!
//! Figures per (code, coupling), after the first `converge_s` of navigation, at 1 Hz:
//! horizontal and vertical error against the reference (RMS, 95th percentile, maximum), the
//! position NEES (mean of `eᵀP⁻¹e`, 3 dof, and the share above χ²₃(0.99) = 11.34), beside the
//! receiver-style epoch fixes' own errors over the same window — what the filter starts from.

use super::consistency::filter_config;
use super::plot::{Chart, Line, color, line_chart};
use super::{ExperimentError, fmt_f64, measurement, progress_bar, scenario_file};
use crate::import_rinex::{ImportMode, antenna_reference_point, epoch_samples};
use drivers_sim::offline::{OfflineSim, run_navigator};
use drivers_sim::scenario::Scenario;
use fusion::earth::{self, WGS84};
use fusion::navigator::{Navigator, NavigatorConfig};
use msgs::{Channel, GnssSample, Record};
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The ESBC observation hour (RINEX 3, gzip), CC BY 4.0 (see `tests/data/rinex-esbc/README.md`).
const OBS_GZ: &[u8] =
    include_bytes!("../../../tests/data/rinex-esbc/ESBC00DNK_R_20201770000_01H_30S_MO.rnx.gz");
/// Its GPS broadcast navigation file (RINEX 3, gzip).
const NAV_GZ: &[u8] =
    include_bytes!("../../../tests/data/rinex-esbc/ESBC00DNK_R_20201770000_01D_GN.rnx.gz");
/// File names the embedded data are reported under.
const OBS_NAME: &str = "ESBC00DNK_R_20201770000_01H_30S_MO.rnx.gz";
const NAV_NAME: &str = "ESBC00DNK_R_20201770000_01D_GN.rnx.gz";

/// χ²₃ 99 % quantile.
const CHI2_3_99: f64 = 11.344_866_730_144_373;

/// Settings of the experiment.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Length of the run from the data's first epoch, s (at most the hour's 3570 s).
    pub duration_s: f64,
    /// Time after which the statistics start (the filter's convergence from alignment), s.
    pub converge_s: f64,
    /// Scenario file name in `config/scenarios`.
    pub scenario: String,
    /// Elevation mask of the epoch fixes, degrees.
    pub elevation_mask_deg: f64,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            duration_s: 3570.0,
            converge_s: 300.0,
            scenario: "esbc_static.toml".into(),
            elevation_mask_deg: 10.0,
        }
    }
}

/// Error statistics of one position series against the reference.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct Errors {
    /// Epochs in the statistics.
    pub epochs: usize,
    /// Horizontal error RMS, m.
    pub horizontal_rms_m: f64,
    /// Horizontal error 95th percentile, m.
    pub horizontal_p95_m: f64,
    /// Largest horizontal error, m.
    pub horizontal_max_m: f64,
    /// Vertical error RMS, m.
    pub vertical_rms_m: f64,
    /// |vertical error| 95th percentile, m.
    pub vertical_p95_m: f64,
    /// Largest |vertical error|, m.
    pub vertical_max_m: f64,
    /// Mean vertical error (up positive), m.
    pub vertical_mean_m: f64,
}

/// One filter run: code solution × coupling.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Run {
    /// `l1` (C1C, Klobuchar) or `iono-free` (C1C/C2W).
    pub code: String,
    /// `loose` or `tight`; `+GM` with the time-correlated GNSS error model
    /// (`fusion::ekf::correlated`, [`OPEN_SKY_ERROR_CORRELATION_TIME_S`]).
    pub coupling: String,
    /// The navigator's errors after convergence, at 1 Hz.
    pub filter: Errors,
    /// The receiver-style epoch fixes' errors over the same window (the loose input).
    pub epoch_fix: Errors,
    /// Largest horizontal error of any epoch fix from the first epoch on, m: a static filter's
    /// estimate is a positively weighted mean of the fixes, so it cannot be farther off (up to
    /// the IMU's own drift between fixes).
    pub epoch_fix_max_horizontal_whole_run_m: f64,
    /// Mean position NEES (3 dof) after convergence.
    pub position_nees_mean: f64,
    /// Share of 1 Hz epochs with position NEES above χ²₃(0.99).
    pub position_nees_above_99: f64,
    /// Filter 1σ horizontal position at the end, m.
    pub final_horizontal_sigma_m: f64,
    /// GNSS NIS per degree of freedom over the run.
    pub gnss_nis_per_dof: f64,
    /// GNSS samples the navigator rejected by its χ² gate.
    pub gnss_rejected: u64,
    /// Time from the first epoch to the first navigating solution, s.
    pub first_solution_s: f64,
}

/// Figures of the experiment.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Summary {
    /// What is real and what is simulated.
    pub data: String,
    /// Marker of the observation file.
    pub marker: String,
    /// The reference (antenna reference point), ECEF, m.
    pub reference_ecef_m: [f64; 3],
    /// Run length, s.
    pub duration_s: f64,
    /// Statistics start, s.
    pub converge_s: f64,
    /// IMU grade of the simulated IMU.
    pub imu_grade: String,
    /// The simulated part's world effects that were on (truth only; empty: the matched
    /// world).
    #[serde(default)]
    pub world_effects: Vec<String>,
    /// IMU rate, Hz.
    pub imu_rate_hz: f64,
    /// Epochs read / fixed (L1 import).
    pub epochs: usize,
    /// Epochs with a fix (L1 import).
    pub epochs_fixed: usize,
    /// The runs.
    pub runs: Vec<Run>,
}

experiment!(
    /// Experiment `hybrid-esbc`; see the module documentation.
    HybridEsbc,
    "hybrid-esbc",
    "Real GNSS (IGS station ESBC, one hour of RINEX) with a simulated static IMU at the station: loose and tight coupling against the station's coordinates"
);

/// The embedded ESBC files, parsed.
fn esbc_files() -> Result<
    (
        sextant_rinex::ObservationFile,
        sextant_rinex::NavigationFile,
    ),
    ExperimentError,
> {
    let text = |raw: &[u8], name: &str| {
        sextant_rinex::decode_text(raw, true).map_err(|e| measurement(format!("{name}: {e}")))
    };
    let obs = sextant_rinex::parse_observation(&text(OBS_GZ, OBS_NAME)?)
        .map_err(|e| measurement(format!("{OBS_NAME}: {e}")))?;
    let nav = sextant_rinex::parse_navigation(&text(NAV_GZ, NAV_NAME)?)
        .map_err(|e| measurement(format!("{NAV_NAME}: {e}")))?;
    Ok((obs, nav))
}

/// The scenario at the reference point, starting at the data's first epoch.
fn scenario(
    settings: &Settings,
    reference: &Vector3<f64>,
    first_epoch: fusion::time::GpsTime,
) -> Result<Scenario, ExperimentError> {
    let path = scenario_file(&settings.scenario);
    let text = std::fs::read_to_string(&path).map_err(|source| ExperimentError::Io {
        path: path.clone(),
        source,
    })?;
    let mut spec = Scenario::parse(&text, &path).map_err(measurement)?;
    let g = earth::ecef_to_geodetic(&WGS84, reference);
    spec.site.lat_deg = g.lat_rad.to_degrees();
    spec.site.lon_deg = g.lon_rad.to_degrees();
    spec.site.height_m = g.height_m;
    spec.scenario.duration_s = settings.duration_s;
    let dir = path
        .parent()
        .unwrap_or(Path::new("."))
        .join(spec.scenario.sensors_dir.as_deref().unwrap_or("../sensors"));
    let scn = Scenario::validate(spec, &path, &dir).map_err(measurement)?;
    if scn.epoch_gps().ns != first_epoch.ns {
        return Err(measurement(format!(
            "{}: start_utc is GPS {} ns, the data start at GPS {} ns",
            path.display(),
            scn.epoch_gps().ns,
            first_epoch.ns
        )));
    }
    Ok(scn)
}

/// The filter configuration: the shipped tuning with the aiding this bench does not have off
/// (no star tracker, odometer or baro samples exist; a static bench is no ground vehicle, so no
/// non-holonomic constraint), and the coupling.
fn config(tight: bool, gm: bool) -> Result<NavigatorConfig, ExperimentError> {
    let mut o: Vec<(&str, toml::Value)> = vec![
        ("updates.star_tracker", toml::Value::Boolean(false)),
        ("updates.odometer", toml::Value::Boolean(false)),
        ("updates.baro", toml::Value::Boolean(false)),
        ("updates.nonholonomic", toml::Value::Boolean(false)),
    ];
    if tight {
        o.push(("gnss_mode", toml::Value::String("tight".into())));
    }
    if gm {
        o.push((
            "gnss.error_correlation_time_s",
            toml::Value::Float(OPEN_SKY_ERROR_CORRELATION_TIME_S),
        ));
    }
    filter_config(&o)
}

/// Horizontal (north, east) and vertical (up) error of `p` against `reference`, m.
fn ne_up(c_n_e: &Matrix3<f64>, p: &Vector3<f64>, reference: &Vector3<f64>) -> (f64, f64) {
    let ned = c_n_e * (p - reference);
    (ned.x.hypot(ned.y), -ned.z)
}

/// Statistics of (horizontal, vertical) errors.
fn errors(hv: &[(f64, f64)]) -> Errors {
    if hv.is_empty() {
        return Errors {
            horizontal_rms_m: f64::NAN,
            horizontal_p95_m: f64::NAN,
            horizontal_max_m: f64::NAN,
            vertical_rms_m: f64::NAN,
            vertical_p95_m: f64::NAN,
            vertical_max_m: f64::NAN,
            vertical_mean_m: f64::NAN,
            epochs: 0,
        };
    }
    let n = hv.len() as f64;
    let rms =
        |f: &dyn Fn(&(f64, f64)) -> f64| (hv.iter().map(|x| f(x).powi(2)).sum::<f64>() / n).sqrt();
    let sorted = |f: &dyn Fn(&(f64, f64)) -> f64| {
        let mut a: Vec<f64> = hv.iter().map(|x| f(x).abs()).collect();
        a.sort_by(f64::total_cmp);
        a
    };
    // Nearest-rank 95th percentile.
    let p95 = |a: &[f64]| a[((0.95 * a.len() as f64).ceil() as usize).max(1) - 1];
    let h = sorted(&|x| x.0);
    let v = sorted(&|x| x.1);
    Errors {
        epochs: hv.len(),
        horizontal_rms_m: rms(&|x| x.0),
        horizontal_p95_m: p95(&h),
        horizontal_max_m: h[h.len() - 1],
        vertical_rms_m: rms(&|x| x.1),
        vertical_p95_m: p95(&v),
        vertical_max_m: v[v.len() - 1],
        vertical_mean_m: hv.iter().map(|x| x.1).sum::<f64>() / n,
    }
}

/// A run's 1 Hz series for the plots: t (s), horizontal and vertical error (m).
#[derive(Debug, Clone, Default)]
struct Series {
    t_s: Vec<f64>,
    h_m: Vec<f64>,
    v_m: Vec<f64>,
    /// The epoch fixes' (t, horizontal, vertical).
    fixes: Vec<(f64, f64, f64)>,
}

fn one_run(
    settings: &Settings,
    scn: &Scenario,
    gnss: &[GnssSample],
    reference: &Vector3<f64>,
    code: ImportMode,
    tight: bool,
    gm: bool,
) -> Result<(Run, Series), ExperimentError> {
    // The simulated IMU stands in the world's gravity field (of the car's installation
    // nothing else applies to a static bench).
    let cfg = super::consistency::with_gravity_class(scn, config(tight, gm)?)?;
    let mut nav = Navigator::new(cfg).map_err(|e| measurement(format!("navigator: {e}")))?;
    let sim = OfflineSim::with_channels(scn, &[Channel::Imu, Channel::Truth]);
    let epoch = sim.epoch_ns();
    let end_ns = epoch + (settings.duration_s * 1e9).round() as i64;
    // The real GNSS stream merged into the simulated one by time of validity (aiding before
    // the IMU at equal times, as everywhere: `msgs::Channel` order).
    let mut real = gnss
        .iter()
        .filter(|g| g.header.time_ns <= end_ns)
        .map(|g| Record::Gnss(Box::new(*g)))
        .peekable();
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
    let g = earth::ecef_to_geodetic(&WGS84, reference);
    let c_n_e = earth::c_e_n(g.lat_rad, g.lon_rad).transpose();
    let mut hv = Vec::new();
    let mut series = Series::default();
    let mut nees = Vec::new();
    let mut first_solution_s = f64::NAN;
    let mut final_sigma = f64::NAN;
    run_navigator(stream, epoch, &mut nav, |p| {
        if first_solution_s.is_nan() {
            first_solution_s = p.t_s;
        }
        // 1 Hz: the truth runs at a whole-hertz multiple from the epoch.
        if (p.t_s - p.t_s.round()).abs() > 1e-6 {
            return;
        }
        // `pos_err_e_m` is truth − estimate.
        let est = p.pos_true_e_m - p.pos_err_e_m;
        let (h, v) = ne_up(&c_n_e, &est, reference);
        series.t_s.push(p.t_s);
        series.h_m.push(h);
        series.v_m.push(v);
        final_sigma = p.horizontal_sigma_m();
        if p.t_s >= settings.converge_s {
            hv.push((h, v));
            let e = est - reference;
            if let Some(inv) = p.pos_cov_e_m2.try_inverse() {
                nees.push((e.transpose() * inv * e)[(0, 0)]);
            }
        }
    })
    .map_err(|e| measurement(format!("{code:?} {}: {e}", coupling(tight, gm))))?;
    series.fixes = gnss
        .iter()
        .filter(|g| g.fix_valid == 1)
        .map(|g| {
            let t = (g.header.time_ns - epoch) as f64 * 1e-9;
            let (h, v) = ne_up(&c_n_e, &Vector3::from(g.pos_ecef_m), reference);
            (t, h, v)
        })
        .filter(|&(t, _, _)| t <= settings.duration_s)
        .collect();
    let fix_hv: Vec<(f64, f64)> = series
        .fixes
        .iter()
        .filter(|&&(t, _, _)| t >= settings.converge_s)
        .map(|&(_, h, v)| (h, v))
        .collect();
    let health = nav.health()[msgs::SensorId::Gnss as usize];
    let run = Run {
        code: code_name(code).into(),
        coupling: coupling(tight, gm).into(),
        filter: errors(&hv),
        epoch_fix: errors(&fix_hv),
        epoch_fix_max_horizontal_whole_run_m: series.fixes.iter().map(|f| f.1).fold(0.0, f64::max),
        position_nees_mean: nees.iter().sum::<f64>() / nees.len().max(1) as f64,
        position_nees_above_99: nees.iter().filter(|&&x| x > CHI2_3_99).count() as f64
            / nees.len().max(1) as f64,
        final_horizontal_sigma_m: final_sigma,
        gnss_nis_per_dof: health.nis_sum / health.nis_dof_sum.max(1) as f64,
        gnss_rejected: health.rejected_gate,
        first_solution_s,
    };
    Ok((run, series))
}

fn coupling(tight: bool, gm: bool) -> &'static str {
    match (tight, gm) {
        (false, false) => "loose",
        (true, false) => "tight",
        (false, true) => "loose+GM",
        (true, true) => "tight+GM",
    }
}

/// Correlation time of an open-sky single-frequency (or dual-frequency) code receiver's
/// errors, s, for the `+GM` runs: the shipped `config/filter.toml`'s open-sky class (residual
/// atmosphere and broadcast orbit and clock; its comment gives the source). Not fitted to
/// this station.
const OPEN_SKY_ERROR_CORRELATION_TIME_S: f64 = 2700.0;

fn code_name(code: ImportMode) -> &'static str {
    match code {
        ImportMode::L1 => "l1",
        ImportMode::IonoFree => "iono-free",
    }
}

/// Measure into `out_dir` (plots) and return the summary.
pub fn measure(
    settings: &Settings,
    out_dir: &Path,
    progress: bool,
) -> Result<Summary, ExperimentError> {
    if !(settings.duration_s > settings.converge_s && settings.duration_s <= 3570.0) {
        return Err(measurement(format!(
            "duration {} s must exceed converge_s {} s and be at most the data's 3570 s",
            settings.duration_s, settings.converge_s
        )));
    }
    let (obs, nav) = esbc_files()?;
    let reference = antenna_reference_point(&obs)
        .ok_or_else(|| measurement(format!("{OBS_NAME}: no APPROX POSITION XYZ")))?;
    let first = obs
        .epochs
        .first()
        .ok_or_else(|| measurement(format!("{OBS_NAME}: no epochs")))?
        .time;
    let scn = scenario(settings, &reference, first)?;
    let mut streams = Vec::new();
    let mut epochs = (0, 0);
    for code in [ImportMode::L1, ImportMode::IonoFree] {
        let (samples, s) = epoch_samples(
            &obs,
            &nav,
            code,
            settings.elevation_mask_deg,
            Path::new(OBS_NAME),
            Path::new(NAV_NAME),
        )
        .map_err(measurement)?;
        if code == ImportMode::L1 {
            epochs = (s.epochs, s.fixed);
        }
        streams.push((code, samples));
    }
    let cases: Vec<(ImportMode, bool, bool)> = [ImportMode::L1, ImportMode::IonoFree]
        .into_iter()
        .flat_map(|c| {
            [
                (c, false, false),
                (c, true, false),
                (c, false, true),
                (c, true, true),
            ]
        })
        .collect();
    let pb = progress_bar(progress, cases.len() as u64, "hybrid-esbc runs");
    let results: Vec<Result<(Run, Series), ExperimentError>> = cases
        .par_iter()
        .map(|&(code, tight, gm)| {
            let gnss = &streams
                .iter()
                .find(|(c, _)| *c == code)
                .expect("both codes imported")
                .1;
            let r = one_run(settings, &scn, gnss, &reference, code, tight, gm);
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
    plots(out_dir, &runs, &series)?;
    Ok(Summary {
        data: "REAL GNSS (IGS ESBC RINEX, raw code + broadcast ephemerides) with a SIMULATED IMU \
               static at the station; reference: the station's coordinates"
            .into(),
        marker: obs.header.marker_name.clone(),
        reference_ecef_m: reference.into(),
        duration_s: settings.duration_s,
        converge_s: settings.converge_s,
        imu_grade: scn.spec.imu.grade.clone(),
        world_effects: super::world_effects(&scn),
        imu_rate_hz: scn.spec.imu.rate_hz,
        epochs: epochs.0,
        epochs_fixed: epochs.1,
        runs,
    })
}

fn plots(out_dir: &Path, runs: &[Run], series: &[Series]) -> Result<(), ExperimentError> {
    for (file, title, y_label, pick) in [
        (
            "horizontal_error.png",
            "hybrid-esbc: horizontal error against the station (real GNSS, simulated IMU)",
            "horizontal error, m",
            0usize,
        ),
        (
            "vertical_error.png",
            "hybrid-esbc: vertical error against the station (real GNSS, simulated IMU)",
            "vertical error (up), m",
            1,
        ),
    ] {
        let mut lines: Vec<Line> = runs
            .iter()
            .zip(series)
            .enumerate()
            .map(|(i, (r, s))| {
                let y = if pick == 0 { &s.h_m } else { &s.v_m };
                let pts = s.t_s.iter().copied().zip(y.iter().copied()).collect();
                Line::solid(format!("{} {}", r.code, r.coupling), pts, color(i))
            })
            .collect();
        // The epoch fixes the filter starts from, once per code (the loose run's).
        let loose = runs
            .iter()
            .zip(series)
            .filter(|(r, _)| r.coupling == "loose");
        for (i, (r, s)) in loose.enumerate() {
            let pts = s
                .fixes
                .iter()
                .map(|&(t, h, v)| (t, if pick == 0 { h } else { v }))
                .collect();
            lines.push(
                Line::dashed(format!("{} epoch fix", r.code), pts, color(4 + i)).with_markers(),
            );
        }
        let path: PathBuf = out_dir.join(file);
        line_chart(
            &path,
            &Chart::linear(title, "time since 2020-06-25 00:00 GPS, s", y_label, &lines),
        )?;
    }
    Ok(())
}

/// The summary as a table.
pub fn table(s: &Summary) -> String {
    let f2 = |x: f64| fmt_f64(x, 2, false);
    let mut t = format!(
        "hybrid-esbc: {}\nstation {}, {} s from the first epoch, statistics after {} s, \
         IMU {} at {} Hz, {} of {} epochs fixed (L1)\n",
        s.data,
        s.marker,
        fmt_f64(s.duration_s, 0, false),
        fmt_f64(s.converge_s, 0, false),
        s.imu_grade,
        fmt_f64(s.imu_rate_hz, 0, false),
        s.epochs_fixed,
        s.epochs,
    );
    t += &format!("the IMU: {}\n", super::world_line(&s.world_effects));
    t += "code       coupling  source     H RMS  H p95  H max   V RMS  V p95  V mean   \
          NEES mean  >χ²99   σH end  NIS/dof  rejected\n";
    for r in &s.runs {
        for (source, e, filter) in [
            ("filter", &r.filter, true),
            ("epoch fix", &r.epoch_fix, false),
        ] {
            let _ = write!(
                t,
                "{:<10} {:<9} {:<9} {:>6} {:>6} {:>6}  {:>6} {:>6} {:>7}",
                r.code,
                r.coupling,
                source,
                f2(e.horizontal_rms_m),
                f2(e.horizontal_p95_m),
                f2(e.horizontal_max_m),
                f2(e.vertical_rms_m),
                f2(e.vertical_p95_m),
                f2(e.vertical_mean_m),
            );
            if filter {
                let _ = writeln!(
                    t,
                    "   {:>9} {:>6.1}%  {:>7} {:>8} {:>9}",
                    f2(r.position_nees_mean),
                    100.0 * r.position_nees_above_99,
                    f2(r.final_horizontal_sigma_m),
                    f2(r.gnss_nis_per_dof),
                    r.gnss_rejected
                );
            } else {
                t.push('\n');
            }
        }
    }
    t += "(errors in m against the station's antenna reference point; NEES: 3-D position, \
          expected mean 3 for a consistent filter)\n";
    t
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiments::test_dir;

    /// The first 900 s: every epoch fixed; both codes and couplings navigate after the
    /// alignment; a static filter's horizontal error stays within the worst epoch fix (its
    /// estimate is a positively weighted mean of them, plus a navigation-grade IMU's drift over
    /// 30 s between fixes, millimetres), and is smaller in RMS than the fixes' (averaging can
    /// only remove their noise, never add); loose and tight agree, because the fix's covariance
    /// is the least-squares covariance of the same pseudoranges with the same weights, so both
    /// updates carry the same information to first order.
    #[test]
    fn real_gnss_with_a_simulated_imu_at_the_station() {
        let dir = test_dir("hybrid-esbc");
        std::fs::create_dir_all(&dir).unwrap();
        let settings = Settings {
            duration_s: 900.0,
            ..Settings::default()
        };
        let s = measure(&settings, &dir, false).expect("runs");
        assert_eq!((s.epochs, s.epochs_fixed), (120, 120));
        assert_eq!(s.runs.len(), 8);
        for r in &s.runs {
            let what = format!("{} {}", r.code, r.coupling);
            // Alignment (filter.toml) then navigation; statistics over 300–900 s at 1 Hz.
            assert!(r.first_solution_s < settings.converge_s, "{what}: {r:?}");
            assert_eq!(r.filter.epochs, 601, "{what}");
            // Epochs every 30 s, their times shifted by the receiver clock (sub-millisecond):
            // 300 s and 900 s fall on either side of the window's edges.
            assert!((20..=21).contains(&r.epoch_fix.epochs), "{what}: {r:?}");
            assert!(
                r.filter.horizontal_max_m <= r.epoch_fix_max_horizontal_whole_run_m + 0.01,
                "{what}: {r:?}"
            );
            assert!(
                r.filter.horizontal_rms_m <= r.epoch_fix.horizontal_rms_m,
                "{what}: {r:?}"
            );
            assert!(r.position_nees_mean.is_finite(), "{what}");
        }
        for code in ["l1", "iono-free"] {
            let get = |c: &str| {
                s.runs
                    .iter()
                    .find(|r| r.code == code && r.coupling == c)
                    .unwrap()
                    .filter
            };
            let (l, t) = (get("loose"), get("tight"));
            assert!(
                (l.horizontal_rms_m - t.horizontal_rms_m).abs() < 0.1
                    && (l.vertical_rms_m - t.vertical_rms_m).abs() < 0.1,
                "{code}: loose {l:?} tight {t:?}"
            );
        }
        assert!(dir.join("horizontal_error.png").is_file());
        assert!(dir.join("vertical_error.png").is_file());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
