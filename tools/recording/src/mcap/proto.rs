//! The protobuf form of our own messages (package `mems`, file `mems.proto`): the prost
//! structs the recording encodes and decodes, and the `FileDescriptorSet` written as the
//! schema of each channel (schema encoding `protobuf`), so that Foxglove and the official
//! readers (`mcap-protobuf-support`) decode them.
//!
//! Field names and numbers follow the JSON form (the same names, numbered in the same order);
//! fixed-size arrays are `repeated` (packed) fields holding exactly their length, `i16` counts
//! are `sint32`, `u16` flags are `uint32`, and an absent sequence number of a recorder event
//! is an unset `optional`. Floats are `double`, so every `f64` reads back bit for bit.
//!
//! The descriptor is built here from one table per message rather than compiled from a
//! `.proto` file: prost's code generator needs `protoc` at build time, and the table is what
//! such a file would hold. The Python decoding test of the recorder checks it against the
//! official decoder.

// Each field is the field of the same name in the ipc-types struct (or the JSON form) it mirrors,
// documented there.
#![allow(missing_docs)]

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

/// [`ipc_types::RawImuSample`].
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
    #[prost(double, tag = 5)]
    pub temp_c: f64,
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
}

/// [`ipc_types::CorrectedImuSample`].
#[derive(Clone, PartialEq, prost::Message)]
pub struct CorrectedImuSample {
    #[prost(message, optional, tag = 1)]
    pub stamps: Option<Stamps>,
    #[prost(uint64, tag = 2)]
    pub seq: u64,
    #[prost(double, repeated, tag = 3)]
    pub accel_mps2: Vec<f64>,
    #[prost(double, repeated, tag = 4)]
    pub gyro_rps: Vec<f64>,
    #[prost(double, tag = 5)]
    pub temp_c: f64,
    #[prost(double, repeated, tag = 6)]
    pub zs_mean_mps2: Vec<f64>,
    #[prost(double, repeated, tag = 7)]
    pub zs_std_mps2: Vec<f64>,
    #[prost(uint64, tag = 8)]
    pub calib_id: u64,
    #[prost(uint32, tag = 9)]
    pub flags: u32,
    #[prost(uint32, tag = 10)]
    pub raw_flags: u32,
    #[prost(uint32, tag = 11)]
    pub settles: u32,
}

/// [`ipc_types::OdometryState`].
#[derive(Clone, PartialEq, prost::Message)]
pub struct OdometryState {
    #[prost(message, optional, tag = 1)]
    pub stamps: Option<Stamps>,
    #[prost(uint64, tag = 2)]
    pub seq: u64,
    #[prost(double, repeated, tag = 3)]
    pub position_m: Vec<f64>,
    #[prost(double, repeated, tag = 4)]
    pub position_sigma_m: Vec<f64>,
    #[prost(double, repeated, tag = 5)]
    pub velocity_mps: Vec<f64>,
    #[prost(double, repeated, tag = 6)]
    pub velocity_sigma_mps: Vec<f64>,
    #[prost(double, repeated, tag = 7)]
    pub gravity_sensor_mps2: Vec<f64>,
    #[prost(double, repeated, tag = 8)]
    pub attitude_wxyz: Vec<f64>,
    #[prost(double, tag = 9)]
    pub distance_m: f64,
    #[prost(uint32, tag = 10)]
    pub flags: u32,
    #[prost(uint32, tag = 11)]
    pub reserved16: u32,
    #[prost(uint32, tag = 12)]
    pub rest_count: u32,
    #[prost(uint32, tag = 13)]
    pub hints_applied: u32,
    #[prost(uint32, tag = 14)]
    pub hint_disagreements: u32,
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
    #[prost(uint32, tag = 8)]
    pub reserved16: u32,
    #[prost(uint32, tag = 9)]
    pub reserved: u32,
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
    /// `repeated sint32`.
    S32s,
    /// `optional uint64` (proto3 explicit presence).
    OptU64,
    /// The `mems.Stamps` message.
    Stamps,
}

/// Each message's fields in tag order (tag = position + 1), as the structs above declare them.
const MESSAGES: &[(&str, &[(&str, Kind)])] = {
    use Kind::*;
    &[
        (
            "Stamps",
            &[
                ("sample_ns", U64),
                ("acquired_ns", U64),
                ("calibrated_ns", U64),
                ("odometry_ns", U64),
            ],
        ),
        (
            "RawImuSample",
            &[
                ("stamps", Stamps),
                ("seq", U64),
                ("accel_g", F64s),
                ("gyro_dps", F64s),
                ("temp_c", F64),
                ("accel_counts", S32s),
                ("gyro_counts", S32s),
                ("temp_counts", S32),
                ("flags", U32),
                ("lost_before", U32),
                ("undelivered", U32),
            ],
        ),
        (
            "CorrectedImuSample",
            &[
                ("stamps", Stamps),
                ("seq", U64),
                ("accel_mps2", F64s),
                ("gyro_rps", F64s),
                ("temp_c", F64),
                ("zs_mean_mps2", F64s),
                ("zs_std_mps2", F64s),
                ("calib_id", U64),
                ("flags", U32),
                ("raw_flags", U32),
                ("settles", U32),
            ],
        ),
        (
            "OdometryState",
            &[
                ("stamps", Stamps),
                ("seq", U64),
                ("position_m", F64s),
                ("position_sigma_m", F64s),
                ("velocity_mps", F64s),
                ("velocity_sigma_mps", F64s),
                ("gravity_sensor_mps2", F64s),
                ("attitude_wxyz", F64s),
                ("distance_m", F64),
                ("flags", U32),
                ("reserved16", U32),
                ("rest_count", U32),
                ("hints_applied", U32),
                ("hint_disagreements", U32),
            ],
        ),
        (
            "RobotHint",
            &[
                ("stamps", Stamps),
                ("seq", U64),
                ("forward_speed_mps", F64),
                ("forward_speed_sigma_mps", F64),
                ("yaw_rate_rps", F64),
                ("yaw_rate_sigma_rps", F64),
                ("flags", U32),
                ("reserved16", U32),
                ("reserved", U32),
            ],
        ),
        (
            "Truth",
            &[
                ("t_ns", U64),
                ("position_m", F64s),
                ("velocity_mps", F64s),
                ("attitude_wxyz", F64s),
                ("specific_force_mps2", F64s),
                ("angular_rate_rps", F64s),
                ("at_rest", Bool),
            ],
        ),
        (
            "RecorderEvent",
            &[
                ("kind", Str),
                ("service", Str),
                ("from_seq", OptU64),
                ("to_seq", OptU64),
                ("t_ns", U64),
            ],
        ),
    ]
};

/// The descriptor of one message of [`MESSAGES`].
fn message(name: &str, fields: &[(&str, Kind)]) -> DescriptorProto {
    let mut oneofs = Vec::new();
    let field = |(number, &(field_name, kind)): (usize, &(&str, Kind))| {
        let (label, ty) = match kind {
            Kind::U64 | Kind::OptU64 => (Label::Optional, Type::Uint64),
            Kind::U32 => (Label::Optional, Type::Uint32),
            Kind::S32 => (Label::Optional, Type::Sint32),
            Kind::F64 => (Label::Optional, Type::Double),
            Kind::Bool => (Label::Optional, Type::Bool),
            Kind::Str => (Label::Optional, Type::String),
            Kind::F64s => (Label::Repeated, Type::Double),
            Kind::S32s => (Label::Repeated, Type::Sint32),
            Kind::Stamps => (Label::Optional, Type::Message),
        };
        let mut f = FieldDescriptorProto {
            name: Some(field_name.into()),
            number: Some(number as i32 + 1),
            label: Some(label as i32),
            r#type: Some(ty as i32),
            json_name: Some(field_name.into()),
            ..Default::default()
        };
        if let Kind::Stamps = kind {
            f.type_name = Some(".mems.Stamps".into());
        }
        if let Kind::OptU64 = kind {
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
    let field = fields.iter().enumerate().map(field).collect();
    DescriptorProto {
        name: Some(name.into()),
        field,
        oneof_decl: oneofs,
        ..Default::default()
    }
}

/// The `FileDescriptorSet` of `mems.proto` (every message of package `mems`), encoded: the
/// data of each protobuf schema record.
pub fn file_descriptor_set() -> Vec<u8> {
    let file = FileDescriptorProto {
        name: Some("mems.proto".into()),
        package: Some("mems".into()),
        message_type: MESSAGES.iter().map(|(n, f)| message(n, f)).collect(),
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

    /// The table and the structs agree: a struct whose every field is set encodes, field by
    /// field, to the numbers and wire types the descriptor gives (each field decoded alone
    /// as the descriptor's type).
    #[test]
    fn descriptor_numbers_match_the_structs() {
        let set = FileDescriptorSet::decode(file_descriptor_set().as_slice()).unwrap();
        let file = &set.file[0];
        let names: Vec<&str> = file.message_type.iter().map(|m| m.name()).collect();
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
        let raw = RawImuSample {
            stamps: Some(Stamps::default()),
            seq: 1,
            accel_g: vec![1.0; 3],
            gyro_dps: vec![1.0; 3],
            temp_c: 1.0,
            accel_counts: vec![-1; 3],
            gyro_counts: vec![-1; 3],
            temp_counts: -1,
            flags: 1,
            lost_before: 1,
            undelivered: 1,
        };
        let bytes = raw.encode_to_vec();
        let tags = field_tags(&bytes);
        let described: Vec<(u32, u32)> = file.message_type[1]
            .field
            .iter()
            .map(|f| (f.number() as u32, wire_type(f)))
            .collect();
        assert_eq!(tags, described);
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
            Type::Message | Type::String => 2,
            _ => 0,
        }
    }
}
