//! Strapdown mechanization in ECEF from delta-angle / delta-velocity samples, with coning and
//! sculling corrections and selectable integrators (paper 002: Euler, Heun, Runge–Kutta).
//!
//! OWNER: foundations helper. Signatures are the contract.

use crate::earth::{Ellipsoid, Geodetic, GravityModel};
use nalgebra::{UnitQuaternion, Vector3};

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
    pub fn step(&mut self, state: &mut NavState, inc: &ImuIncrement) {
        let _ = (state, inc, &self.prev);
        unimplemented!("foundations helper")
    }
}

impl NavState {
    /// Geodetic position on `ell`.
    pub fn geodetic(&self, ell: &Ellipsoid) -> Geodetic {
        crate::earth::ecef_to_geodetic(ell, &self.r_e)
    }
}
