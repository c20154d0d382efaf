//! Diagnostics of the real binaries on stderr: `RUST_LOG` filters them (info by default), and
//! a user error is one `<program>: error: ...` line with exit status 1, never a Debug dump or
//! a backtrace.

use std::path::Path;
use std::process::{Command, Output};

use integration_tests::{bin, path_arg, simulate, unique_namespace};

/// `mems-odometry offline` on `input` with `args`, `RUST_LOG` as given (unset with `None`) and
/// backtraces asked for (a user error must not print one even then).
fn offline(input: &Path, args: &[&str], rust_log: Option<&str>) -> Output {
    let mut cmd = Command::new(bin("mems-odometry"));
    cmd.args(["offline", "--input", path_arg(input)])
        .args(args)
        .env("RUST_BACKTRACE", "1");
    match rust_log {
        Some(level) => cmd.env("RUST_LOG", level),
        None => cmd.env_remove("RUST_LOG"),
    };
    cmd.output().expect("mems-odometry runs")
}

/// A short simulated drive in a fresh folder.
fn drive() -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(unique_namespace("diagnostics"));
    std::fs::create_dir_all(&dir).unwrap();
    simulate(
        &dir,
        "drive.csv",
        &["drive", "--duration", "20", "--rate", "200", "--seed", "3"],
    )
}

#[test]
fn rust_log_filters_info_lines_and_a_user_error_is_one_line() {
    let input = drive();
    // Without --calib the process says which calibration it uses: an info line.
    let note = "mems-odometry: no --calib: the identity calibration";
    let default = offline(&input, &[], None);
    let stderr = String::from_utf8_lossy(&default.stderr);
    assert!(default.status.success(), "{stderr}");
    assert!(
        stderr.contains(note),
        "info line missing at the default level:\n{stderr}"
    );
    let warn = offline(&input, &[], Some("warn"));
    let stderr = String::from_utf8_lossy(&warn.stderr);
    assert!(warn.status.success(), "{stderr}");
    assert!(
        !stderr.contains(note),
        "RUST_LOG=warn printed an info line:\n{stderr}"
    );
    // The same results on stdout whatever the level.
    assert_eq!(default.stdout, warn.stdout);

    // A missing calibration file: one error line naming it, status 1, no dump.
    let missing = input.with_file_name("missing-calib.toml");
    let failed = offline(&input, &["--calib", path_arg(&missing)], None);
    let stderr = String::from_utf8_lossy(&failed.stderr);
    assert_eq!(failed.status.code(), Some(1), "{stderr}");
    let errors: Vec<&str> = stderr.lines().filter(|l| l.contains("error")).collect();
    assert_eq!(errors.len(), 1, "{stderr}");
    assert!(
        errors[0].starts_with("mems-odometry: error: cannot load calibration")
            && errors[0].contains("missing-calib.toml"),
        "{stderr}"
    );
    for dump in ["Caused by", "Stack backtrace", "Error {", "panicked"] {
        assert!(!stderr.contains(dump), "{dump:?} on stderr:\n{stderr}");
    }
}
