//! Rests as short as a robot's, through the real binaries: `mems-sim drive` writes a simulated
//! drive (CSV with truth), `mems-odometry offline` runs it with the default (vehicle) profile
//! and no calibration file (the identity at standard gravity and the datasheet's noise), and
//! the JSON summary is checked against the truth.
//!
//! - A stop-and-go robot with rests of 1-2 s aligns on its first rest of 2 s (a second of
//!   learning, then the odometry's second of alignment) and counts its stops as rests. (Its
//!   end error is not yet within its 1-sigma on every seed: docs/detectors.md, "Short
//!   rests".)
//! - A car whose stops are on slopes of up to 5 degrees (it pitches while it brakes) has a rest
//!   flagged at every stop: the rest test does not compare with the start's gravity direction.

use integration_tests::{path_arg, run_ok, simulate, unique_namespace};

/// Times (s) of the truth's rests in a `mems-sim` CSV: `(start, end)` of each run of rows with
/// `truth_rest` set.
fn truth_rests(csv: &std::path::Path) -> Vec<(f64, f64)> {
    let text = std::fs::read_to_string(csv).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let column = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (t_col, rest_col) = (column("t_s"), column("truth_rest"));
    let (mut rests, mut start, mut last_t) = (Vec::new(), None, 0.0);
    for line in lines {
        let cells: Vec<&str> = line.split(',').collect();
        let t: f64 = cells[t_col].parse().unwrap();
        let rest = matches!(cells[rest_col], "1" | "true");
        match (rest, start) {
            (true, None) => start = Some(t),
            (false, Some(s)) => {
                rests.push((s, t));
                start = None;
            }
            _ => {}
        }
        last_t = t;
    }
    rests.extend(start.map(|s| (s, last_t)));
    rests
}

/// `mems-sim drive` with `args` into `dir/name.csv`, then `mems-odometry offline --json` on it:
/// the truth's rests and the summary.
fn drive_and_run(
    dir: &std::path::Path,
    name: &str,
    args: &[&str],
) -> (Vec<(f64, f64)>, serde_json::Value) {
    let csv = simulate(dir, &format!("{name}.csv"), &[&["drive"], args].concat());
    let out = run_ok(
        "mems-odometry",
        &["offline", "--input", path_arg(&csv), "--json"],
    );
    (truth_rests(&csv), serde_json::from_str(out.trim()).unwrap())
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

#[test]
fn a_stop_and_go_robot_aligns_on_its_first_two_second_rest() {
    let dir = std::env::temp_dir().join(unique_namespace("short-rests-robot"));
    std::fs::create_dir_all(&dir).unwrap();
    let (truth, v) = drive_and_run(
        &dir,
        "robot",
        &[
            "--duration",
            "120",
            "--initial-rest",
            "2",
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
            "1",
        ],
    );
    let aligned = v["aligned_at_s"].as_f64().unwrap();
    assert!(
        aligned <= 2.1,
        "aligned {aligned} s into a drive whose first rest is 2 s"
    );
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
