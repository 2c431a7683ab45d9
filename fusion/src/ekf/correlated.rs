//! Time-correlated measurement errors fused as white noise: the variance inflation that
//! keeps the filter consistent.
//!
//! # Why
//! A GNSS fix or pseudorange carries, beside white code noise, errors that change slowly:
//! residual ionosphere and troposphere, broadcast orbit and clock, multipath. Fused epoch after
//! epoch as white noise with the receiver's reported variance `r`, they are averaged as if
//! independent — the filter's variance falls as `r/N` while the error of the average stays
//! near `r` — and the filter becomes over-confident (position NEES in the hundreds on the
//! simulator's world and on real data).
//!
//! # The model: first-order Gauss–Markov error, white-noise update with inflated variance
//! Model the error as `v_n = ρ v_{n−1} + √(1 − ρ²)·σ·ξ_n` (variance `σ² = r`, correlation
//! `E[v_n v_{n−k}] = r ρᵏ`, `ρ = exp(−Δt/τ)` for epochs `Δt` apart and correlation time `τ`).
//!
//! A filter in steady state along one measured direction (scalar, `H = 1`) with gain `K` and
//! `a = 1 − K` has the posterior error `e_n = a (e_{n−1} + w_n) − K v_n` (`w` the process
//! noise of one interval, variance `q`). Its variance is the process part plus
//! ```text
//!   K² Σ_{i,j≥0} aⁱ aʲ E[v_{n−i} v_{n−j}] = K² r Σ_{i,j} aⁱ⁺ʲ ρ^|i−j|
//!                                       = K² r /(1 − a²) · (1 + aρ)/(1 − aρ),
//! ```
//! while the filter, believing `v` white with variance `r'`, computes the same process part
//! plus `K² r'/(1 − a²)` (the steady state of its own Joseph-form Riccati recursion is the
//! Lyapunov solution of the same error recursion with white noise). The two agree exactly when
//! ```text
//!   r' = g·r,   g = (1 + aρ)/(1 − aρ).
//! ```
//! `g` is the ratio of the exponentially weighted sum of the autocorrelation to the white-noise
//! case: `1` when the filter keeps nothing of its prior (`a = 0`: one epoch, no averaging) or
//! the error is white (`ρ = 0`), and `(1 + ρ)/(1 − ρ) ≈ 2τ/Δt` for a filter that averages
//! over much longer than `τ` (`a → 1`, the long-window limit of the sum of the autocorrelation).
//!
//! `a` itself depends on the inflated variance: for a scalar update with prior variance
//! `p = H P Hᵀ`, `a = 1 − H K = g r/(p + g r)`. Both equations together are the quadratic
//! ```text
//!   r (1 − ρ) g² + (p − r (1 + ρ)) g − p = 0,
//! ```
//! whose positive root ([`scalar_inflation`]) is the factor used at each update, with the
//! filter's current `p`. In a steady state it is the exact factor above; in a transient (first
//! epochs, after an outage: large `p`) it tends to 1, as it should — the first fix of a
//! correlated error is as good as its variance says, only its repetitions are not new
//! information. For a vector measurement ([`inflate_covariance3`]) the same holds per
//! direction in the coordinates where `R` is white and `H P Hᵀ` diagonal.
//!
//! # Why this and not state augmentation
//! Augmenting the state with the correlated error (three position-bias states for the fix,
//! one per satellite for pseudoranges) is the exact model, but the error state is a fixed 31
//! and per-satellite states would need 32 more with their bookkeeping as satellites rise and
//! set; the common-mode part of the pseudorange errors is already absorbed by the receiver
//! clock state. The inflation needs only `τ` and costs one quadratic (or a 3×3 eigen
//! decomposition) per update. What it gives up: it cannot *estimate* the bias (the solution
//! does not get better than the receiver's slowly varying error, it only stops claiming it
//! does), it is exact only in a steady state, and it assumes the whole reported variance is
//! correlated with one `τ` (the white code noise, a few per cent of a code receiver's error
//! budget, is then counted as correlated too: slightly conservative).
//!
//! The inflation also widens the χ² gate of the update (the gate uses `H P Hᵀ + g r`).

use nalgebra::{Cholesky, Matrix3, SymmetricEigen};

/// Lag-one correlation `ρ = exp(−Δt/τ)` of a first-order Gauss–Markov error between two
/// epochs `dt_s` apart with correlation time `tau_s`. 0 (white) when `tau_s ≤ 0`, when
/// `dt_s` is not a finite positive interval, or when either is not finite.
pub fn lag_correlation(dt_s: f64, tau_s: f64) -> f64 {
    if tau_s.is_finite() && tau_s > 0.0 && dt_s.is_finite() && dt_s > 0.0 {
        (-dt_s / tau_s).exp()
    } else {
        0.0
    }
}

/// Inflation `g = (1 + aρ)/(1 − aρ)` of the variance of a Gauss–Markov error with lag-one
/// correlation `rho` fused by a filter that keeps the fraction `a = 1 − HK` of its prior at
/// each update (module docs). `a·ρ` is clamped below 1.
pub fn inflation_for_retention(a: f64, rho: f64) -> f64 {
    let ar = (a * rho).clamp(0.0, 1.0 - 1e-15);
    (1.0 + ar) / (1.0 - ar)
}

/// The consistent inflation `g ≥ 1` of a scalar measurement's noise variance `r` (> 0) given
/// the prior variance `p = H P Hᵀ` (≥ 0) and the error's lag-one correlation `rho` ∈ [0, 1):
/// the positive root of `r (1 − ρ) g² + (p − r (1 + ρ)) g − p = 0` (module docs). 1 for
/// white errors; `(1 + ρ)/(1 − ρ)` for `p = 0`.
pub fn scalar_inflation(p: f64, r: f64, rho: f64) -> f64 {
    let rho = rho.clamp(0.0, 1.0 - 1e-12);
    if rho == 0.0 || r.is_nan() || r <= 0.0 || !p.is_finite() {
        return 1.0;
    }
    let p = p.max(0.0);
    let a2 = r * (1.0 - rho);
    let b = p - r * (1.0 + rho);
    let disc = (b * b + 4.0 * a2 * p).sqrt();
    // Stable forms of the positive root (no cancellation for either sign of b).
    let g = if b > 0.0 {
        2.0 * p / (b + disc)
    } else {
        (disc - b) / (2.0 * a2)
    };
    g.max(1.0)
}

/// [`scalar_inflation`] for a 3-vector measurement with noise covariance `r` (positive
/// definite) and prior `hph = H P Hᵀ`: in the coordinates `L⁻¹` where `R = L Lᵀ` is white,
/// `L⁻¹ H P Hᵀ L⁻ᵀ = V Λ Vᵀ`, each direction gets `g_i = scalar_inflation(λ_i, 1, ρ)` and
/// `R' = L V diag(g) Vᵀ Lᵀ`. Returns `r` unchanged when `rho` is 0 or `r` is not positive
/// definite.
pub fn inflate_covariance3(hph: &Matrix3<f64>, r: &Matrix3<f64>, rho: f64) -> Matrix3<f64> {
    if rho <= 0.0 {
        return *r;
    }
    let Some(chol) = Cholesky::new(*r) else {
        return *r;
    };
    let l = chol.l();
    let Some(l_inv) = l.try_inverse() else {
        return *r;
    };
    let m = l_inv * hph * l_inv.transpose();
    let eig = SymmetricEigen::new((m + m.transpose()) * 0.5);
    let g = eig
        .eigenvalues
        .map(|lambda| scalar_inflation(lambda, 1.0, rho));
    let v = eig.eigenvectors;
    let inner = v * Matrix3::from_diagonal(&g) * v.transpose();
    let out = l * inner * l.transpose();
    (out + out.transpose()) * 0.5
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, Vector2};

    /// Steady state of the scalar filter (random walk with `q` per interval, measurement
    /// `z = x + v`) with the inflation recomputed from its prior at each update, as the
    /// navigator does: returns (prior p⁻, gain K, believed posterior variance P⁺).
    fn steady_filter(q: f64, r: f64, rho: f64) -> (f64, f64, f64) {
        let mut p = 1e6;
        let (mut pm, mut k) = (0.0, 0.0);
        for _ in 0..200_000 {
            pm = p + q;
            let g = scalar_inflation(pm, r, rho);
            k = pm / (pm + g * r);
            p = (1.0 - k) * (1.0 - k) * pm + k * k * g * r;
        }
        (pm, k, p)
    }

    /// True steady-state posterior error variance of the same filter (fixed gain `k`) when
    /// the measurement error is Gauss–Markov with variance `r` and lag-one correlation `rho`:
    /// the stationary covariance of the joint linear system
    /// `v_n = ρ v_{n−1} + √(1−ρ²) √r ξ`, `e_n = a (e_{n−1} + w_n) − k v_n`, by iteration.
    fn true_variance(q: f64, r: f64, rho: f64, k: f64) -> f64 {
        let a = 1.0 - k;
        // State (e, v) after the update: e_n = a e_{n−1} − kρ v_{n−1} + a w − k√(1−ρ²)√r ξ.
        let f = Matrix2::new(a, -k * rho, 0.0, rho);
        let g_w = Vector2::new(a, 0.0);
        let g_xi = Vector2::new(-k, 1.0) * ((1.0 - rho * rho) * r).sqrt();
        let qn = g_w * g_w.transpose() * q + g_xi * g_xi.transpose();
        let mut c = Matrix2::zeros();
        for _ in 0..2_000_000 {
            let next = f * c * f.transpose() + qn;
            if (next - c).abs().max() < 1e-15 * next.abs().max() {
                c = next;
                break;
            }
            c = next;
        }
        c[(0, 0)]
    }

    #[test]
    fn white_errors_are_not_inflated() {
        assert_eq!(scalar_inflation(3.0, 2.0, 0.0), 1.0);
        assert_eq!(lag_correlation(1.0, 0.0), 0.0);
        assert_eq!(lag_correlation(f64::NAN, 10.0), 0.0);
        let r = Matrix3::new(2.0, 0.3, 0.0, 0.3, 1.0, 0.1, 0.0, 0.1, 4.0);
        assert_eq!(inflate_covariance3(&Matrix3::identity(), &r, 0.0), r);
    }

    #[test]
    fn limits_of_the_quadratic() {
        let rho = lag_correlation(1.0, 300.0);
        // No prior uncertainty: the long-window limit (1 + ρ)/(1 − ρ) ≈ 2τ/Δt.
        let g0 = scalar_inflation(0.0, 1.0, rho);
        assert!((g0 - (1.0 + rho) / (1.0 - rho)).abs() < 1e-9 * g0, "{g0}");
        assert!((g0 / 600.0 - 1.0).abs() < 1e-3);
        // A vague prior: no averaging, no inflation.
        assert!((scalar_inflation(1e12, 1.0, rho) - 1.0).abs() < 1e-6);
        // The root satisfies g = (1 + aρ)/(1 − aρ) with a = g r/(p + g r).
        for (p, r) in [(0.5, 2.0), (10.0, 1.0), (1e-3, 5.0), (3.0, 3.0)] {
            let g = scalar_inflation(p, r, rho);
            let a = g * r / (p + g * r);
            let rhs = inflation_for_retention(a, rho);
            assert!((g - rhs).abs() < 1e-9 * g, "p {p} r {r}: {g} vs {rhs}");
        }
    }

    /// The closed-form check: in steady state, the variance the filter believes equals the
    /// true variance of its error under a Gauss–Markov measurement error, for correlation
    /// times from white to far beyond the filter's averaging time; without the inflation the
    /// filter is over-confident by the factor derived in the module docs.
    #[test]
    fn steady_state_variance_matches_gauss_markov_truth() {
        let r = 1.5f64.powi(2);
        for (q, tau_s) in [(1e-2, 10.0), (1e-3, 60.0), (1e-4, 600.0), (1e-2, 3600.0)] {
            let rho = lag_correlation(1.0, tau_s);
            let (_, k, believed) = steady_filter(q, r, rho);
            let truth = true_variance(q, r, rho, k);
            assert!(
                (believed / truth - 1.0).abs() < 1e-6,
                "q {q} τ {tau_s}: believed {believed} true {truth}"
            );
            // The same filter without the model (white, r) believes far less than its error.
            let (_, k_w, believed_w) = steady_filter(q, r, 0.0);
            let truth_w = true_variance(q, r, rho, k_w);
            let a = 1.0 - k_w;
            assert!(
                truth_w / believed_w > 2.0,
                "τ {tau_s}: {truth_w} / {believed_w}"
            );
            // …by the derived factor on its measurement part.
            let meas_believed = k_w * k_w * r / (1.0 - a * a);
            let meas_true = truth_w - (believed_w - meas_believed);
            let g = inflation_for_retention(a, rho);
            assert!((meas_true / meas_believed / g - 1.0).abs() < 1e-6);
        }
    }

    #[test]
    fn vector_inflation_is_per_whitened_direction() {
        let rho = lag_correlation(1.0, 900.0);
        // R diagonal and H P Hᵀ diagonal: each axis as a scalar.
        let r = Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, 4.0, 9.0));
        let hph = Matrix3::from_diagonal(&nalgebra::Vector3::new(0.1, 40.0, 0.9));
        let out = inflate_covariance3(&hph, &r, rho);
        for i in 0..3 {
            let g = scalar_inflation(hph[(i, i)], r[(i, i)], rho);
            assert!((out[(i, i)] / (g * r[(i, i)]) - 1.0).abs() < 1e-9, "{i}");
        }
        assert!(out[(0, 1)].abs() < 1e-9 && out[(1, 2)].abs() < 1e-9);
        // A rotated, correlated R gives the rotated answer.
        let rot = nalgebra::Rotation3::from_euler_angles(0.3, -0.7, 1.1).into_inner();
        let out_rot = inflate_covariance3(
            &(rot * hph * rot.transpose()),
            &(rot * r * rot.transpose()),
            rho,
        );
        let expect = rot * out * rot.transpose();
        assert!((out_rot - expect).abs().max() < 1e-9 * expect.abs().max());
    }
}
