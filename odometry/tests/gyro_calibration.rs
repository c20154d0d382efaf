//! Gyro calibration from simulated N-orientation sessions: the fitted correction against the
//! simulator's own gyro model, its reported uncertainty, and the refusals.

mod common;

use calibrate_science::gyrocal::{GyroCalConfig, GyroCalError, MIN_POSES, calibrate_gyro};
use common::{Case, SESSION_HOLD_S, Simulation};
use ipc_types::stream::SampleError;
use ipc_types::{CorrectedImuSample, Stamps, corrected_flags};
use mems_sim::SimSensor;
use mems_sim::model::{G_MPS2, SensorModel};
use mems_sim::scenario::{PoseParams, PoseSession, Scenario};
use mems_sim::vibration::VibrationModel;
use nalgebra::{UnitQuaternion, Vector3};

/// A case at 100 Hz (enough for the session's slow rotations, and quick in debug builds).
fn case() -> Case {
    Case {
        rate_hz: 100.0,
        ..Case::straight()
    }
}

fn cfg() -> GyroCalConfig {
    GyroCalConfig::new(G_MPS2)
}

#[test]
fn an_error_free_accelerometer_and_noise_free_gyro_give_the_exact_correction() {
    // Only the gyro's 1% scale and 0.5% misalignment remain: the fit must invert them exactly.
    let mut c = case();
    c.off = [
        "accel-noise",
        "accel-scale",
        "accel-temp",
        "accel-turn-on",
        "gyro-noise",
        "gyro-turn-on",
        "adc",
    ]
    .map(String::from)
    .to_vec();
    let session = Simulation::new(&c, 3).session();
    let cal = calibrate_gyro(&session, &cfg()).unwrap();
    let err = (cal.correction - c.gyro_correction_reference()).abs().max();
    assert!(err < 1e-7, "correction error {err:e}");
    assert!(cal.accel_bias_mps2.norm() < 1e-6, "{}", cal.accel_bias_mps2);
    assert_eq!(cal.poses, common::SESSION_POSES);
}

#[test]
fn the_realistic_sensor_is_calibrated_within_the_reported_sigma() {
    let c = case();
    for seed in [0, 1] {
        let mut sim = Simulation::new(&c, seed);
        let session = sim.session();
        let cal = calibrate_gyro(&session, &cfg()).unwrap();
        let reference = c.gyro_correction_reference();
        for i in 0..3 {
            for k in 0..3 {
                let err = cal.correction[(i, k)] - reference[(i, k)];
                let sigma = cal.correction_sigma[(i, k)];
                assert!(
                    err.abs() < 4.0 * sigma && sigma < 1e-3,
                    "seed {seed} C[{i}][{k}]: error {err:.2e}, sigma {sigma:.2e}"
                );
            }
        }
        // The scale that sets the heading after a turn is calibrated 20 times better than the
        // gyro's 1% error.
        assert!((cal.correction[(2, 2)] - reference[(2, 2)]).abs() < 5e-4);
        // The accelerometer's bias (a nuisance parameter) is its turn-on bias plus what the
        // temperature drift adds during the session (0.3 mg/degC over at most 0.6 degC).
        let turn_on = Vector3::from(sim.sensor().turn_on_bias().0) * G_MPS2;
        let bias_err = (cal.accel_bias_mps2 - turn_on).abs().max();
        assert!(bias_err < 2.5e-3, "seed {seed}: bias error {bias_err}");
    }
}

/// Samples of a pose session through `attitudes`, with rest flags from its truth, at 100 Hz.
fn session_through(attitudes: Vec<UnitQuaternion<f64>>) -> Vec<CorrectedImuSample> {
    let session = PoseSession::from_poses(attitudes, &PoseParams::new(SESSION_HOLD_S)).unwrap();
    let duration = session.duration_s();
    let mut sim = SimSensor::new(
        session,
        &SensorModel::mpu9250_calibrated(),
        &VibrationModel::moderate(0.0),
        7,
    )
    .unwrap();
    let rate = 100.0;
    (0..(duration * rate) as u64)
        .map(|k| {
            let t = k as f64 / rate;
            let (a, truth) = sim.sample_with_truth(t, rate);
            CorrectedImuSample {
                stamps: Stamps {
                    sample_ns: k * 10_000_000,
                    ..Default::default()
                },
                seq: k,
                accel_mps2: a.accel_g.map(|x| x * G_MPS2),
                gyro_rps: a.gyro_dps.map(f64::to_radians),
                flags: if truth.at_rest {
                    corrected_flags::ZERO_STATE
                } else {
                    0
                },
                ..Default::default()
            }
        })
        .collect()
}

#[test]
fn rotations_about_one_axis_only_are_refused() {
    // Ten poses turned about the sensor's x axis: nothing shows how the gyro responds to
    // rotations about y or z.
    let attitudes = (0..10)
        .map(|k| UnitQuaternion::from_scaled_axis(Vector3::x() * (0.6 * k as f64)))
        .collect();
    let err = calibrate_gyro(&session_through(attitudes), &cfg()).unwrap_err();
    assert!(matches!(err, GyroCalError::IllConditioned { .. }), "{err}");
    assert!(err.to_string().contains("more varied axes"), "{err}");
}

#[test]
fn too_few_poses_and_bad_samples_are_refused() {
    let mut session = Simulation::new(&case(), 0).session();
    // The first five poses only (each pose and rotation takes 9 s).
    let five: Vec<_> = session
        .iter()
        .take_while(|s| s.stamps.sample_ns < 44_000_000_000)
        .copied()
        .collect();
    let err = calibrate_gyro(&five, &cfg()).unwrap_err();
    assert_eq!(
        err,
        GyroCalError::TooFewPoses {
            found: 5,
            min_static_s: 2.0
        }
    );
    assert!(err.to_string().contains(&format!("at least {MIN_POSES}")));

    session[500].gyro_rps[2] = f64::INFINITY;
    let err = calibrate_gyro(&session, &cfg()).unwrap_err();
    assert!(err.to_string().contains("seq 500") && err.to_string().contains("gyro_rps"));

    session[500].gyro_rps[2] = 0.0;
    session[700].stamps.sample_ns = session[699].stamps.sample_ns;
    let err = calibrate_gyro(&session, &cfg()).unwrap_err();
    assert!(
        matches!(
            err,
            GyroCalError::Sample(SampleError::TimeNotIncreasing { seq: 700, .. })
        ),
        "{err}"
    );
}
