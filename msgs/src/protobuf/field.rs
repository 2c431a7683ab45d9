//! How each field type is written, read and described (see the module comment of
//! [`crate::protobuf`] for the mapping).

use super::{DecodeError, FieldError, MAX_DEPTH, ProtoMessage, WireType};
use prost::encoding::{decode_varint, encode_key, encode_varint, encoded_len_varint};
use prost_types::field_descriptor_proto::{Label, Type};
use prost_types::{DescriptorProto, FieldDescriptorProto};
use std::collections::BTreeMap;

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

/// The elements up to the last one whose bits are not all zero: trailing `+0.0` are not
/// written (a reader fills the rest of the array with zero), `-0.0` and NaN are.
fn up_to_last_nonzero(values: &[f64]) -> &[f64] {
    let n = values
        .iter()
        .rposition(|v| v.to_bits() != 0)
        .map_or(0, |i| i + 1);
    &values[..n]
}

fn encode_doubles(values: &[f64], number: u32, buf: &mut Vec<u8>) {
    let values = up_to_last_nonzero(values);
    if values.is_empty() {
        return;
    }
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
        // Trailing zeros are not written (a reader fills the rest with zero).
        let values = &self[..self.iter().rposition(|&v| v != 0).map_or(0, |i| i + 1)];
        if values.is_empty() {
            return;
        }
        let len: usize = values
            .iter()
            .map(|v| encoded_len_varint(u64::from(*v)))
            .sum();
        encode_key(number, WireType::LengthDelimited, buf);
        encode_varint(len as u64, buf);
        for v in values {
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

/// Every element of a fixed-size array up to the last one with a field to write: trailing
/// elements whose every field is at its default (an empty body) are not written, a reader
/// fills the rest of the array with defaults.
fn encode_message_array<M: ProtoMessage>(ms: &[M], number: u32, buf: &mut Vec<u8>) {
    let mut end = buf.len();
    for m in ms {
        let at = buf.len();
        encode_len_delimited(number, buf, |b| m.encode_fields(b));
        // Key and a one-byte length of zero: the element wrote no field.
        if buf.len() - at > encoded_len_varint(u64::from(number << 3)) + 1 {
            end = buf.len();
        }
    }
    buf.truncate(end);
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
        encode_message_array(self, number, buf);
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
