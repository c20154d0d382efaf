//! Codecs and schemas of the stream's own messages: raw samples, the simulator's truth,
//! corrected samples, odometry states and robot hints.

use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample, RobotHint};
use serde_json::{Value, json};

use super::Topic;
use super::schema::{int16, number, object, stamps_schema, uint, vector};
use crate::Truth;
use crate::mcap::{proto, quantum};

/// Topic of the simulator's ground truth.
pub const TRUTH_TOPIC: &str = "mems/sim/truth";

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
        proto::fill_f32(
            &mut p.refined_accel_mps2,
            &self.refined_accel_mps2,
            quantum::ACCEL_MPS2,
        );
        proto::fill_f32(
            &mut p.refined_gyro_rps,
            &self.refined_gyro_rps,
            quantum::GYRO_RPS,
        );
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
            refined_accel_mps2: refined("refined_accel_mps2", &p.refined_accel_mps2)?,
            refined_gyro_rps: refined("refined_gyro_rps", &p.refined_gyro_rps)?,
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
            refined_accel_mps2: self
                .refined_accel_mps2
                .map(|x| quantum::recorded(x, ACCEL_MPS2)),
            refined_gyro_rps: self
                .refined_gyro_rps
                .map(|x| quantum::recorded(x, GYRO_RPS)),
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
                (
                    "refined_accel_mps2",
                    vector(
                        3,
                        number("Accelerometer offset the bias refinement subtracts, m/s^2."),
                    ),
                ),
                (
                    "refined_gyro_rps",
                    vector(
                        3,
                        number("Gyroscope bias the bias refinement subtracts, rad/s."),
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
            .chain(&self.zs_std_mps2)
            .chain(&self.refined_accel_mps2)
            .chain(&self.refined_gyro_rps);
        values.all(|v| v.is_finite())
    }
}

/// A refinement offset as recorded: absent (a recording made before the field existed) is
/// zero, as the sample's default.
fn refined(field: &str, v: &[f32]) -> std::result::Result<[f64; 3], String> {
    match v {
        [] => Ok([0.0; 3]),
        _ => proto::array_f32(field, v, &[]),
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

/// The scaled values a raw sample writes: none when they derive from the counts with
/// `sensitivity` (non-zero).
fn written(sensitivity: f64, values: &[f64; 3]) -> &[f64] {
    if sensitivity == 0.0 { values } else { &[] }
}
