//! Earth models: reference ellipsoids (WGS-84, PZ-90.11), geodetic ↔ ECEF, radii of curvature,
//! Earth and transport rates, normal gravity (Somigliana) and the J2 gravity model of paper 002
//! (in the corrected form of SEEDS.md).
//!
//! Equations (all ECEF quantities in metres and seconds, angles in radians):
//! - geodetic → ECEF: `x = (R_E + h) cosφ cosλ`, `y = (R_E + h) cosφ sinλ`,
//!   `z = (R_E (1 − e²) + h) sinφ`, with `R_E = a / √(1 − e² sin²φ)`;
//! - ECEF → geodetic: Bowring's parametric-latitude iteration, a fixed number of passes
//!   ([`ECEF_TO_GEODETIC_ITERATIONS`]), height from `h = p cosφ + z sinφ − a √(1 − e² sin²φ)`
//!   (first-order insensitive to a latitude error, exact at the poles and on the equator);
//! - J2 gravitation (paper 002 with `I = 3/2 J2`, the bracket corrected as in SEEDS.md):
//!   `g_x,y = −GM/r³ [1 + 3/2 J2 (a/r)² (1 − 5 z²/r²)] x,y`,
//!   `g_z = −GM/r³ [1 + 3/2 J2 (a/r)² (3 − 5 z²/r²)] z`;
//! - gravity = gravitation − ω_ie × (ω_ie × r) for every model;
//! - normal gravity: Somigliana `γ = γ_e (1 + k sin²φ) / √(1 − e² sin²φ)`,
//!   `k = (b γ_p − a γ_e)/(a γ_e)`, with the second-order free-air correction
//!   `γ_h = γ [1 − 2/a (1 + f + m − 2 f sin²φ) h + 3 h²/a²]`, `m = ω² a² b / GM`
//!   (NIMA TR8350.2 eq. 4-3). `γ_e`, `γ_p` are derived from (a, f, GM, ω) by the closed
//!   formulas of the normal field (Moritz, Geodetic Reference System 1980), which give the
//!   WGS-84 values 9.7803253359 / 9.8321849378 m/s².

use crate::frames::{Ecef, Ned, Rotation};
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

/// WGS-84 (NIMA TR8350.2; J2 from C̄₂₀ = −0.484166774985e-3, J2 = −√5 C̄₂₀).
pub const WGS84: Ellipsoid = Ellipsoid {
    a_m: 6_378_137.0,
    f: 1.0 / 298.257_223_563,
    gm_m3_s2: 3.986_004_418e14,
    omega_ie_rad_s: 7.292_115e-5,
    j2: 1.082_629_821_313_8e-3,
};

/// PZ-90.11 (GLONASS ICD 2016: a = 6 378 136 m, 1/f = 298.25784, GM = 398 600.4418 km³/s²,
/// ω = 7.292115e-5 rad/s, J2⁰ = 1 082 625.75e-9).
pub const PZ90: Ellipsoid = Ellipsoid {
    a_m: 6_378_136.0,
    f: 1.0 / 298.257_84,
    gm_m3_s2: 3.986_004_418e14,
    omega_ie_rad_s: 7.292_115e-5,
    j2: 1.082_625_75e-3,
};

/// Number of Bowring passes in [`ecef_to_geodetic`]. Each pass reduces the latitude error by
/// roughly a factor e²·(a/r)·e² ≈ 1e-4·(a/r)²; three passes are below 1e-12 rad for every point
/// further than ~50 km from the Earth's centre (checked by the round-trip property test).
pub const ECEF_TO_GEODETIC_ITERATIONS: usize = 3;

/// Distance from the Earth's centre beyond which [`ecef_to_geodetic`] stops after two passes,
/// m: from 3000 km below the surface out past the geostationary orbit the third pass changes
/// the latitude by at most an ulp (≤ 3.3·10⁻¹⁶ rad; the test
/// `two_passes_suffice_beyond_the_threshold` compares them), and it costs a third of the
/// conversion that every solution makes.
pub const ECEF_TO_GEODETIC_TWO_PASS_RADIUS_M: f64 = 3.3e6;

impl Ellipsoid {
    /// First eccentricity squared, dimensionless.
    pub fn e2(&self) -> f64 {
        self.f * (2.0 - self.f)
    }
    /// Semi-minor axis b = a (1 − f), m.
    pub fn b_m(&self) -> f64 {
        self.a_m * (1.0 - self.f)
    }
    /// Second eccentricity squared e'² = e² / (1 − e²), dimensionless.
    pub fn ep2(&self) -> f64 {
        let e2 = self.e2();
        e2 / (1.0 - e2)
    }
    /// Earth rotation vector in ECEF, rad/s.
    pub fn omega_ie_e(&self) -> Vector3<f64> {
        Vector3::new(0.0, 0.0, self.omega_ie_rad_s)
    }
    /// Normal-field parameter m = ω² a² b / GM, dimensionless.
    pub fn m_normal(&self) -> f64 {
        self.omega_ie_rad_s * self.omega_ie_rad_s * self.a_m * self.a_m * self.b_m() / self.gm_m3_s2
    }
    /// Normal gravity on the ellipsoid at the equator (γ_e) and at the poles (γ_p), m/s²,
    /// from the closed formulas of the level-ellipsoid normal field (GRS80 document, Moritz):
    /// `γ_e = GM/(ab) (1 − m − m e' q₀'/(6 q₀))`, `γ_p = GM/a² (1 + m e' q₀'/(3 q₀))`.
    pub fn normal_gravity_equator_pole_m_s2(&self) -> (f64, f64) {
        let a = self.a_m;
        let b = self.b_m();
        let ep = self.ep2().sqrt();
        let atan_ep = ep.atan();
        let q0 = 0.5 * ((1.0 + 3.0 / (ep * ep)) * atan_ep - 3.0 / ep);
        let q0p = 3.0 * (1.0 + 1.0 / (ep * ep)) * (1.0 - atan_ep / ep) - 1.0;
        let m = self.m_normal();
        let gm = self.gm_m3_s2;
        let gamma_e = gm / (a * b) * (1.0 - m - m * ep * q0p / (6.0 * q0));
        let gamma_p = gm / (a * a) * (1.0 + m * ep * q0p / (3.0 * q0));
        (gamma_e, gamma_p)
    }
}

/// Geodetic → ECEF position, m.
pub fn geodetic_to_ecef(ell: &Ellipsoid, g: &Geodetic) -> Vector3<f64> {
    let (s_lat, c_lat) = g.lat_rad.sin_cos();
    let (s_lon, c_lon) = g.lon_rad.sin_cos();
    let e2 = ell.e2();
    let r_e = ell.a_m / (1.0 - e2 * s_lat * s_lat).sqrt();
    let rc = (r_e + g.height_m) * c_lat;
    Vector3::new(
        rc * c_lon,
        rc * s_lon,
        (r_e * (1.0 - e2) + g.height_m) * s_lat,
    )
}

/// ECEF → geodetic (exact to < 0.1 mm everywhere, poles included).
///
/// Bowring's iteration on the parametric latitude β with a fixed number of passes
/// ([`ECEF_TO_GEODETIC_ITERATIONS`]; two beyond [`ECEF_TO_GEODETIC_TWO_PASS_RADIUS_M`]); no
/// division by the axis distance, so the poles and the equatorial plane need no special case.
/// Valid for heights from well inside the Earth (≈ −6000 km) to beyond the geostationary orbit.
/// Longitude is 0 on the polar axis.
///
/// The angles are carried as their (sine, cosine) pairs, each the normalised vector whose
/// `atan2` the textbook form takes, so the passes need square roots only; the latitude's
/// and longitude's `atan2` are taken once at the end (it runs for every solution).
pub fn ecef_to_geodetic(ell: &Ellipsoid, r_e: &Vector3<f64>) -> Geodetic {
    bowring(ell, r_e).0
}

/// [`ecef_to_geodetic`] and the NED frame there, [`c_e_n`] at the latitude and longitude
/// found, built from the sines and cosines the iteration ends with rather than from the
/// angles: no trigonometric call (it runs for every solution). Equal to
/// `c_e_n(lat_rad, lon_rad)` to rounding.
pub fn ecef_to_geodetic_and_c_e_n(ell: &Ellipsoid, r_e: &Vector3<f64>) -> (Geodetic, Matrix3<f64>) {
    let (geo, [sl, cl, so, co]) = bowring(ell, r_e);
    (geo, c_e_n_from(sl, cl, so, co))
}

/// Bowring's passes ([`ecef_to_geodetic`]): the geodetic coordinates with the sine and cosine
/// of the latitude and of the longitude.
fn bowring(ell: &Ellipsoid, r_e: &Vector3<f64>) -> (Geodetic, [f64; 4]) {
    let passes = if r_e.norm_squared() > ECEF_TO_GEODETIC_TWO_PASS_RADIUS_M.powi(2) {
        2
    } else {
        ECEF_TO_GEODETIC_ITERATIONS
    };
    bowring_passes(ell, r_e, passes)
}

/// [`bowring`] with a given number of passes.
fn bowring_passes(ell: &Ellipsoid, r_e: &Vector3<f64>, passes: usize) -> (Geodetic, [f64; 4]) {
    let a = ell.a_m;
    let b = ell.b_m();
    let e2 = ell.e2();
    let ep2 = ell.ep2();
    let one_minus_f = 1.0 - ell.f;
    // Plain square roots, not `hypot`: the squares of coordinates up to 10¹⁵⁰ m cannot
    // overflow, and libm's `hypot` costs several times more.
    let p = (r_e.x * r_e.x + r_e.y * r_e.y).sqrt();
    let z = r_e.z;
    // (sin, cos) of atan2(y, x), with atan2(0, 0) = 0 (the Earth's centre).
    let unit = |y: f64, x: f64| {
        let n = (y * y + x * x).sqrt();
        if n > 0.0 { (y / n, x / n) } else { (0.0, 1.0) }
    };
    // Initial parametric latitude: tan β = z a / (p b).
    let (mut sb, mut cb) = unit(z, one_minus_f * p);
    let (mut n_lat, mut d_lat) = (0.0, 1.0);
    for _ in 0..passes {
        n_lat = z + ep2 * b * sb * sb * sb;
        d_lat = p - e2 * a * cb * cb * cb;
        let (sl, cl) = unit(n_lat, d_lat);
        (sb, cb) = unit(one_minus_f * sl, cl);
    }
    let (sl, cl) = unit(n_lat, d_lat);
    let (so, co) = unit(r_e.y, r_e.x);
    let height_m = p * cl + z * sl - a * (1.0 - e2 * sl * sl).sqrt();
    let geo = Geodetic {
        lat_rad: n_lat.atan2(d_lat),
        lon_rad: r_e.y.atan2(r_e.x),
        height_m,
    };
    (geo, [sl, cl, so, co])
}

/// DCM from NED to ECEF at (lat, lon): `r_e = c_e_n · r_n`.
///
/// Columns are the north, east and down unit vectors expressed in ECEF.
pub fn c_e_n(lat_rad: f64, lon_rad: f64) -> Matrix3<f64> {
    let (sl, cl) = lat_rad.sin_cos();
    let (so, co) = lon_rad.sin_cos();
    c_e_n_from(sl, cl, so, co)
}

/// [`c_e_n`] from the sine and cosine of the latitude (`sl`, `cl`) and longitude (`so`, `co`).
fn c_e_n_from(sl: f64, cl: f64, so: f64, co: f64) -> Matrix3<f64> {
    Matrix3::new(
        -sl * co,
        -so,
        -cl * co,
        -sl * so,
        co,
        -cl * so,
        cl,
        0.0,
        -sl,
    )
}

/// The rotation NED → ECEF at (lat, lon), frame-typed ([`c_e_n`]'s matrix; its inverse is
/// `c_n_e`, ECEF → NED).
pub fn ned_to_ecef(lat_rad: f64, lon_rad: f64) -> Rotation<Ned, Ecef> {
    Rotation::from_dcm_unchecked(c_e_n(lat_rad, lon_rad))
}

/// Unit vector of the ellipsoid normal ("up", outward) in ECEF at (lat, lon).
pub fn up_e(lat_rad: f64, lon_rad: f64) -> Vector3<f64> {
    let (sl, cl) = lat_rad.sin_cos();
    let (so, co) = lon_rad.sin_cos();
    Vector3::new(cl * co, cl * so, sl)
}

/// Meridian and prime-vertical radii of curvature at latitude, m: `(r_n, r_e)`.
///
/// `R_N = a (1 − e²) / (1 − e² sin²φ)^{3/2}`, `R_E = a / √(1 − e² sin²φ)`.
pub fn radii_of_curvature(ell: &Ellipsoid, lat_rad: f64) -> (f64, f64) {
    let e2 = ell.e2();
    let s = lat_rad.sin();
    let w2 = 1.0 - e2 * s * s;
    let w = w2.sqrt();
    let r_e = ell.a_m / w;
    let r_n = ell.a_m * (1.0 - e2) / (w2 * w);
    (r_n, r_e)
}

/// Transport rate ω_en in NED for velocity `v_ned` at latitude/height, rad/s.
///
/// `ω_en^n = [v_E/(R_E+h), −v_N/(R_N+h), −v_E tanφ/(R_E+h)]` (singular at the poles, as the
/// NED frame itself).
pub fn transport_rate_n(ell: &Ellipsoid, g: &Geodetic, v_ned: &Vector3<f64>) -> Vector3<f64> {
    let (r_n, r_e) = radii_of_curvature(ell, g.lat_rad);
    let re_h = r_e + g.height_m;
    let rn_h = r_n + g.height_m;
    Vector3::new(
        v_ned.y / re_h,
        -v_ned.x / rn_h,
        -v_ned.y * g.lat_rad.tan() / re_h,
    )
}

/// Centrifugal acceleration −ω_ie × (ω_ie × r) in ECEF at `r_e`, m/s².
pub fn centrifugal_ecef(ell: &Ellipsoid, r_e: &Vector3<f64>) -> Vector3<f64> {
    let w2 = ell.omega_ie_rad_s * ell.omega_ie_rad_s;
    Vector3::new(w2 * r_e.x, w2 * r_e.y, 0.0)
}

/// Gravitational attraction (no centrifugal term) in ECEF at `r_e` under `model`, m/s².
///
/// For [`GravityModel::Normal`] this is the normal gravity vector (along the ellipsoid normal,
/// downward) minus the centrifugal acceleration, so that [`gravity_ecef`] returns the normal
/// gravity vector itself. At the Earth's centre (r = 0) the result is zero.
pub fn gravitation_ecef(ell: &Ellipsoid, model: GravityModel, r_e: &Vector3<f64>) -> Vector3<f64> {
    let r2 = r_e.norm_squared();
    if r2 == 0.0 || !r2.is_finite() {
        return Vector3::zeros();
    }
    match model {
        GravityModel::PointMass => {
            let r = r2.sqrt();
            r_e * (-ell.gm_m3_s2 / (r2 * r))
        }
        GravityModel::J2 => {
            let r = r2.sqrt();
            let k = -ell.gm_m3_s2 / (r2 * r);
            let c = 1.5 * ell.j2 * ell.a_m * ell.a_m / r2;
            let zr2 = r_e.z * r_e.z / r2;
            let xy = k * (1.0 + c * (1.0 - 5.0 * zr2));
            let zz = k * (1.0 + c * (3.0 - 5.0 * zr2));
            Vector3::new(xy * r_e.x, xy * r_e.y, zz * r_e.z)
        }
        GravityModel::Normal => {
            let g = ecef_to_geodetic(ell, r_e);
            let gamma = normal_gravity(ell, g.lat_rad, g.height_m);
            up_e(g.lat_rad, g.lon_rad) * (-gamma) - centrifugal_ecef(ell, r_e)
        }
    }
}

/// Gravity (attraction + centrifugal, what a plumb bob feels) in ECEF at `r_e`, m/s².
///
/// `g = gravitation − ω_ie × (ω_ie × r)`.
pub fn gravity_ecef(ell: &Ellipsoid, model: GravityModel, r_e: &Vector3<f64>) -> Vector3<f64> {
    match model {
        GravityModel::Normal => {
            let g = ecef_to_geodetic(ell, r_e);
            up_e(g.lat_rad, g.lon_rad) * (-normal_gravity(ell, g.lat_rad, g.height_m))
        }
        _ => gravitation_ecef(ell, model, r_e) + centrifugal_ecef(ell, r_e),
    }
}

/// Somigliana normal gravity magnitude at latitude and height, m/s².
///
/// Exact Somigliana formula on the ellipsoid, second-order free-air correction in height
/// (TR8350.2 eq. 4-3); meant for heights up to a few tens of km.
pub fn normal_gravity(ell: &Ellipsoid, lat_rad: f64, height_m: f64) -> f64 {
    let (gamma_e, gamma_p) = ell.normal_gravity_equator_pole_m_s2();
    let a = ell.a_m;
    let b = ell.b_m();
    let e2 = ell.e2();
    let s2 = {
        let s = lat_rad.sin();
        s * s
    };
    let k = (b * gamma_p - a * gamma_e) / (a * gamma_e);
    let gamma0 = gamma_e * (1.0 + k * s2) / (1.0 - e2 * s2).sqrt();
    let m = ell.m_normal();
    let h = height_m;
    gamma0 * (1.0 - 2.0 / a * (1.0 + ell.f + m - 2.0 * ell.f * s2) * h + 3.0 * h * h / (a * a))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    /// Round-trip tolerance of the brief, m.
    const ROUND_TRIP_TOL_M: f64 = 1e-4;

    #[test]
    fn constants_and_derived_normal_gravity() {
        // WGS-84 defining γ_e, γ_p (TR8350.2 Table 3.4) to their printed 10 decimals.
        let (ge, gp) = WGS84.normal_gravity_equator_pole_m_s2();
        assert!((ge - 9.780_325_335_9).abs() < 1e-9, "γe = {ge}");
        assert!((gp - 9.832_184_937_8).abs() < 1e-9, "γp = {gp}");
        assert!((normal_gravity(&WGS84, 0.0, 0.0) - 9.780_325_335_9).abs() < 1e-9);
        assert!((normal_gravity(&WGS84, FRAC_PI_2, 0.0) - 9.832_184_937_8).abs() < 1e-9);
        assert!((normal_gravity(&WGS84, -FRAC_PI_2, 0.0) - 9.832_184_937_8).abs() < 1e-9);
        // PZ-90.11 (GLONASS ICD): γ_e = 9.7803284 m/s², γ_p = 9.8321880 m/s² (7 decimals).
        let (ge, gp) = PZ90.normal_gravity_equator_pole_m_s2();
        assert!((ge - 9.780_328_4).abs() < 1e-6, "PZ-90 γe = {ge}");
        assert!((gp - 9.832_188_0).abs() < 1e-6, "PZ-90 γp = {gp}");
        // WGS-84 semi-minor axis (TR8350.2: 6 356 752.3142 m).
        assert!((WGS84.b_m() - 6_356_752.314_2).abs() < 1e-4);
        // The J2 stored is the normal-field J2 of the level ellipsoid:
        // J2 = e²/3 (1 − 2/15 m e'/q₀) (Moritz).
        let ep = WGS84.ep2().sqrt();
        let q0 = 0.5 * ((1.0 + 3.0 / (ep * ep)) * ep.atan() - 3.0 / ep);
        let j2_normal = WGS84.e2() / 3.0 * (1.0 - 2.0 / 15.0 * WGS84.m_normal() * ep / q0);
        assert!(
            (j2_normal - WGS84.j2).abs() < 1e-11,
            "J2 normal {j2_normal}"
        );
    }

    #[test]
    fn known_points() {
        let a = WGS84.a_m;
        let b = WGS84.b_m();
        let p = geodetic_to_ecef(
            &WGS84,
            &Geodetic {
                lat_rad: 0.0,
                lon_rad: 0.0,
                height_m: 0.0,
            },
        );
        assert!((p - Vector3::new(a, 0.0, 0.0)).norm() < 1e-9);
        let p = geodetic_to_ecef(
            &WGS84,
            &Geodetic {
                lat_rad: FRAC_PI_2,
                lon_rad: 1.0,
                height_m: 0.0,
            },
        );
        assert!((p - Vector3::new(0.0, 0.0, b)).norm() < 1e-9, "{p}");
        let g = ecef_to_geodetic(&WGS84, &Vector3::new(a, 0.0, 0.0));
        assert!(g.lat_rad.abs() < 1e-15 && g.lon_rad.abs() < 1e-15 && g.height_m.abs() < 1e-9);
        let g = ecef_to_geodetic(&WGS84, &Vector3::new(0.0, 0.0, b));
        assert!(
            (g.lat_rad - FRAC_PI_2).abs() < 1e-15 && g.height_m.abs() < 1e-9,
            "{g:?}"
        );
        let g = ecef_to_geodetic(&WGS84, &Vector3::new(0.0, 0.0, -b - 100.0));
        assert!((g.lat_rad + FRAC_PI_2).abs() < 1e-15 && (g.height_m - 100.0).abs() < 1e-9);
        let g = ecef_to_geodetic(&WGS84, &Vector3::new(0.0, -a - 5.0, 0.0));
        assert!(g.lat_rad.abs() < 1e-15 && (g.lon_rad + FRAC_PI_2).abs() < 1e-15);
        assert!((g.height_m - 5.0).abs() < 1e-9);
        // Centre of the Earth: finite, no NaN.
        let g = ecef_to_geodetic(&WGS84, &Vector3::zeros());
        assert!(g.lat_rad.is_finite() && g.height_m.is_finite());
    }

    fn lat_strategy() -> impl Strategy<Value = f64> {
        prop_oneof![
            Just(FRAC_PI_2),
            Just(-FRAC_PI_2),
            Just(0.0),
            (FRAC_PI_2 - 1e-6)..FRAC_PI_2,
            -FRAC_PI_2..FRAC_PI_2,
        ]
    }

    fn height_strategy() -> impl Strategy<Value = f64> {
        prop_oneof![
            -10_000.0..10_000.0,
            -10_000.0..4.0e7_f64,
            Just(-10_000.0),
            Just(4.0e7)
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(4000))]
        /// Beyond the two-pass radius (3000 km below the surface and out, here to 40 000 km
        /// up) the third pass moves the latitude by at most an ulp and the height by a few ulp.
        #[test]
        fn two_passes_suffice_beyond_the_threshold(
            lat in lat_strategy(),
            lon in -PI..PI,
            h in prop_oneof![-3.0e6..-2.9e6, -3.0e6..4.0e7_f64, -10_000.0..10_000.0],
        ) {
            for ell in [WGS84, PZ90] {
                let r = geodetic_to_ecef(&ell, &Geodetic { lat_rad: lat, lon_rad: lon, height_m: h });
                prop_assume!(r.norm() > ECEF_TO_GEODETIC_TWO_PASS_RADIUS_M);
                let (two, _) = bowring_passes(&ell, &r, 2);
                let (three, _) = bowring_passes(&ell, &r, ECEF_TO_GEODETIC_ITERATIONS);
                prop_assert!((two.lat_rad - three.lat_rad).abs() <= 4.5e-16, "{}", two.lat_rad - three.lat_rad);
                // A few ulp of the distance from the centre.
                let dh = (two.height_m - three.height_m).abs();
                prop_assert!(dh <= 1e-15 * r.norm(), "{}", dh);
                prop_assert_eq!(bowring(&ell, &r).0, two);
            }
        }

        #[test]
        fn geodetic_round_trip(lat in lat_strategy(), lon in -PI..PI, h in height_strategy()) {
            for ell in [WGS84, PZ90] {
                let g = Geodetic { lat_rad: lat, lon_rad: lon, height_m: h };
                let r = geodetic_to_ecef(&ell, &g);
                let g2 = ecef_to_geodetic(&ell, &r);
                let r2 = geodetic_to_ecef(&ell, &g2);
                prop_assert!((r2 - r).norm() < ROUND_TRIP_TOL_M, "ecef {}", (r2 - r).norm());
                prop_assert!((g2.height_m - h).abs() < ROUND_TRIP_TOL_M, "h {}", g2.height_m - h);
                let (r_n, r_e) = radii_of_curvature(&ell, lat);
                prop_assert!((g2.lat_rad - lat).abs() * (r_n + h) < ROUND_TRIP_TOL_M);
                if lat.abs() < FRAC_PI_2 {
                    let dlon = (g2.lon_rad - lon + PI).rem_euclid(2.0 * PI) - PI;
                    prop_assert!(dlon.abs() * (r_e + h) * lat.cos() < ROUND_TRIP_TOL_M);
                }
                // The frame from the iteration's sines and cosines is the frame at the angles
                // it returns, to rounding (a few ulp of a unit vector's components).
                let (g3, c) = ecef_to_geodetic_and_c_e_n(&ell, &r);
                prop_assert_eq!(g3, g2);
                let d = (c - c_e_n(g2.lat_rad, g2.lon_rad)).abs().max();
                prop_assert!(d < 1e-15, "c_e_n differs by {}", d);
            }
        }
    }

    #[test]
    fn c_e_n_is_ned() {
        let (lat, lon) = (0.7, -2.1);
        let c = c_e_n(lat, lon);
        assert!((c.transpose() * c - Matrix3::identity()).norm() < 1e-15);
        assert!((c.determinant() - 1.0).abs() < 1e-15);
        // Down is minus the ellipsoid normal; north is the direction of increasing latitude.
        assert!((c * Vector3::new(0.0, 0.0, -1.0) - up_e(lat, lon)).norm() < 1e-15);
        let h = 100.0;
        let dlat = 1e-7;
        let p0 = geodetic_to_ecef(
            &WGS84,
            &Geodetic {
                lat_rad: lat,
                lon_rad: lon,
                height_m: h,
            },
        );
        let p1 = geodetic_to_ecef(
            &WGS84,
            &Geodetic {
                lat_rad: lat + dlat,
                lon_rad: lon,
                height_m: h,
            },
        );
        let north = (p1 - p0).normalize();
        assert!((north - c.column(0)).norm() < 1e-7);
        let p2 = geodetic_to_ecef(
            &WGS84,
            &Geodetic {
                lat_rad: lat,
                lon_rad: lon + dlat,
                height_m: h,
            },
        );
        let east = (p2 - p0).normalize();
        assert!((east - c.column(1)).norm() < 1e-7);
        // Meridian radius from the same finite difference: |dr| = (R_N + h) dφ.
        let (r_n, r_e) = radii_of_curvature(&WGS84, lat);
        assert!(((p1 - p0).norm() / dlat - (r_n + h)).abs() < 1e-2);
        assert!(((p2 - p0).norm() / (dlat * lat.cos()) - (r_e + h)).abs() < 1e-2);
    }

    #[test]
    fn radii_at_equator_and_pole() {
        let a = WGS84.a_m;
        let b = WGS84.b_m();
        let (r_n, r_e) = radii_of_curvature(&WGS84, 0.0);
        assert!((r_e - a).abs() < 1e-8);
        assert!((r_n - a * (1.0 - WGS84.e2())).abs() < 1e-8);
        let (r_n, r_e) = radii_of_curvature(&WGS84, FRAC_PI_2);
        assert!((r_n - a * a / b).abs() < 1e-8 && (r_e - a * a / b).abs() < 1e-8);
    }

    #[test]
    fn transport_rate_values() {
        let g = Geodetic {
            lat_rad: 0.5,
            lon_rad: 0.0,
            height_m: 1000.0,
        };
        let (r_n, r_e) = radii_of_curvature(&WGS84, g.lat_rad);
        let w = transport_rate_n(&WGS84, &g, &Vector3::new(10.0, 20.0, 5.0));
        assert!((w.x - 20.0 / (r_e + 1000.0)).abs() < 1e-18);
        assert!((w.y + 10.0 / (r_n + 1000.0)).abs() < 1e-18);
        assert!((w.z + 20.0 * 0.5_f64.tan() / (r_e + 1000.0)).abs() < 1e-18);
    }

    /// Potential of the J2 field: V = GM/r [1 − J2 (a/r)² P2(z/r)].
    fn potential_j2(ell: &Ellipsoid, r: &Vector3<f64>) -> f64 {
        let rn = r.norm();
        let s = r.z / rn;
        let p2 = 0.5 * (3.0 * s * s - 1.0);
        ell.gm_m3_s2 / rn * (1.0 - ell.j2 * (ell.a_m / rn).powi(2) * p2)
    }

    #[test]
    fn j2_gravitation_is_gradient_of_j2_potential() {
        // Central differences with step d: truncation ≈ d²/6 · V''' ≈ d² · 3g/r² ≈ 1e-12 m/s²
        // for d = 1 m; rounding ≈ ε V / d ≈ 1.3e-8 m/s². Tolerance 1e-7 m/s².
        let d = 1.0;
        for (lat, h) in [
            (0.0, 0.0),
            (0.3, 1e5),
            (1.2, 2e6),
            (-1.5, 0.0),
            (FRAC_PI_2, 10.0),
        ] {
            let r = geodetic_to_ecef(
                &WGS84,
                &Geodetic {
                    lat_rad: lat,
                    lon_rad: 0.4,
                    height_m: h,
                },
            );
            let g = gravitation_ecef(&WGS84, GravityModel::J2, &r);
            for i in 0..3 {
                let mut rp = r;
                let mut rm = r;
                rp[i] += d;
                rm[i] -= d;
                let grad = (potential_j2(&WGS84, &rp) - potential_j2(&WGS84, &rm)) / (2.0 * d);
                assert!(
                    (grad - g[i]).abs() < 1e-7,
                    "axis {i} at lat {lat}: {grad} vs {}",
                    g[i]
                );
            }
        }
    }

    #[test]
    fn gravity_models_consistent() {
        for model in [
            GravityModel::J2,
            GravityModel::Normal,
            GravityModel::PointMass,
        ] {
            for (lat, lon, h) in [(0.1, 0.2, 0.0), (-0.9, 3.0, 5000.0), (1.4, -1.0, 100.0)] {
                let r = geodetic_to_ecef(
                    &WGS84,
                    &Geodetic {
                        lat_rad: lat,
                        lon_rad: lon,
                        height_m: h,
                    },
                );
                let w = WGS84.omega_ie_e();
                let expect = gravitation_ecef(&WGS84, model, &r) - w.cross(&w.cross(&r));
                assert!((gravity_ecef(&WGS84, model, &r) - expect).norm() < 1e-13);
            }
        }
        // Normal gravity points along −up with magnitude γ(φ, h).
        let g0 = Geodetic {
            lat_rad: 0.8,
            lon_rad: 0.1,
            height_m: 300.0,
        };
        let r = geodetic_to_ecef(&WGS84, &g0);
        let g = gravity_ecef(&WGS84, GravityModel::Normal, &r);
        let gamma = normal_gravity(&WGS84, 0.8, 300.0);
        assert!((g + up_e(0.8, 0.1) * gamma).norm() < 1e-12);
        assert_eq!(
            gravitation_ecef(&WGS84, GravityModel::J2, &Vector3::zeros()),
            Vector3::zeros()
        );
    }

    #[test]
    fn free_air_gradient() {
        // dγ/dh = −2γ/a (1 + f + m − 2 f sin²φ) ≈ −3.086e-6 s⁻² at mid latitudes.
        let d = (normal_gravity(&WGS84, 0.785, 100.0) - normal_gravity(&WGS84, 0.785, 0.0)) / 100.0;
        assert!((d + 3.086e-6).abs() < 2e-9, "{d}");
    }

    /// J2-only gravity vs Somigliana normal gravity on the ellipsoid surface.
    ///
    /// Somigliana is the exact gravity of the level ellipsoid, whose external potential is
    /// `V = GM/r [1 − Σ J₂ₙ (a/r)²ⁿ P₂ₙ(sin ψ)]` (ψ geocentric latitude) plus the centrifugal
    /// potential, with J₂ₙ fixed by (a, f, GM, ω) (Heiskanen–Moritz 2-92):
    /// `J₂ₙ = (−1)ⁿ⁺¹ 3 e²ⁿ / ((2n+1)(2n+3)) · (1 − n + 5n J₂/e²)`.
    /// The J2 model drops n ≥ 2, so the difference of magnitudes must be the radial J4 term
    /// `−5 GM/r² J4 (a/r)⁴ P4(sin ψ)` (≈ 1.2e-4 m/s² at the poles, J4 ≈ −2.37e-6), up to
    /// the J6 term (≤ 7 g |J6| ≈ 4e-7 m/s²) and the tangential J4 component's projection on
    /// the (nearly normal) gravity direction (≤ 3.4e-3 · 3 g |J4| ≈ 2.4e-7 m/s²).
    #[test]
    fn j2_vs_normal_gravity_at_surface() {
        let ell = WGS84;
        let e2 = ell.e2();
        let j4 = -3.0 * e2 * e2 / 35.0 * (1.0 - 2.0 + 10.0 * ell.j2 / e2);
        let j6 = 3.0 * e2 * e2 * e2 / 63.0 * (1.0 - 3.0 + 15.0 * ell.j2 / e2);
        let mut max_diff: f64 = 0.0;
        for i in 0..=90 {
            let lat = (i as f64).to_radians() * 2.0 - FRAC_PI_2;
            let r = geodetic_to_ecef(
                &ell,
                &Geodetic {
                    lat_rad: lat,
                    lon_rad: 0.3,
                    height_m: 0.0,
                },
            );
            let rn = r.norm();
            let g_r = ell.gm_m3_s2 / (rn * rn);
            let tol = 7.0 * g_r * j6.abs() + 3.4e-3 * 3.0 * g_r * j4.abs();
            let s = r.z / rn;
            let p4 = (35.0 * s.powi(4) - 30.0 * s * s + 3.0) / 8.0;
            let predicted = -5.0 * g_r * j4 * (ell.a_m / rn).powi(4) * p4;
            let diff = gravity_ecef(&ell, GravityModel::Normal, &r).norm()
                - gravity_ecef(&ell, GravityModel::J2, &r).norm();
            max_diff = max_diff.max(diff.abs());
            assert!(
                (diff - predicted).abs() < tol,
                "lat {lat}: diff {diff} predicted {predicted}"
            );
            // Directions agree to the deflection caused by J4: ≲ 3 g|J4|/g ≈ 7e-6 rad.
            let cosang = gravity_ecef(&ell, GravityModel::Normal, &r)
                .normalize()
                .dot(&gravity_ecef(&ell, GravityModel::J2, &r).normalize());
            assert!(cosang.min(1.0).acos() < 3.0 * j4.abs() * 1.2, "lat {lat}");
        }
        assert!(max_diff < 1.3e-4, "{max_diff}");
    }
}
