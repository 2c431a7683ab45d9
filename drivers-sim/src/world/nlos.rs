//! Non-line-of-sight reception: a satellite hidden behind a building is received only through
//! its echo off another one, which arrives late (a positive pseudorange error of metres to tens
//! of metres) and weaker (a lower C/N0).
//!
//! Per satellite a two-state Markov chain, line of sight (LOS) ⇄ NLOS, in continuous time: an
//! NLOS episode ends at rate `μ = 1/T` (T the mean episode length: the time to pass a
//! building), and one begins at rate `λ = μ·p/(1 − p)`, so that the satellite is NLOS a share
//! `p(el)` of the time, `p(el) = p_z + (p_h − p_z)·e^{−el/θ}`: low satellites are the ones a
//! street's buildings hide (Groves, "Principles of GNSS, Inertial, and Multisensor Integrated
//! Navigation Systems", 2nd ed., §10.3.2 and §11.4: NLOS errors, positive, up to tens of
//! metres in urban canyons; Hsu, "Analysis and modeling GPS NLOS effect in highly urbanized
//! area", GPS Solutions 22, 2018: excess delays mostly below 20 m with a long tail). Each
//! episode's excess path is drawn from an exponential distribution with the configured mean
//! and held for the episode; the echo's C/N0 is lower by a fixed loss.
//!
//! The echo's Doppler and carrier phase are left those of the direct signal (not modelled: the
//! reflector's geometry would set them). The receiver does not know which signals are echoes: it reports them with the C/N0 it
//! measures (so its own σ grows with the loss) and fixes with them. The chain draws one
//! uniform number and one candidate excess per satellite and epoch whether the satellite is
//! visible or not, from a stream of its own: the random stream depends neither on the
//! geometry nor on the other effects present, so the episodes are the same alone and in the
//! whole world.

use rand::Rng;
use rand_chacha::ChaCha20Rng;
use serde::Deserialize;

/// `[world.nlos]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NlosSpec {
    /// Whether the effect is applied.
    #[serde(default = "super::yes")]
    pub enabled: bool,
    /// Share of the time a satellite at the zenith is received NLOS.
    pub probability_zenith: f64,
    /// Share of the time a satellite at the horizon is received NLOS.
    pub probability_horizon: f64,
    /// Elevation scale θ of the exponential, deg.
    pub elevation_scale_deg: f64,
    /// Mean length of one NLOS episode, s.
    pub mean_duration_s: f64,
    /// Mean excess path of the echo (exponential per episode), m.
    pub excess_path_mean_m: f64,
    /// C/N0 lost by the echo against the direct signal, dB.
    pub cn0_loss_db: f64,
}

impl NlosSpec {
    /// Share of the time a satellite at elevation `el_rad` is NLOS.
    pub fn probability(&self, el_rad: f64) -> f64 {
        self.probability_zenith
            + (self.probability_horizon - self.probability_zenith)
                * (-el_rad.max(0.0).to_degrees() / self.elevation_scale_deg).exp()
    }
}

/// One satellite's chain.
#[derive(Debug, Clone, Copy, Default)]
struct Chain {
    /// Excess path of the current episode, m (`None`: line of sight).
    excess_m: Option<f64>,
    /// This epoch's uniform draw, consumed by the first update.
    uniform: Option<f64>,
    /// This epoch's candidate excess path, m.
    candidate_m: f64,
}

/// NLOS state of every satellite.
#[derive(Debug, Clone)]
pub struct Nlos {
    spec: NlosSpec,
    chains: Vec<Chain>,
    dt_s: f64,
    rng: ChaCha20Rng,
}

impl Nlos {
    /// For `n_sats` satellites, all in line of sight, drawing from `rng` (its own stream).
    pub fn new(spec: NlosSpec, n_sats: usize, rng: ChaCha20Rng) -> Self {
        Self {
            spec,
            chains: vec![Chain::default(); n_sats],
            dt_s: 0.0,
            rng,
        }
    }

    /// The next epoch, `dt_s` after the last: one uniform draw and one candidate excess path
    /// per satellite.
    pub fn step(&mut self, dt_s: f64) {
        self.dt_s = dt_s;
        for c in &mut self.chains {
            c.uniform = Some(self.rng.random::<f64>());
            // 1 − U is in (0, 1]: its logarithm is finite.
            c.candidate_m = -self.spec.excess_path_mean_m * (1.0 - self.rng.random::<f64>()).ln();
        }
    }

    /// Advance satellite `i`'s chain over the last step at elevation `el_rad` (once per epoch;
    /// later calls in the same epoch only read it) and return its excess path, m (`None`: line
    /// of sight).
    pub fn update(&mut self, i: usize, el_rad: f64) -> Option<f64> {
        let s = self.spec;
        let c = &mut self.chains[i];
        if let Some(u) = c.uniform.take() {
            let mu = 1.0 / s.mean_duration_s;
            match c.excess_m {
                Some(_) if u < 1.0 - (-mu * self.dt_s).exp() => c.excess_m = None,
                None => {
                    let p = s.probability(el_rad);
                    let lambda = mu * p / (1.0 - p);
                    if u < 1.0 - (-lambda * self.dt_s).exp() {
                        c.excess_m = Some(c.candidate_m);
                    }
                }
                Some(_) => {}
            }
        }
        c.excess_m
    }

    /// C/N0 lost by an echo, dB.
    pub fn cn0_loss_db(&self) -> f64 {
        self.spec.cn0_loss_db
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn spec() -> NlosSpec {
        NlosSpec {
            enabled: true,
            probability_zenith: 0.01,
            probability_horizon: 0.3,
            elevation_scale_deg: 15.0,
            mean_duration_s: 8.0,
            excess_path_mean_m: 12.0,
            cn0_loss_db: 6.0,
        }
    }

    #[test]
    fn probability_by_elevation() {
        let s = spec();
        assert!((s.probability(0.0) - 0.3).abs() < 1e-15);
        let el = 15f64.to_radians();
        assert!((s.probability(el) - (0.01 + 0.29 * (-1f64).exp())).abs() < 1e-15);
        assert!((s.probability(std::f64::consts::FRAC_PI_2) - 0.01).abs() < 1e-3);
    }

    /// 200 satellites held at 10° for 2000 s at 1 Hz: the share of NLOS epochs is p(10°), the
    /// mean episode length T (geometric in whole epochs: mean 1/(1 − e^{−1/T}) = 8.5 s for
    /// T = 8 s), the excess paths exponential with the configured mean (their standard
    /// deviation equals the mean) and held over an episode. Bounds: 5 standard errors, the
    /// epochs' correlation counted (an episode of ~8 epochs is one independent sample).
    #[test]
    fn share_duration_and_excess_of_the_episodes() {
        let s = spec();
        let el = 10f64.to_radians();
        let p = s.probability(el);
        let (n_sats, n_epochs) = (200usize, 2000usize);
        let mut nlos = Nlos::new(s, n_sats, ChaCha20Rng::seed_from_u64(3));
        let mut state = vec![None::<f64>; n_sats];
        let (mut nlos_epochs, mut episodes, mut excess) = (0usize, 0usize, Vec::new());
        for _ in 0..n_epochs {
            nlos.step(1.0);
            for (i, prev) in state.iter_mut().enumerate() {
                let now = nlos.update(i, el);
                assert_eq!(nlos.update(i, el), now, "a second update reads only");
                if let Some(d) = now {
                    nlos_epochs += 1;
                    match *prev {
                        Some(e) => assert_eq!(e, d, "held over the episode"),
                        None => {
                            episodes += 1;
                            excess.push(d);
                        }
                    }
                }
                *prev = now;
            }
        }
        let share = nlos_epochs as f64 / (n_sats * n_epochs) as f64;
        let t_mean = 1.0 / (1.0 - (-1.0 / s.mean_duration_s).exp());
        // Independent samples ≈ epochs / (2·T) (the chain's correlation time is ≈ T·(1 − p)).
        let n_eff = (n_sats * n_epochs) as f64 / (2.0 * t_mean);
        let se_share = (p * (1.0 - p) / n_eff).sqrt();
        assert!(
            (share - p).abs() < 5.0 * se_share,
            "share {share} vs {p} (se {se_share})"
        );
        let mean_len = nlos_epochs as f64 / episodes as f64;
        let se_len = t_mean / (episodes as f64).sqrt();
        assert!(
            (mean_len - t_mean).abs() < 5.0 * se_len,
            "episode {mean_len} s vs {t_mean} s"
        );
        let m = excess.iter().sum::<f64>() / excess.len() as f64;
        let sd = (excess.iter().map(|d| (d - m).powi(2)).sum::<f64>() / excess.len() as f64).sqrt();
        let se = 12.0 / (excess.len() as f64).sqrt();
        assert!((m - 12.0).abs() < 5.0 * se, "mean excess {m} m");
        assert!((sd - 12.0).abs() < 10.0 * se, "excess σ {sd} m");
        assert!(excess.iter().all(|d| *d >= 0.0), "an echo arrives late");
    }

    /// At the zenith with p_z = 0 nothing is ever NLOS; a satellite never updated keeps its
    /// line of sight.
    #[test]
    fn no_episode_where_the_probability_is_zero() {
        let s = NlosSpec {
            probability_zenith: 0.0,
            probability_horizon: 0.0,
            ..spec()
        };
        let mut nlos = Nlos::new(s, 3, ChaCha20Rng::seed_from_u64(1));
        for _ in 0..1000 {
            nlos.step(1.0);
            assert_eq!(nlos.update(0, 1.0), None);
        }
    }
}
