//! `mems-record` records every service (raw, corrected, odometry, robot hints) and derives the
//! Foxglove pose;
//! the official Python `mcap` reader decodes the file with its JSON schemas.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use common::*;
use ipc_types::service;
use ipc_types::{
    CorrectedImuSample, OdometryState, RawImuSample, RobotHint, Stamps, corrected_flags,
    hint_flags, odometry_flags,
};
use recording::mcap::{Topic, read_all};
use serde_json::{Value, json};

const WAIT: Duration = Duration::from_secs(10);
/// The Python `mcap` version `.ci/run` installs (and these tests were run with).
const PYTHON_MCAP: &str = "mcap==1.6.0 mcap-protobuf-support==0.6.0";

/// What the fake stages sent.
struct Sent {
    raw: Vec<RawImuSample>,
    corrected: Vec<CorrectedImuSample>,
    odometry: Vec<OdometryState>,
    hints: Vec<RobotHint>,
}

/// A controller's hint every 10th raw sample: stationary (commanded) or moving at a speed.
fn hint_for(raw: &RawImuSample, seq: u64) -> RobotHint {
    let stationary = seq.is_multiple_of(3);
    RobotHint {
        stamps: Stamps {
            sample_ns: raw.stamps.sample_ns,
            acquired_ns: raw.stamps.sample_ns + 1_500,
            ..Stamps::default()
        },
        seq,
        forward_speed_mps: if stationary { 0.0 } else { 0.25 * seq as f64 },
        forward_speed_sigma_mps: 0.02,
        yaw_rate_rps: -0.125,
        yaw_rate_sigma_rps: 0.01,
        flags: hint_flags::SPEED_VALID
            | hint_flags::YAW_RATE_VALID
            | if stationary {
                hint_flags::STATIONARY | hint_flags::SOURCE_COMMANDED
            } else {
                0
            },
        reserved16: 0,
        reserved: 0,
    }
}

/// A corrected sample derived from a raw one (values are arbitrary but distinct per field).
fn corrected_from(raw: &RawImuSample) -> CorrectedImuSample {
    let g = 9.80665;
    CorrectedImuSample {
        stamps: Stamps {
            calibrated_ns: raw.stamps.sample_ns + 2_000,
            ..raw.stamps
        },
        seq: raw.seq,
        accel_mps2: raw.accel_g.map(|a| a * g),
        gyro_rps: raw.gyro_dps.map(f64::to_radians),
        temp_c: raw.temp_c,
        zs_mean_mps2: [0.01, -0.02, g],
        zs_std_mps2: [0.003, 0.004, 0.005],
        calib_id: 0xDEAD_BEEF_0123_4567,
        flags: corrected_flags::DETECTOR_READY
            | if raw.seq.is_multiple_of(2) {
                corrected_flags::ZERO_STATE
            } else {
                0
            },
        raw_flags: raw.flags,
        settles: 0,
        refined_accel_mps2: [0.001, -0.002, 0.003],
        refined_gyro_rps: [0.0001, -0.0002, 0.0003],
    }
}

/// An odometry state for a corrected sample: a slow turn about z while moving along x.
fn state_from(c: &CorrectedImuSample, flags: u16) -> OdometryState {
    let i = c.seq as f64;
    let half_yaw = 0.001 * i;
    OdometryState {
        stamps: Stamps {
            odometry_ns: c.stamps.calibrated_ns + 3_000,
            ..c.stamps
        },
        seq: c.seq,
        position_m: [0.01 * i, -0.002 * i, 0.125],
        position_sigma_m: [0.001 * i, 0.0015 * i, 0.0005],
        velocity_mps: [0.5, 0.0, -0.0],
        velocity_sigma_mps: [0.01, 0.01, 0.02],
        gravity_sensor_mps2: [0.0, 0.0, 9.80665],
        attitude_wxyz: [half_yaw.cos(), 0.0, 0.0, half_yaw.sin()],
        distance_m: 0.01 * i,
        flags: odometry_flags::ALIGNED | flags,
        reserved16: 0,
        rest_count: 3,
        hints_applied: c.seq as u32 / 10,
        hint_disagreements: 1,
    }
}

/// Runs `mems-record` while this process plays the three stages and a robot controller: `n`
/// samples on each service, plus one revised odometry state and a hint every 10th sample; stops
/// the recorder with SIGTERM once all has arrived.
fn record_fake_stack(test: &str, n: usize) -> (PathBuf, Sent) {
    let ns = namespace(test);
    let mcap = tmp(&format!("{test}.mcap"));
    let recorder = spawn(
        &mems_record(),
        &["--out", mcap.to_str().unwrap(), "--namespace", &ns],
    );
    let node = node();
    let open = |base: &str| service::full_name(&ns, base);
    let raw_svc = service::open::<RawImuSample>(&node, &open(service::RAW)).unwrap();
    let cor_svc = service::open::<CorrectedImuSample>(&node, &open(service::CORRECTED)).unwrap();
    let odo_svc = service::open::<OdometryState>(&node, &open(service::ODOMETRY)).unwrap();
    let raw_pub = service::publisher(&raw_svc).unwrap();
    let cor_pub = service::publisher(&cor_svc).unwrap();
    let odo_pub = service::publisher(&odo_svc).unwrap();
    let hint_svc = service::open::<RobotHint>(&node, &open(service::HINT)).unwrap();
    let hint_pub = service::hint_publisher(&hint_svc).unwrap();
    wait_for_subscribers::<RawImuSample>(&node, &ns, service::RAW, 1);
    wait_for_subscribers::<CorrectedImuSample>(&node, &ns, service::CORRECTED, 1);
    wait_for_subscribers::<OdometryState>(&node, &ns, service::ODOMETRY, 1);
    wait_for_subscribers::<RobotHint>(&node, &ns, service::HINT, 1);

    let raw = raw_samples(n, 0, 1000);
    let corrected: Vec<_> = raw.iter().map(corrected_from).collect();
    let mut odometry: Vec<_> = corrected.iter().map(|c| state_from(c, 0)).collect();
    // A revision of an earlier state, sent after the others: not a gap, not a reset.
    odometry.push(state_from(&corrected[n / 4], odometry_flags::REVISION));
    for s in &raw {
        raw_pub.send_copy(*s).unwrap();
    }
    for s in &corrected {
        cor_pub.send_copy(*s).unwrap();
    }
    for s in &odometry {
        odo_pub.send_copy(*s).unwrap();
    }
    let hints: Vec<RobotHint> = raw
        .iter()
        .step_by(10)
        .zip(0..)
        .map(|(r, seq)| hint_for(r, seq))
        .collect();
    for h in &hints {
        hint_pub.send_copy(*h).unwrap();
    }
    wait_until(WAIT, "every message in the file", || {
        read_all(&mcap).is_ok_and(|c| {
            c.raw.len() == n
                && c.corrected.len() == n
                && c.odometry.len() == n + 1
                && c.hints.len() == hints.len()
        })
    });
    recorder.signal(libc::SIGTERM);
    let (status, stdout) = recorder.wait(WAIT);
    assert!(status.success(), "mems-record failed: {stdout}");
    (
        mcap,
        Sent {
            raw,
            corrected,
            odometry,
            hints,
        },
    )
}

/// Every message of every service arrives exactly as sent, each odometry state (revision
/// included) arrives exactly as sent, each live state has its pose (the revision has its own
/// topic), and a revision is neither a gap nor a reset.
#[test]
fn every_service_is_recorded_with_the_pose() {
    let (mcap, sent) = record_fake_stack("services", 500);
    let contents = read_all(&mcap).unwrap();
    assert_eq!(contents.truncation, None);
    assert_eq!(contents.raw, sent.raw);
    assert_eq!(contents.corrected, recorded(&sent.corrected));
    assert_eq!(contents.odometry, recorded(&sent.odometry));
    assert_eq!(contents.hints, sent.hints);
    let mut run = recording::mcap::run::RunReader::open(&mcap).unwrap();
    run.next().unwrap().unwrap();
    let clock = run.clock().expect("anchored");
    let shown = displayed(live(&sent.odometry));
    // 500 states 1 ms apart from 5 s: one pose per 20 ms.
    assert_eq!(shown.len(), 25);
    let poses: Vec<Value> = shown
        .iter()
        .map(|s| pose_json(s, clock.unix_ns(s.stamps.sample_ns)))
        .collect();
    assert_eq!(json_values(&contents.poses), poses);
    assert_eq!(contents.events, [], "the publishers stayed: no event");
    // The revised pose, the transforms and the path: topics read_all does not decode.
    let path_messages = 1
        + (sent.odometry[sent.odometry.len() - 2].stamps.sample_ns
            - sent.odometry[0].stamps.sample_ns)
            / 500_000_000;
    assert_eq!(contents.other_messages, 1 + 25 + path_messages);
}

/// Messages as a recording gives them back (corrected samples and states at their quanta).
fn recorded<T: Topic + Clone>(messages: &[T]) -> Vec<T> {
    messages.iter().map(Topic::as_recorded).collect()
}

/// The states the Foxglove topics show, as recorded: the first of each 20 ms of sample time.
fn displayed<'a>(states: impl Iterator<Item = &'a OdometryState>) -> Vec<OdometryState> {
    let mut step = None;
    states
        .filter(|s| {
            step.replace(s.stamps.sample_ns / 20_000_000) != Some(s.stamps.sample_ns / 20_000_000)
        })
        .map(Topic::as_recorded)
        .collect()
}

/// The live (not revised) states.
fn live(states: &[OdometryState]) -> impl Iterator<Item = &OdometryState> {
    states
        .iter()
        .filter(|s| s.flags & odometry_flags::REVISION == 0)
}

/// Foxglove's time of Unix ns `t`, as our JSON form spells it.
fn time_json(t: u64) -> Value {
    json!({"sec": t / 1_000_000_000, "nsec": t % 1_000_000_000})
}

/// A state's position and attitude as Foxglove's `foxglove.Pose` (quaternion x, y, z, w).
fn pose_value(s: &OdometryState) -> Value {
    let [x, y, z] = s.position_m;
    let [w, qx, qy, qz] = s.attitude_wxyz;
    json!({"position": {"x": x, "y": y, "z": z}, "orientation": {"x": qx, "y": qy, "z": qz, "w": w}})
}

/// The `foxglove.PoseInFrame` of a state at Unix time `t`.
fn pose_json(s: &OdometryState, t: u64) -> Value {
    json!({"timestamp": time_json(t), "frame_id": "nav", "pose": pose_value(s)})
}

/// Runs the Python decoder on `mcap`; fails (does not skip) when the `mcap` package is missing.
fn python_decode(mcap: &Path) -> Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/decode_mcap.py");
    let output = Command::new("python3")
        .arg(&script)
        .arg(mcap)
        .output()
        .expect("cannot run python3: install Python 3 (CI: .ci/run)");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        output.status.code() != Some(3),
        "the Python packages `mcap` and `mcap-protobuf-support` are not installed: run .ci/run (CI installs {PYTHON_MCAP}) \
         or `python3 -m pip install {PYTHON_MCAP}`\n{stderr}"
    );
    assert!(output.status.success(), "decode_mcap.py failed:\n{stderr}");
    serde_json::from_slice(&output.stdout).unwrap()
}

/// The official Python reader opens the recording (its summary written by the clean finish),
/// decodes every message with its channel's schema (protobuf, with the decoder factory of
/// `mcap-protobuf-support`), and finds what was sent, with
/// publish_time = the sample time and log_time = the receive time, both Unix ns through the
/// clock the file's `mems.clock` metadata record states.
#[test]
fn python_mcap_reader_decodes_every_channel_with_its_schema() {
    let n = 120;
    let start_ns = ipc_types::clock::monotonic_ns();
    let (mcap, sent) = record_fake_stack("python", n);
    let end_ns = ipc_types::clock::monotonic_ns();
    let report = python_decode(&mcap);
    let clock = &report["metadata"]["mems.clock"];
    let field = |name: &str| clock[name].as_str().unwrap().parse::<i128>().unwrap();
    let (realtime, monotonic) = (field("realtime_ns"), field("monotonic_ns"));
    assert_eq!(field("offset_ns"), realtime - monotonic);
    assert!(monotonic >= i128::from(start_ns) && monotonic <= i128::from(end_ns));
    let unix = |t: u64| u64::try_from(i128::from(t) + realtime - monotonic).unwrap();

    let at = |s: &OdometryState| unix(s.stamps.sample_ns);
    // 120 states 1 ms apart from 5 s: one pose per 20 ms.
    let shown = displayed(live(&sent.odometry));
    assert_eq!(shown.len(), 6);
    let poses: Vec<Value> = shown.iter().map(|s| pose_json(s, at(s))).collect();
    let revised: Vec<Value> = displayed(
        sent.odometry
            .iter()
            .filter(|s| s.flags & odometry_flags::REVISION != 0),
    )
    .iter()
    .map(|s| pose_json(s, at(s)))
    .collect();
    let tf: Vec<Value> = shown
        .iter()
        .map(|s| {
            let p = pose_value(s);
            json!({
                "timestamp": time_json(at(s)),
                "parent_frame_id": "nav",
                "child_frame_id": "body",
                "translation": p["position"],
                "rotation": p["orientation"],
            })
        })
        .collect();
    // 120 states 1 ms apart, all aligned: one path message (every 2 s), of one pose (one
    // every 0.25 s), at the first state.
    let first = &sent.odometry[0].as_recorded();
    let path = vec![json!({
        "timestamp": time_json(at(first)),
        "frame_id": "nav",
        "poses": [pose_value(first)],
    })];
    let expect: [(&str, &str, Vec<Value>); 9] = [
        (service::RAW, "mems.RawImuSample", raw_as_stored(&sent.raw)),
        (
            service::CORRECTED,
            "mems.CorrectedImuSample",
            json_values(&recorded(&sent.corrected)),
        ),
        (
            service::ODOMETRY,
            "mems.OdometryState",
            json_values(&recorded(&sent.odometry)),
        ),
        ("mems/odometry/pose", "foxglove.PoseInFrame", poses),
        (
            "mems/odometry/revised_pose",
            "foxglove.PoseInFrame",
            revised,
        ),
        ("mems/odometry/tf", "foxglove.FrameTransform", tf),
        ("mems/odometry/path", "foxglove.PosesInFrame", path),
        (service::HINT, "mems.RobotHint", json_values(&sent.hints)),
        ("mems/recorder/events", "mems.RecorderEvent", vec![]),
    ];
    let channels = report["channels"].as_object().unwrap();
    assert_eq!(channels.len(), expect.len(), "{channels:?}");
    for (topic, schema, values) in &expect {
        let c = &channels[*topic];
        assert_eq!(c["schema_name"], *schema, "{topic}");
        assert_eq!(c["schema_encoding"], "protobuf", "{topic}");
        assert_eq!(c["message_encoding"], "protobuf", "{topic}");
        // A channel without messages may be absent from the statistics.
        assert_eq!(
            report["summary_counts"][*topic].as_u64().unwrap_or(0),
            values.len() as u64,
            "{topic}: the summary's statistics"
        );
        let messages = report["messages"][*topic]
            .as_array()
            .cloned()
            .unwrap_or_default();
        let decoded: Vec<&Value> = messages.iter().map(|m| &m["value"]).collect();
        // Floats compare exactly: both sides write shortest round-trip decimals.
        assert_eq!(decoded, values.iter().collect::<Vec<_>>(), "{topic}");
        for (m, v) in messages.iter().zip(values) {
            // Foxglove's messages carry Unix time; ours their monotonic stamps.
            let own_time = match v.get("timestamp") {
                Some(t) => t["sec"].as_u64().unwrap() * 1_000_000_000 + t["nsec"].as_u64().unwrap(),
                None => unix(v["stamps"]["sample_ns"].as_u64().unwrap()),
            };
            assert_eq!(m["publish_time"].as_u64(), Some(own_time), "{topic}");
            let log = m["log_time"].as_u64().unwrap();
            assert!(
                log > unix(start_ns) && log < unix(end_ns),
                "{topic}: log_time {log} is the receive time"
            );
        }
    }
    // The raw values, rebuilt from what Python decoded as docs/recording.md says, are the
    // values sent, bit for bit.
    let decoded = report["messages"][service::RAW].as_array().unwrap();
    for (m, sent) in decoded.iter().zip(&sent.raw) {
        let v = &m["value"];
        let rebuilt = |counts: &str, lsb: &str| -> Vec<u64> {
            let lsb = v[lsb].as_f64().unwrap();
            let counts = v[counts].as_array().unwrap();
            counts
                .iter()
                .map(|c| (c.as_f64().unwrap() / lsb).to_bits())
                .collect()
        };
        assert_eq!(
            rebuilt("accel_counts", "accel_lsb_per_g"),
            sent.accel_g.map(f64::to_bits)
        );
        assert_eq!(
            rebuilt("gyro_counts", "gyro_lsb_per_dps"),
            sent.gyro_dps.map(f64::to_bits)
        );
        let temp = v["temp_counts"].as_f64().unwrap() / 333.87 + 21.0;
        assert_eq!(temp.to_bits(), sent.temp_c.to_bits());
    }
}

/// Raw samples as the file stores them (their values are what the counts give): the
/// sensitivities instead of the values.
fn raw_as_stored(samples: &[RawImuSample]) -> Vec<Value> {
    json_values(samples)
        .into_iter()
        .map(|mut v| {
            v["accel_g"] = json!([]);
            v["gyro_dps"] = json!([]);
            v["temp_c"] = Value::Null;
            v["accel_lsb_per_g"] = json!(16384.0);
            v["gyro_lsb_per_dps"] = json!(131.0);
            v["temp_from_counts"] = json!(true);
            v
        })
        .collect()
}

/// Messages as serde JSON values.
fn json_values<T: serde::Serialize>(messages: &[T]) -> Vec<Value> {
    messages
        .iter()
        .map(|m| serde_json::to_value(m).unwrap())
        .collect()
}
