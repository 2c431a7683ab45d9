//! The navigator's configuration (`config/filter.toml`, deserialized into
//! [`NavigatorConfig`]): the IMU class, the estimated state groups and the measurement updates,
//! the aiding noise, the vehicle, the deadlines, the latencies and the region's gravity
//! disturbance, each with its defaults. Their validation, every key's range and the consistency
//! between keys reported as a [`ConfigError`] naming the key, is in `validate`.

use super::*;

mod validate;

pub(super) use validate::{check, nonneg, pos};

/// Reference ellipsoid selection.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EllipsoidName {
    /// WGS-84 (default).
    #[default]
    Wgs84,
    /// PZ-90.11.
    Pz90,
}

impl EllipsoidName {
    /// The ellipsoid constants.
    pub fn ellipsoid(self) -> Ellipsoid {
        match self {
            Self::Wgs84 => WGS84,
            Self::Pz90 => PZ90,
        }
    }
}

/// IMU error specification (1-σ values, datasheet units as in the key names).
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImuSpec {
    /// Gyro bias (turn-on / in-run), °/h: initial σ of the gyro bias states.
    pub gyro_bias_deg_h: f64,
    /// Angle random walk, °/√h.
    pub arw_deg_sqrt_h: f64,
    /// Accelerometer bias, µg: initial σ of the accelerometer bias states.
    pub accel_bias_ug: f64,
    /// Velocity random walk, µg/√Hz.
    pub vrw_ug_sqrt_hz: f64,
    /// Gyro bias random walk, °/h/√h.
    pub gyro_bias_rw_deg_h_sqrt_h: f64,
    /// Accelerometer bias random walk, µg/√h.
    pub accel_bias_rw_ug_sqrt_h: f64,
    /// Gyro scale-factor error, ppm: initial σ of the gyro scale-factor states.
    pub gyro_scale_ppm: f64,
    /// Accelerometer scale-factor error, ppm: initial σ of the accelerometer scale states.
    pub accel_scale_ppm: f64,
    /// Axis misalignment of the triads (each off-diagonal term), arcsec: the prior σ of the
    /// gyro non-orthogonality states (`[states] gyro_misalignment`), the widening of the
    /// accelerometer-bias prior (its gravity part) and, since the body frame is realised by
    /// the IMU axes, an irreducible bias of a boresight estimated against them (added to the
    /// reported boresight σ as a "consider" term, see [`Navigator::boresight_rad`]).
    pub misalignment_arcsec: f64,
    /// Largest plausible angular rate, rad/s (input validation).
    pub max_rate_rad_s: f64,
    /// Largest plausible specific force, m/s² (input validation).
    pub max_specific_force_m_s2: f64,
}

impl Default for ImuSpec {
    fn default() -> Self {
        Self {
            gyro_bias_deg_h: 0.01,
            arw_deg_sqrt_h: 0.002,
            accel_bias_ug: 50.0,
            vrw_ug_sqrt_hz: 20.0,
            gyro_bias_rw_deg_h_sqrt_h: 0.002,
            accel_bias_rw_ug_sqrt_h: 5.0,
            gyro_scale_ppm: 50.0,
            accel_scale_ppm: 100.0,
            misalignment_arcsec: 10.0,
            max_rate_rad_s: 10.0,
            max_specific_force_m_s2: 300.0,
        }
    }
}

impl ImuSpec {
    /// Gyro bias σ, rad/s.
    pub fn gyro_bias_rad_s(&self) -> f64 {
        self.gyro_bias_deg_h * DEG / 3600.0
    }
    /// Accelerometer bias σ, m/s².
    pub fn accel_bias_m_s2(&self) -> f64 {
        self.accel_bias_ug * 1e-6 * G0
    }
    /// Noise densities in SI units.
    pub fn process_noise(&self) -> ProcessNoise {
        ProcessNoise {
            arw_rad_sqrt_s: self.arw_deg_sqrt_h * DEG / 60.0,
            vrw_m_s_sqrt_s: self.vrw_ug_sqrt_hz * 1e-6 * G0,
            gyro_bias_rw_rad_s_sqrt_s: self.gyro_bias_rw_deg_h_sqrt_h * DEG / 3600.0 / 60.0,
            accel_bias_rw_m_s2_sqrt_s: self.accel_bias_rw_ug_sqrt_h * 1e-6 * G0 / 60.0,
            baro_bias_rw_m_sqrt_s: 0.0,
            odo_scale_rw_per_sqrt_s: 0.0,
            clock_bias_psd_m2_s: 0.0,
            clock_drift_psd_m2_s3: 0.0,
            gyro_misalignment_rad: self.misalignment_arcsec / 3600.0 * DEG,
            gravity: crate::ekf::GravityDisturbance::default(),
        }
    }
}

/// Switchable state groups (`[states]` in `config/filter.toml`); an inactive group keeps
/// zero covariance and zero process noise ([`crate::ekf`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct StateSwitches {
    /// Gyro scale factors (3 states).
    pub gyro_scale: bool,
    /// Accelerometer scale factors (3 states).
    pub accel_scale: bool,
    /// Star-tracker boresight κ1..κ3 (3 states; only with star-tracker updates). Off by
    /// default: with a calibrated mount (paper 000 calibration, or the default scenarios'
    /// zero misalignment) estimating κ costs accuracy, because κ and the attitude error are
    /// only separable by turns and the IMU's own misalignment (measured, default vehicle run:
    /// horizontal RMS 0.19 → 0.21 m, attitude RMS 0.001° → 0.008°). Switch it on for an
    /// uncalibrated or disturbed mount. With it off, a star tracker whose class states a bias
    /// about its boresight (`aiding.star_roll_bias_sigma_arcsec` > 0) still has the group
    /// estimated, with that prior about the optical axis and none across it.
    pub boresight: bool,
    /// Receiver clock bias and drift (2 states; only with `gnss_mode = "tight"`, which
    /// requires them).
    pub clock: bool,
    /// Gyro non-orthogonality (3 states, prior σ `imu.misalignment_arcsec`). A turn about
    /// body z through it tilts the solution by a body-fixed plus a navigation-fixed angle
    /// (the chord of [`crate::ekf::MISALIGNMENT_COHERENCE_RAD`]): as states, GNSS and the
    /// star tracker calibrate it. Off, it is bounded as attitude noise per radian turned,
    /// which over-states the tilt uncertainty after every turn and, in the tight-coupling
    /// window, let baro updates spoil the tilt (the `inertial-budget` experiment).
    pub gyro_misalignment: bool,
}

impl Default for StateSwitches {
    fn default() -> Self {
        Self {
            gyro_scale: true,
            accel_scale: true,
            boresight: false,
            clock: true,
            gyro_misalignment: true,
        }
    }
}

/// How GNSS is fused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum GnssMode {
    /// The receiver's position/velocity fix with its covariance (needs ≥ 4 satellites).
    #[default]
    Loose,
    /// Each satellite's pseudorange and range rate as scalar updates with the receiver clock
    /// states: usable with any number of satellites from 1 (paper 003).
    Tight,
}

/// The GNSS antenna's installation (`[gnss]` in `config/filter.toml`).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct GnssInstallation {
    /// Antenna phase centre relative to the IMU, body axes (x forward, y right, z down), m:
    /// surveyed on the vehicle. Used by the loose and tight measurement models and to move
    /// the first fix from the antenna to the IMU at alignment.
    pub lever_arm_b_m: [f64; 3],
    /// Correlation time of the receiver's position / pseudorange error, s: the error is
    /// modelled as first-order Gauss–Markov with the receiver's reported variance and fused
    /// with the consistent inflation of [`crate::ekf::correlated`]. 0: white (no inflation).
    /// Doppler velocity and range rates are fused white.
    pub error_correlation_time_s: f64,
}

impl GnssInstallation {
    /// The lever arm as a vector, body axes, m.
    pub fn lever_arm_b(&self) -> Vector3<f64> {
        Vector3::from(self.lever_arm_b_m)
    }
}

/// Initial uncertainties of the filter after coarse alignment.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct InitialUncertainty {
    /// Position σ per axis when the position comes from configuration, m (a GNSS fix brings its
    /// own covariance).
    pub position_sigma_m: f64,
    /// Velocity σ per axis (the vehicle is static during alignment), m/s.
    pub velocity_sigma_m_s: f64,
    /// Lower bound of the roll/pitch σ, deg (the closed-form alignment σ is used when larger).
    pub level_sigma_min_deg: f64,
    /// Lower bound of the heading σ, deg.
    pub heading_sigma_min_deg: f64,
}

impl Default for InitialUncertainty {
    fn default() -> Self {
        Self {
            position_sigma_m: 10.0,
            velocity_sigma_m_s: 0.05,
            level_sigma_min_deg: 0.005,
            heading_sigma_min_deg: 0.05,
        }
    }
}

/// Which measurement updates are used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct UpdateSwitches {
    /// GNSS position (loose coupling).
    pub gnss_position: bool,
    /// GNSS velocity (loose coupling).
    pub gnss_velocity: bool,
    /// Star-tracker attitude.
    pub star_tracker: bool,
    /// Baro altitude.
    pub baro: bool,
    /// Odometer speed along body x.
    pub odometer: bool,
    /// Non-holonomic constraints with the odometer (ground vehicles).
    pub nonholonomic: bool,
    /// Zero-velocity updates while static.
    pub zupt: bool,
    /// Dual-baseline GNSS attitude (paper 003 eq. 14–21) from the baseline carrier phases.
    pub baseline_attitude: bool,
}

impl Default for UpdateSwitches {
    fn default() -> Self {
        Self {
            gnss_position: true,
            gnss_velocity: true,
            star_tracker: true,
            baro: true,
            odometer: true,
            nonholonomic: true,
            zupt: true,
            baseline_attitude: false,
        }
    }
}

/// Noise and scheduling of the aiding measurements that carry no covariance of their own.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct AidingNoise {
    /// Baro height white-noise σ, m (the bias is a filter state).
    pub baro_sigma_m: f64,
    /// Initial σ of the baro height bias state, m.
    pub baro_bias_sigma_m: f64,
    /// Random walk of the baro height bias, m/√s: the day's pressure tendency, which moves
    /// the standard-atmosphere height of a fixed point.
    pub baro_bias_rw_m_sqrt_s: f64,
    /// 1-σ scale error of the standard-atmosphere height on the day's air (the day's
    /// temperature off ISA over the ISA temperature), dimensionless: height changes since the
    /// bias was acquired are read wrong by this fraction.
    pub baro_scale_sigma: f64,
    /// Minimum time between two fused baro samples, s (the samples in between are not fused).
    pub baro_min_interval_s: f64,
    /// Baro samples rejected by the gate in a row after which the baro bias is acquired anew
    /// from the next one (0: never). A barometer reads the day's air, not the standard
    /// atmosphere: 10 hPa off ISA is ≈ 85 m of bias, far outside any prior a fixed start can
    /// give it, and the gate would then refuse the sensor for good.
    pub baro_reacquire_after: u32,
    /// Odometer speed white-noise σ, m/s (the mean speed over the odometer interval is
    /// converted to the end-point speed before the update, `fuse_odometer`).
    pub odometer_sigma_m_s: f64,
    /// Odometer scale-factor σ (not a state yet; added as `σ·|speed|`), dimensionless.
    pub odometer_scale_sigma: f64,
    /// Non-holonomic constraint σ (lateral and vertical body velocity), m/s.
    pub nhc_sigma_m_s: f64,
    /// Zero-velocity update σ per axis, m/s.
    pub zupt_sigma_m_s: f64,
    /// 1-σ noise of each baseline carrier-phase difference, cycles (dual-baseline attitude).
    pub baseline_phase_sigma_cycles: f64,
    /// Ratio test of the baseline integer search ([`crate::phase_ambiguity`]): the second
    /// best integer set's phase χ² over the best one's must reach this, ≥ 1. Derivation for
    /// the receiver class (L1, 1 m baselines, σ_φ = 0.01 cycle): a correct set has χ² ≈ its
    /// 2n − 3 ≥ 5 degrees of freedom; a wrong set that still meets both baseline lengths is off
    /// by ≥ 0.1 cycle (= 10σ_φ) on at least one phase of a satellite outside the primary three,
    /// i.e. χ² ≥ 100 — a ratio ≥ 15 for 7 satellites, so 3 (the fixed-ratio test's customary
    /// value) refuses only epochs whose runner-up is genuinely close; the χ² test
    /// (`gate_probability`) decides the rest.
    pub baseline_ratio_threshold: f64,
    /// 1-σ low-frequency error of the star tracker per axis, arcsec: its thermo-elastic
    /// bending and field-of-view errors, which stay for minutes to hours and do not average
    /// like its white noise (fused with the inflation of [`crate::ekf::correlated`] on top of
    /// the sample's reported white σ). 0: the reported σ is all.
    pub star_low_frequency_sigma_arcsec: f64,
    /// Correlation time of the star tracker's low-frequency error, s.
    pub star_low_frequency_correlation_time_s: f64,
    /// 1-σ of the star tracker's constant error about its boresight (optical axis), arcsec:
    /// what its maker's calibration leaves about the least observable axis, the same for the
    /// whole run. Estimated as the boresight angle about that axis (the boresight group is
    /// active whenever this is above 0, see [`StateSwitches::boresight`]), so the attitude it
    /// corrupts is known no better than this. 0: none.
    pub star_roll_bias_sigma_arcsec: f64,
    /// Initial σ of each star-tracker boresight angle κ1..κ3, deg.
    pub boresight_sigma_deg: f64,
    /// Receiver clock bias PSD (white frequency noise), m²/s (tight coupling).
    pub clock_bias_psd_m2_s: f64,
    /// Receiver clock drift PSD (random-walk frequency noise), m²/s³ (tight coupling).
    pub clock_drift_psd_m2_s3: f64,
    /// Minimum time between two zero-velocity updates, s; also the block over which the
    /// static test averages the IMU (the mount's vibration averages out, `navigator::zupt`).
    pub zupt_interval_s: f64,
    /// The IMU must look static this long before zero-velocity updates start, s.
    pub zupt_window_s: f64,
    /// Static test: |mean angular rate over a block| below this, rad/s.
    pub zupt_max_rate_rad_s: f64,
    /// Static test: |mean specific force over a block + g| below this (ECEF vectors, the
    /// specific force turned with the solution's attitude), m/s².
    pub zupt_max_accel_dev_m_s2: f64,
    /// Static test: estimated speed below this, m/s (guards against constant-velocity motion,
    /// which an IMU cannot tell from rest).
    pub zupt_max_speed_m_s: f64,
}

impl Default for AidingNoise {
    fn default() -> Self {
        Self {
            baro_sigma_m: 0.5,
            baro_bias_sigma_m: 10.0,
            baro_bias_rw_m_sqrt_s: 0.005,
            baro_scale_sigma: 0.0,
            baro_min_interval_s: 0.2,
            baro_reacquire_after: 10,
            odometer_sigma_m_s: 0.02,
            odometer_scale_sigma: 0.003,
            nhc_sigma_m_s: 1e-5,
            zupt_sigma_m_s: 0.005,
            baseline_phase_sigma_cycles: 0.01,
            baseline_ratio_threshold: 3.0,
            star_low_frequency_sigma_arcsec: 0.0,
            star_low_frequency_correlation_time_s: 3600.0,
            star_roll_bias_sigma_arcsec: 0.0,
            boresight_sigma_deg: 0.1,
            clock_bias_psd_m2_s: 0.1,
            clock_drift_psd_m2_s3: 0.01,
            zupt_interval_s: 0.1,
            zupt_window_s: 1.0,
            zupt_max_rate_rad_s: 0.002,
            zupt_max_accel_dev_m_s2: 0.05,
            zupt_max_speed_m_s: 0.3,
        }
    }
}

/// The ground vehicle the IMU rides in (`[vehicle]` of `config/filter.toml`, whose comment
/// derives each value): where the odometer wheel touches the road, and how far a car of its
/// class departs from the non-holonomic constraint and from rolling without slip. The
/// odometer and the constraints are applied at the wheel's contact point
/// ([`crate::ekf::WheelContact`]); their noise is computed at each update from the speed and
/// the accelerations ([`VehicleModel::violation_sigmas_m_s`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct VehicleModel {
    /// Contact point of the odometer wheel (a rear, non-steered wheel: the non-holonomic
    /// constraint holds at the rear axle) from the IMU, body axes (x forward, y right,
    /// z down), m, measured on the vehicle.
    pub wheel_lever_arm_b_m: [f64; 3],
    /// Slip angle of the rear tyres per m/s² of lateral acceleration, deg/(m/s²).
    pub rear_slip_per_lateral_accel_deg: f64,
    /// Body pitch against the wheel plane per m/s² of longitudinal acceleration (squat and
    /// dive), deg/(m/s²).
    pub pitch_per_accel_deg: f64,
    /// Longitudinal slip ratio of the odometer wheel per m/s² of acceleration, s²/m.
    pub wheel_slip_per_accel_s2_m: f64,
    /// 1-σ heave of the body on its springs at speed, m.
    pub ride_heave_sigma_m: f64,
    /// 1-σ pitch of the body on its springs at speed, deg.
    pub ride_pitch_sigma_deg: f64,
    /// 1-σ roll of the body on its springs at speed, deg.
    pub ride_roll_sigma_deg: f64,
    /// Natural frequency of the body on its springs, Hz.
    pub ride_frequency_hz: f64,
    /// 1-σ velocity of the IMU vibrating on its mount (engine orders, road), per axis, m/s.
    pub mount_vibration_velocity_sigma_m_s: f64,
    /// Correlation time of the violations that follow the driver's manoeuvres (sideslip in a
    /// turn, squat and wheel slip in a speed change), s: they are fused with the inflation of
    /// [`crate::ekf::correlated`]. 0: white.
    pub maneuver_correlation_time_s: f64,
}

impl Default for VehicleModel {
    fn default() -> Self {
        Self {
            wheel_lever_arm_b_m: [0.0; 3],
            rear_slip_per_lateral_accel_deg: 0.4,
            pitch_per_accel_deg: 0.2,
            wheel_slip_per_accel_s2_m: 0.005,
            ride_heave_sigma_m: 0.006,
            ride_pitch_sigma_deg: 0.15,
            ride_roll_sigma_deg: 0.15,
            ride_frequency_hz: 1.3,
            mount_vibration_velocity_sigma_m_s: 0.0015,
            maneuver_correlation_time_s: 5.0,
        }
    }
}

/// 1-σ departures of a car from the odometer's and the constraints' model at the wheel's
/// contact point, body axes `[forward, lateral, vertical]`, m/s: the part that changes within
/// a second (ride; fused as white noise) and the part that follows the manoeuvres (fused with
/// a correlation time).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViolationSigmas {
    /// Ride part, m/s.
    pub white_m_s: Vector3<f64>,
    /// Manoeuvre part, m/s.
    pub maneuver_m_s: Vector3<f64>,
}

impl VehicleModel {
    /// The lever arm as a vector, body axes, m.
    pub fn wheel_lever_arm_b(&self) -> Vector3<f64> {
        Vector3::from(self.wheel_lever_arm_b_m)
    }

    /// The departures at forward speed `speed_m_s`, longitudinal acceleration
    /// `accel_long_m_s2` and lateral acceleration `accel_lat_m_s2` (the derivation is the
    /// comment of `[vehicle]` in `config/filter.toml`). With ride angular rates
    /// `ω_θ = 2πf·σ_θ`, `ω_φ = 2πf·σ_φ` and heave rate `2πf·σ_h`:
    /// - forward: the body's pitch rate on its springs turns the rigid lever arm's `ω_y·l_z`
    ///   that the wheel does not see, `|l_z|·ω_θ`; the wheel slips by `k_s·a_x·V`;
    /// - lateral: the roll rate's `|l_z|·ω_φ`; the rear tyres slip by `k_β·a_y·V`;
    /// - vertical: heave rate, the body's pitch against the road `V·σ_θ`, the rates times the
    ///   arm `|l_x|·ω_θ`, `|l_y|·ω_φ`; squat and dive `k_p·a_x·V`;
    /// - every axis: the IMU's vibration on its mount.
    pub fn violation_sigmas_m_s(
        &self,
        speed_m_s: f64,
        accel_long_m_s2: f64,
        accel_lat_m_s2: f64,
    ) -> ViolationSigmas {
        let l = self.wheel_lever_arm_b_m;
        let w0 = std::f64::consts::TAU * self.ride_frequency_hz;
        let w_pitch = w0 * self.ride_pitch_sigma_deg.to_radians();
        let w_roll = w0 * self.ride_roll_sigma_deg.to_radians();
        let v = speed_m_s.abs();
        let (ax, ay) = (accel_long_m_s2.abs(), accel_lat_m_s2.abs());
        let vib2 = self.mount_vibration_velocity_sigma_m_s.powi(2);
        let vertical = ((w0 * self.ride_heave_sigma_m).powi(2)
            + (v * self.ride_pitch_sigma_deg.to_radians()).powi(2)
            + (l[0] * w_pitch).powi(2)
            + (l[1] * w_roll).powi(2)
            + vib2)
            .sqrt();
        ViolationSigmas {
            white_m_s: Vector3::new(
                ((l[2] * w_pitch).powi(2) + vib2).sqrt(),
                ((l[2] * w_roll).powi(2) + vib2).sqrt(),
                vertical,
            ),
            maneuver_m_s: Vector3::new(
                self.wheel_slip_per_accel_s2_m * ax * v,
                self.rear_slip_per_lateral_accel_deg.to_radians() * ay * v,
                self.pitch_per_accel_deg.to_radians() * ax * v,
            ),
        }
    }
}

/// An aiding source counts for the navigation mode while it has been fused within this age of
/// the IMU time, s.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Deadlines {
    /// GNSS, s.
    pub gnss_s: f64,
    /// Star tracker, s.
    pub star_tracker_s: f64,
    /// Odometer, s.
    pub odometer_s: f64,
    /// Baro, s.
    pub baro_s: f64,
}

impl Default for Deadlines {
    fn default() -> Self {
        Self {
            gnss_s: 2.0,
            star_tracker_s: 2.0,
            odometer_s: 1.0,
            baro_s: 3.0,
        }
    }
}

/// Time-tag latency of each aiding sensor (`[latency]` in `config/filter.toml`), s: a sample
/// stamped `t` was valid at `t − latency` (a receiver's fix computed and stamped after its
/// measurement epoch, a star tracker's exposure before its read-out). Each sample is fused at
/// its time of validity through the delayed-fusion buffer, so a latency must stay below
/// `buffer_window_s`. From the sensor's documentation or a calibration; 0: stamped at validity.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Latency {
    /// GNSS receiver (fix, pseudoranges, Doppler), s.
    pub gnss_s: f64,
    /// Star tracker, s.
    pub star_tracker_s: f64,
    /// Odometer, s.
    pub odometer_s: f64,
    /// Barometer, s.
    pub baro_s: f64,
}

impl Latency {
    /// The latency of `sensor` as a duration (zero for the IMU, the filter's time base).
    pub fn of(&self, sensor: SensorId) -> Duration {
        let s = match sensor {
            SensorId::Gnss => self.gnss_s,
            SensorId::StarTracker => self.star_tracker_s,
            SensorId::Odometer => self.odometer_s,
            SensorId::Baro => self.baro_s,
            _ => 0.0,
        };
        Duration::from_seconds_f64(s)
    }
}

/// The gravity disturbance of the region (`[gravity_disturbance]` in `config/filter.toml`):
/// what the real field departs from the mechanization's normal / J2 gravity by, as the class
/// of the terrain (1-σ values over the region, not a map). Absorbed by the accelerometer-bias
/// states ([`crate::ekf::GravityDisturbance`]). Zero (the default): the mechanization's model
/// is taken as the field.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct GravityDisturbanceSpec {
    /// Deflection of the vertical, each component (ξ north–south, η east–west), arcsec.
    pub deflection_sigma_arcsec: f64,
    /// Gravity anomaly (the vertical component), mGal.
    pub anomaly_sigma_mgal: f64,
    /// Correlation distance of the field along the track, km (used when a σ is non-zero).
    pub correlation_distance_km: f64,
}

impl GravityDisturbanceSpec {
    /// The statistics in SI units, horizontal `γ·ξ` with the standard gravity.
    pub fn disturbance(&self) -> crate::ekf::GravityDisturbance {
        crate::ekf::GravityDisturbance {
            horizontal_sigma_m_s2: self.deflection_sigma_arcsec / 3600.0 * DEG * G0,
            vertical_sigma_m_s2: self.anomaly_sigma_mgal * 1e-5,
            correlation_distance_m: self.correlation_distance_km * 1e3,
        }
    }
}

/// A configured initial position (used for alignment when no GNSS fix is wanted or available).
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct InitialPosition {
    /// Geodetic latitude, deg.
    pub lat_deg: f64,
    /// Longitude, deg.
    pub lon_deg: f64,
    /// Height above the ellipsoid, m.
    pub height_m: f64,
}

/// Everything the navigator needs to know, from the filter tuning file (`config/filter.toml`).
/// Deserialized from TOML (unknown keys are errors; omitted keys take the defaults, which
/// match `config/filter.toml`); `validate` checks its meaning.
#[derive(Debug, Clone, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct NavigatorConfig {
    /// Static coarse-alignment time before navigation starts, s.
    pub alignment_s: f64,
    /// Reference ellipsoid for the mechanization and the outputs.
    pub ellipsoid: EllipsoidName,
    /// Gravity model of the mechanization.
    pub gravity: GravityModel,
    /// Integrator of the mechanization.
    pub integrator: Integrator,
    /// Coning and sculling corrections.
    pub coning_sculling: bool,
    /// Probability of the chi-square innovation gate (e.g. 0.999; 1 disables gating).
    pub gate_probability: f64,
    /// How far behind the IMU time a sample may arrive and still be fused, s (≤ 2).
    pub buffer_window_s: f64,
    /// Highest IMU sample rate the delayed-fusion log is sized for, Hz: it keeps
    /// `max_imu_rate_hz × (buffer_window_s + 0.2 s)` steps ([`NavigatorConfig::imu_log_capacity`]).
    /// A faster IMU makes a late sample impossible to replay; it is then dropped and counted
    /// (`replays_impossible` in [`NavigatorDiagnostics`]).
    pub max_imu_rate_hz: f64,
    /// Covariance propagation interval, s: the transition is accumulated over IMU steps and
    /// the covariance propagated at this interval and before every update ([`crate::ekf`]).
    pub covariance_interval_s: f64,
    /// GNSS coupling.
    pub gnss_mode: GnssMode,
    /// GNSS antenna installation (lever arm).
    pub gnss: GnssInstallation,
    /// Estimated state groups.
    pub states: StateSwitches,
    /// Initial position for alignment; when absent, the first valid GNSS fix is used.
    pub initial_position: Option<InitialPosition>,
    /// Earth orientation parameters (UT1 − UTC, polar motion) for the star-tracker model.
    pub eop: EarthOrientation,
    /// IMU error specification.
    pub imu: ImuSpec,
    /// Initial uncertainties.
    pub initial: InitialUncertainty,
    /// Enabled measurement updates.
    pub updates: UpdateSwitches,
    /// Aiding noise and scheduling.
    pub aiding: AidingNoise,
    /// The ground vehicle: odometer wheel lever arm and the class's departures from the
    /// non-holonomic constraint.
    pub vehicle: VehicleModel,
    /// Aiding deadlines for the navigation mode.
    pub deadlines: Deadlines,
    /// Time-tag latency of each aiding sensor, compensated at fusion.
    pub latency: Latency,
    /// The region's gravity disturbance, absorbed by the accelerometer-bias states.
    pub gravity_disturbance: GravityDisturbanceSpec,
    /// Redundant-channel fault detection (paper 004; used when the IMU has channels).
    pub redundancy: crate::redundancy::RedundancyConfig,
    /// Alignment in motion from the star tracker and GNSS.
    pub motion_alignment: MotionAlignment,
    /// Resumption from a snapshot after a restart.
    pub warm_start: WarmStartConfig,
    /// A previous run's sensor errors as the prior of the next start.
    pub calibration_memory: super::CalibrationMemoryConfig,
}

impl Default for NavigatorConfig {
    fn default() -> Self {
        Self {
            alignment_s: 100.0,
            ellipsoid: EllipsoidName::Wgs84,
            gravity: GravityModel::J2,
            integrator: Integrator::Rk4,
            coning_sculling: true,
            gate_probability: 0.999,
            buffer_window_s: 1.0,
            max_imu_rate_hz: 2000.0,
            covariance_interval_s: 0.05,
            gnss_mode: GnssMode::Loose,
            gnss: GnssInstallation::default(),
            states: StateSwitches::default(),
            initial_position: None,
            eop: EarthOrientation::default(),
            imu: ImuSpec::default(),
            initial: InitialUncertainty::default(),
            updates: UpdateSwitches::default(),
            aiding: AidingNoise::default(),
            vehicle: VehicleModel::default(),
            deadlines: Deadlines::default(),
            latency: Latency::default(),
            gravity_disturbance: GravityDisturbanceSpec::default(),
            redundancy: crate::redundancy::RedundancyConfig::default(),
            motion_alignment: MotionAlignment::default(),
            warm_start: WarmStartConfig::default(),
            calibration_memory: super::CalibrationMemoryConfig::default(),
        }
    }
}

impl NavigatorConfig {
    /// This tuning on the idealised vehicle of the built-in defaults: every sensor at the IMU
    /// and stamped at its time of validity, GNSS and star-tracker errors white, a barometer in
    /// the standard atmosphere (no weather to drift with, no height scale error), gravity as
    /// the mechanization's model, the simulator's nominal receiver clock. The rest
    /// (IMU class, gates, switches, noise of the samples) is kept. A real vehicle's
    /// configuration (`config/filter.toml` is the default car's) states each of these.
    pub fn idealised(mut self) -> Self {
        let d = Self::default();
        self.gnss = d.gnss;
        self.latency = d.latency;
        self.gravity_disturbance = d.gravity_disturbance;
        self.vehicle.wheel_lever_arm_b_m = d.vehicle.wheel_lever_arm_b_m;
        let a = &mut self.aiding;
        a.baro_bias_rw_m_sqrt_s = d.aiding.baro_bias_rw_m_sqrt_s;
        a.baro_scale_sigma = d.aiding.baro_scale_sigma;
        a.star_low_frequency_sigma_arcsec = d.aiding.star_low_frequency_sigma_arcsec;
        a.star_low_frequency_correlation_time_s = d.aiding.star_low_frequency_correlation_time_s;
        a.star_roll_bias_sigma_arcsec = d.aiding.star_roll_bias_sigma_arcsec;
        a.clock_bias_psd_m2_s = d.aiding.clock_bias_psd_m2_s;
        a.clock_drift_psd_m2_s3 = d.aiding.clock_drift_psd_m2_s3;
        self
    }
}

impl NavigatorConfig {
    /// 1-σ of the horizontal specific-force error a levelling sees per axis, m/s²: the
    /// accelerometer bias and the deflection of the vertical (`[gravity_disturbance]`), which
    /// a level cannot tell apart.
    pub fn leveling_accel_error_m_s2(&self) -> f64 {
        let dg = self.gravity_disturbance.disturbance().horizontal_sigma_m_s2;
        self.imu.accel_bias_m_s2().hypot(dg)
    }

    /// IMU steps the delayed-fusion log keeps: every step from the checkpoint before the oldest
    /// sample still fused (up to `buffer_window_s` behind, the checkpoint up to one period
    /// before it, the rewind one IMU step after the arrival) to now, at `max_imu_rate_hz`, with
    /// a second checkpoint period and two steps of margin.
    pub fn imu_log_capacity(&self) -> usize {
        let period_s = CHECKPOINT_PERIOD.seconds_f64();
        let steps = (self.max_imu_rate_hz * (self.buffer_window_s + 2.0 * period_s)).ceil();
        // Saturating: an absurd rate fails the IMU_LOG_MAX_CAP check, never overflows.
        if steps.is_finite() && steps < IMU_LOG_MAX_CAP as f64 {
            steps as usize + 2
        } else {
            IMU_LOG_MAX_CAP + 1
        }
    }

    /// Checkpoints the delayed-fusion ring keeps: at most two per period (one per
    /// [`CHECKPOINT_PERIOD`], and before the updates of an epoch with aiding due when the last
    /// is at least [`EPOCH_CHECKPOINT_SPACING`] old; an IMU slower than that spaces them
    /// wider, covering more), enough to reach back over `buffer_window_s` plus two periods,
    /// with two of margin. Sized from the window, not for the longest one allowed: each
    /// checkpoint is a copy of the navigation core (≈ 9.7 kB), and a ring larger than it needs
    /// to be spreads the writes over more memory than the processor's cache keeps (106 for the
    /// 1 s window, ≈ 1 MB).
    pub fn checkpoint_capacity(&self) -> usize {
        let period_s = CHECKPOINT_PERIOD.seconds_f64();
        let spacing_s = EPOCH_CHECKPOINT_SPACING.seconds_f64();
        // buffer_window_s is validated to (0, 2]; anything else gets the 2 s ring.
        let window_s = if self.buffer_window_s.is_finite() {
            self.buffer_window_s.clamp(0.0, 2.0)
        } else {
            2.0
        };
        ((window_s + 2.0 * period_s) / spacing_s).ceil() as usize + 2
    }

    /// Mechanization settings derived from this configuration.
    pub fn mechanization(&self) -> MechanizationConfig {
        MechanizationConfig {
            ellipsoid: self.ellipsoid.ellipsoid(),
            gravity: self.gravity,
            integrator: self.integrator,
            coning_sculling: self.coning_sculling,
        }
    }
}
