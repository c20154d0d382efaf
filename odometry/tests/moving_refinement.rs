//! The calibration stage's gyroscope refinement while speed hints say the robot drives
//! (`eskf::refinement`). A robot aligns on a 2 s rest, then drives at 1 m/s while its detector,
//! fooled, flags every sample rest, and the stage refines the rate it sees into its gyroscope
//! bias (a running mean with a 5 s time constant, as `calibrate::stage`'s refinement at rest):
//! - on a circle at 20 deg/s the refinement is the turn, and the corrected stream loses it; the
//!   odometry follows it back out (the rate before it is beyond a gyro's turn-on bias), and the
//!   heading turns with the robot (without that it lags by the refinement's integral, over 600
//!   degrees in 40 s);
//! - on a straight drive whose gyro bias steps by 0.3 deg/s, the refinement is that step, a
//!   bias measurement the odometry keeps, and the heading turns only by what the stream
//!   carried while the refinement settled (the step times its time constant, 1.5 degrees;
//!   followed out it would turn by the step times the drive, 12 degrees).

use ipc_types::{
    CorrectedImuSample, OdometryState, RobotHint, Stamps, corrected_flags, hint_flags,
};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use odometry::config::OdometryConfig;
use odometry::hints::HintConfig;
use odometry::stage::OdometryStage;

const G: f64 = 9.80665;
const RATE: f64 = 100.0;
const REST_S: f64 = 2.0;
const END_S: f64 = 42.0;
const SPEED_MPS: f64 = 1.0;
/// Time constant of the stage's refinement, s.
const TAU_S: f64 = 5.0;

/// The final heading (rad, about up) of a run whose robot turns at `yaw_rate` (rad/s) while
/// driving and whose raw gyro reads `bias_step` (rad/s about z) more from the drive's start;
/// the stage's refinement follows the raw rate's drive-time excess with [`TAU_S`].
fn final_yaw(yaw_rate: f64, bias_step: f64) -> f64 {
    let hints = HintConfig {
        mounting: Some(UnitQuaternion::identity()),
        imu_mounting: Some(UnitQuaternion::identity()),
        ..HintConfig::default()
    };
    let mut stage = OdometryStage::with_hints(OdometryConfig::mpu9250(G), hints).unwrap();
    let mut last = None;
    let mut keep = |s: &OdometryState| last = Some(*s);
    for k in 0..(END_S * RATE) as u64 {
        let t = k as f64 / RATE;
        let t_ns = ((1.0 + t) * 1e9).round() as u64;
        let driving = t >= REST_S;
        if k % 5 == 0 {
            let flags = hint_flags::SOURCE_ENCODERS
                | hint_flags::SPEED_VALID
                | if driving { 0 } else { hint_flags::STATIONARY };
            let h = RobotHint {
                stamps: Stamps {
                    sample_ns: t_ns,
                    acquired_ns: t_ns,
                    ..Default::default()
                },
                seq: k / 5,
                forward_speed_mps: if driving { SPEED_MPS } else { 0.0 },
                forward_speed_sigma_mps: 0.02,
                flags,
                ..Default::default()
            };
            stage.hint(&h, &mut keep).unwrap();
        }
        let (w, excess) = if driving {
            let settle = 1.0 - (-(t - REST_S) / TAU_S).exp();
            (yaw_rate, (yaw_rate + bias_step) * settle)
        } else {
            (0.0, 0.0)
        };
        let raw = Vector3::new(0.0, 0.0, w + if driving { bias_step } else { 0.0 });
        let centripetal = if driving { SPEED_MPS * yaw_rate } else { 0.0 };
        let sample = CorrectedImuSample {
            stamps: Stamps {
                sample_ns: t_ns,
                acquired_ns: t_ns,
                ..Default::default()
            },
            seq: k,
            accel_mps2: [0.0, centripetal, G],
            gyro_rps: [0.0, 0.0, raw.z - excess],
            zs_std_mps2: [0.002; 3],
            flags: corrected_flags::DETECTOR_READY | corrected_flags::ZERO_STATE,
            refined_gyro_rps: [0.0, 0.0, excess],
            ..Default::default()
        };
        stage.process(&sample, &mut keep).unwrap();
        stage.postprocess(&mut keep);
    }
    assert!(stage.aligned());
    let [w, x, y, z] = last.expect("states emitted").attitude_wxyz;
    UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z))
        .euler_angles()
        .2
}

#[test]
fn a_turn_the_stage_refined_while_the_robot_drove_still_turns_the_heading() {
    let yaw_rate = 20f64.to_radians();
    let expected = yaw_rate * (END_S - REST_S);
    let off = (final_yaw(yaw_rate, 0.0) - expected).rem_euclid(std::f64::consts::TAU);
    let off = off.min(std::f64::consts::TAU - off).to_degrees();
    assert!(off < 1.0, "heading {off} deg off the turn");
}

#[test]
fn a_bias_step_the_stage_refined_on_a_straight_drive_is_kept() {
    let step = 0.3f64.to_radians();
    let yaw = final_yaw(0.0, step).to_degrees();
    // Kept: the stream carries the step until the refinement settles, its integral the step
    // times TAU_S (1.5 deg). Followed out: the step for the whole drive (12 deg).
    assert!(yaw.abs() < 2.0, "heading {yaw} deg off a straight drive");
}
