//! Helpers for Sextant's end-to-end tests: locating the real binaries, reading recordings back
//! with an independent reader (the `mcap` crate's reader, `prost-reflect` decoding protobuf
//! messages from the descriptors in the file's schema records and the `jsonschema` validator
//! for JSON ones, never the writer's own code), and inspecting what a run left behind
//! (processes, shared memory).

use anyhow::{Context, Result, anyhow, bail};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Directory holding the workspace's binaries of the profile the tests were built with
/// (`target/<profile>`), found from the test executable's own path (`target/<profile>/deps`).
pub fn bin_dir() -> Result<PathBuf> {
    let exe = std::env::current_exe()?;
    let deps = exe
        .parent()
        .ok_or_else(|| anyhow!("test executable has no parent"))?;
    let dir = deps.parent().ok_or_else(|| anyhow!("deps has no parent"))?;
    Ok(dir.to_path_buf())
}

/// Path of a workspace binary; fails with a hint when it was not built.
pub fn bin(name: &str) -> Result<PathBuf> {
    let p = bin_dir()?.join(name);
    if !p.exists() {
        bail!(
            "{} not found: build the workspace first (cargo test --workspace builds every binary)",
            p.display()
        );
    }
    Ok(p)
}

/// A fresh scratch directory `sextant-<tag>-<pid>` under the system's temporary directory.
pub fn tempdir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("sextant-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap_or_else(|e| panic!("create {}: {e}", d.display()));
    d
}

/// A fresh copy of the repository's `config/` as `dir/name` (`cp -r`, as a user would copy
/// it to change a setting); the copy's `sextant.toml`.
pub fn config_copy(dir: &Path, name: &str) -> PathBuf {
    let cfg = dir.join(name);
    let _ = std::fs::remove_dir_all(&cfg);
    let st = std::process::Command::new("cp")
        .arg("-r")
        .arg(repo_root().join("config"))
        .arg(&cfg)
        .status()
        .unwrap();
    assert!(st.success(), "cp -r config {}", cfg.display());
    cfg.join("sextant.toml")
}

/// A copy of `config/` in `dir` whose recorder keeps every solution and truth sample
/// (`[recorder] solution_rate_hz = 0`, `truth_rate_hz = 0`; shipped: 10 Hz); the copy's
/// `sextant.toml`. For tests that check the solution at every IMU sample (its continuity
/// through a fault, its stale flags), which a recording at 10 Hz does not show.
pub fn every_solution_config(dir: &Path) -> PathBuf {
    let sys = config_copy(dir, "config-every-solution");
    let text = std::fs::read_to_string(&sys).unwrap();
    let mut changed = text.clone();
    for key in ["solution_rate_hz", "truth_rate_hz"] {
        let line = format!("\n{key} = 10.0\n");
        assert!(
            changed.contains(&line),
            "config/sextant.toml has no `{key} = 10.0` line"
        );
        changed = changed.replacen(&line, &format!("\n{key} = 0.0\n"), 1);
    }
    std::fs::write(&sys, changed).unwrap();
    sys
}

/// Start `sextant run` from the repository root on `prefix` into `out`, with `extra`
/// arguments; its stdout and stderr go to `out/sextant.log`.
pub fn start_run(out: &Path, prefix: &str, extra: &[&str]) -> Result<std::process::Child> {
    let log = std::fs::File::create(out.join("sextant.log"))
        .with_context(|| format!("creating {}/sextant.log", out.display()))?;
    std::process::Command::new(bin("sextant")?)
        .current_dir(repo_root())
        .arg("run")
        .args(extra)
        .args(["--prefix", prefix, "--out"])
        .arg(out)
        .stdin(std::process::Stdio::null())
        .stdout(log.try_clone()?)
        .stderr(log)
        .spawn()
        .context("starting sextant run")
}

/// A loopback TCP port nobody listens on now (the kernel's pick for port 0, released at once).
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("no free loopback port")
}

/// Repository root (for `config/`).
pub fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

/// One decoded message of a recording.
#[derive(Debug, Clone)]
pub struct Record {
    /// MCAP topic.
    pub topic: String,
    /// MCAP log time, ns.
    pub log_time: u64,
    /// Decoded JSON payload.
    pub json: serde_json::Value,
}

/// The `summary.json` an offline command or `sextant run` wrote to `dir`.
pub fn summary_json(dir: &Path) -> serde_json::Value {
    let path = dir.join("summary.json");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Run `sextant --quiet ARGS --out OUT` (an offline command), require success and return
/// the summary it wrote.
pub fn sextant_offline(args: &[&str], out: &Path) -> serde_json::Value {
    let o = std::process::Command::new(bin("sextant").unwrap())
        .arg("--quiet")
        .args(args)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "sextant {args:?}: {}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    summary_json(out)
}

/// `sextant replay --offline RECORDING` into `replay_out`; requires every solution bit for bit.
pub fn replays_bit_exactly(recording: &Path, replay_out: &Path) {
    let s = sextant_offline(
        &["replay", "--offline", &recording.display().to_string()],
        replay_out,
    );
    assert_eq!(s["replay"]["bit_exact"], true, "{s}");
}

/// What a recording holds, read with the `mcap` crate's reader.
#[derive(Debug, Default)]
pub struct Recording {
    /// Messages in file order.
    pub records: Vec<Record>,
    /// Topic → (schema name, schema encoding, message encoding).
    pub channels: BTreeMap<String, (String, String, String)>,
    /// Messages that failed their channel's JSON Schema: (topic, error).
    pub invalid: Vec<(String, String)>,
    /// For a recording cut by a crash ([`read_cut_recording`]): where reading stopped.
    pub cut: Option<String>,
}

impl Recording {
    /// Messages on one topic.
    pub fn topic<'a>(&'a self, topic: &'a str) -> impl Iterator<Item = &'a Record> + 'a {
        self.records.iter().filter(move |r| r.topic == topic)
    }
    /// Number of messages on one topic.
    pub fn count(&self, topic: &str) -> usize {
        self.topic(topic).count()
    }
}

/// Read every message of an MCAP file, decode its JSON and validate it against its channel's
/// JSON Schema.
pub fn read_recording(path: &Path) -> Result<Recording> {
    read(path, false)
}

/// [`read_recording`] for a recording cut by a crash (no footer, a partial last chunk): every
/// message up to the first undecodable record, and where reading stopped in `cut`.
pub fn read_cut_recording(path: &Path) -> Result<Recording> {
    read(path, true)
}

fn read(path: &Path, may_be_cut: bool) -> Result<Recording> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let mut rec = Recording::default();
    let mut validators: BTreeMap<u16, jsonschema::Validator> = BTreeMap::new();
    for msg in mcap::MessageStream::new(&bytes)? {
        let msg = match msg {
            Ok(m) => m,
            Err(e) if may_be_cut => {
                rec.cut = Some(e.to_string());
                break;
            }
            Err(e) => return Err(e).with_context(|| format!("decoding {}", path.display())),
        };
        let ch = &msg.channel;
        let schema = ch
            .schema
            .as_ref()
            .ok_or_else(|| anyhow!("channel {} has no schema", ch.topic))?;
        rec.channels.entry(ch.topic.clone()).or_insert_with(|| {
            (
                schema.name.clone(),
                schema.encoding.clone(),
                ch.message_encoding.clone(),
            )
        });
        if let std::collections::btree_map::Entry::Vacant(slot) = validators.entry(ch.id) {
            let s: Option<serde_json::Value> = match schema.encoding.as_str() {
                "jsonschema" => Some(
                    serde_json::from_slice(&schema.data)
                        .with_context(|| format!("schema of {} is not JSON", ch.topic))?,
                ),
                // A protobuf message is checked against its descriptor by decoding it; a
                // Foxglove view also against Foxglove's published JSON Schema.
                "protobuf" => foxglove_json_schema(&schema.name)?,
                other => bail!("channel {}: schema encoding {other}", ch.topic),
            };
            if let Some(s) = s {
                let v = jsonschema::validator_for(&s).map_err(|e| {
                    anyhow!("schema of {} is not a valid JSON Schema: {e}", ch.topic)
                })?;
                slot.insert(v);
            }
        }
        let json = decode_message(&msg.channel, &msg.data)?;
        if let Some(v) = validators.get(&ch.id)
            && let Err(e) = v.validate(&json)
        {
            rec.invalid.push((ch.topic.clone(), e.to_string()));
        }
        rec.records.push(Record {
            topic: ch.topic.clone(),
            log_time: msg.log_time,
            json,
        });
    }
    Ok(rec)
}

/// Foxglove's published JSON Schema of a well-known schema (`foxglove.LocationFix`), from
/// `tests/data/foxglove-schemas` (the npm package `@foxglove/schemas`); `None` for any other
/// schema name.
pub fn foxglove_json_schema(name: &str) -> Result<Option<serde_json::Value>> {
    let Some(short) = name.strip_prefix("foxglove.") else {
        return Ok(None);
    };
    let file = repo_root()
        .join("tests/data/foxglove-schemas")
        .join(format!("{short}.json"));
    let text = std::fs::read_to_string(&file)
        .with_context(|| format!("{} (schema {name} not shipped)", file.display()))?;
    Ok(Some(serde_json::from_str(&text)?))
}

/// One message of a recording as JSON, whatever its encoding: `json` as written; `protobuf`
/// decoded with `prost-reflect` from the `FileDescriptorSet` in the channel's schema record,
/// every field by its name (proto3 scalars and repeated fields with their defaults, message
/// fields when present), `google.protobuf.Timestamp` as Foxglove's `{sec, nsec}`, enums as
/// numbers, non-finite doubles as `null`. Sextant's messages come out as their JSON form,
/// except that nested arrays are flat (`channel_axis`: 24 numbers, row by row) and that a
/// fixed-size array ends at its last element that is not at its default
/// ([`msgs::protobuf::as_decoded_json`] turns a message's JSON into that form).
pub fn decode_message(channel: &mcap::Channel, data: &[u8]) -> Result<serde_json::Value> {
    match channel.message_encoding.as_str() {
        "json" => serde_json::from_slice(data)
            .with_context(|| format!("message on {} is not JSON", channel.topic)),
        "protobuf" => {
            let schema = channel
                .schema
                .as_ref()
                .ok_or_else(|| anyhow!("protobuf channel {} has no schema", channel.topic))?;
            let pool = prost_reflect::DescriptorPool::decode(&schema.data[..])
                .with_context(|| format!("descriptors of {}", channel.topic))?;
            let desc = pool.get_message_by_name(&schema.name).ok_or_else(|| {
                anyhow!(
                    "{}: no message {} in its descriptors",
                    channel.topic,
                    schema.name
                )
            })?;
            let m = prost_reflect::DynamicMessage::decode(desc, data)
                .with_context(|| format!("message on {} is not its protobuf", channel.topic))?;
            Ok(dynamic_json(&m))
        }
        other => bail!("channel {}: message encoding {other}", channel.topic),
    }
}

fn dynamic_json(m: &prost_reflect::DynamicMessage) -> serde_json::Value {
    use prost_reflect::ReflectMessage;
    use serde_json::{Value, json};
    let desc = m.descriptor();
    if desc.full_name() == "google.protobuf.Timestamp" {
        let secs = m.get_field_by_name("seconds").and_then(|v| v.as_i64());
        let nanos = m.get_field_by_name("nanos").and_then(|v| v.as_i32());
        return json!({"sec": secs.unwrap_or(0), "nsec": nanos.unwrap_or(0)});
    }
    let mut obj = serde_json::Map::new();
    for f in desc.fields() {
        let is_message = matches!(f.kind(), prost_reflect::Kind::Message(_)) && !f.is_list();
        if (is_message || f.supports_presence()) && !m.has_field(&f) {
            continue;
        }
        obj.insert(f.name().to_string(), dynamic_value(&m.get_field(&f)));
    }
    Value::Object(obj)
}

fn dynamic_value(v: &prost_reflect::Value) -> serde_json::Value {
    use prost_reflect::Value as V;
    use serde_json::{Value, json};
    match v {
        V::Bool(b) => json!(b),
        V::I32(x) | V::EnumNumber(x) => json!(x),
        V::I64(x) => json!(x),
        V::U32(x) => json!(x),
        V::U64(x) => json!(x),
        V::F32(x) => serde_json::Number::from_f64(f64::from(*x)).map_or(Value::Null, Value::Number),
        V::F64(x) => serde_json::Number::from_f64(*x).map_or(Value::Null, Value::Number),
        V::String(s) => json!(s),
        V::Bytes(b) => json!(b.to_vec()),
        V::Message(m) => dynamic_json(m),
        V::List(l) => Value::Array(l.iter().map(dynamic_value).collect()),
        V::Map(_) => Value::Null,
    }
}

/// Entries (files and directories, recursively) that iceoryx2 keeps in the file system:
/// shared memory in /dev/shm and its bookkeeping under /tmp/iceoryx2.
pub fn iceoryx_entries() -> BTreeSet<PathBuf> {
    let mut out = BTreeSet::new();
    if let Ok(rd) = std::fs::read_dir("/dev/shm") {
        for e in rd.flatten() {
            let name = e.file_name().to_string_lossy().to_string();
            if name.starts_with("iox2") {
                out.insert(e.path());
            }
        }
    }
    fn walk(p: &Path, out: &mut BTreeSet<PathBuf>) {
        if let Ok(rd) = std::fs::read_dir(p) {
            for e in rd.flatten() {
                let path = e.path();
                if path.is_dir() {
                    walk(&path, out);
                } else {
                    out.insert(path);
                }
            }
        }
    }
    walk(Path::new("/tmp/iceoryx2"), &mut out);
    out
}

/// Processes whose command line contains `needle` (excluding the caller).
pub fn processes_matching(needle: &str) -> Vec<(i32, String)> {
    let me = std::process::id() as i32;
    let mut out = Vec::new();
    if let Ok(rd) = std::fs::read_dir("/proc") {
        for e in rd.flatten() {
            let Ok(pid) = e.file_name().to_string_lossy().parse::<i32>() else {
                continue;
            };
            if pid == me {
                continue;
            }
            if let Ok(raw) = std::fs::read(e.path().join("cmdline")) {
                let cmd = String::from_utf8_lossy(&raw).replace('\0', " ");
                if cmd.contains(needle) {
                    out.push((pid, cmd));
                }
            }
        }
    }
    out
}

/// Assert that a run on `prefix` left nothing behind: no process whose command line names the
/// prefix, no iceoryx2 file-system entry that was not there before (`before`, from
/// [`iceoryx_entries`] taken before the run).
pub fn assert_nothing_left_behind(prefix: &str, before: &BTreeSet<PathBuf>) {
    assert!(
        processes_matching(prefix).is_empty(),
        "{:?}",
        processes_matching(prefix)
    );
    let leaked: Vec<_> = iceoryx_entries().difference(before).cloned().collect();
    assert!(
        leaked.is_empty(),
        "iceoryx2 resources left behind: {leaked:?}"
    );
}

/// Wait for `child` to exit within `timeout`, polling every 50 ms; when it overruns, kill it
/// and panic naming `what`.
pub fn wait_exit(
    child: &mut std::process::Child,
    what: &str,
    timeout: std::time::Duration,
) -> std::process::ExitStatus {
    let t0 = std::time::Instant::now();
    loop {
        if let Some(st) = child.try_wait().expect("wait for a child process") {
            return st;
        }
        if t0.elapsed() > timeout {
            let _ = child.kill();
            panic!("{what} overran {timeout:?}");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

/// Wait until `sextant run` on `prefix` has claimed it: its fusion daemon is up, which it
/// starts only after the check that refuses a prefix live processes already use. Start a
/// process that joins the run's bus (a live replay) only then, or the run may find it first
/// and refuse to start. Panics after `timeout`.
pub fn wait_for_run_to_claim(prefix: &str, timeout: std::time::Duration) {
    let t0 = std::time::Instant::now();
    while pid_of(prefix, "sextant-fusion").is_none() {
        assert!(
            t0.elapsed() < timeout,
            "sextant run on {prefix} started no fusion daemon within {timeout:?}"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// Pid of the process whose executable is `program` and whose command line names `prefix`
/// (a driver or the fusion daemon of a run, not its supervisor).
pub fn pid_of(prefix: &str, program: &str) -> Option<i32> {
    processes_matching(prefix)
        .into_iter()
        .find(|(_, cmd)| {
            cmd.split_whitespace()
                .next()
                .is_some_and(|exe| exe.ends_with(program))
        })
        .map(|(pid, _)| pid)
}

/// A JSON array of numbers as a Vec (empty when absent).
pub fn f64s(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .map(|a| a.iter().filter_map(|x| x.as_f64()).collect())
        .unwrap_or_default()
}

/// Read a number at a JSON pointer (e.g. "/header/time_ns").
pub fn num(v: &serde_json::Value, ptr: &str) -> Option<f64> {
    v.pointer(ptr).and_then(|x| x.as_f64())
}

/// Read an integer at a JSON pointer.
pub fn int(v: &serde_json::Value, ptr: &str) -> Option<i64> {
    v.pointer(ptr).and_then(|x| x.as_i64())
}

/// The default vehicle scenario, driving from the start (speed-up in 5 s, turns at 10 to
/// 15 m/s) for 90 s, its sensor grades and its shared world file from the repository, written
/// into `dir`.
pub fn driving_scenario(dir: &Path) -> PathBuf {
    let root = repo_root();
    let text = std::fs::read_to_string(root.join("config/scenarios/vehicle.toml")).unwrap();
    assert!(
        text.contains("duration_s = 600.0") && text.contains("seed = 2\n"),
        "vehicle.toml changed its [scenario] layout"
    );
    let start = text.find("segments = [").unwrap();
    let end = start + text[start..].find("\n]\n").unwrap() + 3;
    let segments = r#"segments = [
    { type = "speed", to_m_s = 10.0, duration_s = 5.0 },
    { type = "cruise", duration_s = 10.0 },
    { type = "turn", angle_deg = 90.0, duration_s = 15.0 },
    { type = "cruise", duration_s = 10.0 },
    { type = "turn", angle_deg = -60.0, duration_s = 10.0 },
    { type = "speed", to_m_s = 15.0, duration_s = 5.0 },
    { type = "cruise", duration_s = 30.0 },
]
"#;
    let text = format!("{}{segments}{}", &text[..start], &text[end..])
        .replace("duration_s = 600.0", "duration_s = 90.0")
        .replace(
            "seed = 2\n",
            &format!(
                "seed = 2\nsensors_dir = {:?}\n",
                root.join("config/sensors").display().to_string()
            ),
        );
    // The world include is relative to the scenario's directory: make it absolute.
    let include = "include = \"../worlds/";
    assert!(
        text.contains(include),
        "vehicle.toml changed its [world] include"
    );
    let text = text.replace(
        include,
        &format!("include = \"{}/", root.join("config/worlds").display()),
    );
    let path = dir.join("driving.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// Position error (truth − solution) in NED at the solution's latitude/longitude, m, and the
/// reported NED σ.
pub fn ned_position_error(
    nav: &serde_json::Value,
    truth: &serde_json::Value,
) -> ([f64; 3], [f64; 3]) {
    let r_n = f64s(&nav["pos_ecef_m"]);
    let r_t = f64s(&truth["pos_ecef_m"]);
    let d = [r_t[0] - r_n[0], r_t[1] - r_n[1], r_t[2] - r_n[2]];
    let (lat, lon) = (num(nav, "/lat_rad").unwrap(), num(nav, "/lon_rad").unwrap());
    let (sl, cl, so, co) = (lat.sin(), lat.cos(), lon.sin(), lon.cos());
    let n = -sl * co * d[0] - sl * so * d[1] + cl * d[2];
    let e = -so * d[0] + co * d[1];
    let dn = -cl * co * d[0] - cl * so * d[1] - sl * d[2];
    let s = f64s(&nav["pos_sigma_ned_m"]);
    ([n, e, dn], [s[0], s[1], s[2]])
}

/// How many end-to-end runs share the machine at once. Measured per run: a 600 s default run at
/// 20× keeps about half a core busy (≈ 24 CPU-s over 42 s of wall time), a stall test a third
/// of one; two of them fit the two cores the tests are built for without one starving the
/// other's processes.
pub const E2E_AT_ONCE: usize = 2;

/// Taken by every end-to-end test that starts processes, or times or counts what they do, for
/// its whole run. The test files share one test binary (`tests/main.rs`), whose harness runs
/// tests on parallel threads: this admits at most [`E2E_AT_ONCE`] runs at a time
/// ([`Machine::shared`]), and a test that needs the machine to itself takes it whole
/// ([`Machine::exclusive`]): one that checks that nothing is left in `/dev/shm` (iceoryx2's
/// files carry no prefix, so another run's would count as leaked), one that measures
/// latency, memory or a deadline, one that floods the bus. Each test runs on its own prefix
/// and its own output directory. A test that panicked while holding a slot gives it back as
/// its guard drops.
pub static MACHINE: Machine = Machine::new();

/// A counting semaphore of [`E2E_AT_ONCE`] slots with an exclusive mode ([`MACHINE`]).
pub struct Machine {
    state: std::sync::Mutex<MachineState>,
    changed: std::sync::Condvar,
}

#[derive(Clone, Copy)]
struct MachineState {
    /// Shared slots taken.
    shared: usize,
    /// A test holds the machine alone.
    exclusive: bool,
    /// Tests waiting for the machine alone: new shared takers wait behind them, so an
    /// exclusive test is not starved by a stream of shared ones.
    exclusive_waiting: usize,
}

/// A slot of [`MACHINE`], given back when dropped.
#[must_use = "the slot is given back when the guard drops"]
pub struct MachineGuard {
    exclusive: bool,
}

impl Machine {
    const fn new() -> Self {
        Self {
            state: std::sync::Mutex::new(MachineState {
                shared: 0,
                exclusive: false,
                exclusive_waiting: 0,
            }),
            changed: std::sync::Condvar::new(),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, MachineState> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// One of the [`E2E_AT_ONCE`] slots, for a run that may share the machine.
    pub fn shared(&self) -> MachineGuard {
        let mut st = self.lock();
        while st.exclusive || st.exclusive_waiting > 0 || st.shared >= E2E_AT_ONCE {
            st = self.changed.wait(st).unwrap_or_else(|e| e.into_inner());
        }
        st.shared += 1;
        MachineGuard { exclusive: false }
    }

    /// The whole machine: waits until no other end-to-end test runs.
    pub fn exclusive(&self) -> MachineGuard {
        let mut st = self.lock();
        st.exclusive_waiting += 1;
        while st.exclusive || st.shared > 0 {
            st = self.changed.wait(st).unwrap_or_else(|e| e.into_inner());
        }
        st.exclusive_waiting -= 1;
        st.exclusive = true;
        MachineGuard { exclusive: true }
    }
}

impl Drop for MachineGuard {
    fn drop(&mut self) {
        let mut st = MACHINE.lock();
        if self.exclusive {
            st.exclusive = false;
        } else {
            st.shared -= 1;
        }
        drop(st);
        MACHINE.changed.notify_all();
    }
}

#[cfg(test)]
mod tests {
    use super::{E2E_AT_ONCE, MACHINE, repo_root};
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::time::Duration;

    /// At most [`E2E_AT_ONCE`] shared holders at a time, and an exclusive holder alone.
    #[test]
    fn the_machine_admits_two_runs_or_one_alone() {
        static RUNNING: AtomicUsize = AtomicUsize::new(0);
        static MOST: AtomicUsize = AtomicUsize::new(0);
        static ALONE_VIOLATED: AtomicUsize = AtomicUsize::new(0);
        let threads: Vec<_> = (0..8)
            .map(|i| {
                std::thread::spawn(move || {
                    let exclusive = i % 4 == 0;
                    let _g = if exclusive {
                        MACHINE.exclusive()
                    } else {
                        MACHINE.shared()
                    };
                    let n = RUNNING.fetch_add(1, Ordering::SeqCst) + 1;
                    MOST.fetch_max(n, Ordering::SeqCst);
                    std::thread::sleep(Duration::from_millis(30));
                    if exclusive && RUNNING.load(Ordering::SeqCst) != 1 {
                        ALONE_VIOLATED.fetch_add(1, Ordering::SeqCst);
                    }
                    RUNNING.fetch_sub(1, Ordering::SeqCst);
                })
            })
            .collect();
        for t in threads {
            t.join().unwrap();
        }
        assert_eq!(MOST.load(Ordering::SeqCst), E2E_AT_ONCE);
        assert_eq!(ALONE_VIOLATED.load(Ordering::SeqCst), 0);
    }

    /// Each crate whose integration tests are one binary (`autotests = false`, a `[[test]]`
    /// whose `tests/main.rs` declares one module per file) compiles every file of its tests
    /// directory: a file without its `mod` line would silently never run.
    #[test]
    fn every_integration_test_file_is_declared() {
        let root = repo_root();
        let mut checked = 0;
        for member in std::fs::read_dir(&root).unwrap().flatten() {
            let dir = member.path().join("tests");
            let Ok(main) = std::fs::read_to_string(dir.join("main.rs")) else {
                continue;
            };
            let manifest = std::fs::read_to_string(dir.parent().unwrap().join("Cargo.toml"))
                .unwrap_or_default();
            assert!(
                manifest.contains("autotests = false"),
                "{}: a tests/main.rs needs autotests = false in Cargo.toml",
                dir.display()
            );
            for file in std::fs::read_dir(&dir).unwrap().flatten() {
                let name = file.file_name().to_string_lossy().to_string();
                let Some(module) = name.strip_suffix(".rs") else {
                    continue;
                };
                if module == "main" {
                    continue;
                }
                assert!(
                    main.lines().any(|l| l.trim() == format!("mod {module};")),
                    "{}/{name} is not declared in its main.rs (`mod {module};`): it would never run",
                    dir.display()
                );
                checked += 1;
            }
        }
        assert!(
            checked > 0,
            "no integration test file found under {}",
            root.display()
        );
    }
}
