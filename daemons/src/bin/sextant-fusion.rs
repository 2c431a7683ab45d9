//! The fusion daemon: `sextant-fusion --config FILE --prefix P --out FILE.mcap [--speed X]`.
//! Runs until SIGINT/SIGTERM, then finishes the recording, prints its final counters as one
//! line on stdout (`sextant_daemons::exit_report`) and exits 0. It never overwrites an existing
//! recording. It writes the navigator's checkpoint next to the recording
//! (`navigator.checkpoint`, or `--checkpoint FILE`) and, when one is there at start, resumes
//! from it if it is fresh (warm restart); a corrupt or stale one is refused with a message and
//! the navigator aligns. With a calibration memory (`--calibration FILE` or `[fusion]
//! calibration_file`) it starts from the sensor errors the previous run ended with and saves
//! its own at the end.

use anyhow::Context;
use clap::Parser;
use sextant_daemons::{bus_check, checkpoint, config, daemon, exit_report, logging, signals};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Sextant fusion daemon: sensors in, navigation solution and status out, everything recorded.
#[derive(Debug, Parser)]
#[command(name = "sextant-fusion", version)]
struct Args {
    /// System configuration file.
    #[arg(long, default_value = "config/sextant.toml")]
    config: PathBuf,
    /// Service-name prefix (default: `system.prefix` of the config).
    #[arg(long)]
    prefix: Option<String>,
    /// Recording to write (MCAP).
    #[arg(long)]
    out: PathBuf,
    /// Speed-up of simulated over wall time of the drivers (scales the deadlines).
    #[arg(long, default_value_t = 1.0)]
    speed: f64,
    /// Checkpoint file of the warm restart (default: `navigator.checkpoint` in the directory
    /// of `--out`).
    #[arg(long)]
    checkpoint: Option<PathBuf>,
    /// Calibration memory: read at the start (the previous run's sensor errors as the prior),
    /// written at the end (default: `[fusion] calibration_file`; none when neither is given).
    #[arg(long)]
    calibration: Option<PathBuf>,
}

fn main() -> anyhow::Result<()> {
    // A failed log write (full disk) is never fatal.
    logging::init();
    // iceoryx2's own log: warnings and errors only unless IOX2_LOG_LEVEL says otherwise.
    let args = Args::parse();
    let stop = signals::install()?;
    if !(args.speed.is_finite() && args.speed > 0.0) {
        anyhow::bail!("--speed must be > 0, got {}", args.speed);
    }
    let cfg = config::load(&args.config)?;
    let prefix = args
        .prefix
        .unwrap_or_else(|| cfg.system.system.prefix.clone());
    bus_check::validate_prefix(&prefix).with_context(|| format!("--prefix {prefix:?}"))?;
    // Never overwrite a recording (another run's, or one still open by another process).
    if std::fs::metadata(&args.out).is_ok_and(|m| m.is_file() && m.len() > 0) {
        anyhow::bail!(
            "{} exists: a recording is never overwritten; remove it or give another --out",
            args.out.display()
        );
    }
    if let Some(dir) = args.out.parent()
        && !dir.as_os_str().is_empty()
    {
        // Not fatal: without a recording the fusion still navigates and publishes; the recorder
        // reports the error (naming the file) and counts every record as dropped.
        if let Err(e) = std::fs::create_dir_all(dir) {
            tracing::error!(
                "cannot create the recording directory {}: {e}",
                dir.display()
            );
        }
    }
    let mut navigator = fusion::navigator::Navigator::new(cfg.navigator.clone())
        .with_context(|| format!("filter configuration {}", cfg.filter_path.display()))?;
    // A recording to a device or a pipe (`/dev/full`, a FIFO) has no directory of its own:
    // its directory is the system's, shared by every run, so the checkpoint goes there only
    // when `--checkpoint` names it (a run must never resume from another run's checkpoint).
    let recording_is_a_device =
        std::fs::metadata(&args.out).is_ok_and(|m| !m.is_file() && !m.is_dir());
    let checkpoint = args.checkpoint.clone().or_else(|| {
        (!recording_is_a_device).then(|| {
            args.out
                .parent()
                .unwrap_or(std::path::Path::new(""))
                .join("navigator.checkpoint")
        })
    });
    let mut started_from = None;
    let read = match &checkpoint {
        Some(path) => checkpoint::read(path),
        None => {
            tracing::info!(
                "recording to the device {}: no checkpoint (--checkpoint FILE gives one)",
                args.out.display()
            );
            Ok(None)
        }
    };
    let path_of = |c: &Option<PathBuf>| {
        c.as_ref()
            .map_or_else(String::new, |p| p.display().to_string())
    };
    match read {
        Ok(Some(snapshot)) => {
            let t = snapshot.gps_time_ns;
            started_from = Some(snapshot.clone());
            match navigator.warm_start(snapshot) {
                fusion::navigator::WarmStartOutcome::Refused(r) => tracing::warn!(
                    "checkpoint {} refused ({r}): aligning from the priors",
                    path_of(&checkpoint)
                ),
                _ => tracing::info!(
                    "checkpoint {} of GPS time {:.3} s read: resuming if fresh at the first IMU sample",
                    path_of(&checkpoint),
                    t as f64 * 1e-9
                ),
            }
        }
        Ok(None) if checkpoint.is_some() => {
            tracing::info!("no checkpoint at {}: aligning", path_of(&checkpoint))
        }
        Ok(None) => {}
        Err(e) => tracing::warn!("{e}: refused, aligning from the priors"),
    }
    let calibration = args
        .calibration
        .clone()
        .or_else(|| cfg.system.fusion.calibration_file.clone());
    let mut calibration_used = None;
    if let Some(path) = &calibration {
        calibration_used = load_calibration(&mut navigator, path);
    }
    let mut metadata = recording_metadata(&cfg, &prefix, args.speed)?;
    if let Some((saved, elapsed_s)) = &calibration_used {
        // Offline replay loads the same memory with the same time off, so the recording
        // replays bit for bit.
        use sextant_daemons::recorder::{
            CALIBRATION_KEY_ELAPSED_S, CALIBRATION_KEY_SNAPSHOT, CALIBRATION_METADATA_NAME,
        };
        let json = serde_json::to_string(saved).context("serializing the calibration")?;
        metadata.push((
            CALIBRATION_METADATA_NAME.to_string(),
            BTreeMap::from([
                (CALIBRATION_KEY_SNAPSHOT.to_string(), json),
                (CALIBRATION_KEY_ELAPSED_S.to_string(), elapsed_s.to_string()),
            ]),
        ));
    }
    if let Some(snapshot) = &started_from {
        // Offline replay starts from the same snapshot (refused or not: the engine decides
        // again, identically), so a warm-restarted recording replays bit for bit.
        use sextant_daemons::recorder::{WARM_START_KEY_SNAPSHOT, WARM_START_METADATA_NAME};
        let json = serde_json::to_string(snapshot).context("serializing the checkpoint")?;
        metadata.push((
            WARM_START_METADATA_NAME.to_string(),
            BTreeMap::from([(WARM_START_KEY_SNAPSHOT.to_string(), json)]),
        ));
    }
    let opts = daemon::DaemonOptions {
        prefix,
        out: args.out,
        speed: args.speed,
        system: cfg.system,
        node_name: "sextant-fusion".into(),
        metadata,
        checkpoint,
    };
    let report = daemon::run(navigator, &opts, stop)?;
    tracing::info!(
        "done: {} IMU samples, {} solutions ({} published), {} records written, {} dropped",
        report.imu_received,
        report.solutions,
        report.solutions_published,
        report.recorder.written,
        report.recorder.dropped
    );
    if report.recorder.errors > 0 || report.recorder.dropped > 0 {
        tracing::error!(
            "the recording {} is incomplete: {} write errors, {} records dropped",
            opts.out.display(),
            report.recorder.errors,
            report.recorder.dropped
        );
    }
    if let Some(path) = &calibration {
        save_calibration(path, report.final_snapshot.as_ref());
    }
    let exit = exit_report::ExitReport {
        recording: opts.out.clone(),
        imu_received: report.imu_received,
        solutions: report.solutions,
        solutions_published: report.solutions_published,
        records_written: report.recorder.written,
        records_dropped: report.recorder.dropped,
        recorder_errors: report.recorder.errors,
        segments: report.segments.clone(),
        log_lines_lost: logging::lost_lines(),
        solutions_stale: report.solutions_stale,
    };
    logging::stdout_line(&exit.line());
    Ok(())
}

/// Load the calibration memory at `path` into the navigator; the snapshot and the time off
/// (s) when it is used. Any problem is logged and the navigator starts from the data sheet.
fn load_calibration(
    navigator: &mut fusion::navigator::Navigator,
    path: &std::path::Path,
) -> Option<(fusion::navigator::NavSnapshot, f64)> {
    let saved = match checkpoint::read_calibration(path) {
        Ok(Some(s)) => s,
        Ok(None) => {
            tracing::info!(
                "no calibration memory at {} yet: starting from the data sheet",
                path.display()
            );
            return None;
        }
        Err(e) => {
            tracing::warn!("{e}: starting from the data sheet");
            return None;
        }
    };
    let now_ns = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as i64);
    // A system clock set back since the save: the time off is unknown beyond "none".
    let elapsed_s = ((now_ns - saved.saved_unix_ns) as f64 * 1e-9).max(0.0);
    match navigator.load_calibration(&saved.snapshot, elapsed_s) {
        Ok(loaded) => {
            tracing::info!(
                "calibration memory {} saved {:.1} h ago: {} of {} sensor-error states start from it (tighter than the data sheet)",
                path.display(),
                elapsed_s / 3600.0,
                loaded.used(),
                fusion::navigator::REMEMBERED.len()
            );
            Some((saved.snapshot, elapsed_s))
        }
        Err(e) => {
            tracing::warn!(
                "calibration memory {} refused ({e}): starting from the data sheet",
                path.display()
            );
            None
        }
    }
}

/// Save the estimate the run ended with as the calibration memory at `path`; without one (the
/// navigator was not navigating at the end) the file is left as it was.
fn save_calibration(path: &std::path::Path, last: Option<&fusion::navigator::NavSnapshot>) {
    let Some(snapshot) = last else {
        tracing::warn!(
            "not navigating at the end: calibration memory {} left as it was",
            path.display()
        );
        return;
    };
    let saved = checkpoint::SavedCalibration {
        saved_unix_ns: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as i64),
        snapshot: snapshot.clone(),
    };
    match checkpoint::write_calibration(path, &saved) {
        Ok(()) => tracing::info!("calibration memory saved to {}", path.display()),
        Err(e) => tracing::error!("{e}: the calibration memory was not saved"),
    }
}

/// The configuration embedded in the recording (MCAP metadata `sextant/config`): the filter
/// configuration exactly as the engine got it (serialized `NavigatorConfig`), the files it came
/// from, prefix and speed. Offline replay rebuilds the engine from `filter_toml` alone.
fn recording_metadata(
    cfg: &config::LoadedConfig,
    prefix: &str,
    speed: f64,
) -> anyhow::Result<Vec<(String, BTreeMap<String, String>)>> {
    use sextant_daemons::recorder::{CONFIG_KEY_FILTER_TOML, CONFIG_METADATA_NAME};
    let mut m = BTreeMap::new();
    m.insert(
        CONFIG_KEY_FILTER_TOML.to_string(),
        toml::to_string(&cfg.navigator).context("serializing the filter configuration")?,
    );
    m.insert(
        "filter_path".to_string(),
        cfg.filter_path.display().to_string(),
    );
    if let Ok(text) = std::fs::read_to_string(&cfg.filter_path) {
        m.insert("filter_file_text".to_string(), text);
    }
    m.insert("system_path".to_string(), cfg.path.display().to_string());
    if let Ok(text) = std::fs::read_to_string(&cfg.path) {
        m.insert("system_file_text".to_string(), text);
    }
    m.insert("prefix".to_string(), prefix.to_string());
    m.insert("speed".to_string(), speed.to_string());
    m.insert(
        "sextant_version".to_string(),
        env!("CARGO_PKG_VERSION").to_string(),
    );
    Ok(vec![(CONFIG_METADATA_NAME.to_string(), m)])
}
