//! Proves that the redundant-channel path (paper 004) allocates nothing per IMU step: a
//! counting global allocator wraps the system allocator; after the navigator has built its
//! `RedundantImu` and aligned, `Navigator::push_imu` with five skewed channels — including the
//! block in which a failed channel is detected, isolated and excluded — and
//! `RedundantImu::step` on its own must not move the count. It also checks, end to end through
//! the navigator, that the failed channel is the one excluded and reported.
//! Only allocations of the test's own thread are counted (`common`), so that
//! the test harness's main thread, which may still be setting up when a fast test starts,
//! cannot make the count flaky.

use nalgebra::Vector3;
use sextant_fusion::navigator::{Navigator, NavigatorConfig};
use sextant_fusion::redundancy::{FdiConfig, RedundantImu, pyramid_axes};

use crate::common;
use common::{count, samples, track_this_thread};

const T0: i64 = 1_400_000_000_000_000_000;

#[test]
fn redundant_channels_allocate_nothing_per_step() {
    track_this_thread();

    let (_, r_e, q_e_b) = common::static_site(58.52, 31.27, 50.0);
    let cfg = NavigatorConfig {
        alignment_s: 5.0,
        ..NavigatorConfig::default()
    };
    let mut nav = Box::new(Navigator::new(cfg).unwrap());
    let n = 5;
    let axes = pyramid_axes(n, 35.26f64.to_radians());
    // Noise-free channels: σ of the test from the default IMU spec is what the navigator
    // derives; the 1e-6 rad per interval (0.0057 °/s) bias step on channel 2 is thousands of
    // σ, so it is detected in the first full block after onset.
    nav.set_redundancy_config(FdiConfig {
        gyro_sigma_rad: 1e-7,
        accel_sigma_m_s: 1e-6,
        learn_blocks: 2,
        ..FdiConfig::default()
    });
    let dt = 0.01;
    let mut seq = 0u64;
    let fault_from = 1500;
    let mut step = |nav: &mut Navigator, k: i64| {
        seq += 1;
        let t = T0 + k * 10_000_000;
        // The body increments are carried by the channels only.
        let mut s = samples::static_imu(t, seq, dt, &r_e, &q_e_b);
        let dth = Vector3::from(std::mem::take(&mut s.delta_angle_rad));
        let dv = Vector3::from(std::mem::take(&mut s.delta_velocity_m_s));
        s.n_channels = n as u32;
        for (i, ax) in axes.iter().enumerate().take(n) {
            let e = Vector3::from(*ax);
            s.channel_axis[i] = *ax;
            s.channel_delta_angle_rad[i] = e.dot(&dth);
            s.channel_delta_velocity_m_s[i] = e.dot(&dv);
        }
        if k >= fault_from {
            s.channel_delta_angle_rad[2] += 1e-6;
        }
        if k % 10 == 0 {
            let g = samples::with_fix(samples::raw_gnss(t, seq, &r_e, &[], 0.0, 0.0), &r_e);
            nav.push_gnss(&g).unwrap();
        }
        nav.push_imu(&s).unwrap()
    };
    // Warm-up: alignment, the RedundantImu built, parity offset learnt.
    for k in 1..=1000 {
        step(&mut nav, k);
    }
    assert!(nav.is_navigating());
    let before = nav.redundancy_status().expect("channels seen");
    assert_eq!(before.excluded_mask, 0);
    assert!(before.blocks_tested > 0);
    let start = count();
    for k in 1001..=2500 {
        let sol = step(&mut nav, k);
        assert!(sol.is_some());
    }
    let used = count() - start;
    let st = nav.redundancy_status().expect("channels seen");
    eprintln!("{st:?}");
    assert_eq!(used, 0, "push_imu with channels allocated {used} times");
    assert_eq!(st.excluded_mask, 1 << 2, "{st:?}");
    assert_eq!(st.faults_detected, 1);

    // RedundantImu on its own.
    let mut r = RedundantImu::new(&axes[..n], FdiConfig::default()).unwrap();
    let g = [1e-5; 5];
    let a = [0.1; 5];
    for _ in 0..10 {
        r.step(&g, &a);
    }
    let start = count();
    for _ in 0..10_000 {
        std::hint::black_box(r.step(&g, &a));
    }
    assert_eq!(count() - start, 0);
}
