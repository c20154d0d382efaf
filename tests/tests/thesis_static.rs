//! The thesis's real 60 s static recordings through the whole offline pipeline (model 3 fitted
//! on the trial's own six-position means, torn reads repaired, Yu et al.'s detector as in the
//! thesis, zero-velocity updates): the end displacement stays under 1 cm on every trial,
//! against tens of metres without the updates.

use std::path::PathBuf;

use integration_tests::{run_ok, unique_namespace};

fn data_dir() -> Option<PathBuf> {
    test_support::shared_data("data/capstone/Six-Position-Test/data")
}

fn end_displacement(calib: &str, input: &str, zupt: bool) -> [f64; 3] {
    let mut args = vec![
        "offline",
        "--calib",
        calib,
        "--input",
        input,
        "--detector",
        "yu",
        "--repair-torn-reads",
        "--json",
    ];
    if !zupt {
        args.push("--no-zupt");
    }
    let v: serde_json::Value = serde_json::from_str(run_ok("mems-odometry", &args).trim()).unwrap();
    std::array::from_fn(|i| v["end_displacement_m"][i].as_f64().unwrap())
}

#[test]
fn zero_velocity_updates_hold_the_static_files_under_a_centimetre() {
    let Some(data) = data_dir() else { return };
    let dir = std::env::temp_dir().join(unique_namespace("thesis"));
    std::fs::create_dir_all(&dir).unwrap();
    for trial in 1..=3 {
        let six = data.join(format!("trial_{trial}/six_position_data_{trial}.csv"));
        let test = data.join(format!("trial_{trial}/six_position_test_data_{trial}.csv"));
        let calib = dir.join(format!("calib_{trial}.toml"));
        let calib = calib.to_str().unwrap();
        run_ok(
            "mems-calibrate",
            &[
                "fit",
                "--input",
                six.to_str().unwrap(),
                "--model",
                "full",
                "--gravity",
                "9.797",
                "--out",
                calib,
            ],
        );
        let with = end_displacement(calib, test.to_str().unwrap(), true);
        let norm = with.iter().map(|x| x * x).sum::<f64>().sqrt();
        assert!(
            norm < 0.01,
            "trial {trial}: {with:?} m with zero-velocity updates"
        );
        let without = end_displacement(calib, test.to_str().unwrap(), false);
        let norm_without = without.iter().map(|x| x * x).sum::<f64>().sqrt();
        assert!(
            norm_without > 1.0,
            "trial {trial}: only {without:?} m without updates"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
