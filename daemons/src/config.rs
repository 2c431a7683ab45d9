//! The system configuration (`config/sextant.toml`): service prefix, what `sextant run` starts,
//! per-sensor deadlines, solution decimation, recorder settings, and the path of the filter
//! tuning file (`config/filter.toml`, deserialized into [`fusion::navigator::NavigatorConfig`]).
//!
//! Loading is two passes: [`SystemConfig::parse`] checks the syntax and the types (serde, with
//! `deny_unknown_fields`, so a misspelt key is an error), then [`SystemConfig::validate`] checks
//! the meaning (ranges, consistency). Every error names the file and the key.

use fusion::navigator::NavigatorConfig;
use msgs::{PerSensor, SensorId};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Errors while loading the configuration.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{file}: cannot read: {source}")]
    Read {
        /// The file.
        file: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not valid TOML or a key has the wrong type, is unknown or missing.
    #[error("{file}: {message}")]
    Parse {
        /// The file.
        file: PathBuf,
        /// The parser's message (it names the key and shows the line).
        message: String,
    },
    /// A value is out of range or inconsistent.
    #[error("{file}: key `{key}`: {message}")]
    Invalid {
        /// The file.
        file: PathBuf,
        /// The dotted key, e.g. `fusion.deadlines_ms.imu`.
        key: String,
        /// What is wrong.
        message: String,
    },
}

/// `[system]`: naming and the other configuration files.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SystemSection {
    /// Prefix of every iceoryx2 service name (`<prefix>/imu`, …).
    pub prefix: String,
    /// Filter tuning file, relative to the directory of this file.
    pub filter: PathBuf,
    /// Default scenario for `sextant run`, relative to the directory of this file.
    pub scenario: PathBuf,
}

/// `[run]`: defaults of `sextant run`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RunSection {
    /// Default scenario duration to run, s of simulated time.
    pub duration_s: f64,
    /// Upper bound accepted for `--duration`, s of simulated time.
    pub max_duration_s: f64,
    /// Default speed-up of simulated time over wall time.
    pub speed: f64,
    /// Default output directory.
    pub out: PathBuf,
    /// Delay between starting the processes and the first sample (so that every process has
    /// created its services), s of wall time.
    pub start_delay_s: f64,
    /// How long to wait for a process after SIGTERM before SIGKILL, s of wall time.
    pub stop_timeout_s: f64,
    /// How many times a driver that died is restarted.
    pub max_restarts: u32,
    /// A process that sends no heartbeat (`WATCHDOG=1` of the `sd_notify` protocol, sent every
    /// half of this) for this long is killed as hung and restarted, s of wall time; 0 disables
    /// the watch.
    #[serde(default = "default_heartbeat_timeout_s")]
    pub heartbeat_timeout_s: f64,
    /// Driver binaries to start (names next to the `sextant` executable).
    pub drivers: Vec<String>,
}

/// `[fusion]`: the fusion daemon.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct FusionSection {
    /// Publish every N-th solution on `<prefix>/nav` (every solution is recorded).
    pub nav_decimation: u32,
    /// Period of `<prefix>/status`, s of wall time.
    pub status_period_s: f64,
    /// Smallest wall-clock deadline after scaling by the speed-up, ms (scheduling jitter).
    pub min_wall_deadline_ms: f64,
    /// `[fusion.deadlines_ms]`: how long each sensor may stay silent before the daemon declares
    /// it dead, ms of simulated time (divided by the run's speed-up to get the wall-clock
    /// deadline, floored at `min_wall_deadline_ms`). Not the filter's `[deadlines]`, which
    /// say how long a fused aiding source counts for the navigation mode.
    pub deadlines_ms: PerSensor<f64>,
    /// Write the navigator's checkpoint for a warm restart (`navigator.checkpoint` next to the
    /// recording) every this many seconds of filter (GPS) time; 0 disables it.
    #[serde(default = "default_checkpoint_interval_s")]
    pub checkpoint_interval_s: f64,
    /// A solution published more than this many ms of simulated time (divided by the speed-up,
    /// never less than 20 ms of wall time) behind its time of validity, relative to the fastest
    /// delivery seen, is flagged stale (`NavSolution.stale`).
    #[serde(default = "default_stale_after_ms")]
    pub stale_after_ms: f64,
    /// Calibration memory file (`fusion::navigator` module `calibration_memory`): read at the
    /// start, the sensor errors of the previous run as the prior; written at the end with the
    /// estimate the run ended with. None: no calibration memory.
    #[serde(default)]
    pub calibration_file: Option<PathBuf>,
    /// `[fusion.realtime]`: CPU, SCHED_FIFO priority and locked memory for the filter thread
    /// on a dedicated computer ([`crate::realtime`]); absent: none.
    #[serde(default)]
    pub realtime: crate::realtime::RealtimeSection,
    /// After each wake-up, poll for the next sample this long (µs of wall time) before
    /// blocking: no sleep and wake-up on the latency path when a sample arrives within it, at
    /// the price of a busy CPU meanwhile; 0: block at once.
    #[serde(default)]
    pub spin_us: u64,
}

fn default_stale_after_ms() -> f64 {
    100.0
}

fn default_heartbeat_timeout_s() -> f64 {
    5.0
}

fn default_checkpoint_interval_s() -> f64 {
    1.0
}

/// `[recorder]`: the MCAP writer.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RecorderSection {
    /// Capacity of the queue from the filter thread to the writer thread, records.
    pub queue_capacity: usize,
    /// Target uncompressed chunk size, bytes.
    pub chunk_size_bytes: u64,
    /// Close the current chunk at least this often, s of wall time (bounds what a crash loses).
    pub flush_interval_s: f64,
    /// Start a new segment (`recording.part2.mcap`, …) when the current one spans this much
    /// time of validity, s; 0: one file. An MCAP writer keeps an index entry per chunk until
    /// the file is finished, so a file's writer memory grows with its length; segments bound
    /// it for runs of days.
    #[serde(default = "default_segment_duration_s")]
    pub segment_duration_s: f64,
    /// The messages' encoding: `protobuf` (compact, the default) or `json` (text).
    #[serde(default)]
    pub encoding: crate::recorder::RecordingEncoding,
    /// Rate of the solution's Foxglove views (map, pose, frame tree), Hz of time of validity;
    /// 0: a view of every solution.
    #[serde(default = "default_view_rate_hz")]
    pub view_rate_hz: f64,
    /// Rate of the `nav` channel, Hz of time of validity (the first solution of each
    /// interval); 0 (the default when absent): every solution. Replay recomputes every
    /// solution from the inputs, which are always recorded in full.
    #[serde(default)]
    pub solution_rate_hz: f64,
    /// Rate of the simulator's `truth` channel, Hz of time of validity; 0 (the default when
    /// absent): every sample.
    #[serde(default)]
    pub truth_rate_hz: f64,
}

fn default_view_rate_hz() -> f64 {
    crate::recorder::DEFAULT_VIEW_RATE_HZ
}

fn default_segment_duration_s() -> f64 {
    1800.0
}

/// `[foxglove]` (optional): the live view. When present, `sextant run` starts the live
/// Foxglove server (`sextant-foxglove`) on `listen` beside the fusion daemon; `--foxglove ADDR`
/// does the same from the command line.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct FoxgloveSection {
    /// Address of the WebSocket server, `IP:PORT` (e.g. `127.0.0.1:8765`; `0.0.0.0:8765` to
    /// serve other computers).
    pub listen: std::net::SocketAddr,
}

/// `[bridge]` (optional): the Zenoh bridge to other computers. When present, `sextant run`
/// starts `sextant-bridge` beside the fusion daemon (and restarts it when it dies). The wire
/// format is documented in `docs/DATA.md`; the endpoints and key prefixes are checked by the
/// bridge itself (`sextant-bridge --check`) before the run starts.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct BridgeSection {
    /// Key prefix of the exported channels (`<key_prefix>/v1/<channel>`); default: the bus's
    /// service prefix (`system.prefix`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub key_prefix: Option<String>,
    /// Zenoh endpoints to listen on, `tcp/IP:PORT` (`tcp/0.0.0.0:7447` to serve others).
    #[serde(default)]
    pub listen: Vec<String>,
    /// Zenoh endpoints to connect to, `tcp/HOST:PORT` (retried for ever).
    #[serde(default)]
    pub connect: Vec<String>,
    /// Bus channels published on Zenoh (default: `nav`, `status`).
    #[serde(default = "default_bridge_export")]
    pub export: Vec<String>,
    /// Remote channels published on the local bus (default: none).
    #[serde(default)]
    pub import: Vec<String>,
    /// Key prefix of the remote system whose channels are imported.
    #[serde(default)]
    pub import_from: String,
    /// Lease of the links, ms: a silently dropped link is declared down after it.
    #[serde(default = "default_bridge_lease_ms")]
    pub lease_ms: u64,
}

fn default_bridge_export() -> Vec<String> {
    vec!["nav".into(), "status".into()]
}

fn default_bridge_lease_ms() -> u64 {
    3000
}

impl BridgeSection {
    /// The bridge's command-line arguments for the bus `prefix`.
    pub fn args(&self, prefix: &str) -> Vec<String> {
        let mut a = vec![
            "--prefix".to_string(),
            prefix.to_string(),
            "--key-prefix".into(),
            self.key_prefix
                .clone()
                .unwrap_or_else(|| prefix.to_string()),
            "--export".into(),
            self.export.join(","),
            "--lease-ms".into(),
            self.lease_ms.to_string(),
        ];
        for e in &self.listen {
            a.extend(["--listen".to_string(), e.clone()]);
        }
        for e in &self.connect {
            a.extend(["--connect".to_string(), e.clone()]);
        }
        if !self.import.is_empty() {
            a.extend([
                "--import".to_string(),
                self.import.join(","),
                "--import-from".into(),
                self.import_from.clone(),
            ]);
        }
        a
    }
}

/// The whole system configuration file.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SystemConfig {
    /// `[system]`.
    pub system: SystemSection,
    /// `[run]`.
    pub run: RunSection,
    /// `[fusion]`.
    pub fusion: FusionSection,
    /// `[recorder]`.
    pub recorder: RecorderSection,
    /// `[foxglove]`: the live view (absent: not started unless `sextant run --foxglove`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub foxglove: Option<FoxgloveSection>,
    /// `[bridge]`: the Zenoh bridge (absent: not started).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bridge: Option<BridgeSection>,
}

/// A loaded and validated configuration with the file it came from.
#[derive(Debug, Clone)]
pub struct LoadedConfig {
    /// The system configuration file.
    pub path: PathBuf,
    /// Its content.
    pub system: SystemConfig,
    /// The filter tuning file (resolved).
    pub filter_path: PathBuf,
    /// The filter tuning.
    pub navigator: NavigatorConfig,
}

impl LoadedConfig {
    /// The default scenario path (resolved against the config file's directory).
    pub fn scenario_path(&self) -> PathBuf {
        resolve(&self.path, &self.system.system.scenario)
    }
}

fn resolve(config_file: &Path, rel: &Path) -> PathBuf {
    if rel.is_absolute() {
        rel.to_path_buf()
    } else {
        config_file
            .parent()
            .unwrap_or_else(|| Path::new("."))
            .join(rel)
    }
}

fn read(file: &Path) -> Result<String, ConfigError> {
    std::fs::read_to_string(file).map_err(|source| ConfigError::Read {
        file: file.to_path_buf(),
        source,
    })
}

fn invalid(file: &Path, key: &str, message: impl Into<String>) -> ConfigError {
    ConfigError::Invalid {
        file: file.to_path_buf(),
        key: key.to_string(),
        message: message.into(),
    }
}

fn positive(file: &Path, key: &str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(invalid(
            file,
            key,
            format!("must be a finite number > 0, got {v}"),
        ))
    }
}

impl SystemConfig {
    /// Parse the TOML text of `file` (syntax, types, unknown and missing keys).
    pub fn parse(text: &str, file: &Path) -> Result<Self, ConfigError> {
        toml::from_str(text).map_err(|e| ConfigError::Parse {
            file: file.to_path_buf(),
            message: e.to_string(),
        })
    }

    /// Check the meaning of the values; the error names the key.
    pub fn validate(&self, file: &Path) -> Result<(), ConfigError> {
        let p = &self.system.prefix;
        if p.is_empty()
            || p.len() > 64
            || !p
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '/')
            || p.starts_with('/')
            || p.ends_with('/')
        {
            return Err(invalid(
                file,
                "system.prefix",
                format!(
                    "must be 1–64 characters of [A-Za-z0-9_-/], not starting or ending with '/', got {p:?}"
                ),
            ));
        }
        let r = &self.run;
        positive(file, "run.duration_s", r.duration_s)?;
        positive(file, "run.max_duration_s", r.max_duration_s)?;
        if r.duration_s > r.max_duration_s {
            return Err(invalid(
                file,
                "run.duration_s",
                format!(
                    "{} exceeds run.max_duration_s = {}",
                    r.duration_s, r.max_duration_s
                ),
            ));
        }
        positive(file, "run.speed", r.speed)?;
        if !(r.start_delay_s.is_finite() && (0.0..=60.0).contains(&r.start_delay_s)) {
            return Err(invalid(
                file,
                "run.start_delay_s",
                "must be within 0..=60 s",
            ));
        }
        positive(file, "run.stop_timeout_s", r.stop_timeout_s)?;
        if r.drivers.is_empty() {
            return Err(invalid(
                file,
                "run.drivers",
                "must name at least one driver",
            ));
        }
        for (i, d) in r.drivers.iter().enumerate() {
            if d.is_empty() || d.contains('/') {
                return Err(invalid(
                    file,
                    &format!("run.drivers[{i}]"),
                    format!("must be a binary name without a path, got {d:?}"),
                ));
            }
        }
        if let Some(b) = &self.bridge {
            for (key, names) in [("bridge.export", &b.export), ("bridge.import", &b.import)] {
                for (i, n) in names.iter().enumerate() {
                    if msgs::Channel::from_name(n).is_none() {
                        let all: Vec<&str> = msgs::Channel::ALL.iter().map(|c| c.name()).collect();
                        return Err(invalid(
                            file,
                            &format!("{key}[{i}]"),
                            format!("unknown channel {n:?} (channels: {})", all.join(", ")),
                        ));
                    }
                }
            }
            if b.listen.is_empty() && b.connect.is_empty() {
                return Err(invalid(
                    file,
                    "bridge.listen",
                    "the bridge needs at least one endpoint to listen on or connect to",
                ));
            }
        }
        let f = &self.fusion;
        if f.nav_decimation == 0 {
            return Err(invalid(file, "fusion.nav_decimation", "must be >= 1"));
        }
        positive(file, "fusion.status_period_s", f.status_period_s)?;
        positive(file, "fusion.min_wall_deadline_ms", f.min_wall_deadline_ms)?;
        positive(file, "fusion.stale_after_ms", f.stale_after_ms)?;
        f.realtime
            .validate()
            .map_err(|(key, message)| invalid(file, key, message))?;
        if !(f.checkpoint_interval_s.is_finite() && f.checkpoint_interval_s >= 0.0) {
            return Err(invalid(
                file,
                "fusion.checkpoint_interval_s",
                format!("must be >= 0 s, got {}", f.checkpoint_interval_s),
            ));
        }
        for s in SensorId::ALL {
            positive(
                file,
                &format!("fusion.deadlines_ms.{}", s.name()),
                f.deadlines_ms[s],
            )?;
        }
        let rec = &self.recorder;
        if !(16..=10_000_000).contains(&rec.queue_capacity) {
            return Err(invalid(
                file,
                "recorder.queue_capacity",
                "must be within 16..=10000000",
            ));
        }
        if !(1024..=1 << 30).contains(&rec.chunk_size_bytes) {
            return Err(invalid(
                file,
                "recorder.chunk_size_bytes",
                "must be within 1 KiB..=1 GiB",
            ));
        }
        positive(file, "recorder.flush_interval_s", rec.flush_interval_s)?;
        if !(rec.view_rate_hz.is_finite() && rec.view_rate_hz >= 0.0) {
            return Err(invalid(
                file,
                "recorder.view_rate_hz",
                "must be a finite rate >= 0 (0: a view of every solution)",
            ));
        }
        for (key, rate) in [
            ("recorder.solution_rate_hz", rec.solution_rate_hz),
            ("recorder.truth_rate_hz", rec.truth_rate_hz),
        ] {
            if !(rate.is_finite() && rate >= 0.0) {
                return Err(invalid(
                    file,
                    key,
                    "must be a finite rate >= 0 (0: every message)",
                ));
            }
        }
        if !(rec.segment_duration_s.is_finite() && rec.segment_duration_s >= 0.0) {
            return Err(invalid(
                file,
                "recorder.segment_duration_s",
                format!(
                    "must be >= 0 s (0: one file), got {}",
                    rec.segment_duration_s
                ),
            ));
        }
        Ok(())
    }

    /// Wall-clock deadline of a sensor at speed-up `speed`.
    pub fn wall_deadline(&self, sensor: SensorId, speed: f64) -> Duration {
        let ms = (self.fusion.deadlines_ms[sensor] / speed.max(1e-9))
            .max(self.fusion.min_wall_deadline_ms);
        Duration::from_secs_f64(ms / 1000.0)
    }
}

/// Parse and validate a filter tuning file.
pub fn load_navigator_config(file: &Path) -> Result<NavigatorConfig, ConfigError> {
    let text = read(file)?;
    parse_navigator_config(&text, file)
}

/// Parse and validate filter tuning text (`file` is only used in messages).
pub fn parse_navigator_config(text: &str, file: &Path) -> Result<NavigatorConfig, ConfigError> {
    let cfg: NavigatorConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
        file: file.to_path_buf(),
        message: e.to_string(),
    })?;
    cfg.validate().map_err(|e| {
        // fusion names the key as `filter.<dotted key> <what>`: report the key itself.
        let fusion::ConfigError(m) = &e;
        let (key, message) = match m.strip_prefix("filter.") {
            Some(rest) => match rest.split_once(' ') {
                Some((k, what)) => (k.to_string(), what.to_string()),
                None => ("filter".to_string(), m.clone()),
            },
            None => ("filter".to_string(), m.clone()),
        };
        ConfigError::Invalid {
            file: file.to_path_buf(),
            key,
            message,
        }
    })?;
    Ok(cfg)
}

/// Load the system configuration and the filter tuning it points to.
pub fn load(file: &Path) -> Result<LoadedConfig, ConfigError> {
    let text = read(file)?;
    let system = SystemConfig::parse(&text, file)?;
    system.validate(file)?;
    let filter_path = resolve(file, &system.system.filter);
    let navigator = load_navigator_config(&filter_path)?;
    Ok(LoadedConfig {
        path: file.to_path_buf(),
        system,
        filter_path,
        navigator,
    })
}

/// The files of `config/` embedded in the binary at build time (path relative to `config/`,
/// content), used by `sextant run` when no config file exists on disk.
pub fn embedded_config_files() -> &'static [(&'static str, &'static str)] {
    include!(concat!(env!("OUT_DIR"), "/embedded_config.rs"))
}

/// Write the embedded `config/` into `dir` and return the path of its `sextant.toml`.
pub fn materialize_embedded(dir: &Path) -> Result<PathBuf, ConfigError> {
    for (rel, text) in embedded_config_files() {
        let path = dir.join(rel);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(|source| ConfigError::Read {
                file: parent.to_path_buf(),
                source,
            })?;
        }
        std::fs::write(&path, text).map_err(|source| ConfigError::Read {
            file: path.clone(),
            source,
        })?;
    }
    Ok(dir.join("sextant.toml"))
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = include_str!("../../config/sextant.toml");

    fn f() -> PathBuf {
        PathBuf::from("test/sextant.toml")
    }

    #[test]
    fn shipped_config_parses_and_validates() {
        let c = SystemConfig::parse(GOOD, &f()).unwrap();
        c.validate(&f()).unwrap();
        assert_eq!(c.system.prefix, "sextant");
    }

    #[test]
    fn unknown_key_is_named() {
        let text = GOOD.replace("nav_decimation", "nav_decimaton");
        let e = SystemConfig::parse(&text, &f()).unwrap_err().to_string();
        assert!(e.contains("nav_decimaton"), "{e}");
        assert!(e.contains("test/sextant.toml"), "{e}");
    }

    /// `[foxglove]` is optional; its address must be `IP:PORT`, and a bad one is named.
    #[test]
    fn foxglove_section_is_optional_and_checked() {
        let c = SystemConfig::parse(GOOD, &f()).unwrap();
        assert_eq!(c.foxglove, None);
        let text = format!("{GOOD}\n[foxglove]\nlisten = \"127.0.0.1:8765\"\n");
        let c = SystemConfig::parse(&text, &f()).unwrap();
        assert_eq!(
            c.foxglove.map(|s| s.listen),
            Some(([127, 0, 0, 1], 8765).into())
        );
        let text = format!("{GOOD}\n[foxglove]\nlisten = \"localhost\"\n");
        let e = SystemConfig::parse(&text, &f()).unwrap_err().to_string();
        assert!(e.contains("listen"), "{e}");
    }

    /// `[bridge]` is optional, defaults to exporting the solution and the status, and names
    /// an unknown channel.
    #[test]
    fn bridge_section_is_optional_and_checked() {
        let c = SystemConfig::parse(GOOD, &f()).unwrap();
        assert_eq!(c.bridge, None);
        let text = format!("{GOOD}\n[bridge]\nlisten = [\"tcp/0.0.0.0:7447\"]\n");
        let c = SystemConfig::parse(&text, &f()).unwrap();
        c.validate(&f()).unwrap();
        let b = c.bridge.unwrap();
        assert_eq!(b.export, ["nav", "status"]);
        assert_eq!(
            b.args("car1"),
            [
                "--prefix",
                "car1",
                "--key-prefix",
                "car1",
                "--export",
                "nav,status",
                "--lease-ms",
                "3000",
                "--listen",
                "tcp/0.0.0.0:7447"
            ]
        );
        let text =
            format!("{GOOD}\n[bridge]\nlisten = [\"tcp/0.0.0.0:7447\"]\nimport = [\"gps\"]\n");
        let e = SystemConfig::parse(&text, &f())
            .unwrap()
            .validate(&f())
            .unwrap_err()
            .to_string();
        assert!(e.contains("bridge.import[0]") && e.contains("gps"), "{e}");
        let text = format!("{GOOD}\n[bridge]\n");
        let e = SystemConfig::parse(&text, &f())
            .unwrap()
            .validate(&f())
            .unwrap_err()
            .to_string();
        assert!(e.contains("bridge.listen"), "{e}");
    }

    #[test]
    fn wrong_type_is_named() {
        let text = GOOD.replace("speed = 10.0", "speed = \"fast\"");
        let e = SystemConfig::parse(&text, &f()).unwrap_err().to_string();
        assert!(e.contains("speed"), "{e}");
    }

    #[test]
    fn invalid_value_is_named() {
        let mut c = SystemConfig::parse(GOOD, &f()).unwrap();
        c.fusion.deadlines_ms[SensorId::Gnss] = -1.0;
        let e = c.validate(&f()).unwrap_err().to_string();
        assert!(e.contains("fusion.deadlines_ms.gnss"), "{e}");
        assert!(e.contains("test/sextant.toml"), "{e}");

        let mut c = SystemConfig::parse(GOOD, &f()).unwrap();
        c.fusion.nav_decimation = 0;
        let e = c.validate(&f()).unwrap_err().to_string();
        assert!(e.contains("fusion.nav_decimation"), "{e}");

        let mut c = SystemConfig::parse(GOOD, &f()).unwrap();
        c.run.duration_s = c.run.max_duration_s * 2.0;
        let e = c.validate(&f()).unwrap_err().to_string();
        assert!(e.contains("run.duration_s"), "{e}");

        let mut c = SystemConfig::parse(GOOD, &f()).unwrap();
        c.system.prefix = "/bad".into();
        let e = c.validate(&f()).unwrap_err().to_string();
        assert!(e.contains("system.prefix"), "{e}");
    }

    #[test]
    fn deadlines_scale_with_speed_and_are_floored() {
        let c = SystemConfig::parse(GOOD, &f()).unwrap();
        let d1 = c.wall_deadline(SensorId::Gnss, 1.0);
        let d10 = c.wall_deadline(SensorId::Gnss, 10.0);
        assert!((d1.as_secs_f64() / d10.as_secs_f64() - 10.0).abs() < 1e-6);
        let floor = c.wall_deadline(SensorId::Imu, 1e6);
        assert!((floor.as_secs_f64() * 1000.0 - c.fusion.min_wall_deadline_ms).abs() < 1e-9);
    }

    #[test]
    fn missing_file_is_named() {
        let e = load(Path::new("/nonexistent/sextant.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("/nonexistent/sextant.toml"), "{e}");
    }

    /// `[redundancy]` of the filter tuning: the shipped values parse into the defaults, a bad
    /// value or an unknown key is an error naming the file and the key, and the quantisation
    /// steps reach the derived FDI noise.
    #[test]
    fn redundancy_section_parses_validates_and_names_keys() {
        const FILTER: &str = include_str!("../../config/filter.toml");
        let file = Path::new("cfg/filter.toml");
        let c = parse_navigator_config(FILTER, file).unwrap();
        assert_eq!(
            c.redundancy,
            fusion::redundancy::RedundancyConfig::default()
        );
        for (from, to, key) in [
            (
                "gyro_quantum_deg_s = 0.0",
                "gyro_quantum_deg_s = -0.1",
                "redundancy.gyro_quantum_deg_s",
            ),
            (
                "accel_quantum_mg = 0.0",
                "accel_quantum_mg = nan",
                "redundancy.accel_quantum_mg",
            ),
            (
                "false_alarm_probability = 1e-4",
                "false_alarm_probability = 0.7",
                "redundancy.false_alarm_probability",
            ),
            (
                "block_samples = 100",
                "block_samples = 0",
                "redundancy.block_samples",
            ),
        ] {
            assert!(FILTER.contains(from), "{from}");
            let e = parse_navigator_config(&FILTER.replace(from, to), file).unwrap_err();
            assert!(
                matches!(&e, ConfigError::Invalid { key: k, .. } if k == key),
                "{e}"
            );
            let msg = e.to_string();
            assert!(
                msg.contains("cfg/filter.toml") && msg.contains(key),
                "{msg}"
            );
        }
        let e = parse_navigator_config(
            &FILTER.replace("exclude = true", "exclude = true\nisolate = 1"),
            file,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("isolate") && e.contains("cfg/filter.toml"),
            "{e}"
        );
        let e = parse_navigator_config(&FILTER.replace("exclude = true", "exclude = 3"), file)
            .unwrap_err()
            .to_string();
        assert!(e.contains("exclude"), "{e}");

        // 12 bits over ±150 °/s and ±4 g at 100 Hz with the MEMS white noise (0.3 °/√h,
        // 150 µg/√Hz): σ² = N² dt + (q dt)²/12.
        let text = FILTER
            .replace(
                "gyro_quantum_deg_s = 0.0",
                "gyro_quantum_deg_s = 0.0732421875",
            )
            .replace("accel_quantum_mg = 0.0", "accel_quantum_mg = 1.953125");
        let c = parse_navigator_config(&text, file).unwrap();
        let arw = 0.3_f64.to_radians() / 60.0;
        let vrw = 150e-6 * 9.806_65;
        let f = c.redundancy.fdi_config(arw, vrw, 0.01);
        let qg = 0.0732421875_f64.to_radians() * 0.01;
        let qa = 1.953125e-3 * 9.806_65 * 0.01;
        let want_g = (arw * arw * 0.01 + qg * qg / 12.0).sqrt();
        let want_a = (vrw * vrw * 0.01 + qa * qa / 12.0).sqrt();
        assert!((f.gyro_sigma_rad / want_g - 1.0).abs() < 1e-12);
        assert!((f.accel_sigma_m_s / want_a - 1.0).abs() < 1e-12);
        // Quantisation adds 18 % (gyro) and 14 % (accelerometer) of variance here.
        let rg = (f.gyro_sigma_rad / (arw * 0.1)).powi(2);
        let ra = (f.accel_sigma_m_s / (vrw * 0.1)).powi(2);
        assert!(
            (rg - 1.18).abs() < 0.005 && (ra - 1.14).abs() < 0.005,
            "{rg} {ra}"
        );
    }

    #[test]
    fn embedded_config_contains_the_system_file() {
        assert!(
            embedded_config_files()
                .iter()
                .any(|(p, _)| *p == "sextant.toml")
        );
    }
}
