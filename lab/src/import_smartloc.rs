//! `sextant import smartloc INPUT --reference GT --out REC.mcap`: a smartLoc drive (TU
//! Chemnitz; format in [`crate::smartloc`]) turned into a recording of Sextant's GNSS and
//! odometer samples, for `sextant replay --live REC --only gnss,odometer --follow-bus` into a
//! running bench whose scenario follows the drive's reference trajectory (the hybrid run of
//! `config/hybrid_berlin.toml`), or for `report`.
//!
//! The samples are exactly those `sextant experiment hybrid-berlin` fuses offline
//! ([`crate::smartloc::drive_samples`]): per epoch the GPS pseudoranges as the tight
//! coupling's observations (σ from the data's variance, satellite positions rotated into the
//! ECEF frame of reception) with the epoch's weighted least-squares fix for loose coupling; the
//! first sample carries the start fix of the alignment in motion (the reference's first
//! position and velocity, σ 0.5 m and 0.1 m/s); the odometer speeds over their intervals.
//!
//! Time base: the data count seconds from the start of the drive and carry no date. t = 0 is
//! the reference's first point — the `reference` trajectory's t = 0 — and lies at the
//! scenario's `start_utc` (default `config/scenarios/berlin_reference.toml`, whose date is
//! nominal), or at `--start-utc`. The pseudoranges' satellite positions come with the data, so
//! the date enters nothing they are compared with; it must only be the scenario's, so that the
//! real samples meet the simulated IMU at the same GPS time.

use crate::interchange::{self, InterchangeError, Streams};
use crate::smartloc::{self, DriveSamplesError, DriveScenarioError, SmartLocError, StartFix};
use drivers_sim::reference_trajectory::ReferenceError;
use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// What to import and how.
#[derive(Debug, Clone)]
pub struct ImportOptions {
    /// smartLoc input file (`pseudorange3` and `odom3` lines; plain or `.gz`).
    pub input: PathBuf,
    /// smartLoc ground-truth file (`point3` lines; plain or `.gz`).
    pub reference: PathBuf,
    /// The recording to write.
    pub out: PathBuf,
    /// Scenario whose `start_utc` is the time base, with a `reference` trajectory.
    pub scenario: PathBuf,
    /// Start epoch (UTC, `YYYY-MM-DDTHH:MM:SS[.fff]`) instead of the scenario's.
    pub start_utc: Option<String>,
    /// Filter configuration to embed (default: the built-in one).
    pub config: Option<PathBuf>,
    /// Also write the reference as a `reference` trajectory's points file (times from its
    /// first point), with the standstill intervals in its header.
    pub trajectory_out: Option<PathBuf>,
}

/// Figures of an import.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct ImportSummary {
    /// The reference's first point in the files' own time, s (the recording's t = 0).
    pub reference_start_in_file_s: f64,
    /// UTC of t = 0.
    pub start_utc: String,
    /// Length of the reference from its first point, s.
    pub duration_s: f64,
    /// GNSS samples written (one per pseudorange epoch).
    pub gnss_epochs: usize,
    /// GPS pseudoranges in them.
    pub gps_pseudoranges: usize,
    /// Pseudoranges of other systems left out.
    pub other_pseudoranges_left_out: usize,
    /// Epochs without a least-squares fix.
    pub epochs_without_fix: usize,
    /// Odometer samples written.
    pub odometer: usize,
    /// Standstill intervals (odometer zero), s from t = 0.
    pub standstill_s: Vec<[f64; 2]>,
    /// Reference points.
    pub reference_points: usize,
    /// Messages written.
    pub written: u64,
}

/// Why an import failed.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// A file could not be read.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A line of a file is malformed.
    #[error("{}: {source}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// Line and reason.
        source: SmartLocError,
    },
    /// The reference file has no point.
    #[error("{}: no point3 line (the reference gives the time origin and the start)", .0.display())]
    NoReference(PathBuf),
    /// The reference does not make a trajectory.
    #[error("{}: reference trajectory: {source}", path.display())]
    Trajectory {
        /// The reference file.
        path: PathBuf,
        /// Why.
        source: ReferenceError,
    },
    /// `--start-utc` is not a UTC instant.
    #[error(
        "--start-utc `{0}` is not a UTC calendar instant YYYY-MM-DDTHH:MM:SS[.fff] in 1980..=2100"
    )]
    StartUtc(String),
    /// The scenario cannot follow the drive.
    #[error(transparent)]
    Scenario(#[from] DriveScenarioError),
    /// The samples cannot be made.
    #[error("{}: {source}", path.display())]
    Samples {
        /// The input file.
        path: PathBuf,
        /// Why.
        source: DriveSamplesError,
    },
    /// The recording or the points file could not be written.
    #[error(transparent)]
    Write(#[from] InterchangeError),
}

fn read_text(path: &Path) -> Result<String, ImportError> {
    let raw = std::fs::read(path).map_err(|source| ImportError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    // gzip by its magic number, whatever the name.
    let gz = raw.starts_with(&[0x1f, 0x8b]);
    sextant_rinex::decode_text(&raw, gz).map_err(|source| ImportError::Io {
        path: path.to_path_buf(),
        source,
    })
}

fn parse_file(path: &Path) -> Result<smartloc::SmartLoc, ImportError> {
    smartloc::parse(&read_text(path)?).map_err(|source| ImportError::Parse {
        path: path.to_path_buf(),
        source,
    })
}

/// Import the drive of `opts` into a recording (and the points file, if asked).
pub fn import(opts: &ImportOptions) -> Result<ImportSummary, ImportError> {
    if let Some(t) = &opts.start_utc
        && fusion::time::parse_utc(t).is_none()
    {
        return Err(ImportError::StartUtc(t.clone()));
    }
    let mut data = parse_file(&opts.input)?;
    data.reference = parse_file(&opts.reference)?.reference;
    let t0_ms = data
        .from_reference_start()
        .ok_or_else(|| ImportError::NoReference(opts.reference.clone()))?;
    let spline = smartloc::reference_spline(&data).map_err(|source| ImportError::Trajectory {
        path: opts.reference.clone(),
        source,
    })?;
    let duration_s = spline.end_s();
    let scn = smartloc::drive_scenario(
        &opts.scenario,
        Arc::new(spline),
        duration_s,
        opts.start_utc.as_deref(),
    )?;
    let epoch = scn.epoch_gps().ns;
    let other_left_out = data
        .epochs
        .iter()
        .filter(|e| e.t_ms as f64 * 1e-3 <= duration_s)
        .flat_map(|e| &e.pseudoranges)
        .filter(|p| p.system != smartloc::SYSTEM_GPS)
        .count();
    let samples = smartloc::drive_samples(&data, epoch, duration_s, &StartFix::of_scenario(&scn))
        .map_err(|source| ImportError::Samples {
        path: opts.input.clone(),
        source,
    })?;
    let standstill_s = data.standstill_s();
    if let Some(p) = &opts.trajectory_out {
        write_points(p, &data, &standstill_s, opts)?;
    }
    let streams = Streams {
        gnss: samples.gnss.clone(),
        odometer: samples.odometer.clone(),
        ..Default::default()
    };
    let filter = interchange::filter_config(opts.config.as_deref())?;
    let provenance = BTreeMap::from([
        ("format".to_string(), "smartloc".to_string()),
        ("input".to_string(), opts.input.display().to_string()),
        (
            "reference".to_string(),
            opts.reference.display().to_string(),
        ),
        ("scenario".to_string(), opts.scenario.display().to_string()),
        ("start_utc".to_string(), scn.spec.scenario.start_utc.clone()),
        (
            "reference_start_in_file_s".to_string(),
            (t0_ms as f64 * 1e-3).to_string(),
        ),
    ]);
    let written = interchange::write_recording(&opts.out, &streams, &filter, provenance)?;
    Ok(ImportSummary {
        reference_start_in_file_s: t0_ms as f64 * 1e-3,
        start_utc: scn.spec.scenario.start_utc.clone(),
        duration_s,
        gnss_epochs: samples.gnss.len(),
        gps_pseudoranges: samples.gps_pseudoranges,
        other_pseudoranges_left_out: other_left_out,
        epochs_without_fix: samples.epochs_without_fix,
        odometer: samples.odometer.len(),
        standstill_s,
        reference_points: data.reference.len(),
        written,
    })
}

/// The reference as a `reference` trajectory's points file: `t_s x_m y_m z_m` (ECEF), times
/// from the first point, every number the shortest text that reads back to the same `f64`.
fn write_points(
    path: &Path,
    data: &smartloc::SmartLoc,
    standstill_s: &[[f64; 2]],
    opts: &ImportOptions,
) -> Result<(), ImportError> {
    let still = standstill_s
        .iter()
        // The data's millisecond times, written as such (21.9, not 21.900000000000002).
        .map(|w| format!("[{}, {}]", ms(w[0]), ms(w[1])))
        .collect::<Vec<_>>()
        .join(", ");
    let mut text = format!(
        "# Reference trajectory of {} for a scenario's [trajectory] kind = \"reference\":\n\
         # t_s x_m y_m z_m (ECEF), t from the first point. Where the odometer reads zero:\n\
         # still_s = [{still}]\n",
        opts.reference.display()
    );
    for p in data.reference_points() {
        let _ = writeln!(text, "{} {} {} {}", p.t_s, p.r_e_m.x, p.r_e_m.y, p.r_e_m.z);
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(InterchangeError::io(dir))?;
    }
    std::fs::write(path, text).map_err(InterchangeError::io(path))?;
    Ok(())
}

/// `t_s` rounded to the millisecond.
fn ms(t_s: f64) -> f64 {
    (t_s * 1e3).round() / 1e3
}

/// The summary as a table for the terminal.
pub fn format_table(s: &ImportSummary, out: &Path) -> String {
    let still = s
        .standstill_s
        .iter()
        .map(|w| format!("{:.1}–{:.1}", w[0], w[1]))
        .collect::<Vec<_>>()
        .join(", ");
    format!(
        "| GNSS epochs | GPS pseudoranges | other systems left out | without a fix | odometer | reference points | messages |\n\
         |---|---|---|---|---|---|---|\n\
         | {} | {} | {} | {} | {} | {} | {} |\n\
         t = 0: the reference's first point ({} s in the files) at {} UTC; {:.1} s of reference; \
         standing still (odometer zero): {}\nrecording: {}\n",
        s.gnss_epochs,
        s.gps_pseudoranges,
        s.other_pseudoranges_left_out,
        s.epochs_without_fix,
        s.odometer,
        s.reference_points,
        s.written,
        s.reference_start_in_file_s,
        s.start_utc,
        s.duration_s,
        if still.is_empty() { "none" } else { &still },
        out.display()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts(dir: &Path, input: &str, reference: &str) -> ImportOptions {
        let (i, r) = (dir.join("input.txt"), dir.join("gt.txt"));
        std::fs::write(&i, input).unwrap();
        std::fs::write(&r, reference).unwrap();
        ImportOptions {
            input: i,
            reference: r,
            out: dir.join("out.mcap"),
            scenario: crate::shipped_config::scenario("berlin_reference.toml"),
            start_utc: None,
            config: None,
            trajectory_out: None,
        }
    }

    /// Bad input is refused with the file and line named, before anything is written.
    #[test]
    fn errors_name_the_file_and_line() {
        let dir = crate::experiments::test_dir("import-smartloc");
        std::fs::create_dir_all(&dir).unwrap();
        let gt = "point3 0 3785108.1 899901.5 5037234.5\npoint3 0.2 3785107.9 899902.6 5037234.6\n";
        let o = opts(
            &dir,
            "odom3 0 5.85 0 0 0 0 0 0.0025 0 0 0 0 0\nodom3 0.2 x 0 0 0 0 0 0.0025 0 0 0 0 0\n",
            gt,
        );
        let e = import(&o).unwrap_err().to_string();
        assert!(e.contains("input.txt: line 2") && e.contains("`x`"), "{e}");
        let o = opts(&dir, "", "# no points\n");
        let e = import(&o).unwrap_err().to_string();
        assert!(e.contains("gt.txt") && e.contains("no point3"), "{e}");
        let o = ImportOptions {
            start_utc: Some("2021-13-01T00:00:00".into()),
            ..opts(&dir, "", gt)
        };
        let e = import(&o).unwrap_err().to_string();
        assert!(e.contains("--start-utc"), "{e}");
        assert!(!dir.join("out.mcap").exists());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
