//! RINEX 3 observation files (RINEX 3.05 §5.1, Tables A2–A3): header, epoch records, GPS
//! satellite records. Records of the other systems are read past (their line is consumed,
//! its content not interpreted), and event records (flags 2–5) and cycle-slip records (flag 6)
//! are skipped with their announced number of lines.

use crate::columns::{Line, ParseError, ParseErrorKind, gps_calendar};
use crate::{FileError, read_text};
use fusion::time::GpsTime;
use std::path::Path;

/// Width of one observation field: F14.3 value, loss-of-lock indicator, signal strength.
const OBS_WIDTH: usize = 16;

/// The header values Sextant uses.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ObservationHeader {
    /// Format version (3.00–3.05).
    pub version: f64,
    /// Marker (station) name.
    pub marker_name: String,
    /// Approximate marker position, ECEF, m (`APPROX POSITION XYZ`).
    pub approx_position_m: Option<[f64; 3]>,
    /// Antenna reference point above the marker: height, east, north, m
    /// (`ANTENNA: DELTA H/E/N`).
    pub antenna_delta_hen_m: [f64; 3],
    /// Receiver type.
    pub receiver_type: String,
    /// Antenna type.
    pub antenna_type: String,
    /// GPS observation codes in file order (`C1C`, `L2W`, …).
    pub gps_obs_types: Vec<String>,
    /// Observation interval, s.
    pub interval_s: Option<f64>,
}

/// One GPS satellite's values at an epoch, in the order of
/// [`ObservationHeader::gps_obs_types`] (`None`: blank in the file).
#[derive(Debug, Clone, PartialEq)]
pub struct GpsSatelliteRecord {
    /// PRN.
    pub prn: u8,
    /// Values (pseudorange m, phase cycles, Doppler Hz, C/N0 dB-Hz, per the code).
    pub values: Vec<Option<f64>>,
}

/// One epoch.
#[derive(Debug, Clone, PartialEq)]
pub struct ObservationEpoch {
    /// Receiver time of the measurements (GPS time scale).
    pub time: GpsTime,
    /// Epoch flag (0 OK, 1 power failure before the epoch).
    pub flag: u8,
    /// Receiver clock offset given in the file, s.
    pub clock_offset_s: Option<f64>,
    /// GPS satellites of the epoch.
    pub gps: Vec<GpsSatelliteRecord>,
}

/// A parsed observation file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ObservationFile {
    /// Header.
    pub header: ObservationHeader,
    /// Epochs with observations, in file order.
    pub epochs: Vec<ObservationEpoch>,
}

impl ObservationFile {
    /// Index of a GPS observation code in the satellite records.
    pub fn gps_index(&self, code: &str) -> Option<usize> {
        self.header.gps_obs_types.iter().position(|c| c == code)
    }
}

/// Read (and gunzip) an observation file.
pub fn read_observation(path: &Path) -> Result<ObservationFile, FileError> {
    let text = read_text(path)?;
    parse_observation(&text).map_err(|error| FileError::Parse {
        path: path.to_path_buf(),
        error,
    })
}

/// Parse the text of a RINEX 3 observation file.
pub fn parse_observation(text: &str) -> Result<ObservationFile, ParseError> {
    let mut lines = text.lines().enumerate().map(|(i, t)| Line {
        text: t.trim_end_matches('\r'),
        number: i + 1,
    });
    let (header, sys_counts) = parse_header(&mut lines)?;
    let mut epochs = Vec::new();
    while let Some(line) = lines.next() {
        if line.text.trim().is_empty() {
            continue;
        }
        if !line.text.starts_with('>') {
            return Err(line.err("epoch record", ParseErrorKind::BadText));
        }
        let flag = line.uint(31, 32, "epoch flag")?;
        let n = line.uint(32, 35, "number of satellites")? as usize;
        if flag > 1 {
            // Event (2–5: n header lines follow) or cycle-slip records (6: n satellite lines).
            for _ in 0..n {
                lines
                    .next()
                    .ok_or(line.err("event record", ParseErrorKind::UnexpectedEnd))?;
            }
            continue;
        }
        let ymdhm = [
            line.uint(2, 6, "epoch year")?,
            line.uint(7, 9, "epoch month")?,
            line.uint(10, 12, "epoch day")?,
            line.uint(13, 15, "epoch hour")?,
            line.uint(16, 18, "epoch minute")?,
        ];
        let sec = line.f64(18, 29, "epoch second")?;
        let time = gps_calendar(&line, "epoch", ymdhm, sec)?;
        let clock_offset_s = line.opt_f64(41, 56, "receiver clock offset")?;
        let mut gps = Vec::new();
        for _ in 0..n {
            let sl = lines
                .next()
                .ok_or(line.err("satellite record", ParseErrorKind::UnexpectedEnd))?;
            let sys = sl.cols(0, 1, "satellite system")?;
            if sys != "G" {
                // Another system (or a blank system letter meaning GPS in RINEX 2 only).
                if sys.trim().is_empty() || !sys.chars().all(|c| c.is_ascii_uppercase()) {
                    return Err(sl.err("satellite system", ParseErrorKind::BadText));
                }
                continue;
            }
            let prn = sl.uint(1, 3, "satellite number")?;
            if !(1..=32).contains(&prn) {
                return Err(sl.err("satellite number", ParseErrorKind::BadNumber));
            }
            let n_types = sys_counts.gps;
            let mut values = Vec::with_capacity(n_types);
            for k in 0..n_types {
                let start = 3 + k * OBS_WIDTH;
                values.push(sl.opt_f64(start, start + 14, "observation")?);
            }
            gps.push(GpsSatelliteRecord {
                prn: prn as u8,
                values,
            });
        }
        epochs.push(ObservationEpoch {
            time,
            flag: flag as u8,
            clock_offset_s,
            gps,
        });
    }
    Ok(ObservationFile { header, epochs })
}

/// Observation type counts per system that the record layout depends on.
#[derive(Default)]
struct SysCounts {
    gps: usize,
}

fn parse_header<'a>(
    lines: &mut impl Iterator<Item = Line<'a>>,
) -> Result<(ObservationHeader, SysCounts), ParseError> {
    let mut h = ObservationHeader::default();
    let mut counts = SysCounts::default();
    let mut last = 0;
    // Observation types still expected on continuation lines of `SYS / # / OBS TYPES`.
    let mut pending: (bool, usize) = (false, 0);
    let mut first = true;
    for line in lines.by_ref() {
        last = line.number;
        let label = line.label();
        if first {
            first = false;
            if label != "RINEX VERSION / TYPE" {
                return Err(line.err("RINEX VERSION / TYPE", ParseErrorKind::Missing));
            }
            h.version = line.f64(0, 9, "format version")?;
            if !(3.0..4.0).contains(&h.version) {
                return Err(line.err("format version", ParseErrorKind::Unsupported("not RINEX 3")));
            }
            if line.cols(20, 21, "file type")? != "O" {
                return Err(line.err(
                    "file type",
                    ParseErrorKind::Unsupported("not an observation file"),
                ));
            }
            continue;
        }
        match label {
            "MARKER NAME" => h.marker_name = line.cols(0, 60, "marker name")?.trim().to_string(),
            "REC # / TYPE / VERS" => {
                h.receiver_type = line.cols(20, 40, "receiver type")?.trim().to_string()
            }
            "ANT # / TYPE" => {
                h.antenna_type = line.cols(20, 40, "antenna type")?.trim().to_string()
            }
            "APPROX POSITION XYZ" => {
                h.approx_position_m = Some([
                    line.f64(0, 14, "approx position X")?,
                    line.f64(14, 28, "approx position Y")?,
                    line.f64(28, 42, "approx position Z")?,
                ])
            }
            "ANTENNA: DELTA H/E/N" => {
                h.antenna_delta_hen_m = [
                    line.f64(0, 14, "antenna delta H")?,
                    line.f64(14, 28, "antenna delta E")?,
                    line.f64(28, 42, "antenna delta N")?,
                ]
            }
            "INTERVAL" => h.interval_s = line.opt_f64(0, 10, "interval")?,
            "SYS / SCALE FACTOR" => {
                return Err(line.err(
                    "SYS / SCALE FACTOR",
                    ParseErrorKind::Unsupported("scaled observations"),
                ));
            }
            "TIME OF FIRST OBS" => {
                let ts = line.cols(48, 51, "time system")?.trim();
                if !(ts.is_empty() || ts == "GPS") {
                    return Err(line.err(
                        "time system",
                        ParseErrorKind::Unsupported("time system other than GPS"),
                    ));
                }
            }
            "SYS / # / OBS TYPES" => {
                let sys = line.cols(0, 1, "satellite system")?;
                let (is_gps, remaining) = if sys.trim().is_empty() {
                    // Continuation line.
                    if pending.1 == 0 {
                        return Err(line.err("SYS / # / OBS TYPES", ParseErrorKind::BadText));
                    }
                    pending
                } else {
                    let n = line.uint(3, 6, "number of observation types")? as usize;
                    if sys == "G" {
                        counts.gps = n;
                    }
                    (sys == "G", n)
                };
                let on_line = remaining.min(13);
                for k in 0..on_line {
                    let code = line.cols(7 + 4 * k, 10 + 4 * k, "observation type")?;
                    if code.len() != 3 || !code.chars().all(|c| c.is_ascii_alphanumeric()) {
                        return Err(line.err("observation type", ParseErrorKind::BadText));
                    }
                    if is_gps {
                        h.gps_obs_types.push(code.to_string());
                    }
                }
                pending = (is_gps, remaining - on_line);
            }
            "END OF HEADER" => {
                if pending.1 != 0 {
                    return Err(line.err("SYS / # / OBS TYPES", ParseErrorKind::Missing));
                }
                return Ok((h, counts));
            }
            _ => {}
        }
    }
    Err(ParseError {
        line: last + 1,
        field: "END OF HEADER",
        kind: ParseErrorKind::UnexpectedEnd,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) const SAMPLE: &str = "     3.05           OBSERVATION DATA    M (MIXED)           RINEX VERSION / TYPE
ESBC00DNK                                                   MARKER NAME
3047937             SEPT POLARX5        5.2.0               REC # / TYPE / VERS
CR5200327016        ASH701945E_M    SCIS                    ANT # / TYPE
        0.2160        0.0000        0.0000                  ANTENNA: DELTA H/E/N
  3582105.2910   532589.7313  5232754.8054                  APPROX POSITION XYZ
E    4 C1C C5Q D1C S1C                                      SYS / # / OBS TYPES
G   18 C1C C1W C2L C2W C5Q D1C D2L D2W D5Q L1C L2L L2W L5Q  SYS / # / OBS TYPES
       S1C S1W S2L S2W S5Q                                  SYS / # / OBS TYPES
    30.000                                                  INTERVAL
  2020     6    25     0     0    0.0000000     GPS         TIME OF FIRST OBS
                                                            END OF HEADER
> 2020 06 25 00 00 00.0000000  0  3
E01  23456789.123 8
G05  20947300.931 8  20947300.507 9  20947301.155 7  20947300.413 9                     -1037.205 8      -808.180 7      -808.209 9                 110078836.38908  85775716.72307  85775729.71809                        50.500          55.000          47.250          55.000
G07  22123456.789 7
> 2020 06 25 00 00 30.0000000  4  1
                                                            COMMENT
> 2020 06 25 00 00 30.0000000  0  1
G05  20947400.000 8
";

    #[test]
    fn reads_header_epochs_and_gps_records() {
        let f = parse_observation(SAMPLE).unwrap();
        assert_eq!(f.header.marker_name, "ESBC00DNK");
        assert_eq!(
            f.header.approx_position_m,
            Some([3582105.2910, 532589.7313, 5232754.8054])
        );
        assert_eq!(f.header.antenna_delta_hen_m, [0.216, 0.0, 0.0]);
        assert_eq!(f.header.gps_obs_types.len(), 18);
        assert_eq!(f.header.gps_obs_types[17], "S5Q");
        assert_eq!(f.header.interval_s, Some(30.0));
        assert_eq!(f.epochs.len(), 2, "the event record is skipped");
        let e = &f.epochs[0];
        // 2020-06-25 00:00 GPS = week 2111, 345 600 s.
        assert_eq!(e.time.ns, (2111 * 604_800 + 345_600) * 1_000_000_000);
        assert_eq!(e.gps.len(), 2, "Galileo skipped");
        let g05 = &e.gps[0];
        assert_eq!(g05.prn, 5);
        let i = |c| f.gps_index(c).unwrap();
        assert_eq!(g05.values[i("C1C")], Some(20947300.931));
        assert_eq!(g05.values[i("C2W")], Some(20947300.413));
        assert_eq!(g05.values[i("C5Q")], None);
        assert_eq!(g05.values[i("D1C")], Some(-1037.205));
        assert_eq!(g05.values[i("S1C")], Some(50.5));
        assert_eq!(g05.values[i("S5Q")], None);
        // A record cut after its first value: the rest is blank, not an error.
        assert_eq!(e.gps[1].values[i("C1C")], Some(22123456.789));
        assert_eq!(e.gps[1].values[i("C1W")], None);
        assert_eq!(f.epochs[1].time.ns - e.time.ns, 30_000_000_000);
    }

    #[test]
    fn bad_input_names_line_and_field() {
        let bad = SAMPLE.replace("20947300.507", "2094x300.507");
        let err = parse_observation(&bad).unwrap_err();
        assert_eq!(
            err,
            ParseError {
                line: 15,
                field: "observation",
                kind: ParseErrorKind::BadNumber
            }
        );
        let cut = &SAMPLE[..SAMPLE.find("G07").unwrap()];
        let err = parse_observation(cut).unwrap_err();
        assert_eq!((err.line, err.kind), (13, ParseErrorKind::UnexpectedEnd));
        let err = parse_observation(&SAMPLE.replace(" 06 25 00 00 00.0", " 13 25 00 00 00.0"))
            .unwrap_err();
        assert_eq!(
            (err.line, err.field, err.kind),
            (13, "epoch", ParseErrorKind::BadDate)
        );
        let err = parse_observation(&SAMPLE.replace("     3.05", "     2.11")).unwrap_err();
        assert_eq!(err.field, "format version");
        let nohdr = &SAMPLE[..SAMPLE.find("    30.000").unwrap()];
        let err = parse_observation(nohdr).unwrap_err();
        assert_eq!(
            (err.field, err.kind),
            ("END OF HEADER", ParseErrorKind::UnexpectedEnd)
        );
        let err = parse_observation(&SAMPLE.replace("G05  2094", "G5x  2094")).unwrap_err();
        assert_eq!((err.line, err.field), (15, "satellite number"));
        let e = format!("{err}");
        assert!(
            e.contains("line 15") && e.contains("satellite number"),
            "{e}"
        );
    }
}
