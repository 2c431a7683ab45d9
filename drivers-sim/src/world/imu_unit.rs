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
//! Size effect: each accelerometer's proof mass sits away from the point the unit reports
//! for, so on a rotating body it senses also `ω̇ × r_i + ω × (ω × r_i)` along its axis
//! (Savage, "Strapdown Analytics", 2nd ed., §6.4; Titterton & Weston §8.2.3). A unit
//! compensates the offsets its drawings give; what is left is the residual of each offset,
//! drawn here per component (`accel_size_effect_residual_mm`, 1-σ), from its own stream
//! `"world_imu_size_effect"`. Over an interval the integral is exact from the truth's rate:
//! `∫ω̇ dt = Δω`, `∫ω × (ω × r) dt = (W − tr W·I) r` with `W = ∫ωωᵀ dt`.
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
    /// 1-σ per component of each accelerometer's offset left after the unit's size-effect
    /// compensation, mm (0 when absent: a perfect compensation).
    #[serde(default)]
    pub accel_size_effect_residual_mm: f64,
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
    /// Column i: accelerometer i's residual offset from the reported point, body, m.
    pub accel_offsets_b_m: Matrix3<f64>,
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
            accel_offsets_b_m: Matrix3::zeros(),
        }
    }

    /// This unit with its accelerometers' residual offsets drawn from `rng` (the stream
    /// `"world_imu_size_effect"`: the other draws of the unit stay those of `"world_imu"`).
    pub fn with_size_effect(mut self, spec: &ImuUnitSpec, rng: &mut ChaCha20Rng) -> Self {
        let s = spec.accel_size_effect_residual_mm * 1e-3;
        self.accel_offsets_b_m = Matrix3::from_fn(|_, _| s * rng.sample::<f64, _>(StandardNormal));
        self
    }

    /// The size effect's velocity increment over an interval, body, m/s: accelerometer i
    /// senses `e_iᵀ(Δω × r_i + (W − tr W·I) r_i)` with `Δω` the change of the body rate over
    /// the interval (rad/s) and `W = ∫ωωᵀ dt` (rad²/s).
    pub fn size_effect_dv_b_m_s(
        &self,
        delta_rate_b_rad_s: &Vector3<f64>,
        rate_outer_b_rad2_s: &Matrix3<f64>,
    ) -> Vector3<f64> {
        let centripetal = rate_outer_b_rad2_s - Matrix3::identity() * rate_outer_b_rad2_s.trace();
        Vector3::from_fn(|i, _| {
            let r = self.accel_offsets_b_m.column(i).into_owned();
            (delta_rate_b_rad_s.cross(&r) + centripetal * r)[i]
        })
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
            accel_size_effect_residual_mm: 1.0,
        }
    }

    /// A body spinning steadily at ω about z (Δω = 0, W = ω²T e_z e_zᵀ): the x accelerometer
    /// offset by r along x senses the centripetal −ω²r·T, the z one nothing; a step of the
    /// rate Δω about z gives the x accelerometer offset along y the tangential −Δω·r_y. The
    /// drawn offsets have the specified σ (4000 units, 4 standard errors) and leave the
    /// `"world_imu"` draws as they were.
    #[test]
    fn size_effect_closed_forms_and_draws() {
        let mut u = ImuUnit::new(&spec(), &mut ChaCha20Rng::seed_from_u64(3));
        let (w, t, r) = (0.5, 0.01, 0.002);
        u.accel_offsets_b_m = Matrix3::new(r, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, r);
        let outer = Matrix3::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, w * w * t);
        let dv = u.size_effect_dv_b_m_s(&Vector3::zeros(), &outer);
        assert!((dv.x + w * w * r * t).abs() < 1e-18, "{dv}");
        assert!(dv.z.abs() < 1e-18 && dv.y.abs() < 1e-18, "{dv}");
        u.accel_offsets_b_m = Matrix3::new(0.0, 0.0, 0.0, r, 0.0, 0.0, 0.0, 0.0, 0.0);
        let dv = u.size_effect_dv_b_m_s(&Vector3::new(0.0, 0.0, 0.3), &Matrix3::zeros());
        assert!((dv.x + 0.3 * r).abs() < 1e-18, "{dv}");
        let mut rng = ChaCha20Rng::seed_from_u64(9);
        let sq: Vec<f64> = (0..4000)
            .map(|_| {
                ImuUnit::new(&spec(), &mut ChaCha20Rng::seed_from_u64(1))
                    .with_size_effect(&spec(), &mut rng)
                    .accel_offsets_b_m[(2, 1)]
                    .powi(2)
            })
            .collect();
        let (v, se) = mean_and_standard_error(&sq);
        assert!((v - 1e-6).abs() < 4.0 * se, "{v} vs 1e-6 m² ± {se}");
        let a = ImuUnit::new(&spec(), &mut ChaCha20Rng::seed_from_u64(1));
        let b = a.with_size_effect(&spec(), &mut rng);
        assert_eq!(a.gyro_g_sensitivity, b.gyro_g_sensitivity);
        assert_eq!(a.accel_warmup_m_s2, b.accel_warmup_m_s2);
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
