//! Holes in the time line: a simulated 120 s drive (`mems-sim drive`, canonical CSV at 200 Hz)
//! with rows cut out, nothing marking the cut, run through `mems-odometry offline` as a user
//! would. A hole of 3 or 5 s (at a rest, and while moving) is warned on stderr with its line,
//! length and time, counted in the JSON result (`input_holes`), bridged as a gap, and the end
//! error stays within 3 sigma on every axis; a hole of 30 s is beyond what the odometry bridges
//! (`Manoeuvre::bridge_limit_s`, 6.28 s for a ground robot) and the run is refused with the
//! file's line and the time. `mems-info` shows the hole of the raw samples that the offline
//! run wrote to its `--out` recording. A sensor that stops updating while it is read (rows
//! that repeat one reading for longer than a hole) is warned on stderr and counted in the JSON
//! result (`input_frozen`), and `mems-info` counts it in the raw samples (`raw.frozen`); three
//! repeated samples (a reader polling faster than the sensor) are not.

use std::path::{Path, PathBuf};
use std::process::Command;

use integration_tests::{bin, identity_calibration, path_arg, run_ok, simulate_in_scratch};

/// `src` without the rows whose time lies strictly within `start_s` .. `start_s + length_s`.
fn cut(src: &Path, dst: &Path, start_s: f64, length_s: f64) {
    let text = std::fs::read_to_string(src).unwrap();
    let mut out = String::with_capacity(text.len());
    for (i, line) in text.lines().enumerate() {
        let t: f64 = if i == 0 {
            f64::NAN
        } else {
            line.split(',').next().unwrap().parse().unwrap()
        };
        if !(t > start_s && t < start_s + length_s) {
            out.push_str(line);
            out.push('\n');
        }
    }
    std::fs::write(dst, out).unwrap();
}

/// A scratch directory named for `tag`, a simulated drive of `seconds` at 200 Hz in it
/// (canonical CSV, seed 3) and the identity calibration.
fn simulated_drive(tag: &str, seconds: &str) -> (PathBuf, PathBuf, PathBuf) {
    let args = [
        "drive",
        "--duration",
        seconds,
        "--rate",
        "200",
        "--seed",
        "3",
    ];
    let (dir, drive) = simulate_in_scratch(tag, "drive.csv", &args);
    (dir, drive, identity_calibration())
}

/// The line (1-based) of the first row at or after `t_s`.
fn line_at(src: &Path, t_s: f64) -> usize {
    let text = std::fs::read_to_string(src).unwrap();
    text.lines()
        .enumerate()
        .skip(1)
        .find(|(_, l)| l.split(',').next().unwrap().parse::<f64>().unwrap() >= t_s)
        .unwrap()
        .0
        + 1
}

#[test]
fn holes_are_bridged_with_an_honest_sigma_or_refused_naming_line_and_time() {
    let (dir, drive, calib) = simulated_drive("holes", "120");
    // The drive rests 0-10 s, 37.7-39.2 s, 69.2-86.6 s and from 105.9 s; it moves between.
    for (start_s, length_s) in [
        (72.0, 3.0),
        (20.0, 3.0),
        (72.0, 5.0),
        (20.0, 5.0),
        (72.0, 30.0),
        (20.0, 30.0),
    ] {
        let holed = dir.join(format!("hole-{start_s}-{length_s}.csv"));
        cut(&drive, &holed, start_s, length_s);
        let line = line_at(&holed, start_s + length_s);
        let states = dir.join(format!("states-{start_s}-{length_s}.mcap"));
        let out = Command::new(bin("mems-odometry"))
            .args(["offline", "--json", "--calib", path_arg(&calib), "--input"])
            .arg(&holed)
            .arg("--out")
            .arg(&states)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        let name = holed.file_name().unwrap().to_str().unwrap();
        let what = format!("hole of {length_s} s at {start_s} s");
        assert!(
            stderr.contains(&format!(
                "{name}: 1 hole in the time line that nothing marked"
            )) && stderr.contains(&format!("ending at line {line}"))
                && stderr.contains(&format!("the longest {length_s:.3} s")),
            "{what}: the warning names the hole, its line and length: {stderr}"
        );
        // The ground robot's bridge limit: pi over its 0.5 rad/s.
        if length_s > std::f64::consts::TAU {
            assert!(!out.status.success(), "{what}: refused");
            let t = start_s + length_s;
            assert!(
                stderr.contains(&format!("{name}:{line}: at t {t:.3} s"))
                    && stderr.contains("longer than the 6.28 s the odometry bridges"),
                "{what}: the refusal names the line and time: {stderr}"
            );
            assert!(!states.exists(), "{what}: a refused run leaves no --out");
            continue;
        }
        assert!(out.status.success(), "{what}: {stderr}");
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(v["input_holes"]["count"], 1, "{what}: {v}");
        assert_eq!(v["input_holes"]["longest"]["line"], line, "{what}: {v}");
        let length = v["input_holes"]["longest"]["length_s"].as_f64().unwrap();
        assert!((length - length_s).abs() < 0.01, "{what}: {length}");
        let error: Vec<f64> = serde_json::from_value(v["truth_error_m"].clone()).unwrap();
        let sigma: Vec<f64> = serde_json::from_value(v["sigma_m"].clone()).unwrap();
        for axis in 0..3 {
            assert!(
                error[axis].abs() <= 3.0 * sigma[axis],
                "{what}: axis {axis} error {} m beyond 3 sigma ({} m)",
                error[axis],
                sigma[axis]
            );
        }
        // The bridge widened the 1-sigma by the hole's physics: at least the position an
        // unobserved acceleration of 1 m/s^2 (the default manoeuvre) gives over the hole.
        let grown = 0.5 * length_s * length_s;
        assert!(
            sigma[0] > 0.8 * grown,
            "{what}: sigma {sigma:?}, expected ~{grown} m"
        );
        // mems-info reads the hole from the raw samples the run recorded.
        let info = run_ok("mems-info", &["--json", path_arg(&states)]);
        let info: serde_json::Value = serde_json::from_str(info.trim()).unwrap();
        let holes = &info["raw"]["holes"];
        assert_eq!(holes["count"], 1, "{what}: {info}");
        let dt = holes["longest"]["dt_ns"].as_f64().unwrap() * 1e-9;
        assert!((dt - length_s).abs() < 0.01, "{what}: mems-info {holes}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The simulated drive `csv` written as an MCAP recording at `dst`, the samples whose time lies
/// within each `(start_s, length_s)` repeating the first of them (accelerometer, gyroscope,
/// temperature and counts): a sensor that stopped updating while its reader went on. (A text
/// recording's reader drops rows that repeat the one before, a log repair, so the stretch would
/// reach the odometry as a hole.)
fn freeze(csv: &Path, dst: &Path, stretches: &[(f64, f64)]) {
    let samples = recording::load_raw(csv).unwrap().samples;
    let t0 = samples[0].stamps.sample_ns;
    let mut w = recording::mcap::Writer::create(dst).unwrap();
    let raw = w.add_channel::<ipc_types::RawImuSample>().unwrap();
    let mut held: Option<ipc_types::RawImuSample> = None;
    for s in &samples {
        let t = (s.stamps.sample_ns - t0) as f64 * 1e-9;
        let mut out = *s;
        match stretches.iter().any(|&(a, l)| t >= a && t < a + l) {
            true => {
                let h = held.get_or_insert(*s);
                (out.accel_g, out.gyro_dps, out.temp_c) = (h.accel_g, h.gyro_dps, h.temp_c);
                (out.accel_counts, out.gyro_counts) = (h.accel_counts, h.gyro_counts);
                out.temp_counts = h.temp_counts;
            }
            false => held = None,
        }
        w.write(raw, &out, out.stamps.sample_ns).unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn a_sensor_that_stops_updating_is_warned_and_counted() {
    let (dir, drive, calib) = simulated_drive("frozen", "60");
    let run = |input: &Path| {
        let out = Command::new(bin("mems-odometry"))
            .args(["offline", "--json", "--calib", path_arg(&calib), "--input"])
            .arg(input)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(out.status.success(), "{stderr}");
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        (v, stderr)
    };
    let clean = dir.join("clean.mcap");
    freeze(&drive, &clean, &[]);
    let (v, stderr) = run(&clean);
    assert_eq!(v["input_frozen"]["count"], 0, "{}", v["input_frozen"]);
    assert!(!stderr.contains("repeating one reading"), "{stderr}");
    // Three samples (10 ms at 200 Hz) held at 12 s, while moving: a hold, not counted; 1.5 s
    // from 20 s: one run, warned with its length and time.
    let frozen = dir.join("frozen.mcap");
    freeze(&drive, &frozen, &[(12.0, 0.011), (20.0, 1.5)]);
    let (v, stderr) = run(&frozen);
    assert_eq!(v["input_frozen"]["count"], 1, "{}", v["input_frozen"]);
    let length = v["input_frozen"]["longest"]["length_s"].as_f64().unwrap();
    assert!((length - 1.495).abs() < 0.003, "{}", v["input_frozen"]);
    let t = v["input_frozen"]["longest"]["t_s"].as_f64().unwrap();
    assert!((t - 21.495).abs() < 0.003, "{}", v["input_frozen"]);
    assert!(
        stderr.contains("frozen.mcap: 1 run of samples repeating one reading")
            && stderr.contains("the longest 1.495 s"),
        "{stderr}"
    );
    // mems-info finds the same run in the recording's raw samples, and none in the clean one.
    for (file, count, length_s) in [(&clean, 0, 0.0), (&frozen, 1, 1.495)] {
        let info = run_ok("mems-info", &["--json", path_arg(file)]);
        let info: serde_json::Value = serde_json::from_str(info.trim()).unwrap();
        let frozen = &info["raw"]["frozen"];
        assert_eq!(frozen["count"], count, "{info}");
        let dt = frozen["longest"]["dt_ns"].as_f64().unwrap_or(0.0) * 1e-9;
        assert!((dt - length_s).abs() < 0.003, "{frozen}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
