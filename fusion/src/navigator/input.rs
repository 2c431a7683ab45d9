//! Accepting samples: header checks (time order, sequence numbers, far-future times), the
//! per-sensor content checks of [`super::gate`], health bookkeeping, and queueing of the
//! aiding for fusion at its time of validity.

use super::*;

impl Navigator {
    /// Feed one IMU sample (in time order). Returns the solution at its time once navigating
    /// (None while initializing/aligning). Buffered aiding samples whose time of validity is
    /// reached are fused before the solution is formed. Allocates nothing.
    pub fn push_imu(&mut self, s: &ImuSample) -> Result<Option<NavSolution>, Rejection> {
        Ok(if self.push_imu_deferred(s)? {
            self.solution()
        } else {
            None
        })
    }

    /// [`Self::push_imu`] without forming the solution ([`Self::push_deferred`]): true once
    /// navigating, the solution then formed by [`Self::solution`] until the next input.
    pub fn push_imu_deferred(&mut self, s: &ImuSample) -> Result<bool, Rejection> {
        self.catch_up();
        let id = sid(SensorId::Imu);
        self.health[id].received += 1;
        if let Err(e) = self
            .validate_header(SensorId::Imu, &s.header)
            .and_then(|_| self.validate_imu(s))
            .and_then(|_| self.check_imu_time(&s.header))
        {
            self.health[id].rejected_invalid += 1;
            return Err(e);
        }
        let prev_t = self.last_time[id];
        self.accept_header(id, &s.header);
        let t = GpsTime::from_ns(s.header.time_ns);
        // Paper 004: redundant channels combined with fault detection and exclusion.
        let (dth, dv) = self.imu_increments(s);
        match self.phase {
            Phase::Initializing | Phase::Aligning => {
                if self.phase == Phase::Initializing {
                    self.phase = Phase::Aligning;
                    self.mode = NavMode::Aligning;
                }
                self.time = t;
                self.align.add(&dth, &dv, s.dt_s);
                // Logged so that aiding arriving after its epoch can be carried to this one.
                self.log_alignment_step(ImuLogEntry {
                    t,
                    prev_t,
                    dth,
                    dv,
                    dt_s: s.dt_s,
                });
                self.health[id].fused += 1;
                self.consume_during_alignment(t, &dth, &dv, s.dt_s);
                self.try_finish_alignment(t);
            }
            Phase::Navigating => {
                let e = ImuLogEntry {
                    t,
                    prev_t,
                    dth,
                    dv,
                    dt_s: s.dt_s,
                };
                if let Some(p) = prev_t
                    && (t - p).seconds_f64() > 1.5 * s.dt_s
                {
                    self.bridge_imu_gap(p, &e);
                }
                self.imu_log.push(e);
                self.imu_step(&e);
                self.health[id].fused += 1;
            }
        }
        if self.phase != Phase::Navigating {
            return Ok(false);
        }
        self.update_mode(t);
        self.solutions += 1;
        self.solution_ready = true;
        self.solution_imu_send_mono_ns = s.header.send_mono_ns;
        // Only moves the late samples to their queues: the state stays the solution's.
        self.ripen_late();
        Ok(true)
    }

    /// Queue a star-tracker sample for fusion at its time of validity.
    pub fn push_star_tracker(&mut self, s: &StarTrackerSample) -> Result<(), Rejection> {
        self.catch_up();
        let id = sid(SensorId::StarTracker);
        self.health[id].received += 1;
        let ts = GpsTime::from_ns(s.header.time_ns);
        if let Err(e) = self
            .validate_header(SensorId::StarTracker, &s.header)
            .and_then(|_| {
                let bad = |r| Rejection::new(SensorId::StarTracker, ts, r);
                if !s.q_sensor_icrf.iter().all(|x| x.is_finite()) {
                    return Err(bad(RejectReason::NonFiniteQuaternion));
                }
                let n = s.q_sensor_icrf.iter().map(|x| x * x).sum::<f64>().sqrt();
                if s.valid != 0 && (n - 1.0).abs() > 1e-3 {
                    return Err(bad(RejectReason::QuaternionNotUnit));
                }
                if s.valid != 0
                    && !(pos(s.sigma_cross_rad)
                        && pos(s.sigma_roll_rad)
                        && s.sigma_cross_rad < 0.1
                        && s.sigma_roll_rad < 0.1)
                {
                    return Err(bad(RejectReason::StarSigma));
                }
                Ok(())
            })
        {
            self.health[id].rejected_invalid += 1;
            return Err(e);
        }
        self.accept_header(id, &s.header);
        if s.valid != 0 {
            let obs = StarObs {
                q: s.q_sensor_icrf,
                sigma_cross: s.sigma_cross_rad,
                sigma_roll: s.sigma_roll_rad,
            };
            let valid = ts - self.config.latency.of(SensorId::StarTracker);
            let arrival = self.arrival(valid);
            self.health[id].dropped_late += enqueue(
                &mut self.star_q,
                &mut self.star_inbox,
                &mut self.rewind_to,
                arrival,
                valid,
                obs,
            );
        }
        Ok(())
    }

    /// Queue a GNSS sample.
    pub fn push_gnss(&mut self, s: &GnssSample) -> Result<(), Rejection> {
        self.catch_up();
        let id = sid(SensorId::Gnss);
        self.health[id].received += 1;
        let fix = match self
            .validate_header(SensorId::Gnss, &s.header)
            .and_then(|_| validate_gnss(s))
        {
            Ok(f) => f,
            Err(e) => {
                self.health[id].rejected_invalid += 1;
                return Err(e);
            }
        };
        self.accept_header(id, &s.header);
        // Raw satellites are kept in both modes: tight fuses them, and both use them for the
        // least-squares fix (initialisation and cross-check, `gnss_ls_cross_check`).
        let (n_sats, sats) = usable_satellites(s);
        let attitude = self.baseline_attitude(s, fix.as_ref().map(|f| f.pos));
        if fix.is_none() && n_sats == 0 && attitude.is_none() {
            return Ok(());
        }
        let obs = GnssObs {
            fix,
            attitude,
            n_sats,
            sats,
        };
        let ts = GpsTime::from_ns(s.header.time_ns) - self.config.latency.of(SensorId::Gnss);
        let arrival = self.arrival(ts);
        self.health[id].dropped_late += enqueue(
            &mut self.gnss_q,
            &mut self.gnss_inbox,
            &mut self.rewind_to,
            arrival,
            ts,
            obs,
        );
        Ok(())
    }

    /// Queue an odometer sample.
    pub fn push_odometer(&mut self, s: &OdometerSample) -> Result<(), Rejection> {
        self.catch_up();
        let id = sid(SensorId::Odometer);
        self.health[id].received += 1;
        let ts = GpsTime::from_ns(s.header.time_ns);
        if let Err(e) = self
            .validate_header(SensorId::Odometer, &s.header)
            .and_then(|_| {
                let bad = |r| Rejection::new(SensorId::Odometer, ts, r);
                if !(s.dt_s.is_finite() && s.dt_s > 0.0 && s.dt_s <= 10.0) {
                    return Err(bad(RejectReason::OdometerInterval));
                }
                if !(s.speed_m_s.is_finite() && s.speed_m_s.abs() < 200.0) {
                    return Err(bad(RejectReason::OdometerSpeed));
                }
                if !s.distance_m.is_finite() {
                    return Err(bad(RejectReason::NonFiniteDistance));
                }
                Ok(())
            })
        {
            self.health[id].rejected_invalid += 1;
            return Err(e);
        }
        self.accept_header(id, &s.header);
        let valid = ts - self.config.latency.of(SensorId::Odometer);
        let arrival = self.arrival(valid);
        self.health[id].dropped_late += enqueue(
            &mut self.odo_q,
            &mut self.odo_inbox,
            &mut self.rewind_to,
            arrival,
            valid,
            s.speed_m_s,
        );
        Ok(())
    }

    /// Queue a baro sample.
    pub fn push_baro(&mut self, s: &BaroSample) -> Result<(), Rejection> {
        self.catch_up();
        let id = sid(SensorId::Baro);
        self.health[id].received += 1;
        let ts = GpsTime::from_ns(s.header.time_ns);
        if let Err(e) = self
            .validate_header(SensorId::Baro, &s.header)
            .and_then(|_| {
                let bad = |r| Rejection::new(SensorId::Baro, ts, r);
                if !(s.pressure_pa.is_finite() && (1_000.0..=120_000.0).contains(&s.pressure_pa)) {
                    return Err(bad(RejectReason::Pressure));
                }
                if !(s.temperature_c.is_finite() && (-120.0..=100.0).contains(&s.temperature_c)) {
                    return Err(bad(RejectReason::Temperature));
                }
                Ok(())
            })
        {
            self.health[id].rejected_invalid += 1;
            return Err(e);
        }
        self.accept_header(id, &s.header);
        let h = crate::atmosphere::isa_altitude_m(s.pressure_pa);
        if !h.is_finite() {
            // Counted as invalid, but the header has been accepted (time and seq advance).
            self.health[id].rejected_invalid += 1;
            return Err(Rejection::new(
                SensorId::Baro,
                ts,
                RejectReason::NoIsaAltitude,
            ));
        }
        let valid = ts - self.config.latency.of(SensorId::Baro);
        let arrival = self.arrival(valid);
        self.health[id].dropped_late += enqueue(
            &mut self.baro_q,
            &mut self.baro_inbox,
            &mut self.rewind_to,
            arrival,
            valid,
            h,
        );
        Ok(())
    }

    pub(super) fn validate_header(&self, sensor: SensorId, h: &Header) -> Result<(), Rejection> {
        let id = sid(sensor);
        let t = GpsTime::from_ns(h.time_ns);
        let bad = |r: RejectReason| Rejection::new(sensor, t, r);
        if t < GpsTime::EPOCH {
            return Err(bad(RejectReason::NegativeTime));
        }
        // The IMU's own time continuity (backward steps, gaps, jumps) is `check_imu_time`.
        let imu = id == sid(SensorId::Imu);
        if !imu
            && let Some(prev) = self.last_time[id]
            && t <= prev
        {
            return Err(bad(RejectReason::TimeNotIncreasing { previous: prev }));
        }
        if self.last_seq[id] == Some(h.seq) {
            return Err(bad(RejectReason::DuplicatedSequence));
        }
        // An aiding time of validity far ahead of the filter time is a corrupt timestamp:
        // accepted, it would make every later good sample "not increasing" (the sensor lost for
        // good). Its queue is fused when the IMU reaches it, so the filter time is the
        // reference. (The IMU's own jumps: `check_imu_time`; a jump of 170 years found by
        // fuzzing made the covariance non-finite when it was stretched over.)
        /// Largest accepted lead of an aiding time of validity over the filter time (1 h:
        /// samples queued further ahead could only be fused after an IMU gap that is
        /// re-initialised anyway, which clears the queues).
        const MAX_TIME_AHEAD: Duration = Duration::from_seconds(3_600);
        let reference = (!imu && self.time > GpsTime::EPOCH).then_some(self.time);
        if let Some(r) = reference
            && t.saturating_since(r) > MAX_TIME_AHEAD
        {
            return Err(bad(RejectReason::FarAheadOfImu));
        }
        Ok(())
    }

    pub(super) fn accept_header(&mut self, id: usize, h: &Header) {
        if let Some(prev) = self.last_seq[id]
            && h.seq > prev.saturating_add(1)
        {
            self.health[id].seq_gaps += h.seq - prev - 1;
        }
        self.last_time[id] = Some(GpsTime::from_ns(h.time_ns));
        self.last_seq[id] = Some(h.seq);
        self.health[id].last_time_ns = h.time_ns;
    }

    pub(super) fn validate_imu(&self, s: &ImuSample) -> Result<(), Rejection> {
        let bad = |r| Rejection::new(SensorId::Imu, GpsTime::from_ns(s.header.time_ns), r);
        // At least 10 µs: no IMU outputs faster than 100 kHz (DESIGN: up to 2 kHz), and a
        // vanishing interval divides the increments into infinite rates (found by fuzzing: a
        // subnormal dt_s made the state non-finite).
        if !(s.dt_s.is_finite() && (1e-5..=1.0).contains(&s.dt_s)) {
            return Err(bad(RejectReason::ImuInterval));
        }
        let dth = Vector3::from(s.delta_angle_rad);
        let dv = Vector3::from(s.delta_velocity_m_s);
        if !(dth.iter().all(|x| x.is_finite()) && dv.iter().all(|x| x.is_finite())) {
            return Err(bad(RejectReason::NonFiniteIncrement));
        }
        if dth.norm() > self.config.imu.max_rate_rad_s * s.dt_s {
            return Err(bad(RejectReason::RateAboveLimit));
        }
        if dv.norm() > self.config.imu.max_specific_force_m_s2 * s.dt_s {
            return Err(bad(RejectReason::SpecificForceAboveLimit));
        }
        if s.n_channels as usize > MAX_IMU_CHANNELS {
            return Err(bad(RejectReason::TooManyChannels));
        }
        Ok(())
    }

    pub(super) fn too_late(&self, t: GpsTime) -> bool {
        self.phase == Phase::Navigating
            && t < self.time - Duration::from_seconds_f64(self.config.buffer_window_s)
    }
}
