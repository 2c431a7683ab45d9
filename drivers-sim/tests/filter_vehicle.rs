//! The full filter on the default vehicle scenario, offline (drivers_sim::offline stream):
//! horizontal/vertical/attitude RMS after alignment, for the configuration in
//! `config/filter.toml` and variants. The full 600 s run takes longer than a CI test may, so it
//! is `#[ignore]`d; run it with
//! `cargo test --release -p sextant-drivers-sim --test integration filter_vehicle -- --ignored
//! --nocapture`.

use fusion::navigator::{GnssMode, Navigator, NavigatorConfig};
use sextant_drivers_sim::offline::{OfflineSim, RunPoint, run_navigator};
use sextant_drivers_sim::scenario::Scenario;
use std::path::Path;

fn root() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

fn default_config() -> NavigatorConfig {
    let text = std::fs::read_to_string(root().join("config/filter.toml")).unwrap();
    toml::from_str(&text).unwrap()
}

/// (horizontal RMS m, vertical RMS m, attitude RMS deg, mean position NEES) over the navigating
/// part of the run.
fn run(cfg: NavigatorConfig, duration_s: f64) -> (f64, f64, f64, f64) {
    let scn = Scenario::load(&root().join("config/scenarios/vehicle.toml")).unwrap();
    let sim = OfflineSim::new(&scn).with_duration_s(duration_s);
    let epoch = sim.epoch_ns();
    let mut nav = Navigator::new(cfg).unwrap();
    let (mut h2, mut v2, mut a2, mut nees, mut n) = (0.0, 0.0, 0.0, 0.0, 0.0);
    run_navigator(sim, epoch, &mut nav, |p: &RunPoint| {
        if p.t_s < 120.0 {
            return;
        }
        let e = p.pos_err_ned_m();
        h2 += e.x * e.x + e.y * e.y;
        v2 += e.z * e.z;
        a2 += p.att_err_e_rad.norm_squared();
        nees += p.nees()[0];
        n += 1.0;
    })
    .unwrap();
    (
        (h2 / n).sqrt(),
        (v2 / n).sqrt(),
        (a2 / n).sqrt().to_degrees(),
        nees / n,
    )
}

#[test]
#[ignore = "600 s of 200 Hz simulation: minutes in release; an accuracy report, not a CI test"]
fn vehicle_accuracy_report() {
    let base = default_config();
    let mut variants: Vec<(&str, NavigatorConfig)> = vec![("filter.toml", base.clone())];
    let mut c = base.clone();
    c.states.boresight = true;
    variants.push(("boresight on", c));
    let mut c = base.clone();
    c.states.gyro_scale = false;
    c.states.accel_scale = false;
    variants.push(("no scale factors", c));
    let mut c = base.clone();
    c.covariance_interval_s = 0.005;
    variants.push(("covariance every step", c));
    let mut c = base.clone();
    c.gnss_mode = GnssMode::Tight;
    variants.push(("tight", c));
    for (name, cfg) in variants {
        let (h, v, a, nees) = run(cfg, 600.0);
        println!(
            "{name:24} horizontal RMS {h:.3} m, vertical RMS {v:.3} m, attitude RMS {a:.4} deg, \
             mean position NEES {nees:.2}"
        );
    }
}
