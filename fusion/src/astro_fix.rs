//! Astro position fix (paper 000, "astro-inertial navigation: IMU / star-tracker basis
//! alignment", eqs. 4–7): latitude and longitude from one star-tracker attitude, the IMU's
//! gravity vertical (roll and pitch) and time.
//!
//! Paper chain (eq. 4): `M_ISK→ZPSK = M_APSK→ZPSK · C_γ C_θ C_ψ · M_GSK→MSK · M_ISK→GSK`.
//! In Sextant's frames (the simulator's star-tracker contract) the same chain reads
//! `c_s_i = c_s_b · c_b_n · c_n_e · c_e_i(t)` with `c_n_b = R_z(ψ) · R_y(θ) · R_x(γ)`.
//! Solving for the Earth-fixed attitude of the local level (eq. 5):
//! `c_n_e = R_z(ψ) · [R_y(θ) R_x(γ)] · c_s_bᵀ · c_s_i · c_e_iᵀ`.
//! A rotation about the vertical leaves the third ("down") row unchanged, so that row needs no
//! heading: it is the gravity direction `d_e = c_e_i · c_s_iᵀ · c_s_b · d_b`, with
//! `d_b = [−sin θ, cos θ sin γ, cos θ cos γ]` the down vector in body axes. The paper's ENU
//! third row is `up = −d = [cos φ cos λ, cos φ sin λ, sin φ]`, hence eqs. 6–7:
//! `φ = asin(up_z)`, `λ = atan2(up_y, up_x)`. The chains are written with the frame-typed
//! rotations of [`crate::frames`] (`c_s_i: Rotation<Icrf, StarSensor>`, …), so a transposed
//! or misordered factor does not compile.
//!
//! The latitude is the direction of the gravity vertical, i.e. astronomical latitude; it equals
//! geodetic latitude where the deflection of the vertical is zero (as in the simulator, whose
//! gravity vertical is the ellipsoid normal). A tilt error δ of the vertical (IMU levelling or
//! tracker) turns the fix by the same angle δ on the sphere of directions, i.e. moves it by
//! `R·δ` on the ground (1′ ≈ 1 nautical mile, 1852 m) — the paper's rule, tested below.
//!
//! The paper computes `M_ISK→GSK` as Earth rotation only; [`CelestialModel`] offers that
//! reduction next to the full IAU 2006/2000A model of [`crate::celestial`], so that experiments
//! can measure what ignoring precession–nutation costs.

use crate::celestial::{self, EarthOrientation};
use crate::frames::{Body, Ecef, Icrf, Ned, Rotation, StarSensor, Vector};
use crate::time::GpsTime;
use nalgebra::{Matrix3, Vector3};

/// Largest accepted deviation of an input DCM from orthonormality, `max|C·Cᵀ − I|`.
///
/// Star-tracker quaternions on the wire are normalised to ≈1e-16; 1e-6 admits products of a few
/// float matrices while rejecting anything that is not a rotation (a wrong matrix is off by O(1)).
pub const ORTHONORMALITY_TOLERANCE: f64 = 1e-6;

/// Largest accepted |roll| and |pitch| for a fix, rad (80°): beyond that the "vertical" from a
/// levelled IMU is no longer what the caller meant (and pitch ±90° is the Euler singularity).
pub const MAX_TILT_RAD: f64 = 80.0 * std::f64::consts::PI / 180.0;

/// Why an astro fix or a boresight calibration could not be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AstroError {
    /// An input value is NaN or infinite.
    #[error("{what} is not finite")]
    NotFinite {
        /// Which input.
        what: &'static str,
    },
    /// An input matrix is not a rotation.
    #[error("{what} is not a rotation matrix (max |C·Cᵀ − I| = {deviation:.3e})")]
    NotRotation {
        /// Which input.
        what: &'static str,
        /// `max|C·Cᵀ − I|`, or 1 for a reflection (det < 0).
        deviation: f64,
    },
    /// Roll or pitch is beyond [`MAX_TILT_RAD`].
    #[error("{what} = {value_deg:.3}° exceeds ±80°")]
    TiltOutOfRange {
        /// `roll` or `pitch`.
        what: &'static str,
        /// The value, degrees.
        value_deg: f64,
    },
    /// Too few samples (or none in a required time window).
    #[error("not enough samples: {0}")]
    NotEnoughSamples(String),
    /// A setting makes no sense (non-positive step, threshold, sigma…).
    #[error("invalid setting {what}: {reason}")]
    InvalidSetting {
        /// Which setting.
        what: &'static str,
        /// Why.
        reason: String,
    },
}

/// One astro position fix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AstroFix {
    /// Latitude of the gravity vertical (astronomical ≈ geodetic), rad.
    pub lat_rad: f64,
    /// Longitude, rad, in (−π, π].
    pub lon_rad: f64,
    /// The measured down direction, ECEF unit vector.
    pub down_e: Vector3<f64>,
}

/// How the ICRF → ECEF rotation `c_e_i(t)` is computed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CelestialModel {
    /// IAU 2006/2000A precession–nutation, ERA and polar motion ([`celestial::c_e_i`]).
    Full(EarthOrientation),
    /// The paper's reduction: Earth rotation only, `c_e_i = R3(GMST)` with the IAU 2006 GMST
    /// (ERFA `eraGmst06`, UT1 = UTC + `dut1_s`): sidereal time against a J2000 catalogue,
    /// ignoring precession (in right ascension and of the pole), nutation and polar motion.
    GmstOnly {
        /// UT1 − UTC, s.
        dut1_s: f64,
    },
    /// Earth rotation angle only, `c_e_i = R3(ERA)`: like [`CelestialModel::GmstOnly`] but
    /// measured from the CIO, so precession in right ascension is (mostly) absent and what is
    /// ignored is essentially the motion of the pole (precession–nutation tilt).
    EraOnly {
        /// UT1 − UTC, s.
        dut1_s: f64,
    },
}

impl CelestialModel {
    /// `c_e_i` at GPS time `t`: `r_e = c_e_i · r_i`.
    pub fn c_e_i(&self, t: GpsTime) -> Matrix3<f64> {
        match self {
            CelestialModel::Full(eop) => celestial::c_e_i(t, eop),
            CelestialModel::GmstOnly { dut1_s } => r3(gmst06_rad(t, *dut1_s)),
            CelestialModel::EraOnly { dut1_s } => r3(celestial::era(t, *dut1_s)),
        }
    }

    /// Short name for tables (`full`, `gmst_only`, `era_only`).
    pub fn name(&self) -> &'static str {
        match self {
            CelestialModel::Full(_) => "full",
            CelestialModel::GmstOnly { .. } => "gmst_only",
            CelestialModel::EraOnly { .. } => "era_only",
        }
    }
}

/// Rotation of the axes by +`a` about z (ERFA sense): `R3(a) = [[c, s, 0], [−s, c, 0], [0, 0, 1]]`.
fn r3(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0)
}

/// Greenwich mean sidereal time, IAU 2006 (ERFA `eraGmst06`: ERA plus the precession in right
/// ascension polynomial in TT centuries), rad in [0, 2π).
pub fn gmst06_rad(t: GpsTime, dut1_s: f64) -> f64 {
    let tc = t.tt_centuries();
    let poly_arcsec = 0.014506
        + (4612.156534
            + (1.3915817 + (-0.00000044 + (-0.000029956 + (-0.0000000368) * tc) * tc) * tc) * tc)
            * tc;
    (celestial::era(t, dut1_s) + poly_arcsec * celestial::DAS2R).rem_euclid(std::f64::consts::TAU)
}

/// `max|C·Cᵀ − I|` of `c` (1 when det < 0).
pub fn orthonormality_deviation(c: &Matrix3<f64>) -> f64 {
    if c.determinant() <= 0.0 {
        return 1.0;
    }
    (c * c.transpose() - Matrix3::identity()).abs().max()
}

/// Check that `c` is a finite rotation matrix.
pub fn check_rotation(what: &'static str, c: &Matrix3<f64>) -> Result<(), AstroError> {
    if c.iter().any(|v| !v.is_finite()) {
        return Err(AstroError::NotFinite { what });
    }
    let deviation = orthonormality_deviation(c);
    if deviation > ORTHONORMALITY_TOLERANCE {
        return Err(AstroError::NotRotation { what, deviation });
    }
    Ok(())
}

/// Check roll and pitch (rad) for a fix.
pub fn check_tilt(roll_rad: f64, pitch_rad: f64) -> Result<(), AstroError> {
    for (what, v) in [("roll", roll_rad), ("pitch", pitch_rad)] {
        if !v.is_finite() {
            return Err(AstroError::NotFinite { what });
        }
        if v.abs() > MAX_TILT_RAD {
            return Err(AstroError::TiltOutOfRange {
                what,
                value_deg: v.to_degrees(),
            });
        }
    }
    Ok(())
}

/// The down direction in body axes for roll `γ` and pitch `θ` (rad): the third row of
/// `c_n_b = R_z(ψ) R_y(θ) R_x(γ)`, `[−sin θ, cos θ sin γ, cos θ cos γ]`.
pub fn down_b(roll_rad: f64, pitch_rad: f64) -> Vector3<f64> {
    let (sr, cr) = roll_rad.sin_cos();
    let (sp, cp) = pitch_rad.sin_cos();
    Vector3::new(-sp, cp * sr, cp * cr)
}

/// Latitude and longitude (rad) of an ECEF down direction (any length > 0).
pub fn lat_lon_of_down(down_e: &Vector3<f64>) -> (f64, f64) {
    let up = -down_e.normalize();
    (up.z.clamp(-1.0, 1.0).asin(), up.y.atan2(up.x))
}

/// Astro fix without input checks (the hot loop of calibrations over already checked data),
/// on bare DCMs with the meaning of [`astro_fix`]'s typed arguments.
pub fn astro_fix_unchecked(
    c_s_i: &Matrix3<f64>,
    roll_rad: f64,
    pitch_rad: f64,
    c_s_b: &Matrix3<f64>,
    c_e_i: &Matrix3<f64>,
) -> AstroFix {
    fix_of_chain(
        &Rotation::from_dcm_unchecked(*c_s_i),
        roll_rad,
        pitch_rad,
        &Rotation::from_dcm_unchecked(*c_s_b),
        &Rotation::from_dcm_unchecked(*c_e_i),
    )
}

/// The down direction measured through the star tracker, `d_e = c_e_i · c_s_iᵀ · c_s_b · d_b`,
/// and its latitude and longitude.
fn fix_of_chain(
    c_s_i: &Rotation<Icrf, StarSensor>,
    roll_rad: f64,
    pitch_rad: f64,
    c_s_b: &Rotation<Body, StarSensor>,
    c_e_i: &Rotation<Icrf, Ecef>,
) -> AstroFix {
    let d_b = Vector::<Body>::new(down_b(roll_rad, pitch_rad));
    let down_e = (c_e_i * &(c_s_i.inverse() * (c_s_b * &d_b)))
        .into_coords()
        .normalize();
    let (lat_rad, lon_rad) = lat_lon_of_down(&down_e);
    AstroFix {
        lat_rad,
        lon_rad,
        down_e,
    }
}

/// Astro position fix (paper 000 eqs. 5–7, heading-free third row).
///
/// Inputs: `c_s_i`, the star tracker's ICRF → sensor DCM (`v_s = c_s_i v_i`); the IMU's roll and
/// pitch (rad, body relative to the local level); `c_s_b`, body → sensor mounting including the
/// boresight misalignment (`v_s = c_s_b v_b`); `c_e_i`, ICRF → ECEF at the sample's time.
/// Fails on non-finite values, non-rotation matrices or |roll|, |pitch| > 80°.
pub fn astro_fix(
    c_s_i: &Rotation<Icrf, StarSensor>,
    roll_rad: f64,
    pitch_rad: f64,
    c_s_b: &Rotation<Body, StarSensor>,
    c_e_i: &Rotation<Icrf, Ecef>,
) -> Result<AstroFix, AstroError> {
    check_rotation("c_s_i (star-tracker attitude)", c_s_i.dcm())?;
    check_rotation("c_s_b (mounting)", c_s_b.dcm())?;
    check_rotation("c_e_i (ICRF → ECEF)", c_e_i.dcm())?;
    check_tilt(roll_rad, pitch_rad)?;
    Ok(fix_of_chain(c_s_i, roll_rad, pitch_rad, c_s_b, c_e_i))
}

/// The paper's full eq. 5 with heading: the ECEF → NED DCM
/// `c_n_e = R_z(ψ)·R_y(θ)·R_x(γ)·c_s_bᵀ·c_s_i·c_e_iᵀ` (rows: north, east, down in ECEF).
/// Its first two rows depend on the heading; the third is [`astro_fix`]'s `down_e`.
pub fn c_n_e_from_star(
    c_s_i: &Rotation<Icrf, StarSensor>,
    roll_rad: f64,
    pitch_rad: f64,
    heading_rad: f64,
    c_s_b: &Rotation<Body, StarSensor>,
    c_e_i: &Rotation<Icrf, Ecef>,
) -> Rotation<Ecef, Ned> {
    crate::attitude::body_to_ned(roll_rad, pitch_rad, heading_rad)
        * c_s_b.inverse()
        * *c_s_i
        * c_e_i.inverse()
}

/// Great-circle angle (rad) between two directions given as latitude/longitude pairs (rad).
pub fn angular_distance_rad(lat1: f64, lon1: f64, lat2: f64, lon2: f64) -> f64 {
    let a = Vector3::new(lat1.cos() * lon1.cos(), lat1.cos() * lon1.sin(), lat1.sin());
    let b = Vector3::new(lat2.cos() * lon2.cos(), lat2.cos() * lon2.sin(), lat2.sin());
    a.cross(&b).norm().atan2(a.dot(&b))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::attitude::body_to_ned;
    use crate::earth::{WGS84, c_e_n, ned_to_ecef, radii_of_curvature};

    fn nominal_c_s_b() -> Rotation<Body, StarSensor> {
        Rotation::from_dcm_unchecked(Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0)))
    }

    fn rot(axis: Vector3<f64>, angle: f64) -> Rotation<Body, Body> {
        Rotation::from_dcm_unchecked(
            nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle)
                .into_inner(),
        )
    }

    /// Simulated truth: `c_s_i = c_s_b · c_b_n · c_n_e · c_e_i` (the simulator's contract).
    fn c_s_i_true(
        c_s_b: &Rotation<Body, StarSensor>,
        rph: (f64, f64, f64),
        lat: f64,
        lon: f64,
        c_e_i: &Rotation<Icrf, Ecef>,
    ) -> Rotation<Icrf, StarSensor> {
        *c_s_b
            * body_to_ned(rph.0, rph.1, rph.2).inverse()
            * ned_to_ecef(lat, lon).inverse()
            * *c_e_i
    }

    #[test]
    fn round_trip_is_exact_at_several_sites_and_attitudes() {
        let eop = EarthOrientation::default();
        let c_s_b = nominal_c_s_b() * rot(Vector3::new(0.3, -0.5, 0.8), 0.4f64.to_radians());
        let sites = [
            (55.655, 37.534),
            (0.0, 0.0),
            (-33.9, 151.2),
            (78.2, 15.6),
            (-62.0, -58.0),
            (12.0, -179.9),
        ];
        let attitudes = [(0.0, 0.0, 0.0), (2.0, -3.0, 120.0), (-10.0, 5.0, -75.0)];
        for (k, &(lat_d, lon_d)) in sites.iter().enumerate() {
            let t = GpsTime::from_utc(2025, 3, 20, 21, 0, 600.0 * k as f64);
            let c_e_i = celestial::icrf_to_ecef(t, &eop);
            for &(r, p, h) in &attitudes {
                let (lat, lon) = (f64::to_radians(lat_d), f64::to_radians(lon_d));
                let rph = (f64::to_radians(r), f64::to_radians(p), f64::to_radians(h));
                let c_s_i = c_s_i_true(&c_s_b, rph, lat, lon, &c_e_i);
                let fix = astro_fix(&c_s_i, rph.0, rph.1, &c_s_b, &c_e_i).expect("fix");
                // Only float rounding of ~10 matrix products: 1e-12 rad = 6 µm.
                assert!(
                    (fix.lat_rad - lat).abs() < 1e-12,
                    "{lat_d} {lon_d} {r} {p} {h}"
                );
                let dlon = (fix.lon_rad - lon + std::f64::consts::PI)
                    .rem_euclid(std::f64::consts::TAU)
                    - std::f64::consts::PI;
                assert!(dlon.abs() < 1e-12, "{lat_d} {lon_d}: dlon {dlon}");
                // Eq. 5: the full c_n_e with the heading equals the true ECEF → NED DCM.
                let c_n_e = c_n_e_from_star(&c_s_i, rph.0, rph.1, rph.2, &c_s_b, &c_e_i);
                assert!((c_n_e.dcm() - c_e_n(lat, lon).transpose()).abs().max() < 1e-12);
            }
        }
    }

    #[test]
    fn the_fix_does_not_depend_on_heading() {
        let eop = EarthOrientation::default();
        let c_s_b = nominal_c_s_b();
        let t = GpsTime::from_utc(2025, 3, 20, 22, 0, 0.0);
        let c_e_i = celestial::icrf_to_ecef(t, &eop);
        let (lat, lon) = (0.9713, 0.6551);
        let a = astro_fix(
            &c_s_i_true(&c_s_b, (0.01, 0.02, 0.3), lat, lon, &c_e_i),
            0.01,
            0.02,
            &c_s_b,
            &c_e_i,
        )
        .expect("fix");
        let b = astro_fix(
            &c_s_i_true(&c_s_b, (0.01, 0.02, 2.9), lat, lon, &c_e_i),
            0.01,
            0.02,
            &c_s_b,
            &c_e_i,
        )
        .expect("fix");
        assert!((a.lat_rad - b.lat_rad).abs() < 1e-13 && (a.lon_rad - b.lon_rad).abs() < 1e-13);
    }

    /// The paper's rule "1′ of vertical error ≈ 1 nautical mile". Closed form: a tilt error δ of
    /// the vertical about the body axis pointing east (a pitch error with the body x axis
    /// north) rotates the measured normal by δ in the meridian plane, so the geodetic latitude
    /// changes by exactly δ and the fix moves by `M(φ)·δ` (meridian radius of curvature);
    /// about the north axis the normal moves east by δ: `Δλ·cos φ = δ`, a distance `N(φ)·δ`.
    /// 1′ on a sphere of mean radius 6 366.7 km is 1852 m (the definition of the nautical
    /// mile); M and N at 55.655° exceed that radius by 0.2 % and 0.4 % (the bounds below).
    #[test]
    fn one_arcminute_of_tilt_is_one_nautical_mile() {
        let eop = EarthOrientation::default();
        let c_s_b = nominal_c_s_b();
        let t = GpsTime::from_utc(2025, 3, 20, 23, 0, 0.0);
        let c_e_i = celestial::icrf_to_ecef(t, &eop);
        let (lat, lon) = (55.655f64.to_radians(), 37.534f64.to_radians());
        let (m_r, n_r) = radii_of_curvature(&WGS84, lat);
        let delta = (1.0f64 / 60.0).to_radians();
        // Heading 0: body x north, y east. True level; the IMU reports a pitch error +δ.
        let c_s_i = c_s_i_true(&c_s_b, (0.0, 0.0, 0.0), lat, lon, &c_e_i);
        let fix = astro_fix(&c_s_i, 0.0, delta, &c_s_b, &c_e_i).expect("fix");
        let dlat = fix.lat_rad - lat;
        // Reporting a nose-up pitch δ while level means the true down is tilted towards the
        // nose (north) in the IMU's belief, so the fix moves north… by exactly δ.
        assert!(
            (dlat.abs() - delta).abs() < 1e-12,
            "dlat {dlat} vs δ {delta}"
        );
        assert!((fix.lon_rad - lon).abs() < 1e-12);
        let north_m = m_r * dlat.abs();
        assert!((north_m - 1852.0).abs() < 0.003 * 1852.0, "{north_m} m");
        // Roll error δ: the fix moves east/west by δ of arc.
        let fix = astro_fix(&c_s_i, delta, 0.0, &c_s_b, &c_e_i).expect("fix");
        let east_arc = (fix.lon_rad - lon) * lat.cos();
        assert!(
            (east_arc.abs() - delta).abs() < 1e-9,
            "{east_arc} vs {delta}"
        );
        let east_m = n_r * east_arc.abs();
        assert!((east_m - 1852.0).abs() < 0.005 * 1852.0, "{east_m} m");
        // Any direction: the great-circle displacement equals δ.
        for az in [0.3f64, 1.1, 2.5, 4.0] {
            let (r, p) = (delta * az.sin(), delta * az.cos());
            let fix = astro_fix(&c_s_i, r, p, &c_s_b, &c_e_i).expect("fix");
            let d = angular_distance_rad(fix.lat_rad, fix.lon_rad, lat, lon);
            // Small-angle composition of roll then pitch: error O(δ²) ≈ 8e-8 rad relative.
            assert!((d - delta).abs() < 1e-3 * delta, "az {az}: {d} vs {delta}");
        }
    }

    #[test]
    fn bad_inputs_are_rejected_with_their_names() {
        let i = Matrix3::identity();
        let fix = |c_s_i: Matrix3<f64>, roll: f64, pitch: f64, c_s_b: Matrix3<f64>, c_e_i| {
            astro_fix(
                &Rotation::from_dcm_unchecked(c_s_i),
                roll,
                pitch,
                &Rotation::from_dcm_unchecked(c_s_b),
                &Rotation::from_dcm_unchecked(c_e_i),
            )
        };
        let e = fix(i * 2.0, 0.0, 0.0, i, i).unwrap_err();
        assert!(matches!(e, AstroError::NotRotation { what, .. } if what.starts_with("c_s_i")));
        let e = fix(i, 0.0, 0.0, -i, i).unwrap_err();
        assert!(matches!(e, AstroError::NotRotation { what, .. } if what.starts_with("c_s_b")));
        let mut nan = i;
        nan[(1, 1)] = f64::NAN;
        let e = fix(i, 0.0, 0.0, i, nan).unwrap_err();
        assert!(matches!(e, AstroError::NotFinite { what } if what.starts_with("c_e_i")));
        let e = fix(i, f64::INFINITY, 0.0, i, i).unwrap_err();
        assert_eq!(e, AstroError::NotFinite { what: "roll" });
        let e = fix(i, 0.0, 1.5, i, i).unwrap_err();
        assert!(matches!(
            e,
            AstroError::TiltOutOfRange { what: "pitch", .. }
        ));
    }

    /// GMST against ERFA's own test of `eraGmst06` (t_erfa_c.c:
    /// `eraGmst06(2400000.5, 53736.0, 2400000.5, 53736.0) = 1.754174971870091203` rad, i.e.
    /// UT1 = TT = MJD 53736.0). Here UT1 − UTC is chosen so that UT1 = TT exactly.
    #[test]
    fn gmst06_matches_erfa() {
        // TT = MJD 53736.0 = J2000 + 2191.5 d. That instant is 2005-12-31T23:58:54.816 UTC,
        // before the leap second of that night: TT − UTC = 32.184 + 32 s, so UT1 = TT needs
        // DUT1 = 64.184 s.
        let t = GpsTime::from_tt_ns(2191 * 86_400_000_000_000 + 43_200_000_000_000);
        let g = gmst06_rad(t, 64.184);
        // ERFA prints 1.754174971870091203 (more digits than an f64 holds).
        assert!((g - 1.754_174_971_870_091).abs() < 1e-11, "{g}");
        // The reduced models differ from the full one by the precession–nutation (≈ 0.14° of
        // pole offset in 2025 for both; GMST adds the ≈ 0.35° of precession in RA).
        let t = GpsTime::from_utc(2025, 3, 20, 21, 0, 0.0);
        let full = CelestialModel::Full(EarthOrientation::default()).c_e_i(t);
        let era = CelestialModel::EraOnly { dut1_s: 0.0 }.c_e_i(t);
        let gmst = CelestialModel::GmstOnly { dut1_s: 0.0 }.c_e_i(t);
        let a_era = celestial::dcm_angle_between(&full, &era).to_degrees();
        let a_gmst = celestial::dcm_angle_between(&full, &gmst).to_degrees();
        // X of the CIP ≈ 2004.19″·T, T = 0.252 century ⇒ 505″ = 0.140°; nutation adds < 20″.
        assert!((a_era - 0.140).abs() < 0.01, "ERA-only off by {a_era}°");
        // Precession in RA 4612.16″·T = 1162″ = 0.323°, combined with the pole tilt.
        assert!(a_gmst > 0.3 && a_gmst < 0.4, "GMST-only off by {a_gmst}°");
    }
}
