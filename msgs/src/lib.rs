//! Message types shared by every Sextant process, their JSON Schemas, and service names.
//!
//! Every message is a plain `#[repr(C)]` struct of fixed size (no pointers, no heap) so that it
//! crosses iceoryx2 shared memory without copies. The recorder writes it to MCAP in its
//! protobuf form ([`protobuf`], with its descriptor) or as JSON (`serde` + `schemars`, with a
//! JSON Schema). Every message starts with a
//! [`Header`] carrying its *time of validity* in GPS nanoseconds, a sequence number and a
//! driver-set status word.
//!
//! Conventions (DESIGN.md "Frames and conventions"): SI units, angles in radians, quaternions
//! Hamilton with the scalar first (`[w, x, y, z]`). A quaternion field named `q_a_b` rotates
//! coordinates from frame `b` into frame `a` (`v_a = q_a_b ⊗ v_b ⊗ q_a_b*`), the same way
//! `c_n_b` maps body coordinates into NED.

pub mod ipc;
pub mod ipc_service;
pub mod protobuf;
pub mod record;
/// The service manager's notification protocol (readiness, watchdog pings), spoken by every
/// Sextant process to `sextant run` or to systemd.
pub mod sd_notify;

pub use record::{Record, RecordKind, SENSOR_ALIVE_TOPIC, SensorAliveEvent};

use iceoryx2::prelude::ZeroCopySend;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Maximum number of single-axis inertial channels in one IMU sample (paper 004 uses 4).
pub const MAX_IMU_CHANNELS: usize = 8;
/// Maximum number of satellites in one GNSS sample.
pub const MAX_SATELLITES: usize = 32;
/// Number of sensor slots in [`Status`] (indexed by [`SensorId`]).
pub const MAX_SENSORS: usize = 8;
/// Speed of light in vacuum, m/s (IS-GPS-200).
pub const SPEED_OF_LIGHT_M_S: f64 = 299_792_458.0;

/// Common header of every message.
#[repr(C)]
#[derive(
    Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Serialize, Deserialize, JsonSchema,
)]
#[type_name("sextant::Header")]
pub struct Header {
    /// Time of validity of the sample: GPS time, nanoseconds since the GPS epoch
    /// (1980-01-06T00:00:00 UTC).
    pub time_ns: i64,
    /// Sequence number, incremented by one per message by its publisher.
    pub seq: u64,
    /// Driver-set status word (bit meanings per message; 0 = nominal).
    pub status: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// CLOCK_MONOTONIC of the publishing process when the message was sent, ns. Used only to
    /// measure latency across processes on one machine; never used by the navigation math.
    pub send_mono_ns: u64,
}

/// Inertial sample: delta-angle and delta-velocity over the interval ending at `time_ns`,
/// as navigation-grade IMUs output them, in the IMU body frame (x forward, y right, z down).
/// Skewed (redundant) layouts fill the per-channel arrays; the orthogonal triad fills the
/// vectors (and may leave `n_channels` = 0).
#[repr(C)]
#[derive(
    Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Serialize, Deserialize, JsonSchema,
)]
#[type_name("sextant::ImuSample")]
pub struct ImuSample {
    /// Header; `time_ns` is the end of the integration interval.
    pub header: Header,
    /// Length of the integration interval, s.
    pub dt_s: f64,
    /// Integrated angular rate (inertial, in body axes) over the interval, rad.
    pub delta_angle_rad: [f64; 3],
    /// Integrated specific force in body axes over the interval, m/s.
    pub delta_velocity_m_s: [f64; 3],
    /// Number of valid single-axis channels (0 = orthogonal triad only).
    pub n_channels: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// Unit sensitive axis of each channel in body axes.
    pub channel_axis: [[f64; 3]; MAX_IMU_CHANNELS],
    /// Delta-angle of each single-axis gyro channel, rad.
    pub channel_delta_angle_rad: [f64; MAX_IMU_CHANNELS],
    /// Delta-velocity of each single-axis accelerometer channel, m/s.
    pub channel_delta_velocity_m_s: [f64; MAX_IMU_CHANNELS],
    /// Temperature of each channel, °C.
    pub channel_temperature_c: [f64; MAX_IMU_CHANNELS],
    /// Turntable angle about the vertical at `time_ns`, rad (0 when there is no turntable).
    pub turntable_angle_rad: f64,
}

/// Star-tracker attitude solution.
#[repr(C)]
#[derive(
    Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Serialize, Deserialize, JsonSchema,
)]
#[type_name("sextant::StarTrackerSample")]
pub struct StarTrackerSample {
    /// Header; `time_ns` is the exposure mid-time.
    pub header: Header,
    /// Attitude quaternion ICRF → sensor (`v_sensor = q ⊗ v_icrf ⊗ q*`), `[w, x, y, z]`:
    /// fusion's `c_s_i`, a `frames::Rotation<Icrf, StarSensor>`.
    pub q_sensor_icrf: [f64; 4],
    /// 1-σ error about the two axes across the optical axis, rad.
    pub sigma_cross_rad: f64,
    /// 1-σ error about the optical (boresight) axis, rad.
    pub sigma_roll_rad: f64,
    /// Number of stars identified.
    pub n_stars: u32,
    /// 1 when the attitude is valid, 0 otherwise (no stars, sun in view, …).
    pub valid: u32,
}

/// One satellite's raw GNSS measurements.
#[repr(C)]
#[derive(
    Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Serialize, Deserialize, JsonSchema,
)]
#[type_name("sextant::GnssSatellite")]
pub struct GnssSatellite {
    /// Satellite number (GPS PRN).
    pub prn: u32,
    /// Bit 0: pseudorange valid; bit 1: Doppler valid; bit 2: baseline phases valid.
    pub flags: u32,
    /// Pseudorange, m (geometric range + c·receiver clock bias + errors).
    pub pseudorange_m: f64,
    /// Pseudorange rate from Doppler, m/s (range rate + c·receiver clock drift + errors).
    pub range_rate_m_s: f64,
    /// Carrier-to-noise density, dB-Hz.
    pub cn0_dbhz: f64,
    /// 1-σ pseudorange noise, m.
    pub sigma_pseudorange_m: f64,
    /// 1-σ range-rate noise, m/s.
    pub sigma_range_rate_m_s: f64,
    /// Satellite ECEF position at transmission, rotated into the ECEF frame at reception, m.
    pub sat_pos_ecef_m: [f64; 3],
    /// Satellite ECEF velocity, m/s.
    pub sat_vel_ecef_m_s: [f64; 3],
    /// Carrier phase difference across the two antenna baselines (AB, CD), cycles, as a
    /// receiver measures it: the fractional phase plus an unknown integer number of cycles,
    /// constant while the phase is tracked continuously (a cycle slip changes it).
    pub baseline_phase_cycles: [f64; 2],
    /// Continuous carrier-phase lock time of each baseline phase difference (AB, CD), s, as
    /// receivers report it (RINEX loss-of-lock indicator, u-blox `locktime`): it restarts from
    /// zero when tracking restarts or the receiver detects a cycle slip, so a value below the
    /// epoch interval, or one that decreased, means the integer may have changed. A slip the
    /// receiver misses leaves it running. 0 without baseline phases.
    #[serde(default)]
    pub phase_lock_time_s: [f64; 2],
}

/// GNSS receiver output: position/velocity fix with covariance, and raw per-satellite data.
#[repr(C)]
#[derive(
    Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Serialize, Deserialize, JsonSchema,
)]
#[type_name("sextant::GnssSample")]
pub struct GnssSample {
    /// Header; `time_ns` is the measurement epoch (receiver time corrected to GPS time).
    pub header: Header,
    /// 1 when the position/velocity fix is valid.
    pub fix_valid: u32,
    /// Number of valid entries in `satellites`.
    pub n_satellites: u32,
    /// Antenna position, ECEF, m.
    pub pos_ecef_m: [f64; 3],
    /// Antenna velocity, ECEF, m/s.
    pub vel_ecef_m_s: [f64; 3],
    /// Position covariance in ECEF, row-major 3×3, m².
    pub pos_cov_ecef_m2: [f64; 9],
    /// Velocity covariance in ECEF, row-major 3×3, (m/s)².
    pub vel_cov_ecef_m2_s2: [f64; 9],
    /// Position dilution of precision of the fix.
    pub pdop: f64,
    /// Baseline lengths of the two antenna pairs AB and CD, m (0 when absent).
    pub baseline_length_m: [f64; 2],
    /// Carrier wavelength used for the baseline phases, m.
    pub wavelength_m: f64,
    /// Raw measurements, first `n_satellites` valid.
    pub satellites: [GnssSatellite; MAX_SATELLITES],
}

/// Odometer / speed-meter sample.
#[repr(C)]
#[derive(
    Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Serialize, Deserialize, JsonSchema,
)]
#[type_name("sextant::OdometerSample")]
pub struct OdometerSample {
    /// Header; `time_ns` is the end of the counting interval.
    pub header: Header,
    /// Counting interval, s.
    pub dt_s: f64,
    /// Distance travelled along the body x axis over the interval, m.
    pub distance_m: f64,
    /// Forward speed (distance / interval), m/s.
    pub speed_m_s: f64,
}

/// Barometric sample.
#[repr(C)]
#[derive(
    Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Serialize, Deserialize, JsonSchema,
)]
#[type_name("sextant::BaroSample")]
pub struct BaroSample {
    /// Header.
    pub header: Header,
    /// Static pressure, Pa.
    pub pressure_pa: f64,
    /// Static air temperature, °C.
    pub temperature_c: f64,
}

/// Simulated truth (evaluation only: the fusion filter never reads it).
#[repr(C)]
#[derive(
    Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Serialize, Deserialize, JsonSchema,
)]
#[type_name("sextant::TruthSample")]
pub struct TruthSample {
    /// Header.
    pub header: Header,
    /// Geodetic latitude, rad (WGS-84).
    pub lat_rad: f64,
    /// Longitude, rad.
    pub lon_rad: f64,
    /// Height above the ellipsoid, m.
    pub height_m: f64,
    /// Position, ECEF, m.
    pub pos_ecef_m: [f64; 3],
    /// Velocity relative to the Earth in NED, m/s.
    pub vel_ned_m_s: [f64; 3],
    /// Attitude body → NED, `[w, x, y, z]` (Hamilton): `v_ned = q ⊗ v_body ⊗ q*`, the NED frame
    /// being the local level at (`lat_rad`, `lon_rad`). This is fusion's `q_n_b`
    /// (`attitude::q_n_b_from_rpy`); fusion's navigation state carries `q_e_b` (body → ECEF),
    /// and `q_n_b = q_e_n⁻¹ ⊗ q_e_b`.
    pub q_ned_body: [f64; 4],
    /// Roll, pitch, heading (z-y-x Euler angles of `q_ned_body`), rad.
    pub roll_pitch_heading_rad: [f64; 3],
    /// True gyro bias in body axes, rad/s.
    pub gyro_bias_rad_s: [f64; 3],
    /// True accelerometer bias in body axes, m/s².
    pub accel_bias_m_s2: [f64; 3],
}

/// Navigation mode of the solution.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NavMode {
    /// Waiting for the first IMU samples.
    Initializing = 0,
    /// Static coarse alignment in progress.
    Aligning = 1,
    /// Navigation with no aiding: free inertial.
    FreeInertial = 2,
    /// Navigation aided by GNSS (and possibly other sensors), no stars.
    GnssInertial = 3,
    /// Navigation aided by stars, no GNSS.
    AstroInertial = 4,
    /// Navigation aided by GNSS and stars.
    GnssAstroInertial = 5,
    /// Navigation aided only by odometer/baro (no absolute position nor attitude).
    DeadReckoning = 6,
}

impl NavMode {
    /// Every mode, in wire-value order.
    pub const ALL: [NavMode; 7] = [
        Self::Initializing,
        Self::Aligning,
        Self::FreeInertial,
        Self::GnssInertial,
        Self::AstroInertial,
        Self::GnssAstroInertial,
        Self::DeadReckoning,
    ];
    /// Decode the wire value, `None` for an unknown one.
    pub fn from_u32(v: u32) -> Option<Self> {
        Self::ALL.into_iter().find(|m| *m as u32 == v)
    }
    /// Short human name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Initializing => "initializing",
            Self::Aligning => "aligning",
            Self::FreeInertial => "free-inertial",
            Self::GnssInertial => "gnss-inertial",
            Self::AstroInertial => "astro-inertial",
            Self::GnssAstroInertial => "gnss-astro-inertial",
            Self::DeadReckoning => "dead-reckoning",
        }
    }
}

/// Fusion solution.
#[repr(C)]
#[derive(
    Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Serialize, Deserialize, JsonSchema,
)]
#[type_name("sextant::NavSolution")]
pub struct NavSolution {
    /// Header; `time_ns` is the time of validity (that of the last IMU sample used).
    pub header: Header,
    /// [`NavMode`] as u32.
    pub mode: u32,
    /// Bit set of aiding sensors fused within their deadline, bit = [`SensorId`] index.
    pub aiding_mask: u32,
    /// Geodetic latitude, rad (WGS-84 unless configured otherwise).
    pub lat_rad: f64,
    /// Longitude, rad.
    pub lon_rad: f64,
    /// Height above the ellipsoid, m.
    pub height_m: f64,
    /// Position, ECEF, m.
    pub pos_ecef_m: [f64; 3],
    /// Velocity relative to the Earth in NED, m/s.
    pub vel_ned_m_s: [f64; 3],
    /// Attitude body → NED, `[w, x, y, z]` (Hamilton): `v_ned = q ⊗ v_body ⊗ q*`, the NED frame
    /// being the local level at (`lat_rad`, `lon_rad`). This is fusion's `q_n_b`, obtained from
    /// the filter's body → ECEF attitude `q_e_b` as `q_n_b = q_e_n⁻¹ ⊗ q_e_b`.
    pub q_ned_body: [f64; 4],
    /// Roll, pitch, heading, rad.
    pub roll_pitch_heading_rad: [f64; 3],
    /// 1-σ position error north, east, down, m.
    pub pos_sigma_ned_m: [f64; 3],
    /// 1-σ velocity error north, east, down, m/s.
    pub vel_sigma_ned_m_s: [f64; 3],
    /// 1-σ attitude error about north, east, down, rad.
    pub att_sigma_ned_rad: [f64; 3],
    /// Estimated gyro bias in body axes, rad/s.
    pub gyro_bias_rad_s: [f64; 3],
    /// Estimated accelerometer bias in body axes, m/s².
    pub accel_bias_m_s2: [f64; 3],
    /// `send_mono_ns` of the IMU sample this solution was computed from (for latency).
    pub imu_send_mono_ns: u64,
    /// 1-σ of the gyro bias estimate, body axes, rad/s.
    pub gyro_bias_sigma_rad_s: [f64; 3],
    /// 1-σ of the accelerometer bias estimate, body axes, m/s².
    pub accel_bias_sigma_m_s2: [f64; 3],
    /// Estimated gyro scale-factor error per body axis, ppm (0 when the state is off).
    pub gyro_scale_ppm: [f64; 3],
    /// Estimated accelerometer scale-factor error per body axis, ppm (0 when the state is off).
    pub accel_scale_ppm: [f64; 3],
    /// Estimated star-tracker boresight angles κ1, κ2, κ3 (paper 000), rad.
    pub boresight_rad: [f64; 3],
    /// 1-σ of the boresight estimate, rad (0 when the state is off).
    pub boresight_sigma_rad: [f64; 3],
    /// Receiver clock bias times c, m (0 when the state is off).
    pub clock_bias_m: f64,
    /// Receiver clock drift times c, m/s.
    pub clock_drift_m_s: f64,
    /// Estimated baro bias, m.
    pub baro_bias_m: f64,
    /// Estimated odometer scale-factor error (dimensionless; 0 = perfect).
    pub odometer_scale: f64,
    /// 1 when the daemon published this solution later than `fusion.stale_after_ms` (of
    /// simulated time; never less than 20 ms of wall time) behind its time of validity, relative
    /// to the fastest delivery it has seen: it was catching up on a backlog (after a stall of
    /// its own, or a driver's overdue burst). A consumer steering by the solution must not take
    /// it as current. Its latency is `header.send_mono_ns − imu_send_mono_ns`. Set from the
    /// wall clock at publication, so an offline replay does not reproduce it.
    #[serde(default)]
    pub stale: u32,
    /// Position error covariance in NED, m², its six distinct elements (the matrix is
    /// symmetric) `[NN, NE, ND, EE, ED, DD]`: the diagonal is `pos_sigma_ned_m` squared, the
    /// rest the correlations between the axes (a GNSS-aided solution's horizontal error is
    /// an ellipse, seldom aligned with north and east). All zero in recordings made before it
    /// was carried (serde default); [`NavSolution::pos_cov_ned_matrix_m2`] gives the 3×3 form.
    #[serde(default)]
    pub pos_cov_ned_m2: [f64; 6],
}

impl NavSolution {
    /// Index of each element of the NED position covariance, row-major 3×3, in
    /// [`NavSolution::pos_cov_ned_m2`].
    const POS_COV_INDEX: [[usize; 3]; 3] = [[0, 1, 2], [1, 3, 4], [2, 4, 5]];

    /// The position error covariance in NED as a 3×3 matrix, m² (`[row][column]`, rows and
    /// columns north, east, down).
    pub fn pos_cov_ned_matrix_m2(&self) -> [[f64; 3]; 3] {
        Self::POS_COV_INDEX.map(|row| row.map(|k| self.pos_cov_ned_m2[k]))
    }

    /// Store the NED position covariance `p` (m², `[row][column]` north, east, down) in
    /// [`NavSolution::pos_cov_ned_m2`], symmetrized: each off-diagonal element is the mean of
    /// `p[i][j]` and `p[j][i]`, which differ only by rounding.
    pub fn set_pos_cov_ned_m2(&mut self, p: &[[f64; 3]; 3]) {
        for (i, row) in Self::POS_COV_INDEX.iter().enumerate() {
            for (j, &k) in row.iter().enumerate().skip(i) {
                self.pos_cov_ned_m2[k] = if i == j {
                    p[i][i]
                } else {
                    0.5 * (p[i][j] + p[j][i])
                };
            }
        }
    }

    /// Whether the solution carries its position covariance (false for a recording made
    /// before the solution carried it: all six elements zero).
    pub fn has_pos_cov(&self) -> bool {
        self.pos_cov_ned_m2.iter().any(|&v| v != 0.0)
    }
}

/// Sensor slots used in [`Status`] and bit masks.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SensorId {
    /// Inertial measurement unit.
    Imu = 0,
    /// Star tracker.
    StarTracker = 1,
    /// GNSS receiver.
    Gnss = 2,
    /// Odometer / speed meter.
    Odometer = 3,
    /// Barometer.
    Baro = 4,
}

impl SensorId {
    /// Number of sensors (≤ [`MAX_SENSORS`], the slots of the wire format).
    pub const COUNT: usize = 5;
    /// Every sensor, in slot order.
    pub const ALL: [SensorId; Self::COUNT] = [
        SensorId::Imu,
        SensorId::StarTracker,
        SensorId::Gnss,
        SensorId::Odometer,
        SensorId::Baro,
    ];
    /// The sensor of slot `i`, `None` past the last.
    pub fn from_index(i: usize) -> Option<Self> {
        Self::ALL.get(i).copied()
    }
    /// Short name (that of its channel).
    pub const fn name(self) -> &'static str {
        self.channel().name()
    }
    /// The channel the sensor publishes on.
    pub const fn channel(self) -> Channel {
        match self {
            Self::Imu => Channel::Imu,
            Self::StarTracker => Channel::StarTracker,
            Self::Gnss => Channel::Gnss,
            Self::Odometer => Channel::Odometer,
            Self::Baro => Channel::Baro,
        }
    }
}

const _: () = assert!(SensorId::COUNT <= MAX_SENSORS);

/// One value per sensor, indexed by [`SensorId`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PerSensor<T>(pub [T; SensorId::COUNT]);

impl<T: Copy> PerSensor<T> {
    /// `value` for every sensor.
    pub const fn splat(value: T) -> Self {
        Self([value; SensorId::COUNT])
    }
}

impl<T> PerSensor<T> {
    /// Each sensor with its value, in slot order.
    pub fn iter(&self) -> impl Iterator<Item = (SensorId, &T)> {
        SensorId::ALL.into_iter().zip(self.0.iter())
    }
}

/// Written as a table keyed by [`SensorId::name`] in slot order (`imu = …, star_tracker = …`).
impl<T: Serialize> Serialize for PerSensor<T> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut map = serializer.serialize_map(Some(SensorId::COUNT))?;
        for (s, v) in self.iter() {
            map.serialize_entry(s.name(), v)?;
        }
        map.end()
    }
}

/// Read from a table with every sensor's name exactly once and no other key.
impl<'de, T: Deserialize<'de>> Deserialize<'de> for PerSensor<T> {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Visit<T>(core::marker::PhantomData<T>);
        const NAMES: [&str; SensorId::COUNT] = {
            let mut n = [""; SensorId::COUNT];
            let mut i = 0;
            while i < SensorId::COUNT {
                n[i] = SensorId::ALL[i].name();
                i += 1;
            }
            n
        };
        impl<'de, T: Deserialize<'de>> serde::de::Visitor<'de> for Visit<T> {
            type Value = PerSensor<T>;
            fn expecting(&self, f: &mut core::fmt::Formatter) -> core::fmt::Result {
                f.write_str("a table with one value per sensor")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                mut map: A,
            ) -> Result<Self::Value, A::Error> {
                use serde::de::Error;
                let mut values: [Option<T>; SensorId::COUNT] = Default::default();
                while let Some(key) = map.next_key::<String>()? {
                    let Some(i) = NAMES.iter().position(|n| *n == key) else {
                        return Err(A::Error::unknown_field(&key, &NAMES));
                    };
                    if values[i].is_some() {
                        return Err(A::Error::duplicate_field(NAMES[i]));
                    }
                    values[i] = Some(map.next_value()?);
                }
                let mut out = Vec::with_capacity(SensorId::COUNT);
                for (i, v) in values.into_iter().enumerate() {
                    out.push(v.ok_or_else(|| A::Error::missing_field(NAMES[i]))?);
                }
                let Ok(arr) = out.try_into() else {
                    unreachable!("one value per sensor");
                };
                Ok(PerSensor(arr))
            }
        }
        deserializer.deserialize_map(Visit(core::marker::PhantomData))
    }
}

impl<T> core::ops::Index<SensorId> for PerSensor<T> {
    type Output = T;
    fn index(&self, s: SensorId) -> &T {
        &self.0[s as usize]
    }
}

impl<T> core::ops::IndexMut<SensorId> for PerSensor<T> {
    fn index_mut(&mut self, s: SensorId) -> &mut T {
        &mut self.0[s as usize]
    }
}

/// Per-sensor health counters.
#[repr(C)]
#[derive(
    Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Serialize, Deserialize, JsonSchema,
)]
#[type_name("sextant::SensorHealth")]
pub struct SensorHealth {
    /// Samples received.
    pub received: u64,
    /// Samples fused into the filter.
    pub fused: u64,
    /// Samples rejected by the innovation gate.
    pub rejected_gate: u64,
    /// Samples rejected as malformed (NaN, impossible values, time backwards, duplicates).
    pub rejected_invalid: u64,
    /// Samples dropped because they were older than the delayed-fusion buffer.
    pub dropped_late: u64,
    /// Time of validity of the last sample received, GPS ns (0 = never).
    pub last_time_ns: i64,
    /// 1 when the sensor delivered within its deadline, 0 when silent.
    pub alive: u32,
    /// Number of deadline misses so far.
    pub deadline_misses: u32,
    /// Normalized innovation squared of the last update.
    pub last_nis: f64,
    /// Sum of the NIS of all updates of this sensor (mean NIS = sum / count).
    pub nis_sum: f64,
    /// Number of updates summed in `nis_sum`.
    pub nis_count: u64,
    /// Sum of the measurement dimensions of those updates (the expected NIS sum).
    pub nis_dof_sum: u64,
    /// Samples missing by sequence number: each accepted sample whose `seq` jumps ahead of the
    /// previous one adds the number skipped (lost in transport, e.g. a flood overrunning the
    /// subscriber's buffer, or never sent). A restarted driver's sequence starting over adds 0.
    pub seq_gaps: u64,
}

/// Fusion health, published at 1 Hz.
#[repr(C)]
#[derive(
    Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, Serialize, Deserialize, JsonSchema,
)]
#[type_name("sextant::Status")]
pub struct Status {
    /// Header (`time_ns` = filter time).
    pub header: Header,
    /// [`NavMode`] as u32.
    pub mode: u32,
    /// Bit set of sensors alive, bit = [`SensorId`] index.
    pub alive_mask: u32,
    /// Solutions published.
    pub solutions_published: u64,
    /// Records written to the recording.
    pub records_written: u64,
    /// Records dropped because the recorder could not keep up or the disk failed.
    pub records_dropped: u64,
    /// Per-sensor counters, indexed by [`SensorId`].
    pub sensors: [SensorHealth; MAX_SENSORS],
    /// Redundant IMU (paper 004): bit i set = channel i excluded after fault isolation.
    pub imu_channels_excluded_mask: u32,
    /// Redundant IMU: bit i set = channel i currently flagged by the parity test.
    pub imu_channels_suspect_mask: u32,
    /// Redundant IMU: parity-space faults detected so far.
    pub imu_faults_detected: u64,
    /// Status messages or solutions the recorder could not write (disk full, unwritable), also
    /// counted in `records_dropped`; nonzero means the recording is incomplete.
    pub recorder_errors: u64,
    /// Receiver-style least-squares fixes (paper 003 eq. 12–13) compared with the filter's
    /// predicted position (cross-check of the GNSS aiding).
    pub gnss_ls_checks: u64,
    /// Of those, the ones whose position difference failed the 3-dof chi-square test against
    /// the filter covariance plus the fix covariance.
    pub gnss_ls_disagreements: u64,
    /// Normalized squared position difference (3 dof) of the last cross-check.
    pub gnss_ls_last_nis: f64,
    /// Position dilution of precision of the last least-squares fix.
    pub gnss_ls_pdop: f64,
    /// Times the navigator started over (re-alignment after a gap it cannot bridge).
    pub reinitializations: u64,
    /// Zero-velocity pseudo-measurements fused while static.
    pub zupt_fused: u64,
    /// Zero-velocity pseudo-measurements rejected by the gate.
    pub zupt_rejected_gate: u64,
    /// Non-holonomic constraint updates (zero lateral/vertical body velocity) fused.
    pub nhc_fused: u64,
    /// Non-holonomic constraint updates rejected by the gate.
    pub nhc_rejected_gate: u64,
    /// Sum of the NIS of the fused constraint updates (2 dof each: mean NIS/dof =
    /// nhc_nis_sum / (2·nhc_fused)).
    pub nhc_nis_sum: f64,
    /// Solutions published with the `stale` flag (see [`NavSolution::stale`]).
    #[serde(default)]
    pub solutions_stale: u64,
    /// Starts of navigation in motion (star-tracker attitude or GNSS heading, with a GNSS
    /// position and velocity), at the first start or after a gap or restart.
    #[serde(default)]
    pub motion_alignments: u64,
    /// Of those, the ones without a star attitude: heading from GNSS velocity.
    #[serde(default)]
    pub gnss_heading_alignments: u64,
    /// Starts of navigation that resumed the sensor-error estimates from a checkpoint.
    #[serde(default)]
    pub warm_starts: u64,
    /// IMU samples held and rejected as candidates of a new time base after a forward jump of
    /// their time of validity (also in the IMU's `rejected_invalid`): `CONFIRM_SAMPLES − 1`
    /// per confirmed discontinuity, fewer for a candidate run that was cut short.
    #[serde(default)]
    pub imu_held_at_time_jump: u64,
    /// Solutions whose latency (IMU sample's `send_mono_ns` to the solution's) this daemon
    /// has measured since it started: every solution it computed from a stamped IMU sample,
    /// recorded or not (a recording may hold only some of them).
    #[serde(default)]
    pub latency_count: u64,
    /// Median of that latency over the `latency_count` solutions, µs (from a histogram of
    /// 64 logarithmic bins per octave: within 0.6 %).
    #[serde(default)]
    pub latency_p50_us: f64,
    /// 99th percentile of that latency, µs (same histogram).
    #[serde(default)]
    pub latency_p99_us: f64,
    /// Largest of that latency, µs (exact).
    #[serde(default)]
    pub latency_max_us: f64,
}

/// The logical channels of the system.
///
/// The declaration order (`Ord`) is the delivery order of simultaneous messages in every
/// time-ordered stream (the offline simulation, the daemon's drain of one wake-up): aiding
/// (star tracker, GNSS, odometer, baro) before the IMU sample of the same time, so that a
/// navigator fusing an aiding sample once the inertial solution reaches its time fuses it at
/// that IMU epoch; the truth after the IMU, so that the truth at `t` meets the solution already
/// propagated to `t`; the fusion's outputs last.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Channel {
    /// Star-tracker attitude.
    StarTracker,
    /// GNSS fix and raw measurements.
    Gnss,
    /// Odometer.
    Odometer,
    /// Barometer.
    Baro,
    /// IMU samples.
    Imu,
    /// Simulated truth.
    Truth,
    /// Navigation solution.
    Nav,
    /// Fusion health.
    Status,
}

impl Channel {
    /// Number of channels.
    pub const COUNT: usize = 8;
    /// Every channel, in delivery order.
    pub const ALL: [Channel; Self::COUNT] = [
        Channel::StarTracker,
        Channel::Gnss,
        Channel::Odometer,
        Channel::Baro,
        Channel::Imu,
        Channel::Truth,
        Channel::Nav,
        Channel::Status,
    ];
    /// The sensor channels a navigator fuses (IMU and the four aiding sensors), in delivery
    /// order: the inputs of an offline run with every aiding.
    pub const SENSORS: [Channel; 5] = [
        Channel::StarTracker,
        Channel::Gnss,
        Channel::Odometer,
        Channel::Baro,
        Channel::Imu,
    ];
    /// Channel name without prefix: the last component of the service name and the MCAP topic.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Imu => "imu",
            Self::StarTracker => "star_tracker",
            Self::Gnss => "gnss",
            Self::Odometer => "odometer",
            Self::Baro => "baro",
            Self::Truth => "truth",
            Self::Nav => "nav",
            Self::Status => "status",
        }
    }
    /// The sensor publishing on the channel (`None` for truth and the fusion's outputs).
    pub fn sensor(self) -> Option<SensorId> {
        SensorId::ALL.into_iter().find(|s| s.channel() == self)
    }
    /// Full iceoryx2 service name, e.g. `sextant/imu` for prefix `sextant`.
    pub fn service_name(self, prefix: &str) -> String {
        format!("{}/{}", prefix, self.name())
    }
    /// Parse a channel from its name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|c| c.name() == name)
    }
}

/// Implemented by every message that travels on a channel.
pub trait Message:
    ZeroCopySend + Copy + Default + core::fmt::Debug + Serialize + JsonSchema + 'static
{
    /// The channel this message travels on.
    const CHANNEL: Channel;
    /// Schema name used in recordings.
    const SCHEMA_NAME: &'static str;
    /// The message header.
    fn header(&self) -> &Header;
    /// Mutable header.
    fn header_mut(&mut self) -> &mut Header;

    // The shared-memory transport of this type, implemented once per message type in this
    // crate. Rust compiles a generic function again in every crate that uses it, and iceoryx2's
    // ports are generic over the payload: written generically, every process and test binary
    // compiled its own copy of the transport for each message type it uses (tens of seconds of
    // build each). Non-generic methods of a concrete type are compiled once, here. Use
    // [`ipc::Bus::publisher`], [`ipc::Bus::subscriber`], [`ipc::Pub`] and [`ipc::Sub`].
    #[doc(hidden)]
    fn open_publisher(bus: &ipc::Bus) -> Result<ipc::Pub<Self>, ipc::PublisherError>;
    #[doc(hidden)]
    fn open_subscriber(bus: &ipc::Bus) -> Result<ipc::Sub<Self>, ipc::SubscriberError>;
    #[doc(hidden)]
    fn send_on(publisher: &mut ipc::Pub<Self>, msg: Self) -> Result<(), ipc::SendError>;
    #[doc(hidden)]
    fn receive_on(subscriber: &ipc::Sub<Self>) -> Result<Option<Self>, ipc::ReceiveError>;
}

macro_rules! message {
    ($t:ty, $ch:expr, $name:literal) => {
        impl Message for $t {
            const CHANNEL: Channel = $ch;
            const SCHEMA_NAME: &'static str = $name;
            fn header(&self) -> &Header {
                &self.header
            }
            fn header_mut(&mut self) -> &mut Header {
                &mut self.header
            }
            fn open_publisher(bus: &ipc::Bus) -> Result<ipc::Pub<Self>, ipc::PublisherError> {
                ipc::publisher_of::<Self>(bus)
            }
            fn open_subscriber(bus: &ipc::Bus) -> Result<ipc::Sub<Self>, ipc::SubscriberError> {
                ipc::subscriber_of::<Self>(bus)
            }
            fn send_on(publisher: &mut ipc::Pub<Self>, msg: Self) -> Result<(), ipc::SendError> {
                ipc::send_raw_of::<Self>(publisher, msg)
            }
            fn receive_on(subscriber: &ipc::Sub<Self>) -> Result<Option<Self>, ipc::ReceiveError> {
                ipc::receive_of::<Self>(subscriber)
            }
        }
    };
}
message!(ImuSample, Channel::Imu, "sextant.ImuSample");
message!(
    StarTrackerSample,
    Channel::StarTracker,
    "sextant.StarTrackerSample"
);
message!(GnssSample, Channel::Gnss, "sextant.GnssSample");
message!(OdometerSample, Channel::Odometer, "sextant.OdometerSample");
message!(BaroSample, Channel::Baro, "sextant.BaroSample");
message!(TruthSample, Channel::Truth, "sextant.TruthSample");
message!(NavSolution, Channel::Nav, "sextant.NavSolution");
message!(Status, Channel::Status, "sextant.Status");

/// JSON Schema (draft 2020-12) of a message, as a JSON string.
pub fn json_schema<T: Message>() -> String {
    let schema = schemars::schema_for!(T);
    serde_json::to_string(&schema).unwrap_or_else(|_| "{}".to_string())
}

/// Schema name and JSON Schema of the message on a channel.
pub fn channel_schema(channel: Channel) -> (&'static str, String) {
    match channel {
        Channel::Imu => (ImuSample::SCHEMA_NAME, json_schema::<ImuSample>()),
        Channel::StarTracker => (
            StarTrackerSample::SCHEMA_NAME,
            json_schema::<StarTrackerSample>(),
        ),
        Channel::Gnss => (GnssSample::SCHEMA_NAME, json_schema::<GnssSample>()),
        Channel::Odometer => (OdometerSample::SCHEMA_NAME, json_schema::<OdometerSample>()),
        Channel::Baro => (BaroSample::SCHEMA_NAME, json_schema::<BaroSample>()),
        Channel::Truth => (TruthSample::SCHEMA_NAME, json_schema::<TruthSample>()),
        Channel::Nav => (NavSolution::SCHEMA_NAME, json_schema::<NavSolution>()),
        Channel::Status => (Status::SCHEMA_NAME, json_schema::<Status>()),
    }
}

/// Current CLOCK_MONOTONIC in nanoseconds (shared by all processes on one machine), for
/// latency stamps only.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc_timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes a timespec into the pointer we own.
    unsafe {
        clock_gettime(1, &mut ts);
    }
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

#[repr(C)]
struct libc_timespec {
    tv_sec: i64,
    tv_nsec: i64,
}
unsafe extern "C" {
    fn clock_gettime(clk: i32, ts: *mut libc_timespec) -> i32;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_channel_has_a_schema_that_parses() {
        for ch in Channel::ALL {
            let (name, schema) = channel_schema(ch);
            assert!(name.starts_with("sextant."));
            let v: serde_json::Value = serde_json::from_str(&schema).unwrap();
            assert!(v.get("properties").is_some(), "{name}: {schema}");
        }
    }

    #[test]
    fn json_round_trip_is_bit_exact() {
        let mut s = ImuSample {
            delta_angle_rad: [1.0e-7 / 3.0, -2.0_f64.sqrt(), core::f64::consts::PI],
            ..Default::default()
        };
        s.header.time_ns = 1_400_000_000_123_456_789;
        let j = serde_json::to_string(&s).unwrap();
        let back: ImuSample = serde_json::from_str(&j).unwrap();
        assert_eq!(s, back);
    }

    /// The covariance round-trips through its six stored elements, symmetrized; a solution
    /// recorded before it was carried (no `pos_cov_ned_m2` key) still reads, without it.
    #[test]
    fn position_covariance_is_stored_symmetric_and_optional_on_the_wire() {
        // NE and EN differ by rounding (4 ulps of 1.5): stored as their mean, exactly.
        let eps = f64::EPSILON;
        let p = [
            [4.0, 1.5, -0.25],
            [1.5 + 4.0 * eps, 9.0, 0.5],
            [-0.25, 0.5, 16.0],
        ];
        let mut nav = NavSolution::default();
        assert!(!nav.has_pos_cov());
        nav.set_pos_cov_ned_m2(&p);
        assert!(nav.has_pos_cov());
        assert_eq!(
            nav.pos_cov_ned_m2,
            [4.0, 1.5 + 2.0 * eps, -0.25, 9.0, 0.5, 16.0]
        );
        let m = nav.pos_cov_ned_matrix_m2();
        for (i, row) in m.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                assert_eq!(*v, m[j][i]);
                assert!((v - p[i][j]).abs() <= 2.0 * eps, "{i},{j}");
            }
        }
        let mut old = serde_json::to_value(nav).unwrap();
        old.as_object_mut().unwrap().remove("pos_cov_ned_m2");
        let back: NavSolution = serde_json::from_value(old).unwrap();
        assert!(!back.has_pos_cov());
        assert_eq!(back.pos_sigma_ned_m, nav.pos_sigma_ned_m);
    }

    #[test]
    fn service_names_carry_the_prefix() {
        assert_eq!(Channel::Imu.service_name("sextant"), "sextant/imu");
        assert_eq!(Channel::from_name("nav"), Some(Channel::Nav));
    }

    #[test]
    fn sensors_and_channels_map_both_ways() {
        for s in SensorId::ALL {
            assert_eq!(s.channel().sensor(), Some(s));
            assert_eq!(SensorId::from_index(s as usize), Some(s));
        }
        assert_eq!(Channel::Truth.sensor(), None);
        assert_eq!(SensorId::from_index(SensorId::COUNT), None);
        for m in NavMode::ALL {
            assert_eq!(NavMode::from_u32(m as u32), Some(m));
        }
        assert_eq!(NavMode::from_u32(7), None);
        let mut p = PerSensor::splat(0u32);
        p[SensorId::Gnss] += 2;
        assert_eq!(p.0, [0, 0, 2, 0, 0]);
        let j = serde_json::to_string(&p).unwrap();
        assert_eq!(
            j,
            r#"{"imu":0,"star_tracker":0,"gnss":2,"odometer":0,"baro":0}"#
        );
        assert_eq!(serde_json::from_str::<PerSensor<u32>>(&j).unwrap(), p);
        for bad in [
            r#"{"imu":0,"star_tracker":0,"gnss":2,"odometer":0}"#,
            r#"{"imu":0,"star_tracker":0,"gnss":2,"odometer":0,"baro":0,"sonar":1}"#,
        ] {
            assert!(
                serde_json::from_str::<PerSensor<u32>>(bad).is_err(),
                "{bad}"
            );
        }
    }

    #[test]
    fn simultaneous_messages_deliver_aiding_then_imu_then_truth() {
        let mut v = Channel::ALL;
        v.sort();
        assert_eq!(v, Channel::ALL);
        assert!(Channel::Baro < Channel::Imu && Channel::Imu < Channel::Truth);
    }

    #[test]
    fn monotonic_clock_advances() {
        let a = monotonic_ns();
        let b = monotonic_ns();
        assert!(b >= a && a > 0);
    }
}
