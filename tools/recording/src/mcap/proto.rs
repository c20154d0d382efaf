//! The protobuf form of our own messages (package `mems`, file `mems.proto`): the prost
//! structs the recording encodes and decodes, and the `FileDescriptorSet` written as the
//! schema of each channel (schema encoding `protobuf`), so that Foxglove and the official
//! readers (`mcap-protobuf-support`) decode them.
//!
//! Field names follow the JSON form, numbered in its order; fixed-size arrays are `repeated`
//! (packed) fields holding exactly their length, `i16` counts are `sint32`, `u16` flags are
//! `uint32`, and an absent sequence number of a recorder event is an unset `optional`.
//! Precision (docs/recording.md, "Precision"): time stamps and counts are exact; a raw
//! sample's scaled values are not written when they are exactly what its counts give (the
//! sensitivity is, and the reader computes them bit for bit); the corrected samples' and the
//! odometry states' quantities are `float` under new field numbers, their older `double`
//! numbers reserved (older recordings hold them, and the structs still read them); hints and
//! ground truth are `double`.
//!
//! The descriptor is built here from one table per message rather than compiled from a
//! `.proto` file: prost's code generator needs `protoc` at build time, and the table is what
//! such a file would hold. The Python decoding test of the recorder checks it against the
//! official decoder.

// Each field is the field of the same name in the ipc-types struct (or the JSON form) it mirrors,
// documented there.
#![allow(missing_docs)]

use prost_types::descriptor_proto::ReservedRange;
use prost_types::field_descriptor_proto::{Label, Type};
use prost_types::{
    DescriptorProto, FieldDescriptorProto, FileDescriptorProto, FileDescriptorSet,
    OneofDescriptorProto,
};

/// [`ipc_types::Stamps`].
#[derive(Clone, Copy, PartialEq, prost::Message)]
pub struct Stamps {
    #[prost(uint64, tag = 1)]
    pub sample_ns: u64,
    #[prost(uint64, tag = 2)]
    pub acquired_ns: u64,
    #[prost(uint64, tag = 3)]
    pub calibrated_ns: u64,
    #[prost(uint64, tag = 4)]
    pub odometry_ns: u64,
}

/// [`ipc_types::RawImuSample`]. The scaled values are written only when they are not
/// exactly what the counts give: `accel_g` when it is not `accel_counts / accel_lsb_per_g`
/// (then `accel_lsb_per_g` is 0), likewise `gyro_dps` with `gyro_lsb_per_dps`, and `temp_c`
/// when `temp_from_counts` is false. Older recordings hold every value and no sensitivity.
#[derive(Clone, PartialEq, prost::Message)]
pub struct RawImuSample {
    #[prost(message, optional, tag = 1)]
    pub stamps: Option<Stamps>,
    #[prost(uint64, tag = 2)]
    pub seq: u64,
    #[prost(double, repeated, tag = 3)]
    pub accel_g: Vec<f64>,
    #[prost(double, repeated, tag = 4)]
    pub gyro_dps: Vec<f64>,
    #[prost(double, optional, tag = 5)]
    pub temp_c: Option<f64>,
    #[prost(sint32, repeated, tag = 6)]
    pub accel_counts: Vec<i32>,
    #[prost(sint32, repeated, tag = 7)]
    pub gyro_counts: Vec<i32>,
    #[prost(sint32, tag = 8)]
    pub temp_counts: i32,
    #[prost(uint32, tag = 9)]
    pub flags: u32,
    #[prost(uint32, tag = 10)]
    pub lost_before: u32,
    #[prost(uint32, tag = 11)]
    pub undelivered: u32,
    /// Counts per g that `accel_g` is derived with; 0 when `accel_g` is written.
    #[prost(double, tag = 12)]
    pub accel_lsb_per_g: f64,
    /// Counts per deg/s that `gyro_dps` is derived with; 0 when `gyro_dps` is written.
    #[prost(double, tag = 13)]
    pub gyro_lsb_per_dps: f64,
    /// `temp_c` is `temp_counts / 333.87 + 21` ([`ipc_types::units::temp_c_from_counts`]).
    #[prost(bool, tag = 14)]
    pub temp_from_counts: bool,
}

/// [`ipc_types::CorrectedImuSample`]: `float`s under new tags (12-16); older recordings hold
/// `double`s under tags 3-7 (the `*_f64` fields), read when the `float` ones are absent.
#[derive(Clone, PartialEq, prost::Message)]
pub struct CorrectedImuSample {
    #[prost(message, optional, tag = 1)]
    pub stamps: Option<Stamps>,
    #[prost(uint64, tag = 2)]
    pub seq: u64,
    #[prost(double, repeated, tag = 3)]
    pub accel_mps2_f64: Vec<f64>,
    #[prost(double, repeated, tag = 4)]
    pub gyro_rps_f64: Vec<f64>,
    #[prost(double, tag = 5)]
    pub temp_c_f64: f64,
    #[prost(double, repeated, tag = 6)]
    pub zs_mean_mps2_f64: Vec<f64>,
    #[prost(double, repeated, tag = 7)]
    pub zs_std_mps2_f64: Vec<f64>,
    #[prost(uint64, tag = 8)]
    pub calib_id: u64,
    #[prost(uint32, tag = 9)]
    pub flags: u32,
    #[prost(uint32, tag = 10)]
    pub raw_flags: u32,
    #[prost(uint32, tag = 11)]
    pub settles: u32,
    #[prost(float, repeated, tag = 12)]
    pub accel_mps2: Vec<f32>,
    #[prost(float, repeated, tag = 13)]
    pub gyro_rps: Vec<f32>,
    #[prost(float, optional, tag = 14)]
    pub temp_c: Option<f32>,
    #[prost(float, repeated, tag = 15)]
    pub zs_mean_mps2: Vec<f32>,
    #[prost(float, repeated, tag = 16)]
    pub zs_std_mps2: Vec<f32>,
    #[prost(float, repeated, tag = 17)]
    pub refined_accel_mps2: Vec<f32>,
    #[prost(float, repeated, tag = 18)]
    pub refined_gyro_rps: Vec<f32>,
}

/// [`ipc_types::OdometryState`]: `float`s under new tags (15-21); older recordings hold
/// `double`s under tags 3-9 (the `*_f64` fields), read when the `float` ones are absent.
#[derive(Clone, PartialEq, prost::Message)]
pub struct OdometryState {
    #[prost(message, optional, tag = 1)]
    pub stamps: Option<Stamps>,
    #[prost(uint64, tag = 2)]
    pub seq: u64,
    #[prost(double, repeated, tag = 3)]
    pub position_m_f64: Vec<f64>,
    #[prost(double, repeated, tag = 4)]
    pub position_sigma_m_f64: Vec<f64>,
    #[prost(double, repeated, tag = 5)]
    pub velocity_mps_f64: Vec<f64>,
    #[prost(double, repeated, tag = 6)]
    pub velocity_sigma_mps_f64: Vec<f64>,
    #[prost(double, repeated, tag = 7)]
    pub gravity_sensor_mps2_f64: Vec<f64>,
    #[prost(double, repeated, tag = 8)]
    pub attitude_wxyz_f64: Vec<f64>,
    #[prost(double, tag = 9)]
    pub distance_m_f64: f64,
    #[prost(uint32, tag = 10)]
    pub flags: u32,
    #[prost(uint32, tag = 12)]
    pub rest_count: u32,
    #[prost(uint32, tag = 13)]
    pub hints_applied: u32,
    #[prost(uint32, tag = 14)]
    pub hint_disagreements: u32,
    #[prost(float, repeated, tag = 15)]
    pub position_m: Vec<f32>,
    #[prost(float, repeated, tag = 16)]
    pub position_sigma_m: Vec<f32>,
    #[prost(float, repeated, tag = 17)]
    pub velocity_mps: Vec<f32>,
    #[prost(float, repeated, tag = 18)]
    pub velocity_sigma_mps: Vec<f32>,
    #[prost(float, repeated, tag = 19)]
    pub gravity_sensor_mps2: Vec<f32>,
    #[prost(float, repeated, tag = 20)]
    pub attitude_wxyz: Vec<f32>,
    #[prost(float, optional, tag = 21)]
    pub distance_m: Option<f32>,
}

/// [`ipc_types::RobotHint`].
#[derive(Clone, PartialEq, prost::Message)]
pub struct RobotHint {
    #[prost(message, optional, tag = 1)]
    pub stamps: Option<Stamps>,
    #[prost(uint64, tag = 2)]
    pub seq: u64,
    #[prost(double, tag = 3)]
    pub forward_speed_mps: f64,
    #[prost(double, tag = 4)]
    pub forward_speed_sigma_mps: f64,
    #[prost(double, tag = 5)]
    pub yaw_rate_rps: f64,
    #[prost(double, tag = 6)]
    pub yaw_rate_sigma_rps: f64,
    #[prost(uint32, tag = 7)]
    pub flags: u32,
}

/// [`crate::Truth`].
#[derive(Clone, PartialEq, prost::Message)]
pub struct Truth {
    #[prost(uint64, tag = 1)]
    pub t_ns: u64,
    #[prost(double, repeated, tag = 2)]
    pub position_m: Vec<f64>,
    #[prost(double, repeated, tag = 3)]
    pub velocity_mps: Vec<f64>,
    #[prost(double, repeated, tag = 4)]
    pub attitude_wxyz: Vec<f64>,
    #[prost(double, repeated, tag = 5)]
    pub specific_force_mps2: Vec<f64>,
    #[prost(double, repeated, tag = 6)]
    pub angular_rate_rps: Vec<f64>,
    #[prost(bool, tag = 7)]
    pub at_rest: bool,
}

/// [`super::RecorderEvent`]; `kind` is the JSON form's string (`gap`, `seq_reset`, ...).
#[derive(Clone, PartialEq, prost::Message)]
pub struct RecorderEvent {
    #[prost(string, tag = 1)]
    pub kind: String,
    #[prost(string, tag = 2)]
    pub service: String,
    #[prost(uint64, optional, tag = 3)]
    pub from_seq: Option<u64>,
    #[prost(uint64, optional, tag = 4)]
    pub to_seq: Option<u64>,
    #[prost(uint64, tag = 5)]
    pub t_ns: u64,
}

/// A field's kind in the descriptor table.
#[derive(Clone, Copy)]
enum Kind {
    U64,
    U32,
    S32,
    F64,
    Bool,
    Str,
    /// `repeated double`.
    F64s,
    /// `repeated float`.
    F32s,
    /// `repeated sint32`.
    S32s,
    /// `optional uint64` (proto3 explicit presence).
    OptU64,
    /// `optional double`.
    OptF64,
    /// `optional float`.
    OptF32,
    /// The `mems.Stamps` message.
    Stamps,
}

/// One message of the descriptor: its name, its fields (name, number, kind) as the structs
/// above write them, and the numbers it no longer writes (those of older recordings' `double`
/// fields, which the structs still read).
struct Table {
    name: &'static str,
    fields: &'static [(&'static str, i32, Kind)],
    reserved: &'static [(i32, i32)],
}

/// Every message of `mems.proto`.
const MESSAGES: &[Table] = {
    use Kind::*;
    &[
        Table {
            name: "Stamps",
            fields: &[
                ("sample_ns", 1, U64),
                ("acquired_ns", 2, U64),
                ("calibrated_ns", 3, U64),
                ("odometry_ns", 4, U64),
            ],
            reserved: &[],
        },
        Table {
            name: "RawImuSample",
            fields: &[
                ("stamps", 1, Stamps),
                ("seq", 2, U64),
                ("accel_g", 3, F64s),
                ("gyro_dps", 4, F64s),
                ("temp_c", 5, OptF64),
                ("accel_counts", 6, S32s),
                ("gyro_counts", 7, S32s),
                ("temp_counts", 8, S32),
                ("flags", 9, U32),
                ("lost_before", 10, U32),
                ("undelivered", 11, U32),
                ("accel_lsb_per_g", 12, F64),
                ("gyro_lsb_per_dps", 13, F64),
                ("temp_from_counts", 14, Bool),
            ],
            reserved: &[],
        },
        Table {
            name: "CorrectedImuSample",
            fields: &[
                ("stamps", 1, Stamps),
                ("seq", 2, U64),
                ("calib_id", 8, U64),
                ("flags", 9, U32),
                ("raw_flags", 10, U32),
                ("settles", 11, U32),
                ("accel_mps2", 12, F32s),
                ("gyro_rps", 13, F32s),
                ("temp_c", 14, OptF32),
                ("zs_mean_mps2", 15, F32s),
                ("zs_std_mps2", 16, F32s),
                ("refined_accel_mps2", 17, F32s),
                ("refined_gyro_rps", 18, F32s),
            ],
            reserved: &[(3, 7)],
        },
        Table {
            name: "OdometryState",
            fields: &[
                ("stamps", 1, Stamps),
                ("seq", 2, U64),
                ("flags", 10, U32),
                ("rest_count", 12, U32),
                ("hints_applied", 13, U32),
                ("hint_disagreements", 14, U32),
                ("position_m", 15, F32s),
                ("position_sigma_m", 16, F32s),
                ("velocity_mps", 17, F32s),
                ("velocity_sigma_mps", 18, F32s),
                ("gravity_sensor_mps2", 19, F32s),
                ("attitude_wxyz", 20, F32s),
                ("distance_m", 21, OptF32),
            ],
            reserved: &[(3, 9), (11, 11)],
        },
        Table {
            name: "RobotHint",
            fields: &[
                ("stamps", 1, Stamps),
                ("seq", 2, U64),
                ("forward_speed_mps", 3, F64),
                ("forward_speed_sigma_mps", 4, F64),
                ("yaw_rate_rps", 5, F64),
                ("yaw_rate_sigma_rps", 6, F64),
                ("flags", 7, U32),
            ],
            reserved: &[],
        },
        Table {
            name: "Truth",
            fields: &[
                ("t_ns", 1, U64),
                ("position_m", 2, F64s),
                ("velocity_mps", 3, F64s),
                ("attitude_wxyz", 4, F64s),
                ("specific_force_mps2", 5, F64s),
                ("angular_rate_rps", 6, F64s),
                ("at_rest", 7, Bool),
            ],
            reserved: &[],
        },
        Table {
            name: "RecorderEvent",
            fields: &[
                ("kind", 1, Str),
                ("service", 2, Str),
                ("from_seq", 3, OptU64),
                ("to_seq", 4, OptU64),
                ("t_ns", 5, U64),
            ],
            reserved: &[],
        },
    ]
};

/// The descriptor of one message of [`MESSAGES`].
fn message(table: &Table) -> DescriptorProto {
    let mut oneofs = Vec::new();
    let field = |&(field_name, number, kind): &(&str, i32, Kind)| {
        let (label, ty) = match kind {
            Kind::U64 | Kind::OptU64 => (Label::Optional, Type::Uint64),
            Kind::U32 => (Label::Optional, Type::Uint32),
            Kind::S32 => (Label::Optional, Type::Sint32),
            Kind::F64 | Kind::OptF64 => (Label::Optional, Type::Double),
            Kind::OptF32 => (Label::Optional, Type::Float),
            Kind::Bool => (Label::Optional, Type::Bool),
            Kind::Str => (Label::Optional, Type::String),
            Kind::F64s => (Label::Repeated, Type::Double),
            Kind::F32s => (Label::Repeated, Type::Float),
            Kind::S32s => (Label::Repeated, Type::Sint32),
            Kind::Stamps => (Label::Optional, Type::Message),
        };
        let mut f = FieldDescriptorProto {
            name: Some(field_name.into()),
            number: Some(number),
            label: Some(label as i32),
            r#type: Some(ty as i32),
            json_name: Some(field_name.into()),
            ..Default::default()
        };
        if let Kind::Stamps = kind {
            f.type_name = Some(".mems.Stamps".into());
        }
        if let Kind::OptU64 | Kind::OptF64 | Kind::OptF32 = kind {
            // proto3 `optional`: a synthetic one-field oneof named `_NAME`.
            f.proto3_optional = Some(true);
            f.oneof_index = Some(oneofs.len() as i32);
            oneofs.push(OneofDescriptorProto {
                name: Some(format!("_{field_name}")),
                options: None,
            });
        }
        f
    };
    let field = table.fields.iter().map(field).collect();
    // A reserved range's end is exclusive in the descriptor.
    let reserved_range = table
        .reserved
        .iter()
        .map(|&(start, end)| ReservedRange {
            start: Some(start),
            end: Some(end + 1),
        })
        .collect();
    DescriptorProto {
        name: Some(table.name.into()),
        field,
        oneof_decl: oneofs,
        reserved_range,
        ..Default::default()
    }
}

/// The `FileDescriptorSet` of `mems.proto` (every message of package `mems`), encoded: the
/// data of each protobuf schema record.
pub fn file_descriptor_set() -> Vec<u8> {
    let file = FileDescriptorProto {
        name: Some("mems.proto".into()),
        package: Some("mems".into()),
        message_type: MESSAGES.iter().map(message).collect(),
        syntax: Some("proto3".into()),
        ..Default::default()
    };
    prost::Message::encode_to_vec(&FileDescriptorSet { file: vec![file] })
}

/// Copies `values` into `out`, keeping its storage (no allocation once it has grown).
pub fn fill<T: Copy, U: From<T>>(out: &mut Vec<U>, values: &[T]) {
    out.clear();
    out.extend(values.iter().map(|&v| U::from(v)));
}

/// The `N` values of the repeated field `name`; errors if there are not exactly `N` or one
/// does not fit `T`.
pub fn array<const N: usize, T, U>(name: &str, values: &[U]) -> Result<[T; N], String>
where
    U: Copy + TryInto<T> + std::fmt::Display,
    T: Copy + Default,
{
    if values.len() != N {
        return Err(format!(
            "field {name} holds {} values, expected {N}",
            values.len()
        ));
    }
    let mut out = [T::default(); N];
    for (o, &v) in out.iter_mut().zip(values) {
        *o = v
            .try_into()
            .map_err(|_| format!("field {name}: {v} is out of range"))?;
    }
    Ok(out)
}

/// `value` rounded to the nearest multiple of `quantum` (a power of two), as a `float`:
/// exact while `|value| < 2^24 quantum`, beyond that `float`'s own rounding of it. NaN and
/// infinities stay what they are.
pub fn quantize(value: f64, quantum: f64) -> f32 {
    ((value / quantum).round() * quantum) as f32
}

/// [`quantize`]d `values` into `out`, keeping its storage.
pub fn fill_f32(out: &mut Vec<f32>, values: &[f64], quantum: f64) {
    out.clear();
    out.extend(values.iter().map(|&v| quantize(v, quantum)));
}

/// The `N` values of field `name`: its `float`s (`values`, widened exactly), or in an older
/// recording its `double`s (`older`, the field's former number); errors unless exactly one
/// of them holds exactly `N`.
pub fn array_f32<const N: usize>(
    name: &str,
    values: &[f32],
    older: &[f64],
) -> Result<[f64; N], String> {
    if values.is_empty() {
        return array(name, older);
    }
    if !older.is_empty() {
        return Err(format!("field {name} holds both float and double values"));
    }
    let values: [f32; N] = array(name, values)?;
    Ok(values.map(f64::from))
}

/// A `float` scalar widened exactly, or in an older recording its `double` (0 when neither
/// is present, as proto3 writes 0).
pub fn scalar_f32(value: Option<f32>, older: f64) -> f64 {
    value.map_or(older, f64::from)
}

/// The sensitivity (counts per unit) among `last` and then `candidates` with which `values`
/// are exactly `counts / sensitivity`, bit for bit, as the driver computes them; 0 if none
/// is (the values are then written).
pub fn sensitivity(
    values: &[f64; 3],
    counts: &[i16; 3],
    last: f64,
    candidates: impl IntoIterator<Item = f64>,
) -> f64 {
    let exact = |lsb: f64| {
        lsb != 0.0
            && values
                .iter()
                .zip(counts)
                .all(|(v, &c)| (f64::from(c) / lsb).to_bits() == v.to_bits())
    };
    std::iter::once(last)
        .chain(candidates)
        .find(|&lsb| exact(lsb))
        .unwrap_or(0.0)
}

/// The values of field `name`: those written, or `counts / sensitivity` when none are (an
/// error if neither is).
pub fn scaled(
    name: &str,
    values: &[f64],
    counts: &[i16; 3],
    sensitivity: f64,
) -> Result<[f64; 3], String> {
    if values.is_empty() && sensitivity != 0.0 {
        return Ok(counts.map(|c| f64::from(c) / sensitivity));
    }
    array(name, values)
}

/// `value` as a `T`, or an error naming field `name`.
pub fn narrow<T, U: Copy + TryInto<T> + std::fmt::Display>(
    name: &str,
    value: U,
) -> Result<T, String> {
    value
        .try_into()
        .map_err(|_| format!("field {name}: {value} is out of range"))
}

impl From<ipc_types::Stamps> for Stamps {
    fn from(s: ipc_types::Stamps) -> Self {
        Self {
            sample_ns: s.sample_ns,
            acquired_ns: s.acquired_ns,
            calibrated_ns: s.calibrated_ns,
            odometry_ns: s.odometry_ns,
        }
    }
}

/// The stamps of a message; errors if the field is absent.
pub fn stamps(s: Option<Stamps>) -> Result<ipc_types::Stamps, String> {
    let s = s.ok_or("field stamps is absent")?;
    Ok(ipc_types::Stamps {
        sample_ns: s.sample_ns,
        acquired_ns: s.acquired_ns,
        calibrated_ns: s.calibrated_ns,
        odometry_ns: s.odometry_ns,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use prost::Message;

    /// The (number, wire type) of each field message `name` of the descriptor declares, and
    /// its reserved numbers.
    fn described(set: &FileDescriptorSet, name: &str) -> (Vec<(u32, u32)>, Vec<u32>) {
        let m = set.file[0]
            .message_type
            .iter()
            .find(|m| m.name() == name)
            .unwrap();
        let fields = m
            .field
            .iter()
            .map(|f| (f.number() as u32, wire_type(f)))
            .collect();
        let reserved = m
            .reserved_range
            .iter()
            .flat_map(|r| r.start() as u32..r.end() as u32)
            .collect();
        (fields, reserved)
    }

    /// The table and the structs agree: what the writer fills in encodes, field by field, to
    /// the numbers and wire types the descriptor gives, and the numbers of older recordings'
    /// `double`s are reserved, not reused.
    #[test]
    fn descriptor_numbers_match_the_structs() {
        use crate::mcap::Topic;
        let set = FileDescriptorSet::decode(file_descriptor_set().as_slice()).unwrap();
        let names: Vec<&str> = set.file[0].message_type.iter().map(|m| m.name()).collect();
        assert_eq!(
            names,
            [
                "Stamps",
                "RawImuSample",
                "CorrectedImuSample",
                "OdometryState",
                "RobotHint",
                "Truth",
                "RecorderEvent"
            ]
        );
        let ones = |n: f64| [n; 3];
        // Values the counts do not give, so that every field of the raw sample is written.
        let raw = ipc_types::RawImuSample {
            seq: 1,
            accel_g: ones(0.1),
            gyro_dps: ones(0.1),
            temp_c: 0.1,
            accel_counts: [-1; 3],
            gyro_counts: [-1; 3],
            temp_counts: -1,
            flags: 1,
            lost_before: 1,
            undelivered: 1,
            ..Default::default()
        };
        let mut p = RawImuSample::default();
        raw.fill_proto(&mut p);
        let (fields, _) = described(&set, "RawImuSample");
        assert_eq!(field_tags(&p.encode_to_vec()), fields[..11]);
        // Values the counts give: the sensitivities instead of the values.
        let raw = ipc_types::RawImuSample {
            accel_g: ones(-1.0 / 16384.0),
            gyro_dps: ones(-1.0 / 131.0),
            temp_c: ipc_types::units::temp_c_from_counts(-1),
            ..raw
        };
        raw.fill_proto(&mut p);
        let written = [&fields[..2], &fields[5..]].concat();
        assert_eq!(field_tags(&p.encode_to_vec()), written);

        let corrected = ipc_types::CorrectedImuSample {
            seq: 1,
            accel_mps2: ones(1.0),
            gyro_rps: ones(1.0),
            temp_c: 1.0,
            zs_mean_mps2: ones(1.0),
            zs_std_mps2: ones(1.0),
            calib_id: 1,
            flags: 1,
            raw_flags: 1,
            settles: 1,
            refined_accel_mps2: ones(1.0),
            refined_gyro_rps: ones(1.0),
            ..Default::default()
        };
        let mut p = CorrectedImuSample::default();
        corrected.fill_proto(&mut p);
        let (fields, reserved) = described(&set, "CorrectedImuSample");
        let mut tags = field_tags(&p.encode_to_vec());
        tags.sort();
        assert_eq!(tags, fields);
        assert_eq!(reserved, [3, 4, 5, 6, 7]);

        let state = ipc_types::OdometryState {
            seq: 1,
            position_m: ones(1.0),
            position_sigma_m: ones(1.0),
            velocity_mps: ones(1.0),
            velocity_sigma_mps: ones(1.0),
            gravity_sensor_mps2: ones(1.0),
            attitude_wxyz: [1.0; 4],
            distance_m: 1.0,
            flags: 1,
            rest_count: 1,
            hints_applied: 1,
            hint_disagreements: 1,
            ..Default::default()
        };
        let mut p = OdometryState::default();
        state.fill_proto(&mut p);
        let (fields, reserved) = described(&set, "OdometryState");
        let mut tags = field_tags(&p.encode_to_vec());
        tags.sort();
        assert_eq!(tags, fields);
        assert_eq!(reserved, [3, 4, 5, 6, 7, 8, 9, 11]);
    }

    /// A raw sample whose values are what its counts give writes none of them, and reads
    /// them back bit for bit; one whose values are not (a repaired sample, a thesis file)
    /// writes them. Every sensitivity of the part is found.
    #[test]
    fn raw_values_are_rebuilt_from_the_counts_bit_for_bit() {
        use crate::mcap::Topic;
        use ipc_types::units::{AccelRange, GyroRange, temp_c_from_counts};
        let accel = [
            AccelRange::G2,
            AccelRange::G4,
            AccelRange::G8,
            AccelRange::G16,
        ];
        let gyro = [
            GyroRange::Dps250,
            GyroRange::Dps500,
            GyroRange::Dps1000,
            GyroRange::Dps2000,
        ];
        let mut p = RawImuSample::default();
        for (a, g) in accel.into_iter().zip(gyro) {
            for c in [i16::MIN, -12345, -1, 0, 1, 7, 16384, i16::MAX] {
                let counts = [c, c.wrapping_add(1), c.wrapping_mul(3)];
                let raw = ipc_types::RawImuSample {
                    accel_g: counts.map(|c| f64::from(c) / a.lsb_per_g()),
                    gyro_dps: counts.map(|c| f64::from(c) / g.lsb_per_dps()),
                    temp_c: temp_c_from_counts(c),
                    accel_counts: counts,
                    gyro_counts: counts,
                    temp_counts: c,
                    ..Default::default()
                };
                raw.fill_proto(&mut p);
                assert!(p.accel_g.is_empty() && p.gyro_dps.is_empty() && p.temp_c.is_none());
                let back = ipc_types::RawImuSample::from_proto(p.clone()).unwrap();
                assert_eq!(
                    back.accel_g.map(f64::to_bits),
                    raw.accel_g.map(f64::to_bits)
                );
                assert_eq!(
                    back.gyro_dps.map(f64::to_bits),
                    raw.gyro_dps.map(f64::to_bits)
                );
                assert_eq!(back.temp_c.to_bits(), raw.temp_c.to_bits());
                let off = ipc_types::RawImuSample {
                    accel_g: [raw.accel_g[0], raw.accel_g[1], raw.accel_g[2] + 1e-9],
                    temp_c: -0.0,
                    ..raw
                };
                off.fill_proto(&mut p);
                assert_eq!((p.accel_lsb_per_g, p.accel_g.len()), (0.0, 3));
                let back = ipc_types::RawImuSample::from_proto(p.clone()).unwrap();
                assert_eq!(
                    back.accel_g.map(f64::to_bits),
                    off.accel_g.map(f64::to_bits)
                );
                assert_eq!(back.temp_c.to_bits(), (-0.0f64).to_bits());
            }
        }
    }

    /// A value is recorded at its quantum: a multiple of it, the nearest, exactly; -0.0,
    /// NaN and infinities stay what they are.
    #[test]
    fn quantize_rounds_to_the_nearest_multiple() {
        let q = 1.0 / 1024.0;
        for x in [0.1, -0.1, 9.80665, 1e-7, -3.0 / 2048.0, 123.456] {
            let r = f64::from(quantize(x, q));
            assert_eq!(r / q, (r / q).round(), "{x}");
            assert!((r - x).abs() <= q / 2.0, "{x}: {r}");
        }
        assert_eq!(quantize(-0.0, q).to_bits(), (-0.0f32).to_bits());
        assert!(quantize(f64::NAN, q).is_nan());
        assert_eq!(quantize(f64::NEG_INFINITY, q), f32::NEG_INFINITY);
        assert_eq!(quantize(1e300, q), f32::INFINITY);
    }

    /// The (field number, wire type) of each top-level field of an encoded message.
    fn field_tags(mut bytes: &[u8]) -> Vec<(u32, u32)> {
        let mut out = Vec::new();
        while !bytes.is_empty() {
            let key = prost::encoding::decode_varint(&mut bytes).unwrap();
            let (number, wire) = ((key >> 3) as u32, (key & 7) as u32);
            match wire {
                0 => {
                    prost::encoding::decode_varint(&mut bytes).unwrap();
                }
                1 => bytes = &bytes[8..],
                5 => bytes = &bytes[4..],
                2 => {
                    let n = prost::encoding::decode_varint(&mut bytes).unwrap() as usize;
                    bytes = &bytes[n..];
                }
                w => panic!("wire type {w}"),
            }
            out.push((number, wire));
        }
        out
    }

    /// The wire type a field of the descriptor is written with (repeated scalars packed).
    fn wire_type(f: &FieldDescriptorProto) -> u32 {
        if f.label() == Label::Repeated {
            return 2;
        }
        match f.r#type() {
            Type::Double => 1,
            Type::Float => 5,
            Type::Message | Type::String => 2,
            _ => 0,
        }
    }
}
