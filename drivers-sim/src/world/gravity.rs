//! Truth gravity disturbance: deflection of the vertical and gravity anomaly along the track.
//!
//! The disturbing potential `T` is a random harmonic field over the local horizontal plane,
//! `T(x, z) = A·√(2/N)·Σᵢ cos(kᵢ·x + φᵢ)·e^{−|kᵢ| z}` (x north/east from the site, z up; each
//! term solves Laplace's equation, so the field is a physical potential outside the masses),
//! wave vectors `kᵢ ~ N(0, I/L²)`. The disturbance vector is `δg = ∇T`
//! (Heiskanen & Moritz, "Physical Geodesy", 1967, §2-13), in NED
//! `δg = (∂T/∂x_N, ∂T/∂x_E, −∂T/∂z)`, and the deflection of the vertical
//! `ξ = −δg_N/γ`, `η = −δg_E/γ` (§2-22). Over the ensemble:
//! - `σ²(δg_D) = A²·E|k|² = 2A²/L²`, so `A = σ_δg·L/√2`;
//! - `σ²(δg_N) = σ²(δg_E) = σ_δg²/2`: the deflection's 1-σ per component is `σ_δg/(√2 γ)`
//!   (35 mGal ↔ 5.2″), the ratio a harmonic isotropic field imposes;
//! - along a horizontal displacement d (north), the correlations are
//!   `ρ_D(d) = (1 − d²/2L²)·e^{−d²/2L²}` and `ρ_N(d) = (1 − d²/L²)·e^{−d²/2L²}`.
//!
//! Truth only: the IMU's specific force sees `g + δg`; the filter's gravity model (normal or
//! J2) knows nothing of it, as with a real gravity field.

use super::spectral::TERMS;
use nalgebra::Vector3;
use rand::Rng;
use rand_chacha::ChaCha20Rng;
use rand_distr::StandardNormal;
use serde::Deserialize;
use std::f64::consts::TAU;

/// 1 mGal in m/s².
pub const MGAL_M_S2: f64 = 1e-5;

/// `[world.gravity]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GravitySpec {
    /// Whether the effect is applied.
    #[serde(default = "super::yes")]
    pub enabled: bool,
    /// 1-σ of the vertical gravity disturbance (anomaly), mGal; the deflection of the vertical
    /// follows (1-σ per component `σ/(√2 γ)`).
    pub anomaly_sigma_mgal: f64,
    /// Correlation length L of the field, km.
    pub correlation_length_km: f64,
}

/// One realisation of the field.
#[derive(Debug, Clone, PartialEq)]
pub struct GravityField {
    amplitude: f64,
    k: [[f64; 2]; TERMS],
    /// `|kᵢ|`, rad/m.
    k_norm: [f64; TERMS],
    phase: [f64; TERMS],
}

impl GravityField {
    /// Draw a realisation of `spec` from `rng`.
    pub fn new(spec: &GravitySpec, rng: &mut ChaCha20Rng) -> Self {
        let l_m = spec.correlation_length_km * 1e3;
        let sigma = spec.anomaly_sigma_mgal * MGAL_M_S2;
        let (mut k, mut phase) = ([[0.0; 2]; TERMS], [0.0; TERMS]);
        for i in 0..TERMS {
            let kn: f64 = rng.sample(StandardNormal);
            let ke: f64 = rng.sample(StandardNormal);
            k[i] = [kn / l_m, ke / l_m];
            phase[i] = rng.random::<f64>() * TAU;
        }
        Self {
            amplitude: sigma * l_m / std::f64::consts::SQRT_2 * (2.0 / TERMS as f64).sqrt(),
            k_norm: k.map(|k| k[0].hypot(k[1])),
            k,
            phase,
        }
    }

    /// Disturbance vector `δg` in NED, m/s², at `north_m`, `east_m` from the site and `up_m`
    /// above it.
    pub fn disturbance_ned_m_s2(&self, north_m: f64, east_m: f64, up_m: f64) -> Vector3<f64> {
        let mut g = Vector3::zeros();
        for ((k, p), kk) in self.k.iter().zip(&self.phase).zip(self.k_norm) {
            let decay = (-kk * up_m).exp();
            let (s, c) = super::spectral::sin_cos(k[0] * north_m + k[1] * east_m + p);
            g.x -= k[0] * s * decay;
            g.y -= k[1] * s * decay;
            g.z += kk * c * decay;
        }
        g * self.amplitude
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::ARCSEC_RAD;
    use crate::world::gauss_markov::mean_and_standard_error;
    use rand::SeedableRng;

    /// Variance and correlation at d = L/2 north of the anomaly and of the north deflection,
    /// over independent realisations, against the closed forms within 4 standard errors.
    #[test]
    fn anomaly_and_deflection_magnitude_and_correlation() {
        let spec = GravitySpec {
            enabled: true,
            anomaly_sigma_mgal: 35.0,
            correlation_length_km: 20.0,
        };
        let gamma = 9.81;
        let l = 20e3;
        let d = l / 2.0;
        let mut rng = ChaCha20Rng::seed_from_u64(11);
        let (mut dd, mut dd_lag, mut nn, mut nn_lag) = (vec![], vec![], vec![], vec![]);
        for _ in 0..3000 {
            let f = GravityField::new(&spec, &mut rng);
            let (x0, y0) = (rng.random::<f64>() * 1e5, rng.random::<f64>() * 1e5);
            let a = f.disturbance_ned_m_s2(x0, y0, 0.0);
            let b = f.disturbance_ned_m_s2(x0 + d, y0, 0.0);
            dd.push(a.z * a.z);
            dd_lag.push(a.z * b.z);
            // Deflection ξ = −δg_N/γ, arcsec.
            let (xa, xb) = (-a.x / gamma / ARCSEC_RAD, -b.x / gamma / ARCSEC_RAD);
            nn.push(xa * xa);
            nn_lag.push(xa * xb);
        }
        let s_d = spec.anomaly_sigma_mgal * MGAL_M_S2;
        let s_xi = s_d / (std::f64::consts::SQRT_2 * gamma) / ARCSEC_RAD;
        let r = d * d / (l * l);
        for (name, sq, lag, s, rho) in [
            (
                "anomaly",
                &dd,
                &dd_lag,
                s_d,
                (1.0 - r / 2.0) * (-r / 2.0).exp(),
            ),
            (
                "deflection",
                &nn,
                &nn_lag,
                s_xi,
                (1.0 - r) * (-r / 2.0).exp(),
            ),
        ] {
            let (v, se_v) = mean_and_standard_error(sq);
            let (c, se_c) = mean_and_standard_error(lag);
            assert!(
                (v - s * s).abs() < 4.0 * se_v,
                "{name}: variance {v} vs {} (SE {se_v})",
                s * s
            );
            assert!(
                (c - rho * s * s).abs() < 4.0 * se_c,
                "{name}: covariance at L/2 {c} vs {} (SE {se_c})",
                rho * s * s
            );
            assert!(rho * s * s > 4.0 * se_c && s * s * (1.0 - rho) > 4.0 * se_c);
        }
        // The magnitudes asked of a realistic field: 20–50 mGal, 5–10″ (here 35 mGal, 5.2″).
        assert!((5.0..10.0).contains(&s_xi), "{s_xi}");
    }
}
