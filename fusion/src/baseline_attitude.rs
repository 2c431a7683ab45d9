//! Dual-baseline GNSS attitude (paper 003, eq. 14–21): two perpendicular antenna baselines
//! AB and CD of known lengths; the carrier phase difference across a baseline to a satellite
//! gives the baseline's projection on the line of sight, `cos α = λ·Δφ/(2π d)` (Δφ in
//! radians; with Δφ in cycles, as `msgs::GnssSatellite::baseline_phase_cycles` carries it,
//! `d·cos α = λ·Δφ`). From the projections on several lines of sight both baseline vectors are
//! solved in ECEF, the third axis completes the triad, and the DCM gives heading, pitch, roll.
//!
//! Conventions (the simulator's, `drivers-sim/src/gnss.rs`): AB lies along body x (forward),
//! CD along body y (right), so `b_AB^e = C_e_b·(d_AB, 0, 0)`, `b_CD^e = C_e_b·(0, d_CD, 0)`,
//! and the third body axis is `z = x × y = AB × CD / (d_AB d_CD)` (the paper's `CD × AB` is the
//! same axis in its north-up-east / OXYZ frames, where the second body axis points up). The
//! phase to satellite k is `Δφ_k = b·u_k/λ + ε`, `u_k` the unit line of sight from the
//! receiver to the satellite in ECEF, ε white with σ_φ cycles.
//!
//! **Integer ambiguity**: this module takes phases whose integers are resolved. A receiver's
//! phases carry an unknown integer per satellite and baseline (and cycle slips): resolve them
//! first with [`crate::phase_ambiguity`] (a search constrained by the known baseline lengths,
//! held across epochs), which calls this solver on `φ − N`.
//!
//! Solution:
//! 1. unconstrained linear least squares for each baseline, `U b = λ Δφ` (needs ≥ 3 lines of
//!    sight not in one plane), orthonormalised (Gram–Schmidt, x first) into a first `C_e_b`;
//!    or a caller-supplied prior (then 2 satellites suffice: 4 equations, 3 unknowns);
//! 2. Gauss–Newton on the rotation with both constraints built in (`|b_AB| = d_AB`,
//!    `|b_CD| = d_CD`, `AB ⊥ CD` hold by construction): with `C_e_b = (I + [δ×])·Ĉ`, the
//!    phase row is `∂(u·b)/∂δ = (b × u)ᵀ`, weights `1/(λσ_φ)²`;
//! 3. covariance `(JᵀWJ)⁻¹` of the small ECEF rotation `ε_e` with
//!    `C_e_b,est = (I + [ε_e×])·C_e_b,true`, rotated into NED and mapped to roll/pitch/heading.
//!
//! The attitude σ therefore scales as `λσ_φ/d` (cycles), i.e. `λσ_φ,rad/(2π d)`, divided by a
//! geometry factor of the lines of sight. Pure, stack only.

use crate::attitude::{quat_from_rotation_vector, rpy_from_c_n_b};
use crate::earth;
use msgs::{GnssSample, MAX_SATELLITES};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// Satellite flag bit (msgs::GnssSatellite::flags): baseline phases valid.
pub const FLAG_PHASE: u32 = 4;

/// Why no baseline attitude could be computed.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum BaselineAttitudeError {
    /// Not enough satellites with phases (3 without a prior, 2 with one).
    #[error("{have} satellites with baseline phases, need at least {need}")]
    TooFewSatellites {
        /// Usable satellites.
        have: usize,
        /// Needed.
        need: usize,
    },
    /// The lines of sight do not determine the attitude (coplanar / collinear).
    #[error("singular line-of-sight geometry: {0}")]
    SingularGeometry(&'static str),
    /// Gauss–Newton did not converge.
    #[error(
        "baseline attitude did not converge in {iterations} iterations (last step {last_step_rad:.3e} rad)"
    )]
    NoConvergence {
        /// Iterations made.
        iterations: usize,
        /// Norm of the last rotation step, rad.
        last_step_rad: f64,
    },
    /// A configuration or measurement value cannot be physical.
    #[error("invalid {field} = {value}")]
    Invalid {
        /// Which value (with satellite index when per satellite).
        field: &'static str,
        /// The value.
        value: f64,
    },
}

/// Antenna geometry and phase noise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BaselineConfig {
    /// Lengths of AB (body x) and CD (body y), m.
    pub baseline_length_m: [f64; 2],
    /// Carrier wavelength, m.
    pub wavelength_m: f64,
    /// 1-σ noise of each phase difference, cycles.
    pub sigma_phase_cycles: f64,
}

/// One satellite: unit line of sight and the two phase differences.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PhaseObservation {
    /// Unit vector from the receiver to the satellite, ECEF.
    pub los_e: Vector3<f64>,
    /// Phase differences across AB and CD, cycles (ambiguity resolved).
    pub phase_cycles: [f64; 2],
}

/// Up to [`MAX_SATELLITES`] phase observations (fixed-size).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhaseObservations {
    obs: [PhaseObservation; MAX_SATELLITES],
    n: usize,
}

impl Default for PhaseObservations {
    fn default() -> Self {
        Self {
            obs: [PhaseObservation::default(); MAX_SATELLITES],
            n: 0,
        }
    }
}

impl PhaseObservations {
    /// Add one observation; the line of sight is normalised. Fails on non-finite values.
    pub fn push(&mut self, o: PhaseObservation) -> Result<(), BaselineAttitudeError> {
        let norm = o.los_e.norm();
        if !(norm.is_finite() && norm > 0.0) {
            return Err(BaselineAttitudeError::Invalid {
                field: "line of sight norm",
                value: norm,
            });
        }
        for p in o.phase_cycles {
            if !p.is_finite() {
                return Err(BaselineAttitudeError::Invalid {
                    field: "phase_cycles",
                    value: p,
                });
            }
        }
        if self.n < MAX_SATELLITES {
            self.obs[self.n] = PhaseObservation {
                los_e: o.los_e / norm,
                ..o
            };
            self.n += 1;
        }
        Ok(())
    }

    /// The phase observations of a receiver message, with lines of sight from the receiver
    /// position `r_e_m` (ECEF, m; a few metres of error change them by ~1e-7 rad, negligible).
    /// Satellites without the phase flag are skipped.
    pub fn from_sample(
        sample: &GnssSample,
        r_e_m: &Vector3<f64>,
    ) -> Result<Self, BaselineAttitudeError> {
        let mut out = Self::default();
        let n = (sample.n_satellites as usize).min(MAX_SATELLITES);
        for s in &sample.satellites[..n] {
            if s.flags & FLAG_PHASE == 0 {
                continue;
            }
            out.push(PhaseObservation {
                los_e: Vector3::from(s.sat_pos_ecef_m) - r_e_m,
                phase_cycles: s.baseline_phase_cycles,
            })?;
        }
        Ok(out)
    }

    /// The observations.
    pub fn as_slice(&self) -> &[PhaseObservation] {
        &self.obs[..self.n]
    }

    /// Number of observations.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }
}

/// Dual-baseline attitude with its covariance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BaselineAttitude {
    /// Body → ECEF DCM.
    pub c_e_b: Matrix3<f64>,
    /// The same as a quaternion.
    pub q_e_b: UnitQuaternion<f64>,
    /// Body → NED DCM at the receiver position given to [`solve`].
    pub c_n_b: Matrix3<f64>,
    /// `[roll, pitch, heading]`, rad.
    pub rpy_rad: Vector3<f64>,
    /// Covariance of the attitude error `ε_e` (`C_e_b,est = (I + [ε_e×])·C_e_b,true`), rad².
    pub cov_e_rad2: Matrix3<f64>,
    /// The same error resolved in NED (`ε_n = C_n_e ε_e`), rad².
    pub cov_n_rad2: Matrix3<f64>,
    /// Covariance of `[roll, pitch, heading]`, rad².
    pub cov_rpy_rad2: Matrix3<f64>,
    /// Weighted sum of squared post-fit phase residuals, χ² with 2n − 3 degrees of freedom.
    pub chi2: f64,
    /// Satellites used.
    pub n_used: usize,
    /// Gauss–Newton iterations.
    pub iterations: usize,
}

fn check_config(cfg: &BaselineConfig) -> Result<(), BaselineAttitudeError> {
    let bad = |field, value| Err(BaselineAttitudeError::Invalid { field, value });
    for d in cfg.baseline_length_m {
        if !(d.is_finite() && d > 0.0) {
            return bad("baseline_length_m", d);
        }
    }
    if !(cfg.wavelength_m.is_finite() && cfg.wavelength_m > 0.0) {
        return bad("wavelength_m", cfg.wavelength_m);
    }
    if !(cfg.sigma_phase_cycles.is_finite() && cfg.sigma_phase_cycles > 0.0) {
        return bad("sigma_phase_cycles", cfg.sigma_phase_cycles);
    }
    Ok(())
}

/// Unconstrained least-squares baseline `b` (ECEF, m) from `u_k·b = λΔφ_k`.
fn unconstrained(
    obs: &[PhaseObservation],
    k: usize,
    wavelength_m: f64,
) -> Result<Vector3<f64>, BaselineAttitudeError> {
    let mut n = Matrix3::zeros();
    let mut y = Vector3::zeros();
    for o in obs {
        n += o.los_e * o.los_e.transpose();
        y += o.los_e * (wavelength_m * o.phase_cycles[k]);
    }
    let inv = n
        .try_inverse()
        .ok_or(BaselineAttitudeError::SingularGeometry(
            "lines of sight in one plane",
        ))?;
    // Condition: the smallest eigenvalue of ΣuuT must not vanish (coplanar lines of sight).
    if !(inv.norm().is_finite() && inv.norm() < 1e8) {
        return Err(BaselineAttitudeError::SingularGeometry(
            "lines of sight nearly in one plane",
        ));
    }
    Ok(inv * y)
}

/// Gram–Schmidt: the DCM whose x column is along `a`, y along the part of `c` ⊥ `a`.
pub(crate) fn triad(
    a: &Vector3<f64>,
    c: &Vector3<f64>,
) -> Result<Matrix3<f64>, BaselineAttitudeError> {
    let x = a
        .try_normalize(1e-12)
        .ok_or(BaselineAttitudeError::SingularGeometry("zero baseline AB"))?;
    let y =
        (c - x * x.dot(c))
            .try_normalize(1e-12)
            .ok_or(BaselineAttitudeError::SingularGeometry(
                "baselines AB and CD parallel",
            ))?;
    let z = x.cross(&y);
    Ok(Matrix3::from_columns(&[x, y, z]))
}

/// Dual-baseline attitude from the phase observations `obs` with antenna configuration `cfg`,
/// at receiver position `r_e_m` (ECEF, m; used only for the NED angles). With `prior_c_e_b`
/// the iteration starts there (two satellites suffice); without, at least three are needed.
pub fn solve(
    obs: &PhaseObservations,
    cfg: &BaselineConfig,
    r_e_m: &Vector3<f64>,
    prior_c_e_b: Option<&Matrix3<f64>>,
) -> Result<BaselineAttitude, BaselineAttitudeError> {
    check_config(cfg)?;
    let o = obs.as_slice();
    let need = if prior_c_e_b.is_some() { 2 } else { 3 };
    if o.len() < need {
        return Err(BaselineAttitudeError::TooFewSatellites {
            have: o.len(),
            need,
        });
    }
    let lam = cfg.wavelength_m;
    let [d_ab, d_cd] = cfg.baseline_length_m;
    let mut c = match prior_c_e_b {
        Some(p) => Rotation3::from_matrix(p).into_inner(),
        None => triad(&unconstrained(o, 0, lam)?, &unconstrained(o, 1, lam)?)?,
    };
    let w = 1.0 / (lam * cfg.sigma_phase_cycles).powi(2);
    let max_iterations = 20;
    let tol_rad = 1e-12;
    let mut iterations = 0;
    let mut last_step = f64::INFINITY;
    let mut normal = Matrix3::zeros();
    while iterations < max_iterations {
        iterations += 1;
        let b = [c.column(0) * d_ab, c.column(1) * d_cd];
        normal = Matrix3::zeros();
        let mut g = Vector3::zeros();
        for ob in o {
            for (k, bk) in b.iter().enumerate() {
                let j = bk.cross(&ob.los_e);
                let r = lam * ob.phase_cycles[k] - bk.dot(&ob.los_e);
                normal += w * j * j.transpose();
                g += w * r * j;
            }
        }
        let inv = normal
            .try_inverse()
            .ok_or(BaselineAttitudeError::SingularGeometry(
                "attitude not observable from these lines of sight",
            ))?;
        let delta = inv * g;
        if !delta.iter().all(|v| v.is_finite()) {
            return Err(BaselineAttitudeError::SingularGeometry(
                "attitude not observable from these lines of sight",
            ));
        }
        c = quat_from_rotation_vector(&delta)
            .to_rotation_matrix()
            .into_inner()
            * c;
        last_step = delta.norm();
        if last_step < tol_rad {
            break;
        }
    }
    if last_step >= tol_rad && last_step > 1e-9 {
        return Err(BaselineAttitudeError::NoConvergence {
            iterations,
            last_step_rad: last_step,
        });
    }
    // Re-orthonormalise against accumulated rounding.
    let c = Rotation3::from_matrix(&c).into_inner();
    let cov_e = normal
        .try_inverse()
        .ok_or(BaselineAttitudeError::SingularGeometry(
            "final normal matrix",
        ))?;
    let b = [c.column(0) * d_ab, c.column(1) * d_cd];
    let mut chi2 = 0.0;
    for ob in o {
        for (k, bk) in b.iter().enumerate() {
            let r = lam * ob.phase_cycles[k] - bk.dot(&ob.los_e);
            chi2 += w * r * r;
        }
    }
    let geo = earth::ecef_to_geodetic(&earth::WGS84, r_e_m);
    let c_e_n = earth::c_e_n(geo.lat_rad, geo.lon_rad);
    let c_n_b = c_e_n.transpose() * c;
    let cov_n = c_e_n.transpose() * cov_e * c_e_n;
    let rpy = rpy_from_c_n_b(&c_n_b);
    let e = euler_rate_matrix(rpy.x, rpy.y, rpy.z);
    let cov_rpy = match e.try_inverse() {
        Some(ei) => ei * cov_n * ei.transpose(),
        None => Matrix3::from_element(f64::INFINITY),
    };
    Ok(BaselineAttitude {
        c_e_b: c,
        q_e_b: UnitQuaternion::from_matrix(&c),
        c_n_b,
        rpy_rad: rpy,
        cov_e_rad2: cov_e,
        cov_n_rad2: cov_n,
        cov_rpy_rad2: cov_rpy,
        chi2,
        n_used: o.len(),
        iterations,
    })
}

/// `E` with `ε_n = E·[δroll, δpitch, δheading]` for a left small rotation of
/// `C_n_b = R_z(ψ)R_y(θ)R_x(φ)`: columns `R_z R_y e_x`, `R_z e_y`, `e_z`. Singular at
/// pitch ±90°.
pub fn euler_rate_matrix(_roll: f64, pitch: f64, heading: f64) -> Matrix3<f64> {
    let (sp, cp) = pitch.sin_cos();
    let (sh, ch) = heading.sin_cos();
    Matrix3::new(ch * cp, -sh, 0.0, sh * cp, ch, 0.0, -sp, 0.0, 1.0)
}

/// Small rotation `ε` (rad) with `a ≈ (I + [ε×])·b` for two nearby DCMs.
pub fn small_rotation_between(a: &Matrix3<f64>, b: &Matrix3<f64>) -> Vector3<f64> {
    let m = a * b.transpose();
    let s = 0.5 * (m - m.transpose());
    Vector3::new(s[(2, 1)], s[(0, 2)], s[(1, 0)])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::attitude::c_n_b_from_rpy;
    use crate::earth::{Geodetic, WGS84, c_e_n, geodetic_to_ecef};
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    use crate::test_sky::{L1_WAVELENGTH_M, SKY_AZ_EL_DEG as SKY};

    fn site() -> (Vector3<f64>, Matrix3<f64>) {
        let g = Geodetic {
            lat_rad: 55.655f64.to_radians(),
            lon_rad: 37.534f64.to_radians(),
            height_m: 200.0,
        };
        (geodetic_to_ecef(&WGS84, &g), c_e_n(g.lat_rad, g.lon_rad))
    }

    fn los(c_e_n: &Matrix3<f64>, az_deg: f64, el_deg: f64) -> Vector3<f64> {
        let (az, el) = (az_deg.to_radians(), el_deg.to_radians());
        c_e_n * Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), -el.sin())
    }

    fn observations(
        c_e_b: &Matrix3<f64>,
        cfg: &BaselineConfig,
        sky: &[(f64, f64)],
        noise: Option<&mut rand_chacha::ChaCha8Rng>,
    ) -> PhaseObservations {
        let (_, cen) = site();
        let b = [
            c_e_b * Vector3::new(cfg.baseline_length_m[0], 0.0, 0.0),
            c_e_b * Vector3::new(0.0, cfg.baseline_length_m[1], 0.0),
        ];
        let mut rng = noise;
        let mut out = PhaseObservations::default();
        for &(az, el) in sky {
            let u = los(&cen, az, el);
            let mut ph = [0.0; 2];
            for k in 0..2 {
                ph[k] = b[k].dot(&u) / cfg.wavelength_m;
                if let Some(r) = rng.as_deref_mut() {
                    let z: f64 = StandardNormal.sample(r);
                    ph[k] += cfg.sigma_phase_cycles * z;
                }
            }
            out.push(PhaseObservation {
                los_e: u,
                phase_cycles: ph,
            })
            .unwrap();
        }
        out
    }

    #[test]
    fn exact_on_noise_free_data() {
        let (r, cen) = site();
        let cfg = BaselineConfig {
            baseline_length_m: [1.0, 0.7],
            wavelength_m: L1_WAVELENGTH_M,
            sigma_phase_cycles: 0.01,
        };
        for &(roll, pitch, heading) in &[
            (0.0, 0.0, 0.0),
            (0.05, -0.1, 1.0),
            (-0.3, 0.2, -2.8),
            (0.0, 0.0, 3.1),
        ] {
            let c_n_b = c_n_b_from_rpy(roll, pitch, heading);
            let c_e_b = cen * c_n_b;
            let obs = observations(&c_e_b, &cfg, &SKY, None);
            let a = solve(&obs, &cfg, &r, None).unwrap();
            assert!((a.c_n_b - c_n_b).norm() < 1e-10, "{}", a.c_n_b - c_n_b);
            assert!((a.rpy_rad - Vector3::new(roll, pitch, heading)).norm() < 1e-10);
            assert!(a.chi2 < 1e-12);
            // With a prior and only two satellites.
            let two = observations(&c_e_b, &cfg, &SKY[1..3], None);
            let prior = quat_from_rotation_vector(&Vector3::new(0.02, -0.01, 0.03))
                .to_rotation_matrix()
                .into_inner()
                * c_e_b;
            let a2 = solve(&two, &cfg, &r, Some(&prior)).unwrap();
            assert!((a2.c_e_b - c_e_b).norm() < 1e-9);
            assert!(solve(&two, &cfg, &r, None).is_err());
        }
    }

    /// Monte Carlo: the covariance (JᵀWJ)⁻¹ matches the spread. For each NED axis the sum of
    /// ε²/σ² over N trials is χ²(N): accepted N ± 4√(2N); the whole-vector NEES sum is
    /// χ²(3N). And σ scales as λσ_φ/d: doubling d halves every σ, doubling σ_φ doubles it.
    #[test]
    fn sigma_matches_monte_carlo() {
        let (r, cen) = site();
        let cfg = BaselineConfig {
            baseline_length_m: [1.0, 1.0],
            wavelength_m: L1_WAVELENGTH_M,
            sigma_phase_cycles: 0.01,
        };
        let c_e_b = cen * c_n_b_from_rpy(0.02, -0.03, 0.7);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let n = 2000;
        let mut z2 = Vector3::<f64>::zeros();
        let mut nees = 0.0;
        let mut cov_n = Matrix3::zeros();
        for _ in 0..n {
            let obs = observations(&c_e_b, &cfg, &SKY, Some(&mut rng));
            let a = solve(&obs, &cfg, &r, None).unwrap();
            let eps_e = small_rotation_between(&a.c_e_b, &c_e_b);
            let eps_n = cen.transpose() * eps_e;
            for k in 0..3 {
                z2[k] += eps_n[k] * eps_n[k] / a.cov_n_rad2[(k, k)];
            }
            nees += eps_e.dot(&(a.cov_e_rad2.try_inverse().unwrap() * eps_e));
            cov_n = a.cov_n_rad2;
        }
        let nf = n as f64;
        for k in 0..3 {
            assert!(
                (z2[k] - nf).abs() < 4.0 * (2.0 * nf).sqrt(),
                "axis {k}: Σz² {} vs {nf}",
                z2[k]
            );
        }
        assert!(
            (nees - 3.0 * nf).abs() < 4.0 * (6.0 * nf).sqrt(),
            "NEES {nees}"
        );
        // Predicted σ scaling (exact: J is linear in d, W in 1/σ_φ²).
        let obs = observations(&c_e_b, &cfg, &SKY, None);
        let base = solve(&obs, &cfg, &r, None).unwrap();
        // J is evaluated at the estimate, so it differs from trial to trial by O(|ε|) ≈ 3σ ≈ 6e-3
        // relative (σ ≈ λσ_φ/d = 1.9e-3 rad).
        assert!((base.cov_n_rad2 - cov_n).norm() < 2e-2 * cov_n.norm());
        let cfg2 = BaselineConfig {
            baseline_length_m: [2.0, 2.0],
            ..cfg
        };
        let a2 = solve(&observations(&c_e_b, &cfg2, &SKY, None), &cfg2, &r, None).unwrap();
        assert!((a2.cov_n_rad2 * 4.0 - base.cov_n_rad2).norm() < 1e-9 * base.cov_n_rad2.norm());
        // Heading σ against the closed form: for a level body the heading row of each phase is
        // d·(u_k · horizontal ⊥ baseline), and the two perpendicular baselines together give
        // Σ_k d² cos² el_k of information, so the σ *conditional* on a known tilt is
        // λσ_φ/(d √Σcos² el). The marginal σ (tilt estimated too) can only be larger.
        let s_h = base.cov_rpy_rad2[(2, 2)].sqrt();
        let sum_cos2: f64 = SKY
            .iter()
            .map(|&(_, el)| el.to_radians().cos().powi(2))
            .sum();
        let conditional = L1_WAVELENGTH_M * 0.01 / (1.0 * sum_cos2.sqrt());
        assert!(s_h >= conditional * (1.0 - 1e-9), "{s_h} vs {conditional}");
        eprintln!(
            "heading σ {:.4e} rad, conditional closed form {conditional:.4e} rad",
            s_h
        );
    }

    #[test]
    fn rejects_bad_input() {
        let (r, cen) = site();
        let cfg = BaselineConfig {
            baseline_length_m: [1.0, 1.0],
            wavelength_m: L1_WAVELENGTH_M,
            sigma_phase_cycles: 0.01,
        };
        let obs = observations(&cen, &cfg, &SKY, None);
        let bad = BaselineConfig {
            sigma_phase_cycles: 0.0,
            ..cfg
        };
        assert!(matches!(
            solve(&obs, &bad, &r, None),
            Err(BaselineAttitudeError::Invalid { .. })
        ));
        let mut o = PhaseObservations::default();
        assert!(
            o.push(PhaseObservation {
                los_e: Vector3::new(1.0, 0.0, 0.0),
                phase_cycles: [f64::NAN, 0.0],
            })
            .is_err()
        );
        // Three lines of sight in one vertical plane: the baseline component normal to the
        // plane is unobservable.
        let plane = [(10.0, 20.0), (10.0, 50.0), (190.0, 30.0)];
        let obs = observations(&cen, &cfg, &plane, None);
        assert!(matches!(
            solve(&obs, &cfg, &r, None),
            Err(BaselineAttitudeError::SingularGeometry(_))
        ));
    }
}
