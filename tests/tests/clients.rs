//! The client examples against real processes, each test in its own namespace:
//!
//! - the Rust subscriber (`ipc-types/examples/subscribe_odometry.rs`) and the Python one
//!   (`ipc-types/python/subscribe.py`, iceoryx2 Python package 0.10) against a live
//!   `mems-stack`: both receive odometry states, live ones with consecutive sequence numbers;
//! - the Rust and the Python hint publishers (`ipc-types/examples/publish_hints.rs`,
//!   `ipc-types/python/publish_hints.py`) against a live `mems-odometry serve` on a sensor
//!   lying still: the states count the hints applied while each publisher runs, and report the
//!   hints stale once it has stopped.
//!
//! - the Rust subscriber alone: `--help` works, it names the service and namespace it waits
//!   on, and prints "not aligned yet" for a state before alignment.
//!
//! The Python halves skip, loudly, only when `python3` cannot import iceoryx2 (`.ci/run`
//! installs it).

use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use iceoryx2::prelude::PortFactory;
use integration_tests::{
    Proc, calibrate_sim_part, example, odometry_state, path_arg, python_iceoryx2, unique_namespace,
    wait_until, workspace_root,
};
use ipc_types::{OdometryState, odometry_flags, service, wake};

const WAIT: Duration = Duration::from_secs(40);

/// Asserts that `seqs` (live states, in arrival order) are consecutive.
fn assert_consecutive(who: &str, seqs: &[u64]) {
    assert!(seqs.len() >= 200, "{who}: {} live states", seqs.len());
    for w in seqs.windows(2) {
        assert_eq!(w[1], w[0] + 1, "{who}: seq {} after {}", w[1], w[0]);
    }
}

#[test]
fn rust_and_python_subscribers_receive_the_live_stack_odometry() {
    let ns = unique_namespace("subscribers");
    let python = python_iceoryx2();
    // Built before any process starts (cargo may wait for the build directory's lock).
    let subscriber = example("ipc-types", "subscribe_odometry");
    let stack = Proc::spawn("mems-stack", &["--duration", "30", "--namespace", &ns]);
    let mut rust = Command::new(subscriber);
    rust.arg("400").env(service::NAMESPACE_ENV, &ns);
    let rust = Proc::start("subscribe_odometry", rust);
    let python = python.then(|| {
        let mut cmd = Command::new("python3");
        cmd.arg(workspace_root().join("ipc-types/python/subscribe.py"))
            .args([service::ODOMETRY, "--namespace", &ns, "--count", "400"])
            .args(["--timeout", "30"]);
        Proc::start("subscribe.py", cmd)
    });

    let (status, out) = rust.wait(WAIT);
    assert!(status.success(), "subscribe_odometry failed: {status}");
    // "seq N t T s: position (x, y, z) m +- (...)": one line per live state.
    let seqs: Vec<u64> = out
        .lines()
        .map(|l| {
            let seq = l.strip_prefix("seq ").and_then(|r| r.split(' ').next());
            seq.and_then(|s| s.parse().ok())
                .unwrap_or_else(|| panic!("unexpected line {l:?}"))
        })
        .collect();
    assert_eq!(seqs.len(), 400);
    assert_consecutive("Rust subscriber", &seqs);

    if let Some(python) = python {
        let (status, out) = python.wait(WAIT);
        assert!(status.success(), "subscribe.py failed: {status}");
        let states: Vec<serde_json::Value> = out
            .lines()
            .map(|l| serde_json::from_str(l).expect("one JSON object per line"))
            .collect();
        assert_eq!(states.len(), 400);
        let live: Vec<u64> = states
            .iter()
            .filter(|s| s["flags"].as_u64().unwrap() & u64::from(odometry_flags::REVISION) == 0)
            .map(|s| s["seq"].as_u64().unwrap())
            .collect();
        assert_consecutive("Python subscriber", &live);
        // Every field of the ctypes struct arrived: a unit attitude quaternion.
        let q: Vec<f64> = states[0]["attitude_wxyz"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let norm = q.iter().map(|x| x * x).sum::<f64>().sqrt();
        assert!((norm - 1.0).abs() < 1e-9, "attitude {q:?}");
    }
    stack.signal(libc::SIGTERM);
    let (status, summary) = stack.wait(WAIT);
    assert!(status.success(), "mems-stack failed: {status}");
    assert!(
        summary.contains("restarts: odometry 0, calibrate 0, acquire 0"),
        "{summary}"
    );
}

/// The newest live state, kept up to date by a subscriber thread.
struct Latest {
    state: Arc<Mutex<Option<OdometryState>>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Latest {
    fn subscribe(ns: &str) -> Self {
        let state: Arc<Mutex<Option<OdometryState>>> = Arc::default();
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let (state, stop) = (state.clone(), stop.clone());
            let name = service::full_name(ns, service::ODOMETRY);
            std::thread::spawn(move || {
                let node = service::node().unwrap();
                let svc = service::open::<OdometryState>(&node, &name).unwrap();
                let sub = service::subscriber(&svc).unwrap();
                while !stop.load(Ordering::Relaxed) {
                    while let Some(s) = sub.receive().unwrap() {
                        if s.flags & odometry_flags::REVISION == 0 {
                            *state.lock().unwrap() = Some(*s);
                        }
                    }
                    std::thread::sleep(Duration::from_millis(1));
                }
            })
        };
        Self {
            state,
            stop,
            thread: Some(thread),
        }
    }

    fn get(&self) -> Option<OdometryState> {
        *self.state.lock().unwrap()
    }

    fn has(&self, flag: u16) -> bool {
        self.get().is_some_and(|s| s.flags & flag != 0)
    }
}

impl Drop for Latest {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Runs a hint publisher to completion and returns the odometry's `hints_applied` before and
/// after, having waited for the hints to go stale again.
fn applied_by(latest: &Latest, who: &str, command: Command) -> (u32, u32) {
    let before = latest.get().unwrap().hints_applied;
    let (status, out) = Proc::start(who, command).wait(WAIT);
    assert!(status.success(), "{who} failed: {status}");
    assert!(out.contains("published"), "{who}: {out}");
    wait_until(WAIT, "the hints to go stale", || {
        latest.has(odometry_flags::HINT_STALE)
    });
    (before, latest.get().unwrap().hints_applied)
}

#[test]
fn rust_and_python_hint_publishers_are_applied_by_live_odometry() {
    let ns = unique_namespace("hints");
    let python = python_iceoryx2();
    // Built before any process starts (cargo may wait for the build directory's lock).
    let publisher = example("ipc-types", "publish_hints");
    let dir = std::env::temp_dir().join(&ns);
    std::fs::create_dir_all(&dir).unwrap();
    let calib = calibrate_sim_part(&dir, 3);
    let calib = path_arg(&calib);
    let latest = Latest::subscribe(&ns);
    let stages = [
        Proc::spawn(
            "mems-odometry",
            &["serve", "--calib", calib, "--namespace", &ns],
        ),
        Proc::spawn(
            "mems-calibrate",
            &[
                "serve",
                "--calib",
                calib,
                "--learn-s",
                "1",
                "--learn-first-s",
                "1",
                "--namespace",
                &ns,
            ],
        ),
    ];
    std::thread::sleep(Duration::from_millis(700));
    let acquire = Proc::spawn(
        "mems-acquire",
        &[
            "--scenario",
            "static",
            "--duration",
            "30",
            "--namespace",
            &ns,
        ],
    );
    wait_until(WAIT, "the odometry aligned", || {
        latest.has(odometry_flags::ALIGNED)
    });
    assert_eq!(latest.get().unwrap().hints_applied, 0, "no hint yet");

    let mut rust = Command::new(publisher);
    rust.args(["1.5", "0"]).env(service::NAMESPACE_ENV, &ns);
    let (before, after) = applied_by(&latest, "publish_hints", rust);
    assert_eq!(before, 0);
    assert!(after > 0, "the Rust hints were applied: {after}");

    if python {
        let mut cmd = Command::new("python3");
        cmd.arg(workspace_root().join("ipc-types/python/publish_hints.py"))
            .args(["--duration", "1.5", "--namespace", &ns]);
        let (before, after) = applied_by(&latest, "publish_hints.py", cmd);
        assert!(
            after > before,
            "the Python hints were applied: {before} -> {after}"
        );
    }

    acquire.signal(libc::SIGTERM);
    let (status, _) = acquire.wait(WAIT);
    assert!(status.success());
    for p in stages {
        p.signal(libc::SIGTERM);
        let (status, _) = p.wait(WAIT);
        assert!(status.success(), "a stage failed: {status}");
    }
    drop(latest);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_rust_subscriber_has_help_says_what_it_waits_for_and_marks_unaligned_states() {
    let subscriber = example("ipc-types", "subscribe_odometry");
    let help = Command::new(&subscriber).arg("--help").output().unwrap();
    assert!(help.status.success(), "--help: {help:?}");
    assert!(String::from_utf8_lossy(&help.stdout).contains("--namespace"));

    let ns = unique_namespace("subscriber-wait");
    let name = service::full_name(&ns, service::ODOMETRY);
    let client = Command::new(&subscriber)
        .args(["2", "--namespace", &ns])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let node = service::node().unwrap();
    let svc = service::open::<OdometryState>(&node, &name).unwrap();
    wait_until(WAIT, "the subscriber", || {
        svc.dynamic_config().number_of_subscribers() >= 1
    });
    let mut out = wake::Output::new(&node, &svc, &name).unwrap();
    let mut unaligned = odometry_state(0);
    unaligned.flags &= !odometry_flags::ALIGNED;
    let mut aligned = odometry_state(1);
    aligned.flags |= odometry_flags::ALIGNED;
    for state in [unaligned, aligned] {
        out.send(state);
        out.end_of_input().unwrap();
    }
    let done = client.wait_with_output().unwrap();
    assert!(done.status.success(), "{done:?}");
    let printed = String::from_utf8(done.stdout).unwrap();
    let lines: Vec<&str> = printed.lines().collect();
    assert_eq!(lines.len(), 2, "{printed}");
    assert!(lines[0].ends_with(": not aligned yet"), "{printed}");
    assert!(lines[1].contains("position ("), "{printed}");
    let said = String::from_utf8(done.stderr).unwrap();
    assert!(
        said.contains(&format!("waiting for states on {name} (namespace {ns:?}")),
        "{said}"
    );
}
