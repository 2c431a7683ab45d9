//! The paper-000 stand (`config/scenarios/astro_stand.toml`) as the astro-calibration
//! experiment simulates it: the boresight convention of the simulator equals the calibration
//! tool's, and the experiment's shortcut for a static stand (one constant truth point, IMU
//! increments `ω_ib·dt`, `f·dt`) reproduces the driver sources exactly.

use fusion::boresight;
use nalgebra::Vector3;
use sextant_drivers_sim::imu::ImuErrorModel;
use sextant_drivers_sim::scenario::{Scenario, period_ns};
use sextant_drivers_sim::sensors::{StarTrackerSim, kappa_matrix};
use sextant_drivers_sim::sources::{ImuSource, SampleSource, StarTrackerSource};
use sextant_drivers_sim::truth::{Increments, TruthGenerator};
use std::path::Path;

fn stand() -> Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/scenarios/astro_stand.toml");
    Scenario::load(&path).expect("astro_stand.toml")
}

#[test]
fn simulator_and_calibration_use_the_same_kappa_matrix() {
    for k in [[0.3f64, 0.45, -0.35], [-1.0, 2.0, 0.5], [10.0, -20.0, 30.0]] {
        let rad = [k[0].to_radians(), k[1].to_radians(), k[2].to_radians()];
        let sim = kappa_matrix(&rad);
        let cal = boresight::kappa_matrix(&Vector3::from(rad));
        assert!((sim - cal).abs().max() < 1e-15, "{k:?}");
        assert!(
            (boresight::kappa_from_matrix(&sim) - Vector3::from(rad))
                .abs()
                .max()
                < 1e-14
        );
    }
    assert_eq!(
        sextant_drivers_sim::sensors::c_s_b_nominal(),
        boresight::c_s_b_nominal()
    );
}

/// The stand's IMU source integrates the 1 ms truth grid with the trapezoid rule; for a static
/// stand the integrand is constant, so each increment is `ω_ib·dt`, `f·dt` up to the rounding
/// of summing 10 grid steps (≈ 1e-15 relative), and the error model applied to it draws the
/// same random numbers in the same order.
#[test]
fn static_shortcut_equals_the_driver_sources() {
    let scn = stand();
    let epoch = scn.epoch_gps().ns;
    let truth = *TruthGenerator::new(&scn).current();
    let mut src = ImuSource::new(&scn, epoch);
    let mut model = ImuErrorModel::new(&scn);
    let p = period_ns(scn.spec.imu.rate_hz);
    let dt = p as f64 * 1e-9;
    let inc = Increments {
        dt_s: dt,
        delta_angle_b_rad: truth.w_ib_b_rad_s * dt,
        delta_velocity_b_m_s: truth.f_b_m_s2 * dt,
        distance_x_m: 0.0,
    };
    for k in 1..=300i64 {
        let s = src.sample(k * p);
        let e = model.next_interval(k as f64 * dt, dt);
        let (da, dv) = model.corrupt(&e, &inc);
        let da_src = Vector3::from(s.delta_angle_rad);
        let dv_src = Vector3::from(s.delta_velocity_m_s);
        assert!((da_src - da).norm() < 1e-12 * da.norm().max(1e-9), "k {k}");
        assert!((dv_src - dv).norm() < 1e-12 * dv.norm(), "k {k}");
    }
    // Star tracker: the source at whole seconds equals the sensor model on the constant truth.
    let mut st_src = StarTrackerSource::new(&scn, epoch);
    let mut st = StarTrackerSim::new(&scn);
    for k in 0..20i64 {
        let t_ns = k * 1_000_000_000;
        let a = st_src.sample(t_ns);
        let b = st.sample(k as f64, epoch + t_ns, &truth);
        for i in 0..4 {
            assert!(
                (a.q_sensor_icrf[i] - b.q_sensor_icrf[i]).abs() < 1e-12,
                "k {k}"
            );
        }
    }
}
