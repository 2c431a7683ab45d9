//! Experiment `baseline-attitude` (paper 003, GNSS attitude from two perpendicular antenna
//! baselines, eq. 14–21): accuracy of [`fusion::baseline_attitude`] against baseline length d
//! and carrier-phase noise σ_φ, measured against the σ the solver predicts from its
//! covariance `(JᵀWJ)⁻¹`.
//!
//! The data are the simulator's own GNSS messages (`drivers_sim::sources::GnssSource`) on the
//! moving `config/scenarios/vehicle.toml` (turns change the heading, so the line-of-sight
//! geometry in the body frame changes too), with the grade's baseline lengths and phase σ
//! overridden per configuration and an independent noise stream (seed) for each; the receiver
//! position for the lines of sight is the
//! least-squares fix of the same message ([`fusion::gnss_ls`]). Every epoch draws new phase
//! noise, so the epochs are independent samples.
//!
//! The phases are the receiver's: the car's `[world.carrier_phase]` is on (an unknown integer
//! per satellite and baseline drawn at each acquisition, cycle slips at a rate growing as C/N0
//! falls, one in ten of them not flagged by the lock time), the rest of the world matched. Each
//! configuration runs its own [`fusion::phase_ambiguity`] resolver from the first epoch (no
//! attitude prior): the figures are those of the fixed epochs, and per configuration the time
//! to first fix, the fix rate, the epochs with a wrong integer held (checked against the
//! simulator's hidden integers) and the slips — the world's, the ones the receiver flagged and
//! the ones the residual test found.
//!
//! Theory: a phase difference in cycles gives the baseline projection `λΔφ` with σ `λσ_φ`
//! (in radians of phase, `λσ_φ,rad/(2π)`), and an angle error δ tilts a baseline of length d
//! by `d·δ`, so every attitude σ is `λσ_φ/d` (= `λσ_φ,rad/(2π d)`) times a geometry factor of
//! the lines of sight. Figures: per configuration the RMS error of heading, pitch and roll,
//! the RMS of the predicted σ, and the normalised error `Σ(ε/σ)²/N` per axis (χ²(N)/N: 1 ±
//! 4√(2/N) at 4σ); log-log slopes of RMS error against `λσ_φ/d` along both sweeps (theory: 1).
//!
//! The sweeps check the method's σ law, so the rest of their world is matched. The reference
//! configuration then runs once more on the car's whole world (`vehicle.toml`'s `[world]`:
//! the road's grade and bank, the antenna's lever arm and time tag — the truth is taken at the
//! measurement instant — the pseudorange errors under the fix that gives the lines of sight,
//! and the two antennas' carrier-phase multipath, [`drivers_sim::world::phase_multipath`]),
//! the solver still weighting the phases by the receiver's σ_φ: what paper 003's method gives
//! on a car, reported beside the law.

use super::plot::{Chart, Line, color, finite_points, line_chart};
use super::{Experiment, ExperimentError, fmt_f64, fmt_opt, linear_fit, progress_bar};
use drivers_sim::scenario::Scenario;
use drivers_sim::sources::GnssSource;
use drivers_sim::truth::{TruthGenerator, wrap_pi};
use fusion::baseline_attitude::BaselineConfig;
use fusion::phase_ambiguity::{AmbiguityConfig, AmbiguityResolver, RawPhases};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

const DEG: f64 = 180.0 / std::f64::consts::PI;

/// Settings of the experiment.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Baseline lengths swept at `reference_sigma_cycles`, m (both baselines equal).
    pub lengths_m: Vec<f64>,
    /// Phase noises swept at `reference_length_m`, cycles.
    pub sigmas_cycles: Vec<f64>,
    /// Baseline length of the σ sweep, m.
    pub reference_length_m: f64,
    /// Phase σ of the length sweep, cycles.
    pub reference_sigma_cycles: f64,
    /// Epochs (1 Hz) per configuration.
    pub epochs: usize,
    /// The differential carrier-phase multipath an engineer expects of the installation (two
    /// antennas on a car's roof), mm: added in quadrature to the receiver's σ_φ to weight the
    /// phases in the car's-world run that knows it.
    pub installation_multipath_mm: f64,
}

impl Default for Settings {
    /// d = 0.25…5 m at σ_φ = 0.01 cycle; σ_φ = 0.002…0.05 cycle at d = 1 m; 600 epochs.
    fn default() -> Self {
        Self {
            lengths_m: vec![0.25, 0.5, 1.0, 2.0, 5.0],
            sigmas_cycles: vec![0.002, 0.005, 0.01, 0.02, 0.05],
            reference_length_m: 1.0,
            reference_sigma_cycles: 0.01,
            epochs: 600,
            installation_multipath_mm: INSTALLATION_MULTIPATH_MM,
        }
    }
}

/// Differential carrier-phase multipath of a car-roof antenna pair, mm, as an installation
/// class: a weak echo of relative amplitude α shifts one antenna's phase by up to `αλ/(2π)`
/// (Braasch 1996, ch. 14 of Parkinson & Spilker), 3–9 mm at L1 for α = 0.1–0.3 (roof and
/// ground reflections); its RMS over the reflection phase is that over √2, and the
/// difference of two antennas' independent errors √2 times one's: 3–9 mm. The class is the
/// low end, since the roof's reflections weaken with elevation above the antenna's gain
/// pattern cut-off. Not the world's parameter (an elevation law hidden from the solver).
pub const INSTALLATION_MULTIPATH_MM: f64 = 4.0;

fn scenario_path() -> PathBuf {
    crate::shipped_config::scenario("vehicle.toml")
}

fn measurement(e: impl std::fmt::Display) -> ExperimentError {
    ExperimentError::Measurement(e.to_string())
}

/// Figures of one configuration.
#[derive(Debug, Clone, Copy, Default)]
struct Config {
    length_m: f64,
    sigma_cycles: f64,
    solver_sigma_cycles: f64,
    wavelength_m: f64,
    epochs: usize,
    rms_rad: [f64; 3],
    predicted_rms_rad: [f64; 3],
    normalised_sq: [f64; 3],
    integers: Integers,
}

/// The integer ambiguity figures of one configuration.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Integers {
    /// Epochs with a GNSS fix and baseline phases.
    pub epochs_with_phases: usize,
    /// Of those, epochs with an integer-fixed attitude.
    pub fixed_epochs: usize,
    /// fixed / with phases.
    pub fix_rate: f64,
    /// From the first epoch with phases to the first fix, s (absent: never fixed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_to_first_fix_s: Option<f64>,
    /// Fixed epochs with any held integer different from the simulator's (wrong fixes).
    pub wrong_fix_epochs: usize,
    /// Fixed epochs whose integers came from a new search.
    pub search_fixes: usize,
    /// Epochs float only (ratio test or no candidate).
    pub float_only_epochs: usize,
    /// Epochs rejected otherwise (too few satellites, χ², solver, too many candidates).
    pub rejected_epochs: usize,
    /// Slips of the world (truth), flagged and not flagged by the receiver.
    pub world_slips: u64,
    /// Of those, not flagged.
    pub world_slips_unflagged: u64,
    /// Held satellites dropped on the receiver's lock flag.
    pub slips_flagged_seen: usize,
    /// Held satellites dropped by the residual test (unflagged slips found).
    pub slips_found_by_residuals: usize,
    /// Held sets rejected as a whole by the residual test.
    pub held_sets_rejected: usize,
}

/// One configuration: the receiver's loop noise `sigma_cycles`, the solver weighting the
/// phases by `solver_sigma_cycles`.
fn run_config(
    base: &Scenario,
    length_m: f64,
    (sigma_cycles, solver_sigma_cycles): (f64, f64),
    epochs: usize,
    seed: u64,
) -> Result<Config, ExperimentError> {
    let mut scn = base.clone();
    scn.spec.scenario.seed = seed;
    scn.gnss.baseline_length_m = [length_m, length_m];
    scn.gnss.phase_sigma_cycles = sigma_cycles;
    let mut src = GnssSource::new(&scn, scn.epoch_gps().ns);
    let mut truth = TruthGenerator::new(&scn);
    // The receiver stamps its epoch `latency` after the measurement instant (the world's
    // documented time tag): the attitude solved is the one of that instant.
    let latency_ns = scn.spec.world.map_or(0, |w| w.gnss_latency_ns());
    let (mut se, mut sp, mut sz) = ([0.0; 3], [0.0; 3], [0.0; 3]);
    let mut n = 0usize;
    let mut wavelength = 0.0;
    let mut resolver: Option<AmbiguityResolver> = None;
    let mut ig = Integers::default();
    let mut first_t_s: Option<f64> = None;
    for k in 0..epochs as i64 {
        let t_ns = k * 1_000_000_000;
        let (msg, hidden) = src.sample_with_truth(t_ns);
        truth.advance_to((t_ns - latency_ns).max(0));
        let tp = truth.current();
        if msg.fix_valid == 0 {
            continue;
        }
        let fix = fusion::gnss_ls::solve_sample(&msg).map_err(measurement)?;
        let r = fix.position.r_e_m;
        let raw = RawPhases::from_sample(&msg, &r).map_err(measurement)?;
        if raw.as_slice().is_empty() {
            continue;
        }
        let cfg = BaselineConfig {
            baseline_length_m: msg.baseline_length_m,
            wavelength_m: msg.wavelength_m,
            sigma_phase_cycles: solver_sigma_cycles,
        };
        wavelength = msg.wavelength_m;
        let res = match &mut resolver {
            Some(r) => r,
            None => resolver.insert(
                AmbiguityResolver::new(AmbiguityConfig {
                    baseline: cfg,
                    // The shipped filter's values (`config/filter.toml`).
                    ratio_threshold: 3.0,
                    chi2_probability: 0.999,
                })
                .map_err(measurement)?,
            ),
        };
        let t_s = msg.header.time_ns as f64 * 1e-9;
        ig.epochs_with_phases += 1;
        let t0 = *first_t_s.get_or_insert(t_s);
        let out = res.resolve(t_s, &raw, &r, None);
        ig.slips_flagged_seen += out.slips_flagged;
        ig.slips_found_by_residuals += out.slips_detected;
        ig.held_sets_rejected += usize::from(out.held_set_rejected);
        let a = match out.result {
            Ok(f) => {
                ig.search_fixes += usize::from(f.searched);
                f.attitude
            }
            Err(e) => {
                if e.is_float_only() {
                    ig.float_only_epochs += 1;
                } else {
                    ig.rejected_epochs += 1;
                }
                continue;
            }
        };
        ig.fixed_epochs += 1;
        ig.time_to_first_fix_s.get_or_insert(t_s - t0);
        let nsat = (msg.n_satellites as usize).min(msg.satellites.len());
        let wrong = msg.satellites[..nsat]
            .iter()
            .zip(&hidden.phase_ambiguity_cycles)
            .any(|(s, truth_int)| res.held(s.prn).is_some_and(|h| h != *truth_int));
        ig.wrong_fix_epochs += usize::from(wrong);
        let err = [
            wrap_pi(a.rpy_rad.x - tp.roll_pitch_heading_rad.x),
            wrap_pi(a.rpy_rad.y - tp.roll_pitch_heading_rad.y),
            wrap_pi(a.rpy_rad.z - tp.roll_pitch_heading_rad.z),
        ];
        for i in 0..3 {
            let var = a.cov_rpy_rad2[(i, i)];
            se[i] += err[i] * err[i];
            sp[i] += var;
            sz[i] += err[i] * err[i] / var;
        }
        n += 1;
    }
    let c = src.sim.phase_slip_counts();
    ig.world_slips = c.flagged + c.unflagged;
    ig.world_slips_unflagged = c.unflagged;
    ig.fix_rate = ig.fixed_epochs as f64 / ig.epochs_with_phases.max(1) as f64;
    let nf = n.max(1) as f64;
    let nan_if_none = |x: f64| if n == 0 { f64::NAN } else { x };
    Ok(Config {
        length_m,
        sigma_cycles,
        solver_sigma_cycles,
        wavelength_m: wavelength,
        epochs: n,
        rms_rad: se.map(|x| nan_if_none((x / nf).sqrt())),
        predicted_rms_rad: sp.map(|x| nan_if_none((x / nf).sqrt())),
        normalised_sq: sz.map(|x| nan_if_none(x / nf)),
        integers: ig,
    })
}

/// One baseline configuration: RMS errors over the epochs against the predicted σ, deg.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Row {
    /// Baseline length d (both baselines), m.
    pub baseline_length_m: f64,
    /// Carrier-phase noise σ_φ, cycles.
    pub phase_sigma_cycles: f64,
    /// The σ the solver weights the phases by, cycles (σ_φ, or σ_φ with the installation's
    /// multipath).
    pub solver_phase_sigma_cycles: f64,
    /// λσ_φ/d, rad.
    pub lambda_sigma_over_d_rad: f64,
    /// Epochs with an integer-fixed solution (the figures below are over these).
    pub epochs: usize,
    /// Roll RMS error.
    pub roll_rms_deg: f64,
    /// Pitch RMS error.
    pub pitch_rms_deg: f64,
    /// Heading RMS error.
    pub heading_rms_deg: f64,
    /// Roll σ predicted by the solver's covariance (RMS over the epochs).
    pub roll_predicted_deg: f64,
    /// Pitch σ predicted.
    pub pitch_predicted_deg: f64,
    /// Heading σ predicted.
    pub heading_predicted_deg: f64,
    /// Roll Σ(ε/σ)²/N (χ²(N)/N for a consistent solver).
    pub roll_normalised_sq: f64,
    /// Pitch Σ(ε/σ)²/N.
    pub pitch_normalised_sq: f64,
    /// Heading Σ(ε/σ)²/N.
    pub heading_normalised_sq: f64,
    /// Predicted heading σ over λσ_φ/d.
    pub heading_geometry_factor: f64,
    /// Integer ambiguity resolution: fixes, wrong fixes, slips.
    pub integers: Integers,
}

impl Row {
    /// (axis, RMS error, predicted σ, Σ(ε/σ)²/N) for heading, pitch and roll.
    fn by_axis(&self) -> [(&'static str, f64, f64, f64); 3] {
        [
            (
                "heading",
                self.heading_rms_deg,
                self.heading_predicted_deg,
                self.heading_normalised_sq,
            ),
            (
                "pitch",
                self.pitch_rms_deg,
                self.pitch_predicted_deg,
                self.pitch_normalised_sq,
            ),
            (
                "roll",
                self.roll_rms_deg,
                self.roll_predicted_deg,
                self.roll_normalised_sq,
            ),
        ]
    }
}

/// Log-log slopes of the RMS errors and predicted σ against λσ_φ/d over each sweep (theory 1);
/// absent when a sweep has fewer than two distinct points.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[allow(missing_docs)]
pub struct Slopes {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub length_sweep_heading_rms_loglog_slope: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub length_sweep_heading_predicted_loglog_slope: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub length_sweep_pitch_rms_loglog_slope: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub length_sweep_pitch_predicted_loglog_slope: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub length_sweep_roll_rms_loglog_slope: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub length_sweep_roll_predicted_loglog_slope: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_sweep_heading_rms_loglog_slope: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_sweep_heading_predicted_loglog_slope: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_sweep_pitch_rms_loglog_slope: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_sweep_pitch_predicted_loglog_slope: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_sweep_roll_rms_loglog_slope: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_sweep_roll_predicted_loglog_slope: Option<f64>,
}

impl Slopes {
    fn of(by_length: &[Row], by_sigma: &[Row]) -> Self {
        Self {
            length_sweep_heading_rms_loglog_slope: slope(by_length, |r| r.heading_rms_deg),
            length_sweep_heading_predicted_loglog_slope: slope(by_length, |r| {
                r.heading_predicted_deg
            }),
            length_sweep_pitch_rms_loglog_slope: slope(by_length, |r| r.pitch_rms_deg),
            length_sweep_pitch_predicted_loglog_slope: slope(by_length, |r| r.pitch_predicted_deg),
            length_sweep_roll_rms_loglog_slope: slope(by_length, |r| r.roll_rms_deg),
            length_sweep_roll_predicted_loglog_slope: slope(by_length, |r| r.roll_predicted_deg),
            sigma_sweep_heading_rms_loglog_slope: slope(by_sigma, |r| r.heading_rms_deg),
            sigma_sweep_heading_predicted_loglog_slope: slope(by_sigma, |r| {
                r.heading_predicted_deg
            }),
            sigma_sweep_pitch_rms_loglog_slope: slope(by_sigma, |r| r.pitch_rms_deg),
            sigma_sweep_pitch_predicted_loglog_slope: slope(by_sigma, |r| r.pitch_predicted_deg),
            sigma_sweep_roll_rms_loglog_slope: slope(by_sigma, |r| r.roll_rms_deg),
            sigma_sweep_roll_predicted_loglog_slope: slope(by_sigma, |r| r.roll_predicted_deg),
        }
    }
}

/// The figures of `baseline-attitude` (`summary.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// `"baseline-attitude"`.
    pub experiment: String,
    /// The paper reproduced, `"003"`.
    pub paper: String,
    /// The scenario file.
    pub scenario: String,
    /// Epochs simulated per configuration.
    pub epochs_per_configuration: usize,
    /// Baseline lengths at the reference phase noise.
    pub length_sweep: Vec<Row>,
    /// Phase noises at the reference baseline length.
    pub sigma_sweep: Vec<Row>,
    /// Log-log slopes against λσ_φ/d.
    pub slopes: Slopes,
    /// Largest |measured RMS / predicted σ − 1| over the configurations and axes.
    pub max_abs_measured_over_predicted_minus_one: f64,
    /// The reference configuration on the car's whole world (the shipped scenario's
    /// `[world]`: its road, antenna, time tag, pseudorange errors and the phases' multipath),
    /// the solver still weighting the phases by the receiver's σ_φ.
    pub car_world: Row,
    /// The same run, the solver weighting the phases by σ_φ with the installation's
    /// multipath class ([`INSTALLATION_MULTIPATH_MM`]) in quadrature.
    pub car_world_multipath_weighted: Row,
    /// The world effects on in those runs (truth only).
    pub car_world_effects: Vec<String>,
}

experiment!(
    /// `sextant experiment baseline-attitude`.
    BaselineAttitude,
    "baseline-attitude",
    "Paper 003: dual-baseline GNSS attitude"
);

fn row(c: &Config) -> Row {
    let unit = c.wavelength_m * c.sigma_cycles / c.length_m;
    Row {
        baseline_length_m: c.length_m,
        phase_sigma_cycles: c.sigma_cycles,
        solver_phase_sigma_cycles: c.solver_sigma_cycles,
        lambda_sigma_over_d_rad: unit,
        epochs: c.epochs,
        roll_rms_deg: c.rms_rad[0] * DEG,
        pitch_rms_deg: c.rms_rad[1] * DEG,
        heading_rms_deg: c.rms_rad[2] * DEG,
        roll_predicted_deg: c.predicted_rms_rad[0] * DEG,
        pitch_predicted_deg: c.predicted_rms_rad[1] * DEG,
        heading_predicted_deg: c.predicted_rms_rad[2] * DEG,
        roll_normalised_sq: c.normalised_sq[0],
        pitch_normalised_sq: c.normalised_sq[1],
        heading_normalised_sq: c.normalised_sq[2],
        heading_geometry_factor: c.predicted_rms_rad[2] / unit,
        integers: c.integers,
    }
}

/// Log-log slope of `y` against λσ/d over `rows` (undefined figures left out).
fn slope(rows: &[Row], y: impl Fn(&Row) -> f64) -> Option<f64> {
    // Pairs with both figures defined (a configuration without a fix has none).
    let (x, y): (Vec<f64>, Vec<f64>) = rows
        .iter()
        .map(|r| (r.lambda_sigma_over_d_rad, y(r)))
        .filter(|(a, b)| a.is_finite() && b.is_finite() && *a > 0.0 && *b > 0.0)
        .map(|(a, b)| (a.ln(), b.ln()))
        .unzip();
    linear_fit(&x, &y).map(|(s, _)| s)
}

/// The measurement with `settings` into the existing `out_dir` (plots); returns the summary
/// ([`Experiment::run_with`] writes it to `summary.json`).
fn measure(
    settings: &Settings,
    out_dir: &Path,
    progress: bool,
) -> Result<Summary, ExperimentError> {
    // The car's drive on the matched world (`drivers_sim::matched`): this checks the σ law of
    // the method against its own Monte Carlo, which needs the phases' errors to be the model's;
    // but with the receiver's carrier-phase tracking of the car's world (integers, slips,
    // lock time), which the integer resolution must undo.
    let shipped = Scenario::load(&scenario_path()).map_err(measurement)?;
    let phases = shipped
        .spec
        .world
        .and_then(|w| w.only(&["carrier_phase"]).ok())
        .filter(|w| w.carrier_phase().is_some())
        .ok_or_else(|| measurement("the car's world has no [world.carrier_phase]"))?;
    let car_world = shipped.clone();
    let mut base = drivers_sim::matched::scenario(shipped);
    base.spec.world = Some(phases);
    let mut jobs: Vec<(bool, f64, f64)> = settings
        .lengths_m
        .iter()
        .map(|&d| (true, d, settings.reference_sigma_cycles))
        .collect();
    jobs.extend(
        settings
            .sigmas_cycles
            .iter()
            .map(|&s| (false, settings.reference_length_m, s)),
    );
    let bar = progress_bar(progress, jobs.len() as u64, "baseline configurations");
    let results: Vec<Result<Config, ExperimentError>> = jobs
        .par_iter()
        .enumerate()
        .map(|(i, &(_, d, s))| {
            // An independent noise stream per configuration (the scenario seed + index).
            let seed = base.spec.scenario.seed + 1 + i as u64;
            let r = run_config(&base, d, (s, s), settings.epochs, seed);
            bar.inc(1);
            r
        })
        .collect();
    // The reference configuration on the car's whole world, its own noise stream (the same
    // for both solvers): weighted by the receiver's σ_φ, and by σ_φ with the installation's
    // multipath class.
    let sigma = settings.reference_sigma_cycles;
    let lambda = msgs::SPEED_OF_LIGHT_M_S / car_world.gnss.carrier_frequency_hz;
    let with_multipath = sigma.hypot(1e-3 * settings.installation_multipath_mm / lambda);
    let world_seed = base.spec.scenario.seed + 1 + jobs.len() as u64;
    let [on_world, on_world_weighted] = [sigma, with_multipath].map(|solver| {
        run_config(
            &car_world,
            settings.reference_length_m,
            (sigma, solver),
            settings.epochs,
            world_seed,
        )
    });
    let (on_world, on_world_weighted) = (on_world?, on_world_weighted?);
    bar.finish_and_clear();
    let (mut by_length, mut by_sigma) = (Vec::new(), Vec::new());
    for (job, r) in jobs.iter().zip(results) {
        let c = r?;
        if job.0 {
            by_length.push(row(&c));
        } else {
            by_sigma.push(row(&c));
        }
    }
    let worst_ratio = by_length
        .iter()
        .chain(&by_sigma)
        .flat_map(|r| r.by_axis().map(|(_, m, p, _)| (m / p - 1.0).abs()))
        .fold(0.0, f64::max);
    let summary = Summary {
        experiment: BaselineAttitude::NAME.into(),
        paper: "003".into(),
        scenario: "config/scenarios/vehicle.toml".into(),
        epochs_per_configuration: settings.epochs,
        slopes: Slopes::of(&by_length, &by_sigma),
        length_sweep: by_length,
        sigma_sweep: by_sigma,
        max_abs_measured_over_predicted_minus_one: worst_ratio,
        car_world: row(&on_world),
        car_world_multipath_weighted: row(&on_world_weighted),
        car_world_effects: super::world_effects(&car_world),
    };
    let mut lines = Vec::new();
    for (i, (label, rows)) in [
        ("length sweep", &summary.length_sweep),
        ("σ_φ sweep", &summary.sigma_sweep),
    ]
    .iter()
    .enumerate()
    {
        for j in 0..2 {
            // by_axis() order: heading, pitch.
            let axis = ["heading", "pitch"][j];
            let pts = |k: usize| -> Vec<(f64, f64)> {
                finite_points(rows.iter().map(|r| {
                    let a = r.by_axis()[j];
                    (r.lambda_sigma_over_d_rad, if k == 0 { a.1 } else { a.2 })
                }))
            };
            lines.push(
                Line::solid(
                    format!("{label} {axis} measured"),
                    pts(0),
                    color(2 * (2 * i + j)),
                )
                .with_markers(),
            );
            lines.push(Line::dashed(
                format!("{label} {axis} predicted σ"),
                pts(1),
                color(2 * (2 * i + j) + 1),
            ));
        }
    }
    line_chart(
        &out_dir.join("attitude_vs_lambda_sigma_over_d.png"),
        &Chart {
            title: "Dual-baseline GNSS attitude: RMS error vs λσ_φ/d",
            x_label: "λσ_φ/d = λσ_φ,rad/(2πd) [rad]",
            y_label: "RMS error [deg]",
            log_x: true,
            log_y: true,
            lines: &lines,
        },
    )?;
    Ok(summary)
}

/// Human table.
pub fn table(summary: &Summary) -> String {
    let mut out = String::from(
        "Dual-baseline GNSS attitude (paper 003): RMS error vs predicted σ, degrees\n\
         SIMULATED: the car's drive (config/scenarios/vehicle.toml) on the matched world with\n\
         the world effect carrier_phase on (unknown integers, cycle slips, lock time); integers\n\
         resolved by the unaided search (no attitude prior); figures over the fixed epochs\n\n",
    );
    out.push_str(&format!(
        "{:>6} {:>8} {:>10} | {:>9} {:>9} {:>6} | {:>9} {:>9} {:>6} | {:>9} {:>9} {:>6}\n",
        "d m",
        "σφ cyc",
        "λσ/d rad",
        "heading",
        "pred",
        "z²",
        "pitch",
        "pred",
        "z²",
        "roll",
        "pred",
        "z²"
    ));
    for sweep in [
        &summary.length_sweep,
        &summary.sigma_sweep,
        &vec![
            summary.car_world.clone(),
            summary.car_world_multipath_weighted.clone(),
        ],
    ] {
        for r in sweep {
            let mut line = format!(
                "{:>6} {:>8} {:>10}",
                fmt_f64(r.baseline_length_m, 2, false),
                fmt_f64(r.phase_sigma_cycles, 3, false),
                fmt_f64(r.lambda_sigma_over_d_rad, 2, true),
            );
            for (_, rms, predicted, z) in r.by_axis() {
                line += &format!(
                    " | {:>9} {:>9} {:>6}",
                    fmt_f64(rms, 2, true),
                    fmt_f64(predicted, 2, true),
                    fmt_f64(z, 2, false),
                );
            }
            out.push_str(&line);
            out.push('\n');
        }
        out.push('\n');
    }
    out.push_str(&format!(
        "the last two rows: the car's whole world ({}), the solver weighting by the receiver's σ_φ, then by σ_φ ⊕ the installation's multipath class ({} cycle)\n",
        summary.car_world_effects.join(", "),
        fmt_f64(summary.car_world_multipath_weighted.solver_phase_sigma_cycles, 4, false),
    ));
    out.push_str(&format!(
        "log-log slope of heading RMS vs λσ/d: length sweep {}, σ sweep {} (theory 1)\n",
        fmt_opt(
            summary.slopes.length_sweep_heading_rms_loglog_slope,
            3,
            false
        ),
        fmt_opt(
            summary.slopes.sigma_sweep_heading_rms_loglog_slope,
            3,
            false
        ),
    ));
    out.push_str(&format!(
        "\nInteger ambiguities ({} epochs at 1 Hz per configuration)\n\
         {:>6} {:>8} | {:>6} {:>6} {:>7} {:>5} {:>6} {:>5} {:>5} | {:>6} {:>6} | {:>6} {:>6} {:>5}\n",
        summary.epochs_per_configuration,
        "d m",
        "σφ cyc",
        "epochs",
        "fixed",
        "TTFF s",
        "wrong",
        "search",
        "float",
        "rej",
        "w.slip",
        "unflag",
        "lock",
        "resid",
        "sets",
    ));
    for (k, r) in summary
        .length_sweep
        .iter()
        .chain(&summary.sigma_sweep)
        .chain([&summary.car_world, &summary.car_world_multipath_weighted])
        .enumerate()
    {
        if k == summary.length_sweep.len() + summary.sigma_sweep.len() {
            out.push_str("on the car's whole world (solver σ_φ, then σ_φ ⊕ multipath class):\n");
        }
        let i = &r.integers;
        out.push_str(&format!(
            "{:>6} {:>8} | {:>6} {:>6} {:>7} {:>5} {:>6} {:>5} {:>5} | {:>6} {:>6} | {:>6} {:>6} {:>5}\n",
            fmt_f64(r.baseline_length_m, 2, false),
            fmt_f64(r.phase_sigma_cycles, 3, false),
            i.epochs_with_phases,
            i.fixed_epochs,
            fmt_opt(i.time_to_first_fix_s, 0, false),
            i.wrong_fix_epochs,
            i.search_fixes,
            i.float_only_epochs,
            i.rejected_epochs,
            i.world_slips,
            i.world_slips_unflagged,
            i.slips_flagged_seen,
            i.slips_found_by_residuals,
            i.held_sets_rejected,
        ));
    }
    out.push_str(
        "TTFF: first epoch with phases to first fix; wrong: fixed epochs holding an integer\n\
         other than the simulator's; search: fixes by a new search; float: ratio test or no\n\
         candidate; rej: other rejections (too few satellites, χ², too many candidates);\n\
         w.slip/unflag: the world's slips, and of those not flagged by the receiver; lock: held\n\
         satellites dropped on a lock-time restart (flagged slips, reacquisitions after the\n\
         outage); resid: dropped by the residual test (unflagged slips and the test's 0.1 %\n\
         false alarms); sets: held sets rejected whole\n",
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reduced run: d = 0.5, 1, 2 m at 0.01 cycle and σ_φ = 0.005, 0.02 cycle at 1 m, 200
    /// epochs each.
    /// * per axis the normalised squared error Σ(ε/σ)²/N is χ²(N)/N: within 1 ± 4√(2/N);
    /// * the predicted σ scales exactly as λσ_φ/d (J ∝ d, W ∝ 1/σ²) up to the geometry
    ///   evaluated at the estimate (relative change O(σ) < 1e-2): log-log slope 1 ± 0.01;
    /// * the measured RMS slope: each RMS has relative σ ≈ 1/√(2N) = 0.05, so over a factor
    ///   4 in λσ/d the slope of three points is within 1 ± 4·0.05·√2/ln 4 ≈ 1 ± 0.2.
    #[test]
    fn sigma_scales_as_lambda_sigma_over_d_and_matches_monte_carlo() {
        let settings = Settings {
            lengths_m: vec![0.5, 1.0, 2.0],
            sigmas_cycles: vec![0.005, 0.02],
            reference_length_m: 1.0,
            reference_sigma_cycles: 0.01,
            epochs: 200,
            installation_multipath_mm: INSTALLATION_MULTIPATH_MM,
        };
        let dir = crate::experiments::test_dir("baseline-attitude");
        let s = BaselineAttitude::run_with(&settings, &dir, false).expect("run");
        assert!(table(&s).contains("heading"));
        assert!(dir.join("attitude_vs_lambda_sigma_over_d.png").exists());
        for (sweep, rows) in [
            ("length_sweep", &s.length_sweep),
            ("sigma_sweep", &s.sigma_sweep),
        ] {
            assert!(!rows.is_empty(), "{sweep}");
            for r in rows {
                let n = r.epochs as f64;
                for (axis, _, _, z) in r.by_axis() {
                    assert!(
                        (z - 1.0).abs() < 4.0 * (2.0 / n).sqrt(),
                        "{sweep} {axis}: Σz²/N = {z}"
                    );
                }
            }
        }
        // The integers (σ_φ ≤ 0.02 cycle, d ≤ 2 m: every single-epoch search succeeds, the
        // wrong candidates lying ≥ 0.1 cycle = 5σ_φ off): fixed from the first epoch on,
        // never wrong; at least one slip of the world reached the resolver.
        let mut slips = 0;
        for r in s.length_sweep.iter().chain(&s.sigma_sweep) {
            let i = &r.integers;
            assert_eq!(i.wrong_fix_epochs, 0, "{i:?}");
            assert_eq!(i.time_to_first_fix_s, Some(0.0), "{i:?}");
            assert_eq!(i.fixed_epochs, i.epochs_with_phases, "{i:?}");
            slips += i.slips_flagged_seen + i.slips_found_by_residuals;
        }
        assert!(slips > 0);
        // On the car's whole world the phases also carry the antennas' multipath, which the
        // receiver's σ_φ leaves out: the solver weighting by σ_φ alone is optimistic (heading
        // Σz²/N above the χ² band) and fixes fewer epochs — but never a wrong integer.
        let w = &s.car_world;
        assert_eq!(w.integers.wrong_fix_epochs, 0, "{w:?}");
        assert!(w.epochs > 0, "{w:?}");
        assert!(
            w.heading_normalised_sq > 1.0 + 4.0 * (2.0 / w.epochs as f64).sqrt(),
            "{w:?}"
        );
        assert!(s.car_world_effects.iter().any(|e| e == "phase_multipath"));
        // Weighted with the installation's class the same run fixes more epochs, never wrong.
        let m = &s.car_world_multipath_weighted;
        assert_eq!(m.integers.wrong_fix_epochs, 0, "{m:?}");
        assert!(m.epochs > w.epochs, "{m:?}\n{w:?}");
        let sl = |x: Option<f64>| x.expect("slope");
        let slopes = &s.slopes;
        assert!((sl(slopes.length_sweep_heading_predicted_loglog_slope) - 1.0).abs() < 0.01);
        assert!((sl(slopes.sigma_sweep_heading_predicted_loglog_slope) - 1.0).abs() < 0.01);
        assert!((sl(slopes.length_sweep_heading_rms_loglog_slope) - 1.0).abs() < 0.2);
        assert!((sl(slopes.length_sweep_pitch_rms_loglog_slope) - 1.0).abs() < 0.2);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
