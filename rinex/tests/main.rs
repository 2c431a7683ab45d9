//! The RINEX reader's integration tests: one module per file of this directory, all linked into
//! one test binary (one link instead of one per file). `cargo test --release -p sextant-rinex
//! --test integration esbc::` runs one file's tests. A new file here needs its `mod` line below
//! (a test of `sextant-tests` checks that every file is declared).

mod esbc;
mod mutated_input;
