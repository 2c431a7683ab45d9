//! The fusion daemon's own final counters, handed to `sextant run` as one line on its stdout
//! when it exits: `sextant-fusion-report {json}`.
//!
//! `sextant run` builds its summary's counters (records written and dropped, write errors,
//! solutions) from this line, not from the recording: after a full disk the recording's last
//! status is the one written before the disk filled up (it showed 0 drops while the live
//! status had counted tens of thousands), and after a crash the recording has no end at all.
//! stdout is a pipe to the supervisor, so the line arrives even when the disk is full.

use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Marker that starts the report line.
pub const PREFIX: &str = "sextant-fusion-report ";

/// What one fusion daemon did, from its own counters at exit.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ExitReport {
    /// The recording it was told to write (`--out`, its first segment).
    pub recording: PathBuf,
    /// IMU samples received.
    pub imu_received: u64,
    /// Solutions computed (every one is handed to the recorder).
    pub solutions: u64,
    /// Solutions published on `<prefix>/nav`.
    pub solutions_published: u64,
    /// Messages the recorder wrote (including the Foxglove views of the solution).
    pub records_written: u64,
    /// Records lost: queue full, a failed write, or no file to write to.
    pub records_dropped: u64,
    /// Write failures (creation, full disk, I/O error).
    pub recorder_errors: u64,
    /// The recording's files, in order (more than one after a failed write resumed).
    pub segments: Vec<PathBuf>,
    /// Log lines that could not be written (the log on a full disk).
    pub log_lines_lost: u64,
    /// Solutions published with the stale flag (a backlog caught up after a stall).
    #[serde(default)]
    pub solutions_stale: u64,
}

impl ExitReport {
    /// Every record reached the disk and nothing failed.
    pub fn recording_complete(&self) -> bool {
        self.records_dropped == 0 && self.recorder_errors == 0 && !self.segments.is_empty()
    }

    /// The report line (without newline).
    pub fn line(&self) -> String {
        // Serializing plain integers and paths cannot fail.
        format!(
            "{PREFIX}{}",
            serde_json::to_string(self).unwrap_or_else(|_| "{}".into())
        )
    }

    /// Parse a line of the fusion's stdout; `None` when it is not a report line.
    pub fn parse(line: &str) -> Option<Self> {
        serde_json::from_str(line.strip_prefix(PREFIX)?.trim_end()).ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn report_line_round_trips_and_other_lines_are_not_reports() {
        let r = ExitReport {
            imu_received: 7,
            solutions: 5,
            records_written: 20,
            records_dropped: 3,
            recorder_errors: 1,
            segments: vec!["a/recording.mcap".into(), "a/recording.part2.mcap".into()],
            ..Default::default()
        };
        assert!(!r.recording_complete());
        assert_eq!(ExitReport::parse(&(r.line() + "\n")), Some(r));
        assert_eq!(ExitReport::parse("2026 INFO fusion running"), None);
        let ok = ExitReport {
            segments: vec!["r.mcap".into()],
            ..Default::default()
        };
        assert!(ok.recording_complete());
        assert!(!ExitReport::default().recording_complete());
    }
}
