//! The filter's consistency on the simulator's whole world (ionosphere and troposphere
//! residuals, multipath, broadcast orbit and clock errors, code noise by C/N0, the receiver's
//! oscillator, the antenna lever arm), whose GNSS errors are correlated for minutes, with the
//! time-correlated GNSS error model of `fusion::ekf::correlated` at the open-sky receiver
//! class's correlation time (`config/filter.toml`, `[gnss] error_correlation_time_s`).
//!
//! The statistic: over `N` runs of the default vehicle scenario with independent seeds (the
//! world's and the sensors' draws), each run's mean position NEES after the filter has
//! converged. Each run's mean has the expectation 3 of a consistent filter and a variance at
//! most that of one χ²₃ sample (an average of correlated χ²₃ samples), so the sum of the `N`
//! run means lies, with at least the nominal probability, in the two-sided 99 % interval of
//! χ² with 3N degrees of freedom; the bound is that interval, nothing tuned. Without the model
//! the same runs are far above it (world_accuracy.rs: mean position NEES ≈ 290, loose).

use fusion::ekf::chi2_quantile;
use fusion::navigator::{GnssMode, Navigator, NavigatorConfig};
use nalgebra::{Matrix3, Vector3};
use sextant_drivers_sim::offline::{OfflineSim, RunPoint, run_navigator};
use sextant_drivers_sim::scenario::Scenario;
use sextant_drivers_sim::sources::GnssSource;
use std::path::Path;

fn root() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

/// Correlation time of an open-sky single-frequency code receiver's errors, s: the value and
/// source given in `config/filter.toml`'s comment on `[gnss] error_correlation_time_s`.
const OPEN_SKY_CORRELATION_TIME_S: f64 = 2700.0;

/// The default vehicle scenario with the GNSS part of its world and the given seed.
fn vehicle_world(seed: u64) -> Scenario {
    let path = root().join("config/scenarios/vehicle.toml");
    let mut doc: toml::Table = toml::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    doc["scenario"]
        .as_table_mut()
        .unwrap()
        .insert("seed".into(), (seed as i64).into());
    let mut scn = Scenario::from_toml_str(&toml::to_string(&doc).unwrap(), &path).unwrap();
    scn.spec.world = Some(
        scn.spec
            .world
            .unwrap()
            .only(&sextant_drivers_sim::world::GNSS_EFFECTS)
            .unwrap(),
    );
    scn
}

/// The car's filter (`config/filter.toml`) installed for this world: the surveyed antenna,
/// its time tag and the receiver class's error correlation time.
fn filter_config(scn: &Scenario, mode: GnssMode) -> NavigatorConfig {
    let car = crate::fixture::car_filter();
    assert_eq!(
        car.gnss.error_correlation_time_s,
        OPEN_SKY_CORRELATION_TIME_S
    );
    let mut cfg = sextant_drivers_sim::matched::installed_for(
        scn.spec.world.as_ref(),
        crate::fixture::car_filter(),
        &car,
    );
    cfg.gnss_mode = mode;
    cfg
}

/// Mean position NEES of one run after `from_s`.
fn mean_nees(scn: &Scenario, cfg: NavigatorConfig, from_s: f64) -> f64 {
    let sim = OfflineSim::new(scn);
    let epoch = sim.epoch_ns();
    let mut nav = Navigator::new(cfg).unwrap();
    let (mut sum, mut n) = (0.0, 0usize);
    run_navigator(sim, epoch, &mut nav, |p: &RunPoint| {
        if p.t_s >= from_s {
            sum += p.nees()[0];
            n += 1;
        }
    })
    .unwrap();
    sum / n as f64
}

/// Mean NEES of the receiver's own fixes after `from_s` against their reported covariance
/// (3 when its error budget has the size of its errors): printed beside the filter's, to tell
/// a run whose errors are larger than the receiver says from a filter that averages wrongly.
fn fix_nees(scn: &Scenario, from_s: f64) -> f64 {
    let mut src = GnssSource::new(scn, scn.epoch_gps().ns);
    let (mut sum, mut n) = (0.0, 0usize);
    for k in (from_s as i64)..(scn.spec.scenario.duration_s as i64) {
        let (m, hidden) = src.sample_with_truth(k * 1_000_000_000);
        if m.fix_valid != 1 {
            continue;
        }
        let e = Vector3::from(m.pos_ecef_m) - hidden.antenna_r_e_m;
        let cov = Matrix3::from_row_slice(&m.pos_cov_ecef_m2);
        if let Some(inv) = cov.try_inverse() {
            sum += (e.transpose() * inv * e)[(0, 0)];
            n += 1;
        }
    }
    sum / n as f64
}

fn check(mode: GnssMode, seeds: std::ops::Range<u64>) {
    let (means, fixes): (Vec<f64>, Vec<f64>) = seeds
        .clone()
        .map(|seed| {
            let scn = vehicle_world(seed);
            (
                mean_nees(&scn, filter_config(&scn, mode), 150.0),
                fix_nees(&scn, 150.0),
            )
        })
        .unzip();
    eprintln!("{mode:?}: the receiver fixes' own mean NEES per run {fixes:.2?}");
    let n = means.len() as f64;
    let avg = means.iter().sum::<f64>() / n;
    let dof = 3 * means.len() as u32;
    let (lo, hi) = (chi2_quantile(dof, 0.005) / n, chi2_quantile(dof, 0.995) / n);
    eprintln!(
        "{mode:?}: mean position NEES per run {means:.2?}, average {avg:.2} (99 % band [{lo:.2}, {hi:.2}])"
    );
    assert!(
        (lo..=hi).contains(&avg),
        "{mode:?}: mean position NEES {avg:.2} outside the χ²({dof}) 99 % band [{lo:.2}, {hi:.2}]: {means:.2?}"
    );
}

#[test]
fn loose_coupling_is_consistent_on_the_whole_world() {
    check(GnssMode::Loose, 1..7);
}

#[test]
fn tight_coupling_is_consistent_on_the_whole_world() {
    check(GnssMode::Tight, 1..7);
}
