//! Sextant's real-time runtime: the fusion daemon (filter thread and recorder), its
//! configuration, the recording format and reader, and the process glue around them.
//!
//! - [`config`]: the system configuration (`config/sextant.toml`) and the filter tuning file.
//! - [`daemon`]: the fusion daemon's WaitSet loop.
//! - [`recorder`]: the MCAP writer thread.
//! - [`recording`]: the bounded, corruption-tolerant reader of those recordings.
//! - [`foxglove`]: the solution on Foxglove's well-known schemas.
//! - [`signals`]: SIGINT/SIGTERM to a stop flag.
//! - [`supervisor`]: `sextant run`'s process supervisor (start, restart, ordered stop, status).
//!
//! The offline lab (experiments, reports, analysis, plots) is the `sextant-lab` crate.

pub mod config;
pub mod daemon;
pub mod foxglove;
pub mod recorder;
pub mod recording;
pub mod signals;
pub mod supervisor;
