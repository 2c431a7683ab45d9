//! End-to-end hybrid run on real urban-canyon data, live: the shipped smartLoc slice (Berlin
//! Potsdamer Platz, 60 s) imported by `sextant import smartloc`, its real GPS pseudoranges and
//! odometer played by `sextant replay --live --only gnss,odometer --follow-bus` into a running
//! `sextant run --config config/hybrid_berlin.toml`, whose simulated tactical IMU follows the
//! drive's NovAtel reference and whose simulated GNSS, odometer and baro drivers are not
//! started; the filter couples the pseudoranges tightly.
//!
//! Checks, on the recording read back by an independent reader:
//! * every real sample reached the fusion daemon: 298 GNSS epochs (the slice's distinct
//!   `pseudorange3` times, as the import wrote them) and 297 odometer samples, none late or
//!   invalid; the navigator started in motion from the start fix the import put on the first
//!   epoch, its first solution that of the first IMU sample after the fix arrived, then updated with every later epoch and judged every
//!   odometer sample (fused or rejected by its χ² gate), but for the last of each, which may
//!   arrive after the IMU's last sample;
//! * the horizontal error against the NovAtel reference points (the shipped points file, not
//!   the spline the IMU flies), after 10 s, has a 95th percentile below that of the epoch-by-epoch
//!   least-squares fixes of the same pseudoranges (carried in the imported samples). The bound
//!   is the offline experiment's test's: between two pseudorange epochs (0.2–0.3 s) the IMU and
//!   odometer carry the position to centimetres, so the filter's estimate weighs many epochs'
//!   pseudoranges while a fix has one epoch's, and the canyon's reflection errors change within
//!   metres of travel (seconds at the car's 5–9 m/s), so the 50 s hold tens of independent
//!   epochs, whose weighted mean spreads less than each; the χ² gate keeps the large reflected
//!   ranges out of the mean.

use fusion::earth::{self, WGS84};
use nalgebra::Vector3;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use sextant_tests::*;
use std::process::{Command, Stdio};
use std::time::Duration;

/// Simulated time per wall time (the 59.9 s slice in 12 s of wall time).
const SPEED: f64 = 5.0;
/// Statistics start, s after the first epoch (as in the offline experiment).
const CONVERGE_S: f64 = 10.0;

#[test]
fn real_pseudoranges_and_odometer_played_live_into_a_simulated_imu() {
    let _g = MACHINE.shared();
    let root = repo_root();
    let dir = tempdir("hybrid-berlin-live");
    let data = root.join("tests/data/smartloc-berlin");
    let rec = dir.join("berlin.mcap");
    let sextant = bin("sextant").unwrap();
    let imported = Command::new(&sextant)
        .args(["import", "smartloc"])
        .arg(data.join("Berlin_Potsdamer_Platz_Input_150-210s.txt.gz"))
        .arg("--reference")
        .arg(data.join("Berlin_Potsdamer_Platz_GT_150-210s.txt.gz"))
        .arg("--out")
        .arg(&rec)
        .output()
        .unwrap();
    assert!(
        imported.status.success(),
        "import: {}",
        String::from_utf8_lossy(&imported.stderr)
    );

    let prefix = format!("sextant_berlin_{}", std::process::id());
    let out = dir.join("out");
    std::fs::create_dir_all(&out).unwrap();
    let mut run = start_run(
        &out,
        &prefix,
        &[
            "--config",
            "config/hybrid_berlin.toml",
            "--speed",
            &SPEED.to_string(),
        ],
    )
    .unwrap();
    // `sextant run` refuses a prefix that live processes already use: let it claim it first.
    wait_for_run_to_claim(&prefix, Duration::from_secs(30));
    let replay = Command::new(&sextant)
        .args(["replay", "--live"])
        .arg(&rec)
        .args(["--only", "gnss,odometer", "--follow-bus", "--speed"])
        .arg(SPEED.to_string())
        .args(["--prefix", &prefix])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let status = wait_exit(&mut run, "sextant run", Duration::from_secs(120));
    // The replay ends with its last sample (59.9 s); stop it in case it still waits.
    let _ = kill(Pid::from_raw(replay.id() as i32), Signal::SIGTERM);
    let replay_out = replay.wait_with_output().unwrap();
    let log = std::fs::read_to_string(out.join("sextant.log")).unwrap_or_default();
    assert!(status.success(), "sextant run failed: {status}\n{log}");
    let summary: serde_json::Value = serde_json::from_slice(&replay_out.stdout)
        .unwrap_or_else(|e| panic!("replay summary: {e}: {:?}", replay_out.stdout));
    assert_eq!(summary["skipped_before_bus"], 0, "{summary}");
    assert_eq!(summary["sent_per_channel"]["gnss"], 298, "{summary}");
    assert_eq!(summary["sent_per_channel"]["odometer"], 297, "{summary}");

    let imported = read_recording(&rec).unwrap();
    let r = read_recording(&out.join("recording.mcap")).unwrap();
    // Every real sample was received and recorded: the import's counts.
    assert_eq!(imported.count("gnss"), 298);
    assert_eq!(imported.count("odometer"), 297);
    assert_eq!(r.count("gnss"), 298, "{log}");
    assert_eq!(r.count("odometer"), 297, "{log}");
    let st = r.topic("status").last().expect("a status").json.clone();
    let sensor = |i: usize, k: &str| int(&st, &format!("/sensors/{i}/{k}")).unwrap();
    let (gnss, odo) = (2, 3);
    for i in [gnss, odo] {
        assert_eq!(sensor(i, "dropped_late"), 0, "{st}");
        assert_eq!(sensor(i, "rejected_invalid"), 0, "{st}");
    }
    assert_eq!(sensor(gnss, "received"), 298, "{st}");
    // The first epoch starts the navigation (alignment in motion); every later one is fused
    // (the gate rejects single pseudoranges of an epoch, never all of them here) except that
    // the last (59.9 s) stays pending when it arrives after the IMU's last sample, also of
    // 59.9 s: a sample is taken at the first IMU epoch at or after its time.
    let fused = sensor(gnss, "fused");
    assert!((296..=297).contains(&fused), "GNSS fused {fused}: {st}");
    assert!(sensor(gnss, "rejected_gate") > 0, "{st}");
    assert_eq!(sensor(odo, "received"), 297, "{st}");
    // Every odometer sample is judged (fused or gated), the last one possibly pending.
    let judged = sensor(odo, "fused") + sensor(odo, "rejected_gate");
    assert!(
        (296..=297).contains(&judged),
        "odometer judged {judged}: {st}"
    );

    // Time base: the first real epoch is the scenario's t = 0.
    let epoch_ns = r
        .topic("gnss")
        .map(|g| int(&g.json, "/header/time_ns").unwrap())
        .min()
        .unwrap();
    let nav: Vec<(i64, Vector3<f64>)> = r
        .topic("nav")
        .map(|n| {
            let p = [0, 1, 2].map(|i| num(&n.json, &format!("/pos_ecef_m/{i}")).unwrap());
            (int(&n.json, "/header/time_ns").unwrap(), Vector3::from(p))
        })
        .collect();
    // Navigation starts in motion when the start fix arrives: its first solution is that of
    // the first IMU sample the daemon took after the fix (the recording holds the inputs in the
    // order they were pushed). How late the fix arrives after the IMU has passed its epoch is
    // the live replay's reaction to the bus time on this machine, a few IMU steps at most.
    let first_gnss = r
        .records
        .iter()
        .position(|m| m.topic == "gnss")
        .expect("a GNSS record");
    let imu_after_fix = r.records[first_gnss..]
        .iter()
        .find(|m| m.topic == "imu")
        .map(|m| int(&m.json, "/header/time_ns").unwrap())
        .expect("an IMU sample after the start fix");
    let first_nav = nav.first().map(|n| n.0);
    eprintln!(
        "first epoch {epoch_ns}, first IMU after the fix +{} ns, first solution {:?}",
        imu_after_fix - epoch_ns,
        first_nav.map(|t| t - epoch_ns)
    );
    assert_eq!(
        first_nav,
        Some(imu_after_fix),
        "navigation starts at {:?} ns after the first epoch, the first IMU sample after the \
         start fix at {} ns",
        first_nav.map(|t| t - epoch_ns),
        imu_after_fix - epoch_ns
    );
    assert!(
        imu_after_fix - epoch_ns <= 500_000_000,
        "the start fix arrived {} ns after its epoch",
        imu_after_fix - epoch_ns
    );
    // The NovAtel reference points (times from the first epoch, ms grid).
    let points =
        std::fs::read_to_string(data.join("Berlin_Potsdamer_Platz_GT_150-210s_points.txt"))
            .unwrap();
    let reference: Vec<(i64, Vector3<f64>)> = points
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|w| w.parse().unwrap()).collect();
            (
                epoch_ns + (v[0] * 1e3).round() as i64 * 1_000_000,
                Vector3::new(v[1], v[2], v[3]),
            )
        })
        .collect();
    let converged = |t: i64| t - epoch_ns >= (CONVERGE_S * 1e9) as i64;
    let mut filter: Vec<f64> = reference
        .iter()
        .filter(|(t, _)| converged(*t))
        .filter_map(|(t, r)| {
            let i = nav.binary_search_by_key(t, |n| n.0).ok()?;
            Some(horizontal_m(&nav[i].1, r))
        })
        .collect();
    let mut fixes: Vec<f64> = imported
        .topic("gnss")
        .filter(|g| num(&g.json, "/fix_valid") == Some(1.0))
        .filter_map(|g| {
            let t = int(&g.json, "/header/time_ns").unwrap();
            let r = reference.iter().find(|x| x.0 == t)?.1;
            let p = [0, 1, 2].map(|i| num(&g.json, &format!("/pos_ecef_m/{i}")).unwrap());
            converged(t).then(|| horizontal_m(&Vector3::from(p), &r))
        })
        .collect();
    // 50 s of the reference at 0.2/0.3 s; the fixes at the same epochs.
    assert!(filter.len() > 190, "{} compared epochs", filter.len());
    assert!(fixes.len() > 190, "{} compared fixes", fixes.len());
    let (f95, w95) = (p95(&mut filter), p95(&mut fixes));
    eprintln!(
        "live: horizontal p50 {:.2} m, p95 {f95:.2} m, max {:.2} m over {} epochs; \
         least-squares fixes p95 {w95:.2} m",
        filter[filter.len() / 2],
        filter.last().unwrap(),
        filter.len()
    );
    assert!(
        f95 < w95,
        "filter p95 {f95:.2} m, least-squares fixes p95 {w95:.2} m"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Sorts `v` and returns its nearest-rank 95th percentile.
fn p95(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((0.95 * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1]
}

/// Horizontal distance of `p` from `reference` (in the local level at the reference), m.
fn horizontal_m(p: &Vector3<f64>, reference: &Vector3<f64>) -> f64 {
    let g = earth::ecef_to_geodetic(&WGS84, reference);
    let ned = earth::c_e_n(g.lat_rad, g.lon_rad).transpose() * (p - reference);
    ned.x.hypot(ned.y)
}
