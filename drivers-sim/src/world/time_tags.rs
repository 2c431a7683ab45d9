//! Host time-stamping of the aiding sensors (`[world.time_tags]`): the odometer's latency and
//! the jitter of every stamp.
//!
//! A computer that stamps a sensor's message when it arrives stamps it late by the sensor's
//! processing and transport (a constant the installation documents: the GNSS fix's 50 ms in
//! `[world.gnss_antenna]`, the star tracker's in `[world.star_tracker]`, the odometer's CAN
//! frame here) and by a varying part — bus arbitration, the operating system's scheduling —
//! that no document gives: the jitter. The sample stamped `t` is the measurement made at
//! `t − L − j`, `j` drawn per sample uniformly among the whole milliseconds of `[−J, J]` (the
//! truth's 1 ms grid), variance `J(J + 1)/3` ms² for `J` in ms. The filter is told `L`, never
//! `j`.
//!
//! A measurement is never stamped before it is made: `J` is cut to `L` where it is larger
//! (no jitter where the sensor's latency table is off). Validation keeps `L + J` and `2J`
//! below one sample period, so that the measurement instants stay in order.
//!
//! Draws come from one stream per sensor (`"world_time_tag_<sensor>"`): each driver process
//! draws its own, and switching the effect changes no other realisation.

use rand::Rng;
use rand_chacha::ChaCha20Rng;
use serde::Deserialize;

/// `[world.time_tags]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeTagsSpec {
    /// Whether the effect is applied.
    #[serde(default = "super::yes")]
    pub enabled: bool,
    /// The odometer's latency: the sample stamped `t` is the distance up to `t − L`, s.
    pub odometer_latency_s: f64,
    /// Half-width of the GNSS stamp's jitter, s (whole milliseconds).
    pub gnss_jitter_s: f64,
    /// Half-width of the odometer stamp's jitter, s.
    pub odometer_jitter_s: f64,
    /// Half-width of the star tracker stamp's jitter, s.
    pub star_tracker_jitter_s: f64,
}

/// One sensor's stamping: its latency and jitter, and the stream its jitter is drawn from.
#[derive(Debug, Clone)]
pub struct TimeTag {
    latency_ns: i64,
    jitter_ms: i64,
    rng: Option<ChaCha20Rng>,
}

impl TimeTag {
    /// Latency `latency_ns`, jitter half-width `jitter_s` (whole milliseconds, validated),
    /// jitter drawn from `rng`.
    pub fn new(latency_ns: i64, jitter_s: f64, rng: ChaCha20Rng) -> Self {
        let jitter_ms = (jitter_s * 1e3).round() as i64;
        Self {
            latency_ns,
            jitter_ms,
            rng: (jitter_ms > 0).then_some(rng),
        }
    }

    /// A constant latency, no jitter.
    pub fn fixed(latency_ns: i64) -> Self {
        Self {
            latency_ns,
            jitter_ms: 0,
            rng: None,
        }
    }

    /// The documented latency, ns.
    pub fn latency_ns(&self) -> i64 {
        self.latency_ns
    }

    /// Whether a stamp differs from its measurement instant.
    pub fn is_delayed(&self) -> bool {
        self.latency_ns != 0 || self.jitter_ms != 0
    }

    /// The measurement instant of the sample stamped `stamp_ns` (ns since the scenario
    /// epoch, not before 0); one draw per call.
    pub fn measurement_instant_ns(&mut self, stamp_ns: i64) -> i64 {
        let j_ms = match &mut self.rng {
            Some(rng) => rng.random_range(-self.jitter_ms..=self.jitter_ms),
            None => 0,
        };
        (stamp_ns - self.latency_ns - j_ms * 1_000_000).max(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::gauss_markov::mean_and_standard_error;
    use rand::SeedableRng;

    /// The car's odometer (10 ms, ±2 ms): every instant within `[t − L − J, t − L + J]` on the
    /// millisecond grid, mean lateness `L` and variance `J(J + 1)/3` ms² within 4 standard
    /// errors, independent from one sample to the next (lag-1 product within 4 SE of 0).
    #[test]
    fn jitter_is_uniform_on_whole_milliseconds_about_the_latency() {
        let mut tag = TimeTag::new(10_000_000, 0.002, ChaCha20Rng::seed_from_u64(7));
        let period = 100_000_000;
        let mut late_ms = Vec::new();
        for k in 1..=20_000i64 {
            let t = k * period;
            let m = tag.measurement_instant_ns(t);
            assert_eq!(m % 1_000_000, 0);
            let late = (t - m) as f64 * 1e-6;
            assert!((8.0..=12.0).contains(&late), "{late} ms");
            late_ms.push(late - 10.0);
        }
        let (mean, se) = mean_and_standard_error(&late_ms);
        assert!(mean.abs() < 4.0 * se, "mean {mean} ± {se}");
        let sq: Vec<f64> = late_ms.iter().map(|x| x * x).collect();
        let (var, se_v) = mean_and_standard_error(&sq);
        assert!(
            (var - 2.0).abs() < 4.0 * se_v,
            "variance {var} vs 2 ms² ± {se_v}"
        );
        let lag: Vec<f64> = late_ms.windows(2).map(|w| w[0] * w[1]).collect();
        let (c, se_c) = mean_and_standard_error(&lag);
        assert!(c.abs() < 4.0 * se_c, "lag-1 {c} ± {se_c}");
    }

    /// A world's stamps: the jitter is cut to the sensor's latency, so without the GNSS
    /// antenna's latency the fix is measured exactly at its stamp, and the odometer's instants
    /// stay within `L ± min(J, L)`.
    #[test]
    fn jitter_is_cut_to_the_latency() {
        let w = crate::world::WorldSection {
            time_tags: Some(TimeTagsSpec {
                enabled: true,
                odometer_latency_s: 0.001,
                gnss_jitter_s: 0.002,
                odometer_jitter_s: 0.003,
                star_tracker_jitter_s: 0.0,
            }),
            ..Default::default()
        };
        let (mut gnss, mut odo) = (
            w.time_tag(1, msgs::SensorId::Gnss),
            w.time_tag(1, msgs::SensorId::Odometer),
        );
        let mut seen = [false; 3];
        for k in 1..=1000i64 {
            let t = k * 50_000_000;
            assert_eq!(gnss.measurement_instant_ns(t), t);
            let late_ms = (t - odo.measurement_instant_ns(t)) / 1_000_000;
            assert!((0..=2).contains(&late_ms), "{late_ms} ms");
            seen[late_ms as usize] = true;
        }
        assert_eq!(seen, [true; 3]);
    }

    /// Without jitter the instant is the stamp less the latency, clamped at the start.
    #[test]
    fn fixed_latency_is_exact() {
        let mut tag = TimeTag::fixed(50_000_000);
        assert_eq!(tag.measurement_instant_ns(1_000_000_000), 950_000_000);
        assert_eq!(tag.measurement_instant_ns(0), 0);
        assert!(tag.is_delayed() && !TimeTag::fixed(0).is_delayed());
    }
}
