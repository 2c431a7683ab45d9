//! Strapdown mechanization in ECEF from delta-angle / delta-velocity samples, with coning and
//! sculling corrections and selectable integrators (paper 002: Euler, Heun, Runge–Kutta).
//!
//! State: position `r_e` (ECEF, m), velocity relative to the Earth `v_e` (ECEF axes, m/s),
//! attitude `q_e_b` (body → ECEF). One IMU interval `[t_{k−1}, t_k]` of length `dt` with
//! increments `Δθ` (rad) and `Δv` (m/s) in body axes is processed as follows.
//!
//! **Attitude** (paper 002's Poisson equation `Ċ_e_b = C_e_b Ω_ib − Ω_ie C_e_b`, integrated
//! exactly over the interval for a constant-axis rotation):
//! `q_e_b(k) = q_z(−ω_ie dt) ⊗ q_e_b(k−1) ⊗ q(φ)`, with the rotation vector
//! `φ = Δθ + (1/12) Δθ_prev × Δθ` (coning correction, when enabled) and `q(·)` the exact
//! rotation-vector quaternion ([`crate::attitude::quat_from_rotation_vector`]).
//!
//! **Specific force** over the interval, in ECEF:
//! `Δv_f^e = C_e_b(k−1) [Δv + ½ Δθ × Δv + (1/12)(Δθ_prev × Δv + Δv_prev × Δθ)]
//!          − ½ dt ω_ie × (C_e_b(k−1) Δv)`
//! (rotation compensation, sculling when enabled, and the Earth's rotation of the ECEF frame
//! during the interval, all to first order in the rotation). The ECEF specific force is taken
//! constant over the interval, `f^e = Δv_f^e / dt`, which is what the increment tells (its
//! mean) and keeps the attitude used for the translation the same for every integrator stage.
//!
//! **Translation** (paper 002's navigation equation in the rotating frame):
//! `ṙ_e = v_e`, `v̇_e = f^e + g^e(r_e) − 2 ω_ie × v_e`, with `g^e` the gravity (gravitation +
//! centrifugal) of [`crate::earth::gravity_ecef`] for the configured model, integrated over the
//! interval by Euler (order 1), Heun (order 2) or classical Runge–Kutta (order 4).
//!
//! The step allocates nothing (fixed-size nalgebra types only) and renormalises the quaternion.

use crate::attitude::quat_from_rotation_vector;
use crate::earth::{Ellipsoid, Geodetic, GravityModel, c_e_n, geodetic_to_ecef, gravity_ecef};
use nalgebra::{Quaternion, Rotation3, UnitQuaternion, Vector3};

/// Numerical integrator of the navigation equations.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Integrator {
    /// First order.
    Euler,
    /// Second order (trapezoidal predictor–corrector).
    Heun,
    /// Fourth-order Runge–Kutta.
    #[default]
    Rk4,
}

/// Inertial increments over one IMU interval, body axes.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ImuIncrement {
    /// Interval, s.
    pub dt_s: f64,
    /// Integrated angular rate (inertial), rad.
    pub delta_angle_rad: Vector3<f64>,
    /// Integrated specific force, m/s.
    pub delta_velocity_m_s: Vector3<f64>,
}

/// Kinematic state in ECEF.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavState {
    /// Position, ECEF, m.
    pub r_e: Vector3<f64>,
    /// Velocity relative to the Earth in ECEF axes, m/s.
    pub v_e: Vector3<f64>,
    /// Attitude body → ECEF.
    pub q_e_b: UnitQuaternion<f64>,
}

/// Mechanization settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MechanizationConfig {
    /// Reference ellipsoid.
    pub ellipsoid: Ellipsoid,
    /// Gravity model.
    pub gravity: GravityModel,
    /// Integrator.
    pub integrator: Integrator,
    /// Apply coning and sculling corrections from the previous increment.
    pub coning_sculling: bool,
}

/// The strapdown integrator with its one-sample history (for coning/sculling).
#[derive(Debug, Clone, Copy)]
pub struct Strapdown {
    /// Settings.
    pub config: MechanizationConfig,
    prev: Option<ImuIncrement>,
}

impl Strapdown {
    /// A mechanization with no history.
    pub fn new(config: MechanizationConfig) -> Self {
        Self { config, prev: None }
    }
    /// Forget the previous increment (after a gap in the data).
    pub fn reset_history(&mut self) {
        self.prev = None;
    }
    /// Advance `state` by one IMU increment. Allocates nothing.
    ///
    /// An increment with a non-finite value or a non-positive interval cannot be integrated:
    /// the state is left unchanged and the coning/sculling history is cleared (callers validate
    /// samples before this point; this is the last line of defence against NaN propagation).
    pub fn step(&mut self, state: &mut NavState, inc: &ImuIncrement) {
        let dt = inc.dt_s;
        let d_theta = inc.delta_angle_rad;
        let d_v = inc.delta_velocity_m_s;
        let valid = dt > 0.0
            && dt.is_finite()
            && d_theta.iter().all(|x| x.is_finite())
            && d_v.iter().all(|x| x.is_finite());
        if !valid {
            self.prev = None;
            return;
        }
        let ell = self.config.ellipsoid;
        let (coning, sculling) = match (self.config.coning_sculling, self.prev) {
            (true, Some(p)) => (
                p.delta_angle_rad.cross(&d_theta) / 12.0,
                (p.delta_angle_rad.cross(&d_v) + p.delta_velocity_m_s.cross(&d_theta)) / 12.0,
            ),
            _ => (Vector3::zeros(), Vector3::zeros()),
        };
        let omega_ie_e = ell.omega_ie_e();
        let q_e_b0 = state.q_e_b;

        // Specific-force velocity increment in ECEF, taken as a constant force over dt.
        let d_v_b = d_v + 0.5 * d_theta.cross(&d_v) + sculling;
        let d_v_f_e = q_e_b0 * d_v_b - 0.5 * dt * omega_ie_e.cross(&(q_e_b0 * d_v));
        let f_e = d_v_f_e / dt;

        let (r_e, v_e) = integrate_translation(
            &ell,
            self.config.gravity,
            self.config.integrator,
            &state.r_e,
            &state.v_e,
            &f_e,
            dt,
        );
        state.r_e = r_e;
        state.v_e = v_e;

        // Attitude: Earth rotation of the reference frame on the left, body rotation on the right.
        let (s, c) = (0.5 * ell.omega_ie_rad_s * dt).sin_cos();
        let q_earth = UnitQuaternion::new_unchecked(Quaternion::new(c, 0.0, 0.0, -s));
        let q_body = quat_from_rotation_vector(&(d_theta + coning));
        state.q_e_b = UnitQuaternion::new_normalize((q_earth * q_e_b0 * q_body).into_inner());
        self.prev = Some(*inc);
    }
}

/// Time derivative of velocity in ECEF, m/s²: `v̇_e = f^e + g^e(r_e) − 2 ω_ie × v_e`.
fn accel_e(
    ell: &Ellipsoid,
    model: GravityModel,
    r_e: &Vector3<f64>,
    v_e: &Vector3<f64>,
    f_e: &Vector3<f64>,
) -> Vector3<f64> {
    f_e + gravity_ecef(ell, model, r_e) - 2.0 * ell.omega_ie_e().cross(v_e)
}

/// Integrate `ṙ = v`, `v̇ = f + g(r) − 2 ω_ie × v` over `dt` with constant ECEF specific force
/// `f_e` (m/s²); returns `(r_e, v_e)` at the end of the interval. Allocates nothing.
pub fn integrate_translation(
    ell: &Ellipsoid,
    model: GravityModel,
    integrator: Integrator,
    r_e: &Vector3<f64>,
    v_e: &Vector3<f64>,
    f_e: &Vector3<f64>,
    dt: f64,
) -> (Vector3<f64>, Vector3<f64>) {
    let a = |r: &Vector3<f64>, v: &Vector3<f64>| accel_e(ell, model, r, v, f_e);
    match integrator {
        Integrator::Euler => {
            let a1 = a(r_e, v_e);
            (r_e + v_e * dt, v_e + a1 * dt)
        }
        Integrator::Heun => {
            let a1 = a(r_e, v_e);
            let r2 = r_e + v_e * dt;
            let v2 = v_e + a1 * dt;
            let a2 = a(&r2, &v2);
            (r_e + (v_e + v2) * (0.5 * dt), v_e + (a1 + a2) * (0.5 * dt))
        }
        Integrator::Rk4 => {
            let h2 = 0.5 * dt;
            let (k1r, k1v) = (*v_e, a(r_e, v_e));
            let (r2, v2) = (r_e + k1r * h2, v_e + k1v * h2);
            let (k2r, k2v) = (v2, a(&r2, &v2));
            let (r3, v3) = (r_e + k2r * h2, v_e + k2v * h2);
            let (k3r, k3v) = (v3, a(&r3, &v3));
            let (r4, v4) = (r_e + k3r * dt, v_e + k3v * dt);
            let (k4r, k4v) = (v4, a(&r4, &v4));
            let w = dt / 6.0;
            (
                r_e + (k1r + 2.0 * k2r + 2.0 * k3r + k4r) * w,
                v_e + (k1v + 2.0 * k2v + 2.0 * k3v + k4v) * w,
            )
        }
    }
}

/// The increments a perfect IMU at rest relative to the Earth outputs over `dt_s` at `r_e`
/// with attitude `q_e_b`: `Δθ = C_b_e ω_ie dt` (rad), `Δv = −C_b_e g^e(r_e) dt` (m/s).
pub fn stationary_increment(
    ell: &Ellipsoid,
    model: GravityModel,
    r_e: &Vector3<f64>,
    q_e_b: &UnitQuaternion<f64>,
    dt_s: f64,
) -> ImuIncrement {
    let q_b_e = q_e_b.inverse();
    ImuIncrement {
        dt_s,
        delta_angle_rad: q_b_e * (ell.omega_ie_e() * dt_s),
        delta_velocity_m_s: q_b_e * (-gravity_ecef(ell, model, r_e) * dt_s),
    }
}

impl NavState {
    /// Geodetic position on `ell`.
    pub fn geodetic(&self, ell: &Ellipsoid) -> Geodetic {
        crate::earth::ecef_to_geodetic(ell, &self.r_e)
    }
    /// State from a geodetic position, a NED velocity (m/s) and a body → NED attitude.
    pub fn from_geodetic(
        ell: &Ellipsoid,
        g: &Geodetic,
        v_ned_m_s: &Vector3<f64>,
        q_n_b: &UnitQuaternion<f64>,
    ) -> Self {
        let q_e_n = q_e_n(g.lat_rad, g.lon_rad);
        Self {
            r_e: geodetic_to_ecef(ell, g),
            v_e: q_e_n * v_ned_m_s,
            q_e_b: q_e_n * q_n_b,
        }
    }
    /// Velocity in NED at the current position, m/s.
    pub fn v_ned(&self, ell: &Ellipsoid) -> Vector3<f64> {
        let g = self.geodetic(ell);
        q_e_n(g.lat_rad, g.lon_rad).inverse() * self.v_e
    }
    /// Attitude body → NED at the current position.
    pub fn q_n_b(&self, ell: &Ellipsoid) -> UnitQuaternion<f64> {
        let g = self.geodetic(ell);
        q_e_n(g.lat_rad, g.lon_rad).inverse() * self.q_e_b
    }
}

/// Quaternion of the NED → ECEF rotation at (lat, lon) (rad), same as [`c_e_n`].
pub fn q_e_n(lat_rad: f64, lon_rad: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(c_e_n(lat_rad, lon_rad)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::attitude::{q_n_b_from_rpy, rotation_vector_from_quat, skew};
    use crate::earth::{WGS84, ecef_to_geodetic, normal_gravity, radii_of_curvature, up_e};
    use nalgebra::Matrix3;
    use std::f64::consts::PI;

    fn config(integrator: Integrator, gravity: GravityModel) -> MechanizationConfig {
        MechanizationConfig {
            ellipsoid: WGS84,
            gravity,
            integrator,
            coning_sculling: true,
        }
    }

    /// The static site of paper 000's experiment.
    fn site() -> Geodetic {
        Geodetic {
            lat_rad: 55.655_f64.to_radians(),
            lon_rad: 37.534_f64.to_radians(),
            height_m: 150.0,
        }
    }

    /// Earth-rate consistency: a perfect stationary IMU, mechanized for one hour at 100 Hz,
    /// must stay put. For those increments the mechanization is an exact equilibrium
    /// (q_z(−ω dt)·q·q(C_b_e ω dt) = q; the rotation compensation ½ C Δθ×Δv cancels the
    /// −½ dt ω×(C Δv) frame-rotation term; sculling and coning vanish), so only rounding is
    /// left. Bound: a systematic attitude rounding of ≤ ε ≈ 2.2e-16 rad per step gives a tilt
    /// ≤ 3.6e5 ε ≈ 8e-11 rad after 3.6e5 steps, which the Schuler loop turns into at most
    /// R·tilt ≈ 0.5 mm; specific-force rounding ≈ 1e-14 m/s² amplified by the unstable
    /// vertical channel (τ ≈ 570 s: τ² cosh(3600/τ) ≈ 9e7 s²) gives ≈ 1e-6 m. Hence 1 mm.
    #[test]
    fn stationary_imu_stays_put_for_one_hour() {
        let cases = [
            (Integrator::Euler, GravityModel::J2),
            (Integrator::Heun, GravityModel::J2),
            (Integrator::Rk4, GravityModel::J2),
            (Integrator::Rk4, GravityModel::Normal),
            (Integrator::Rk4, GravityModel::PointMass),
        ];
        for (integrator, gravity) in cases {
            let q_n_b = q_n_b_from_rpy(0.01, -0.02, 1.0);
            let mut s = NavState::from_geodetic(&WGS84, &site(), &Vector3::zeros(), &q_n_b);
            let (r0, q0) = (s.r_e, s.q_e_b);
            let inc = stationary_increment(&WGS84, gravity, &r0, &q0, 0.01);
            let mut sd = Strapdown::new(config(integrator, gravity));
            for _ in 0..360_000 {
                sd.step(&mut s, &inc);
            }
            let dr = (s.r_e - r0).norm();
            eprintln!(
                "stationary 1 h {integrator:?}/{gravity:?}: |dr| = {dr:.3e} m, |v| = {:.3e} m/s, att = {:.3e} rad",
                s.v_e.norm(),
                s.q_e_b.angle_to(&q0)
            );
            assert!(dr < 1e-3, "{integrator:?}/{gravity:?}: {dr} m");
            assert!(s.q_e_b.angle_to(&q0) < 1e-9);
            assert!((s.q_e_b.norm() - 1.0).abs() < 1e-15);
        }
    }

    /// Free-inertial Schuler oscillation: start at rest with a 0.1 m/s north velocity error,
    /// 3 h at 100 Hz with RK4 and J2 gravity. The vertical channel is unstable (see
    /// `vertical_channel_diverges`): in 3 h the Eötvös coupling of the Foucault-induced east
    /// velocity would grow it by e^(3 h/570 s) ≈ 1e8, so here a perfect altimeter holds height
    /// and vertical velocity after each step (what baro aiding does); the horizontal dynamics
    /// are untouched. The north error is `v0/ν' sin(ν' t) cos(Ω_z t)` with
    /// `ν'² = g/(R_N+h) + Ω_z²`, `Ω_z = ω_ie sinφ` (Foucault), so its zero crossings are
    /// spaced by half of `2π/ν'`, which differs from `2π √((R_N+h)/g)` by ≈ 0.1 %.
    #[test]
    fn schuler_period_free_inertial() {
        let ell = WGS84;
        let g0 = site();
        let dt = 0.01;
        let n_steps = 3 * 3600 * 100;
        let q_n_b = q_n_b_from_rpy(0.0, 0.0, 0.3);
        let truth = NavState::from_geodetic(&ell, &g0, &Vector3::zeros(), &q_n_b);
        let inc = stationary_increment(&ell, GravityModel::J2, &truth.r_e, &truth.q_e_b, dt);
        let v0 = 0.1;
        let mut s = NavState::from_geodetic(&ell, &g0, &Vector3::new(v0, 0.0, 0.0), &q_n_b);
        let mut sd = Strapdown::new(config(Integrator::Rk4, GravityModel::J2));
        let c_n_e = c_e_n(g0.lat_rad, g0.lon_rad).transpose();
        let mut prev_north: f64 = 0.0;
        let mut crossings = [0.0_f64; 16];
        let mut n_cross = 0;
        let mut max_north: f64 = 0.0;
        for k in 1..=n_steps {
            sd.step(&mut s, &inc);
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
            let north = (c_n_e * (s.r_e - truth.r_e)).x;
            max_north = max_north.max(north.abs());
            if k > 1 && prev_north != 0.0 && north.signum() != prev_north.signum() && n_cross < 16 {
                let t = (k - 1) as f64 * dt + dt * prev_north / (prev_north - north);
                crossings[n_cross] = t;
                n_cross += 1;
            }
            prev_north = north;
        }
        assert!(n_cross >= 3, "{n_cross} crossings");
        let period = 2.0 * (crossings[n_cross - 1] - crossings[0]) / (n_cross - 1) as f64;
        let (r_n, _) = radii_of_curvature(&ell, g0.lat_rad);
        let radius = r_n + g0.height_m;
        let gamma = normal_gravity(&ell, g0.lat_rad, g0.height_m);
        let t_schuler = 2.0 * PI * (radius / gamma).sqrt();
        let omega_z = ell.omega_ie_rad_s * g0.lat_rad.sin();
        let t_foucault = 2.0 * PI / (gamma / radius + omega_z * omega_z).sqrt();
        eprintln!(
            "Schuler: {n_cross} crossings, measured T = {period:.2} s ({:.3} min), \
             2π√(R/g) = {t_schuler:.2} s (rel err {:.3e}), with Foucault {t_foucault:.2} s \
             (rel err {:.3e}), max north error {max_north:.2} m",
            period / 60.0,
            period / t_schuler - 1.0,
            period / t_foucault - 1.0
        );
        assert!((period / t_schuler - 1.0).abs() < 0.01);
        // Amplitude v0/ν ≈ 80 m (cos(Ω_z t) ≥ 0.8 over the first lobe).
        let amp = v0 * (radius / gamma).sqrt();
        assert!(
            max_north < amp * 1.01 && max_north > amp * 0.75,
            "{max_north} vs {amp}"
        );
    }

    /// The free vertical channel diverges: a 1 m initial height error grows as
    /// `δh0 cosh(t/τ)` with `1/τ² = −∂|g|/∂h` (≈ 2g/r, so τ ≈ √(R/2g) ≈ 570 s).
    #[test]
    fn vertical_channel_diverges() {
        let ell = WGS84;
        let g0 = site();
        let dt = 0.02;
        let q_n_b = q_n_b_from_rpy(0.0, 0.0, 0.0);
        let truth = NavState::from_geodetic(&ell, &g0, &Vector3::zeros(), &q_n_b);
        let inc = stationary_increment(&ell, GravityModel::J2, &truth.r_e, &truth.q_e_b, dt);
        let dh0 = 1.0;
        let mut s = NavState::from_geodetic(
            &ell,
            &Geodetic {
                height_m: g0.height_m + dh0,
                ..g0
            },
            &Vector3::zeros(),
            &q_n_b,
        );
        let mut sd = Strapdown::new(config(Integrator::Rk4, GravityModel::J2));
        let t_end = 3600.0;
        let n = (t_end / dt) as usize;
        for _ in 0..n {
            sd.step(&mut s, &inc);
        }
        let dh = s.geodetic(&ell).height_m - g0.height_m;
        let tau_meas = t_end / (dh / dh0).acosh();
        // Vertical gradient of the model's gravity magnitude by central difference (±10 m).
        let up = up_e(g0.lat_rad, g0.lon_rad);
        let gmag = |d: f64| gravity_ecef(&ell, GravityModel::J2, &(truth.r_e + up * d)).norm();
        let k = -(gmag(10.0) - gmag(-10.0)) / 20.0;
        let tau_model = 1.0 / k.sqrt();
        let tau_simple = (truth.r_e.norm() / (2.0 * gmag(0.0))).sqrt();
        eprintln!(
            "vertical: dh(1 h) = {dh:.1} m, tau measured {tau_meas:.2} s, model {tau_model:.2} s, \
             sqrt(R/2g) {tau_simple:.2} s"
        );
        assert!((tau_meas / tau_model - 1.0).abs() < 0.01);
        assert!((tau_meas / tau_simple - 1.0).abs() < 0.02);
    }

    /// Integrator ranking and convergence orders on an analytically solvable trajectory: an
    /// equatorial circular orbit under J2 gravity (in the equatorial plane J2 gravitation is
    /// central, `GM/r² (1 + 3/2 J2 (a/r)²)`, so the orbit is circular with
    /// `n² = GM/r³ (1 + 3/2 J2 (a/r)²)`), seen in ECEF as `r (cos (n−ω)t, sin (n−ω)t, 0)`.
    /// A free-falling IMU measures zero specific force, so the increments are exactly known
    /// (Δv = 0, Δθ = 0 for an inertially fixed body) and the only error left is the
    /// integrator's truncation error of the rotating-frame equations (gravity, centrifugal,
    /// Coriolis): global error ∝ dtᵖ with p = 1, 2, 4. The orbit is 7000 km, 4000 s,
    /// dt = 40…5 s, so even RK4's error (≈ 1e-3 m) is far above rounding (≈ 1e-8 m).
    #[test]
    fn integrator_ranking_and_orders() {
        let ell = WGS84;
        let radius: f64 = 7.0e6;
        let n = (ell.gm_m3_s2 / radius.powi(3) * (1.0 + 1.5 * ell.j2 * (ell.a_m / radius).powi(2)))
            .sqrt();
        let w = n - ell.omega_ie_rad_s;
        let exact = |t: f64| {
            let (s, c) = (w * t).sin_cos();
            (
                Vector3::new(c, s, 0.0) * radius,
                Vector3::new(-s, c, 0.0) * radius * w,
            )
        };
        let t_end = 4000.0;
        let dts = [40.0, 20.0, 10.0, 5.0];
        let mut errors = [[0.0; 4]; 3];
        for (ii, integrator) in [Integrator::Euler, Integrator::Heun, Integrator::Rk4]
            .iter()
            .enumerate()
        {
            for (jj, dt) in dts.iter().enumerate() {
                let (r0, v0) = exact(0.0);
                let mut s = NavState {
                    r_e: r0,
                    v_e: v0,
                    q_e_b: UnitQuaternion::identity(),
                };
                let mut sd = Strapdown::new(config(*integrator, GravityModel::J2));
                let inc = ImuIncrement {
                    dt_s: *dt,
                    ..Default::default()
                };
                for _ in 0..(t_end / dt).round() as usize {
                    sd.step(&mut s, &inc);
                }
                errors[ii][jj] = (s.r_e - exact(t_end).0).norm();
            }
        }
        let expected = [1.0, 2.0, 4.0];
        for jj in 0..dts.len() {
            assert!(
                errors[0][jj] > errors[1][jj] && errors[1][jj] > errors[2][jj],
                "{errors:?}"
            );
        }
        for ii in 0..3 {
            let orders: Vec<f64> = (0..3)
                .map(|jj| (errors[ii][jj] / errors[ii][jj + 1]).log2())
                .collect();
            eprintln!(
                "integrator {ii}: errors {:?} m, observed orders {orders:?}",
                errors[ii]
            );
            let p = orders[2];
            assert!(
                (p - expected[ii]).abs() < 0.1 * expected[ii],
                "order {p} vs {}",
                expected[ii]
            );
        }
    }

    /// Classic coning (rotation vector of constant length α turning at Ω about z): the coning
    /// correction removes the leading attitude drift of the uncorrected algorithm.
    #[test]
    fn coning_correction_reduces_drift() {
        let alpha = 0.02;
        let omega = 2.0 * PI * 5.0;
        let q_i_b = |t: f64| {
            let (s, c) = (omega * t).sin_cos();
            crate::attitude::quat_from_rotation_vector(&(Vector3::new(c, s, 0.0) * alpha))
        };
        // Body rate ω_b = J_r(φ) φ̇ (right Jacobian of the exponential map).
        let rate = |t: f64| {
            let (s, c) = (omega * t).sin_cos();
            let phi = Vector3::new(c, s, 0.0) * alpha;
            let phi_dot = Vector3::new(-s, c, 0.0) * alpha * omega;
            let a = alpha;
            let k = skew(&phi);
            let jr = Matrix3::identity() - k * ((1.0 - a.cos()) / (a * a))
                + k * k * ((a - a.sin()) / (a * a * a));
            jr * phi_dot
        };
        let dt = 0.01;
        let n = 1000;
        let ell = WGS84;
        let mut drift = [0.0; 2];
        for (ci, coning) in [false, true].iter().enumerate() {
            let mut cfg = config(Integrator::Rk4, GravityModel::J2);
            cfg.coning_sculling = *coning;
            let mut sd = Strapdown::new(cfg);
            let mut s = NavState {
                r_e: Vector3::new(4.2e7, 0.0, 0.0),
                v_e: Vector3::zeros(),
                q_e_b: q_i_b(0.0),
            };
            for k in 0..n {
                let t0 = k as f64 * dt;
                // Simpson with 64 panels: error ≈ (Ω dt/64)⁴ relative, negligible.
                let m = 64;
                let h = dt / m as f64;
                let mut d_theta = rate(t0) + rate(t0 + dt);
                for j in 1..m {
                    d_theta += rate(t0 + j as f64 * h) * if j % 2 == 1 { 4.0 } else { 2.0 };
                }
                d_theta *= h / 3.0;
                sd.step(
                    &mut s,
                    &ImuIncrement {
                        dt_s: dt,
                        delta_angle_rad: d_theta,
                        delta_velocity_m_s: Vector3::zeros(),
                    },
                );
            }
            let t = n as f64 * dt;
            let (sz, cz) = (0.5 * ell.omega_ie_rad_s * t).sin_cos();
            let q_earth = UnitQuaternion::new_unchecked(Quaternion::new(cz, 0.0, 0.0, -sz));
            let truth = q_earth * q_i_b(t);
            drift[ci] = rotation_vector_from_quat(&(truth.inverse() * s.q_e_b)).norm();
        }
        eprintln!(
            "coning drift over 10 s: without {:.3e} rad, with {:.3e} rad",
            drift[0], drift[1]
        );
        assert!(drift[1] * 10.0 < drift[0], "{drift:?}");
    }

    #[test]
    fn invalid_increment_is_ignored() {
        let mut s = NavState::from_geodetic(
            &WGS84,
            &site(),
            &Vector3::zeros(),
            &UnitQuaternion::identity(),
        );
        let before = s;
        let mut sd = Strapdown::new(config(Integrator::Rk4, GravityModel::J2));
        for inc in [
            ImuIncrement {
                dt_s: 0.0,
                ..Default::default()
            },
            ImuIncrement {
                dt_s: -0.01,
                ..Default::default()
            },
            ImuIncrement {
                dt_s: f64::NAN,
                ..Default::default()
            },
            ImuIncrement {
                dt_s: 0.01,
                delta_angle_rad: Vector3::new(f64::NAN, 0.0, 0.0),
                ..Default::default()
            },
            ImuIncrement {
                dt_s: 0.01,
                delta_velocity_m_s: Vector3::new(0.0, f64::INFINITY, 0.0),
                ..Default::default()
            },
        ] {
            sd.step(&mut s, &inc);
            assert_eq!(s, before);
        }
        // Round trip of the NED helpers.
        let q_n_b = q_n_b_from_rpy(0.1, 0.2, 0.3);
        let v = Vector3::new(1.0, -2.0, 0.5);
        let st = NavState::from_geodetic(&WGS84, &site(), &v, &q_n_b);
        assert!((st.v_ned(&WGS84) - v).norm() < 1e-12);
        assert!(st.q_n_b(&WGS84).angle_to(&q_n_b) < 1e-12);
    }
}
