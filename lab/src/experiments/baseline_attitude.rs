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
//! Theory: a phase difference in cycles gives the baseline projection `λΔφ` with σ `λσ_φ`
//! (in radians of phase, `λσ_φ,rad/(2π)`), and an angle error δ tilts a baseline of length d
//! by `d·δ`, so every attitude σ is `λσ_φ/d` (= `λσ_φ,rad/(2π d)`) times a geometry factor of
//! the lines of sight. Figures: per configuration the RMS error of heading, pitch and roll,
//! the RMS of the predicted σ, and the normalised error `Σ(ε/σ)²/N` per axis (χ²(N)/N: 1 ±
//! 4√(2/N) at 4σ); log-log slopes of RMS error against `λσ_φ/d` along both sweeps (theory: 1).

use super::plot::{Chart, Line, color, line_chart};
use super::{ExperimentError, create_out_dir, fmt_num, linear_fit, progress_bar, write_summary};
use drivers_sim::scenario::Scenario;
use drivers_sim::sources::GnssSource;
use drivers_sim::truth::{TruthGenerator, wrap_pi};
use fusion::baseline_attitude::{BaselineConfig, PhaseObservations, solve};
use rayon::prelude::*;
use serde_json::{Value, json};
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
        }
    }
}

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
    wavelength_m: f64,
    epochs: usize,
    rms_rad: [f64; 3],
    predicted_rms_rad: [f64; 3],
    normalised_sq: [f64; 3],
}

fn run_config(
    base: &Scenario,
    length_m: f64,
    sigma_cycles: f64,
    epochs: usize,
    seed: u64,
) -> Result<Config, ExperimentError> {
    let mut scn = base.clone();
    scn.spec.scenario.seed = seed;
    scn.gnss.baseline_length_m = [length_m, length_m];
    scn.gnss.phase_sigma_cycles = sigma_cycles;
    let mut src = GnssSource::new(&scn, scn.epoch_gps().ns);
    let mut truth = TruthGenerator::new(&scn);
    let (mut se, mut sp, mut sz) = ([0.0; 3], [0.0; 3], [0.0; 3]);
    let mut n = 0usize;
    let mut wavelength = 0.0;
    for k in 0..epochs as i64 {
        let t_ns = k * 1_000_000_000;
        let (msg, _) = src.sample_with_truth(t_ns);
        truth.advance_to(t_ns);
        let tp = truth.current();
        if msg.fix_valid == 0 {
            continue;
        }
        let fix = fusion::gnss_ls::solve_sample(&msg).map_err(measurement)?;
        let obs = PhaseObservations::from_sample(&msg, &fix.position.r_e_m).map_err(measurement)?;
        let cfg = BaselineConfig {
            baseline_length_m: msg.baseline_length_m,
            wavelength_m: msg.wavelength_m,
            sigma_phase_cycles: sigma_cycles,
        };
        wavelength = msg.wavelength_m;
        let a = solve(&obs, &cfg, &fix.position.r_e_m, None).map_err(measurement)?;
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
    if n == 0 {
        return Err(measurement("no epoch with a GNSS fix"));
    }
    let nf = n as f64;
    Ok(Config {
        length_m,
        sigma_cycles,
        wavelength_m: wavelength,
        epochs: n,
        rms_rad: se.map(|x| (x / nf).sqrt()),
        predicted_rms_rad: sp.map(|x| (x / nf).sqrt()),
        normalised_sq: sz.map(|x| x / nf),
    })
}

/// Run with the default settings.
pub fn run(out_dir: &Path, progress: bool) -> Result<Value, ExperimentError> {
    run_with(out_dir, progress, &Settings::default())
}

fn row(c: &Config) -> Value {
    let unit = c.wavelength_m * c.sigma_cycles / c.length_m;
    json!({
        "baseline_length_m": c.length_m,
        "phase_sigma_cycles": c.sigma_cycles,
        "lambda_sigma_over_d_rad": unit,
        "epochs": c.epochs,
        "roll_rms_deg": c.rms_rad[0] * DEG,
        "pitch_rms_deg": c.rms_rad[1] * DEG,
        "heading_rms_deg": c.rms_rad[2] * DEG,
        "roll_predicted_deg": c.predicted_rms_rad[0] * DEG,
        "pitch_predicted_deg": c.predicted_rms_rad[1] * DEG,
        "heading_predicted_deg": c.predicted_rms_rad[2] * DEG,
        "roll_normalised_sq": c.normalised_sq[0],
        "pitch_normalised_sq": c.normalised_sq[1],
        "heading_normalised_sq": c.normalised_sq[2],
        "heading_geometry_factor": c.predicted_rms_rad[2] / unit,
    })
}

/// Log-log slope of `key` against λσ/d over `rows`.
fn slope(rows: &[Value], key: &str) -> Option<f64> {
    let x: Vec<f64> = rows
        .iter()
        .filter_map(|r| r["lambda_sigma_over_d_rad"].as_f64().map(f64::ln))
        .collect();
    let y: Vec<f64> = rows
        .iter()
        .filter_map(|r| r[key].as_f64().map(f64::ln))
        .collect();
    linear_fit(&x, &y).map(|(s, _)| s)
}

/// Run with `settings`.
pub fn run_with(
    out_dir: &Path,
    progress: bool,
    settings: &Settings,
) -> Result<Value, ExperimentError> {
    create_out_dir(out_dir)?;
    let base = Scenario::load(&scenario_path()).map_err(measurement)?;
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
            let r = run_config(&base, d, s, settings.epochs, seed);
            bar.inc(1);
            r
        })
        .collect();
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
    let mut slopes = serde_json::Map::new();
    for (name, rows) in [("length", &by_length), ("sigma", &by_sigma)] {
        for axis in ["heading", "pitch", "roll"] {
            if let Some(s) = slope(rows, &format!("{axis}_rms_deg")) {
                slopes.insert(format!("{name}_sweep_{axis}_rms_loglog_slope"), json!(s));
            }
            if let Some(s) = slope(rows, &format!("{axis}_predicted_deg")) {
                slopes.insert(
                    format!("{name}_sweep_{axis}_predicted_loglog_slope"),
                    json!(s),
                );
            }
        }
    }
    let all: Vec<&Value> = by_length.iter().chain(&by_sigma).collect();
    let worst_ratio = all
        .iter()
        .flat_map(|r| {
            ["heading", "pitch", "roll"].map(|a| {
                let m = r[format!("{a}_rms_deg")].as_f64().unwrap_or(f64::NAN);
                let p = r[format!("{a}_predicted_deg")].as_f64().unwrap_or(f64::NAN);
                (m / p - 1.0).abs()
            })
        })
        .fold(0.0, f64::max);
    let summary = json!({
        "experiment": "baseline-attitude",
        "paper": "003",
        "scenario": "config/scenarios/vehicle.toml",
        "epochs_per_configuration": settings.epochs,
        "length_sweep": by_length,
        "sigma_sweep": by_sigma,
        "slopes": slopes,
        "max_abs_measured_over_predicted_minus_one": worst_ratio,
    });
    write_summary(out_dir, &summary)?;
    let mut lines = Vec::new();
    for (i, (label, rows)) in [("length sweep", &by_length), ("σ_φ sweep", &by_sigma)]
        .iter()
        .enumerate()
    {
        for (j, axis) in ["heading", "pitch"].iter().enumerate() {
            let pts = |key: &str| -> Vec<(f64, f64)> {
                rows.iter()
                    .filter_map(|r| {
                        Some((r["lambda_sigma_over_d_rad"].as_f64()?, r[key].as_f64()?))
                    })
                    .collect()
            };
            lines.push(Line {
                label: format!("{label} {axis} measured"),
                points: pts(&format!("{axis}_rms_deg")),
                color: color(2 * (2 * i + j)),
                dashed: false,
                markers: true,
            });
            lines.push(Line {
                label: format!("{label} {axis} predicted σ"),
                points: pts(&format!("{axis}_predicted_deg")),
                color: color(2 * (2 * i + j) + 1),
                dashed: true,
                markers: false,
            });
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
pub fn table(summary: &Value) -> String {
    let mut out = String::from(
        "Dual-baseline GNSS attitude (paper 003): RMS error vs predicted σ, degrees\n\n",
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
    for sweep in ["length_sweep", "sigma_sweep"] {
        let n = summary[sweep].as_array().map_or(0, |a| a.len());
        for i in 0..n {
            let p = |k: &str, prec: usize, sci: bool| {
                fmt_num(summary, &format!("/{sweep}/{i}/{k}"), prec, sci)
            };
            out.push_str(&format!(
                "{:>6} {:>8} {:>10} | {:>9} {:>9} {:>6} | {:>9} {:>9} {:>6} | {:>9} {:>9} {:>6}\n",
                p("baseline_length_m", 2, false),
                p("phase_sigma_cycles", 3, false),
                p("lambda_sigma_over_d_rad", 2, true),
                p("heading_rms_deg", 2, true),
                p("heading_predicted_deg", 2, true),
                p("heading_normalised_sq", 2, false),
                p("pitch_rms_deg", 2, true),
                p("pitch_predicted_deg", 2, true),
                p("pitch_normalised_sq", 2, false),
                p("roll_rms_deg", 2, true),
                p("roll_predicted_deg", 2, true),
                p("roll_normalised_sq", 2, false),
            ));
        }
        out.push('\n');
    }
    out.push_str(&format!(
        "log-log slope of heading RMS vs λσ/d: length sweep {}, σ sweep {} (theory 1)\n",
        fmt_num(
            summary,
            "/slopes/length_sweep_heading_rms_loglog_slope",
            3,
            false
        ),
        fmt_num(
            summary,
            "/slopes/sigma_sweep_heading_rms_loglog_slope",
            3,
            false
        ),
    ));
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
        };
        let dir = crate::experiments::test_dir("baseline-attitude");
        let s = run_with(&dir, false, &settings).expect("run");
        assert!(table(&s).contains("heading"));
        assert!(dir.join("attitude_vs_lambda_sigma_over_d.png").exists());
        for sweep in ["length_sweep", "sigma_sweep"] {
            for r in s[sweep].as_array().unwrap() {
                let n = r["epochs"].as_f64().unwrap();
                for axis in ["heading", "pitch", "roll"] {
                    let z = r[format!("{axis}_normalised_sq")].as_f64().unwrap();
                    assert!(
                        (z - 1.0).abs() < 4.0 * (2.0 / n).sqrt(),
                        "{sweep} {axis}: Σz²/N = {z}"
                    );
                }
            }
        }
        let sl = |k: &str| s["slopes"][k].as_f64().unwrap();
        assert!((sl("length_sweep_heading_predicted_loglog_slope") - 1.0).abs() < 0.01);
        assert!((sl("sigma_sweep_heading_predicted_loglog_slope") - 1.0).abs() < 0.01);
        assert!((sl("length_sweep_heading_rms_loglog_slope") - 1.0).abs() < 0.2);
        assert!((sl("length_sweep_pitch_rms_loglog_slope") - 1.0).abs() < 0.2);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
