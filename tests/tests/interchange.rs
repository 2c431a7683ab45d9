//! Log interchange end to end, through the `sextant` command and files on disk:
//! a simulated drive (IMU triad, GNSS, odometer, baro, truth) is recorded, exported with
//! `sextant export csv` / `export kfgins`, imported back with `sextant import csv` /
//! `import kfgins`, and re-run with `sextant replay --offline`; the replays' solutions are read
//! back with the independent `mcap` reader and compared as f64 bit patterns.
//!
//! What must hold, and why:
//! - CSV: the export writes times as integer nanoseconds in decimal and every number as the
//!   shortest text that reads back to the same bits, with ECEF positions and full covariances,
//!   so every input the navigator reads comes back bit for bit and the solution of the import
//!   is the solution of the original, bit for bit, at every epoch.
//! - KF-GINS: the IMU file keeps the increments bit for bit and the times to the nanosecond
//!   (exported again, the same file byte for byte), but the GNSS file has geodetic degrees and
//!   NED standard deviations only (no velocity, no correlations), so the import differs from
//!   the original in its GNSS inputs, and its positions come back to the precision of the
//!   geodetic conversion, not bit for bit.
//! - A slice of a real RTK position file (KF-GINS example dataset, GPL-3.0, see
//!   `tests/data/kfgins-rtk/README.md`) imports row for row.

use sextant_tests::*;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Alignment is 100 s (config/filter.toml); 30 s of driving after the vehicle scenario's
/// 120 s hold gives solutions with GNSS, odometer and baro updates while moving.
const DURATION_S: f64 = 150.0;

fn out_dir(name: &str) -> PathBuf {
    tempdir(&format!("interchange-{name}"))
}

fn sextant(args: &[&str]) -> String {
    let out = Command::new(bin("sextant").unwrap())
        .current_dir(repo_root())
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "sextant {args:?} failed: {}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The simulated drive as a recording of inputs and truth, in the offline simulator's order,
/// with the repository's filter configuration embedded (loose coupling); `send_mono_ns` is the
/// time of validity (what an import writes: a log has no reception clock).
fn source_recording(dir: &Path) -> PathBuf {
    use drivers_sim::offline::OfflineSim;
    use drivers_sim::scenario::Scenario;
    use msgs::{Channel, Record};
    use sextant_daemons::recorder::{
        CONFIG_KEY_FILTER_TOML, CONFIG_METADATA_NAME, Recorder, RecorderOptions,
    };
    let root = repo_root();
    let scn = Scenario::load(&root.join("config/scenarios/vehicle.toml")).unwrap();
    let filter = std::fs::read_to_string(root.join("config/filter.toml")).unwrap();
    let path = dir.join("source.mcap");
    let rec = Recorder::start(
        &path,
        &RecorderOptions {
            metadata: vec![(
                CONFIG_METADATA_NAME.to_string(),
                [(CONFIG_KEY_FILTER_TOML.to_string(), filter)].into(),
            )],
            ..Default::default()
        },
    )
    .unwrap();
    let channels = [
        Channel::Imu,
        Channel::Gnss,
        Channel::Odometer,
        Channel::Baro,
        Channel::Truth,
    ];
    for mut r in OfflineSim::with_channels(&scn, &channels).with_duration_s(DURATION_S) {
        let t = sextant_lab::interchange::record_time_ns(&r);
        match &mut r {
            Record::Imu(x) => {
                assert_eq!(x.n_channels, 0, "the scenario's IMU is a plain triad");
                x.header.send_mono_ns = t as u64;
            }
            Record::Gnss(x) => {
                // Neither format carries raw satellite measurements, and with them the
                // navigator would start from their least-squares fix rather than the
                // receiver's: the source has the fix only, as the formats do.
                x.n_satellites = 0;
                x.satellites = [msgs::GnssSatellite::default(); msgs::MAX_SATELLITES];
                x.header.send_mono_ns = t as u64;
            }
            Record::Odometer(x) => x.header.send_mono_ns = t as u64,
            Record::Baro(x) => x.header.send_mono_ns = t as u64,
            Record::Truth(x) => x.header.send_mono_ns = t as u64,
            _ => {}
        }
        assert!(rec.record_blocking(r, 0));
    }
    assert_eq!(rec.finish().unwrap().dropped, 0);
    path
}

/// The solutions of an offline replay of `rec` (into `dir`), as JSON.
fn replay(rec: &Path, dir: &Path) -> Vec<serde_json::Value> {
    sextant(&["replay", "--offline", s(rec), "--out", s(dir)]);
    let r = read_recording(&dir.join("recording.mcap")).unwrap();
    assert!(r.invalid.is_empty(), "{:?}", r.invalid.first());
    r.topic("nav").map(|m| m.json.clone()).collect()
}

/// First difference of two JSON values, numbers compared as f64 bit patterns.
fn bit_diff(a: &serde_json::Value, b: &serde_json::Value, path: &str) -> Option<String> {
    use serde_json::Value as V;
    match (a, b) {
        (V::Object(x), V::Object(y)) => x.iter().find_map(|(k, va)| match y.get(k) {
            Some(vb) => bit_diff(va, vb, &format!("{path}/{k}")),
            None => Some(format!("{path}/{k} missing")),
        }),
        (V::Array(x), V::Array(y)) if x.len() == y.len() => x
            .iter()
            .zip(y)
            .enumerate()
            .find_map(|(i, (va, vb))| bit_diff(va, vb, &format!("{path}/{i}"))),
        (V::Number(x), V::Number(y)) => {
            let (fx, fy) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            (fx.to_bits() != fy.to_bits()).then(|| format!("{path}: {fx:e} vs {fy:e}"))
        }
        _ => (a != b).then(|| format!("{path}: {a} vs {b}")),
    }
}

fn assert_same_solutions(a: &[serde_json::Value], b: &[serde_json::Value], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: number of solutions");
    assert!(a.len() > 1000, "{what}: only {} solutions", a.len());
    let navigating = a
        .iter()
        .filter(|j| int(j, "/mode").unwrap_or(0) >= 2)
        .count();
    assert!(
        navigating > 1000,
        "{what}: only {navigating} navigating solutions"
    );
    for (k, (x, y)) in a.iter().zip(b).enumerate() {
        // header.send_mono_ns is the wall clock of publication (replay: the input's).
        if let Some(d) = bit_diff(&x["header"]["time_ns"], &y["header"]["time_ns"], "/time")
            .or_else(|| {
                let (mut x, mut y) = (x.clone(), y.clone());
                x["header"]["send_mono_ns"] = 0.into();
                y["header"]["send_mono_ns"] = 0.into();
                bit_diff(&x, &y, "")
            })
        {
            panic!("{what}: solution {k} differs: {d}");
        }
    }
}

#[test]
fn csv_and_kfgins_round_trips_reproduce_the_solution() {
    let _g = MACHINE.shared();
    let dir = out_dir("roundtrip");
    let source = source_recording(&dir);
    let original = replay(&source, &dir.join("replay-source"));

    // CSV: bit for bit against the original.
    let csv1 = dir.join("csv1");
    sextant(&["export", "csv", s(&source), "--out", s(&csv1)]);
    let rec_csv = dir.join("csv.mcap");
    sextant(&[
        "import",
        "csv",
        "--describe",
        s(&csv1.join("description.toml")),
        "--config",
        s(&csv1.join("filter.toml")),
        "--out",
        s(&rec_csv),
    ]);
    let via_csv = replay(&rec_csv, &dir.join("replay-csv"));
    assert_same_solutions(&original, &via_csv, "CSV import");
    let csv2 = dir.join("csv2");
    sextant(&["export", "csv", s(&rec_csv), "--out", s(&csv2)]);
    for f in ["imu.csv", "gnss.csv", "odometer.csv", "baro.csv"] {
        assert!(
            std::fs::read(csv1.join(f)).unwrap() == std::fs::read(csv2.join(f)).unwrap(),
            "{f} differs after a round trip"
        );
    }

    // KF-GINS: the week is not in the IMU and GNSS files; the reference trajectory gives it.
    let k1 = dir.join("kfgins1");
    sextant(&["export", "kfgins", s(&source), "--out", s(&k1)]);
    let import_kfgins = |d: &Path, out: &Path| {
        sextant(&[
            "import",
            "kfgins",
            "--imu",
            s(&d.join("imu.txt")),
            "--gnss",
            s(&d.join("gnss.txt")),
            "--truth",
            s(&d.join("truth.nav")),
            "--config",
            s(&d.join("filter.toml")),
            "--out",
            s(out),
        ])
    };
    let rec_k1 = dir.join("kfgins1.mcap");
    import_kfgins(&k1, &rec_k1);
    // The IMU inputs are the original's bit for bit.
    let imu = |p: &Path| -> Vec<serde_json::Value> {
        read_recording(p)
            .unwrap()
            .topic("imu")
            .map(|m| {
                serde_json::json!([
                    m.json["header"]["time_ns"],
                    m.json["delta_angle_rad"],
                    m.json["delta_velocity_m_s"]
                ])
            })
            .collect()
    };
    let (imu0, imu1) = (imu(&source), imu(&rec_k1));
    assert_eq!(imu0.len(), imu1.len());
    for (k, (a, b)) in imu0.iter().zip(&imu1).enumerate() {
        assert_eq!(bit_diff(a, b, ""), None, "IMU sample {k}");
    }
    let via_k1 = replay(&rec_k1, &dir.join("replay-kfgins1"));
    assert_eq!(via_k1.len(), original.len());
    let navigating = via_k1
        .iter()
        .filter(|j| int(j, "/mode").unwrap_or(0) >= 2)
        .count();
    assert!(navigating > 1000, "only {navigating} navigating solutions");
    // Exported again: the IMU file byte for byte; the GNSS file to the precision of the
    // geodetic conversion (degrees → ECEF → degrees: `ecef_to_geodetic` is exact to < 0.1 mm
    // by its contract, < 1e-9° and < 1e-4 m), which is why the format is not a bit-exact
    // fixed point for the GNSS positions.
    let k2 = dir.join("kfgins2");
    sextant(&["export", "kfgins", s(&rec_k1), "--out", s(&k2)]);
    assert!(
        std::fs::read(k1.join("imu.txt")).unwrap() == std::fs::read(k2.join("imu.txt")).unwrap(),
        "imu.txt differs after a round trip"
    );
    let rows = |p: &Path| -> Vec<Vec<f64>> {
        std::fs::read_to_string(p)
            .unwrap()
            .lines()
            .map(|l| l.split_whitespace().map(|x| x.parse().unwrap()).collect())
            .collect()
    };
    let (g1, g2) = (rows(&k1.join("gnss.txt")), rows(&k2.join("gnss.txt")));
    assert_eq!(g1.len(), g2.len());
    assert!(g1.len() > 100);
    for (a, b) in g1.iter().zip(&g2) {
        assert_eq!(a[0], b[0], "time");
        assert!(
            (a[1] - b[1]).abs() < 1e-9 && (a[2] - b[2]).abs() < 1e-9,
            "{a:?} vs {b:?}"
        );
        assert!((a[3] - b[3]).abs() < 1e-4, "{a:?} vs {b:?}");
        for (x, y) in a[4..7].iter().zip(&b[4..7]) {
            assert!((x - y).abs() < 1e-9 * x, "{a:?} vs {b:?}");
        }
    }
    // KF-GINS's configuration starts it at Sextant's first solution (the replay's recording),
    // or without solutions (the simulated source) at the truth's first pose.
    let k3 = dir.join("kfgins3");
    sextant(&[
        "export",
        "kfgins",
        s(&dir.join("replay-kfgins1").join("recording.mcap")),
        "--out",
        s(&k3),
    ]);
    let start = |d: &Path| -> (f64, Vec<f64>) {
        let text = std::fs::read_to_string(d.join("kf-gins.yaml")).unwrap();
        let value = |k: &str| {
            text.lines()
                .find_map(|l| l.strip_prefix(&format!("{k}: ")))
                .unwrap_or_else(|| panic!("{k} missing in {}", d.display()))
                .to_string()
        };
        let pos = value("initpos")
            .trim_matches(|c| c == '[' || c == ']')
            .split(',')
            .map(|x| x.trim().parse().unwrap())
            .collect();
        (value("starttime").parse().unwrap(), pos)
    };
    for (d, reference) in [(&k1, "truth.nav"), (&k3, "nav.nav")] {
        // The first pose at or after the first IMU epoch (KF-GINS starts within its IMU file).
        let t_imu = rows(&d.join("imu.txt"))[0][0];
        let first = rows(&d.join(reference))
            .into_iter()
            .find(|r| r[1] >= t_imu)
            .unwrap();
        let (t, pos) = start(d);
        assert_eq!(t, first[1], "{}", d.display());
        assert_eq!(pos, first[2..5].to_vec(), "{}", d.display());
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The shipped slice of the real RTK file imports row for row: the same count, and exported
/// back, each fix's time exactly and its position and standard deviations as written, to the
/// accuracy of the ECEF → geodetic conversion (`fusion::earth::ecef_to_geodetic`: exact to
/// < 0.1 mm by its contract, i.e. < 1e-9° of latitude or longitude, 111 km per degree, and
/// < 1e-4 m of height). The NED standard deviations are rotated into ECEF at the fix and back
/// at the converted position: a latitude or longitude off by δ < 2e-11 rad mixes the axes'
/// variances by a relative δ, far below the bound 1e-9 relative used here.
#[test]
fn real_rtk_positions_import_row_for_row() {
    let _g = MACHINE.shared();
    let dir = out_dir("rtk");
    let slice = repo_root().join("tests/data/kfgins-rtk/GNSS-RTK-slice.txt");
    let rec = dir.join("rtk.mcap");
    let text = std::fs::read_to_string(&slice).unwrap();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split_whitespace().map(|x| x.parse().unwrap()).collect())
        .collect();
    let out = sextant(&[
        "import",
        "kfgins",
        "--gnss",
        s(&slice),
        "--week",
        "2100",
        "--out",
        s(&rec),
    ]);
    assert!(out.contains(&format!("| {} |", rows.len())), "{out}");
    let back = dir.join("back");
    sextant(&["export", "kfgins", s(&rec), "--out", s(&back)]);
    let again: Vec<Vec<f64>> = std::fs::read_to_string(back.join("gnss.txt"))
        .unwrap()
        .lines()
        .map(|l| l.split_whitespace().map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(again.len(), rows.len());
    for (a, b) in rows.iter().zip(&again) {
        assert_eq!(a[0], b[0], "time");
        for (x, y) in a[1..3].iter().zip(&b[1..3]) {
            assert!((x - y).abs() < 1e-9, "{a:?} vs {b:?}");
        }
        assert!((a[3] - b[3]).abs() < 1e-4, "{a:?} vs {b:?}");
        for (x, y) in a[4..7].iter().zip(&b[4..7]) {
            assert!((x - y).abs() < 1e-9 * x, "{a:?} vs {b:?}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_input_is_reported_with_file_line_and_column() {
    let _g = MACHINE.shared();
    let dir = out_dir("bad");
    let imu = dir.join("imu.txt");
    std::fs::write(&imu, "100.000 0 0 0 0 0 0\n100.005 0 0 0 0 0 oops\n").unwrap();
    let out = Command::new(bin("sextant").unwrap())
        .args([
            "import",
            "kfgins",
            "--imu",
            s(&imu),
            "--week",
            "2000",
            "--out",
        ])
        .arg(dir.join("x.mcap"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(&format!(
            "{}: line 2, column 7: \"oops\" is not a number",
            imu.display()
        )),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
