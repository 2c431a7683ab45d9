//! Bad input: never fused, never a crash, always counted or named.
//!
//! - End to end: a test publisher process sends NaN, infinite, impossible and out-of-order
//!   samples, a duplicated and a skipped sequence number and a flood over iceoryx2 to a real
//!   `sextant-fusion`; its status counts exactly the bad ones in `rejected_invalid`, the skip is
//!   accepted (a gap in the recording, not a rejection), the flood is absorbed by bounded queues
//!   and the daemon stays alive and small.
//! - A malformed configuration or scenario given to the real binaries: an error naming the file,
//!   the key and (for TOML syntax and type errors) the line.
//! - Property tests: arbitrary bit patterns in every field of every message never panic the
//!   navigator, never leave a non-finite state, and a rejected sample changes nothing; arbitrary
//!   bytes and mutations of the shipped configuration and scenarios, and truncated or corrupted
//!   recordings, give errors, never panics.

use fusion::navigator::Navigator;
use msgs::{BaroSample, GnssSample, ImuSample, OdometerSample, SensorId, StarTrackerSample};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use proptest::prelude::*;
use sextant_tests::*;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

fn rss_peak_mib(pid: u32) -> f64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|v| v.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |k| k / 1024.0)
}

/// Every message of a recording up to the first undecodable byte (NaN inputs come out as JSON
/// null, so the schema check of `read_recording` is not wanted here).
fn messages(path: &Path) -> Vec<(String, serde_json::Value)> {
    let bytes = std::fs::read(path).unwrap();
    let mut out = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let Ok(m) = m else { break };
        if let Ok(v) = decode_message(&m.channel, &m.data) {
            out.push((m.channel.topic.clone(), v));
        }
    }
    out
}

#[test]
fn bad_samples_over_iceoryx2_are_counted_never_fused_and_the_daemon_survives() {
    let _g = MACHINE.exclusive();
    let dir = tempdir("bad-input");
    let prefix = format!("sextant_bad_{}", std::process::id());
    let rec_path = dir.join("recording.mcap");
    let root = repo_root();
    let mut fusion = Command::new(bin("sextant-fusion").unwrap())
        .current_dir(&root)
        .args(["--config", "config/sextant.toml", "--prefix", &prefix])
        .args(["--speed", "1", "--out"])
        .arg(&rec_path)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(dir.join("fusion.log")).unwrap())
        .spawn()
        .unwrap();
    let flood = 20_000u64;
    let out = Command::new(env!("CARGO_BIN_EXE_sextant-test-publisher"))
        .args(["--prefix", &prefix, "--flood", &flood.to_string()])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "publisher: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let sent: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // Two status periods, so that the last status reflects everything.
    std::thread::sleep(Duration::from_millis(2200));
    assert!(
        fusion.try_wait().unwrap().is_none(),
        "the fusion daemon died on bad input"
    );
    let rss = rss_peak_mib(fusion.id());
    kill(Pid::from_raw(fusion.id() as i32), Signal::SIGTERM).unwrap();
    let st = wait_exit(&mut fusion, "fusion stopping", Duration::from_secs(20));
    let log = std::fs::read_to_string(dir.join("fusion.log")).unwrap_or_default();
    assert!(st.success(), "fusion exit {st}\n{log}");

    let msgs = messages(&rec_path);
    let status = msgs
        .iter()
        .rev()
        .find(|(t, _)| t == "status")
        .map(|(_, v)| v.clone())
        .expect("a status");
    let h = |s: SensorId, field: &str| {
        int(&status, &format!("/sensors/{}/{field}", s as usize)).unwrap() as u64
    };
    let n = |k: &str| sent[k].as_u64().unwrap();
    // Exactly the bad samples are rejected, per sensor — plus, for the IMU, the samples held
    // as candidates of a new time base: the flood loses whole runs of samples in transport
    // (bounded queues), a gap of more than 1 s of IMU time that the navigator cannot bridge,
    // so it holds the samples after it until CONFIRM_SAMPLES consecutive ones confirm the new
    // time base and it re-initialises (navigator's gap policy). A candidate run cut short by
    // a further loss holds fewer, so the held samples have their own counter: at least
    // CONFIRM_SAMPLES − 1 per re-initialisation.
    let reinit = int(&status, "/reinitializations").unwrap() as u64;
    let held = int(&status, "/imu_held_at_time_jump").unwrap() as u64;
    assert_eq!(
        h(SensorId::Imu, "rejected_invalid"),
        n("imu_bad") + held,
        "{status}"
    );
    assert!(
        held >= reinit * u64::from(fusion::navigator::CONFIRM_SAMPLES - 1),
        "{status}"
    );
    assert_eq!(
        h(SensorId::Gnss, "rejected_invalid"),
        n("gnss_bad"),
        "{status}"
    );
    assert_eq!(
        h(SensorId::StarTracker, "rejected_invalid"),
        n("star_tracker_bad")
    );
    assert_eq!(h(SensorId::Odometer, "rejected_invalid"), n("odometer_bad"));
    assert_eq!(h(SensorId::Baro, "rejected_invalid"), n("baro_bad"));
    // Nothing rejected was fused: every IMU sample the daemon received is either fused or
    // rejected, and the transport lost at most the flood's excess (bounded queues).
    let received = h(SensorId::Imu, "received");
    let fused = h(SensorId::Imu, "fused");
    assert_eq!(
        fused + h(SensorId::Imu, "rejected_invalid"),
        received,
        "{status}"
    );
    assert!(received <= n("imu_sent"));
    let lost = n("imu_sent") - received;
    assert!(lost <= flood, "lost {lost} of a flood of {flood}");
    // The skipped sequence number is a gap in what was received, not a rejection (the exact
    // rejection count above excludes it): the recorded IMU stream (every received sample,
    // rejected ones included) goes from the duplicated 100 straight to 119.
    let seqs: Vec<u64> = msgs
        .iter()
        .filter(|(t, _)| t == "imu")
        .filter_map(|(_, v)| int(v, "/header/seq"))
        .map(|s| s as u64)
        .collect();
    let skipped = n("imu_seq_skipped");
    assert!(
        seqs.windows(2).any(|w| w == [100, 110 + skipped]),
        "no jump 100 -> {} in the recorded IMU sequence",
        110 + skipped
    );
    assert!(!seqs.iter().any(|s| (110..110 + skipped).contains(s)));
    // The status counts the missing sequence numbers between accepted samples: at least the
    // skipped ones; at most everything that was not accepted (skipped, lost, rejected).
    let gaps = h(SensorId::Imu, "seq_gaps");
    let rejected = h(SensorId::Imu, "rejected_invalid");
    assert!(
        gaps >= skipped && gaps <= skipped + lost + rejected,
        "seq_gaps {gaps}: skipped {skipped}, lost {lost}, rejected {rejected}"
    );
    let recorded_dropped = int(&status, "/records_dropped").unwrap();
    eprintln!(
        "sent {} IMU samples ({flood} in a flood), received {received}, lost in transport {lost}, \
         sequence gaps {gaps}, rejected {}, fused {fused}; records dropped by the recorder {recorded_dropped}; \
         fusion peak RSS {rss:.1} MiB",
        n("imu_sent"),
        h(SensorId::Imu, "rejected_invalid")
    );
    // Bounded queues: the flood does not grow the daemon.
    assert!(rss < 64.0, "fusion peak RSS {rss} MiB after the flood");
}

/// Run a binary that must fail; its stderr.
fn failing(cmd: &mut Command) -> String {
    let out = cmd.output().unwrap();
    assert!(
        !out.status.success(),
        "expected a failure of {cmd:?}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stderr).to_string()
}

#[test]
fn malformed_config_and_scenario_are_named_by_file_key_and_line() {
    let dir = tempdir("bad-config");
    let root = repo_root();
    // Copy the configuration, then break one thing at a time.
    let cfg_dir = dir.join("config");
    std::fs::create_dir_all(cfg_dir.join("scenarios")).unwrap();
    let sys = std::fs::read_to_string(root.join("config/sextant.toml")).unwrap();
    let filter = std::fs::read_to_string(root.join("config/filter.toml")).unwrap();
    std::fs::write(cfg_dir.join("filter.toml"), &filter).unwrap();
    // The sensor grades and the shared world files the scenarios name.
    for sub in ["sensors", "worlds"] {
        std::fs::create_dir_all(cfg_dir.join(sub)).unwrap();
        for e in std::fs::read_dir(root.join("config").join(sub))
            .unwrap()
            .flatten()
        {
            std::fs::copy(e.path(), cfg_dir.join(sub).join(e.file_name())).unwrap();
        }
    }
    let scen = std::fs::read_to_string(root.join("config/scenarios/static_site.toml")).unwrap();
    std::fs::write(cfg_dir.join("scenarios/vehicle.toml"), &scen).unwrap();
    let sextant = bin("sextant").unwrap();
    let run = |config: &Path, scenario: Option<&Path>| {
        let mut c = Command::new(&sextant);
        c.current_dir(&root)
            .args([
                "run",
                "--duration",
                "1",
                "--prefix",
                "sextant_bad_cfg",
                "--config",
            ])
            .arg(config);
        if let Some(s) = scenario {
            c.arg("--scenario").arg(s);
        }
        c.arg("--out").arg(dir.join("out"));
        failing(&mut c)
    };

    // A wrong type in the system config: file, key and line.
    let bad = cfg_dir.join("sextant.toml");
    std::fs::write(
        &bad,
        sys.replace("max_restarts = 3", "max_restarts = \"three\""),
    )
    .unwrap();
    let line = 1 + sys
        .lines()
        .position(|l| l.starts_with("max_restarts"))
        .unwrap();
    let e = run(&bad, None);
    assert!(e.contains(&bad.display().to_string()), "{e}");
    assert!(e.contains("max_restarts"), "{e}");
    assert!(e.contains(&format!("line {line}")), "{e}");
    // A value out of range: file and dotted key.
    std::fs::write(&bad, sys.replace("imu = 50.0", "imu = -50.0")).unwrap();
    let e = run(&bad, None);
    assert!(e.contains(&bad.display().to_string()), "{e}");
    assert!(e.contains("fusion.deadlines_ms.imu"), "{e}");
    // Not TOML at all.
    std::fs::write(&bad, "[system\nprefix = ").unwrap();
    let e = run(&bad, None);
    assert!(
        e.contains(&bad.display().to_string()) && e.contains("line 1"),
        "{e}"
    );
    // An unknown key in the filter tuning: the filter file and the key.
    std::fs::write(&bad, &sys).unwrap();
    std::fs::write(
        cfg_dir.join("filter.toml"),
        format!("alignment_seconds = 5.0\n{filter}"),
    )
    .unwrap();
    let e = run(&bad, None);
    assert!(
        e.contains("filter.toml") && e.contains("alignment_seconds"),
        "{e}"
    );
    std::fs::write(cfg_dir.join("filter.toml"), &filter).unwrap();

    // Scenario: a negative rate, a typo'd key, a bad date.
    let sc = cfg_dir.join("scenarios/broken.toml");
    let cases = [
        (
            scen.replace("rate_hz = 200.0", "rate_hz = -200.0"),
            "imu.rate_hz",
        ),
        (scen.replace("heading_deg", "headin_deg"), "headin_deg"),
        (
            scen.replace("2025-03-20T21:00:00", "2025-13-45T99:00:00"),
            "start_utc",
        ),
    ];
    for (text, key) in cases {
        std::fs::write(&sc, text).unwrap();
        let e = run(&bad, Some(&sc));
        assert!(e.contains(&sc.display().to_string()), "{e}");
        assert!(e.contains(key), "{key}: {e}");
    }
    // The same broken scenario given to a driver directly.
    std::fs::write(&sc, scen.replace("[site]", "[site]\nlat_deg = \"north\"")).unwrap();
    let e = failing(
        Command::new(bin("sextant-sim-imu").unwrap())
            .arg("--scenario")
            .arg(&sc)
            .args(["--prefix", "sextant_bad_cfg", "--speed", "1"]),
    );
    assert!(
        e.contains(&sc.display().to_string()) && e.contains("lat_deg"),
        "{e}"
    );
}

// ------------------------------------------------------------------ property tests

/// The aligned static navigator shared with the fuzz target `samples` (fuzz/src/fixture.rs).
#[path = "../../fuzz/src/fixture.rs"]
mod fixture;
use fixture::state_is_finite;

/// A static navigator that has aligned (IMU and GNSS of a level site), for the bit-pattern
/// properties.
fn aligned() -> (Navigator, ImuSample) {
    let text = std::fs::read_to_string(repo_root().join("config/filter.toml")).unwrap();
    fixture::aligned_static_navigator(&text).unwrap()
}

/// f64 from raw bits: every pattern, NaNs, infinities, subnormals included.
fn bits() -> impl Strategy<Value = f64> {
    prop_oneof![
        any::<u64>().prop_map(f64::from_bits),
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        Just(0.0),
        -1e3f64..1e3,
    ]
}

fn header() -> impl Strategy<Value = msgs::Header> {
    (any::<i64>(), any::<u64>(), any::<u32>(), any::<u64>()).prop_map(|(t, seq, st, mono)| {
        msgs::Header {
            time_ns: t,
            seq,
            status: st,
            reserved: 0,
            send_mono_ns: mono,
        }
    })
}

#[derive(Debug, Clone)]
enum AnyMsg {
    Imu(Box<ImuSample>),
    Star(StarTrackerSample),
    Gnss(Box<GnssSample>),
    Odo(OdometerSample),
    Baro(BaroSample),
}

fn any_msg() -> impl Strategy<Value = AnyMsg> {
    let imu = (
        header(),
        bits(),
        [bits(), bits(), bits()],
        [bits(), bits(), bits()],
        any::<u32>(),
        proptest::collection::vec(bits(), 8 * 6),
        bits(),
    )
        .prop_map(|(h, dt, da, dv, n, ch, turn)| {
            let mut s = ImuSample {
                header: h,
                dt_s: dt,
                delta_angle_rad: da,
                delta_velocity_m_s: dv,
                n_channels: n % 16,
                turntable_angle_rad: turn,
                ..Default::default()
            };
            for i in 0..msgs::MAX_IMU_CHANNELS {
                s.channel_axis[i] = [ch[6 * i], ch[6 * i + 1], ch[6 * i + 2]];
                s.channel_delta_angle_rad[i] = ch[6 * i + 3];
                s.channel_delta_velocity_m_s[i] = ch[6 * i + 4];
                s.channel_temperature_c[i] = ch[6 * i + 5];
            }
            AnyMsg::Imu(Box::new(s))
        });
    let star = (
        header(),
        [bits(), bits(), bits(), bits()],
        bits(),
        bits(),
        any::<u32>(),
        any::<u32>(),
    )
        .prop_map(|(h, q, sc, sr, n, v)| {
            AnyMsg::Star(StarTrackerSample {
                header: h,
                q_sensor_icrf: q,
                sigma_cross_rad: sc,
                sigma_roll_rad: sr,
                n_stars: n,
                valid: v % 2,
            })
        });
    let gnss = (
        header(),
        any::<u32>(),
        any::<u32>(),
        [bits(), bits(), bits()],
        [bits(), bits(), bits()],
        proptest::collection::vec(bits(), 18),
        bits(),
    )
        .prop_map(|(h, fv, ns, p, v, cov, pdop)| {
            let mut g = GnssSample {
                header: h,
                fix_valid: fv % 2,
                n_satellites: ns % 64,
                pos_ecef_m: p,
                vel_ecef_m_s: v,
                pdop,
                ..Default::default()
            };
            g.pos_cov_ecef_m2.copy_from_slice(&cov[..9]);
            g.vel_cov_ecef_m2_s2.copy_from_slice(&cov[9..]);
            AnyMsg::Gnss(Box::new(g))
        });
    let odo = (header(), bits(), bits(), bits()).prop_map(|(h, dt, d, v)| {
        AnyMsg::Odo(OdometerSample {
            header: h,
            dt_s: dt,
            distance_m: d,
            speed_m_s: v,
        })
    });
    let baro = (header(), bits(), bits()).prop_map(|(h, p, t)| {
        AnyMsg::Baro(BaroSample {
            header: h,
            pressure_pa: p,
            temperature_c: t,
        })
    });
    prop_oneof![imu, star, gnss, odo, baro]
}

fn push(nav: &mut Navigator, m: &AnyMsg) -> (SensorId, bool) {
    match m {
        AnyMsg::Imu(s) => (SensorId::Imu, nav.push_imu(s).is_ok()),
        AnyMsg::Star(s) => (SensorId::StarTracker, nav.push_star_tracker(s).is_ok()),
        AnyMsg::Gnss(s) => (SensorId::Gnss, nav.push_gnss(s).is_ok()),
        AnyMsg::Odo(s) => (SensorId::Odometer, nav.push_odometer(s).is_ok()),
        AnyMsg::Baro(s) => (SensorId::Baro, nav.push_baro(s).is_ok()),
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// Arbitrary bit patterns in every field of every message: no panic; a rejected sample is
    /// counted once in `rejected_invalid` and leaves the state and covariance bit-identical;
    /// whatever is accepted leaves them finite; the next good IMU sample still navigates.
    #[test]
    fn navigator_survives_arbitrary_samples(msgs in proptest::collection::vec(any_msg(), 1..12)) {
        let (mut nav, mut last) = aligned();
        for m in &msgs {
            let before = *nav.nav_state();
            let p = *nav.covariance();
            let h0 = nav.health();
            let (id, ok) = push(&mut nav, m);
            let h1 = nav.health();
            prop_assert_eq!(h1[id as usize].received, h0[id as usize].received + 1);
            if !ok {
                prop_assert_eq!(h1[id as usize].rejected_invalid, h0[id as usize].rejected_invalid + 1);
                prop_assert_eq!(*nav.nav_state(), before);
                prop_assert_eq!(*nav.covariance(), p);
            }
            prop_assert!(state_is_finite(&nav));
        }
        // A good IMU sample after the last accepted one still gives a finite solution (unless
        // an accepted arbitrary sample moved the IMU time far ahead).
        last.header.seq = last.header.seq.wrapping_add(1_000_003);
        last.header.time_ns = nav.time().ns.max(last.header.time_ns) + 5_000_000;
        if let Ok(Some(sol)) = nav.push_imu(&last) {
            prop_assert!(sol.pos_ecef_m.iter().all(|v| v.is_finite()));
        }
    }

    /// Arbitrary text as the system configuration: an error naming the file, never a panic.
    #[test]
    fn system_config_never_panics(text in "\\PC{0,400}") {
        let f = Path::new("/nonexistent/sextant.toml");
        if let Err(e) = sextant_daemons::config::SystemConfig::parse(&text, f)
            .and_then(|c| c.validate(f).map(|_| c))
        {
            prop_assert!(e.to_string().contains("/nonexistent/sextant.toml"), "{}", e);
        }
    }

    /// The shipped configuration with one line deleted or one value replaced: an error names
    /// the file, never a panic.
    #[test]
    fn mutated_system_config_never_panics(line in 0usize..80, junk in "[-a-z0-9.\"\\[\\]=]{0,12}", delete in any::<bool>()) {
        let text = std::fs::read_to_string(repo_root().join("config/sextant.toml")).unwrap();
        let mut lines: Vec<String> = text.lines().map(String::from).collect();
        let k = line % lines.len();
        if delete {
            lines.remove(k);
        } else if let Some((key, _)) = lines[k].clone().split_once('=') {
            lines[k] = format!("{key}= {junk}");
        } else {
            lines[k] = junk;
        }
        let f = Path::new("cfg/sextant.toml");
        if let Err(e) = sextant_daemons::config::SystemConfig::parse(&lines.join("\n"), f)
            .and_then(|c| c.validate(f).map(|_| c))
        {
            prop_assert!(e.to_string().contains("cfg/sextant.toml"), "{}", e);
        }
    }

    /// The filter tuning with one value replaced: parse + validate error or a valid config.
    #[test]
    fn mutated_filter_config_never_panics(line in 0usize..200, junk in "[-a-z0-9.e\"]{0,10}") {
        let text = std::fs::read_to_string(repo_root().join("config/filter.toml")).unwrap();
        let mut lines: Vec<String> = text.lines().map(String::from).collect();
        let k = line % lines.len();
        if let Some((key, _)) = lines[k].clone().split_once('=') {
            lines[k] = format!("{key}= {junk}");
        }
        let f = Path::new("cfg/filter.toml");
        if let Err(e) = sextant_daemons::config::parse_navigator_config(&lines.join("\n"), f) {
            prop_assert!(e.to_string().contains("cfg/filter.toml"), "{}", e);
        }
    }

    /// Arbitrary text and mutated shipped scenarios: an error naming the file, never a panic.
    #[test]
    fn mutated_scenario_never_panics(which in any::<bool>(), line in 0usize..80, junk in "[-a-z0-9.\"\\[\\]={}:T]{0,14}") {
        let name = if which { "vehicle.toml" } else { "static_site.toml" };
        let path = repo_root().join("config/scenarios").join(name);
        let text = std::fs::read_to_string(&path).unwrap();
        let mut lines: Vec<String> = text.lines().map(String::from).collect();
        let k = line % lines.len();
        if let Some((key, _)) = lines[k].clone().split_once('=') {
            lines[k] = format!("{key}= {junk}");
        } else {
            lines[k] = junk;
        }
        if let Err(e) = drivers_sim::scenario::Scenario::from_toml_str(&lines.join("\n"), &path) {
            prop_assert!(e.to_string().contains(name), "{}", e);
        }
    }
}

/// A small real recording (the daemon's recorder), made once.
fn small_recording() -> &'static [u8] {
    use std::sync::OnceLock;
    static REC: OnceLock<Vec<u8>> = OnceLock::new();
    REC.get_or_init(|| {
        use sextant_daemons::recorder::{Record, Recorder, RecorderOptions};
        let dir = tempdir("mcap-fuzz");
        let path = dir.join("small.mcap");
        let rec = Recorder::start(
            &path,
            &RecorderOptions {
                chunk_size_bytes: 4096,
                ..Default::default()
            },
        )
        .unwrap();
        for k in 0..300u64 {
            let mut s = ImuSample::default();
            s.header.seq = k + 1;
            s.header.time_ns = 1_398_556_800_000_000_000 + k as i64 * 5_000_000;
            s.dt_s = 0.005;
            rec.record(Record::Imu(s), k);
            if k % 10 == 0 {
                let n = msgs::NavSolution {
                    header: s.header,
                    q_ned_body: [1.0, 0.0, 0.0, 0.0],
                    ..Default::default()
                };
                rec.record(Record::Nav(n), k);
            }
        }
        rec.finish().unwrap();
        std::fs::read(&path).unwrap()
    })
}

fn write_tmp(name: &str, bytes: &[u8]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("sextant-mcap-prop-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// Byte offset of the first chunk record (opcode 0x06) of an MCAP file written by the recorder.
fn first_chunk_offset(bytes: &[u8]) -> usize {
    let mut at = 8; // magic
    loop {
        let op = bytes[at];
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
        if op == 0x06 {
            return at;
        }
        at += 9 + len;
    }
}

/// A chunk whose header claims 2^62 bytes uncompressed: the reader reports the offset instead
/// of trying to allocate it; the messages before it are still returned.
#[test]
fn chunk_claiming_an_absurd_size_is_named_by_offset() {
    let mut bytes = small_recording().to_vec();
    let at = first_chunk_offset(&bytes);
    // Chunk body: message_start_time u64, message_end_time u64, uncompressed_size u64, ...
    let size_at = at + 9 + 16;
    bytes[size_at..size_at + 8].copy_from_slice(&(1u64 << 62).to_le_bytes());
    let p = write_tmp("huge_chunk.mcap", &bytes);
    let out = sextant_daemons::recording::read_all(&p).unwrap();
    let e = out.error.expect("an error").to_string();
    assert!(e.contains(&format!("offset {at}")), "{e}");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 128, ..ProptestConfig::default() })]

    /// A truncated or corrupted recording given to the recording reader (behind `sextant
    /// replay` and `sextant report`): whatever was readable plus an error naming the byte offset,
    /// never a panic; a cut recording yields a prefix of the intact one's messages.
    #[test]
    fn corrupt_recording_never_panics(cut in 0usize..100_000, flips in proptest::collection::vec((0usize..100_000, any::<u8>()), 0..8)) {
        let intact = small_recording();
        let mut bytes = intact.to_vec();
        for (at, x) in &flips {
            let n = bytes.len();
            bytes[at % n] ^= x;
        }
        bytes.truncate(cut % (bytes.len() + 1));
        let p = write_tmp("corrupt.mcap", &bytes);
        match sextant_daemons::recording::read_all(&p) {
            Ok(out) => {
                if let Some(e) = &out.error {
                    prop_assert!(e.to_string().contains("offset"), "{}", e);
                }
                if flips.is_empty() {
                    let full = sextant_daemons::recording::read_all(&write_tmp("intact.mcap", intact)).unwrap();
                    prop_assert!(full.error.is_none());
                    prop_assert!(out.entries.len() <= full.entries.len());
                    for (a, b) in out.entries.iter().zip(&full.entries) {
                        prop_assert_eq!(a.log_time_ns, b.log_time_ns);
                        prop_assert_eq!(&a.topic, &b.topic);
                    }
                }
            }
            Err(e) => prop_assert!(!e.to_string().is_empty()),
        }
    }
}

/// The analysis behind `sextant run`'s summary (regression: with `mcap::MessageStream`, which
/// in mcap 0.26 sets no record length limit, such a chunk made it allocate the claimed size and
/// abort): an error or a partial summary, never an abort.
#[test]
fn analysis_of_a_chunk_claiming_an_absurd_size_is_an_error() {
    let mut bytes = small_recording().to_vec();
    let at = first_chunk_offset(&bytes);
    let size_at = at + 9 + 16;
    bytes[size_at..size_at + 8].copy_from_slice(&(1u64 << 62).to_le_bytes());
    let p = write_tmp("huge_chunk_analysis.mcap", &bytes);
    let _ = sextant_lab::analysis::analyze_recording(&p, &[]);
}

/// A non-finite input value has no JSON encoding (serde_json would write `null`, which the
/// schema and the reader reject, failing its whole chunk): a JSON recording keeps such a record
/// on `fusion/non_finite_input` in `Debug` form, and every other record stays readable. A
/// protobuf recording holds it on its own topic, its NaN bit for bit.
#[test]
fn recording_with_a_nan_input_stays_readable() {
    use sextant_daemons::recorder::{Record, RecordingEncoding};
    let (json, _) = record_with_a_nan(RecordingEncoding::Json);
    let imu = json
        .iter()
        .filter(|e| matches!(e.record, Some(Record::Imu(_))))
        .count();
    assert_eq!(imu, 9, "the nine finite samples on their own topic");
    let bad: Vec<_> = json
        .iter()
        .filter(|e| &*e.topic == sextant_daemons::recorder::NON_FINITE_TOPIC)
        .collect();
    assert_eq!(bad.len(), 1, "the NaN sample kept on the non-finite topic");

    let (pb, nan_bits) = record_with_a_nan(RecordingEncoding::Protobuf);
    let imu: Vec<_> = pb
        .iter()
        .filter_map(|e| match &e.record {
            Some(Record::Imu(s)) => Some(s),
            _ => None,
        })
        .collect();
    assert_eq!(imu.len(), 10, "every sample on its own topic");
    assert_eq!(imu[5].delta_angle_rad[0].to_bits(), nan_bits);
}

/// Ten IMU samples, the sixth with a NaN (a payload of its own), recorded in `encoding`; the
/// entries read back (no error) and the NaN's bits.
fn record_with_a_nan(
    encoding: sextant_daemons::recorder::RecordingEncoding,
) -> (Vec<sextant_daemons::recording::Entry>, u64) {
    use sextant_daemons::recorder::{Record, Recorder, RecorderOptions};
    let dir = tempdir(&format!("nan-record-{encoding:?}"));
    let path = dir.join("nan.mcap");
    let nan = f64::from_bits(0x7ff8_0000_dead_beef);
    let opts = RecorderOptions {
        encoding,
        ..Default::default()
    };
    let rec = Recorder::start(&path, &opts).unwrap();
    for k in 0..10u64 {
        let mut s = ImuSample::default();
        s.header.seq = k + 1;
        s.header.time_ns = 1_398_556_800_000_000_000 + k as i64 * 5_000_000;
        s.dt_s = 0.005;
        if k == 5 {
            s.delta_angle_rad[0] = nan;
        }
        rec.record(Record::Imu(s), k);
    }
    rec.finish().unwrap();
    let out = sextant_daemons::recording::read_all(&path).unwrap();
    assert!(out.error.is_none(), "{:?}", out.error);
    assert_eq!(out.entries.len(), 10);
    (out.entries, nan.to_bits())
}

/// Regressions found by the `samples` fuzz target: a timestamp 170 years ahead and a subnormal
/// IMU interval were accepted and made the covariance non-finite; both are now rejected and
/// counted, and the next good sample navigates on.
#[test]
fn far_future_time_and_vanishing_interval_are_rejected() {
    let (mut nav, last) = aligned();
    let mut s = last;
    s.header.seq += 1;
    s.header.time_ns = 6_768_910_239_937_855_488;
    assert!(nav.push_imu(&s).is_err());
    let mut s = last;
    s.header.seq += 1;
    s.header.time_ns += 5_000_000;
    s.dt_s = 1.28324e-319;
    assert!(nav.push_imu(&s).is_err());
    let mut g = GnssSample::default();
    g.header.seq = 99_999;
    g.header.time_ns = last.header.time_ns + 2 * 3_600_000_000_000;
    assert!(nav.push_gnss(&g).is_err());
    assert_eq!(nav.health()[SensorId::Imu as usize].rejected_invalid, 2);
    assert_eq!(nav.health()[SensorId::Gnss as usize].rejected_invalid, 1);
    let mut s = last;
    s.header.seq += 1;
    s.header.time_ns += 5_000_000;
    let sol = nav.push_imu(&s).unwrap().expect("navigating");
    assert!(
        sol.pos_sigma_ned_m
            .iter()
            .all(|x| x.is_finite() && *x < 100.0)
    );
    assert!(state_is_finite(&nav));
}
