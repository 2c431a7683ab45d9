//! Pairing of the replayed solutions with the recorded ones for the bit-for-bit comparison of
//! an offline replay.
//!
//! The replay computes every solution; the file holds one per interval of its `nav` rate
//! (every one at rate 0), each recorded right after the input that produced it (the daemon
//! records the input, then its solution, from one thread, in that order). The two are paired by
//! number (`header.seq`). A replayed solution waits here until its recorded counterpart is
//! read, or a later recorded one shows it is not in the file — a mismatch when the source's
//! rate keeps it — or it is [`MATCH_HORIZON_NS`] older than the newest replayed solution: by
//! then its counterpart, which follows its input within milliseconds of data time, can no
//! longer come. The horizon bounds the memory whatever the file: an imported log, which has
//! inputs only, would otherwise keep every replayed solution of the run (≈ 390 MB per hour
//! at 200 Hz).

use super::compare_solutions;
use crate::recorder::{RateGate, log_time_of};
use msgs::NavSolution;
use std::collections::VecDeque;

/// How long a replayed solution waits for its recorded counterpart, ns of time of validity
/// after it: far beyond the lag of a recorded solution behind its input in the file (that of
/// the queue between the daemon and its recorder, milliseconds), and a bound on the waiting
/// solutions (2 000 at 200 Hz, 20 000 at 2 kHz).
pub const MATCH_HORIZON_NS: i64 = 10_000_000_000;

/// The comparison's figures (fields of the replay's summary of the same names).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MatchOutcome {
    /// Pairs compared.
    pub solutions_compared: u64,
    /// Pairs identical bit for bit.
    pub solutions_bit_identical: u64,
    /// The first difference, missing solution or unpaired recorded solution.
    pub first_mismatch: Option<String>,
    /// Replayed solutions the source's rate keeps that met no recorded counterpart: those
    /// still waiting at the end of the file and those that outlived the horizon.
    pub unmatched_expected: u64,
}

/// Replayed solutions waiting for their recorded counterparts (see the module comment).
#[derive(Debug)]
pub struct SolutionMatcher {
    /// Waiting solutions in number order, each with whether the source's rate keeps it.
    waiting: VecDeque<(NavSolution, bool)>,
    /// The source's `nav` rate, run on the replayed solutions.
    kept: RateGate,
    /// Recorded solutions met so far.
    recorded: u64,
    /// Kept solutions that outlived the horizon before the file showed any solution (an
    /// inputs-only file has none: not a mismatch there, see [`Self::finish`]).
    expired_before_any: u64,
    out: MatchOutcome,
}

impl SolutionMatcher {
    /// A matcher for a file whose `nav` channel keeps one solution per `1/solution_rate_hz`
    /// (0: every solution).
    pub fn new(solution_rate_hz: f64) -> Self {
        Self {
            waiting: VecDeque::new(),
            kept: RateGate::new(solution_rate_hz),
            recorded: 0,
            expired_before_any: 0,
            out: MatchOutcome::default(),
        }
    }

    /// Solutions waiting now.
    #[cfg(test)]
    pub fn waiting(&self) -> usize {
        self.waiting.len()
    }

    /// A solution the replay computed (numbers increase).
    pub fn replayed(&mut self, sol: NavSolution) {
        let expected = self
            .kept
            .admit(log_time_of(sol.header.time_ns).unwrap_or(0));
        let horizon = sol.header.time_ns.saturating_sub(MATCH_HORIZON_NS);
        self.give_up_while(|old| old.header.time_ns < horizon);
        self.waiting.push_back((sol, expected));
    }

    /// A solution read from the file: compared with the replayed one of its number.
    pub fn recorded(&mut self, recorded: &NavSolution) {
        self.recorded += 1;
        // Replayed solutions before this one: left out by the source's rate, or missing.
        self.give_up_while(|mine| mine.header.seq < recorded.header.seq);
        match self.waiting.pop_front() {
            Some((mine, _)) if mine.header.seq == recorded.header.seq => {
                self.out.solutions_compared += 1;
                match compare_solutions(recorded, &mine) {
                    Ok(()) => self.out.solutions_bit_identical += 1,
                    Err(d) => self.mismatch(|| {
                        format!(
                            "solution {} (time {} ns): {d}",
                            recorded.header.seq, recorded.header.time_ns
                        )
                    }),
                }
            }
            other => {
                if let Some(o) = other {
                    self.waiting.push_front(o);
                }
                self.mismatch(|| {
                    format!(
                        "recorded solution {} (time {} ns) has no replayed counterpart",
                        recorded.header.seq, recorded.header.time_ns
                    )
                });
            }
        }
    }

    /// The outcome at the end of the file. Kept solutions still waiting are missing from a
    /// complete file (the last ones of a file cut by a crash legitimately are, not counted as
    /// a difference); a file without any solution (inputs only) has nothing to compare.
    pub fn finish(mut self, recording_complete: bool) -> MatchOutcome {
        let left = self
            .waiting
            .iter()
            .filter(|(_, expected)| *expected)
            .count() as u64;
        self.out.unmatched_expected += left;
        if self.recorded > 0 && self.expired_before_any > 0 {
            let n = self.expired_before_any;
            self.mismatch(|| format!("{n} replayed solutions before the first recorded one are missing from the recording"));
        }
        if recording_complete && left > 0 && self.recorded > 0 {
            self.mismatch(|| format!("{left} replayed solutions have no recorded counterpart"));
        }
        self.out
    }

    /// Stop waiting for the solutions at the front for which `gone` holds: those the source's
    /// rate keeps are missing from the file.
    fn give_up_while(&mut self, gone: impl Fn(&NavSolution) -> bool) {
        while let Some(&(old, expected)) = self.waiting.front().filter(|(old, _)| gone(old)) {
            if expected {
                self.missing(old.header.seq, old.header.time_ns);
            }
            self.waiting.pop_front();
        }
    }

    /// A kept solution absent from the file.
    fn missing(&mut self, seq: u64, time_ns: i64) {
        self.out.unmatched_expected += 1;
        if self.recorded == 0 {
            self.expired_before_any += 1;
            return;
        }
        self.mismatch(|| {
            format!("replayed solution {seq} (time {time_ns} ns) is missing from the recording")
        });
    }

    fn mismatch(&mut self, what: impl FnOnce() -> String) {
        if self.out.first_mismatch.is_none() {
            self.out.first_mismatch = Some(what());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: i64 = 1_000_000;
    /// A GPS time well after 1980 (2026), ns.
    const T0: i64 = 1_450_000_000_000_000_000;

    fn sol(seq: u64, t_ns: i64) -> NavSolution {
        let mut s = NavSolution::default();
        s.header.seq = seq;
        s.header.time_ns = t_ns;
        s.lat_rad = seq as f64 * 1e-9;
        s
    }

    /// Every solution recorded: all pairs compared, nothing waits, bit exact.
    #[test]
    fn every_solution_pairs() {
        let mut m = SolutionMatcher::new(0.0);
        for k in 1..=1000 {
            let s = sol(k, T0 + k as i64 * 5 * MS);
            m.replayed(s);
            m.recorded(&s);
            assert_eq!(m.waiting(), 0);
        }
        let out = m.finish(true);
        assert_eq!(out.solutions_compared, 1000);
        assert_eq!(out.solutions_bit_identical, 1000);
        assert_eq!(out.first_mismatch, None);
        assert_eq!(out.unmatched_expected, 0);
    }

    /// A file at 10 Hz of a 200 Hz run: the solutions between the kept ones wait at most one
    /// interval (two around a missing one: 20 solutions each); a kept solution missing is
    /// named.
    #[test]
    fn a_thinned_file_pairs_the_kept_and_names_a_missing_one() {
        let mut m = SolutionMatcher::new(10.0);
        let mut gate = RateGate::new(10.0);
        let (mut most, mut kept) = (0, 0);
        let mut missing = None;
        for k in 1..=2000u64 {
            let s = sol(k, T0 + k as i64 * 5 * MS);
            m.replayed(s);
            if gate.admit(log_time_of(s.header.time_ns).unwrap()) {
                kept += 1;
                if kept == 50 {
                    missing = Some(k);
                    continue;
                }
                m.recorded(&s);
            }
            most = most.max(m.waiting());
        }
        assert!(most <= 41, "{most} solutions waited at once");
        let out = m.finish(true);
        assert_eq!(out.solutions_compared, kept - 1);
        assert_eq!(out.solutions_bit_identical, kept - 1);
        let missing = missing.unwrap();
        let msg = out.first_mismatch.expect("the missing solution is named");
        assert!(
            msg.contains(&format!("replayed solution {missing} ")),
            "{msg}"
        );
        assert_eq!(out.unmatched_expected, 1);
    }

    /// An inputs-only file (an imported log): an hour of 200 Hz solutions keeps at most the
    /// horizon's worth waiting, and is no mismatch — there is nothing to compare.
    #[test]
    fn an_inputs_only_file_keeps_the_memory_bounded() {
        let mut m = SolutionMatcher::new(0.0);
        let mut most = 0;
        for k in 1..=720_000u64 {
            m.replayed(sol(k, T0 + k as i64 * 5 * MS));
            most = most.max(m.waiting());
        }
        assert_eq!(most as i64, MATCH_HORIZON_NS / (5 * MS) + 1);
        let out = m.finish(true);
        assert_eq!(out.solutions_compared, 0);
        assert_eq!(
            out.first_mismatch, None,
            "no recorded solution, no mismatch"
        );
    }

    /// A solution missing before the first recorded one is a mismatch once the file shows
    /// it records solutions; one whose recorded counterpart comes after the horizon is
    /// reported as unpaired.
    #[test]
    fn missing_before_the_first_and_beyond_the_horizon() {
        let mut m = SolutionMatcher::new(0.0);
        let first = sol(1, T0);
        m.replayed(first);
        let late = sol(2, T0 + MATCH_HORIZON_NS + MS);
        m.replayed(late);
        m.recorded(&late);
        let out = m.finish(true);
        assert_eq!(out.solutions_compared, 1);
        let msg = out
            .first_mismatch
            .expect("the expired solution is reported");
        assert!(msg.contains("before the first recorded one"), "{msg}");

        let mut m = SolutionMatcher::new(0.0);
        m.replayed(first);
        m.replayed(late);
        m.recorded(&first);
        let out = m.finish(true);
        let msg = out
            .first_mismatch
            .expect("an unpaired recorded solution is reported");
        assert!(msg.contains("has no replayed counterpart"), "{msg}");
    }

    /// The end of a file cut by a crash: the solutions after the last recorded one are no
    /// difference; in a complete file they are.
    #[test]
    fn the_tail_of_a_cut_file_is_no_difference() {
        for complete in [false, true] {
            let mut m = SolutionMatcher::new(0.0);
            for k in 1..=10 {
                let s = sol(k, T0 + k as i64 * 5 * MS);
                m.replayed(s);
                if k <= 8 {
                    m.recorded(&s);
                }
            }
            let out = m.finish(complete);
            assert_eq!(out.unmatched_expected, 2);
            assert_eq!(out.first_mismatch.is_some(), complete);
        }
    }
}
