//! Aiding of an earlier epoch carried to the current IMU epoch while aligning: a star-tracker
//! attitude or a GNSS fix that reaches the navigator after the IMU has passed its time of
//! validity (a receiver's latency, tens to hundreds of milliseconds) still starts navigation
//! in motion, carried forward with the IMU increments logged since its epoch.
//!
//! While aligning, every accepted IMU step is logged in the delayed-fusion IMU log (cleared
//! when navigation starts, sized for `buffer_window_s`), so any aiding the input gate accepts
//! (at most `buffer_window_s` old) is covered unless the alignment itself began after its
//! epoch or the IMU had a gap since.
//!
//! # Attitude
//! With `C_e_b(t_k) = R_z(−ω_ie Δt_k) · C_e_b(t_{k−1}) · exp([Δθ_k×])` per step, an attitude
//! known at the current epoch is taken back to `ts` by the inverse steps, and one known at
//! `ts` forward; the step that contains `ts` counts with the fraction of it after `ts`
//! (increments taken as uniform over the step). A gyro error over the carried time `τ` adds
//! `ARW²τ + (σ_bg τ)²` per axis (callers add it, as for the in-interval carry).
//!
//! # Position and velocity
//! The fix gives the antenna's position and velocity at `ts`. The IMU's are
//! `r = r_a − C_e_b(ts) l_b`, `v = v_a − C_e_b(ts)(ω_b × l_b)`, then the strapdown
//! ([`crate::strapdown`]) integrates the logged increments from `ts` to the current epoch.
//! Its error over `τ` (first order, errors at `ts` independent):
//! `δv(t) = δv₀ + τ a`, `δr(t) = δr₀ + τ δv₀ + τ²/2 a` with `a` the specific-force error of
//! the carry: the attitude error seen by the specific force (`|f| σ_ψ`, σ_ψ the largest axis)
//! and the accelerometer bias (`σ_ba`), per axis; plus the velocity random walk
//! (`VRW² τ` on velocity, `VRW² τ³/3` on position, `VRW² τ²/2` between them).
//!
//! # Velocity for the GNSS heading estimator
//! The bank of yaw hypotheses lives at the current epoch, the velocity at `ts`. Each
//! hypothesis predicts the velocity at `ts` as its own less `C_n_b Δv_b`, with `Δv_b` the
//! specific-force increments since `ts` in the current body axes: the same form as the
//! antenna's lever-arm velocity in [`crate::yaw_gsf::YawGsf::update`], which therefore takes
//! `ω_b × l_b − Δv_b` (gravity is vertical in NED and the Coriolis term over `τ ≤ 2 s` is
//! below 3 mm/s at 10 m/s).

use super::*;
use nalgebra::Matrix6;

/// A GNSS fix carried to the current IMU epoch: the IMU's position and velocity (ECEF) and
/// their joint covariance (position first, m², m²/s, m²/s²).
#[derive(Debug, Clone, Copy)]
pub(super) struct CarriedFix {
    pub(super) r_e: Vector3<f64>,
    pub(super) v_e: Vector3<f64>,
    pub(super) p_rv: Matrix6<f64>,
}

impl Navigator {
    /// Log one IMU step accepted while aligning (the log is the one delayed fusion uses once
    /// navigating; `start_navigation` clears it).
    pub(super) fn log_alignment_step(&mut self, e: ImuLogEntry) {
        self.imu_log.push(e);
    }

    /// The logged steps from the newest back to the one containing `ts`, each with the
    /// fraction of it after `ts` (1 for whole steps); None when the log does not reach back
    /// to `ts` without a gap. Visits at most the log's capacity.
    fn steps_since(&self, ts: GpsTime, mut visit: impl FnMut(&ImuLogEntry, f64)) -> Option<()> {
        let n = self.imu_log.len;
        let mut next_start: Option<GpsTime> = None;
        for i in (0..n).rev() {
            let e = *self.imu_log.get(i);
            if e.dt_s <= 0.0 {
                return None;
            }
            let start = e.t - Duration::from_seconds_f64(e.dt_s);
            // Contiguous with the step after it (half a step of jitter allowed).
            if let Some(s) = next_start
                && (s - e.t).seconds_f64().abs() > 0.5 * e.dt_s
            {
                return None;
            }
            if e.t <= ts {
                return Some(());
            }
            if start <= ts {
                let frac = ((e.t - ts).seconds_f64() / e.dt_s).clamp(0.0, 1.0);
                visit(&e, frac);
                return Some(());
            }
            visit(&e, 1.0);
            next_start = Some(start);
        }
        // The log begins after `ts`: the alignment started later than the sample's epoch.
        None
    }

    /// The attitude body → ECEF at `ts` from the one at the newest logged epoch.
    pub(super) fn attitude_back_to(
        &self,
        q_e_b_now: UnitQuaternion<f64>,
        ts: GpsTime,
    ) -> Option<UnitQuaternion<f64>> {
        let omega = self.ell.omega_ie_rad_s;
        let mut q = q_e_b_now;
        self.steps_since(ts, |e, frac| {
            let earth = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), omega * e.dt_s * frac);
            q = earth * q * UnitQuaternion::from_scaled_axis(-e.dth * frac);
        })?;
        Some(q)
    }

    /// The attitude body → ECEF at the newest logged epoch from the one at `ts`, and the time
    /// carried, s.
    pub(super) fn attitude_forward_from(
        &self,
        q_e_b_ts: UnitQuaternion<f64>,
        ts: GpsTime,
    ) -> Option<(UnitQuaternion<f64>, f64)> {
        let omega = self.ell.omega_ie_rad_s;
        // The steps come newest first: compose them on the inside, between `q_e_b_ts` and the
        // steps already seen (earth rotation on the left commutes with nothing, so keep both
        // products: C(t) = E_n…E_1 · C(ts) · B_1…B_n).
        let mut earth = UnitQuaternion::identity();
        let mut body = UnitQuaternion::identity();
        let mut carried_s = 0.0;
        self.steps_since(ts, |e, frac| {
            earth *= UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -omega * e.dt_s * frac);
            body = UnitQuaternion::from_scaled_axis(e.dth * frac) * body;
            carried_s += e.dt_s * frac;
        })?;
        Some((earth * q_e_b_ts * body, carried_s))
    }

    /// Since `ts`: the specific-force velocity increment in the body axes of the newest logged
    /// epoch (m/s), the time it spans (s), and the body rate at `ts` (rad/s).
    pub(super) fn velocity_increment_since(
        &self,
        ts: GpsTime,
    ) -> Option<(Vector3<f64>, f64, Vector3<f64>)> {
        // C_{b_now b_k}, built newest first: each step's increment is taken at its middle.
        let mut c_now_k = UnitQuaternion::identity();
        let mut dv = Vector3::zeros();
        let mut tau = 0.0;
        let mut w_b = Vector3::zeros();
        self.steps_since(ts, |e, frac| {
            let dth = e.dth * frac;
            dv += c_now_k * (UnitQuaternion::from_scaled_axis(-0.5 * dth) * (e.dv * frac));
            c_now_k *= UnitQuaternion::from_scaled_axis(-dth);
            tau += e.dt_s * frac;
            w_b = e.dth / e.dt_s;
        })?;
        Some((dv, tau, w_b))
    }

    /// The IMU's position and velocity at the newest logged epoch from the antenna fix of
    /// epoch `ts`, given the attitude there `q_e_b_now` whose error has the covariance
    /// `p_psi` (rad²). None when the log does not cover `ts`.
    pub(super) fn carry_fix(
        &self,
        fix: &GnssFix,
        ts: GpsTime,
        q_e_b_now: UnitQuaternion<f64>,
        p_psi: &Matrix3<f64>,
    ) -> Option<CarriedFix> {
        let q_ts = self.attitude_back_to(q_e_b_now, ts)?;
        // How many logged steps reach back to `ts`, and the rate of the oldest (it contains
        // `ts`: the steps are visited newest first).
        let mut count = 0usize;
        let mut w_b = Vector3::zeros();
        self.steps_since(ts, |e, _| {
            count += 1;
            w_b = e.dth / e.dt_s;
        })?;
        let lever_b = self.config.gnss.lever_arm_b();
        let mut state = NavState {
            r_e: fix.pos - q_ts * lever_b,
            v_e: fix.vel - q_ts * w_b.cross(&lever_b),
            q_e_b: q_ts,
        };
        let mut mech = Strapdown::new(self.config.mechanization());
        let mut tau = 0.0;
        let mut f_max = 0.0f64;
        let n = self.imu_log.len;
        for i in n - count..n {
            let e = *self.imu_log.get(i);
            let frac = if i == n - count {
                ((e.t - ts).seconds_f64() / e.dt_s).clamp(0.0, 1.0)
            } else {
                1.0
            };
            if frac <= 0.0 {
                continue;
            }
            mech.step(
                &mut state,
                &ImuIncrement {
                    dt_s: e.dt_s * frac,
                    delta_angle_rad: e.dth * frac,
                    delta_velocity_m_s: e.dv * frac,
                },
            );
            tau += e.dt_s * frac;
            f_max = f_max.max(e.dv.norm() / e.dt_s);
        }
        // Error of the carry (module docs): per axis, `a` from the attitude error under the
        // largest specific force sensed and from the accelerometer bias.
        let imu = &self.config.imu;
        let vrw2 = imu.process_noise().vrw_m_s_sqrt_s.powi(2);
        let sigma_psi2 = (0..3).map(|k| p_psi[(k, k)]).fold(0.0, f64::max);
        let qa = f_max * f_max * sigma_psi2 + self.config.leveling_accel_error_m_s2().powi(2);
        let mut p0 = Matrix6::zeros();
        p0.fixed_view_mut::<3, 3>(0, 0).copy_from(&fix.pos_cov);
        p0.fixed_view_mut::<3, 3>(3, 3).copy_from(&fix.vel_cov);
        let mut phi = Matrix6::identity();
        phi.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(Matrix3::identity() * tau));
        let mut p = phi * p0 * phi.transpose();
        let (t2, t3) = (tau * tau, tau * tau * tau);
        for k in 0..3 {
            let c = qa * t3 / 2.0 + vrw2 * t2 / 2.0;
            p[(k, k)] += qa * t2 * t2 / 4.0 + vrw2 * t3 / 3.0;
            p[(k + 3, k + 3)] += qa * t2 + vrw2 * tau;
            p[(k, k + 3)] += c;
            p[(k + 3, k)] += c;
        }
        Some(CarriedFix {
            r_e: state.r_e,
            v_e: state.v_e,
            p_rv: p,
        })
    }
}
