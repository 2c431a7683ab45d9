//! From the receiver's bytes to [`GnssSample`]s: framing, decoding, and grouping the messages
//! of one navigation epoch.
//!
//! A receiver sends several messages per epoch (UBX: RXM-RAWX, NAV-SAT, NAV-PVT; NMEA: RMC,
//! GGA, GSA, GST, in an order that depends on its configuration) and no end-of-epoch marker
//! that every configuration has. Messages are grouped by their epoch time (UBX time of week,
//! NMEA time of day; GSA has none and joins the open NMEA epoch). An epoch is complete
//! when the set of message kinds the receiver sent for the previous epoch has arrived — the
//! set is learned from the stream, so no configuration is needed and the sample goes out as
//! soon as its last message is in; until the set is known (the first epoch) or when a kind goes
//! missing, a message of a newer epoch closes the open one. A kind that stops coming for two
//! epochs in a row is dropped from the set.
//!
//! Samples leave in strictly increasing time order: an epoch not newer than the last published
//! one (e.g. the NMEA copy of an epoch already sent from UBX) is counted and not published.
//! Nothing the receiver sends can make this panic; everything skipped is counted in
//! [`Report`].

use crate::framing::{Frame, Framer, FramingCounters};
use crate::nmea::{self, Date, Gsa, Sentence, TimeOfDay};
use crate::sample::{self, EpochError, NmeaEpoch};
use crate::ubx::{self, NavPvt, NavSat, Rawx};
use msgs::GnssSample;
use serde::Serialize;

/// Two epoch times (ms, on a circle of `modulus` ms) within this are the same epoch: RXM-RAWX's
/// receiver time differs from the navigation epoch by the receiver clock's sub-millisecond
/// offset, NMEA prints times to 10 ms.
const SAME_EPOCH_MS: i64 = 5;
const WEEK_MS: i64 = 604_800_000;
const DAY_MS: i64 = 86_400_000;

/// What the driver did with the epochs. Every counter only grows.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct EpochCounters {
    /// Valid UBX frames of other messages than NAV-PVT, NAV-SAT, RXM-RAWX.
    pub ubx_ignored: u64,
    /// NAV-PVT, NAV-SAT or RXM-RAWX frames whose payload does not have the message's layout.
    pub ubx_malformed: u64,
    /// Valid NMEA sentences of other types than GGA, RMC, GSA, GST.
    pub nmea_ignored: u64,
    /// GGA, RMC, GSA or GST sentences with a field that cannot be read.
    pub nmea_malformed: u64,
    /// Messages of an epoch that was already complete and published.
    pub late_messages: u64,
    /// Samples published.
    pub samples_published: u64,
    /// Of those, samples with a valid fix.
    pub fixes_published: u64,
    /// Epochs not newer than the last published sample (not published).
    pub epochs_stale: u64,
    /// Epochs whose date could not be known (not published).
    pub epochs_undated: u64,
    /// NMEA fixes without any accuracy (no GST nor GSA; not published).
    pub epochs_without_accuracy: u64,
}

/// Everything counted, for logs and the driver's exit summary.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Report {
    /// Byte-level counters.
    pub framing: FramingCounters,
    /// Message- and epoch-level counters.
    pub epochs: EpochCounters,
}

/// Settings of the conversion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// User-equivalent range error, m, that turns NMEA GSA DOPs into sigmas when the receiver
    /// sends no GST.
    pub nmea_uere_m: f64,
}

impl Default for Settings {
    fn default() -> Self {
        Self { nmea_uere_m: 5.0 }
    }
}

/// Which kinds of message an epoch is made of, and when to close it.
#[derive(Debug, Default)]
struct EpochSet {
    /// Kinds (bit set) of a complete epoch, learned from the stream; 0 = not known yet.
    learned: u8,
    /// Kinds of the last epoch closed incomplete.
    last_incomplete: Option<u8>,
    /// Key of the last closed epoch.
    last_closed: Option<i64>,
}

impl EpochSet {
    fn complete(&self, mask: u8) -> bool {
        self.learned != 0 && mask & self.learned == self.learned
    }
    /// An epoch with `mask` closed because a newer one began.
    fn closed_by_newer(&mut self, mask: u8) {
        if mask == self.learned {
            self.last_incomplete = None;
        } else if self.last_incomplete == Some(mask) || self.learned == 0 {
            // The receiver now sends this set (or this is the first epoch seen).
            self.learned = mask;
            self.last_incomplete = None;
        } else {
            self.last_incomplete = Some(mask);
            self.learned |= mask;
        }
    }
}

fn same_epoch(a: i64, b: i64, modulus: i64) -> bool {
    let d = (a - b).rem_euclid(modulus);
    d.min(modulus - d) <= SAME_EPOCH_MS
}

#[derive(Debug, Default)]
struct UbxEpoch {
    key: i64,
    mask: u8,
    pvt: Option<NavPvt>,
    sat: Option<NavSat>,
    rawx: Option<Rawx>,
}

#[derive(Debug, Default)]
struct NmeaOpen {
    key: i64,
    mask: u8,
    epoch: NmeaEpoch,
}

/// One UBX message of an epoch.
enum UbxPart {
    Pvt(NavPvt),
    Sat(NavSat),
    Rawx(Rawx),
}

/// One NMEA sentence of an epoch (GSA excepted).
enum NmeaPart {
    Gga(nmea::Gga),
    Rmc(nmea::Rmc),
    Gst(nmea::Gst),
}

const BIT_PVT: u8 = 1;
const BIT_SAT: u8 = 2;
const BIT_RAWX: u8 = 4;
const BIT_GGA: u8 = 1;
const BIT_RMC: u8 = 2;
const BIT_GSA: u8 = 4;
const BIT_GST: u8 = 8;

/// A receiver's stream: push bytes, collect samples.
#[derive(Debug, Default)]
pub struct Receiver {
    framer: Framer,
    settings: Settings,
    ubx: Option<UbxEpoch>,
    ubx_set: EpochSet,
    nmea: Option<NmeaOpen>,
    nmea_set: EpochSet,
    /// A GSA received while no NMEA epoch was open, for the next one.
    pending_gsa: Option<Gsa>,
    /// Last RMC date and the time of day it came with.
    last_date: Option<(Date, TimeOfDay)>,
    last_published_ns: Option<i64>,
    counters: EpochCounters,
}

impl Receiver {
    /// A receiver stream with these settings.
    pub fn new(settings: Settings) -> Self {
        Self {
            settings,
            ..Self::default()
        }
    }

    /// Counters so far.
    pub fn report(&self) -> Report {
        Report {
            framing: self.framer.counters(),
            epochs: self.counters,
        }
    }

    /// Take received bytes; the samples completed by them are appended to `out`, oldest first.
    pub fn push(&mut self, bytes: &[u8], out: &mut Vec<GnssSample>) {
        self.framer.push(bytes);
        while let Some(frame) = self.framer.next_frame() {
            self.on_frame(frame, out);
        }
    }

    /// End of the input: the open epochs are closed (their samples appended to `out`) and the
    /// final counters returned.
    pub fn finish(&mut self, out: &mut Vec<GnssSample>) -> Report {
        self.framer.finish();
        while let Some(frame) = self.framer.next_frame() {
            self.on_frame(frame, out);
        }
        if let Some(e) = self.ubx.take() {
            self.close_ubx(e, out);
        }
        if let Some(e) = self.nmea.take() {
            self.close_nmea(e, out);
        }
        self.report()
    }

    fn on_frame(&mut self, frame: Frame, out: &mut Vec<GnssSample>) {
        match frame {
            Frame::Ubx { class, id, payload } => {
                let part = match (class, id) {
                    ubx::NAV_PVT => NavPvt::decode(&payload).map(UbxPart::Pvt),
                    ubx::NAV_SAT => NavSat::decode(&payload).map(UbxPart::Sat),
                    ubx::RXM_RAWX => Rawx::decode(&payload).map(UbxPart::Rawx),
                    _ => {
                        self.counters.ubx_ignored += 1;
                        return;
                    }
                };
                match part {
                    Ok(p) => self.on_ubx(p, out),
                    Err(e) => {
                        tracing::debug!("{e}");
                        self.counters.ubx_malformed += 1;
                    }
                }
            }
            Frame::Nmea(body) => match nmea::parse(&body) {
                Ok(Sentence::Gga(g)) => self.on_nmea(g.time, NmeaPart::Gga(g), out),
                Ok(Sentence::Rmc(r)) => self.on_nmea(r.time, NmeaPart::Rmc(r), out),
                Ok(Sentence::Gst(g)) => self.on_nmea(g.time, NmeaPart::Gst(g), out),
                Ok(Sentence::Gsa(g)) => self.on_gsa(g, out),
                Ok(Sentence::Other) => self.counters.nmea_ignored += 1,
                Err(e) => {
                    tracing::debug!("{e}");
                    self.counters.nmea_malformed += 1;
                }
            },
        }
    }

    fn on_ubx(&mut self, part: UbxPart, out: &mut Vec<GnssSample>) {
        let (key, bit) = match &part {
            UbxPart::Pvt(p) => (i64::from(p.itow_ms), BIT_PVT),
            UbxPart::Sat(s) => (i64::from(s.itow_ms), BIT_SAT),
            UbxPart::Rawx(r) => {
                let ms = (r.rcv_tow_s * 1e3).round();
                // A time of week outside the week is not an epoch time.
                if !(0.0..WEEK_MS as f64).contains(&ms) {
                    self.counters.ubx_malformed += 1;
                    return;
                }
                (ms as i64, BIT_RAWX)
            }
        };
        if self
            .ubx
            .as_ref()
            .is_some_and(|e| !same_epoch(e.key, key, WEEK_MS))
            && let Some(e) = self.ubx.take()
        {
            self.ubx_set.closed_by_newer(e.mask);
            self.close_ubx(e, out);
        }
        if self.ubx.is_none() {
            if self
                .ubx_set
                .last_closed
                .is_some_and(|k| same_epoch(k, key, WEEK_MS))
            {
                self.ubx_set.learned |= bit;
                self.counters.late_messages += 1;
                return;
            }
            self.ubx = Some(UbxEpoch {
                key,
                ..UbxEpoch::default()
            });
        }
        let Some(e) = self.ubx.as_mut() else { return };
        e.mask |= bit;
        match part {
            UbxPart::Pvt(p) => e.pvt = Some(p),
            UbxPart::Sat(s) => e.sat = Some(s),
            UbxPart::Rawx(r) => e.rawx = Some(r),
        }
        if self.ubx_set.complete(e.mask)
            && let Some(e) = self.ubx.take()
        {
            self.ubx_set.last_incomplete = None;
            self.close_ubx(e, out);
        }
    }

    fn on_gsa(&mut self, g: Gsa, out: &mut Vec<GnssSample>) {
        match self.nmea.as_mut() {
            Some(e) => {
                e.mask |= BIT_GSA;
                e.epoch.gsa = Some(g);
                if self.nmea_set.complete(e.mask)
                    && let Some(e) = self.nmea.take()
                {
                    self.nmea_set.last_incomplete = None;
                    self.close_nmea(e, out);
                }
            }
            None => self.pending_gsa = Some(g),
        }
    }

    fn on_nmea(&mut self, time: Option<TimeOfDay>, part: NmeaPart, out: &mut Vec<GnssSample>) {
        // A sentence without a time (no fix yet) belongs to no epoch.
        let Some(time) = time else {
            return;
        };
        let key = i64::from(time.0);
        if self
            .nmea
            .as_ref()
            .is_some_and(|e| !same_epoch(e.key, key, DAY_MS))
            && let Some(e) = self.nmea.take()
        {
            self.nmea_set.closed_by_newer(e.mask);
            self.close_nmea(e, out);
        }
        let bit = match part {
            NmeaPart::Gga(_) => BIT_GGA,
            NmeaPart::Rmc(_) => BIT_RMC,
            NmeaPart::Gst(_) => BIT_GST,
        };
        if self.nmea.is_none() {
            if self
                .nmea_set
                .last_closed
                .is_some_and(|k| same_epoch(k, key, DAY_MS))
            {
                self.nmea_set.learned |= bit;
                self.counters.late_messages += 1;
                return;
            }
            let mut open = NmeaOpen {
                key,
                ..NmeaOpen::default()
            };
            open.epoch.time = time;
            if let Some(g) = self.pending_gsa.take() {
                open.epoch.gsa = Some(g);
                open.mask |= BIT_GSA;
            }
            self.nmea = Some(open);
        }
        let Some(e) = self.nmea.as_mut() else { return };
        e.mask |= bit;
        match part {
            NmeaPart::Gga(g) => e.epoch.gga = Some(g),
            NmeaPart::Rmc(r) => e.epoch.rmc = Some(r),
            NmeaPart::Gst(g) => e.epoch.gst = Some(g),
        }
        if self.nmea_set.complete(e.mask)
            && let Some(e) = self.nmea.take()
        {
            self.nmea_set.last_incomplete = None;
            self.close_nmea(e, out);
        }
    }

    fn close_ubx(&mut self, e: UbxEpoch, out: &mut Vec<GnssSample>) {
        self.ubx_set.last_closed = Some(e.key);
        let s = sample::from_ubx(e.pvt.as_ref(), e.sat.as_ref(), e.rawx.as_ref());
        self.publish(s, out);
    }

    fn close_nmea(&mut self, mut e: NmeaOpen, out: &mut Vec<GnssSample>) {
        self.nmea_set.last_closed = Some(e.key);
        let time = e.epoch.time;
        e.epoch.date = match e.epoch.rmc.and_then(|r| r.date) {
            Some(d) => {
                self.last_date = Some((d, time));
                Some(d)
            }
            // Carry the last date over, to the next day when the time of day wrapped.
            None => self
                .last_date
                .map(|(d, t)| if time < t { next_day(d) } else { d }),
        };
        let s = sample::from_nmea(&e.epoch, self.settings.nmea_uere_m);
        self.publish(s, out);
    }

    fn publish(&mut self, s: Result<GnssSample, EpochError>, out: &mut Vec<GnssSample>) {
        let s = match s {
            Ok(s) => s,
            Err(EpochError::Undated) => {
                self.counters.epochs_undated += 1;
                return;
            }
            Err(EpochError::NoAccuracy) => {
                self.counters.epochs_without_accuracy += 1;
                return;
            }
        };
        if self
            .last_published_ns
            .is_some_and(|t| s.header.time_ns <= t)
        {
            self.counters.epochs_stale += 1;
            return;
        }
        self.last_published_ns = Some(s.header.time_ns);
        self.counters.samples_published += 1;
        self.counters.fixes_published += u64::from(s.fix_valid == 1);
        out.push(s);
    }
}

fn next_day(d: Date) -> Date {
    let (year, month, day) =
        fusion::time::civil_from_days(fusion::time::days_from_civil(d.year, d.month, d.day) + 1);
    Date { year, month, day }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::framing::{nmea_sentence, ubx_frame};
    use crate::nmea::{format_angle, format_time};
    use proptest::prelude::*;

    const T0_TOW_MS: u32 = (4 * 86_400 + 21 * 3600 + 18) * 1000;

    fn pvt_frame(k: u32) -> Vec<u8> {
        let p = NavPvt {
            itow_ms: T0_TOW_MS + 1000 * k,
            utc: (2025, 3, 20, 21, 0, k as u8),
            valid: 0x07,
            fix_type: 3,
            flags: 1,
            num_sv: 8,
            lat_rad: 55.655f64.to_radians(),
            lon_rad: 37.534f64.to_radians(),
            height_m: 200.0,
            h_acc_m: 2.0,
            v_acc_m: 3.0,
            s_acc_m_s: 0.2,
            pdop: 1.5,
            ..NavPvt::default()
        };
        ubx_frame(0x01, 0x07, &p.encode())
    }

    fn sat_frame(k: u32) -> Vec<u8> {
        let s = NavSat {
            itow_ms: T0_TOW_MS + 1000 * k,
            svs: vec![ubx::NavSatSv {
                gnss_id: 0,
                sv_id: 5,
                cn0_dbhz: 40.0,
                ..Default::default()
            }],
        };
        ubx_frame(0x01, 0x35, &s.encode())
    }

    fn nmea_epoch(k: u32) -> String {
        let t = format_time(TimeOfDay(75_600_000 + 1000 * k));
        let lat = format_angle(55.655f64.to_radians(), true);
        let lon = format_angle(37.534f64.to_radians(), false);
        [
            nmea_sentence(&format!("GNRMC,{t},A,{lat},{lon},0.000,,200325,,,A,V")),
            nmea_sentence(&format!("GNGGA,{t},{lat},{lon},1,08,1.00,185.0,M,15.0,M,,")),
            nmea_sentence("GNGSA,A,3,01,02,03,04,05,06,07,08,,,,,1.80,1.00,1.50,1"),
            nmea_sentence(&format!("GNGST,{t},3.0,,,,1.5,1.6,2.5")),
        ]
        .concat()
    }

    fn run(bytes: &[u8]) -> (Vec<GnssSample>, Report) {
        let mut r = Receiver::new(Settings::default());
        let mut out = Vec::new();
        r.push(bytes, &mut out);
        let rep = r.finish(&mut out);
        (out, rep)
    }

    #[test]
    fn epochs_close_as_soon_as_the_learned_set_is_in() {
        let mut r = Receiver::new(Settings::default());
        let mut out = Vec::new();
        r.push(&[sat_frame(0), pvt_frame(0)].concat(), &mut out);
        // First epoch: the set is not known yet, it closes when the next begins.
        assert!(out.is_empty());
        r.push(&sat_frame(1), &mut out);
        assert_eq!(out.len(), 1);
        r.push(&pvt_frame(1), &mut out);
        assert_eq!(out.len(), 2, "closed on its last message");
        let t0 = fusion::time::GpsTime::from_utc(2025, 3, 20, 21, 0, 0.0).ns;
        assert_eq!(out[1].header.time_ns - out[0].header.time_ns, 1_000_000_000);
        assert_eq!(out[0].header.time_ns, t0);
        assert_eq!((out[0].n_satellites, out[0].satellites[0].prn), (1, 5));
        // A kind that stops: two epochs closed by the next one, then the new set is learned.
        r.push(&pvt_frame(2), &mut out);
        r.push(&pvt_frame(3), &mut out);
        assert_eq!(out.len(), 3);
        r.push(&pvt_frame(4), &mut out);
        assert_eq!(
            out.len(),
            5,
            "epoch 3 closed by epoch 4, which PVT alone now completes"
        );
        r.push(&pvt_frame(5), &mut out);
        assert_eq!(out.len(), 6);
        let rep = r.finish(&mut out);
        assert_eq!(rep.epochs.samples_published, 6);
        assert_eq!(rep.epochs.fixes_published, 6);
    }

    #[test]
    fn nmea_epochs_are_dated_and_an_older_duplicate_is_stale() {
        let mut bytes = nmea_epoch(0).into_bytes();
        bytes.extend_from_slice(nmea_epoch(1).as_bytes());
        bytes.extend_from_slice(&pvt_frame(2));
        bytes.extend_from_slice(&pvt_frame(3));
        // The NMEA copy of epoch 3, after UBX sent it.
        bytes.extend_from_slice(nmea_epoch(3).as_bytes());
        let (out, rep) = run(&bytes);
        let t0 = fusion::time::GpsTime::from_utc(2025, 3, 20, 21, 0, 0.0).ns;
        let times: Vec<i64> = out
            .iter()
            .map(|s| (s.header.time_ns - t0) / 1_000_000_000)
            .collect();
        assert_eq!(times, [0, 1, 2, 3]);
        assert_eq!(out[0].header.status, sample::STATUS_FROM_NMEA);
        assert_eq!(out[2].header.status, 0);
        assert_eq!(rep.epochs.epochs_stale, 1);
        assert_eq!(rep.epochs.fixes_published, 4);
        // GST's sigmas: 1.5 m north, 1.6 m east, 2.5 m down, and the height is MSL + separation.
        let g = fusion::earth::ecef_to_geodetic(
            &fusion::earth::WGS84,
            &nalgebra::Vector3::from(out[0].pos_ecef_m),
        );
        assert!((g.height_m - 200.0).abs() < 1e-6);
        let tr: f64 = [0, 4, 8].iter().map(|&i| out[0].pos_cov_ecef_m2[i]).sum();
        assert!((tr - (1.5f64.powi(2) + 1.6f64.powi(2) + 2.5f64.powi(2))).abs() < 1e-9);
    }

    #[test]
    fn undecodable_and_foreign_messages_are_counted() {
        let mut bytes = ubx_frame(0x01, 0x07, &[0; 10]);
        bytes.extend_from_slice(&ubx_frame(0x0A, 0x04, &[0; 4]));
        bytes.extend_from_slice(nmea_sentence("GPGSV,1,1,01,05,40,100,40").as_bytes());
        bytes.extend_from_slice(nmea_sentence("GPGGA,999999,,,,,0,00,,,,,,,").as_bytes());
        let (out, rep) = run(&bytes);
        assert!(out.is_empty());
        assert_eq!(
            (
                rep.epochs.ubx_malformed,
                rep.epochs.ubx_ignored,
                rep.epochs.nmea_ignored,
                rep.epochs.nmea_malformed
            ),
            (1, 1, 1, 1)
        );
        assert_eq!(rep.framing.skipped_bytes, 0);
    }

    proptest! {
        /// A valid stream with bytes changed, inserted or removed at random: never a panic,
        /// samples strictly increasing in time, every byte accounted for.
        #[test]
        fn mutated_streams_never_panic_and_stay_ordered(
            edits in proptest::collection::vec((any::<usize>(), any::<u8>(), 0u8..3), 0..40),
        ) {
            let mut bytes = Vec::new();
            for k in 0..6 {
                bytes.extend_from_slice(&sat_frame(k));
                bytes.extend_from_slice(&pvt_frame(k));
                bytes.extend_from_slice(nmea_epoch(k).as_bytes());
            }
            for (at, b, op) in edits {
                let i = at % (bytes.len() + 1);
                match op {
                    0 if i < bytes.len() => bytes[i] = b,
                    1 => bytes.insert(i, b),
                    _ if i < bytes.len() => { bytes.remove(i); }
                    _ => {}
                }
            }
            let (out, rep) = run(&bytes);
            prop_assert!(out.windows(2).all(|w| w[0].header.time_ns < w[1].header.time_ns));
            prop_assert_eq!(rep.epochs.samples_published as usize, out.len());
            prop_assert_eq!(rep.framing.bytes_in as usize, bytes.len());
        }
    }
}
