//! The `sextant` command. `sextant run`: check the configuration, start the drivers and the
//! fusion daemon under the supervisor (`sextant_daemons::supervisor`), then analyse the
//! recording (table, `summary.json`, PNG plots).

use anyhow::{Context, bail};
use clap::{Parser, Subcommand};
use sextant_lab::shipped_config as experiments_config;
use sextant_lab::supervisor::{self, ChildSpec, End};
use sextant_lab::{analysis, config, plots, scenario};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Sextant navigation computer.
#[derive(Debug, Parser)]
#[command(
    name = "sextant",
    version,
    about,
    after_help = "Examples:\n  sextant run                                  the live system on the default configuration\n  sextant report out/run/recording.mcap --out out/report\n  sextant completions bash > ~/.local/share/bash-completion/completions/sextant\n\nExit status: 0 success; 1 error (the message says why); 2 bad command line;\n3 `run` ended but its recording is incomplete."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// No progress bars (they are drawn only when stderr is a terminal anyway).
    #[arg(long, short, global = true)]
    quiet: bool,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the live system: drivers, fusion and recorder; then summarise the recording.
    #[command(
        after_help = "Examples:\n  sextant run --duration 300 --speed 20 --out out/short\n  sextant run --foxglove        then in Foxglove: Open connection → Foxglove WebSocket → ws://127.0.0.1:8765\n\nExit status: 0 complete recording; 3 the run ended but its recording is incomplete;\n1 the fusion daemon failed or the run was refused."
    )]
    Run(RunArgs),
    /// Run a named offline experiment; prints its table, writes summary.json and PNG plots.
    #[command(
        after_help = "Examples:\n  sextant experiment schuler --out out/schuler\n  sextant experiment all --out docs\n  sextant experiment hybrid-berlin --data DIR --out out/berlin"
    )]
    Experiment(ExperimentArgs),
    /// Measure latency through the real processes (200 Hz and 1 kHz IMU), offline fusion and
    /// recorder throughput, CPU and memory; prints a table, writes summary.json and a histogram.
    #[command(after_help = "Example:\n  sextant bench --out out/bench")]
    Bench(BenchArgs),
    /// The echo end of the bench's floor measurement (started by `sextant bench`): answers
    /// every IMU sample on PREFIX/imu with a solution on PREFIX/nav until SIGINT/SIGTERM.
    #[command(
        hide = true,
        after_help = "Example (normally started by `sextant bench`):\n  sextant bench-echo --prefix sextant-floor"
    )]
    BenchEcho {
        /// Service-name prefix of the floor run.
        #[arg(long)]
        prefix: String,
    },
    /// Replay a recording: offline through the fusion (bit-exact check, or other settings with
    /// --config), or live onto the iceoryx2 services (bench).
    #[command(
        after_help = "Examples:\n  sextant replay --offline out/run/recording.mcap --out out/replay\n  sextant replay --offline out/run/recording.mcap --config my-filter.toml --out out/tuned\n  sextant replay --live out/run/recording.mcap --speed 10 --prefix bench"
    )]
    Replay(ReplayArgs),
    /// Post-analysis of a recording: errors against truth, NIS per sensor, rejections, mode
    /// changes, dropouts; REPORT.md, summary.json and PNG plots.
    #[command(after_help = "Example:\n  sextant report out/run/recording.mcap --out out/report")]
    Report(ReportArgs),
    /// Calibrate a sensor from a recording: `calibrate boresight REC.mcap --site LAT,LON,H`
    /// estimates the star-tracker / IMU boresight angles κ1..κ3 (paper 000) from a static log.
    #[command(
        after_help = "Example:\n  sextant calibrate boresight static.mcap --site 55.655,37.534,200 --out out/calibrate"
    )]
    Calibrate(CalibrateArgs),
    /// Import real data into a recording: `import rinex OBS NAV --out REC.mcap` fixes every
    /// epoch of a RINEX 3 observation file with the GPS broadcast ephemerides of a navigation
    /// file and writes the GNSS samples (measurements and fix) for `report` and `replay`.
    #[command(
        after_help = "Example:\n  sextant import rinex tests/data/rinex-esbc/ESBC00DNK_R_20201770000_01H_30S_MO.rnx.gz \\\n    tests/data/rinex-esbc/ESBC00DNK_R_20201770000_01D_GN.rnx.gz --out out/import/esbc.mcap"
    )]
    Import(ImportArgs),
    /// Print a shell completion script for SHELL (bash, zsh, fish, elvish, powershell).
    #[command(
        after_help = "Examples:\n  sextant completions bash > ~/.local/share/bash-completion/completions/sextant\n  sextant completions zsh > ~/.zfunc/_sextant\n  sextant completions fish > ~/.config/fish/completions/sextant.fish"
    )]
    Completions {
        /// The shell.
        shell: clap_complete::Shell,
    },
    /// Export a recording to other tools' formats: `export kfgins REC.mcap --out DIR` (KF-GINS
    /// text files), `export csv REC.mcap --out DIR` (CSV with a TOML description).
    #[command(
        after_help = "Examples:\n  sextant export kfgins out/run/recording.mcap --out out/export/kfgins\n  sextant export csv out/run/recording.mcap --out out/export/csv"
    )]
    Export(ExportArgs),
}

#[derive(Debug, clap::Args)]
struct ExportArgs {
    #[command(subcommand)]
    what: ExportWhat,
}

#[derive(Debug, Subcommand)]
enum ExportWhat {
    /// KF-GINS text files: imu.txt (GPS seconds of week, Δθ rad, Δv m/s), gnss.txt (seconds of
    /// week, lat, lon deg, height m, σ N/E/D m), truth.nav and nav.nav (week, seconds of week,
    /// lat, lon, height, v N/E/D, roll, pitch, yaw deg), filter.toml.
    #[command(
        after_help = "Example:\n  sextant export kfgins out/run/recording.mcap --out out/export/kfgins"
    )]
    Kfgins {
        /// The recording.
        recording: PathBuf,
        /// Output directory.
        #[arg(long, default_value = "out/export/kfgins")]
        out: PathBuf,
    },
    /// CSV files (GPS seconds, ECEF GNSS with full covariances, IMU increments) and the
    /// description.toml that `import csv --describe` reads back bit for bit.
    #[command(
        after_help = "Example:\n  sextant export csv out/run/recording.mcap --out out/export/csv"
    )]
    Csv {
        /// The recording.
        recording: PathBuf,
        /// Output directory.
        #[arg(long, default_value = "out/export/csv")]
        out: PathBuf,
    },
}

#[derive(Debug, clap::Args)]
struct ImportArgs {
    #[command(subcommand)]
    what: ImportWhat,
}

#[derive(Debug, Subcommand)]
enum ImportWhat {
    /// RINEX 3 observations (GPS C1C, C2W, D1C, S1C) + GPS broadcast navigation (`.rnx` or
    /// `.rnx.gz`). Pseudoranges are written corrected for the satellite clock and the modelled
    /// atmosphere, as the GNSS message defines them.
    #[command(
        after_help = "Example:\n  sextant import rinex tests/data/rinex-esbc/ESBC00DNK_R_20201770000_01H_30S_MO.rnx.gz \\\n    tests/data/rinex-esbc/ESBC00DNK_R_20201770000_01D_GN.rnx.gz --out out/import/esbc.mcap"
    )]
    Rinex {
        /// Observation file.
        observation: PathBuf,
        /// Navigation file.
        navigation: PathBuf,
        /// The recording to write.
        #[arg(long, default_value = "out/import/recording.mcap")]
        out: PathBuf,
        /// Code solution: l1 (C1C + Klobuchar) or iono-free (C1C/C2W).
        #[arg(long, value_enum, default_value = "l1")]
        mode: sextant_lab::import_rinex::ImportMode,
        /// Elevation mask, degrees.
        #[arg(long, default_value_t = 10.0)]
        elevation_mask: f64,
    },
    /// KF-GINS text files (plain or `.gz`): IMU increments (GPS seconds of week, Δθ rad, Δv
    /// m/s, front-right-down axes), GNSS positions (seconds of week, lat, lon deg, height m,
    /// σ N/E/D m) and a reference trajectory (recorded as the truth).
    #[command(
        after_help = "Example:\n  sextant import kfgins --gnss tests/data/kfgins-rtk/GNSS-RTK-slice.txt --week 2100 --out out/import/rtk.mcap"
    )]
    Kfgins {
        /// IMU increment file.
        #[arg(long)]
        imu: Option<PathBuf>,
        /// GNSS position file.
        #[arg(long)]
        gnss: Option<PathBuf>,
        /// Reference trajectory (week, seconds of week, lat, lon, height, v N/E/D, roll,
        /// pitch, yaw deg).
        #[arg(long)]
        truth: Option<PathBuf>,
        /// GPS week of the first rows of the IMU and GNSS files (else the trajectory's).
        #[arg(long)]
        week: Option<i64>,
        /// Filter configuration to embed (filter.toml or a system configuration; default:
        /// the built-in one).
        #[arg(long)]
        config: Option<PathBuf>,
        /// The recording to write.
        #[arg(long, default_value = "out/import/recording.mcap")]
        out: PathBuf,
    },
    /// A smartLoc drive (TU Chemnitz; plain or `.gz`): the input file's GPS pseudoranges and
    /// odometer as GNSS and odometer samples, on the time base of a scenario whose `reference`
    /// trajectory starts at the ground-truth file's first point; the first GNSS sample carries
    /// that point as the start fix. For `replay --live REC --only gnss,odometer --follow-bus`
    /// into `sextant run --config config/hybrid_berlin.toml` (see docs/DATA.md).
    #[command(
        after_help = "Example:\n  sextant import smartloc tests/data/smartloc-berlin/Berlin_Potsdamer_Platz_Input_150-210s.txt.gz \\\n    --reference tests/data/smartloc-berlin/Berlin_Potsdamer_Platz_GT_150-210s.txt.gz --out out/import/berlin.mcap"
    )]
    Smartloc {
        /// Input file (`pseudorange3`, `odom3` lines).
        input: PathBuf,
        /// Ground-truth file (`point3` lines): its first point is t = 0 and the start fix.
        #[arg(long)]
        reference: PathBuf,
        /// Scenario whose `start_utc` is the time base (default: the shipped
        /// scenarios/berlin_reference.toml).
        #[arg(long)]
        scenario: Option<PathBuf>,
        /// UTC of t = 0 (YYYY-MM-DDTHH:MM:SS[.fff]) instead of the scenario's `start_utc`; the
        /// data carry no date. The bench's scenario must start at the same instant.
        #[arg(long)]
        start_utc: Option<String>,
        /// Filter configuration to embed (default: the built-in one).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Also write the reference as a points file for a scenario's `reference` trajectory
        /// (times from its first point; the standstill intervals in its header).
        #[arg(long)]
        trajectory_out: Option<PathBuf>,
        /// The recording to write.
        #[arg(long, default_value = "out/import/recording.mcap")]
        out: PathBuf,
    },
    /// CSV files described by a TOML file (columns, units, frames, time base; see
    /// docs/DATA.md).
    #[command(
        after_help = "Example:\n  sextant export csv out/run/recording.mcap --out out/export/csv\n  sextant import csv --describe out/export/csv/description.toml --out out/import/csv.mcap"
    )]
    Csv {
        /// The description.
        #[arg(long)]
        describe: PathBuf,
        /// Filter configuration to embed (default: the built-in one).
        #[arg(long)]
        config: Option<PathBuf>,
        /// The recording to write.
        #[arg(long, default_value = "out/import/recording.mcap")]
        out: PathBuf,
    },
}

#[derive(Debug, clap::Args)]
struct ReportArgs {
    /// The recording.
    recording: PathBuf,
    /// Output directory (default out/report).
    #[arg(long, default_value = "out/report")]
    out: PathBuf,
}

#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("mode").required(true).args(["offline", "live"])))]
struct ReplayArgs {
    /// Re-run the fusion over this recording's inputs at full speed.
    #[arg(long, value_name = "REC.mcap")]
    offline: Option<PathBuf>,
    /// Republish this recording's sensor channels with the recorded timing.
    #[arg(long, value_name = "REC.mcap")]
    live: Option<PathBuf>,
    /// Output directory of an offline replay (default out/replay).
    #[arg(long, default_value = "out/replay")]
    out: PathBuf,
    /// Filter tuning (filter.toml) or system configuration to replay with instead of the
    /// configuration embedded in the recording (offline).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Start the replay's next file (`recording.part2.mcap`, …) every this many seconds of
    /// recorded time, as the live recorder does, so that replaying days holds the memory of
    /// one segment (offline; 0: one file).
    #[arg(long, default_value_t = sextant_lab::replay::DEFAULT_SEGMENT_DURATION_S, value_parser = parse_non_negative_s)]
    segment_duration_s: f64,
    /// Rate of the solutions written to the replay's recording, Hz of time of validity (0:
    /// every solution; offline). Default: the replayed recording's `[recorder]
    /// solution_rate_hz`. The replay computes every solution either way.
    #[arg(long, value_name = "HZ", value_parser = parse_rate_hz)]
    solution_rate: Option<f64>,
    /// Speed-up of simulated over wall time (live).
    #[arg(long, default_value_t = 1.0)]
    speed: f64,
    /// Service-name prefix (live).
    #[arg(long, default_value = "sextant")]
    prefix: String,
    /// Do not republish the truth (live).
    #[arg(long)]
    no_truth: bool,
    /// Republish only these channels (live; comma-separated: imu, star_tracker, gnss,
    /// odometer, baro, truth), e.g. `--only gnss` to play real GNSS into a simulated system.
    #[arg(long, value_delimiter = ',', value_parser = parse_channel)]
    only: Vec<msgs::Channel>,
    /// Schedule on the clock of the system already running on the prefix (live): wait for its
    /// first IMU or star-tracker sample and send each sample when the drivers send theirs of
    /// the same time.
    #[arg(long)]
    follow_bus: bool,
}

/// A duration in seconds: finite and not negative.
fn parse_non_negative_s(s: &str) -> Result<f64, String> {
    parse_non_negative(s, "s: a duration is finite and not negative")
}

/// A rate in Hz: finite and not negative (0: every message).
fn parse_rate_hz(s: &str) -> Result<f64, String> {
    parse_non_negative(
        s,
        "Hz: a rate is finite and not negative (0: every message)",
    )
}

/// A finite, non-negative number; otherwise the value followed by `rule` (its unit and what
/// the option accepts).
fn parse_non_negative(s: &str, rule: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        Ok(v) => Err(format!("{v} {rule}")),
        Err(e) => Err(format!("{s:?}: {e}")),
    }
}

/// A channel name of `--only`.
fn parse_channel(s: &str) -> Result<msgs::Channel, String> {
    msgs::Channel::from_name(s).ok_or_else(|| {
        let known: Vec<&str> = msgs::Channel::ALL.iter().map(|c| c.name()).collect();
        format!("unknown channel {s:?}; known: {}", known.join(", "))
    })
}

#[derive(Debug, clap::Args)]
struct BenchArgs {
    /// Output directory (default out/bench).
    #[arg(long, default_value = "out/bench")]
    out: PathBuf,
    /// System configuration whose directory is copied (default config/sextant.toml; the
    /// embedded copy when absent).
    #[arg(long, default_value = DEFAULT_CONFIG)]
    config: PathBuf,
    /// Short runs (a few seconds each) for tests; the same figures, less precise.
    #[arg(long)]
    quick: bool,
}

#[derive(Debug, clap::Args)]
struct ExperimentArgs {
    /// Experiment name (`sextant experiment list` is not needed: an unknown name lists them), or
    /// `all`: every experiment into OUT/NAME plus OUT/RESULTS.md.
    name: String,
    /// Output directory (default out/experiment/NAME).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Configuration directory laid out like `config/` (scenarios/, sensors/), or its
    /// sextant.toml, to read the scenarios from (default: the configuration embedded in the
    /// binary).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Directory of a dataset an experiment reads instead of its shipped slice: for
    /// `hybrid-berlin`, the smartLoc files Berlin_Potsdamer_Platz_Input.txt.gz and
    /// Berlin_Potsdamer_Platz_GT.txt.gz (the whole drive).
    #[arg(long)]
    data: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
struct RunArgs {
    /// System configuration (default config/sextant.toml; if absent, the copy embedded in the
    /// binary is written to OUT/config/ and used).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Scenario file (default: `system.scenario` of the configuration).
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Simulated duration, s (default: `run.duration_s`, at most `run.max_duration_s`).
    #[arg(long)]
    duration: Option<f64>,
    /// Speed-up of simulated time over wall time (default: `run.speed`).
    #[arg(long)]
    speed: Option<f64>,
    /// Output directory (default: `run.out`): recording.mcap, summary.json, plots, logs/.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Service-name prefix (default: `system.prefix`); use distinct prefixes for parallel runs.
    #[arg(long)]
    prefix: Option<String>,
    /// Wall time between a driver's unexpected death and its restart, s (crash-loop backoff).
    /// The fusion daemon is restarted at once.
    #[arg(long, default_value_t = 0.5)]
    restart_delay: f64,
    /// Serve the live channels (solution, status, frame tree, sensor inputs) to Foxglove over
    /// its WebSocket protocol on ADDR (default 127.0.0.1:8765; `[foxglove] listen` of the
    /// configuration without this option), by the process `sextant-foxglove`.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "127.0.0.1:8765")]
    foxglove: Option<std::net::SocketAddr>,
    /// Wall time a process may go without a heartbeat before it is killed as hung and
    /// restarted, s (default: `run.heartbeat_timeout_s`; 0 disables the watch).
    #[arg(long)]
    heartbeat_timeout: Option<f64>,
    /// Calibration memory file: the fusion daemon starts from the sensor errors (biases,
    /// scale factors, boresight, odometer scale) saved in it by the previous run, and saves
    /// its own there at the end (default: `[fusion] calibration_file`; none when neither).
    #[arg(long, value_name = "FILE")]
    calibration: Option<PathBuf>,
    /// Skip the analysis of the recording at the end (its table, plots and error figures in
    /// summary.json; the counters are still written): the analysis of a day's recording
    /// takes minutes. `sextant report` analyses the recording later, in bounded memory.
    #[arg(long)]
    no_analysis: bool,
}

#[derive(Debug, clap::Args)]
struct CalibrateArgs {
    #[command(subcommand)]
    what: CalibrateWhat,
}

#[derive(Debug, Subcommand)]
enum CalibrateWhat {
    /// Star-tracker boresight from a static recording at a known site: the paper's three
    /// stages and least squares; prints a table, writes summary.json and a PNG plot.
    #[command(
        after_help = "Example:\n  sextant calibrate boresight static.mcap --site 55.655,37.534,200 --out out/calibrate"
    )]
    Boresight {
        /// The recording (MCAP) of a static run with star-tracker and IMU channels.
        recording: PathBuf,
        /// Known site: latitude, longitude (deg), height (m), e.g. `55.655,37.534,200`.
        #[arg(long, allow_hyphen_values = true)]
        site: sextant_lab::calibrate::SiteArg,
        /// Output directory.
        #[arg(long, default_value = "out/calibrate")]
        out: PathBuf,
        /// Calibration window from the start of the record, s.
        #[arg(long, default_value_t = 600.0)]
        window: f64,
    },
}

/// `println!` that never panics: a failed write to stdout (full disk, closed pipe) is ignored.
macro_rules! out {
    ($($t:tt)*) => { sextant_lab::logging::stdout_line(&format!($($t)*)) };
}

/// `eprintln!` that never panics: a failed write to stderr (the log on a full disk) is counted.
macro_rules! err {
    ($($t:tt)*) => { sextant_lab::logging::stderr_text(&(format!($($t)*) + "\n")) };
}

const DEFAULT_CONFIG: &str = "config/sextant.toml";

fn main() -> anyhow::Result<()> {
    // A failed log write (full disk) is never fatal.
    sextant_lab::logging::init();
    // iceoryx2's own log: warnings and errors only unless IOX2_LOG_LEVEL says otherwise.
    let cli = Cli::parse();
    sextant_lab::progress::set_quiet(cli.quiet);
    match cli.command {
        Command::Run(args) => {
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()?;
            let code = rt.block_on(run(args))?;
            std::process::exit(code);
        }
        Command::Experiment(args) => experiment(args),
        Command::Bench(args) => bench(args),
        Command::BenchEcho { prefix } => {
            let stop = sextant_lab::signals::install()?;
            let replies = sextant_lab::bench::floor::echo(&prefix, stop)?;
            tracing::info!("bench echo on {prefix}: {replies} replies");
            Ok(())
        }
        Command::Replay(args) => replay(args),
        Command::Calibrate(CalibrateArgs {
            what:
                CalibrateWhat::Boresight {
                    recording,
                    site,
                    out,
                    window,
                },
        }) => {
            let opts = sextant_lab::calibrate::BoresightOptions {
                recording,
                site,
                out: out.clone(),
                window_s: window,
            };
            let s = sextant_lab::calibrate::boresight(&opts)?;
            out!("{}", sextant_lab::calibrate::table(&s));
            out!("summary.json and plot in {}", out.display());
            Ok(())
        }
        Command::Import(ImportArgs {
            what:
                ImportWhat::Rinex {
                    observation,
                    navigation,
                    out,
                    mode,
                    elevation_mask,
                },
        }) => {
            if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir)?;
            }
            let opts = sextant_lab::import_rinex::ImportOptions {
                observation,
                navigation,
                out: out.clone(),
                mode,
                elevation_mask_deg: elevation_mask,
            };
            let s = sextant_lab::import_rinex::import_rinex(&opts)?;
            out!("{}", sextant_lab::import_rinex::format_table(&s, &out));
            Ok(())
        }
        Command::Completions { shell } => {
            use clap::CommandFactory;
            let mut cmd = Cli::command();
            clap_complete::generate(shell, &mut cmd, "sextant", &mut std::io::stdout());
            Ok(())
        }
        Command::Import(ImportArgs {
            what:
                ImportWhat::Kfgins {
                    imu,
                    gnss,
                    truth,
                    week,
                    config,
                    out,
                },
        }) => {
            use sextant_lab::interchange::{format_counts, kfgins};
            if imu.is_none() && gnss.is_none() {
                bail!("give --imu and/or --gnss");
            }
            let files = kfgins::ImportFiles {
                imu,
                gnss,
                truth,
                week,
            };
            let c = kfgins::import(&files, config.as_deref(), &out)?;
            out!("{}", format_counts("imported", &c));
            Ok(())
        }
        Command::Import(ImportArgs {
            what:
                ImportWhat::Smartloc {
                    input,
                    reference,
                    scenario,
                    start_utc,
                    config,
                    trajectory_out,
                    out,
                },
        }) => {
            use sextant_lab::import_smartloc;
            let opts = import_smartloc::ImportOptions {
                input,
                reference,
                out: out.clone(),
                scenario: scenario.unwrap_or_else(|| {
                    sextant_lab::shipped_config::scenario("berlin_reference.toml")
                }),
                start_utc,
                config,
                trajectory_out,
            };
            let s = import_smartloc::import(&opts)?;
            out!("{}", import_smartloc::format_table(&s, &out));
            Ok(())
        }
        Command::Import(ImportArgs {
            what:
                ImportWhat::Csv {
                    describe,
                    config,
                    out,
                },
        }) => {
            use sextant_lab::interchange::{csv_log, format_counts};
            let c = csv_log::import(&describe, config.as_deref(), &out)?;
            out!("{}", format_counts("imported", &c));
            Ok(())
        }
        Command::Export(ExportArgs { what }) => {
            use sextant_lab::interchange::{csv_log, format_counts, kfgins};
            let c = match what {
                ExportWhat::Kfgins { recording, out } => kfgins::export(&recording, &out)?,
                ExportWhat::Csv { recording, out } => csv_log::export(&recording, &out)?,
            };
            out!("{}", format_counts("exported", &c));
            Ok(())
        }
        Command::Report(args) => {
            let s = sextant_lab::report::report(&args.recording, &args.out)?;
            out!("{}", sextant_lab::report::format_table(&s));
            out!(
                "REPORT.md, summary.json and plots in {}",
                args.out.display()
            );
            Ok(())
        }
    }
}

/// Check that the process binaries `names` are in `bin_dir` (next to `sextant`). When some are
/// missing and `sextant` was started by `cargo run` (which sets `CARGO` and
/// `CARGO_MANIFEST_DIR` for the program it runs), build the workspace's binaries first with that
/// cargo, into the same target directory and profile: on a fresh checkout
/// `cargo run --release -- run` alone suffices. (`cargo run` builds only the package it runs;
/// the drivers and `sextant-fusion` are binaries of other packages.)
fn ensure_binaries(bin_dir: &Path, names: &[String]) -> anyhow::Result<()> {
    let missing = || -> Vec<String> {
        names
            .iter()
            .filter(|n| !bin_dir.join(n).is_file())
            .cloned()
            .collect()
    };
    let first = missing();
    if first.is_empty() {
        return Ok(());
    }
    if let (Some(cargo), Some(manifest_dir), Some(target_dir), Some(profile)) = (
        std::env::var_os("CARGO"),
        std::env::var_os("CARGO_MANIFEST_DIR"),
        bin_dir.parent(),
        bin_dir.file_name().and_then(|p| p.to_str()),
    ) {
        // The directory of the `dev` profile is called `debug`.
        let profile = if profile == "debug" { "dev" } else { profile };
        err!(
            "sextant: building the process binaries first ({}): cargo build --workspace --bins --profile {profile}",
            first.join(", ")
        );
        let status = std::process::Command::new(cargo)
            .args(["build", "--workspace", "--bins", "--profile", profile])
            .arg("--manifest-path")
            .arg(Path::new(&manifest_dir).join("Cargo.toml"))
            .arg("--target-dir")
            .arg(target_dir)
            .status()
            .context("running cargo build")?;
        if !status.success() {
            bail!("cargo build of the process binaries failed ({status})");
        }
    }
    let still = missing();
    if !still.is_empty() {
        bail!(
            "missing binaries in {}: {} (build them: cargo build --workspace --bins)",
            bin_dir.display(),
            still.join(", ")
        );
    }
    Ok(())
}

/// `sextant bench`: run it, print its table.
fn bench(args: BenchArgs) -> anyhow::Result<()> {
    use sextant_lab::bench;
    let bin_dir = std::env::current_exe()?
        .parent()
        .map(Path::to_path_buf)
        .context("no directory of the current executable")?;
    let names: Vec<String> = std::iter::once("sextant-fusion")
        .chain(
            drivers_sim::driver::SimDriver::ALL.map(drivers_sim::driver::SimDriver::process_name),
        )
        .map(String::from)
        .collect();
    ensure_binaries(&bin_dir, &names)?;
    let cleaned = msgs::ipc::cleanup_dead_nodes()?;
    if cleaned > 0 {
        tracing::info!("removed the shared memory of {cleaned} dead node(s) of an earlier run");
    }
    let opts = bench::BenchOptions {
        out: args.out.clone(),
        config: args.config,
        bin_dir,
        prefix: format!("sextant_bench_{}", std::process::id()),
        quick: args.quick,
    };
    let summary = bench::run(&opts)?;
    out!("{}", bench::table(&summary));
    out!("summary and histogram in {}", args.out.display());
    Ok(())
}

/// `sextant experiment NAME`: run it, print its table, point at its files.
fn experiment(args: ExperimentArgs) -> anyhow::Result<()> {
    use sextant_lab::experiments;
    if args.name != "all" && !experiments::names().contains(&args.name.as_str()) {
        bail!(
            "unknown experiment `{}`; known: {}",
            args.name,
            experiments::names().join(", ")
        );
    }
    if let Some(c) = args.config {
        let dir = if c.is_file() {
            c.parent().map(Path::to_path_buf).unwrap_or_default()
        } else {
            c
        };
        if !dir.join("scenarios").is_dir() {
            bail!("--config {}: no scenarios/ directory there", dir.display());
        }
        experiments_config::use_dir(dir);
    }
    if let Some(d) = args.data {
        if !d.is_dir() {
            bail!("--data {}: not a directory", d.display());
        }
        experiments::hybrid_berlin::use_data_dir(d);
    }
    let out = args
        .out
        .unwrap_or_else(|| PathBuf::from("out/experiment").join(&args.name));
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let summary = experiments::run_by_name(&args.name, &out, true)?;
    out!("{}", summary.table());
    out!("summary and plots in {}", out.display());
    Ok(())
}

fn load_config(args: &RunArgs, out: &Path) -> anyhow::Result<config::LoadedConfig> {
    let path = match &args.config {
        Some(p) => p.clone(),
        None if Path::new(DEFAULT_CONFIG).exists() => PathBuf::from(DEFAULT_CONFIG),
        None => {
            let dir = out.join("config");
            let p = config::materialize_embedded(&dir)?;
            tracing::info!(
                "{DEFAULT_CONFIG} not found: using the embedded configuration, written to {}",
                dir.display()
            );
            p
        }
    };
    Ok(config::load(&path)?)
}

/// Files of an earlier run in `dir` (its recording or summary), when there is one.
fn earlier_run(dir: &Path) -> Option<PathBuf> {
    let rd = std::fs::read_dir(dir).ok()?;
    rd.flatten().map(|e| e.path()).find(|p| {
        let name = p
            .file_name()
            .map(|n| n.to_string_lossy())
            .unwrap_or_default();
        name == "summary.json" || (name.starts_with("recording") && name.ends_with(".mcap"))
    })
}

/// Name of the lock file that a run holds in its output directory.
const OUT_LOCK: &str = ".sextant-run.lock";

/// Take the output directory of a run: create it and hold its lock file for the whole run. An
/// earlier run's files are never removed: when `out` holds one (or another run holds its
/// lock), a `--out` given explicitly is refused, and the default is replaced by the first free
/// `OUT-2`, `OUT-3`, … (printed).
fn claim_out_dir(out: &Path, explicit: bool) -> anyhow::Result<(PathBuf, Option<std::fs::File>)> {
    for k in 1..=1000 {
        let dir = if k == 1 {
            out.to_path_buf()
        } else {
            let name = out
                .file_name()
                .map(|n| n.to_string_lossy())
                .unwrap_or_default();
            out.with_file_name(format!("{name}-{k}"))
        };
        let busy = match earlier_run(&dir) {
            Some(f) => Some(format!("it holds an earlier run ({})", f.display())),
            None => {
                std::fs::create_dir_all(&dir)
                    .with_context(|| format!("create {}", dir.display()))?;
                match std::fs::File::options()
                    .create(true)
                    .truncate(false)
                    .write(true)
                    .open(dir.join(OUT_LOCK))
                {
                    Ok(f) => match f.try_lock() {
                        Ok(()) => {
                            if k > 1 {
                                tracing::warn!(
                                    "{} holds an earlier run, which is kept: this run writes to {}",
                                    out.display(),
                                    dir.display()
                                );
                            }
                            return Ok((dir, Some(f)));
                        }
                        Err(_) => Some("another sextant run is writing into it".to_string()),
                    },
                    // Cannot even create an empty file (e.g. read-only): run without the lock;
                    // the fusion reports the unwritable recording and keeps navigating.
                    Err(e) => {
                        tracing::warn!("cannot create {}: {e}", dir.join(OUT_LOCK).display());
                        return Ok((dir, None));
                    }
                }
            }
        };
        if explicit {
            bail!(
                "--out {}: {}; it is kept — give another --out or remove it first",
                dir.display(),
                busy.unwrap_or_default()
            );
        }
    }
    bail!("no free output directory next to {}", out.display())
}

/// Hold the lock of a service prefix for the whole run (a file in the temporary directory), so
/// that two runs started at the same moment cannot both find the prefix free.
fn lock_prefix(prefix: &str) -> anyhow::Result<Option<std::fs::File>> {
    let name: String = prefix
        .chars()
        .map(|c| if c == '/' { '%' } else { c })
        .collect();
    let path = std::env::temp_dir().join(format!("sextant-prefix-{name}.lock"));
    let f = match std::fs::File::options()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)
    {
        Ok(f) => f,
        Err(e) => {
            tracing::warn!("cannot create {}: {e}", path.display());
            return Ok(None);
        }
    };
    if f.try_lock().is_err() {
        bail!(
            "service prefix {prefix:?} is in use by another sextant run (it holds {}); give another --prefix",
            path.display()
        );
    }
    Ok(Some(f))
}

/// Write `text` to `path` atomically: a temporary file renamed over it, so that a full disk
/// leaves no empty or half-written file (the temporary file is removed on failure).
fn write_atomically(path: &Path, text: &str) -> std::io::Result<()> {
    let tmp = path.with_extension("json.tmp");
    let r = std::fs::write(&tmp, text).and_then(|()| std::fs::rename(&tmp, path));
    if r.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    r
}

/// Exit status of `sextant run` when the run itself went well but its recording is incomplete
/// (records dropped, write errors, or no final counters from the fusion daemon).
const EXIT_RECORDING_INCOMPLETE: i32 = 3;

async fn run(args: RunArgs) -> anyhow::Result<i32> {
    let wall_start = Instant::now();
    // A file-size limit (ulimit -f) makes the summary's write fail with EFBIG, handled below,
    // instead of killing the command by SIGXFSZ.
    // SAFETY: SIG_IGN installs no code.
    unsafe {
        nix::sys::signal::signal(
            nix::sys::signal::Signal::SIGXFSZ,
            nix::sys::signal::SigHandler::SigIgn,
        )
    }?;
    // The output directory is needed before the config only for the embedded fallback, whose
    // default is the built-in `out/run`.
    let pre_out = args.out.clone().unwrap_or_else(|| PathBuf::from("out/run"));
    let cfg = load_config(&args, &pre_out)?;
    let rc = &cfg.system.run;
    let duration = args.duration.unwrap_or(rc.duration_s);
    if !(duration.is_finite() && duration > 0.0 && duration <= rc.max_duration_s) {
        bail!(
            "--duration must be within (0, {}] s (run.max_duration_s of {}), got {duration}",
            rc.max_duration_s,
            cfg.path.display()
        );
    }
    let speed = args.speed.unwrap_or(rc.speed);
    if !(speed.is_finite() && speed > 0.0 && speed <= 1000.0) {
        bail!("--speed must be within (0, 1000], got {speed}");
    }
    let scenario_path = args.scenario.clone().unwrap_or_else(|| cfg.scenario_path());
    // Validate the whole scenario (every key, grade and range) before starting anything: a
    // malformed file is one clear error naming it and the key, not drivers dying at start-up.
    let world = drivers_sim::scenario::Scenario::load(&scenario_path)?
        .spec
        .world;
    // The receiver's fixes are judged at the world's antenna (its true lever arm), whatever the
    // filter is told.
    let antenna_lever_arm_b_m: [f64; 3] = world
        .as_ref()
        .map_or([0.0; 3], |w| w.lever_arm_b_m().into());
    let scen = scenario::ScenarioInfo::load(&scenario_path)?;
    let prefix = args
        .prefix
        .clone()
        .unwrap_or_else(|| cfg.system.system.prefix.clone());
    // A prefix that cannot name the services would make every process fail at start-up.
    sextant_lab::bus_check::validate_prefix(&prefix).context("--prefix")?;
    if !(args.restart_delay.is_finite() && (0.0..=600.0).contains(&args.restart_delay)) {
        bail!(
            "--restart-delay must be within [0, 600] s, got {}",
            args.restart_delay
        );
    }
    let restart_delay = Duration::from_secs_f64(args.restart_delay);
    let heartbeat_s = args
        .heartbeat_timeout
        .unwrap_or(cfg.system.run.heartbeat_timeout_s);
    if !(heartbeat_s.is_finite() && (0.0..=3600.0).contains(&heartbeat_s)) {
        bail!("--heartbeat-timeout must be within [0, 3600] s, got {heartbeat_s}");
    }
    // Below 0.2 s a ping cadence of half of it would compete with the processes' own loops.
    let heartbeat_timeout =
        (heartbeat_s > 0.0).then(|| Duration::from_secs_f64(heartbeat_s.max(0.2)));

    // One bus per prefix: remove what crashed processes left, then refuse when live processes
    // still use the prefix (they would fuse each other's samples).
    let cleaned = msgs::ipc::cleanup_dead_nodes()?;
    if cleaned > 0 {
        tracing::info!("removed the shared memory of {cleaned} dead node(s) of an earlier run");
    }
    let _prefix_lock = lock_prefix(&prefix)?;
    let users = sextant_lab::bus_check::live_nodes_on(&prefix)?;
    if !users.is_empty() {
        let names: Vec<String> = users.iter().map(ToString::to_string).collect();
        bail!(
            "service prefix {prefix:?} is in use by live processes: {}; give another --prefix or stop them",
            names.join(", ")
        );
    }

    let foxglove = args
        .foxglove
        .or(cfg.system.foxglove.as_ref().map(|f| f.listen));
    // Refuse a busy or foreign address now, with a clear message and before anything is
    // created, rather than watch the live server die at start-up (restarted, then given up on).
    if let Some(addr) = foxglove {
        std::net::TcpListener::bind(addr)
            .with_context(|| format!("--foxglove {addr}: cannot listen there"))?;
    }

    let (out, _out_lock) = claim_out_dir(
        &args.out.clone().unwrap_or_else(|| rc.out.clone()),
        args.out.is_some(),
    )?;
    std::fs::create_dir_all(out.join("logs"))
        .with_context(|| format!("create {}", out.join("logs").display()))?;
    let recording = out.join("recording.mcap");

    let bin_dir = std::env::current_exe()?
        .parent()
        .map(Path::to_path_buf)
        .context("no directory of the current executable")?;
    let mut names: Vec<String> = rc.drivers.clone();
    names.push("sextant-fusion".into());
    if foxglove.is_some() {
        names.push("sextant-foxglove".into());
    }
    let bridge_args = cfg.system.bridge.as_ref().map(|b| b.args(&prefix));
    if bridge_args.is_some() {
        names.push("sextant-bridge".into());
    }
    ensure_binaries(&bin_dir, &names)?;
    // The bridge checks its own endpoints and key prefixes: ask it now, so that a bad value
    // refuses the run with the bridge's message rather than a bridge that dies at start-up.
    if let Some(a) = &bridge_args {
        let check = std::process::Command::new(bin_dir.join("sextant-bridge"))
            .args(a)
            .arg("--check")
            .output()
            .context("running sextant-bridge --check")?;
        if !check.status.success() {
            bail!(
                "[bridge] of {}: {}",
                cfg.path.display(),
                String::from_utf8_lossy(&check.stderr).trim()
            );
        }
    }

    let interrupt = supervisor::stop_signals()?;
    let start_mono_ns = msgs::monotonic_ns() + (rc.start_delay_s * 1e9) as u64;
    let drivers: Vec<ChildSpec> = rc
        .drivers
        .iter()
        .map(|n| ChildSpec {
            name: n.clone(),
            program: bin_dir.join(n),
            args: supervisor::driver_args(&scenario_path, &prefix, start_mono_ns, speed, duration),
            log: out.join("logs").join(format!("{n}.log")),
        })
        .collect();
    let mut fusion_args = supervisor::fusion_args(&cfg.path, &prefix, &recording, speed);
    if let Some(c) = &args.calibration {
        fusion_args.extend(["--calibration".to_string(), c.display().to_string()]);
    }
    let fusion = ChildSpec {
        name: "sextant-fusion".into(),
        program: bin_dir.join("sextant-fusion"),
        args: fusion_args,
        log: out.join("logs").join("sextant-fusion.log"),
    };
    let fusion_log = fusion.log.clone();
    let services: Vec<ChildSpec> = foxglove
        .map(|addr| ChildSpec {
            name: "sextant-foxglove".into(),
            program: bin_dir.join("sextant-foxglove"),
            args: vec![
                "--prefix".into(),
                prefix.clone(),
                "--listen".into(),
                addr.to_string(),
                "--config".into(),
                cfg.path.display().to_string(),
            ],
            log: out.join("logs").join("sextant-foxglove.log"),
        })
        .into_iter()
        .chain(bridge_args.map(|args| ChildSpec {
            name: "sextant-bridge".into(),
            program: bin_dir.join("sextant-bridge"),
            args,
            log: out.join("logs").join("sextant-bridge.log"),
        }))
        .collect();
    // The drivers end by themselves; a watchdog stops a run that overruns by far.
    let expected = Duration::from_secs_f64(rc.start_delay_s + duration / speed);
    let plan = supervisor::RunPlan {
        drivers,
        fusion,
        services,
        out: out.clone(),
        max_restarts: rc.max_restarts,
        restart_delay,
        stop_timeout: Duration::from_secs_f64(rc.stop_timeout_s),
        watchdog: expected + Duration::from_secs(30) + expected / 2,
        heartbeat_timeout,
        status_prefix: Some(prefix.clone()),
    };

    err!(
        "sextant run: scenario {} ({}), {duration} s at {speed}x, prefix {prefix}, output {}",
        scenario_path.display(),
        scen.name,
        out.display()
    );
    if let Some(addr) = foxglove {
        err!(
            "sextant run: live view for Foxglove on ws://{addr} (Open connection → Foxglove WebSocket)"
        );
    }
    let outcome = supervisor::supervise(&plan, interrupt).await?;
    let end = outcome.end;
    let fusion_ok = outcome.fusion_ok();
    if !fusion_ok {
        tracing::error!(
            "sextant-fusion did not exit cleanly ({:?}); see {}",
            outcome.fusion_exit,
            fusion_log.display()
        );
    }

    let wall_s = wall_start.elapsed().as_secs_f64();
    // The counters are the fusion daemons' own (their exit reports), summed over restarts;
    // the recording's last status predates a full disk or a crash. A daemon killed and
    // restarted leaves no report (its recording is readable up to its last chunk, by design);
    // the last one must report.
    let reports = &outcome.fusion_reports;
    let report_of = |rec: &Path| reports.iter().find(|r| r.recording == rec);
    let last_reported = outcome
        .recordings
        .last()
        .is_some_and(|r| report_of(r).is_some());
    let sum = |f: fn(&sextant_lab::exit_report::ExitReport) -> u64| -> u64 {
        reports.iter().map(f).sum()
    };
    let records_dropped = sum(|r| r.records_dropped);
    let recorder_errors = sum(|r| r.recorder_errors);
    let complete = last_reported && reports.iter().all(|r| r.recording_complete());
    // Every file written: each fusion daemon's segments (several after a failed write).
    let files: Vec<PathBuf> = outcome
        .recordings
        .iter()
        .flat_map(|first| match report_of(first) {
            Some(r) => r.segments.clone(),
            None => vec![first.clone()],
        })
        .filter(|p| p.exists())
        .collect();
    // The table is of the last fusion's recording (the whole run when it never crashed).
    let recording = outcome.recordings.last().cloned().unwrap_or(recording);
    let analysis = if args.no_analysis {
        out!(
            "  analysis skipped (--no-analysis): sextant report {}",
            recording.display()
        );
        None
    } else if recording.exists() {
        match analysis::analyze_with_progress(
            &recording,
            &scen.gnss_outages,
            Some(antenna_lever_arm_b_m),
            true,
        ) {
            Ok(a) => Some(a),
            Err(e) => {
                tracing::error!("analysis of {}: {e}", recording.display());
                None
            }
        }
    } else {
        tracing::error!("no recording was written ({})", recording.display());
        None
    };
    let mut json = match &analysis {
        Some(a) => {
            let mut summary = a.summary.clone();
            if last_reported {
                summary.records_dropped = records_dropped;
            }
            out!("{}", analysis::format_table(&summary));
            serde_json::to_value(&summary)?
        }
        None => serde_json::json!({}),
    };
    if let Some(m) = json.as_object_mut() {
        m.insert("run_wall_time_s".into(), wall_s.into());
        m.insert(
            "scenario".into(),
            scenario_path.display().to_string().into(),
        );
        m.insert("requested_duration_s".into(), duration.into());
        m.insert("speed".into(), speed.into());
        m.insert("service_prefix".into(), prefix.clone().into());
        m.insert("end".into(), format!("{end:?}").into());
        m.insert("fusion_restarts".into(), outcome.fusion_restarts.into());
        m.insert(
            "recordings".into(),
            outcome
                .recordings
                .iter()
                .map(|p| serde_json::Value::from(p.display().to_string()))
                .collect(),
        );
        m.insert(
            "recording_files".into(),
            files
                .iter()
                .map(|p| serde_json::Value::from(p.display().to_string()))
                .collect(),
        );
        m.insert(
            "analysed_recording".into(),
            recording.display().to_string().into(),
        );
        m.insert(
            "driver_restarts".into(),
            serde_json::Value::Object(
                outcome
                    .driver_restarts
                    .iter()
                    .map(|(name, n)| (name.clone(), (*n).into()))
                    .collect(),
            ),
        );
        if !outcome.service_restarts.is_empty() {
            m.insert(
                "service_restarts".into(),
                serde_json::Value::Object(
                    outcome
                        .service_restarts
                        .iter()
                        .map(|(name, n)| (name.clone(), (*n).into()))
                        .collect(),
                ),
            );
        }
        m.insert(
            "hung_processes_killed".into(),
            serde_json::Value::Object(
                outcome
                    .hung_kills
                    .iter()
                    .map(|(name, n)| (name.clone(), (*n).into()))
                    .collect(),
            ),
        );
        m.insert("recording_complete".into(), complete.into());
        if files.len() > 1 && !args.no_analysis {
            // Several daemon lives (or segments): the losses of the whole run, including what
            // the drivers sent while no daemon listened (`run_losses`).
            let losses = sextant_lab::run_losses::of_run(&files);
            m.insert("run_losses".into(), serde_json::to_value(&losses)?);
        }
        m.insert(
            "counters_source".into(),
            format!(
                "exit reports of {} of {} fusion daemons",
                reports.len(),
                outcome.recordings.len()
            )
            .into(),
        );
        if last_reported {
            m.insert("records_dropped".into(), records_dropped.into());
            m.insert("records_written".into(), sum(|r| r.records_written).into());
            m.insert("recorder_errors".into(), recorder_errors.into());
            m.insert("solutions_computed".into(), sum(|r| r.solutions).into());
            m.insert("log_lines_lost".into(), sum(|r| r.log_lines_lost).into());
            m.insert("solutions_stale".into(), sum(|r| r.solutions_stale).into());
        }
    }
    let summary_path = out.join("summary.json");
    let text = serde_json::to_string_pretty(&json)? + "\n";
    let summary_written = match write_atomically(&summary_path, &text) {
        Ok(()) => true,
        Err(e) => {
            tracing::error!(
                "cannot write {}: {e}; the summary follows on stdout",
                summary_path.display()
            );
            out!("{text}");
            false
        }
    };
    if let Some(a) = &analysis {
        match plots::write_plots(&out, &a.series) {
            Ok(files) => {
                for f in files {
                    out!("  plot: {}", f.display());
                }
            }
            Err(e) => tracing::warn!("{e}"),
        }
    }
    if summary_written {
        out!("  summary: {}", summary_path.display());
    }
    out!("  run time: {wall_s:.1} s wall");
    if !complete {
        tracing::error!(
            "the recording is incomplete: {}; files: {}",
            if last_reported {
                format!("{records_dropped} records dropped, {recorder_errors} write errors")
            } else {
                "the fusion daemon ended without reporting its counters".to_string()
            },
            files
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    Ok(match end {
        End::Completed | End::Interrupted(_) if fusion_ok => {
            // Skipping the analysis on request leaves a complete recording; an analysis that
            // failed or found no recording does not.
            if complete && summary_written && (analysis.is_some() || args.no_analysis) {
                0
            } else {
                EXIT_RECORDING_INCOMPLETE
            }
        }
        _ => 1,
    })
}

/// `sextant replay`: offline (table, summary.json, the replay's recording) or live.
fn replay(args: ReplayArgs) -> anyhow::Result<()> {
    use sextant_lab::replay as rp;
    if let Some(rec) = args.offline {
        let replayed = args.out.join("recording.mcap");
        // The fixes are compared at the antenna of the configuration the replay runs with.
        let source = sextant_lab::recording::Recording::open(&rec)?;
        let antenna_lever_arm_b_m = match &args.config {
            Some(p) => rp::load_filter_config(p)?,
            None => rp::embedded_filter_config(&source)?,
        }
        .gnss
        .lever_arm_b_m;
        // The replay records at the source's rates, unless told another solution rate.
        let mut thinned = analysis::thinned_topics(source.metadata());
        if args.solution_rate == Some(0.0) {
            thinned.retain(|t| *t != msgs::Channel::Nav.name());
        } else if args.solution_rate.is_some() && !thinned.contains(&msgs::Channel::Nav.name()) {
            thinned.push(msgs::Channel::Nav.name());
        }
        drop(source);
        // The replay's recording is analysed while it is written, on a thread of its own: the
        // recorder hands it every message it writes (the queue ends with the recorder).
        let (tap, written) = std::sync::mpsc::sync_channel(8);
        let (s, tapped) = std::thread::scope(|scope| {
            let analysis = scope.spawn(|| {
                analysis::analyze_written(&replayed, written, &[], antenna_lever_arm_b_m, &thinned)
            });
            let s = rp::replay_offline(&rp::OfflineOptions {
                recording: rec,
                out_dir: args.out.clone(),
                config: args.config,
                progress: true,
                segment_duration: (args.segment_duration_s > 0.0)
                    .then(|| std::time::Duration::from_secs_f64(args.segment_duration_s)),
                tap: Some(tap),
                solution_rate_hz: args.solution_rate,
            });
            (s, analysis.join())
        });
        let s = s?;
        out!("{}", rp::format_offline_table(&s));
        let replayed = std::path::Path::new(&s.replayed_recording);
        // What the file lacks (a record the recorder dropped or lost to a write error) the tap
        // may still have seen: then the file is read back, what the figures are about.
        let analysis = match tapped {
            Ok(a) if s.replay_records_dropped == 0 && s.replay_recorder_errors == 0 => Some(a),
            _ => analysis::analyze_with_progress(replayed, &[], Some(antenna_lever_arm_b_m), true)
                .ok(),
        };
        if let Some(a) = &analysis {
            out!("{}", analysis::format_table(&a.summary));
            let _ = plots::write_plots(&args.out, &a.series);
        }
        let summary = serde_json::json!({
            "replay": s,
            "analysis": analysis.map(|a| a.summary),
        });
        let path = args.out.join("summary.json");
        std::fs::write(&path, serde_json::to_string_pretty(&summary)?)
            .with_context(|| format!("writing {}", path.display()))?;
        out!("summary in {}", path.display());
        // An imported log has inputs only: nothing to compare, the replay is its first run.
        if s.config_source == "embedded" && s.solutions_recorded > 0 && !s.bit_exact {
            bail!("the replay did not reproduce the recorded solution bit for bit");
        }
        return Ok(());
    }
    let Some(rec) = args.live else {
        bail!("give --offline REC.mcap or --live REC.mcap");
    };
    let stop = sextant_lab::signals::install()?;
    let s = rp::replay_live(
        &rp::LiveOptions {
            recording: rec,
            prefix: args.prefix,
            speed: args.speed,
            start_delay_s: 1.0,
            with_truth: !args.no_truth,
            only: args.only,
            clock: if args.follow_bus {
                rp::LiveClock::FollowBus { timeout_s: 60.0 }
            } else {
                rp::LiveClock::Recording
            },
            progress: true,
        },
        stop,
    )?;
    out!("{}", serde_json::to_string_pretty(&s)?);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    /// The clap definitions are consistent, and every command and subcommand's `--help` ends
    /// with an example (the command line a user copies first).
    #[test]
    fn every_help_has_an_example() {
        Cli::command().debug_assert();
        fn walk(cmd: &mut clap::Command, path: &str, missing: &mut Vec<String>) {
            let name = format!("{path} {}", cmd.get_name()).trim().to_string();
            let help = cmd.render_long_help().to_string();
            if !help.contains("Example") {
                missing.push(name.clone());
            }
            for sub in cmd.get_subcommands_mut() {
                if sub.get_name() != "help" {
                    walk(sub, &name, missing);
                }
            }
        }
        let mut missing = Vec::new();
        walk(&mut Cli::command(), "", &mut missing);
        assert!(missing.is_empty(), "--help without an example: {missing:?}");
    }

    #[test]
    fn completions_name_every_subcommand() {
        let mut out = Vec::new();
        clap_complete::generate(
            clap_complete::Shell::Bash,
            &mut Cli::command(),
            "sextant",
            &mut out,
        );
        let script = String::from_utf8(out).unwrap();
        for sub in Cli::command().get_subcommands() {
            assert!(script.contains(sub.get_name()), "{}", sub.get_name());
        }
    }
}
