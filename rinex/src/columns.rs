//! Fixed-column field access and the parse error type shared by both file kinds.

use fusion::time::{GpsTime, NS_PER_DAY, NS_PER_S, days_from_civil};

/// What was wrong with a field.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ParseErrorKind {
    /// The field does not hold a (finite) number.
    #[error("not a number")]
    BadNumber,
    /// A required field is blank or the line ends before it.
    #[error("missing")]
    Missing,
    /// A date or time field is out of range.
    #[error("invalid date or time")]
    BadDate,
    /// The file is not of the expected RINEX type or version.
    #[error("unsupported: {0}")]
    Unsupported(&'static str),
    /// The file ends inside a header or record.
    #[error("unexpected end of file")]
    UnexpectedEnd,
    /// A field holds characters the format does not allow there.
    #[error("invalid text")]
    BadText,
}

/// A parse error: 1-based line number, field name and what was wrong.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("line {line}, {field}: {kind}")]
pub struct ParseError {
    /// 1-based line number.
    pub line: usize,
    /// Name of the field (RINEX 3.05 wording).
    pub field: &'static str,
    /// What was wrong.
    pub kind: ParseErrorKind,
}

/// One line of a file with its 1-based number, for field extraction.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Line<'a> {
    pub text: &'a str,
    pub number: usize,
}

impl<'a> Line<'a> {
    pub fn err(&self, field: &'static str, kind: ParseErrorKind) -> ParseError {
        ParseError {
            line: self.number,
            field,
            kind,
        }
    }

    /// Columns `start..end` (0-based, byte columns of an ASCII record), clipped to the line;
    /// `BadText` if the cut falls inside a non-ASCII character.
    pub fn cols(
        &self,
        start: usize,
        end: usize,
        field: &'static str,
    ) -> Result<&'a str, ParseError> {
        let b = self.text.as_bytes();
        let (s, e) = (start.min(b.len()), end.min(b.len()));
        std::str::from_utf8(&b[s..e]).map_err(|_| self.err(field, ParseErrorKind::BadText))
    }

    /// The header label (columns 61–80), trimmed.
    pub fn label(&self) -> &'a str {
        self.cols(60, 80, "label").map(str::trim).unwrap_or("")
    }

    /// An optional number in columns `start..end` (`D` exponents accepted); `None` if blank.
    pub fn opt_f64(
        &self,
        start: usize,
        end: usize,
        field: &'static str,
    ) -> Result<Option<f64>, ParseError> {
        let s = self.cols(start, end, field)?.trim();
        if s.is_empty() {
            return Ok(None);
        }
        let v: f64 = if s.contains(['D', 'd']) {
            s.replace(['D', 'd'], "E").parse()
        } else {
            s.parse()
        }
        .map_err(|_| self.err(field, ParseErrorKind::BadNumber))?;
        if v.is_finite() {
            Ok(Some(v))
        } else {
            Err(self.err(field, ParseErrorKind::BadNumber))
        }
    }

    /// A required number in columns `start..end`.
    pub fn f64(&self, start: usize, end: usize, field: &'static str) -> Result<f64, ParseError> {
        self.opt_f64(start, end, field)?
            .ok_or(self.err(field, ParseErrorKind::Missing))
    }

    /// A required non-negative integer in columns `start..end`.
    pub fn uint(&self, start: usize, end: usize, field: &'static str) -> Result<u32, ParseError> {
        let s = self.cols(start, end, field)?.trim();
        if s.is_empty() {
            return Err(self.err(field, ParseErrorKind::Missing));
        }
        s.parse()
            .map_err(|_| self.err(field, ParseErrorKind::BadNumber))
    }
}

/// GPS time of a calendar epoch given in the GPS time scale (no leap seconds), with the
/// seconds as written (fractional).
pub(crate) fn gps_calendar(
    line: &Line,
    field: &'static str,
    ymdhm: [u32; 5],
    second: f64,
) -> Result<GpsTime, ParseError> {
    let [y, mo, d, h, mi] = ymdhm;
    let bad = || line.err(field, ParseErrorKind::BadDate);
    if !(1980..=2200).contains(&y)
        || !(1..=12).contains(&mo)
        || !(1..=31).contains(&d)
        || h > 23
        || mi > 59
    {
        return Err(bad());
    }
    if !(0.0..61.0).contains(&second) {
        return Err(bad());
    }
    let days = days_from_civil(y as i32, mo, d) - days_from_civil(1980, 1, 6);
    let whole = second.floor();
    let ns = days * NS_PER_DAY
        + ((h as i64 * 60 + mi as i64) * 60 + whole as i64) * NS_PER_S
        + ((second - whole) * 1e9).round() as i64;
    Ok(GpsTime::from_ns(ns))
}
