//! Experiment `schuler` (paper 002's error equations, eq. 22: `ΔV̇ = … − ν² Δr + 3ν² r (r·Δr)/r²`,
//! Schuler frequency `ν² = g/r`, period `T = 2π √(R/g) ≈ 84.4 min`): free-inertial navigation
//! with a perfect IMU at rest on the static site (φ = 55.655°, λ = 37.534°, h = 150 m),
//! [`fusion::strapdown::Strapdown`] with RK4 at 100 Hz and J2 gravity.
//!
//! Runs (errors are the computed minus the true position in the site's NED axes, m):
//! 1. **Velocity error**: 0.1 m/s north at t = 0, vertical channel held, several hours. The
//!    linearised solution (horizontal error as `z = north + i·east`) is
//!    `z = v₀/ν' e^{−iΩ_z t} sin(ν' t)`, with the Foucault rate `Ω_z = ω_ie sin φ` and
//!    `ν'² = ν² + Ω_z²`: the north error is `v₀/ν' sin(ν' t) cos(Ω_z t)`, whose zero crossings
//!    are exactly `π/ν'` apart (the Foucault factor only modulates the amplitude, its own zero
//!    is at 7.2 h). The period is measured from those crossings (linear interpolation between
//!    steps) and compared with `2π √(R/g)` (R the Gaussian mean radius `√(R_N R_E)` plus
//!    height, g the normal gravity at the site) and with the Foucault-corrected `2π/ν'`
//!    (0.12 % shorter).
//! 2. **Tilt error**: 1e-4 rad about the north axis at t = 0, vertical held: the east error
//!    oscillates about an offset `R ε` (≈ 640 m) with the same period; measured by a
//!    least-squares fit of `poly₂(t) + (A sin ωt + B cos ωt) cos Ω_z t + (C sin ωt + D cos ωt)
//!    sin Ω_z t` (ω by scan and golden section), a cross-check independent of zero crossings.
//! 3. **Free vertical channel**: 1 m initial height error, nothing held, 1 h. The vertical
//!    channel is unstable: gravity decreases with height (`∂|g|/∂h ≈ −2g/r`), so a height error
//!    grows as `δh₀ cosh(t/τ)`, `τ = √(R/2g) ≈ 570 s`. τ is measured by a least-squares fit of
//!    `ln δh` against t over the second half of the run (where the decaying mode is below
//!    0.2 %), and also by `t / acosh(δh/δh₀)` at the end; compared with `√(r/2g)` (r the
//!    geocentric radius, g the model's gravity magnitude) and with the model's own vertical
//!    gradient `1/√(−∂|g|/∂h)`.
//!
//! **Why the vertical channel is held in runs 1–2**: with τ ≈ 570 s, any vertical error
//! (rounding, the Eötvös/Coriolis coupling of the horizontal velocity error) is amplified by
//! `e^{t/τ}` ≈ 1e11 in 4 h; the height error would then reach hundreds of km, the gravity and
//! radius seen by the horizontal channel would be wrong and the Schuler period itself would
//! change. Holding height and vertical velocity at their true values after every step is what
//! a perfect baro/altimeter aiding does; the horizontal dynamics are untouched.

use super::plot::{Chart, Line, color, line_chart, xy};
use super::{Experiment, ExperimentError, fmt_f64, linear_fit, progress_bar};
use fusion::attitude::q_n_b_from_rpy;
use fusion::earth::{
    Geodetic, GravityModel, WGS84, c_e_n, ecef_to_geodetic, geodetic_to_ecef, gravity_ecef,
    normal_gravity, radii_of_curvature, up_e,
};
use fusion::strapdown::{
    Integrator, MechanizationConfig, NavState, Strapdown, stationary_increment,
};
use nalgebra::{DMatrix, DVector, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use std::path::Path;

/// Settings of the experiment.
#[derive(Debug, Clone)]
pub struct Settings {
    /// IMU interval, s.
    pub dt_s: f64,
    /// Duration of the horizontal runs (1, 2), s.
    pub horizontal_duration_s: f64,
    /// Initial north velocity error of run 1, m/s.
    pub velocity_error_north_m_s: f64,
    /// Initial tilt about the north axis of run 2, rad.
    pub tilt_rad: f64,
    /// Duration of the free-vertical run (3), s.
    pub vertical_duration_s: f64,
    /// Initial height error of run 3, m.
    pub height_error_m: f64,
    /// Interval at which errors are kept for fits and plots, s.
    pub sample_interval_s: f64,
}

impl Default for Settings {
    /// 100 Hz, 4 h horizontal runs, 1 h vertical run, 0.1 m/s, 1e-4 rad, 1 m.
    fn default() -> Self {
        Self {
            dt_s: 0.01,
            horizontal_duration_s: 4.0 * 3600.0,
            velocity_error_north_m_s: 0.1,
            tilt_rad: 1e-4,
            vertical_duration_s: 3600.0,
            height_error_m: 1.0,
            sample_interval_s: 10.0,
        }
    }
}

/// The static site, h = 150 m.
pub fn site() -> Geodetic {
    Geodetic {
        lat_rad: 55.655_f64.to_radians(),
        lon_rad: 37.534_f64.to_radians(),
        height_m: 150.0,
    }
}

/// Sampled errors of one run: time (s), NED position error (m) and height error (m).
#[derive(Debug, Default)]
struct Series {
    t_s: Vec<f64>,
    north_m: Vec<f64>,
    east_m: Vec<f64>,
    height_m: Vec<f64>,
    /// Zero crossings of the north error found at full rate, s.
    north_crossings_s: Vec<f64>,
}

/// How the run starts and whether the vertical channel is held.
#[derive(Debug, Clone, Copy)]
enum Start {
    VelocityNorth(f64),
    TiltNorth(f64),
    Height(f64),
}

/// Free-inertial run at the site: a perfect IMU at rest (true attitude level, heading 0.3 rad),
/// the navigator started with the error `start`.
fn free_inertial(
    settings: &Settings,
    start: Start,
    hold_vertical: bool,
    duration_s: f64,
    bar: &indicatif::ProgressBar,
) -> Result<Series, ExperimentError> {
    let ell = WGS84;
    let g0 = site();
    let dt = settings.dt_s;
    if !(dt > 0.0 && dt.is_finite() && duration_s > dt && settings.sample_interval_s >= dt) {
        return Err(ExperimentError::Measurement(format!(
            "invalid settings: dt {dt} s, duration {duration_s} s, sample interval {} s",
            settings.sample_interval_s
        )));
    }
    let q_n_b = q_n_b_from_rpy(0.0, 0.0, 0.3);
    let truth = NavState::from_geodetic(&ell, &g0, &Vector3::zeros(), &q_n_b);
    let inc = stationary_increment(&ell, GravityModel::J2, &truth.r_e, &truth.q_e_b, dt);
    let mut s = match start {
        Start::VelocityNorth(v) => {
            NavState::from_geodetic(&ell, &g0, &Vector3::new(v, 0.0, 0.0), &q_n_b)
        }
        Start::TiltNorth(eps) => {
            let tilt = UnitQuaternion::from_scaled_axis(Vector3::new(eps, 0.0, 0.0));
            NavState::from_geodetic(&ell, &g0, &Vector3::zeros(), &(tilt * q_n_b))
        }
        Start::Height(dh) => NavState::from_geodetic(
            &ell,
            &Geodetic {
                height_m: g0.height_m + dh,
                ..g0
            },
            &Vector3::zeros(),
            &q_n_b,
        ),
    };
    let mut sd = Strapdown::new(MechanizationConfig {
        ellipsoid: ell,
        gravity: GravityModel::J2,
        integrator: Integrator::Rk4,
        coning_sculling: true,
    });
    let c_n_e = c_e_n(g0.lat_rad, g0.lon_rad).transpose();
    let n_steps = (duration_s / dt).round() as usize;
    let every = ((settings.sample_interval_s / dt).round() as usize).max(1);
    let mut out = Series::default();
    let push = |out: &mut Series, t: f64, s: &NavState| {
        let d = c_n_e * (s.r_e - truth.r_e);
        out.t_s.push(t);
        out.north_m.push(d.x);
        out.east_m.push(d.y);
        out.height_m
            .push(ecef_to_geodetic(&ell, &s.r_e).height_m - g0.height_m);
    };
    push(&mut out, 0.0, &s);
    let mut prev_north = 0.0_f64;
    for k in 1..=n_steps {
        sd.step(&mut s, &inc);
        if hold_vertical {
            let g = ecef_to_geodetic(&ell, &s.r_e);
            s.r_e = geodetic_to_ecef(
                &ell,
                &Geodetic {
                    height_m: g0.height_m,
                    ..g
                },
            );
            let up = up_e(g.lat_rad, g.lon_rad);
            s.v_e -= up * up.dot(&s.v_e);
        }
        let north = (c_n_e * (s.r_e - truth.r_e)).x;
        if prev_north != 0.0 && north != 0.0 && north.signum() != prev_north.signum() {
            out.north_crossings_s
                .push((k - 1) as f64 * dt + dt * prev_north / (prev_north - north));
        }
        prev_north = north;
        if k % every == 0 {
            push(&mut out, k as f64 * dt, &s);
        }
        if k % 10_000 == 0 {
            bar.inc(10_000);
        }
    }
    Ok(out)
}

/// Least-squares fit of `y(t)` to
/// `c₀ + c₁τ + c₂τ² + (A sin ωt + B cos ωt) cos Ωt + (C sin ωt + D cos ωt) sin Ωt`
/// (τ = t / t_max) for given ω; returns the residual sum of squares.
fn fit_residual(t: &[f64], y: &[f64], omega: f64, foucault: f64) -> f64 {
    let n = t.len();
    let t_max = t.last().copied().unwrap_or(1.0).max(1e-9);
    let x = DMatrix::from_fn(n, 7, |i, j| {
        let ti = t[i];
        let (s, c) = (omega * ti).sin_cos();
        let (sf, cf) = (foucault * ti).sin_cos();
        match j {
            0 => 1.0,
            1 => ti / t_max,
            2 => (ti / t_max).powi(2),
            3 => s * cf,
            4 => c * cf,
            5 => s * sf,
            _ => c * sf,
        }
    });
    let yv = DVector::from_column_slice(y);
    let svd = x.clone().svd(true, true);
    match svd.solve(&yv, 1e-12) {
        Ok(beta) => (yv - x * beta).norm_squared(),
        Err(_) => f64::INFINITY,
    }
}

/// Angular frequency (rad/s) minimising [`fit_residual`] in `[0.7 ω₀, 1.3 ω₀]`: a scan of 121
/// points, then golden section around the best.
fn fit_frequency(t: &[f64], y: &[f64], omega0: f64, foucault: f64) -> f64 {
    let (lo, hi) = (0.7 * omega0, 1.3 * omega0);
    let n = 120;
    let step = (hi - lo) / n as f64;
    let mut best = (f64::INFINITY, omega0);
    for i in 0..=n {
        let w = lo + step * i as f64;
        let r = fit_residual(t, y, w, foucault);
        if r < best.0 {
            best = (r, w);
        }
    }
    let (mut a, mut b) = (best.1 - step, best.1 + step);
    let gr = 0.5 * (5.0_f64.sqrt() - 1.0);
    let mut c = b - gr * (b - a);
    let mut d = a + gr * (b - a);
    let (mut fc, mut fd) = (
        fit_residual(t, y, c, foucault),
        fit_residual(t, y, d, foucault),
    );
    for _ in 0..60 {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - gr * (b - a);
            fc = fit_residual(t, y, c, foucault);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + gr * (b - a);
            fd = fit_residual(t, y, d, foucault);
        }
    }
    0.5 * (a + b)
}

/// The figures of `schuler` (`summary.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// `"schuler"`.
    pub experiment: String,
    /// The paper reproduced, `"002"`.
    pub paper: String,
    /// Site latitude, deg.
    pub site_latitude_deg: f64,
    /// Site longitude, deg.
    pub site_longitude_deg: f64,
    /// Site height, m.
    pub site_height_m: f64,
    /// `"rk4"`.
    pub integrator: String,
    /// `"j2"`.
    pub gravity_model: String,
    /// IMU rate, Hz.
    pub imu_rate_hz: f64,
    /// Duration of the horizontal runs, s.
    pub horizontal_duration_s: f64,
    /// Height and vertical velocity held at their true values in runs 1–2.
    pub vertical_channel_held_in_horizontal_runs: bool,
    /// Schuler period from the zero crossings of run 1's north error, s.
    pub schuler_period_measured_s: f64,
    /// The same, min.
    pub schuler_period_measured_min: f64,
    /// How the period is measured.
    pub schuler_period_measurement: String,
    /// `2π √(R/g)`, s.
    pub schuler_period_expected_s: f64,
    /// The same, min.
    pub schuler_period_expected_min: f64,
    /// Measured / expected − 1.
    pub schuler_period_relative_error: f64,
    /// `2π/ν'` with `ν'² = g/R + Ω_z²`, s.
    pub schuler_period_foucault_corrected_expected_s: f64,
    /// Measured / Foucault-corrected − 1.
    pub schuler_period_relative_error_vs_foucault_corrected: f64,
    /// R of the expectation: Gaussian mean radius plus height, m.
    pub schuler_expected_radius_m: f64,
    /// g of the expectation: normal gravity at the site, m/s².
    pub schuler_expected_gravity_m_s2: f64,
    /// `Ω_z = ω_ie sin φ`, rad/s.
    pub foucault_rate_rad_s: f64,
    /// Run 1's initial north velocity error, m/s.
    pub velocity_run_initial_north_velocity_error_m_s: f64,
    /// Run 1's zero crossings of the north error, s.
    pub velocity_run_north_zero_crossings_s: Vec<f64>,
    /// Run 1's period from the least-squares fit, s.
    pub velocity_run_fit_period_s: f64,
    /// Run 1's largest |north error|, m.
    pub velocity_run_max_north_error_m: f64,
    /// Run 1's largest |east error|, m.
    pub velocity_run_max_east_error_m: f64,
    /// `v₀/ν'`, m.
    pub velocity_run_expected_amplitude_m: f64,
    /// Run 2's initial tilt about north, rad.
    pub tilt_run_initial_tilt_about_north_rad: f64,
    /// Run 2's period from the least-squares fit of the east error, s.
    pub tilt_run_fit_period_s: f64,
    /// Run 2's fitted / expected period − 1.
    pub tilt_run_fit_period_relative_error: f64,
    /// Run 2's largest |east error|, m.
    pub tilt_run_max_east_error_m: f64,
    /// `2 R ε`, m.
    pub tilt_run_expected_max_east_error_m: f64,
    /// Run 3's initial height error, m.
    pub vertical_initial_height_error_m: f64,
    /// Run 3's duration, s.
    pub vertical_duration_s: f64,
    /// Run 3's height error at the end, m.
    pub vertical_final_height_error_m: f64,
    /// Time constant of the free vertical channel from the ln fit, s.
    pub vertical_time_constant_measured_s: f64,
    /// How the time constant is measured.
    pub vertical_time_constant_measurement: String,
    /// `t / acosh(δh/δh₀)` at the end, s.
    pub vertical_time_constant_acosh_at_end_s: f64,
    /// `√(r/2g)`, s.
    pub vertical_time_constant_expected_s: f64,
    /// Measured / expected − 1.
    pub vertical_time_constant_relative_error: f64,
    /// `1/√(−∂|g|/∂h)` of the model, s.
    pub vertical_time_constant_gravity_gradient_model_s: f64,
}

experiment!(
    /// `sextant experiment schuler`.
    Schuler,
    "schuler",
    "Paper 002: Schuler period and vertical-channel divergence of free inertial navigation"
);

/// The measurement with `settings` into the existing `out_dir` (plots); returns the summary
/// ([`Experiment::run_with`] writes it to `summary.json`).
fn measure(
    settings: &Settings,
    out_dir: &Path,
    progress: bool,
) -> Result<Summary, ExperimentError> {
    let ell = WGS84;
    let g0 = site();
    let total =
        (2.0 * settings.horizontal_duration_s + settings.vertical_duration_s) / settings.dt_s;
    let bar = progress_bar(progress, total as u64, "schuler (free inertial)");
    let vel = free_inertial(
        settings,
        Start::VelocityNorth(settings.velocity_error_north_m_s),
        true,
        settings.horizontal_duration_s,
        &bar,
    )?;
    let tilt = free_inertial(
        settings,
        Start::TiltNorth(settings.tilt_rad),
        true,
        settings.horizontal_duration_s,
        &bar,
    )?;
    let vert = free_inertial(
        settings,
        Start::Height(settings.height_error_m),
        false,
        settings.vertical_duration_s,
        &bar,
    )?;
    bar.finish_and_clear();

    // Expectations.
    let (r_n, r_e) = radii_of_curvature(&ell, g0.lat_rad);
    let radius = (r_n * r_e).sqrt() + g0.height_m;
    let gamma = normal_gravity(&ell, g0.lat_rad, g0.height_m);
    let nu2 = gamma / radius;
    let t_expected = 2.0 * PI / nu2.sqrt();
    let omega_z = ell.omega_ie_rad_s * g0.lat_rad.sin();
    let nu_f = (nu2 + omega_z * omega_z).sqrt();
    let t_foucault = 2.0 * PI / nu_f;

    // Run 1: zero crossings of the north error.
    let c = &vel.north_crossings_s;
    if c.len() < 3 {
        return Err(ExperimentError::Measurement(format!(
            "only {} zero crossings of the north error in {} s; need 3",
            c.len(),
            settings.horizontal_duration_s
        )));
    }
    let t_cross = 2.0 * (c[c.len() - 1] - c[0]) / (c.len() - 1) as f64;
    let vel_fit = 2.0 * PI / fit_frequency(&vel.t_s, &vel.north_m, nu_f, omega_z);
    // Run 2: the east error carries the tilt's oscillation.
    let tilt_fit = 2.0 * PI / fit_frequency(&tilt.t_s, &tilt.east_m, nu_f, omega_z);
    let max_abs = |v: &[f64]| v.iter().fold(0.0_f64, |m, x| m.max(x.abs()));

    // Run 3: log-growth fit over the second half, and acosh at the end.
    let half = settings.vertical_duration_s / 2.0;
    let (tx, ly): (Vec<f64>, Vec<f64>) = vert
        .t_s
        .iter()
        .zip(&vert.height_m)
        .filter(|(t, dh)| **t >= half && **dh > 0.0)
        .map(|(t, dh)| (*t, dh.ln()))
        .unzip();
    let (slope, _) = linear_fit(&tx, &ly).ok_or_else(|| {
        ExperimentError::Measurement("height error not positive over the second half".into())
    })?;
    if slope <= 0.0 {
        return Err(ExperimentError::Measurement(format!(
            "height error does not grow (log slope {slope} 1/s)"
        )));
    }
    let tau_fit = 1.0 / slope;
    let (t_end, dh_end) = match (vert.t_s.last(), vert.height_m.last()) {
        (Some(t), Some(dh)) => (*t, *dh),
        _ => return Err(ExperimentError::Measurement("empty vertical run".into())),
    };
    let tau_acosh = t_end / (dh_end / settings.height_error_m).acosh();
    let truth_r = geodetic_to_ecef(&ell, &g0);
    let g_mag = |dh: f64| {
        gravity_ecef(
            &ell,
            GravityModel::J2,
            &(truth_r + up_e(g0.lat_rad, g0.lon_rad) * dh),
        )
        .norm()
    };
    let tau_expected = (truth_r.norm() / (2.0 * g_mag(0.0))).sqrt();
    let tau_gradient = 1.0 / (-(g_mag(10.0) - g_mag(-10.0)) / 20.0).sqrt();

    let summary = Summary {
        experiment: Schuler::NAME.into(),
        paper: "002".into(),
        site_latitude_deg: g0.lat_rad.to_degrees(),
        site_longitude_deg: g0.lon_rad.to_degrees(),
        site_height_m: g0.height_m,
        integrator: "rk4".into(),
        gravity_model: "j2".into(),
        imu_rate_hz: 1.0 / settings.dt_s,
        horizontal_duration_s: settings.horizontal_duration_s,
        vertical_channel_held_in_horizontal_runs: true,
        schuler_period_measured_s: t_cross,
        schuler_period_measured_min: t_cross / 60.0,
        schuler_period_measurement:
            "zero crossings of the north error, 0.1 m/s north velocity error run".into(),
        schuler_period_expected_s: t_expected,
        schuler_period_expected_min: t_expected / 60.0,
        schuler_period_relative_error: t_cross / t_expected - 1.0,
        schuler_period_foucault_corrected_expected_s: t_foucault,
        schuler_period_relative_error_vs_foucault_corrected: t_cross / t_foucault - 1.0,
        schuler_expected_radius_m: radius,
        schuler_expected_gravity_m_s2: gamma,
        foucault_rate_rad_s: omega_z,
        velocity_run_initial_north_velocity_error_m_s: settings.velocity_error_north_m_s,
        velocity_run_north_zero_crossings_s: c.clone(),
        velocity_run_fit_period_s: vel_fit,
        velocity_run_max_north_error_m: max_abs(&vel.north_m),
        velocity_run_max_east_error_m: max_abs(&vel.east_m),
        velocity_run_expected_amplitude_m: settings.velocity_error_north_m_s / nu_f,
        tilt_run_initial_tilt_about_north_rad: settings.tilt_rad,
        tilt_run_fit_period_s: tilt_fit,
        tilt_run_fit_period_relative_error: tilt_fit / t_expected - 1.0,
        tilt_run_max_east_error_m: max_abs(&tilt.east_m),
        tilt_run_expected_max_east_error_m: 2.0 * settings.tilt_rad * gamma / nu2,
        vertical_initial_height_error_m: settings.height_error_m,
        vertical_duration_s: settings.vertical_duration_s,
        vertical_final_height_error_m: dh_end,
        vertical_time_constant_measured_s: tau_fit,
        vertical_time_constant_measurement:
            "least-squares slope of ln(height error) over the second half of the run".into(),
        vertical_time_constant_acosh_at_end_s: tau_acosh,
        vertical_time_constant_expected_s: tau_expected,
        vertical_time_constant_relative_error: tau_fit / tau_expected - 1.0,
        vertical_time_constant_gravity_gradient_model_s: tau_gradient,
    };

    // Plots.
    let minutes = |t: &[f64]| t.iter().map(|t| t / 60.0).collect::<Vec<f64>>();
    let tm = minutes(&vel.t_s);
    let v0 = settings.velocity_error_north_m_s;
    let theory: Vec<(f64, f64)> = vel
        .t_s
        .iter()
        .map(|&t| (t / 60.0, v0 / nu_f * (nu_f * t).sin() * (omega_z * t).cos()))
        .collect();
    let ne_chart = |file: &str, title: &str, run: &Series, tm: &[f64], extra: Vec<Line>| {
        let mut lines = vec![
            Line::solid("north", xy(tm, &run.north_m), color(0)),
            Line::solid("east", xy(tm, &run.east_m), color(1)),
        ];
        lines.extend(extra);
        line_chart(
            &out_dir.join(file),
            &Chart::linear(title, "time [min]", "position error [m]", &lines),
        )
    };
    ne_chart(
        "schuler_velocity_error_run_ne_error.png",
        "Free inertial, 0.1 m/s north velocity error: position error",
        &vel,
        &tm,
        vec![Line::dashed(
            "north, linear theory v0/ν' sin(ν't) cos(Ω_z t)",
            theory,
            color(2),
        )],
    )?;
    ne_chart(
        "schuler_tilt_run_ne_error.png",
        "Free inertial, 1e-4 rad tilt about north: position error",
        &tilt,
        &minutes(&tilt.t_s),
        Vec::new(),
    )?;
    let tm = minutes(&vert.t_s);
    let dh0 = settings.height_error_m;
    let abs_height: Vec<f64> = vert.height_m.iter().map(|h| h.abs()).collect();
    line_chart(
        &out_dir.join("schuler_free_vertical_height_error_log.png"),
        &Chart {
            title: "Free vertical channel, 1 m initial height error",
            x_label: "time [min]",
            y_label: "|height error| [m] (log)",
            log_x: false,
            log_y: true,
            lines: &[
                Line::solid("|height error|", xy(&tm, &abs_height), color(0)),
                Line::dashed(
                    format!("δh0 cosh(t/τ), τ = √(r/2g) = {tau_expected:.1} s"),
                    vert.t_s
                        .iter()
                        .map(|&t| (t / 60.0, dh0 * (t / tau_expected).cosh()))
                        .collect(),
                    color(1),
                ),
            ],
        },
    )?;
    Ok(summary)
}

/// Human table: measured against expected period and time constant.
pub fn table(summary: &Summary) -> String {
    let s = summary;
    let f = |x: f64, p: usize| fmt_f64(x, p, false);
    let e = |x: f64| fmt_f64(x, 2, true);
    let mut out = String::new();
    out.push_str("Schuler / vertical channel (free inertial, RK4, J2, static site)\n");
    let mut row = |figure: &str, measured: String, expected: String, rel: Option<String>| {
        let line = format!("{figure:<46} {measured:>12} {expected:>12}");
        match rel {
            Some(r) => out.push_str(&format!("{line} {r:>11}\n")),
            None => out.push_str(&format!("{line}\n")),
        }
    };
    row(
        "figure",
        "measured".into(),
        "expected".into(),
        Some("rel. error".into()),
    );
    row(
        "Schuler period, zero crossings [s]",
        f(s.schuler_period_measured_s, 1),
        f(s.schuler_period_expected_s, 1),
        Some(e(s.schuler_period_relative_error)),
    );
    row(
        "  vs Foucault-corrected 2π/√(g/R+Ω_z²) [s]",
        f(s.schuler_period_measured_s, 1),
        f(s.schuler_period_foucault_corrected_expected_s, 1),
        Some(e(s.schuler_period_relative_error_vs_foucault_corrected)),
    );
    row(
        "Schuler period, tilt run fit [s]",
        f(s.tilt_run_fit_period_s, 1),
        f(s.schuler_period_expected_s, 1),
        Some(e(s.tilt_run_fit_period_relative_error)),
    );
    row(
        "Vertical time constant, ln fit [s]",
        f(s.vertical_time_constant_measured_s, 2),
        f(s.vertical_time_constant_expected_s, 2),
        Some(e(s.vertical_time_constant_relative_error)),
    );
    row(
        "  acosh at end / gravity-gradient model [s]",
        f(s.vertical_time_constant_acosh_at_end_s, 2),
        f(s.vertical_time_constant_gravity_gradient_model_s, 2),
        None,
    );
    row(
        "Max north error, velocity run [m]",
        f(s.velocity_run_max_north_error_m, 2),
        f(s.velocity_run_expected_amplitude_m, 2),
        None,
    );
    row(
        "Max east error, tilt run [m]",
        f(s.tilt_run_max_east_error_m, 1),
        f(s.tilt_run_expected_max_east_error_m, 1),
        None,
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Shortened: 20 Hz, 3 h horizontal runs (4 zero crossings), 1 h vertical run.
    #[test]
    fn schuler_period_and_vertical_time_constant() {
        let dir = crate::experiments::test_dir("schuler");
        let settings = Settings {
            dt_s: 0.05,
            horizontal_duration_s: 3.0 * 3600.0,
            ..Settings::default()
        };
        let s = Schuler::run_with(&settings, &dir, false).expect("run");
        eprintln!("{}", table(&s));
        assert!(s.schuler_period_relative_error.abs() < 0.01, "{s:?}");
        assert!(s.tilt_run_fit_period_relative_error.abs() < 0.01, "{s:?}");
        assert!((s.schuler_period_expected_s / 60.0 - 84.4).abs() < 0.2);
        assert!(
            s.vertical_time_constant_relative_error.abs() < 0.02,
            "{s:?}"
        );
        let amp = s.velocity_run_expected_amplitude_m;
        assert!(s.velocity_run_max_north_error_m < 1.01 * amp);
        for png in [
            "schuler_velocity_error_run_ne_error.png",
            "schuler_tilt_run_ne_error.png",
            "schuler_free_vertical_height_error_log.png",
            "summary.json",
        ] {
            assert!(dir.join(png).is_file(), "{png}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn invalid_settings_are_rejected() {
        let dir = crate::experiments::test_dir("schuler-bad");
        let settings = Settings {
            dt_s: -1.0,
            ..Settings::default()
        };
        assert!(Schuler::run_with(&settings, &dir, false).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// The fit recovers the frequency of a synthetic modulated sinusoid with a background.
    #[test]
    fn frequency_fit_on_synthetic_signal() {
        let w = 1.24e-3;
        let wf = 6.0e-5;
        let t: Vec<f64> = (0..1000).map(|i| i as f64 * 12.0).collect();
        let y: Vec<f64> = t
            .iter()
            .map(|&t| 5.0 + 1e-3 * t + 80.0 * (w * t + 0.3).sin() * (wf * t).cos())
            .collect();
        let got = fit_frequency(&t, &y, 1.1 * w, wf);
        assert!((got / w - 1.0).abs() < 1e-6, "{got}");
    }
}
