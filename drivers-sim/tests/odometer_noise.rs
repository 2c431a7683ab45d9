//! Odometer and non-holonomic-constraint noise of `config/filter.toml` against the simulator's
//! odometer model (drivers_sim::sensors::OdometerSim): normalized innovations on the default
//! vehicle run.

use fusion::navigator::{Navigator, NavigatorConfig};
use msgs::Record;
use msgs::SensorId;
use sextant_drivers_sim::offline::{OfflineSim, compare, feed};
use sextant_drivers_sim::scenario::Scenario;
use std::path::Path;

fn root() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

fn default_config() -> NavigatorConfig {
    crate::fixture::matched_filter()
}

/// `config/filter.toml` told the car it drives: the default scenario's car on the matched
/// world (no `[world.vehicle]`) is rigid, its wheel at the IMU, without slip, ride or
/// vibration, so the class noise of `[vehicle]` (a passenger car's) is zero for it and only the
/// odometer's white noise is left to test.
fn matched_car_config() -> NavigatorConfig {
    let mut c = default_config();
    crate::world_accuracy::rigid(&mut c);
    c
}

/// Figures of one run.
#[derive(Debug, Default)]
struct OdoRun {
    /// Odometer updates accepted, and their NIS sum over the dof sum (health counters).
    nis_per_dof: f64,
    updates: u64,
    rejected: u64,
    /// Non-holonomic constraint updates: mean NIS per dof, count.
    nhc_nis_per_dof: f64,
    nhc_updates: u64,
    horizontal_rms_m: f64,
    vertical_rms_m: f64,
    /// RMS over the same epochs of the filter's own 1-σ of the vertical, m.
    vertical_sigma_rms_m: f64,
    attitude_rms_deg: f64,
}

fn run(cfg: NavigatorConfig, duration_s: f64) -> OdoRun {
    run_on(matched_vehicle(), cfg, duration_s)
}

fn matched_vehicle() -> Scenario {
    sextant_drivers_sim::matched::scenario(
        Scenario::load(&root().join("config/scenarios/vehicle.toml")).expect("vehicle"),
    )
}

fn run_on(scn: Scenario, cfg: NavigatorConfig, duration_s: f64) -> OdoRun {
    let sim = OfflineSim::new(&scn).with_duration_s(duration_s);
    let epoch = sim.epoch_ns();
    let mut nav = Navigator::new(cfg).expect("config");
    let mut out = OdoRun::default();
    let (mut h2, mut v2, mut a2, mut n) = (0.0, 0.0, 0.0, 0.0);
    let mut var_d = 0.0;
    for msg in sim {
        if let Record::Truth(t) = &msg {
            if nav.is_navigating() && nav.time().ns == t.header.time_ns {
                let p = compare(&nav, t, epoch);
                if p.t_s >= 120.0 {
                    let e = p.pos_err_ned_m();
                    h2 += e.x * e.x + e.y * e.y;
                    v2 += e.z * e.z;
                    var_d += (p.c_e_n.transpose() * p.pos_cov_e_m2 * p.c_e_n)[(2, 2)];
                    a2 += p.att_err_e_rad.norm_squared();
                    n += 1.0;
                }
            }
            continue;
        }
        feed(&mut nav, &msg).unwrap_or_else(|e| panic!("{e}"));
    }
    let h = nav.health()[SensorId::Odometer as usize];
    out.nis_per_dof = h.nis_sum / h.nis_dof_sum as f64;
    out.updates = h.nis_count;
    out.rejected = h.rejected_gate;
    let c = nav.nhc_health();
    out.nhc_nis_per_dof = c.nis_sum / (2 * c.fused.max(1)) as f64;
    out.nhc_updates = c.fused;
    out.horizontal_rms_m = (h2 / n).sqrt();
    out.vertical_rms_m = (v2 / n).sqrt();
    out.vertical_sigma_rms_m = (var_d / n).sqrt();
    out.attitude_rms_deg = (a2 / n).sqrt().to_degrees();
    out
}

/// Every sample of the 600 s run fused, and the speed's NIS per dof inside the χ² band of a
/// consistent filter: with n ≈ 10 000 one-dof updates its mean is 1 ± √(2/n), 3σ ± 0.042.
fn assert_speed_nis_in_band(r: &OdoRun) {
    println!("{r:?}");
    let band = 3.0 * (2.0 / r.updates as f64).sqrt();
    assert!(r.updates > 9000, "{} updates", r.updates);
    assert!(
        (r.nis_per_dof - 1.0).abs() < band,
        "odometer NIS/dof {} outside 1 ± {band}",
        r.nis_per_dof
    );
}

#[test]
#[ignore = "diagnostic: the default 600 s run with several odometer/NHC noise settings"]
fn odometer_noise_report() {
    let base = default_config();
    for (so, sn) in [
        (0.05, 0.05),
        (0.02, 0.05),
        (0.02, 0.01),
        (0.02, 0.005),
        (0.02, 0.002),
        (0.02, 0.001),
    ] {
        let mut c = base.clone();
        c.aiding.odometer_sigma_m_s = so;
        c.aiding.nhc_sigma_m_s = sn;
        let r = run(c, 600.0);
        println!("odometer σ {so} m/s, NHC σ {sn} m/s: {r:?}");
    }
}

/// The default vehicle run (600 s, 20 Hz odometer) with `config/filter.toml` told its rigid
/// car ([`matched_car_config`]; the shipped passenger-car noise is conservative on it, odometer
/// NIS/dof 0.87, by the wheel slip in speed changes the rigid car does not have):
/// - odometer speed NIS per dof inside the χ² band: with n ≈ 10 000 one-dof updates the mean
///   NIS of a consistent filter is 1 ± √(2/n) = 1 ± 0.014; 3σ band ±0.042. (Before this
///   change: 0.07 for the joint speed + constraint update with σ = 0.05 m/s both.)
/// - the constraint update runs at the odometer rate, almost never gated;
/// - horizontal RMS no worse than before the change, when this run measured 0.201 m
///   (vertical 0.108 m, attitude 0.00064°); then 0.139 m (the odometer noise 2.5× smaller
///   and no longer biased by the interval mean during speed changes), 0.104 m since the
///   alignment starts from the mean of its window's fixes;
/// - the vertical, which the odometer hardly sees (it is the GNSS's and the barometer's), within
///   3 × the filter's own RMS σ of it: the RMS of a consistent filter's error over one run is
///   near its σ (a long-correlated error: about one draw, beyond 3σ with probability 0.3 %).
///   Measured 0.157 m against σ 0.128 m (0.108 m from a single start fix before).
#[test]
fn default_run_odometer_is_consistent() {
    let r = run(matched_car_config(), 600.0);
    assert_speed_nis_in_band(&r);
    // Gate at 0.999: 0.1 % of consistent updates rejected, ≈ 10; 3σ of a Poisson(10): 20.
    assert!(r.rejected <= 20, "{} rejected", r.rejected);
    assert!(r.nhc_updates + 20 >= r.updates);
    assert!(
        r.horizontal_rms_m < 0.201,
        "horizontal {}",
        r.horizontal_rms_m
    );
    assert!(
        r.vertical_rms_m < 3.0 * r.vertical_sigma_rms_m,
        "vertical {} m, filter σ {} m",
        r.vertical_rms_m,
        r.vertical_sigma_rms_m
    );
}

/// The same run with the odometer's frames stamped 10 ms late (`[world.time_tags]` alone, no
/// jitter) and the filter told so: every sample arrives after the IMU has passed its time of
/// validity, so each is fused in a replay from a checkpoint, re-fusing the odometer samples
/// since. Its interval-mean correction needs the epoch fused before it, which must rewind
/// with the state: when it did not, a re-fused sample met its own (or a later) epoch, lost
/// the `a·dt/2` correction (2.5 cm/s at 1 m/s², beyond the 2 cm/s noise) and the NIS per dof
/// left the band (1.11 measured, 53 samples gated out). Same band as above.
#[test]
fn late_odometer_samples_keep_their_interval_mean_correction() {
    let mut scn = matched_vehicle();
    scn.spec.world = Some(sextant_drivers_sim::world::WorldSection {
        time_tags: Some(sextant_drivers_sim::world::time_tags::TimeTagsSpec {
            enabled: true,
            odometer_latency_s: 0.01,
            gnss_jitter_s: 0.0,
            odometer_jitter_s: 0.0,
            star_tracker_jitter_s: 0.0,
        }),
        ..Default::default()
    });
    let mut cfg = matched_car_config();
    cfg.latency.odometer_s = 0.01;
    let r = run_on(scn, cfg, 600.0);
    assert_speed_nis_in_band(&r);
}
