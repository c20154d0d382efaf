//! `mems-odometry offline` as a process on files holding values no sensor produces: each exits
//! non-zero with a message naming the file, the line and the field (or the calibration file and
//! its field); the same command on the clean file succeeds.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use calibrate::calibfile::CalibrationFile;

/// A scratch directory for this test binary.
fn scratch() -> PathBuf {
    let dir = std::env::temp_dir().join(format!("bad-files-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A canonical CSV of 12 s at 200 Hz, level and at rest, with white noise at the MPU-9250's
/// levels (3 mg, 0.1 deg/s per sample; a fixed xorshift sequence); `spoil` may change any row's
/// cells (row index, then the cells).
fn csv(path: &Path, spoil: impl Fn(usize, &mut Vec<String>)) {
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut noise = |sigma: f64| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        // Uniform on (-0.5, 0.5) has sigma 1/sqrt(12).
        ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * sigma * 12f64.sqrt()
    };
    let mut text = String::from("t_s,ax_g,ay_g,az_g,gx_dps,gy_dps,gz_dps\n");
    for k in 0..ROWS {
        let mut cells: Vec<String> = vec![format!("{}", 1.0 + k as f64 * 0.005)];
        cells.extend((0..3).map(|i| format!("{}", f64::from(u8::from(i == 2)) + noise(0.003))));
        cells.extend((0..3).map(|_| format!("{}", noise(0.1))));
        spoil(k, &mut cells);
        text.push_str(&cells.join(","));
        text.push('\n');
    }
    std::fs::write(path, text).unwrap();
}

/// Rows of the test files, and the one spoiled (line `BAD_ROW + 2`).
const ROWS: usize = 2400;
const BAD_ROW: usize = 1500;

fn offline(input: &Path, calib: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mems-odometry"))
        .args(["offline", "--input"])
        .arg(input)
        .arg("--calib")
        .arg(calib)
        .args(["--learn-s", "1"])
        .output()
        .unwrap()
}

/// Asserts a failure whose stderr names every one of `what`.
fn assert_refused(out: &Output, what: &[&str]) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "exit 0 with {err}");
    for w in what {
        assert!(err.contains(w), "{w:?} not in: {err}");
    }
}

#[test]
fn absurd_samples_and_calibrations_stop_the_offline_run_naming_file_line_and_field() {
    let dir = scratch();
    let calib = dir.join("calib.toml");
    CalibrationFile::identity(9.80665).save(&calib).unwrap();
    let clean = dir.join("clean.csv");
    csv(&clean, |_, _| {});
    let out = offline(&clean, &calib);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    // The header is line 1.
    let line = format!(":{}", BAD_ROW + 2);
    let cases: [(&str, usize, &str, &str); 4] = [
        ("1e300", 2, "ay_g", "1e300"),
        ("100", 3, "az_g", "100"),
        ("-9000", 4, "gx_dps", "-9000"),
        ("3601.5", 0, "t_s", "steps longer than 60 s"),
    ];
    for (i, (value, column, field, shown)) in cases.into_iter().enumerate() {
        let input = dir.join(format!("bad_{i}.csv"));
        csv(&input, |k, cells| {
            if k >= BAD_ROW && (k == BAD_ROW || column == 0) {
                cells[column] = if column == 0 {
                    format!("{}", 3601.5 + (k - BAD_ROW) as f64 * 0.005)
                } else {
                    value.to_owned()
                };
            }
        });
        let name = input.file_name().unwrap().to_str().unwrap();
        let field = format!("field \"{field}\"");
        assert_refused(&offline(&input, &calib), &[name, &line, &field, shown]);
    }

    type Spoil = fn(&mut CalibrationFile);
    let spoiled: [(&str, Spoil); 3] = [
        ("scale[0][0]", |f| f.scale[0][0] = 1e300),
        ("scale[0][0]", |f| f.scale[0][0] = -1.0),
        ("gyro.correction[0][0]", |f| {
            f.gyro.correction = Some([[0.0; 3]; 3])
        }),
    ];
    for (i, (field, spoil)) in spoiled.into_iter().enumerate() {
        let bad = dir.join(format!("bad_{i}.toml"));
        let mut f = CalibrationFile::identity(9.80665);
        spoil(&mut f);
        f.save(&bad).unwrap();
        let name = bad.file_name().unwrap().to_str().unwrap();
        assert_refused(&offline(&clean, &bad), &[name, field]);
    }

    std::fs::remove_dir_all(&dir).unwrap();
}

/// A run that fails leaves no `--out` file (nor its temporary file) behind.
#[test]
fn a_failed_run_leaves_no_out_file() {
    let dir = scratch();
    let calib = dir.join("calib.toml");
    CalibrationFile::identity(9.80665).save(&calib).unwrap();
    let input = dir.join("failing.csv");
    csv(&input, |k, cells| {
        if k == BAD_ROW {
            cells[2] = "1e300".to_owned();
        }
    });
    let out_dir = dir.join("failed-out");
    std::fs::create_dir_all(&out_dir).unwrap();
    let out = out_dir.join("states.mcap");
    let run = Command::new(env!("CARGO_BIN_EXE_mems-odometry"))
        .args(["offline", "--input"])
        .arg(&input)
        .arg("--calib")
        .arg(&calib)
        .args(["--learn-s", "1", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_refused(&run, &["failing.csv"]);
    let left: Vec<_> = std::fs::read_dir(&out_dir).unwrap().flatten().collect();
    assert!(left.is_empty(), "a failed run left {left:?}");
}
