//! The aiding sensors as units of their model, not their data sheets: the star tracker's, the
//! odometer's, the barometer's and the GNSS receiver's code-tracking white noise scattered about
//! the class value, the receiver oscillator's Allan coefficients scattered about its class, and
//! the constant errors a data sheet states as a 1-σ (the odometer's scale factor, the
//! barometer's bias) drawn per unit.
//!
//! Units of one model differ: noise figures by tens of percent between serial numbers (the
//! same log-normal law as the IMU's, [`super::imu_unit`]), oscillators of one class by a factor
//! of about two in their Allan deviation (IEEE Std 1139-2008 specifies a class bound; Brown &
//! Hwang, 4th ed., Table 9.2, lists typical values for a class). A data sheet's constant error
//! ("scale factor 0.2 %", "bias 30 Pa") is a 1-σ over the units made, not the value every unit
//! has: with `[world.units]` each unit draws its own from `N(0, σ²)`. Without the table the
//! sensors are their data sheets (the matched fixture: noise exactly the class value, constant
//! errors exactly the stated value).
//!
//! Each sensor draws its unit from its own stream `"world_unit_<sensor>"`, a fixed number of
//! draws ([`AidingUnit::draw`]), so every process simulating that sensor draws the same unit
//! and no other stream moves.

use rand::Rng;
use rand_distr::StandardNormal;
use serde::Deserialize;

/// `[world.units]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UnitsSpec {
    /// Whether the effect is applied.
    #[serde(default = "super::yes")]
    pub enabled: bool,
    /// 1-σ of the natural log of each unit's white-noise σ over the data sheet's (star tracker
    /// cross and roll, odometer speed, barometer pressure, receiver code tracking).
    pub noise_log_sigma: f64,
    /// 1-σ of the natural log of the receiver oscillator's `h₀` and `h₋₂` over its class.
    pub oscillator_log_sigma: f64,
}

/// One unit's draws (fixed layout, whatever the sensor uses of it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AidingUnit {
    /// Factors on the data sheet's white-noise σ (`e^{s·n}`), up to three per sensor (star
    /// tracker: cross, roll; the others use the first).
    pub noise_factors: [f64; 3],
    /// Unit-normal draws of the constant errors (a data sheet's 1-σ times these).
    pub constant_normals: [f64; 2],
    /// Factors on the oscillator class's `h₀` and `h₋₂` (receiver only).
    pub oscillator_factors: [f64; 2],
}

impl AidingUnit {
    /// The unit of `sensor` (`"star_tracker"`, `"odometer"`, `"baro"`, `"gnss"`) for scenario
    /// seed `seed`: seven draws from stream `"world_unit_<sensor>"` (three noise factors, two
    /// constant errors, two oscillator factors).
    pub fn draw(spec: &UnitsSpec, seed: u64, sensor: &str) -> Self {
        let mut rng = crate::sensor_rng(seed, &format!("world_unit_{sensor}"));
        let mut n = || rng.sample::<f64, _>(StandardNormal);
        let s = spec.noise_log_sigma;
        let noise_factors = [(s * n()).exp(), (s * n()).exp(), (s * n()).exp()];
        let constant_normals = [n(), n()];
        let o = spec.oscillator_log_sigma;
        let oscillator_factors = [(o * n()).exp(), (o * n()).exp()];
        Self {
            noise_factors,
            constant_normals,
            oscillator_factors,
        }
    }

    /// The data sheet itself: every factor 1 and every constant error its stated value (a
    /// unit normal of 1).
    pub const DATA_SHEET: Self = Self {
        noise_factors: [1.0; 3],
        constant_normals: [1.0; 2],
        oscillator_factors: [1.0; 2],
    };
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::gauss_markov::mean_and_standard_error;

    /// Over 4000 units (seeds): E[ln² factor] = s² for the noise and the oscillator factors,
    /// E[n²] = 1 and E[n] = 0 for the constant errors, each within 4 standard errors; the
    /// sensors' streams are independent (correlation of their first factors' logs within
    /// 4/√4000); the same seed and sensor give the same unit.
    #[test]
    fn unit_scatter_magnitudes_and_independence() {
        let spec = UnitsSpec {
            enabled: true,
            noise_log_sigma: 0.2,
            oscillator_log_sigma: 0.5,
        };
        let units = |sensor: &str| -> Vec<AidingUnit> {
            (0..4000u64)
                .map(|seed| AidingUnit::draw(&spec, seed, sensor))
                .collect()
        };
        let (odo, baro) = (units("odometer"), units("baro"));
        type Draw = fn(&AidingUnit) -> f64;
        let checks: [(&str, f64, Draw); 5] = [
            ("noise 0", 0.04, |u| u.noise_factors[0].ln().powi(2)),
            ("noise 2", 0.04, |u| u.noise_factors[2].ln().powi(2)),
            ("oscillator 1", 0.25, |u| {
                u.oscillator_factors[1].ln().powi(2)
            }),
            ("constant 0 squared", 1.0, |u| u.constant_normals[0].powi(2)),
            ("constant 1", 0.0, |u| u.constant_normals[1]),
        ];
        for (name, want, f) in checks {
            let v: Vec<f64> = odo.iter().map(f).collect();
            let (m, se) = mean_and_standard_error(&v);
            assert!(
                (m - want).abs() < 4.0 * se,
                "{name}: {m} vs {want} (SE {se})"
            );
        }
        let r: f64 = odo
            .iter()
            .zip(&baro)
            .map(|(a, b)| a.noise_factors[0].ln() * b.noise_factors[0].ln())
            .sum::<f64>()
            / 4000.0
            / 0.04;
        assert!(r.abs() < 4.0 / 4000f64.sqrt(), "correlation {r}");
        assert_eq!(AidingUnit::draw(&spec, 7, "baro"), baro[7]);
    }
}
