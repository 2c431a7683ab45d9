//! Sextant simulator: scenarios, truth trajectories, sensor error models, and the shared loop of
//! the driver processes (`sextant-sim-imu`, `-star-tracker`, `-gnss`, `-odometer`, `-baro`,
//! `-truth`).
//!
//! Every driver derives the same truth from the scenario file alone ([`truth`]): no process
//! talks to another, yet all agree bit for bit. Each sensor draws from its own random stream
//! ([`sensor_rng`]), so each process is reproducible on its own. The truth-only effects the
//! filter does not model (atmosphere, multipath, broadcast errors, oscillator, lever arm,
//! latency) are the [`world`]'s, switched and sized by a scenario's `[world]` section.

pub mod driver;
pub mod gnss;
pub mod imu;
pub mod matched;
pub mod offline;
pub mod reference_trajectory;
pub mod scenario;
pub mod sensors;
pub mod sources;
pub mod stand;
pub mod truth;
pub mod world;

#[cfg(test)]
mod tests;

use rand::SeedableRng;
use rand_chacha::ChaCha20Rng;
use std::path::PathBuf;

/// Errors of the simulator library.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A file could not be read.
    #[error("{}: cannot read: {reason}", file.display())]
    Io {
        /// The file.
        file: PathBuf,
        /// Why.
        reason: String,
    },
    /// A file is not valid TOML or does not match the expected structure (the message names
    /// the key and its line).
    #[error("{}: {message}", file.display())]
    Parse {
        /// The file.
        file: PathBuf,
        /// Parser message.
        message: String,
    },
    /// A value is out of range or inconsistent.
    #[error("{}: key `{key}`: {reason}", file.display())]
    Invalid {
        /// The file (or `command line`).
        file: PathBuf,
        /// Dotted key, e.g. `trajectory.segments[3].to_m_s`.
        key: String,
        /// What is wrong.
        reason: String,
    },
    /// A scenario's `[world] include` names a world file that cannot be used.
    #[error("{}: [world] include = {include:?} ({}): {reason}", file.display(), resolved.display())]
    Include {
        /// The scenario file.
        file: PathBuf,
        /// The include path as written in the scenario.
        include: String,
        /// Where it was looked for (relative paths start at the scenario file's directory).
        resolved: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The driver could not join the bus.
    #[error(transparent)]
    Bus(#[from] msgs::ipc::NodeError),
    /// The driver's publisher could not be created.
    #[error(transparent)]
    Publisher(#[from] msgs::ipc::PublisherError),
    /// A sample could not be sent.
    #[error(transparent)]
    Send(#[from] msgs::ipc::SendError),
    /// Installing the signal handlers failed.
    #[error("cannot install signal handler: {0}")]
    Signal(String),
}

/// 64-bit FNV-1a hash of a sensor name (stable across platforms and releases).
pub fn fnv1a64(name: &str) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in name.as_bytes() {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// The random stream of sensor `name` for scenario seed `seed`: ChaCha20 keyed by the seed,
/// on the stream number given by the FNV-1a hash of the name.
pub fn sensor_rng(seed: u64, name: &str) -> ChaCha20Rng {
    let mut rng = ChaCha20Rng::seed_from_u64(seed);
    rng.set_stream(fnv1a64(name));
    rng
}
