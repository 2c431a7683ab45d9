//! The fusion daemon's latency statistics: every solution's IMU-send-to-solution-send latency
//! in a fixed histogram, so that the daemon reports percentiles over every solution it
//! computed (in its `Status`) whatever share of the solutions the recording keeps, without
//! allocating on the filter thread.
//!
//! Bins are logarithmic, [`BINS_PER_OCTAVE`] per doubling from 1 µs: a percentile read from a
//! bin is within a factor 2^(1/128) (0.55 %) of the true value when taken at the bin's
//! geometric middle. Latencies under 1 µs share the first bin, those over 2^[`OCTAVES`] µs
//! (≈ 16.8 s) the last; the largest is kept exactly.

/// Bins per doubling of the latency.
pub const BINS_PER_OCTAVE: usize = 64;
/// Doublings covered from 1 µs (2^24 µs ≈ 16.8 s).
pub const OCTAVES: usize = 24;
const BINS: usize = BINS_PER_OCTAVE * OCTAVES + 1;

/// Counts of latencies per logarithmic bin, and the largest one.
#[derive(Debug, Clone)]
pub struct LatencyHistogram {
    /// Bin 0: under 1 µs; bin b ≥ 1: [2^((b−1)/64), 2^(b/64)) µs; the last is open above.
    counts: Box<[u64; BINS]>,
    count: u64,
    max_ns: u64,
}

impl Default for LatencyHistogram {
    fn default() -> Self {
        Self {
            counts: Box::new([0; BINS]),
            count: 0,
            max_ns: 0,
        }
    }
}

impl LatencyHistogram {
    /// Count one latency, ns.
    pub fn record(&mut self, latency_ns: u64) {
        let us = latency_ns as f64 * 1e-3;
        let bin = if us < 1.0 {
            0
        } else {
            ((us.log2() * BINS_PER_OCTAVE as f64) as usize + 1).min(BINS - 1)
        };
        self.counts[bin] += 1;
        self.count += 1;
        self.max_ns = self.max_ns.max(latency_ns);
    }

    /// Latencies counted.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Largest latency counted, µs (0 when none).
    pub fn max_us(&self) -> f64 {
        self.max_ns as f64 * 1e-3
    }

    /// The `p`-th percentile (0–100), µs: the geometric middle of the bin holding the sample
    /// of rank ⌈p/100 · n⌉, never above the largest; 0 when nothing was counted.
    pub fn percentile_us(&self, p: f64) -> f64 {
        if self.count == 0 {
            return 0.0;
        }
        let rank = ((p / 100.0 * self.count as f64).ceil() as u64).clamp(1, self.count);
        let mut seen = 0;
        for (bin, &c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                let mid = if bin == 0 {
                    0.5
                } else {
                    2f64.powf((bin as f64 - 0.5) / BINS_PER_OCTAVE as f64)
                };
                return mid.min(self.max_us());
            }
        }
        self.max_us()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Percentiles of a known set, within the bins' resolution (half a bin: 2^(1/128)).
    #[test]
    fn percentiles_are_within_half_a_bin_of_the_exact_ones() {
        let mut h = LatencyHistogram::default();
        // 1..=10 000 µs: the exact p50 is 5 000 µs, p99 9 900 µs.
        for us in 1..=10_000u64 {
            h.record(us * 1000);
        }
        let tol = 2f64.powf(1.0 / 128.0);
        for (p, exact) in [(50.0, 5000.0), (99.0, 9900.0), (1.0, 100.0)] {
            let got = h.percentile_us(p);
            assert!(
                got / exact < tol * 1.0001 && exact / got < tol * 1.0001,
                "p{p}: {got} vs {exact}"
            );
        }
        assert_eq!(h.count(), 10_000);
        assert_eq!(h.max_us(), 10_000.0);
        assert_eq!(h.percentile_us(100.0), 10_000.0);
    }

    #[test]
    fn extremes_land_in_the_end_bins() {
        let mut h = LatencyHistogram::default();
        assert_eq!(h.percentile_us(50.0), 0.0);
        h.record(10);
        assert_eq!(h.percentile_us(50.0), 0.01, "capped at the largest");
        h.record(u64::MAX / 2);
        assert_eq!(h.count(), 2);
        assert!(h.percentile_us(100.0) > 1.6e7);
    }
}
