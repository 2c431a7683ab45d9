//! From static coarse alignment to navigation (paper 003, [`crate::alignment`]): the aiding
//! consumed while aligning (the GNSS position and, in tight mode, the least-squares clock; the
//! star-tracker attitude and GNSS velocity for the alignment in motion, `motion_align`),
//! and the initial state and joint covariance once the static alignment window is complete.

use super::*;

impl Navigator {
    /// While aligning, at IMU epoch `t` with the increments `dth` (body, rad) and `dv` (body,
    /// m/s) over `dt_s`: carry the star attitude and the GNSS-velocity yaw estimator, take the
    /// aiding due, and start navigating in motion when the sensors allow it (from a star
    /// attitude, `try_align_in_motion`, else from the GNSS heading,
    /// `try_align_from_gnss_heading`).
    pub(super) fn consume_during_alignment(
        &mut self,
        t: GpsTime,
        dth: &Vector3<f64>,
        dv: &Vector3<f64>,
        dt_s: f64,
    ) {
        self.check_warm_start_age(t);
        if self.align.count() == 1 {
            self.static_position
                .restart(t - Duration::from_seconds_f64(dt_s));
        }
        self.carry_star_attitude(dth, dt_s);
        self.gsf_predict(dth, dv, dt_s);
        while let Some((ts, obs, _)) = self.star_q.pop_due(t) {
            self.alignment_star(ts, &obs);
        }
        while let Some((ts, obs, _)) = self.gnss_q.pop_due(t) {
            self.alignment_gnss(ts, &obs);
            if self.try_align_in_motion(ts, &obs, t)
                || self.try_align_from_gnss_heading(ts, &obs, t)
            {
                return;
            }
        }
        // Other aiding is not used before navigation starts.
        while self.odo_q.pop_due(t).is_some() {}
        while self.baro_q.pop_due(t).is_some() {}
        self.static_position.settle(
            t - Duration::from_seconds_f64(self.config.buffer_window_s),
            self.config.gnss.error_correlation_time_s,
        );
    }

    pub(super) fn try_finish_alignment(&mut self, t: GpsTime) {
        if self.phase == Phase::Navigating
            || self.align.duration_s() + 1e-9 < self.config.alignment_s
        {
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
        } else if let Some(f) = self.static_position.position() {
            from_gnss = true;
            f
        } else {
            return; // keep averaging until a position is known
        };
        let geo = earth::ecef_to_geodetic(&self.ell, &r_e);
        // The mean increments corrected with the prior's sensor-error estimates (zero unless a
        // calibration memory is tighter than the data sheet): biases and scale factors; the
        // non-orthogonality acts on the Earth rate only, 10⁻⁴ of it for 20″.
        let (mut p0, x0) = self.sensor_prior(&self.align.mean_specific_force_m_s2());
        let f_b = (self.align.mean_specific_force_m_s2() - x0.fixed_rows::<3>(idx::BA))
            .component_div(&x0.fixed_rows::<3>(idx::SA).add_scalar(1.0));
        let w_b = (self.align.mean_rate_rad_s() - x0.fixed_rows::<3>(idx::BG))
            .component_div(&x0.fixed_rows::<3>(idx::SG).add_scalar(1.0));
        let a = match alignment::coarse_align(&f_b, &w_b, geo.lat_rad, self.ell.omega_ie_rad_s) {
            Ok(a) => a,
            Err(_) => {
                // Not static (or polar): start the window again (its fixes with it).
                self.align.reset();
                return;
            }
        };
        let imu = &self.config.imu;
        let noise = self.filter_noise();
        // The bias σ the levelling and gyrocompassing see: the prior's (largest axis).
        let axis_sigma = |i0: usize| {
            (0..3)
                .map(|k| p0[(i0 + k, i0 + k)])
                .fold(0.0, f64::max)
                .sqrt()
        };
        let (gyro_bias_rad_s, accel_bias_m_s2) = if self.calibration.is_some() {
            (axis_sigma(idx::BG), axis_sigma(idx::BA))
        } else {
            (
                imu.gyro_bias_rad_s(),
                self.config.leveling_accel_error_m_s2(),
            )
        };
        let spec = alignment::AlignmentErrorSpec {
            gyro_bias_rad_s,
            accel_bias_m_s2,
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
        // The joint block replaced the biases' prior block; a calibration memory's
        // correlations of the biases with the other remembered states are dropped with it
        // (their variances stay), so that the whole stays positive semi-definite.
        if self.calibration.is_some() {
            for i in idx::BG..idx::BA + 3 {
                for j in (idx::BA + 3)..ekf::NX {
                    p0[(i, j)] = 0.0;
                    p0[(j, i)] = 0.0;
                }
            }
        }
        // A snapshot's sensor errors are not taken over here: the coarse attitude above was
        // derived with zero biases and is correlated with them (the joint block).
        if self.warm.take().is_some() {
            self.warm_outcome = Some(WarmStartOutcome::Refused(WarmStartRefusal::StandingStart));
        }
        // The tight-mode clock from the window's fixes too, not from whichever arrived last.
        self.init_ls = self.static_position.clock_fix(from_gnss);
        self.start_navigation(p0, &x0, t);
    }

    /// During alignment: the least-squares fix of the raw pseudoranges (kept as the next
    /// one's first guess and for a start in motion) and the receiver's fix, queued for the
    /// static window's position ([`StaticPosition`]).
    pub(super) fn alignment_gnss(&mut self, ts: GpsTime, obs: &GnssObs) {
        let guess = self
            .init_ls
            .map(|(_, f)| (f.position.r_e_m, f.position.clock_bias_m));
        let ls = self.ls_fix(obs, guess);
        if let Some(fix) = ls {
            self.init_ls = Some((ts, fix));
        }
        self.static_position.push(
            ts,
            ls,
            obs.fix.map(|f| (f.pos, f.pos_cov)),
            self.config.gnss.error_correlation_time_s,
        );
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
            boresight: (s.boresight || self.config.aiding.star_roll_bias_sigma_arcsec > 0.0)
                && self.config.updates.star_tracker,
            clock: clock && s.clock && self.config.gnss_mode == GnssMode::Tight,
            gyro_misalignment: s.gyro_misalignment,
        }
    }
}
