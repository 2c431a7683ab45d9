//! `sextant calibrate boresight REC.mcap --site LAT,LON,H`: star-tracker / IMU boresight
//! calibration (paper 000) over a recorded static log.
//!
//! The star-tracker and IMU channels are read with [`crate::recording`]. For every valid
//! star-tracker sample the IMU's vertical is levelled from the mean specific force of the IMU
//! samples in the preceding second (`fusion::alignment::level`); the heading, which only the
//! paper's stage 1 uses, is gyrocompassed once from the calibration window (first 600 s). Then:
//! the paper's three stages ([`fusion::boresight::three_stage`]) and Gauss–Newton least squares
//! over the window and over all samples ([`fusion::boresight::least_squares`]); each κ is
//! evaluated by the astro fixes of the samples after the window against the known site.
//! Celestial frames: full IAU 2006/2000A with zero EOP (UT1 = UTC), as the simulator.
//!
//! The record must be static (the procedure assumes a fixed site): a mean specific force far
//! from 1 g or a mean rate far from the Earth rate is an error.

use crate::experiments::plot::{Chart, Line, color, line_chart};
use crate::recorder::Record;
use crate::recording::{Recording, RecordingError};
use fusion::astro_fix::{AstroError, CelestialModel, astro_fix_unchecked};
use fusion::boresight::{
    self, BoresightSample, FixErrors, LeastSquaresSettings, Site, ThreeStageSettings,
};
use fusion::time::GpsTime;
use nalgebra::{Matrix3, Vector3};
use serde_json::{Value, json};
use std::path::{Path, PathBuf};

/// Why a calibration failed.
#[derive(Debug, thiserror::Error)]
pub enum CalibrateError {
    /// The recording could not be read at all.
    #[error(transparent)]
    Recording(#[from] RecordingError),
    /// The site argument is malformed.
    #[error("--site `{0}`: expected LAT,LON,H (degrees, degrees, metres)")]
    Site(String),
    /// The data does not allow a calibration (too few samples, not static…).
    #[error("{path}: {reason}")]
    Data {
        /// The recording.
        path: PathBuf,
        /// What is missing or wrong.
        reason: String,
    },
    /// The calibration math rejected the data.
    #[error("{path}: {source}")]
    Astro {
        /// The recording.
        path: PathBuf,
        /// The cause.
        source: AstroError,
    },
    /// Writing the output failed.
    #[error("{path}: {reason}")]
    Output {
        /// The file or directory.
        path: PathBuf,
        /// What failed.
        reason: String,
    },
}

/// The known site of the calibration (WGS-84).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SiteArg {
    /// Latitude, deg.
    pub lat_deg: f64,
    /// Longitude, deg.
    pub lon_deg: f64,
    /// Height, m (not used by the fix: the vertical's direction does not depend on it).
    pub height_m: f64,
}

impl std::str::FromStr for SiteArg {
    type Err = CalibrateError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || CalibrateError::Site(s.to_string());
        let v: Vec<f64> = s
            .split(',')
            .map(|p| p.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| bad())?;
        let [lat, lon, h] = v[..] else {
            return Err(bad());
        };
        if !(lat.is_finite()
            && lat.abs() <= 90.0
            && lon.is_finite()
            && lon.abs() <= 360.0
            && h.is_finite())
        {
            return Err(bad());
        }
        Ok(Self {
            lat_deg: lat,
            lon_deg: lon,
            height_m: h,
        })
    }
}

/// Settings of `sextant calibrate boresight`.
#[derive(Debug, Clone)]
pub struct BoresightOptions {
    /// The recording.
    pub recording: PathBuf,
    /// The known site.
    pub site: SiteArg,
    /// Output directory.
    pub out: PathBuf,
    /// Calibration window, s (paper: 600).
    pub window_s: f64,
}

/// The samples extracted from a recording.
#[derive(Debug, Clone)]
pub struct Extracted {
    /// Calibration samples (one per valid star-tracker sample with IMU data before it).
    pub samples: Vec<BoresightSample>,
    /// Mean star-tracker σ across / about the optical axis, rad.
    pub tracker_sigma_rad: (f64, f64),
    /// Star-tracker samples skipped (invalid, outage, or no IMU data in the second before).
    pub skipped: usize,
    /// IMU samples read.
    pub imu_samples: usize,
    /// Why reading stopped early (truncated or corrupt file), if it did.
    pub read_error: Option<String>,
}

/// Read the star-tracker and IMU channels of `path` and build calibration samples; the heading
/// is gyrocompassed from the first `window_s` at latitude `lat_rad`.
pub fn extract(path: &Path, lat_rad: f64, window_s: f64) -> Result<Extracted, CalibrateError> {
    let data = |reason: String| CalibrateError::Data {
        path: path.to_path_buf(),
        reason,
    };
    let mut imu: Vec<(i64, f64, Vector3<f64>, Vector3<f64>)> = Vec::new();
    let mut stars: Vec<(i64, Matrix3<f64>, f64, f64)> = Vec::new();
    let mut skipped = 0;
    let mut read_error = None;
    for e in Recording::open(path)? {
        let e = match e {
            Ok(e) => e,
            Err(err) => {
                read_error = Some(err.to_string());
                break;
            }
        };
        match e.record {
            Some(Record::Imu(s)) => {
                let da = Vector3::from(s.delta_angle_rad);
                let dv = Vector3::from(s.delta_velocity_m_s);
                if s.dt_s.is_finite()
                    && s.dt_s > 0.0
                    && da.iter().chain(dv.iter()).all(|v| v.is_finite())
                {
                    imu.push((s.header.time_ns, s.dt_s, da, dv));
                }
            }
            Some(Record::StarTracker(s)) => {
                let q = s.q_sensor_icrf;
                let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
                if s.valid == 0 || !(n.is_finite() && (n - 1.0).abs() < 1e-6) {
                    skipped += 1;
                    continue;
                }
                let c = fusion::attitude::quat_from_wire(&q)
                    .to_rotation_matrix()
                    .into_inner();
                stars.push((s.header.time_ns, c, s.sigma_cross_rad, s.sigma_roll_rad));
            }
            _ => {}
        }
    }
    imu.sort_by_key(|s| s.0);
    imu.dedup_by_key(|s| s.0);
    stars.sort_by_key(|s| s.0);
    stars.dedup_by_key(|s| s.0);
    if imu.is_empty() || stars.is_empty() {
        return Err(data(format!(
            "{} IMU and {} valid star-tracker samples: both channels are needed",
            imu.len(),
            stars.len()
        )));
    }
    // Heading (stage 1 only) and the static check from the window's IMU means.
    let t0 = imu[0].0;
    let win_ns = (window_s * 1e9) as i64;
    let (mut da, mut dv, mut dt) = (Vector3::zeros(), Vector3::zeros(), 0.0);
    for s in imu.iter().take_while(|s| s.0 - t0 <= win_ns) {
        da += s.2;
        dv += s.3;
        dt += s.1;
    }
    let omega = fusion::earth::WGS84.omega_ie_rad_s;
    let align = fusion::alignment::coarse_align(&(dv / dt), &(da / dt), lat_rad, omega)
        .map_err(|e| data(format!("not a static record: {e}")))?;
    // Per star sample: level from the IMU samples in (t − 1 s, t].
    let mut samples = Vec::with_capacity(stars.len());
    let (mut lo, mut hi) = (0usize, 0usize);
    let (mut sc, mut sr) = (0.0, 0.0);
    for (t, c, s_cross, s_roll) in &stars {
        while hi < imu.len() && imu[hi].0 <= *t {
            hi += 1;
        }
        while lo < hi && imu[lo].0 <= t - 1_000_000_000 {
            lo += 1;
        }
        if lo >= hi {
            skipped += 1;
            continue;
        }
        let f: Vector3<f64> = imu[lo..hi].iter().map(|s| s.3).sum::<Vector3<f64>>()
            / imu[lo..hi].iter().map(|s| s.1).sum::<f64>();
        let (roll, pitch) = fusion::alignment::level(&f);
        samples.push(BoresightSample {
            time: GpsTime { ns: *t },
            c_s_i: *c,
            roll_rad: roll,
            pitch_rad: pitch,
            heading_rad: align.heading_rad,
        });
        sc += s_cross;
        sr += s_roll;
    }
    let n = samples.len().max(1) as f64;
    Ok(Extracted {
        samples,
        tracker_sigma_rad: (sc / n, sr / n),
        skipped,
        imu_samples: imu.len(),
        read_error,
    })
}

fn errors_json(e: &FixErrors, kappa: &Vector3<f64>) -> Value {
    json!({
        "kappa_deg": [kappa.x.to_degrees(), kappa.y.to_degrees(), kappa.z.to_degrees()],
        "lat_error_mean_abs_deg": e.mean_abs_dlat_rad.to_degrees(),
        "lat_error_mean_abs_m": e.mean_abs_north_m,
        "lon_error_mean_abs_deg": e.mean_abs_dlon_rad.to_degrees(),
        "lon_error_mean_abs_m": e.mean_abs_east_m,
        "horizontal_error_rms_m": e.rms_horizontal_m,
        "mean_fix_error_m": e.mean_fix_error_m,
    })
}

/// Run the calibration; writes `summary.json` and PNG plots into `opts.out` and returns the
/// summary.
pub fn boresight(opts: &BoresightOptions) -> Result<Value, CalibrateError> {
    let path = &opts.recording;
    let site = Site {
        lat_rad: opts.site.lat_deg.to_radians(),
        lon_rad: opts.site.lon_deg.to_radians(),
    };
    let ex = extract(path, site.lat_rad, opts.window_s)?;
    let s = &ex.samples;
    let astro = |source| CalibrateError::Astro {
        path: path.clone(),
        source,
    };
    let win_end = s
        .iter()
        .position(|x| x.time.seconds_since(s[0].time) > opts.window_s)
        .unwrap_or(s.len());
    if win_end < 10 || s.len() - win_end < 10 {
        return Err(CalibrateError::Data {
            path: path.clone(),
            reason: format!(
                "{} usable samples, {} in the {} s window: need ≥ 10 in the window and ≥ 10 after it",
                s.len(),
                win_end,
                opts.window_s
            ),
        });
    }
    let c_e_i = boresight::c_e_i_of(s, &CelestialModel::Full(Default::default()));
    let three = ThreeStageSettings {
        window_s: opts.window_s,
        ..Default::default()
    };
    let r3 = boresight::three_stage(s, &c_e_i, &site, &three).map_err(astro)?;
    // White tilt noise of the 1-s levelling, from the data: RMS of successive differences / √2
    // (insensitive to the slow drift of the vertical).
    let diffs: Vec<f64> = s
        .windows(2)
        .flat_map(|w| {
            [
                w[1].roll_rad - w[0].roll_rad,
                w[1].pitch_rad - w[0].pitch_rad,
            ]
        })
        .collect();
    let sigma_tilt = (diffs.iter().map(|d| d * d).sum::<f64>() / diffs.len().max(1) as f64 / 2.0)
        .sqrt()
        .max(1e-7);
    let ls_settings = LeastSquaresSettings {
        sigma_tracker_cross_rad: ex.tracker_sigma_rad.0.max(1e-7),
        sigma_tracker_roll_rad: ex.tracker_sigma_rad.1.max(1e-7),
        sigma_tilt_rad: sigma_tilt,
        kappa_prior_rad: r3.initial.kappa_rad,
        sigma_prior_rad: 1f64.to_radians(),
        max_iterations: 20,
    };
    let ls_win = boresight::least_squares(&s[..win_end], &c_e_i[..win_end], &site, &ls_settings)
        .map_err(astro)?;
    let ls_all = boresight::least_squares(s, &c_e_i, &site, &ls_settings).map_err(astro)?;
    let eval = |k: &Vector3<f64>| {
        boresight::fix_errors(&s[win_end..], &c_e_i[win_end..], &site, k).map_err(astro)
    };
    let zero = Vector3::zeros();
    let methods = [
        ("uncalibrated", zero, eval(&zero)?),
        ("three_stage", r3.kappa_rad(), eval(&r3.kappa_rad())?),
        (
            "least_squares_window",
            ls_win.kappa_rad,
            eval(&ls_win.kappa_rad)?,
        ),
        (
            "least_squares_all_samples",
            ls_all.kappa_rad,
            eval(&ls_all.kappa_rad)?,
        ),
    ];
    let mut m = serde_json::Map::new();
    for (name, k, e) in &methods {
        m.insert((*name).into(), errors_json(e, k));
    }
    let ls_json = |r: &boresight::LeastSquaresResult| {
        json!({
            "kappa_sigma_deg": r.sigma_rad().iter().map(|v| v.to_degrees()).collect::<Vec<_>>(),
            "mounting_tilt_deg": [r.tilt_rad.x.to_degrees(), r.tilt_rad.y.to_degrees()],
            "mounting_tilt_sigma_deg": [
                r.tilt_covariance_rad2[(0, 0)].sqrt().to_degrees(),
                r.tilt_covariance_rad2[(1, 1)].sqrt().to_degrees(),
            ],
            "chi2_per_dof": r.chi2_per_dof,
            "iterations": r.iterations,
        })
    };
    let summary = json!({
        "recording": path.display().to_string(),
        "site": { "lat_deg": opts.site.lat_deg, "lon_deg": opts.site.lon_deg, "height_m": opts.site.height_m },
        "calibration_window_s": opts.window_s,
        "samples": s.len(),
        "samples_in_window": win_end,
        "evaluated_samples": s.len() - win_end,
        "star_tracker_samples_skipped": ex.skipped,
        "imu_samples": ex.imu_samples,
        "read_error": ex.read_error,
        "gyrocompass_heading_deg": s[0].heading_rad.to_degrees(),
        "tilt_noise_per_sample_deg": sigma_tilt.to_degrees(),
        "three_stage_iterations": r3.refinement.iterations,
        "three_stage_window_error_m": r3.refinement.error_m,
        "methods": Value::Object(m),
        "least_squares_window": ls_json(&ls_win),
        "least_squares_all_samples": ls_json(&ls_all),
    });
    std::fs::create_dir_all(&opts.out).map_err(|e| CalibrateError::Output {
        path: opts.out.clone(),
        reason: e.to_string(),
    })?;
    let sp = opts.out.join("summary.json");
    let text = serde_json::to_string_pretty(&summary).map_err(|e| CalibrateError::Output {
        path: sp.clone(),
        reason: e.to_string(),
    })?;
    std::fs::write(&sp, text + "\n").map_err(|e| CalibrateError::Output {
        path: sp.clone(),
        reason: e.to_string(),
    })?;
    // Plot: horizontal error of the single fixes (60 s means) per method over time.
    let (m_lat, m_lon) = site.metres_per_rad();
    let mut lines = Vec::new();
    for (i, (name, k, _)) in methods.iter().enumerate().skip(1) {
        let c_s_b = boresight::c_s_b_of_kappa(k);
        let pts: Vec<(f64, f64)> = s
            .chunks(60)
            .zip(c_e_i.chunks(60))
            .map(|(ch, ce)| {
                let (mut n, mut e) = (0.0, 0.0);
                for (x, c) in ch.iter().zip(ce) {
                    let f = astro_fix_unchecked(&x.c_s_i, x.roll_rad, x.pitch_rad, &c_s_b, c);
                    n += (f.lat_rad - site.lat_rad) * m_lat;
                    e += (f.lon_rad - site.lon_rad) * m_lon;
                }
                let k = ch.len() as f64;
                (
                    ch[0].time.seconds_since(s[0].time) / 60.0,
                    (n / k).hypot(e / k),
                )
            })
            .collect();
        lines.push(Line {
            label: (*name).replace('_', " "),
            points: pts,
            color: color(i),
            dashed: false,
            markers: false,
        });
    }
    let png = opts.out.join("calibrate_boresight_error_vs_time.png");
    line_chart(
        &png,
        &Chart::linear(
            "Astro fix error with the calibrated boresight (60 s means)",
            "time since start [min]",
            "horizontal error [m]",
            &lines,
        ),
    )
    .map_err(|e| CalibrateError::Output {
        path: png.clone(),
        reason: e.to_string(),
    })?;
    Ok(summary)
}

/// The table of a calibration summary.
pub fn table(summary: &Value) -> String {
    let f = |p: &str, d: usize| crate::experiments::fmt_num(summary, p, d, false);
    let mut out = format!(
        "Boresight calibration of {} ({} samples, {} in the {} s window)\n",
        summary["recording"].as_str().unwrap_or("?"),
        f("/samples", 0),
        f("/samples_in_window", 0),
        f("/calibration_window_s", 0),
    );
    out.push_str(&format!(
        "{:<28} | {:>9} {:>9} {:>9} | {:>9} {:>9} | {:>9}\n",
        "method", "κ1 [°]", "κ2 [°]", "κ3 [°]", "|Δφ| [m]", "|Δλ| [m]", "mean fix"
    ));
    for name in [
        "uncalibrated",
        "three_stage",
        "least_squares_window",
        "least_squares_all_samples",
    ] {
        let b = format!("/methods/{name}");
        out.push_str(&format!(
            "{:<28} | {:>9} {:>9} {:>9} | {:>9} {:>9} | {:>9}\n",
            name.replace('_', " "),
            f(&format!("{b}/kappa_deg/0"), 4),
            f(&format!("{b}/kappa_deg/1"), 4),
            f(&format!("{b}/kappa_deg/2"), 4),
            f(&format!("{b}/lat_error_mean_abs_m"), 0),
            f(&format!("{b}/lon_error_mean_abs_m"), 0),
            f(&format!("{b}/mean_fix_error_m"), 0),
        ));
    }
    out.push_str(&format!(
        "least squares (all samples): mounting tilt σ {}° / {}°, κ σ {}° {}° {}° (κ1 ≈ rotation about the vertical: not observable when static), χ²/dof {}\n",
        f("/least_squares_all_samples/mounting_tilt_sigma_deg/0", 5),
        f("/least_squares_all_samples/mounting_tilt_sigma_deg/1", 5),
        f("/least_squares_all_samples/kappa_sigma_deg/0", 3),
        f("/least_squares_all_samples/kappa_sigma_deg/1", 4),
        f("/least_squares_all_samples/kappa_sigma_deg/2", 4),
        f("/least_squares_all_samples/chi2_per_dof", 2),
    ));
    out.push_str("errors: mean over the fixes after the window; mean fix = distance of their mean from the site\n");
    if let Some(e) = summary["read_error"].as_str() {
        out.push_str(&format!("warning: the recording ends early: {e}\n"));
    }
    out
}
