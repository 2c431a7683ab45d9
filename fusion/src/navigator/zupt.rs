//! Zero-velocity updates: the static detector on the IMU increments and the update schedule.
//!
//! # The static test on block means
//! A stopped car's IMU is not still: its engine shakes the mount (engine orders from ≈ 35 Hz at
//! idle, broadband road and body noise above ≈ 20 Hz) with accelerations of tenths of m/s²,
//! so one 5 ms sample's specific force is off gravity by far more than any threshold that
//! would still see a vehicle start to move. That vibration is a displacement of the mount of
//! micrometres about a fixed point: its velocity stays below ≈ 1 mm/s (an acceleration
//! amplitude `A` at frequency `f` is a velocity `A/(2πf)`: 0.4 m/s² at 70 Hz is 0.9 mm/s), so
//! the mean specific force over a block of length `T` — the velocity change over the block
//! divided by `T` — is off by at most `2·v/T`, < 0.02 m/s² for `T` = 0.1 s. The test is
//! therefore made on the IMU increments summed over blocks of `aiding.zupt_interval_s` (the
//! update interval): the mean angular rate below `zupt_max_rate_rad_s`, and the mean specific
//! force, turned to ECEF with the solution's attitude, within `zupt_max_accel_dev_m_s2` of
//! `−g` as a vector. Its magnitude alone would not do: a car braking at 1 m/s² feels
//! `√(g² + 1) − g` = 0.05 m/s² more than gravity, at the threshold, while its specific force
//! leans 6° from the vertical (an attitude known to a milliradian puts 0.01 m/s² of gravity
//! into the horizontal). A vehicle is static from the start of the first block of an unbroken
//! run of static blocks, and updates start once that run is `zupt_window_s` long. What a block
//! mean cannot see (constant-velocity motion) is vetoed by the estimated speed and the
//! odometer.

use super::*;

/// The IMU increments of the static detector's current block (bias-corrected, body axes).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct StaticBlock {
    /// Start of the block (the start of its first increment).
    start: Option<GpsTime>,
    /// Sum of the angle increments, rad.
    dth_b_rad: Vector3<f64>,
    /// Sum of the velocity increments, m/s.
    dv_b_m_s: Vector3<f64>,
    /// Length of the block so far, s.
    dt_s: f64,
}

impl Navigator {
    /// Add the increment `inc` ending at `t` to the current block; at the block's end, test it
    /// (module docs) and start or break the static period.
    pub(super) fn update_static_detector(&mut self, t: GpsTime, inc: &ImuIncrement) {
        let a = &self.config.aiding;
        let b = &mut self.core.static_block;
        if b.start.is_none() {
            b.start = Some(t - Duration::from_seconds_f64(inc.dt_s));
        }
        b.dth_b_rad += inc.delta_angle_rad;
        b.dv_b_m_s += inc.delta_velocity_m_s;
        b.dt_s += inc.dt_s;
        if b.dt_s < a.zupt_interval_s - 1e-9 {
            return;
        }
        let block = std::mem::take(b);
        let w = block.dth_b_rad.norm() / block.dt_s;
        let f_e = self.core.nav.q_e_b * (block.dv_b_m_s / block.dt_s);
        let g_e = earth::gravity_ecef(&self.ell, self.config.gravity, &self.core.nav.r_e);
        if w < a.zupt_max_rate_rad_s && (f_e + g_e).norm() < a.zupt_max_accel_dev_m_s2 {
            if self.core.static_since.is_none() {
                self.core.static_since = block.start;
            }
        } else {
            self.core.static_since = None;
        }
    }

    /// Whether a zero-velocity update is due at `t` (static long enough, its interval since
    /// the last one, slow, no odometer saying the vehicle moves).
    pub(super) fn zupt_due(&self, t: GpsTime) -> bool {
        let a = self.config.aiding;
        if !self.config.updates.zupt {
            return false;
        }
        let Some(since) = self.core.static_since else {
            return false;
        };
        if (t - since).seconds_f64() < a.zupt_window_s {
            return false;
        }
        if let Some(last) = self.core.last_zupt
            && (t - last).seconds_f64() < a.zupt_interval_s
        {
            return false;
        }
        if self.core.nav.v_e.norm() > a.zupt_max_speed_m_s {
            return false;
        }
        // A recent odometer sample saying the vehicle moves vetoes the update.
        if let Some((to, v)) = self.core.last_odo
            && (t - to).seconds_f64() < 1.0
            && v.abs() > 0.02
        {
            return false;
        }
        true
    }

    /// The zero-velocity update due at `t`, if any. Counted in the health once per epoch as
    /// time advances (`zupt_counted_until`), whether it is fused live or first in a replay:
    /// a late aiding sample (an odometer's latency) rewinds the filter, and the replayed
    /// static detector, fed the corrected biases, may schedule its updates at other epochs
    /// than the live run did.
    pub(super) fn maybe_zupt(&mut self, t: GpsTime) {
        if !self.zupt_due(t) {
            return;
        }
        self.core.last_zupt = Some(t);
        let tally = if self.zupt_counted_until.is_some_and(|c| t <= c) {
            Tally::Skip
        } else {
            self.zupt_counted_until = Some(t);
            Tally::Count
        };
        let m = ekf::zero_velocity(&self.core.nav, self.config.aiding.zupt_sigma_m_s);
        self.run_update(Counter::Zupt, &m, tally);
    }
}
