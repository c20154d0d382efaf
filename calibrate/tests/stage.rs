//! The calibration stage against an independent computation of the correction, its ordering
//! and latency, bad input, stream restarts and gaps, and the bias refinement at rest.

use calibrate::calibfile::CalibrationFile;
use calibrate::model::{AccelModel, ModelKind, ParamCovariance};
use calibrate::stage::{CalibrationStage, RefineConfig, Settler, StageError, calib_id};
use calibrate::zero_state::{BATCH_LEN, DetectorConfig, DetectorKind};
use ipc_types::{CorrectedImuSample, RawImuSample, Stamps, corrected_flags, raw_flags};
use mems_stage::Stage;
use nalgebra::{Matrix3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

const GRAVITY: f64 = 9.797;

/// A full model with a non-trivial S and b, temperature terms and a gyroscope bias.
fn calibration() -> CalibrationFile {
    let s = Matrix3::new(
        1.01, 0.008, 0.009, -0.006, 0.995, 0.011, -0.010, -0.004, 1.022,
    );
    let m = AccelModel::new(ModelKind::Full, s, Vector3::new(0.04, -0.035, 0.055)).unwrap();
    let mut f = CalibrationFile::identity(GRAVITY);
    f.set_accel_model(&m, &ParamCovariance::zeros());
    f.temperature.reference_c = Some(25.0);
    f.temperature.bias_g_per_c = Some([8e-4, -6e-4, 1.2e-3]);
    f.gyro.bias_dps = Some([2.0, -1.5, 3.0]);
    f
}

fn stage(file: &CalibrationFile, kind: DetectorKind) -> CalibrationStage {
    CalibrationStage::new(
        file,
        DetectorConfig::new(kind, file.gravity_mps2),
        RefineConfig::default(),
    )
    .unwrap()
}

fn raw(seq: u64, t_ns: u64, accel_g: [f64; 3], gyro_dps: [f64; 3], temp_c: f64) -> RawImuSample {
    RawImuSample {
        stamps: Stamps {
            sample_ns: t_ns,
            acquired_ns: t_ns + 500,
            ..Stamps::default()
        },
        seq,
        accel_g,
        gyro_dps,
        temp_c,
        flags: raw_flags::GYRO_VALID | raw_flags::TEMP_VALID,
        ..RawImuSample::default()
    }
}

/// Pushes `samples`, collecting outputs and checking each push succeeds.
fn run(stage: &mut CalibrationStage, samples: &[RawImuSample]) -> Vec<CorrectedImuSample> {
    let mut out = Vec::new();
    for s in samples {
        stage.process(s, &mut |c| out.push(*c)).unwrap();
    }
    out
}

/// [`run`], with every sample's final flags (a [`Settler`] behind the stage).
fn run_settled(stage: &mut CalibrationStage, samples: &[RawImuSample]) -> Vec<CorrectedImuSample> {
    let mut settler = Settler::default();
    let mut out = Vec::new();
    for s in samples {
        stage
            .process(s, &mut |c| settler.push(c, &mut |c| out.push(*c)))
            .unwrap();
    }
    settler.finish(&mut |c| out.push(*c));
    out
}

#[test]
fn correction_matches_an_independent_computation() {
    let file = calibration();
    let mut st = stage(&file, DetectorKind::Glrt);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let samples: Vec<RawImuSample> = (0..2 * BATCH_LEN as u64)
        .map(|k| {
            let a = std::array::from_fn(|_| rng.random_range(-1.5..1.5));
            let w = std::array::from_fn(|_| rng.random_range(-200.0..200.0));
            raw(k, 1_000_000 * (k + 1), a, w, rng.random_range(20.0..40.0))
        })
        .collect();
    let out = run(&mut st, &samples);
    assert_eq!(out.len(), samples.len());
    // Before any rest the output is the file's correction alone: solve S a = a' - b - c dT
    // with an LU decomposition (the stage uses the cached inverse).
    let s = Matrix3::from_fn(|r, c| file.scale[r][c]);
    let b = Vector3::from(file.bias_g);
    let c = Vector3::from(file.temperature.bias_g_per_c.unwrap());
    for (o, r) in out.iter().zip(&samples) {
        assert_eq!(o.flags & corrected_flags::BIAS_REFINED, 0);
        let rhs = Vector3::from(r.accel_g) - b - c * (r.temp_c - 25.0);
        let a = s.lu().solve(&rhs).unwrap() * GRAVITY;
        for i in 0..3 {
            assert!((o.accel_mps2[i] - a[i]).abs() < 1e-12, "{o:?}");
            let w = (r.gyro_dps[i] - file.gyro.bias_dps.unwrap()[i]) * std::f64::consts::PI / 180.0;
            assert!((o.gyro_rps[i] - w).abs() < 1e-15);
        }
        assert_eq!(o.seq, r.seq);
        assert_eq!(
            o.stamps, r.stamps,
            "stamps copied, calibrated_ns left to the process"
        );
        assert_eq!(o.temp_c, r.temp_c);
        assert_eq!(o.raw_flags, r.flags);
        assert_eq!(o.calib_id, calib_id(&file));
        assert_eq!(o.flags & corrected_flags::DETECTOR_READY, 0);
    }
}

#[test]
fn each_sample_leaves_at_once_and_its_batch_end_settles_it() {
    let file = calibration();
    let mut st = stage(&file, DetectorKind::Yu);
    let mut released = Vec::new();
    for k in 0..(3 * BATCH_LEN + 7) as u64 {
        let mut now = Vec::new();
        st.process(
            &raw(
                k,
                1_000_000 * (k + 1),
                [0.0, 0.0, 1.05],
                [2.0, -1.5, 3.0],
                25.0,
            ),
            &mut |c| now.push((c.seq, c.flags, c.settles)),
        )
        .unwrap();
        // Each sample in the call that takes it; the batch's last settles the others.
        let batch_end = (k + 1) % BATCH_LEN as u64 == 0;
        assert_eq!(now.len(), 1);
        let (seq, flags, settles) = now[0];
        assert_eq!(seq, k);
        assert_eq!(flags & corrected_flags::PROVISIONAL == 0, batch_end);
        assert_eq!(settles, if batch_end { BATCH_LEN as u32 - 1 } else { 0 });
        released.push(seq);
    }
    assert_eq!(st.unsettled(), 7);
    st.finish(&mut |_| {});
    assert_eq!(st.unsettled(), 0);
    assert_eq!(
        released,
        (0..(3 * BATCH_LEN + 7) as u64).collect::<Vec<_>>()
    );
    assert_eq!(st.stats().accepted, st.stats().released);
}

#[test]
fn bad_input_is_refused_with_the_sample_named_and_the_state_unchanged() {
    let file = calibration();
    let mut st = stage(&file, DetectorKind::Glrt);
    let ok = |k: u64| raw(k, 1_000_000 * (k + 1), [0.0, 0.0, 1.0], [0.0; 3], 25.0);
    run(&mut st, &[ok(0), ok(1)]);
    let mut nan = ok(2);
    nan.accel_g[1] = f64::NAN;
    let e = st
        .process(&nan, &mut |_| panic!("nothing released"))
        .unwrap_err();
    assert!(
        matches!(
            e,
            StageError::NotFinite {
                seq: 2,
                field: "accel_g[1]",
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("seq 2") && e.to_string().contains("accel_g[1]"));
    let mut back = ok(2);
    back.stamps.sample_ns = 2_000_000; // equal to sample 1's time
    let e = st.process(&back, &mut |_| {}).unwrap_err();
    assert!(
        matches!(
            e,
            StageError::TimeNotIncreasing {
                seq: 2,
                prev_seq: 1,
                ..
            }
        ),
        "{e}"
    );
    let mut no_gyro = ok(2);
    no_gyro.flags = raw_flags::TEMP_VALID;
    let e = st.process(&no_gyro, &mut |_| {}).unwrap_err();
    assert!(
        e.to_string().contains("glrt") && e.to_string().contains("seq 2"),
        "{e}"
    );
    let mut no_temp = ok(2);
    no_temp.flags = raw_flags::GYRO_VALID;
    assert!(matches!(
        st.process(&no_temp, &mut |_| {}),
        Err(StageError::NoTemperature { seq: 2 })
    ));
    let mut bad_gyro = ok(2);
    bad_gyro.gyro_dps[2] = f64::INFINITY;
    assert!(
        st.process(&bad_gyro, &mut |_| {})
            .unwrap_err()
            .to_string()
            .contains("gyro_dps[2]")
    );
    // Nothing changed: the good sample 2 continues the stream without a gap.
    run(&mut st, &[ok(2)]);
    assert_eq!(st.stats().accepted, 3);
    assert_eq!(st.stats().gaps, 0);
    assert_eq!(st.unsettled(), 3);
    // Yu's detector does not need the gyroscope.
    let mut yu = stage(&file, DetectorKind::Yu);
    run(&mut yu, &[no_gyro]);
}

#[test]
fn absurd_samples_and_time_jumps_are_dropped_counted_and_flag_the_gap() {
    let file = calibration();
    let mut st = stage(&file, DetectorKind::Glrt);
    let ms = 1_000_000;
    let ok = |k: u64| raw(k, ms * (k + 1), [0.0, 0.0, 1.0], [0.0; 3], 25.0);
    let mut out = run(&mut st, &[ok(0), ok(1), ok(2)]);
    let mut refused = 0;
    let mut push = |st: &mut CalibrationStage, s: &RawImuSample, out: &mut Vec<_>| {
        st.process(s, &mut |c| out.push(*c))
            .inspect_err(|_| refused += 1)
    };
    for (seq, field, value) in [(3, 1, 1e300), (4, 2, 100.0)] {
        let mut bad = ok(seq);
        bad.accel_g[field] = value;
        let e = push(&mut st, &bad, &mut out).unwrap_err();
        assert!(matches!(e, StageError::OutOfRange { .. }), "{e}");
        assert!(e.to_string().contains("beyond the sensor's range"), "{e}");
    }
    let mut bad_gyro = ok(4);
    bad_gyro.gyro_dps[0] = -1e5;
    assert!(push(&mut st, &bad_gyro, &mut out).is_err());
    // The next good sample is after a gap, and says so.
    push(&mut st, &ok(5), &mut out).unwrap();
    let last = out.last().unwrap();
    assert_eq!(last.seq, 5);
    assert_ne!(last.raw_flags & raw_flags::GAP_BEFORE, 0);
    assert_eq!(st.stats().gaps, 1);
    // One stamp an hour ahead is dropped; the stream goes on after it.
    let mut ahead = ok(6);
    ahead.stamps.sample_ns += 3_600_000_000_000;
    let e = push(&mut st, &ahead, &mut out).unwrap_err();
    assert!(matches!(e, StageError::TimeStep { seq: 6, .. }), "{e}");
    push(&mut st, &ok(7), &mut out).unwrap();
    assert_eq!((st.stats().gaps, st.stats().restarts), (2, 0));
    // Two in a row are a new time base: a new stream from the second.
    let later = |k: u64| {
        let mut s = ok(k);
        s.stamps.sample_ns += 3_600_000_000_000;
        s
    };
    assert!(push(&mut st, &later(8), &mut out).is_err());
    push(&mut st, &later(9), &mut out).unwrap();
    push(&mut st, &later(10), &mut out).unwrap();
    assert_eq!(st.stats().restarts, 1);
    assert_eq!(refused, 5);
    assert_eq!(st.stats().accepted, 7);
    for c in &out {
        assert!(
            c.accel_mps2
                .iter()
                .chain(&c.gyro_rps)
                .all(|v| v.is_finite() && v.abs() < 300.0)
        );
    }
}

/// Rest samples of the sensor lying still with gravity along `up` (unit, sensor frame), with
/// the file's errors applied in reverse plus an extra accelerometer bias (m/s^2) and gyroscope
/// bias (deg/s) the file does not know, white noise at the MPU-9250's densities at 1 kHz.
fn still(
    file: &CalibrationFile,
    up: Vector3<f64>,
    extra_accel_mps2: Vector3<f64>,
    extra_gyro_dps: [f64; 3],
    seconds: f64,
    seed: u64,
) -> Vec<RawImuSample> {
    let model = file.accel_model().unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let na = Normal::new(0.0, 300e-6 * 1000f64.sqrt()).unwrap();
    let ng = Normal::new(0.0, 0.01 * 1000f64.sqrt()).unwrap();
    let n = (seconds * 1000.0) as u64;
    (0..n)
        .map(|k| {
            let truth_g = up + extra_accel_mps2 / GRAVITY;
            let noise = Vector3::from_fn(|_, _| na.sample(&mut rng));
            let a = model.measure(&truth_g) + noise;
            let w = std::array::from_fn(|i| {
                file.gyro.bias_dps.unwrap()[i] + extra_gyro_dps[i] + ng.sample(&mut rng)
            });
            raw(k, 1_000_000 * (k + 1), a.into(), w, 25.0)
        })
        .collect()
}

#[test]
fn refinement_at_rest_corrects_gyro_bias_and_only_the_accelerometer_along_gravity() {
    let file = calibration();
    let mut st = stage(&file, DetectorKind::Glrt);
    // Unknown to the file: 20 mm/s^2 on z (along gravity) and 50 mm/s^2 on x (across it), and
    // a gyroscope bias of (0.5, -0.3, 0.2) deg/s.
    let extra = Vector3::new(0.05, 0.0, 0.02);
    let gyro = [0.5, -0.3, 0.2];
    let out = run_settled(&mut st, &still(&file, Vector3::z(), extra, gyro, 30.0, 2));
    let ready = out
        .iter()
        .position(|o| o.flags & corrected_flags::DETECTOR_READY != 0)
        .unwrap();
    assert_eq!(
        ready, 4980,
        "ready with the batch that completes 5 s of learning"
    );
    // The refinement applies from the sample that completes learning on.
    let refined = ready + BATCH_LEN - 1;
    assert!(
        out[..refined]
            .iter()
            .all(|o| o.flags & corrected_flags::BIAS_REFINED == 0)
    );
    assert!(
        out[refined..]
            .iter()
            .all(|o| o.flags & corrected_flags::BIAS_REFINED != 0)
    );
    let rest = out
        .iter()
        .filter(|o| o.flags & corrected_flags::ZERO_STATE != 0)
        .count();
    assert!(rest as f64 > 0.9 * (out.len() - ready) as f64, "{rest}");
    let (accel, gyro_rps, refined) = st.refinement();
    assert!(refined);
    // About 30 s of rest at 3 mm/s^2 and 0.01 deg/s per sqrt(s) of rest (plus the prior).
    assert!((accel[2] - 0.02).abs() < 0.003, "{accel:?}");
    // Along the measured gravity direction, which the unknown x offset tilts by 0.05 / g rad:
    // x gets 0.02 * 0.05 / g = 1e-4, not the 0.05 it lacks.
    let along = 0.02 * 0.05 / GRAVITY;
    assert!(
        (accel[0] - along).abs() < 3e-5 && accel[1].abs() < 3e-5,
        "{accel:?}"
    );
    for i in 0..3 {
        assert!(
            (gyro_rps[i].to_degrees() - gyro[i]).abs() < 0.01,
            "{gyro_rps:?}"
        );
    }
    // The output at rest now has |a| = g and zero rate (the x offset stays: it is a tilt).
    let tail = &out[out.len() - 5000..];
    let mean = |f: &dyn Fn(&CorrectedImuSample) -> f64| {
        tail.iter().map(f).sum::<f64>() / tail.len() as f64
    };
    let a = Vector3::new(
        mean(&|o| o.accel_mps2[0]),
        mean(&|o| o.accel_mps2[1]),
        mean(&|o| o.accel_mps2[2]),
    );
    assert!((a.norm() - GRAVITY).abs() < 0.004, "{a:?}");
    assert!((a.x - 0.05).abs() < 0.004, "{a:?}");
    assert!(mean(&|o| o.gyro_rps[0]).abs().to_degrees() < 0.01);
    // zs_mean is on the refined output's scale.
    let last = out.last().unwrap();
    assert!((Vector3::from(last.zs_mean_mps2).norm() - GRAVITY).abs() < 0.01);

    // Resting on another side afterwards corrects that direction's component: y up.
    let mut second = still(&file, Vector3::y(), extra, gyro, 70.0, 3);
    for (k, s) in second.iter_mut().enumerate() {
        s.seq += out.len() as u64;
        s.stamps.sample_ns = 1_000_000 * (out.len() + k + 1) as u64;
    }
    run(&mut st, &second);
    let (accel, _, _) = st.refinement();
    // x still unobservable; y's true extra is 0; z's earlier estimate is kept.
    assert!(accel[0].abs() < 1e-3 && accel[1].abs() < 0.003, "{accel:?}");
    assert!((accel[2] - 0.02).abs() < 0.003, "{accel:?}");
}

#[test]
fn a_restarted_publisher_starts_a_new_session_and_a_gap_leaves_the_partial_batch_unsettled() {
    let file = calibration();
    let mut st = stage(&file, DetectorKind::Glrt);
    let first = still(&file, Vector3::z(), Vector3::zeros(), [0.0; 3], 6.01, 4);
    let mut out = run(&mut st, &first);
    assert!(st.detector().is_ready());
    assert_eq!(st.unsettled(), 10);
    // A gap: seq 6011 missing.
    let mut after_gap = still(&file, Vector3::z(), Vector3::zeros(), [0.0; 3], 0.1, 5);
    for (k, s) in after_gap.iter_mut().enumerate() {
        s.seq = 6011 + k as u64;
        s.stamps.sample_ns = 1_000_000 * (6012 + k as u64);
    }
    let released = run(&mut st, &after_gap[..BATCH_LEN]);
    assert_eq!(st.stats().gaps, 1);
    // The batch after the gap starts afresh: its last sample settles it alone.
    assert_eq!(released.len(), BATCH_LEN);
    assert!(
        released[..BATCH_LEN - 1]
            .iter()
            .all(|o| o.flags & corrected_flags::PROVISIONAL != 0)
    );
    assert_eq!(released[BATCH_LEN - 1].settles, BATCH_LEN as u32 - 1);
    // The 10 samples before the gap are never settled: their carried rest verdict stands.
    let mut settled = Vec::new();
    let mut settler = Settler::default();
    for o in out.iter().chain(&released) {
        settler.push(o, &mut |o| settled.push(*o));
    }
    assert_eq!(settled.len(), out.len() + BATCH_LEN);
    assert!(
        settled[out.len() - 10..out.len()]
            .iter()
            .all(|o| o.flags & corrected_flags::PROVISIONAL != 0
                && o.flags & corrected_flags::DETECTOR_READY != 0)
    );
    out.extend(released);
    out.extend(run(&mut st, &after_gap[BATCH_LEN..]));
    // A new publisher: sequence numbers and sample times start again.
    let second = still(&file, Vector3::z(), Vector3::zeros(), [0.0; 3], 1.0, 6);
    let released = run(&mut st, &second);
    assert_eq!(st.stats().restarts, 1);
    assert!(!st.detector().is_ready(), "learning starts again");
    assert!(!st.refinement().2, "refinement starts again");
    // The new session is marked on its first sample only (the odometry follows the mark).
    assert_ne!(released[0].flags & corrected_flags::NEW_SESSION, 0);
    assert!(
        released
            .iter()
            .all(|o| o.flags & !(corrected_flags::PROVISIONAL | corrected_flags::NEW_SESSION) == 0)
    );
    assert!(
        released[1..]
            .iter()
            .all(|o| o.flags & corrected_flags::NEW_SESSION == 0)
    );
    assert!(
        out.iter()
            .all(|o| o.flags & corrected_flags::NEW_SESSION == 0)
    );
    out.extend(released);
    st.finish(&mut |_| {});
    assert_eq!(out.len(), first.len() + after_gap.len() + second.len());
}

#[test]
fn an_unmarked_hole_in_the_time_line_is_a_counted_gap_marked_as_a_hole() {
    let file = calibration();
    let mut st = stage(&file, DetectorKind::Glrt);
    let samples = still(&file, Vector3::z(), Vector3::zeros(), [0.0; 3], 3.0, 7);
    // Sequence numbers run on; 2 s of sample times are missing before sample 2000.
    let mut holed = samples.clone();
    for s in &mut holed[2000..] {
        s.stamps.sample_ns += 2_000_000_000;
    }
    let out = run(&mut st, &holed);
    let holes = st.stats().holes;
    assert_eq!(
        (holes.count, st.stats().gaps, st.stats().restarts),
        (1, 1, 0)
    );
    let longest = holes.longest.unwrap();
    assert_eq!(longest.seq, holed[2000].seq);
    assert_eq!(longest.dt_ns, 2_001_000_000);
    let marked: Vec<usize> = (0..out.len())
        .filter(|&i| out[i].flags & corrected_flags::HOLE_BEFORE != 0)
        .collect();
    assert_eq!(marked, [2000]);
    assert_ne!(out[2000].raw_flags & raw_flags::GAP_BEFORE, 0);
    assert_eq!(out[1999].raw_flags & raw_flags::GAP_BEFORE, 0);
    // Without the hole nothing is marked.
    let mut plain = stage(&file, DetectorKind::Glrt);
    let out = run(&mut plain, &samples);
    assert_eq!(plain.stats().holes.count, 0);
    assert!(
        out.iter()
            .all(|o| o.flags & corrected_flags::HOLE_BEFORE == 0)
    );
}

#[test]
fn calib_id_is_stable_and_changes_with_every_parameter() {
    let f = calibration();
    assert_eq!(calib_id(&f), calib_id(&f.clone()));
    // Independent of what is not a parameter.
    let mut g = f.clone();
    g.source.file = "elsewhere.csv".into();
    assert_eq!(calib_id(&g), calib_id(&f));
    let mut variants = Vec::new();
    let mut g = f.clone();
    g.bias_g[2] += 1e-9;
    variants.push(g);
    let mut g = f.clone();
    g.scale[1][0] += 1e-9;
    variants.push(g);
    let mut g = f.clone();
    g.gravity_mps2 = 9.80665;
    variants.push(g);
    let mut g = f.clone();
    g.temperature.bias_g_per_c = None;
    g.temperature.reference_c = None;
    variants.push(g);
    let mut g = f.clone();
    g.gyro.bias_dps = None;
    variants.push(g);
    let mut g = f.clone();
    g.temperature.scale_per_c = Some([1e-4, 0.0, 0.0]);
    variants.push(g);
    let mut g = f.clone();
    g.time.drift_g_per_s = Some([1e-6, 0.0, 0.0]);
    g.time.drift_max_s = Some(60.0);
    variants.push(g);
    let mut g = f.clone();
    g.time.warm_up_g = Some([1e-3, 0.0, 0.0]);
    g.time.warm_up_time_constant_s = Some(10.0);
    variants.push(g);
    let mut g = f.clone();
    g.nonlinearity.quadratic_g_per_g2 = Some([1e-3, 0.0, 0.0]);
    variants.push(g);
    for (k, g) in variants.iter().enumerate() {
        assert_ne!(calib_id(g), calib_id(&f));
        for h in &variants[..k] {
            assert_ne!(calib_id(g), calib_id(h));
        }
    }
}

#[test]
fn every_fitted_term_is_applied_with_the_time_since_the_stream_began() {
    let mut file = calibration();
    file.temperature.scale_per_c = Some([2e-3, -1e-3, 1.5e-3]);
    file.time.drift_g_per_s = Some([0.2, -0.1, 0.3]);
    file.time.drift_max_s = Some(0.02);
    file.time.warm_up_g = Some([0.01, 0.02, -0.03]);
    file.time.warm_up_time_constant_s = Some(0.01);
    file.nonlinearity.quadratic_g_per_g2 = Some([0.01, -0.008, 0.012]);
    let mut st = stage(&file, DetectorKind::Yu);
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    // Two streams: the second restarts its sequence numbers 5 s later, so its time since
    // power-on starts again from 0.
    let mut samples = Vec::new();
    for (t0_ns, n) in [
        (1_000_000_u64, 2 * BATCH_LEN as u64),
        (5_000_000_000, BATCH_LEN as u64),
    ] {
        for k in 0..n {
            let a = std::array::from_fn(|_| rng.random_range(-1.5..1.5));
            samples.push(raw(
                k,
                t0_ns + 1_000_000 * k,
                a,
                [0.0; 3],
                rng.random_range(20.0..40.0),
            ));
        }
    }
    let out = run(&mut st, &samples);
    st.finish(&mut |_| {});
    assert_eq!(out.len(), samples.len());
    let s = Matrix3::from_fn(|r, c| file.scale[r][c]);
    let b = Vector3::from(file.bias_g);
    let cb = Vector3::from(file.temperature.bias_g_per_c.unwrap());
    let cs = Vector3::from(file.temperature.scale_per_c.unwrap());
    let r = Vector3::from(file.time.drift_g_per_s.unwrap());
    let w = Vector3::from(file.time.warm_up_g.unwrap());
    let k = Vector3::from(file.nonlinearity.quadratic_g_per_g2.unwrap());
    for (o, x) in out.iter().zip(&samples) {
        let start_ns = if x.stamps.sample_ns >= 5_000_000_000 {
            5_000_000_000
        } else {
            1_000_000
        };
        let t = (x.stamps.sample_ns - start_ns) as f64 * 1e-9;
        let dt = x.temp_c - 25.0;
        // The output must satisfy the reading model written out here:
        // a' = (S + diag(c_s) dT) a + b + c_b dT + r min(t, 0.02) + w exp(-t / 0.01) + k a^2.
        let a = Vector3::from(o.accel_mps2) / GRAVITY;
        let reading = (s + Matrix3::from_diagonal(&(cs * dt))) * a
            + b
            + cb * dt
            + r * t.min(0.02)
            + w * (-t / 0.01).exp()
            + k.component_mul(&a).component_mul(&a);
        assert!(
            (reading - Vector3::from(x.accel_g)).norm() < 1e-12,
            "seq {} t {t}: {reading} vs {:?}",
            x.seq,
            x.accel_g
        );
    }
}

/// A SHOE stance is a foot with zero velocity, not a still sensor: it rolls at several deg/s.
/// Its rest flags reach the output, but nothing is refined from them (with the GLRT, the same
/// still sensor refines the gyro bias: `refinement_at_rest_corrects_gyro_bias_...`).
#[test]
fn shoe_stances_are_rest_but_refine_nothing() {
    let file = calibration();
    let mut st = stage(&file, DetectorKind::Shoe);
    // Rolling at 6 deg/s about y: inside SHOE's 17 deg/s, far from the file's bias.
    let out = run(
        &mut st,
        &still(
            &file,
            Vector3::z(),
            Vector3::zeros(),
            [0.0, 6.0, 0.0],
            2.0,
            5,
        ),
    );
    let rest = out
        .iter()
        .filter(|c| c.flags & corrected_flags::ZERO_STATE != 0)
        .count();
    assert!(
        rest as f64 > 0.9 * out.len() as f64,
        "{rest} of {}",
        out.len()
    );
    let (accel, gyro, refined) = st.refinement();
    assert!(
        !refined && accel == [0.0; 3] && gyro == [0.0; 3],
        "{gyro:?}"
    );
}

/// A restarted process that goes on from its predecessor's warm state behaves exactly as the
/// predecessor would have after a gap: the same corrected samples, flags and zero-state
/// verdicts (through JSON, as `mems-calibrate serve --state` writes it). Only the first batch's
/// provisional samples differ: the predecessor carries its verdict from before the gap over
/// to them, the new process has none to carry (not rest).
#[test]
fn a_resumed_stage_goes_on_as_the_original_after_a_gap() {
    let file = calibration();
    let samples = still(
        &file,
        Vector3::z(),
        Vector3::new(0.03, 0.0, 0.01),
        [0.4, -0.2, 0.1],
        12.0,
        7,
    );
    let (before, after) = samples.split_at(8_000);
    // 300 samples lost: the restart's gap.
    let after = &after[300..];
    let mut original = stage(&file, DetectorKind::Glrt);
    run(&mut original, before);
    let state = original.warm_state().unwrap();
    assert!(state.reference.is_some() && state.refined);
    let text = serde_json::to_string(&state).unwrap();
    let mut resumed = stage(&file, DetectorKind::Glrt);
    resumed
        .resume(&serde_json::from_str(&text).unwrap())
        .unwrap();
    let (a, b) = (run(&mut original, after), run(&mut resumed, after));
    assert_eq!(a.len(), b.len());
    let first = BATCH_LEN - 1;
    for (x, y) in a[..first].iter().zip(&b[..first]) {
        assert_eq!((x.accel_mps2, x.gyro_rps), (y.accel_mps2, y.gyro_rps));
        assert_eq!(y.flags & corrected_flags::ZERO_STATE, 0);
        assert_ne!(y.flags & corrected_flags::PROVISIONAL, 0);
    }
    let first_difference = a[first..].iter().zip(&b[first..]).position(|(x, y)| x != y);
    assert_eq!(
        first_difference,
        None,
        "{:?}",
        first_difference.map(|i| (&a[first + i], &b[first + i]))
    );
    assert!(
        b.iter()
            .all(|o| o.flags & corrected_flags::BIAS_REFINED != 0)
    );
    assert!(
        b[first..]
            .iter()
            .all(|o| o.flags & corrected_flags::DETECTOR_READY != 0),
        "ready without learning again"
    );
    // A fresh stage on the same samples learns from them first: not the same output.
    assert_ne!(run(&mut stage(&file, DetectorKind::Glrt), after), b);
}

/// A warm state from another stream (a new power-on: sequence numbers start again) or another
/// calibration is not gone on from.
#[test]
fn a_warm_state_from_another_stream_or_calibration_is_not_used() {
    let file = calibration();
    let samples = still(
        &file,
        Vector3::z(),
        Vector3::zeros(),
        [0.4, -0.2, 0.1],
        8.0,
        8,
    );
    let mut original = stage(&file, DetectorKind::Glrt);
    run(&mut original, &samples);
    let state = original.warm_state().unwrap();
    // The same samples again: sequence numbers and times not after the state's.
    let mut resumed = stage(&file, DetectorKind::Glrt);
    resumed.resume(&state).unwrap();
    let out = run(&mut resumed, &samples[..2_000]);
    assert!(
        out.iter()
            .all(|o| o.flags & corrected_flags::DETECTOR_READY == 0)
    );
    assert_eq!(resumed.stats().restarts, 1);
    // A new session, marked on its first sample; otherwise what a fresh stage gives.
    let mut out = out;
    assert_ne!(out[0].flags & corrected_flags::NEW_SESSION, 0);
    out[0].flags &= !corrected_flags::NEW_SESSION;
    assert_eq!(
        out,
        run(&mut stage(&file, DetectorKind::Glrt), &samples[..2_000])
    );

    let mut other = calibration();
    other.bias_g[0] += 1e-3;
    let err = stage(&other, DetectorKind::Glrt)
        .resume(&state)
        .unwrap_err();
    assert_eq!(err.state, calib_id(&file));
    assert_eq!(err.stage, calib_id(&other));
}
