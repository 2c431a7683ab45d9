//! Tests of the redundant-inertial combination and its fault detection, isolation and exclusion.

use super::*;
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha20Rng;
use rand_distr::StandardNormal;

fn isotropic_alpha() -> f64 {
    (1.0 / 3.0_f64.sqrt()).asin()
}

fn axes_slice(axes: &[[f64; 3]; MAX_CHANNELS], n: usize) -> Vec<[f64; 3]> {
    axes[..n].to_vec()
}

fn channels(axes: &[[f64; 3]; MAX_CHANNELS], n: usize, x: &Vector3<f64>) -> ChannelVector {
    let mut z = ChannelVector::zeros();
    for i in 0..n {
        z[i] = Vector3::from(axes[i]).dot(x);
    }
    z
}

#[test]
fn noise_free_channels_are_combined_exactly() {
    for (n, alpha) in [(4, 28.7_f64.to_radians()), (5, isotropic_alpha()), (6, 0.3)] {
        let axes = pyramid_axes(n, alpha);
        let imu = RedundantImu::new(&axes_slice(&axes, n), FdiConfig::default()).unwrap();
        let x = Vector3::new(0.01, -0.02, 0.005);
        let err = (imu.combine(&channels(&axes, n, &x)) - x).norm();
        // Exact up to rounding: a few ulps of |x|.
        assert!(err < 1e-16, "n = {n}: {err}");
    }
}

#[test]
fn ls_noise_of_isotropic_pyramid_is_sqrt_three_quarters() {
    // Closed form: HᵀH = Σ e_i e_iᵀ; for the pyramid Σcos²β_k = Σsin²β_k = n/2 and the
    // cross terms vanish, so HᵀH = diag(2cos²α, 2cos²α, 4sin²α) for n = 4; with
    // sin²α = 1/3 it is (4/3) I and the per-axis noise is σ·√(3/4) against σ for the
    // orthogonal triad (trace 9/4 against 3).
    let h4 = measurement_matrix(&pyramid_axes(4, isotropic_alpha()), 0b1111);
    let c4 = ls_covariance_per_unit_variance(&h4).unwrap();
    for i in 0..3 {
        assert!((c4[(i, i)] - 0.75).abs() < 1e-12);
    }
    assert!((c4.trace() - 2.25).abs() < 1e-12);
    let h3 = measurement_matrix(&orthogonal_axes(), 0b111);
    let c3 = ls_covariance_per_unit_variance(&h3).unwrap();
    assert!((c3.trace() - 3.0).abs() < 1e-12);
    // The paper's α = 28.7°: x, y get 1/(2cos²α) = 0.650, z 1/(4 sin²α) = 1.085.
    let a = 28.7_f64.to_radians();
    let hp = measurement_matrix(&pyramid_axes(4, a), 0b1111);
    let cp = ls_covariance_per_unit_variance(&hp).unwrap();
    assert!((cp[(0, 0)] - 1.0 / (2.0 * a.cos().powi(2))).abs() < 1e-12);
    assert!((cp[(2, 2)] - 1.0 / (4.0 * a.sin().powi(2))).abs() < 1e-12);

    // Monte Carlo: 20 000 draws; the sample variance of a χ²-like estimate has relative
    // σ √(2/20000) = 1 %, so 5 % is a 5-σ bound.
    let n = 4;
    let axes = pyramid_axes(n, isotropic_alpha());
    let imu = RedundantImu::new(&axes_slice(&axes, n), FdiConfig::default()).unwrap();
    let mut rng = ChaCha20Rng::seed_from_u64(4);
    let mut var = Vector3::zeros();
    let draws = 20_000;
    for _ in 0..draws {
        let mut z = ChannelVector::zeros();
        for i in 0..n {
            z[i] = rng.sample(StandardNormal);
        }
        let x = imu.combine(&z);
        var += x.component_mul(&x);
    }
    var /= draws as f64;
    for i in 0..3 {
        assert!((var[i] - 0.75).abs() < 0.05 * 0.75, "axis {i}: {}", var[i]);
    }
}

#[test]
fn projector_is_symmetric_idempotent_and_annihilates_motion() {
    let n = 5;
    let axes = pyramid_axes(n, 0.5);
    let imu = RedundantImu::new(&axes_slice(&axes, n), FdiConfig::default()).unwrap();
    let p = imu.projector();
    assert!((p - p.transpose()).norm() < 1e-14);
    assert!((p * p - p).norm() < 1e-13);
    assert!((p.trace() - 2.0).abs() < 1e-12, "rank N − 3");
    let z = channels(&axes, n, &Vector3::new(1.0, 2.0, 3.0));
    assert!((p * z).norm() < 1e-13);
}

fn white_run(
    imu: &mut RedundantImu,
    rng: &mut ChaCha20Rng,
    axes: &[[f64; 3]; MAX_CHANNELS],
    steps: usize,
    fault: impl Fn(usize, &mut ChannelVector),
) {
    let cfg = imu.config;
    let n = imu.n_channels();
    let x = Vector3::new(1e-4, -2e-4, 5e-5);
    let xa = Vector3::new(0.0, 0.0, -0.098);
    for k in 0..steps {
        let mut zg = channels(axes, n, &x);
        let mut za = channels(axes, n, &xa);
        for i in 0..n {
            let a: f64 = rng.sample(StandardNormal);
            let b: f64 = rng.sample(StandardNormal);
            zg[i] += cfg.gyro_sigma_rad * a;
            za[i] += cfg.accel_sigma_m_s * b;
        }
        fault(k, &mut zg);
        imu.step_vectors(&zg, &za);
    }
}

#[test]
fn false_alarm_rate_matches_chi_square_probability() {
    // Pure white noise, no scale errors (κ = 0): each block statistic is χ²(N−3), and each
    // block over the threshold is a false alarm with probability p = 0.01 (the gyro and
    // accelerometer tests are independent: the block is over with 1 − (1 − p)²). With
    // 2000 blocks the count is binomial with mean 2000·0.0199 = 39.8 and σ = 6.2; the
    // bounds are ±4σ. The offset learning is off (no bias), so it cannot absorb anything.
    let cfg = FdiConfig {
        gyro_relative_sigma: 0.0,
        accel_relative_sigma: 0.0,
        block_samples: 10,
        false_alarm_probability: 0.01,
        persistence_blocks: 1,
        learn_blocks: 0,
        track_blocks: 0,
        exclude: false,
        ..Default::default()
    };
    for n in [4, 5] {
        let axes = pyramid_axes(n, isotropic_alpha());
        let mut imu = RedundantImu::new(&axes_slice(&axes, n), cfg).unwrap();
        let mut rng = ChaCha20Rng::seed_from_u64(40 + n as u64);
        white_run(&mut imu, &mut rng, &axes, 20_000, |_, _| {});
        let st = imu.status();
        assert_eq!(st.blocks_tested, 2000);
        let p_block = 1.0 - (1.0 - 0.01f64).powi(2);
        let mean = 2000.0 * p_block;
        let sd = (2000.0 * p_block * (1.0 - p_block)).sqrt();
        let got = st.blocks_over_threshold as f64;
        assert!(
            (got - mean).abs() < 4.0 * sd,
            "n = {n}: {got} over, expected {mean:.1} ± {sd:.1}"
        );
        // Persistence 1: every run of consecutive exceedances is one declared fault.
        let runs = u64::from(st.faults_detected);
        assert!(runs <= st.blocks_over_threshold && runs as f64 > 0.8 * got);
        assert_eq!(st.excluded_mask, 0);
    }
}

#[test]
fn bias_step_is_detected_isolated_and_excluded_in_stated_time() {
    // A bias step of b rad per interval on channel j adds M·b·P e_j to the block parity.
    // Its noncentrality is λ = (M b)² P_jj / (M σ²). With N = 5 isotropic-ish cone
    // (α = 35.26°) P_jj = 1 − 3/5 = 0.4 for every channel (trace 2 shared equally by
    // symmetry). Choose b so that λ = 100 (10 σ_parity of the block in the fault
    // direction): the χ²(2) quantile at 1e-4 is 18.4, so the detection probability per
    // block is > 0.9999 and detection (persistence 2) happens within the block in which
    // the step falls (partial) plus 2 full blocks: ≤ 3 blocks = 300 intervals.
    let cfg = FdiConfig {
        gyro_relative_sigma: 0.0,
        accel_relative_sigma: 0.0,
        learn_blocks: 0,
        ..Default::default()
    };
    let n = 5;
    let axes = pyramid_axes(n, isotropic_alpha());
    let m = f64::from(cfg.block_samples);
    let pjj = 0.4;
    let b = (100.0 * cfg.gyro_sigma_rad.powi(2) / (m * pjj)).sqrt();
    for j in 0..n {
        let mut imu = RedundantImu::new(&axes_slice(&axes, n), cfg).unwrap();
        assert!((imu.projector()[(j, j)] - pjj).abs() < 1e-12);
        let mut rng = ChaCha20Rng::seed_from_u64(7 + j as u64);
        let onset = 5_050;
        white_run(&mut imu, &mut rng, &axes, 5_400, |k, z| {
            if k >= onset {
                z[j] += b;
            }
        });
        let st = imu.status();
        assert_eq!(st.excluded_mask, 1 << j, "channel {j}");
        assert_eq!(st.faults_detected, 1);
        let delay = st.last_detection_step as i64 - onset as i64;
        assert!((0..=300).contains(&delay), "delay {delay}");
        assert_eq!(imu.active_mask().count_ones(), 4);
        // Navigation continues exactly with the 4 remaining channels.
        let x = Vector3::new(0.3, 0.2, 0.1);
        let mut z = channels(&axes, n, &x);
        z[j] += 1.0;
        assert!((imu.combine(&z) - x).norm() < 1e-14);
    }
}

#[test]
fn four_channels_detect_but_cannot_isolate() {
    // N = 4: P has rank 1, every column parallel: the fault is flagged on all channels and
    // nothing is excluded.
    let cfg = FdiConfig {
        gyro_relative_sigma: 0.0,
        accel_relative_sigma: 0.0,
        learn_blocks: 0,
        ..Default::default()
    };
    let n = 4;
    let axes = pyramid_axes(n, 28.7_f64.to_radians());
    let mut imu = RedundantImu::new(&axes_slice(&axes, n), cfg).unwrap();
    let mut rng = ChaCha20Rng::seed_from_u64(9);
    let b = 20.0 * cfg.gyro_sigma_rad;
    white_run(&mut imu, &mut rng, &axes, 2_000, |k, z| {
        if k >= 1_000 {
            z[2] += b;
        }
    });
    let st = imu.status();
    assert_eq!(st.faults_detected, 1);
    assert_eq!(st.excluded_mask, 0);
    assert_eq!(st.suspect_mask, 0b1111);
}

#[test]
fn learnt_offset_removes_constant_biases() {
    // Channel biases of 30 σ per interval would saturate the test; after learning the
    // offset the false-alarm count is back to the χ² level (≤ 5 of 500 blocks at 1e-4 is
    // generous: expected 0.1).
    let cfg = FdiConfig {
        gyro_relative_sigma: 0.0,
        accel_relative_sigma: 0.0,
        learn_blocks: 20,
        exclude: false,
        ..Default::default()
    };
    let n = 5;
    let axes = pyramid_axes(n, 0.4);
    let mut imu = RedundantImu::new(&axes_slice(&axes, n), cfg).unwrap();
    let mut rng = ChaCha20Rng::seed_from_u64(11);
    let bias = [3.0, -1.0, 0.5, 2.0, -2.5];
    white_run(&mut imu, &mut rng, &axes, 52_000, |_, z| {
        for i in 0..5 {
            z[i] += bias[i] * 10.0 * cfg.gyro_sigma_rad;
        }
    });
    let st = imu.status();
    assert_eq!(st.blocks_tested, 500);
    assert!(st.blocks_over_threshold <= 5, "{st:?}");
}

/// A warm-up transient `b_i·e^{−t/τ}` on each gyro channel (b of 5 block σ, τ = 300
/// blocks), learnt into the offset at power-on. With the slow tracker alone (600 blocks) the
/// offset keeps most of it for the first ~τ after learning, so the statistic is far above its
/// χ² mean and blocks cross the threshold. With the warm-up configured (3τ, tracked with
/// τ/10) the lag is b/9 ≤ 0.6 block σ, decaying as the transient: over blocks 300–1500 the
/// mean statistic per dof is 1 ± 4·√(2/1200) = ± 0.16.
#[test]
fn warmup_tracking_follows_a_bias_transient() {
    let tau_blocks = 300.0;
    let run = |warmup_blocks: u32| {
        let cfg = FdiConfig {
            gyro_relative_sigma: 0.0,
            accel_relative_sigma: 0.0,
            learn_blocks: 30,
            track_blocks: 600,
            warmup_blocks,
            warmup_track_blocks: 30,
            exclude: false,
            ..Default::default()
        };
        let n = 4;
        let axes = pyramid_axes(n, 0.5);
        let mut imu = RedundantImu::new(&axes_slice(&axes, n), cfg).unwrap();
        let mut rng = ChaCha20Rng::seed_from_u64(17);
        let b = [1.0, -0.6, 0.3, -0.9].map(|v| v * 5.0 * 10.0 * cfg.gyro_sigma_rad / 100.0);
        let m = f64::from(cfg.block_samples);
        let (mut sum, mut blocks, mut tested) = (0.0, 0, 0);
        let steps = 1500 * cfg.block_samples as usize;
        let x = Vector3::new(1e-4, -2e-4, 5e-5);
        let xa = Vector3::new(0.0, 0.0, -0.098);
        for k in 0..steps {
            let d = (-(k as f64) / m / tau_blocks).exp();
            let mut zg = channels(&axes, n, &x);
            let mut za = channels(&axes, n, &xa);
            for i in 0..n {
                let (u, v): (f64, f64) = (rng.sample(StandardNormal), rng.sample(StandardNormal));
                zg[i] += cfg.gyro_sigma_rad * u + b[i] * d;
                za[i] += cfg.accel_sigma_m_s * v;
            }
            imu.step_vectors(&zg, &za);
            let st = imu.status();
            if st.blocks_tested > tested {
                tested = st.blocks_tested;
                if k >= 300 * cfg.block_samples as usize {
                    sum += st.last_gyro_statistic / f64::from(st.dof);
                    blocks += 1;
                }
            }
        }
        (sum / f64::from(blocks), imu.status())
    };
    let (slow, st_slow) = run(0);
    let (warm, st_warm) = run((3.0 * tau_blocks) as u32);
    println!("mean statistic per dof: slow tracker {slow:.3}, warm-up configured {warm:.3}");
    assert!(slow > 1.5, "slow tracker: mean {slow}");
    assert!(st_slow.blocks_over_threshold > 0, "{st_slow:?}");
    assert!((warm - 1.0).abs() < 0.16, "warm-up configured: mean {warm}");
    assert_eq!(st_warm.faults_detected, 0, "{st_warm:?}");
}

#[test]
fn rejects_bad_layouts() {
    let coplanar = [
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.6, 0.8, 0.0],
        [-0.6, 0.8, 0.0],
    ];
    assert!(RedundantImu::new(&coplanar, FdiConfig::default()).is_err());
    assert!(RedundantImu::new(&coplanar[..2], FdiConfig::default()).is_err());
    let not_unit = [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]];
    assert!(RedundantImu::new(&not_unit, FdiConfig::default()).is_err());
}
