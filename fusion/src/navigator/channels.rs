//! Redundant IMU channels (paper 004, [`crate::redundancy`]): least-squares combination with
//! parity-space fault detection and exclusion.

use super::*;

impl Navigator {
    /// Body increments of an IMU sample: with `n_channels` ≥ 3 finite channels, their
    /// least-squares combination after parity-space fault detection and exclusion; otherwise
    /// (or if the channels are unusable) the sample's triad. Allocates nothing.
    pub(super) fn imu_increments(&mut self, s: &ImuSample) -> (Vector3<f64>, Vector3<f64>) {
        let triad = (
            Vector3::from(s.delta_angle_rad),
            Vector3::from(s.delta_velocity_m_s),
        );
        let n = s.n_channels as usize;
        if !(3..=MAX_IMU_CHANNELS).contains(&n) {
            return triad;
        }
        let (g, a, axes) = (
            &s.channel_delta_angle_rad[..n],
            &s.channel_delta_velocity_m_s[..n],
            &s.channel_axis[..n],
        );
        if !(g.iter().chain(a).all(|x| x.is_finite())) {
            return triad;
        }
        if !self
            .redundancy
            .as_ref()
            .is_some_and(|r| r.same_layout(axes))
        {
            // From `[redundancy]` with the white noise of `[imu]` and the quantisation of
            // the channels over this sample interval, unless set_redundancy_config was called.
            let cfg = self.redundancy_config.unwrap_or_else(|| {
                let noise = self.config.imu.process_noise();
                self.config.redundancy.fdi_config(
                    noise.arw_rad_sqrt_s,
                    noise.vrw_m_s_sqrt_s,
                    s.dt_s,
                )
            });
            self.redundancy = crate::redundancy::RedundantImu::new(axes, cfg).ok();
        }
        match self.redundancy.as_mut() {
            Some(r) => r.step(g, a),
            None => triad,
        }
    }

    /// Set the fault-detection settings of the redundant channels (before the first sample
    /// with channels; a later call takes effect at the next layout change).
    pub fn set_redundancy_config(&mut self, cfg: crate::redundancy::FdiConfig) {
        self.redundancy_config = Some(cfg);
    }

    /// Health of the redundant channels (excluded / suspect masks, faults detected) for
    /// `sextant/status`; None when the IMU has no channels.
    pub fn redundancy_status(&self) -> Option<crate::redundancy::RedundancyStatus> {
        self.redundancy.as_ref().map(|r| r.status())
    }
}
