//! Channel geometry and least-squares combination of redundant inertial channels (paper 004).
//!
//! # Measurement model (paper eqs. (3)–(5))
//! `N` single-axis gyro + accelerometer channels with unit sensitive axes `e_i` in body axes
//! (the paper's truncated pyramid: `e_i = (cosα cosβ_i, cosα sinβ_i, sinα)`, β_i = 45° + i·90°)
//! measure `z = H x + ε`, `H` the `N×3` stack of `e_iᵀ`, `x` the body delta-angle (or
//! delta-velocity) over one IMU interval. The least-squares estimate is (eqs. (6), (7))
//! `x̂ = (HᵀH)⁻¹ Hᵀ z`, with error covariance `σ² (HᵀH)⁻¹` for white channel noise σ.

use super::{HMatrix, MAX_CHANNELS};
use nalgebra::Matrix3;

/// Unit axes of the paper's pyramid: `n` channels at azimuths β_k = 45° + k·360°/n (90° steps
/// for n = 4) and elevation `alpha_rad` above the body x-y plane, body axes.
/// α = asin(1/√3) = 35.26° makes four axes isotropic (`HᵀH = (4/3) I`).
pub fn pyramid_axes(n: usize, alpha_rad: f64) -> [[f64; 3]; MAX_CHANNELS] {
    let mut axes = [[0.0; 3]; MAX_CHANNELS];
    let n = n.min(MAX_CHANNELS);
    let (sa, ca) = alpha_rad.sin_cos();
    for (k, a) in axes.iter_mut().enumerate().take(n) {
        let beta = (45.0_f64 + k as f64 * 360.0 / n as f64).to_radians();
        *a = [ca * beta.cos(), ca * beta.sin(), sa];
    }
    axes
}

/// The three orthogonal body axes as channels (the conventional triad).
pub fn orthogonal_axes() -> [[f64; 3]; MAX_CHANNELS] {
    let mut axes = [[0.0; 3]; MAX_CHANNELS];
    axes[0] = [1.0, 0.0, 0.0];
    axes[1] = [0.0, 1.0, 0.0];
    axes[2] = [0.0, 0.0, 1.0];
    axes
}

/// Measurement matrix of the channels in `active` (bit i = channel i used).
pub fn measurement_matrix(axes: &[[f64; 3]; MAX_CHANNELS], active: u32) -> HMatrix {
    let mut h = HMatrix::zeros();
    for (i, a) in axes.iter().enumerate() {
        if active & (1 << i) != 0 {
            h[(i, 0)] = a[0];
            h[(i, 1)] = a[1];
            h[(i, 2)] = a[2];
        }
    }
    h
}

/// `(HᵀH)⁻¹`: the least-squares error covariance of the combined vector per unit channel
/// variance, body axes. None if the active axes do not span 3-D.
pub fn ls_covariance_per_unit_variance(h: &HMatrix) -> Option<Matrix3<f64>> {
    let hth = h.transpose() * h;
    // Reject near-coplanar layouts: condition through the determinant of the normal matrix
    // relative to its scale (trace³/27 for an isotropic one).
    let tr = hth.trace();
    if tr.is_nan() || tr <= 0.0 || hth.determinant() < 1e-9 * tr * tr * tr {
        return None;
    }
    hth.try_inverse()
}
