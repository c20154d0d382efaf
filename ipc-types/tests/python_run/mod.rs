//! Runs a Python script against the package's `python/` module directory (shared by the
//! tests of the Python client).

use std::process::Command;

/// Runs `script` with python3, the package's `python/` directory as its first argument and
/// `args` after it; its standard output (panics with its standard error if it fails).
pub fn run_python(script: &str, args: &[&str]) -> String {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/python");
    let out = Command::new("python3")
        .args(["-c", script, dir])
        .args(args)
        .output()
        .expect("python3 must be installed");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}
