//! Payloads of the three UBX messages the driver uses, decoded from (and encoded to) their
//! little-endian layouts in the u-blox M8/F9 interface descriptions:
//!
//! - UBX-NAV-PVT (0x01 0x07, 92 bytes): the navigation solution — UTC date and time, GPS time
//!   of week, fix type, geodetic position (WGS-84), NED velocity and the receiver's accuracy
//!   estimates `hAcc`, `vAcc`, `sAcc`, PDOP;
//! - UBX-NAV-SAT (0x01 0x35, 8 + 12·n bytes): per satellite C/N0, elevation, azimuth, use flag;
//! - UBX-RXM-RAWX (0x02 0x15, 16 + 32·n bytes): per signal raw pseudorange, carrier phase,
//!   Doppler and their standard deviations, with the receiver's GPS week and time of week.
//!
//! Units are converted to SI at decoding (m, m/s, rad, s); times stay in the receiver's own
//! terms (time of week, week) and are put on Sextant's time base by `epoch`.

use std::f64::consts::PI;

/// Class and id of UBX-NAV-PVT.
pub const NAV_PVT: (u8, u8) = (0x01, 0x07);
/// Class and id of UBX-NAV-SAT.
pub const NAV_SAT: (u8, u8) = (0x01, 0x35);
/// Class and id of UBX-RXM-RAWX.
pub const RXM_RAWX: (u8, u8) = (0x02, 0x15);

const NAV_PVT_LEN: usize = 92;
const NAV_SAT_HEADER: usize = 8;
const NAV_SAT_BLOCK: usize = 12;
const RAWX_HEADER: usize = 16;
const RAWX_BLOCK: usize = 32;

/// A UBX payload that does not have its message's layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum UbxDecodeError {
    /// The payload length is not the one the message's layout (and its count field) implies.
    #[error("UBX {class:#04x} {id:#04x}: payload of {got} bytes, expected {expected}")]
    Length {
        /// Message class.
        class: u8,
        /// Message id.
        id: u8,
        /// Payload length received.
        got: usize,
        /// Length the layout implies.
        expected: usize,
    },
}

/// GNSS identifier of GPS in NAV-SAT and RXM-RAWX.
pub const GNSS_ID_GPS: u8 = 0;

/// UBX-NAV-PVT, in SI units.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NavPvt {
    /// GPS time of week of the navigation epoch, ms.
    pub itow_ms: u32,
    /// UTC year, month, day, hour, minute, second.
    pub utc: (u16, u8, u8, u8, u8, u8),
    /// Fraction of the UTC second, ns (−1e9..1e9: the UTC fields are rounded).
    pub utc_nano_ns: i32,
    /// Validity flags: bit 0 date valid, bit 1 time valid, bit 2 fully resolved.
    pub valid: u8,
    /// Time accuracy estimate, s.
    pub t_acc_s: f64,
    /// Fix type: 0 none, 1 dead reckoning, 2 2-D, 3 3-D, 4 GNSS + dead reckoning, 5 time only.
    pub fix_type: u8,
    /// Fix status flags: bit 0 `gnssFixOK` (the fix is within the receiver's limits).
    pub flags: u8,
    /// Satellites used in the solution.
    pub num_sv: u8,
    /// Geodetic latitude (WGS-84), rad.
    pub lat_rad: f64,
    /// Longitude, rad.
    pub lon_rad: f64,
    /// Height above the ellipsoid, m.
    pub height_m: f64,
    /// Height above mean sea level, m.
    pub height_msl_m: f64,
    /// Horizontal accuracy estimate, m.
    pub h_acc_m: f64,
    /// Vertical accuracy estimate, m.
    pub v_acc_m: f64,
    /// Velocity north, east, down, m/s.
    pub vel_ned_m_s: [f64; 3],
    /// Speed accuracy estimate, m/s.
    pub s_acc_m_s: f64,
    /// Position dilution of precision.
    pub pdop: f64,
    /// `flags3` bit 0: latitude, longitude and heights are invalid.
    pub invalid_llh: bool,
}

/// One satellite of UBX-NAV-SAT.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NavSatSv {
    /// GNSS identifier (0 = GPS).
    pub gnss_id: u8,
    /// Satellite identifier within its GNSS (the PRN for GPS).
    pub sv_id: u8,
    /// Carrier-to-noise density, dB-Hz.
    pub cn0_dbhz: f64,
    /// Elevation, rad.
    pub elevation_rad: f64,
    /// Azimuth, rad.
    pub azimuth_rad: f64,
    /// Pseudorange residual, m.
    pub pr_residual_m: f64,
    /// Flags: bit 3 `svUsed` (used in the navigation solution).
    pub flags: u32,
}

/// UBX-NAV-SAT.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct NavSat {
    /// GPS time of week of the navigation epoch, ms.
    pub itow_ms: u32,
    /// Satellites.
    pub svs: Vec<NavSatSv>,
}

/// One measurement of UBX-RXM-RAWX.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RawxMeas {
    /// Pseudorange, m.
    pub pr_m: f64,
    /// Carrier phase, cycles.
    pub cp_cycles: f64,
    /// Doppler, Hz (positive when the satellite approaches).
    pub doppler_hz: f64,
    /// GNSS identifier (0 = GPS).
    pub gnss_id: u8,
    /// Satellite identifier within its GNSS.
    pub sv_id: u8,
    /// Signal identifier (0 = GPS L1 C/A).
    pub sig_id: u8,
    /// Carrier-to-noise density, dB-Hz.
    pub cn0_dbhz: f64,
    /// Pseudorange standard deviation, m (0.01·2ⁿ m).
    pub pr_stdev_m: f64,
    /// Doppler standard deviation, Hz (0.002·2ⁿ Hz).
    pub doppler_stdev_hz: f64,
    /// Tracking status: bit 0 pseudorange valid, bit 1 carrier phase valid.
    pub trk_stat: u8,
}

/// UBX-RXM-RAWX.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Rawx {
    /// Receiver time of week of the measurements, s.
    pub rcv_tow_s: f64,
    /// GPS week number (full, not modulo 1024).
    pub week: u16,
    /// GPS − UTC leap seconds, s.
    pub leap_s: i8,
    /// Receiver status: bit 0 leap seconds determined.
    pub rec_stat: u8,
    /// Measurements.
    pub meas: Vec<RawxMeas>,
}

fn u16_at(p: &[u8], i: usize) -> u16 {
    u16::from_le_bytes([p[i], p[i + 1]])
}
fn i16_at(p: &[u8], i: usize) -> i16 {
    i16::from_le_bytes([p[i], p[i + 1]])
}
fn u32_at(p: &[u8], i: usize) -> u32 {
    u32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]])
}
fn i32_at(p: &[u8], i: usize) -> i32 {
    u32_at(p, i) as i32
}
fn f32_at(p: &[u8], i: usize) -> f32 {
    f32::from_bits(u32_at(p, i))
}
fn f64_at(p: &[u8], i: usize) -> f64 {
    let mut b = [0u8; 8];
    b.copy_from_slice(&p[i..i + 8]);
    f64::from_le_bytes(b)
}

fn check_len((class, id): (u8, u8), p: &[u8], expected: usize) -> Result<(), UbxDecodeError> {
    if p.len() == expected {
        Ok(())
    } else {
        Err(UbxDecodeError::Length {
            class,
            id,
            got: p.len(),
            expected,
        })
    }
}

const DEG_1E7: f64 = 1e-7 * PI / 180.0;

impl NavPvt {
    /// Decode a NAV-PVT payload.
    pub fn decode(p: &[u8]) -> Result<Self, UbxDecodeError> {
        check_len(NAV_PVT, p, NAV_PVT_LEN)?;
        Ok(Self {
            itow_ms: u32_at(p, 0),
            utc: (u16_at(p, 4), p[6], p[7], p[8], p[9], p[10]),
            valid: p[11],
            t_acc_s: f64::from(u32_at(p, 12)) * 1e-9,
            utc_nano_ns: i32_at(p, 16),
            fix_type: p[20],
            flags: p[21],
            num_sv: p[23],
            lon_rad: f64::from(i32_at(p, 24)) * DEG_1E7,
            lat_rad: f64::from(i32_at(p, 28)) * DEG_1E7,
            height_m: f64::from(i32_at(p, 32)) * 1e-3,
            height_msl_m: f64::from(i32_at(p, 36)) * 1e-3,
            h_acc_m: f64::from(u32_at(p, 40)) * 1e-3,
            v_acc_m: f64::from(u32_at(p, 44)) * 1e-3,
            vel_ned_m_s: [
                f64::from(i32_at(p, 48)) * 1e-3,
                f64::from(i32_at(p, 52)) * 1e-3,
                f64::from(i32_at(p, 56)) * 1e-3,
            ],
            s_acc_m_s: f64::from(u32_at(p, 68)) * 1e-3,
            pdop: f64::from(u16_at(p, 76)) * 0.01,
            invalid_llh: u16_at(p, 78) & 1 != 0,
        })
    }

    /// Encode to a NAV-PVT payload (fields not held here are zero), rounding to the wire's
    /// resolution: what a receiver would send for this solution.
    pub fn encode(&self) -> Vec<u8> {
        let mut p = vec![0u8; NAV_PVT_LEN];
        let put = |p: &mut Vec<u8>, i: usize, b: &[u8]| p[i..i + b.len()].copy_from_slice(b);
        put(&mut p, 0, &self.itow_ms.to_le_bytes());
        put(&mut p, 4, &self.utc.0.to_le_bytes());
        put(
            &mut p,
            6,
            &[self.utc.1, self.utc.2, self.utc.3, self.utc.4, self.utc.5],
        );
        p[11] = self.valid;
        put(
            &mut p,
            12,
            &((self.t_acc_s * 1e9).round() as u32).to_le_bytes(),
        );
        put(&mut p, 16, &self.utc_nano_ns.to_le_bytes());
        p[20] = self.fix_type;
        p[21] = self.flags;
        p[23] = self.num_sv;
        put(
            &mut p,
            24,
            &((self.lon_rad / DEG_1E7).round() as i32).to_le_bytes(),
        );
        put(
            &mut p,
            28,
            &((self.lat_rad / DEG_1E7).round() as i32).to_le_bytes(),
        );
        put(
            &mut p,
            32,
            &((self.height_m * 1e3).round() as i32).to_le_bytes(),
        );
        put(
            &mut p,
            36,
            &((self.height_msl_m * 1e3).round() as i32).to_le_bytes(),
        );
        put(
            &mut p,
            40,
            &((self.h_acc_m * 1e3).round() as u32).to_le_bytes(),
        );
        put(
            &mut p,
            44,
            &((self.v_acc_m * 1e3).round() as u32).to_le_bytes(),
        );
        for k in 0..3 {
            let v = (self.vel_ned_m_s[k] * 1e3).round() as i32;
            put(&mut p, 48 + 4 * k, &v.to_le_bytes());
        }
        let g_speed = self.vel_ned_m_s[0].hypot(self.vel_ned_m_s[1]);
        put(&mut p, 60, &((g_speed * 1e3).round() as i32).to_le_bytes());
        put(
            &mut p,
            68,
            &((self.s_acc_m_s * 1e3).round() as u32).to_le_bytes(),
        );
        put(
            &mut p,
            76,
            &((self.pdop * 100.0).round() as u16).to_le_bytes(),
        );
        put(&mut p, 78, &u16::from(self.invalid_llh).to_le_bytes());
        p
    }
}

impl NavSat {
    /// Decode a NAV-SAT payload.
    pub fn decode(p: &[u8]) -> Result<Self, UbxDecodeError> {
        if p.len() < NAV_SAT_HEADER {
            return check_len(NAV_SAT, p, NAV_SAT_HEADER).map(|_| Self::default());
        }
        let n = usize::from(p[5]);
        check_len(NAV_SAT, p, NAV_SAT_HEADER + NAV_SAT_BLOCK * n)?;
        let svs = (0..n)
            .map(|k| {
                let b = &p[NAV_SAT_HEADER + NAV_SAT_BLOCK * k..];
                NavSatSv {
                    gnss_id: b[0],
                    sv_id: b[1],
                    cn0_dbhz: f64::from(b[2]),
                    elevation_rad: f64::from(b[3] as i8).to_radians(),
                    azimuth_rad: f64::from(i16_at(b, 4)).to_radians(),
                    pr_residual_m: f64::from(i16_at(b, 6)) * 0.1,
                    flags: u32_at(b, 8),
                }
            })
            .collect();
        Ok(Self {
            itow_ms: u32_at(p, 0),
            svs,
        })
    }

    /// Encode to a NAV-SAT payload (message version 1).
    pub fn encode(&self) -> Vec<u8> {
        let n = self.svs.len().min(255);
        let mut p = vec![0u8; NAV_SAT_HEADER + NAV_SAT_BLOCK * n];
        p[0..4].copy_from_slice(&self.itow_ms.to_le_bytes());
        p[4] = 1;
        p[5] = n as u8;
        for (k, sv) in self.svs.iter().take(n).enumerate() {
            let b = &mut p[NAV_SAT_HEADER + NAV_SAT_BLOCK * k..][..NAV_SAT_BLOCK];
            b[0] = sv.gnss_id;
            b[1] = sv.sv_id;
            b[2] = sv.cn0_dbhz.round().clamp(0.0, 255.0) as u8;
            b[3] = sv.elevation_rad.to_degrees().round().clamp(-90.0, 90.0) as i8 as u8;
            b[4..6].copy_from_slice(&(sv.azimuth_rad.to_degrees().round() as i16).to_le_bytes());
            b[6..8].copy_from_slice(&((sv.pr_residual_m * 10.0).round() as i16).to_le_bytes());
            b[8..12].copy_from_slice(&sv.flags.to_le_bytes());
        }
        p
    }
}

impl Rawx {
    /// Decode an RXM-RAWX payload.
    pub fn decode(p: &[u8]) -> Result<Self, UbxDecodeError> {
        if p.len() < RAWX_HEADER {
            return check_len(RXM_RAWX, p, RAWX_HEADER).map(|_| Self::default());
        }
        let n = usize::from(p[11]);
        check_len(RXM_RAWX, p, RAWX_HEADER + RAWX_BLOCK * n)?;
        let meas = (0..n)
            .map(|k| {
                let b = &p[RAWX_HEADER + RAWX_BLOCK * k..];
                RawxMeas {
                    pr_m: f64_at(b, 0),
                    cp_cycles: f64_at(b, 8),
                    doppler_hz: f64::from(f32_at(b, 16)),
                    gnss_id: b[20],
                    sv_id: b[21],
                    sig_id: b[22],
                    cn0_dbhz: f64::from(b[26]),
                    pr_stdev_m: 0.01 * f64::from(1u32 << (b[27] & 0x0F)),
                    doppler_stdev_hz: 0.002 * f64::from(1u32 << (b[29] & 0x0F)),
                    trk_stat: b[30],
                }
            })
            .collect();
        Ok(Self {
            rcv_tow_s: f64_at(p, 0),
            week: u16_at(p, 8),
            leap_s: p[10] as i8,
            rec_stat: p[12],
            meas,
        })
    }

    /// Encode to an RXM-RAWX payload (message version 1). Standard deviations are rounded up
    /// to the next power-of-two step of the wire format.
    pub fn encode(&self) -> Vec<u8> {
        let n = self.meas.len().min(255);
        let mut p = vec![0u8; RAWX_HEADER + RAWX_BLOCK * n];
        p[0..8].copy_from_slice(&self.rcv_tow_s.to_le_bytes());
        p[8..10].copy_from_slice(&self.week.to_le_bytes());
        p[10] = self.leap_s as u8;
        p[11] = n as u8;
        p[12] = self.rec_stat;
        p[13] = 1;
        let exponent = |value: f64, step: f64| -> u8 {
            (0u8..15)
                .find(|&e| step * f64::from(1u32 << e) >= value)
                .unwrap_or(15)
        };
        for (k, m) in self.meas.iter().take(n).enumerate() {
            let b = &mut p[RAWX_HEADER + RAWX_BLOCK * k..][..RAWX_BLOCK];
            b[0..8].copy_from_slice(&m.pr_m.to_le_bytes());
            b[8..16].copy_from_slice(&m.cp_cycles.to_le_bytes());
            b[16..20].copy_from_slice(&(m.doppler_hz as f32).to_le_bytes());
            b[20] = m.gnss_id;
            b[21] = m.sv_id;
            b[22] = m.sig_id;
            b[26] = m.cn0_dbhz.round().clamp(0.0, 255.0) as u8;
            b[27] = exponent(m.pr_stdev_m, 0.01);
            b[29] = exponent(m.doppler_stdev_hz, 0.002);
            b[30] = m.trk_stat;
        }
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A NAV-PVT payload written field by field at the offsets of the interface description,
    /// independently of `encode`.
    #[test]
    fn nav_pvt_fields_are_read_at_their_documented_offsets() {
        let mut p = [0u8; 92];
        p[0..4].copy_from_slice(&345_600_000u32.to_le_bytes());
        p[4..6].copy_from_slice(&2025u16.to_le_bytes());
        p[6..11].copy_from_slice(&[3, 20, 21, 0, 0]);
        p[11] = 0x07;
        p[20] = 3;
        p[21] = 0x01;
        p[23] = 9;
        p[24..28].copy_from_slice(&375_340_000i32.to_le_bytes());
        p[28..32].copy_from_slice(&556_550_000i32.to_le_bytes());
        p[32..36].copy_from_slice(&200_000i32.to_le_bytes());
        p[40..44].copy_from_slice(&1_500u32.to_le_bytes());
        p[44..48].copy_from_slice(&2_500u32.to_le_bytes());
        p[48..52].copy_from_slice(&(-250i32).to_le_bytes());
        p[68..72].copy_from_slice(&120u32.to_le_bytes());
        p[76..78].copy_from_slice(&163u16.to_le_bytes());
        let pvt = NavPvt::decode(&p).unwrap();
        assert_eq!(pvt.itow_ms, 345_600_000);
        assert_eq!(pvt.utc, (2025, 3, 20, 21, 0, 0));
        assert_eq!((pvt.fix_type, pvt.flags, pvt.num_sv), (3, 1, 9));
        assert!((pvt.lat_rad.to_degrees() - 55.655).abs() < 1e-12);
        assert!((pvt.lon_rad.to_degrees() - 37.534).abs() < 1e-12);
        assert_eq!(pvt.height_m, 200.0);
        assert_eq!((pvt.h_acc_m, pvt.v_acc_m, pvt.s_acc_m_s), (1.5, 2.5, 0.12));
        assert_eq!(pvt.vel_ned_m_s, [-0.25, 0.0, 0.0]);
        assert!((pvt.pdop - 1.63).abs() < 1e-12);
        assert_eq!(NavPvt::decode(&pvt.encode()).unwrap(), pvt);
    }

    #[test]
    fn wrong_lengths_are_errors() {
        assert!(matches!(
            NavPvt::decode(&[0; 91]),
            Err(UbxDecodeError::Length {
                got: 91,
                expected: 92,
                ..
            })
        ));
        let mut sat = NavSat {
            itow_ms: 1,
            svs: vec![NavSatSv::default(); 2],
        }
        .encode();
        sat.pop();
        assert!(NavSat::decode(&sat).is_err());
        assert!(Rawx::decode(&[0; 3]).is_err());
    }

    #[test]
    fn rawx_round_trips_at_wire_resolution() {
        let r = Rawx {
            rcv_tow_s: 421_200.000_123,
            week: 2358,
            leap_s: 18,
            rec_stat: 1,
            meas: vec![RawxMeas {
                pr_m: 21_345_678.125,
                cp_cycles: 1.0e8,
                doppler_hz: -1234.5,
                gnss_id: 0,
                sv_id: 7,
                sig_id: 0,
                cn0_dbhz: 44.0,
                pr_stdev_m: 0.32,
                doppler_stdev_hz: 0.128,
                trk_stat: 1,
            }],
        };
        assert_eq!(Rawx::decode(&r.encode()).unwrap(), r);
    }

    proptest! {
        /// Arbitrary payloads of any length: an error or a value, never a panic.
        #[test]
        fn arbitrary_payloads_never_panic(p in proptest::collection::vec(any::<u8>(), 0..600)) {
            let _ = NavPvt::decode(&p);
            let _ = NavSat::decode(&p);
            let _ = Rawx::decode(&p);
        }
    }
}
