//! The GNSS paths allocate nothing on the hot path: the per-epoch
//! least-squares cross-check (`gnss_ls::solve` inside `Navigator::push_imu`), the tight clock
//! start by state augmentation (first tight epoch after alignment without GNSS) and the tight
//! updates. A static navigator in tight mode gets GNSS only after alignment (position from the
//! configuration), so its first counted GNSS epoch starts the clock from the satellites and
//! every counted epoch is cross-checked (≥ 4 satellites). Allocations of this test's thread
//! only are counted (`common`).

use crate::common;
use common::{count, samples, track_this_thread};
use msgs::{GnssSample, SensorId};
use nalgebra::Vector3;
use sextant_fusion::gnss_ls;
use sextant_fusion::navigator::{GnssMode, InitialPosition, Navigator, NavigatorConfig};

const T0: i64 = 1_400_000_000_000_000_000;

#[test]
fn gnss_cross_check_and_clock_start_allocate_nothing() {
    track_this_thread();

    let (site, r_e, q_e_b) = common::static_site(55.655, 37.534, 180.0);
    let sats: [Vector3<f64>; 6] = samples::sky(site.lat_rad, site.lon_rad, &r_e, 1.1, 25.0, 10.0);
    let mut nav = Box::new(
        Navigator::new(NavigatorConfig {
            alignment_s: 5.0,
            gnss_mode: GnssMode::Tight,
            initial_position: Some(InitialPosition {
                lat_deg: site.lat_rad.to_degrees(),
                lon_deg: site.lon_rad.to_degrees(),
                height_m: site.height_m,
            }),
            ..NavigatorConfig::default()
        })
        .unwrap(),
    );
    let rate = 100;
    let dt = 1.0 / rate as f64;
    let mut seq = 0u64;
    let mut step = |nav: &mut Navigator, k: i64, with_gnss: bool| {
        seq += 1;
        let t = T0 + k * 10_000_000;
        let s = samples::static_imu(t, seq, dt, &r_e, &q_e_b);
        if with_gnss && k % 10 == 0 {
            nav.push_gnss(&samples::raw_gnss(t, seq, &r_e, &sats, 150.0, 0.2))
                .unwrap();
        }
        nav.push_imu(&s).unwrap()
    };
    let mut k = 0;
    while k < 10 * rate {
        k += 1;
        step(&mut nav, k, false);
    }
    assert!(nav.is_navigating());
    // The solver alone, on the stack.
    let mut sample = GnssSample {
        n_satellites: sats.len() as u32,
        ..GnssSample::default()
    };
    for (i, r_s) in sats.iter().enumerate() {
        let sat = &mut sample.satellites[i];
        sat.flags = 1;
        sat.pseudorange_m = (r_s - r_e).norm();
        sat.sigma_pseudorange_m = 3.0;
        sat.sat_pos_ecef_m = (*r_s).into();
    }
    let before = count();
    let fix = gnss_ls::solve_sample(&std::hint::black_box(sample)).expect("fix");
    assert!((fix.position.r_e_m - r_e).norm() < 1e-3);
    for _ in 0..5 * rate {
        k += 1;
        step(&mut nav, k, true).expect("navigating");
    }
    let used = count() - before;
    assert_eq!(used, 0, "GNSS paths allocated {used} times");
    // Every counted epoch was cross-checked, and the clock was started (bias 150 m).
    let d = nav.diagnostics();
    assert!(d.gnss_ls_checks >= 45, "{d:?}");
    assert_eq!(d.gnss_ls_disagreements, 0, "{d:?}");
    assert!(nav.health()[SensorId::Gnss as usize].fused >= 45);
    assert!(
        (nav.clock().bias_m - 150.0).abs() < 10.0,
        "{:?}",
        nav.clock()
    );
}
