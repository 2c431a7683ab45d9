//! ISA (ICAO standard atmosphere) pressure ↔ altitude, used by the baro simulator and by the
//! filter's baro measurement model.
//!
//! Two layers: troposphere (0–11 km, lapse rate −6.5 K/km) and lower stratosphere (11–20 km,
//! isothermal at 216.65 K); the troposphere law is also used below sea level. Altitudes are
//! treated as geopotential (the < 0.1 % difference to geometric altitude below 20 km is ignored
//! consistently in both directions, so the pair is an exact inverse). Sextant feeds it the
//! height above the WGS-84 ellipsoid (docs/ARCHITECTURE.md: no geoid).

/// Sea-level standard pressure, Pa.
pub const ISA_P0_PA: f64 = 101_325.0;
/// Sea-level standard temperature, K.
pub const ISA_T0_K: f64 = 288.15;
/// Tropospheric temperature lapse rate, K/m (temperature falls with height).
pub const ISA_LAPSE_K_M: f64 = 0.0065;
/// Height of the tropopause, m.
pub const ISA_TROPOPAUSE_M: f64 = 11_000.0;
/// Standard gravity, m/s².
const G0: f64 = 9.806_65;
/// Specific gas constant of dry air, J/(kg·K).
const R_AIR: f64 = 287.052_87;

/// Exponent g0/(R·L) of the tropospheric pressure law (≈ 5.2559).
fn exponent() -> f64 {
    G0 / (R_AIR * ISA_LAPSE_K_M)
}

/// Temperature at the tropopause, K.
fn t11_k() -> f64 {
    ISA_T0_K - ISA_LAPSE_K_M * ISA_TROPOPAUSE_M
}

/// Pressure at the tropopause, Pa (≈ 22 632 Pa).
fn p11_pa() -> f64 {
    ISA_P0_PA * (t11_k() / ISA_T0_K).powf(exponent())
}

/// ISA static air temperature at altitude `h_m` above mean sea level, K.
pub fn isa_temperature_k(h_m: f64) -> f64 {
    if h_m <= ISA_TROPOPAUSE_M {
        ISA_T0_K - ISA_LAPSE_K_M * h_m
    } else {
        t11_k()
    }
}

/// Static pressure at altitude `h_m` above mean sea level in the ISA troposphere and
/// lower stratosphere, Pa.
pub fn isa_pressure_pa(h_m: f64) -> f64 {
    if h_m <= ISA_TROPOPAUSE_M {
        ISA_P0_PA * (1.0 - ISA_LAPSE_K_M * h_m / ISA_T0_K).powf(exponent())
    } else {
        p11_pa() * (-G0 * (h_m - ISA_TROPOPAUSE_M) / (R_AIR * t11_k())).exp()
    }
}

/// Altitude above mean sea level from static pressure in the ISA, m (inverse of
/// [`isa_pressure_pa`]). Non-positive or non-finite pressure gives NaN.
pub fn isa_altitude_m(pressure_pa: f64) -> f64 {
    if !(pressure_pa.is_finite() && pressure_pa > 0.0) {
        return f64::NAN;
    }
    let p11 = p11_pa();
    if pressure_pa >= p11 {
        ISA_T0_K / ISA_LAPSE_K_M * (1.0 - (pressure_pa / ISA_P0_PA).powf(1.0 / exponent()))
    } else {
        ISA_TROPOPAUSE_M - R_AIR * t11_k() / G0 * (pressure_pa / p11).ln()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn standard_values() {
        assert_eq!(isa_pressure_pa(0.0), 101_325.0);
        // ICAO table: 22 632.1 Pa at 11 km, 5 474.9 Pa at 20 km, 89 874.6 Pa at 1 km.
        assert!((isa_pressure_pa(11_000.0) - 22_632.1).abs() < 1.0);
        assert!((isa_pressure_pa(20_000.0) - 5_474.9).abs() < 2.0);
        assert!((isa_pressure_pa(1_000.0) - 89_874.6).abs() < 1.0);
        assert!((isa_temperature_k(11_000.0) - 216.65).abs() < 1e-9);
    }

    #[test]
    fn inverse_round_trips() {
        for h in [
            -400.0, 0.0, 200.0, 5_000.0, 10_999.0, 11_000.0, 11_001.0, 18_000.0,
        ] {
            let back = isa_altitude_m(isa_pressure_pa(h));
            assert!((back - h).abs() < 1e-6, "{h} -> {back}");
        }
        assert!(isa_altitude_m(101_325.0).abs() < 1e-9);
        assert!(isa_altitude_m(0.0).is_nan());
    }

    #[test]
    fn pressure_is_continuous_at_the_tropopause_and_decreasing() {
        let below = isa_pressure_pa(11_000.0 - 1e-6);
        let above = isa_pressure_pa(11_000.0 + 1e-6);
        assert!((below - above).abs() < 1e-3);
        let mut prev = f64::INFINITY;
        for i in 0..200 {
            let p = isa_pressure_pa(-500.0 + 100.0 * i as f64);
            assert!(p < prev);
            prev = p;
        }
    }
}
