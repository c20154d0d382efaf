//! A wheeled robot that starts in motion, through the real `mems-odometry offline` binary on
//! an MCAP file of a simulated drive with truth and encoder hints (`mems_sim`'s drive with no
//! initial rest, its hints from the drive's truth): the filter aligns on the first steady
//! cruise (the IMU's detector flags it still, the encoders say the robot moves) instead of
//! waiting for the first stop, ends within its 1-sigma of the truth, and counts the IMU's rest
//! flags during the cruise as disagreements; without the hints it waits for the first stop.
//!
//! No vibration (`vibration: 0`): a straight leg at constant speed is then as still for the IMU
//! as a rest, which is what the real wheeled recordings of the corpus show while cruising.

mod common;

use std::path::Path;
use std::process::Command;

use common::{Case, scratch, write_drive_with_encoder_hints};

/// Writes a drive with turns that starts by driving off, and its encoder hints (on the
/// samples' clock, recorded at their publication), to `path`.
fn write_drive(path: &Path) {
    write_drive_with_encoder_hints(path, &Case::driving_off(), 5);
}

/// `mems-odometry offline --json --input PATH ARGS`: its JSON result and stderr.
fn offline(input: &Path, extra: &[&str]) -> (serde_json::Value, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_mems-odometry"))
        .args(["offline", "--json", "--input"])
        .arg(input)
        .args(extra)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "offline failed: {err}");
    (serde_json::from_slice(&out.stdout).unwrap(), err)
}

fn horizontal(v: &serde_json::Value, key: &str) -> (f64, f64) {
    let a = |i: usize| v[key][i].as_f64().unwrap();
    (a(0), a(1))
}

#[test]
fn a_robot_that_starts_in_motion_aligns_on_its_first_cruise_and_ends_within_its_sigma() {
    let dir = scratch("start-in-motion");
    let path = dir.join("drive.mcap");
    write_drive(&path);
    let (with_hints, stderr) = offline(&path, &["--mount", "0,0,0"]);
    let (imu_only, _) = offline(&path, &["--mount", "0,0,0", "--no-hints"]);
    std::fs::remove_dir_all(&dir).unwrap();

    // Aligned in motion, at a cruise speed of the simulated robot (0.2-1 m/s), and said so.
    let speed = with_hints["aligned_in_motion"]["speed_mps"]
        .as_f64()
        .unwrap_or_else(|| panic!("not aligned in motion: {with_hints}"));
    assert!((0.2..=1.0).contains(&speed), "{with_hints}");
    assert!(stderr.contains("in motion"), "{stderr}");
    // Without the hints the detector's still cruise is no rest to align on either way: the
    // IMU alone aligns at rest, later (at the first stop or a still cruise taken for one).
    assert!(imu_only["aligned_in_motion"].is_null(), "{imu_only}");
    let aligned_at = with_hints["aligned_at_s"].as_f64().unwrap();
    assert!(aligned_at < 10.0, "{with_hints}");

    // Ends within its 1-sigma: the horizontal error inside the radius that holds 68 % of a
    // circular 2-D Gaussian with the reported per-axis sigma (1.515 sigma, as bench.py).
    let (ex, ey) = horizontal(&with_hints, "truth_error_m");
    let (sx, sy) = horizontal(&with_hints, "sigma_m");
    let error = ex.hypot(ey);
    let r68 = 1.515 * ((sx * sx + sy * sy) / 2.0).sqrt();
    let distance = with_hints["truth_distance_m"].as_f64().unwrap();
    eprintln!(
        "aligned in motion {aligned_at:.2} s in at {speed:.2} m/s; end error {error:.3} m, \
         r68 {r68:.3} m, distance {distance:.1} m"
    );
    assert!(
        error <= r68,
        "error {error:.3} m beyond r68 {r68:.3} m: {with_hints}"
    );
    // And the sigma is not so wide that covering means nothing: within 5 % of the distance.
    assert!(r68 < 0.05 * distance, "{with_hints}");
    // The IMU's rest flags while the encoders said moving were counted, not taken for rest.
    assert!(
        with_hints["hints"]["disagreements"].as_u64().unwrap() > 0,
        "{with_hints}"
    );
}
