//! Tests of the integer-ambiguity resolution on a simulated sky: the search, the held
//! integers across epochs, slips flagged by the receiver or found by the residual test, wrong
//! fixes, float-only epochs and the statistics of single-epoch fixes.

use super::*;
use crate::attitude::{c_n_b_from_rpy, quat_from_rotation_vector};
use crate::baseline_attitude::small_rotation_between;
use crate::earth::{Geodetic, WGS84, c_e_n, geodetic_to_ecef};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::test_sky::{L1_WAVELENGTH_M, SKY_AZ_EL_DEG as SKY};

fn site() -> (Vector3<f64>, Matrix3<f64>) {
    let g = Geodetic {
        lat_rad: 52.5f64.to_radians(),
        lon_rad: 13.4f64.to_radians(),
        height_m: 50.0,
    };
    (geodetic_to_ecef(&WGS84, &g), c_e_n(g.lat_rad, g.lon_rad))
}

fn config() -> AmbiguityConfig {
    AmbiguityConfig {
        baseline: BaselineConfig {
            baseline_length_m: [1.0, 1.0],
            wavelength_m: L1_WAVELENGTH_M,
            sigma_phase_cycles: 0.01,
        },
        ratio_threshold: 3.0,
        chi2_probability: 0.999,
    }
}

/// A receiver epoch: phases `b·u/λ + N + ε` of the satellites `prns` (indices into SKY
/// + 1) with integers `ints[prn − 1]` and lock times `lock[prn − 1]`.
struct Receiver {
    c_e_b: Matrix3<f64>,
    ints: [[i64; 2]; 7],
    lock: [[f64; 2]; 7],
    rng: ChaCha8Rng,
}

impl Receiver {
    fn new(seed: u64, rpy: (f64, f64, f64)) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (_, cen) = site();
        let ints = std::array::from_fn(|_| {
            [
                rng.random_range(-1000..=1000),
                rng.random_range(-1000..=1000),
            ]
        });
        Self {
            c_e_b: cen * c_n_b_from_rpy(rpy.0, rpy.1, rpy.2),
            ints,
            lock: [[100.0; 2]; 7],
            rng,
        }
    }

    fn epoch(&mut self, prns: &[u32], noise: bool) -> RawPhases {
        let cfg = config().baseline;
        let (_, cen) = site();
        let b = baselines(&self.c_e_b, &cfg);
        let mut out = RawPhases::default();
        for &prn in prns {
            let (az, el) = SKY[prn as usize - 1];
            let (az, el) = (az.to_radians(), el.to_radians());
            let u = cen * Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), -el.sin());
            let mut ph = [0.0; 2];
            for j in 0..2 {
                let e: f64 = if noise {
                    StandardNormal.sample(&mut self.rng)
                } else {
                    0.0
                };
                ph[j] = b[j].dot(&u) / cfg.wavelength_m
                    + self.ints[prn as usize - 1][j] as f64
                    + cfg.sigma_phase_cycles * e;
            }
            out.push(RawPhase {
                prn,
                los_e: u,
                phase_cycles: ph,
                lock_time_s: self.lock[prn as usize - 1],
            })
            .unwrap();
        }
        out
    }

    /// One second later: every lock time +1 s.
    fn tick(&mut self) {
        for l in &mut self.lock {
            l[0] += 1.0;
            l[1] += 1.0;
        }
    }

    fn holds_truth(&self, r: &AmbiguityResolver, prns: &[u32]) -> bool {
        prns.iter()
            .all(|&p| r.held(p) == Some(self.ints[p as usize - 1]))
    }

    /// NEES of an attitude against the truth with its covariance.
    fn nees(&self, a: &BaselineAttitude) -> f64 {
        let e = small_rotation_between(&a.c_e_b, &self.c_e_b);
        e.dot(&(a.cov_e_rad2.try_inverse().unwrap() * e))
    }
}

const ALL: [u32; 7] = [1, 2, 3, 4, 5, 6, 7];
/// 99.99 % of χ²(3): the attitude error of a correct fix.
fn nees_bound() -> f64 {
    chi2_quantile(3, 0.9999)
}

/// From nothing: the search finds the receiver's arbitrary integers (±1000) exactly at
/// several attitudes, with a ratio above the threshold and the attitude error inside the
/// χ²(3) bound of its covariance; noise-free, the attitude is exact.
#[test]
fn search_finds_the_integers_and_the_attitude() {
    let (r, _) = site();
    for (seed, rpy) in [
        (1, (0.0, 0.0, 0.0)),
        (2, (0.05, -0.1, 1.0)),
        (3, (-0.3, 0.2, -2.8)),
        (4, (0.1, 0.05, 3.1)),
    ] {
        let mut rx = Receiver::new(seed, rpy);
        let mut res = AmbiguityResolver::new(config()).unwrap();
        let o = res.resolve(0.0, &rx.epoch(&ALL, false), &r, None);
        let fix = o.result.unwrap();
        assert!(fix.searched && fix.n_fixed == 7);
        assert!(rx.holds_truth(&res, &ALL));
        assert!(small_rotation_between(&fix.attitude.c_e_b, &rx.c_e_b).norm() < 1e-9);
        let mut res = AmbiguityResolver::new(config()).unwrap();
        let fix = res
            .resolve(0.0, &rx.epoch(&ALL, true), &r, None)
            .result
            .unwrap();
        assert!(rx.holds_truth(&res, &ALL), "seed {seed}");
        assert!(fix.ratio.unwrap() >= 3.0);
        assert!(rx.nees(&fix.attitude) < nees_bound());
    }
}

/// Held integers carry over (no search); a rising satellite is re-fixed from the held
/// attitude; a slip the receiver flags (lock time restarted) drops the satellite and it
/// is re-fixed at once with its new integer.
#[test]
fn integers_are_held_new_and_flagged_satellites_refixed() {
    let (r, _) = site();
    let mut rx = Receiver::new(5, (0.02, -0.03, 0.7));
    let mut res = AmbiguityResolver::new(config()).unwrap();
    let six = &ALL[..6];
    assert!(
        res.resolve(0.0, &rx.epoch(six, true), &r, None)
            .result
            .is_ok()
    );
    rx.tick();
    let o = res.resolve(1.0, &rx.epoch(&ALL, true), &r, None);
    let fix = o.result.unwrap();
    assert!(!fix.searched);
    assert_eq!((fix.n_fixed, fix.n_new), (7, 1));
    assert!(rx.holds_truth(&res, &ALL));
    rx.tick();
    rx.ints[2][1] += 2;
    rx.lock[2][1] = 0.4;
    let o = res.resolve(2.0, &rx.epoch(&ALL, true), &r, None);
    assert_eq!(o.slips_flagged, 1);
    let fix = o.result.unwrap();
    assert_eq!((fix.n_fixed, fix.n_new, fix.searched), (7, 1, false));
    assert!(rx.holds_truth(&res, &ALL));
    assert!(rx.nees(&fix.attitude) < nees_bound());
}

/// A slip the receiver does not flag (lock time running on) is found by the residual
/// test: the satellite is dropped, the fused attitude is the one of the others (inside
/// the χ²(3) bound, not pulled by the 1-cycle error = 19 cm on a 1 m baseline), and the
/// satellite comes back with its new integer.
#[test]
fn unflagged_slip_is_detected_and_not_fused() {
    let (r, _) = site();
    let mut rx = Receiver::new(6, (0.0, 0.1, -1.2));
    let mut res = AmbiguityResolver::new(config()).unwrap();
    assert!(
        res.resolve(0.0, &rx.epoch(&ALL, true), &r, None)
            .result
            .is_ok()
    );
    rx.tick();
    rx.ints[4][0] -= 1;
    let o = res.resolve(1.0, &rx.epoch(&ALL, true), &r, None);
    assert_eq!((o.slips_flagged, o.slips_detected), (0, 1));
    let fix = o.result.unwrap();
    assert!(fix.attitude.chi2 <= fix.chi2_threshold);
    assert!(
        rx.nees(&fix.attitude) < nees_bound(),
        "{}",
        rx.nees(&fix.attitude)
    );
    assert!(rx.holds_truth(&res, &ALL), "re-fixed with the new integer");
}

/// A wrong integer set held (the integers of an attitude 20° off in heading, each
/// phase within half a cycle of it: the most plausible wrong fix) fails the residual
/// test at the next epoch; it is rejected as a whole, never fused, and the search of the
/// same epoch fixes the true integers. With only three satellites no search can run:
/// the epoch gives no attitude at all.
#[test]
fn wrong_integer_set_is_detected_and_not_fused() {
    let (r, _) = site();
    let mut rx = Receiver::new(7, (0.05, 0.0, 0.4));
    let wrong_c = quat_from_rotation_vector(&(rx.c_e_b.column(2) * 20f64.to_radians()))
        .to_rotation_matrix()
        .into_inner()
        * rx.c_e_b;
    let raw = rx.epoch(&ALL, true);
    let mut wrong = [[0i64; 2]; MAX_SATELLITES];
    round_against(raw.as_slice(), &wrong_c, &config().baseline, &mut wrong);
    assert!(
        wrong[..7]
            .iter()
            .zip(&rx.ints)
            .filter(|(w, t)| w != t)
            .count()
            >= 3
    );
    for sats in [&ALL[..], &ALL[..3]] {
        let mut res = AmbiguityResolver::new(config()).unwrap();
        for &p in sats {
            res.force_hold(p, wrong[p as usize - 1], rx.lock[p as usize - 1]);
        }
        rx.tick();
        let o = res.resolve(1.0, &rx.epoch(sats, true), &r, None);
        assert!(o.held_set_rejected, "{o:?}");
        if sats.len() == 7 {
            let fix = o.result.unwrap();
            assert!(fix.searched);
            assert!(rx.holds_truth(&res, sats));
            assert!(rx.nees(&fix.attitude) < nees_bound());
        } else {
            assert!(matches!(
                o.result,
                Err(AmbiguityError::TooFewSatellites { .. })
            ));
            assert_eq!(res.n_held(), 0);
        }
    }
}

/// A resolver told σ_φ = 0.09 cycle (the widest its rounding allows) keeps runner-up
/// candidates through its gates; with an unreachable ratio threshold the epoch is float
/// only: no attitude, nothing held. With the true σ_φ no runner-up survives the gates
/// (infinite ratio). Bad configurations are refused.
#[test]
fn ratio_test_failure_is_float_only() {
    let (r, _) = site();
    let mut rx = Receiver::new(8, (0.0, 0.0, 2.0));
    let raw = rx.epoch(&ALL, true);
    let mut res = AmbiguityResolver::new(config()).unwrap();
    let fix = res.resolve(0.0, &raw, &r, None).result.unwrap();
    assert_eq!(fix.ratio, Some(f64::INFINITY));
    let mut wide = config();
    wide.baseline.sigma_phase_cycles = 0.09;
    let mut res = AmbiguityResolver::new(AmbiguityConfig {
        ratio_threshold: 1e300,
        ..wide
    })
    .unwrap();
    let o = res.resolve(0.0, &raw, &r, None);
    let e = o.result.unwrap_err();
    assert!(matches!(e, AmbiguityError::RatioTest { .. }) && e.is_float_only());
    assert_eq!(res.n_held(), 0);
    for bad in [
        AmbiguityConfig {
            ratio_threshold: 0.5,
            ..config()
        },
        AmbiguityConfig {
            chi2_probability: 1.0,
            ..config()
        },
    ] {
        assert!(AmbiguityResolver::new(bad).is_err());
    }
}

/// Monte Carlo of single-epoch searches (120 random attitudes and integers, 5–7
/// satellites): no wrong fix is ever accepted, and the χ² of the accepted fixes has the
/// mean of its degrees of freedom (Σχ² over Σdof within 1 ± 4√(2/Σdof)). With σ_φ =
/// 0.01 cycle and 1 m baselines every epoch fixes (the wrong sets lie ≥ 0.1 cycle off).
#[test]
fn single_epoch_fixes_are_never_wrong_and_chi2_is_consistent() {
    let (r, _) = site();
    let mut rng = ChaCha8Rng::seed_from_u64(99);
    let (mut chi2, mut dof, mut fixed, mut wrong) = (0.0, 0.0, 0, 0);
    let trials = 120;
    for t in 0..trials {
        let rpy = (
            rng.random_range(-0.3..0.3),
            rng.random_range(-0.3..0.3),
            rng.random_range(-3.1..3.1),
        );
        let mut rx = Receiver::new(1000 + t, rpy);
        let n = 5 + (t as usize % 3);
        let sats = &ALL[..n];
        let mut res = AmbiguityResolver::new(config()).unwrap();
        if let Ok(fix) = res.resolve(0.0, &rx.epoch(sats, true), &r, None).result {
            fixed += 1;
            wrong += usize::from(!rx.holds_truth(&res, sats));
            chi2 += fix.attitude.chi2;
            dof += (2 * n - 3) as f64;
        }
    }
    eprintln!(
        "{fixed}/{trials} fixed, {wrong} wrong, Σχ²/Σdof {:.3}",
        chi2 / dof
    );
    assert_eq!(wrong, 0);
    assert_eq!(fixed, trials);
    assert!((chi2 / dof - 1.0).abs() < 4.0 * (2.0 / dof).sqrt());
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]
    /// Any attitude, any integers (±1000), white phase noise of σ_φ: the resolver
    /// either refuses or holds exactly the true integers — never a wrong set.
    #[test]
    fn never_holds_a_wrong_set(
        roll in -0.5f64..0.5,
        pitch in -0.5f64..0.5,
        heading in -std::f64::consts::PI..std::f64::consts::PI,
        seed in 0u64..1_000_000,
        n in 4usize..=7,
    ) {
        let (r, _) = site();
        let mut rx = Receiver::new(seed, (roll, pitch, heading));
        let sats = &ALL[..n];
        let mut res = AmbiguityResolver::new(config()).unwrap();
        let o = res.resolve(0.0, &rx.epoch(sats, true), &r, None);
        if o.result.is_ok() {
            prop_assert!(rx.holds_truth(&res, sats));
        } else {
            prop_assert_eq!(res.n_held(), 0);
        }
    }
}
