//! End-to-end: `sextant run` starts the real processes (six simulated drivers and the fusion
//! daemon) over iceoryx2, the run ends by itself, and the recording is read back with an
//! independent reader. Checks channels, schemas, message counts against the configured rates,
//! and the solution's accuracy against truth with bounds derived from the sensor errors.

use sextant_tests::*;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

const SCENARIO: &str = "config/scenarios/vehicle.toml";

/// Horizontal and vertical position error of ECEF `r` against truth at (lat, lon, `r_true`), m.
fn ned_error(r: &[f64], r_true: &[f64], lat: f64, lon: f64) -> (f64, f64) {
    ned_error_offset(r, r_true, lat, lon, [0.0; 3])
}

/// As [`ned_error`], against the truth moved by `offset_ned_m` (NED, m): a point a lever arm
/// away from the IMU.
fn ned_error_offset(
    r: &[f64],
    r_true: &[f64],
    lat: f64,
    lon: f64,
    offset_ned_m: [f64; 3],
) -> (f64, f64) {
    let d = [r[0] - r_true[0], r[1] - r_true[1], r[2] - r_true[2]];
    let (sl, cl, so, co) = (lat.sin(), lat.cos(), lon.sin(), lon.cos());
    let n = -sl * co * d[0] - sl * so * d[1] + cl * d[2] - offset_ned_m[0];
    let e = -so * d[0] + co * d[1] - offset_ned_m[1];
    let down = -cl * co * d[0] - cl * so * d[1] - sl * d[2] - offset_ned_m[2];
    ((n * n + e * e).sqrt(), down.abs())
}

/// Rotation angle between two unit quaternions `[w, x, y, z]`, rad.
fn quat_angle(a: &[f64], b: &[f64]) -> f64 {
    let dot: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| x * y)
        .sum::<f64>()
        .abs()
        .min(1.0);
    2.0 * dot.acos()
}

fn rms(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

struct Outage {
    start_s: f64,
    end_s: f64,
}

/// GNSS outage windows of the scenario (seconds since its epoch), read from the scenario file.
fn scenario_outages(path: &Path) -> Vec<Outage> {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let v: toml::Value = toml::from_str(&text).unwrap_or(toml::Value::Integer(0));
    let mut out = Vec::new();
    let find = |v: &toml::Value| -> Option<Vec<toml::Value>> {
        v.get("gnss")?.get("outages")?.as_array().cloned()
    };
    if let Some(arr) = find(&v) {
        for o in arr {
            let s = o
                .get("start_s")
                .and_then(|x| x.as_float().or(x.as_integer().map(|i| i as f64)));
            let e = o
                .get("end_s")
                .and_then(|x| x.as_float().or(x.as_integer().map(|i| i as f64)));
            let d = o
                .get("duration_s")
                .and_then(|x| x.as_float().or(x.as_integer().map(|i| i as f64)));
            match (s, e, d) {
                (Some(s), Some(e), _) => out.push(Outage {
                    start_s: s,
                    end_s: e,
                }),
                (Some(s), None, Some(d)) => out.push(Outage {
                    start_s: s,
                    end_s: s + d,
                }),
                _ => {}
            }
        }
    }
    out
}

/// `sextant run` of the default scenario's 600 s at 20x under `prefix`, into `out`.
fn sextant_run(root: &Path, prefix: &str, out: &Path) -> Command {
    let mut cmd = Command::new(bin("sextant").unwrap());
    cmd.current_dir(root)
        .args([
            "run",
            "--scenario",
            SCENARIO,
            "--duration",
            "600",
            "--speed",
            "20",
        ])
        .args(["--prefix", prefix, "--out"])
        .arg(out);
    cmd
}

#[test]
fn run_records_every_channel_and_navigates_within_sensor_bounds() {
    let _g = MACHINE.exclusive();
    let root = repo_root();
    let out = tempdir("pipeline");
    let prefix = format!("sextant_e2e_{}", std::process::id());
    let shm_before = iceoryx_entries();
    let duration_s = 600.0;
    let speed = 20.0;

    let t0 = Instant::now();
    let status = sextant_run(&root, &prefix, &out)
        .status()
        .expect("start sextant run");
    assert!(status.success(), "sextant run failed: {status}");
    // It ended by itself, in about the scenario's duration at the requested speed.
    assert!(t0.elapsed() < Duration::from_secs_f64(duration_s / speed + 60.0));

    // No process and no shared memory of this run is left behind.
    assert_nothing_left_behind(&prefix, &shm_before);

    // Exactly one recording; every channel is protobuf with its descriptors (the default
    // encoding), every message decodes from them alone and the Foxglove views validate against
    // Foxglove's published schemas.
    let mcaps: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .flatten()
        .filter(|e| e.path().extension().is_some_and(|x| x == "mcap"))
        .collect();
    assert_eq!(mcaps.len(), 1, "expected one MCAP in {}", out.display());
    let rec = read_recording(&mcaps[0].path()).expect("recording readable");
    for topic in [
        "imu",
        "star_tracker",
        "gnss",
        "odometer",
        "baro",
        "truth",
        "nav",
        "status",
    ] {
        let (schema, schema_enc, msg_enc) = rec
            .channels
            .get(topic)
            .unwrap_or_else(|| panic!("no channel {topic}; have {:?}", rec.channels.keys()));
        assert_eq!(schema_enc, "protobuf", "{topic}: {schema}");
        assert_eq!(msg_enc, "protobuf", "{topic}");
        assert_eq!(
            schema,
            &format!("sextant.{}", schema_name_of(topic)),
            "{topic}"
        );
    }
    for (topic, (_, schema_enc, msg_enc)) in rec.channels.iter() {
        assert_eq!(
            (schema_enc.as_str(), msg_enc.as_str()),
            ("protobuf", "protobuf"),
            "{topic}"
        );
    }
    assert!(
        rec.invalid.is_empty(),
        "messages failing their schema: {:?}",
        &rec.invalid[..rec.invalid.len().min(5)]
    );

    // Message counts within the configured rates (drivers send every sample of the scenario;
    // the recording keeps them all unless it reports drops).
    let expect = |topic: &str, hz: f64| {
        let n = rec.count(topic) as f64;
        let want = hz * duration_s;
        assert!(
            (n - want).abs() <= 0.01 * want + 2.0,
            "{topic}: {n} messages, expected {want} at {hz} Hz"
        );
    };
    expect("imu", 200.0);
    expect("star_tracker", 5.0);
    expect("gnss", 1.0);
    expect("odometer", 20.0);
    expect("baro", 20.0);
    let n_status = rec.count("status") as f64;
    assert!(
        n_status >= 0.8 * duration_s / speed,
        "status at 1 Hz wall: {n_status}"
    );

    // Accuracy against truth, matched by time of validity.
    let mut truth = std::collections::BTreeMap::new();
    for r in rec.topic("truth") {
        truth.insert(int(&r.json, "/header/time_ns").unwrap(), r.json.clone());
    }
    let t_start = *truth.keys().next().expect("truth recorded");
    let outages = scenario_outages(&root.join(SCENARIO));
    assert!(
        !outages.is_empty(),
        "the default vehicle scenario has a GNSS outage"
    );
    let in_window = |t: f64, a: f64, b: f64| t >= a && t < b;

    // The GNSS fix noise, measured from the recording itself: each fix against the true
    // position of the world's antenna, a lever arm away from the IMU in the true attitude.
    let lever_arm_b_m = drivers_sim::scenario::Scenario::load(&root.join(SCENARIO))
        .expect("scenario loads")
        .spec
        .world
        .expect("the default scenario has a world")
        .lever_arm_b_m();
    let mut gnss_h = Vec::new();
    for r in rec.topic("gnss") {
        if int(&r.json, "/fix_valid") != Some(1) {
            continue;
        }
        if let Some(tr) = truth.get(&int(&r.json, "/header/time_ns").unwrap()) {
            let q: [f64; 4] = f64s(&tr["q_ned_body"]).try_into().expect("a quaternion");
            let arm_ned_m = fusion::attitude::quat_from_wire(&q) * lever_arm_b_m;
            let (h, _) = ned_error_offset(
                &f64s(&r.json["pos_ecef_m"]),
                &f64s(&tr["pos_ecef_m"]),
                num(tr, "/lat_rad").unwrap(),
                num(tr, "/lon_rad").unwrap(),
                arm_ned_m.into(),
            );
            gnss_h.push(h);
        }
    }
    let gnss_h_rms = rms(&gnss_h);
    assert!(gnss_h.len() > 100 && gnss_h_rms.is_finite());

    // Star-tracker noise: total angle RMS from the σ's it reports (two cross axes + roll).
    let st = rec
        .topic("star_tracker")
        .next()
        .expect("star tracker recorded");
    let (sc, sr) = (
        num(&st.json, "/sigma_cross_rad").unwrap(),
        num(&st.json, "/sigma_roll_rad").unwrap(),
    );
    let star_noise_rad = (2.0 * sc * sc + sr * sr).sqrt();

    let (mut h_aided, mut att_aided, mut h_out, mut h_after) = (vec![], vec![], vec![], vec![]);
    let nav_start_s = 150.0; // alignment (120 s static) plus filter settling
    for r in rec.topic("nav") {
        let t_ns = int(&r.json, "/header/time_ns").unwrap();
        let Some(tr) = truth.get(&t_ns) else { continue };
        let t = (t_ns - t_start) as f64 * 1e-9;
        let (h, _v) = ned_error(
            &f64s(&r.json["pos_ecef_m"]),
            &f64s(&tr["pos_ecef_m"]),
            num(tr, "/lat_rad").unwrap(),
            num(tr, "/lon_rad").unwrap(),
        );
        let att = quat_angle(&f64s(&r.json["q_ned_body"]), &f64s(&tr["q_ned_body"]));
        let during = outages.iter().any(|o| in_window(t, o.start_s, o.end_s));
        let after = outages
            .iter()
            .any(|o| in_window(t, o.end_s + 30.0, o.end_s + 90.0));
        let recovering = outages
            .iter()
            .any(|o| in_window(t, o.end_s, o.end_s + 30.0));
        if t < nav_start_s {
            continue;
        }
        if during {
            h_out.push((t, h));
        } else if after {
            h_after.push(h);
        }
        if !during && !recovering {
            h_aided.push(h);
            att_aided.push(att);
        }
    }
    let h_rms = rms(&h_aided);
    let att_rms = rms(&att_aided);
    println!(
        "horizontal RMS {h_rms:.3} m (GNSS fix {gnss_h_rms:.3} m), attitude RMS {:.2}\" (star tracker {:.2}\")",
        att_rms.to_degrees() * 3600.0,
        star_noise_rad.to_degrees() * 3600.0
    );
    // The receiver's errors are white code noise plus slow errors (ionosphere, orbit,
    // multipath). Started from the mean of the static window's fixes and fusing them with the
    // IMU, the filter averages the white part away; the slow part it cannot see. So its error
    // stays below the fixes' own.
    assert!(
        h_rms < gnss_h_rms,
        "horizontal RMS {h_rms} m not below GNSS fix noise {gnss_h_rms} m"
    );
    assert!(
        att_rms < 3.0 * star_noise_rad,
        "attitude RMS {att_rms} rad vs star tracker {star_noise_rad} rad"
    );

    // During the outage the error grows as inertial physics allows: starting from the aided
    // error, with the navigation-grade accelerometer bias (50 µg) and the star-held tilt
    // (g·σ_cross) as the worst constant acceleration error, plus a velocity error of 3× the
    // GNSS velocity noise (0.05 m/s) at the start:  e(T) ≤ 3·e0 + 3·σv·T + ½·a·T².
    let g = 9.81;
    let a_err = 50e-6 * g + g * 3.0 * sc;
    for o in &outages {
        let e0 = 3.0 * gnss_h_rms;
        for &(t, h) in &h_out {
            if t < o.start_s || t >= o.end_s {
                continue;
            }
            let dt = t - o.start_s;
            let bound = e0 + 3.0 * 0.05 * dt + 0.5 * a_err * dt * dt;
            assert!(
                h <= bound,
                "outage error {h} m at +{dt} s exceeds inertial bound {bound} m"
            );
        }
    }
    let h_after_rms = rms(&h_after);
    assert!(
        h_after_rms < gnss_h_rms,
        "no recovery after the outage: {h_after_rms} m"
    );

    // The summary has the figures under self-explaining names.
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    for key in [
        "horizontal_error_rms_m",
        "gnss_fix_horizontal_error_rms_m",
        "attitude_error_rms_deg",
        "latency_p50_us",
        "latency_p99_us",
    ] {
        assert!(
            summary.get(key).and_then(|v| v.as_f64()).is_some(),
            "summary.json lacks {key}: {summary}"
        );
    }
}

#[test]
fn ctrl_c_leaves_no_process_no_shared_memory_and_a_readable_recording() {
    let _g = MACHINE.exclusive();
    let root = repo_root();
    let out = tempdir("sigint");
    let prefix = format!("sextant_sigint_{}", std::process::id());
    let shm_before = iceoryx_entries();
    let mut child = sextant_run(&root, &prefix, &out)
        .spawn()
        .expect("start sextant run");
    // 12 s of wall time at 20× is 240 s of scenario: past the 100 s alignment, mid-drive.
    std::thread::sleep(Duration::from_secs(12));
    assert!(
        processes_matching(&prefix).len() >= 7,
        "expected >= 7 processes of the run, found {:?}",
        processes_matching(&prefix)
    );
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(child.id() as i32),
        nix::sys::signal::Signal::SIGINT,
    )
    .unwrap();
    let status = wait_exit(
        &mut child,
        "sextant run stopping on SIGINT",
        Duration::from_secs(30),
    );
    assert!(
        status.success() || status.code() == Some(130),
        "exit status {status}"
    );
    std::thread::sleep(Duration::from_millis(300));
    assert_nothing_left_behind(&prefix, &shm_before);
    let rec = read_recording(&out.join("recording.mcap")).expect("recording readable after Ctrl-C");
    assert!(rec.count("imu") > 100, "imu messages: {}", rec.count("imu"));
    assert!(rec.count("nav") > 10);
    assert!(rec.invalid.is_empty());
}

/// The message type recorded on a Sextant channel (`imu` → `ImuSample`).
fn schema_name_of(topic: &str) -> &'static str {
    match topic {
        "imu" => "ImuSample",
        "star_tracker" => "StarTrackerSample",
        "gnss" => "GnssSample",
        "odometer" => "OdometerSample",
        "baro" => "BaroSample",
        "truth" => "TruthSample",
        "nav" => "NavSolution",
        "status" => "Status",
        other => panic!("no Sextant channel {other}"),
    }
}
