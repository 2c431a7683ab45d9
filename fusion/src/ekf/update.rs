//! The Kalman update as a pure function, and covariance augmentation.
//!
//! [`update()`] is a pure function in the style of nyx `od/kalman`: it returns the correction,
//! the new covariance and a [`Residual`] record (innovation, its covariance `S`, normalized
//! innovation squared `NIS = yᵀ S⁻¹ y`, the chi-square gate for `dim y` at the configured
//! probability and whether the sample was rejected). Joseph form
//! `P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ`, evaluated in its expanded, algebraically identical
//! `O(n²m)` form `P − K (P Hᵀ)ᵀ − (P Hᵀ) Kᵀ + K S Kᵀ` (valid for any gain, like the factored
//! form), written as the exactly symmetric `P − (K Eᵀ + E Kᵀ)`, `E = P Hᵀ − K S/2`.
//! [`update_in_place`] writes it over the prior (the navigator's hot path), [`update()`] returns
//! it. Everything is fixed-size (`SMatrix`/`SVector`): no allocation.
//!
//! The filter keeps no statistics of its own: the caller folds each [`Residual`] into its
//! health record (rejection counts, NIS windows).

use super::{Covariance, NX, StateVector};
use nalgebra::{Cholesky, SMatrix, SVector};

/// `(P + Pᵀ)/2`.
pub fn symmetrize<const D: usize>(p: &SMatrix<f64, D, D>) -> SMatrix<f64, D, D> {
    let mut out = *p;
    symmetrize_in_place(&mut out);
    out
}

/// `P ← (P + Pᵀ)/2` in place: each pair of mirrored entries replaced by their mean, the
/// diagonal untouched (the same numbers as [`symmetrize`], without the temporaries).
pub fn symmetrize_in_place<const D: usize>(p: &mut SMatrix<f64, D, D>) {
    for j in 1..D {
        for i in 0..j {
            let v = 0.5 * (p[(i, j)] + p[(j, i)]);
            p[(i, j)] = v;
            p[(j, i)] = v;
        }
    }
}

/// `P Hᵀ` from the columns of `P` that `H` weighs: a measurement's Jacobian touches a few
/// states (a height one, a pseudorange four), so the zero entries are skipped. Adding the
/// skipped `0·P` would change nothing: `x + 0 = x`.
pub(super) fn p_times_h_transpose<const M: usize>(
    p: &Covariance,
    h: &SMatrix<f64, M, NX>,
) -> SMatrix<f64, NX, M> {
    let mut pht = SMatrix::<f64, NX, M>::zeros();
    for a in 0..M {
        let mut out = pht.column_mut(a);
        for k in 0..NX {
            let h_ak = h[(a, k)];
            if h_ak != 0.0 {
                out.zip_apply(&p.column(k), |o, p_ik| *o += p_ik * h_ak);
            }
        }
    }
    pht
}

/// `H X` for an `NX × M` matrix `X` (e.g. `P Hᵀ`), summing over the non-zero entries of each
/// row of `H` in increasing order: the dense product's sums without their `0·x` terms, so the
/// same numbers.
fn h_times<const M: usize>(h: &SMatrix<f64, M, NX>, x: &SMatrix<f64, NX, M>) -> SMatrix<f64, M, M> {
    let mut out = SMatrix::<f64, M, M>::zeros();
    for i in 0..M {
        for k in 0..NX {
            let h_ik = h[(i, k)];
            if h_ik != 0.0 {
                for l in 0..M {
                    out[(i, l)] += h_ik * x[(k, l)];
                }
            }
        }
    }
    out
}

/// `H P Hᵀ` of a measurement Jacobian `H` and a symmetric covariance `P`, from the columns of
/// `P` that `H` weighs: the numbers of the dense `(H P) Hᵀ` (`H P` is `(P Hᵀ)ᵀ` exactly when
/// `P` is symmetric, and the zero entries of `H` add nothing), for a fraction of the work.
pub fn h_p_ht<const M: usize>(p: &Covariance, h: &SMatrix<f64, M, NX>) -> SMatrix<f64, M, M> {
    h_times(h, &p_times_h_transpose(p, h)).transpose()
}

/// True when every entry of `m` is finite, in one vectorisable pass: a NaN or an infinity
/// makes the sum non-finite (`+∞ − ∞` is NaN). The sum of finite entries overflows only
/// near 10³⁰⁸, far beyond any covariance, and would then refuse the result, not accept it.
fn all_finite<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> bool {
    m.as_slice().iter().sum::<f64>().is_finite()
}

/// A linearised measurement: innovation `y = z − h(x̂)`, Jacobian `H = ∂h/∂x` and noise
/// covariance `R`, all for measurement dimension `M`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement<const M: usize> {
    /// Innovation `z − h(x̂)` (units of the measurement).
    pub innovation: SVector<f64, M>,
    /// Jacobian with respect to the error state.
    pub h: SMatrix<f64, M, NX>,
    /// Measurement noise covariance.
    pub r: SMatrix<f64, M, M>,
}

/// Residual record of one update (nyx `od/kalman` style).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Residual<const M: usize> {
    /// Innovation `z − h(x̂)`.
    pub innovation: SVector<f64, M>,
    /// Innovation covariance `S = H P Hᵀ + R`.
    pub covariance: SMatrix<f64, M, M>,
    /// Normalized innovation squared `yᵀ S⁻¹ y` (chi-square with M dof if consistent).
    pub nis: f64,
    /// Gate threshold used (chi-square quantile for M dof).
    pub gate: f64,
    /// True when the sample was not fused (NIS above the gate, `S` not positive definite, or
    /// anything non-finite in the measurement or the result).
    pub rejected: bool,
}

/// Result of [`update()`]: correction, covariance after the update, and the residual record.
/// When rejected, `dx` is zero and `p` is the prior covariance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UpdateOutcome<const M: usize> {
    /// Error-state correction to feed back.
    pub dx: StateVector,
    /// Posterior covariance.
    pub p: Covariance,
    /// Residual record.
    pub residual: Residual<M>,
}

/// Kalman update of prior covariance `p` (error state zero) with measurement `m`, gated at
/// `gate` (NIS threshold; `f64::INFINITY` disables the gate). Pure; allocates nothing. A
/// measurement with any non-finite entry is rejected before it can touch anything.
pub fn update<const M: usize>(p: &Covariance, m: &Measurement<M>, gate: f64) -> UpdateOutcome<M> {
    let mut p_new = *p;
    let (dx, residual) = update_in_place(&mut p_new, m, gate);
    UpdateOutcome {
        dx,
        p: p_new,
        residual,
    }
}

/// [`update()`] writing the posterior covariance over the prior in `p`: the correction and the
/// residual record are returned, and `p` is left exactly as it was when the sample is
/// rejected. The filter's hot path: no copy of the 31×31 matrix.
pub fn update_in_place<const M: usize>(
    p: &mut Covariance,
    m: &Measurement<M>,
    gate: f64,
) -> (StateVector, Residual<M>) {
    let pht = p_times_h_transpose(p, &m.h);
    let s = symmetrize(&(h_times(&m.h, &pht) + m.r));
    let residual = |nis: f64, rejected: bool| Residual {
        innovation: m.innovation,
        covariance: s,
        nis,
        gate,
        rejected,
    };
    let rejected = |nis: f64| (StateVector::zeros(), residual(nis, true));
    if !(all_finite(&m.innovation) && all_finite(&m.h) && all_finite(&m.r)) {
        return rejected(f64::INFINITY);
    }
    let Some(chol) = Cholesky::new(s) else {
        return rejected(f64::INFINITY);
    };
    let nis = m.innovation.dot(&chol.solve(&m.innovation));
    if !nis.is_finite() || nis > gate {
        return rejected(nis);
    }
    let s_inv = chol.inverse();
    let k: SMatrix<f64, NX, M> = pht * s_inv;
    let dx = k * m.innovation;
    // Joseph form, expanded: (I−KH)P(I−KH)ᵀ + KRKᵀ = P − K(PHᵀ)ᵀ − (PHᵀ)Kᵀ + K S Kᵀ
    // = P − (K Eᵀ + E Kᵀ) with E = PHᵀ − K S/2: a rank-2M correction applied column by
    // column (contiguous in memory) without any n×n temporary. Entry (i, j) subtracts
    // K_ia·E_ja + E_ia·K_ja and entry (j, i) the same two products added the other way
    // round; floating-point addition and multiplication commute, so a symmetric P stays
    // exactly symmetric with no symmetrisation pass.
    let e = pht - k * s * 0.5;
    // The result is finite when P, K and E are and no sum can overflow: every entry of P⁺ is
    // bounded by max|P| + 2M·max|K|·max|E|, and a covariance's largest entry is on its
    // diagonal (|P_ij| ≤ √(P_ii·P_jj)). Checked before P is touched, so that a refused update
    // leaves it as it was.
    let max_abs = |x: &[f64]| x.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
    let p_max = (0..NX).fold(0.0_f64, |a, i| a.max(p[(i, i)].abs()));
    let bound = p_max + 2.0 * M as f64 * max_abs(k.as_slice()) * max_abs(e.as_slice());
    if !(all_finite(&dx) && all_finite(&k) && all_finite(&e) && bound < 1e300) {
        return rejected(f64::INFINITY);
    }
    // Only the upper triangle is computed (each column's leading part, contiguous in memory)
    // and mirrored: the lower entries would be the same numbers (see above), for half the work.
    let (k_s, e_s) = (k.as_slice(), e.as_slice());
    let p_s = p.as_mut_slice();
    for j in 0..NX {
        let col = &mut p_s[j * NX..j * NX + j + 1];
        for a in 0..M {
            let (e_ja, k_ja) = (e[(j, a)], k[(j, a)]);
            let k_a = &k_s[a * NX..a * NX + j + 1];
            let e_a = &e_s[a * NX..a * NX + j + 1];
            for ((x, k_ia), e_ia) in col.iter_mut().zip(k_a).zip(e_a) {
                *x -= k_ia * e_ja + e_ia * k_ja;
            }
        }
        for i in 0..j {
            p_s[i * NX + j] = p_s[j * NX + i];
        }
    }
    (dx, residual(nis, false))
}

/// State augmentation from measurements (used to start the receiver-clock states).
///
/// New states `c` (indices `new`, currently without covariance: their rows and columns of `p`
/// are zero) are set from `M` measurements `z = h(x) + c + ε`, `ε ~ N(0, r)`, as
/// `ĉ = z − h(x̂)`. Their error is then `δc = c − ĉ = −H δx − ε`, where `H` (`h`, with zero
/// columns at `new`) is the Jacobian of `h` with respect to the existing error states. Hence
///
/// `P_cc = H P Hᵀ + R`,  `P_cx = −H P`,
///
/// exactly (to first order in δx), so the new states carry the existing errors they were
/// computed with — e.g. a clock bias taken from `ρ − |s − r̂|` carries `+u·δr` (`H_r = −uᵀ`).
/// Setting `P_cx = 0` instead would let the filter later "explain" the inertial error along the
/// line of sight by a clock it believes independent (with one satellite, the tight-coupling
/// filter then drifts along that line of sight).
/// The measurements used are consumed: fusing them again would count them twice. Pure; no
/// allocation.
pub fn augment_covariance<const M: usize>(
    p: &mut Covariance,
    new: [usize; M],
    h: &SMatrix<f64, M, NX>,
    r: &SMatrix<f64, M, M>,
) {
    let mut h0 = *h;
    for &i in &new {
        h0.column_mut(i).fill(0.0);
        p.row_mut(i).fill(0.0);
        p.column_mut(i).fill(0.0);
    }
    let hp: SMatrix<f64, M, NX> = h0 * *p;
    let p_cc = symmetrize(&(hp * h0.transpose() + r));
    for (a, &i) in new.iter().enumerate() {
        for j in 0..NX {
            p[(i, j)] = -hp[(a, j)];
            p[(j, i)] = -hp[(a, j)];
        }
    }
    for (a, &i) in new.iter().enumerate() {
        for (b, &j) in new.iter().enumerate() {
            p[(i, j)] = p_cc[(a, b)];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{nav_at_origin, random_spd};
    use super::super::{GateTable, idx};
    use super::super::{GnssAntenna, gnss_position};
    use super::*;
    use nalgebra::{Matrix3, Vector3};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    /// `H P Hᵀ` from the weighed columns is the dense product bit for bit, for Jacobians of
    /// one to three rows with random zeros (a symmetric `P`, as the filter keeps it).
    #[test]
    fn h_p_ht_is_the_dense_product() {
        fn check<const M: usize>(rng: &mut ChaCha8Rng) {
            let p = random_spd(rng, 3.0);
            let h = SMatrix::<f64, M, NX>::from_fn(|_, _| {
                if rng.random_bool(0.7) {
                    0.0
                } else {
                    rng.random_range(-2.0..2.0)
                }
            });
            let dense = h * p * h.transpose();
            let sparse = h_p_ht(&p, &h);
            for (d, s) in dense.iter().zip(sparse.iter()) {
                assert_eq!(d.to_bits(), s.to_bits(), "{dense} {sparse}");
            }
        }
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for _ in 0..50 {
            check::<1>(&mut rng);
            check::<2>(&mut rng);
            check::<3>(&mut rng);
        }
    }

    #[test]
    fn update_accepts_consistent_and_rejects_outlier() {
        let mut p = Covariance::identity() * 1.0e-4;
        p.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(Matrix3::identity() * 100.0));
        let nav = nav_at_origin();
        let cov = Matrix3::identity() * 4.0;
        let gates = GateTable::new(0.999);
        let good = gnss_position(
            &nav,
            &GnssAntenna::AT_IMU,
            &(nav.r_e + Vector3::new(3.0, -2.0, 1.0)),
            &cov,
        );
        let out = update(&p, &good, gates.threshold(3));
        assert!(!out.residual.rejected);
        assert!((out.dx[0] - 3.0 * 100.0 / 104.0).abs() < 1e-9);
        assert!((out.p[(0, 0)] - 100.0 * 4.0 / 104.0).abs() < 1e-9);
        let bad = gnss_position(
            &nav,
            &GnssAntenna::AT_IMU,
            &(nav.r_e + Vector3::new(300.0, 0.0, 0.0)),
            &cov,
        );
        let out = update(&p, &bad, gates.threshold(3));
        assert!(out.residual.rejected);
        assert!(out.residual.nis > out.residual.gate);
        assert_eq!(out.dx, StateVector::zeros());
        assert_eq!(out.p, p);
        let mut nan = good;
        nan.innovation[1] = f64::NAN;
        let out = update(&p, &nan, f64::INFINITY);
        assert!(out.residual.rejected);
        assert_eq!(out.p, p);
        // In place, a refused update leaves the covariance as it was.
        for m in [&bad, &nan] {
            let mut q = p;
            let (dx, residual) = update_in_place(&mut q, m, gates.threshold(3));
            assert!(residual.rejected);
            assert_eq!((q, dx), (p, StateVector::zeros()));
        }
    }

    #[test]
    fn random_updates_keep_covariance_symmetric_positive_definite_and_joseph_exact() {
        // 2000 random sequential updates of random dimension-3 measurements on a random
        // prior: the expanded Joseph form must equal the factored one (relative 1e-10), the
        // covariance must stay exactly symmetric and Cholesky-factorisable, and never grow.
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let mut p = random_spd(&mut rng, 1.0);
        for k in 0..2000 {
            let h = SMatrix::<f64, 3, NX>::from_fn(|_, _| rng.random_range(-1.0..1.0));
            let r = Matrix3::from_diagonal(&Vector3::from_fn(|_, _| {
                10f64.powf(rng.random_range(-6.0..1.0))
            }));
            let y = Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0));
            let m = Measurement {
                innovation: y,
                h,
                r,
            };
            let out = update(&p, &m, f64::INFINITY);
            assert!(!out.residual.rejected, "step {k}");
            let mut in_place = p;
            let (dx, residual) = update_in_place(&mut in_place, &m, f64::INFINITY);
            assert_eq!((in_place, dx, residual), (out.p, out.dx, out.residual));
            let s = h * p * h.transpose() + r;
            let kk = p * h.transpose() * s.try_inverse().unwrap();
            let ikh = Covariance::identity() - kk * h;
            let factored = ikh * p * ikh.transpose() + kk * r * kk.transpose();
            let scale = p.abs().max();
            assert!((out.p - factored).abs().max() < 1e-10 * scale, "step {k}");
            assert_eq!(out.p, out.p.transpose());
            assert!(Cholesky::new(out.p).is_some(), "step {k}: not PD");
            assert!(out.p.trace() <= p.trace() * (1.0 + 1e-12));
            p = out.p;
            // Re-inflate occasionally so the test explores well-conditioned priors too.
            if k % 50 == 49 {
                p += random_spd(&mut rng, 1e-2);
            }
        }
    }

    /// Monte Carlo: draw δx ~ N(0, P) and ε, form δc = −Hδx − ε; the sample covariance of
    /// (δx, δc) must equal the augmented P. With N draws the sample covariance of two unit
    /// variables has standard error ≤ √(2/N); we accept 5 standard errors on every element
    /// of the correlation-normalised difference.
    #[test]
    fn augmented_covariance_is_the_covariance_of_the_construction() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        // A random SPD prior on the 29 non-clock states, clock rows zero.
        let mut a = SMatrix::<f64, NX, NX>::zeros();
        for v in a.iter_mut() {
            *v = StandardNormal.sample(&mut rng);
        }
        let mut p: Covariance = a * a.transpose() + Covariance::identity();
        for i in [idx::CLK, idx::CLK_DRIFT] {
            p.row_mut(i).fill(0.0);
            p.column_mut(i).fill(0.0);
        }
        let mut h = SMatrix::<f64, 2, NX>::zeros();
        for v in h.iter_mut() {
            *v = StandardNormal.sample(&mut rng);
        }
        h[(0, idx::CLK)] = 1.0;
        h[(1, idx::CLK_DRIFT)] = 1.0;
        let r = SMatrix::<f64, 2, 2>::new(2.0, 0.5, 0.5, 1.0);
        let mut pa = p;
        augment_covariance(&mut pa, [idx::CLK, idx::CLK_DRIFT], &h, &r);
        let mut h0 = h;
        h0.column_mut(idx::CLK).fill(0.0);
        h0.column_mut(idx::CLK_DRIFT).fill(0.0);
        let lp = {
            // P has zero rows at the clock: factor the 26×26 part through eigenvectors.
            let e = p.symmetric_eigen();
            e.eigenvectors * Covariance::from_diagonal(&e.eigenvalues.map(|l| l.max(0.0).sqrt()))
        };
        let lr = r.cholesky().unwrap().l();
        let n = 20_000;
        let mut s = Covariance::zeros();
        for _ in 0..n {
            let z = SVector::<f64, NX>::from_fn(|_, _| StandardNormal.sample(&mut rng));
            let w = SVector::<f64, 2>::from_fn(|_, _| StandardNormal.sample(&mut rng));
            let mut dx = lp * z;
            let dc = -(h0 * dx) - lr * w;
            dx[idx::CLK] = dc[0];
            dx[idx::CLK_DRIFT] = dc[1];
            s += dx * dx.transpose();
        }
        s /= n as f64;
        for i in 0..NX {
            for j in 0..NX {
                let scale = (pa[(i, i)] * pa[(j, j)]).sqrt().max(1e-12);
                let d = (s[(i, j)] - pa[(i, j)]) / scale;
                assert!(
                    d.abs() < 5.0 * (2.0 / n as f64).sqrt(),
                    "({i},{j}): sample {} vs augmented {}",
                    s[(i, j)],
                    pa[(i, j)]
                );
            }
        }
    }
}
