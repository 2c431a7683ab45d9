//! Integer ambiguity resolution for the dual-baseline attitude (paper 003, eq. 14–21,
//! [`crate::baseline_attitude`]): the receiver's phase difference across baseline `j` to
//! satellite `k` is `φ_kj = b_j·u_k/λ + N_kj + ε` with an unknown integer `N_kj`, constant while
//! the receiver keeps lock. This module finds the integers, keeps them from epoch to epoch,
//! detects slips and wrong fixes, and hands the resolved phases `φ − N` to the attitude solver.
//!
//! **Search** (attitude determination with known baseline lengths: the "constrained search"
//! family — Hatch's primary/secondary satellite split as used by Knight, "A new method of
//! instantaneous ambiguity resolution", ION GPS 1994; Teunissen's LAMBDA decorrelation is not
//! needed at this size): three primary satellites, the triple with the largest
//! `|det[u_a u_b u_c]|`, fix the baseline through `U b = λ(φ − N)`. For a baseline of length
//! `d` every primary integer lies in `φ − N ∈ [−d/λ, d/λ]` (±5.3 cycles for 1 m at L1), so
//! each baseline has about `(2d/λ + 1)³` candidate triples (≈ 1500). A candidate is kept when
//! its length is within `k σ_len` of `d` (`σ_len² = λ²σ_φ² b̂ᵀ(UᵀU)⁻¹b̂`) and every other
//! satellite's phase lies within `k σ` of an integer (`σ² = σ_φ²(1 + uᵀ(UᵀU)⁻¹u)`), a pair of AB and CD
//! candidates when `|b_AB·b_CD| ≤ k σ_dot` (perpendicular baselines;
//! `σ_dot² = λ²σ_φ²(b_CDᵀ(UᵀU)⁻¹b_CD + b_ABᵀ(UᵀU)⁻¹b_AB)`). Each surviving pair gives an
//! attitude (Gram–Schmidt), the integers of every satellite by rounding `φ − b·u/λ`, and the
//! constrained Gauss–Newton solution on all of them; its weighted residual
//! `χ² = Σ (λ(φ − N) − b·u)²/(λσ_φ)²` has `2n − 3` degrees of freedom.
//!
//! **Validation**: the best set is accepted when (1) its χ² passes the chi-square test at the
//! configured probability and (2) the ratio test holds, `χ²_second / χ²_best ≥ ratio`, the
//! second-best being the best *different* integer set (none left: infinite ratio, the length,
//! secondary-satellite and perpendicularity gates having excluded every other — the usual
//! case at σ_φ = 0.01 cycle with 5 or more satellites). Otherwise the epoch is *float only*:
//! no attitude is given.
//!
//! **Hold and re-fix**: accepted integers are held per satellite (by PRN) while the receiver
//! keeps lock. A held satellite is dropped when it disappears, or when its lock time shows a
//! restart (it decreased, or is below the interval since the last epoch: the receiver re-locked
//! in between). Each epoch the held satellites alone give the attitude (≥ 3 of them, so the
//! χ² has ≥ 3 degrees of freedom) and its χ² is tested; a failure is a slip the receiver did
//! not flag, or a wrong fix: with ≥ 4 held satellites the satellite whose exclusion passes the
//! test with the least χ² is dropped (a residual test per satellite), otherwise every held
//! integer is dropped and the search runs again in the same epoch. New and slipped satellites
//! are re-fixed from the held attitude: the predicted phase `b_j·u/λ` has variance
//! `J P Jᵀ/λ² + σ_φ²` (`J = (b_j × u)ᵀ`, `P` the attitude covariance), and the integer is the
//! rounding of `φ − b_j·u/λ` when `k σ ≤ 0.5` (the rounding is then wrong with probability
//! `2Φ(−k) ≈ 6·10⁻⁷`) and the residual is within `k σ`; the set with the new satellites must
//! pass the χ² test again, else they wait for the next epoch.
//!
//! `k = 5` for every gate of the search and the re-fix: a correct candidate is lost with
//! probability `2Φ(−5) ≈ 6·10⁻⁷` per test. What decides between candidates is the χ² and ratio
//! test, not `k`.
//!
//! Limits: the line bias between the antennas' receiver channels is taken as zero (as the
//! simulator's receiver has it; a real pair of receivers needs between-satellite differences);
//! candidates are kept in fixed arrays of [`CANDIDATE_CAPACITY`] per baseline; with the
//! secondary satellites' check a handful survive even for 5 m at L1 (the length gate alone
//! leaves ≈ 50 for 1 m and ≈ 1000 for 5 m), more only with few satellites and long baselines
//! ([`AmbiguityError::TooManyCandidates`]). The enumeration itself grows as `(2d/λ + 1)³`:
//! ≈ 1500 triples for 1 m, ≈ 150 000 for 5 m (about a millisecond). Pure, allocation-free (stack arrays, at most
//! [`MAX_SATELLITES`] satellites).

use crate::baseline_attitude::{
    self as ba, BaselineAttitude, BaselineAttitudeError, BaselineConfig, FLAG_PHASE,
    PhaseObservation, PhaseObservations,
};
use crate::ekf::chi2_quantile;
use msgs::{GnssSample, MAX_SATELLITES};
use nalgebra::{Matrix3, Vector3};

/// Gate width of the search and the re-fix, σ (module docs).
pub const GATE_SIGMAS: f64 = 5.0;
/// Candidates kept per baseline in a search.
pub const CANDIDATE_CAPACITY: usize = 512;
/// Satellites a search needs (2n − 3 = 5 degrees of freedom for the χ² and ratio tests).
pub const MIN_SEARCH_SATELLITES: usize = 4;
/// Held satellites the held attitude needs (2n − 3 = 3 degrees of freedom).
pub const MIN_HELD_SATELLITES: usize = 3;
/// Tolerance of the lock-time comparison, s (receivers report it to the millisecond).
const LOCK_TOLERANCE_S: f64 = 1e-3;

/// Why an epoch gives no integer-fixed attitude.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum AmbiguityError {
    /// Too few satellites with baseline phases to search (and none held).
    #[error("{have} satellites with baseline phases, a search needs {need}")]
    TooFewSatellites {
        /// Satellites with phases.
        have: usize,
        /// Needed.
        need: usize,
    },
    /// No integer set satisfies the baseline lengths, their perpendicularity and the phases.
    #[error("no integer candidate fits the baseline lengths and the phases")]
    NoCandidate,
    /// More candidates than the search holds (a baseline too long for an unaided search).
    #[error("more than {capacity} integer candidates for baseline {baseline}")]
    TooManyCandidates {
        /// 0 = AB, 1 = CD.
        baseline: usize,
        /// The capacity.
        capacity: usize,
    },
    /// The best and second-best integer sets are too close to tell (float only).
    #[error("ratio test failed: second/best χ² = {ratio:.2} < {threshold:.2}")]
    RatioTest {
        /// χ²_second / χ²_best.
        ratio: f64,
        /// The configured threshold.
        threshold: f64,
    },
    /// The best integer set's phase residuals fail the chi-square test.
    #[error("phase residual χ² = {chi2:.1} above {threshold:.1} ({dof} dof)")]
    ChiSquare {
        /// Weighted residual sum.
        chi2: f64,
        /// Threshold at the configured probability.
        threshold: f64,
        /// Degrees of freedom.
        dof: u32,
    },
    /// The attitude solver failed on the resolved phases.
    #[error("attitude solver: {0}")]
    Solver(BaselineAttitudeError),
    /// A configuration value cannot be physical.
    #[error("invalid {field} = {value}")]
    Invalid {
        /// Which value.
        field: &'static str,
        /// The value.
        value: f64,
    },
}

impl AmbiguityError {
    /// Whether the search ran but could not validate an integer set (float only), as opposed
    /// to an epoch rejected outright.
    pub fn is_float_only(&self) -> bool {
        matches!(self, Self::RatioTest { .. } | Self::NoCandidate)
    }
}

/// Resolution settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AmbiguityConfig {
    /// Antenna geometry and phase σ.
    pub baseline: BaselineConfig,
    /// Ratio test threshold `χ²_second / χ²_best`, ≥ 1.
    pub ratio_threshold: f64,
    /// Probability of the chi-square test on the phase residuals, e.g. 0.999.
    pub chi2_probability: f64,
}

/// One satellite's ambiguous phases as the receiver gives them.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RawPhase {
    /// Satellite number (the key the integers are held by).
    pub prn: u32,
    /// Unit line of sight receiver → satellite, ECEF (normalised by [`RawPhases::push`]).
    pub los_e: Vector3<f64>,
    /// Phase differences across AB and CD, cycles, with their unknown integers.
    pub phase_cycles: [f64; 2],
    /// Continuous lock time of each, s.
    pub lock_time_s: [f64; 2],
}

/// Up to [`MAX_SATELLITES`] raw phases (fixed-size).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RawPhases {
    obs: [RawPhase; MAX_SATELLITES],
    n: usize,
}

impl Default for RawPhases {
    fn default() -> Self {
        Self {
            obs: [RawPhase::default(); MAX_SATELLITES],
            n: 0,
        }
    }
}

impl RawPhases {
    /// Add one satellite (line of sight normalised); non-finite values are refused.
    pub fn push(&mut self, o: RawPhase) -> Result<(), AmbiguityError> {
        let norm = o.los_e.norm();
        if !(norm.is_finite() && norm > 0.0) {
            return Err(AmbiguityError::Invalid {
                field: "line of sight norm",
                value: norm,
            });
        }
        for v in o.phase_cycles.iter().chain(&o.lock_time_s) {
            if !v.is_finite() {
                return Err(AmbiguityError::Invalid {
                    field: "phase or lock time",
                    value: *v,
                });
            }
        }
        if self.n < MAX_SATELLITES {
            self.obs[self.n] = RawPhase {
                los_e: o.los_e / norm,
                ..o
            };
            self.n += 1;
        }
        Ok(())
    }

    /// The satellites of a receiver message that carry baseline phases, lines of sight from
    /// `r_e_m` (ECEF, m; metres of error are negligible at orbital distance).
    pub fn from_sample(sample: &GnssSample, r_e_m: &Vector3<f64>) -> Result<Self, AmbiguityError> {
        let mut out = Self::default();
        let n = (sample.n_satellites as usize).min(MAX_SATELLITES);
        for s in sample.satellites[..n]
            .iter()
            .filter(|s| s.flags & FLAG_PHASE != 0)
        {
            out.push(RawPhase {
                prn: s.prn,
                los_e: Vector3::from(s.sat_pos_ecef_m) - r_e_m,
                phase_cycles: s.baseline_phase_cycles,
                lock_time_s: s.phase_lock_time_s,
            })?;
        }
        Ok(out)
    }

    /// The satellites.
    pub fn as_slice(&self) -> &[RawPhase] {
        &self.obs[..self.n]
    }
}

/// An integer-fixed attitude and what happened to the integers this epoch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resolution {
    /// The attitude from the resolved phases of the fixed satellites.
    pub attitude: BaselineAttitude,
    /// χ² threshold the attitude passed (its `chi2` is below it).
    pub chi2_threshold: f64,
    /// Satellites whose integers are held after this epoch (those in the attitude).
    pub n_fixed: usize,
    /// Of those, fixed this epoch (by a search or re-fixed from the held attitude).
    pub n_new: usize,
    /// Whether the integers came from a search this epoch.
    pub searched: bool,
    /// The search's ratio `χ²_second / χ²_best` (searched epochs).
    pub ratio: Option<f64>,
    /// Held satellites dropped because their lock time restarted (a slip the receiver
    /// flagged, or a reacquisition since the last epoch given).
    pub slips_flagged: usize,
    /// Held satellites dropped by the residual test (a slip the receiver did not flag).
    pub slips_detected: usize,
    /// Whether the whole held set failed the residual test (a wrong fix or several slips)
    /// and was replaced by a new search.
    pub held_set_rejected: bool,
}

#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Held {
    prn: u32,
    integer_cycles: [i64; 2],
    lock_time_s: [f64; 2],
}

/// Per-satellite integer state across epochs (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct AmbiguityResolver {
    config: AmbiguityConfig,
    held: [Held; MAX_SATELLITES],
    n_held: usize,
    last_t_s: Option<f64>,
}

/// The outcome of one epoch together with the slip counts of the lock test, which happen
/// before the epoch can fail.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EpochOutcome {
    /// The fixed attitude, or why there is none.
    pub result: Result<Resolution, AmbiguityError>,
    /// Held satellites dropped because their lock time restarted (a slip the receiver
    /// flagged, or a reacquisition since the last epoch given).
    pub slips_flagged: usize,
    /// Held satellites dropped by the residual test.
    pub slips_detected: usize,
    /// Whether the whole held set was rejected by the residual test.
    pub held_set_rejected: bool,
}

fn check_config(c: &AmbiguityConfig) -> Result<(), AmbiguityError> {
    let bad = |field, value| Err(AmbiguityError::Invalid { field, value });
    for d in c.baseline.baseline_length_m {
        if !(d.is_finite() && d > 0.0) {
            return bad("baseline_length_m", d);
        }
    }
    if !(c.baseline.wavelength_m.is_finite() && c.baseline.wavelength_m > 0.0) {
        return bad("wavelength_m", c.baseline.wavelength_m);
    }
    let s = c.baseline.sigma_phase_cycles;
    if !(s.is_finite() && s > 0.0 && GATE_SIGMAS * s < 0.5) {
        // Above 0.1 cycle no rounding is reliable.
        return bad("sigma_phase_cycles", s);
    }
    if !(c.ratio_threshold.is_finite() && c.ratio_threshold >= 1.0) {
        return bad("ratio_threshold", c.ratio_threshold);
    }
    if !(c.chi2_probability > 0.5 && c.chi2_probability < 1.0) {
        return bad("chi2_probability", c.chi2_probability);
    }
    Ok(())
}

/// Resolved phases `φ − N` of the satellites `sats` with integers `ints`.
fn resolved(sats: &[RawPhase], ints: &[[i64; 2]]) -> PhaseObservations {
    let mut o = PhaseObservations::default();
    for (s, n) in sats.iter().zip(ints) {
        // Finite values, unit line of sight: cannot fail.
        let _ = o.push(PhaseObservation {
            los_e: s.los_e,
            phase_cycles: [
                s.phase_cycles[0] - n[0] as f64,
                s.phase_cycles[1] - n[1] as f64,
            ],
        });
    }
    o
}

/// Integers of `sats` by rounding against the attitude `c_e_b`.
fn round_against(
    sats: &[RawPhase],
    c_e_b: &Matrix3<f64>,
    cfg: &BaselineConfig,
    out: &mut [[i64; 2]; MAX_SATELLITES],
) {
    let b = baselines(c_e_b, cfg);
    for (s, n) in sats.iter().zip(out.iter_mut()) {
        for j in 0..2 {
            n[j] = (s.phase_cycles[j] - b[j].dot(&s.los_e) / cfg.wavelength_m).round() as i64;
        }
    }
}

fn baselines(c_e_b: &Matrix3<f64>, cfg: &BaselineConfig) -> [Vector3<f64>; 2] {
    [
        c_e_b.column(0) * cfg.baseline_length_m[0],
        c_e_b.column(1) * cfg.baseline_length_m[1],
    ]
}

fn chi2_threshold(c: &AmbiguityConfig, n_sats: usize) -> (u32, f64) {
    let dof = (2 * n_sats).saturating_sub(3).max(1) as u32;
    (dof, chi2_quantile(dof, c.chi2_probability))
}

/// One candidate of the search.
#[derive(Clone, Copy)]
struct Candidate {
    chi2: f64,
    ints: [[i64; 2]; MAX_SATELLITES],
}

impl AmbiguityResolver {
    /// A resolver with nothing held.
    pub fn new(config: AmbiguityConfig) -> Result<Self, AmbiguityError> {
        check_config(&config)?;
        Ok(Self {
            config,
            held: [Held::default(); MAX_SATELLITES],
            n_held: 0,
            last_t_s: None,
        })
    }

    /// The settings.
    pub fn config(&self) -> &AmbiguityConfig {
        &self.config
    }

    /// Replace the antenna geometry (a receiver message reports it each epoch); a change
    /// drops every held integer.
    pub fn set_baseline(&mut self, baseline: BaselineConfig) -> Result<(), AmbiguityError> {
        if baseline != self.config.baseline {
            let c = AmbiguityConfig {
                baseline,
                ..self.config
            };
            check_config(&c)?;
            self.config = c;
            self.reset();
        }
        Ok(())
    }

    /// Drop every held integer.
    pub fn reset(&mut self) {
        self.n_held = 0;
    }

    /// The integers held for satellite `prn`, cycles.
    pub fn held(&self, prn: u32) -> Option<[i64; 2]> {
        self.held[..self.n_held]
            .iter()
            .find(|h| h.prn == prn)
            .map(|h| h.integer_cycles)
    }

    /// Number of satellites with held integers.
    pub fn n_held(&self) -> usize {
        self.n_held
    }

    /// Test-only: hold integers for a satellite, as a wrong fix would.
    #[cfg(test)]
    fn force_hold(&mut self, prn: u32, integer_cycles: [i64; 2], lock_time_s: [f64; 2]) {
        if let Some(h) = self.held[..self.n_held].iter_mut().find(|h| h.prn == prn) {
            h.integer_cycles = integer_cycles;
        } else if self.n_held < MAX_SATELLITES {
            self.held[self.n_held] = Held {
                prn,
                integer_cycles,
                lock_time_s,
            };
            self.n_held += 1;
        }
    }

    fn drop_held(&mut self, k: usize) {
        self.held.copy_within(k + 1..self.n_held, k);
        self.n_held -= 1;
    }

    /// One epoch at time `t_s` (s, increasing) with the receiver's phases `sats`, receiver
    /// position `r_e_m` (ECEF, m; for the NED angles of the result) and an optional attitude
    /// to start the solver from (`prior_c_e_b`, e.g. the inertial one; the result does not
    /// depend on it).
    pub fn resolve(
        &mut self,
        t_s: f64,
        sats: &RawPhases,
        r_e_m: &Vector3<f64>,
        prior_c_e_b: Option<&Matrix3<f64>>,
    ) -> EpochOutcome {
        let dt_s = self.last_t_s.map(|t| t_s - t);
        self.last_t_s = Some(t_s);
        let all = sats.as_slice();
        // 1. The receiver's lock indicator and lost satellites.
        let mut slips_flagged = 0;
        let mut k = 0;
        while k < self.n_held {
            let h = self.held[k];
            let Some(s) = all.iter().find(|s| s.prn == h.prn) else {
                self.drop_held(k);
                continue;
            };
            let restarted = (0..2).any(|j| {
                s.lock_time_s[j] + LOCK_TOLERANCE_S < h.lock_time_s[j]
                    || dt_s.is_some_and(|dt| s.lock_time_s[j] + LOCK_TOLERANCE_S < dt)
            });
            if restarted {
                slips_flagged += 1;
                self.drop_held(k);
                continue;
            }
            self.held[k].lock_time_s = s.lock_time_s;
            k += 1;
        }
        let mut out = EpochOutcome {
            result: Err(AmbiguityError::NoCandidate),
            slips_flagged,
            slips_detected: 0,
            held_set_rejected: false,
        };
        // 2. The held set: its attitude and residual test.
        if self.n_held > 0 {
            match self.held_attitude(all, r_e_m, prior_c_e_b) {
                Ok((att, detected)) => {
                    out.slips_detected = detected;
                    out.result = Ok(self.refix(all, r_e_m, att, slips_flagged, detected));
                    return out;
                }
                Err(detected) => {
                    out.slips_detected = detected;
                    out.held_set_rejected = true;
                    self.reset();
                }
            }
        }
        // 3. No usable held set: search.
        out.result = self.search(all, r_e_m).map(|mut r| {
            r.slips_flagged = out.slips_flagged;
            r.slips_detected = out.slips_detected;
            r.held_set_rejected = out.held_set_rejected;
            r
        });
        out
    }

    /// The attitude of the held satellites that passes the χ² test, after dropping at most
    /// one satellite by the residual test; with the number dropped. Err(dropped) when no
    /// held set passes (too few held satellites count as a failure too: nothing to test).
    fn held_attitude(
        &mut self,
        all: &[RawPhase],
        r_e_m: &Vector3<f64>,
        prior: Option<&Matrix3<f64>>,
    ) -> Result<(BaselineAttitude, usize), usize> {
        let mut sats = [RawPhase::default(); MAX_SATELLITES];
        let mut ints = [[0i64; 2]; MAX_SATELLITES];
        let n = self.n_held;
        if n < MIN_HELD_SATELLITES {
            return Err(0);
        }
        for (k, h) in self.held[..n].iter().enumerate() {
            // Present: step 1 dropped the absent ones.
            if let Some(s) = all.iter().find(|s| s.prn == h.prn) {
                sats[k] = *s;
            }
            ints[k] = h.integer_cycles;
        }
        let cfg = &self.config;
        let test = |sats: &[RawPhase], ints: &[[i64; 2]]| -> Option<BaselineAttitude> {
            let a = ba::solve(&resolved(sats, ints), &cfg.baseline, r_e_m, prior).ok()?;
            (a.chi2 <= chi2_threshold(cfg, sats.len()).1).then_some(a)
        };
        if let Some(a) = test(&sats[..n], &ints[..n]) {
            return Ok((a, 0));
        }
        if n <= MIN_HELD_SATELLITES {
            return Err(0);
        }
        // Leave one out: the satellite whose exclusion passes with the least χ².
        let mut best: Option<(usize, BaselineAttitude)> = None;
        for skip in 0..n {
            let mut s2 = [RawPhase::default(); MAX_SATELLITES];
            let mut i2 = [[0i64; 2]; MAX_SATELLITES];
            let mut m = 0;
            for k in (0..n).filter(|&k| k != skip) {
                s2[m] = sats[k];
                i2[m] = ints[k];
                m += 1;
            }
            if let Some(a) = test(&s2[..m], &i2[..m])
                && best.as_ref().is_none_or(|(_, b)| a.chi2 < b.chi2)
            {
                best = Some((skip, a));
            }
        }
        match best {
            Some((skip, a)) => {
                self.drop_held(skip);
                Ok((a, 1))
            }
            None => Err(0),
        }
    }

    /// Re-fix the satellites not held from the held attitude `att`; the resolution.
    fn refix(
        &mut self,
        all: &[RawPhase],
        r_e_m: &Vector3<f64>,
        att: BaselineAttitude,
        slips_flagged: usize,
        slips_detected: usize,
    ) -> Resolution {
        let cfg = self.config;
        let bl = &cfg.baseline;
        let lam = bl.wavelength_m;
        let b = baselines(&att.c_e_b, bl);
        let mut sats = [RawPhase::default(); MAX_SATELLITES];
        let mut ints = [[0i64; 2]; MAX_SATELLITES];
        let mut n = 0;
        for h in &self.held[..self.n_held] {
            if let Some(s) = all.iter().find(|s| s.prn == h.prn) {
                sats[n] = *s;
                ints[n] = h.integer_cycles;
                n += 1;
            }
        }
        let n_held = n;
        for s in all {
            if n >= MAX_SATELLITES || self.held(s.prn).is_some() {
                continue;
            }
            let mut cand = [0i64; 2];
            let mut ok = true;
            for j in 0..2 {
                let jac = b[j].cross(&s.los_e);
                let var_m2 = (jac.transpose() * att.cov_e_rad2 * jac)[(0, 0)];
                let sigma = (var_m2 / (lam * lam) + bl.sigma_phase_cycles.powi(2)).sqrt();
                let x = s.phase_cycles[j] - b[j].dot(&s.los_e) / lam;
                cand[j] = x.round() as i64;
                let r = x - cand[j] as f64;
                ok &= GATE_SIGMAS * sigma <= 0.5 && r.abs() <= GATE_SIGMAS * sigma;
            }
            if ok {
                sats[n] = *s;
                ints[n] = cand;
                n += 1;
            }
        }
        let mut result = Resolution {
            attitude: att,
            chi2_threshold: chi2_threshold(&cfg, n_held).1,
            n_fixed: n_held,
            n_new: 0,
            searched: false,
            ratio: None,
            slips_flagged,
            slips_detected,
            held_set_rejected: false,
        };
        if n > n_held {
            let (_, thr) = chi2_threshold(&cfg, n);
            if let Ok(a) = ba::solve(
                &resolved(&sats[..n], &ints[..n]),
                bl,
                r_e_m,
                Some(&att.c_e_b),
            ) && a.chi2 <= thr
            {
                for k in n_held..n {
                    self.hold(&sats[k], ints[k]);
                }
                result.attitude = a;
                result.chi2_threshold = thr;
                result.n_fixed = n;
                result.n_new = n - n_held;
            }
        }
        result
    }

    fn hold(&mut self, s: &RawPhase, integer_cycles: [i64; 2]) {
        if let Some(h) = self.held[..self.n_held].iter_mut().find(|h| h.prn == s.prn) {
            h.integer_cycles = integer_cycles;
            h.lock_time_s = s.lock_time_s;
        } else if self.n_held < MAX_SATELLITES {
            self.held[self.n_held] = Held {
                prn: s.prn,
                integer_cycles,
                lock_time_s: s.lock_time_s,
            };
            self.n_held += 1;
        }
    }

    /// The constrained search of every satellite's integers (module docs); on success the
    /// integers are held.
    fn search(
        &mut self,
        all: &[RawPhase],
        r_e_m: &Vector3<f64>,
    ) -> Result<Resolution, AmbiguityError> {
        let cfg = self.config;
        let bl = cfg.baseline;
        let lam = bl.wavelength_m;
        let n = all.len();
        if n < MIN_SEARCH_SATELLITES {
            return Err(AmbiguityError::TooFewSatellites {
                have: n,
                need: MIN_SEARCH_SATELLITES,
            });
        }
        // Primary triple: the largest |det|, i.e. the best-conditioned U.
        let mut best_det = 0.0;
        let mut prim = [0usize; 3];
        for a in 0..n {
            for b in a + 1..n {
                for c in b + 1..n {
                    let d = all[a].los_e.dot(&all[b].los_e.cross(&all[c].los_e)).abs();
                    if d > best_det {
                        best_det = d;
                        prim = [a, b, c];
                    }
                }
            }
        }
        let u = Matrix3::from_rows(&[
            all[prim[0]].los_e.transpose(),
            all[prim[1]].los_e.transpose(),
            all[prim[2]].los_e.transpose(),
        ]);
        let u_inv = u
            .try_inverse()
            .filter(|m| m.iter().all(|x| x.is_finite()) && m.norm() < 1e6)
            .ok_or(AmbiguityError::Solver(
                BaselineAttitudeError::SingularGeometry("lines of sight in one plane"),
            ))?;
        // Covariance of b per (λσ_φ)²: U⁻¹U⁻ᵀ.
        let g = u_inv * u_inv.transpose();
        let var_unit = (lam * bl.sigma_phase_cycles).powi(2);
        let mut cands = [[Vector3::<f64>::zeros(); CANDIDATE_CAPACITY]; 2];
        let mut n_c = [0usize; 2];
        for j in 0..2 {
            let d = bl.baseline_length_m[j];
            let half = d / lam + GATE_SIGMAS * bl.sigma_phase_cycles;
            let phi = [0, 1, 2].map(|i| all[prim[i]].phase_cycles[j]);
            let lo = phi.map(|p| (p - half).ceil() as i64);
            let hi = phi.map(|p| (p + half).floor() as i64);
            for n0 in lo[0]..=hi[0] {
                for n1 in lo[1]..=hi[1] {
                    for n2 in lo[2]..=hi[2] {
                        let y = Vector3::new(
                            phi[0] - n0 as f64,
                            phi[1] - n1 as f64,
                            phi[2] - n2 as f64,
                        ) * lam;
                        let b = u_inv * y;
                        let len = b.norm();
                        if len == 0.0 {
                            continue;
                        }
                        let bh = b / len;
                        let s_len = (var_unit * bh.dot(&(g * bh))).sqrt();
                        if (len - d).abs() > GATE_SIGMAS * s_len {
                            continue;
                        }
                        // Every other satellite's phase must sit near an integer of this
                        // baseline: residual to the nearest integer within k σ, σ² = σ_φ²(1 +
                        // uᵀ(UᵀU)⁻¹u). A wrong candidate passes each with probability ≈ 2kσ,
                        // so the few secondaries leave few of them.
                        let consistent = (0..n).filter(|i| !prim.contains(i)).all(|i| {
                            let u = &all[i].los_e;
                            let x = all[i].phase_cycles[j] - b.dot(u) / lam;
                            let sigma = bl.sigma_phase_cycles * (1.0 + u.dot(&(g * u))).sqrt();
                            (x - x.round()).abs() <= GATE_SIGMAS * sigma
                        });
                        if !consistent {
                            continue;
                        }
                        if n_c[j] == CANDIDATE_CAPACITY {
                            return Err(AmbiguityError::TooManyCandidates {
                                baseline: j,
                                capacity: CANDIDATE_CAPACITY,
                            });
                        }
                        cands[j][n_c[j]] = b;
                        n_c[j] += 1;
                    }
                }
            }
        }
        let mut best: Option<Candidate> = None;
        let mut second_chi2 = f64::INFINITY;
        let mut best_att: Option<BaselineAttitude> = None;
        let mut ints = [[0i64; 2]; MAX_SATELLITES];
        let sats = &all[..n.min(MAX_SATELLITES)];
        for ab in &cands[0][..n_c[0]] {
            for cd in &cands[1][..n_c[1]] {
                let s_dot = (var_unit * (cd.dot(&(g * cd)) + ab.dot(&(g * ab)))).sqrt();
                if ab.dot(cd).abs() > GATE_SIGMAS * s_dot {
                    continue;
                }
                let Ok(c0) = ba::triad(ab, cd) else { continue };
                // Integers of all satellites against this attitude, refined once against the
                // least-squares attitude of all of them.
                round_against(sats, &c0, &bl, &mut ints);
                let Ok(a0) = ba::solve(&resolved(sats, &ints[..n]), &bl, r_e_m, Some(&c0)) else {
                    continue;
                };
                round_against(sats, &a0.c_e_b, &bl, &mut ints);
                let Ok(a) = ba::solve(&resolved(sats, &ints[..n]), &bl, r_e_m, Some(&a0.c_e_b))
                else {
                    continue;
                };
                let same_as_best = best.as_ref().is_some_and(|b| b.ints[..n] == ints[..n]);
                if same_as_best {
                    continue;
                }
                // The second best is the best of the sets that differ from the final best: a
                // set that loses its place to a better one becomes the second.
                if best.as_ref().is_none_or(|b| a.chi2 < b.chi2) {
                    if let Some(b) = &best {
                        second_chi2 = second_chi2.min(b.chi2);
                    }
                    best = Some(Candidate { chi2: a.chi2, ints });
                    best_att = Some(a);
                } else {
                    second_chi2 = second_chi2.min(a.chi2);
                }
            }
        }
        let (Some(best), Some(att)) = (best, best_att) else {
            return Err(AmbiguityError::NoCandidate);
        };
        let (dof, thr) = chi2_threshold(&cfg, n);
        if best.chi2 > thr {
            return Err(AmbiguityError::ChiSquare {
                chi2: best.chi2,
                threshold: thr,
                dof,
            });
        }
        let ratio = if best.chi2 > 0.0 {
            second_chi2 / best.chi2
        } else {
            f64::INFINITY
        };
        if ratio < cfg.ratio_threshold {
            return Err(AmbiguityError::RatioTest {
                ratio,
                threshold: cfg.ratio_threshold,
            });
        }
        self.reset();
        for (s, i) in sats.iter().zip(&best.ints[..n]) {
            self.hold(s, *i);
        }
        Ok(Resolution {
            attitude: att,
            chi2_threshold: thr,
            n_fixed: n,
            n_new: n,
            searched: true,
            ratio: Some(ratio),
            slips_flagged: 0,
            slips_detected: 0,
            held_set_rejected: false,
        })
    }
}

#[cfg(test)]
mod tests;
