//! One receiver epoch as a [`GnssSample`]: the receiver's own solution and accuracy put on
//! Sextant's time base and frames.
//!
//! - **Time.** UBX: the GPS time of week of NAV-PVT (`iTOW`) in the GPS week found from the
//!   message's UTC date through fusion's leap-second table (the week is the only thing taken
//!   from UTC, so a table one leap second out of date changes nothing), or from RXM-RAWX's
//!   week. NMEA: UTC date and time of day → GPS time through fusion's table.
//! - **Position.** Geodetic latitude, longitude and ellipsoidal height (NMEA: MSL altitude +
//!   geoid separation) → ECEF with fusion's WGS-84 functions.
//! - **Covariance.** Only what the receiver reports, as a NED covariance rotated into ECEF
//!   (`P_e = C_e_n · P_n · C_e_nᵀ`). NAV-PVT: `hAcc` as the 1-σ of north and of east (u-blox
//!   does not say how the horizontal estimate splits; taking it per axis is the conservative
//!   reading), `vAcc` down, `sAcc` on each velocity axis. NMEA: GST's error ellipse (or its
//!   latitude/longitude sigmas) and altitude sigma; without GST, GSA's HDOP and VDOP times a
//!   configured user-equivalent range error (σ_n = σ_e = HDOP·UERE/√2, σ_d = VDOP·UERE).
//!   NMEA reports no velocity accuracy, so its velocity covariance is zero, which the fusion
//!   reads as "velocity not measured".
//! - **Satellites.** RXM-RAWX GPS L1 C/A measurements (else NAV-SAT's GPS satellites) are
//!   recorded with PRN, C/N0, raw pseudorange, Doppler range rate and their sigmas, with
//!   flags 0: UBX gives no satellite positions (they come from broadcast ephemerides, which
//!   this driver does not decode) and its pseudoranges carry the satellite clock and
//!   atmosphere, so they are kept for analysis but are not for the filter's tight coupling.
//!   The fusion runs loosely coupled on this driver's fixes.

use crate::nmea::{Date, Gga, Gsa, Gst, Rmc, TimeOfDay};
use crate::ubx::{GNSS_ID_GPS, NavPvt, NavSat, Rawx};
use fusion::earth::{Geodetic, WGS84, c_e_n, geodetic_to_ecef};
use fusion::time::{GpsTime, NS_PER_S};
use msgs::{GnssSample, GnssSatellite, MAX_SATELLITES, SPEED_OF_LIGHT_M_S};
use nalgebra::{Matrix3, Vector3};

/// Header status bit of a sample made from NMEA sentences (10 ms time resolution, no velocity
/// accuracy, no raw measurements).
pub const STATUS_FROM_NMEA: u32 = 1 << 8;
/// GPS L1 carrier frequency, Hz (IS-GPS-200).
pub const GPS_L1_HZ: f64 = 1_575.42e6;
/// Nanoseconds in a GPS week.
pub const WEEK_NS: i64 = 604_800 * NS_PER_S;

/// Why an epoch gives no sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum EpochError {
    /// No message of the epoch fixes its date (NAV-PVT without a valid UTC date and no
    /// RXM-RAWX week; NMEA before any RMC date).
    #[error("the epoch's date is unknown")]
    Undated,
    /// An NMEA fix without GST sigmas nor GSA DOPs: no accuracy to give it.
    #[error("the fix comes without an accuracy (no GST, no GSA)")]
    NoAccuracy,
}

/// NED covariance → ECEF at (lat, lon), row-major.
fn ned_cov_to_ecef(c: &Matrix3<f64>, p_ned: &Matrix3<f64>) -> [f64; 9] {
    let p = c * p_ned * c.transpose();
    let mut out = [0.0; 9];
    for r in 0..3 {
        for k in 0..3 {
            out[3 * r + k] = p[(r, k)];
        }
    }
    out
}

fn set_fix(
    out: &mut GnssSample,
    g: &Geodetic,
    v_ned: Vector3<f64>,
    p_ned: &Matrix3<f64>,
    v_cov_ned: &Matrix3<f64>,
) {
    let c = c_e_n(g.lat_rad, g.lon_rad);
    let r = geodetic_to_ecef(&WGS84, g);
    let v = c * v_ned;
    out.pos_ecef_m = [r.x, r.y, r.z];
    out.vel_ecef_m_s = [v.x, v.y, v.z];
    out.pos_cov_ecef_m2 = ned_cov_to_ecef(&c, p_ned);
    out.vel_cov_ecef_m2_s2 = ned_cov_to_ecef(&c, v_cov_ned);
    out.fix_valid = 1;
}

/// GPS time of a time of week (ns) in the week closest to `approx_ns`.
fn in_nearest_week(tow_ns: i64, approx_ns: i64) -> i64 {
    let week = approx_ns.div_euclid(WEEK_NS);
    [week - 1, week, week + 1]
        .map(|w| w * WEEK_NS + tow_ns)
        .into_iter()
        .min_by_key(|t| (t - approx_ns).abs())
        .unwrap_or(tow_ns)
}

/// GPS time of a NAV-PVT epoch, ns; `None` without a valid UTC date or RAWX week.
fn ubx_time_ns(pvt: &NavPvt, rawx: Option<&Rawx>) -> Option<i64> {
    let tow_ns = i64::from(pvt.itow_ms) * 1_000_000;
    let (y, mo, d, h, mi, s) = pvt.utc;
    let date_ok = pvt.valid & 0x03 == 0x03
        && (1..=12).contains(&mo)
        && (1..=31).contains(&d)
        && h < 24
        && mi < 60
        && s <= 60
        && y >= 1980;
    if date_ok {
        let approx = GpsTime::from_utc_ns(
            i32::from(y),
            u32::from(mo),
            u32::from(d),
            u32::from(h),
            u32::from(mi),
            u32::from(s),
            0,
        )
        .ns + i64::from(pvt.utc_nano_ns);
        return Some(in_nearest_week(tow_ns, approx));
    }
    rawx.map(|r| in_nearest_week(tow_ns, rawx_time_ns(r)))
}

/// GPS time of an RXM-RAWX epoch (receiver time), ns.
fn rawx_time_ns(r: &Rawx) -> i64 {
    i64::from(r.week) * WEEK_NS + (r.rcv_tow_s * 1e9).round() as i64
}

fn satellites_from(out: &mut GnssSample, sat: Option<&NavSat>, rawx: Option<&Rawx>) {
    let wavelength = SPEED_OF_LIGHT_M_S / GPS_L1_HZ;
    let mut n = 0;
    if let Some(r) = rawx {
        for m in r
            .meas
            .iter()
            .filter(|m| m.gnss_id == GNSS_ID_GPS && m.sig_id == 0 && m.trk_stat & 1 != 0)
        {
            if n == MAX_SATELLITES {
                break;
            }
            out.satellites[n] = GnssSatellite {
                prn: u32::from(m.sv_id),
                flags: 0,
                pseudorange_m: m.pr_m,
                range_rate_m_s: -m.doppler_hz * wavelength,
                cn0_dbhz: m.cn0_dbhz,
                sigma_pseudorange_m: m.pr_stdev_m,
                sigma_range_rate_m_s: m.doppler_stdev_hz * wavelength,
                ..GnssSatellite::default()
            };
            n += 1;
        }
    } else if let Some(s) = sat {
        for sv in s
            .svs
            .iter()
            .filter(|sv| sv.gnss_id == GNSS_ID_GPS && sv.cn0_dbhz > 0.0)
        {
            if n == MAX_SATELLITES {
                break;
            }
            out.satellites[n] = GnssSatellite {
                prn: u32::from(sv.sv_id),
                cn0_dbhz: sv.cn0_dbhz,
                ..GnssSatellite::default()
            };
            n += 1;
        }
    }
    out.n_satellites = n as u32;
}

/// The sample of a UBX epoch: NAV-PVT's fix (when present and valid) with RXM-RAWX's or
/// NAV-SAT's satellites. Without NAV-PVT the epoch is timed by RXM-RAWX and has no fix.
pub fn from_ubx(
    pvt: Option<&NavPvt>,
    sat: Option<&NavSat>,
    rawx: Option<&Rawx>,
) -> Result<GnssSample, EpochError> {
    let mut out = GnssSample::default();
    out.header.time_ns = match (pvt, rawx) {
        (Some(p), _) => ubx_time_ns(p, rawx).ok_or(EpochError::Undated)?,
        (None, Some(r)) => rawx_time_ns(r),
        (None, None) => return Err(EpochError::Undated),
    };
    satellites_from(&mut out, sat, rawx);
    if let Some(p) = pvt {
        let fix_ok = p.flags & 1 != 0
            && matches!(p.fix_type, 3 | 4)
            && !p.invalid_llh
            && p.h_acc_m > 0.0
            && p.v_acc_m > 0.0;
        if fix_ok {
            let g = Geodetic {
                lat_rad: p.lat_rad,
                lon_rad: p.lon_rad,
                height_m: p.height_m,
            };
            let p_ned = Matrix3::from_diagonal(&Vector3::new(
                p.h_acc_m.powi(2),
                p.h_acc_m.powi(2),
                p.v_acc_m.powi(2),
            ));
            let v_ned_cov = Matrix3::from_diagonal_element(p.s_acc_m_s.powi(2));
            set_fix(
                &mut out,
                &g,
                Vector3::from(p.vel_ned_m_s),
                &p_ned,
                &v_ned_cov,
            );
            out.pdop = p.pdop;
        }
    }
    Ok(out)
}

/// What an NMEA epoch holds.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct NmeaEpoch {
    /// UTC time of day of the epoch.
    pub time: TimeOfDay,
    /// UTC date of the epoch (from its RMC or carried over from the last one).
    pub date: Option<Date>,
    /// GGA of the epoch.
    pub gga: Option<Gga>,
    /// RMC of the epoch.
    pub rmc: Option<Rmc>,
    /// GSA of the epoch.
    pub gsa: Option<Gsa>,
    /// GST of the epoch.
    pub gst: Option<Gst>,
}

/// GPS time of a UTC date and time of day, ns.
pub fn utc_to_gps_ns(date: Date, t: TimeOfDay) -> i64 {
    let ms = t.0;
    GpsTime::from_utc_ns(
        date.year,
        date.month,
        date.day,
        ms / 3_600_000,
        ms / 60_000 % 60,
        ms / 1000 % 60,
        ms % 1000 * 1_000_000,
    )
    .ns
}

/// NED position covariance from GST: the error ellipse when given, else the latitude and
/// longitude sigmas; `None` without an altitude sigma and one of those.
fn gst_cov(g: &Gst) -> Option<Matrix3<f64>> {
    let alt = g.alt_sigma_m?;
    let mut p = Matrix3::zeros();
    match (g.major_m, g.minor_m, g.orientation_rad) {
        (Some(a), Some(b), Some(th)) => {
            // Semi-major axis along azimuth θ: P = R diag(a², b²) Rᵀ in (north, east).
            let (s, c) = th.sin_cos();
            p[(0, 0)] = a * a * c * c + b * b * s * s;
            p[(1, 1)] = a * a * s * s + b * b * c * c;
            p[(0, 1)] = (a * a - b * b) * s * c;
            p[(1, 0)] = p[(0, 1)];
        }
        _ => {
            p[(0, 0)] = g.lat_sigma_m?.powi(2);
            p[(1, 1)] = g.lon_sigma_m?.powi(2);
        }
    }
    p[(2, 2)] = alt * alt;
    Some(p)
}

/// The sample of an NMEA epoch. `uere_m` is the user-equivalent range error that turns GSA's
/// DOPs into sigmas when there is no GST.
pub fn from_nmea(e: &NmeaEpoch, uere_m: f64) -> Result<GnssSample, EpochError> {
    let date = e.date.ok_or(EpochError::Undated)?;
    let mut out = GnssSample::default();
    out.header.time_ns = utc_to_gps_ns(date, e.time);
    out.header.status = STATUS_FROM_NMEA;
    let Some(gga) = e.gga else {
        return Ok(out);
    };
    out.pdop = e.gsa.and_then(|g| g.pdop).unwrap_or(0.0);
    let three_d = e.gsa.is_none_or(|g| g.fix_mode == 3);
    let rmc_ok = e.rmc.is_none_or(|r| r.valid);
    let position = match (
        gga.lat_rad,
        gga.lon_rad,
        gga.altitude_msl_m,
        gga.geoid_separation_m,
    ) {
        (Some(lat), Some(lon), Some(alt), Some(sep)) => Some(Geodetic {
            lat_rad: lat,
            lon_rad: lon,
            height_m: alt + sep,
        }),
        _ => None,
    };
    let Some(g) = position.filter(|_| (1..=5).contains(&gga.quality) && three_d && rmc_ok) else {
        return Ok(out);
    };
    let p_ned = match e.gst.as_ref().and_then(gst_cov) {
        Some(p) => p,
        None => {
            let (h, v) = e
                .gsa
                .and_then(|s| s.hdop.zip(s.vdop))
                .ok_or(EpochError::NoAccuracy)?;
            let sh2 = (h * uere_m).powi(2) / 2.0;
            Matrix3::from_diagonal(&Vector3::new(sh2, sh2, (v * uere_m).powi(2)))
        }
    };
    if !(p_ned[(0, 0)] > 0.0 && p_ned[(1, 1)] > 0.0 && p_ned[(2, 2)] > 0.0) {
        return Err(EpochError::NoAccuracy);
    }
    let v_ned = e
        .rmc
        .and_then(|r| r.speed_m_s.zip(r.course_rad))
        .map_or(Vector3::zeros(), |(sp, c)| {
            Vector3::new(sp * c.cos(), sp * c.sin(), 0.0)
        });
    set_fix(&mut out, &g, v_ned, &p_ned, &Matrix3::zeros());
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pvt() -> NavPvt {
        NavPvt {
            // 2025-03-20 is a Thursday: 21:00:00 UTC = 21:00:18 GPS, day 4 of the GPS week.
            itow_ms: (4 * 86_400 + 21 * 3600 + 18) * 1000,
            utc: (2025, 3, 20, 21, 0, 0),
            valid: 0x07,
            fix_type: 3,
            flags: 1,
            num_sv: 9,
            lat_rad: 55.655f64.to_radians(),
            lon_rad: 37.534f64.to_radians(),
            height_m: 200.0,
            h_acc_m: 1.5,
            v_acc_m: 2.5,
            vel_ned_m_s: [1.0, 2.0, -0.5],
            s_acc_m_s: 0.1,
            pdop: 1.6,
            ..NavPvt::default()
        }
    }

    #[test]
    fn nav_pvt_gives_gps_time_ecef_fix_and_rotated_covariance() {
        let s = from_ubx(Some(&pvt()), None, None).unwrap();
        assert_eq!(
            s.header.time_ns,
            GpsTime::from_utc(2025, 3, 20, 21, 0, 0.0).ns
        );
        assert_eq!(s.fix_valid, 1);
        let g = Geodetic {
            lat_rad: 55.655f64.to_radians(),
            lon_rad: 37.534f64.to_radians(),
            height_m: 200.0,
        };
        let r = geodetic_to_ecef(&WGS84, &g);
        assert_eq!(s.pos_ecef_m, [r.x, r.y, r.z]);
        // Rotating back to NED gives the receiver's sigmas.
        let c = c_e_n(g.lat_rad, g.lon_rad);
        let p_n = c.transpose() * Matrix3::from_row_slice(&s.pos_cov_ecef_m2) * c;
        assert!((p_n[(0, 0)] - 2.25).abs() < 1e-12 && (p_n[(2, 2)] - 6.25).abs() < 1e-12);
        assert!(p_n[(0, 2)].abs() < 1e-12);
        let v_n = c.transpose() * Vector3::from(s.vel_ecef_m_s);
        assert!((v_n - Vector3::new(1.0, 2.0, -0.5)).norm() < 1e-12);
        assert_eq!(s.pdop, 1.6);
    }

    #[test]
    fn an_invalid_or_undated_nav_pvt_is_no_fix_or_no_sample() {
        let mut p = pvt();
        p.flags = 0;
        assert_eq!(from_ubx(Some(&p), None, None).unwrap().fix_valid, 0);
        p = pvt();
        p.fix_type = 2;
        assert_eq!(from_ubx(Some(&p), None, None).unwrap().fix_valid, 0);
        p.valid = 0;
        assert_eq!(from_ubx(Some(&p), None, None), Err(EpochError::Undated));
        // RAWX's week dates it.
        let rawx = Rawx {
            week: 2358,
            rcv_tow_s: f64::from(p.itow_ms) * 1e-3,
            ..Rawx::default()
        };
        let s = from_ubx(Some(&p), None, Some(&rawx)).unwrap();
        assert_eq!(
            s.header.time_ns,
            2358 * WEEK_NS + i64::from(p.itow_ms) * 1_000_000
        );
    }

    #[test]
    fn week_rollover_between_utc_and_gps_time_picks_the_right_week() {
        // 2025-03-22 23:59:50 UTC is 2025-03-23 00:00:08 GPS, the next GPS week (Sunday).
        let mut p = pvt();
        p.utc = (2025, 3, 22, 23, 59, 50);
        p.itow_ms = 8000;
        let s = from_ubx(Some(&p), None, None).unwrap();
        assert_eq!(
            s.header.time_ns,
            GpsTime::from_utc(2025, 3, 22, 23, 59, 50.0).ns
        );
    }

    #[test]
    fn nmea_covariance_comes_from_gst_or_gsa_dops() {
        let date = Date {
            year: 2025,
            month: 3,
            day: 20,
        };
        let gga = Gga {
            time: Some(TimeOfDay(75_600_000)),
            lat_rad: Some(0.0),
            lon_rad: Some(0.0),
            quality: 1,
            num_sv: Some(8),
            hdop: Some(1.0),
            altitude_msl_m: Some(100.0),
            geoid_separation_m: Some(20.0),
        };
        let gsa = Gsa {
            fix_mode: 3,
            pdop: Some(2.0),
            hdop: Some(1.2),
            vdop: Some(1.6),
        };
        let mut e = NmeaEpoch {
            time: TimeOfDay(75_600_000),
            date: Some(date),
            gga: Some(gga),
            gsa: Some(gsa),
            ..NmeaEpoch::default()
        };
        let s = from_nmea(&e, 5.0).unwrap();
        assert_eq!(
            s.header.time_ns,
            GpsTime::from_utc(2025, 3, 20, 21, 0, 0.0).ns
        );
        assert_eq!(s.header.status, STATUS_FROM_NMEA);
        // At lat = lon = 0, NED (n, e, d) = ECEF (z, y, −x).
        assert!((s.pos_ecef_m[0] - (WGS84.a_m + 120.0)).abs() < 1e-6);
        assert!((s.pos_cov_ecef_m2[8] - 18.0).abs() < 1e-9);
        assert!((s.pos_cov_ecef_m2[0] - 64.0).abs() < 1e-9);
        assert_eq!(s.vel_cov_ecef_m2_s2, [0.0; 9]);
        // GST wins over the DOPs: an ellipse with its major axis to the north-east.
        e.gst = Some(Gst {
            time: e.gga.unwrap().time,
            major_m: Some(3.0),
            minor_m: Some(1.0),
            orientation_rad: Some(45f64.to_radians()),
            lat_sigma_m: Some(2.2),
            lon_sigma_m: Some(2.2),
            alt_sigma_m: Some(4.0),
        });
        let s = from_nmea(&e, 5.0).unwrap();
        // north = z, east = y: P_ne = (9 − 1)/2.
        assert!((s.pos_cov_ecef_m2[8] - 5.0).abs() < 1e-9);
        assert!((s.pos_cov_ecef_m2[5] - 4.0).abs() < 1e-9);
        assert!((s.pos_cov_ecef_m2[0] - 16.0).abs() < 1e-9);
        e.gst = None;
        e.gsa = None;
        assert_eq!(from_nmea(&e, 5.0), Err(EpochError::NoAccuracy));
        e.date = None;
        assert_eq!(from_nmea(&e, 5.0), Err(EpochError::Undated));
    }
}
