//! Unit tests of the filter.

use super::*;
use approx::assert_relative_eq;

const G: f64 = 9.81;

/// The MPU-9250's noise densities (no vibration), for the filter's tests and its users'.
pub(crate) fn noise() -> NoiseModel {
    NoiseModel {
        accel_noise_density: 300e-6 * G,
        gyro_noise_density: 0.01_f64.to_radians(),
        accel_bias_random_walk: 1e-5,
        gyro_bias_random_walk: 1e-6,
        vibration_accel_density_per_mps: 0.0,
        vibration_gyro_density_per_mps: 0.0,
    }
}

/// The filter aligned on a rest whose mean specific force is `g_s` (no gyro bias measured),
/// with 5 mm/s^2 of accelerometer and 1e-4 rad/s of gyro bias 1-sigma.
fn level_alignment(g_s: Vector3<f64>) -> (Nominal, Cov) {
    align(
        g_s,
        Vector3::zeros(),
        G,
        Vector3::repeat(0.005),
        Vector3::repeat(1e-4),
    )
}

/// A dense, well-conditioned covariance with every entry non-zero.
fn full_cov() -> Cov {
    let a = Cov::from_fn(|i, j| ((7 * i + 3 * j) as f64).sin());
    a * a.transpose() * 1e-3 + Cov::identity() * 1e-4
}

/// A filter whose every state is non-zero, on the dense covariance [`full_cov`], its first
/// sample reading near gravity with the rate `w` (rad/s).
fn busy_filter(w: Vector3<f64>) -> Eskf {
    let x = Nominal {
        p: Vector3::new(1.0, 2.0, 3.0),
        v: Vector3::new(0.1, -0.2, 0.05),
        q: UnitQuaternion::from_scaled_axis(Vector3::new(0.1, 0.2, 0.3)),
        b_a: Vector3::new(0.01, 0.02, -0.01),
        b_g: Vector3::new(1e-3, -2e-3, 3e-3),
        k: 0.01,
        m: 0.0,
    };
    let first = Imu {
        f: Vector3::new(0.1, 0.2, 9.8),
        w,
    };
    Eskf::new(x, full_cov(), G, noise(), first)
}

#[test]
fn selected_update_is_the_general_update() {
    let mut a = busy_filter(Vector3::new(0.01, 0.02, -0.03));
    a.sens = Sensitivity::from_fn(|j, i| ((i * 5 + j) as f64).cos());
    let mut b = a.clone();
    for c in [V, BG] {
        let residual = Vector3::new(0.03, -0.01, 0.02);
        let mut h = SMatrix::<f64, 3, N>::zeros();
        h.fixed_view_mut::<3, 3>(0, c)
            .copy_from(&Matrix3::identity());
        a.update(
            &h,
            residual,
            &(Matrix3::identity() * 4e-6),
            Heading::Corrected,
        );
        b.update_selected(c, residual, 4e-6);
    }
    assert_relative_eq!(a.cov, b.cov, epsilon = 1e-15);
    assert_relative_eq!(a.sens, b.sens, epsilon = 1e-12);
    assert_relative_eq!(a.x.p, b.x.p, epsilon = 1e-12);
    assert_relative_eq!(a.x.q, b.x.q, epsilon = 1e-12);
    assert_relative_eq!(a.x.b_g, b.x.b_g, epsilon = 1e-15);
}

/// A position reset takes the given position and per-axis variance, uncorrelated with every
/// other state, and leaves the other states' means and covariance entries as they were.
#[test]
fn a_position_reset_decorrelates_the_position() {
    let mut kf = busy_filter(Vector3::zeros());
    let (x, before) = (kf.x, kf.cov);
    let (p, var) = (
        Vector3::new(-40.0, 7.0, 0.5),
        Vector3::new(100.0, 121.0, 4.0),
    );
    kf.reset_position(p, var);
    assert_eq!(kf.x.p, p);
    assert_eq!(
        (kf.x.v, kf.x.q, kf.x.b_a, kf.x.b_g),
        (x.v, x.q, x.b_a, x.b_g)
    );
    for i in 0..N {
        for j in 0..N {
            let expected = match (P..P + 3).contains(&i) || (P..P + 3).contains(&j) {
                true if i == j => var[i - P],
                true => 0.0,
                false => before[(i, j)],
            };
            assert_eq!(kf.cov[(i, j)], expected, "({i}, {j})");
        }
    }
}

/// The scale measurement through the one update is the scalar Kalman update it replaced
/// (gain `P e / (P_kk + R)`), to rounding.
#[test]
fn scale_measurement_is_the_scalar_update() {
    let x = Nominal {
        p: Vector3::zeros(),
        v: Vector3::new(1.0, 0.2, 0.0),
        q: UnitQuaternion::identity(),
        b_a: Vector3::zeros(),
        b_g: Vector3::zeros(),
        k: 0.05,
        m: 0.0,
    };
    let first = Imu {
        f: Vector3::new(0.0, 0.0, 9.8),
        w: Vector3::zeros(),
    };
    let mut a = Eskf::new(x, full_cov(), G, noise(), first);
    let p = a.cov;
    let s = p[(KS, KS)] + 1e-4;
    let gain: VecN = p.column(KS) / s;
    a.measure_scale(0.3, 1e-4);
    assert_relative_eq!(a.x.k, 0.05 + gain[KS] * 0.25, epsilon = 1e-12);
    assert_relative_eq!(a.x.v, x.v + gain.fixed_rows::<3>(V) * 0.25, epsilon = 1e-12);
    let expected = p - gain * p.column(KS).transpose();
    assert_relative_eq!(a.cov, expected, epsilon = 1e-12);
}

/// A speed update with the heading kept moves neither the heading nor the gyro bias about up,
/// moves the other states, and leaves a symmetric covariance whose heading variance is the
/// prior's.
#[test]
fn a_kept_heading_stays_put() {
    let tilt = UnitQuaternion::from_scaled_axis(Vector3::new(0.2, -0.1, 0.7));
    let x = Nominal {
        p: Vector3::zeros(),
        v: Vector3::new(1.5, 0.4, 0.0),
        q: tilt,
        b_a: Vector3::zeros(),
        b_g: Vector3::zeros(),
        k: 0.0,
        m: 0.0,
    };
    let first = Imu {
        f: tilt.inverse() * Vector3::new(0.0, 0.0, 9.8),
        w: Vector3::zeros(),
    };
    let mut a = Eskf::new(x, full_cov(), G, noise(), first);
    let up = a.x.q.inverse_transform_vector(&Vector3::z());
    let heading_var = |f: &Eskf| (up.transpose() * f.cov.fixed_view::<3, 3>(TH, TH) * up)[0];
    let before = heading_var(&a);
    let nis = a.body_velocity_update_with(
        &Matrix3::identity(),
        Vector3::new(0.3, -0.2, 0.05),
        Vector3::repeat(0.05),
        Heading::Kept,
    );
    assert!(nis.is_some());
    let turn = tilt.inverse() * a.x.q;
    assert!(turn.scaled_axis().dot(&up).abs() < 1e-12, "{turn:?}");
    assert!(a.x.b_g.dot(&up).abs() < 1e-12, "{}", a.x.b_g);
    assert!((a.x.v - x.v).norm() > 1e-3);
    assert_relative_eq!(a.cov, a.cov.transpose(), epsilon = 1e-15);
    assert_relative_eq!(heading_var(&a), before, max_relative = 1e-9);
}

#[test]
fn alignment_levels_a_tilted_sensor() {
    // Sensor tilted 10 deg about x: gravity reaction seen in the sensor frame.
    let tilt = UnitQuaternion::from_scaled_axis(Vector3::x() * 10f64.to_radians());
    let f_s = tilt.inverse() * Vector3::new(0.0, 0.0, G + 0.05);
    let (x, cov) = align(
        f_s,
        Vector3::new(0.01, 0.0, 0.0),
        G,
        Vector3::repeat(0.005),
        Vector3::repeat(1e-4),
    );
    let up = x.q * f_s;
    assert_relative_eq!(up.normalize(), Vector3::z(), epsilon = 1e-12);
    // The 0.05 m/s^2 excess is vertical bias, in the sensor frame along the measured up.
    assert_relative_eq!(x.q * x.b_a, Vector3::new(0.0, 0.0, 0.05), epsilon = 1e-12);
    assert_eq!(x.b_g, Vector3::new(0.01, 0.0, 0.0));
    // Tilt variance is bias variance / g^2 (5 mm/s^2 -> 0.51 mrad).
    assert_relative_eq!(cov[(TH, TH)].sqrt(), 0.005 / G, max_relative = 0.05);
}

#[test]
fn static_integration_with_a_bias_grows_quadratically() {
    // Level sensor with an (unknown to the filter) 0.01 m/s^2 x bias: after t seconds of
    // pure prediction the x position error is b t^2 / 2, as the thesis's error model says.
    let g_s = Vector3::new(0.0, 0.0, G);
    let bias = Vector3::new(0.01, 0.0, 0.0);
    let m = Imu {
        f: g_s + bias,
        w: Vector3::zeros(),
    };
    let (x, cov) = level_alignment(g_s);
    let mut kf = Eskf::new(x, cov, G, noise(), m);
    let dt = 0.001;
    for _ in 0..10_000 {
        kf.predict(m, dt);
    }
    assert_relative_eq!(kf.x.p.x, 0.5 * 0.01 * 100.0, max_relative = 1e-9);
    assert_relative_eq!(kf.x.v.x, 0.01 * 10.0, max_relative = 1e-9);
    // The covariance knows about it: the bias-induced 1-sigma at 10 s is about
    // sigma_b * t^2 / 2 = 0.25 m; tilt-bias correlation cancels part of it.
    assert!(kf.position_sigma().x > 0.0);
}

#[test]
fn zupt_removes_the_velocity_error() {
    let g_s = Vector3::new(0.0, 0.0, G);
    let m = Imu {
        f: g_s + Vector3::new(0.02, -0.01, 0.0),
        w: Vector3::zeros(),
    };
    let (x, cov) = level_alignment(g_s);
    let mut kf = Eskf::new(x, cov, G, noise(), m);
    for _ in 0..1000 {
        kf.predict(m, 0.001);
    }
    assert!(kf.x.v.norm() > 0.01);
    for _ in 0..200 {
        kf.predict(m, 0.001);
        kf.zero_velocity(1e-3);
    }
    assert!(kf.x.v.norm() < 1e-3, "v = {}", kf.x.v);
}

#[test]
fn gyro_integration_follows_a_constant_rate() {
    let g_s = Vector3::new(0.0, 0.0, G);
    let rate = Vector3::new(0.0, 0.0, 0.5);
    let m = Imu { f: g_s, w: rate };
    let (x, cov) = level_alignment(g_s);
    let mut kf = Eskf::new(x, cov, G, noise(), m);
    for _ in 0..2000 {
        kf.predict(m, 0.001);
    }
    let expected = UnitQuaternion::from_scaled_axis(rate * 2.0);
    assert_relative_eq!(kf.x.q.angle_to(&expected), 0.0, epsilon = 1e-9);
    // Rotating about the vertical does not move a level sensor.
    assert!(kf.x.p.norm() < 1e-9);
}

#[test]
fn vibration_noise_grows_with_speed() {
    // The transition does not depend on the velocity, so two filters that differ only in
    // speed differ after one step by exactly the speed-dependent process noise.
    let g_s = Vector3::new(0.0, 0.0, G);
    let m = Imu {
        f: g_s,
        w: Vector3::zeros(),
    };
    let (x, cov) = level_alignment(g_s);
    let (k_a, k_g) = (4e-3, 4e-4);
    let n = NoiseModel {
        vibration_accel_density_per_mps: k_a,
        vibration_gyro_density_per_mps: k_g,
        ..noise()
    };
    let dt = 0.01;
    let step = |speed: f64| {
        let moving = Nominal {
            v: Vector3::new(speed, 0.0, 0.0),
            ..x
        };
        let mut kf = Eskf::new(moving, cov, G, n, m);
        kf.predict(m, dt);
        kf.cov
    };
    let (slow, fast) = (step(0.0), step(2.0));
    for i in 0..3 {
        let dv = fast[(V + i, V + i)] - slow[(V + i, V + i)];
        let dth = fast[(TH + i, TH + i)] - slow[(TH + i, TH + i)];
        assert_relative_eq!(dv, (k_a * 2.0).powi(2) * dt, max_relative = 1e-9);
        assert_relative_eq!(dth, (k_g * 2.0).powi(2) * dt, max_relative = 1e-9);
    }
}

/// The consider sensitivity against an independent computation: the same trajectory
/// integrated twice by the nonlinear filter, once from exact readings and once with one
/// reading scaled by `1 + eps`. Their position difference is the error that entry causes,
/// and the first-order sensitivity must predict it (dx = true - nominal = M e).
#[test]
fn consider_sensitivity_predicts_a_scale_errors_effect() {
    let g_s = Vector3::new(0.0, 0.0, G);
    let eps = 1e-3;
    let dt = 0.005;
    // 2 s of yawing at 0.8 rad/s while the specific force pushes 1 m/s^2 along sensor x.
    let reading = |k: usize| Imu {
        f: g_s + Vector3::new(if k < 400 { 1.0 } else { 0.0 }, 0.0, 0.0),
        w: Vector3::new(0.0, 0.0, if k < 400 { 0.8 } else { 0.0 }),
    };
    let run = |scale: &dyn Fn(Imu) -> Imu| {
        let (x, cov) = level_alignment(g_s);
        let model = ConsiderModel {
            gyro: Matrix3::repeat(0.01),
            accel: Matrix3::repeat(0.01),
        };
        let mut kf = Eskf::new(x, cov, G, noise(), scale(reading(0))).with_consider(model, g_s);
        for k in 1..600 {
            kf.predict(scale(reading(k)), dt);
        }
        kf
    };
    let exact = run(&|m| m);
    // Gyro z scale (entry (2, 2), consider index 8).
    let gyro = run(&|m: Imu| Imu {
        w: m.w * (1.0 + eps),
        ..m
    });
    let predicted = exact.sens.fixed_view::<1, 3>(8, P).transpose() * eps;
    assert_relative_eq!(exact.x.p - gyro.x.p, predicted, max_relative = 0.02);
    assert!(predicted.norm() > 1e-3, "{predicted}");
    // Accelerometer x scale (entry (0, 0), consider index 9): only the change of specific
    // force since alignment counts, and gravity lies along z.
    let accel = run(&|m: Imu| Imu {
        f: Vector3::new(m.f.x * (1.0 + eps), m.f.y, m.f.z),
        ..m
    });
    let predicted = exact.sens.fixed_view::<1, 3>(9, P).transpose() * eps;
    assert_relative_eq!(exact.x.p - accel.x.p, predicted, max_relative = 0.02);
    assert!(predicted.norm() > 1e-3, "{predicted}");
    // The reported sigma holds the consider share: at 1 % per entry, well above eps's.
    assert!(exact.position_sigma().x > 10.0 * predicted.x.abs());
}

/// The alignment's tilt/bias correlation is what makes a horizontal bias observable after a
/// heading change: a level sensor with an unknown bias, aligned, spun 180 deg in place and
/// held at rest, must end with the bias estimated (which it cannot be without the turn).
#[test]
fn heading_change_reveals_the_horizontal_bias() {
    let bias = Vector3::new(0.03, -0.02, 0.0);
    let up_s = Vector3::new(0.0, 0.0, G);
    let dt = 0.002;
    let run = |turn: bool| {
        let (x, cov) = align(
            up_s + bias,
            Vector3::zeros(),
            G,
            Vector3::repeat(0.05),
            Vector3::repeat(1e-4),
        );
        let first = Imu {
            f: up_s + bias,
            w: Vector3::zeros(),
        };
        let mut kf = Eskf::new(x, cov, G, noise(), first);
        let rate = if turn {
            std::f64::consts::PI / 2.0
        } else {
            0.0
        };
        let mut heading = 0.0;
        for k in 0..3000 {
            // 2 s of spinning (when turning), then rest; always zero velocity.
            let w = if k < 1000 { rate } else { 0.0 };
            heading += w * dt;
            let r = UnitQuaternion::from_scaled_axis(Vector3::z() * heading);
            let m = Imu {
                f: r.inverse() * up_s + bias,
                w: Vector3::new(0.0, 0.0, w),
            };
            kf.predict(m, dt);
            kf.zero_velocity(1e-3);
        }
        kf
    };
    let turned = run(true);
    assert!(
        (turned.x.b_a - bias).norm() < 2e-3,
        "estimated {} vs {bias}",
        turned.x.b_a
    );
    let still = run(false);
    assert!(
        (still.x.b_a - bias).norm() > 0.02,
        "without a turn the bias stays hidden"
    );
}
