//! End-to-end replay: a live run of the real processes (`sextant run`) is recorded, then
//! - `sextant replay --offline` re-runs the fusion over the recorded inputs and must reproduce
//!   every recorded solution bit for bit (read back with the independent `mcap` reader and
//!   compared as f64 bit patterns), while a replay with a changed filter setting must not;
//! - `sextant replay --live` republishes the recorded sensors into a real `sextant-fusion`,
//!   whose solution must stay close to the original (tolerance derived below).

use sextant_tests::*;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// The e2e tests share the machine's two cores; run them one at a time.
static SERIAL: Mutex<()> = Mutex::new(());

/// Alignment takes 100 s of simulated time (config/filter.toml); 20 s of navigation after it
/// gives 4 000 solutions with GNSS, star tracker, odometer and baro updates.
const DURATION_S: f64 = 120.0;
const SPEED: f64 = 25.0;

fn out_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("sextant-replay-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A live recording made by `sextant run` (once per test binary).
fn live_recording() -> PathBuf {
    static REC: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    REC.get_or_init(|| {
        let out = out_dir("live");
        let prefix = format!("sextant_replay_e2e_{}", std::process::id());
        let status = Command::new(bin("sextant").unwrap())
            .current_dir(repo_root())
            .args(["run", "--duration", &DURATION_S.to_string()])
            .args(["--speed", &SPEED.to_string(), "--prefix", &prefix, "--out"])
            .arg(&out)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .unwrap();
        assert!(status.success(), "sextant run failed: {status}");
        out.join("recording.mcap")
    })
    .clone()
}

/// Compare two JSON values bit for bit (numbers as f64 bit patterns), skipping `skip` paths.
fn bit_diff(
    a: &serde_json::Value,
    b: &serde_json::Value,
    path: &str,
    skip: &[&str],
) -> Option<String> {
    use serde_json::Value as V;
    if skip.contains(&path) {
        return None;
    }
    match (a, b) {
        (V::Object(x), V::Object(y)) => {
            if x.len() != y.len() {
                return Some(format!("{path}: different keys"));
            }
            x.iter().find_map(|(k, va)| match y.get(k) {
                Some(vb) => bit_diff(va, vb, &format!("{path}/{k}"), skip),
                None => Some(format!("{path}/{k} missing")),
            })
        }
        (V::Array(x), V::Array(y)) => {
            if x.len() != y.len() {
                return Some(format!("{path}: lengths differ"));
            }
            x.iter()
                .zip(y)
                .enumerate()
                .find_map(|(i, (va, vb))| bit_diff(va, vb, &format!("{path}/{i}"), skip))
        }
        (V::Number(x), V::Number(y)) => {
            let same = match (x.as_u64(), y.as_u64(), x.as_i64(), y.as_i64()) {
                (Some(p), Some(q), _, _) => p == q,
                (_, _, Some(p), Some(q)) => p == q,
                _ => x.as_f64().map(f64::to_bits) == y.as_f64().map(f64::to_bits),
            };
            (!same).then(|| format!("{path}: {x} vs {y}"))
        }
        _ => (a != b).then(|| format!("{path}: {a} vs {b}")),
    }
}

fn navs(rec: &Recording) -> Vec<serde_json::Value> {
    rec.topic("nav").map(|r| r.json.clone()).collect()
}

fn replay_offline(rec: &Path, out: &Path, config: Option<&Path>) -> std::process::Output {
    let mut cmd = Command::new(bin("sextant").unwrap());
    cmd.current_dir(repo_root())
        .args(["replay", "--offline"])
        .arg(rec)
        .arg("--out")
        .arg(out);
    if let Some(c) = config {
        cmd.arg("--config").arg(c);
    }
    cmd.output().unwrap()
}

#[test]
fn offline_replay_reproduces_the_live_solution_bit_for_bit() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let rec = live_recording();
    let out = out_dir("offline");
    let t0 = Instant::now();
    let o = replay_offline(&rec, &out, None);
    let wall = t0.elapsed();
    assert!(
        o.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    let live = read_recording(&rec).unwrap();
    let replayed = read_recording(&out.join("recording.mcap")).unwrap();
    assert!(live.invalid.is_empty() && replayed.invalid.is_empty());
    // The live run navigated for DURATION_S − 100 s at 200 Hz (±1 solution).
    let (a, b) = (navs(&live), navs(&replayed));
    let expected = (DURATION_S - 100.0) * 200.0;
    assert!(
        (a.len() as f64 - expected).abs() <= 2.0,
        "{} solutions",
        a.len()
    );
    assert_eq!(a.len(), b.len());
    // The engine's inputs include the daemon's alive/dead decisions (one per sensor at least).
    assert!(live.count("fusion/sensor_alive") >= 5);
    for (i, (x, y)) in a.iter().zip(&b).enumerate() {
        // send_mono_ns is the wall clock of publication: not an engine output.
        if let Some(d) = bit_diff(x, y, "", &["/header/send_mono_ns"]) {
            panic!("solution {i} differs: {d}");
        }
    }
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["replay"]["bit_exact"], true, "{summary}");
    assert_eq!(
        summary["replay"]["solutions_bit_identical"].as_u64(),
        Some(a.len() as u64)
    );
    eprintln!(
        "offline replay: {} solutions bit-identical, {:.2} s wall (process), {:.0} IMU samples/s in the engine loop",
        a.len(),
        wall.as_secs_f64(),
        summary["replay"]["imu_samples_per_s"]
            .as_f64()
            .unwrap_or(0.0)
    );

    // The comparison can fail: a different filter setting (accelerometer bias sigma ×2)
    // changes the solution, and the replay with --config writes its own recording.
    let filter = std::fs::read_to_string(repo_root().join("config/filter.toml")).unwrap();
    let changed = filter.replacen("accel_bias_ug = 50.0", "accel_bias_ug = 100.0", 1);
    assert_ne!(
        filter, changed,
        "config/filter.toml has no accel_bias_ug = 50.0 line"
    );
    let cfg = out.join("filter-changed.toml");
    std::fs::write(&cfg, changed).unwrap();
    let out2 = out.join("changed");
    let o = replay_offline(&rec, &out2, Some(&cfg));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let c = navs(&read_recording(&out2.join("recording.mcap")).unwrap());
    assert_eq!(c.len(), a.len());
    let differing = a
        .iter()
        .zip(&c)
        .filter(|(x, y)| bit_diff(x, y, "", &["/header/send_mono_ns"]).is_some())
        .count();
    assert!(differing > a.len() / 2, "{differing} of {} differ", a.len());
}

#[test]
fn truncated_recording_replays_up_to_the_cut_and_names_the_offset() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let rec = live_recording();
    let out = out_dir("truncated");
    let bytes = std::fs::read(&rec).unwrap();
    let cut = out.join("cut.mcap");
    // Cut inside the navigation part (the last ~20 % of the file holds the 20 s after alignment).
    let len = bytes.len() * 19 / 20;
    std::fs::write(&cut, &bytes[..len]).unwrap();
    let o = replay_offline(&cut, &out.join("r"), None);
    let stdout = String::from_utf8_lossy(&o.stdout);
    // Everything readable is replayed bit for bit; the table names the truncation offset.
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(stdout.contains("truncated at byte offset"), "{stdout}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("r/summary.json")).unwrap())
            .unwrap();
    let compared = summary["replay"]["solutions_compared"].as_u64().unwrap();
    assert!(compared > 1000, "{summary}");
    assert_eq!(
        summary["replay"]["solutions_bit_identical"].as_u64(),
        Some(compared)
    );
}

/// Horizontal distance between two ECEF positions given as JSON arrays, m.
fn dist(a: &serde_json::Value, b: &serde_json::Value) -> f64 {
    let (p, q) = (f64s(&a["pos_ecef_m"]), f64s(&b["pos_ecef_m"]));
    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
}

#[test]
fn live_replay_drives_a_real_fusion_daemon_like_the_drivers() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let rec = live_recording();
    let out = out_dir("live-replay");
    let prefix = format!("sextant_replay_live_{}", std::process::id());
    let fused = out.join("fusion.mcap");
    let mut fusion = Command::new(bin("sextant-fusion").unwrap())
        .current_dir(repo_root())
        .args(["--config", "config/sextant.toml", "--prefix", &prefix])
        .args(["--speed", &SPEED.to_string(), "--out"])
        .arg(&fused)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let t0 = Instant::now();
    let o = Command::new(bin("sextant").unwrap())
        .current_dir(repo_root())
        .args(["replay", "--live"])
        .arg(&rec)
        .args(["--speed", &SPEED.to_string(), "--prefix", &prefix])
        .output()
        .unwrap();
    let wall = t0.elapsed().as_secs_f64();
    std::thread::sleep(Duration::from_millis(300));
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(fusion.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
    let st = fusion.wait().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(st.success(), "fusion exit {st}");
    // Recorded timing: DURATION_S of simulated time at SPEED, plus the 1 s start delay.
    let expect = DURATION_S / SPEED + 1.0;
    assert!(wall > expect - 0.5 && wall < expect + 5.0, "{wall} s");

    let orig = navs(&read_recording(&rec).unwrap());
    let live = navs(&read_recording(&fused).unwrap());
    let by_time: std::collections::HashMap<i64, &serde_json::Value> = live
        .iter()
        .filter_map(|n| int(n, "/header/time_ns").map(|t| (t, n)))
        .collect();
    let mut worst = 0.0f64;
    let mut worst_ratio = 0.0f64;
    let mut matched = 0;
    let mut worst_t = 0.0;
    let t_first = orig
        .first()
        .and_then(|a| num(a, "/header/time_ns"))
        .unwrap_or(0.0)
        * 1e-9;
    for a in &orig {
        let Some(b) = int(a, "/header/time_ns").and_then(|t| by_time.get(&t)) else {
            continue;
        };
        matched += 1;
        let d = dist(a, b);
        let sig = f64s(&a["pos_sigma_ned_m"]);
        let sigma = (sig[0].powi(2) + sig[1].powi(2) + sig[2].powi(2)).sqrt();
        if d / sigma > worst_ratio {
            worst_t = num(a, "/header/time_ns").unwrap_or(0.0) * 1e-9;
        }
        worst = worst.max(d);
        worst_ratio = worst_ratio.max(d / sigma);
    }
    eprintln!(
        "live replay: {matched} of {} solutions matched by time, largest position difference {worst:.3} m = {worst_ratio:.3} σ ({:.2} s after the first solution)",
        orig.len(),
        worst_t - t_first
    );
    // Same inputs, same filter: only the arrival timing differs (an aiding sample may be
    // fused one IMU step earlier or later, and the alive/dead decisions come from wall-clock
    // deadlines). Both solutions are estimates of the same state from the same measurements,
    // so they may differ by a fraction of the filter's own position uncertainty, never by
    // more than it: |Δr| < 1 σ_pos (3-D). Alignment takes the same 100 s, so ≥ 95 % of the
    // solutions exist in both at identical times of validity.
    assert!(
        matched as f64 >= 0.95 * orig.len() as f64,
        "{matched} of {}",
        orig.len()
    );
    assert!(
        worst_ratio < 1.0,
        "largest difference {worst} m = {worst_ratio} σ"
    );
}
