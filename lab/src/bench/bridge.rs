//! The Zenoh bridge's latency: what a solution takes from the navigation computer's bus to
//! another computer's bus, through two real `sextant-bridge` processes on loopback.
//!
//! Bridge A exports `nav` from bus `<prefix>_a` and listens on a free loopback port; bridge B
//! connects to it and imports `nav` into bus `<prefix>_b`. The bench publishes solutions on A's
//! bus at the solution rate (200 Hz, paced like a driver, each stamped by
//! [`msgs::ipc::Pub::send`]) and receives them on B's bus; latency = arrival on B's bus (its
//! CLOCK_MONOTONIC) − the solution's send time on A's bus (the bridges carry the message
//! unchanged, so its `send_mono_ns` is A's publication; the receiver blocks on B's WaitSet as
//! the fusion daemon does). This is the bridge's whole cost —
//! two iceoryx2 deliveries, protobuf encoding and decoding, two Zenoh sessions and TCP — to be
//! read beside the floor (one bare iceoryx2 delivery and reply).

use anyhow::{Context, bail};
use msgs::NavSolution;
use msgs::ipc::{Bus, Pub, Sub};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Rate of the solutions sent through the bridges, Hz (the default solution rate).
pub const RATE_HZ: f64 = 200.0;

/// What one bridge run measured.
#[derive(Debug, Clone, Default)]
pub struct BridgeRun {
    /// Latency of every solution received in the measured run, µs, sorted.
    pub latencies_us: Vec<f64>,
    /// Solutions sent in the measured run.
    pub sent: u64,
}

fn start(bin: &Path, args: &[String], log: &Path) -> anyhow::Result<Child> {
    let file = std::fs::File::create(log).with_context(|| format!("create {}", log.display()))?;
    Command::new(bin)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(file)
        .spawn()
        .with_context(|| format!("start {}", bin.display()))
}

/// The far side: B's bus, blocked on its WaitSet; records the latency of every solution at
/// its arrival until `stop`. `crossed` is set at the first arrival of any solution.
fn receive(prefix_b: &str, crossed: &AtomicBool, stop: &AtomicBool) -> anyhow::Result<Vec<f64>> {
    let bus = Bus::new(prefix_b, "sextant-bench-bridge-b")?;
    let far: Sub<NavSolution> = bus.subscriber()?;
    let ws = msgs::ipc::waitset()?;
    let _guard = ws
        .attach_notification(far.listener())
        .map_err(msgs::ipc::WaitSetError::Attach)?;
    let mut latencies_us = Vec::new();
    while !stop.load(Ordering::SeqCst) {
        ws.wait_and_process_once_with_timeout(
            |_| iceoryx2::prelude::CallbackProgression::Continue,
            Duration::from_millis(100),
        )
        .map_err(msgs::ipc::WaitSetError::Wait)?;
        far.clear_events();
        while let Some(r) = far.receive()? {
            let now = msgs::monotonic_ns();
            crossed.store(true, Ordering::SeqCst);
            if r.header.time_ns > 0 && now >= r.header.send_mono_ns {
                latencies_us.push((now - r.header.send_mono_ns) as f64 * 1e-3);
            }
        }
    }
    Ok(latencies_us)
}

fn measure(prefix: &str, duration_s: f64, logs: &Path) -> anyhow::Result<BridgeRun> {
    let bus_a = Bus::new(&format!("{prefix}_a"), "sextant-bench-bridge-a")?;
    let mut nav: Pub<NavSolution> = bus_a.publisher()?;
    let crossed = Arc::new(AtomicBool::new(false));
    let stop = Arc::new(AtomicBool::new(false));
    let (c, st, prefix_b) = (crossed.clone(), stop.clone(), format!("{prefix}_b"));
    let receiver = std::thread::spawn(move || receive(&prefix_b, &c, &st));
    // Probes (time_ns 0) until one crosses: the bridges connect, declare and subscribe first.
    let t_probe = Instant::now();
    while !crossed.load(Ordering::SeqCst) {
        nav.send(NavSolution::default())?;
        std::thread::sleep(Duration::from_millis(20));
        if t_probe.elapsed() > Duration::from_secs(20) || receiver.is_finished() {
            stop.store(true, Ordering::SeqCst);
            let why = match receiver.join() {
                Ok(Err(e)) => e.to_string(),
                _ => "nothing arrived".into(),
            };
            bail!(
                "no solution crossed the bridges within 20 s: {why} (see the logs in {})",
                logs.display()
            );
        }
    }
    std::thread::sleep(Duration::from_millis(200));

    let n = (RATE_HZ * duration_s).round() as u64;
    let period_ns = 1e9 / RATE_HZ;
    let t0 = msgs::monotonic_ns() + 100_000_000;
    for k in 0..n {
        // Same pacing as a driver: sleep to the absolute send time, then send.
        drivers_sim::driver::sleep_until_mono(t0 + (k as f64 * period_ns) as u64);
        let mut s = NavSolution::default();
        s.header.time_ns = k as i64 + 1;
        nav.send(s)?;
    }
    std::thread::sleep(Duration::from_millis(500));
    stop.store(true, Ordering::SeqCst);
    let mut latencies_us = match receiver.join() {
        Ok(r) => r?,
        Err(_) => bail!("the bench's receiving thread panicked"),
    };
    latencies_us.sort_by(f64::total_cmp);
    Ok(BridgeRun {
        latencies_us,
        sent: n,
    })
}

/// Start the two bridges (binaries in `bin_dir`), measure for `duration_s`, stop them.
pub fn run(
    bin_dir: &Path,
    prefix: &str,
    duration_s: f64,
    logs: &Path,
) -> anyhow::Result<BridgeRun> {
    let bin = bin_dir.join("sextant-bridge");
    if !bin.is_file() {
        bail!(
            "{} not found: build it first (cargo build --release --workspace)",
            bin.display()
        );
    }
    let port = std::net::TcpListener::bind("127.0.0.1:0")?
        .local_addr()?
        .port();
    let s = |v: &[&str]| v.iter().map(ToString::to_string).collect::<Vec<_>>();
    let key_a = format!("{prefix}_a");
    let mut a = start(
        &bin,
        &s(&[
            "--prefix",
            &key_a,
            "--listen",
            &format!("tcp/127.0.0.1:{port}"),
            "--export",
            "nav",
            "--name",
            "bench-a",
        ]),
        &logs.join("bench-bridge-a.log"),
    )?;
    let b = start(
        &bin,
        &s(&[
            "--prefix",
            &format!("{prefix}_b"),
            "--connect",
            &format!("tcp/127.0.0.1:{port}"),
            "--export",
            "",
            "--import",
            "nav",
            "--import-from",
            &key_a,
            "--name",
            "bench-b",
        ]),
        &logs.join("bench-bridge-b.log"),
    );
    let mut b = match b {
        Ok(b) => b,
        Err(e) => {
            super::stop(&mut a, Duration::from_secs(5));
            return Err(e);
        }
    };
    let r = measure(prefix, duration_s, logs);
    super::stop(&mut b, Duration::from_secs(5));
    super::stop(&mut a, Duration::from_secs(5));
    r
}
