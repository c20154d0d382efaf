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

pub mod derived;
pub mod durable;
pub mod proto;
pub mod run;
pub mod scan;

use std::any::Any;
use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap};
use std::fmt;
use std::fs::File;
use std::io::{BufWriter, Read, Seek, SeekFrom, Write};
use std::marker::PhantomData;
use std::path::{Path, PathBuf};

use ::mcap::records::MessageHeader;
use ::mcap::{Compression, MAGIC, WriteOptions};
use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample, RobotHint, limits};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use crate::clock::WallClock;
use crate::error::{Error, ErrorKind, Result};
use crate::{Format, Recording, Truth};

/// The resolution at which the corrected samples and the odometry states are recorded: each
/// value is the nearest multiple of its quantum (a power of two), written as a `float`
/// (docs/recording.md, "Precision"). Each is far below the sensor's one count or the
/// estimate's 1-sigma.
pub mod quantum {
    /// Specific force, m/s^2: 2^-15 (31 um/s^2), 1/20 of one count at +-2 g (599 um/s^2).
    pub const ACCEL_MPS2: f64 = 1.0 / (1u64 << 15) as f64;
    /// Angular rate, rad/s: 2^-17 (7.6 urad/s), 1/17 of one count at +-250 deg/s
    /// (133 urad/s).
    pub const GYRO_RPS: f64 = 1.0 / (1u64 << 17) as f64;
    /// Die temperature, degC: 2^-12 (0.24 mK), 1/12 of one count (3.0 mK).
    pub const TEMP_C: f64 = 1.0 / (1u64 << 12) as f64;
    /// Position, its 1-sigma and the distance travelled, m: 2^-16 (15 um).
    pub const POSITION_M: f64 = 1.0 / (1u64 << 16) as f64;
    /// Velocity and its 1-sigma, m/s: 2^-16 (15 um/s).
    pub const VELOCITY_MPS: f64 = 1.0 / (1u64 << 16) as f64;
    /// Attitude quaternion components: 2^-20 (about 2 urad of rotation).
    pub const ATTITUDE: f64 = 1.0 / (1u64 << 20) as f64;

    /// `value` as a recording gives it back at resolution `quantum`.
    pub fn recorded(value: f64, quantum: f64) -> f64 {
        f64::from(super::proto::quantize(value, quantum))
    }
}

/// Topic of the simulator's ground truth.
pub const TRUTH_TOPIC: &str = "mems/sim/truth";
/// How a channel's messages are encoded, from its message encoding and its schema's encoding:
/// the decoder its messages go through, and the encoding a [`Writer`] writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MessageEncoding {
    /// `json` described by `jsonschema` (or schemaless), read with `serde_json`: what older
    /// recordings hold.
    Json,
    /// `protobuf` described by a `protobuf` schema (a `FileDescriptorSet`), read with
    /// `prost`: what [`Writer::create`] writes; a recorder's finished file is half the size
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
    /// The protobuf message of the topic ([`proto`], or Foxglove's for its schemas).
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

impl Topic for RawImuSample {
    const TOPIC: &'static str = ipc_types::service::RAW;
    const SCHEMA_NAME: &'static str = "mems.RawImuSample";

    type Proto = proto::RawImuSample;

    fn proto_schema() -> Vec<u8> {
        proto::file_descriptor_set()
    }

    /// Writes the scaled values only where they are not what the counts give with one of
    /// the part's sensitivities (the one of the previous sample first).
    fn fill_proto(&self, p: &mut Self::Proto) {
        use ipc_types::units::{self, AccelRange, GyroRange};
        p.stamps = Some(self.stamps.into());
        p.seq = self.seq;
        p.accel_lsb_per_g = proto::sensitivity(
            &self.accel_g,
            &self.accel_counts,
            p.accel_lsb_per_g,
            [
                AccelRange::G2,
                AccelRange::G4,
                AccelRange::G8,
                AccelRange::G16,
            ]
            .map(AccelRange::lsb_per_g),
        );
        p.gyro_lsb_per_dps = proto::sensitivity(
            &self.gyro_dps,
            &self.gyro_counts,
            p.gyro_lsb_per_dps,
            [
                GyroRange::Dps250,
                GyroRange::Dps500,
                GyroRange::Dps1000,
                GyroRange::Dps2000,
            ]
            .map(GyroRange::lsb_per_dps),
        );
        proto::fill(&mut p.accel_g, written(p.accel_lsb_per_g, &self.accel_g));
        proto::fill(&mut p.gyro_dps, written(p.gyro_lsb_per_dps, &self.gyro_dps));
        p.temp_from_counts =
            units::temp_c_from_counts(self.temp_counts).to_bits() == self.temp_c.to_bits();
        p.temp_c = (!p.temp_from_counts).then_some(self.temp_c);
        proto::fill(&mut p.accel_counts, &self.accel_counts);
        proto::fill(&mut p.gyro_counts, &self.gyro_counts);
        p.temp_counts = self.temp_counts.into();
        p.flags = self.flags.into();
        p.lost_before = self.lost_before;
        p.undelivered = self.undelivered;
    }

    fn from_proto(p: Self::Proto) -> std::result::Result<Self, String> {
        let accel_counts = proto::array("accel_counts", &p.accel_counts)?;
        let gyro_counts = proto::array("gyro_counts", &p.gyro_counts)?;
        let temp_counts = proto::narrow("temp_counts", p.temp_counts)?;
        let temp_c = match p.temp_c {
            _ if p.temp_from_counts => ipc_types::units::temp_c_from_counts(temp_counts),
            // proto3 omits a 0 (older recordings' `temp_c` has no presence).
            value => value.unwrap_or(0.0),
        };
        Ok(Self {
            stamps: proto::stamps(p.stamps)?,
            seq: p.seq,
            accel_g: proto::scaled("accel_g", &p.accel_g, &accel_counts, p.accel_lsb_per_g)?,
            gyro_dps: proto::scaled("gyro_dps", &p.gyro_dps, &gyro_counts, p.gyro_lsb_per_dps)?,
            temp_c,
            accel_counts,
            gyro_counts,
            temp_counts,
            flags: proto::narrow("flags", p.flags)?,
            lost_before: p.lost_before,
            undelivered: p.undelivered,
        })
    }

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
                (
                    "undelivered",
                    uint(
                        "Samples the publisher gave up delivering so far because a subscriber stayed full, all subscribers.",
                        u32::MAX.into(),
                    ),
                ),
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

    type Proto = proto::Truth;

    fn proto_schema() -> Vec<u8> {
        proto::file_descriptor_set()
    }

    fn fill_proto(&self, p: &mut Self::Proto) {
        p.t_ns = self.t_ns;
        proto::fill(&mut p.position_m, &self.position_m);
        proto::fill(&mut p.velocity_mps, &self.velocity_mps);
        proto::fill(&mut p.attitude_wxyz, &self.attitude_wxyz);
        proto::fill(&mut p.specific_force_mps2, &self.specific_force_mps2);
        proto::fill(&mut p.angular_rate_rps, &self.angular_rate_rps);
        p.at_rest = self.at_rest;
    }

    fn from_proto(p: Self::Proto) -> std::result::Result<Self, String> {
        Ok(Self {
            t_ns: p.t_ns,
            position_m: proto::array("position_m", &p.position_m)?,
            velocity_mps: proto::array("velocity_mps", &p.velocity_mps)?,
            attitude_wxyz: proto::array("attitude_wxyz", &p.attitude_wxyz)?,
            specific_force_mps2: proto::array("specific_force_mps2", &p.specific_force_mps2)?,
            angular_rate_rps: proto::array("angular_rate_rps", &p.angular_rate_rps)?,
            at_rest: p.at_rest,
        })
    }

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

impl Topic for CorrectedImuSample {
    const TOPIC: &'static str = ipc_types::service::CORRECTED;
    const SCHEMA_NAME: &'static str = "mems.CorrectedImuSample";

    type Proto = proto::CorrectedImuSample;

    fn proto_schema() -> Vec<u8> {
        proto::file_descriptor_set()
    }

    fn fill_proto(&self, p: &mut Self::Proto) {
        p.stamps = Some(self.stamps.into());
        p.seq = self.seq;
        proto::fill_f32(&mut p.accel_mps2, &self.accel_mps2, quantum::ACCEL_MPS2);
        proto::fill_f32(&mut p.gyro_rps, &self.gyro_rps, quantum::GYRO_RPS);
        p.temp_c = Some(proto::quantize(self.temp_c, quantum::TEMP_C));
        proto::fill_f32(&mut p.zs_mean_mps2, &self.zs_mean_mps2, quantum::ACCEL_MPS2);
        proto::fill_f32(&mut p.zs_std_mps2, &self.zs_std_mps2, quantum::ACCEL_MPS2);
        p.calib_id = self.calib_id;
        p.flags = self.flags.into();
        p.raw_flags = self.raw_flags.into();
        p.settles = self.settles;
    }

    fn from_proto(p: Self::Proto) -> std::result::Result<Self, String> {
        Ok(Self {
            stamps: proto::stamps(p.stamps)?,
            seq: p.seq,
            accel_mps2: proto::array_f32("accel_mps2", &p.accel_mps2, &p.accel_mps2_f64)?,
            gyro_rps: proto::array_f32("gyro_rps", &p.gyro_rps, &p.gyro_rps_f64)?,
            temp_c: proto::scalar_f32(p.temp_c, p.temp_c_f64),
            zs_mean_mps2: proto::array_f32("zs_mean_mps2", &p.zs_mean_mps2, &p.zs_mean_mps2_f64)?,
            zs_std_mps2: proto::array_f32("zs_std_mps2", &p.zs_std_mps2, &p.zs_std_mps2_f64)?,
            calib_id: p.calib_id,
            flags: proto::narrow("flags", p.flags)?,
            raw_flags: proto::narrow("raw_flags", p.raw_flags)?,
            settles: p.settles,
        })
    }

    fn as_recorded(&self) -> Self {
        use quantum::{ACCEL_MPS2, GYRO_RPS, TEMP_C};
        Self {
            accel_mps2: self.accel_mps2.map(|x| quantum::recorded(x, ACCEL_MPS2)),
            gyro_rps: self.gyro_rps.map(|x| quantum::recorded(x, GYRO_RPS)),
            temp_c: quantum::recorded(self.temp_c, TEMP_C),
            zs_mean_mps2: self.zs_mean_mps2.map(|x| quantum::recorded(x, ACCEL_MPS2)),
            zs_std_mps2: self.zs_std_mps2.map(|x| quantum::recorded(x, ACCEL_MPS2)),
            ..*self
        }
    }

    fn json_schema() -> Value {
        object(
            Self::SCHEMA_NAME,
            "One calibrated sample, sensor frame, SI units (ipc-types CorrectedImuSample).",
            &[
                ("stamps", stamps_schema()),
                ("seq", uint("Sequence number of the raw sample.", u64::MAX)),
                (
                    "accel_mps2",
                    vector(3, number("Calibrated specific force, m/s^2, sensor frame.")),
                ),
                (
                    "gyro_rps",
                    vector(3, number("Calibrated angular rate, rad/s, sensor frame.")),
                ),
                ("temp_c", number("Die temperature, degC.")),
                (
                    "zs_mean_mps2",
                    vector(3, number("Zero-state window mean specific force, m/s^2.")),
                ),
                (
                    "zs_std_mps2",
                    vector(3, number("Zero-state window standard deviation, m/s^2.")),
                ),
                (
                    "calib_id",
                    uint("Identifier of the calibration applied.", u64::MAX),
                ),
                (
                    "flags",
                    uint("ipc-types corrected_flags bits.", u16::MAX.into()),
                ),
                (
                    "raw_flags",
                    uint("The raw sample's raw_flags bits.", u16::MAX.into()),
                ),
                (
                    "settles",
                    uint(
                        "Provisional samples before this one whose verdict it settles.",
                        u32::MAX.into(),
                    ),
                ),
            ],
        )
    }

    fn publish_time_ns(&self) -> u64 {
        self.stamps.sample_ns
    }

    fn is_finite(&self) -> bool {
        let mut values = self
            .accel_mps2
            .iter()
            .chain(&self.gyro_rps)
            .chain([&self.temp_c])
            .chain(&self.zs_mean_mps2)
            .chain(&self.zs_std_mps2);
        values.all(|v| v.is_finite())
    }
}

impl Topic for OdometryState {
    const TOPIC: &'static str = ipc_types::service::ODOMETRY;
    const SCHEMA_NAME: &'static str = "mems.OdometryState";

    type Proto = proto::OdometryState;

    fn proto_schema() -> Vec<u8> {
        proto::file_descriptor_set()
    }

    fn fill_proto(&self, p: &mut Self::Proto) {
        p.stamps = Some(self.stamps.into());
        p.seq = self.seq;
        proto::fill_f32(&mut p.position_m, &self.position_m, quantum::POSITION_M);
        proto::fill_f32(
            &mut p.position_sigma_m,
            &self.position_sigma_m,
            quantum::POSITION_M,
        );
        proto::fill_f32(
            &mut p.velocity_mps,
            &self.velocity_mps,
            quantum::VELOCITY_MPS,
        );
        proto::fill_f32(
            &mut p.velocity_sigma_mps,
            &self.velocity_sigma_mps,
            quantum::VELOCITY_MPS,
        );
        proto::fill_f32(
            &mut p.gravity_sensor_mps2,
            &self.gravity_sensor_mps2,
            quantum::ACCEL_MPS2,
        );
        proto::fill_f32(&mut p.attitude_wxyz, &self.attitude_wxyz, quantum::ATTITUDE);
        p.distance_m = Some(proto::quantize(self.distance_m, quantum::POSITION_M));
        p.flags = self.flags.into();
        p.rest_count = self.rest_count;
        p.hints_applied = self.hints_applied;
        p.hint_disagreements = self.hint_disagreements;
    }

    fn from_proto(p: Self::Proto) -> std::result::Result<Self, String> {
        Ok(Self {
            stamps: proto::stamps(p.stamps)?,
            seq: p.seq,
            position_m: proto::array_f32("position_m", &p.position_m, &p.position_m_f64)?,
            position_sigma_m: proto::array_f32(
                "position_sigma_m",
                &p.position_sigma_m,
                &p.position_sigma_m_f64,
            )?,
            velocity_mps: proto::array_f32("velocity_mps", &p.velocity_mps, &p.velocity_mps_f64)?,
            velocity_sigma_mps: proto::array_f32(
                "velocity_sigma_mps",
                &p.velocity_sigma_mps,
                &p.velocity_sigma_mps_f64,
            )?,
            gravity_sensor_mps2: proto::array_f32(
                "gravity_sensor_mps2",
                &p.gravity_sensor_mps2,
                &p.gravity_sensor_mps2_f64,
            )?,
            attitude_wxyz: proto::array_f32(
                "attitude_wxyz",
                &p.attitude_wxyz,
                &p.attitude_wxyz_f64,
            )?,
            distance_m: proto::scalar_f32(p.distance_m, p.distance_m_f64),
            flags: proto::narrow("flags", p.flags)?,
            reserved16: 0,
            rest_count: p.rest_count,
            hints_applied: p.hints_applied,
            hint_disagreements: p.hint_disagreements,
        })
    }

    fn as_recorded(&self) -> Self {
        use quantum::{ACCEL_MPS2, ATTITUDE, POSITION_M, VELOCITY_MPS, recorded};
        Self {
            position_m: self.position_m.map(|x| recorded(x, POSITION_M)),
            position_sigma_m: self.position_sigma_m.map(|x| recorded(x, POSITION_M)),
            velocity_mps: self.velocity_mps.map(|x| recorded(x, VELOCITY_MPS)),
            velocity_sigma_mps: self.velocity_sigma_mps.map(|x| recorded(x, VELOCITY_MPS)),
            gravity_sensor_mps2: self.gravity_sensor_mps2.map(|x| recorded(x, ACCEL_MPS2)),
            attitude_wxyz: self.attitude_wxyz.map(|x| recorded(x, ATTITUDE)),
            distance_m: recorded(self.distance_m, POSITION_M),
            ..*self
        }
    }

    fn json_schema() -> Value {
        object(
            Self::SCHEMA_NAME,
            "The odometry estimate at one sample time; navigation frame z-up (ipc-types OdometryState).",
            &[
                ("stamps", stamps_schema()),
                ("seq", uint("Sequence number of the raw sample.", u64::MAX)),
                (
                    "position_m",
                    vector(
                        3,
                        number("Displacement from alignment, m, navigation frame."),
                    ),
                ),
                (
                    "position_sigma_m",
                    vector(3, number("1-sigma of position_m, m.")),
                ),
                (
                    "velocity_mps",
                    vector(3, number("Velocity, m/s, navigation frame.")),
                ),
                (
                    "velocity_sigma_mps",
                    vector(3, number("1-sigma of velocity_mps, m/s.")),
                ),
                (
                    "gravity_sensor_mps2",
                    vector(
                        3,
                        number("Gravity's specific-force reaction, m/s^2, sensor frame."),
                    ),
                ),
                (
                    "attitude_wxyz",
                    vector(
                        4,
                        number("Unit quaternion (w, x, y, z), sensor to navigation frame."),
                    ),
                ),
                ("distance_m", number("Path length since alignment, m.")),
                (
                    "flags",
                    uint("ipc-types odometry_flags bits.", u16::MAX.into()),
                ),
                (
                    "rest_count",
                    uint("Rest intervals since alignment.", u32::MAX.into()),
                ),
                (
                    "hints_applied",
                    uint("Robot hints applied since alignment.", u32::MAX.into()),
                ),
                (
                    "hint_disagreements",
                    uint(
                        "Samples at which a fresh robot hint and the IMU detector disagreed.",
                        u32::MAX.into(),
                    ),
                ),
            ],
        )
    }

    /// The sample time of the state; for a revision, the time of the state it replaces.
    fn publish_time_ns(&self) -> u64 {
        self.stamps.sample_ns
    }

    fn is_finite(&self) -> bool {
        let mut values = self
            .position_m
            .iter()
            .chain(&self.position_sigma_m)
            .chain(&self.velocity_mps)
            .chain(&self.velocity_sigma_mps)
            .chain(&self.gravity_sensor_mps2)
            .chain(&self.attitude_wxyz)
            .chain([&self.distance_m]);
        values.all(|v| v.is_finite())
    }
}

impl Topic for RobotHint {
    const TOPIC: &'static str = ipc_types::service::HINT;
    const SCHEMA_NAME: &'static str = "mems.RobotHint";

    type Proto = proto::RobotHint;

    fn proto_schema() -> Vec<u8> {
        proto::file_descriptor_set()
    }

    fn fill_proto(&self, p: &mut Self::Proto) {
        p.stamps = Some(self.stamps.into());
        p.seq = self.seq;
        p.forward_speed_mps = self.forward_speed_mps;
        p.forward_speed_sigma_mps = self.forward_speed_sigma_mps;
        p.yaw_rate_rps = self.yaw_rate_rps;
        p.yaw_rate_sigma_rps = self.yaw_rate_sigma_rps;
        p.flags = self.flags.into();
    }

    fn from_proto(p: Self::Proto) -> std::result::Result<Self, String> {
        Ok(Self {
            stamps: proto::stamps(p.stamps)?,
            seq: p.seq,
            forward_speed_mps: p.forward_speed_mps,
            forward_speed_sigma_mps: p.forward_speed_sigma_mps,
            yaw_rate_rps: p.yaw_rate_rps,
            yaw_rate_sigma_rps: p.yaw_rate_sigma_rps,
            flags: proto::narrow("flags", p.flags)?,
            reserved16: 0,
            reserved: 0,
        })
    }

    fn json_schema() -> Value {
        object(
            Self::SCHEMA_NAME,
            "A rest/speed hint from the robot's controller; body frame x forward, y left, z up (ipc-types RobotHint).",
            &[
                ("stamps", stamps_schema()),
                (
                    "seq",
                    uint("The hint publisher's sequence number, from 0.", u64::MAX),
                ),
                (
                    "forward_speed_mps",
                    number("Forward speed along body x, m/s (valid with SPEED_VALID)."),
                ),
                (
                    "forward_speed_sigma_mps",
                    number("1-sigma of forward_speed_mps, m/s."),
                ),
                (
                    "yaw_rate_rps",
                    number(
                        "Yaw rate about body z, rad/s, counter-clockwise positive (valid with YAW_RATE_VALID).",
                    ),
                ),
                (
                    "yaw_rate_sigma_rps",
                    number("1-sigma of yaw_rate_rps, rad/s."),
                ),
                ("flags", uint("ipc-types hint_flags bits.", u16::MAX.into())),
            ],
        )
    }

    /// The time the hint describes (`stamps.sample_ns`, on the IMU samples' clock).
    fn publish_time_ns(&self) -> u64 {
        self.stamps.sample_ns
    }

    fn is_finite(&self) -> bool {
        [
            self.forward_speed_mps,
            self.forward_speed_sigma_mps,
            self.yaw_rate_rps,
            self.yaw_rate_sigma_rps,
        ]
        .iter()
        .all(|v| v.is_finite())
    }
}

/// Topic of the pose derived from each odometry state ([`PoseInFrame`]), for Foxglove.
pub const POSE_TOPIC: &str = "mems/odometry/pose";
/// The frame every [`PoseInFrame`] is expressed in: the navigation frame (z up, origin and
/// heading fixed at alignment).
pub const NAV_FRAME: &str = "nav";

/// A time as Foxglove's JSON schemas spell it: whole seconds and nanoseconds (here of
/// `CLOCK_MONOTONIC`, like every time in this project).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct FoxgloveTime {
    /// Whole seconds.
    pub sec: u64,
    /// Nanoseconds, 0..=999_999_999.
    pub nsec: u32,
}

impl FoxgloveTime {
    /// Splits integer nanoseconds.
    pub fn from_ns(ns: u64) -> Self {
        Self {
            sec: ns / 1_000_000_000,
            nsec: (ns % 1_000_000_000) as u32,
        }
    }

    /// Back to integer nanoseconds.
    pub fn to_ns(self) -> u64 {
        self.sec * 1_000_000_000 + u64::from(self.nsec)
    }

    /// Foxglove's protobuf timestamp (seconds saturated at `u32::MAX`, past 2106).
    pub fn foxglove(self) -> foxglove::messages::Timestamp {
        let sec = u32::try_from(self.sec).unwrap_or(u32::MAX);
        foxglove::messages::Timestamp::new_checked(sec, self.nsec)
            .unwrap_or(foxglove::messages::Timestamp::MAX)
    }
}

/// The encoded `FileDescriptorSet` of one of Foxglove's protobuf schemas, as its SDK ships it.
fn foxglove_schema<T: foxglove::Encode>() -> Vec<u8> {
    T::get_schema()
        .expect("Foxglove's messages have schemas")
        .data
        .into_owned()
}

/// A point or vector, Foxglove's `foxglove.Vector3`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FoxgloveVector3 {
    /// x component.
    pub x: f64,
    /// y component.
    pub y: f64,
    /// z component.
    pub z: f64,
}

/// A rotation, Foxglove's `foxglove.Quaternion` (note the order x, y, z, w).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FoxgloveQuaternion {
    /// x (vector part).
    pub x: f64,
    /// y (vector part).
    pub y: f64,
    /// z (vector part).
    pub z: f64,
    /// w (scalar part).
    pub w: f64,
}

/// Position and orientation, Foxglove's `foxglove.Pose`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FoxglovePose {
    /// Position, m.
    pub position: FoxgloveVector3,
    /// Orientation (rotates body-frame vectors into the frame named by `frame_id`).
    pub orientation: FoxgloveQuaternion,
}

/// The sensor's pose in the navigation frame, in the layout of Foxglove's `foxglove.PoseInFrame`
/// JSON schema (its optional `message_id` and `lineage` fields are not written), so that
/// Foxglove's 3D panel and plots understand it. Derived from an [`OdometryState`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseInFrame {
    /// The state's sample time (`stamps.sample_ns`), ns `CLOCK_MONOTONIC`.
    pub timestamp: FoxgloveTime,
    /// Always [`NAV_FRAME`] (borrowed: a pose per state allocates nothing).
    pub frame_id: Cow<'static, str>,
    /// `position_m` and `attitude_wxyz` of the state.
    pub pose: FoxglovePose,
}

impl PoseInFrame {
    /// The pose of an odometry state: its position (m, navigation frame) and its attitude
    /// (sensor to navigation frame), at its sample time.
    pub fn from_state(state: &OdometryState) -> Self {
        let [x, y, z] = state.position_m;
        let [w, qx, qy, qz] = state.attitude_wxyz;
        Self {
            timestamp: FoxgloveTime::from_ns(state.stamps.sample_ns),
            frame_id: Cow::Borrowed(NAV_FRAME),
            pose: FoxglovePose {
                position: FoxgloveVector3 { x, y, z },
                orientation: FoxgloveQuaternion {
                    x: qx,
                    y: qy,
                    z: qz,
                    w,
                },
            },
        }
    }
}

impl Topic for PoseInFrame {
    const TOPIC: &'static str = POSE_TOPIC;
    const SCHEMA_NAME: &'static str = "foxglove.PoseInFrame";

    type Proto = foxglove::messages::PoseInFrame;

    fn proto_schema() -> Vec<u8> {
        foxglove_schema::<Self::Proto>()
    }

    fn fill_proto(&self, p: &mut Self::Proto) {
        p.timestamp = Some(self.timestamp.foxglove());
        p.frame_id.clear();
        p.frame_id.push_str(&self.frame_id);
        let FoxglovePose {
            position: v,
            orientation: q,
        } = self.pose;
        p.pose = Some(foxglove::messages::Pose {
            position: Some(foxglove::messages::Vector3 {
                x: v.x,
                y: v.y,
                z: v.z,
            }),
            orientation: Some(foxglove::messages::Quaternion {
                x: q.x,
                y: q.y,
                z: q.z,
                w: q.w,
            }),
        });
    }

    fn from_proto(p: Self::Proto) -> std::result::Result<Self, String> {
        let t = p.timestamp.ok_or("field timestamp is absent")?;
        let pose = p.pose.ok_or("field pose is absent")?;
        let v = pose.position.ok_or("field pose.position is absent")?;
        let q = pose.orientation.ok_or("field pose.orientation is absent")?;
        Ok(Self {
            timestamp: FoxgloveTime {
                sec: t.sec().into(),
                nsec: t.nsec(),
            },
            frame_id: Cow::Owned(p.frame_id),
            pose: FoxglovePose {
                position: FoxgloveVector3 {
                    x: v.x,
                    y: v.y,
                    z: v.z,
                },
                orientation: FoxgloveQuaternion {
                    x: q.x,
                    y: q.y,
                    z: q.z,
                    w: q.w,
                },
            },
        })
    }

    fn json_schema() -> Value {
        let time = object(
            "time",
            "Timestamp of pose (CLOCK_MONOTONIC).",
            &[
                ("sec", uint("Whole seconds.", u64::MAX)),
                ("nsec", uint("Nanoseconds.", 999_999_999)),
            ],
        );
        let xyz = |title: &str, description: &str, names: &[&str]| {
            let fields: Vec<(&str, Value)> = names
                .iter()
                .map(|n| (*n, number(&format!("{n} component."))))
                .collect();
            object(title, description, &fields)
        };
        let pose = object(
            "foxglove.Pose",
            "Pose in 3D space.",
            &[
                (
                    "position",
                    xyz(
                        "foxglove.Vector3",
                        "Position, m, navigation frame.",
                        &["x", "y", "z"],
                    ),
                ),
                (
                    "orientation",
                    xyz(
                        "foxglove.Quaternion",
                        "Attitude, sensor to navigation frame.",
                        &["x", "y", "z", "w"],
                    ),
                ),
            ],
        );
        object(
            Self::SCHEMA_NAME,
            "A timestamped pose for an object or reference frame in 3D space.",
            &[
                ("timestamp", time),
                (
                    "frame_id",
                    json!({"type": "string", "description": "Frame of reference for pose position and orientation."}),
                ),
                ("pose", pose),
            ],
        )
    }

    fn publish_time_ns(&self) -> u64 {
        self.timestamp.to_ns()
    }

    fn is_finite(&self) -> bool {
        let FoxglovePose {
            position: p,
            orientation: q,
        } = self.pose;
        [p.x, p.y, p.z, q.x, q.y, q.z, q.w]
            .iter()
            .all(|v| v.is_finite())
    }
}

/// Topic of the recorder's own events ([`RecorderEvent`]).
pub const EVENTS_TOPIC: &str = "mems/recorder/events";

/// What a [`RecorderEvent`] reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EventKind {
    /// Sequence numbers `from_seq..=to_seq` never arrived: they are missing from the recording.
    Gap,
    /// The sequence went back: `to_seq` arrived when `from_seq` was expected (a restarted
    /// publisher that counts from 0 again).
    SeqReset,
    /// The service's last publisher went away (`from_seq` = `to_seq` = the last sequence
    /// number received, `None` if none was).
    PublisherLost,
    /// A publisher appeared again after [`EventKind::PublisherLost`] (sequence numbers as there).
    PublisherBack,
    /// The recorder was restarted and this file continues the run of the previous segment
    /// (see [`crate::segment`]): `from_seq` = `to_seq` = this segment's number (1 for the first
    /// successor), `service` empty. What was lost across the split follows as
    /// [`EventKind::Gap`] events.
    Segment,
}

impl EventKind {
    /// Every kind.
    pub const ALL: [Self; 5] = [
        Self::Gap,
        Self::SeqReset,
        Self::PublisherLost,
        Self::PublisherBack,
        Self::Segment,
    ];

    /// The kind's name, as JSON and protobuf spell it (`gap`, `seq_reset`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Self::Gap => "gap",
            Self::SeqReset => "seq_reset",
            Self::PublisherLost => "publisher_lost",
            Self::PublisherBack => "publisher_back",
            Self::Segment => "segment",
        }
    }
}

/// An event the recorder noticed on a service, so that a crashed or restarted stage shows in
/// the recording explicitly.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RecorderEvent {
    /// What happened.
    pub kind: EventKind,
    /// The service's base name (without namespace), e.g. `mems/imu/corrected`.
    pub service: String,
    /// First sequence number concerned (see [`EventKind`]).
    pub from_seq: Option<u64>,
    /// Last sequence number concerned (see [`EventKind`]).
    pub to_seq: Option<u64>,
    /// When the recorder noticed, ns `CLOCK_MONOTONIC`.
    pub t_ns: u64,
}

impl Topic for RecorderEvent {
    const TOPIC: &'static str = EVENTS_TOPIC;
    const SCHEMA_NAME: &'static str = "mems.RecorderEvent";

    type Proto = proto::RecorderEvent;

    fn proto_schema() -> Vec<u8> {
        proto::file_descriptor_set()
    }

    fn fill_proto(&self, p: &mut Self::Proto) {
        p.kind.clear();
        p.kind.push_str(self.kind.name());
        p.service.clear();
        p.service.push_str(&self.service);
        p.from_seq = self.from_seq;
        p.to_seq = self.to_seq;
        p.t_ns = self.t_ns;
    }

    fn from_proto(p: Self::Proto) -> std::result::Result<Self, String> {
        let kind = EventKind::ALL
            .into_iter()
            .find(|k| k.name() == p.kind)
            .ok_or_else(|| format!("field kind: unknown event kind {:?}", p.kind))?;
        Ok(Self {
            kind,
            service: p.service,
            from_seq: p.from_seq,
            to_seq: p.to_seq,
            t_ns: p.t_ns,
        })
    }

    fn json_schema() -> Value {
        let seq = |what: &str| {
            json!({
                "type": ["integer", "null"],
                "minimum": 0,
                "maximum": u64::MAX,
                "description": what,
            })
        };
        object(
            Self::SCHEMA_NAME,
            "Something the recorder noticed on a service: lost sequence numbers, a publisher gone or back.",
            &[
                (
                    "kind",
                    json!({
                        "type": "string",
                        "enum": ["gap", "seq_reset", "publisher_lost", "publisher_back", "segment"],
                        "description": "gap: from_seq..=to_seq missing; seq_reset: to_seq arrived when from_seq was expected; publisher_lost/back: from_seq = to_seq = last sequence number received (null if none); segment: a restarted recorder continues the run in this file, from_seq = to_seq = its segment number.",
                    }),
                ),
                (
                    "service",
                    json!({"type": "string", "description": "Service base name, e.g. mems/imu/raw."}),
                ),
                ("from_seq", seq("First sequence number concerned.")),
                ("to_seq", seq("Last sequence number concerned.")),
                (
                    "t_ns",
                    uint("When the recorder noticed, ns CLOCK_MONOTONIC.", u64::MAX),
                ),
            ],
        )
    }

    fn publish_time_ns(&self) -> u64 {
        self.t_ns
    }

    fn is_finite(&self) -> bool {
        true
    }
}

/// The scaled values a raw sample writes: none when they derive from the counts with
/// `sensitivity` (non-zero).
fn written(sensitivity: f64, values: &[f64; 3]) -> &[f64] {
    if sensitivity == 0.0 { values } else { &[] }
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

/// A channel of one of Foxglove's messages ([`Writer::add_foxglove_channel`]).
pub struct FoxgloveChannel<M> {
    id: u16,
    message: PhantomData<fn(&M)>,
}

impl<M> Clone for FoxgloveChannel<M> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<M> Copy for FoxgloveChannel<M> {}

/// The `mcap` crate's writer on a file.
type McapWriter = ::mcap::Writer<Sink>;

/// Where an `mcap` writer writes: a buffered file, or the recorder's flushed file, which is
/// whole after every flush ([`durable`]).
enum Sink {
    Buffered(BufWriter<File>),
    Durable(durable::DurableFile<File>),
}

impl Write for Sink {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match self {
            Self::Buffered(w) => w.write(buf),
            Self::Durable(w) => w.write(buf),
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        match self {
            Self::Buffered(w) => w.flush(),
            Self::Durable(w) => w.flush(),
        }
    }
}

impl Seek for Sink {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        match self {
            Self::Buffered(w) => w.seek(to),
            Self::Durable(w) => w.seek(to),
        }
    }
}

impl Sink {
    /// Flushes what is buffered and returns the file.
    fn into_file(self) -> std::io::Result<File> {
        match self {
            Self::Buffered(w) => w.into_inner().map_err(|e| e.into_error()),
            Self::Durable(w) => Ok(w.into_inner()),
        }
    }
}

/// zstd level of the compact copy a recorder writes beside its file
/// ([`Writer::create_new_compacting`]), measured on a 60 s, 1 kHz stack run (docs/recording.md,
/// "Size and write cost"): with [`COMPACT_CHUNK_BYTES`] it is 0.88 of the file flushed every
/// 50 ms at zstd's default level 3, and 0.96 of the same chunks at level 3; level 17 would
/// take 0.94 of level 9's bytes at 10 times its cost per message.
pub const COMPACT_LEVEL: u32 = 9;
/// Uncompressed size of the compact copy's chunks: 4 MiB (about 9 s of a 1 kHz run), 0.97 of
/// the size the `mcap` crate's default 1 MiB chunks take at [`COMPACT_LEVEL`].
pub const COMPACT_CHUNK_BYTES: u64 = 4 << 20;

/// Writes an MCAP recording to a file: zstd chunks, protobuf messages (or JSON, for files in
/// the older encoding: [`Writer::with_encoding`]).
///
/// Only [`Writer::finish`] completes the file: a writer dropped unfinished (a failed run)
/// leaves no file at its path, except the recorder's ([`Writer::create_new_compacting`]),
/// which holds what was flushed.
pub struct Writer {
    inner: McapWriter,
    /// The private temporary file renamed to the path at [`Writer::finish`]; `None` for the
    /// recorder's file, written in place.
    output: Option<mems_files::Output>,
    /// The compact copy of a recorder's file, if it writes one
    /// ([`Writer::create_new_compacting`]).
    compact: Option<Compact>,
    path: PathBuf,
    encoding: MessageEncoding,
    sequences: HashMap<u16, u32>,
    /// The encoded message being written, reused: a message allocates nothing once the
    /// buffer has grown to the largest one.
    buf: Vec<u8>,
    /// Each channel's protobuf message ([`Topic::Proto`]), reused in the same way.
    protos: HashMap<u16, Box<dyn Any>>,
    /// Shifts log and publish times to Unix time, once [`Writer::anchor`]ed.
    clock: Option<WallClock>,
}

impl Writer {
    /// Starts the file at `path`, which replaces any file there when finished (atomically:
    /// the file is written beside it and renamed; a symbolic link there is replaced, not
    /// followed), and writes the MCAP header.
    pub fn create(path: impl AsRef<Path>) -> Result<Self> {
        let replace = mems_files::Existing::Replace;
        Self::staged(path.as_ref(), replace, 0, DEFAULT_CHUNK_BYTES)
    }

    /// Starts the file at `path`, which must not exist (an existing file or symbolic link is
    /// never overwritten: the error names it and `--force`), as [`Writer::create`] does.
    pub fn create_new(path: impl AsRef<Path>) -> Result<Self> {
        let refuse = mems_files::Existing::Refuse;
        Self::staged(path.as_ref(), refuse, 0, DEFAULT_CHUNK_BYTES)
    }

    /// The recorder's file: created at `path`, which must not exist (0600), and written in
    /// place, each [`Writer::flush`] closing a chunk and leaving a whole MCAP file
    /// ([`durable`]), so that a killed recorder loses little and leaves a file every reader
    /// opens; and a compact copy beside it ([`compacting_path`]): the same records, in chunks
    /// of [`COMPACT_CHUNK_BYTES`] at zstd level [`COMPACT_LEVEL`], which [`Writer::flush`]
    /// leaves alone. [`Writer::finish`] finishes both and renames the copy over the file, so
    /// a finished recording is the compact one; a recorder killed before that leaves its
    /// flushed file (and a copy that [`remove_stale_copy`] removes).
    pub fn create_new_compacting(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let file = mems_files::create_new(path, None).map_err(|e| Error::io(path, e.io))?;
        let sink = Sink::Durable(durable::DurableFile::new(file));
        let mut writer = Self::on(path, sink, None, 0, DEFAULT_CHUNK_BYTES)?;
        // The header, committed: the file is whole from the start.
        writer.flush()?;
        let temp = compacting_path(path);
        let file = mems_files::create_new(&temp, None).map_err(|e| Error::io(&temp, e.io))?;
        let sink = Sink::Buffered(BufWriter::new(file));
        let copy = mcap_writer(&temp, sink, COMPACT_LEVEL, COMPACT_CHUNK_BYTES)?;
        writer.compact = Some(Compact {
            writer: Some(copy),
            temp,
        });
        Ok(writer)
    }

    /// Starts the file at `path` as [`Writer::create`] does, with chunks of `chunk_bytes`
    /// (uncompressed) compressed at zstd level `level` (0: zstd's default, 3): for measuring
    /// what they cost (`examples/encoding_cost.rs`).
    pub fn create_tuned(path: impl AsRef<Path>, level: u32, chunk_bytes: u64) -> Result<Self> {
        let replace = mems_files::Existing::Replace;
        Self::staged(path.as_ref(), replace, level, chunk_bytes)
    }

    /// A writer on a private temporary file renamed to `path` when finished.
    fn staged(
        path: &Path,
        existing: mems_files::Existing,
        level: u32,
        chunk_bytes: u64,
    ) -> Result<Self> {
        let mut output =
            mems_files::Output::create(path, None, existing).map_err(|e| Error::io(path, e.io))?;
        let file = output.file().try_clone().map_err(|e| Error::io(path, e))?;
        let sink = Sink::Buffered(BufWriter::new(file));
        Self::on(path, sink, Some(output), level, chunk_bytes)
    }

    /// Writes the MCAP header to `sink`, for chunks of `chunk_bytes` compressed at zstd level
    /// `level`.
    fn on(
        path: &Path,
        sink: Sink,
        output: Option<mems_files::Output>,
        level: u32,
        chunk_bytes: u64,
    ) -> Result<Self> {
        Ok(Self {
            inner: mcap_writer(path, sink, level, chunk_bytes)?,
            output,
            compact: None,
            path: path.to_path_buf(),
            encoding: MessageEncoding::Protobuf,
            sequences: HashMap::new(),
            buf: Vec::new(),
            protos: HashMap::new(),
            clock: None,
        })
    }

    /// Anchors the recording to the wall clock: writes `clock` as the metadata record
    /// [`crate::clock::METADATA_NAME`], and from now on every message's log and publish time
    /// is the Unix time (ns, UTC) of the monotonic time given for it
    /// ([`WallClock::unix_ns`]). The messages' own stamps stay `CLOCK_MONOTONIC`.
    pub fn anchor(&mut self, clock: WallClock) -> Result<()> {
        let metadata = ::mcap::records::Metadata {
            name: crate::clock::METADATA_NAME.into(),
            metadata: clock.metadata(),
        };
        self.each(|w| w.write_metadata(&metadata))?;
        self.clock = Some(clock);
        Ok(())
    }

    /// Writes the channels added from now on in `encoding` (protobuf unless told).
    pub fn with_encoding(mut self, encoding: MessageEncoding) -> Self {
        self.encoding = encoding;
        self
    }

    /// Adds the channel for messages of type `T` (its schema too, once). Adding the same type
    /// again returns the same channel.
    pub fn add_channel<T: Topic>(&mut self) -> Result<Channel<T>> {
        let schema = match self.encoding {
            MessageEncoding::Json => {
                serde_json::to_vec(&T::json_schema()).map_err(|e| self.fail(ErrorKind::Json(e)))?
            }
            MessageEncoding::Protobuf => T::proto_schema(),
        };
        let (schema_encoding, encoding) = (self.encoding.schema(), self.encoding.message());
        let schema_id = self.each(|w| w.add_schema(T::SCHEMA_NAME, schema_encoding, &schema))?;
        let id = self.each(|w| w.add_channel(schema_id, T::TOPIC, encoding, &BTreeMap::new()))?;
        if self.encoding == MessageEncoding::Protobuf {
            self.protos
                .entry(id)
                .or_insert_with(|| Box::new(T::Proto::default()));
        }
        Ok(Channel {
            id,
            message: PhantomData,
        })
    }

    /// Writes one message; `log_time_ns` is the MCAP log time (the recorder's receive time),
    /// the publish time is the message's own ([`Topic::publish_time_ns`]).
    ///
    /// On a JSON channel, errors if a float in the message is not finite (protobuf keeps
    /// every `f64` as it is).
    pub fn write<T: Topic>(
        &mut self,
        channel: Channel<T>,
        message: &T,
        log_time_ns: u64,
    ) -> Result<()> {
        let (publish_time, log_time_ns) = match &self.clock {
            Some(clock) => (
                clock.unix_ns(message.publish_time_ns()),
                clock.unix_ns(log_time_ns),
            ),
            None => (message.publish_time_ns(), log_time_ns),
        };
        self.buf.clear();
        match self.protos.get_mut(&channel.id) {
            Some(proto) => {
                let proto = proto
                    .downcast_mut::<T::Proto>()
                    .expect("a channel's protobuf message is its topic's");
                message.fill_proto(proto);
                prost::Message::encode(proto, &mut self.buf).expect("a Vec grows to any message");
            }
            None => {
                if !message.is_finite() {
                    let kind = ErrorKind::Invalid(format!(
                        "message at publish time {publish_time} ns holds NaN or infinity, which JSON cannot store"
                    ));
                    return Err(Error {
                        field: Some(T::TOPIC.to_owned()),
                        ..self.fail(kind)
                    });
                }
                serde_json::to_writer(&mut self.buf, message)
                    .map_err(|e| Error::file(&self.path, ErrorKind::Json(e)))?;
            }
        }
        self.write_buf(channel.id, publish_time, log_time_ns)
    }

    /// Writes the encoded message in `self.buf` on channel `id` with these times (already
    /// anchored).
    fn write_buf(&mut self, id: u16, publish_time: u64, log_time: u64) -> Result<()> {
        let sequence = self.sequences.entry(id).or_default();
        let header = MessageHeader {
            channel_id: id,
            sequence: *sequence,
            log_time,
            publish_time,
        };
        *sequence = sequence.wrapping_add(1);
        let buf = std::mem::take(&mut self.buf);
        let written = self.each(|w| w.write_to_known_channel(&header, &buf));
        self.buf = buf;
        written
    }

    /// Runs `f` on the file's writer, then on the compact copy's (which takes the same
    /// records in the same order, so the ids they return are the same); an error names the
    /// file it was met on.
    fn each<T>(
        &mut self,
        mut f: impl FnMut(&mut McapWriter) -> ::mcap::McapResult<T>,
    ) -> Result<T> {
        let out = f(&mut self.inner).map_err(|e| self.fail(ErrorKind::Mcap(e)))?;
        if let Some(c) = &mut self.compact
            && let Some(w) = &mut c.writer
        {
            f(w).map_err(|e| Error::file(&c.temp, ErrorKind::Mcap(e)))?;
        }
        Ok(out)
    }

    /// The wall clock the file is anchored to ([`Writer::anchor`]), if it is.
    pub fn clock(&self) -> Option<WallClock> {
        self.clock
    }

    /// Adds a protobuf channel on `topic` for one of Foxglove's messages `M` (its SDK's
    /// schema), written as it is: the derived topics of [`derived`], which have no JSON form.
    pub fn add_foxglove_channel<M: foxglove::Encode>(
        &mut self,
        topic: &str,
    ) -> Result<FoxgloveChannel<M>> {
        let schema = M::get_schema().expect("Foxglove's messages have schemas");
        let schema_id =
            self.each(|w| w.add_schema(&schema.name, &schema.encoding, &schema.data))?;
        let id = self.each(|w| w.add_channel(schema_id, topic, "protobuf", &BTreeMap::new()))?;
        Ok(FoxgloveChannel {
            id,
            message: PhantomData,
        })
    }

    /// Writes one message on a Foxglove channel; `publish_time_ns` and `log_time_ns` are
    /// monotonic, anchored like [`Writer::write`]'s.
    pub fn write_foxglove<M: prost::Message>(
        &mut self,
        channel: FoxgloveChannel<M>,
        message: &M,
        publish_time_ns: u64,
        log_time_ns: u64,
    ) -> Result<()> {
        let (publish_time, log_time) = match &self.clock {
            Some(clock) => (clock.unix_ns(publish_time_ns), clock.unix_ns(log_time_ns)),
            None => (publish_time_ns, log_time_ns),
        };
        self.buf.clear();
        message
            .encode(&mut self.buf)
            .expect("a Vec grows to any message");
        self.write_buf(channel.id, publish_time, log_time)
    }

    /// Closes the current chunk and hands everything written so far to the operating system,
    /// so that a killed process loses nothing written before this call (the compact copy, if
    /// any, keeps its chunk open); the recorder's file is whole after it ([`durable`]).
    pub fn flush(&mut self) -> Result<()> {
        self.inner
            .flush()
            .map_err(|e| self.fail(ErrorKind::Mcap(e)))
    }

    /// Writes the summary and footer and renames the file to its path; the recorder's file
    /// gets its last chunk (it has no summary: readers read it from its start), and its
    /// compact copy is finished and renamed over it.
    pub fn finish(mut self) -> Result<()> {
        let closed = match self.output {
            Some(_) => self.inner.finish().map(drop),
            None => self.inner.flush(),
        };
        closed.map_err(|e| self.fail(ErrorKind::Mcap(e)))?;
        let (compact, output) = (self.compact.take(), self.output.take());
        let path = self.path.clone();
        self.inner
            .into_inner()
            .into_file()
            .map_err(|e| Error::io(&path, e))?;
        if let Some(output) = output {
            output.commit().map_err(|e| Error::io(&path, e.io))?;
        }
        compact.map_or(Ok(()), |c| c.finish(&path))
    }

    fn fail(&self, kind: ErrorKind) -> Error {
        Error::file(&self.path, kind)
    }
}

/// Uncompressed size of a chunk, unless a writer is tuned: the `mcap` crate's default (1 MiB).
const DEFAULT_CHUNK_BYTES: u64 = WriteOptions::DEFAULT_CHUNK_SIZE;

/// The `mcap` crate's writer of zstd chunks of `chunk_bytes` (uncompressed) at `level` on
/// `sink`, a new file at `path` (named in its error), with the MCAP header written. On the
/// recorder's flushed file ([`Sink::Durable`]) it keeps each chunk in memory until it closes.
fn mcap_writer(path: &Path, sink: Sink, level: u32, chunk_bytes: u64) -> Result<McapWriter> {
    let durable = matches!(sink, Sink::Durable(_));
    WriteOptions::new()
        .compression(Some(Compression::Zstd))
        .compression_level(level)
        .chunk_size(Some(chunk_bytes))
        .disable_seeking(durable)
        .create(sink)
        .map_err(|e| Error::file(path, ErrorKind::Mcap(e)))
}

/// The compact copy of a recorder's file ([`Writer::create_new_compacting`]): written at
/// `temp`, renamed over the file when finished, removed if dropped unfinished.
struct Compact {
    /// `None` once finished.
    writer: Option<McapWriter>,
    temp: PathBuf,
}

impl Compact {
    /// Finishes the copy, syncs it to disk and renames it over `target`, the file it copies.
    fn finish(mut self, target: &Path) -> Result<()> {
        let Some(mut writer) = self.writer.take() else {
            return Ok(());
        };
        writer
            .finish()
            .map_err(|e| Error::file(&self.temp, ErrorKind::Mcap(e)))?;
        let file = writer
            .into_inner()
            .into_file()
            .map_err(|e| Error::io(&self.temp, e))?;
        file.sync_all().map_err(|e| Error::io(&self.temp, e))?;
        std::fs::rename(&self.temp, target).map_err(|e| Error::io(target, e))
    }
}

impl Drop for Compact {
    fn drop(&mut self) {
        if self.writer.take().is_some() {
            // Unfinished: the flushed file is the recording. Best effort, as in any drop.
            let _ = std::fs::remove_file(&self.temp);
        }
    }
}

/// Where [`Writer::create_new_compacting`] writes the compact copy of `path`: `path` with
/// `.compacting` added (`run.mcap.compacting`), which no reader takes for a recording.
pub fn compacting_path(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(".compacting");
    PathBuf::from(name)
}

/// Removes the compact copy a killed recorder left beside `path`, if there is one; whether
/// it did.
pub fn remove_stale_copy(path: &Path) -> Result<bool> {
    let copy = compacting_path(path);
    match std::fs::remove_file(&copy) {
        Ok(()) => Ok(true),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(false),
        Err(e) => Err(Error::io(&copy, e)),
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
pub fn has_magic(path: &Path) -> Result<bool> {
    let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
    let mut start = Vec::with_capacity(MAGIC.len());
    Read::by_ref(&mut file)
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
    ///
    /// Memory is bounded by the file: a chunk that declares more than
    /// [`scan::MAX_CHUNK_EXPANSION`] times its record's size uncompressed is damage, and
    /// reading stops before it; no record or string may be longer than what holds it (see
    /// [`scan`]).
    pub fn messages(&self) -> Result<Messages<'_>> {
        Ok(Messages {
            path: &self.path,
            stream: scan::Scanner::new(&self.bytes),
            read: 0,
            done: false,
        })
    }
}

/// Iterator over the messages of a [`Reader`].
pub struct Messages<'a> {
    path: &'a Path,
    stream: scan::Scanner<std::io::Cursor<&'a [u8]>>,
    read: u64,
    done: bool,
}

impl Messages<'_> {
    /// The damaged records skipped so far ([`scan::Damage`]).
    pub fn damaged(&self) -> &[scan::Damage] {
        self.stream.damaged()
    }
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
                Some(Ok(Recorded {
                    source: self.path,
                    index: self.read,
                    topic: message.channel.topic.clone(),
                    schema_name: message.channel.schema_name.clone(),
                    encoding: message.channel.encoding.clone(),
                    schema_encoding: message.channel.schema_encoding.clone(),
                    log_time_ns: message.log_time_ns,
                    publish_time_ns: message.publish_time_ns,
                    data: message.data,
                }))
            }
            Some(Err(reason)) => {
                self.done = true;
                let truncation = Truncation {
                    messages_read: self.read,
                    reason,
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
    /// The encoding of the channel's schema ("" without a schema).
    pub schema_encoding: String,
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
        Some(decode_as(
            self.source,
            self.index,
            &self.topic,
            &self.schema_name,
            MessageEncoding::of(&self.encoding, &self.schema_encoding)
                .ok_or((&self.encoding, &self.schema_encoding)),
            &self.data,
        ))
    }
}

/// Decodes message `index` of `path` (on `topic`, schema `schema_name`, in `encoding` or in
/// an encoding no decoder reads) as a `T`; errors name the message.
pub(crate) fn decode_as<T: Topic>(
    path: &Path,
    index: u64,
    topic: &str,
    schema_name: &str,
    encoding: std::result::Result<MessageEncoding, (&String, &String)>,
    data: &[u8],
) -> Result<T> {
    let fail = |kind| Error::message(path, index, Some(topic), kind);
    let encoding = match encoding {
        Ok(e) if schema_name == T::SCHEMA_NAME => e,
        Ok(_) | Err(_) => {
            let (message, schema) = encoding.err().map_or(("json", ""), |(m, s)| (m, s));
            let kind = ErrorKind::Invalid(format!(
                "channel has encoding {message:?} (schema encoding {schema:?}) and schema \
                 {schema_name:?}, expected \"protobuf\" or \"json\" and {:?}",
                T::SCHEMA_NAME
            ));
            return Err(fail(kind));
        }
    };
    encoding.decode(data).map_err(fail)
}

/// Everything [`read_all`] found in a file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Contents {
    /// Raw samples in file order, exactly as recorded.
    pub raw: Vec<RawImuSample>,
    /// The acquisition sessions in `raw`, as index ranges in file order (none when `raw` is
    /// empty). A session ends where the sequence number does not increase: the publisher was
    /// restarted and counts from 0 again (an acquire restarted inside one recording, or two
    /// replays recorded into one file); its sample times may start over. Within a session,
    /// sample times strictly increase.
    pub raw_sessions: Vec<std::ops::Range<usize>>,
    /// Ground-truth records in file order.
    pub truth: Vec<Truth>,
    /// Corrected samples in file order.
    pub corrected: Vec<CorrectedImuSample>,
    /// Odometry states in file order (revisions included, where the odometry stage sent them).
    pub odometry: Vec<OdometryState>,
    /// Robot hints in file order.
    pub hints: Vec<RobotHint>,
    /// Poses derived from the odometry states, in file order.
    pub poses: Vec<PoseInFrame>,
    /// The recorder's events in file order.
    pub events: Vec<RecorderEvent>,
    /// Number of messages on other topics (not decoded).
    pub other_messages: u64,
    /// Set when the run's last segment ends early or is damaged (a killed recorder);
    /// everything before the cut is above.
    pub truncation: Option<Truncation>,
    /// The files read, in order: the run's first file and its successors
    /// ([`crate::segment`]), each with its own truncation (a segment whose recorder was killed
    /// ends early; the next one continues the run).
    pub segments: Vec<SegmentRead>,
}

/// One file of a run as [`read_all`] read it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SegmentRead {
    /// The file.
    pub path: PathBuf,
    /// Set when the file ends early or its record framing is damaged.
    pub truncation: Option<Truncation>,
    /// Damaged records skipped (the read went on after each), with what they held.
    pub damaged: Vec<scan::Damage>,
}

impl Contents {
    /// The raw samples of session `index` of [`Contents::raw_sessions`].
    ///
    /// Panics if there is no such session.
    pub fn raw_session(&self, index: usize) -> &[RawImuSample] {
        &self.raw[self.raw_sessions[index].clone()]
    }

    /// The raw samples and truth as a [`Recording`] of `path`. Errors with
    /// [`ErrorKind::SeveralSessions`] if the raw stream restarts: a [`Recording`] is one
    /// session, in time order.
    pub(crate) fn into_recording(self, path: &Path) -> Result<Recording> {
        if let Some(second) = self.raw_sessions.get(1) {
            let kind = ErrorKind::SeveralSessions {
                sessions: self.raw_sessions.len(),
                index: second.start,
                previous_seq: self.raw[second.start - 1].seq,
                seq: self.raw[second.start].seq,
            };
            return Err(Error::file(path, kind));
        }
        Ok(Recording {
            source: path.to_path_buf(),
            format: Format::Mcap,
            samples: self.raw,
            truth: (!self.truth.is_empty()).then_some(self.truth),
            truncation: self.truncation,
            repairs: crate::LogRepairs::default(),
        })
    }
}

/// Refuses a raw sample whose values the sensor cannot produce ([`limits::check_raw`]; the
/// gyroscope and temperature when their flags mark them valid).
fn check_raw_values(path: &Path, index: u64, topic: &str, sample: &RawImuSample) -> Result<()> {
    let gyro = sample.flags & ipc_types::raw_flags::GYRO_VALID != 0;
    let temp = sample.flags & ipc_types::raw_flags::TEMP_VALID != 0;
    limits::check_raw(
        &sample.accel_g,
        gyro.then_some(&sample.gyro_dps),
        temp.then_some(sample.temp_c),
    )
    .map_err(|bad| {
        let field = format!("{topic}: {}", bad.field);
        Error::message(path, index, Some(&field), ErrorKind::OutOfRange(bad))
    })
}

/// The checks of the raw stream as it is read: values the sensor can produce, and within a
/// session (a run of increasing sequence numbers) times that strictly increase by at most
/// [`limits::MAX_STEP_S`]. Public for readers that stream a run's raw samples themselves
/// (`mems-replay`), so that they refuse what [`read_all`] refuses.
#[derive(Debug, Clone, Copy, Default)]
pub struct RawChecks {
    /// The previous sample's sequence number and time.
    previous: Option<(u64, u64)>,
}

impl RawChecks {
    /// The sequence number of the last sample checked.
    pub fn previous_seq(&self) -> Option<u64> {
        self.previous.map(|(seq, _)| seq)
    }

    /// Checks `sample`, message `index` of `path` on `topic`; whether it starts a new session
    /// (the first sample, or a sequence number that does not increase).
    pub fn check(
        &mut self,
        path: &Path,
        index: u64,
        topic: &str,
        sample: &RawImuSample,
    ) -> Result<bool> {
        check_raw_values(path, index, topic, sample)?;
        let previous = self.previous.replace((sample.seq, sample.stamps.sample_ns));
        let Some((_, previous_ns)) = previous.filter(|(seq, _)| sample.seq > *seq) else {
            return Ok(true);
        };
        let t_ns = sample.stamps.sample_ns;
        let kind = if t_ns < previous_ns {
            ErrorKind::TimeBackwards { t_ns, previous_ns }
        } else if t_ns == previous_ns {
            ErrorKind::DuplicateTime { t_ns }
        } else if t_ns > previous_ns.saturating_add(limits::MAX_STEP_NS) {
            ErrorKind::TimeStep { t_ns, previous_ns }
        } else {
            return Ok(false);
        };
        let field = format!("{topic}: stamps.sample_ns");
        Err(Error::message(path, index, Some(&field), kind))
    }
}

/// Reads every message of the known topics of an MCAP recording (raw, truth, corrected,
/// odometry, robot hints, pose, events), from the file at `path` and then from each of its
/// successor segments ([`crate::segment`]: files named as successors that begin with their
/// [`EventKind::Segment`] event) as one run, each up to its cut if it was truncated
/// (reported in [`Contents::segments`], and for the last in [`Contents::truncation`], never
/// silently).
///
/// Raw samples are split into acquisition sessions where their sequence number restarts
/// ([`Contents::raw_sessions`]). Errors if the file is not MCAP, a message does not decode, a
/// raw sample holds a value the sensor cannot produce ([`limits::check_raw`]), or raw sample
/// times (`stamps.sample_ns`) do not strictly increase within a session or step further than
/// [`limits::MAX_STEP_S`].
pub fn read_all(path: impl AsRef<Path>) -> Result<Contents> {
    let path = path.as_ref();
    let mut contents = Contents::default();
    // The first file is read even if missing, for its error.
    let segments = crate::segment::existing(path);
    for (n, segment) in segments
        .iter()
        .map(PathBuf::as_path)
        .chain(segments.is_empty().then_some(path))
        .enumerate()
    {
        if n > 0 && !continues_run(segment, n)? {
            break;
        }
        let (truncation, damaged) = read_segment(segment, &mut contents)?;
        contents.segments.push(SegmentRead {
            path: segment.to_path_buf(),
            truncation: truncation.clone(),
            damaged,
        });
        contents.truncation = truncation;
    }
    Ok(contents)
}

/// Whether the file at `path` is segment `n` of a run: its first message is the recorder's
/// [`EventKind::Segment`] event numbered `n` (a file that merely has a successor's name is
/// not read with the run).
pub(crate) fn continues_run(path: &Path, n: usize) -> Result<bool> {
    let mut run = run::RunReader::one(path)?;
    Ok(match run.next() {
        Some(Ok(message)) => match message.decode::<RecorderEvent>() {
            Some(event) => {
                let event = event?;
                event.kind == EventKind::Segment && event.from_seq == Some(n as u64)
            }
            None => false,
        },
        _ => false,
    })
}

/// Appends the messages of one file to `contents`; returns its truncation, if any, and the
/// damaged records skipped.
fn read_segment(
    path: &Path,
    contents: &mut Contents,
) -> Result<(Option<Truncation>, Vec<scan::Damage>)> {
    let reader = Reader::open(path)?;
    let mut messages = reader.messages()?;
    while let Some(message) = messages.next() {
        let message = match message {
            Ok(message) => message,
            Err(Error {
                kind: ErrorKind::Truncated(truncation),
                ..
            }) => return Ok((Some(truncation), messages.damaged().to_vec())),
            Err(e) => return Err(e),
        };
        if let Some(sample) = message.decode::<RawImuSample>() {
            let sample = sample?;
            let mut checks = RawChecks {
                previous: contents.raw.last().map(|p| (p.seq, p.stamps.sample_ns)),
            };
            if checks.check(&reader.path, message.index, &message.topic, &sample)? {
                let start = contents.raw.len();
                contents.raw_sessions.push(start..start);
            }
            contents.raw.push(sample);
            if let Some(session) = contents.raw_sessions.last_mut() {
                session.end = contents.raw.len();
            }
        } else if let Some(truth) = message.decode::<Truth>() {
            contents.truth.push(truth?);
        } else if let Some(sample) = message.decode::<CorrectedImuSample>() {
            contents.corrected.push(sample?);
        } else if let Some(state) = message.decode::<OdometryState>() {
            contents.odometry.push(state?);
        } else if let Some(hint) = message.decode::<RobotHint>() {
            contents.hints.push(hint?);
        } else if let Some(pose) = message.decode::<PoseInFrame>() {
            contents.poses.push(pose?);
        } else if let Some(event) = message.decode::<RecorderEvent>() {
            contents.events.push(event?);
        } else {
            contents.other_messages += 1;
        }
    }
    Ok((None, messages.damaged().to_vec()))
}

/// The last sequence number of each service in one MCAP file (odometry revisions excluded),
/// as (topic, seq), for a restarted recorder to name what was lost across the split. Reads up
/// to the cut of a truncated file.
pub fn last_seqs(path: impl AsRef<Path>) -> Result<Vec<(&'static str, u64)>> {
    let reader = Reader::open(path)?;
    let mut last: Vec<(&'static str, u64)> = Vec::new();
    let mut note = |topic: &'static str, seq: u64| match last.iter_mut().find(|(t, _)| *t == topic)
    {
        Some(entry) => entry.1 = seq,
        None => last.push((topic, seq)),
    };
    for message in reader.messages()? {
        let Ok(message) = message else { break };
        if let Some(s) = message.decode::<RawImuSample>() {
            note(RawImuSample::TOPIC, s?.seq);
        } else if let Some(s) = message.decode::<CorrectedImuSample>() {
            note(CorrectedImuSample::TOPIC, s?.seq);
        } else if let Some(s) = message.decode::<OdometryState>() {
            let s = s?;
            if s.flags & ipc_types::odometry_flags::REVISION == 0 {
                note(OdometryState::TOPIC, s.seq);
            }
        } else if let Some(s) = message.decode::<RobotHint>() {
            note(RobotHint::TOPIC, s?.seq);
        }
    }
    Ok(last)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ipc_types::Stamps;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn stamps(rng: &mut ChaCha8Rng) -> Stamps {
        Stamps {
            sample_ns: rng.random(),
            acquired_ns: rng.random(),
            calibrated_ns: rng.random(),
            odometry_ns: rng.random(),
        }
    }

    /// Any finite f64 bit pattern (subnormals, -0.0 and extremes included).
    fn finite(rng: &mut ChaCha8Rng) -> f64 {
        loop {
            let v = f64::from_bits(rng.random());
            if v.is_finite() {
                return v;
            }
        }
    }

    fn corrected(rng: &mut ChaCha8Rng) -> CorrectedImuSample {
        CorrectedImuSample {
            stamps: stamps(rng),
            seq: rng.random(),
            accel_mps2: [(); 3].map(|_| finite(rng)),
            gyro_rps: [(); 3].map(|_| finite(rng)),
            temp_c: finite(rng),
            zs_mean_mps2: [(); 3].map(|_| finite(rng)),
            zs_std_mps2: [(); 3].map(|_| finite(rng)),
            calib_id: rng.random(),
            flags: rng.random(),
            raw_flags: rng.random(),
            settles: rng.random(),
        }
    }

    fn odometry(rng: &mut ChaCha8Rng) -> OdometryState {
        OdometryState {
            stamps: stamps(rng),
            seq: rng.random(),
            position_m: [(); 3].map(|_| finite(rng)),
            position_sigma_m: [(); 3].map(|_| finite(rng)),
            velocity_mps: [(); 3].map(|_| finite(rng)),
            velocity_sigma_mps: [(); 3].map(|_| finite(rng)),
            gravity_sensor_mps2: [(); 3].map(|_| finite(rng)),
            attitude_wxyz: [(); 4].map(|_| finite(rng)),
            distance_m: finite(rng),
            flags: rng.random(),
            reserved16: 0,
            rest_count: rng.random(),
            hints_applied: rng.random(),
            hint_disagreements: rng.random(),
        }
    }

    fn hint(rng: &mut ChaCha8Rng) -> RobotHint {
        RobotHint {
            stamps: stamps(rng),
            seq: rng.random(),
            forward_speed_mps: finite(rng),
            forward_speed_sigma_mps: finite(rng),
            yaw_rate_rps: finite(rng),
            yaw_rate_sigma_rps: finite(rng),
            flags: rng.random(),
            reserved16: 0,
            reserved: 0,
        }
    }

    fn tmp(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("recording-unit-{}-{name}", std::process::id()))
    }

    /// Every message type the recorder writes reads back bit for bit, each on its own topic,
    /// in both encodings.
    #[test]
    fn recorder_topics_round_trip_bit_exact() {
        round_trip(MessageEncoding::Protobuf);
        round_trip(MessageEncoding::Json);
    }

    fn round_trip(encoding: MessageEncoding) {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let corrected: Vec<_> = (0..50).map(|_| corrected(&mut rng)).collect();
        let odometry: Vec<_> = (0..50).map(|_| odometry(&mut rng)).collect();
        // Foxglove's timestamps hold whole seconds as u32 (up to 2106).
        let poses: Vec<_> = odometry
            .iter()
            .map(|s| {
                let mut s = *s;
                s.stamps.sample_ns %= u64::from(u32::MAX) * 1_000_000_000;
                PoseInFrame::from_state(&s)
            })
            .collect();
        let hints: Vec<_> = (0..50).map(|_| hint(&mut rng)).collect();
        let events = vec![
            RecorderEvent {
                kind: EventKind::Gap,
                service: ipc_types::service::CORRECTED.into(),
                from_seq: Some(10),
                to_seq: Some(19),
                t_ns: 5,
            },
            RecorderEvent {
                kind: EventKind::PublisherLost,
                service: ipc_types::service::RAW.into(),
                from_seq: None,
                to_seq: None,
                t_ns: u64::MAX,
            },
        ];
        let path = tmp(&format!("topics-{encoding:?}.mcap"));
        let mut writer = Writer::create(&path).unwrap().with_encoding(encoding);
        let c = writer.add_channel::<CorrectedImuSample>().unwrap();
        let o = writer.add_channel::<OdometryState>().unwrap();
        let p = writer.add_channel::<PoseInFrame>().unwrap();
        let e = writer.add_channel::<RecorderEvent>().unwrap();
        let h = writer.add_channel::<RobotHint>().unwrap();
        for i in 0..50 {
            writer.write(c, &corrected[i], i as u64).unwrap();
            writer.write(o, &odometry[i], i as u64).unwrap();
            writer.write(p, &poses[i], i as u64).unwrap();
            writer.write(h, &hints[i], i as u64).unwrap();
        }
        for event in &events {
            writer.write(e, event, event.t_ns).unwrap();
        }
        writer.finish().unwrap();

        let contents = read_all(&path).unwrap();
        // Protobuf records corrected samples and states at their quanta; JSON as they are.
        let (corrected, odometry): (Vec<_>, Vec<_>) = match encoding {
            MessageEncoding::Protobuf => (
                corrected.iter().map(Topic::as_recorded).collect(),
                odometry.iter().map(Topic::as_recorded).collect(),
            ),
            MessageEncoding::Json => (corrected, odometry),
        };
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(contents.corrected.len(), 50);
        for (a, b) in contents.corrected.iter().zip(&corrected) {
            assert_eq!(bits(&a.accel_mps2), bits(&b.accel_mps2));
            assert_eq!(bits(&a.zs_std_mps2), bits(&b.zs_std_mps2));
        }
        for (a, b) in contents.odometry.iter().zip(&odometry) {
            assert_eq!(bits(&a.position_m), bits(&b.position_m));
            assert_eq!(bits(&a.attitude_wxyz), bits(&b.attitude_wxyz));
        }
        assert_eq!(contents.hints.len(), 50);
        for (a, b) in contents.hints.iter().zip(&hints) {
            let fields = |x: &RobotHint| {
                bits(&[
                    x.forward_speed_mps,
                    x.forward_speed_sigma_mps,
                    x.yaw_rate_rps,
                    x.yaw_rate_sigma_rps,
                ])
            };
            assert_eq!(fields(a), fields(b));
        }
        // PartialEq on f64 treats -0.0 == 0.0; the bit comparisons above catch that case.
        assert_eq!(contents.corrected, corrected);
        assert_eq!(contents.odometry, odometry);
        assert_eq!(contents.hints, hints);
        assert_eq!(contents.poses, poses);
        assert_eq!(contents.events, events);
        assert!(contents.raw.is_empty() && contents.truncation.is_none());
        assert_eq!(contents.other_messages, 0);

        // publish_time is each message's own time.
        let reader = Reader::open(&path).unwrap();
        for m in reader.messages().unwrap() {
            let m = m.unwrap();
            let expected = if let Some(s) = m.decode::<CorrectedImuSample>() {
                s.unwrap().stamps.sample_ns
            } else if let Some(s) = m.decode::<OdometryState>() {
                s.unwrap().stamps.sample_ns
            } else if let Some(s) = m.decode::<PoseInFrame>() {
                s.unwrap().timestamp.to_ns()
            } else if let Some(s) = m.decode::<RobotHint>() {
                s.unwrap().stamps.sample_ns
            } else {
                m.decode::<RecorderEvent>().unwrap().unwrap().t_ns
            };
            assert_eq!(m.publish_time_ns, expected, "{}", m.topic);
        }
        std::fs::remove_file(&path).unwrap();
    }

    /// The pose is the state's position and attitude in Foxglove's JSON layout: quaternion
    /// reordered from (w, x, y, z) to {x, y, z, w}, time split into sec and nsec.
    #[test]
    fn pose_has_foxglove_layout() {
        let state = OdometryState {
            stamps: Stamps {
                sample_ns: 12_345_678_901,
                ..Stamps::default()
            },
            position_m: [1.5, -2.0, 0.25],
            attitude_wxyz: [0.5, -0.5, 0.5, -0.5],
            ..OdometryState::default()
        };
        let json = serde_json::to_value(PoseInFrame::from_state(&state)).unwrap();
        assert_eq!(
            json,
            json!({
                "timestamp": {"sec": 12, "nsec": 345_678_901},
                "frame_id": "nav",
                "pose": {
                    "position": {"x": 1.5, "y": -2.0, "z": 0.25},
                    "orientation": {"x": -0.5, "y": 0.5, "z": -0.5, "w": 0.5},
                },
            })
        );
    }

    /// Collects, for every object in `schema`, the path and its required property names.
    fn schema_objects(schema: &Value, at: &str, out: &mut Vec<(String, Vec<String>)>) {
        if let Some(properties) = schema["properties"].as_object() {
            let required = schema["required"].as_array().unwrap();
            let mut names: Vec<String> = required
                .iter()
                .map(|r| r.as_str().unwrap().into())
                .collect();
            names.sort();
            out.push((at.to_owned(), names));
            for (name, sub) in properties {
                schema_objects(sub, &format!("{at}.{name}"), out);
            }
        }
    }

    /// The same for a JSON value.
    fn value_objects(value: &Value, at: &str, out: &mut Vec<(String, Vec<String>)>) {
        if let Some(map) = value.as_object() {
            let mut names: Vec<String> = map.keys().cloned().collect();
            names.sort();
            out.push((at.to_owned(), names));
            for (name, sub) in map {
                value_objects(sub, &format!("{at}.{name}"), out);
            }
        }
    }

    fn assert_schema_describes<T: Topic>(message: &T) {
        let mut from_schema = Vec::new();
        schema_objects(&T::json_schema(), "", &mut from_schema);
        let mut from_value = Vec::new();
        value_objects(&serde_json::to_value(message).unwrap(), "", &mut from_value);
        from_schema.sort();
        from_value.sort();
        assert_eq!(from_schema, from_value, "{}", T::SCHEMA_NAME);
        assert_eq!(T::json_schema()["title"], T::SCHEMA_NAME);
    }

    /// Each schema names exactly the fields serde writes, at every nesting level.
    #[test]
    fn schemas_describe_the_serialized_messages() {
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let state = odometry(&mut rng);
        assert_schema_describes(&corrected(&mut rng));
        assert_schema_describes(&state);
        assert_schema_describes(&PoseInFrame::from_state(&state));
        assert_schema_describes(&hint(&mut rng));
        assert_schema_describes(&RecorderEvent {
            kind: EventKind::SeqReset,
            service: "s".into(),
            from_seq: Some(1),
            to_seq: Some(0),
            t_ns: 0,
        });
    }

    /// Event kinds serialize to the strings the schema's enum lists.
    #[test]
    fn event_kinds_match_the_schema_enum() {
        let kinds = [
            EventKind::Gap,
            EventKind::SeqReset,
            EventKind::PublisherLost,
            EventKind::PublisherBack,
            EventKind::Segment,
        ];
        let written: Vec<Value> = kinds
            .iter()
            .map(|k| serde_json::to_value(k).unwrap())
            .collect();
        let schema = RecorderEvent::json_schema();
        assert_eq!(
            &written,
            schema["properties"]["kind"]["enum"].as_array().unwrap()
        );
    }

    /// Protobuf keeps NaN and infinity: a raw sample's values bit for bit (they are not what
    /// the counts give, so they are written as `double`s), a state's as `float`s.
    #[test]
    fn protobuf_keeps_non_finite_values() {
        let path = tmp("nan-protobuf.mcap");
        let mut writer = Writer::create(&path).unwrap();
        let r = writer.add_channel::<RawImuSample>().unwrap();
        let o = writer.add_channel::<OdometryState>().unwrap();
        let nan = f64::from_bits(0x7ff8_0000_dead_beef);
        let raw = RawImuSample {
            accel_g: [nan, f64::INFINITY, -0.0],
            temp_c: f64::NEG_INFINITY,
            ..RawImuSample::default()
        };
        writer.write(r, &raw, 0).unwrap();
        let state = OdometryState {
            distance_m: nan,
            position_m: [f64::INFINITY, f64::NEG_INFINITY, -0.0],
            ..OdometryState::default()
        };
        writer.write(o, &state, 0).unwrap();
        writer.finish().unwrap();
        let reader = Reader::open(&path).unwrap();
        let mut messages = reader.messages().unwrap().map(Result::unwrap);
        let back = messages
            .next()
            .unwrap()
            .decode::<RawImuSample>()
            .unwrap()
            .unwrap();
        assert_eq!(
            back.accel_g.map(f64::to_bits),
            raw.accel_g.map(f64::to_bits)
        );
        assert_eq!(back.temp_c, f64::NEG_INFINITY);
        let back = messages
            .next()
            .unwrap()
            .decode::<OdometryState>()
            .unwrap()
            .unwrap();
        assert!(back.distance_m.is_nan());
        let bits = back.position_m.map(f64::to_bits);
        assert_eq!(bits, state.position_m.map(f64::to_bits));
        std::fs::remove_file(&path).unwrap();
    }

    /// On a JSON channel, NaN in a corrected sample or an odometry state is refused, naming
    /// the topic.
    #[test]
    fn non_finite_values_are_refused() {
        let path = tmp("nan.mcap");
        let mut writer = Writer::create(&path)
            .unwrap()
            .with_encoding(MessageEncoding::Json);
        let o = writer.add_channel::<OdometryState>().unwrap();
        let state = OdometryState {
            distance_m: f64::NAN,
            ..OdometryState::default()
        };
        let err = writer.write(o, &state, 0).unwrap_err();
        assert!(err.to_string().contains("mems/odometry/state"), "{err}");
        let h = writer.add_channel::<RobotHint>().unwrap();
        let hint = RobotHint {
            forward_speed_sigma_mps: f64::INFINITY,
            ..RobotHint::default()
        };
        let err = writer.write(h, &hint, 0).unwrap_err();
        assert!(err.to_string().contains("mems/robot/hint"), "{err}");
        drop(writer);
        assert!(!path.exists(), "an unfinished writer leaves no file");
    }
}
