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
//! - `[f64; N]` → `repeated double` (packed), always all `N` elements; `[[f64; 3]; N]` →
//!   `repeated double` of the `3·N` elements row by row;
//! - a nested struct → a message field, always written (even empty), so that every reader sees
//!   it present; `[M; N]` → `repeated M`, all `N` elements;
//! - field numbers are explicit in the [`proto_message!`] declarations and never reused: a
//!   field is only ever added with a new number, so a recording stays readable by later
//!   versions (unknown fields are skipped, missing ones read as zero).
//!
//! Decoding is exact: doubles travel as their 64 bits, so a message read back equals the one
//! written bit for bit (what offline replay needs).

/// Protobuf wire types, as [`Field::merge`] receives them.
pub use prost::encoding::WireType;
use prost::encoding::{decode_varint, encode_key, encode_varint, encoded_len_varint};
use prost_types::field_descriptor_proto::{Label, Type};
use prost_types::{DescriptorProto, FieldDescriptorProto, FileDescriptorProto, FileDescriptorSet};
use std::collections::BTreeMap;

/// The schema encoding (MCAP `Schema.encoding`) and message encoding (MCAP
/// `Channel.message_encoding`) of this form.
pub const ENCODING: &str = "protobuf";

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

/// One occurrence of a field being read: its wire type, the data from its value on, the
/// elements of a repeated field already read, and the nesting depth of its message.
#[doc(hidden)]
pub struct Occurrence<'a, 'b> {
    /// The occurrence's wire type.
    pub wire: WireType,
    /// The data, from the occurrence's value on; advanced past it.
    pub data: &'a mut &'b [u8],
    /// Elements of a repeated field already read (fixed-size arrays fill from here).
    pub count: &'a mut usize,
    /// Nesting depth of the message holding the field.
    pub depth: u32,
}

/// One field's type: how it is written, read and described. Implemented for the scalar and
/// array types Sextant's messages use and for every [`ProtoMessage`].
#[doc(hidden)]
pub trait Field {
    /// Append the field with number `number` (nothing for a default scalar).
    fn encode(&self, number: u32, buf: &mut Vec<u8>);
    /// Merge one occurrence of the field.
    fn merge(&mut self, at: Occurrence<'_, '_>) -> Result<(), FieldError>;
    /// The field's descriptor; message types it uses go into `nested`.
    fn describe(
        name: &str,
        number: u32,
        nested: &mut BTreeMap<&'static str, DescriptorProto>,
    ) -> FieldDescriptorProto;
}

fn field_descriptor(
    name: &str,
    number: u32,
    ty: Type,
    repeated: bool,
    type_name: Option<&str>,
) -> FieldDescriptorProto {
    FieldDescriptorProto {
        name: Some(name.to_string()),
        number: Some(number as i32),
        label: Some(if repeated {
            Label::Repeated
        } else {
            Label::Optional
        } as i32),
        r#type: Some(ty as i32),
        type_name: type_name.map(|t| format!(".{t}")),
        ..Default::default()
    }
}

fn wire_code(w: WireType) -> u8 {
    w as u8
}

fn read_varint(data: &mut &[u8]) -> Result<u64, FieldError> {
    decode_varint(data).map_err(|_| FieldError::Truncated)
}

fn read_fixed64(data: &mut &[u8]) -> Result<u64, FieldError> {
    let (head, rest) = data.split_first_chunk::<8>().ok_or(FieldError::Truncated)?;
    *data = rest;
    Ok(u64::from_le_bytes(*head))
}

fn read_len_delimited<'a>(data: &mut &'a [u8]) -> Result<&'a [u8], FieldError> {
    let len = read_varint(data)?;
    let len = usize::try_from(len).map_err(|_| FieldError::Truncated)?;
    if len > data.len() {
        return Err(FieldError::Truncated);
    }
    let (body, rest) = data.split_at(len);
    *data = rest;
    Ok(body)
}

/// Skip a field of an unknown number.
#[doc(hidden)]
pub fn skip(wire: WireType, data: &mut &[u8]) -> Result<(), FieldError> {
    match wire {
        WireType::Varint => read_varint(data).map(|_| ()),
        WireType::SixtyFourBit => read_fixed64(data).map(|_| ()),
        WireType::LengthDelimited => read_len_delimited(data).map(|_| ()),
        WireType::ThirtyTwoBit => {
            let (_, rest) = data.split_first_chunk::<4>().ok_or(FieldError::Truncated)?;
            *data = rest;
            Ok(())
        }
        WireType::StartGroup | WireType::EndGroup => Err(FieldError::WireType(wire_code(wire))),
    }
}

/// Read the next key of a message: `None` at its end.
#[doc(hidden)]
pub fn next_key(
    data: &mut &[u8],
    message: &'static str,
) -> Result<Option<(u32, WireType)>, DecodeError> {
    if data.is_empty() {
        return Ok(None);
    }
    let key = decode_varint(data).map_err(|_| DecodeError::Truncated {
        message,
        field: "?",
    })?;
    let number = key >> 3;
    if number == 0 || number > u64::from(u32::MAX >> 3) {
        return Err(DecodeError::InvalidKey { message });
    }
    let wire = WireType::try_from(key & 7).map_err(|_| DecodeError::InvalidKey { message })?;
    Ok(Some((number as u32, wire)))
}

/// A length-delimited nested value written in place: the body is encoded after a one-byte
/// length, which grows to the varint the body's length needs.
fn encode_len_delimited(number: u32, buf: &mut Vec<u8>, body: impl FnOnce(&mut Vec<u8>)) {
    encode_key(number, WireType::LengthDelimited, buf);
    let at = buf.len();
    buf.push(0);
    body(buf);
    let len = buf.len() - at - 1;
    if len < 0x80 {
        buf[at] = len as u8;
    } else {
        let mut prefix = Vec::with_capacity(encoded_len_varint(len as u64));
        encode_varint(len as u64, &mut prefix);
        buf.splice(at..at + 1, prefix);
    }
}

macro_rules! varint_field {
    ($t:ty, $proto:expr, $to:expr, $from:expr) => {
        impl Field for $t {
            fn encode(&self, number: u32, buf: &mut Vec<u8>) {
                let v: u64 = $to(*self);
                if v != 0 {
                    encode_key(number, WireType::Varint, buf);
                    encode_varint(v, buf);
                }
            }
            fn merge(&mut self, at: Occurrence<'_, '_>) -> Result<(), FieldError> {
                let Occurrence { wire, data, .. } = at;
                if wire != WireType::Varint {
                    return Err(FieldError::WireType(wire_code(wire)));
                }
                *self = $from(read_varint(data)?)?;
                Ok(())
            }
            fn describe(
                name: &str,
                number: u32,
                _nested: &mut BTreeMap<&'static str, DescriptorProto>,
            ) -> FieldDescriptorProto {
                field_descriptor(name, number, $proto, false, None)
            }
        }
    };
}

varint_field!(u64, Type::Uint64, |v: u64| v, |v: u64| Ok(v));
varint_field!(i64, Type::Int64, |v: i64| v as u64, |v: u64| Ok(v as i64));
varint_field!(u32, Type::Uint32, u64::from, |v: u64| u32::try_from(v)
    .map_err(|_| FieldError::OutOfRange));
varint_field!(i32, Type::Int32, |v: i32| i64::from(v) as u64, |v: u64| {
    i32::try_from(v as i64).map_err(|_| FieldError::OutOfRange)
});
varint_field!(u8, Type::Uint32, u64::from, |v: u64| u8::try_from(v)
    .map_err(|_| FieldError::OutOfRange));
varint_field!(bool, Type::Bool, u64::from, |v: u64| match v {
    0 => Ok(false),
    1 => Ok(true),
    _ => Err(FieldError::OutOfRange),
});

impl Field for f64 {
    fn encode(&self, number: u32, buf: &mut Vec<u8>) {
        if self.to_bits() != 0 {
            encode_key(number, WireType::SixtyFourBit, buf);
            buf.extend_from_slice(&self.to_le_bytes());
        }
    }
    fn merge(&mut self, at: Occurrence<'_, '_>) -> Result<(), FieldError> {
        let Occurrence { wire, data, .. } = at;
        if wire != WireType::SixtyFourBit {
            return Err(FieldError::WireType(wire_code(wire)));
        }
        *self = f64::from_bits(read_fixed64(data)?);
        Ok(())
    }
    fn describe(
        name: &str,
        number: u32,
        _nested: &mut BTreeMap<&'static str, DescriptorProto>,
    ) -> FieldDescriptorProto {
        field_descriptor(name, number, Type::Double, false, None)
    }
}

/// A fixed number of doubles, flat: `[f64; N]` and `[[f64; 3]; N]` (row by row).
trait DoubleArray {
    fn values(&self) -> &[f64];
    fn values_mut(&mut self) -> &mut [f64];
}

impl<const N: usize> DoubleArray for [f64; N] {
    fn values(&self) -> &[f64] {
        self
    }
    fn values_mut(&mut self) -> &mut [f64] {
        self
    }
}

impl<const N: usize> DoubleArray for [[f64; 3]; N] {
    fn values(&self) -> &[f64] {
        self.as_flattened()
    }
    fn values_mut(&mut self) -> &mut [f64] {
        self.as_flattened_mut()
    }
}

fn encode_doubles(values: &[f64], number: u32, buf: &mut Vec<u8>) {
    encode_key(number, WireType::LengthDelimited, buf);
    encode_varint(8 * values.len() as u64, buf);
    for v in values {
        buf.extend_from_slice(&v.to_le_bytes());
    }
}

/// Packed (one length-delimited run) or not (one fixed64 per element): proto3 readers accept
/// both.
fn merge_doubles(
    values: &mut [f64],
    wire: WireType,
    data: &mut &[u8],
    count: &mut usize,
) -> Result<(), FieldError> {
    let capacity = values.len();
    let mut put = |bits: u64, count: &mut usize| {
        let slot = values
            .get_mut(*count)
            .ok_or(FieldError::TooMany(capacity))?;
        *slot = f64::from_bits(bits);
        *count += 1;
        Ok(())
    };
    match wire {
        WireType::SixtyFourBit => put(read_fixed64(data)?, count),
        WireType::LengthDelimited => {
            let mut body = read_len_delimited(data)?;
            if body.len() % 8 != 0 {
                return Err(FieldError::Truncated);
            }
            while !body.is_empty() {
                put(read_fixed64(&mut body)?, count)?;
            }
            Ok(())
        }
        w => Err(FieldError::WireType(wire_code(w))),
    }
}

macro_rules! double_array_field {
    ($($t:ty),*) => {$(
        impl<const N: usize> Field for $t {
            fn encode(&self, number: u32, buf: &mut Vec<u8>) {
                encode_doubles(self.values(), number, buf);
            }
            fn merge(&mut self, at: Occurrence<'_, '_>) -> Result<(), FieldError> {
                let Occurrence { wire, data, count, .. } = at;
                merge_doubles(self.values_mut(), wire, data, count)
            }
            fn describe(
                name: &str,
                number: u32,
                _nested: &mut BTreeMap<&'static str, DescriptorProto>,
            ) -> FieldDescriptorProto {
                field_descriptor(name, number, Type::Double, true, None)
            }
        }
    )*};
}
double_array_field!([f64; N], [[f64; 3]; N]);

impl<const N: usize> Field for [u32; N] {
    fn encode(&self, number: u32, buf: &mut Vec<u8>) {
        let len: usize = self.iter().map(|v| encoded_len_varint(u64::from(*v))).sum();
        encode_key(number, WireType::LengthDelimited, buf);
        encode_varint(len as u64, buf);
        for v in self {
            encode_varint(u64::from(*v), buf);
        }
    }
    fn merge(&mut self, at: Occurrence<'_, '_>) -> Result<(), FieldError> {
        let Occurrence {
            wire, data, count, ..
        } = at;
        let mut put = |v: u64, count: &mut usize| {
            let slot = self.get_mut(*count).ok_or(FieldError::TooMany(N))?;
            *slot = u32::try_from(v).map_err(|_| FieldError::OutOfRange)?;
            *count += 1;
            Ok(())
        };
        match wire {
            WireType::Varint => put(read_varint(data)?, count),
            WireType::LengthDelimited => {
                let mut body = read_len_delimited(data)?;
                while !body.is_empty() {
                    put(read_varint(&mut body)?, count)?;
                }
                Ok(())
            }
            w => Err(FieldError::WireType(wire_code(w))),
        }
    }
    fn describe(
        name: &str,
        number: u32,
        _nested: &mut BTreeMap<&'static str, DescriptorProto>,
    ) -> FieldDescriptorProto {
        field_descriptor(name, number, Type::Uint32, true, None)
    }
}

impl Field for String {
    fn encode(&self, number: u32, buf: &mut Vec<u8>) {
        if !self.is_empty() {
            encode_len_delimited(number, buf, |b| b.extend_from_slice(self.as_bytes()));
        }
    }
    fn merge(&mut self, at: Occurrence<'_, '_>) -> Result<(), FieldError> {
        let Occurrence { wire, data, .. } = at;
        if wire != WireType::LengthDelimited {
            return Err(FieldError::WireType(wire_code(wire)));
        }
        let body = read_len_delimited(data)?;
        *self = std::str::from_utf8(body)
            .map_err(|_| FieldError::OutOfRange)?
            .to_string();
        Ok(())
    }
    fn describe(
        name: &str,
        number: u32,
        _nested: &mut BTreeMap<&'static str, DescriptorProto>,
    ) -> FieldDescriptorProto {
        field_descriptor(name, number, Type::String, false, None)
    }
}

fn describe_message<M: ProtoMessage>(nested: &mut BTreeMap<&'static str, DescriptorProto>) {
    if !nested.contains_key(M::FULL_NAME) {
        let d = M::describe(nested);
        nested.insert(M::FULL_NAME, d);
    }
}

fn encode_messages<M: ProtoMessage>(ms: &[M], number: u32, buf: &mut Vec<u8>) {
    for m in ms {
        encode_len_delimited(number, buf, |b| m.encode_fields(b));
    }
}

/// The descriptor of a field of message type `M` (its type registered in `nested`).
fn message_field<M: ProtoMessage>(
    name: &str,
    number: u32,
    nested: &mut BTreeMap<&'static str, DescriptorProto>,
    repeated: bool,
) -> FieldDescriptorProto {
    describe_message::<M>(nested);
    field_descriptor(name, number, Type::Message, repeated, Some(M::FULL_NAME))
}

fn merge_message<M: ProtoMessage>(
    m: &mut M,
    wire: WireType,
    data: &mut &[u8],
    depth: u32,
) -> Result<(), FieldError> {
    if wire != WireType::LengthDelimited {
        return Err(FieldError::WireType(wire_code(wire)));
    }
    if depth >= MAX_DEPTH {
        return Err(FieldError::Nested(DecodeError::TooDeep {
            message: M::FULL_NAME,
        }));
    }
    let body = read_len_delimited(data)?;
    m.merge_fields(body, depth + 1).map_err(FieldError::Nested)
}

impl<M: ProtoMessage> Field for M {
    fn encode(&self, number: u32, buf: &mut Vec<u8>) {
        encode_len_delimited(number, buf, |b| self.encode_fields(b));
    }
    fn merge(&mut self, at: Occurrence<'_, '_>) -> Result<(), FieldError> {
        let Occurrence {
            wire, data, depth, ..
        } = at;
        merge_message(self, wire, data, depth)
    }
    fn describe(
        name: &str,
        number: u32,
        nested: &mut BTreeMap<&'static str, DescriptorProto>,
    ) -> FieldDescriptorProto {
        message_field::<M>(name, number, nested, false)
    }
}

impl<M: ProtoMessage, const N: usize> Field for [M; N] {
    fn encode(&self, number: u32, buf: &mut Vec<u8>) {
        encode_messages(self, number, buf);
    }
    fn merge(&mut self, at: Occurrence<'_, '_>) -> Result<(), FieldError> {
        let Occurrence {
            wire,
            data,
            count,
            depth,
            ..
        } = at;
        let slot = self.get_mut(*count).ok_or(FieldError::TooMany(N))?;
        merge_message(slot, wire, data, depth)?;
        *count += 1;
        Ok(())
    }
    fn describe(
        name: &str,
        number: u32,
        nested: &mut BTreeMap<&'static str, DescriptorProto>,
    ) -> FieldDescriptorProto {
        message_field::<M>(name, number, nested, true)
    }
}

impl<M: ProtoMessage> Field for Vec<M> {
    fn encode(&self, number: u32, buf: &mut Vec<u8>) {
        encode_messages(self, number, buf);
    }
    fn merge(&mut self, at: Occurrence<'_, '_>) -> Result<(), FieldError> {
        let Occurrence {
            wire,
            data,
            count,
            depth,
            ..
        } = at;
        let mut m = M::default();
        merge_message(&mut m, wire, data, depth)?;
        self.push(m);
        *count += 1;
        Ok(())
    }
    fn describe(
        name: &str,
        number: u32,
        nested: &mut BTreeMap<&'static str, DescriptorProto>,
    ) -> FieldDescriptorProto {
        message_field::<M>(name, number, nested, true)
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

use crate::{
    BaroSample, GnssSample, GnssSatellite, Header, ImuSample, NavSolution, OdometerSample,
    SensorAliveEvent, SensorHealth, StarTrackerSample, Status, TruthSample,
};

crate::proto_message!(Header = "sextant.Header" {
    1 => time_ns, 2 => seq, 3 => status, 4 => reserved, 5 => send_mono_ns,
});
crate::proto_message!(ImuSample = "sextant.ImuSample" {
    1 => header, 2 => dt_s, 3 => delta_angle_rad, 4 => delta_velocity_m_s, 5 => n_channels,
    6 => reserved, 7 => channel_axis, 8 => channel_delta_angle_rad,
    9 => channel_delta_velocity_m_s, 10 => channel_temperature_c, 11 => turntable_angle_rad,
});
crate::proto_message!(StarTrackerSample = "sextant.StarTrackerSample" {
    1 => header, 2 => q_sensor_icrf, 3 => sigma_cross_rad, 4 => sigma_roll_rad, 5 => n_stars,
    6 => valid,
});
crate::proto_message!(GnssSatellite = "sextant.GnssSatellite" {
    1 => prn, 2 => flags, 3 => pseudorange_m, 4 => range_rate_m_s, 5 => cn0_dbhz,
    6 => sigma_pseudorange_m, 7 => sigma_range_rate_m_s, 8 => sat_pos_ecef_m,
    9 => sat_vel_ecef_m_s, 10 => baseline_phase_cycles, 11 => phase_lock_time_s,
});
crate::proto_message!(GnssSample = "sextant.GnssSample" {
    1 => header, 2 => fix_valid, 3 => n_satellites, 4 => pos_ecef_m, 5 => vel_ecef_m_s,
    6 => pos_cov_ecef_m2, 7 => vel_cov_ecef_m2_s2, 8 => pdop, 9 => baseline_length_m,
    10 => wavelength_m, 11 => satellites,
});
crate::proto_message!(OdometerSample = "sextant.OdometerSample" {
    1 => header, 2 => dt_s, 3 => distance_m, 4 => speed_m_s,
});
crate::proto_message!(BaroSample = "sextant.BaroSample" {
    1 => header, 2 => pressure_pa, 3 => temperature_c,
});
crate::proto_message!(TruthSample = "sextant.TruthSample" {
    1 => header, 2 => lat_rad, 3 => lon_rad, 4 => height_m, 5 => pos_ecef_m,
    6 => vel_ned_m_s, 7 => q_ned_body, 8 => roll_pitch_heading_rad, 9 => gyro_bias_rad_s,
    10 => accel_bias_m_s2,
});
crate::proto_message!(NavSolution = "sextant.NavSolution" {
    1 => header, 2 => mode, 3 => aiding_mask, 4 => lat_rad, 5 => lon_rad, 6 => height_m,
    7 => pos_ecef_m, 8 => vel_ned_m_s, 9 => q_ned_body, 10 => roll_pitch_heading_rad,
    11 => pos_sigma_ned_m, 12 => vel_sigma_ned_m_s, 13 => att_sigma_ned_rad,
    14 => gyro_bias_rad_s, 15 => accel_bias_m_s2, 16 => imu_send_mono_ns,
    17 => gyro_bias_sigma_rad_s, 18 => accel_bias_sigma_m_s2, 19 => gyro_scale_ppm,
    20 => accel_scale_ppm, 21 => boresight_rad, 22 => boresight_sigma_rad,
    23 => clock_bias_m, 24 => clock_drift_m_s, 25 => baro_bias_m, 26 => odometer_scale,
    27 => stale, 28 => pos_cov_ned_m2,
});
crate::proto_message!(SensorHealth = "sextant.SensorHealth" {
    1 => received, 2 => fused, 3 => rejected_gate, 4 => rejected_invalid, 5 => dropped_late,
    6 => last_time_ns, 7 => alive, 8 => deadline_misses, 9 => last_nis, 10 => nis_sum,
    11 => nis_count, 12 => nis_dof_sum, 13 => seq_gaps,
});
crate::proto_message!(Status = "sextant.Status" {
    1 => header, 2 => mode, 3 => alive_mask, 4 => solutions_published, 5 => records_written,
    6 => records_dropped, 7 => sensors, 8 => imu_channels_excluded_mask,
    9 => imu_channels_suspect_mask, 10 => imu_faults_detected, 11 => recorder_errors,
    12 => gnss_ls_checks, 13 => gnss_ls_disagreements, 14 => gnss_ls_last_nis,
    15 => gnss_ls_pdop, 16 => reinitializations, 17 => zupt_fused, 18 => zupt_rejected_gate,
    19 => nhc_fused, 20 => nhc_rejected_gate, 21 => nhc_nis_sum, 22 => solutions_stale,
    23 => motion_alignments, 24 => gnss_heading_alignments, 25 => warm_starts,
    26 => imu_held_at_time_jump,
});
crate::proto_message!(SensorAliveEvent = "sextant.SensorAliveEvent" {
    1 => header, 2 => sensor, 3 => alive,
});

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Record, RecordKind};
    use proptest::prelude::*;

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
            assert_json_matches(&expected, &decoded, r.topic());
        }
    }

    /// `expected` (serde's JSON of the struct) against `decoded` (protobuf JSON mapping): equal,
    /// except that nested number arrays are flat in protobuf, and that protobuf's JSON writes
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
                let flat: Vec<Value> =
                    if e.iter().all(Value::is_array) && !d.iter().any(Value::is_array) {
                        e.iter()
                            .flat_map(|x| x.as_array().unwrap().clone())
                            .collect()
                    } else {
                        e.clone()
                    };
                assert_eq!(flat.len(), d.len(), "{at}");
                for (i, (x, y)) in flat.iter().zip(d).enumerate() {
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
        let pinned = include_str!("../tests/protobuf_fields.txt");
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
}
