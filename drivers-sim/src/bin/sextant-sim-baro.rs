//! `sextant-sim-baro`: simulated driver process (command line: docs/ARCHITECTURE.md, process contract).

use clap::Parser;
use sextant_drivers_sim::driver::{self, DriverArgs};
use sextant_drivers_sim::sources::BaroSource;

fn main() -> anyhow::Result<()> {
    driver::init_logging();
    let args = DriverArgs::parse();
    driver::run(&args, "sextant-sim-baro", BaroSource::new)?;
    Ok(())
}
