//! Zero-velocity updates on the car's world: the car stops with its engine running, and the
//! mount's vibration (`[world.vibration]` of `config/scenarios/vehicle.toml`: engine orders at
//! 35–140 Hz, broadband 20–200 Hz) shakes every IMU sample by tenths of m/s². The filter's
//! static test on 0.1 s block means (`fusion::navigator::zupt`) must still see the stop, and
//! only the stop; the same test made sample by sample never does.

use crate::fixture::{car_filter, vehicle_path, with_segments};
use fusion::navigator::{Navigator, NavigatorConfig};
use msgs::Record;
use sextant_drivers_sim::offline::{OfflineSim, feed};
use sextant_drivers_sim::scenario::Scenario;

/// Alignment at rest (120 s), a drive to 10 m/s and back to rest, 30 s stopped.
const SEGMENTS: &str = r#"
    { type = "hold", duration_s = 120.0 },
    { type = "speed", to_m_s = 10.0, duration_s = 10.0 },
    { type = "cruise", duration_s = 20.0 },
    { type = "speed", to_m_s = 0.0, duration_s = 10.0 },
    { type = "hold", duration_s = 30.0 },
"#;
const DURATION_S: f64 = 190.0;
/// Start of the final stop, s.
const STOP_S: f64 = 160.0;

/// Run the car's world with `cfg`: (updates fused in the final stop, updates fused while the
/// truth moved faster than three times the update's own σ — a zero-velocity update there is
/// wrong beyond its noise model; slower, at the creeping start of a drive that no block mean
/// or odometer can yet see, it is within it —, first update after the stop began, s after
/// it). Each
/// update is placed at its own epoch (a late odometer sample rewinds the filter, and an
/// update may be fused first in the replay, after the IMU has passed it).
fn zupts(cfg: NavigatorConfig) -> (u64, u64, Option<f64>) {
    let path = vehicle_path();
    let text = std::fs::read_to_string(&path).expect("vehicle.toml");
    let edited = with_segments(&text, SEGMENTS, DURATION_S);
    let scn = Scenario::from_toml_str(&edited, &path).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        scn.spec
            .world
            .as_ref()
            .and_then(|w| w.vibration())
            .is_some(),
        "the car's world shakes its IMU"
    );
    let sim = OfflineSim::new(&scn).with_duration_s(DURATION_S);
    let epoch = sim.epoch_ns();
    let moving_m_s = 3.0 * cfg.aiding.zupt_sigma_m_s;
    let mut nav = Navigator::new(cfg).unwrap();
    // Truth speed by time (s since the epoch, m/s).
    let mut speeds: Vec<(f64, f64)> = Vec::new();
    let (mut moving, mut first) = (0, None);
    let (mut fused, mut stopped) = (0, 0);
    for msg in sim {
        if let Record::Truth(t) = &msg {
            let v = t.vel_ned_m_s;
            let speed = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            speeds.push(((t.header.time_ns - epoch) as f64 * 1e-9, speed));
            continue;
        }
        feed(&mut nav, &msg).unwrap();
        let now = nav.zupt_health().fused;
        if now > fused {
            let at = nav.last_zupt_counted().expect("an update was counted");
            let t_s = (at.ns - epoch) as f64 * 1e-9;
            // The truth (50 Hz) within 20 ms of the update's epoch.
            let speed = speeds
                .iter()
                .rev()
                .take_while(|(ts, _)| *ts >= t_s - 0.02)
                .filter(|(ts, _)| *ts <= t_s + 0.02)
                .map(|(_, v)| *v)
                .fold(0.0, f64::max);
            if speed > moving_m_s {
                println!("update at {t_s:.3} s while the truth moved at {speed:.4} m/s");
                moving += now - fused;
            }
            if t_s >= STOP_S {
                stopped += now - fused;
                first.get_or_insert(t_s - STOP_S);
            }
            fused = now;
        }
    }
    (stopped, moving, first)
}

#[test]
fn a_stopped_car_with_its_engine_running_gets_zero_velocity_updates() {
    let car = car_filter();
    assert!(car.updates.zupt && car.aiding.zupt_interval_s > 0.0);
    let (fused, moving, first) = zupts(car.clone());
    println!(
        "block test: {fused} updates in the stop, {moving} while moving, first {first:?} s into it"
    );
    // 30 s stopped: the 1 s window, then one update per 0.1 s.
    assert!(fused >= 250, "{fused} updates");
    assert_eq!(moving, 0, "an update while the car moved");
    assert!(first.is_some_and(|s| s <= 2.5), "{first:?}");
    let mut per_sample = car;
    per_sample.aiding.zupt_interval_s = 0.0;
    let (fused, _, _) = zupts(per_sample);
    println!("sample-by-sample test: {fused} updates in the stop");
    assert_eq!(
        fused, 0,
        "the vibration should defeat a sample-by-sample test"
    );
}
