//! The fusion daemon's filter thread: subscribes to every sensor channel and the truth, blocks on
//! the IMU channel's wake-ups (with a timeout at the next sensor deadline, status or stop check:
//! the loop keeps those clocks itself), pushes samples into the navigator, publishes the
//! solution and the status, and hands every input and output to the [`Recorder`].
//!
//! Why not an iceoryx2 WaitSet over every channel: each of its waits allocates twice (0.10), on
//! the path of every IMU sample, and the aiding's own wake-ups change nothing: the navigator
//! fuses an aiding sample at its time of validity, and the loop takes every channel's samples
//! at each wake-up, aiding first — one that arrives between two IMU samples is taken before the
//! second, as it was when it woke the loop itself. While the IMU is silent, the timeout (at
//! most [`STOP_CHECK`]) drains the other channels.
//!
//! The navigator is reached through the [`NavEngine`] trait, so that the loop can be tested with
//! a stand-in before (and independently of) the real filter.

use crate::checkpoint::CheckpointWriter;
use crate::config::SystemConfig;
use crate::latency::LatencyHistogram;
use crate::recorder::{Recorder, RecorderError, RecorderOptions, RecorderStats};
use crate::staleness::Staleness;
use fusion::Rejection;
use fusion::navigator::{Input, NavSnapshot, Navigator, WarmStartOutcome};
use msgs::ipc::{Bus, NodeError, PublisherError, Sub, SubscriberError, WaitError};
use msgs::{
    BaroSample, Channel, GnssSample, ImuSample, MAX_SENSORS, Message, NavSolution, OdometerSample,
    PerSensor, Record, SensorAliveEvent, SensorHealth, SensorId, StarTrackerSample, Status,
    TruthSample,
};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Longest wait for the IMU's wake-up: how soon a stop request (the signal handler's flag) is
/// seen, and the other channels are drained, while the IMU is silent.
const STOP_CHECK: Duration = Duration::from_millis(100);

/// What the daemon needs from the fusion engine ([`Navigator`] implements it).
pub trait NavEngine {
    /// Feed one input; the solution an IMU sample produced once navigating. By default
    /// dispatched to the per-sensor methods; the [`Navigator`] takes it whole
    /// ([`Navigator::push`], its single entry point).
    fn push(&mut self, input: Input<'_>) -> Result<Option<NavSolution>, Rejection> {
        match input {
            Input::Imu(s) => self.push_imu(s),
            Input::StarTracker(s) => self.push_star_tracker(s).map(|()| None),
            Input::Gnss(s) => self.push_gnss(s).map(|()| None),
            Input::Odometer(s) => self.push_odometer(s).map(|()| None),
            Input::Baro(s) => self.push_baro(s).map(|()| None),
            Input::SensorAlive { sensor, alive } => {
                self.set_sensor_alive(sensor, alive);
                Ok(None)
            }
        }
    }
    /// Feed an IMU sample; the solution once navigating.
    fn push_imu(&mut self, s: &ImuSample) -> Result<Option<NavSolution>, Rejection>;
    /// Queue a star-tracker sample.
    fn push_star_tracker(&mut self, s: &StarTrackerSample) -> Result<(), Rejection>;
    /// Queue a GNSS sample.
    fn push_gnss(&mut self, s: &GnssSample) -> Result<(), Rejection>;
    /// Queue an odometer sample.
    fn push_odometer(&mut self, s: &OdometerSample) -> Result<(), Rejection>;
    /// Queue a baro sample.
    fn push_baro(&mut self, s: &BaroSample) -> Result<(), Rejection>;
    /// Tell whether a sensor delivers within its deadline.
    fn set_sensor_alive(&mut self, sensor: usize, alive: bool);
    /// Fuse the late samples held out of the last solution now, off the next IMU sample's
    /// path ([`Navigator::catch_up`]; the next input would do it first otherwise).
    fn catch_up(&mut self) {}
    /// Per-sensor counters.
    fn health(&self) -> [SensorHealth; MAX_SENSORS];
    /// Navigation mode (`msgs::NavMode` as u32).
    fn mode(&self) -> u32;
    /// Redundant-IMU fault detection state (paper 004), when the engine combines channels.
    fn redundancy(&self) -> Option<fusion::redundancy::RedundancyStatus> {
        None
    }
    /// GNSS cross-check and re-initialisation counters.
    fn diagnostics(&self) -> fusion::navigator::NavigatorDiagnostics {
        fusion::navigator::NavigatorDiagnostics::default()
    }
    /// Counters of the pseudo-measurements (zero velocity, non-holonomic constraint).
    fn constraint_health(&self) -> (fusion::navigator::ZuptHealth, fusion::navigator::NhcHealth) {
        Default::default()
    }
    /// The estimate to write to the checkpoint (None while not navigating, or for an engine
    /// without one).
    fn snapshot(&self) -> Option<NavSnapshot> {
        None
    }
    /// [`NavEngine::snapshot`] written into `out` (false when there is none); an engine that
    /// can fill it in place without allocating overrides this.
    fn snapshot_into(&self, out: &mut NavSnapshot) -> bool {
        match self.snapshot() {
            Some(s) => {
                *out = s;
                true
            }
            None => false,
        }
    }
    /// What became of the checkpoint the engine was started from.
    fn warm_start_outcome(&self) -> Option<WarmStartOutcome> {
        None
    }
}

/// Fill a status from the engine: mode, per-sensor health and the redundant-IMU counters.
/// The daemon's own fields (alive mask, recorder counters) are the caller's.
pub fn engine_status<E: NavEngine>(engine: &E) -> Status {
    let mut st = Status {
        mode: engine.mode(),
        sensors: engine.health(),
        ..Default::default()
    };
    if let Some(r) = engine.redundancy() {
        st.imu_channels_excluded_mask = r.excluded_mask;
        st.imu_channels_suspect_mask = r.suspect_mask;
        st.imu_faults_detected = u64::from(r.faults_detected);
    }
    let d = engine.diagnostics();
    st.gnss_ls_checks = d.gnss_ls_checks;
    st.gnss_ls_disagreements = d.gnss_ls_disagreements;
    st.gnss_ls_last_nis = d.gnss_ls_last_nis;
    st.gnss_ls_pdop = d.gnss_ls_pdop;
    st.reinitializations = d.reinitializations;
    st.motion_alignments = d.motion_alignments;
    st.gnss_heading_alignments = d.gnss_heading_alignments;
    st.warm_starts = d.warm_starts;
    st.imu_held_at_time_jump = d.imu_held_at_time_jump;
    let (zupt, nhc) = engine.constraint_health();
    st.zupt_fused = zupt.fused;
    st.zupt_rejected_gate = zupt.rejected_gate;
    st.nhc_fused = nhc.fused;
    st.nhc_rejected_gate = nhc.rejected_gate;
    st.nhc_nis_sum = nhc.nis_sum;
    st
}

impl NavEngine for Navigator {
    fn push(&mut self, input: Input<'_>) -> Result<Option<NavSolution>, Rejection> {
        Navigator::push(self, input)
    }
    fn push_imu(&mut self, s: &ImuSample) -> Result<Option<NavSolution>, Rejection> {
        Navigator::push_imu(self, s)
    }
    fn push_star_tracker(&mut self, s: &StarTrackerSample) -> Result<(), Rejection> {
        Navigator::push_star_tracker(self, s)
    }
    fn push_gnss(&mut self, s: &GnssSample) -> Result<(), Rejection> {
        Navigator::push_gnss(self, s)
    }
    fn push_odometer(&mut self, s: &OdometerSample) -> Result<(), Rejection> {
        Navigator::push_odometer(self, s)
    }
    fn push_baro(&mut self, s: &BaroSample) -> Result<(), Rejection> {
        Navigator::push_baro(self, s)
    }
    fn set_sensor_alive(&mut self, sensor: usize, alive: bool) {
        Navigator::set_sensor_alive(self, sensor, alive)
    }
    fn catch_up(&mut self) {
        Navigator::catch_up(self)
    }
    fn health(&self) -> [SensorHealth; MAX_SENSORS] {
        Navigator::health(self)
    }
    fn mode(&self) -> u32 {
        Navigator::mode(self)
    }
    fn redundancy(&self) -> Option<fusion::redundancy::RedundancyStatus> {
        Navigator::redundancy_status(self)
    }
    fn diagnostics(&self) -> fusion::navigator::NavigatorDiagnostics {
        Navigator::diagnostics(self)
    }
    fn constraint_health(&self) -> (fusion::navigator::ZuptHealth, fusion::navigator::NhcHealth) {
        (self.zupt_health(), self.nhc_health())
    }
    fn snapshot(&self) -> Option<NavSnapshot> {
        Navigator::snapshot(self)
    }
    fn snapshot_into(&self, out: &mut NavSnapshot) -> bool {
        Navigator::snapshot_into(self, out)
    }
    fn warm_start_outcome(&self) -> Option<WarmStartOutcome> {
        Navigator::warm_start_outcome(self)
    }
}

/// Push one recorded input into the engine: the single code path by which both the live daemon
/// and offline replay drive the engine, so that replaying a recording's inputs in file order
/// reproduces the live solution bit for bit. Sensor samples and alive/dead transitions go to
/// [`NavEngine::push`] as a `fusion::navigator::Input` ([`Input::from_record`]); outputs and
/// truth are not inputs and are ignored. Returns the solution an IMU sample produced.
pub fn feed<E: NavEngine>(
    engine: &mut E,
    record: &Record,
) -> Result<Option<NavSolution>, Rejection> {
    match Input::from_record(record) {
        Some(input) => engine.push(input),
        None => Ok(None),
    }
}

/// [`feed`] to a [`Navigator`] without forming the solution ([`Navigator::push_deferred`]):
/// true when an IMU sample produced one, formed by [`Navigator::solution`] until the next
/// input. The same state as [`feed`]; for offline replay, which forms only the solutions it
/// keeps.
pub fn feed_deferred(engine: &mut Navigator, record: &Record) -> Result<bool, Rejection> {
    match Input::from_record(record) {
        Some(input) => engine.push_deferred(input),
        None => Ok(false),
    }
}

/// Stamp a solution the engine produced the way the daemon publishes it: `seq` = solution
/// count (from 1), `imu_send_mono_ns` = send time of the IMU sample that produced it.
/// (`header.send_mono_ns` is the wall clock of publication and is not reproducible offline.)
pub fn stamp_solution(sol: &mut NavSolution, imu: &ImuSample, solutions: u64) {
    sol.imu_send_mono_ns = imu.header.send_mono_ns;
    sol.header.seq = solutions;
}

/// Errors of the daemon.
#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    /// The daemon could not join the bus.
    #[error(transparent)]
    Bus(#[from] NodeError),
    /// A sensor or truth subscriber could not be created.
    #[error(transparent)]
    Subscriber(#[from] SubscriberError),
    /// The solution or status publisher could not be created.
    #[error(transparent)]
    Publisher(#[from] PublisherError),
    /// Recorder.
    #[error(transparent)]
    Recorder(#[from] RecorderError),
    /// The wait for the IMU channel's wake-ups.
    #[error(transparent)]
    Wait(#[from] WaitError),
    /// A real-time setting the system refused (`[fusion.realtime]`).
    #[error(transparent)]
    Realtime(#[from] crate::realtime::RealtimeError),
}

/// Settings of one daemon run.
#[derive(Debug, Clone)]
pub struct DaemonOptions {
    /// Service-name prefix.
    pub prefix: String,
    /// Recording path.
    pub out: PathBuf,
    /// Speed-up of simulated time over wall time (scales the deadlines).
    pub speed: f64,
    /// The system configuration.
    pub system: SystemConfig,
    /// iceoryx2 node name.
    pub node_name: String,
    /// MCAP metadata written first in the recording (name, key/value map): the configuration
    /// under [`crate::recorder::CONFIG_METADATA_NAME`], so that replay needs no outside file.
    pub metadata: Vec<(String, BTreeMap<String, String>)>,
    /// Checkpoint file for a warm restart, written every `fusion.checkpoint_interval_s` of
    /// filter time (None: no checkpoint).
    pub checkpoint: Option<PathBuf>,
}

/// Totals of a finished run.
#[derive(Debug, Clone)]
pub struct DaemonReport {
    /// IMU samples received.
    pub imu_received: u64,
    /// Solutions computed (all recorded).
    pub solutions: u64,
    /// Solutions published (after decimation).
    pub solutions_published: u64,
    /// Recorder totals.
    pub recorder: RecorderStats,
    /// Files of the recording, in order (more than one when writing failed and resumed).
    pub segments: Vec<PathBuf>,
    /// Solutions flagged stale (published late behind their time of validity).
    pub solutions_stale: u64,
    /// The engine's estimate at the end (None when it was not navigating): the calibration
    /// memory the next run starts from.
    pub final_snapshot: Option<NavSnapshot>,
}

struct State<'a, E: NavEngine> {
    engine: E,
    recorder: Recorder,
    nav_pub: msgs::ipc::Pub<NavSolution>,
    status_pub: msgs::ipc::Pub<Status>,
    decimation: u64,
    /// Delivering within its deadline (as last told to the engine).
    alive: PerSensor<bool>,
    /// Delivered at least once.
    seen: PerSensor<bool>,
    /// Delivered in the current wake-up.
    got: PerSensor<bool>,
    /// Deadlines missed after the first sample.
    misses: PerSensor<u32>,
    imu_received: u64,
    solutions: u64,
    published: u64,
    filter_time_ns: i64,
    errors_logged: u64,
    alive_events: u64,
    stop: &'a AtomicBool,
    checkpoint: Option<CheckpointWriter>,
    checkpoint_interval_ns: i64,
    /// Filter time of the last checkpoint submitted, GPS ns.
    last_checkpoint_ns: i64,
    /// The warm-start outcome last logged.
    warm_logged: Option<WarmStartOutcome>,
    /// Judges each solution's lag behind its time of validity.
    staleness: Staleness,
    /// Solutions flagged stale.
    stale: u64,
    /// Stale solutions since the last fresh one (logged once per backlog).
    stale_run: u64,
    /// Every solution's IMU-send-to-solution-send latency (reported in the status: the
    /// recording may keep only some solutions).
    latency: LatencyHistogram,
}

impl<E: NavEngine> State<'_, E> {
    /// Push an alive/dead transition into the engine and record it (an engine input).
    fn set_alive(&mut self, sensor: SensorId, alive: bool) {
        self.alive[sensor] = alive;
        self.alive_events += 1;
        let mut ev = SensorAliveEvent {
            sensor: sensor as u32,
            alive,
            ..Default::default()
        };
        ev.header.time_ns = self.filter_time_ns;
        ev.header.seq = self.alive_events;
        ev.header.send_mono_ns = msgs::monotonic_ns();
        let rec = Record::SensorAlive(ev);
        let _ = feed(&mut self.engine, &rec);
        self.recorder.record_live(rec, ev.header.send_mono_ns);
    }

    fn mark_received(&mut self, sensor: SensorId) {
        self.got[sensor] = true;
        self.seen[sensor] = true;
        if !self.alive[sensor] {
            self.set_alive(sensor, true);
            tracing::info!("{} alive", sensor.name());
        }
    }

    fn log_push_error(&mut self, e: Rejection) {
        self.errors_logged += 1;
        if self.errors_logged <= 20 || self.errors_logged.is_power_of_two() {
            tracing::warn!("rejected input ({} so far): {e}", self.errors_logged);
        }
    }

    /// Take every sample queued on `sub`.
    fn drain<T: Message>(&mut self, sub: &Sub<T>)
    where
        Record: From<T>,
    {
        loop {
            match sub.receive() {
                Ok(Some(s)) => self.on_message(Record::from(s)),
                Ok(None) => break,
                Err(e) => {
                    tracing::error!("{e}");
                    break;
                }
            }
        }
    }

    /// A message received: a sensor's goes into the engine; an IMU sample's solution is
    /// published; then the input and the solution go to the recorder, in that order. The
    /// recorder's hand-off (a batch of [`crate::recorder::LIVE_BATCH`] records pushed to its
    /// queue, which may wake its thread) comes after the publication, off the latency path
    /// from IMU sample to solution.
    fn on_message(&mut self, rec: Record) {
        let now = msgs::monotonic_ns();
        let Some(sensor) = rec.channel().and_then(Channel::sensor) else {
            // Truth goes to the recorder only: the filter never sees it.
            self.recorder.record_live(rec, now);
            return;
        };
        let imu = match &rec {
            Record::Imu(s) => Some(*s),
            _ => None,
        };
        if let Some(s) = &imu {
            self.imu_received += 1;
            self.staleness.observe(s.header.time_ns, now);
        }
        self.mark_received(sensor);
        let r = feed(&mut self.engine, &rec);
        let solution = match (r, imu) {
            (Ok(Some(mut sol)), Some(s)) => {
                self.filter_time_ns = sol.header.time_ns;
                self.solutions += 1;
                stamp_solution(&mut sol, &s, self.solutions);
                sol.header.send_mono_ns = msgs::monotonic_ns();
                if s.header.send_mono_ns > 0 {
                    self.latency.record(
                        sol.header
                            .send_mono_ns
                            .saturating_sub(s.header.send_mono_ns),
                    );
                }
                self.judge_staleness(&mut sol);
                if self.solutions.is_multiple_of(self.decimation) {
                    match self.nav_pub.send_raw(sol) {
                        Ok(()) => self.published += 1,
                        Err(e) => tracing::error!("{e}"),
                    }
                }
                Some(sol)
            }
            (Ok(_), Some(s)) => {
                self.filter_time_ns = s.header.time_ns;
                None
            }
            (Ok(_), None) => None,
            (Err(e), _) => {
                self.log_push_error(e);
                None
            }
        };
        self.recorder.record_live(rec, now);
        if let Some(sol) = solution {
            self.recorder
                .record_live(Record::Nav(sol), sol.header.send_mono_ns);
            // The solution is out: the late samples held out of it are fused now, before the
            // next IMU sample comes (and before a checkpoint is taken of the state).
            self.engine.catch_up();
            self.maybe_checkpoint(sol.header.time_ns);
        }
    }

    /// Flag a solution published late behind its time of validity (a backlog being caught
    /// up), count it, and log each backlog once when it ends.
    fn judge_staleness(&mut self, sol: &mut NavSolution) {
        if self
            .staleness
            .is_stale(sol.header.time_ns, sol.header.send_mono_ns)
        {
            sol.stale = 1;
            self.stale += 1;
            self.stale_run += 1;
        } else if self.stale_run > 0 {
            tracing::warn!(
                "caught up after a backlog: {} solutions published stale (flagged), fresh again at filter time {:.3} s",
                self.stale_run,
                sol.header.time_ns as f64 * 1e-9
            );
            self.stale_run = 0;
        }
    }

    /// Hand the engine's estimate to the checkpoint writer when the interval has passed.
    fn maybe_checkpoint(&mut self, t_ns: i64) {
        let Some(w) = &self.checkpoint else {
            return;
        };
        if t_ns - self.last_checkpoint_ns < self.checkpoint_interval_ns {
            return;
        }
        // The buffer comes back from the writer thread: no allocation per checkpoint.
        let mut s = w.buffer();
        if self.engine.snapshot_into(&mut s) {
            w.submit(s);
            self.last_checkpoint_ns = t_ns;
        } else {
            w.recycle(s);
        }
    }

    /// Log what became of the checkpoint the engine started from, once per change.
    fn log_warm_start(&mut self) {
        let o = self.engine.warm_start_outcome();
        if o == self.warm_logged {
            return;
        }
        self.warm_logged = o;
        match o {
            Some(WarmStartOutcome::Held) => {
                tracing::info!("checkpoint is fresh: held for the alignment in motion")
            }
            Some(WarmStartOutcome::Resumed { gap_s }) => tracing::info!(
                "warm restart: sensor-error estimates resumed from the checkpoint, {gap_s:.2} s after it"
            ),
            Some(WarmStartOutcome::Refused(r)) => {
                tracing::warn!("checkpoint refused ({r}): aligning from the priors")
            }
            None => {}
        }
    }

    fn deadline_missed(&mut self, sensor: SensorId) {
        if self.got[sensor] {
            return; // a sample arrived in the same wake-up
        }
        if self.seen[sensor] {
            self.misses[sensor] = self.misses[sensor].saturating_add(1);
        }
        if self.alive[sensor] {
            self.set_alive(sensor, false);
            tracing::warn!("{} silent beyond its deadline", sensor.name());
        }
    }

    fn status(&self) -> Status {
        let mut st = Status {
            solutions_published: self.published,
            records_written: self.recorder.written(),
            records_dropped: self.recorder.dropped(),
            recorder_errors: self.recorder.errors(),
            solutions_stale: self.stale,
            latency_count: self.latency.count(),
            latency_p50_us: self.latency.percentile_us(50.0),
            latency_p99_us: self.latency.percentile_us(99.0),
            latency_max_us: self.latency.max_us(),
            ..engine_status(&self.engine)
        };
        st.header.time_ns = self.filter_time_ns;
        for (s, &alive) in self.alive.iter() {
            let i = s as usize;
            if alive {
                st.alive_mask |= 1 << i;
            }
            st.sensors[i].alive = u32::from(alive);
            st.sensors[i].deadline_misses = self.misses[s];
        }
        st
    }

    fn publish_status(&mut self) {
        self.log_warm_start();
        let st = self.status();
        match self.status_pub.send(st) {
            Ok(stamped) => {
                self.recorder.record_live(
                    Record::Status(Box::new(stamped)),
                    stamped.header.send_mono_ns,
                );
            }
            Err(e) => tracing::error!("{e}"),
        }
    }
}

/// Run the daemon until `stop` is set; then drain what is queued, publish a last status, finish
/// the recording and return.
pub fn run<E: NavEngine>(
    engine: E,
    opts: &DaemonOptions,
    stop: &AtomicBool,
) -> Result<DaemonReport, DaemonError> {
    let bus = Bus::new(&opts.prefix, &opts.node_name)?;
    let imu = bus.subscriber::<ImuSample>()?;
    let star = bus.subscriber::<StarTrackerSample>()?;
    let gnss = bus.subscriber::<GnssSample>()?;
    let odo = bus.subscriber::<OdometerSample>()?;
    let baro = bus.subscriber::<BaroSample>()?;
    let truth = bus.subscriber::<TruthSample>()?;
    let nav_pub = bus.publisher::<NavSolution>()?;
    let status_pub = bus.publisher::<Status>()?;
    let rc = &opts.system.recorder;
    // An unwritable or full output disk must not stop navigation: the recorder degrades to
    // counting drops (Status.records_dropped / recorder_errors) and the error is logged.
    let recorder = Recorder::start_or_degrade(
        &opts.out,
        &RecorderOptions {
            queue_capacity: rc.queue_capacity,
            chunk_size_bytes: rc.chunk_size_bytes,
            flush_interval: Duration::from_secs_f64(rc.flush_interval_s),
            segment_duration: (rc.segment_duration_s > 0.0)
                .then(|| Duration::from_secs_f64(rc.segment_duration_s)),
            metadata: opts.metadata.clone(),
            encoding: rc.encoding,
            view_rate_hz: rc.view_rate_hz,
            solution_rate_hz: rc.solution_rate_hz,
            truth_rate_hz: rc.truth_rate_hz,
            ..Default::default()
        },
    );
    let mut st = State {
        engine,
        recorder,
        nav_pub,
        status_pub,
        decimation: u64::from(opts.system.fusion.nav_decimation.max(1)),
        alive: PerSensor::splat(false),
        seen: PerSensor::splat(false),
        got: PerSensor::splat(false),
        misses: PerSensor::splat(0),
        imu_received: 0,
        solutions: 0,
        published: 0,
        filter_time_ns: 0,
        errors_logged: 0,
        alive_events: 0,
        stop,
        checkpoint: None,
        checkpoint_interval_ns: (opts.system.fusion.checkpoint_interval_s * 1e9) as i64,
        last_checkpoint_ns: i64::MIN / 2,
        warm_logged: None,
        staleness: Staleness::new(
            opts.speed,
            Duration::from_secs_f64(opts.system.fusion.stale_after_ms * 1e-3),
        ),
        stale: 0,
        stale_run: 0,
        latency: LatencyHistogram::default(),
    };
    if let Some(path) = &opts.checkpoint
        && opts.system.fusion.checkpoint_interval_s > 0.0
    {
        // Not fatal: without checkpoints the daemon navigates; a restart aligns again.
        match CheckpointWriter::start(path.clone()) {
            Ok(w) => st.checkpoint = Some(w),
            Err(e) => tracing::error!("no checkpoints ({}): {e}", path.display()),
        }
    }

    let dl = |s: SensorId| opts.system.wall_deadline(s, opts.speed);
    for s in SensorId::ALL {
        tracing::info!("{} deadline {:?} (wall)", s.name(), dl(s));
    }
    let status_period = Duration::from_secs_f64(opts.system.fusion.status_period_s);
    tracing::info!(
        "fusion running: prefix {}, recording {}",
        opts.prefix,
        opts.out.display()
    );
    // The scheduling of this (the filter) thread, once the recorder's and checkpoint writer's
    // threads have started with the normal policy and slice.
    // The short time slice first: a SCHED_FIFO priority below replaces it.
    match crate::time_slice::apply_short_slice() {
        Ok(()) => tracing::debug!(
            "filter thread: {} µs time slice",
            crate::time_slice::FILTER_SLICE_NS / 1000
        ),
        Err(e) => tracing::info!("filter thread: the default time slice kept ({e})"),
    }
    let rt = &opts.system.fusion.realtime;
    if rt.any() {
        crate::realtime::apply(rt)?;
        tracing::info!("real-time settings applied: {rt:?}");
    }
    let started = Instant::now();
    // Readiness, status and watchdog for a service manager (no-op without NOTIFY_SOCKET).
    let mut service = crate::sd_notify::Service::from_env();

    // Every subscriber is drained at each wake-up, in `Channel` order, aiding first: the
    // navigator buffers it until the inertial solution reaches its time.
    let drain_all = |st: &mut State<'_, E>| {
        st.got = PerSensor::splat(false);
        st.drain(&star);
        st.drain(&gnss);
        st.drain(&odo);
        st.drain(&baro);
        st.drain(&imu);
        st.drain(&truth);
    };

    // Spin-then-block: after each wake-up, poll the IMU listener's wake-up for up to `spin_us`
    // (a `poll` with no timeout: no sleep, no allocation, nothing consumed), so that the next
    // sample is met awake: the wait after it returns at once instead of sleeping and being
    // woken. A core's worth of CPU while spinning: for a computer that has one to give.
    let spin = Duration::from_micros(opts.system.fusion.spin_us);
    // A sensor silent for its deadline is declared dead, and again each deadline after while
    // it stays silent (its misses are counted); the status goes out every period.
    let mut deadline_at = PerSensor::splat(started);
    for s in SensorId::ALL {
        deadline_at[s] = started + dl(s);
    }
    let mut status_at = started + status_period;
    while !st.stop.load(Ordering::SeqCst) {
        if !spin.is_zero() {
            let until = Instant::now() + spin;
            while !imu.wake_up_pending() && Instant::now() < until {
                std::hint::spin_loop();
            }
        }
        let now = Instant::now();
        let mut wake_by = (now + STOP_CHECK).min(status_at);
        for s in SensorId::ALL {
            wake_by = wake_by.min(deadline_at[s]);
        }
        // At least a microsecond: the socket's receive timeout counts whole microseconds, and
        // zero would mean no timeout at all.
        let timeout = wake_by
            .saturating_duration_since(now)
            .max(Duration::from_micros(1));
        imu.wait_for_wake_up(timeout)?;
        drain_all(&mut st);
        let now = Instant::now();
        for s in SensorId::ALL {
            if st.got[s] {
                deadline_at[s] = now + dl(s);
            } else if now >= deadline_at[s] {
                st.deadline_missed(s);
                deadline_at[s] = now + dl(s);
            }
        }
        if now >= status_at {
            st.publish_status();
            status_at = (status_at + status_period).max(now);
        }
        st.recorder.hand_over_live_if_due(now);
        service.tick(st.engine.mode(), st.solutions, st.recorder.dropped());
    }
    service.stopping();
    tracing::info!(
        "stopping after {:.1} s (signal {})",
        started.elapsed().as_secs_f64(),
        crate::signals::last_signal()
    );
    drain_all(&mut st);
    st.publish_status();
    st.log_warm_start();
    let report_base = (st.imu_received, st.solutions, st.published, st.stale);
    let final_snapshot = st.engine.snapshot();
    let State {
        recorder,
        checkpoint,
        ..
    } = st;
    if let Some(w) = checkpoint {
        let c = w.finish();
        tracing::info!(
            "checkpoints: {} written, {} failed, {} superseded",
            c.written,
            c.failed,
            c.superseded
        );
    }
    let (recorder, segments) = recorder.finish_with_segments()?;
    Ok(DaemonReport {
        imu_received: report_base.0,
        solutions: report_base.1,
        solutions_published: report_base.2,
        recorder,
        segments,
        solutions_stale: report_base.3,
        final_snapshot,
    })
}

#[cfg(test)]
#[allow(clippy::field_reassign_with_default)]
mod tests {
    use super::*;
    use std::sync::{Arc, Mutex};

    #[derive(Clone, Default)]
    struct Fake {
        alive_calls: Arc<Mutex<Vec<(usize, bool)>>>,
        gnss: Arc<Mutex<u64>>,
    }

    impl NavEngine for Fake {
        fn push_imu(&mut self, s: &ImuSample) -> Result<Option<NavSolution>, Rejection> {
            let mut n = NavSolution::default();
            n.header.time_ns = s.header.time_ns;
            n.q_ned_body = [1.0, 0.0, 0.0, 0.0];
            Ok(Some(n))
        }
        fn push_star_tracker(&mut self, _: &StarTrackerSample) -> Result<(), Rejection> {
            Ok(())
        }
        fn push_gnss(&mut self, _: &GnssSample) -> Result<(), Rejection> {
            *self.gnss.lock().unwrap() += 1;
            Ok(())
        }
        fn push_odometer(&mut self, _: &OdometerSample) -> Result<(), Rejection> {
            Ok(())
        }
        fn push_baro(&mut self, _: &BaroSample) -> Result<(), Rejection> {
            Ok(())
        }
        fn set_sensor_alive(&mut self, sensor: usize, alive: bool) {
            self.alive_calls.lock().unwrap().push((sensor, alive));
        }
        fn health(&self) -> [SensorHealth; MAX_SENSORS] {
            Default::default()
        }
        fn mode(&self) -> u32 {
            msgs::NavMode::GnssInertial as u32
        }
    }

    /// The status carries the engine's redundant-IMU counters (paper 004) when it has them.
    #[test]
    fn status_carries_redundancy_counters() {
        struct Red(Fake);
        impl NavEngine for Red {
            fn push_imu(&mut self, s: &ImuSample) -> Result<Option<NavSolution>, Rejection> {
                self.0.push_imu(s)
            }
            fn push_star_tracker(&mut self, s: &StarTrackerSample) -> Result<(), Rejection> {
                self.0.push_star_tracker(s)
            }
            fn push_gnss(&mut self, s: &GnssSample) -> Result<(), Rejection> {
                self.0.push_gnss(s)
            }
            fn push_odometer(&mut self, s: &OdometerSample) -> Result<(), Rejection> {
                self.0.push_odometer(s)
            }
            fn push_baro(&mut self, s: &BaroSample) -> Result<(), Rejection> {
                self.0.push_baro(s)
            }
            fn set_sensor_alive(&mut self, sensor: usize, alive: bool) {
                self.0.set_sensor_alive(sensor, alive)
            }
            fn health(&self) -> [SensorHealth; MAX_SENSORS] {
                self.0.health()
            }
            fn mode(&self) -> u32 {
                self.0.mode()
            }
            fn redundancy(&self) -> Option<fusion::redundancy::RedundancyStatus> {
                Some(fusion::redundancy::RedundancyStatus {
                    excluded_mask: 0b100,
                    suspect_mask: 0b110,
                    faults_detected: 2,
                    ..Default::default()
                })
            }
        }
        let st = engine_status(&Red(Fake::default()));
        assert_eq!(st.imu_channels_excluded_mask, 0b100);
        assert_eq!(st.imu_channels_suspect_mask, 0b110);
        assert_eq!(st.imu_faults_detected, 2);
        assert_eq!(st.mode, msgs::NavMode::GnssInertial as u32);
        let st = engine_status(&Fake::default());
        assert_eq!(st.imu_faults_detected, 0);
    }

    #[test]
    fn daemon_fuses_records_and_detects_silence() {
        let prefix = format!("sextant-test-daemon-{}", std::process::id());
        let dir = std::env::temp_dir().join(&prefix);
        std::fs::create_dir_all(&dir).unwrap();
        let out = dir.join("recording.mcap");
        let path = std::path::Path::new("sextant.toml");
        let mut system =
            SystemConfig::parse(include_str!("../../config/sextant.toml"), path).unwrap();
        system.fusion.status_period_s = 0.1;
        system.fusion.deadlines_ms[SensorId::Imu] = 50.0;
        system.fusion.min_wall_deadline_ms = 20.0;
        // Every solution and truth sample recorded (the thinning has its own recorder test).
        system.recorder.solution_rate_hz = 0.0;
        system.recorder.truth_rate_hz = 0.0;
        system.validate(path).unwrap();
        let opts = DaemonOptions {
            prefix: prefix.clone(),
            out: out.clone(),
            speed: 1.0,
            system,
            node_name: "test-fusion".into(),
            metadata: Vec::new(),
            checkpoint: None,
        };
        let fake = Fake::default();
        let engine = fake.clone();
        let stop = Arc::new(AtomicBool::new(false));
        let stop2 = stop.clone();
        let daemon = std::thread::spawn(move || run(engine, &opts, &stop2));

        std::thread::sleep(Duration::from_millis(500));
        let bus = Bus::new(&prefix, "test-drivers").unwrap();
        let mut imu = bus.publisher::<ImuSample>().unwrap();
        let mut gnss = bus.publisher::<GnssSample>().unwrap();
        let mut truth = bus.publisher::<TruthSample>().unwrap();
        let t0 = 1_400_000_000_000_000_000i64;
        for k in 0..100i64 {
            let mut s = ImuSample::default();
            s.header.time_ns = t0 + k * 5_000_000;
            imu.send(s).unwrap();
            let mut t = TruthSample::default();
            t.header.time_ns = s.header.time_ns;
            t.q_ned_body = [1.0, 0.0, 0.0, 0.0];
            truth.send(t).unwrap();
            if k % 20 == 0 {
                let mut g = GnssSample::default();
                g.header.time_ns = s.header.time_ns;
                gnss.send(g).unwrap();
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        // Silence: the IMU deadline (50 ms) must be missed.
        std::thread::sleep(Duration::from_millis(400));
        stop.store(true, Ordering::SeqCst);
        let report = daemon.join().unwrap().unwrap();
        assert_eq!(report.imu_received, 100);
        assert_eq!(report.solutions, 100);
        assert_eq!(report.recorder.dropped, 0);
        assert_eq!(*fake.gnss.lock().unwrap(), 5);
        let calls = fake.alive_calls.lock().unwrap().clone();
        assert!(calls.contains(&(0, true)), "{calls:?}");
        assert!(calls.contains(&(0, false)), "{calls:?}");
        assert!(calls.contains(&(2, true)), "{calls:?}");

        let s = sextant_lab::analysis::analyze_recording(&out, &[]).unwrap();
        assert_eq!(s.messages_per_channel["imu"], 100);
        assert_eq!(s.messages_per_channel["truth"], 100);
        assert_eq!(s.messages_per_channel["gnss"], 5);
        assert_eq!(s.messages_per_channel["nav"], 100);
        assert!(s.messages_per_channel["status"] >= 3);
        assert_eq!(s.solutions_matched_with_truth, 100);
        assert_eq!(s.sequence_gaps_per_channel["imu"], 0);
        assert!(s.horizontal_error_max_m.unwrap() < 1e-9);
        assert!(s.latency_p50_us.unwrap() > 0.0);
        // The latency is the daemon's own, over every solution (its last status).
        assert_eq!(s.latency_solutions, 100);
        assert!(s.latency_max_us.unwrap() >= s.latency_p99_us.unwrap());
        assert_eq!(s.final_mode.as_deref(), Some("gnss-inertial"));
        assert!(!s.recording_truncated);
    }
}
