//! `sextant-gnss-ublox`: the receiver driver process. Reads a u-blox receiver (UBX and/or
//! NMEA) from a serial device, a TCP stream or a file and publishes `GnssSample`s on
//! `<prefix>/gnss` as soon as each epoch is complete. Runs until the input ends or SIGINT /
//! SIGTERM; then prints its counters as one JSON object on stdout.

use anyhow::Context;
use clap::{ArgGroup, Parser};
use nix::sys::signal::{SaFlags, SigAction, SigHandler, SigSet, Signal, sigaction};
use sextant_drivers_ublox::input::{Input, ReadOutcome};
use sextant_drivers_ublox::receiver::{Receiver, Settings};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// u-blox / NMEA receiver driver: publishes the receiver's fixes on `<prefix>/gnss`.
#[derive(Debug, Parser)]
#[command(group(ArgGroup::new("input").required(true).args(["device", "tcp", "file"])))]
struct Args {
    /// Serial device (or any tty) the receiver is on, e.g. /dev/ttyACM0.
    #[arg(long)]
    device: Option<PathBuf>,
    /// Baud rate of the serial device.
    #[arg(long, default_value_t = 115_200)]
    baud: u32,
    /// TCP stream of the receiver's output, HOST:PORT.
    #[arg(long)]
    tcp: Option<String>,
    /// A file of the receiver's output, read to its end.
    #[arg(long)]
    file: Option<PathBuf>,
    /// Service-name prefix of the run.
    #[arg(long, default_value = "sextant")]
    prefix: String,
    /// User-equivalent range error, m, that turns NMEA GSA DOPs into sigmas when the receiver
    /// sends no GST.
    #[arg(long, default_value_t = Settings::default().nmea_uere_m)]
    nmea_uere_m: f64,
}

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: nix::libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

const NODE: &str = "sextant-gnss-ublox";
/// Period of the counters in the log, s.
const LOG_PERIOD: Duration = Duration::from_secs(10);

fn main() -> anyhow::Result<()> {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init();
    let args = Args::parse();
    if !(args.nmea_uere_m.is_finite() && args.nmea_uere_m > 0.0) {
        anyhow::bail!("--nmea-uere-m must be > 0 m, got {}", args.nmea_uere_m);
    }
    let action = SigAction::new(
        SigHandler::Handler(on_signal),
        SaFlags::empty(),
        SigSet::empty(),
    );
    for sig in [Signal::SIGINT, Signal::SIGTERM] {
        // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
        unsafe { sigaction(sig, &action) }
            .with_context(|| format!("installing the {sig} handler"))?;
    }
    let (mut input, source) = match (&args.device, &args.tcp, &args.file) {
        (Some(d), _, _) => (
            Input::serial(d, args.baud)?,
            format!("{} at {} Bd", d.display(), args.baud),
        ),
        (_, Some(a), _) => (Input::tcp(a)?, format!("tcp {a}")),
        (_, _, Some(f)) => (Input::file(f)?, f.display().to_string()),
        _ => unreachable!("clap requires one input"),
    };
    let bus = msgs::ipc::Bus::new(&args.prefix, NODE)?;
    let mut publisher = bus.publisher::<msgs::GnssSample>()?;
    tracing::info!(input = %source, prefix = %args.prefix, "{NODE} started");

    let mut receiver = Receiver::new(Settings {
        nmea_uere_m: args.nmea_uere_m,
    });
    let mut buf = vec![0u8; 4096];
    let mut samples = Vec::new();
    let mut last_log = Instant::now();
    let mut first_fix = true;
    let mut interrupted = false;
    // Readiness and watchdog pings to `sextant run` (or systemd): the loop wakes at least every
    // poll interval, so a silent receiver does not look like a hung driver.
    let mut service = msgs::sd_notify::Service::from_env();
    loop {
        service.ping();
        if STOP.load(Ordering::SeqCst) {
            interrupted = true;
            break;
        }
        match input
            .read(&mut buf)
            .with_context(|| format!("reading {source}"))?
        {
            ReadOutcome::Data(n) => receiver.push(&buf[..n], &mut samples),
            ReadOutcome::Idle => {}
            ReadOutcome::End => break,
        }
        for s in samples.drain(..) {
            if first_fix && s.fix_valid == 1 {
                first_fix = false;
                tracing::info!(time_ns = s.header.time_ns, "first fix");
            }
            publisher.send(s)?;
        }
        if last_log.elapsed() >= LOG_PERIOD {
            last_log = Instant::now();
            tracing::info!("{}", serde_json::to_string(&receiver.report())?);
        }
    }
    let report = receiver.finish(&mut samples);
    for s in samples.drain(..) {
        publisher.send(s)?;
    }
    tracing::info!(interrupted, "{NODE} finished");
    println!("{}", serde_json::to_string(&report)?);
    drop(publisher);
    drop(bus);
    Ok(())
}
