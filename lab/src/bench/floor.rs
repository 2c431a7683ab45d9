//! The floor of the latency: a bare iceoryx2 round trip between two processes with the same
//! transport and wake-up mechanism as Sextant's own channels and nothing else.
//!
//! Process A (the bench) publishes an [`ImuSample`] on `<prefix>/imu` at the IMU rate, paced
//! like the simulated IMU driver (absolute `clock_nanosleep` on CLOCK_MONOTONIC), stamped by
//! [`msgs::ipc::Pub::send`] and followed by a notification. Process B ([`echo`], the hidden
//! `sextant bench-echo` command) blocks on the channel's listener as the fusion daemon does
//! ([`Sub::wait_for_wake_up`], at most 100 ms at a time), wakes, drains
//! the subscriber and publishes for each sample a [`NavSolution`] carrying the sample's send time
//! in `imu_send_mono_ns`, stamped and notified the same way. Both ends are [`msgs::ipc::Bus`]
//! ports, so the services, queue depths, overflow policy and message sizes are exactly those of
//! the live system. The latency is defined as Sextant's is: solution send time − IMU send time
//! (`NavSolution.header.send_mono_ns − NavSolution.imu_send_mono_ns`); what the fusion daemon
//! adds to this floor is the filter step, the recorder hand-off and its other channels.

use anyhow::{Context, bail};
use msgs::ipc::{Bus, Pub, Sub};
use msgs::{ImuSample, NavSolution};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// Failure of the echo process ([`echo`]).
#[derive(Debug, thiserror::Error)]
pub enum EchoError {
    /// Joining the bus.
    #[error("echo: {0}")]
    Node(#[from] msgs::ipc::NodeError),
    /// The IMU subscriber.
    #[error("echo: {0}")]
    Subscriber(#[from] msgs::ipc::SubscriberError),
    /// The solution publisher.
    #[error("echo: {0}")]
    Publisher(#[from] msgs::ipc::PublisherError),
    /// The wait for the IMU channel's wake-ups.
    #[error("echo: {0}")]
    Wait(#[from] msgs::ipc::WaitError),
    /// Receiving an IMU sample.
    #[error("echo: {0}")]
    Receive(#[from] msgs::ipc::ReceiveError),
    /// Sending a reply.
    #[error("echo: {0}")]
    Send(#[from] msgs::ipc::SendError),
}

/// Node name of the echo process.
pub const ECHO_NODE: &str = "sextant-bench-echo";

/// The echo end of the floor: until `stop` is set, answer every IMU sample on `prefix` with a
/// solution that carries its send time. Returns the number of replies sent.
pub fn echo(prefix: &str, stop: &AtomicBool) -> Result<u64, EchoError> {
    let bus = Bus::new(prefix, ECHO_NODE)?;
    let imu: Sub<ImuSample> = bus.subscriber()?;
    let mut nav: Pub<NavSolution> = bus.publisher()?;
    let mut replies = 0u64;
    // The stop flag is looked at at least every 100 ms, as in the fusion daemon.
    while !stop.load(Ordering::SeqCst) {
        imu.wait_for_wake_up(Duration::from_millis(100))?;
        while let Some(s) = imu.receive()? {
            let mut reply = NavSolution::default();
            reply.header.time_ns = s.header.time_ns;
            reply.imu_send_mono_ns = s.header.send_mono_ns;
            nav.send(reply)?;
            replies += 1;
        }
    }
    Ok(replies)
}

/// What one floor run measured.
#[derive(Debug, Clone, Default)]
pub struct FloorRun {
    /// Latencies (reply send − IMU send) of every measured sample, µs, sorted.
    pub latencies_us: Vec<f64>,
    /// Samples sent in the measured run.
    pub sent: u64,
    /// CPU time of the echo process over the run, % of one core.
    pub echo_cpu_percent: f64,
    /// Peak resident memory of the echo process, MiB.
    pub echo_peak_rss_mib: f64,
    /// Runs measured: 1, or the slices [`FloorRun::append`]ed.
    pub runs: usize,
}

impl FloorRun {
    /// Add an equally long run of the same rate (a slice of the bench's alternation of the
    /// floor with the live run): latencies together, samples summed, the echo's CPU the mean
    /// over the runs, its peak memory the largest.
    pub fn append(&mut self, run: FloorRun) {
        let (a, b) = (self.runs as f64, run.runs as f64);
        if a + b > 0.0 {
            self.echo_cpu_percent =
                (self.echo_cpu_percent * a + run.echo_cpu_percent * b) / (a + b);
        }
        self.echo_peak_rss_mib = self.echo_peak_rss_mib.max(run.echo_peak_rss_mib);
        self.sent += run.sent;
        self.runs += run.runs;
        self.latencies_us.extend(run.latencies_us);
        self.latencies_us.sort_by(f64::total_cmp);
    }
}

/// Run the floor at `imu_hz` for `duration_s` against the echo process `echo_pid` listening on
/// `prefix`: wait until it answers, then send `imu_hz · duration_s` paced samples and collect
/// the replies. `echo_log` is named in the error when the echo never answers.
pub fn measure(
    prefix: &str,
    echo_pid: u32,
    imu_hz: f64,
    duration_s: f64,
    echo_log: &std::path::Path,
) -> anyhow::Result<FloorRun> {
    let bus = Bus::new(prefix, "sextant-bench-floor")?;
    let mut imu: Pub<ImuSample> = bus.publisher()?;
    let nav: Sub<NavSolution> = bus.subscriber()?;
    // Probes (time_ns 0) until the echo answers: before its subscriber is connected a sample is
    // lost (the services keep no history), and a probe's reply is never counted.
    let t_probe = std::time::Instant::now();
    'ready: loop {
        imu.send(ImuSample::default())?;
        std::thread::sleep(Duration::from_millis(20));
        while let Some(r) = nav.receive()? {
            if r.header.time_ns == 0 {
                break 'ready;
            }
        }
        if t_probe.elapsed() > Duration::from_secs(10) {
            bail!(
                "the floor's echo process never answered on {prefix} (see {})",
                echo_log.display()
            );
        }
    }
    std::thread::sleep(Duration::from_millis(50));
    while nav.receive()?.is_some() {}

    let n = (imu_hz * duration_s).round() as u64;
    let period_ns = 1e9 / imu_hz;
    let before = super::proc_sample(echo_pid);
    let t0 = msgs::monotonic_ns() + 100_000_000;
    let mut latencies_us = Vec::with_capacity(n as usize);
    let mut collect = |nav: &Sub<NavSolution>| -> anyhow::Result<()> {
        while let Some(r) = nav.receive()? {
            if r.header.time_ns > 0 && r.header.send_mono_ns >= r.imu_send_mono_ns {
                latencies_us.push((r.header.send_mono_ns - r.imu_send_mono_ns) as f64 * 1e-3);
            }
        }
        Ok(())
    };
    for k in 0..n {
        // Same pacing as the simulated IMU driver: sleep to the absolute send time, then send.
        drivers_sim::driver::sleep_until_mono(t0 + (k as f64 * period_ns) as u64);
        let mut s = ImuSample::default();
        s.header.time_ns = k as i64 + 1;
        s.dt_s = 1.0 / imu_hz;
        imu.send(s)?;
        // The replies of earlier samples, without waiting (the echo's latency is in its stamp).
        collect(&nav)?;
    }
    std::thread::sleep(Duration::from_millis(200));
    collect(&nav)?;
    let after = super::proc_sample(echo_pid);
    let wall_s = n as f64 / imu_hz + 0.3;
    let (cpu, rss) = match (before, after) {
        (Some(a), Some(b)) => (
            100.0 * (b.cpu_s - a.cpu_s) / wall_s,
            b.hwm_kib as f64 / 1024.0,
        ),
        _ => (f64::NAN, f64::NAN),
    };
    if latencies_us.is_empty() {
        bail!(
            "the floor's echo process answered no sample at {imu_hz} Hz (see {})",
            echo_log.display()
        );
    }
    latencies_us.sort_by(f64::total_cmp);
    Ok(FloorRun {
        latencies_us,
        sent: n,
        echo_cpu_percent: cpu,
        echo_peak_rss_mib: rss,
        runs: 1,
    })
}

/// Start `sextant bench-echo --prefix PREFIX` (the binary in `bin_dir`), run [`measure`], stop it.
pub fn run(
    bin_dir: &std::path::Path,
    prefix: &str,
    imu_hz: f64,
    duration_s: f64,
    logs: &std::path::Path,
) -> anyhow::Result<FloorRun> {
    let log_path = logs.join(format!("bench-echo_{}hz.log", imu_hz as u64));
    let log = std::fs::File::create(&log_path)
        .with_context(|| format!("create {}", log_path.display()))?;
    let mut child = std::process::Command::new(bin_dir.join("sextant"))
        .args(["bench-echo", "--prefix", prefix])
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(log)
        .spawn()
        .with_context(|| format!("start {} bench-echo", bin_dir.join("sextant").display()))?;
    let r = measure(prefix, child.id(), imu_hz, duration_s, &log_path);
    super::stop(&mut child, Duration::from_secs(5));
    r
}
