//! The bridge: `sextant-bridge --prefix P --key-prefix K [--listen E]... [--connect E]...
//! [--export CH,...] [--import CH,... --import-from R]` publishes the bus channels of the run
//! with prefix `P` on Zenoh under `K/v1/<channel>` and brings the channels of the remote
//! system `R` into the local bus (see `sextant_bridge`), until SIGINT/SIGTERM, then exits 0.
//! `sextant run` starts it when the configuration has a `[bridge]` table.

use anyhow::Context;
use clap::Parser;
use msgs::Channel;
use sextant_bridge::{BridgeOptions, DEFAULT_LEASE_MS};
use sextant_daemons::{bus_check, logging, signals};

/// Sextant bridge: bus channels to and from other computers over Zenoh.
#[derive(Debug, Parser)]
#[command(
    name = "sextant-bridge",
    version,
    after_help = "Examples:\n  \
        on the vehicle:  sextant-bridge --prefix sextant --key-prefix car1 --listen tcp/0.0.0.0:7447\n  \
        on the ground:   sextant-bridge --prefix ground --key-prefix ground --connect tcp/car1.local:7447 \\\n                     \
        --export '' --import nav,status --import-from car1\n\n\
        Wire format: docs/DATA.md (Zenoh bridge)."
)]
struct Args {
    /// Service-name prefix of the local bus.
    #[arg(long, default_value = "sextant")]
    prefix: String,
    /// Key prefix of the exported channels (`KEY_PREFIX/v1/<channel>`; default: the bus prefix).
    #[arg(long)]
    key_prefix: Option<String>,
    /// Zenoh endpoint to listen on, `tcp/IP:PORT` (repeatable).
    #[arg(long)]
    listen: Vec<String>,
    /// Zenoh endpoint to connect to, `tcp/HOST:PORT` (repeatable; retried for ever).
    #[arg(long)]
    connect: Vec<String>,
    /// Local channels to publish on Zenoh, comma-separated (`''` for none).
    #[arg(long, value_delimiter = ',', default_value = "nav,status")]
    export: Vec<String>,
    /// Remote channels to publish on the local bus, comma-separated.
    #[arg(long, value_delimiter = ',')]
    import: Vec<String>,
    /// Key prefix of the remote system whose channels are imported.
    #[arg(long, default_value = "")]
    import_from: String,
    /// Lease of the links, ms: a silent link is declared down after it.
    #[arg(long, default_value_t = DEFAULT_LEASE_MS)]
    lease_ms: u64,
    /// Name of this bridge (its bus node and its liveliness token).
    #[arg(long, default_value = "sextant-bridge")]
    name: String,
    /// Check the options and exit (0 when valid), joining neither the bus nor the network.
    #[arg(long)]
    check: bool,
}

fn channels(flag: &str, names: &[String]) -> anyhow::Result<Vec<Channel>> {
    names
        .iter()
        .filter(|n| !n.is_empty())
        .map(|n| {
            Channel::from_name(n).with_context(|| {
                let all: Vec<&str> = Channel::ALL.iter().map(|c| c.name()).collect();
                format!(
                    "{flag}: unknown channel {n:?} (channels: {})",
                    all.join(", ")
                )
            })
        })
        .collect()
}

fn main() -> anyhow::Result<()> {
    logging::init();
    let args = Args::parse();
    let stop = signals::install()?;
    bus_check::validate_prefix(&args.prefix)
        .with_context(|| format!("--prefix {:?}", args.prefix))?;
    let opts = BridgeOptions {
        key_prefix: args
            .key_prefix
            .clone()
            .unwrap_or_else(|| args.prefix.clone()),
        prefix: args.prefix.clone(),
        name: args.name.clone(),
        listen: args.listen.clone(),
        connect: args.connect.clone(),
        export: channels("--export", &args.export)?,
        import: channels("--import", &args.import)?,
        import_from: args.import_from.clone(),
        lease_ms: args.lease_ms,
    };
    opts.check()?;
    if args.check {
        return Ok(());
    }
    let counters = sextant_bridge::run(&opts, stop, &mut || {
        tracing::info!(
            "bridge {}: bus {} ↔ Zenoh (listen {:?}, connect {:?}); exporting {:?} as {}; importing {:?} from {}",
            opts.name,
            opts.prefix,
            opts.listen,
            opts.connect,
            opts.export.iter().map(|c| c.name()).collect::<Vec<_>>(),
            opts.key_prefix,
            opts.import.iter().map(|c| c.name()).collect::<Vec<_>>(),
            opts.import_from,
        );
    })?;
    tracing::info!(
        "done: {} exported ({} refused), {} imported ({} dropped, {} undecodable), {} link loss(es), {} bus errors",
        counters.exported,
        counters.export_errors,
        counters.imported,
        counters.import_dropped,
        counters.decode_errors,
        counters.link_losses,
        counters.bus_errors
    );
    Ok(())
}
