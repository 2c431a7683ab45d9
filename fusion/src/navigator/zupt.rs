//! Zero-velocity updates: the static detector on the IMU increments and the update schedule.

use super::*;

impl Navigator {
    pub(super) fn update_static_detector(&mut self, t: GpsTime, inc: &ImuIncrement) {
        let a = &self.config.aiding;
        let w = inc.delta_angle_rad.norm() / inc.dt_s;
        let f = inc.delta_velocity_m_s.norm() / inc.dt_s;
        let g = earth::gravity_ecef(&self.ell, self.config.gravity, &self.core.nav.r_e).norm();
        if w < a.zupt_max_rate_rad_s && (f - g).abs() < a.zupt_max_accel_dev_m_s2 {
            if self.core.static_since.is_none() {
                self.core.static_since = Some(t);
            }
        } else {
            self.core.static_since = None;
        }
    }

    pub(super) fn maybe_zupt(&mut self, t: GpsTime, tally: Tally) {
        let a = self.config.aiding;
        if !self.config.updates.zupt {
            return;
        }
        let Some(since) = self.core.static_since else {
            return;
        };
        if (t - since).seconds_f64() < a.zupt_window_s {
            return;
        }
        if let Some(last) = self.core.last_zupt
            && (t - last).seconds_f64() < a.zupt_interval_s
        {
            return;
        }
        if self.core.nav.v_e.norm() > a.zupt_max_speed_m_s {
            return;
        }
        // A recent odometer sample saying the vehicle moves vetoes the update.
        if let Some((to, v)) = self.core.last_odo
            && (t - to).seconds_f64() < 1.0
            && v.abs() > 0.02
        {
            return;
        }
        self.core.last_zupt = Some(t);
        let m = ekf::zero_velocity(&self.core.nav, a.zupt_sigma_m_s);
        self.run_update(Counter::Zupt, &m, tally);
    }
}
