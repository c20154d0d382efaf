//! A wheeled robot whose recording starts in the middle of a turn, through the real binaries:
//! `mems-sim drive --start-at turn` (no rest before the first sample: the robot turns at the
//! fastest rate of its first motion that turns, 30-120 degree turns at up to 45 deg/s, with
//! encoder hints) and `mems-odometry offline --json` with no flags.
//!
//! The calibration stage takes its start-up interval for a rest by assumption. A mean rate of
//! tens of deg/s there is no MEMS part's bias (the MPU-9250's datasheet zero-rate offset is
//! +-5 deg/s, `calibrate::stage::ZERO_RATE_OFFSET_DPS`), so it must not be learned. The
//! filter's gyro bias is relative to the stage's corrected rate and is measured at the drive's
//! real rests: a turn learned by the stage comes back there as a filter bias of the turn's
//! rate with the opposite sign (32-40 deg/s about up on these seeds when the stage learned
//! it), so the filter's bias at the end stays within the datasheet bound on every axis only
//! when the turn was not learned.

use integration_tests::{path_arg, run_ok, simulate};

/// The datasheet bound on a gyro bias, deg/s (MPU-9250, PS-MPU-9250A-01 table 3.1).
const ZERO_RATE_OFFSET_DPS: f64 = 5.0;

/// `mems-sim drive` starting in a turn with seed `seed`, then `mems-odometry offline --json`:
/// the truth's rate at the first sample (deg/s) and the summary.
fn run(dir: &std::path::Path, seed: u64) -> (f64, serde_json::Value) {
    let seed = seed.to_string();
    let mcap = simulate(
        dir,
        &format!("turn-{seed}.mcap"),
        &[
            "drive",
            "--duration",
            "200",
            "--turns",
            "on",
            "--initial-rest",
            "0",
            "--legs",
            "2,4",
            "--start-at",
            "turn",
            "--hints",
            "encoders",
            "--rate",
            "100",
            "--vibration",
            "0",
            "--seed",
            &seed,
        ],
    );
    let contents = recording::mcap::read_all(&mcap).unwrap();
    let w = contents.truth[0].angular_rate_rps;
    let rate_dps = w.iter().map(|x| x * x).sum::<f64>().sqrt().to_degrees();
    let out = run_ok(
        "mems-odometry",
        &["offline", "--input", path_arg(&mcap), "--json"],
    );
    (rate_dps, serde_json::from_str(out.trim()).unwrap())
}

#[test]
fn a_robot_starting_in_a_turn_does_not_learn_the_turn_as_gyro_bias() {
    let dir = tempfile::tempdir().unwrap();
    for seed in 1..=3 {
        let (rate_dps, summary) = run(dir.path(), seed);
        // The recording does start in a turn, far faster than any bias.
        assert!(
            rate_dps > 20.0,
            "seed {seed}: first rate {rate_dps:.1} deg/s"
        );
        let bias = &summary["gyro_bias"]["bias_dps"];
        for axis in 0..3 {
            let b = bias[axis].as_f64().unwrap();
            assert!(
                b.abs() <= ZERO_RATE_OFFSET_DPS,
                "seed {seed}: the filter's gyro bias {bias} deg/s undoes a learned turn \
                 (first rate {rate_dps:.1} deg/s)"
            );
        }
    }
}
