//! Gauss–Newton least squares for the boresight κ over all samples of a static record at a
//! known site (the estimator next to the paper's three stages; model in the parent module's
//! comment, "Least squares").

use super::{BoresightSample, Site, c_s_b_nominal, check_inputs, icrf_to_ecef, kappa_matrix};
use crate::astro_fix::{AstroError, down_b};
use crate::frames::{Ecef, Vector};
use nalgebra::{Matrix2, Matrix3, Matrix3x2, Vector2, Vector3};

/// Error model and prior of the least-squares estimator (1-σ, rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LeastSquaresSettings {
    /// Star-tracker attitude noise across the optical axis (sensor x, y).
    pub sigma_tracker_cross_rad: f64,
    /// Star-tracker attitude noise about the optical axis (sensor z).
    pub sigma_tracker_roll_rad: f64,
    /// White noise of the IMU's vertical per sample, each horizontal axis.
    pub sigma_tilt_rad: f64,
    /// Prior κ (normally stage 1's), rad.
    pub kappa_prior_rad: Vector3<f64>,
    /// Prior σ of each κ, rad.
    pub sigma_prior_rad: f64,
    /// Largest number of Gauss–Newton iterations.
    pub max_iterations: usize,
}

/// Least-squares estimate of κ.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LeastSquaresResult {
    /// Estimated κ, rad.
    pub kappa_rad: Vector3<f64>,
    /// Covariance of κ̂ (white-noise model plus prior), rad².
    pub covariance_rad2: Matrix3<f64>,
    /// Gauss–Newton iterations done.
    pub iterations: usize,
    /// Weighted residual sum of squares per degree of freedom (≈ 1 when the noise model holds).
    pub chi2_per_dof: f64,
    /// Samples used.
    pub samples: usize,
    /// The observable part: the body z (down) axis in the nominal sensor axes through the
    /// mounting, `v = M(κ̂)·ẑ`, as the two small angles `(v_x, v_y)` (rad) ([`mounting_tilt_rad`]).
    pub tilt_rad: Vector2<f64>,
    /// Covariance of `tilt_rad`, rad².
    pub tilt_covariance_rad2: Matrix2<f64>,
}

impl LeastSquaresResult {
    /// 1-σ of each κ, rad.
    pub fn sigma_rad(&self) -> Vector3<f64> {
        Vector3::new(
            self.covariance_rad2[(0, 0)].max(0.0).sqrt(),
            self.covariance_rad2[(1, 1)].max(0.0).sqrt(),
            self.covariance_rad2[(2, 2)].max(0.0).sqrt(),
        )
    }
}

/// The tilt of the mounting, the part of κ a static level record observes: the body z axis
/// in the nominal sensor axes, `v = M(κ)·ẑ`, as `(v_x, v_y)` (rad for small angles). A
/// rotation of the mounting about the vertical (≈ κ1, but for a tilted mounting a mix of all
/// three angles) leaves it unchanged, which is why κ1..κ3 individually are correlated.
pub fn mounting_tilt_rad(kappa_rad: &Vector3<f64>) -> Vector2<f64> {
    let v = kappa_matrix(kappa_rad) * Vector3::z();
    Vector2::new(v.x, v.y)
}

/// Two unit vectors completing `d` (unit) to an orthonormal basis.
fn tangent_basis(d: &Vector3<f64>) -> Matrix3x2<f64> {
    let a = if d.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = d.cross(&a).normalize();
    let e2 = d.cross(&e1);
    Matrix3x2::from_columns(&[e1, e2])
}

/// Gauss–Newton least squares for κ over all `samples` at the known `site` (module comment).
///
/// Residual of sample k, a small angle in the plane across the vertical:
/// `r_k = Tᵀ (d_model × d_meas)`, `d_meas = c_s_i c_e_iᵀ d_e(site)`,
/// `d_model = c_s_b(κ) d_b(γ_k, θ_k)`, T a basis across `d_model`; its covariance
/// `Tᵀ([d×] diag(σc², σc², σr²) [d×]ᵀ + σ_t² (I − d dᵀ)) T`. Normal equations with the prior:
/// `(Σ Jᵀ R⁻¹ J + P₀⁻¹) Δκ = −Σ Jᵀ R⁻¹ r − P₀⁻¹ (κ − κ₀)`; the inverse of the left matrix is
/// the covariance of κ̂. Stops when every component of the step is below 10⁻³ of its σ
/// (further iterations could not change the estimate measurably; an absolute bound is not
/// usable because the unobservable direction is conditioned ≈ 10⁸ worse than the others).
pub fn least_squares(
    samples: &[BoresightSample],
    c_e_i: &[Matrix3<f64>],
    site: &Site,
    settings: &LeastSquaresSettings,
) -> Result<LeastSquaresResult, AstroError> {
    check_inputs(samples, c_e_i, site)?;
    for (what, v) in [
        ("sigma_tracker_cross_rad", settings.sigma_tracker_cross_rad),
        ("sigma_tracker_roll_rad", settings.sigma_tracker_roll_rad),
        ("sigma_tilt_rad", settings.sigma_tilt_rad),
        ("sigma_prior_rad", settings.sigma_prior_rad),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(AstroError::InvalidSetting {
                what,
                reason: format!("{v} is not > 0"),
            });
        }
    }
    if settings.kappa_prior_rad.iter().any(|k| !k.is_finite()) {
        return Err(AstroError::NotFinite {
            what: "kappa_prior_rad",
        });
    }
    let down_e_site = -crate::earth::up_e(site.lat_rad, site.lon_rad);
    let d_meas: Vec<Vector3<f64>> = samples
        .iter()
        .zip(c_e_i)
        .map(|(s, c)| {
            let d_e = Vector::<Ecef>::new(down_e_site);
            (s.icrf_to_sensor() * (icrf_to_ecef(c).inverse() * d_e)).into_coords()
        })
        .collect();
    let d_b: Vec<Vector3<f64>> = samples
        .iter()
        .map(|s| down_b(s.roll_rad, s.pitch_rad))
        .collect();
    let s_eps = Matrix3::from_diagonal(&Vector3::new(
        settings.sigma_tracker_cross_rad.powi(2),
        settings.sigma_tracker_cross_rad.powi(2),
        settings.sigma_tracker_roll_rad.powi(2),
    ));
    let p0_inv = Matrix3::identity() / settings.sigma_prior_rad.powi(2);
    let nom = c_s_b_nominal();
    let mut kappa = settings.kappa_prior_rad;
    let mut normal = p0_inv;
    let mut chi2 = 0.0;
    let mut iterations = 0;
    let h = 1e-6;
    for _ in 0..settings.max_iterations.max(1) {
        let m = kappa_matrix(&kappa);
        // ∂M/∂κ_j by central differences (M is smooth; h = 1e-6 rad gives ~1e-12 accuracy).
        let dm: [Matrix3<f64>; 3] = std::array::from_fn(|j| {
            let mut kp = kappa;
            let mut km = kappa;
            kp[j] += h;
            km[j] -= h;
            (kappa_matrix(&kp) - kappa_matrix(&km)) / (2.0 * h)
        });
        normal = p0_inv;
        let mut rhs = -(p0_inv * (kappa - settings.kappa_prior_rad));
        chi2 = 0.0;
        for (dm_k, db) in d_meas.iter().zip(&d_b) {
            let d_model = nom * (m * db);
            let t = tangent_basis(&d_model);
            let r: Vector2<f64> = t.transpose() * d_model.cross(dm_k);
            let dx = crate::attitude::skew(&d_model);
            let cov3 = dx * s_eps * dx.transpose()
                + (Matrix3::identity() - d_model * d_model.transpose())
                    * settings.sigma_tilt_rad.powi(2);
            let cov: Matrix2<f64> = t.transpose() * cov3 * t;
            let Some(w) = cov.try_inverse() else {
                continue;
            };
            let mut jac = nalgebra::Matrix2x3::zeros();
            for (j, dm_j) in dm.iter().enumerate() {
                let dd = nom * (dm_j * db);
                jac.set_column(j, &(t.transpose() * dd.cross(dm_k)));
            }
            normal += jac.transpose() * w * jac;
            rhs -= jac.transpose() * (w * r);
            chi2 += (r.transpose() * w * r)[(0, 0)];
        }
        let Some(step) = normal.lu().solve(&rhs) else {
            return Err(AstroError::InvalidSetting {
                what: "samples",
                reason: "singular normal equations".into(),
            });
        };
        kappa += step;
        iterations += 1;
        let converged = normal
            .try_inverse()
            .is_some_and(|p| (0..3).all(|j| step[j].abs() < 1e-3 * p[(j, j)].max(0.0).sqrt()));
        if converged {
            break;
        }
    }
    let covariance_rad2 = normal
        .try_inverse()
        .unwrap_or_else(|| Matrix3::from_element(f64::NAN));
    let dof = (2 * samples.len()).saturating_sub(3).max(1) as f64;
    let mut g = nalgebra::Matrix2x3::zeros();
    for j in 0..3 {
        let mut kp = kappa;
        let mut km = kappa;
        kp[j] += h;
        km[j] -= h;
        g.set_column(
            j,
            &((mounting_tilt_rad(&kp) - mounting_tilt_rad(&km)) / (2.0 * h)),
        );
    }
    Ok(LeastSquaresResult {
        kappa_rad: kappa,
        covariance_rad2,
        iterations,
        chi2_per_dof: chi2 / dof,
        samples: samples.len(),
        tilt_rad: mounting_tilt_rad(&kappa),
        tilt_covariance_rad2: g * covariance_rad2 * g.transpose(),
    })
}
