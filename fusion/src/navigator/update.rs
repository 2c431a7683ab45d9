//! One gated measurement update ([`crate::ekf::update`]) and the health counters folded from
//! its outcome.

use super::*;

impl Navigator {
    /// Apply an accepted correction to the current state and the error estimates.
    pub(super) fn correct(&mut self, dx: &StateVector) {
        self.core.ekf.apply_correction(&mut self.core.nav, dx);
    }

    /// Run one gated update at the current epoch and fold its outcome into `counter`'s health
    /// counters when `tally` says so; returns the outcome.
    pub(super) fn run_update<const M: usize>(
        &mut self,
        counter: Counter,
        m: &Measurement<M>,
        tally: Tally,
    ) -> Verdict {
        // The covariance must be at the current time before any update.
        self.core
            .ekf
            .propagate_covariance(&self.ell, &self.core.nav.r_e);
        let (dx, residual) = ekf::update_in_place(&mut self.core.ekf.p, m, self.gates.threshold(M));
        let v = Verdict {
            nis: residual.nis,
            dof: M as u64,
            rejected: residual.rejected,
        };
        if tally == Tally::Count {
            match counter {
                Counter::Sensor(id) => fold_sensor(&mut self.health[id], v),
                Counter::Zupt => self.zupt.fold(v),
            }
        }
        if v.accepted() {
            self.correct(&dx);
        }
        v
    }

    /// Note that sample `ts` of sensor `id` was fused (for the mode), counting it once.
    pub(super) fn mark_fused(&mut self, id: usize, ts: GpsTime, tally: Tally) {
        // A sample with several updates (baseline attitude + fix) counts once; sample times
        // strictly increase per sensor.
        if tally == Tally::Count && self.last_fused[id] != Some(ts) {
            self.health[id].fused += 1;
        }
        self.last_fused[id] = Some(self.last_fused[id].map_or(ts, |p| p.max(ts)));
    }
}
