//! A wheeled robot with encoder hints whose gyro bias about up moves by 0.5 deg/s in mid-drive
//! (what a vibration or a temperature change does to a MEMS gyro, and what a bias learned while
//! the robot moved is off by), through the real `mems-odometry offline` binary: at its next
//! stops the stationary hints say the wheels stand still, the gyro's mean reading there lies
//! many 1-sigmas from the filter's bias, and the filter takes it as a refuted bias
//! (`hints.gyro_bias_refuted`) instead of refusing every zero-rate update as a spin. The run
//! ends less than half as far off as the shift alone would move it with the heading turning
//! at 0.5 deg/s for the rest of the drive (computed here from the truth track).

mod common;

use common::{Case, drive_with_encoder_hints, offline_drive_with_hints};

/// The bias shift about the sensor's z axis (up: the IMU lies level on the robot), deg/s.
const SHIFT_DPS: f64 = 0.5;
/// When it happens, s after the first sample.
const SHIFT_AT_S: f64 = 100.0;

#[test]
fn a_stop_the_wheels_report_refutes_a_gyro_bias_that_moved() {
    let case = Case {
        duration_s: 240.0,
        rate_hz: 100.0,
        turns: true,
        ..Case::straight()
    };
    let (mut raw, hints) = drive_with_encoder_hints(&case, 11);
    let t0 = raw[0].0.stamps.sample_ns;
    // Counts per deg/s, from the samples themselves (the sensor's full-scale range).
    let lsb = raw
        .iter()
        .find(|(r, _)| r.gyro_dps[2].abs() > 5.0)
        .map(|(r, _)| f64::from(r.gyro_counts[2]) / r.gyro_dps[2])
        .unwrap();
    for (r, _) in raw.iter_mut() {
        if (r.stamps.sample_ns - t0) as f64 * 1e-9 >= SHIFT_AT_S {
            r.gyro_dps[2] += SHIFT_DPS;
            r.gyro_counts[2] = (f64::from(r.gyro_counts[2]) + SHIFT_DPS * lsb).round() as i16;
        }
    }
    // What the shift alone would do to the position with nothing to correct the heading:
    // each horizontal step after it turned by the heading error accumulated by then.
    let unchecked = {
        let (mut ex, mut ey) = (0.0, 0.0);
        for w in raw.windows(2) {
            let (a, b) = (&w[0].1, &w[1].1);
            let t = (b.t_ns - t0) as f64 * 1e-9;
            let turn = (SHIFT_DPS * (t - SHIFT_AT_S).max(0.0)).to_radians();
            let (dx, dy) = (
                b.position_m[0] - a.position_m[0],
                b.position_m[1] - a.position_m[1],
            );
            ex += (turn.cos() - 1.0) * dx - turn.sin() * dy;
            ey += turn.sin() * dx + (turn.cos() - 1.0) * dy;
        }
        f64::hypot(ex, ey)
    };
    let v = offline_drive_with_hints(
        env!("CARGO_BIN_EXE_mems-odometry"),
        "hint-gyro-bias",
        &raw,
        hints,
        &["--mount", "0,0,0"],
    );
    let refuted = v["hints"]["gyro_bias_refuted"].as_u64().unwrap();
    let e = |i: usize| v["truth_error_m"][i].as_f64().unwrap();
    let s = |i: usize| v["sigma_m"][i].as_f64().unwrap();
    let error = e(0).hypot(e(1));
    let r68 = 1.515 * ((s(0).powi(2) + s(1).powi(2)) / 2.0).sqrt();
    let distance = v["truth_distance_m"].as_f64().unwrap();
    let drift_deg = SHIFT_DPS * (case.duration_s - SHIFT_AT_S);
    eprintln!(
        "refuted {refuted}, end error {error:.3} m ({:.2} % of {distance:.1} m), r68 {r68:.3} m; \
         unchecked, the heading would drift {drift_deg:.0} deg by the end and that alone \
         move the end by {unchecked:.3} m",
        100.0 * error / distance
    );
    assert!(refuted >= 1, "{v}");
    assert!(error < 0.5 * unchecked, "{v}");
}
