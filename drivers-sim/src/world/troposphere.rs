//! Truth troposphere: Saastamoinen zenith delays from the site's actual weather, the Niell
//! continued-fraction mapping at mid-latitude, and a slowly varying zenith wet residual.
//!
//! * Zenith hydrostatic delay `0.0022768 P/(1 − 0.00266 cos 2φ − 0.00028 H_km)` and zenith wet
//!   delay `0.002277 (1255/T + 0.05) e` (Saastamoinen 1972; Davis et al. 1985), with P, T, e
//!   from the scenario's sea-level weather brought to the site height by a 6.5 K/km lapse
//!   and the hydrostatic exponent g/(R_d·L) = 5.2559.
//! * Mapping: the Marini/Herring continued fraction
//!   `m(el) = (1 + a/(1 + b/(1 + c)))/(sin el + a/(sin el + b/(sin el + c)))` with Niell's
//!   (1996, JGR 101(B2), Table 3) 45° hydrostatic and wet coefficients, NOT the receiver's
//!   cosecant (≈ 1.5 % apart at 10°).
//! * Residual: the zenith wet delay carries a first-order Gauss–Markov deviation common to
//!   every satellite (the weather the surface values miss), mapped with the wet function.

use super::gauss_markov::GaussMarkov;
use rand_chacha::ChaCha20Rng;
use serde::Deserialize;

/// Niell hydrostatic coefficients (a, b, c) at 45° latitude, annual mean.
const NIELL_HYDROSTATIC_45: [f64; 3] = [1.2465397e-3, 2.9288445e-3, 62.837393e-3];
/// Niell wet coefficients at 45° latitude.
const NIELL_WET_45: [f64; 3] = [5.8021897e-4, 1.4275268e-3, 4.3472961e-2];

/// `[world.troposphere]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TroposphereSpec {
    /// Whether the effect is applied.
    #[serde(default = "super::yes")]
    pub enabled: bool,
    /// Sea-level pressure of the day, hPa.
    pub sea_level_pressure_hpa: f64,
    /// Sea-level temperature of the day, °C.
    pub sea_level_temperature_c: f64,
    /// Relative humidity, 0–1.
    pub relative_humidity: f64,
    /// 1-σ of the zenith wet-delay residual, m.
    pub wet_residual_m: f64,
    /// Correlation time of the residual, s.
    pub wet_residual_tau_s: f64,
}

/// Marini/Herring continued-fraction mapping with coefficients `abc` at elevation `el_rad`.
pub fn continued_fraction_mapping(abc: &[f64; 3], el_rad: f64) -> f64 {
    let [a, b, c] = *abc;
    let s = el_rad.sin();
    (1.0 + a / (1.0 + b / (1.0 + c))) / (s + a / (s + b / (s + c)))
}

impl TroposphereSpec {
    /// Zenith hydrostatic and wet delays (m) at latitude `lat_rad`, height `height_m`.
    pub fn zenith_m(&self, lat_rad: f64, height_m: f64) -> (f64, f64) {
        let h = height_m.max(0.0);
        let t0 = self.sea_level_temperature_c + 273.15;
        let t = t0 - 6.5e-3 * h;
        let p = self.sea_level_pressure_hpa * (t / t0).powf(5.2559);
        let tc = t - 273.15;
        let e = self.relative_humidity * 6.1078 * (17.27 * tc / (tc + 237.3)).exp();
        let gravity = 1.0 - 0.00266 * (2.0 * lat_rad).cos() - 0.00028 * h * 1e-3;
        (
            0.002_276_8 * p / gravity,
            0.002_277 * (1255.0 / t + 0.05) * e,
        )
    }
}

/// The troposphere of a run.
#[derive(Debug, Clone)]
pub struct Troposphere {
    spec: TroposphereSpec,
    residual: GaussMarkov,
}

impl Troposphere {
    /// The model with its residual drawn from `rng`.
    pub fn new(spec: TroposphereSpec, rng: &mut ChaCha20Rng) -> Self {
        Self {
            residual: GaussMarkov::new(spec.wet_residual_m, spec.wet_residual_tau_s, rng),
            spec,
        }
    }

    /// Advance the residual by `dt_s`.
    pub fn step(&mut self, dt_s: f64, rng: &mut ChaCha20Rng) {
        self.residual.step(dt_s, rng);
    }

    /// Slant delay, m, at `lat_rad`, `height_m`, elevation `el_rad` (> 0).
    pub fn delay_m(&self, lat_rad: f64, height_m: f64, el_rad: f64) -> f64 {
        let (zhd, zwd) = self.spec.zenith_m(lat_rad, height_m);
        zhd * continued_fraction_mapping(&NIELL_HYDROSTATIC_45, el_rad)
            + (zwd + self.residual.value()) * continued_fraction_mapping(&NIELL_WET_45, el_rad)
    }
}

#[cfg(test)]
mod tests {
    use super::super::gauss_markov::assert_gauss_markov_statistics;
    use super::*;
    use rand::SeedableRng;
    use std::f64::consts::FRAC_PI_2;

    fn spec() -> TroposphereSpec {
        TroposphereSpec {
            enabled: true,
            sea_level_pressure_hpa: 1005.0,
            sea_level_temperature_c: 8.0,
            relative_humidity: 0.8,
            wet_residual_m: 0.03,
            wet_residual_tau_s: 3600.0,
        }
    }

    #[test]
    fn zenith_and_slant_magnitudes() {
        let s = spec();
        // Sea level, 45°: ZHD = 0.0022768·1005/(1 − 0) = 2.288 m; ZWD with e = 0.8·10.73 hPa
        // = 8.59 hPa at 281.15 K: 0.002277·(4.464 + 0.05)·8.59 = 0.0883 m.
        let (zhd, zwd) = s.zenith_m(45f64.to_radians(), 0.0);
        assert!((zhd - 0.002_276_8 * 1005.0).abs() < 1e-9, "{zhd}");
        assert!((zwd - 0.0883).abs() < 1e-3, "{zwd}");
        // Mapping: exactly 1 at the zenith; at 10° between 5.5 and 5.7 (Niell 1996, Fig. 3),
        // i.e. within 1–3 % of the cosecant 5.76, which is the receiver's model.
        for abc in [&NIELL_HYDROSTATIC_45, &NIELL_WET_45] {
            assert!((continued_fraction_mapping(abc, FRAC_PI_2) - 1.0).abs() < 1e-12);
            let m10 = continued_fraction_mapping(abc, 10f64.to_radians());
            let csc = 1.0 / 10f64.to_radians().sin();
            assert!(
                (5.5..5.75).contains(&m10) && (csc - m10) / csc > 0.005,
                "{m10}"
            );
        }
    }

    #[test]
    fn wet_residual_is_gauss_markov_with_its_sigma_and_tau() {
        let mut rng = ChaCha20Rng::seed_from_u64(4);
        let s = spec();
        assert_gauss_markov_statistics("tropo residual", 2000, 60.0, 40, 0.03, 3600.0, |_| {
            let mut t = Troposphere::new(s, &mut rng);
            let mut x = vec![t.residual.value()];
            for _ in 0..40 {
                t.step(60.0, &mut rng);
                x.push(t.residual.value());
            }
            x
        });
    }
}
