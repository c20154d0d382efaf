//! MCAP recordings: JSON messages described by JSON Schema (message encoding `json`, schema
//! encoding `jsonschema`, which Foxglove and the official MCAP readers understand), in
//! zstd-compressed chunks.
//!
//! Channels: [`ipc_types::service::RAW`] (`mems/imu/raw`, [`RawImuSample`]) and
//! [`TRUTH_TOPIC`] (`mems/sim/truth`, [`Truth`]). Another message type becomes recordable by
//! implementing [`Topic`] for it; its channel is then one [`Writer::add_channel`] call.
//!
//! Times: each message's `log_time` is chosen by the writer's caller (the recorder uses the
//! receive time, ns `CLOCK_MONOTONIC`); its `publish_time` is the message's own time
//! ([`Topic::publish_time_ns`], e.g. a raw sample's `stamps.sample_ns`). Floats are written in
//! their shortest round-trip form and parsed with `serde_json`'s `float_roundtrip`, so every
//! `f64` reads back bit for bit. JSON cannot hold NaN or infinity: the writer rejects them.
//!
//! A writer killed mid-recording leaves a file without summary or footer. [`Reader`] scans
//! linearly and yields every message of every complete chunk before the cut, then reports the
//! truncation ([`ErrorKind::Truncated`]); [`read_all`] returns it in [`Contents::truncation`].
//! [`Writer::flush`] closes the current chunk, bounding what a kill can lose.

use std::collections::{BTreeMap, HashMap};
use std::fmt;
use std::fs::File;
use std::io::{BufWriter, Read};
use std::marker::PhantomData;
use std::path::{Path, PathBuf};

use ::mcap::records::MessageHeader;
use ::mcap::{Compression, MAGIC, MessageStream, WriteOptions};
use ipc_types::RawImuSample;
use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::{Value, json};

use crate::error::{Error, ErrorKind, Result};
use crate::{Format, Recording, Truth};

/// Topic of the simulator's ground truth.
pub const TRUTH_TOPIC: &str = "mems/sim/truth";
/// The message encoding of every channel this crate writes.
pub const MESSAGE_ENCODING: &str = "json";
/// The schema encoding of every schema this crate writes.
pub const SCHEMA_ENCODING: &str = "jsonschema";

/// A message type that can be recorded: its topic, its JSON Schema, and its own time.
pub trait Topic: Serialize + DeserializeOwned {
    /// The channel's topic, e.g. `mems/imu/raw`.
    const TOPIC: &'static str;
    /// The schema's name, e.g. `mems.RawImuSample`.
    const SCHEMA_NAME: &'static str;
    /// A JSON Schema describing the message's serde JSON form, with units in descriptions.
    fn json_schema() -> Value;
    /// The message's own time, ns, recorded as the MCAP `publish_time`.
    fn publish_time_ns(&self) -> u64;
    /// Whether every float in the message is finite (JSON cannot hold NaN or infinity).
    fn is_finite(&self) -> bool;
}

impl Topic for RawImuSample {
    const TOPIC: &'static str = ipc_types::service::RAW;
    const SCHEMA_NAME: &'static str = "mems.RawImuSample";

    fn json_schema() -> Value {
        object(
            Self::SCHEMA_NAME,
            "One raw IMU sample, sensor frame, sensor units (ipc-types RawImuSample).",
            &[
                ("stamps", stamps_schema()),
                ("seq", uint("Publisher sequence number, from 0.", u64::MAX)),
                (
                    "accel_g",
                    vector(3, number("Specific force, g, sensor frame.")),
                ),
                (
                    "gyro_dps",
                    vector(3, number("Angular rate, deg/s, sensor frame.")),
                ),
                ("temp_c", number("Die temperature, degC.")),
                (
                    "accel_counts",
                    vector(3, int16("Accelerometer output, counts.")),
                ),
                ("gyro_counts", vector(3, int16("Gyroscope output, counts."))),
                ("temp_counts", int16("TEMP_OUT, counts.")),
                ("flags", uint("ipc-types raw_flags bits.", u16::MAX.into())),
                (
                    "lost_before",
                    uint("Samples lost just before this one.", u32::MAX.into()),
                ),
                ("reserved", uint("Zero.", u32::MAX.into())),
            ],
        )
    }

    fn publish_time_ns(&self) -> u64 {
        self.stamps.sample_ns
    }

    fn is_finite(&self) -> bool {
        let mut values = self
            .accel_g
            .iter()
            .chain(&self.gyro_dps)
            .chain([&self.temp_c]);
        values.all(|v| v.is_finite())
    }
}

impl Topic for Truth {
    const TOPIC: &'static str = TRUTH_TOPIC;
    const SCHEMA_NAME: &'static str = "mems.Truth";

    fn json_schema() -> Value {
        object(
            Self::SCHEMA_NAME,
            "Ground truth of a simulated session; navigation frame z-up, sensor frame as ipc-types.",
            &[
                ("t_ns", uint("Sample time, ns.", u64::MAX)),
                (
                    "position_m",
                    vector(3, number("Position, m, navigation frame.")),
                ),
                (
                    "velocity_mps",
                    vector(3, number("Velocity, m/s, navigation frame.")),
                ),
                (
                    "attitude_wxyz",
                    vector(
                        4,
                        number("Unit quaternion (w, x, y, z), sensor to navigation frame."),
                    ),
                ),
                (
                    "specific_force_mps2",
                    vector(3, number("Ideal specific force, m/s^2, sensor frame.")),
                ),
                (
                    "angular_rate_rps",
                    vector(3, number("Ideal angular rate, rad/s, sensor frame.")),
                ),
                (
                    "at_rest",
                    json!({"type": "boolean", "description": "Body at rest."}),
                ),
            ],
        )
    }

    fn publish_time_ns(&self) -> u64 {
        self.t_ns
    }

    fn is_finite(&self) -> bool {
        let mut values = self
            .position_m
            .iter()
            .chain(&self.velocity_mps)
            .chain(&self.attitude_wxyz)
            .chain(&self.specific_force_mps2)
            .chain(&self.angular_rate_rps);
        values.all(|v| v.is_finite())
    }
}

/// JSON Schema of [`ipc_types::Stamps`].
fn stamps_schema() -> Value {
    let stamp = |what: &str| {
        uint(
            &format!("{what}, ns CLOCK_MONOTONIC; 0 if not yet."),
            u64::MAX,
        )
    };
    object(
        "mems.Stamps",
        "Per-stage timestamps.",
        &[
            ("sample_ns", stamp("When the sensor sampled")),
            ("acquired_ns", stamp("When acquisition published")),
            ("calibrated_ns", stamp("When calibration published")),
            ("odometry_ns", stamp("When odometry published")),
        ],
    )
}

/// A JSON Schema object whose properties are all required.
fn object(title: &str, description: &str, properties: &[(&str, Value)]) -> Value {
    let required: Vec<&str> = properties.iter().map(|(name, _)| *name).collect();
    let properties: serde_json::Map<String, Value> = properties
        .iter()
        .map(|(name, schema)| ((*name).to_owned(), schema.clone()))
        .collect();
    json!({
        "title": title,
        "description": description,
        "type": "object",
        "properties": properties,
        "required": required,
    })
}

/// A JSON Schema number (an `f64`).
fn number(description: &str) -> Value {
    json!({"type": "number", "description": description})
}

/// A JSON Schema unsigned integer up to `max`.
fn uint(description: &str, max: u64) -> Value {
    json!({"type": "integer", "minimum": 0, "maximum": max, "description": description})
}

/// A JSON Schema `i16`.
fn int16(description: &str) -> Value {
    json!({"type": "integer", "minimum": i16::MIN, "maximum": i16::MAX, "description": description})
}

/// A JSON Schema array of exactly `n` items.
fn vector(n: usize, item: Value) -> Value {
    json!({"type": "array", "items": item, "minItems": n, "maxItems": n})
}

/// A channel added to a [`Writer`], typed by the messages it carries.
pub struct Channel<T> {
    id: u16,
    message: PhantomData<fn(&T)>,
}

impl<T> Clone for Channel<T> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<T> Copy for Channel<T> {}

/// Writes an MCAP recording to a file (zstd chunks, JSON messages).
///
/// Dropping the writer finishes the file but ignores errors; call [`Writer::finish`].
pub struct Writer {
    inner: ::mcap::Writer<BufWriter<File>>,
    path: PathBuf,
    sequences: HashMap<u16, u32>,
}

impl Writer {
    /// Creates (or truncates) the file at `path` and writes the MCAP header.
    pub fn create(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let file = File::create(path).map_err(|e| Error::io(path, e))?;
        let inner = WriteOptions::new()
            .compression(Some(Compression::Zstd))
            .create(BufWriter::new(file))
            .map_err(|e| Error::file(path, ErrorKind::Mcap(e)))?;
        Ok(Self {
            inner,
            path: path.to_path_buf(),
            sequences: HashMap::new(),
        })
    }

    /// Adds the channel for messages of type `T` (its schema too, once). Adding the same type
    /// again returns the same channel.
    pub fn add_channel<T: Topic>(&mut self) -> Result<Channel<T>> {
        let schema =
            serde_json::to_vec(&T::json_schema()).map_err(|e| self.fail(ErrorKind::Json(e)))?;
        let schema_id = self
            .inner
            .add_schema(T::SCHEMA_NAME, SCHEMA_ENCODING, &schema)
            .map_err(|e| self.fail(ErrorKind::Mcap(e)))?;
        let id = self
            .inner
            .add_channel(schema_id, T::TOPIC, MESSAGE_ENCODING, &BTreeMap::new())
            .map_err(|e| self.fail(ErrorKind::Mcap(e)))?;
        Ok(Channel {
            id,
            message: PhantomData,
        })
    }

    /// Writes one message; `log_time_ns` is the MCAP log time (the recorder's receive time),
    /// the publish time is the message's own ([`Topic::publish_time_ns`]).
    ///
    /// Errors if a float in the message is not finite.
    pub fn write<T: Topic>(
        &mut self,
        channel: Channel<T>,
        message: &T,
        log_time_ns: u64,
    ) -> Result<()> {
        let publish_time = message.publish_time_ns();
        if !message.is_finite() {
            let kind = ErrorKind::Invalid(format!(
                "message at publish time {publish_time} ns holds NaN or infinity, which JSON cannot store"
            ));
            return Err(Error {
                field: Some(T::TOPIC.to_owned()),
                ..self.fail(kind)
            });
        }
        let data = serde_json::to_vec(message).map_err(|e| self.fail(ErrorKind::Json(e)))?;
        let sequence = self.sequences.entry(channel.id).or_default();
        let header = MessageHeader {
            channel_id: channel.id,
            sequence: *sequence,
            log_time: log_time_ns,
            publish_time,
        };
        *sequence = sequence.wrapping_add(1);
        self.inner
            .write_to_known_channel(&header, &data)
            .map_err(|e| self.fail(ErrorKind::Mcap(e)))
    }

    /// Closes the current chunk and hands everything written so far to the operating system,
    /// so that a killed process loses nothing written before this call.
    pub fn flush(&mut self) -> Result<()> {
        self.inner
            .flush()
            .map_err(|e| self.fail(ErrorKind::Mcap(e)))
    }

    /// Writes the summary and footer and closes the file.
    pub fn finish(mut self) -> Result<()> {
        self.inner
            .finish()
            .map_err(|e| self.fail(ErrorKind::Mcap(e)))?;
        let path = self.path.clone();
        self.inner
            .into_inner()
            .into_inner()
            .map_err(|e| Error::io(&path, e.into_error()))?;
        Ok(())
    }

    fn fail(&self, kind: ErrorKind) -> Error {
        Error::file(&self.path, kind)
    }
}

/// Where a truncated or damaged MCAP file stops being readable.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Truncation {
    /// Complete messages read before the cut (all topics).
    pub messages_read: u64,
    /// What the MCAP reader found at the cut.
    pub reason: String,
}

impl fmt::Display for Truncation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "the file ends early or is damaged after {} complete messages ({})",
            self.messages_read, self.reason
        )
    }
}

/// Whether the file starts with the MCAP magic bytes.
pub(crate) fn has_magic(path: &Path) -> Result<bool> {
    let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
    let mut start = Vec::with_capacity(MAGIC.len());
    file.by_ref()
        .take(MAGIC.len() as u64)
        .read_to_end(&mut start)
        .map_err(|e| Error::io(path, e))?;
    Ok(start == MAGIC)
}

/// An MCAP file read into memory, to be scanned with [`Reader::messages`].
pub struct Reader {
    path: PathBuf,
    bytes: Vec<u8>,
}

impl Reader {
    /// Reads the file; errors if it does not start with the MCAP magic bytes.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        if !bytes.starts_with(MAGIC) {
            let kind = ErrorKind::UnknownFormat("does not start with the MCAP magic bytes".into());
            return Err(Error::file(path, kind));
        }
        Ok(Self {
            path: path.to_path_buf(),
            bytes,
        })
    }

    /// The messages of all topics in file order. If the file ends early or is damaged, the
    /// last item is an [`ErrorKind::Truncated`] error after every message before the cut.
    pub fn messages(&self) -> Result<Messages<'_>> {
        let options = ::mcap::read::Options::ValidateChunkCrcs.into();
        let stream = MessageStream::new_with_options(&self.bytes, options)
            .map_err(|e| Error::file(&self.path, ErrorKind::Mcap(e)))?;
        Ok(Messages {
            path: &self.path,
            stream,
            read: 0,
            done: false,
        })
    }
}

/// Iterator over the messages of a [`Reader`].
pub struct Messages<'a> {
    path: &'a Path,
    stream: MessageStream<'a>,
    read: u64,
    done: bool,
}

impl<'a> Iterator for Messages<'a> {
    type Item = Result<Recorded<'a>>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        match self.stream.next() {
            Some(Ok(message)) => {
                self.read += 1;
                let channel = &message.channel;
                Some(Ok(Recorded {
                    source: self.path,
                    index: self.read,
                    topic: channel.topic.clone(),
                    schema_name: channel
                        .schema
                        .as_ref()
                        .map(|s| s.name.clone())
                        .unwrap_or_default(),
                    encoding: channel.message_encoding.clone(),
                    log_time_ns: message.log_time,
                    publish_time_ns: message.publish_time,
                    data: message.data.into_owned(),
                }))
            }
            Some(Err(e)) => {
                self.done = true;
                let truncation = Truncation {
                    messages_read: self.read,
                    reason: e.to_string(),
                };
                Some(Err(Error::file(
                    self.path,
                    ErrorKind::Truncated(truncation),
                )))
            }
            None => {
                self.done = true;
                None
            }
        }
    }
}

/// One message as stored in an MCAP file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Recorded<'a> {
    source: &'a Path,
    /// 1-based index in the file, all topics counted.
    pub index: u64,
    /// The channel's topic.
    pub topic: String,
    /// The channel's schema name ("" without a schema).
    pub schema_name: String,
    /// The channel's message encoding.
    pub encoding: String,
    /// MCAP log time, ns (the recorder's receive time).
    pub log_time_ns: u64,
    /// MCAP publish time, ns (the message's own time).
    pub publish_time_ns: u64,
    /// The encoded message.
    pub data: Vec<u8>,
}

impl Recorded<'_> {
    /// Decodes the message as a `T`, or `None` if it is on another topic. Errors if the channel's
    /// encoding or schema name is not `T`'s, or the JSON does not decode.
    pub fn decode<T: Topic>(&self) -> Option<Result<T>> {
        if self.topic != T::TOPIC {
            return None;
        }
        let fail = |kind| Error::message(self.source, self.index, Some(&self.topic), kind);
        if self.encoding != MESSAGE_ENCODING || self.schema_name != T::SCHEMA_NAME {
            let kind = ErrorKind::Invalid(format!(
                "channel has encoding {:?} and schema {:?}, expected {MESSAGE_ENCODING:?} and {:?}",
                self.encoding,
                self.schema_name,
                T::SCHEMA_NAME
            ));
            return Some(Err(fail(kind)));
        }
        Some(serde_json::from_slice(&self.data).map_err(|e| fail(ErrorKind::Json(e))))
    }
}

/// Everything [`read_all`] found in a file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Contents {
    /// Raw samples in file order, exactly as recorded.
    pub raw: Vec<RawImuSample>,
    /// Ground-truth records in file order.
    pub truth: Vec<Truth>,
    /// Number of messages on other topics (not decoded).
    pub other_messages: u64,
    /// Set when the file ends early or is damaged; everything before the cut is above.
    pub truncation: Option<Truncation>,
}

impl Contents {
    /// The raw samples and truth as a [`Recording`] of `path`.
    pub(crate) fn into_recording(self, path: &Path) -> Recording {
        Recording {
            source: path.to_path_buf(),
            format: Format::Mcap,
            samples: self.raw,
            truth: (!self.truth.is_empty()).then_some(self.truth),
            truncation: self.truncation,
        }
    }
}

/// Reads every raw sample and truth record of an MCAP file, up to the cut if the file was
/// truncated (reported in [`Contents::truncation`], never silently).
///
/// Errors if the file is not MCAP, a message does not decode, or raw sample times
/// (`stamps.sample_ns`) do not strictly increase.
pub fn read_all(path: impl AsRef<Path>) -> Result<Contents> {
    let reader = Reader::open(path)?;
    let mut contents = Contents::default();
    for message in reader.messages()? {
        let message = match message {
            Ok(message) => message,
            Err(Error {
                kind: ErrorKind::Truncated(truncation),
                ..
            }) => {
                contents.truncation = Some(truncation);
                break;
            }
            Err(e) => return Err(e),
        };
        if let Some(sample) = message.decode::<RawImuSample>() {
            let sample = sample?;
            if let Some(previous) = contents.raw.last() {
                let previous_ns = previous.stamps.sample_ns;
                let t_ns = sample.stamps.sample_ns;
                let kind = if t_ns < previous_ns {
                    Some(ErrorKind::TimeBackwards { t_ns, previous_ns })
                } else if t_ns == previous_ns {
                    Some(ErrorKind::DuplicateTime { t_ns })
                } else {
                    None
                };
                if let Some(kind) = kind {
                    let field = format!("{}: stamps.sample_ns", message.topic);
                    return Err(Error::message(
                        &reader.path,
                        message.index,
                        Some(&field),
                        kind,
                    ));
                }
            }
            contents.raw.push(sample);
        } else if let Some(truth) = message.decode::<Truth>() {
            contents.truth.push(truth?);
        } else {
            contents.other_messages += 1;
        }
    }
    Ok(contents)
}
