//! Error dynamics of the [`ErrorStateEkf`] and its covariance propagation.
//!
//! # Dynamics (Groves, *Principles of GNSS, Inertial and Multisensor Integrated Navigation*,
//! 2nd ed., §14.2.3 ECEF and §14.2.7 scale factors; paper 002 eq. 22)
//! With `f̂_e = Ĉ_e_b f̂`:
//! ```text
//! δṙ = δv
//! δv̇ = G·δr − 2[ω_ie×]·δv − [f̂_e×]·ψ − Ĉ_e_b·δb_a − Ĉ_e_b·diag(f̂)·δs_a − Ĉ_e_b·n_a
//! ψ̇  = −[ω_ie×]·ψ − Ĉ_e_b·δb_g − Ĉ_e_b·diag(ω̂)·δs_g − Ĉ_e_b·W(ω̂)·δp_g − Ĉ_e_b·n_g
//! δḃ_clk = δd_clk + w_b,   δḋ_clk = w_d                (two-state receiver clock)
//! biases, baro bias, odometer scale: random walks; scale factors, non-orthogonality, κ:
//! random constants
//! ```
//! `G = ∂g/∂r = GM/r³·(3 u uᵀ − I) − [ω_ie×]²` is the gravity gradient: the `−GM/r³·I` part is
//! paper 002's `−ν²Δr` (Schuler frequency `ν² = g/r`), `3GM/r³ u uᵀ` its `3ν² r (r·Δr)/r²`
//! (unstable vertical channel), the last term the centrifugal gradient.
//!
//! # Discretisation and cost
//! Propagating a dense 31×31 covariance every IMU sample (`Φ P Φᵀ`, 2·31³ ≈ 59 600
//! multiply-adds) would dominate the cost of an IMU sample. Instead the strapdown step only
//! *accumulates* the integral of `F` over a covariance interval ([`TransitionAccumulator`]:
//! `∫Ĉ_e_b dt`, `∫f̂_e dt`, `∫Ĉ_e_b diag(f̂) dt`, `∫Ĉ_e_b diag(ω̂) dt`, a few 3×3 sums) and the
//! covariance is propagated at the end of the interval and always before an update
//! ([`ErrorStateEkf::propagate_covariance`]), with `Φ = I + F̄T + ½(F̄T)²` (`F̄T = ∫F dt`; the
//! neglected commutator terms are `O(|F|²T²)` of the varying part, < 10⁻⁶ for T = 50 ms) and
//! trapezoidal noise `P⁺ = Φ (P + ½ Q_c T) Φᵀ + ½ Q_c T`. `Φ` differs from the identity only
//! in the 9 navigation rows `a` (and the clock bias–drift entry), so `Φ P Φᵀ` needs only
//! `G = P aᵀ` (31×9) and the symmetric `a G` (9×9): `a` is built from its 17 non-zero 3×3
//! blocks (about 140 of its 279 entries are non-zero), `G` from those entries alone
//! (≈ 4 400 multiply-adds) and `a G` as a 9×31·31×9 product of which the upper triangle is kept
//! (≈ 7 000 multiply-adds in all, once per interval and before each update).

use super::update::p_times_h_transpose;
use super::{Covariance, ErrorStateEkf, NX, StateVector, idx, symmetrize};
use crate::attitude::skew;
use crate::earth::Ellipsoid;
use crate::strapdown::NavState;
use nalgebra::{Matrix3, SMatrix, Vector3};

/// The rows of `Φ` that differ from the identity: position, velocity, attitude.
type NavRows = SMatrix<f64, 9, NX>;

/// Continuous-time noise densities of the error model, SI units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProcessNoise {
    /// Angle random walk (gyro white noise density), rad/√s.
    pub arw_rad_sqrt_s: f64,
    /// Velocity random walk (accelerometer white noise density), m/s/√s.
    pub vrw_m_s_sqrt_s: f64,
    /// Gyro bias random-walk density, rad/s/√s.
    pub gyro_bias_rw_rad_s_sqrt_s: f64,
    /// Accelerometer bias random-walk density, m/s²/√s.
    pub accel_bias_rw_m_s2_sqrt_s: f64,
    /// Baro height bias random-walk density, m/√s.
    pub baro_bias_rw_m_sqrt_s: f64,
    /// Odometer scale-factor random-walk density, 1/√s.
    pub odo_scale_rw_per_sqrt_s: f64,
    /// Receiver clock bias (white frequency noise) PSD, m²/s.
    pub clock_bias_psd_m2_s: f64,
    /// Receiver clock drift (random-walk frequency noise) PSD, m²/s³.
    pub clock_drift_psd_m2_s3: f64,
    /// 1-σ non-orthogonality of the gyro triad (each off-diagonal of its symmetric part),
    /// rad: the prior σ of the [`idx::SGM`] states, or, with that group off, the size of
    /// the attitude noise per radian turned ([`MISALIGNMENT_COHERENCE_RAD`]).
    pub gyro_misalignment_rad: f64,
    /// The gravity field's departure from the mechanization's model, absorbed by the
    /// accelerometer-bias states ([`GravityDisturbance`]; zero: the model is the field).
    pub gravity: GravityDisturbance,
}

/// Statistics of the gravity disturbance (deflection of the vertical and anomaly) the
/// mechanization's normal / J2 gravity does not contain, SI units.
///
/// An inertial system cannot tell a gravity disturbance from an accelerometer bias (both add
/// to the specific force it integrates), so no state of its own is needed: the
/// accelerometer-bias states absorb it. What makes it differ from a bias is that it is fixed
/// to the Earth, not to the body, and changes along the track:
/// - the prior: the bias states start wider by the disturbance's covariance in body axes,
///   `S_b = σ_h² (I − u uᵀ) + σ_v² u uᵀ` (`u` the local vertical in body axes);
/// - driving: the field is modelled as a first-order Gauss–Markov process in distance with
///   correlation distance `L` (Kasper, "A second-order Markov gravity anomaly model",
///   J. Geophys. Res. 76, 1971, introduces the Markov-in-distance description for INS error
///   analysis; the first order is the conservative member of that family: its increment over a
///   short distance `d` is `2σ²·d/L`, while any smooth field's is `O(d²)`), so the bias states
///   random-walk by `2 S_b · d/L` over a distance `d`;
/// - turning: the body axes turn under the Earth-fixed disturbance, so its body components
///   change by `−[Δθ×]·δg_b` for a rotation `Δθ` relative to the Earth, bounded as a random walk
///   in the angle turned exactly as the gyro non-orthogonality is
///   ([`MISALIGNMENT_COHERENCE_RAD`]): `Θ_c/|Δθ| · [Δθ×] S_b [Δθ×]ᵀ` (a half turn then adds
///   `4.6 σ²`, the exact change of a reversed vector being `4 σ²`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GravityDisturbance {
    /// 1-σ of each horizontal component (`γ ξ`, `γ η`), m/s².
    pub horizontal_sigma_m_s2: f64,
    /// 1-σ of the vertical component (the anomaly), m/s².
    pub vertical_sigma_m_s2: f64,
    /// Correlation distance of the field along the track, m.
    pub correlation_distance_m: f64,
}

impl GravityDisturbance {
    /// Whether any disturbance is modelled.
    pub fn is_modelled(&self) -> bool {
        self.horizontal_sigma_m_s2 > 0.0 || self.vertical_sigma_m_s2 > 0.0
    }

    /// Covariance of the disturbance in body axes, (m/s²)², for the local vertical `up_b`
    /// expressed in body axes (any length; its sign does not matter).
    pub fn body_covariance(&self, up_b: &Vector3<f64>) -> Matrix3<f64> {
        let n = up_b.norm();
        if !n.is_normal() {
            return Matrix3::identity() * self.horizontal_sigma_m_s2.powi(2);
        }
        let u = up_b / n;
        let uut = u * u.transpose();
        (Matrix3::identity() - uut) * self.horizontal_sigma_m_s2.powi(2)
            + uut * self.vertical_sigma_m_s2.powi(2)
    }
}

/// Coherence angle of the gyro non-orthogonality when it is not estimated
/// (`ActiveStates::gyro_misalignment` off), rad: the attitude noise added per covariance
/// interval is `σ_m² · Θ_c · |Δθ|` (per axis, see below), i.e. a random walk in the angle
/// turned. A pessimistic bound: the states, on by default, model the error exactly.
///
/// Derivation. The gyro triad defines the body frame, so its misalignment is a symmetric
/// non-orthogonality `S` (off-diagonals σ_m, zero diagonal; a rigid rotation of the triad
/// would be the body frame itself). The measured rate is `(I + S) ω`, so the attitude error
/// rate is `S ω`, a vector fixed in the body while the body turns. For a turn by Θ about one
/// axis u, the error accumulated in the (non-rotating) navigation frame is the chord of the
/// circle the error-rate vector `s = S u` sweeps: `|∫ R(θ) s dθ| = |s_⊥| · 2 sin(Θ/2)`, whose
/// variance per perpendicular axis is `σ_m² · 4 sin²(Θ/2)`. A random walk in Θ with density
/// `σ_m² Θ_c` bounds it for every Θ iff `Θ_c ≥ max_Θ 4 sin²(Θ/2)/Θ = max 2(1 − cos Θ)/Θ`;
/// the maximum is at `Θ = tan(Θ/2)` (Θ* = 2.3311 rad) and equals 1.449223, rounded up here (the test
/// `misalignment_coherence_bounds_the_chord` checks it). The random walk equals the
/// coherent error at Θ*, exceeds it for smaller turns (by Θ_c/Θ) and keeps growing after
/// Θ* where the true error is bounded by 2|s|; the star tracker resets it in between.
pub const MISALIGNMENT_COHERENCE_RAD: f64 = 1.44923;

impl ProcessNoise {
    /// Diagonal of the continuous process-noise spectral density `Q_c` in error-state layout
    /// (scale factors and κ are random constants: zero).
    pub fn qc_diagonal(&self) -> StateVector {
        let mut q = StateVector::zeros();
        for i in 0..3 {
            q[idx::VEL + i] = self.vrw_m_s_sqrt_s.powi(2);
            q[idx::ATT + i] = self.arw_rad_sqrt_s.powi(2);
            q[idx::BG + i] = self.gyro_bias_rw_rad_s_sqrt_s.powi(2);
            q[idx::BA + i] = self.accel_bias_rw_m_s2_sqrt_s.powi(2);
        }
        q[idx::BARO] = self.baro_bias_rw_m_sqrt_s.powi(2);
        q[idx::ODO] = self.odo_scale_rw_per_sqrt_s.powi(2);
        q[idx::CLK] = self.clock_bias_psd_m2_s;
        q[idx::CLK_DRIFT] = self.clock_drift_psd_m2_s3;
        q
    }
}

/// Gravity gradient `∂g/∂r` in ECEF (point-mass attraction plus centrifugal), 1/s².
///
/// `G = GM/r³ (3 u uᵀ − I) − [ω_ie×]²`; the J2 part of the gradient is ~10⁻³ of this and is
/// neglected (paper 002 eq. 22 uses the same point-mass form).
pub fn gravity_gradient(ell: &Ellipsoid, r_e: &Vector3<f64>) -> Matrix3<f64> {
    let r = r_e.norm();
    let u = r_e / r;
    let k = ell.gm_m3_s2 / (r * r * r);
    let w = ell.omega_ie_rad_s;
    let mut g = (3.0 * u * u.transpose() - Matrix3::identity()) * k;
    g[(0, 0)] += w * w;
    g[(1, 1)] += w * w;
    g
}

/// Integral of the error dynamics `F` over a covariance interval, accumulated per IMU step
/// from the quantities that vary along the trajectory (module docs "Discretisation").
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TransitionAccumulator {
    /// Interval length `T`, s.
    pub dt_s: f64,
    /// `∫ Ĉ_e_b dt`, s.
    sum_c_e_b: Matrix3<f64>,
    /// `∫ f̂_e dt` (ECEF velocity increment), m/s.
    sum_f_e: Vector3<f64>,
    /// `∫ Ĉ_e_b diag(f̂) dt`, m/s.
    sum_c_diag_f: Matrix3<f64>,
    /// `∫ Ĉ_e_b diag(ω̂) dt`, rad.
    sum_c_diag_w: Matrix3<f64>,
    /// `∫ ω̂ dt` (body angle increment), rad.
    sum_dtheta_b: Vector3<f64>,
    /// `∫ Ĉ_e_b W(ω̂) dt` (non-orthogonality Jacobian, module docs), rad.
    sum_c_w_mis: Matrix3<f64>,
    /// `∫ |v_e| dt`, the distance travelled over the Earth, m.
    pub distance_m: f64,
}

/// `W(ω)` with `S·ω = W(ω)·(S_xy, S_xz, S_yz)` for a symmetric `S` with zero diagonal.
pub fn nonorthogonality_jacobian(w: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(w.y, w.z, 0.0, w.x, 0.0, w.z, 0.0, w.x, w.y)
}

/// The symmetric zero-diagonal matrix `S` of the parameters `p = (S_xy, S_xz, S_yz)`.
pub fn nonorthogonality_matrix(p: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, p.x, p.y, p.x, 0.0, p.z, p.y, p.z, 0.0)
}

impl TransitionAccumulator {
    /// Add one IMU step of `dt_s` with attitude `c_e_b` (body → ECEF) and the corrected
    /// specific force `f_b` (m/s²) and angular rate `w_b` (rad/s), body.
    pub fn add(&mut self, c_e_b: &Matrix3<f64>, f_b: &Vector3<f64>, w_b: &Vector3<f64>, dt_s: f64) {
        let c_dt = c_e_b * dt_s;
        self.dt_s += dt_s;
        self.sum_c_e_b += c_dt;
        self.sum_f_e += c_dt * f_b;
        self.sum_dtheta_b += w_b * dt_s;
        self.sum_c_w_mis += c_dt * nonorthogonality_jacobian(w_b);
        for j in 0..3 {
            for i in 0..3 {
                self.sum_c_diag_f[(i, j)] += c_dt[(i, j)] * f_b[j];
                self.sum_c_diag_w[(i, j)] += c_dt[(i, j)] * w_b[j];
            }
        }
    }

    /// Attitude noise (ECEF, rad²) of the unmodelled gyro non-orthogonality over the
    /// accumulated interval, for `sigma_rad` per off-diagonal ([`MISALIGNMENT_COHERENCE_RAD`]).
    /// Body axis i's error `Σ_{j≠i} S_ij Δθ_j` has variance `σ_m² (|Δθ|² − Δθ_i²)` over the
    /// interval; as a random walk in the angle turned it is `σ_m² Θ_c (|Δθ|² − Δθ_i²)/|Δθ|`,
    /// rotated to ECEF with the interval's mean attitude (the body turns by |Δθ| ≪ 1 rad).
    pub fn misalignment_noise(&self, sigma_rad: f64) -> Matrix3<f64> {
        let dth = self.sum_dtheta_b;
        let angle = dth.norm();
        if !(angle > 0.0 && sigma_rad > 0.0 && self.dt_s > 0.0) {
            return Matrix3::zeros();
        }
        let k = sigma_rad * sigma_rad * MISALIGNMENT_COHERENCE_RAD / angle;
        let d = Matrix3::from_diagonal(&dth.map(|x| k * (angle * angle - x * x)));
        let c = self.sum_c_e_b / self.dt_s;
        c * d * c.transpose()
    }

    /// Random walk of the accelerometer-bias states (body axes, (m/s²)²) over the accumulated
    /// interval from the gravity disturbance `g` ([`GravityDisturbance`]): the distance driven
    /// and the body's rotation relative to the Earth (`ω_ie_e`, rad/s) under the local vertical
    /// `up_e` (ECEF, any length). The mean attitude of the interval stands for the attitude
    /// (the body turns by |Δθ| ≪ 1 rad in one).
    pub fn gravity_disturbance_noise(
        &self,
        g: &GravityDisturbance,
        up_e: &Vector3<f64>,
        omega_ie_e: &Vector3<f64>,
    ) -> Matrix3<f64> {
        if !(g.is_modelled() && self.dt_s > 0.0) {
            return Matrix3::zeros();
        }
        let c_mean = self.sum_c_e_b / self.dt_s;
        let s_b = g.body_covariance(&(c_mean.transpose() * up_e));
        let mut q = Matrix3::zeros();
        if g.correlation_distance_m > 0.0 {
            q += s_b * (2.0 * self.distance_m / g.correlation_distance_m);
        }
        // Rotation relative to the Earth: the body increment less the Earth's rate seen in
        // body axes over the interval.
        let dtheta_eb = self.sum_dtheta_b - self.sum_c_e_b.transpose() * omega_ie_e;
        let angle = dtheta_eb.norm();
        if angle > 0.0 {
            let k = skew(&dtheta_eb);
            q += k * s_b * k.transpose() * (MISALIGNMENT_COHERENCE_RAD / angle);
        }
        q
    }

    /// The navigation rows (0..9) of `Φ = I + F̄T + ½(F̄T)²` with the gravity gradient taken
    /// at `r_e` (it changes by < 10⁻⁵ relative over an interval).
    pub fn nav_rows(&self, ell: &Ellipsoid, r_e: &Vector3<f64>) -> SMatrix<f64, 9, NX> {
        let t = self.dt_s;
        let omega = skew(&ell.omega_ie_e());
        // The non-zero 3×3 blocks of F̄T (module docs): its position rows are T·I in the
        // velocity columns; velocity rows read position, velocity, attitude, accelerometer bias
        // and scale factor; attitude rows read attitude and the gyro bias, scale factor and
        // non-orthogonality.
        let v_p = gravity_gradient(ell, r_e) * t;
        let v_v = omega * (-2.0 * t);
        let v_a = -skew(&self.sum_f_e);
        let v_ba = -self.sum_c_e_b;
        let v_sa = -self.sum_c_diag_f;
        let a_a = omega * (-t);
        let a_bg = -self.sum_c_e_b;
        let a_sg = -self.sum_c_diag_w;
        let a_sgm = -self.sum_c_w_mis;
        // F has non-zero rows only in 0..9 (plus the clock row, whose column 27 meets no
        // non-zero row of F), so (F̄T)² restricted to rows 0..9 is F̄T[:, 0..9] · F̄T[0..9, :]:
        // block by block, Φ = I + F̄T + ½(F̄T)² is
        //   position rows: I + ½T·v_p | T·I + ½T·v_v | ½T·v_a | ½T·v_ba | ½T·v_sa
        //   velocity rows: v_p + ½v_v·v_p | I + v_v + ½(v_v² + T·v_p) | v_a + ½(v_v·v_a +
        //     v_a·a_a) | v_ba + ½v_v·v_ba | v_sa + ½v_v·v_sa | ½v_a·a_bg | ½v_a·a_sg | ½v_a·a_sgm
        //   attitude rows: I + a_a + ½a_a² | a_bg + ½a_a·a_bg | (the same for a_sg, a_sgm)
        let i3 = Matrix3::identity();
        let h = 0.5 * t;
        let mut a = NavRows::zeros();
        let mut put = |r: usize, c: usize, m: Matrix3<f64>| {
            a.fixed_view_mut::<3, 3>(r, c).copy_from(&m);
        };
        let (p, v, q) = (idx::POS, idx::VEL, idx::ATT);
        put(p, p, i3 + v_p * h);
        put(p, v, i3 * t + v_v * h);
        put(p, q, v_a * h);
        put(p, idx::BA, v_ba * h);
        put(p, idx::SA, v_sa * h);
        put(v, p, v_p + v_v * v_p * 0.5);
        put(v, v, i3 + v_v + (v_v * v_v + v_p * t) * 0.5);
        put(v, q, v_a + (v_v * v_a + v_a * a_a) * 0.5);
        put(v, idx::BA, v_ba + v_v * v_ba * 0.5);
        put(v, idx::SA, v_sa + v_v * v_sa * 0.5);
        put(v, idx::BG, v_a * a_bg * 0.5);
        put(v, idx::SG, v_a * a_sg * 0.5);
        put(v, idx::SGM, v_a * a_sgm * 0.5);
        put(q, q, i3 + a_a + a_a * a_a * 0.5);
        put(q, idx::BG, a_bg + a_a * a_bg * 0.5);
        put(q, idx::SG, a_sg + a_a * a_sg * 0.5);
        put(q, idx::SGM, a_sgm + a_a * a_sgm * 0.5);
        a
    }
}

/// Continuous error dynamics matrix `F` (module docs), dense, at the estimated position
/// `r_e` (ECEF, m), attitude `c_e_b`, corrected specific force `f_b` (m/s²) and angular rate
/// `w_b` (rad/s), body. Used by tests and as the reference for [`TransitionAccumulator`].
pub fn error_dynamics(
    ell: &Ellipsoid,
    r_e: &Vector3<f64>,
    c_e_b: &Matrix3<f64>,
    f_b: &Vector3<f64>,
    w_b: &Vector3<f64>,
) -> Covariance {
    let omega = skew(&ell.omega_ie_e());
    let f_e = c_e_b * f_b;
    let mut f = Covariance::zeros();
    f.fixed_view_mut::<3, 3>(idx::POS, idx::VEL)
        .copy_from(&Matrix3::identity());
    f.fixed_view_mut::<3, 3>(idx::VEL, idx::POS)
        .copy_from(&gravity_gradient(ell, r_e));
    f.fixed_view_mut::<3, 3>(idx::VEL, idx::VEL)
        .copy_from(&(-2.0 * omega));
    f.fixed_view_mut::<3, 3>(idx::VEL, idx::ATT)
        .copy_from(&(-skew(&f_e)));
    f.fixed_view_mut::<3, 3>(idx::VEL, idx::BA)
        .copy_from(&(-c_e_b));
    f.fixed_view_mut::<3, 3>(idx::VEL, idx::SA)
        .copy_from(&(-c_e_b * Matrix3::from_diagonal(f_b)));
    f.fixed_view_mut::<3, 3>(idx::ATT, idx::ATT)
        .copy_from(&(-omega));
    f.fixed_view_mut::<3, 3>(idx::ATT, idx::BG)
        .copy_from(&(-c_e_b));
    f.fixed_view_mut::<3, 3>(idx::ATT, idx::SG)
        .copy_from(&(-c_e_b * Matrix3::from_diagonal(w_b)));
    f.fixed_view_mut::<3, 3>(idx::ATT, idx::SGM)
        .copy_from(&(-c_e_b * nonorthogonality_jacobian(w_b)));
    f[(idx::CLK, idx::CLK_DRIFT)] = 1.0;
    f
}

impl ErrorStateEkf {
    /// Accumulate one IMU step of `dt_s` at the (already propagated) state `nav`, with the
    /// corrected specific force `f_b` (m/s²) and angular rate `w_b` (rad/s), body. Cheap:
    /// the covariance itself moves in [`Self::propagate_covariance`].
    pub fn accumulate(
        &mut self,
        nav: &NavState,
        f_b: &Vector3<f64>,
        w_b: &Vector3<f64>,
        dt_s: f64,
    ) {
        let c_e_b = nav.q_e_b.to_rotation_matrix().into_inner();
        self.acc.add(&c_e_b, f_b, w_b, dt_s);
        self.acc.distance_m += nav.v_e.norm() * dt_s;
    }

    /// Time accumulated since the last covariance propagation, s.
    pub fn pending_s(&self) -> f64 {
        self.acc.dt_s
    }

    /// Propagate the covariance over the accumulated interval (module docs), position `r_e`
    /// (ECEF, m) for the gravity gradient. A no-op when nothing is pending. Allocates nothing.
    pub fn propagate_covariance(&mut self, ell: &Ellipsoid, r_e: &Vector3<f64>) {
        let t = self.acc.dt_s;
        if t <= 0.0 {
            return;
        }
        let a = self.acc.nav_rows(ell, r_e);
        // With the non-orthogonality estimated its error is in F; otherwise it is bounded as
        // attitude noise.
        let q_mis = if self.active[idx::SGM] {
            Matrix3::zeros()
        } else {
            self.acc
                .misalignment_noise(self.noise.gyro_misalignment_rad)
        };
        let q_grav =
            self.acc
                .gravity_disturbance_noise(&self.noise.gravity, r_e, &ell.omega_ie_e());
        self.acc = TransitionAccumulator::default();
        // In place: the trapezoid's first half of the noise, then Φ (P + Q/2) Φᵀ, then the
        // second half.
        let (pn, qc) = (&mut self.p, &self.qc);
        for i in 0..NX {
            pn[(i, i)] += 0.5 * qc[i] * t;
        }
        // Φ is the identity but for its navigation rows 0..9 (`a`) and the clock row, and the
        // two commute (no navigation row reads the clock). Navigation part, with
        // G = P aᵀ (31×9, P symmetric so G = (aP)ᵀ):
        //   P⁺[0..9, 0..9] = a G,  P⁺[9.., 0..9] = G[9.., ·] (and its mirror),  the rest = P.
        let g = p_times_h_transpose(pn, &a);
        // a G = a P aᵀ is symmetric: its upper triangle, mirrored.
        let top = a * g;
        for c in 0..9 {
            for r in 0..=c {
                let v = top[(r, c)];
                pn[(r, c)] = v;
                pn[(c, r)] = v;
            }
            for r in 9..NX {
                pn[(r, c)] = g[(r, c)];
                pn[(c, r)] = g[(r, c)];
            }
        }
        // Clock: bias row += T · drift row, then bias column += T · drift column (exactly
        // symmetric again: each mirrored pair gets the same sum).
        if self.active[idx::CLK] {
            for j in 0..NX {
                let v = pn[(idx::CLK_DRIFT, j)] * t;
                pn[(idx::CLK, j)] += v;
            }
            for i in 0..NX {
                let v = pn[(i, idx::CLK_DRIFT)] * t;
                pn[(i, idx::CLK)] += v;
            }
        }
        for i in 0..NX {
            pn[(i, i)] += 0.5 * qc[i] * t;
        }
        let mut att = pn.fixed_view_mut::<3, 3>(idx::ATT, idx::ATT);
        att += symmetrize(&q_mis);
        if self.active[idx::BA] {
            let mut ba = pn.fixed_view_mut::<3, 3>(idx::BA, idx::BA);
            ba += symmetrize(&q_grav);
        }
        // The clock estimate moves with its drift (the error model's δḃ = δd).
        self.clock_bias_m += self.clock_drift_m_s * t;
    }

    /// Accumulate one step and propagate at once (tests, benches).
    pub fn predict(
        &mut self,
        ell: &Ellipsoid,
        nav: &NavState,
        f_b: &Vector3<f64>,
        w_b: &Vector3<f64>,
        dt_s: f64,
    ) {
        self.accumulate(nav, f_b, w_b, dt_s);
        self.propagate_covariance(ell, &nav.r_e);
    }
}

#[cfg(test)]
mod tests {
    use super::super::ActiveStates;
    use super::super::test_support::random_spd;
    use super::*;
    use crate::earth::WGS84;
    use nalgebra::UnitQuaternion;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// Θ_c bounds the variance of the nav-frame error of a body-fixed error rate over any
    /// turn, `4 sin²(Θ/2) ≤ Θ_c Θ`, and is the smallest such constant (touches at Θ* where
    /// `Θ* = tan(Θ*/2)`); closed form of the derivation at [`MISALIGNMENT_COHERENCE_RAD`].
    #[test]
    fn misalignment_coherence_bounds_the_chord() {
        let mut worst = 0.0_f64;
        for k in 1..=20_000 {
            let th = k as f64 * 1e-3;
            let chord2 = 4.0 * (th / 2.0).sin().powi(2);
            assert!(chord2 <= MISALIGNMENT_COHERENCE_RAD * th, "{th}");
            worst = worst.max(chord2 / th);
        }
        // The constant is the maximum rounded up in its last digit.
        assert!((worst - MISALIGNMENT_COHERENCE_RAD).abs() < 1e-5, "{worst}");
        // Turn about body z by 1 rad in one interval: noise only on the two tilt axes,
        // σ_m² Θ_c |Δθ| each.
        let mut acc = TransitionAccumulator::default();
        let w = Vector3::new(0.0, 0.0, 0.1);
        for _ in 0..1000 {
            acc.add(&Matrix3::identity(), &Vector3::zeros(), &w, 0.01);
        }
        let sigma = 1e-4;
        let q = acc.misalignment_noise(sigma);
        let expect = sigma * sigma * MISALIGNMENT_COHERENCE_RAD * 1.0;
        assert!((q[(0, 0)] - expect).abs() < 1e-9 * expect, "{q}");
        assert!((q[(1, 1)] - expect).abs() < 1e-9 * expect, "{q}");
        assert!(q[(2, 2)].abs() < 1e-20, "{q}");
    }

    /// The non-orthogonality states use the simulator's form `(I + S)·ω` with `S` symmetric:
    /// `W(ω)·p = S(p)·ω` exactly, and the compensation `(I − Ŝ)` inverts `I + S` up to
    /// `S²`, whose norm is at most `‖S‖_F² = 2|p|²`.
    #[test]
    fn nonorthogonality_model_matches_the_simulator_form() {
        let p = Vector3::new(3e-5, -5e-5, 2e-5);
        let w = Vector3::new(0.1, -0.2, 0.3);
        let d = (nonorthogonality_jacobian(&w) * p - nonorthogonality_matrix(&p) * w).norm();
        assert!(d < 1e-18, "{d}");
        let mut f = ErrorStateEkf::new(
            Covariance::identity() * 1e-6,
            crate::navigator::ImuSpec::default().process_noise(),
            ActiveStates::ALL,
        );
        f.gyro_misalignment_rad = p;
        let dth = Vector3::new(0.01, -0.02, 0.03);
        let meas = (Matrix3::identity() + nonorthogonality_matrix(&p)) * dth;
        let (c, _) = f.correct_increment(&meas, &Vector3::zeros(), 0.005);
        let bound = 2.0 * p.norm_squared() * dth.norm();
        assert!(
            (c - dth).norm() <= bound + 1e-18,
            "{} > {bound}",
            (c - dth).norm()
        );
        // Without a compensation the error would be first order.
        assert!((meas - dth).norm() > 1e3 * bound);
    }

    #[test]
    fn accumulated_transition_matches_dense_second_order_expansion() {
        // One step: the block-sparse nav rows must equal the dense I + F dt + ½(F dt)² (the
        // same polynomial, so only rounding differs).
        let r = Vector3::new(4.0e6, 3.0e6, 3.5e6);
        let c = UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3)
            .to_rotation_matrix()
            .into_inner();
        let f_b = Vector3::new(0.3, -0.2, -9.8);
        let w_b = Vector3::new(0.01, -0.3, 0.2);
        let f = error_dynamics(&WGS84, &r, &c, &f_b, &w_b);
        let dt = 0.01;
        let fd = f * dt;
        let dense = Covariance::identity() + fd + fd * fd * 0.5;
        let mut acc = TransitionAccumulator::default();
        acc.add(&c, &f_b, &w_b, dt);
        let a = acc.nav_rows(&WGS84, &r);
        let d = (a - dense.fixed_rows::<9>(0)).abs().max();
        assert!(d < 1e-15, "{d}");
    }

    #[test]
    fn sparse_covariance_propagation_equals_dense() {
        // Φ P Φᵀ formed block-sparse must equal the dense product with the same Φ and the
        // trapezoidal noise, to rounding (relative 1e-12 of the largest entry), and stay
        // exactly symmetric.
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let p0 = random_spd(&mut rng, 1e-2);
        let noise = crate::navigator::ImuSpec::default().process_noise();
        let mut noise = noise;
        noise.clock_bias_psd_m2_s = 0.1;
        noise.clock_drift_psd_m2_s3 = 0.01;
        // The misalignment noise is checked on its own (misalignment_coherence_bounds_the_chord).
        noise.gyro_misalignment_rad = 0.0;
        let mut f = ErrorStateEkf::new(p0, noise, ActiveStates::ALL);
        let nav = NavState {
            r_e: Vector3::new(4.0e6, 3.0e6, 3.5e6),
            v_e: Vector3::new(10.0, 0.0, 1.0),
            q_e_b: UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3),
        };
        let f_b = Vector3::new(0.3, -0.2, -9.8);
        let w_b = Vector3::new(0.01, -0.3, 0.2);
        let dt = 0.05;
        let c = nav.q_e_b.to_rotation_matrix().into_inner();
        let fm = error_dynamics(&WGS84, &nav.r_e, &c, &f_b, &w_b) * dt;
        let phi = Covariance::identity() + fm + fm * fm * 0.5;
        let q = Covariance::from_diagonal(&(noise.qc_diagonal() * (0.5 * dt)));
        let dense = phi * (p0 + q) * phi.transpose() + q;
        f.predict(&WGS84, &nav, &f_b, &w_b, dt);
        let d = (f.p - dense).abs().max() / dense.abs().max();
        assert!(d < 1e-12, "{d}");
        // Exactly symmetric, with no symmetrisation pass over the whole matrix.
        assert_eq!(f.p, f.p.transpose());
    }

    /// Body axes of a level vehicle heading `yaw` at latitude `lat`, longitude 0: `C_e_b`.
    fn level_c_e_b(lat: f64, yaw: f64) -> Matrix3<f64> {
        let c_e_n = crate::strapdown::q_e_n(lat, 0.0)
            .to_rotation_matrix()
            .into_inner();
        let c_n_b = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw)
            .to_rotation_matrix()
            .into_inner();
        c_e_n * c_n_b
    }

    fn disturbance() -> GravityDisturbance {
        GravityDisturbance {
            horizontal_sigma_m_s2: 2.4e-4,
            vertical_sigma_m_s2: 3.0e-4,
            correlation_distance_m: 25e3,
        }
    }

    /// The disturbance's body covariance keeps its principal values under any attitude:
    /// `σ_v²` along the vertical, `σ_h²` across it.
    #[test]
    fn gravity_disturbance_rotates_with_the_vertical() {
        let g = disturbance();
        let (sh2, sv2) = (2.4e-4_f64.powi(2), 3.0e-4_f64.powi(2));
        let level = g.body_covariance(&Vector3::new(0.0, 0.0, -9.8));
        let expect = Matrix3::from_diagonal(&Vector3::new(sh2, sh2, sv2));
        assert!((level - expect).abs().max() < 1e-22, "{level}");
        let up = Vector3::new(0.3, -0.5, 0.8);
        let tilted = g.body_covariance(&up);
        let u = up.normalize();
        assert!(((tilted * u).dot(&u) - sv2).abs() < 1e-22);
        let across = u.cross(&Vector3::x()).normalize();
        assert!(((tilted * across).dot(&across) - sh2).abs() < 1e-22);
        assert!((tilted.trace() - (2.0 * sh2 + sv2)).abs() < 1e-22);
    }

    /// Driving straight: the bias random walk is the first-order Gauss–Markov increment
    /// `2 S_b d/L`, and the Earth's rotation under a body fixed to the Earth turns nothing.
    #[test]
    fn gravity_disturbance_walks_with_the_distance_driven() {
        let g = disturbance();
        let lat = 0.9;
        let c = level_c_e_b(lat, 0.7);
        let r_e = c.column(2) * -6.37e6; // body z points down
        let w_ie = WGS84.omega_ie_e();
        let mut acc = TransitionAccumulator::default();
        let dt = 0.01;
        for _ in 0..5 {
            // A body at rest on the Earth senses the Earth's rate only.
            acc.add(
                &c,
                &Vector3::new(0.0, 0.0, -9.8),
                &(c.transpose() * w_ie),
                dt,
            );
            acc.distance_m += 20.0 * dt;
        }
        let q = acc.gravity_disturbance_noise(&g, &r_e, &w_ie);
        let k = 2.0 * 1.0 / 25e3;
        let expect = g.body_covariance(&Vector3::z()) * k;
        assert!(
            (q - expect).abs().max() < 1e-9 * expect.max(),
            "{q}\n{expect}"
        );
        // Nothing modelled, nothing added.
        let q0 = acc.gravity_disturbance_noise(&GravityDisturbance::default(), &r_e, &w_ie);
        assert_eq!(q0, Matrix3::zeros());
    }

    /// Turning in place under an Earth-fixed disturbance: over a turn by Θ the body components
    /// of a horizontal vector of per-axis variance σ_h² change with variance `2σ_h²(1 − cos Θ)`
    /// per horizontal axis; the accumulated random walk is `Θ_c Θ σ_h²`, which bounds it for
    /// every Θ (the bound [`MISALIGNMENT_COHERENCE_RAD`] is derived for), and the vertical
    /// axis gains nothing from a turn about it.
    #[test]
    fn gravity_disturbance_turning_bound_covers_the_rotated_vector() {
        let g = disturbance();
        let sh2 = g.horizontal_sigma_m_s2.powi(2);
        let lat = 0.9;
        let w_ie = WGS84.omega_ie_e();
        let rate = 0.2; // rad/s about the body's down axis
        let dt = 0.05;
        let mut total = Matrix3::zeros();
        let mut yaw = 0.0_f64;
        while yaw < std::f64::consts::PI {
            let c = level_c_e_b(lat, yaw);
            let r_e = c.column(2) * -6.37e6;
            let mut acc = TransitionAccumulator::default();
            let w_b = c.transpose() * w_ie + Vector3::new(0.0, 0.0, rate);
            acc.add(&c, &Vector3::new(0.0, 0.0, -9.8), &w_b, dt);
            total += acc.gravity_disturbance_noise(&g, &r_e, &w_ie);
            yaw += rate * dt;
            let theta = yaw;
            let exact = 2.0 * sh2 * (1.0 - theta.cos());
            for axis in 0..2 {
                assert!(total[(axis, axis)] >= exact, "{theta}: {total}");
            }
        }
        let expect = MISALIGNMENT_COHERENCE_RAD * yaw * sh2;
        assert!((total[(0, 0)] - expect).abs() < 1e-6 * expect, "{total}");
        assert!(total[(2, 2)].abs() < 1e-6 * expect, "{total}");
    }

    #[test]
    fn schuler_frequency_from_gradient() {
        // Horizontal eigenvalue of the gradient ≈ −g/r (paper 002: ν² = g/r, T ≈ 84.4 min).
        let g = gravity_gradient(&WGS84, &Vector3::new(0.0, 0.0, 6_356_752.0));
        let nu2 = -g[(0, 0)];
        let period_min = 2.0 * std::f64::consts::PI / nu2.sqrt() / 60.0;
        assert!((period_min - 84.4).abs() < 0.844, "{period_min}");
        assert!(g[(2, 2)] > 0.0, "vertical channel must be unstable");
    }
}
