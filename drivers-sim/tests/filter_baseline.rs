//! Dual-baseline GNSS attitude (paper 003 eq. 14–21, `fusion::baseline_attitude`) as a filter
//! measurement, on the vehicle scenario with the star tracker off (stars would dominate the
//! attitude). Heading error RMS with and without it (both runs in parallel, ≈ 4 s).
//!
//! Expected size: one epoch gives the attitude to ≈ λσ_φ/d = 0.19 m · 0.01 / 1 m ≈ 1.9 mrad
//! (0.11°) per axis divided by a geometry factor; fused at 1 Hz for ~480 s of navigation it
//! bounds the heading error to a few hundredths of a degree even when the vehicle does not
//! accelerate (GNSS velocity alone observes heading only during accelerations and turns).

use fusion::navigator::{Navigator, NavigatorConfig};
use msgs::SensorId;
use sextant_drivers_sim::offline::{OfflineSim, RunPoint, run_navigator};
use sextant_drivers_sim::scenario::Scenario;
use std::path::Path;

/// (heading error RMS deg, heading σ RMS deg, GNSS NIS per dof).
fn run(baseline: bool) -> (f64, f64, f64) {
    let path = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../config/scenarios/vehicle.toml"
    ));
    let scn = Scenario::load(path).unwrap();
    let sim = OfflineSim::new(&scn);
    let epoch = sim.epoch_ns();
    let mut cfg = NavigatorConfig::default();
    cfg.updates.star_tracker = false;
    cfg.updates.baseline_attitude = baseline;
    let mut nav = Navigator::new(cfg).unwrap();
    let (mut e2, mut s2, mut n) = (0.0, 0.0, 0.0);
    run_navigator(sim, epoch, &mut nav, |p: &RunPoint| {
        if p.t_s < 130.0 {
            return;
        }
        e2 += p.att_err_ned_rad().z.powi(2);
        s2 += p.att_sigma_ned_rad().z.powi(2);
        n += 1.0;
    })
    .unwrap();
    let g = nav.health()[SensorId::Gnss as usize];
    (
        (e2 / n).sqrt().to_degrees(),
        (s2 / n).sqrt().to_degrees(),
        g.nis_sum / g.nis_dof_sum.max(1) as f64,
    )
}

#[test]
fn baseline_attitude_is_fused_consistently_without_stars() {
    let (with, without) = std::thread::scope(|s| {
        let a = s.spawn(|| run(true));
        let b = s.spawn(|| run(false));
        (a.join().unwrap(), b.join().unwrap())
    });
    eprintln!(
        "heading error RMS: with baseline attitude {:.4}° (σ {:.4}°, GNSS NIS/dof {:.2}), \
         without {:.4}° (σ {:.4}°)",
        with.0, with.1, with.2, without.0, without.1
    );
    // The measurement is consistent with its covariance (mean NIS per dof ≈ 1; thousands of
    // GNSS updates, standard error < 0.05) …
    assert!((0.8..1.2).contains(&with.2), "NIS/dof {}", with.2);
    // … and the heading stays at the multi-epoch level of the baseline solution: 0.11° per
    // epoch, averaged over hundreds of epochs → well below 0.02° (a wrong sign or frame in
    // H would make the heading diverge to the per-epoch level or beyond).
    assert!(with.0 < 0.02, "heading RMS {}°", with.0);
    // Measured (open problem, see the report): with baseline attitude the heading σ is
    // 0.004° for an error of 0.008°, i.e. the filter is about 2× overconfident in heading,
    // and the error is not better than GNSS velocity alone gives on this turning vehicle
    // (0.007°). Not asserted as an improvement.
}
