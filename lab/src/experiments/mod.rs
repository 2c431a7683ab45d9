//! The "Inertial foundations" experiments of paper 002 (strapdown INS algorithm, error equations
//! in the inertial frame; digest in SEEDS.md): what `sextant experiment NAME --out DIR` runs.
//!
//! - [`integrators`]: Euler, Heun and RK4 on trajectories with an exact solution; observed
//!   convergence orders and ranking.
//! - [`schuler`]: free-inertial navigation at a static site: the Schuler period of the
//!   horizontal error (84.4 min) and the divergence time constant of the free vertical channel.
//! - [`gravity`]: the J2 gravity model against normal gravity (Somigliana + free air) and a
//!   point mass, over latitude and height.
//!
//! Every experiment is pure math over the `fusion` API (no I/O except its results): it writes
//! `summary.json` (figures under self-explaining names with their units in the name) and PNG
//! plots into the output directory, and returns the summary so that the caller can print it
//! with the experiment's `table`.

pub mod alignment;
pub mod all;
pub mod astro_calibration;
pub mod baseline_attitude;
pub mod consistency;
pub mod gnss_denied_astro;
pub mod gravity;
pub mod inertial_budget;
pub mod integrators;
pub mod plot;
pub mod redundancy;
pub mod schuler;
pub mod tight_coupling;

use std::path::{Path, PathBuf};

/// Why an experiment failed.
#[derive(Debug, thiserror::Error)]
pub enum ExperimentError {
    /// No experiment of that name (see [`names`]).
    #[error("unknown experiment {name:?}; known: {known}")]
    Unknown {
        /// The requested name.
        name: String,
        /// The known names, comma-separated.
        known: String,
    },
    /// Creating the output directory or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Serialising the summary failed.
    #[error("summary: {0}")]
    Json(#[from] serde_json::Error),
    /// Drawing a plot failed.
    #[error("plot {path}: {detail}")]
    Plot {
        /// The PNG file.
        path: PathBuf,
        /// What failed.
        detail: String,
    },
    /// The data did not allow the measurement (e.g. too few zero crossings, a non-positive
    /// error in a logarithm, invalid settings).
    #[error("measurement: {0}")]
    Measurement(String),
}

/// Names of the experiments, in the order of the issue.
pub fn names() -> &'static [&'static str] {
    &[
        "integrators",
        "schuler",
        "gravity",
        "consistency",
        "astro-calibration",
        "tight-coupling",
        "gnss-denied-astro",
        "alignment",
        "baseline-attitude",
        "redundancy",
        "inertial-budget",
    ]
}

/// Run the experiment `name` into `out_dir` (created if missing); `progress` shows progress
/// bars on stderr for the long loops. Returns the summary also written to `summary.json`.
pub fn run_by_name(
    name: &str,
    out_dir: &Path,
    progress: bool,
) -> Result<serde_json::Value, ExperimentError> {
    match name {
        "integrators" => integrators::run(out_dir, progress),
        "schuler" => schuler::run(out_dir, progress),
        "gravity" => gravity::run(out_dir, progress),
        "consistency" => consistency::run(out_dir, progress),
        "tight-coupling" => tight_coupling::run(out_dir, progress),
        "gnss-denied-astro" => gnss_denied_astro::run(out_dir, progress),
        "astro-calibration" => astro_calibration::run(out_dir, progress),
        "alignment" => alignment::run(out_dir, progress),
        "baseline-attitude" => baseline_attitude::run(out_dir, progress),
        "redundancy" => redundancy::run(out_dir, progress),
        "inertial-budget" => inertial_budget::run(out_dir, progress),
        "all" => all::run(out_dir, progress),
        _ => Err(unknown(name)),
    }
}

/// The human-readable table of experiment `name`'s summary.
pub fn table_by_name(name: &str, summary: &serde_json::Value) -> Result<String, ExperimentError> {
    match name {
        "integrators" => Ok(integrators::table(summary)),
        "schuler" => Ok(schuler::table(summary)),
        "gravity" => Ok(gravity::table(summary)),
        "consistency" => Ok(consistency::table(summary)),
        "tight-coupling" => Ok(tight_coupling::table(summary)),
        "gnss-denied-astro" => Ok(gnss_denied_astro::table(summary)),
        "astro-calibration" => Ok(astro_calibration::table(summary)),
        "alignment" => Ok(alignment::table(summary)),
        "baseline-attitude" => Ok(baseline_attitude::table(summary)),
        "redundancy" => Ok(redundancy::table(summary)),
        "inertial-budget" => Ok(inertial_budget::table(summary)),
        "all" => Ok(all::table(summary)),
        _ => Err(unknown(name)),
    }
}

fn unknown(name: &str) -> ExperimentError {
    ExperimentError::Unknown {
        name: name.to_string(),
        known: names().join(", "),
    }
}

/// Create `out_dir` and write `summary` as pretty JSON to `out_dir/summary.json`.
pub(crate) fn write_summary(
    out_dir: &Path,
    summary: &serde_json::Value,
) -> Result<(), ExperimentError> {
    let path = out_dir.join("summary.json");
    let text = serde_json::to_string_pretty(summary)?;
    std::fs::write(&path, text + "\n").map_err(|source| ExperimentError::Io { path, source })
}

/// A shipped scenario file: `config/scenarios/NAME` of the repository.
pub(crate) fn scenario_file(name: &str) -> PathBuf {
    crate::shipped_config::scenario(name)
}

/// A step of the measurement that failed (a scenario that does not load, a solver that does
/// not converge), as an experiment error: `.map_err(measurement)?`.
pub(crate) fn measurement(e: impl std::fmt::Display) -> ExperimentError {
    ExperimentError::Measurement(e.to_string())
}

/// Create the output directory.
pub(crate) fn create_out_dir(out_dir: &Path) -> Result<(), ExperimentError> {
    std::fs::create_dir_all(out_dir).map_err(|source| ExperimentError::Io {
        path: out_dir.to_path_buf(),
        source,
    })
}

/// A progress bar of `len` steps on stderr, hidden when `progress` is false.
pub(crate) fn progress_bar(progress: bool, len: u64, what: &str) -> indicatif::ProgressBar {
    if !progress {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len);
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "{msg:28} [{bar:40}] {percent:>3}% {elapsed_precise} eta {eta}",
    ) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message(what.to_string());
    bar
}

/// A number from a summary for a table: the value at JSON pointer `ptr` formatted with
/// `prec` decimals (or `prec` significant digits in scientific notation when `sci`), `–` if
/// absent.
pub(crate) fn fmt_num(summary: &serde_json::Value, ptr: &str, prec: usize, sci: bool) -> String {
    match summary.pointer(ptr).and_then(serde_json::Value::as_f64) {
        Some(x) if sci => format!("{x:.prec$e}"),
        Some(x) => format!("{x:.prec$}"),
        None => "–".to_string(),
    }
}

/// Least-squares slope and intercept of `y` against `x`; `None` with fewer than two distinct
/// abscissae.
pub(crate) fn linear_fit(x: &[f64], y: &[f64]) -> Option<(f64, f64)> {
    let n = x.len().min(y.len());
    if n < 2 {
        return None;
    }
    let mx = x[..n].iter().sum::<f64>() / n as f64;
    let my = y[..n].iter().sum::<f64>() / n as f64;
    let (mut sxx, mut sxy) = (0.0, 0.0);
    for i in 0..n {
        sxx += (x[i] - mx) * (x[i] - mx);
        sxy += (x[i] - mx) * (y[i] - my);
    }
    if sxx <= 0.0 {
        return None;
    }
    let slope = sxy / sxx;
    Some((slope, my - slope * mx))
}

#[cfg(test)]
pub(crate) fn test_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "sextant-experiment-{name}-{}-{}",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0)
    ));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn registry_rejects_unknown_names() {
        assert!(names().starts_with(&["integrators", "schuler", "gravity"]));
        let dir = test_dir("unknown");
        let err = run_by_name("nope", &dir, false).err();
        assert!(
            matches!(err, Some(ExperimentError::Unknown { .. })),
            "{err:?}"
        );
        assert!(table_by_name("nope", &serde_json::json!({})).is_err());
        assert!(!dir.exists());
    }

    /// The full-length runs, timed: `cargo test --release -p sextant-lab --lib
    /// full_length -- --ignored --nocapture` (seconds in release mode). With
    /// `SEXTANT_EXPERIMENT_KEEP=DIR` the results are kept in `DIR/NAME`.
    #[test]
    #[ignore]
    fn full_length_runs() {
        let keep = std::env::var_os("SEXTANT_EXPERIMENT_KEEP").map(PathBuf::from);
        for name in names() {
            let dir = match &keep {
                Some(k) => k.join(name),
                None => test_dir(&format!("full-{name}")),
            };
            let t0 = std::time::Instant::now();
            let summary = run_by_name(name, &dir, false).expect("run");
            let table = table_by_name(name, &summary).expect("table");
            eprintln!("{name}: {:.2} s\n{table}", t0.elapsed().as_secs_f64());
            if keep.is_none() {
                let _ = std::fs::remove_dir_all(&dir);
            }
        }
    }

    #[test]
    fn linear_fit_recovers_a_line() {
        let x = [0.0, 1.0, 2.0, 3.0];
        let y: Vec<f64> = x.iter().map(|x| 2.5 * x - 1.0).collect();
        let (s, c) = linear_fit(&x, &y).expect("fit");
        assert!((s - 2.5).abs() < 1e-12 && (c + 1.0).abs() < 1e-12);
        assert!(linear_fit(&[1.0], &[1.0]).is_none());
        assert!(linear_fit(&[1.0, 1.0], &[1.0, 2.0]).is_none());
    }
}
