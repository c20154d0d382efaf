//! A datasheet-level simulated part (uncompensated temperature drift, the part `mems-stack`
//! simulates) calibrated as `mems-stack` calibrates it ([`calibrate_sim_part`]: six-position
//! fit, then the gyro from 16 orientations), then driven for 10 minutes with turns and run through `mems-odometry offline`:
//! the zero-state detector keeps finding rest to the end of the drive, and the end error stays
//! a few percent of the distance. With a 60 s reference memory the detector's reference lagged
//! the self-heating drift, no rest was found after 173 s and the position diverged to tens of
//! kilometres (docs/detectors.md).

use integration_tests::{calibrate_sim_part, path_arg, run_ok, simulate, unique_namespace};

#[test]
fn the_detector_follows_the_temperature_drift_of_an_uncompensated_part() {
    let dir = std::env::temp_dir().join(unique_namespace("datasheet-drive"));
    std::fs::create_dir_all(&dir).unwrap();
    let calib = calibrate_sim_part(&dir, 1001);
    let calib = path_arg(&calib);
    let drive = simulate(
        &dir,
        "drive.mcap",
        &[
            "drive",
            "--duration",
            "600",
            "--turns",
            "on",
            "--preset",
            "datasheet",
            "--rate",
            "200",
            "--seed",
            "1",
        ],
    );
    let out = run_ok(
        "mems-odometry",
        &[
            "offline",
            "--calib",
            calib,
            "--input",
            path_arg(&drive),
            "--json",
        ],
    );
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    let last_rest_s = v["rest_intervals"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["t_s"].as_f64().unwrap())
        .fold(0.0, f64::max);
    assert!(
        last_rest_s > 500.0,
        "the last rest interval ended at {last_rest_s} s of a 600 s drive"
    );
    let error: Vec<f64> = v["truth_error_m"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e.as_f64().unwrap())
        .collect();
    let distance = v["truth_distance_m"].as_f64().unwrap();
    let horizontal = error[0].hypot(error[1]);
    assert!(
        horizontal < 0.05 * distance,
        "end error {horizontal} m over {distance} m"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
