//! Stalls, tried with real processes and signals while the vehicle drives:
//! - a driver stopped (SIGSTOP) and resumed drops the samples that fell overdue instead of
//!   flooding the bus, every lost sample is counted as a sequence gap, navigation resumes;
//! - the fusion daemon stopped and resumed catches up on its backlog: what it publishes late is
//!   flagged stale, every sample lost in transport is counted, the recording replays bit for bit;
//! - a driver that hangs (stopped for good) is killed by `sextant run` when its heartbeat
//!   stops, restarted, and the samples missed meanwhile are counted.
//!
//! Staleness is checked as a theorem, not by a tuned margin: the daemon judges a solution's lag
//! behind the fastest delivery it has seen (its running minimum of reception time − time of
//! validity ÷ speed-up, over the IMU samples). The test recomputes that running minimum from
//! the solutions' publication times, which come after the receptions, so its lag can exceed the
//! daemon's only by the minimum's allowed upward drift (100 ppm of the elapsed wall time). A
//! solution whose recomputed lag exceeds the limit by more than that drift must be flagged.

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use sextant_tests::*;
use std::path::Path;
use std::process::Child;
use std::sync::Mutex;
use std::time::Duration;

/// The e2e tests share the machine's two cores; run them one at a time.
static SERIAL: Mutex<()> = Mutex::new(());

/// `run.start_delay_s` of config/sextant.toml: wall time from launch to the first sample.
const START_DELAY_S: f64 = 2.0;
/// Speed-up of the runs.
const SPEED: f64 = 20.0;
/// Simulated duration of the runs, s (the driving scenario of the test library lasts 90 s).
const DURATION_S: f64 = 85.0;
/// IMU rate of the scenario, Hz.
const IMU_HZ: f64 = 200.0;
/// The drivers' allowed lateness at this speed-up, wall s: max(1 s simulated / speed, 0.25 s).
const MAX_LAG_WALL_S: f64 = 0.25;
/// `fusion.stale_after_ms` of config/sextant.toml (simulated), floored at 20 ms of wall time.
const STALE_LIMIT_WALL_S: f64 = 0.020;

fn run(tag: &str, extra: &[&str]) -> (std::path::PathBuf, String, Child) {
    let out = tempdir(&format!("stall-{tag}"));
    let prefix = format!("sextant_stall_{tag}_{}", std::process::id());
    let scenario = driving_scenario(&out).display().to_string();
    let mut args = vec!["--scenario", &scenario, "--duration", "85", "--speed", "20"];
    args.extend_from_slice(extra);
    let child = start_run(&out, &prefix, &args).expect("start sextant run");
    (out, prefix, child)
}

fn stop_for(pid: i32, d: Duration) {
    kill(Pid::from_raw(pid), Signal::SIGSTOP).unwrap();
    std::thread::sleep(d);
    kill(Pid::from_raw(pid), Signal::SIGCONT).unwrap();
}

fn log_text(out: &Path) -> String {
    let mut s = std::fs::read_to_string(out.join("sextant.log")).unwrap_or_default();
    for entry in std::fs::read_dir(out.join("logs")).into_iter().flatten() {
        s += &std::fs::read_to_string(entry.unwrap().path()).unwrap_or_default();
    }
    s
}

fn summary(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
}

/// Sequence numbers of a channel's messages: strictly increasing; returns the samples lost
/// (the holes in the numbering, the first sample being number 1).
fn lost_in_sequence(rec: &Recording, topic: &str) -> u64 {
    let seq: Vec<i64> = rec
        .topic(topic)
        .map(|r| int(&r.json, "/header/seq").unwrap())
        .collect();
    assert!(
        seq.windows(2).all(|w| w[1] > w[0]),
        "{topic}: sequence not increasing"
    );
    (seq.last().copied().unwrap_or(0) - seq.len() as i64) as u64
}

/// Every solution later than the staleness limit (recomputed as the module comment says) is
/// flagged; returns (flagged, recomputed-late) counts.
fn check_staleness(rec: &Recording) -> (u64, u64) {
    let nav: Vec<(i64, u64, i64)> = rec
        .topic("nav")
        .map(|r| {
            (
                int(&r.json, "/header/time_ns").unwrap(),
                int(&r.json, "/header/send_mono_ns").unwrap() as u64,
                int(&r.json, "/stale").unwrap(),
            )
        })
        .collect();
    let (t0, mono0) = (nav[0].0, nav[0].1);
    let mut min_offset = f64::INFINITY;
    let (mut flagged, mut late) = (0, 0);
    for &(t, mono, stale) in &nav {
        let offset = (mono - mono0) as f64 * 1e-9 - (t - t0) as f64 * 1e-9 / SPEED;
        min_offset = min_offset.min(offset);
        let lag = offset - min_offset;
        let drift = 100e-6 * (mono - mono0) as f64 * 1e-9;
        flagged += stale as u64;
        if lag > STALE_LIMIT_WALL_S + drift + 1e-6 {
            late += 1;
            assert_eq!(
                stale, 1,
                "solution at {t} ns published {lag:.3} s late but not flagged stale"
            );
        }
    }
    (flagged, late)
}

/// Replay offline and require every solution bit for bit.
fn replays_bit_exactly(recording: &Path, out: &Path) {
    let replay_out = out.join("replay");
    let st = std::process::Command::new(bin("sextant").unwrap())
        .args(["replay", "--offline"])
        .arg(recording)
        .arg("--out")
        .arg(&replay_out)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let s = summary(&replay_out);
    assert_eq!(s["replay"]["bit_exact"], true, "{s}");
}

/// The solution after the stall: in an aided mode again and, at the last solution matched with
/// the truth, each NED axis within 3σ (probability 0.9973 each for a consistent filter).
fn navigates_at_the_end(rec: &Recording) {
    let truth: std::collections::BTreeMap<i64, &serde_json::Value> = rec
        .topic("truth")
        .map(|r| (int(&r.json, "/header/time_ns").unwrap(), &r.json))
        .collect();
    let last = rec
        .topic("nav")
        .filter(|r| truth.contains_key(&int(&r.json, "/header/time_ns").unwrap()))
        .last()
        .expect("solutions matched with the truth");
    let tr = truth[&int(&last.json, "/header/time_ns").unwrap()];
    let (e, s) = ned_position_error(&last.json, tr);
    for k in 0..3 {
        assert!(
            e[k].abs() <= 3.0 * s[k],
            "axis {k}: error {:.2} m beyond 3σ = {:.2} m",
            e[k],
            3.0 * s[k]
        );
    }
}

#[test]
fn stopped_imu_driver_drops_overdue_samples_counts_them_and_navigation_resumes() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let (out, prefix, mut child) = run("imu", &[]);
    // 40 s simulated (2 s wall) into the drive, stop the IMU driver for 1.5 s of wall time:
    // 30 s of simulated IMU data fall due while it is stopped.
    std::thread::sleep(Duration::from_secs_f64(START_DELAY_S + 2.0));
    let imu = pid_of(&prefix, "sextant-sim-imu").expect("IMU driver running");
    let stop = Duration::from_millis(1500);
    stop_for(imu, stop);
    let st = wait_exit(&mut child, "sextant run", Duration::from_secs(60));
    let log = log_text(&out);
    assert!(st.success(), "sextant run: {st}\n{log}");
    let s = summary(&out);
    assert_eq!(s["hung_processes_killed"]["sextant-sim-imu"], 0, "{s}");
    assert_eq!(s["driver_restarts"]["sextant-sim-imu"], 0, "{s}");
    assert!(log.contains("overdue samples dropped"), "{log}");

    let rec = read_recording(&out.join("recording.mcap")).unwrap();
    // Lost: what fell due more than the allowed lateness before the driver ran again; at most
    // the whole stop. (0.2 s of wall time are allowed for signal delivery and scheduling.)
    let lost = lost_in_sequence(&rec, "imu");
    let per_wall_s = IMU_HZ * SPEED;
    let low = (stop.as_secs_f64() - MAX_LAG_WALL_S - 0.2) * per_wall_s;
    let high = stop.as_secs_f64() * per_wall_s;
    println!("IMU samples lost over a {stop:?} stop: {lost} (expected {low:.0}–{high:.0})");
    assert!((low..=high).contains(&(lost as f64)), "lost {lost}");
    assert_eq!(s["sequence_gaps_per_channel"]["imu"], lost, "{s}");
    // Every sample is either recorded or counted lost.
    let recorded = rec.count("imu") as f64;
    assert!(
        (recorded + lost as f64 - DURATION_S * IMU_HZ).abs() <= 1.0,
        "{recorded} recorded + {lost} lost"
    );

    let (flagged, late) = check_staleness(&rec);
    println!("solutions flagged stale: {flagged} (late by the recomputation: {late})");
    assert_eq!(s["solutions_stale"], flagged, "{s}");
    navigates_at_the_end(&rec);
    replays_bit_exactly(&out.join("recording.mcap"), &out);
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn stopped_fusion_daemon_publishes_nothing_stale_as_fresh_counts_losses_and_replays_bit_exactly() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let (out, prefix, mut child) = run("fusion", &[]);
    std::thread::sleep(Duration::from_secs_f64(START_DELAY_S + 2.0));
    let fusion = pid_of(&prefix, "sextant-fusion").expect("fusion running");
    // 1.5 s of wall time (30 s simulated, 6000 IMU samples: more than the subscriber's
    // buffer holds), shorter than the 5 s heartbeat timeout: the daemon is not killed.
    stop_for(fusion, Duration::from_millis(1500));
    let st = wait_exit(&mut child, "sextant run", Duration::from_secs(60));
    let log = log_text(&out);
    assert!(st.success(), "sextant run: {st}\n{log}");
    let s = summary(&out);
    assert_eq!(s["fusion_restarts"], 0, "{s}");
    assert_eq!(s["hung_processes_killed"]["sextant-fusion"], 0, "{s}");

    let rec = read_recording(&out.join("recording.mcap")).unwrap();
    let lost = lost_in_sequence(&rec, "imu");
    println!("IMU samples lost in transport while the fusion was stopped: {lost}");
    assert!(lost > 0, "a 30 s backlog exceeds the subscriber's buffer");
    assert_eq!(s["sequence_gaps_per_channel"]["imu"], lost, "{s}");
    let (flagged, late) = check_staleness(&rec);
    println!("solutions flagged stale: {flagged} (late by the recomputation: {late})");
    assert_eq!(s["solutions_stale"], flagged, "{s}");
    navigates_at_the_end(&rec);
    replays_bit_exactly(&out.join("recording.mcap"), &out);
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn hung_driver_is_killed_restarted_and_its_lost_samples_counted() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let (out, prefix, mut child) = run("hung", &["--heartbeat-timeout", "1"]);
    std::thread::sleep(Duration::from_secs_f64(START_DELAY_S + 1.0));
    let odo = pid_of(&prefix, "sextant-sim-odometer").expect("odometer driver running");
    // Stopped for good: only the supervisor's SIGKILL ends it.
    kill(Pid::from_raw(odo), Signal::SIGSTOP).unwrap();
    let st = wait_exit(&mut child, "sextant run", Duration::from_secs(60));
    let log = log_text(&out);
    assert!(st.success(), "sextant run: {st}\n{log}");
    assert!(
        log.contains("sextant-sim-odometer sent no heartbeat"),
        "{log}"
    );
    let s = summary(&out);
    assert_eq!(s["hung_processes_killed"]["sextant-sim-odometer"], 1, "{s}");
    assert_eq!(s["driver_restarts"]["sextant-sim-odometer"], 1, "{s}");
    for other in ["sextant-sim-imu", "sextant-sim-gnss", "sextant-fusion"] {
        assert_eq!(s["hung_processes_killed"][other], 0, "{s}");
    }

    let rec = read_recording(&out.join("recording.mcap")).unwrap();
    // Lost, at 20 Hz × 20: from the stop to the kill at least the timeout less the half
    // timeout between pings (0.5 s), then the 0.5 s restart delay and the start-up.
    let lost = lost_in_sequence(&rec, "odometer");
    println!("odometer samples lost while hung and restarting: {lost}");
    assert!(lost as f64 >= (0.5 + 0.5) * 20.0 * SPEED, "lost {lost}");
    assert_eq!(s["sequence_gaps_per_channel"]["odometer"], lost, "{s}");
    // The restarted driver delivered again, and the fusion never stopped publishing.
    let odo_t: Vec<i64> = rec
        .topic("odometer")
        .map(|r| int(&r.json, "/header/time_ns").unwrap())
        .collect();
    let nav_t: Vec<i64> = rec
        .topic("nav")
        .map(|r| int(&r.json, "/header/time_ns").unwrap())
        .collect();
    assert!(
        odo_t.last().unwrap() - nav_t.last().unwrap() > -2_000_000_000,
        "the odometer did not come back"
    );
    assert!(
        nav_t.windows(2).all(|w| w[1] - w[0] <= 10_000_000),
        "a hole in the solutions"
    );
    navigates_at_the_end(&rec);
    let _ = std::fs::remove_dir_all(&out);
}
