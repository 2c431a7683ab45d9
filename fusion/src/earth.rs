//! Earth models: reference ellipsoids (WGS-84, PZ-90.11), geodetic ↔ ECEF, radii of curvature,
//! Earth and transport rates, normal gravity (Somigliana) and the J2 gravity model of paper 002
//! (in the corrected form of SEEDS.md).
//!
//! OWNER: foundations helper. Signatures are the contract other modules build against.

use nalgebra::{Matrix3, Vector3};

/// A reference ellipsoid with its gravity constants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ellipsoid {
    /// Semi-major axis, m.
    pub a_m: f64,
    /// Flattening.
    pub f: f64,
    /// Geocentric gravitational constant, m³/s².
    pub gm_m3_s2: f64,
    /// Earth rotation rate, rad/s.
    pub omega_ie_rad_s: f64,
    /// Second zonal harmonic J2 (unnormalised).
    pub j2: f64,
}

/// Geodetic coordinates on an ellipsoid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geodetic {
    /// Geodetic latitude, rad.
    pub lat_rad: f64,
    /// Longitude, rad.
    pub lon_rad: f64,
    /// Height above the ellipsoid, m.
    pub height_m: f64,
}

/// Which gravity model the mechanization uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum GravityModel {
    /// J2 gravitation plus centrifugal term (paper 002).
    #[default]
    J2,
    /// Somigliana normal gravity with free-air height correction, along the ellipsoid normal.
    Normal,
    /// Point mass GM/r² plus centrifugal term (for comparison only).
    PointMass,
}

/// WGS-84.
pub const WGS84: Ellipsoid = Ellipsoid {
    a_m: 6_378_137.0,
    f: 1.0 / 298.257_223_563,
    gm_m3_s2: 3.986_004_418e14,
    omega_ie_rad_s: 7.292_115e-5,
    j2: 1.082_629_821_313_8e-3,
};

/// PZ-90.11.
pub const PZ90: Ellipsoid = Ellipsoid {
    a_m: 6_378_136.0,
    f: 1.0 / 298.257_84,
    gm_m3_s2: 3.986_004_418e14,
    omega_ie_rad_s: 7.292_115e-5,
    j2: 1.082_625_75e-3,
};

impl Ellipsoid {
    /// First eccentricity squared.
    pub fn e2(&self) -> f64 {
        self.f * (2.0 - self.f)
    }
    /// Earth rotation vector in ECEF, rad/s.
    pub fn omega_ie_e(&self) -> Vector3<f64> {
        Vector3::new(0.0, 0.0, self.omega_ie_rad_s)
    }
}

/// Geodetic → ECEF position, m.
pub fn geodetic_to_ecef(ell: &Ellipsoid, g: &Geodetic) -> Vector3<f64> {
    let _ = (ell, g);
    unimplemented!("foundations helper")
}

/// ECEF → geodetic (exact to < 0.1 mm everywhere, poles included).
pub fn ecef_to_geodetic(ell: &Ellipsoid, r_e: &Vector3<f64>) -> Geodetic {
    let _ = (ell, r_e);
    unimplemented!("foundations helper")
}

/// DCM from NED to ECEF at (lat, lon): `r_e = c_e_n · r_n`.
pub fn c_e_n(lat_rad: f64, lon_rad: f64) -> Matrix3<f64> {
    let _ = (lat_rad, lon_rad);
    unimplemented!("foundations helper")
}

/// Meridian and prime-vertical radii of curvature at latitude, m: `(r_n, r_e)`.
pub fn radii_of_curvature(ell: &Ellipsoid, lat_rad: f64) -> (f64, f64) {
    let _ = (ell, lat_rad);
    unimplemented!("foundations helper")
}

/// Transport rate ω_en in NED for velocity `v_ned` at latitude/height, rad/s.
pub fn transport_rate_n(ell: &Ellipsoid, g: &Geodetic, v_ned: &Vector3<f64>) -> Vector3<f64> {
    let _ = (ell, g, v_ned);
    unimplemented!("foundations helper")
}

/// Gravitational attraction (no centrifugal term) in ECEF at `r_e` under `model`, m/s².
pub fn gravitation_ecef(ell: &Ellipsoid, model: GravityModel, r_e: &Vector3<f64>) -> Vector3<f64> {
    let _ = (ell, model, r_e);
    unimplemented!("foundations helper")
}

/// Gravity (attraction + centrifugal, what a plumb bob feels) in ECEF at `r_e`, m/s².
pub fn gravity_ecef(ell: &Ellipsoid, model: GravityModel, r_e: &Vector3<f64>) -> Vector3<f64> {
    let _ = (ell, model, r_e);
    unimplemented!("foundations helper")
}

/// Somigliana normal gravity magnitude at latitude and height, m/s².
pub fn normal_gravity(ell: &Ellipsoid, lat_rad: f64, height_m: f64) -> f64 {
    let _ = (ell, lat_rad, height_m);
    unimplemented!("foundations helper")
}
