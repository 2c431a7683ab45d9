//! Tight GNSS coupling with fewer than four satellites (paper 003: each pseudorange and range
//! rate is a scalar update with the receiver-clock states, so one satellite already helps).
//!
//! The vehicle scenario without odometer (so that GNSS is the only horizontal aiding besides
//! the inertial/astro solution), with at most `n` satellites tracked from 370 s to 590 s (the
//! receiver then has no fix: loose coupling gets nothing). Horizontal error over that window,
//! tight with n = 1, 2, 3 satellites vs loose.

use fusion::navigator::{GnssMode, Navigator, NavigatorConfig};
use msgs::SensorId;
use sextant_drivers_sim::offline::{OfflineSim, RunPoint, SatelliteLimit, run_navigator};
use sextant_drivers_sim::scenario::Scenario;
use std::path::Path;

const WINDOW: (f64, f64) = (370.0, 590.0);

/// (horizontal RMS in the window m, max m, GNSS epochs fused, mean NIS per dof).
fn run(mode: GnssMode, max_sats: usize) -> (f64, f64, u64, f64) {
    let path = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../config/scenarios/vehicle.toml"
    ));
    let scn = Scenario::load(path).unwrap();
    let sim = OfflineSim::new(&scn)
        .with_duration_s(WINDOW.1)
        .limit_satellites(SatelliteLimit {
            start_s: WINDOW.0,
            duration_s: WINDOW.1 - WINDOW.0,
            max_satellites: max_sats,
        });
    let epoch = sim.epoch_ns();
    let mut cfg = NavigatorConfig {
        gnss_mode: mode,
        ..NavigatorConfig::default()
    };
    cfg.updates.odometer = false;
    let mut nav = Navigator::new(cfg).unwrap();
    let (mut s2, mut max, mut n) = (0.0, 0.0f64, 0.0);
    run_navigator(sim, epoch, &mut nav, |p: &RunPoint| {
        if p.t_s >= WINDOW.0 {
            let h = p.horizontal_error_m();
            s2 += h * h;
            max = max.max(h);
            n += 1.0;
        }
    })
    .unwrap();
    let g = nav.health()[SensorId::Gnss as usize];
    let nis = g.nis_sum / g.nis_dof_sum.max(1) as f64;
    ((s2 / n).sqrt(), max, g.fused, nis)
}

#[test]
fn tight_coupling_works_with_one_two_three_satellites() {
    let loose = run(GnssMode::Loose, 3);
    eprintln!(
        "loose (no fix in the window): RMS {:.2} m, max {:.2} m",
        loose.0, loose.1
    );
    let mut rms = [0.0; 4];
    for n in [1, 2, 3] {
        let t = run(GnssMode::Tight, n);
        eprintln!(
            "tight, {n} satellites: RMS {:.2} m, max {:.2} m, GNSS epochs fused {}, \
             mean NIS/dof {:.2}",
            t.0, t.1, t.2, t.3
        );
        rms[n] = t.0;
        // Every GNSS epoch after alignment (100–590 s) minus the scenario outage (300–360 s)
        // has at least one satellite: ≈ 430 epochs, all must be fused.
        assert!(t.2 >= 420, "{n} satellites: only {} epochs fused", t.2);
        // Thousands of scalar updates: the mean NIS per dof of a consistent filter is 1 with
        // a standard error < 0.05; gating at 99.9 % trims it by < 0.01.
        assert!(
            (0.85..1.15).contains(&t.3),
            "{n} satellites: NIS/dof {}",
            t.3
        );
    }
    // One satellite cannot beat the receiver clock: its bias (0.1 m²/s) and drift
    // (0.01 m²/s³) random walks grow to √(0.1·220) ≈ 4.7 m and √(0.01·220) ≈ 1.5 m/s over the
    // 220 s window, so its pseudorange and range rate mostly re-estimate the clock — it must
    // at least not hurt (10 % margin).
    assert!(
        rms[1] < 1.1 * loose.0,
        "1 sat {} vs loose {}",
        rms[1],
        loose.0
    );
    // Two satellites: the clock is common to both, so their single difference bounds ONE
    // horizontal direction (u1 − u2 projected) and leaves the other as free as without GNSS.
    // With the free error split about evenly between the two horizontal axes the RMS can only
    // fall to ≈ √(1/2) ≈ 0.71 of the loose one (measured 0.60–0.61: the split is not even);
    // the direction-resolved check is in `sextant experiment tight-coupling`'s test. Here: two
    // must beat one and the loose run. Three satellites bound both horizontal directions
    // (measured 0.20–0.22 m vs 0.93–1.2 m).
    assert!(
        rms[2] < rms[1] && rms[2] < 0.8 * loose.0,
        "2 sats {} vs 1 sat {} vs loose {}",
        rms[2],
        rms[1],
        loose.0
    );
    assert!(
        rms[3] < 0.5 * loose.0,
        "3 sats {} vs loose {}",
        rms[3],
        loose.0
    );
    assert!(rms[3] <= rms[2] * 1.05);
}
