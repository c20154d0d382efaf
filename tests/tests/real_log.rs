//! `mems-odometry offline` on what real logs look like: a logger's repeated rows and
//! quantised (equal) timestamps, no calibration file, and a recording that starts in motion.
//! The logs are simulated drives run through `mems-sim`, edited the way a logger would.

use std::path::Path;
use std::process::{Command, Output};

use integration_tests::{bin, path_arg, run_ok, simulate, unique_namespace};

fn offline(args: &[&str]) -> Output {
    Command::new(bin("mems-odometry"))
        .arg("offline")
        .args(args)
        .output()
        .expect("mems-odometry runs")
}

fn json(out: &Output) -> serde_json::Value {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "mems-odometry failed: {stderr}");
    serde_json::from_slice(&out.stdout).unwrap()
}

fn drive(dir: &Path, name: &str, extra: &[&str]) -> std::path::PathBuf {
    let common = ["drive", "--duration", "120", "--rate", "200", "--seed", "3"];
    simulate(dir, name, &[&common[..], extra].concat())
}

#[test]
fn repeated_rows_and_equal_times_are_repaired_counted_and_change_nothing() {
    let dir = std::env::temp_dir().join(unique_namespace("real-log"));
    std::fs::create_dir_all(&dir).unwrap();
    let clean = drive(&dir, "clean.csv", &[]);
    // Every 50th row repeated exactly (same time and values), every 70th row's time set to
    // its predecessor's (a host clock quantised coarser than the sample period).
    let text = std::fs::read_to_string(&clean).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let mut out = vec![header.to_owned()];
    let (mut repeats, mut equal_times) = (0, 0);
    let mut previous_time = String::new();
    for (i, line) in lines.enumerate() {
        let (time, rest) = line.split_once(',').unwrap();
        if i > 0 && i % 70 == 0 {
            out.push(format!("{previous_time},{rest}"));
            equal_times += 1;
        } else {
            out.push(line.to_owned());
        }
        if i > 0 && i % 50 == 0 {
            out.push(out.last().unwrap().clone());
            repeats += 1;
        }
        previous_time = time.to_owned();
    }
    let logged = dir.join("logged.csv");
    std::fs::write(&logged, out.join("\n") + "\n").unwrap();

    // Refused line by line when asked to be strict.
    let strict = offline(&["--input", path_arg(&logged), "--strict-time", "--json"]);
    let stderr = String::from_utf8_lossy(&strict.stderr);
    assert!(!strict.status.success());
    assert!(
        stderr.contains("logged.csv:") && stderr.contains("duplicate time"),
        "{stderr}"
    );

    // Repaired by default, with the counts on stderr and in the JSON; no --calib needed.
    let repaired = offline(&["--input", path_arg(&logged), "--json"]);
    let stderr = String::from_utf8_lossy(&repaired.stderr).into_owned();
    let v = json(&repaired);
    assert_eq!(v["log_repairs"]["repeats_dropped"], repeats, "{stderr}");
    assert_eq!(v["log_repairs"]["times_rebuilt"], equal_times, "{stderr}");
    assert!(
        stderr.contains(&format!("dropped {repeats} rows")) && stderr.contains("no --calib"),
        "{stderr}"
    );
    // The simulated sensor's period is exact, so the rebuilt times are the true ones and
    // the result is the clean file's, bit for bit.
    let reference = json(&offline(&["--input", path_arg(&clean), "--json"]));
    assert_eq!(v["end_displacement_m"], reference["end_displacement_m"]);
    assert_eq!(v["sigma_m"], reference["sigma_m"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A calibration of the simulated part whose `[noise]` table was measured on a static run
/// (what tells a rest from a vehicle cruising with its vibration), from white samples like
/// the drive it is used with (see `a_recording_that_starts_in_motion_aligns_at_its_first_rest`).
fn calibration_with_noise(dir: &Path) -> std::path::PathBuf {
    let (six, still, calib) = (
        dir.join("six.csv"),
        dir.join("still.csv"),
        dir.join("c.toml"),
    );
    let sim = |kind: &str, extra: &[&str], out: &Path| {
        let mut args = vec![kind, "--rate", "200", "--seed", "3", "--dlpf", "off"];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--out", path_arg(out)]);
        run_ok("mems-sim", &args);
    };
    sim("six-position", &[], &six);
    let (six, calib_arg) = (path_arg(&six), path_arg(&calib));
    run_ok(
        "mems-calibrate",
        &["fit", "--input", six, "--model", "full", "--out", calib_arg],
    );
    sim("static", &["--duration", "120"], &still);
    run_ok(
        "mems-calibrate",
        &["allan", "--input", path_arg(&still), "--into", calib_arg],
    );
    calib
}

#[test]
fn a_recording_that_starts_in_motion_aligns_at_its_first_rest() {
    let dir = std::env::temp_dir().join(unique_namespace("in-motion"));
    std::fs::create_dir_all(&dir).unwrap();
    // White samples: this test is about a start in motion; what the part's DLPF does to
    // drives is measured by `drive_eval` (docs/odometry.md), and the calibration here is
    // configured with the white noise it draws.
    let moving = drive(
        &dir,
        "moving.csv",
        &["--initial-rest", "0", "--dlpf", "off"],
    );
    let calib = calibration_with_noise(&dir);
    let out = offline(&[
        "--input",
        path_arg(&moving),
        "--calib",
        path_arg(&calib),
        "--json",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let v = json(&out);
    let aligned_at = v["aligned_at_s"].as_f64().unwrap();
    assert!(aligned_at > 5.0, "aligned at {aligned_at} s: {stderr}");
    assert!(stderr.contains("into the recording"), "{stderr}");
    let e: Vec<f64> = v["truth_error_m"]
        .as_array()
        .expect("a position against the truth")
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let distance = v["truth_distance_m"].as_f64().unwrap();
    assert!(
        e[0].hypot(e[1]) < 0.02 * distance,
        "end error {e:?} over {distance} m"
    );
    // Without the measured noise, the vehicle profile's half second of learning, taken with the
    // confidence of 5 s of rest, is not fooled by the first steady cruise either (5 s of
    // learning without the noise learned there, 8.3 s in, and ended 35 m off): it aligns at
    // the same rest.
    let blind = json(&offline(&["--input", path_arg(&moving), "--json"]));
    let blind_at = blind["aligned_at_s"].as_f64().unwrap();
    assert!(
        (blind_at - aligned_at).abs() < 0.5,
        "aligned at {blind_at} s without the measured noise, {aligned_at} s with it"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
