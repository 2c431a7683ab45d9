//! Celestial → terrestrial: GCRS/ICRF → ITRS through IAU 2006/2000A precession-nutation, Earth
//! rotation angle and polar motion, checked against ERFA.
//!
//! OWNER: time/celestial helper. Signatures are the contract.

use crate::time::GpsTime;
use nalgebra::Matrix3;

/// Earth orientation parameters from configuration.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Deserialize, serde::Serialize)]
pub struct EarthOrientation {
    /// UT1 − UTC, s.
    #[serde(default)]
    pub dut1_s: f64,
    /// Polar motion x, rad.
    #[serde(default)]
    pub xp_rad: f64,
    /// Polar motion y, rad.
    #[serde(default)]
    pub yp_rad: f64,
}

/// DCM from GCRS (≈ ICRF axes) to ITRS (ECEF) at time `t`: `r_itrs = c_e_i · r_gcrs`.
pub fn c_e_i(t: GpsTime, eop: &EarthOrientation) -> Matrix3<f64> {
    let _ = (t, eop);
    unimplemented!("time/celestial helper")
}
