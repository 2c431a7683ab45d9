//! Carrier-phase tracking of the baseline phase differences: integer ambiguities, cycle slips
//! and the receiver's lock indicator (`[world.carrier_phase]`).
//!
//! A receiver measures the phase of the carrier only modulo one cycle: when a tracking loop
//! locks, the whole-cycle count it starts from is arbitrary, so the phase difference across a
//! baseline it publishes is `b·u/λ + N + ε` with an unknown integer `N`, constant for as long
//! as the loop keeps lock. This model draws `N` per satellite and baseline at every
//! acquisition (a satellite that rises, or reappears after it was not tracked at an epoch:
//! below the mask, in a receiver outage, or beyond the channel count) uniformly in
//! `±initial_ambiguity_cycles`.
//!
//! **Cycle slips**: the loop loses a whole number of cycles and re-locks, `N` jumps by
//! `±1…±max_slip_cycles` (uniform). On a car they come from fades (foliage, bridges, signs,
//! multipath), not from thermal noise: the thermal mean time between slips of a carrier loop
//! is `π²ρI₀(ρ)²/(2B_L)` (Viterbi; loop SNR `ρ = (C/N0)/B_L`) — for 35 dB-Hz in a 15 Hz loop,
//! `ρ ≈ 210`, practically never. Fades deep enough to break lock are more frequent the weaker
//! the signal is already, i.e. at low elevation; the model takes the rate per satellite and
//! baseline inversely proportional to C/N0 (linear), `rate = rate₄₅·10^{(45 − C/N0)/10}` —
//! one decade per 10 dB, so the 35 dB-Hz horizon slips ten times as often as the 45 dB-Hz
//! mid sky. Slips are a Poisson process of that rate, drawn per epoch with probability
//! `1 − exp(−rate·Δt)`.
//!
//! **Lock indicator**: the receiver reports per satellite and baseline the time its phase has
//! been tracked continuously (RINEX loss-of-lock indicator, u-blox `locktime`), restarted at
//! an acquisition and at every slip it detects, at an instant uniform within the epoch
//! interval (the loop re-locks between two epochs). A fraction `unflagged_fraction` of the
//! slips is not detected by the receiver: the integer changes while the lock time runs on,
//! so a user cannot rely on the indicator alone.
//!
//! Draws come from their own stream (`"world_carrier_phase"`), a fixed number per satellite
//! and epoch whether visible or not, so switching the effect changes no other realisation and
//! the stream does not depend on the geometry.

use super::yes;
use rand::Rng;
use rand_chacha::ChaCha20Rng;
use serde::Deserialize;

/// `[world.carrier_phase]`: integer ambiguity, cycle slips and lock indicator of the baseline
/// carrier-phase differences.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CarrierPhaseSpec {
    /// Whether the effect is applied (without it the phases are published with the integer
    /// already resolved, and never slip).
    #[serde(default = "yes")]
    pub enabled: bool,
    /// Cycle slips per hour of one satellite's baseline phase at 45 dB-Hz.
    pub slips_per_hour_at_45_dbhz: f64,
    /// Fraction of the slips the receiver does not detect (its lock time keeps running).
    pub unflagged_fraction: f64,
    /// Largest slip, whole cycles: a slip is `±1…±max_slip_cycles`, uniform.
    pub max_slip_cycles: u32,
    /// The integer drawn at an acquisition is uniform in `±initial_ambiguity_cycles`.
    pub initial_ambiguity_cycles: u32,
}

impl CarrierPhaseSpec {
    /// Slip rate of one satellite's baseline phase at `cn0_dbhz`, 1/s.
    pub fn slip_rate_per_s(&self, cn0_dbhz: f64) -> f64 {
        self.slips_per_hour_at_45_dbhz / 3600.0 * 10f64.powf((45.0 - cn0_dbhz) / 10.0)
    }
}

/// Uniform draws per satellite and epoch: per baseline slip, magnitude, sign, detection,
/// initial integer, re-lock instant.
const DRAWS_PER_BASELINE: usize = 6;
const DRAWS: usize = 2 * DRAWS_PER_BASELINE;

#[derive(Debug, Clone, Copy, Default)]
struct Track {
    /// Tracked at the previous epoch (lock continues).
    tracked: bool,
    /// Tracked at the current epoch.
    seen: bool,
    ambiguity_cycles: [i64; 2],
    lock_start_s: [f64; 2],
}

/// One satellite's baseline phases as tracked at an epoch.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TrackedPhase {
    /// The integer the receiver's phase differences carry (truth only), cycles.
    pub ambiguity_cycles: [i64; 2],
    /// The lock time the receiver reports, s.
    pub lock_time_s: [f64; 2],
}

/// Slip and acquisition counts since the start (truth, for tests and experiments).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SlipCounts {
    /// Acquisitions (new integer, lock time restarted) per satellite and baseline.
    pub acquisitions: u64,
    /// Slips the receiver flagged (lock time restarted).
    pub flagged: u64,
    /// Slips the receiver missed (lock time running on).
    pub unflagged: u64,
}

/// Carrier-phase tracking state of every satellite of the constellation.
#[derive(Debug, Clone)]
pub struct PhaseTracking {
    spec: Option<CarrierPhaseSpec>,
    rng: ChaCha20Rng,
    tracks: Vec<Track>,
    draws: Vec<[f64; DRAWS]>,
    t_s: f64,
    dt_s: f64,
    started: bool,
    counts: SlipCounts,
}

impl PhaseTracking {
    /// Tracking of `n_sats` satellites; `spec` None (or disabled): ambiguity resolved and no
    /// slips, the lock time still restarting at each acquisition.
    pub fn new(spec: Option<CarrierPhaseSpec>, n_sats: usize, rng: ChaCha20Rng) -> Self {
        Self {
            spec: spec.filter(|s| s.enabled),
            rng,
            tracks: vec![Track::default(); n_sats],
            draws: vec![[0.0; DRAWS]; n_sats],
            t_s: 0.0,
            dt_s: 0.0,
            started: false,
            counts: SlipCounts::default(),
        }
    }

    /// Whether ambiguities and slips are simulated.
    pub fn is_on(&self) -> bool {
        self.spec.is_some()
    }

    /// Counts since the start.
    pub fn counts(&self) -> SlipCounts {
        self.counts
    }

    /// Start the epoch at `t_s`: satellites not tracked at the previous epoch lose lock, and
    /// the epoch's draws are made for every satellite.
    pub fn begin_epoch(&mut self, t_s: f64) {
        self.dt_s = if self.started {
            (t_s - self.t_s).max(0.0)
        } else {
            0.0
        };
        self.started = true;
        self.t_s = t_s;
        for t in &mut self.tracks {
            t.tracked = t.seen;
            t.seen = false;
        }
        if self.spec.is_some() {
            for d in &mut self.draws {
                for x in d.iter_mut() {
                    *x = self.rng.random::<f64>();
                }
            }
        }
    }

    /// Satellite `i` (0-based) is tracked at this epoch with `cn0_dbhz`: its integers and lock
    /// times after this epoch's acquisition or slips.
    pub fn track(&mut self, i: usize, cn0_dbhz: f64) -> TrackedPhase {
        let (t_s, dt_s) = (self.t_s, self.dt_s);
        let Some(tr) = self.tracks.get_mut(i) else {
            return TrackedPhase::default();
        };
        let d = self.draws[i];
        let continuing = tr.tracked;
        tr.seen = true;
        for k in 0..2 {
            let u = &d[k * DRAWS_PER_BASELINE..(k + 1) * DRAWS_PER_BASELINE];
            // Re-lock at an instant uniform within the last interval.
            let relock_s = t_s - u[5] * dt_s;
            if !continuing {
                self.counts.acquisitions += 1;
                tr.lock_start_s[k] = relock_s;
                tr.ambiguity_cycles[k] = match self.spec {
                    Some(s) => {
                        let r = f64::from(s.initial_ambiguity_cycles);
                        ((2.0 * u[4] - 1.0) * r).round() as i64
                    }
                    None => 0,
                };
                continue;
            }
            let Some(s) = self.spec else { continue };
            let p_slip = 1.0 - (-s.slip_rate_per_s(cn0_dbhz) * dt_s).exp();
            if u[0] < p_slip {
                let size = 1
                    + ((u[1] * f64::from(s.max_slip_cycles.max(1))) as i64)
                        .min(i64::from(s.max_slip_cycles.max(1)) - 1);
                tr.ambiguity_cycles[k] += if u[2] < 0.5 { -size } else { size };
                if u[3] < s.unflagged_fraction {
                    self.counts.unflagged += 1;
                } else {
                    self.counts.flagged += 1;
                    tr.lock_start_s[k] = relock_s;
                }
            }
        }
        TrackedPhase {
            ambiguity_cycles: tr.ambiguity_cycles,
            lock_time_s: [t_s - tr.lock_start_s[0], t_s - tr.lock_start_s[1]],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn spec() -> CarrierPhaseSpec {
        CarrierPhaseSpec {
            enabled: true,
            slips_per_hour_at_45_dbhz: 2.0,
            unflagged_fraction: 0.1,
            max_slip_cycles: 3,
            initial_ambiguity_cycles: 1000,
        }
    }

    fn rng() -> ChaCha20Rng {
        ChaCha20Rng::seed_from_u64(7)
    }

    /// Integers are arbitrary and different per satellite and baseline at acquisition,
    /// constant over a continuous arc without slips, re-drawn when a satellite reappears; the
    /// lock time runs with the epochs and restarts below one interval at a reacquisition.
    #[test]
    fn integers_are_constant_over_an_arc_and_redrawn_at_reacquisition() {
        let s = CarrierPhaseSpec {
            slips_per_hour_at_45_dbhz: 0.0,
            ..spec()
        };
        let mut tr = PhaseTracking::new(Some(s), 4, rng());
        let mut first = [TrackedPhase::default(); 4];
        for e in 0..100 {
            tr.begin_epoch(f64::from(e));
            for (i, f) in first.iter_mut().enumerate() {
                let p = tr.track(i, 45.0);
                if e == 0 {
                    *f = p;
                    assert!(p.lock_time_s.iter().all(|l| *l == 0.0));
                } else {
                    assert_eq!(p.ambiguity_cycles, f.ambiguity_cycles);
                    for k in 0..2 {
                        assert!((p.lock_time_s[k] - f64::from(e)).abs() < 1e-9);
                    }
                }
            }
        }
        let all: Vec<i64> = first.iter().flat_map(|p| p.ambiguity_cycles).collect();
        let distinct: std::collections::BTreeSet<_> = all.iter().collect();
        assert_eq!(distinct.len(), 8, "{all:?}");
        assert!(all.iter().all(|n| n.abs() <= 1000));
        // Satellite 0 not tracked at epoch 100: at 101 it is reacquired with new integers.
        tr.begin_epoch(100.0);
        tr.begin_epoch(101.0);
        let p = tr.track(0, 45.0);
        assert_ne!(p.ambiguity_cycles, first[0].ambiguity_cycles);
        assert!(p.lock_time_s.iter().all(|l| (0.0..1.0).contains(l)));
        assert_eq!(tr.counts().acquisitions, 10);
    }

    /// Slip counts over 200 satellite-hours at 45 and at 35 dB-Hz: Poisson with the model's
    /// rate (within 4√mean), ten times as many at 35 dB-Hz; the undetected share within 4σ of
    /// its binomial; a flagged slip restarts the lock time, an unflagged one does not; sizes
    /// within ±max_slip_cycles and never 0.
    #[test]
    fn slip_rate_follows_cn0_and_some_slips_are_unflagged() {
        let s = spec();
        let n_sats = 20;
        let hours = 10.0;
        let dt = 1.0;
        for (cn0, factor) in [(45.0, 1.0), (35.0, 10.0)] {
            let mut tr = PhaseTracking::new(Some(s), n_sats, rng());
            let mut prev: Vec<TrackedPhase> = vec![TrackedPhase::default(); n_sats];
            let (mut flagged_seen, mut unflagged_seen) = (0u64, 0u64);
            let epochs = (hours * 3600.0 / dt) as usize;
            for e in 0..epochs {
                tr.begin_epoch(e as f64 * dt);
                for (i, pv) in prev.iter_mut().enumerate() {
                    let p = tr.track(i, cn0);
                    if e > 0 {
                        for k in 0..2 {
                            let jump = p.ambiguity_cycles[k] - pv.ambiguity_cycles[k];
                            let reset = p.lock_time_s[k] < dt;
                            assert!(jump.abs() <= i64::from(s.max_slip_cycles));
                            if jump != 0 {
                                if reset {
                                    flagged_seen += 1;
                                } else {
                                    unflagged_seen += 1;
                                }
                            } else {
                                assert!(!reset, "lock restarted without a slip");
                            }
                        }
                    }
                    *pv = p;
                }
            }
            let c = tr.counts();
            assert_eq!((c.flagged, c.unflagged), (flagged_seen, unflagged_seen));
            let total = (c.flagged + c.unflagged) as f64;
            let mean = s.slips_per_hour_at_45_dbhz * factor * hours * (2 * n_sats) as f64;
            assert!(
                (total - mean).abs() < 4.0 * mean.sqrt(),
                "{cn0} dB-Hz: {total} slips, expected {mean}"
            );
            let f = s.unflagged_fraction;
            let share = c.unflagged as f64 / total;
            assert!(
                (share - f).abs() < 4.0 * (f * (1.0 - f) / total).sqrt(),
                "unflagged share {share}"
            );
            assert!(c.unflagged > 0);
        }
    }

    /// Switched off: integer 0 (resolved), never a slip, no draws; the lock time still
    /// restarts at acquisition.
    #[test]
    fn off_means_resolved_and_no_slips() {
        let off = CarrierPhaseSpec {
            enabled: false,
            ..spec()
        };
        let mut tr = PhaseTracking::new(Some(off), 2, rng());
        assert!(!tr.is_on());
        for e in 0..1000 {
            tr.begin_epoch(f64::from(e));
            let p = tr.track(0, 30.0);
            assert_eq!(p.ambiguity_cycles, [0, 0]);
            assert!((p.lock_time_s[0] - f64::from(e)).abs() < 1e-9);
        }
        assert_eq!(tr.counts().flagged + tr.counts().unflagged, 0);
    }
}
