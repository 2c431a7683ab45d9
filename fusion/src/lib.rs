//! Sextant's navigation math: pure functions and plain state, no I/O, no clocks, no threads.
//!
//! Every algorithm here runs identically in the live fusion daemon, in offline replay and in
//! Monte Carlo experiments. Module map (papers in `shared/SEEDS.md`):
//! - [`earth`]: ellipsoids, geodetic ↔ ECEF, gravity (normal and J2, paper 002), rates, radii.
//! - [`atmosphere`]: ISA pressure ↔ altitude for the barometer.
//! - [`attitude`]: rotation helpers (Euler angles, rotation vectors, skew matrices).
//! - [`frames`]: frame-typed rotations (ICRF, ECEF, NED, body, star sensor) where chains meet.
//! - [`time`]: time scales (GPS, TAI, UTC, TT, UT1).
//! - [`celestial`]: GCRS/ICRF → ITRS (IAU 2006/2000A precession-nutation, ERA, polar motion).
//! - [`strapdown`]: ECEF strapdown mechanization with selectable integrators (paper 002).
//! - [`ekf`]: the error-state Kalman filter and its measurement models.
//! - [`alignment`]: static coarse alignment (levelling and gyrocompassing, paper 003).
//! - [`baseline_attitude`]: dual-baseline GNSS attitude from carrier phase (paper 003 eq. 14–21).
//! - [`phase_ambiguity`]: integer ambiguities of the baseline carrier phases (constrained search,
//!   ratio and χ² tests, hold across epochs, slip and wrong-fix detection).
//! - [`gnss_ls`]: receiver-style least-squares GNSS fix with DOPs (paper 003 eq. 12–13).
//! - [`broadcast_ephemeris`]: GPS broadcast orbits and clocks (IS-GPS-200).
//! - [`gnss_corrections`]: Klobuchar ionosphere, Saastamoinen troposphere, iono-free code.
//! - [`point_positioning`]: single-epoch GPS fix from raw code and broadcast ephemerides.
//! - [`navigator`]: the fusion engine the daemons drive: alignment, mechanization, filter,
//!   measurement buffering, modes and health.

pub mod alignment;
pub mod astro_fix;
pub mod atmosphere;
pub mod attitude;
pub mod baseline_attitude;
pub mod boresight;
pub mod broadcast_ephemeris;
pub mod celestial;
pub mod earth;
pub mod ekf;
pub mod frames;
pub mod gnss_corrections;
pub mod gnss_ls;
pub mod navigator;
pub mod phase_ambiguity;
pub mod point_positioning;
pub mod redundancy;
pub mod strapdown;
pub mod time;
pub mod yaw_gsf;

#[cfg(test)]
mod test_sky;

pub use navigator::{RejectReason, Rejection};

/// A configuration value makes no sense; the message names the key (`filter.<key> <what>` for
/// the filter tuning file).
#[derive(Debug, thiserror::Error, Clone, PartialEq, Eq)]
#[error("invalid configuration: {0}")]
pub struct ConfigError(pub String);

/// Errors of the navigation library's batch estimators and constructors (the navigator's
/// per-sample refusals are the `Copy` [`Rejection`], its configuration errors [`ConfigError`]).
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum FusionError {
    /// Input data of a batch estimator that cannot be used (not static, not physical).
    #[error("invalid {sensor} sample at t = {time_ns} ns: {reason}")]
    InvalidSample {
        /// Which sensor.
        sensor: &'static str,
        /// Time of validity of the sample, GPS ns.
        time_ns: i64,
        /// What was wrong.
        reason: String,
    },
    /// A sample refused by the navigator.
    #[error(transparent)]
    Rejected(#[from] Rejection),
    /// A configuration value makes no sense.
    #[error(transparent)]
    Config(#[from] ConfigError),
}
