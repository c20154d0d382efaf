//! `mems-bridge out` and `mems-bridge in` as two hosts on loopback (two iceoryx2 namespaces,
//! a Zenoh TCP link between the processes): every odometry state published on the robot's side
//! arrives on the other side's iceoryx2 service, in order and bit for bit, and both ends count
//! nothing lost. With `--auth`, only a peer with the credentials receives anything; an endpoint
//! that other machines reach is refused without `--auth`. A bridge whose stderr is a file says
//! which service it carries, in plain text (no terminal colour codes), and its `--help` has
//! whole sentences.

use std::time::{Duration, Instant};

use std::path::Path;

use iceoryx2::prelude::PortFactory;
use integration_tests::{
    Proc, bin, free_port, odometry_state, path_arg, run_ok, unique_namespace, wait_until,
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

/// `mems-bridge in` for odometry from `endpoint` into namespace `ns`, with `extra` arguments,
/// its stderr in `log`.
fn station(endpoint: &str, ns: &str, extra: &[&str], log: &Path) -> Proc {
    let mut args = vec![
        "in",
        "--service",
        "odometry",
        "--connect",
        endpoint,
        "--namespace",
        ns,
    ];
    args.extend_from_slice(extra);
    Proc::spawn_logged("mems-bridge", &args, log)
}

#[test]
fn only_a_peer_with_the_credentials_receives_states() {
    let dir = std::env::temp_dir().join(unique_namespace("bridge-auth"));
    std::fs::create_dir_all(&dir).unwrap();
    let (auth, wrong) = (dir.join("bridge.auth"), dir.join("wrong.auth"));
    std::fs::write(&auth, "robot1:8c1f0e4b9d2a7736\n").unwrap();
    std::fs::write(&wrong, "robot1:not-the-password\n").unwrap();
    let robot = unique_namespace("auth-robot");
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let out = Proc::spawn_logged(
        "mems-bridge",
        &[
            "out",
            "--service",
            "odometry",
            "--listen",
            &endpoint,
            "--auth",
            path_arg(&auth),
            "--namespace",
            &robot,
        ],
        &dir.join("out.log"),
    );
    // The station with the credentials, one without any, one with a wrong password.
    let names = ["auth-good", "auth-none", "auth-wrong"].map(unique_namespace);
    let logs = ["good", "none", "wrong"].map(|n| dir.join(format!("{n}.log")));
    let good = station(&endpoint, &names[0], &["--auth", path_arg(&auth)], &logs[0]);
    let none = station(&endpoint, &names[1], &[], &logs[1]);
    let bad = station(
        &endpoint,
        &names[2],
        &["--auth", path_arg(&wrong)],
        &logs[2],
    );

    let node = service::node().unwrap();
    let open = |ns: &str| {
        service::open::<OdometryState>(&node, &service::full_name(ns, service::ODOMETRY)).unwrap()
    };
    let robot_svc = open(&robot);
    let publisher = service::publisher(&robot_svc).unwrap();
    let subscribers = names
        .each_ref()
        .map(|ns| service::subscriber(&open(ns)).unwrap());
    wait_until(WAIT, "the bridge's subscriber on the robot", || {
        robot_svc.dynamic_config().number_of_subscribers() >= 1
    });
    let mut seq = 0;
    let mut send = |n: u64| {
        for _ in 0..n {
            publisher.send_copy(odometry_state(seq)).unwrap();
            seq += 1;
        }
        seq
    };
    let mut received = [0u64; 3];
    let drain = |received: &mut [u64; 3]| {
        for (count, sub) in received.iter_mut().zip(&subscribers) {
            while sub.receive().unwrap().is_some() {
                *count += 1;
            }
        }
    };
    wait_until(WAIT, "a state at the station with the credentials", || {
        send(1);
        std::thread::sleep(Duration::from_millis(10));
        drain(&mut received);
        received[0] > 0
    });
    // Both strangers tried to open the link and were refused (Zenoh logs each refusal on the
    // opening side: the robot closed the link in answer to its InitSyn or OpenSyn); states sent
    // after that reach the good station and neither stranger.
    for log in &logs[1..] {
        wait_until(WAIT, "a refused connection", || {
            std::fs::read_to_string(log).is_ok_and(|t| t.contains("Received a close message"))
        });
    }
    let last = send(1000) - 1;
    let mut newest = 0;
    wait_until(WAIT, "the last state at the good station", || {
        while let Some(s) = subscribers[0].receive().unwrap() {
            received[0] += 1;
            newest = s.seq;
        }
        newest == last
    });
    drain(&mut received);
    assert_eq!(received[1..], [0, 0], "the strangers received states");

    for p in [&out, &good, &none, &bad] {
        p.signal(libc::SIGTERM);
    }
    let mut carried = Vec::new();
    for p in [out, good, none, bad] {
        let (status, summary) = p.wait(WAIT);
        assert!(status.success(), "{status}: {summary}");
        carried.push(count_after(&summary, "carried"));
    }
    assert!(carried[0] >= 1000 && carried[1] >= 1000, "{carried:?}");
    assert_eq!(carried[2..], [0, 0], "{carried:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn an_endpoint_other_machines_reach_needs_auth() {
    let endpoint = format!("tcp/0.0.0.0:{}", free_port());
    let output = std::process::Command::new(bin("mems-bridge"))
        .args(["out", "--service", "odometry", "--listen", &endpoint])
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.starts_with("mems-bridge: error: --listen tcp/0.0.0.0:")
            && stderr.contains("--auth FILE")
            && stderr.contains("--no-auth"),
        "{stderr}"
    );
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
