//! Experiment `gnss-denied-astro` (paper 000: the star tracker plus the accelerometers' vertical
//! give the position; paper 002: the error equations that say how well): 10 hours at the paper
//! 000 site (`config/scenarios/astro_10h.toml`, static, navigation-grade IMU), no GNSS at all,
//! the start position given (surveyed point, σ 10 m). Two runs on the same samples
//! ([`drivers_sim::offline`]):
//!
//! - **astro-inertial**: star tracker (5″ cross-axis, 40″ about the boresight, 5 Hz) + baro;
//! - **free inertial**: baro only (the vertical channel is unstable without it).
//!
//! Zero-velocity updates are off in both (they would use the knowledge that the vehicle is
//! static, which a ship or a vehicle does not have); odometer and NHC likewise.
//!
//! # The floor, from the error model ([`fusion::ekf`], ECEF)
//! `δv̇ = G·δr − 2[ω_ie×]·δv − [f_e×]·ψ − C_e_b·δb_a − C_e_b·n_a`, `ψ̇ = −[ω_ie×]·ψ − C_e_b·δb_g`.
//! The stars measure ψ directly, so ψ stays at the estimation-noise level and the gyro bias
//! becomes observable (ψ's drift). Nothing measures δr, δv or the horizontal accelerometer bias
//! (the horizontal `δb_a` and a position offset enter `δv̇` only as their combination):
//!
//! 1. **Bias floor** — the equilibrium of the horizontal channel (`δv = 0`, ψ ≈ 0, vertical held
//!    by the baro) is `G_hh·δr_h = (C_n_b·δb_a)_h`; with `G_hh ≈ −(g/R)·I` (Schuler),
//!    `δr_h ≈ −R·(C_n_b δb_a)_h / g`: the astro fix's "1′ of vertical ≈ 1 nmi", with the
//!    accelerometer bias tilting the sensed vertical by `δb/g`. Computed at every epoch from the
//!    true bias minus the filter's estimate and the model's own gravity gradient
//!    (`fusion::ekf::gravity_gradient`), so it includes the bias random walk and temperature.
//!    For 50 µg per axis: R·δb/g ≈ 320 m per axis. The Earth's real gravity field adds its own
//!    term: the INS computes the normal gravity, so the site's gravity disturbance δg (truth,
//!    `[world.gravity]`) acts as an accelerometer error of `−δg`, and the floor is
//!    `G_hh⁻¹ (C_n_b δb_a − δg)_h`: a deflection of the vertical θ moves it by `R·θ` (5″ ≈
//!    155 m), which no star can see — the astronomer's classical astro-geodetic difference.
//! 2. **Noise term** — the residual tilt noise and the accelerometer white noise drive the
//!    (undamped) Schuler oscillator. Tilt: a random walk of density `q = ARW²` observed with
//!    white noise `σ_st²` at rate f (continuous `R_c = σ_st²/f`) has the steady-state variance
//!    `P_ψ = √(q R_c)` and correlation time `τ = √(R_c/q)` — that is, `σ_st/√N` with
//!    `N = f·τ` star samples averaged — and so a low-frequency acceleration density
//!    `g²·2P_ψτ`; the accelerometer adds `VRW²`. White acceleration of density S makes an
//!    undamped oscillator of frequency `ω_s = √(g/R)` diffuse as `σ_r² = S·t/(2ω_s²)` per axis.
//!    With the navigation-grade numbers this is tens of metres after 10 h: the bias term
//!    dominates.
//! 3. **Bound** — the run starts at equilibrium's opposite corner (position known, velocity
//!    zero, the first star updates remove the levelling error into which alignment had folded
//!    the bias), so the horizontal error oscillates with the Schuler period around the floor
//!    vector with an amplitude equal to it: `|δr_h| ≤ 2·|floor| + 3σ_noise`, and its mean over
//!    whole Schuler periods is the floor vector itself. (An astro position fix inside the
//!    filter would damp the oscillation and leave the floor alone.)
//!
//! Free inertial, in contrast, integrates the gyro bias into tilt and azimuth errors: its
//! horizontal error grows without bound (km after hours for 0.01°/h).
//!
//! Two effects beyond the three items, both visible in the run: the baro observes the east
//! velocity through the Coriolis term (`2Ω cosφ·δv_E` in the vertical), which damps the
//! oscillation over hours and makes the bias slowly observable, so the floor itself shrinks;
//! and with the boresight as free filter states a static run cannot separate tilt from
//! boresight, the stars no longer fix the vertical, and the error sits near zero instead of
//! the floor (the accelerometer level, bias included, defines the vertical) — the boresight
//! states are therefore off here (mount calibrated).
//!
//! # Measured (seed 7, 10 h, IMU 100 Hz, the stand's world of `astro_10h.toml`)
//! Floor 332 m mean (976 m max, early, before the bias estimate improves), of which the
//! site's deflection of the vertical (4.4″ east) alone makes 137 m; noise term σ 38 m at 10 h,
//! bound 2064 m. Astro-inertial: max 947 m, final 339 m, mean error over the 7 whole Schuler
//! periods (−233.0, 252.2) m against the floor's (−226.9, 240.2) m. Free inertial: 20.2 km at
//! 10 h. (On the matched world: floor 231 m mean, astro-inertial max 780 m, free 5.3 km.)

use super::consistency::{filter_config, load_scenario};
use super::plot::{Chart, Line, color, line_chart};
use super::{Experiment, ExperimentError, fmt_f64, fmt_opt, nan_if_null, progress_bar};
use drivers_sim::offline::{OfflineSim, RunPoint, run_navigator};
use drivers_sim::scenario::Scenario;
use drivers_sim::sources::{ImuSource, SampleSource};
use fusion::earth::{WGS84, normal_gravity};
use fusion::ekf::gravity_gradient;
use fusion::navigator::Navigator;
use msgs::Channel;
use nalgebra::{Matrix2, Vector2, Vector3};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One arcsecond, rad.
const ARCSEC_RAD: f64 = std::f64::consts::PI / 180.0 / 3600.0;

/// Settings of the experiment.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Scenario name in `config/scenarios`.
    pub scenario: String,
    /// Duration override, s (None: the file's 10 h).
    pub duration_s: Option<f64>,
    /// IMU rate override, Hz (None: the file's).
    pub imu_rate_hz: Option<f64>,
    /// Also run free inertial (the comparison; the reduced test leaves it out).
    pub free_inertial: bool,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            scenario: "astro_10h".to_string(),
            duration_s: None,
            imu_rate_hz: None,
            free_inertial: true,
        }
    }
}

/// One epoch of a run.
#[derive(Debug, Clone, Copy)]
struct Sample {
    t_s: f64,
    err_h_m: f64,
    err_ne_m: Vector2<f64>,
    sigma_h_m: f64,
    floor_ne_m: Vector2<f64>,
    /// True and estimated accelerometer bias in NED, µg.
    bias_true_ned_ug: nalgebra::Vector3<f64>,
    bias_est_ned_ug: nalgebra::Vector3<f64>,
    bias_truth_ned_ug: nalgebra::Vector3<f64>,
}

/// The horizontal equilibrium (bias floor) vector in NED north/east, m, at point `p`:
/// `δr_h = G_hh⁻¹ (C_n_b δf − δg)_h` with `δf` the accelerometer triad's effective error (body,
/// m/s²) minus the filter's bias estimate and `δg` the site's gravity disturbance (NED, m/s²:
/// the INS computes the normal gravity, so a deflection of the vertical acts as a bias of
/// `−δg`).
fn floor_ne(
    p: &RunPoint,
    accel_error_b: &Vector3<f64>,
    gravity_disturbance_n: &Vector3<f64>,
) -> Vector2<f64> {
    let g_n = p.c_e_n.transpose() * gravity_gradient(&WGS84, &p.pos_true_e_m) * p.c_e_n;
    let g_hh = Matrix2::new(g_n[(0, 0)], g_n[(0, 1)], g_n[(1, 0)], g_n[(1, 1)]);
    let db_n = p.c_n_b_true * (accel_error_b - p.accel_bias_est_m_s2) - gravity_disturbance_n;
    g_hh.try_inverse()
        .map(|inv| inv * Vector2::new(db_n.x, db_n.y))
        .unwrap_or_else(|| Vector2::repeat(f64::NAN))
}

/// Effective error of the accelerometer triad, body, m/s², per whole second of the run (index
/// k: the mean over `[k − 60, k)` s): the simulated IMU's delta-velocities minus those of the
/// same IMU with its error model switched off. Unlike the truth's bias it includes every
/// static error the model has (bias, its random walk and temperature term, and the axis
/// misalignment and scale factor acting on gravity: 10″ of misalignment alone tilts the
/// sensed vertical like a 48 µg bias).
fn effective_accel_error(scn: &Scenario) -> Vec<Vector3<f64>> {
    let epoch = scn.epoch_gps().ns;
    let mut real = ImuSource::new(scn, epoch);
    let mut ideal = ImuSource::new(scn, epoch);
    ideal.model.enabled = false;
    let period = real.period_ns();
    let n_s = (scn.duration_ns() / 1_000_000_000) as usize + 1;
    let mut per_s = vec![Vector3::zeros(); n_s];
    let mut k = real.first_index();
    while k * period <= scn.duration_ns() {
        let t = k * period;
        let (a, b) = (real.sample(t), ideal.sample(t));
        // The interval ending at t lies in second ⌈t⌉ − 1.
        let sec = ((t - 1) / 1_000_000_000) as usize;
        if let Some(acc) = per_s.get_mut(sec) {
            *acc += Vector3::from(a.delta_velocity_m_s) - Vector3::from(b.delta_velocity_m_s);
        }
        k += 1;
    }
    // Trailing 60 s mean, indexed by the second that ends it.
    let mut out = vec![Vector3::zeros(); n_s];
    let mut sum = Vector3::zeros();
    for i in 0..n_s {
        sum += per_s[i];
        if i >= 60 {
            sum -= per_s[i - 60];
        }
        if i + 1 < n_s {
            out[i + 1] = sum / (i + 1).min(60) as f64;
        }
    }
    out
}

fn one_run(
    scn: &Scenario,
    stars: bool,
    bar: &indicatif::ProgressBar,
) -> Result<Vec<RunPoint>, ExperimentError> {
    let site = scn.spec.site;
    let cfg = filter_config(&[
        ("updates.star_tracker", toml::Value::Boolean(stars)),
        // The mounting is calibrated (paper 000's procedure, `sextant calibrate`): with the
        // boresight as free states a static run cannot tell a tilt from a boresight angle,
        // and the stars would no longer fix the vertical (module comment).
        ("states.boresight", toml::Value::Boolean(false)),
        ("updates.zupt", toml::Value::Boolean(false)),
        ("updates.odometer", toml::Value::Boolean(false)),
        ("updates.nonholonomic", toml::Value::Boolean(false)),
        (
            "initial_position",
            toml::Value::Table(toml::Table::from_iter([
                ("lat_deg".to_string(), toml::Value::Float(site.lat_deg)),
                ("lon_deg".to_string(), toml::Value::Float(site.lon_deg)),
                ("height_m".to_string(), toml::Value::Float(site.height_m)),
            ])),
        ),
    ])?;
    let channels: &[Channel] = if stars {
        &[
            Channel::StarTracker,
            Channel::Baro,
            Channel::Imu,
            Channel::Truth,
        ]
    } else {
        &[Channel::Baro, Channel::Imu, Channel::Truth]
    };
    let sim = OfflineSim::with_channels(scn, channels);
    let epoch = sim.epoch_ns();
    let mut nav = Navigator::new(super::consistency::installed(scn, cfg)?)
        .map_err(|e| ExperimentError::Measurement(format!("navigator: {e}")))?;
    let mut out = Vec::new();
    let mut last_tick = 0.0;
    run_navigator(sim, epoch, &mut nav, |p| {
        out.push(*p);
        if p.t_s - last_tick >= 60.0 {
            bar.inc((p.t_s - last_tick) as u64);
            last_tick = p.t_s;
        }
    })
    .map_err(|e| ExperimentError::Measurement(e.to_string()))?;
    Ok(out)
}

/// The epochs of a run with the floor of the effective accelerometer error `accel_error` and
/// the site's gravity disturbance `dg_n` (NED, m/s²).
fn samples(points: &[RunPoint], accel_error: &[Vector3<f64>], dg_n: &Vector3<f64>) -> Vec<Sample> {
    points
        .iter()
        .map(|p| {
            let e = p.pos_err_ned_m();
            let eff = accel_error
                .get(p.t_s.round() as usize)
                .unwrap_or(&p.accel_bias_true_m_s2);
            Sample {
                t_s: p.t_s,
                err_h_m: p.horizontal_error_m(),
                err_ne_m: Vector2::new(e.x, e.y),
                sigma_h_m: p.horizontal_sigma_m(),
                floor_ne_m: floor_ne(p, eff, dg_n),
                bias_true_ned_ug: p.c_n_b_true * eff / 9.806_65e-6,
                bias_est_ned_ug: p.c_n_b_true * p.accel_bias_est_m_s2 / 9.806_65e-6,
                bias_truth_ned_ug: p.c_n_b_true * p.accel_bias_true_m_s2 / 9.806_65e-6,
            }
        })
        .collect()
}

/// Closed-form noise term (item 2 of the module comment): per-axis σ of the horizontal
/// position after `t_s`, m, for the scenario's IMU and star tracker.
fn noise_sigma_per_axis_m(scn: &Scenario, t_s: f64, with_stars: bool) -> f64 {
    let g = normal_gravity(
        &WGS84,
        scn.spec.site.lat_deg.to_radians(),
        scn.spec.site.height_m,
    );
    let r = WGS84.a_m * (1.0 - WGS84.f / 2.0) + scn.spec.site.height_m;
    let omega_s2 = g / r;
    let deg = std::f64::consts::PI / 180.0;
    let arw_rad_sqrt_s = scn.imu.gyro.arw_deg_per_rt_h * deg / 60.0;
    let vrw_m_s2_sqrt_hz = scn.imu.accel.vrw_ug_per_rt_hz * 1e-6 * 9.806_65;
    let mut s = vrw_m_s2_sqrt_hz.powi(2);
    if with_stars {
        let sigma_st = scn.star_tracker.sigma_cross_arcsec * deg / 3600.0;
        let rc = sigma_st.powi(2) / scn.spec.star_tracker.rate_hz;
        let q = arw_rad_sqrt_s.powi(2);
        let p_psi = (q * rc).sqrt();
        let tau = (rc / q).sqrt();
        s += g * g * 2.0 * p_psi * tau;
    }
    (s * t_s / (2.0 * omega_s2)).sqrt()
}

/// The closed forms of the module comment at the end of the run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Floor {
    /// Mean over the run of the bias floor's magnitude `|G_hh⁻¹ δf_h|`, m.
    pub bias_floor_mean_m: f64,
    /// Its maximum, m.
    pub bias_floor_max_m: f64,
    /// Radial 1σ of the noise term with the star tracker, m.
    pub noise_sigma_at_end_astro_m: f64,
    /// Radial 1σ of the VRW term alone (free inertial), m.
    pub noise_sigma_at_end_free_vrw_only_m: f64,
    /// `2·floor_max + 3σ_noise`, m.
    pub bound_2_floor_plus_3_sigma_m: f64,
    /// The site's deflection of the vertical (the world's gravity field, truth), north and
    /// east components of `−δg_h/g`, arcsec; zero without `[world.gravity]`.
    #[serde(default)]
    pub deflection_arcsec: [f64; 2],
    /// The part of the floor the deflection alone makes, `|G_hh⁻¹ δg_h|`, m.
    #[serde(default)]
    pub deflection_floor_m: f64,
}

/// The astro-inertial run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AstroRun {
    /// Horizontal error at the end, m.
    pub final_horizontal_error_m: f64,
    /// Largest horizontal error, m.
    pub max_horizontal_error_m: f64,
    /// The filter's horizontal σ at the end, m.
    pub final_horizontal_sigma_m: f64,
    /// Mean north error over the whole Schuler periods, m (undefined with none).
    #[serde(deserialize_with = "nan_if_null")]
    pub mean_error_north_over_whole_periods_m: f64,
    /// Mean east error over the whole Schuler periods, m.
    #[serde(deserialize_with = "nan_if_null")]
    pub mean_error_east_over_whole_periods_m: f64,
    /// Mean north floor over the same epochs, m.
    #[serde(deserialize_with = "nan_if_null")]
    pub mean_floor_north_over_whole_periods_m: f64,
    /// Mean east floor over the same epochs, m.
    #[serde(deserialize_with = "nan_if_null")]
    pub mean_floor_east_over_whole_periods_m: f64,
    /// How far the floor moves from its mean over those epochs, m.
    #[serde(deserialize_with = "nan_if_null")]
    pub floor_spread_over_whole_periods_m: f64,
    /// |mean error − mean floor|, m.
    #[serde(deserialize_with = "nan_if_null")]
    pub mean_error_minus_mean_floor_m: f64,
    /// The largest error is within the bound.
    pub within_bound: bool,
    /// Effective accelerometer error at the end, NED, µg.
    pub accel_effective_error_ned_at_end_ug: [f64; 3],
    /// The truth's accelerometer bias at the end, NED, µg.
    pub accel_bias_of_truth_ned_at_end_ug: [f64; 3],
    /// The filter's accelerometer bias estimate at the end, NED, µg.
    pub accel_bias_estimate_ned_at_end_ug: [f64; 3],
}

/// The free-inertial run (inertial + baro, no star tracker).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FreeRun {
    /// Horizontal error at the end, m.
    pub final_horizontal_error_m: f64,
    /// Largest horizontal error, m.
    pub max_horizontal_error_m: f64,
    /// The filter's horizontal σ at the end, m.
    pub final_horizontal_sigma_m: f64,
}

/// The figures of `gnss-denied-astro` (`summary.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// `"gnss-denied-astro"`.
    pub experiment: String,
    /// The scenario's world effects that were on (truth only; empty: the matched world).
    #[serde(default)]
    pub world_effects: Vec<String>,
    /// Scenario name in `config/scenarios`.
    pub scenario: String,
    /// Simulated duration, s.
    pub duration_s: f64,
    /// IMU rate, Hz.
    pub imu_rate_hz: f64,
    /// Time navigated, s.
    pub navigation_time_s: f64,
    /// The Schuler period at the site, s.
    pub schuler_period_s: f64,
    /// Whole Schuler periods navigated.
    pub whole_schuler_periods: f64,
    /// The closed forms.
    pub floor: Floor,
    /// The astro-inertial run.
    pub astro_inertial: AstroRun,
    /// The free-inertial run (absent from the reduced test).
    pub free_inertial: Option<FreeRun>,
    /// Wall-clock time of the runs, s.
    pub wall_time_s: f64,
}

experiment!(
    /// `sextant experiment gnss-denied-astro`.
    GnssDeniedAstro,
    "gnss-denied-astro",
    "Paper 000: 10 h astro-inertial without GNSS against its error floor"
);

/// The measurement with `settings` into the existing `out_dir` (plots); returns the summary
/// ([`Experiment::run_with`] writes it to `summary.json`).
fn measure(
    settings: &Settings,
    out_dir: &Path,
    progress: bool,
) -> Result<Summary, ExperimentError> {
    let mut scn = load_scenario(&settings.scenario, None)?;
    if let Some(d) = settings.duration_s {
        scn.spec.scenario.duration_s = d;
    }
    if let Some(r) = settings.imu_rate_hz {
        scn.spec.imu.rate_hz = r;
    }
    let duration_s = scn.spec.scenario.duration_s;
    let bar = progress_bar(
        progress,
        2 * duration_s as u64,
        "gnss-denied-astro (2 runs, sim s)",
    );
    let t0 = std::time::Instant::now();
    // The three sequential simulations run side by side (the free run is optional: the
    // reduced test leaves it out).
    let (accel_error, (astro, free)) = rayon::join(
        || effective_accel_error(&scn),
        || {
            rayon::join(
                || one_run(&scn, true, &bar),
                || {
                    if settings.free_inertial {
                        one_run(&scn, false, &bar)
                    } else {
                        Ok(Vec::new())
                    }
                },
            )
        },
    );
    bar.finish_and_clear();
    let dg_n = scn.site_gravity_disturbance_ned_m_s2();
    let astro_points = astro?;
    let astro = samples(&astro_points, &accel_error, &dg_n);
    let free = samples(&free?, &accel_error, &dg_n);
    let wall_s = t0.elapsed().as_secs_f64();
    let last = |v: &[Sample]| {
        v.last()
            .copied()
            .ok_or_else(|| ExperimentError::Measurement("no navigating epoch".into()))
    };
    let a_end = last(&astro)?;
    let f_end = if settings.free_inertial {
        Some(last(&free)?)
    } else {
        None
    };

    // Floor: radial magnitude of the equilibrium vector (mean and max over the run).
    let floor_mag: Vec<f64> = astro.iter().map(|s| s.floor_ne_m.norm()).collect();
    let floor_mean = floor_mag.iter().sum::<f64>() / floor_mag.len() as f64;
    let floor_max = floor_mag.iter().cloned().fold(0.0, f64::max);
    let nav_time = a_end.t_s - astro[0].t_s;
    let noise_astro = noise_sigma_per_axis_m(&scn, nav_time, true) * 2f64.sqrt();
    let bound = 2.0 * floor_max + 3.0 * noise_astro;
    let astro_max = astro.iter().map(|s| s.err_h_m).fold(0.0, f64::max);

    // Mean error vector over whole Schuler periods (from the start of navigation) against the
    // mean floor vector over the same epochs.
    let g = normal_gravity(
        &WGS84,
        scn.spec.site.lat_deg.to_radians(),
        scn.spec.site.height_m,
    );
    let r = WGS84.a_m * (1.0 - WGS84.f / 2.0) + scn.spec.site.height_m;
    let schuler_s = 2.0 * std::f64::consts::PI * (r / g).sqrt();
    let periods = (nav_time / schuler_s).floor();
    let (mean_err, mean_floor, floor_spread) = if periods >= 1.0 {
        let t_end = astro[0].t_s + periods * schuler_s;
        let w: Vec<&Sample> = astro.iter().filter(|s| s.t_s <= t_end).collect();
        let n = w.len() as f64;
        let mean_floor = w.iter().map(|s| s.floor_ne_m).sum::<Vector2<f64>>() / n;
        // How far the floor itself moves (bias random walk, the filter's slowly improving
        // bias estimate): the mean error can only match the mean floor to within this.
        let spread = w
            .iter()
            .map(|s| (s.floor_ne_m - mean_floor).norm())
            .fold(0.0, f64::max);
        (
            w.iter().map(|s| s.err_ne_m).sum::<Vector2<f64>>() / n,
            mean_floor,
            spread,
        )
    } else {
        (
            Vector2::repeat(f64::NAN),
            Vector2::repeat(f64::NAN),
            f64::NAN,
        )
    };

    let ned = |v: &Vector3<f64>| [v.x, v.y, v.z];
    let summary = Summary {
        experiment: GnssDeniedAstro::NAME.into(),
        world_effects: super::world_effects(&scn),
        scenario: settings.scenario.clone(),
        duration_s,
        imu_rate_hz: scn.spec.imu.rate_hz,
        navigation_time_s: nav_time,
        schuler_period_s: schuler_s,
        whole_schuler_periods: periods,
        floor: Floor {
            bias_floor_mean_m: floor_mean,
            bias_floor_max_m: floor_max,
            noise_sigma_at_end_astro_m: noise_astro,
            noise_sigma_at_end_free_vrw_only_m: noise_sigma_per_axis_m(&scn, nav_time, false)
                * 2f64.sqrt(),
            bound_2_floor_plus_3_sigma_m: bound,
            deflection_arcsec: [-dg_n.x / g / ARCSEC_RAD, -dg_n.y / g / ARCSEC_RAD],
            deflection_floor_m: {
                let p = &astro_points[0];
                let g_n = p.c_e_n.transpose() * gravity_gradient(&WGS84, &p.pos_true_e_m) * p.c_e_n;
                Matrix2::new(g_n[(0, 0)], g_n[(0, 1)], g_n[(1, 0)], g_n[(1, 1)])
                    .try_inverse()
                    .map_or(f64::NAN, |inv| (inv * Vector2::new(dg_n.x, dg_n.y)).norm())
            },
        },
        astro_inertial: AstroRun {
            final_horizontal_error_m: a_end.err_h_m,
            max_horizontal_error_m: astro_max,
            final_horizontal_sigma_m: a_end.sigma_h_m,
            mean_error_north_over_whole_periods_m: mean_err.x,
            mean_error_east_over_whole_periods_m: mean_err.y,
            mean_floor_north_over_whole_periods_m: mean_floor.x,
            mean_floor_east_over_whole_periods_m: mean_floor.y,
            floor_spread_over_whole_periods_m: floor_spread,
            mean_error_minus_mean_floor_m: (mean_err - mean_floor).norm(),
            within_bound: astro_max <= bound,
            accel_effective_error_ned_at_end_ug: ned(&a_end.bias_true_ned_ug),
            accel_bias_of_truth_ned_at_end_ug: ned(&a_end.bias_truth_ned_ug),
            accel_bias_estimate_ned_at_end_ug: ned(&a_end.bias_est_ned_ug),
        },
        free_inertial: f_end.map(|f_end| FreeRun {
            final_horizontal_error_m: f_end.err_h_m,
            max_horizontal_error_m: free.iter().map(|s| s.err_h_m).fold(0.0, f64::max),
            final_horizontal_sigma_m: f_end.sigma_h_m,
        }),
        wall_time_s: wall_s,
    };

    // Plots (every 10th epoch: at 1 Hz truth, 3600 points per line over 10 h).
    let hours = |v: &[Sample], f: &dyn Fn(&Sample) -> f64| -> Vec<(f64, f64)> {
        v.iter()
            .step_by(10)
            .map(|s| (s.t_s / 3600.0, f(s)))
            .collect()
    };
    let lines = vec![
        Line::solid(
            "free inertial: horizontal error",
            hours(&free, &|s| s.err_h_m),
            color(1),
        ),
        Line::solid(
            "astro-inertial: horizontal error",
            hours(&astro, &|s| s.err_h_m),
            color(0),
        ),
        Line::dashed(
            "bias floor R·|δb_h|/g (closed form)",
            hours(&astro, &|s| s.floor_ne_m.norm()),
            color(2),
        ),
        Line::dashed(
            "bound 2·floor + 3σ_noise",
            hours(&astro, &|s| {
                2.0 * floor_max
                    + 3.0 * noise_sigma_per_axis_m(&scn, s.t_s - astro[0].t_s, true) * 2f64.sqrt()
            }),
            color(3),
        ),
        Line::dashed(
            "astro-inertial: filter horizontal σ",
            hours(&astro, &|s| s.sigma_h_m),
            color(4),
        ),
    ];
    line_chart(
        &out_dir.join("horizontal_error.png"),
        &Chart::log_y(
            "GNSS denied, 10 h: astro-inertial vs free inertial",
            "time, h",
            "horizontal position error, m",
            &lines,
        ),
    )?;
    let comp = vec![
        Line::solid(
            "astro north error",
            hours(&astro, &|s| s.err_ne_m.x),
            color(0),
        ),
        Line::solid(
            "astro east error",
            hours(&astro, &|s| s.err_ne_m.y),
            color(1),
        ),
        Line::dashed("floor north", hours(&astro, &|s| s.floor_ne_m.x), color(0)),
        Line::dashed("floor east", hours(&astro, &|s| s.floor_ne_m.y), color(1)),
    ];
    line_chart(
        &out_dir.join("astro_error_components.png"),
        &Chart::linear(
            "Astro-inertial error (truth − estimate) oscillates about the bias floor",
            "time, h",
            "position error, m",
            &comp,
        ),
    )?;
    Ok(summary)
}

/// The table printed after the run.
pub fn table(summary: &Summary) -> String {
    let f1 = |x: f64| fmt_f64(x, 1, false);
    let mut s = format!(
        "gnss-denied-astro: {} h, IMU {} Hz, {} Schuler periods of {} s\n",
        f1(summary.duration_s / 3600.0),
        fmt_f64(summary.imu_rate_hz, 0, false),
        fmt_f64(summary.whole_schuler_periods, 0, false),
        fmt_f64(summary.schuler_period_s, 0, false),
    );
    s += &super::world_line(&summary.world_effects);
    s.push('\n');
    let floor = &summary.floor;
    s += &format!(
        "closed form: bias floor mean {} m (max {} m), noise σ at end {} m, bound {} m\n",
        f1(floor.bias_floor_mean_m),
        f1(floor.bias_floor_max_m),
        f1(floor.noise_sigma_at_end_astro_m),
        f1(floor.bound_2_floor_plus_3_sigma_m),
    );
    s += &format!(
        "  the site's deflection of the vertical (N {}″, E {}″) alone: {} m of it\n",
        f1(floor.deflection_arcsec[0]),
        f1(floor.deflection_arcsec[1]),
        f1(floor.deflection_floor_m),
    );
    s += "run              final error, m   max error, m   filter σ at end, m\n";
    let astro = &summary.astro_inertial;
    let free = summary.free_inertial.as_ref();
    for (name, final_m, max_m, sigma_m) in [
        (
            "astro-inertial",
            Some(astro.final_horizontal_error_m),
            Some(astro.max_horizontal_error_m),
            Some(astro.final_horizontal_sigma_m),
        ),
        (
            "free inertial",
            free.map(|f| f.final_horizontal_error_m),
            free.map(|f| f.max_horizontal_error_m),
            free.map(|f| f.final_horizontal_sigma_m),
        ),
    ] {
        s += &format!(
            "{name:16} {:>14} {:>14} {:>20}\n",
            fmt_opt(final_m, 1, false),
            fmt_opt(max_m, 1, false),
            fmt_opt(sigma_m, 1, false),
        );
    }
    s += &format!(
        "astro mean error over whole periods (N, E): ({}, {}) m; floor ({}, {}) m\n",
        f1(astro.mean_error_north_over_whole_periods_m),
        f1(astro.mean_error_east_over_whole_periods_m),
        f1(astro.mean_floor_north_over_whole_periods_m),
        f1(astro.mean_floor_east_over_whole_periods_m),
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 1.5 h (one whole Schuler period of navigation) at 50 Hz IMU. The closed forms of the
    /// module comment: the error never exceeds `2·floor + 3σ_noise`, and its mean over the
    /// whole period is the floor vector, to within the floor's own spread over that period
    /// plus 3σ of the noise term.
    #[test]
    fn astro_inertial_error_oscillates_about_the_bias_floor() {
        let dir = crate::experiments::test_dir("gnss-denied-astro");
        let settings = Settings {
            duration_s: Some(5400.0),
            imu_rate_hz: Some(50.0),
            free_inertial: false,
            ..Settings::default()
        };
        let t0 = std::time::Instant::now();
        let s = GnssDeniedAstro::run_with(&settings, &dir, false).expect("run");
        eprintln!("{:.1} s\n{}", t0.elapsed().as_secs_f64(), table(&s));
        assert_eq!(s.whole_schuler_periods, 1.0);
        let bound = s.floor.bound_2_floor_plus_3_sigma_m;
        assert!(s.astro_inertial.max_horizontal_error_m <= bound);
        let noise = s.floor.noise_sigma_at_end_astro_m;
        let spread = s.astro_inertial.floor_spread_over_whole_periods_m;
        let miss = s.astro_inertial.mean_error_minus_mean_floor_m;
        assert!(
            miss <= spread + 3.0 * noise,
            "{miss} > {spread} + 3·{noise}"
        );
        // The floor is the accelerometer's, not zero: R·δb/g with δb of tens of µg.
        assert!(s.floor.bias_floor_mean_m > 3.0 * noise);
        // The stand's world has the Earth's real gravity field: the site's deflection θ is
        // part of the floor as R·θ (G_hh ≈ −g/r, r the geocentric radius, to J2's 0.3 %).
        let d = s.floor.deflection_arcsec;
        let theta = d[0].hypot(d[1]) * ARCSEC_RAD;
        assert!(theta > 0.0, "the stand's world has a gravity field");
        let lat = 55.655f64.to_radians();
        let r = WGS84.a_m * (1.0 - WGS84.f * lat.sin().powi(2));
        let ratio = s.floor.deflection_floor_m / (r * theta);
        assert!(
            (ratio - 1.0).abs() < 0.01,
            "deflection floor / R·θ = {ratio}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
