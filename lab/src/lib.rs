//! Sextant's offline lab: what reads recordings and simulations after the fact — analysis,
//! reports, plots, calibration, the offline and live replay, the bench and the experiments —
//! and the building blocks of the `sextant` command.
//!
//! - [`analysis`]: errors against truth, drops and latency from a recording.
//! - [`stats`]: RMS, maximum, percentiles.
//! - [`plots`]: PNG plots of an analysis.
//! - [`fonts`]: the font embedded for the plots' text.
//! - [`scenario`]: what the analysis needs from a scenario file (GNSS outage windows).
//! - [`report`]: post-analysis of a recording (REPORT.md, summary.json, plots).
//! - [`replay`]: a recording re-run through the fusion (bit-exact check) or republished live.
//! - [`calibrate`]: star-tracker boresight calibration from a static recording.
//! - [`bench`]: latency, throughput and resources of the real processes.
//! - [`experiments`]: the named offline experiments of `sextant experiment`.
//! - [`shipped_config`]: where they find their scenarios (embedded, or `--config DIR`).
//! - [`import_rinex`]: RINEX 3 observation + navigation files to a recording of GNSS samples.
//! - [`interchange`]: KF-GINS text logs and described CSV logs into and out of recordings.
//! - [`smartloc`]: the smartLoc dataset's text format (pseudoranges, odometry, reference).
//!
//! The runtime modules the lab reads (configuration, daemon, recorder, recording reader,
//! Foxglove conversion, signals, supervisor) are those of `sextant-daemons`, re-exported here under the
//! same names.

pub use sextant_daemons::{
    bus_check, config, daemon, exit_report, foxglove, logging, recorder, recording, signals,
    supervisor,
};

pub mod analysis;
pub mod bench;
pub mod calibrate;
pub mod experiments;
pub mod fonts;
pub mod import_rinex;
pub mod import_smartloc;
pub mod interchange;
pub mod plots;
pub mod progress;
pub mod replay;
pub mod report;
pub mod run_losses;
pub mod scenario;
pub mod shipped_config;
pub mod smartloc;
pub mod stats;
