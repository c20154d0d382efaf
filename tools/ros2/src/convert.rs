//! Our payloads as ROS 2 messages: frames, units and covariances (docs/recording.md, "ROS 2").
//!
//! Frames (REP 105): `odom` is our navigation frame (z up, origin and heading fixed at
//! alignment); `base_link` is the IMU's sensor frame, because a state's attitude is the
//! sensor's and the recording does not carry the IMU's mounting on the robot (the body and the
//! sensor are taken as one: the mounting is the identity); `imu_link`, the frame of the IMU's
//! samples, is the sensor frame too, so `base_link` -> `imu_link` is the identity. Units are
//! ROS's and ours alike (m, m/s, m/s^2, rad/s); acceleration is specific force in both (+g
//! upward at rest, REP 145).
//!
//! Covariances come from our 1-sigma (variance = sigma^2); an entry we have no estimate of is
//! [`UNKNOWN_VARIANCE`] on the diagonal (Odometry), or as `sensor_msgs/Imu` asks: an orientation
//! covariance whose element 0 is -1 (no orientation), all zeros for a covariance unknown.

use ipc_types::{CorrectedImuSample, OdometryState, odometry_flags};
use nalgebra::{Matrix3, Quaternion as NQuaternion, UnitQuaternion, Vector3 as NVector3};

use crate::msg::{
    Covariance6, Header, Imu, Odometry, Pose, PoseWithCovariance, Quaternion, TfMessage, Time,
    Transform, TransformStamped, Twist, TwistWithCovariance, Vector3,
};

/// The frame of the IMU's samples (`/imu/data`).
pub const IMU_FRAME: &str = "imu_link";
/// The odometry's fixed frame: our navigation frame.
pub const ODOM_FRAME: &str = "odom";
/// The robot's frame: the IMU's sensor frame (mounting unknown, taken as the identity).
pub const BASE_FRAME: &str = "base_link";
/// The variance of an Odometry entry we have no estimate of (m^2, rad^2, (m/s)^2, (rad/s)^2):
/// large enough that no filter trusts it, finite so that every consumer can invert the matrix.
pub const UNKNOWN_VARIANCE: f64 = 1e6;

/// A corrected sample as `sensor_msgs/Imu` in [`IMU_FRAME`] at `stamp`: no orientation
/// (covariance element 0 is -1), the angular velocity and the linear acceleration with their
/// covariances unknown (zeros: a corrected sample carries no 1-sigma of its own).
pub fn imu(sample: &CorrectedImuSample, stamp: Time) -> Imu {
    let mut orientation_covariance = [0.0; 9];
    orientation_covariance[0] = -1.0;
    Imu {
        header: header(stamp, IMU_FRAME),
        orientation: Quaternion::IDENTITY,
        orientation_covariance,
        angular_velocity: sample.gyro_rps.into(),
        angular_velocity_covariance: [0.0; 9],
        linear_acceleration: sample.accel_mps2.into(),
        linear_acceleration_covariance: [0.0; 9],
    }
}

/// A state as `nav_msgs/Odometry` at `stamp`: the pose of [`BASE_FRAME`] in [`ODOM_FRAME`] and
/// its velocity in [`BASE_FRAME`], as REP 105 and the message define them.
///
/// Covariances, row-major over (x, y, z, rotation about x, y, z): position variances
/// `position_sigma_m^2` on the diagonal; the attitude's unknown ([`UNKNOWN_VARIANCE`]). Twist:
/// the velocity's covariance `R^T diag(velocity_sigma_mps^2) R` rotated into the body frame
/// (R the attitude), the angular rate unknown (zero, with [`UNKNOWN_VARIANCE`]). Before
/// alignment (and without a gyroscope) the state estimates nothing: every variance is unknown.
pub fn odometry(state: &OdometryState, stamp: Time) -> Odometry {
    let aligned = state.flags & odometry_flags::ALIGNED != 0;
    let velocity_nav = NVector3::from(state.velocity_mps);
    let rotation = attitude(state);
    let mut pose_covariance = unknown_diagonal();
    let mut twist_covariance = unknown_diagonal();
    if aligned {
        let position = Matrix3::from_diagonal(&NVector3::from(state.position_sigma_m).map(sq));
        set_block(&mut pose_covariance, &position);
        let velocity = Matrix3::from_diagonal(&NVector3::from(state.velocity_sigma_mps).map(sq));
        let r = rotation.to_rotation_matrix().into_inner();
        set_block(&mut twist_covariance, &(r.transpose() * velocity * r));
    }
    let velocity_body = rotation.inverse_transform_vector(&velocity_nav);
    Odometry {
        header: header(stamp, ODOM_FRAME),
        child_frame_id: BASE_FRAME.into(),
        pose: PoseWithCovariance {
            pose: Pose {
                position: state.position_m.into(),
                orientation: Quaternion::from_wxyz(state.attitude_wxyz),
            },
            covariance: pose_covariance,
        },
        twist: TwistWithCovariance {
            twist: Twist {
                linear: <[f64; 3]>::from(velocity_body).into(),
                angular: Vector3::default(),
            },
            covariance: twist_covariance,
        },
    }
}

/// The transforms of a state at `stamp`: [`ODOM_FRAME`] -> [`BASE_FRAME`] (its pose) once
/// aligned, and always [`BASE_FRAME`] -> [`IMU_FRAME`] (the identity), so that the samples'
/// frame is in the tree.
pub fn transforms(state: &OdometryState, stamp: Time) -> TfMessage {
    let mut transforms = Vec::with_capacity(2);
    if state.flags & odometry_flags::ALIGNED != 0 {
        transforms.push(TransformStamped {
            header: header(stamp, ODOM_FRAME),
            child_frame_id: BASE_FRAME.into(),
            transform: Transform {
                translation: state.position_m.into(),
                rotation: Quaternion::from_wxyz(state.attitude_wxyz),
            },
        });
    }
    transforms.push(TransformStamped {
        header: header(stamp, BASE_FRAME),
        child_frame_id: IMU_FRAME.into(),
        transform: Transform {
            translation: Vector3::default(),
            rotation: Quaternion::IDENTITY,
        },
    });
    TfMessage { transforms }
}

fn header(stamp: Time, frame: &str) -> Header {
    Header {
        stamp,
        frame_id: frame.into(),
    }
}

/// The state's attitude (sensor to navigation frame), normalised: a recording keeps each
/// component to 2^-20, so the recorded quaternion is unit only to about 1e-6.
fn attitude(state: &OdometryState) -> UnitQuaternion<f64> {
    let [w, x, y, z] = state.attitude_wxyz;
    UnitQuaternion::from_quaternion(NQuaternion::new(w, x, y, z))
}

fn sq(sigma: f64) -> f64 {
    sigma * sigma
}

/// A 6x6 covariance with [`UNKNOWN_VARIANCE`] on the diagonal, zeros elsewhere.
fn unknown_diagonal() -> Covariance6 {
    let mut c = [0.0; 36];
    for i in 0..6 {
        c[i * 7] = UNKNOWN_VARIANCE;
    }
    Covariance6(c)
}

/// Puts `block` in the upper-left 3x3 of `c` (the translational part).
fn set_block(c: &mut Covariance6, block: &Matrix3<f64>) {
    for row in 0..3 {
        for col in 0..3 {
            c.0[row * 6 + col] = block[(row, col)];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn aligned_state() -> OdometryState {
        // 90 degrees about z: sensor x points along navigation y.
        let h = std::f64::consts::FRAC_1_SQRT_2;
        OdometryState {
            position_m: [1.0, 2.0, 3.0],
            position_sigma_m: [0.1, 0.2, 0.3],
            velocity_mps: [0.0, 2.0, 0.0],
            velocity_sigma_mps: [0.01, 0.04, 0.0],
            attitude_wxyz: [h, 0.0, 0.0, h],
            flags: odometry_flags::ALIGNED,
            ..OdometryState::default()
        }
    }

    #[test]
    fn the_twist_is_in_the_body_frame_with_its_covariance_rotated() {
        let o = odometry(&aligned_state(), Time::default());
        let v = o.twist.twist.linear;
        // Moving along navigation y is moving along sensor x.
        assert!((v.x - 2.0).abs() < 1e-12 && v.y.abs() < 1e-12 && v.z.abs() < 1e-12);
        let c = o.twist.covariance.0;
        // Navigation y's variance is body x's, navigation x's is body y's.
        assert!((c[0] - 0.04 * 0.04).abs() < 1e-15, "{}", c[0]);
        assert!((c[7] - 0.01 * 0.01).abs() < 1e-15, "{}", c[7]);
        assert!(c[1].abs() < 1e-15 && c[14].abs() < 1e-15);
        assert_eq!([c[21], c[28], c[35]], [UNKNOWN_VARIANCE; 3]);
    }

    #[test]
    fn the_pose_carries_the_position_variances_and_an_unknown_attitude() {
        let o = odometry(&aligned_state(), Time::default());
        let c = o.pose.covariance.0;
        assert_eq!([c[0], c[7], c[14]], [0.1 * 0.1, 0.2 * 0.2, 0.3 * 0.3]);
        assert_eq!([c[21], c[28], c[35]], [UNKNOWN_VARIANCE; 3]);
        assert_eq!(c.iter().filter(|&&v| v != 0.0).count(), 6);
        let q = o.pose.pose.orientation;
        assert_eq!([q.w, q.x, q.y, q.z], aligned_state().attitude_wxyz);
    }

    #[test]
    fn an_unaligned_state_estimates_nothing_and_has_no_odom_transform() {
        let state = OdometryState {
            flags: 0,
            ..aligned_state()
        };
        let o = odometry(&state, Time::default());
        for c in [o.pose.covariance.0, o.twist.covariance.0] {
            assert_eq!(c, unknown_diagonal().0);
        }
        let tf = transforms(&state, Time::default());
        assert_eq!(tf.transforms.len(), 1);
        assert_eq!(tf.transforms[0].child_frame_id, IMU_FRAME);
        assert_eq!(
            transforms(&aligned_state(), Time::default())
                .transforms
                .len(),
            2
        );
    }

    #[test]
    fn an_imu_sample_has_no_orientation() {
        let sample = CorrectedImuSample {
            accel_mps2: [0.1, 0.2, 9.8],
            gyro_rps: [0.01, -0.02, 0.03],
            ..CorrectedImuSample::default()
        };
        let m = imu(&sample, Time::default());
        assert_eq!(m.orientation_covariance[0], -1.0);
        assert_eq!(m.linear_acceleration, Vector3::from([0.1, 0.2, 9.8]));
        assert_eq!(m.angular_velocity, Vector3::from([0.01, -0.02, 0.03]));
        assert_eq!(m.header.frame_id, IMU_FRAME);
    }
}
