//! The ROS 2 messages we write, as serde structs whose field order is the `.msg` files' (CDR
//! writes fields in declaration order), and their `ros2msg` definitions.
//!
//! A complete definition is built as rosbag2 builds it for a bag
//! (`rosbag2_cpp::LocalMessageDefinitionSource::get_full_text`, and rosbag2's
//! `docs/message_definition_encoding.md`): the type's own definition, then each type it uses,
//! depth first in the sorted order of their names, each once, preceded by a line of 80 `=` and
//! a line `MSG: pkg/Type`. The definitions here hold the fields (names, types, defaults) of the
//! ROS 2 interface files without their comments.

use serde::ser::{Serialize, SerializeTuple, Serializer};

/// One `.msg` definition and the message types its fields use.
pub struct Definition {
    /// The name fields refer to it by, `pkg/Type` (`MSG:` lines carry it).
    pub name: &'static str,
    /// The `.msg` text, one field per line.
    pub text: &'static str,
    /// The definitions of the message types its fields use, sorted by name.
    pub uses: &'static [&'static Definition],
}

impl Definition {
    /// The complete `ros2msg` definition: this one, then every type it uses (see the module
    /// documentation).
    pub fn complete(&'static self) -> String {
        let mut seen = Vec::new();
        let mut out = String::new();
        self.append(&mut seen, &mut out);
        out
    }

    fn append(&'static self, seen: &mut Vec<&'static str>, out: &mut String) {
        out.push_str(self.text);
        for used in self.uses {
            if !seen.contains(&used.name) {
                seen.push(used.name);
                out.push('\n');
                out.push_str(&"=".repeat(80));
                out.push_str("\nMSG: ");
                out.push_str(used.name);
                out.push('\n');
                used.append(seen, out);
            }
        }
    }
}

/// A ROS 2 message type.
pub trait RosMessage: Serialize {
    /// Its full name, `pkg/msg/Type`: the MCAP schema's name.
    const TYPE_NAME: &'static str;
    /// Its type name as DDS declares it, `pkg::msg::dds_::Type_` (rmw_zenoh's key expressions
    /// carry it).
    const DDS_TYPE_NAME: &'static str;
    /// Its type hash (REP 2011 `RIHS01_` and the SHA-256 of its type description), as rosidl
    /// generates it for ROS 2 Jazzy: the test computes it from [`RosMessage::DEFINITION`] with
    /// rosbags and compares it with rosbags' copy of the Jazzy interfaces.
    const TYPE_HASH: &'static str;
    /// Its definition.
    const DEFINITION: &'static Definition;
}

const TIME: Definition = Definition {
    name: "builtin_interfaces/Time",
    text: "int32 sec\nuint32 nanosec\n",
    uses: &[],
};
const HEADER: Definition = Definition {
    name: "std_msgs/Header",
    text: "builtin_interfaces/Time stamp\nstring frame_id\n",
    uses: &[&TIME],
};
const VECTOR3: Definition = Definition {
    name: "geometry_msgs/Vector3",
    text: "float64 x\nfloat64 y\nfloat64 z\n",
    uses: &[],
};
const POINT: Definition = Definition {
    name: "geometry_msgs/Point",
    text: "float64 x\nfloat64 y\nfloat64 z\n",
    uses: &[],
};
const QUATERNION: Definition = Definition {
    name: "geometry_msgs/Quaternion",
    text: "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    uses: &[],
};
const POSE: Definition = Definition {
    name: "geometry_msgs/Pose",
    text: "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
    uses: &[&POINT, &QUATERNION],
};
const POSE_WITH_COVARIANCE: Definition = Definition {
    name: "geometry_msgs/PoseWithCovariance",
    text: "geometry_msgs/Pose pose\nfloat64[36] covariance\n",
    uses: &[&POSE],
};
const TWIST: Definition = Definition {
    name: "geometry_msgs/Twist",
    text: "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n",
    uses: &[&VECTOR3],
};
const TWIST_WITH_COVARIANCE: Definition = Definition {
    name: "geometry_msgs/TwistWithCovariance",
    text: "geometry_msgs/Twist twist\nfloat64[36] covariance\n",
    uses: &[&TWIST],
};
const TRANSFORM: Definition = Definition {
    name: "geometry_msgs/Transform",
    text: "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
    uses: &[&QUATERNION, &VECTOR3],
};
const TRANSFORM_STAMPED: Definition = Definition {
    name: "geometry_msgs/TransformStamped",
    text: "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n",
    uses: &[&TRANSFORM, &HEADER],
};
const IMU: Definition = Definition {
    name: "sensor_msgs/Imu",
    text: "std_msgs/Header header\n\
           geometry_msgs/Quaternion orientation\n\
           float64[9] orientation_covariance\n\
           geometry_msgs/Vector3 angular_velocity\n\
           float64[9] angular_velocity_covariance\n\
           geometry_msgs/Vector3 linear_acceleration\n\
           float64[9] linear_acceleration_covariance\n",
    uses: &[&QUATERNION, &VECTOR3, &HEADER],
};
const ODOMETRY: Definition = Definition {
    name: "nav_msgs/Odometry",
    text: "std_msgs/Header header\n\
           string child_frame_id\n\
           geometry_msgs/PoseWithCovariance pose\n\
           geometry_msgs/TwistWithCovariance twist\n",
    uses: &[&POSE_WITH_COVARIANCE, &TWIST_WITH_COVARIANCE, &HEADER],
};
const TF_MESSAGE: Definition = Definition {
    name: "tf2_msgs/TFMessage",
    text: "geometry_msgs/TransformStamped[] transforms\n",
    uses: &[&TRANSFORM_STAMPED],
};

/// `builtin_interfaces/msg/Time`: seconds and nanoseconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds, below 1e9.
    pub nanosec: u32,
}

impl Time {
    /// The time `ns` nanoseconds after the clock's zero; `None` past `i32::MAX` seconds
    /// (2038-01-19 for Unix time).
    pub fn from_ns(ns: u64) -> Option<Self> {
        Some(Self {
            sec: i32::try_from(ns / 1_000_000_000).ok()?,
            nanosec: (ns % 1_000_000_000) as u32,
        })
    }
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Header {
    /// The time the data describes.
    pub stamp: Time,
    /// The frame the data is expressed in.
    pub frame_id: String,
}

/// `geometry_msgs/msg/Vector3` (and `Point`, which has the same fields).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

impl From<[f64; 3]> for Vector3 {
    fn from([x, y, z]: [f64; 3]) -> Self {
        Self { x, y, z }
    }
}

/// `geometry_msgs/msg/Quaternion`: (x, y, z, w), w last.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Quaternion {
    /// The identity rotation (the message's default).
    pub const IDENTITY: Self = Self {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    };

    /// The quaternion given as (w, x, y, z), our order.
    pub fn from_wxyz([w, x, y, z]: [f64; 4]) -> Self {
        Self { x, y, z, w }
    }
}

/// A 6x6 covariance, row-major (`float64[36]`): serde implements arrays only up to 32
/// elements, so this writes its 36 as a fixed-size array (no length in CDR) itself.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Covariance6(pub [f64; 36]);

impl Serialize for Covariance6 {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut tuple = serializer.serialize_tuple(36)?;
        for value in &self.0 {
            tuple.serialize_element(value)?;
        }
        tuple.end()
    }
}

/// `sensor_msgs/msg/Imu`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Imu {
    /// Sample time and the sensor's frame.
    pub header: Header,
    /// Orientation of the frame.
    pub orientation: Quaternion,
    /// Row-major 3x3 about x, y, z, rad^2; element 0 is -1 when there is no orientation.
    pub orientation_covariance: [f64; 9],
    /// Angular rate, rad/s.
    pub angular_velocity: Vector3,
    /// Row-major 3x3, (rad/s)^2; all zero: unknown.
    pub angular_velocity_covariance: [f64; 9],
    /// Specific force, m/s^2.
    pub linear_acceleration: Vector3,
    /// Row-major 3x3, (m/s^2)^2; all zero: unknown.
    pub linear_acceleration_covariance: [f64; 9],
}

impl RosMessage for Imu {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/Imu";
    const DDS_TYPE_NAME: &'static str = "sensor_msgs::msg::dds_::Imu_";
    const TYPE_HASH: &'static str =
        "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b";
    const DEFINITION: &'static Definition = &IMU;
}

/// `geometry_msgs/msg/Pose`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Pose {
    /// Position, m.
    pub position: Vector3,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `geometry_msgs/msg/PoseWithCovariance`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct PoseWithCovariance {
    /// The pose.
    pub pose: Pose,
    /// Over (x, y, z, rotation about x, y, z), row-major.
    pub covariance: Covariance6,
}

/// `geometry_msgs/msg/Twist`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Twist {
    /// Velocity, m/s.
    pub linear: Vector3,
    /// Angular rate, rad/s.
    pub angular: Vector3,
}

/// `geometry_msgs/msg/TwistWithCovariance`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct TwistWithCovariance {
    /// The twist.
    pub twist: Twist,
    /// Over (vx, vy, vz, rate about x, y, z), row-major.
    pub covariance: Covariance6,
}

/// `nav_msgs/msg/Odometry`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Odometry {
    /// Time and the pose's frame.
    pub header: Header,
    /// The twist's frame.
    pub child_frame_id: String,
    /// Pose in `header.frame_id`.
    pub pose: PoseWithCovariance,
    /// Twist in `child_frame_id`.
    pub twist: TwistWithCovariance,
}

impl RosMessage for Odometry {
    const TYPE_NAME: &'static str = "nav_msgs/msg/Odometry";
    const DDS_TYPE_NAME: &'static str = "nav_msgs::msg::dds_::Odometry_";
    const TYPE_HASH: &'static str =
        "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0";
    const DEFINITION: &'static Definition = &ODOMETRY;
}

/// `geometry_msgs/msg/Transform`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Transform {
    /// Translation, m.
    pub translation: Vector3,
    /// Rotation.
    pub rotation: Quaternion,
}

/// `geometry_msgs/msg/TransformStamped`: the pose of `child_frame_id` in `header.frame_id`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TransformStamped {
    /// Time and the parent frame.
    pub header: Header,
    /// The child frame.
    pub child_frame_id: String,
    /// The child's pose in the parent.
    pub transform: Transform,
}

/// `tf2_msgs/msg/TFMessage`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TfMessage {
    /// The transforms.
    pub transforms: Vec<TransformStamped>,
}

impl RosMessage for TfMessage {
    const TYPE_NAME: &'static str = "tf2_msgs/msg/TFMessage";
    const DDS_TYPE_NAME: &'static str = "tf2_msgs::msg::dds_::TFMessage_";
    const TYPE_HASH: &'static str =
        "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087";
    const DEFINITION: &'static Definition = &TF_MESSAGE;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The layout rosbag2 writes: dependencies depth first in sorted order, each once.
    #[test]
    fn a_complete_definition_lists_each_dependency_once_depth_first() {
        let rule = "=".repeat(80);
        let expected = format!(
            "geometry_msgs/TransformStamped[] transforms\n\
             \n{rule}\nMSG: geometry_msgs/TransformStamped\n{}\
             \n{rule}\nMSG: geometry_msgs/Transform\n{}\
             \n{rule}\nMSG: geometry_msgs/Quaternion\n{}\
             \n{rule}\nMSG: geometry_msgs/Vector3\n{}\
             \n{rule}\nMSG: std_msgs/Header\n{}\
             \n{rule}\nMSG: builtin_interfaces/Time\n{}",
            TRANSFORM_STAMPED.text,
            TRANSFORM.text,
            QUATERNION.text,
            VECTOR3.text,
            HEADER.text,
            TIME.text
        );
        assert_eq!(TF_MESSAGE.complete(), expected);
    }

    #[test]
    fn every_list_of_uses_is_sorted() {
        for d in [
            &HEADER,
            &POSE,
            &POSE_WITH_COVARIANCE,
            &TWIST,
            &TWIST_WITH_COVARIANCE,
            &TRANSFORM,
            &TRANSFORM_STAMPED,
            &IMU,
            &ODOMETRY,
            &TF_MESSAGE,
        ] {
            let names: Vec<_> = d.uses.iter().map(|u| u.name).collect();
            assert!(names.is_sorted(), "{}: {names:?}", d.name);
        }
    }

    #[test]
    fn times_split_and_stop_at_2038() {
        let t = Time::from_ns(1_795_935_601_500_000_007).unwrap();
        assert_eq!((t.sec, t.nanosec), (1_795_935_601, 500_000_007));
        assert_eq!(Time::from_ns((1 << 31) * 1_000_000_000), None);
    }
}
