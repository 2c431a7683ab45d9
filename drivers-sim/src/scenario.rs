//! Scenario files (TOML): what the simulated world and sensors are.
//!
//! Loading is two passes: [`ScenarioFile`] is parsed strictly (`deny_unknown_fields`, so a typo
//! is an error naming the key), then [`Scenario::validate`] checks values and ranges and names
//! the file and the dotted key of the first offending value. Sensor error models are *grades*:
//! each sensor section names a grade `G`, read from the table of that sensor kind (`[imu]`,
//! `[star_tracker]`, `[gnss]`, `[odometer]`, `[baro]`) in `<sensors_dir>/G.toml`; the scenario's
//! optional `overrides` table is deep-merged over the grade table before it is parsed.
//!
//! A scenario's `[world]` may name a shared world file, `include = "../worlds/car.toml"` (relative
//! to the scenario file's directory; an absolute path is used as it is). That file holds only
//! `[world.<effect>]` tables; the scenario's own `[world.*]` tables are deep-merged over them key
//! by key (the scenario's keys win, a table the scenario adds is added), so a scenario names only
//! what differs, e.g. `[world.nlos] enabled = false`. A world file cannot include another
//! ([`SimError::Include`]). [`Scenario::resolved_toml`] gives the merged document.
//!
//! Units are in the key names (`_deg`, `_m`, `_s`, `_hz`, `_ppm`, …); every model converts to SI
//! radians/metres/seconds internally.

use crate::SimError;
use serde::Deserialize;
use serde::de::DeserializeOwned;
use std::path::{Path, PathBuf};

/// Step of the truth integration grid, ns (1 ms), where every sensor period is a whole number
/// of milliseconds; otherwise the grid is the largest divisor of it that every period is a
/// multiple of ([`Scenario::truth_grid_ns`]: 0.5 ms for a 400 Hz or 2 kHz IMU).
pub const TRUTH_GRID_NS: i64 = 1_000_000;

/// The finest truth grid, ns (0.1 ms): a sensor period must be a whole multiple of it. The truth
/// costs one RK4 step per grid point in every driver process, so a grid finer than the sensors
/// need is never used.
pub const MIN_TRUTH_GRID_NS: i64 = 100_000;

/// Greatest common divisor of two positive integers.
fn gcd(mut a: i64, mut b: i64) -> i64 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

/// The scenario file as written (strict parse, no semantic checks yet).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioFile {
    /// Name, epoch, duration, seed.
    pub scenario: ScenarioMeta,
    /// Starting point of the trajectory.
    pub site: Site,
    /// Motion of the vehicle.
    pub trajectory: Trajectory,
    /// Inertial measurement unit.
    pub imu: ImuSection,
    /// Star tracker.
    pub star_tracker: StarTrackerSection,
    /// GNSS receiver.
    pub gnss: GnssSection,
    /// Odometer.
    pub odometer: OdometerSection,
    /// Barometer.
    pub baro: BaroSection,
    /// Truth publication.
    #[serde(default)]
    pub truth: TruthSection,
    /// Earth orientation parameters (UT1 − UTC, polar motion) used for the star tracker.
    #[serde(default)]
    pub earth_orientation: fusion::celestial::EarthOrientation,
    /// Truth-only world effects ([`crate::world`]); absent: the matched world.
    #[serde(default)]
    pub world: Option<crate::world::WorldSection>,
}

/// `[scenario]`: identity, time and randomness.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioMeta {
    /// Human name.
    pub name: String,
    /// Start epoch, UTC calendar `YYYY-MM-DDTHH:MM:SS[.fff][Z]`.
    pub start_utc: String,
    /// Duration of the run, s.
    pub duration_s: f64,
    /// Master random seed; every sensor derives its own stream from it and its name.
    pub seed: u64,
    /// Directory of the sensor grade files, relative to the scenario file
    /// (default `../sensors`).
    #[serde(default)]
    pub sensors_dir: Option<String>,
}

/// `[site]`: geodetic start position on WGS-84.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Site {
    /// Geodetic latitude, degrees.
    pub lat_deg: f64,
    /// Longitude, degrees (east positive).
    pub lon_deg: f64,
    /// Height above the WGS-84 ellipsoid, m.
    pub height_m: f64,
}

/// `[trajectory]`: the motion, selected by `kind`.
#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Trajectory {
    /// Fixed at the site, optionally on a turntable rotating about the local vertical.
    Static(StaticTrajectory),
    /// A ground vehicle driving a list of segments on the ellipsoid at constant height.
    GroundVehicle(GroundVehicleTrajectory),
    /// A fixed-wing aircraft (UAV, paper 004): take-off roll, climb, cruise with coordinated
    /// (banked) turns, descent.
    Aircraft(AircraftTrajectory),
    /// Follows a recorded reference trajectory: a smooth spline through its points
    /// ([`crate::reference_trajectory`]); `[site]` is replaced by the spline's start.
    Reference(ReferenceTrajectorySpec),
}

/// `kind = "reference"`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReferenceTrajectorySpec {
    /// Text file of the points, relative to the scenario file: one point per line,
    /// `t_s x_m y_m z_m` (time from the first point, ECEF position), optionally after a leading
    /// tag word (the smartLoc ground-truth `point3` lines) and before further columns (ignored);
    /// `#` starts a comment. May be absent only when the caller sets `spline` itself.
    #[serde(default)]
    pub file: Option<String>,
    /// Intervals `[start_s, end_s]` in which the vehicle stands still.
    #[serde(default)]
    pub still_s: Vec<[f64; 2]>,
    /// Smallest chord length between the path spline's nodes, m.
    #[serde(default = "default_path_node_spacing_m")]
    pub path_node_spacing_m: f64,
    /// Points farther than this from the quadratic through their neighbours are left out, m.
    #[serde(default = "default_outlier_threshold_m")]
    pub outlier_threshold_m: f64,
    /// The spline: built from `file` at validation, or set by the caller.
    #[serde(skip)]
    pub spline: Option<std::sync::Arc<crate::reference_trajectory::ReferenceTrajectory>>,
}

fn default_path_node_spacing_m() -> f64 {
    crate::reference_trajectory::ReferenceSettings::default().path_node_spacing_m
}

fn default_outlier_threshold_m() -> f64 {
    crate::reference_trajectory::ReferenceSettings::default().outlier_threshold_m
}

/// `kind = "aircraft"`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AircraftTrajectory {
    /// Heading at the start, degrees from north, clockwise.
    pub initial_heading_deg: f64,
    /// Segments flown in order; after the last one the aircraft keeps its final speed, heading
    /// and flight-path angle. Body x is along the velocity (no angle of attack or sideslip), so
    /// pitch is the flight-path angle; turns are coordinated, with the bank
    /// `φ = atan(V ψ̇ / g0)`.
    pub segments: Vec<Segment>,
}

/// `kind = "static"`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StaticTrajectory {
    /// Roll of the body, degrees.
    #[serde(default)]
    pub roll_deg: f64,
    /// Pitch of the body, degrees.
    #[serde(default)]
    pub pitch_deg: f64,
    /// Heading of the body (turntable at zero), degrees from north, clockwise.
    #[serde(default)]
    pub heading_deg: f64,
    /// Turntable moves about the table axis = body z (applied in order, must not overlap). The
    /// roll and pitch above are the tilt of the table top, so with a tilted table the axis is
    /// tilted too and the body turns about its own z axis (`C_n_b = C_n_b0·R_z(β)`).
    #[serde(default)]
    pub turntable: Vec<TurntableMove>,
}

/// One turntable move: from its current angle to `to_deg` with a raised-cosine rate profile.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TurntableMove {
    /// Start of the move, s since the scenario epoch.
    pub start_s: f64,
    /// Target turntable angle, degrees (about body z = down, positive clockwise seen from above).
    pub to_deg: f64,
    /// Duration of the move, s.
    pub duration_s: f64,
}

/// `kind = "ground_vehicle"`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroundVehicleTrajectory {
    /// Heading at the start, degrees from north, clockwise.
    pub initial_heading_deg: f64,
    /// Segments driven in order; after the last one the vehicle keeps its final speed and heading.
    pub segments: Vec<Segment>,
}

/// One piece of a ground-vehicle or aircraft trajectory. Accelerations, turn and pitch rates
/// follow raised-cosine profiles that start and end at zero, so specific force and angular rate
/// are continuous.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum Segment {
    /// Stand still (speed must be zero) for `duration_s`.
    Hold {
        /// Duration, s.
        duration_s: f64,
    },
    /// Change speed to `to_m_s` over `duration_s` (accelerate or decelerate).
    Speed {
        /// Target forward speed, m/s.
        to_m_s: f64,
        /// Duration, s.
        duration_s: f64,
    },
    /// Turn by `angle_deg` (positive = right, heading increases) over `duration_s` at the
    /// current speed (coordinated for an aircraft).
    Turn {
        /// Heading change, degrees.
        angle_deg: f64,
        /// Duration, s.
        duration_s: f64,
    },
    /// Aircraft only: change the flight-path angle (= pitch) to `to_deg` (positive = climb). A
    /// ground vehicle's pitch follows its road.
    Pitch {
        /// Target pitch, degrees.
        to_deg: f64,
        /// Duration, s.
        duration_s: f64,
    },
    /// Keep speed, heading (and an aircraft's flight-path angle) for `duration_s`.
    Cruise {
        /// Duration, s.
        duration_s: f64,
    },
}

impl Segment {
    /// Duration of the segment, s.
    pub fn duration_s(&self) -> f64 {
        match *self {
            Segment::Hold { duration_s }
            | Segment::Speed { duration_s, .. }
            | Segment::Turn { duration_s, .. }
            | Segment::Pitch { duration_s, .. }
            | Segment::Cruise { duration_s } => duration_s,
        }
    }
}

/// A time window `[start_s, start_s + duration_s)` in s since the scenario epoch.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Window {
    /// Start, s since the scenario epoch.
    pub start_s: f64,
    /// Length, s.
    pub duration_s: f64,
}

impl Window {
    /// Whether time `t_s` (s since the epoch) lies inside the window.
    pub fn contains(&self, t_s: f64) -> bool {
        t_s >= self.start_s && t_s < self.start_s + self.duration_s
    }
}

/// IMU temperature: `T(t) = initial_c + rate_c_per_h · t/3600`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TemperatureProfile {
    /// Temperature at the epoch, °C.
    pub initial_c: f64,
    /// Linear drift, °C per hour.
    #[serde(default)]
    pub rate_c_per_h: f64,
}

impl Default for TemperatureProfile {
    fn default() -> Self {
        Self {
            initial_c: 20.0,
            rate_c_per_h: 0.0,
        }
    }
}

/// `[imu]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImuSection {
    /// Grade file name (without `.toml`) in the sensors directory.
    pub grade: String,
    /// Output rate, Hz.
    pub rate_hz: f64,
    /// Temperature profile of the sensor block.
    #[serde(default)]
    pub temperature: TemperatureProfile,
    /// Partial `[imu]` grade table merged over the grade file.
    #[serde(default)]
    pub overrides: Option<toml::Table>,
    /// Redundant single-axis channels (paper 004). Absent: the orthogonal triad only.
    #[serde(default)]
    pub channels: Option<ImuChannelsSpec>,
}

/// Layout of the single-axis channels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ChannelLayout {
    /// The paper's pyramid: `n` channels, azimuth β_k = 45° + k·360°/n, elevation `alpha_deg`
    /// above the body x-y plane: `e_k = (cosα cosβ_k, cosα sinβ_k, sinα)`.
    Pyramid,
    /// Three channels on body x, y, z (the conventional triad as single-axis channels).
    Orthogonal,
    /// Explicit unit axes in `axes` (body frame).
    Axes,
}

/// `[imu.channels]`: N ≥ 3 single-axis gyro + accelerometer channels. Each channel has the
/// grade's per-axis error model drawn independently (bias, bias random walk, temperature
/// coefficient, scale factor, axis misalignment, white noise, ADC quantisation at the grade's
/// full scale).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImuChannelsSpec {
    /// Layout kind.
    pub layout: ChannelLayout,
    /// Number of pyramid channels (default 4).
    #[serde(default)]
    pub n: Option<usize>,
    /// Elevation of the pyramid axes above the body x-y plane, degrees (paper: 28.7°;
    /// 35.26° makes four axes isotropic).
    #[serde(default)]
    pub alpha_deg: Option<f64>,
    /// Explicit axes (layout `axes`), body frame; normalised on load.
    #[serde(default)]
    pub axes: Vec<[f64; 3]>,
    /// Temperature of each channel relative to the block profile, °C (default 0).
    #[serde(default)]
    pub temperature_offsets_c: Vec<f64>,
    /// Injected channel failures.
    #[serde(default)]
    pub failures: Vec<ChannelFailure>,
}

/// Which sensor of a combined channel fails.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FailedSensor {
    /// The single-axis gyro.
    Gyro,
    /// The single-axis accelerometer.
    Accel,
}

/// Kind of an injected failure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FailureKind {
    /// The output freezes at its last healthy increment (`magnitude` unused).
    Stuck,
    /// A constant bias of `magnitude` is added from `start_s`.
    BiasStep,
    /// A bias growing at `magnitude` per second from `start_s`.
    DriftRamp,
    /// Extra white noise of 1-σ `magnitude` (rate units) on every sample.
    NoiseBurst,
}

/// One injected channel failure. Units of `magnitude`: gyro °/h (bias step, noise burst) and
/// °/h per s (drift ramp); accelerometer µg and µg per s.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelFailure {
    /// Channel index (0-based).
    pub channel: usize,
    /// Failing sensor of the channel.
    pub sensor: FailedSensor,
    /// Failure kind.
    pub kind: FailureKind,
    /// Onset, s since the scenario epoch.
    pub start_s: f64,
    /// Length, s (default: to the end of the run).
    #[serde(default)]
    pub duration_s: Option<f64>,
    /// Size (units above).
    #[serde(default)]
    pub magnitude: f64,
}

impl ChannelFailure {
    /// Whether the failure is active at `t_s`.
    pub fn active(&self, t_s: f64) -> bool {
        t_s >= self.start_s && self.duration_s.is_none_or(|d| t_s < self.start_s + d)
    }
}

impl ImuChannelsSpec {
    /// The unit axes of the channels, body frame.
    pub fn unit_axes(&self) -> Vec<[f64; 3]> {
        match self.layout {
            ChannelLayout::Pyramid => {
                let n = self.n.unwrap_or(4);
                let alpha = self.alpha_deg.unwrap_or(28.7).to_radians();
                fusion::redundancy::pyramid_axes(n, alpha)[..n.min(msgs::MAX_IMU_CHANNELS)].to_vec()
            }
            ChannelLayout::Orthogonal => fusion::redundancy::orthogonal_axes()[..3].to_vec(),
            ChannelLayout::Axes => self
                .axes
                .iter()
                .map(|a| {
                    let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
                    [a[0] / n, a[1] / n, a[2] / n]
                })
                .collect(),
        }
    }
}

/// `[star_tracker]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StarTrackerSection {
    /// Grade file name.
    pub grade: String,
    /// Output rate, Hz.
    pub rate_hz: f64,
    /// True mounting misalignment κ1, κ2, κ3 (paper 000, `M = R_z(κ1)·R_x(κ2)·R_y(κ3)`), deg.
    #[serde(default)]
    pub mounting_kappa_deg: [f64; 3],
    /// Outage windows (no attitude; samples flagged invalid).
    #[serde(default)]
    pub outages: Vec<Window>,
    /// Partial grade table merged over the grade file.
    #[serde(default)]
    pub overrides: Option<toml::Table>,
}

/// Walker constellation `T/P/F` on circular orbits.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConstellationSpec {
    /// Number of orbital planes P.
    pub planes: u32,
    /// Satellites per plane (T = planes · per_plane).
    pub per_plane: u32,
    /// Walker phasing factor F.
    pub phasing: u32,
    /// Inclination, degrees.
    pub inclination_deg: f64,
    /// Semi-major axis, m.
    pub semi_major_axis_m: f64,
    /// Right ascension of the first plane's node in the inertial frame at the GPS epoch, deg.
    #[serde(default)]
    pub raan0_deg: f64,
}

impl Default for ConstellationSpec {
    fn default() -> Self {
        Self {
            planes: 6,
            per_plane: 4,
            phasing: 1,
            inclination_deg: 55.0,
            semi_major_axis_m: 26_559_700.0,
            raan0_deg: 0.0,
        }
    }
}

/// `[gnss]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GnssSection {
    /// Grade file name.
    pub grade: String,
    /// Output rate, Hz.
    pub rate_hz: f64,
    /// Outage windows (no satellites tracked, no fix).
    #[serde(default)]
    pub outages: Vec<Window>,
    /// Constellation geometry.
    #[serde(default)]
    pub constellation: ConstellationSpec,
    /// Partial grade table merged over the grade file.
    #[serde(default)]
    pub overrides: Option<toml::Table>,
}

/// `[odometer]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OdometerSection {
    /// Grade file name.
    pub grade: String,
    /// Output rate, Hz.
    pub rate_hz: f64,
    /// Partial grade table merged over the grade file.
    #[serde(default)]
    pub overrides: Option<toml::Table>,
}

/// `[baro]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BaroSection {
    /// Grade file name.
    pub grade: String,
    /// Output rate, Hz.
    pub rate_hz: f64,
    /// Partial grade table merged over the grade file.
    #[serde(default)]
    pub overrides: Option<toml::Table>,
}

/// `[truth]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TruthSection {
    /// Publication rate, Hz.
    pub rate_hz: f64,
}

impl Default for TruthSection {
    fn default() -> Self {
        Self { rate_hz: 50.0 }
    }
}

/// Error model of one gyro triad (grade file `[imu.gyro]`). All 1-σ values are per axis.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GyroGrade {
    /// 1-σ constant (turn-on) bias, deg/h.
    pub bias_deg_h: f64,
    /// Bias random walk, deg/h per √h.
    #[serde(default)]
    pub bias_rw_deg_h_per_rt_h: f64,
    /// Angle random walk, deg/√h.
    pub arw_deg_per_rt_h: f64,
    /// 1-σ scale-factor error, ppm.
    pub scale_factor_ppm: f64,
    /// 1-σ axis misalignment (each off-diagonal term), arcsec.
    pub misalignment_arcsec: f64,
    /// Bias temperature coefficient, deg/h per °C (times a per-axis unit-normal draw).
    #[serde(default)]
    pub temp_coeff_deg_h_per_c: f64,
    /// ADC resolution for the rate output, bits (0 = no quantisation).
    #[serde(default)]
    pub adc_bits: u32,
    /// Full-scale range ± of the rate output, deg/s (used when `adc_bits` > 0).
    #[serde(default)]
    pub full_scale_deg_s: f64,
    /// Resolution of the delta-angle output, rad per count (0 = none). The output is a whole
    /// number of counts and the remainder carries into the next interval, as in a sensor that
    /// integrates (or counts pulses) before it digitises: the error of the summed angle stays
    /// within half a count.
    #[serde(default)]
    pub delta_angle_lsb_rad: f64,
}

/// Error model of one accelerometer triad (grade file `[imu.accel]`).
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AccelGrade {
    /// 1-σ constant (turn-on) bias, µg.
    pub bias_ug: f64,
    /// Bias random walk, µg per √h.
    #[serde(default)]
    pub bias_rw_ug_per_rt_h: f64,
    /// Velocity random walk, µg/√Hz.
    pub vrw_ug_per_rt_hz: f64,
    /// 1-σ scale-factor error, ppm.
    pub scale_factor_ppm: f64,
    /// 1-σ axis misalignment (each off-diagonal term), arcsec.
    pub misalignment_arcsec: f64,
    /// Bias temperature coefficient, µg per °C (times a per-axis unit-normal draw).
    #[serde(default)]
    pub temp_coeff_ug_per_c: f64,
    /// ADC resolution for the specific-force output, bits (0 = no quantisation).
    #[serde(default)]
    pub adc_bits: u32,
    /// Full-scale range ± of the specific-force output, g (used when `adc_bits` > 0).
    #[serde(default)]
    pub full_scale_g: f64,
    /// Resolution of the delta-velocity output, m/s per count (0 = none; carried remainder
    /// as for the gyros' `delta_angle_lsb_rad`).
    #[serde(default)]
    pub delta_velocity_lsb_m_s: f64,
}

/// IMU grade (`[imu]` of a grade file).
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImuGrade {
    /// Temperature at which the bias is specified, °C.
    #[serde(default = "default_ref_temp")]
    pub reference_temperature_c: f64,
    /// Time after power-on within which the data sheet says the biases settle, s (0: not
    /// stated). What a user configures the redundant channels' FDI warm-up from; the
    /// world's actual transient is `[world.imu]`'s.
    #[serde(default)]
    pub warmup_time_s: f64,
    /// Gyros.
    pub gyro: GyroGrade,
    /// Accelerometers.
    pub accel: AccelGrade,
}

fn default_ref_temp() -> f64 {
    20.0
}

impl ImuGrade {
    /// What the data sheet's settling time `warmup_time_s` means for a redundant-channel FDI
    /// with test blocks of `block_s` seconds: (blocks from power-on until the parts have
    /// settled, the offset tracker's time constant during that time, blocks). The settling
    /// time is read as 3τ (95 % settled) and the tracker set to τ/10, which lags an
    /// exponential transient by a ninth of it (`b·T/(τ − T)`). (0, 1) without a stated time.
    pub fn fdi_warmup_blocks(&self, block_s: f64) -> (u32, u32) {
        let settle = self.warmup_time_s;
        (
            (settle / block_s).ceil() as u32,
            ((settle / 3.0 / 10.0 / block_s).round() as u32).max(1),
        )
    }
}

/// Star-tracker grade.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StarTrackerGrade {
    /// 1-σ attitude noise about each axis across the boresight, arcsec.
    pub sigma_cross_arcsec: f64,
    /// 1-σ attitude noise about the boresight, arcsec.
    pub sigma_roll_arcsec: f64,
    /// 1-σ of a unit's constant error about the boresight after its maker's calibration,
    /// arcsec (the filter's `aiding.star_roll_bias_sigma_arcsec`; what a unit of the class
    /// actually has is its world's, `[world.star_tracker]`). 0 when the data sheet states none.
    #[serde(default)]
    pub roll_bias_arcsec: f64,
    /// Fewest stars identified in a valid frame.
    #[serde(default = "default_min_stars")]
    pub min_stars: u32,
    /// Most stars identified in a valid frame.
    #[serde(default = "default_max_stars")]
    pub max_stars: u32,
}

fn default_min_stars() -> u32 {
    6
}
fn default_max_stars() -> u32 {
    15
}

/// GNSS receiver grade.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GnssGrade {
    /// 1-σ pseudorange noise, m.
    pub pseudorange_sigma_m: f64,
    /// 1-σ range-rate (Doppler) noise, m/s.
    pub range_rate_sigma_m_s: f64,
    /// Elevation mask, degrees.
    pub elevation_mask_deg: f64,
    /// 1-σ of the receiver clock bias at the epoch, m (c·s).
    pub clock_bias_initial_sigma_m: f64,
    /// 1-σ of the receiver clock drift at the epoch, m/s.
    pub clock_drift_initial_sigma_m_s: f64,
    /// White-frequency noise PSD driving the clock bias, m²/s.
    pub clock_bias_psd_m2_s: f64,
    /// Random-walk-frequency noise PSD driving the clock drift, m²/s³.
    pub clock_drift_psd_m2_s3: f64,
    /// C/N0 at zenith, dB-Hz.
    pub cn0_zenith_dbhz: f64,
    /// C/N0 at the horizon, dB-Hz (linear in sin(elevation) between).
    pub cn0_horizon_dbhz: f64,
    /// 1-σ noise of each baseline carrier-phase difference, cycles.
    pub phase_sigma_cycles: f64,
    /// Lengths of baselines AB (body x) and CD (body y), m.
    pub baseline_length_m: [f64; 2],
    /// Carrier frequency of the phase measurements, Hz (GPS L1 = 1 575.42 MHz).
    pub carrier_frequency_hz: f64,
    /// The receiver's own pseudorange error budget (`[gnss.uere]`): the σ it reports per
    /// satellite and weights its fix with when the scenario has a `[world]`.
    #[serde(default)]
    pub uere: Option<UereModel>,
}

/// A receiver's pseudorange error budget (user equivalent range error) by elevation and
/// C/N0, after its broadcast corrections, in the form of RTCA DO-229 (Appendix J) and
/// RTKLIB's single-point weighting:
/// `σ² = σ_sis² + (k_iono·I_klob)² + σ_tropo(el)² + σ_mp(el)² + σ_noise(C/N0)²` with
/// `σ_tropo = t_z·1.001/√(0.002001 + sin²el)`, `σ_mp = a + b·e^{−el/θ}`,
/// `σ_noise = n₄₅·10^{(45 − C/N0)/20}`, `I_klob` the receiver's own Klobuchar correction.
/// These are the receiver's data-sheet beliefs, not the world's values.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UereModel {
    /// Signal-in-space range error (broadcast clock and orbit), 1-σ, m.
    pub sis_m: f64,
    /// Fraction of the Klobuchar correction taken as its 1-σ residual.
    pub iono_fraction: f64,
    /// Zenith troposphere residual t_z, 1-σ, m.
    pub tropo_zenith_m: f64,
    /// Multipath floor a, m.
    pub multipath_floor_m: f64,
    /// Multipath low-elevation term b, m.
    pub multipath_low_m: f64,
    /// Multipath elevation scale θ, deg.
    pub multipath_scale_deg: f64,
    /// Code noise at 45 dB-Hz, m.
    pub noise_45_dbhz_m: f64,
}

impl UereModel {
    /// The receiver's 1-σ for a satellite at `el_rad` with C/N0 `cn0_dbhz` whose Klobuchar
    /// correction was `klobuchar_m`, m.
    pub fn sigma_m(&self, el_rad: f64, cn0_dbhz: f64, klobuchar_m: f64) -> f64 {
        let s = el_rad.sin();
        let tropo = self.tropo_zenith_m * 1.001 / (0.002001 + s * s).sqrt();
        let mp = self.multipath_floor_m
            + self.multipath_low_m * (-el_rad.to_degrees() / self.multipath_scale_deg).exp();
        let noise = self.noise_45_dbhz_m * 10f64.powf((45.0 - cn0_dbhz) / 20.0);
        (self.sis_m.powi(2)
            + (self.iono_fraction * klobuchar_m).powi(2)
            + tropo * tropo
            + mp * mp
            + noise * noise)
            .sqrt()
    }
}

/// Odometer grade.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OdometerGrade {
    /// Scale-factor error (true value applied), ppm.
    pub scale_factor_error_ppm: f64,
    /// 1-σ white noise of the speed, m/s.
    pub speed_noise_m_s: f64,
}

/// Barometer grade.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BaroGrade {
    /// Constant pressure bias (true value applied), Pa.
    pub bias_pa: f64,
    /// Bias random walk, Pa/√s.
    #[serde(default)]
    pub bias_rw_pa_per_rt_s: f64,
    /// 1-σ white pressure noise, Pa.
    pub noise_pa: f64,
}

/// A parsed and validated scenario with its grades resolved.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// File it came from (for messages).
    pub file: PathBuf,
    /// The file as written.
    pub spec: ScenarioFile,
    /// Start epoch, UTC.
    pub start: fusion::time::UtcDateTime,
    /// Resolved IMU grade.
    pub imu: ImuGrade,
    /// Resolved star-tracker grade.
    pub star_tracker: StarTrackerGrade,
    /// Resolved GNSS grade.
    pub gnss: GnssGrade,
    /// Resolved odometer grade.
    pub odometer: OdometerGrade,
    /// Resolved baro grade.
    pub baro: BaroGrade,
}

fn invalid(file: &Path, key: impl Into<String>, reason: impl Into<String>) -> SimError {
    SimError::Invalid {
        file: file.to_path_buf(),
        key: key.into(),
        reason: reason.into(),
    }
}

/// Deep-merge `over` into `base` (tables merge key by key, other values replace).
fn merge(base: &mut toml::Table, over: &toml::Table) {
    for (k, v) in over {
        match (base.get_mut(k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge(b, o),
            _ => {
                base.insert(k.clone(), v.clone());
            }
        }
    }
}

/// The grade names (`*.toml` stems) present in `dir`, sorted; empty when it cannot be read.
fn known_grades(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| {
            let p = e.path();
            (p.extension()? == "toml").then(|| p.file_stem()?.to_str().map(String::from))?
        })
        .collect();
    names.sort();
    names
}

/// Load the `section` table of grade file `<dir>/<grade>.toml`, merge `overrides`, parse it.
fn load_grade<T: DeserializeOwned>(
    dir: &Path,
    scenario_file: &Path,
    section: &str,
    grade: &str,
    overrides: Option<&toml::Table>,
) -> Result<T, SimError> {
    if grade.is_empty() || grade.contains(['/', '\\']) || grade.starts_with('.') {
        return Err(invalid(
            scenario_file,
            format!("{section}.grade"),
            format!("`{grade}` is not a plain grade name"),
        ));
    }
    let path = dir.join(format!("{grade}.toml"));
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        // An unknown grade is a mistake in the scenario, so the scenario's key is named (with
        // the grades that do exist), not only the missing file.
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(invalid(
                scenario_file,
                format!("{section}.grade"),
                format!(
                    "unknown grade `{grade}` (no {}; known grades: {})",
                    path.display(),
                    known_grades(dir).join(", ")
                ),
            ));
        }
        Err(e) => {
            return Err(SimError::Io {
                file: path.clone(),
                reason: format!(
                    "grade `{grade}` of `{section}.grade` in {}: {e}",
                    scenario_file.display()
                ),
            });
        }
    };
    let mut doc: toml::Table = toml::from_str(&text).map_err(|e| SimError::Parse {
        file: path.clone(),
        message: e.to_string(),
    })?;
    let mut table = match doc.remove(section) {
        Some(toml::Value::Table(t)) => t,
        _ => {
            return Err(invalid(
                &path,
                section,
                format!("grade file has no `[{section}]` table"),
            ));
        }
    };
    if let Some(o) = overrides {
        merge(&mut table, o);
    }
    toml::Value::Table(table)
        .try_into()
        .map_err(|e: toml::de::Error| {
            let origin = if overrides.is_some() {
                format!(
                    " (grade `{grade}` merged with `{section}.overrides` of {})",
                    scenario_file.display()
                )
            } else {
                String::new()
            };
            SimError::Parse {
                file: path.clone(),
                message: format!("[{section}]{origin}: {}", e.message()),
            }
        })
}

/// The key of `[world]` that names a shared world file.
pub const WORLD_INCLUDE: &str = "include";

/// `[world] include` of a scenario document: the path as written and where it points.
struct WorldInclude {
    written: String,
    resolved: PathBuf,
}

impl WorldInclude {
    /// The include of `doc` (the scenario file `file` as a table), if it has one.
    fn of(doc: &toml::Table, file: &Path) -> Result<Option<Self>, SimError> {
        let Some(v) = doc
            .get("world")
            .and_then(toml::Value::as_table)
            .and_then(|w| w.get(WORLD_INCLUDE))
        else {
            return Ok(None);
        };
        let Some(written) = v.as_str() else {
            return Err(invalid(
                file,
                "world.include",
                format!("{v} is not a string naming a world file"),
            ));
        };
        let resolved = file.parent().unwrap_or(Path::new(".")).join(written);
        Ok(Some(Self {
            written: written.to_string(),
            resolved,
        }))
    }

    fn error(&self, file: &Path, reason: impl Into<String>) -> SimError {
        SimError::Include {
            file: file.to_path_buf(),
            include: self.written.clone(),
            resolved: self.resolved.clone(),
            reason: reason.into(),
        }
    }

    /// The `[world]` table of the included file.
    fn world(&self, file: &Path) -> Result<toml::Table, SimError> {
        let text = std::fs::read_to_string(&self.resolved)
            .map_err(|e| self.error(file, format!("cannot read: {e}")))?;
        let mut doc: toml::Table = toml::from_str(&text)
            .map_err(|e| self.error(file, format!("not a valid TOML file: {e}")))?;
        if let Some(k) = doc.keys().find(|k| *k != "world") {
            return Err(self.error(
                file,
                format!("`{k}`: a world file holds only `[world.<effect>]` tables"),
            ));
        }
        let world = match doc.remove("world") {
            Some(toml::Value::Table(t)) => t,
            None => toml::Table::new(),
            Some(v) => {
                return Err(self.error(
                    file,
                    format!("`world = {v}`: a world file holds only `[world.<effect>]` tables"),
                ));
            }
        };
        if world.contains_key(WORLD_INCLUDE) {
            return Err(self.error(
                file,
                "the world file has `[world] include` of its own; a world file cannot include \
                 another (copy its tables instead)",
            ));
        }
        Ok(world)
    }
}

/// `doc` (the scenario file `file` as a table) with its world include resolved: the included
/// world's tables with the scenario's own `[world]` merged over them, the `include` key removed.
/// Returns the include, if there was one.
fn resolve_world_include(
    doc: &mut toml::Table,
    file: &Path,
) -> Result<Option<WorldInclude>, SimError> {
    let Some(include) = WorldInclude::of(doc, file)? else {
        return Ok(None);
    };
    let mut world = include.world(file)?;
    if let Some(toml::Value::Table(own)) = doc.get_mut("world") {
        own.remove(WORLD_INCLUDE);
        merge(&mut world, own);
    }
    doc.insert("world".into(), toml::Value::Table(world));
    Ok(Some(include))
}

/// The name of the table whose header is `line` (`[a.b]` or `[[a.b]]`, spaces and a comment
/// allowed), if it is one.
fn table_header(line: &str) -> Option<&str> {
    let rest = line.trim().strip_prefix('[')?;
    let rest = rest.strip_prefix('[').unwrap_or(rest);
    let (name, after) = rest.split_once(']')?;
    let after = after.strip_prefix(']').unwrap_or(after).trim_start();
    let plain = name
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || "_-. \"'".contains(c));
    (plain && (after.is_empty() || after.starts_with('#'))).then(|| name.trim())
}

/// `text` with the lines of its `[world]` and `[world.*]` tables blanked, so that every other
/// line keeps its number.
fn without_world_tables(text: &str) -> String {
    let mut in_world = false;
    let mut out = String::with_capacity(text.len());
    for line in text.lines() {
        if let Some(name) = table_header(line) {
            in_world = name == "world" || name.starts_with("world.");
        }
        if !in_world {
            out.push_str(line);
        }
        out.push('\n');
    }
    out
}

impl Scenario {
    /// Step of the truth integration grid of this scenario, ns: 1 ms ([`TRUTH_GRID_NS`]) where
    /// every sensor period is a whole number of milliseconds, else the largest divisor of 1 ms
    /// that every period is a multiple of (validation keeps it ≥ [`MIN_TRUTH_GRID_NS`]). Every
    /// process derives it from the scenario alone, so all follow the same grid.
    pub fn truth_grid_ns(&self) -> i64 {
        let s = &self.spec;
        [
            s.imu.rate_hz,
            s.star_tracker.rate_hz,
            s.gnss.rate_hz,
            s.odometer.rate_hz,
            s.baro.rate_hz,
            s.truth.rate_hz,
        ]
        .into_iter()
        .fold(TRUTH_GRID_NS, |g, hz| gcd(g, period_ns(hz)))
    }

    /// The scenario file `path` (its text `text`) as one TOML document, with its world include
    /// resolved: the included file's `[world.*]` tables with the scenario's own merged over them
    /// key by key, no `include` key. A scenario without an include is its text parsed. Edit the
    /// result and give `toml::to_string` of it to [`Scenario::from_toml_str`] with the same path
    /// to change a value wherever it was written.
    pub fn resolved_toml(text: &str, path: &Path) -> Result<toml::Table, SimError> {
        let mut doc: toml::Table = toml::from_str(text).map_err(|e| SimError::Parse {
            file: path.to_path_buf(),
            message: e.to_string(),
        })?;
        resolve_world_include(&mut doc, path)?;
        Ok(doc)
    }

    /// [`Scenario::resolved_toml`] of the file `path`.
    pub fn read_resolved_toml(path: &Path) -> Result<toml::Table, SimError> {
        let text = std::fs::read_to_string(path).map_err(|e| SimError::Io {
            file: path.to_path_buf(),
            reason: e.to_string(),
        })?;
        Self::resolved_toml(&text, path)
    }

    /// Read, parse and validate a scenario file; grade files are looked up in `sensors_dir`
    /// (relative to the scenario file, default `../sensors`).
    pub fn load(path: &Path) -> Result<Self, SimError> {
        let text = std::fs::read_to_string(path).map_err(|e| SimError::Io {
            file: path.to_path_buf(),
            reason: e.to_string(),
        })?;
        Self::from_toml_str(&text, path)
    }

    /// Parse and validate scenario text as if read from `path` (which fixes the sensors dir).
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Self, SimError> {
        let spec = Self::parse(text, path)?;
        let base = path.parent().unwrap_or(Path::new("."));
        let dir = base.join(spec.scenario.sensors_dir.as_deref().unwrap_or("../sensors"));
        Self::validate(spec, path, &dir)
    }

    /// First pass: strict TOML parse, with the world include (if any) resolved relative to
    /// `path`.
    pub fn parse(text: &str, path: &Path) -> Result<ScenarioFile, SimError> {
        let parse_error = |e: toml::de::Error| SimError::Parse {
            file: path.to_path_buf(),
            message: e.to_string(),
        };
        let mut doc: toml::Table = toml::from_str(text).map_err(parse_error)?;
        let Some(include) = resolve_world_include(&mut doc, path)? else {
            // Parsed from the text, so that an error names its line.
            return toml::from_str(text).map_err(parse_error);
        };
        let merged_world = doc.get("world").cloned();
        toml::Value::Table(doc)
            .try_into()
            .map_err(|e: toml::de::Error| {
                // The merged document has no lines: name the world table that fails, if one does.
                let failing = merged_world
                    .as_ref()
                    .and_then(toml::Value::as_table)
                    .into_iter()
                    .flatten()
                    .find_map(|(name, table)| {
                        let one = toml::Table::from_iter([(name.clone(), table.clone())]);
                        toml::Value::Table(one)
                            .try_into::<crate::world::WorldSection>()
                            .err()
                            .map(|e| (name.clone(), e))
                    });
                let message = match failing {
                    Some((name, e)) => format!(
                        "[world.{name}] (with `[world] include = {:?}` merged in): {}",
                        include.written,
                        e.message()
                    ),
                    // Outside `[world]`: the scenario's own text without its world tables names
                    // the line.
                    None => match toml::from_str::<ScenarioFile>(&without_world_tables(text)) {
                        Err(own) => own.to_string(),
                        Ok(_) => format!(
                            "{} (with `[world] include = {:?}` merged in)",
                            e.message(),
                            include.written
                        ),
                    },
                };
                SimError::Parse {
                    file: path.to_path_buf(),
                    message,
                }
            })
    }

    /// Second pass: check values, resolve grades. Errors name `file` and the dotted key.
    pub fn validate(
        mut spec: ScenarioFile,
        file: &Path,
        sensors_dir: &Path,
    ) -> Result<Self, SimError> {
        let f = file;
        if let Trajectory::Reference(r) = &mut spec.trajectory {
            let spline = crate::reference_trajectory::load_spec(r, f)?;
            if spec.scenario.duration_s > spline.end_s() {
                return Err(invalid(
                    f,
                    "scenario.duration_s",
                    format!(
                        "{} s runs past the reference trajectory's last point at {} s",
                        spec.scenario.duration_s,
                        spline.end_s()
                    ),
                ));
            }
            let g = spline.start();
            spec.site = Site {
                lat_deg: g.lat_rad.to_degrees(),
                lon_deg: g.lon_rad.to_degrees(),
                height_m: g.height_m,
            };
        }
        let finite = |key: &str, v: f64| -> Result<(), SimError> {
            if v.is_finite() {
                Ok(())
            } else {
                Err(invalid(f, key, format!("must be finite, got {v}")))
            }
        };
        let positive = |key: &str, v: f64| -> Result<(), SimError> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(invalid(f, key, format!("must be > 0, got {v}")))
            }
        };
        let nonneg = |key: &str, v: f64| -> Result<(), SimError> {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(invalid(f, key, format!("must be ≥ 0, got {v}")))
            }
        };
        let rate = |key: &str, hz: f64| -> Result<(), SimError> {
            positive(key, hz)?;
            let period_ns = 1e9 / hz;
            let p = period_ns.round();
            if (period_ns - p).abs() > 1e-6 * p || (p as i64) % MIN_TRUTH_GRID_NS != 0 {
                return Err(invalid(
                    f,
                    key,
                    format!(
                        "{hz} Hz: the period must be a whole multiple of 0.1 ms (the finest \
                         truth grid)"
                    ),
                ));
            }
            Ok(())
        };
        let windows = |key: &str, ws: &[Window]| -> Result<(), SimError> {
            for (i, w) in ws.iter().enumerate() {
                nonneg(&format!("{key}[{i}].start_s"), w.start_s)?;
                positive(&format!("{key}[{i}].duration_s"), w.duration_s)?;
            }
            Ok(())
        };

        let m = &spec.scenario;
        let start = fusion::time::parse_utc(&m.start_utc).ok_or_else(|| {
            invalid(
                f,
                "scenario.start_utc",
                format!(
                    "`{}` is not a UTC calendar instant YYYY-MM-DDTHH:MM:SS[.fff] in 1980..=2100",
                    m.start_utc
                ),
            )
        })?;
        positive("scenario.duration_s", m.duration_s)?;
        if m.duration_s > 30.0 * 86_400.0 {
            return Err(invalid(f, "scenario.duration_s", "longer than 30 days"));
        }
        let s = &spec.site;
        finite("site.lat_deg", s.lat_deg)?;
        if s.lat_deg.abs() > 89.0 {
            return Err(invalid(
                f,
                "site.lat_deg",
                format!(
                    "{} is outside ±89° (NED trajectory is singular at the poles)",
                    s.lat_deg
                ),
            ));
        }
        finite("site.lon_deg", s.lon_deg)?;
        if !(-180.0..=360.0).contains(&s.lon_deg) {
            return Err(invalid(
                f,
                "site.lon_deg",
                format!("{} is outside −180..360", s.lon_deg),
            ));
        }
        finite("site.height_m", s.height_m)?;
        if !(-500.0..=20_000.0).contains(&s.height_m) {
            return Err(invalid(
                f,
                "site.height_m",
                "outside −500..20 000 m (ISA range)",
            ));
        }
        match &spec.trajectory {
            Trajectory::Aircraft(ac) => {
                validate_segments(f, ac.initial_heading_deg, &ac.segments, Mover::Aircraft)?
            }
            Trajectory::Reference(_) => {} // checked when its spline was built above
            Trajectory::Static(st) => {
                finite("trajectory.roll_deg", st.roll_deg)?;
                finite("trajectory.pitch_deg", st.pitch_deg)?;
                if st.pitch_deg.abs() >= 89.0 {
                    return Err(invalid(f, "trajectory.pitch_deg", "must be within ±89°"));
                }
                finite("trajectory.heading_deg", st.heading_deg)?;
                let mut end = 0.0;
                for (i, mv) in st.turntable.iter().enumerate() {
                    let k = format!("trajectory.turntable[{i}]");
                    nonneg(&format!("{k}.start_s"), mv.start_s)?;
                    finite(&format!("{k}.to_deg"), mv.to_deg)?;
                    positive(&format!("{k}.duration_s"), mv.duration_s)?;
                    if mv.start_s < end {
                        return Err(invalid(
                            f,
                            format!("{k}.start_s"),
                            "overlaps the previous move",
                        ));
                    }
                    end = mv.start_s + mv.duration_s;
                }
            }
            Trajectory::GroundVehicle(gv) => validate_segments(
                f,
                gv.initial_heading_deg,
                &gv.segments,
                Mover::GroundVehicle,
            )?,
        }
        rate("imu.rate_hz", spec.imu.rate_hz)?;
        if let Some(ch) = &spec.imu.channels {
            validate_channels(f, ch, spec.scenario.duration_s)?;
        }
        finite("imu.temperature.initial_c", spec.imu.temperature.initial_c)?;
        finite(
            "imu.temperature.rate_c_per_h",
            spec.imu.temperature.rate_c_per_h,
        )?;
        rate("star_tracker.rate_hz", spec.star_tracker.rate_hz)?;
        for (i, k) in spec.star_tracker.mounting_kappa_deg.iter().enumerate() {
            finite(&format!("star_tracker.mounting_kappa_deg[{i}]"), *k)?;
        }
        windows("star_tracker.outages", &spec.star_tracker.outages)?;
        rate("gnss.rate_hz", spec.gnss.rate_hz)?;
        windows("gnss.outages", &spec.gnss.outages)?;
        let c = &spec.gnss.constellation;
        let max = crate::gnss::MAX_CONSTELLATION as u32;
        if c.planes == 0 || c.per_plane == 0 || c.planes.saturating_mul(c.per_plane) > max {
            return Err(invalid(
                f,
                "gnss.constellation.planes",
                format!(
                    "need 1..={max} satellites in total (a sample carries the {} highest in \
                     view)",
                    msgs::MAX_SATELLITES
                ),
            ));
        }
        finite("gnss.constellation.inclination_deg", c.inclination_deg)?;
        finite("gnss.constellation.raan0_deg", c.raan0_deg)?;
        if !(c.semi_major_axis_m.is_finite() && c.semi_major_axis_m > 7.0e6) {
            return Err(invalid(
                f,
                "gnss.constellation.semi_major_axis_m",
                "must be > 7000 km",
            ));
        }
        if let Some(w) = &spec.world {
            w.validate(f)?;
            if w.vehicle().is_some() && !matches!(spec.trajectory, Trajectory::GroundVehicle(_)) {
                return Err(invalid(
                    f,
                    "world.vehicle",
                    "applies to a ground_vehicle trajectory only",
                ));
            }
            if w.star_tracker_latency_ns() >= (1e9 / spec.star_tracker.rate_hz) as i64 {
                return Err(invalid(
                    f,
                    "world.star_tracker.latency_s",
                    "must be shorter than the star tracker's period",
                ));
            }
            if w.gnss_latency_ns() >= (1e9 / spec.gnss.rate_hz) as i64 {
                return Err(invalid(
                    f,
                    "world.gnss_antenna.latency_s",
                    "must be shorter than the GNSS period",
                ));
            }
            // The jitter keeps the measurement instants in order and within one period of
            // their stamps: latency + jitter and twice the jitter below the period.
            if let Some(t) = w.time_tags() {
                for (key, jitter, latency_ns, rate_hz) in [
                    (
                        "gnss_jitter_s",
                        t.gnss_jitter_s,
                        w.gnss_latency_ns(),
                        spec.gnss.rate_hz,
                    ),
                    (
                        "star_tracker_jitter_s",
                        t.star_tracker_jitter_s,
                        w.star_tracker_latency_ns(),
                        spec.star_tracker.rate_hz,
                    ),
                    (
                        "odometer_jitter_s",
                        t.odometer_jitter_s,
                        w.odometer_latency_ns(),
                        spec.odometer.rate_hz,
                    ),
                ] {
                    let period_s = 1.0 / rate_hz;
                    let latency_s = latency_ns as f64 * 1e-9;
                    if !(latency_s + jitter < period_s && 2.0 * jitter < period_s) {
                        return Err(invalid(
                            f,
                            format!("world.time_tags.{key}"),
                            format!(
                                "latency {latency_s} s + jitter {jitter} s and twice the jitter must be shorter than the period {period_s} s"
                            ),
                        ));
                    }
                }
            }
        }
        rate("odometer.rate_hz", spec.odometer.rate_hz)?;
        rate("baro.rate_hz", spec.baro.rate_hz)?;
        rate("truth.rate_hz", spec.truth.rate_hz)?;

        let imu: ImuGrade = load_grade(
            sensors_dir,
            f,
            "imu",
            &spec.imu.grade,
            spec.imu.overrides.as_ref(),
        )?;
        let gf = sensors_dir.join(format!("{}.toml", spec.imu.grade));
        let g = &imu.gyro;
        for (k, v) in [
            ("imu.gyro.bias_deg_h", g.bias_deg_h),
            ("imu.gyro.bias_rw_deg_h_per_rt_h", g.bias_rw_deg_h_per_rt_h),
            ("imu.gyro.arw_deg_per_rt_h", g.arw_deg_per_rt_h),
            ("imu.gyro.scale_factor_ppm", g.scale_factor_ppm),
            ("imu.gyro.misalignment_arcsec", g.misalignment_arcsec),
            ("imu.gyro.temp_coeff_deg_h_per_c", g.temp_coeff_deg_h_per_c),
            ("imu.gyro.full_scale_deg_s", g.full_scale_deg_s),
            ("imu.gyro.delta_angle_lsb_rad", g.delta_angle_lsb_rad),
            ("imu.accel.bias_ug", imu.accel.bias_ug),
            (
                "imu.accel.bias_rw_ug_per_rt_h",
                imu.accel.bias_rw_ug_per_rt_h,
            ),
            ("imu.accel.vrw_ug_per_rt_hz", imu.accel.vrw_ug_per_rt_hz),
            ("imu.accel.scale_factor_ppm", imu.accel.scale_factor_ppm),
            (
                "imu.accel.misalignment_arcsec",
                imu.accel.misalignment_arcsec,
            ),
            (
                "imu.accel.temp_coeff_ug_per_c",
                imu.accel.temp_coeff_ug_per_c,
            ),
            ("imu.accel.full_scale_g", imu.accel.full_scale_g),
            (
                "imu.accel.delta_velocity_lsb_m_s",
                imu.accel.delta_velocity_lsb_m_s,
            ),
            ("imu.warmup_time_s", imu.warmup_time_s),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(&gf, k, format!("must be finite and ≥ 0, got {v}")));
            }
        }
        finite("imu.reference_temperature_c", imu.reference_temperature_c)?;
        for (k, bits, fs) in [
            ("imu.gyro", g.adc_bits, g.full_scale_deg_s),
            ("imu.accel", imu.accel.adc_bits, imu.accel.full_scale_g),
        ] {
            if bits > 32 || (bits > 0 && fs <= 0.0) {
                return Err(invalid(
                    &gf,
                    format!("{k}.adc_bits"),
                    "needs 1..=32 bits and a full scale > 0 (or 0 bits for none)",
                ));
            }
        }

        let star_tracker: StarTrackerGrade = load_grade(
            sensors_dir,
            f,
            "star_tracker",
            &spec.star_tracker.grade,
            spec.star_tracker.overrides.as_ref(),
        )?;
        let sf = sensors_dir.join(format!("{}.toml", spec.star_tracker.grade));
        for (k, v) in [
            (
                "star_tracker.sigma_cross_arcsec",
                star_tracker.sigma_cross_arcsec,
            ),
            (
                "star_tracker.sigma_roll_arcsec",
                star_tracker.sigma_roll_arcsec,
            ),
            (
                "star_tracker.roll_bias_arcsec",
                star_tracker.roll_bias_arcsec,
            ),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(&sf, k, format!("must be finite and ≥ 0, got {v}")));
            }
        }
        if star_tracker.min_stars > star_tracker.max_stars {
            return Err(invalid(
                &sf,
                "star_tracker.min_stars",
                "greater than max_stars",
            ));
        }

        let gnss: GnssGrade = load_grade(
            sensors_dir,
            f,
            "gnss",
            &spec.gnss.grade,
            spec.gnss.overrides.as_ref(),
        )?;
        let nf = sensors_dir.join(format!("{}.toml", spec.gnss.grade));
        for (k, v) in [
            ("gnss.pseudorange_sigma_m", gnss.pseudorange_sigma_m),
            ("gnss.range_rate_sigma_m_s", gnss.range_rate_sigma_m_s),
            (
                "gnss.clock_bias_initial_sigma_m",
                gnss.clock_bias_initial_sigma_m,
            ),
            (
                "gnss.clock_drift_initial_sigma_m_s",
                gnss.clock_drift_initial_sigma_m_s,
            ),
            ("gnss.clock_bias_psd_m2_s", gnss.clock_bias_psd_m2_s),
            ("gnss.clock_drift_psd_m2_s3", gnss.clock_drift_psd_m2_s3),
            ("gnss.phase_sigma_cycles", gnss.phase_sigma_cycles),
            ("gnss.baseline_length_m[0]", gnss.baseline_length_m[0]),
            ("gnss.baseline_length_m[1]", gnss.baseline_length_m[1]),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(&nf, k, format!("must be finite and ≥ 0, got {v}")));
            }
        }
        if !(gnss.elevation_mask_deg.is_finite() && (-5.0..80.0).contains(&gnss.elevation_mask_deg))
        {
            return Err(invalid(&nf, "gnss.elevation_mask_deg", "outside −5..80°"));
        }
        if !(gnss.carrier_frequency_hz.is_finite() && gnss.carrier_frequency_hz > 1e6) {
            return Err(invalid(&nf, "gnss.carrier_frequency_hz", "must be > 1 MHz"));
        }
        for (k, v) in [
            ("gnss.cn0_zenith_dbhz", gnss.cn0_zenith_dbhz),
            ("gnss.cn0_horizon_dbhz", gnss.cn0_horizon_dbhz),
        ] {
            if !(v.is_finite() && (0.0..=70.0).contains(&v)) {
                return Err(invalid(&nf, k, "outside 0..70 dB-Hz"));
            }
        }
        match &gnss.uere {
            Some(u) => {
                for (k, v) in [
                    ("gnss.uere.sis_m", u.sis_m),
                    ("gnss.uere.iono_fraction", u.iono_fraction),
                    ("gnss.uere.tropo_zenith_m", u.tropo_zenith_m),
                    ("gnss.uere.multipath_floor_m", u.multipath_floor_m),
                    ("gnss.uere.multipath_low_m", u.multipath_low_m),
                    ("gnss.uere.multipath_scale_deg", u.multipath_scale_deg),
                    ("gnss.uere.noise_45_dbhz_m", u.noise_45_dbhz_m),
                ] {
                    if !(v.is_finite() && v >= 0.0) {
                        return Err(invalid(&nf, k, format!("must be finite and ≥ 0, got {v}")));
                    }
                }
                if u.sigma_m(std::f64::consts::FRAC_PI_2, 50.0, 0.0) <= 0.0
                    || u.multipath_scale_deg <= 0.0
                {
                    return Err(invalid(
                        &nf,
                        "gnss.uere",
                        "needs a σ > 0 at the zenith and multipath_scale_deg > 0",
                    ));
                }
            }
            None if spec.world.is_some_and(|w| w.gnss_errors_on()) => {
                return Err(invalid(
                    &nf,
                    "gnss.uere",
                    "a scenario with [world] pseudorange errors needs the receiver's error \
                     budget [gnss.uere] in its grade (the σ it reports and weights its fix with)",
                ));
            }
            None => {}
        }

        let odometer: OdometerGrade = load_grade(
            sensors_dir,
            f,
            "odometer",
            &spec.odometer.grade,
            spec.odometer.overrides.as_ref(),
        )?;
        let of = sensors_dir.join(format!("{}.toml", spec.odometer.grade));
        if !(odometer.scale_factor_error_ppm.is_finite()
            && odometer.scale_factor_error_ppm.abs() < 1e5)
        {
            return Err(invalid(
                &of,
                "odometer.scale_factor_error_ppm",
                "|value| must be < 1e5",
            ));
        }
        if !(odometer.speed_noise_m_s.is_finite() && odometer.speed_noise_m_s >= 0.0) {
            return Err(invalid(
                &of,
                "odometer.speed_noise_m_s",
                "must be finite and ≥ 0",
            ));
        }
        let baro: BaroGrade = load_grade(
            sensors_dir,
            f,
            "baro",
            &spec.baro.grade,
            spec.baro.overrides.as_ref(),
        )?;
        let bf = sensors_dir.join(format!("{}.toml", spec.baro.grade));
        for (k, v) in [
            ("baro.bias_pa", baro.bias_pa),
            ("baro.bias_rw_pa_per_rt_s", baro.bias_rw_pa_per_rt_s.abs()),
            ("baro.noise_pa", baro.noise_pa),
        ] {
            if !v.is_finite() || (k != "baro.bias_pa" && v < 0.0) {
                return Err(invalid(
                    &bf,
                    k,
                    format!("must be finite (and ≥ 0), got {v}"),
                ));
            }
        }
        Ok(Scenario {
            file: file.to_path_buf(),
            spec,
            start,
            imu,
            star_tracker,
            gnss,
            odometer,
            baro,
        })
    }

    /// Duration of the run, ns.
    pub fn duration_ns(&self) -> i64 {
        (self.spec.scenario.duration_s * 1e9).round() as i64
    }

    /// GPS time of the scenario epoch (needs `fusion::time`).
    pub fn epoch_gps(&self) -> fusion::time::GpsTime {
        fusion::time::GpsTime::from_utc_datetime(&self.start)
    }

    /// This scenario's unit of aiding `sensor` (`"star_tracker"`, `"odometer"`, `"baro"`,
    /// `"gnss"`; `[world.units]`), or its data sheet without that table.
    pub fn aiding_unit(&self, sensor: &str) -> crate::world::units::AidingUnit {
        self.spec
            .world
            .map_or(crate::world::units::AidingUnit::DATA_SHEET, |w| {
                w.aiding_unit(self.spec.scenario.seed, sensor)
            })
    }

    /// The world's gravity disturbance at the site, NED, m/s² (true gravity minus the normal
    /// gravity an INS computes; its horizontal part is `g` times the deflection of the
    /// vertical): what a unit standing at the site senses beyond the normal gravity. Zero
    /// without `[world.gravity]`. The same draw as every driver's truth (stream
    /// `"world_gravity"` of the scenario seed).
    pub fn site_gravity_disturbance_ned_m_s2(&self) -> nalgebra::Vector3<f64> {
        crate::world::MotionWorld::new(self.spec.world.as_ref(), self.spec.scenario.seed)
            .gravity
            .map_or_else(nalgebra::Vector3::zeros, |field| {
                field.disturbance_ned_m_s2(0.0, 0.0, 0.0)
            })
    }
}

/// Checks of `[imu.channels]` (paper 004 channels).
fn validate_channels(f: &Path, ch: &ImuChannelsSpec, duration_s: f64) -> Result<(), SimError> {
    let max = msgs::MAX_IMU_CHANNELS;
    match ch.layout {
        ChannelLayout::Pyramid => {
            let n = ch.n.unwrap_or(4);
            if !(3..=max).contains(&n) {
                return Err(invalid(
                    f,
                    "imu.channels.n",
                    format!("needs 3..={max}, got {n}"),
                ));
            }
            let a = ch.alpha_deg.unwrap_or(28.7);
            if !(a.is_finite() && a.abs() < 89.0 && a.abs() > 1.0) {
                return Err(invalid(
                    f,
                    "imu.channels.alpha_deg",
                    format!("{a} must be within 1..89° in magnitude (axes must span 3-D)"),
                ));
            }
        }
        ChannelLayout::Orthogonal => {}
        ChannelLayout::Axes => {
            let n = ch.axes.len();
            if !(3..=max).contains(&n) {
                return Err(invalid(
                    f,
                    "imu.channels.axes",
                    format!("needs 3..={max} axes, got {n}"),
                ));
            }
            for (i, a) in ch.axes.iter().enumerate() {
                let norm = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
                if !(norm.is_finite() && norm > 1e-6) {
                    return Err(invalid(
                        f,
                        format!("imu.channels.axes[{i}]"),
                        "must be a finite non-zero vector",
                    ));
                }
            }
        }
    }
    let axes = ch.unit_axes();
    let h = fusion::redundancy::measurement_matrix(
        &{
            let mut a = [[0.0; 3]; msgs::MAX_IMU_CHANNELS];
            a[..axes.len()].copy_from_slice(&axes);
            a
        },
        (1u32 << axes.len()) - 1,
    );
    if fusion::redundancy::ls_covariance_per_unit_variance(&h).is_none() {
        return Err(invalid(
            f,
            "imu.channels",
            "the channel axes do not span 3-D",
        ));
    }
    if ch.temperature_offsets_c.len() > axes.len()
        || ch.temperature_offsets_c.iter().any(|t| !t.is_finite())
    {
        return Err(invalid(
            f,
            "imu.channels.temperature_offsets_c",
            "one finite value per channel at most",
        ));
    }
    for (i, fl) in ch.failures.iter().enumerate() {
        let k = format!("imu.channels.failures[{i}]");
        if fl.channel >= axes.len() {
            return Err(invalid(
                f,
                format!("{k}.channel"),
                format!("{} is not a channel (0..{})", fl.channel, axes.len()),
            ));
        }
        if !(fl.start_s.is_finite() && (0.0..=duration_s).contains(&fl.start_s)) {
            return Err(invalid(f, format!("{k}.start_s"), "outside the run"));
        }
        if fl.duration_s.is_some_and(|d| !(d.is_finite() && d > 0.0)) {
            return Err(invalid(f, format!("{k}.duration_s"), "must be > 0"));
        }
        if !fl.magnitude.is_finite() {
            return Err(invalid(f, format!("{k}.magnitude"), "must be finite"));
        }
    }
    Ok(())
}

/// What moves along a segment list: what its segments may ask of it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mover {
    GroundVehicle,
    Aircraft,
}

/// Checks of a segment list: durations, the speed each segment leaves, and what the mover can do
/// (a car turns only while moving and never pitches on its own; an aircraft's coordinated turn
/// keeps its bank below 60°, its flight-path angle within ±30°).
fn validate_segments(
    f: &Path,
    initial_heading_deg: f64,
    segments: &[Segment],
    mover: Mover,
) -> Result<(), SimError> {
    if !initial_heading_deg.is_finite() {
        return Err(invalid(
            f,
            "trajectory.initial_heading_deg",
            format!("must be finite, got {initial_heading_deg}"),
        ));
    }
    let max_speed_m_s = match mover {
        Mover::GroundVehicle => 100.0,
        Mover::Aircraft => 300.0,
    };
    let mut speed = 0.0;
    for (i, seg) in segments.iter().enumerate() {
        let k = format!("trajectory.segments[{i}]");
        let d = seg.duration_s();
        if !(d.is_finite() && d > 0.0) {
            return Err(invalid(
                f,
                format!("{k}.duration_s"),
                format!("must be > 0, got {d}"),
            ));
        }
        match *seg {
            Segment::Hold { .. } if speed != 0.0 => {
                return Err(invalid(
                    f,
                    format!("{k}.type"),
                    "`hold` needs the vehicle stopped (add a `speed` segment to 0)",
                ));
            }
            Segment::Speed { to_m_s, .. } => {
                if !(to_m_s.is_finite() && (0.0..=max_speed_m_s).contains(&to_m_s)) {
                    return Err(invalid(
                        f,
                        format!("{k}.to_m_s"),
                        format!("{to_m_s} is outside 0..{max_speed_m_s} m/s"),
                    ));
                }
                speed = to_m_s;
            }
            Segment::Turn {
                angle_deg,
                duration_s,
            } => {
                if !angle_deg.is_finite() {
                    return Err(invalid(
                        f,
                        format!("{k}.angle_deg"),
                        format!("must be finite, got {angle_deg}"),
                    ));
                }
                if speed == 0.0 {
                    return Err(invalid(
                        f,
                        format!("{k}.type"),
                        "a vehicle cannot turn while stopped",
                    ));
                }
                // Peak turn rate of the raised-cosine profile is 2·Δψ/T; the coordinated
                // turn's bank atan(V·ψ̇/g) must stay below 60°.
                let peak_rad_s = 2.0 * angle_deg.to_radians().abs() / duration_s;
                if mover == Mover::Aircraft && speed * peak_rad_s / 9.806_65 > 3f64.sqrt() {
                    return Err(invalid(
                        f,
                        format!("{k}.angle_deg"),
                        "the turn needs a peak bank above 60°: turn by less or for longer",
                    ));
                }
            }
            Segment::Pitch { to_deg, .. } => {
                if mover == Mover::GroundVehicle {
                    return Err(invalid(
                        f,
                        format!("{k}.type"),
                        "a ground vehicle's pitch follows its road ([world.vehicle]); \
                         `pitch` segments are for aircraft",
                    ));
                }
                if !(to_deg.is_finite() && to_deg.abs() <= 30.0) {
                    return Err(invalid(
                        f,
                        format!("{k}.to_deg"),
                        format!("{to_deg} is outside ±30°"),
                    ));
                }
            }
            Segment::Hold { .. } | Segment::Cruise { .. } => {}
        }
    }
    Ok(())
}

/// Sample period of a rate validated by [`Scenario::validate`], ns.
pub fn period_ns(rate_hz: f64) -> i64 {
    (1e9 / rate_hz).round() as i64
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shipped(name: &str) -> (std::path::PathBuf, String) {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../config/scenarios")
            .join(name);
        let text = std::fs::read_to_string(&path).unwrap();
        (path, text)
    }

    /// A grade that has no file is the scenario's mistake: the error names the scenario file,
    /// the key and the grades that exist.
    #[test]
    fn unknown_grade_names_the_scenario_key_and_the_known_grades() {
        let (path, text) = shipped("static_site.toml");
        let line = text
            .lines()
            .skip_while(|l| l.trim() != "[gnss]")
            .find(|l| l.trim_start().starts_with("grade"))
            .expect("static_site.toml has a [gnss] grade");
        let broken = text.replacen(line, "grade = \"}\"", 1);
        let e = Scenario::from_toml_str(&broken, &path)
            .unwrap_err()
            .to_string();
        assert!(e.contains("static_site.toml"), "{e}");
        assert!(e.contains("gnss.grade"), "{e}");
        assert!(e.contains("unknown grade `}`"), "{e}");
        assert!(e.contains("known grades:"), "{e}");
    }

    /// One segment grammar for cars and aircraft; what each can do is checked by mover and
    /// named by key: a car's `pitch` segment and an aircraft's turn beyond a 60° bank are refused.
    #[test]
    fn segments_are_checked_for_what_the_mover_can_do() {
        let (path, text) = shipped("vehicle.toml");
        let car = "{ type = \"cruise\", duration_s = 30.0 },     # ends at 368 s";
        assert!(text.contains(car), "vehicle.toml has its cruise to 368 s");
        let pitched = text.replacen(
            car,
            "{ type = \"pitch\", to_deg = 3.0, duration_s = 30.0 },",
            1,
        );
        let e = Scenario::from_toml_str(&pitched, &path)
            .unwrap_err()
            .to_string();
        assert!(e.contains("trajectory.segments[10].type"), "{e}");
        assert!(e.contains("pitch follows its road"), "{e}");

        let (path, text) = shipped("uav.toml");
        let turn = "{ type = \"turn\", angle_deg = 90.0, duration_s = 60.0 },";
        assert!(text.contains(turn), "uav.toml has a 90° turn in 60 s");
        // 30 m/s, peak rate 2·90°/2 s = π/2 rad/s: bank atan(4.8) ≈ 78°.
        let steep = text.replacen(
            turn,
            "{ type = \"turn\", angle_deg = 90.0, duration_s = 2.0 },",
            1,
        );
        let e = Scenario::from_toml_str(&steep, &path)
            .unwrap_err()
            .to_string();
        assert!(e.contains("trajectory.segments[6].angle_deg"), "{e}");
        assert!(e.contains("bank above 60°"), "{e}");
        assert!(Scenario::from_toml_str(&text, &path).is_ok());
    }

    /// A scratch configuration directory: `scenarios/s.toml` (the shipped static site without
    /// its world, then `scenario`) and `worlds/` with the given files; the sensor grades are the
    /// shipped ones. Returns the scenario's path.
    fn scratch(tag: &str, scenario: &str, worlds: &[(&str, &str)]) -> PathBuf {
        let dir = std::env::temp_dir().join(format!(
            "sextant-world-include-{tag}-{}",
            std::process::id()
        ));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("scenarios")).unwrap();
        std::fs::create_dir_all(dir.join("worlds")).unwrap();
        for (name, text) in worlds {
            std::fs::write(dir.join("worlds").join(name), text).unwrap();
        }
        let sensors = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/sensors");
        let path = dir.join("scenarios/s.toml");
        let head = shipped("static_site.toml").1;
        let head = &head[..head.find("\n[world").unwrap() + 1];
        let head = head.replacen(
            "seed = 1\n",
            &format!(
                "seed = 1\nsensors_dir = {:?}\n",
                sensors.display().to_string()
            ),
            1,
        );
        assert!(
            head.contains("sensors_dir"),
            "static_site.toml has `seed = 1`"
        );
        std::fs::write(&path, format!("{head}\n{scenario}")).unwrap();
        path
    }

    const WORLD: &str = "# a shared world\n\
        [world.code_noise]\nsigma_at_45_dbhz_m = 0.3\n\
        [world.gnss_antenna]\nlever_arm_b_m = [0.3, 0.0, -1.5]\nlatency_s = 0.05\n\
        [world.units]\nnoise_log_sigma = 0.2\noscillator_log_sigma = 0.5\n";

    /// The scenario's own keys win over the included ones key by key; the included keys it
    /// does not name stay; a table it adds is added; `enabled = false` switches an included
    /// effect off.
    #[test]
    fn world_include_merges_key_by_key() {
        let path = scratch(
            "merge",
            "[world]\ninclude = \"../worlds/w.toml\"\n\
             [world.gnss_antenna]\nlatency_s = 0.02\n\
             [world.units]\nenabled = false\n\
             [world.gravity]\nanomaly_sigma_mgal = 10.0\ncorrelation_length_km = 5.0\n",
            &[("w.toml", WORLD)],
        );
        let w = Scenario::load(&path).unwrap().spec.world.unwrap();
        let antenna = w.gnss_antenna.unwrap();
        assert_eq!(antenna.latency_s, 0.02);
        assert_eq!(antenna.lever_arm_b_m, [0.3, 0.0, -1.5]);
        assert_eq!(w.code_noise.unwrap().sigma_at_45_dbhz_m, 0.3);
        let units = w.units.unwrap();
        assert!(!units.enabled && units.noise_log_sigma == 0.2);
        assert!(w.units().is_none());
        assert_eq!(w.gravity.unwrap().anomaly_sigma_mgal, 10.0);
        assert!(w.ionosphere.is_none());
        // The merged document: no include left, the scenario's value in place.
        let doc = Scenario::read_resolved_toml(&path).unwrap();
        let world = doc["world"].as_table().unwrap();
        assert!(!world.contains_key(WORLD_INCLUDE));
        assert_eq!(world["gnss_antenna"]["latency_s"].as_float(), Some(0.02));
        assert_eq!(
            world["code_noise"]["sigma_at_45_dbhz_m"].as_float(),
            Some(0.3)
        );
        // It loads to the same scenario as the file.
        let again = Scenario::from_toml_str(&toml::to_string(&doc).unwrap(), &path).unwrap();
        assert_eq!(format!("{:?}", again.spec.world), format!("{:?}", Some(w)));
        std::fs::remove_dir_all(path.parent().unwrap().parent().unwrap()).unwrap();
    }

    /// A world include is resolved relative to the scenario file's directory, an absolute one
    /// as it is; a scenario with only the include has exactly the included world.
    #[test]
    fn world_include_is_relative_to_the_scenario() {
        let path = scratch(
            "relative",
            "[world]\ninclude = \"../worlds/w.toml\"\n",
            &[("w.toml", WORLD)],
        );
        let dir = path.parent().unwrap().parent().unwrap().to_path_buf();
        let included = Scenario::load(&path).unwrap().spec.world;
        let abs = dir.join("worlds/w.toml");
        let text = std::fs::read_to_string(&path).unwrap().replace(
            "\"../worlds/w.toml\"",
            &format!("{:?}", abs.display().to_string()),
        );
        let absolute = Scenario::from_toml_str(&text, &path).unwrap().spec.world;
        let own = std::fs::read_to_string(&path)
            .unwrap()
            .replace("[world]\ninclude = \"../worlds/w.toml\"\n", WORLD);
        let written = Scenario::from_toml_str(&own, &path).unwrap().spec.world;
        assert_eq!(format!("{included:?}"), format!("{written:?}"));
        assert_eq!(format!("{absolute:?}"), format!("{written:?}"));
        // Relative to the scenario, not to the working directory.
        let e = Scenario::from_toml_str(
            &text.replace(&abs.display().to_string(), "worlds/w.toml"),
            &path,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains(&dir.join("scenarios/worlds/w.toml").display().to_string()),
            "{e}"
        );
        std::fs::remove_dir_all(dir).unwrap();
    }

    /// An include that cannot be used is an error naming the scenario, the include as written
    /// and what is wrong.
    #[test]
    fn bad_world_include_names_scenario_include_and_reason() {
        // (include, the world files written, what the error says)
        type Case<'a> = (&'a str, &'a [(&'a str, &'a str)], &'a str);
        let cases: [Case; 6] = [
            ("missing.toml", &[], "cannot read"),
            (
                "w.toml",
                &[("w.toml", "[world.code_noise\n")],
                "not a valid TOML file",
            ),
            (
                "w.toml",
                &[("w.toml", "[imu]\ngrade = \"mems\"\n")],
                "holds only `[world.<effect>]` tables",
            ),
            (
                "w.toml",
                &[
                    ("w.toml", "[world]\ninclude = \"v.toml\"\n"),
                    ("v.toml", WORLD),
                ],
                "cannot include another",
            ),
            (
                "w.toml",
                &[("w.toml", "[world.code_noise]\nsigma_m = 0.3\n")],
                "[world.code_noise]",
            ),
            (
                "w.toml",
                &[("w.toml", "[world.nowhere]\nsigma_m = 0.3\n")],
                "nowhere",
            ),
        ];
        for (i, (include, worlds, reason)) in cases.into_iter().enumerate() {
            let path = scratch(
                &format!("bad{i}"),
                &format!("[world]\ninclude = \"../worlds/{include}\"\n"),
                worlds,
            );
            let e = Scenario::load(&path).unwrap_err().to_string();
            assert!(e.contains(&path.display().to_string()), "{e}");
            assert!(e.contains(include), "{e}");
            assert!(e.contains(reason), "{reason}: {e}");
            std::fs::remove_dir_all(path.parent().unwrap().parent().unwrap()).unwrap();
        }
        // An error outside `[world]` in a scenario with an include names its key and line.
        let path = scratch(
            "line",
            "[world]\ninclude = \"../worlds/w.toml\"\n",
            &[("w.toml", WORLD)],
        );
        let text = std::fs::read_to_string(&path).unwrap();
        let line = 1 + text.lines().position(|l| l.starts_with("lat_deg")).unwrap();
        let broken = text.replacen("lat_deg = 55.655", "lat_deg = \"north\"", 1);
        assert_ne!(broken, text, "static_site.toml has `lat_deg = 55.655`");
        let e = Scenario::from_toml_str(&broken, &path)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("s.toml") && e.contains("lat_deg") && e.contains(&format!("line {line}")),
            "{e}"
        );
        std::fs::remove_dir_all(path.parent().unwrap().parent().unwrap()).unwrap();
        // Not a string.
        let path = scratch("type", "[world]\ninclude = 3\n", &[]);
        let e = Scenario::load(&path).unwrap_err().to_string();
        assert!(e.contains("world.include") && e.contains("s.toml"), "{e}");
        std::fs::remove_dir_all(path.parent().unwrap().parent().unwrap()).unwrap();
    }

    /// The shipped scenarios load as they are.
    #[test]
    fn shipped_scenarios_load() {
        for name in ["static_site.toml", "vehicle.toml"] {
            let (path, text) = shipped(name);
            Scenario::from_toml_str(&text, &path).unwrap();
        }
    }
}
