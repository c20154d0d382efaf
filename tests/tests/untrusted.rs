//! Input the odometry must not take at its word, through `mems-odometry offline` as a user
//! runs it (docs/input-checks.md):
//! - a simulated walk whose gyroscope clips at +-250 deg/s (`mems-sim walk --gyro-range 250`):
//!   the clipped samples are flagged per axis and counted (stderr, JSON, and `mems-info` on
//!   the run's `--out` recording); each clipped swing is reconstructed at the rest after it
//!   (odometry/src/clip.rs) and the walk ends within 2x of the same walk's unclipped error,
//!   covered by its 1-sigma, where bridging the clips only ends metres off;
//! - the same walk written as a logger without flags or counts would (values only, clipped
//!   at +-250 deg/s by hand): the range is inferred from the readings stuck at the extreme,
//!   and the unclipped file trips nothing;
//! - a simulated drive with one sample at 19.99 g, and one with 1 s at 19.9 g (at a rest):
//!   implausible for the default profile, counted, bridged as unobserved, and the end error
//!   within 3 sigma (as the unspoiled drive's) where integrating them as measured ends 6 m
//!   and 512 m off.

use std::path::Path;
use std::process::Command;

use integration_tests::{
    bin, identity_calibration, path_arg, run_ok, simulate, simulate_in_scratch, unique_namespace,
};

/// `mems-odometry offline --json` on `input` with `args`: the JSON result and stderr.
fn offline(input: &Path, args: &[&str]) -> (serde_json::Value, String) {
    let out = Command::new(bin("mems-odometry"))
        .args([
            "offline",
            "--json",
            "--calib",
            path_arg(&identity_calibration()),
        ])
        .arg("--input")
        .arg(input)
        .args(args)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{}: {stderr}", input.display());
    (serde_json::from_slice(&out.stdout).unwrap(), stderr)
}

fn vec3(v: &serde_json::Value) -> [f64; 3] {
    serde_json::from_value(v.clone()).unwrap()
}

fn horizontal(v: [f64; 3]) -> f64 {
    v[0].hypot(v[1])
}

/// Rewrites the CSV `src` into `dst` with `edit` applied to each data row's cells (the header
/// names them).
fn rewrite(src: &Path, dst: &Path, edit: impl Fn(&[&str], &mut Vec<String>)) {
    let text = std::fs::read_to_string(src).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let mut out = String::with_capacity(text.len());
    let mut head = header.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    edit(&header, &mut head);
    out.push_str(&head.join(","));
    out.push('\n');
    for line in lines {
        let mut cells: Vec<String> = line.split(',').map(str::to_string).collect();
        edit(&header, &mut cells);
        out.push_str(&cells.join(","));
        out.push('\n');
    }
    std::fs::write(dst, out).unwrap();
}

#[test]
fn a_walk_clipped_at_250_dps_is_flagged_counted_and_reconstructed() {
    let dir = std::env::temp_dir().join(unique_namespace("clipped-walk"));
    std::fs::create_dir_all(&dir).unwrap();
    let walk = |name, range| {
        simulate(
            &dir,
            name,
            &[
                "walk",
                "--rate",
                "200",
                "--seed",
                "3",
                "--accel-range",
                "16",
                "--gyro-range",
                range,
            ],
        )
    };
    let clipped = walk("walk-250.csv", "250");
    let states = dir.join("walk-250.mcap");
    let (v, stderr) = offline(
        &clipped,
        &["--profile", "pedestrian", "--out", path_arg(&states)],
    );
    let flagged = v["clipped_samples"].as_u64().unwrap();
    let gy = v["clipped_per_axis"]["gy"].as_u64().unwrap();
    assert!(flagged > 100 && gy > 100, "{v}");
    assert_eq!(v["clipped_per_axis"]["ax"], 0, "{v}");
    assert!(
        stderr.contains(&format!(
            "{flagged} samples clipped at the end of their range"
        )),
        "{stderr}"
    );
    // The recording the run wrote says so too: the raw samples per axis, the corrected
    // samples CLIPPED, the states UNTRUSTED_INPUT.
    let info = run_ok("mems-info", &["--json", path_arg(&states)]);
    let info: serde_json::Value = serde_json::from_str(info.trim()).unwrap();
    assert_eq!(info["raw"]["clipped"]["samples"], flagged, "{info}");
    assert_eq!(info["raw"]["clipped"]["per_axis"][4], gy, "{info}");
    assert_eq!(
        info["topics"]["mems/imu/corrected"]["untrusted"], flagged,
        "{info}"
    );
    assert!(
        info["topics"]["mems/odometry/state"]["untrusted"]
            .as_u64()
            .unwrap()
            > 0,
        "{info}"
    );
    // Integrated as measured, the filter's 1-sigma knows nothing of the clips (only the
    // innovations' consistency, off here, would widen it afterwards); bridged only, it holds
    // their loss (but does not cover the error of a gyroscope clipped at every step).
    let (trusted, _) = offline(
        &clipped,
        &[
            "--profile",
            "pedestrian",
            "--trust-clipped",
            "--innovation-scaling",
            "off",
        ],
    );
    assert_eq!(trusted["clipped_samples"], flagged);
    let (bridged, bridged_stderr) =
        offline(&clipped, &["--profile", "pedestrian", "--bridge-clipped"]);
    assert!(
        bridged_stderr.contains("not reconstructed (--bridge-clipped)")
            && !bridged_stderr.contains("reconstructed at the rest"),
        "{bridged_stderr}"
    );
    assert!(stderr.contains("reconstructed at the rest"), "{stderr}");
    let (bs, ts) = (vec3(&bridged["sigma_m"]), vec3(&trusted["sigma_m"]));
    assert!(
        horizontal(bs) > 2.0 * horizontal(ts),
        "sigma {bs:?} against {ts:?}"
    );
    assert_eq!(bridged["clipped_runs"]["reconstructed"], 0, "{bridged}");

    // Reconstructed at the rests: within 2x of the unclipped walk's error, and covered (the
    // 68 % radius of the horizontal 1-sigma, as tools/real-data/bench.py's).
    let runs = v["clipped_runs"]["reconstructed"].as_u64().unwrap();
    assert!(runs > 20, "{v}");
    let clean = walk("walk-2000.csv", "2000");
    let (u, _) = offline(&clean, &["--profile", "pedestrian"]);
    let error = horizontal(vec3(&v["truth_error_m"]));
    let clean_error = horizontal(vec3(&u["truth_error_m"]));
    let s = vec3(&v["sigma_m"]);
    let r68 = 1.515 * ((s[0] * s[0] + s[1] * s[1]) / 2.0).sqrt();
    assert!(
        error <= 2.0 * clean_error,
        "reconstructed {error} m against unclipped {clean_error} m"
    );
    assert!(
        error <= r68,
        "error {error} m outside the 68 % radius {r68} m"
    );
    let bridged_error = horizontal(vec3(&bridged["truth_error_m"]));
    assert!(
        bridged_error > 2.0 * clean_error,
        "bridged only {bridged_error} m: the test no longer tells reconstruction apart"
    );

    // The unclipped walk trips nothing.
    assert_eq!(u["clipped_samples"], 0, "{u}");
    assert_eq!(u["implausible_samples"], 0, "{u}");
    assert_eq!(u["clipped_runs"]["reconstructed"], 0, "{u}");
}

#[test]
fn a_range_is_inferred_from_a_logger_file_without_flags() {
    let (dir, walk) = simulate_in_scratch(
        "inferred-range",
        "walk.csv",
        &[
            "walk",
            "--rate",
            "200",
            "--seed",
            "5",
            "--accel-range",
            "16",
            "--gyro-range",
            "2000",
        ],
    );
    // A logger's file: time and values only.
    let keep = ["t_s", "ax_g", "ay_g", "az_g", "gx_dps", "gy_dps", "gz_dps"];
    let values = |header: &[&str], cells: &mut Vec<String>, clip: Option<f64>| {
        let kept: Vec<String> = header
            .iter()
            .zip(cells.iter())
            .filter(|(h, _)| keep.contains(h))
            .map(
                |(h, c)| match (clip, h.starts_with('g'), c.parse::<f64>()) {
                    (Some(limit), true, Ok(x)) => x.clamp(-limit, limit).to_string(),
                    _ => c.clone(),
                },
            )
            .collect();
        *cells = kept;
    };
    let plain = dir.join("plain.csv");
    rewrite(&walk, &plain, |h, c| values(h, c, None));
    let cut = dir.join("cut.csv");
    rewrite(&walk, &cut, |h, c| values(h, c, Some(250.0)));

    let (v, _) = offline(&plain, &["--profile", "pedestrian"]);
    assert_eq!(v["ranges"]["gyro_dps"]["source"], "unknown", "{v}");
    assert_eq!(v["clipped_samples"], 0, "{v}");
    let (v, stderr) = offline(&cut, &["--profile", "pedestrian"]);
    assert_eq!(v["ranges"]["gyro_dps"]["source"], "inferred", "{v}");
    assert_eq!(v["ranges"]["gyro_dps"]["value"], 250.0, "{v}");
    assert_eq!(v["ranges"]["accel_g"]["source"], "unknown", "{v}");
    assert!(v["clipped_per_axis"]["gy"].as_u64().unwrap() > 100, "{v}");
    assert!(
        stderr.contains("gyroscope range +-250 deg/s inferred"),
        "{stderr}"
    );
    // Stated on the command line, the range is the caller's.
    let (v, _) = offline(
        &cut,
        &["--profile", "pedestrian", "--gyro-range-dps", "250"],
    );
    assert_eq!(v["ranges"]["gyro_dps"]["source"], "given", "{v}");
}

#[test]
fn absurd_specific_forces_are_flagged_counted_and_covered() {
    let dir = std::env::temp_dir().join(unique_namespace("absurd"));
    std::fs::create_dir_all(&dir).unwrap();
    let drive = simulate(
        &dir,
        "drive.csv",
        &["drive", "--duration", "120", "--rate", "200", "--seed", "3"],
    );
    // The drive rests from 69.2 to 86.6 s.
    for (what, from_s, to_s, value, count, trusted_off_m) in [
        ("one sample at 19.99 g", 72.0, 72.0025, "19.99", 1, 5.0),
        ("1 s at 19.9 g", 72.0, 72.9999, "19.9", 200, 400.0),
    ] {
        let bad = dir.join(format!("{value}.csv"));
        rewrite(&drive, &bad, |header, cells| {
            let (t, ax) = (header.iter().position(|h| *h == "t_s").unwrap(), 1);
            if let Ok(t) = cells[t].parse::<f64>()
                && (from_s - 1e-6..to_s).contains(&t)
            {
                cells[ax] = value.to_string();
            }
        });
        let (v, stderr) = offline(&bad, &[]);
        assert_eq!(v["implausible_samples"], count, "{what}: {v}");
        let first = v["first_implausible"]["t_s"].as_f64().unwrap();
        assert!((first - 72.0).abs() < 0.01, "{what}: {v}");
        assert!(
            stderr.contains("beyond what the profile's platforms do"),
            "{stderr}"
        );
        let (e, s) = (vec3(&v["truth_error_m"]), vec3(&v["sigma_m"]));
        for axis in 0..3 {
            assert!(
                e[axis].abs() <= 3.0 * s[axis],
                "{what}: axis {axis} error {} m against a 1-sigma of {} m",
                e[axis],
                s[axis]
            );
        }
        // Integrated as measured, the same input ends far off.
        let (t, _) = offline(&bad, &["--trust-clipped"]);
        let te = vec3(&t["truth_error_m"]);
        assert!(te[0].abs() > trusted_off_m, "{what}: {te:?}");
    }
}
