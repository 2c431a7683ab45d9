//! Barometric height updates (ISA height against the ellipsoidal height plus the baro bias
//! state).

use super::*;

impl Navigator {
    pub(super) fn fuse_baro(&mut self, ts: GpsTime, height_m: f64, tally: Tally) {
        let id = sid(SensorId::Baro);
        if !self.config.updates.baro {
            return;
        }
        let min_dt = Duration::from_seconds_f64(self.config.aiding.baro_min_interval_s);
        if let Some(last) = self.core.last_baro_fused
            && ts - last < min_dt
        {
            return;
        }
        let m = ekf::baro_height(
            &self.core.nav,
            &self.ell,
            height_m,
            self.core.ekf.baro_bias_m,
            self.config.aiding.baro_sigma_m,
        );
        self.core.last_baro_fused = Some(ts);
        if self.run_update(Counter::Sensor(id), &m, tally).accepted() {
            self.mark_fused(id, ts, tally);
        }
    }
}
