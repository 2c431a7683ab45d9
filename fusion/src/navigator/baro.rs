//! Barometric height updates (ISA height against the ellipsoidal height plus the baro bias
//! state).
//!
//! Bias acquisition: when the gate has refused `aiding.baro_reacquire_after` samples in a
//! row, the bias state's old estimate is given up: its covariance row and column are cleared
//! and its variance set to cover the innovation, `max(σ_b0², (2ν)²)`, so that the next sample
//! is fused and moves the bias by (almost) the whole innovation while the other states move by
//! their share of it. What the bias then knows is the height's uncertainty plus the baro's
//! noise, as after any first fix of an unknown offset. Why: the bias is the day's weather
//! (≈ 8.5 m per hPa off the standard atmosphere, drifting ≈ 1 hPa/h), not an instrument
//! constant a prior can bound.
//!
//! The day's air also scales heights: the standard atmosphere inverted on a day `ΔT` off its
//! temperature reads a height change `Δh` as `Δh (1 + ΔT/T)` (hypsometric equation, the
//! layer's mean temperature). The bias state is a constant offset, so the part of this error
//! that grows with the height driven since the bias was acquired is added to the sample's
//! noise: `σ² = σ_w² + (k (h − h_anchor))²`, `k` = `aiding.baro_scale_sigma`. The anchor
//! stays where the bias was acquired although the other aiding keeps refining the bias, which
//! makes the term conservative on long climbs; the day's tendency is the bias's random walk.

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
        let aid = &self.config.aiding;
        let anchor = *self.core.baro_anchor_height_m.get_or_insert(height_m);
        let scale_m = aid.baro_scale_sigma * (height_m - anchor);
        let m = ekf::baro_height(
            &self.core.nav,
            &self.ell,
            height_m,
            self.core.ekf.baro_bias_m,
            aid.baro_sigma_m.hypot(scale_m),
        );
        self.core.last_baro_fused = Some(ts);
        let after = aid.baro_reacquire_after;
        if after > 0 && self.core.baro_rejected_in_row >= after {
            self.reacquire_baro_bias(m.innovation[0], tally);
            self.core.baro_anchor_height_m = Some(height_m);
        }
        let v = self.run_update(Counter::Sensor(id), &m, tally);
        if v.accepted() {
            self.core.baro_rejected_in_row = 0;
            self.mark_fused(id, ts, tally);
        } else if v.rejected {
            self.core.baro_rejected_in_row += 1;
        }
    }

    /// Give up the baro bias estimate (module docs): its covariance row and column cleared,
    /// its variance set to cover `innovation_m`.
    fn reacquire_baro_bias(&mut self, innovation_m: f64, tally: Tally) {
        let e = &mut self.core.ekf;
        // At the current time first, so no pending transition re-couples the old estimate.
        e.propagate_covariance(&self.ell, &self.core.nav.r_e);
        let b = ekf::idx::BARO;
        let sigma0 = self.config.aiding.baro_bias_sigma_m;
        let var = sigma0.powi(2).max((2.0 * innovation_m).powi(2));
        e.p.row_mut(b).fill(0.0);
        e.p.column_mut(b).fill(0.0);
        e.p[(b, b)] = var;
        self.core.baro_rejected_in_row = 0;
        if tally == Tally::Count {
            self.diagnostics.baro_bias_reacquisitions += 1;
        }
    }
}
