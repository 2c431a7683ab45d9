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
use std::time::{Duration, Instant};

const SPEED: f64 = 25.0;
/// Alignment takes 100 s simulated; 12 s of navigation after it = 2 400 solutions at 200 Hz.
const DURATION_S: f64 = 112.0;
const NAV_S: f64 = DURATION_S - 100.0;

struct Outcome {
    /// Highest solution sequence number seen on the nav service (= solutions computed).
    nav_seq_max: u64,
    /// Solutions received by the test.
    nav_received: u64,
    last_status: Option<Status>,
    log: String,
    exit_ok: bool,
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
    // Every solution recorded: the limits below are sized for the full data rate.
    let config = every_solution_config(&dir);
    let args = format!(
        "--config {} --prefix {prefix} --speed {SPEED} --out {}",
        config.display(),
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
    let mut drivers: Vec<Child> = drivers_sim::driver::SimDriver::ALL
        .map(drivers_sim::driver::SimDriver::process_name)
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
    let _g = MACHINE.shared();
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
    let _g = MACHINE.shared();
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
    // A device's directory is the system's, shared by every run: no checkpoint goes there
    // (another run would resume from it).
    assert!(
        o.log
            .contains("recording to the device /dev/full: no checkpoint"),
        "{}",
        o.log
    );
    assert_kept_navigating(&o);
    let st = o.last_status.expect("a status");
    assert!(st.records_dropped > o.nav_seq_max, "{st:?}");
    assert!(st.recorder_errors >= 1);
}

#[test]
fn disk_filling_up_mid_run_counts_the_drops_and_resumes_in_a_new_segment() {
    let _g = MACHINE.shared();
    let dir = tempdir("fsize-out");
    let rec = dir.join("recording.mcap");
    if Command::new("prlimit").arg("--version").output().is_err() {
        eprintln!("skipped: prlimit (util-linux) not installed");
        return;
    }
    // File-size limit 1.3 MB, hit during the run: the alignment's first 100 s record ≈ 23 kB
    // per simulated second (chunks of ≈ 25 s, 0.57 MB with their message index), every
    // solution after it ≈ 80 kB/s. The limit is crossed by the chunk that ends ≈ 68 s in; the
    // next segment is tried 1 s of wall time later (25 s simulated: before the solutions start
    // at 100 s) and holds the rest of the 112 s (≈ 1.1 MB). Each segment is a new file, so the
    // recording resumes at once in it (on a full disk: once space returns).
    const LIMIT: u64 = 1_300_000;
    let o = run_fusion("fsize", &rec, Some(LIMIT));
    assert!(o.log.contains(&rec.display().to_string()), "{}", o.log);
    assert!(o.log.contains("File too large"), "{}", o.log);
    assert!(o.log.contains("recording resumed in"), "{}", o.log);
    assert_kept_navigating(&o);
    let st = o.last_status.expect("a status");
    assert!(st.records_written > 0, "{st:?}");
    assert!(st.records_dropped > 0, "{st:?}");
    assert!(st.recorder_errors >= 1, "{st:?}");
    // What reached the disk before the failure is readable (up to the last complete chunk).
    let bytes = std::fs::read(&rec).unwrap();
    assert!(bytes.len() as u64 <= LIMIT);
    let readable =
        mcap::MessageStream::new_with_options(&bytes, mcap::read::Options::IgnoreEndMagic.into())
            .unwrap()
            .take_while(|m| m.is_ok())
            .count();
    assert!(readable > 100, "{readable} messages readable");
    // The next segment holds later solutions.
    let part2 = sextant_daemons::recorder::segment_path(&rec, 2);
    let bytes2 = std::fs::read(&part2).expect("recording.part2.mcap");
    let mut nav2 = 0;
    for m in
        mcap::MessageStream::new_with_options(&bytes2, mcap::read::Options::IgnoreEndMagic.into())
            .unwrap()
            .take_while(|m| m.is_ok())
            .flatten()
    {
        nav2 += usize::from(m.channel.topic == "nav");
    }
    assert!(nav2 > 100, "{nav2} solutions in {}", part2.display());
}

/// How this machine gives a test a small filesystem: a tmpfs in a private mount namespace
/// (`unshare -m` as root, `unshare -Urm` where user namespaces are allowed), or, where mounting
/// is not allowed (a container without the right, a chroot), a file-size limit on the fusion
/// daemon once it has created its shared memory (`prlimit --pid --fsize`: each file it writes,
/// the recording's included, can grow to that size only — a per-file full disk; a limit from
/// the start would refuse the shared memory itself, which the kernel sizes as a file).
#[derive(Debug, Clone, Copy, PartialEq)]
enum SmallFs {
    Tmpfs(&'static [&'static str]),
    FileSizeLimit,
}

fn small_fs(probe: &Path) -> SmallFs {
    for args in [&["-m"][..], &["-Urm"][..]] {
        let ok = Command::new("unshare")
            .args(args)
            .args(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs"])
            .arg(probe)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        if ok {
            return SmallFs::Tmpfs(if args[0] == "-m" { &["-m"] } else { &["-Urm"] });
        }
    }
    eprintln!("mounting a tmpfs is not allowed here: using a file-size limit instead");
    SmallFs::FileSizeLimit
}

/// What a `sextant run` on a small filesystem left.
struct SmallFsRun {
    code: Option<i32>,
    stdout: String,
    stderr: String,
    /// Copy of the run's output directory.
    out: PathBuf,
    /// Largest `records_dropped` seen on the live status.
    live_dropped_max: u64,
}

/// `sextant run` (vehicle, `duration` s at 25x) with its output on a small filesystem: a tmpfs
/// of 16 MiB filled up to `free_bytes`, the filler removed `free_after_s` of wall time after
/// the start (never: `None`); or, without mount rights, every file limited to `free_bytes`
/// (SIGXFSZ ignored by the processes; their writes fail with EFBIG). The output directory is
/// copied out for the checks.
fn run_on_small_fs(
    tag: &str,
    duration: f64,
    free_bytes: u64,
    free_after_s: Option<f64>,
) -> SmallFsRun {
    let dir = tempdir(tag);
    let mnt = dir.join("mnt");
    std::fs::create_dir_all(&mnt).unwrap();
    let copy = dir.join("copy");
    let prefix = format!("sextant_smallfs_{tag}_{}", std::process::id());
    let root = repo_root();
    let run = format!(
        "{} run --config {} --scenario {} --duration {duration} --speed 25 --prefix {prefix} --out {}/run",
        bin("sextant").unwrap().display(),
        // Every solution recorded: the file system's size is for the full data rate.
        every_solution_config(&dir).display(),
        root.join("config/scenarios/vehicle.toml").display(),
        mnt.display(),
    );
    let fs = small_fs(&mnt);
    let script = match fs {
        SmallFs::Tmpfs(_) => {
            let free = match free_after_s {
                Some(t) => format!("( sleep {t}; rm -f {m}/filler ) &", m = mnt.display()),
                None => String::new(),
            };
            format!(
                "set -e; mount -t tmpfs -o size=16m tmpfs {m}; \
                 fallocate -l {fill} {m}/filler; {free} set +e; \
                 {run} > {d}/stdout 2> {d}/stderr; echo $? > {d}/rc; cp -r {m}/run {c}",
                m = mnt.display(),
                fill = 16 * 1024 * 1024 - free_bytes,
                d = dir.display(),
                c = copy.display(),
            )
        }
        SmallFs::FileSizeLimit => format!(
            "trap '' XFSZ; {run} > {d}/stdout 2> {d}/stderr; \
             echo $? > {d}/rc; cp -r {m}/run {c}",
            m = mnt.display(),
            d = dir.display(),
            c = copy.display(),
        ),
    };
    let mut cmd = match fs {
        SmallFs::Tmpfs(args) => {
            let mut c = Command::new("unshare");
            c.args(args).args(["sh", "-c", &script]);
            c
        }
        SmallFs::FileSizeLimit => {
            let mut c = Command::new("sh");
            c.args(["-c", &script]);
            c
        }
    };
    let mut child = cmd.current_dir(&root).spawn().unwrap();
    // Watch the live status (the shared memory is the host's, whatever the mounts), once the
    // run has started: before, the test's node would be a live user of the prefix, and the run
    // would refuse to start.
    let t0 = Instant::now();
    let fusion_pid = loop {
        if let Some((pid, _)) = processes_matching(&prefix)
            .into_iter()
            .find(|(_, c)| c.contains("sextant-fusion"))
        {
            break pid;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "the run did not start"
        );
        assert!(child.try_wait().unwrap().is_none(), "the run ended at once");
        std::thread::sleep(Duration::from_millis(20));
    };
    let prlimit = |fsize: &str| {
        let st = Command::new("prlimit")
            .args([
                "--pid",
                &fusion_pid.to_string(),
                &format!("--fsize={fsize}"),
            ])
            .status()
            .unwrap();
        assert!(st.success(), "prlimit --fsize={fsize} failed");
    };
    let mut lift_at = None;
    if fs == SmallFs::FileSizeLimit {
        // Its services exist once it subscribes; 300 ms is far more than that takes.
        std::thread::sleep(Duration::from_millis(300));
        // The soft limit only: raising it back needs no privilege (the hard one stays).
        prlimit(&format!("{free_bytes}:unlimited"));
        lift_at = free_after_s.map(|t| t0 + Duration::from_secs_f64(t));
    }
    let bus = Bus::new(&prefix, "smallfs-test").unwrap();
    let status = bus.subscriber::<Status>().unwrap();
    let mut live_dropped_max = 0;
    let t0 = Instant::now();
    while child.try_wait().unwrap().is_none() {
        while let Ok(Some(s)) = status.receive() {
            live_dropped_max = live_dropped_max.max(s.records_dropped);
        }
        if lift_at.is_some_and(|t| Instant::now() >= t) {
            lift_at = None;
            prlimit("unlimited:unlimited");
        }
        assert!(t0.elapsed() < Duration::from_secs(120), "run overran");
        std::thread::sleep(Duration::from_millis(20));
    }
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).unwrap_or_default();
    SmallFsRun {
        code: read("rc").trim().parse().ok(),
        stdout: read("stdout"),
        stderr: read("stderr"),
        out: copy,
        live_dropped_max,
    }
}

/// No process of the run died: no panic in any log, no restart.
fn assert_nothing_died(r: &SmallFsRun, summary: &serde_json::Value) {
    assert!(!r.stderr.contains("panicked"), "{}", r.stderr);
    for e in std::fs::read_dir(r.out.join("logs")).unwrap().flatten() {
        let log = std::fs::read_to_string(e.path()).unwrap_or_default();
        assert!(!log.contains("panicked"), "{}: {log}", e.path().display());
    }
    assert_eq!(summary["fusion_restarts"], 0, "{summary}");
    for (name, n) in summary["driver_restarts"].as_object().unwrap() {
        assert_eq!(n, 0, "{name} restarted: {summary}");
    }
}

#[test]
fn full_disk_during_a_run_resumes_the_recording_and_the_summary_tells_the_truth() {
    let _g = MACHINE.shared();
    // 3 MiB free: full ≈ 110 s into the scenario (the 100 s alignment ≈ 2.4 MB, every
    // solution after it ≈ 80 kB/s), freed 7 s after the start (≈ 125 s of scenario at 25×
    // after the 2 s start delay); the run is 200 s.
    let r = run_on_small_fs("resume", 200.0, 3 * 1024 * 1024, Some(7.0));
    let s: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(r.out.join("summary.json")).expect("summary.json"),
    )
    .expect("summary.json is complete JSON");
    // An incomplete recording: a non-zero exit, said so.
    assert_eq!(r.code, Some(3), "{}\n{}", r.stdout, r.stderr);
    assert!(r.stderr.contains("recording is incomplete"), "{}", r.stderr);
    assert_nothing_died(&r, &s);
    // The summary's counters are the fusion's own: at least what the live status showed.
    assert_eq!(s["recording_complete"], false, "{s}");
    let dropped = s["records_dropped"].as_u64().unwrap();
    assert!(r.live_dropped_max > 0, "the disk never filled up");
    assert!(
        dropped >= r.live_dropped_max,
        "{dropped} < live {}",
        r.live_dropped_max
    );
    assert!(s["recorder_errors"].as_u64().unwrap() >= 1, "{s}");
    let table_dropped = r
        .stdout
        .lines()
        .find(|l| l.trim_start().starts_with("records dropped"))
        .and_then(|l| l.split_whitespace().last())
        .and_then(|v| v.parse::<u64>().ok());
    assert_eq!(table_dropped, Some(dropped), "{}", r.stdout);
    // The recording resumed in a second segment, with solutions after the gap.
    let files: Vec<String> = s["recording_files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap().rsplit('/').next().unwrap().to_string())
        .collect();
    assert!(
        files.len() >= 2 && files[1] == "recording.part2.mcap",
        "{files:?}"
    );
    let last = read_recording(&r.out.join(&files[files.len() - 1])).expect("last segment");
    assert!(last.count("nav") > 1000, "{} solutions", last.count("nav"));
    let first_nav_after = last.topic("nav").map(|m| m.log_time).min().unwrap();
    let bytes = std::fs::read(r.out.join("recording.mcap")).unwrap();
    let last_before =
        mcap::MessageStream::new_with_options(&bytes, mcap::read::Options::IgnoreEndMagic.into())
            .unwrap()
            .take_while(|m| m.is_ok())
            .flatten()
            .map(|m| m.log_time)
            .max()
            .unwrap();
    assert!(first_nav_after > last_before);
}

#[test]
fn disk_full_to_the_end_leaves_no_empty_summary_and_fails_the_command() {
    let _g = MACHINE.shared();
    // 16 kB free, never freed: no recording, no room for the summary.
    let r = run_on_small_fs("stays-full", 110.0, 16 * 1024, None);
    assert_ne!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    assert!(r.code.is_some());
    // summary.json is complete or absent, never empty: the summary is on stdout then.
    match std::fs::read_to_string(r.out.join("summary.json")) {
        Ok(t) => {
            let s: serde_json::Value = serde_json::from_str(&t).expect("complete JSON");
            assert_eq!(s["recording_complete"], false);
        }
        Err(_) => assert!(
            r.stdout.contains("\"recording_complete\": false"),
            "{}",
            r.stdout
        ),
    }
    assert!(!r.stderr.contains("panicked"), "{}", r.stderr);
    assert!(r.stderr.contains("recording is incomplete"), "{}", r.stderr);
}
