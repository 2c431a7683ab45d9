//! The Navigator's redundant-channel FDI (paper 004, fusion::redundancy) configured from the
//! `[redundancy]` section of the filter tuning, on the UAV scenario's 12-bit MEMS channels:
//! with the quantisation in the per-interval noise the parity statistic is χ² (mean = dof),
//! an hour of flight raises no false alarm, and a gyro bias step is still isolated and
//! excluded.

use fusion::navigator::{Navigator, NavigatorConfig};
use msgs::{Channel, Record};
use sextant_drivers_sim::imu::ChannelErrorModel;
use sextant_drivers_sim::offline::{OfflineSim, feed};
use sextant_drivers_sim::scenario::Scenario;
use std::path::Path;

fn root() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

/// The UAV scenario with `edit` applied to its text.
fn uav_with(edit: impl Fn(String) -> String) -> Scenario {
    let p = root().join("config/scenarios/uav.toml");
    let text = std::fs::read_to_string(&p).expect("uav.toml");
    Scenario::from_toml_str(&edit(text), &p).unwrap_or_else(|e| panic!("{e}"))
}

/// Filter tuning for the scenario's MEMS IMU, as a user would write it: `config/filter.toml`
/// with the `[imu]` white noise and biases of the grade and, when `quantised`, the
/// `[redundancy]` quantisation steps of its ADC (2·full scale / 2^bits), parsed from TOML.
/// With `warmup`, the `[redundancy]` warm-up from the data sheet's settling time
/// (`ImuGrade::fdi_warmup_blocks`): blocks until then after the 30 learning blocks.
fn mems_config(scn: &Scenario, quantised: bool, warmup: bool) -> NavigatorConfig {
    let g = &scn.imu.gyro;
    let a = &scn.imu.accel;
    let text = std::fs::read_to_string(root().join("config/filter.toml")).expect("filter.toml");
    let set = |t: String, key: &str, v: f64| {
        let start = t.find(&format!("\n{key} = ")).expect(key) + 1;
        let end = start + t[start..].find('#').expect("comment");
        let v = if v.fract() == 0.0 && v >= 0.0 && key.ends_with("blocks") {
            format!("{v}")
        } else {
            format!("{v:e}")
        };
        format!("{}{key} = {v} {}", &t[..start], &t[end..])
    };
    let mut t = text;
    t = set(t, "gyro_bias_deg_h", g.bias_deg_h);
    t = set(t, "arw_deg_sqrt_h", g.arw_deg_per_rt_h);
    t = set(t, "accel_bias_ug", a.bias_ug);
    t = set(t, "vrw_ug_sqrt_hz", a.vrw_ug_per_rt_hz);
    if quantised {
        let qg = 2.0 * g.full_scale_deg_s / 2f64.powi(g.adc_bits as i32);
        let qa = 2.0 * a.full_scale_g * 1e3 / 2f64.powi(a.adc_bits as i32);
        t = set(t, "gyro_quantum_deg_s", qg);
        t = set(t, "accel_quantum_mg", qa);
    }
    if warmup {
        let (settled, track) = scn.imu.fdi_warmup_blocks(100.0 / scn.spec.imu.rate_hz);
        t = set(t, "warmup_blocks", f64::from(settled.saturating_sub(30)));
        t = set(t, "warmup_track_blocks", f64::from(track));
    }
    let cfg: NavigatorConfig = toml::from_str(&t).unwrap_or_else(|e| panic!("{e}\n{t}"));
    cfg.validate().unwrap_or_else(|e| panic!("{e}"));
    cfg
}

/// Mean parity statistic per degree of freedom over the test blocks that closed inside each
/// of `windows` (s), for the gyros and the accelerometers, with the blocks over the threshold
/// there; plus the final FDI status.
struct FdiRun {
    windows: Vec<WindowStats>,
    status: fusion::redundancy::RedundancyStatus,
    /// Sim time (s) of the first exclusion.
    excluded_at: Option<f64>,
}

/// One window's test blocks.
#[derive(Debug, Clone, Copy, Default)]
struct WindowStats {
    gyro_sum: f64,
    accel_sum: f64,
    blocks: usize,
    over_threshold: u64,
}

impl FdiRun {
    /// (gyro mean, accel mean, blocks, blocks over the threshold) over the windows `range`.
    fn over(&self, range: std::ops::Range<usize>) -> (f64, f64, usize, u64) {
        let w = self.windows[range]
            .iter()
            .fold(WindowStats::default(), |a, w| WindowStats {
                gyro_sum: a.gyro_sum + w.gyro_sum,
                accel_sum: a.accel_sum + w.accel_sum,
                blocks: a.blocks + w.blocks,
                over_threshold: a.over_threshold + w.over_threshold,
            });
        let n = w.blocks.max(1) as f64;
        (w.gyro_sum / n, w.accel_sum / n, w.blocks, w.over_threshold)
    }
}

fn run_fdi(scn: &Scenario, cfg: NavigatorConfig, windows: &[(f64, f64)]) -> FdiRun {
    // IMU and GNSS: the navigator aligns on the ground and navigates with GNSS fixes (the FDI
    // runs on every IMU sample whatever the phase).
    let sim = OfflineSim::with_channels(scn, &[Channel::Imu, Channel::Gnss]);
    let epoch = sim.epoch_ns();
    let mut nav = Navigator::new(cfg).expect("config");
    let mut stats = vec![WindowStats::default(); windows.len()];
    let (mut tested, mut over) = (0, 0);
    let mut excluded_at = None;
    for m in sim {
        let t = (m.time_ns() - epoch) as f64 * 1e-9;
        if let Err(e) = feed(&mut nav, &m) {
            panic!("{e}");
        }
        if !matches!(m, Record::Imu(_)) {
            continue;
        }
        let st = nav.redundancy_status().expect("channels");
        if st.blocks_tested > tested {
            tested = st.blocks_tested;
            if let Some(k) = windows.iter().position(|(a, b)| t >= *a && t < *b) {
                let w = &mut stats[k];
                w.gyro_sum += st.last_gyro_statistic / f64::from(st.dof);
                w.accel_sum += st.last_accel_statistic / f64::from(st.dof);
                w.blocks += 1;
                w.over_threshold += st.blocks_over_threshold - over;
            }
            over = st.blocks_over_threshold;
        }
        if excluded_at.is_none() && st.excluded_mask != 0 {
            excluded_at = Some(t);
        }
    }
    FdiRun {
        windows: stats,
        status: nav.redundancy_status().expect("channels"),
        excluded_at,
    }
}

/// The mean per degree of freedom that the parity statistic should have over level cruise
/// (gyros, accelerometers) when the FDI is configured with per-interval σ `configured` and
/// the channels are the world's parts: with `P = I − H(HᵀH)⁻¹Hᵀ` the parity projector and
/// `D = diag(σ_i²)` the parts' actual per-interval variances (noise density and
/// quantisation), `E‖P z‖² = tr(P D) = Σ P_ii σ_i²`, over `dof · σ²`. Equal to 1 when every
/// part is its data sheet.
fn predicted_mean(scn: &Scenario, configured: (f64, f64), dt_s: f64) -> (f64, f64) {
    let model = ChannelErrorModel::new(scn).expect("channels");
    let axes = model.axes();
    let n = axes.len();
    let h = nalgebra::DMatrix::from_fn(n, 3, |i, j| axes[i][j]);
    let hth = (h.transpose() * &h).try_inverse().expect("rank 3");
    let p = nalgebra::DMatrix::<f64>::identity(n, n) - &h * hth * h.transpose();
    let dof = (n - 3) as f64;
    let (mut g, mut a) = (0.0, 0.0);
    for i in 0..n {
        let (sg, sa) = model.actual_interval_sigmas(i, dt_s).expect("channel");
        g += p[(i, i)] * sg * sg;
        a += p[(i, i)] * sa * sa;
    }
    (
        g / (dof * configured.0.powi(2)),
        a / (dof * configured.1.powi(2)),
    )
}

/// One hour of the UAV flight (ground, take-off, climb, cruise, two turns) with its four
/// 12-bit pyramid channels, each its own part (`[world.imu]` of uav.toml), and the FDI
/// configured from the MEMS data sheet as a user would.
///
/// The statistic of a block is ‖P Σz − offset‖² / (M σ² + (κ ΔX)²) with σ the data sheet's
/// per-interval noise. Over the straight level cruise legs (600–1680 s, 1750–2880 s,
/// 2950–3600 s: the adaptive κ term, which is there for manoeuvres, is negligible) its mean per
/// dof is the parts' parity variance over the data sheet's, [`predicted_mean`] (1 when every
/// part is its data sheet), ± √(2/n) = ± 0.027 over n ≈ 2 850 one-second blocks.
/// - Gyros, with the `[redundancy]` quantisation step: within 0.1 of the prediction (3.7σ).
/// - Gyros without it (white noise only, the previous default): the configured variance
///   lacks (q dt)²/12 (q = 0.0732 °/s, ARW 0.3 °/√h, dt = 0.01 s), so the mean is the
///   prediction with the white-only σ: within 0.12 of it (about 1.18 × the quantised one).
/// - Accelerometers: quantisation adds 14 % (1.953 mg, 150 µg/√Hz) — the white-only run's
///   mean over the quantised one's is the ratio of the configured variances, 1.14 ± 0.02 — but
///   the mean is above the prediction and grows along the flight (on the data sheet's parts:
///   1.07, 1.25, 1.37 over the three legs; 1.12, 1.12, 1.21 with the temperature ramp off): the
///   learnt parity offset lags the channel biases' random walk (100 µg/√h) and temperature
///   drift (100 µg/°C × 2 °C/h), which the block test does not model (the gyro drifts are
///   100× smaller relative to their noise). Bounded at the prediction + 0.5 with the parts'
///   warm-up switched off; at that excess the χ²₁ 1e-4 threshold (15.1) is crossed with
///   probability 1e-3 per block, twice in a row (persistence 2) 1e-6: no false alarm expected
///   in the hour, and single blocks over the threshold at most 3.6 in the hour's ≈ 3 600 on
///   average, so at most 12 (Poisson, P(≥ 13) = 1e-4).
/// - The parts' accelerometer warm-up (1 mg 1-σ per part, τ 300 s) is learnt into the offset
///   at power-on and then forgotten by the tracker (time constant `track_blocks` = 600 s, as
///   slow as drift-ramp faults require): the legs' excess over the run without the warm-up
///   is positive and shrinks leg by leg (measured on seed 4: 1.36, 0.30, 0.06; 11 blocks
///   over the threshold in the hour). With the data sheet's settling time in the
///   configuration (`[redundancy] warmup_blocks`, tracked with τ/10 until then) every leg is
///   back under the bound above. Either way no fault is declared in the hour and nothing is
///   excluded.
#[test]
fn uav_hour_with_quantised_channels_has_no_false_alarm() {
    use crate::fixture::replace_present;
    let hour = |t: String| replace_present(&t, "duration_s = 18000.0", "duration_s = 3600.0");
    let scn = uav_with(hour);
    let no_warmup = uav_with(|t| {
        replace_present(
            &hour(t),
            "accel_warmup_ug = 1000.0",
            "accel_warmup_ug = 0.0",
        )
    });
    let warmup = |s: &Scenario| {
        s.spec
            .world
            .and_then(|w| w.imu())
            .map(|u| u.accel_warmup_ug)
    };
    assert_eq!(
        (warmup(&scn), warmup(&no_warmup)),
        (Some(1000.0), Some(0.0))
    );
    assert_eq!(scn.imu.gyro.adc_bits, 12);
    let windows = [(600.0, 1680.0), (1750.0, 2880.0), (2950.0, 3600.0)];
    let dt = 1.0 / scn.spec.imu.rate_hz;
    let sheet = ChannelErrorModel::new(&scn)
        .expect("channels")
        .interval_sigmas(dt);
    let (pg, pa) = predicted_mean(&scn, sheet, dt);
    let q = run_fdi(&scn, mems_config(&scn, true, false), &windows);
    let nw = run_fdi(&no_warmup, mems_config(&no_warmup, true, false), &windows);
    let cw = run_fdi(&scn, mems_config(&scn, true, true), &windows);
    let (qg, qa, blocks, _) = q.over(0..3);
    let (_, nwa, _, nw_over) = nw.over(0..3);
    println!(
        "the parts' parity variance over the data sheet's: gyro {pg:.3}, accel {pa:.3}\n\
         quantisation in the threshold: gyro mean statistic/dof {qg:.3}, accel {qa:.3} over \
         {blocks} blocks; status {:?}\n\
         accel warm-up off: accel {nwa:.3}; {nw_over} blocks over the threshold",
        q.status
    );
    let legs: Vec<(f64, f64)> = (0..3)
        .map(|k| (q.over(k..k + 1).1, nw.over(k..k + 1).1))
        .collect();
    println!("accel per leg (with, without the warm-up): {legs:.3?}");
    let (_, cwa, _, cw_over) = cw.over(0..3);
    let cw_legs: Vec<f64> = (0..3).map(|k| cw.over(k..k + 1).1).collect();
    println!(
        "warm-up configured from the data sheet: accel {cwa:.3} per leg {cw_legs:.3?}; \
         {cw_over} blocks over the threshold; status {:?}",
        cw.status
    );
    assert!(blocks > 2700, "{blocks} blocks");
    assert!((qg - pg).abs() < 0.1, "gyro {qg} vs predicted {pg}");
    assert!(
        nwa < pa + 0.5,
        "accel without warm-up {nwa} vs predicted {pa}"
    );
    assert!(nw_over <= 12, "{nw_over} blocks over the threshold");
    for k in 0..3 {
        let excess = legs[k].0 - legs[k].1;
        assert!(excess > 0.0, "leg {k}: the warm-up adds to the statistic");
        if k > 0 {
            assert!(
                excess < legs[k - 1].0 - legs[k - 1].1,
                "leg {k}: the excess shrinks"
            );
        }
    }
    // The data sheet's warm-up in the FDI configuration takes the transient out of the
    // learnt offset: every leg as without the warm-up (prediction + 0.5, the same bound).
    for (k, a) in cw_legs.iter().enumerate() {
        assert!(
            *a < pa + 0.5,
            "leg {k}: accel {a} with the warm-up configured"
        );
    }
    assert!(cw_over <= 12, "{cw_over} blocks over the threshold");
    for r in [&q, &nw, &cw] {
        assert_eq!(r.status.faults_detected, 0, "false alarm");
        assert_eq!(r.status.excluded_mask, 0);
        assert!(r.status.blocks_tested > 3500);
    }

    let w = run_fdi(&scn, mems_config(&scn, false, false), &windows);
    let (wg, wa, _, _) = w.over(0..3);
    let g = &scn.imu.gyro;
    let white = g.arw_deg_per_rt_h.to_radians() / 60.0 * dt.sqrt();
    let (pwg, _) = predicted_mean(&scn, (white, sheet.1), dt);
    println!(
        "white noise only: gyro {wg:.3} (predicted {pwg:.3}), accel {wa:.3}; faults {}",
        w.status.faults_detected
    );
    assert!((wg - pwg).abs() < 0.12, "gyro {wg} vs predicted {pwg}");
    let ratio = wa / qa;
    assert!((ratio - 1.14).abs() < 0.02, "accel ratio {ratio}");
}

/// Five 12-bit channels on the isotropic pyramid (isolation needs N ≥ 5), gyro channel 1
/// steps by 300 °/h at 400 s (in the climb). With the quantisation in the threshold the
/// step is isolated and channel 1 excluded, nothing before it.
///
/// Detectability: one block (M = 100 samples, 1 s) of white noise has σ_block = √M σ_g =
/// 10 · 9.5e-6 = 9.5e-5 rad; the step adds b·1 s = 1.45e-3 rad to the channel, of which the
/// parity space keeps P_ii = (N−3)/N = 0.4 of the energy: non-centrality
/// λ = 0.4 · (1.45e-3 / 9.5e-5)² ≈ 94 against the χ²₂ threshold 18.4 (p = 1e-4): a miss
/// needs a 4σ low draw, so each full block detects, and with `persistence_blocks` = 2 the
/// exclusion comes within 3 blocks of the step (one partial, two full): before 403 s.
#[test]
fn bias_step_on_quantised_channel_is_still_isolated() {
    use crate::fixture::replace_present;
    let scn = uav_with(|t| {
        replace_present(
            &replace_present(&t, "duration_s = 18000.0", "duration_s = 420.0"),
            "channels = { layout = \"pyramid\", n = 4, alpha_deg = 28.7 }",
            "channels = { layout = \"pyramid\", n = 5, alpha_deg = 35.26, failures = [\
             { channel = 1, sensor = \"gyro\", kind = \"bias_step\", start_s = 400.0, magnitude = 300.0 } ] }",
        )
    });
    let r = run_fdi(&scn, mems_config(&scn, true, false), &[]);
    println!("status {:?}, excluded at {:?} s", r.status, r.excluded_at);
    assert_eq!(r.status.excluded_mask, 1 << 1, "channel 1 excluded");
    assert_eq!(r.status.faults_detected, 1);
    let t = r.excluded_at.expect("excluded");
    assert!((400.0..403.0).contains(&t), "excluded at {t} s");
}
