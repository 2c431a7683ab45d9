//! The simulated world: truth-only effects the navigation filter does not model.
//!
//! A scenario's optional `[world]` section names every effect and its magnitude; each effect
//! is switchable (`enabled = false`, or leave its table out). Without a `[world]` section the
//! simulator is the *matched* world: GNSS errors white with exactly the covariance the
//! receiver reports — a fixture for the filter's algebra, not a test of navigation.
//!
//! With it, the GNSS receiver ([`crate::gnss`]) sees, per satellite: the ionosphere
//! ([`ionosphere`]), the troposphere ([`troposphere`]), multipath ([`multipath`]), echoes of
//! satellites hidden by buildings ([`nlos`]), broadcast clock and orbit errors ([`satellite`]), code tracking noise by C/N0 ([`CodeNoiseSpec`]),
//! its own oscillator ([`receiver_clock`]) and the antenna's lever arm and time-tag latency
//! ([`antenna`]); its baseline carrier-phase differences carry an unknown integer per
//! satellite and baseline, cycle slips and a lock indicator ([`carrier_phase`]) and the
//! differential carrier-phase multipath of the two antennas ([`phase_multipath`]); it corrects the pseudoranges with its own broadcast models and reports a
//! least-squares fix with the covariance of its own noise model, as a receiver does.
//!
//! The motion world ([`MotionWorld`], built by every driver's [`crate::truth::TruthGenerator`]
//! from its own streams of the seed, so all processes agree bit for bit) changes the truth
//! itself: a ground vehicle on a real road ([`vehicle`]: terrain grade and bank as random
//! functions of the distance driven, suspension load transfer and ride, sideslip in turns, a
//! slipping odometer wheel with its lever arm), the IMU's mount vibration (engine orders and
//! broadband) and a gravity disturbance field ([`gravity`]: anomaly and deflection of the
//! vertical from one harmonic potential). Its random functions are sums of random-phase
//! cosines ([`spectral`]) with analytic derivatives, so the attitude, velocity and position
//! stay exactly consistent and the IMU's increments come from the perturbed motion: a perfect
//! strapdown INS follows it. Only the gravity disturbance separates the IMU from a perfect
//! INS's normal gravity, as the real field does. The sensors' own worlds: the actual IMU unit
//! ([`imu_unit`]: its noise and bias instability scattered about the data sheet, g-sensitive
//! gyro drift, warm-up), the star tracker's thermal error, boresight bias and time-tag latency
//! and the barometer's day of weather ([`aiding`]), and every aiding sensor as a unit of its
//! model ([`units`]: noise and oscillator scattered about the data sheet, constant errors drawn),
//! and the host's time-stamping of them ([`time_tags`]: the odometer's latency, every stamp's
//! jitter). Off unless a table is present and enabled;
//! every table is on in `config/scenarios/vehicle.toml`, the default scenario (its shared world
//! `config/worlds/car.toml` and its own carrier-phase tracking). A scenario's tables may come
//! from a shared world file (`[world] include`, merged key by key: [`crate::scenario`]).
//!
//! These models are the world's own: none calls `fusion`'s ionosphere, troposphere or gravity
//! models, nor its sensor error models (only its proven foundations: ellipsoid, time, frames;
//! the truth's normal gravity under the disturbance is the generator's own J2 field, as before).

pub mod aiding;
pub mod antenna;
pub mod carrier_phase;
pub mod gauss_markov;
pub mod gravity;
pub mod imu_unit;
pub mod ionosphere;
pub mod multipath;
pub mod nlos;
pub mod phase_multipath;
pub mod receiver_clock;
pub mod satellite;
pub mod spectral;
pub mod time_tags;
pub mod troposphere;
pub mod units;
pub mod vehicle;

#[cfg(test)]
mod motion_tests;

use crate::SimError;
use antenna::GnssAntennaSpec;
use carrier_phase::CarrierPhaseSpec;
use gravity::{GravityField, GravitySpec};
use ionosphere::{Ionosphere, IonosphereSpec};
use multipath::{Multipath, MultipathSpec};
use nalgebra::Vector3;
use nlos::{Nlos, NlosSpec};
use phase_multipath::PhaseMultipathSpec;
use rand_chacha::ChaCha20Rng;
use receiver_clock::ReceiverClockSpec;
use satellite::{EphemerisSpec, SatelliteClockSpec, SignalInSpace};
use serde::Deserialize;
use std::path::Path;
use troposphere::{Troposphere, TroposphereSpec};
use vehicle::{VehicleSpec, VehicleWorld, Vibration, VibrationSpec};

/// One arcsecond, rad.
pub const ARCSEC_RAD: f64 = std::f64::consts::PI / 180.0 / 3600.0;

pub(crate) fn yes() -> bool {
    true
}

/// `[world.code_noise]`: code tracking noise, white, by carrier-to-noise density.
///
/// `σ(C/N0) = σ₄₅·10^{(45 − C/N0)/20}`: the delay-lock-loop jitter scales as `1/√(C/N0)`
/// (Kaplan & Hegarty, "Understanding GPS/GNSS", 3rd ed., eq. 8.48, thermal term).
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CodeNoiseSpec {
    /// Whether the effect is applied.
    #[serde(default = "yes")]
    pub enabled: bool,
    /// 1-σ pseudorange noise at 45 dB-Hz, m.
    pub sigma_at_45_dbhz_m: f64,
}

impl CodeNoiseSpec {
    /// 1-σ at `cn0_dbhz`, m.
    pub fn sigma_m(&self, cn0_dbhz: f64) -> f64 {
        self.sigma_at_45_dbhz_m * 10f64.powf((45.0 - cn0_dbhz) / 20.0)
    }
}

/// `[world]`: every truth-only effect with its magnitude.
#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldSection {
    /// Ionospheric group delay.
    pub ionosphere: Option<IonosphereSpec>,
    /// Tropospheric delay.
    pub troposphere: Option<TroposphereSpec>,
    /// Code multipath.
    pub multipath: Option<MultipathSpec>,
    /// Non-line-of-sight reception (echoes off buildings).
    pub nlos: Option<NlosSpec>,
    /// Broadcast satellite clock error.
    pub satellite_clock: Option<SatelliteClockSpec>,
    /// Broadcast orbit error.
    pub ephemeris: Option<EphemerisSpec>,
    /// Code tracking noise.
    pub code_noise: Option<CodeNoiseSpec>,
    /// Receiver oscillator (replaces the grade's clock PSDs).
    pub receiver_clock: Option<ReceiverClockSpec>,
    /// Antenna lever arm and time-tag latency.
    pub gnss_antenna: Option<GnssAntennaSpec>,
    /// Integer ambiguity, cycle slips and lock indicator of the baseline carrier phases.
    pub carrier_phase: Option<CarrierPhaseSpec>,
    /// Differential carrier-phase multipath of the baseline phases.
    pub phase_multipath: Option<PhaseMultipathSpec>,
    /// Ground vehicle on a real road: terrain, suspension, sideslip, wheel slip, odometer
    /// lever arm (ground-vehicle trajectories only).
    pub vehicle: Option<VehicleSpec>,
    /// Vibration of the IMU on its mount.
    pub vibration: Option<VibrationSpec>,
    /// Gravity disturbance: anomaly and deflection of the vertical.
    pub gravity: Option<GravitySpec>,
    /// The actual IMU unit: scatter about its data sheet, g-sensitivity, warm-up.
    pub imu: Option<imu_unit::ImuUnitSpec>,
    /// Star tracker: thermal error, bias about the boresight, time-tag latency.
    pub star_tracker: Option<aiding::StarTrackerWorldSpec>,
    /// The barometer's air (day's pressure, temperature, tendency) and its sensor's
    /// temperature coefficient.
    pub baro: Option<aiding::BaroWorldSpec>,
    /// The aiding sensors as units of their model: noise and oscillator scatter, constant
    /// errors drawn per unit.
    pub units: Option<units::UnitsSpec>,
    /// Host time-stamping: the odometer's latency and every aiding stamp's jitter.
    pub time_tags: Option<time_tags::TimeTagsSpec>,
}

/// The GNSS part of `[world]`: every effect on the pseudoranges, the receiver's oscillator,
/// the antenna and the carrier phases, by table name (the first entries of [`EFFECTS`]).
pub const GNSS_EFFECTS: [&str; 11] = [
    "ionosphere",
    "troposphere",
    "multipath",
    "nlos",
    "satellite_clock",
    "ephemeris",
    "code_noise",
    "receiver_clock",
    "gnss_antenna",
    "carrier_phase",
    "phase_multipath",
];

/// Every effect of `[world]`, by its table name.
pub const EFFECTS: [&str; 19] = [
    GNSS_EFFECTS[0],
    GNSS_EFFECTS[1],
    GNSS_EFFECTS[2],
    GNSS_EFFECTS[3],
    GNSS_EFFECTS[4],
    GNSS_EFFECTS[5],
    GNSS_EFFECTS[6],
    GNSS_EFFECTS[7],
    GNSS_EFFECTS[8],
    GNSS_EFFECTS[9],
    GNSS_EFFECTS[10],
    "vehicle",
    "vibration",
    "gravity",
    "imu",
    "star_tracker",
    "baro",
    "units",
    "time_tags",
];

/// Calls macro `$m` with every table's field of [`WorldSection`], in the order of [`EFFECTS`].
macro_rules! every_table {
    ($m:ident) => {
        $m!(
            ionosphere,
            troposphere,
            multipath,
            nlos,
            satellite_clock,
            ephemeris,
            code_noise,
            receiver_clock,
            gnss_antenna,
            carrier_phase,
            phase_multipath,
            vehicle,
            vibration,
            gravity,
            imu,
            star_tracker,
            baro,
            units,
            time_tags
        )
    };
}

impl WorldSection {
    /// Each table of [`EFFECTS`], in that order: (present, present and enabled).
    fn tables(&self) -> [(bool, bool); EFFECTS.len()] {
        macro_rules! flags {
            ($($field:ident),*) => {
                [$((self.$field.is_some(), self.$field.is_some_and(|s| s.enabled)),)*]
            };
        }
        every_table!(flags)
    }

    /// The effects whose tables are present (enabled or not), in the order of [`EFFECTS`].
    pub fn effects_present(&self) -> Vec<&'static str> {
        EFFECTS
            .iter()
            .zip(self.tables())
            .filter_map(|(name, (present, _))| present.then_some(*name))
            .collect()
    }

    /// The effects switched on (present and enabled), in the order of [`EFFECTS`].
    pub fn effects_on(&self) -> Vec<&'static str> {
        EFFECTS
            .iter()
            .zip(self.tables())
            .filter_map(|(name, (_, on))| on.then_some(*name))
            .collect()
    }

    /// This world with only the effects named in `keep` (table names, [`EFFECTS`]), each of
    /// them switched on (`enabled = true`); the others are removed, as if their tables were
    /// left out. A name that is not an effect is an error naming it.
    pub fn only(&self, keep: &[&str]) -> Result<Self, String> {
        if let Some(bad) = keep.iter().find(|k| !EFFECTS.contains(k)) {
            return Err(format!(
                "`{bad}` is not a world effect (one of: {})",
                EFFECTS.join(", ")
            ));
        }
        let k = |name: &str| keep.contains(&name);
        macro_rules! keep_on {
            ($($field:ident),*) => {
                Self {
                    $($field: self.$field.filter(|_| k(stringify!($field))).map(|mut s| {
                        s.enabled = true;
                        s
                    }),)*
                }
            };
        }
        Ok(every_table!(keep_on))
    }
}

fn on<T: Copy>(x: Option<T>, enabled: impl Fn(&T) -> bool) -> Option<T> {
    x.filter(|s| enabled(s))
}

impl WorldSection {
    /// Whether any pseudorange error effect is on: then the simulator's receiver is the real
    /// one ([`crate::gnss`]); otherwise the matched one (white errors of the grade's σ),
    /// with the antenna, latency and oscillator of this section still applied.
    pub fn gnss_errors_on(&self) -> bool {
        on(self.ionosphere, |s| s.enabled).is_some()
            || on(self.troposphere, |s| s.enabled).is_some()
            || on(self.multipath, |s| s.enabled).is_some()
            || on(self.nlos, |s| s.enabled).is_some()
            || on(self.satellite_clock, |s| s.enabled).is_some()
            || on(self.ephemeris, |s| s.enabled).is_some()
            || on(self.code_noise, |s| s.enabled).is_some()
    }

    /// The vehicle spec when enabled.
    pub fn vehicle(&self) -> Option<VehicleSpec> {
        on(self.vehicle, |s| s.enabled)
    }
    /// The vibration spec when enabled.
    pub fn vibration(&self) -> Option<VibrationSpec> {
        on(self.vibration, |s| s.enabled)
    }
    /// The gravity spec when enabled.
    pub fn gravity(&self) -> Option<GravitySpec> {
        on(self.gravity, |s| s.enabled)
    }

    /// The star tracker's world when enabled.
    pub fn star_tracker(&self) -> Option<aiding::StarTrackerWorldSpec> {
        on(self.star_tracker, |s| s.enabled)
    }
    /// The star tracker's time-tag latency, ns (0 when off).
    pub fn star_tracker_latency_ns(&self) -> i64 {
        self.star_tracker()
            .map_or(0, |s| (s.latency_s * 1e9).round() as i64)
    }
    /// The barometer's world when enabled.
    pub fn baro(&self) -> Option<aiding::BaroWorldSpec> {
        on(self.baro, |s| s.enabled)
    }
    /// The aiding sensors' unit scatter when enabled.
    pub fn units(&self) -> Option<units::UnitsSpec> {
        on(self.units, |s| s.enabled)
    }
    /// `sensor`'s unit for scenario seed `seed` ([`units::AidingUnit::draw`]), or the data
    /// sheet itself without `[world.units]`.
    pub fn aiding_unit(&self, seed: u64, sensor: &str) -> units::AidingUnit {
        self.units().map_or(units::AidingUnit::DATA_SHEET, |u| {
            units::AidingUnit::draw(&u, seed, sensor)
        })
    }

    /// The host time-stamping when enabled.
    pub fn time_tags(&self) -> Option<time_tags::TimeTagsSpec> {
        on(self.time_tags, |s| s.enabled)
    }
    /// The odometer's latency, ns (0 when off).
    pub fn odometer_latency_ns(&self) -> i64 {
        self.time_tags()
            .map_or(0, |t| (t.odometer_latency_s * 1e9).round() as i64)
    }
    /// How `sensor` is stamped in this world for scenario seed `seed`: its latency and
    /// jitter (stream `"world_time_tag_<sensor>"`); the IMU and the barometer are stamped at
    /// their sampling instant.
    pub fn time_tag(&self, seed: u64, sensor: msgs::SensorId) -> time_tags::TimeTag {
        use msgs::SensorId;
        let t = self.time_tags();
        let (latency_ns, jitter_s, stream) = match sensor {
            SensorId::Gnss => (
                self.gnss_latency_ns(),
                t.map_or(0.0, |t| t.gnss_jitter_s),
                "world_time_tag_gnss",
            ),
            SensorId::StarTracker => (
                self.star_tracker_latency_ns(),
                t.map_or(0.0, |t| t.star_tracker_jitter_s),
                "world_time_tag_star_tracker",
            ),
            SensorId::Odometer => (
                self.odometer_latency_ns(),
                t.map_or(0.0, |t| t.odometer_jitter_s),
                "world_time_tag_odometer",
            ),
            SensorId::Imu | SensorId::Baro => return time_tags::TimeTag::fixed(0),
        };
        // A sample is never stamped before it is measured: the jitter is cut to the latency it
        // scatters about (none where the sensor's latency table is off).
        time_tags::TimeTag::new(
            latency_ns,
            jitter_s.min(latency_ns as f64 * 1e-9),
            crate::sensor_rng(seed, stream),
        )
    }

    /// The IMU unit spec when enabled.
    pub fn imu(&self) -> Option<imu_unit::ImuUnitSpec> {
        on(self.imu, |s| s.enabled)
    }

    /// The antenna spec when enabled.
    pub fn antenna(&self) -> Option<GnssAntennaSpec> {
        on(self.gnss_antenna, |s| s.enabled)
    }
    /// The carrier-phase tracking world when enabled.
    pub fn carrier_phase(&self) -> Option<CarrierPhaseSpec> {
        on(self.carrier_phase, |s| s.enabled)
    }
    /// The baseline phases' multipath when enabled.
    pub fn phase_multipath(&self) -> Option<PhaseMultipathSpec> {
        on(self.phase_multipath, |s| s.enabled)
    }
    /// The receiver oscillator when enabled.
    pub fn receiver_clock(&self) -> Option<ReceiverClockSpec> {
        on(self.receiver_clock, |s| s.enabled)
    }
    /// The antenna lever arm (body, m), zero when off.
    pub fn lever_arm_b_m(&self) -> Vector3<f64> {
        self.antenna()
            .map_or_else(Vector3::zeros, |a| Vector3::from(a.lever_arm_b_m))
    }
    /// The GNSS time-tag latency, ns (0 when off).
    pub fn gnss_latency_ns(&self) -> i64 {
        self.antenna()
            .map_or(0, |a| (a.latency_s * 1e9).round() as i64)
    }

    /// Check every value; errors name `file` and the dotted key.
    pub fn validate(&self, file: &Path) -> Result<(), SimError> {
        let bad = |key: &str, reason: String| SimError::Invalid {
            file: file.to_path_buf(),
            key: format!("world.{key}"),
            reason,
        };
        let nonneg = |key: &str, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(bad(key, format!("must be finite and ≥ 0, got {v}")))
            }
        };
        let positive = |key: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(bad(key, format!("must be finite and > 0, got {v}")))
            }
        };
        if let Some(s) = &self.ionosphere {
            nonneg("ionosphere.night_vtec_tecu", s.night_vtec_tecu)?;
            nonneg("ionosphere.day_vtec_tecu", s.day_vtec_tecu)?;
            if !(0.0..=24.0).contains(&s.peak_local_hour) {
                return Err(bad("ionosphere.peak_local_hour", "outside 0..24 h".into()));
            }
            nonneg("ionosphere.gradient_per_deg", s.gradient_per_deg)?;
            if !(s.shell_height_km.is_finite() && (100.0..=2000.0).contains(&s.shell_height_km)) {
                return Err(bad(
                    "ionosphere.shell_height_km",
                    "outside 100..2000 km".into(),
                ));
            }
            if !(s.residual_fraction.is_finite() && (0.0..1.0).contains(&s.residual_fraction)) {
                return Err(bad("ionosphere.residual_fraction", "outside 0..1".into()));
            }
            positive("ionosphere.residual_tau_s", s.residual_tau_s)?;
        }
        if let Some(s) = &self.troposphere {
            if !(s.sea_level_pressure_hpa.is_finite()
                && (850.0..=1100.0).contains(&s.sea_level_pressure_hpa))
            {
                return Err(bad(
                    "troposphere.sea_level_pressure_hpa",
                    "outside 850..1100 hPa".into(),
                ));
            }
            if !(s.sea_level_temperature_c.is_finite()
                && (-60.0..=60.0).contains(&s.sea_level_temperature_c))
            {
                return Err(bad(
                    "troposphere.sea_level_temperature_c",
                    "outside −60..60 °C".into(),
                ));
            }
            if !(s.relative_humidity.is_finite() && (0.0..=1.0).contains(&s.relative_humidity)) {
                return Err(bad("troposphere.relative_humidity", "outside 0..1".into()));
            }
            nonneg("troposphere.wet_residual_m", s.wet_residual_m)?;
            positive("troposphere.wet_residual_tau_s", s.wet_residual_tau_s)?;
        }
        if let Some(s) = &self.multipath {
            nonneg("multipath.sigma_zenith_m", s.sigma_zenith_m)?;
            nonneg("multipath.sigma_horizon_m", s.sigma_horizon_m)?;
            positive("multipath.elevation_scale_deg", s.elevation_scale_deg)?;
            positive("multipath.tau_s", s.tau_s)?;
        }
        if let Some(s) = &self.phase_multipath {
            nonneg("phase_multipath.sigma_zenith_mm", s.sigma_zenith_mm)?;
            nonneg("phase_multipath.sigma_horizon_mm", s.sigma_horizon_mm)?;
            positive("phase_multipath.elevation_scale_deg", s.elevation_scale_deg)?;
            positive("phase_multipath.tau_s", s.tau_s)?;
        }
        if let Some(s) = &self.nlos {
            for (key, p) in [
                ("nlos.probability_zenith", s.probability_zenith),
                ("nlos.probability_horizon", s.probability_horizon),
            ] {
                if !(p.is_finite() && (0.0..=0.9).contains(&p)) {
                    return Err(bad(key, format!("{p} is outside 0..0.9")));
                }
            }
            positive("nlos.elevation_scale_deg", s.elevation_scale_deg)?;
            positive("nlos.mean_duration_s", s.mean_duration_s)?;
            nonneg("nlos.excess_path_mean_m", s.excess_path_mean_m)?;
            nonneg("nlos.cn0_loss_db", s.cn0_loss_db)?;
        }
        if let Some(s) = &self.satellite_clock {
            nonneg("satellite_clock.sigma_m", s.sigma_m)?;
            positive("satellite_clock.tau_s", s.tau_s)?;
        }
        if let Some(s) = &self.ephemeris {
            nonneg("ephemeris.sigma_radial_m", s.sigma_radial_m)?;
            nonneg("ephemeris.sigma_along_m", s.sigma_along_m)?;
            nonneg("ephemeris.sigma_cross_m", s.sigma_cross_m)?;
            positive("ephemeris.tau_s", s.tau_s)?;
        }
        if let Some(s) = &self.code_noise {
            nonneg("code_noise.sigma_at_45_dbhz_m", s.sigma_at_45_dbhz_m)?;
        }
        if let Some(s) = &self.receiver_clock {
            nonneg("receiver_clock.h0", s.h0)?;
            nonneg("receiver_clock.h_minus2", s.h_minus2)?;
        }
        if let Some(s) = &self.gnss_antenna {
            for (i, v) in s.lever_arm_b_m.iter().enumerate() {
                if !(v.is_finite() && v.abs() <= 50.0) {
                    return Err(bad(
                        &format!("gnss_antenna.lever_arm_b_m[{i}]"),
                        format!("{v} is outside ±50 m"),
                    ));
                }
            }
            let ms = s.latency_s * 1e3;
            if !(s.latency_s.is_finite()
                && (0.0..1.0).contains(&s.latency_s)
                && (ms - ms.round()).abs() < 1e-6)
            {
                return Err(bad(
                    "gnss_antenna.latency_s",
                    format!(
                        "{} must be a whole number of milliseconds (the truth grid) in [0, 1) s",
                        s.latency_s
                    ),
                ));
            }
        }
        if let Some(s) = &self.carrier_phase {
            nonneg(
                "carrier_phase.slips_per_hour_at_45_dbhz",
                s.slips_per_hour_at_45_dbhz,
            )?;
            if !(s.unflagged_fraction.is_finite() && (0.0..=1.0).contains(&s.unflagged_fraction)) {
                return Err(bad(
                    "carrier_phase.unflagged_fraction",
                    "outside 0..1".into(),
                ));
            }
            if !(1..=1000).contains(&s.max_slip_cycles) {
                return Err(bad(
                    "carrier_phase.max_slip_cycles",
                    format!("{} is outside 1..1000", s.max_slip_cycles),
                ));
            }
            if s.initial_ambiguity_cycles > 1_000_000 {
                return Err(bad(
                    "carrier_phase.initial_ambiguity_cycles",
                    format!("{} is above 1e6", s.initial_ambiguity_cycles),
                ));
            }
        }
        if let Some(s) = &self.vehicle {
            for (key, v, max) in [
                ("grade_sigma_deg", s.grade_sigma_deg, 15.0),
                ("bank_sigma_deg", s.bank_sigma_deg, 10.0),
                ("pitch_per_accel_deg", s.pitch_per_accel_deg, 2.0),
                (
                    "roll_per_lateral_accel_deg",
                    s.roll_per_lateral_accel_deg,
                    2.0,
                ),
                (
                    "sideslip_per_lateral_accel_deg",
                    s.sideslip_per_lateral_accel_deg,
                    2.0,
                ),
                ("ride_heave_sigma_m", s.ride_heave_sigma_m, 0.2),
                ("ride_pitch_sigma_deg", s.ride_pitch_sigma_deg, 3.0),
                ("ride_roll_sigma_deg", s.ride_roll_sigma_deg, 3.0),
                ("ride_bandwidth_hz", s.ride_bandwidth_hz, 5.0),
                (
                    "wheel_slip_per_accel_s2_m",
                    s.wheel_slip_per_accel_s2_m,
                    0.05,
                ),
            ] {
                nonneg(&format!("vehicle.{key}"), v)?;
                if v > max {
                    return Err(bad(
                        &format!("vehicle.{key}"),
                        format!("{v} is above the physical bound {max}"),
                    ));
                }
            }
            positive("vehicle.grade_length_m", s.grade_length_m)?;
            positive("vehicle.bank_length_m", s.bank_length_m)?;
            positive("vehicle.ride_frequency_hz", s.ride_frequency_hz)?;
            positive("vehicle.ride_half_speed_m_s", s.ride_half_speed_m_s)?;
            for (i, v) in s.odometer_lever_arm_b_m.iter().enumerate() {
                if !(v.is_finite() && v.abs() <= 10.0) {
                    return Err(bad(
                        &format!("vehicle.odometer_lever_arm_b_m[{i}]"),
                        format!("{v} is outside ±10 m"),
                    ));
                }
            }
        }
        if let Some(s) = &self.vibration {
            positive("vibration.engine_rotation_hz", s.engine_rotation_hz)?;
            for (i, v) in s.engine_order_rms_m_s2.iter().enumerate() {
                nonneg(&format!("vibration.engine_order_rms_m_s2[{i}]"), *v)?;
            }
            nonneg("vibration.broadband_rms_m_s2", s.broadband_rms_m_s2)?;
            let [lo, hi] = s.broadband_band_hz;
            // The truth grid is 1 ms: keep every line below its 500 Hz Nyquist frequency.
            if !(lo.is_finite() && hi.is_finite() && 0.0 < lo && lo < hi && hi <= 400.0)
                || 4.0 * s.engine_rotation_hz > 400.0
            {
                return Err(bad(
                    "vibration.broadband_band_hz",
                    format!(
                        "[{lo}, {hi}] Hz and engine orders up to {} Hz must lie in (0, 400] Hz",
                        4.0 * s.engine_rotation_hz
                    ),
                ));
            }
        }
        if let Some(s) = &self.imu {
            for (key, v, max) in [
                ("noise_log_sigma", s.noise_log_sigma, 1.0),
                (
                    "bias_instability_log_sigma",
                    s.bias_instability_log_sigma,
                    1.0,
                ),
            ] {
                nonneg(&format!("imu.{key}"), v)?;
                if v > max {
                    return Err(bad(&format!("imu.{key}"), format!("{v} is above {max}")));
                }
            }
            nonneg(
                "imu.gyro_g_sensitivity_deg_h_per_g",
                s.gyro_g_sensitivity_deg_h_per_g,
            )?;
            nonneg("imu.gyro_warmup_deg_h", s.gyro_warmup_deg_h)?;
            nonneg("imu.accel_warmup_ug", s.accel_warmup_ug)?;
            positive("imu.warmup_tau_s", s.warmup_tau_s)?;
        }
        if let Some(s) = &self.units {
            for (key, v, max) in [
                ("noise_log_sigma", s.noise_log_sigma, 1.0),
                ("oscillator_log_sigma", s.oscillator_log_sigma, 2.0),
            ] {
                nonneg(&format!("units.{key}"), v)?;
                if v > max {
                    return Err(bad(&format!("units.{key}"), format!("{v} is above {max}")));
                }
            }
        }
        if let Some(s) = &self.star_tracker {
            nonneg("star_tracker.thermal_sigma_arcsec", s.thermal_sigma_arcsec)?;
            positive("star_tracker.thermal_tau_s", s.thermal_tau_s)?;
            nonneg(
                "star_tracker.boresight_bias_sigma_arcsec",
                s.boresight_bias_sigma_arcsec,
            )?;
            let ms = s.latency_s * 1e3;
            if !(s.latency_s.is_finite()
                && (0.0..1.0).contains(&s.latency_s)
                && (ms - ms.round()).abs() < 1e-6)
            {
                return Err(bad(
                    "star_tracker.latency_s",
                    format!(
                        "{} must be a whole number of milliseconds (the truth grid) in [0, 1) s",
                        s.latency_s
                    ),
                ));
            }
        }
        if let Some(s) = &self.baro {
            if !(s.sea_level_pressure_hpa.is_finite()
                && (850.0..=1100.0).contains(&s.sea_level_pressure_hpa))
            {
                return Err(bad(
                    "baro.sea_level_pressure_hpa",
                    "outside 850..1100 hPa".into(),
                ));
            }
            if !(s.temperature_offset_k.is_finite() && s.temperature_offset_k.abs() <= 40.0) {
                return Err(bad("baro.temperature_offset_k", "outside ±40 K".into()));
            }
            nonneg("baro.tendency_sigma_hpa_h", s.tendency_sigma_hpa_h)?;
            if !s.sensor_temp_coeff_pa_per_c.is_finite() {
                return Err(bad(
                    "baro.sensor_temp_coeff_pa_per_c",
                    "must be finite".into(),
                ));
            }
        }
        if let Some(s) = &self.time_tags {
            for (key, v) in [
                ("odometer_latency_s", s.odometer_latency_s),
                ("gnss_jitter_s", s.gnss_jitter_s),
                ("odometer_jitter_s", s.odometer_jitter_s),
                ("star_tracker_jitter_s", s.star_tracker_jitter_s),
            ] {
                let ms = v * 1e3;
                if !(v.is_finite() && (0.0..1.0).contains(&v) && (ms - ms.round()).abs() < 1e-6) {
                    return Err(bad(
                        &format!("time_tags.{key}"),
                        format!(
                            "{v} must be a whole number of milliseconds (the truth grid) in [0, 1) s"
                        ),
                    ));
                }
            }
        }
        if let Some(s) = &self.gravity {
            nonneg("gravity.anomaly_sigma_mgal", s.anomaly_sigma_mgal)?;
            positive("gravity.correlation_length_km", s.correlation_length_km)?;
        }
        Ok(())
    }
}

/// The truth-side world of the motion, shared by every driver's truth generator: each
/// realisation is drawn from its own stream of the scenario seed, so every process builds the
/// same one.
#[derive(Debug, Clone, Default)]
pub struct MotionWorld {
    /// Road, body and odometer wheel (ground vehicles).
    pub vehicle: Option<VehicleWorld>,
    /// IMU mount vibration.
    pub vibration: Option<Vibration>,
    /// Gravity disturbance field.
    pub gravity: Option<GravityField>,
}

impl MotionWorld {
    /// The motion world of `spec` for scenario seed `seed` (streams `"world_vehicle"`,
    /// `"world_vibration"`, `"world_gravity"`); empty without a section.
    pub fn new(spec: Option<&WorldSection>, seed: u64) -> Self {
        let Some(w) = spec else {
            return Self::default();
        };
        Self {
            vehicle: w
                .vehicle()
                .map(|s| VehicleWorld::new(s, &mut crate::sensor_rng(seed, "world_vehicle"))),
            vibration: w
                .vibration()
                .map(|s| Vibration::new(&s, &mut crate::sensor_rng(seed, "world_vibration"))),
            gravity: w
                .gravity()
                .map(|s| GravityField::new(&s, &mut crate::sensor_rng(seed, "world_gravity"))),
        }
    }

    /// Whether no effect is on (the truth is then computed exactly as without a world).
    pub fn is_empty(&self) -> bool {
        self.vehicle.is_none() && self.vibration.is_none() && self.gravity.is_none()
    }
}

/// The GNSS error state of the world during a run: one instance per receiver, advanced once
/// per epoch (every process draws for every satellite, visible or not, so the stream is
/// independent of the geometry).
#[derive(Debug, Clone)]
pub struct GnssWorld {
    spec: WorldSection,
    rng: ChaCha20Rng,
    ionosphere: Option<Ionosphere>,
    troposphere: Option<Troposphere>,
    multipath: Option<Multipath>,
    nlos: Option<Nlos>,
    signal_in_space: SignalInSpace,
}

/// The world's error terms of one satellite's pseudorange, m (positive: the range reads long).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RangeErrors {
    /// Ionospheric group delay.
    pub ionosphere_m: f64,
    /// Tropospheric delay.
    pub troposphere_m: f64,
    /// Code multipath.
    pub multipath_m: f64,
    /// Broadcast satellite clock error.
    pub satellite_clock_m: f64,
}

impl RangeErrors {
    /// Sum of the terms, m.
    pub fn total_m(&self) -> f64 {
        self.ionosphere_m + self.troposphere_m + self.multipath_m + self.satellite_clock_m
    }
}

impl GnssWorld {
    /// The world of `spec` for `n_sats` satellites, drawing from `rng` (the `"world"` stream)
    /// and, for the echoes, from `nlos_rng` (the `"world_nlos"` stream).
    pub fn new(
        spec: WorldSection,
        n_sats: usize,
        mut rng: ChaCha20Rng,
        nlos_rng: ChaCha20Rng,
    ) -> Self {
        let ionosphere =
            on(spec.ionosphere, |s| s.enabled).map(|s| Ionosphere::new(s, n_sats, &mut rng));
        let troposphere =
            on(spec.troposphere, |s| s.enabled).map(|s| Troposphere::new(s, &mut rng));
        let multipath =
            on(spec.multipath, |s| s.enabled).map(|s| Multipath::new(s, n_sats, &mut rng));
        let signal_in_space =
            SignalInSpace::new(spec.satellite_clock, spec.ephemeris, n_sats, &mut rng);
        let nlos = on(spec.nlos, |s| s.enabled).map(|s| Nlos::new(s, n_sats, nlos_rng));
        Self {
            spec,
            rng,
            ionosphere,
            troposphere,
            multipath,
            nlos,
            signal_in_space,
        }
    }

    /// The section it was built from.
    pub fn spec(&self) -> &WorldSection {
        &self.spec
    }

    /// Advance every process by `dt_s`.
    pub fn step(&mut self, dt_s: f64) {
        if let Some(i) = &mut self.ionosphere {
            i.step(dt_s, &mut self.rng);
        }
        if let Some(t) = &mut self.troposphere {
            t.step(dt_s, &mut self.rng);
        }
        if let Some(m) = &mut self.multipath {
            m.step(dt_s, &mut self.rng);
        }
        self.signal_in_space.step(dt_s, &mut self.rng);
        if let Some(n) = &mut self.nlos {
            n.step(dt_s);
        }
    }

    /// Satellite `i` at elevation `el_rad` this epoch: `Some((excess path m, C/N0 loss dB))`
    /// when it is received only through an echo ([`nlos`]), `None` in line of sight or without
    /// the effect. Advances its NLOS chain once per epoch.
    pub fn nlos(&mut self, i: usize, el_rad: f64) -> Option<(f64, f64)> {
        let n = self.nlos.as_mut()?;
        n.update(i, el_rad).map(|d| (d, n.cn0_loss_db()))
    }

    /// Whether the world delays the signals in the ionosphere and in the troposphere. The
    /// receiver's broadcast corrections are applied only for a delay the world has: without
    /// it, they would be an error of their own (the world's effect is the delay *left* after
    /// the receiver's correction, so a world without it is one whose correction is exact).
    pub fn has_atmosphere(&self) -> (bool, bool) {
        (self.ionosphere.is_some(), self.troposphere.is_some())
    }

    /// Error terms of satellite `i` seen from geodetic `(lat, lon)` rad and `height_m` at
    /// azimuth/elevation `az_el_rad` on carrier `f_hz`, at `utc_s_of_day`.
    pub fn range_errors(
        &self,
        i: usize,
        lat_lon_rad: (f64, f64),
        height_m: f64,
        az_el_rad: (f64, f64),
        utc_s_of_day: f64,
        f_hz: f64,
    ) -> RangeErrors {
        RangeErrors {
            ionosphere_m: self.ionosphere.as_ref().map_or(0.0, |m| {
                m.delay_m(i, lat_lon_rad, az_el_rad, utc_s_of_day, f_hz)
            }),
            troposphere_m: self
                .troposphere
                .as_ref()
                .map_or(0.0, |m| m.delay_m(lat_lon_rad.0, height_m, az_el_rad.1)),
            multipath_m: self
                .multipath
                .as_ref()
                .map_or(0.0, |m| m.error_m(i, az_el_rad.1)),
            satellite_clock_m: self.signal_in_space.clock_error_m(i),
        }
    }

    /// Broadcast orbit error of satellite `i` (ECEF, m) at its true state.
    pub fn orbit_error_e_m(
        &self,
        i: usize,
        r_s: &Vector3<f64>,
        v_s: &Vector3<f64>,
    ) -> Vector3<f64> {
        self.signal_in_space.orbit_error_e_m(i, r_s, v_s)
    }

    /// Code tracking noise σ at `cn0_dbhz`, m (`None` when the effect is off).
    pub fn code_noise_sigma_m(&self, cn0_dbhz: f64) -> Option<f64> {
        on(self.spec.code_noise, |s| s.enabled).map(|s| s.sigma_m(cn0_dbhz))
    }
}
