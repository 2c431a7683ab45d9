//! The receiver-style least-squares fix (`fusion::gnss_ls`, paper 003 eq. 12–13) on the
//! simulator's own GNSS messages: it agrees with the true antenna position, velocity and
//! receiver clock within its covariance, and with the simulator's linearised fix.

use fusion::gnss_ls::{self, Observations};
use nalgebra::{Matrix3, Vector3};
use sextant_drivers_sim::scenario::Scenario;
use sextant_drivers_sim::sources::GnssSource;
use sextant_drivers_sim::truth::TruthGenerator;
use std::path::Path;

/// The shipped scenario `name` on the matched world (the least-squares algebra against the
/// receiver's exact covariance).
fn load(name: &str) -> Scenario {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../config/scenarios/{name}.toml"));
    match Scenario::load(&p) {
        Ok(s) => sextant_drivers_sim::matched::scenario(s),
        Err(e) => panic!("{e}"),
    }
}

fn nees(e: &Vector3<f64>, p: &Matrix3<f64>) -> f64 {
    e.dot(&(p.try_inverse().expect("covariance invertible") * e))
}

/// Over `n_epochs` 1 Hz epochs of scenario `name` (skipping outages):
/// * the per-epoch noise draws are independent, so Σ NEES of the position (and velocity) is
///   χ²(3N): mean 3N, σ √(6N); we accept 3N ± 4√(6N);
/// * clock bias and drift errors normalised by their σ: Σ z² is χ²(N), accepted N ± 4√(2N);
/// * Σ of the post-fit χ² is χ²(Σ(n_i − 4)), accepted likewise;
/// * the simulator's fix in the message is the linearised LS at the *true* lines of sight with
///   the same noise and equal weights, so it equals ours up to the second-order term
///   |δr|²/ρ ≈ (10 m)²/2·10⁷ m = 5·10⁻⁶ m: accepted 1 mm.
fn check(name: &str, n_epochs: i64) {
    let scn = load(name);
    let epoch = scn.epoch_gps().ns;
    let mut src = GnssSource::new(&scn, epoch);
    let mut truth = TruthGenerator::new(&scn);
    let (mut nees_p, mut nees_v, mut z2_b, mut z2_d, mut chi2, mut dof) =
        (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    let mut n = 0.0;
    let mut max_vs_sim: f64 = 0.0;
    for k in 0..n_epochs {
        let t_ns = k * 1_000_000_000;
        let (msg, hidden) = src.sample_with_truth(t_ns);
        truth.advance_to(t_ns);
        let tp = truth.current();
        if msg.fix_valid == 0 {
            continue;
        }
        let obs = Observations::from_sample(&msg).expect("valid sample");
        let fix = gnss_ls::solve(&obs, &Default::default()).expect("fix");
        let p = fix.position;
        let v = fix.velocity.expect("Doppler on every satellite");
        nees_p += nees(&(p.r_e_m - tp.r_e_m), &p.cov_r_e_m2);
        nees_v += nees(&(v.v_e_m_s - tp.v_e_m_s()), &v.cov_v_e_m2_s2);
        z2_b += (p.clock_bias_m - hidden.clock_bias_m).powi(2) / p.var_clock_bias_m2;
        z2_d += (v.clock_drift_m_s - hidden.clock_drift_m_s).powi(2) / v.var_clock_drift_m2_s2;
        chi2 += p.chi2;
        dof += (p.n_used - 4) as f64;
        max_vs_sim = max_vs_sim.max((p.r_e_m - Vector3::from(msg.pos_ecef_m)).norm());
        assert!(
            (p.dop.pdop - msg.pdop).abs() < 1e-6,
            "PDOP {} vs sim {}",
            p.dop.pdop,
            msg.pdop
        );
        n += 1.0;
    }
    assert!(n > 0.8 * n_epochs as f64, "{name}: only {n} fixes");
    let band = |sum: f64, mean: f64, var: f64, what: &str| {
        assert!(
            (sum - mean).abs() < 4.0 * var.sqrt(),
            "{name} {what}: {sum:.1} vs χ² mean {mean:.1} ± 4·{:.1}",
            var.sqrt()
        );
    };
    band(nees_p, 3.0 * n, 6.0 * n, "position NEES");
    band(nees_v, 3.0 * n, 6.0 * n, "velocity NEES");
    band(z2_b, n, 2.0 * n, "clock bias z²");
    band(z2_d, n, 2.0 * n, "clock drift z²");
    band(chi2, dof, 2.0 * dof, "post-fit χ²");
    assert!(
        max_vs_sim < 1e-3,
        "{name}: {max_vs_sim} m from the simulator's fix"
    );
}

#[test]
fn ls_fix_agrees_with_static_truth() {
    check("static_site", 300);
}

#[test]
fn ls_fix_agrees_with_moving_truth() {
    check("vehicle", 600);
}

/// One vehicle run (default filter, `mode`), watching the Navigator's least-squares
/// diagnostics after every message: the NIS of every cross-check, the checks, the
/// disagreements; and, at the first navigating epoch, the distance of the Navigator's
/// position from the nearest least-squares fix of the alignment period and its clock.
struct CrossCheckRun {
    nis: Vec<f64>,
    checks: u64,
    disagreements: u64,
    pdop: f64,
    /// |r̂ − r_ls| at navigation start, m, and the clock bias minus the LS bias moved to that
    /// time with the LS drift, m (tight only).
    start_offset_m: f64,
    start_clock_offset_m: Option<f64>,
    /// Largest |P_r,b − C_ls,r,b| at navigation start relative to √(P_rr P_bb) (tight only):
    /// the position↔clock covariance must be the fix's.
    start_cross_cov_rel: Option<f64>,
    /// Mean NIS per dof of the accepted GNSS updates of the run.
    update_nis_per_dof: f64,
}

fn cross_check_run(mode: fusion::navigator::GnssMode, spoof: bool) -> CrossCheckRun {
    use fusion::navigator::{GnssMode, Navigator, NavigatorConfig};
    use msgs::Record;
    use sextant_drivers_sim::offline::{OfflineSim, feed};
    let scn = load("vehicle");
    let sim = OfflineSim::new(&scn);
    let mut nav = Navigator::new(NavigatorConfig {
        gnss_mode: mode,
        ..NavigatorConfig::default()
    })
    .expect("default config");
    // The fixes by time of validity (the receiver's stamp less its configured latency).
    let mut ls_fixes: Vec<(i64, gnss_ls::GnssFix)> = Vec::new();
    let mut window_start_ns: Option<i64> = None;
    let mut out = CrossCheckRun {
        nis: Vec::new(),
        checks: 0,
        disagreements: 0,
        pdop: 0.0,
        start_offset_m: f64::NAN,
        start_clock_offset_m: None,
        start_cross_cov_rel: None,
        update_nis_per_dof: f64::NAN,
    };
    let mut was_navigating = false;
    let epoch = sim.epoch_ns();
    for mut msg in sim {
        if spoof {
            spoof_epoch(&mut msg, epoch);
        }
        if let Record::Gnss(g) = &msg
            && let Ok(fix) = gnss_ls::solve_sample(g)
        {
            let latency_ns = (nav.config().latency.gnss_s * 1e9).round() as i64;
            ls_fixes.push((g.header.time_ns - latency_ns, fix));
        }
        if let Record::Imu(s) = &msg
            && window_start_ns.is_none()
        {
            window_start_ns = Some(s.header.time_ns - (s.dt_s * 1e9).round() as i64);
        }
        feed(&mut nav, &msg).expect("simulated samples are valid");
        let d = nav.diagnostics();
        if d.gnss_ls_checks > out.checks {
            assert_eq!(d.gnss_ls_checks, out.checks + 1, "one check per GNSS epoch");
            out.nis.push(d.gnss_ls_last_nis);
            out.checks = d.gnss_ls_checks;
            out.disagreements = d.gnss_ls_disagreements;
            out.pdop = d.gnss_ls_pdop;
        }
        if nav.is_navigating() && !was_navigating {
            was_navigating = true;
            let r = nav.nav_state().r_e;
            let cfg = nav.config();
            let until = nav.time().ns - (cfg.buffer_window_s * 1e9).round() as i64;
            let from = window_start_ns.expect("IMU before navigation");
            let window: Vec<_> = ls_fixes
                .iter()
                .filter(|(t, _)| (from..=until).contains(t))
                .collect();
            let n = window.len() as f64;
            assert!(n > 50.0, "{n} fixes in the alignment window");
            let mean = window
                .iter()
                .fold(Vector3::zeros(), |a, (_, f)| a + f.position.r_e_m)
                / n;
            out.start_offset_m = (mean - r).norm();
            let &&(t_ls, fix) = window.last().expect("fixes during alignment");
            let tau_s = cfg.gnss.error_correlation_time_s;
            let share = window
                .iter()
                .map(|(t, _)| {
                    if tau_s > 0.0 {
                        (-((t_ls - t) as f64 * 1e-9) / tau_s).exp()
                    } else if *t == t_ls {
                        1.0
                    } else {
                        0.0
                    }
                })
                .sum::<f64>()
                / n;
            if mode == GnssMode::Tight {
                let dt = (nav.time().ns - t_ls) as f64 * 1e-9;
                let v = fix.velocity.expect("Doppler on every satellite");
                let b = fix.position.clock_bias_m + v.clock_drift_m_s * dt;
                out.start_clock_offset_m = Some(nav.clock().bias_m - b);
                // Propagation leaves P_r,b alone while P_v,b = P_r,d = 0 (static start, drift
                // independent of the position fix): it must still be the fix's.
                use fusion::ekf::idx;
                let p = nav.covariance();
                let rel = (0..3)
                    .map(|k| {
                        let scale =
                            (p[(idx::POS + k, idx::POS + k)] * p[(idx::CLK, idx::CLK)]).sqrt();
                        (p[(idx::POS + k, idx::CLK)] - share * fix.position.cov_r_clock_m2[k]).abs()
                            / scale
                    })
                    .fold(0.0, f64::max);
                out.start_cross_cov_rel = Some(rel);
            }
        }
    }
    let g = nav.health()[msgs::SensorId::Gnss as usize];
    out.update_nis_per_dof = g.nis_sum / g.nis_dof_sum.max(1) as f64;
    out
}

/// GNSS epochs 400–404 s of the vehicle run, spoofed.
const SPOOF_WINDOW_S: (f64, f64) = (400.0, 404.5);
/// The spoofed displacement, ECEF, m.
const SPOOF_OFFSET_M: [f64; 3] = [30.0, -20.0, 10.0];

/// Inside [`SPOOF_WINDOW_S`], every pseudorange and the receiver fix as if the antenna were
/// [`SPOOF_OFFSET_M`] away (range change evaluated at the receiver's fix, which is within
/// metres of the truth: the error of that linearisation is ~|Δ|·|δr|/ρ ≈ 10⁻⁵ m).
fn spoof_epoch(msg: &mut msgs::Record, epoch_ns: i64) {
    use msgs::Record;
    let Record::Gnss(g) = msg else {
        return;
    };
    let t_s = (g.header.time_ns - epoch_ns) as f64 * 1e-9;
    if g.fix_valid == 0 || t_s < SPOOF_WINDOW_S.0 || t_s > SPOOF_WINDOW_S.1 {
        return;
    }
    let r = Vector3::from(g.pos_ecef_m);
    let delta = Vector3::from(SPOOF_OFFSET_M);
    let n = g.n_satellites as usize;
    for s in g.satellites[..n].iter_mut() {
        let r_s = Vector3::from(s.sat_pos_ecef_m);
        s.pseudorange_m += (r_s - r - delta).norm() - (r_s - r).norm();
    }
    g.pos_ecef_m = (r + delta).into();
}

/// A spoofed jump of 37 m (five epochs) against a filter that knows its position to
/// decimetres: d ≈ Δ, NIS ≈ |Δ|²/(PDOP²σ²) ≈ 1400/10 ≫ the 16.3 gate, so each of the five
/// epochs is a disagreement (the updates of those epochs are gated away, so the filter does
/// not follow the jump and the next spoofed epoch disagrees as well); at most 3 more from
/// chance (previous test).
#[test]
fn cross_check_flags_a_spoofed_jump() {
    use fusion::navigator::GnssMode;
    for mode in [GnssMode::Loose, GnssMode::Tight] {
        let r = cross_check_run(mode, true);
        eprintln!(
            "{mode:?}: {} checks, {} disagreements",
            r.checks, r.disagreements
        );
        assert!(
            (5..=8).contains(&r.disagreements),
            "{mode:?}: {} disagreements",
            r.disagreements
        );
    }
}

/// The Navigator uses the least-squares fix: for its initial position and (tight)
/// clock, and as a per-epoch cross-check whose NIS is χ²(3) when filter and fix are both
/// consistent.
///
/// * Start: the vehicle is static during alignment, so the first navigating position is the
///   mean of the LS fixes of the static window valid at least `buffer_window_s` before its end
///   (< 1 mm); the clock is the latest of them moved with its drift (same arithmetic, 1 mm),
///   its position↔clock covariance the fix's times `Σ_j ρ_jN / N` (ρ the error correlation
///   between the fixes' epochs: the covariance with the mean of the positions).
/// * Cross-check: after convergence the filter's P_rr (dm²) is small against the fix's
///   covariance (PDOP²σ² ≈ 10 m²), so the NIS of successive epochs are nearly independent
///   χ²(3) draws (the fix's noise is white). The mean NIS/dof of N of them has σ √(2/(3N))
///   (≈ 0.04 for N ≈ 420); accepted within ±4σ + 0.05 for the residual correlation through
///   the filter term. Disagreements at the 99.9 % gate: Poisson with mean 0.001·N ≈ 0.4;
///   P(≥ 4) < 10⁻³, so at most 3.
/// * One check per epoch with ≥ 4 satellites: the vehicle scenario has 540 s of GNSS after a
///   120 s alignment minus a 60 s outage, i.e. ≈ 420 epochs; ≥ 400 required.
#[test]
fn navigator_initialises_from_and_cross_checks_with_the_ls_fix() {
    use fusion::navigator::GnssMode;
    for mode in [GnssMode::Loose, GnssMode::Tight] {
        let r = cross_check_run(mode, false);
        let n = r.nis.len() as f64;
        let mean_per_dof = r.nis.iter().sum::<f64>() / (3.0 * n);
        eprintln!(
            "{mode:?}: {} checks, {} disagreements, mean NIS/dof {mean_per_dof:.3}, \
             last PDOP {:.2}, start offset {:.2e} m, clock offset {:?} m, \
             GNSS update NIS/dof {:.3}",
            r.checks,
            r.disagreements,
            r.pdop,
            r.start_offset_m,
            r.start_clock_offset_m,
            r.update_nis_per_dof
        );
        assert!(r.checks >= 400, "{mode:?}: {} checks", r.checks);
        let tol = 4.0 * (2.0 / (3.0 * n)).sqrt() + 0.05;
        assert!(
            (mean_per_dof - 1.0).abs() < tol,
            "{mode:?}: mean NIS/dof {mean_per_dof} outside 1 ± {tol}"
        );
        assert!(r.disagreements <= 3, "{mode:?}: {}", r.disagreements);
        assert!(r.pdop > 1.0 && r.pdop < 10.0, "{mode:?}: PDOP {}", r.pdop);
        assert!(r.start_offset_m < 1e-3, "{mode:?}: {} m", r.start_offset_m);
        if mode == GnssMode::Tight {
            let c = r.start_clock_offset_m.expect("tight");
            assert!(c.abs() < 1e-3, "clock {c} m from the LS clock");
            let x = r.start_cross_cov_rel.expect("tight");
            assert!(x < 1e-6, "position-clock covariance off by {x} (relative)");
        }
    }
}
