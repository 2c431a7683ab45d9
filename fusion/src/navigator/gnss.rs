//! GNSS fusion: loose (position/velocity fix), tight (pseudorange and range rate per satellite
//! with the receiver clock states, started by state augmentation), dual-baseline attitude, and
//! the receiver-style least-squares cross-check (paper 003 eq. 12–21).

use super::*;

impl Navigator {
    /// The GNSS antenna as the measurement models need it: the configured lever arm and the
    /// last bias-corrected body rate.
    pub(super) fn gnss_antenna(&self) -> ekf::GnssAntenna {
        ekf::GnssAntenna {
            lever_arm_b_m: self.config.gnss.lever_arm_b(),
            w_ib_b_rad_s: self.core.w_ib_b_rad_s,
        }
    }

    /// Dual-baseline attitude of a sample (paper 003, [`crate::baseline_attitude`]) from its
    /// integer-resolved phases ([`crate::phase_ambiguity`]): the receiver's phases carry an
    /// unknown integer per satellite and baseline, which the navigator's resolver finds by a
    /// search constrained by the baseline lengths and holds across epochs while the receiver
    /// keeps lock, dropping slipped satellites (lock indicator, residual test) and rejecting
    /// wrong sets. The resolution runs from the first sample on (lines of sight from the
    /// sample's own fix until navigation starts, from the inertial position after), so the
    /// integers are ready when navigation starts; an attitude is returned only while
    /// navigating, started from the inertial one (the result does not depend on it). The
    /// outcome of every epoch is counted in [`NavigatorDiagnostics`] (`baseline_*`). None when
    /// switched off, not navigating, not fixed, or not solvable.
    pub(super) fn baseline_attitude(
        &mut self,
        s: &GnssSample,
        fix_r_e_m: Option<Vector3<f64>>,
    ) -> Option<(Matrix3<f64>, Matrix3<f64>)> {
        use crate::baseline_attitude as ba;
        use crate::phase_ambiguity as pa;
        let has_baselines = s.baseline_length_m.iter().all(|d| pos(*d)) && pos(s.wavelength_m);
        if !(self.config.updates.baseline_attitude && has_baselines) {
            return None;
        }
        let navigating = self.phase == Phase::Navigating;
        let r_e = if navigating {
            self.core.nav.r_e
        } else {
            fix_r_e_m?
        };
        let baseline = ba::BaselineConfig {
            baseline_length_m: s.baseline_length_m,
            wavelength_m: s.wavelength_m,
            sigma_phase_cycles: self.config.aiding.baseline_phase_sigma_cycles,
        };
        let resolver = match &mut self.ambiguity {
            Some(r) => {
                r.set_baseline(baseline).ok()?;
                r
            }
            None => self.ambiguity.insert(
                pa::AmbiguityResolver::new(pa::AmbiguityConfig {
                    baseline,
                    ratio_threshold: self.config.aiding.baseline_ratio_threshold,
                    chi2_probability: self.config.gate_probability,
                })
                .ok()?,
            ),
        };
        let dg = &mut self.diagnostics;
        let Ok(raw) = pa::RawPhases::from_sample(s, &r_e) else {
            dg.baseline_rejected += 1;
            return None;
        };
        if raw.as_slice().is_empty() {
            return None;
        }
        let prior = navigating.then(|| self.core.nav.q_e_b.to_rotation_matrix().into_inner());
        let t_s = s.header.time_ns as f64 * 1e-9;
        let out = resolver.resolve(t_s, &raw, &r_e, prior.as_ref());
        dg.baseline_epochs += 1;
        dg.baseline_slips_flagged += out.slips_flagged as u64;
        dg.baseline_slips_detected += out.slips_detected as u64;
        dg.baseline_held_sets_rejected += u64::from(out.held_set_rejected);
        let sol = match out.result {
            Ok(r) => {
                dg.baseline_fixed += 1;
                dg.baseline_search_fixes += u64::from(r.searched);
                if dg.baseline_first_fix_ns == 0 {
                    dg.baseline_first_fix_ns = s.header.time_ns;
                }
                r.attitude
            }
            Err(e) => {
                if e.is_float_only() {
                    dg.baseline_float_only += 1;
                } else {
                    dg.baseline_rejected += 1;
                }
                return None;
            }
        };
        let finite = sol
            .c_e_b
            .iter()
            .chain(sol.cov_e_rad2.iter())
            .all(|x| x.is_finite());
        (navigating && finite).then_some((sol.c_e_b, sol.cov_e_rad2))
    }

    pub(super) fn fuse_gnss(&mut self, ts: GpsTime, obs: &GnssObs, tally: Tally) {
        let id = sid(SensorId::Gnss);
        // First, before any update of this epoch: the least-squares cross-check.
        self.gnss_ls_cross_check(ts, obs, tally);
        if let Some((c_e_b, cov)) = obs.attitude {
            let m = ekf::gnss_baseline_attitude(&self.core.nav, &c_e_b, &cov);
            if self.run_update(Counter::Sensor(id), &m, tally).accepted() {
                self.mark_fused(id, ts, tally);
            }
        }
        if self.config.gnss_mode == GnssMode::Tight {
            if obs.n_sats > 0 {
                self.fuse_gnss_tight(ts, obs, tally);
            }
            return;
        }
        let Some(fix) = obs.fix else {
            return;
        };
        // Position and velocity are gated separately; the sample's NIS is the larger one.
        let mut fused = false;
        let mut nis = f64::NEG_INFINITY;
        if self.config.updates.gnss_position {
            let rho = self.gnss_error_correlation(ts);
            let mut m =
                ekf::gnss_position(&self.core.nav, &self.gnss_antenna(), &fix.pos, &fix.pos_cov);
            if rho > 0.0 {
                self.core
                    .ekf
                    .propagate_covariance(&self.ell, &self.core.nav.r_e);
                let hph = ekf::h_p_ht(&self.core.ekf.p, &m.h);
                m.r = ekf::correlated::inflate_covariance3(&hph, &m.r, rho);
            }
            let v = self.run_update(Counter::Sensor(id), &m, tally);
            fused |= v.accepted();
            nis = nis.max(v.nis);
            if v.accepted() {
                self.core.last_gnss_ranging = Some(ts);
            }
        }
        if self.config.updates.gnss_velocity && fix.vel_valid {
            let m =
                ekf::gnss_velocity(&self.core.nav, &self.gnss_antenna(), &fix.vel, &fix.vel_cov);
            let v = self.run_update(Counter::Sensor(id), &m, tally);
            fused |= v.accepted();
            nis = nis.max(v.nis);
        }
        if tally == Tally::Count && (nis.is_finite() || nis == f64::INFINITY) {
            self.health[id].last_nis = nis;
        }
        if fused {
            self.mark_fused(id, ts, tally);
        }
    }

    /// Tight coupling: every satellite's pseudorange and range rate as a sequential scalar
    /// update (each gated on its own 1-dof NIS) at the inertial state of the epoch. The first
    /// epoch without clock states starts them by state augmentation from one pseudorange and
    /// one range rate ([`Self::initialize_clock`]); those two are consumed, the others fused.
    /// The sample's NIS is the largest one.
    pub(super) fn fuse_gnss_tight(&mut self, ts: GpsTime, obs: &GnssObs, tally: Tally) {
        let id = sid(SensorId::Gnss);
        // The clock estimate is kept at the filter time; move it back to the sample's time.
        let back_s = (self.time - ts).seconds_f64();
        let (skip_pr, skip_rr) = if self.core.clock_initialized {
            (None, None)
        } else {
            self.initialize_clock(obs, back_s)
        };
        // A measurement consumed by the clock initialisation was used: the epoch counts.
        let mut fused = skip_pr.is_some();
        let mut ranged = skip_pr.is_some();
        let rho = self.gnss_error_correlation(ts);
        let mut nis = f64::NEG_INFINITY;
        for (i, sat) in obs.sats.iter().take(obs.n_sats).enumerate() {
            if sat.has_pr && skip_pr != Some(i) {
                let b = self.core.ekf.clock_bias_m - self.core.ekf.clock_drift_m_s * back_s;
                let mut m = ekf::gnss_pseudorange(
                    &self.core.nav,
                    &self.gnss_antenna(),
                    &sat.pos,
                    sat.pseudorange_m,
                    b,
                    sat.sigma_pr_m,
                );
                if rho > 0.0 {
                    self.core
                        .ekf
                        .propagate_covariance(&self.ell, &self.core.nav.r_e);
                    let hph = ekf::h_p_ht(&self.core.ekf.p, &m.h)[(0, 0)];
                    m.r[(0, 0)] *= ekf::correlated::scalar_inflation(hph, m.r[(0, 0)], rho);
                }
                let v = self.run_update(Counter::Sensor(id), &m, tally);
                fused |= v.accepted();
                ranged |= v.accepted();
                nis = nis.max(v.nis);
            }
            if sat.has_rr && self.config.updates.gnss_velocity && skip_rr != Some(i) {
                let m = ekf::gnss_range_rate(
                    &self.core.nav,
                    &self.gnss_antenna(),
                    &sat.pos,
                    &sat.vel,
                    sat.range_rate_m_s,
                    self.core.ekf.clock_drift_m_s,
                    sat.sigma_rr_m_s,
                );
                let v = self.run_update(Counter::Sensor(id), &m, tally);
                fused |= v.accepted();
                nis = nis.max(v.nis);
            }
        }
        if tally == Tally::Count && nis > f64::NEG_INFINITY {
            self.health[id].last_nis = nis;
        }
        if ranged {
            self.core.last_gnss_ranging = Some(ts);
        }
        if fused {
            self.mark_fused(id, ts, tally);
        }
    }

    /// Lag-one correlation `ρ = exp(−Δt/τ)` of the receiver's position / pseudorange error
    /// between the epoch `ts` and the last GNSS epoch whose position or pseudoranges were
    /// fused (`τ` = `gnss.error_correlation_time_s`; 0 when it is 0 or nothing was fused
    /// since navigation started). Every satellite of an epoch gets the epoch's lag: a
    /// satellite that has just risen is inflated as if it had been tracked (conservative).
    pub(super) fn gnss_error_correlation(&self, ts: GpsTime) -> f64 {
        match self.core.last_gnss_ranging {
            Some(prev) if ts > prev => ekf::correlated::lag_correlation(
                (ts - prev).seconds_f64(),
                self.config.gnss.error_correlation_time_s,
            ),
            _ => 0.0,
        }
    }

    /// Start the clock states from this epoch by state augmentation
    /// ([`ekf::augment_covariance`]), from one satellite up; no 4-satellite fix needed.
    ///
    /// Bias from the first satellite k with a pseudorange, `b̂(t_s) = ρ_k − |s_k − r̂|`, drift
    /// from the first one j with a range rate, `d̂ = ρ̇_j − (ṡ_j − v̂)·u_j` (without one: `d̂ = 0`
    /// with a TCXO-class σ of 10⁻⁶·c = 300 m/s). Their errors are `δb = −H_k δx − ε_k`
    /// (`H_k,r = −u_kᵀ`, so `δb = u_k·δr − ε_k`: the bias carries the inertial error along the
    /// line of sight) and `δd = −H_j δx − η_j`; the bias is stored at the filter time
    /// `t = t_s + back_s` as `b̂(t) = b̂(t_s) + d̂·back_s`, so its row is `H_k + back_s·H_j` and
    /// the noise `[[σ_k² + back_s²σ_j², back_s σ_j²], [back_s σ_j², σ_j²]]`. The covariance
    /// rows follow exactly (`P_cx = −H P`, `P_cc = H P Hᵀ + R`). Earlier the clock
    /// got a variance uncorrelated with position, which made one satellite worse than none
    /// (82 m vs 44 m along its line of sight in `tight-coupling`).
    ///
    /// Returns the indices (in `obs.sats`) of the pseudorange and range rate consumed: they
    /// carry no further information and must not be fused again.
    pub(super) fn initialize_clock(
        &mut self,
        obs: &GnssObs,
        back_s: f64,
    ) -> (Option<usize>, Option<usize>) {
        let sats = &obs.sats[..obs.n_sats];
        let Some(k) = sats.iter().position(|s| s.has_pr) else {
            return (None, None);
        };
        let j = if self.config.updates.gnss_velocity {
            sats.iter().position(|s| s.has_rr)
        } else {
            None
        };
        self.core
            .ekf
            .propagate_covariance(&self.ell, &self.core.nav.r_e);
        let mut active = self.active_states(true);
        active.clock = true;
        self.core.ekf.set_active(active);
        let sk = &sats[k];
        let m_b = ekf::gnss_pseudorange(
            &self.core.nav,
            &self.gnss_antenna(),
            &sk.pos,
            sk.pseudorange_m,
            0.0,
            sk.sigma_pr_m,
        );
        let (d_hat, h_d, var_d) = match j {
            Some(j) => {
                let sj = &sats[j];
                let m_d = ekf::gnss_range_rate(
                    &self.core.nav,
                    &self.gnss_antenna(),
                    &sj.pos,
                    &sj.vel,
                    sj.range_rate_m_s,
                    0.0,
                    sj.sigma_rr_m_s,
                );
                (m_d.innovation[0], m_d.h, sj.sigma_rr_m_s.powi(2))
            }
            None => (
                0.0,
                nalgebra::SMatrix::<f64, 1, { ekf::NX }>::zeros(),
                300.0f64.powi(2),
            ),
        };
        let mut h = nalgebra::SMatrix::<f64, 2, { ekf::NX }>::zeros();
        h.row_mut(0).copy_from(&(m_b.h + h_d * back_s));
        h.row_mut(1).copy_from(&h_d);
        let r = nalgebra::Matrix2::new(
            m_b.r[(0, 0)] + back_s * back_s * var_d,
            back_s * var_d,
            back_s * var_d,
            var_d,
        );
        ekf::augment_covariance(&mut self.core.ekf.p, [idx::CLK, idx::CLK_DRIFT], &h, &r);
        self.core.ekf.clock_drift_m_s = d_hat;
        self.core.ekf.clock_bias_m = m_b.innovation[0] + d_hat * back_s;
        self.core.clock_initialized = true;
        (Some(k), j)
    }

    /// The epoch's pseudoranges (and range rates) as least-squares observations, and the fix
    /// (paper 003 eq. 12–13, [`crate::gnss_ls`]) started from `guess` (ECEF position m, clock
    /// bias m; the Earth's centre without one). None with fewer than four pseudoranges or
    /// when the solver fails (singular geometry). Allocates nothing.
    pub(super) fn ls_fix(
        &self,
        obs: &GnssObs,
        guess: Option<(Vector3<f64>, f64)>,
    ) -> Option<crate::gnss_ls::GnssFix> {
        use crate::gnss_ls as ls;
        let mut o = ls::Observations::default();
        for sat in obs.sats.iter().take(obs.n_sats).filter(|s| s.has_pr) {
            // usable_satellites already vetted every value, so push cannot fail.
            o.push(ls::SatelliteObservation {
                prn: 0,
                sat_pos_ecef_m: sat.pos,
                sat_vel_ecef_m_s: sat.vel,
                pseudorange_m: sat.pseudorange_m,
                sigma_pseudorange_m: sat.sigma_pr_m,
                has_range_rate: sat.has_rr,
                range_rate_m_s: sat.range_rate_m_s,
                sigma_range_rate_m_s: sat.sigma_rr_m_s,
            })
            .ok()?;
        }
        if o.len() < 4 {
            return None;
        }
        let (r0, b0) = guess.unwrap_or((Vector3::zeros(), 0.0));
        let settings = ls::LsSettings {
            initial_r_e_m: r0,
            initial_clock_bias_m: b0,
            ellipsoid: self.ell,
            ..ls::LsSettings::default()
        };
        ls::solve(&o, &settings).ok()
    }

    /// Receiver-style cross-check of one epoch (the least-squares fix "as a
    /// cross-check"): with ≥ 4 pseudoranges, the fix `r_ls` of this epoch alone against the
    /// filter's prediction at its time of validity, before any update of the epoch:
    /// `d = r_ls − r̂(t_s)`, `S = P_rr + C_ls`, `NIS = dᵀS⁻¹d`, χ² with 3 dof if both are
    /// consistent, tested at the configured gate probability.
    ///
    /// Why `S` has no cross term: the filter's error before this update depends on the IMU,
    /// on earlier epochs' measurement noise and on the clock model; the fix's error is
    /// `(HᵀWH)⁻¹HᵀWε` of THIS epoch's pseudorange errors — independent of the filter's when
    /// they are white (the matched simulator). In a real receiver (and the simulator's world)
    /// they share slowly varying satellite-orbit/clock and atmosphere errors that the filter
    /// has absorbed from earlier epochs; there `S` would need their covariance subtracted
    /// twice, and the NIS here reads high. An echo of a hidden satellite (metres, one epoch
    /// to the next) makes the fix disagree: that is what the count is for.
    ///
    /// What a disagreement does: it is counted (`gnss_ls_disagreements`, with
    /// `gnss_ls_last_nis` and `gnss_ls_pdop` on `msgs::Status`) and nothing else. The epoch's
    /// updates still go through their own gates: the test cannot tell whether the fix (one
    /// bad pseudorange, which the per-satellite gates can single out and reject) or the filter
    /// (drifted beyond its covariance, e.g. after a long outage) is wrong, and skipping the
    /// epoch would, in the second case, lock the filter out of the only measurements that can
    /// bring it back. At 99.9 % a consistent filter disagrees on 0.1 % of the epochs; a run
    /// of disagreements is the operator's (or a supervisor's) signal to re-initialise.
    pub(super) fn gnss_ls_cross_check(&mut self, ts: GpsTime, obs: &GnssObs, tally: Tally) {
        let back_s = (self.time - ts).seconds_f64();
        // The fix is the antenna's: compare it with the predicted antenna position.
        let (r_a, v_a, _, _) = self.gnss_antenna().predict(&self.core.nav);
        let r_pred = r_a - v_a * back_s;
        let b_guess = if self.core.clock_initialized {
            self.core.ekf.clock_bias_m - self.core.ekf.clock_drift_m_s * back_s
        } else {
            0.0
        };
        let Some(fix) = self.ls_fix(obs, Some((r_pred, b_guess))) else {
            return;
        };
        self.core
            .ekf
            .propagate_covariance(&self.ell, &self.core.nav.r_e);
        let p_rr: Matrix3<f64> = self
            .core
            .ekf
            .p
            .fixed_view::<3, 3>(idx::POS, idx::POS)
            .into_owned();
        let s = ekf::symmetrize(&(p_rr + fix.position.cov_r_e_m2));
        let d = fix.position.r_e_m - r_pred;
        let Some(chol) = nalgebra::Cholesky::new(s) else {
            return;
        };
        let nis = d.dot(&chol.solve(&d));
        if tally == Tally::Skip {
            return; // re-fused during a replay: counted the first time
        }
        let dg = &mut self.diagnostics;
        dg.gnss_ls_checks += 1;
        if nis > self.gates.threshold(3) {
            dg.gnss_ls_disagreements += 1;
        }
        dg.gnss_ls_last_nis = nis;
        dg.gnss_ls_pdop = fix.position.dop.pdop;
    }
}
