//! Robot hints in the odometry stage, on simulated drives (`mems_sim::hints` derives the hints
//! from the drive's truth): stationary hints give the zero-velocity updates an IMU detector
//! misses, speed hints bound the drift of a long cruise, stale hints fall back to the IMU with
//! a state for every sample, disagreements are counted, the mounting is estimated, and the
//! output does not depend on how hints and samples interleave.
//!
//! The drives run at 100 Hz to be quick, with white samples (`dlpf: None`): the tolerances
//! are those of the hint logic on the noise the stage is configured for. With the part's DLPF
//! at 100 Hz the samples lag the hints by the filter's delay (the harness does not take it
//! off the sample times as the driver does) and the filter folds 1.2x (41 Hz, our driver's
//! setting at 100 Hz) to 2x (184 Hz) the datasheet noise density in; the DLPF's effect on drives is measured
//! by `drive_eval` (docs/odometry.md).

mod common;

use calibrate_science::gyrocal::{GyroCalConfig, calibrate_gyro};
use common::{Case, Simulation, run_with_hints};
use ipc_types::{CorrectedImuSample, OdometryState, RobotHint, corrected_flags, odometry_flags};
use mems_sim::hints::{HintParams, RestSource};
use mems_sim::model::G_MPS2;
use nalgebra::{UnitQuaternion, Vector2};
use odometry::config::OdometryConfig;
use odometry::hints::HintConfig;
use odometry::stage::OdometryStage;
use recording::Truth;

/// A drive's samples (perfect rest flags) and truth, and the configuration with the gyro
/// calibrated from the same power-on's pose session.
fn simulate(c: &Case, seed: u64) -> (Vec<CorrectedImuSample>, Vec<Truth>, OdometryConfig) {
    let mut sim = Simulation::new(c, seed);
    let session = sim.session();
    let cal = calibrate_gyro(&session, &GyroCalConfig::new(G_MPS2))
        .expect("the session calibrates the gyro");
    let mut cfg =
        OdometryConfig::mpu9250(G_MPS2).with_gyro_calibration(cal.correction, cal.correction_sigma);
    let (accel, gyro) = c.vibration_density_per_mps();
    cfg.noise.vibration_accel_density_per_mps = accel;
    cfg.noise.vibration_gyro_density_per_mps = gyro;
    let (mut samples, mut truth) = (Vec::new(), Vec::new());
    sim.drive(|s, t| {
        samples.push(*s);
        truth.push(*t);
    });
    (samples, truth, cfg)
}

/// Horizontal end error against the truth, m. The navigation frame's heading is fixed at
/// alignment (the sensor's), the truth's is the scenario's: the truth is turned by the yaw
/// between the two attitudes at the first aligned state (as `mems-odometry offline` does).
fn end_error(states: &[OdometryState], truth: &[Truth]) -> f64 {
    let quat = |q: [f64; 4]| {
        UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]))
    };
    let i = states
        .iter()
        .position(|o| o.flags & odometry_flags::ALIGNED != 0)
        .expect("aligned");
    let m = (quat(states[i].attitude_wxyz) * quat(truth[i].attitude_wxyz).inverse())
        .to_rotation_matrix();
    let yaw = m[(1, 0)].atan2(m[(0, 0)]);
    let to_ours = nalgebra::Rotation2::new(yaw);
    let xy = |p: [f64; 3]| Vector2::new(p[0], p[1]);
    let (o, t) = (states.last().unwrap(), truth.last().unwrap());
    (xy(o.position_m) - to_ours * (xy(t.position_m) - xy(truth[i].position_m))).norm()
}

fn distance(truth: &[Truth]) -> f64 {
    truth
        .windows(2)
        .map(|w| {
            (w[1].position_m[0] - w[0].position_m[0]).hypot(w[1].position_m[1] - w[0].position_m[1])
        })
        .sum()
}

fn no_losses(source: RestSource) -> HintParams {
    let mut p = HintParams::new(source);
    p.drop_fraction = 0.0;
    p.bursts_per_min = 0.0;
    p
}

/// Only the rest part of each hint (no speed, no yaw rate).
fn rest_only(hints: &[RobotHint]) -> Vec<RobotHint> {
    hints
        .iter()
        .map(|h| RobotHint {
            flags: h.flags
                & (ipc_types::hint_flags::STATIONARY
                    | ipc_types::hint_flags::SOURCE_COMMANDED
                    | ipc_types::hint_flags::SOURCE_ENCODERS),
            ..*h
        })
        .collect()
}

/// A detector that never sees rest after the first 10 s (the drive's initial rest, used for
/// alignment): without zero-velocity updates the velocity drifts for ever. Stationary hints
/// alone (no speed) bring the updates back, and every sample where they say "stationary"
/// against the detector's "moving" is a counted disagreement.
#[test]
fn stationary_hints_give_the_zero_velocity_updates_a_blind_detector_misses() {
    let c = Case {
        duration_s: 150.0,
        rate_hz: 100.0,
        dlpf: None,
        turns: true,
        ..Case::straight()
    };
    let (mut samples, truth, cfg) = simulate(&c, 11);
    for s in samples.iter_mut() {
        if s.stamps.sample_ns >= 10_000_000_000 {
            s.flags &= !corrected_flags::ZERO_STATE;
        }
    }
    let hints = rest_only(&c.hints(11, &no_losses(RestSource::Encoders)).hints);
    let imu_only = run_with_hints(cfg, HintConfig::default(), &samples, &[]);
    let with_hints = run_with_hints(cfg, HintConfig::default(), &samples, &hints);
    let d = distance(&truth);
    let (e_imu, e_hints) = (
        end_error(&imu_only.states, &truth),
        end_error(&with_hints.states, &truth),
    );
    assert!(e_imu > 0.2 * d, "IMU only: {e_imu} m of {d} m");
    assert!(e_hints < 0.02 * d, "with hints: {e_hints} m of {d} m");

    // Counting, checked against the flags: a disagreement is a sample flagged stationary by the
    // hint while the detector (ready) said motion, or the reverse.
    let mut expected = 0u32;
    for (s, o) in samples.iter().zip(&with_hints.states) {
        let hint_rest = o.flags & odometry_flags::HINT_STATIONARY != 0;
        let imu_rest = s.flags & corrected_flags::ZERO_STATE != 0;
        let disagree = o.flags & odometry_flags::HINT_DISAGREE != 0;
        if o.flags & odometry_flags::ALIGNED != 0 {
            // Hints are fresh throughout (no losses), so they decide rest.
            assert_eq!(o.flags & odometry_flags::ZERO_VELOCITY != 0, hint_rest);
            assert_eq!(disagree, hint_rest != imu_rest, "seq {}", s.seq);
            expected += u32::from(disagree);
        }
        assert_eq!(o.hint_disagreements, expected, "seq {}", s.seq);
    }
    // Every rest after the first 10 s is a disagreement: tens of seconds of samples.
    assert!(expected > 2000, "{expected}");
    assert_eq!(imu_only.states.last().unwrap().hint_disagreements, 0);
}

/// Long cruises with an accelerometer bias of 20 mg the configuration does not expect: the
/// velocity drift of a 30 s cruise costs the IMU alone (with perfect rest flags) several
/// percent, and speed hints (forward speed with its scale error, and the non-holonomic
/// constraint) hold the error far below it.
#[test]
fn speed_hints_bound_the_drift_of_long_cruises() {
    let c = Case {
        duration_s: 150.0,
        rate_hz: 100.0,
        dlpf: None,
        turns: true,
        leg_s: [25.0, 30.0],
        max_legs: 1,
        max_motion_s: 60.0,
        accel_turn_on_mg: Some(20.0),
        ..Case::straight()
    };
    let (samples, truth, cfg) = simulate(&c, 4);
    let hints = c.hints(4, &no_losses(RestSource::Encoders));
    let imu_only = run_with_hints(cfg, HintConfig::default(), &samples, &[]);
    let with_hints = run_with_hints(cfg, HintConfig::default(), &samples, &hints.hints);
    let d = distance(&truth);
    let (e_imu, e_hints) = (
        end_error(&imu_only.states, &truth),
        end_error(&with_hints.states, &truth),
    );
    eprintln!("IMU only {e_imu} m, with hints {e_hints} m, of {d} m");
    assert!(e_imu > 0.02 * d, "IMU only: {e_imu} m of {d} m");
    assert!(e_hints < 0.005 * d, "with hints: {e_hints} m of {d} m");
    assert!(e_hints < e_imu / 5.0);
    let stats = with_hints.session.stage().hint_stats();
    // 50 Hz while moving.
    assert!(stats.speed_updates > 1000, "{stats:?}");
    let speed_flagged = with_hints
        .states
        .iter()
        .filter(|o| o.flags & odometry_flags::HINT_SPEED != 0)
        .count() as u64;
    // Every flagged sample had at least one update; two hints can become usable at one
    // sample (their latencies differ), a third hardly.
    assert!(
        speed_flagged <= stats.speed_updates && 2 * speed_flagged >= stats.speed_updates,
        "{speed_flagged} flagged, {stats:?}"
    );
    // The scale state learned the encoder's scale error.
    let k = with_hints.session.stage().filter().unwrap().x.k;
    assert!(
        (k - hints.speed_scale).abs() < 0.005,
        "{k} vs {}",
        hints.speed_scale
    );
}

/// Hints stop for 20 s and resume: every sample still gives one state, `HINT_STALE` is set
/// exactly while the newest delivered hint is older than the maximum age (computed here from
/// the hints' own times), and the stage uses the IMU's rest flags meanwhile.
#[test]
fn stale_hints_fall_back_to_the_imu_without_a_gap() {
    let c = Case {
        duration_s: 90.0,
        rate_hz: 100.0,
        dlpf: None,
        turns: true,
        ..Case::straight()
    };
    let (samples, truth, cfg) = simulate(&c, 6);
    let all = c.hints(6, &no_losses(RestSource::Commanded)).hints;
    let (gap_from, gap_to) = (30_000_000_000u64, 50_000_000_000u64);
    let hints: Vec<RobotHint> = all
        .into_iter()
        .filter(|h| !(gap_from..gap_to).contains(&h.stamps.acquired_ns))
        .collect();
    let hint_cfg = HintConfig::default();
    let r = run_with_hints(cfg, hint_cfg, &samples, &hints);
    assert_eq!(r.states.len(), samples.len());
    let delivery = (hint_cfg.delivery_s * 1e9) as u64;
    let max_age = (hint_cfg.max_age_s * 1e9) as u64;
    let (mut stale, mut first_stale, mut last_stale) = (0, None, None);
    for (s, o) in samples.iter().zip(&r.states) {
        assert_eq!(o.seq, s.seq);
        let t = s.stamps.sample_ns;
        let newest = hints
            .iter()
            .filter(|h| h.stamps.acquired_ns + delivery <= t)
            .map(|h| h.stamps.sample_ns)
            .max();
        let expect_stale = newest.is_some_and(|n| t - n > max_age);
        assert_eq!(
            o.flags & odometry_flags::HINT_STALE != 0,
            expect_stale,
            "t {t}"
        );
        if expect_stale {
            stale += 1;
            first_stale.get_or_insert(t);
            last_stale = Some(t);
            // Without a fresh hint, no hint flag but the stale one.
            assert_eq!(
                o.flags
                    & (odometry_flags::HINT_STATIONARY
                        | odometry_flags::HINT_SPEED
                        | odometry_flags::HINT_DISAGREE),
                0
            );
        }
    }
    // Stale from about max age after the last hint before the gap to the first after it.
    assert!(stale > 1900 && stale < 2000, "{stale} stale samples");
    assert!(first_stale.unwrap() > gap_from && last_stale.unwrap() < gap_to + 50_000_000);
    // The fallback used the IMU's (here perfect) rest flags: rests in the gap got updates.
    let gap_rests = samples
        .iter()
        .zip(&r.states)
        .filter(|(s, o)| {
            o.flags & odometry_flags::HINT_STALE != 0
                && s.flags & corrected_flags::ZERO_STATE != 0
                && o.flags & odometry_flags::ZERO_VELOCITY != 0
        })
        .count();
    assert!(gap_rests > 0);
    assert!(end_error(&r.states, &truth) < 0.02 * distance(&truth));
}

/// The IMU mounted with a yaw of 35 degrees and a small tilt on the robot: estimated from the
/// first drive (the revised sensor-frame displacement of forward driving, and gravity), it
/// is recovered to a fraction of a degree, and speed hints are used once it is known.
#[test]
fn the_mounting_is_estimated_from_the_first_drive() {
    let mounting = UnitQuaternion::from_euler_angles(
        3f64.to_radians(),
        -2f64.to_radians(),
        35f64.to_radians(),
    );
    let c = Case {
        duration_s: 90.0,
        rate_hz: 100.0,
        dlpf: None,
        turns: true,
        mounting,
        ..Case::straight()
    };
    let (samples, truth, cfg) = simulate(&c, 8);
    let hints = c.hints(8, &no_losses(RestSource::Encoders)).hints;
    let estimate = HintConfig {
        mounting: None,
        ..HintConfig::default()
    };
    let r = run_with_hints(cfg, estimate, &samples, &hints);
    let got = r.session.stage().mounting().expect("estimated");
    let error_deg = got.angle_to(&mounting).to_degrees();
    assert!(error_deg < 0.3, "mounting off by {error_deg} deg");
    assert!(r.session.stage().hint_stats().speed_updates > 500);
    let wrong = run_with_hints(cfg, HintConfig::default(), &samples, &hints);
    let (e, e_wrong) = (
        end_error(&r.states, &truth),
        end_error(&wrong.states, &truth),
    );
    eprintln!("end error {e} m estimated, {e_wrong} m with the identity configured");
    assert!(e < 0.01 * distance(&truth), "{e} m");
}

/// The states depend on the hints' times only, not on when they are handed over: all hints
/// given before the first sample, or each just before the sample that may use it, give
/// bit-identical states (what makes a replay reproduce a live run).
#[test]
fn states_do_not_depend_on_how_hints_and_samples_interleave() {
    let c = Case {
        duration_s: 40.0,
        rate_hz: 100.0,
        dlpf: None,
        turns: true,
        ..Case::straight()
    };
    let (samples, _, cfg) = simulate(&c, 2);
    let mut p = HintParams::new(RestSource::Encoders);
    p.drop_fraction = 0.3;
    let hints = c.hints(2, &p).hints;
    let hint_cfg = HintConfig {
        capacity: hints.len(),
        ..HintConfig::default()
    };
    let just_in_time = run_with_hints(cfg, hint_cfg, &samples, &hints);
    let mut stage = OdometryStage::with_hints(cfg, hint_cfg).unwrap();
    for h in &hints {
        stage.hint(h, &mut |_| {}).unwrap();
    }
    let mut upfront = Vec::new();
    for s in &samples {
        stage
            .process(s, &mut |o| {
                if o.flags & odometry_flags::REVISION == 0 {
                    upfront.push(*o);
                }
            })
            .unwrap();
    }
    let bits = |o: &OdometryState| {
        let mut v: Vec<u64> = o
            .position_m
            .iter()
            .chain(&o.velocity_mps)
            .chain(&o.position_sigma_m)
            .chain(&o.attitude_wxyz)
            .map(|x| x.to_bits())
            .collect();
        v.extend([u64::from(o.flags), u64::from(o.hints_applied)]);
        v
    };
    assert_eq!(upfront.len(), just_in_time.states.len());
    for (a, b) in upfront.iter().zip(&just_in_time.states) {
        assert_eq!(bits(a), bits(b), "seq {}", a.seq);
    }
    assert!(just_in_time.session.stage().hint_stats().speed_updates > 100);
}

/// A stationary hint does not align the filter before the calibration stage's detector is
/// ready (its gyro output is about to change by the turn-on bias it subtracts then); the
/// detector's own rest flag is not needed once it is.
#[test]
fn stationary_hints_align_only_once_the_detector_is_ready() {
    let c = Case {
        duration_s: 20.0,
        rate_hz: 100.0,
        dlpf: None,
        ..Case::straight()
    };
    let (mut samples, _, cfg) = simulate(&c, 3);
    for s in samples.iter_mut() {
        // The detector learns for the first 5 s, and never flags rest itself.
        s.flags &= !corrected_flags::ZERO_STATE;
        if s.stamps.sample_ns < 5_000_000_000 {
            s.flags &= !corrected_flags::DETECTOR_READY;
        }
    }
    let hints = rest_only(&c.hints(3, &no_losses(RestSource::Encoders)).hints);
    let r = run_with_hints(cfg, HintConfig::default(), &samples, &hints);
    let first_aligned = r
        .states
        .iter()
        .find(|o| o.flags & odometry_flags::ALIGNED != 0)
        .expect("aligned on the hints' rest");
    // align_s (1 s) of rest after the detector became ready at 5 s.
    let t = first_aligned.stamps.sample_ns as f64 * 1e-9;
    assert!((6.0..6.1).contains(&t), "aligned at {t} s");
}
