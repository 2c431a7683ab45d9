//! Proves that the filter allocates nothing in steady state: a counting global allocator wraps
//! the system allocator for this test binary; after alignment, `Navigator::push_imu` (with
//! GNSS, star-tracker, odometer and baro samples fused inside it, and zero-velocity updates),
//! the `push_*` queueing calls and every `ekf` measurement update must not move the count;
//! likewise a second navigator in tight GNSS mode (per-satellite pseudorange and range-rate
//! updates, clock states), and a late sample that forces a rewind and replay.
//! Only allocations of the test's own thread are counted (`common`), so that the harness's
//! other threads cannot make the count flaky.

use msgs::{GnssSample, NavMode, SensorId};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use sextant_fusion::celestial::{EarthOrientation, c_e_i};
use sextant_fusion::earth::WGS84;
use sextant_fusion::ekf::{self, GateTable};
use sextant_fusion::frames::Rotation;
use sextant_fusion::navigator::{GnssMode, Navigator, NavigatorConfig};
use sextant_fusion::time::GpsTime;

use crate::common;
use common::{count, samples, track_this_thread};

const T0: i64 = 1_400_000_000_000_000_000;

#[test]
fn filter_allocates_nothing_in_steady_state() {
    track_this_thread();

    let (site, r_e, q_e_b) = common::static_site(55.655, 37.534, 180.0);
    let c_s_b = Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0);
    let pressure = sextant_fusion::atmosphere::isa_pressure_pa(site.height_m);
    let cfg = NavigatorConfig {
        alignment_s: 5.0,
        ..NavigatorConfig::default()
    };
    let mut nav = Box::new(Navigator::new(cfg).unwrap());
    let tight = NavigatorConfig {
        alignment_s: 5.0,
        gnss_mode: GnssMode::Tight,
        ..NavigatorConfig::default()
    };
    let mut nav_tight = Box::new(Navigator::new(tight).unwrap());
    // Six satellites 20 000 km away at elevations 25°–75°.
    let sats: [Vector3<f64>; 6] = samples::sky(site.lat_rad, site.lon_rad, &r_e, 1.1, 25.0, 10.0);
    let rate = 100;
    let dt = 1.0 / rate as f64;
    let mut seq = 0u64;
    let mut step = |nav: &mut Navigator, k: i64| {
        seq += 1;
        let t = T0 + k * 10_000_000;
        let s = samples::static_imu(t, seq, dt, &r_e, &q_e_b);
        if k % 10 == 0 {
            let g = samples::with_fix(samples::raw_gnss(t, seq, &r_e, &sats, 150.0, 0.2), &r_e);
            nav.push_gnss(&g).unwrap();
            nav.push_star_tracker(&samples::star(t, seq, &c_s_b, &q_e_b))
                .unwrap();
            nav.push_baro(&samples::baro(t, seq, pressure)).unwrap();
        }
        if k % 2 == 0 {
            nav.push_odometer(&samples::odometer_at_rest(t, seq, 0.02))
                .unwrap();
        }
        nav.push_imu(&s).unwrap()
    };
    // Alignment (5 s) and warm-up.
    let mut k = 0;
    while k < 10 * rate {
        k += 1;
        step(&mut nav, k);
        step(&mut nav_tight, k);
    }
    assert!(nav.is_navigating());
    // The daemon's checkpoint buffer, filled once before counting (its covariance's storage).
    let mut snapshot = nav.snapshot().expect("navigating");
    let before = count();
    for i in 0..5 * rate {
        k += 1;
        let sol = step(&mut nav, k).expect("navigating");
        assert!(sol.lat_rad.is_finite());
        if i % rate == 0 {
            // A checkpoint a second, as the daemon takes one: into the same buffer.
            assert!(nav.snapshot_into(&mut snapshot));
            assert_eq!(snapshot.gps_time_ns, sol.header.time_ns);
        }
        let sol = step(&mut nav_tight, k).expect("navigating");
        assert!(sol.clock_bias_m.is_finite());
    }
    // A late sample: a GNSS fix of 25 ms ago arrives after the IMU has passed it: held out
    // of the next IMU step, then fused by rewinding to a checkpoint and replaying (delayed
    // fusion, `catch_up`, as the daemon calls it once the solution is out) — still no
    // allocation.
    for _ in 0..4 {
        k += 1;
        step(&mut nav, k).expect("navigating");
    }
    let gnss_fused = nav.health()[SensorId::Gnss as usize].fused;
    let mut late = GnssSample::default();
    late.header.time_ns = T0 + k * 10_000_000 - 25_000_000;
    late.header.seq = 9_999_999;
    late.fix_valid = 1;
    late.pos_ecef_m = r_e.into();
    late.pos_cov_ecef_m2 = [4.0, 0.0, 0.0, 0.0, 4.0, 0.0, 0.0, 0.0, 4.0];
    nav.push_gnss(&late).unwrap();
    k += 1;
    step(&mut nav, k).expect("navigating");
    assert_eq!(nav.health()[SensorId::Gnss as usize].fused, gnss_fused);
    nav.catch_up();
    assert_eq!(nav.health()[SensorId::Gnss as usize].fused, gnss_fused + 1);
    let used = count() - before;
    assert_eq!(
        used, 0,
        "push_imu / push_* allocated {used} times in steady state"
    );
    assert_eq!(nav.mode(), NavMode::GnssAstroInertial as u32);
    let h = nav.health();
    for s in [
        SensorId::Gnss,
        SensorId::StarTracker,
        SensorId::Odometer,
        SensorId::Baro,
    ] {
        assert!(
            h[s as usize].fused > 0,
            "{s:?} never fused: {:?}",
            h[s as usize]
        );
    }
    assert!(nav.zupt_health().fused > 0);
    // Tight coupling fused satellites and estimated the clock (150 m, 0.2 m/s in the data).
    let g = nav_tight.health()[SensorId::Gnss as usize];
    assert!(g.fused > 0 && g.nis_count >= 12, "{g:?}");
    assert!(
        (nav_tight.clock().bias_m - 150.0).abs() < 10.0,
        "{:?}",
        nav_tight.clock()
    );

    // Each update function on its own.
    let p = *nav.covariance();
    let state = *nav.nav_state();
    let gates = GateTable::new(0.999);
    let before = count();
    let c_e_i_now = c_e_i(GpsTime { ns: T0 }, &EarthOrientation::default());
    let q = UnitQuaternion::identity();
    let outs = [
        ekf::update(
            &p,
            &ekf::gnss_position(
                &state,
                &ekf::GnssAntenna::AT_IMU,
                &r_e,
                &(Matrix3::identity() * 4.0),
            ),
            gates.threshold(3),
        )
        .residual
        .nis,
        ekf::update(
            &p,
            &ekf::gnss_velocity(
                &state,
                &ekf::GnssAntenna::AT_IMU,
                &Vector3::zeros(),
                &(Matrix3::identity() * 1e-4),
            ),
            gates.threshold(3),
        )
        .residual
        .nis,
        ekf::update(
            &p,
            &ekf::star_attitude(
                &state,
                &q,
                &Rotation::from_dcm_unchecked(c_e_i_now),
                &Rotation::from_dcm_unchecked(c_s_b),
                &Vector3::zeros(),
                2e-5,
                1e-4,
            ),
            gates.threshold(3),
        )
        .residual
        .nis,
        ekf::update(
            &p,
            &ekf::baro_height(&state, &WGS84, 180.0, 0.0, 0.5),
            gates.threshold(1),
        )
        .residual
        .nis,
        ekf::update(
            &p,
            &ekf::odometer_nhc(&state, &ekf::WheelContact::AT_IMU, 0.0, 0.0, 0.05, 0.05),
            gates.threshold(3),
        )
        .residual
        .nis,
        ekf::update(
            &p,
            &ekf::odometer_speed(&state, &ekf::WheelContact::AT_IMU, 0.0, 0.0, 0.05),
            gates.threshold(1),
        )
        .residual
        .nis,
        ekf::update(&p, &ekf::zero_velocity(&state, 0.005), gates.threshold(3))
            .residual
            .nis,
        ekf::update(
            &p,
            &ekf::gnss_pseudorange(
                &state,
                &ekf::GnssAntenna::AT_IMU,
                &(r_e * 4.0),
                3.0 * r_e.norm(),
                0.0,
                3.0,
            ),
            gates.threshold(1),
        )
        .residual
        .nis,
        ekf::update(
            &p,
            &ekf::gnss_range_rate(
                &state,
                &ekf::GnssAntenna::AT_IMU,
                &(r_e * 4.0),
                &Vector3::zeros(),
                0.0,
                0.0,
                0.05,
            ),
            gates.threshold(1),
        )
        .residual
        .nis,
    ];
    let used = count() - before;
    assert_eq!(used, 0, "ekf updates allocated {used} times");
    assert!(outs.iter().all(|n| !n.is_nan()));
}
