//! End-to-end: the real `sextant-fusion` with an output it cannot write — a path under a
//! regular file (unwritable even for root), the full device `/dev/full`, and a file-size limit
//! hit in the middle of the run (RLIMIT_FSIZE, the same EFBIG/ENOSPC path as a disk filling up)
//! — fed by the real simulated drivers. In each case the fusion logs a clear error naming the
//! path, keeps navigating and publishing, and counts the lost records in the status
//! (`records_dropped`, `recorder_errors`).

use msgs::ipc::Bus;
use msgs::{NavSolution, Status};
use sextant_tests::*;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// The e2e tests share the machine's two cores; run them one at a time.
static SERIAL: Mutex<()> = Mutex::new(());

const SPEED: f64 = 25.0;
/// Alignment takes 100 s simulated; 12 s of navigation after it = 2 400 solutions at 200 Hz.
const DURATION_S: f64 = 112.0;
const NAV_S: f64 = DURATION_S - 100.0;

const DRIVERS: [&str; 6] = [
    "sextant-sim-imu",
    "sextant-sim-star-tracker",
    "sextant-sim-gnss",
    "sextant-sim-odometer",
    "sextant-sim-baro",
    "sextant-sim-truth",
];

struct Outcome {
    /// Highest solution sequence number seen on the nav service (= solutions computed).
    nav_seq_max: u64,
    /// Solutions received by the test.
    nav_received: u64,
    last_status: Option<Status>,
    log: String,
    exit_ok: bool,
}

fn tempdir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("sextant-disk-{}-{tag}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Run the fusion with `--out out` and the six drivers; watch nav and status until the fusion
/// has exited. With `fsize_limit`, the fusion runs with SIGXFSZ ignored and, once its shared
/// memory exists, its file-size limit is lowered to that many bytes (`prlimit`), so that the
/// recording's writes fail with EFBIG in the middle of the run like on a filling disk.
fn run_fusion(tag: &str, out: &Path, fsize_limit: Option<u64>) -> Outcome {
    let dir = tempdir(tag);
    let prefix = format!("sextant_disk_{tag}_{}", std::process::id());
    let log_path = dir.join("fusion.log");
    let log = std::fs::File::create(&log_path).unwrap();
    let fusion_bin = bin("sextant-fusion").unwrap();
    let args = format!(
        "--config config/sextant.toml --prefix {prefix} --speed {SPEED} --out {}",
        out.display()
    );
    let mut fusion: Child = match fsize_limit {
        Some(_) => Command::new("sh")
            .arg("-c")
            .arg(format!(
                "trap '' XFSZ; exec {} {args}",
                fusion_bin.display()
            ))
            .current_dir(repo_root())
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .unwrap(),
        None => Command::new(&fusion_bin)
            .args(args.split(' '))
            .current_dir(repo_root())
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .unwrap(),
    };
    let bus = Bus::new(&prefix, "disk-test").unwrap();
    let nav = bus.subscriber::<NavSolution>().unwrap();
    let status = bus.subscriber::<Status>().unwrap();
    std::thread::sleep(Duration::from_millis(300));
    if let Some(limit) = fsize_limit {
        let st = Command::new("prlimit")
            .args([
                "--pid",
                &fusion.id().to_string(),
                &format!("--fsize={limit}"),
            ])
            .status()
            .unwrap();
        assert!(st.success(), "prlimit failed");
    }
    let start = msgs::monotonic_ns() + 1_000_000_000;
    let mut drivers: Vec<Child> = DRIVERS
        .iter()
        .map(|d| {
            Command::new(bin(d).unwrap())
                .current_dir(repo_root())
                .args([
                    "--scenario",
                    "config/scenarios/vehicle.toml",
                    "--prefix",
                    &prefix,
                ])
                .args(["--start-mono-ns", &start.to_string()])
                .args([
                    "--speed",
                    &SPEED.to_string(),
                    "--duration",
                    &DURATION_S.to_string(),
                ])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .unwrap()
        })
        .collect();
    let mut o = Outcome {
        nav_seq_max: 0,
        nav_received: 0,
        last_status: None,
        log: String::new(),
        exit_ok: false,
    };
    let poll = |o: &mut Outcome| {
        while let Ok(Some(n)) = nav.receive() {
            o.nav_received += 1;
            o.nav_seq_max = o.nav_seq_max.max(n.header.seq);
        }
        while let Ok(Some(s)) = status.receive() {
            o.last_status = Some(s);
        }
    };
    let deadline = Instant::now() + Duration::from_secs_f64(DURATION_S / SPEED + 20.0);
    while drivers
        .iter_mut()
        .any(|c| c.try_wait().ok().flatten().is_none())
    {
        assert!(Instant::now() < deadline, "drivers did not finish");
        poll(&mut o);
        std::thread::sleep(Duration::from_millis(2));
    }
    // Let a status or two go out after the last sample, then stop the fusion.
    let t = Instant::now();
    while t.elapsed() < Duration::from_millis(1200) {
        poll(&mut o);
        std::thread::sleep(Duration::from_millis(2));
    }
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(fusion.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
    let t = Instant::now();
    let st = loop {
        poll(&mut o);
        if let Some(st) = fusion.try_wait().unwrap() {
            break st;
        }
        assert!(t.elapsed() < Duration::from_secs(10), "fusion did not stop");
        std::thread::sleep(Duration::from_millis(2));
    };
    poll(&mut o);
    o.exit_ok = st.success();
    o.log = std::fs::read_to_string(&log_path).unwrap_or_default();
    o
}

/// The fusion navigated through the whole run and published what it computed.
fn assert_kept_navigating(o: &Outcome) {
    // 200 Hz over NAV_S of navigation (±2 solutions at the alignment boundary and the end).
    let expected = NAV_S * 200.0;
    assert!(
        (o.nav_seq_max as f64 - expected).abs() <= 3.0,
        "{} solutions computed, expected {expected}\n{}",
        o.nav_seq_max,
        o.log
    );
    assert!(o.nav_received > 0, "no solution received");
    assert!(o.exit_ok, "fusion exit\n{}", o.log);
}

#[test]
fn unwritable_output_path_is_reported_and_navigation_continues() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    // A path below a regular file: ENOTDIR for everyone, root included.
    let bad = Path::new("/etc/hostname/sextant/recording.mcap");
    let o = run_fusion("unwritable", bad, None);
    assert!(
        o.log.contains("/etc/hostname/sextant/recording.mcap"),
        "{}",
        o.log
    );
    assert!(o.log.contains("Not a directory"), "{}", o.log);
    assert_kept_navigating(&o);
    let st = o.last_status.expect("a status");
    // Every input and output record was dropped and counted; one error (the creation).
    assert!(st.records_dropped > o.nav_seq_max, "{st:?}");
    assert_eq!(st.records_written, 0);
    assert_eq!(st.recorder_errors, 1);
}

#[test]
fn full_disk_is_reported_and_navigation_continues() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    if std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/full")
        .is_err()
    {
        eprintln!("skipped: /dev/full not writable here");
        return;
    }
    let o = run_fusion("devfull", Path::new("/dev/full"), None);
    assert!(o.log.contains("/dev/full"), "{}", o.log);
    assert!(o.log.contains("No space left on device"), "{}", o.log);
    assert_kept_navigating(&o);
    let st = o.last_status.expect("a status");
    assert!(st.records_dropped > o.nav_seq_max, "{st:?}");
    assert!(st.recorder_errors >= 1);
}

#[test]
fn disk_filling_up_mid_run_stops_the_recording_and_counts_the_drops() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempdir("fsize-out");
    let rec = dir.join("recording.mcap");
    if Command::new("prlimit").arg("--version").output().is_err() {
        eprintln!("skipped: prlimit (util-linux) not installed");
        return;
    }
    // File-size limit 2 MB: the full recording of this run is about 7 MB (65 kB per simulated
    // second), so the limit is hit during the run.
    const LIMIT: u64 = 2_000_000;
    let o = run_fusion("fsize", &rec, Some(LIMIT));
    assert!(o.log.contains(&rec.display().to_string()), "{}", o.log);
    assert!(o.log.contains("File too large"), "{}", o.log);
    assert_kept_navigating(&o);
    let st = o.last_status.expect("a status");
    assert!(st.records_written > 0, "{st:?}");
    assert!(st.records_dropped > o.nav_seq_max, "{st:?}");
    assert_eq!(st.recorder_errors, 1);
    // What reached the disk before the failure is readable (up to the last complete chunk).
    let bytes = std::fs::read(&rec).unwrap();
    assert!(bytes.len() as u64 <= LIMIT);
    let readable =
        mcap::MessageStream::new_with_options(&bytes, mcap::read::Options::IgnoreEndMagic.into())
            .unwrap()
            .take_while(|m| m.is_ok())
            .count();
    assert!(readable > 100, "{readable} messages readable");
}
