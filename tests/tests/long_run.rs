//! Runs of days: a recording in segments that every reader takes as one, and a fusion daemon
//! whose memory stays flat.
//!
//! - `a_recording_in_segments_…` (short, in every test run): a run whose recorder starts a new
//!   segment every 20 s of simulated time leaves complete MCAP files that an independent
//!   reader opens one by one; `sextant run`'s analysis, `report` and `replay --offline` read
//!   them as one recording, and the replay reproduces every solution bit for bit across the
//!   segment boundaries.
//! - `fusion_memory_stays_flat_over_a_simulated_day` (ignored: about 15 min of both cores and
//!   10 GB of disk; run it with `cargo test --release -p sextant-tests --test integration
//!   long_run -- --ignored --nocapture`):
//!   24 h of the default scenario at 100×, the fusion daemon's resident set sampled from
//!   `/proc` every simulated ten minutes, must stay within 2 MiB of its value after the first
//!   simulated hour; `sextant report` on the whole day must stay under 200 MB.

use sextant_tests::*;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

/// A system configuration like the shipped one, with `segment_duration_s` changed (and the
/// filter and scenario named by absolute path, so that it works from a temporary directory).
fn system_config(dir: &Path, segment_duration_s: f64) -> PathBuf {
    let root = repo_root();
    let text = std::fs::read_to_string(root.join("config/sextant.toml")).unwrap();
    assert!(text.contains("segment_duration_s = 1800.0"));
    let text = text
        .replace(
            "segment_duration_s = 1800.0",
            &format!("segment_duration_s = {segment_duration_s:.1}"),
        )
        .replace(
            "filter = \"filter.toml\"",
            &format!(
                "filter = {:?}",
                root.join("config/filter.toml").display().to_string()
            ),
        )
        .replace(
            "scenario = \"scenarios/vehicle.toml\"",
            &format!(
                "scenario = {:?}",
                root.join("config/scenarios/vehicle.toml")
                    .display()
                    .to_string()
            ),
        );
    let path = dir.join("sextant.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn a_recording_in_segments_reads_reports_and_replays_as_one() {
    let _g = MACHINE.shared();
    let dir = tempdir("segments");
    let cfg = system_config(&dir, 20.0);
    let prefix = format!("sextant_segments_{}", std::process::id());
    let cfg_arg = cfg.display().to_string();
    // A vehicle that drives from the start (navigation begins at once, aligned in motion).
    let scenario = driving_scenario(&dir).display().to_string();
    let mut child = start_run(
        &dir,
        &prefix,
        &[
            "--config",
            &cfg_arg,
            "--scenario",
            &scenario,
            "--duration",
            "70",
            "--speed",
            "20",
        ],
    )
    .expect("start sextant run");
    let st = wait_exit(&mut child, "sextant run", Duration::from_secs(60));
    let log = std::fs::read_to_string(dir.join("sextant.log")).unwrap_or_default();
    assert!(st.success(), "sextant run: {st}\n{log}");

    // 70 s in segments of 20 s of time of validity: four files, each complete on its own.
    let files: Vec<PathBuf> = ["recording.mcap", "recording.part2.mcap"]
        .into_iter()
        .map(String::from)
        .chain((3..=4).map(|n| format!("recording.part{n}.mcap")))
        .map(|f| dir.join(f))
        .collect();
    assert!(!dir.join("recording.part5.mcap").exists());
    let mut nav_total = 0;
    let mut imu_seq = Vec::new();
    for f in &files {
        let bytes = std::fs::read(f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        let stats = mcap::Summary::read(&bytes)
            .unwrap()
            .expect("a complete MCAP with a summary")
            .stats
            .unwrap();
        // Records are written in the order they arrive: one stamped before the segment's
        // first record (an aiding sample that arrived after an IMU sample of a later time)
        // widens the span by its lateness, milliseconds of wall time (under 1 s simulated at
        // 20×, the most a driver may lag before it drops samples being 5 s simulated).
        let span_s = (stats.message_end_time - stats.message_start_time) as f64 * 1e-9;
        println!("{}: {span_s:.3} s", f.display());
        assert!(span_s < 21.0, "{}: spans {span_s} s", f.display());
        let rec = read_recording(f).unwrap();
        assert!(rec.invalid.is_empty(), "{:?}", &rec.invalid[..1]);
        nav_total += rec.count("nav");
        imu_seq.extend(
            rec.topic("imu")
                .map(|r| int(&r.json, "/header/seq").unwrap()),
        );
    }
    // Nothing lost or repeated at the boundaries.
    assert!(imu_seq.windows(2).all(|w| w[1] == w[0] + 1), "IMU sequence");
    assert!(nav_total > 0);

    let s = summary_json(&dir);
    assert_eq!(s["solutions"], nav_total, "{s}");
    assert_eq!(s["recording_files"].as_array().unwrap().len(), 4, "{s}");
    assert_eq!(s["recording_complete"], true, "{s}");

    let first = files[0].display().to_string();
    let rep = sextant_offline(&["report", &first], &dir.join("report"));
    assert_eq!(rep["solutions"], nav_total, "{rep}");
    // The replay writes its recording in segments of the same span, so replaying days holds
    // one segment's index in memory; the segments read back as one, complete.
    let rp = sextant_offline(
        &["replay", "--offline", &first, "--segment-duration-s", "20"],
        &dir.join("replay"),
    );
    assert_eq!(rp["replay"]["solutions_compared"], nav_total, "{rp}");
    assert_eq!(rp["replay"]["bit_exact"], true, "{rp}");
    let replayed: Vec<&str> = rp["replay"]["replayed_segments"]
        .as_array()
        .expect("replayed_segments")
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert_eq!(replayed.len(), 4, "{rp}");
    for f in &replayed {
        let bytes = std::fs::read(f).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert!(mcap::Summary::read(&bytes).unwrap().is_some(), "{f}");
    }
    let rep = sextant_offline(&["report", replayed[0]], &dir.join("report-of-replay"));
    assert_eq!(rep["solutions"], nav_total, "{rep}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Resident set of a process, KiB.
fn rss_kib(pid: i32) -> Option<u64> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    s.lines()
        .find(|l| l.starts_with("VmRSS:"))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()
}

#[test]
#[ignore = "24 h of simulated time: 15 min of both cores and 10 GB of disk, then about 10 min for the report of the day"]
fn fusion_memory_stays_flat_over_a_simulated_day() {
    let _g = MACHINE.exclusive();
    const SPEED: f64 = 100.0;
    const DAY_S: f64 = 86_400.0;
    let dir = tempdir("day");
    let prefix = format!("sextant_day_{}", std::process::id());
    let mut child = start_run(
        &dir,
        &prefix,
        // The report below analyses the day; the run's own analysis would do it twice.
        &[
            "--duration",
            "86400",
            "--speed",
            &SPEED.to_string(),
            "--no-analysis",
        ],
    )
    .expect("start sextant run");
    std::thread::sleep(Duration::from_secs(4));
    let pid = pid_of(&prefix, "sextant-fusion").expect("fusion running");
    let started = std::time::Instant::now();
    // (simulated hours since the first sample, RSS KiB), every 10 simulated minutes.
    let mut samples: Vec<(f64, u64)> = Vec::new();
    while let Some(kib) = rss_kib(pid) {
        let h = started.elapsed().as_secs_f64() * SPEED / 3600.0;
        samples.push((h, kib));
        if samples.len() % 6 == 1 {
            println!(
                "{h:6.2} h simulated: fusion RSS {:.2} MiB",
                kib as f64 / 1024.0
            );
        }
        std::thread::sleep(Duration::from_secs_f64(600.0 / SPEED));
    }
    // The fusion has exited: judge its memory before anything else.
    let after_first_hour = samples
        .iter()
        .find(|(h, _)| *h >= 1.0)
        .expect("a sample after the first hour")
        .1;
    let max = samples.iter().map(|s| s.1).max().unwrap();
    let last_h = samples.last().unwrap().0;
    println!(
        "fusion RSS after 1 h {:.2} MiB, max {:.2} MiB over {last_h:.1} h ({} samples)",
        after_first_hour as f64 / 1024.0,
        max as f64 / 1024.0,
        samples.len()
    );
    assert!(
        last_h >= 0.95 * DAY_S / 3600.0,
        "sampled {last_h:.1} h only"
    );
    assert!(
        max <= after_first_hour + 2048,
        "fusion RSS grew by {} KiB after the first hour",
        max - after_first_hour
    );
    let st = wait_exit(&mut child, "sextant run", Duration::from_secs(600));
    let s = summary_json(&dir);
    // At 100× on a 2-core machine the JSON recorder is at its throughput (about 100 000
    // records/s beside the fusion and six drivers) and may drop records. That is an overload
    // beyond real time, not a memory effect: it must be counted and reported, never silent —
    // the run ends with exit status 3 ("completed, recording incomplete") exactly when records
    // were dropped, and the summary's counters are the fusion's.
    let dropped = s["records_dropped"].as_u64().expect("records_dropped");
    let written = s["records_written"].as_u64().expect("records_written");
    println!(
        "recording: {written} records written, {dropped} dropped ({:.2} %)",
        100.0 * dropped as f64 / (written + dropped) as f64
    );
    if dropped == 0 {
        assert!(st.success(), "sextant run: {st}");
        assert_eq!(s["recording_complete"], true, "{s}");
    } else {
        assert_eq!(st.code(), Some(3), "sextant run with drops: {st}");
        assert_eq!(s["recording_complete"], false, "{s}");
    }
    assert_eq!(s["fusion_restarts"], 0, "{s}");

    // The report of the whole day, in bounded memory.
    let report = Command::new("/usr/bin/time")
        .arg("-v")
        .arg(bin("sextant").unwrap())
        .args(["--quiet", "report"])
        .arg(dir.join("recording.mcap"))
        .arg("--out")
        .arg(dir.join("report"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&report.stderr);
    assert!(report.status.success(), "{err}");
    let max_rss_kib: u64 = err
        .lines()
        .find_map(|l| {
            l.trim()
                .strip_prefix("Maximum resident set size (kbytes): ")
        })
        .and_then(|v| v.trim().parse().ok())
        .expect("GNU time's maximum resident set size");
    println!(
        "report of the day: max RSS {:.0} MB",
        max_rss_kib as f64 * 1.024 / 1000.0
    );
    assert!(
        max_rss_kib * 1024 <= 200_000_000,
        "report used {max_rss_kib} KiB"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
