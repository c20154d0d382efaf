//! The lever-arm candidate of `mems-odometry diagnose` on simulated drives, through the real
//! binaries: `mems-sim drive` with turns writes a run whose IMU sits ahead of the rear axle
//! (`--lever-arm-m`: the sensor's position from the axle, sensor frame, which the drive's
//! default mounting makes the body frame), `mems-odometry diagnose --json -- --profile
//! vehicle` diagnoses it.
//!
//! - Undeclared: the forward offset from the IMU to the axle is found, the truth within two
//!   of its 1-sigma, and the rerun with it ends nearer the truth.
//! - Declared (`diagnose --lever-arm`), or a run with the IMU on the axle: not found.
//! - `offline --lever-arm 0,0,0` gives the outputs of a run without the flag, bit for bit.
//! - With speed hints (and the mounting given), the lever arm declared takes most of the end
//!   error an undeclared one leaves.

use std::path::{Path, PathBuf};

use integration_tests::{path_arg, run_ok, simulate};
use serde_json::Value;

/// The IMU's distance ahead of the rear axle in the simulated drive, m.
const AHEAD_M: f64 = 1.5;

/// A 120 s drive with turns (seed 4, 200 Hz) with the IMU `ahead_m` ahead of the axle, and
/// `extra` simulator options (its file named by `tag`).
fn drive(dir: &Path, ahead_m: f64, tag: &str, extra: &[&str]) -> PathBuf {
    let lever = format!("{ahead_m},0,0");
    let mut args = vec![
        "drive",
        "--duration",
        "120",
        "--turns",
        "on",
        "--seed",
        "4",
        "--rate",
        "200",
        "--lever-arm-m",
        &lever,
    ];
    args.extend_from_slice(extra);
    simulate(dir, &format!("drive-{ahead_m}{tag}.mcap"), &args)
}

/// `mems-odometry diagnose RUN --json` with `extra` diagnose options, as the vehicle profile.
fn diagnose(run: &Path, extra: &[&str]) -> Value {
    let mut args = vec!["diagnose", path_arg(run), "--json"];
    args.extend_from_slice(extra);
    args.extend(["--", "--profile", "vehicle"]);
    serde_json::from_str(&run_ok("mems-odometry", &args)).unwrap()
}

fn num(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

#[test]
fn an_imu_ahead_of_the_axle_is_found_and_its_rerun_ends_nearer_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let run = drive(dir.path(), AHEAD_M, "", &[]);
    let d = diagnose(&run, &[]);
    let lever = &d["lever_arm"];
    let c = &lever["candidate"];
    assert_eq!(c["found"], true, "{lever:#}");
    // From the IMU to the axle: -AHEAD_M along body x.
    let (r, sigma) = (num(&c["r_x_m"]), num(&c["sigma_m"]));
    assert!(
        (r + AHEAD_M).abs() < 2.0 * sigma,
        "{r} +- {sigma} m, truth {}",
        -AHEAD_M
    );
    assert!(sigma < 0.5 * AHEAD_M, "{sigma}");
    assert_eq!(lever["confirmed"], true, "{lever:#}");
    let (before, after) = (
        num(&lever["before"]["truth_error_m"]),
        num(&lever["after"]["truth_error_m"]),
    );
    assert!(after < before, "truth end error {before} -> {after} m");

    // Declared, there is nothing left to find.
    let declared = format!("{},0,0", -AHEAD_M);
    let d = diagnose(&run, &["--lever-arm", &declared]);
    assert_eq!(d["lever_arm"]["candidate"]["found"], false, "{d:#}");
}

#[test]
fn an_imu_on_the_axle_has_no_lever_arm_and_a_zero_flag_changes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let run = drive(dir.path(), 0.0, "", &[]);
    let d = diagnose(&run, &[]);
    let c = &d["lever_arm"]["candidate"];
    assert!(c["untestable"].is_null(), "{c:#}");
    assert_eq!(c["found"], false, "{c:#}");

    let offline = |extra: &[&str]| {
        let mut args = vec!["offline", "--input", path_arg(&run), "--json"];
        args.extend_from_slice(extra);
        args.extend(["--profile", "vehicle"]);
        run_ok("mems-odometry", &args)
    };
    assert_eq!(offline(&[]), offline(&["--lever-arm", "0,0,0"]));
}

#[test]
fn a_malformed_lever_arm_names_the_flag() {
    let out = std::process::Command::new(integration_tests::bin("mems-odometry"))
        .args(["offline", "--input", "x.csv", "--lever-arm", "1,2"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--lever-arm") && err.contains("X,Y,Z"),
        "{err}"
    );
}

/// The horizontal end error against the truth (the axle's) of `offline --json` on `run`
/// with the mounting given and the lever arm `lever`, m.
fn hinted_error(run: &Path, lever: &str) -> f64 {
    let out = run_ok(
        "mems-odometry",
        &[
            "offline",
            "--input",
            path_arg(run),
            "--json",
            "--profile",
            "vehicle",
            "--mount",
            "0,0,0",
            "--lever-arm",
            lever,
        ],
    );
    let v: Value = serde_json::from_str(&out).unwrap();
    let e = &v["truth_error_m"];
    num(&e[0]).hypot(num(&e[1]))
}

#[test]
fn speed_hints_compared_at_the_axle_take_the_lever_arm_out() {
    let dir = tempfile::tempdir().unwrap();
    let run = drive(dir.path(), AHEAD_M, "-hinted", &["--hints", "encoders"]);
    let undeclared = hinted_error(&run, "0,0,0");
    let declared = hinted_error(&run, "-1.5,0,0");
    assert!(
        declared < 0.5 * undeclared,
        "end error {undeclared} m undeclared, {declared} m declared"
    );
}
