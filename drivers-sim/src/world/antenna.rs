//! The GNSS antenna's place on the vehicle and the receiver's time-tag latency.
//!
//! The antenna phase centre is at `r_a = r + C_e_b l_b` (lever arm `l_b` in body axes, m,
//! from the IMU), moving with `v_a = v + C_e_b (ω_eb^b × l_b)`,
//! `ω_eb^b = ω_ib^b − C_b_e ω_ie^e` (Groves, "Principles of GNSS, Inertial, and Multisensor
//! Integrated Navigation Systems", 2nd ed., eq. 2.150/2.151). A time-tag latency `L` means the
//! measurement stamped `t` was made at `t − L`.

use fusion::earth::WGS84;
use nalgebra::{Matrix3, Vector3};
use serde::Deserialize;

/// `[world.gnss_antenna]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GnssAntennaSpec {
    /// Whether the lever arm and the latency are applied.
    #[serde(default = "super::yes")]
    pub enabled: bool,
    /// Antenna phase centre relative to the IMU, body axes (x fwd, y right, z down), m.
    pub lever_arm_b_m: [f64; 3],
    /// Time-tag latency, s (a whole number of milliseconds, the truth grid; below 1 s).
    #[serde(default)]
    pub latency_s: f64,
}

/// Antenna position and velocity (ECEF, m and m/s) of a body at `r_e`, `v_e` with attitude
/// `c_e_b` and inertial rate `w_ib_b` (rad/s) for the lever arm `lever_arm_b`.
pub fn antenna_state(
    r_e: &Vector3<f64>,
    v_e: &Vector3<f64>,
    c_e_b: &Matrix3<f64>,
    w_ib_b: &Vector3<f64>,
    lever_arm_b: &Vector3<f64>,
) -> (Vector3<f64>, Vector3<f64>) {
    let w_eb_b = w_ib_b - c_e_b.transpose() * WGS84.omega_ie_e();
    (
        r_e + c_e_b * lever_arm_b,
        v_e + c_e_b * w_eb_b.cross(lever_arm_b),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    #[test]
    fn antenna_velocity_is_the_derivative_of_its_position() {
        // A tilted body turning at 0.2 rad/s with a 1.5 m lever arm: the antenna velocity
        // must be the central difference of its position (error O(h²ω³|l|) ≈ 1e-14 m/s).
        let l = Vector3::new(0.3, 0.2, -1.5);
        let r0 = Vector3::new(WGS84.a_m, 0.0, 0.0);
        let v = Vector3::new(0.0, 10.0, 0.0);
        let att = |t: f64| Rotation3::from_euler_angles(0.1, -0.05, 0.3 + 0.2 * t).into_inner();
        // ω_eb^b of this attitude history from the DCM's derivative: [ω×] = Cᵀ Ċ.
        let h = 1e-6;
        let c0 = att(0.0);
        let cdot = (att(h) - att(-h)) / (2.0 * h);
        let omega = c0.transpose() * cdot; // [ω_eb^b ×]
        let w_b = Vector3::new(omega[(2, 1)], omega[(0, 2)], omega[(1, 0)]);
        let w_ib = w_b + c0.transpose() * WGS84.omega_ie_e();
        let (_, va) = antenna_state(&r0, &v, &c0, &w_ib, &l);
        // Position r0 + v t + C(t) l, differenced without r0 (6.4e6 m would cost 1e-3 m/s of
        // rounding at h = 1e-6 s).
        let fd = v + (att(h) * l - att(-h) * l) / (2.0 * h);
        assert!((va - fd).norm() < 1e-6, "{va} vs {fd}");
        assert!(
            (va - v).norm() > 0.1,
            "lever arm term visible: {}",
            (va - v).norm()
        );
    }
}
