//! The fusion engine that the daemons drive: static coarse alignment, strapdown mechanization,
//! the error-state Kalman filter, buffering of aiding samples until the inertial solution reaches
//! their time of validity, navigation modes and per-sensor health.
//!
//! OWNER: filter helper. The public signatures below are the contract the fusion daemon and the
//! offline tools build against; bodies are the filter helper's.

use crate::FusionError;
use msgs::{
    BaroSample, GnssSample, ImuSample, NavSolution, OdometerSample, SensorHealth, StarTrackerSample,
    MAX_SENSORS,
};

/// Everything the navigator needs to know, from the `[filter]` (and related) tables of the
/// system config. Deserialized from TOML; `validate` checks its meaning.
#[derive(Debug, Clone, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct NavigatorConfig {
    /// Static coarse-alignment time before navigation starts, s.
    pub alignment_s: f64,
}

impl NavigatorConfig {
    /// Check the meaning of the values (ranges, consistency); the error names the key.
    pub fn validate(&self) -> Result<(), FusionError> {
        if !(self.alignment_s.is_finite() && self.alignment_s >= 0.0) {
            return Err(FusionError::Config("filter.alignment_s must be >= 0".into()));
        }
        Ok(())
    }
}

/// The fusion engine.
pub struct Navigator {
    config: NavigatorConfig,
}

impl Navigator {
    /// A navigator waiting for its first IMU sample.
    pub fn new(config: NavigatorConfig) -> Result<Self, FusionError> {
        config.validate()?;
        Ok(Self { config })
    }
    /// Feed one IMU sample (in time order). Returns the solution at its time once navigating
    /// (None while initializing/aligning). Buffered aiding samples whose time of validity is
    /// reached are fused before the solution is formed. Allocates nothing.
    pub fn push_imu(&mut self, s: &ImuSample) -> Result<Option<NavSolution>, FusionError> {
        let _ = (s, &self.config);
        unimplemented!("filter helper")
    }
    /// Queue a star-tracker sample for fusion at its time of validity.
    pub fn push_star_tracker(&mut self, s: &StarTrackerSample) -> Result<(), FusionError> {
        let _ = s;
        unimplemented!("filter helper")
    }
    /// Queue a GNSS sample.
    pub fn push_gnss(&mut self, s: &GnssSample) -> Result<(), FusionError> {
        let _ = s;
        unimplemented!("filter helper")
    }
    /// Queue an odometer sample.
    pub fn push_odometer(&mut self, s: &OdometerSample) -> Result<(), FusionError> {
        let _ = s;
        unimplemented!("filter helper")
    }
    /// Queue a baro sample.
    pub fn push_baro(&mut self, s: &BaroSample) -> Result<(), FusionError> {
        let _ = s;
        unimplemented!("filter helper")
    }
    /// Tell the navigator whether a sensor (index = `msgs::SensorId`) is delivering within its
    /// deadline (decided by the daemon, which owns the clock).
    pub fn set_sensor_alive(&mut self, sensor: usize, alive: bool) {
        let _ = (sensor, alive);
        unimplemented!("filter helper")
    }
    /// Per-sensor health counters, indexed by `msgs::SensorId`.
    pub fn health(&self) -> [SensorHealth; MAX_SENSORS] {
        unimplemented!("filter helper")
    }
    /// Current mode (`msgs::NavMode` as u32).
    pub fn mode(&self) -> u32 {
        unimplemented!("filter helper")
    }
}
