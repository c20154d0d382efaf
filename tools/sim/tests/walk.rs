//! The foot-mounted walk's truth against independent computations: its specific force and
//! angular rate integrate to its velocities, positions and attitudes (with the trapezoid
//! rule's second-order convergence), stance is still, the loop closes, and the gait has the
//! configured stance times, strides, foot speeds, pitch swing and heel strikes.

use mems_sim::SimSensor;
use mems_sim::model::SensorModel;
use mems_sim::scenario::{Scenario, Walk, WalkParams};
use mems_sim::vibration::VibrationModel;
use nalgebra::{UnitQuaternion, Vector3};
use recording::Truth;

fn attitude(t: &Truth) -> UnitQuaternion<f64> {
    let [w, x, y, z] = t.attitude_wxyz;
    UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z))
}

fn walk(laps: u32, seed: u64) -> Walk {
    Walk::new(&WalkParams::new(laps), seed).unwrap()
}

fn truths(s: &impl Scenario, rate_hz: f64) -> Vec<Truth> {
    let n = (s.duration_s() * rate_hz).floor() as usize;
    (0..=n).map(|k| s.truth(k as f64 / rate_hz)).collect()
}

/// Integrates the truth's specific force (rotated by the truth attitude, plus gravity) twice
/// and its angular rate once with the trapezoid / midpoint rules at `rate_hz`; returns the
/// largest position (m), velocity (m/s) and attitude (rad) errors against the truth.
fn integration_errors(w: &Walk, rate_hz: f64) -> [f64; 3] {
    let h = 1.0 / rate_hz;
    let g = Vector3::new(0.0, 0.0, -w.params().gravity_mps2);
    let tr = truths(w, rate_hz);
    let a: Vec<Vector3<f64>> = tr
        .iter()
        .map(|t| attitude(t) * Vector3::from(t.specific_force_mps2) + g)
        .collect();
    let mut v = Vector3::from(tr[0].velocity_mps);
    let mut p = Vector3::from(tr[0].position_m);
    let mut q = attitude(&tr[0]);
    let mut err = [0.0f64; 3];
    for k in 1..tr.len() {
        let v_next = v + 0.5 * h * (a[k - 1] + a[k]);
        p += 0.5 * h * (v + v_next);
        v = v_next;
        let rate = 0.5
            * (Vector3::from(tr[k - 1].angular_rate_rps) + Vector3::from(tr[k].angular_rate_rps));
        q *= UnitQuaternion::from_scaled_axis(rate * h);
        err[0] = err[0].max((p - Vector3::from(tr[k].position_m)).norm());
        err[1] = err[1].max((v - Vector3::from(tr[k].velocity_mps)).norm());
        err[2] = err[2].max(q.angle_to(&attitude(&tr[k])));
    }
    err
}

#[test]
fn specific_force_and_rate_integrate_to_the_truth() {
    let w = walk(1, 3);
    let coarse = integration_errors(&w, 5_000.0);
    let fine = integration_errors(&w, 10_000.0);
    eprintln!("errors at 5 kHz {coarse:?}, at 10 kHz {fine:?}");
    // Second order: halving the step divides each error by about 4.
    for i in 0..3 {
        assert!(
            fine[i] < 0.35 * coarse[i],
            "error {i} does not converge: {coarse:?} -> {fine:?}"
        );
    }
    assert!(fine[0] < 1e-6, "position error {} m", fine[0]);
    assert!(fine[1] < 1e-4, "velocity error {} m/s", fine[1]);
    assert!(fine[2] < 1e-5, "attitude error {} rad", fine[2]);
}

#[test]
fn the_loop_closes_and_stances_are_still() {
    for laps in [1, 2] {
        let w = walk(laps, 5);
        let rate = 1000.0;
        let tr = truths(&w, rate);
        let (first, last) = (&tr[0], tr.last().unwrap());
        let end = Vector3::from(last.position_m);
        assert!(end.norm() < 1e-12, "ends {end:?} from the start");
        assert!(attitude(first).angle_to(&attitude(last)) < 1e-9);
        assert!(first.at_rest && last.at_rest);
        // Still means still, in the truth.
        for t in tr.iter().filter(|t| t.at_rest) {
            assert_eq!(t.velocity_mps, [0.0; 3]);
            assert_eq!(t.angular_rate_rps, [0.0; 3]);
        }
        // Every stance between the initial and the final rest lasts 0.2-0.5 s.
        let mut runs = Vec::new();
        let mut run = 0usize;
        for t in &tr {
            if t.at_rest {
                run += 1;
            } else if run > 0 {
                runs.push(run);
                run = 0;
            }
        }
        assert!(runs.len() > 25 * laps as usize, "{} stances", runs.len());
        for r in &runs[1..] {
            let s = *r as f64 / rate;
            assert!((0.2 - 2e-3..=0.5 + 2e-3).contains(&s), "stance of {s} s");
        }
        // The footprints: strides of 1.0-1.6 m, a perimeter of 36 m per lap.
        let mut prints: Vec<Vector3<f64>> = Vec::new();
        for t in tr.iter().filter(|t| t.at_rest) {
            let p = Vector3::from(t.position_m);
            if prints.last().is_none_or(|q| (p - q).norm() > 1e-9) {
                prints.push(p);
            }
        }
        let mut walked = 0.0;
        for s in prints.windows(2) {
            let stride = (s[1] - s[0]).norm();
            assert!(
                (1.0 - 1e-9..=1.6 + 1e-9).contains(&stride),
                "stride {stride} m"
            );
            walked += stride;
        }
        assert!(
            (walked - 36.0 * laps as f64).abs() < 1e-9,
            "walked {walked} m"
        );
    }
}

#[test]
fn swings_have_the_configured_speed_pitch_and_heel_strikes() {
    let w = walk(1, 7);
    let rate = 2000.0;
    let tr = truths(&w, rate);
    let g = w.params().gravity_mps2;
    let impact = w.impact_s();
    for (start, swing, _) in w.step_times() {
        let window = |from: f64, to: f64| {
            let (a, b) = ((from * rate).ceil() as usize, (to * rate) as usize);
            &tr[a..b.min(tr.len())]
        };
        let swing_truth = window(start, start + swing);
        let horizontal = |t: &Truth| t.velocity_mps[0].hypot(t.velocity_mps[1]);
        if swing_truth.iter().all(|t| horizontal(t) == 0.0) {
            continue; // the final pivot on the start footprint
        }
        let speed = swing_truth
            .iter()
            .map(|t| Vector3::from(t.velocity_mps).norm())
            .fold(0.0, f64::max);
        assert!(
            (3.99..=5.01).contains(&speed),
            "peak foot speed {speed} m/s"
        );
        // Foot pitch: toe-down then toe-up by tens of degrees (heading removed).
        let pitches: Vec<f64> = swing_truth
            .iter()
            .map(|t| {
                let (_, pitch, _) = attitude(t).euler_angles();
                pitch.to_degrees()
            })
            .collect();
        let (lo, hi) = pitches
            .iter()
            .fold((f64::MAX, f64::MIN), |(l, h), p| (l.min(*p), h.max(*p)));
        assert!(hi > 25.0 && lo < -10.0, "pitch {lo}..{hi} degrees");
        // Heel strike: a burst of several g in the specific force, foot still on the floor.
        let strike = window(start + swing, start + swing + impact);
        let peak = strike
            .iter()
            .map(|t| (Vector3::from(t.specific_force_mps2).norm() - g).abs())
            .fold(0.0, f64::max);
        assert!(peak > 2.0 * g, "heel strike peaks at {} g", peak / g);
        let moved = strike
            .iter()
            .map(|t| (Vector3::from(t.position_m) - Vector3::from(strike[0].position_m)).norm())
            .fold(0.0, f64::max);
        assert!(moved < 1e-3, "the heel strike moves the foot {moved} m");
    }
}

#[test]
fn the_sensor_sees_tremor_in_stance_only() {
    let w = walk(1, 9);
    let rate = 1000.0;
    let mut sim = SimSensor::new(
        w.clone(),
        &SensorModel::ideal(),
        &VibrationModel::moderate(0.0),
        9,
    )
    .unwrap();
    let (mut still, mut still_sq, mut moving_max) = (0usize, 0.0, 0.0f64);
    let n = (w.duration_s() * rate) as usize;
    for k in 0..n {
        let t = k as f64 / rate;
        let (a, truth) = sim.sample_with_truth(t, rate);
        let dev: f64 = (0..3)
            .map(|i| {
                (a.accel_g[i] * mems_sim::model::G_MPS2 - truth.specific_force_mps2[i]).powi(2)
            })
            .sum();
        if truth.at_rest {
            still += 1;
            still_sq += dev / 3.0;
        } else {
            moving_max = moving_max.max(dev.sqrt());
        }
    }
    let rms = (still_sq / still as f64).sqrt();
    assert!(
        (0.03..0.07).contains(&rms),
        "tremor {rms} m/s^2 RMS per axis"
    );
    assert!(moving_max < 1e-9, "disturbance while moving: {moving_max}");
}

#[test]
fn invalid_walks_name_their_field() {
    let bad = [
        (
            WalkParams {
                laps: 0,
                ..WalkParams::new(1)
            },
            "laps",
        ),
        (
            WalkParams {
                stride_m: [1.0, 1.05],
                rectangle_m: [5.5, 5.5],
                ..WalkParams::new(1)
            },
            "stride_m",
        ),
        (
            WalkParams {
                stance_s: [0.5, 0.2],
                ..WalkParams::new(1)
            },
            "stance_s",
        ),
        (
            WalkParams {
                initial_rest_s: -1.0,
                ..WalkParams::new(1)
            },
            "initial_rest_s",
        ),
    ];
    for (p, field) in bad {
        assert_eq!(Walk::new(&p, 1).unwrap_err().field, field);
    }
}
