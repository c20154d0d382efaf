//! `mems-bridge out` and `mems-bridge in` as two hosts on loopback (two iceoryx2 namespaces,
//! a Zenoh TCP link between the processes): every odometry state published on the robot's side
//! arrives on the other side's iceoryx2 service, in order and bit for bit, and both ends count
//! nothing lost. A bridge whose stderr is a file says which service it carries, in plain
//! text (no terminal colour codes), and its `--help` has whole sentences.

use std::time::{Duration, Instant};

use iceoryx2::prelude::PortFactory;
use integration_tests::{
    Proc, bin, free_port, odometry_state, run_ok, unique_namespace, wait_until,
};
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

#[test]
fn a_bridge_logging_to_a_file_names_its_service_without_colour_codes() {
    let dir = std::env::temp_dir().join(format!("mems-bridge-log-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let log = dir.join("stderr.log");
    let namespace = unique_namespace("bridge-log");
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let mut command = std::process::Command::new(bin("mems-bridge"));
    command
        .args(["out", "--service", "odometry", "--listen", &endpoint])
        .args(["--namespace", &namespace])
        .stderr(std::fs::File::create(&log).unwrap());
    // `Proc::start` would send stderr to the terminal: start it here, stdout captured.
    let mut child = command.stdout(std::process::Stdio::null()).spawn().unwrap();
    let service = service::full_name(&namespace, service::ODOMETRY);
    wait_until(WAIT, "the bridge's start line", || {
        std::fs::read_to_string(&log).is_ok_and(|s| s.contains(&service))
    });
    // SAFETY: kill(2) on our own child's pid.
    assert_eq!(unsafe { libc::kill(child.id() as i32, libc::SIGTERM) }, 0);
    assert!(child.wait().unwrap().success());
    let stderr = std::fs::read_to_string(&log).unwrap();
    assert!(
        stderr.contains(&format!("mems-bridge: carrying {service} out to Zenoh key")),
        "{stderr}"
    );
    assert!(
        !stderr.contains('\x1b'),
        "colour codes in a file: {stderr:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_bridge_help_has_whole_sentences() {
    let help = run_ok("mems-bridge", &["--help"]);
    assert!(
        help.contains("onto this machine's iceoryx2 services"),
        "{help}"
    );
    assert!(help.contains("On the robot, `mems-bridge out"), "{help}");
    assert!(help.contains("carried N lost M"), "{help}");
}
