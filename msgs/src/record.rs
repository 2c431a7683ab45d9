//! One message of any kind: the sum of every channel's message and of the fusion daemon's own
//! sensor alive/dead events. The daemon receives, produces and records these; the recording
//! reader yields them; the offline simulation streams them; replay and the benchmark feed them
//! to the navigator. One enum for all of them, so that the live and offline paths cannot
//! diverge in what they carry.
//!
//! The two large messages (GNSS ≈ 4 kB with 32 satellites, status ≈ 1 kB) are boxed: a
//! [`Record`] travels through the recorder's bounded queue, whose slots are allocated up front
//! at the size of the largest variant. The box costs one allocation per GNSS sample and per
//! status, nothing per IMU sample.

use crate::{
    BaroSample, Channel, GnssSample, Header, ImuSample, NavSolution, OdometerSample, SensorId,
    StarTrackerSample, Status, TruthSample,
};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Topic of the sensor alive/dead transitions in recordings (not a channel: the fusion daemon
/// decides them from each sensor's deadline, nothing publishes them).
pub const SENSOR_ALIVE_TOPIC: &str = "fusion/sensor_alive";

/// Schema name of [`SensorAliveEvent`] in recordings.
pub const SENSOR_ALIVE_SCHEMA_NAME: &str = "sextant::SensorAliveEvent";

/// A sensor alive/dead transition decided by the fusion daemon and pushed into the navigator
/// (an input that does not come from a sensor, recorded for bit-exact replay).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SensorAliveEvent {
    /// `time_ns` = filter time (time of validity of the last IMU sample pushed, GPS ns; 0 before
    /// the first), `seq` = event counter, `send_mono_ns` = CLOCK_MONOTONIC of the decision.
    pub header: Header,
    /// Sensor index ([`SensorId`] as u32).
    pub sensor: u32,
    /// True: the sensor delivers again; false: silent beyond its deadline.
    pub alive: bool,
}

impl SensorAliveEvent {
    /// The sensor, `None` for an index that names none.
    pub fn sensor_id(&self) -> Option<SensorId> {
        SensorId::from_index(self.sensor as usize)
    }
}

/// What a [`Record`] is: the message of a channel, or a sensor alive/dead event.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RecordKind {
    /// The message of a channel.
    Channel(Channel),
    /// A [`SensorAliveEvent`].
    SensorAlive,
}

impl RecordKind {
    /// The recording topic: the channel's name, or [`SENSOR_ALIVE_TOPIC`].
    pub fn topic(self) -> &'static str {
        match self {
            Self::Channel(c) => c.name(),
            Self::SensorAlive => SENSOR_ALIVE_TOPIC,
        }
    }

    /// The kind recorded under `topic`, `None` for any other topic.
    pub fn from_topic(topic: &str) -> Option<Self> {
        if topic == SENSOR_ALIVE_TOPIC {
            return Some(Self::SensorAlive);
        }
        Channel::from_name(topic).map(Self::Channel)
    }
}

/// One message of any kind (see the module comment).
#[derive(Debug, Clone, PartialEq)]
pub enum Record {
    /// IMU sample.
    Imu(ImuSample),
    /// Star-tracker sample.
    StarTracker(StarTrackerSample),
    /// GNSS sample (boxed: it is large).
    Gnss(Box<GnssSample>),
    /// Odometer sample.
    Odometer(OdometerSample),
    /// Baro sample.
    Baro(BaroSample),
    /// Truth sample (evaluation only: never an input of the navigator).
    Truth(TruthSample),
    /// Solution.
    Nav(NavSolution),
    /// Status (boxed: it is large).
    Status(Box<Status>),
    /// Sensor alive/dead transition pushed into the navigator.
    SensorAlive(SensorAliveEvent),
}

impl Record {
    /// What the record is.
    pub fn kind(&self) -> RecordKind {
        RecordKind::Channel(match self {
            Record::Imu(_) => Channel::Imu,
            Record::StarTracker(_) => Channel::StarTracker,
            Record::Gnss(_) => Channel::Gnss,
            Record::Odometer(_) => Channel::Odometer,
            Record::Baro(_) => Channel::Baro,
            Record::Truth(_) => Channel::Truth,
            Record::Nav(_) => Channel::Nav,
            Record::Status(_) => Channel::Status,
            Record::SensorAlive(_) => return RecordKind::SensorAlive,
        })
    }

    /// The channel of the record (`None` for the daemon's own events).
    pub fn channel(&self) -> Option<Channel> {
        match self.kind() {
            RecordKind::Channel(c) => Some(c),
            RecordKind::SensorAlive => None,
        }
    }

    /// The recording topic of the record.
    pub fn topic(&self) -> &'static str {
        self.kind().topic()
    }

    /// The message header.
    pub fn header(&self) -> &Header {
        match self {
            Record::Imu(m) => &m.header,
            Record::StarTracker(m) => &m.header,
            Record::Gnss(m) => &m.header,
            Record::Odometer(m) => &m.header,
            Record::Baro(m) => &m.header,
            Record::Truth(m) => &m.header,
            Record::Nav(m) => &m.header,
            Record::Status(m) => &m.header,
            Record::SensorAlive(m) => &m.header,
        }
    }

    /// Time of validity, GPS ns.
    pub fn time_ns(&self) -> i64 {
        self.header().time_ns
    }

    /// Write the message as JSON into `buf` (cleared first), as recordings hold it.
    pub fn write_json(&self, buf: &mut Vec<u8>) -> serde_json::Result<()> {
        buf.clear();
        match self {
            Record::Imu(m) => serde_json::to_writer(buf, m),
            Record::StarTracker(m) => serde_json::to_writer(buf, m),
            Record::Gnss(m) => serde_json::to_writer(buf, m.as_ref()),
            Record::Odometer(m) => serde_json::to_writer(buf, m),
            Record::Baro(m) => serde_json::to_writer(buf, m),
            Record::Truth(m) => serde_json::to_writer(buf, m),
            Record::Nav(m) => serde_json::to_writer(buf, m),
            Record::Status(m) => serde_json::to_writer(buf, m.as_ref()),
            Record::SensorAlive(m) => serde_json::to_writer(buf, m),
        }
    }

    /// Write the message in its protobuf wire form into `buf` (cleared first), as compact
    /// recordings hold it (see [`crate::protobuf`]).
    pub fn write_protobuf(&self, buf: &mut Vec<u8>) {
        use crate::protobuf::encode;
        match self {
            Record::Imu(m) => encode(m, buf),
            Record::StarTracker(m) => encode(m, buf),
            Record::Gnss(m) => encode(m.as_ref(), buf),
            Record::Odometer(m) => encode(m, buf),
            Record::Baro(m) => encode(m, buf),
            Record::Truth(m) => encode(m, buf),
            Record::Nav(m) => encode(m, buf),
            Record::Status(m) => encode(m.as_ref(), buf),
            Record::SensorAlive(m) => encode(m, buf),
        }
    }

    /// Read a record of `kind` from its protobuf wire form (the inverse of
    /// [`Record::write_protobuf`], bit for bit).
    pub fn from_protobuf(
        kind: RecordKind,
        data: &[u8],
    ) -> Result<Self, crate::protobuf::DecodeError> {
        use crate::protobuf::decode;
        Ok(match kind {
            RecordKind::SensorAlive => Record::SensorAlive(decode(data)?),
            RecordKind::Channel(c) => match c {
                Channel::Imu => Record::Imu(decode(data)?),
                Channel::StarTracker => Record::StarTracker(decode(data)?),
                Channel::Gnss => Record::Gnss(Box::new(decode(data)?)),
                Channel::Odometer => Record::Odometer(decode(data)?),
                Channel::Baro => Record::Baro(decode(data)?),
                Channel::Truth => Record::Truth(decode(data)?),
                Channel::Nav => Record::Nav(decode(data)?),
                Channel::Status => Record::Status(Box::new(decode(data)?)),
            },
        })
    }

    /// Read a record of `kind` from its JSON (the inverse of [`Record::write_json`]).
    pub fn from_json(kind: RecordKind, data: &[u8]) -> serde_json::Result<Self> {
        use serde_json::from_slice;
        Ok(match kind {
            RecordKind::SensorAlive => Record::SensorAlive(from_slice(data)?),
            RecordKind::Channel(c) => match c {
                Channel::Imu => Record::Imu(from_slice(data)?),
                Channel::StarTracker => Record::StarTracker(from_slice(data)?),
                Channel::Gnss => Record::Gnss(Box::new(from_slice(data)?)),
                Channel::Odometer => Record::Odometer(from_slice(data)?),
                Channel::Baro => Record::Baro(from_slice(data)?),
                Channel::Truth => Record::Truth(from_slice(data)?),
                Channel::Nav => Record::Nav(from_slice(data)?),
                Channel::Status => Record::Status(Box::new(from_slice(data)?)),
            },
        })
    }
}

impl RecordKind {
    /// The protobuf schema of the kind: the message's full name and the serialized
    /// `FileDescriptorSet` (MCAP schema name and data, encoding `protobuf`).
    pub fn protobuf_schema(self) -> (&'static str, Vec<u8>) {
        use crate::protobuf::{ProtoMessage, file_descriptor_set as fds};
        fn of<M: ProtoMessage>() -> (&'static str, Vec<u8>) {
            (M::FULL_NAME, fds::<M>())
        }
        match self {
            RecordKind::SensorAlive => of::<SensorAliveEvent>(),
            RecordKind::Channel(c) => match c {
                Channel::Imu => of::<ImuSample>(),
                Channel::StarTracker => of::<StarTrackerSample>(),
                Channel::Gnss => of::<GnssSample>(),
                Channel::Odometer => of::<OdometerSample>(),
                Channel::Baro => of::<BaroSample>(),
                Channel::Truth => of::<TruthSample>(),
                Channel::Nav => of::<NavSolution>(),
                Channel::Status => of::<Status>(),
            },
        }
    }
}

macro_rules! record_from {
    ($t:ty, $var:ident) => {
        impl From<$t> for Record {
            fn from(m: $t) -> Self {
                Record::$var(m)
            }
        }
    };
    ($t:ty, $var:ident, boxed) => {
        impl From<$t> for Record {
            fn from(m: $t) -> Self {
                Record::$var(Box::new(m))
            }
        }
    };
}
record_from!(ImuSample, Imu);
record_from!(StarTrackerSample, StarTracker);
record_from!(GnssSample, Gnss, boxed);
record_from!(OdometerSample, Odometer);
record_from!(BaroSample, Baro);
record_from!(TruthSample, Truth);
record_from!(NavSolution, Nav);
record_from!(Status, Status, boxed);
record_from!(SensorAliveEvent, SensorAlive);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_round_trips_through_json_and_topic() {
        let mut records = vec![
            Record::Imu(ImuSample::default()),
            Record::StarTracker(StarTrackerSample::default()),
            Record::Gnss(Box::default()),
            Record::Odometer(OdometerSample::default()),
            Record::Baro(BaroSample::default()),
            Record::Truth(TruthSample::default()),
            Record::Nav(NavSolution::default()),
            Record::Status(Box::default()),
            Record::SensorAlive(SensorAliveEvent {
                sensor: SensorId::Gnss as u32,
                alive: true,
                ..Default::default()
            }),
        ];
        for (k, r) in records.iter_mut().enumerate() {
            let mut h = Header {
                time_ns: 1_400_000_000_000_000_000 + k as i64,
                seq: k as u64 + 1,
                ..Default::default()
            };
            h.status = k as u32;
            match r {
                Record::Imu(m) => m.header = h,
                Record::StarTracker(m) => m.header = h,
                Record::Gnss(m) => m.header = h,
                Record::Odometer(m) => m.header = h,
                Record::Baro(m) => m.header = h,
                Record::Truth(m) => m.header = h,
                Record::Nav(m) => m.header = h,
                Record::Status(m) => m.header = h,
                Record::SensorAlive(m) => m.header = h,
            }
        }
        let mut buf = Vec::new();
        for r in &records {
            r.write_json(&mut buf).unwrap();
            let kind = RecordKind::from_topic(r.topic()).unwrap();
            assert_eq!(kind, r.kind());
            assert_eq!(&Record::from_json(kind, &buf).unwrap(), r);
        }
        assert_eq!(RecordKind::from_topic("nav/pose"), None);
    }
}
