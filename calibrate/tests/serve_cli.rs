//! `mems-calibrate serve` refuses bad start-up input before it opens any service, with the
//! file or option named.

use std::process::Command;

fn serve(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_mems-calibrate"))
        .arg("serve")
        .args(args)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn serve_refuses_a_missing_or_invalid_calibration_and_bad_options() {
    let dir = std::env::temp_dir().join(format!("serve-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let missing = dir.join("missing.toml");
    let (ok, err) = serve(&["--calib", missing.to_str().unwrap()]);
    assert!(!ok && err.contains("missing.toml"), "{err}");
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "model = \"full\"\n").unwrap();
    let (ok, err) = serve(&["--calib", bad.to_str().unwrap()]);
    assert!(
        !ok && err.contains("bad.toml") && err.contains("missing field"),
        "{err}"
    );
    let (ok, err) = serve(&["--calib", bad.to_str().unwrap(), "--detector", "foo"]);
    assert!(!ok && err.contains("foo"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}
