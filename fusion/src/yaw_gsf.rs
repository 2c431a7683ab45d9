//! Heading alignment in motion from GNSS velocity, without a heading sensor: a Gaussian sum
//! filter (GSF) over a bank of yaw hypotheses, the method of PX4's `ekf2` yaw estimator
//! (EKF-GSF, P. Riseborough 2020) with the per-hypothesis tilt estimated inside each EKF.
//!
//! # Why a bank
//! With GNSS velocity as the only aiding, the heading error ψ_D enters the horizontal
//! velocity error only through the horizontal acceleration (`δv̇_N = −g φ_E − a_E ψ_D`,
//! `δv̇_E = g φ_N + a_N ψ_D`): it is observable during turns and speed changes, not on a
//! straight line at constant speed, and one EKF started with a heading error of tens of
//! degrees diverges (the linearisation `sin ψ ≈ ψ` fails). N EKFs started at headings
//! `ψ_k = 2π k / N`: the nearest sees an error of at most π/N; it explains the GNSS
//! velocities best, and the Gaussian-sum weights pick it.
//!
//! # One hypothesis (a 5-state error-state EKF in local NED)
//! Nominal: attitude `q_n_b` (body → NED) and horizontal velocity `v_ne`, mechanised with the
//! IMU increments: `C_n_b ← R(−ω_ie^n Δt) · C_n_b · exp([Δθ×])`,
//! `v_ne += [C_n_b(mid) Δv]_NE + [−2 ω_ie^n × v]_NE Δt` (ω_ie^n = Ω (cos L, 0, −sin L) at
//! the start latitude; gravity has no horizontal component; the transport rate, ≤ 2.4·10⁻⁶
//! rad/s at 15 m/s, is below a tactical gyro's bias and left out).
//! Error state `x = (δv_N, δv_E, φ_N, φ_E, φ_D)`, with the truth `C = exp([φ×]) Ĉ` and
//! `δv = v − v̂`: `δv̇ = (−[f̂_n×] φ)_NE + Coriolis`, `φ̇ = −[ω_ie^n×] φ − Ĉ n_g`.
//! Process noise per step: velocity `VRW²·Δt`, attitude `ARW²·Δt + 2 σ_bg² t Δt` (the
//! second term makes the marginal variance of an unestimated constant gyro bias, `(σ_bg t)²`,
//! grow as it does). The tilt φ_N, φ_E is therefore estimated from the same velocities (it
//! is observable through gravity at all times) rather than by a separate complementary
//! filter as in PX4; a horizontal accelerometer bias is indistinguishable from tilt
//! (`b = g φ`), so the reported tilt variance carries `(σ_ba/g)²` on top.
//!
//! Update with a GNSS horizontal velocity `z` (antenna lever-arm velocity `v_l = ω_b × l_b`,
//! body): `h = v̂ + [Ĉ v_l]_NE`, `H = [I₂ | (−[(Ĉ v_l)×])_NE]`, innovation `ν = z − h`,
//! `S = H P Hᵀ + R`, `K = P Hᵀ S⁻¹`, Joseph-form covariance; the correction is applied to
//! the nominal state (`v̂ += δv`, `q ← exp(φ) q`) and the error reset to zero.
//!
//! # Gaussian sum (Alspach & Sorenson 1972)
//! Each update multiplies hypothesis k's weight by its innovation likelihood
//! `N(ν_k; 0, S_k) = exp(−½ ν_kᵀ S_k⁻¹ ν_k) / (2π √det S_k)` and normalises (kept as
//! logarithms, so that no weight underflows). The estimate is the moment-matched mixture:
//! the weighted mean attitude `q̄` (fixed point of `q̄ ← exp(Σ w_k d_k) q̄`,
//! `d_k = log(q_k q̄⁻¹)`, NED) and its error covariance `P = Σ w_k (P_φφ,k + d_k d_kᵀ)`; the
//! heading variance is `P_DD`. While the hypotheses disagree (no manoeuvre yet) the spread
//! term keeps it large: the heading is reported as unobservable, never as a wrong value.

use crate::frames::{Body, Ned, Rotation};
use nalgebra::{Matrix2, Matrix3, SMatrix, SVector, UnitQuaternion, Vector2, Vector3};
use std::f64::consts::PI;

/// Number of yaw hypotheses: spaced 30°, the nearest starts at most 15° from the truth (the
/// linearisation error of its first updates is second order in that; measured on the simulated
/// drives of the navigator's tests, 6 hypotheses gave a larger worst attitude NEES at the start,
/// 24 no smaller one).
pub const GSF_MODELS: usize = 12;

type Mat5 = SMatrix<f64, 5, 5>;
type Vec5 = SVector<f64, 5>;
type Mat2x5 = SMatrix<f64, 2, 5>;

/// The IMU error model the hypotheses propagate with (1-σ per axis).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct YawGsfNoise {
    /// Gyro angle random walk, rad/√s.
    pub arw_rad_sqrt_s: f64,
    /// Accelerometer velocity random walk, m/s/√s.
    pub vrw_m_s_sqrt_s: f64,
    /// Unestimated constant gyro bias, rad/s.
    pub gyro_bias_rad_s: f64,
    /// Unestimated constant accelerometer bias, m/s².
    pub accel_bias_m_s2: f64,
}

/// Where the bank starts: a levelled attitude (all headings) and one GNSS velocity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct YawGsfStart {
    /// Mean specific force over the levelling window, in the body axes at the start, m/s².
    pub f_b_m_s2: Vector3<f64>,
    /// Mean horizontal acceleration over the same window (north, east; the GNSS velocity
    /// change over it divided by its length), m/s²: taken out of the specific force by each
    /// hypothesis at its own heading.
    pub a_ne_m_s2: Vector2<f64>,
    /// 1-σ of the levelled roll and pitch about the horizontal axes
    /// ([`leveling_tilt_sigma_rad`]), rad.
    pub tilt_sigma_rad: f64,
    /// GNSS horizontal velocity (north, east), m/s.
    pub v_ne_m_s: Vector2<f64>,
    /// Its covariance, m²/s².
    pub p_vv_m2_s2: Matrix2<f64>,
    /// Specific-force increment between the velocity's epoch and the start, in the body axes
    /// at the start, m/s (zero when the velocity is of the start's epoch): each hypothesis
    /// adds it at its own attitude.
    pub dv_since_b_m_s: Vector3<f64>,
    /// Geodetic latitude (earth rate in NED), rad.
    pub lat_rad: f64,
    /// Earth rotation rate, rad/s.
    pub omega_ie_rad_s: f64,
    /// Local gravity magnitude, m/s².
    pub gravity_m_s2: f64,
}

/// Bad input to the yaw estimator, naming what was wrong.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum YawGsfError {
    /// The levelling specific force cannot give a tilt.
    #[error("levelling specific force {0:?} m/s² is not finite or too small to level with")]
    SpecificForce([f64; 3]),
    /// A noise, σ, latitude or gravity value out of its domain.
    #[error("{0} is not finite or out of range")]
    Parameter(&'static str),
    /// An IMU increment or interval not finite or not positive.
    #[error("IMU increment not finite or interval {0} s not positive")]
    Increment(f64),
    /// A GNSS velocity or its covariance not finite, or the covariance not positive definite.
    #[error("GNSS velocity or its covariance not finite / not positive definite")]
    Velocity,
}

/// The heading (and tilt) estimate of the bank.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct YawEstimate {
    /// Mixture mean attitude, body → local NED.
    pub c_n_b: Rotation<Body, Ned>,
    /// Heading of `c_n_b` (from north towards east), rad in (−π, π].
    pub yaw_rad: f64,
    /// 1-σ of the heading, rad.
    pub yaw_sigma_rad: f64,
    /// Covariance of the attitude error φ (NED, `C = exp([φ×]) Ĉ`), rad².
    pub p_att_n_rad2: Matrix3<f64>,
    /// Mixture mean horizontal velocity (north, east), m/s.
    pub v_ne_m_s: Vector2<f64>,
    /// Largest hypothesis weight (1/N: undecided, 1: one hypothesis left).
    pub max_weight: f64,
}

#[derive(Debug, Clone, Copy)]
struct Hypothesis {
    q_n_b: UnitQuaternion<f64>,
    v_ne_m_s: Vector2<f64>,
    p: Mat5,
    log_weight: f64,
}

/// The bank of yaw hypotheses (fixed size; nothing allocates).
#[derive(Debug, Clone, Copy)]
pub struct YawGsf {
    models: [Hypothesis; GSF_MODELS],
    noise: YawGsfNoise,
    omega_ie_n: Vector3<f64>,
    gravity_m_s2: f64,
    elapsed_s: f64,
}

/// 1-σ of roll and pitch levelled from the mean specific force of a window of `dt_s` seconds
/// with the horizontal acceleration over it taken out (the GNSS velocity change over the
/// window, velocity σ `sigma_v_m_s` per axis at both ends): the velocity noise leaves an
/// acceleration error of `√2 σ_v/Δt`, seen as a tilt of that over g, and an accelerometer bias
/// one of `σ_ba/g`. (The error of the hypothesis' own heading tilts it too, about the apparent
/// vertical: that part is carried in its prior covariance, [`YawGsf::new`].)
pub fn leveling_tilt_sigma_rad(
    dt_s: f64,
    sigma_v_m_s: f64,
    accel_bias_m_s2: f64,
    gravity_m_s2: f64,
) -> f64 {
    let n = 2f64.sqrt() * sigma_v_m_s / dt_s;
    (n * n + accel_bias_m_s2 * accel_bias_m_s2).sqrt() / gravity_m_s2
}

/// Roll and pitch (rad) of the attitude with heading `yaw_rad` that turns the apparent
/// vertical `u_n = a_n − g_n` (NED, any length) into the measured specific force `f_b` (body,
/// any length): `C_b_n(φ, θ, ψ) û = f̂`. Pitch from the x axis, `f̂_x = cos θ û_x − sin θ û_z`
/// (û in the heading frame, the solution nearer level), roll from the angle between the y–z
/// components. With `a_n = 0` this is the usual levelling `φ = atan2(−f_y, −f_z)`,
/// `θ = atan2(f_x, √(f_y² + f_z²))`.
pub fn level_at_heading(f_b: &Vector3<f64>, u_n: &Vector3<f64>, yaw_rad: f64) -> (f64, f64) {
    let f = f_b.normalize();
    let (sy, cy) = yaw_rad.sin_cos();
    let un = u_n.normalize();
    let u = Vector3::new(cy * un.x + sy * un.y, -sy * un.x + cy * un.y, un.z);
    let a = u.x.hypot(u.z);
    let alpha = u.z.atan2(u.x);
    let r = (f.x / a).clamp(-1.0, 1.0);
    let wrap = |x: f64| (x + PI).rem_euclid(2.0 * PI) - PI;
    let c1 = wrap(-alpha - r.acos());
    let c2 = wrap(-alpha + r.acos());
    let pitch = if c1.abs() <= c2.abs() { c1 } else { c2 };
    let (sp, cp) = pitch.sin_cos();
    let w = Vector3::new(cp * u.x - sp * u.z, u.y, sp * u.x + cp * u.z);
    let roll = wrap(w.z.atan2(w.y) - f.z.atan2(f.y));
    (roll, pitch)
}

fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

fn finite3(v: &Vector3<f64>) -> bool {
    v.iter().all(|x| x.is_finite())
}

impl YawGsf {
    /// A bank of [`GSF_MODELS`] hypotheses at headings `2π k/N`, each levelled at its heading
    /// from `start.f_b_m_s2` and the horizontal acceleration `start.a_ne_m_s2`
    /// ([`level_at_heading`]; without acceleration roll `atan2(−f_y, −f_z)`, pitch
    /// `atan2(f_x, √(f_y² + f_z²))`), with the GNSS velocity carried to the start at its
    /// attitude, equal weights and the prior covariance `P_vv` and
    /// `P_φ = σ_ε² û ûᵀ + σ_tilt² (I − û ûᵀ)`: a hypothesis levelled at a heading δψ off the
    /// truth is off by a rotation about the apparent vertical û = (a_n − g_n)/|a_n − g_n|
    /// (both attitudes turn û into the same specific force), of angle ε = δψ/|û_D|; δψ is at
    /// most half a spacing, σ_ε = (π/N)/|û_D|. Without acceleration û is the down axis and
    /// `P_φ = diag(σ_tilt², σ_tilt², (π/N)²)`.
    pub fn new(start: &YawGsfStart, noise: YawGsfNoise) -> Result<Self, YawGsfError> {
        let f = start.f_b_m_s2;
        if !finite3(&f) || f.norm() < 0.5 * start.gravity_m_s2 {
            return Err(YawGsfError::SpecificForce([f.x, f.y, f.z]));
        }
        let param = |ok: bool, what| {
            if ok {
                Ok(())
            } else {
                Err(YawGsfError::Parameter(what))
            }
        };
        let nonneg = |x: f64| x.is_finite() && x >= 0.0;
        param(
            start.tilt_sigma_rad.is_finite() && start.tilt_sigma_rad > 0.0,
            "tilt_sigma_rad",
        )?;
        param(start.lat_rad.abs() <= PI / 2.0, "lat_rad")?;
        param(nonneg(start.omega_ie_rad_s), "omega_ie_rad_s")?;
        param(
            start.gravity_m_s2.is_finite() && start.gravity_m_s2 > 1.0,
            "gravity_m_s2",
        )?;
        param(nonneg(noise.arw_rad_sqrt_s), "arw_rad_sqrt_s")?;
        param(nonneg(noise.vrw_m_s_sqrt_s), "vrw_m_s_sqrt_s")?;
        param(nonneg(noise.gyro_bias_rad_s), "gyro_bias_rad_s")?;
        param(nonneg(noise.accel_bias_m_s2), "accel_bias_m_s2")?;
        check_velocity(&start.v_ne_m_s, &start.p_vv_m2_s2)?;
        let a = start.a_ne_m_s2;
        let dv = start.dv_since_b_m_s;
        if !(a.iter().all(|x| x.is_finite()) && a.norm() < 0.5 * start.gravity_m_s2) {
            return Err(YawGsfError::Parameter("a_ne_m_s2"));
        }
        param(finite3(&dv), "dv_since_b_m_s")?;
        let u_n = Vector3::new(a.x, a.y, -start.gravity_m_s2);
        let u = u_n.normalize();
        let s2 = start.tilt_sigma_rad.powi(2);
        let s_eps = PI / GSF_MODELS as f64 / u.z.abs();
        let uu = u * u.transpose();
        let p_att = uu * (s_eps * s_eps) + (Matrix3::identity() - uu) * s2;
        let mut p = Mat5::zeros();
        p.fixed_view_mut::<2, 2>(0, 0).copy_from(&start.p_vv_m2_s2);
        p.fixed_view_mut::<3, 3>(2, 2).copy_from(&p_att);
        let models = std::array::from_fn(|k| {
            let yaw = 2.0 * PI * k as f64 / GSF_MODELS as f64;
            let (roll, pitch) = level_at_heading(&f, &u_n, yaw);
            let q_n_b = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
            let dv_n = q_n_b * dv;
            Hypothesis {
                q_n_b,
                v_ne_m_s: start.v_ne_m_s + Vector2::new(dv_n.x, dv_n.y),
                p,
                log_weight: -(GSF_MODELS as f64).ln(),
            }
        });
        let w = start.omega_ie_rad_s;
        Ok(Self {
            models,
            noise,
            omega_ie_n: Vector3::new(w * start.lat_rad.cos(), 0.0, -w * start.lat_rad.sin()),
            gravity_m_s2: start.gravity_m_s2,
            elapsed_s: 0.0,
        })
    }

    /// Propagate every hypothesis over one IMU interval: angle increment `dth_b_rad` and
    /// velocity increment `dv_b_m_s` (body) over `dt_s` seconds.
    pub fn predict(
        &mut self,
        dth_b_rad: &Vector3<f64>,
        dv_b_m_s: &Vector3<f64>,
        dt_s: f64,
    ) -> Result<(), YawGsfError> {
        if !(finite3(dth_b_rad) && finite3(dv_b_m_s) && dt_s.is_finite() && dt_s > 0.0) {
            return Err(YawGsfError::Increment(dt_s));
        }
        let w = self.omega_ie_n;
        let earth = UnitQuaternion::from_scaled_axis(-w * dt_s);
        let half = UnitQuaternion::from_scaled_axis(dth_b_rad * 0.5);
        let step = UnitQuaternion::from_scaled_axis(*dth_b_rad);
        let n = &self.noise;
        let q_att = n.arw_rad_sqrt_s.powi(2) * dt_s
            + 2.0 * n.gyro_bias_rad_s.powi(2) * (self.elapsed_s + 0.5 * dt_s) * dt_s;
        let q_vel = n.vrw_m_s_sqrt_s.powi(2) * dt_s;
        for m in &mut self.models {
            let f_n_dt = (m.q_n_b * half) * dv_b_m_s;
            let v = m.v_ne_m_s;
            // −2 ω_ie × v with v_D = 0, horizontal part.
            let coriolis = Vector2::new(2.0 * w.z * v.y, -2.0 * w.z * v.x) * dt_s;
            m.v_ne_m_s += Vector2::new(f_n_dt.x, f_n_dt.y) + coriolis;
            m.q_n_b = earth * m.q_n_b * step;
            m.q_n_b.renormalize_fast();
            let mut f = Mat5::identity();
            let fx = skew(&f_n_dt);
            // δv̇ = −[f̂×] φ (rows N, E); the increment already carries the Δt.
            f.fixed_view_mut::<2, 3>(0, 2)
                .copy_from(&(-fx.fixed_view::<2, 3>(0, 0)));
            f[(0, 1)] += 2.0 * w.z * dt_s;
            f[(1, 0)] -= 2.0 * w.z * dt_s;
            f.fixed_view_mut::<3, 3>(2, 2)
                .copy_from(&(Matrix3::identity() - skew(&w) * dt_s));
            let mut p = f * m.p * f.transpose();
            for k in 0..2 {
                p[(k, k)] += q_vel;
            }
            for k in 2..5 {
                p[(k, k)] += q_att;
            }
            m.p = 0.5 * (p + p.transpose());
        }
        self.elapsed_s += dt_s;
        Ok(())
    }

    /// Update every hypothesis with a GNSS horizontal velocity `v_ne_m_s` (north, east) of
    /// covariance `r_m2_s2`, measured at an antenna moving `lever_vel_b_m_s = ω_b × l_b`
    /// (body) relative to the IMU, and re-weight the bank by the innovation likelihoods.
    pub fn update(
        &mut self,
        v_ne_m_s: &Vector2<f64>,
        r_m2_s2: &Matrix2<f64>,
        lever_vel_b_m_s: &Vector3<f64>,
    ) -> Result<(), YawGsfError> {
        check_velocity(v_ne_m_s, r_m2_s2)?;
        if !finite3(lever_vel_b_m_s) {
            return Err(YawGsfError::Velocity);
        }
        for m in &mut self.models {
            let c_l = m.q_n_b * lever_vel_b_m_s;
            let nu = v_ne_m_s - m.v_ne_m_s - Vector2::new(c_l.x, c_l.y);
            let mut h = Mat2x5::zeros();
            h[(0, 0)] = 1.0;
            h[(1, 1)] = 1.0;
            h.fixed_view_mut::<2, 3>(0, 2)
                .copy_from(&(-skew(&c_l).fixed_view::<2, 3>(0, 0)));
            let s = h * m.p * h.transpose() + r_m2_s2;
            let (Some(s_inv), det) = (s.try_inverse(), s.determinant()) else {
                return Err(YawGsfError::Velocity);
            };
            if det <= 0.0 {
                return Err(YawGsfError::Velocity);
            }
            let k = m.p * h.transpose() * s_inv;
            let dx: Vec5 = k * nu;
            let ikh = Mat5::identity() - k * h;
            let p = ikh * m.p * ikh.transpose() + k * r_m2_s2 * k.transpose();
            m.p = 0.5 * (p + p.transpose());
            m.v_ne_m_s += Vector2::new(dx[0], dx[1]);
            m.q_n_b = UnitQuaternion::from_scaled_axis(Vector3::new(dx[2], dx[3], dx[4])) * m.q_n_b;
            m.log_weight +=
                -0.5 * (nu.transpose() * s_inv * nu)[0] - (2.0 * PI).ln() - 0.5 * det.ln();
        }
        let max = self
            .models
            .iter()
            .map(|m| m.log_weight)
            .fold(f64::NEG_INFINITY, f64::max);
        let sum: f64 = self.models.iter().map(|m| (m.log_weight - max).exp()).sum();
        let norm = max + sum.ln();
        for m in &mut self.models {
            m.log_weight -= norm;
        }
        Ok(())
    }

    /// The moment-matched mixture: mean attitude, heading and their covariance.
    pub fn estimate(&self) -> YawEstimate {
        let w: [f64; GSF_MODELS] = std::array::from_fn(|k| self.models[k].log_weight.exp());
        let best = (0..GSF_MODELS)
            .max_by(|&a, &b| w[a].total_cmp(&w[b]))
            .unwrap_or(0);
        let mut q_bar = self.models[best].q_n_b;
        // Weighted mean rotation (Karcher mean), a few fixed-point steps from the best
        // hypothesis; once one dominates, the first step is exact to its weight's precision.
        for _ in 0..4 {
            let mut d = Vector3::zeros();
            for (m, wk) in self.models.iter().zip(&w) {
                d += (m.q_n_b * q_bar.inverse()).scaled_axis() * *wk;
            }
            q_bar = UnitQuaternion::from_scaled_axis(d) * q_bar;
        }
        let mut p_att = Matrix3::zeros();
        let mut v = Vector2::zeros();
        for (m, wk) in self.models.iter().zip(&w) {
            let d = (m.q_n_b * q_bar.inverse()).scaled_axis();
            p_att += (m.p.fixed_view::<3, 3>(2, 2) + d * d.transpose()) * *wk;
            v += m.v_ne_m_s * *wk;
        }
        let tilt_bias = (self.noise.accel_bias_m_s2 / self.gravity_m_s2).powi(2);
        p_att[(0, 0)] += tilt_bias;
        p_att[(1, 1)] += tilt_bias;
        let c = q_bar.to_rotation_matrix().into_inner();
        YawEstimate {
            c_n_b: Rotation::from_dcm_unchecked(c),
            yaw_rad: c[(1, 0)].atan2(c[(0, 0)]),
            yaw_sigma_rad: p_att[(2, 2)].max(0.0).sqrt(),
            p_att_n_rad2: p_att,
            v_ne_m_s: v,
            max_weight: w.iter().copied().fold(0.0, f64::max),
        }
    }

    /// Time propagated since the start, s.
    pub fn elapsed_s(&self) -> f64 {
        self.elapsed_s
    }
}

fn check_velocity(v: &Vector2<f64>, p: &Matrix2<f64>) -> Result<(), YawGsfError> {
    let ok = v.iter().chain(p.iter()).all(|x| x.is_finite())
        && p[(0, 0)] > 0.0
        && p.determinant() > 0.0
        && (p[(0, 1)] - p[(1, 0)]).abs() <= 1e-9 * (p[(0, 0)] + p[(1, 1)]);
    if ok {
        Ok(())
    } else {
        Err(YawGsfError::Velocity)
    }
}

#[cfg(test)]
mod tests;
