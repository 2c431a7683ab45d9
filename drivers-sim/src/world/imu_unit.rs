//! The actual IMU unit, not its data sheet: its noise densities and bias instability scattered
//! around the grade's class values, a g-sensitive gyro drift, and the turn-on warm-up transient
//! of both biases.
//!
//! A data sheet gives a class: units of one model differ (noise densities and bias
//! instability vary by tens of percent between serial numbers; IEEE Std 952-1997 Annex C and
//! IEEE Std 1293-2018 show the Allan deviations of several units of one model scattered about
//! the specified line). The world draws this unit's factor per triad from a log-normal
//! distribution with median 1 (`factor = e^{s·n}`, n ~ N(0, 1)), so the filter, tuned to the
//! data sheet, meets a unit that is quieter or noisier than it believes.
//!
//! g-sensitivity: a gyro's bias changes with the specific force along its axes,
//! `δω = G·f^b` (IEEE Std 952-1997 §8.1.3 "acceleration-sensitive drift", 1-σ per element of
//! G in °/h/g); integrated over an interval it is `G·Δv`. The truth process's reported gyro
//! bias includes the warm-up but not this term (it depends on the motion, not on the unit's
//! state).
//!
//! Warm-up: at power-on both biases settle exponentially, `b_w·e^{−t/τ}` with `b_w` drawn per
//! axis (thermal gradients settling; Titterton & Weston, "Strapdown Inertial Navigation
//! Technology", 2nd ed., §4.2.4 and §8.2: run-up transients).
//!
//! The accelerometer triad's misalignment to the gyro-defined body frame is already part of
//! every unit's constant errors ([`crate::imu`], six independent terms).
//!
//! Draws come from the stream `"world_imu"`, so the `"imu"` stream of every run is unchanged.

use nalgebra::{Matrix3, Vector3};
use rand::Rng;
use rand_chacha::ChaCha20Rng;
use rand_distr::StandardNormal;
use serde::Deserialize;

const DEG_H_TO_RAD_S: f64 = std::f64::consts::PI / 180.0 / 3600.0;
/// Standard gravity for the per-g and µg units, m/s².
const G0_M_S2: f64 = 9.806_65;

/// `[world.imu]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImuUnitSpec {
    /// Whether the effect is applied.
    #[serde(default = "super::yes")]
    pub enabled: bool,
    /// 1-σ of the natural log of this unit's white-noise densities (ARW, VRW) over the
    /// data sheet's (0.2: about ±20 %).
    pub noise_log_sigma: f64,
    /// 1-σ of the natural log of this unit's bias random-walk intensities over the data
    /// sheet's.
    pub bias_instability_log_sigma: f64,
    /// 1-σ of each element of the gyros' g-sensitivity matrix, °/h per g.
    pub gyro_g_sensitivity_deg_h_per_g: f64,
    /// 1-σ per axis of the gyro warm-up transient at power-on, °/h.
    pub gyro_warmup_deg_h: f64,
    /// 1-σ per axis of the accelerometer warm-up transient at power-on, µg.
    pub accel_warmup_ug: f64,
    /// Time constant of the warm-up, s.
    pub warmup_tau_s: f64,
}

/// This unit's draws.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuUnit {
    /// Factor on the data sheet's gyro ARW.
    pub gyro_noise_factor: f64,
    /// Factor on the data sheet's accelerometer VRW.
    pub accel_noise_factor: f64,
    /// Factor on the data sheet's gyro bias random walk.
    pub gyro_bias_rw_factor: f64,
    /// Factor on the data sheet's accelerometer bias random walk.
    pub accel_bias_rw_factor: f64,
    /// Gyro g-sensitivity, (rad/s) per (m/s²).
    pub gyro_g_sensitivity: Matrix3<f64>,
    /// Gyro warm-up bias at power-on, rad/s.
    pub gyro_warmup_rad_s: Vector3<f64>,
    /// Accelerometer warm-up bias at power-on, m/s².
    pub accel_warmup_m_s2: Vector3<f64>,
    /// Warm-up time constant, s.
    pub warmup_tau_s: f64,
}

impl ImuUnit {
    /// Draw the unit of `spec` from `rng` (fixed order: four factors, G by rows, gyro then
    /// accelerometer warm-up).
    pub fn new(spec: &ImuUnitSpec, rng: &mut ChaCha20Rng) -> Self {
        let mut n = || rng.sample::<f64, _>(StandardNormal);
        let gyro_noise_factor = (spec.noise_log_sigma * n()).exp();
        let accel_noise_factor = (spec.noise_log_sigma * n()).exp();
        let gyro_bias_rw_factor = (spec.bias_instability_log_sigma * n()).exp();
        let accel_bias_rw_factor = (spec.bias_instability_log_sigma * n()).exp();
        let g = spec.gyro_g_sensitivity_deg_h_per_g * DEG_H_TO_RAD_S / G0_M_S2;
        let gyro_g_sensitivity = Matrix3::from_fn(|_, _| g * n());
        let gw = spec.gyro_warmup_deg_h * DEG_H_TO_RAD_S;
        let gyro_warmup_rad_s = Vector3::from_fn(|_, _| gw * n());
        let aw = spec.accel_warmup_ug * 1e-6 * G0_M_S2;
        let accel_warmup_m_s2 = Vector3::from_fn(|_, _| aw * n());
        Self {
            gyro_noise_factor,
            accel_noise_factor,
            gyro_bias_rw_factor,
            accel_bias_rw_factor,
            gyro_g_sensitivity,
            gyro_warmup_rad_s,
            accel_warmup_m_s2,
            warmup_tau_s: spec.warmup_tau_s,
        }
    }

    /// Warm-up biases (gyro rad/s, accelerometer m/s²) at `t_s` after power-on.
    pub fn warmup(&self, t_s: f64) -> (Vector3<f64>, Vector3<f64>) {
        let d = (-t_s.max(0.0) / self.warmup_tau_s).exp();
        (self.gyro_warmup_rad_s * d, self.accel_warmup_m_s2 * d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::gauss_markov::mean_and_standard_error;
    use rand::SeedableRng;

    fn spec() -> ImuUnitSpec {
        ImuUnitSpec {
            enabled: true,
            noise_log_sigma: 0.2,
            bias_instability_log_sigma: 0.3,
            gyro_g_sensitivity_deg_h_per_g: 0.01,
            gyro_warmup_deg_h: 0.02,
            accel_warmup_ug: 30.0,
            warmup_tau_s: 300.0,
        }
    }

    /// Over independent units: E[ln² factor] = s², E[G_ij²] = σ_G², E[b_w²] = σ_w² (each
    /// within 4 standard errors); the warm-up has decayed to e^{−1} after τ, exactly.
    #[test]
    fn unit_scatter_g_sensitivity_and_warmup_magnitudes() {
        let s = spec();
        let mut rng = ChaCha20Rng::seed_from_u64(31);
        let units: Vec<ImuUnit> = (0..4000).map(|_| ImuUnit::new(&s, &mut rng)).collect();
        let g_sigma = s.gyro_g_sensitivity_deg_h_per_g * DEG_H_TO_RAD_S / G0_M_S2;
        type Draw = fn(&ImuUnit) -> f64;
        let checks: [(&str, f64, Draw); 6] = [
            ("gyro noise", s.noise_log_sigma, |u| {
                u.gyro_noise_factor.ln()
            }),
            ("accel noise", s.noise_log_sigma, |u| {
                u.accel_noise_factor.ln()
            }),
            ("gyro bias rw", s.bias_instability_log_sigma, |u| {
                u.gyro_bias_rw_factor.ln()
            }),
            ("g-sensitivity", g_sigma, |u| u.gyro_g_sensitivity[(1, 2)]),
            ("gyro warm-up", s.gyro_warmup_deg_h * DEG_H_TO_RAD_S, |u| {
                u.gyro_warmup_rad_s.x
            }),
            ("accel warm-up", s.accel_warmup_ug * 1e-6 * G0_M_S2, |u| {
                u.accel_warmup_m_s2.z
            }),
        ];
        for (name, sigma, f) in checks {
            let sq: Vec<f64> = units.iter().map(|u| f(u).powi(2)).collect();
            let (v, se) = mean_and_standard_error(&sq);
            assert!(
                (v - sigma * sigma).abs() < 4.0 * se,
                "{name}: {v} vs {} (SE {se})",
                sigma * sigma
            );
        }
        let u = &units[0];
        let (g0, a0) = u.warmup(0.0);
        let (g1, a1) = u.warmup(s.warmup_tau_s);
        assert!((g1 - g0 * (-1f64).exp()).norm() < 1e-18);
        assert!((a1 - a0 * (-1f64).exp()).norm() < 1e-15);
    }
}
