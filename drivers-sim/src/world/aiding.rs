//! The aiding sensors' own world: the star tracker's slow thermal error, its bias about the
//! boresight and its time-tag latency; the weather and the air temperature the barometer
//! lives in, and its sensor's temperature sensitivity.
//!
//! **Star tracker.** Thermal gradients across the optical head bend the line of sight slowly:
//! a first-order Gauss–Markov rotation about each cross axis (arcseconds, correlation times of
//! tens of minutes; Liebe, "Accuracy performance of star trackers — a tutorial", IEEE TAES
//! 38(2), 2002, §"low spatial frequency error" and thermal distortion), plus a constant
//! rotation about the boresight drawn per unit (the roll axis is the least observable, and
//! what a calibration leaves there stays). A time-tag latency L: the sample stamped t is the
//! attitude at t − L.
//!
//! **Barometer.** The real atmosphere is not ISA: the sea-level pressure of the day, an air
//! temperature offset ΔT from ISA at every height (hypsometric law with the same lapse rate:
//! `p(h) = p₀(t)·((T₀ + ΔT − L h)/(T₀ + ΔT))^{g/(R L)}`, so a receiver converting with ISA
//! sees its height scaled by ≈ T₀/(T₀ + ΔT)), and the weather's pressure tendency, drawn per
//! run (1-σ about 1 hPa/h for a passing system; WMO "Guide to Meteorological Instruments",
//! WMO-No. 8, pressure tendency), which the filter's bias state must track. The sensor's own
//! temperature coefficient acts on the temperature of its bay (the scenario's `[imu]`
//! temperature profile).

use super::gauss_markov::GaussMarkov;
use super::{ARCSEC_RAD, yes};
use rand::Rng;
use rand_chacha::ChaCha20Rng;
use rand_distr::StandardNormal;
use serde::Deserialize;

/// `[world.star_tracker]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StarTrackerWorldSpec {
    /// Whether the effect is applied.
    #[serde(default = "yes")]
    pub enabled: bool,
    /// 1-σ of the thermal error about each cross axis, arcsec.
    pub thermal_sigma_arcsec: f64,
    /// Correlation time of the thermal error, s.
    pub thermal_tau_s: f64,
    /// 1-σ of the unit's constant error about the boresight, arcsec.
    pub boresight_bias_sigma_arcsec: f64,
    /// Time-tag latency, s (a whole number of milliseconds below one period).
    pub latency_s: f64,
}

/// The star tracker's world state during a run (one per star-tracker process).
#[derive(Debug, Clone)]
pub struct StarTrackerWorld {
    rng: ChaCha20Rng,
    thermal: [GaussMarkov; 2],
    boresight_bias_rad: f64,
    last_t_s: Option<f64>,
}

impl StarTrackerWorld {
    /// Draw the unit and start the thermal processes from `rng` (stream `"world_star"`).
    pub fn new(spec: &StarTrackerWorldSpec, mut rng: ChaCha20Rng) -> Self {
        let s = spec.thermal_sigma_arcsec * ARCSEC_RAD;
        let thermal = [
            GaussMarkov::new(s, spec.thermal_tau_s, &mut rng),
            GaussMarkov::new(s, spec.thermal_tau_s, &mut rng),
        ];
        let n: f64 = rng.sample(StandardNormal);
        Self {
            boresight_bias_rad: spec.boresight_bias_sigma_arcsec * ARCSEC_RAD * n,
            thermal,
            rng,
            last_t_s: None,
        }
    }

    /// The error rotation (sensor axes, rad; z = boresight) at `t_s` (times must increase).
    pub fn error_s_rad(&mut self, t_s: f64) -> [f64; 3] {
        if let Some(prev) = self.last_t_s {
            let dt = t_s - prev;
            for g in &mut self.thermal {
                g.step(dt, &mut self.rng);
            }
        }
        self.last_t_s = Some(t_s);
        [
            self.thermal[0].value(),
            self.thermal[1].value(),
            self.boresight_bias_rad,
        ]
    }
}

/// `[world.baro]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BaroWorldSpec {
    /// Whether the effect is applied.
    #[serde(default = "yes")]
    pub enabled: bool,
    /// Sea-level pressure at the start of the run, hPa (ISA: 1013.25).
    pub sea_level_pressure_hpa: f64,
    /// Air temperature offset from ISA at every height, K.
    pub temperature_offset_k: f64,
    /// 1-σ of the run's pressure tendency, hPa/h.
    pub tendency_sigma_hpa_h: f64,
    /// The sensor's pressure error per °C of its temperature from 20 °C, Pa/°C.
    pub sensor_temp_coeff_pa_per_c: f64,
}

/// Standard gravity, m/s².
const G0_M_S2: f64 = 9.806_65;
/// Specific gas constant of dry air, J/(kg·K).
const R_DRY_J_KG_K: f64 = 287.052_87;
/// Standard tropospheric lapse rate, K/m.
const LAPSE_K_M: f64 = 0.0065;
/// Standard sea-level temperature, K.
const T0_K: f64 = 288.15;
/// Reference temperature of the sensor's coefficient, °C.
const SENSOR_REFERENCE_C: f64 = 20.0;

/// The barometer's world during a run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BaroWorld {
    spec: BaroWorldSpec,
    /// This run's pressure tendency, Pa/s.
    pub tendency_pa_s: f64,
}

impl BaroWorld {
    /// Draw the run's tendency from `rng` (stream `"world_baro"`).
    pub fn new(spec: &BaroWorldSpec, rng: &mut ChaCha20Rng) -> Self {
        let n: f64 = rng.sample(StandardNormal);
        Self {
            spec: *spec,
            tendency_pa_s: spec.tendency_sigma_hpa_h * 100.0 / 3600.0 * n,
        }
    }

    /// True static pressure (Pa) and air temperature (K) at height `h_m` and `t_s`.
    pub fn air(&self, h_m: f64, t_s: f64) -> (f64, f64) {
        let p0 = self.spec.sea_level_pressure_hpa * 100.0 + self.tendency_pa_s * t_s;
        let t0 = T0_K + self.spec.temperature_offset_k;
        let t = t0 - LAPSE_K_M * h_m;
        (p0 * (t / t0).powf(G0_M_S2 / (R_DRY_J_KG_K * LAPSE_K_M)), t)
    }

    /// The sensor's own error at its temperature `sensor_c`, Pa.
    pub fn sensor_error_pa(&self, sensor_c: f64) -> f64 {
        self.spec.sensor_temp_coeff_pa_per_c * (sensor_c - SENSOR_REFERENCE_C)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::gauss_markov::{assert_gauss_markov_statistics, mean_and_standard_error};
    use rand::SeedableRng;

    fn star() -> StarTrackerWorldSpec {
        StarTrackerWorldSpec {
            enabled: true,
            thermal_sigma_arcsec: 3.0,
            thermal_tau_s: 1800.0,
            boresight_bias_sigma_arcsec: 5.0,
            latency_s: 0.0,
        }
    }

    /// Thermal error: σ and e^{−lag/τ} at lag 20 min (4 SE); the boresight bias: E[b²] = σ²
    /// and constant.
    #[test]
    fn star_tracker_thermal_and_boresight_magnitude_and_correlation() {
        let s = star();
        let mut seeds = ChaCha20Rng::seed_from_u64(41);
        let mut bias_sq = Vec::new();
        assert_gauss_markov_statistics(
            "thermal",
            3000,
            60.0,
            20,
            s.thermal_sigma_arcsec * ARCSEC_RAD,
            s.thermal_tau_s,
            |_| {
                let mut w = StarTrackerWorld::new(&s, ChaCha20Rng::seed_from_u64(seeds.random()));
                let x: Vec<[f64; 3]> = (0..=20).map(|k| w.error_s_rad(k as f64 * 60.0)).collect();
                assert!(x.iter().all(|e| e[2] == x[0][2]));
                bias_sq.push(x[0][2].powi(2));
                x.iter().map(|e| e[0]).collect()
            },
        );
        let (v, se) = mean_and_standard_error(&bias_sq);
        let s2 = (s.boresight_bias_sigma_arcsec * ARCSEC_RAD).powi(2);
        assert!((v - s2).abs() < 4.0 * se, "{v} vs {s2}");
    }

    /// Pressure tendency: E[rate²] = σ² (4 SE); a warm day: the ISA inversion of the true
    /// pressure reads the height short by the hypsometric ratio `T₀/(T₀ + ΔT)` exactly (same
    /// lapse rate: `h_ISA = (T₀/L)(1 − (p/p₀)^{1/n}) = (T₀/L)·L h/(T₀ + ΔT)`).
    #[test]
    fn baro_tendency_and_warm_air() {
        let spec = BaroWorldSpec {
            enabled: true,
            sea_level_pressure_hpa: 1013.25,
            temperature_offset_k: 15.0,
            tendency_sigma_hpa_h: 1.0,
            sensor_temp_coeff_pa_per_c: 2.0,
        };
        let mut rng = ChaCha20Rng::seed_from_u64(42);
        let sq: Vec<f64> = (0..4000)
            .map(|_| BaroWorld::new(&spec, &mut rng).tendency_pa_s.powi(2))
            .collect();
        let (v, se) = mean_and_standard_error(&sq);
        let s2 = (100.0f64 / 3600.0).powi(2);
        assert!((v - s2).abs() < 4.0 * se, "{v} vs {s2}");
        let w = BaroWorld {
            spec,
            tendency_pa_s: 0.0,
        };
        for h in [200.0, 1000.0, 3000.0] {
            let (p, t) = w.air(h, 0.0);
            let h_isa = fusion::atmosphere::isa_altitude_m(p);
            let expect = h * T0_K / (T0_K + spec.temperature_offset_k);
            assert!(
                (h_isa - expect).abs() < 1e-9 * h,
                "{h}: ISA {h_isa} vs {expect}"
            );
            assert!((t - (T0_K + 15.0 - LAPSE_K_M * h)).abs() < 1e-12);
        }
        assert_eq!(w.sensor_error_pa(25.0), 10.0);
    }
}
