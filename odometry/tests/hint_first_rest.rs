//! A robot with wheel-encoder hints whose first rest is barely longer than its detector's
//! learning, through the real `mems-odometry offline` binary on an MCAP file of a simulated
//! drive with truth and encoder hints: the filter aligns on that rest, the learning window
//! included (the learner judged it still, the encoders said stationary), instead of waiting
//! for a later rest or a cruise. The real TurtleBot runs of docs/real-data.md (first rests of
//! 1.6-1.7 s by their encoders) aligned only at their end with `--learn-s 1 --learn-first-s 1`
//! that way.

mod common;

use common::{Case, drive_with_encoder_hints, offline_drive_with_hints};

#[test]
fn a_robot_with_hints_aligns_on_a_first_rest_its_learning_takes_most_of() {
    // 1.2 s of rest (the encoders say stationary for 0.4-0.5 s more while the robot creeps
    // off), then legs of 2-6 s: the detector learns from 1 s of rest before its first rule
    // (`--learn-s 1 --learn-first-s 1`) and a filter with speed hints aligns on at least 1 s
    // of it.
    for seed in [3, 4] {
        let case = Case {
            duration_s: 60.0,
            rate_hz: 100.0,
            initial_rest_s: 1.2,
            dlpf: Some(mems_sim::dlpf::DlpfConfig::driver(100.0)),
            ..Case::straight()
        };
        let (raw, hints) = drive_with_encoder_hints(&case, seed);
        let v = offline_drive_with_hints(
            env!("CARGO_BIN_EXE_mems-odometry"),
            "hint-first-rest",
            &raw,
            hints,
            &["--learn-s", "1", "--learn-first-s", "1", "--mount", "0,0,0"],
        );
        let aligned_at = v["aligned_at_s"].as_f64().unwrap();
        // At rest (not on a cruise), at the end of the first rest (the encoders' stationary
        // hints and a batch of motion after them): without the learning window, the
        // hints' 0.6-0.7 s of rest after it never sufficed and the filter aligned on a cruise
        // 3.4 s in or at a later rest 21 s in.
        assert!(v["aligned_in_motion"].is_null(), "seed {seed}: {v}");
        assert!(
            aligned_at < 2.5,
            "seed {seed}: aligned {aligned_at} s in: {v}"
        );
        // Ends within its 1-sigma (the radius holding 68 % of a circular 2-D Gaussian, as
        // bench.py).
        let e = |k: &str, i: usize| v[k][i].as_f64().unwrap();
        let error = e("truth_error_m", 0).hypot(e("truth_error_m", 1));
        let r68 = 1.515 * ((e("sigma_m", 0).powi(2) + e("sigma_m", 1).powi(2)) / 2.0).sqrt();
        eprintln!(
            "seed {seed}: aligned {aligned_at:.2} s in, end error {error:.3} m, r68 {r68:.3} m"
        );
        assert!(
            error <= r68,
            "seed {seed}: error {error:.3} m beyond r68 {r68:.3} m: {v}"
        );
    }
}
