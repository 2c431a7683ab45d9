//! The processes around the navigation math: the fusion daemon (filter thread and recorder),
//! the analysis of recordings, and the `sextant` command's building blocks.
//!
//! - [`config`]: the system configuration (`config/sextant.toml`) and the filter tuning file.
//! - [`daemon`]: the fusion daemon's WaitSet loop.
//! - [`recorder`]: the MCAP writer thread.
//! - [`foxglove`]: the solution on Foxglove's well-known schemas.
//! - [`analysis`]: errors against truth, drops and latency from a recording.
//! - [`stats`]: RMS, maximum, percentiles.
//! - [`plots`]: PNG plots of an analysis.
//! - [`scenario`]: what the analysis needs from a scenario file (GNSS outage windows).
//! - [`signals`]: SIGINT/SIGTERM to a stop flag.

pub mod analysis;
pub mod bench;
pub mod calibrate;
pub mod config;
pub mod daemon;
pub mod experiments;
pub mod foxglove;
pub mod plots;
pub mod recorder;
pub mod recording;
pub mod replay;
pub mod report;
pub mod scenario;
pub mod signals;
pub mod stats;
