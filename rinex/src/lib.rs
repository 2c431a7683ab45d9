//! RINEX 3 reader: observation files (every system's records are read past, GPS kept) and
//! navigation files (GPS LNAV ephemerides and the Klobuchar coefficients of the header),
//! turned into the types of [`fusion::broadcast_ephemeris`] and [`fusion::point_positioning`].
//!
//! Format: "RINEX, The Receiver Independent Exchange Format, Version 3.05" (IGS/RTCM-SC104,
//! 2020), fixed-column records; versions 3.00–3.05 share the layout read here.
//!
//! Why a hand parser rather than the `rinex` crate: Sextant needs two record types of one
//! system, with errors that name the line and field of a bad value; the `rinex` crate reads
//! far more (every system, ANTEX, IONEX, clocks, meteo, BINEX, RTCM) and its navigation
//! feature brings an astrodynamics toolkit (`anise`) and `hifitime` with their own time and
//! frame types, on a public API that changed in each of its last minor versions. The layout
//! needed is a few hundred lines here, with no dependency but `flate2` for `.gz` files.
//!
//! Errors: parsing never panics; a malformed value gives a [`ParseError`] with the 1-based line
//! number, the field name and what was wrong, and reading a file wraps it with the path
//! ([`FileError`]).

pub mod measurements;
pub mod navigation;
pub mod observation;

mod columns;

pub use columns::{ParseError, ParseErrorKind};
pub use navigation::{NavigationFile, parse_navigation, read_navigation};
pub use observation::{ObservationFile, parse_observation, read_observation};

use std::io::Read;
use std::path::{Path, PathBuf};

/// Why a RINEX file could not be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FileError {
    /// The file could not be opened, read or decompressed.
    #[error("{path}: {kind}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error kind.
        kind: std::io::ErrorKind,
    },
    /// The text is not valid RINEX.
    #[error("{path}: {error}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// Where and what.
        error: ParseError,
    },
}

/// The text of a file, decompressed when its name ends in `.gz`. Bytes that are not UTF-8
/// (RINEX is ASCII; comment lines sometimes carry Latin-1) are replaced, which only matters
/// in fields that are then rejected as bad text by the parser.
pub fn read_text(path: &Path) -> Result<String, FileError> {
    let io = |e: std::io::Error| FileError::Io {
        path: path.to_path_buf(),
        kind: e.kind(),
    };
    let raw = std::fs::read(path).map_err(io)?;
    let gzip = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gz"));
    decode_text(&raw, gzip).map_err(io)
}

/// The text of a file's bytes (`gzip`: decompress first), as [`read_text`] reads it: for data
/// held in memory, e.g. embedded in a binary.
pub fn decode_text(raw: &[u8], gzip: bool) -> Result<String, std::io::Error> {
    if gzip {
        let mut out = Vec::new();
        flate2::read::MultiGzDecoder::new(raw).read_to_end(&mut out)?;
        Ok(String::from_utf8_lossy(&out).into_owned())
    } else {
        Ok(String::from_utf8_lossy(raw).into_owned())
    }
}
