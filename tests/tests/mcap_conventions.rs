//! Recordings follow MCAP's and Foxglove's time conventions, read back with the independent
//! `mcap` reader: every message's `log_time` is the Unix time (UTC) of its time of validity,
//! `publish_time` the wall time of its reception, the summary statistics span the run's real
//! (simulated) UTC times, and recordings of the earlier convention (log time in GPS ns,
//! publish time on CLOCK_MONOTONIC, solutions without their position covariance) still replay
//! bit for bit. Each `foxglove.LocationFix` carries its solution's full position covariance
//! rotated into ENU (type 3, known). The Foxglove well-known-schema
//! messages validate against Foxglove's own published JSON Schemas (`tests/data/foxglove-schemas`,
//! from the npm package `@foxglove/schemas`).

use sextant_tests::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{SystemTime, UNIX_EPOCH};

/// Simulated seconds of the run: the default scenario aligns for 100 s before it navigates, so
/// 120 s give 20 s of solutions (4000 at 200 Hz) on every channel.
const DURATION_S: f64 = 120.0;
const SPEED: f64 = 25.0;

/// Start of the default scenario (`config/scenarios/vehicle.toml`, `start_utc`
/// 2025-03-20T21:00:00Z) as Unix seconds (`date -u -d 2025-03-20T21:00:00Z +%s`).
const START_UNIX_S: i64 = 1_742_504_400;

/// GPS − UTC in 2025: 18 s (TAI − UTC = 37 s since 2017-01-01, IERS Bulletin C; TAI − GPS =
/// 19 s). Unix time of the GPS epoch 1980-01-06: 315 964 800 s. Written out here rather than
/// taken from `fusion::time`, so that the check is independent of the conversion it checks.
const GPS_MINUS_UTC_2025_NS: i64 = 18_000_000_000;
const GPS_EPOCH_UNIX_NS: i64 = 315_964_800_000_000_000;

fn out_dir(name: &str) -> PathBuf {
    tempdir(&format!("mcapconv-{name}"))
}

fn unix_now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64
}

/// The message's own time of validity in GPS ns (Sextant channels' header), if it has one.
fn header_gps_ns(json: &serde_json::Value) -> Option<i64> {
    json.get("header")
        .and_then(|h| h.get("time_ns"))
        .or_else(|| json.get("time_ns"))
        .and_then(serde_json::Value::as_i64)
}

/// A Foxglove `time` field as Unix ns.
fn foxglove_time_ns(t: &serde_json::Value) -> u64 {
    t["sec"].as_u64().unwrap() * 1_000_000_000 + t["nsec"].as_u64().unwrap()
}

fn replay_offline(rec: &Path, out: &Path) -> serde_json::Value {
    sextant_offline(&["replay", "--offline", rec.to_str().unwrap()], out)
}

/// Rewrite a recording into the earlier convention (log time = GPS ns of validity, publish
/// time = CLOCK_MONOTONIC of reception, no time-base metadata), as recordings written before
/// the change are: JSON messages with their JSON Schemas (a protobuf recording's messages are
/// rewritten as JSON, the Foxglove views left out: replay does not read them), and without the
/// solutions' position covariance (`pos_cov_ned_m2`, the last field of `nav`), which
/// recordings of that time did not carry.
fn to_gps_monotonic(bytes: &[u8], out: &Path) {
    let summary = mcap::Summary::read(bytes).unwrap().unwrap();
    let mut metadata = BTreeMap::new();
    for idx in &summary.metadata_indexes {
        let m = mcap::read::metadata(bytes, idx).unwrap();
        metadata.insert(m.name.clone(), m.metadata);
    }
    let time = metadata.remove("sextant/time").expect("time-base metadata");
    let offset: i64 = time["unix_minus_monotonic_ns"].parse().unwrap();
    let mut w = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .create(std::io::BufWriter::new(std::fs::File::create(out).unwrap()))
        .unwrap();
    for (name, m) in metadata {
        w.write_metadata(&mcap::records::Metadata { name, metadata: m })
            .unwrap();
    }
    let mut ids = BTreeMap::new();
    for m in mcap::MessageStream::new(bytes).unwrap() {
        let m = m.unwrap();
        let Some(kind) = msgs::RecordKind::from_topic(&m.channel.topic) else {
            continue;
        };
        let json_bytes = match m.channel.message_encoding.as_str() {
            "json" => m.data.to_vec(),
            _ => {
                let record = msgs::Record::from_protobuf(kind, &m.data).unwrap();
                let mut b = Vec::new();
                record.write_json(&mut b).unwrap();
                b
            }
        };
        let id = *ids.entry(m.channel.id).or_insert_with(|| {
            let schema = match kind {
                msgs::RecordKind::Channel(ch) => msgs::channel_schema(ch).1,
                msgs::RecordKind::SensorAlive => "{}".to_string(),
            };
            let sid = w
                .add_schema(kind.topic(), "jsonschema", schema.as_bytes())
                .unwrap();
            w.add_channel(sid, &m.channel.topic, "json", &BTreeMap::new())
                .unwrap()
        });
        let json: serde_json::Value = serde_json::from_slice(&json_bytes).unwrap();
        let gps = header_gps_ns(&json).unwrap_or(0).max(0) as u64;
        let mono = if m.publish_time == m.log_time {
            0
        } else {
            (m.publish_time as i64 - offset) as u64
        };
        let data = if m.channel.topic == "nav" {
            without_pos_cov(&json_bytes)
        } else {
            json_bytes
        };
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: id,
                sequence: m.sequence,
                log_time: gps,
                publish_time: mono,
            },
            &data,
        )
        .unwrap();
    }
    w.finish().unwrap();
}

/// A solution's JSON text without its `pos_cov_ned_m2` member (cut from the text, so every
/// other number keeps its bits).
fn without_pos_cov(json: &[u8]) -> Vec<u8> {
    let text = std::str::from_utf8(json).unwrap();
    let key = r#","pos_cov_ned_m2":["#;
    let start = text.find(key).expect("solution with its covariance");
    let end = start + text[start..].find(']').unwrap() + 1;
    let cut = format!("{}{}", &text[..start], &text[end..]);
    let v: serde_json::Value = serde_json::from_str(&cut).unwrap();
    assert!(v.get("pos_cov_ned_m2").is_none() && v.get("pos_sigma_ned_m").is_some());
    cut.into_bytes()
}

/// A LocationFix's ENU covariance against its solution's NED one: C·P·Cᵀ with east = north-
/// east-down's second axis, north its first, up its negated third, written out element by
/// element. Returns the north-east correlation coefficient.
fn check_location_fix_covariance(fix: &serde_json::Value, nav: &serde_json::Value) -> f64 {
    let f = |v: &serde_json::Value| -> Vec<f64> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let [nn, ne, nd, ee, ed, dd] = f(&nav["pos_cov_ned_m2"])[..] else {
        panic!("pos_cov_ned_m2 of six: {nav}");
    };
    let expected_enu = [ee, ne, -ed, ne, nn, -nd, -ed, -nd, dd];
    assert_eq!(fix["position_covariance_type"], 3, "{fix}");
    assert_eq!(f(&fix["position_covariance"]), expected_enu, "{fix}\n{nav}");
    // The diagonal is the square of the solution's σ.
    let sigma = f(&nav["pos_sigma_ned_m"]);
    for (var, s) in [nn, ee, dd].iter().zip(&sigma) {
        assert_eq!(var.sqrt(), *s, "{nav}");
    }
    // The north-east correlation coefficient: the tilt of the horizontal error ellipse.
    ne / (nn * ee).sqrt()
}

#[test]
fn default_run_logs_at_utc_validates_against_foxglove_and_replays_in_both_time_bases() {
    let _g = MACHINE.shared();
    let out = out_dir("run");
    let prefix = format!("sextant_mcapconv_{}", std::process::id());
    let wall_start = unix_now_ns();
    let status = Command::new(bin("sextant").unwrap())
        .current_dir(repo_root())
        .args(["run", "--duration", &DURATION_S.to_string()])
        .args(["--speed", &SPEED.to_string(), "--prefix", &prefix, "--out"])
        .arg(&out)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .unwrap();
    let wall_end = unix_now_ns();
    assert!(status.success(), "sextant run failed: {status}");
    let path = out.join("recording.mcap");
    let bytes = std::fs::read(&path).unwrap();

    // The summary statistics start and end at the run's simulated UTC times, within the 1 s
    // the convention promises (the first message is a sample at or just after the start, the
    // last one a status or sample within the last second).
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let stats = summary.stats.expect("statistics record");
    let start_ns = (START_UNIX_S * 1_000_000_000) as u64;
    let end_ns = start_ns + (DURATION_S * 1e9) as u64;
    let s = 1_000_000_000u64;
    assert!(
        stats.message_start_time.abs_diff(start_ns) < s,
        "statistics start at {} ns, the run at {start_ns}",
        stats.message_start_time
    );
    assert!(
        stats.message_end_time.abs_diff(end_ns) < s,
        "statistics end at {} ns, the run at {end_ns}",
        stats.message_end_time
    );
    let run_span = start_ns - s..=end_ns + s;

    // Every message: log_time is the UTC of its header's GPS time (the conversion is exact, the
    // convention promises 1 s); untimed records (header time 0) inside the run; Foxglove
    // timestamps equal the log time; publish_time is a wall time of this test's run.
    let mut validators: BTreeMap<String, jsonschema::Validator> = BTreeMap::new();
    let mut validated: BTreeMap<String, usize> = BTreeMap::new();
    let mut untimed = 0;
    let mut n = 0;
    // The latest solution by log time, and the LocationFixes checked against it (the view is
    // written right after its solution, with the same log time).
    let mut last_nav: Option<(u64, serde_json::Value)> = None;
    let (mut fixes_checked, mut max_ne_correlation) = (0, 0.0f64);
    // The views are written for the first solution of each 100 ms of log time (the default
    // `[recorder] view_rate_hz = 10`), the solutions at the same rate (`solution_rate_hz`).
    const VIEW_PERIOD_NS: u64 = 100_000_000;
    let mut view_slots = std::collections::BTreeSet::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        n += 1;
        let topic = &m.channel.topic;
        let json = decode_message(&m.channel, &m.data).unwrap();
        if topic == "nav" {
            view_slots.insert(m.log_time / VIEW_PERIOD_NS);
            last_nav = Some((m.log_time, json.clone()));
        } else if topic == "nav/location_fix" {
            let (t, nav) = last_nav
                .as_ref()
                .expect("a solution before its LocationFix");
            assert_eq!(*t, m.log_time, "LocationFix without its solution");
            fixes_checked += 1;
            max_ne_correlation =
                max_ne_correlation.max(check_location_fix_covariance(&json, nav).abs());
        }
        match header_gps_ns(&json) {
            Some(t) if t > 0 => {
                let utc = (t - GPS_MINUS_UTC_2025_NS + GPS_EPOCH_UNIX_NS) as u64;
                assert!(
                    m.log_time.abs_diff(utc) < s,
                    "{topic}: log_time {} for UTC {utc}",
                    m.log_time
                );
            }
            Some(_) => {
                untimed += 1;
                assert!(
                    run_span.contains(&m.log_time),
                    "{topic}: untimed record at log_time {}",
                    m.log_time
                );
            }
            None => {
                let t = json
                    .get("timestamp")
                    .or_else(|| json.pointer("/transforms/0/timestamp"))
                    .unwrap_or_else(|| panic!("{topic}: neither header nor timestamp: {json}"));
                assert_eq!(foxglove_time_ns(t), m.log_time, "{topic}");
            }
        }
        assert!(
            run_span.contains(&m.log_time),
            "{topic}: log_time {} outside the run",
            m.log_time
        );
        assert!(
            m.publish_time == m.log_time || (wall_start..=wall_end).contains(&m.publish_time),
            "{topic}: publish_time {} not a wall time of the run [{wall_start}, {wall_end}]",
            m.publish_time
        );
        let schema = m.channel.schema.as_ref().unwrap();
        if let Some(official) = foxglove_json_schema(&schema.name).unwrap() {
            let v = validators
                .entry(schema.name.clone())
                .or_insert_with(|| jsonschema::validator_for(&official).unwrap());
            if let Err(e) = v.validate(&json) {
                panic!("{topic} ({}): {e}\n{json}", schema.name);
            }
            *validated.entry(schema.name.clone()).or_default() += 1;
        }
    }
    // The default run navigates 20 s: 4 000 solutions at 200 Hz, of which the recording keeps
    // the first of each 100 ms, each with its views.
    assert!(
        view_slots.len() >= 190,
        "{} view intervals",
        view_slots.len()
    );
    for name in [
        "foxglove.LocationFix",
        "foxglove.PoseInFrame",
        "foxglove.FrameTransforms",
    ] {
        assert_eq!(
            validated.get(name).copied().unwrap_or(0),
            view_slots.len(),
            "{name}: {validated:?}"
        );
    }
    // Every fix carried its solution's full covariance.
    assert_eq!(
        fixes_checked,
        view_slots.len(),
        "{fixes_checked} LocationFixes"
    );
    eprintln!(
        "{fixes_checked} LocationFixes carry their solution's covariance in ENU; largest |north-east correlation| {max_ne_correlation:.3e}"
    );
    eprintln!(
        "{n} messages, {untimed} without a time of validity; statistics {} .. {} ns; validated against Foxglove's schemas: {validated:?}",
        stats.message_start_time, stats.message_end_time
    );

    // Offline replay reproduces the solution bit for bit from this recording and from the same
    // recording in the earlier time base.
    let replayed = replay_offline(&path, &out_dir("replay-unix"));
    let legacy = out.join("recording-gps-monotonic.mcap");
    to_gps_monotonic(&bytes, &legacy);
    let replayed_legacy = replay_offline(&legacy, &out_dir("replay-legacy"));
    for r in [&replayed, &replayed_legacy] {
        assert_eq!(r["replay"]["bit_exact"], true, "{r}");
        assert!(
            r["replay"]["solutions_bit_identical"].as_u64().unwrap() >= 190,
            "{r}"
        );
    }
    assert_eq!(
        replayed["replay"]["solutions_bit_identical"],
        replayed_legacy["replay"]["solutions_bit_identical"]
    );
}
