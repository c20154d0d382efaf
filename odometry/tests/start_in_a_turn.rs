//! A sensor that turns steadily about gravity from its first sample (a robot turning on the
//! spot at 40 deg/s for 8 s, then standing), through the real `mems-odometry offline` binary:
//! the calibration stage's learner refuses the turn (its mean rate lies beyond any MEMS
//! gyroscope's zero-rate offset, `calibrate::zero_state::learn::MAX_GYRO_OFFSET_DPS`) and
//! the filter aligns on the rest after it. With the limit widened past the turn
//! (`--max-gyro-offset-dps 45`), the turn is learned as gyroscope bias and the filter aligns
//! in it.

mod common;

use std::fmt::Write as _;
use std::path::Path;

use common::{offline_json, scratch};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// Length of the turn at the start, s.
const TURN_S: f64 = 8.0;

/// Writes the session as a canonical CSV (g, deg/s) at 100 Hz: level, 40 deg/s about up for
/// [`TURN_S`], then 12 s standing; gyro bias (0.3, -0.2, -0.4) deg/s, white noise 3 mg and
/// 0.05 deg/s per sample.
fn write_session(path: &Path) {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let (accel, gyro) = (
        Normal::new(0.0, 0.003).unwrap(),
        Normal::new(0.0, 0.05).unwrap(),
    );
    let mut csv = String::from("t_s,ax_g,ay_g,az_g,gx_dps,gy_dps,gz_dps\n");
    for k in 0..2000 {
        let t = f64::from(k) / 100.0;
        let turn = if t < TURN_S { 40.0 } else { 0.0 };
        let a: [f64; 3] = std::array::from_fn(|i| [0.0, 0.0, 1.0][i] + accel.sample(&mut rng));
        let w: [f64; 3] =
            std::array::from_fn(|i| [0.3, -0.2, turn - 0.4][i] + gyro.sample(&mut rng));
        writeln!(
            csv,
            "{t:.6},{:.6},{:.6},{:.6},{:.4},{:.4},{:.4}",
            a[0], a[1], a[2], w[0], w[1], w[2]
        )
        .unwrap();
    }
    std::fs::write(path, csv).unwrap();
}

#[test]
fn a_turn_from_the_first_sample_is_not_learned_as_gyro_bias() {
    let dir = scratch("start-in-a-turn");
    let path = dir.join("turn.csv");
    write_session(&path);
    let bin = env!("CARGO_BIN_EXE_mems-odometry");
    let run = |args: &[&str]| {
        let v = offline_json(bin, &path, args);
        let aligned = v["aligned_at_s"].as_f64().unwrap();
        let p = &v["end_displacement_m"];
        let horizontal = p[0].as_f64().unwrap().hypot(p[1].as_f64().unwrap());
        eprintln!("{args:?}: aligned at {aligned:.2} s, ends {horizontal:.3} m off");
        (aligned, horizontal)
    };
    let (aligned, horizontal) = run(&[]);
    let (widened, _) = run(&["--max-gyro-offset-dps", "45"]);
    std::fs::remove_dir_all(&dir).unwrap();
    // Aligned on the rest, it stays where it stood.
    assert!(
        aligned > TURN_S && horizontal < 0.01,
        "{aligned} {horizontal}"
    );
    // The turn learned as bias: the filter took the turn for rest.
    assert!(widened < TURN_S, "{widened}");
}
