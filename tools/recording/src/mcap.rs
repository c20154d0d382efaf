//! MCAP recordings: protobuf messages with their `FileDescriptorSet` schemas (message and
//! schema encoding `protobuf`, which Foxglove and the official MCAP readers decode; [`proto`]),
//! or JSON described by JSON Schema in older recordings, which every reader here still reads
//! ([`MessageEncoding`]), in zstd-compressed chunks.
//!
//! Channels: [`ipc_types::service::RAW`] (`mems/imu/raw`, [`RawImuSample`]),
//! [`ipc_types::service::CORRECTED`] (`mems/imu/corrected`, [`CorrectedImuSample`]),
//! [`ipc_types::service::ODOMETRY`] (`mems/odometry/state`, [`OdometryState`]),
//! [`ipc_types::service::HINT`] (`mems/robot/hint`, [`RobotHint`]), the Foxglove messages
//! derived from each odometry state ([`derived`]: pose [`POSE_TOPIC`], read back as
//! [`PoseInFrame`], revised pose, transform and path), the recorder's events ([`EVENTS_TOPIC`],
//! [`RecorderEvent`]) and [`TRUTH_TOPIC`] (`mems/sim/truth`, [`Truth`]). Topics are the
//! services' base names, without the namespace they were recorded under. Another message type
//! becomes recordable by implementing [`Topic`] for it; its channel is then one
//! [`Writer::add_channel`] call.
//!
//! Times: each message's `log_time` is chosen by the writer's caller (the recorder uses the
//! receive time, ns `CLOCK_MONOTONIC`); its `publish_time` is the message's own time
//! ([`Topic::publish_time_ns`], e.g. a raw sample's `stamps.sample_ns`). A writer anchored to
//! the wall clock ([`Writer::anchor`], as the recorder's is) writes both as Unix ns and states
//! the anchor in a metadata record ([`crate::clock`]). Precision: protobuf keeps time stamps,
//! counts and raw samples exact, and the corrected samples' and states' quantities at their
//! [`quantum`] ([`Topic::as_recorded`]); JSON keeps every `f64` bit for bit, in its shortest
//! round-trip form parsed with `serde_json`'s `float_roundtrip` (JSON cannot hold NaN or
//! infinity: a JSON writer refuses them).
//!
//! Files: [`Writer::create`] and [`Writer::create_new`] write a private temporary file beside
//! the path and rename it there when [`Writer::finish`]ed (`mems_files::Output`), so a run
//! that fails leaves no file. The recorder's file ([`Writer::create_new_compacting`]) is
//! written in place instead and is a whole MCAP file after every [`Writer::flush`] ([`durable`]):
//! a recorder killed at any point leaves a file that every reader opens, with every message
//! flushed before the kill. A file cut short some other way (a copy interrupted, a full disk)
//! is read up to the cut: [`Reader`] scans linearly and yields every message of every complete
//! chunk before it, then reports the truncation ([`ErrorKind::Truncated`]); [`read_all`]
//! returns it in [`Contents::truncation`].
//!
//! Modules: [`codec`] (the recorded types' codecs and schemas), the writer ([`Writer`], with
//! the recorder's compact copy), the reader of one file ([`Reader`]), whole-run reading into
//! memory ([`read_all`]) and streamed ([`run`]), the raw stream's checks ([`RawChecks`]).
//!
//! [`RawImuSample`]: ipc_types::RawImuSample
//! [`CorrectedImuSample`]: ipc_types::CorrectedImuSample
//! [`OdometryState`]: ipc_types::OdometryState
//! [`RobotHint`]: ipc_types::RobotHint
//! [`Truth`]: crate::Truth
//! [`ErrorKind::Truncated`]: crate::ErrorKind::Truncated

mod checks;
pub mod codec;
mod contents;
pub mod derived;
pub mod durable;
pub mod proto;
pub mod quantum;
mod reader;
pub mod run;
pub mod scan;
#[cfg(test)]
mod tests;
mod writer;

pub use crate::error::Truncation;
pub use checks::RawChecks;
pub use codec::events::{EVENTS_TOPIC, EventKind, RecorderEvent};
pub use codec::pose::{
    FoxglovePose, FoxgloveQuaternion, FoxgloveTime, FoxgloveVector3, NAV_FRAME, POSE_TOPIC,
    PoseInFrame,
};
pub use codec::{MessageEncoding, TRUTH_TOPIC, Topic};
pub use contents::{Contents, last_seqs, read_all};
pub use reader::{Messages, Reader, Recorded, SegmentRead, has_magic};
pub use writer::{
    COMPACT_CHUNK_BYTES, COMPACT_LEVEL, Channel, FoxgloveChannel, Writer, compacting_path,
    remove_stale_copy,
};
