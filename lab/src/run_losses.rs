//! What a whole run lost, over all of its recordings.
//!
//! A run whose fusion daemon was restarted (crash, or killed by the supervisor after a hang)
//! leaves one recording per daemon life (`recording.mcap`, `recording.1.mcap`, …). The
//! analysis of `sextant run` tables the last one; the losses of the run are in all of them:
//! - inside each recording, a jump in a sensor channel's sequence numbers is a sample the
//!   daemon never received (lost in transport, or skipped by a driver after a stall);
//! - between two recordings, the samples the drivers sent while no daemon was listening: the
//!   next recording's first sequence number minus the previous one's last, minus one (the
//!   drivers number their samples across their own restarts, so the numbering is one run-wide
//!   count per channel);
//! - the solutions a killed daemon flagged stale, which no exit report of it counts.
//!
//! Sequence numbers restart at 1 only for a driver that was restarted without continuing its
//! numbering; such a restart is counted, not taken as a loss.

use crate::recorder::Record;
use crate::recording::{Recording, RecordingError};
use msgs::Channel;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Sequence numbers of one sensor channel in one recording.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct ChannelSpan {
    /// First sequence number recorded.
    pub first: u64,
    /// Last sequence number recorded.
    pub last: u64,
    /// Sequence numbers missing between the first and the last.
    pub gaps: u64,
    /// Times the numbering went back (a driver restarted at 1).
    pub restarts: u64,
}

/// One recording's sensor channels and stale solutions.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct RecordingSpans {
    /// The recording.
    pub recording: PathBuf,
    /// Per sensor channel (inputs only: the daemon's own outputs are numbered per life).
    pub channels: BTreeMap<String, ChannelSpan>,
    /// Solutions recorded with the stale flag.
    pub solutions_stale: u64,
    /// Solutions recorded.
    pub solutions: u64,
    /// True when the recording was cut (crash): scanned up to its last readable record.
    pub truncated: bool,
}

/// The losses of a run, per sensor channel, over every recording.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct RunLosses {
    /// Samples never recorded: the gaps inside the recordings plus those between them.
    pub samples_lost_per_channel: BTreeMap<String, u64>,
    /// Of those, the samples sent while no fusion daemon was listening (between recordings).
    pub samples_lost_between_recordings: BTreeMap<String, u64>,
    /// Solutions flagged stale in every recording.
    pub solutions_stale: u64,
    /// Solutions in every recording.
    pub solutions: u64,
}

/// Sensor channels: the inputs the drivers number.
fn is_input(topic: &str) -> bool {
    Channel::ALL
        .iter()
        .any(|c| c.name() == topic && !matches!(c, Channel::Nav | Channel::Status))
}

/// Scan one file of a recording (unordered, non-seeking: a file cut by a crash is read up to
/// its last readable record; the recording's further segments are scanned on their own).
pub fn scan(path: &Path) -> Result<RecordingSpans, RecordingError> {
    let rec = Recording::open_file(path)?;
    let mut s = RecordingSpans {
        recording: path.to_path_buf(),
        ..Default::default()
    };
    for m in rec {
        let m = match m {
            Ok(m) => m,
            Err(e) => {
                tracing::warn!("{}: reading stopped: {e}", path.display());
                s.truncated = true;
                break;
            }
        };
        let Some(record) = m.record else { continue };
        if let Record::Nav(n) = &record {
            s.solutions += 1;
            s.solutions_stale += u64::from(n.stale != 0);
            continue;
        }
        let Some(ch) = record.channel() else { continue };
        if !is_input(ch.name()) {
            continue;
        }
        let seq = record.header().seq;
        match s.channels.get_mut(ch.name()) {
            None => {
                s.channels.insert(
                    ch.name().to_string(),
                    ChannelSpan {
                        first: seq,
                        last: seq,
                        ..Default::default()
                    },
                );
            }
            Some(c) => {
                if seq > c.last {
                    c.gaps += seq - c.last - 1;
                } else {
                    c.restarts += 1;
                }
                c.last = seq;
            }
        }
    }
    Ok(s)
}

/// Fold the scans of a run's recordings, in the order the daemons wrote them.
pub fn fold(scans: &[RecordingSpans]) -> RunLosses {
    let mut r = RunLosses::default();
    for (k, s) in scans.iter().enumerate() {
        r.solutions += s.solutions;
        r.solutions_stale += s.solutions_stale;
        for (name, c) in &s.channels {
            *r.samples_lost_per_channel.entry(name.clone()).or_insert(0) += c.gaps;
            let between = k
                .checked_sub(1)
                .and_then(|p| scans[p].channels.get(name))
                .map_or(0, |prev| c.first.saturating_sub(prev.last + 1));
            if k > 0 {
                *r.samples_lost_between_recordings
                    .entry(name.clone())
                    .or_insert(0) += between;
            }
            *r.samples_lost_per_channel.get_mut(name).unwrap() += between;
        }
    }
    r
}

/// Scan and fold a run's recordings (a file that cannot be opened is skipped with a warning:
/// its losses are unknown, and the caller says the recording is incomplete).
pub fn of_run(recordings: &[PathBuf]) -> RunLosses {
    let scans: Vec<RecordingSpans> = recordings
        .iter()
        .filter_map(|p| match scan(p) {
            Ok(s) => Some(s),
            Err(e) => {
                tracing::warn!("{}: {e}", p.display());
                None
            }
        })
        .collect();
    fold(&scans)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spans(channels: &[(&str, u64, u64, u64)], stale: u64) -> RecordingSpans {
        RecordingSpans {
            channels: channels
                .iter()
                .map(|&(n, first, last, gaps)| {
                    (
                        n.to_string(),
                        ChannelSpan {
                            first,
                            last,
                            gaps,
                            restarts: 0,
                        },
                    )
                })
                .collect(),
            solutions_stale: stale,
            ..Default::default()
        }
    }

    #[test]
    fn losses_inside_and_between_recordings_add_up() {
        // Life 1 received imu 1..=1000 with 10 lost inside; the daemon was down while 1000
        // more were sent; life 2 received 2001..=3000 with 5 lost inside.
        let a = spans(&[("imu", 1, 1000, 10), ("gnss", 1, 10, 0)], 3);
        let b = spans(&[("imu", 2001, 3000, 5), ("gnss", 21, 30, 0)], 1);
        let r = fold(&[a, b]);
        assert_eq!(r.samples_lost_per_channel["imu"], 10 + 1000 + 5);
        assert_eq!(r.samples_lost_between_recordings["imu"], 1000);
        assert_eq!(r.samples_lost_per_channel["gnss"], 10);
        assert_eq!(r.solutions_stale, 4);
    }

    #[test]
    fn a_single_recording_loses_only_its_gaps() {
        let r = fold(&[spans(&[("imu", 1, 100, 7)], 0)]);
        assert_eq!(r.samples_lost_per_channel["imu"], 7);
        assert!(r.samples_lost_between_recordings.is_empty());
    }

    #[test]
    fn outputs_are_not_inputs() {
        assert!(is_input("imu") && is_input("gnss") && is_input("truth"));
        assert!(!is_input("nav") && !is_input("status") && !is_input("foxglove/pose"));
    }
}
