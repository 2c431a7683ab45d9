//! Validation of the navigator's configuration: every key's range and the consistency between
//! keys, reported as a [`ConfigError`] naming the key (`filter.<key> <what>`).

use super::*;

pub(in crate::navigator) fn check(ok: bool, key: &str, what: &str) -> Result<(), ConfigError> {
    if ok {
        Ok(())
    } else {
        Err(ConfigError(format!("filter.{key} {what}")))
    }
}

pub(in crate::navigator) fn pos(x: f64) -> bool {
    x.is_finite() && x > 0.0
}

pub(in crate::navigator) fn nonneg(x: f64) -> bool {
    x.is_finite() && x >= 0.0
}

impl VehicleModel {
    /// Checks naming the key: a finite lever arm within 10 m of the IMU, finite non-negative
    /// class values, a positive ride frequency.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for (i, x) in self.wheel_lever_arm_b_m.iter().enumerate() {
            check(
                x.is_finite() && x.abs() <= 10.0,
                &format!("vehicle.wheel_lever_arm_b_m[{i}]"),
                "must be a finite distance within 10 m",
            )?;
        }
        for (v, k) in [
            (
                self.rear_slip_per_lateral_accel_deg,
                "vehicle.rear_slip_per_lateral_accel_deg",
            ),
            (self.pitch_per_accel_deg, "vehicle.pitch_per_accel_deg"),
            (
                self.wheel_slip_per_accel_s2_m,
                "vehicle.wheel_slip_per_accel_s2_m",
            ),
            (self.ride_heave_sigma_m, "vehicle.ride_heave_sigma_m"),
            (self.ride_pitch_sigma_deg, "vehicle.ride_pitch_sigma_deg"),
            (self.ride_roll_sigma_deg, "vehicle.ride_roll_sigma_deg"),
            (
                self.mount_vibration_velocity_sigma_m_s,
                "vehicle.mount_vibration_velocity_sigma_m_s",
            ),
            (
                self.maneuver_correlation_time_s,
                "vehicle.maneuver_correlation_time_s",
            ),
        ] {
            check(nonneg(v), k, "must be a finite number >= 0")?;
        }
        check(
            pos(self.ride_frequency_hz),
            "vehicle.ride_frequency_hz",
            "must be a finite number > 0",
        )
    }
}

impl GravityDisturbanceSpec {
    fn validate(&self) -> Result<(), ConfigError> {
        let key = |k: &str| format!("gravity_disturbance.{k}");
        for (v, k) in [
            (self.deflection_sigma_arcsec, "deflection_sigma_arcsec"),
            (self.anomaly_sigma_mgal, "anomaly_sigma_mgal"),
            (self.correlation_distance_km, "correlation_distance_km"),
        ] {
            check(nonneg(v), &key(k), "must be >= 0")?;
        }
        let modelled = self.deflection_sigma_arcsec > 0.0 || self.anomaly_sigma_mgal > 0.0;
        check(
            !modelled || pos(self.correlation_distance_km),
            &key("correlation_distance_km"),
            "must be > 0 when a disturbance sigma is",
        )
    }
}

impl NavigatorConfig {
    /// Check the meaning of the values (ranges, consistency); the error names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.motion_alignment.validate()?;
        self.warm_start.validate()?;
        self.calibration_memory.validate()?;
        self.gravity_disturbance.validate()?;
        check(
            nonneg(self.alignment_s) && self.alignment_s <= 3600.0,
            "alignment_s",
            "must be in [0, 3600] s",
        )?;
        check(
            self.gate_probability.is_finite()
                && self.gate_probability > 0.5
                && self.gate_probability <= 1.0,
            "gate_probability",
            "must be in (0.5, 1]",
        )?;
        check(
            nonneg(self.buffer_window_s) && self.buffer_window_s <= 2.0,
            "buffer_window_s",
            "must be in [0, 2] s",
        )?;
        for (v, k) in [
            (self.latency.gnss_s, "latency.gnss_s"),
            (self.latency.star_tracker_s, "latency.star_tracker_s"),
            (self.latency.odometer_s, "latency.odometer_s"),
            (self.latency.baro_s, "latency.baro_s"),
        ] {
            check(
                nonneg(v) && v < self.buffer_window_s.max(f64::MIN_POSITIVE),
                k,
                "must be in [0, buffer_window_s) s: a sample is fused at its time of validity \
                 through the delayed-fusion buffer",
            )?;
        }
        check(
            pos(self.max_imu_rate_hz) && self.max_imu_rate_hz <= 100_000.0,
            "max_imu_rate_hz",
            "must be in (0, 100000] Hz",
        )?;
        check(
            self.imu_log_capacity() <= IMU_LOG_MAX_CAP,
            "max_imu_rate_hz",
            "× (buffer_window_s + 0.2 s) must be at most 65536 IMU steps (the delayed-fusion \
             log): lower the rate or the window",
        )?;
        if let Some(p) = &self.initial_position {
            check(
                p.lat_deg.is_finite() && p.lat_deg.abs() <= 90.0,
                "initial_position.lat_deg",
                "must be in [-90, 90]",
            )?;
            check(
                p.lon_deg.is_finite() && p.lon_deg.abs() <= 360.0,
                "initial_position.lon_deg",
                "must be in [-360, 360]",
            )?;
            check(
                p.height_m.is_finite() && (-1000.0..=100_000.0).contains(&p.height_m),
                "initial_position.height_m",
                "must be in [-1000, 100000] m",
            )?;
        }
        check(
            self.eop.dut1_s.is_finite() && self.eop.dut1_s.abs() <= 0.9,
            "eop.dut1_s",
            "must be in [-0.9, 0.9] s",
        )?;
        check(
            self.eop.xp_rad.is_finite() && self.eop.xp_rad.abs() < 1e-5,
            "eop.xp_rad",
            "must be a finite polar motion below 1e-5 rad",
        )?;
        check(
            self.eop.yp_rad.is_finite() && self.eop.yp_rad.abs() < 1e-5,
            "eop.yp_rad",
            "must be a finite polar motion below 1e-5 rad",
        )?;
        let i = &self.imu;
        for (v, k) in [
            (i.gyro_bias_deg_h, "imu.gyro_bias_deg_h"),
            (i.arw_deg_sqrt_h, "imu.arw_deg_sqrt_h"),
            (i.accel_bias_ug, "imu.accel_bias_ug"),
            (i.vrw_ug_sqrt_hz, "imu.vrw_ug_sqrt_hz"),
            (i.max_rate_rad_s, "imu.max_rate_rad_s"),
            (i.max_specific_force_m_s2, "imu.max_specific_force_m_s2"),
            (self.initial.position_sigma_m, "initial.position_sigma_m"),
            (
                self.initial.velocity_sigma_m_s,
                "initial.velocity_sigma_m_s",
            ),
            (
                self.initial.level_sigma_min_deg,
                "initial.level_sigma_min_deg",
            ),
            (
                self.initial.heading_sigma_min_deg,
                "initial.heading_sigma_min_deg",
            ),
            (self.aiding.baro_sigma_m, "aiding.baro_sigma_m"),
            (self.aiding.baro_bias_sigma_m, "aiding.baro_bias_sigma_m"),
            (self.aiding.odometer_sigma_m_s, "aiding.odometer_sigma_m_s"),
            (self.aiding.nhc_sigma_m_s, "aiding.nhc_sigma_m_s"),
            (self.aiding.zupt_sigma_m_s, "aiding.zupt_sigma_m_s"),
            (
                self.aiding.zupt_max_rate_rad_s,
                "aiding.zupt_max_rate_rad_s",
            ),
            (
                self.aiding.zupt_max_accel_dev_m_s2,
                "aiding.zupt_max_accel_dev_m_s2",
            ),
            (self.aiding.zupt_max_speed_m_s, "aiding.zupt_max_speed_m_s"),
            (self.deadlines.gnss_s, "deadlines.gnss_s"),
            (self.deadlines.star_tracker_s, "deadlines.star_tracker_s"),
            (self.deadlines.odometer_s, "deadlines.odometer_s"),
            (self.deadlines.baro_s, "deadlines.baro_s"),
        ] {
            check(pos(v), k, "must be a finite number > 0")?;
        }
        for (v, k) in [
            (i.gyro_bias_rw_deg_h_sqrt_h, "imu.gyro_bias_rw_deg_h_sqrt_h"),
            (i.accel_bias_rw_ug_sqrt_h, "imu.accel_bias_rw_ug_sqrt_h"),
            (
                self.aiding.baro_min_interval_s,
                "aiding.baro_min_interval_s",
            ),
            (
                self.aiding.baro_bias_rw_m_sqrt_s,
                "aiding.baro_bias_rw_m_sqrt_s",
            ),
            (self.aiding.baro_scale_sigma, "aiding.baro_scale_sigma"),
            (
                self.aiding.star_low_frequency_sigma_arcsec,
                "aiding.star_low_frequency_sigma_arcsec",
            ),
            (
                self.aiding.star_low_frequency_correlation_time_s,
                "aiding.star_low_frequency_correlation_time_s",
            ),
            (
                self.aiding.odometer_scale_sigma,
                "aiding.odometer_scale_sigma",
            ),
            (self.aiding.zupt_interval_s, "aiding.zupt_interval_s"),
            (self.aiding.zupt_window_s, "aiding.zupt_window_s"),
        ] {
            check(nonneg(v), k, "must be a finite number >= 0")?;
        }
        check(
            i.max_specific_force_m_s2 > 2.0 * G0,
            "imu.max_specific_force_m_s2",
            "must exceed 2 g",
        )?;
        self.vehicle.validate()?;
        self.redundancy.validate()?;
        self.validate_filter_keys()
    }

    /// Checks of the state-group and coupling keys (filter engineer's part of `validate`).
    pub(in crate::navigator) fn validate_filter_keys(&self) -> Result<(), ConfigError> {
        check(
            pos(self.covariance_interval_s) && self.covariance_interval_s <= 1.0,
            "covariance_interval_s",
            "must be in (0, 1] s",
        )?;
        for (v, k) in [
            (self.imu.gyro_scale_ppm, "imu.gyro_scale_ppm"),
            (self.imu.accel_scale_ppm, "imu.accel_scale_ppm"),
            (self.imu.misalignment_arcsec, "imu.misalignment_arcsec"),
            (
                self.aiding.boresight_sigma_deg,
                "aiding.boresight_sigma_deg",
            ),
            (
                self.aiding.star_roll_bias_sigma_arcsec,
                "aiding.star_roll_bias_sigma_arcsec",
            ),
            (
                self.aiding.baseline_phase_sigma_cycles,
                "aiding.baseline_phase_sigma_cycles",
            ),
            (
                self.aiding.clock_bias_psd_m2_s,
                "aiding.clock_bias_psd_m2_s",
            ),
            (
                self.aiding.clock_drift_psd_m2_s3,
                "aiding.clock_drift_psd_m2_s3",
            ),
        ] {
            check(nonneg(v), k, "must be a finite number >= 0")?;
        }
        check(
            self.aiding.baseline_ratio_threshold.is_finite()
                && self.aiding.baseline_ratio_threshold >= 1.0,
            "aiding.baseline_ratio_threshold",
            "must be a finite number >= 1",
        )?;
        check(
            self.aiding.baseline_phase_sigma_cycles < 0.1,
            "aiding.baseline_phase_sigma_cycles",
            "must be below 0.1 cycle (integer ambiguities cannot be resolved above it)",
        )?;
        for (i, v) in self.gnss.lever_arm_b_m.iter().enumerate() {
            check(
                v.is_finite() && v.abs() <= 50.0,
                &format!("gnss.lever_arm_b_m[{i}]"),
                "must be a finite number within ±50 m",
            )?;
        }
        check(
            nonneg(self.gnss.error_correlation_time_s),
            "gnss.error_correlation_time_s",
            "must be a finite number >= 0",
        )?;
        check(
            self.gnss_mode == GnssMode::Loose || self.states.clock,
            "states.clock",
            "must be true with gnss_mode = \"tight\"",
        )?;
        Ok(())
    }
}
