//! Accelerometer and gyroscope axes that disagree: a simulated 120 s drive with turns and
//! in-place turns (`mems-sim drive`, canonical CSV at 200 Hz) whose `ax_g` and `az_g` header
//! names are swapped, run through `mems-odometry offline` as a user would. The run is warned
//! about on stderr (how many turns disagreed, the worst, the likely cause) and the JSON
//! result's `axes_check` says so; the file as written is not.

use std::path::Path;
use std::process::Command;

use integration_tests::{bin, identity_calibration, simulate_in_scratch};

/// `src` with the header names `a` and `b` exchanged (the data rows as they are).
fn swap_header(src: &Path, dst: &Path, a: &str, b: &str) {
    let text = std::fs::read_to_string(src).unwrap();
    let (header, rows) = text.split_once('\n').unwrap();
    let names: Vec<&str> = header
        .split(',')
        .map(|n| match n {
            n if n == a => b,
            n if n == b => a,
            n => n,
        })
        .collect();
    std::fs::write(dst, format!("{}\n{rows}", names.join(","))).unwrap();
}

/// `mems-odometry offline --json` on `csv`: the JSON result and stderr.
fn offline(csv: &Path) -> (serde_json::Value, String) {
    let out = Command::new(bin("mems-odometry"))
        .args(["offline", "--json", "--calib"])
        .arg(identity_calibration())
        .arg("--input")
        .arg(csv)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{}: {stderr}", csv.display());
    (serde_json::from_slice(&out.stdout).unwrap(), stderr)
}

#[test]
fn swapped_accelerometer_columns_are_reported() {
    let (dir, drive) = simulate_in_scratch(
        "swapped-axes",
        "drive.csv",
        &[
            "drive",
            "--duration",
            "120",
            "--rate",
            "200",
            "--seed",
            "3",
            "--turns",
            "on",
            "--in-place-turns",
            "on",
        ],
    );
    let (v, stderr) = offline(&drive);
    let axes = &v["axes_check"];
    assert_eq!(axes["disagree"], false, "as written: {axes}");
    assert_eq!(axes["disagreed"], 0, "as written: {axes}");
    assert!(!stderr.contains("axes disagree"), "{stderr}");

    let swapped = dir.join("swapped.csv");
    swap_header(&drive, &swapped, "ax_g", "az_g");
    let (v, stderr) = offline(&swapped);
    let axes = &v["axes_check"];
    assert_eq!(axes["disagree"], true, "swapped: {axes}");
    let checked = axes["checked"].as_u64().unwrap();
    assert!(checked >= 2, "swapped: {axes}");
    assert_eq!(axes["disagreed"], checked, "swapped: {axes}");
    // The turns are 90 deg and more: gravity ends tens of degrees from where the gyro says.
    assert!(axes["worst"]["off_deg"].as_f64().unwrap() > 45.0, "{axes}");
    assert!(
        stderr.contains("swapped.csv: the accelerometer's and the gyroscope's axes disagree")
            && stderr.contains("columns swapped"),
        "{stderr}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
