//! Wall-clock anchors of the recordings written outside the recorder: `mems-sim --out F.mcap`
//! anchors its file at the time it is written, `mems-odometry offline --out F.mcap` copies its
//! input's anchor (an input without one gives an unanchored file). Real processes, real MCAP
//! files read back by `mems-info --json` and `recording::mcap::run::clock_of`.
//!
//! Needs the workspace binaries (`cargo build --release -p mems-sim -p calibrate
//! -p calibrate-science -p odometry -p mems-info`).

use std::time::{SystemTime, UNIX_EPOCH};

use integration_tests::{calibrate_sim_part, path_arg, run_ok, unique_namespace};
use recording::mcap::run::clock_of;

fn unix_ns_now() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64
}

/// `mems-info --json` of `path`: its `wall_clock` object (null when unanchored).
fn wall_clock(path: &std::path::Path) -> serde_json::Value {
    let out = run_ok("mems-info", &[path_arg(path), "--json"]);
    let info: serde_json::Value = serde_json::from_str(out.trim()).expect("JSON");
    info["wall_clock"].clone()
}

#[test]
fn simulated_and_offline_recordings_are_wall_clock_anchored() {
    let ns = unique_namespace("anchors");
    let dir = std::env::temp_dir().join(&ns);
    std::fs::create_dir_all(&dir).unwrap();
    let calib = calibrate_sim_part(&dir, 7);
    let (sim, out, csv, csv_out) = (
        dir.join("drive.mcap"),
        dir.join("states.mcap"),
        dir.join("drive.csv"),
        dir.join("csv-states.mcap"),
    );

    // The simulator: scenario time 0 at the time the file is written.
    let before = unix_ns_now();
    for file in [&sim, &csv] {
        let args = [
            "static",
            "--preset",
            "datasheet",
            "--seed",
            "7",
            "--duration",
            "12",
        ];
        run_ok(
            "mems-sim",
            &[&args[..], &["--out", path_arg(file)]].concat(),
        );
    }
    let after = unix_ns_now();
    let clock = clock_of(&sim)
        .unwrap()
        .expect("the simulated MCAP is anchored");
    assert_eq!(clock.monotonic_ns, 0, "anchored at scenario time 0");
    assert!((before..=after).contains(&clock.realtime_ns), "{clock:?}");
    let info = wall_clock(&sim);
    let start_utc = info["start_utc"].as_str().expect("a UTC start date");
    assert_eq!(start_utc, recording::clock::utc(clock.realtime_ns));
    assert!(
        start_utc.ends_with('Z') && start_utc.len() == 30,
        "{start_utc}"
    );

    // Offline: the output carries its input's anchor; a CSV input gives an unanchored file.
    for (input, output) in [(&sim, &out), (&csv, &csv_out)] {
        let args = ["offline", "--calib", path_arg(&calib), "--input"];
        let tail = [path_arg(input), "--out", path_arg(output), "--force"];
        run_ok("mems-odometry", &[&args[..], &tail].concat());
    }
    assert_eq!(clock_of(&out).unwrap(), Some(clock));
    assert_eq!(wall_clock(&out)["start_utc"], info["start_utc"]);
    assert_eq!(clock_of(&csv_out).unwrap(), None);
    assert!(wall_clock(&csv_out).is_null());
    // The stamps inside the messages stay as the input's (monotonic), anchor or not.
    let (a, b) = (
        recording::mcap::read_all(&out).unwrap(),
        recording::mcap::read_all(&csv_out).unwrap(),
    );
    assert_eq!(a.raw, recording::mcap::read_all(&sim).unwrap().raw);
    assert_eq!(a.odometry.len(), b.odometry.len());
    assert_eq!(a.odometry.last(), b.odometry.last());
    std::fs::remove_dir_all(&dir).unwrap();
}
