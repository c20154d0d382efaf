//! The published 1-sigma against the run's own innovations (`odometry::consistency`), through
//! `mems-sim` and `mems-odometry offline`: a simulated foot walk whose sensor is as noisy as
//! the filter assumes (the MPU-9250's datasheet densities) keeps its 1-sigma (no factor above
//! 1 is found significant); the same walk with ten times the white noise on both sensors
//! (100 times the variance) is found overconfident by its zero-velocity innovations and
//! publishes a wider 1-sigma. In both, the estimate is the one `--innovation-scaling off`
//! gives, to the bit: only the published 1-sigma changes.

use integration_tests::{path_arg, run_ok, unique_namespace};
use std::path::Path;

/// The offline run's JSON with `--innovation-scaling scaling`.
fn offline(input: &Path, scaling: &str) -> serde_json::Value {
    let out = run_ok(
        "mems-odometry",
        &[
            "offline",
            "--input",
            path_arg(input),
            "--json",
            "--innovation-scaling",
            scaling,
        ],
    );
    serde_json::from_str(out.trim()).unwrap()
}

/// Per-axis rms horizontal 1-sigma and horizontal end error, m.
fn sigma_and_error(v: &serde_json::Value) -> (f64, f64) {
    let s = |i: usize| v["sigma_m"][i].as_f64().unwrap();
    let e = |i: usize| v["truth_error_m"][i].as_f64().unwrap();
    (((s(0) * s(0) + s(1) * s(1)) / 2.0).sqrt(), e(0).hypot(e(1)))
}

/// Simulates two laps of the foot walk (seed 1) with the extra `mems-sim` arguments and runs
/// it both ways; returns (off, report) JSON.
fn walk(dir: &Path, name: &str, extra: &[&str]) -> (serde_json::Value, serde_json::Value) {
    let path = dir.join(format!("{name}.csv"));
    let mut args = vec![
        "walk",
        "--laps",
        "2",
        "--rate",
        "200",
        "--seed",
        "1",
        "--accel-range",
        "16",
        "--gyro-range",
        "2000",
    ];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--out", path_arg(&path)]);
    run_ok("mems-sim", &args);
    let (off, on) = (offline(&path, "off"), offline(&path, "report"));
    assert_eq!(
        off["end_displacement_m"], on["end_displacement_m"],
        "{name}"
    );
    let ((s_off, e), (s_on, _)) = (sigma_and_error(&off), sigma_and_error(&on));
    eprintln!(
        "{name}: error {e:.3} m, 1-sigma {s_off:.3} m (off) -> {s_on:.3} m (report); {}",
        on["consistency"]
    );
    (off, on)
}

#[test]
fn a_consistent_walk_keeps_its_sigma_and_a_ten_times_noisier_one_widens_it() {
    let dir = std::env::temp_dir().join(unique_namespace("innovation-consistency"));
    std::fs::create_dir_all(&dir).unwrap();

    let (off, on) = walk(&dir, "nominal", &[]);
    let c = &on["consistency"];
    assert_eq!(c["lambda_max"].as_f64().unwrap(), 1.0, "{c}");
    assert!(c["zero_velocity"]["count"].as_u64().unwrap() > 1000, "{c}");
    assert!(
        c["zero_velocity"]["nis_per_dof"].as_f64().unwrap() < 1.0,
        "{c}"
    );
    assert_eq!(off["sigma_m"], on["sigma_m"]);
    let (sigma, error) = sigma_and_error(&on);
    assert!(
        error <= 1.515 * sigma,
        "nominal walk: {error} m outside 1.515 x {sigma} m"
    );

    let (off, on) = walk(
        &dir,
        "noisy",
        &["--accel-noise-ug", "3000", "--gyro-noise-dps", "0.1"],
    );
    let c = &on["consistency"];
    assert!(c["lambda_max"].as_f64().unwrap() > 2.0, "{c}");
    assert!(
        c["zero_velocity"]["nis_per_dof"].as_f64().unwrap() > 1.5,
        "{c}"
    );
    let (s_off, _) = sigma_and_error(&off);
    let (s_on, _) = sigma_and_error(&on);
    assert!(s_on > 1.5 * s_off, "1-sigma {s_off} m -> {s_on} m");
    std::fs::remove_dir_all(&dir).unwrap();
}
