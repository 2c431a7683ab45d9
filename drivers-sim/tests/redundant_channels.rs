//! Paper 004 simulator: redundant single-axis channels and the aircraft (UAV) trajectory.

use fusion::strapdown::ImuIncrement;
use nalgebra::{Matrix3, Rotation3, Vector3};
use sextant_drivers_sim::scenario::{Scenario, period_ns};
use sextant_drivers_sim::sources::{ImuSource, SampleSource};
use sextant_drivers_sim::truth::TruthGenerator;
use std::path::{Path, PathBuf};

fn scenario_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../config/scenarios/{name}.toml"))
}

/// The UAV scenario with `edit` applied to its text (same sensors directory).
fn uav_with(edit: impl Fn(String) -> String) -> Scenario {
    let p = scenario_path("uav");
    let text = std::fs::read_to_string(&p).expect("uav.toml");
    match Scenario::from_toml_str(&edit(text), &p) {
        Ok(s) => s,
        Err(e) => panic!("{e}"),
    }
}

/// Shorter flight: the first cruise leg cut to 100 s so that take-off, climb, level-off and a
/// coordinated turn (peak bank 9°) happen within 1000 s.
fn short_uav() -> Scenario {
    uav_with(|t| {
        let from = "{ type = \"cruise\", duration_s = 1140.0 },";
        assert!(t.contains(from), "uav.toml has no `{from}`");
        crate::fixture::replace_present(
            &t.replacen(from, "{ type = \"cruise\", duration_s = 100.0 },", 1),
            "duration_s = 18000.0",
            "duration_s = 1000.0",
        )
    })
}

#[test]
fn shipped_uav_scenario_validates_with_four_pyramid_channels() {
    let scn = Scenario::load(&scenario_path("uav")).expect("uav.toml");
    assert_eq!(scn.spec.scenario.duration_s, 18_000.0);
    let ch = scn.spec.imu.channels.as_ref().expect("channels");
    let axes = ch.unit_axes();
    assert_eq!(axes.len(), 4);
    // e_1 = (cos α cos 45°, cos α sin 45°, sin α), α = 28.7°.
    let a = 28.7_f64.to_radians();
    assert!((axes[0][0] - a.cos() * 0.5f64.sqrt()).abs() < 1e-15);
    assert!((axes[0][2] - a.sin()).abs() < 1e-15);
    // The default scenarios carry no channels: their IMU output is unchanged.
    let veh = Scenario::load(&scenario_path("vehicle")).expect("vehicle.toml");
    assert!(veh.spec.imu.channels.is_none());
    let mut src = ImuSource::new(&veh, 0);
    let s = src.sample(period_ns(veh.spec.imu.rate_hz));
    assert_eq!(s.n_channels, 0);
}

/// Error-free channels: the least-squares triad of the sample equals the truth increments,
/// and mechanizing it reproduces the aircraft truth (take-off, 5° climb, level-off, banked
/// turn). This checks the aircraft kinematics (pitch/roll rates as exact derivatives of the
/// pitch/bank profiles): a wrong roll rate would leave an attitude error of the order of the
/// bank angle (0.16 rad).
///
/// Budget: 100 Hz mechanization with rates ≤ 0.06 rad/s and accelerations ≤ 1.6 m/s²: the
/// third-order residual per interval (ωT)²|a|T/12 ≈ 5e-11 m/s, ≤ 5e-6 m/s over 1e5 intervals;
/// the vertical channel amplifies by ≤ cosh(1000/570) ≈ 3: bounds 2 cm, 0.1 mm/s... taken
/// as 5 cm / 1 mm/s / 1 µrad to leave room for the LS rounding (1e-16 relative per step).
/// On the matched world: the world's gravity field and the engine's vibration are outside the
/// mechanization's model by design, and this checks its algebra.
#[test]
fn strapdown_of_ls_triad_reproduces_aircraft_truth() {
    let scn = sextant_drivers_sim::matched::scenario(short_uav());
    let mut src = ImuSource::new(&scn, 0);
    src.model.enabled = false;
    src.channels.as_mut().expect("channels").enabled = false;
    let mut truth = TruthGenerator::new(&scn);
    let (mut state, mut sd) = truth.current().reference_ins();
    let p = period_ns(scn.spec.imu.rate_hz);
    let (mut max_pos, mut max_vel, mut max_att) = (0.0f64, 0.0f64, 0.0f64);
    let (mut max_bank, mut max_h) = (0.0f64, 0.0f64);
    let mut k = 1;
    let mut gen_check = TruthGenerator::new(&scn);
    while k * p <= scn.duration_ns() {
        let m = src.sample(k * p);
        assert_eq!(m.n_channels, 4);
        let inc = gen_check.advance_to(k * p);
        let d = (Vector3::from(m.delta_angle_rad) - inc.delta_angle_b_rad).norm();
        assert!(d < 1e-15, "LS triad differs from the truth by {d} rad");
        sd.step(
            &mut state,
            &ImuIncrement {
                dt_s: m.dt_s,
                delta_angle_rad: Vector3::from(m.delta_angle_rad),
                delta_velocity_m_s: Vector3::from(m.delta_velocity_m_s),
            },
        );
        truth.advance_to(k * p);
        let t = truth.current();
        max_bank = max_bank.max(t.roll_pitch_heading_rad.x.abs());
        max_h = max_h.max(t.geodetic.height_m);
        max_pos = max_pos.max((state.r_e - t.r_e_m).norm());
        max_vel = max_vel.max((state.v_e - t.v_e_m_s()).norm());
        let c_e_b_true = t.c_e_n * t.c_n_b;
        let c_err: Matrix3<f64> =
            state.q_e_b.to_rotation_matrix().into_inner() * c_e_b_true.transpose();
        max_att = max_att.max(Rotation3::from_matrix_unchecked(c_err).angle());
        k += 1;
    }
    eprintln!(
        "aircraft: bank ≤ {:.2}°, height ≤ {max_h:.0} m; strapdown vs truth: pos {max_pos:.3e} m, vel {max_vel:.3e} m/s, att {max_att:.3e} rad",
        max_bank.to_degrees()
    );
    // Coordinated 90° turn in 60 s at 30 m/s: peak rate π/60, bank atan(30·π/60/g0) = 9.1°.
    let bank = (30.0 * std::f64::consts::PI / 60.0 / 9.806_65).atan();
    assert!((max_bank - bank).abs() < 1e-3, "bank {max_bank}");
    assert!(max_h > 1000.0 && max_h < 1060.0, "climb height {max_h}");
    assert!(max_pos < 0.05, "position error {max_pos} m");
    assert!(max_vel < 1e-3, "velocity error {max_vel} m/s");
    assert!(max_att < 1e-6, "attitude error {max_att} rad");
}

/// Channel errors: over 60 s on the ground, each channel's mean rate equals its projection of
/// the truth plus the bias the model applied, within the noise. And the injected failures
/// have the configured size.
#[test]
fn channel_errors_and_failures_have_configured_size() {
    let scn = uav_with(|t| {
        crate::fixture::replace_present(
            &t,
            "channels = { layout = \"pyramid\", n = 4, alpha_deg = 28.7 }",
            "channels = { layout = \"pyramid\", n = 5, alpha_deg = 35.26, failures = [\
             { channel = 1, sensor = \"gyro\", kind = \"bias_step\", start_s = 30.0, magnitude = 3600.0 },\
             { channel = 2, sensor = \"accel\", kind = \"stuck\", start_s = 30.0 },\
             { channel = 3, sensor = \"gyro\", kind = \"drift_ramp\", start_s = 30.0, magnitude = 100.0 },\
             { channel = 4, sensor = \"accel\", kind = \"noise_burst\", start_s = 30.0, duration_s = 10.0, magnitude = 100000.0 } ] }",
        )
    });
    let mut src = ImuSource::new(&scn, 0);
    let p = period_ns(scn.spec.imu.rate_hz);
    let mut truth = TruthGenerator::new(&scn);
    let axes = src.channels.as_ref().unwrap().axes().to_vec();
    let (sg, sa) = src.channels.as_ref().unwrap().interval_sigmas(0.01);
    let deg_h = std::f64::consts::PI / 180.0 / 3600.0;
    let mut sum_g = [0.0f64; 5];
    let mut stuck = None;
    let mut burst_sq = 0.0;
    let mut burst_n = 0;
    let mut ramp_last = 0.0;
    for k in 1..=6000i64 {
        let m = src.sample(k * p);
        assert_eq!(m.n_channels, 5);
        let inc = truth.advance_to(k * p);
        let t_s = (k * p) as f64 * 1e-9;
        if k <= 3000 {
            for (i, s) in sum_g.iter_mut().enumerate() {
                *s += m.channel_delta_angle_rad[i]
                    - Vector3::from(axes[i]).dot(&inc.delta_angle_b_rad);
            }
        } else {
            // Stuck accelerometer: repeats its last healthy value exactly.
            let v = m.channel_delta_velocity_m_s[2];
            let s = *stuck.get_or_insert(v);
            assert_eq!(v, s);
            if t_s < 40.0 {
                let e = Vector3::from(axes[4]).dot(&inc.delta_velocity_b_m_s);
                burst_sq += (m.channel_delta_velocity_m_s[4] - e).powi(2);
                burst_n += 1;
            }
            ramp_last = m.channel_delta_angle_rad[3];
        }
        assert!(m.channel_temperature_c[0] > 14.9 && m.channel_temperature_c[0] < 15.1);
    }
    // Healthy 30 s mean: 3000 samples, noise σ_mean = σ/√3000 per interval; gyro biases of
    // the MEMS grade are 10 °/h 1-σ, i.e. 4.8e-7 rad per interval ≈ 0.05 σ: the mean must be
    // within 5 σ_mean + 5 × bias σ.
    for (i, s) in sum_g.iter().enumerate() {
        let mean = s / 3000.0;
        assert!(
            mean.abs() < 5.0 * sg / 3000f64.sqrt() + 5.0 * 10.0 * deg_h * 0.01,
            "channel {i}: {mean}"
        );
    }
    // Noise burst of 1e5 µg = 0.98 m/s² per sample: σ of Δv = 0.98·0.01 = 9.8e-3 m/s over
    // 1000 samples (χ² ± 10 %).
    let burst = (burst_sq / burst_n as f64).sqrt();
    let want = (1e5 * 1e-6 * 9.806_65 * 0.01f64).hypot(sa);
    assert!(
        (burst / want - 1.0).abs() < 0.1,
        "burst σ {burst} vs {want}"
    );
    // Drift ramp 100 °/h per s for 30 s: bias 3000 °/h = 0.8 °/s at the end, Δθ 1.45e-4 rad
    // per interval (the channel's own noise and bias are < 1e-5 rad).
    let ramp_want = 100.0 * deg_h * 29.995 * 0.01;
    assert!(
        (ramp_last - ramp_want).abs() < 5.0 * sg + 2e-6,
        "ramp {ramp_last} vs {ramp_want}"
    );
}

/// Bad channel configuration is rejected with the key named.
#[test]
fn bad_channel_config_is_named() {
    let p = scenario_path("uav");
    let text = std::fs::read_to_string(&p).unwrap();
    for (from, to, key) in [
        ("n = 4,", "n = 2,", "imu.channels.n"),
        (
            "alpha_deg = 28.7",
            "alpha_deg = 90.0",
            "imu.channels.alpha_deg",
        ),
        (
            "alpha_deg = 28.7 }",
            "alpha_deg = 28.7, failures = [{ channel = 7, sensor = \"gyro\", kind = \"stuck\", start_s = 1.0 }] }",
            "imu.channels.failures[0].channel",
        ),
    ] {
        let t = text.replace(from, to);
        let e = Scenario::from_toml_str(&t, &p).expect_err(key).to_string();
        assert!(e.contains(key), "{e}");
    }
}
