//! Where each aiding sensor's next sample is expected: its last time of validity plus the
//! spacing before it. The IMU step that reaches such an epoch brings the covariance to it
//! (`imu_step`), so the checkpoint taken there before the updates serves that sample whether
//! it arrives in time or late: a late sample's rewind then restores the propagated
//! covariance instead of propagating again, and the fixed interval's grid, which a forced
//! propagation (e.g. an in-time baro update) shifts, meets the late sensor's epochs again.
//!
//! Kept in the replayable core and fed from the samples fused (in time-of-validity order), so
//! an in-time and a late arrival of the same stream propagate at the same epochs and give the
//! same result bit for bit.

use crate::time::{Duration, GpsTime};

/// Longest spacing taken as a cadence: sensors slower than 1 Hz are not forecast.
const MAX_SPACING: Duration = Duration::from_seconds(1);

/// The last two times of validity of one sensor's samples.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(super) struct Cadence {
    /// Time of validity of the last sample fused.
    last: Option<GpsTime>,
    /// Spacing between it and the one before.
    spacing: Option<Duration>,
}

impl Cadence {
    /// A sample of time of validity `ts` is being fused.
    pub(super) fn observe(&mut self, ts: GpsTime) {
        if let Some(last) = self.last {
            if ts <= last {
                return;
            }
            self.spacing = Some(ts - last);
        }
        self.last = Some(ts);
    }

    /// The next sample's expected time of validity, if the sensor keeps a cadence (spacing
    /// positive and at most [`MAX_SPACING`]).
    pub(super) fn next(&self) -> Option<GpsTime> {
        match (self.last, self.spacing) {
            (Some(last), Some(d)) if d > Duration::ZERO && d <= MAX_SPACING => Some(last + d),
            _ => None,
        }
    }

    /// Whether the next sample is expected within `(after, upto]`: the IMU step from `after`
    /// to `upto` is the first to reach its epoch, and fuses it.
    pub(super) fn expected_within(&self, after: GpsTime, upto: GpsTime) -> bool {
        self.next().is_some_and(|t| after < t && t <= upto)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at_ms(ms: i64) -> GpsTime {
        GpsTime::from_ns(1_000_000_000_000 + ms * 1_000_000)
    }

    #[test]
    fn the_next_epoch_is_the_last_plus_the_last_spacing() {
        let mut c = Cadence::default();
        assert_eq!(c.next(), None);
        c.observe(at_ms(40));
        assert_eq!(c.next(), None, "one sample is no cadence");
        c.observe(at_ms(90));
        assert_eq!(c.next(), Some(at_ms(140)));
        // The step from 135 to 140 ms reaches it, the one from 140 to 145 ms does not.
        assert!(c.expected_within(at_ms(135), at_ms(140)));
        assert!(!c.expected_within(at_ms(140), at_ms(145)));
        assert!(!c.expected_within(at_ms(130), at_ms(135)));
        // A replayed (older or equal) sample changes nothing.
        c.observe(at_ms(90));
        c.observe(at_ms(60));
        assert_eq!(c.next(), Some(at_ms(140)));
        // A dropout: the spacing follows the samples, then recovers.
        c.observe(at_ms(190));
        assert_eq!(c.next(), Some(at_ms(290)));
        c.observe(at_ms(240));
        assert_eq!(c.next(), Some(at_ms(290)));
    }

    #[test]
    fn a_gap_longer_than_a_second_is_no_cadence() {
        let mut c = Cadence::default();
        c.observe(at_ms(0));
        c.observe(at_ms(1_000));
        assert_eq!(c.next(), Some(at_ms(2_000)));
        c.observe(at_ms(2_500));
        assert_eq!(c.next(), None, "1.5 s since the last sample");
        c.observe(at_ms(3_000));
        assert_eq!(c.next(), Some(at_ms(3_500)));
    }
}
