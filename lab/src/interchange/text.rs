//! What the text formats share: errors that name the file, line and column; exact decimal
//! seconds; GPS week bookkeeping; numbers written so that they read back bit for bit.

use fusion::time::{GpsTime, NS_PER_DAY, NS_PER_S, civil_from_days};
use std::path::{Path, PathBuf};

/// Seconds in a GPS week.
pub const SECONDS_PER_WEEK: i64 = 604_800;
/// Nanoseconds in a GPS week.
pub const NS_PER_WEEK: i64 = SECONDS_PER_WEEK * NS_PER_S;

/// A value of a text file that cannot be read: where (file, 1-based line, 1-based column =
/// field number of the row) and what.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{}: line {line}, column {column}: {message}", path.display())]
pub struct TextError {
    /// The file.
    pub path: PathBuf,
    /// Line number, from 1.
    pub line: u64,
    /// Field (column) number within the row, from 1; 0 when the whole line is at fault.
    pub column: usize,
    /// What is wrong.
    pub message: String,
}

impl TextError {
    /// An error at `line`, `column` of `path`.
    pub fn new(path: &Path, line: u64, column: usize, message: impl Into<String>) -> Self {
        Self {
            path: path.to_path_buf(),
            line,
            column,
            message: message.into(),
        }
    }
}

/// A finite number of field `column` (from 1) of `line`, or the error naming them.
pub fn number(path: &Path, line: u64, column: usize, token: &str) -> Result<f64, TextError> {
    match token.trim().parse::<f64>() {
        Ok(x) if x.is_finite() => Ok(x),
        Ok(_) => Err(TextError::new(
            path,
            line,
            column,
            format!("{token:?} is not finite"),
        )),
        Err(_) => Err(TextError::new(
            path,
            line,
            column,
            format!("{token:?} is not a number"),
        )),
    }
}

/// Decimal seconds (`"456300.005"`, `"12"`, `"1.5e3"`) to integer nanoseconds, exactly for
/// plain decimals (the digits are read, not a binary float: `456300.005` is
/// 456 300 005 000 000 ns, which an `f64` of seconds cannot hold), rounded half up beyond the
/// ninth decimal; numbers in exponent form go through `f64` and are rounded to the nanosecond.
/// `None` for anything else, a negative value, or more than 10¹² s.
pub fn parse_seconds_ns(token: &str) -> Option<i64> {
    let s = token.trim();
    let s = s.strip_prefix('+').unwrap_or(s);
    if s.contains(['e', 'E']) {
        let x: f64 = s.parse().ok()?;
        return (x.is_finite() && (0.0..=1e12).contains(&x)).then(|| (x * 1e9).round() as i64);
    }
    let (int, frac) = s.split_once('.').unwrap_or((s, ""));
    if int.is_empty() && frac.is_empty() {
        return None;
    }
    let all_digits = |t: &str| t.bytes().all(|b| b.is_ascii_digit());
    if !all_digits(int) || !all_digits(frac) {
        return None;
    }
    let int = int.trim_start_matches('0');
    if int.len() > 12 {
        return None;
    }
    let whole: i64 = if int.is_empty() { 0 } else { int.parse().ok()? };
    let mut frac_ns = 0i64;
    for k in 0..9 {
        let d = frac.as_bytes().get(k).map_or(0, |b| (b - b'0') as i64);
        frac_ns = frac_ns * 10 + d;
    }
    if frac.as_bytes().get(9).is_some_and(|b| *b >= b'5') {
        frac_ns += 1;
    }
    let ns = whole.checked_mul(NS_PER_S)?.checked_add(frac_ns)?;
    (whole <= 1_000_000_000_000).then_some(ns)
}

/// Nanoseconds as decimal seconds with nine decimals (exact: [`parse_seconds_ns`] reads it
/// back to the same integer).
pub fn format_seconds_ns(ns: i64) -> String {
    let sign = if ns < 0 { "-" } else { "" };
    let a = ns.unsigned_abs();
    format!("{sign}{}.{:09}", a / NS_PER_S as u64, a % NS_PER_S as u64)
}

/// An `f64` as the shortest decimal text that reads back to the same bits (Rust's `Display`
/// and `LowerExp` are shortest-round-trip), in exponent form outside 10⁻⁵ ≤ |x| < 10¹⁶ so
/// that tiny values stay short.
pub fn format_f64(x: f64) -> String {
    let a = x.abs();
    if a == 0.0 || (1e-5..1e16).contains(&a) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// GPS week and seconds of week (ns) of a GPS time.
pub fn week_and_sow_ns(t: GpsTime) -> (i64, i64) {
    (t.ns.div_euclid(NS_PER_WEEK), t.ns.rem_euclid(NS_PER_WEEK))
}

/// Follows the GPS week through a file whose times are seconds of week: the first row's week
/// is given (or the one nearest a reference time), and a time more than half a week before the
/// previous one is taken as a week rollover.
#[derive(Debug, Clone, Copy)]
pub struct WeekTracker {
    week: i64,
    last_sow_ns: Option<i64>,
    reference_ns: Option<i64>,
}

impl WeekTracker {
    /// The first row is in `week`.
    pub fn with_week(week: i64) -> Self {
        Self {
            week,
            last_sow_ns: None,
            reference_ns: None,
        }
    }

    /// The first row is in the week that puts it nearest `reference` (e.g. the first epoch of
    /// a reference trajectory that carries its week).
    pub fn near(reference: GpsTime) -> Self {
        Self {
            week: reference.ns.div_euclid(NS_PER_WEEK),
            last_sow_ns: None,
            reference_ns: Some(reference.ns),
        }
    }

    /// GPS time of the next row's seconds of week (ns).
    pub fn time(&mut self, sow_ns: i64) -> GpsTime {
        match (self.last_sow_ns, self.reference_ns) {
            (None, Some(r)) => {
                let t = self.week * NS_PER_WEEK + sow_ns;
                if t - r > NS_PER_WEEK / 2 {
                    self.week -= 1;
                } else if r - t > NS_PER_WEEK / 2 {
                    self.week += 1;
                }
            }
            (Some(last), _) if last - sow_ns > NS_PER_WEEK / 2 => self.week += 1,
            _ => {}
        }
        self.last_sow_ns = Some(sow_ns);
        GpsTime::from_ns(self.week * NS_PER_WEEK + sow_ns)
    }
}

/// GPS time of a POSIX time (UTC seconds since 1970-01-01 without leap seconds, ns), through
/// fusion's leap-second table.
pub fn gps_from_unix_ns(unix_ns: i64) -> GpsTime {
    let day = unix_ns.div_euclid(NS_PER_DAY);
    let tod = unix_ns.rem_euclid(NS_PER_DAY);
    let (y, m, d) = civil_from_days(day);
    let s = tod / NS_PER_S;
    GpsTime::from_utc_ns(
        y,
        m,
        d,
        (s / 3600) as u32,
        (s / 60 % 60) as u32,
        (s % 60) as u32,
        (tod % NS_PER_S) as u32,
    )
}

/// The POSIX time (ns) of a GPS time: the inverse of [`gps_from_unix_ns`] outside leap
/// seconds.
pub fn unix_ns_from_gps(t: GpsTime) -> i64 {
    let u = t.to_utc();
    let days = fusion::time::days_from_civil(u.year, u.month, u.day);
    days * NS_PER_DAY
        + ((u.hour as i64 * 60 + u.minute as i64) * 60 + u.second as i64) * NS_PER_S
        + u.nanosecond as i64
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn seconds_are_read_exactly() {
        assert_eq!(parse_seconds_ns("456300.005"), Some(456_300_005_000_000));
        assert_eq!(parse_seconds_ns("0.0000000015"), Some(2));
        assert_eq!(parse_seconds_ns("12"), Some(12 * NS_PER_S));
        assert_eq!(parse_seconds_ns(".5"), Some(NS_PER_S / 2));
        assert_eq!(parse_seconds_ns("1.5e3"), Some(1500 * NS_PER_S));
        for bad in ["", ".", "-1", "1.2.3", "abc", "1e999", "99999999999999"] {
            assert_eq!(parse_seconds_ns(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn week_rollover_and_nearest_week() {
        let mut w = WeekTracker::with_week(2000);
        assert_eq!(
            w.time(604_799 * NS_PER_S).ns,
            2000 * NS_PER_WEEK + 604_799 * NS_PER_S
        );
        assert_eq!(w.time(NS_PER_S).ns, 2001 * NS_PER_WEEK + NS_PER_S);
        // A row just before the reference's week boundary belongs to the previous week.
        let r = GpsTime::from_ns(2001 * NS_PER_WEEK + 10 * NS_PER_S);
        let mut w = WeekTracker::near(r);
        assert_eq!(
            w.time(604_790 * NS_PER_S).ns,
            2000 * NS_PER_WEEK + 604_790 * NS_PER_S
        );
    }

    #[test]
    fn unix_time_round_trips_through_gps() {
        // 2020-06-25T00:00:00Z: GPS − UTC = 18 s.
        let unix = 1_593_043_200 * NS_PER_S;
        let g = gps_from_unix_ns(unix);
        assert_eq!(g, GpsTime::from_utc_ns(2020, 6, 25, 0, 0, 0, 0));
        assert_eq!(unix_ns_from_gps(g), unix);
    }

    proptest! {
        #[test]
        fn any_ns_round_trips_through_text(ns in 0i64..1_000_000_000_000_000_000) {
            prop_assert_eq!(parse_seconds_ns(&format_seconds_ns(ns)), Some(ns));
        }

        #[test]
        fn any_f64_round_trips_through_text(x in any::<f64>().prop_filter("finite", |x| x.is_finite())) {
            let back: f64 = format_f64(x).parse().unwrap();
            prop_assert_eq!(back.to_bits(), x.to_bits());
        }

        #[test]
        fn arbitrary_text_never_panics(s in "\\PC{0,40}") {
            let _ = parse_seconds_ns(&s);
            let _ = number(Path::new("f"), 1, 1, &s);
        }
    }
}
