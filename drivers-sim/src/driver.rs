//! The loop shared by every driver binary: command line, scenario loading, signal handling,
//! pacing on CLOCK_MONOTONIC and publishing on the iceoryx2 bus.
//!
//! Sample k at sim time `t_k = k·period` (ns since the scenario epoch) is computed first, then
//! sent at CLOCK_MONOTONIC `start_mono_ns + (t_k + d)/speed`, `d` the driver's publication delay
//! after the stamp (none for the IMU, [`MESSAGE_HANDLING_NS`] for the message sensors and the
//! truth) (absolute `clock_nanosleep`, woken at
//! least every 100 ms to notice a stop request). The process exits after the last sample with
//! `t_k ≤ duration`, or as soon as SIGINT/SIGTERM arrives; either way the iceoryx2 ports and
//! node are dropped cleanly. A sample found overdue by more than [`max_lag_ns`] when its turn
//! comes (the process was stopped or starved) is dropped, not sent late: the driver resumes with
//! current data and the lost samples show as sequence gaps at every subscriber.

use crate::SimError;
use crate::scenario::Scenario;
use crate::sources::SampleSource;
use clap::Parser;
use nix::sys::signal::{SaFlags, SigAction, SigHandler, SigSet, Signal, sigaction};
use nix::sys::time::TimeSpec;
use nix::time::{ClockId, ClockNanosleepFlags, clock_nanosleep};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

/// Command line common to every simulated driver (docs/ARCHITECTURE.md, process contract).
#[derive(Debug, Clone, Parser)]
pub struct DriverArgs {
    /// Scenario file (TOML).
    #[arg(long)]
    pub scenario: PathBuf,
    /// Service-name prefix of this run.
    #[arg(long, default_value = "sextant")]
    pub prefix: String,
    /// CLOCK_MONOTONIC time (ns) that corresponds to the scenario epoch; default: now.
    #[arg(long)]
    pub start_mono_ns: Option<u64>,
    /// Simulation speed relative to wall time (`inf` = as fast as possible).
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Override of the scenario duration, s.
    #[arg(long)]
    pub duration: Option<f64>,
}

/// Set by the SIGINT/SIGTERM handler.
static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: nix::libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

/// Install the SIGINT/SIGTERM handlers that request a clean stop (no `SA_RESTART`, so sleeps
/// are interrupted).
pub fn install_signal_handlers() -> Result<(), SimError> {
    let action = SigAction::new(
        SigHandler::Handler(on_signal),
        SaFlags::empty(),
        SigSet::empty(),
    );
    for sig in [Signal::SIGINT, Signal::SIGTERM] {
        // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
        unsafe { sigaction(sig, &action) }.map_err(|e| SimError::Signal(format!("{sig}: {e}")))?;
    }
    Ok(())
}

/// Whether a stop was requested by a signal.
pub fn stop_requested() -> bool {
    STOP.load(Ordering::SeqCst)
}

/// Sleep until CLOCK_MONOTONIC reaches `target_ns`; returns false when a stop was requested.
pub fn sleep_until_mono(target_ns: u64) -> bool {
    loop {
        if stop_requested() {
            return false;
        }
        let now = msgs::monotonic_ns();
        if now >= target_ns {
            return true;
        }
        let wake = target_ns.min(now + 100_000_000);
        let ts = TimeSpec::new(
            (wake / 1_000_000_000) as nix::libc::time_t,
            (wake % 1_000_000_000) as nix::libc::c_long,
        );
        // EINTR (a signal) and spurious wake-ups just loop.
        let _ = clock_nanosleep(
            ClockId::CLOCK_MONOTONIC,
            ClockNanosleepFlags::TIMER_ABSTIME,
            &ts,
        );
    }
}

/// How long before its send time a driver computes its next sample, ns of wall time: half its
/// period, at most 2 ms (a GNSS epoch of the simulator's world takes up to ≈ 2 ms of CPU, the
/// other sources tens of µs).
fn compute_lead_ns(period_ns: i64, speed: f64) -> u64 {
    let half_period = period_ns as f64 / speed / 2.0;
    if half_period.is_finite() && half_period > 0.0 {
        half_period.min(2e6) as u64
    } else {
        0
    }
}

/// [`sleep_until_mono`] in steps of at most 100 ms, pinging the service manager's watchdog
/// before each: a driver waiting for its next sample (1 s for a 1 Hz receiver) is not hung.
fn sleep_pinging(target_ns: u64, service: &mut msgs::sd_notify::Service) -> bool {
    loop {
        service.ping();
        let now = msgs::monotonic_ns();
        if now >= target_ns {
            return !stop_requested();
        }
        if !sleep_until_mono(target_ns.min(now + 100_000_000)) {
            return false;
        }
    }
}

/// Log to stderr, filter from `RUST_LOG` (default `info`). A failed write (the log file on a
/// full disk) is dropped, never fatal: `tracing-subscriber` would report it with `eprintln!`,
/// which panics when stderr is the failing file.
pub fn init_logging() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(|| LossyStderr)
        .log_internal_errors(false)
        .try_init();
}

/// stderr whose write errors are ignored (reported as success).
struct LossyStderr;

impl std::io::Write for LossyStderr {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let _ = std::io::stderr().write_all(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        let _ = std::io::stderr().flush();
        Ok(())
    }
}

/// What a driver run did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RunSummary {
    /// Messages published.
    pub published: u64,
    /// True when stopped by a signal before the end.
    pub interrupted: bool,
    /// Samples dropped because they were overdue by more than [`max_lag_ns`] (the process was
    /// stopped or starved); each consumed a sequence number, so subscribers count them as lost.
    pub overdue_dropped: u64,
}

/// Simulated time by which a sample may be late and still be sent: 1 s, the fusion daemon's
/// default delayed-fusion window (`buffer_window_s`) — an aiding sample older than that could
/// not be fused, and an IMU burst older than that would only produce stale solutions.
const MAX_LAG_SIM_S: f64 = 1.0;
/// Floor of the allowed lateness in wall time: scheduling delays of a loaded machine
/// (tens of milliseconds) must not drop samples at high speed-ups.
const MIN_LAG_WALL_S: f64 = 0.25;

/// Wall-clock lateness (ns) beyond which a driver running at `speed` drops a sample instead
/// of sending it: like a real sensor whose FIFO overflows while nobody reads it, a driver that
/// was stopped (SIGSTOP, a debugger, a starved CPU) resumes with current data instead of
/// flooding the bus with an overdue burst. `None` at infinite speed (no clock to be late on).
pub fn max_lag_ns(speed: f64) -> Option<u64> {
    speed
        .is_finite()
        .then(|| ((MAX_LAG_SIM_S / speed).max(MIN_LAG_WALL_S) * 1e9) as u64)
}

fn cli_invalid(key: &str, reason: String) -> SimError {
    SimError::Invalid {
        file: Path::new("command line").to_path_buf(),
        key: key.to_string(),
        reason,
    }
}

/// How long after a message's stamp the simulated driver of a message sensor (star tracker,
/// GNSS receiver, odometer, barometer; and the truth) publishes it, ns of simulated time: a
/// driver stamps a serial or CAN message when it arrives, then reads, decodes and publishes it.
/// The simulator's stamps lie on its truth grid, which is also the IMU's: published at their
/// stamps, every sensor's messages would reach the fusion at the very microsecond of an IMU
/// sample, with every driver due woken at once (a computer whose sensors run on their own
/// clocks never sees that), and the fusion's latency would measure the test rig's pile-up. 0.3
/// ms is off the instants of every IMU rate up to 2 kHz, and so is the computation before it
/// ([`compute_lead_ns`]: at most 2 ms earlier). The samples are no later for the filter: their
/// times of validity are their stamps' (less the sensor's latency), a sample published after
/// the IMU sample of its epoch is fused at that epoch by the delayed fusion's rewind.
pub const MESSAGE_HANDLING_NS: i64 = 300_000;

/// The six simulated sensor processes, one binary each (`sextant-sim-imu`, …).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SimDriver {
    /// `sextant-sim-imu`.
    Imu,
    /// `sextant-sim-star-tracker`.
    StarTracker,
    /// `sextant-sim-gnss`.
    Gnss,
    /// `sextant-sim-odometer`.
    Odometer,
    /// `sextant-sim-baro`.
    Baro,
    /// `sextant-sim-truth`.
    Truth,
}

impl SimDriver {
    /// Every simulated driver, in the order a run starts them.
    pub const ALL: [SimDriver; 6] = [
        Self::Imu,
        Self::StarTracker,
        Self::Gnss,
        Self::Odometer,
        Self::Baro,
        Self::Truth,
    ];

    /// Simulated time from a sample's stamp to its publication, ns: none for the IMU (its
    /// publication starts the latency the fusion is measured by), [`MESSAGE_HANDLING_NS`] for
    /// the others.
    pub fn publish_delay_ns(self) -> i64 {
        match self {
            Self::Imu => 0,
            _ => MESSAGE_HANDLING_NS,
        }
    }

    /// The process's name (its binary's and its iceoryx2 node's).
    pub fn process_name(self) -> &'static str {
        match self {
            Self::Imu => "sextant-sim-imu",
            Self::StarTracker => "sextant-sim-star-tracker",
            Self::Gnss => "sextant-sim-gnss",
            Self::Odometer => "sextant-sim-odometer",
            Self::Baro => "sextant-sim-baro",
            Self::Truth => "sextant-sim-truth",
        }
    }
}

/// The `main` of a simulated driver process: logging, its command line, [`run`] with its
/// source. Not generic on purpose: the six binaries link the driver loop compiled once here
/// instead of each compiling its own copy of it (and of iceoryx2's publisher).
pub fn main_of(driver: SimDriver) -> Result<RunSummary, SimError> {
    use crate::sources::{
        BaroSource, GnssSource, ImuSource, OdometerSource, StarTrackerSource, TruthSource,
    };
    init_logging();
    let args = DriverArgs::parse();
    match driver {
        SimDriver::Imu => run(&args, driver, ImuSource::new),
        SimDriver::StarTracker => run(&args, driver, StarTrackerSource::new),
        SimDriver::Gnss => run(&args, driver, GnssSource::new),
        SimDriver::Odometer => run(&args, driver, OdometerSource::new),
        SimDriver::Baro => run(&args, driver, BaroSource::new),
        SimDriver::Truth => run(&args, driver, TruthSource::new),
    }
}

/// Run one driver: load the scenario, build the source with `make(scenario, epoch_gps_ns)`,
/// publish every sample on time (its stamp plus the driver's
/// [`SimDriver::publish_delay_ns`]) as the driver's node.
pub fn run<S, F>(args: &DriverArgs, driver: SimDriver, make: F) -> Result<RunSummary, SimError>
where
    S: SampleSource,
    F: FnOnce(&Scenario, i64) -> S,
{
    if args.speed.is_nan() || args.speed <= 0.0 {
        return Err(cli_invalid(
            "--speed",
            format!("must be > 0, got {}", args.speed),
        ));
    }
    let node_name = driver.process_name();
    let publish_delay_ns = driver.publish_delay_ns();
    let scn = Scenario::load(&args.scenario)?;
    let duration_ns = match args.duration {
        Some(d) if d.is_finite() && d > 0.0 => (d * 1e9).round() as i64,
        Some(d) => return Err(cli_invalid("--duration", format!("must be > 0 s, got {d}"))),
        None => scn.duration_ns(),
    };
    install_signal_handlers()?;
    let start_mono = args.start_mono_ns.unwrap_or_else(msgs::monotonic_ns);
    let epoch_ns = scn.epoch_gps().ns;
    let mut source = make(&scn, epoch_ns);
    let bus = msgs::ipc::Bus::new(&args.prefix, node_name)?;
    let mut publisher = bus.publisher::<S::Msg>()?;
    let period = source.period_ns();
    tracing::info!(
        scenario = %args.scenario.display(),
        prefix = %args.prefix,
        period_ns = period,
        duration_s = duration_ns as f64 * 1e-9,
        speed = args.speed,
        "{node_name} started"
    );
    let mut summary = RunSummary {
        published: 0,
        interrupted: false,
        overdue_dropped: 0,
    };
    let max_lag = max_lag_ns(args.speed);
    // Readiness and watchdog pings to `sextant run` (or systemd); inert without NOTIFY_SOCKET.
    let mut service = msgs::sd_notify::Service::from_env();
    // Overdue samples dropped since the last one sent (logged once per stall).
    let mut dropping = 0u64;
    // A driver restarted mid-run (by `sextant run` after a crash) must not replay the samples
    // that fell due while it was dead: like a real sensor it resumes with current data. Their
    // values are still computed, because every source is a sequential process (random streams,
    // truth integration) that must stay identical to an uninterrupted run.
    let started_mono = msgs::monotonic_ns();
    let compute_lead = compute_lead_ns(period, args.speed);
    let mut k = source.first_index();
    while k * period <= duration_ns {
        if stop_requested() {
            summary.interrupted = true;
            break;
        }
        let t_ns = k * period;
        let offset = (t_ns + publish_delay_ns) as f64 / args.speed;
        let target = start_mono.saturating_add(if offset.is_finite() { offset as u64 } else { 0 });
        // Idle after a send, as a device driver blocked on its next read is: the sample is
        // computed shortly before its send time, not right after the previous send, when the
        // subscribers it woke are starting on the same cores.
        let compute_at = target.saturating_sub(compute_lead);
        if compute_at > msgs::monotonic_ns() && !sleep_pinging(compute_at, &mut service) {
            summary.interrupted = true;
            break;
        }
        let msg = source.sample(t_ns);
        if args.speed.is_finite() && target < started_mono {
            // Lost while the driver was down: the sequence number is consumed, so the sample
            // numbering continues where an uninterrupted driver's would be and subscribers
            // count the samples missed across the restart as a sequence gap.
            publisher.skip();
            k += 1;
            continue;
        }
        if let Some(lag) = max_lag
            && msgs::monotonic_ns() > target.saturating_add(lag)
        {
            publisher.skip();
            dropping += 1;
            summary.overdue_dropped += 1;
            k += 1;
            continue;
        }
        if dropping > 0 {
            tracing::warn!(
                "{node_name} fell behind its clock (stopped or starved): {dropping} overdue samples dropped, resuming at {:.3} s",
                t_ns as f64 * 1e-9
            );
            dropping = 0;
        }
        if !sleep_pinging(target, &mut service) {
            summary.interrupted = true;
            break;
        }
        publisher.send(msg)?;
        summary.published += 1;
        k += 1;
    }
    tracing::info!(
        published = summary.published,
        overdue_dropped = summary.overdue_dropped,
        interrupted = summary.interrupted,
        "{node_name} finished"
    );
    drop(publisher);
    drop(bus);
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::compute_lead_ns;

    #[test]
    fn the_next_sample_is_computed_half_a_period_before_its_send_at_most_2_ms() {
        // 1 kHz in real time: 0.5 ms; ten times faster: 50 µs of wall time.
        assert_eq!(compute_lead_ns(1_000_000, 1.0), 500_000);
        assert_eq!(compute_lead_ns(1_000_000, 10.0), 50_000);
        // 200 Hz and a 1 Hz receiver: capped at 2 ms.
        assert_eq!(compute_lead_ns(5_000_000, 1.0), 2_000_000);
        assert_eq!(compute_lead_ns(1_000_000_000, 1.0), 2_000_000);
        // As fast as possible (no pacing): none.
        assert_eq!(compute_lead_ns(1_000_000, f64::INFINITY), 0);
    }
}
