//! Experiment `integrators` (paper 002: the navigation equations integrated by Euler, Heun and
//! Runge–Kutta): the same trajectory mechanized with each integrator at several step sizes,
//! the final position error against an analytic truth, the observed convergence orders and
//! the ranking.
//!
//! Both cases go through the production path, [`fusion::strapdown::Strapdown::step`], fed with
//! exact IMU increments (body axes: Δθ in rad, Δv in m/s) of an analytic ECEF trajectory.
//!
//! **Case 1, equatorial circular orbit under J2** (the exact solution of
//! `fusion::strapdown`'s order test): in the equatorial plane J2 gravitation is central,
//! `GM/r² (1 + 3/2 J2 (a/r)²)`, so a circular orbit of radius r has mean motion
//! `n² = GM/r³ (1 + 3/2 J2 (a/r)²)` and is seen in ECEF as `r (cos wt, sin wt, 0)`,
//! `w = n − ω_ie`. A free-falling, inertially non-rotating IMU measures Δθ = 0, Δv = 0, so the
//! only error is the integrators' truncation error of `ṙ = v`, `v̇ = g(r) − 2 ω_ie × v`
//! (rotating frame): global error ∝ hᵖ with p = 1, 2, 4.
//!
//! **Case 2, time-varying specific force**: a vehicle near the static site (φ = 55.655°,
//! λ = 37.534°, h = 150 m) moving on `r(t) = r₀ + C_e_n(φ, λ) p(t)` with sinusoidal north, east
//! and down excursions (accelerations ≈ 1–2 m/s², 300 s), the body held fixed in ECEF (so
//! Δθ = C_b_e ω_ie h exactly and the mechanization's rotation terms cancel; coning/sculling off).
//! The specific force `f^e = r̈ − g(r) + 2 ω_ie × ṙ` varies along the interval, but an IMU
//! reports only its integral Δv, so the mechanization takes `f^e` constant (the interval mean
//! `f̄`) over each step. For the position this costs, per step,
//! `∫₀ʰ (h − u)(f(u) − f̄) du = −ḟ h³/12`, which accumulates to the global position error
//! `≈ (h²/12) (f^e(T) − f^e(0))`: a second-order term that no integrator of the
//! constant-force equations can beat. Euler (1) and Heun (2) keep their orders; RK4 is limited
//! to order 2, with the predicted coefficient (reported and checked). Beating it would need
//! the force's variation inside the interval (several sub-increments, or a polynomial fit over
//! neighbouring increments), i.e. more information than one increment carries.

use super::plot::{Chart, Line, color, line_chart};
use super::{Experiment, ExperimentError, fmt_f64, linear_fit, progress_bar};
use fusion::earth::{
    Ellipsoid, Geodetic, GravityModel, WGS84, c_e_n, geodetic_to_ecef, gravity_ecef,
};
use fusion::strapdown::{
    ImuIncrement, Integrator, MechanizationConfig, NavState, Strapdown, q_e_n,
};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use std::path::Path;

/// The integrators compared, with their names in the summary and their theoretical orders.
const INTEGRATORS: [(Integrator, &str, f64); 3] = [
    (Integrator::Euler, "euler", 1.0),
    (Integrator::Heun, "heun", 2.0),
    (Integrator::Rk4, "rk4", 4.0),
];

/// Settings of the experiment.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Orbit case: radius, m.
    pub orbit_radius_m: f64,
    /// Orbit case: duration, s.
    pub orbit_duration_s: f64,
    /// Orbit case: step sizes, s (each must divide the duration).
    pub orbit_steps_s: Vec<f64>,
    /// Vehicle case: duration, s.
    pub vehicle_duration_s: f64,
    /// Vehicle case: step sizes, s.
    pub vehicle_steps_s: Vec<f64>,
}

impl Default for Settings {
    /// 7000 km orbit for 4000 s at 40…2.5 s; vehicle for 300 s at 2…0.125 s.
    fn default() -> Self {
        Self {
            orbit_radius_m: 7.0e6,
            orbit_duration_s: 4000.0,
            orbit_steps_s: vec![40.0, 20.0, 10.0, 5.0, 2.5],
            vehicle_duration_s: 300.0,
            vehicle_steps_s: vec![2.0, 1.0, 0.5, 0.25, 0.125],
        }
    }
}

/// An analytic ECEF trajectory: position (m) and velocity (m/s) at time t (s), and the exact
/// IMU increment over `[t, t + h]`.
trait Trajectory {
    fn state(&self, t: f64) -> (Vector3<f64>, Vector3<f64>);
    fn attitude(&self) -> UnitQuaternion<f64>;
    fn increment(&self, t: f64, h: f64) -> ImuIncrement;
    fn coning_sculling(&self) -> bool;
}

/// Equatorial circular orbit under J2, free fall, body inertially fixed at t = 0 attitude
/// (identity), so the increments are zero.
struct Orbit {
    radius_m: f64,
    w_rad_s: f64,
}

impl Orbit {
    fn new(ell: &Ellipsoid, radius_m: f64) -> Self {
        let n = (ell.gm_m3_s2 / radius_m.powi(3)
            * (1.0 + 1.5 * ell.j2 * (ell.a_m / radius_m).powi(2)))
        .sqrt();
        Self {
            radius_m,
            w_rad_s: n - ell.omega_ie_rad_s,
        }
    }
}

impl Trajectory for Orbit {
    fn state(&self, t: f64) -> (Vector3<f64>, Vector3<f64>) {
        let (s, c) = (self.w_rad_s * t).sin_cos();
        (
            Vector3::new(c, s, 0.0) * self.radius_m,
            Vector3::new(-s, c, 0.0) * self.radius_m * self.w_rad_s,
        )
    }
    fn attitude(&self) -> UnitQuaternion<f64> {
        UnitQuaternion::identity()
    }
    fn increment(&self, _t: f64, h: f64) -> ImuIncrement {
        ImuIncrement {
            dt_s: h,
            ..Default::default()
        }
    }
    fn coning_sculling(&self) -> bool {
        true
    }
}

/// Vehicle near the site: `r(t) = r₀ + C_e_n p(t)`, with
/// `p = [A_n sin(w_n t), A_e (1 − cos(w_e t)), −A_d sin(w_d t)]` (m, NED axes of the start
/// point, fixed in ECEF); body axes = those NED axes, fixed in ECEF.
struct Vehicle {
    ell: Ellipsoid,
    r0: Vector3<f64>,
    c_e_n: Matrix3<f64>,
    q_e_b: UnitQuaternion<f64>,
    amp_m: [f64; 3],
    w_rad_s: [f64; 3],
}

impl Vehicle {
    fn new(ell: Ellipsoid) -> Self {
        let site = site();
        Self {
            ell,
            r0: geodetic_to_ecef(&ell, &site),
            c_e_n: c_e_n(site.lat_rad, site.lon_rad),
            q_e_b: q_e_n(site.lat_rad, site.lon_rad),
            amp_m: [2000.0, 1000.0, 100.0],
            w_rad_s: [2.0 * PI / 240.0, 2.0 * PI / 150.0, 2.0 * PI / 90.0],
        }
    }
    /// (p, ṗ, p̈) in the start point's NED axes.
    fn local(&self, t: f64) -> [Vector3<f64>; 3] {
        let [an, ae, ad] = self.amp_m;
        let [wn, we, wd] = self.w_rad_s;
        let (sn, cn) = (wn * t).sin_cos();
        let (se, ce) = (we * t).sin_cos();
        let (sd, cd) = (wd * t).sin_cos();
        [
            Vector3::new(an * sn, ae * (1.0 - ce), -ad * sd),
            Vector3::new(an * wn * cn, ae * we * se, -ad * wd * cd),
            Vector3::new(-an * wn * wn * sn, ae * we * we * ce, ad * wd * wd * sd),
        ]
    }
    /// Specific force in ECEF, m/s²: `f^e = r̈ − g(r) + 2 ω_ie × ṙ`.
    fn specific_force_e(&self, t: f64) -> Vector3<f64> {
        let [p, pd, pdd] = self.local(t);
        let r = self.r0 + self.c_e_n * p;
        self.c_e_n * pdd - gravity_ecef(&self.ell, GravityModel::J2, &r)
            + 2.0 * self.ell.omega_ie_e().cross(&(self.c_e_n * pd))
    }
}

/// Site of the static experiments (paper 000's), h = 150 m.
fn site() -> Geodetic {
    Geodetic {
        lat_rad: 55.655_f64.to_radians(),
        lon_rad: 37.534_f64.to_radians(),
        height_m: 150.0,
    }
}

impl Trajectory for Vehicle {
    fn state(&self, t: f64) -> (Vector3<f64>, Vector3<f64>) {
        let [p, pd, _] = self.local(t);
        (self.r0 + self.c_e_n * p, self.c_e_n * pd)
    }
    fn attitude(&self) -> UnitQuaternion<f64> {
        self.q_e_b
    }
    /// `Δv = C_b_e ∫ f^e dt`: the kinematic terms integrate in closed form
    /// (`ṙ(t+h) − ṙ(t) + 2 ω_ie × (r(t+h) − r(t))`), gravity by 5-point Gauss–Legendre
    /// (error ∝ h¹⁰, far below rounding for h ≤ 2 s). `Δθ = C_b_e ω_ie h`.
    fn increment(&self, t: f64, h: f64) -> ImuIncrement {
        const GL_X: [f64; 5] = [
            -0.906_179_845_938_664,
            -0.538_469_310_105_683,
            0.0,
            0.538_469_310_105_683,
            0.906_179_845_938_664,
        ];
        const GL_W: [f64; 5] = [
            0.236_926_885_056_189,
            0.478_628_670_499_366,
            0.568_888_888_888_889,
            0.478_628_670_499_366,
            0.236_926_885_056_189,
        ];
        let (r0, v0) = self.state(t);
        let (r1, v1) = self.state(t + h);
        let mut int_g = Vector3::zeros();
        for (x, w) in GL_X.iter().zip(GL_W) {
            let (r, _) = self.state(t + 0.5 * h * (1.0 + x));
            int_g += gravity_ecef(&self.ell, GravityModel::J2, &r) * (0.5 * h * w);
        }
        let int_f_e = (v1 - v0) - int_g + 2.0 * self.ell.omega_ie_e().cross(&(r1 - r0));
        let q_b_e = self.q_e_b.inverse();
        ImuIncrement {
            dt_s: h,
            delta_angle_rad: q_b_e * (self.ell.omega_ie_e() * h),
            delta_velocity_m_s: q_b_e * int_f_e,
        }
    }
    fn coning_sculling(&self) -> bool {
        false
    }
}

/// Mechanize `traj` over `[0, duration]` with step `h`; final position error norm, m.
fn final_error(
    traj: &dyn Trajectory,
    integrator: Integrator,
    duration_s: f64,
    h: f64,
) -> Result<f64, ExperimentError> {
    let n = (duration_s / h).round();
    if !(n >= 1.0 && ((n * h) - duration_s).abs() < 1e-9 * duration_s) {
        return Err(ExperimentError::Measurement(format!(
            "step {h} s does not divide the duration {duration_s} s"
        )));
    }
    let n = n as usize;
    let (r0, v0) = traj.state(0.0);
    let mut s = NavState {
        r_e: r0,
        v_e: v0,
        q_e_b: traj.attitude(),
    };
    let mut sd = Strapdown::new(MechanizationConfig {
        ellipsoid: WGS84,
        gravity: GravityModel::J2,
        integrator,
        coning_sculling: traj.coning_sculling(),
    });
    for k in 0..n {
        let inc = traj.increment(k as f64 * h, h);
        sd.step(&mut s, &inc);
    }
    let (r_true, _) = traj.state(n as f64 * h);
    Ok((s.r_e - r_true).norm())
}

/// Errors (m) of each integrator (rows in [`INTEGRATORS`] order) at each step size.
fn error_table(
    traj: &dyn Trajectory,
    duration_s: f64,
    steps: &[f64],
    bar: &indicatif::ProgressBar,
) -> Result<Vec<Vec<f64>>, ExperimentError> {
    let mut rows = Vec::new();
    for (integrator, _, _) in INTEGRATORS {
        let mut row = Vec::new();
        for &h in steps {
            row.push(final_error(traj, integrator, duration_s, h)?);
            bar.inc(1);
        }
        rows.push(row);
    }
    Ok(rows)
}

/// Observed order between the two finest steps (`ln(e₁/e₂)/ln(h₁/h₂)`) and the least-squares
/// slope of ln e against ln h over all steps.
fn orders(steps: &[f64], errors: &[f64]) -> Result<(f64, f64), ExperimentError> {
    let n = steps.len().min(errors.len());
    if n < 2 || errors[..n].iter().any(|e| !(e.is_finite() && *e > 0.0)) {
        return Err(ExperimentError::Measurement(format!(
            "cannot take orders of errors {errors:?} m"
        )));
    }
    let finest = (errors[n - 2] / errors[n - 1]).ln() / (steps[n - 2] / steps[n - 1]).ln();
    let lx: Vec<f64> = steps[..n].iter().map(|h| h.ln()).collect();
    let ly: Vec<f64> = errors[..n].iter().map(|e| e.ln()).collect();
    let (slope, _) = linear_fit(&lx, &ly)
        .ok_or_else(|| ExperimentError::Measurement("step sizes all equal".into()))?;
    Ok((finest, slope))
}

/// Ranking from most to least accurate at the finest step, and whether the same ranking holds
/// at every step size.
fn ranking(errors: &[Vec<f64>]) -> (Vec<&'static str>, bool) {
    let order_at = |j: usize| {
        let mut idx: Vec<usize> = (0..INTEGRATORS.len()).collect();
        idx.sort_by(|&a, &b| errors[a][j].total_cmp(&errors[b][j]));
        idx
    };
    let n = errors.first().map_or(0, Vec::len);
    if n == 0 {
        return (Vec::new(), false);
    }
    let finest = order_at(n - 1);
    let consistent = (0..n).all(|j| order_at(j) == finest);
    (
        finest.iter().map(|&i| INTEGRATORS[i].1).collect(),
        consistent,
    )
}

/// The figures of one case common to both: each integrator's final position errors and
/// observed orders, and the ranking.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaseFigures {
    /// The step sizes, s, coarsest first.
    pub step_sizes_s: Vec<f64>,
    /// Euler: observed order between the two finest steps.
    pub euler_observed_order: f64,
    /// Euler: least-squares slope of ln error against ln step over all steps.
    pub euler_fitted_order_all_steps: f64,
    /// Euler: theoretical order (1).
    pub euler_theoretical_order: f64,
    /// Euler: final position error norm at each step size, m.
    pub euler_final_position_error_m: Vec<f64>,
    /// Heun: observed order between the two finest steps.
    pub heun_observed_order: f64,
    /// Heun: least-squares slope of ln error against ln step over all steps.
    pub heun_fitted_order_all_steps: f64,
    /// Heun: theoretical order (2).
    pub heun_theoretical_order: f64,
    /// Heun: final position error norm at each step size, m.
    pub heun_final_position_error_m: Vec<f64>,
    /// RK4: observed order between the two finest steps.
    pub rk4_observed_order: f64,
    /// RK4: least-squares slope of ln error against ln step over all steps.
    pub rk4_fitted_order_all_steps: f64,
    /// RK4: theoretical order (4).
    pub rk4_theoretical_order: f64,
    /// RK4: final position error norm at each step size, m.
    pub rk4_final_position_error_m: Vec<f64>,
    /// Integrator names from most to least accurate at the finest step.
    pub ranking_most_accurate_first: Vec<String>,
    /// Whether the same ranking holds at every step size.
    pub ranking_same_at_every_step_size: bool,
}

impl CaseFigures {
    /// The figures of the errors (m) of each integrator (rows in [`INTEGRATORS`] order) at
    /// each of `steps` (s).
    fn new(steps: &[f64], errors: &[Vec<f64>]) -> Result<Self, ExperimentError> {
        let (euler_observed, euler_fitted) = orders(steps, &errors[0])?;
        let (heun_observed, heun_fitted) = orders(steps, &errors[1])?;
        let (rk4_observed, rk4_fitted) = orders(steps, &errors[2])?;
        let (rank, consistent) = ranking(errors);
        Ok(Self {
            step_sizes_s: steps.to_vec(),
            euler_observed_order: euler_observed,
            euler_fitted_order_all_steps: euler_fitted,
            euler_theoretical_order: INTEGRATORS[0].2,
            euler_final_position_error_m: errors[0].clone(),
            heun_observed_order: heun_observed,
            heun_fitted_order_all_steps: heun_fitted,
            heun_theoretical_order: INTEGRATORS[1].2,
            heun_final_position_error_m: errors[1].clone(),
            rk4_observed_order: rk4_observed,
            rk4_fitted_order_all_steps: rk4_fitted,
            rk4_theoretical_order: INTEGRATORS[2].2,
            rk4_final_position_error_m: errors[2].clone(),
            ranking_most_accurate_first: rank.iter().map(|n| n.to_string()).collect(),
            ranking_same_at_every_step_size: consistent,
        })
    }

    /// (final position errors m, observed order) per integrator, in [`INTEGRATORS`] order.
    fn by_integrator(&self) -> [(&[f64], f64); 3] {
        [
            (
                &self.euler_final_position_error_m,
                self.euler_observed_order,
            ),
            (&self.heun_final_position_error_m, self.heun_observed_order),
            (&self.rk4_final_position_error_m, self.rk4_observed_order),
        ]
    }
}

/// Case 1: the equatorial circular orbit under J2.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OrbitCase {
    /// What the case is.
    pub description: String,
    /// Orbit radius, m.
    pub orbit_radius_m: f64,
    /// Mechanized duration, s.
    pub duration_s: f64,
    /// Errors, orders and ranking.
    #[serde(flatten)]
    pub figures: CaseFigures,
}

/// Case 2: the vehicle with a time-varying specific force.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TimeVaryingForceCase {
    /// What the case is.
    pub description: String,
    /// Mechanized duration, s.
    pub duration_s: f64,
    /// `|f^e(T) − f^e(0)|`, m/s².
    pub specific_force_change_norm_m_s2: f64,
    /// The mean-force position error `h²/12 |Δf|` at each step size, m.
    pub mean_force_position_error_predicted_m: Vec<f64>,
    /// RK4's final error over that prediction at each step size.
    pub rk4_error_over_predicted_mean_force_error: Vec<f64>,
    /// Errors, orders and ranking.
    #[serde(flatten)]
    pub figures: CaseFigures,
}

/// The figures of `integrators` (`summary.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// `"integrators"`.
    pub experiment: String,
    /// The paper reproduced, `"002"`.
    pub paper: String,
    /// Orbit case: Euler's observed order (theory 1).
    pub euler_observed_order: f64,
    /// Orbit case: Heun's observed order (theory 2).
    pub heun_observed_order: f64,
    /// Orbit case: RK4's observed order (theory 4).
    pub rk4_observed_order: f64,
    /// Orbit case: most accurate first at the finest step.
    pub ranking: Vec<String>,
    /// Orbit case: the same ranking at every step size.
    pub ranking_same_at_every_step_size: bool,
    /// Time-varying force: Euler's observed order.
    pub time_varying_force_euler_observed_order: f64,
    /// Time-varying force: Heun's observed order.
    pub time_varying_force_heun_observed_order: f64,
    /// Time-varying force: RK4's observed order (limited to 2 by the mean force).
    pub time_varying_force_rk4_observed_order: f64,
    /// Case 1 in full.
    pub orbit_j2: OrbitCase,
    /// Case 2 in full.
    pub time_varying_force: TimeVaryingForceCase,
}

experiment!(
    /// `sextant experiment integrators`.
    Integrators,
    "integrators",
    "Paper 002: convergence order of the strapdown integrators (Euler, Heun, RK4)"
);

/// The measurement with `settings` into the existing `out_dir` (plots); returns the summary
/// ([`Experiment::run_with`] writes it to `summary.json`).
fn measure(
    settings: &Settings,
    out_dir: &Path,
    progress: bool,
) -> Result<Summary, ExperimentError> {
    let n_runs =
        INTEGRATORS.len() * (settings.orbit_steps_s.len() + settings.vehicle_steps_s.len());
    let bar = progress_bar(progress, n_runs as u64, "integrators");

    let orbit = Orbit::new(&WGS84, settings.orbit_radius_m);
    let orbit_err = error_table(
        &orbit,
        settings.orbit_duration_s,
        &settings.orbit_steps_s,
        &bar,
    )?;
    let vehicle = Vehicle::new(WGS84);
    let veh_err = error_table(
        &vehicle,
        settings.vehicle_duration_s,
        &settings.vehicle_steps_s,
        &bar,
    )?;
    bar.finish_and_clear();

    let orbit_case = OrbitCase {
        description:
            "equatorial circular orbit under J2 gravity, free fall (zero increments), ECEF".into(),
        orbit_radius_m: settings.orbit_radius_m,
        duration_s: settings.orbit_duration_s,
        figures: CaseFigures::new(&settings.orbit_steps_s, &orbit_err)?,
    };

    let df = (vehicle.specific_force_e(settings.vehicle_duration_s)
        - vehicle.specific_force_e(0.0))
    .norm();
    let predicted: Vec<f64> = settings
        .vehicle_steps_s
        .iter()
        .map(|h| h * h / 12.0 * df)
        .collect();
    let rk4_ratio: Vec<f64> = veh_err[2]
        .iter()
        .zip(&predicted)
        .map(|(e, p)| e / p)
        .collect();
    let vehicle_case = TimeVaryingForceCase {
        description: "vehicle near the site with sinusoidal N/E/D excursions, body fixed in ECEF; \
               the specific force varies within each interval but an increment carries only \
               its mean, which limits any integrator to order 2 in position"
            .into(),
        duration_s: settings.vehicle_duration_s,
        specific_force_change_norm_m_s2: df,
        mean_force_position_error_predicted_m: predicted.clone(),
        rk4_error_over_predicted_mean_force_error: rk4_ratio,
        figures: CaseFigures::new(&settings.vehicle_steps_s, &veh_err)?,
    };

    let (o, v) = (&orbit_case.figures, &vehicle_case.figures);
    let summary = Summary {
        experiment: Integrators::NAME.into(),
        paper: "002".into(),
        euler_observed_order: o.euler_observed_order,
        heun_observed_order: o.heun_observed_order,
        rk4_observed_order: o.rk4_observed_order,
        ranking: o.ranking_most_accurate_first.clone(),
        ranking_same_at_every_step_size: o.ranking_same_at_every_step_size,
        time_varying_force_euler_observed_order: v.euler_observed_order,
        time_varying_force_heun_observed_order: v.heun_observed_order,
        time_varying_force_rk4_observed_order: v.rk4_observed_order,
        orbit_j2: orbit_case,
        time_varying_force: vehicle_case,
    };

    plot_errors(
        &out_dir.join("integrators_orbit_error_vs_step.png"),
        "Equatorial J2 orbit: final position error vs step",
        &settings.orbit_steps_s,
        &orbit_err,
        None,
    )?;
    plot_errors(
        &out_dir.join("integrators_time_varying_force_error_vs_step.png"),
        "Time-varying specific force: final position error vs step",
        &settings.vehicle_steps_s,
        &veh_err,
        Some(&predicted),
    )?;
    Ok(summary)
}

/// Log-log error against step, with reference slopes hᵖ through each integrator's finest point
/// and, optionally, the predicted mean-force error.
fn plot_errors(
    path: &Path,
    title: &str,
    steps: &[f64],
    errors: &[Vec<f64>],
    predicted: Option<&[f64]>,
) -> Result<(), ExperimentError> {
    let mut lines = Vec::new();
    for (i, (_, name, p)) in INTEGRATORS.iter().enumerate() {
        lines.push(Line {
            label: name.to_string(),
            points: steps
                .iter()
                .copied()
                .zip(errors[i].iter().copied())
                .collect(),
            color: color(i),
            dashed: false,
            markers: true,
        });
        if let (Some(&h0), Some(&e0)) = (steps.last(), errors[i].last()) {
            lines.push(Line {
                label: format!("slope {p}"),
                points: steps.iter().map(|h| (*h, e0 * (h / h0).powf(*p))).collect(),
                color: color(i),
                dashed: true,
                markers: false,
            });
        }
    }
    if let Some(pred) = predicted {
        lines.push(Line {
            label: "predicted mean-force error h²|Δf|/12".into(),
            points: steps.iter().copied().zip(pred.iter().copied()).collect(),
            color: color(4),
            dashed: true,
            markers: true,
        });
    }
    line_chart(
        path,
        &Chart {
            title,
            x_label: "step size h [s]",
            y_label: "final position error [m]",
            log_x: true,
            log_y: true,
            lines: &lines,
        },
    )
}

/// Human table: errors per step size and observed orders for both cases.
pub fn table(summary: &Summary) -> String {
    let mut out = String::new();
    for (block, title) in [
        (
            &summary.orbit_j2.figures,
            "Equatorial circular orbit under J2 (exact solution)",
        ),
        (
            &summary.time_varying_force.figures,
            "Time-varying specific force (vehicle near the site)",
        ),
    ] {
        out.push_str(&format!("{title}\n"));
        out.push_str(&format!("{:>10}", "step [s]"));
        for (_, name, _) in INTEGRATORS {
            out.push_str(&format!(" {:>14}", format!("{name} err [m]")));
        }
        out.push('\n');
        let per = block.by_integrator();
        for (j, h) in block.step_sizes_s.iter().enumerate() {
            out.push_str(&format!("{:>10}", format!("{h}")));
            for (errors, _) in per {
                let e = errors.get(j).map_or("–".into(), |e| fmt_f64(*e, 3, true));
                out.push_str(&format!(" {e:>14}"));
            }
            out.push('\n');
        }
        out.push_str(&format!("{:>10}", "order"));
        for (_, order) in per {
            out.push_str(&format!(" {:>14}", fmt_f64(order, 2, false)));
        }
        out.push('\n');
        out.push_str(&format!("{:>10}", "(theory)"));
        for (_, _, p) in INTEGRATORS {
            out.push_str(&format!(" {:>14}", format!("{p}")));
        }
        out.push('\n');
        out.push_str(&format!(
            "ranking (most accurate first): {}\n",
            block.ranking_most_accurate_first.join(" > ")
        ));
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The full experiment (it is a few thousand steps): orders within ±0.2 of 1, 2, 4 on the
    /// orbit, the ranking RK4 > Heun > Euler at every step; with a time-varying force Euler and
    /// Heun keep 1 and 2, RK4 drops to 2 with the predicted mean-force coefficient.
    #[test]
    fn orders_and_ranking() {
        let dir = crate::experiments::test_dir("integrators");
        let s = Integrators::run(&dir, false).expect("run");
        eprintln!("{}", table(&s));
        assert!((s.euler_observed_order - 1.0).abs() < 0.2, "{s:?}");
        assert!((s.heun_observed_order - 2.0).abs() < 0.2, "{s:?}");
        assert!((s.rk4_observed_order - 4.0).abs() < 0.2, "{s:?}");
        assert_eq!(s.ranking, ["rk4", "heun", "euler"]);
        assert!(s.ranking_same_at_every_step_size);
        assert!(
            (s.time_varying_force_euler_observed_order - 1.0).abs() < 0.2,
            "{s:?}"
        );
        assert!(
            (s.time_varying_force_heun_observed_order - 2.0).abs() < 0.2,
            "{s:?}"
        );
        assert!(
            (s.time_varying_force_rk4_observed_order - 2.0).abs() < 0.2,
            "{s:?}"
        );
        let last = s
            .time_varying_force
            .rk4_error_over_predicted_mean_force_error
            .last()
            .copied()
            .unwrap_or(f64::NAN);
        assert!((last - 1.0).abs() < 0.2, "RK4 / predicted = {last}");
        for png in [
            "integrators_orbit_error_vs_step.png",
            "integrators_time_varying_force_error_vs_step.png",
            "summary.json",
        ] {
            assert!(dir.join(png).is_file(), "{png}");
        }
        // summary.json reads back as the summary.
        let json = std::fs::read_to_string(dir.join("summary.json")).expect("summary.json");
        assert_eq!(serde_json::from_str::<Summary>(&json).expect("parse"), s);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn step_that_does_not_divide_is_rejected() {
        let orbit = Orbit::new(&WGS84, 7.0e6);
        assert!(final_error(&orbit, Integrator::Rk4, 100.0, 30.0).is_err());
        assert!(orders(&[2.0, 1.0], &[1.0, 0.0]).is_err());
    }
}
