//! Alignment in motion without a star attitude: the heading from GNSS velocity by the bank of
//! yaw hypotheses of [`crate::yaw_gsf`], run on the IMU/GNSS stream while the navigator
//! aligns; navigation starts (`start_in_motion`, as from a star attitude) once the vehicle
//! moves and the heading σ is below `motion_alignment.yaw_sigma_deg`.
//!
//! # Start of the bank
//! At the first GNSS epoch with a moving vehicle that follows another GNSS epoch, the window
//! between the two levels the hypotheses: its specific force `Σ C_{b_t b_k} Δv_k` in the
//! body axes of now (from the IMU log, `alignment_carry`), and the horizontal acceleration
//! over it from the two GNSS velocities, `a_n = Δv_n / Δt`. Since
//! `Σ C_n_b(t_k) Δv_k = C_n_b(t) Σ C_{b_t b_k} Δv_k = Δv_n − g_n Δt`, each hypothesis solves
//! for the roll and pitch that turn `a_n − g_n` into that specific force at its own heading
//! ([`crate::yaw_gsf::level_at_heading`]): the bank starts in a turn or a speed change as well
//! as on a straight, so a vehicle that never stops manoeuvring still aligns. The tilt σ is the
//! velocity noise's ([`crate::yaw_gsf::leveling_tilt_sigma_rad`]), at most
//! `MAX_LEVELING_SIGMA_RAD`.
//! The velocities are the receiver's, rotated to NED at its position (`v_n = C_n_e v_e`,
//! `P_n = C_n_e P_e C_e_n`, horizontal block). The bank's IMU error model is the filter's
//! (`[imu]`: ARW, VRW, constant biases).
//!
//! # After
//! Every IMU interval propagates the bank; every GNSS epoch with a velocity updates it (also
//! at standstill, which tells it the velocity), with the antenna's lever-arm velocity
//! `ω_b × l_b`. A GNSS velocity of epoch `ts` is applied at the IMU epoch `t` it is due at or
//! arrives at, whichever is later: each hypothesis compares it with its own velocity less the
//! velocity change the IMU sensed since `ts` (`alignment_carry`), with the velocity random
//! walk and accelerometer bias over that time added to the receiver's covariance. The start
//! takes the GNSS fix's position and velocity (carried to the IMU epoch) and the bank's attitude with its covariance, rotated to ECEF: `q_e_b = q_e_n · q_n_b`,
//! `P_ψ = C_e_n P_φ C_n_e` (the attitude's correlation with the last fix's velocity error,
//! one of the many epochs behind it, is not carried). A stopped vehicle keeps the static
//! alignment: after `alignment_s` at rest it finishes first.

use super::*;
use crate::yaw_gsf::{YawGsf, YawGsfNoise, YawGsfStart, leveling_tilt_sigma_rad};
use nalgebra::{Matrix2, Vector2};

/// Largest levelling σ the bank starts with, rad (1°). The horizontal acceleration over the
/// window is taken out per hypothesis and the tilt a hypothesis' heading error causes is in
/// its prior (`YawGsf::new`); what is left comes from the receiver's velocity noise,
/// `√2 σ_v/(Δt g)`: 0.8° for 0.1 m/s over one second. A noisier receiver waits for a longer
/// window between its fixes (a larger Δt) rather than start a bank that its first
/// linearisation would mislead.
const MAX_LEVELING_SIGMA_RAD: f64 = DEG;

/// The yaw estimator of the alignment, and the GNSS velocity its levelling window starts at.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct GsfAlignment {
    bank: Option<YawGsf>,
    /// The last GNSS velocity (north, east, m/s) and its epoch.
    last_v: Option<(GpsTime, Vector2<f64>)>,
}

impl Navigator {
    /// While aligning: propagate the yaw bank over one IMU increment (the levelling window
    /// before it starts is read from the IMU log, `alignment_carry`).
    pub(super) fn gsf_predict(
        &mut self,
        dth_b_rad: &Vector3<f64>,
        dv_b_m_s: &Vector3<f64>,
        dt_s: f64,
    ) {
        if !self.config.motion_alignment.enabled {
            return;
        }
        let g = &mut self.gsf;
        // The increments were validated (finite, positive interval): a refusal cannot happen;
        // should it, the bank starts over.
        if let Some(bank) = &mut g.bank
            && bank.predict(dth_b_rad, dv_b_m_s, dt_s).is_err()
        {
            *g = GsfAlignment::default();
        }
    }

    /// During alignment, at a GNSS epoch `ts` due at IMU epoch `t` (increment `dth_b_rad` over
    /// `dt_s`): start or update the yaw bank, and start navigating when the vehicle moves and
    /// the heading is known well enough. True when navigation started.
    pub(super) fn try_align_from_gnss_heading(
        &mut self,
        ts: GpsTime,
        obs: &GnssObs,
        t: GpsTime,
    ) -> bool {
        let cfg = self.config.motion_alignment;
        let Some(fix) = obs.fix else {
            return false;
        };
        if !cfg.enabled || !fix.vel_valid {
            return false;
        }
        // The velocity change since the fix epoch (`alignment_carry`): none from before the
        // alignment began or across an IMU gap.
        let Some((dv_since_b, tau, w_b)) = self.velocity_increment_since(ts) else {
            return false;
        };
        let geo = earth::ecef_to_geodetic(&self.ell, &fix.pos);
        let q_e_n = q_e_n(geo.lat_rad, geo.lon_rad);
        let c_e_n = q_e_n.to_rotation_matrix().into_inner();
        let v_n = c_e_n.transpose() * fix.vel;
        let p_n = c_e_n.transpose() * fix.vel_cov * c_e_n;
        let v_ne = Vector2::new(v_n.x, v_n.y);
        let r_ne: Matrix2<f64> = p_n.fixed_view::<2, 2>(0, 0).into_owned();
        let moving = self.moving(&fix);
        let imu = self.config.imu;
        let noise = imu.process_noise();
        // The bias and the deflection of the vertical alike move the apparent level.
        let accel_error = self.config.leveling_accel_error_m_s2();
        // The velocity random walk and accelerometer bias over the time since the fix epoch.
        let carried = noise.vrw_m_s_sqrt_s.powi(2) * tau + (accel_error * tau).powi(2);
        let Some(bank) = &mut self.gsf.bank else {
            // The window between the last GNSS velocity and this one: its specific force in
            // the body axes of now, from the IMU log (none across a gap, or from before the
            // alignment began).
            let window =
                self.gsf
                    .last_v
                    .filter(|(t_prev, _)| ts > *t_prev)
                    .and_then(|(t_prev, v_prev)| {
                        let (dv_prev_b, _, _) = self.velocity_increment_since(t_prev)?;
                        Some((t_prev, v_prev, dv_prev_b - dv_since_b))
                    });
            self.gsf.last_v = Some((ts, v_ne));
            let Some((t_prev, v_prev, dv_window_b)) = window.filter(|_| moving) else {
                return false;
            };
            let dt_window = (ts - t_prev).seconds_f64();
            let gravity = earth::normal_gravity(&self.ell, geo.lat_rad, geo.height_m);
            let sigma_v = r_ne[(0, 0)].max(r_ne[(1, 1)]).max(0.0).sqrt();
            let tilt_sigma_rad = leveling_tilt_sigma_rad(dt_window, sigma_v, accel_error, gravity);
            let start = YawGsfStart {
                f_b_m_s2: dv_window_b / dt_window,
                a_ne_m_s2: (v_ne - v_prev) / dt_window,
                tilt_sigma_rad,
                v_ne_m_s: v_ne,
                p_vv_m2_s2: r_ne + Matrix2::identity() * carried,
                dv_since_b_m_s: dv_since_b,
                lat_rad: geo.lat_rad,
                omega_ie_rad_s: self.ell.omega_ie_rad_s,
                gravity_m_s2: gravity,
            };
            let noise = YawGsfNoise {
                arw_rad_sqrt_s: noise.arw_rad_sqrt_s,
                vrw_m_s_sqrt_s: noise.vrw_m_s_sqrt_s,
                gyro_bias_rad_s: imu.gyro_bias_rad_s(),
                accel_bias_m_s2: accel_error,
            };
            // A refusal (a window sensing no gravity, or accelerating beyond half a g) waits
            // for the next window; so does one whose velocities are too noisy to level with.
            if tilt_sigma_rad <= MAX_LEVELING_SIGMA_RAD {
                self.gsf.bank = YawGsf::new(&start, noise).ok();
            }
            return false;
        };
        // The bank is at the IMU epoch, the velocity at `ts`: each hypothesis takes the
        // velocity change since then off its own, like the lever arm's.
        let lever_v_b = w_b.cross(&self.config.gnss.lever_arm_b()) - dv_since_b;
        let r_ne = r_ne + Matrix2::identity() * carried;
        if bank.update(&v_ne, &r_ne, &lever_v_b).is_err() {
            // A receiver covariance that is not positive definite: skip the epoch.
            return false;
        }
        let est = bank.estimate();
        if !moving || est.yaw_sigma_rad >= cfg.yaw_sigma_deg * DEG {
            return false;
        }
        let q_e_b = q_e_n * est.c_n_b.to_quaternion();
        let p_psi = c_e_n * est.p_att_n_rad2 * c_e_n.transpose();
        let Some(at_t) = self.carry_fix(&fix, ts, q_e_b, &p_psi) else {
            return false;
        };
        // The bank's tilt is a levelling: it carries the accelerometer error over g, added to
        // its covariance as `(σ/g)²` per tilt axis (`YawGsf::estimate`). The filter gets that
        // part as the joint tilt–bias block instead of an independent tilt (counted twice, the
        // tilt would look known once the velocities pin their sum down). Levelling nulls the
        // horizontal specific force: `ψ_N = δb_a,E/g`, `ψ_E = −δb_a,N/g` (NED, rows of C_n_b).
        let c_n_b = *est.c_n_b.dcm();
        let g = earth::normal_gravity(&self.ell, geo.lat_rad, geo.height_m);
        let mut level_n = Matrix3::zeros();
        level_n.set_row(0, &(c_n_b.row(1) / g));
        level_n.set_row(1, &(-c_n_b.row(0) / g));
        let tilt_part = (accel_error / g).powi(2);
        let mut p_other_n = est.p_att_n_rad2;
        p_other_n[(0, 0)] -= tilt_part;
        p_other_n[(1, 1)] -= tilt_part;
        let p_other = c_e_n * p_other_n * c_e_n.transpose();
        // No star attitude: the boresight has nothing to correlate with.
        self.start_in_motion(&at_t, t, q_e_b, &p_other, None, Some(c_e_n * level_n));
        self.diagnostics.gnss_heading_alignments += 1;
        true
    }
}
