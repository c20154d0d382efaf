//! The defects of real logs: repeated rows, host timestamp jitter and quantisation, a start in
//! motion; every row's truth stays that of the measurement it carries.

use ipc_types::RawImuSample;
use ipc_types::units::{AccelRange, GyroRange};
use mems_sim::SimSensor;
use mems_sim::adc::quantize_sample;
use mems_sim::defects::{LogDefects, Logger, peak_speed_time};
use mems_sim::model::SensorModel;
use mems_sim::scenario::{Drive, DriveParams, Scenario, ns_from_s};
use mems_sim::vibration::VibrationModel;
use recording::Truth;

fn drive(duration_s: f64, initial_rest_s: f64) -> Drive {
    let p = DriveParams {
        initial_rest_s,
        turns: true,
        ..DriveParams::new(duration_s)
    };
    Drive::new(&p, 4).unwrap()
}

/// The session of `drive` at `rate_hz` through a logger with `defects`: (rows, their true
/// sample times).
fn logged(drive: &Drive, rate_hz: f64, defects: &LogDefects) -> Vec<(RawImuSample, Truth, f64)> {
    let mut sim = SimSensor::new(
        drive.clone(),
        &SensorModel::mpu9250_calibrated(),
        &VibrationModel::moderate(1.0),
        2,
    )
    .unwrap();
    let mut logger = Logger::new(defects, rate_hz, 2).unwrap();
    let n = (drive.duration_s() * rate_hz) as u64;
    let mut rows = Vec::new();
    for k in 0..n {
        let t = k as f64 / rate_hz;
        let (a, truth) = sim.sample_with_truth(t, rate_hz);
        let raw = quantize_sample(&a, AccelRange::G2, GyroRange::Dps250, ns_from_s(t), k);
        logger.log(raw, truth, |s, tr| rows.push((s, tr, t)));
    }
    rows
}

/// Checks what every defect keeps: times never decrease, every row's truth is the scenario's
/// truth at the instant its data was sampled (the row's seq says which), paired by time.
fn check_rows(drive: &Drive, rate_hz: f64, rows: &[(RawImuSample, Truth, f64)]) {
    for w in rows.windows(2) {
        assert!(w[1].0.stamps.sample_ns >= w[0].0.stamps.sample_ns);
    }
    for (s, t, _) in rows {
        let mut want = drive.truth(s.seq as f64 / rate_hz);
        want.t_ns = s.stamps.sample_ns;
        assert_eq!(*t, want, "row of sample {}", s.seq);
    }
}

#[test]
fn repeats_are_exact_copies_at_the_configured_fraction() {
    let d = drive(120.0, 5.0);
    let rate = 200.0;
    for same_time in [false, true] {
        let defects = LogDefects {
            repeat_fraction: 0.3,
            repeat_same_time: same_time,
            ..LogDefects::none()
        };
        let rows = logged(&d, rate, &defects);
        check_rows(&d, rate, &rows);
        let n = (120.0 * rate) as usize;
        let repeats = rows.len() - n;
        let fraction = repeats as f64 / n as f64;
        let se = (0.3 * 0.7 / n as f64).sqrt();
        assert!(
            (fraction - 0.3).abs() < 5.0 * se,
            "repeat fraction {fraction}"
        );
        let period_ns = (1e9 / rate) as u64;
        let mut seen = 0;
        for w in rows.windows(2) {
            if w[1].0.seq != w[0].0.seq {
                continue;
            }
            seen += 1;
            let (a, b) = (&w[0].0, &w[1].0);
            assert_eq!(a.accel_counts, b.accel_counts);
            assert_eq!(a.gyro_counts, b.gyro_counts);
            assert_eq!(a.flags, b.flags);
            let dt = b.stamps.sample_ns - a.stamps.sample_ns;
            if same_time {
                assert_eq!(dt, 0);
            } else {
                assert!(dt <= period_ns, "repeat {dt} ns after its original");
            }
        }
        assert_eq!(seen, repeats);
    }
}

#[test]
fn host_timestamps_jitter_with_the_configured_spread() {
    let d = drive(300.0, 5.0);
    let rate = 100.0;
    let jitter = 0.2e-3;
    let defects = LogDefects {
        jitter_std_s: jitter,
        ..LogDefects::none()
    };
    let rows = logged(&d, rate, &defects);
    check_rows(&d, rate, &rows);
    let err: Vec<f64> = rows
        .iter()
        .map(|(s, _, t)| s.stamps.sample_ns as f64 * 1e-9 - t)
        .collect();
    let n = err.len() as f64;
    let mean = err.iter().sum::<f64>() / n;
    let std = (err.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n).sqrt();
    assert!(mean.abs() < 5.0 * jitter / n.sqrt(), "mean {mean}");
    assert!(
        (std / jitter - 1.0).abs() < 5.0 / (2.0 * n).sqrt(),
        "std {std} s"
    );
}

#[test]
fn quantised_timestamps_repeat_and_stay_within_one_quantum() {
    let d = drive(60.0, 5.0);
    let rate = 2000.0;
    let defects = LogDefects {
        quantum_s: 1e-3,
        ..LogDefects::none()
    };
    let rows = logged(&d, rate, &defects);
    check_rows(&d, rate, &rows);
    let mut equal = 0;
    for w in rows.windows(2) {
        equal += usize::from(w[1].0.stamps.sample_ns == w[0].0.stamps.sample_ns);
    }
    // At 2 kHz a 1 ms clock gives every second row its predecessor's time.
    assert_eq!(equal, rows.len() / 2);
    for (s, _, t) in &rows {
        let host = s.stamps.sample_ns;
        assert_eq!(host % 1_000_000, 0);
        let lag = t - host as f64 * 1e-9;
        assert!(
            (-1e-9..1e-3).contains(&lag),
            "host time {lag} s before the sample"
        );
    }
}

#[test]
fn a_start_in_motion_has_no_rest_before_it() {
    let d = drive(200.0, 10.0);
    let rate = 100.0;
    let t0 = peak_speed_time(&d, rate).unwrap();
    let truth = d.truth(t0);
    assert!(!truth.at_rest && t0 > 10.0);
    let speed = |t: &Truth| t.velocity_mps.iter().map(|v| v * v).sum::<f64>().sqrt();
    assert!(speed(&truth) >= 0.2, "speed {}", speed(&truth));
    // The highest speed of the first motion: nothing faster between its start and its end.
    let mut k = (10.0 * rate) as u64;
    while d.truth(k as f64 / rate).at_rest {
        k += 1;
    }
    while !d.truth(k as f64 / rate).at_rest {
        assert!(speed(&d.truth(k as f64 / rate)) <= speed(&truth));
        k += 1;
    }
    assert!(k as f64 / rate > t0);
}

#[test]
fn invalid_defects_name_their_field() {
    for (defects, field) in [
        (
            LogDefects {
                repeat_fraction: 1.5,
                ..LogDefects::none()
            },
            "repeat_fraction",
        ),
        (
            LogDefects {
                jitter_std_s: -1.0,
                ..LogDefects::none()
            },
            "jitter_std_s",
        ),
        (
            LogDefects {
                quantum_s: f64::NAN,
                ..LogDefects::none()
            },
            "quantum_s",
        ),
    ] {
        let e = Logger::new(&defects, 100.0, 1).err().unwrap();
        assert_eq!(e.field, field);
    }
}
