//! End-to-end: `sextant report` on a recording of the real processes (`sextant run`): the
//! figures agree with an independent computation from the recording (read with the `mcap`
//! crate), the files are written, and a truncated copy is reported up to the cut with the
//! byte offset named.

use sextant_tests::*;
use std::path::PathBuf;
use std::process::{Command, Stdio};

fn out_dir(name: &str) -> PathBuf {
    tempdir(&format!("report-{name}"))
}

/// North, east, down components of ECEF `r − r_true` at (lat, lon), m.
fn ned(r: &[f64], r_true: &[f64], lat: f64, lon: f64) -> [f64; 3] {
    let d = [r[0] - r_true[0], r[1] - r_true[1], r[2] - r_true[2]];
    let (sl, cl, so, co) = (lat.sin(), lat.cos(), lon.sin(), lon.cos());
    [
        -sl * co * d[0] - sl * so * d[1] + cl * d[2],
        -so * d[0] + co * d[1],
        -cl * co * d[0] - cl * so * d[1] - sl * d[2],
    ]
}

#[test]
fn report_of_a_live_recording_matches_an_independent_computation() {
    let _g = MACHINE.shared();
    let out = out_dir("run");
    let prefix = format!("sextant_report_e2e_{}", std::process::id());
    let st = Command::new(bin("sextant").unwrap())
        .current_dir(repo_root())
        .args([
            "run",
            "--duration",
            "115",
            "--speed",
            "25",
            "--prefix",
            &prefix,
            "--out",
        ])
        .arg(&out)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .unwrap();
    assert!(st.success());
    let rec = out.join("recording.mcap");
    let rep = out.join("report");
    let o = Command::new(bin("sextant").unwrap())
        .args(["report"])
        .arg(&rec)
        .arg("--out")
        .arg(&rep)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(rep.join("summary.json")).unwrap()).unwrap();

    // Independent: match solutions with truth by time of validity, north/east/down errors.
    let r = read_recording(&rec).unwrap();
    let truth: std::collections::HashMap<i64, &serde_json::Value> = r
        .topic("truth")
        .filter_map(|t| int(&t.json, "/header/time_ns").map(|k| (k, &t.json)))
        .collect();
    let mut e: [Vec<f64>; 3] = Default::default();
    for n in r.topic("nav") {
        let Some(t) = int(&n.json, "/header/time_ns").and_then(|k| truth.get(&k)) else {
            continue;
        };
        let v = ned(
            &f64s(&n.json["pos_ecef_m"]),
            &f64s(&t["pos_ecef_m"]),
            num(t, "/lat_rad").unwrap(),
            num(t, "/lon_rad").unwrap(),
        );
        for i in 0..3 {
            e[i].push(v[i]);
        }
    }
    let te = &s["truth_errors"];
    assert_eq!(te["solutions_matched"].as_u64(), Some(e[0].len() as u64));
    // 15 s of navigation, solutions and truth recorded at 10 Hz: 150 pairs.
    assert!(e[0].len() > 100, "{} pairs", e[0].len());
    for (i, axis) in ["position_north_m", "position_east_m", "position_down_m"]
        .iter()
        .enumerate()
    {
        let rms = (e[i].iter().map(|x| x * x).sum::<f64>() / e[i].len() as f64).sqrt();
        let max = e[i].iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let got_rms = te[axis]["rms"].as_f64().unwrap();
        let got_max = te[axis]["max"].as_f64().unwrap();
        let got_p95 = te[axis]["p95"].as_f64().unwrap();
        // Same numbers, different code: agreement to rounding (1e-9 relative).
        assert!(
            (got_rms - rms).abs() <= 1e-9 * rms.max(1e-3),
            "{axis}: {got_rms} vs {rms}"
        );
        assert!(
            (got_max - max).abs() <= 1e-9 * max.max(1e-3),
            "{axis}: {got_max} vs {max}"
        );
        assert!(got_p95 <= got_max && got_p95 > 0.0);
    }
    // NIS per dof equals Σ NIS / Σ dof of the last status.
    let last = r.topic("status").last().unwrap();
    for (i, name) in ["imu", "star_tracker", "gnss", "odometer", "baro"]
        .iter()
        .enumerate()
    {
        let h = &last.json["sensors"][i];
        let sensor = &s["sensors"][i];
        assert_eq!(sensor["sensor"], *name);
        let dof = h["nis_dof_sum"].as_u64().unwrap();
        if dof > 0 {
            let want = h["nis_sum"].as_f64().unwrap() / dof as f64;
            assert_eq!(sensor["nis_over_dof"].as_f64(), Some(want), "{name}");
        }
        assert_eq!(sensor["fused"], h["fused"]);
    }
    // No gaps in a healthy run.
    assert_eq!(s["dropouts"].as_array().map(|a| a.len()), Some(0));
    assert!(!s["mode_changes"].as_array().unwrap().is_empty());
    for f in [
        "REPORT.md",
        "trajectory.png",
        "error_north_3sigma.png",
        "error_east_3sigma.png",
        "error_down_3sigma.png",
        "gyro_bias.png",
        "accel_bias.png",
        "boresight.png",
        "nis.png",
    ] {
        let b = std::fs::read(rep.join(f)).unwrap_or_default();
        assert!(b.len() > 1000, "{f}");
    }

    // A truncated copy: reported up to the cut, the offset named. The cut falls in the middle
    // of the last chunk holding solutions, found from the file's own chunk index (a fixed
    // fraction of the bytes would depend on how the recorder's chunks fell on this run).
    let bytes = std::fs::read(&rec).unwrap();
    let summary = mcap::Summary::read(&bytes)
        .unwrap()
        .expect("a finished recording has a summary");
    let nav_channel = summary
        .channels
        .values()
        .find(|c| c.topic == "nav")
        .expect("a nav channel")
        .id;
    let nav_chunks: Vec<_> = summary
        .chunk_indexes
        .iter()
        .filter(|c| c.message_index_offsets.contains_key(&nav_channel))
        .collect();
    assert!(
        nav_chunks.len() >= 2,
        "{} chunks hold solutions",
        nav_chunks.len()
    );
    let last = nav_chunks.last().unwrap();
    let cut_at = (last.chunk_start_offset + last.chunk_length / 2) as usize;
    let cut = out.join("cut.mcap");
    std::fs::write(&cut, &bytes[..cut_at]).unwrap();
    let rep2 = out.join("report-cut");
    let o = Command::new(bin("sextant").unwrap())
        .args(["report"])
        .arg(&cut)
        .arg("--out")
        .arg(&rep2)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let md = std::fs::read_to_string(rep2.join("REPORT.md")).unwrap();
    assert!(md.contains("truncated at byte offset"), "{md}");
    let s2: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(rep2.join("summary.json")).unwrap()).unwrap();
    let n2 = s2["solutions"].as_u64().unwrap();
    let n1 = s["solutions"].as_u64().unwrap();
    assert!(n2 > 0 && n2 < n1, "{n2} of {n1}");
}
