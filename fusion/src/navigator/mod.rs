//! The fusion engine that the daemons drive: static coarse alignment, strapdown mechanization,
//! the error-state Kalman filter, buffering of aiding samples until the inertial solution reaches
//! their time of validity, navigation modes and per-sensor health.
//!
//! # Life cycle
//! `Initializing` (no IMU yet) → `Aligning`: IMU increments are averaged for
//! [`NavigatorConfig::alignment_s`] (paper 003 static alignment, [`crate::alignment`]) while
//! GNSS gives the position (or [`NavigatorConfig::initial_position`]) → navigating: strapdown
//! ([`crate::strapdown`]) plus the 28-state error-state EKF ([`crate::ekf`]), mode from the
//! aiding actually fused within its deadline. While GNSS shows the vehicle moving, the
//! alignment in motion (`motion_align`) starts navigation at once instead, from one
//! star-tracker attitude and the GNSS position and velocity, resuming the sensor-error
//! estimates of a snapshot after a restart or a re-initialisation (`warm_start`); without a
//! star attitude, from the heading a bank of yaw hypotheses finds in the GNSS velocities
//! once the vehicle has turned or changed speed (`gsf_align`, [`crate::yaw_gsf`]).
//!
//! # GNSS least squares (paper 003 eq. 12–13, [`crate::gnss_ls`])
//! With ≥ 4 pseudoranges (loose or tight mode) the receiver-style fix is computed from the raw
//! observations: during alignment the latest one is the initial position with its covariance,
//! and in tight mode also the initial clock bias/drift with the fix's position↔clock
//! covariance (`initialize_from_ls`); without raw observations the receiver's fix is used.
//! While navigating, every such epoch is cross-checked against the filter's prediction before
//! its updates (`gnss_ls_cross_check`: 3-dof NIS, counted in [`NavigatorDiagnostics`]). With
//! fewer satellites the tight clock states start by state augmentation from one satellite
//! (`initialize_clock`).
//!
//! # Modes
//! The mode reports the aiding fused within its deadline ([`Deadlines`]): GNSS and stars →
//! GNSS-astro-inertial; GNSS lost → **astro-inertial**; stars lost → GNSS-inertial; both lost
//! → dead reckoning (odometer/baro/ZUPT) or free inertial, with the covariance growing by the
//! process noise only. Astro-inertial bounds the horizontal position (paper 000's astro fix,
//! done inside the filter): the star attitude residual is taken in ECEF
//! (`C_s_i = C_s_b·C_b_e·C_e_i(t)`, [`crate::ekf::star_attitude`]), so the stars fix ψ
//! independently of position, while the accelerometers sense gravity along the *true*
//! vertical. A horizontal position error δr tilts the vertical the filter assumes by δr/R;
//! with ψ pinned by the stars that appears as a horizontal specific-force error `g·δr/R` in
//! the velocity error equation (the `[f̂_e×]ψ` and gravity-gradient terms of
//! [`crate::ekf`]), i.e. the Schuler loop now has a measurement closing it, and the
//! position error settles at what the accelerometers cannot distinguish from a tilted
//! vertical: `δr ≈ R·b_a/g` (50 µg → 320 m per axis). Free inertial has no such feedback
//! and drifts with the gyro errors. Test: `drivers-sim/tests/filter_modes.rs` (2 h without
//! GNSS: astro-inertial error ≤ 600 m with σ at that floor, free inertial 1.4 km and
//! growing).
//!
//! # Solutions
//! Every navigating IMU step has a solution (`msgs::NavSolution`: geodetic position, NED
//! velocity and attitude, σ, estimates), formed only when asked ([`Navigator::solution`], until
//! the next input): [`Navigator::push`] forms it for every IMU sample, as the daemon publishes
//! them; [`Navigator::push_deferred`] leaves it to the caller (offline replay forms only the
//! solutions its recordings keep). Forming one changes nothing in the navigator.
//!
//! A solution needs the state at its epoch, not what the step does for later epochs: the
//! periodic checkpoint, and at an epoch where nothing is fused the covariance propagation and
//! the checkpoint before the (absent) updates, are done once the solution is formed — by
//! [`Navigator::catch_up`], which the daemon calls after publishing, or at the start of the
//! next input — with the same state, so the filter evolves bit for bit as if the step had
//! done them. The solution of such an epoch therefore reports σ (and the receiver clock
//! estimate) as of the propagation before it, as every solution between two propagations does.
//!
//! # Delayed fusion (at the time of validity, exactly)
//! Aiding samples are queued in fixed-capacity, time-ordered ring buffers (no allocation) and
//! fused when the IMU time reaches their time of validity: at the first IMU epoch ≥ that time
//! (the simulator puts every sample on the IMU grid; otherwise the approximation is at most one
//! IMU interval, ≤ 5 ms at 200 Hz).
//!
//! A sample that arrives after the inertial solution has passed its time (but within
//! [`NavigatorConfig::buffer_window_s`]) is fused by **re-propagation from buffered IMU
//! data**: every 20 ms of IMU time the replayable filter state (inertial state, error-state
//! filter with its covariance and pending transition, strapdown history, ZUPT/baro
//! schedulers) is checkpointed (once the step's solution is formed, "Solutions" above), and
//! also before the updates of an epoch where aiding is due
//! or the covariance has just been propagated (at least 10 ms after the last checkpoint): a
//! sample of that epoch arriving later rewinds no further than its own epoch; the validated
//! IMU increments and every fused aiding sample are kept for the window. A late sample is held out of the next IMU step (its solution is
//! formed without it, so that the work below is not between that sample's arrival and its
//! solution); once that solution is formed, the navigator — at the start of the next input,
//! or earlier when told ([`Navigator::catch_up`], which the daemon calls once it has
//! published) — restores the latest checkpoint before the late sample's time (or before the
//! updates of its own epoch), re-queues the aiding fused since then and replays the logged IMU
//! steps, fusing everything — the late
//! sample included — at the epoch, with the state *and covariance* that an in-time arrival
//! would have met. So a late sample reaches the solutions one IMU interval after the one it
//! arrived with; when the rewind runs changes nothing (test
//! `catching_up_early_changes_no_solution`). The result is the
//! in-time result up to floating-point rounding (test
//! `late_gnss_sample_gives_the_in_time_update`), unlike the usual shortcut of applying a
//! correction computed with the current covariance (which ignores the cross-covariance
//! between the delayed and the current error). Cost: one replay of up to window + 20 ms of
//! IMU steps (≈ 2 µs each) per IMU interval with late samples. Samples older than the window are
//! counted in `dropped_late` and never fused. The IMU log is sized from the configuration
//! ([`NavigatorConfig::imu_log_capacity`]: `max_imu_rate_hz × (window + 0.2 s)` steps); should
//! a faster IMU leave it too short for a replay, the late samples are dropped (`dropped_late`)
//! and the event counted (`replays_impossible`), never fused at a later epoch. The first checkpoint is the start of navigation,
//! so a sample late in the first 20 ms is replayed from there too; a sample whose time of
//! validity is at or before the start belongs to the alignment period and is discarded
//! whenever it arrives, as alignment discards it in time. So the solution at an epoch depends
//! only on which samples had arrived by the IMU sample before it (and on the in-time ones),
//! not on the order (test `arrival_order_changes_only_the_epochs_with_a_sample_pending`). Health counters count every
//! sample once (re-fused samples do not count again).
//!
//! # Input validation
//! Every sample is checked (NaN/inf, impossible magnitudes, time not increasing, duplicated
//! sequence number); a bad one is counted in `rejected_invalid`, returned as an error and never
//! touches the filter. Nothing here panics on input, allocates per sample, reads a clock or
//! does I/O.
//!
//! # Modules
//! - `config`: the configuration types (`config/filter.toml`) and their validation.
//! - `gate`: the content checks of each sample, refusing with a `Copy` [`Rejection`].
//! - `input`: header checks, health bookkeeping and queueing of each accepted sample.
//! - `imu_time`: IMU time continuity (bridged gaps, confirmed discontinuities).
//! - `channels`: redundant IMU channels with fault detection (paper 004).
//! - `align`: static coarse alignment.
//! - `motion_align`: alignment in motion from the star tracker and GNSS, and the start of
//!   navigation.
//! - `gsf_align`: alignment in motion without stars, the heading from GNSS velocity
//!   ([`crate::yaw_gsf`]).
//! - `warm_start`: the snapshot of the estimate for a warm restart, and the resumption from it.
//! - `calibration_memory`: a previous run's sensor errors as the prior of the next start.
//! - `core`: the replayable state as one `Clone` value; a checkpoint is `(time, Core)`.
//! - `cadence`: where each aiding sensor's next sample is expected (the covariance is
//!   propagated at that epoch, so that a late sample's rewind finds it there).
//! - `buffer`, `obs`: the delayed-fusion queues and logs, and the observations they hold.
//! - `replay`: the navigating IMU step, checkpoints and the replay of late samples.
//! - `update`: one gated measurement update and the counters folded from it.
//! - `gnss`, `star`, `odometer`, `baro`, `zupt`: the aiding updates per sensor.
//! - `output`: navigation mode and the `msgs::NavSolution`.
//! - `health`: update outcomes folded into the counters, with an explicit tally (a sample
//!   counts the first time it is fused, not again in a replay).

use crate::ConfigError;
use crate::alignment::{self, Accumulator};
use crate::attitude::{quat_from_wire, quat_to_wire, rpy_from_q_n_b};
use crate::celestial::EarthOrientation;
use crate::earth::{self, Ellipsoid, Geodetic, GravityModel, PZ90, WGS84};
use crate::ekf::{
    self, ActiveStates, Covariance, ErrorStateEkf, GateTable, Measurement, ProcessNoise,
    StateVector, idx,
};
use crate::strapdown::{ImuIncrement, Integrator, MechanizationConfig, NavState, Strapdown, q_e_n};
use crate::time::{Duration, GpsTime};
use msgs::{
    BaroSample, GnssSample, Header, ImuSample, MAX_IMU_CHANNELS, MAX_SATELLITES, MAX_SENSORS,
    NavMode, NavSolution, OdometerSample, Record, SensorHealth, SensorId, StarTrackerSample,
};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};

mod align;
mod alignment_carry;
mod baro;
mod buffer;
mod cadence;
mod calibration_memory;
mod channels;
mod config;
mod core;
mod gate;
mod gnss;
mod gsf_align;
mod health;
mod imu_time;
mod input;
mod motion_align;
mod obs;
mod odometer;
mod output;
mod replay;
mod star;
mod static_position;
mod update;
mod warm_start;
mod zupt;

use self::core::*;
use alignment_carry::*;
use buffer::*;
use cadence::Cadence;
use calibration_memory::CalibrationPrior;
pub use calibration_memory::{
    CalibrationLoaded, CalibrationMemoryConfig, CalibrationRefusal, REMEMBERED,
};
pub use config::*;
use gate::*;
pub use gate::{RejectReason, Rejection};
use gsf_align::*;
use health::*;
pub use health::{ConstraintHealth, NavigatorDiagnostics, NhcHealth, ZuptHealth};
pub use imu_time::CONFIRM_SAMPLES;
use imu_time::*;
pub use motion_align::MotionAlignment;
use motion_align::*;
use obs::*;
use odometer::*;
pub use output::ClockEstimate;
use star::*;
use static_position::StaticPosition;
pub use warm_start::{NavSnapshot, WarmStartConfig, WarmStartOutcome, WarmStartRefusal};

const DEG: f64 = std::f64::consts::PI / 180.0;

/// Standard gravity, m/s² (unit conversions only).
const G0: f64 = 9.806_65;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Initializing,
    Aligning,
    Navigating,
}

/// One input of the navigator ([`Navigator::push`]): a sensor sample (borrowed, time of
/// validity in its header, GPS ns) or the daemon's verdict that a sensor is, or no longer is,
/// delivering within its deadline.
#[derive(Debug, Clone, Copy)]
pub enum Input<'a> {
    /// IMU increments (body frame).
    Imu(&'a ImuSample),
    /// Star-tracker attitude (sensor frame w.r.t. ICRF).
    StarTracker(&'a StarTrackerSample),
    /// GNSS fix, raw satellites and baseline phases (ECEF).
    Gnss(&'a GnssSample),
    /// Odometer speed and distance over its interval.
    Odometer(&'a OdometerSample),
    /// Barometric pressure.
    Baro(&'a BaroSample),
    /// Whether sensor `sensor` (index = `msgs::SensorId`; out-of-range indices are ignored)
    /// delivers within its deadline.
    SensorAlive {
        /// Sensor slot (`msgs::SensorId as usize`).
        sensor: usize,
        /// True when it delivers again, false when its deadline was missed.
        alive: bool,
    },
}

impl<'a> Input<'a> {
    /// The navigator input a recorded message is: sensor samples and alive/dead transitions
    /// (`msgs::SensorAliveEvent`); None for truth and the navigator's own outputs, which are
    /// never inputs. The daemon, offline runs, the bench and replay all convert with this and
    /// push the result ([`Navigator::push`]).
    pub fn from_record(record: &'a Record) -> Option<Self> {
        Some(match record {
            Record::Imu(s) => Self::Imu(s),
            Record::StarTracker(s) => Self::StarTracker(s),
            Record::Gnss(s) => Self::Gnss(s),
            Record::Odometer(s) => Self::Odometer(s),
            Record::Baro(s) => Self::Baro(s),
            Record::SensorAlive(e) => Self::SensorAlive {
                sensor: e.sensor as usize,
                alive: e.alive,
            },
            Record::Truth(_) | Record::Nav(_) | Record::Status(_) => return None,
        })
    }
}

/// The fusion engine.
#[derive(Debug, Clone)]
pub struct Navigator {
    config: NavigatorConfig,
    ell: Ellipsoid,
    gates: GateTable,
    c_s_b: Matrix3<f64>,
    phase: Phase,
    align: Accumulator,
    /// The static alignment's GNSS position: the window's fixes by time of validity.
    static_position: StaticPosition,
    /// The replayable navigation state (a checkpoint is its copy with the time).
    core: Core,
    /// Time of the last IMU sample processed (the epoch of the solution).
    time: GpsTime,
    last_seq: [Option<u64>; MAX_SENSORS],
    /// Time of validity of each sensor's last accepted sample.
    last_time: [Option<GpsTime>; MAX_SENSORS],
    health: [SensorHealth; MAX_SENSORS],
    /// Time of validity of each sensor's latest fused sample (the mode's deadlines).
    last_fused: [Option<GpsTime>; MAX_SENSORS],
    /// Boxed like `gnss_done`: each holds 100 kB of observations (a full sky of pseudoranges
    /// per epoch) that the navigator, held on the stack by its callers, should not carry
    /// inline.
    gnss_q: Box<TimeQueue<GnssObs, GNSS_CAP>>,
    celestial: CelestialCache,
    star_q: TimeQueue<StarObs, STAR_CAP>,
    odo_q: TimeQueue<f64, ODO_CAP>,
    baro_q: TimeQueue<f64, BARO_CAP>,
    imu_log: Ring<ImuLogEntry>,
    checkpoints: Ring<Checkpoint>,
    /// What is left of the last IMU step until its solution is formed (propagation,
    /// checkpoints: [`Navigator::catch_up`]).
    deferred_step: Option<DeferredStep>,
    gnss_done: Box<TimeQueue<GnssObs, GNSS_CAP>>,
    star_done: TimeQueue<StarObs, STAR_CAP>,
    odo_done: TimeQueue<f64, ODO_CAP>,
    baro_done: TimeQueue<f64, BARO_CAP>,
    /// Earliest time of validity of a late sample queued and not yet fused by a rewind.
    rewind_to: Option<GpsTime>,
    /// Late samples (the IMU had passed their time of validity when they arrived), held out
    /// of the next IMU step until its solution is formed (module docs, "Delayed fusion").
    gnss_inbox: Box<TimeQueue<GnssObs, INBOX_CAP>>,
    star_inbox: TimeQueue<StarObs, INBOX_CAP>,
    odo_inbox: TimeQueue<f64, INBOX_CAP>,
    baro_inbox: TimeQueue<f64, INBOX_CAP>,
    /// Time of validity at which navigation started (the end of alignment; None before):
    /// aiding up to it belongs to the alignment period, whenever it arrives (`fuse_due`).
    nav_start: Option<GpsTime>,
    zupt: ZuptHealth,
    /// Epoch of the latest zero-velocity update counted in `zupt`: a replay re-fuses updates
    /// up to it (not counted again) and may fuse some at epochs the live run did not have,
    /// which are counted once when they lie beyond it.
    zupt_counted_until: Option<GpsTime>,
    /// IMU epochs with a solution (its `seq`), formed or not.
    solutions: u64,
    /// Whether the state is still that of the last IMU step's solution: set by a navigating
    /// IMU step, cleared by the next input or rewind ([`Navigator::solution`]).
    solution_ready: bool,
    /// Send time of the IMU sample of that step (`NavSolution::imu_send_mono_ns`), ns.
    solution_imu_send_mono_ns: u64,
    mode: NavMode,
    aiding_mask: u32,
    /// Redundant-channel combination and FDI (paper 004), built from the first sample with
    /// channels.
    redundancy: Option<crate::redundancy::RedundantImu>,
    /// FDI settings (None: derived from `config.imu` and the sample interval).
    redundancy_config: Option<crate::redundancy::FdiConfig>,
    /// Cross-check and re-initialisation counters.
    diagnostics: NavigatorDiagnostics,
    /// The baseline phases' integers held per satellite ([`crate::phase_ambiguity`]), built
    /// from the first sample with baselines. Not part of [`Core`]: samples arrive in time
    /// order and are resolved once, on arrival; the queued observation keeps the resolved
    /// attitude, so a replay re-fuses exactly what was resolved and this state never rewinds.
    ambiguity: Option<crate::phase_ambiguity::AmbiguityResolver>,
    /// An IMU time discontinuity waiting for confirmation (see [`Navigator::check_imu_time`]).
    imu_time_jump: Option<ImuTimeJump>,
    /// Non-holonomic constraint counters.
    nhc: NhcHealth,
    /// The latest least-squares GNSS fix of the alignment period and its time of validity
    /// (the next fix's first guess; the tight-mode clock of a start in motion,
    /// `initialize_from_ls`).
    init_ls: Option<(GpsTime, crate::gnss_ls::GnssFix)>,
    /// While aligning: the latest star-tracker attitude, carried by the gyros
    /// (`motion_align`).
    star_attitude: Option<StarAttitude>,
    /// While aligning: the GNSS-velocity yaw estimator, for a start in motion without a star
    /// attitude (`gsf_align`).
    gsf: GsfAlignment,
    /// A snapshot to resume the sensor-error states from (`warm_start`).
    warm: Option<NavSnapshot>,
    /// What became of the snapshot given to [`Navigator::warm_start`].
    warm_outcome: Option<WarmStartOutcome>,
    /// The sensor errors of a previous run, the prior of every start
    /// (`calibration_memory`). Boxed: 8 kB that the navigator, itself held on the stack by
    /// its callers, should not carry inline.
    calibration: Option<Box<CalibrationPrior>>,
}

/// Slot of a sensor in the health array.
const fn sid(s: SensorId) -> usize {
    s as usize
}

impl Navigator {
    /// A navigator waiting for its first IMU sample.
    pub fn new(config: NavigatorConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        let ell = config.ellipsoid.ellipsoid();
        let core = Core::new(&config, &ell);
        Ok(Self {
            gates: GateTable::new(config.gate_probability),
            // Nominal star-tracker mount (docs/ARCHITECTURE.md): 180° about body x.
            c_s_b: Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0),
            phase: Phase::Initializing,
            align: Accumulator::default(),
            static_position: StaticPosition::default(),
            time: GpsTime::EPOCH,
            last_seq: [None; MAX_SENSORS],
            last_time: [None; MAX_SENSORS],
            health: [SensorHealth::default(); MAX_SENSORS],
            last_fused: [None; MAX_SENSORS],
            gnss_q: Box::new(TimeQueue::new()),
            celestial: CelestialCache::default(),
            star_q: TimeQueue::new(),
            odo_q: TimeQueue::new(),
            baro_q: TimeQueue::new(),
            imu_log: Ring::new(config.imu_log_capacity(), ImuLogEntry::default()),
            checkpoints: Ring::new(
                config.checkpoint_capacity(),
                Checkpoint {
                    t: GpsTime::EPOCH,
                    serves_after: GpsTime::EPOCH,
                    core,
                },
            ),
            deferred_step: None,
            gnss_done: Box::new(TimeQueue::new()),
            star_done: TimeQueue::new(),
            odo_done: TimeQueue::new(),
            baro_done: TimeQueue::new(),
            rewind_to: None,
            gnss_inbox: Box::new(TimeQueue::new()),
            star_inbox: TimeQueue::new(),
            odo_inbox: TimeQueue::new(),
            baro_inbox: TimeQueue::new(),
            nav_start: None,
            core,
            zupt: ZuptHealth::default(),
            zupt_counted_until: None,
            solutions: 0,
            solution_ready: false,
            solution_imu_send_mono_ns: 0,
            mode: NavMode::Initializing,
            aiding_mask: 0,
            redundancy: None,
            redundancy_config: None,
            diagnostics: NavigatorDiagnostics::default(),
            ambiguity: None,
            imu_time_jump: None,
            nhc: NhcHealth::default(),
            init_ls: None,
            star_attitude: None,
            gsf: GsfAlignment::default(),
            warm: None,
            warm_outcome: None,
            calibration: None,
            ell,
            config,
        })
    }

    /// Feed one input: the single entry point by which the daemon, offline runs and replay
    /// drive the navigator. An IMU sample returns the solution at its time once navigating;
    /// aiding samples are queued for fusion at their time of validity and return None, as does
    /// a sensor alive/dead report. Allocates nothing.
    pub fn push(&mut self, input: Input<'_>) -> Result<Option<NavSolution>, Rejection> {
        Ok(if self.push_deferred(input)? {
            self.solution()
        } else {
            None
        })
    }

    /// [`Self::push`] without forming the solution: true when an IMU sample produced one,
    /// which [`Self::solution`] forms until the next input. For a caller that keeps only some
    /// solutions (`replay --offline` keeps those its recording holds): forming one — the
    /// geodetic position, NED velocity, attitude angles and σ of the output message — costs
    /// about a sixth of an IMU step with every aiding. The state is the same either way.
    pub fn push_deferred(&mut self, input: Input<'_>) -> Result<bool, Rejection> {
        match input {
            Input::Imu(s) => self.push_imu_deferred(s),
            Input::StarTracker(s) => self.push_star_tracker(s).map(|()| false),
            Input::Gnss(s) => self.push_gnss(s).map(|()| false),
            Input::Odometer(s) => self.push_odometer(s).map(|()| false),
            Input::Baro(s) => self.push_baro(s).map(|()| false),
            Input::SensorAlive { sensor, alive } => {
                self.set_sensor_alive(sensor, alive);
                Ok(false)
            }
        }
    }

    /// Tell the navigator whether a sensor (index = `msgs::SensorId`) is delivering within its
    /// deadline (decided by the daemon, which owns the clock).
    pub fn set_sensor_alive(&mut self, sensor: usize, alive: bool) {
        self.catch_up();
        if let Some(h) = self.health.get_mut(sensor) {
            if h.alive != 0 && !alive {
                h.deadline_misses = h.deadline_misses.saturating_add(1);
            }
            h.alive = u32::from(alive);
        }
    }

    /// Per-sensor health counters, indexed by `msgs::SensorId`.
    pub fn health(&self) -> [SensorHealth; MAX_SENSORS] {
        self.health
    }

    /// Current mode (`msgs::NavMode` as u32).
    pub fn mode(&self) -> u32 {
        self.mode as u32
    }

    /// Cross-check and re-initialisation counters.
    pub fn diagnostics(&self) -> NavigatorDiagnostics {
        self.diagnostics
    }

    /// Zero-velocity update counters.
    pub fn zupt_health(&self) -> ZuptHealth {
        self.zupt
    }

    /// Time of validity of the latest zero-velocity update counted in [`Self::zupt_health`]
    /// (it may precede [`Self::time`]: an update first fused in a replay).
    pub fn last_zupt_counted(&self) -> Option<GpsTime> {
        self.zupt_counted_until
    }

    /// Counters of the non-holonomic constraint updates.
    pub fn nhc_health(&self) -> NhcHealth {
        self.nhc
    }

    /// The configuration in use.
    pub fn config(&self) -> &NavigatorConfig {
        &self.config
    }

    /// Current inertial state (ECEF), valid once navigating.
    pub fn nav_state(&self) -> &NavState {
        &self.core.nav
    }

    /// Current error-state covariance (layout in [`crate::ekf`]).
    pub fn covariance(&self) -> &Covariance {
        &self.core.ekf.p
    }

    /// Estimated gyro bias (body, rad/s) and accelerometer bias (body, m/s²).
    pub fn biases(&self) -> (Vector3<f64>, Vector3<f64>) {
        (self.core.ekf.gyro_bias_rad_s, self.core.ekf.accel_bias_m_s2)
    }

    /// Estimated baro height bias (`h_baro = h + b`), m.
    pub fn baro_bias_m(&self) -> f64 {
        self.core.ekf.baro_bias_m
    }

    /// Estimated star-tracker boresight angles κ1..κ3 (paper 000) and their 1-σ relative to
    /// the true body frame, rad: `σ² = P_κκ + σ_mis²`, the filter's own variance (κ relative
    /// to the frame the IMU axes realise) plus the IMU axis misalignment
    /// (`imu.misalignment_arcsec`), which no estimator that uses the IMU as its body
    /// reference can remove. 0 when the boresight group is off.
    pub fn boresight_rad(&self) -> (Vector3<f64>, Vector3<f64>) {
        (self.core.ekf.kappa_rad, self.boresight_sigma())
    }

    fn boresight_sigma(&self) -> Vector3<f64> {
        if !self.core.ekf.is_active(idx::KAPPA) {
            return Vector3::zeros();
        }
        let mis = self.config.imu.misalignment_arcsec / 3600.0 * DEG;
        Vector3::from_fn(|i, _| {
            (self.core.ekf.p[(idx::KAPPA + i, idx::KAPPA + i)].max(0.0) + mis * mis).sqrt()
        })
    }

    /// Receiver clock: bias × c (m), drift × c (m/s) and their 1-σ; zeros before tight
    /// coupling has initialised the clock states.
    pub fn clock(&self) -> ClockEstimate {
        let p = &self.core.ekf.p;
        ClockEstimate {
            bias_m: self.core.ekf.clock_bias_m,
            drift_m_s: self.core.ekf.clock_drift_m_s,
            bias_sigma_m: p[(idx::CLK, idx::CLK)].max(0.0).sqrt(),
            drift_sigma_m_s: p[(idx::CLK_DRIFT, idx::CLK_DRIFT)].max(0.0).sqrt(),
        }
    }

    /// Estimated gyro and accelerometer scale-factor errors per body axis (dimensionless).
    pub fn scale_factors(&self) -> (Vector3<f64>, Vector3<f64>) {
        (self.core.ekf.gyro_scale, self.core.ekf.accel_scale)
    }

    /// 1-σ of every error state (layout in [`crate::ekf`]); zero for inactive groups.
    pub fn state_sigma(&self) -> StateVector {
        StateVector::from_fn(|i, _| self.core.ekf.p[(i, i)].max(0.0).sqrt())
    }

    /// The error-state filter (covariance as of its last propagation, estimates).
    pub fn filter(&self) -> &ErrorStateEkf {
        &self.core.ekf
    }

    /// True once alignment is complete and the filter runs.
    pub fn is_navigating(&self) -> bool {
        self.phase == Phase::Navigating
    }

    /// Time of the last IMU sample processed (the GPS epoch before the first).
    pub fn time(&self) -> GpsTime {
        self.time
    }
}

#[cfg(test)]
mod tests;
