//! First-order Gauss–Markov process, the building block of every slowly varying world error.
//!
//! `ẋ = −x/τ + w`, stationary variance σ². Its exact discretisation over a step `Δt`
//! (Gelb, "Applied Optimal Estimation", 1974, §3.8; Brown & Hwang, "Introduction to Random
//! Signals and Applied Kalman Filtering", 4th ed., eq. 4.2.19) is
//! `x_{k+1} = φ x_k + σ √(1 − φ²) w_k`, `φ = e^{−Δt/τ}`, `w_k ~ N(0, 1)`, so the process is
//! stationary for any step and its autocorrelation is `R(Δ) = σ² e^{−|Δ|/τ}`.

use rand::Rng;
use rand_chacha::ChaCha20Rng;
use rand_distr::StandardNormal;

/// A first-order Gauss–Markov process started in its stationary distribution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GaussMarkov {
    sigma: f64,
    tau_s: f64,
    x: f64,
}

impl GaussMarkov {
    /// Standard deviation `sigma` (any unit) and correlation time `tau_s` (s, > 0); the first
    /// value is drawn from N(0, σ²), so the process is stationary from its start.
    pub fn new(sigma: f64, tau_s: f64, rng: &mut ChaCha20Rng) -> Self {
        let w: f64 = rng.sample(StandardNormal);
        Self {
            sigma,
            tau_s,
            x: sigma * w,
        }
    }

    /// Advance by `dt_s` (≥ 0) with one unit-normal draw; returns the new value.
    pub fn step(&mut self, dt_s: f64, rng: &mut ChaCha20Rng) -> f64 {
        let w: f64 = rng.sample(StandardNormal);
        let phi = (-dt_s.max(0.0) / self.tau_s).exp();
        self.x = phi * self.x + self.sigma * (1.0 - phi * phi).max(0.0).sqrt() * w;
        self.x
    }

    /// Current value.
    pub fn value(&self) -> f64 {
        self.x
    }

    /// Stationary standard deviation.
    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    /// Correlation time, s.
    pub fn tau_s(&self) -> f64 {
        self.tau_s
    }
}

/// Sample mean and its standard error of `values` (for the statistical tests of the world
/// effects: every assertion compares a sample mean with a closed form within 4 standard
/// errors: a correct model fails such an assertion with probability 6·10⁻⁵ for a random seed;
/// the seeds are fixed, so every run is the same).
#[cfg(test)]
pub(crate) fn mean_and_standard_error(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let m = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, (var / n).sqrt())
}

/// Check a stationary process's variance and lag autocovariance against σ² and σ² e^{−lag/τ}
/// from `runs` independent realisations (one product per realisation, so the samples are
/// independent and the standard error is the plain one of their mean).
#[cfg(test)]
pub(crate) fn assert_gauss_markov_statistics(
    name: &str,
    runs: usize,
    dt_s: f64,
    lag_steps: usize,
    sigma: f64,
    tau_s: f64,
    mut realisation: impl FnMut(usize) -> Vec<f64>,
) {
    let mut sq = Vec::with_capacity(runs);
    let mut prod = Vec::with_capacity(runs);
    for r in 0..runs {
        let x = realisation(r);
        assert!(x.len() > lag_steps, "{name}: realisation too short");
        sq.push(x[0] * x[0]);
        prod.push(x[0] * x[lag_steps]);
    }
    let (v, se_v) = mean_and_standard_error(&sq);
    let (c, se_c) = mean_and_standard_error(&prod);
    let lag_s = lag_steps as f64 * dt_s;
    let c_model = sigma * sigma * (-lag_s / tau_s).exp();
    assert!(
        (v - sigma * sigma).abs() < 4.0 * se_v,
        "{name}: variance {v} vs σ² {} (SE {se_v})",
        sigma * sigma
    );
    assert!(
        (c - c_model).abs() < 4.0 * se_c,
        "{name}: autocovariance at {lag_s} s {c} vs σ² e^(−lag/τ) {c_model} (SE {se_c})"
    );
    // The lag must be informative: the model's correlation differs from both 0 and 1 by
    // more than the test's resolution, so a wrong τ cannot pass.
    assert!(c_model > 4.0 * se_c && sigma * sigma - c_model > 4.0 * se_c);
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn stationary_variance_and_exponential_autocorrelation() {
        // σ = 2, τ = 60 s, steps of 1 s, lag 45 s (correlation e^{−0.75} = 0.47); 4000
        // independent realisations give a standard error of ≈ √2σ²/√4000 ≈ 0.09 on σ² = 4.
        let mut rng = ChaCha20Rng::seed_from_u64(1);
        assert_gauss_markov_statistics("gm", 4000, 1.0, 45, 2.0, 60.0, |_| {
            let mut gm = GaussMarkov::new(2.0, 60.0, &mut rng);
            let mut x = vec![gm.value()];
            for _ in 0..45 {
                x.push(gm.step(1.0, &mut rng));
            }
            x
        });
    }
}
