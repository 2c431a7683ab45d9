//! `sextant bench --quick`: every figure present and sane (the targets themselves are reported by
//! the bench, not asserted here: they depend on the machine's load).

use sextant_tests::*;
use std::process::Command;

fn f(v: &serde_json::Value, ptr: &str) -> f64 {
    v.pointer(ptr)
        .and_then(|x| x.as_f64())
        .unwrap_or_else(|| panic!("summary lacks {ptr}"))
}

#[test]
fn quick_bench_reports_every_figure() {
    let _g = MACHINE.exclusive();
    let out = std::env::temp_dir().join(format!("sextant-bench-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let o = Command::new(bin("sextant").unwrap())
        .current_dir(repo_root())
        .args(["bench", "--quick", "--out"])
        .arg(&out)
        .output()
        .expect("start sextant bench");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(stdout.contains("p99.9 us"), "{stdout}");
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert!(f(&s, "/machine/nproc") >= 1.0);
    assert!(s["machine"]["cpu_model"].as_str().is_some());
    // Quick mode: 4 s live runs, 1 s of which is the shortened alignment.
    for (key, hz) in [("imu_200hz", 200.0), ("imu_1000hz", 1000.0)] {
        let p = |name: &str| format!("/live/{key}/{name}");
        let (p50, p99, p999, max) = (
            f(&s, &p("latency_p50_us")),
            f(&s, &p("latency_p99_us")),
            f(&s, &p("latency_p99_9_us")),
            f(&s, &p("latency_max_us")),
        );
        assert!(
            0.0 < p50 && p50 <= p99 && p99 <= p999 && p999 <= max,
            "{key}: {p50} {p99} {p999} {max}"
        );
        // A median above one IMU period would mean the loop cannot keep up at all.
        assert!(p50 < 1e6 / hz, "{key}: p50 {p50} us");
        // Every IMU sample gives a solution once navigating: the rate over the navigating
        // span is the IMU's. Navigation starts after the 1 s window once a GNSS fix of it is
        // `buffer_window_s` (1 s) old — at most one GNSS period (1 s) more — so at least 1 s
        // of the 4 s navigates.
        let n = f(&s, &p("solutions"));
        let span_s = f(&s, &format!("/live/{key}/navigating_s"));
        assert!(span_s >= 0.9, "{key}: navigated {span_s} s");
        let rate = f(&s, &p("solutions_per_s"));
        assert!(
            (rate - hz).abs() < 0.1 * hz,
            "{key}: {n} solutions over {span_s} s: {rate}/s, expected {hz}"
        );
        // The floor: a bare iceoryx2 round trip at the same rate in the same run (1 s in quick
        // mode); Sextant's figures against it are finite.
        let (f50, f99, f999) = (
            f(&s, &p("floor/latency_p50_us")),
            f(&s, &p("floor/latency_p99_us")),
            f(&s, &p("floor/latency_p99_9_us")),
        );
        assert!(
            0.0 < f50 && f50 <= f99 && f99 <= f999,
            "{key} floor: {f50} {f99} {f999}"
        );
        assert!(f50 < 1e6 / hz, "{key}: floor p50 {f50} us");
        let replies = f(&s, &p("floor/solutions"));
        assert!(
            replies >= 0.9 * f(&s, &p("floor/sent")) && replies > 0.9 * want_replies(hz),
            "{key}: {replies} floor replies"
        );
        let excess = f(&s, &p("vs_floor/p50_excess_us"));
        let ratio = f(&s, &p("vs_floor/p99_ratio"));
        assert!(excess.is_finite(), "{key}: p50 excess {excess}");
        assert!(ratio.is_finite() && ratio > 0.0, "{key}: p99 ratio {ratio}");
        assert!(f(&s, &p("floor/echo_peak_rss_mib")) > 0.0);
        // The recording's size: the run's files on disk, scaled to 600 s of operation.
        let stem = format!("latency_{}hz", hz as u64);
        let on_disk: u64 = std::fs::read_dir(&out)
            .unwrap()
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().starts_with(&stem))
            .map(|e| e.metadata().unwrap().len())
            .sum();
        assert!(on_disk > 0, "{key}: no recording");
        assert_eq!(f(&s, &p("recording/bytes")), on_disk as f64, "{key}");
        let per_600 = on_disk as f64 / 1e6 * 600.0 / f(&s, &p("recording/duration_s"));
        assert!(
            (f(&s, &p("recording/mb_per_600s")) - per_600).abs() <= 1e-9 * per_600,
            "{key}"
        );
        for proc_name in ["sextant-fusion", "sextant-sim-imu", "sextant-sim-gnss"] {
            let cpu = f(&s, &p(&format!("processes/{proc_name}/cpu_percent")));
            let rss = f(&s, &p(&format!("processes/{proc_name}/peak_rss_mib")));
            assert!(
                (0.0..=100.0 * f(&s, "/machine/nproc")).contains(&cpu),
                "{proc_name} {cpu} %"
            );
            assert!(rss > 1.0 && rss < 1024.0, "{proc_name} {rss} MiB");
        }
    }
    // The Zenoh bridge: 1 s at 200 Hz through two real bridges on loopback; every solution
    // crosses (TCP is reliable and the bridges' queues are far deeper than 200 messages), in
    // order of its percentiles, and its median is above the bare iceoryx2 floor's (it holds
    // two iceoryx2 deliveries).
    let (b50, b99, bmax) = (
        f(&s, "/bridge/latency_p50_us"),
        f(&s, "/bridge/latency_p99_us"),
        f(&s, "/bridge/latency_max_us"),
    );
    assert!(
        0.0 < b50 && b50 <= b99 && b99 <= bmax,
        "bridge: {b50} {b99} {bmax}"
    );
    assert_eq!(f(&s, "/bridge/sent"), 200.0);
    assert_eq!(f(&s, "/bridge/lost"), 0.0, "bridge lost solutions");
    assert!(f(&s, "/bridge/p50_over_floor_us") > 0.0);
    assert!(stdout.contains("Zenoh bridge"), "{stdout}");
    // Offline: 60 s simulated, faster than real time by far even on a loaded machine.
    assert!(f(&s, "/offline/navigating_imu_samples") > 200.0 * 40.0);
    assert!(f(&s, "/offline/navigating_x_real_time") > 10.0);
    assert_eq!(f(&s, "/offline/rejected_inputs"), 0.0);
    // Replay: a 130 s drive (its 100 s alignment, then navigation) replayed with every aiding
    // and, through the KF-GINS files, loosely coupled; every IMU sample replayed, solutions
    // after the alignment, and the KF-GINS files with KF-GINS's configuration left behind.
    for leg in ["every_aiding", "loosely_coupled"] {
        assert_eq!(
            f(&s, &format!("/replay/{leg}/imu_samples")),
            200.0 * 130.0,
            "{leg}"
        );
        let solutions = f(&s, &format!("/replay/{leg}/solutions"));
        assert!(
            solutions > 200.0 * 20.0 && solutions < 200.0 * 31.0,
            "{leg}: {solutions}"
        );
        assert!(
            f(&s, &format!("/replay/{leg}/imu_samples_per_s")) > 1000.0,
            "{leg}"
        );
        // The figure is the median of the five timed replays, each kept.
        let mut runs: Vec<f64> = s["replay"][leg]["imu_samples_per_s_runs"]
            .as_array()
            .expect("the replays' rates")
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(runs.len(), 5, "{leg}");
        runs.sort_by(f64::total_cmp);
        assert_eq!(
            f(&s, &format!("/replay/{leg}/imu_samples_per_s")),
            runs[2],
            "{leg}"
        );
    }
    assert!(out.join("kfgins").join("kf-gins.yaml").is_file());
    assert!(stdout.contains("KF-GINS kf-gins.yaml"), "{stdout}");
    // Recorder: every offered record accounted for.
    assert!(f(&s, "/recorder/saturated_records_per_s") > 1000.0);
    assert!(f(&s, "/recorder/saturated_mcap_mb_per_s") > 0.0);
    assert_eq!(
        f(&s, "/recorder/paced_10x_accepted") + f(&s, "/recorder/paced_10x_dropped"),
        f(&s, "/recorder/paced_10x_records")
    );
    // The recording target is the replayed drive's own file, at the shipped rates.
    let rec_bytes = std::fs::metadata(out.join("replay/every_aiding/recording.mcap"))
        .expect("the replay's recording")
        .len() as f64;
    let per_600 = rec_bytes / 1e6 * 600.0 / f(&s, "/replay/simulated_s");
    let measured = f(&s, "/replay/every_aiding/recording_mb_per_600s");
    assert!(
        (measured - per_600).abs() <= 1e-9 * per_600,
        "{measured} vs {per_600}"
    );
    assert_eq!(
        f(&s, "/targets/recording_mb_per_600s_at_200hz/measured"),
        measured
    );
    for t in [
        "latency_p50_us_at_1khz",
        "latency_p99_us_at_1khz",
        "offline_x_real_time_all_aiding",
        "fusion_peak_rss_mib",
        "recorder_10x_dropped",
        "recording_mb_per_600s_at_200hz",
        "replay_imu_samples_per_s_all_aiding",
    ] {
        assert!(s["targets"][t]["measured"].is_number(), "target {t}");
    }
    let png = std::fs::metadata(out.join("latency_histogram.png")).expect("histogram");
    assert!(png.len() > 1000);
    assert!(stdout.contains("over the floor"), "{stdout}");
    // Cost curves: every point timed, positive and finite.
    for curve in [
        "imu_rate",
        "active_states",
        "tight_satellites",
        "imu_channels",
    ] {
        let pts = s["cost_curves"][curve]
            .as_array()
            .unwrap_or_else(|| panic!("cost curve {curve}"));
        assert!(pts.len() >= 2, "{curve}: {pts:?}");
        for pt in pts {
            let ns = f(pt, "/ns_per_imu_sample");
            assert!(ns.is_finite() && ns > 0.0, "{curve}: {pt}");
            assert!(f(pt, "/imu_samples") > 100.0, "{curve}: {pt}");
            assert_eq!(f(pt, "/rejected_inputs"), 0.0, "{curve}: {pt}");
        }
    }
    // The IMU-rate curve reaches 2 kHz (the simulator's 0.5 ms truth grid).
    let rates = s["cost_curves"]["imu_rate"].as_array().expect("imu_rate");
    assert_eq!(rates.last().map(|p| f(p, "/imu_rate_hz")), Some(2000.0));
    // The crowded sky fills the receiver's channels: the satellite curve reaches 32.
    assert_eq!(f(&s, "/cost_curves/satellites_simulated_max"), 32.0);
    let sats = s["cost_curves"]["tight_satellites"]
        .as_array()
        .expect("tight_satellites");
    assert_eq!(sats.last().map(|p| f(p, "/satellites")), Some(32.0));
    assert!(f(&s, "/cost_curves/triad_ns_per_imu_sample") > 0.0);
    let png = std::fs::metadata(out.join("cost_curves.png")).expect("cost curves");
    assert!(png.len() > 1000);
}

/// Samples of a quick floor run: 1 s at `hz`.
fn want_replies(hz: f64) -> f64 {
    hz
}
