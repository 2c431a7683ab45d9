//! From static coarse alignment to navigation (paper 003, [`crate::alignment`]): the aiding
//! consumed while aligning (the GNSS position and, in tight mode, the least-squares clock),
//! and the initial state and joint covariance once the alignment window is complete.

use super::*;

impl Navigator {
    pub(super) fn consume_during_alignment(&mut self, t: GpsTime) {
        while let Some((ts, obs, _)) = self.gnss_q.pop_due(t) {
            self.alignment_gnss(ts, &obs);
        }
        // Other aiding is not used before navigation starts.
        while self.star_q.pop_due(t).is_some() {}
        while self.odo_q.pop_due(t).is_some() {}
        while self.baro_q.pop_due(t).is_some() {}
    }

    pub(super) fn try_finish_alignment(&mut self, t: GpsTime) {
        if self.align.duration_s() + 1e-9 < self.config.alignment_s {
            return;
        }
        let mut from_gnss = false;
        let (r_e, pos_cov) = if let Some(p) = &self.config.initial_position {
            let g = Geodetic {
                lat_rad: p.lat_deg * DEG,
                lon_rad: p.lon_deg * DEG,
                height_m: p.height_m,
            };
            let s2 = self.config.initial.position_sigma_m.powi(2);
            (
                earth::geodetic_to_ecef(&self.ell, &g),
                Matrix3::identity() * s2,
            )
        } else if let Some(f) = self.initial_fix() {
            from_gnss = true;
            f
        } else {
            return; // keep averaging until a position is known
        };
        let geo = earth::ecef_to_geodetic(&self.ell, &r_e);
        let f_b = self.align.mean_specific_force_m_s2();
        let w_b = self.align.mean_rate_rad_s();
        let a = match alignment::coarse_align(&f_b, &w_b, geo.lat_rad, self.ell.omega_ie_rad_s) {
            Ok(a) => a,
            Err(_) => {
                // Not static (or polar): start the window again.
                self.align.reset();
                return;
            }
        };
        let imu = &self.config.imu;
        let mut noise = imu.process_noise();
        noise.baro_bias_rw_m_sqrt_s = self.config.aiding.baro_bias_rw_m_sqrt_s;
        noise.clock_bias_psd_m2_s = self.config.aiding.clock_bias_psd_m2_s;
        noise.clock_drift_psd_m2_s3 = self.config.aiding.clock_drift_psd_m2_s3;
        let spec = alignment::AlignmentErrorSpec {
            gyro_bias_rad_s: imu.gyro_bias_rad_s(),
            accel_bias_m_s2: imu.accel_bias_m_s2(),
            arw_rad_sqrt_s: noise.arw_rad_sqrt_s,
            vrw_m_s_sqrt_s: noise.vrw_m_s_sqrt_s,
        };
        let (s_level, s_head) = alignment::expected_sigmas(
            &spec,
            self.align.duration_s(),
            geo.lat_rad,
            self.ell.omega_ie_rad_s,
            f_b.norm(),
        );
        let s_level = s_level.max(self.config.initial.level_sigma_min_deg * DEG);
        let s_head = s_head.max(self.config.initial.heading_sigma_min_deg * DEG);
        let q_e_n = q_e_n(geo.lat_rad, geo.lon_rad);
        let c_e_n = q_e_n.to_rotation_matrix().into_inner();
        let q_e_b = q_e_n * a.q_n_b;
        // A GNSS fix is the antenna's position: the IMU is a lever arm away from it.
        let lever_e = if from_gnss {
            q_e_b * self.config.gnss.lever_arm_b()
        } else {
            Vector3::zeros()
        };
        self.core.nav = NavState {
            r_e: r_e - lever_e,
            v_e: Vector3::zeros(),
            q_e_b,
        };
        let mut p0 = Covariance::zeros();
        p0.fixed_view_mut::<3, 3>(idx::POS, idx::POS)
            .copy_from(&pos_cov);
        let sv = self.config.initial.velocity_sigma_m_s.powi(2);
        p0.fixed_view_mut::<3, 3>(idx::VEL, idx::VEL)
            .copy_from(&(Matrix3::identity() * sv));
        let att_n = Matrix3::from_diagonal(&Vector3::new(
            s_level * s_level,
            s_level * s_level,
            s_head * s_head,
        ));
        p0.fixed_view_mut::<3, 3>(idx::ATT, idx::ATT)
            .copy_from(&(c_e_n * att_n * c_e_n.transpose()));
        let sbg = imu.gyro_bias_rad_s().powi(2);
        let sba = imu.accel_bias_m_s2().powi(2);
        // The accelerometer misalignment (relative to the gyro-defined body frame, σ_m per
        // off-diagonal, not a state) turns the specific force f_b into the error M f_b; axis
        // k's part `Σ_{j≠k} M_kj f_j` has variance σ_m² (|f|² − f_k²). With the static f_b
        // of the alignment (gravity) it is constant in the body, i.e. a bias: it widens the
        // initial accelerometer-bias σ (≈ 48 µg on the level axes for 10″).
        let s_mis = imu.misalignment_arcsec / 3600.0 * DEG;
        for k in 0..3 {
            p0[(idx::BG + k, idx::BG + k)] = sbg;
            p0[(idx::BA + k, idx::BA + k)] =
                sba + s_mis * s_mis * (f_b.norm_squared() - f_b[k] * f_b[k]);
        }
        // The alignment's tilt and heading errors are the accelerometer and gyro biases seen
        // through levelling and gyrocompassing, not independent of them (counting both would
        // make e.g. a star tracker's boresight tilt look √2 better known than it is):
        // the joint (ψ, b_g, b_a) block of alignment::alignment_error_covariance.
        let joint = alignment::alignment_error_covariance(
            &c_e_n,
            &a.q_n_b.to_rotation_matrix().into_inner(),
            geo.lat_rad,
            self.ell.omega_ie_rad_s,
            f_b.norm(),
            &p0.fixed_view::<3, 3>(idx::BG, idx::BG).into_owned(),
            &p0.fixed_view::<3, 3>(idx::BA, idx::BA).into_owned(),
            &spec,
            self.align.duration_s(),
            self.config.initial.level_sigma_min_deg * DEG,
            self.config.initial.heading_sigma_min_deg * DEG,
        );
        p0.fixed_view_mut::<9, 9>(idx::ATT, idx::ATT)
            .copy_from(&joint);
        p0[(idx::BARO, idx::BARO)] = self.config.aiding.baro_bias_sigma_m.powi(2);
        p0[(idx::ODO, idx::ODO)] = self.config.aiding.odometer_scale_sigma.powi(2);
        let sg = imu.gyro_scale_ppm * 1e-6;
        let sa = imu.accel_scale_ppm * 1e-6;
        let sk = self.config.aiding.boresight_sigma_deg * DEG;
        for k in 0..3 {
            p0[(idx::SG + k, idx::SG + k)] = sg * sg;
            p0[(idx::SA + k, idx::SA + k)] = sa * sa;
            p0[(idx::KAPPA + k, idx::KAPPA + k)] = sk * sk;
        }
        self.core.ekf = ErrorStateEkf::new(p0, noise, self.active_states(false));
        self.core.clock_initialized = false;
        self.initialize_from_ls(t);
        self.core.strapdown = Strapdown::new(self.config.mechanization());
        self.phase = Phase::Navigating;
        self.time = t;
        self.imu_log.clear();
        self.checkpoints.clear();
        self.rewind_to = None;
        self.take_checkpoint(t);
        // Aiding queued up to now belongs to the alignment period.
        self.gnss_q.clear();
    }

    /// During alignment: keep the latest least-squares fix of the raw pseudoranges (the
    /// initial position and clock, [`Self::initialize_from_ls`]); without raw observations,
    /// the first receiver fix as before.
    pub(super) fn alignment_gnss(&mut self, ts: GpsTime, obs: &GnssObs) {
        let guess = self
            .init_ls
            .map(|(_, f)| (f.position.r_e_m, f.position.clock_bias_m));
        if let Some(fix) = self.ls_fix(obs, guess) {
            self.init_ls = Some((ts, fix));
        } else if self.init_fix.is_none()
            && let Some(fix) = obs.fix
        {
            self.init_fix = Some((fix.pos, fix.pos_cov));
        }
    }

    /// The alignment position from GNSS: the least-squares fix with its covariance when raw
    /// observations were received, else the receiver's fix.
    pub(super) fn initial_fix(&self) -> Option<(Vector3<f64>, Matrix3<f64>)> {
        self.init_ls
            .map(|(_, f)| (f.position.r_e_m, f.position.cov_r_e_m2))
            .or(self.init_fix)
    }

    /// At the start of navigation (tight mode, a least-squares fix with velocity from the
    /// alignment): the clock bias and drift from the fix, moved from its time `t_ls` to the
    /// start `t` over `Δt` with the clock model (`b += d·Δt`; variances
    /// `P_bb = σ_b² + Δt²σ_d² + q_b Δt + q_d Δt³/3`, `P_bd = Δt σ_d² + q_d Δt²/2`,
    /// `P_dd = σ_d² + q_d Δt`). When the initial position is that fix too, the bias keeps the
    /// fix's position↔clock covariance (`cov_r_clock_m2`: both come from the same
    /// pseudoranges); with a configured position the fix's errors are independent of the
    /// filter's, so the cross terms are zero. The drift is independent of both (range-rate
    /// noise) and the initial velocity (zero, static alignment) is not from the fix. The
    /// pseudoranges of that epoch are not fused again (the alignment queue is dropped).
    /// Without a velocity fix the clock starts at the first tight epoch
    /// ([`Self::initialize_clock`]).
    pub(super) fn initialize_from_ls(&mut self, t: GpsTime) {
        let Some((t_ls, fix)) = self.init_ls.take() else {
            return;
        };
        let Some(vel) = fix.velocity else {
            return;
        };
        if self.config.gnss_mode != GnssMode::Tight {
            return;
        }
        let mut active = self.active_states(true);
        active.clock = true;
        self.core.ekf.set_active(active);
        let dt = (t - t_ls).seconds_f64();
        let qb = self.config.aiding.clock_bias_psd_m2_s;
        let qd = self.config.aiding.clock_drift_psd_m2_s3;
        let var_d = vel.var_clock_drift_m2_s2;
        let p = &mut self.core.ekf.p;
        for i in [idx::CLK, idx::CLK_DRIFT] {
            p.row_mut(i).fill(0.0);
            p.column_mut(i).fill(0.0);
        }
        p[(idx::CLK, idx::CLK)] =
            fix.position.var_clock_bias_m2 + dt * dt * var_d + qb * dt + qd * dt * dt * dt / 3.0;
        let p_bd = dt * var_d + qd * dt * dt / 2.0;
        p[(idx::CLK, idx::CLK_DRIFT)] = p_bd;
        p[(idx::CLK_DRIFT, idx::CLK)] = p_bd;
        p[(idx::CLK_DRIFT, idx::CLK_DRIFT)] = var_d + qd * dt;
        if self.config.initial_position.is_none() {
            for k in 0..3 {
                p[(idx::POS + k, idx::CLK)] = fix.position.cov_r_clock_m2[k];
                p[(idx::CLK, idx::POS + k)] = fix.position.cov_r_clock_m2[k];
            }
        }
        self.core.ekf.clock_drift_m_s = vel.clock_drift_m_s;
        self.core.ekf.clock_bias_m = fix.position.clock_bias_m + vel.clock_drift_m_s * dt;
        self.core.clock_initialized = true;
    }

    /// The state groups to estimate, from the configuration (clock only once initialised).
    pub(super) fn active_states(&self, clock: bool) -> ActiveStates {
        let s = &self.config.states;
        ActiveStates {
            gyro_scale: s.gyro_scale,
            accel_scale: s.accel_scale,
            boresight: s.boresight && self.config.updates.star_tracker,
            clock: clock && s.clock && self.config.gnss_mode == GnssMode::Tight,
            gyro_misalignment: s.gyro_misalignment,
        }
    }
}
