//! Splitting a receiver's byte stream into UBX frames and NMEA 0183 sentences.
//!
//! A u-blox receiver interleaves both protocols on one port, and a serial line adds noise, lost
//! bytes and half frames after a reconnect. The [`Framer`] scans the bytes once, in order:
//!
//! - `0xB5 0x62` starts a UBX frame (u-blox Interface Description, "UBX frame structure"):
//!   class, id, a little-endian payload length, the payload and the two-byte 8-bit Fletcher
//!   checksum over class..payload. A length above [`MAX_UBX_PAYLOAD`] is not a frame.
//! - `$` starts an NMEA sentence (NMEA 0183 §5.3): printable ASCII up to `*`, two hex digits of
//!   the XOR of the characters between `$` and `*`, then CR LF. At most [`MAX_NMEA_LEN`] bytes.
//!
//! Every byte that is not part of a frame whose checksum holds is *skipped* and counted in
//! [`FramingCounters::skipped_bytes`]; the event that caused it is counted too (a checksum
//! failure, a sentence cut short by the start of the next one, a frame left incomplete at the
//! end of the input). After a UBX checksum failure only the sync byte is dropped and scanning
//! resumes right after it, so that a valid frame hidden behind a truncated one is still found.
//! Nothing here allocates per byte, and no input makes it panic (property-tested).

use serde::Serialize;

/// Largest UBX payload accepted, bytes. RXM-RAWX with 32 measurements is 1040 bytes and
/// NAV-SAT with 170 satellites 2048; a larger length field is taken for noise, so that a
/// false sync in garbage cannot hold back the frames behind it for more than 2 KiB.
pub const MAX_UBX_PAYLOAD: usize = 2048;
/// Longest NMEA sentence accepted, `$` to LF included. The standard's limit is 82; u-blox
/// receivers emit longer GSV/GSA sentences with several constellations.
pub const MAX_NMEA_LEN: usize = 120;

const SYNC_1: u8 = 0xB5;
const SYNC_2: u8 = 0x62;
/// Sync (2) + class + id + length (2).
const UBX_HEADER_LEN: usize = 6;
/// Header + checksum (2).
const UBX_OVERHEAD: usize = UBX_HEADER_LEN + 2;

/// One complete frame whose checksum holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Frame {
    /// A UBX frame.
    Ubx {
        /// Message class.
        class: u8,
        /// Message id within the class.
        id: u8,
        /// Payload bytes.
        payload: Vec<u8>,
    },
    /// An NMEA sentence: the characters between `$` and `*` (talker, type and fields).
    Nmea(String),
}

/// What the framer has seen so far. Every counter only grows.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct FramingCounters {
    /// Bytes given to the framer.
    pub bytes_in: u64,
    /// Bytes that were not part of a valid frame (garbage, failed and truncated frames).
    pub skipped_bytes: u64,
    /// UBX frames whose checksum held.
    pub ubx_frames: u64,
    /// UBX frames whose checksum failed.
    pub ubx_checksum_errors: u64,
    /// NMEA sentences whose checksum held.
    pub nmea_sentences: u64,
    /// NMEA sentences whose checksum failed.
    pub nmea_checksum_errors: u64,
    /// NMEA sentences without a checksum, with a non-hex checksum, longer than
    /// [`MAX_NMEA_LEN`] or not ending in CR LF.
    pub nmea_malformed: u64,
    /// Frames cut short: an NMEA sentence interrupted by a byte that cannot be part of it, or
    /// any frame left incomplete at the end of the input.
    pub truncated_frames: u64,
}

/// Incremental framer: feed bytes as they arrive with [`Framer::push`], take complete frames
/// with [`Framer::next_frame`], and call [`Framer::finish`] at the end of the input.
#[derive(Debug, Default)]
pub struct Framer {
    buf: Vec<u8>,
    /// Index of the first byte not yet consumed.
    pos: usize,
    counters: FramingCounters,
    /// The input has ended ([`Framer::finish`]).
    ended: bool,
    /// The frame left open at the end has been counted.
    open_counted: bool,
}

/// Outcome of looking at the byte at the scan position.
enum Step {
    Frame(Frame, usize),
    /// Skip this many bytes (counted).
    Skip(usize),
    /// Wait for more input.
    NeedMore,
}

impl Framer {
    /// An empty framer.
    pub fn new() -> Self {
        Self::default()
    }

    /// Counters so far.
    pub fn counters(&self) -> FramingCounters {
        self.counters
    }

    /// Append received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        // Drop what was consumed before growing, so the buffer stays at most one partial frame
        // plus one read.
        if self.pos > 0 {
            self.buf.drain(..self.pos);
            self.pos = 0;
        }
        self.buf.extend_from_slice(bytes);
        self.counters.bytes_in += bytes.len() as u64;
    }

    /// The next complete frame, or `None` when more input is needed.
    pub fn next_frame(&mut self) -> Option<Frame> {
        loop {
            match self.step() {
                Step::Frame(f, len) => {
                    self.pos += len;
                    match f {
                        Frame::Ubx { .. } => self.counters.ubx_frames += 1,
                        Frame::Nmea(_) => self.counters.nmea_sentences += 1,
                    }
                    return Some(f);
                }
                Step::Skip(n) => {
                    self.pos += n;
                    self.counters.skipped_bytes += n as u64;
                }
                Step::NeedMore if self.ended && self.pos < self.buf.len() => {
                    if !self.open_counted {
                        self.counters.truncated_frames += 1;
                        self.open_counted = true;
                    }
                    self.pos += 1;
                    self.counters.skipped_bytes += 1;
                }
                Step::NeedMore => return None,
            }
        }
    }

    /// End of input: from now on a frame still waiting for its remaining bytes is counted as
    /// truncated (once) and its bytes are scanned again as if it had not started there, so that
    /// a valid frame behind it is still found by [`Framer::next_frame`]; whatever is left over
    /// is skipped.
    pub fn finish(&mut self) {
        self.ended = true;
    }

    fn step(&mut self) -> Step {
        let rest = &self.buf[self.pos..];
        let Some(&first) = rest.first() else {
            return Step::NeedMore;
        };
        match first {
            SYNC_1 => self.step_ubx(),
            b'$' => self.step_nmea(),
            _ => {
                // Skip the whole run of bytes that cannot start a frame at once.
                let n = rest
                    .iter()
                    .position(|&b| b == SYNC_1 || b == b'$')
                    .unwrap_or(rest.len());
                Step::Skip(n)
            }
        }
    }

    fn step_ubx(&mut self) -> Step {
        let rest = &self.buf[self.pos..];
        if rest.len() < 2 {
            return Step::NeedMore;
        }
        if rest[1] != SYNC_2 {
            return Step::Skip(1);
        }
        if rest.len() < UBX_HEADER_LEN {
            return Step::NeedMore;
        }
        let len = usize::from(u16::from_le_bytes([rest[4], rest[5]]));
        if len > MAX_UBX_PAYLOAD {
            return Step::Skip(1);
        }
        let total = len + UBX_OVERHEAD;
        if rest.len() < total {
            return Step::NeedMore;
        }
        let (ck_a, ck_b) = fletcher8(&rest[2..UBX_HEADER_LEN + len]);
        if ck_a != rest[total - 2] || ck_b != rest[total - 1] {
            self.counters.ubx_checksum_errors += 1;
            return Step::Skip(1);
        }
        Step::Frame(
            Frame::Ubx {
                class: rest[2],
                id: rest[3],
                payload: rest[UBX_HEADER_LEN..UBX_HEADER_LEN + len].to_vec(),
            },
            total,
        )
    }

    fn step_nmea(&mut self) -> Step {
        let rest = &self.buf[self.pos..];
        // Find the end of the line, or the first byte that cannot belong to a sentence.
        let limit = rest.len().min(MAX_NMEA_LEN);
        let mut end = None;
        for (i, &b) in rest.iter().enumerate().take(limit).skip(1) {
            match b {
                b'\n' => {
                    end = Some(i);
                    break;
                }
                b'\r' | 0x20..=0x7E if b != b'$' => {}
                _ => {
                    // The start of another frame or a byte no sentence holds: this one was
                    // cut short. Skip it up to (not including) that byte.
                    self.counters.truncated_frames += 1;
                    return Step::Skip(i);
                }
            }
        }
        let Some(lf) = end else {
            if rest.len() >= MAX_NMEA_LEN {
                self.counters.nmea_malformed += 1;
                return Step::Skip(1);
            }
            return Step::NeedMore;
        };
        let line = &rest[..=lf];
        match check_sentence(line) {
            Ok(body) => Step::Frame(Frame::Nmea(body), line.len()),
            Err(SentenceFault::Checksum) => {
                self.counters.nmea_checksum_errors += 1;
                Step::Skip(line.len())
            }
            Err(SentenceFault::Malformed) => {
                self.counters.nmea_malformed += 1;
                Step::Skip(line.len())
            }
        }
    }
}

enum SentenceFault {
    Checksum,
    Malformed,
}

/// Check `$body*HH\r\n` (printable ASCII already checked) and return the body.
fn check_sentence(line: &[u8]) -> Result<String, SentenceFault> {
    let Some(text) = line.strip_suffix(b"\r\n") else {
        return Err(SentenceFault::Malformed);
    };
    // text = "$" body "*" HH
    if text.len() < 4 || text[text.len() - 3] != b'*' {
        return Err(SentenceFault::Malformed);
    }
    let body = &text[1..text.len() - 3];
    if body.contains(&b'*') || body.contains(&b'\r') {
        return Err(SentenceFault::Malformed);
    }
    let hex = std::str::from_utf8(&text[text.len() - 2..]).map_err(|_| SentenceFault::Malformed)?;
    let want = u8::from_str_radix(hex, 16).map_err(|_| SentenceFault::Malformed)?;
    if nmea_checksum(body) != want {
        return Err(SentenceFault::Checksum);
    }
    // Printable ASCII was checked by the caller, so this cannot fail.
    String::from_utf8(body.to_vec()).map_err(|_| SentenceFault::Malformed)
}

/// The UBX 8-bit Fletcher checksum (CK_A, CK_B) of `bytes` (class through payload).
pub fn fletcher8(bytes: &[u8]) -> (u8, u8) {
    let mut a = 0u8;
    let mut b = 0u8;
    for &x in bytes {
        a = a.wrapping_add(x);
        b = b.wrapping_add(a);
    }
    (a, b)
}

/// The NMEA checksum: XOR of the characters between `$` and `*`.
pub fn nmea_checksum(body: &[u8]) -> u8 {
    body.iter().fold(0, |acc, &b| acc ^ b)
}

/// A complete UBX frame (sync, class, id, length, payload, checksum) for `payload`.
///
/// # Panics
/// When `payload` is longer than 65535 bytes, which no UBX message is.
pub fn ubx_frame(class: u8, id: u8, payload: &[u8]) -> Vec<u8> {
    let len = u16::try_from(payload.len()).expect("UBX payload fits in 16 bits");
    let mut out = Vec::with_capacity(payload.len() + UBX_OVERHEAD);
    out.extend_from_slice(&[SYNC_1, SYNC_2, class, id]);
    out.extend_from_slice(&len.to_le_bytes());
    out.extend_from_slice(payload);
    let (a, b) = fletcher8(&out[2..]);
    out.extend_from_slice(&[a, b]);
    out
}

/// A complete NMEA sentence `$body*HH\r\n` for `body` (talker, type and fields).
pub fn nmea_sentence(body: &str) -> String {
    format!("${body}*{:02X}\r\n", nmea_checksum(body.as_bytes()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn frames_of(bytes: &[u8]) -> (Vec<Frame>, FramingCounters) {
        let mut f = Framer::new();
        f.push(bytes);
        let mut out = Vec::new();
        while let Some(fr) = f.next_frame() {
            out.push(fr);
        }
        f.finish();
        while let Some(fr) = f.next_frame() {
            out.push(fr);
        }
        (out, f.counters())
    }

    #[test]
    fn checksums_match_published_examples() {
        // UBX-CFG-PRT poll (class 0x06, id 0x00, empty payload): B5 62 06 00 00 00 06 18,
        // the example of the u-blox M8 interface description.
        assert_eq!(
            ubx_frame(0x06, 0x00, &[]),
            [0xB5, 0x62, 0x06, 0x00, 0, 0, 0x06, 0x18]
        );
        // A GGA sentence as printed in NMEA references, with its checksum 47.
        let body = "GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,";
        assert_eq!(nmea_checksum(body.as_bytes()), 0x47);
    }

    #[test]
    fn frames_among_garbage_bad_checksums_and_truncations_are_found_and_counted() {
        let pvt = ubx_frame(0x01, 0x07, &[7u8; 92]);
        let gga = nmea_sentence("GPGGA,000000.00,,,,,0,00,99.99,,,,,,");
        let mut bad_ubx = ubx_frame(0x01, 0x35, &[1, 2, 3, 4]);
        let n = bad_ubx.len();
        bad_ubx[n - 1] ^= 0xFF;
        let mut bad_nmea = nmea_sentence("GPRMC,,V,,,,,,,,,,N").into_bytes();
        bad_nmea[3] = b'X';
        let garbage = [0x00u8, 0xFF, 0x13, b'x', 0xB5, 0x00];
        let truncated_nmea = b"$GPGSA,A,3,0".to_vec();
        let truncated_ubx = pvt[..20].to_vec();
        let mut stream = Vec::new();
        stream.extend_from_slice(&garbage);
        stream.extend_from_slice(&pvt);
        stream.extend_from_slice(&bad_ubx);
        stream.extend_from_slice(gga.as_bytes());
        stream.extend_from_slice(&bad_nmea);
        stream.extend_from_slice(&truncated_nmea);
        stream.extend_from_slice(gga.as_bytes());
        stream.extend_from_slice(&truncated_ubx);
        stream.extend_from_slice(&pvt);
        stream.extend_from_slice(&truncated_ubx);
        let (frames, c) = frames_of(&stream);
        assert_eq!(frames.len(), 4, "{frames:?}");
        assert_eq!(c.ubx_frames, 2);
        assert_eq!(c.nmea_sentences, 2);
        assert_eq!(c.nmea_checksum_errors, 1);
        // The truncated UBX frame in the middle swallows the start of the next one: its
        // checksum fails, the scan resumes after its sync byte and finds the next frame.
        assert_eq!(c.ubx_checksum_errors, 2);
        // The sentence cut by the next '$', and the frame left open at the end.
        assert_eq!(c.truncated_frames, 2);
        let valid = 2 * pvt.len() + 2 * gga.len();
        assert_eq!(c.skipped_bytes, (stream.len() - valid) as u64);
        assert_eq!(c.bytes_in, stream.len() as u64);
    }

    #[test]
    fn byte_by_byte_feeding_finds_the_same_frames() {
        let mut stream = b"junk".to_vec();
        stream.extend_from_slice(&ubx_frame(0x02, 0x15, &[9u8; 16]));
        stream.extend_from_slice(nmea_sentence("GNGST,1,2,3,4,5,6,7,8").as_bytes());
        let (whole, c_whole) = frames_of(&stream);
        let mut f = Framer::new();
        let mut one = Vec::new();
        for b in &stream {
            f.push(std::slice::from_ref(b));
            while let Some(fr) = f.next_frame() {
                one.push(fr);
            }
        }
        f.finish();
        while let Some(fr) = f.next_frame() {
            one.push(fr);
        }
        assert_eq!(one, whole);
        assert_eq!(f.counters(), c_whole);
    }

    proptest! {
        /// Arbitrary bytes, fed in arbitrary pieces: no panic, every byte either in a valid
        /// frame or counted as skipped.
        #[test]
        fn arbitrary_bytes_are_accounted_for(bytes in proptest::collection::vec(any::<u8>(), 0..2000),
                                              cut in 1usize..64) {
            let mut f = Framer::new();
            let mut framed = 0u64;
            let chunks: Vec<&[u8]> = bytes.chunks(cut).chain([&[][..]]).collect();
            for (i, chunk) in chunks.iter().enumerate() {
                f.push(chunk);
                if i == chunks.len() - 1 {
                    f.finish();
                }
                while let Some(fr) = f.next_frame() {
                    framed += match fr {
                        Frame::Ubx { payload, .. } => (payload.len() + UBX_OVERHEAD) as u64,
                        Frame::Nmea(body) => (body.len() + 6) as u64,
                    };
                }
            }
            prop_assert_eq!(framed + f.counters().skipped_bytes, bytes.len() as u64);
        }

        /// Valid frames with one byte changed: the damaged frame is never delivered as it
        /// was sent, the others are all found.
        #[test]
        fn a_mutated_frame_is_rejected_and_its_neighbours_kept(
            payload in proptest::collection::vec(any::<u8>(), 0..200),
            at in any::<usize>(), xor in 1u8..=255,
        ) {
            let good = ubx_frame(0x01, 0x07, &payload);
            let mut bad = good.clone();
            let i = at % bad.len();
            bad[i] ^= xor;
            let mut stream = good.clone();
            stream.extend_from_slice(&bad);
            stream.extend_from_slice(&good);
            let (frames, c) = frames_of(&stream);
            let want = Frame::Ubx { class: 0x01, id: 0x07, payload: payload.clone() };
            prop_assert!(frames.iter().filter(|f| **f == want).count() >= 2);
            // Fletcher-8 detects every single-byte change within class..payload; a change of
            // the sync bytes turns the frame into garbage. Either way it is not delivered.
            prop_assert_eq!(frames.len(), 2);
            prop_assert!(c.skipped_bytes >= 1);
        }
    }
}
