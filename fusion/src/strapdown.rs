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
//!
//! OWNER: foundations helper. Signatures are the contract.

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
#[derive(Debug, Clone)]
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
        if !(dt > 0.0 && dt.is_finite())
            || !d_theta.iter().all(|x| x.is_finite())
            || !d_v.iter().all(|x| x.is_finite())
        {
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
