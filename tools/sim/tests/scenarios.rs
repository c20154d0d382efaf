//! Scenario truth against independent computations: kinematic consistency (accelerations and
//! rates integrate to the truth's own velocities, positions and attitudes), rest flags,
//! gravity in poses, spread of orientations, vibration level, determinism.

// Index loops over axes mirror the equations they check.
#![allow(clippy::needless_range_loop)]

use mems_sim::SimSensor;
use mems_sim::model::{G_MPS2, SensorModel};
use mems_sim::scenario::{Arm, ArmParams, Drive, DriveParams, PoseParams, PoseSession, Scenario};
use mems_sim::vibration::VibrationModel;
use nalgebra::{UnitQuaternion, Vector3};
use recording::Truth;

fn attitude(t: &Truth) -> UnitQuaternion<f64> {
    let [w, x, y, z] = t.attitude_wxyz;
    UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z))
}

/// Kinematic acceleration in the navigation frame from the truth's specific force:
/// `a = R f + g_nav`.
fn nav_accel(t: &Truth, gravity: f64) -> Vector3<f64> {
    attitude(t) * Vector3::from(t.specific_force_mps2) + Vector3::new(0.0, 0.0, -gravity)
}

fn truths(s: &impl Scenario, rate_hz: f64) -> Vec<Truth> {
    let n = (s.duration_s() * rate_hz).floor() as usize;
    (0..=n).map(|k| s.truth(k as f64 / rate_hz)).collect()
}

fn drive_params(duration_s: f64) -> DriveParams {
    DriveParams {
        turns: true,
        in_place_turns: true,
        mounting: UnitQuaternion::from_euler_angles(0.1, -0.2, 0.7),
        ..DriveParams::new(duration_s)
    }
}

/// Maximum over samples of the central-difference derivative's norm.
fn max_rate_of_change(x: &[Vector3<f64>], h: f64) -> f64 {
    x.windows(3)
        .map(|w| ((w[2] - w[0]) / (2.0 * h)).norm())
        .fold(0.0, f64::max)
}

/// Integrates the truth's nav-frame accelerations twice with the trapezoid rule and returns the
/// largest velocity and position errors against the truth, and the tolerances:
///
/// By the Euler-Maclaurin formula the cumulative trapezoid integral of a smooth `y` over
/// `[0, t]` errs by `h^2 / 12 (y'(t) - y'(0))` to leading order. For the velocity (`y = a`)
/// that is at most `h^2 / 6 max|jerk|`. The position is the trapezoid integral of the
/// integrated velocity: its error is `h^2 / 12 (a(t) - a(0))` from the rule plus the integral
/// of the velocity error, `h^2 / 12 (a(t) - a(0) - jerk(0) t)`; the drive starts at rest
/// (`a(0) = jerk(0) = 0`), so at most `h^2 / 6 max|a|`. The profiles' accelerations have three
/// continuous derivatives, so the next terms are O(h^4); a factor 2 of margin covers them.
fn trapezoid_errors(s: &impl Scenario, g: f64, rate_hz: f64) -> ([f64; 2], [f64; 2]) {
    let h = 1.0 / rate_hz;
    let tr = truths(s, rate_hz);
    let a: Vec<Vector3<f64>> = tr.iter().map(|t| nav_accel(t, g)).collect();
    let mut v = Vector3::from(tr[0].velocity_mps);
    let mut p = Vector3::from(tr[0].position_m);
    let (mut ev, mut ep) = (0.0f64, 0.0f64);
    for k in 1..tr.len() {
        let v_next = v + 0.5 * h * (a[k - 1] + a[k]);
        p += 0.5 * h * (v + v_next);
        v = v_next;
        ev = ev.max((v - Vector3::from(tr[k].velocity_mps)).norm());
        ep = ep.max((p - Vector3::from(tr[k].position_m)).norm());
    }
    let a_max = a.iter().map(|x| x.norm()).fold(0.0, f64::max);
    let jerk_max = max_rate_of_change(&a, h);
    let tol_v = 2.0 * h * h / 6.0 * jerk_max;
    let tol_p = 2.0 * h * h / 6.0 * a_max;
    ([ev, ep], [tol_v, tol_p])
}

#[test]
fn drive_accelerations_integrate_to_truth_velocity_and_position() {
    let drive = Drive::new(&drive_params(180.0), 5).unwrap();
    let distance: f64 = {
        let tr = truths(&drive, 10.0);
        tr.windows(2)
            .map(|w| (Vector3::from(w[1].position_m) - Vector3::from(w[0].position_m)).norm())
            .sum()
    };
    assert!(
        distance > 30.0,
        "the drive should go somewhere: {distance} m"
    );
    let g = drive.params().gravity_mps2;
    let (e100, tol100) = trapezoid_errors(&drive, g, 100.0);
    let (e200, tol200) = trapezoid_errors(&drive, g, 200.0);
    eprintln!("100 Hz: errors {e100:?} tolerances {tol100:?}; 200 Hz: {e200:?} {tol200:?}");
    for i in 0..2 {
        assert!(e100[i] <= tol100[i], "100 Hz: {:?} > {:?}", e100, tol100);
        assert!(e200[i] <= tol200[i], "200 Hz: {:?} > {:?}", e200, tol200);
        // What is left is the rule's h^2 error, not an inconsistency of the truth: halving
        // the step divides it by 4.
        let ratio = e100[i] / e200[i];
        assert!(
            (3.5..4.5).contains(&ratio),
            "error ratio 100/200 Hz: {ratio}"
        );
    }
}

#[test]
fn drive_positions_are_exact_integrals_of_velocity() {
    // An independent fine integral of the truth's velocity: composite Simpson at h = 1 ms. Its
    // error is at most T h^4 max|v''''| / 180; the fastest profile here (a 0.2 m/s change at
    // 0.5 m/s^2 takes 1.07 s) has |v''''| of order dv (2 pi / T)^4 (8/3) < 1e4 m/s^5, so over
    // T = 180 s the bound is 1e-8 m: the truth's positions must agree to that.
    let drive = Drive::new(&drive_params(180.0), 9).unwrap();
    let h = 1e-3;
    let mut p = Vector3::zeros();
    let mut worst = 0.0f64;
    let v = |t: f64| Vector3::from(drive.truth(t).velocity_mps);
    let steps = (180.0 / (2.0 * h)) as usize;
    for k in 0..steps {
        let t0 = 2.0 * h * k as f64;
        p += h / 3.0 * (v(t0) + 4.0 * v(t0 + h) + v(t0 + 2.0 * h));
        worst = worst.max((p - Vector3::from(drive.truth(t0 + 2.0 * h).position_m)).norm());
    }
    eprintln!("Simpson vs truth position: {worst:e} m");
    assert!(
        worst < 1e-8,
        "position differs from the integral of velocity by {worst} m"
    );
    assert!(p.norm() > 10.0, "the drive went {} m", p.norm());
}

/// Integrates the truth's sensor-frame angular rate to an attitude (quaternion product with the
/// rotation of the mean rate over each step) and returns the largest angle to the truth's
/// attitude, rad, and its tolerance. In these scenarios the rate's direction in the sensor
/// frame is constant within each manoeuvre, so the only error is the trapezoid rule's on the
/// angle: at most `h^2 / 6 max|angular acceleration|` (see `trapezoid_errors`), times 2.
fn attitude_error(tr: &[Truth], rate_hz: f64) -> (f64, f64) {
    let h = 1.0 / rate_hz;
    let mut q = attitude(&tr[0]);
    let mut worst = 0.0f64;
    for k in 1..tr.len() {
        let w = 0.5
            * (Vector3::from(tr[k - 1].angular_rate_rps) + Vector3::from(tr[k].angular_rate_rps));
        q *= UnitQuaternion::from_scaled_axis(w * h);
        worst = worst.max(q.angle_to(&attitude(&tr[k])));
    }
    let rates: Vec<Vector3<f64>> = tr
        .iter()
        .map(|t| Vector3::from(t.angular_rate_rps))
        .collect();
    (
        worst,
        2.0 * h * h / 6.0 * max_rate_of_change(&rates, h) + 1e-12,
    )
}

#[test]
fn angular_rates_integrate_to_truth_attitudes() {
    let drive = Drive::new(&drive_params(180.0), 6).unwrap();
    let six = PoseSession::six_position(&PoseParams::new(2.0), 6).unwrap();
    let many = PoseSession::orientations(15, &PoseParams::new(1.0), 6).unwrap();
    for (name, tr) in [
        ("drive", truths(&drive, 100.0)),
        ("six-position", truths(&six, 100.0)),
        ("orientations", truths(&many, 100.0)),
    ] {
        let (err, tol) = attitude_error(&tr, 100.0);
        eprintln!("{name}: attitude error {err:e} rad, tolerance {tol:e}");
        assert!(err <= tol, "{name}: {err} > {tol}");
        // The scenario really rotates (its turns may cancel by the end, so the widest angle).
        let turned = tr
            .iter()
            .map(|t| attitude(&tr[0]).angle_to(&attitude(t)))
            .fold(0.0, f64::max);
        assert!(turned > 0.1, "{name} never turns");
    }
}

#[test]
fn rest_flags_match_zero_velocity_and_rate() {
    let params = drive_params(300.0);
    let drive = Drive::new(&params, 8).unwrap();
    let tr = truths(&drive, 50.0);
    let mut rest_runs: Vec<(f64, f64)> = Vec::new();
    for t in &tr {
        let speed = Vector3::from(t.velocity_mps).norm();
        let rate = Vector3::from(t.angular_rate_rps).norm();
        let time = t.t_ns as f64 * 1e-9;
        if t.at_rest {
            assert_eq!((speed, rate), (0.0, 0.0), "flagged at rest at {time} s");
            match rest_runs.last_mut() {
                Some(run) if (time - run.1 - 0.02).abs() < 1e-9 => run.1 = time,
                _ => rest_runs.push((time, time)),
            }
        } else {
            assert!(speed > 0.0 || rate > 0.0, "moving but still at {time} s");
        }
    }
    // Starts with the initial rest, ends at rest, and every rest between is 1-30 s long (to
    // within the 20 ms sampling).
    assert_eq!(rest_runs[0].0, 0.0);
    assert!(rest_runs[0].1 >= params.initial_rest_s - 0.02);
    assert!(tr.last().unwrap().at_rest);
    assert!(rest_runs.len() >= 5, "only {} rests", rest_runs.len());
    for run in &rest_runs[1..rest_runs.len() - 1] {
        let len = run.1 - run.0;
        assert!(
            (1.0 - 0.04..=30.0).contains(&len),
            "rest of {len} s at {} s",
            run.0
        );
    }
    // While moving the robot really drives: its speed reaches the cruise range.
    let top = tr
        .iter()
        .map(|t| Vector3::from(t.velocity_mps).norm())
        .fold(0.0, f64::max);
    assert!((0.2..=1.0).contains(&top) && top > 0.5, "top speed {top}");
}

#[test]
fn drive_specific_force_is_gravity_at_rest_and_follows_the_mounting() {
    let params = DriveParams {
        gravity_mps2: 9.797,
        ..drive_params(60.0)
    };
    let drive = Drive::new(&params, 2).unwrap();
    // At rest the sensor reads gravity's reaction along body z, expressed in the sensor frame.
    let t = drive.truth(1.0);
    assert!(t.at_rest);
    let want = params
        .mounting
        .inverse_transform_vector(&Vector3::new(0.0, 0.0, 9.797));
    assert!((Vector3::from(t.specific_force_mps2) - want).norm() < 1e-12);
    // The body stays level: the sensor's attitude is a heading rotation times the mounting.
    for k in 0..600 {
        let t = drive.truth(k as f64 * 0.1);
        let body = attitude(&t) * params.mounting.inverse();
        let z = body * Vector3::z();
        assert!((z - Vector3::z()).norm() < 1e-12);
        assert_eq!(t.position_m[2], 0.0);
    }
}

#[test]
fn six_position_poses_point_each_axis_up() {
    let params = PoseParams {
        gravity_mps2: 9.797,
        ..PoseParams::new(5.0)
    };
    let six = PoseSession::six_position(&params, 3).unwrap();
    // Thesis order: +z, -z, +y, -y, +x, -x up; the up axis reads +g.
    let g = 9.797;
    let ups = [
        [0.0, 0.0, g],
        [0.0, 0.0, -g],
        [0.0, g, 0.0],
        [0.0, -g, 0.0],
        [g, 0.0, 0.0],
        [-g, 0.0, 0.0],
    ];
    for (i, up) in ups.iter().enumerate() {
        let (start, end) = six.hold_interval_s(i);
        for t_s in [start, 0.5 * (start + end), end - 1e-6] {
            let t = six.truth(t_s);
            assert!(t.at_rest);
            assert_eq!(t.velocity_mps, [0.0; 3]);
            assert_eq!(t.position_m, [0.0; 3]);
            assert_eq!(t.angular_rate_rps, [0.0; 3]);
            for k in 0..3 {
                assert!(
                    (t.specific_force_mps2[k] - up[k]).abs() < 1e-12,
                    "pose {i} at {t_s}: {:?}",
                    t.specific_force_mps2
                );
            }
        }
    }
    // Rotations in between are not rests, and |f| = g throughout (rotation about the origin).
    for t in truths(&six, 20.0) {
        assert!((Vector3::from(t.specific_force_mps2).norm() - 9.797).abs() < 1e-12);
    }
    assert!(!six.truth(5.0 + 2.0).at_rest);
    assert_eq!(six.duration_s(), 6.0 * 5.0 + 5.0 * 4.0);
}

#[test]
fn placement_tilt_tilts_the_poses_by_the_configured_spread() {
    let params = PoseParams {
        placement_tilt_std_deg: 1.0,
        ..PoseParams::new(1.0)
    };
    // A +z-up placement is tilted from vertical by a normal draw (1 degree 1-sigma) about a
    // random horizontal axis, so over many seeds the tilt's rms is 1 degree.
    let n = 400;
    let sum_sq: f64 = (0..n)
        .map(|seed| {
            let six = PoseSession::six_position(&params, seed).unwrap();
            let f = Vector3::from(six.truth(0.0).specific_force_mps2);
            f.angle(&Vector3::z()).to_degrees().powi(2)
        })
        .sum();
    let rms = (sum_sq / n as f64).sqrt();
    // The mean of n chi-square(1) terms has relative std sqrt(2 / n); the rms half of that.
    assert!(
        (rms - 1.0).abs() < 4.0 * (0.5f64 / n as f64).sqrt(),
        "rms tilt {rms} deg"
    );
}

#[test]
fn orientations_are_well_spread() {
    for n in [9usize, 12, 24] {
        let s = PoseSession::orientations(n, &PoseParams::new(1.0), 4).unwrap();
        let ups: Vec<Vector3<f64>> = (0..n)
            .map(|i| {
                let t = s.truth(s.hold_interval_s(i).0);
                Vector3::from(t.specific_force_mps2).normalize()
            })
            .collect();
        // n points spread evenly over the sphere are about sqrt(4 pi / n) rad apart; require the
        // closest pair to be at least half of that.
        let ideal = (4.0 * std::f64::consts::PI / n as f64).sqrt();
        let mut closest = f64::MAX;
        for i in 0..n {
            for j in 0..i {
                closest = closest.min(ups[i].angle(&ups[j]));
            }
        }
        assert!(
            closest > 0.5 * ideal,
            "n = {n}: closest pair {closest} rad, ideal {ideal}"
        );
        // And they cover the sphere: their mean direction is near zero.
        let mean: Vector3<f64> = ups.iter().sum::<Vector3<f64>>() / n as f64;
        assert!(mean.norm() < 0.2, "n = {n}: mean up {mean:?}");
    }
}

#[test]
fn vibration_is_zero_at_rest_and_scales_with_wheel_speed() {
    let drive = Drive::new(&drive_params(240.0), 12).unwrap();
    let level = VibrationModel::moderate(1.0);
    let mut sim = SimSensor::new(drive.clone(), &SensorModel::ideal(), &level, 12).unwrap();
    let rate = 200.0;
    let n = (240.0 * rate) as usize;
    let (mut acc_sq, mut acc_want, mut gyr_sq, mut gyr_want) = (0.0, 0.0, 0.0, 0.0);
    for k in 0..n {
        let t_s = k as f64 / rate;
        let (a, truth) = sim.sample_with_truth(t_s, rate);
        let speed = drive.wheel_speed_mps(t_s);
        for i in 0..3 {
            let va = a.accel_g[i] * G_MPS2 - truth.specific_force_mps2[i];
            let vg = a.gyro_dps[i] - truth.angular_rate_rps[i].to_degrees();
            if truth.at_rest {
                assert!(
                    va.abs() < 1e-12 && vg.abs() < 1e-12,
                    "vibration at rest at {t_s} s"
                );
            }
            acc_sq += va * va;
            gyr_sq += vg * vg;
            acc_want += (level.accel_rms_mps2 * speed).powi(2);
            gyr_want += (level.gyro_rms_dps * speed).powi(2);
        }
    }
    // The mean square matches (level x speed)^2. Sampling error: the chassis resonance (40% of
    // the power) decorrelates in 1 / (damping 2 pi 25 Hz) = 64 ms, giving over 100 s of motion
    // about 800 independent values per axis, 2400 in all: relative std of its mean square
    // sqrt(2 / 2400) = 3%, 1.2% of the total; the sinusoids average over hundreds of cycles.
    // A 5% bound is 4 sigma.
    for (name, got, want) in [("accel", acc_sq, acc_want), ("gyro", gyr_sq, gyr_want)] {
        assert!(
            (got / want - 1.0).abs() < 0.05,
            "{name}: mean square ratio {}",
            got / want
        );
    }
    // Level zero: no vibration at all.
    let mut quiet = SimSensor::new(
        drive.clone(),
        &SensorModel::ideal(),
        &VibrationModel::moderate(0.0),
        12,
    )
    .unwrap();
    for k in 0..2000 {
        let (a, truth) = quiet.sample_with_truth(20.0 + k as f64 * 0.05, rate);
        for i in 0..3 {
            assert!((a.accel_g[i] * G_MPS2 - truth.specific_force_mps2[i]).abs() < 1e-12);
        }
    }
}

#[test]
fn the_vibration_floor_holds_at_any_wheel_speed_and_not_at_rest() {
    // Only the floor: 0.3 m/s^2 and 1 deg/s RMS per axis whenever the wheels turn.
    let drive = Drive::new(&drive_params(240.0), 12).unwrap();
    let level = VibrationModel::moderate(0.0).with_floor(0.3, 1.0);
    let mut sim = SimSensor::new(drive.clone(), &SensorModel::ideal(), &level, 12).unwrap();
    let rate = 200.0;
    let (mut acc_sq, mut gyr_sq, mut turning, mut slow) = (0.0, 0.0, 0usize, 0usize);
    for k in 0..(240.0 * rate) as usize {
        let t_s = k as f64 / rate;
        let (a, truth) = sim.sample_with_truth(t_s, rate);
        let speed = drive.wheel_speed_mps(t_s);
        for i in 0..3 {
            let va = a.accel_g[i] * G_MPS2 - truth.specific_force_mps2[i];
            let vg = a.gyro_dps[i] - truth.angular_rate_rps[i].to_degrees();
            if speed == 0.0 {
                assert!(
                    va.abs() < 1e-12 && vg.abs() < 1e-12,
                    "vibration with the wheels still at {t_s} s"
                );
            } else {
                acc_sq += va * va;
                gyr_sq += vg * vg;
            }
        }
        turning += usize::from(speed != 0.0);
        slow += usize::from(speed != 0.0 && speed < 0.1);
    }
    assert!(slow > 0, "the drive never turns its wheels slowly");
    // The chassis resonance alone: about 800 independent values per axis over 100 s of
    // motion (see above), 3% relative std of the mean square over three axes; 10% is 3 sigma.
    let n = 3.0 * turning as f64;
    for (name, got, want) in [("accel", acc_sq / n, 0.09), ("gyro", gyr_sq / n, 1.0)] {
        assert!(
            (got / want - 1.0).abs() < 0.1,
            "{name}: mean square {got} while the wheels turn, floor^2 {want}"
        );
    }
}

#[test]
fn scenarios_are_deterministic_in_the_seed() {
    let a = Drive::new(&drive_params(120.0), 77).unwrap();
    let b = Drive::new(&drive_params(120.0), 77).unwrap();
    let c = Drive::new(&drive_params(120.0), 78).unwrap();
    assert_eq!(a.segments(), b.segments());
    assert_ne!(a.segments(), c.segments());
    let model = SensorModel::mpu9250_datasheet();
    let vib = VibrationModel::moderate(1.0);
    let run = |d: &Drive, seed| {
        let mut s = SimSensor::new(d.clone(), &model, &vib, seed).unwrap();
        (0..3000)
            .map(|k| s.sample_with_truth(k as f64 * 0.01, 100.0))
            .collect::<Vec<_>>()
    };
    assert_eq!(run(&a, 1), run(&b, 1));
    assert_ne!(run(&a, 1), run(&a, 2));
    let p = PoseSession::orientations(10, &PoseParams::new(1.0), 5).unwrap();
    let q = PoseSession::orientations(10, &PoseParams::new(1.0), 5).unwrap();
    assert_eq!(p.poses(), q.poses());
}

#[test]
fn invalid_scenario_parameters_name_their_field() {
    let e = Drive::new(
        &DriveParams {
            rest_s: [5.0, 1.0],
            ..DriveParams::new(60.0)
        },
        0,
    )
    .unwrap_err();
    assert_eq!(e.field, "rest_s");
    let e = Drive::new(
        &DriveParams {
            initial_rest_s: 100.0,
            ..DriveParams::new(60.0)
        },
        0,
    )
    .unwrap_err();
    assert_eq!(e.field, "initial_rest_s");
    let e = PoseSession::orientations(0, &PoseParams::new(1.0), 0).unwrap_err();
    assert_eq!(e.field, "n");
    let e = PoseSession::six_position(
        &PoseParams {
            rotate_s: 0.0,
            ..PoseParams::new(1.0)
        },
        0,
    )
    .unwrap_err();
    assert!(e.to_string().contains("rotate_s"), "{e}");
    let e = PoseSession::static_pose(UnitQuaternion::identity(), -1.0, 9.8).unwrap_err();
    assert_eq!(e.field, "duration_s");
}

#[test]
fn static_pose_holds_still() {
    let tilt = UnitQuaternion::from_euler_angles(0.02, -0.01, 1.0);
    let s = PoseSession::static_pose(tilt, 3600.0, 9.81).unwrap();
    let want = tilt.inverse_transform_vector(&Vector3::new(0.0, 0.0, 9.81));
    for t_s in [0.0, 1000.0, 3599.9, 5000.0] {
        let t = s.truth(t_s);
        assert!(t.at_rest);
        assert!((Vector3::from(t.specific_force_mps2) - want).norm() < 1e-12);
        assert_eq!(t.t_ns, (t_s * 1e9).round() as u64);
    }
}

#[test]
fn slopes_and_arms_are_consistent_truths() {
    // A drive whose stops are on grades of up to 8 deg, and an arm: accelerations integrate
    // to the truth's velocity and position, rates to its attitude, and the slope drive climbs
    // and rests pitched.
    let slopes = Drive::new(
        &DriveParams {
            max_slope_deg: 8.0,
            ..drive_params(180.0)
        },
        5,
    )
    .unwrap();
    let arm = Arm::new(&ArmParams::new(10), 5).unwrap();
    let g = slopes.params().gravity_mps2;
    let (e, tol) = trapezoid_errors(&slopes, g, 200.0);
    assert!(e[0] <= tol[0] && e[1] <= tol[1], "slopes: {e:?} > {tol:?}");
    let (e, tol) = trapezoid_errors(&arm, g, 200.0);
    assert!(e[0] <= tol[0] && e[1] <= tol[1], "arm: {e:?} > {tol:?}");
    for (name, tr) in [
        ("slopes", truths(&slopes, 100.0)),
        ("arm", truths(&arm, 100.0)),
    ] {
        let (err, tol) = attitude_error(&tr, 100.0);
        assert!(err <= tol, "{name}: attitude {err} > {tol}");
    }
    let tr = truths(&slopes, 10.0);
    let climbed = tr.iter().map(|t| t.position_m[2].abs()).fold(0.0, f64::max);
    assert!(
        climbed > 0.5,
        "the slope drive stays within {climbed} m of its start's height"
    );
    let tilted_rest = tr.iter().filter(|t| t.at_rest).any(|t| {
        let f = Vector3::from(t.specific_force_mps2);
        f.x.abs() > 0.01 * f.z
    });
    assert!(tilted_rest, "no rest on a slope");
}
