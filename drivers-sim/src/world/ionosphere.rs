//! Truth ionosphere: a thin-shell slant TEC with a diurnal and a latitudinal variation and a
//! correlated per-satellite residual.
//!
//! Vertical TEC at the ionospheric pierce point (IPP) of a shell at height `h_s`:
//! `VTEC = [N + (D − N)·((1 + cos 2π(t_loc − t_peak)/24 h)/2)²]·max(0.2, 1 + g·(|φ_0| − |φ_ipp|))`,
//! N the night-time and D the day-peak value (TECU), `t_loc` the IPP's local solar time,
//! `g` the fractional increase per degree towards the equator from the site latitude `φ_0`.
//! Slant TEC = VTEC·M(el) with the single-layer mapping `M = 1/√(1 − (R cos el/(R + h_s))²)`
//! (Schaer 1999, "Mapping and predicting the Earth's ionosphere using GPS", eq. 2.8), times
//! `(1 + r_k(t))` with `r_k` a first-order Gauss–Markov residual per satellite (travelling
//! disturbances, the shell's own errors). The first-order group delay is
//! `40.3·10¹⁶ STEC/f²` m per TECU (Hofmann-Wellenhof et al., "GNSS", 2008, eq. 5.63).
//!
//! Deliberately NOT the broadcast Klobuchar model the receiver corrects with: a squared
//! raised cosine instead of a half cosine on a floor, 450 km instead of 350 km, a thin-shell
//! mapping instead of `1 + 16(0.53 − E)³`, a latitude gradient instead of geomagnetic
//! coefficients. Klobuchar is documented to remove about half of the delay (Klobuchar 1987);
//! the test below checks the residual this world leaves is of that order.

use super::gauss_markov::GaussMarkov;
use rand_chacha::ChaCha20Rng;
use serde::Deserialize;
use std::f64::consts::{PI, TAU};

/// Mean Earth radius of the thin-shell geometry, m.
const EARTH_RADIUS_M: f64 = 6_371_000.0;
/// First-order ionospheric group delay per TECU at frequency f: 40.3·10¹⁶/f², m·Hz².
const DELAY_M_HZ2_PER_TECU: f64 = 40.3e16;

/// `[world.ionosphere]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IonosphereSpec {
    /// Whether the effect is applied.
    #[serde(default = "super::yes")]
    pub enabled: bool,
    /// Night-time vertical TEC, TECU (10¹⁶ el/m²).
    pub night_vtec_tecu: f64,
    /// Day-peak vertical TEC at the site latitude, TECU.
    pub day_vtec_tecu: f64,
    /// Local solar time of the daily peak, h.
    pub peak_local_hour: f64,
    /// Fractional VTEC increase per degree of IPP latitude towards the equator, 1/deg.
    pub gradient_per_deg: f64,
    /// Height of the thin shell, km.
    pub shell_height_km: f64,
    /// 1-σ of the per-satellite relative residual (fraction of the slant delay).
    pub residual_fraction: f64,
    /// Correlation time of the residual, s.
    pub residual_tau_s: f64,
}

/// The ionospheric pierce point of a line of sight: its latitude and longitude (rad) and the
/// thin-shell mapping factor.
pub fn pierce_point(
    lat_rad: f64,
    lon_rad: f64,
    az_rad: f64,
    el_rad: f64,
    shell_height_m: f64,
) -> (f64, f64, f64) {
    let ratio = EARTH_RADIUS_M / (EARTH_RADIUS_M + shell_height_m) * el_rad.cos();
    let psi = PI / 2.0 - el_rad - ratio.asin();
    let lat_i = (lat_rad.sin() * psi.cos() + lat_rad.cos() * psi.sin() * az_rad.cos())
        .clamp(-1.0, 1.0)
        .asin();
    let lon_i = lon_rad
        + (psi.sin() * az_rad.sin() / lat_i.cos())
            .clamp(-1.0, 1.0)
            .asin();
    (lat_i, lon_i, 1.0 / (1.0 - ratio * ratio).sqrt())
}

impl IonosphereSpec {
    /// Vertical TEC (TECU) at local solar time `local_hour` and IPP latitude `lat_ipp_rad`
    /// for a site at latitude `site_lat_rad`.
    pub fn vtec_tecu(&self, local_hour: f64, lat_ipp_rad: f64, site_lat_rad: f64) -> f64 {
        let d = ((1.0 + (TAU * (local_hour - self.peak_local_hour) / 24.0).cos()) / 2.0).powi(2);
        let towards_equator_deg = (site_lat_rad.abs() - lat_ipp_rad.abs()).to_degrees();
        let lat_factor = (1.0 + self.gradient_per_deg * towards_equator_deg).max(0.2);
        (self.night_vtec_tecu + (self.day_vtec_tecu - self.night_vtec_tecu) * d) * lat_factor
    }

    /// Deterministic slant delay (m) at frequency `f_hz` without the residual, for a receiver
    /// at `lat_rad`, `lon_rad` seeing azimuth `az_rad`, elevation `el_rad` at `utc_s_of_day`.
    pub fn model_delay_m(
        &self,
        lat_rad: f64,
        lon_rad: f64,
        az_rad: f64,
        el_rad: f64,
        utc_s_of_day: f64,
        f_hz: f64,
    ) -> f64 {
        let (lat_i, lon_i, m) =
            pierce_point(lat_rad, lon_rad, az_rad, el_rad, self.shell_height_km * 1e3);
        let local_hour = (utc_s_of_day / 3600.0 + lon_i.to_degrees() / 15.0).rem_euclid(24.0);
        DELAY_M_HZ2_PER_TECU * self.vtec_tecu(local_hour, lat_i, lat_rad) * m / (f_hz * f_hz)
    }
}

/// The ionosphere of a run: the model and one residual process per satellite.
#[derive(Debug, Clone)]
pub struct Ionosphere {
    spec: IonosphereSpec,
    residual: Vec<GaussMarkov>,
}

impl Ionosphere {
    /// For `n_sats` satellites, residuals drawn from `rng`.
    pub fn new(spec: IonosphereSpec, n_sats: usize, rng: &mut ChaCha20Rng) -> Self {
        let residual = (0..n_sats)
            .map(|_| GaussMarkov::new(spec.residual_fraction, spec.residual_tau_s, rng))
            .collect();
        Self { spec, residual }
    }

    /// Advance every satellite's residual by `dt_s` (one draw each, visible or not).
    pub fn step(&mut self, dt_s: f64, rng: &mut ChaCha20Rng) {
        for r in &mut self.residual {
            r.step(dt_s, rng);
        }
    }

    /// Slant group delay of satellite `i`, m (see [`IonosphereSpec::model_delay_m`]).
    pub fn delay_m(
        &self,
        i: usize,
        geo: (f64, f64),
        az_el_rad: (f64, f64),
        utc_s_of_day: f64,
        f_hz: f64,
    ) -> f64 {
        let d = self
            .spec
            .model_delay_m(geo.0, geo.1, az_el_rad.0, az_el_rad.1, utc_s_of_day, f_hz);
        d * (1.0 + self.residual[i].value())
    }
}

#[cfg(test)]
mod tests {
    use super::super::gauss_markov::assert_gauss_markov_statistics;
    use super::*;
    use fusion::earth::Geodetic;
    use fusion::gnss_corrections::{F_L1_HZ, KlobucharCoefficients};
    use rand::SeedableRng;

    pub(crate) fn spec() -> IonosphereSpec {
        IonosphereSpec {
            enabled: true,
            night_vtec_tecu: 4.0,
            day_vtec_tecu: 20.0,
            peak_local_hour: 14.0,
            gradient_per_deg: 0.02,
            shell_height_km: 450.0,
            residual_fraction: 0.2,
            residual_tau_s: 1800.0,
        }
    }

    #[test]
    fn vertical_delay_magnitude_and_diurnal_shape() {
        let s = spec();
        let lat = 55.0f64.to_radians();
        // At the zenith the IPP is overhead (M = 1, no gradient): 1 TECU = 0.1624 m at L1.
        let per_tecu = DELAY_M_HZ2_PER_TECU / (F_L1_HZ * F_L1_HZ);
        assert!((per_tecu - 0.1624).abs() < 5e-4, "{per_tecu}");
        // Local noon-peak at lon 0: UTC 14 h → day value; 02 h → night value exactly.
        let day = s.model_delay_m(lat, 0.0, 0.0, PI / 2.0, 14.0 * 3600.0, F_L1_HZ);
        let night = s.model_delay_m(lat, 0.0, 0.0, PI / 2.0, 2.0 * 3600.0, F_L1_HZ);
        assert!((day - 20.0 * per_tecu).abs() < 1e-9, "{day}");
        assert!((night - 4.0 * per_tecu).abs() < 1e-9, "{night}");
        // Thin-shell mapping at 10° elevation: 1/√(1 − (6371/6821·cos 10°)²) = 2.549.
        let (_, _, m) = pierce_point(lat, 0.0, 0.0, 10f64.to_radians(), 450e3);
        let r = 6371.0 / 6821.0 * 10f64.to_radians().cos();
        assert!((m - 1.0 / (1.0 - r * r).sqrt()).abs() < 1e-12 && (m - 2.549).abs() < 1e-3);
    }

    #[test]
    fn residual_is_gauss_markov_with_its_sigma_and_tau() {
        let s = spec();
        let mut rng = ChaCha20Rng::seed_from_u64(3);
        // 2000 realisations of one satellite's residual, 30 s steps, lag 900 s (e^{−0.5}).
        assert_gauss_markov_statistics("iono residual", 2000, 30.0, 30, 0.2, 1800.0, |_| {
            let mut iono = Ionosphere::new(s, 1, &mut rng);
            let mut x = vec![iono.residual[0].value()];
            for _ in 0..30 {
                iono.step(30.0, &mut rng);
                x.push(iono.residual[0].value());
            }
            x
        });
    }

    #[test]
    fn broadcast_klobuchar_leaves_tens_of_percent() {
        // Over a day at 55.7° N, 37.5° E, satellites every 30° of azimuth at 15–90°
        // elevation: the RMS of (truth − Klobuchar)/truth without the random residual.
        // Klobuchar (1987) states the broadcast model removes ≈ 50 % RMS of the delay; a world
        // the receiver corrects to better than 20 % or worse than 80 % would not be honest.
        let s = spec();
        let k = KlobucharCoefficients {
            alpha: [4.6566e-09, 1.4901e-08, -5.9605e-08, -1.1921e-07],
            beta: [8.1920e+04, 9.8304e+04, -6.5536e+04, -5.2429e+05],
        };
        let (lat, lon) = (55.7f64.to_radians(), 37.5f64.to_radians());
        let rx = Geodetic {
            lat_rad: lat,
            lon_rad: lon,
            height_m: 200.0,
        };
        let (mut num, mut den) = (0.0, 0.0);
        for hour in 0..24 {
            for az in (0..360).step_by(30) {
                for el in [15.0f64, 30.0, 50.0, 90.0] {
                    let (a, e) = ((az as f64).to_radians(), el.to_radians());
                    let t = s.model_delay_m(lat, lon, a, e, hour as f64 * 3600.0, F_L1_HZ);
                    let b = k.l1_delay_m(&rx, a, e, hour as f64 * 3600.0);
                    num += (t - b).powi(2);
                    den += t * t;
                }
            }
        }
        let rel = (num / den).sqrt();
        assert!((0.2..0.8).contains(&rel), "Klobuchar residual {rel}");
    }
}
