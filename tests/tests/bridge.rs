//! `mems-bridge out` and `mems-bridge in` as two hosts on loopback (two iceoryx2 namespaces,
//! a Zenoh TCP link between the processes): every odometry state published on the robot's side
//! arrives on the other side's iceoryx2 service, in order and bit for bit, and both ends count
//! nothing lost.

use std::time::{Duration, Instant};

use iceoryx2::prelude::PortFactory;
use integration_tests::{Proc, free_port, odometry_state, unique_namespace, wait_until};
use ipc_types::{OdometryState, service};

const WAIT: Duration = Duration::from_secs(60);

/// The number after `label` in `line`.
fn count_after(line: &str, label: &str) -> u64 {
    let rest = &line[line
        .find(label)
        .unwrap_or_else(|| panic!("{label} in {line}"))
        + label.len()..];
    rest.split_whitespace().next().unwrap().parse().unwrap()
}

#[test]
fn odometry_crosses_the_bridge_without_loss() {
    let (robot, station) = (unique_namespace("bridge-a"), unique_namespace("bridge-b"));
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let out = Proc::spawn(
        "mems-bridge",
        &[
            "out",
            "--service",
            "odometry",
            "--listen",
            &endpoint,
            "--namespace",
            &robot,
        ],
    );
    let into = Proc::spawn(
        "mems-bridge",
        &[
            "in",
            "--service",
            "odometry",
            "--connect",
            &endpoint,
            "--namespace",
            &station,
        ],
    );
    let node = service::node().unwrap();
    let robot_svc =
        service::open::<OdometryState>(&node, &service::full_name(&robot, service::ODOMETRY))
            .unwrap();
    let publisher = service::publisher(&robot_svc).unwrap();
    let station_svc =
        service::open::<OdometryState>(&node, &service::full_name(&station, service::ODOMETRY))
            .unwrap();
    let subscriber = service::subscriber(&station_svc).unwrap();
    wait_until(WAIT, "the bridge's subscriber on the robot", || {
        robot_svc.dynamic_config().number_of_subscribers() >= 1
    });

    // Until the link is up, states go nowhere: send one every 10 ms until one arrives.
    let start = Instant::now();
    let mut seq = 0;
    let first = loop {
        assert!(start.elapsed() < WAIT, "nothing crossed the bridge");
        publisher.send_copy(odometry_state(seq)).unwrap();
        seq += 1;
        std::thread::sleep(Duration::from_millis(10));
        if let Some(s) = subscriber.receive().unwrap() {
            break s.seq;
        }
    };
    // Whatever was sent after the first arrival arrives too, in order, exactly as sent.
    let warm_up: Vec<u64> = (first + 1..seq).collect();
    let n = 5000;
    let mut received = Vec::new();
    let mut expected = Vec::new();
    let drain = |received: &mut Vec<OdometryState>| {
        while let Some(r) = subscriber.receive().unwrap() {
            received.push(*r);
        }
    };
    for k in seq..seq + n {
        let s = odometry_state(k);
        publisher.send_copy(s).unwrap();
        expected.push(s);
        if k % 100 == 0 {
            drain(&mut received);
        }
    }
    wait_until(WAIT, "every state across the bridge", || {
        drain(&mut received);
        received.len() >= warm_up.len() + expected.len()
    });
    let (warm, main) = received.split_at(warm_up.len());
    assert_eq!(warm.iter().map(|s| s.seq).collect::<Vec<_>>(), warm_up);
    assert_eq!(main, expected.as_slice());

    out.signal(libc::SIGTERM);
    into.signal(libc::SIGTERM);
    let (status, out_summary) = out.wait(WAIT);
    assert!(status.success(), "mems-bridge out: {status}");
    let (status, in_summary) = into.wait(WAIT);
    assert!(status.success(), "mems-bridge in: {status}");
    let total = seq + n - first;
    assert_eq!(count_after(&out_summary, "lost"), 0, "{out_summary}");
    assert_eq!(count_after(&in_summary, "lost"), 0, "{in_summary}");
    assert!(count_after(&in_summary, "carried") >= total, "{in_summary}");
}
