//! Sextant's real-time runtime: the fusion daemon (filter thread and recorder), its
//! configuration, the recording format and reader, and the process glue around them.
//!
//! - [`bus_check`]: one bus per prefix (who is on it; is the prefix valid).
//! - [`checkpoint`]: the navigator checkpoint file of a warm restart.
//! - [`config`]: the system configuration (`config/sextant.toml`) and the filter tuning file.
//! - [`daemon`]: the fusion daemon's WaitSet loop.
//! - [`latency`]: the histogram of every solution's latency the daemon reports.
//! - [`realtime`]: CPU, SCHED_FIFO priority and locked memory for the filter thread.
//! - [`recorder`]: the MCAP writer thread.
//! - [`recording`]: the bounded, corruption-tolerant reader of those recordings.
//! - [`exit_report`]: the fusion daemon's final counters, read by `sextant run`.
//! - [`foxglove`]: the solution on Foxglove's well-known schemas.
//! - [`signals`]: SIGINT/SIGTERM to a stop flag.
//! - [`logging`]: the processes' log, whose failed writes are never fatal.
//! - [`supervisor`]: `sextant run`'s process supervisor (start, restart, ordered stop, status).
//!
//! The offline lab (experiments, reports, analysis, plots) is the `sextant-lab` crate.

pub mod bus_check;
pub mod checkpoint;
pub mod config;
pub mod daemon;
pub mod exit_report;
pub mod foxglove;
pub mod latency;
pub mod logging;
pub mod realtime;
pub mod recorder;
pub mod recording;
pub use msgs::sd_notify;
pub mod signals;
pub mod staleness;
pub mod supervisor;
pub mod time_slice;
