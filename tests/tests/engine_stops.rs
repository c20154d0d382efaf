//! A car that stops with its engine running, through the real binaries: `mems-sim drive`
//! writes a simulated car (parked for 10 s with its engine running, then cruising at 3-8 m/s
//! for up to a few minutes between stops of 3-8 s, with turns, the IMU mounted 2 deg pitched
//! and 5 deg yawed on the body) whose engine idles harder at its stops than at the start
//! (`--engine-start 0.15 --engine-idle 0.3,23`: 0.15 and 0.3 m/s^2 per axis at 23 Hz and its
//! double, as wid-car-06's 42-46 mg at its start and 52-55 mg at its stop,
//! tools/sim/src/vibration.rs) and which shakes more while it drives (`--vibration 3`: 0.3
//! m/s^2 per axis per m/s), and `mems-odometry offline` runs it with no flags. The stops
//! shake the sensor above what the detector learned standing, so it calls every stop motion;
//! below 2 Hz a stop is as quiet as standing (`odometry::stops`).
//! - On a road that rocks the body while it drives (`--road 0.1`: 0.1 m/s^2 per axis at
//!   1.2 Hz, the low end of the wid-car drives), every stop after the start has a rest
//!   starting within it, flagged `VIBRATING_STOP`, and no rest starts while the car cruises
//!   (from 10 s after it drove off to 5 s before a stop: the detector, which learned the
//!   engine's shaking standing, flags the first seconds of creeping and braking).
//! - On a perfectly smooth road with the simulator's moderate vibration, where the car's
//!   driving is as quiet below 2 Hz as its stops, the test cannot tell the two apart and takes
//!   no window for a stop. (Not covered: with `--vibration 3` its 5 cm wheels put their
//!   rotation below 2 Hz while it creeps off, its first 30 s of driving are not quiet, and its
//!   cruise on a smooth road is then taken for stops: docs/odometry.md.)

use std::path::PathBuf;

use integration_tests::{offline_json, path_arg, run_ok, simulate, truth_rests, unique_namespace};
use ipc_types::{OdometryState, odometry_flags};

/// The car of the module documentation with seed `seed` and `extra` arguments, run through
/// `mems-odometry offline --json`: the truth's rests and the summary.
fn car(dir: &std::path::Path, seed: u64, extra: &[&str]) -> (Vec<(f64, f64)>, serde_json::Value) {
    let csv = car_csv(dir, seed, "3,8", extra);
    (truth_rests(&csv), offline_json(&csv, &[]))
}

/// The car of the module documentation with seed `seed`, stops of `rests` s (`MIN,MAX`) and
/// `extra` arguments, written by `mems-sim drive`.
fn car_csv(dir: &std::path::Path, seed: u64, rests: &str, extra: &[&str]) -> PathBuf {
    let seed = seed.to_string();
    let args = [
        &[
            "drive",
            "--duration",
            "240",
            "--initial-rest",
            "10",
            "--rests",
            rests,
            "--legs",
            "5,15",
            "--max-motion",
            "200",
            "--cruise",
            "3,8",
            "--turns",
            "on",
            "--rate",
            "100",
            "--mount-deg",
            "0,2,5",
            "--engine-idle",
            "0.3,23",
            "--engine-start",
            "0.15",
            "--seed",
            &seed,
        ],
        extra,
    ]
    .concat();
    let name = format!("car-{seed}-{rests}-{}.csv", extra.len());
    simulate(dir, &name, &args)
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

fn vibrating_stop_states(v: &serde_json::Value) -> u64 {
    v["wheeled"]["vibrating_stop_states"].as_u64().unwrap()
}

/// Asserts that the run `v` (`what` names it) took a stop with the engine running, has a rest
/// starting in every stop of `truth` after the start, and none while the car cruises (from
/// 10 s after it drove off to 5 s before a stop).
fn rests_at_the_stops_only(what: &str, truth: &[(f64, f64)], v: &serde_json::Value) {
    assert!(
        truth.len() >= 3,
        "{what}: the car stops {} times",
        truth.len()
    );
    assert!(
        vibrating_stop_states(v) > 0,
        "{what}: no stop taken with the engine running: {}",
        v["wheeled"]
    );
    let starts = rest_starts(v);
    for (a, b) in &truth[1..] {
        assert!(
            starts.iter().any(|t| (*a..=*b).contains(t)),
            "{what}: the stop over {a:.1}-{b:.1} s has no rest (rests start at {starts:?})"
        );
    }
    let drove_off = truth[0].1;
    let cruising: Vec<_> = starts
        .iter()
        .filter(|t| **t > drove_off + 10.0)
        .filter(|t| !truth.iter().any(|(a, b)| (a - 5.0..=*b).contains(*t)))
        .collect();
    assert!(
        cruising.is_empty(),
        "{what}: rests start while the car cruises at {cruising:?} s (stops {truth:?})"
    );
}

#[test]
fn a_car_idling_at_its_stops_rests_there() {
    let dir = std::env::temp_dir().join(unique_namespace("engine-stops"));
    std::fs::create_dir_all(&dir).unwrap();
    for seed in [1, 3] {
        let (truth, v) = car(&dir, seed, &["--road", "0.1", "--vibration", "3"]);
        rests_at_the_stops_only(&format!("seed {seed}"), &truth, &v);
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The same car with the GLRT windows and learning lengths the real-data bench's
/// leave-one-source-out search tries for vehicles (tools/real-data/corpus.json's `tuning`):
/// its stops are found whichever it runs. With the mean of the standing's windows as the
/// low-frequency test's reference instead of their median (`odometry::stops`), the windows
/// of the creep off the start, which the longer GLRT windows still flag rest, raised it: with
/// `--glrt-window-s 1 --learn-s 0.5` and `--glrt-window-s 2 --learn-s 2` no stop of either
/// seed had a rest, rests started while the car cruised, and the car ended 94.6-341.1 m off
/// (seed 1) and 145.6-155.3 m (seed 3). With the median every stop rests, and the car ends
/// 97.6-112.6 m (seed 1) and 8.2-14.2 m (seed 3) off with the two flag pairs, 24.3 and 1.0 m
/// with the defaults (`car_csv`'s `mems-sim drive`, then `mems-odometry offline --json`).
#[test]
fn a_car_idling_at_its_stops_rests_there_with_any_glrt_window() {
    let dir = std::env::temp_dir().join(unique_namespace("engine-stops-windows"));
    std::fs::create_dir_all(&dir).unwrap();
    for seed in [1, 3] {
        let csv = car_csv(&dir, seed, "3,8", &["--road", "0.1", "--vibration", "3"]);
        let truth = truth_rests(&csv);
        for flags in [
            &["--glrt-window-s", "1", "--learn-s", "0.5"][..],
            &[
                "--glrt-window-s",
                "2",
                "--learn-s",
                "2",
                "--learn-first-s",
                "2",
            ],
        ] {
            let v = offline_json(&csv, flags);
            rests_at_the_stops_only(&format!("seed {seed}, {}", flags.join(" ")), &truth, &v);
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn on_a_smooth_road_no_window_is_taken_for_a_stop() {
    let dir = std::env::temp_dir().join(unique_namespace("engine-stops-smooth"));
    std::fs::create_dir_all(&dir).unwrap();
    let (_, v) = car(&dir, 1, &[]);
    assert_eq!(vibrating_stop_states(&v), 0, "{}", v["wheeled"]);
    std::fs::remove_dir_all(&dir).ok();
}

/// Heading of `state`, rad: the yaw of its attitude (sensor to navigation frame, z up,
/// counter-clockwise positive seen from above), from the quaternion's components directly.
fn yaw_rad(state: &OdometryState) -> f64 {
    let [w, x, y, z] = state.attitude_wxyz;
    (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
}

/// The heading's change over each of the truth's stops after the first, deg, from the states
/// (revisions left out) one second inside the stop's ends.
fn heading_changes(states: &[OdometryState], stops: &[(f64, f64)]) -> Vec<f64> {
    let at = |t_s: f64| {
        states
            .iter()
            .filter(|s| s.flags & odometry_flags::REVISION == 0)
            .find(|s| s.stamps.sample_ns as f64 * 1e-9 >= t_s)
            .map(yaw_rad)
    };
    stops[1..]
        .iter()
        .filter_map(|(a, b)| Some((at(b - 1.0)? - at(a + 1.0)?).to_degrees()))
        .map(|d| (d + 180.0).rem_euclid(360.0) - 180.0)
        .collect()
}

/// An engine that shakes the gyroscope at the car's stops (`--engine-idle-gyro 0.45`: 0.45
/// deg/s per axis at 23 Hz and its double, zero-mean, as wid-car-06's 0.37-0.53 deg/s,
/// tools/sim/src/vibration.rs) and stops of 20-30 s: the heading stays within `BOUND_DEG`
/// over each stop (the truth's does not turn). The zero-rate update with the datasheet's 0.01
/// deg/s/sqrt(Hz) as its sigma and its 5-sigma gate refuses the shaken windows, and the bias
/// the filter holds turns the heading; with the rests' own scatter as its sigma
/// (`odometry::rest_scatter`) it takes them. Measured: with the datasheet's sigma the heading
/// turns 6.3 and 7.5 deg (seed 1) and 0.5 and 1.8 deg (seed 3) over the two stops; with the
/// rests' scatter at most 0.09 deg; without the shake at most 0.36 deg either way.
#[test]
fn a_car_shaking_its_gyroscope_at_its_stops_keeps_its_heading() {
    /// Largest heading change over a stop, deg: well above what the gyro's white noise turns
    /// over 30 s (0.01 deg/s/sqrt(Hz) times sqrt(30 s): 0.05 deg) and the end's gyro-bias
    /// 1-sigma over 30 s (the `--json` `gyro_bias`, 0.001 deg/s: 0.03 deg), well below
    /// what the datasheet's sigma turns (1.8-7.5 deg over the stops that fail).
    const BOUND_DEG: f64 = 1.0;
    let dir = std::env::temp_dir().join(unique_namespace("engine-stops-gyro"));
    std::fs::create_dir_all(&dir).unwrap();
    for seed in [1, 3] {
        let extra = [
            "--road",
            "0.1",
            "--vibration",
            "3",
            "--engine-idle-gyro",
            "0.45",
        ];
        let csv = car_csv(&dir, seed, "20,30", &extra);
        let out = dir.join(format!("states-{seed}.mcap"));
        let args = [
            "offline",
            "--input",
            path_arg(&csv),
            "--out",
            path_arg(&out),
        ];
        run_ok("mems-odometry", &args);
        let stops = truth_rests(&csv);
        assert!(
            stops.len() >= 3,
            "seed {seed}: the car stops {} times",
            stops.len()
        );
        let states = recording::mcap::read_all(&out).unwrap().odometry;
        let turned = heading_changes(&states, &stops);
        eprintln!("seed {seed}: heading change over the stops {turned:.2?} deg");
        assert_eq!(
            turned.len(),
            stops.len() - 1,
            "seed {seed}: stops {stops:?}"
        );
        for (d, (a, b)) in turned.iter().zip(&stops[1..]) {
            assert!(
                d.abs() <= BOUND_DEG,
                "seed {seed}: the heading turned {d:.2} deg over the stop at {a:.1}-{b:.1} s"
            );
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}
