//! Rest detection without the gyroscope, as the MPU-9250 runs at 4 kHz (accelerometer only):
//! a simulated 4 kHz drive with ground truth through the calibration stage, the accelerometer's
//! DLPF bypassed as our driver configures it (1.13 kHz at 4 kHz).
//!
//! Yu's 20-sample batch lasts 5 ms there: its std test cannot see the vibration of a moving
//! robot against the per-sample noise (0.14 m/s^2 at 4 kHz), and its magnitude test is blind to
//! horizontal acceleration, so it calls nearly every moving sample rest (this is what made
//! `mems-stack --rate 4000` show "at rest" for a whole drive). The accelerometer-only GLRT over
//! 100 batches (0.5 s, what `mems-stack` runs at 4 kHz) against the learned gravity vector sees
//! most of the motion and still finds the rests.

use calibrate::calibfile::CalibrationFile;
use calibrate::stage::{CalibrationStage, RefineConfig, Settler, StageError};
use calibrate::zero_state::{DetectorConfig, DetectorKind};
use ipc_types::units::{AccelRange, GyroRange};
use ipc_types::{RawImuSample, corrected_flags, raw_flags};
use mems_sim::dlpf::DlpfConfig;
use mems_sim::model::{G_MPS2, SensorModel};
use mems_sim::scenario::{Drive, DriveParams, ns_from_s};
use mems_sim::vibration::VibrationModel;
use mems_sim::{DlpfGrid, SimSensor, adc};
use mems_stage::Stage;

const RATE_HZ: f64 = 4000.0;
const DURATION_S: f64 = 150.0;
/// Moving samples at least this fast (or turning this fast) count as clearly moving.
const CLEAR_SPEED_MPS: f64 = 0.05;
const CLEAR_RATE_DPS: f64 = 1.0;

/// (true-rest samples flagged rest, true-rest samples once the detector is ready,
/// clearly moving samples flagged rest, clearly moving samples) for each detector.
fn run(configs: &[DetectorConfig]) -> Vec<[u64; 4]> {
    let mut params = DriveParams::new(DURATION_S);
    params.turns = true;
    params.in_place_turns = true;
    let seed = 3;
    let drive = Drive::new(&params, seed).unwrap();
    let mut sim = SimSensor::new(
        drive,
        &SensorModel::mpu9250_calibrated(),
        &VibrationModel::moderate(1.0),
        seed,
    )
    .unwrap();
    sim.set_dlpf(Some(DlpfGrid::from_power_on(DlpfConfig::driver(RATE_HZ))));
    let calib = CalibrationFile::identity(G_MPS2);
    let mut stages: Vec<_> = configs
        .iter()
        .map(|c| CalibrationStage::new(&calib, *c, RefineConfig::default()).unwrap())
        .collect();
    let mut counts = vec![[0u64; 4]; configs.len()];
    // Scored on every sample's final verdict.
    let mut settlers = vec![Settler::default(); configs.len()];
    // Truth per sample, (at rest, clearly moving), until its corrected sample is released.
    let mut labels = std::collections::VecDeque::new();
    for k in 0..(DURATION_S * RATE_HZ) as u64 {
        let t = k as f64 / RATE_HZ;
        let (analog, truth) = sim.sample_with_truth(t, RATE_HZ);
        let speed = truth.velocity_mps[0].hypot(truth.velocity_mps[1]);
        let turning = truth.angular_rate_rps[2].abs().to_degrees() >= CLEAR_RATE_DPS;
        labels.push_back((truth.at_rest, speed >= CLEAR_SPEED_MPS || turning));
        let raw = accel_only(adc::quantize_sample(
            &analog,
            AccelRange::G2,
            GyroRange::Dps250,
            ns_from_s(t),
            k,
        ));
        let mut released = 0;
        for ((stage, c), settler) in stages.iter_mut().zip(counts.iter_mut()).zip(&mut settlers) {
            let mut i = 0;
            stage
                .process(&raw, &mut |out| {
                    settler.push(out, &mut |out| {
                        let (rest, clearly_moving) = labels[i];
                        i += 1;
                        let flagged = u64::from(out.flags & corrected_flags::ZERO_STATE != 0);
                        if rest && out.flags & corrected_flags::DETECTOR_READY != 0 {
                            c[0] += flagged;
                            c[1] += 1;
                        } else if clearly_moving {
                            c[2] += flagged;
                            c[3] += 1;
                        }
                    })
                })
                .unwrap();
            released = i;
        }
        labels.drain(..released);
    }
    counts
}

/// The sample as the 4 kHz mode delivers it: no gyroscope.
fn accel_only(mut raw: RawImuSample) -> RawImuSample {
    raw.flags &= !raw_flags::GYRO_VALID;
    raw.gyro_dps = [0.0; 3];
    raw.gyro_counts = [0; 3];
    raw
}

#[test]
fn at_4_khz_without_gyro_yu_calls_motion_rest_and_the_accelerometer_glrt_does_not() {
    let yu = DetectorConfig::new(DetectorKind::Yu, G_MPS2);
    let glrt_accel = DetectorConfig::new(DetectorKind::GlrtAccel, G_MPS2);
    let counts = run(&[yu, glrt_accel]);
    let ratio = |a: u64, b: u64| {
        assert!(b > 10_000, "too few samples in a category: {counts:?}");
        a as f64 / b as f64
    };
    let [yu, glrt] = [counts[0], counts[1]].map(|c| (ratio(c[0], c[1]), ratio(c[2], c[3])));
    eprintln!("(detection, false rest while clearly moving): yu {yu:?}, glrt-accel {glrt:?}");
    // Yu: rests found, but most clearly moving samples called rest too.
    assert!(yu.0 > 0.95, "yu detection {:.3}", yu.0);
    assert!(yu.1 > 0.7, "yu false rest while clearly moving {:.3}", yu.1);
    // The accelerometer GLRT: rests found, at most a third of the clearly moving samples
    // called rest (in-place turns, invisible to an accelerometer at the turn's centre, are
    // most of what is left).
    assert!(glrt.0 > 0.95, "glrt-accel detection {:.3}", glrt.0);
    assert!(
        glrt.1 < 0.33,
        "glrt-accel false rest while clearly moving {:.3}",
        glrt.1
    );
    assert!(glrt.1 < yu.1 / 2.0, "glrt-accel {glrt:?} against yu {yu:?}");
}

#[test]
fn without_gyro_the_glrt_is_refused_and_the_accelerometer_glrt_is_not() {
    let calib = CalibrationFile::identity(G_MPS2);
    let raw = accel_only(RawImuSample {
        accel_g: [0.0, 0.0, 1.0],
        flags: raw_flags::GYRO_VALID,
        ..RawImuSample::default()
    });
    let mut glrt = CalibrationStage::new(
        &calib,
        DetectorConfig::new(DetectorKind::Glrt, G_MPS2),
        RefineConfig::default(),
    )
    .unwrap();
    let err = glrt.process(&raw, &mut |_| {}).unwrap_err();
    assert!(matches!(err, StageError::NoGyro { .. }), "{err:?}");
    assert!(err.to_string().contains("glrt-accel"), "{err}");
    let mut accel = CalibrationStage::new(
        &calib,
        DetectorConfig::new(DetectorKind::GlrtAccel, G_MPS2),
        RefineConfig::default(),
    )
    .unwrap();
    accel.process(&raw, &mut |_| {}).unwrap();
}
