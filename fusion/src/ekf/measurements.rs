//! Measurement models of the [`ErrorStateEkf`](super::ErrorStateEkf).
//!
//! [`gnss_position`], [`gnss_velocity`] (loose), [`gnss_pseudorange`], [`gnss_range_rate`]
//! (tight, one satellite each, paper 003), [`star_attitude`] (with boresight κ),
//! [`gnss_baseline_attitude`] (dual-baseline GNSS attitude, paper 003),
//! [`baro_height`], [`odometer_nhc`] / [`odometer_speed`] (at the wheel, [`WheelContact`]),
//! [`zero_velocity`]; each returns a
//! [`Measurement`] (innovation, `H`, `R`) evaluated at the inertial state of the sample's time
//! of validity.

use super::{Measurement, NX, idx};
use crate::attitude::skew;
use crate::earth::Ellipsoid;
use crate::frames::{Body, Ecef, Icrf, Rotation, StarSensor};
use crate::strapdown::NavState;
use nalgebra::{Matrix3, Rotation3, SMatrix, SVector, UnitQuaternion, Vector3};

/// Where the GNSS antenna is and how the body turns at the measurement: the lever arm from
/// the IMU to the antenna phase centre in body axes (m, configured: `gnss.lever_arm_b_m`)
/// and the body's inertial angular rate (rad/s, body axes; the last bias-corrected gyro
/// rate) for the velocity term.
///
/// The antenna is at `r_a = r + C_e_b l` and moves with
/// `v_a = v + C_e_b (ω_ib × l) − ω_ie × (C_e_b l)` (Groves 2013, eq. 14.104–14.105 with
/// `ω_eb = ω_ib − C_b_e ω_ie`). With `C_e_b = (I + [ψ×]) Ĉ_e_b` (module [`super`]) and
/// `l_e = Ĉ_e_b l`, `a_e = Ĉ_e_b (ω_ib × l)`:
/// `δr_a = δr − [l_e×] ψ` and `δv_a = δv − [a_e×] ψ + [ω_ie×][l_e×] ψ`. The gyro-bias term
/// of `δv_a` (`Ĉ_e_b [l×] δb_g`, ≈ 10⁻⁷ m/s for a navigation-grade bias and 1.5 m) is left
/// out.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GnssAntenna {
    /// Lever arm IMU → antenna phase centre, body axes, m.
    pub lever_arm_b_m: Vector3<f64>,
    /// Inertial angular rate of the body, body axes, rad/s.
    pub w_ib_b_rad_s: Vector3<f64>,
}

impl GnssAntenna {
    /// An antenna at the IMU (no lever arm).
    pub const AT_IMU: Self = Self {
        lever_arm_b_m: Vector3::new(0.0, 0.0, 0.0),
        w_ib_b_rad_s: Vector3::new(0.0, 0.0, 0.0),
    };

    /// Predicted antenna position and velocity (ECEF, m and m/s) and the attitude Jacobians
    /// `∂δr_a/∂ψ`, `∂δv_a/∂ψ` at the inertial state `nav`.
    pub fn predict(
        &self,
        nav: &NavState,
    ) -> (Vector3<f64>, Vector3<f64>, Matrix3<f64>, Matrix3<f64>) {
        let c_e_b = nav.q_e_b.to_rotation_matrix().into_inner();
        let l_e = c_e_b * self.lever_arm_b_m;
        let a_e = c_e_b * self.w_ib_b_rad_s.cross(&self.lever_arm_b_m);
        let w_ie = crate::earth::WGS84.omega_ie_e();
        let r_a = nav.r_e + l_e;
        let v_a = nav.v_e + a_e - w_ie.cross(&l_e);
        let h_r_psi = -skew(&l_e);
        let h_v_psi = -skew(&a_e) + skew(&w_ie) * skew(&l_e);
        (r_a, v_a, h_r_psi, h_v_psi)
    }
}

/// GNSS position of the antenna: `z = r_a` (ECEF, m) with covariance `cov` (ECEF, m²);
/// `nav` is the inertial state at the fix's time of validity; `H_r = I`, `H_ψ = −[l_e×]`
/// ([`GnssAntenna`]).
pub fn gnss_position(
    nav: &NavState,
    antenna: &GnssAntenna,
    pos_e: &Vector3<f64>,
    cov: &Matrix3<f64>,
) -> Measurement<3> {
    let (r_a, _, h_psi, _) = antenna.predict(nav);
    let mut h = SMatrix::<f64, 3, NX>::zeros();
    h.fixed_view_mut::<3, 3>(0, idx::POS)
        .copy_from(&Matrix3::identity());
    h.fixed_view_mut::<3, 3>(0, idx::ATT).copy_from(&h_psi);
    Measurement {
        innovation: pos_e - r_a,
        h,
        r: *cov,
    }
}

/// GNSS velocity of the antenna: `z = v_a` (ECEF, Earth-relative, m/s) with covariance
/// `cov` ((m/s)²); `H_v = I`, `H_ψ` of [`GnssAntenna`].
pub fn gnss_velocity(
    nav: &NavState,
    antenna: &GnssAntenna,
    vel_e: &Vector3<f64>,
    cov: &Matrix3<f64>,
) -> Measurement<3> {
    let (_, v_a, _, h_psi) = antenna.predict(nav);
    let mut h = SMatrix::<f64, 3, NX>::zeros();
    h.fixed_view_mut::<3, 3>(0, idx::VEL)
        .copy_from(&Matrix3::identity());
    h.fixed_view_mut::<3, 3>(0, idx::ATT).copy_from(&h_psi);
    Measurement {
        innovation: vel_e - v_a,
        h,
        r: *cov,
    }
}

/// One satellite's pseudorange (tight coupling, paper 003 eq. 12 linearised at the inertial
/// solution) at the antenna ([`GnssAntenna`]). The satellite position `sat_pos_e` is the one
/// at transmission rotated into the ECEF frame of reception (Sagnac included, as the receiver
/// and `drivers-sim/src/gnss.rs` give it), so `ρ̂ = |r_s − r̂_a| + b̂_clk`,
/// `H_r = −uᵀ` (u = unit line of sight antenna → satellite), `H_ψ = −uᵀ ∂δr_a/∂ψ`,
/// `H_clk = 1`; noise `sigma_m`.
pub fn gnss_pseudorange(
    nav: &NavState,
    antenna: &GnssAntenna,
    sat_pos_e: &Vector3<f64>,
    pseudorange_m: f64,
    clock_bias_m: f64,
    sigma_m: f64,
) -> Measurement<1> {
    let (r_a, _, h_r_psi, _) = antenna.predict(nav);
    let d = sat_pos_e - r_a;
    let range = d.norm();
    let u = d / range;
    let mut h = SMatrix::<f64, 1, NX>::zeros();
    h.fixed_view_mut::<1, 3>(0, idx::POS)
        .copy_from(&(-u.transpose()));
    h.fixed_view_mut::<1, 3>(0, idx::ATT)
        .copy_from(&(-u.transpose() * h_r_psi));
    h[(0, idx::CLK)] = 1.0;
    Measurement {
        innovation: SVector::<f64, 1>::new(pseudorange_m - range - clock_bias_m),
        h,
        r: SMatrix::<f64, 1, 1>::new(sigma_m * sigma_m),
    }
}

/// One satellite's Doppler range rate (tight coupling) at the antenna: `ρ̇̂ = (v_s − v̂_a)·u
/// + d̂_clk` with `u = (r_s − r̂_a)/|r_s − r̂_a|` (the simulator's definition). `H_v = −uᵀ`,
/// `H_d = 1`, and through the line of sight `H_r = −(v_s − v̂_a)ᵀ (I − u uᵀ)/ρ`
/// (`∂u/∂r̂ = −(I − u uᵀ)/ρ`, ~10⁻⁴ per m: small but kept exact); the attitude enters through
/// both the antenna velocity and position: `H_ψ = −uᵀ ∂δv_a/∂ψ + H_r ∂δr_a/∂ψ`; noise
/// `sigma_m_s`.
pub fn gnss_range_rate(
    nav: &NavState,
    antenna: &GnssAntenna,
    sat_pos_e: &Vector3<f64>,
    sat_vel_e: &Vector3<f64>,
    range_rate_m_s: f64,
    clock_drift_m_s: f64,
    sigma_m_s: f64,
) -> Measurement<1> {
    let (r_a, v_a, h_r_psi, h_v_psi) = antenna.predict(nav);
    let d = sat_pos_e - r_a;
    let range = d.norm();
    let u = d / range;
    let dv = sat_vel_e - v_a;
    let mut h = SMatrix::<f64, 1, NX>::zeros();
    let h_r = -(dv.transpose() * (Matrix3::identity() - u * u.transpose())) / range;
    h.fixed_view_mut::<1, 3>(0, idx::POS).copy_from(&h_r);
    h.fixed_view_mut::<1, 3>(0, idx::VEL)
        .copy_from(&(-u.transpose()));
    h.fixed_view_mut::<1, 3>(0, idx::ATT)
        .copy_from(&(-u.transpose() * h_v_psi + h_r * h_r_psi));
    h[(0, idx::CLK_DRIFT)] = 1.0;
    Measurement {
        innovation: SVector::<f64, 1>::new(range_rate_m_s - dv.dot(&u) - clock_drift_m_s),
        h,
        r: SMatrix::<f64, 1, 1>::new(sigma_m_s * sigma_m_s),
    }
}

/// Zero-velocity update: `z = 0` for the ECEF velocity, isotropic noise `sigma_m_s`.
pub fn zero_velocity(nav: &NavState, sigma_m_s: f64) -> Measurement<3> {
    let mut m = gnss_velocity(
        nav,
        &GnssAntenna::AT_IMU,
        &Vector3::zeros(),
        &(Matrix3::identity() * sigma_m_s * sigma_m_s),
    );
    m.innovation = -nav.v_e;
    m
}

/// Paper 000 boresight misalignment `M(κ) = R_z(κ1)·R_x(κ2)·R_y(κ3)` (κ in rad); the true
/// mount is `C_s_b = C_s_b,nominal · M(κ)` (the simulator's `kappa_matrix`, `drivers-sim`).
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
/// time (ICRF → ITRS → body → sensor) and `c_s_b_nominal` the nominal body → sensor mounting;
/// both are frame-typed ([`crate::frames`]), so the chain cannot be assembled in a wrong order
/// (the misalignment `M(κ)` turns the body axes onto themselves). With
/// `C_b_e = Ĉ_b_e (I − [ψ×])`, `M(κ) = M(κ̂)(I + [B δκ×])` ([`kappa_jacobian`]) and
/// sensor-frame noise ν (`C̃_s_i = (I − [ν×]) C_s_i`), the residual rotation vector
/// `y = rotvec(Ĉ_s_i C̃_s_iᵀ) = Ĉ_s_b Ĉ_b_e ψ − Ĉ_s_b B δκ + ν` (sensor axes, rad), so
/// `H_ψ = Ĉ_s_e`, `H_κ = −Ĉ_s_b B`, `R = diag(σ_cross², σ_cross², σ_roll²)` (optical axis =
/// sensor z). Only a heading change separates κ from ψ: a rotation of the mount and one of
/// the vehicle look the same until the body turns relative to the Earth (or the Earth turns
/// relative to the stars, which `C_e_i(t)` carries).
pub fn star_attitude(
    nav: &NavState,
    q_s_i_meas: &UnitQuaternion<f64>,
    c_e_i: &Rotation<Icrf, Ecef>,
    c_s_b_nominal: &Rotation<Body, StarSensor>,
    kappa_rad: &Vector3<f64>,
    sigma_cross_rad: f64,
    sigma_roll_rad: f64,
) -> Measurement<3> {
    let c_b_e = Rotation::<Body, Ecef>::from_quaternion(&nav.q_e_b).inverse();
    let c_s_b =
        c_s_b_nominal * &Rotation::<Body, Body>::from_dcm_unchecked(kappa_matrix(kappa_rad));
    let c_s_e = c_s_b * c_b_e;
    let c_s_i_pred = &c_s_e * c_e_i;
    let c_s_i_meas = Rotation::<Icrf, StarSensor>::from_quaternion(q_s_i_meas);
    let y = (c_s_i_pred * c_s_i_meas.inverse())
        .to_quaternion()
        .scaled_axis();
    let mut h = SMatrix::<f64, 3, NX>::zeros();
    h.fixed_view_mut::<3, 3>(0, idx::ATT).copy_from(c_s_e.dcm());
    h.fixed_view_mut::<3, 3>(0, idx::KAPPA)
        .copy_from(&(-c_s_b.dcm() * kappa_jacobian(kappa_rad)));
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

/// Baro altitude taken as height above the WGS-84 ellipsoid (no geoid, as simulated):
/// `z = h_baro` (m), predicted `ĥ + b̂_h` (geodetic height of `r̂_e` plus the estimated baro
/// bias `baro_bias_m`); `H_r = u_upᵀ` (ECEF unit up vector at the estimated
/// latitude/longitude), `H_b = 1`; white noise `sigma_m`.
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

/// Where the odometer wheel touches the road and how the body turns: the lever arm from the
/// IMU to the wheel's contact point in body axes (m, configured: `vehicle.wheel_lever_arm_b_m`)
/// and the body's inertial angular rate (rad/s, body axes; the last bias-corrected gyro rate).
///
/// The odometer reads the forward speed of the contact point, and a car's non-holonomic
/// constraint (no lateral, no vertical velocity) holds at its rear axle, not at the IMU: in a
/// turn the IMU ahead of the rear axle moves sideways by `−ψ̇·l_x`, and a wheel beside it rolls
/// faster or slower by `−ψ̇·l_y`. The contact point, rigidly attached to the body, moves with
/// `v_c^b = C_b_e v_e + ω_eb^b × l` (`ω_eb^b = ω_ib^b − C_b_e ω_ie^e`). With
/// `C_b_e = Ĉ_b_e (I − [ψ×])` (module [`super`]):
/// `δv_c^b = Ĉ_b_e δv + Ĉ_b_e [v̂×] ψ + [l×] Ĉ_b_e [ω_ie×] ψ`. The gyro-bias term
/// (`[l×] δb_g`, 10⁻⁸ m/s for a navigation-grade bias and 2 m) is left out. The body's
/// suspension pitch and roll are rotations the contact point does *not* share; their rates
/// times the lever arm are part of the constraint's noise (`config/filter.toml` `[vehicle]`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct WheelContact {
    /// Lever arm IMU → odometer wheel contact point, body axes, m.
    pub lever_arm_b_m: Vector3<f64>,
    /// Inertial angular rate of the body, body axes, rad/s.
    pub w_ib_b_rad_s: Vector3<f64>,
}

impl WheelContact {
    /// A wheel at the IMU (no lever arm).
    pub const AT_IMU: Self = Self {
        lever_arm_b_m: Vector3::new(0.0, 0.0, 0.0),
        w_ib_b_rad_s: Vector3::new(0.0, 0.0, 0.0),
    };

    /// Velocity of the contact point relative to the Earth in body axes (m/s) and its
    /// Jacobians `∂δv_c^b/∂δv`, `∂δv_c^b/∂ψ` at the inertial state `nav`.
    pub fn body_velocity(&self, nav: &NavState) -> (Vector3<f64>, Matrix3<f64>, Matrix3<f64>) {
        let (v_b, h_v, h_psi) = body_velocity_jacobians(nav);
        let w_ie = crate::earth::WGS84.omega_ie_e();
        let l = self.lever_arm_b_m;
        let w_eb_b = self.w_ib_b_rad_s - h_v * w_ie;
        let v_c = v_b + w_eb_b.cross(&l);
        let h_psi_c = h_psi + skew(&l) * h_v * skew(&w_ie);
        (v_c, h_v, h_psi_c)
    }
}

/// Odometer speed along body x plus non-holonomic constraints (zero lateral and vertical body
/// velocity) for a ground vehicle, both at the odometer wheel's contact point `wheel`:
/// `z = [speed, 0, 0]` (body, m/s), noise `diag(σ_odo², σ_nhc², σ_nhc²)`. The odometer reads
/// `(1 + k)·v_c,x`, `k` the scale-factor state with estimate `odo_scale`.
pub fn odometer_nhc(
    nav: &NavState,
    wheel: &WheelContact,
    odo_scale: f64,
    speed_m_s: f64,
    sigma_speed_m_s: f64,
    sigma_nhc_m_s: f64,
) -> Measurement<3> {
    let (v_c, h_v, h_psi) = wheel.body_velocity(nav);
    let mut h = SMatrix::<f64, 3, NX>::zeros();
    h.fixed_view_mut::<3, 3>(0, idx::VEL).copy_from(&h_v);
    h.fixed_view_mut::<3, 3>(0, idx::ATT).copy_from(&h_psi);
    let scale = 1.0 + odo_scale;
    for j in 0..NX {
        h[(0, j)] *= scale;
    }
    h[(0, idx::ODO)] = v_c.x;
    Measurement {
        innovation: Vector3::new(speed_m_s - scale * v_c.x, -v_c.y, -v_c.z),
        h,
        r: Matrix3::from_diagonal(&Vector3::new(
            sigma_speed_m_s.powi(2),
            sigma_nhc_m_s.powi(2),
            sigma_nhc_m_s.powi(2),
        )),
    }
}

/// Covariance (m²/s², lateral and vertical body axes) of the second-order terms that the
/// non-holonomic constraints' linear model leaves out, for an error state with velocity and
/// attitude covariance `p_vel_att` (`[δv; ψ]`, e-frame, m/s and rad).
///
/// With `C_b_e = Ĉ_b_e exp(−[ψ×])` the body velocity is, to second order,
/// `v_b = Ĉ_b_e (v̂ + δv) + Ĉ_b_e [v̂×] ψ − Ĉ_b_e [ψ×] δv + ½ Ĉ_b_e [ψ×]² v̂`; for body axis
/// `k` with e-frame direction `a = Ĉ_e_b e_k` the neglected part is `½ xᵀ Hₖ x` over
/// `x = [δv; ψ]` with the Hessian `Hₖ = [[0, B], [Bᵀ, A]]`, `B = −[a×]` and
/// `A = ½(a v̂ᵀ + v̂ aᵀ) − (aᵀv̂) I`. For Gaussian `x` its covariance is
/// `Sₖₗ = ½ tr(Hₖ P Hₗ P)` — the term a second-order EKF adds to the innovation covariance
/// (Gelb, *Applied Optimal Estimation*, 1974, § 6.1). An exact constraint (σ of 10⁻⁵ m/s)
/// fused with the linear model alone while the heading is still uncertain by a degree and the
/// velocity by centimetres per second (a start in motion) pins the wrong combination of
/// states: the bilinear term `ψ × δv` is then 10⁻³ m/s, a hundred times the constraint's σ.
/// Once the filter has converged the term is about `σψ·σv` (2″ × 3 mm/s ≈ 3·10⁻⁸ m/s), far
/// below the constraint's σ.
pub fn nhc_linearisation_covariance(
    nav: &NavState,
    p_vel_att: &SMatrix<f64, 6, 6>,
) -> nalgebra::Matrix2<f64> {
    let c_e_b = nav.q_e_b.to_rotation_matrix().into_inner();
    let hessian = |k: usize| {
        let a: Vector3<f64> = c_e_b.column(k).into_owned();
        let b = -skew(&a);
        let v = nav.v_e;
        let quad = 0.5 * (a * v.transpose() + v * a.transpose()) - Matrix3::identity() * a.dot(&v);
        let mut h = SMatrix::<f64, 6, 6>::zeros();
        h.fixed_view_mut::<3, 3>(0, 3).copy_from(&b);
        h.fixed_view_mut::<3, 3>(3, 0).copy_from(&b.transpose());
        h.fixed_view_mut::<3, 3>(3, 3).copy_from(&quad);
        h * p_vel_att
    };
    let hp = [hessian(1), hessian(2)];
    nalgebra::Matrix2::from_fn(|i, j| 0.5 * (hp[i] * hp[j]).trace())
}

/// Odometer speed along body x alone (non-holonomic constraints switched off), at the wheel's
/// contact point ([`WheelContact`]).
pub fn odometer_speed(
    nav: &NavState,
    wheel: &WheelContact,
    odo_scale: f64,
    speed_m_s: f64,
    sigma_speed_m_s: f64,
) -> Measurement<1> {
    let (v_c, h_v, h_psi) = wheel.body_velocity(nav);
    let scale = 1.0 + odo_scale;
    let mut h = SMatrix::<f64, 1, NX>::zeros();
    h.fixed_view_mut::<1, 3>(0, idx::VEL)
        .copy_from(&(h_v.fixed_rows::<1>(0) * scale));
    h.fixed_view_mut::<1, 3>(0, idx::ATT)
        .copy_from(&(h_psi.fixed_rows::<1>(0) * scale));
    h[(0, idx::ODO)] = v_c.x;
    Measurement {
        innovation: SVector::<f64, 1>::new(speed_m_s - scale * v_c.x),
        h,
        r: SMatrix::<f64, 1, 1>::new(sigma_speed_m_s.powi(2)),
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::nav_at_origin;
    use super::super::{StateVector, correct_nav_state};
    use super::*;

    #[test]
    fn nhc_linearisation_covariance_matches_monte_carlo() {
        // The exact body velocity minus its linear model, over errors drawn from P: its sample
        // covariance must equal the second-order formula. Third-order terms (|ψ|³|v|/6 ≈ 2e-6
        // m/s here) are 1 % of the second-order ones (|ψ||δv| ≈ 4e-4 m/s) in σ, 0.01 % in
        // variance; the bound is 5 standard errors of a sample variance, from the samples'
        // own fourth moment.
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut nav = nav_at_origin();
        nav.q_e_b = UnitQuaternion::from_euler_angles(0.2, -0.3, 2.1);
        nav.v_e = nav.q_e_b * Vector3::new(12.0, 0.0, 0.0);
        // σ 3–5 cm/s in velocity, 0.3–1.2° in attitude, with a velocity–heading correlation.
        let l = SMatrix::<f64, 6, 6>::from_fn(|i, j| match (i, j) {
            (i, j) if i == j && i < 3 => 0.03 + 0.01 * i as f64,
            (i, j) if i == j => [0.005, 0.008, 0.02][i - 3],
            (5, 1) => 0.01,
            (4, 0) => 0.002,
            _ => 0.0,
        });
        let p = l * l.transpose();
        let s = nhc_linearisation_covariance(&nav, &p);
        let (_, h_v, h_psi) = body_velocity_jacobians(&nav);
        let c_b_e = nav.q_e_b.to_rotation_matrix().into_inner().transpose();
        let n = 40_000;
        let mut r = Vec::with_capacity(n);
        for _ in 0..n {
            let z = SVector::<f64, 6>::from_fn(|_, _| StandardNormal.sample(&mut rng));
            let x = l * z;
            let (dv, psi) = (
                x.fixed_rows::<3>(0).into_owned(),
                x.fixed_rows::<3>(3).into_owned(),
            );
            let c_true = c_b_e * Rotation3::new(-psi).into_inner();
            let exact = c_true * (nav.v_e + dv);
            let linear = c_b_e * nav.v_e + h_v * dv + h_psi * psi;
            r.push((exact - linear).fixed_rows::<2>(1).into_owned());
        }
        let mean = r.iter().sum::<nalgebra::Vector2<f64>>() / n as f64;
        for k in 0..2 {
            let d: Vec<f64> = r.iter().map(|v| v[k] - mean[k]).collect();
            let var = d.iter().map(|x| x * x).sum::<f64>() / n as f64;
            let m4 = d.iter().map(|x| x.powi(4)).sum::<f64>() / n as f64;
            let se = ((m4 - var * var) / n as f64).sqrt();
            assert!(
                (var - s[(k, k)]).abs() < 5.0 * se,
                "axis {k}: sample variance {var:.3e} vs formula {:.3e} (se {se:.1e})",
                s[(k, k)]
            );
            assert!(
                s[(k, k)].sqrt() > 1e-4,
                "the test's errors must make the term large"
            );
        }
        let cov = r
            .iter()
            .map(|v| (v[0] - mean[0]) * (v[1] - mean[1]))
            .sum::<f64>()
            / n as f64;
        let se = (s[(0, 0)] * s[(1, 1)] / n as f64).sqrt();
        assert!(
            (cov - s[(0, 1)]).abs() < 5.0 * se,
            "cross term {cov:.3e} vs {:.3e}",
            s[(0, 1)]
        );
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
        let (c_s_b_nom_t, c_e_i_t) = (
            Rotation::from_dcm_unchecked(c_s_b_nom),
            Rotation::from_dcm_unchecked(c_e_i),
        );
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
            let m = star_attitude(&nav, &q, &c_e_i_t, &c_s_b_nom_t, &kappa_hat, 1e-5, 1e-4);
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
        let at_imu = GnssAntenna::AT_IMU;
        let m0 = gnss_pseudorange(&nav, &at_imu, &r_s, 2.3e7, 100.0, 3.0);
        let d0 = gnss_range_rate(&nav, &at_imu, &r_s, &v_s, -300.0, 1.5, 0.05);
        let mut dx = StateVector::zeros();
        dx.fixed_rows_mut::<3>(idx::POS)
            .copy_from(&Vector3::new(30.0, -20.0, 10.0));
        dx.fixed_rows_mut::<3>(idx::VEL)
            .copy_from(&Vector3::new(0.5, 0.2, -0.3));
        dx[idx::CLK] = 7.0;
        dx[idx::CLK_DRIFT] = 0.3;
        let mut nav2 = nav;
        correct_nav_state(&mut nav2, &dx);
        let m1 = gnss_pseudorange(&nav2, &at_imu, &r_s, 2.3e7, 100.0 + 7.0, 3.0);
        let d1 = gnss_range_rate(&nav2, &at_imu, &r_s, &v_s, -300.0, 1.5 + 0.3, 0.05);
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
    fn lever_arm_jacobians_match_finite_differences() {
        // Estimate moved by dx (position, velocity, attitude ψ): every GNSS innovation must
        // change by H·dx up to second order. With |ψ| = 5e-4 rad, |l| = 1.5 m the neglected
        // attitude term is |ψ|²|l|/2 ≈ 2e-7 m (position, pseudorange), and |ψ|²|ω||l| ≈ 1e-7
        // m/s for the velocities; the range-rate line-of-sight term adds
        // |δr_a|·|δv_a|/ρ ≈ 1e-6 m/s and the pseudorange |δr_a|²/(2ρ) ≈ 1e-6 m.
        let mut nav = nav_at_origin();
        nav.v_e = Vector3::new(3.0, 15.0, -1.0);
        nav.q_e_b = UnitQuaternion::from_euler_angles(0.1, -0.2, 2.1);
        let antenna = GnssAntenna {
            lever_arm_b_m: Vector3::new(0.3, 0.1, -1.5),
            w_ib_b_rad_s: Vector3::new(0.01, -0.02, 0.25),
        };
        let r_s = Vector3::new(2.0e7, 1.2e7, 0.9e7);
        let v_s = Vector3::new(-1200.0, 2500.0, 800.0);
        let z_r = nav.r_e + Vector3::new(1.0, 2.0, -1.0);
        let z_v = nav.v_e + Vector3::new(0.1, -0.1, 0.05);
        let cov = Matrix3::identity();
        let mut dx = StateVector::zeros();
        dx.fixed_rows_mut::<3>(idx::POS)
            .copy_from(&Vector3::new(0.8, -0.5, 0.3));
        dx.fixed_rows_mut::<3>(idx::VEL)
            .copy_from(&Vector3::new(0.05, 0.02, -0.03));
        dx.fixed_rows_mut::<3>(idx::ATT)
            .copy_from(&Vector3::new(3e-4, -2e-4, 3e-4));
        let mut nav2 = nav;
        correct_nav_state(&mut nav2, &dx);
        let p0 = gnss_position(&nav, &antenna, &z_r, &cov);
        let p1 = gnss_position(&nav2, &antenna, &z_r, &cov);
        let v0 = gnss_velocity(&nav, &antenna, &z_v, &cov);
        let v1 = gnss_velocity(&nav2, &antenna, &z_v, &cov);
        let r0 = gnss_pseudorange(&nav, &antenna, &r_s, 2.3e7, 0.0, 3.0);
        let r1 = gnss_pseudorange(&nav2, &antenna, &r_s, 2.3e7, 0.0, 3.0);
        let d0 = gnss_range_rate(&nav, &antenna, &r_s, &v_s, -300.0, 0.0, 0.05);
        let d1 = gnss_range_rate(&nav2, &antenna, &r_s, &v_s, -300.0, 0.0, 0.05);
        let e_p = p0.innovation - p1.innovation - p0.h * dx;
        let e_v = v0.innovation - v1.innovation - v0.h * dx;
        let e_r = r0.innovation[0] - r1.innovation[0] - (r0.h * dx)[0];
        let e_d = d0.innovation[0] - d1.innovation[0] - (d0.h * dx)[0];
        assert!(e_p.norm() < 1e-6, "position {e_p}");
        assert!(e_v.norm() < 1e-6, "velocity {e_v}");
        assert!(e_r.abs() < 5e-6, "pseudorange {e_r}");
        assert!(e_d.abs() < 5e-6, "range rate {e_d}");
        // The lever-arm attitude terms are at least 10× those tolerances, so the check above
        // fails without them (|ψ × l_e| = 3.1e-4 m, |ψ × (ω × l)_e| = 4.1e-5 m/s here).
        let att = |m: &SMatrix<f64, 3, NX>| {
            m.fixed_view::<3, 3>(0, idx::ATT) * dx.fixed_rows::<3>(idx::ATT)
        };
        assert!(att(&p0.h).norm() > 1e-5 && att(&v0.h).norm() > 1e-5);
        // No lever arm: the predicted antenna is the IMU.
        let (r_a, v_a, _, _) = GnssAntenna::AT_IMU.predict(&nav);
        assert_eq!((r_a, v_a), (nav.r_e, nav.v_e));
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
        // Estimate moved by dx (velocity, attitude): the innovations of the odometer and the
        // constraints at a wheel 1.8 m from the IMU must change by H·dx up to second order:
        // |δv|·|ψ| ≈ 3e-6 m/s and |ψ|²·|v|/2 ≈ 1e-7 m/s here. The attitude's lever-arm term
        // (|[l×] C [ω_ie×] ψ| ≈ 1e-8 m/s) is below that; the check against the IMU's model
        // shows the lever arm's velocity itself is in the prediction.
        let mut nav = nav_at_origin();
        nav.v_e = Vector3::new(1.0, 10.0, -2.0);
        nav.q_e_b = UnitQuaternion::from_euler_angles(0.2, 0.1, 1.3);
        let wheel = WheelContact {
            lever_arm_b_m: Vector3::new(-1.5, -0.8, 1.0),
            w_ib_b_rad_s: Vector3::new(0.02, -0.01, 0.25),
        };
        let m0 = odometer_nhc(&nav, &wheel, 0.002, 5.0, 0.1, 0.1);
        let s0 = odometer_speed(&nav, &wheel, 0.002, 5.0, 0.1);
        let mut dx = StateVector::zeros();
        dx.fixed_rows_mut::<3>(idx::VEL)
            .copy_from(&Vector3::new(0.01, -0.02, 0.005));
        dx.fixed_rows_mut::<3>(idx::ATT)
            .copy_from(&Vector3::new(1e-4, -5e-5, 1.5e-4));
        dx[idx::ODO] = 1e-4;
        let mut nav2 = nav;
        correct_nav_state(&mut nav2, &dx);
        let k2 = 0.002 + 1e-4;
        let m1 = odometer_nhc(&nav2, &wheel, k2, 5.0, 0.1, 0.1);
        let s1 = odometer_speed(&nav2, &wheel, k2, 5.0, 0.1);
        let d = m0.innovation - m1.innovation - m0.h * dx;
        assert!(d.norm() < 1e-5, "{d}");
        let d1 = s0.innovation[0] - s1.innovation[0] - (s0.h * dx)[0];
        assert!((d1 - d[0]).abs() < 1e-12 && (s0.h - m0.h.fixed_rows::<1>(0)).norm() < 1e-15);
        // The attitude columns alone: ψ moves the contact point's body velocity by more than
        // the tolerance (|v|·|ψ| ≈ 1e-3 m/s), so a wrong H_ψ fails.
        let mut dpsi = StateVector::zeros();
        dpsi.fixed_rows_mut::<3>(idx::ATT)
            .copy_from(&dx.fixed_rows::<3>(idx::ATT));
        let mut nav3 = nav;
        correct_nav_state(&mut nav3, &dpsi);
        let m3 = odometer_nhc(&nav3, &wheel, 0.002, 5.0, 0.1, 0.1);
        let e = m0.innovation - m3.innovation - m0.h * dpsi;
        assert!(e.norm() < 1e-6 && (m0.h * dpsi).norm() > 5e-4, "{e}");
        // The wheel's prediction is not the IMU's.
        let at_imu = odometer_nhc(&nav, &WheelContact::AT_IMU, 0.002, 5.0, 0.1, 0.1);
        assert!((at_imu.innovation - m0.innovation).norm() > 0.1);
    }

    #[test]
    fn wheel_velocity_in_a_steady_turn_is_the_closed_form() {
        // Steady right turn about body z at V = 10 m/s along body x (the IMU), yaw rate
        // relative to the Earth r = 0.2 rad/s (the gyro reads r plus the Earth's rate in body
        // axes): the rigid body's contact point at l moves with (V − r·l_y, r·l_x, 0) in body
        // axes. The Earth's rate (|ω_ie × l| ≈ 1e-4 m/s) must cancel exactly.
        let mut nav = nav_at_origin();
        nav.q_e_b = UnitQuaternion::from_euler_angles(0.0, 0.0, 0.7);
        nav.v_e = nav.q_e_b * Vector3::new(10.0, 0.0, 0.0);
        let c_b_e = nav.q_e_b.to_rotation_matrix().into_inner().transpose();
        let r = 0.2;
        let w_ie_b = c_b_e * crate::earth::WGS84.omega_ie_e();
        let l = Vector3::new(-1.5, -0.8, 1.0);
        let wheel = WheelContact {
            lever_arm_b_m: l,
            w_ib_b_rad_s: Vector3::new(0.0, 0.0, r) + w_ie_b,
        };
        let (v_c, _, _) = wheel.body_velocity(&nav);
        let closed = Vector3::new(10.0 - r * l.y, r * l.x, 0.0);
        assert!((v_c - closed).norm() < 1e-9, "{v_c} vs {closed}");
        // The outer (left) wheel of a right turn rolls faster, and the constraint sees the
        // rear axle's sideways motion relative to the IMU.
        assert!(v_c.x > 10.0 && v_c.y < -0.29);
    }
}
