//! Tests of the motion world through the truth generator: magnitudes and correlations of the
//! vehicle and vibration effects, the odometer's physics, the gravity disturbance in the
//! specific force, and a perfect strapdown INS following the perturbed truth.

use super::gauss_markov::mean_and_standard_error;
use super::vehicle::{Intent, VehicleSpec, VehicleWorld, Vibration, VibrationSpec};
use crate::scenario::{Scenario, period_ns};
use crate::sources::{ImuSource, SampleSource};
use crate::truth::TruthGenerator;
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha20Rng;
use std::f64::consts::TAU;
use std::path::{Path, PathBuf};

fn vehicle_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/scenarios/vehicle.toml")
}

/// The default vehicle scenario with only the `on` tables of its world, `segments` in place
/// of its trajectory and `duration_s`.
pub(crate) fn vehicle_in_motion_world(on: &[&str], segments: &str, duration_s: f64) -> Scenario {
    let text = std::fs::read_to_string(vehicle_path()).unwrap();
    assert!(
        text.contains("duration_s = 600.0"),
        "vehicle.toml's duration"
    );
    let seg_start = text.find("segments = [").unwrap();
    let seg_end = seg_start + text[seg_start..].find("\n]\n").unwrap() + 3;
    let text = format!(
        "{}segments = [{segments}]\n{}",
        &text[..seg_start],
        &text[seg_end..]
    )
    .replace(
        "duration_s = 600.0",
        &format!("duration_s = {duration_s:.1}"),
    );
    let mut scn = Scenario::from_toml_str(&text, &vehicle_path()).unwrap();
    scn.spec.world = Some(scn.spec.world.expect("the car's world").only(on).unwrap());
    scn
}

/// The car's road and vibration specs (the shipped world's, whichever tables `_scn` keeps).
fn spec_of(_scn: &Scenario) -> (VehicleSpec, VibrationSpec) {
    let w = Scenario::load(&vehicle_path()).unwrap().spec.world.unwrap();
    (w.vehicle.unwrap(), w.vibration.unwrap())
}

/// Road slope and bank: variance and correlation at one correlation length (e^{−1/2}) over
/// independent roads, within 4 standard errors; the ride heave at speed the same at a lag of
/// 0.1 s (cos(2πf₀τ)·e^{−(2π·bw·τ)²/2}, scaled by V²/(V² + V½²)).
#[test]
fn road_and_ride_magnitude_and_correlation() {
    let scn = vehicle_in_motion_world(&["vehicle"], r#"{ type = "hold", duration_s = 1.0 }"#, 1.0);
    let (spec, _) = spec_of(&scn);
    let mut rng = ChaCha20Rng::seed_from_u64(21);
    let n = 3000;
    let (mut g, mut gl, mut b, mut bl, mut h, mut hl) =
        (vec![], vec![], vec![], vec![], vec![], vec![]);
    let v = 15.0;
    let m = v * v / (v * v + spec.ride_half_speed_m_s.powi(2));
    let lag_s = 0.1;
    let intent = |d: f64| Intent {
        distance_m: d,
        speed: [v, 0.0, 0.0],
        course: [0.3, 0.0, 0.0],
    };
    for _ in 0..n {
        let w = VehicleWorld::new(spec, &mut rng);
        let s0 = rng.random::<f64>() * 1e4;
        let (g0, b0) = w.road(s0);
        g.push(g0 * g0);
        gl.push(g0 * w.road(s0 + spec.grade_length_m).0);
        b.push(b0 * b0);
        bl.push(b0 * w.road(s0 + spec.bank_length_m).1);
        let t0 = rng.random::<f64>() * 1e3;
        let h0 = w.state(t0, &intent(s0)).heave_up[0];
        h.push(h0 * h0);
        hl.push(h0 * w.state(t0 + lag_s, &intent(s0)).heave_up[0]);
    }
    let (f, bw) = (spec.ride_frequency_hz, spec.ride_bandwidth_hz);
    let rho_ride = (TAU * f * lag_s).cos() * (-(TAU * bw * lag_s).powi(2) / 2.0).exp();
    for (name, sq, lag, sigma, rho) in [
        (
            "grade",
            &g,
            &gl,
            spec.grade_sigma_deg.to_radians().tan(),
            (-0.5f64).exp(),
        ),
        (
            "bank",
            &b,
            &bl,
            spec.bank_sigma_deg.to_radians(),
            (-0.5f64).exp(),
        ),
        ("heave", &h, &hl, m * spec.ride_heave_sigma_m, rho_ride),
    ] {
        let (var, se_v) = mean_and_standard_error(sq);
        let (cov, se_c) = mean_and_standard_error(lag);
        let s2 = sigma * sigma;
        assert!(
            (var - s2).abs() < 4.0 * se_v,
            "{name}: {var} vs {s2} (SE {se_v})"
        );
        assert!(
            (cov - rho * s2).abs() < 4.0 * se_c,
            "{name}: lag covariance {cov} vs {} (SE {se_c})",
            rho * s2
        );
        assert!((rho * s2).abs() > 4.0 * se_c && s2 * (1.0 - rho) > 4.0 * se_c);
    }
}

/// Vibration: the acceleration's variance per axis is the sum of the engine orders' and the
/// broadband's mean squares, its autocovariance at 3 ms the sum of `rms²·cos(ωτ)` and the flat
/// band's `σ²(sin ω₂τ − sin ω₁τ)/((ω₂ − ω₁)τ)`, over independent mounts within 4 SE.
#[test]
fn vibration_magnitude_and_correlation() {
    let scn = vehicle_in_motion_world(
        &["vibration"],
        r#"{ type = "hold", duration_s = 1.0 }"#,
        1.0,
    );
    let (_, spec) = spec_of(&scn);
    let tau = 3e-3;
    let (mut var_model, mut cov_model) = (0.0, 0.0);
    for (k, rms) in spec.engine_order_rms_m_s2.iter().enumerate() {
        var_model += rms * rms;
        cov_model += rms * rms * (TAU * spec.engine_rotation_hz * (k + 1) as f64 * tau).cos();
    }
    let [lo, hi] = spec.broadband_band_hz.map(|f| TAU * f);
    let s2 = spec.broadband_rms_m_s2.powi(2);
    var_model += s2;
    cov_model += s2 * ((hi * tau).sin() - (lo * tau).sin()) / ((hi - lo) * tau);
    let mut rng = ChaCha20Rng::seed_from_u64(22);
    let (mut sq, mut lag) = (vec![], vec![]);
    for _ in 0..3000 {
        let v = Vibration::new(&spec, &mut rng);
        let t0 = rng.random::<f64>() * 100.0;
        let (a0, a1) = (v.at(t0)[2], v.at(t0 + tau)[2]);
        sq.push(a0.x * a0.x);
        lag.push(a0.x * a1.x);
    }
    let (var, se_v) = mean_and_standard_error(&sq);
    let (cov, se_c) = mean_and_standard_error(&lag);
    assert!(
        (var - var_model).abs() < 4.0 * se_v,
        "{var} vs {var_model} (SE {se_v})"
    );
    assert!(
        (cov - cov_model).abs() < 4.0 * se_c,
        "{cov} vs {cov_model} (SE {se_c})"
    );
    assert!(cov_model.abs() > 4.0 * se_c && var_model - cov_model > 4.0 * se_c);
}

/// The mount followed along the 1 ms grid for 2 500 steps (past its re-anchoring, with a jump
/// off the grid) is the closed form's to the rounding of its turns.
#[test]
fn followed_vibration_is_the_closed_form() {
    let scn = vehicle_in_motion_world(
        &["vibration"],
        r#"{ type = "hold", duration_s = 1.0 }"#,
        1.0,
    );
    let (_, spec) = spec_of(&scn);
    let v = Vibration::new(&spec, &mut ChaCha20Rng::seed_from_u64(23));
    let h = 1e-3;
    let mut f = v.follower(0.0, Some(h));
    // Displacement, velocity and acceleration scales of the mount: 10 µm, 1 mm/s, 1 m/s².
    let scale = [1e-5, 1e-3, 1.0];
    let mut worst = 0.0f64;
    for k in 1..=2_500 {
        let t = if k > 2_000 {
            7.0 + k as f64 * h
        } else {
            k as f64 * h
        };
        v.move_to(&mut f, t);
        let (a, b) = (v.at_followed(&f), v.at(t));
        for i in 0..3 {
            worst = worst.max((a[i] - b[i]).norm() / scale[i]);
        }
    }
    // The closed form's own phase `ωt + φ` is rounded to an ulp of ω_max·t_max (200 Hz, 9.5 s).
    let bound = 4.0 * TAU * spec.broadband_band_hz[1] * 9.5 * f64::EPSILON;
    assert!(worst < bound, "{worst} > {bound}");
}

/// The odometer reads the wheel: accelerating from 0 to 10 m/s on a straight level road adds
/// the slip `k_s·∫V V̇ dt = k_s·V²/2`; a 90° right turn at 10 m/s adds `−l_y·Δψ` (the rear-left
/// wheel runs on the outside); the body's slip angle at the IMU is `β = k_β·Vψ̇ + x_r·ψ̇/V`
/// (rear tyre slip, and the IMU ahead of the rear axle), so the velocity has a body-y
/// component `−V sin β`, and the rear axle's lateral velocity is the tyre slip's alone; the
/// body squats by `k_p·V̇` and rolls out by `k_r·Vψ̇`.
/// Terrain and ride are switched off to isolate the effects (their statistics are tested above).
#[test]
fn odometer_wheel_slip_lever_arm_sideslip_and_load_transfer() {
    let mut scn = vehicle_in_motion_world(
        &["vehicle"],
        r#"{ type = "speed", to_m_s = 10.0, duration_s = 8.0 },
           { type = "turn", angle_deg = 90.0, duration_s = 10.0 }"#,
        18.0,
    );
    let mut spec = scn.spec.world.unwrap();
    let v = spec.vehicle.as_mut().unwrap();
    v.grade_sigma_deg = 0.0;
    v.bank_sigma_deg = 0.0;
    v.ride_heave_sigma_m = 0.0;
    v.ride_pitch_sigma_deg = 0.0;
    v.ride_roll_sigma_deg = 0.0;
    let vs = *v;
    scn.spec.world = Some(spec);
    let mut truth = TruthGenerator::new(&scn);
    // Accelerating: at mid-ramp (4 s) V̇ is the peak 2·ΔV/T = 2.5 m/s².
    let acc = truth.advance_to(4_000_000_000);
    let p = *truth.current();
    let k_p = vs.pitch_per_accel_deg.to_radians();
    assert!((p.roll_pitch_heading_rad.y - k_p * 2.5).abs() < 1e-9);
    let mut odo = acc.odometer_distance_m;
    let mut dist = acc.distance_x_m;
    let inc = truth.advance_to(8_000_000_000);
    odo += inc.odometer_distance_m;
    dist += inc.distance_x_m;
    // The true (horizontal) distance of a raised-cosine ramp 0 → 10 m/s in 8 s is 40 m; the
    // body-x distance is shorter by the squat's cosine.
    let slip = vs.wheel_slip_per_accel_s2_m * 10.0 * 10.0 / 2.0;
    // Trapezoid on a 1 ms grid of a raised-cosine profile: error ≪ 1e-6 m.
    assert!(
        (odo - 40.0 - slip).abs() < 1e-6,
        "slip {} vs {slip}",
        odo - 40.0
    );
    assert!(dist < 40.0);
    // Mid-turn (13 s): ψ̇ = 2·(π/2)/10 s, lateral acceleration V·ψ̇.
    truth.advance_to(13_000_000_000);
    let p = *truth.current();
    let psi_rate = std::f64::consts::PI / 10.0;
    let a_lat = 10.0 * psi_rate;
    // Tyre slip at the rear axle plus the IMU's place ahead of it (x_r·ψ̇/V, regularised).
    let inv_v = 10.0 / (100.0 + crate::world::vehicle::KINEMATIC_SPEED_FLOOR_M_S.powi(2));
    let beta = vs.sideslip_per_lateral_accel_deg.to_radians() * a_lat
        + vs.odometer_lever_arm_b_m[0] * psi_rate * inv_v;
    let roll = -vs.roll_per_lateral_accel_deg.to_radians() * a_lat;
    // Horizontal velocity, body yawed by β and rolled by φ: v_y^b = −V sin β cos φ.
    let v_b = p.c_n_b.transpose() * p.v_ned_m_s;
    assert!(
        (v_b.y - (-10.0 * beta.sin() * roll.cos())).abs() < 1e-9,
        "{v_b}"
    );
    assert!((p.roll_pitch_heading_rad.x - roll).abs() < 1e-9);
    // At the rear axle (ω × l with the body's rate; mid-turn β̇ = 0 on the raised cosine's
    // crest) the lateral velocity is the tyre slip's −V·k_β·a_y, up to O(β³) ≈ 1e-5 m/s.
    let l = nalgebra::Vector3::from(vs.odometer_lever_arm_b_m);
    let w_nb_b = p.w_ib_b_rad_s; // the Earth's rate adds ~1e-4 m/s over 1.5 m
    let v_axle = v_b + w_nb_b.cross(&l);
    let slip = -10.0 * vs.sideslip_per_lateral_accel_deg.to_radians() * a_lat;
    assert!((v_axle.y - slip).abs() < 5e-4, "{v_axle} vs {slip}");
    assert!(
        (v_b.y - slip).abs() > 0.1,
        "the IMU itself slips by the geometry"
    );
    // Over the whole turn (8–18 s) the wheel adds −l_y·Δψ_b to the body-x distance; the
    // sideslip is zero at both ends, so Δψ_b = 90°.
    let mut truth = TruthGenerator::new(&scn);
    truth.advance_to(8_000_000_000);
    let b = truth.advance_to(18_000_000_000);
    let wheel_minus_body = b.odometer_distance_m - b.distance_x_m;
    let expect = -vs.odometer_lever_arm_b_m[1] * std::f64::consts::FRAC_PI_2;
    assert!(
        (wheel_minus_body - expect).abs() < 1e-6,
        "lever arm {wheel_minus_body} vs {expect}"
    );
}

/// A perfect strapdown INS (the foundations' RK4 mechanization, J2 gravity, as the truth's
/// own normal field) integrating the error-free IMU follows the truth on the road: hills,
/// bank, load transfer, ride, sideslip. 38 s of driving: speed-ups and two turns;
/// bounds as the plain vehicle scenario's strapdown test (1 cm, 0.1 mm/s, 0.5 µrad), the
/// ride adding ≤ 1.3 Hz motions, far below the 200 Hz rate.
#[test]
fn perfect_ins_follows_the_vehicle_on_the_road() {
    let scn = vehicle_in_motion_world(
        &["vehicle"],
        r#"{ type = "speed", to_m_s = 10.0, duration_s = 10.0 },
           { type = "turn", angle_deg = 90.0, duration_s = 10.0 },
           { type = "speed", to_m_s = 20.0, duration_s = 8.0 },
           { type = "turn", angle_deg = -60.0, duration_s = 10.0 }"#,
        38.0,
    );
    let (mut max_pitch, mut max_slip) = (0.0f64, 0.0f64);
    let (max_pos, max_vel, max_att) = crate::tests::perfect_ins_max_errors(&scn, |t| {
        max_pitch = max_pitch.max(t.roll_pitch_heading_rad.y.abs());
        max_slip = max_slip.max((t.c_n_b.transpose() * t.v_ned_m_s).y.abs());
    });
    eprintln!(
        "strapdown vs road truth over 38 s: pos {max_pos:.3e} m, vel {max_vel:.3e} m/s, \
         att {max_att:.3e} rad; |pitch| ≤ {max_pitch:.4} rad, |v_y| ≤ {max_slip:.3} m/s"
    );
    // The road really moves the body (else the test would prove nothing).
    assert!(max_pitch > 0.005 && max_slip > 0.05);
    assert!(max_pos < 0.01, "position error {max_pos} m");
    assert!(max_vel < 1e-4, "velocity error {max_vel} m/s");
    assert!(max_att < 5e-7, "attitude error {max_att} rad");
}

/// The IMU's specific force sees the gravity disturbance at its position: standing still,
/// `f_b(with) − f_b(without) = −C_b_n·δg`, δg of the field at the site.
#[test]
fn specific_force_sees_the_gravity_disturbance() {
    let hold = r#"{ type = "hold", duration_s = 1.0 }"#;
    let with = TruthGenerator::new(&vehicle_in_motion_world(&["gravity"], hold, 1.0));
    let without = TruthGenerator::new(&vehicle_in_motion_world(&[], hold, 1.0));
    let dg = with
        .world()
        .gravity
        .as_ref()
        .unwrap()
        .disturbance_ned_m_s2(0.0, 0.0, 0.0);
    let (a, b) = (with.current(), without.current());
    let d = a.f_b_m_s2 - b.f_b_m_s2 + a.c_n_b.transpose() * dg;
    assert!(d.norm() < 1e-12, "{d}");
    // Of the order the field is sized for (35 mGal): not zero, not metres per second squared.
    assert!((1e-6..1e-2).contains(&dg.norm()), "{dg}");
}

/// The actual unit reaches the IMU's output and the truth's biases: with the grade's noise,
/// scale factor, misalignment, bias walk and output counts off, a standing IMU's output minus the true
/// increment is `b·dt + G·Δv` with `b` the bias the truth process reports (turn-on,
/// temperature and the warm-up, which decays by e^{−1} in τ) and G the unit's g-sensitivity;
/// the accelerometers' is `b·dt` plus the size effect of the unit's offsets on the Earth's
/// rate (≈ 3·10⁻¹⁴ m/s per interval for 1 mm: the comparison is to 10⁻¹⁵).
#[test]
fn imu_unit_reaches_the_output_and_the_truth() {
    use crate::sources::TruthSource;
    let hold = r#"{ type = "hold", duration_s = 1.0 }"#;
    let mut scn = vehicle_in_motion_world(&["imu"], hold, 1.0);
    for s in [
        &mut scn.imu.gyro.arw_deg_per_rt_h,
        &mut scn.imu.gyro.scale_factor_ppm,
    ] {
        *s = 0.0;
    }
    scn.imu.gyro.misalignment_arcsec = 0.0;
    scn.imu.gyro.bias_rw_deg_h_per_rt_h = 0.0;
    scn.imu.accel.vrw_ug_per_rt_hz = 0.0;
    scn.imu.accel.scale_factor_ppm = 0.0;
    scn.imu.accel.misalignment_arcsec = 0.0;
    scn.imu.accel.bias_rw_ug_per_rt_h = 0.0;
    scn.imu.gyro.delta_angle_lsb_rad = 0.0;
    scn.imu.accel.delta_velocity_lsb_m_s = 0.0;
    let mut imu = ImuSource::new(&scn, 0);
    let mut clean = ImuSource::new(&scn, 0);
    clean.model.enabled = false;
    let mut truth = TruthSource::new(&scn, 0);
    let mut truth_gen = crate::truth::TruthGenerator::new(&scn);
    let unit = *imu.model.unit().expect("world imu");
    assert!(unit.accel_offsets_b_m.norm() > 0.0);
    let p = period_ns(scn.spec.imu.rate_hz);
    let dt = p as f64 * 1e-9;
    for k in 1..=200i64 {
        let (a, c) = (imu.sample(k * p), clean.sample(k * p));
        let t = truth.sample(k * p);
        let inc = truth_gen.advance_to(k * p);
        if k != 1 && k != 200 {
            continue;
        }
        let dv = Vector3::from(c.delta_velocity_m_s);
        let dg = Vector3::from(a.delta_angle_rad) - Vector3::from(c.delta_angle_rad);
        let expect = Vector3::from(t.gyro_bias_rad_s) * dt + unit.gyro_g_sensitivity * dv;
        assert!((dg - expect).norm() < 1e-15, "{dg} vs {expect}");
        let da = Vector3::from(a.delta_velocity_m_s) - dv;
        let size = unit.size_effect_dv_b_m_s(&inc.delta_rate_b_rad_s, &inc.rate_outer_b_rad2_s);
        assert!(size.norm() > 5e-15, "{size}");
        assert!((da - Vector3::from(t.accel_bias_m_s2) * dt - size).norm() < 1e-15);
        // The truth's bias is turn-on + temperature term + the warm-up, at the interval's
        // middle.
        let t_mid = (k as f64 - 0.5) * dt;
        let c = imu.model.gyro_constants();
        let d_temp = crate::imu::temperature_c(&scn.spec.imu.temperature, t_mid)
            - scn.imu.reference_temperature_c;
        let b = c.bias + c.temp_coeff_per_c * d_temp + unit.warmup(t_mid).0;
        assert!((Vector3::from(t.gyro_bias_rad_s) - b).norm() < 1e-20);
    }
}

/// The star tracker's time tag: with its thermal error and boresight bias at zero, the sample
/// stamped t is the world-free sample of t − L (the same noise draws), stamped t.
#[test]
fn star_tracker_latency_stamps_the_past_attitude() {
    use crate::sources::StarTrackerSource;
    let segs = r#"{ type = "speed", to_m_s = 10.0, duration_s = 2.0 },
                  { type = "turn", angle_deg = 20.0, duration_s = 2.0 }"#;
    let mut scn = vehicle_in_motion_world(&["star_tracker"], segs, 4.0);
    let mut w = scn.spec.world.unwrap();
    let st = w.star_tracker.as_mut().unwrap();
    st.thermal_sigma_arcsec = 0.0;
    st.boresight_bias_sigma_arcsec = 0.0;
    let latency_ns = (st.latency_s * 1e9).round() as i64;
    assert!(latency_ns > 0);
    scn.spec.world = Some(w);
    let plain = vehicle_in_motion_world(&[], segs, 4.0);
    let (mut a, mut b) = (
        StarTrackerSource::new(&scn, 0),
        StarTrackerSource::new(&plain, 0),
    );
    let p = period_ns(scn.spec.star_tracker.rate_hz);
    for k in 1..20 {
        let (x, y) = (a.sample(k * p), b.sample(k * p - latency_ns));
        assert_eq!(x.header.time_ns - y.header.time_ns, latency_ns);
        let d: f64 = (0..4)
            .map(|i| (x.q_sensor_icrf[i] - y.q_sensor_icrf[i]).abs())
            .sum();
        assert!(d < 1e-15, "{k}: {d}");
    }
}

/// The barometer reads the world's air: its pressure minus the world-free sample's (same
/// noise draws) is the day's pressure at the true height and time plus the sensor's
/// temperature error, minus ISA's.
#[test]
fn baro_reads_the_air_of_the_day() {
    use crate::sources::BaroSource;
    use crate::world::aiding::BaroWorld;
    let hold = r#"{ type = "hold", duration_s = 10.0 }"#;
    let scn = vehicle_in_motion_world(&["baro"], hold, 10.0);
    let plain = vehicle_in_motion_world(&[], hold, 10.0);
    let air = BaroWorld::new(
        &scn.spec.world.unwrap().baro.unwrap(),
        &mut crate::sensor_rng(scn.spec.scenario.seed, "world_baro"),
    );
    let (mut a, mut b) = (BaroSource::new(&scn, 0), BaroSource::new(&plain, 0));
    let h = scn.spec.site.height_m;
    let p = period_ns(scn.spec.baro.rate_hz);
    for k in [0i64, 1, 199] {
        let (x, y) = (a.sample(k * p), b.sample(k * p));
        let t = (k * p) as f64 * 1e-9;
        let bay_c = crate::imu::temperature_c(&scn.spec.imu.temperature, t);
        let expect =
            air.air(h, t).0 + air.sensor_error_pa(bay_c) - fusion::atmosphere::isa_pressure_pa(h);
        assert!(
            (x.pressure_pa - y.pressure_pa - expect).abs() < 1e-8,
            "{} vs {expect}",
            x.pressure_pa - y.pressure_pa
        );
    }
}

/// Bad motion-world values are refused with the file and the dotted key.
#[test]
fn motion_world_is_validated() {
    // The scenarios with their shared world files merged in, edited value by value.
    let car = Scenario::read_resolved_toml(&vehicle_path()).unwrap();
    let err = |doc: &toml::Table, path: &Path| match Scenario::from_toml_str(
        &toml::to_string(doc).unwrap(),
        path,
    ) {
        Ok(_) => String::from("accepted"),
        Err(e) => e.to_string(),
    };
    let set = |effect: &str, key: &str, value: toml::Value| {
        let mut doc = car.clone();
        let table = doc["world"][effect].as_table_mut().unwrap();
        assert!(
            table.insert(key.into(), value).is_some(),
            "the car has world.{effect}.{key}"
        );
        err(&doc, &vehicle_path())
    };
    assert_eq!(err(&car, &vehicle_path()), "accepted");
    let e = set("vehicle", "grade_sigma_deg", (-2.0).into());
    assert!(e.contains("world.vehicle.grade_sigma_deg"), "{e}");
    let e = set("star_tracker", "latency_s", 0.0105.into());
    assert!(e.contains("world.star_tracker.latency_s"), "{e}");
    let e = set(
        "vibration",
        "broadband_band_hz",
        toml::Value::Array(vec![20.0.into(), 600.0.into()]),
    );
    assert!(e.contains("world.vibration.broadband_band_hz"), "{e}");
    let e = set("imu", "warmup_tau_s", 0.0.into());
    assert!(e.contains("world.imu.warmup_tau_s"), "{e}");
    // The road needs a car: a static trajectory with [world.vehicle] on is refused.
    let stat_path = vehicle_path().with_file_name("static_site.toml");
    let mut stat = Scenario::read_resolved_toml(&stat_path).unwrap();
    let stat_world = stat["world"].as_table_mut().unwrap();
    assert!(
        !stat_world.contains_key("vehicle"),
        "the parked car has no road"
    );
    stat_world.insert("vehicle".into(), car["world"]["vehicle"].clone());
    let e = err(&stat, &stat_path);
    assert!(e.contains("world.vehicle"), "{e}");
}
