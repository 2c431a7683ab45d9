//! Input gating: why a sample is refused before it can touch the filter.
//!
//! A [`Rejection`] names the sensor, the sample's time of validity and a [`RejectReason`]; all
//! three are `Copy`, so refusing a sample on the real-time path allocates nothing (the text is
//! only built when the caller formats the error, e.g. to log it).

use super::obs::GnssFix;
use crate::ekf;
use crate::time::GpsTime;
use msgs::{GnssSample, MAX_SATELLITES, SensorId};
use nalgebra::{Matrix3, Vector3};

/// Why the navigator refused a sample. Each reason names the offending quantity and the range
/// the navigator accepts (units as in `msgs`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum RejectReason {
    /// The time of validity is before the GPS epoch.
    #[error("negative time of validity")]
    NegativeTime,
    /// The time of validity did not advance over the sensor's previous sample.
    #[error("not after the previous one ({} ns)", previous.ns)]
    TimeNotIncreasing {
        /// Time of validity of the sensor's previous sample.
        previous: GpsTime,
    },
    /// The sequence number repeats the previous sample's.
    #[error("duplicated sequence number")]
    DuplicatedSequence,
    /// An aiding time of validity more than an hour ahead of the last IMU sample.
    #[error("time of validity more than an hour ahead of the last IMU sample")]
    FarAheadOfImu,
    /// An IMU time of validity more than 1 s ahead: held as a candidate new time base.
    #[error(
        "time of validity more than 1 s ahead of the last IMU sample (held: 20 consistent \
         samples on the new time base re-initialise the navigator)"
    )]
    ImuTimeJumpHeld,
    /// IMU interval `dt_s` outside [1e-5, 1] s.
    #[error("interval dt_s must be in [1e-5, 1] s")]
    ImuInterval,
    /// A non-finite IMU increment.
    #[error("non-finite increment")]
    NonFiniteIncrement,
    /// |Δθ|/dt above `imu.max_rate_rad_s`.
    #[error("angular rate above imu.max_rate_rad_s")]
    RateAboveLimit,
    /// |Δv|/dt above `imu.max_specific_force_m_s2`.
    #[error("specific force above imu.max_specific_force_m_s2")]
    SpecificForceAboveLimit,
    /// More redundant channels than `msgs::MAX_IMU_CHANNELS`.
    #[error("n_channels above MAX_IMU_CHANNELS")]
    TooManyChannels,
    /// A non-finite star-tracker quaternion.
    #[error("non-finite quaternion")]
    NonFiniteQuaternion,
    /// A valid star-tracker quaternion whose norm differs from 1 by more than 1e-3.
    #[error("quaternion is not unit norm")]
    QuaternionNotUnit,
    /// Star-tracker σ not finite, ≤ 0 or ≥ 0.1 rad.
    #[error("sigmas must be finite, > 0 and < 0.1 rad")]
    StarSigma,
    /// Odometer interval outside (0, 10] s.
    #[error("interval must be in (0, 10] s")]
    OdometerInterval,
    /// Odometer speed not finite or ≥ 200 m/s.
    #[error("speed must be finite and below 200 m/s")]
    OdometerSpeed,
    /// A non-finite odometer distance.
    #[error("non-finite distance")]
    NonFiniteDistance,
    /// Pressure outside [1000, 120000] Pa.
    #[error("pressure must be in [1000, 120000] Pa")]
    Pressure,
    /// Temperature outside [−120, 100] °C.
    #[error("temperature must be in [-120, 100] °C")]
    Temperature,
    /// The pressure gives no finite ISA altitude.
    #[error("pressure gives no ISA altitude")]
    NoIsaAltitude,
    /// More satellites than `msgs::MAX_SATELLITES`.
    #[error("n_satellites above MAX_SATELLITES")]
    TooManySatellites,
    /// A non-finite GNSS position or velocity.
    #[error("non-finite position or velocity")]
    NonFiniteFix,
    /// The GNSS position is not near the Earth's surface.
    #[error("position is not near the Earth's surface (|r| outside 6300–6480 km)")]
    PositionNotNearEarth,
    /// GNSS speed above 2000 m/s.
    #[error("velocity above 2000 m/s")]
    VelocityAboveLimit,
    /// A non-finite GNSS covariance.
    #[error("non-finite covariance")]
    NonFiniteCovariance,
    /// GNSS position covariance not positive definite or with a variance above 1e8 m².
    #[error("position covariance not positive definite or absurd")]
    PositionCovariance,
    /// GNSS velocity covariance not positive definite or with a variance above 1e4 m²/s².
    #[error("velocity covariance not positive definite or absurd")]
    VelocityCovariance,
}

/// A sample the navigator refused: counted in the sensor's `rejected_invalid`, never fused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rejection {
    /// Which sensor.
    pub sensor: SensorId,
    /// The sample's time of validity (GPS).
    pub time: GpsTime,
    /// What was wrong.
    pub reason: RejectReason,
}

impl Rejection {
    /// A rejection of `sensor`'s sample valid at `time`.
    pub const fn new(sensor: SensorId, time: GpsTime, reason: RejectReason) -> Self {
        Self {
            sensor,
            time,
            reason,
        }
    }
}

impl std::fmt::Display for Rejection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (name, t) = (self.sensor.name(), self.time.ns);
        match self.reason {
            RejectReason::TimeNotIncreasing { previous } => write!(
                f,
                "{name} sample at t = {t} ns is not after the previous one ({} ns)",
                previous.ns
            ),
            r => write!(f, "invalid {name} sample at t = {t} ns: {r}"),
        }
    }
}

impl std::error::Error for Rejection {}

pub(super) fn matrix_from_row_major(a: &[f64; 9]) -> Matrix3<f64> {
    Matrix3::from_row_slice(a)
}

/// Check a GNSS sample; Ok(None) when it carries no valid fix (not an error).
pub(super) fn validate_gnss(s: &GnssSample) -> Result<Option<GnssFix>, Rejection> {
    let bad = |r| Rejection::new(SensorId::Gnss, GpsTime::from_ns(s.header.time_ns), r);
    if s.n_satellites as usize > MAX_SATELLITES {
        return Err(bad(RejectReason::TooManySatellites));
    }
    if s.fix_valid == 0 {
        return Ok(None);
    }
    let p = Vector3::from(s.pos_ecef_m);
    let v = Vector3::from(s.vel_ecef_m_s);
    if !(p.iter().all(|x| x.is_finite()) && v.iter().all(|x| x.is_finite())) {
        return Err(bad(RejectReason::NonFiniteFix));
    }
    let r = p.norm();
    if !(6.30e6..=6.48e6).contains(&r) {
        return Err(bad(RejectReason::PositionNotNearEarth));
    }
    if v.norm() > 2_000.0 {
        return Err(bad(RejectReason::VelocityAboveLimit));
    }
    let pc = matrix_from_row_major(&s.pos_cov_ecef_m2);
    let vc = matrix_from_row_major(&s.vel_cov_ecef_m2_s2);
    if !(pc.iter().all(|x| x.is_finite()) && vc.iter().all(|x| x.is_finite())) {
        return Err(bad(RejectReason::NonFiniteCovariance));
    }
    let pc = ekf::symmetrize(&pc);
    if nalgebra::Cholesky::new(pc).is_none() || pc.diagonal().max() > 1e8 {
        return Err(bad(RejectReason::PositionCovariance));
    }
    let vc = ekf::symmetrize(&vc);
    let vel_valid = if vc.iter().all(|x| *x == 0.0) {
        false
    } else if nalgebra::Cholesky::new(vc).is_none() || vc.diagonal().max() > 1e4 {
        return Err(bad(RejectReason::VelocityCovariance));
    } else {
        true
    };
    Ok(Some(GnssFix {
        pos: p,
        vel: v,
        pos_cov: pc,
        vel_cov: vc,
        vel_valid,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejection_is_small_copy_and_reads_like_before() {
        let r = Rejection::new(
            SensorId::Gnss,
            GpsTime::from_ns(5),
            RejectReason::NonFiniteFix,
        );
        assert!(std::mem::size_of::<Rejection>() <= 32);
        assert_eq!(
            r.to_string(),
            "invalid gnss sample at t = 5 ns: non-finite position or velocity"
        );
        let t = Rejection::new(
            SensorId::Imu,
            GpsTime::from_ns(5),
            RejectReason::TimeNotIncreasing {
                previous: GpsTime { ns: 7 },
            },
        );
        assert_eq!(
            t.to_string(),
            "imu sample at t = 5 ns is not after the previous one (7 ns)"
        );
    }
}
