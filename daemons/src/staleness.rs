//! Staleness of a solution at publication: how much later than usual it leaves the daemon
//! relative to its time of validity.
//!
//! The daemon's wall clock (CLOCK_MONOTONIC) and the sensors' time of validity (GPS time,
//! scaled by the run's speed-up) differ by an unknown offset plus the delivery delay. The
//! smallest offset seen over the IMU samples is the fastest delivery, i.e. the offset itself;
//! a solution's lag is how far its publication falls behind that. A stalled daemon catching up
//! on its backlog, or a driver flushing a burst of overdue samples, lags by the length of the
//! stall; a daemon keeping up lags by microseconds.
//!
//! The minimum leaks upwards at [`CLOCK_DRIFT_BOUND`] so that a wall clock running slower
//! than GPS time (crystal tolerance, tens of ppm) never turns into an ever-growing false lag.

use std::time::Duration;

/// Largest rate difference between the computer's monotonic clock and the sensors' time
/// (100 ppm, a generous bound for a crystal oscillator): the offset estimate may rise this fast.
pub const CLOCK_DRIFT_BOUND: f64 = 100e-6;

/// Smallest wall-clock staleness limit after scaling by the speed-up: below it, scheduling
/// delays of an ordinary (not real-time) machine would flag solutions as stale.
pub const MIN_WALL_LIMIT: Duration = Duration::from_millis(20);

/// Tracks the delivery offset and judges each solution's lag.
#[derive(Debug, Clone)]
pub struct Staleness {
    speed: f64,
    limit_ns: f64,
    /// First time of validity seen, GPS ns (times are taken relative to it to keep f64 exact).
    t0_ns: Option<i64>,
    /// Smallest `mono − (t − t0)/speed` seen, ns, with its leak applied.
    offset_ns: f64,
    /// Wall time of the last update, ns.
    last_mono_ns: u64,
}

impl Staleness {
    /// A tracker for a run at `speed` (simulated over wall time) whose solutions are stale
    /// when later than `stale_after` of simulated time (floored at [`MIN_WALL_LIMIT`] of wall
    /// time).
    pub fn new(speed: f64, stale_after: Duration) -> Self {
        let wall = if speed.is_finite() && speed > 0.0 {
            stale_after.as_secs_f64() / speed
        } else {
            0.0
        };
        Self {
            speed,
            limit_ns: wall.max(MIN_WALL_LIMIT.as_secs_f64()) * 1e9,
            t0_ns: None,
            offset_ns: f64::INFINITY,
            last_mono_ns: 0,
        }
    }

    fn offset_of(&mut self, t_ns: i64, mono_ns: u64) -> Option<f64> {
        if !(self.speed.is_finite() && self.speed > 0.0) {
            return None; // as fast as possible: no clock to be late on
        }
        let t0 = *self.t0_ns.get_or_insert(t_ns);
        Some(mono_ns as f64 - (t_ns - t0) as f64 / self.speed)
    }

    /// An IMU sample of time of validity `t_ns` (GPS ns) received at `mono_ns`.
    pub fn observe(&mut self, t_ns: i64, mono_ns: u64) {
        let Some(o) = self.offset_of(t_ns, mono_ns) else {
            return;
        };
        if self.offset_ns.is_finite() {
            let dt = mono_ns.saturating_sub(self.last_mono_ns) as f64;
            self.offset_ns += CLOCK_DRIFT_BOUND * dt;
        }
        self.offset_ns = self.offset_ns.min(o);
        self.last_mono_ns = mono_ns;
    }

    /// Lag (ns of wall time) of a solution of time of validity `t_ns` published at `mono_ns`
    /// behind the fastest delivery seen; 0 before any observation.
    pub fn lag_ns(&mut self, t_ns: i64, mono_ns: u64) -> f64 {
        match self.offset_of(t_ns, mono_ns) {
            Some(o) if self.offset_ns.is_finite() => (o - self.offset_ns).max(0.0),
            _ => 0.0,
        }
    }

    /// True when that lag exceeds the limit.
    pub fn is_stale(&mut self, t_ns: i64, mono_ns: u64) -> bool {
        self.lag_ns(t_ns, mono_ns) > self.limit_ns
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn a_daemon_keeping_up_is_fresh_and_a_backlog_is_stale() {
        // 200 Hz at 5×: a sample every 1 ms of wall time, delivered 50 µs after its due time.
        let mut s = Staleness::new(5.0, Duration::from_millis(100));
        let t0 = 1_400_000_000_000_000_000i64;
        for k in 0..1000u64 {
            let t = t0 + (k * 5 * MS) as i64;
            let mono = 10_000 * MS + k * MS + 50_000;
            s.observe(t, mono);
            assert!(!s.is_stale(t, mono + 30_000), "k {k}");
        }
        // Then the daemon stops for 2 s of wall time and drains the samples that waited.
        let t = t0 + (1000 * 5 * MS) as i64;
        let due = 10_000 * MS + 1000 * MS;
        let resumed = due + 2000 * MS;
        s.observe(t, resumed);
        let lag = s.lag_ns(t, resumed);
        assert!((lag - 2000.0 * MS as f64).abs() < 1e6, "lag {lag}");
        assert!(s.is_stale(t, resumed));
    }

    #[test]
    fn limit_scales_with_speed_and_is_floored() {
        let mut s = Staleness::new(20.0, Duration::from_millis(100));
        // 100 ms simulated = 5 ms wall at 20×, floored at 20 ms.
        s.observe(0, 1_000 * MS);
        assert!(!s.is_stale(0, 1_000 * MS + 19 * MS));
        assert!(s.is_stale(0, 1_000 * MS + 21 * MS));
        let mut s = Staleness::new(1.0, Duration::from_millis(100));
        s.observe(0, 1_000 * MS);
        assert!(!s.is_stale(0, 1_000 * MS + 99 * MS));
        assert!(s.is_stale(0, 1_000 * MS + 101 * MS));
    }

    #[test]
    fn a_fast_wall_clock_does_not_accumulate_false_lag() {
        // The wall clock runs 50 ppm fast against GPS time for 24 h of 1 Hz samples: the true
        // lag is 0 throughout; without the leak the last one would look 4.3 s late. (A slow
        // clock lowers the offset, which the minimum follows at once.)
        let mut s = Staleness::new(1.0, Duration::from_millis(100));
        let mut worst = 0.0f64;
        for k in 0..86_400i64 {
            let t = k * 1_000_000_000;
            let mono = (1e12 + k as f64 * 1e9 * (1.0 + 50e-6)) as u64;
            s.observe(t, mono);
            worst = worst.max(s.lag_ns(t, mono));
        }
        assert!(worst < 1e6, "worst false lag {worst} ns");
    }

    #[test]
    fn infinite_speed_is_never_stale() {
        let mut s = Staleness::new(f64::INFINITY, Duration::from_millis(100));
        s.observe(0, 1);
        assert!(!s.is_stale(1_000_000_000_000, 10_000_000_000_000));
    }
}
