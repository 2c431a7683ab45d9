//! The navigation mode from the aiding fused within its deadline, and the output message
//! (`msgs::NavSolution`: geodetic position, NED velocity and attitude, σ in NED, estimates).

use super::*;

/// Receiver clock estimate (tight coupling).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ClockEstimate {
    /// Clock bias × c, m.
    pub bias_m: f64,
    /// Clock drift × c, m/s.
    pub drift_m_s: f64,
    /// 1-σ of the bias, m.
    pub bias_sigma_m: f64,
    /// 1-σ of the drift, m/s.
    pub drift_sigma_m_s: f64,
}

impl Navigator {
    pub(super) fn update_mode(&mut self, t: GpsTime) {
        let d = &self.config.deadlines;
        let recent = |s: SensorId, dl: f64| -> bool {
            self.last_fused[sid(s)].is_some_and(|f| (t - f).seconds_f64() <= dl)
        };
        let star = recent(SensorId::StarTracker, d.star_tracker_s);
        let gnss = recent(SensorId::Gnss, d.gnss_s);
        let odo = recent(SensorId::Odometer, d.odometer_s);
        let baro = recent(SensorId::Baro, d.baro_s);
        let zupt = self
            .core
            .last_zupt
            .is_some_and(|z| (t - z).seconds_f64() <= 1.0)
            && self.core.static_since.is_some();
        let mut mask = 0u32;
        for (on, s) in [
            (star, SensorId::StarTracker),
            (gnss, SensorId::Gnss),
            (odo, SensorId::Odometer),
            (baro, SensorId::Baro),
        ] {
            if on {
                mask |= 1 << (s as u32);
            }
        }
        self.aiding_mask = mask;
        self.mode = match (gnss, star) {
            (true, true) => NavMode::GnssAstroInertial,
            (true, false) => NavMode::GnssInertial,
            (false, true) => NavMode::AstroInertial,
            (false, false) if odo || baro || zupt => NavMode::DeadReckoning,
            _ => NavMode::FreeInertial,
        };
    }

    /// The solution of the IMU sample just pushed, formed now: None when that sample gave none
    /// (not navigating) or when another input or a rewind ([`Self::catch_up`]) has come since.
    /// Forming it changes nothing in the navigator; allocates nothing.
    pub fn solution(&self) -> Option<NavSolution> {
        self.solution_ready.then(|| self.form_solution())
    }

    fn form_solution(&self) -> NavSolution {
        let (geo, c_e_n) = earth::ecef_to_geodetic_and_c_e_n(&self.ell, &self.core.nav.r_e);
        let q_e_n = UnitQuaternion::from_rotation_matrix(
            &nalgebra::Rotation3::from_matrix_unchecked(c_e_n),
        );
        let c_n_e = c_e_n.transpose();
        let q_n_b = q_e_n.inverse() * self.core.nav.q_e_b;
        let v_ned = c_n_e * self.core.nav.v_e;
        let rpy = rpy_from_q_n_b(&q_n_b);
        let p = &self.core.ekf.p;
        // Only the diagonal of C B Cᵀ: row i of C B dotted with row i of C.
        let sig = |k: usize| -> [f64; 3] {
            let cb = c_n_e * p.fixed_view::<3, 3>(k, k);
            [0, 1, 2].map(|i| cb.row(i).dot(&c_n_e.row(i)).max(0.0).sqrt())
        };
        // The position error block is in ECEF: rotated into NED whole, so the horizontal
        // error ellipse keeps its orientation (`pos_sigma_ned_m` is its diagonal's root).
        let pos_cov_ned: Matrix3<f64> = {
            let b: Matrix3<f64> = p.fixed_view::<3, 3>(idx::POS, idx::POS).into_owned();
            c_n_e * b * c_n_e.transpose()
        };
        let pos_sigma = [0, 1, 2].map(|i| pos_cov_ned[(i, i)].max(0.0).sqrt());
        let mut sol = NavSolution {
            header: Header {
                time_ns: self.time.ns,
                seq: self.solutions,
                status: 0,
                reserved: 0,
                send_mono_ns: 0,
            },
            mode: self.mode as u32,
            aiding_mask: self.aiding_mask,
            lat_rad: geo.lat_rad,
            lon_rad: geo.lon_rad,
            height_m: geo.height_m,
            pos_ecef_m: self.core.nav.r_e.into(),
            vel_ned_m_s: v_ned.into(),
            q_ned_body: quat_to_wire(&q_n_b),
            roll_pitch_heading_rad: rpy.into(),
            pos_sigma_ned_m: pos_sigma,
            vel_sigma_ned_m_s: sig(idx::VEL),
            att_sigma_ned_rad: sig(idx::ATT),
            gyro_bias_rad_s: self.core.ekf.gyro_bias_rad_s.into(),
            accel_bias_m_s2: self.core.ekf.accel_bias_m_s2.into(),
            imu_send_mono_ns: self.solution_imu_send_mono_ns,
            gyro_bias_sigma_rad_s: diag_sigma(p, idx::BG),
            accel_bias_sigma_m_s2: diag_sigma(p, idx::BA),
            gyro_scale_ppm: (self.core.ekf.gyro_scale * 1e6).into(),
            accel_scale_ppm: (self.core.ekf.accel_scale * 1e6).into(),
            boresight_rad: self.core.ekf.kappa_rad.into(),
            boresight_sigma_rad: self.boresight_sigma().into(),
            clock_bias_m: self.core.ekf.clock_bias_m,
            clock_drift_m_s: self.core.ekf.clock_drift_m_s,
            baro_bias_m: self.core.ekf.baro_bias_m,
            odometer_scale: self.core.ekf.odo_scale,
            // Judged by the daemon at publication (wall clock), not by the navigator.
            stale: 0,
            pos_cov_ned_m2: [0.0; 6],
        };
        sol.set_pos_cov_ned_m2(&[0, 1, 2].map(|i| [0, 1, 2].map(|j| pos_cov_ned[(i, j)])));
        sol
    }
}

/// 1-σ of three consecutive states from the covariance diagonal.
pub(super) fn diag_sigma(p: &Covariance, k: usize) -> [f64; 3] {
    [0, 1, 2].map(|i| p[(k + i, k + i)].max(0.0).sqrt())
}
