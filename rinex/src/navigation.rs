//! RINEX 3 navigation files (RINEX 3.05 §5.4, Tables A6, A8): the GPS Klobuchar coefficients
//! of the header and the GPS LNAV ephemeris records. Records of the other systems are read
//! past: a record runs from a line starting with a system letter to the next such line
//! (continuation lines start with blanks), so their different lengths need no table.

use crate::columns::{Line, ParseError, ParseErrorKind, gps_calendar};
use crate::{FileError, read_text};
use fusion::broadcast_ephemeris::{GpsEphemeris, SECONDS_PER_WEEK, from_week_seconds};
use fusion::gnss_corrections::KlobucharCoefficients;
use fusion::time::NS_PER_S;
use std::path::Path;

/// A parsed navigation file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct NavigationFile {
    /// Format version.
    pub version: f64,
    /// GPS Klobuchar coefficients (`IONOSPHERIC CORR GPSA` and `GPSB`), when both are given.
    pub klobuchar: Option<KlobucharCoefficients>,
    /// `LEAP SECONDS` (GPS − UTC), when given.
    pub leap_seconds: Option<u32>,
    /// GPS ephemerides in file order.
    pub gps: Vec<GpsEphemeris>,
    /// Records of other systems read past.
    pub skipped_records: usize,
}

/// Read (and gunzip) a navigation file.
pub fn read_navigation(path: &Path) -> Result<NavigationFile, FileError> {
    let text = read_text(path)?;
    parse_navigation(&text).map_err(|error| FileError::Parse {
        path: path.to_path_buf(),
        error,
    })
}

/// Columns of the four values of a "BROADCAST ORBIT" line (4X, 4D19.12).
const ORBIT_COLS: [(usize, usize); 4] = [(4, 23), (23, 42), (42, 61), (61, 80)];

/// Parse the text of a RINEX 3 navigation file.
pub fn parse_navigation(text: &str) -> Result<NavigationFile, ParseError> {
    let lines: Vec<Line> = text
        .lines()
        .enumerate()
        .map(|(i, t)| Line {
            text: t.trim_end_matches('\r'),
            number: i + 1,
        })
        .collect();
    let mut nav = NavigationFile::default();
    let mut alpha = None;
    let mut beta = None;
    let mut i = 0;
    // Header.
    loop {
        let Some(line) = lines.get(i) else {
            return Err(ParseError {
                line: lines.len() + 1,
                field: "END OF HEADER",
                kind: ParseErrorKind::UnexpectedEnd,
            });
        };
        i += 1;
        let label = line.label();
        if i == 1 {
            if label != "RINEX VERSION / TYPE" {
                return Err(line.err("RINEX VERSION / TYPE", ParseErrorKind::Missing));
            }
            nav.version = line.f64(0, 9, "format version")?;
            if !(3.0..4.0).contains(&nav.version) {
                return Err(line.err("format version", ParseErrorKind::Unsupported("not RINEX 3")));
            }
            if line.cols(20, 21, "file type")? != "N" {
                return Err(line.err(
                    "file type",
                    ParseErrorKind::Unsupported("not a navigation file"),
                ));
            }
            continue;
        }
        match label {
            "IONOSPHERIC CORR" => {
                let kind = line.cols(0, 4, "correction type")?;
                let read4 = |field| -> Result<[f64; 4], ParseError> {
                    Ok([
                        line.f64(5, 17, field)?,
                        line.f64(17, 29, field)?,
                        line.f64(29, 41, field)?,
                        line.f64(41, 53, field)?,
                    ])
                };
                match kind {
                    "GPSA" => alpha = Some(read4("GPSA coefficient")?),
                    "GPSB" => beta = Some(read4("GPSB coefficient")?),
                    _ => {}
                }
            }
            "LEAP SECONDS" => nav.leap_seconds = Some(line.uint(0, 6, "leap seconds")?),
            "END OF HEADER" => break,
            _ => {}
        }
    }
    if let (Some(alpha), Some(beta)) = (alpha, beta) {
        nav.klobuchar = Some(KlobucharCoefficients { alpha, beta });
    }
    // Records.
    while i < lines.len() {
        let line = lines[i];
        i += 1;
        if line.text.trim().is_empty() {
            continue;
        }
        let sys = line.cols(0, 1, "satellite system")?;
        if !sys.chars().all(|c| c.is_ascii_uppercase()) || sys.is_empty() {
            return Err(line.err("satellite system", ParseErrorKind::BadText));
        }
        if sys != "G" {
            nav.skipped_records += 1;
            while i < lines.len() && lines[i].text.starts_with(' ') {
                i += 1;
            }
            continue;
        }
        let orbit = lines
            .get(i..i + 7)
            .ok_or(line.err("broadcast orbit", ParseErrorKind::UnexpectedEnd))?;
        i += 7;
        nav.gps.push(gps_record(&line, orbit)?);
    }
    Ok(nav)
}

/// One GPS record: the epoch/clock line and its seven "BROADCAST ORBIT" lines.
fn gps_record(first: &Line, orbit: &[Line]) -> Result<GpsEphemeris, ParseError> {
    let prn = first.uint(1, 3, "satellite number")?;
    if !(1..=32).contains(&prn) {
        return Err(first.err("satellite number", ParseErrorKind::BadNumber));
    }
    let ymdhm = [
        first.uint(4, 8, "toc year")?,
        first.uint(9, 11, "toc month")?,
        first.uint(12, 14, "toc day")?,
        first.uint(15, 17, "toc hour")?,
        first.uint(18, 20, "toc minute")?,
    ];
    let sec = first.uint(21, 23, "toc second")?;
    let toc = gps_calendar(first, "toc", ymdhm, sec as f64)?;
    for l in orbit {
        if !l.text.starts_with("    ") {
            return Err(l.err("broadcast orbit", ParseErrorKind::BadText));
        }
    }
    let v = |row: usize, col: usize, field: &'static str| {
        let (a, b) = ORBIT_COLS[col];
        orbit[row].f64(a, b, field)
    };
    // Fields that may be left blank (spare or optional) read as 0.
    let opt = |row: usize, col: usize, field: &'static str| {
        let (a, b) = ORBIT_COLS[col];
        orbit[row].opt_f64(a, b, field).map(|x| x.unwrap_or(0.0))
    };
    let nonneg_int = |x: f64, line: &Line, field: &'static str| {
        if (0.0..4.3e9).contains(&x) && x.fract() == 0.0 {
            Ok(x as u32)
        } else {
            Err(line.err(field, ParseErrorKind::BadNumber))
        }
    };
    let toe_sow = v(2, 0, "Toe")?;
    let week = nonneg_int(v(4, 2, "GPS week")?, &orbit[4], "GPS week")?;
    if !(0.0..SECONDS_PER_WEEK).contains(&toe_sow) {
        return Err(orbit[2].err("Toe", ParseErrorKind::BadNumber));
    }
    // The week number goes with t_oe; near a week boundary it may still be the week of the
    // upload: put t_oe within half a week of t_oc.
    let mut toe = from_week_seconds(week, toe_sow);
    let half_week_ns = 302_400 * NS_PER_S;
    if toe.ns - toc.ns > half_week_ns {
        toe = toe.add_ns(-2 * half_week_ns);
    } else if toc.ns - toe.ns > half_week_ns {
        toe = toe.add_ns(2 * half_week_ns);
    }
    let fit = opt(6, 1, "fit interval")?;
    Ok(GpsEphemeris {
        prn: prn as u8,
        toc,
        af0_s: first.f64(23, 42, "SV clock bias")?,
        af1_s_s: first.f64(42, 61, "SV clock drift")?,
        af2_s_s2: first.f64(61, 80, "SV clock drift rate")?,
        iode: nonneg_int(v(0, 0, "IODE")?, &orbit[0], "IODE")?,
        crs_m: v(0, 1, "Crs")?,
        delta_n_rad_s: v(0, 2, "Delta n")?,
        m0_rad: v(0, 3, "M0")?,
        cuc_rad: v(1, 0, "Cuc")?,
        e: v(1, 1, "e")?,
        cus_rad: v(1, 2, "Cus")?,
        sqrt_a_sqrt_m: v(1, 3, "sqrt(A)")?,
        toe,
        cic_rad: v(2, 1, "Cic")?,
        omega0_rad: v(2, 2, "OMEGA0")?,
        cis_rad: v(2, 3, "Cis")?,
        i0_rad: v(3, 0, "i0")?,
        crc_m: v(3, 1, "Crc")?,
        omega_rad: v(3, 2, "omega")?,
        omega_dot_rad_s: v(3, 3, "OMEGA DOT")?,
        idot_rad_s: v(4, 0, "IDOT")?,
        ura_m: v(5, 0, "SV accuracy")?,
        health: nonneg_int(v(5, 1, "SV health")?, &orbit[5], "SV health")?,
        tgd_s: v(5, 2, "TGD")?,
        iodc: nonneg_int(opt(5, 3, "IODC")?, &orbit[5], "IODC")?,
        fit_interval_h: if fit > 0.0 { fit } else { 4.0 },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) const SAMPLE: &str =
        "     3.05           NAVIGATION DATA     MIXED               RINEX VERSION / TYPE
GAL    2.8250e+01  7.8125e-03  1.0071e-02  0.0000E+00       IONOSPHERIC CORR
GPSA   4.6566e-09  1.4901e-08 -5.9605e-08 -1.1921E-07       IONOSPHERIC CORR
GPSB   8.1920e+04  9.8304e+04 -6.5536e+04 -5.2429E+05       IONOSPHERIC CORR
    18                                                      LEAP SECONDS
                                                            END OF HEADER
R01 2020 06 25 00 15 00 1.234567890123e-05 0.000000000000e+00 3.456000000000e+05
    1.000000000000e+04 0.000000000000e+00 0.000000000000e+00 0.000000000000e+00
    1.000000000000e+04 0.000000000000e+00 0.000000000000e+00 1.000000000000e+00
    1.000000000000e+04 0.000000000000e+00 0.000000000000e+00 0.000000000000e+00
G05 2020 06 25 00 00 00-1.531792804599e-05-7.958078640513e-13 0.000000000000e+00
     1.200000000000e+01-1.046875000000e+02 4.706267463502e-09 1.465137968214e+00
    -5.315989255905e-06 5.968198296614e-03 9.898096323013e-06 5.153691232681e+03
     3.456000000000e+05-1.285225152969e-07-2.702593756598e+00 1.229345798492e-07
     9.531592011466e-01 1.876562500000e+02 8.074291054860e-01-8.116766667340e-09
     6.071681481333e-12 1.000000000000e+00 2.111000000000e+03 0.000000000000e+00
     2.000000000000e+00 0.000000000000e+00-1.117587089539e-08 1.200000000000e+01
     3.384180000000e+05 4.000000000000e+00
E01 2020 06 25 00 00 00 1.0e-05 0.0 0.0
     1.0 1.0 1.0 1.0
";

    #[test]
    fn reads_gps_records_and_klobuchar() {
        let nav = parse_navigation(SAMPLE).unwrap();
        let k = nav.klobuchar.unwrap();
        assert_eq!(k.alpha, [4.6566e-09, 1.4901e-08, -5.9605e-08, -1.1921e-07]);
        assert_eq!(k.beta[3], -5.2429e+05);
        assert_eq!(nav.leap_seconds, Some(18));
        assert_eq!(nav.skipped_records, 2);
        assert_eq!(nav.gps.len(), 1);
        let e = &nav.gps[0];
        assert_eq!(e.prn, 5);
        assert_eq!(e.toe, from_week_seconds(2111, 345_600.0));
        assert_eq!(e.toc, e.toe);
        assert_eq!(e.af0_s, -1.531792804599e-05);
        assert_eq!(e.sqrt_a_sqrt_m, 5.153691232681e+03);
        assert_eq!(e.omega_dot_rad_s, -8.116766667340e-09);
        assert_eq!(e.tgd_s, -1.117587089539e-08);
        assert_eq!((e.iode, e.iodc, e.health), (12, 12, 0));
        assert_eq!(e.ura_m, 2.0);
        assert_eq!(e.fit_interval_h, 4.0);
    }

    #[test]
    fn bad_input_names_line_and_field() {
        let err = parse_navigation(&SAMPLE.replace("5.153691232681e+03", "5.153691232681x+03"))
            .unwrap_err();
        assert_eq!(
            err,
            ParseError {
                line: 13,
                field: "sqrt(A)",
                kind: ParseErrorKind::BadNumber
            }
        );
        let cut = &SAMPLE[..SAMPLE.find("     3.384180000000e+05").unwrap()];
        let err = parse_navigation(cut).unwrap_err();
        assert_eq!(
            (err.line, err.field, err.kind),
            (11, "broadcast orbit", ParseErrorKind::UnexpectedEnd)
        );
        let err = parse_navigation(&SAMPLE.replace("G05 2020 06 25 00", "G05 2020 06 32 00"))
            .unwrap_err();
        assert_eq!((err.line, err.field), (11, "toc"));
        let err =
            parse_navigation(&SAMPLE.replace("NAVIGATION DATA ", "OBSERVATION DATA")).unwrap_err();
        assert_eq!(err.field, "file type");
        // D exponents (Fortran) are read.
        let d =
            parse_navigation(&SAMPLE.replace("5.153691232681e+03", "5.153691232681D+03")).unwrap();
        assert_eq!(d.gps[0].sqrt_a_sqrt_m, 5153.691232681);
    }
}
