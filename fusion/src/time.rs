//! Time scales: GPS, TAI, UTC (leap-second table), TT, UT1 = UTC + DUT1.
//!
//! OWNER: time/celestial helper. Signatures are the contract.

/// GPS time as integer nanoseconds since the GPS epoch 1980-01-06T00:00:00 UTC.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct GpsTime {
    /// Nanoseconds since the GPS epoch.
    pub ns: i64,
}

impl GpsTime {
    /// GPS time of a UTC calendar instant (leap seconds applied).
    pub fn from_utc(year: i32, month: u32, day: u32, hour: u32, minute: u32, second: f64) -> Self {
        let _ = (year, month, day, hour, minute, second);
        unimplemented!("time helper")
    }
    /// TT as a two-part Julian date (ERFA convention: jd1 + jd2).
    pub fn tt_jd(&self) -> (f64, f64) {
        unimplemented!("time helper")
    }
    /// UT1 as a two-part Julian date, given DUT1 = UT1 − UTC in seconds.
    pub fn ut1_jd(&self, dut1_s: f64) -> (f64, f64) {
        let _ = dut1_s;
        unimplemented!("time helper")
    }
}
