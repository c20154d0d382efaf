//! `mems-foxglove` against real WebSocket clients of Foxglove's protocol, one offering the
//! SDK's name `foxglove.sdk.v1` and one the specification's `foxglove.websocket.v1`: both are
//! accepted, see every channel with the recording's topic, encoding and schema name, and
//! receive messages on every channel while this test publishes raw samples, corrected
//! samples, odometry states (revisions too) and hints on iceoryx2; the states arrive as
//! the recording's protobuf, equal to what was sent as a recording keeps it, with log times
//! on the wall clock (not 1970). The settings given as `--parameter` are read back.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use integration_tests::foxglove::{Client, SDK_V1, WEBSOCKET_V1};
use integration_tests::odometry_state;
use ipc_types::{
    CorrectedImuSample, OdometryState, RawImuSample, RobotHint, odometry_flags, service,
};
use recording::mcap::derived::{PATH_TOPIC, POSE_TOPIC, REVISED_POSE_TOPIC, TF_TOPIC};
use recording::mcap::{MessageEncoding, Topic};
use serde_json::json;

/// Generous: CI is a loaded 2-core machine.
const WAIT: Duration = Duration::from_secs(60);

/// Kills the server if the test ends early.
struct Server(Child);

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `mems-foxglove` on a free loopback port in `namespace` with `args`; returns it and
/// its URL.
fn start(namespace: &str, args: &[&str]) -> (Server, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_mems-foxglove"))
        .args(["--listen", "127.0.0.1:0", "--namespace", namespace])
        .args(args)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = child.stderr.take().unwrap();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            eprintln!("{line}");
            if let Some(url) = line.strip_prefix("mems-foxglove: serving ") {
                let _ = tx.send(url.to_string());
            }
        }
    });
    let url = rx
        .recv_timeout(WAIT)
        .expect("mems-foxglove did not say where it serves");
    (Server(child), url)
}

/// Every channel: topic, message encoding, schema name.
fn channels() -> Vec<(&'static str, &'static str, &'static str)> {
    vec![
        (RawImuSample::TOPIC, "protobuf", RawImuSample::SCHEMA_NAME),
        (
            CorrectedImuSample::TOPIC,
            "protobuf",
            CorrectedImuSample::SCHEMA_NAME,
        ),
        (OdometryState::TOPIC, "protobuf", OdometryState::SCHEMA_NAME),
        (RobotHint::TOPIC, "protobuf", RobotHint::SCHEMA_NAME),
        (POSE_TOPIC, "protobuf", "foxglove.PoseInFrame"),
        (REVISED_POSE_TOPIC, "protobuf", "foxglove.PoseInFrame"),
        (TF_TOPIC, "protobuf", "foxglove.FrameTransform"),
        (PATH_TOPIC, "protobuf", "foxglove.PosesInFrame"),
    ]
}

/// The iceoryx2 publishers of the test, one per service the view reads.
struct Publishers {
    _node: iceoryx2::prelude::Node<iceoryx2::prelude::ipc::Service>,
    raw: iceoryx2::port::publisher::Publisher<iceoryx2::prelude::ipc::Service, RawImuSample, ()>,
    corrected: iceoryx2::port::publisher::Publisher<
        iceoryx2::prelude::ipc::Service,
        CorrectedImuSample,
        (),
    >,
    state: iceoryx2::port::publisher::Publisher<iceoryx2::prelude::ipc::Service, OdometryState, ()>,
    hint: iceoryx2::port::publisher::Publisher<iceoryx2::prelude::ipc::Service, RobotHint, ()>,
}

impl Publishers {
    fn new(namespace: &str) -> Self {
        let node = service::node().unwrap();
        let name = |base| service::full_name(namespace, base);
        let raw = service::publisher(&service::open(&node, &name(service::RAW)).unwrap()).unwrap();
        let corrected =
            service::publisher(&service::open(&node, &name(service::CORRECTED)).unwrap()).unwrap();
        let state =
            service::publisher(&service::open(&node, &name(service::ODOMETRY)).unwrap()).unwrap();
        let hint =
            service::hint_publisher(&service::open(&node, &name(service::HINT)).unwrap()).unwrap();
        Self {
            _node: node,
            raw,
            corrected,
            state,
            hint,
        }
    }

    /// Publishes one message of each kind numbered `seq`; every fourth state is a revision.
    fn publish(&self, seq: u64) -> OdometryState {
        let mut s = odometry_state(seq);
        if seq % 4 == 3 {
            s.flags |= odometry_flags::REVISION;
        }
        let stamps = s.stamps;
        self.raw
            .send_copy(RawImuSample {
                stamps,
                seq,
                ..Default::default()
            })
            .unwrap();
        self.corrected
            .send_copy(CorrectedImuSample {
                stamps,
                seq,
                ..Default::default()
            })
            .unwrap();
        self.state.send_copy(s).unwrap();
        self.hint
            .send_copy(RobotHint {
                stamps,
                seq,
                flags: 1,
                ..Default::default()
            })
            .unwrap();
        s
    }
}

#[test]
fn clients_of_both_protocol_names_receive_every_channel() {
    let namespace = format!("test-foxglove-{}", std::process::id());
    let (mut server, url) = start(
        &namespace,
        &["--parameter", "rate=1000", "--parameter", "source=sim"],
    );
    let mut clients = [
        Client::connect_as(&url, SDK_V1, WAIT),
        Client::connect_as(&url, WEBSOCKET_V1, WAIT),
    ];
    let topics: Vec<&str> = channels().iter().map(|c| c.0).collect();
    for client in &mut clients {
        client.wait_for_channels(&topics, WAIT);
        for (topic, encoding, schema) in channels() {
            assert_eq!(client.channels[topic]["encoding"], encoding, "{topic}");
            assert_eq!(client.schema(topic), schema, "{topic}");
        }
        client.subscribe(&topics);
        client.send(&json!({"op": "getParameters", "parameterNames": [], "id": "all"}));
        let values = client.wait_for_op("parameterValues", WAIT);
        assert_eq!(
            values["parameters"],
            json!([{"name": "rate", "value": 1000}, {"name": "source", "value": "sim"}]),
            "{}",
            client.subprotocol
        );
    }

    // Publish until both clients have messages on every subscription (a subscription takes
    // effect some time after it is sent; the path comes every 2 s).
    let publishers = Publishers::new(&namespace);
    let mut sent = Vec::new();
    let mut received = [vec![0usize; topics.len()], vec![0usize; topics.len()]];
    let mut states = Vec::new();
    let start = Instant::now();
    while received.iter().any(|r| r.contains(&0)) {
        assert!(
            start.elapsed() < WAIT,
            "messages per channel {topics:?}: {received:?}"
        );
        sent.push(publishers.publish(sent.len() as u64));
        std::thread::sleep(Duration::from_millis(5));
        for (client, counts) in clients.iter_mut().zip(&mut received) {
            while let Some(data) = client.read() {
                let now_ns = SystemTime::now()
                    .duration_since(UNIX_EPOCH)
                    .unwrap()
                    .as_nanos() as u64;
                assert!(
                    data.log_ns.abs_diff(now_ns) < 3_600_000_000_000,
                    "log time {} ns is not wall-clock time (now {now_ns} ns)",
                    data.log_ns
                );
                let index = data.subscription as usize - 1;
                counts[index] += 1;
                if topics[index] == OdometryState::TOPIC {
                    let s: OdometryState = MessageEncoding::Protobuf.decode(&data.payload).unwrap();
                    states.push(s);
                }
            }
        }
    }
    assert!(!states.is_empty());
    for s in &states {
        assert_eq!(
            *s,
            sent[s.seq as usize].as_recorded(),
            "state {} as received",
            s.seq
        );
    }
    stop(&mut server);
}

/// SIGTERM stops the server cleanly.
fn stop(server: &mut Server) {
    // SAFETY: kill(2) on our own child, not yet reaped.
    assert_eq!(
        unsafe { libc::kill(server.0.id() as i32, libc::SIGTERM) },
        0
    );
    let deadline = Instant::now() + WAIT;
    let status = loop {
        if let Some(status) = server.0.try_wait().unwrap() {
            break status;
        }
        assert!(Instant::now() < deadline, "mems-foxglove did not stop");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(status.success(), "{status}");
}
