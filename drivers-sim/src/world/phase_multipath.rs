//! Carrier-phase multipath of the baseline phase differences (`[world.phase_multipath]`).
//!
//! A reflected signal of relative amplitude α and path delay δ shifts the phase the loop
//! tracks by `atan(α sin ψ / (1 + α cos ψ))`, `ψ = 2πδ/λ`: at most `λ/4` (α → 1), about
//! `αλ/(2π)` for a weak echo — a few millimetres at L1 for the roof and ground reflections of
//! a car (Braasch, "Multipath Effects", in Parkinson & Spilker, *GPS: Theory and Applications*
//! I, 1996, ch. 14). Unlike the code's, the phase error does not average over the chip: it is
//! the error that limits short-baseline attitude (the thermal noise of a carrier loop is a
//! fraction of a millimetre).
//!
//! Each antenna of a baseline sees its own reflections (antennas a wavelength or more apart
//! decorrelate), so the phase *difference* carries the difference of two independent errors;
//! this model states that differential error directly, per satellite and baseline:
//! `m_{k,b}(t) = σ(el)·u_{k,b}(t)` with `σ(el) = σ_z + σ_h e^{−el/θ}` (the exponential
//! elevation model of the code multipath, [`super::multipath`]) and `u` a unit-variance
//! Gauss–Markov process of correlation time τ (the reflector geometry changes as the vehicle
//! turns and moves: tens of seconds on a car, minutes on a fixed site, where the satellite's
//! own motion sets it).
//!
//! The receiver does not report it: its phase σ is the tracking loop's, so a solver weighted
//! by that σ alone (paper 003's) is optimistic by `√(σ_φ² + (σ(el)/λ)²)/σ_φ`.
//!
//! Draws come from their own stream (`"world_phase_multipath"`), one per satellite, baseline
//! and epoch whether visible or not: switching the effect changes no other realisation.

use super::gauss_markov::GaussMarkov;
use rand_chacha::ChaCha20Rng;
use serde::Deserialize;

/// `[world.phase_multipath]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhaseMultipathSpec {
    /// Whether the effect is applied.
    #[serde(default = "super::yes")]
    pub enabled: bool,
    /// 1-σ of the differential phase error at the zenith (the floor), mm.
    pub sigma_zenith_mm: f64,
    /// Additional 1-σ at the horizon, mm.
    pub sigma_horizon_mm: f64,
    /// Elevation scale θ of the exponential, deg.
    pub elevation_scale_deg: f64,
    /// Correlation time, s.
    pub tau_s: f64,
}

impl PhaseMultipathSpec {
    /// 1-σ of the differential error at elevation `el_rad`, m.
    pub fn sigma_m(&self, el_rad: f64) -> f64 {
        1e-3 * (self.sigma_zenith_mm
            + self.sigma_horizon_mm * (-el_rad.to_degrees() / self.elevation_scale_deg).exp())
    }
}

/// The phase multipath of every satellite's two baselines.
#[derive(Debug, Clone)]
pub struct PhaseMultipath {
    spec: PhaseMultipathSpec,
    rng: ChaCha20Rng,
    unit: Vec<[GaussMarkov; 2]>,
}

impl PhaseMultipath {
    /// For `n_sats` satellites, drawing from `rng` (its own stream).
    pub fn new(spec: PhaseMultipathSpec, n_sats: usize, mut rng: ChaCha20Rng) -> Self {
        let unit = (0..n_sats)
            .map(|_| {
                [
                    GaussMarkov::new(1.0, spec.tau_s, &mut rng),
                    GaussMarkov::new(1.0, spec.tau_s, &mut rng),
                ]
            })
            .collect();
        Self { spec, rng, unit }
    }

    /// Advance every satellite's processes by `dt_s`.
    pub fn step(&mut self, dt_s: f64) {
        for pair in &mut self.unit {
            for u in pair {
                u.step(dt_s, &mut self.rng);
            }
        }
    }

    /// Differential phase error of satellite `i`'s baselines (AB, CD) at elevation `el_rad`, m
    /// (divide by the wavelength for cycles).
    pub fn error_m(&self, i: usize, el_rad: f64) -> [f64; 2] {
        let s = self.spec.sigma_m(el_rad);
        [s * self.unit[i][0].value(), s * self.unit[i][1].value()]
    }
}

#[cfg(test)]
mod tests {
    use super::super::gauss_markov::assert_gauss_markov_statistics;
    use super::*;
    use rand::SeedableRng;

    /// The car's values (`config/scenarios/vehicle.toml`): σ by elevation in closed form, and
    /// the process' variance and lag correlation at a fixed elevation (4 standard errors).
    #[test]
    fn magnitude_by_elevation_and_correlation_time() {
        let spec = PhaseMultipathSpec {
            enabled: true,
            sigma_zenith_mm: 2.0,
            sigma_horizon_mm: 8.0,
            elevation_scale_deg: 15.0,
            tau_s: 30.0,
        };
        let el = 30f64.to_radians();
        let sigma = 1e-3 * (2.0 + 8.0 * (-2f64).exp());
        assert!((spec.sigma_m(el) - sigma).abs() < 1e-15);
        // At the zenith: the floor plus 8·e^{−6} mm.
        assert!(
            (spec.sigma_m(std::f64::consts::FRAC_PI_2) - 1e-3 * (2.0 + 8.0 * (-6f64).exp())).abs()
                < 1e-15
        );
        // At 30°: 3.08 mm = 0.016 cycle at L1, 1.6 times a 0.01-cycle loop's noise.
        assert!((sigma / 0.190_293_672_798 - 0.0162).abs() < 1e-3);
        for baseline in 0..2 {
            let mut seed = 0u64;
            assert_gauss_markov_statistics("phase multipath", 3000, 1.0, 20, sigma, 30.0, |_| {
                seed += 1;
                let mut mp = PhaseMultipath::new(spec, 2, ChaCha20Rng::seed_from_u64(1000 + seed));
                let mut x = vec![mp.error_m(1, el)[baseline]];
                for _ in 0..20 {
                    mp.step(1.0);
                    x.push(mp.error_m(1, el)[baseline]);
                }
                x
            });
        }
    }

    /// The two baselines of a satellite are independent (distinct antennas): their sample
    /// correlation over 4000 independent draws is within 4/√4000 of zero.
    #[test]
    fn baselines_are_independent() {
        let spec = PhaseMultipathSpec {
            enabled: true,
            sigma_zenith_mm: 2.0,
            sigma_horizon_mm: 0.0,
            elevation_scale_deg: 15.0,
            tau_s: 30.0,
        };
        let n = 4000;
        let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
        for k in 0..n {
            let mp = PhaseMultipath::new(spec, 1, ChaCha20Rng::seed_from_u64(k));
            let [a, b] = mp.error_m(0, 1.0);
            sab += a * b;
            saa += a * a;
            sbb += b * b;
        }
        let r = sab / (saa * sbb).sqrt();
        assert!(r.abs() < 4.0 / (n as f64).sqrt(), "correlation {r}");
    }
}
