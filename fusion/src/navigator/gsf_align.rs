//! Alignment in motion without a star attitude: the heading from GNSS velocity by the bank of
//! yaw hypotheses of [`crate::yaw_gsf`], run on the IMU/GNSS stream while the navigator
//! aligns; navigation starts (`start_in_motion`, as from a star attitude) once the vehicle
//! moves and the heading σ is below `motion_alignment.yaw_sigma_deg`.
//!
//! # Start of the bank
//! At the first GNSS epoch with a moving vehicle that follows another GNSS epoch: the roll and
//! pitch are levelled from the mean specific force `Σ Δv_b / Σ Δt` over the IMU intervals
//! between the two epochs, with the σ of [`crate::yaw_gsf::leveling_tilt_sigma_rad`] from the
//! velocity change over them (the horizontal acceleration the accelerometers also sense),
//! when that σ is at most `MAX_LEVELING_SIGMA_RAD`.
//! The velocities are the receiver's, rotated to NED at its position (`v_n = C_n_e v_e`,
//! `P_n = C_n_e P_e C_e_n`, horizontal block). The bank's IMU error model is the filter's
//! (`[imu]`: ARW, VRW, constant biases).
//!
//! # After
//! Every IMU interval propagates the bank; every GNSS epoch with a velocity updates it (also
//! at standstill, which tells it the velocity), with the antenna's lever-arm velocity
//! `ω_b × l_b`. A GNSS velocity of epoch `ts` is applied at the IMU epoch `t` it is due at,
//! at most 1.5 IMU intervals later (7.5 ms at 200 Hz: 7.5 mm/s at 1 m/s², a tenth of a
//! receiver's velocity σ). The start takes the GNSS fix's position and velocity and the
//! bank's attitude with its covariance, rotated to ECEF: `q_e_b = q_e_n · q_n_b`,
//! `P_ψ = C_e_n P_φ C_n_e` (the attitude's correlation with the last fix's velocity error,
//! one of the many epochs behind it, is not carried). A stopped vehicle keeps the static
//! alignment: after `alignment_s` at rest it finishes first.

use super::*;
use crate::yaw_gsf::{YawGsf, YawGsfNoise, YawGsfStart, leveling_tilt_sigma_rad};
use nalgebra::{Matrix2, Vector2};

/// Largest levelling σ the bank starts with, rad (1°). Under a horizontal acceleration `a` a
/// hypothesis with the heading error δψ explains the velocities as well as the truth if its
/// tilt is off by `a sin δψ / g` (a tilt and a heading error both turn the specific force
/// horizontally): every hypothesis but the two nearest is ≥ 2π/N = 30° off, which a car's 1 m/s²
/// (a turn at 10 m/s and 6°/s, or a brisk speed change) hides behind 2.9° of tilt. A prior
/// tilt σ of 1° keeps that ≥ 3σ away; a window accelerating harder (|a_h| > 0.17 m/s²) waits
/// for the next.
const MAX_LEVELING_SIGMA_RAD: f64 = DEG;

/// The yaw estimator of the alignment and the levelling window before it starts.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct GsfAlignment {
    bank: Option<YawGsf>,
    /// Σ Δv (body, m/s) and Σ Δt (s) of the IMU intervals since the last GNSS velocity.
    sum_dv_b_m_s: Vector3<f64>,
    sum_dt_s: f64,
    /// The last GNSS velocity (north, east, m/s) and its epoch.
    last_v: Option<(GpsTime, Vector2<f64>)>,
}

impl Navigator {
    /// While aligning: propagate the yaw bank over one IMU increment, or add it to the
    /// levelling window while the bank has not started.
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
        match &mut g.bank {
            // The increments were validated (finite, positive interval): a refusal cannot
            // happen; should it, the bank starts over.
            Some(bank) => {
                if bank.predict(dth_b_rad, dv_b_m_s, dt_s).is_err() {
                    *g = GsfAlignment::default();
                }
            }
            None => {
                g.sum_dv_b_m_s += dv_b_m_s;
                g.sum_dt_s += dt_s;
            }
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
        dth_b_rad: &Vector3<f64>,
        dt_s: f64,
    ) -> bool {
        let cfg = self.config.motion_alignment;
        let Some(fix) = obs.fix else {
            return false;
        };
        if !cfg.enabled || !fix.vel_valid || !within_interval(t - ts, dt_s) {
            return false;
        }
        let geo = earth::ecef_to_geodetic(&self.ell, &fix.pos);
        let q_e_n = q_e_n(geo.lat_rad, geo.lon_rad);
        let c_e_n = q_e_n.to_rotation_matrix().into_inner();
        let v_n = c_e_n.transpose() * fix.vel;
        let p_n = c_e_n.transpose() * fix.vel_cov * c_e_n;
        let v_ne = Vector2::new(v_n.x, v_n.y);
        let r_ne: Matrix2<f64> = p_n.fixed_view::<2, 2>(0, 0).into_owned();
        let moving = self.moving(&fix);
        let imu = &self.config.imu;
        let g = &mut self.gsf;
        match &mut g.bank {
            None => {
                if let Some((t_prev, v_prev)) = g.last_v
                    && moving
                    && g.sum_dt_s > 0.0
                    && ts > t_prev
                {
                    let gravity = earth::normal_gravity(&self.ell, geo.lat_rad, geo.height_m);
                    let sigma_v = r_ne[(0, 0)].max(r_ne[(1, 1)]).max(0.0).sqrt();
                    let noise = imu.process_noise();
                    let tilt_sigma_rad = leveling_tilt_sigma_rad(
                        &(v_ne - v_prev),
                        (ts - t_prev).seconds_f64(),
                        sigma_v,
                        imu.accel_bias_m_s2(),
                        gravity,
                    );
                    let start = YawGsfStart {
                        f_b_m_s2: g.sum_dv_b_m_s / g.sum_dt_s,
                        tilt_sigma_rad,
                        v_ne_m_s: v_ne,
                        p_vv_m2_s2: r_ne,
                        lat_rad: geo.lat_rad,
                        omega_ie_rad_s: self.ell.omega_ie_rad_s,
                        gravity_m_s2: gravity,
                    };
                    let noise = YawGsfNoise {
                        arw_rad_sqrt_s: noise.arw_rad_sqrt_s,
                        vrw_m_s_sqrt_s: noise.vrw_m_s_sqrt_s,
                        gyro_bias_rad_s: imu.gyro_bias_rad_s(),
                        accel_bias_m_s2: imu.accel_bias_m_s2(),
                    };
                    // A refusal (a window sensing no gravity) waits for the next window;
                    // so does a window too accelerated to level in (`MAX_LEVELING_SIGMA_RAD`).
                    if tilt_sigma_rad <= MAX_LEVELING_SIGMA_RAD {
                        g.bank = YawGsf::new(&start, noise).ok();
                    }
                }
                g.last_v = Some((ts, v_ne));
                g.sum_dv_b_m_s = Vector3::zeros();
                g.sum_dt_s = 0.0;
                false
            }
            Some(bank) => {
                let w_b = if dt_s > 0.0 {
                    dth_b_rad / dt_s
                } else {
                    Vector3::zeros()
                };
                let lever_v_b = w_b.cross(&self.config.gnss.lever_arm_b());
                if bank.update(&v_ne, &r_ne, &lever_v_b).is_err() {
                    // A receiver covariance that is not positive definite: skip the epoch.
                    return false;
                }
                let est = bank.estimate();
                if !moving || est.yaw_sigma_rad >= cfg.yaw_sigma_deg * DEG {
                    return false;
                }
                let q_n_b = est.c_n_b.to_quaternion();
                let p_psi = c_e_n * est.p_att_n_rad2 * c_e_n.transpose();
                // No star attitude: the boresight has nothing to correlate with.
                self.start_in_motion(&fix, ts, t, q_e_n * q_n_b, &p_psi, None, dth_b_rad, dt_s);
                self.diagnostics.gnss_heading_alignments += 1;
                true
            }
        }
    }
}
