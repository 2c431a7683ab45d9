//! Rotation helpers: skew matrices, rotation vectors, Euler angles (roll, pitch, heading as in
//! paper 002: z-y-x), quaternion wire format (Hamilton, scalar first).
//!
//! Euler convention: the body → NED DCM is `c_n_b = R_z(ψ) · R_y(θ) · R_x(γ)` (heading ψ,
//! pitch θ, roll γ; body x forward, y right, z down), so that
//! `ψ = atan2(C21, C11)`, `θ = −asin(C31)`, `γ = atan2(C32, C33)` (1-based indices).
//! Paper 002 reads the same angles from a DCM whose rows are the geographic axes (east, north,
//! up) and whose columns are the body axes (right, forward, up); that matrix is
//! `P · c_n_b · Pᵀ` with the axis permutation `P = [[0,1,0],[1,0,0],[0,0,−1]]` (NED → ENU and
//! FRD → RFU alike). Its heading `ψ = atan(C12/C22)` and pitch `θ = asin(C32)` hold as printed;
//! its roll, printed `γ = atan(C13/C33)`, equals the true roll only at zero heading and zero
//! pitch: in that layout roll is `γ = atan(−C31/C33)` (a transposed index in the extracted
//! text; the tests prove both statements, and Sextant uses the correct one).
//!
//! Rotation vectors: `q(φ) = [cos(|φ|/2), sin(|φ|/2) φ/|φ|]`, evaluated by its Taylor series
//! near zero so that small rotations (one IMU increment) lose no precision.

use crate::frames::{Body, Ned, Rotation};
use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};

/// Below this angle squared (rad², i.e. |φ| < 1e-3 rad) [`quat_from_rotation_vector`] uses the
/// Taylor series; the first neglected term is |φ|⁶/46080 < 3e-23.
const SMALL_ANGLE2_RAD2: f64 = 1e-6;

/// Skew-symmetric (cross-product) matrix of `v`: `skew(v)·w = v × w`.
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Roll, pitch, heading (rad) of a body → NED rotation, as `[roll, pitch, heading]`.
///
/// Roll and heading in (−π, π], pitch in [−π/2, π/2].
pub fn rpy_from_q_n_b(q_n_b: &UnitQuaternion<f64>) -> Vector3<f64> {
    let (r, p, y) = q_n_b.euler_angles();
    Vector3::new(r, p, y)
}

/// Body → NED rotation from roll, pitch, heading (rad): `R_z(heading) R_y(pitch) R_x(roll)`.
pub fn q_n_b_from_rpy(roll: f64, pitch: f64, heading: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(roll, pitch, heading)
}

/// The rotation body → NED from roll, pitch, heading (rad), frame-typed ([`c_n_b_from_rpy`]'s
/// matrix).
pub fn body_to_ned(roll: f64, pitch: f64, heading: f64) -> Rotation<Body, Ned> {
    Rotation::from_dcm_unchecked(c_n_b_from_rpy(roll, pitch, heading))
}

/// Body → NED DCM `c_n_b = R_z(heading) R_y(pitch) R_x(roll)` from roll, pitch, heading (rad).
pub fn c_n_b_from_rpy(roll: f64, pitch: f64, heading: f64) -> Matrix3<f64> {
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let (sh, ch) = heading.sin_cos();
    Matrix3::new(
        ch * cp,
        ch * sp * sr - sh * cr,
        ch * sp * cr + sh * sr,
        sh * cp,
        sh * sp * sr + ch * cr,
        sh * sp * cr - ch * sr,
        -sp,
        cp * sr,
        cp * cr,
    )
}

/// Roll, pitch, heading (rad) as `[roll, pitch, heading]` from a body → NED DCM:
/// `γ = atan2(C32, C33)`, `θ = −asin(C31)`, `ψ = atan2(C21, C11)` (1-based indices).
pub fn rpy_from_c_n_b(c_n_b: &Matrix3<f64>) -> Vector3<f64> {
    let roll = c_n_b[(2, 1)].atan2(c_n_b[(2, 2)]);
    let pitch = -c_n_b[(2, 0)].clamp(-1.0, 1.0).asin();
    let heading = c_n_b[(1, 0)].atan2(c_n_b[(0, 0)]);
    Vector3::new(roll, pitch, heading)
}

/// Unit quaternion of the rotation vector `phi_rad` (axis × angle, rad):
/// `[cos(|φ|/2), sin(|φ|/2)/|φ| · φ]`, by Taylor series for |φ| < 1e-3 rad (exact to rounding
/// for every angle, zero included). Allocates nothing.
pub fn quat_from_rotation_vector(phi_rad: &Vector3<f64>) -> UnitQuaternion<f64> {
    let a2 = phi_rad.norm_squared();
    let (c, s) = if a2 < SMALL_ANGLE2_RAD2 {
        // cos(a/2) = 1 − a²/8 + a⁴/384; sin(a/2)/a = 1/2 − a²/48 + a⁴/3840.
        (
            1.0 - a2 / 8.0 + a2 * a2 / 384.0,
            0.5 - a2 / 48.0 + a2 * a2 / 3840.0,
        )
    } else {
        let a = a2.sqrt();
        let (sh, ch) = (0.5 * a).sin_cos();
        (ch, sh / a)
    };
    UnitQuaternion::new_normalize(Quaternion::new(
        c,
        s * phi_rad.x,
        s * phi_rad.y,
        s * phi_rad.z,
    ))
}

/// Rotation vector (axis × angle, rad, angle in [0, π]) of a unit quaternion; the inverse of
/// [`quat_from_rotation_vector`]. `q` and `−q` give the same vector. Series near zero.
pub fn rotation_vector_from_quat(q: &UnitQuaternion<f64>) -> Vector3<f64> {
    let (w, v) = if q.w < 0.0 {
        (-q.w, -q.imag())
    } else {
        (q.w, q.imag())
    };
    let s = v.norm();
    let factor = if s < 1e-4 {
        // 2 atan(x)/s with x = s/w: (2/w)(1 − x²/3 + x⁴/5), next term x⁶/7 < 2e-25.
        let x2 = s * s / (w * w);
        2.0 / w * (1.0 - x2 / 3.0 + x2 * x2 / 5.0)
    } else {
        2.0 * s.atan2(w) / s
    };
    v * factor
}

/// Quaternion to wire format `[w, x, y, z]`.
pub fn quat_to_wire(q: &UnitQuaternion<f64>) -> [f64; 4] {
    [q.w, q.i, q.j, q.k]
}

/// Quaternion from wire format `[w, x, y, z]` (normalised).
pub fn quat_from_wire(q: &[f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f64::consts::FRAC_PI_2;

    proptest! {
        #[test]
        fn euler_round_trip_and_paper_002_formulas(
            roll in -3.1..3.1_f64, pitch in -1.5..1.5_f64, heading in -3.1..3.1_f64,
        ) {
            let c = c_n_b_from_rpy(roll, pitch, heading);
            let q = q_n_b_from_rpy(roll, pitch, heading);
            prop_assert!((q.to_rotation_matrix().into_inner() - c).norm() < 1e-14);
            prop_assert!((c.transpose() * c - Matrix3::identity()).norm() < 1e-14);
            let rpy = rpy_from_c_n_b(&c);
            prop_assert!((rpy - Vector3::new(roll, pitch, heading)).norm() < 1e-12);
            let rpy_q = rpy_from_q_n_b(&q);
            prop_assert!((rpy_q - Vector3::new(roll, pitch, heading)).norm() < 1e-12);
            // Paper 002 layout: rows east, north, up; columns body right, forward, up.
            let p = Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0);
            let cp = p * c * p.transpose();
            let psi = cp[(0, 1)].atan2(cp[(1, 1)]);
            let theta = cp[(2, 1)].asin();
            prop_assert!((psi - heading).abs() < 1e-12);
            prop_assert!((theta - pitch).abs() < 1e-12);
            // Roll: −C31/C33 = cosθ sinγ / (cosθ cosγ).
            let gamma = (-cp[(2, 0)]).atan2(cp[(2, 2)]);
            prop_assert!((gamma - roll).abs() < 1e-12);
            // The printed C13/C33 = (cosψ sinγ − sinψ sinθ cosγ)/(cosθ cosγ): right at ψ = θ = 0.
            let c0 = p * c_n_b_from_rpy(roll, 0.0, 0.0) * p.transpose();
            prop_assert!((c0[(0, 2)].atan2(c0[(2, 2)]) - roll).abs() < 1e-12);
        }

        #[test]
        fn rotation_vector_round_trip(
            x in -1.0..1.0_f64, y in -1.0..1.0_f64, z in -1.0..1.0_f64, scale_exp in -12..0_i32,
        ) {
            let phi = Vector3::new(x, y, z) * 10f64.powi(scale_exp) * 3.0;
            let q = quat_from_rotation_vector(&phi);
            prop_assert!((q.norm() - 1.0).abs() < 1e-15);
            let back = rotation_vector_from_quat(&q);
            prop_assert!((back - phi).norm() <= 1e-15 * phi.norm().max(1e-300) * 4.0 + 1e-300);
            // Same rotation as nalgebra's (for angles where nalgebra is exact).
            if phi.norm() > 1e-6 {
                let qn = UnitQuaternion::from_scaled_axis(phi);
                prop_assert!(q.angle_to(&qn) < 1e-14);
            }
        }
    }

    #[test]
    fn paper_002_roll_sign() {
        // Right wing down by 0.2 rad, level, heading north: body up leans east.
        let c = c_n_b_from_rpy(0.2, 0.0, 0.0);
        let p = Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0);
        let cp = p * c * p.transpose();
        assert!((cp[(0, 2)].atan2(cp[(2, 2)]) - 0.2).abs() < 1e-15);
        assert!(cp[(0, 2)] > 0.0);
    }

    #[test]
    fn small_angle_series_exact() {
        // Compare the series branch with a high-precision evaluation at the switch point.
        let a = 0.999e-3;
        let q = quat_from_rotation_vector(&Vector3::new(a, 0.0, 0.0));
        assert!((q.w - (0.5 * a).cos()).abs() <= f64::EPSILON);
        assert!((q.i - (0.5 * a).sin()).abs() <= 2.0 * f64::EPSILON * q.i);
        let q0 = quat_from_rotation_vector(&Vector3::zeros());
        assert_eq!(q0, UnitQuaternion::identity());
        let tiny = Vector3::new(1e-20, -2e-20, 3e-20);
        assert!(
            (rotation_vector_from_quat(&quat_from_rotation_vector(&tiny)) - tiny).norm() < 1e-35
        );
        // Gimbal lock: pitch ±90° still returns finite angles.
        let rpy = rpy_from_c_n_b(&c_n_b_from_rpy(0.0, FRAC_PI_2, 0.3));
        assert!(rpy.iter().all(|v| v.is_finite()));
        assert!(
            (skew(&Vector3::new(1.0, 2.0, 3.0)) * Vector3::new(-1.0, 0.5, 2.0)
                - Vector3::new(1.0, 2.0, 3.0).cross(&Vector3::new(-1.0, 0.5, 2.0)))
            .norm()
                < 1e-15
        );
    }
}
