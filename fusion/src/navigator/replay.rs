//! Delayed fusion at the time of validity (module docs of [`super`], "Delayed fusion"): the
//! navigating IMU step, checkpoints of the replayable state, the rewind and replay when a
//! late sample arrives, and the fusion of every queued sample whose epoch is reached.

use super::*;

impl Navigator {
    /// One navigating IMU step (live or replayed): mechanization, transition accumulation,
    /// covariance propagation at its interval, fusion of the aiding due, ZUPT, checkpoints.
    /// The same live and replayed: a queued sample carries its own tally
    /// ([`Tally::first_time`]), the ZUPT counts by its epoch ([`Self::maybe_zupt`]).
    ///
    /// What the step's solution does not need is left to [`Self::finish_deferred_step`], after
    /// the solution is formed (module docs, "Solutions"): the periodic checkpoint always, and
    /// at an epoch where nothing is fused the covariance propagation and its checkpoint too.
    pub(super) fn imu_step(&mut self, e: &ImuLogEntry) {
        self.finish_deferred_step();
        let t = e.t;
        // The increment covers dt_s; after missing samples, stretch it over the gap.
        let gap_s = e.prev_t.map_or(e.dt_s, |p| (t - p).seconds_f64());
        let (scale, dt) = if gap_s > 1.5 * e.dt_s {
            self.core.strapdown.reset_history();
            (gap_s / e.dt_s, gap_s)
        } else {
            (1.0, e.dt_s)
        };
        let (dth_c, dv_c) = self
            .core
            .ekf
            .correct_increment(&(e.dth * scale), &(e.dv * scale), dt);
        self.core.w_ib_b_rad_s = dth_c / dt;
        let inc = ImuIncrement {
            dt_s: dt,
            delta_angle_rad: dth_c,
            delta_velocity_m_s: dv_c,
        };
        self.core.strapdown.step(&mut self.core.nav, &inc);
        self.core
            .ekf
            .accumulate(&self.core.nav, &(dv_c / dt), &(dth_c / dt), dt);
        // At the fixed interval, and at the epoch where a sensor's next sample is expected: a
        // forced propagation (an update) shifts the interval's grid off a late sensor's
        // epochs, and its rewind would then propagate again ([`super::cadence`]).
        let propagate = self.core.ekf.pending_s() >= self.config.covariance_interval_s - 1e-9
            || e.prev_t
                .is_some_and(|p| self.core.cadence.iter().any(|c| c.expected_within(p, t)));
        self.time = t;
        // The static detector reads the inertial state only, the propagation writes the
        // covariance and transition only: their order does not matter.
        self.update_static_detector(t, &inc);
        let aiding_due = self.aiding_due(t);
        // Where nothing is fused at this epoch the solution is the mechanized state: the
        // propagation and its checkpoint wait until it is formed (fusion and ZUPT would be
        // no-ops).
        let nothing_fused = !aiding_due && !self.zupt_due(t);
        if !nothing_fused {
            if propagate {
                self.core
                    .ekf
                    .propagate_covariance(&self.ell, &self.core.nav.r_e);
            }
            if propagate || aiding_due {
                self.epoch_checkpoint(t, e.prev_t);
            }
            self.finish_step(t);
        }
        self.deferred_step = Some(DeferredStep {
            t,
            prev_t: e.prev_t,
            propagate: propagate && nothing_fused,
        });
    }

    /// The checkpoint of epoch `t`'s state before its updates, where the covariance was just
    /// brought to the epoch or aiding is due (and the last checkpoint is
    /// [`EPOCH_CHECKPOINT_SPACING`] old): the state a sample of this epoch arriving later meets,
    /// whatever else arrives late; it spares that sample's rewind the steps before the epoch
    /// (and, after a propagation, the propagation): a sensor late by its latency rewinds for
    /// each of its samples.
    fn epoch_checkpoint(&mut self, t: GpsTime, prev_t: Option<GpsTime>) {
        if let Some(last_t) = self
            .checkpoints
            .len
            .checked_sub(1)
            .map(|i| self.checkpoints.get(i).t)
            && t - last_t >= EPOCH_CHECKPOINT_SPACING
        {
            // Every sample fused at t is after the IMU epoch before it, and after the last
            // checkpoint (its epoch or an earlier one) when that epoch is unknown.
            self.take_checkpoint(t, prev_t.unwrap_or(last_t));
        }
    }

    /// The end of IMU epoch `t` once its mechanization is done (and its state before the
    /// updates checkpointed where aiding is due or the covariance was just propagated): fusion
    /// of the aiding due and ZUPT. The periodic checkpoint follows after the solution
    /// ([`Self::finish_deferred_step`]).
    fn finish_step(&mut self, t: GpsTime) {
        self.fuse_due(t);
        self.maybe_zupt(t);
    }

    /// The rest of the last IMU step, once its solution is formed ([`Self::catch_up`]) or at
    /// the latest before the next step or a rewind: the state has not changed since the step,
    /// so this is the work the step would have done itself, in the same order — where nothing
    /// was fused at its epoch, the covariance propagation and the checkpoint before the
    /// (absent) updates; then the periodic checkpoint, every
    /// [`CHECKPOINT_PERIOD`] of IMU time.
    fn finish_deferred_step(&mut self) {
        let Some(d) = self.deferred_step.take() else {
            return;
        };
        if d.propagate {
            self.core
                .ekf
                .propagate_covariance(&self.ell, &self.core.nav.r_e);
            self.epoch_checkpoint(d.t, d.prev_t);
        }
        let due = self.checkpoints.len == 0
            || d.t - self.checkpoints.get(self.checkpoints.len - 1).t >= CHECKPOINT_PERIOD;
        if due {
            self.take_checkpoint(d.t, d.t);
        }
    }

    /// Whether an aiding sample is queued for fusion at epoch `t` (time of validity ≤ `t`).
    fn aiding_due(&self, t: GpsTime) -> bool {
        self.gnss_q.next_due(t)
            || self.star_q.next_due(t)
            || self.odo_q.next_due(t)
            || self.baro_q.next_due(t)
    }

    /// How a sample of time of validity `ts` arrives: too late (older than the window), late
    /// (the inertial solution has passed it: held until the next IMU step's solution is
    /// formed, then fused by a rewind, [`Self::ripen_late`], [`Self::catch_up`]) or in time.
    pub(super) fn arrival(&self, ts: GpsTime) -> Arrival {
        if self.too_late(ts) {
            Arrival::TooLate
        } else if self.phase == Phase::Navigating && ts <= self.time {
            Arrival::Late
        } else {
            Arrival::InTime
        }
    }

    /// After an IMU step's solution is formed: the late samples held out of it go to their
    /// queues, their rewind due ([`Self::catch_up`], or at the start of the next push).
    pub(super) fn ripen_late(&mut self) {
        let evicted = [
            (
                SensorId::Gnss,
                ripen(&mut self.gnss_inbox, &mut self.gnss_q, &mut self.rewind_to),
            ),
            (
                SensorId::StarTracker,
                ripen(&mut self.star_inbox, &mut self.star_q, &mut self.rewind_to),
            ),
            (
                SensorId::Odometer,
                ripen(&mut self.odo_inbox, &mut self.odo_q, &mut self.rewind_to),
            ),
            (
                SensorId::Baro,
                ripen(&mut self.baro_inbox, &mut self.baro_q, &mut self.rewind_to),
            ),
        ];
        for (s, n) in evicted {
            self.health[sid(s)].dropped_late += n;
        }
    }

    /// Fuse now the late samples whose rewind is due (module docs, "Delayed fusion"): the
    /// rewind the next input would otherwise start with, the same steps and the same state.
    /// Every input begins with it, so that each meets the state the late samples made; a
    /// caller that has published the current solution and waits for the next IMU sample (the
    /// daemon) calls it then, which takes the replay of the IMU steps off the next sample's
    /// path from arrival to solution. Allocates nothing.
    pub fn catch_up(&mut self) {
        // Every input starts here: the last IMU step's solution is no longer the state's.
        self.solution_ready = false;
        self.finish_deferred_step();
        if self.phase == Phase::Navigating
            && let Some(ts) = self.rewind_to.take()
        {
            self.replay_from(ts);
        }
    }

    /// Checkpoint the core at epoch `t` ([`Checkpoint`]: the samples it can serve are those
    /// of validity after `serves_after`, `t` at the end of the epoch, earlier before its
    /// updates).
    pub(super) fn take_checkpoint(&mut self, t: GpsTime, serves_after: GpsTime) {
        // The checkpoints are cleared only when navigation starts (and a replay keeps at least
        // one), so the first one marks the start.
        if self.checkpoints.len == 0 {
            self.nav_start = Some(t);
        }
        let slot = self.checkpoints.push_slot();
        slot.t = t;
        slot.serves_after = serves_after;
        slot.core = self.core;
    }

    /// Fuse late samples at their time of validity exactly as if they had arrived in time
    /// (module docs, "Delayed fusion"): restore the latest checkpoint before `ts`, put the
    /// aiding fused since then back in the queues (flagged as already counted) and replay the
    /// logged IMU steps, which fuse every sample — the late ones included — at the epoch and
    /// with the state and covariance an in-time arrival would have met. No checkpoint is
    /// before `ts` only when `ts` is at or before the start of navigation (the first
    /// checkpoint; the ring holds more than the window): such samples belong to the alignment
    /// period and `fuse_due` discards them. When the IMU log does not reach back to the
    /// checkpoint (an IMU faster than `max_imu_rate_hz`), the replay is impossible: counted,
    /// and the late samples are dropped ([`Self::drop_unreplayable`]).
    pub(super) fn replay_from(&mut self, ts: GpsTime) {
        // `serves_after` never decreases along the ring (a checkpoint before the updates of
        // epoch t serves from the epoch before t, which no earlier checkpoint is after).
        let mut k = self.checkpoints.len;
        while k > 0 && self.checkpoints.get(k - 1).serves_after >= ts {
            k -= 1;
        }
        if k == 0 {
            return;
        }
        // Its times only: the core (≈ 10 kB) is copied once, straight into place, below.
        let (c_t, c_after, c_before_updates) = {
            let c = self.checkpoints.get(k - 1);
            (c.t, c.serves_after, c.before_updates())
        };
        // The IMU log must hold every step after the checkpoint epoch: its first entry is at
        // or before it, or is the very step after it (the log starts with navigation, right
        // after the checkpoint taken at the start).
        let covered = self.imu_log.len > 0 && {
            let first = self.imu_log.get(0);
            first.t <= c_t || first.prev_t.is_some_and(|p| p <= c_t)
        };
        if !covered {
            self.drop_unreplayable();
            return;
        }
        self.checkpoints.truncate(k);
        self.core = self.checkpoints.get(k - 1).core;
        self.time = c_t;
        self.diagnostics.rewinds += 1;
        // Everything fused after the checkpoint goes back: before the updates of epoch c_t,
        // that epoch's own samples too.
        while let Some((t, v, _)) = self.gnss_done.pop_newer(c_after) {
            self.gnss_q.insert_flagged(t, v, true);
        }
        while let Some((t, v, _)) = self.star_done.pop_newer(c_after) {
            self.star_q.insert_flagged(t, v, true);
        }
        while let Some((t, v, _)) = self.odo_done.pop_newer(c_after) {
            self.odo_q.insert_flagged(t, v, true);
        }
        while let Some((t, v, _)) = self.baro_done.pop_newer(c_after) {
            self.baro_q.insert_flagged(t, v, true);
        }
        if c_before_updates {
            self.finish_step(c_t);
            self.deferred_step = Some(DeferredStep {
                t: c_t,
                prev_t: None,
                propagate: false,
            });
        }
        // The log is in time order (IMU times only increase): the steps after the checkpoint
        // are its tail, found from the end — a few steps, where the log holds seconds.
        let mut first = self.imu_log.len;
        while first > 0 && self.imu_log.get(first - 1).t > c_t {
            first -= 1;
        }
        for i in first..self.imu_log.len {
            let e = *self.imu_log.get(i);
            self.imu_step(&e);
            self.diagnostics.replayed_imu_steps += 1;
        }
    }

    /// A rewind the IMU log cannot serve: drop the samples the solution has passed (those
    /// queued at or before the current epoch; the in-time ones stay), count them as late and
    /// the event in `replays_impossible`.
    pub(super) fn drop_unreplayable(&mut self) {
        self.drop_queued_until(self.time);
        self.diagnostics.replays_impossible += 1;
    }

    /// Drop the queued aiding with time of validity ≤ `t`, counting each sample (once) in its
    /// sensor's `dropped_late`.
    pub(super) fn drop_queued_until(&mut self, t: GpsTime) {
        let mut dropped = [0u64; MAX_SENSORS];
        while let Some((_, _, counted)) = self.gnss_q.pop_due(t) {
            dropped[sid(SensorId::Gnss)] += u64::from(!counted);
        }
        while let Some((_, _, counted)) = self.star_q.pop_due(t) {
            dropped[sid(SensorId::StarTracker)] += u64::from(!counted);
        }
        while let Some((_, _, counted)) = self.odo_q.pop_due(t) {
            dropped[sid(SensorId::Odometer)] += u64::from(!counted);
        }
        while let Some((_, _, counted)) = self.baro_q.pop_due(t) {
            dropped[sid(SensorId::Baro)] += u64::from(!counted);
        }
        for (h, d) in self.health.iter_mut().zip(dropped) {
            h.dropped_late += d;
        }
    }

    /// A sample of `sensor` valid at `ts` is being fused: where its next one is expected, for
    /// a sensor with a time-tag latency, whose samples arrive after their epoch
    /// ([`super::cadence`]; one stamped at its epoch arrives in time and needs no forecast).
    fn note_cadence(&mut self, sensor: SensorId, ts: GpsTime) {
        if self.config.latency.of(sensor) > Duration::ZERO {
            self.core.cadence[sid(sensor)].observe(ts);
        }
    }

    /// Fuse every queued sample with time of validity ≤ `t` (the current epoch) and keep it
    /// for a possible replay.
    pub(super) fn fuse_due(&mut self, t: GpsTime) {
        while let Some((ts, obs, counted)) = self.gnss_q.pop_due(t) {
            // Alignment discards the aiding of its own period when it arrives in time
            // (`consume_during_alignment`); arriving after the start, it is discarded too.
            if self.nav_start.is_some_and(|start| ts <= start) {
                continue;
            }
            self.note_cadence(SensorId::Gnss, ts);
            self.fuse_gnss(ts, &obs, Tally::first_time(counted));
            self.gnss_done.insert_flagged(ts, obs, true);
        }
        while let Some((ts, obs, counted)) = self.star_q.pop_due(t) {
            if self.nav_start.is_some_and(|start| ts <= start) {
                continue;
            }
            self.note_cadence(SensorId::StarTracker, ts);
            self.fuse_star(ts, &obs, Tally::first_time(counted));
            self.star_done.insert_flagged(ts, obs, true);
        }
        while let Some((ts, speed, counted)) = self.odo_q.pop_due(t) {
            if self.nav_start.is_some_and(|start| ts <= start) {
                continue;
            }
            self.note_cadence(SensorId::Odometer, ts);
            self.fuse_odometer(ts, speed, Tally::first_time(counted));
            self.odo_done.insert_flagged(ts, speed, true);
        }
        while let Some((ts, h, counted)) = self.baro_q.pop_due(t) {
            if self.nav_start.is_some_and(|start| ts <= start) {
                continue;
            }
            self.note_cadence(SensorId::Baro, ts);
            self.fuse_baro(ts, h, Tally::first_time(counted));
            self.baro_done.insert_flagged(ts, h, true);
        }
    }
}
