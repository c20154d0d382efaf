//! `--profile auto` (the default) through the real binaries: `mems-odometry offline` recognizes
//! the platform of simulated recordings written by `mems-sim`: a walk with the IMU on a foot is
//! a foot (profile pedestrian, from the whole recording), a drive with turns is wheeled
//! (profile vehicle, decided as live after 10 s of motion), and a sensor turned by hand or an
//! arm through orientations, held 6 s each, is neither (profile other). The choice and its
//! figures are in the `--json` result.

use integration_tests::{offline_json, path_arg, simulate, unique_namespace};

/// Writes `mems-sim ARGS --rate 100 --seed 2 --out DIR/NAME.mcap` and returns what
/// `mems-odometry offline --json` says of its profile.
fn profile_of(dir: &std::path::Path, name: &str, args: &[&str]) -> serde_json::Value {
    let common = ["--rate", "100", "--seed", "2"];
    let out = simulate(dir, &format!("{name}.mcap"), &[args, &common[..]].concat());
    offline_json(&out, &[])["profile"].clone()
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

/// Live: a simulated drive replayed (`mems-replay --max`) into `mems-calibrate serve` ->
/// `mems-odometry serve` (no `--profile`: auto) is recognized as wheeled after 10 s of motion,
/// said on the odometry process's stderr, and its exit summary names the profile it ran.
#[test]
fn live_auto_decides_wheeled_on_a_replayed_drive_and_says_so() {
    use integration_tests::{Proc, calibrate_sim_part};
    use std::time::Duration;
    let ns = unique_namespace("platform-live");
    let dir = std::env::temp_dir().join(&ns);
    std::fs::create_dir_all(&dir).unwrap();
    let calib = calibrate_sim_part(&dir, 78);
    let calib = path_arg(&calib);
    let drive = simulate(
        &dir,
        "drive.mcap",
        &[
            "drive",
            "--duration",
            "300",
            "--turns",
            "on",
            "--rate",
            "200",
            "--seed",
            "1",
        ],
    );
    let log = dir.join("odometry.log");
    let ns_args = ["--namespace", ns.as_str()];
    let odometry = Proc::spawn_logged(
        "mems-odometry",
        &[&["serve", "--calib", calib][..], &ns_args].concat(),
        &log,
    );
    let calibrate = Proc::spawn(
        "mems-calibrate",
        &[&["serve", "--calib", calib][..], &ns_args].concat(),
    );
    let (status, out) = Proc::spawn(
        "mems-replay",
        &[
            &[path_arg(&drive), "--max", "--wait-subscribers", "1"][..],
            &ns_args,
        ]
        .concat(),
    )
    .wait(Duration::from_secs(120));
    assert!(status.success(), "mems-replay failed: {status}: {out}");
    // The decision comes at the drive's tenth second of motion, long before its end: wait for
    // the odometry to reach it (it may lag the replay on a loaded machine).
    let decided = "--profile auto: wheeled platform after 10 s of motion";
    integration_tests::wait_until(Duration::from_secs(60), "the live decision", || {
        std::fs::read_to_string(&log).is_ok_and(|s| s.contains(decided))
    });
    for p in [calibrate, odometry] {
        p.signal(libc::SIGTERM);
        let (status, _) = p.wait(Duration::from_secs(20));
        assert!(status.success(), "a stage failed: {status}");
    }
    let stderr = std::fs::read_to_string(&log).unwrap();
    assert!(stderr.contains(decided), "{stderr}");
    assert!(
        stderr.contains("profile auto: wheeled platform, ran profile vehicle"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
