//! The pose derived from each odometry state, in Foxglove's `PoseInFrame` layout: its codec
//! and schema.

use std::borrow::Cow;

use ipc_types::OdometryState;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::Topic;
use super::schema::{number, object, uint};

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
