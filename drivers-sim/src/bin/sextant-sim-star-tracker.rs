//! `sextant-sim-star-tracker`: simulated driver process (see HELPERS.md for the command line).

use clap::Parser;
use sextant_drivers_sim::driver::{self, DriverArgs};
use sextant_drivers_sim::sources::StarTrackerSource;

fn main() -> anyhow::Result<()> {
    driver::init_logging();
    let args = DriverArgs::parse();
    driver::run(&args, "sextant-sim-star-tracker", StarTrackerSource::new)?;
    Ok(())
}
