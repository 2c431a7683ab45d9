//! `sextant report` streams: its peak memory does not grow with the recording's length.
//!
//! Two synthetic recordings written with the recorder (in segments of 2 min, truth at a
//! quarter of the solution rate and 0.3 s behind it in the file, like a live recording), one of
//! 2 min and one of 8 min of 200 Hz data, are reported by the real `sextant report`; the peak
//! resident set (VmHWM) of the longer one may exceed the shorter one's by at most
//! [`GROWTH_BOUND_KIB`].
//!
//! The bound: what the report holds that can still grow after 2 min of 200 Hz data is the
//! IMU channel's period window (at most 65 536 times of 8 bytes and their periods: 1 MiB) and
//! the touched bins of its twelve 95th-percentile histograms (at most 0.4 MiB each: 5 MiB);
//! the matching window (60 s) and the plotted series (8 000 points) are full at 2 min. Twice
//! that, 12 MiB, leaves room for the allocator. Keeping every solution, truth sample and
//! sample time, as the report did before it streamed, fails it: measured 33.3 MiB for 2 min
//! and 75.1 MiB for 8 min (streaming: 39.4 and 40.0 MiB).
//!
//! The peak is read from `/proc/PID/status` every 5 ms while the report runs (VmHWM only
//! grows, so the largest reading is the peak up to the last 5 ms of its life, which both
//! runs share: the plots and files at the end are of the same size).

use sextant_lab::recorder::{Record, Recorder, RecorderOptions};
use sextant_tests::*;
use std::path::Path;
use std::time::Duration;

/// Allowed growth of the peak resident set from the 2 min to the 8 min recording, KiB.
const GROWTH_BOUND_KIB: u64 = 12 * 1024;

/// WGS-84 ECEF of geodetic (lat, lon, h): where the synthetic solutions are.
fn ecef(lat: f64, lon: f64, h: f64) -> [f64; 3] {
    use fusion::earth::{Geodetic, WGS84, geodetic_to_ecef};
    let r = geodetic_to_ecef(
        &WGS84,
        &Geodetic {
            lat_rad: lat,
            lon_rad: lon,
            height_m: h,
        },
    );
    [r.x, r.y, r.z]
}

/// A recording of `seconds` of 200 Hz IMU and solutions, 50 Hz truth written 0.3 s late,
/// 1 Hz GNSS and status, in segments of 120 s.
fn write_recording(path: &Path, seconds: i64) {
    let opts = RecorderOptions {
        segment_duration: Some(Duration::from_secs(120)),
        ..Default::default()
    };
    let rec = Recorder::start(path, &opts).unwrap();
    let put = |r: Record| {
        while !rec.record(r.clone(), 0) {
            std::thread::sleep(Duration::from_millis(1));
        }
    };
    let (lat, lon) = (0.97f64, 0.65f64);
    let t0 = 1_400_000_000_000_000_000i64;
    let dt = 5_000_000i64;
    let mut late = std::collections::VecDeque::new();
    for k in 0..seconds * 200 {
        let t = t0 + k * dt;
        let x = k as f64;
        let mut imu = msgs::ImuSample::default();
        imu.header.time_ns = t;
        imu.header.seq = k as u64 + 1;
        put(Record::Imu(imu));
        // Errors that keep changing (distinct values fill the percentile histograms).
        let mut nav = msgs::NavSolution::default();
        nav.header.time_ns = t;
        nav.header.seq = k as u64 + 1;
        nav.mode = msgs::NavMode::GnssInertial as u32;
        let r = ecef(lat, lon, 150.0);
        nav.pos_ecef_m = [
            r[0] + 0.3 * (x * 0.013).sin(),
            r[1] + 0.2 * (x * 0.007).cos(),
            r[2] + 0.1 * (x * 0.021).sin(),
        ];
        nav.vel_ned_m_s = [1e-3 * (x * 0.1).sin(), 2e-3 * (x * 0.05).cos(), 0.0];
        nav.pos_sigma_ned_m = [0.2, 0.2, 0.3];
        nav.att_sigma_ned_rad = [1e-4, 1e-4, 5e-4];
        let yaw = 1e-4 * (x * 0.003).sin();
        nav.q_ned_body = [(yaw / 2.0).cos(), 0.0, 0.0, (yaw / 2.0).sin()];
        put(Record::Nav(nav));
        if k % 4 == 0 {
            let mut tr = msgs::TruthSample::default();
            tr.header.time_ns = t;
            tr.header.seq = k as u64 / 4 + 1;
            tr.lat_rad = lat;
            tr.lon_rad = lon;
            tr.pos_ecef_m = r;
            tr.q_ned_body = [1.0, 0.0, 0.0, 0.0];
            late.push_back(tr);
        }
        while late
            .front()
            .is_some_and(|tr: &msgs::TruthSample| tr.header.time_ns <= t - 60 * dt)
        {
            put(Record::Truth(late.pop_front().unwrap()));
        }
        if k % 200 == 0 {
            let mut g = msgs::GnssSample::default();
            g.header.time_ns = t;
            g.header.seq = k as u64 / 200 + 1;
            put(Record::Gnss(Box::new(g)));
            let mut st = msgs::Status::default();
            st.header.time_ns = t;
            st.header.seq = k as u64 / 200 + 1;
            st.sensors[2].nis_sum = x * 0.01;
            st.sensors[2].nis_dof_sum = k as u64 / 100;
            put(Record::Status(Box::new(st)));
        }
    }
    for tr in late {
        put(Record::Truth(tr));
    }
    rec.finish().unwrap();
}

/// Run `sextant report REC --out OUT`, require success; its peak resident set, KiB, and the
/// summary it wrote.
fn report_peak_kib(rec: &Path, out: &Path) -> (u64, serde_json::Value) {
    let mut child = std::process::Command::new(bin("sextant").unwrap())
        .args(["--quiet", "report"])
        .arg(rec)
        .arg("--out")
        .arg(out)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let pid = child.id();
    let mut peak = 0u64;
    let t0 = std::time::Instant::now();
    let status = loop {
        if let Some(kib) = std::fs::read_to_string(format!("/proc/{pid}/status"))
            .ok()
            .and_then(|s| {
                s.lines()
                    .find(|l| l.starts_with("VmHWM:"))?
                    .split_whitespace()
                    .nth(1)?
                    .parse::<u64>()
                    .ok()
            })
        {
            peak = peak.max(kib);
        }
        if let Some(st) = child.try_wait().unwrap() {
            break st;
        }
        assert!(t0.elapsed() < Duration::from_secs(120), "report overran");
        std::thread::sleep(Duration::from_millis(5));
    };
    assert!(
        status.success(),
        "sextant report {}: {status}",
        rec.display()
    );
    assert!(peak > 0, "no reading of the report's memory");
    (peak, summary_json(out))
}

#[test]
fn report_memory_does_not_grow_with_the_recording() {
    let _g = MACHINE.exclusive();
    let dir = tempdir("report-memory");
    let (short, long) = (
        dir.join("short/recording.mcap"),
        dir.join("long/recording.mcap"),
    );
    for (p, s) in [(&short, 120), (&long, 480)] {
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        write_recording(p, s);
    }
    assert!(dir.join("long/recording.part4.mcap").exists());
    let (short_kib, s1) = report_peak_kib(&short, &dir.join("short-report"));
    let (long_kib, s2) = report_peak_kib(&long, &dir.join("long-report"));
    println!(
        "report peak RSS: {:.1} MiB for 2 min, {:.1} MiB for 8 min",
        short_kib as f64 / 1024.0,
        long_kib as f64 / 1024.0
    );
    // Every solution counted and every truth sample matched, across the segments.
    assert_eq!(s1["solutions"], 24_000, "{s1}");
    assert_eq!(s2["solutions"], 96_000, "{s2}");
    assert_eq!(s2["truth_errors"]["solutions_matched"], 24_000, "{s2}");
    assert_eq!(s2["dropouts"].as_array().map(Vec::len), Some(0), "{s2}");
    assert!(
        long_kib <= short_kib + GROWTH_BOUND_KIB,
        "peak RSS grew from {short_kib} KiB (2 min) to {long_kib} KiB (8 min)"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
