//! Star-tracker attitude updates (paper 000, [`crate::ekf::star_attitude`]) and the cached
//! celestial transformation they need.
//!
//! A star tracker's error is not all white: its head bends with temperature and its
//! field-of-view errors follow the stars in view, a few arcseconds that stay for minutes to
//! hours. Fused as white, 5 samples a second would average the attitude far below them. The
//! sample's reported σ is taken as its white part and the class's low-frequency error
//! (`aiding.star_low_frequency_sigma_arcsec`, first-order Gauss–Markov with
//! `aiding.star_low_frequency_correlation_time_s`) is added with the consistent inflation of
//! [`crate::ekf::correlated`] for its correlation since the last fused sample.

use super::*;

/// GCRS → ITRS for the star tracker with the expensive part cached.
///
/// `C_e_i = W(x_p, y_p, s') · R3(ERA) · C_cirs_gcrs` ([`crate::celestial::c_e_i`], IAU
/// 2006/2000A, ~1 400 sin/cos pairs). Only `C_cirs_gcrs` (precession–nutation) is cached; it
/// is recomputed when the sample is more than [`CelestialCache::REFRESH`] from the cached
/// epoch. Its largest rates are precession, 50.3″/yr ≈ 1.6·10⁻⁶ ″/s, and the short-period
/// nutation terms (e.g. 0.23″ at 13.66 d: 2π·0.23″/13.66 d ≈ 1.2·10⁻⁶ ″/s), so over 60 s the
/// cached matrix is off by < 0.2 mas — four orders below star-tracker noise (arcseconds). The
/// Earth rotation angle and polar motion are evaluated exactly at every call.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct CelestialCache {
    /// Epoch of the cached precession–nutation matrix.
    pub(super) epoch: Option<GpsTime>,
    pub(super) c_cirs_gcrs: Matrix3<f64>,
}

impl CelestialCache {
    /// Largest distance between a sample and the cached precession–nutation epoch.
    const REFRESH: Duration = Duration::from_seconds(60);

    pub(super) fn c_e_i(&mut self, t: GpsTime, eop: &EarthOrientation) -> Matrix3<f64> {
        use crate::celestial::{NutationModel, c_cirs_gcrs, era, polar_motion_matrix};
        if self.epoch.is_none_or(|e| (t - e).abs() > Self::REFRESH) {
            self.c_cirs_gcrs = c_cirs_gcrs(t, NutationModel::Iau2000A);
            self.epoch = Some(t);
        }
        let (s, c) = era(t, eop.dut1_s).sin_cos();
        let r3 = Matrix3::new(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0);
        let sp = crate::celestial::tio_locator_sp00(t.tt_centuries());
        polar_motion_matrix(eop.xp_rad, eop.yp_rad, sp) * r3 * self.c_cirs_gcrs
    }
}

impl Navigator {
    /// Prior covariance of the boresight angles κ1..κ3 (rad²): `aiding.boresight_sigma_deg`
    /// about every axis when the boresight group is switched on (an uncalibrated mount), plus
    /// the class's constant error about the optical axis (`aiding.star_roll_bias_sigma_arcsec`).
    /// As a rotation in body axes that is `P_b = C_b_s · diag(σ², σ², σ² + σ_roll²) · C_s_b`
    /// (the sensor's z axis is its boresight); the angles are Euler angles whose small
    /// rotation is `B·δκ` ([`ekf::kappa_jacobian`] at κ = 0, a permutation: κ1 about body z),
    /// so `P_κ = Bᵀ P_b B`.
    pub(super) fn boresight_prior_covariance(&self) -> Matrix3<f64> {
        let a = &self.config.aiding;
        let mount = if self.config.states.boresight {
            (a.boresight_sigma_deg * DEG).powi(2)
        } else {
            0.0
        };
        let roll = (a.star_roll_bias_sigma_arcsec / 3600.0 * DEG).powi(2);
        let d = Matrix3::from_diagonal(&Vector3::new(mount, mount, mount + roll));
        let p_b = self.c_s_b.transpose() * d * self.c_s_b;
        let b = ekf::kappa_jacobian(&Vector3::zeros());
        b.transpose() * p_b * b
    }

    pub(super) fn fuse_star(&mut self, ts: GpsTime, obs: &StarObs, tally: Tally) {
        let id = sid(SensorId::StarTracker);
        if !self.config.updates.star_tracker {
            return;
        }
        let c_e_i = self.celestial.c_e_i(ts, &self.config.eop);
        let q = quat_from_wire(&obs.q);
        let mut m = ekf::star_attitude(
            &self.core.nav,
            &q,
            &crate::frames::Rotation::from_dcm_unchecked(c_e_i),
            &crate::frames::Rotation::from_dcm_unchecked(self.c_s_b),
            &self.core.ekf.kappa_rad,
            obs.sigma_cross,
            obs.sigma_roll,
        );
        let aid = &self.config.aiding;
        let sigma_lf_rad = (aid.star_low_frequency_sigma_arcsec / 3600.0).to_radians();
        if sigma_lf_rad > 0.0 {
            let rho = match self.core.last_star_fused {
                Some(prev) if ts > prev => ekf::correlated::lag_correlation(
                    (ts - prev).seconds_f64(),
                    aid.star_low_frequency_correlation_time_s,
                ),
                _ => 0.0,
            };
            self.core
                .ekf
                .propagate_covariance(&self.ell, &self.core.nav.r_e);
            let hph = ekf::h_p_ht(&self.core.ekf.p, &m.h);
            let r_lf = Matrix3::identity() * (sigma_lf_rad * sigma_lf_rad);
            m.r += ekf::correlated::inflate_covariance3(&hph, &r_lf, rho);
        }
        if self.run_update(Counter::Sensor(id), &m, tally).accepted() {
            self.core.last_star_fused = Some(ts);
            self.mark_fused(id, ts, tally);
        }
    }
}
