//! The four NMEA 0183 sentences the driver uses (NMEA 0183 v4.11 field layouts, as u-blox
//! receivers emit them, any talker: GP, GN, GL, GA, GB, …):
//!
//! - GGA: UTC time of day, latitude, longitude, fix quality, satellites used, HDOP, altitude
//!   above mean sea level and geoid separation (their sum is the ellipsoidal height);
//! - RMC: UTC time and date, status, speed and course over ground;
//! - GSA: fix mode (2-D/3-D), satellites used, PDOP, HDOP, VDOP;
//! - GST: pseudorange residual RMS, error ellipse and 1-σ latitude, longitude, altitude errors.
//!
//! Input is the body of a sentence whose checksum the framer has already verified. Empty
//! fields (a receiver without a fix leaves most of them empty) are `None`; a field that is
//! present but not a number, or out of its range, is an error naming the sentence and field.

/// A field of a sentence that could not be read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum NmeaParseError {
    /// Fewer fields than the sentence's layout.
    #[error("{sentence}: {got} fields, at least {expected} expected")]
    TooFewFields {
        /// Sentence type (GGA, RMC, …).
        sentence: &'static str,
        /// Fields received (after the address field).
        got: usize,
        /// Fields the layout requires.
        expected: usize,
    },
    /// A field present but not readable or out of range.
    #[error("{sentence}: field {field} is invalid")]
    Field {
        /// Sentence type.
        sentence: &'static str,
        /// 1-based field number after the address field.
        field: usize,
    },
}

/// UTC time of day, ms since midnight.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Default)]
pub struct TimeOfDay(pub u32);

/// UTC date.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Date {
    /// Year (four digits).
    pub year: i32,
    /// Month 1–12.
    pub month: u32,
    /// Day 1–31.
    pub day: u32,
}

/// GGA: fix data.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Gga {
    /// UTC time of the fix.
    pub time: Option<TimeOfDay>,
    /// Geodetic latitude, rad.
    pub lat_rad: Option<f64>,
    /// Longitude, rad.
    pub lon_rad: Option<f64>,
    /// Fix quality: 0 invalid, 1 GNSS, 2 differential, 4 RTK fixed, 5 RTK float,
    /// 6 dead reckoning.
    pub quality: u8,
    /// Satellites used.
    pub num_sv: Option<u32>,
    /// Horizontal dilution of precision.
    pub hdop: Option<f64>,
    /// Altitude above mean sea level, m.
    pub altitude_msl_m: Option<f64>,
    /// Geoid separation (ellipsoid height − MSL altitude), m.
    pub geoid_separation_m: Option<f64>,
}

/// RMC: recommended minimum data.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Rmc {
    /// UTC time.
    pub time: Option<TimeOfDay>,
    /// Status `A` (valid).
    pub valid: bool,
    /// Speed over ground, m/s.
    pub speed_m_s: Option<f64>,
    /// Course over ground, true, rad.
    pub course_rad: Option<f64>,
    /// UTC date.
    pub date: Option<Date>,
}

/// GSA: DOP and satellites used.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Gsa {
    /// Fix mode: 1 none, 2 2-D, 3 3-D.
    pub fix_mode: u8,
    /// Position DOP.
    pub pdop: Option<f64>,
    /// Horizontal DOP.
    pub hdop: Option<f64>,
    /// Vertical DOP.
    pub vdop: Option<f64>,
}

/// GST: pseudorange error statistics.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Gst {
    /// UTC time.
    pub time: Option<TimeOfDay>,
    /// 1-σ semi-major axis of the horizontal error ellipse, m.
    pub major_m: Option<f64>,
    /// 1-σ semi-minor axis, m.
    pub minor_m: Option<f64>,
    /// Orientation of the semi-major axis, from true north, rad.
    pub orientation_rad: Option<f64>,
    /// 1-σ latitude error, m.
    pub lat_sigma_m: Option<f64>,
    /// 1-σ longitude error, m.
    pub lon_sigma_m: Option<f64>,
    /// 1-σ altitude error, m.
    pub alt_sigma_m: Option<f64>,
}

/// A sentence the driver uses, or another valid one it ignores.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Sentence {
    /// GGA.
    Gga(Gga),
    /// RMC.
    Rmc(Rmc),
    /// GSA.
    Gsa(Gsa),
    /// GST.
    Gst(Gst),
    /// Any other sentence (GSV, VTG, GLL, proprietary, …): not used.
    Other,
}

const KNOT_M_S: f64 = 1852.0 / 3600.0;

struct Fields<'a> {
    sentence: &'static str,
    f: Vec<&'a str>,
}

impl<'a> Fields<'a> {
    fn new(
        sentence: &'static str,
        f: Vec<&'a str>,
        expected: usize,
    ) -> Result<Self, NmeaParseError> {
        if f.len() < expected {
            return Err(NmeaParseError::TooFewFields {
                sentence,
                got: f.len(),
                expected,
            });
        }
        Ok(Self { sentence, f })
    }
    fn err(&self, i: usize) -> NmeaParseError {
        NmeaParseError::Field {
            sentence: self.sentence,
            field: i,
        }
    }
    fn raw(&self, i: usize) -> &'a str {
        self.f.get(i - 1).copied().unwrap_or("")
    }
    /// A finite number in `range`, `None` when empty.
    fn num(
        &self,
        i: usize,
        range: std::ops::RangeInclusive<f64>,
    ) -> Result<Option<f64>, NmeaParseError> {
        let s = self.raw(i);
        if s.is_empty() {
            return Ok(None);
        }
        match s.parse::<f64>() {
            Ok(v) if v.is_finite() && range.contains(&v) => Ok(Some(v)),
            _ => Err(self.err(i)),
        }
    }
    fn time(&self, i: usize) -> Result<Option<TimeOfDay>, NmeaParseError> {
        let s = self.raw(i);
        if s.is_empty() {
            return Ok(None);
        }
        let bad = || self.err(i);
        if s.len() < 6 || !s.is_char_boundary(6) || !s[..6].bytes().all(|b| b.is_ascii_digit()) {
            return Err(bad());
        }
        let n = |a: usize| {
            u32::from(s.as_bytes()[a] - b'0') * 10 + u32::from(s.as_bytes()[a + 1] - b'0')
        };
        let (h, m, sec) = (n(0), n(2), n(4));
        // Second 60 is a leap second.
        if h > 23 || m > 59 || sec > 60 {
            return Err(bad());
        }
        let frac_ms = if s.len() > 6 {
            let frac = &s[6..];
            if !frac.starts_with('.')
                || frac.len() < 2
                || !frac[1..].bytes().all(|b| b.is_ascii_digit())
            {
                return Err(bad());
            }
            let v: f64 = frac.parse().map_err(|_| bad())?;
            (v * 1000.0).round().min(999.0) as u32
        } else {
            0
        };
        Ok(Some(TimeOfDay(((h * 60 + m) * 60 + sec) * 1000 + frac_ms)))
    }
    /// Latitude (`ddmm.mmmm`, N/S) or longitude (`dddmm.mmmm`, E/W), rad.
    fn angle(
        &self,
        i: usize,
        deg_digits: usize,
        pos: char,
        neg: char,
    ) -> Result<Option<f64>, NmeaParseError> {
        let s = self.raw(i);
        let h = self.raw(i + 1);
        if s.is_empty() && h.is_empty() {
            return Ok(None);
        }
        let bad = || self.err(i);
        if s.len() < deg_digits + 2 || !s.is_char_boundary(deg_digits) {
            return Err(bad());
        }
        let deg: f64 = s[..deg_digits].parse().map_err(|_| bad())?;
        let min: f64 = s[deg_digits..].parse().map_err(|_| bad())?;
        let limit = if deg_digits == 2 { 90.0 } else { 180.0 };
        if !((0.0..60.0).contains(&min) && (0.0..=180.0).contains(&deg)) {
            return Err(bad());
        }
        let v = deg + min / 60.0;
        if v > limit {
            return Err(bad());
        }
        let sign = match h.chars().next() {
            Some(c) if c == pos && h.len() == 1 => 1.0,
            Some(c) if c == neg && h.len() == 1 => -1.0,
            _ => return Err(self.err(i + 1)),
        };
        Ok(Some((sign * v).to_radians()))
    }
    fn date(&self, i: usize) -> Result<Option<Date>, NmeaParseError> {
        let s = self.raw(i);
        if s.is_empty() {
            return Ok(None);
        }
        if s.len() != 6 || !s.bytes().all(|b| b.is_ascii_digit()) {
            return Err(self.err(i));
        }
        let n = |a: usize| {
            u32::from(s.as_bytes()[a] - b'0') * 10 + u32::from(s.as_bytes()[a + 1] - b'0')
        };
        let (day, month, yy) = (n(0), n(2), n(4));
        if !(1..=31).contains(&day) || !(1..=12).contains(&month) {
            return Err(self.err(i));
        }
        // Two-digit years: GNSS receivers date from 1980 on.
        let year = if yy >= 80 { 1900 + yy } else { 2000 + yy } as i32;
        Ok(Some(Date { year, month, day }))
    }
}

/// Parse the body of a sentence (between `$` and `*`).
pub fn parse(body: &str) -> Result<Sentence, NmeaParseError> {
    let mut parts = body.split(',');
    let address = parts.next().unwrap_or("");
    let fields: Vec<&str> = parts.collect();
    // Talker (2 characters) + type (3); proprietary sentences start with P.
    if address.len() != 5 || address.starts_with('P') || !address.is_ascii() {
        return Ok(Sentence::Other);
    }
    Ok(match &address[2..] {
        "GGA" => {
            let f = Fields::new("GGA", fields, 14)?;
            Sentence::Gga(Gga {
                time: f.time(1)?,
                lat_rad: f.angle(2, 2, 'N', 'S')?,
                lon_rad: f.angle(4, 3, 'E', 'W')?,
                quality: f.num(6, 0.0..=9.0)?.map_or(0, |q| q as u8),
                num_sv: f.num(7, 0.0..=999.0)?.map(|n| n as u32),
                hdop: f.num(8, 0.0..=99.99)?,
                altitude_msl_m: f.num(9, -1.0e5..=1.0e6)?,
                geoid_separation_m: f.num(11, -1.0e3..=1.0e3)?,
            })
        }
        "RMC" => {
            let f = Fields::new("RMC", fields, 11)?;
            let valid = match f.raw(2) {
                "A" => true,
                "V" | "" => false,
                _ => return Err(f.err(2)),
            };
            Sentence::Rmc(Rmc {
                time: f.time(1)?,
                valid,
                speed_m_s: f.num(7, 0.0..=1.0e5)?.map(|k| k * KNOT_M_S),
                course_rad: f.num(8, 0.0..=360.0)?.map(f64::to_radians),
                date: f.date(9)?,
            })
        }
        "GSA" => {
            let f = Fields::new("GSA", fields, 17)?;
            Sentence::Gsa(Gsa {
                fix_mode: f.num(2, 1.0..=3.0)?.map_or(1, |m| m as u8),
                pdop: f.num(15, 0.0..=99.99)?,
                hdop: f.num(16, 0.0..=99.99)?,
                vdop: f.num(17, 0.0..=99.99)?,
            })
        }
        "GST" => {
            let f = Fields::new("GST", fields, 8)?;
            let sigma = |i| f.num(i, 0.0..=1.0e6);
            Sentence::Gst(Gst {
                time: f.time(1)?,
                major_m: sigma(3)?,
                minor_m: sigma(4)?,
                orientation_rad: f.num(5, 0.0..=360.0)?.map(f64::to_radians),
                lat_sigma_m: sigma(6)?,
                lon_sigma_m: sigma(7)?,
                alt_sigma_m: sigma(8)?,
            })
        }
        _ => Sentence::Other,
    })
}

/// NMEA `ddmm.mmmmm,N` / `dddmm.mmmmm,E` of an angle in radians (latitude when `lat`), as a
/// receiver prints it: for generating test input.
pub fn format_angle(rad: f64, lat: bool) -> String {
    let deg = rad.to_degrees();
    let (pos, neg, width) = if lat { ('N', 'S', 2) } else { ('E', 'W', 3) };
    let a = deg.abs();
    let mut d = a.floor();
    let mut m = (a - d) * 60.0;
    // Round to the printed resolution first so that 59.999995 does not print as 60.00000.
    m = (m * 1e5).round() / 1e5;
    if m >= 60.0 {
        d += 1.0;
        m -= 60.0;
    }
    format!(
        "{:0width$}{:08.5},{}",
        d as u32,
        m,
        if deg < 0.0 { neg } else { pos }
    )
}

/// NMEA `hhmmss.ss` of a time of day.
pub fn format_time(t: TimeOfDay) -> String {
    let ms = t.0;
    format!(
        "{:02}{:02}{:02}.{:02}",
        ms / 3_600_000,
        ms / 60_000 % 60,
        ms / 1000 % 60,
        ms % 1000 / 10
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn u_blox_sentences_are_read() {
        let gga = "GNGGA,092725.00,4717.11399,N,00833.91590,E,1,08,1.01,499.6,M,48.0,M,,";
        let Sentence::Gga(g) = parse(gga).unwrap() else {
            panic!()
        };
        assert_eq!(g.time, Some(TimeOfDay((9 * 3600 + 27 * 60 + 25) * 1000)));
        assert!((g.lat_rad.unwrap().to_degrees() - (47.0 + 17.11399 / 60.0)).abs() < 1e-12);
        assert!((g.lon_rad.unwrap().to_degrees() - (8.0 + 33.91590 / 60.0)).abs() < 1e-12);
        assert_eq!((g.quality, g.num_sv, g.hdop), (1, Some(8), Some(1.01)));
        assert_eq!(
            (g.altitude_msl_m, g.geoid_separation_m),
            (Some(499.6), Some(48.0))
        );

        let rmc = "GPRMC,083559.00,A,4717.11437,N,00833.91522,E,0.004,77.52,091202,,,A";
        let Sentence::Rmc(r) = parse(rmc).unwrap() else {
            panic!()
        };
        assert!(r.valid);
        assert_eq!(
            r.date,
            Some(Date {
                year: 2002,
                month: 12,
                day: 9
            })
        );
        assert!((r.speed_m_s.unwrap() - 0.004 * 1852.0 / 3600.0).abs() < 1e-15);

        let gsa = "GPGSA,A,3,23,29,07,08,09,18,26,28,,,,,1.94,1.18,1.54";
        assert_eq!(
            parse(gsa).unwrap(),
            Sentence::Gsa(Gsa {
                fix_mode: 3,
                pdop: Some(1.94),
                hdop: Some(1.18),
                vdop: Some(1.54)
            })
        );
        let gst = "GPGST,082356.00,1.8,,,,1.7,1.3,2.2";
        let Sentence::Gst(s) = parse(gst).unwrap() else {
            panic!()
        };
        assert_eq!(
            (s.major_m, s.lat_sigma_m, s.lon_sigma_m, s.alt_sigma_m),
            (None, Some(1.7), Some(1.3), Some(2.2))
        );
        assert_eq!(parse("GPGSV,3,1,10,23,38,230,44").unwrap(), Sentence::Other);
    }

    #[test]
    fn no_fix_sentences_have_empty_fields() {
        let Sentence::Gga(g) = parse("GPGGA,000001.00,,,,,0,00,99.99,,,,,,").unwrap() else {
            panic!()
        };
        assert_eq!((g.quality, g.lat_rad, g.altitude_msl_m), (0, None, None));
        let Sentence::Rmc(r) = parse("GPRMC,000001.00,V,,,,,,,,,,N").unwrap() else {
            panic!()
        };
        assert!(!r.valid);
    }

    #[test]
    fn bad_fields_are_named() {
        assert_eq!(
            parse("GPGGA,250000.00,4717.1,N,00833.9,E,1,08,1.0,499.6,M,48.0,M,,"),
            Err(NmeaParseError::Field {
                sentence: "GGA",
                field: 1
            })
        );
        assert_eq!(
            parse("GPGGA,000000.00,4717.1,X,00833.9,E,1,08,1.0,499.6,M,48.0,M,,"),
            Err(NmeaParseError::Field {
                sentence: "GGA",
                field: 3
            })
        );
        assert!(matches!(
            parse("GPGST,1"),
            Err(NmeaParseError::TooFewFields { .. })
        ));
    }

    #[test]
    fn formatted_angles_and_times_read_back() {
        for deg in [55.655f64, -33.9, 0.0, 89.9999999] {
            let s = format_angle(deg.to_radians(), true);
            let body = format!("GPGGA,000000.00,{s},00000.000,E,1,08,1.0,0,M,0,M,,");
            let Sentence::Gga(g) = parse(&body).unwrap() else {
                panic!()
            };
            assert!((g.lat_rad.unwrap().to_degrees() - deg).abs() < 1e-6, "{s}");
        }
        assert_eq!(format_time(TimeOfDay(75_600_010)), "210000.01");
    }

    proptest! {
        /// Arbitrary text after a known address: an error or a value, never a panic.
        #[test]
        fn arbitrary_fields_never_panic(kind in prop::sample::select(vec!["GPGGA", "GNRMC", "GPGSA", "GLGST", "GPXXX"]),
                                        rest in "[ -~]{0,100}") {
            let _ = parse(&format!("{kind},{rest}"));
        }
        /// Any printable bytes as a whole body: never a panic.
        #[test]
        fn arbitrary_bodies_never_panic(body in "[ -~]{0,100}") {
            let _ = parse(&body);
        }
    }
}
