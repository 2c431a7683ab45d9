//! Time scales: GPS, TAI, UTC (leap-second table), TT, UT1 = UTC + DUT1.
//!
//! Every instant in Sextant is a [`GpsTime`]: integer nanoseconds since the GPS epoch
//! 1980-01-06T00:00:00 UTC, counted in the GPS time scale (no leap seconds). The other scales
//! are derived from it exactly to the nanosecond:
//!
//! | scale | relation |
//! |---|---|
//! | TAI | TAI = GPS + 19 s |
//! | TT  | TT = TAI + 32.184 s = GPS + 51.184 s |
//! | UTC | UTC = TAI − ΔAT, ΔAT = TAI − UTC from [`LEAP_SECONDS`] |
//! | UT1 | UT1 = UTC + DUT1, DUT1 from configuration (IERS Bulletin A) |
//!
//! # Leap seconds — this table must be maintained
//! [`LEAP_SECONDS`] holds every leap second from 1972 to the last one announced at the time of
//! writing, 2017-01-01 (TAI − UTC = 37 s). IERS Bulletin C announces new ones about six months
//! ahead; **a new leap second must be appended to [`LEAP_SECONDS`]** or UTC (and UT1 computed
//! from UTC) will be off by one second after it. GPS, TAI and TT do not depend on the table.
//! Before 1972-01-01 (the era of "rubber" UTC) ΔAT is clamped to 10 s: such dates are not
//! supported for UTC work.
//!
//! # Why hand-written rather than `hifitime`
//! The table is 28 lines and the arithmetic is a few integer divisions. `hifitime` is well kept,
//! but it brings its own epoch/duration types (centuries + ns), parsing, formatting and several
//! transitive dependencies into a crate that must stay small, allocation-free and bit-exact
//! across live and offline runs. Integer nanoseconds in `i64` (±292 years around 1980) cover the
//! mission, and every conversion here is exact integer arithmetic except the final split of a
//! Julian date into two `f64` parts.
//!
//! # Julian dates
//! [`GpsTime::tt_jd`] and [`GpsTime::ut1_jd`] return two-part Julian dates in the ERFA/SOFA
//! "date and time" convention: `jd1` is the Julian date of the preceding midnight (an exact
//! `xxxxxxx.5` value) and `jd2 ∈ [0, 1)` the fraction of day, so that no precision is lost
//! (`jd2` resolves ~1e-11 s).

/// GPS time as integer nanoseconds since the GPS epoch 1980-01-06T00:00:00 UTC.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct GpsTime {
    /// Nanoseconds since the GPS epoch.
    pub ns: i64,
}

/// A signed span of time in integer nanoseconds: the difference of two [`GpsTime`]s (GPS, TAI
/// and TT seconds are the same length, so it is a span in any of them).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Duration {
    /// Nanoseconds.
    pub ns: i64,
}

impl Duration {
    /// No time.
    pub const ZERO: Self = Self { ns: 0 };

    /// A span of `ns` nanoseconds.
    pub const fn from_ns(ns: i64) -> Self {
        Self { ns }
    }

    /// A span of a whole number of seconds.
    pub const fn from_seconds(s: i64) -> Self {
        Self { ns: s * NS_PER_S }
    }

    /// A span of `s` seconds, truncated toward zero to whole nanoseconds (Rust's `as i64`:
    /// saturating at the `i64` bounds, NaN gives zero). Truncation rather than rounding keeps
    /// spans configured in seconds (buffer windows, minimum intervals) at or below the
    /// configured value.
    pub fn from_seconds_f64(s: f64) -> Self {
        Self {
            ns: (s * 1e9) as i64,
        }
    }

    /// The span in seconds (`ns · 10⁻⁹`; exact below 2⁵³ ns ≈ 104 days).
    pub fn seconds_f64(self) -> f64 {
        self.ns as f64 * 1e-9
    }

    /// The absolute value.
    pub const fn abs(self) -> Self {
        Self { ns: self.ns.abs() }
    }
}

impl core::ops::Sub for GpsTime {
    type Output = Duration;
    /// The span from `rhs` to `self`.
    fn sub(self, rhs: GpsTime) -> Duration {
        Duration {
            ns: self.ns - rhs.ns,
        }
    }
}

impl core::ops::Add<Duration> for GpsTime {
    type Output = GpsTime;
    fn add(self, d: Duration) -> GpsTime {
        GpsTime { ns: self.ns + d.ns }
    }
}

impl core::ops::Sub<Duration> for GpsTime {
    type Output = GpsTime;
    fn sub(self, d: Duration) -> GpsTime {
        GpsTime { ns: self.ns - d.ns }
    }
}

impl core::ops::Add for Duration {
    type Output = Duration;
    fn add(self, d: Duration) -> Duration {
        Duration { ns: self.ns + d.ns }
    }
}

impl core::ops::Sub for Duration {
    type Output = Duration;
    fn sub(self, d: Duration) -> Duration {
        Duration { ns: self.ns - d.ns }
    }
}

impl core::ops::Neg for Duration {
    type Output = Duration;
    fn neg(self) -> Duration {
        Duration { ns: -self.ns }
    }
}

/// Nanoseconds per second.
pub const NS_PER_S: i64 = 1_000_000_000;
/// Nanoseconds per day of 86 400 s.
pub const NS_PER_DAY: i64 = 86_400 * NS_PER_S;
/// TAI − GPS, ns (exactly 19 s, fixed since 1980).
pub const TAI_MINUS_GPS_NS: i64 = 19 * NS_PER_S;
/// TT − TAI, ns (exactly 32.184 s).
pub const TT_MINUS_TAI_NS: i64 = 32_184_000_000;
/// Julian date of the GPS epoch 1980-01-06T00:00:00 (as a date in any of the scales).
pub const JD_GPS_EPOCH: f64 = 2_444_244.5;
/// Julian date of J2000.0 (2000-01-01T12:00:00 TT).
pub const JD_J2000: f64 = 2_451_545.0;
/// Days from 1970-01-01 to the GPS epoch date 1980-01-06 (proleptic Gregorian).
const GPS_EPOCH_DAYS_FROM_1970: i64 = 3657;
/// Unix time of the GPS epoch 1980-01-06T00:00:00 UTC, ns (3657 days after 1970-01-01).
pub const GPS_EPOCH_UNIX_NS: i64 = GPS_EPOCH_DAYS_FROM_1970 * NS_PER_DAY;
/// TAI nanoseconds from 1958-01-01T00:00:00 TAI to the GPS epoch (8040 days + 19 s).
const TAI1958_AT_GPS_EPOCH_NS: i64 = 8040 * NS_PER_DAY + TAI_MINUS_GPS_NS;
/// TT nanoseconds from J2000.0 TT back to the GPS epoch: the GPS epoch is 7300.5 days minus
/// 51.184 s before J2000.0 TT.
const TT_J2000_AT_GPS_EPOCH_NS: i64 =
    TAI_MINUS_GPS_NS + TT_MINUS_TAI_NS - 7300 * NS_PER_DAY - NS_PER_DAY / 2;

/// One step of UTC: from 00:00:00 UTC of (`year`, `month`, 1) on, TAI − UTC = `tai_minus_utc_s`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LeapSecond {
    /// Year (UTC) the value takes effect.
    pub year: i32,
    /// Month (1–12, UTC); always the first day of that month at 00:00:00 UTC.
    pub month: u32,
    /// TAI − UTC from that instant on, s.
    pub tai_minus_utc_s: i32,
}

const fn ls(year: i32, month: u32, tai_minus_utc_s: i32) -> LeapSecond {
    LeapSecond {
        year,
        month,
        tai_minus_utc_s,
    }
}

/// TAI − UTC since 1972 (IERS Bulletin C). **Append new leap seconds here** when announced.
/// The last one at the time of writing is 2017-01-01 (37 s).
pub const LEAP_SECONDS: [LeapSecond; 28] = [
    ls(1972, 1, 10),
    ls(1972, 7, 11),
    ls(1973, 1, 12),
    ls(1974, 1, 13),
    ls(1975, 1, 14),
    ls(1976, 1, 15),
    ls(1977, 1, 16),
    ls(1978, 1, 17),
    ls(1979, 1, 18),
    ls(1980, 1, 19),
    ls(1981, 7, 20),
    ls(1982, 7, 21),
    ls(1983, 7, 22),
    ls(1985, 7, 23),
    ls(1988, 1, 24),
    ls(1990, 1, 25),
    ls(1991, 1, 26),
    ls(1992, 7, 27),
    ls(1993, 7, 28),
    ls(1994, 7, 29),
    ls(1996, 1, 30),
    ls(1997, 7, 31),
    ls(1999, 1, 32),
    ls(2006, 1, 33),
    ls(2009, 1, 34),
    ls(2012, 7, 35),
    ls(2015, 7, 36),
    ls(2017, 1, 37),
];

/// A UTC calendar instant, exact to the nanosecond. `second` is 60 during a leap second.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct UtcDateTime {
    /// Year (proleptic Gregorian).
    pub year: i32,
    /// Month, 1–12.
    pub month: u32,
    /// Day of month, 1–31.
    pub day: u32,
    /// Hour, 0–23.
    pub hour: u32,
    /// Minute, 0–59.
    pub minute: u32,
    /// Second, 0–59 (60 inside a leap second).
    pub second: u32,
    /// Nanoseconds within the second, 0–999 999 999.
    pub nanosecond: u32,
}

impl UtcDateTime {
    /// Seconds of the minute including the fraction (`second + nanosecond·1e-9`).
    pub fn seconds_f64(&self) -> f64 {
        self.second as f64 + self.nanosecond as f64 * 1e-9
    }
}

/// Days since 1970-01-01 of a proleptic Gregorian date (H. Hinnant's `days_from_civil`).
/// Month and day may be out of their usual range only as far as the algorithm tolerates;
/// callers pass valid dates.
pub const fn days_from_civil(year: i32, month: u32, day: u32) -> i64 {
    let y = if month <= 2 {
        year as i64 - 1
    } else {
        year as i64
    };
    let era = y.div_euclid(400);
    let yoe = y - era * 400; // [0, 399]
    let m = month as i64;
    let mp = if m > 2 { m - 3 } else { m + 9 }; // [0, 11]
    let doy = (153 * mp + 2) / 5 + day as i64 - 1; // [0, 365]
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy; // [0, 146096]
    era * 146_097 + doe - 719_468
}

/// Proleptic Gregorian (year, month, day) of a count of days since 1970-01-01.
pub const fn civil_from_days(days: i64) -> (i32, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let y = if m <= 2 { y + 1 } else { y };
    (y as i32, m, d)
}

/// Days since the GPS epoch date (1980-01-06) of a leap-second table entry.
const fn leap_day(l: &LeapSecond) -> i64 {
    days_from_civil(l.year, l.month, 1) - GPS_EPOCH_DAYS_FROM_1970
}

/// TAI − UTC (s) in force during the UTC day `day` (days since 1980-01-06).
fn tai_minus_utc_for_utc_day(day: i64) -> i64 {
    let mut dat = LEAP_SECONDS[0].tai_minus_utc_s as i64;
    for l in LEAP_SECONDS.iter() {
        if day >= leap_day(l) {
            dat = l.tai_minus_utc_s as i64;
        } else {
            break;
        }
    }
    dat
}

/// GPS ns at which the table entry takes effect (00:00:00 UTC of its date).
const fn leap_gps_ns(l: &LeapSecond) -> i64 {
    leap_day(l) * NS_PER_DAY + (l.tai_minus_utc_s as i64) * NS_PER_S - TAI_MINUS_GPS_NS
}

/// [`leap_gps_ns`] of every entry of [`LEAP_SECONDS`], computed once at build time (the
/// recorder converts every message's time through the table).
const LEAP_GPS_NS: [i64; LEAP_SECONDS.len()] = {
    let mut at = [0; LEAP_SECONDS.len()];
    let mut i = 0;
    while i < at.len() {
        at[i] = leap_gps_ns(&LEAP_SECONDS[i]);
        i += 1;
    }
    at
};

/// Round a finite `f64` number of seconds to integer nanoseconds.
fn seconds_to_ns(s: f64) -> i64 {
    (s * 1e9).round() as i64
}

impl GpsTime {
    /// The GPS epoch, 1980-01-06T00:00:00 UTC.
    pub const EPOCH: GpsTime = GpsTime { ns: 0 };

    /// GPS time from nanoseconds since the GPS epoch.
    pub const fn from_ns(ns: i64) -> Self {
        Self { ns }
    }

    /// GPS time of a UTC calendar instant (leap seconds applied). `second` may be in [60, 61)
    /// inside a leap second; it is rounded to the nearest nanosecond. For exact input use
    /// [`GpsTime::from_utc_ns`].
    pub fn from_utc(year: i32, month: u32, day: u32, hour: u32, minute: u32, second: f64) -> Self {
        let whole = second.floor();
        let frac_ns = seconds_to_ns(second - whole);
        let s = Self::from_utc_ns(year, month, day, hour, minute, whole as u32, 0);
        Self { ns: s.ns + frac_ns }
    }

    /// GPS time of a UTC calendar instant given to the nanosecond (`second` = 60 inside a
    /// leap second). Fields out of their range are not rejected, they simply add up
    /// (e.g. minute 60 = next hour), except that the leap-second offset is taken from the date.
    pub fn from_utc_ns(
        year: i32,
        month: u32,
        day: u32,
        hour: u32,
        minute: u32,
        second: u32,
        nanosecond: u32,
    ) -> Self {
        let d = days_from_civil(year, month, day) - GPS_EPOCH_DAYS_FROM_1970;
        let tod_ns = ((hour as i64 * 60 + minute as i64) * 60 + second as i64) * NS_PER_S
            + nanosecond as i64;
        let dat = tai_minus_utc_for_utc_day(d);
        Self {
            ns: d * NS_PER_DAY + tod_ns + dat * NS_PER_S - TAI_MINUS_GPS_NS,
        }
    }

    /// GPS time of a [`UtcDateTime`].
    pub fn from_utc_datetime(u: &UtcDateTime) -> Self {
        Self::from_utc_ns(
            u.year,
            u.month,
            u.day,
            u.hour,
            u.minute,
            u.second,
            u.nanosecond,
        )
    }

    /// UTC calendar instant of this GPS time (second = 60 inside a leap second).
    pub fn to_utc(&self) -> UtcDateTime {
        // Find the entry in force and whether we sit inside the leap second just before it.
        let mut dat = LEAP_SECONDS[0].tai_minus_utc_s as i64;
        let mut in_leap = false;
        for l in LEAP_SECONDS.iter() {
            let g = leap_gps_ns(l);
            if self.ns >= g {
                dat = l.tai_minus_utc_s as i64;
            } else {
                let step = l.tai_minus_utc_s as i64 - dat;
                if step > 0 && self.ns >= g - step * NS_PER_S {
                    in_leap = true;
                }
                break;
            }
        }
        let u = self.ns + TAI_MINUS_GPS_NS - dat * NS_PER_S; // UTC ns, leap seconds not counted
        let (mut days, mut tod) = (u.div_euclid(NS_PER_DAY), u.rem_euclid(NS_PER_DAY));
        if in_leap {
            // u is in the first second of the next day: show it as 23:59:60 of the day before.
            days -= 1;
            tod += NS_PER_DAY;
        }
        let (year, month, day) = civil_from_days(days + GPS_EPOCH_DAYS_FROM_1970);
        let secs = tod.div_euclid(NS_PER_S);
        let nanosecond = tod.rem_euclid(NS_PER_S) as u32;
        let (hour, minute, second) = if in_leap {
            (23, 59, (secs - 86_340) as u32)
        } else {
            (
                (secs / 3600) as u32,
                ((secs / 60) % 60) as u32,
                (secs % 60) as u32,
            )
        };
        UtcDateTime {
            year,
            month,
            day,
            hour,
            minute,
            second,
            nanosecond,
        }
    }

    /// TAI − UTC (s) in force at this instant (during a leap second, the old value).
    pub fn tai_minus_utc_s(&self) -> i32 {
        // From the latest entry back: a time of today is past the first one looked at.
        LEAP_GPS_NS
            .iter()
            .rposition(|&at| self.ns >= at)
            .map_or(LEAP_SECONDS[0].tai_minus_utc_s, |i| {
                LEAP_SECONDS[i].tai_minus_utc_s
            })
    }

    /// TAI as nanoseconds since 1958-01-01T00:00:00 TAI.
    pub const fn tai_ns(&self) -> i64 {
        self.ns + TAI1958_AT_GPS_EPOCH_NS
    }

    /// GPS time from TAI nanoseconds since 1958-01-01T00:00:00 TAI.
    pub const fn from_tai_ns(tai_ns: i64) -> Self {
        Self {
            ns: tai_ns - TAI1958_AT_GPS_EPOCH_NS,
        }
    }

    /// TT as nanoseconds since J2000.0 (2000-01-01T12:00:00 TT).
    pub const fn tt_ns(&self) -> i64 {
        self.ns + TT_J2000_AT_GPS_EPOCH_NS
    }

    /// GPS time from TT nanoseconds since J2000.0 (2000-01-01T12:00:00 TT).
    pub const fn from_tt_ns(tt_ns: i64) -> Self {
        Self {
            ns: tt_ns - TT_J2000_AT_GPS_EPOCH_NS,
        }
    }

    /// UTC as nanoseconds since 1980-01-06T00:00:00 UTC, not counting leap seconds (each UTC
    /// day is 86 400 s; during a leap second this value repeats the first second of the next
    /// day, as POSIX time does).
    pub fn utc_ns(&self) -> i64 {
        self.ns + TAI_MINUS_GPS_NS - self.tai_minus_utc_s() as i64 * NS_PER_S
    }

    /// Unix time (POSIX: nanoseconds since 1970-01-01T00:00:00 UTC, leap seconds not counted)
    /// of this instant, the time base of MCAP `log_time` and Foxglove `time`. During a leap
    /// second the value repeats the first second of the next day, as POSIX time does (see
    /// [`GpsTime::utc_ns`]). Saturates at the ends of `i64` instead of overflowing.
    pub fn unix_ns(&self) -> i64 {
        self.ns
            .saturating_add(TAI_MINUS_GPS_NS - self.tai_minus_utc_s() as i64 * NS_PER_S)
            .saturating_add(GPS_EPOCH_UNIX_NS)
    }

    /// Julian centuries of TT since J2000.0 (single `f64`, for series arguments).
    pub fn tt_centuries(&self) -> f64 {
        let (a, b) = self.tt_jd();
        ((a - JD_J2000) + b) / 36_525.0
    }

    /// TT as a two-part Julian date (ERFA convention: jd1 + jd2, jd1 = the JD of the preceding
    /// TT midnight, jd2 ∈ [0, 1) the fraction of day).
    pub fn tt_jd(&self) -> (f64, f64) {
        split_jd(self.ns + TAI_MINUS_GPS_NS + TT_MINUS_TAI_NS, 0.0)
    }

    /// UT1 as a two-part Julian date, given DUT1 = UT1 − UTC in seconds (ERFA convention:
    /// jd1 = the JD of a UT1 midnight, jd2 the fraction of day, in [0, 1) unless DUT1 pushes
    /// it just outside). During a leap second UTC is taken as continuous (the old ΔAT holds
    /// until the leap second ends); DUT1 itself jumps by 1 s at a leap second.
    pub fn ut1_jd(&self, dut1_s: f64) -> (f64, f64) {
        split_jd(self.utc_ns_continuous(), dut1_s)
    }

    /// UTC ns since the GPS epoch date with ΔAT stepping at the end of a leap second (i.e.
    /// TAI − ΔAT(t)); continuous except for a 1 s step back at each leap second.
    fn utc_ns_continuous(&self) -> i64 {
        self.ns + TAI_MINUS_GPS_NS - self.tai_minus_utc_s() as i64 * NS_PER_S
    }

    /// Seconds from `earlier` to `self` (GPS/TAI/TT seconds are the same length).
    pub fn seconds_since(&self, earlier: GpsTime) -> f64 {
        (*self - earlier).seconds_f64()
    }

    /// The span from `earlier` to `self`, clamped to the range of [`Duration`] instead of
    /// overflowing (for comparing corrupt time stamps, which may lie anywhere in `i64`).
    pub const fn saturating_since(&self, earlier: GpsTime) -> Duration {
        Duration {
            ns: self.ns.saturating_sub(earlier.ns),
        }
    }

    /// This time plus `ns` nanoseconds.
    pub const fn add_ns(&self, ns: i64) -> Self {
        Self { ns: self.ns + ns }
    }
}

/// Two-part JD of `ns` nanoseconds after the date JD_GPS_EPOCH of some scale, plus `extra_s`.
fn split_jd(ns: i64, extra_s: f64) -> (f64, f64) {
    let days = ns.div_euclid(NS_PER_DAY);
    let rem = ns.rem_euclid(NS_PER_DAY);
    let jd1 = JD_GPS_EPOCH + days as f64;
    let jd2 = (rem as f64 + extra_s * 1e9) / NS_PER_DAY as f64;
    (jd1, jd2)
}

#[cfg(test)]
mod tests {
    #[test]
    fn unix_time_counts_leap_seconds_out() {
        // 2025-03-20T21:00:00Z is Unix 1742504400 s (date -d @1742504400 -u); GPS is 18 s ahead
        // of UTC since 2017.
        let t = super::GpsTime::from_utc(2025, 3, 20, 21, 0, 0.0);
        assert_eq!(t.unix_ns(), 1_742_504_400 * super::NS_PER_S);
        // The GPS epoch itself: Unix 315964800 s.
        assert_eq!(
            super::GpsTime::from_ns(0).unix_ns(),
            315_964_800 * super::NS_PER_S
        );
        // No overflow at the ends of the range.
        assert!(super::GpsTime::from_ns(i64::MAX).unix_ns() > 0);
    }

    use super::*;
    use proptest::prelude::*;

    #[test]
    fn durations_are_differences_of_times() {
        let t0 = GpsTime::from_ns(1_000);
        let t1 = GpsTime::from_ns(2_500_000_001_000);
        let d = t1 - t0;
        assert_eq!(d, Duration::from_ns(2_500_000_000_000));
        assert_eq!(t0 + d, t1);
        assert_eq!(t1 - d, t0);
        assert_eq!(t0 - t1, -d);
        assert_eq!((-d).abs(), d);
        assert_eq!(d.seconds_f64(), t1.seconds_since(t0));
        assert_eq!(Duration::from_seconds(3).seconds_f64(), 3.0);
        // Truncation toward zero, as `as i64`: −1.5 ns is −1 ns, not −2.
        assert_eq!(Duration::from_seconds_f64(0.3).ns, 300_000_000);
        assert_eq!(Duration::from_seconds_f64(-1.5e-9).ns, -1);
        assert_eq!(Duration::from_seconds_f64(f64::NAN), Duration::ZERO);
        // Corrupt time stamps anywhere in i64 compare without overflow.
        let far = GpsTime::from_ns(i64::MAX);
        assert_eq!(far.saturating_since(GpsTime::from_ns(-1)).ns, i64::MAX);
        assert_eq!(GpsTime::EPOCH.saturating_since(far).ns, -i64::MAX);
    }

    #[test]
    fn gps_epoch_is_zero() {
        assert_eq!(GpsTime::from_utc(1980, 1, 6, 0, 0, 0.0).ns, 0);
        let u = GpsTime::from_ns(0).to_utc();
        assert_eq!(
            (u.year, u.month, u.day, u.hour, u.minute, u.second),
            (1980, 1, 6, 0, 0, 0)
        );
    }

    #[test]
    fn tt_minus_tai() {
        // J2000.0 TT = 2000-01-01T11:59:27.816 TAI = 2000-01-01T11:58:55.816 UTC.
        let days_1958_2000 = days_from_civil(2000, 1, 1) - days_from_civil(1958, 1, 1);
        let j2000 = GpsTime::from_utc_ns(2000, 1, 1, 11, 58, 55, 816_000_000);
        assert_eq!(j2000.tt_ns(), 0);
        assert_eq!(
            j2000.tai_ns(),
            days_1958_2000 * NS_PER_DAY + 43_200 * NS_PER_S - TT_MINUS_TAI_NS
        );
        assert_eq!(TT_MINUS_TAI_NS, 32_184_000_000);
        let (a, b) = j2000.tt_jd();
        assert_eq!(a + b, JD_J2000);
        // TAI − GPS = 19 s.
        assert_eq!(
            GpsTime::from_ns(0).tai_ns(),
            8040 * NS_PER_DAY + 19 * NS_PER_S
        );
        assert_eq!(
            days_from_civil(1980, 1, 6) - days_from_civil(1958, 1, 1),
            8040
        );
    }

    #[test]
    fn leap_second_2017() {
        let before = GpsTime::from_utc(2016, 12, 31, 23, 59, 59.0);
        let after = GpsTime::from_utc(2017, 1, 1, 0, 0, 0.0);
        assert_eq!(after.ns - before.ns, 2 * NS_PER_S);
        let leap = GpsTime::from_utc(2016, 12, 31, 23, 59, 60.5);
        assert_eq!(leap.ns - before.ns, 1_500_000_000);
        let u = leap.to_utc();
        assert_eq!(
            (u.day, u.hour, u.minute, u.second, u.nanosecond),
            (31, 23, 59, 60, 500_000_000)
        );
        assert_eq!(before.tai_minus_utc_s(), 36);
        assert_eq!(after.tai_minus_utc_s(), 37);
        // Known value: GPS − UTC = 18 s after 2017-01-01.
        let n = days_from_civil(2017, 1, 1) - GPS_EPOCH_DAYS_FROM_1970;
        assert_eq!(after.ns, n * NS_PER_DAY + 18 * NS_PER_S);
    }

    #[test]
    fn every_leap_second_round_trips() {
        for w in LEAP_SECONDS.windows(2) {
            let l = w[1];
            let (y, m, d) = civil_from_days(days_from_civil(l.year, l.month, 1) - 1);
            let s59 = GpsTime::from_utc_ns(y, m, d, 23, 59, 59, 0);
            let s60 = GpsTime::from_utc_ns(y, m, d, 23, 59, 60, 999_999_999);
            let s00 = GpsTime::from_utc_ns(l.year, l.month, 1, 0, 0, 0, 0);
            assert_eq!(s00.ns - s59.ns, 2 * NS_PER_S, "{l:?}");
            assert_eq!(s00.ns - s60.ns, 1);
            for t in [s59, s60, s00] {
                assert_eq!(GpsTime::from_utc_datetime(&t.to_utc()), t);
            }
            assert_eq!(s60.to_utc().second, 60);
            assert_eq!(s00.to_utc().second, 0);
        }
    }

    #[test]
    fn julian_dates() {
        // 2017-01-01T00:00:00 UTC: TT = UTC + 69.184 s.
        let t = GpsTime::from_utc(2017, 1, 1, 0, 0, 0.0);
        let (a, b) = t.tt_jd();
        assert_eq!(a, 2_457_754.5);
        assert!((b * 86_400.0 - 69.184).abs() < 1e-9);
        let (a, b) = t.ut1_jd(0.4);
        assert_eq!(a, 2_457_754.5);
        assert!((b * 86_400.0 - 0.4).abs() < 1e-9);
        assert_eq!(GpsTime::from_tai_ns(t.tai_ns()), t);
        assert_eq!(GpsTime::from_tt_ns(t.tt_ns()), t);
    }

    #[test]
    fn calendar_algorithms() {
        assert_eq!(days_from_civil(1970, 1, 1), 0);
        assert_eq!(days_from_civil(1980, 1, 6), GPS_EPOCH_DAYS_FROM_1970);
        assert_eq!(civil_from_days(days_from_civil(2000, 2, 29)), (2000, 2, 29));
        assert_eq!(
            civil_from_days(days_from_civil(2100, 3, 1) - 1),
            (2100, 2, 28)
        );
    }

    proptest! {
        #[test]
        fn gps_utc_gps_round_trip(ns in -250_000_000_000_000_000i64..4_000_000_000_000_000_000i64) {
            let t = GpsTime::from_ns(ns);
            prop_assert_eq!(GpsTime::from_utc_datetime(&t.to_utc()), t);
        }

        #[test]
        fn utc_gps_utc_round_trip(days in 0i64..30_000, tod in 0i64..NS_PER_DAY) {
            let (y, m, d) = civil_from_days(days);
            let s = tod / NS_PER_S;
            let u = UtcDateTime {
                year: y, month: m, day: d,
                hour: (s / 3600) as u32, minute: ((s / 60) % 60) as u32, second: (s % 60) as u32,
                nanosecond: (tod % NS_PER_S) as u32,
            };
            prop_assert_eq!(GpsTime::from_utc_datetime(&u).to_utc(), u);
        }

        #[test]
        fn tai_tt_round_trip(ns in -4_000_000_000_000_000_000i64..4_000_000_000_000_000_000i64) {
            let t = GpsTime::from_ns(ns);
            prop_assert_eq!(GpsTime::from_tai_ns(t.tai_ns()), t);
            prop_assert_eq!(GpsTime::from_tt_ns(t.tt_ns()), t);
            prop_assert_eq!(t.tt_ns() - t.tai_ns(), TT_J2000_AT_GPS_EPOCH_NS - TAI1958_AT_GPS_EPOCH_NS);
        }

        #[test]
        fn jd_parts_keep_precision(ns in 0i64..2_500_000_000_000_000_000i64) {
            let t = GpsTime::from_ns(ns);
            let (a, b) = t.tt_jd();
            prop_assert!((0.0..1.0).contains(&b));
            prop_assert_eq!(a.fract(), 0.5);
            let back_ns = ((a - JD_GPS_EPOCH) * 86_400.0) as i64 * NS_PER_S
                + (b * NS_PER_DAY as f64).round() as i64;
            prop_assert!((back_ns - t.ns - TAI_MINUS_GPS_NS - TT_MINUS_TAI_NS).abs() <= 10);
        }
    }
}

/// Parse a UTC instant written `YYYY-MM-DDTHH:MM:SS[.fffffffff][Z]` (ISO 8601; a space may
/// replace the `T`; at most nine decimals, read exactly). `None` unless it names a real
/// instant of years 1980–2100: month 1–12, the day within its month, hour 0–23, minute 0–59,
/// second 0–60 (60 inside a leap second).
pub fn parse_utc(s: &str) -> Option<UtcDateTime> {
    fn digits<T: core::str::FromStr>(s: &str) -> Option<T> {
        if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        s.parse().ok()
    }
    let s = s.trim();
    let s = s.strip_suffix('Z').unwrap_or(s);
    let (date, time) = s.split_once(['T', ' '])?;
    let mut d = date.split('-');
    let (year, month, day) = (d.next()?, d.next()?, d.next()?);
    let mut t = time.split(':');
    let (hour, minute, second) = (t.next()?, t.next()?, t.next()?);
    if d.next().is_some() || t.next().is_some() {
        return None;
    }
    let (second, fraction) = second.split_once('.').unwrap_or((second, ""));
    if fraction.len() > 9 || (!fraction.is_empty() && digits::<u32>(fraction).is_none()) {
        return None;
    }
    let nanosecond = fraction
        .bytes()
        .chain(core::iter::repeat(b'0'))
        .take(9)
        .fold(0u32, |n, b| n * 10 + u32::from(b - b'0'));
    let u = UtcDateTime {
        year: digits(year)?,
        month: digits(month)?,
        day: digits(day)?,
        hour: digits(hour)?,
        minute: digits(minute)?,
        second: digits(second)?,
        nanosecond,
    };
    // The day exists when it survives the round trip through the day count.
    let real_day = (1..=12).contains(&u.month)
        && u.day >= 1
        && civil_from_days(days_from_civil(u.year, u.month, u.day)) == (u.year, u.month, u.day);
    let valid = (1980..=2100).contains(&u.year)
        && real_day
        && u.hour <= 23
        && u.minute <= 59
        && u.second <= 60;
    valid.then_some(u)
}

#[cfg(test)]
mod parse_utc_tests {
    use super::*;

    #[test]
    fn instants_parse_exactly_and_nonsense_is_refused() {
        let u = parse_utc("2025-03-20T21:00:00").unwrap();
        assert_eq!(
            GpsTime::from_utc_datetime(&u),
            GpsTime::from_utc(2025, 3, 20, 21, 0, 0.0)
        );
        assert_eq!(
            parse_utc(" 2024-02-29 12:30:05.25Z").unwrap().nanosecond,
            250_000_000
        );
        assert_eq!(
            parse_utc("2016-12-31T23:59:60.123456789").unwrap(),
            UtcDateTime {
                year: 2016,
                month: 12,
                day: 31,
                hour: 23,
                minute: 59,
                second: 60,
                nanosecond: 123_456_789,
            }
        );
        for bad in [
            "2025-13-20T21:00:00",
            "2025-13-45T99:00:00",
            "2023-02-29T00:00:00",
            "2025-04-31T00:00:00",
            "1979-12-31T23:59:59",
            "2025-03-20T24:00:00",
            "2025-03-20T21:60:00",
            "2025-03-20T21:00:61",
            "2025-03-20T21:00:00.1234567891",
            "2025-03-20T21:00:-1",
            "2025-03-20T21:00",
            "2025-03-20",
            "2025-03-20T21:00:00:00",
            "yesterday",
            "",
        ] {
            assert_eq!(parse_utc(bad), None, "{bad}");
        }
    }
}
