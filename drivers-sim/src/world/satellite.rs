//! Signal-in-space errors: the broadcast satellite clock and ephemeris differ from the truth.
//!
//! Each satellite's clock error (m) and its orbit error in the radial, along-track and
//! cross-track directions are independent first-order Gauss–Markov processes (metre level,
//! correlation times of an hour or more: broadcast parameters are refreshed every two hours
//! and fitted over four). The receiver computes the satellite position from the broadcast
//! ephemeris, so the published satellite position carries the orbit error; the true range
//! does not. The range error seen is `−u·δr_s + δt_s`: the along-track error projects weakly,
//! the radial one almost fully (the SISRE of Montenbruck et al. 2015, GPS Solutions 19).

use super::gauss_markov::GaussMarkov;
use nalgebra::Vector3;
use rand_chacha::ChaCha20Rng;
use serde::Deserialize;

/// `[world.satellite_clock]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SatelliteClockSpec {
    /// Whether the effect is applied.
    #[serde(default = "super::yes")]
    pub enabled: bool,
    /// 1-σ broadcast clock error, m.
    pub sigma_m: f64,
    /// Correlation time, s.
    pub tau_s: f64,
}

/// `[world.ephemeris]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EphemerisSpec {
    /// Whether the effect is applied.
    #[serde(default = "super::yes")]
    pub enabled: bool,
    /// 1-σ radial orbit error, m.
    pub sigma_radial_m: f64,
    /// 1-σ along-track orbit error, m.
    pub sigma_along_m: f64,
    /// 1-σ cross-track orbit error, m.
    pub sigma_cross_m: f64,
    /// Correlation time, s.
    pub tau_s: f64,
}

/// Broadcast clock and orbit errors of every satellite.
#[derive(Debug, Clone)]
pub struct SignalInSpace {
    clock: Vec<GaussMarkov>,
    /// Radial, along, cross per satellite.
    orbit: Vec<[GaussMarkov; 3]>,
}

impl SignalInSpace {
    /// For `n_sats` satellites; an effect that is `None` or disabled contributes zero.
    pub fn new(
        clock: Option<SatelliteClockSpec>,
        ephemeris: Option<EphemerisSpec>,
        n_sats: usize,
        rng: &mut ChaCha20Rng,
    ) -> Self {
        let c = clock.filter(|c| c.enabled);
        let e = ephemeris.filter(|e| e.enabled);
        let mut out = Self {
            clock: Vec::new(),
            orbit: Vec::new(),
        };
        for _ in 0..n_sats {
            let (s, tau) = c.map_or((0.0, 1.0), |c| (c.sigma_m, c.tau_s));
            out.clock.push(GaussMarkov::new(s, tau, rng));
            let (sr, sa, sc, tau) = e.map_or((0.0, 0.0, 0.0, 1.0), |e| {
                (e.sigma_radial_m, e.sigma_along_m, e.sigma_cross_m, e.tau_s)
            });
            out.orbit.push([
                GaussMarkov::new(sr, tau, rng),
                GaussMarkov::new(sa, tau, rng),
                GaussMarkov::new(sc, tau, rng),
            ]);
        }
        out
    }

    /// Advance every process by `dt_s` (four draws per satellite).
    pub fn step(&mut self, dt_s: f64, rng: &mut ChaCha20Rng) {
        for (c, o) in self.clock.iter_mut().zip(&mut self.orbit) {
            c.step(dt_s, rng);
            for p in o {
                p.step(dt_s, rng);
            }
        }
    }

    /// Broadcast clock error of satellite `i`, m (added to the pseudorange).
    pub fn clock_error_m(&self, i: usize) -> f64 {
        self.clock[i].value()
    }

    /// Broadcast orbit error of satellite `i` (ECEF, m) for its true position `r_s` and
    /// velocity `v_s` (ECEF, m and m/s): radial along `r_s`, cross-track along `r_s × v_s`.
    pub fn orbit_error_e_m(
        &self,
        i: usize,
        r_s: &Vector3<f64>,
        v_s: &Vector3<f64>,
    ) -> Vector3<f64> {
        let radial = r_s.normalize();
        let cross = r_s.cross(v_s).normalize();
        let along = cross.cross(&radial);
        let [r, a, c] = &self.orbit[i];
        radial * r.value() + along * a.value() + cross * c.value()
    }
}

#[cfg(test)]
mod tests {
    use super::super::gauss_markov::assert_gauss_markov_statistics;
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn clock_and_orbit_magnitudes_and_correlation() {
        let clock = SatelliteClockSpec {
            enabled: true,
            sigma_m: 1.0,
            tau_s: 7200.0,
        };
        let eph = EphemerisSpec {
            enabled: true,
            sigma_radial_m: 0.4,
            sigma_along_m: 1.5,
            sigma_cross_m: 0.8,
            tau_s: 3600.0,
        };
        let r_s = Vector3::new(2.6e7, 0.0, 0.0);
        let v_s = Vector3::new(0.0, 3.9e3, 0.0);
        let mut rng = ChaCha20Rng::seed_from_u64(6);
        // Clock: lag 3600 s of τ = 7200 s (e^{−0.5}); orbit along-track (the y axis here,
        // radial = x, cross = z): lag 1800 s of τ = 3600 s.
        let mut along = Vec::new();
        assert_gauss_markov_statistics("satellite clock", 2000, 300.0, 12, 1.0, 7200.0, |_| {
            let mut s = SignalInSpace::new(Some(clock), Some(eph), 1, &mut rng);
            let mut x = vec![s.clock_error_m(0)];
            let mut y = vec![s.orbit_error_e_m(0, &r_s, &v_s).y];
            for _ in 0..12 {
                s.step(300.0, &mut rng);
                x.push(s.clock_error_m(0));
                y.push(s.orbit_error_e_m(0, &r_s, &v_s).y);
            }
            along.push(y);
            x
        });
        let mut k = 0;
        assert_gauss_markov_statistics("along-track", 2000, 300.0, 6, 1.5, 3600.0, |_| {
            k += 1;
            along[k - 1].clone()
        });
        // Disabled: exactly zero.
        let s = SignalInSpace::new(None, None, 2, &mut rng);
        assert_eq!(s.clock_error_m(1), 0.0);
        assert_eq!(s.orbit_error_e_m(1, &r_s, &v_s), Vector3::zeros());
    }
}
