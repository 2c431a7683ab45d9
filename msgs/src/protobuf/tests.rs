//! Round trips, an independent decoder, pinned field numbers and bad input.

use super::*;
use crate::{
    BaroSample, GnssSample, GnssSatellite, Header, ImuSample, NavSolution, OdometerSample, Record,
    RecordKind, SensorAliveEvent, StarTrackerSample, Status, TruthSample,
};
use proptest::prelude::*;
use prost::encoding::{encode_key, encode_varint};

fn filled_gnss(seed: u64) -> GnssSample {
    let mut g = GnssSample {
        fix_valid: 1,
        n_satellites: 9,
        pos_ecef_m: [3_900_000.5, 1.0e-300, -4_900_000.25],
        pdop: 1.7,
        wavelength_m: 0.190_293_672_798_364_9,
        ..Default::default()
    };
    g.header.time_ns = 1_400_000_000_123_456_789;
    g.header.seq = seed;
    for (k, s) in g.satellites.iter_mut().take(9).enumerate() {
        s.prn = k as u32 + 1;
        s.flags = 7;
        s.pseudorange_m = 2.1e7 + k as f64 / 3.0;
        s.sat_pos_ecef_m = [1.5e7, -2.0e7 * (k as f64).sin(), 9.0e6];
        s.baseline_phase_cycles = [0.25, -0.0];
        s.phase_lock_time_s = [f64::MIN_POSITIVE, 1.0e308];
    }
    g
}

fn every_kind() -> Vec<Record> {
    let mut imu = ImuSample {
        dt_s: 0.001,
        delta_angle_rad: [1.0e-7 / 3.0, -(2.0f64.sqrt()), f64::NAN],
        delta_velocity_m_s: [f64::INFINITY, -0.0, f64::NEG_INFINITY],
        n_channels: 4,
        ..Default::default()
    };
    imu.channel_axis[3] = [0.6, 0.0, -0.8];
    imu.channel_temperature_c[7] = -40.0;
    imu.header.time_ns = -5;
    imu.header.send_mono_ns = u64::MAX;
    let mut status = Status {
        mode: 5,
        records_written: 1 << 40,
        gnss_ls_last_nis: 0.1 + 0.2,
        imu_held_at_time_jump: 3,
        latency_count: 7,
        latency_p99_us: 123.25,
        ..Default::default()
    };
    status.sensors[2].nis_sum = 1234.5;
    status.sensors[7].seq_gaps = u64::MAX;
    let mut nav = NavSolution {
        lat_rad: 0.9,
        stale: 1,
        ..Default::default()
    };
    nav.set_pos_cov_ned_m2(&[[4.0, 1.5, -0.25], [1.5, 9.0, 0.5], [-0.25, 0.5, 16.0]]);
    vec![
        Record::Imu(imu),
        Record::StarTracker(StarTrackerSample {
            q_sensor_icrf: [0.5, -0.5, 0.5, -0.5],
            valid: 1,
            ..Default::default()
        }),
        Record::Gnss(Box::new(filled_gnss(3))),
        Record::Odometer(OdometerSample {
            speed_m_s: 12.5,
            ..Default::default()
        }),
        Record::Baro(BaroSample {
            pressure_pa: 101_325.0,
            ..Default::default()
        }),
        Record::Truth(TruthSample {
            height_m: -12.0,
            ..Default::default()
        }),
        Record::Nav(nav),
        Record::Status(Box::new(status)),
        Record::SensorAlive(SensorAliveEvent {
            sensor: 2,
            alive: true,
            ..Default::default()
        }),
    ]
}

/// Equal bit for bit (NaN included): the records' Debug forms print every float exactly.
fn same(a: &Record, b: &Record) -> bool {
    format!("{a:?}") == format!("{b:?}")
}

#[test]
fn every_kind_round_trips_bit_for_bit() {
    let mut buf = Vec::new();
    for r in every_kind() {
        r.write_protobuf(&mut buf);
        let back = Record::from_protobuf(r.kind(), &buf).unwrap();
        assert!(same(&r, &back), "{r:?}\n{back:?}");
    }
    // An all-default message is all defaults after the round trip, too.
    let d = Record::Nav(NavSolution::default());
    d.write_protobuf(&mut buf);
    assert!(same(&d, &Record::from_protobuf(d.kind(), &buf).unwrap()));
}

/// Trailing defaults are left out of fixed-size arrays, and come back as defaults: an IMU
/// sample without redundant channels carries none of their 48 doubles, a GNSS epoch with nine
/// satellites no empty slot; a zero inside an array, a trailing `-0.0` and a last satellite
/// with only a PRN are kept.
#[test]
fn trailing_defaults_of_arrays_are_left_out_and_read_back() {
    let mut buf = Vec::new();
    let imu = ImuSample {
        dt_s: 0.005,
        delta_angle_rad: [1e-4, 0.0, 2e-4],
        delta_velocity_m_s: [0.0, 0.0, -0.0],
        ..Default::default()
    };
    Record::Imu(imu).write_protobuf(&mut buf);
    // Header (empty), dt, two packed triads (3 and 3 doubles: the -0.0 keeps the second).
    assert_eq!(buf.len(), 2 + 9 + 2 * (2 + 24), "{buf:?}");
    let back = Record::from_protobuf(Record::Imu(imu).kind(), &buf).unwrap();
    assert!(same(&Record::Imu(imu), &back));

    let mut g = filled_gnss(1);
    let full = {
        Record::Gnss(Box::new(g)).write_protobuf(&mut buf);
        buf.len()
    };
    g.satellites[9].prn = 31;
    Record::Gnss(Box::new(g)).write_protobuf(&mut buf);
    // One more element, holding only its PRN: key, length, PRN key and value.
    assert_eq!(buf.len(), full + 4);
    let back = Record::from_protobuf(Record::Gnss(Box::new(g)).kind(), &buf).unwrap();
    assert!(same(&Record::Gnss(Box::new(g)), &back));
    assert_eq!(
        GnssSample::default().satellites.len(),
        crate::MAX_SATELLITES,
        "the slots left out are the array's"
    );
}

/// A protobuf library that knows nothing of Sextant (prost-reflect) decodes every message
/// from the schema's descriptor alone, and finds the values the JSON form holds.
#[test]
fn an_independent_protobuf_library_decodes_every_kind_from_the_schema_alone() {
    use prost_reflect::{DescriptorPool, DynamicMessage, SerializeOptions};
    let mut buf = Vec::new();
    let mut json = Vec::new();
    for r in every_kind() {
        let (name, fds) = r.kind().protobuf_schema();
        let pool = DescriptorPool::decode(fds.as_slice()).unwrap();
        let desc = pool.get_message_by_name(name).unwrap();
        r.write_protobuf(&mut buf);
        let dynamic = DynamicMessage::decode(desc, buf.as_slice()).unwrap();
        let opts = SerializeOptions::new()
            .use_proto_field_name(true)
            .stringify_64_bit_integers(false)
            .skip_default_fields(false);
        let mut ser = serde_json::Serializer::new(Vec::new());
        dynamic.serialize_with_options(&mut ser, &opts).unwrap();
        let decoded: serde_json::Value = serde_json::from_slice(&ser.into_inner()).unwrap();
        r.write_json(&mut json).unwrap();
        let expected: serde_json::Value = serde_json::from_slice(&json).unwrap();
        // Trailing defaults of arrays are not written (module docs): compared as decoded.
        assert_json_matches(&as_decoded_json(expected), &decoded, r.topic());
    }
}

/// `expected` (serde's JSON of the struct in [`as_decoded_json`]'s form: nested arrays flat,
/// trailing defaults left out) against `decoded` (protobuf JSON mapping): equal, except that
/// protobuf's JSON writes
/// non-finite doubles as strings (serde writes `null`, which the recorder never does: such
/// records go elsewhere in JSON recordings).
fn assert_json_matches(expected: &serde_json::Value, decoded: &serde_json::Value, at: &str) {
    use serde_json::Value;
    match (expected, decoded) {
        (Value::Object(e), Value::Object(d)) => {
            assert_eq!(e.len(), d.len(), "{at}: {e:?} vs {d:?}");
            for (k, v) in e {
                let dv = d.get(k).unwrap_or_else(|| panic!("{at}.{k} missing"));
                assert_json_matches(v, dv, &format!("{at}.{k}"));
            }
        }
        (Value::Array(e), Value::Array(d)) => {
            assert_eq!(e.len(), d.len(), "{at}");
            for (i, (x, y)) in e.iter().zip(d).enumerate() {
                assert_json_matches(x, y, &format!("{at}[{i}]"));
            }
        }
        (Value::Null, Value::String(s)) => {
            assert!(
                ["NaN", "Infinity", "-Infinity"].contains(&s.as_str()),
                "{at}: {s}"
            );
        }
        (Value::Bool(e), Value::Number(n)) | (Value::Number(n), Value::Bool(e)) => {
            panic!("{at}: {e} vs {n}")
        }
        (Value::Number(e), Value::Number(d)) => {
            assert_eq!(
                e.as_f64().map(f64::to_bits),
                d.as_f64().map(f64::to_bits),
                "{at}"
            );
            assert_eq!(e.as_u64(), d.as_u64(), "{at}");
            assert_eq!(e.as_i64(), d.as_i64(), "{at}");
        }
        (e, d) => assert_eq!(e, d, "{at}"),
    }
}

/// The wire format is pinned: field numbers, names and types of every message, as
/// recordings already written hold them. A change here makes old recordings unreadable;
/// only additions with new numbers are allowed.
#[test]
fn field_numbers_are_pinned() {
    use prost::Message;
    let mut out = String::new();
    let kinds = [
        RecordKind::Channel(crate::Channel::Imu),
        RecordKind::Channel(crate::Channel::StarTracker),
        RecordKind::Channel(crate::Channel::Gnss),
        RecordKind::Channel(crate::Channel::Odometer),
        RecordKind::Channel(crate::Channel::Baro),
        RecordKind::Channel(crate::Channel::Truth),
        RecordKind::Channel(crate::Channel::Nav),
        RecordKind::Channel(crate::Channel::Status),
        RecordKind::SensorAlive,
    ];
    let mut seen = std::collections::BTreeSet::new();
    for k in kinds {
        let (_, fds) = k.protobuf_schema();
        let set = FileDescriptorSet::decode(fds.as_slice()).unwrap();
        for f in &set.file {
            for m in &f.message_type {
                if !seen.insert(format!("{}.{}", f.package(), m.name())) {
                    continue;
                }
                out.push_str(&format!("{}.{}\n", f.package(), m.name()));
                for fd in &m.field {
                    let line = format!(
                        "  {} {} {:?} {:?} {}",
                        fd.number(),
                        fd.name(),
                        fd.label(),
                        fd.r#type(),
                        fd.type_name()
                    );
                    out.push_str(line.trim_end());
                    out.push('\n');
                }
            }
        }
    }
    let pinned = include_str!("../../tests/protobuf_fields.txt");
    if out != pinned {
        panic!(
            "the protobuf form changed; if only by additions, update \
                msgs/tests/protobuf_fields.txt to:\n{out}"
        );
    }
}

#[test]
fn bad_input_names_the_message_and_the_field() {
    let mut buf = Vec::new();
    Record::Gnss(Box::new(filled_gnss(1))).write_protobuf(&mut buf);
    let kind = RecordKind::Channel(crate::Channel::Gnss);
    // Cut inside the satellites.
    let e = Record::from_protobuf(kind, &buf[..buf.len() - 3]).unwrap_err();
    assert!(
        matches!(
            e,
            DecodeError::Truncated {
                message: "sextant.GnssSample",
                field: "satellites"
            }
        ),
        "{e}"
    );
    // A 33rd satellite.
    let mut more = buf.clone();
    let one = {
        let mut b = Vec::new();
        GnssSatellite::default().encode(11, &mut b);
        b
    };
    for _ in 0..32 {
        more.extend_from_slice(&one);
    }
    let e = Record::from_protobuf(kind, &more).unwrap_err();
    assert_eq!(
        e,
        DecodeError::TooMany {
            message: "sextant.GnssSample",
            field: "satellites",
            capacity: 32
        }
    );
    assert_eq!(
        e.to_string(),
        "sextant.GnssSample.satellites: more than 32 elements"
    );
    // A double where a uint32 is declared.
    let mut wrong = Vec::new();
    encode_key(2, WireType::SixtyFourBit, &mut wrong);
    wrong.extend_from_slice(&1.0f64.to_le_bytes());
    let e = decode::<GnssSample>(&wrong).unwrap_err();
    assert_eq!(
        e,
        DecodeError::WireType {
            message: "sextant.GnssSample",
            field: "fix_valid",
            found: 1
        }
    );
    // A uint32 beyond its range.
    let mut big = Vec::new();
    encode_key(2, WireType::Varint, &mut big);
    encode_varint(1 << 33, &mut big);
    let e = decode::<GnssSample>(&big).unwrap_err();
    assert_eq!(
        e,
        DecodeError::OutOfRange {
            message: "sextant.GnssSample",
            field: "fix_valid"
        }
    );
    // Field number 0.
    assert_eq!(
        decode::<Header>(&[0x00]).unwrap_err(),
        DecodeError::InvalidKey {
            message: "sextant.Header"
        }
    );
}

#[test]
fn unknown_fields_are_skipped_and_missing_ones_read_as_zero() {
    let mut buf = Vec::new();
    let b = BaroSample {
        pressure_pa: 9.0e4,
        temperature_c: -3.5,
        ..Default::default()
    };
    encode(&b, &mut buf);
    let mut later = buf.clone();
    // A field a later version added: a varint, a double, a string and a fixed32.
    encode_key(99, WireType::Varint, &mut later);
    encode_varint(12345, &mut later);
    encode_key(100, WireType::SixtyFourBit, &mut later);
    later.extend_from_slice(&2.5f64.to_le_bytes());
    encode_key(101, WireType::LengthDelimited, &mut later);
    encode_varint(3, &mut later);
    later.extend_from_slice(b"abc");
    encode_key(102, WireType::ThirtyTwoBit, &mut later);
    later.extend_from_slice(&[1, 2, 3, 4]);
    assert_eq!(decode::<BaroSample>(&later).unwrap(), b);
    assert_eq!(decode::<BaroSample>(&[]).unwrap(), BaroSample::default());
}

#[test]
fn packed_and_unpacked_repeated_doubles_both_read() {
    let mut buf = Vec::new();
    for v in [1.0f64, -2.0] {
        encode_key(2, WireType::SixtyFourBit, &mut buf);
        buf.extend_from_slice(&v.to_le_bytes());
    }
    let st: StarTrackerSample = decode(&buf).unwrap();
    assert_eq!(st.q_sensor_icrf, [1.0, -2.0, 0.0, 0.0]);
}

#[test]
fn large_nested_messages_get_multi_byte_lengths() {
    // A GNSS sample's satellites are each over 127 bytes once filled, and the status's
    // sensors near it: the length prefix grows in place.
    let g = filled_gnss(7);
    let mut buf = Vec::new();
    encode(&g, &mut buf);
    assert_eq!(decode::<GnssSample>(&buf).unwrap(), g);
}

fn f64_bits() -> impl Strategy<Value = f64> {
    any::<u64>().prop_map(f64::from_bits)
}

proptest! {
    /// Any bytes: an error or a message, never a panic.
    #[test]
    fn arbitrary_bytes_never_panic(data in proptest::collection::vec(any::<u8>(), 0..600), k in 0usize..9) {
        let kind = every_kind()[k].kind();
        let _ = Record::from_protobuf(kind, &data);
    }

    /// Any values (every bit pattern of every double) round-trip exactly.
    #[test]
    fn arbitrary_messages_round_trip(
        t in any::<i64>(), seq in any::<u64>(), d in proptest::array::uniform3(f64_bits()),
        v in proptest::array::uniform3(f64_bits()), n in any::<u32>(), x in f64_bits(),
        sat in 0usize..32, prn in any::<u32>(),
    ) {
        let mut imu = ImuSample { dt_s: x, delta_angle_rad: d, delta_velocity_m_s: v, n_channels: n, ..Default::default() };
        imu.header.time_ns = t;
        imu.header.seq = seq;
        imu.channel_axis[n as usize % 8] = v;
        let mut g = filled_gnss(seq);
        g.satellites[sat].prn = prn;
        g.satellites[sat].range_rate_m_s = x;
        g.vel_cov_ecef_m2_s2[sat % 9] = d[0];
        let mut buf = Vec::new();
        for r in [Record::Imu(imu), Record::Gnss(Box::new(g))] {
            r.write_protobuf(&mut buf);
            let back = Record::from_protobuf(r.kind(), &buf).unwrap();
            prop_assert!(same(&r, &back));
        }
    }
}
