//! What makes a message type recordable ([`Topic`]: its topic, schemas and protobuf form) and
//! how a channel's messages are encoded ([`MessageEncoding`]); the seven recorded types'
//! codecs and schemas are the submodules.

pub mod events;
pub mod pose;
mod samples;
mod schema;

use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::Value;

use crate::error::ErrorKind;

pub use samples::TRUTH_TOPIC;

/// How a channel's messages are encoded, from its message encoding and its schema's encoding:
/// the decoder its messages go through, and the encoding a [`Writer`](super::Writer) writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MessageEncoding {
    /// `json` described by `jsonschema` (or schemaless), read with `serde_json`: what older
    /// recordings hold.
    Json,
    /// `protobuf` described by a `protobuf` schema (a `FileDescriptorSet`), read with
    /// `prost`: what [`Writer::create`](super::Writer::create) writes; a recorder's finished file is half the size
    /// of the same messages in JSON (docs/recording.md).
    Protobuf,
}

impl MessageEncoding {
    /// The encoding of a channel with message encoding `message` and schema encoding `schema`
    /// ("" without a schema); `None` when no decoder reads it.
    pub fn of(message: &str, schema: &str) -> Option<Self> {
        match (message, schema) {
            ("json", "jsonschema" | "") => Some(Self::Json),
            ("protobuf", "protobuf") => Some(Self::Protobuf),
            _ => None,
        }
    }

    /// The channel's message encoding, as MCAP names it.
    pub fn message(self) -> &'static str {
        match self {
            Self::Json => "json",
            Self::Protobuf => "protobuf",
        }
    }

    /// The schema's encoding, as MCAP names it.
    pub fn schema(self) -> &'static str {
        match self {
            Self::Json => "jsonschema",
            Self::Protobuf => "protobuf",
        }
    }

    /// Decodes one message as a `T`.
    pub fn decode<T: Topic>(self, data: &[u8]) -> std::result::Result<T, ErrorKind> {
        match self {
            Self::Json => serde_json::from_slice(data).map_err(ErrorKind::Json),
            Self::Protobuf => {
                let proto = <T::Proto as prost::Message>::decode(data)
                    .map_err(|e| ErrorKind::Protobuf(e.to_string()))?;
                T::from_proto(proto).map_err(ErrorKind::Protobuf)
            }
        }
    }
}

/// A message type that can be recorded: its topic, its schemas (JSON Schema and protobuf),
/// and its own time.
pub trait Topic: Serialize + DeserializeOwned {
    /// The channel's topic, e.g. `mems/imu/raw`.
    const TOPIC: &'static str;
    /// The schema's name, e.g. `mems.RawImuSample`: the JSON Schema's title and the protobuf
    /// message's full name.
    const SCHEMA_NAME: &'static str;
    /// The protobuf message of the topic ([`proto`](super::proto), or Foxglove's for its schemas).
    type Proto: prost::Message + Default + 'static;
    /// A JSON Schema describing the message's serde JSON form, with units in descriptions.
    fn json_schema() -> Value;
    /// The encoded `FileDescriptorSet` that describes [`Topic::Proto`].
    fn proto_schema() -> Vec<u8>;
    /// Writes the message into `proto` (whose storage is reused from message to message).
    fn fill_proto(&self, proto: &mut Self::Proto);
    /// The message of a decoded `proto`; errors name the field that does not fit.
    fn from_proto(proto: Self::Proto) -> std::result::Result<Self, String>;
    /// The message as a protobuf recording gives it back: the same, or with its `float`
    /// fields rounded to `f32` (docs/recording.md, "Precision").
    fn as_recorded(&self) -> Self
    where
        Self: Clone,
    {
        self.clone()
    }
    /// The message's own time, ns, recorded as the MCAP `publish_time`.
    fn publish_time_ns(&self) -> u64;
    /// Whether every float in the message is finite (JSON cannot hold NaN or infinity).
    fn is_finite(&self) -> bool;
}
