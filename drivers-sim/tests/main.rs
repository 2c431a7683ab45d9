//! The simulator's integration tests: one module per file of this directory, all linked into
//! one test binary (one link against the heavy dependencies instead of one per file).
//! `cargo test --release -p sextant-drivers-sim --test integration gnss_ls::` runs one file's
//! tests. A new file here needs its `mod` line below (a test of `sextant-tests` checks that
//! every file is declared).

mod astro_stand;
mod fdi_quantisation;
mod filter_baseline;
mod filter_boresight;
mod filter_modes;
mod filter_tight;
mod filter_vehicle;
mod fixture;
mod gap_reinit;
mod gnss_ls;
mod live;
mod motion_alignment;
mod odometer_noise;
mod redundant_channels;
mod world_accuracy;
mod world_consistency;
mod zupt_vibration;
