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

/// Declares the experiment of the module it is invoked in: the unit struct `$ty` implementing
/// [`Experiment`] by the module's items of the same names: `Settings` (its `Default` is the
/// full experiment), `Summary`, `table`, and `measure(settings, out_dir, progress)`, which
/// measures into an existing `out_dir` (its plots) and returns the summary; the generated
/// `run_with` creates `out_dir` before and writes `summary.json` after.
macro_rules! experiment {
    ($(#[$doc:meta])* $ty:ident, $name:literal, $description:literal) => {
        $(#[$doc])*
        pub struct $ty;

        impl $crate::experiments::Experiment for $ty {
            const NAME: &'static str = $name;
            const DESCRIPTION: &'static str = $description;
            type Settings = Settings;
            type Summary = Summary;
            fn run_with(
                settings: &Settings,
                out_dir: &std::path::Path,
                progress: bool,
            ) -> Result<Summary, $crate::experiments::ExperimentError> {
                $crate::experiments::create_out_dir(out_dir)?;
                let summary = measure(settings, out_dir, progress)?;
                $crate::experiments::write_summary(out_dir, &summary)?;
                Ok(summary)
            }
            fn table(summary: &Summary) -> String {
                table(summary)
            }
        }
    };
}

pub mod alignment;
pub mod all;
pub mod astro_calibration;
pub mod baseline_attitude;
pub mod consistency;
pub mod gnss_denied_astro;
pub mod gravity;
pub mod hybrid_berlin;
pub mod hybrid_esbc;
pub mod inertial_budget;
pub mod integrators;
pub mod plot;
pub mod redundancy;
pub mod schuler;
pub mod tight_coupling;
pub mod world_budget;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
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

/// One experiment of `sextant experiment NAME`: its name, what it reproduces, how it runs and
/// how its summary reads as a table.
pub trait Experiment {
    /// The name on the command line (`sextant experiment NAME`) and of its directory under
    /// `sextant experiment all`.
    const NAME: &'static str;
    /// One line about what it reproduces (the heading text of its section in RESULTS.md).
    const DESCRIPTION: &'static str;
    /// Its settings; the default is the full experiment.
    type Settings: Default;
    /// The figures it measures, under self-explaining names with their units in the name;
    /// written as `summary.json`.
    type Summary: Serialize + DeserializeOwned;
    /// Run with `settings` into `out_dir` (created if missing): `summary.json` and PNG plots;
    /// `progress` shows progress bars on stderr for the long loops.
    fn run_with(
        settings: &Self::Settings,
        out_dir: &Path,
        progress: bool,
    ) -> Result<Self::Summary, ExperimentError>;
    /// Run with the default settings (the full experiment).
    fn run(out_dir: &Path, progress: bool) -> Result<Self::Summary, ExperimentError> {
        Self::run_with(&Self::Settings::default(), out_dir, progress)
    }
    /// The human-readable table of `summary`.
    fn table(summary: &Self::Summary) -> String;
}

/// The registry: every experiment once, in the order of [`names`]. Generates [`Summary`] (one
/// variant per experiment, plus `all`), [`names`], [`run_by_name`] and [`describe`].
macro_rules! registry {
    ($($module:ident :: $experiment:ident => $variant:ident),* $(,)?) => {
        /// The typed summary of any experiment, as [`run_by_name`] returns it; it serialises as
        /// the experiment's own summary (`summary.json`).
        #[derive(Debug, Clone)]
        pub enum Summary {
            $(
                #[doc = concat!("`", stringify!($module), "`: [`", stringify!($module), "::Summary`].")]
                $variant($module::Summary),
            )*
            /// `all`: every experiment's summary by name.
            All(all::Summary),
        }

        /// Names of the experiments, in the order of the issue.
        pub fn names() -> &'static [&'static str] {
            &[$(<$module::$experiment as Experiment>::NAME),*]
        }

        /// One line about what experiment `name` reproduces; empty for an unknown name.
        pub fn describe(name: &str) -> &'static str {
            $(
                if name == <$module::$experiment as Experiment>::NAME {
                    return <$module::$experiment as Experiment>::DESCRIPTION;
                }
            )*
            ""
        }

        /// Run the experiment `name` (or `all`) into `out_dir` (created if missing); `progress`
        /// shows progress bars on stderr for the long loops. Returns the summary also written
        /// to `summary.json`.
        pub fn run_by_name(
            name: &str,
            out_dir: &Path,
            progress: bool,
        ) -> Result<Summary, ExperimentError> {
            $(
                if name == <$module::$experiment as Experiment>::NAME {
                    return <$module::$experiment as Experiment>::run(out_dir, progress)
                        .map(Summary::$variant);
                }
            )*
            if name == all::NAME {
                return all::run(out_dir, progress).map(Summary::All);
            }
            Err(unknown(name))
        }

        impl Summary {
            /// The name of the experiment this summary is of.
            pub fn name(&self) -> &'static str {
                match self {
                    $(Summary::$variant(_) => <$module::$experiment as Experiment>::NAME,)*
                    Summary::All(_) => all::NAME,
                }
            }

            /// The human-readable table of the summary.
            pub fn table(&self) -> String {
                match self {
                    $(Summary::$variant(s) => <$module::$experiment as Experiment>::table(s),)*
                    Summary::All(s) => all::table(s),
                }
            }

            /// The summary of experiment `name` read back from its `summary.json` document.
            pub fn from_value(
                name: &str,
                json: serde_json::Value,
            ) -> Result<Self, ExperimentError> {
                $(
                    if name == <$module::$experiment as Experiment>::NAME {
                        return Ok(Summary::$variant(serde_json::from_value(json)?));
                    }
                )*
                if name == all::NAME {
                    return Ok(Summary::All(serde_json::from_value(json)?));
                }
                Err(unknown(name))
            }
        }

        impl Serialize for Summary {
            fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
                match self {
                    $(Summary::$variant(s) => s.serialize(serializer),)*
                    Summary::All(s) => s.serialize(serializer),
                }
            }
        }
    };
}

registry! {
    integrators::Integrators => Integrators,
    schuler::Schuler => Schuler,
    gravity::Gravity => Gravity,
    consistency::Consistency => Consistency,
    astro_calibration::AstroCalibration => AstroCalibration,
    tight_coupling::TightCoupling => TightCoupling,
    gnss_denied_astro::GnssDeniedAstro => GnssDeniedAstro,
    alignment::Alignment => Alignment,
    baseline_attitude::BaselineAttitude => BaselineAttitude,
    redundancy::Redundancy => Redundancy,
    inertial_budget::InertialBudget => InertialBudget,
    hybrid_esbc::HybridEsbc => HybridEsbc,
    hybrid_berlin::HybridBerlin => HybridBerlin,
    world_budget::WorldBudget => WorldBudget,
}

fn unknown(name: &str) -> ExperimentError {
    ExperimentError::Unknown {
        name: name.to_string(),
        known: names().join(", "),
    }
}

/// Create `out_dir` and write `summary` as pretty JSON to `out_dir/summary.json`, its keys in
/// alphabetical order at every level (the order of the file does not depend on the order of
/// the struct's fields).
pub(crate) fn write_summary(
    out_dir: &Path,
    summary: &impl Serialize,
) -> Result<(), ExperimentError> {
    let path = out_dir.join("summary.json");
    let text = serde_json::to_string_pretty(&serde_json::to_value(summary)?)?;
    std::fs::write(&path, text + "\n").map_err(|source| ExperimentError::Io { path, source })
}

/// A shipped scenario file: `config/scenarios/NAME` of the repository.
pub(crate) fn scenario_file(name: &str) -> PathBuf {
    crate::shipped_config::scenario(name)
}

/// A step of the measurement that failed (a scenario that does not load, a solver that does
/// not converge), as an experiment error: `.map_err(measurement)?`.
/// What a simulated experiment's figures were measured on, for its table: the world effects
/// that were on (`effects`, from [`world_effects`]; truth only, the filter does not know
/// them), or the matched world.
pub(crate) fn world_line(effects: &[String]) -> String {
    if effects.is_empty() {
        "SIMULATED on the matched world (no [world]: every error is the filter's own model)".into()
    } else {
        format!(
            "SIMULATED, world effects on (truth only): {}",
            effects.join(", ")
        )
    }
}

/// The effects of `scn`'s `[world]` that are on (for a summary).
pub(crate) fn world_effects(scn: &drivers_sim::scenario::Scenario) -> Vec<String> {
    scn.spec
        .world
        .as_ref()
        .map(|w| w.effects_on().into_iter().map(String::from).collect())
        .unwrap_or_default()
}

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

/// A progress bar of `len` steps on stderr, hidden when `progress` is false (and see
/// [`crate::progress`]).
pub(crate) fn progress_bar(progress: bool, len: u64, what: &str) -> indicatif::ProgressBar {
    crate::progress::steps(progress, len, what)
}

/// `x` with `prec` decimals for a table (or `prec` significant digits in scientific notation
/// when `sci`); `–` when it is not finite (an undefined figure: `null` in `summary.json`).
pub(crate) fn fmt_f64(x: f64, prec: usize, sci: bool) -> String {
    match x {
        x if !x.is_finite() => "–".to_string(),
        x if sci => format!("{x:.prec$e}"),
        x => format!("{x:.prec$}"),
    }
}

/// [`fmt_f64`] of an optional figure: `–` when absent.
pub(crate) fn fmt_opt(x: Option<f64>, prec: usize, sci: bool) -> String {
    x.map_or_else(|| "–".to_string(), |x| fmt_f64(x, prec, sci))
}

/// A number from a JSON document for a table: the value at JSON pointer `ptr` formatted as
/// [`fmt_f64`] does, `–` if absent.
pub(crate) fn fmt_num(summary: &serde_json::Value, ptr: &str, prec: usize, sci: bool) -> String {
    fmt_opt(
        summary.pointer(ptr).and_then(serde_json::Value::as_f64),
        prec,
        sci,
    )
}

/// Serde of a figure that may be undefined (NaN, e.g. a maximum over no value): serde_json
/// writes a non-finite number as `null`; this reads `null` back as NaN. For
/// `#[serde(deserialize_with = "nan_if_null")]`.
pub(crate) fn nan_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// Serde of an optional entry whose value may be `null`: absent is `None`, `null` is
/// `Some(None)`. For `#[serde(default, skip_serializing_if = "Option::is_none",
/// deserialize_with = "present")]` on an `Option<Option<T>>`.
pub(crate) fn present<'de, D, T>(d: D) -> Result<Option<T>, D::Error>
where
    D: serde::Deserializer<'de>,
    T: Deserialize<'de>,
{
    T::deserialize(d).map(Some)
}

/// The mean of `values` that are finite (NaN when there is none).
pub(crate) fn mean_of_finite(values: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = values.filter(|v| v.is_finite()).collect();
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().sum::<f64>() / v.len() as f64
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
        assert!(Summary::from_value("nope", serde_json::json!({})).is_err());
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
            assert_eq!(summary.name(), *name);
            let table = summary.table();
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
