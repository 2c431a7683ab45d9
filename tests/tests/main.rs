//! Sextant's end-to-end tests: one module per file of this directory, all linked into one test
//! binary (one link against the whole workspace instead of one per file).
//! `cargo test --release -p sextant-tests --test integration pipeline::` runs one file's tests
//! (build the workspace's binaries first: `cargo build --release --workspace --bins`). A new
//! file here needs its `mod` line below (`every_integration_test_file_is_declared` checks it).
//!
//! The files' tests run on the harness's threads in this one process: every test that starts
//! processes, or times or counts what they do, takes a slot of [`sextant_tests::MACHINE`] for
//! its whole run: at most two such runs share the machine, and a test that checks `/dev/shm`
//! for leftovers or measures latency, memory or a deadline takes the machine alone.

mod bad_input;
mod bench;
mod bridge;
mod calibration_memory;
mod disk;
mod faults;
mod foxglove_live;
mod gnss_ublox;
mod hybrid;
mod hybrid_berlin;
mod hybrid_berlin_live;
mod interchange;
mod long_run;
mod mcap_conventions;
mod operation;
mod pipeline;
mod realtime;
mod replay;
mod report;
mod report_memory;
mod restart;
mod service;
mod stalls;
