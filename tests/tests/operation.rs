//! End-to-end: `sextant run` against what a user does to it, with the real processes.
//!
//! - A second run on a prefix in use is refused and names the processes using it; the first
//!   run is untouched. An existing output directory is kept: an explicit `--out` holding a run
//!   is refused, the default gets a new name. A prefix that cannot name the services is
//!   refused before anything starts.
//! - A failed log write is never fatal: every process with its stderr on a full device keeps
//!   running and ends normally.
//! - A short stall of a driver (SIGSTOP, as a loaded machine deschedules it) is no deadline
//!   miss at the configured speed-up; a long one is.
//! - `report` refuses an empty or foreign MCAP with a clear error and a non-zero exit.
//!
//! The full-disk behaviour (recording resumes, summary from the fusion's own counters, exit
//! status) is in `tests/tests/disk.rs`.

use msgs::ipc::Bus;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use sextant_tests::*;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// `sextant run` of the vehicle scenario: `duration` s at `speed`, in `cwd`, with `args`.
fn sextant_run(cwd: &Path, duration: f64, speed: f64, args: &[&str]) -> Command {
    let root = repo_root();
    let mut c = Command::new(bin("sextant").unwrap());
    c.current_dir(cwd)
        .arg("run")
        .arg("--config")
        .arg(root.join("config/sextant.toml"))
        .arg("--scenario")
        .arg(root.join("config/scenarios/vehicle.toml"))
        .args(["--duration", &duration.to_string()])
        .args(["--speed", &speed.to_string()])
        .args(args)
        .stdin(Stdio::null());
    c
}

/// Run to the end (at most `timeout`), output captured.
fn output_within(c: &mut Command, timeout: Duration) -> Output {
    let mut child = c
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t0.elapsed() > timeout {
            let _ = child.kill();
            panic!("overran {timeout:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

fn wait_for_pid(prefix: &str, program: &str) -> i32 {
    let t0 = Instant::now();
    loop {
        if let Some(p) = pid_of(prefix, program) {
            return p;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "{program} not started"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn one_bus_per_prefix_and_an_earlier_run_is_never_overwritten() {
    let _g = MACHINE.shared();
    let dir = tempdir("prefix");
    let prefix = format!("sextant_op_prefix_{}", std::process::id());
    // An earlier run in the default output directory (out/run of the configuration).
    let old = dir.join("out/run");
    std::fs::create_dir_all(&old).unwrap();
    std::fs::write(old.join("recording.mcap"), b"an earlier recording").unwrap();

    // A prefix that cannot name the services: refused at once, nothing started.
    let long = "p".repeat(300);
    let t0 = Instant::now();
    let o = output_within(
        &mut sextant_run(&dir, 110.0, 25.0, &["--prefix", &long]),
        Duration::from_secs(30),
    );
    assert!(!o.status.success());
    assert!(text(&o).contains("at most 242"), "{}", text(&o));
    assert!(t0.elapsed() < Duration::from_secs(10), "{:?}", t0.elapsed());
    assert!(processes_matching(&long).is_empty());

    // Run A, default output: out/run holds a run, so A writes to out/run-2.
    let mut a = sextant_run(&dir, 110.0, 25.0, &["--prefix", &prefix])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let fusion_a = wait_for_pid(&prefix, "sextant-fusion");
    // Wait until A's fusion is on the bus.
    let t0 = Instant::now();
    while sextant_daemons_live(&prefix) == 0 {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "run A not on the bus"
        );
        std::thread::sleep(Duration::from_millis(50));
    }

    // Run B on the same prefix: refused, naming A's processes; it leaves no recording.
    let b_out = dir.join("b");
    let o = output_within(
        sextant_run(&dir, 110.0, 25.0, &["--prefix", &prefix, "--out"]).arg(&b_out),
        Duration::from_secs(30),
    );
    let t = text(&o);
    assert!(!o.status.success(), "{t}");
    assert!(t.contains(&prefix) && t.contains("in use"), "{t}");
    assert!(
        t.contains(&format!("pid {fusion_a}")) || t.contains("another sextant run"),
        "{t}"
    );
    assert!(!b_out.join("recording.mcap").exists());

    // Run C on another prefix into A's directory: refused while A writes it.
    let a_out = dir.join("out/run-2");
    let o = output_within(
        sextant_run(
            &dir,
            110.0,
            25.0,
            &["--prefix", &format!("{prefix}_c"), "--out"],
        )
        .arg(&a_out),
        Duration::from_secs(30),
    );
    assert!(!o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("is kept"), "{}", text(&o));

    // A is unaffected: it completes, navigates, and its recording is complete.
    let st = wait_exit(&mut a, "sextant run", Duration::from_secs(60));
    assert!(st.success(), "run A: {st}");
    let s = summary_json(&a_out);
    assert_eq!(s["recording_complete"], true, "{s}");
    assert_eq!(s["records_dropped"], 0, "{s}");
    // 10 s of navigation: 2 000 solutions at 200 Hz, 100 recorded at 10 Hz.
    assert!(s["solutions_computed"].as_u64().unwrap() > 1000, "{s}");
    let rec = read_recording(&a_out.join("recording.mcap")).unwrap();
    assert!(
        rec.count("nav") > 50,
        "{} solutions recorded",
        rec.count("nav")
    );
    // The earlier run is untouched.
    assert_eq!(
        std::fs::read(old.join("recording.mcap")).unwrap(),
        b"an earlier recording"
    );

    // Re-running into A's directory explicitly: refused, A's recording kept as it was.
    let before = std::fs::read(a_out.join("recording.mcap")).unwrap();
    let o = output_within(
        sextant_run(&dir, 110.0, 25.0, &["--prefix", &prefix, "--out"]).arg(&a_out),
        Duration::from_secs(30),
    );
    assert!(!o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("earlier run"), "{}", text(&o));
    assert_eq!(std::fs::read(a_out.join("recording.mcap")).unwrap(), before);
}

/// Live nodes on the prefix's services, as `sextant run` sees them.
fn sextant_daemons_live(prefix: &str) -> usize {
    sextant_daemons::bus_check::live_nodes_on(prefix)
        .map(|v| v.len())
        .unwrap_or(0)
}

#[test]
fn a_failed_log_write_is_never_fatal() {
    let _g = MACHINE.shared();
    let full = || {
        std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/full")
            .expect("/dev/full (a device that is always full) must be writable")
    };
    let dir = tempdir("log");
    let prefix = format!("sextant_op_log_{}", std::process::id());
    let rec = dir.join("recording.mcap");
    // Every process logs to a full device: the fusion and a driver (whose log lines at start
    // and end fail), both must run and end normally.
    let mut fusion = Command::new(bin("sextant-fusion").unwrap())
        .current_dir(repo_root())
        .args(["--config", "config/sextant.toml", "--prefix", &prefix])
        .args(["--speed", "25", "--out"])
        .arg(&rec)
        .stdout(Stdio::piped())
        .stderr(full())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let start = msgs::monotonic_ns() + 500_000_000;
    let driver = Command::new(bin("sextant-sim-imu").unwrap())
        .current_dir(repo_root())
        .args(["--scenario", "config/scenarios/vehicle.toml"])
        .args(["--prefix", &prefix, "--start-mono-ns", &start.to_string()])
        .args(["--speed", "25", "--duration", "10"])
        .stdout(Stdio::null())
        .stderr(full())
        .status()
        .unwrap();
    assert!(driver.success(), "driver: {driver}");
    std::thread::sleep(Duration::from_millis(1500));
    assert!(
        fusion.try_wait().unwrap().is_none(),
        "the fusion died with its log on a full device"
    );
    kill(Pid::from_raw(fusion.id() as i32), Signal::SIGTERM).unwrap();
    let o = {
        let t0 = Instant::now();
        while fusion.try_wait().unwrap().is_none() {
            assert!(
                t0.elapsed() < Duration::from_secs(20),
                "fusion did not stop"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        fusion.wait_with_output().unwrap()
    };
    assert!(o.status.success(), "fusion: {}", o.status);
    // Its exit report counts the lost log lines and the IMU samples it received.
    let stdout = String::from_utf8_lossy(&o.stdout);
    let report = stdout
        .lines()
        .find_map(sextant_daemons::exit_report::ExitReport::parse)
        .unwrap_or_else(|| panic!("no exit report in {stdout:?}"));
    assert!(report.log_lines_lost > 0, "{report:?}");
    assert_eq!(report.imu_received, 2000, "{report:?}");
    assert!(report.recording_complete(), "{report:?}");
    let r = read_recording(&rec).unwrap();
    assert_eq!(r.count("imu"), 2000);
}

#[test]
fn a_short_driver_stall_is_no_deadline_miss_at_the_configured_speed_up() {
    let _g = MACHINE.exclusive();
    let dir = tempdir("stall");
    let prefix = format!("sextant_op_stall_{}", std::process::id());
    let out = dir.join("run");
    // The configured speed-up (10x), 40 s of scenario: 4 s of wall time.
    let mut run = sextant_run(&dir, 40.0, 10.0, &["--prefix", &prefix, "--out"])
        .arg(&out)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let imu = wait_for_pid(&prefix, "sextant-sim-imu");
    let baro = wait_for_pid(&prefix, "sextant-sim-baro");
    let bus = Bus::new(&prefix, "stall-test").unwrap();
    let status = bus.subscriber::<msgs::Status>().unwrap();
    // Wait for the samples to flow (the IMU alive on the status).
    let t0 = Instant::now();
    loop {
        let mut alive = false;
        while let Ok(Some(s)) = status.receive() {
            alive = s.alive_mask & 1 != 0;
        }
        if alive {
            break;
        }
        assert!(t0.elapsed() < Duration::from_secs(20), "IMU never alive");
        std::thread::sleep(Duration::from_millis(20));
    }
    let stall = |pid: i32, d: Duration| {
        kill(Pid::from_raw(pid), Signal::SIGSTOP).unwrap();
        std::thread::sleep(d);
        kill(Pid::from_raw(pid), Signal::SIGCONT).unwrap();
    };
    // Three stalls of 120 ms of the IMU driver (a loaded machine's scheduling, 1.2 s of
    // scenario at 10x): not deaths.
    for _ in 0..3 {
        stall(imu, Duration::from_millis(120));
        std::thread::sleep(Duration::from_millis(300));
    }
    // The barometer stopped for 1.5 s: a real silence, beyond every deadline.
    stall(baro, Duration::from_millis(1500));
    let st = wait_exit(&mut run, "sextant run", Duration::from_secs(60));
    assert!(st.success(), "sextant run: {st}");
    let rec = read_recording(&out.join("recording.mcap")).unwrap();
    let events: Vec<(i64, bool)> = rec
        .topic("fusion/sensor_alive")
        .map(|r| {
            (
                int(&r.json, "/sensor").unwrap(),
                r.json["alive"].as_bool().unwrap(),
            )
        })
        .collect();
    let imu_id = msgs::SensorId::Imu as i64;
    let baro_id = msgs::SensorId::Baro as i64;
    // The IMU: alive once, never dead.
    assert_eq!(
        events.iter().filter(|e| e.0 == imu_id).collect::<Vec<_>>(),
        [&(imu_id, true)],
        "{events:?}"
    );
    // The barometer: alive, dead during its stop, alive again.
    assert_eq!(
        events.iter().filter(|e| e.0 == baro_id).collect::<Vec<_>>(),
        [&(baro_id, true), &(baro_id, false), &(baro_id, true)],
        "{events:?}"
    );
    // No other sensor flapped.
    assert!(
        events.iter().filter(|e| e.0 != baro_id).all(|e| e.1),
        "{events:?}"
    );
}

#[test]
fn report_refuses_an_empty_or_foreign_recording() {
    let dir = tempdir("report");
    // A zero-byte file, a valid MCAP without messages, and another program's MCAP.
    let empty_file = dir.join("empty.mcap");
    std::fs::write(&empty_file, b"").unwrap();
    let no_messages = dir.join("no-messages.mcap");
    {
        let mut w = mcap::Writer::new(std::io::BufWriter::new(
            std::fs::File::create(&no_messages).unwrap(),
        ))
        .unwrap();
        w.finish().unwrap();
    }
    let foreign = dir.join("foreign.mcap");
    {
        let mut w = mcap::Writer::new(std::io::BufWriter::new(
            std::fs::File::create(&foreign).unwrap(),
        ))
        .unwrap();
        let ch = w
            .add_channel(0, "/camera/image", "raw", &Default::default())
            .unwrap();
        for k in 0..3u32 {
            w.write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: ch,
                    sequence: k,
                    log_time: u64::from(k),
                    publish_time: u64::from(k),
                },
                b"pixels",
            )
            .unwrap();
        }
        w.finish().unwrap();
    }
    for (file, want) in [
        (&empty_file, "empty.mcap"),
        (&no_messages, "no Sextant message"),
        (&foreign, "/camera/image"),
    ] {
        let o = Command::new(bin("sextant").unwrap())
            .arg("report")
            .arg(file)
            .arg("--out")
            .arg(dir.join("report"))
            .output()
            .unwrap();
        assert!(!o.status.success(), "{}: {}", file.display(), text(&o));
        assert!(text(&o).contains(want), "{}: {}", file.display(), text(&o));
        assert!(!dir.join("report/REPORT.md").exists());
    }
}

#[test]
fn readme_python_recipe_reads_a_crashed_recording() {
    use sextant_daemons::recorder::{Recorder, RecorderOptions};
    let has_mcap = Command::new("python3")
        .args(["-c", "import mcap.reader, mcap_protobuf.decoder"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !has_mcap {
        eprintln!(
            "NOT RUN: python3 with the `mcap` and `mcap-protobuf-support` packages is not installed here (pip install mcap mcap-protobuf-support)"
        );
        return;
    }
    let dir = tempdir("python");
    let path = dir.join("recording.mcap");
    // A recording of 2 000 solutions in small chunks, then cut at two thirds (a crash, or a
    // copy cut short): no summary, no footer, a torn chunk at the end.
    let rec = Recorder::start(
        &path,
        &RecorderOptions {
            chunk_size_bytes: 16 * 1024,
            ..Default::default()
        },
    )
    .unwrap();
    for k in 1..=2000u64 {
        let mut nav = msgs::NavSolution::default();
        nav.header.seq = k;
        nav.header.time_ns = 1_400_000_000_000_000_000 + k as i64 * 5_000_000;
        nav.q_ned_body = [1.0, 0.0, 0.0, 0.0];
        nav.lat_rad = 0.97;
        rec.record_blocking(msgs::Record::Nav(nav), k);
    }
    rec.finish().unwrap();
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() * 2 / 3]).unwrap();
    // The recipe exactly as the README gives it, on that file.
    let readme = std::fs::read_to_string(repo_root().join("README.md")).unwrap();
    let start = readme
        .find("from mcap.reader import NonSeekingReader")
        .expect("recipe");
    let end = start + readme[start..].find("```").unwrap();
    let recipe: String = readme[start..end]
        .lines()
        .map(|l| l.strip_prefix("  ").unwrap_or(l))
        .collect::<Vec<_>>()
        .join("\n")
        .replace("out/run/recording.mcap", &path.display().to_string());
    let o = Command::new("python3")
        .args(["-c", &recipe])
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{out}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let solutions = out.lines().filter(|l| l.starts_with("14000")).count();
    assert!(solutions > 500, "{solutions} solutions read\n{out}");
    assert!(out.contains("recording ends early"), "{out}");
}

/// The documentation stands alone: every file or folder of the repository that the README and
/// the docs name in backticks exists. A path is one word under one of the repository's
/// top-level folders ending in `/` or in a file name with an extension (`fusion/sensor_alive`
/// is a recording topic); a `*` in the last part must match at least one file.
#[test]
fn every_path_the_documentation_names_exists() {
    let root = repo_root();
    let tops: Vec<String> = std::fs::read_dir(&root)
        .unwrap()
        .flatten()
        .filter(|e| e.path().is_dir())
        .map(|e| format!("{}/", e.file_name().to_string_lossy()))
        .filter(|t| !t.starts_with('.') && t != "target/" && t != "out/")
        .collect();
    let mut missing = Vec::new();
    for doc in [
        "README.md",
        "docs/ARCHITECTURE.md",
        "docs/DATA.md",
        "docs/SPEED.md",
        "CHANGELOG.md",
    ] {
        let text = std::fs::read_to_string(root.join(doc)).unwrap();
        for (k, quoted) in text.split('`').enumerate() {
            // Odd pieces are inside backticks; a path is one word under a top-level folder.
            let path = quoted.trim_end_matches([',', ':']);
            let last = path.rsplit('/').next().unwrap_or_default();
            let is_path = k % 2 == 1
                && !path.contains(char::is_whitespace)
                && tops.iter().any(|t| path.starts_with(t.as_str()))
                && (path.ends_with('/') || last.contains('.'));
            if !is_path {
                continue;
            }
            let found = match last.split_once('*') {
                None => root.join(path).exists(),
                Some((head, tail)) => {
                    let dir = root.join(&path[..path.len() - last.len()]);
                    std::fs::read_dir(dir).is_ok_and(|rd| {
                        rd.flatten().any(|e| {
                            let n = e.file_name().to_string_lossy().to_string();
                            n.starts_with(head) && n.ends_with(tail)
                        })
                    })
                }
            };
            if !found {
                missing.push(format!("{doc}: {quoted}"));
            }
        }
    }
    assert!(missing.is_empty(), "named but absent: {missing:#?}");
}
