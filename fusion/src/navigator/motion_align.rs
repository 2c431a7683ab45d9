//! Alignment in motion from the star tracker and GNSS: one star-tracker attitude gives the
//! whole body attitude, one GNSS fix the position and velocity, and navigation starts at once;
//! the filter refines. Used whenever the navigator aligns (start, re-initialisation after an
//! IMU gap, restart of the daemon) while GNSS says the vehicle moves; a standing vehicle keeps
//! the static gyrocompass alignment (`align`, paper 003).
//!
//! # Attitude (paper 000's measurement chain, inverted)
//! The star tracker measures `C̃_s_i` (ICRF → sensor). With the celestial transformation
//! `C_e_i(t)` (GCRS → ITRS, IAU 2006/2000A, [`crate::celestial`]) at the exposure time and the
//! body → sensor mount `C_s_b = C_s_b,nom·M(κ̂)` ([`crate::ekf::star_attitude`]),
//! `Ĉ_e_b = C_e_i · C̃_s_iᵀ · C_s_b`.
//! The update model of [`crate::ekf::star_attitude`] is `y = Ĉ_s_e ψ − C_s_b B δκ + ν`; the
//! attitude that makes y = 0 therefore has the error `ψ = C_e_s (C_s_b B δκ − ν)`, i.e.
//! `P_ψψ = C_e_s R C_s_e + C_e_b B P_κκ Bᵀ C_b_e` and `P_ψκ = C_e_b B P_κκ`
//! (R = diag(σ_cross², σ_cross², σ_roll²), sensor axes; P_κκ only when the boresight is
//! estimated — otherwise the filter takes the mount as exact, as its star updates do).
//!
//! Between the exposure and the start (the next GNSS epoch, ≤ one GNSS interval later; from
//! the logged IMU steps when the sample arrives late, `alignment_carry`) the attitude is
//! carried by the gyros: `C_e_b ← R_z(−ω_ie Δt) · C_e_b · exp([Δθ×])`, which adds
//! the angle random walk `ARW²·τ` and the unestimated gyro bias `(σ_bg τ)²` per axis over the
//! carried time τ (for τ = 1 s and the navigation-grade defaults: 5·10⁻⁷ and 5·10⁻⁸ rad,
//! two orders below the star tracker's arcseconds).
//!
//! # Position and velocity
//! From the GNSS fix with its own covariance, taken from the antenna to the IMU by the lever
//! arm `l_b` (`[gnss]`: `r −= C_e_b l_b`, `v −= C_e_b (ω_b × l_b)`) at the fix epoch and
//! carried to the IMU epoch by the strapdown over the IMU steps logged since
//! (`alignment_carry`, with the covariance of that carry): a fix that arrives late, as a real
//! receiver's always does, starts navigation as well as one in time.
//! Without a star attitude the same start takes the attitude of the
//! GNSS-velocity heading estimator (`gsf_align`).
//! The sensors' errors are independent, so the position, velocity and attitude blocks start
//! uncorrelated; the sensor biases start from their priors (`sensor_prior`) or,
//! after a warm restart, from the checkpoint (`warm_start`).
//!
//! # When the vehicle moves
//! GNSS velocity with `|v| ≥ motion_alignment.min_speed_m_s` and `|v|² > 9·tr(P_vv)` (the
//! speed is more than three of its own σ away from zero), so a receiver's noise on a
//! standing vehicle never triggers it.

use super::*;

/// Alignment in motion (`[motion_alignment]` in `config/filter.toml`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct MotionAlignment {
    /// Start navigation from one star-tracker attitude and one GNSS fix when the vehicle
    /// moves (false: only the static alignment).
    pub enabled: bool,
    /// GNSS speed above which the vehicle counts as moving, m/s.
    pub min_speed_m_s: f64,
    /// Without a star attitude: start navigation once the heading 1-σ of the GNSS-velocity
    /// yaw estimator ([`crate::yaw_gsf`]) is below this, deg. Default 2°: 3σ = 6° ≈ 0.1 rad
    /// keeps the terms the error-state filter's small-angle model drops (`1 − cos ψ ≈ ψ²/2`,
    /// ≤ 0.5 % of the specific force; `ψ − sin ψ ≈ ψ³/6`, ≤ 0.02 %) below one percent.
    pub yaw_sigma_deg: f64,
}

impl Default for MotionAlignment {
    fn default() -> Self {
        Self {
            enabled: true,
            min_speed_m_s: 1.0,
            yaw_sigma_deg: 2.0,
        }
    }
}

impl MotionAlignment {
    pub(super) fn validate(&self) -> Result<(), ConfigError> {
        check(
            pos(self.min_speed_m_s) && self.min_speed_m_s <= 100.0,
            "motion_alignment.min_speed_m_s",
            "must be in (0, 100] m/s",
        )?;
        // Beyond 10° (3σ = 30°) the small-angle model of the filter no longer holds.
        check(
            pos(self.yaw_sigma_deg) && self.yaw_sigma_deg <= 10.0,
            "motion_alignment.yaw_sigma_deg",
            "must be in (0, 10] deg",
        )
    }
}

/// A star-tracker attitude carried by the gyros until navigation starts.
#[derive(Debug, Clone, Copy)]
pub(super) struct StarAttitude {
    /// Attitude body → ECEF at the last IMU epoch.
    pub(super) q_e_b: UnitQuaternion<f64>,
    /// Covariance of the ECEF attitude error ψ at the exposure, rad².
    pub(super) p_psi: Matrix3<f64>,
    /// Cross-covariance of ψ with the boresight error δκ, rad².
    pub(super) p_psi_kappa: Matrix3<f64>,
    /// Time carried by the gyros since the exposure, s.
    pub(super) carried_s: f64,
}

impl Navigator {
    /// During alignment: carry a star attitude over one IMU increment `dth` (body, rad) of
    /// `dt_s` seconds.
    pub(super) fn carry_star_attitude(&mut self, dth: &Vector3<f64>, dt_s: f64) {
        let omega = self.ell.omega_ie_rad_s;
        if let Some(a) = &mut self.star_attitude {
            let earth = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -omega * dt_s);
            a.q_e_b = earth * a.q_e_b * UnitQuaternion::from_scaled_axis(*dth);
            a.carried_s += dt_s;
        }
    }

    /// During alignment: the attitude from a star-tracker sample of exposure time `ts`, carried
    /// by the gyros to the newest IMU epoch (`alignment_carry`), however late it arrived.
    pub(super) fn alignment_star(&mut self, ts: GpsTime, obs: &StarObs) {
        if !(self.config.motion_alignment.enabled && self.config.updates.star_tracker) {
            return;
        }
        let c_e_i = self.celestial.c_e_i(ts, &self.config.eop);
        let (kappa, p_kk) = self.boresight_prior();
        let c_s_b = self.c_s_b * ekf::kappa_matrix(&kappa);
        let c_s_i = quat_from_wire(&obs.q).to_rotation_matrix().into_inner();
        let c_e_b = c_e_i * c_s_i.transpose() * c_s_b;
        let c_e_s = c_e_b * c_s_b.transpose();
        let r = Matrix3::from_diagonal(&Vector3::new(
            obs.sigma_cross * obs.sigma_cross,
            obs.sigma_cross * obs.sigma_cross,
            obs.sigma_roll * obs.sigma_roll,
        ));
        let b = ekf::kappa_jacobian(&kappa);
        let g = c_e_b * b;
        let q_e_b = UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix(&c_e_b));
        // Not a sample from before the first logged IMU step (queued before the alignment
        // began) or from across an IMU gap.
        let Some((q_e_b, carried_s)) = self.attitude_forward_from(q_e_b, ts) else {
            return;
        };
        self.star_attitude = Some(StarAttitude {
            q_e_b,
            p_psi: c_e_s * r * c_e_s.transpose() + g * p_kk * g.transpose(),
            p_psi_kappa: g * p_kk,
            carried_s,
        });
    }

    /// The boresight estimate and its covariance the star attitude is derived with: the
    /// checkpoint's after a warm restart, else the calibration memory's where it is tighter
    /// than the prior, else zero with the configured prior σ; zero
    /// covariance when the boresight is not estimated.
    fn boresight_prior(&self) -> (Vector3<f64>, Matrix3<f64>) {
        if !self.active_states(false).boresight {
            return (Vector3::zeros(), Matrix3::zeros());
        }
        if let Some(w) = &self.warm {
            let p = w.covariance_matrix();
            return (
                Vector3::from(w.kappa_rad),
                p.fixed_view::<3, 3>(idx::KAPPA, idx::KAPPA).into_owned(),
            );
        }
        if let Some(remembered) = self.remembered_boresight() {
            return remembered;
        }
        (Vector3::zeros(), self.boresight_prior_covariance())
    }

    /// During alignment, at a GNSS epoch `ts` due at IMU epoch `t` (however late it arrived):
    /// start navigating when the fix shows a moving vehicle and a star attitude is at hand.
    /// True when it started.
    pub(super) fn try_align_in_motion(&mut self, ts: GpsTime, obs: &GnssObs, t: GpsTime) -> bool {
        if !self.config.motion_alignment.enabled {
            return false;
        }
        let (Some(att), Some(fix)) = (self.star_attitude, obs.fix) else {
            return false;
        };
        if !self.moving(&fix) {
            return false;
        }
        let imu = &self.config.imu;
        let noise = imu.process_noise();
        let tau = att.carried_s;
        let carried = noise.arw_rad_sqrt_s.powi(2) * tau + (imu.gyro_bias_rad_s() * tau).powi(2);
        let p_psi = att.p_psi + Matrix3::identity() * carried;
        let Some(at_t) = self.carry_fix(&fix, ts, att.q_e_b, &p_psi) else {
            return false;
        };
        let kappa = self
            .active_states(false)
            .boresight
            .then_some(att.p_psi_kappa);
        self.start_in_motion(&at_t, t, att.q_e_b, &p_psi, kappa, None);
        true
    }

    /// Whether a GNSS fix shows a moving vehicle: a valid velocity with
    /// `|v| ≥ motion_alignment.min_speed_m_s` and `|v|² > 9·tr(P_vv)`.
    pub(super) fn moving(&self, fix: &GnssFix) -> bool {
        if !fix.vel_valid {
            return false;
        }
        let speed2 = fix.vel.norm_squared();
        let min = self.config.motion_alignment.min_speed_m_s;
        speed2 >= min * min && speed2 > 9.0 * fix.vel_cov.trace()
    }

    /// Start navigating in motion at IMU epoch `t` from the IMU's position and velocity there,
    /// carried from a GNSS fix (`alignment_carry::CarriedFix`, with the antenna's lever arm
    /// taken off), and an attitude `q_e_b` whose ECEF error ψ has the covariance `p_psi`
    /// (rad²) and, with the boresight estimated, the cross-covariance `p_psi_kappa` with it.
    /// A levelled attitude (`leveled_e`, the ECEF map from the body accelerometer error to the
    /// tilt the levelling left, `ψ_e = L·δb_a`) shares its tilt error with the
    /// accelerometer-bias states: `p_psi` is then the attitude covariance without that part,
    /// and the joint block is built from the bias prior (as the static alignment does).
    pub(super) fn start_in_motion(
        &mut self,
        at_t: &CarriedFix,
        t: GpsTime,
        q_e_b: UnitQuaternion<f64>,
        p_psi: &Matrix3<f64>,
        p_psi_kappa: Option<Matrix3<f64>>,
        leveled_e: Option<Matrix3<f64>>,
    ) {
        let r_e = at_t.r_e;
        let v_e = at_t.v_e;
        let c_e_b = q_e_b.to_rotation_matrix().into_inner();
        // Gravity as the body senses it on average (the accelerometer-misalignment prior).
        let geo = earth::ecef_to_geodetic(&self.ell, &r_e);
        let c_e_n = q_e_n(geo.lat_rad, geo.lon_rad)
            .to_rotation_matrix()
            .into_inner();
        let f_b = c_e_b.transpose() * c_e_n * Vector3::new(0.0, 0.0, -G0);
        let (mut p0, x0) = self.sensor_prior(&f_b);
        // POS and VEL are adjacent in the state vector: one 6×6 block.
        p0.fixed_view_mut::<6, 6>(idx::POS, idx::POS)
            .copy_from(&at_t.p_rv);
        p0.fixed_view_mut::<3, 3>(idx::ATT, idx::ATT)
            .copy_from(p_psi);
        if let Some(l) = leveled_e {
            // ψ = ψ_other + L δb_a: Cov(ψ) = P_other + L P_ba Lᵀ, Cov(ψ, δb_a) = L P_ba.
            let p_ba = p0.fixed_view::<3, 3>(idx::BA, idx::BA).into_owned();
            let cross = l * p_ba;
            let mut att = p0.fixed_view_mut::<3, 3>(idx::ATT, idx::ATT);
            att += cross * l.transpose();
            p0.fixed_view_mut::<3, 3>(idx::ATT, idx::BA)
                .copy_from(&cross);
            p0.fixed_view_mut::<3, 3>(idx::BA, idx::ATT)
                .copy_from(&cross.transpose());
        }
        if let Some(p_pk) = p_psi_kappa {
            p0.fixed_view_mut::<3, 3>(idx::ATT, idx::KAPPA)
                .copy_from(&p_pk);
            p0.fixed_view_mut::<3, 3>(idx::KAPPA, idx::ATT)
                .copy_from(&p_pk.transpose());
        }
        self.core.nav = NavState { r_e, v_e, q_e_b };
        self.start_navigation(p0, &x0, t);
        self.diagnostics.motion_alignments += 1;
    }

    /// The process noise of the filter: the IMU's plus the aiding states' random walks.
    pub(super) fn filter_noise(&self) -> ProcessNoise {
        let mut noise = self.config.imu.process_noise();
        noise.baro_bias_rw_m_sqrt_s = self.config.aiding.baro_bias_rw_m_sqrt_s;
        noise.clock_bias_psd_m2_s = self.config.aiding.clock_bias_psd_m2_s;
        noise.clock_drift_psd_m2_s3 = self.config.aiding.clock_drift_psd_m2_s3;
        noise.gravity = self.config.gravity_disturbance.disturbance();
        noise
    }

    /// Start navigating at IMU epoch `t` from the inertial state already in `core.nav`, the
    /// initial covariance `p0` and the sensor-error estimates `x0`: a fresh filter (or, after a warm restart, the checkpoint's
    /// sensor estimates with their covariance, `apply_warm_start`), fresh
    /// mechanization history, delayed-fusion log and checkpoints; aiding queued up to `t`
    /// belongs to the alignment period.
    pub(super) fn start_navigation(&mut self, p0: Covariance, x0: &StateVector, t: GpsTime) {
        self.core.ekf = ErrorStateEkf::new(p0, self.filter_noise(), self.active_states(false));
        // The sensor-error estimates of the prior (the calibration memory's, else zero).
        self.core.ekf.apply_sensor_estimates(x0);
        self.core.clock_initialized = false;
        self.core.last_gnss_ranging = None;
        self.apply_warm_start(t);
        if !self.core.clock_initialized {
            self.initialize_from_ls(t);
        }
        self.core.strapdown = Strapdown::new(self.config.mechanization());
        self.phase = Phase::Navigating;
        self.time = t;
        self.star_attitude = None;
        self.gsf = GsfAlignment::default();
        self.imu_log.clear();
        self.checkpoints.clear();
        self.deferred_step = None;
        self.rewind_to = None;
        self.take_checkpoint(t, t);
        self.gnss_q.clear();
        self.gnss_inbox.clear();
        self.star_inbox.clear();
        self.odo_inbox.clear();
        self.baro_inbox.clear();
    }
}
