//! What the launcher and the analysis need from a scenario file: its start epoch, duration and
//! GNSS outage windows. Read leniently from the TOML (`[scenario] start_utc`, `duration_s`;
//! `[[gnss.outages]] start_s, duration_s`, s since the epoch), so that the rest of the scenario
//! format stays the simulator's business.

use fusion::time::GpsTime;
use std::path::{Path, PathBuf};

/// Errors reading a scenario.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// The file could not be read.
    #[error("{file}: cannot read: {source}")]
    Read {
        /// The file.
        file: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Not TOML, or a key has a wrong value.
    #[error("{file}: {message}")]
    Invalid {
        /// The file.
        file: PathBuf,
        /// What is wrong (names the key).
        message: String,
    },
}

/// A time window in GPS ns, `[start_ns, end_ns)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct TimeWindow {
    /// Start, GPS ns.
    pub start_ns: i64,
    /// End, GPS ns.
    pub end_ns: i64,
}

impl TimeWindow {
    /// Whether `t_ns` lies inside.
    pub fn contains(&self, t_ns: i64) -> bool {
        t_ns >= self.start_ns && t_ns < self.end_ns
    }
}

/// The facts of a scenario used here.
#[derive(Debug, Clone, PartialEq)]
pub struct ScenarioInfo {
    /// Scenario name (empty when absent).
    pub name: String,
    /// Start epoch, GPS ns.
    pub epoch_ns: i64,
    /// Duration, s (None when absent).
    pub duration_s: Option<f64>,
    /// GNSS outage windows.
    pub gnss_outages: Vec<TimeWindow>,
}

fn num(v: &toml::Value) -> Option<f64> {
    v.as_float().or_else(|| v.as_integer().map(|i| i as f64))
}

impl ScenarioInfo {
    /// Read the scenario file.
    pub fn load(file: &Path) -> Result<Self, ScenarioError> {
        let text = std::fs::read_to_string(file).map_err(|source| ScenarioError::Read {
            file: file.to_path_buf(),
            source,
        })?;
        Self::parse(&text, file)
    }

    /// Parse scenario text (`file` only for messages).
    pub fn parse(text: &str, file: &Path) -> Result<Self, ScenarioError> {
        let bad = |message: String| ScenarioError::Invalid {
            file: file.to_path_buf(),
            message,
        };
        let v: toml::Table = toml::from_str(text).map_err(|e| bad(e.to_string()))?;
        let meta = v
            .get("scenario")
            .and_then(|m| m.as_table())
            .ok_or_else(|| bad("missing table [scenario]".into()))?;
        let start = meta
            .get("start_utc")
            .and_then(|s| s.as_str())
            .ok_or_else(|| bad("missing string scenario.start_utc".into()))?;
        let epoch = fusion::time::parse_utc(start)
            .map(|u| GpsTime::from_utc_datetime(&u))
            .ok_or_else(|| {
                bad(format!(
                    "scenario.start_utc: expected YYYY-MM-DDTHH:MM:SS[.fff][Z], got {start:?}"
                ))
            })?;
        let duration_s = meta.get("duration_s").and_then(num);
        let name = meta
            .get("name")
            .and_then(|s| s.as_str())
            .unwrap_or_default()
            .to_string();
        let mut gnss_outages = Vec::new();
        if let Some(outages) = v.get("gnss").and_then(|g| g.get("outages")) {
            let arr = outages
                .as_array()
                .ok_or_else(|| bad("gnss.outages must be an array of tables".into()))?;
            for (i, w) in arr.iter().enumerate() {
                let start_s = w.get("start_s").and_then(num);
                let dur_s = w.get("duration_s").and_then(num);
                match (start_s, dur_s) {
                    (Some(s), Some(d)) if s.is_finite() && d.is_finite() && d >= 0.0 => {
                        let start_ns = epoch.ns + (s * 1e9).round() as i64;
                        gnss_outages.push(TimeWindow {
                            start_ns,
                            end_ns: start_ns + (d * 1e9).round() as i64,
                        });
                    }
                    _ => {
                        return Err(bad(format!(
                            "gnss.outages[{i}]: needs numbers start_s and duration_s >= 0"
                        )));
                    }
                }
            }
        }
        Ok(Self {
            name,
            epoch_ns: epoch.ns,
            duration_s,
            gnss_outages,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outages_are_in_gps_ns() {
        let text = r#"
[scenario]
name = "t"
start_utc = "2024-03-20T12:00:00Z"
duration_s = 600
[[gnss.outages]]
start_s = 100.0
duration_s = 60.0
"#;
        let s = ScenarioInfo::parse(text, Path::new("x.toml")).unwrap();
        let epoch = GpsTime::from_utc(2024, 3, 20, 12, 0, 0.0).ns;
        assert_eq!(s.epoch_ns, epoch);
        assert_eq!(s.duration_s, Some(600.0));
        assert_eq!(
            s.gnss_outages,
            vec![TimeWindow {
                start_ns: epoch + 100_000_000_000,
                end_ns: epoch + 160_000_000_000
            }]
        );
    }

    #[test]
    fn bad_epoch_names_the_key() {
        let e = ScenarioInfo::parse(
            "[scenario]\nstart_utc = \"yesterday\"\n",
            Path::new("x.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("scenario.start_utc") && e.contains("x.toml"),
            "{e}"
        );
    }
}
