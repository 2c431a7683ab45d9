//! The sky of the GNSS tests: seven satellites spread in azimuth and from 12° to 80° of
//! elevation (a geometry with a good PDOP that still has low satellites), and the GPS L1
//! carrier's wavelength.

/// GPS L1 carrier wavelength, m (c / 1575.42 MHz).
pub const L1_WAVELENGTH_M: f64 = 299_792_458.0 / 1_575_420_000.0;

/// (azimuth, elevation) of each satellite, deg; the PRN is the index + 1.
pub const SKY_AZ_EL_DEG: [(f64, f64); 7] = [
    (0.0, 80.0),
    (40.0, 20.0),
    (110.0, 45.0),
    (170.0, 15.0),
    (230.0, 60.0),
    (300.0, 30.0),
    (340.0, 12.0),
];
