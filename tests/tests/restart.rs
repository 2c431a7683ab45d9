//! End-to-end warm restart: `sextant run` of a vehicle that drives from the first second, the
//! fusion daemon SIGKILLed while it drives; the supervisor restarts it and navigation resumes
//! within 2 s of wall time of the kill, with the error inside the reported 3σ:
//! - (a) from the checkpoint the daemon wrote (`navigator.checkpoint` in the output
//!   directory): the restarted daemon resumes the sensor-error estimates and takes position,
//!   velocity and attitude from the alignment in motion;
//! - (b) with the checkpoint deleted before the kill (the daemon stopped with SIGSTOP first, so
//!   that it cannot write a new one): from the alignment in motion with stars alone;
//! - (c) checkpoint deleted and no star tracker in the system (its driver not started): from
//!   the heading the GNSS velocities give once the vehicle turns or changes speed
//!   (`fusion::yaw_gsf`). On a straight road at constant speed the heading is unobservable, so
//!   this start cannot be bounded in wall time; the requirement is a solution within 60 s of
//!   simulated driving after the restart. The drive after the kill (30 s) has a straight at
//!   constant speed (30–40 s), a −60° turn (40–50 s) and a speed-up (50–55 s): the heading
//!   becomes observable in the turn. Besides the position, the attitude error is checked
//!   against the reported attitude σ. This case runs on the car's world with the car's filter,
//!   like the others. The solution carries the attitude σ per NED axis only, while a start in
//!   a turn has its heading and tilt errors correlated (the turn's acceleration ties them), so
//!   the attitude is held to the bounding box of the χ²(3) 99.99 % ellipsoid, ±4.6σ per axis
//!   (a per-axis 3σ test of correlated axes has no stated false-alarm rate). Measured on this
//!   drive and start with 72 seeds (`drivers-sim` ignored test
//!   `starts_without_stars_on_the_cars_world_statistics`): mean attitude NEES 3.42 at the
//!   start (χ² band for 72 runs [2.45, 3.58]); this scenario's seed is the worst start of the
//!   72 (NEES 10.9; north tilt 3.2σ, heading 2.0σ).
//!
//! The figures (wall time from the kill to the first solution of the restarted daemon, from
//! its first IMU sample to its first solution, and the error over σ) are printed.

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use sextant_tests::*;
use std::path::Path;
use std::process::Child;
use std::time::{Duration, Instant};

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
/// Without stars: simulated duration (the whole driving scenario, so that the 60 s bound
/// below is reached before the run ends) and the required simulated time from the restarted
/// daemon's first IMU sample to its first solution, s.
const DURATION_NO_STARS_S: f64 = 90.0;
const RESUME_NO_STARS_SIM_S: f64 = 60.0;

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

/// The repository's system configuration without the star-tracker driver, written into `dir`
/// (the filter file by its absolute path).
fn system_without_star_tracker(dir: &Path) -> std::path::PathBuf {
    let root = repo_root();
    let text = std::fs::read_to_string(root.join("config/sextant.toml")).unwrap();
    let filter = root.join("config/filter.toml");
    let edited = text
        .replace("    \"sextant-sim-star-tracker\",\n", "")
        .replace(
            "filter = \"filter.toml\"",
            &format!("filter = {:?}", filter.display().to_string()),
        );
    assert!(
        !edited.contains("sextant-sim-star-tracker") && edited.contains(&*filter.to_string_lossy()),
        "config/sextant.toml changed its layout"
    );
    let path = dir.join("sextant-no-stars.toml");
    std::fs::write(&path, edited).unwrap();
    path
}

/// Attitude error of a solution against the truth, as the rotation vector δ (NED, rad) with
/// `C_true = exp([δ×]) C_nav`, and the reported attitude σ (NED, rad).
fn ned_attitude_error(nav: &serde_json::Value, truth: &serde_json::Value) -> ([f64; 3], [f64; 3]) {
    let q = |v: &serde_json::Value| {
        let c = f64s(&v["q_ned_body"]);
        nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(c[0], c[1], c[2], c[3]))
    };
    let d = (q(truth) * q(nav).inverse()).scaled_axis();
    let s = f64s(&nav["att_sigma_ned_rad"]);
    ([d.x, d.y, d.z], [s[0], s[1], s[2]])
}

/// Kill the fusion while the vehicle drives (after deleting its checkpoint when
/// `delete_checkpoint`), let the run finish, and check the restarted daemon's recording;
/// `stars` false: the system runs without the star-tracker driver.
fn kill_and_check(tag: &str, delete_checkpoint: bool, stars: bool) -> Figures {
    let out = tempdir(tag);
    let prefix = format!("sextant_restart_{tag}_{}", std::process::id());
    let scenario = driving_scenario(&out);
    let duration_s = if stars {
        DURATION_S
    } else {
        DURATION_NO_STARS_S
    };
    let mut args = vec![
        "--scenario".to_string(),
        scenario.display().to_string(),
        "--duration".to_string(),
        duration_s.to_string(),
        "--speed".to_string(),
        SPEED.to_string(),
    ];
    if !stars {
        args.push("--config".to_string());
        args.push(system_without_star_tracker(&out).display().to_string());
    }
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let mut child = start_run(&out, &prefix, &args).expect("start sextant run");
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
    // The restarted daemon's status says how it started: warm from the checkpoint, or aligned
    // in motion (with the heading from GNSS velocity when there are no stars).
    let status = &rec.topic("status").last().expect("status").json;
    let counter = |name: &str| int(status, &format!("/{name}")).unwrap();
    assert_eq!(
        counter("warm_starts"),
        i64::from(!delete_checkpoint),
        "{status}"
    );
    assert_eq!(counter("motion_alignments"), 1, "{status}");
    assert_eq!(
        counter("gnss_heading_alignments"),
        i64::from(!stars),
        "{status}"
    );
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
    let first_imu_to_solution_sim_s =
        (t_first - int(&first_imu.json, "/header/time_ns").unwrap()) as f64 * 1e-9;
    println!("{tag}: first IMU → first solution {first_imu_to_solution_sim_s:.2} s simulated");

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
            if !stars {
                // The attitude from the GNSS heading: within the bounding box of the χ²(3)
                // 99.99 % ellipsoid (see the module comment).
                let box_sigmas = fusion::ekf::chi2::chi2_quantile(3, 0.9999).sqrt();
                let (d, sa) = ned_attitude_error(&r.json, tr);
                println!(
                    "{tag}: attitude error NED {:.3?}°, σ {:.3?}°",
                    d.map(f64::to_degrees),
                    sa.map(f64::to_degrees)
                );
                for k in 0..3 {
                    assert!(
                        d[k].abs() <= box_sigmas * sa[k],
                        "{tag}: attitude axis {k} error {:.3}° beyond {box_sigmas:.2}σ = {:.3}°",
                        d[k].to_degrees(),
                        box_sigmas * sa[k].to_degrees()
                    );
                }
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
    if stars {
        assert!(
            f.kill_to_solution_s <= RESUME_WALL_S,
            "{tag}: navigation resumed {:.2} s after the kill",
            f.kill_to_solution_s
        );
    } else {
        assert!(
            first_imu_to_solution_sim_s <= RESUME_NO_STARS_SIM_S,
            "{tag}: navigation resumed {first_imu_to_solution_sim_s:.2} s of driving after the restart"
        );
    }
    let _ = std::fs::remove_dir_all(&out);
    f
}

#[test]
fn killed_fusion_resumes_from_its_checkpoint_while_driving() {
    let _g = MACHINE.exclusive();
    kill_and_check("ckpt", false, true);
}

#[test]
fn killed_fusion_without_checkpoint_aligns_in_motion_from_the_stars() {
    let _g = MACHINE.exclusive();
    kill_and_check("nockpt", true, true);
}

#[test]
fn killed_fusion_without_checkpoint_or_stars_aligns_from_the_gnss_heading() {
    let _g = MACHINE.exclusive();
    kill_and_check("nostars", true, false);
}
