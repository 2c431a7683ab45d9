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
use std::time::Duration;

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
    run_at(tag, SPEED, extra)
}

fn run_at(tag: &str, speed: f64, extra: &[&str]) -> (std::path::PathBuf, String, Child) {
    let out = tempdir(&format!("stall-{tag}"));
    let prefix = format!("sextant_stall_{tag}_{}", std::process::id());
    let scenario = driving_scenario(&out).display().to_string();
    let speed = speed.to_string();
    let duration = DURATION_S.to_string();
    // Every solution recorded: holes and stale flags are checked at each IMU sample.
    let config = every_solution_config(&out).display().to_string();
    let mut args = vec![
        "--config",
        &config,
        "--scenario",
        &scenario,
        "--duration",
        &duration,
        "--speed",
        &speed,
    ];
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
fn check_staleness(rec: &Recording, speed: f64) -> (u64, u64) {
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
        let offset = (mono - mono0) as f64 * 1e-9 - (t - t0) as f64 * 1e-9 / speed;
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

/// The end of a run of one daemon life: every late solution flagged and the flags counted in
/// the summary, navigation at the end within 3σ, the recording replayed bit for bit.
fn stale_flagged_navigating_and_replayed(s: &serde_json::Value, rec: &Recording, out: &Path) {
    let (flagged, late) = check_staleness(rec, SPEED);
    println!("solutions flagged stale: {flagged} (late by the recomputation: {late})");
    assert_eq!(s["solutions_stale"], flagged, "{s}");
    navigates_at_the_end(rec);
    replays_bit_exactly(&out.join("recording.mcap"), &out.join("replay"));
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
    let _g = MACHINE.shared();
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
    let s = summary_json(&out);
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

    stale_flagged_navigating_and_replayed(&s, &rec, &out);
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn stopped_fusion_daemon_publishes_nothing_stale_as_fresh_counts_losses_and_replays_bit_exactly() {
    let _g = MACHINE.shared();
    let (out, prefix, mut child) = run("fusion", &[]);
    std::thread::sleep(Duration::from_secs_f64(START_DELAY_S + 2.0));
    let fusion = pid_of(&prefix, "sextant-fusion").expect("fusion running");
    // 1.5 s of wall time (30 s simulated, 6000 IMU samples: more than the subscriber's
    // buffer holds), shorter than the 5 s heartbeat timeout: the daemon is not killed.
    stop_for(fusion, Duration::from_millis(1500));
    let st = wait_exit(&mut child, "sextant run", Duration::from_secs(60));
    let log = log_text(&out);
    assert!(st.success(), "sextant run: {st}\n{log}");
    let s = summary_json(&out);
    assert_eq!(s["fusion_restarts"], 0, "{s}");
    assert_eq!(s["hung_processes_killed"]["sextant-fusion"], 0, "{s}");

    let rec = read_recording(&out.join("recording.mcap")).unwrap();
    let lost = lost_in_sequence(&rec, "imu");
    println!("IMU samples lost in transport while the fusion was stopped: {lost}");
    assert!(lost > 0, "a 30 s backlog exceeds the subscriber's buffer");
    assert_eq!(s["sequence_gaps_per_channel"]["imu"], lost, "{s}");
    stale_flagged_navigating_and_replayed(&s, &rec, &out);
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn hung_driver_is_killed_restarted_and_its_lost_samples_counted() {
    let _g = MACHINE.shared();
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
    let s = summary_json(&out);
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

#[test]
fn fusion_stopped_for_ten_seconds_is_killed_resumes_warm_and_every_loss_is_counted() {
    let _g = MACHINE.shared();
    // At 5× the 85 s drive lasts 17 s of wall time; the 10 s stop (50 s simulated) begins
    // 10 s into the drive. The default 5 s heartbeat timeout kills the stopped daemon; the
    // supervisor restarts it and it resumes from its checkpoint (written every
    // `fusion.checkpoint_interval_s`, so at most one interval plus the 5 s old at the kill,
    // within `warm_start.max_age_s` = 60 s).
    let speed = 5.0;
    let (out, prefix, mut child) = run_at("fusion10", speed, &[]);
    std::thread::sleep(Duration::from_secs_f64(START_DELAY_S + 2.0));
    let fusion = pid_of(&prefix, "sextant-fusion").expect("fusion running");
    kill(Pid::from_raw(fusion), Signal::SIGSTOP).unwrap();
    std::thread::sleep(Duration::from_secs(10));
    // Killed by then: SIGCONT finds no such process (or a reused pid's owner ignores it
    // being ours to continue only if it is still the stopped daemon).
    let _ = kill(Pid::from_raw(fusion), Signal::SIGCONT);
    let st = wait_exit(&mut child, "sextant run", Duration::from_secs(60));
    let log = log_text(&out);
    assert!(st.success(), "sextant run: {st}\n{log}");
    assert!(log.contains("sextant-fusion sent no heartbeat"), "{log}");
    assert!(
        log.contains("warm restart: sensor-error estimates resumed"),
        "{log}"
    );
    let s = summary_json(&out);
    assert_eq!(s["hung_processes_killed"]["sextant-fusion"], 1, "{s}");
    assert_eq!(s["fusion_restarts"], 1, "{s}");

    let first = read_cut_recording(&out.join("recording.mcap")).unwrap();
    assert!(
        first.cut.is_some(),
        "the killed daemon's recording has no end"
    );
    let second = read_recording(&out.join("recording.1.mcap")).unwrap();
    // Every IMU sample the drivers numbered is recorded in one of the two lives or counted
    // lost: inside a recording (gaps) or between them (sent while no daemon listened).
    let seq = |rec: &Recording| -> Vec<i64> {
        rec.topic("imu")
            .map(|r| int(&r.json, "/header/seq").unwrap())
            .collect()
    };
    let (a, b) = (seq(&first), seq(&second));
    let between = b[0] - a.last().unwrap() - 1;
    let lost = b.last().unwrap() - (a.len() + b.len()) as i64;
    println!(
        "IMU samples lost: {lost} ({between} while no daemon listened), recorded {} + {}",
        a.len(),
        b.len()
    );
    // Nothing listened from the stop until the restarted daemon subscribed. The supervisor
    // kills a child silent for more than the 5 s timeout, counted from its last ping, and
    // children ping every half timeout: the kill comes 2.5–5 s (plus a check interval) after
    // the stop, the restart 0.5 s later. So at least 2.5 s of wall time were lost and at most
    // the whole 10 s stop (the restarted daemon listens before the SIGCONT).
    let per_wall_s = IMU_HZ * speed;
    assert!(
        (2.5 * per_wall_s..=10.0 * per_wall_s).contains(&(lost as f64)),
        "lost {lost} over a 10 s stop"
    );
    let losses = &s["run_losses"];
    assert_eq!(losses["samples_lost_per_channel"]["imu"], lost, "{s}");
    assert_eq!(
        losses["samples_lost_between_recordings"]["imu"], between,
        "{s}"
    );
    // Nothing late published as fresh, in either life; every flag counted.
    let (f1, _) = check_staleness(&first, speed);
    let (f2, _) = check_staleness(&second, speed);
    println!("solutions flagged stale: {f1} before the kill, {f2} after the restart");
    assert_eq!(losses["solutions_stale"], f1 + f2, "{s}");
    // Navigation continued after the restart, and ends within 3σ.
    navigates_at_the_end(&second);
    // Both recordings replay bit for bit: the first up to where the kill cut it, the second
    // from the checkpoint it started from (embedded in its metadata).
    replays_bit_exactly(&out.join("recording.mcap"), &out.join("replay.0"));
    replays_bit_exactly(&out.join("recording.1.mcap"), &out.join("replay.1"));
    let _ = std::fs::remove_dir_all(&out);
}
