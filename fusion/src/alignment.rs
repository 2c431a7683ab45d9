//! Static coarse alignment (paper 003, "alignment mode"): levelling from the mean specific
//! force and gyrocompassing from the horizontal component of the measured Earth rate.
//!
//! Over the alignment window the IMU increments are averaged (an [`Accumulator`]): a static
//! IMU measures `f_b = −C_b_n g_n` (specific force, body, pointing up) and
//! `ω_b = C_b_n ω_ie^n` with `ω_ie^n = (Ω cos φ, 0, −Ω sin φ)` in NED.
//!
//! * Levelling (Groves 2nd ed. eq. 5.101; body x forward, y right, z down):
//!   `roll = atan2(−f_y, −f_z)`, `pitch = atan2(f_x, √(f_y² + f_z²))`.
//! * Gyrocompassing: rotate `ω_b` into the levelled frame `l` (body with roll and pitch
//!   removed, heading still unknown), where `ω_l = (Ω cos φ cos ψ, −Ω cos φ sin ψ, ·)`, so
//!   `ψ = atan2(−ω_l,y, ω_l,x)` (Groves eq. 5.104). The horizontal Earth rate `Ω cos φ` is the
//!   signal; latitude φ (from the first GNSS fix or the configured position) is used to check
//!   it and to predict the accuracy.
//!
//! Closed-form errors (Titterton & Weston §10.3; Groves §5.6.2): with an east gyro bias
//! `b_g,E` (rad/s) and north/east accelerometer biases `b_a,N`, `b_a,E` (m/s²), all resolved
//! in NED, the heading error is `δψ ≈ −b_g,E / (Ω cos φ)` and the tilts about north and east
//! are `−b_a,E/g` and `b_a,N/g` (see [`expected_errors`]); white noise adds
//! `ARW / (Ω cos φ √T)` in heading and `VRW / (g √T)` in tilt over a window of `T` s. Turntable indexing (0°/180°,
//! paper 003) is not implemented yet.

use crate::FusionError;
use crate::attitude::q_n_b_from_rpy;
use nalgebra::{UnitQuaternion, Vector3};

/// Running sums of IMU increments over the alignment window. Allocates nothing.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Accumulator {
    sum_delta_angle_rad: Vector3<f64>,
    sum_delta_velocity_m_s: Vector3<f64>,
    sum_dt_s: f64,
    n: u64,
}

impl Accumulator {
    /// Add one increment (body axes): delta-angle, rad; delta-velocity, m/s; interval, s.
    pub fn add(
        &mut self,
        delta_angle_rad: &Vector3<f64>,
        delta_velocity_m_s: &Vector3<f64>,
        dt_s: f64,
    ) {
        self.sum_delta_angle_rad += delta_angle_rad;
        self.sum_delta_velocity_m_s += delta_velocity_m_s;
        self.sum_dt_s += dt_s;
        self.n += 1;
    }
    /// Forget everything.
    pub fn reset(&mut self) {
        *self = Self::default();
    }
    /// Accumulated time, s.
    pub fn duration_s(&self) -> f64 {
        self.sum_dt_s
    }
    /// Number of increments.
    pub fn count(&self) -> u64 {
        self.n
    }
    /// Mean angular rate, body, rad/s.
    pub fn mean_rate_rad_s(&self) -> Vector3<f64> {
        self.sum_delta_angle_rad / self.sum_dt_s.max(f64::MIN_POSITIVE)
    }
    /// Mean specific force, body, m/s².
    pub fn mean_specific_force_m_s2(&self) -> Vector3<f64> {
        self.sum_delta_velocity_m_s / self.sum_dt_s.max(f64::MIN_POSITIVE)
    }
}

/// Result of the coarse alignment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoarseAlignment {
    /// Roll, rad.
    pub roll_rad: f64,
    /// Pitch, rad.
    pub pitch_rad: f64,
    /// Heading (from true north, positive east), rad, in (−π, π].
    pub heading_rad: f64,
    /// Attitude body → NED.
    pub q_n_b: UnitQuaternion<f64>,
}

/// Roll and pitch (rad) from the mean specific force `f_b` (body, m/s²) of a static IMU.
pub fn level(f_b: &Vector3<f64>) -> (f64, f64) {
    let roll = (-f_b.y).atan2(-f_b.z);
    let pitch = f_b.x.atan2((f_b.y * f_b.y + f_b.z * f_b.z).sqrt());
    (roll, pitch)
}

/// Heading (rad) from the mean angular rate `w_b` (body, rad/s) given roll and pitch.
pub fn gyrocompass(w_b: &Vector3<f64>, roll_rad: f64, pitch_rad: f64) -> f64 {
    // Levelled frame: C_l_b = R_y(pitch)·R_x(roll) applied to body vectors.
    let c_l_b = q_n_b_from_rpy(roll_rad, pitch_rad, 0.0);
    let w_l = c_l_b * w_b;
    (-w_l.y).atan2(w_l.x)
}

/// Static coarse alignment from the mean specific force `f_b` (m/s²) and angular rate `w_b`
/// (rad/s), body axes, at geodetic latitude `lat_rad`, with Earth rate `omega_ie_rad_s`.
///
/// Fails when the data cannot be from a static IMU (specific force far from 1 g, rate far
/// from the Earth rate), or too close to a pole for gyrocompassing (|φ| > 85°).
pub fn coarse_align(
    f_b: &Vector3<f64>,
    w_b: &Vector3<f64>,
    lat_rad: f64,
    omega_ie_rad_s: f64,
) -> Result<CoarseAlignment, FusionError> {
    let bad = |reason: String| FusionError::InvalidSample {
        sensor: "alignment",
        time_ns: 0,
        reason,
    };
    let g = f_b.norm();
    if !(g.is_finite() && (9.6..10.1).contains(&g)) {
        return Err(bad(format!(
            "mean specific force {g:.4} m/s² is not 1 g: not static"
        )));
    }
    let w = w_b.norm();
    if !(w.is_finite() && w < 5.0 * omega_ie_rad_s) {
        return Err(bad(format!(
            "mean rate {w:.3e} rad/s is not the Earth rate: not static"
        )));
    }
    if !(lat_rad.is_finite() && lat_rad.abs() < 85f64.to_radians()) {
        return Err(bad(format!(
            "latitude {:.3}° too close to a pole for gyrocompassing",
            lat_rad.to_degrees()
        )));
    }
    let (roll, pitch) = level(f_b);
    let heading = gyrocompass(w_b, roll, pitch);
    Ok(CoarseAlignment {
        roll_rad: roll,
        pitch_rad: pitch,
        heading_rad: heading,
        q_n_b: q_n_b_from_rpy(roll, pitch, heading),
    })
}

/// Closed-form alignment errors `(tilt about north, tilt about east, heading)`, rad, as
/// *estimate − truth* small angles in NED, from sensor biases resolved in NED (gyro
/// `b_g_n`, rad/s; accelerometer `b_a_n`, m/s²) at latitude `lat_rad`, gravity `g`.
///
/// `δψ ≈ −b_g,E / (Ω cos φ)` is the classic gyrocompassing limit; the tilts are the
/// accelerometer biases over g (`−b_a,E/g` about north, `b_a,N/g` about east). The heading
/// formula ignores the coupling of tilt into heading through the vertical Earth rate
/// (`≈ tilt_N·tan φ`), which is two orders of magnitude smaller for a navigation-grade IMU.
pub fn expected_errors(
    b_g_n: &Vector3<f64>,
    b_a_n: &Vector3<f64>,
    lat_rad: f64,
    omega_ie_rad_s: f64,
    g: f64,
) -> Vector3<f64> {
    Vector3::new(
        -b_a_n.y / g,
        b_a_n.x / g,
        -b_g_n.y / (omega_ie_rad_s * lat_rad.cos()),
    )
}

/// IMU error figures that limit a static alignment (1-σ, SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AlignmentErrorSpec {
    /// Gyro bias σ, rad/s.
    pub gyro_bias_rad_s: f64,
    /// Accelerometer bias σ, m/s².
    pub accel_bias_m_s2: f64,
    /// Angle random walk, rad/√s.
    pub arw_rad_sqrt_s: f64,
    /// Velocity random walk, m/s/√s.
    pub vrw_m_s_sqrt_s: f64,
}

/// 1-σ coarse-alignment accuracy `(level, heading)`, rad, of an IMU with errors `spec` over a
/// window of `t_s` seconds at latitude `lat_rad` (Earth rate `omega_ie_rad_s`, gravity `g`).
pub fn expected_sigmas(
    spec: &AlignmentErrorSpec,
    t_s: f64,
    lat_rad: f64,
    omega_ie_rad_s: f64,
    g: f64,
) -> (f64, f64) {
    let t = t_s.max(1e-3);
    let level = (spec.accel_bias_m_s2.powi(2) + spec.vrw_m_s_sqrt_s.powi(2) / t).sqrt() / g;
    let heading = (spec.gyro_bias_rad_s.powi(2) + spec.arw_rad_sqrt_s.powi(2) / t).sqrt()
        / (omega_ie_rad_s * lat_rad.cos());
    (level, heading)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::earth::{Geodetic, GravityModel, WGS84, c_e_n, geodetic_to_ecef, gravity_ecef};
    use nalgebra::Matrix3;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// Static increments at a site from fusion::earth: Δθ = C_b_e ω_ie dt + b_g dt + noise,
    /// Δv = −C_b_e g dt + b_a dt + noise.
    fn static_means(
        lat: f64,
        rpy: (f64, f64, f64),
        b_g: Vector3<f64>,
        b_a: Vector3<f64>,
        seconds: f64,
        noisy: bool,
        model: GravityModel,
    ) -> (Vector3<f64>, Vector3<f64>, Matrix3<f64>) {
        let site = Geodetic {
            lat_rad: lat,
            lon_rad: 0.6,
            height_m: 150.0,
        };
        let r_e = geodetic_to_ecef(&WGS84, &site);
        let c_e_n = c_e_n(site.lat_rad, site.lon_rad);
        let c_n_b = q_n_b_from_rpy(rpy.0, rpy.1, rpy.2)
            .to_rotation_matrix()
            .into_inner();
        let c_b_e = (c_e_n * c_n_b).transpose();
        let g_e = gravity_ecef(&WGS84, model, &r_e);
        let dt: f64 = 0.005;
        let mut acc = Accumulator::default();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        // Navigation grade: ARW 0.002°/√h, VRW 20 µg/√Hz.
        let arw = 0.002f64.to_radians() / 60.0;
        let vrw = 20e-6 * 9.80665;
        let n_g = Normal::new(0.0, arw * dt.sqrt()).unwrap();
        let n_a = Normal::new(0.0, vrw * dt.sqrt()).unwrap();
        let steps = (seconds / dt).round() as usize;
        for _ in 0..steps {
            let mut dth = (c_b_e * WGS84.omega_ie_e() + b_g) * dt;
            let mut dv = (-(c_b_e * g_e) + b_a) * dt;
            if noisy {
                for i in 0..3 {
                    dth[i] += n_g.sample(&mut rng);
                    dv[i] += n_a.sample(&mut rng);
                }
            }
            acc.add(&dth, &dv, dt);
        }
        assert!((acc.duration_s() - seconds).abs() < 1e-6);
        (acc.mean_specific_force_m_s2(), acc.mean_rate_rad_s(), c_n_b)
    }

    fn wrap(a: f64) -> f64 {
        (a + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI
    }

    #[test]
    fn noise_free_alignment_is_exact() {
        let lat = 55.655f64.to_radians();
        for &(r, p, y) in &[
            (0.0, 0.0, 0.0),
            (0.02, -0.03, 1.2),
            (-0.1, 0.05, -2.5),
            (0.0, 0.0, 3.1),
        ] {
            let (f, w, _) = static_means(
                lat,
                (r, p, y),
                Vector3::zeros(),
                Vector3::zeros(),
                10.0,
                false,
                GravityModel::Normal,
            );
            let a = coarse_align(&f, &w, lat, WGS84.omega_ie_rad_s).unwrap();
            assert!((a.roll_rad - r).abs() < 1e-9, "roll {} vs {r}", a.roll_rad);
            assert!((a.pitch_rad - p).abs() < 1e-9);
            assert!(
                wrap(a.heading_rad - y).abs() < 1e-9,
                "heading {} vs {y}",
                a.heading_rad
            );
        }
    }

    #[test]
    fn gyro_bias_gives_the_closed_form_heading_error() {
        let lat = 55.655f64.to_radians();
        let heading = 0.7;
        // Gyro bias 0.01°/h on every body axis, accelerometer bias 50 µg on x.
        let bg_mag = 0.01f64.to_radians() / 3600.0;
        let b_g = Vector3::new(bg_mag, bg_mag, bg_mag);
        let b_a = Vector3::new(50e-6 * 9.80665, 0.0, 0.0);
        let (f, w, c_n_b) = static_means(
            lat,
            (0.01, -0.02, heading),
            b_g,
            b_a,
            120.0,
            true,
            GravityModel::J2,
        );
        let a = coarse_align(&f, &w, lat, WGS84.omega_ie_rad_s).unwrap();
        let exp = expected_errors(
            &(c_n_b * b_g),
            &(c_n_b * b_a),
            lat,
            WGS84.omega_ie_rad_s,
            9.81,
        );
        let spec = AlignmentErrorSpec {
            gyro_bias_rad_s: 0.0,
            accel_bias_m_s2: 0.0,
            arw_rad_sqrt_s: 0.002f64.to_radians() / 60.0,
            vrw_m_s_sqrt_s: 20e-6 * 9.80665,
        };
        let (s_level, s_head) = expected_sigmas(&spec, 120.0, lat, WGS84.omega_ie_rad_s, 9.81);
        // Attitude error as a small rotation in NED: C_n_b_est · C_n_b_trueᵀ = I + [e×].
        let c_est = a.q_n_b.to_rotation_matrix().into_inner();
        let e_m = c_est * c_n_b.transpose();
        let e = Vector3::new(e_m[(2, 1)], e_m[(0, 2)], e_m[(1, 0)]);
        let dh = wrap(a.heading_rad - heading);
        assert!(
            exp[2].abs() > 5e-4,
            "bias must produce a visible heading error"
        );
        // Within the closed form plus 4σ of the white-noise part plus the tan φ coupling.
        let tol_h = 4.0 * s_head + 0.05 * exp[2].abs() + 3e-5;
        assert!(
            (dh - exp[2]).abs() < tol_h,
            "heading error {dh:e} vs closed form {:e} (tol {tol_h:e})",
            exp[2]
        );
        assert!((e[2] - exp[2]).abs() < tol_h);
        let tol_l = 4.0 * s_level + 1e-6;
        assert!(
            (e[0] - exp[0]).abs() < tol_l,
            "tilt N {:e} vs {:e}",
            e[0],
            exp[0]
        );
        assert!(
            (e[1] - exp[1]).abs() < tol_l,
            "tilt E {:e} vs {:e}",
            e[1],
            exp[1]
        );
    }

    #[test]
    fn rejects_moving_or_polar_data() {
        let f = Vector3::new(0.0, 0.0, -9.81);
        let w = Vector3::new(5e-5, 0.0, -5e-5);
        assert!(coarse_align(&(f * 1.2), &w, 0.9, 7.29e-5).is_err());
        assert!(coarse_align(&f, &(w * 100.0), 0.9, 7.29e-5).is_err());
        assert!(coarse_align(&f, &w, 1.55, 7.29e-5).is_err());
        assert!(coarse_align(&f, &w, 0.9, 7.29e-5).is_ok());
    }
}
