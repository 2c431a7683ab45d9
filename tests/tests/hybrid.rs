//! End-to-end hybrid run, the hardware-in-the-loop bench's use case: real GNSS (the ESBC
//! station's RINEX hour, imported by `sextant import rinex`) played by `sextant replay --live
//! --only gnss --follow-bus` into a running `sextant run` whose simulated IMU, star tracker,
//! odometer and baro stand still at the station from the data's first epoch and whose
//! simulated GNSS driver is not started (`config/hybrid_esbc.toml`).
//!
//! Checks: the fusion receives and fuses the real epochs (one every 30 s), navigates, and its
//! position stays within the worst real fix of the run's window from the station (the
//! simulated truth is the station's antenna reference point): a static filter's estimate is a
//! positively weighted mean of the fixes plus what the simulated sensors add, which on a static
//! bench is the baro's height (its error is the simulator's, decimetres) and nothing
//! horizontal.

use fusion::earth::{self, WGS84};
use nalgebra::Vector3;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use sextant_tests::*;
use std::process::{Command, Stdio};
use std::time::Duration;

const DURATION_S: f64 = 240.0;
const SPEED: f64 = 20.0;

#[test]
fn real_gnss_played_into_a_simulated_bench_is_fused() {
    let _g = MACHINE.shared();
    let root = repo_root();
    let dir = std::env::temp_dir().join(format!("sextant-hybrid-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let data = root.join("tests/data/rinex-esbc");
    let rec = dir.join("esbc.mcap");
    let sextant = bin("sextant").unwrap();
    let st = Command::new(&sextant)
        .arg("import")
        .arg("rinex")
        .arg(data.join("ESBC00DNK_R_20201770000_01H_30S_MO.rnx.gz"))
        .arg(data.join("ESBC00DNK_R_20201770000_01D_GN.rnx.gz"))
        .arg("--out")
        .arg(&rec)
        .stdout(Stdio::null())
        .status()
        .unwrap();
    assert!(st.success(), "import failed");

    let prefix = format!("sextant_hybrid_{}", std::process::id());
    let out = dir.join("out");
    let mut run = Command::new(&sextant)
        .current_dir(&root)
        .args(["run", "--config", "config/hybrid_esbc.toml"])
        .args([
            "--duration",
            &DURATION_S.to_string(),
            "--speed",
            &SPEED.to_string(),
        ])
        .args(["--prefix", &prefix, "--out"])
        .arg(&out)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    wait_for_run_to_claim(&prefix, Duration::from_secs(30));
    let replay = Command::new(&sextant)
        .args(["replay", "--live"])
        .arg(&rec)
        .args([
            "--only",
            "gnss",
            "--follow-bus",
            "--speed",
            &SPEED.to_string(),
        ])
        .args(["--prefix", &prefix])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let status = wait_exit(&mut run, "sextant run", Duration::from_secs(180));
    // The replay would go on to the end of the hour: stop it as a user would.
    kill(Pid::from_raw(replay.id() as i32), Signal::SIGTERM).expect("SIGTERM");
    let replay_out = replay.wait_with_output().unwrap();
    assert!(status.success(), "sextant run failed: {status}");
    let summary: serde_json::Value = serde_json::from_slice(&replay_out.stdout)
        .unwrap_or_else(|e| panic!("replay summary: {e}: {:?}", replay_out.stdout));
    assert!(summary["followed_bus_time_ns"].is_i64(), "{summary}");
    assert_eq!(
        summary["sent_per_channel"].as_object().unwrap().len(),
        1,
        "{summary}"
    );

    let r = read_recording(&out.join("recording.mcap")).unwrap();
    // Real epochs every 30 s of the run (their times are the receiver's, shifted by its clock
    // bias of under a millisecond): 0, 30, …, 240 s, the first skipped when it precedes the
    // bus's first IMU or star-tracker sample by more than the replay's allowance, which it does not.
    let gnss: Vec<&Record> = r.topic("gnss").collect();
    assert!((8..=9).contains(&gnss.len()), "{} GNSS samples", gnss.len());
    // Every one is a real one: the imported fixes, not a simulator's 1 Hz stream.
    for g in &gnss {
        assert_eq!(num(&g.json, "/fix_valid"), Some(1.0), "{}", g.json);
    }
    let status = r.topic("status").last().expect("a status");
    let fused = num(&status.json, "/sensors/2/fused").expect("GNSS health");
    assert!(fused >= 4.0, "GNSS fused {fused}: {}", status.json);

    // The worst real fix of the window, from the station's antenna reference point.
    let reference = esbc_reference();
    let worst_fix_m = gnss
        .iter()
        .map(|g| {
            let p = [0, 1, 2].map(|i| num(&g.json, &format!("/pos_ecef_m/{i}")).unwrap());
            horizontal_m(&p, &reference)
        })
        .fold(0.0, f64::max);
    let nav: Vec<&Record> = r.topic("nav").collect();
    assert!(nav.len() > 10_000, "{} solutions", nav.len());
    let last = nav.last().unwrap();
    let p = [0, 1, 2].map(|i| num(&last.json, &format!("/pos_ecef_m/{i}")).unwrap());
    let err = horizontal_m(&p, &reference);
    assert!(
        err <= worst_fix_m + 0.05,
        "final horizontal error {err:.2} m, worst fix {worst_fix_m:.2} m"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The ESBC antenna reference point from the RINEX header: APPROX POSITION XYZ plus the
/// 0.216 m antenna height along the ellipsoid normal, ECEF m.
fn esbc_reference() -> Vector3<f64> {
    let marker = Vector3::new(3582105.2910, 532589.7313, 5232754.8054);
    let g = earth::ecef_to_geodetic(&WGS84, &marker);
    marker + 0.216 * earth::up_e(g.lat_rad, g.lon_rad)
}

/// Horizontal distance of `p` from `reference` (in the local level at the reference), m.
fn horizontal_m(p: &[f64; 3], reference: &Vector3<f64>) -> f64 {
    let g = earth::ecef_to_geodetic(&WGS84, reference);
    let ned = earth::c_e_n(g.lat_rad, g.lon_rad).transpose() * (Vector3::from(*p) - reference);
    ned.x.hypot(ned.y)
}
