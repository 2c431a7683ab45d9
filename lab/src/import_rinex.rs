//! `sextant import rinex OBS NAV --out REC.mcap`: a RINEX 3 observation file and its GPS
//! broadcast navigation file turned into a Sextant recording of `GnssSample` messages, one per
//! epoch, written through the runtime's recorder so that `report` and `replay` read it.
//!
//! Each epoch is fixed by [`fusion::point_positioning`] (single-frequency L1 C/A with Klobuchar,
//! or the L1/L2 ionosphere-free code, Saastamoinen troposphere, elevation mask) and written
//! with the message's measurement model (`msgs::GnssSatellite`: the pseudorange is the
//! geometric range plus c·receiver clock bias plus errors, the satellite position is at
//! transmission, rotated into the ECEF frame of reception):
//! * `pseudorange_m`: the measured code with the broadcast satellite clock (and `T_GD` for L1)
//!   and the modelled ionosphere and troposphere removed — what the filter's tight coupling
//!   and `gnss_ls` expect; the raw code is `pseudorange_m` plus these corrections;
//! * `range_rate_m_s`: `−λ_L1 · D1` plus the satellite clock drift;
//! * `sigma_*`: the weighting model of the fix (orbit/clock accuracy, C/N0, elevation,
//!   model residuals);
//! * `header.time_ns`: the receiver epoch corrected by the fix's clock bias to GPS time;
//! * `pos_ecef_m`, `vel_ecef_m_s`, covariances, `pdop`: the least-squares fix of the antenna
//!   reference point (`fix_valid` = 0 for an epoch that could not be fixed, its satellites
//!   then absent).
//!
//! The recording embeds the default filter configuration (so `replay --offline` runs without
//! `--config`) and, under `sextant/import`, the source files, station and options.

use crate::recorder::{
    CONFIG_KEY_FILTER_TOML, CONFIG_METADATA_NAME, Record, Recorder, RecorderError, RecorderOptions,
};
use fusion::broadcast_ephemeris::SPEED_OF_LIGHT_M_S;
use fusion::gnss_ls::{FLAG_DOPPLER, FLAG_PSEUDORANGE};
use fusion::navigator::NavigatorConfig;
use fusion::point_positioning::{Ionosphere, PointPositioningSettings, PointSolution, solve_epoch};
use msgs::{GnssSample, GnssSatellite, Header, MAX_SATELLITES};
use serde::Serialize;
use sextant_rinex::measurements::{GpsCodes, MissingCode, epoch_measurements};
use sextant_rinex::{NavigationFile, ObservationFile};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Metadata record name of the import's provenance.
pub const IMPORT_METADATA_NAME: &str = "sextant/import";

/// Errors of the import.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// An input file could not be read or parsed.
    #[error(transparent)]
    Rinex(#[from] sextant_rinex::FileError),
    /// A needed observation code is absent.
    #[error("{path}: {source}")]
    Code {
        /// The observation file.
        path: PathBuf,
        /// Which code.
        source: MissingCode,
    },
    /// The navigation file has no Klobuchar coefficients but the mode needs them.
    #[error("{0}: no IONOSPHERIC CORR GPSA/GPSB in the header (needed for --mode l1)")]
    NoKlobuchar(PathBuf),
    /// The recording could not be written.
    #[error(transparent)]
    Recorder(#[from] RecorderError),
    /// The default filter configuration could not be serialized.
    #[error("filter configuration: {0}")]
    Config(String),
}

/// Which code solution to compute.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum ImportMode {
    /// L1 C/A code with T_GD and the broadcast Klobuchar ionosphere.
    L1,
    /// L1 C/A and L2 P(Y) (C1C/C2W) ionosphere-free combination.
    IonoFree,
}

/// What to import and how.
#[derive(Debug, Clone)]
pub struct ImportOptions {
    /// RINEX 3 observation file (`.rnx` or `.rnx.gz`).
    pub observation: PathBuf,
    /// RINEX 3 navigation file with the GPS ephemerides.
    pub navigation: PathBuf,
    /// The recording to write.
    pub out: PathBuf,
    /// Code solution.
    pub mode: ImportMode,
    /// Elevation mask, degrees.
    pub elevation_mask_deg: f64,
}

/// Figures of an import.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct ImportSummary {
    /// Marker name of the observation file.
    pub marker: String,
    /// Epochs read.
    pub epochs: usize,
    /// Epochs with a valid fix.
    pub fixed: usize,
    /// Epochs whose fix failed, with the first reason.
    pub failed: usize,
    /// First failure, if any.
    pub first_failure: Option<String>,
    /// Mean number of satellites used per fixed epoch.
    pub mean_satellites: f64,
    /// GPS ephemerides read.
    pub ephemerides: usize,
    /// Messages written.
    pub written: u64,
}

/// The `GnssSample` of one epoch's solution.
pub fn sample_of(sol: &PointSolution, t_rx: fusion::time::GpsTime, seq: u64) -> GnssSample {
    let p = &sol.fix.position;
    let mut s = GnssSample {
        header: Header {
            time_ns: t_rx.ns - (p.clock_bias_m / SPEED_OF_LIGHT_M_S * 1e9).round() as i64,
            seq,
            ..Default::default()
        },
        fix_valid: 1,
        n_satellites: sol.n_used.min(MAX_SATELLITES) as u32,
        pos_ecef_m: p.r_e_m.into(),
        pdop: p.dop.pdop,
        ..Default::default()
    };
    s.header.send_mono_ns = s.header.time_ns.max(0) as u64;
    for r in 0..3 {
        for c in 0..3 {
            s.pos_cov_ecef_m2[3 * r + c] = p.cov_r_e_m2[(r, c)];
        }
    }
    if let Some(v) = &sol.fix.velocity {
        s.vel_ecef_m_s = v.v_e_m_s.into();
        for r in 0..3 {
            for c in 0..3 {
                s.vel_cov_ecef_m2_s2[3 * r + c] = v.cov_v_e_m2_s2[(r, c)];
            }
        }
    }
    for (k, u) in sol.used().iter().enumerate() {
        s.satellites[k] = GnssSatellite {
            prn: u.prn as u32,
            flags: FLAG_PSEUDORANGE | if u.has_range_rate { FLAG_DOPPLER } else { 0 },
            pseudorange_m: u.corrected_pseudorange_m,
            range_rate_m_s: u.corrected_range_rate_m_s,
            cn0_dbhz: u.cn0_dbhz,
            sigma_pseudorange_m: u.sigma_m,
            sigma_range_rate_m_s: if u.has_range_rate {
                u.sigma_range_rate_m_s
            } else {
                0.0
            },
            sat_pos_ecef_m: u.state.pos_ecef_m.into(),
            sat_vel_ecef_m_s: u.state.vel_ecef_m_s.into(),
            baseline_phase_cycles: [0.0; 2],
            phase_lock_time_s: [0.0; 2],
        };
    }
    s
}

/// The GNSS samples of every epoch of `obs` (the fix and its satellites, see the module
/// comment; an epoch that cannot be fixed gives an invalid sample without satellites), with the
/// import's counters. `obs_path` and `nav_path` name the files in errors.
pub fn epoch_samples(
    obs: &ObservationFile,
    nav: &NavigationFile,
    mode: ImportMode,
    elevation_mask_deg: f64,
    obs_path: &Path,
    nav_path: &Path,
) -> Result<(Vec<GnssSample>, ImportSummary), ImportError> {
    let hidden = indicatif::ProgressBar::hidden();
    epoch_samples_showing(
        obs,
        nav,
        mode,
        elevation_mask_deg,
        (obs_path, nav_path),
        &hidden,
    )
}

/// [`epoch_samples`], advancing `bar` by one per epoch.
fn epoch_samples_showing(
    obs: &ObservationFile,
    nav: &NavigationFile,
    mode: ImportMode,
    elevation_mask_deg: f64,
    (obs_path, nav_path): (&Path, &Path),
    bar: &indicatif::ProgressBar,
) -> Result<(Vec<GnssSample>, ImportSummary), ImportError> {
    let l2 = matches!(mode, ImportMode::IonoFree).then_some("C2W");
    let codes = GpsCodes::select(obs, "C1C", l2).map_err(|source| ImportError::Code {
        path: obs_path.to_path_buf(),
        source,
    })?;
    let ionosphere = match mode {
        ImportMode::L1 => Ionosphere::Klobuchar(
            nav.klobuchar
                .ok_or_else(|| ImportError::NoKlobuchar(nav_path.to_path_buf()))?,
        ),
        ImportMode::IonoFree => Ionosphere::IonoFree,
    };
    let settings = PointPositioningSettings {
        elevation_mask_rad: elevation_mask_deg.to_radians(),
        ionosphere,
        ..Default::default()
    };
    let mut summary = ImportSummary {
        marker: obs.header.marker_name.clone(),
        epochs: obs.epochs.len(),
        ephemerides: nav.gps.len(),
        ..Default::default()
    };
    let mut sats_total = 0usize;
    let mut samples = Vec::with_capacity(obs.epochs.len());
    for (seq, e) in obs.epochs.iter().enumerate() {
        let meas = epoch_measurements(e, &codes);
        let sample = match solve_epoch(e.time, &meas, &nav.gps, &settings) {
            Ok(sol) => {
                summary.fixed += 1;
                sats_total += sol.n_used;
                sample_of(&sol, e.time, seq as u64)
            }
            Err(err) => {
                summary.failed += 1;
                summary
                    .first_failure
                    .get_or_insert_with(|| format!("epoch {} ns: {err}", e.time.ns));
                GnssSample {
                    header: Header {
                        time_ns: e.time.ns,
                        seq: seq as u64,
                        send_mono_ns: e.time.ns.max(0) as u64,
                        ..Default::default()
                    },
                    ..Default::default()
                }
            }
        };
        samples.push(sample);
        bar.inc(1);
    }
    bar.finish_and_clear();
    summary.mean_satellites = if summary.fixed > 0 {
        sats_total as f64 / summary.fixed as f64
    } else {
        0.0
    };
    Ok((samples, summary))
}

/// The antenna reference point of the observation file's marker, ECEF m: the header's
/// `APPROX POSITION XYZ` plus `ANTENNA: DELTA H` along the ellipsoid normal (what a code
/// solution without an antenna phase-centre model estimates); `None` without a position.
pub fn antenna_reference_point(obs: &ObservationFile) -> Option<nalgebra::Vector3<f64>> {
    use fusion::earth::{self, WGS84};
    let marker = nalgebra::Vector3::from(obs.header.approx_position_m?);
    let g = earth::ecef_to_geodetic(&WGS84, &marker);
    Some(marker + obs.header.antenna_delta_hen_m[0] * earth::up_e(g.lat_rad, g.lon_rad))
}

/// Import the files of `opts` into a recording.
pub fn import_rinex(opts: &ImportOptions) -> Result<ImportSummary, ImportError> {
    let obs = sextant_rinex::read_observation(&opts.observation)?;
    let nav = sextant_rinex::read_navigation(&opts.navigation)?;
    let bar = crate::progress::steps(true, obs.epochs.len() as u64, "fixing epochs");
    let (samples, mut summary) = epoch_samples_showing(
        &obs,
        &nav,
        opts.mode,
        opts.elevation_mask_deg,
        (&opts.observation, &opts.navigation),
        &bar,
    )?;
    let filter_toml = toml::to_string(&NavigatorConfig::default())
        .map_err(|e| ImportError::Config(e.to_string()))?;
    let mut config_meta = BTreeMap::new();
    config_meta.insert(CONFIG_KEY_FILTER_TOML.to_string(), filter_toml);
    let mut import_meta = BTreeMap::new();
    let mut put = |k: &str, v: String| {
        import_meta.insert(k.to_string(), v);
    };
    put("observation", opts.observation.display().to_string());
    put("navigation", opts.navigation.display().to_string());
    put("marker", obs.header.marker_name.clone());
    if let Some(p) = obs.header.approx_position_m {
        put(
            "approx_position_ecef_m",
            format!("{} {} {}", p[0], p[1], p[2]),
        );
    }
    let d = obs.header.antenna_delta_hen_m;
    put("antenna_delta_hen_m", format!("{} {} {}", d[0], d[1], d[2]));
    put("mode", format!("{:?}", opts.mode));
    put("elevation_mask_deg", opts.elevation_mask_deg.to_string());
    let recorder = Recorder::start(
        &opts.out,
        &RecorderOptions {
            metadata: vec![
                (CONFIG_METADATA_NAME.to_string(), config_meta),
                (IMPORT_METADATA_NAME.to_string(), import_meta),
            ],
            ..Default::default()
        },
    )?;
    for sample in samples {
        let mono = sample.header.send_mono_ns;
        recorder.record_blocking(Record::Gnss(Box::new(sample)), mono);
    }
    let stats = recorder.finish()?;
    summary.written = stats.written;
    Ok(summary)
}

/// The summary as a table for the terminal.
pub fn format_table(s: &ImportSummary, out: &Path) -> String {
    let mut t = format!(
        "| station | epochs | fixed | failed | mean satellites | GPS ephemerides | messages |\n|---|---|---|---|---|---|---|\n| {} | {} | {} | {} | {:.1} | {} | {} |\n",
        s.marker, s.epochs, s.fixed, s.failed, s.mean_satellites, s.ephemerides, s.written
    );
    if let Some(f) = &s.first_failure {
        t.push_str(&format!("first failure: {f}\n"));
    }
    t.push_str(&format!("recording: {}\n", out.display()));
    t
}
