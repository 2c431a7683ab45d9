//! Receiver clock with the Allan deviation of its oscillator class.
//!
//! The two-state clock (phase `b = c·δt`, m; frequency `d = c·δṫ`, m/s) driven by white
//! frequency noise and random-walk frequency noise, with the power-law coefficients `h₀`,
//! `h₋₂` of the fractional-frequency PSD `S_y(f) = h₀ + h₋₂ f⁻²`: the phase PSD is
//! `q_b = c² h₀/2` (m²/s) and the frequency PSD `q_d = 2π² c² h₋₂` (m²/s³) (Brown & Hwang,
//! 4th ed., §9.3, eq. 9.3.9–9.3.10). The Allan variance is
//! `σ_y²(τ) = h₀/(2τ) + (2π²/3) h₋₂ τ` (IEEE Std 1139-2008, Table 1). A TCXO is
//! `h₀ ≈ 2·10⁻¹⁹`, `h₋₂ ≈ 2·10⁻²⁰` (Brown & Hwang, Table 9.2); the flicker term `h₋₁` is not
//! modelled (its Allan floor ≈ 1.2·10⁻¹⁰ would add to the minimum near τ ≈ 1–10 s).
//! Discretisation is exact: the process noise of a step Δt is
//! `Q = [[q_b Δt + q_d Δt³/3, q_d Δt²/2], [q_d Δt²/2, q_d Δt]]`.

use msgs::SPEED_OF_LIGHT_M_S;
use nalgebra::{Matrix2, Vector2};
use rand::Rng;
use rand_chacha::ChaCha20Rng;
use rand_distr::StandardNormal;
use serde::Deserialize;

/// `[world.receiver_clock]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReceiverClockSpec {
    /// Whether this oscillator replaces the grade's clock model.
    #[serde(default = "super::yes")]
    pub enabled: bool,
    /// White-frequency coefficient h₀, s.
    pub h0: f64,
    /// Random-walk-frequency coefficient h₋₂, 1/s.
    pub h_minus2: f64,
}

impl ReceiverClockSpec {
    /// Phase (white-frequency) PSD q_b, m²/s.
    pub fn phase_psd_m2_s(&self) -> f64 {
        SPEED_OF_LIGHT_M_S.powi(2) * self.h0 / 2.0
    }
    /// Frequency (random-walk) PSD q_d, m²/s³.
    pub fn frequency_psd_m2_s3(&self) -> f64 {
        2.0 * std::f64::consts::PI.powi(2) * SPEED_OF_LIGHT_M_S.powi(2) * self.h_minus2
    }
    /// Allan variance of the fractional frequency at averaging time `tau_s`.
    pub fn allan_variance(&self, tau_s: f64) -> f64 {
        self.h0 / (2.0 * tau_s) + 2.0 * std::f64::consts::PI.powi(2) / 3.0 * self.h_minus2 * tau_s
    }
}

/// Two-state clock: bias (m) and drift (m/s) driven by PSDs `q_b`, `q_d`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwoStateClock {
    /// Phase PSD, m²/s.
    pub q_b_m2_s: f64,
    /// Frequency PSD, m²/s³.
    pub q_d_m2_s3: f64,
    /// Bias, m.
    pub bias_m: f64,
    /// Drift, m/s.
    pub drift_m_s: f64,
}

impl TwoStateClock {
    /// Advance by `dt_s` with two unit-normal draws (always two, so the stream stays aligned).
    pub fn step(&mut self, dt_s: f64, rng: &mut ChaCha20Rng) {
        let (qb, qd, dt) = (self.q_b_m2_s, self.q_d_m2_s3, dt_s);
        let q = Matrix2::new(
            qb * dt + qd * dt * dt * dt / 3.0,
            qd * dt * dt / 2.0,
            qd * dt * dt / 2.0,
            qd * dt,
        );
        let n1: f64 = rng.sample(StandardNormal);
        let n2: f64 = rng.sample(StandardNormal);
        let w = match q.cholesky() {
            Some(c) => c.l() * Vector2::new(n1, n2),
            None => Vector2::zeros(),
        };
        self.bias_m += self.drift_m_s * dt + w.x;
        self.drift_m_s += w.y;
    }
}

#[cfg(test)]
mod tests {
    use super::super::gauss_markov::mean_and_standard_error;
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn allan_deviation_of_a_tcxo() {
        // Brown & Hwang's TCXO: σ_y(1 s) = √(1e-19 + 1.3e-19) ≈ 4.8e-10, minimum near 2 s,
        // σ_y(100 s) ≈ 3.6e-9 (random-walk frequency dominates).
        let spec = ReceiverClockSpec {
            enabled: true,
            h0: 2e-19,
            h_minus2: 2e-20,
        };
        let mut rng = ChaCha20Rng::seed_from_u64(7);
        let c = SPEED_OF_LIGHT_M_S;
        for tau in [1.0, 10.0, 100.0] {
            // One Allan sample (x(t+2τ) − 2x(t+τ) + x(t))²/(2τ²) per independent run, the
            // phase x = b/c sampled every τ; its mean is σ_y²(τ) exactly for this model.
            let samples: Vec<f64> = (0..4000)
                .map(|_| {
                    let mut k = TwoStateClock {
                        q_b_m2_s: spec.phase_psd_m2_s(),
                        q_d_m2_s3: spec.frequency_psd_m2_s3(),
                        bias_m: 0.0,
                        drift_m_s: 0.0,
                    };
                    let x0 = k.bias_m / c;
                    k.step(tau, &mut rng);
                    let x1 = k.bias_m / c;
                    k.step(tau, &mut rng);
                    let x2 = k.bias_m / c;
                    (x2 - 2.0 * x1 + x0).powi(2) / (2.0 * tau * tau)
                })
                .collect();
            let (m, se) = mean_and_standard_error(&samples);
            let model = spec.allan_variance(tau);
            assert!(
                (m - model).abs() < 4.0 * se,
                "τ = {tau} s: Allan variance {m:e} vs {model:e} (SE {se:e})"
            );
        }
        assert!((spec.allan_variance(1.0).sqrt() - 4.8e-10).abs() < 0.1e-10);
    }
}
