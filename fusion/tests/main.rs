//! The fusion crate's integration tests: one module per file of this directory, all linked into
//! one test binary (one link instead of one per file). `cargo test --release -p sextant-fusion
//! --test integration no_alloc_filter::` runs one file's tests. A new file here needs its `mod`
//! line below (a test of `sextant-tests` checks that every file is declared).
//!
//! `common` installs the counting global allocator of the no-allocation tests for the whole
//! binary; it counts per thread, so tests running in parallel do not see each other's
//! allocations.

mod common;

mod celestial_erfa;
mod no_alloc_filter;
mod no_alloc_gnss;
mod no_alloc_redundancy;
mod no_alloc_strapdown;
