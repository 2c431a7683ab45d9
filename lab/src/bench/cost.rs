//! Cost curves: how the offline cost of the fusion per IMU sample (the in-process
//! [`Navigator`] over a pre-generated message stream, as the bench's offline throughput) grows
//! with the IMU rate, the number of active filter states, the satellites of tight GNSS coupling
//! and the number of redundant IMU channels.
//!
//! Every point runs the vehicle scenario with every aiding sensor (star tracker, GNSS, odometer,
//! baro) and one thing changed:
//! - **IMU rate**: `[imu] rate_hz` of the scenario, 100 Hz to 2 kHz (400 Hz and 2 kHz on the
//!   simulator's 0.5 ms truth grid, the others on its 1 ms grid);
//! - **active states**: the switchable groups of `[states]` switched on one after the other;
//!   the position, velocity, attitude, gyro and accelerometer bias (15), baro bias and odometer
//!   scale (2) are always estimated, so the curve spans 17 to 31 states;
//! - **tight satellites**: `gnss_mode = "tight"` with at most n satellites tracked (those of
//!   highest C/N0, [`OfflineSim::limit_satellites`]) from 3 s on (after the alignment fix); 0 is
//!   tight with no satellite (no GNSS update), the top of the curve is a full receiver: 32
//!   satellites, the highest of a sky of 128 (one Walker pattern of four constellations'
//!   worth; [`drivers_sim::gnss::MAX_CONSTELLATION`]);
//! - **redundant IMU channels**: `[imu.channels]` pyramid of N single-axis channels (least
//!   squares combination and parity-space FDI in the navigator), the triad as reference.
//!
//! Only the fusion is timed (the stream is generated first), in CPU time of the thread, from the
//! first IMU sample at or after the measurement start while the navigator navigates, to the
//! end; each point is the least of its repetitions (a loaded machine only ever adds time).

use crate::experiments::plot::{Chart, Line, Panel, color, panel_chart};
use anyhow::Context;
use drivers_sim::offline::{OfflineSim, SatelliteLimit, feed};
use drivers_sim::scenario::Scenario;
use fusion::navigator::{GnssMode, Navigator, NavigatorConfig, StateSwitches};
use msgs::{Channel, Record};
use serde_json::{Value, json};
use std::path::Path;

/// Points and lengths of the curves.
struct CurveSizes {
    /// Simulated seconds of each run.
    sim_s: f64,
    /// Timing starts at this simulated time, s.
    measure_from_s: f64,
    /// Timed passes per point (the least is kept).
    repetitions: usize,
    rates_hz: Vec<f64>,
    /// Indices into [`STATE_STEPS`].
    state_steps: Vec<usize>,
    /// Satellite counts (clipped to what the simulator shows; `usize::MAX` = all).
    satellites: Vec<usize>,
    channels: Vec<usize>,
}

impl CurveSizes {
    fn of(quick: bool) -> Self {
        if quick {
            CurveSizes {
                sim_s: 10.0,
                measure_from_s: 3.0,
                repetitions: 1,
                rates_hz: vec![100.0, 2000.0],
                state_steps: vec![0, STATE_STEPS.len() - 1],
                satellites: vec![1, usize::MAX],
                channels: vec![3, 8],
            }
        } else {
            // 120 s standing, then driving: the timed part is the first minute of the drive.
            CurveSizes {
                sim_s: 185.0,
                measure_from_s: 125.0,
                repetitions: 3,
                rates_hz: vec![100.0, 125.0, 200.0, 250.0, 400.0, 500.0, 1000.0, 2000.0],
                state_steps: (0..STATE_STEPS.len()).collect(),
                satellites: vec![0, 1, 2, 3, 4, 6, 8, 10, 12, 16, 24, 32, usize::MAX],
                channels: vec![3, 4, 5, 6, 7, 8],
            }
        }
    }
}

/// The state groups switched on cumulatively, with the label of each step.
const STATE_STEPS: [&str; 6] = [
    "core 15 + baro bias + odometer scale",
    "+ gyro scale factors",
    "+ accelerometer scale factors",
    "+ gyro non-orthogonality",
    "+ receiver clock",
    "+ star-tracker boresight",
];

fn switches(step: usize) -> StateSwitches {
    StateSwitches {
        gyro_scale: step >= 1,
        accel_scale: step >= 2,
        gyro_misalignment: step >= 3,
        clock: step >= 4,
        boresight: step >= 5,
    }
}

fn state_count(s: &StateSwitches) -> usize {
    let on = |b: bool, n: usize| if b { n } else { 0 };
    17 + on(s.gyro_scale, 3)
        + on(s.accel_scale, 3)
        + on(s.gyro_misalignment, 3)
        + on(s.clock, 2)
        + on(s.boresight, 3)
}

/// One timed point.
#[derive(Debug, Clone, Copy)]
struct Timing {
    ns_per_imu_sample: f64,
    imu_samples: u64,
    rejected: u64,
}

/// CPU time of the calling thread, ns: unlike wall time it does not count the time the thread
/// waited for a core, so the curves survive a machine loaded by other work (cache sharing and
/// frequency changes remain).
fn thread_cpu_ns() -> u64 {
    nix::time::clock_gettime(nix::time::ClockId::CLOCK_THREAD_CPUTIME_ID).map_or(0, |t| {
        t.tv_sec() as u64 * 1_000_000_000 + t.tv_nsec() as u64
    })
}

/// Time (thread CPU) the navigator over `msgs` from the first navigating IMU sample at or after
/// `from_ns`.
fn time_fusion(
    cfg: &NavigatorConfig,
    msgs: &[Record],
    from_ns: i64,
    repetitions: usize,
) -> anyhow::Result<Timing> {
    let mut best: Option<Timing> = None;
    for _ in 0..repetitions.max(1) {
        let mut nav = Navigator::new(cfg.clone())?;
        let mut t0: Option<u64> = None;
        let mut n = 0u64;
        let mut rejected = 0u64;
        for m in msgs {
            let r = feed(&mut nav, m);
            rejected += u64::from(r.is_err());
            if let Record::Imu(s) = m
                && s.header.time_ns >= from_ns
                && nav.is_navigating()
            {
                if t0.is_none() {
                    t0 = Some(thread_cpu_ns());
                } else {
                    n += 1;
                }
            }
        }
        let t0 = t0.context("the navigator was not navigating in the timed part of the run")?;
        let ns = thread_cpu_ns().saturating_sub(t0) as f64 / n.max(1) as f64;
        if best.is_none_or(|b| ns < b.ns_per_imu_sample) {
            best = Some(Timing {
                ns_per_imu_sample: ns,
                imu_samples: n,
                rejected,
            });
        }
    }
    best.context("no repetition")
}

/// A copy of the vehicle scenario with `edit` applied to its `[table]`, loaded.
fn scenario_variant(
    cfg_dir: &Path,
    name: &str,
    table: &str,
    edit: impl FnOnce(&mut toml::Table),
) -> anyhow::Result<Scenario> {
    let src = cfg_dir.join("scenarios/vehicle.toml");
    let text = std::fs::read_to_string(&src).with_context(|| format!("read {}", src.display()))?;
    let mut doc: toml::Table =
        toml::from_str(&text).with_context(|| format!("parse {}", src.display()))?;
    let t = doc
        .get_mut(table)
        .and_then(|v| v.as_table_mut())
        .with_context(|| format!("no [{table}] in {}", src.display()))?;
    edit(t);
    let path = cfg_dir.join(format!("scenarios/bench_cost_{name}.toml"));
    std::fs::write(&path, toml::to_string(&doc)?)
        .with_context(|| format!("write {}", path.display()))?;
    Ok(Scenario::load(&path)?)
}

fn stream(scn: &Scenario, sim_s: f64, limit: Option<usize>) -> (Vec<Record>, i64) {
    let mut sim = OfflineSim::with_channels(scn, &Channel::SENSORS).with_duration_s(sim_s);
    if let Some(max_satellites) = limit {
        sim = sim.limit_satellites(SatelliteLimit {
            start_s: 3.0,
            duration_s: 1e9,
            max_satellites,
        });
    }
    let epoch = sim.epoch_ns();
    (sim.collect(), epoch)
}

fn point(x: f64, t: &Timing) -> Value {
    json!({
        "x": x,
        "ns_per_imu_sample": t.ns_per_imu_sample,
        "imu_samples": t.imu_samples,
        "rejected_inputs": t.rejected,
    })
}

/// Measure every curve; `base` is the bench's filter configuration (short alignment).
pub fn run(cfg_dir: &Path, base: &NavigatorConfig, quick: bool) -> anyhow::Result<Value> {
    let sz = CurveSizes::of(quick);
    let from = |epoch: i64| epoch + (sz.measure_from_s * 1e9) as i64;

    // IMU rate.
    let mut rate = Vec::new();
    for &hz in &sz.rates_hz {
        let scn = scenario_variant(cfg_dir, &format!("{}hz", hz as u64), "imu", |imu| {
            imu.insert("rate_hz".into(), toml::Value::Float(hz));
        })?;
        let (msgs, epoch) = stream(&scn, sz.sim_s, None);
        let t = time_fusion(base, &msgs, from(epoch), sz.repetitions)?;
        let mut p = point(hz, &t);
        p["imu_rate_hz"] = json!(hz);
        // Share of one core the fusion needs at this rate (cost × rate).
        p["cpu_percent_of_one_core"] = json!(t.ns_per_imu_sample * hz * 1e-7);
        rate.push(p);
    }

    // Active states and tight satellites, on the default 200 Hz scenario.
    let scn = scenario_variant(cfg_dir, "default", "imu", |_| {})?;
    let (msgs, epoch) = stream(&scn, sz.sim_s, None);
    let mut states = Vec::new();
    for &step in &sz.state_steps {
        let mut cfg = base.clone();
        cfg.states = switches(step);
        if !cfg.states.boresight {
            // The star tracker's roll bias would keep the boresight group active.
            cfg.aiding.star_roll_bias_sigma_arcsec = 0.0;
        }
        let t = time_fusion(&cfg, &msgs, from(epoch), sz.repetitions)?;
        let n = state_count(&cfg.states) as f64;
        let mut p = point(n, &t);
        p["active_states"] = json!(n);
        p["groups"] = json!(STATE_STEPS[step]);
        states.push(p);
    }
    // The satellites: a sky of four constellations' worth (128 in one Walker pattern, about
    // 45 above the mask), so that the receiver's 32 channels are all in use.
    let dense = scenario_variant(cfg_dir, "128sats", "gnss", |gnss| {
        let mut c = toml::Table::new();
        c.insert("planes".into(), toml::Value::Integer(16));
        c.insert("per_plane".into(), toml::Value::Integer(8));
        c.insert("phasing".into(), toml::Value::Integer(1));
        c.insert("inclination_deg".into(), toml::Value::Float(55.0));
        c.insert("semi_major_axis_m".into(), toml::Value::Float(26_559_700.0));
        gnss.insert("constellation".into(), toml::Value::Table(c));
    })?;
    let (dense_msgs, _) = stream(&dense, sz.sim_s, None);
    let max_sats = dense_msgs
        .iter()
        .filter_map(|m| match m {
            Record::Gnss(g) => Some(g.n_satellites as usize),
            _ => None,
        })
        .max()
        .unwrap_or(0);
    let mut sat_counts: Vec<usize> = sz.satellites.iter().map(|&n| n.min(max_sats)).collect();
    sat_counts.dedup();
    let mut tight_cfg = base.clone();
    tight_cfg.gnss_mode = GnssMode::Tight;
    tight_cfg.states.clock = true;
    let mut sats = Vec::new();
    for &n in &sat_counts {
        let (msgs, epoch) = stream(&dense, sz.sim_s, Some(n));
        let t = time_fusion(&tight_cfg, &msgs, from(epoch), sz.repetitions)?;
        let mut p = point(n as f64, &t);
        p["satellites"] = json!(n);
        sats.push(p);
    }

    // Redundant channels, with the triad for reference.
    let triad = time_fusion(base, &msgs, from(epoch), sz.repetitions)?;
    let mut channels = Vec::new();
    for &n in &sz.channels {
        let scn = scenario_variant(cfg_dir, &format!("{n}ch"), "imu", |imu| {
            let mut t = toml::Table::new();
            t.insert("layout".into(), toml::Value::String("pyramid".into()));
            t.insert("n".into(), toml::Value::Integer(n as i64));
            imu.insert("channels".into(), toml::Value::Table(t));
        })?;
        let (msgs, epoch) = stream(&scn, sz.sim_s, None);
        let t = time_fusion(base, &msgs, from(epoch), sz.repetitions)?;
        let mut p = point(n as f64, &t);
        p["channels"] = json!(n);
        channels.push(p);
    }
    Ok(json!({
        "scenario": "vehicle (every aiding sensor)",
        "simulated_s": sz.sim_s,
        "timed_from_s": sz.measure_from_s,
        "repetitions": sz.repetitions,
        "imu_rate": rate,
        "active_states": states,
        "tight_satellites": sats,
        "satellites_simulated_max": max_sats,
        "gnss_rate_hz": scn.spec.gnss.rate_hz,
        "imu_channels": channels,
        "triad_ns_per_imu_sample": triad.ns_per_imu_sample,
    }))
}

fn series(curve: &Value) -> Vec<(f64, f64)> {
    curve
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(|p| Some((p["x"].as_f64()?, p["ns_per_imu_sample"].as_f64()?)))
                .collect()
        })
        .unwrap_or_default()
}

/// The four curves as panels of one PNG.
pub fn png(path: &Path, c: &Value) -> anyhow::Result<()> {
    let panel = |key: &str, label: &str, i: usize| {
        vec![Line::solid(label.to_string(), series(&c[key]), color(i)).with_markers()]
    };
    let rate = panel("imu_rate", "ns per IMU sample", 0);
    let states = panel("active_states", "ns per IMU sample", 1);
    let sats = panel("tight_satellites", "ns per IMU sample (tight)", 2);
    let mut chans = panel("imu_channels", "ns per IMU sample (pyramid)", 3);
    if let (Some(t), Some(x0), Some(x1)) = (
        c["triad_ns_per_imu_sample"].as_f64(),
        series(&c["imu_channels"]).first().map(|p| p.0),
        series(&c["imu_channels"]).last().map(|p| p.0),
    ) {
        chans.push(Line::dashed("triad", vec![(x0, t), (x1, t)], color(4)));
    }
    let sat_label = format!(
        "satellites tracked (GNSS {} Hz)",
        c["gnss_rate_hz"].as_f64().unwrap_or(f64::NAN)
    );
    let charts = [
        Panel {
            chart: Chart {
                title: "Cost vs IMU rate",
                x_label: "IMU rate, Hz",
                y_label: "fusion CPU time, ns per IMU sample",
                log_x: true,
                log_y: false,
                lines: &rate,
            },
            y_from_zero: true,
        },
        Panel {
            chart: Chart::linear(
                "Cost vs active filter states",
                "active error states",
                "fusion CPU time, ns per IMU sample",
                &states,
            ),
            y_from_zero: true,
        },
        Panel {
            chart: Chart::linear(
                "Cost vs satellites (tight coupling)",
                &sat_label,
                "fusion CPU time, ns per IMU sample",
                &sats,
            ),
            y_from_zero: true,
        },
        Panel {
            chart: Chart::linear(
                "Cost vs redundant IMU channels",
                "single-axis channels",
                "fusion CPU time, ns per IMU sample",
                &chans,
            ),
            y_from_zero: true,
        },
    ];
    panel_chart(path, &charts, 2, (1400, 1000))?;
    Ok(())
}

/// The curves' lines of the bench table.
pub fn table(c: &Value) -> String {
    let line = |key: &str, unit: &str| {
        c[key]
            .as_array()
            .map(|a| {
                a.iter()
                    .map(|p| {
                        format!(
                            "{}{unit} {:.0}",
                            p["x"].as_f64().unwrap_or(f64::NAN),
                            p["ns_per_imu_sample"].as_f64().unwrap_or(f64::NAN)
                        )
                    })
                    .collect::<Vec<_>>()
                    .join(", ")
            })
            .unwrap_or_default()
    };
    let mut t = String::new();
    t += "fusion cost, CPU ns per IMU sample (offline, thread CPU time, every aiding sensor):\n";
    t += &format!("  vs IMU rate: {}\n", line("imu_rate", " Hz"));
    t += &format!("  vs active states: {}\n", line("active_states", " states"));
    t += &format!(
        "  vs satellites (tight, GNSS {} Hz, simulator shows up to {}): {}\n",
        c["gnss_rate_hz"],
        c["satellites_simulated_max"],
        line("tight_satellites", " sats")
    );
    t += &format!(
        "  vs redundant channels: {} (triad {:.0})\n",
        line("imu_channels", " ch"),
        c["triad_ns_per_imu_sample"].as_f64().unwrap_or(f64::NAN)
    );
    t
}
