//! Error-state extended Kalman filter in ECEF, closed loop (corrections are fed back into the
//! strapdown state and the sensor-error estimates, after which the error state is zero again).
//!
//! # Error state (fixed size [`NX`] = 31; groups switchable, see [`ActiveStates`])
//! Every error is *truth minus estimate* (so that a measurement residual `y = z − h(x̂)` is
//! `y = H·δx + v` with `H = ∂h/∂x` and the correction is `x̂ ← x̂ + δx`):
//!
//! | index | group | meaning | unit |
//! |---|---|---|---|
//! | 0..3 | [`idx::POS`] | `δr_e = r_e − r̂_e`, ECEF | m |
//! | 3..6 | [`idx::VEL`] | `δv_e = v_e − v̂_e`, ECEF (velocity relative to the Earth) | m/s |
//! | 6..9 | [`idx::ATT`] | `ψ`, attitude error in ECEF: `C_e_b = (I + [ψ×])·Ĉ_e_b` | rad |
//! | 9..12 | [`idx::BG`] | `δb_g = b_g − b̂_g`, gyro bias, body | rad/s |
//! | 12..15 | [`idx::BA`] | `δb_a = b_a − b̂_a`, accelerometer bias, body | m/s² |
//! | 15 | [`idx::BARO`] | `δb_h`, baro height bias (`h_baro = h + b_h`) | m |
//! | 16 | [`idx::ODO`] | `δk`, odometer scale-factor error (`s_odo = (1 + k)·v_x`) | – |
//! | 17..20 | [`idx::SG`] | `δs_g`, gyro scale-factor error per body axis | – |
//! | 20..23 | [`idx::SA`] | `δs_a`, accelerometer scale-factor error per body axis | – |
//! | 23..26 | [`idx::KAPPA`] | `δκ`, star-tracker boresight angles κ1..κ3 (paper 000) | rad |
//! | 26 | [`idx::CLK`] | `δb_clk`, receiver clock bias × c | m |
//! | 27 | [`idx::CLK_DRIFT`] | `δd_clk`, receiver clock drift × c | m/s |
//! | 28..31 | [`idx::SGM`] | `δp_g = (δS_xy, δS_xz, δS_yz)`, gyro non-orthogonality | rad |
//!
//! An inactive group keeps zero covariance rows/columns and zero process noise: its Kalman
//! gain rows are then zero (`K = P Hᵀ S⁻¹`), so it is never corrected and costs nothing in
//! accuracy; the matrices stay fixed-size so nothing allocates or changes shape at run time.
//!
//! The odometer scale factor and the baro bias are states because the simulated (and real)
//! errors are dominated by constants that white noise cannot represent (measured: horizontal
//! RMS 1.1 m with the odometer scale as noise, 0.24 m as a state, in the default vehicle run).
//!
//! # Sensor error models (the simulator's, `drivers-sim/src/imu.rs`)
//! `ω̃ = (1 + s_g)∘((I + S_g)·ω) + b_g + n_g`, `f̃ = (1 + s_a)∘f + b_a + n_a` (∘ element-wise),
//! `S_g` the gyro triad's symmetric non-orthogonality (the triad defines the body frame, so a
//! rigid rotation is not an error; `S_g·ω = W(ω)·p_g` with `p_g = (S_xy, S_xz, S_yz)` and
//! `W(ω) = [[ω_y, ω_z, 0], [ω_x, 0, ω_z], [0, ω_x, ω_y]]`), so the corrected outputs are
//! `ω̂ = (I − Ŝ_g)·((ω̃ − b̂_g) ⊘ (1 + ŝ_g))` and `f̂ = (f̃ − b̂_a) ⊘ (1 + ŝ_a)`
//! ([`ErrorStateEkf::correct_increment`]) and, to first order,
//! `ω − ω̂ = −δb_g − diag(ω̂)·δs_g − W(ω̂)·δp_g`, `f − f̂ = −δb_a − diag(f̂)·δs_a`.
//! The accelerometer misalignment is not a state: with the vehicle level its gravity part is
//! a bias (absorbed by `b_a`, whose prior the navigator widens for it) and its part times the
//! vehicle acceleration is below a metre over 10 minutes of free inertial (the
//! `inertial-budget` experiment: 0.17 m in the tight-coupling window).
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
//! Propagating a dense 28×28 covariance every IMU sample (`Φ P Φᵀ`, 2·28³ ≈ 44 000
//! multiply-adds) would cap the filter near 30 000 samples/s. Instead the strapdown step only
//! *accumulates* the integral of `F` over a covariance interval ([`TransitionAccumulator`]:
//! `∫Ĉ_e_b dt`, `∫f̂_e dt`, `∫Ĉ_e_b diag(f̂) dt`, `∫Ĉ_e_b diag(ω̂) dt`, a few 3×3 sums) and the
//! covariance is propagated at the end of the interval and always before an update
//! ([`ErrorStateEkf::propagate_covariance`]), with `Φ = I + F̄T + ½(F̄T)²` (`F̄T = ∫F dt`; the
//! neglected commutator terms are `O(|F|²T²)` of the varying part, < 10⁻⁶ for T = 50 ms) and
//! trapezoidal noise `P⁺ = Φ (P + ½ Q_c T) Φᵀ + ½ Q_c T`. `Φ` differs from the identity only
//! in the 9 navigation rows (and the clock bias–drift entry), so `Φ P Φᵀ` is formed as a
//! 9×28·28×28 product for the rows and a 28×28·28×9 one for the columns (≈ 14 000
//! multiply-adds, once per interval).
//!
//! # Update
//! [`update`] is a pure function in the style of nyx `od/kalman`: it returns the correction,
//! the new covariance and a [`Residual`] record (innovation, its covariance `S`, normalized
//! innovation squared `NIS = yᵀ S⁻¹ y`, the chi-square gate for `dim y` at the configured
//! probability and whether the sample was rejected). Joseph form
//! `P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ`, evaluated in its expanded, algebraically identical
//! `O(n²m)` form `P − K (P Hᵀ)ᵀ − (P Hᵀ) Kᵀ + K S Kᵀ` (valid for any gain, like the factored
//! form), then symmetrised. Everything is fixed-size (`SMatrix`/`SVector`): no allocation.
//!
//! # Measurement models
//! [`gnss_position`], [`gnss_velocity`] (loose), [`gnss_pseudorange`], [`gnss_range_rate`]
//! (tight, one satellite each, paper 003), [`star_attitude`] (with boresight κ),
//! [`gnss_baseline_attitude`] (dual-baseline GNSS attitude, paper 003),
//! [`baro_height`], [`odometer_nhc`] / [`odometer_speed`], [`zero_velocity`]; each returns a
//! [`Measurement`] (innovation, `H`, `R`) evaluated at the inertial state of the sample's time
//! of validity.

use crate::attitude::skew;
use crate::earth::Ellipsoid;
use crate::strapdown::NavState;
use nalgebra::{Cholesky, Matrix3, Rotation3, SMatrix, SVector, UnitQuaternion, Vector3};

/// Number of error states.
pub const NX: usize = 31;

/// Start index of each state group in the error-state vector.
pub mod idx {
    /// Position error δr_e, ECEF, m.
    pub const POS: usize = 0;
    /// Velocity error δv_e, ECEF, m/s.
    pub const VEL: usize = 3;
    /// Attitude error ψ, ECEF, rad.
    pub const ATT: usize = 6;
    /// Gyro bias error, body, rad/s.
    pub const BG: usize = 9;
    /// Accelerometer bias error, body, m/s².
    pub const BA: usize = 12;
    /// Baro height bias error, m (one state).
    pub const BARO: usize = 15;
    /// Odometer scale-factor error (one state, dimensionless).
    pub const ODO: usize = 16;
    /// Gyro scale-factor errors, body x, y, z (dimensionless).
    pub const SG: usize = 17;
    /// Accelerometer scale-factor errors, body x, y, z (dimensionless).
    pub const SA: usize = 20;
    /// Star-tracker boresight angles κ1, κ2, κ3, rad.
    pub const KAPPA: usize = 23;
    /// Receiver clock bias × c, m.
    pub const CLK: usize = 26;
    /// Receiver clock drift × c, m/s.
    pub const CLK_DRIFT: usize = 27;
    /// Gyro non-orthogonality `(S_xy, S_xz, S_yz)` (symmetric), rad.
    pub const SGM: usize = 28;
}

/// Error-state vector (see the module table for layout and units).
pub type StateVector = SVector<f64, NX>;
/// Error-state covariance.
pub type Covariance = SMatrix<f64, NX, NX>;
/// The rows of `Φ` that differ from the identity: position, velocity, attitude.
type NavRows = SMatrix<f64, 9, NX>;

/// Largest measurement dimension any model produces (for gate tables).
pub const MAX_MEAS_DIM: usize = 6;

/// Which switchable state groups are estimated (the others keep zero covariance).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ActiveStates {
    /// Gyro scale factors (3).
    pub gyro_scale: bool,
    /// Accelerometer scale factors (3).
    pub accel_scale: bool,
    /// Star-tracker boresight κ1..κ3 (3).
    pub boresight: bool,
    /// Receiver clock bias and drift (2).
    pub clock: bool,
    /// Gyro non-orthogonality (3). Off: its attitude error enters as noise per radian turned
    /// ([`MISALIGNMENT_COHERENCE_RAD`]).
    pub gyro_misalignment: bool,
}

impl ActiveStates {
    /// Every group on.
    pub const ALL: Self = Self {
        gyro_scale: true,
        accel_scale: true,
        boresight: true,
        clock: true,
        gyro_misalignment: true,
    };

    /// Per-state flag: true when the state is estimated.
    pub fn mask(&self) -> [bool; NX] {
        let mut m = [true; NX];
        for (on, start, len) in [
            (self.gyro_scale, idx::SG, 3),
            (self.accel_scale, idx::SA, 3),
            (self.boresight, idx::KAPPA, 3),
            (self.clock, idx::CLK, 2),
            (self.gyro_misalignment, idx::SGM, 3),
        ] {
            for v in m.iter_mut().skip(start).take(len) {
                *v = on;
            }
        }
        m
    }
}

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
/// the maximum is at `Θ = tan(Θ/2)` (Θ* = 2.3311 rad) and equals 1.4492 (the test
/// `misalignment_coherence_bounds_the_chord` checks it). The random walk equals the
/// coherent error at Θ*, exceeds it for smaller turns (by Θ_c/Θ) and keeps growing after
/// Θ* where the true error is bounded by 2|s|; the star tracker resets it in between.
pub const MISALIGNMENT_COHERENCE_RAD: f64 = 1.4492;

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

    /// The navigation rows (0..9) of `Φ = I + F̄T + ½(F̄T)²` with the gravity gradient taken
    /// at `r_e` (it changes by < 10⁻⁵ relative over an interval).
    pub fn nav_rows(&self, ell: &Ellipsoid, r_e: &Vector3<f64>) -> SMatrix<f64, 9, NX> {
        let t = self.dt_s;
        let omega = skew(&ell.omega_ie_e());
        let mut fi = NavRows::zeros();
        // Rows 0..3 position, 3..6 velocity, 6..9 attitude (state indices equal row indices).
        fi.fixed_view_mut::<3, 3>(idx::POS, idx::VEL)
            .copy_from(&(Matrix3::identity() * t));
        fi.fixed_view_mut::<3, 3>(idx::VEL, idx::POS)
            .copy_from(&(gravity_gradient(ell, r_e) * t));
        fi.fixed_view_mut::<3, 3>(idx::VEL, idx::VEL)
            .copy_from(&(omega * (-2.0 * t)));
        fi.fixed_view_mut::<3, 3>(idx::VEL, idx::ATT)
            .copy_from(&(-skew(&self.sum_f_e)));
        fi.fixed_view_mut::<3, 3>(idx::VEL, idx::BA)
            .copy_from(&(-self.sum_c_e_b));
        fi.fixed_view_mut::<3, 3>(idx::VEL, idx::SA)
            .copy_from(&(-self.sum_c_diag_f));
        fi.fixed_view_mut::<3, 3>(idx::ATT, idx::ATT)
            .copy_from(&(omega * (-t)));
        fi.fixed_view_mut::<3, 3>(idx::ATT, idx::BG)
            .copy_from(&(-self.sum_c_e_b));
        fi.fixed_view_mut::<3, 3>(idx::ATT, idx::SG)
            .copy_from(&(-self.sum_c_diag_w));
        fi.fixed_view_mut::<3, 3>(idx::ATT, idx::SGM)
            .copy_from(&(-self.sum_c_w_mis));
        // F has non-zero rows only in 0..9 (plus the clock row, whose column 27 meets no
        // non-zero row of F), so (F̄T)² restricted to rows 0..9 is F̄T[:, 0..9] · F̄T[0..9, :].
        let sq = fi.fixed_columns::<9>(0) * fi;
        let mut a = fi + sq * 0.5;
        for i in 0..9 {
            a[(i, i)] += 1.0;
        }
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

/// The filter's own state: error covariance, the sensor-error estimates it feeds back, and
/// the transition accumulated since the last covariance propagation.
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorStateEkf {
    /// Error-state covariance (layout in the module docs), valid at the last propagation.
    pub p: Covariance,
    /// Estimated gyro bias, body, rad/s.
    pub gyro_bias_rad_s: Vector3<f64>,
    /// Estimated accelerometer bias, body, m/s².
    pub accel_bias_m_s2: Vector3<f64>,
    /// Estimated baro height bias, m (`h_baro = h + b_h`).
    pub baro_bias_m: f64,
    /// Estimated odometer scale-factor error `k` (`s_odo = (1 + k)·v_x`).
    pub odo_scale: f64,
    /// Estimated gyro scale-factor errors, body axes (dimensionless).
    pub gyro_scale: Vector3<f64>,
    /// Estimated accelerometer scale-factor errors, body axes (dimensionless).
    pub accel_scale: Vector3<f64>,
    /// Estimated star-tracker boresight angles κ1..κ3, rad.
    pub kappa_rad: Vector3<f64>,
    /// Estimated receiver clock bias × c, m.
    pub clock_bias_m: f64,
    /// Estimated receiver clock drift × c, m/s.
    pub clock_drift_m_s: f64,
    /// Estimated gyro non-orthogonality `(S_xy, S_xz, S_yz)`, rad.
    pub gyro_misalignment_rad: Vector3<f64>,
    /// Process noise densities.
    pub noise: ProcessNoise,
    active: [bool; NX],
    qc: StateVector,
    acc: TransitionAccumulator,
}

impl ErrorStateEkf {
    /// A filter with initial covariance `p0` (rows/columns of inactive groups are zeroed),
    /// zero error estimates, the given noise and active state groups. Active
    /// non-orthogonality states to which `p0` gives no variance start with the grade's
    /// `noise.gyro_misalignment_rad²` (the prior of a random constant).
    pub fn new(p0: Covariance, noise: ProcessNoise, active: ActiveStates) -> Self {
        let mut f = Self {
            p: p0,
            gyro_bias_rad_s: Vector3::zeros(),
            accel_bias_m_s2: Vector3::zeros(),
            baro_bias_m: 0.0,
            odo_scale: 0.0,
            gyro_scale: Vector3::zeros(),
            accel_scale: Vector3::zeros(),
            kappa_rad: Vector3::zeros(),
            clock_bias_m: 0.0,
            clock_drift_m_s: 0.0,
            gyro_misalignment_rad: Vector3::zeros(),
            noise,
            active: [true; NX],
            qc: StateVector::zeros(),
            acc: TransitionAccumulator::default(),
        };
        f.set_active(active);
        for i in idx::SGM..idx::SGM + 3 {
            if f.p[(i, i)] == 0.0 {
                f.set_initial_sigma(i, noise.gyro_misalignment_rad);
            }
        }
        f
    }

    /// Switch state groups on or off. Switching a group off zeroes its covariance rows and
    /// columns (its estimate is kept); switching it on leaves its covariance zero until
    /// [`Self::set_initial_sigma`] gives it one.
    pub fn set_active(&mut self, active: ActiveStates) {
        self.active = active.mask();
        let q = self.noise.qc_diagonal();
        for i in 0..NX {
            self.qc[i] = if self.active[i] { q[i] } else { 0.0 };
            if !self.active[i] {
                self.p.row_mut(i).fill(0.0);
                self.p.column_mut(i).fill(0.0);
            }
        }
    }

    /// Whether state `i` is estimated.
    pub fn is_active(&self, i: usize) -> bool {
        self.active.get(i).copied().unwrap_or(false)
    }

    /// Give state `i` (when active) the variance `sigma²`, uncorrelated with the others.
    pub fn set_initial_sigma(&mut self, i: usize, sigma: f64) {
        if self.is_active(i) && sigma.is_finite() {
            self.p.row_mut(i).fill(0.0);
            self.p.column_mut(i).fill(0.0);
            self.p[(i, i)] = sigma * sigma;
        }
    }

    /// Correct one raw IMU increment (`delta_angle_rad`, `delta_velocity_m_s`, body, over
    /// `dt_s`) with the bias and scale-factor estimates, `(x̃ − b̂ dt) ⊘ (1 + ŝ)`, and the
    /// delta-angle also with the non-orthogonality, `(I − Ŝ_g)·(…)` (`(I + Ŝ)⁻¹` to first
    /// order; the second-order term `Ŝ²` is ≈ 10⁻⁹ for 10″).
    pub fn correct_increment(
        &self,
        delta_angle_rad: &Vector3<f64>,
        delta_velocity_m_s: &Vector3<f64>,
        dt_s: f64,
    ) -> (Vector3<f64>, Vector3<f64>) {
        let dth = (delta_angle_rad - self.gyro_bias_rad_s * dt_s)
            .component_div(&self.gyro_scale.add_scalar(1.0));
        let dth = dth - nonorthogonality_matrix(&self.gyro_misalignment_rad) * dth;
        let dv = (delta_velocity_m_s - self.accel_bias_m_s2 * dt_s)
            .component_div(&self.accel_scale.add_scalar(1.0));
        (dth, dv)
    }

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
        self.acc = TransitionAccumulator::default();
        let mut p = self.p;
        for i in 0..NX {
            p[(i, i)] += 0.5 * self.qc[i] * t;
        }
        // M = Φ P: rows 0..9 from A, clock bias row += T · drift row.
        let mut m = p;
        m.fixed_rows_mut::<9>(0).copy_from(&(a * p));
        if self.active[idx::CLK] {
            let drift_row = p.row(idx::CLK_DRIFT).into_owned();
            let mut r = m.row_mut(idx::CLK);
            r += drift_row * t;
        }
        // P⁺ = M Φᵀ: columns 0..9 from Aᵀ, clock bias column += T · drift column.
        let mut pn = m;
        pn.fixed_columns_mut::<9>(0).copy_from(&(m * a.transpose()));
        if self.active[idx::CLK] {
            let drift_col = m.column(idx::CLK_DRIFT).into_owned();
            let mut c = pn.column_mut(idx::CLK);
            c += drift_col * t;
        }
        for i in 0..NX {
            pn[(i, i)] += 0.5 * self.qc[i] * t;
        }
        let mut att = pn.fixed_view_mut::<3, 3>(idx::ATT, idx::ATT);
        att += q_mis;
        self.p = symmetrize(&pn);
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

    /// Apply an accepted correction `dx` to the navigation state and the error estimates
    /// (closed loop); the error state is zero afterwards. The covariance reset Jacobian
    /// `I − ½[ψ×]` is ≈ I for the small ψ of a running filter and is not applied.
    pub fn apply_correction(&mut self, nav: &mut NavState, dx: &StateVector) {
        correct_nav_state(nav, dx);
        self.gyro_bias_rad_s += dx.fixed_rows::<3>(idx::BG);
        self.accel_bias_m_s2 += dx.fixed_rows::<3>(idx::BA);
        self.baro_bias_m += dx[idx::BARO];
        self.odo_scale += dx[idx::ODO];
        self.gyro_scale += dx.fixed_rows::<3>(idx::SG);
        self.accel_scale += dx.fixed_rows::<3>(idx::SA);
        self.kappa_rad += dx.fixed_rows::<3>(idx::KAPPA);
        self.clock_bias_m += dx[idx::CLK];
        self.clock_drift_m_s += dx[idx::CLK_DRIFT];
        self.gyro_misalignment_rad += dx.fixed_rows::<3>(idx::SGM);
    }
}

/// Apply the kinematic part of a correction (position, velocity, attitude) to a state.
pub fn correct_nav_state(nav: &mut NavState, dx: &StateVector) {
    nav.r_e += dx.fixed_rows::<3>(idx::POS);
    nav.v_e += dx.fixed_rows::<3>(idx::VEL);
    let psi: Vector3<f64> = dx.fixed_rows::<3>(idx::ATT).into_owned();
    nav.q_e_b = UnitQuaternion::from_scaled_axis(psi) * nav.q_e_b;
    nav.q_e_b.renormalize();
}

/// `(P + Pᵀ)/2`.
pub fn symmetrize<const D: usize>(p: &SMatrix<f64, D, D>) -> SMatrix<f64, D, D> {
    (p + p.transpose()) * 0.5
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

/// Result of [`update`]: correction, covariance after the update, and the residual record.
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
    let pht: SMatrix<f64, NX, M> = p * m.h.transpose();
    let s = symmetrize(&(m.h * pht + m.r));
    let rejected_outcome = |nis: f64| UpdateOutcome {
        dx: StateVector::zeros(),
        p: *p,
        residual: Residual {
            innovation: m.innovation,
            covariance: s,
            nis,
            gate,
            rejected: true,
        },
    };
    let finite = m.innovation.iter().all(|x| x.is_finite())
        && m.h.iter().all(|x| x.is_finite())
        && m.r.iter().all(|x| x.is_finite());
    if !finite {
        return rejected_outcome(f64::INFINITY);
    }
    let Some(chol) = Cholesky::new(s) else {
        return rejected_outcome(f64::INFINITY);
    };
    let nis = m.innovation.dot(&chol.solve(&m.innovation));
    if !nis.is_finite() || nis > gate {
        return rejected_outcome(nis);
    }
    let s_inv = chol.inverse();
    let k: SMatrix<f64, NX, M> = pht * s_inv;
    let dx = k * m.innovation;
    // Joseph form, expanded: (I−KH)P(I−KH)ᵀ + KRKᵀ = P − K(PHᵀ)ᵀ − (PHᵀ)Kᵀ + K S Kᵀ.
    let k_pht_t = k * pht.transpose();
    let p_new = p - k_pht_t - k_pht_t.transpose() + k * s * k.transpose();
    let p_new = symmetrize(&p_new);
    if !(dx.iter().all(|x| x.is_finite()) && p_new.iter().all(|x| x.is_finite())) {
        return rejected_outcome(f64::INFINITY);
    }
    UpdateOutcome {
        dx,
        p: p_new,
        residual: Residual {
            innovation: m.innovation,
            covariance: s,
            nis,
            gate,
            rejected: false,
        },
    }
}

/// GNSS position (antenna at the IMU, HELPERS.md): `z = r_e` (ECEF, m) with covariance
/// `cov` (ECEF, m²); `nav` is the inertial state at the fix's time of validity.
pub fn gnss_position(nav: &NavState, pos_e: &Vector3<f64>, cov: &Matrix3<f64>) -> Measurement<3> {
    let mut h = SMatrix::<f64, 3, NX>::zeros();
    h.fixed_view_mut::<3, 3>(0, idx::POS)
        .copy_from(&Matrix3::identity());
    Measurement {
        innovation: pos_e - nav.r_e,
        h,
        r: *cov,
    }
}

/// GNSS velocity: `z = v_e` (ECEF, Earth-relative, m/s) with covariance `cov` ((m/s)²).
pub fn gnss_velocity(nav: &NavState, vel_e: &Vector3<f64>, cov: &Matrix3<f64>) -> Measurement<3> {
    let mut h = SMatrix::<f64, 3, NX>::zeros();
    h.fixed_view_mut::<3, 3>(0, idx::VEL)
        .copy_from(&Matrix3::identity());
    Measurement {
        innovation: vel_e - nav.v_e,
        h,
        r: *cov,
    }
}

/// One satellite's pseudorange (tight coupling, paper 003 eq. 12 linearised at the inertial
/// solution; antenna at the IMU). The satellite position `sat_pos_e` is the one at
/// transmission rotated into the ECEF frame of reception (Sagnac included, as the receiver
/// and `drivers-sim/src/gnss.rs` give it), so `ρ̂ = |r_s − r̂_e| + b̂_clk`,
/// `H_r = −uᵀ` (u = unit line of sight receiver → satellite), `H_clk = 1`; noise `sigma_m`.
pub fn gnss_pseudorange(
    nav: &NavState,
    sat_pos_e: &Vector3<f64>,
    pseudorange_m: f64,
    clock_bias_m: f64,
    sigma_m: f64,
) -> Measurement<1> {
    let d = sat_pos_e - nav.r_e;
    let range = d.norm();
    let u = d / range;
    let mut h = SMatrix::<f64, 1, NX>::zeros();
    h.fixed_view_mut::<1, 3>(0, idx::POS)
        .copy_from(&(-u.transpose()));
    h[(0, idx::CLK)] = 1.0;
    Measurement {
        innovation: SVector::<f64, 1>::new(pseudorange_m - range - clock_bias_m),
        h,
        r: SMatrix::<f64, 1, 1>::new(sigma_m * sigma_m),
    }
}

/// One satellite's Doppler range rate (tight coupling): `ρ̇̂ = (v_s − v̂_e)·u + d̂_clk` with
/// `u = (r_s − r̂_e)/|r_s − r̂_e|` (the simulator's definition). `H_v = −uᵀ`, `H_d = 1`, and
/// through the line of sight `H_r = −(v_s − v̂_e)ᵀ (I − u uᵀ)/ρ` (`∂u/∂r̂ = −(I − u uᵀ)/ρ`,
/// ~10⁻⁴ per m: small but kept exact); noise `sigma_m_s`.
pub fn gnss_range_rate(
    nav: &NavState,
    sat_pos_e: &Vector3<f64>,
    sat_vel_e: &Vector3<f64>,
    range_rate_m_s: f64,
    clock_drift_m_s: f64,
    sigma_m_s: f64,
) -> Measurement<1> {
    let d = sat_pos_e - nav.r_e;
    let range = d.norm();
    let u = d / range;
    let dv = sat_vel_e - nav.v_e;
    let mut h = SMatrix::<f64, 1, NX>::zeros();
    let h_r = -(dv.transpose() * (Matrix3::identity() - u * u.transpose())) / range;
    h.fixed_view_mut::<1, 3>(0, idx::POS).copy_from(&h_r);
    h.fixed_view_mut::<1, 3>(0, idx::VEL)
        .copy_from(&(-u.transpose()));
    h[(0, idx::CLK_DRIFT)] = 1.0;
    Measurement {
        innovation: SVector::<f64, 1>::new(range_rate_m_s - dv.dot(&u) - clock_drift_m_s),
        h,
        r: SMatrix::<f64, 1, 1>::new(sigma_m_s * sigma_m_s),
    }
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
/// line of sight by a clock it believes independent (the one-satellite defect of issue 5).
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
mod augmentation_tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    /// Monte Carlo: draw δx ~ N(0, P) and ε, form δc = −Hδx − ε; the sample covariance of
    /// (δx, δc) must equal the augmented P. With N draws the sample covariance of two unit
    /// variables has standard error ≤ √(2/N); we accept 5 standard errors on every element
    /// of the correlation-normalised difference.
    #[test]
    fn augmented_covariance_is_the_covariance_of_the_construction() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        // A random SPD prior on the 26 non-clock states, clock rows zero.
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

/// Zero-velocity update: `z = 0` for the ECEF velocity, isotropic noise `sigma_m_s`.
pub fn zero_velocity(nav: &NavState, sigma_m_s: f64) -> Measurement<3> {
    let mut m = gnss_velocity(
        nav,
        &Vector3::zeros(),
        &(Matrix3::identity() * sigma_m_s * sigma_m_s),
    );
    m.innovation = -nav.v_e;
    m
}

/// Paper 000 boresight misalignment `M(κ) = R_z(κ1)·R_x(κ2)·R_y(κ3)` (κ in rad); the true
/// mount is `C_s_b = C_s_b,nominal · M(κ)` (HELPERS.md, `drivers-sim` `kappa_matrix`).
pub fn kappa_matrix(kappa_rad: &Vector3<f64>) -> Matrix3<f64> {
    let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), kappa_rad[0]);
    let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), kappa_rad[1]);
    let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), kappa_rad[2]);
    (rz * rx * ry).into_inner()
}

/// Right Jacobian `B(κ)` of the boresight matrix: `M(κ + δκ) ≈ M(κ)·(I + [B δκ ×])`.
/// From `∂M/∂κ1 = [e_z×] M`, `∂M/∂κ2 = R_z [e_x×] R_x R_y`, `∂M/∂κ3 = M [e_y×]` and
/// `Mᵀ[a×]M = [(Mᵀa)×]`: `B = [R_yᵀR_xᵀ e_z, R_yᵀ e_x, e_y]`.
pub fn kappa_jacobian(kappa_rad: &Vector3<f64>) -> Matrix3<f64> {
    let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), kappa_rad[1]).into_inner();
    let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), kappa_rad[2]).into_inner();
    let c1 = ry.transpose() * rx.transpose() * Vector3::z();
    let c2 = ry.transpose() * Vector3::x();
    Matrix3::from_columns(&[c1, c2, Vector3::y()])
}

/// Star-tracker attitude with boresight states.
///
/// Measured `C̃_s_i` (ICRF → sensor, from `q_s_i_meas`), predicted
/// `Ĉ_s_i = C_s_b,nom · M(κ̂) · Ĉ_b_e · C_e_i(t)` with `c_e_i` = GCRS → ITRS at the exposure
/// time (ICRF → ITRS → body → sensor). With `C_b_e = Ĉ_b_e (I − [ψ×])`,
/// `M(κ) = M(κ̂)(I + [B δκ×])` ([`kappa_jacobian`]) and sensor-frame noise ν
/// (`C̃_s_i = (I − [ν×]) C_s_i`), the residual rotation vector
/// `y = rotvec(Ĉ_s_i C̃_s_iᵀ) = Ĉ_s_b Ĉ_b_e ψ − Ĉ_s_b B δκ + ν` (sensor axes, rad), so
/// `H_ψ = Ĉ_s_e`, `H_κ = −Ĉ_s_b B`, `R = diag(σ_cross², σ_cross², σ_roll²)` (optical axis =
/// sensor z). Only a heading change separates κ from ψ: a rotation of the mount and one of
/// the vehicle look the same until the body turns relative to the Earth (or the Earth turns
/// relative to the stars, which `C_e_i(t)` carries).
pub fn star_attitude(
    nav: &NavState,
    q_s_i_meas: &UnitQuaternion<f64>,
    c_e_i: &Matrix3<f64>,
    c_s_b_nominal: &Matrix3<f64>,
    kappa_rad: &Vector3<f64>,
    sigma_cross_rad: f64,
    sigma_roll_rad: f64,
) -> Measurement<3> {
    let c_b_e = nav.q_e_b.to_rotation_matrix().into_inner().transpose();
    let c_s_b = c_s_b_nominal * kappa_matrix(kappa_rad);
    let c_s_e = c_s_b * c_b_e;
    let c_s_i_pred = c_s_e * c_e_i;
    let c_s_i_meas = q_s_i_meas.to_rotation_matrix().into_inner();
    let e = c_s_i_pred * c_s_i_meas.transpose();
    let y =
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(e)).scaled_axis();
    let mut h = SMatrix::<f64, 3, NX>::zeros();
    h.fixed_view_mut::<3, 3>(0, idx::ATT).copy_from(&c_s_e);
    h.fixed_view_mut::<3, 3>(0, idx::KAPPA)
        .copy_from(&(-c_s_b * kappa_jacobian(kappa_rad)));
    let r = Matrix3::from_diagonal(&Vector3::new(
        sigma_cross_rad.powi(2),
        sigma_cross_rad.powi(2),
        sigma_roll_rad.powi(2),
    ));
    Measurement {
        innovation: y,
        h,
        r,
    }
}
/// Dual-baseline GNSS attitude (paper 003 eq. 14–21, [`crate::baseline_attitude`]) as a
/// measurement. The solver reports `C̃_e_b = (I + [ε×])·C_e_b` with covariance `cov_e` of the
/// ECEF rotation ε; with `C_e_b = (I + [ψ×])·Ĉ_e_b`, the residual rotation vector
/// `y = rotvec(C̃_e_b Ĉ_e_bᵀ) = ψ + ε` (ECEF, rad), so `H_ψ = I`, `R = cov_e`.
pub fn gnss_baseline_attitude(
    nav: &NavState,
    c_e_b_meas: &Matrix3<f64>,
    cov_e_rad2: &Matrix3<f64>,
) -> Measurement<3> {
    let c_e_b = nav.q_e_b.to_rotation_matrix().into_inner();
    let e = c_e_b_meas * c_e_b.transpose();
    let y =
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(e)).scaled_axis();
    let mut h = SMatrix::<f64, 3, NX>::zeros();
    h.fixed_view_mut::<3, 3>(0, idx::ATT)
        .copy_from(&Matrix3::identity());
    Measurement {
        innovation: y,
        h,
        r: *cov_e_rad2,
    }
}

/// Baro altitude taken as height above the ellipsoid (HELPERS.md): `z = h_baro` (m),
/// predicted `ĥ + b̂_h` (geodetic height of `r̂_e` plus the estimated baro bias
/// `baro_bias_m`); `H_r = u_upᵀ` (ECEF unit up vector at the estimated latitude/longitude),
/// `H_b = 1`; white noise `sigma_m`.
pub fn baro_height(
    nav: &NavState,
    ell: &Ellipsoid,
    height_baro_m: f64,
    baro_bias_m: f64,
    sigma_m: f64,
) -> Measurement<1> {
    let g = crate::earth::ecef_to_geodetic(ell, &nav.r_e);
    let up = Vector3::new(
        g.lat_rad.cos() * g.lon_rad.cos(),
        g.lat_rad.cos() * g.lon_rad.sin(),
        g.lat_rad.sin(),
    );
    let mut h = SMatrix::<f64, 1, NX>::zeros();
    h.fixed_view_mut::<1, 3>(0, idx::POS)
        .copy_from(&up.transpose());
    h[(0, idx::BARO)] = 1.0;
    Measurement {
        innovation: SVector::<f64, 1>::new(height_baro_m - g.height_m - baro_bias_m),
        h,
        r: SMatrix::<f64, 1, 1>::new(sigma_m * sigma_m),
    }
}

/// Body-frame velocity Jacobians: `v_b = C_b_e v_e`; with the error definitions
/// `δv_b = Ĉ_b_e δv + Ĉ_b_e [v̂_e×] ψ`.
fn body_velocity_jacobians(nav: &NavState) -> (Vector3<f64>, Matrix3<f64>, Matrix3<f64>) {
    let c_b_e = nav.q_e_b.to_rotation_matrix().into_inner().transpose();
    (c_b_e * nav.v_e, c_b_e, c_b_e * skew(&nav.v_e))
}

/// Odometer speed along body x plus non-holonomic constraints (zero lateral and vertical body
/// velocity) for a ground vehicle: `z = [speed, 0, 0]` (body, m/s), noise
/// `diag(σ_odo², σ_nhc², σ_nhc²)`. The odometer reads `(1 + k)·v_x`, `k` the scale-factor
/// state with estimate `odo_scale`.
pub fn odometer_nhc(
    nav: &NavState,
    odo_scale: f64,
    speed_m_s: f64,
    sigma_speed_m_s: f64,
    sigma_nhc_m_s: f64,
) -> Measurement<3> {
    let (v_b, h_v, h_psi) = body_velocity_jacobians(nav);
    let mut h = SMatrix::<f64, 3, NX>::zeros();
    h.fixed_view_mut::<3, 3>(0, idx::VEL).copy_from(&h_v);
    h.fixed_view_mut::<3, 3>(0, idx::ATT).copy_from(&h_psi);
    let scale = 1.0 + odo_scale;
    for j in 0..NX {
        h[(0, j)] *= scale;
    }
    h[(0, idx::ODO)] = v_b.x;
    Measurement {
        innovation: Vector3::new(speed_m_s - scale * v_b.x, -v_b.y, -v_b.z),
        h,
        r: Matrix3::from_diagonal(&Vector3::new(
            sigma_speed_m_s.powi(2),
            sigma_nhc_m_s.powi(2),
            sigma_nhc_m_s.powi(2),
        )),
    }
}

/// Odometer speed along body x alone (non-holonomic constraints switched off).
pub fn odometer_speed(
    nav: &NavState,
    odo_scale: f64,
    speed_m_s: f64,
    sigma_speed_m_s: f64,
) -> Measurement<1> {
    let (v_b, h_v, h_psi) = body_velocity_jacobians(nav);
    let scale = 1.0 + odo_scale;
    let mut h = SMatrix::<f64, 1, NX>::zeros();
    h.fixed_view_mut::<1, 3>(0, idx::VEL)
        .copy_from(&(h_v.fixed_rows::<1>(0) * scale));
    h.fixed_view_mut::<1, 3>(0, idx::ATT)
        .copy_from(&(h_psi.fixed_rows::<1>(0) * scale));
    h[(0, idx::ODO)] = v_b.x;
    Measurement {
        innovation: SVector::<f64, 1>::new(speed_m_s - scale * v_b.x),
        h,
        r: SMatrix::<f64, 1, 1>::new(sigma_speed_m_s.powi(2)),
    }
}

/// Chi-square gate thresholds for dimensions 1..=[`MAX_MEAS_DIM`] at one probability,
/// computed once (construction allocates nothing either).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GateTable {
    thresholds: [f64; MAX_MEAS_DIM + 1],
    /// Probability the gates were computed for.
    pub probability: f64,
}

impl GateTable {
    /// Gates at `probability` (0 < p < 1); `p >= 1` disables gating (infinite thresholds).
    pub fn new(probability: f64) -> Self {
        let mut thresholds = [f64::INFINITY; MAX_MEAS_DIM + 1];
        if probability < 1.0 {
            for (k, t) in thresholds.iter_mut().enumerate().skip(1) {
                *t = chi2_quantile(k as u32, probability);
            }
        }
        Self {
            thresholds,
            probability,
        }
    }
    /// Threshold for measurement dimension `m` (1..=MAX_MEAS_DIM).
    pub fn threshold(&self, m: usize) -> f64 {
        self.thresholds[m.min(MAX_MEAS_DIM)]
    }
}

/// `ln Γ(x)` for x > 0 (Lanczos, g = 7, n = 9; ~1e-15 relative).
fn ln_gamma(x: f64) -> f64 {
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + 7.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// Regularized lower incomplete gamma `P(a, x)` (Numerical Recipes `gammp`).
fn gamma_p(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    let gln = ln_gamma(a);
    if x < a + 1.0 {
        let mut ap = a;
        let mut sum = 1.0 / a;
        let mut del = sum;
        for _ in 0..500 {
            ap += 1.0;
            del *= x / ap;
            sum += del;
            if del.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        sum * (-x + a * x.ln() - gln).exp()
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..500 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-16 {
                break;
            }
        }
        1.0 - (-x + a * x.ln() - gln).exp() * h
    }
}

/// Chi-square cumulative distribution with `k` degrees of freedom at `x`.
pub fn chi2_cdf(x: f64, k: u32) -> f64 {
    gamma_p(0.5 * k as f64, 0.5 * x)
}

/// Chi-square quantile: the `x` with `chi2_cdf(x, k) = p` (bisection, ~1e-12 relative).
pub fn chi2_quantile(k: u32, p: f64) -> f64 {
    if p <= 0.0 {
        return 0.0;
    }
    if p >= 1.0 {
        return f64::INFINITY;
    }
    let mut lo = 0.0;
    let mut hi = k as f64 + 10.0;
    while chi2_cdf(hi, k) < p {
        lo = hi;
        hi *= 2.0;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if chi2_cdf(mid, k) < p {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo < 1e-12 * hi {
            break;
        }
    }
    0.5 * (lo + hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::earth::WGS84;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn nav_at_origin() -> NavState {
        NavState {
            r_e: Vector3::new(WGS84.a_m, 0.0, 0.0),
            v_e: Vector3::zeros(),
            q_e_b: UnitQuaternion::identity(),
        }
    }

    /// Θ_c bounds the variance of the nav-frame error of a body-fixed error rate over any
    /// turn, `4 sin²(Θ/2) ≤ Θ_c Θ`, and is the smallest such constant (touches at Θ* where
    /// `Θ* = tan(Θ*/2)`); closed form of the derivation at [`MISALIGNMENT_COHERENCE_RAD`].
    #[test]
    fn misalignment_coherence_bounds_the_chord() {
        let mut worst = 0.0_f64;
        for k in 1..=20_000 {
            let th = k as f64 * 1e-3;
            let chord2 = 4.0 * (th / 2.0).sin().powi(2);
            assert!(chord2 <= MISALIGNMENT_COHERENCE_RAD * th + 1e-4, "{th}");
            worst = worst.max(chord2 / th);
        }
        // 4-digit constant: the grid maximum agrees to its rounding.
        assert!((worst - MISALIGNMENT_COHERENCE_RAD).abs() < 1e-4, "{worst}");
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

    fn random_spd(rng: &mut ChaCha8Rng, scale: f64) -> Covariance {
        let a = Covariance::from_fn(|_, _| rng.random_range(-1.0..1.0));
        a * a.transpose() * scale + Covariance::identity() * 1e-6
    }

    #[test]
    fn chi2_quantiles_match_tables() {
        assert!((chi2_quantile(1, 0.99) - 6.634_897).abs() < 1e-5);
        assert!((chi2_quantile(3, 0.95) - 7.814_728).abs() < 1e-5);
        assert!((chi2_quantile(2, 0.999) - 13.815_511).abs() < 1e-5);
        assert!((chi2_quantile(6, 0.9973) - 20.062).abs() < 1e-2);
        assert!((chi2_cdf(7.814_728, 3) - 0.95).abs() < 1e-7);
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
        // trapezoidal noise, to rounding (relative 1e-12 of the largest entry).
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
    }

    #[test]
    fn inactive_groups_stay_zero() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let p0 = random_spd(&mut rng, 1e-2);
        let active = ActiveStates {
            gyro_scale: false,
            accel_scale: true,
            boresight: false,
            clock: false,
            gyro_misalignment: false,
        };
        let mut noise = crate::navigator::ImuSpec::default().process_noise();
        noise.clock_bias_psd_m2_s = 0.1;
        noise.clock_drift_psd_m2_s3 = 0.01;
        let mut f = ErrorStateEkf::new(p0, noise, active);
        let nav = nav_at_origin();
        f.predict(
            &WGS84,
            &nav,
            &Vector3::new(0.0, 0.0, -9.8),
            &Vector3::new(0.1, 0.0, 0.0),
            0.1,
        );
        let m = star_attitude(
            &nav,
            &UnitQuaternion::from_euler_angles(PI_X, 0.0, 0.0),
            &Matrix3::identity(),
            &Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0),
            &Vector3::zeros(),
            1e-4,
            1e-4,
        );
        let out = update(&f.p, &m, f64::INFINITY);
        for i in (idx::SG..idx::SG + 3)
            .chain(idx::KAPPA..idx::CLK + 2)
            .chain(idx::SGM..NX)
        {
            assert_eq!(out.p.row(i).abs().max(), 0.0, "row {i}");
            assert_eq!(out.dx[i], 0.0);
        }
        assert!(out.p[(idx::SA, idx::SA)] > 0.0);
    }

    const PI_X: f64 = std::f64::consts::PI;

    #[test]
    fn schuler_frequency_from_gradient() {
        // Horizontal eigenvalue of the gradient ≈ −g/r (paper 002: ν² = g/r, T ≈ 84.4 min).
        let g = gravity_gradient(&WGS84, &Vector3::new(0.0, 0.0, 6_356_752.0));
        let nu2 = -g[(0, 0)];
        let period_min = 2.0 * std::f64::consts::PI / nu2.sqrt() / 60.0;
        assert!((period_min - 84.4).abs() < 0.844, "{period_min}");
        assert!(g[(2, 2)] > 0.0, "vertical channel must be unstable");
    }

    #[test]
    fn update_accepts_consistent_and_rejects_outlier() {
        let mut p = Covariance::identity() * 1.0e-4;
        p.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(Matrix3::identity() * 100.0));
        let nav = nav_at_origin();
        let cov = Matrix3::identity() * 4.0;
        let gates = GateTable::new(0.999);
        let good = gnss_position(&nav, &(nav.r_e + Vector3::new(3.0, -2.0, 1.0)), &cov);
        let out = update(&p, &good, gates.threshold(3));
        assert!(!out.residual.rejected);
        assert!((out.dx[0] - 3.0 * 100.0 / 104.0).abs() < 1e-9);
        assert!((out.p[(0, 0)] - 100.0 * 4.0 / 104.0).abs() < 1e-9);
        let bad = gnss_position(&nav, &(nav.r_e + Vector3::new(300.0, 0.0, 0.0)), &cov);
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

    #[test]
    fn star_jacobian_matches_finite_differences() {
        // Truth = estimate + (ψ, δκ): the innovation must equal H·δx to second order.
        // With |ψ|, |δκ| ≤ 3e-4 rad the neglected terms are ≲ |δ|² ≈ 1e-7 rad.
        let mut nav = nav_at_origin();
        nav.q_e_b = UnitQuaternion::from_euler_angles(0.3, -0.4, 1.2);
        let c_s_b_nom = Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0);
        let c_e_i = UnitQuaternion::from_euler_angles(0.1, 0.2, 1.0)
            .to_rotation_matrix()
            .into_inner();
        let kappa_hat = Vector3::new(2e-3, -1e-3, 3e-3);
        for (psi, dk) in [
            (Vector3::new(1e-4, -2e-4, 3e-4), Vector3::zeros()),
            (Vector3::zeros(), Vector3::new(3e-4, 0.0, 0.0)),
            (Vector3::zeros(), Vector3::new(0.0, 3e-4, 0.0)),
            (Vector3::zeros(), Vector3::new(0.0, 0.0, 3e-4)),
            (
                Vector3::new(-2e-4, 1e-4, 0.0),
                Vector3::new(1e-4, -2e-4, 2e-4),
            ),
        ] {
            let c_e_b_true = UnitQuaternion::from_scaled_axis(psi) * nav.q_e_b;
            let c_s_b_true = c_s_b_nom * kappa_matrix(&(kappa_hat + dk));
            let c_s_i_true =
                c_s_b_true * c_e_b_true.to_rotation_matrix().into_inner().transpose() * c_e_i;
            let q = UnitQuaternion::from_matrix(&c_s_i_true);
            let m = star_attitude(&nav, &q, &c_e_i, &c_s_b_nom, &kappa_hat, 1e-5, 1e-4);
            let mut dx = StateVector::zeros();
            dx.fixed_rows_mut::<3>(idx::ATT).copy_from(&psi);
            dx.fixed_rows_mut::<3>(idx::KAPPA).copy_from(&dk);
            let d = m.innovation - m.h * dx;
            assert!(d.norm() < 2e-7, "ψ {psi:?} δκ {dk:?}: {d}");
            assert!(m.innovation.norm() > 1e-4);
        }
        // B itself against central differences of M(κ): Mᵀ ∂M/∂κ_j = [b_j×].
        let h = 1e-6;
        let b = kappa_jacobian(&kappa_hat);
        let m0 = kappa_matrix(&kappa_hat);
        for j in 0..3 {
            let mut kp = kappa_hat;
            let mut km = kappa_hat;
            kp[j] += h;
            km[j] -= h;
            let dm = (kappa_matrix(&kp) - kappa_matrix(&km)) / (2.0 * h);
            let w = m0.transpose() * dm;
            let col = Vector3::new(w[(2, 1)], w[(0, 2)], w[(1, 0)]);
            assert!((col - b.column(j)).norm() < 1e-9, "column {j}");
        }
    }

    #[test]
    fn pseudorange_and_range_rate_jacobians_match_finite_differences() {
        let mut nav = nav_at_origin();
        nav.v_e = Vector3::new(5.0, -12.0, 3.0);
        let r_s = Vector3::new(2.0e7, 1.2e7, 0.9e7);
        let v_s = Vector3::new(-1200.0, 2500.0, 800.0);
        let m0 = gnss_pseudorange(&nav, &r_s, 2.3e7, 100.0, 3.0);
        let d0 = gnss_range_rate(&nav, &r_s, &v_s, -300.0, 1.5, 0.05);
        let mut dx = StateVector::zeros();
        dx.fixed_rows_mut::<3>(idx::POS)
            .copy_from(&Vector3::new(30.0, -20.0, 10.0));
        dx.fixed_rows_mut::<3>(idx::VEL)
            .copy_from(&Vector3::new(0.5, 0.2, -0.3));
        dx[idx::CLK] = 7.0;
        dx[idx::CLK_DRIFT] = 0.3;
        let mut nav2 = nav;
        correct_nav_state(&mut nav2, &dx);
        let m1 = gnss_pseudorange(&nav2, &r_s, 2.3e7, 100.0 + 7.0, 3.0);
        let d1 = gnss_range_rate(&nav2, &r_s, &v_s, -300.0, 1.5 + 0.3, 0.05);
        // Second-order terms: |δr|²/(2ρ) ≈ 2e-5 m for the range; |δr||δv|/ρ ≈ 1e-6 m/s and
        // |δr|²|v|/ρ² ≈ 1e-8 m/s for the rate.
        let e_pr = m0.innovation[0] - m1.innovation[0] - (m0.h * dx)[0];
        let e_rr = d0.innovation[0] - d1.innovation[0] - (d0.h * dx)[0];
        assert!(e_pr.abs() < 1e-4, "{e_pr}");
        assert!(e_rr.abs() < 1e-5, "{e_rr}");
        // The position column of the rate Jacobian is not negligible against its noise.
        assert!((d0.h.fixed_view::<1, 3>(0, idx::POS) * dx.fixed_rows::<3>(0))[0].abs() > 1e-4);
    }

    #[test]
    fn baseline_attitude_residual_is_psi_plus_noise() {
        // Truth = (I + [ψ×])·estimate, measurement = (I + [ε×])·truth: y = ψ + ε to second
        // order (|ψ|·|ε| ≈ 1e-7 rad here).
        let mut nav = nav_at_origin();
        nav.q_e_b = UnitQuaternion::from_euler_angles(0.3, -0.4, 1.2);
        let psi = Vector3::new(2e-4, -1e-4, 3e-4);
        let eps = Vector3::new(-1e-4, 2e-4, 1e-4);
        let truth = UnitQuaternion::from_scaled_axis(psi) * nav.q_e_b;
        let meas = UnitQuaternion::from_scaled_axis(eps) * truth;
        let m = gnss_baseline_attitude(
            &nav,
            &meas.to_rotation_matrix().into_inner(),
            &(Matrix3::identity() * 1e-6),
        );
        let mut dx = StateVector::zeros();
        dx.fixed_rows_mut::<3>(idx::ATT).copy_from(&psi);
        let d = m.innovation - m.h * dx - eps;
        assert!(d.norm() < 2e-7, "{d}");
    }

    #[test]
    fn odometer_jacobian_matches_finite_difference() {
        let mut nav = nav_at_origin();
        nav.v_e = Vector3::new(1.0, 10.0, -2.0);
        nav.q_e_b = UnitQuaternion::from_euler_angles(0.2, 0.1, 1.3);
        let m0 = odometer_nhc(&nav, 0.0, 5.0, 0.1, 0.1);
        let mut dx = StateVector::zeros();
        dx[idx::VEL + 1] = 0.01;
        dx[idx::ATT + 2] = 1e-5;
        let mut nav2 = nav;
        correct_nav_state(&mut nav2, &dx);
        let m1 = odometer_nhc(&nav2, 0.0, 5.0, 0.1, 0.1);
        // Innovation shrinks by H·dx when the estimate moves by dx.
        let d = m0.innovation - m1.innovation - m0.h * dx;
        assert!(d.norm() < 1e-6, "{d}"); // second order: |δv|·|ψ| = 1e-7
    }
}
