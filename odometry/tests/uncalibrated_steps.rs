//! A hand-held walker's part that the calibration stage flagged `GRAVITY_OFF` and whose
//! filter aligns on whole steps (no rest to align on): the stage's refinement has already
//! removed the error along gravity, so the steps' mean specific force reads gravity right, and
//! only the flag says the part is uncalibrated. The odometry stage (`odometry::stage`, in the
//! walking mode of `odometry::walking`) is fed the same walk with and without the flag: with it
//! the filter aligns with the uncalibrated prior and reports its estimate as an uncalibrated
//! part's, with a bias 1-sigma of at least the scale's share of gravity; without it, a
//! calibrated part's. (A corpus phone, tyrex-iphone5-guillaume-texting with a 4 % scale error
//! and 0.15 g bias added, aligned on steps like this and reported a bias of 0.06 m/s^2 with a
//! 1-sigma of 0.00 for the 1.47 m/s^2 added on every axis.)

use ipc_types::{CorrectedImuSample, Stamps, corrected_flags, raw_flags};
use odometry::config::OdometryConfig;
use odometry::stage::OdometryStage;
use odometry::walking::WalkingConfig;

const G: f64 = 9.80665;
const RATE_HZ: u64 = 100;
/// Steps per second of the walker.
const STEP_HZ: f64 = 1.7;
/// Peak of the hand's vertical bounce at each step, m/s^2 (the Tyrex phones held for texting
/// bounce by 0.7-1.8 m/s^2 peak to peak, `odometry::steps`).
const BOUNCE_MPS2: f64 = 1.0;

/// 20 s of walking with the phone held level (sensor z up), never at rest, from a detector
/// that is ready; `flags` added to every sample.
fn walk(flags: u16) -> Vec<CorrectedImuSample> {
    (0..20 * RATE_HZ)
        .map(|k| {
            let t = k as f64 / RATE_HZ as f64;
            let phase = 2.0 * std::f64::consts::PI * STEP_HZ * t;
            CorrectedImuSample {
                stamps: Stamps {
                    sample_ns: 1_000_000_000 + k * 1_000_000_000 / RATE_HZ,
                    ..Stamps::default()
                },
                seq: k,
                accel_mps2: [0.3 * phase.cos(), 0.0, G + BOUNCE_MPS2 * phase.sin()],
                flags: corrected_flags::DETECTOR_READY | flags,
                raw_flags: raw_flags::GYRO_VALID,
                ..CorrectedImuSample::default()
            }
        })
        .collect()
}

/// The odometry stage in the walking mode after `samples`.
fn navigate(samples: &[CorrectedImuSample]) -> OdometryStage {
    let mut cfg = OdometryConfig::mpu9250(G);
    cfg.walking = Some(WalkingConfig::default());
    let mut stage = OdometryStage::new(cfg);
    for s in samples {
        stage.process(s, &mut |_| {}).unwrap();
    }
    stage
}

#[test]
fn a_part_flagged_gravity_off_that_aligns_on_steps_is_run_as_uncalibrated() {
    let cfg = OdometryConfig::mpu9250(G);
    let flagged = navigate(&walk(corrected_flags::GRAVITY_OFF));
    let stats = flagged.walking_stats().expect("the walking mode");
    assert!(stats.aligned_on_steps, "{stats:?}");
    let e = flagged.accel_estimate().expect("aligned");
    assert!(e.gravity_error.abs() < cfg.uncalibrated.trigger, "{e:?}");
    assert!(e.uncalibrated && e.flagged, "{e:?}");
    // Along gravity the scale's 3 % of g at least; across it the offset's prior.
    let along = cfg.uncalibrated.scale_sigma * G;
    assert!(e.bias_sigma_mps2.iter().all(|&s| s >= along), "{e:?}");

    let calibrated = navigate(&walk(0));
    assert!(calibrated.walking_stats().unwrap().aligned_on_steps);
    let e = calibrated.accel_estimate().expect("aligned");
    assert!(!e.uncalibrated && !e.flagged, "{e:?}");
    assert!(e.bias_sigma_mps2.iter().all(|&s| s < 0.1 * along), "{e:?}");
}
