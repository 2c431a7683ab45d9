//! Sextant's receiver driver: u-blox UBX (NAV-PVT, NAV-SAT, RXM-RAWX) and NMEA 0183 (GGA, RMC,
//! GSA, GST) from a serial port, a TCP stream or a file, published on the bus as the same
//! [`msgs::GnssSample`] the simulated GNSS driver sends, so the fusion daemon cannot tell them
//! apart.
//!
//! | module | does |
//! |---|---|
//! | [`framing`] | bytes → UBX frames and NMEA sentences, checksums, skipped bytes counted |
//! | [`ubx`] | NAV-PVT, NAV-SAT, RXM-RAWX payloads ↔ SI values |
//! | [`nmea`] | GGA, RMC, GSA, GST fields → SI values |
//! | [`sample`] | one epoch → `GnssSample`: GPS time, ECEF fix, covariance from the receiver's accuracy |
//! | [`receiver`] | grouping messages into epochs, publication order, counters |
//! | [`input`] | serial (termios raw mode), TCP, file |
//!
//! # Why hand-written rather than the `ublox`, `nmea` and `serialport` crates
//! The driver must count every skipped byte and every failed frame of a stream where UBX and
//! NMEA are interleaved with noise. The `ublox` crate's parser resynchronises silently on
//! anything that is not UBX (NMEA included) and brings a proc-macro layer for hundreds of
//! messages, of which three are used here; the `nmea` crate parses one sentence at a time and
//! needs the same framing in front of it. The framer is 200 lines, the three UBX layouts and
//! four NMEA sentences are fixed-offset and comma-separated fields, and writing them keeps the
//! counting exact and property-tested in one place. `serialport` pulls libudev (a system
//! library) for port enumeration, which a driver given a device path does not need: termios
//! through `nix`, already a dependency of the workspace, sets a tty to raw mode.

pub mod framing;
pub mod input;
pub mod nmea;
pub mod receiver;
pub mod sample;
pub mod ubx;
