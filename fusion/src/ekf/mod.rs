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
//! # Where things are
//! - this module: the state layout ([`idx`], [`NX`]), the switchable groups
//!   ([`ActiveStates`]) and the filter's own state ([`ErrorStateEkf`]: covariance, sensor-error
//!   estimates, closed-loop feedback);
//! - [`dynamics`]: error dynamics `F`, process noise, the transition accumulator and the
//!   covariance propagation (Groves §14.2, paper 002 eq. 22);
//! - [`update`](mod@update): the Joseph-form update as a pure function returning a
//!   [`Residual`] record, and covariance augmentation;
//! - [`measurements`]: the measurement models (innovation, Jacobian `H`, noise `R`);
//! - [`chi2`]: chi-square distribution and the gate thresholds;
//! - [`correlated`]: the variance inflation that fuses a time-correlated (Gauss–Markov)
//!   measurement error as white noise without over-confidence (GNSS).
//!
//! Every item of the submodules is re-exported here, so `crate::ekf::update`,
//! `crate::ekf::star_attitude`, … name the same items as before the split.

pub mod chi2;
pub mod correlated;
pub mod dynamics;
pub mod measurements;
pub mod update;

pub use chi2::{GateTable, chi2_cdf, chi2_quantile};
pub use dynamics::{
    GravityDisturbance, MISALIGNMENT_COHERENCE_RAD, ProcessNoise, TransitionAccumulator,
    error_dynamics, gravity_gradient, nonorthogonality_jacobian, nonorthogonality_matrix,
};
pub use measurements::{
    GnssAntenna, WheelContact, baro_height, gnss_baseline_attitude, gnss_position,
    gnss_pseudorange, gnss_range_rate, gnss_velocity, kappa_jacobian, kappa_matrix,
    nhc_linearisation_covariance, odometer_nhc, odometer_speed, star_attitude, zero_velocity,
};
pub use update::{
    Measurement, Residual, UpdateOutcome, augment_covariance, h_p_ht, symmetrize, update,
    update_in_place,
};

use crate::strapdown::NavState;
use nalgebra::{SMatrix, SVector, UnitQuaternion, Vector3};

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

/// The filter's own state: error covariance, the sensor-error estimates it feeds back, and
/// the transition accumulated since the last covariance propagation.
#[derive(Debug, Clone, Copy, PartialEq)]
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

    /// Set the estimates of the hardware errors (gyro and accelerometer biases and scale
    /// factors, odometer scale, boresight, gyro non-orthogonality) to the values of `x`
    /// (error-state layout); the baro bias and the clock are left as they are.
    pub fn apply_sensor_estimates(&mut self, x: &StateVector) {
        self.gyro_bias_rad_s = x.fixed_rows::<3>(idx::BG).into_owned();
        self.accel_bias_m_s2 = x.fixed_rows::<3>(idx::BA).into_owned();
        self.odo_scale = x[idx::ODO];
        self.gyro_scale = x.fixed_rows::<3>(idx::SG).into_owned();
        self.accel_scale = x.fixed_rows::<3>(idx::SA).into_owned();
        self.kappa_rad = x.fixed_rows::<3>(idx::KAPPA).into_owned();
        self.gyro_misalignment_rad = x.fixed_rows::<3>(idx::SGM).into_owned();
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

#[cfg(test)]
mod test_support {
    use super::*;
    use crate::earth::WGS84;
    use rand::Rng;
    use rand_chacha::ChaCha8Rng;

    pub fn nav_at_origin() -> NavState {
        NavState {
            r_e: Vector3::new(WGS84.a_m, 0.0, 0.0),
            v_e: Vector3::zeros(),
            q_e_b: UnitQuaternion::identity(),
        }
    }

    pub fn random_spd(rng: &mut ChaCha8Rng, scale: f64) -> Covariance {
        let a = Covariance::from_fn(|_, _| rng.random_range(-1.0..1.0));
        a * a.transpose() * scale + Covariance::identity() * 1e-6
    }
}

#[cfg(test)]
mod tests {
    use super::test_support::{nav_at_origin, random_spd};
    use super::*;
    use crate::earth::WGS84;
    use nalgebra::Matrix3;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

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
            &crate::frames::Rotation::from_dcm_unchecked(Matrix3::identity()),
            &crate::frames::Rotation::from_dcm_unchecked(Matrix3::new(
                1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0,
            )),
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
}
