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
use sextant_drivers_sim::matched;
use sextant_drivers_sim::offline::{OfflineSim, RunPoint, run_navigator};
use sextant_drivers_sim::scenario::Scenario;
use sextant_drivers_sim::sources::GnssSource;
use sextant_drivers_sim::world::{EFFECTS, GNSS_EFFECTS};
use std::path::Path;

/// The world's effects beyond the GNSS ones (motion, gravity and the sensors' own), each
/// switched on by its name.
const NON_GNSS_EFFECTS: &[&str] = EFFECTS.split_at(GNSS_EFFECTS.len()).1;

fn root() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

/// The shipped car's filter (`config/filter.toml`).
fn car_filter() -> NavigatorConfig {
    let text = std::fs::read_to_string(root().join("config/filter.toml")).unwrap();
    toml::from_str(&text).unwrap()
}

/// The car's tuning with the matched installation (antenna and wheel at the IMU, white GNSS
/// errors, no time tags); the reports add what their world has.
fn filter_config() -> NavigatorConfig {
    matched::filter(car_filter())
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
    // The scenario with its shared world file merged in: every effect's table is here.
    let mut doc = Scenario::read_resolved_toml(&path).unwrap();
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
                // The car's installation of the effects this world has.
                let mut cfg =
                    matched::installed_for(scn.spec.world.as_ref(), car_filter(), &car_filter());
                cfg.gnss_mode = mode;
                cfg.gnss.error_correlation_time_s = tau_s;
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

/// The default vehicle scenario with only the `on` tables of its world.
fn vehicle_in_motion(on: &[&str]) -> Scenario {
    let mut scn = Scenario::load(&root().join("config/scenarios/vehicle.toml")).unwrap();
    scn.spec.world = Some(scn.spec.world.unwrap().only(on).unwrap());
    scn
}

#[test]
#[ignore = "600 s of 200 Hz simulation per line: minutes in release; a report, not a CI test"]
fn world_motion_report() {
    for on in [
        &[][..],
        &["vehicle"],
        &["vibration"],
        &["gravity"],
        &["imu"],
        &["star_tracker"],
        &["baro"],
        NON_GNSS_EFFECTS,
    ] {
        motion_report_line(&format!("{on:?}"), &vehicle_in_motion(on));
    }
}

#[test]
#[ignore = "600 s of 200 Hz simulation per line: minutes in release; a report, not a CI test"]
fn world_motion_vehicle_breakdown() {
    type Keep = fn(&mut sextant_drivers_sim::world::vehicle::VehicleSpec);
    let parts: [(&str, Keep); 4] = [
        ("road (grade, bank)", |v| {
            v.pitch_per_accel_deg = 0.0;
            v.roll_per_lateral_accel_deg = 0.0;
            v.sideslip_per_lateral_accel_deg = 0.0;
            v.ride_heave_sigma_m = 0.0;
            v.ride_pitch_sigma_deg = 0.0;
            v.ride_roll_sigma_deg = 0.0;
            v.wheel_slip_per_accel_s2_m = 0.0;
            v.odometer_lever_arm_b_m = [0.0; 3];
        }),
        ("body (load transfer, ride)", |v| {
            v.grade_sigma_deg = 0.0;
            v.bank_sigma_deg = 0.0;
            v.sideslip_per_lateral_accel_deg = 0.0;
            v.wheel_slip_per_accel_s2_m = 0.0;
            v.odometer_lever_arm_b_m = [0.0; 3];
        }),
        ("sideslip", |v| {
            let s = v.sideslip_per_lateral_accel_deg;
            *v = zero_vehicle(*v);
            v.sideslip_per_lateral_accel_deg = s;
        }),
        ("rear wheel (slip, lever arm, kinematic sideslip)", |v| {
            let (s, l) = (v.wheel_slip_per_accel_s2_m, v.odometer_lever_arm_b_m);
            *v = zero_vehicle(*v);
            v.wheel_slip_per_accel_s2_m = s;
            v.odometer_lever_arm_b_m = l;
        }),
    ];
    for (label, keep) in parts {
        let mut scn = vehicle_in_motion(&["vehicle"]);
        let mut w = scn.spec.world.unwrap();
        keep(w.vehicle.as_mut().unwrap());
        scn.spec.world = Some(w);
        // Each part is a car of its own: only the last reads its odometer off the IMU.
        let mut cfg = filter_config();
        if label.starts_with("rear wheel") {
            cfg.vehicle.wheel_lever_arm_b_m = WHEEL_TAPE_B_M;
        }
        motion_report_line_with(&format!("vehicle: {label}"), &scn, cfg);
    }
    // The car with each other effect: which ones compound.
    for other in ["vibration", "gravity", "imu", "star_tracker", "baro"] {
        let on = ["vehicle", other];
        motion_report_line(&format!("{on:?}"), &vehicle_in_motion(&on));
    }
}

/// Every magnitude of the vehicle set to zero (its lengths and frequencies kept).
fn zero_vehicle(
    v: sextant_drivers_sim::world::vehicle::VehicleSpec,
) -> sextant_drivers_sim::world::vehicle::VehicleSpec {
    sextant_drivers_sim::world::vehicle::VehicleSpec {
        grade_sigma_deg: 0.0,
        bank_sigma_deg: 0.0,
        pitch_per_accel_deg: 0.0,
        roll_per_lateral_accel_deg: 0.0,
        sideslip_per_lateral_accel_deg: 0.0,
        ride_heave_sigma_m: 0.0,
        ride_pitch_sigma_deg: 0.0,
        ride_roll_sigma_deg: 0.0,
        wheel_slip_per_accel_s2_m: 0.0,
        odometer_lever_arm_b_m: [0.0; 3],
        ..v
    }
}

/// The odometer wheel's contact point from the IMU on the car of `[world.vehicle]`, as a user
/// measures it with a tape (`config/filter.toml` `[vehicle]` comment), body axes, m.
const WHEEL_TAPE_B_M: [f64; 3] = [-1.5, -0.8, 1.0];

/// One line of the motion world's report: the shipped loose filter on `scn`, after 150 s,
/// with the car's installation of the effects `scn` has (`matched::installed_for`).
fn motion_report_line(label: &str, scn: &Scenario) {
    let cfg = matched::installed_for(scn.spec.world.as_ref(), car_filter(), &car_filter());
    motion_report_line_with(label, scn, cfg);
}

/// The filter's vehicle model, part by part, on the car of `[world.vehicle]` (and with every
/// motion-world table): the rigid model at the IMU (no lever arm, no class noise: the
/// constraint σ alone, as before the vehicle model), the lever arm alone, the class noise
/// alone, both.
#[test]
#[ignore = "600 s of 200 Hz simulation per line: minutes in release; a report, not a CI test"]
fn world_motion_vehicle_model() {
    type Model = fn(&mut NavigatorConfig);
    let models: [(&str, Model); 4] = [
        ("rigid at the IMU", |c| {
            c.vehicle.wheel_lever_arm_b_m = [0.0; 3];
            rigid(c);
        }),
        ("lever arm, no class noise", rigid),
        ("class noise at the IMU", |c| {
            c.vehicle.wheel_lever_arm_b_m = [0.0; 3]
        }),
        ("lever arm and class noise", |_| {}),
    ];
    for on in [&["vehicle"][..], &["vehicle", "baro"], NON_GNSS_EFFECTS] {
        let scn = vehicle_in_motion(on);
        for (label, model) in models {
            let mut cfg = filter_config();
            cfg.vehicle.wheel_lever_arm_b_m = WHEEL_TAPE_B_M;
            model(&mut cfg);
            motion_report_line_with(&format!("{on:?}, filter {label}"), &scn, cfg);
        }
    }
}

/// The vehicle class's noise switched off: a rigid car, the constraint σ alone.
pub(crate) fn rigid(c: &mut NavigatorConfig) {
    let v = &mut c.vehicle;
    v.rear_slip_per_lateral_accel_deg = 0.0;
    v.pitch_per_accel_deg = 0.0;
    v.wheel_slip_per_accel_s2_m = 0.0;
    v.ride_heave_sigma_m = 0.0;
    v.ride_pitch_sigma_deg = 0.0;
    v.ride_roll_sigma_deg = 0.0;
    v.mount_vibration_velocity_sigma_m_s = 0.0;
}

/// One line of the motion world's report with the filter configuration `cfg`.
fn motion_report_line_with(label: &str, scn: &Scenario, cfg: NavigatorConfig) {
    let sim = OfflineSim::new(scn);
    let epoch = sim.epoch_ns();
    let mut nav = Navigator::new(cfg).unwrap();
    let (mut h, mut v, mut yaw, mut tilt, mut nees) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), 0.0);
    let mut outage_max = 0.0f64;
    run_navigator(sim, epoch, &mut nav, |p: &RunPoint| {
        if p.t_s < 150.0 {
            return;
        }
        let e = p.pos_err_ned_m();
        h.push(e.x.hypot(e.y));
        v.push(e.z);
        let a = p.att_err_ned_rad();
        tilt.push(a.x.hypot(a.y));
        yaw.push(a.z);
        nees += p.nees()[0];
        if (300.0..360.0).contains(&p.t_s) {
            outage_max = outage_max.max(e.x.hypot(e.y));
        }
    })
    .unwrap();
    let n = h.len() as f64;
    let health = nav.health();
    let [odo, baro] = [msgs::SensorId::Odometer, msgs::SensorId::Baro].map(|id| {
        let s = health[id as usize];
        (
            s.nis_sum / s.nis_dof_sum.max(1) as f64,
            s.fused,
            s.rejected_gate,
        )
    });
    let c = nav.nhc_health();
    println!(
        "motion world {label}: horizontal RMS {:.3} m, vertical RMS {:.3} m, max horizontal \
         in the 300–360 s GNSS outage {outage_max:.3} m, tilt RMS {:.1}″, heading RMS {:.1}″, \
         position NEES {:.2}; NIS/dof odometer {:.2}, constraint {:.2} (rejected {}); baro \
         fused {} rejected {}",
        rms(&h),
        rms(&v),
        rms(&tilt).to_degrees() * 3600.0,
        rms(&yaw).to_degrees() * 3600.0,
        nees / n,
        odo.0,
        c.nis_sum / (2 * c.fused.max(1)) as f64,
        c.rejected_gate,
        baro.1,
        baro.2,
    );
}

/// The whole motion world with the rigid filter (the constraint σ alone at the IMU) and with
/// the vehicle model: vertical error, its σ and the vertical velocity error every 50 s, then
/// the gate rejections of GNSS and baro and the constraint's NIS per dof — where the
/// interaction of the car with the other effects goes.
#[test]
#[ignore = "600 s of 200 Hz simulation per line: minutes in release; a report, not a CI test"]
fn world_motion_interaction() {
    let scn = vehicle_in_motion(NON_GNSS_EFFECTS);
    type Model = fn(&mut NavigatorConfig);
    let models: [(&str, Model); 2] = [
        ("rigid at the IMU", |c| {
            c.vehicle.wheel_lever_arm_b_m = [0.0; 3];
            rigid(c);
        }),
        ("lever arm and class noise", |_| {}),
    ];
    for (label, model) in models {
        let mut cfg = filter_config();
        cfg.vehicle.wheel_lever_arm_b_m = WHEEL_TAPE_B_M;
        model(&mut cfg);
        let sim = OfflineSim::new(&scn);
        let epoch = sim.epoch_ns();
        let mut nav = Navigator::new(cfg).unwrap();
        let mut next = 150.0;
        run_navigator(sim, epoch, &mut nav, |p: &RunPoint| {
            if p.t_s >= next {
                next += 50.0;
                let c = p.c_e_n.transpose() * p.pos_cov_e_m2 * p.c_e_n;
                let ab = p.accel_bias_true_m_s2 - p.accel_bias_est_m_s2;
                println!(
                    "{label} t {:.0} s: down error {:.3} m (σ {:.3}), down velocity error \
                     {:.4} m/s, accel bias error z {:.1} µg",
                    p.t_s,
                    p.pos_err_ned_m().z,
                    c[(2, 2)].sqrt(),
                    p.vel_err_ned_m_s().z,
                    ab.z / 9.80665e-6
                );
            }
        })
        .unwrap();
        let h = nav.health();
        let g = h[msgs::SensorId::Gnss as usize];
        let b = h[msgs::SensorId::Baro as usize];
        let c = nav.nhc_health();
        println!(
            "{label}: GNSS fused {} rejected {}, baro fused {} rejected {}, constraint NIS/dof \
             {:.3} over {} (rejected {}), baro bias estimate {:.2} m",
            g.fused,
            g.rejected_gate,
            b.fused,
            b.rejected_gate,
            c.nis_sum / (2 * c.fused.max(1)) as f64,
            c.fused,
            c.rejected_gate,
            nav.baro_bias_m()
        );
    }
}
