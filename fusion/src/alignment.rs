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
//! `ARW / (Ω cos φ √T)` in heading and `VRW / (g √T)` in tilt over a window of `T` s.
//!
//! **Turntable indexing** (paper 003, [`indexed_align`]): the IMU sits square on a table that
//! turns about its own axis (body z). Averaging at β = 0° and β = 180°, the second position
//! sees `C_b_n(180°) = R_z(π)ᵀ C_b_n(0°)`, i.e. the horizontal body components of every
//! navigation-frame vector reversed, while a sensor bias (fixed in the body) is not. Hence the
//! half-differences `(x₀ − x₁₈₀)/2` of the x and y gyros and accelerometers are the true
//! horizontal Earth-rate and gravity components of the 0° position with the biases cancelled,
//! and the half-sums are the x/y biases. The z components are not modulated and are taken
//! from the half-sum (accelerometer: its bias moves the tilt only at second order) or, when
//! the latitude is known, from the constraint `ω·up = Ω sin φ` (gyro). What remains is noise
//! and the bias's change between the two positions: for windows of T/2 each (T in total) the
//! half-difference of the white noise has variance `ARW²/T` (as unindexed), and a bias random
//! walk of intensity q contributes `var((m₂ − m₁)/2) = q²T/12` (the difference of the two
//! window means of a Wiener process has variance `2·(T/2)/3`), see [`expected_indexed_sigmas`].
//!
//! **Latitude from the IMU alone** ([`imu_latitude`]): the angle between the measured Earth
//! rate and the horizontal plane normal to the measured specific force,
//! `φ = atan2(ω·u, |ω − (ω·u)u|)`, `u = f/|f|` (up: a static IMU's specific force). A bias `b` (NED) moves it by
//! `δφ ≈ (−b_g,D cos φ − b_g,N sin φ)/Ω + b_a,N/g` unindexed; indexed, the north terms cancel.

use crate::FusionError;
use crate::attitude::q_n_b_from_rpy;
use nalgebra::{Matrix3, SMatrix, UnitQuaternion, Vector3};

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

/// Joint 1-σ model of a coarse alignment's attitude error and the sensor biases that caused
/// it: the covariance of `(ψ_e, δb_g, δb_a)` (rad, rad/s, m/s²; ψ in ECEF, biases in body
/// axes, the filter's *truth − estimate* convention of [`crate::ekf`]), for a filter that
/// starts navigating from [`coarse_align`].
///
/// Why the correlation matters: levelling makes the measured specific force vertical, so the
/// tilt error *is* the horizontal accelerometer bias over g, and gyrocompassing makes the
/// measured east rate vanish, so the heading error *is* the east gyro bias over `Ω cos φ`.
/// Initialising the filter with the tilt σ and the bias σ as independent counts the same
/// information twice: on a static stand, where the star tracker sees tilt + boresight and the
/// GNSS velocity sees `g·tilt − b_a`, the filter then believes the boresight tilt to
/// `σ_tilt/√2` although only one of the two is known (paper 000 stand, 250 µg: 0.0101°
/// reported for an error of 0.0143° 1-σ).
///
/// Model (NED, first order). With `C_n_b = (I + [ψ_n×])·Ĉ_n_b`, sensor errors
/// `e_a = b_a + n_a`, `e_g = b_g + n_g` (`n` the window means of the white noise, variances
/// `VRW²/T`, `ARW²/T`) resolved in NED by `C_n_b`:
/// * levelling nulls the horizontal part of `Ĉ_n_b f̃_b ≈ f_n − ψ_n × f_n + e_a,n` with
///   `f_n = (0, 0, −g)`: `ψ_N = e_a,E/g`, `ψ_E = −e_a,N/g` (the tilts of [`expected_errors`]
///   with the sign of *truth − estimate*);
/// * gyrocompassing nulls the east part of `Ĉ_n_b ω̃_b ≈ Ω_n − ψ_n × Ω_n + e_g,n` with
///   `Ω_n = (Ω cos φ, 0, −Ω sin φ)`: `ψ_D Ω cos φ + ψ_N Ω sin φ = e_g,E`, i.e.
///   `ψ_D = e_g,E/(Ω cos φ) − ψ_N tan φ` (the tilt-coupling term [`expected_errors`] leaves
///   out; it is kept here because a 250 µg accelerometer makes it 0.02° at 55.7°).
///
/// So `ψ_n = A_g e_g + A_a e_a` and the joint covariance follows from `P_bg`, `P_ba` (body,
/// as the filter initialises them) and the white-noise means. The floors `min_level_rad` /
/// `min_heading_rad` (unmodelled effects) are added as independent attitude noise where the
/// modelled marginal σ is smaller. The bias random walk within the window (the window mean
/// differs from the end value by `q²T/3`: 2 µg for 20 µg/√h over 120 s) is neglected.
#[allow(clippy::too_many_arguments)]
pub fn alignment_error_covariance(
    c_e_n: &Matrix3<f64>,
    c_n_b: &Matrix3<f64>,
    lat_rad: f64,
    omega_ie_rad_s: f64,
    g: f64,
    p_gyro_bias: &Matrix3<f64>,
    p_accel_bias: &Matrix3<f64>,
    spec: &AlignmentErrorSpec,
    window_s: f64,
    min_level_rad: f64,
    min_heading_rad: f64,
) -> SMatrix<f64, 9, 9> {
    let t = window_s.max(1e-3);
    let e_n = c_n_b.row(0);
    let e_e = c_n_b.row(1);
    let h_rate = omega_ie_rad_s * lat_rad.cos();
    // ψ_n ← body gyro error and body accelerometer error.
    let mut a_g = Matrix3::zeros();
    a_g.set_row(2, &(e_e / h_rate));
    let mut a_a = Matrix3::zeros();
    a_a.set_row(0, &(e_e / g));
    a_a.set_row(1, &(-e_n / g));
    a_a.set_row(2, &(-e_e * (lat_rad.tan() / g)));
    let white_g = spec.arw_rad_sqrt_s.powi(2) / t;
    let white_a = spec.vrw_m_s_sqrt_s.powi(2) / t;
    let mut p_psi = a_g * (p_gyro_bias + Matrix3::identity() * white_g) * a_g.transpose()
        + a_a * (p_accel_bias + Matrix3::identity() * white_a) * a_a.transpose();
    for (k, min) in [(0, min_level_rad), (1, min_level_rad), (2, min_heading_rad)] {
        p_psi[(k, k)] += (min * min - p_psi[(k, k)]).max(0.0);
    }
    let mut out = SMatrix::<f64, 9, 9>::zeros();
    out.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(c_e_n * p_psi * c_e_n.transpose()));
    let cross_g = c_e_n * a_g * p_gyro_bias;
    let cross_a = c_e_n * a_a * p_accel_bias;
    out.fixed_view_mut::<3, 3>(0, 3).copy_from(&cross_g);
    out.fixed_view_mut::<3, 3>(3, 0)
        .copy_from(&cross_g.transpose());
    out.fixed_view_mut::<3, 3>(0, 6).copy_from(&cross_a);
    out.fixed_view_mut::<3, 3>(6, 0)
        .copy_from(&cross_a.transpose());
    out.fixed_view_mut::<3, 3>(3, 3).copy_from(p_gyro_bias);
    out.fixed_view_mut::<3, 3>(6, 6).copy_from(p_accel_bias);
    out
}

/// Latitude (rad) from the IMU alone: the elevation of the mean Earth-rate vector `w_b`
/// (rad/s) above the plane normal to the mean specific force `f_b` (m/s²), body axes.
pub fn imu_latitude(f_b: &Vector3<f64>, w_b: &Vector3<f64>) -> f64 {
    // The specific force of a static IMU is the reaction to gravity: it points up.
    let up = f_b / f_b.norm().max(f64::MIN_POSITIVE);
    let v = w_b.dot(&up);
    let h = (w_b - up * v).norm();
    v.atan2(h)
}

/// Closed-form error (rad) of [`imu_latitude`] from the gyro bias `b_g_n` (rad/s) and the
/// accelerometer bias `b_a_n` (m/s²), both resolved in NED, at latitude `lat_rad`:
/// `δφ ≈ (−b_g,D cos φ − b_g,N sin φ)/Ω + b_a,N/g` (first order). The last term is the
/// measured "up" tilted toward north by `b_a,N/g`, which raises the Earth-rate elevation by
/// the same angle.
pub fn expected_latitude_error(
    b_g_n: &Vector3<f64>,
    b_a_n: &Vector3<f64>,
    lat_rad: f64,
    omega_ie_rad_s: f64,
    g: f64,
) -> f64 {
    (-b_g_n.z * lat_rad.cos() - b_g_n.x * lat_rad.sin()) / omega_ie_rad_s + b_a_n.x / g
}

/// Result of a 0°/180° indexed alignment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IndexedAlignment {
    /// Attitude of the body at turntable angle 0 (the table zero), with its Euler angles.
    pub at_zero: CoarseAlignment,
    /// Half-sums of the x, y gyros: their biases (z not observable by indexing), rad/s.
    pub gyro_bias_xy_rad_s: [f64; 2],
    /// Half-sums of the x, y accelerometers minus the (unmodulated) gravity part: their
    /// biases, m/s².
    pub accel_bias_xy_m_s2: [f64; 2],
    /// Latitude from the indexed IMU data alone (x/y gyro biases cancelled), rad.
    pub imu_latitude_rad: f64,
}

impl IndexedAlignment {
    /// Body → NED DCM at turntable angle `beta_rad` (table axis = body z):
    /// `C_n_b(β) = C_n_b(0)·R_z(β)`.
    pub fn c_n_b_at(&self, beta_rad: f64) -> nalgebra::Matrix3<f64> {
        let (sb, cb) = beta_rad.sin_cos();
        let r_z = nalgebra::Matrix3::new(cb, -sb, 0.0, sb, cb, 0.0, 0.0, 0.0, 1.0);
        self.at_zero.q_n_b.to_rotation_matrix().into_inner() * r_z
    }
}

/// Coarse alignment with 0°/180° turntable indexing (paper 003; see the module comment).
///
/// `acc_0` and `acc_180` hold the increments averaged while the table rested at the mean
/// angles `beta_0_rad` and `beta_180_rad` (from `ImuSample::turntable_angle_rad`); they must
/// differ by 180° ± 1°. With `lat_rad = Some(φ)` (GNSS) the z gyro is replaced by the
/// constraint `ω·up = Ω sin φ`; with `None` the half-sum of the z gyro is used and the
/// latitude is the IMU's own. Returns the attitude of the table zero.
pub fn indexed_align(
    acc_0: &Accumulator,
    acc_180: &Accumulator,
    beta_0_rad: f64,
    beta_180_rad: f64,
    lat_rad: Option<f64>,
    omega_ie_rad_s: f64,
) -> Result<IndexedAlignment, FusionError> {
    let bad = |reason: String| FusionError::InvalidSample {
        sensor: "alignment",
        time_ns: 0,
        reason,
    };
    if acc_0.count() == 0 || acc_180.count() == 0 {
        return Err(bad(
            "indexed alignment needs data at both 0° and 180°".to_string()
        ));
    }
    let d_beta = (beta_180_rad - beta_0_rad).rem_euclid(2.0 * std::f64::consts::PI);
    if !(d_beta.is_finite() && (d_beta - std::f64::consts::PI).abs() < 1f64.to_radians()) {
        return Err(bad(format!(
            "turntable positions {:.2}° and {:.2}° are not 180° apart",
            beta_0_rad.to_degrees(),
            beta_180_rad.to_degrees()
        )));
    }
    let (f0, f1) = (
        acc_0.mean_specific_force_m_s2(),
        acc_180.mean_specific_force_m_s2(),
    );
    let (w0, w1) = (acc_0.mean_rate_rad_s(), acc_180.mean_rate_rad_s());
    let f = Vector3::new(
        0.5 * (f0.x - f1.x),
        0.5 * (f0.y - f1.y),
        0.5 * (f0.z + f1.z),
    );
    let mut w = Vector3::new(
        0.5 * (w0.x - w1.x),
        0.5 * (w0.y - w1.y),
        0.5 * (w0.z + w1.z),
    );
    let imu_lat = imu_latitude(&f, &w);
    let lat_for_checks = lat_rad.unwrap_or(imu_lat);
    if let Some(lat) = lat_rad {
        let up = f / f.norm().max(f64::MIN_POSITIVE);
        if up.z.abs() > 0.5 {
            w.z = (omega_ie_rad_s * lat.sin() - w.x * up.x - w.y * up.y) / up.z;
        }
    }
    let at_zero = coarse_align(&f, &w, lat_for_checks, omega_ie_rad_s)?;
    Ok(IndexedAlignment {
        at_zero,
        gyro_bias_xy_rad_s: [0.5 * (w0.x + w1.x), 0.5 * (w0.y + w1.y)],
        accel_bias_xy_m_s2: [0.5 * (f0.x + f1.x), 0.5 * (f0.y + f1.y)],
        imu_latitude_rad: imu_lat,
    })
}

/// 1-σ accuracy `(level, heading)`, rad, of an indexed alignment over `t_total_s` seconds
/// (half at each position): white noise `ARW²/T`, `VRW²/T` and bias random walks of
/// intensity `gyro_bias_rw_rad_s_per_rt_s`, `accel_bias_rw_m_s2_per_rt_s` (`q²T/12`, see the
/// module comment). The constant biases cancel.
pub fn expected_indexed_sigmas(
    spec: &AlignmentErrorSpec,
    gyro_bias_rw_rad_s_per_rt_s: f64,
    accel_bias_rw_m_s2_per_rt_s: f64,
    t_total_s: f64,
    lat_rad: f64,
    omega_ie_rad_s: f64,
    g: f64,
) -> (f64, f64) {
    let t = t_total_s.max(1e-3);
    let level = (spec.vrw_m_s_sqrt_s.powi(2) / t + accel_bias_rw_m_s2_per_rt_s.powi(2) * t / 12.0)
        .sqrt()
        / g;
    let heading =
        (spec.arw_rad_sqrt_s.powi(2) / t + gyro_bias_rw_rad_s_per_rt_s.powi(2) * t / 12.0).sqrt()
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

    /// The increments of a static IMU with attitude `c_b_e` (ECEF → body) under gravity `g_e`
    /// (ECEF, m/s²) over `dt` s: Δθ = C_b_e ω_ie dt + b_g dt, Δv = −C_b_e g dt + b_a dt.
    struct StaticIncrements {
        c_b_e: Matrix3<f64>,
        g_e: Vector3<f64>,
        b_g: Vector3<f64>,
        b_a: Vector3<f64>,
        dt: f64,
    }

    impl StaticIncrements {
        /// Add `steps` increments to `acc`, with navigation-grade white noise (ARW 0.002°/√h,
        /// VRW 20 µg/√Hz) drawn from `rng` when one is given.
        fn accumulate(
            &self,
            acc: &mut Accumulator,
            steps: usize,
            mut rng: Option<&mut rand_chacha::ChaCha8Rng>,
        ) {
            let dt = self.dt;
            let arw = 0.002f64.to_radians() / 60.0;
            let vrw = 20e-6 * 9.80665;
            let n_g = Normal::new(0.0, arw * dt.sqrt()).unwrap();
            let n_a = Normal::new(0.0, vrw * dt.sqrt()).unwrap();
            for _ in 0..steps {
                let mut dth = (self.c_b_e * WGS84.omega_ie_e() + self.b_g) * dt;
                let mut dv = (-(self.c_b_e * self.g_e) + self.b_a) * dt;
                if let Some(rng) = rng.as_deref_mut() {
                    for i in 0..3 {
                        dth[i] += n_g.sample(rng);
                        dv[i] += n_a.sample(rng);
                    }
                }
                acc.add(&dth, &dv, dt);
            }
        }
    }

    /// Static increments at a site from fusion::earth ([`StaticIncrements`], with noise when
    /// `noisy`), averaged.
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
        let steps = (seconds / dt).round() as usize;
        let inc = StaticIncrements {
            c_b_e,
            g_e,
            b_g,
            b_a,
            dt,
        };
        inc.accumulate(&mut acc, steps, noisy.then_some(&mut rng));
        assert!((acc.duration_s() - seconds).abs() < 1e-6);
        (acc.mean_specific_force_m_s2(), acc.mean_rate_rad_s(), c_n_b)
    }

    fn wrap(a: f64) -> f64 {
        (a + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI
    }

    /// Monte Carlo of the joint alignment-error model: draw biases and window-mean noise,
    /// align, and compare the error vector `(ψ_e, b_g, b_a)` with
    /// [`alignment_error_covariance`]. NEES over N trials is χ²(9N): accepted 9N ± 4√(18N).
    /// The tilt–bias correlation must be ≈ ±1 (the point of the model): the sample
    /// correlation of ψ_N with b_a,E over N trials has standard error < (1 − ρ²)/√N.
    #[test]
    fn joint_alignment_covariance_matches_monte_carlo() {
        let lat = 55.655f64.to_radians();
        // The model's static IMU: specific force straight up along the ellipsoid normal (the
        // J2 gravity of `fusion::earth` deviates from it by a few arcsec, a constant tilt the
        // white-noise part of this model — 0.3 mdeg — would resolve), Earth rate in NED.
        let c_e_n = c_e_n(lat, 0.6);
        let g = 9.815;
        let c_n_b = q_n_b_from_rpy(0.01, -0.02, 0.52)
            .to_rotation_matrix()
            .into_inner();
        let f_b_true = c_n_b.transpose() * Vector3::new(0.0, 0.0, -g);
        let w = WGS84.omega_ie_rad_s;
        let w_b_true = c_n_b.transpose() * Vector3::new(w * lat.cos(), 0.0, -w * lat.sin());
        // The astro-stand accelerometers (250 µg) and a navigation-grade gyro, 120 s window.
        let spec = AlignmentErrorSpec {
            gyro_bias_rad_s: 0.01f64.to_radians() / 3600.0,
            accel_bias_m_s2: 250e-6 * 9.80665,
            arw_rad_sqrt_s: 0.002f64.to_radians() / 60.0,
            vrw_m_s_sqrt_s: 50e-6 * 9.80665,
        };
        let t = 120.0;
        let p_bg = Matrix3::identity() * spec.gyro_bias_rad_s.powi(2);
        let p_ba = Matrix3::identity() * spec.accel_bias_m_s2.powi(2);
        let p = alignment_error_covariance(
            &c_e_n,
            &c_n_b,
            lat,
            WGS84.omega_ie_rad_s,
            g,
            &p_bg,
            &p_ba,
            &spec,
            t,
            0.0,
            0.0,
        );
        let p_inv = p.try_inverse().expect("positive definite");
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let unit = Normal::new(0.0, 1.0).unwrap();
        let mut draw = |s: f64| {
            Vector3::new(
                unit.sample(&mut rng),
                unit.sample(&mut rng),
                unit.sample(&mut rng),
            ) * s
        };
        let n = 3000;
        let mut nees = 0.0;
        let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
        for _ in 0..n {
            let b_g = draw(spec.gyro_bias_rad_s);
            let b_a = draw(spec.accel_bias_m_s2);
            let f = f_b_true + b_a + draw(spec.vrw_m_s_sqrt_s / t.sqrt());
            let w = w_b_true + b_g + draw(spec.arw_rad_sqrt_s / t.sqrt());
            let a = coarse_align(&f, &w, lat, WGS84.omega_ie_rad_s).unwrap();
            let c_e_b_est = c_e_n * a.q_n_b.to_rotation_matrix().into_inner();
            // ψ_e with C_e_b = (I + [ψ×]) Ĉ_e_b.
            let m = (c_e_n * c_n_b) * c_e_b_est.transpose();
            let psi_e = Vector3::new(
                m[(2, 1)] - m[(1, 2)],
                m[(0, 2)] - m[(2, 0)],
                m[(1, 0)] - m[(0, 1)],
            ) * 0.5;
            let mut x = SMatrix::<f64, 9, 1>::zeros();
            x.fixed_rows_mut::<3>(0).copy_from(&psi_e);
            x.fixed_rows_mut::<3>(3).copy_from(&b_g);
            x.fixed_rows_mut::<3>(6).copy_from(&b_a);
            nees += (x.transpose() * p_inv * x)[(0, 0)];
            let psi_n = c_e_n.transpose() * psi_e;
            let b_ae = (c_n_b * b_a).y;
            sxy += psi_n.x * b_ae;
            sxx += psi_n.x * psi_n.x;
            syy += b_ae * b_ae;
        }
        let nf = n as f64;
        assert!(
            (nees - 9.0 * nf).abs() < 4.0 * (18.0 * nf).sqrt(),
            "NEES {} vs {}",
            nees / nf,
            9.0
        );
        let rho = sxy / (sxx * syy).sqrt();
        // Predicted ρ = σ_b/√(σ_b² + VRW²/T) = 0.9999 here; the independent model says 0.
        eprintln!(
            "joint alignment NEES/9 {:.3}, ρ(ψ_N, b_a,E) {rho:.5}",
            nees / nf / 9.0
        );
        assert!(rho > 0.99, "tilt–bias correlation {rho}");
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
    /// Increments at the two table positions of a tilted table (C_n_b(β) = C0·R_z(β)) with
    /// body-fixed biases.
    fn indexed_means(
        lat: f64,
        c0: &Matrix3<f64>,
        b_g: Vector3<f64>,
        b_a: Vector3<f64>,
        seconds_each: f64,
        noisy: bool,
    ) -> (Accumulator, Accumulator) {
        let site = Geodetic {
            lat_rad: lat,
            lon_rad: 0.6,
            height_m: 150.0,
        };
        let r_e = geodetic_to_ecef(&WGS84, &site);
        let cen = c_e_n(site.lat_rad, site.lon_rad);
        let g_e = gravity_ecef(&WGS84, GravityModel::J2, &r_e);
        let dt: f64 = 0.005;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut out = [Accumulator::default(), Accumulator::default()];
        for (k, acc) in out.iter_mut().enumerate() {
            let beta = k as f64 * std::f64::consts::PI;
            let (sb, cb) = beta.sin_cos();
            let r_z = Matrix3::new(cb, -sb, 0.0, sb, cb, 0.0, 0.0, 0.0, 1.0);
            let c_b_e = (cen * c0 * r_z).transpose();
            let inc = StaticIncrements {
                c_b_e,
                g_e,
                b_g,
                b_a,
                dt,
            };
            let steps = (seconds_each / dt).round() as usize;
            inc.accumulate(acc, steps, noisy.then_some(&mut rng));
        }
        (out[0], out[1])
    }

    #[test]
    fn indexing_cancels_horizontal_biases() {
        let lat = 55.655f64.to_radians();
        let c0 = q_n_b_from_rpy(0.003, -0.002, 0.7)
            .to_rotation_matrix()
            .into_inner();
        let bg = 0.01f64.to_radians() / 3600.0;
        let b_g = Vector3::new(bg, -bg, 0.5 * bg);
        let b_a = Vector3::new(50e-6 * 9.80665, -40e-6 * 9.80665, 30e-6 * 9.80665);
        // Noise-free: the biases cancel exactly up to the z-bias × tilt coupling
        // (b_a,z·tilt/g ≈ 1.5e-9 rad) and the z gyro is replaced by the latitude constraint.
        let (a0, a1) = indexed_means(lat, &c0, b_g, b_a, 60.0, false);
        let ia = indexed_align(
            &a0,
            &a1,
            0.0,
            std::f64::consts::PI,
            Some(lat),
            WGS84.omega_ie_rad_s,
        )
        .unwrap();
        let c_est = ia.at_zero.q_n_b.to_rotation_matrix().into_inner();
        let e_m = c_est * c0.transpose();
        let e = Vector3::new(e_m[(2, 1)], e_m[(0, 2)], e_m[(1, 0)]);
        // Residual: the deflection of the J2 gravity vector from the ellipsoid normal used for
        // the truth's NED frame (≈ 1 arcsec) tilts both alignments alike; and the z-bias ×
        // tilt coupling (≈ 1.5e-9 rad). Heading inherits tilt·tan φ.
        assert!(e.norm() < 2e-5, "indexed attitude error {e}");
        assert!((ia.gyro_bias_xy_rad_s[0] - b_g.x).abs() < 1e-12);
        assert!((ia.gyro_bias_xy_rad_s[1] - b_g.y).abs() < 1e-12);
        // The unindexed alignment at 0° shows the closed-form heading error instead.
        let ua = coarse_align(
            &a0.mean_specific_force_m_s2(),
            &a0.mean_rate_rad_s(),
            lat,
            WGS84.omega_ie_rad_s,
        )
        .unwrap();
        let exp = expected_errors(&(c0 * b_g), &(c0 * b_a), lat, WGS84.omega_ie_rad_s, 9.81);
        let dh = wrap(ua.heading_rad - 0.7);
        assert!(dh.abs() > 20.0 * e.norm(), "unindexed {dh:e}, indexed {e}");
        assert!(
            (dh - exp[2]).abs() < 0.05 * exp[2].abs() + 3e-5,
            "{dh} vs {}",
            exp[2]
        );
        // Latitude from the IMU alone: indexed error set by the z bias only.
        let lat_err = ia.imu_latitude_rad - lat;
        let b_n = c0 * b_g;
        let exp_idx = -b_n.z * lat.cos() / WGS84.omega_ie_rad_s;
        assert!(
            (lat_err - exp_idx).abs() < 0.05 * exp_idx.abs() + 1e-5,
            "{lat_err} vs {exp_idx}"
        );
        let lat_un = imu_latitude(&a0.mean_specific_force_m_s2(), &a0.mean_rate_rad_s()) - lat;
        let exp_un = expected_latitude_error(&b_n, &(c0 * b_a), lat, WGS84.omega_ie_rad_s, 9.81);
        assert!(
            (lat_un - exp_un).abs() < 0.05 * exp_un.abs() + 1e-5,
            "{lat_un} vs {exp_un}"
        );
    }

    /// With white noise only, the indexed heading error is inside 4σ of
    /// `ARW/(Ω cos φ √T)` (T = both positions), and the wrong table angles are rejected.
    #[test]
    fn indexed_noise_matches_bound_and_angles_are_checked() {
        let lat = 30f64.to_radians();
        let c0 = q_n_b_from_rpy(0.0, 0.0, -1.3)
            .to_rotation_matrix()
            .into_inner();
        let bg = 0.01f64.to_radians() / 3600.0;
        let (a0, a1) = indexed_means(lat, &c0, Vector3::repeat(bg), Vector3::zeros(), 150.0, true);
        let ia = indexed_align(
            &a0,
            &a1,
            0.0,
            std::f64::consts::PI,
            Some(lat),
            WGS84.omega_ie_rad_s,
        )
        .unwrap();
        let spec = AlignmentErrorSpec {
            gyro_bias_rad_s: 0.0,
            accel_bias_m_s2: 0.0,
            arw_rad_sqrt_s: 0.002f64.to_radians() / 60.0,
            vrw_m_s_sqrt_s: 20e-6 * 9.80665,
        };
        let (_, s_h) =
            expected_indexed_sigmas(&spec, 0.0, 0.0, 300.0, lat, WGS84.omega_ie_rad_s, 9.81);
        let dh = wrap(ia.at_zero.heading_rad + 1.3);
        assert!(dh.abs() < 4.0 * s_h, "{dh} vs σ {s_h}");
        assert!(indexed_align(&a0, &a1, 0.0, 1.0, Some(lat), WGS84.omega_ie_rad_s).is_err());
        assert!(
            indexed_align(
                &a0,
                &Accumulator::default(),
                0.0,
                std::f64::consts::PI,
                None,
                WGS84.omega_ie_rad_s
            )
            .is_err()
        );
    }
}
