//! The navigation core: everything an IMU step or a measurement update changes, as one `Clone`
//! value — the inertial state, the error-state filter (bias, scale-factor, misalignment,
//! boresight, clock and baro/odometer estimates with their covariance and pending transition),
//! the strapdown integrator's history, and the schedules of the updates that look back at
//! earlier epochs (ZUPT, baro rate limit, odometer veto). A delayed-fusion checkpoint is the
//! time and a copy of it ([`Checkpoint`]), so a rewind restores all of it in one assignment
//! (module docs of [`super`], "Delayed fusion"). Health counters, the mode and the time
//! references of the inputs are not in it: they describe what arrived, not the solution.

use super::*;

/// The replayable navigation state at the end of one IMU epoch.
#[derive(Debug, Clone, Copy)]
pub(super) struct Core {
    /// Inertial state (ECEF position, velocity, body attitude).
    pub(super) nav: NavState,
    /// Error-state filter: estimates and covariance (layout in [`crate::ekf`]).
    pub(super) ekf: ErrorStateEkf,
    /// Mechanization with its coning/sculling history.
    pub(super) strapdown: Strapdown,
    /// Start of the current static period (ZUPT detector).
    pub(super) static_since: Option<GpsTime>,
    /// The ZUPT detector's block of IMU increments being summed.
    pub(super) static_block: super::zupt::StaticBlock,
    /// Time of the last zero-velocity update.
    pub(super) last_zupt: Option<GpsTime>,
    /// Time of validity of the last fused baro sample (`aiding.baro_min_interval_s`).
    pub(super) last_baro_fused: Option<GpsTime>,
    /// Baro samples rejected by the gate since the last accepted one
    /// (`aiding.baro_reacquire_after`).
    pub(super) baro_rejected_in_row: u32,
    /// Time of validity of the last fused star-tracker sample (the lag of its low-frequency
    /// error, `aiding.star_low_frequency_correlation_time_s`).
    pub(super) last_star_fused: Option<GpsTime>,
    /// Baro height at which its bias was acquired (the first fused sample, or the one after a
    /// re-acquisition), m: the reference of the height-scale error (`aiding.baro_scale_sigma`).
    pub(super) baro_anchor_height_m: Option<f64>,
    /// Time of validity and speed (m/s) of the last odometer sample (ZUPT veto).
    pub(super) last_odo: Option<(GpsTime, f64)>,
    /// The last odometer epoch fused (interval-mean to end-point speed, `fuse_odometer`):
    /// replayable, so that a sample re-fused after a rewind meets the epoch before it, not a
    /// later one.
    pub(super) odo_epoch: Option<OdometerEpoch>,
    /// Whether the receiver clock states have been started (tight coupling).
    pub(super) clock_initialized: bool,
    /// Time of validity of the last GNSS epoch whose position or pseudoranges were fused
    /// (the lag of the time-correlated error model, [`crate::ekf::correlated`]).
    pub(super) last_gnss_ranging: Option<GpsTime>,
    /// Bias-corrected inertial angular rate of the last IMU step, body axes, rad/s (the
    /// velocity lever-arm term of the GNSS antenna).
    pub(super) w_ib_b_rad_s: Vector3<f64>,
    /// Each aiding sensor's cadence (index `SensorId as usize`): where its next sample is
    /// expected, for the propagation at its epoch ([`super::cadence`]).
    pub(super) cadence: [Cadence; SensorId::COUNT],
}

impl Core {
    /// The state before alignment: at the equator on the prime meridian, at rest, identity
    /// attitude, unit covariance (replaced when navigation starts).
    pub(super) fn new(config: &NavigatorConfig, ell: &Ellipsoid) -> Self {
        Self {
            nav: NavState {
                r_e: Vector3::new(ell.a_m, 0.0, 0.0),
                v_e: Vector3::zeros(),
                q_e_b: UnitQuaternion::identity(),
            },
            ekf: ErrorStateEkf::new(
                Covariance::identity(),
                config.imu.process_noise(),
                ActiveStates::ALL,
            ),
            strapdown: Strapdown::new(config.mechanization()),
            static_since: None,
            static_block: Default::default(),
            last_zupt: None,
            last_baro_fused: None,
            baro_rejected_in_row: 0,
            baro_anchor_height_m: None,
            last_star_fused: None,
            last_odo: None,
            odo_epoch: None,
            clock_initialized: false,
            last_gnss_ranging: None,
            cadence: Default::default(),
            w_ib_b_rad_s: Vector3::zeros(),
        }
    }
}

/// A delayed-fusion checkpoint: the [`Core`] at the IMU epoch `t`, either at the end of the
/// epoch or, at an epoch where aiding is due or the covariance was just propagated, before its
/// updates, which a sample of that very epoch can rewind to.
#[derive(Debug, Clone, Copy)]
pub(super) struct Checkpoint {
    /// IMU epoch.
    pub(super) t: GpsTime,
    /// A late sample with a time of validity after this one can rewind here: `t` for the end
    /// of the epoch; before its updates, an earlier time no sample fused at `t` is at or before
    /// (the IMU epoch before `t`: a sample of validity in between is fused at `t`).
    pub(super) serves_after: GpsTime,
    /// The navigation core at that point.
    pub(super) core: Core,
}

impl Checkpoint {
    /// Taken before the updates of epoch `t` (it serves samples of `t` itself): a rewind here
    /// fuses the aiding of epoch `t` again before it replays the logged steps after it.
    pub(super) fn before_updates(&self) -> bool {
        self.serves_after < self.t
    }
}

/// The part of an IMU step left until its solution is formed
/// ([`super::Navigator::catch_up`]): none of it changes the solution of its epoch.
#[derive(Debug, Clone, Copy)]
pub(super) struct DeferredStep {
    /// IMU epoch of the step.
    pub(super) t: GpsTime,
    /// The IMU epoch before it (the checkpoint before its updates serves samples after it).
    pub(super) prev_t: Option<GpsTime>,
    /// Nothing was fused at the epoch and its covariance propagation is due: the propagation
    /// and the checkpoint before the (absent) updates are left too.
    pub(super) propagate: bool,
}
