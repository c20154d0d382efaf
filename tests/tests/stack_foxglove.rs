//! `mems-stack --foxglove 127.0.0.1:PORT --record run.mcap` on the simulated MPU-9250: a
//! client of Foxglove's WebSocket protocol offering the specification's subprotocol name
//! `foxglove.websocket.v1` (Lichtblick's, the ws-protocol libraries') connects to the running
//! stack (a real client of the protocol, this test), publishes stationary robot hints from
//! the "app" (clientPublish), and receives the live odometry, which applies them. The
//! channels it was advertised have the same topics, message encodings, schema names and
//! schemas as the channels of the stack's own recording, so one Foxglove layout opens both.
//! Without the flag no view process runs (`stack_losses` checks that).

use std::collections::HashMap;
use std::time::{Duration, Instant};

use base64::Engine as _;
use integration_tests::foxglove::{Client, WEBSOCKET_V1};
use integration_tests::{Proc, child_named, free_port, unique_namespace};
use ipc_types::{OdometryState, hint_flags, odometry_flags};
use recording::mcap::{EVENTS_TOPIC, MessageEncoding, TRUTH_TOPIC, Topic};
use serde_json::json;

/// The recording's channels by topic: message encoding, schema name, schema encoding, schema.
fn recorded_channels(path: &std::path::Path) -> HashMap<String, (String, String, String, Vec<u8>)> {
    let bytes = std::fs::read(path).unwrap();
    let summary = mcap::Summary::read(&bytes)
        .unwrap()
        .expect("a finished recording");
    summary
        .channels
        .values()
        .map(|c| {
            let s = c.schema.as_ref().expect("every channel has a schema");
            let value = (
                c.message_encoding.clone(),
                s.name.clone(),
                s.encoding.clone(),
                s.data.to_vec(),
            );
            (c.topic.clone(), value)
        })
        .collect()
}

/// The advertised channel of `topic` in the recording's terms (a binary schema is base64 in
/// the protocol's `advertise`).
fn advertised(client: &Client, topic: &str) -> (String, String, String, Vec<u8>) {
    let c = &client.channels[topic];
    let text = |key: &str| c[key].as_str().unwrap_or_default().to_string();
    let schema_encoding = text("schemaEncoding");
    let schema = match schema_encoding.as_str() {
        "protobuf" => base64::engine::general_purpose::STANDARD
            .decode(text("schema"))
            .unwrap(),
        _ => text("schema").into_bytes(),
    };
    (
        text("encoding"),
        text("schemaName"),
        schema_encoding,
        schema,
    )
}

#[test]
fn a_websocket_v1_client_publishes_hints_and_sees_the_recordings_channels() {
    let ns = unique_namespace("foxglove");
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run.mcap");
    // A free port now; the stack binds it after calibrating, some seconds later.
    let addr = format!("127.0.0.1:{}", free_port());
    let stack = Proc::spawn(
        "mems-stack",
        &[
            "--duration",
            "60",
            "--namespace",
            &ns,
            "--foxglove",
            &addr,
            "--record",
            run.to_str().unwrap(),
        ],
    );
    // Calibration of the simulated part comes first: minutes on a loaded machine.
    let mut client = Client::connect_as(
        &format!("ws://{addr}"),
        WEBSOCKET_V1,
        Duration::from_secs(240),
    );
    assert!(
        child_named(stack.pid(), "mems-foxglove").is_some(),
        "the view runs as the stack's child"
    );
    let topics = [
        "mems/imu/raw",
        "mems/imu/corrected",
        "mems/odometry/state",
        "mems/robot/hint",
        "mems/odometry/pose",
        "mems/odometry/revised_pose",
        "mems/odometry/tf",
        "mems/odometry/path",
    ];
    client.wait_for_channels(&topics, Duration::from_secs(60));
    assert_eq!(
        client.channels.len(),
        topics.len(),
        "{:?}",
        client.channels.keys()
    );
    client.subscribe(&[OdometryState::TOPIC]);
    client.advertise(1, ipc_types::service::HINT, "json", "mems.AppHint");
    let stationary =
        hint_flags::STATIONARY | hint_flags::SOURCE_COMMANDED | hint_flags::SOURCE_ENCODERS;
    let hint = json!({"flags": stationary}).to_string();

    // Publish a stationary hint every 20 ms until a state says hints were applied.
    let start = Instant::now();
    let (mut states, mut aligned, mut applied) = (0, 0, 0);
    let mut last_hint = Instant::now() - Duration::from_secs(1);
    while applied == 0 {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "{states} states received, {aligned} aligned, none with a hint applied"
        );
        if last_hint.elapsed() >= Duration::from_millis(20) {
            client.publish(1, hint.as_bytes());
            last_hint = Instant::now();
        }
        if let Some(data) = client.read() {
            let state: OdometryState = MessageEncoding::Protobuf.decode(&data.payload).unwrap();
            states += 1;
            aligned += usize::from(state.flags & odometry_flags::ALIGNED != 0);
            applied = state.hints_applied;
        }
    }
    let (status, summary) = stack.wait(Duration::from_secs(120));
    assert!(status.success(), "mems-stack failed: {status}\n{summary}");

    let recorded = recorded_channels(&run);
    for topic in topics {
        let live = advertised(&client, topic);
        let file = recorded
            .get(topic)
            .unwrap_or_else(|| panic!("{topic} not recorded"));
        assert_eq!(
            (&live.0, &live.1, &live.2),
            (&file.0, &file.1, &file.2),
            "{topic}"
        );
        assert!(
            live.3 == file.3,
            "{topic}: the live schema differs from the recorded one"
        );
    }
    for topic in recorded.keys() {
        assert!(
            topics.contains(&topic.as_str())
                || [EVENTS_TOPIC, TRUTH_TOPIC].contains(&topic.as_str()),
            "{topic} is recorded but not served live"
        );
    }
}
