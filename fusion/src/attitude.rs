//! Rotation helpers: skew matrices, rotation vectors, Euler angles (roll, pitch, heading as in
//! paper 002: z-y-x), quaternion wire format (Hamilton, scalar first).
//!
//! OWNER: foundations helper.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

/// Skew-symmetric (cross-product) matrix of `v`: `skew(v)·w = v × w`.
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Roll, pitch, heading (rad) of a body → NED rotation.
pub fn rpy_from_q_n_b(q_n_b: &UnitQuaternion<f64>) -> Vector3<f64> {
    let (r, p, y) = q_n_b.euler_angles();
    Vector3::new(r, p, y)
}

/// Body → NED rotation from roll, pitch, heading (rad).
pub fn q_n_b_from_rpy(roll: f64, pitch: f64, heading: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(roll, pitch, heading)
}

/// Quaternion to wire format `[w, x, y, z]`.
pub fn quat_to_wire(q: &UnitQuaternion<f64>) -> [f64; 4] {
    [q.w, q.i, q.j, q.k]
}

/// Quaternion from wire format `[w, x, y, z]` (normalised).
pub fn quat_from_wire(q: &[f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]))
}
