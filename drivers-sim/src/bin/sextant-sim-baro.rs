//! `sextant-sim-baro`: simulated driver process (command line: docs/ARCHITECTURE.md, process contract).

use sextant_drivers_sim::driver::{SimDriver, main_of};

fn main() -> anyhow::Result<()> {
    main_of(SimDriver::Baro)?;
    Ok(())
}
