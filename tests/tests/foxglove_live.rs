//! The live view end to end: a real `sextant run --foxglove 127.0.0.1:PORT` at high speed, and
//! WebSocket clients speaking the Foxglove protocol (subprotocol `foxglove.sdk.v1`, the current
//! name of `foxglove.websocket.v1`) to it. Checked:
//! - the server's `serverInfo` and `advertise` (every bus channel and the Foxglove views, with
//!   the recording's schemas);
//! - a client that subscribes to every channel, takes some frames and vanishes without a close
//!   handshake, and a SIGKILL of the live server itself (restarted by `sextant run` as a
//!   driver is), leave the navigation untouched: the fusion's status keeps counting solutions,
//!   drops nothing, the run completes with a complete recording and the fusion never restarts;
//! - after the restart a new client subscribes to the solution (`nav`, `nav/location_fix`) and
//!   to the status, receives binary `messageData` frames and decodes them: the JSON validates
//!   against the advertised schema, which is the recording's; `logTime` is the Unix time of
//!   the message's GPS time of validity (exactly: the conversion is integer arithmetic, and a
//!   wrong leap-second count would show as whole seconds); the LocationFix validates against
//!   Foxglove's own published schema and its `timestamp` is the same time.

use sextant_tests::*;
use std::collections::BTreeMap;
use std::net::{SocketAddr, TcpStream};
use std::path::PathBuf;
use std::process::Command;
use std::time::{Duration, Instant};
use tungstenite::client::IntoClientRequest;
use tungstenite::{Message, WebSocket};

/// The default scenario aligns for 100 s of simulated time before it publishes solutions; 200 s
/// at 25× are 8 s of wall time, the last 4 s with solutions at 200 Hz.
const DURATION_S: f64 = 200.0;
const SPEED: f64 = 25.0;

/// GPS − UTC in 2025 (18 s, IERS Bulletin C) and the Unix time of the GPS epoch 1980-01-06
/// (315 964 800 s), written out: independent of the conversion under test.
const GPS_MINUS_UTC_2025_NS: i64 = 18_000_000_000;
const GPS_EPOCH_UNIX_NS: i64 = 315_964_800_000_000_000;

fn out_dir(name: &str) -> PathBuf {
    tempdir(&format!("foxlive-{name}"))
}

type Client = WebSocket<TcpStream>;

/// Connect with the Foxglove subprotocol, retrying until `deadline` (the server starts with the
/// run, and restarts after a kill).
fn connect(addr: SocketAddr, deadline: Instant) -> Client {
    loop {
        let attempt = || -> anyhow::Result<Client> {
            let stream = TcpStream::connect_timeout(&addr, Duration::from_millis(500))?;
            stream.set_read_timeout(Some(Duration::from_secs(2)))?;
            let mut req = format!("ws://{addr}").into_client_request()?;
            req.headers_mut()
                .insert("Sec-WebSocket-Protocol", "foxglove.sdk.v1".parse()?);
            let (ws, resp) = tungstenite::client(req, stream)?;
            assert_eq!(
                resp.headers()
                    .get("sec-websocket-protocol")
                    .and_then(|v| v.to_str().ok()),
                Some("foxglove.sdk.v1")
            );
            Ok(ws)
        };
        match attempt() {
            Ok(ws) => return ws,
            Err(e) if Instant::now() < deadline => {
                let _ = e;
                std::thread::sleep(Duration::from_millis(100));
            }
            Err(e) => panic!("no Foxglove server on {addr}: {e}"),
        }
    }
}

/// One advertised channel: topic → (id, schema name, schema).
type Channels = BTreeMap<String, (u64, String, String)>;

/// Read the text messages up to and including the first `advertise`: check `serverInfo`, return
/// the channels.
fn handshake(ws: &mut Client) -> Channels {
    let mut server_info = false;
    loop {
        let Message::Text(t) = ws.read().unwrap() else {
            continue;
        };
        let v: serde_json::Value = serde_json::from_str(&t).unwrap();
        match v["op"].as_str() {
            Some("serverInfo") => {
                assert_eq!(v["name"], "sextant", "{v}");
                server_info = true;
            }
            Some("advertise") => {
                assert!(server_info, "advertise before serverInfo");
                let mut ch = Channels::new();
                for c in v["channels"].as_array().unwrap() {
                    assert_eq!(c["encoding"], "json", "{c}");
                    assert_eq!(c["schemaEncoding"], "jsonschema", "{c}");
                    ch.insert(
                        c["topic"].as_str().unwrap().to_string(),
                        (
                            c["id"].as_u64().unwrap(),
                            c["schemaName"].as_str().unwrap().to_string(),
                            c["schema"].as_str().unwrap().to_string(),
                        ),
                    );
                }
                return ch;
            }
            _ => {}
        }
    }
}

/// Subscribe to `topics`; subscription id k+1 for `topics[k]`.
fn subscribe(ws: &mut Client, channels: &Channels, topics: &[&str]) {
    let subs: Vec<serde_json::Value> = topics
        .iter()
        .enumerate()
        .map(|(k, t)| serde_json::json!({"id": k + 1, "channelId": channels[*t].0}))
        .collect();
    let msg = serde_json::json!({"op": "subscribe", "subscriptions": subs});
    ws.send(Message::Text(msg.to_string().into())).unwrap();
}

/// A binary `messageData` frame: opcode 1, subscription id (u32 LE), log time (u64 LE, ns),
/// then the message.
fn message_data(b: &[u8]) -> (u32, u64, serde_json::Value) {
    assert_eq!(b[0], 1, "opcode");
    let sub = u32::from_le_bytes(b[1..5].try_into().unwrap());
    let t = u64::from_le_bytes(b[5..13].try_into().unwrap());
    (sub, t, serde_json::from_slice(&b[13..]).unwrap())
}

fn utc_of_gps(gps_ns: i64) -> u64 {
    (gps_ns - GPS_MINUS_UTC_2025_NS + GPS_EPOCH_UNIX_NS) as u64
}

#[test]
fn live_solution_over_foxglove_websocket_and_clients_never_disturb_navigation() {
    let _g = MACHINE.exclusive();
    let out = out_dir("run");
    let prefix = format!("sextant_foxlive_{}", std::process::id());
    let addr: SocketAddr = ([127, 0, 0, 1], free_port()).into();
    let log = std::fs::File::create(out.join("sextant.log")).unwrap();
    let mut run = Command::new(bin("sextant").unwrap())
        .current_dir(repo_root())
        .args(["run", "--duration", &DURATION_S.to_string()])
        .args(["--speed", &SPEED.to_string(), "--prefix", &prefix])
        .args(["--foxglove", &addr.to_string(), "--out"])
        .arg(out.join("run"))
        .stdout(log.try_clone().unwrap())
        .stderr(log)
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    let deadline = t0 + Duration::from_secs(60);

    // A client that subscribes to everything, reads a little, and vanishes without closing.
    let mut rude = connect(addr, deadline);
    let channels = handshake(&mut rude);
    for ch in msgs::Channel::ALL {
        let (name, schema) = msgs::channel_schema(ch);
        let (_, got_name, got_schema) = &channels[ch.name()];
        assert_eq!(
            (got_name.as_str(), got_schema),
            (name, &schema),
            "{}",
            ch.name()
        );
    }
    for t in ["nav/location_fix", "nav/pose", "tf", "status/plot"] {
        assert!(channels.contains_key(t), "{t} not advertised: {channels:?}");
    }
    let all: Vec<&str> = channels.keys().map(String::as_str).collect();
    subscribe(&mut rude, &channels, &all);
    let mut frames = 0;
    while frames < 50 && Instant::now() < deadline {
        if let Ok(Message::Binary(_)) = rude.read() {
            frames += 1;
        }
    }
    assert_eq!(
        frames, 50,
        "the subscribed-to-everything client got {frames} frames"
    );
    rude.get_mut().shutdown(std::net::Shutdown::Both).unwrap();
    drop(rude);

    // The live server dies; `sextant run` restarts it.
    let server = pid_of(&prefix, "sextant-foxglove").expect("sextant-foxglove running");
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(server),
        nix::sys::signal::Signal::SIGKILL,
    )
    .unwrap();
    std::thread::sleep(Duration::from_millis(200));

    let mut ws = connect(addr, deadline);
    let channels = handshake(&mut ws);
    let topics = ["nav", "nav/location_fix", "status"];
    subscribe(&mut ws, &channels, &topics);
    let validator = |topic: &str| {
        let schema: serde_json::Value = serde_json::from_str(&channels[topic].2).unwrap();
        jsonschema::validator_for(&schema).unwrap()
    };
    let (v_nav, v_fix, v_status) = (
        validator("nav"),
        validator("nav/location_fix"),
        validator("status"),
    );
    let foxglove_fix: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(repo_root().join("tests/data/foxglove-schemas/LocationFix.json"))
            .unwrap(),
    )
    .unwrap();
    let v_foxglove_fix = jsonschema::validator_for(&foxglove_fix).unwrap();
    let (mut navs, mut fixes) = (0, 0);
    let mut statuses: Vec<serde_json::Value> = Vec::new();
    // Statuses come at 1 Hz of wall time; those after the first solution show the counting.
    while (navs < 200 || fixes < 200 || statuses.len() < 2) && Instant::now() < deadline {
        let Ok(Message::Binary(b)) = ws.read() else {
            continue;
        };
        let (sub, log_time, json) = message_data(&b);
        match topics[sub as usize - 1] {
            "nav" => {
                assert!(v_nav.is_valid(&json), "nav: {json}");
                let gps = int(&json, "/header/time_ns").unwrap();
                assert_eq!(log_time, utc_of_gps(gps), "nav logTime of GPS {gps}");
                navs += 1;
            }
            "nav/location_fix" => {
                assert!(v_fix.is_valid(&json), "location_fix: {json}");
                assert!(
                    v_foxglove_fix.is_valid(&json),
                    "Foxglove LocationFix: {json}"
                );
                let ts = int(&json, "/timestamp/sec").unwrap() as u64 * 1_000_000_000
                    + int(&json, "/timestamp/nsec").unwrap() as u64;
                assert_eq!(ts, log_time);
                fixes += 1;
            }
            _ => {
                assert!(v_status.is_valid(&json), "status: {json}");
                let gps = int(&json, "/header/time_ns").unwrap();
                if gps > 0 {
                    assert_eq!(log_time, utc_of_gps(gps), "status logTime of GPS {gps}");
                }
                if navs > 0 {
                    statuses.push(json);
                }
            }
        }
    }
    assert!(
        navs >= 200 && fixes >= 200 && statuses.len() >= 2,
        "received {navs} solutions, {fixes} fixes, {} statuses after the first solution in {:?}",
        statuses.len(),
        t0.elapsed()
    );
    // The fusion went on counting through the disconnect and the kill, dropping nothing.
    let published: Vec<i64> = statuses
        .iter()
        .map(|s| int(s, "/solutions_published").unwrap())
        .collect();
    assert!(
        published.windows(2).all(|w| w[1] > w[0]),
        "solutions_published {published:?}"
    );
    for s in &statuses {
        assert_eq!(int(s, "/records_dropped"), Some(0), "{s}");
        assert_eq!(int(s, "/recorder_errors"), Some(0), "{s}");
    }
    drop(ws);

    let status = wait_exit(&mut run, "sextant run", Duration::from_secs(60));
    let log = std::fs::read_to_string(out.join("sextant.log")).unwrap();
    assert!(status.success(), "sextant run: {status}\n{log}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run/summary.json")).unwrap())
            .unwrap();
    assert_eq!(summary["end"], "Completed", "{summary}");
    assert_eq!(summary["fusion_restarts"], 0, "{summary}");
    assert_eq!(summary["recording_complete"], true, "{summary}");
    assert_eq!(summary["records_dropped"], 0, "{summary}");
    assert_eq!(
        summary["service_restarts"]["sextant-foxglove"], 1,
        "{summary}"
    );
    assert!(
        pid_of(&prefix, "sextant-foxglove").is_none(),
        "the live server outlived the run"
    );
}
