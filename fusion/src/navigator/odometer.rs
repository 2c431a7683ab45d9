//! Odometer speed with the interval-mean correction, and the non-holonomic constraints, at the
//! odometer wheel's contact point with the vehicle class's noise.

use super::*;

/// Odometer epoch kept for the next sample's interval-mean correction (`fuse_odometer`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct OdometerEpoch {
    /// Time of validity.
    pub(super) t: GpsTime,
    /// Spacing from the epoch before.
    pub(super) spacing: Option<Duration>,
    /// Forward speed of the odometer wheel's contact point in the solution after the update,
    /// m/s.
    pub(super) v_x_m_s: f64,
}

impl Navigator {
    /// The odometer wheel's contact point and the body's last angular rate.
    fn wheel_contact(&self) -> ekf::WheelContact {
        ekf::WheelContact {
            lever_arm_b_m: self.config.vehicle.wheel_lever_arm_b(),
            w_ib_b_rad_s: self.core.w_ib_b_rad_s,
        }
    }

    /// The noise variance of one row of the odometer/constraint model: the white part
    /// `white²`, plus the manoeuvre part `maneuver²` inflated for its correlation `rho`
    /// between odometer epochs given the prior variance `hph` along the row
    /// ([`ekf::correlated::scalar_inflation`]; the white part is left out of the inflation's
    /// steady state, which makes it slightly conservative).
    fn violation_variance(hph: f64, white: f64, maneuver: f64, rho: f64) -> f64 {
        let r_c = maneuver * maneuver;
        white * white + r_c * ekf::correlated::scalar_inflation(hph, r_c, rho)
    }

    /// Odometer speed, then the non-holonomic constraints as a separate update, both at the
    /// odometer wheel's contact point (`vehicle.wheel_lever_arm_b_m`, [`ekf::WheelContact`]).
    ///
    /// The odometer outputs the distance over its interval, i.e. the *mean* speed over
    /// `(ts − dt, ts]` (drivers-sim `OdometerSim`: `dist/dt = (1 + s)·mean v + σ·n`), while
    /// the measurement model compares with the speed at `ts`. They differ by `a·dt/2` under an
    /// acceleration `a` (2.5 cm/s at 1 m/s² and 20 Hz — more than the 2 cm/s white noise, and
    /// systematic: a speed-up biases every sample the same way). With contiguous intervals
    /// (same spacing as the previous sample) the mean is turned into the end-point speed by
    /// adding half the speed change over the interval, taken from the navigation solution at
    /// the previous odometer epoch: exact for constant acceleration, the rest is
    /// `dt²·ȧ/12` (≈ 0.2 mm/s at 1 m/s³).
    ///
    /// The noise is the odometer's white noise `odometer_sigma_m_s` plus the car's departure
    /// from the model ([`VehicleModel::violation_sigmas_m_s`]) at this update's speed, its
    /// longitudinal acceleration (the solution's change of the wheel's forward speed since
    /// the previous odometer epoch) and its lateral acceleration (`V·ω_z`): tight on a
    /// straight road at constant speed, loose in turns and speed changes, where the sideslip,
    /// the squat and the wheel slip persist for the manoeuvre (fused with the inflation of
    /// [`ekf::correlated`] for `vehicle.maneuver_correlation_time_s`).
    ///
    /// The constraints (zero lateral and vertical velocity) are a second update with
    /// their own counters ([`Navigator::nhc_health`]): equivalent to the joint update for
    /// independent noises, and the odometer's NIS on `sextant/status` is then the speed's
    /// alone — the constraint's NIS is far below its dof whatever its σ (its innovations are
    /// below the prior's lateral-velocity spread) and would hide the speed's consistency.
    pub(super) fn fuse_odometer(&mut self, ts: GpsTime, speed: f64, tally: Tally) {
        let id = sid(SensorId::Odometer);
        self.core.last_odo = Some((ts, speed));
        if !self.config.updates.odometer {
            return;
        }
        let a = self.config.aiding;
        let vehicle = self.config.vehicle;
        // The scale factor is a filter state (initial σ `odometer_scale_sigma`), so only the
        // white part of the odometer error is measurement noise.
        let k = self.core.ekf.odo_scale;
        let wheel = self.wheel_contact();
        let wheel_vx = |nav: &NavState| wheel.body_velocity(nav).0.x;
        let prev = self.core.odo_epoch.take();
        let spacing = prev.map(|p| ts - p.t);
        let v_now = wheel_vx(&self.core.nav);
        let mut accel_long_m_s2 = 0.0;
        let mut rho = 0.0;
        let mut end_speed = speed;
        if let (Some(p), Some(d)) = (prev, spacing)
            && d > Duration::ZERO
            && d <= Duration::from_seconds(1)
        {
            let d_s = d.seconds_f64();
            accel_long_m_s2 = (v_now - p.v_x_m_s) / d_s;
            rho = ekf::correlated::lag_correlation(d_s, vehicle.maneuver_correlation_time_s);
            if p.spacing
                .is_some_and(|s| (s - d).abs() <= Duration::from_ns(1_000))
            {
                end_speed = speed + (1.0 + k) * 0.5 * (v_now - p.v_x_m_s);
            }
        }
        let sig =
            vehicle.violation_sigmas_m_s(v_now, accel_long_m_s2, v_now * self.core.w_ib_b_rad_s.z);
        self.core
            .ekf
            .propagate_covariance(&self.ell, &self.core.nav.r_e);
        let mut m = ekf::odometer_speed(&self.core.nav, &wheel, k, end_speed, a.odometer_sigma_m_s);
        let hph = ekf::h_p_ht(&self.core.ekf.p, &m.h)[(0, 0)];
        m.r[(0, 0)] += Self::violation_variance(hph, sig.white_m_s.x, sig.maneuver_m_s.x, rho);
        if self.run_update(Counter::Sensor(id), &m, tally).accepted() {
            self.mark_fused(id, ts, tally);
        }
        if self.config.updates.nonholonomic {
            let m3 = ekf::odometer_nhc(&self.core.nav, &wheel, k, end_speed, 1.0, 0.0);
            self.core
                .ekf
                .propagate_covariance(&self.ell, &self.core.nav.r_e);
            // The exact constraint holds only as far as its linear model does: the
            // second-order terms (heading error × velocity error, a degree × centimetres per
            // second after a start in motion) are added to its noise.
            let p = &self.core.ekf.p;
            let mut p_vel_att = nalgebra::SMatrix::<f64, 6, 6>::zeros();
            for (i, si) in [(0, idx::VEL), (3, idx::ATT)] {
                for (j, sj) in [(0, idx::VEL), (3, idx::ATT)] {
                    p_vel_att
                        .fixed_view_mut::<3, 3>(i, j)
                        .copy_from(&p.fixed_view::<3, 3>(si, sj));
                }
            }
            let h: nalgebra::SMatrix<f64, 2, { ekf::NX }> = m3.h.fixed_rows::<2>(1).into_owned();
            let hph = ekf::h_p_ht(p, &h);
            let floor = a.nhc_sigma_m_s * a.nhc_sigma_m_s;
            let r = nalgebra::Matrix2::from_diagonal(&nalgebra::Vector2::from_fn(|i, _| {
                floor
                    + Self::violation_variance(
                        hph[(i, i)],
                        sig.white_m_s[i + 1],
                        sig.maneuver_m_s[i + 1],
                        rho,
                    )
            }));
            let m = Measurement::<2> {
                innovation: m3.innovation.fixed_rows::<2>(1).into_owned(),
                h,
                r: r + ekf::nhc_linearisation_covariance(&self.core.nav, &p_vel_att),
            };
            let (dx, residual) =
                ekf::update_in_place(&mut self.core.ekf.p, &m, self.gates.threshold(2));
            if tally == Tally::Count {
                self.nhc.fold(Verdict {
                    nis: residual.nis,
                    dof: 2,
                    rejected: residual.rejected,
                });
            }
            if !residual.rejected {
                self.correct(&dx);
            }
        }
        self.core.odo_epoch = Some(OdometerEpoch {
            t: ts,
            spacing,
            v_x_m_s: wheel_vx(&self.core.nav),
        });
    }
}
