//! The calibration stage's gyroscope refinement on a rest the odometry refuses as vibration
//! (`eskf::refinement`): a car idles after its start rest, its engine shaking the detector's
//! window to 0.3 m/s^2 per axis while the detector still flags rest, and the stage's refinement
//! takes 2e-4 rad/s about z (0.011 deg/s, the size measured on the corpus's car drives) into
//! its gyroscope bias, so that the still car's stream reads -2e-4 rad/s from then on. The
//! odometry refuses those rests (`REST_VIBRATING`) and so makes no zero-rate update there; it
//! follows the stage's step, and the heading stays. Without following it the heading turns by
//! the step times the idle (0.011 rad in 55 s).

use ipc_types::{CorrectedImuSample, OdometryState, Stamps, corrected_flags, odometry_flags};
use nalgebra::{Quaternion, UnitQuaternion};
use odometry::config::OdometryConfig;
use odometry::stage::OdometryStage;

const G: f64 = 9.80665;
const RATE: f64 = 100.0;
const START_REST_S: f64 = 2.0;
/// When the stage's refinement steps, and how long the run lasts, s.
const STEP_AT_S: f64 = 5.0;
const END_S: f64 = 60.0;
/// The stage's refinement step about z, rad/s.
const STEP_RPS: f64 = 2e-4;

/// The last state of the run, and how many states were flagged `REST_VIBRATING`.
fn run() -> (OdometryState, usize) {
    let mut cfg = OdometryConfig::mpu9250(G);
    cfg.rest_vibration_factor = 3.0;
    let mut stage = OdometryStage::new(cfg);
    let (mut last, mut vibrating) = (None, 0);
    let mut keep = |s: &OdometryState| {
        vibrating += usize::from(s.flags & odometry_flags::REST_VIBRATING != 0);
        last = Some(*s);
    };
    for k in 0..(END_S * RATE) as u64 {
        let t = k as f64 / RATE;
        let idling = t >= START_REST_S;
        let refined = if t >= STEP_AT_S { STEP_RPS } else { 0.0 };
        let sample = CorrectedImuSample {
            stamps: Stamps {
                sample_ns: (t * 1e9).round() as u64,
                ..Default::default()
            },
            seq: k,
            accel_mps2: [0.0, 0.0, G],
            gyro_rps: [0.0, 0.0, -refined],
            zs_std_mps2: [if idling { 0.3 } else { 0.002 }; 3],
            flags: corrected_flags::DETECTOR_READY | corrected_flags::ZERO_STATE,
            refined_gyro_rps: [0.0, 0.0, refined],
            ..Default::default()
        };
        stage.process(&sample, &mut keep).unwrap();
        stage.postprocess(&mut keep);
    }
    assert!(stage.aligned());
    (last.expect("states emitted"), vibrating)
}

#[test]
fn a_gyro_refinement_on_a_vibrating_rest_does_not_turn_the_heading() {
    let (state, vibrating) = run();
    assert!(
        vibrating > 5000,
        "{vibrating} states flagged REST_VIBRATING"
    );
    let [w, x, y, z] = state.attitude_wxyz;
    let yaw = UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z))
        .euler_angles()
        .2;
    // Unfollowed: -STEP_RPS * (END_S - STEP_AT_S) = -0.011 rad.
    let unfollowed = STEP_RPS * (END_S - STEP_AT_S);
    assert!(yaw.abs() < 0.01 * unfollowed, "yaw {yaw} rad");
}
