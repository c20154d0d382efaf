//! `mems-stack --foxglove 127.0.0.1:PORT` on the simulated MPU-9250: a Foxglove WebSocket
//! client connects to the running stack (a real client of the protocol, this test), sees the
//! advertised channels with Foxglove's schema names, and receives the live odometry, aligned.
//! Without the flag no view process runs (`stack_losses` checks that).

use std::time::{Duration, Instant};

use integration_tests::foxglove::Client;
use integration_tests::{Proc, child_named, free_port, unique_namespace};
use ipc_types::{OdometryState, odometry_flags};

#[test]
fn a_foxglove_client_receives_the_stacks_odometry() {
    let ns = unique_namespace("foxglove");
    // A free port now; the stack binds it after calibrating, some seconds later.
    let addr = format!("127.0.0.1:{}", free_port());
    let stack = Proc::spawn(
        "mems-stack",
        &["--duration", "40", "--namespace", &ns, "--foxglove", &addr],
    );
    // Calibration of the simulated part comes first: minutes on a loaded machine.
    let mut client = Client::connect(&format!("ws://{addr}"), Duration::from_secs(240));
    assert!(
        child_named(stack.pid(), "mems-foxglove").is_some(),
        "the view runs as the stack's child"
    );
    client.wait_for_channels(
        &["/mems/odometry/state", "/mems/odometry/pose", "/tf"],
        Duration::from_secs(60),
    );
    assert_eq!(client.schema("/mems/odometry/pose"), "foxglove.PoseInFrame");
    assert_eq!(client.schema("/tf"), "foxglove.FrameTransform");
    client.subscribe(&["/mems/odometry/state"]);
    let start = Instant::now();
    let (mut states, mut aligned) = (0, 0);
    while aligned == 0 {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "{states} states received, none aligned"
        );
        if let Some(data) = client.read() {
            let state: OdometryState = serde_json::from_slice(&data.payload).unwrap();
            states += 1;
            aligned += usize::from(state.flags & odometry_flags::ALIGNED != 0);
        }
    }
    let (status, summary) = stack.wait(Duration::from_secs(120));
    assert!(status.success(), "mems-stack failed: {status}\n{summary}");
}
