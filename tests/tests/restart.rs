//! End-to-end warm restart: `sextant run` of a vehicle that drives from the first second, the
//! fusion daemon SIGKILLed while it drives; the supervisor restarts it and navigation resumes
//! within 2 s of wall time of the kill, with the error inside the reported 3σ:
//! - (a) from the checkpoint the daemon wrote (`navigator.checkpoint` in the output
//!   directory): the restarted daemon resumes the sensor-error estimates and takes position,
//!   velocity and attitude from the alignment in motion;
//! - (b) with the checkpoint deleted before the kill (the daemon stopped with SIGSTOP first, so
//!   that it cannot write a new one): from the alignment in motion with stars alone.
//!
//! The figures (wall time from the kill to the first solution of the restarted daemon, from
//! its first IMU sample to its first solution, and the error over σ) are printed.

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use sextant_tests::*;
use std::path::Path;
use std::process::Child;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// The e2e tests share the machine's two cores; run them one at a time.
static SERIAL: Mutex<()> = Mutex::new(());

/// `run.start_delay_s` of config/sextant.toml: wall time from launch to the first sample.
const START_DELAY_S: f64 = 2.0;
/// Speed-up of the runs.
const SPEED: f64 = 20.0;
/// Simulated duration of the runs, s.
const DURATION_S: f64 = 70.0;
/// Wall time after the first sample at which the fusion is killed (30 s simulated, driving).
const KILL_AFTER_S: f64 = 1.5;
/// Required wall time from the kill to the first solution of the restarted daemon, s.
const RESUME_WALL_S: f64 = 2.0;

fn wait_for(child: &mut Child, timeout: Duration) -> std::process::ExitStatus {
    let t0 = Instant::now();
    loop {
        if let Some(st) = child.try_wait().unwrap() {
            return st;
        }
        if t0.elapsed() > timeout {
            let _ = child.kill();
            panic!("process overran {timeout:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn log_text(out: &Path) -> String {
    let mut s = std::fs::read_to_string(out.join("sextant.log")).unwrap_or_default();
    s += &std::fs::read_to_string(out.join("logs/sextant-fusion.log")).unwrap_or_default();
    s
}

struct Figures {
    kill_to_solution_s: f64,
    first_imu_to_solution_s: f64,
    max_ratio_first_5s: f64,
}

/// Kill the fusion while the vehicle drives (after deleting its checkpoint when
/// `delete_checkpoint`), let the run finish, and check the restarted daemon's recording.
fn kill_and_check(tag: &str, delete_checkpoint: bool) -> Figures {
    let out = tempdir(tag);
    let prefix = format!("sextant_restart_{tag}_{}", std::process::id());
    let scenario = driving_scenario(&out);
    let mut child = start_run(
        &out,
        &prefix,
        &[
            "--scenario",
            &scenario.display().to_string(),
            "--duration",
            &DURATION_S.to_string(),
            "--speed",
            &SPEED.to_string(),
        ],
    )
    .expect("start sextant run");
    std::thread::sleep(Duration::from_secs_f64(START_DELAY_S + KILL_AFTER_S));
    let checkpoint = out.join("navigator.checkpoint");
    assert!(
        checkpoint.is_file(),
        "no checkpoint written after {} s of driving\n{}",
        KILL_AFTER_S * SPEED,
        log_text(&out)
    );
    let pid = pid_of(&prefix, "sextant-fusion").expect("fusion running");
    if delete_checkpoint {
        kill(Pid::from_raw(pid), Signal::SIGSTOP).unwrap();
        std::fs::remove_file(&checkpoint).unwrap();
    }
    let kill_mono = msgs::monotonic_ns();
    kill(Pid::from_raw(pid), Signal::SIGKILL).unwrap();
    let st = wait_for(&mut child, Duration::from_secs(60));
    let log = log_text(&out);
    assert!(st.success(), "sextant run: {st}\n{log}");
    if delete_checkpoint {
        // Once at the first start, once at the restart.
        assert_eq!(log.matches("no checkpoint at").count(), 2, "{log}");
        assert!(!log.contains("warm restart:"), "{log}");
    } else {
        assert!(
            log.contains("warm restart: sensor-error estimates resumed"),
            "{log}"
        );
    }

    let rec = read_recording(&out.join("recording.1.mcap")).expect("recording.1.mcap");
    assert!(rec.invalid.is_empty(), "{:?}", &rec.invalid[..1]);
    let first_nav = rec
        .topic("nav")
        .next()
        .expect("the restarted fusion navigated");
    let first_imu = rec.topic("imu").next().expect("IMU after the restart");
    let t_first = int(&first_nav.json, "/header/time_ns").unwrap();
    let nav_mono = int(&first_nav.json, "/header/send_mono_ns").unwrap() as u64;
    let kill_to_solution_s = (nav_mono - kill_mono) as f64 * 1e-9;
    let first_imu_to_solution_s =
        (nav_mono as f64 - int(&first_imu.json, "/header/send_mono_ns").unwrap() as f64) * 1e-9;

    // Errors against the truth recorded alongside (50 Hz, on the IMU grid).
    let truth: std::collections::BTreeMap<i64, &serde_json::Value> = rec
        .topic("truth")
        .map(|r| (int(&r.json, "/header/time_ns").unwrap(), &r.json))
        .collect();
    let mut first_checked = false;
    let mut max_ratio_first_5s = 0.0f64;
    for r in rec.topic("nav") {
        let t = int(&r.json, "/header/time_ns").unwrap();
        if t > t_first + 5_000_000_000 {
            break;
        }
        let Some(tr) = truth.get(&t) else { continue };
        let (e, s) = ned_position_error(&r.json, tr);
        let ratio = (0..3).map(|k| e[k].abs() / s[k]).fold(0.0, f64::max);
        max_ratio_first_5s = max_ratio_first_5s.max(ratio);
        if !first_checked {
            first_checked = true;
            println!(
                "{tag}: first compared solution {:.2} s after the first: error NED {:.2?} m, σ {:.2?} m",
                (t - t_first) as f64 * 1e-9,
                e,
                s
            );
            // For a consistent filter each axis is within 3σ with probability 0.9973; the
            // three together fail by chance in < 1 % of runs.
            for k in 0..3 {
                assert!(
                    e[k].abs() <= 3.0 * s[k],
                    "{tag}: axis {k} error {:.2} m beyond 3σ = {:.2} m",
                    e[k],
                    3.0 * s[k]
                );
            }
        }
    }
    assert!(first_checked, "no solution matched with the truth");
    let f = Figures {
        kill_to_solution_s,
        first_imu_to_solution_s,
        max_ratio_first_5s,
    };
    println!(
        "{tag}: kill → first solution {:.3} s wall, first IMU → first solution {:.3} s wall, max |error|/σ over the first 5 s {:.2}",
        f.kill_to_solution_s, f.first_imu_to_solution_s, f.max_ratio_first_5s
    );
    assert!(
        f.kill_to_solution_s <= RESUME_WALL_S,
        "{tag}: navigation resumed {:.2} s after the kill",
        f.kill_to_solution_s
    );
    let _ = std::fs::remove_dir_all(&out);
    f
}

#[test]
fn killed_fusion_resumes_from_its_checkpoint_while_driving() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    kill_and_check("ckpt", false);
}

#[test]
fn killed_fusion_without_checkpoint_aligns_in_motion_from_the_stars() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    kill_and_check("nockpt", true);
}
