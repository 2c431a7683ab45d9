//! ISA (ICAO standard atmosphere) pressure ↔ altitude, used by the baro simulator and by the
//! filter's baro measurement model.
//!
//! OWNER: simulator helper.

/// Static pressure at geometric altitude `h_m` above mean sea level in the ISA troposphere and
/// lower stratosphere, Pa.
pub fn isa_pressure_pa(h_m: f64) -> f64 {
    let _ = h_m;
    unimplemented!("simulator helper")
}

/// Altitude above mean sea level from static pressure in the ISA, m (inverse of
/// [`isa_pressure_pa`]).
pub fn isa_altitude_m(pressure_pa: f64) -> f64 {
    let _ = pressure_pa;
    unimplemented!("simulator helper")
}
