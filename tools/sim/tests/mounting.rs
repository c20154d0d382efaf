//! The mounting effects of `mems_sim::mounting` through `SimSensor`: an ideal sensor (no
//! errors, no noise, no filter) on an arm run reads, with a lever arm, the reference point's
//! specific force plus `alpha x r + omega x (omega x r)`, and with an accelerometer lag the
//! specific force of that much earlier, its gyro unchanged.

use mems_sim::SimSensor;
use mems_sim::model::{G_MPS2, SensorModel};
use mems_sim::mounting::Mounting;
use mems_sim::scenario::{Arm, ArmParams, Scenario};
use mems_sim::vibration::VibrationModel;
use nalgebra::Vector3;

const RATE_HZ: f64 = 200.0;

fn sensor(mounting: Mounting) -> SimSensor<Arm> {
    let arm = Arm::new(&ArmParams::new(6), 5).unwrap();
    let mut s = SimSensor::new(
        arm,
        &SensorModel::ideal(),
        &VibrationModel::moderate(0.0),
        1,
    )
    .unwrap();
    s.set_mounting(mounting);
    s
}

#[test]
fn a_lever_arm_adds_the_rigid_body_terms_and_leaves_the_rate() {
    let r = Vector3::new(0.3, -0.2, 0.1);
    let (mut plain, mut off) = (
        sensor(Mounting::default()),
        sensor(Mounting {
            lever_arm_m: r.into(),
            ..Mounting::default()
        }),
    );
    let duration = plain.scenario().duration_s();
    let mut largest: f64 = 0.0;
    for k in 1..(duration * RATE_HZ) as usize {
        let t = k as f64 / RATE_HZ;
        let ((a, truth), (b, _)) = (
            plain.sample_with_truth(t, RATE_HZ),
            off.sample_with_truth(t, RATE_HZ),
        );
        assert_eq!(a.gyro_dps, b.gyro_dps, "t {t}");
        let w = Vector3::from(truth.angular_rate_rps);
        let h = 1e-4;
        let rate = |t: f64| Vector3::from(plain.scenario().truth(t).angular_rate_rps);
        let alpha = (rate(t + h) - rate(t - h)) / (2.0 * h);
        let expected = alpha.cross(&r) + w.cross(&w.cross(&r));
        let got = (Vector3::from(b.accel_g) - Vector3::from(a.accel_g)) * G_MPS2;
        assert!(
            (got - expected).norm() < 1e-3 * (1.0 + expected.norm()),
            "t {t}: {got} against {expected}"
        );
        largest = largest.max(expected.norm());
    }
    // The run turns fast enough for the terms to matter.
    assert!(largest > 0.5, "largest lever-arm term {largest} m/s^2");
}

#[test]
fn an_accelerometer_lag_reads_the_earlier_force_and_the_same_rate() {
    let lag = 0.02;
    let (mut plain, mut late) = (
        sensor(Mounting::default()),
        sensor(Mounting {
            accel_lag_s: lag,
            ..Mounting::default()
        }),
    );
    let duration = plain.scenario().duration_s();
    for k in 10..(duration * RATE_HZ) as usize {
        let t = k as f64 / RATE_HZ;
        let (a, _) = plain.sample_with_truth(t, RATE_HZ);
        let (b, _) = late.sample_with_truth(t, RATE_HZ);
        assert_eq!(a.gyro_dps, b.gyro_dps, "t {t}");
        let earlier = plain.scenario().truth(t - lag).specific_force_mps2;
        for (i, (read, want)) in b.accel_g.iter().zip(earlier).enumerate() {
            assert!(
                (read * G_MPS2 - want).abs() < 1e-9,
                "t {t} axis {i}: {} against {want}",
                read * G_MPS2
            );
        }
    }
}

#[test]
fn mountings_out_of_bounds_are_refused() {
    let bad = [
        Mounting {
            accel_lag_s: f64::NAN,
            ..Mounting::default()
        },
        Mounting {
            accel_lag_s: 0.6,
            ..Mounting::default()
        },
        Mounting {
            lever_arm_m: [0.0, 11.0, 0.0],
            ..Mounting::default()
        },
    ];
    for m in bad {
        assert!(m.validate().is_err(), "{m:?}");
    }
    assert!(Mounting::default().validate().is_ok());
}
