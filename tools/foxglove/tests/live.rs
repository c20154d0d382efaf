//! `mems-foxglove` against a real WebSocket client speaking Foxglove's protocol: it advertises
//! its channels with Foxglove's schema names, and a subscribed client receives the odometry
//! states this test publishes on iceoryx2, as JSON equal to what was sent and as
//! `foxglove.PoseInFrame`, with log times on the wall clock (not 1970).

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use integration_tests::foxglove::Client;
use integration_tests::odometry_state;
use ipc_types::{OdometryState, service};

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

/// Starts `mems-foxglove` on a free loopback port in `namespace`; returns it and its URL.
fn start(namespace: &str) -> (Server, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_mems-foxglove"))
        .args(["--listen", "127.0.0.1:0", "--namespace", namespace])
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

#[test]
fn a_foxglove_client_sees_the_channels_and_the_odometry() {
    let namespace = format!("test-foxglove-{}", std::process::id());
    let (mut server, url) = start(&namespace);
    let mut client = Client::connect(&url, WAIT);
    client.wait_for_channels(
        &[
            "/mems/odometry/pose",
            "/mems/odometry/revised_pose",
            "/tf",
            "/mems/odometry/path",
            "/mems/odometry/state",
            "/mems/imu/corrected",
        ],
        WAIT,
    );
    assert_eq!(client.schema("/mems/odometry/pose"), "foxglove.PoseInFrame");
    assert_eq!(
        client.schema("/mems/odometry/revised_pose"),
        "foxglove.PoseInFrame"
    );
    assert_eq!(client.schema("/tf"), "foxglove.FrameTransform");
    assert_eq!(
        client.schema("/mems/odometry/path"),
        "foxglove.PosesInFrame"
    );
    assert_eq!(client.schema("/mems/odometry/state"), "mems.OdometryState");
    assert_eq!(client.channels["/mems/odometry/state"]["encoding"], "json");
    assert_eq!(
        client.schema("/mems/imu/corrected"),
        "mems.CorrectedImuSample"
    );
    client.subscribe(&["/mems/odometry/state", "/mems/odometry/pose"]);

    // Publish until the client has received states on both subscriptions (a subscription
    // takes effect some time after it is sent).
    let node = service::node().unwrap();
    let svc =
        service::open::<OdometryState>(&node, &service::full_name(&namespace, service::ODOMETRY))
            .unwrap();
    let publisher = service::publisher(&svc).unwrap();
    let mut sent = Vec::new();
    let (mut states, mut poses) = (Vec::new(), 0);
    let start = Instant::now();
    while states.len() < 20 || poses < 20 {
        assert!(
            start.elapsed() < WAIT,
            "received {} states, {poses} poses",
            states.len()
        );
        let s = odometry_state(sent.len() as u64);
        publisher.send_copy(s).unwrap();
        sent.push(s);
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
            match data.subscription {
                1 => states.push(serde_json::from_slice::<OdometryState>(&data.payload).unwrap()),
                2 => poses += 1,
                other => panic!("message for subscription {other}"),
            }
        }
    }
    for s in &states {
        assert_eq!(*s, sent[s.seq as usize], "state {} as received", s.seq);
    }
    // SIGTERM stops it cleanly.
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
