//! A recording in the layout before `float`s (`tests/data/stack-f64.mcap`: 250 ms of a
//! `mems-stack` run recorded by that layout's recorder, revisions included, cut out with the
//! official Python writer; every raw value and every corrected and state quantity a protobuf
//! `double`) reads with today's reader, and every raw sample, corrected sample and state
//! equals, bit for bit, what the official Python reader decodes with the file's own schemas.
//! Fails, not skips, without the `mcap` and `mcap-protobuf-support` packages.

use std::path::Path;
use std::process::Command;

use recording::mcap::read_all;
use serde_json::Value;

/// Decodes every message of the three topics with the official reader, as JSON: each
/// field of the file's schema by name (Python's shortest round-trip floats).
const DECODE: &str = r#"
import json, sys
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

def plain(m):
    out = {}
    for f in m.DESCRIPTOR.fields:
        v = getattr(m, f.name)
        repeated = f.is_repeated if hasattr(f, "is_repeated") else f.label == f.LABEL_REPEATED
        out[f.name] = list(v) if repeated else plain(v) if f.message_type else v
    return out

topics = ["mems/imu/raw", "mems/imu/corrected", "mems/odometry/state"]
out = {t: [] for t in topics}
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f, decoder_factories=[DecoderFactory()])
    for _, channel, _, value in reader.iter_decoded_messages(topics=topics, log_time_order=False):
        out[channel.topic].append(plain(value))
json.dump(out, sys.stdout)
"#;

#[test]
fn an_older_f64_recording_reads_bit_for_bit() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/stack-f64.mcap");
    let contents = read_all(&path).unwrap();
    assert_eq!(contents.truncation, None);
    assert_eq!(contents.raw.len(), 248);
    assert_eq!(contents.corrected.len(), 248);
    assert_eq!(contents.odometry.len(), 268);
    let revisions = contents
        .odometry
        .iter()
        .filter(|s| s.flags & ipc_types::odometry_flags::REVISION != 0)
        .count();
    assert_eq!(revisions, 20);
    // The states' values are the file's doubles, not floats.
    let doubles = contents
        .odometry
        .iter()
        .flat_map(|s| s.gravity_sensor_mps2.into_iter().chain(s.attitude_wxyz))
        .filter(|&v| f64::from(v as f32) != v)
        .count();
    assert!(doubles > 0, "no value needs a double");

    let output = Command::new("python3")
        .args(["-c", DECODE])
        .arg(&path)
        .output()
        .expect("cannot run python3: install Python 3 (CI: .ci/run)");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        output.status.success(),
        "the official reader failed (the `mcap` and `mcap-protobuf-support` packages: .ci/run \
         installs them):\n{stderr}"
    );
    let mut python: Value = serde_json::from_slice(&output.stdout).unwrap();
    // The older schema held the state's padding field (always 0), which ours and the serde
    // form no longer show.
    for state in python["mems/odometry/state"].as_array_mut().unwrap() {
        let padding = state.as_object_mut().unwrap().remove("reserved16");
        assert!(
            padding.as_ref().is_none_or(|v| *v == 0),
            "padding {padding:?}"
        );
    }
    assert_eq!(python["mems/imu/raw"], values(&contents.raw));
    // The older layout had no refinement offsets: ours reads them as zero.
    let mut corrected = values(&contents.corrected);
    for sample in corrected.as_array_mut().unwrap() {
        for field in ["refined_accel_mps2", "refined_gyro_rps"] {
            let offset = sample.as_object_mut().unwrap().remove(field);
            assert_eq!(offset, Some(serde_json::json!([0.0, 0.0, 0.0])), "{field}");
        }
    }
    assert_eq!(python["mems/imu/corrected"], corrected);
    assert_eq!(python["mems/odometry/state"], values(&contents.odometry));
}

/// Messages in their JSON form (the field names the older schemas use).
fn values<T: serde::Serialize>(messages: &[T]) -> Value {
    serde_json::to_value(messages).unwrap()
}
