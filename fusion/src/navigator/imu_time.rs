//! IMU time continuity: normal steps, bridged gaps (the stretched increment and the
//! covariance of the unknown motion over the gap) and confirmed discontinuities, after which
//! the navigator starts over with alignment.

use super::*;

/// IMU samples that continued consistently from a time discontinuity (a jump of the time of
/// validity by more than [`MAX_BRIDGED_GAP`] forward, or any step backward) and were held.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct ImuTimeJump {
    /// Time of validity of the latest sample on the new time base.
    pub(super) last_t: GpsTime,
    /// Consecutive samples on the new time base so far.
    pub(super) count: u32,
}

/// Longest IMU gap bridged by one stretched increment (1 s).
///
/// Policy for a gap `g` between consecutive IMU samples (nominal interval `dt`):
/// - `g ≤ 1.5·dt`: a normal step.
/// - `1.5·dt < g ≤ 1 s` (a few lost samples, a transport hiccup): bridged. The sample after the
///   gap is stretched over it (`imu_step`), i.e. its rate and specific force are assumed
///   constant over the gap. The unknown motion during the gap is added to the covariance
///   (`bridge_imu_gap`), aiding samples whose epoch fell inside the gap are dropped (counted as
///   late: the inertial solution never passed through their epoch).
/// - `g > 1 s`, or time going backward: a time discontinuity. A single wild time stamp (a
///   corrupt header) is rejected and navigation goes on with the next sample on the old time
///   base. Only when [`CONFIRM_SAMPLES`] consecutive samples continue consistently from the
///   new time (each within 1 s of the previous) is it a real gap, and the navigator starts over
///   with alignment (`reinitialize`): after more than a second without inertial data, the
///   attitude of a moving vehicle is unknown beyond the small-angle error model (a turn of
///   0.1 rad/s for 10 s is a radian), and the first-order covariance transition over one
///   stretched step no longer holds; a static vehicle re-aligns in `alignment_s`.
///
/// 1 s also bounds the unknown-motion term: with `|Δf| ≤ 10 m/s²` between the samples around
/// the gap, the added velocity σ is ≤ 10·1/√3 ≈ 6 m/s — large, but the filter stays linear
/// and the next GNSS epoch pulls it back; beyond that the inflation, not the data, would
/// carry the solution.
pub(super) const MAX_BRIDGED_GAP: Duration = Duration::from_seconds(1);

/// Consecutive IMU samples on a new time base that confirm a real gap (0.1 s at 200 Hz). A
/// corrupt time stamp is one sample (or a burst of unrelated ones); twenty samples, each
/// within 1 s of the previous and increasing, are a sensor that really continues there.
/// The first `CONFIRM_SAMPLES − 1` of them are held and counted in `rejected_invalid`
/// (navigation rejected them); the last one starts the new alignment.
pub const CONFIRM_SAMPLES: u32 = 20;

impl Navigator {
    /// IMU time continuity (policy: [`MAX_BRIDGED_GAP`]). Ok for a normal step, a
    /// bridgeable gap, and the sample that confirms a time discontinuity (the navigator has
    /// then been re-initialised and this sample starts the new alignment). Err for a sample
    /// that steps backward or jumps more than 1 s ahead: it is held as a candidate new time
    /// base (only `imu_time_jump` changes, never the solution).
    pub(super) fn check_imu_time(&mut self, h: &Header) -> Result<(), Rejection> {
        let id = sid(SensorId::Imu);
        let Some(prev) = self.last_time[id] else {
            return Ok(());
        };
        let t = GpsTime::from_ns(h.time_ns);
        let step = t.saturating_since(prev);
        if step > Duration::ZERO && step <= MAX_BRIDGED_GAP {
            // Back on the old time base: a held candidate was a wild time stamp.
            self.imu_time_jump = None;
            return Ok(());
        }
        let jump = match self.imu_time_jump {
            Some(j)
                if (Duration::from_ns(1)..=MAX_BRIDGED_GAP)
                    .contains(&t.saturating_since(j.last_t)) =>
            {
                ImuTimeJump {
                    last_t: t,
                    count: j.count + 1,
                }
            }
            _ => ImuTimeJump {
                last_t: t,
                count: 1,
            },
        };
        if jump.count >= CONFIRM_SAMPLES {
            self.reinitialize();
            return Ok(());
        }
        self.imu_time_jump = Some(jump);
        let reason = if step <= Duration::ZERO {
            RejectReason::TimeNotIncreasing { previous: prev }
        } else {
            self.diagnostics.imu_held_at_time_jump += 1;
            RejectReason::ImuTimeJumpHeld
        };
        Err(Rejection::new(SensorId::Imu, t, reason))
    }

    /// Start over with alignment after a confirmed IMU time discontinuity. Kept: what
    /// describes the navigator's life rather than its solution — the health counters, the
    /// diagnostics (counting this re-initialisation), the ZUPT counters, the solution count,
    /// the aiding sequence numbers, and the redundant-channel FDI (an excluded channel is
    /// broken hardware, whatever the time base). New: the filter, the alignment, the delayed-
    /// fusion queues, log and checkpoints, the clock state and every time reference; the
    /// sensor-error estimates are held as a snapshot for the alignment in motion
    /// (`warm_start`).
    pub(super) fn reinitialize(&mut self) {
        // The configuration was validated when this navigator was built: `new` cannot fail.
        let Ok(mut fresh) = Navigator::new(self.config.clone()) else {
            return;
        };
        fresh.health = self.health;
        fresh.diagnostics = self.diagnostics;
        fresh.diagnostics.reinitializations += 1;
        fresh.zupt = self.zupt;
        fresh.nhc = self.nhc;
        fresh.solutions = self.solutions;
        fresh.last_seq = self.last_seq;
        // The held samples were received, not lost: no sequence gap for the IMU.
        fresh.last_seq[sid(SensorId::Imu)] = None;
        fresh.redundancy = self.redundancy.take();
        // The receiver keeps tracking through an IMU gap: its integers stay valid.
        fresh.ambiguity = self.ambiguity.take();
        fresh.redundancy_config = self.redundancy_config;
        // The sensor-error estimates survive the gap (calibration memory): resumed when the
        // new alignment is one in motion and the gap is within `warm_start.max_age_s`.
        fresh.warm = self.snapshot();
        fresh.warm_outcome = self.warm_outcome;
        fresh.calibration = self.calibration.take();
        *self = fresh;
    }

    /// Bridge an IMU gap `(p, e.t]` shorter than [`MAX_BRIDGED_GAP`]: drop the aiding
    /// whose epoch fell inside it, and add the unknown motion over it to the covariance.
    ///
    /// `imu_step` stretches the sample after the gap over the gap, i.e. uses its rate ω₁ and
    /// specific force f₁ throughout. The truth went from the previous sample's (ω₀, f₀) to
    /// (ω₁, f₁); if in between, the stretched integrals are off by a fraction u ∈ [0, 1] of
    /// Δ = x₁ − x₀ over the gap g: velocity u·C_e_b·Δf·g, position u·C_e_b·Δf·g²/2, attitude
    /// (ψ, ECEF) u·C_e_b·Δω·g, all with the same u. With u uniform, E[u²] = 1/3: the rank-one
    /// second moment `e eᵀ/3`, `e = (C Δf g²/2, C Δf g, C Δω g)`, is added to the position,
    /// velocity and attitude block (the second moment rather than the variance, so that it
    /// also covers the mean error u = 1/2).
    ///
    /// Stretching also scales the sample's own white noise by g/dt: its velocity increment
    /// error becomes `VRW·√dt·g/dt`, variance `VRW²·g²/dt`, where white noise over the gap
    /// would have given `VRW²·g` (which the stretched step's process noise already adds). The
    /// difference `VRW²·(g²/dt − g)` goes on the velocity, with the position it integrates
    /// into over the gap (`δr = δv·g/2`: variance ×(g/2)², covariance ×g/2), and
    /// `ARW²·(g²/dt − g)` on the attitude. For 0.5 s at 200 Hz: 1.4 mm/s per axis at
    /// 20 µg/√Hz, ten times the white-noise value.
    ///
    /// Not re-applied if a late sample older than the gap makes the filter replay across it.
    pub(super) fn bridge_imu_gap(&mut self, p: GpsTime, e: &ImuLogEntry) {
        // Aiding more than one IMU interval inside the gap: its epoch was never navigated.
        let inside = e.t - Duration::from_seconds_f64(e.dt_s) - Duration::from_ns(1);
        self.drop_queued_until(inside);
        if self.imu_log.len == 0 {
            return; // first step after alignment: nothing to compare with
        }
        let prev = *self.imu_log.get(self.imu_log.len - 1);
        if prev.t != p || prev.dt_s <= 0.0 {
            return;
        }
        let g = (e.t - p).seconds_f64();
        let c_e_b = self.core.nav.q_e_b.to_rotation_matrix().into_inner();
        let df = c_e_b * (e.dv / e.dt_s - prev.dv / prev.dt_s);
        let dw = c_e_b * (e.dth / e.dt_s - prev.dth / prev.dt_s);
        let mut v = nalgebra::SVector::<f64, 9>::zeros();
        v.fixed_rows_mut::<3>(idx::POS)
            .copy_from(&(df * (0.5 * g * g)));
        v.fixed_rows_mut::<3>(idx::VEL).copy_from(&(df * g));
        v.fixed_rows_mut::<3>(idx::ATT).copy_from(&(dw * g));
        let mut add = v * v.transpose() / 3.0;
        let amp = (g * g / e.dt_s - g).max(0.0);
        let sv2 = self.core.ekf.noise.vrw_m_s_sqrt_s.powi(2) * amp;
        let sa2 = self.core.ekf.noise.arw_rad_sqrt_s.powi(2) * amp;
        for k in 0..3 {
            let (p, v, a) = (idx::POS + k, idx::VEL + k, idx::ATT + k);
            add[(v, v)] += sv2;
            add[(p, p)] += sv2 * 0.25 * g * g;
            add[(p, v)] += sv2 * 0.5 * g;
            add[(v, p)] += sv2 * 0.5 * g;
            add[(a, a)] += sa2;
        }
        let mut blk = self.core.ekf.p.fixed_view_mut::<9, 9>(idx::POS, idx::POS);
        blk += add;
    }
}
