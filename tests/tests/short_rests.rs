//! Rests as short as a robot's, through the real binaries: `mems-sim drive` writes a simulated
//! drive (CSV with truth), `mems-odometry offline` runs it with the default (auto) profile
//! and no calibration file (the identity at standard gravity and the datasheet's noise), and
//! the JSON summary is checked against the truth.
//!
//! - A stop-and-go robot with rests of 1-2 s aligns on its first rest of 1 s (half a second
//!   of learning against the part's known noise, which the alignment stands on) and counts its
//!   stops as rests, also when it starts off so briskly that the hindsight withdraws every
//!   rest flag of that first rest. (Its end error is not within its 1-sigma on every seed
//!   when its motors do not vibrate: docs/detectors.md, "Short rests".)
//! - The same robot vibrating as real ones do while their wheels turn is taken for wheeled,
//!   rests only in its stops and ends within twice its 1-sigma.
//! - An arm (`mems-sim arm`: 1.6 s of rest, then moves with pauses of 0.3 s) aligns on its
//!   first rest and its filter stays bounded: the end error within the reported 1-sigma's
//!   reach and a small part of the path.
//! - An arm that moves slowly for 20-30 s between waypoints 0.5 m apart, never resting (the
//!   other profile, its velocity bounded at a hand's speed), ends within reach of its start:
//!   its position is bounded by the reach, not left a random walk.
//! - A robot cruising at 0.08 m/s on a smooth floor, with the vibration its motors make at any
//!   speed (`--vibration-floor`), is not taken for rest.
//! - An alignment on a first rest that the hindsight then withdraws (a start right after it)
//!   is not the one the position counts from: the summary says so, and its truth frame and
//!   distance start at the alignment the end state stands on.
//! - A car whose stops are on slopes of up to 5 degrees (it pitches while it brakes) has a rest
//!   flagged at every stop: the rest test does not compare with the start's gravity direction.

use integration_tests::{offline_json, simulate, truth_rests, unique_namespace};

/// `mems-sim drive` with `args` into `dir/name.csv`, then `mems-odometry offline --json` on it:
/// the truth's rests and the summary.
fn drive_and_run(
    dir: &std::path::Path,
    name: &str,
    args: &[&str],
) -> (Vec<(f64, f64)>, serde_json::Value) {
    simulate_and_run(dir, name, &[&["drive"], args].concat(), &[])
}

/// `mems-sim` with `args` (a scenario and its arguments) into `dir/name.csv`, then
/// `mems-odometry offline --json` with `offline` on it: the truth's rests and the summary.
fn simulate_and_run(
    dir: &std::path::Path,
    name: &str,
    args: &[&str],
    offline: &[&str],
) -> (Vec<(f64, f64)>, serde_json::Value) {
    let csv = simulate(dir, &format!("{name}.csv"), args);
    (truth_rests(&csv), offline_json(&csv, offline))
}

/// The stop-and-go robot of docs/detectors.md, "Short rests" (a first rest of 1 s, then rests
/// of 1-2 s between legs of 2-4 s at 0.2-0.5 m/s, 200 Hz) at `seed`, with `extra` arguments.
fn stop_and_go<'a>(seed: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = drive_args("120", "1", seed);
    args.extend_from_slice(extra);
    args
}

/// `mems-sim drive`'s arguments for that robot over `duration` s with a first rest of
/// `initial_rest` s, at `seed`.
fn drive_args<'a>(duration: &'a str, initial_rest: &'a str, seed: &'a str) -> Vec<&'a str> {
    vec![
        "--duration",
        duration,
        "--initial-rest",
        initial_rest,
        "--rests",
        "1,2",
        "--legs",
        "2,4",
        "--max-motion",
        "10",
        "--cruise",
        "0.2,0.5",
        "--rate",
        "200",
        "--seed",
        seed,
    ]
}

/// Alignments the summary reports withdrawn.
fn withdrawals(v: &serde_json::Value) -> usize {
    v["alignments_withdrawn"].as_array().map_or(0, Vec::len)
}

/// Start times of the rests the odometry counted, s.
fn rest_starts(v: &serde_json::Value) -> Vec<f64> {
    v["rests"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["t_s"].as_f64().unwrap())
        .collect()
}

/// Horizontal end error against the truth and the reported 1-sigma per horizontal axis, m,
/// and the truth's horizontal distance, m.
fn end_error(v: &serde_json::Value) -> (f64, f64, f64) {
    let pair = |key: &str| {
        let a = v[key].as_array().unwrap();
        (a[0].as_f64().unwrap(), a[1].as_f64().unwrap())
    };
    let (ex, ey) = pair("truth_error_m");
    let (sx, sy) = pair("sigma_m");
    (
        ex.hypot(ey),
        ((sx * sx + sy * sy) / 2.0).sqrt(),
        v["truth_distance_m"].as_f64().unwrap(),
    )
}

#[test]
fn a_stop_and_go_robot_aligns_on_its_first_one_second_rest() {
    let dir = std::env::temp_dir().join(unique_namespace("short-rests-robot"));
    std::fs::create_dir_all(&dir).unwrap();
    let (truth, v) = drive_and_run(&dir, "robot", &stop_and_go("1", &[]));
    let aligned = v["aligned_at_s"].as_f64().unwrap();
    assert!(
        aligned <= 1.1,
        "aligned {aligned} s into a drive whose first rest is 1 s"
    );
    assert_eq!(withdrawals(&v), 0, "{v}");
    // Every stop after the start (1-2 s each) is counted as a rest.
    let starts = rest_starts(&v);
    let stops = &truth[1..];
    let missed: Vec<_> = stops
        .iter()
        .filter(|(a, b)| !starts.iter().any(|t| (a - 0.5..=*b).contains(t)))
        .collect();
    assert!(
        missed.len() * 5 <= stops.len(),
        "stops with no rest counted: {missed:?} of {}",
        stops.len()
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Seed 2 starts off so briskly that the hindsight withdraws the rest flags the detector set
/// after its learning (the half second before the motion): the alignment stands on the
/// learning window and what is left of that rest (`odometry::navigator::learning`), made a
/// batch (0.1 s) after the rest's end, and the end state counts from it.
#[test]
fn a_start_right_after_a_one_second_rest_keeps_its_alignment() {
    let dir = std::env::temp_dir().join(unique_namespace("short-rests-brisk"));
    std::fs::create_dir_all(&dir).unwrap();
    let (truth, v) = drive_and_run(&dir, "brisk", &stop_and_go("2", &[]));
    let aligned = v["aligned_at_s"].as_f64().unwrap();
    let first = truth[0].1;
    assert!(
        aligned <= first + 0.1 && withdrawals(&v) == 0,
        "aligned at {aligned} s on a first rest that ends at {first} s: {v}"
    );
    // The first stop after it is where the truth is, in the frame of that alignment (the
    // first leg covers a metre or two).
    let rests = v["rest_intervals"].as_array().unwrap();
    let e = &rests[0]["error_m"];
    let horizontal = e[0].as_f64().unwrap().hypot(e[1].as_f64().unwrap());
    assert!(
        horizontal < 0.3,
        "first rest {horizontal} m off: {}",
        rests[0]
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The same robot as a real one is, vibrating while its wheels turn (`--vibration-floor`, the
/// low end of the corpus's wheeled robots): `auto` takes it for wheeled, its alignment on the
/// first rest of 1 s stands, every stop has a rest and no rest starts in a leg, and the end
/// is within twice its 1-sigma.
#[test]
fn a_vibrating_stop_and_go_robot_rests_only_in_its_stops() {
    let dir = std::env::temp_dir().join(unique_namespace("short-rests-vibrating"));
    std::fs::create_dir_all(&dir).unwrap();
    let args = stop_and_go("2", &["--vibration-floor", "0.3,1"]);
    let (truth, v) = drive_and_run(&dir, "vibrating", &args);
    let profile = &v["profile"];
    assert_eq!(
        profile["profile"], "vehicle",
        "not taken for wheeled: {profile}"
    );
    let aligned = v["aligned_at_s"].as_f64().unwrap();
    assert!(
        aligned <= truth[0].1 + 0.1 && withdrawals(&v) == 0,
        "aligned at {aligned} s: {v}"
    );
    let starts = rest_starts(&v);
    for (a, b) in &truth[1..] {
        assert!(
            starts.iter().any(|t| (a - 0.5..=*b).contains(t)),
            "the stop over {a:.1}-{b:.1} s has no rest (rests start at {starts:?})"
        );
    }
    let in_legs: Vec<_> = starts
        .iter()
        .filter(|t| **t > aligned && !truth.iter().any(|(a, b)| (a - 0.5..=*b).contains(*t)))
        .collect();
    assert!(in_legs.is_empty(), "rests start in legs at {in_legs:?} s");
    let (error, sigma, distance) = end_error(&v);
    assert!(
        error <= 2.0 * sigma && error <= 0.03 * distance,
        "end error {error:.3} m, 1-sigma {sigma:.3} m after {distance:.1} m"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn stops_on_slopes_are_rests() {
    let dir = std::env::temp_dir().join(unique_namespace("short-rests-slopes"));
    std::fs::create_dir_all(&dir).unwrap();
    let (truth, v) = drive_and_run(
        &dir,
        "car",
        &[
            "--duration",
            "240",
            "--initial-rest",
            "2",
            "--rests",
            "3,6",
            "--legs",
            "5,10",
            "--max-motion",
            "45",
            "--cruise",
            "1,3",
            "--max-slope-deg",
            "5",
            "--turns",
            "on",
            "--rate",
            "100",
            "--seed",
            "1",
        ],
    );
    // The stops after the start: a rest starts in each (or in the last seconds of braking,
    // where a car creeps at millimetres per second).
    let starts = rest_starts(&v);
    assert!(truth.len() >= 5, "the drive stops {} times", truth.len());
    for (a, b) in &truth[1..] {
        assert!(
            starts.iter().any(|t| (a - 5.0..=*b).contains(t)),
            "the stop over {a:.1}-{b:.1} s has no rest (rests start at {starts:?})"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn an_arm_with_short_pauses_aligns_and_stays_bounded() {
    let dir = std::env::temp_dir().join(unique_namespace("short-rests-arm"));
    std::fs::create_dir_all(&dir).unwrap();
    let (truth, v) = simulate_and_run(
        &dir,
        "arm",
        &[
            "arm", "--moves", "12", "--pauses", "0.3,0.3", "--rate", "200", "--seed", "1",
        ],
        &[],
    );
    let aligned = v["aligned_at_s"].as_f64().unwrap();
    let first = truth[0].1;
    assert!(
        aligned <= first + 0.1,
        "aligned {aligned} s into an arm path whose first rest ends at {first} s"
    );
    let (error, sigma, distance) = end_error(&v);
    assert!(
        error <= 3.0 * sigma,
        "end error {error:.3} m beyond 3 sigma ({sigma:.3} m)"
    );
    assert!(
        error <= 0.1 * distance && sigma <= 0.1 * distance,
        "end error {error:.3} m, 1-sigma {sigma:.3} m after {distance:.1} m: not bounded"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn an_arm_that_never_rests_ends_within_reach() {
    let dir = std::env::temp_dir().join(unique_namespace("short-rests-reach"));
    std::fs::create_dir_all(&dir).unwrap();
    for seed in ["1", "2", "3"] {
        // Six moves of 20-30 s with pauses of 0.02 s, which no detector finds: about 150 s of
        // motion after the first rest, the datasheet part's biases unknown to the filter.
        let (_, v) = simulate_and_run(
            &dir,
            &format!("reach-{seed}"),
            &[
                "arm",
                "--moves",
                "6",
                "--pauses",
                "0.02,0.02",
                "--move-s",
                "20,30",
                "--rate",
                "200",
                "--preset",
                "datasheet",
                "--seed",
                seed,
            ],
            &["--profile", "other"],
        );
        let (error, sigma, distance) = end_error(&v);
        // With the velocity bound alone seed 3 ends 6.3 m off with a 1-sigma of 3.5 m.
        assert!(
            error <= 2.5 && sigma <= 2.0,
            "seed {seed}: end error {error:.3} m, 1-sigma {sigma:.3} m after {distance:.1} m"
        );
        assert!(
            error <= 3.0 * sigma,
            "seed {seed}: end error {error:.3} m beyond 3 sigma ({sigma:.3} m)"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_slow_cruise_on_a_smooth_floor_is_not_rest() {
    let dir = std::env::temp_dir().join(unique_namespace("short-rests-cruise"));
    std::fs::create_dir_all(&dir).unwrap();
    let (truth, v) = drive_and_run(
        &dir,
        "cruise",
        &[
            "--duration",
            "120",
            "--initial-rest",
            "2",
            "--rests",
            "2,3",
            "--legs",
            "20,30",
            "--max-motion",
            "40",
            "--cruise",
            "0.08,0.08",
            "--vibration-floor",
            "0.3,1",
            "--rate",
            "200",
            "--seed",
            "1",
        ],
    );
    // No rest starts inside a drive between two stops, a second away from either.
    let starts = rest_starts(&v);
    for w in truth.windows(2) {
        let (a, b) = (w[0].1 + 1.0, w[1].0 - 1.0);
        let inside: Vec<_> = starts.iter().filter(|t| (a..=b).contains(*t)).collect();
        assert!(
            inside.is_empty(),
            "rests counted at {inside:?} s of a cruise over {a:.1}-{b:.1} s"
        );
    }
    // The detector says what told the cruise from rest: most of the 70-odd seconds of cruise
    // were steady (no acceleration or turn) but vibrating.
    let vibrating = v["steady_vibrating_s"].as_f64().unwrap();
    assert!(
        vibrating >= 30.0,
        "{vibrating} s found steady but vibrating"
    );
    // Taken for rest, the robot would end where it started (the whole distance off); its
    // drift between stops is the IMU's alone (its 1-sigma does not yet hold the vibration
    // floor: docs/detectors.md, "Short rests").
    let (error, _, distance) = end_error(&v);
    assert!(
        error <= 0.4 * distance,
        "end error {error:.3} m after {distance:.1} m of slow cruise"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The vehicle profile learns from its first second of rest and aligns on a second: on a first
/// rest of 1.5 s (seed 2 starts off briskly, and the hindsight withdraws the rest flags after
/// the learning) the alignment stands on the whole learning window and what is left of the
/// rest, and holds. With only the learning window's last half second it was withdrawn 0.6 s
/// later and the filter waited for the next rest, 12.4 s in.
#[test]
fn the_vehicle_profile_aligns_on_a_first_rest_half_a_second_longer_than_its_learning() {
    let dir = std::env::temp_dir().join(unique_namespace("short-rests-vehicle"));
    std::fs::create_dir_all(&dir).unwrap();
    let (truth, v) = simulate_and_run(
        &dir,
        "vehicle",
        &[&["drive"][..], &drive_args("30", "1.5", "2")].concat(),
        &["--profile", "vehicle"],
    );
    std::fs::remove_dir_all(&dir).unwrap();
    let aligned = v["aligned_at_s"].as_f64().unwrap();
    // On the first rest, a batch of motion after its end at most.
    assert!(
        aligned <= truth[0].1 + 0.5,
        "aligned {aligned} s in, truth rests {truth:?}: {v}"
    );
    assert_eq!(withdrawals(&v), 0, "{v}");
    // Within its 1-sigma: the radius holding 68 % of a circular 2-D Gaussian (as bench.py).
    let (error, sigma, distance) = end_error(&v);
    let r68 = 1.515 * sigma;
    assert!(
        error <= r68,
        "end error {error:.3} m beyond r68 {r68:.3} m: {v}"
    );
    assert!(distance > 5.0, "distance {distance} m counted");
}

/// A drive whose first rest (1 s) is all the vehicle profile's learning takes: its filter
/// aligns on the learning window and the rest flags after it as the robot starts off (its
/// second of alignment), the settled flags take the rest flags away, the filter waits for the
/// next rest, and the summary measures from there (before, it kept the first alignment's truth
/// frame: every rest 1.8-2.0 m off on such a drive).
#[test]
fn a_withdrawn_alignment_is_reported_and_not_counted_from() {
    let dir = std::env::temp_dir().join(unique_namespace("short-rests-withdrawn"));
    std::fs::create_dir_all(&dir).unwrap();
    let (truth, v) = simulate_and_run(
        &dir,
        "withdrawn",
        &[&["drive"][..], &drive_args("30", "1.0", "2")].concat(),
        &["--profile", "vehicle"],
    );
    let withdrawn = v["alignments_withdrawn"].as_array().unwrap();
    assert!(!withdrawn.is_empty(), "no withdrawal on this seed: {v}");
    let aligned = v["aligned_at_s"].as_f64().unwrap();
    for w in withdrawn {
        let (a, at) = (
            w["aligned_at_s"].as_f64().unwrap(),
            w["withdrawn_at_s"].as_f64().unwrap(),
        );
        assert!(
            a < at && at < aligned,
            "{w} against the alignment at {aligned} s"
        );
    }
    // The alignment that holds is on a rest of the truth.
    assert!(
        truth.iter().any(|(a, b)| (*a..=b + 0.2).contains(&aligned)),
        "aligned at {aligned} s, truth rests {truth:?}"
    );
    // Every rest counted after it is within 0.3 m of the truth in the frame of that alignment
    // (the legs before the second rest cover about 2 m).
    let rests = v["rest_intervals"].as_array().unwrap();
    assert!(!rests.is_empty());
    let first = &rests[0];
    let e = &first["error_m"];
    let horizontal = e[0].as_f64().unwrap().hypot(e[1].as_f64().unwrap());
    assert!(
        horizontal < 0.3,
        "first rest after the alignment {horizontal} m off: {first}"
    );
    assert!(rests.iter().all(|r| r["t_s"].as_f64().unwrap() > aligned));
    // The truth's distance counts from the alignment: below the truth's whole path.
    let (_, _, distance) = end_error(&v);
    assert!(distance > 0.0 && distance < 10.0, "distance {distance} m");
}
