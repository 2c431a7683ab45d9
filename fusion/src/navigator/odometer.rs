//! Odometer speed with the interval-mean correction, and the non-holonomic constraints.

use super::*;

/// Odometer epoch kept for the next sample's interval-mean correction (`fuse_odometer`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct OdometerEpoch {
    /// Time of validity.
    pub(super) t: GpsTime,
    /// Spacing from the epoch before.
    pub(super) spacing: Option<Duration>,
    /// Body-x speed of the solution after the update, m/s.
    pub(super) v_x_m_s: f64,
}

impl Navigator {
    /// Odometer speed, then the non-holonomic constraints as a separate update.
    ///
    /// The odometer outputs the distance over its interval, i.e. the *mean* body-x speed over
    /// `(ts − dt, ts]` (drivers-sim `OdometerSim`: `dist/dt = (1 + s)·mean v_x + σ·n`), while
    /// the measurement model compares with the speed at `ts`. They differ by `a·dt/2` under an
    /// acceleration `a` (2.5 cm/s at 1 m/s² and 20 Hz — more than the 2 cm/s white noise, and
    /// systematic: a speed-up biases every sample the same way). With contiguous intervals
    /// (same spacing as the previous sample) the mean is turned into the end-point speed by
    /// adding half the speed change over the interval, taken from the navigation solution at
    /// the previous odometer epoch: exact for constant acceleration, the rest is
    /// `dt²·ȧ/12` (≈ 0.2 mm/s at 1 m/s³). So `odometer_sigma_m_s` is the odometer's white
    /// noise alone.
    ///
    /// The constraints (zero lateral and vertical body velocity) are a second update with
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
        // The scale factor is a filter state (initial σ `odometer_scale_sigma`), so only the
        // white part of the odometer error is measurement noise.
        let k = self.core.ekf.odo_scale;
        let body_vx = |nav: &NavState| (nav.q_e_b.inverse() * nav.v_e).x;
        let prev = self.odo_epoch.take();
        let spacing = prev.map(|p| ts - p.t);
        let end_speed = match (prev, spacing) {
            (Some(p), Some(d))
                if d > Duration::ZERO
                    && d <= Duration::from_seconds(1)
                    && p.spacing
                        .is_some_and(|s| (s - d).abs() <= Duration::from_ns(1_000)) =>
            {
                speed + (1.0 + k) * 0.5 * (body_vx(&self.core.nav) - p.v_x_m_s)
            }
            _ => speed,
        };
        let m = ekf::odometer_speed(&self.core.nav, k, end_speed, a.odometer_sigma_m_s);
        if self.run_update(Counter::Sensor(id), &m, tally).accepted() {
            self.mark_fused(id, ts, tally);
        }
        if self.config.updates.nonholonomic {
            let m3 = ekf::odometer_nhc(&self.core.nav, k, end_speed, 1.0, a.nhc_sigma_m_s);
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
            let m = Measurement::<2> {
                innovation: m3.innovation.fixed_rows::<2>(1).into_owned(),
                h: m3.h.fixed_rows::<2>(1).into_owned(),
                r: m3.r.fixed_view::<2, 2>(1, 1).into_owned()
                    + ekf::nhc_linearisation_covariance(&self.core.nav, &p_vel_att),
            };
            let out = ekf::update(&self.core.ekf.p, &m, self.gates.threshold(2));
            if tally == Tally::Count {
                self.nhc.fold(Verdict {
                    nis: out.residual.nis,
                    dof: 2,
                    rejected: out.residual.rejected,
                });
            }
            if !out.residual.rejected {
                self.core.ekf.p = out.p;
                self.correct(&out.dx);
            }
        }
        self.odo_epoch = Some(OdometerEpoch {
            t: ts,
            spacing,
            v_x_m_s: body_vx(&self.core.nav),
        });
    }
}
