//! The default vehicle scenario on the matched world (no `[world]`), with only its antenna
//! (lever arm, latency) and on the whole world of `config/scenarios/vehicle.toml` (every
//! effect switched on), loose and
//! tight: the solution's horizontal/vertical RMS beside the receiver fix's own, with the mean
//! position NEES (3 for a consistent filter). Minutes in release, so
//! `#[ignore]`d; run with
//! `cargo test --release -p sextant-drivers-sim --test integration world_accuracy -- --ignored
//! --nocapture`.

use fusion::navigator::{GnssMode, Navigator, NavigatorConfig};
use nalgebra::Vector3;
use sextant_drivers_sim::offline::{OfflineSim, RunPoint, run_navigator};
use sextant_drivers_sim::scenario::Scenario;
use sextant_drivers_sim::sources::GnssSource;
use std::path::Path;

fn root() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

fn filter_config() -> NavigatorConfig {
    let text = std::fs::read_to_string(root().join("config/filter.toml")).unwrap();
    toml::from_str(&text).unwrap()
}

/// Which world the vehicle runs in.
#[derive(Debug, Clone, Copy, PartialEq)]
enum World {
    /// No `[world]` at all and no lever arm in the filter: the matched simulator.
    Matched,
    /// Only `[world.gnss_antenna]` (lever arm and latency), errors white as in `Matched`.
    AntennaOnly,
    /// The scenario's whole `[world]`.
    Full,
}

fn vehicle(world: World) -> Scenario {
    let path = root().join("config/scenarios/vehicle.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let mut doc: toml::Table = toml::from_str(&text).unwrap();
    match world {
        World::Matched => {
            doc.remove("world");
        }
        World::AntennaOnly | World::Full => {
            let w = doc["world"].as_table_mut().unwrap();
            for (name, effect) in w.iter_mut() {
                let on = world == World::Full || name == "gnss_antenna";
                effect
                    .as_table_mut()
                    .unwrap()
                    .insert("enabled".into(), on.into());
            }
        }
    }
    Scenario::from_toml_str(&toml::to_string(&doc).unwrap(), &path).unwrap()
}

fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

/// Receiver fix alone after `from_s`: (horizontal RMS, vertical RMS), m, against the antenna.
fn fix_rms(scn: &Scenario, from_s: f64) -> (f64, f64) {
    let epoch = scn.epoch_gps().ns;
    let mut src = GnssSource::new(scn, epoch);
    let (mut h, mut v) = (Vec::new(), Vec::new());
    let n = scn.spec.scenario.duration_s as i64;
    for k in 0..n {
        let (m, hidden) = src.sample_with_truth(k * 1_000_000_000);
        if m.fix_valid != 1 || (k as f64) < from_s {
            continue;
        }
        let g = fusion::earth::ecef_to_geodetic(&fusion::earth::WGS84, &hidden.antenna_r_e_m);
        let c_e_n = fusion::earth::c_e_n(g.lat_rad, g.lon_rad);
        let e = c_e_n.transpose() * (Vector3::from(m.pos_ecef_m) - hidden.antenna_r_e_m);
        h.push(e.x.hypot(e.y));
        v.push(e.z);
    }
    (rms(&h), rms(&v))
}

/// Solution after `from_s`: (horizontal RMS m, vertical RMS m, mean position NEES, mean
/// velocity NEES).
fn solution_rms(scn: &Scenario, cfg: NavigatorConfig, from_s: f64) -> (f64, f64, f64, f64) {
    let sim = OfflineSim::new(scn);
    let epoch = sim.epoch_ns();
    let mut nav = Navigator::new(cfg).unwrap();
    let (mut h, mut v, mut nees, mut nees_v) = (Vec::new(), Vec::new(), 0.0, 0.0);
    run_navigator(sim, epoch, &mut nav, |p: &RunPoint| {
        if p.t_s < from_s {
            return;
        }
        let e = p.pos_err_ned_m();
        h.push(e.x.hypot(e.y));
        v.push(e.z);
        let n = p.nees();
        nees += n[0];
        nees_v += n[1];
    })
    .unwrap();
    let n = h.len() as f64;
    (rms(&h), rms(&v), nees / n, nees_v / n)
}

/// Correlation time of an open-sky single-frequency code receiver's errors, s (the shipped
/// `config/filter.toml` comment gives its source): the filter's model when "GM" is printed.
const OPEN_SKY_CORRELATION_TIME_S: f64 = 2700.0;

#[test]
#[ignore = "600 s of 200 Hz simulation per line: minutes in release; a report, not a CI test"]
fn world_accuracy_report() {
    for world in [World::Matched, World::AntennaOnly, World::Full] {
        let scn = vehicle(world);
        let (fh, fv) = fix_rms(&scn, 150.0);
        for mode in [GnssMode::Loose, GnssMode::Tight] {
            for tau_s in [0.0, OPEN_SKY_CORRELATION_TIME_S] {
                let mut cfg = filter_config();
                cfg.gnss_mode = mode;
                cfg.gnss.error_correlation_time_s = tau_s;
                if world != World::Matched {
                    // The surveyed antenna of the vehicle (the scenario's).
                    let w = scn.spec.world.unwrap();
                    cfg.gnss.lever_arm_b_m = w.gnss_antenna.unwrap().lever_arm_b_m;
                }
                let (h, v, nees, nees_v) = solution_rms(&scn, cfg, 150.0);
                let model = if tau_s > 0.0 { "GM" } else { "white" };
                println!(
                    "{world:?} {mode:?} {model}: solution horizontal {h:.3} m vertical {v:.3} m \
                     (position NEES {nees:.2}, velocity NEES {nees_v:.2}); receiver fix \
                     horizontal {fh:.3} m vertical {fv:.3} m"
                );
            }
        }
    }
}
