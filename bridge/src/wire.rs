//! The bridge's wire format, version 1: what another computer sees on Zenoh.
//!
//! - Each bus channel of a system is published under the key expression
//!   `<key_prefix>/v1/<channel>` (`<channel>` as [`msgs::Channel::name`]: `imu`, `star_tracker`,
//!   `gnss`, `odometer`, `baro`, `truth`, `nav`, `status`).
//! - The payload is one message in its protobuf wire form, exactly as the recordings hold it
//!   ([`msgs::protobuf`]; field numbers pinned by the crate's tests). The Zenoh encoding is
//!   `application/protobuf` with the message's full name as its schema (`sextant.NavSolution`).
//!   The message is the publisher's, unchanged: its header keeps its time of validity (GPS ns),
//!   sequence number and `send_mono_ns` (the sending process's monotonic clock, comparable only
//!   on one machine).
//! - `<key_prefix>/v1/schema/<channel>` answers a query with the channel's serialized
//!   `google.protobuf.FileDescriptorSet`, so a client decodes without Sextant's code.
//! - Each bridge holds a liveliness token `<key_prefix>/v1/alive/<bridge name>`: a remote side
//!   sees it vanish when the link drops (Zenoh's lease) or the bridge stops.
//!
//! `v1` changes only when a message changes incompatibly (a field renumbered or its type
//! changed); fields added to a message keep `v1`, as protobuf readers skip unknown fields.

use msgs::{Channel, RecordKind};

/// The wire format's version, the key expressions' second-to-last chunk.
pub const VERSION: &str = "v1";

/// Key expression of `channel`'s messages under `key_prefix`.
pub fn data_key(key_prefix: &str, channel: Channel) -> String {
    format!("{key_prefix}/{VERSION}/{}", channel.name())
}

/// Key expression of the query answered with `channel`'s protobuf descriptors.
pub fn schema_key(key_prefix: &str, channel: Channel) -> String {
    format!("{key_prefix}/{VERSION}/schema/{}", channel.name())
}

/// Key expression of the liveliness token of the bridge named `name`.
pub fn alive_key(key_prefix: &str, name: &str) -> String {
    format!("{key_prefix}/{VERSION}/alive/{name}")
}

/// Key expression matching every bridge's liveliness token under `key_prefix`.
pub fn alive_keys(key_prefix: &str) -> String {
    format!("{key_prefix}/{VERSION}/alive/**")
}

/// The Zenoh encoding of `channel`'s messages: protobuf, schema the message's full name.
pub fn encoding(channel: Channel) -> zenoh::bytes::Encoding {
    let (name, _) = RecordKind::Channel(channel).protobuf_schema();
    zenoh::bytes::Encoding::APPLICATION_PROTOBUF.with_schema(name)
}

/// Why a key prefix cannot name a system's channels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum KeyPrefixError {
    /// Empty.
    #[error("empty")]
    Empty,
    /// Holds a wildcard or reserved character (`*`, `$`, `?`, `#`, `@`), an empty chunk, or a
    /// leading or trailing `/`.
    #[error("not a plain Zenoh key expression (no wildcards, no empty chunks, no `@ ? # $`)")]
    NotPlain,
}

/// Check that `key_prefix` is a plain key expression (chunks of ordinary characters separated
/// by `/`), so that every key built from it is valid and matches only this system.
pub fn check_key_prefix(key_prefix: &str) -> Result<(), KeyPrefixError> {
    if key_prefix.is_empty() {
        return Err(KeyPrefixError::Empty);
    }
    let plain = key_prefix
        .split('/')
        .all(|chunk| !chunk.is_empty() && !chunk.contains(['*', '$', '?', '#', '@']));
    if !plain || zenoh::key_expr::KeyExpr::try_from(data_key(key_prefix, Channel::Nav)).is_err() {
        return Err(KeyPrefixError::NotPlain);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_of_a_prefix() {
        assert_eq!(data_key("car1", Channel::Nav), "car1/v1/nav");
        assert_eq!(
            schema_key("fleet/car1", Channel::StarTracker),
            "fleet/car1/v1/schema/star_tracker"
        );
        assert_eq!(alive_key("car1", "a"), "car1/v1/alive/a");
        assert_eq!(alive_keys("car1"), "car1/v1/alive/**");
        for ch in Channel::ALL {
            let k = data_key("fleet/car1", ch);
            assert!(
                zenoh::key_expr::KeyExpr::try_from(k.as_str()).is_ok(),
                "{k}"
            );
        }
    }

    #[test]
    fn only_plain_prefixes_are_accepted() {
        assert_eq!(check_key_prefix("sextant"), Ok(()));
        assert_eq!(check_key_prefix("fleet/car-1"), Ok(()));
        assert_eq!(check_key_prefix(""), Err(KeyPrefixError::Empty));
        for bad in ["a/*", "a/**", "a//b", "/a", "a/", "@a", "a$b", "a?b", "a#b"] {
            assert_eq!(
                check_key_prefix(bad),
                Err(KeyPrefixError::NotPlain),
                "{bad}"
            );
        }
    }

    #[test]
    fn the_encoding_names_the_message() {
        let e = encoding(Channel::Nav);
        assert_eq!(e.to_string(), "application/protobuf;sextant.NavSolution");
    }
}
