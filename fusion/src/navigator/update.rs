//! One gated measurement update ([`crate::ekf::update`]) and the health counters folded from
//! its outcome.

use super::*;

impl Navigator {
    /// Apply an accepted correction to the current state and the error estimates.
    pub(super) fn correct(&mut self, dx: &StateVector) {
        self.core.ekf.apply_correction(&mut self.core.nav, dx);
    }

    /// Run one gated update (health counters of sensor `id`, or the ZUPT counters for None);
    /// returns whether it was accepted.
    pub(super) fn run_update<const M: usize>(
        &mut self,
        id: Option<usize>,
        m: &Measurement<M>,
    ) -> bool {
        // The covariance must be at the current time before any update.
        self.core
            .ekf
            .propagate_covariance(&self.ell, &self.core.nav.r_e);
        let out = ekf::update(&self.core.ekf.p, m, self.gates.threshold(M));
        if !self.count_health || (id.is_none() && self.replaying) {
            // Re-fused during a replay: counted the first time.
        } else if let Some(id) = id {
            self.health[id].last_nis = out.residual.nis;
            if out.residual.rejected {
                self.health[id].rejected_gate += 1;
            } else {
                // Mean NIS over accepted updates (nis_sum / nis_count) should be ≈ the mean
                // dimension (nis_dof_sum / nis_count) for a consistent filter.
                self.health[id].nis_sum += out.residual.nis;
                self.health[id].nis_count += 1;
                self.health[id].nis_dof_sum += M as u64;
            }
        } else {
            self.zupt.last_nis = out.residual.nis;
            if out.residual.rejected {
                self.zupt.rejected_gate += 1;
            } else {
                self.zupt.fused += 1;
            }
        }
        if out.residual.rejected {
            return false;
        }
        self.core.ekf.p = out.p;
        self.correct(&out.dx);
        true
    }

    pub(super) fn mark_fused(&mut self, id: usize, ts: i64) {
        // A sample with several updates (baseline attitude + fix) counts once; sample times
        // strictly increase per sensor.
        if self.count_health && self.last_fused_ns[id] != Some(ts) {
            self.health[id].fused += 1;
        }
        self.last_fused_ns[id] = Some(self.last_fused_ns[id].map_or(ts, |p| p.max(ts)));
    }
}
