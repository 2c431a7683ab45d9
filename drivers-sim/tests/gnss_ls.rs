//! The receiver-style least-squares fix (`fusion::gnss_ls`, paper 003 eq. 12–13) on the
//! simulator's own GNSS messages: it agrees with the true antenna position, velocity and
//! receiver clock within its covariance, and with the simulator's linearised fix.

use fusion::gnss_ls::{self, Observations};
use nalgebra::{Matrix3, Vector3};
use sextant_drivers_sim::scenario::Scenario;
use sextant_drivers_sim::sources::GnssSource;
use sextant_drivers_sim::truth::TruthGenerator;
use std::path::Path;

fn load(name: &str) -> Scenario {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../config/scenarios/{name}.toml"));
    match Scenario::load(&p) {
        Ok(s) => s,
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
