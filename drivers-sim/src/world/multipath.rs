//! Code multipath: an elevation-dependent first-order Gauss–Markov error per satellite.
//!
//! `m_k(t) = σ(el)·u_k(t)`, `u_k` a unit-variance Gauss–Markov process with correlation time
//! τ (seconds to minutes: the reflector geometry changes as the satellite and the vehicle
//! move), and `σ(el) = σ_z + σ_h·e^{−el/θ}` — the exponential elevation model of RTCA DO-229
//! (airborne multipath `0.13 + 0.53 e^{−θ/10°}` m), with this world's own magnitudes.

use super::gauss_markov::GaussMarkov;
use rand_chacha::ChaCha20Rng;
use serde::Deserialize;

/// `[world.multipath]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MultipathSpec {
    /// Whether the effect is applied.
    #[serde(default = "super::yes")]
    pub enabled: bool,
    /// 1-σ at the zenith (the floor), m.
    pub sigma_zenith_m: f64,
    /// Additional 1-σ at the horizon, m.
    pub sigma_horizon_m: f64,
    /// Elevation scale θ of the exponential, deg.
    pub elevation_scale_deg: f64,
    /// Correlation time, s.
    pub tau_s: f64,
}

impl MultipathSpec {
    /// 1-σ at elevation `el_rad`, m.
    pub fn sigma_m(&self, el_rad: f64) -> f64 {
        self.sigma_zenith_m
            + self.sigma_horizon_m * (-el_rad.to_degrees() / self.elevation_scale_deg).exp()
    }
}

/// Multipath of every satellite.
#[derive(Debug, Clone)]
pub struct Multipath {
    spec: MultipathSpec,
    unit: Vec<GaussMarkov>,
}

impl Multipath {
    /// For `n_sats` satellites.
    pub fn new(spec: MultipathSpec, n_sats: usize, rng: &mut ChaCha20Rng) -> Self {
        Self {
            unit: (0..n_sats)
                .map(|_| GaussMarkov::new(1.0, spec.tau_s, rng))
                .collect(),
            spec,
        }
    }

    /// Advance every satellite's process by `dt_s`.
    pub fn step(&mut self, dt_s: f64, rng: &mut ChaCha20Rng) {
        for u in &mut self.unit {
            u.step(dt_s, rng);
        }
    }

    /// Code multipath error of satellite `i` at elevation `el_rad`, m.
    pub fn error_m(&self, i: usize, el_rad: f64) -> f64 {
        self.spec.sigma_m(el_rad) * self.unit[i].value()
    }
}

#[cfg(test)]
mod tests {
    use super::super::gauss_markov::assert_gauss_markov_statistics;
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn magnitude_by_elevation_and_correlation_time() {
        let spec = MultipathSpec {
            enabled: true,
            sigma_zenith_m: 0.2,
            sigma_horizon_m: 1.5,
            elevation_scale_deg: 10.0,
            tau_s: 60.0,
        };
        let el = 15f64.to_radians();
        let sigma = 0.2 + 1.5 * (-1.5f64).exp();
        assert!((spec.sigma_m(el) - sigma).abs() < 1e-12);
        // At the zenith the floor plus 1.5·e^{−9} = 1.9e-4 m.
        assert!(
            (spec.sigma_m(std::f64::consts::FRAC_PI_2) - 0.2 - 1.5 * (-9f64).exp()).abs() < 1e-12
        );
        let mut rng = ChaCha20Rng::seed_from_u64(5);
        // A satellite held at 15°: σ(15°) = 0.535 m, lag 40 s (e^{−2/3}).
        assert_gauss_markov_statistics("multipath", 3000, 1.0, 40, sigma, 60.0, |_| {
            let mut mp = Multipath::new(spec, 1, &mut rng);
            let mut x = vec![mp.error_m(0, el)];
            for _ in 0..40 {
                mp.step(1.0, &mut rng);
                x.push(mp.error_m(0, el));
            }
            x
        });
    }
}
