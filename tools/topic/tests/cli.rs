//! The `mems-topic` binary's command line: unknown services are refused with a clear message.

use std::process::Command;

#[test]
fn unknown_service_is_refused() {
    let out = Command::new(env!("CARGO_BIN_EXE_mems-topic"))
        .args(["hz", "mems/imu/nonsense", "--duration", "0.1"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("unknown service \"mems/imu/nonsense\""),
        "{err}"
    );
}
