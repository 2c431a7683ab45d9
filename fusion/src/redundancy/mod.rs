//! Redundant (skewed) inertial channels: least-squares combination and parity-space fault
//! detection, isolation and exclusion (paper 004, "structural redundancy", eqs. (1)–(7)).
//!
//! - [`least_squares`]: the channel geometry (paper eqs. (3)–(7)): sensitive axes,
//!   measurement matrix `H` and the least-squares combination `(HᵀH)⁻¹Hᵀ`;
//! - [`parity`]: the parity-space test, isolation and exclusion ([`RedundantImu`]);
//! - [`config`]: the FDI settings and the `[redundancy]` section of the filter tuning.
//!
//! Everything is fixed size (`MAX_IMU_CHANNELS` = 8 rows, unused rows zero): no allocation per
//! step. Every item of the submodules is re-exported here.

pub mod config;
pub mod least_squares;
pub mod parity;

#[cfg(test)]
mod tests;

pub use config::{FdiConfig, RedundancyConfig};
pub use least_squares::{
    ls_covariance_per_unit_variance, measurement_matrix, orthogonal_axes, pyramid_axes,
};
pub use parity::{RedundancyStatus, RedundantImu};

use msgs::MAX_IMU_CHANNELS;
use nalgebra::{SMatrix, SVector};

/// Number of channel slots (`msgs::MAX_IMU_CHANNELS`).
pub const MAX_CHANNELS: usize = MAX_IMU_CHANNELS;

/// `MAX_CHANNELS × 3` measurement matrix (rows of unused or excluded channels are zero).
pub type HMatrix = SMatrix<f64, MAX_CHANNELS, 3>;
/// `3 × MAX_CHANNELS` least-squares combination `(HᵀH)⁻¹Hᵀ`.
pub type LsMatrix = SMatrix<f64, 3, MAX_CHANNELS>;
/// `MAX_CHANNELS × MAX_CHANNELS` parity projector.
pub type ParityProjector = SMatrix<f64, MAX_CHANNELS, MAX_CHANNELS>;
/// One value per channel slot.
pub type ChannelVector = SVector<f64, MAX_CHANNELS>;
