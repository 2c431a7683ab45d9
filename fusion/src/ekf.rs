//! Error-state extended Kalman filter in ECEF, closed loop (corrections are fed back into the
//! strapdown state and the bias estimates, after which the error state is zero again).
//!
//! # Error state
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
//! | 15 | [`idx::BARO`] | `δb_h = b_h − b̂_h`, baro height bias (`h_baro = h + b_h`) | m |
//! | 16 | [`idx::ODO`] | `δk = k − k̂`, odometer scale-factor error (`s_odo = (1 + k)·v_x`) | – |
//!
//! The odometer scale factor is a state for the same reason: a 0.2 % scale error at 20 m/s is a
//! constant 0.04 m/s that white noise cannot represent; treated as noise it biases the along-track
//! velocity and the position drifts by metres between GNSS fixes (measured: horizontal RMS 1.1 m
//! with it as noise, 0.2 m with no odometer at all, in the default vehicle scenario).
//!
//! The baro bias is a state rather than extra measurement noise because the simulated (and
//! real) baro error is dominated by a constant bias (30 Pa ≈ 2.5 m) that white noise cannot
//! represent: treating it as noise would make the height covariance dishonest after a few
//! samples. With GNSS it is observable; without GNSS the height stays tied to the baro with
//! the bias σ as its honest uncertainty.
//!
//! New groups (scale factors, star-tracker boresight, receiver clock, odometer scale —
//! DESIGN.md "Filter") are appended after index 16: raise [`NX`], add their indices in
//! [`idx`], their dynamics in [`error_dynamics`] and their noise in [`ProcessNoise`]; existing
//! measurement models only fill the columns they know, so they keep working unchanged.
//!
//! # Dynamics (Groves, *Principles of GNSS, Inertial and Multisensor Integrated Navigation*,
//! 2nd ed., §14.2.3, ECEF; paper 002 eq. 22)
//! With the IMU outputs corrected by the bias estimates (`ω̂ = ω̃ − b̂_g`, `f̂ = f̃ − b̂_a`) and
//! `f̂_e = Ĉ_e_b f̂`:
//! ```text
//! δṙ = δv
//! δv̇ = G·δr − 2[ω_ie×]·δv − [f̂_e×]·ψ − Ĉ_e_b·δb_a − Ĉ_e_b·n_a
//! ψ̇  = −[ω_ie×]·ψ − Ĉ_e_b·δb_g − Ĉ_e_b·n_g
//! δḃ_g = w_g,  δḃ_a = w_a,  δḃ_h = w_h          (random walks)
//! ```
//! `G = ∂g/∂r = GM/r³·(3 u uᵀ − I) − [ω_ie×]²` is the gravity gradient: the `−GM/r³·I` part is
//! paper 002's `−ν²Δr` (Schuler frequency `ν² = g/r`), `3GM/r³ u uᵀ` its `3ν² r (r·Δr)/r²`
//! (unstable vertical channel), the last term the centrifugal gradient.
//!
//! Discretisation per IMU step: `Φ = I + F dt + ½ (F dt)²`,
//! `P⁺ = Φ (P + ½ Q_c dt) Φᵀ + ½ Q_c dt` (trapezoidal `Q_d`), with `Q_c` from the noise
//! densities (ARW, VRW, bias random walks). Because the body→ECEF rotation of isotropic white
//! noise is isotropic, `Q_c` is diagonal.
//!
//! # Update
//! [`update`] is a pure function in the style of nyx `od/kalman`: it returns the correction,
//! the new covariance and a [`Residual`] record (innovation, its covariance `S`, normalized
//! innovation squared `NIS = yᵀ S⁻¹ y`, the chi-square gate for `dim y` at the configured
//! probability and whether the sample was rejected). Joseph form
//! `P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ`, then symmetrised. Everything is fixed-size
//! (`SMatrix`/`SVector`): no allocation.
//!
//! # Measurement models
//! [`gnss_position`], [`gnss_velocity`], [`star_attitude`], [`baro_height`],
//! [`odometer_nhc`] / [`odometer_speed`], [`zero_velocity`]; each returns a [`Measurement`]
//! (innovation, `H`, `R`) evaluated at the inertial state of the sample's time of validity.

use crate::attitude::skew;
use crate::earth::Ellipsoid;
use crate::strapdown::NavState;
use nalgebra::{Cholesky, Matrix3, Rotation3, SMatrix, SVector, UnitQuaternion, Vector3};

/// Number of error states.
pub const NX: usize = 17;

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
}

/// Error-state vector (see the module table for layout and units).
pub type StateVector = SVector<f64, NX>;
/// Error-state covariance.
pub type Covariance = SMatrix<f64, NX, NX>;

/// Largest measurement dimension any model produces (for gate tables).
pub const MAX_MEAS_DIM: usize = 6;

/// Continuous-time noise densities of the IMU error model, SI units.
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
}

impl ProcessNoise {
    /// Diagonal of the continuous process-noise spectral density `Q_c` in error-state layout.
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

/// Continuous error dynamics matrix `F` (module docs) at the estimated position `r_e` (ECEF,
/// m), attitude `c_e_b` (body → ECEF) and bias-corrected specific force `f_b` (body, m/s²).
pub fn error_dynamics(
    ell: &Ellipsoid,
    r_e: &Vector3<f64>,
    c_e_b: &Matrix3<f64>,
    f_b: &Vector3<f64>,
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
    f.fixed_view_mut::<3, 3>(idx::ATT, idx::ATT)
        .copy_from(&(-omega));
    f.fixed_view_mut::<3, 3>(idx::ATT, idx::BG)
        .copy_from(&(-c_e_b));
    f
}

/// State transition `Φ = I + F dt + ½ (F dt)²` over `dt_s`.
///
/// The square is formed block-wise: only the 7 non-zero 3×3 blocks of `F` contribute, so this
/// costs a handful of 3×3 products instead of a dense 15×15 one.
pub fn transition(f: &Covariance, dt_s: f64) -> Covariance {
    // Non-zero blocks of F (row group, column group); all other blocks are zero.
    const BLOCKS: [(usize, usize); 7] = [
        (idx::POS, idx::VEL),
        (idx::VEL, idx::POS),
        (idx::VEL, idx::VEL),
        (idx::VEL, idx::ATT),
        (idx::VEL, idx::BA),
        (idx::ATT, idx::ATT),
        (idx::ATT, idx::BG),
    ];
    let mut phi = Covariance::identity() + f * dt_s;
    let half_dt2 = 0.5 * dt_s * dt_s;
    for &(i, k) in &BLOCKS {
        let a: Matrix3<f64> = f.fixed_view::<3, 3>(i, k).into_owned();
        for &(k2, j) in &BLOCKS {
            if k2 == k {
                let b: Matrix3<f64> = f.fixed_view::<3, 3>(k, j).into_owned();
                let mut v = phi.fixed_view_mut::<3, 3>(i, j);
                v += a * b * half_dt2;
            }
        }
    }
    phi
}

/// The filter's own state: error covariance and the bias estimates it feeds back.
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorStateEkf {
    /// Error-state covariance (layout in the module docs).
    pub p: Covariance,
    /// Estimated gyro bias, body, rad/s (subtracted from the IMU before mechanization).
    pub gyro_bias_rad_s: Vector3<f64>,
    /// Estimated accelerometer bias, body, m/s².
    pub accel_bias_m_s2: Vector3<f64>,
    /// Estimated baro height bias, m (`h_baro = h + b_h`).
    pub baro_bias_m: f64,
    /// Estimated odometer scale-factor error `k` (`s_odo = (1 + k)·v_x`).
    pub odo_scale: f64,
    /// Process noise densities.
    pub noise: ProcessNoise,
    qc: StateVector,
}

impl ErrorStateEkf {
    /// A filter with initial covariance `p0`, zero bias estimates and the given noise.
    pub fn new(p0: Covariance, noise: ProcessNoise) -> Self {
        Self {
            p: p0,
            gyro_bias_rad_s: Vector3::zeros(),
            accel_bias_m_s2: Vector3::zeros(),
            baro_bias_m: 0.0,
            odo_scale: 0.0,
            qc: noise.qc_diagonal(),
            noise,
        }
    }

    /// Propagate the covariance over one IMU step of `dt_s` at the (already propagated)
    /// state `nav`, with bias-corrected specific force `f_b` (body, m/s²). Allocates nothing.
    pub fn predict(&mut self, ell: &Ellipsoid, nav: &NavState, f_b: &Vector3<f64>, dt_s: f64) {
        let c_e_b = nav.q_e_b.to_rotation_matrix().into_inner();
        let f = error_dynamics(ell, &nav.r_e, &c_e_b, f_b);
        let phi = transition(&f, dt_s);
        let mut p = self.p;
        for i in 0..NX {
            p[(i, i)] += 0.5 * self.qc[i] * dt_s;
        }
        let mut p = phi * p * phi.transpose();
        for i in 0..NX {
            p[(i, i)] += 0.5 * self.qc[i] * dt_s;
        }
        self.p = symmetrize(&p);
    }

    /// Apply an accepted correction `dx` to the navigation state and the bias estimates (closed
    /// loop); the error state is zero afterwards. The covariance reset Jacobian
    /// `I − ½[ψ×]` is ≈ I for the small ψ of a running filter and is not applied.
    pub fn apply_correction(&mut self, nav: &mut NavState, dx: &StateVector) {
        correct_nav_state(nav, dx);
        self.gyro_bias_rad_s += dx.fixed_rows::<3>(idx::BG);
        self.accel_bias_m_s2 += dx.fixed_rows::<3>(idx::BA);
        self.baro_bias_m += dx[idx::BARO];
        self.odo_scale += dx[idx::ODO];
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
    /// True when the sample was not fused (NIS above the gate, or `S` not positive definite).
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
/// `gate` (NIS threshold; `f64::INFINITY` disables the gate). Pure; allocates nothing.
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
    let ikh = Covariance::identity() - k * m.h;
    let p_new = ikh * p * ikh.transpose() + k * m.r * k.transpose();
    UpdateOutcome {
        dx,
        p: symmetrize(&p_new),
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

/// Star-tracker attitude.
///
/// Measured `C̃_s_i` (ICRF → sensor, from `q_s_i_meas`), predicted
/// `Ĉ_s_i = C_s_b · Ĉ_b_e · C_e_i(t)` with `c_e_i` = GCRS → ITRS at the exposure time and
/// `c_s_b` the nominal mount (HELPERS.md). With `C_e_b = (I + [ψ×])Ĉ_e_b` and sensor-frame
/// noise ν (`C̃_s_i = (I − [ν×]) C_s_i`), the residual rotation vector
/// `y = rotvec(Ĉ_s_i C̃_s_iᵀ) = C_s_b Ĉ_b_e ψ + ν` (sensor axes, rad), so
/// `H_ψ = C_s_b Ĉ_b_e`, `R = diag(σ_cross², σ_cross², σ_roll²)` (optical axis = sensor z).
pub fn star_attitude(
    nav: &NavState,
    q_s_i_meas: &UnitQuaternion<f64>,
    c_e_i: &Matrix3<f64>,
    c_s_b: &Matrix3<f64>,
    sigma_cross_rad: f64,
    sigma_roll_rad: f64,
) -> Measurement<3> {
    let c_b_e = nav.q_e_b.to_rotation_matrix().into_inner().transpose();
    let c_s_e = c_s_b * c_b_e;
    let c_s_i_pred = c_s_e * c_e_i;
    let c_s_i_meas = q_s_i_meas.to_rotation_matrix().into_inner();
    let e = c_s_i_pred * c_s_i_meas.transpose();
    let y =
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(e)).scaled_axis();
    let mut h = SMatrix::<f64, 3, NX>::zeros();
    h.fixed_view_mut::<3, 3>(0, idx::ATT).copy_from(&c_s_e);
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

    fn nav_at_origin() -> NavState {
        NavState {
            r_e: Vector3::new(WGS84.a_m, 0.0, 0.0),
            v_e: Vector3::zeros(),
            q_e_b: UnitQuaternion::identity(),
        }
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
    fn transition_matches_dense_second_order_expansion() {
        let r = Vector3::new(4.0e6, 3.0e6, 3.5e6);
        let c = UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3)
            .to_rotation_matrix()
            .into_inner();
        let f = error_dynamics(&WGS84, &r, &c, &Vector3::new(0.3, -0.2, -9.8));
        let dt = 0.01;
        let fd = f * dt;
        let dense = Covariance::identity() + fd + fd * fd * 0.5;
        assert!((transition(&f, dt) - dense).abs().max() < 1e-15);
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
    }

    #[test]
    fn star_residual_recovers_small_rotation() {
        let nav = nav_at_origin();
        let c_s_b = Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0);
        let c_e_i = UnitQuaternion::from_euler_angles(0.0, 0.0, 1.0)
            .to_rotation_matrix()
            .into_inner();
        // Truth differs from the estimate by psi (ECEF): C_e_b = (I + [psi×]) Ĉ_e_b.
        let psi = Vector3::new(1e-4, -2e-4, 3e-4);
        let c_e_b_true = UnitQuaternion::from_scaled_axis(psi)
            .to_rotation_matrix()
            .into_inner();
        let c_s_i_true = c_s_b * c_e_b_true.transpose() * c_e_i;
        let q = UnitQuaternion::from_matrix(&c_s_i_true);
        let m = star_attitude(&nav, &q, &c_e_i, &c_s_b, 1e-5, 1e-4);
        let predicted = m.h.fixed_view::<3, 3>(0, idx::ATT) * psi;
        assert!((m.innovation - predicted).norm() < 1e-9, "{m:?}");
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
