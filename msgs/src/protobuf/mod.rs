//! The Protocol Buffers form of every message: the compact binary encoding of recordings.
//!
//! MCAP's `protobuf` profile: a channel's schema record holds a serialized
//! `google.protobuf.FileDescriptorSet` describing the message (schema encoding `protobuf`, schema
//! name = the message's full name, e.g. `sextant.ImuSample`), and each message is the protobuf
//! wire form. Foxglove, Python's `mcap-protobuf-support` and any protobuf library decode it
//! from the schema alone, without Sextant's code.
//!
//! The mapping from the fixed-size message structs (proto3, package `sextant`):
//! - `f64` → `double`, `u32`/`u8` → `uint32`, `u64` → `uint64`, `i64` → `int64`,
//!   `bool` → `bool`; a scalar equal to its default (all bits zero: `-0.0` is written) is
//!   omitted, as proto3 does;
//! - `[f64; N]` → `repeated double` (packed); `[[f64; 3]; N]` → `repeated double` of the `3·N`
//!   elements row by row; `[u32; N]` → `repeated uint32` (packed);
//! - a nested struct → a message field, always written (even empty), so that every reader sees
//!   it present; `[M; N]` → `repeated M`;
//! - a fixed-size array is written up to its last element that is not at its default: trailing
//!   `+0.0` doubles (all bits zero), zero integers and messages with no field to write are
//!   left out, as proto3 leaves out a default scalar, and a reader fills the rest of the array
//!   with defaults (an array all at its default is absent). An IMU sample without redundant
//!   channels does not carry their 48 zeros, a GNSS epoch not its empty satellite slots;
//! - field numbers are explicit in the [`proto_message!`] declarations and never reused: a
//!   field is only ever added with a new number, so a recording stays readable by later
//!   versions (unknown fields are skipped, missing ones read as zero).
//!
//! Decoding is exact: doubles travel as their 64 bits, so a message read back equals the one
//! written bit for bit (what offline replay needs).

/// Protobuf wire types, as [`Field::merge`] receives them.
pub use prost::encoding::WireType;
use prost_types::{DescriptorProto, FieldDescriptorProto, FileDescriptorProto, FileDescriptorSet};
use std::collections::BTreeMap;

mod field;
mod messages;
#[cfg(test)]
mod tests;

pub use field::{Field, Occurrence, next_key, skip};

/// The schema encoding (MCAP `Schema.encoding`) and message encoding (MCAP
/// `Channel.message_encoding`) of this form.
pub const ENCODING: &str = "protobuf";

/// The JSON form of a message (serde's, of the struct) as an independent protobuf reader sees
/// the message decoded: an array of arrays flattened row by row, and every array without its
/// trailing elements at their default (`+0`, not `-0`; `false`; an object of defaults), which
/// the encoding leaves out (module docs). For comparing a message with what a generic protobuf
/// library decodes from a recording.
pub fn as_decoded_json(v: serde_json::Value) -> serde_json::Value {
    use serde_json::Value;
    fn is_default(v: &Value) -> bool {
        match v {
            Value::Number(n) => n.as_f64().map(f64::to_bits) == Some(0),
            Value::Bool(b) => !b,
            Value::String(s) => s.is_empty(),
            Value::Array(a) => a.iter().all(is_default),
            Value::Object(o) => o.values().all(is_default),
            Value::Null => false,
        }
    }
    match v {
        Value::Array(a) => {
            let flat = !a.is_empty() && a.iter().all(Value::is_array);
            let mut a: Vec<Value> = if flat {
                a.into_iter()
                    .flat_map(|row| match row {
                        Value::Array(r) => r,
                        other => vec![other],
                    })
                    .collect()
            } else {
                a.into_iter().map(as_decoded_json).collect()
            };
            while a.last().is_some_and(is_default) {
                a.pop();
            }
            Value::Array(a)
        }
        Value::Object(o) => Value::Object(
            o.into_iter()
                .map(|(k, v)| (k, as_decoded_json(v)))
                .collect(),
        ),
        other => other,
    }
}

/// Why a protobuf message could not be read. `message` and `field` name the message type and
/// the field (or `"?"` for a key that could not be read).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// The data ended inside a key, a value or a length-delimited field.
    #[error("{message}.{field}: the data ends inside the field")]
    Truncated {
        /// Message type.
        message: &'static str,
        /// Field.
        field: &'static str,
    },
    /// A key with field number 0, an unknown wire type or a group (not used by proto3).
    #[error("{message}: invalid field key")]
    InvalidKey {
        /// Message type.
        message: &'static str,
    },
    /// A known field arrived with a wire type its declared type cannot have.
    #[error("{message}.{field}: wire type {found} where the field's type needs another")]
    WireType {
        /// Message type.
        message: &'static str,
        /// Field.
        field: &'static str,
        /// The wire type found (0 varint, 1 fixed64, 2 length-delimited, 5 fixed32).
        found: u8,
    },
    /// A repeated field with more elements than its fixed-size array holds.
    #[error("{message}.{field}: more than {capacity} elements")]
    TooMany {
        /// Message type.
        message: &'static str,
        /// Field.
        field: &'static str,
        /// The array's length.
        capacity: usize,
    },
    /// An integer too large for the field's type (e.g. above `u32::MAX` in a `uint32`).
    #[error("{message}.{field}: integer out of the field's range")]
    OutOfRange {
        /// Message type.
        message: &'static str,
        /// Field.
        field: &'static str,
    },
    /// A nested message nested deeper than any Sextant message is.
    #[error("{message}: messages nested too deep")]
    TooDeep {
        /// Message type.
        message: &'static str,
    },
}

/// What went wrong in one field, before the message adds its own and the field's name.
#[doc(hidden)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FieldError {
    /// See [`DecodeError::Truncated`].
    Truncated,
    /// See [`DecodeError::WireType`].
    WireType(u8),
    /// See [`DecodeError::TooMany`].
    TooMany(usize),
    /// See [`DecodeError::OutOfRange`].
    OutOfRange,
    /// An error inside a nested message, already complete.
    Nested(DecodeError),
}

impl FieldError {
    /// The [`DecodeError`] of this error in `field` of `message`.
    #[doc(hidden)]
    pub fn at(self, message: &'static str, field: &'static str) -> DecodeError {
        match self {
            Self::Truncated => DecodeError::Truncated { message, field },
            Self::WireType(found) => DecodeError::WireType {
                message,
                field,
                found,
            },
            Self::TooMany(capacity) => DecodeError::TooMany {
                message,
                field,
                capacity,
            },
            Self::OutOfRange => DecodeError::OutOfRange { message, field },
            Self::Nested(e) => e,
        }
    }
}

/// A struct with a protobuf form, declared with [`proto_message!`].
pub trait ProtoMessage: Default {
    /// Full protobuf name, `package.Name` (e.g. `sextant.ImuSample`): the MCAP schema name.
    const FULL_NAME: &'static str;
    /// Append the message's fields (without a length prefix) to `buf`.
    fn encode_fields(&self, buf: &mut Vec<u8>);
    /// Read fields from `data` (one whole message) into `self`; `depth` counts the nesting.
    fn merge_fields(&mut self, data: &[u8], depth: u32) -> Result<(), DecodeError>;
    /// The message's descriptor (its name without the package) and, through `nested`, those of
    /// the message types its fields use, keyed by full name.
    fn describe(nested: &mut BTreeMap<&'static str, DescriptorProto>) -> DescriptorProto;
}

/// Messages nested deeper than this are refused (Sextant's go two levels deep): bounds the
/// recursion on hostile input.
const MAX_DEPTH: u32 = 8;

/// `message` in its protobuf wire form, into `buf` (cleared first).
pub fn encode<M: ProtoMessage>(message: &M, buf: &mut Vec<u8>) {
    buf.clear();
    message.encode_fields(buf);
}

/// Read a `M` from its protobuf wire form. Unknown fields are skipped; fields absent read as
/// zero.
pub fn decode<M: ProtoMessage>(data: &[u8]) -> Result<M, DecodeError> {
    let mut m = M::default();
    m.merge_fields(data, 0)?;
    Ok(m)
}

/// The serialized `FileDescriptorSet` describing `M` and every message type it uses (one file
/// per package, dependencies first): the MCAP schema data of a channel of `M`.
pub fn file_descriptor_set<M: ProtoMessage>() -> Vec<u8> {
    use prost::Message;
    let mut types = BTreeMap::new();
    let root = M::describe(&mut types);
    types.insert(M::FULL_NAME, root);
    // Group by package; a package's file depends on the files of the other packages it uses
    // (here only google.protobuf's well-known Timestamp), which therefore come first.
    let mut files: BTreeMap<&str, FileDescriptorProto> = BTreeMap::new();
    for (full, d) in types {
        let package = full.rsplit_once('.').map_or("", |(p, _)| p);
        let file = files.entry(package).or_insert_with(|| FileDescriptorProto {
            name: Some(file_name(package)),
            package: Some(package.to_string()),
            syntax: Some("proto3".to_string()),
            ..Default::default()
        });
        file.message_type.push(d);
    }
    let packages: Vec<&str> = files.keys().copied().collect();
    for file in files.values_mut() {
        let own = file.package().to_string();
        let uses: Vec<String> = file
            .message_type
            .iter()
            .flat_map(|d| d.field.iter())
            .filter_map(|f| f.type_name.as_deref())
            .filter_map(|t| t.strip_prefix('.')?.rsplit_once('.').map(|(p, _)| p))
            .filter(|p| *p != own && packages.contains(p))
            .map(file_name)
            .collect();
        for dep in uses {
            if !file.dependency.contains(&dep) {
                file.dependency.push(dep);
            }
        }
    }
    let mut ordered: Vec<FileDescriptorProto> = Vec::new();
    let (base, rest): (Vec<_>, Vec<_>) = files.into_values().partition(|f| f.dependency.is_empty());
    ordered.extend(base);
    ordered.extend(rest);
    FileDescriptorSet { file: ordered }.encode_to_vec()
}

fn file_name(package: &str) -> String {
    match package {
        "google.protobuf" => "google/protobuf/timestamp.proto".to_string(),
        p => format!("{}.proto", p.replace('.', "/")),
    }
}

/// Declare the protobuf form of a struct: its full name and, for each field, its number.
///
/// ```ignore
/// proto_message!(Header = "sextant.Header" { 1 => time_ns, 2 => seq });
/// ```
#[macro_export]
macro_rules! proto_message {
    ($t:ty = $full:literal { $($n:literal => $f:ident),+ $(,)? }) => {
        impl $crate::protobuf::ProtoMessage for $t {
            const FULL_NAME: &'static str = $full;
            fn encode_fields(&self, buf: &mut ::std::vec::Vec<u8>) {
                $( $crate::protobuf::Field::encode(&self.$f, $n, buf); )+
            }
            fn merge_fields(
                &mut self,
                mut data: &[u8],
                depth: u32,
            ) -> ::core::result::Result<(), $crate::protobuf::DecodeError> {
                #[allow(non_camel_case_types)]
                enum Counts { $($f),+ }
                let mut counts = [0usize; [$(Counts::$f),+].len()];
                while let Some((number, wire)) = $crate::protobuf::next_key(&mut data, $full)? {
                    match number {
                        $( $n => $crate::protobuf::Field::merge(
                            &mut self.$f,
                            $crate::protobuf::Occurrence {
                                wire,
                                data: &mut data,
                                count: &mut counts[Counts::$f as usize],
                                depth,
                            },
                        ).map_err(|e| e.at($full, stringify!($f)))?, )+
                        _ => $crate::protobuf::skip(wire, &mut data)
                            .map_err(|e| e.at($full, "?"))?,
                    }
                }
                Ok(())
            }
            fn describe(
                nested: &mut ::std::collections::BTreeMap<
                    &'static str,
                    $crate::protobuf::prost_types::DescriptorProto,
                >,
            ) -> $crate::protobuf::prost_types::DescriptorProto {
                $crate::protobuf::prost_types::DescriptorProto {
                    name: Some($full.rsplit('.').next().unwrap_or($full).to_string()),
                    field: vec![$(
                        $crate::protobuf::field_of(&|m: &$t| &m.$f, stringify!($f), $n, nested)
                    ),+],
                    ..Default::default()
                }
            }
        }
    };
}

/// The descriptor of the field `get` selects (type inference helper of [`proto_message!`]).
#[doc(hidden)]
pub fn field_of<T, F: Field>(
    _get: &dyn Fn(&T) -> &F,
    name: &str,
    number: u32,
    nested: &mut BTreeMap<&'static str, DescriptorProto>,
) -> FieldDescriptorProto {
    F::describe(name, number, nested)
}

#[doc(hidden)]
pub use prost_types;

/// `google.protobuf.Timestamp`, the well-known type Foxglove shows as a time: Unix seconds and
/// nanoseconds.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Timestamp {
    /// Seconds since 1970-01-01T00:00:00 UTC (leap seconds not counted).
    pub seconds: i64,
    /// Nanoseconds within the second, 0 ..= 999 999 999.
    pub nanos: i32,
}

impl Timestamp {
    /// The timestamp of Unix time `unix_ns`, ns.
    pub fn from_unix_ns(unix_ns: u64) -> Self {
        Self {
            seconds: (unix_ns / 1_000_000_000) as i64,
            nanos: (unix_ns % 1_000_000_000) as i32,
        }
    }
}

crate::proto_message!(Timestamp = "google.protobuf.Timestamp" { 1 => seconds, 2 => nanos });
