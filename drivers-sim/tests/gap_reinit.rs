//! IMU time discontinuities in a real simulated stream (drivers_sim::offline): an hour without
//! IMU samples re-initialises the navigator, which re-aligns and navigates again as well as
//! after its first alignment; a single wild IMU time stamp is rejected and navigation goes on
//! (policy: `fusion::navigator`, `MAX_BRIDGED_GAP_NS`).

use fusion::alignment::{AlignmentErrorSpec, expected_sigmas};
use fusion::navigator::{Navigator, NavigatorConfig};
use msgs::Record;
use msgs::{ImuSample, NavMode, SensorId};
use nalgebra::Vector3;
use sextant_drivers_sim::offline::{OfflineSim, RunPoint, compare, feed};
use sextant_drivers_sim::scenario::Scenario;

fn default_config() -> NavigatorConfig {
    crate::fixture::matched_filter()
}

/// The default vehicle scenario (matched world) with the trajectory and duration replaced.
fn vehicle_with(segments: &str, duration_s: f64) -> Scenario {
    crate::fixture::matched_vehicle_with(segments, duration_s)
}

/// One drive: speed up, cruise, a 90° turn, cruise, stop (75 s).
const DRIVE: &str = r#"
    { type = "speed", to_m_s = 10.0, duration_s = 10.0 },
    { type = "cruise", duration_s = 20.0 },
    { type = "turn", angle_deg = 90.0, duration_s = 15.0 },
    { type = "cruise", duration_s = 20.0 },
    { type = "speed", to_m_s = 0.0, duration_s = 10.0 },"#;

/// What happens to an IMU sample of the stream.
enum Edit {
    Keep,
    Drop,
    /// Replace its time of validity (a corrupt header).
    Retime(i64),
}

/// Per-run results.
#[derive(Default)]
struct Run {
    /// IMU samples the navigator rejected, with the sim time (s).
    imu_rejected: Vec<f64>,
    /// Aiding samples rejected (during an IMU gap they may be more than 1 h ahead).
    aiding_rejected: u64,
    /// Sim time (s) of each start of navigation (alignment end), with the first point.
    nav_starts: Vec<RunPoint>,
    points: Vec<RunPoint>,
    modes: Vec<(f64, u32)>,
}

/// Feed the scenario to a navigator with `edit` applied to the IMU stream.
fn run(scn: &Scenario, nav: &mut Navigator, edit: impl Fn(f64, &ImuSample) -> Edit) -> Run {
    let sim = OfflineSim::new(scn);
    let epoch = sim.epoch_ns();
    let mut out = Run::default();
    let mut was_navigating = false;
    for msg in sim {
        let t_s = (msg.time_ns() - epoch) as f64 * 1e-9;
        match msg {
            Record::Truth(tr) => {
                if nav.is_navigating() && nav.time().ns == tr.header.time_ns {
                    let p = compare(nav, &tr, epoch);
                    if !was_navigating {
                        out.nav_starts.push(p);
                    }
                    out.points.push(p);
                }
                was_navigating = nav.is_navigating();
            }
            Record::Imu(mut s) => {
                match edit(t_s, &s) {
                    Edit::Keep => {}
                    Edit::Drop => continue,
                    Edit::Retime(t) => s.header.time_ns = t,
                }
                if nav.push_imu(&s).is_err() {
                    out.imu_rejected.push(t_s);
                }
                if out.modes.last().is_none_or(|m| m.1 != nav.mode()) {
                    out.modes.push((t_s, nav.mode()));
                }
            }
            m => {
                if feed(nav, &m).is_err() {
                    out.aiding_rejected += 1;
                }
            }
        }
    }
    out
}

/// Horizontal RMS (m) and attitude RMS (rad) of the points in `[t0, t1]` s.
fn rms(points: &[RunPoint], t0: f64, t1: f64) -> (f64, f64, usize) {
    let w: Vec<&RunPoint> = points
        .iter()
        .filter(|p| p.t_s >= t0 && p.t_s <= t1)
        .collect();
    let n = w.len().max(1) as f64;
    let h = (w
        .iter()
        .map(|p| p.horizontal_error_m().powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    let a = (w
        .iter()
        .map(|p| p.att_err_e_rad.norm_squared())
        .sum::<f64>()
        / n)
        .sqrt();
    (h, a, w.len())
}

/// Closed-form 1-σ (level, heading) of the static coarse alignment (fusion::alignment) for the
/// configured IMU over `alignment_s` = T at the scenario's latitude φ: gyrocompassing heading
/// σ = √(ε² + N²/T)/(Ω cos φ) (bias ε = 0.01 °/h, ARW N = 0.002 °/√h, T = 100 s: 0.106° at
/// 55.655°), levelling σ = √(b_a² + V²/T)/g (50 µg, 20 µg/√Hz: 0.0029°).
fn alignment_sigmas(cfg: &NavigatorConfig, lat_deg: f64) -> (f64, f64) {
    let noise = cfg.imu.process_noise();
    let spec = AlignmentErrorSpec {
        gyro_bias_rad_s: cfg.imu.gyro_bias_rad_s(),
        accel_bias_m_s2: cfg.imu.accel_bias_m_s2(),
        arw_rad_sqrt_s: noise.arw_rad_sqrt_s,
        vrw_m_s_sqrt_s: noise.vrw_m_s_sqrt_s,
    };
    expected_sigmas(
        &spec,
        cfg.alignment_s,
        lat_deg.to_radians(),
        fusion::earth::WGS84.omega_ie_rad_s,
        9.815,
    )
}

/// (level, heading) error of a solution point, rad: the NED components of ψ.
fn level_heading_error(p: &RunPoint) -> (f64, f64) {
    let psi_n: Vector3<f64> = p.c_e_n.transpose() * p.att_err_e_rad;
    (psi_n.x.hypot(psi_n.y), psi_n.z.abs())
}

/// An hour without IMU samples while the vehicle is parked. Trajectory: 120 s static, a 75 s
/// drive, parked 3800 s, the same drive again. The IMU stream is cut from 200 s to 3800 s
/// (GNSS, star tracker, odometer and baro keep publishing). Expected:
/// - the first 19 samples after the gap are held (rejected), the 20th re-initialises
///   (`reinitializations` = 1, mode back to aligning) and starts a new alignment, which ends
///   `alignment_s` later while the vehicle is still parked;
/// - at the end of each alignment the attitude error is within 3σ of the closed-form
///   alignment accuracy (`alignment_sigmas`): the re-alignment is a real alignment, not the old
///   attitude carried over;
/// - over the second drive the horizontal and attitude RMS are within twice those of the first
///   drive (same manoeuvres, same sensors: the default-run level). Factor 2: each RMS is over
///   75 s in which the GNSS (1 Hz) and the star tracker give ≈ 75 independent corrections, a
///   relative scatter of 1/√(2·75) ≈ 8 % per RMS; the error being correlated over the ≈ 10 s
///   filter time constant leaves ≈ 8 independent values, 1/√16 ≈ 25 %; two such RMS differ by
///   more than a factor 2 only at > 3σ.
#[test]
fn hour_gap_reinitialises_and_realigns() {
    let segments = format!(
        r#"
    {{ type = "hold", duration_s = 120.0 }},{DRIVE}
    {{ type = "hold", duration_s = 3800.0 }},{DRIVE}
    {{ type = "hold", duration_s = 5.0 }},
"#
    );
    // Drive 1: 120–195 s; parked 195–3995 s; drive 2: 3995–4070 s.
    let scn = vehicle_with(&segments, 4075.0);
    let cfg = default_config();
    let mut nav = Navigator::new(cfg.clone()).expect("config");
    let (gap_start, gap_end) = (200.0, 3800.0);
    let r = run(&scn, &mut nav, |t, _| {
        if t > gap_start && t <= gap_end {
            Edit::Drop
        } else {
            Edit::Keep
        }
    });
    let d = nav.diagnostics();
    println!(
        "IMU rejected {} (first {:?}), aiding rejected {}, modes {:?}, nav starts {:?}",
        r.imu_rejected.len(),
        r.imu_rejected.first(),
        r.aiding_rejected,
        r.modes,
        r.nav_starts.iter().map(|p| p.t_s).collect::<Vec<_>>()
    );
    assert_eq!(d.reinitializations, 1);
    // 19 held samples, right after the gap (5 ms apart).
    assert_eq!(r.imu_rejected.len(), 19, "{:?}", r.imu_rejected);
    assert_eq!(d.imu_held_at_time_jump, 19);
    assert!(
        r.imu_rejected
            .iter()
            .all(|t| *t > gap_end && *t < gap_end + 0.1)
    );
    let h = nav.health()[SensorId::Imu as usize];
    assert_eq!(h.rejected_invalid, 19);
    // Mode sequence: aligning, navigating, aligning again (the re-initialisation), navigating.
    let aligning = NavMode::Aligning as u32;
    let realign = r
        .modes
        .iter()
        .find(|(t, m)| *t > gap_end && *m == aligning)
        .expect("back to aligning after the gap");
    assert!(
        realign.0 < gap_end + 0.11,
        "re-initialised at {}",
        realign.0
    );
    assert_eq!(r.nav_starts.len(), 2, "two alignments");
    let (first, second) = (&r.nav_starts[0], &r.nav_starts[1]);
    assert!(
        (first.t_s - 100.0).abs() < 0.1,
        "first alignment ends {}",
        first.t_s
    );
    let want = realign.0 + cfg.alignment_s;
    assert!(
        (second.t_s - want).abs() < 0.1,
        "re-alignment ends {} (want {want})",
        second.t_s
    );

    let (s_level, s_head) = alignment_sigmas(&cfg, 55.655);
    for p in [first, second] {
        let (level, head) = level_heading_error(p);
        println!(
            "alignment end {:.1} s: level {:.5}° (3σ {:.5}°), heading {:.4}° (3σ {:.4}°)",
            p.t_s,
            level.to_degrees(),
            3.0 * s_level.to_degrees(),
            head.to_degrees(),
            3.0 * s_head.to_degrees()
        );
        // Level: two axes, the norm of two N(0, σ²) is below 3.44σ at 99.7 %.
        assert!(level < 3.44 * s_level, "level {level} rad at {}", p.t_s);
        assert!(head < 3.0 * s_head, "heading {head} rad at {}", p.t_s);
    }

    let (h1, a1, n1) = rms(&r.points, 120.0, 195.0);
    let (h2, a2, n2) = rms(&r.points, 3995.0, 4070.0);
    println!(
        "drive 1: horizontal RMS {h1:.3} m, attitude RMS {:.5}° ({n1} points); drive 2 after \
         the gap: {h2:.3} m, {:.5}° ({n2} points)",
        a1.to_degrees(),
        a2.to_degrees()
    );
    assert!(n1 > 3000 && n2 > 3000);
    assert!(
        h2 < 2.0 * h1,
        "horizontal RMS {h2} m after the gap vs {h1} m"
    );
    assert!(
        a2 < 2.0 * a1,
        "attitude RMS {a2} rad after the gap vs {a1} rad"
    );
}

/// A single wild IMU time stamp (2 h ahead), and one going back 10 s, in the default vehicle
/// run: both rejected and counted, no re-initialisation, the next sample on the old time base
/// navigates on. The lost samples are bridged by the following one (a 10 ms step instead of
/// 5 ms), so the solution stays at the clean run's level: its horizontal and attitude RMS over
/// the drive within 5 % of the run without the wild stamps (one lost 5 ms increment during a
/// drive changes the velocity by at most |Δf|·dt ≈ 1 m/s² · 5 ms = 5 mm/s, which the next GNSS
/// epoch corrects).
#[test]
fn single_wild_time_stamp_is_rejected_and_navigation_goes_on() {
    let segments = format!(
        r#"
    {{ type = "hold", duration_s = 120.0 }},{DRIVE}
    {{ type = "hold", duration_s = 5.0 }},
"#
    );
    let scn = vehicle_with(&segments, 200.0);
    let cfg = default_config();
    let mut clean = Navigator::new(cfg.clone()).expect("config");
    let rc = run(&scn, &mut clean, |_, _| Edit::Keep);
    assert!(rc.imu_rejected.is_empty());

    let mut nav = Navigator::new(cfg).expect("config");
    let r = run(&scn, &mut nav, |t, s| {
        let k = (t * 200.0).round() as i64;
        match k {
            30_001 => Edit::Retime(s.header.time_ns + 7_200_000_000_000),
            32_001 => Edit::Retime(s.header.time_ns - 10_000_000_000),
            _ => Edit::Keep,
        }
    });
    println!(
        "rejected at {:?}, modes {:?}",
        r.imu_rejected,
        r.modes.iter().map(|m| m.1).collect::<Vec<_>>()
    );
    assert_eq!(r.imu_rejected.len(), 2, "{:?}", r.imu_rejected);
    assert_eq!(nav.diagnostics().reinitializations, 0);
    assert_eq!(nav.health()[SensorId::Imu as usize].rejected_invalid, 2);
    // The wild stamp ahead was held as a candidate time base; the one behind is a plain
    // backward step.
    assert_eq!(nav.diagnostics().imu_held_at_time_jump, 1);
    assert_eq!(r.nav_starts.len(), 1, "navigates on, no new alignment");
    assert_eq!(r.aiding_rejected, 0);
    let (hc, ac, _) = rms(&rc.points, 120.0, 195.0);
    let (hw, aw, _) = rms(&r.points, 120.0, 195.0);
    println!(
        "clean: horizontal RMS {hc:.4} m, attitude {:.5}°; wild stamps: {hw:.4} m, {:.5}°",
        ac.to_degrees(),
        aw.to_degrees()
    );
    assert!((hw / hc - 1.0).abs() < 0.05, "{hw} vs {hc}");
    assert!((aw / ac - 1.0).abs() < 0.05, "{aw} vs {ac}");
}

/// A bridged gap: 0.5 s of IMU samples lost while the vehicle starts driving (120.0–120.5 s,
/// the speed-up from rest) and 0.5 s in the middle of the turn. No sample is rejected and
/// there is no re-initialisation; the stretched step's error is covered by the covariance
/// added for the unknown motion (`bridge_imu_gap`): right after each gap the velocity NEES
/// (3 dof) is below the χ²₃ 99.9 % point, 16.27.
///
/// Size of what is covered: the speed profile's acceleration rises from 0 at the start
/// of the speed-up, so the stretched step (the acceleration at the end of the gap, held over
/// 0.5 s) overstates the velocity change by up to |Δf|·g/2; the added velocity second moment
/// is (|Δf|·g)²/3. Without it the filter's velocity σ (≈ 1 cm/s) would put that error at
/// tens of σ. And the stretched sample's own white noise, scaled by g/dt = 100, is 1.4 mm/s
/// per axis (VRW 20 µg/√Hz): found by this test once the 1 mm/s non-holonomic constraint
/// made the lateral velocity σ smaller than that (NEES 31.8 before it was added).
#[test]
fn bridged_gap_keeps_the_covariance_honest() {
    let segments = format!(
        r#"
    {{ type = "hold", duration_s = 120.0 }},{DRIVE}
    {{ type = "hold", duration_s = 5.0 }},
"#
    );
    let scn = vehicle_with(&segments, 200.0);
    let mut nav = Navigator::new(default_config()).expect("config");
    let gaps = [(120.0, 120.5), (160.0, 160.5)];
    let r = run(&scn, &mut nav, |t, _| {
        if gaps.iter().any(|(a, b)| t > *a + 1e-6 && t < *b - 1e-6) {
            Edit::Drop
        } else {
            Edit::Keep
        }
    });
    assert!(r.imu_rejected.is_empty(), "{:?}", r.imu_rejected);
    assert_eq!(nav.diagnostics().reinitializations, 0);
    for (_, end) in gaps {
        let p = r
            .points
            .iter()
            .find(|p| p.t_s >= end - 1e-6)
            .expect("a point after the gap");
        let nees_v = p.nees()[1];
        println!(
            "after the gap ending {end} s: velocity error {:.4} m/s, σ {:?} m/s, NEES {nees_v:.2}",
            p.vel_err_e_m_s.norm(),
            p.vel_sigma_ned_m_s()
        );
        assert!(
            nees_v < 16.27,
            "velocity NEES {nees_v} after the gap at {end} s"
        );
    }
    let (h, a, _) = rms(&r.points, 120.0, 195.0);
    println!(
        "drive with two bridged gaps: horizontal RMS {h:.3} m, attitude {:.5}°",
        a.to_degrees()
    );
}

/// The IMU time base steps back 600 s for good at 150 s (a clock reset): every sample from
/// then on is "not increasing" against the old base. The first 19 are held, the 20th
/// re-initialises (otherwise the IMU would be lost forever); the vehicle is driving, so the
/// new static alignment cannot finish and the navigator stays aligning — honest, as nothing
/// is known about the attitude.
#[test]
fn clock_reset_backward_reinitialises() {
    let segments = format!(
        r#"
    {{ type = "hold", duration_s = 120.0 }},{DRIVE}
    {{ type = "hold", duration_s = 5.0 }},
"#
    );
    let scn = vehicle_with(&segments, 170.0);
    let mut nav = Navigator::new(default_config()).expect("config");
    let r = run(&scn, &mut nav, |t, s| {
        if t > 150.0 {
            Edit::Retime(s.header.time_ns - 600_000_000_000)
        } else {
            Edit::Keep
        }
    });
    assert_eq!(nav.diagnostics().reinitializations, 1);
    assert_eq!(r.imu_rejected.len(), 19, "{:?}", r.imu_rejected);
    assert!(r.imu_rejected.iter().all(|t| *t > 150.0 && *t < 150.1));
    // Held, but as backward steps (`TimeNotIncreasing`), not after a forward jump.
    assert_eq!(nav.diagnostics().imu_held_at_time_jump, 0);
    assert_eq!(nav.mode(), NavMode::Aligning as u32);
    assert!(!nav.is_navigating());
    let h = nav.health()[SensorId::Imu as usize];
    assert_eq!(h.rejected_invalid, 19);
    // Every later sample was accepted by the new alignment.
    assert_eq!(h.fused + h.rejected_invalid, h.received);
}
