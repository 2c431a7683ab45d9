//! `sextant bench --out DIR`: measured speed of the system.
//!
//! 1. **Latency through the real processes**: the six simulated drivers and `sextant-fusion`
//!    run at real time (speed 1) on the vehicle scenario with the IMU at 200 Hz and at 1 kHz
//!    (a copy of the scenario with `imu.rate_hz` overridden). For every solution, latency =
//!    solution send time − send time of the IMU sample it was computed from (both
//!    CLOCK_MONOTONIC, `NavSolution.header.send_mono_ns` − `NavSolution.imu_send_mono_ns`),
//!    read back from the run's recording. The filter's alignment is shortened (`alignment_s`)
//!    so that the run navigates within about two seconds (the 1 s window, then a GNSS fix of it
//!    `buffer_window_s` old): latency is a property of the running loop, not of the
//!    alignment quality. The solution rate is counted over the span the solutions cover.
//! 2. **CPU and memory of each process**, from `/proc/PID/stat` (user + system time over the
//!    measurement window) and `/proc/PID/status` (`VmRSS`, `VmHWM`), sampled before the end.
//! 3. **Offline fusion throughput**: the navigator fed in-process from
//!    [`drivers_sim::offline::OfflineSim`] (every aiding sensor, pre-generated so that only
//!    the fusion is timed): IMU samples per second and × real time.
//! 4. **Recording throughput**: the [`Recorder`] saturated with a realistic record mix
//!    (records/s, MB/s of MCAP written), then paced at 10× the default live load (the default
//!    `sextant run` at speed 10) to check that nothing is dropped.
//! 5. **The floor** ([`floor`]), measured in the same run at the same IMU rate and for about as
//!    many samples as the live run has solutions (1 s in quick mode): a bare iceoryx2 IMU →
//!    reply round trip between two processes with Sextant's own services and wake-up mechanism
//!    and message sizes. The floor and the live run alternate in slices (three, two in quick
//!    mode), each live slice a run of its own with its short alignment, and each figure is
//!    taken over all the slices. Sextant's latency is reported against the floor (p50 excess
//!    in µs, p99 ratio): on a loaded machine both move together, so the comparison survives
//!    the load that the absolute figures do not, and a spell of load falls on both.
//! 6. **Cost curves** ([`cost`]): the offline fusion cost per IMU sample against the IMU rate,
//!    the active filter states, the satellites of tight coupling and the redundant IMU channels.
//! 7. **Replay** ([`replay_throughput`]): `replay --offline`'s replay stage (reading, the
//!    filter, writing its recording; not the analysis), the median of five replays, on a
//!    simulated drive recorded with every aiding sensor, and on its loosely coupled part (IMU
//!    and GNSS fixes) exported to the KF-GINS formats and imported back — the files and
//!    `kf-gins.yaml` stay in `OUT/kfgins`, so that KF-GINS can be run on the very same data and
//!    its samples per second compared.
//!
//! Writes `summary.json`, a latency histogram PNG (Sextant and the floor), the cost curves'
//! PNG, and returns the summary for the table.

pub mod bridge;
pub mod cost;
pub mod floor;

use crate::experiments::plot::{Chart, Line, color, line_chart};
use crate::recorder::{OFFLINE_BATCH, OFFLINE_QUEUE, Recorder, RecorderOptions};
use crate::recording::Recording;
use anyhow::{Context, bail};
use drivers_sim::offline::{OfflineSim, feed};
use drivers_sim::scenario::Scenario;
use fusion::navigator::Navigator;
use msgs::{
    BaroSample, GnssSample, ImuSample, NavSolution, OdometerSample, StarTrackerSample, Status,
    TruthSample,
};
use msgs::{Channel, Record};
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Settings of one bench run.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    /// Output directory.
    pub out: PathBuf,
    /// The system configuration whose directory (filter, scenarios, sensors) is copied.
    pub config: PathBuf,
    /// Directory of the driver and daemon binaries.
    pub bin_dir: PathBuf,
    /// Service prefix (unique per run).
    pub prefix: String,
    /// Quick mode (for tests): short runs, same figures.
    pub quick: bool,
}

/// Wall seconds of each live latency run, simulated seconds of the offline run, wall seconds
/// of the paced recorder run.
struct Sizes {
    /// Wall seconds of the live runs at one rate, over all their slices: each slice has its
    /// own [`BENCH_ALIGNMENT_S`] on top of its share of the rest, rounded up to whole seconds
    /// (three slices of 11 s for 30 s).
    live_s: f64,
    /// Seconds of each floor run: as long as the live run's measured part, but 1 s in quick
    /// mode (tests), where the comparison is a smoke check.
    floor_s: f64,
    offline_s: f64,
    /// Simulated seconds of the replayed drive.
    replay_s: f64,
    record_paced_s: f64,
    record_saturated: usize,
    /// Slices the floor and the live run alternate in at each rate: a noisy spell of the
    /// machine (a virtual machine's host takes tens of seconds of it at a time) then falls on
    /// both rather than on whichever ran through it, and the ratio of their percentiles
    /// measures Sextant rather than the spell.
    slices: usize,
}

impl Sizes {
    fn of(quick: bool) -> Self {
        if quick {
            Sizes {
                live_s: 4.0,
                floor_s: 1.0,
                offline_s: 60.0,
                replay_s: 130.0,
                record_paced_s: 1.0,
                record_saturated: 50_000,
                slices: 2,
            }
        } else {
            Sizes {
                live_s: 30.0,
                floor_s: 30.0 - BENCH_ALIGNMENT_S,
                offline_s: 600.0,
                replay_s: 600.0,
                record_paced_s: 5.0,
                record_saturated: 500_000,
                slices: 3,
            }
        }
    }
}

/// Filter alignment time used by the live runs, s (shortened; see the module comment).
const BENCH_ALIGNMENT_S: f64 = 1.0;
/// Wall time from starting the processes to the first sample, s.
const START_DELAY_S: f64 = 1.0;

fn copy_dir(from: &Path, to: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(to).with_context(|| format!("create {}", to.display()))?;
    for e in std::fs::read_dir(from).with_context(|| format!("read {}", from.display()))? {
        let e = e?;
        let p = e.path();
        if p.is_dir() {
            copy_dir(&p, &to.join(e.file_name()))?;
        } else {
            std::fs::copy(&p, to.join(e.file_name()))
                .with_context(|| format!("copy {}", p.display()))?;
        }
    }
    Ok(())
}

/// Set `table.key = value` in a TOML file.
fn toml_set(path: &Path, table: Option<&str>, key: &str, value: toml::Value) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(path).with_context(|| format!("read {}", path.display()))?;
    let mut doc: toml::Table =
        toml::from_str(&text).with_context(|| format!("parse {}", path.display()))?;
    let t = match table {
        Some(name) => doc
            .get_mut(name)
            .and_then(|v| v.as_table_mut())
            .with_context(|| format!("no [{name}] in {}", path.display()))?,
        None => &mut doc,
    };
    t.insert(key.into(), value);
    std::fs::write(path, toml::to_string(&doc)?)
        .with_context(|| format!("write {}", path.display()))?;
    Ok(())
}

/// CPU time (user + system, s) and resident memory (current, peak; KiB) of a process.
#[derive(Debug, Clone, Copy, Default)]
struct ProcSample {
    cpu_s: f64,
    rss_kib: u64,
    hwm_kib: u64,
}

fn proc_sample(pid: u32) -> Option<ProcSample> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // Fields after the command name (which may contain spaces) start after the last ')'.
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    // utime and stime are fields 14 and 15 of stat(5), i.e. 11 and 12 after the name.
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    // /proc reports in USER_HZ clock ticks, fixed at 100 by the Linux ABI on every architecture
    // Sextant targets (sysconf(_SC_CLK_TCK)).
    let hz = 100.0;
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let kib = |key: &str| {
        status
            .lines()
            .find(|l| l.starts_with(key))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|v| v.parse().ok())
            .unwrap_or(0)
    };
    Some(ProcSample {
        cpu_s: ticks / hz,
        rss_kib: kib("VmRSS:"),
        hwm_kib: kib("VmHWM:"),
    })
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let k = ((p / 100.0) * (sorted.len() - 1) as f64).round() as usize;
    sorted[k.min(sorted.len() - 1)]
}

fn stop(child: &mut Child, timeout: Duration) {
    let pid = nix::unistd::Pid::from_raw(child.id() as i32);
    let _ = nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM);
    let t0 = Instant::now();
    while t0.elapsed() < timeout {
        if let Ok(Some(_)) = child.try_wait() {
            return;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let _ = child.kill();
    let _ = child.wait();
}

/// Latencies of every solution in a recording, µs. Transport = the IMU record's reception
/// time on CLOCK_MONOTONIC (from its MCAP publish time) − the IMU sample's send time: iceoryx2
/// delivery and the daemon's wake-up. Processing = the solution's send time − that receive
/// time: the filter step and the recorder hand-off. Each solution is also sorted by whether
/// another simulated driver (aiding or truth) sent a sample near its IMU sample's send
/// ([`BESIDE_OTHER_DRIVERS`]): those drivers compute their sample from the world model in the
/// 2 ms before they send it and share the machine's cores with the IMU driver and the daemon.
/// Also the span of simulated time the solutions cover, s (first to last solution's time of
/// validity; 0 without solutions).
fn latencies_and_span(recording: &Path) -> anyhow::Result<(LatencySeries, f64)> {
    // The project's reader: bounded on corrupt input, errors name the byte offset.
    let rec = Recording::open(recording)?;
    let mut received: std::collections::HashMap<u64, u64> = std::collections::HashMap::new();
    let mut series = LatencySeries::default();
    // (IMU send time, total latency) of each solution, and the other drivers' send times.
    let mut solutions: Vec<(u64, f64)> = Vec::new();
    let mut other_sends: Vec<u64> = Vec::new();
    let (mut first_ns, mut last_ns) = (i64::MAX, i64::MIN);
    for e in rec {
        let e = e?;
        match e.record {
            Some(Record::Imu(imu)) => {
                received.insert(imu.header.send_mono_ns, e.receive_mono_ns);
            }
            Some(Record::Nav(nav))
                if nav.imu_send_mono_ns > 0 && nav.header.send_mono_ns >= nav.imu_send_mono_ns =>
            {
                first_ns = first_ns.min(nav.header.time_ns);
                last_ns = last_ns.max(nav.header.time_ns);
                let total = (nav.header.send_mono_ns - nav.imu_send_mono_ns) as f64 * 1e-3;
                series.total.push(total);
                solutions.push((nav.imu_send_mono_ns, total));
                if let Some(&rx) = received.get(&nav.imu_send_mono_ns)
                    && rx >= nav.imu_send_mono_ns
                    && nav.header.send_mono_ns >= rx
                {
                    series
                        .transport
                        .push((rx - nav.imu_send_mono_ns) as f64 * 1e-3);
                    series
                        .processing
                        .push((nav.header.send_mono_ns - rx) as f64 * 1e-3);
                }
            }
            Some(Record::StarTracker(m)) => other_sends.push(m.header.send_mono_ns),
            Some(Record::Gnss(m)) => other_sends.push(m.header.send_mono_ns),
            Some(Record::Odometer(m)) => other_sends.push(m.header.send_mono_ns),
            Some(Record::Baro(m)) => other_sends.push(m.header.send_mono_ns),
            Some(Record::Truth(m)) => other_sends.push(m.header.send_mono_ns),
            _ => {}
        }
    }
    other_sends.sort_unstable();
    let (before, after) = BESIDE_OTHER_DRIVERS;
    for (imu_send, total) in solutions {
        let from = imu_send.saturating_sub(before.as_nanos() as u64);
        let k = other_sends.partition_point(|&t| t < from);
        let beside = other_sends
            .get(k)
            .is_some_and(|&t| t <= imu_send + after.as_nanos() as u64);
        if beside {
            series.beside_other_drivers.push(total);
        } else {
            series.apart_from_other_drivers.push(total);
        }
    }
    let span_s = if last_ns > first_ns {
        (last_ns - first_ns) as f64 * 1e-9
    } else {
        0.0
    };
    Ok((series, span_s))
}

/// A solution is "beside" the other simulated drivers when one of them sent a sample from this
/// long before its IMU sample's send to this long after (the drivers' work per sample, from
/// their CPU time: up to ≈ 2 ms for a GNSS epoch, ≈ 0.1–0.5 ms for the others).
const BESIDE_OTHER_DRIVERS: (Duration, Duration) =
    (Duration::from_millis(3), Duration::from_millis(1));

/// Latencies of a live run's solutions, µs.
#[derive(Debug, Default)]
struct LatencySeries {
    /// IMU sample sent → solution sent.
    total: Vec<f64>,
    /// IMU sample sent → received by the daemon.
    transport: Vec<f64>,
    /// Received by the daemon → solution sent.
    processing: Vec<f64>,
    /// Total, of the solutions no other simulated driver sent a sample near.
    apart_from_other_drivers: Vec<f64>,
    /// Total, of the others.
    beside_other_drivers: Vec<f64>,
}

/// What one slice of the live run at a rate measured ([`live_slice`]).
struct LiveSlice {
    series: LatencySeries,
    /// Simulated time its solutions span (first to last), s.
    span_s: f64,
    /// Its recording's size on disk, bytes.
    bytes: u64,
    /// Its drivers' simulated duration, s.
    duration_s: f64,
    /// Per process: its name, CPU seconds over the measured window, and at the window's end
    /// its resident and peak resident memory, KiB.
    procs: Vec<(String, f64, u64, u64)>,
    /// The measured window, wall s.
    window_s: f64,
}

/// The file of a slice of a bench run: `{stem}.{ext}` for the first, `{stem}_slice{n}.{ext}`
/// for the n-th after it.
fn slice_file(stem: &str, slice: usize, ext: &str) -> String {
    match slice {
        0 => format!("{stem}.{ext}"),
        k => format!("{stem}_slice{}.{ext}", k + 1),
    }
}

/// Slice `slice` (from 0) of the live run at `imu_hz`: the daemon and every simulated driver
/// for `duration_s` of wall time (its short alignment included).
fn live_slice(
    opts: &BenchOptions,
    cfg_dir: &Path,
    imu_hz: f64,
    duration_s: f64,
    slice: usize,
) -> anyhow::Result<LiveSlice> {
    let scenario = cfg_dir.join(format!("scenarios/bench_imu_{}hz.toml", imu_hz as u64));
    std::fs::copy(cfg_dir.join("scenarios/vehicle.toml"), &scenario)?;
    toml_set(
        &scenario,
        Some("imu"),
        "rate_hz",
        toml::Value::Float(imu_hz),
    )?;
    let prefix = format!("{}_{}hz_{slice}", opts.prefix, imu_hz as u64);
    let recording = opts.out.join(slice_file(
        &format!("latency_{}hz", imu_hz as u64),
        slice,
        "mcap",
    ));
    let _ = std::fs::remove_file(&recording);
    let logs = opts.out.join("logs");
    std::fs::create_dir_all(&logs)?;
    let log = |name: &str| -> anyhow::Result<std::fs::File> {
        Ok(std::fs::File::create(logs.join(slice_file(
            &format!("{name}_{}hz", imu_hz as u64),
            slice,
            "log",
        )))?)
    };
    let mut fusion = Command::new(opts.bin_dir.join("sextant-fusion"))
        .arg("--config")
        .arg(cfg_dir.join("sextant.toml"))
        .args(["--prefix", &prefix, "--speed", "1", "--out"])
        .arg(&recording)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(log("sextant-fusion")?)
        .spawn()
        .context("start sextant-fusion")?;
    let start_mono_ns = msgs::monotonic_ns() + (START_DELAY_S * 1e9) as u64;
    let drivers =
        drivers_sim::driver::SimDriver::ALL.map(drivers_sim::driver::SimDriver::process_name);
    let mut children: Vec<(String, Child)> = Vec::new();
    for d in drivers {
        let c = Command::new(opts.bin_dir.join(d))
            .arg("--scenario")
            .arg(&scenario)
            .args(["--prefix", &prefix, "--speed", "1"])
            .args(["--start-mono-ns", &start_mono_ns.to_string()])
            .args(["--duration", &duration_s.to_string()])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(log(d)?)
            .spawn()
            .with_context(|| format!("start {d}"));
        match c {
            Ok(c) => children.push((d.to_string(), c)),
            Err(e) => {
                for (_, c) in &mut children {
                    stop(c, Duration::from_secs(2));
                }
                stop(&mut fusion, Duration::from_secs(5));
                return Err(e);
            }
        }
    }
    // CPU window: from the first sample + 0.5 s to 0.5 s before the drivers' end.
    let t_first = Instant::now() + Duration::from_secs_f64(START_DELAY_S);
    std::thread::sleep(Duration::from_secs_f64(START_DELAY_S + 0.5));
    let pids: Vec<(String, u32)> = std::iter::once(("sextant-fusion".to_string(), fusion.id()))
        .chain(children.iter().map(|(n, c)| (n.clone(), c.id())))
        .collect();
    let first: Vec<Option<ProcSample>> = pids.iter().map(|(_, p)| proc_sample(*p)).collect();
    let t_a = Instant::now();
    let end = t_first + Duration::from_secs_f64(duration_s - 0.5);
    std::thread::sleep(end.saturating_duration_since(Instant::now()));
    let last: Vec<Option<ProcSample>> = pids.iter().map(|(_, p)| proc_sample(*p)).collect();
    let window_s = t_a.elapsed().as_secs_f64();
    // Let the drivers finish, then stop the daemon (which finishes the recording).
    let t_wait = Instant::now();
    for (name, c) in &mut children {
        loop {
            match c.try_wait()? {
                Some(st) if !st.success() => tracing::warn!("{name} exited with {st}"),
                Some(_) => {}
                None if t_wait.elapsed() < Duration::from_secs(10) => {
                    std::thread::sleep(Duration::from_millis(20));
                    continue;
                }
                None => stop(c, Duration::from_secs(2)),
            }
            break;
        }
    }
    std::thread::sleep(Duration::from_millis(200));
    stop(&mut fusion, Duration::from_secs(10));
    let procs = (pids.iter().zip(first.iter().zip(&last)))
        .filter_map(|((name, _), (a, b))| {
            let (a, b) = (a.as_ref()?, b.as_ref()?);
            Some((name.clone(), b.cpu_s - a.cpu_s, b.rss_kib, b.hwm_kib))
        })
        .collect();
    let (series, span_s) = latencies_and_span(&recording)?;
    if series.total.is_empty() {
        bail!(
            "no solution in {} (see {})",
            recording.display(),
            logs.display()
        );
    }
    Ok(LiveSlice {
        series,
        span_s,
        bytes: crate::recording::recording_len(&recording),
        duration_s,
        procs,
        window_s,
    })
}

/// The slices of the live run at one rate as one run: (latencies µs, sorted; per-process
/// figures, with `navigating_s`, `recording` and `latency_split`).
fn combine_live(slices: Vec<LiveSlice>) -> (Vec<f64>, Value) {
    let mut series = LatencySeries::default();
    let (mut span_s, mut bytes, mut duration_s) = (0.0, 0u64, 0.0);
    // Per process: CPU s and the windows it was measured over, s (a process whose /proc
    // entry could not be read in a slice is left out of that slice), resident KiB at the
    // last such window's end, peak KiB over them.
    let mut cpu: Vec<(String, f64, f64, u64, u64)> = Vec::new();
    for sl in slices {
        for (all, part) in [
            (&mut series.total, sl.series.total),
            (&mut series.transport, sl.series.transport),
            (&mut series.processing, sl.series.processing),
            (
                &mut series.apart_from_other_drivers,
                sl.series.apart_from_other_drivers,
            ),
            (
                &mut series.beside_other_drivers,
                sl.series.beside_other_drivers,
            ),
        ] {
            all.extend(part);
        }
        span_s += sl.span_s;
        bytes += sl.bytes;
        duration_s += sl.duration_s;
        for (name, cpu_s, rss, hwm) in sl.procs {
            match cpu.iter_mut().find(|p| p.0 == name) {
                Some(p) => {
                    p.1 += cpu_s;
                    p.2 += sl.window_s;
                    p.3 = rss;
                    p.4 = p.4.max(hwm);
                }
                None => cpu.push((name, cpu_s, sl.window_s, rss, hwm)),
            }
        }
    }
    let mut procs = serde_json::Map::new();
    for (name, cpu_s, window_s, rss, hwm) in cpu {
        procs.insert(
            name,
            json!({
                "cpu_percent": 100.0 * cpu_s / window_s,
                "rss_mib": rss as f64 / 1024.0,
                "peak_rss_mib": hwm as f64 / 1024.0,
            }),
        );
    }
    // How long it navigated: the alignment ends when its window is complete and a GNSS fix
    // is `buffer_window_s` old, not at a fixed time.
    procs.insert("navigating_s".into(), json!(span_s));
    // The recording's size per 600 s of operation (the default run's length), in the
    // configuration's encoding: the slices' files scaled by their simulated duration.
    procs.insert(
        "recording".into(),
        json!({
            "bytes": bytes,
            "duration_s": duration_s,
            "mb_per_600s": bytes as f64 / 1e6 * 600.0 / duration_s,
        }),
    );
    for v in [
        &mut series.total,
        &mut series.transport,
        &mut series.processing,
        &mut series.apart_from_other_drivers,
        &mut series.beside_other_drivers,
    ] {
        v.sort_by(f64::total_cmp);
    }
    let part = |v: &[f64]| {
        json!({
            "solutions": v.len(),
            "latency_p50_us": percentile(v, 50.0),
            "latency_p99_us": percentile(v, 99.0),
        })
    };
    procs.insert(
        "latency_split".into(),
        json!({
            "transport_p50_us": percentile(&series.transport, 50.0),
            "transport_p99_us": percentile(&series.transport, 99.0),
            "processing_p50_us": percentile(&series.processing, 50.0),
            "processing_p99_us": percentile(&series.processing, 99.0),
            "apart_from_other_drivers": part(&series.apart_from_other_drivers),
            "beside_other_drivers": part(&series.beside_other_drivers),
            "beside_window_ms": [
                BESIDE_OTHER_DRIVERS.0.as_secs_f64() * 1e3,
                BESIDE_OTHER_DRIVERS.1.as_secs_f64() * 1e3,
            ],
        }),
    );
    (series.total, Value::Object(procs))
}

fn latency_figures(lat: &[f64], imu_hz: f64, duration_s: f64) -> Value {
    json!({
        "imu_rate_hz": imu_hz,
        "solutions": lat.len(),
        "solutions_per_s": lat.len() as f64 / duration_s,
        "latency_p50_us": percentile(lat, 50.0),
        "latency_p99_us": percentile(lat, 99.0),
        "latency_p99_9_us": percentile(lat, 99.9),
        "latency_max_us": lat.last().copied().unwrap_or(f64::NAN),
        "latency_mean_us": lat.iter().sum::<f64>() / lat.len().max(1) as f64,
    })
}

/// Offline throughput: the navigator over a pre-generated message stream with every aiding
/// sensor of the vehicle scenario.
fn offline_throughput(cfg_dir: &Path, sim_s: f64) -> anyhow::Result<Value> {
    let cfg = crate::config::load(&cfg_dir.join("sextant.toml"))?;
    let scn = Scenario::load(&cfg_dir.join("scenarios/vehicle.toml"))?;
    let msgs: Vec<Record> = OfflineSim::with_channels(&scn, &Channel::SENSORS)
        .with_duration_s(sim_s)
        .collect();
    let mut nav = Navigator::new(cfg.navigator.clone())?;
    let mut imu_all = 0u64;
    let mut imu_nav = 0u64;
    let mut t_nav_start: Option<(Instant, i64)> = None;
    let mut last_t = 0i64;
    let mut rejected = 0u64;
    let t0 = Instant::now();
    for m in &msgs {
        let r = feed(&mut nav, m);
        if let Record::Imu(s) = m {
            imu_all += 1;
            if nav.is_navigating() {
                if t_nav_start.is_none() {
                    t_nav_start = Some((Instant::now(), s.header.time_ns));
                } else {
                    imu_nav += 1;
                }
                last_t = s.header.time_ns;
            }
        }
        if r.is_err() {
            rejected += 1;
        }
    }
    let total_s = t0.elapsed().as_secs_f64();
    let (t_nav, sim0) = t_nav_start.context("the offline run never finished its alignment")?;
    let nav_wall_s = t_nav.elapsed().as_secs_f64();
    let nav_sim_s = (last_t - sim0) as f64 * 1e-9;
    let imu_hz = scn.spec.imu.rate_hz;
    Ok(json!({
        "scenario": "vehicle",
        "imu_rate_hz": imu_hz,
        "simulated_s": sim_s,
        "messages": msgs.len(),
        "rejected_inputs": rejected,
        "navigating_imu_samples": imu_nav,
        "navigating_imu_samples_per_s": imu_nav as f64 / nav_wall_s,
        "navigating_x_real_time": nav_sim_s / nav_wall_s,
        "whole_run_imu_samples_per_s": imu_all as f64 / total_s,
        "whole_run_x_real_time": sim_s / total_s,
        "wall_s": total_s,
        // The delayed fusion's extra work: late samples (the car's odometer and star tracker
        // 10 ms, its receiver 50 ms) rewind the filter and replay the IMU steps since.
        "rewinds": nav.diagnostics().rewinds,
        "replayed_imu_steps": nav.diagnostics().replayed_imu_steps,
    }))
}

/// Replays timed per leg of the replay bench: the figure is their median.
const REPLAY_RUNS: usize = 5;

/// The replay stage of `replay --offline` (see the module comment) with the filter
/// configuration `filter` on the vehicle scenario of `cfg_dir`, simulated for `sim_s`, the
/// drive recorded at the rates of `recorder` (the configuration's: the replay then writes its
/// solutions at the same rate, as it would for a recording of `sextant run`).
fn replay_throughput(
    out: &Path,
    cfg_dir: &Path,
    filter: &fusion::navigator::NavigatorConfig,
    recorder: &crate::config::RecorderSection,
    sim_s: f64,
) -> anyhow::Result<Value> {
    use crate::interchange::kfgins;
    use crate::recorder::{CONFIG_KEY_FILTER_TOML, CONFIG_METADATA_NAME};
    use crate::replay::{OfflineOptions, replay_offline};
    let scn = Scenario::load(&cfg_dir.join("scenarios/vehicle.toml"))?;
    let dir = out.join("replay");
    std::fs::create_dir_all(&dir)?;
    let source = dir.join("drive.mcap");
    let rec = Recorder::start(
        &source,
        &RecorderOptions {
            metadata: vec![(
                CONFIG_METADATA_NAME.to_string(),
                [(CONFIG_KEY_FILTER_TOML.to_string(), toml::to_string(filter)?)].into(),
            )],
            solution_rate_hz: recorder.solution_rate_hz,
            truth_rate_hz: recorder.truth_rate_hz,
            view_rate_hz: recorder.view_rate_hz,
            queue_capacity: OFFLINE_QUEUE,
            ..Default::default()
        },
    )?;
    let channels = [Channel::SENSORS.as_slice(), &[Channel::Truth]].concat();
    let mut batch = rec.batched(OFFLINE_BATCH);
    for r in OfflineSim::with_channels(&scn, &channels).with_duration_s(sim_s) {
        batch.record(r, 0);
    }
    drop(batch);
    let stats = rec.finish()?;
    if stats.dropped > 0 {
        bail!(
            "the replay bench's recording dropped {} records",
            stats.dropped
        );
    }
    // One replay takes a fraction of a second, where a 2-core machine's run-to-run spread is
    // ±10 %: the figure is the median of REPLAY_RUNS, each run's kept beside it.
    let replay = |recording: &Path, name: &str| -> anyhow::Result<Value> {
        let mut runs = Vec::with_capacity(REPLAY_RUNS);
        for _ in 0..REPLAY_RUNS {
            let out_dir = dir.join(name);
            if out_dir.exists() {
                std::fs::remove_dir_all(&out_dir)?;
            }
            runs.push(replay_offline(&OfflineOptions {
                recording: recording.to_path_buf(),
                out_dir,
                config: None,
                progress: false,
                segment_duration: None,
                tap: None,
                solution_rate_hz: None,
            })?);
        }
        let rates: Vec<f64> = runs.iter().map(|s| s.imu_samples_per_s).collect();
        let mut order: Vec<usize> = (0..runs.len()).collect();
        order.sort_by(|&a, &b| rates[a].total_cmp(&rates[b]));
        let s = &runs[order[order.len() / 2]];
        // The replay records at the source's rates: the shipped ones, as the default run. The
        // last run's recording is the one left in the directory.
        let bytes: u64 = runs[runs.len() - 1]
            .replayed_segments
            .iter()
            .filter_map(|p| std::fs::metadata(p).ok())
            .map(|m| m.len())
            .sum();
        Ok(json!({
            "imu_samples": s.imu_samples,
            "solutions": s.solutions_replayed,
            "wall_s": s.wall_time_s,
            "imu_samples_per_s": s.imu_samples_per_s,
            "imu_samples_per_s_runs": rates,
            "recording_mb_per_600s": bytes as f64 / 1e6 * 600.0 / sim_s,
        }))
    };
    let every_aiding = replay(&source, "every_aiding")?;
    // The loosely coupled part through the KF-GINS files.
    let kf_dir = out.join("kfgins");
    kfgins::export(&source, &kf_dir)?;
    let lc = dir.join("loosely_coupled.mcap");
    kfgins::import(
        &kfgins::ImportFiles {
            imu: Some(kf_dir.join(kfgins::IMU_FILE)),
            gnss: Some(kf_dir.join(kfgins::GNSS_FILE)),
            truth: Some(kf_dir.join(kfgins::TRUTH_FILE)),
            week: None,
        },
        Some(&kf_dir.join(kfgins::FILTER_FILE)),
        &lc,
    )?;
    let loosely_coupled = replay(&lc, "loosely_coupled")?;
    Ok(json!({
        "simulated_s": sim_s,
        "every_aiding": every_aiding,
        "loosely_coupled": loosely_coupled,
        "kfgins_files": kf_dir.display().to_string(),
    }))
}

/// A realistic record mix for the recorder: per second of the default live system at speed 1,
/// IMU 200, solutions 200, truth 50, star tracker 5, odometer 20, baro 20, GNSS 1, status 1.
fn record_mix(k: u64) -> Record {
    let mut h = msgs::Header {
        time_ns: 1_400_000_000_000_000_000 + k as i64 * 1_000_000,
        seq: k,
        ..Default::default()
    };
    h.send_mono_ns = k;
    // 497 records per simulated second; position k within that second picks the type.
    match k % 497 {
        0..200 => Record::Imu(ImuSample {
            header: h,
            dt_s: 0.005,
            delta_angle_rad: [1.234e-7 * k as f64, -2.5e-8, 3.3e-8],
            delta_velocity_m_s: [1.0e-3, -2.0e-3, -0.049_033],
            ..Default::default()
        }),
        200..400 => Record::Nav(NavSolution {
            header: h,
            lat_rad: 0.971_3,
            lon_rad: 0.655_1,
            height_m: 200.123_456,
            pos_ecef_m: [2_846_000.123, 2_193_000.456, 5_240_000.789],
            q_ned_body: [0.9, 0.1, 0.2, 0.3],
            pos_sigma_ned_m: [0.5, 0.5, 0.8],
            ..Default::default()
        }),
        400..450 => Record::Truth(TruthSample {
            header: h,
            ..Default::default()
        }),
        450..455 => Record::StarTracker(StarTrackerSample {
            header: h,
            ..Default::default()
        }),
        455..475 => Record::Odometer(OdometerSample {
            header: h,
            ..Default::default()
        }),
        475..495 => Record::Baro(BaroSample {
            header: h,
            ..Default::default()
        }),
        495 => Record::Gnss(Box::new(GnssSample {
            header: h,
            ..Default::default()
        })),
        _ => Record::Status(Box::new(Status {
            header: h,
            ..Default::default()
        })),
    }
}

/// Live records per wall second of the default `sextant run` (speed 10).
const DEFAULT_LIVE_RECORDS_PER_S: f64 = 497.0 * 10.0;

fn recorder_throughput(out: &Path, saturated: usize, paced_s: f64) -> anyhow::Result<Value> {
    let ropts = RecorderOptions {
        queue_capacity: 16384,
        chunk_size_bytes: 1 << 20,
        flush_interval: Duration::from_secs(1),
        ..Default::default()
    };
    // Saturated: offer records as fast as possible; retry when the queue is full, so that the
    // figure is what the writer thread sustains.
    let path = out.join("recorder_saturated.mcap");
    let rec = Recorder::start(&path, &ropts)?;
    let t0 = Instant::now();
    let mut offered = 0u64;
    for k in 0..saturated as u64 {
        while !rec.record(record_mix(k), k) {
            offered += 1;
            std::thread::yield_now();
        }
    }
    let stats = rec.finish()?;
    let sat_s = t0.elapsed().as_secs_f64();
    // `written` counts MCAP messages: a solution is written three times (nav and Foxglove's
    // LocationFix and pose), so records and messages differ.
    let sat_records = saturated as f64;
    let bytes = std::fs::metadata(&path)?.len();
    let retries = offered;

    // Paced at 10x the default live load, 1 ms batches: nothing may be dropped.
    let rate = 10.0 * DEFAULT_LIVE_RECORDS_PER_S;
    let path2 = out.join("recorder_10x.mcap");
    let rec = Recorder::start(&path2, &ropts)?;
    let t0 = Instant::now();
    let n = (rate * paced_s) as u64;
    let mut k = 0u64;
    let mut accepted = 0u64;
    while k < n {
        let due = ((t0.elapsed().as_secs_f64() * rate) as u64).min(n);
        while k < due {
            accepted += u64::from(rec.record(record_mix(k), k));
            k += 1;
        }
        std::thread::sleep(Duration::from_micros(500));
    }
    let stats2 = rec.finish()?;
    let _ = std::fs::remove_file(&path);
    let _ = std::fs::remove_file(&path2);
    Ok(json!({
        "saturated_records": saturated,
        "saturated_records_per_s": sat_records / sat_s,
        "saturated_mcap_messages_per_s": stats.written as f64 / sat_s,
        "saturated_mcap_mb_per_s": bytes as f64 / 1e6 / sat_s,
        "saturated_mcap_bytes_per_record": bytes as f64 / sat_records,
        "saturated_queue_full_retries": retries,
        "default_live_records_per_s": DEFAULT_LIVE_RECORDS_PER_S,
        "paced_10x_records_per_s": rate,
        "paced_10x_records": n,
        "paced_10x_accepted": accepted,
        "paced_10x_mcap_messages": stats2.written,
        "paced_10x_dropped": stats2.dropped,
    }))
}

/// Sextant's latency against the floor's: the median's excess in µs (what the fusion daemon
/// adds per solution) and the tail's ratio (p99, p99.9).
fn vs_floor(sextant: &[f64], floor: &[f64]) -> Value {
    let p = |l: &[f64], q: f64| percentile(l, q);
    json!({
        "p50_excess_us": p(sextant, 50.0) - p(floor, 50.0),
        "p99_ratio": p(sextant, 99.0) / p(floor, 99.0),
        "p99_9_ratio": p(sextant, 99.9) / p(floor, 99.9),
        "p50_ratio": p(sextant, 50.0) / p(floor, 50.0),
    })
}

/// Latency histograms of the live runs (solid) and of the floor at the same rates (dashed).
fn histogram_png(
    path: &Path,
    runs: &[(f64, &[f64])],
    floors: &[(f64, &[f64])],
) -> anyhow::Result<()> {
    // Bins up to the largest p99.9 of the runs (the tail beyond is in the table).
    let top = runs
        .iter()
        .chain(floors)
        .map(|(_, l)| percentile(l, 99.9))
        .fold(0.0f64, f64::max)
        .max(50.0);
    let width = (top / 60.0).max(1.0);
    let nbins = (top / width).ceil() as usize + 1;
    let histogram = |lat: &[f64]| {
        let mut counts = vec![0u64; nbins];
        for &x in lat {
            let b = ((x / width) as usize).min(nbins - 1);
            counts[b] += 1;
        }
        let mut points = Vec::new();
        for (b, &c) in counts.iter().enumerate() {
            let y = c as f64 / lat.len().max(1) as f64;
            points.push((b as f64 * width, y));
            points.push(((b + 1) as f64 * width, y));
        }
        points
    };
    let mut lines: Vec<Line> = Vec::new();
    for (i, (hz, lat)) in runs.iter().enumerate() {
        lines.push(Line::solid(
            format!("Sextant, IMU {hz:.0} Hz ({} solutions)", lat.len()),
            histogram(lat),
            color(i),
        ));
    }
    for (i, (hz, lat)) in floors.iter().enumerate() {
        lines.push(Line::dashed(
            format!(
                "floor (bare iceoryx2 round trip), {hz:.0} Hz ({} replies)",
                lat.len()
            ),
            histogram(lat),
            color(i),
        ));
    }
    line_chart(
        path,
        &Chart::log_y(
            "IMU send -> solution send latency: Sextant and the bare iceoryx2 floor",
            &format!("latency, us (bins of {width:.1} us; last bin holds the tail)"),
            "fraction of solutions",
            &lines,
        ),
    )?;
    Ok(())
}

fn machine() -> Value {
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let model = cpuinfo
        .lines()
        .find(|l| l.starts_with("model name"))
        .and_then(|l| l.split(':').nth(1))
        .map(|s| s.trim().to_string())
        .unwrap_or_else(|| "unknown".into());
    let nproc = std::thread::available_parallelism().map_or(0, |n| n.get());
    let mem = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|m| {
            m.lines()
                .find(|l| l.starts_with("MemTotal:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|v| v.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |k| k / 1024.0 / 1024.0);
    json!({ "nproc": nproc, "cpu_model": model, "mem_total_gib": mem })
}

/// Run the bench; writes `summary.json` and `latency_histogram.png` into `opts.out`.
pub fn run(opts: &BenchOptions) -> anyhow::Result<Value> {
    let sizes = Sizes::of(opts.quick);
    std::fs::create_dir_all(&opts.out).with_context(|| format!("create {}", opts.out.display()))?;
    // A private copy of the configuration with the short alignment.
    let cfg_dir = opts.out.join("config");
    let _ = std::fs::remove_dir_all(&cfg_dir);
    match opts.config.parent() {
        Some(dir) if opts.config.is_file() => copy_dir(dir, &cfg_dir)?,
        _ => {
            crate::config::materialize_embedded(&cfg_dir)?;
        }
    }
    let cfg = crate::config::load(&cfg_dir.join("sextant.toml"))?;
    toml_set(
        &cfg.filter_path,
        None,
        "alignment_s",
        toml::Value::Float(BENCH_ALIGNMENT_S),
    )?;
    // Every solution recorded: the latencies are read from each solution's stamps (a recording
    // at the shipped 10 Hz would hold only the solutions at whole 100 ms, the instants where
    // the odometer, baro and GNSS updates fall, and overstate them).
    toml_set(
        &cfg_dir.join("sextant.toml"),
        Some("recorder"),
        "solution_rate_hz",
        toml::Value::Float(0.0),
    )?;

    let mut runs: Vec<(f64, Vec<f64>)> = Vec::new();
    let mut live = serde_json::Map::new();
    let mut floors: Vec<(f64, Vec<f64>)> = Vec::new();
    let logs = opts.out.join("logs");
    std::fs::create_dir_all(&logs)?;
    for hz in [200.0, 1000.0] {
        // The floor and the live run alternate in slices (`Sizes::slices`).
        let n = sizes.slices;
        let floor_slice_s = sizes.floor_s / n as f64;
        // Whole seconds: the drivers stop after their last sample at or before the end, and
        // the CPU window closes 0.5 s before it, after the 1 Hz GNSS driver's last sample.
        let live_slice_s =
            (BENCH_ALIGNMENT_S + (sizes.live_s - BENCH_ALIGNMENT_S) / n as f64).ceil();
        let mut fl = floor::FloorRun::default();
        let mut slices = Vec::new();
        for k in 0..n {
            eprintln!(
                "bench: floor, IMU {hz} Hz, {floor_slice_s:.1} s (slice {} of {n})",
                k + 1
            );
            let floor_prefix = format!("{}_floor_{}hz_{k}", opts.prefix, hz as u64);
            fl.append(floor::run(
                &opts.bin_dir,
                &floor_prefix,
                hz,
                floor_slice_s,
                &logs,
            )?);
            eprintln!(
                "bench: live run, IMU {hz} Hz, {live_slice_s:.1} s (slice {} of {n})",
                k + 1
            );
            slices.push(live_slice(opts, &cfg_dir, hz, live_slice_s, k)?);
        }
        let (lat, procs) = combine_live(slices);
        let mut procs = procs;
        let measured_s = procs
            .as_object_mut()
            .and_then(|m| m.remove("navigating_s"))
            .and_then(|v| v.as_f64())
            .unwrap_or(0.0);
        let mut fig = latency_figures(&lat, hz, measured_s);
        fig["navigating_s"] = json!(measured_s);
        fig["processes"] = procs;
        if let Some(split) = fig["processes"]
            .as_object_mut()
            .and_then(|m| m.remove("latency_split"))
        {
            fig["latency_split"] = split;
        }
        if let Some(r) = fig["processes"]
            .as_object_mut()
            .and_then(|m| m.remove("recording"))
        {
            fig["recording"] = r;
        }
        let mut ff = latency_figures(&fl.latencies_us, hz, sizes.floor_s);
        ff["sent"] = json!(fl.sent);
        ff["echo_cpu_percent"] = json!(fl.echo_cpu_percent);
        ff["echo_peak_rss_mib"] = json!(fl.echo_peak_rss_mib);
        fig["vs_floor"] = vs_floor(&lat, &fl.latencies_us);
        fig["floor"] = ff;
        live.insert(format!("imu_{}hz", hz as u64), fig);
        runs.push((hz, lat));
        floors.push((hz, fl.latencies_us));
    }
    eprintln!("bench: Zenoh bridge, {} s", sizes.floor_s);
    let br = bridge::run(
        &opts.bin_dir,
        &format!("{}_bridge", opts.prefix),
        sizes.floor_s,
        &logs,
    )?;
    let mut bridge_fig = latency_figures(&br.latencies_us, bridge::RATE_HZ, sizes.floor_s);
    bridge_fig["sent"] = json!(br.sent);
    bridge_fig["lost"] = json!(br.sent.saturating_sub(br.latencies_us.len() as u64));
    let floor_200 = &live["imu_200hz"]["floor"];
    bridge_fig["p50_over_floor_us"] = json!(
        percentile(&br.latencies_us, 50.0)
            - floor_200["latency_p50_us"].as_f64().unwrap_or(f64::NAN)
    );
    eprintln!("bench: offline fusion, {} s simulated", sizes.offline_s);
    let offline = offline_throughput(&cfg_dir, sizes.offline_s)?;
    eprintln!("bench: replay, {} s simulated", sizes.replay_s);
    // The filter as configured (its own alignment), not the live runs' short one: the
    // replayed drive navigates as the default run does.
    // At the configuration's recording rates, read before the live runs' copy was set to
    // record every solution.
    let replay = replay_throughput(
        &opts.out,
        &cfg_dir,
        &cfg.navigator,
        &cfg.system.recorder,
        sizes.replay_s,
    )?;
    eprintln!("bench: recorder");
    let recorder = recorder_throughput(&opts.out, sizes.record_saturated, sizes.record_paced_s)?;
    eprintln!("bench: cost curves");
    // The configuration as the live runs read it (with the short alignment).
    let bench_cfg = crate::config::load(&cfg_dir.join("sextant.toml"))?;
    let curves = cost::run(&cfg_dir, &bench_cfg.navigator, opts.quick)?;
    let curves_png = opts.out.join("cost_curves.png");
    if let Err(e) = cost::png(&curves_png, &curves) {
        tracing::warn!("cost curves: {e}");
    }
    let hist: Vec<(f64, &[f64])> = runs.iter().map(|(h, l)| (*h, l.as_slice())).collect();
    let hist_floor: Vec<(f64, &[f64])> = floors.iter().map(|(h, l)| (*h, l.as_slice())).collect();
    let png = opts.out.join("latency_histogram.png");
    if let Err(e) = histogram_png(&png, &hist, &hist_floor) {
        tracing::warn!("histogram: {e}");
    }
    let l1k = &live["imu_1000hz"];
    let fusion_rss = live
        .values()
        .filter_map(|v| v["processes"]["sextant-fusion"]["peak_rss_mib"].as_f64())
        .fold(0.0f64, f64::max);
    let targets = json!({
        "latency_p50_us_at_1khz": { "target": 30.0, "measured": l1k["latency_p50_us"] },
        "latency_p99_us_at_1khz": { "target": 100.0, "measured": l1k["latency_p99_us"] },
        "offline_x_real_time_all_aiding": { "target": 1000.0, "measured": offline["navigating_x_real_time"] },
        "replay_imu_samples_per_s_all_aiding": { "target": 500000.0, "measured": replay["every_aiding"]["imu_samples_per_s"] },
        "fusion_peak_rss_mib": { "target": 30.0, "measured": fusion_rss },
        "recorder_10x_dropped": { "target": 0, "measured": recorder["paced_10x_dropped"] },
        "recording_mb_per_600s_at_200hz": {
            "what": "the replayed drive's recording at the shipped rates (inputs and truth in full, solutions and views at 10 Hz), scaled to 600 s; the live runs record every solution (the bench times each one): live.*.recording",
            "target": 16.0,
            "measured": replay["every_aiding"]["recording_mb_per_600s"],
        },
    });
    let summary = json!({
        "machine": machine(),
        "quick": opts.quick,
        "live": Value::Object(live),
        "offline": offline,
        "replay": replay,
        "recorder": recorder,
        "bridge": bridge_fig,
        "cost_curves": curves,
        "targets": targets,
        "histogram_png": png.display().to_string(),
        "cost_curves_png": curves_png.display().to_string(),
    });
    std::fs::write(
        opts.out.join("summary.json"),
        serde_json::to_string_pretty(&summary)? + "\n",
    )?;
    Ok(summary)
}

/// "lowest–highest" of a list of rates (IMU samples/s), "—" without one.
fn runs_range(v: &Value) -> String {
    let rates: Vec<f64> = v
        .as_array()
        .map(|a| a.iter().filter_map(Value::as_f64).collect())
        .unwrap_or_default();
    let lo = rates.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = rates.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if rates.is_empty() {
        "—".into()
    } else {
        format!("{lo:.0}–{hi:.0} over the runs")
    }
}

/// The bench's table.
pub fn table(s: &Value) -> String {
    let f = |v: &Value| v.as_f64().map_or("—".into(), |x| format!("{x:.1}"));
    let mut t = String::new();
    t += &format!(
        "machine: {} x {}\n",
        s["machine"]["nproc"],
        s["machine"]["cpu_model"].as_str().unwrap_or("?")
    );
    t += "IMU rate | run     | solutions | p50 us | p99 us | p99.9 us | max us | CPU % (fusion/echo) | RSS MiB (fusion/echo)\n";
    for key in ["imu_200hz", "imu_1000hz"] {
        let r = &s["live"][key];
        t += &format!(
            "{:>6} Hz | Sextant | {:>9} | {:>6} | {:>6} | {:>8} | {:>6} | {:>19} | {:>21}\n",
            r["imu_rate_hz"].to_string(),
            r["solutions"].to_string(),
            f(&r["latency_p50_us"]),
            f(&r["latency_p99_us"]),
            f(&r["latency_p99_9_us"]),
            f(&r["latency_max_us"]),
            f(&r["processes"]["sextant-fusion"]["cpu_percent"]),
            f(&r["processes"]["sextant-fusion"]["peak_rss_mib"]),
        );
        let fl = &r["floor"];
        t += &format!(
            "{:>6} Hz | floor   | {:>9} | {:>6} | {:>6} | {:>8} | {:>6} | {:>19} | {:>21}\n",
            r["imu_rate_hz"].to_string(),
            fl["solutions"].to_string(),
            f(&fl["latency_p50_us"]),
            f(&fl["latency_p99_us"]),
            f(&fl["latency_p99_9_us"]),
            f(&fl["latency_max_us"]),
            f(&fl["echo_cpu_percent"]),
            f(&fl["echo_peak_rss_mib"]),
        );
    }
    t += "Sextant against the floor (bare iceoryx2 round trip between two processes, same run):\n";
    for key in ["imu_200hz", "imu_1000hz"] {
        let r = &s["live"][key];
        let v = &r["vs_floor"];
        t += &format!(
            "  {} Hz: p50 +{} us over the floor, p99 x{:.2}, p99.9 x{:.2}\n",
            r["imu_rate_hz"],
            f(&v["p50_excess_us"]),
            v["p99_ratio"].as_f64().unwrap_or(f64::NAN),
            v["p99_9_ratio"].as_f64().unwrap_or(f64::NAN),
        );
    }
    t += "Sextant's latency apart from / beside the other simulated drivers' sends (another \
          driver sent a sample from 3 ms before to 1 ms after the IMU sample; they share the \
          cores):\n";
    for key in ["imu_200hz", "imu_1000hz"] {
        let r = &s["live"][key];
        let (a, b) = (
            &r["latency_split"]["apart_from_other_drivers"],
            &r["latency_split"]["beside_other_drivers"],
        );
        t += &format!(
            "  {} Hz: apart p50 {} us, p99 {} us ({} solutions); beside p50 {} us, p99 {} us \
             ({} solutions)\n",
            r["imu_rate_hz"],
            f(&a["latency_p50_us"]),
            f(&a["latency_p99_us"]),
            a["solutions"],
            f(&b["latency_p50_us"]),
            f(&b["latency_p99_us"]),
            b["solutions"],
        );
    }
    let b = &s["bridge"];
    t += &format!(
        "Zenoh bridge (bus -> sextant-bridge -> TCP loopback -> sextant-bridge -> bus, {} Hz): p50 {} us, p99 {} us, p99.9 {} us, max {} us, {} of {} lost\n",
        b["imu_rate_hz"],
        f(&b["latency_p50_us"]),
        f(&b["latency_p99_us"]),
        f(&b["latency_p99_9_us"]),
        f(&b["latency_max_us"]),
        b["lost"],
        b["sent"]
    );
    let o = &s["offline"];
    t += &format!(
        "offline fusion (all aiding, {} Hz IMU): {} IMU samples/s, {} x real time; {} rewinds \
         for late samples replayed {} IMU steps again\n",
        o["imu_rate_hz"],
        f(&o["navigating_imu_samples_per_s"]),
        f(&o["navigating_x_real_time"]),
        o["rewinds"],
        o["replayed_imu_steps"]
    );
    let rp = &s["replay"];
    t += &format!(
        "replay --offline (reading, filter, writing; {} s drive; median of {}): every aiding {} \
         IMU samples/s ({}), loosely coupled (IMU + GNSS fixes via the KF-GINS files) {} IMU \
         samples/s; KF-GINS on the same files: cd {} && KF-GINS kf-gins.yaml\n",
        rp["simulated_s"],
        REPLAY_RUNS,
        f(&rp["every_aiding"]["imu_samples_per_s"]),
        runs_range(&rp["every_aiding"]["imu_samples_per_s_runs"]),
        f(&rp["loosely_coupled"]["imu_samples_per_s"]),
        rp["kfgins_files"].as_str().unwrap_or("?"),
    );
    let r = &s["recorder"];
    t += &format!(
        "recorder: {} records/s, {} MB/s MCAP saturated; 10x live load ({} records/s): {} dropped\n",
        f(&r["saturated_records_per_s"]),
        f(&r["saturated_mcap_mb_per_s"]),
        f(&r["paced_10x_records_per_s"]),
        r["paced_10x_dropped"]
    );
    t += &cost::table(&s["cost_curves"]);
    t += "targets:\n";
    if let Some(m) = s["targets"].as_object() {
        for (k, v) in m {
            t += &format!(
                "  {k}: target {} measured {}\n",
                v["target"],
                f(&v["measured"])
            );
        }
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_range_names_the_lowest_and_highest() {
        assert_eq!(
            runs_range(&json!([510000.4, 470000.0, 498000.0])),
            "470000–510000 over the runs"
        );
        assert_eq!(runs_range(&json!([])), "—");
        assert_eq!(runs_range(&Value::Null), "—");
    }

    /// Latencies come back from the recording through the project's reader: transport =
    /// receive (MCAP publish time) − IMU send, processing = solution send − receive; the
    /// solutions beside another driver's send told from the others; the solutions' span from
    /// their times of validity; a cut
    /// recording is an error naming its byte offset, not a hang or a silent partial read.
    #[test]
    fn latencies_from_a_recording_and_a_cut_one() {
        let dir = std::env::temp_dir().join(format!("sextant-bench-lat-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join("r.mcap");
        let rec = Recorder::start(
            &path,
            &RecorderOptions {
                queue_capacity: 1024,
                chunk_size_bytes: 4096,
                flush_interval: Duration::from_secs(1),
                metadata: Vec::new(),
                ..Default::default()
            },
        )
        .expect("recorder");
        for k in 0..200u64 {
            let send = 1_000_000 + k * 5_000_000;
            let mut imu = ImuSample::default();
            imu.header.time_ns = 1 + k as i64 * 5_000_000;
            imu.header.send_mono_ns = send;
            rec.record_blocking(Record::Imu(imu), send + 40_000);
            let mut nav = NavSolution::default();
            nav.header.time_ns = imu.header.time_ns;
            nav.imu_send_mono_ns = send;
            nav.header.send_mono_ns = send + 55_000;
            rec.record_blocking(Record::Nav(nav), nav.header.send_mono_ns);
            // A baro sample sent 2 ms before every 20th IMU sample (beside it; 3 ms after the
            // IMU sample before, outside that one's window), and ten IMU samples later an
            // odometer sample 1.5 ms after one (apart from it, and from the next, 3.5 ms later).
            if k % 20 == 5 {
                let mut b = msgs::BaroSample::default();
                b.header.send_mono_ns = send - 2_000_000;
                rec.record_blocking(Record::Baro(b), send);
            }
            if k % 20 == 15 {
                let mut o = msgs::OdometerSample::default();
                o.header.send_mono_ns = send + 1_500_000;
                rec.record_blocking(Record::Odometer(o), send + 1_500_000);
            }
        }
        rec.finish().expect("finish");
        let (series, span_s) = latencies_and_span(&path).expect("read");
        assert_eq!(series.beside_other_drivers.len(), 10);
        assert_eq!(series.apart_from_other_drivers.len(), 190);
        let (total, transport, processing) = (series.total, series.transport, series.processing);
        assert_eq!(total.len(), 200);
        // 200 solutions 5 ms apart: 199 intervals.
        assert!((span_s - 0.995).abs() < 1e-12, "{span_s}");
        assert!(total.iter().all(|&x| (x - 55.0).abs() < 1e-9), "{total:?}");
        assert!(transport.iter().all(|&x| (x - 40.0).abs() < 1e-9));
        assert!(processing.iter().all(|&x| (x - 15.0).abs() < 1e-9));

        let bytes = std::fs::read(&path).expect("read back");
        let cut = dir.join("cut.mcap");
        std::fs::write(&cut, &bytes[..bytes.len() / 2]).expect("write");
        let err = latencies_and_span(&cut)
            .expect_err("cut recording")
            .to_string();
        assert!(err.contains("byte offset"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
