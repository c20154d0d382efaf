//! `--profile auto` (the default) through the real binaries: `mems-odometry offline` recognizes
//! the platform of simulated recordings written by `mems-sim`: a walk with the IMU on a foot is
//! a foot (profile pedestrian, from the whole recording), a drive with turns is wheeled
//! (profile vehicle, decided as live after 10 s of motion), and a sensor turned by hand or an
//! arm through orientations, held 6 s each, is neither (profile other). The choice and its
//! figures are in the `--json` result.

use integration_tests::{path_arg, run_ok, unique_namespace};

/// Writes `mems-sim ARGS --rate 100 --seed 2 --out DIR/NAME.mcap` and returns what
/// `mems-odometry offline --json` says of its profile.
fn profile_of(dir: &std::path::Path, name: &str, args: &[&str]) -> serde_json::Value {
    let out = dir.join(format!("{name}.mcap"));
    let common = ["--rate", "100", "--seed", "2", "--out", path_arg(&out)];
    run_ok("mems-sim", &[args, &common[..]].concat());
    let json = run_ok(
        "mems-odometry",
        &["offline", "--input", path_arg(&out), "--json"],
    );
    let v: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    v["profile"].clone()
}

#[test]
fn auto_tells_a_foot_a_wheeled_robot_and_an_arm_apart() {
    let dir = std::env::temp_dir().join(unique_namespace("platform"));
    std::fs::create_dir_all(&dir).unwrap();
    let walk = profile_of(&dir, "walk", &["walk", "--laps", "1"]);
    let drive = profile_of(
        &dir,
        "drive",
        &["drive", "--duration", "300", "--turns", "on"],
    );
    let arm = profile_of(&dir, "arm", &["orientations", "--n", "10", "--hold", "6"]);
    for (v, platform, profile) in [
        (&walk, "foot", "pedestrian"),
        (&drive, "wheeled", "vehicle"),
        (&arm, "other", "other"),
    ] {
        assert!(v["chosen_by"].as_str().unwrap().starts_with("auto"), "{v}");
        assert_eq!(v["platform"]["platform"], platform, "{v}");
        assert_eq!(v["profile"], profile, "{v}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
