//! The live view: `sextant-foxglove --prefix P --listen ADDR [--config FILE]` serves the bus channels of the
//! run with prefix `P` to Foxglove over its WebSocket protocol on `ADDR` (see
//! `sextant_live`) until SIGINT/SIGTERM, then exits 0. `sextant run --foxglove [ADDR]` starts
//! it (and restarts it when it dies); it can also be started by hand beside any running system.

use anyhow::Context;
use clap::Parser;
use sextant_daemons::{bus_check, config, foxglove, logging, signals};
use std::net::SocketAddr;
use std::path::PathBuf;

/// Sextant live view: the bus channels of a running system served to Foxglove (WebSocket).
#[derive(Debug, Parser)]
#[command(
    name = "sextant-foxglove",
    version,
    after_help = "Example:\n  sextant-foxglove --prefix sextant --listen 127.0.0.1:8765\n  \
                  then in Foxglove: Open connection → Foxglove WebSocket → ws://127.0.0.1:8765"
)]
struct Args {
    /// Service-name prefix of the run to serve.
    #[arg(long, default_value = "sextant")]
    prefix: String,
    /// Address of the WebSocket server (port 0: any free port, printed at start).
    #[arg(long, default_value = "127.0.0.1:8765")]
    listen: SocketAddr,
    /// System configuration of the run: its filter's GNSS lever arm places the antenna in the
    /// frame tree (without it the sensors are drawn at the body origin).
    #[arg(long)]
    config: Option<PathBuf>,
}

fn main() -> anyhow::Result<()> {
    logging::init();
    let args = Args::parse();
    let stop = signals::install()?;
    bus_check::validate_prefix(&args.prefix)
        .with_context(|| format!("--prefix {:?}", args.prefix))?;
    let mounts = match &args.config {
        Some(path) => foxglove::SensorMounts::of_filter(&config::load(path)?.navigator),
        None => foxglove::SensorMounts::default(),
    };
    let opts = sextant_live::ServeOptions {
        prefix: args.prefix.clone(),
        listen: args.listen,
        node_name: "sextant-foxglove".into(),
        mounts,
    };
    let counters = sextant_live::serve(&opts, stop, &mut |addr| {
        tracing::info!(
            "serving the channels of prefix {} to Foxglove on ws://{addr}",
            args.prefix
        );
    })?;
    tracing::info!(
        "done: {} messages received, {} sent to clients, {} not sent (non-finite), {} receive errors",
        counters.received,
        counters.logged,
        counters.non_finite,
        counters.receive_errors
    );
    Ok(())
}
