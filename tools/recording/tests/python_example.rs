//! The README's Python reader example (`tools/recording/python/read_recording.py`) on a
//! recording written by our writer, protobuf and JSON (older recordings): it decodes every
//! channel with its decoder factories and finds the last live position (revisions skipped).
//! Fails, not skips, without the `mcap` and `mcap-protobuf-support` packages (`.ci/run`
//! installs them).

use std::path::Path;
use std::process::Command;

use ipc_types::{OdometryState, RawImuSample, Stamps, odometry_flags};
use recording::mcap::{MessageEncoding, Writer};

#[test]
fn the_python_example_reads_every_channel() {
    reads(MessageEncoding::Protobuf, "protobuf");
    reads(MessageEncoding::Json, "json");
}

fn reads(encoding: MessageEncoding, name: &str) {
    let dir = std::env::temp_dir().join(format!("python-example-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("run.mcap");
    let mut writer = Writer::create(&path).unwrap().with_encoding(encoding);
    let raw = writer.add_channel::<RawImuSample>().unwrap();
    let odometry = writer.add_channel::<OdometryState>().unwrap();
    for seq in 0..10u64 {
        let stamps = Stamps {
            sample_ns: 1_000 + seq,
            ..Stamps::default()
        };
        let sample = RawImuSample {
            stamps,
            seq,
            ..RawImuSample::default()
        };
        writer.write(raw, &sample, 2_000 + seq).unwrap();
        let state = OdometryState {
            stamps,
            seq,
            position_m: [seq as f64, -0.5, 0.25],
            position_sigma_m: [0.01, 0.02, 0.03],
            attitude_wxyz: [1.0, 0.0, 0.0, 0.0],
            ..OdometryState::default()
        };
        writer.write(odometry, &state, 2_000 + seq).unwrap();
    }
    // A revision after the last live state must not be taken for it.
    let revision = OdometryState {
        position_m: [99.0, 0.0, 0.0],
        flags: odometry_flags::REVISION,
        attitude_wxyz: [1.0, 0.0, 0.0, 0.0],
        ..OdometryState::default()
    };
    writer.write(odometry, &revision, 3_000).unwrap();
    writer.finish().unwrap();

    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("python/read_recording.py");
    let output = Command::new("python3")
        .arg(&script)
        .arg(&path)
        .output()
        .expect("cannot run python3: install Python 3 (CI: .ci/run)");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        output.status.success(),
        "read_recording.py failed on {name} (the `mcap` and `mcap-protobuf-support` packages: \
         .ci/run installs them):\n{stderr}"
    );
    assert_eq!(
        stdout.lines().collect::<Vec<_>>(),
        [
            "mems/imu/raw: 10",
            "mems/odometry/state: 11",
            "last position: (+9.000, -0.500, +0.250) m +- (0.010, 0.020, 0.030)",
        ],
        "{name}: {stdout}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
