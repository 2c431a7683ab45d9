//! Cross-module tests of the simulator.

use crate::gnss::Constellation;
use crate::scenario::{Scenario, period_ns};
use crate::sources::{GnssSource, ImuSource, SampleSource, TruthSource};
use crate::truth::TruthGenerator;
use fusion::earth::{self, GravityModel, WGS84};
use fusion::strapdown::ImuIncrement;
use nalgebra::{Matrix3, Rotation3, Vector3};
use std::path::{Path, PathBuf};

fn scenario_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../config/scenarios/{name}.toml"))
}

/// A shipped scenario as it is, with its world.
fn load_shipped(name: &str) -> Scenario {
    match Scenario::load(&scenario_path(name)) {
        Ok(s) => s,
        Err(e) => panic!("{e}"),
    }
}

/// A shipped scenario on the matched world (the sensor models' own errors only).
fn load(name: &str) -> Scenario {
    crate::matched::scenario(load_shipped(name))
}

/// A shipped scenario's text without its `[world]` (the tables a test appends its own to).
fn text_without_world(name: &str) -> String {
    let text = std::fs::read_to_string(scenario_path(name)).unwrap();
    // `[world]` (its include) or the first `[world.<effect>]` table, whichever comes first.
    let end = text.find("\n[world").map_or(text.len(), |i| i + 1);
    text[..end].to_string()
}

/// Both shipped scenarios load and validate.
#[test]
fn shipped_scenarios_validate() {
    for name in ["static_site", "vehicle"] {
        let s = load_shipped(name);
        assert_eq!(s.spec.scenario.duration_s, 600.0);
    }
}

/// Static, levelled, error-free IMU: Δθ/dt = C_b_n ω_ie^n and Δv/dt = −C_b_n g^n.
#[test]
fn static_imu_measures_earth_rate_and_minus_gravity() {
    let scn = load("static_site");
    let mut src = ImuSource::new(&scn, 0);
    src.model.enabled = false;
    let s = &scn.spec.site;
    let (lat, lon) = (s.lat_deg.to_radians(), s.lon_deg.to_radians());
    let c_e_n = earth::c_e_n(lat, lon);
    let geo = earth::Geodetic {
        lat_rad: lat,
        lon_rad: lon,
        height_m: s.height_m,
    };
    let g_n = c_e_n.transpose()
        * earth::gravity_ecef(
            &WGS84,
            GravityModel::J2,
            &earth::geodetic_to_ecef(&WGS84, &geo),
        );
    let w_ie_n = c_e_n.transpose() * WGS84.omega_ie_e();
    let c_n_b = fusion::attitude::c_n_b_from_rpy(0.0, 0.0, 30f64.to_radians());
    let w_b = c_n_b.transpose() * w_ie_n;
    let f_b = -(c_n_b.transpose() * g_n);
    let p = period_ns(scn.spec.imu.rate_hz);
    for k in 1..=2000 {
        let m = src.sample(k * p);
        let dt = m.dt_s;
        assert!((dt - 0.005).abs() < 1e-15);
        let w = Vector3::from(m.delta_angle_rad) / dt;
        let f = Vector3::from(m.delta_velocity_m_s) / dt;
        assert!((w - w_b).norm() < 1e-15, "{w} vs {w_b}");
        assert!((f - f_b).norm() < 1e-11, "{f} vs {f_b}");
    }
    // Sanity of the physics: |ω| = Earth rate, |f| ≈ 9.815 m/s² at 55.7° N, 200 m; f points up.
    assert!((w_b.norm() - WGS84.omega_ie_rad_s).abs() < 1e-18);
    assert!((f_b.norm() - 9.8151).abs() < 2e-3, "{}", f_b.norm());
    assert!(f_b.z < -9.8);
}

/// Mechanizing the error-free IMU increments with `fusion::strapdown` reproduces the truth over
/// the whole 600 s vehicle scenario.
///
/// Error budget: the truth itself (RK4 on a 1 ms grid; trapezoid increments whose error
/// telescopes to ~h²/12·|Δȧ| ≈ 1e-7 m/s over the whole run) is exact far below a millimetre.
/// What remains is the mechanization at 200 Hz: ECEF specific force taken constant over each
/// 5 ms interval and rotation/sculling compensated to second order. With turn rates ≤ 0.2 rad/s
/// and accelerations ≤ 2.3 m/s², the third-order residual per interval is
/// ~(ωT)²·|a|T/12 ≈ 1e-9 m/s; over the ≈ 40 000 intervals of motion this accumulates to
/// ≤ 4e-5 m/s, i.e. ≤ 1 cm of position in the ≤ 470 s of driving (Schuler-bounded
/// horizontally, amplified ≤ cosh(600/570) ≈ 1.6 by the unstable vertical channel).
/// Bounds: 1 cm position, 0.1 mm/s velocity, 0.5 µrad attitude (measured: 0.9 mm, 3 µm/s,
/// 37 nrad with the foundations' RK4 mechanization).
#[test]
fn strapdown_reproduces_truth_over_vehicle_scenario() {
    assert_perfect_ins_follows_truth(&crate::matched::scenario(load("vehicle")), "600 s");
}

/// [`perfect_ins_max_errors`] within the bounds of
/// `strapdown_reproduces_truth_over_vehicle_scenario`; `what` names the run in the printout.
fn assert_perfect_ins_follows_truth(scn: &Scenario, what: &str) {
    let (max_pos, max_vel, max_att) = perfect_ins_max_errors(scn, |_| {});
    eprintln!(
        "strapdown vs truth, {what}: pos {max_pos:.3e} m, vel {max_vel:.3e} m/s, att {max_att:.3e} rad"
    );
    assert!(max_pos < 0.01, "position error {max_pos} m");
    assert!(max_vel < 1e-4, "velocity error {max_vel} m/s");
    assert!(max_att < 5e-7, "attitude error {max_att} rad");
}

/// A perfect strapdown INS (the foundations' RK4 mechanization with coning and sculling, J2
/// gravity) started on the truth and fed the scenario's error-free IMU increments: its
/// largest position (m), velocity (m/s) and attitude (rad) errors against the truth over the
/// whole run. `each` sees every truth point on an IMU epoch.
pub(crate) fn perfect_ins_max_errors(
    scn: &Scenario,
    mut each: impl FnMut(&crate::truth::TruthPoint),
) -> (f64, f64, f64) {
    let mut src = ImuSource::new(scn, 0);
    src.model.enabled = false;
    let mut truth = TruthGenerator::new(scn);
    let (mut state, mut sd) = truth.current().reference_ins();
    let p = period_ns(scn.spec.imu.rate_hz);
    let (mut max_pos, mut max_vel, mut max_att) = (0.0f64, 0.0f64, 0.0f64);
    let mut k = 1;
    while k * p <= scn.duration_ns() {
        let m = src.sample(k * p);
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
        max_pos = max_pos.max((state.r_e - t.r_e_m).norm());
        max_vel = max_vel.max((state.v_e - t.v_e_m_s()).norm());
        let c_err: Matrix3<f64> =
            state.q_e_b.to_rotation_matrix().into_inner() * (t.c_e_n * t.c_n_b).transpose();
        max_att = max_att.max(Rotation3::from_matrix_unchecked(c_err).angle());
        each(t);
        k += 1;
    }
    (max_pos, max_vel, max_att)
}

/// The truth grid is 1 ms where every sensor period is a whole number of milliseconds, else
/// the largest divisor of 1 ms that every period is a multiple of; a period that is not a
/// multiple of 0.1 ms is refused naming the key.
#[test]
fn truth_grid_follows_the_sensor_periods() {
    let text = std::fs::read_to_string(scenario_path("vehicle")).unwrap();
    let with_imu = |hz: &str| {
        Scenario::from_toml_str(
            &text.replacen("rate_hz = 200.0", &format!("rate_hz = {hz}"), 1),
            &scenario_path("vehicle"),
        )
    };
    for (hz, grid_ns) in [
        ("200.0", 1_000_000),
        ("100.0", 1_000_000),
        ("1000.0", 1_000_000),
        ("400.0", 500_000),
        ("2000.0", 500_000),
        ("2500.0", 200_000),
        ("10000.0", 100_000),
    ] {
        let scn = with_imu(hz).unwrap_or_else(|e| panic!("{hz} Hz: {e}"));
        assert_eq!(scn.truth_grid_ns(), grid_ns, "{hz} Hz");
        assert_eq!(TruthGenerator::new(&scn).grid_ns(), grid_ns, "{hz} Hz");
    }
    for hz in ["3000.0", "20000.0", "333.0"] {
        let e = with_imu(hz).map(|_| ()).unwrap_err().to_string();
        assert!(
            e.contains("imu.rate_hz") && e.contains("0.1 ms"),
            "{hz} Hz: {e}"
        );
    }
}

/// On the 0.5 ms grid of a 2 kHz IMU the truth is the same trajectory as on the 1 ms grid:
/// RK4's truncation on the smooth profile is far below the round-off of the latitude and
/// longitude sums, at most half an ulp of the angle per step on each grid (the bound below;
/// measured 1.7 µm in 300 s against a bound of 1.2 mm), and the error-free 2 kHz increments
/// carry a perfect strapdown INS along it as closely as at 200 Hz (bounds of
/// `strapdown_reproduces_truth_over_vehicle_scenario`).
#[test]
fn truth_on_a_half_millisecond_grid_is_the_same_trajectory() {
    let mut coarse = load("vehicle");
    coarse.spec.scenario.duration_s = 300.0;
    let mut fine = coarse.clone();
    fine.spec.imu.rate_hz = 2000.0;
    assert_eq!(fine.truth_grid_ns(), 500_000);
    let (mut a, mut b) = (TruthGenerator::new(&coarse), TruthGenerator::new(&fine));
    let mut max_diff = 0.0f64;
    for k in 1..=300 {
        let t_ns = k * 1_000_000_000;
        let (ia, ib) = (a.advance_to(t_ns), b.advance_to(t_ns));
        assert_eq!(a.current().t_ns, t_ns);
        assert_eq!(b.current().t_ns, t_ns);
        max_diff = max_diff.max((a.current().r_e_m - b.current().r_e_m).norm());
        // The increments over the same second: trapezoid sums on two grids of a smooth
        // body rate and specific force, equal to O(h²·|ẍ|·T) ≈ 1e-7 of them.
        let dv = (ia.delta_velocity_b_m_s - ib.delta_velocity_b_m_s).norm();
        let dth = (ia.delta_angle_b_rad - ib.delta_angle_b_rad).norm();
        assert!(
            dv < 1e-6 && dth < 1e-8,
            "t = {k} s: dv {dv:e} m/s, dθ {dth:e} rad"
        );
    }
    // Half an ulp of the latitude (the larger angle here) per step of either grid, on both
    // angles, at the Earth's radius plus the height.
    let g = &a.current().geodetic;
    let half_ulp_rad = f64::EPSILON * g.lat_rad.abs().max(g.lon_rad.abs()) / 2.0;
    let steps = (300_000 + 600_000) as f64;
    let bound_m = 2.0 * steps * half_ulp_rad * (WGS84.a_m + g.height_m);
    eprintln!(
        "truth 1 ms vs 0.5 ms grid over 300 s: max position difference {max_diff:.3e} m \
         (round-off bound {bound_m:.1e} m)"
    );
    assert!(max_diff < bound_m, "{max_diff} m");
    assert_perfect_ins_follows_truth(&fine, "2 kHz over 300 s");
}

/// The same scenario and seed give bit-identical samples twice; another seed differs.
#[test]
fn same_seed_is_bit_identical() {
    let scn = load("vehicle");
    let epoch = scn.epoch_gps().ns;
    let run = |scn: &Scenario| {
        let mut imu = ImuSource::new(scn, epoch);
        let mut gnss = GnssSource::new(scn, epoch);
        let mut truth = TruthSource::new(scn, epoch);
        let p = period_ns(scn.spec.imu.rate_hz);
        let imus: Vec<_> = (1..=2000).map(|k| imu.sample(k * p)).collect();
        let gs: Vec<_> = (0..5).map(|k| gnss.sample(k * 1_000_000_000)).collect();
        let ts: Vec<_> = (0..50).map(|k| truth.sample(k * 20_000_000)).collect();
        (imus, gs, ts)
    };
    let a = run(&scn);
    let b = run(&scn);
    assert!(a.0 == b.0 && a.1 == b.1 && a.2 == b.2);
    let mut other = scn.clone();
    other.spec.scenario.seed += 1;
    let c = run(&other);
    assert!(a.0 != c.0 && a.1 != c.1);
}

/// The truth process's IMU biases are the ones the IMU process applies: with the white noise,
/// scale factor, misalignment and output counts switched off, IMU output minus the error-free
/// increment is
/// exactly bias·dt, and the truth driver reports that bias.
#[test]
fn truth_biases_match_imu_stream() {
    let mut scn = load("static_site");
    scn.imu.gyro.arw_deg_per_rt_h = 0.0;
    scn.imu.gyro.scale_factor_ppm = 0.0;
    scn.imu.gyro.misalignment_arcsec = 0.0;
    scn.imu.accel.vrw_ug_per_rt_hz = 0.0;
    scn.imu.accel.scale_factor_ppm = 0.0;
    scn.imu.accel.misalignment_arcsec = 0.0;
    scn.imu.gyro.delta_angle_lsb_rad = 0.0;
    scn.imu.accel.delta_velocity_lsb_m_s = 0.0;
    let mut imu = ImuSource::new(&scn, 0);
    let mut clean = ImuSource::new(&scn, 0);
    clean.model.enabled = false;
    let mut truth = TruthSource::new(&scn, 0);
    let p = period_ns(scn.spec.imu.rate_hz);
    let tp = period_ns(scn.spec.truth.rate_hz);
    for k in 1..=4000 {
        let a = imu.sample(k * p);
        let b = clean.sample(k * p);
        let gb = (Vector3::from(a.delta_angle_rad) - Vector3::from(b.delta_angle_rad)) / a.dt_s;
        let ab =
            (Vector3::from(a.delta_velocity_m_s) - Vector3::from(b.delta_velocity_m_s)) / a.dt_s;
        if (k * p) % tp == 0 {
            let t = truth.sample(k * p);
            assert!(
                (gb - Vector3::from(t.gyro_bias_rad_s)).norm() < 1e-15,
                "{gb}"
            );
            assert!(
                (ab - Vector3::from(t.accel_bias_m_s2)).norm() < 1e-11,
                "{ab}"
            );
            assert!(gb.norm() > 1e-9 && ab.norm() > 1e-5);
        }
    }
}

/// Pseudorange − geometric range − clock bias is white noise with the configured σ
/// (sample variance inside its 99.9 % chi-square interval), and the satellite position is
/// transmission-time (Sagnac) consistent.
#[test]
fn pseudorange_residuals_have_configured_sigma() {
    let scn = load("static_site");
    let epoch = scn.epoch_gps().ns;
    let mut src = GnssSource::new(&scn, epoch);
    let c = Constellation::new(scn.spec.gnss.constellation);
    let sigma = scn.gnss.pseudorange_sigma_m;
    let sigma_rr = scn.gnss.range_rate_sigma_m_s;
    let (mut res, mut res_rr) = (Vec::new(), Vec::new());
    let mut nees_sum = 0.0;
    let mut n_fix = 0.0;
    for k in 0..600 {
        let t_ns = k * 1_000_000_000;
        let (m, hidden) = src.sample_with_truth(t_ns);
        assert!(m.fix_valid == 1 && m.n_satellites >= 4);
        let r_rx = {
            let s = &scn.spec.site;
            earth::geodetic_to_ecef(
                &WGS84,
                &earth::Geodetic {
                    lat_rad: s.lat_deg.to_radians(),
                    lon_rad: s.lon_deg.to_radians(),
                    height_m: s.height_m,
                },
            )
        };
        for sat in &m.satellites[..m.n_satellites as usize] {
            let i = sat.prn as usize - 1;
            let r_s = Vector3::from(sat.sat_pos_ecef_m);
            let range = (r_s - r_rx).norm();
            // Sagnac/light-time consistency, independent of the model's iteration.
            let tau = range / msgs::SPEED_OF_LIGHT_M_S;
            let (r_tx, _) = c.sat_ecef(i, (epoch + t_ns) as f64 * 1e-9 - tau);
            let th = WGS84.omega_ie_rad_s * tau;
            let rot = Vector3::new(
                th.cos() * r_tx.x + th.sin() * r_tx.y,
                -th.sin() * r_tx.x + th.cos() * r_tx.y,
                r_tx.z,
            );
            assert!((rot - r_s).norm() < 1e-3, "{}", (rot - r_s).norm());
            res.push(sat.pseudorange_m - range - hidden.clock_bias_m);
            let u = (r_s - r_rx) / range;
            let rate = Vector3::from(sat.sat_vel_ecef_m_s).dot(&u);
            res_rr.push(sat.range_rate_m_s - rate - hidden.clock_drift_m_s);
        }
        // Fix error against its covariance.
        let d = Vector3::from(m.pos_ecef_m) - r_rx;
        let cov = Matrix3::from_row_slice(&m.pos_cov_ecef_m2);
        if let Some(inv) = cov.try_inverse() {
            nees_sum += (d.transpose() * inv * d)[(0, 0)];
            n_fix += 1.0;
        }
    }
    for (r, s) in [(&res, sigma), (&res_rr, sigma_rr)] {
        let n = r.len() as f64;
        let mean = r.iter().sum::<f64>() / n;
        let var = r.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
        // (n−1)s²/σ² ~ χ²(n−1); for n ≈ 5000 the 99.9 % interval is ≈ (n−1) ± 3.29·√(2(n−1)).
        let chi = (n - 1.0) * var / (s * s);
        let half = 3.29 * (2.0 * (n - 1.0)).sqrt();
        assert!((chi - (n - 1.0)).abs() < half, "chi² {chi} for n {n}");
        assert!(mean.abs() < 4.0 * s / n.sqrt(), "mean {mean}");
    }
    // Mean NEES of a 3-D fix ≈ 3 (600 samples: σ of the mean ≈ 0.1).
    let nees = nees_sum / n_fix;
    assert!((nees - 3.0).abs() < 0.5, "fix NEES {nees}");
}

/// With the 24-satellite Walker constellation at least four satellites are above 10° at the
/// site at every minute of a sidereal day.
#[test]
fn at_least_four_satellites_visible_all_day() {
    let scn = load("static_site");
    let c = Constellation::new(scn.spec.gnss.constellation);
    let s = &scn.spec.site;
    let (lat, lon) = (s.lat_deg.to_radians(), s.lon_deg.to_radians());
    let r_rx = earth::geodetic_to_ecef(
        &WGS84,
        &earth::Geodetic {
            lat_rad: lat,
            lon_rad: lon,
            height_m: s.height_m,
        },
    );
    let c_e_n = earth::c_e_n(lat, lon);
    let t0 = scn.epoch_gps().ns as f64 * 1e-9;
    let mut min_vis = usize::MAX;
    for m in 0..(24 * 60) {
        let t = t0 + 60.0 * m as f64;
        let vis = (0..c.len())
            .filter(|&i| {
                let (r, _, range) = c.at_reception(i, t, &r_rx);
                crate::gnss::elevation_rad(&c_e_n, &((r - r_rx) / range)) >= 10f64.to_radians()
            })
            .count();
        min_vis = min_vis.min(vis);
    }
    assert!(min_vis >= 4, "only {min_vis} satellites visible");
}

/// A sky with more satellites above the mask than a sample has channels (a Walker pattern of
/// 128, four constellations' worth): each sample carries 32, the highest in view — none left
/// out is higher than one carried — by the matched and by the world's receiver alike.
#[test]
fn a_crowded_sky_fills_the_channels_with_the_highest_satellites() {
    for (name, scn) in [
        ("matched static site", load("static_site")),
        ("vehicle in its world", load_shipped("vehicle")),
    ] {
        let mut scn = scn;
        scn.spec.gnss.constellation.planes = 16;
        scn.spec.gnss.constellation.per_plane = 8;
        let c = Constellation::new(scn.spec.gnss.constellation);
        let epoch = scn.epoch_gps().ns;
        let mut src = GnssSource::new(&scn, epoch);
        let mask = 10f64.to_radians();
        // Ten epochs outside the vehicle scenario's GNSS outage (300–360 s).
        for k in [0, 50, 100, 150, 200, 250, 400, 450, 500, 550] {
            let t_ns = k * 1_000_000_000;
            let (sample, hidden) = src.sample_with_truth(t_ns);
            let r_rx = hidden.antenna_r_e_m;
            let (_, c_e_n) = earth::ecef_to_geodetic_and_c_e_n(&WGS84, &r_rx);
            let t_rx = (epoch + t_ns) as f64 * 1e-9;
            let el = |i: usize| {
                let (r, _, range) = c.at_reception(i, t_rx, &r_rx);
                crate::gnss::elevation_rad(&c_e_n, &((r - r_rx) / range))
            };
            let n = sample.n_satellites as usize;
            let carried: Vec<usize> = sample.satellites[..n]
                .iter()
                .map(|s| s.prn as usize - 1)
                .collect();
            let in_view = (0..c.len()).filter(|&i| el(i) >= mask).count();
            assert!(in_view > msgs::MAX_SATELLITES, "{name}: {in_view} in view");
            assert_eq!(n, msgs::MAX_SATELLITES, "{name} at {k} s");
            let lowest_carried = carried.iter().map(|&i| el(i)).fold(f64::MAX, f64::min);
            let highest_left = (0..c.len())
                .filter(|i| !carried.contains(i))
                .map(el)
                .fold(f64::MIN, f64::max);
            assert!(lowest_carried >= mask, "{name}");
            assert!(
                highest_left <= lowest_carried,
                "{name} at {k} s: {highest_left} rad left out, {lowest_carried} rad carried"
            );
        }
    }
}

/// Star tracker at the level static site: optical axis (sensor z) points to the local up, and
/// the measured attitude differs from the truth by ≈ the configured noise.
#[test]
fn star_tracker_boresight_points_up() {
    let scn = load("static_site");
    let epoch = scn.epoch_gps().ns;
    let mut sim = crate::sensors::StarTrackerSim::new(&scn);
    let gen_ = TruthGenerator::new(&scn);
    let p = gen_.current();
    let c_s_i = sim.c_s_i_true(epoch, p);
    let c_e_i = fusion::celestial::c_e_i(
        fusion::time::GpsTime { ns: epoch },
        &scn.spec.earth_orientation,
    );
    let z_e = c_e_i * c_s_i.transpose() * Vector3::z();
    let up = p.c_e_n * Vector3::new(0.0, 0.0, -1.0);
    assert!((z_e - up).norm() < 1e-12);
    let mut sum2 = 0.0;
    for k in 0..200 {
        let m = sim.sample(k as f64 * 0.2, epoch, p);
        assert_eq!(m.valid, 1);
        let q = fusion::attitude::quat_from_wire(&m.q_sensor_icrf);
        let err = q.to_rotation_matrix().into_inner() * c_s_i.transpose();
        let e = Rotation3::from_matrix_unchecked(err).scaled_axis();
        sum2 += e.x * e.x + e.y * e.y;
    }
    let rms_cross_arcsec = (sum2 / 400.0).sqrt().to_degrees() * 3600.0;
    assert!((rms_cross_arcsec - 5.0).abs() < 1.0, "{rms_cross_arcsec}");
}

/// GNSS outage windows empty the receiver output.
#[test]
fn gnss_outage_window_is_honoured() {
    let scn = crate::matched::scenario(load("vehicle"));
    let mut src = GnssSource::new(&scn, scn.epoch_gps().ns);
    for k in [299i64, 300, 330, 359, 360] {
        let m = src.sample(k * 1_000_000_000);
        let out = (300..360).contains(&k);
        assert_eq!(m.n_satellites == 0, out, "t = {k}");
        assert_eq!(m.fix_valid == 0, out, "t = {k}");
    }
}

mod parse_errors {
    use super::*;
    use proptest::prelude::*;

    fn base_text() -> String {
        std::fs::read_to_string(scenario_path("static_site")).unwrap_or_default()
    }

    fn err_of(text: &str) -> String {
        match Scenario::from_toml_str(text, &scenario_path("static_site")) {
            Ok(_) => String::from("<accepted>"),
            Err(e) => e.to_string(),
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]

        /// An unknown key anywhere is rejected by name.
        #[test]
        fn unknown_key_is_named(key in "[a-z]{3,10}_typo", section in 0usize..4) {
            let sec = ["[scenario]", "[site]", "[imu]", "[gnss]"][section];
            let text = base_text().replacen(sec, &format!("{sec}\n{key} = 1"), 1);
            let e = err_of(&text);
            prop_assert!(e.contains(&key), "{e}");
            prop_assert!(e.contains("static_site.toml"), "{e}");
        }

        /// A wrong type is rejected and the message shows the key.
        #[test]
        fn wrong_type_is_named(which in 0usize..4, junk in "[a-z]{1,8}") {
            let (k, v) = [("duration_s", "600.0"), ("lat_deg", "55.655"), ("seed", "1"), ("height_m", "200.0")][which];
            let text = base_text().replacen(&format!("{k} = {v}"), &format!("{k} = \"{junk}\""), 1);
            let e = err_of(&text);
            prop_assert!(e.contains(k), "{e}");
        }

        /// Out-of-range values fail validation naming file and dotted key.
        #[test]
        fn bad_value_is_named(which in 0usize..5, bad in -1.0e6f64..-1.0) {
            let (k, v, key) = [
                ("duration_s", "600.0", "scenario.duration_s"),
                ("lat_deg", "55.655", "site.lat_deg"),
                ("rate_hz = 200.0", "", "imu.rate_hz"),
                ("rate_hz = 5.0", "", "star_tracker.rate_hz"),
                ("rate_hz = 1.0", "", "gnss.rate_hz"),
            ][which];
            let text = if v.is_empty() {
                base_text().replacen(k, &format!("rate_hz = {bad}"), 1)
            } else {
                base_text().replacen(&format!("{k} = {v}"), &format!("{k} = {bad}"), 1)
            };
            let e = err_of(&text);
            prop_assert!(e.contains(&format!("`{key}`")), "{e}");
            prop_assert!(e.contains("static_site.toml"), "{e}");
        }
    }

    #[test]
    fn missing_key_and_bad_segment_are_named() {
        let e = err_of(&base_text().replacen("seed = 1\n", "", 1));
        assert!(e.contains("seed"), "{e}");
        let e = err_of(&base_text().replacen("rate_hz = 200.0", "rate_hz = 300.0", 1));
        assert!(e.contains("imu.rate_hz") && e.contains("1 ms"), "{e}");
        let e = err_of(&base_text().replacen(
            "start_utc = \"2025-03-20T21:00:00\"",
            "start_utc = \"2025-13-20T21:00:00\"",
            1,
        ));
        assert!(e.contains("scenario.start_utc"), "{e}");
        let e = err_of(&base_text().replacen("grade = \"navigation\"", "grade = \"nosuch\"", 1));
        assert!(e.contains("nosuch"), "{e}");
        let e = err_of(&base_text().replacen(
            "[imu]\ngrade = \"navigation\"",
            "[imu]\ngrade = \"navigation\"\noverrides = { gyro = { bias_deg_hour = 1.0 } }",
            1,
        ));
        assert!(
            e.contains("bias_deg_hour") && e.contains("navigation.toml"),
            "{e}"
        );
        let vehicle = std::fs::read_to_string(scenario_path("vehicle")).unwrap_or_default();
        let e = match Scenario::from_toml_str(
            &vehicle.replacen(
                "{ type = \"turn\", angle_deg = 90.0",
                "{ type = \"turn\", angel_deg = 90.0",
                1,
            ),
            &scenario_path("vehicle"),
        ) {
            Ok(_) => String::from("<accepted>"),
            Err(e) => e.to_string(),
        };
        assert!(e.contains("angel_deg"), "{e}");
    }
}

/// Odometer distance over the vehicle run = (1 + scale-factor error) × true path length, up to
/// the white noise (σ_speed·dt·√n ≈ 0.02·0.05·√12000 ≈ 0.11 m).
#[test]
fn odometer_distance_carries_scale_factor() {
    use crate::sources::OdometerSource;
    let scn = crate::matched::scenario(load("vehicle"));
    let mut odo = OdometerSource::new(&scn, 0);
    let mut gen_ = TruthGenerator::new(&scn);
    let p = period_ns(scn.spec.odometer.rate_hz);
    let (mut meas, mut truth) = (0.0, 0.0);
    let mut k = 1;
    while k * p <= scn.duration_ns() {
        meas += odo.sample(k * p).distance_m;
        truth += gen_.advance_to(k * p).distance_x_m;
        k += 1;
    }
    let sf = scn.odometer.scale_factor_error_ppm * 1e-6;
    assert!(truth > 5000.0, "path {truth} m");
    assert!((meas - (1.0 + sf) * truth).abs() < 0.5, "{meas} vs {truth}");
}

/// Baro: pressure minus ISA at the true height averages to the configured bias.
#[test]
fn baro_bias_and_noise() {
    use crate::sources::BaroSource;
    let scn = load("static_site");
    let mut baro = BaroSource::new(&scn, 0);
    let p = period_ns(scn.spec.baro.rate_hz);
    let n = 4000;
    let res: Vec<f64> = (0..n)
        .map(|k| baro.sample(k * p).pressure_pa - fusion::atmosphere::isa_pressure_pa(200.0))
        .collect();
    let mean = res.iter().sum::<f64>() / n as f64;
    let sd = (res.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n as f64 - 1.0)).sqrt();
    assert!((mean - 30.0).abs() < 0.5, "{mean}");
    assert!((sd - 5.0).abs() < 0.3, "{sd}");
}

/// MEMS grade: the 12-bit ADC makes every output rate a whole number of LSBs.
#[test]
fn mems_outputs_are_quantised() {
    let mut scn = load("static_site");
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/sensors");
    let text = std::fs::read_to_string(scenario_path("static_site"))
        .unwrap_or_default()
        .replacen("grade = \"navigation\"", "grade = \"mems\"", 1);
    let spec = Scenario::parse(&text, &scenario_path("static_site")).expect("parse");
    scn = Scenario::validate(spec, &scn.file, &dir).expect("validate");
    let lsb_w = 2.0 * 150f64.to_radians() / 4096.0;
    let lsb_f = 2.0 * 4.0 * crate::imu::G0_M_S2 / 4096.0;
    let mut src = ImuSource::new(&scn, 0);
    for k in 1..=200 {
        let m = src.sample(k * 5_000_000);
        for i in 0..3 {
            let qw = m.delta_angle_rad[i] / m.dt_s / lsb_w;
            let qf = m.delta_velocity_m_s[i] / m.dt_s / lsb_f;
            assert!((qw - qw.round()).abs() < 1e-6 && (qf - qf.round()).abs() < 1e-6);
        }
    }
}

/// Navigation grade: every increment is a whole number of output counts (2^-33 rad,
/// 2^-29 m/s), and the counts carry their remainder, so the summed output stays within half
/// a count of what the same sensor would give undigitised.
#[test]
fn navigation_grade_outputs_whole_counts_that_carry_the_remainder() {
    let counted = load_shipped("vehicle");
    let (lsb_w, lsb_f) = (
        counted.imu.gyro.delta_angle_lsb_rad,
        counted.imu.accel.delta_velocity_lsb_m_s,
    );
    assert_eq!((lsb_w, lsb_f), (2f64.powi(-33), 2f64.powi(-29)));
    let mut analog = counted.clone();
    analog.imu.gyro.delta_angle_lsb_rad = 0.0;
    analog.imu.accel.delta_velocity_lsb_m_s = 0.0;
    let (mut a, mut b) = (ImuSource::new(&counted, 0), ImuSource::new(&analog, 0));
    let p = period_ns(counted.spec.imu.rate_hz);
    // Σ(output − undigitised) per axis: minus the remainder the counts still owe.
    let mut owed = [0.0f64; 6];
    let mut differ = 0;
    for k in 1..=20_000 {
        let (m, u) = (a.sample(k * p), b.sample(k * p));
        for (i, owed) in owed.iter_mut().enumerate() {
            let (v, w, lsb) = if i < 3 {
                (m.delta_angle_rad[i], u.delta_angle_rad[i], lsb_w)
            } else {
                (
                    m.delta_velocity_m_s[i - 3],
                    u.delta_velocity_m_s[i - 3],
                    lsb_f,
                )
            };
            assert_eq!(
                (v / lsb).fract(),
                0.0,
                "sample {k} axis {i}: {v} is not whole counts"
            );
            differ += usize::from(v != w);
            *owed += v - w;
            // Half a count, and the rounding of ≤ 20 000 differences of terms ≤ 0.1 rad or
            // m/s (each exact to ≈ 1e-17).
            assert!(
                owed.abs() <= 0.5 * lsb + 1e-12,
                "sample {k} axis {i}: the summed output is {} off the undigitised (count {lsb})",
                *owed
            );
        }
    }
    assert!(
        differ > 6 * 20_000 * 9 / 10,
        "digitising changed only {differ} values"
    );
}

/// The static site with the GNSS part of the vehicle scenario's `[world]` (every effect on the
/// pseudoranges, the oscillator and the antenna; a road needs a car).
fn static_site_in_the_world() -> Scenario {
    let mut scn = load("static_site");
    let car = load_shipped("vehicle").spec.world.expect("the car's world");
    scn.spec.world = Some(car.only(&crate::world::GNSS_EFFECTS).unwrap());
    scn
}

/// The real receiver: its fix is the weighted least-squares solution of exactly the
/// pseudoranges (and satellite positions) it publishes, after its own fault exclusion (the
/// echoes of `[world.nlos]`), at the antenna (lever arm from the IMU), and its error is
/// correlated over minutes, unlike the matched receiver's.
#[test]
fn real_receiver_fix_is_its_own_least_squares_and_correlated() {
    let scn = static_site_in_the_world();
    let epoch = scn.epoch_gps().ns;
    let mut src = GnssSource::new(&scn, epoch);
    let mut truth = TruthGenerator::new(&scn);
    let lever = Vector3::from(scn.spec.world.unwrap().gnss_antenna.unwrap().lever_arm_b_m);
    let n = 1200;
    let mut north = Vec::with_capacity(n);
    for k in 0..n as i64 {
        let t_ns = k * 1_000_000_000;
        let (m, hidden) = src.sample_with_truth(t_ns);
        assert_eq!(m.fix_valid, 1, "epoch {k}");
        truth.advance_to(t_ns);
        let tp = truth.current();
        // Static: the antenna is the IMU plus C_e_b l (rate term ≈ Ω|l| = 1e-4 m/s only).
        let antenna = tp.r_e_m + tp.c_e_n * tp.c_n_b * lever;
        assert!((hidden.antenna_r_e_m - antenna).norm() < 1e-9);
        let obs = fusion::gnss_ls::Observations::from_sample(&m).unwrap();
        let own = fusion::gnss_ls::solve_excluding_faults(
            &obs,
            &fusion::gnss_ls::LsSettings::default(),
            crate::gnss::RECEIVER_FDE_PROBABILITY,
            5,
        )
        .unwrap()
        .fix;
        // Both iterate to a 1e-4 m step tolerance.
        let d = own.position.r_e_m - Vector3::from(m.pos_ecef_m);
        assert!(d.norm() < 1e-3, "fix differs from its own LS by {d}");
        let cov = Matrix3::from_row_slice(&m.pos_cov_ecef_m2);
        assert!((own.position.cov_r_e_m2 - cov).norm() < 1e-9 * cov.norm());
        north.push((tp.c_e_n.transpose() * (Vector3::from(m.pos_ecef_m) - antenna)).x);
    }
    // Lag-60 s autocorrelation of the north error. For a white series its estimate has a
    // standard error of 1/√N = 0.029 (N = 1200); the world's slow terms (τ of 45 s to 2 h)
    // must put it far above 4 standard errors.
    let mean = north.iter().sum::<f64>() / n as f64;
    let c = |lag: usize| {
        (0..n - lag)
            .map(|i| (north[i] - mean) * (north[i + lag] - mean))
            .sum::<f64>()
            / n as f64
    };
    let rho = c(60) / c(0);
    assert!(
        rho > 4.0 / (n as f64).sqrt(),
        "lag-60 s autocorrelation {rho}"
    );
}

/// `[world.carrier_phase]` and `[world.phase_multipath]` through the receiver: each published
/// baseline phase is the true `b·u/λ` plus the hidden integer plus the hidden multipath plus
/// white noise (residual within 5σ_φ); the multipath has the world's σ(el) (its normalised
/// variance, sampled every 60 s = 2τ so the samples are nearly independent, within 4 standard
/// errors of 1), the integers are
/// arbitrary (not 0), and the lock time runs with the epochs except where the integer changed
/// (a flagged slip) or the satellite was (re)acquired; some integers change without a restart
/// (the unflagged slips), and the source's slip counts agree with what is seen. Static site
/// with the car's GNSS world, 1200 s at 1 Hz.
#[test]
fn published_baseline_phases_carry_the_tracked_integer_and_lock_time() {
    let scn = static_site_in_the_world();
    assert!(scn.spec.world.unwrap().carrier_phase().is_some());
    let epoch = scn.epoch_gps().ns;
    let mut src = GnssSource::new(&scn, epoch);
    let mut truth = TruthGenerator::new(&scn);
    let g = scn.gnss;
    let lambda = msgs::SPEED_OF_LIGHT_M_S / g.carrier_frequency_hz;
    let mp = scn
        .spec
        .world
        .unwrap()
        .phase_multipath()
        .expect("phase multipath");
    let mut mp_z2 = Vec::new();
    let mut prev: std::collections::HashMap<u32, ([i64; 2], [f64; 2])> = Default::default();
    let (mut nonzero, mut total, mut flagged, mut unflagged) = (0, 0, 0u64, 0u64);
    for k in 0..1200i64 {
        let (m, hidden) = src.sample_with_truth(k * 1_000_000_000);
        truth.advance_to(k * 1_000_000_000);
        let tp = truth.current();
        let c_e_b = tp.c_e_n * tp.c_n_b;
        let b = [
            c_e_b * Vector3::new(g.baseline_length_m[0], 0.0, 0.0),
            c_e_b * Vector3::new(0.0, g.baseline_length_m[1], 0.0),
        ];
        let mut now = std::collections::HashMap::new();
        for (i, s) in m.satellites[..m.n_satellites as usize].iter().enumerate() {
            let u = (Vector3::from(s.sat_pos_ecef_m) - hidden.antenna_r_e_m).normalize();
            let n_int = hidden.phase_ambiguity_cycles[i];
            for j in 0..2 {
                // The broadcast orbit error moves u by < 1e-7 rad: ≪ σ_φ on 1 m.
                let m_cyc = hidden.phase_multipath_cycles[i][j];
                let r =
                    s.baseline_phase_cycles[j] - b[j].dot(&u) / lambda - n_int[j] as f64 - m_cyc;
                assert!(r.abs() < 5.0 * g.phase_sigma_cycles, "residual {r} cycles");
                if k % 60 == 0 {
                    let el = (-(tp.c_e_n.transpose() * u).z).asin();
                    mp_z2.push((m_cyc * lambda / mp.sigma_m(el)).powi(2));
                }
                total += 1;
                nonzero += usize::from(n_int[j] != 0);
            }
            if let Some((n0, l0)) = prev.get(&s.prn) {
                for j in 0..2 {
                    // The first interval is 0.95 s (the 50 ms latency at t = 0), the
                    // others 1 s: a restart leaves less than one interval.
                    let restarted = s.phase_lock_time_s[j] < l0[j] + 0.9;
                    if n0[j] != n_int[j] {
                        if restarted {
                            flagged += 1;
                        } else {
                            unflagged += 1;
                        }
                    } else {
                        assert!(!restarted, "lock restarted without a slip");
                        let d = s.phase_lock_time_s[j] - l0[j];
                        assert!((0.95 - 1e-9..=1.0 + 1e-9).contains(&d), "lock time +{d} s");
                    }
                }
            } else {
                assert!(s.phase_lock_time_s.iter().all(|l| (0.0..1.0).contains(l)));
            }
            now.insert(s.prn, (n_int, s.phase_lock_time_s));
        }
        prev = now;
    }
    let (v, se) = crate::world::gauss_markov::mean_and_standard_error(&mp_z2);
    assert!(
        mp_z2.len() > 200 && (v - 1.0).abs() < 4.0 * se,
        "multipath z² {v} ± {se}"
    );
    let c = src.sim.phase_slip_counts();
    eprintln!("{total} phases, {nonzero} with a non-zero integer; slips {c:?}");
    assert!(nonzero as f64 > 0.99 * total as f64);
    assert_eq!((c.flagged, c.unflagged), (flagged, unflagged));
    assert!(c.flagged > 0, "{c:?}");
}

/// A `[world]` with pseudorange errors needs the receiver's own error budget in its grade,
/// and every world value is range-checked with its dotted key.
#[test]
fn world_section_is_validated() {
    let path = scenario_path("static_site");
    let base = text_without_world("static_site");
    let err = |extra: &str| match Scenario::from_toml_str(&format!("{base}\n{extra}"), &path) {
        Ok(_) => String::from("accepted"),
        Err(e) => e.to_string(),
    };
    let e = err(
        "[world.multipath]\nsigma_zenith_m = 0.2\nsigma_horizon_m = -1.0\n\
                 elevation_scale_deg = 10.0\ntau_s = 60.0\n",
    );
    assert!(e.contains("world.multipath.sigma_horizon_m"), "{e}");
    let e = err("[world.gnss_antenna]\nlever_arm_b_m = [0.0, 0.0, -1.5]\nlatency_s = 0.0505\n");
    assert!(e.contains("world.gnss_antenna.latency_s"), "{e}");
    let e = err(
        "[world.carrier_phase]\nslips_per_hour_at_45_dbhz = 1.0\nunflagged_fraction = 1.5\n\
         max_slip_cycles = 3\ninitial_ambiguity_cycles = 10\n",
    );
    assert!(e.contains("world.carrier_phase.unflagged_fraction"), "{e}");
    let e = err(
        "[world.phase_multipath]\nsigma_zenith_mm = 2.0\nsigma_horizon_mm = 8.0\n\
         elevation_scale_deg = 15.0\ntau_s = 0.0\n",
    );
    assert!(e.contains("world.phase_multipath.tau_s"), "{e}");
    let tags = |odo_latency: f64, gnss_jitter: f64| {
        format!(
            "[world.time_tags]\nodometer_latency_s = {odo_latency}\ngnss_jitter_s = {gnss_jitter}\n\
             odometer_jitter_s = 0.002\nstar_tracker_jitter_s = 0.0\n"
        )
    };
    let e = err(&tags(0.0105, 0.0));
    assert!(e.contains("world.time_tags.odometer_latency_s"), "{e}");
    let e = err(&tags(0.049, 0.0));
    assert!(e.contains("world.time_tags.odometer_jitter_s"), "{e}");
    // Without an antenna latency the GNSS stamp has no jitter to scatter (cut to 0).
    assert_eq!(err(&tags(0.01, 0.002)), "accepted");
    let e = err("[world.code_noise]\nsigma_at_45_dbhz_m = 0.3\nbogus = 1\n");
    assert!(e.contains("bogus"), "{e}");
    let nlos = |p_h: f64, t: f64| {
        format!(
            "[world.nlos]\nprobability_zenith = 0.0\nprobability_horizon = {p_h}\n\
             elevation_scale_deg = 10.0\nmean_duration_s = {t}\nexcess_path_mean_m = 10.0\n\
             cn0_loss_db = 6.0\n"
        )
    };
    let units = |n: f64, o: f64| {
        format!("[world.units]\nnoise_log_sigma = {n}\noscillator_log_sigma = {o}\n")
    };
    let e = err(&units(1.5, 0.5));
    assert!(e.contains("world.units.noise_log_sigma"), "{e}");
    let e = err(&units(0.2, -0.1));
    assert!(e.contains("world.units.oscillator_log_sigma"), "{e}");
    assert_eq!(err(&units(0.2, 0.5)), "accepted");
    let e = err(&nlos(1.5, 5.0));
    assert!(e.contains("world.nlos.probability_horizon"), "{e}");
    let e = err(&nlos(0.1, 0.0));
    assert!(e.contains("world.nlos.mean_duration_s"), "{e}");
    assert_eq!(err(&nlos(0.1, 5.0)), "accepted");
    // The receiver's budget: the static site's grade has one; overriding it away is an error.
    let no_uere = base.replace("[gnss]", "[gnss]\noverrides = { uere = { sis_m = -1.0 } }");
    let e = match Scenario::from_toml_str(
        &format!("{no_uere}\n[world.code_noise]\nsigma_at_45_dbhz_m = 0.3\n"),
        &path,
    ) {
        Ok(_) => String::from("accepted"),
        Err(e) => e.to_string(),
    };
    assert!(e.contains("gnss.uere"), "{e}");
    assert_eq!(
        err("[world.code_noise]\nsigma_at_45_dbhz_m = 0.3\n"),
        "accepted"
    );
}
