//! The supervisor of `sextant run`: starts the driver processes, the fusion daemon and the
//! auxiliary services (the live Foxglove server), restarts one that dies unexpectedly, stops
//! them in order when the run ends or `sextant` is told to stop (SIGINT/SIGTERM), and shows a
//! live one-line status read from `<prefix>/status`.
//!
//! Every child runs in its own process group (a terminal Ctrl-C reaches only `sextant`, which
//! then stops the drivers first and the fusion daemon last, so that the recorder sees every
//! sample) and gets SIGTERM if `sextant` itself dies, even by SIGKILL.
//!
//! `sextant run` also plays the service manager for its children (the `sd_notify` protocol,
//! [`msgs::sd_notify`]): each gets a notification socket of its own and `WATCHDOG_USEC`; a child
//! that sends nothing for [`RunPlan::heartbeat_timeout`] is hung (stopped, deadlocked, spinning
//! outside its loop) and is killed with SIGKILL, after which the restart policy applies to it
//! as to any other death.
//!
//! The policy is in plain functions ([`on_exit`], [`driver_args`], [`fusion_args`],
//! [`recording_path`]); [`supervise`] is the event loop that applies it to real processes.

use crate::exit_report::ExitReport;
use msgs::ipc::Bus;
use msgs::{NavMode, SensorId, Status};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use std::collections::HashMap;
use std::future::Future;
use std::os::linux::net::SocketAddrExt;
use std::os::unix::net::{SocketAddr, UnixDatagram};
use std::path::{Path, PathBuf};
use std::process::{ExitStatus, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::mpsc;

/// One process to supervise: what to start and where its stdout/stderr go.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChildSpec {
    /// Name in messages and in the summary (a driver's binary name, `sextant-fusion`).
    pub name: String,
    /// Executable.
    pub program: PathBuf,
    /// Command-line arguments.
    pub args: Vec<String>,
    /// Log file, appended to across restarts.
    pub log: PathBuf,
}

/// A run to supervise.
#[derive(Debug, Clone)]
pub struct RunPlan {
    /// The drivers; the run is complete when every one has ended (exit 0 or given up on).
    pub drivers: Vec<ChildSpec>,
    /// The fusion daemon; its arguments contain `--out RECORDING`, replaced by
    /// [`recording_path`]`(out, k)` on its k-th restart.
    pub fusion: ChildSpec,
    /// Auxiliary services (the live Foxglove server): started after the fusion daemon, run
    /// until the run ends, restarted like a driver whenever they exit, stopped with the
    /// drivers; the run never waits for them and goes on when one is given up on.
    pub services: Vec<ChildSpec>,
    /// Output directory of the run (recordings of restarted fusion daemons).
    pub out: PathBuf,
    /// Restarts allowed per child.
    pub max_restarts: u32,
    /// Wall time between a driver's unexpected death and its restart (crash-loop backoff); the
    /// fusion daemon is restarted at once.
    pub restart_delay: Duration,
    /// Wall time a driver is given after SIGTERM before SIGKILL; the fusion daemon, which drains
    /// and finishes its recording, gets four times as long.
    pub stop_timeout: Duration,
    /// Wall time after which a run that has not completed is stopped.
    pub watchdog: Duration,
    /// Wall time a child may go without a notification (`WATCHDOG=1`, sent every half of it)
    /// before it is killed as hung and restarted; `None`: children are not watched.
    pub heartbeat_timeout: Option<Duration>,
    /// Service-name prefix whose status is shown as a live line on stderr; `None`: no display.
    pub status_prefix: Option<String>,
}

/// How a supervised run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum End {
    /// Every driver ended by itself.
    Completed,
    /// `sextant` was told to stop (the signal's name).
    Interrupted(&'static str),
    /// The fusion daemon died more often than allowed, or could not be restarted.
    FusionDied,
    /// The run overran [`RunPlan::watchdog`].
    Watchdog,
}

/// What a supervised run left behind.
#[derive(Debug, Clone)]
pub struct RunOutcome {
    /// How it ended.
    pub end: End,
    /// The last fusion daemon's exit status (`None`: not collected, e.g. killed and unreaped).
    pub fusion_exit: Option<ExitStatus>,
    /// Restarts of the fusion daemon.
    pub fusion_restarts: u32,
    /// Restarts per driver, in the order of [`RunPlan::drivers`].
    pub driver_restarts: Vec<(String, u32)>,
    /// Restarts per service, in the order of [`RunPlan::services`].
    pub service_restarts: Vec<(String, u32)>,
    /// Children killed because their heartbeat stopped, per child (drivers, then the fusion
    /// daemon); each kill is also counted in that child's restarts when it was restarted.
    pub hung_kills: Vec<(String, u32)>,
    /// Recordings written, in order: the first fusion daemon's, then one per restart.
    pub recordings: Vec<PathBuf>,
    /// The exit reports of the fusion daemons that reported (one per clean exit, in order);
    /// a daemon that crashed left none.
    pub fusion_reports: Vec<ExitReport>,
}

impl RunOutcome {
    /// The last fusion daemon exited with status 0 (its recording is complete).
    pub fn fusion_ok(&self) -> bool {
        self.fusion_exit.is_some_and(|s| s.success())
    }
}

/// A child could not be started.
#[derive(Debug, thiserror::Error)]
pub enum SuperviseError {
    /// Its log file could not be opened.
    #[error("open log {path}: {source}")]
    Log {
        /// The log file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The child's heartbeat socket could not be created.
    #[error("heartbeat socket @{name}: {source}")]
    Heartbeat {
        /// Its abstract name.
        name: String,
        /// Why.
        source: std::io::Error,
    },
    /// The executable could not be started.
    #[error("start {program}: {source}")]
    Spawn {
        /// The executable.
        program: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

/// Which kind of child exited.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// A driver: exit 0 is its normal end.
    Driver,
    /// The fusion daemon: it ends only when stopped, so any exit during the run is a death.
    Fusion,
    /// An auxiliary service: it too ends only when stopped.
    Service,
}

/// What to do about a child that exited during the run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExitAction {
    /// Its work is done (a driver that exited 0).
    Finished,
    /// Start it again after this wall time.
    Restart(Duration),
    /// It died and has used up its restarts.
    GiveUp,
}

/// The restart policy: a driver that exits 0 is finished; a driver that dies otherwise, or the
/// fusion daemon or a service whatever its status, is restarted while it has had fewer than
/// `max_restarts` restarts (a driver or a service after `restart_delay`, the fusion daemon at
/// once), else given up on.
pub fn on_exit(
    role: Role,
    exited_ok: bool,
    restarts: u32,
    max_restarts: u32,
    restart_delay: Duration,
) -> ExitAction {
    match role {
        Role::Driver if exited_ok => ExitAction::Finished,
        _ if restarts >= max_restarts => ExitAction::GiveUp,
        Role::Driver | Role::Service => ExitAction::Restart(restart_delay),
        Role::Fusion => ExitAction::Restart(Duration::ZERO),
    }
}

/// Command line of a simulated driver (see `drivers_sim::driver::DriverArgs`): every driver of
/// a run shares the scenario, the prefix, the monotonic start time (ns) of the first sample,
/// the speed-up and the simulated duration (s).
pub fn driver_args(
    scenario: &Path,
    prefix: &str,
    start_mono_ns: u64,
    speed: f64,
    duration_s: f64,
) -> Vec<String> {
    vec![
        "--scenario".into(),
        scenario.display().to_string(),
        "--prefix".into(),
        prefix.into(),
        "--start-mono-ns".into(),
        start_mono_ns.to_string(),
        "--speed".into(),
        speed.to_string(),
        "--duration".into(),
        duration_s.to_string(),
    ]
}

/// Command line of `sextant-fusion`: the system configuration, the prefix, the recording to
/// write and the drivers' speed-up.
pub fn fusion_args(config: &Path, prefix: &str, recording: &Path, speed: f64) -> Vec<String> {
    vec![
        "--config".into(),
        config.display().to_string(),
        "--prefix".into(),
        prefix.into(),
        "--out".into(),
        recording.display().to_string(),
        "--speed".into(),
        speed.to_string(),
    ]
}

/// Recording of the `k`-th fusion daemon of a run: `recording.mcap` for the first (k = 0),
/// `recording.k.mcap` after its k-th restart.
pub fn recording_path(out: &Path, k: usize) -> PathBuf {
    if k == 0 {
        out.join("recording.mcap")
    } else {
        out.join(format!("recording.{k}.mcap"))
    }
}

/// The live status line (starts with `\r`, overwrites itself): GPS time of day, mode, alive
/// sensors and the counters of solutions, records, drops and gated measurements.
pub fn status_line(st: &Status) -> String {
    let mode = NavMode::from_u32(st.mode).map_or("?", |m| m.name());
    let t = if st.header.time_ns > 0 {
        let s = st.header.time_ns as f64 * 1e-9;
        format!("{:.1}", s % 86_400.0)
    } else {
        "—".into()
    };
    let alive: Vec<&str> = SensorId::ALL
        .iter()
        .filter(|s| st.alive_mask & (1 << (**s as u32)) != 0)
        .map(|s| s.name())
        .collect();
    let gated: u64 = st.sensors.iter().map(|h| h.rejected_gate).sum();
    format!(
        "\r[GPS tod {t} s] {mode:<19} alive: {:<38} nav {} rec {} dropped {} gated {}   ",
        alive.join(","),
        st.solutions_published,
        st.records_written,
        st.records_dropped,
        gated
    )
}

/// SIGINT and SIGTERM of this process, from now on, as a future yielding the signal's name:
/// [`supervise`] forwards it to the children as an ordered stop.
pub fn stop_signals() -> std::io::Result<impl Future<Output = &'static str>> {
    use tokio::signal::unix::{SignalKind, signal};
    let mut sigint = signal(SignalKind::interrupt())?;
    let mut sigterm = signal(SignalKind::terminate())?;
    Ok(async move {
        tokio::select! {
            _ = sigint.recv() => "SIGINT",
            _ = sigterm.recv() => "SIGTERM",
        }
    })
}

type Exits = mpsc::UnboundedSender<(usize, std::io::Result<ExitStatus>)>;

/// One supervised child and its state.
struct Slot {
    spec: ChildSpec,
    restarts: u32,
    finished: bool,
    pid: Option<i32>,
    /// For the fusion daemon: its stdout is read (and copied into its log) for the exit
    /// reports of each of its runs ([`crate::exit_report`]).
    reports: Option<Arc<Mutex<Vec<ExitReport>>>>,
    /// The service-manager end of its notification socket, when heartbeats are watched.
    heartbeat: Option<Heartbeat>,
    /// Killed as hung, its exit not yet seen.
    hung_kill_sent: bool,
    /// Kills for a stopped heartbeat.
    hung_kills: u32,
}

/// The supervisor's end of one child's notification socket.
struct Heartbeat {
    socket: UnixDatagram,
    /// When a notification was last seen (or the child started), CLOCK_MONOTONIC ns.
    last_mono_ns: u64,
}

/// Bind the notification socket of the `generation`-th start of child `idx` in the abstract
/// namespace (no file to clean up, no path-length limit), non-blocking: it is drained by
/// [`check_heartbeats`].
fn heartbeat_socket(idx: usize, generation: u32) -> Result<(String, UnixDatagram), SuperviseError> {
    let name = format!(
        "sextant-heartbeat-{}-{idx}-{generation}",
        std::process::id()
    );
    let err = |source| SuperviseError::Heartbeat {
        name: name.clone(),
        source,
    };
    let addr = SocketAddr::from_abstract_name(name.as_bytes()).map_err(err)?;
    let socket = UnixDatagram::bind_addr(&addr).map_err(err)?;
    socket.set_nonblocking(true).map_err(err)?;
    Ok((name, socket))
}

/// Take every notification the children sent since the last check; SIGKILL each running child
/// that has sent none for `timeout` (its exit then goes through the restart policy).
fn check_heartbeats(slots: &mut [Slot], timeout: Duration) {
    let now = msgs::monotonic_ns();
    let mut buf = [0u8; 512];
    for slot in slots.iter_mut() {
        let Some(hb) = &mut slot.heartbeat else {
            continue;
        };
        while let Ok(n) = hb.socket.recv(&mut buf) {
            if n > 0 {
                hb.last_mono_ns = now;
            }
        }
        if slot.pid.is_none() || slot.hung_kill_sent {
            continue;
        }
        let silent = Duration::from_nanos(now.saturating_sub(hb.last_mono_ns));
        if silent > timeout {
            crate::logging::stderr_text("\n");
            tracing::error!(
                "{} sent no heartbeat for {:.1} s (limit {:.1} s): hung, killing it",
                slot.spec.name,
                silent.as_secs_f64(),
                timeout.as_secs_f64()
            );
            signal_pid(slot, Signal::SIGKILL);
            slot.hung_kill_sent = true;
            slot.hung_kills += 1;
        }
    }
}

/// Copy a child's stdout into its log file line by line, keeping its exit reports. A failed
/// write to the log (full disk) loses that line only: the reports stay in memory.
fn read_reports(
    pipe: std::io::PipeReader,
    mut log: std::fs::File,
    reports: Arc<Mutex<Vec<ExitReport>>>,
) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        use std::io::{BufRead, Write};
        for line in std::io::BufReader::new(pipe).lines() {
            let Ok(line) = line else { break };
            if let Some(r) = ExitReport::parse(&line)
                && let Ok(mut v) = reports.lock()
            {
                v.push(r);
            }
            let _ = writeln!(log, "{line}");
        }
    })
}

fn spawn(
    idx: usize,
    slot: &mut Slot,
    tx: &Exits,
    heartbeat_timeout: Option<Duration>,
) -> Result<(), SuperviseError> {
    let spec = &slot.spec;
    let log = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&spec.log)
        .map_err(|source| SuperviseError::Log {
            path: spec.log.clone(),
            source,
        })?;
    let log_err = log.try_clone().map_err(|source| SuperviseError::Log {
        path: spec.log.clone(),
        source,
    })?;
    // The fusion daemon's stdout goes through a pipe (its exit report), the rest to the log.
    let mut reader = None;
    let stdout = match &slot.reports {
        Some(reports) => {
            let (r, w) = std::io::pipe().map_err(|source| SuperviseError::Spawn {
                program: spec.program.clone(),
                source,
            })?;
            reader = Some((r, reports.clone()));
            Stdio::from(w)
        }
        None => Stdio::from(log.try_clone().map_err(|source| SuperviseError::Log {
            path: spec.log.clone(),
            source,
        })?),
    };
    let mut cmd = tokio::process::Command::new(&spec.program);
    cmd.args(&spec.args)
        .stdin(Stdio::null())
        .stdout(stdout)
        .stderr(log_err)
        // Own process group: a terminal Ctrl-C reaches only `sextant`, which stops the children
        // in order (drivers, then fusion, so that the recorder sees everything).
        .process_group(0)
        // `sextant run` is the children's service manager, never one of its own (under systemd
        // it is `sextant run` that reports to systemd).
        .env_remove("NOTIFY_SOCKET")
        .env_remove("WATCHDOG_USEC")
        .env_remove("WATCHDOG_PID");
    let mut heartbeat = None;
    if let Some(timeout) = heartbeat_timeout {
        let (name, socket) = heartbeat_socket(idx, slot.restarts)?;
        cmd.env("NOTIFY_SOCKET", format!("@{name}"))
            .env("WATCHDOG_USEC", timeout.as_micros().to_string());
        heartbeat = Some(Heartbeat {
            socket,
            last_mono_ns: msgs::monotonic_ns(),
        });
    }
    // SAFETY: only calls prctl(2), async-signal-safe, between fork and exec.
    unsafe {
        cmd.pre_exec(|| {
            // If `sextant` dies (even by SIGKILL), the child gets SIGTERM: no orphans.
            nix::sys::prctl::set_pdeathsig(Signal::SIGTERM).map_err(std::io::Error::from)
        });
    }
    let mut child = cmd.spawn().map_err(|source| SuperviseError::Spawn {
        program: spec.program.clone(),
        source,
    })?;
    // The pipe's write end lives on in the child only: EOF when it exits.
    drop(cmd);
    let copier = reader.map(|(r, reports)| read_reports(r, log, reports));
    slot.pid = child.id().map(|p| p as i32);
    slot.heartbeat = heartbeat;
    slot.hung_kill_sent = false;
    tracing::debug!("started {} (pid {:?})", spec.name, slot.pid);
    let tx = tx.clone();
    tokio::spawn(async move {
        let r = child.wait().await;
        // The exit is reported once its stdout is read to the end (the exit report with it).
        if let Some(c) = copier {
            let _ = tokio::task::spawn_blocking(move || c.join()).await;
        }
        let _ = tx.send((idx, r));
    });
    Ok(())
}

fn signal_pid(slot: &Slot, sig: Signal) {
    if let Some(pid) = slot.pid
        && let Err(e) = kill(Pid::from_raw(pid), sig)
    {
        tracing::debug!("{sig} to {} ({pid}): {e}", slot.spec.name);
    }
}

/// SIGTERM every slot in `which`, wait until each has exited, up to `timeout`; then SIGKILL the
/// rest and wait for them too.
async fn stop_and_wait(
    slots: &mut [Slot],
    which: &[usize],
    rx: &mut mpsc::UnboundedReceiver<(usize, std::io::Result<ExitStatus>)>,
    timeout: Duration,
    results: &mut HashMap<usize, ExitStatus>,
) {
    for &i in which {
        if slots[i].pid.is_some() {
            signal_pid(&slots[i], Signal::SIGTERM);
        }
    }
    let live = |slots: &[Slot]| which.iter().any(|&i| slots[i].pid.is_some());
    let deadline = tokio::time::Instant::now() + timeout;
    let mut killed = false;
    while live(slots) {
        match tokio::time::timeout_at(deadline, rx.recv()).await {
            Ok(Some((i, r))) => {
                slots[i].pid = None;
                if let Ok(st) = r {
                    results.insert(i, st);
                }
            }
            Ok(None) => break,
            Err(_) if !killed => {
                killed = true;
                for &i in which {
                    if slots[i].pid.is_some() {
                        tracing::warn!(
                            "{} did not stop in {timeout:?}: SIGKILL",
                            slots[i].spec.name
                        );
                        signal_pid(&slots[i], Signal::SIGKILL);
                    }
                }
                // Reaping after SIGKILL is immediate.
                while live(slots) {
                    match tokio::time::timeout(Duration::from_secs(5), rx.recv()).await {
                        Ok(Some((i, _))) => slots[i].pid = None,
                        _ => return,
                    }
                }
            }
            Err(_) => break,
        }
    }
}

/// Remove the shared memory of crashed processes (a SIGKILLed driver or daemon leaves its
/// iceoryx2 node and ports behind; they would hold port slots of the services).
fn clean_dead_nodes() {
    match msgs::ipc::cleanup_dead_nodes() {
        Ok(n) if n > 0 => tracing::info!("cleaned the shared memory of {n} dead node(s)"),
        Ok(_) => {}
        Err(e) => tracing::warn!("cleanup of dead nodes: {e}"),
    }
}

/// Subscribe to the status on a plain thread and print a live one-line status.
fn status_thread(prefix: String, stop: Arc<AtomicBool>) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        use iceoryx2::prelude::*;
        let run = || -> Result<(), String> {
            let bus = Bus::new(&prefix, "sextant-run").map_err(|e| e.to_string())?;
            let sub = bus.subscriber::<Status>().map_err(|e| e.to_string())?;
            let ws = WaitSetBuilder::new()
                .signal_handling_mode(SignalHandlingMode::Disabled)
                .create::<msgs::ipc::IpcService>()
                .map_err(|e| format!("{e:?}"))?;
            let _g = ws
                .attach_notification(sub.listener())
                .map_err(|e| format!("{e:?}"))?;
            let _tick = ws
                .attach_interval(Duration::from_millis(200))
                .map_err(|e| format!("{e:?}"))?;
            let mut printed = false;
            while !stop.load(Ordering::SeqCst) {
                ws.wait_and_process_once_with_timeout(
                    |_| CallbackProgression::Continue,
                    Duration::from_secs(1),
                )
                .map_err(|e| format!("{e:?}"))?;
                sub.clear_events();
                let mut last = None;
                while let Ok(Some(st)) = sub.receive() {
                    last = Some(st);
                }
                if let Some(st) = last {
                    crate::logging::stderr_text(&status_line(&st));
                    printed = true;
                }
            }
            if printed {
                crate::logging::stderr_text("\n");
            }
            Ok(())
        };
        if let Err(e) = run() {
            tracing::warn!("status display: {e}");
        }
    })
}

/// Run `plan`: start the fusion daemon (first, so that its subscribers exist before the first
/// sample), then the drivers; apply [`on_exit`] to every child that exits; end when every driver
/// has ended, on `interrupt`, when the fusion daemon is given up on, or at the watchdog; then
/// stop the drivers and, after them, the fusion daemon. Must run inside a tokio runtime with
/// time and process drivers enabled.
pub async fn supervise(
    plan: &RunPlan,
    interrupt: impl Future<Output = &'static str>,
) -> Result<RunOutcome, SuperviseError> {
    let new_slot = |spec: &ChildSpec| Slot {
        spec: spec.clone(),
        restarts: 0,
        finished: false,
        pid: None,
        reports: None,
        heartbeat: None,
        hung_kill_sent: false,
        hung_kills: 0,
    };
    let mut slots: Vec<Slot> = plan.drivers.iter().map(new_slot).collect();
    let fusion_idx = slots.len();
    let fusion_reports = Arc::new(Mutex::new(Vec::new()));
    slots.push(Slot {
        reports: Some(fusion_reports.clone()),
        ..new_slot(&plan.fusion)
    });
    let driver_idx: Vec<usize> = (0..fusion_idx).collect();
    slots.extend(plan.services.iter().map(new_slot));
    let service_idx: Vec<usize> = (fusion_idx + 1..slots.len()).collect();

    let (tx, mut rx) = mpsc::unbounded_channel();
    let hb_timeout = plan.heartbeat_timeout;
    spawn(fusion_idx, &mut slots[fusion_idx], &tx, hb_timeout)?;
    for &i in service_idx.iter().chain(&driver_idx) {
        if let Err(e) = spawn(i, &mut slots[i], &tx, hb_timeout) {
            let mut results = HashMap::new();
            let all: Vec<usize> = (0..slots.len()).collect();
            stop_and_wait(
                &mut slots,
                &all,
                &mut rx,
                Duration::from_secs(5),
                &mut results,
            )
            .await;
            return Err(e);
        }
    }
    let status_stop = Arc::new(AtomicBool::new(false));
    let status = plan
        .status_prefix
        .clone()
        .map(|p| status_thread(p, status_stop.clone()));

    let watchdog = tokio::time::sleep(plan.watchdog);
    tokio::pin!(watchdog);
    // Heartbeats are checked four times per timeout: a hung child is killed between 1 and
    // 1.25 timeouts after its last notification.
    let mut heartbeat_check =
        tokio::time::interval(hb_timeout.map_or(Duration::from_secs(3600), |t| t / 4));
    tokio::pin!(interrupt);
    let mut results: HashMap<usize, ExitStatus> = HashMap::new();
    // Recordings written, in order: the first fusion writes recording.mcap, the k-th restart
    // recording.k.mcap; each is a complete MCAP up to its last flushed chunk.
    let first = plan
        .fusion
        .args
        .iter()
        .position(|a| a == "--out")
        .and_then(|k| plan.fusion.args.get(k + 1))
        .map_or_else(|| recording_path(&plan.out, 0), PathBuf::from);
    let mut recordings: Vec<PathBuf> = vec![first];
    // Drivers waiting out `restart_delay` before their restart.
    let (respawn_tx, mut respawn_rx) = mpsc::unbounded_channel::<usize>();
    let max = plan.max_restarts;
    let end = loop {
        tokio::select! {
            sig = &mut interrupt => break End::Interrupted(sig),
            _ = &mut watchdog => break End::Watchdog,
            _ = heartbeat_check.tick(), if hb_timeout.is_some() => {
                if let Some(t) = hb_timeout {
                    check_heartbeats(&mut slots, t);
                }
            }
            Some(i) = respawn_rx.recv() => {
                clean_dead_nodes();
                let slot = &mut slots[i];
                if let Err(e) = spawn(i, slot, &tx, hb_timeout) {
                    tracing::error!("restart of {} failed: {e:#}", slot.spec.name);
                    slot.finished = true;
                    if driver_idx.iter().all(|&d| slots[d].finished) {
                        break End::Completed;
                    }
                }
            }
            Some((i, r)) = rx.recv() => {
                slots[i].pid = None;
                let ok = matches!(&r, Ok(st) if st.success());
                if i == fusion_idx {
                    let slot = &mut slots[i];
                    match on_exit(Role::Fusion, ok, slot.restarts, max, plan.restart_delay) {
                        ExitAction::Restart(_) => {}
                        ExitAction::Finished | ExitAction::GiveUp => {
                            tracing::error!("sextant-fusion exited unexpectedly: {r:?} after {} restarts (see {})", slot.restarts, slot.spec.log.display());
                            if let Ok(st) = r { results.insert(i, st); }
                            break End::FusionDied;
                        }
                    }
                    slot.restarts += 1;
                    let next = recording_path(&plan.out, slot.restarts as usize);
                    crate::logging::stderr_text("\n");
                    tracing::warn!(
                        "sextant-fusion died ({r:?}): restart {}/{max}, new recording {} ({} stays readable up to its last chunk)",
                        slot.restarts, next.display(),
                        recordings.last().map_or(String::new(), |p| p.display().to_string())
                    );
                    if let Some(k) = slot.spec.args.iter().position(|a| a == "--out") {
                        slot.spec.args[k + 1] = next.display().to_string();
                    }
                    recordings.push(next);
                    // The dead daemon's ports still occupy the services: free them first.
                    clean_dead_nodes();
                    if let Err(e) = spawn(i, slot, &tx, hb_timeout) {
                        tracing::error!("restart of sextant-fusion failed: {e:#}");
                        break End::FusionDied;
                    }
                    continue;
                }
                let role = if service_idx.contains(&i) { Role::Service } else { Role::Driver };
                let slot = &mut slots[i];
                match on_exit(role, ok, slot.restarts, max, plan.restart_delay) {
                    ExitAction::Finished => {
                        slot.finished = true;
                        if let Ok(st) = r { results.insert(i, st); }
                    }
                    ExitAction::Restart(delay) => {
                        slot.restarts += 1;
                        crate::logging::stderr_text("\n");
                        tracing::warn!("{} died ({r:?}): restart {}/{max} in {delay:?}", slot.spec.name, slot.restarts);
                        let respawn_tx = respawn_tx.clone();
                        tokio::spawn(async move {
                            tokio::time::sleep(delay).await;
                            let _ = respawn_tx.send(i);
                        });
                    }
                    ExitAction::GiveUp => {
                        tracing::error!("{} died ({r:?}) after {} restarts: giving up on it", slot.spec.name, slot.restarts);
                        slot.finished = true;
                        if let Ok(st) = r { results.insert(i, st); }
                    }
                }
                if driver_idx.iter().all(|&d| slots[d].finished) {
                    break End::Completed;
                }
            }
        }
    };
    if end != End::Completed {
        crate::logging::stderr_text("\n");
        tracing::info!("stopping ({end:?})");
    }
    // Drivers and services first, then the fusion daemon (which drains, finishes the recording
    // and exits).
    let first: Vec<usize> = driver_idx.iter().chain(&service_idx).copied().collect();
    stop_and_wait(&mut slots, &first, &mut rx, plan.stop_timeout, &mut results).await;
    stop_and_wait(
        &mut slots,
        &[fusion_idx],
        &mut rx,
        plan.stop_timeout * 4,
        &mut results,
    )
    .await;
    status_stop.store(true, Ordering::SeqCst);
    if let Some(status) = status {
        let _ = tokio::task::spawn_blocking(move || status.join()).await;
    }
    match msgs::ipc::cleanup_dead_nodes() {
        Ok(n) if n > 0 => tracing::warn!("cleaned the shared memory of {n} dead node(s)"),
        Ok(_) => {}
        Err(e) => tracing::warn!("cleanup: {e}"),
    }
    Ok(RunOutcome {
        end,
        fusion_exit: results.get(&fusion_idx).copied(),
        fusion_restarts: slots[fusion_idx].restarts,
        driver_restarts: slots[..fusion_idx]
            .iter()
            .map(|s| (s.spec.name.clone(), s.restarts))
            .collect(),
        service_restarts: slots[fusion_idx + 1..]
            .iter()
            .map(|s| (s.spec.name.clone(), s.restarts))
            .collect(),
        hung_kills: slots
            .iter()
            .map(|s| (s.spec.name.clone(), s.hung_kills))
            .collect(),
        recordings,
        fusion_reports: fusion_reports.lock().map(|v| v.clone()).unwrap_or_default(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Instant;

    const SECOND: Duration = Duration::from_secs(1);

    fn tmp_dir(what: &str) -> PathBuf {
        let d =
            std::env::temp_dir().join(format!("sextant-supervisor-{what}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// A child running `script` under /bin/sh, its `$@` = `args`.
    fn sh(dir: &Path, name: &str, script: &str, args: &[String]) -> ChildSpec {
        let mut a = vec!["-c".to_string(), script.to_string(), name.to_string()];
        a.extend_from_slice(args);
        ChildSpec {
            name: name.into(),
            program: "/bin/sh".into(),
            args: a,
            log: dir.join(format!("{name}.log")),
        }
    }

    /// Runs until SIGTERM, then appends its name to `dir/order` and exits 0.
    fn stoppable(dir: &Path) -> String {
        format!(
            "trap 'echo \"$0\" >> {}/order; exit 0' TERM; while :; do sleep 0.02; done",
            dir.display()
        )
    }

    fn plan(dir: &Path, drivers: Vec<ChildSpec>, fusion: ChildSpec) -> RunPlan {
        RunPlan {
            drivers,
            fusion,
            services: Vec::new(),
            out: dir.to_path_buf(),
            max_restarts: 2,
            restart_delay: Duration::from_millis(20),
            stop_timeout: 2 * SECOND,
            watchdog: 30 * SECOND,
            heartbeat_timeout: None,
            status_prefix: None,
        }
    }

    fn run(plan: &RunPlan, interrupt: impl Future<Output = &'static str>) -> RunOutcome {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        rt.block_on(supervise(plan, interrupt)).unwrap()
    }

    async fn after(d: Duration) -> &'static str {
        tokio::time::sleep(d).await;
        "SIGTERM"
    }

    #[test]
    fn restart_policy() {
        let d = Duration::from_millis(500);
        assert_eq!(on_exit(Role::Driver, true, 0, 3, d), ExitAction::Finished);
        // A driver that ends normally is finished even with its restarts used up.
        assert_eq!(on_exit(Role::Driver, true, 3, 3, d), ExitAction::Finished);
        assert_eq!(
            on_exit(Role::Driver, false, 0, 3, d),
            ExitAction::Restart(d)
        );
        assert_eq!(
            on_exit(Role::Driver, false, 2, 3, d),
            ExitAction::Restart(d)
        );
        assert_eq!(on_exit(Role::Driver, false, 3, 3, d), ExitAction::GiveUp);
        assert_eq!(on_exit(Role::Driver, false, 0, 0, d), ExitAction::GiveUp);
        // The fusion daemon is restarted at once, whatever its exit status.
        for ok in [true, false] {
            assert_eq!(
                on_exit(Role::Fusion, ok, 0, 3, d),
                ExitAction::Restart(Duration::ZERO)
            );
            assert_eq!(on_exit(Role::Fusion, ok, 3, 3, d), ExitAction::GiveUp);
            // A service runs until stopped: any exit is a death, restarted after the delay.
            assert_eq!(on_exit(Role::Service, ok, 0, 3, d), ExitAction::Restart(d));
            assert_eq!(on_exit(Role::Service, ok, 3, 3, d), ExitAction::GiveUp);
        }
    }

    #[test]
    fn command_lines_and_recording_names() {
        let a = driver_args(Path::new("s/v.toml"), "p", 42, 10.0, 60.5);
        assert_eq!(
            a,
            [
                "--scenario",
                "s/v.toml",
                "--prefix",
                "p",
                "--start-mono-ns",
                "42",
                "--speed",
                "10",
                "--duration",
                "60.5"
            ]
        );
        let f = fusion_args(Path::new("c/sextant.toml"), "p", Path::new("o/r.mcap"), 2.5);
        assert_eq!(
            f,
            [
                "--config",
                "c/sextant.toml",
                "--prefix",
                "p",
                "--out",
                "o/r.mcap",
                "--speed",
                "2.5"
            ]
        );
        assert_eq!(
            recording_path(Path::new("o"), 0),
            Path::new("o/recording.mcap")
        );
        assert_eq!(
            recording_path(Path::new("o"), 2),
            Path::new("o/recording.2.mcap")
        );
    }

    #[test]
    fn status_line_shows_time_of_day_mode_alive_sensors_and_counters() {
        let mut st = Status::default();
        assert!(status_line(&st).contains("[GPS tod — s] initializing"));
        st.header.time_ns = (86_400 * 3 + 3_723) * 1_000_000_000 + 500_000_000;
        st.mode = NavMode::GnssInertial as u32;
        st.alive_mask = (1 << SensorId::Imu as u32) | (1 << SensorId::Gnss as u32);
        st.solutions_published = 7;
        st.records_written = 9;
        st.records_dropped = 1;
        st.sensors[0].rejected_gate = 2;
        st.sensors[2].rejected_gate = 3;
        let line = status_line(&st);
        assert!(
            line.starts_with("\r[GPS tod 3723.5 s] gnss-inertial "),
            "{line}"
        );
        assert!(line.contains("alive: imu,gnss "), "{line}");
        assert!(line.contains("nav 7 rec 9 dropped 1 gated 5"), "{line}");
    }

    #[test]
    fn silent_children_are_killed_as_hung_and_restarted() {
        // Shell stand-ins never notify: with a 200 ms heartbeat timeout each is killed as hung
        // within 200–250 ms of each start and restarted, until one of them is given up on
        // after its 2 restarts (the run then ends: completed when it is the driver, given up
        // when it is the fusion daemon; both run the same rhythm, so either may come first).
        let dir = tmp_dir("hung");
        let rec = recording_path(&dir, 0).display().to_string();
        let driver = sh(&dir, "driver", "echo started; exec sleep 30", &[]);
        let fusion = sh(&dir, "fusion", "exec sleep 30", &["--out".into(), rec]);
        let mut p = plan(&dir, vec![driver], fusion);
        p.heartbeat_timeout = Some(Duration::from_millis(200));
        let t0 = Instant::now();
        let o = run(&p, after(10 * SECOND));
        assert!(
            matches!(o.end, End::FusionDied | End::Completed),
            "{:?}",
            o.end
        );
        assert!(t0.elapsed() < 5 * SECOND, "{:?}", t0.elapsed());
        let kills: HashMap<_, _> = o.hung_kills.iter().cloned().collect();
        assert!(kills["fusion"] >= 1, "{kills:?}");
        assert!(kills["driver"] >= 1, "{kills:?}");
        assert!(kills["fusion"] == 3 || kills["driver"] == 3, "{kills:?}");
        assert!(o.driver_restarts[0].1 >= 1, "{:?}", o.driver_restarts);
        let log = std::fs::read_to_string(dir.join("driver.log")).unwrap();
        assert!(log.matches("started").count() >= 2, "{log}");
    }

    #[test]
    fn crashing_driver_is_restarted_then_given_up_on() {
        let dir = tmp_dir("crash");
        let rec = recording_path(&dir, 0).display().to_string();
        let crasher = sh(&dir, "crasher", "echo started; exit 3", &[]);
        let finisher = sh(&dir, "finisher", "exit 0", &[]);
        let fusion = sh(
            &dir,
            "fusion",
            &stoppable(&dir),
            &["--out".into(), rec.clone()],
        );
        let p = plan(&dir, vec![crasher, finisher], fusion);
        let o = run(&p, std::future::pending());
        assert_eq!(o.end, End::Completed);
        assert_eq!(
            o.driver_restarts,
            [("crasher".to_string(), 2), ("finisher".to_string(), 0)]
        );
        let log = std::fs::read_to_string(dir.join("crasher.log")).unwrap();
        assert_eq!(log.matches("started").count(), 3, "{log}");
        assert!(o.fusion_ok(), "{:?}", o.fusion_exit);
        assert_eq!(o.fusion_restarts, 0);
        assert_eq!(o.recordings, [PathBuf::from(rec)]);
    }

    /// A service that dies is restarted after the delay; the run ends when the drivers end,
    /// whatever the service does, and the service is stopped then.
    #[test]
    fn service_is_restarted_and_never_holds_the_run() {
        let dir = tmp_dir("service");
        let driver = sh(&dir, "driver", "sleep 1; exit 0", &[]);
        let fusion = sh(&dir, "fusion", &stoppable(&dir), &[]);
        // First start: exits at once (as a server whose port is busy would); later: runs.
        let flaky = sh(
            &dir,
            "flaky",
            &format!(
                "echo started; if [ ! -e {d}/ran ]; then touch {d}/ran; exit 1; fi; {}",
                stoppable(&dir),
                d = dir.display()
            ),
            &[],
        );
        let mut p = plan(&dir, vec![driver], fusion);
        p.services = vec![flaky];
        let t0 = Instant::now();
        let o = run(&p, std::future::pending());
        assert_eq!(o.end, End::Completed);
        assert_eq!(o.service_restarts, [("flaky".to_string(), 1)]);
        assert_eq!(o.driver_restarts, [("driver".to_string(), 0)]);
        let log = std::fs::read_to_string(dir.join("flaky.log")).unwrap();
        assert_eq!(log.matches("started").count(), 2, "{log}");
        // Stopped by SIGTERM at the end (its trap wrote its name), before the fusion daemon.
        let order = std::fs::read_to_string(dir.join("order")).unwrap();
        assert_eq!(
            order.lines().collect::<Vec<_>>(),
            ["flaky", "fusion"],
            "{order}"
        );
        assert!(o.fusion_ok(), "{:?}", o.fusion_exit);
        assert!(t0.elapsed() < 10 * SECOND, "{:?}", t0.elapsed());
    }

    #[test]
    fn dead_fusion_daemon_restarts_at_once_with_a_new_recording() {
        let dir = tmp_dir("fusion");
        let rec = recording_path(&dir, 0).display().to_string();
        let driver = sh(&dir, "driver", "exec sleep 30", &[]);
        let fusion = sh(
            &dir,
            "fusion",
            "echo \"$@\"; exit 1",
            &["--out".into(), rec],
        );
        let p = plan(&dir, vec![driver], fusion);
        let t0 = Instant::now();
        let o = run(&p, std::future::pending());
        assert_eq!(o.end, End::FusionDied);
        assert_eq!(o.fusion_restarts, 2);
        assert!(!o.fusion_ok());
        let want: Vec<PathBuf> = (0..3).map(|k| recording_path(&dir, k)).collect();
        assert_eq!(o.recordings, want);
        let log = std::fs::read_to_string(dir.join("fusion.log")).unwrap();
        let outs: Vec<&str> = log
            .lines()
            .filter_map(|l| l.strip_prefix("--out "))
            .collect();
        let want: Vec<String> = want.iter().map(|p| p.display().to_string()).collect();
        assert_eq!(outs, want, "{log}");
        // The driver (`sleep`) was stopped by SIGTERM, not left to run its 30 s.
        assert!(t0.elapsed() < 10 * SECOND, "{:?}", t0.elapsed());
    }

    #[test]
    fn stop_reaches_the_drivers_before_the_fusion_daemon() {
        let dir = tmp_dir("order");
        let d1 = sh(&dir, "driver-a", &stoppable(&dir), &[]);
        let d2 = sh(&dir, "driver-b", &stoppable(&dir), &[]);
        let fusion = sh(&dir, "fusion", &stoppable(&dir), &[]);
        let p = plan(&dir, vec![d1, d2], fusion);
        let o = run(&p, after(Duration::from_millis(300)));
        assert_eq!(o.end, End::Interrupted("SIGTERM"));
        assert!(o.fusion_ok(), "{:?}", o.fusion_exit);
        let order = std::fs::read_to_string(dir.join("order")).unwrap();
        let lines: Vec<&str> = order.lines().collect();
        assert_eq!(lines.len(), 3, "{order}");
        assert_eq!(lines[2], "fusion", "{order}");
    }

    #[test]
    fn child_ignoring_sigterm_is_killed_after_the_stop_timeout() {
        let dir = tmp_dir("kill");
        let stubborn = sh(&dir, "stubborn", "trap '' TERM; exec sleep 30", &[]);
        let fusion = sh(&dir, "fusion", "exec sleep 30", &[]);
        let mut p = plan(&dir, vec![stubborn], fusion);
        p.stop_timeout = Duration::from_millis(300);
        let t0 = Instant::now();
        let o = run(&p, after(Duration::from_millis(100)));
        let took = t0.elapsed();
        assert_eq!(o.end, End::Interrupted("SIGTERM"));
        // SIGTERM ended `sleep` (the fusion stand-in): not a clean exit.
        assert!(!o.fusion_ok());
        assert!(took >= Duration::from_millis(400), "{took:?}");
        assert!(took < 10 * SECOND, "{took:?}");
    }

    #[test]
    fn watchdog_stops_an_overrunning_run() {
        let dir = tmp_dir("watchdog");
        let driver = sh(&dir, "driver", "exec sleep 30", &[]);
        let fusion = sh(&dir, "fusion", &stoppable(&dir), &[]);
        let mut p = plan(&dir, vec![driver], fusion);
        p.watchdog = Duration::from_millis(200);
        let t0 = Instant::now();
        let o = run(&p, std::future::pending());
        assert_eq!(o.end, End::Watchdog);
        assert!(t0.elapsed() < 10 * SECOND);
    }
}
