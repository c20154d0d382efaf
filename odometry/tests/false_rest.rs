//! A walk taken for rest (`odometry::consistency`): the stage aligns at rest, walks off along
//! x to 1.4 m/s, and then the detector flags rest for 10 s while the walk goes on at 1.4 m/s
//! with a walker's 2 Hz surge of +-3 m/s^2 (sensor level, x forward). Every zero-velocity
//! update of that "rest" stops a real motion: the first removes the walk's 1.4 m/s, the next
//! ones what each window's surge added, far beyond what rest allows. The estimate ends about
//! 18 m short of the truth with either scaling (the updates are made: the estimate is the
//! same), but only with the innovations' consistency does the published 1-sigma say so: the
//! rest is counted as inconsistent and the 1-sigma grows from millimetres to metres. It does
//! not reach the error (measured: 6.5 m per axis against 18 m): the velocity the updates
//! removed is what the filter integrated, and repeated updates against a surge leak part of
//! it into the accelerometer bias and tilt estimates, so the sum of what they removed falls
//! to about 0.8 of the walk's speed; and a steady walk after the first window is, to an
//! IMU, indistinguishable from rest.

use ipc_types::{CorrectedImuSample, OdometryState, Stamps, corrected_flags};
use odometry::config::OdometryConfig;
use odometry::consistency::{ConsistencyReport, Scaling};
use odometry::stage::OdometryStage;

const G: f64 = 9.80665;
const RATE: f64 = 200.0;
const REST_S: f64 = 1.5;
const WALK_OFF_S: f64 = 2.0;
const FALSE_REST_S: f64 = 10.0;
/// Acceleration of the walk-off, m/s^2 (to 1.4 m/s in 2 s).
const WALK_OFF_MPS2: f64 = 0.7;
/// Amplitude (m/s^2) and frequency (Hz) of the surge during the false rest.
const SURGE: (f64, f64) = (3.0, 2.0);
/// Radius holding 68 % of a circular 2-D Gaussian, per-axis sigmas (bench.py's `R68_FACTOR`).
const R68_FACTOR: f64 = 1.515;

/// Forward acceleration (m/s^2), whether flagged rest, and the true position (m) at `t`.
fn truth(t: f64) -> (f64, bool, f64) {
    let v0 = WALK_OFF_MPS2 * WALK_OFF_S;
    let x0 = 0.5 * WALK_OFF_MPS2 * WALK_OFF_S * WALK_OFF_S;
    if t < REST_S {
        (0.0, true, 0.0)
    } else if t < REST_S + WALK_OFF_S {
        let s = t - REST_S;
        (WALK_OFF_MPS2, false, 0.5 * WALK_OFF_MPS2 * s * s)
    } else {
        // v = v0 + a / w (1 - cos w s), x = x0 + v0 s + a / w (s - sin(w s) / w).
        let s = t - REST_S - WALK_OFF_S;
        let w = 2.0 * std::f64::consts::PI * SURGE.1;
        let a = SURGE.0;
        let x = x0 + v0 * s + a / w * (s - (w * s).sin() / w);
        (a * (w * s).sin(), true, x)
    }
}

/// The last state and the consistency report of a run with `scaling`, and the true end
/// position along x, m.
fn run(scaling: Scaling) -> (OdometryState, ConsistencyReport, f64) {
    let mut cfg = OdometryConfig::mpu9250(G);
    cfg.consistency.scaling = scaling;
    let mut stage = OdometryStage::new(cfg);
    let mut last = None;
    let n = ((REST_S + WALK_OFF_S + FALSE_REST_S) * RATE) as u64;
    let mut end_x = 0.0;
    for k in 0..n {
        let t = k as f64 / RATE;
        let (a, rest, x) = truth(t);
        end_x = x;
        let sample = CorrectedImuSample {
            stamps: Stamps {
                sample_ns: (t * 1e9).round() as u64,
                ..Default::default()
            },
            seq: k,
            accel_mps2: [a, 0.0, G],
            flags: corrected_flags::DETECTOR_READY
                | if rest { corrected_flags::ZERO_STATE } else { 0 },
            ..Default::default()
        };
        stage.process(&sample, &mut |s| last = Some(*s)).unwrap();
        stage.postprocess(&mut |s| last = Some(*s));
    }
    assert!(stage.aligned());
    (last.expect("states emitted"), stage.consistency(), end_x)
}

fn horizontal_sigma(s: &OdometryState) -> f64 {
    let p = s.position_sigma_m;
    ((p[0] * p[0] + p[1] * p[1]) / 2.0).sqrt()
}

#[test]
fn a_walk_taken_for_rest_is_counted_and_widens_the_sigma() {
    let (off, off_report, end_x) = run(Scaling::Off);
    let (on, report, _) = run(Scaling::Report);
    // The estimates are the same: only the published 1-sigma differs.
    assert_eq!(off.position_m, on.position_m);
    let error = (on.position_m[0] - end_x).hypot(on.position_m[1]);
    assert!(
        error > 10.0,
        "the false rest stopped the walk: error {error} m"
    );
    // Counted either way (`off` still reports), one rest.
    assert_eq!(report.rests_inconsistent, 1, "{report}");
    assert_eq!(off_report.rests_inconsistent, 1, "{off_report}");
    let (s_off, s_on) = (horizontal_sigma(&off), horizontal_sigma(&on));
    eprintln!(
        "error {error:.2} m; 1-sigma {s_off:.3} m without the consistency, {s_on:.2} m with \
         it; {report}"
    );
    assert!(error > R68_FACTOR * s_off, "{s_off}");
    // From millimetres to a third of the error at least, and not beyond it.
    assert!(s_off < 0.01, "{s_off}");
    assert!(s_on > error / 3.0, "error {error} m, 1-sigma {s_on} m");
    assert!(s_on < error, "1-sigma {s_on} m against {error} m");
}
