//! The odometry stage on an analytic straight drive: rest, raised-cosine acceleration, cruise,
//! raised-cosine braking, rest. The accelerometer bias changes by 0.01 m/s^2 after alignment
//! (a warm-up step the alignment cannot see), so dead reckoning drifts by b t^2 / 2 during the
//! motion; the zero-velocity updates at the final rest must remove most of it, and the revised
//! history must be closer to the truth than the forward estimate.

use ipc_types::{CorrectedImuSample, OdometryState, Stamps, corrected_flags, odometry_flags};
use odometry::config::OdometryConfig;
use odometry::stage::OdometryStage;
use std::f64::consts::PI;

const G: f64 = 9.81;
const RATE: f64 = 500.0;

/// Truth (acceleration, velocity, position) along x at time t for the profile
/// rest 2 s | accelerate 2 s (peak 0.5 m/s^2) | cruise 3 s | brake 2 s | rest 3 s.
fn truth(t: f64) -> (f64, f64, f64) {
    let (a_pk, ta) = (0.5, 2.0);
    // Raised cosine a(s) = A/2 (1 - cos(2 pi s / T)) and its exact integrals.
    let seg = |s: f64| {
        let w = 2.0 * PI / ta;
        let a = a_pk / 2.0 * (1.0 - (w * s).cos());
        let v = a_pk / 2.0 * (s - (w * s).sin() / w);
        let p = a_pk / 2.0 * (s * s / 2.0 + ((w * s).cos() - 1.0) / (w * w));
        (a, v, p)
    };
    let (_, v_top, p_acc) = seg(ta);
    match t {
        t if t < 2.0 => (0.0, 0.0, 0.0),
        t if t < 4.0 => seg(t - 2.0),
        t if t < 7.0 => (0.0, v_top, p_acc + v_top * (t - 4.0)),
        t if t < 9.0 => {
            let (a, v, p) = seg(t - 7.0);
            (-a, v_top - v, p_acc + v_top * 3.0 + v_top * (t - 7.0) - p)
        }
        _ => (0.0, 0.0, 2.0 * p_acc + v_top * 3.0),
    }
}

/// Sample `k` with an accelerometer bias `bias_x` on x, flagged at rest where the truth is and
/// for `late_s` seconds after each rest (a detector slow to see the start of motion).
fn sample(k: u64, bias_x: f64, late_s: f64) -> CorrectedImuSample {
    let t = k as f64 / RATE;
    let (a, _, _) = truth(t);
    let at_rest = |t: f64| {
        let (a, v, _) = truth(t);
        v.abs() < 1e-12 && a.abs() < 1e-12
    };
    let rest = at_rest(t) || at_rest(t - late_s);
    CorrectedImuSample {
        stamps: Stamps {
            sample_ns: k * (1e9 / RATE) as u64,
            ..Default::default()
        },
        seq: k,
        accel_mps2: [a + bias_x, 0.0, G],
        flags: if rest { corrected_flags::ZERO_STATE } else { 0 },
        ..Default::default()
    }
}

#[test]
fn zero_velocity_updates_remove_drift_and_revise_history() {
    let mut stage = OdometryStage::new(OdometryConfig::mpu9250(G));
    let mut live: Vec<OdometryState> = Vec::new();
    let mut revised: Vec<OdometryState> = Vec::new();
    let n = (12.0 * RATE) as u64;
    for k in 0..n {
        // The bias steps to 0.01 m/s^2 once alignment (the first second of rest) is done.
        let bias = if k as f64 / RATE > 1.5 { 0.01 } else { 0.0 };
        stage
            .process(&sample(k, bias, 0.0), &mut |s| {
                if s.flags & odometry_flags::REVISION != 0 {
                    revised.push(*s);
                } else {
                    live.push(*s);
                }
            })
            .unwrap();
    }
    assert!(stage.aligned());
    let (_, _, p_end) = truth(11.99);

    // Without updates the drift over the 7 s from the bias step to the end of motion would be
    // b t^2 / 2 = 0.245 m; the live state just before the final rest shows it.
    let before_rest = live
        .iter()
        .rfind(|s| s.stamps.sample_ns < 9_000_000_000)
        .unwrap();
    let drift_before =
        before_rest.position_m[0] - truth(before_rest.stamps.sample_ns as f64 * 1e-9).2;
    assert!(drift_before > 0.15, "forward drift {drift_before}");

    // After the final rest, most of it is gone.
    let last = live.last().unwrap();
    let err_end = last.position_m[0] - p_end;
    assert!(
        err_end.abs() < 0.25 * drift_before,
        "end error {err_end}, drift {drift_before}"
    );
    assert!(last.velocity_mps.iter().all(|v| v.abs() < 1e-3));
    assert_eq!(last.rest_count, 1);
    // The reported 1-sigma covers the remaining error.
    assert!(
        err_end.abs() < 3.0 * last.position_sigma_m[0],
        "err {err_end} sigma {:?}",
        last.position_sigma_m
    );

    // The revised history (decimated to 100 Hz) is closer to the truth than the forward one.
    // A state can be revised twice (the rest flags of the last half second before the motion
    // are withdrawn in hindsight, then the motion's drift is removed): the latest counts.
    let mut latest: std::collections::BTreeMap<u64, OdometryState> = Default::default();
    for r in &revised {
        latest.insert(r.seq, *r);
    }
    let revised: Vec<OdometryState> = latest.into_values().collect();
    assert!(revised.len() > 600, "{} revised states", revised.len());
    let max_err = |states: &[OdometryState]| {
        states
            .iter()
            .map(|s| (s.position_m[0] - truth(s.stamps.sample_ns as f64 * 1e-9).2).abs())
            .fold(0.0, f64::max)
    };
    let forward: Vec<OdometryState> = live
        .iter()
        .filter(|s| revised.iter().any(|r| r.seq == s.seq))
        .copied()
        .collect();
    assert_eq!(forward.len(), revised.len());
    assert!(
        max_err(&revised) < 0.3 * max_err(&forward),
        "revised {} vs forward {}",
        max_err(&revised),
        max_err(&forward)
    );
}

/// The end position error of a run over the whole profile with rest flags `late_s` late.
fn end_error(cfg: OdometryConfig, late_s: f64) -> f64 {
    let mut stage = OdometryStage::new(cfg);
    let mut last = None;
    for k in 0..(12.0 * RATE) as u64 {
        stage
            .process(&sample(k, 0.0, late_s), &mut |s| {
                if s.flags & odometry_flags::REVISION == 0 {
                    last = Some(*s);
                }
            })
            .unwrap();
    }
    last.unwrap().position_m[0] - truth(11.99).2
}

#[test]
fn late_rest_flags_are_withdrawn_in_hindsight() {
    // Flags 0.4 s late at the start: the zero-velocity updates there cut the speed gained by
    // then, v(0.4 s) = 0.0243 m/s. Held over the 7 s of motion, with the linear drift removal
    // at the final rest giving back half, the path comes out about 0.024 * 7 / 2 = 0.085 m
    // short (the final rest's flags are punctual: lateness only holds a rest on). The hindsight
    // (0.5 s by default) withdraws those flags, and the run is that of punctual flags.
    let cfg = OdometryConfig::mpu9250(G);
    let no_hindsight = OdometryConfig {
        rest_hindsight_s: 0.0,
        ..cfg
    };
    let (v_cut, motion_s) = (0.25 * (0.4 - (0.4 * PI).sin() / PI), 7.0);
    let cut = end_error(no_hindsight, 0.4);
    assert!(
        cut < -0.8 * v_cut * motion_s / 2.0 && cut > -1.5 * v_cut * motion_s / 2.0,
        "error without hindsight {cut} m, expected about {} m",
        -v_cut * motion_s / 2.0
    );
    let punctual = end_error(no_hindsight, 0.0);
    let withdrawn = end_error(cfg, 0.4);
    assert!(punctual.abs() < 1e-6, "{punctual}");
    // Bit for bit: without noise, the updates withdrawn from the rest before the motion had
    // nothing to correct.
    assert_eq!(withdrawn.to_bits(), punctual.to_bits());
}

#[test]
fn time_going_backwards_is_refused() {
    let mut stage = OdometryStage::new(OdometryConfig::mpu9250(G));
    stage.process(&sample(10, 0.0, 0.0), &mut |_| {}).unwrap();
    let err = stage
        .process(&sample(9, 0.0, 0.0), &mut |_| {})
        .unwrap_err();
    assert!(err.to_string().contains("seq 9"), "{err}");
    let mut nan = sample(11, 0.0, 0.0);
    nan.accel_mps2[1] = f64::NAN;
    let err = stage.process(&nan, &mut |_| {}).unwrap_err();
    assert!(err.to_string().contains("accel_mps2"), "{err}");
}
