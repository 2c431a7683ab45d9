//! Propagation corrections of a GNSS pseudorange: the broadcast Klobuchar ionosphere, the
//! Saastamoinen troposphere, the dual-frequency ionosphere-free combination, and the
//! receiver-to-satellite azimuth and elevation they depend on.
//!
//! * Ionosphere: the GPS broadcast model of Klobuchar ("Ionospheric time-delay algorithm for
//!   single-frequency GPS users", IEEE Trans. AES 23(3), 1987) exactly as specified in
//!   IS-GPS-200 §20.3.3.5.2.5 (Figure 20-4): a half-cosine daytime bump on a 5 ns night-time
//!   floor, evaluated at the ionospheric pierce point (350 km shell) in geomagnetic latitude and
//!   local time, with the obliquity factor `F = 1 + 16 (0.53 − E)³`. It returns the L1 group
//!   delay; another frequency `f` sees `(f_L1/f)²` times it.
//! * Troposphere: Saastamoinen's zenith delays ("Atmospheric correction for the troposphere and
//!   stratosphere in radio ranging of satellites", AGU Geophys. Monograph 15, 1972) with the
//!   Davis et al. (1985) gravity factor `1 − 0.00266 cos 2φ − 0.00028 H` for the hydrostatic
//!   part, a standard atmosphere (pressure 1013.25 hPa, 15 °C at sea level, −6.5 K/km lapse,
//!   relative humidity given) when no meteorological data are available, and the **cosecant
//!   mapping function `1/sin(el)`** for both parts. The cosecant is what RTKLIB's single-point
//!   mode uses with its Saastamoinen option, so that a comparison of fixes compares the
//!   solvers, not the mapping; above 10° elevation it is within 1.5 % of the Niell mapping
//!   (≈ 0.2 m of a 13 m slant delay at 10°, ≈ 1 cm above 30°).
//! * Ionosphere-free pseudorange `P_IF = (f₁² P₁ − f₂² P₂)/(f₁² − f₂²)`: removes the
//!   first-order (1/f²) ionospheric delay; it amplifies uncorrelated code noise by
//!   `√(f₁⁴ + f₂⁴)/(f₁² − f₂²)` = 2.98 for GPS L1/L2.
//!
//! Pure functions, SI units except where a published model is stated in its own units (hPa,
//! semicircles), which are converted at the boundary.

use crate::broadcast_ephemeris::SPEED_OF_LIGHT_M_S;
use crate::earth::{self, Geodetic};
use nalgebra::Vector3;
use std::f64::consts::PI;

/// GPS L1 carrier frequency, Hz.
pub const F_L1_HZ: f64 = 1_575.42e6;
/// GPS L2 carrier frequency, Hz.
pub const F_L2_HZ: f64 = 1_227.60e6;
/// GPS L5 carrier frequency, Hz.
pub const F_L5_HZ: f64 = 1_176.45e6;

/// Azimuth (from north, clockwise, rad in [0, 2π)) and elevation (rad) of the satellite at
/// `sat_e_m` seen from the receiver at `rx_e_m` (both ECEF, m) whose geodetic position is `rx`.
pub fn azimuth_elevation(
    rx: &Geodetic,
    rx_e_m: &Vector3<f64>,
    sat_e_m: &Vector3<f64>,
) -> (f64, f64) {
    let los_e = (sat_e_m - rx_e_m).normalize();
    let los_n = earth::c_e_n(rx.lat_rad, rx.lon_rad).transpose() * los_e;
    let az = los_n.y.atan2(los_n.x).rem_euclid(2.0 * PI);
    let el = (-los_n.z).clamp(-1.0, 1.0).asin();
    (az, el)
}

/// The eight broadcast Klobuchar coefficients (RINEX `IONOSPHERIC CORR GPSA/GPSB`, the
/// `α_n`/`β_n` of IS-GPS-200 Table 20-X) in their native units: `α_n` in s/semicircleⁿ,
/// `β_n` in s/semicircleⁿ.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct KlobucharCoefficients {
    /// Amplitude polynomial `α_0..α_3`.
    pub alpha: [f64; 4],
    /// Period polynomial `β_0..β_3`.
    pub beta: [f64; 4],
}

/// Night-time (constant) term of the Klobuchar model, s.
pub const KLOBUCHAR_NIGHT_S: f64 = 5e-9;
/// Local time of the daytime maximum, s (14:00).
const KLOBUCHAR_PEAK_LOCAL_S: f64 = 50_400.0;
/// Smallest period of the daytime cosine, s.
const KLOBUCHAR_MIN_PERIOD_S: f64 = 72_000.0;

impl KlobucharCoefficients {
    /// L1 ionospheric group delay, m (positive: the code is late), for a receiver at geodetic
    /// `rx` looking at azimuth `az_rad` and elevation `el_rad` at GPS seconds of week
    /// `gps_seconds_of_week`. Zero for a satellite below the horizon.
    pub fn l1_delay_m(
        &self,
        rx: &Geodetic,
        az_rad: f64,
        el_rad: f64,
        gps_seconds_of_week: f64,
    ) -> f64 {
        if el_rad <= 0.0 {
            return 0.0;
        }
        // The model is stated in semicircles (1 semicircle = π rad).
        let e = el_rad / PI;
        let phi_u = rx.lat_rad / PI;
        let lam_u = rx.lon_rad / PI;
        // Earth-central angle between user and pierce point, pierce-point latitude (clamped
        // to ±0.416 semicircles) and longitude, geomagnetic latitude.
        let psi = 0.0137 / (e + 0.11) - 0.022;
        let phi_i = (phi_u + psi * az_rad.cos()).clamp(-0.416, 0.416);
        let lam_i = lam_u + psi * az_rad.sin() / (phi_i * PI).cos();
        let phi_m = phi_i + 0.064 * ((lam_i - 1.617) * PI).cos();
        // Local time at the pierce point.
        let t = (43_200.0 * lam_i + gps_seconds_of_week).rem_euclid(86_400.0);
        let f = 1.0 + 16.0 * (0.53 - e).powi(3);
        let poly = |c: &[f64; 4]| c[0] + phi_m * (c[1] + phi_m * (c[2] + phi_m * c[3]));
        let amp = poly(&self.alpha).max(0.0);
        let per = poly(&self.beta).max(KLOBUCHAR_MIN_PERIOD_S);
        let x = 2.0 * PI * (t - KLOBUCHAR_PEAK_LOCAL_S) / per;
        let delay_s = if x.abs() < 1.57 {
            f * (KLOBUCHAR_NIGHT_S + amp * (1.0 - x * x / 2.0 + x.powi(4) / 24.0))
        } else {
            f * KLOBUCHAR_NIGHT_S
        };
        delay_s * SPEED_OF_LIGHT_M_S
    }
}

/// Scale an L1 ionospheric group delay to frequency `f_hz` (first-order, 1/f²).
pub fn iono_delay_at(l1_delay_m: f64, f_hz: f64) -> f64 {
    l1_delay_m * (F_L1_HZ / f_hz).powi(2)
}

/// Surface meteorological values for the troposphere model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Meteo {
    /// Total pressure, hPa.
    pub pressure_hpa: f64,
    /// Temperature, K.
    pub temperature_k: f64,
    /// Partial pressure of water vapour, hPa.
    pub water_vapour_hpa: f64,
}

/// A standard atmosphere at `height_m` above sea level (the geoid; an ellipsoidal height is
/// within ±100 m of it, ≈ 1 % in pressure): pressure 1013.25 hPa·(1 − 2.2557e-5 h)^5.2568,
/// temperature 288.15 K − 6.5 K/km·h, water vapour at `relative_humidity` (0–1) of the
/// saturation pressure `6.108 exp((17.15 T − 4684)/(T − 38.45))` hPa. Heights below sea
/// level are treated as sea level.
pub fn standard_atmosphere(height_m: f64, relative_humidity: f64) -> Meteo {
    let h = height_m.max(0.0);
    let pressure_hpa = 1013.25 * (1.0 - 2.2557e-5 * h).powf(5.2568);
    let temperature_k = 288.15 - 6.5e-3 * h;
    let saturation = 6.108 * ((17.15 * temperature_k - 4684.0) / (temperature_k - 38.45)).exp();
    Meteo {
        pressure_hpa,
        temperature_k,
        water_vapour_hpa: relative_humidity * saturation,
    }
}

/// Zenith tropospheric delays, m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ZenithTroposphere {
    /// Hydrostatic ("dry") part, m.
    pub hydrostatic_m: f64,
    /// Wet part, m.
    pub wet_m: f64,
}

/// Saastamoinen zenith delays at geodetic latitude `lat_rad` and height `height_m` for the
/// surface values `meteo`: hydrostatic `0.0022768 P / (1 − 0.00266 cos 2φ − 0.00028 H_km)`,
/// wet `0.002277 (1255/T + 0.05) e` (P, e in hPa, T in K).
pub fn saastamoinen_zenith(lat_rad: f64, height_m: f64, meteo: &Meteo) -> ZenithTroposphere {
    let gravity = 1.0 - 0.00266 * (2.0 * lat_rad).cos() - 0.00028 * height_m.max(0.0) * 1e-3;
    ZenithTroposphere {
        hydrostatic_m: 0.002_276_8 * meteo.pressure_hpa / gravity,
        wet_m: 0.002_277 * (1255.0 / meteo.temperature_k + 0.05) * meteo.water_vapour_hpa,
    }
}

/// Slant tropospheric delay with the cosecant mapping `(ZHD + ZWD)/sin(el)`, m; zero for a
/// satellite at or below the horizon (the model is not meant for it).
pub fn slant_troposphere_m(zenith: &ZenithTroposphere, el_rad: f64) -> f64 {
    if el_rad <= 0.0 {
        return 0.0;
    }
    (zenith.hydrostatic_m + zenith.wet_m) / el_rad.sin()
}

/// Ionosphere-free combination of two pseudoranges on frequencies `f1_hz` and `f2_hz`, m.
pub fn iono_free(p1_m: f64, p2_m: f64, f1_hz: f64, f2_hz: f64) -> f64 {
    let (g1, g2) = (f1_hz * f1_hz, f2_hz * f2_hz);
    (g1 * p1_m - g2 * p2_m) / (g1 - g2)
}

/// Factor by which the ionosphere-free combination multiplies the standard deviation of
/// independent, equal code noise on both frequencies.
pub fn iono_free_noise_factor(f1_hz: f64, f2_hz: f64) -> f64 {
    let (g1, g2) = (f1_hz * f1_hz, f2_hz * f2_hz);
    (g1 * g1 + g2 * g2).sqrt() / (g1 - g2)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ESBC navigation header of 2020-06-25.
    fn esbc_klobuchar() -> KlobucharCoefficients {
        KlobucharCoefficients {
            alpha: [4.6566e-09, 1.4901e-08, -5.9605e-08, -1.1921e-07],
            beta: [8.1920e+04, 9.8304e+04, -6.5536e+04, -5.2429e+05],
        }
    }

    fn esbc() -> Geodetic {
        Geodetic {
            lat_rad: 55.4935f64.to_radians(),
            lon_rad: 8.4571f64.to_radians(),
            height_m: 50.0,
        }
    }

    /// At the zenith F = 1 + 16(0.53 − 0.5)³ = 1.000432; at night the delay is the 5 ns floor
    /// times F exactly, 1.4996 m; it never drops below 5 ns·F anywhere.
    #[test]
    fn klobuchar_night_floor() {
        let k = esbc_klobuchar();
        let rx = esbc();
        // 00:00 GPS at 8.5° E: local time ≈ 00:34, far from the 14:00 peak.
        let d = k.l1_delay_m(&rx, 0.0, PI / 2.0, 345_600.0);
        let f = 1.0 + 16.0 * (0.53f64 - 0.5).powi(3);
        assert!((d - f * 5e-9 * SPEED_OF_LIGHT_M_S).abs() < 1e-12, "{d}");
        for h in 0..24 {
            for el in [5.0f64, 15.0, 45.0, 90.0] {
                let el = el.to_radians();
                let f = 1.0 + 16.0 * (0.53 - el / PI).powi(3);
                let d = k.l1_delay_m(&rx, 1.0, el, 345_600.0 + h as f64 * 3600.0);
                assert!(d >= f * 5e-9 * SPEED_OF_LIGHT_M_S - 1e-9, "{h} h {el}: {d}");
                // A mid-latitude day-time delay is a few metres at the zenith, ≤ ~3× at 5°.
                assert!(d < 60.0);
            }
        }
        assert_eq!(k.l1_delay_m(&rx, 0.0, -0.01, 0.0), 0.0);
    }

    /// At 14:00 local time at the pierce point x = 0 and the delay is F (5 ns + AMP), AMP the
    /// α polynomial at the geomagnetic latitude; the L2 delay is (77/60)² times the L1 one.
    #[test]
    fn klobuchar_daytime_peak_and_frequency_scaling() {
        let k = KlobucharCoefficients {
            alpha: [2e-8, 0.0, 0.0, 0.0],
            beta: [100_000.0, 0.0, 0.0, 0.0],
        };
        let rx = Geodetic {
            lat_rad: 0.0,
            lon_rad: 0.0,
            height_m: 0.0,
        };
        // Zenith: ψ = 0.0137/0.61 − 0.022, pierce point at the user; λ_i = 0 → local = GPS time.
        let d = k.l1_delay_m(&rx, 0.0, PI / 2.0, 50_400.0);
        let f = 1.0 + 16.0 * (0.03f64).powi(3);
        assert!((d - f * 25e-9 * SPEED_OF_LIGHT_M_S).abs() < 1e-9, "{d}");
        let l2 = iono_delay_at(d, F_L2_HZ);
        assert!((l2 / d - (77.0f64 / 60.0).powi(2)).abs() < 1e-12);
    }

    /// Sea-level standard atmosphere: hydrostatic zenith delay ≈ 2.3 m (2.3070 m at 45°),
    /// wet ≈ 0.12 m at 70 % humidity; the slant delay at 30° is exactly twice the zenith one.
    #[test]
    fn saastamoinen_zenith_delays() {
        let m = standard_atmosphere(0.0, 0.7);
        assert!((m.pressure_hpa - 1013.25).abs() < 1e-12);
        let z = saastamoinen_zenith(45f64.to_radians(), 0.0, &m);
        assert!(
            (z.hydrostatic_m - 0.0022768 * 1013.25).abs() < 1e-12,
            "{z:?}"
        );
        assert!((z.hydrostatic_m - 2.3070).abs() < 1e-3);
        assert!((0.10..0.14).contains(&z.wet_m), "{z:?}");
        let s = slant_troposphere_m(&z, 30f64.to_radians());
        assert!((s - 2.0 * (z.hydrostatic_m + z.wet_m)).abs() < 1e-12);
        // 1 km up: pressure −11.3 %, the delay scales with it.
        let hi = saastamoinen_zenith(
            45f64.to_radians(),
            1000.0,
            &standard_atmosphere(1000.0, 0.7),
        );
        assert!(
            (hi.hydrostatic_m / z.hydrostatic_m - 0.8870).abs() < 2e-3,
            "{hi:?}"
        );
        assert_eq!(slant_troposphere_m(&z, 0.0), 0.0);
    }

    /// The combination removes any 1/f² delay exactly and passes a common range unchanged.
    #[test]
    fn iono_free_removes_first_order_delay() {
        let rho = 21_234_567.891;
        let i1 = 7.3;
        let p1 = rho + i1;
        let p2 = rho + iono_delay_at(i1, F_L2_HZ);
        assert!((iono_free(p1, p2, F_L1_HZ, F_L2_HZ) - rho).abs() < 1e-7);
        assert!((iono_free_noise_factor(F_L1_HZ, F_L2_HZ) - 2.978).abs() < 1e-3);
    }

    #[test]
    fn azimuth_and_elevation_of_known_directions() {
        let rx = esbc();
        let r = earth::geodetic_to_ecef(&earth::WGS84, &rx);
        let c = earth::c_e_n(rx.lat_rad, rx.lon_rad);
        // 20 000 km straight up, and along the horizon to the east.
        let (_, el) = azimuth_elevation(&rx, &r, &(r + c * Vector3::new(0.0, 0.0, -2e7)));
        assert!((el - PI / 2.0).abs() < 1e-9);
        let (az, el) = azimuth_elevation(&rx, &r, &(r + c * Vector3::new(0.0, 2e7, 0.0)));
        assert!((az - PI / 2.0).abs() < 1e-12 && el.abs() < 1e-12);
        let (az, el) = azimuth_elevation(&rx, &r, &(r + c * Vector3::new(-1e7, 0.0, -1e7)));
        assert!((az - PI).abs() < 1e-12 && (el - PI / 4.0).abs() < 1e-12);
    }
}
