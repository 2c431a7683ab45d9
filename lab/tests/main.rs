//! The lab's integration tests (they run the `sextant` binary): one module per file of this
//! directory, all linked into one test binary (one link instead of one per file).
//! `cargo test --release -p sextant-lab --test integration calibrate::` runs one file's tests.
//! A new file here needs its `mod` line below (a test of `sextant-tests` checks that every file
//! is declared).

mod calibrate;
mod cli;
mod import_rinex;
