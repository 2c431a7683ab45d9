//! The `sextant` command. `sextant run`: start the drivers and the fusion daemon, supervise them,
//! stop them cleanly, then analyse the recording (table, `summary.json`, PNG plots).

use anyhow::{Context, bail};
use clap::{Parser, Subcommand};
use msgs::ipc::Bus;
use msgs::{NavMode, SensorId, Status};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use sextant_lab::{analysis, config, plots, scenario};
use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{ExitStatus, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use tokio::signal::unix::{SignalKind, signal};
use tokio::sync::mpsc;

/// Sextant navigation computer.
#[derive(Debug, Parser)]
#[command(name = "sextant", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the live system: drivers, fusion and recorder; then summarise the recording.
    Run(RunArgs),
    /// Run a named offline experiment; prints its table, writes summary.json and PNG plots.
    Experiment(ExperimentArgs),
    /// Measure latency through the real processes (200 Hz and 1 kHz IMU), offline fusion and
    /// recorder throughput, CPU and memory; prints a table, writes summary.json and a histogram.
    Bench(BenchArgs),
    /// Replay a recording: offline through the fusion (bit-exact check, or other settings with
    /// --config), or live onto the iceoryx2 services (bench).
    Replay(ReplayArgs),
    /// Post-analysis of a recording: errors against truth, NIS per sensor, rejections, mode
    /// changes, dropouts; REPORT.md, summary.json and PNG plots.
    Report(ReportArgs),
    /// Calibrate a sensor from a recording: `calibrate boresight REC.mcap --site LAT,LON,H`
    /// estimates the star-tracker / IMU boresight angles κ1..κ3 (paper 000) from a static log.
    Calibrate(CalibrateArgs),
}

#[derive(Debug, clap::Args)]
struct ReportArgs {
    /// The recording.
    recording: PathBuf,
    /// Output directory (default out/report).
    #[arg(long, default_value = "out/report")]
    out: PathBuf,
}

#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("mode").required(true).args(["offline", "live"])))]
struct ReplayArgs {
    /// Re-run the fusion over this recording's inputs at full speed.
    #[arg(long, value_name = "REC.mcap")]
    offline: Option<PathBuf>,
    /// Republish this recording's sensor channels with the recorded timing.
    #[arg(long, value_name = "REC.mcap")]
    live: Option<PathBuf>,
    /// Output directory of an offline replay (default out/replay).
    #[arg(long, default_value = "out/replay")]
    out: PathBuf,
    /// Filter tuning (filter.toml) or system configuration to replay with instead of the
    /// configuration embedded in the recording (offline).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Speed-up of simulated over wall time (live).
    #[arg(long, default_value_t = 1.0)]
    speed: f64,
    /// Service-name prefix (live).
    #[arg(long, default_value = "sextant")]
    prefix: String,
    /// Do not republish the truth (live).
    #[arg(long)]
    no_truth: bool,
}

#[derive(Debug, clap::Args)]
struct BenchArgs {
    /// Output directory (default out/bench).
    #[arg(long, default_value = "out/bench")]
    out: PathBuf,
    /// System configuration whose directory is copied (default config/sextant.toml; the
    /// embedded copy when absent).
    #[arg(long, default_value = DEFAULT_CONFIG)]
    config: PathBuf,
    /// Short runs (a few seconds each) for tests; the same figures, less precise.
    #[arg(long)]
    quick: bool,
}

#[derive(Debug, clap::Args)]
struct ExperimentArgs {
    /// Experiment name (`sextant experiment list` is not needed: an unknown name lists them), or
    /// `all`: every experiment into OUT/NAME plus OUT/RESULTS.md.
    name: String,
    /// Output directory (default out/experiment/NAME).
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
struct RunArgs {
    /// System configuration (default config/sextant.toml; if absent, the copy embedded in the
    /// binary is written to OUT/config/ and used).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Scenario file (default: `system.scenario` of the configuration).
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Simulated duration, s (default: `run.duration_s`, at most `run.max_duration_s`).
    #[arg(long)]
    duration: Option<f64>,
    /// Speed-up of simulated time over wall time (default: `run.speed`).
    #[arg(long)]
    speed: Option<f64>,
    /// Output directory (default: `run.out`): recording.mcap, summary.json, plots, logs/.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Service-name prefix (default: `system.prefix`); use distinct prefixes for parallel runs.
    #[arg(long)]
    prefix: Option<String>,
    /// Wall time between a driver's unexpected death and its restart, s (crash-loop backoff).
    /// The fusion daemon is restarted at once.
    #[arg(long, default_value_t = 0.5)]
    restart_delay: f64,
}

#[derive(Debug, clap::Args)]
struct CalibrateArgs {
    #[command(subcommand)]
    what: CalibrateWhat,
}

#[derive(Debug, Subcommand)]
enum CalibrateWhat {
    /// Star-tracker boresight from a static recording at a known site: the paper's three
    /// stages and least squares; prints a table, writes summary.json and a PNG plot.
    Boresight {
        /// The recording (MCAP) of a static run with star-tracker and IMU channels.
        recording: PathBuf,
        /// Known site: latitude, longitude (deg), height (m), e.g. `55.655,37.534,200`.
        #[arg(long, allow_hyphen_values = true)]
        site: sextant_lab::calibrate::SiteArg,
        /// Output directory.
        #[arg(long, default_value = "out/calibrate")]
        out: PathBuf,
        /// Calibration window from the start of the record, s.
        #[arg(long, default_value_t = 600.0)]
        window: f64,
    },
}

const DEFAULT_CONFIG: &str = "config/sextant.toml";

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .init();
    // iceoryx2's own log: warnings and errors only unless IOX2_LOG_LEVEL says otherwise.
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let cli = Cli::parse();
    match cli.command {
        Command::Run(args) => {
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()?;
            let code = rt.block_on(run(args))?;
            std::process::exit(code);
        }
        Command::Experiment(args) => experiment(args),
        Command::Bench(args) => bench(args),
        Command::Replay(args) => replay(args),
        Command::Calibrate(CalibrateArgs {
            what:
                CalibrateWhat::Boresight {
                    recording,
                    site,
                    out,
                    window,
                },
        }) => {
            let opts = sextant_lab::calibrate::BoresightOptions {
                recording,
                site,
                out: out.clone(),
                window_s: window,
            };
            let s = sextant_lab::calibrate::boresight(&opts)?;
            println!("{}", sextant_lab::calibrate::table(&s));
            println!("summary.json and plot in {}", out.display());
            Ok(())
        }
        Command::Report(args) => {
            let s = sextant_lab::report::report(&args.recording, &args.out)?;
            println!("{}", sextant_lab::report::format_table(&s));
            println!(
                "REPORT.md, summary.json and plots in {}",
                args.out.display()
            );
            Ok(())
        }
    }
}

/// `sextant bench`: run it, print its table.
fn bench(args: BenchArgs) -> anyhow::Result<()> {
    use sextant_lab::bench;
    let bin_dir = std::env::current_exe()?
        .parent()
        .map(Path::to_path_buf)
        .context("no directory of the current executable")?;
    let cleaned = msgs::ipc::cleanup_dead_nodes()?;
    if cleaned > 0 {
        tracing::info!("removed the shared memory of {cleaned} dead node(s) of an earlier run");
    }
    let opts = bench::BenchOptions {
        out: args.out.clone(),
        config: args.config,
        bin_dir,
        prefix: format!("sextant_bench_{}", std::process::id()),
        quick: args.quick,
    };
    let summary = bench::run(&opts)?;
    println!("{}", bench::table(&summary));
    println!("summary and histogram in {}", args.out.display());
    Ok(())
}

/// `sextant experiment NAME`: run it, print its table, point at its files.
fn experiment(args: ExperimentArgs) -> anyhow::Result<()> {
    use sextant_lab::experiments;
    if args.name != "all" && !experiments::names().contains(&args.name.as_str()) {
        bail!(
            "unknown experiment `{}`; known: {}",
            args.name,
            experiments::names().join(", ")
        );
    }
    let out = args
        .out
        .unwrap_or_else(|| PathBuf::from("out/experiment").join(&args.name));
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let summary = experiments::run_by_name(&args.name, &out, true)?;
    println!("{}", experiments::table_by_name(&args.name, &summary)?);
    println!("summary and plots in {}", out.display());
    Ok(())
}

/// One supervised child process.
struct Slot {
    name: String,
    program: PathBuf,
    args: Vec<String>,
    log: PathBuf,
    restarts: u32,
    finished: bool,
    pid: Option<i32>,
}

fn spawn(
    idx: usize,
    slot: &mut Slot,
    tx: &mpsc::UnboundedSender<(usize, std::io::Result<ExitStatus>)>,
) -> anyhow::Result<()> {
    let log = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&slot.log)
        .with_context(|| format!("open log {}", slot.log.display()))?;
    let mut cmd = tokio::process::Command::new(&slot.program);
    cmd.args(&slot.args)
        .stdin(Stdio::null())
        .stdout(log.try_clone()?)
        .stderr(log)
        // Own process group: a terminal Ctrl-C reaches only `sextant`, which stops the children
        // in order (drivers, then fusion, so that the recorder sees everything).
        .process_group(0);
    // SAFETY: only calls prctl(2), async-signal-safe, between fork and exec.
    unsafe {
        cmd.pre_exec(|| {
            // If `sextant` dies (even by SIGKILL), the child gets SIGTERM: no orphans.
            nix::sys::prctl::set_pdeathsig(Signal::SIGTERM).map_err(std::io::Error::from)
        });
    }
    let mut child = cmd
        .spawn()
        .with_context(|| format!("start {}", slot.program.display()))?;
    slot.pid = child.id().map(|p| p as i32);
    tracing::debug!("started {} (pid {:?})", slot.name, slot.pid);
    let tx = tx.clone();
    tokio::spawn(async move {
        let r = child.wait().await;
        let _ = tx.send((idx, r));
    });
    Ok(())
}

fn signal_pid(slot: &Slot, sig: Signal) {
    if let Some(pid) = slot.pid
        && let Err(e) = kill(Pid::from_raw(pid), sig)
    {
        tracing::debug!("{sig} to {} ({pid}): {e}", slot.name);
    }
}

/// Wait until every slot in `which` has exited, up to `timeout`; then SIGKILL the rest and wait
/// for them too.
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
                        tracing::warn!("{} did not stop in {timeout:?}: SIGKILL", slots[i].name);
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

/// Recording of the `k`-th fusion daemon of a run: `recording.mcap` for the first (k = 0),
/// `recording.k.mcap` after its k-th restart.
fn recording_path(out: &Path, k: usize) -> PathBuf {
    if k == 0 {
        out.join("recording.mcap")
    } else {
        out.join(format!("recording.{k}.mcap"))
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

fn status_line(st: &Status) -> String {
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

/// Subscribe to the status on a plain thread and print a live one-line status.
fn status_thread(prefix: String, stop: Arc<AtomicBool>) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        use iceoryx2::prelude::*;
        let run = || -> Result<(), String> {
            let bus = Bus::new(&prefix, "sextant-run").map_err(|e| e.to_string())?;
            let sub = bus.subscriber::<Status>().map_err(|e| e.to_string())?;
            let ws = WaitSetBuilder::new()
                .signal_handling_mode(SignalHandlingMode::Disabled)
                .create::<ipc::Service>()
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
                    let mut err = std::io::stderr().lock();
                    let _ = write!(err, "{}", status_line(&st));
                    let _ = err.flush();
                    printed = true;
                }
            }
            if printed {
                eprintln!();
            }
            Ok(())
        };
        if let Err(e) = run() {
            tracing::warn!("status display: {e}");
        }
    })
}

fn load_config(args: &RunArgs, out: &Path) -> anyhow::Result<config::LoadedConfig> {
    let path = match &args.config {
        Some(p) => p.clone(),
        None if Path::new(DEFAULT_CONFIG).exists() => PathBuf::from(DEFAULT_CONFIG),
        None => {
            let dir = out.join("config");
            let p = config::materialize_embedded(&dir)?;
            tracing::info!(
                "{DEFAULT_CONFIG} not found: using the embedded configuration, written to {}",
                dir.display()
            );
            p
        }
    };
    Ok(config::load(&path)?)
}

async fn run(args: RunArgs) -> anyhow::Result<i32> {
    let wall_start = Instant::now();
    // The output directory is needed before the config only for the embedded fallback, whose
    // default is the built-in `out/run`.
    let pre_out = args.out.clone().unwrap_or_else(|| PathBuf::from("out/run"));
    let cfg = load_config(&args, &pre_out)?;
    let rc = &cfg.system.run;
    let out = args.out.clone().unwrap_or_else(|| rc.out.clone());
    let duration = args.duration.unwrap_or(rc.duration_s);
    if !(duration.is_finite() && duration > 0.0 && duration <= rc.max_duration_s) {
        bail!(
            "--duration must be within (0, {}] s (run.max_duration_s of {}), got {duration}",
            rc.max_duration_s,
            cfg.path.display()
        );
    }
    let speed = args.speed.unwrap_or(rc.speed);
    if !(speed.is_finite() && speed > 0.0 && speed <= 1000.0) {
        bail!("--speed must be within (0, 1000], got {speed}");
    }
    let scenario_path = args.scenario.clone().unwrap_or_else(|| cfg.scenario_path());
    // Validate the whole scenario (every key, grade and range) before starting anything: a
    // malformed file is one clear error naming it and the key, not drivers dying at start-up.
    drivers_sim::scenario::Scenario::load(&scenario_path)?;
    let scen = scenario::ScenarioInfo::load(&scenario_path)?;
    let prefix = args
        .prefix
        .clone()
        .unwrap_or_else(|| cfg.system.system.prefix.clone());
    std::fs::create_dir_all(out.join("logs"))
        .with_context(|| format!("create {}", out.display()))?;
    let recording = out.join("recording.mcap");
    // Recordings of an earlier run in this directory: recording.mcap and, after fusion restarts,
    // recording.1.mcap, recording.2.mcap, ... (see `recording_path`).
    for k in 0..=64 {
        let old = recording_path(&out, k);
        if old.exists() {
            std::fs::remove_file(&old).with_context(|| format!("remove old {}", old.display()))?;
        }
    }
    if !(args.restart_delay.is_finite() && (0.0..=600.0).contains(&args.restart_delay)) {
        bail!(
            "--restart-delay must be within [0, 600] s, got {}",
            args.restart_delay
        );
    }
    let restart_delay = Duration::from_secs_f64(args.restart_delay);

    let cleaned = msgs::ipc::cleanup_dead_nodes()?;
    if cleaned > 0 {
        tracing::info!("removed the shared memory of {cleaned} dead node(s) of an earlier run");
    }

    let bin_dir = std::env::current_exe()?
        .parent()
        .map(Path::to_path_buf)
        .context("no directory of the current executable")?;
    let mut names: Vec<String> = rc.drivers.clone();
    names.push("sextant-fusion".into());
    let missing: Vec<_> = names
        .iter()
        .filter(|n| !bin_dir.join(n).is_file())
        .cloned()
        .collect();
    if !missing.is_empty() {
        bail!(
            "missing binaries in {}: {} (build them: cargo build --workspace --bins)",
            bin_dir.display(),
            missing.join(", ")
        );
    }

    let mut sigint = signal(SignalKind::interrupt())?;
    let mut sigterm = signal(SignalKind::terminate())?;

    let start_mono_ns = msgs::monotonic_ns() + (rc.start_delay_s * 1e9) as u64;
    let scenario_arg = scenario_path.display().to_string();
    let mut slots: Vec<Slot> = rc
        .drivers
        .iter()
        .map(|n| Slot {
            name: n.clone(),
            program: bin_dir.join(n),
            args: vec![
                "--scenario".into(),
                scenario_arg.clone(),
                "--prefix".into(),
                prefix.clone(),
                "--start-mono-ns".into(),
                start_mono_ns.to_string(),
                "--speed".into(),
                speed.to_string(),
                "--duration".into(),
                duration.to_string(),
            ],
            log: out.join("logs").join(format!("{n}.log")),
            restarts: 0,
            finished: false,
            pid: None,
        })
        .collect();
    let fusion_idx = slots.len();
    slots.push(Slot {
        name: "sextant-fusion".into(),
        program: bin_dir.join("sextant-fusion"),
        args: vec![
            "--config".into(),
            cfg.path.display().to_string(),
            "--prefix".into(),
            prefix.clone(),
            "--out".into(),
            recording.display().to_string(),
            "--speed".into(),
            speed.to_string(),
        ],
        log: out.join("logs").join("sextant-fusion.log"),
        restarts: 0,
        finished: false,
        pid: None,
    });
    let driver_idx: Vec<usize> = (0..fusion_idx).collect();

    eprintln!(
        "sextant run: scenario {} ({}), {duration} s at {speed}x, prefix {prefix}, output {}",
        scenario_path.display(),
        scen.name,
        out.display()
    );
    let (tx, mut rx) = mpsc::unbounded_channel();
    // Fusion first, so that its subscribers exist before the first sample.
    spawn(fusion_idx, &mut slots[fusion_idx], &tx)?;
    for &i in &driver_idx {
        if let Err(e) = spawn(i, &mut slots[i], &tx) {
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
    let status = status_thread(prefix.clone(), status_stop.clone());

    // The drivers end by themselves; a watchdog stops a run that overruns by far.
    let expected = Duration::from_secs_f64(rc.start_delay_s + duration / speed);
    let watchdog = tokio::time::sleep(expected + Duration::from_secs(30) + expected / 2);
    tokio::pin!(watchdog);
    let stop_timeout = Duration::from_secs_f64(rc.stop_timeout_s);
    let mut results: HashMap<usize, ExitStatus> = HashMap::new();
    #[derive(Debug, PartialEq)]
    enum End {
        Completed,
        Interrupted(&'static str),
        FusionDied,
        Watchdog,
    }
    // Recordings written, in order: the first fusion writes recording.mcap, the k-th restart
    // recording.k.mcap; each is a complete MCAP up to its last flushed chunk.
    let mut recordings: Vec<PathBuf> = vec![recording.clone()];
    // Drivers waiting out `restart_delay` before their restart.
    let (respawn_tx, mut respawn_rx) = mpsc::unbounded_channel::<usize>();
    let end = loop {
        tokio::select! {
            _ = sigint.recv() => break End::Interrupted("SIGINT"),
            _ = sigterm.recv() => break End::Interrupted("SIGTERM"),
            _ = &mut watchdog => break End::Watchdog,
            Some(i) = respawn_rx.recv() => {
                clean_dead_nodes();
                let slot = &mut slots[i];
                if let Err(e) = spawn(i, slot, &tx) {
                    tracing::error!("restart of {} failed: {e:#}", slot.name);
                    slot.finished = true;
                    if driver_idx.iter().all(|&d| slots[d].finished) {
                        break End::Completed;
                    }
                }
            }
            Some((i, r)) = rx.recv() => {
                slots[i].pid = None;
                if i == fusion_idx {
                    let slot = &mut slots[i];
                    if slot.restarts >= rc.max_restarts {
                        tracing::error!("sextant-fusion exited unexpectedly: {r:?} after {} restarts (see {})", slot.restarts, slot.log.display());
                        if let Ok(st) = r { results.insert(i, st); }
                        break End::FusionDied;
                    }
                    slot.restarts += 1;
                    let next = recording_path(&out, slot.restarts as usize);
                    eprintln!();
                    tracing::warn!(
                        "sextant-fusion died ({r:?}): restart {}/{}, new recording {} ({} stays readable up to its last chunk)",
                        slot.restarts, rc.max_restarts, next.display(),
                        recordings.last().map_or(String::new(), |p| p.display().to_string())
                    );
                    if let Some(k) = slot.args.iter().position(|a| a == "--out") {
                        slot.args[k + 1] = next.display().to_string();
                    }
                    recordings.push(next);
                    // The dead daemon's ports still occupy the services: free them first.
                    clean_dead_nodes();
                    if let Err(e) = spawn(i, slot, &tx) {
                        tracing::error!("restart of sextant-fusion failed: {e:#}");
                        break End::FusionDied;
                    }
                    continue;
                }
                match r {
                    Ok(st) if st.success() => {
                        slots[i].finished = true;
                        results.insert(i, st);
                    }
                    other => {
                        let slot = &mut slots[i];
                        if slot.restarts < rc.max_restarts {
                            slot.restarts += 1;
                            eprintln!();
                            tracing::warn!("{} died ({other:?}): restart {}/{} in {restart_delay:?}", slot.name, slot.restarts, rc.max_restarts);
                            let respawn_tx = respawn_tx.clone();
                            tokio::spawn(async move {
                                tokio::time::sleep(restart_delay).await;
                                let _ = respawn_tx.send(i);
                            });
                        } else {
                            tracing::error!("{} died ({other:?}) after {} restarts: giving up on it", slot.name, slot.restarts);
                            slot.finished = true;
                            if let Ok(st) = other { results.insert(i, st); }
                        }
                    }
                }
                if driver_idx.iter().all(|&d| slots[d].finished) {
                    break End::Completed;
                }
            }
        }
    };
    if end != End::Completed {
        eprintln!();
        tracing::info!("stopping ({end:?})");
    }
    // Drivers first, then the fusion daemon (which drains, finishes the recording and exits).
    stop_and_wait(&mut slots, &driver_idx, &mut rx, stop_timeout, &mut results).await;
    stop_and_wait(
        &mut slots,
        &[fusion_idx],
        &mut rx,
        stop_timeout * 4,
        &mut results,
    )
    .await;
    status_stop.store(true, Ordering::SeqCst);
    let _ = tokio::task::spawn_blocking(move || status.join()).await;
    match msgs::ipc::cleanup_dead_nodes() {
        Ok(n) if n > 0 => tracing::warn!("cleaned the shared memory of {n} dead node(s)"),
        Ok(_) => {}
        Err(e) => tracing::warn!("cleanup: {e}"),
    }
    let fusion_ok = results.get(&fusion_idx).is_some_and(|s| s.success());
    if !fusion_ok {
        tracing::error!(
            "sextant-fusion did not exit cleanly ({:?}); see {}",
            results.get(&fusion_idx),
            slots[fusion_idx].log.display()
        );
    }

    let wall_s = wall_start.elapsed().as_secs_f64();
    // The summary is of the last fusion's recording (the whole run when it never crashed).
    let recording = recordings.last().cloned().unwrap_or(recording);
    if !recording.exists() {
        bail!("no recording was written ({})", recording.display());
    }
    let a = analysis::analyze(&recording, &scen.gnss_outages)?;
    println!("{}", analysis::format_table(&a.summary));
    let mut json = serde_json::to_value(&a.summary)?;
    if let Some(m) = json.as_object_mut() {
        m.insert("run_wall_time_s".into(), wall_s.into());
        m.insert("scenario".into(), scenario_arg.clone().into());
        m.insert("requested_duration_s".into(), duration.into());
        m.insert("speed".into(), speed.into());
        m.insert("service_prefix".into(), prefix.clone().into());
        m.insert("end".into(), format!("{end:?}").into());
        m.insert("fusion_restarts".into(), slots[fusion_idx].restarts.into());
        m.insert(
            "recordings".into(),
            recordings
                .iter()
                .map(|p| serde_json::Value::from(p.display().to_string()))
                .collect(),
        );
        m.insert(
            "analysed_recording".into(),
            recording.display().to_string().into(),
        );
        m.insert(
            "driver_restarts".into(),
            serde_json::Value::Object(
                slots[..fusion_idx]
                    .iter()
                    .map(|s| (s.name.clone(), s.restarts.into()))
                    .collect(),
            ),
        );
    }
    let summary_path = out.join("summary.json");
    std::fs::write(&summary_path, serde_json::to_string_pretty(&json)? + "\n")
        .with_context(|| format!("write {}", summary_path.display()))?;
    match plots::write_plots(&out, &a.series) {
        Ok(files) => {
            for f in files {
                println!("  plot: {}", f.display());
            }
        }
        Err(e) => tracing::warn!("{e}"),
    }
    println!("  summary: {}", summary_path.display());
    println!("  run time: {wall_s:.1} s wall");
    Ok(match end {
        End::Completed | End::Interrupted(_) if fusion_ok => 0,
        _ => 1,
    })
}

/// `sextant replay`: offline (table, summary.json, the replay's recording) or live.
fn replay(args: ReplayArgs) -> anyhow::Result<()> {
    use sextant_lab::replay as rp;
    if let Some(rec) = args.offline {
        let s = rp::replay_offline(&rp::OfflineOptions {
            recording: rec,
            out_dir: args.out.clone(),
            config: args.config,
            progress: true,
        })?;
        println!("{}", rp::format_offline_table(&s));
        let replayed = std::path::Path::new(&s.replayed_recording);
        let analysis = analysis::analyze(replayed, &[]).ok();
        if let Some(a) = &analysis {
            println!("{}", analysis::format_table(&a.summary));
            let _ = plots::write_plots(&args.out, &a.series);
        }
        let summary = serde_json::json!({
            "replay": s,
            "analysis": analysis.map(|a| a.summary),
        });
        let path = args.out.join("summary.json");
        std::fs::write(&path, serde_json::to_string_pretty(&summary)?)
            .with_context(|| format!("writing {}", path.display()))?;
        println!("summary in {}", path.display());
        if s.config_source == "embedded" && !s.bit_exact {
            bail!("the replay did not reproduce the recorded solution bit for bit");
        }
        return Ok(());
    }
    let Some(rec) = args.live else {
        bail!("give --offline REC.mcap or --live REC.mcap");
    };
    let stop = sextant_lab::signals::install()?;
    let s = rp::replay_live(
        &rp::LiveOptions {
            recording: rec,
            prefix: args.prefix,
            speed: args.speed,
            start_delay_s: 1.0,
            with_truth: !args.no_truth,
            progress: true,
        },
        stop,
    )?;
    println!("{}", serde_json::to_string_pretty(&s)?);
    Ok(())
}
