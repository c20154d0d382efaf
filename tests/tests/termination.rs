//! A requested stop is never forgotten. Every long-running process is stopped with SIGSTOP, sent
//! SIGTERM and other signals, then SIGCONT: all are pending when it resumes, and Linux runs
//! their handlers highest number first (each delivery stacks a frame over the previous one,
//! lowest number dequeued first), so the signal numbered below SIGTERM (15) is the last one
//! the process sees: SIGUSR1 (10), which iceoryx2 also records in its one-slot last signal.
//! Each process must still exit 0, each by its own way of waiting: the event-driven serve loop
//! (mems-calibrate serve, mems-odometry serve, mems-topic hz, mems-record), its spinning
//! variant (`--spin`), a paced acquisition (mems-acquire) and a replay waiting for subscribers
//! (mems-replay).
//!
//! Needs the binaries: `cargo build -p acquire -p calibrate -p odometry -p mems-sim -p
//! mems-topic -p mems-record -p mems-replay` (or `cargo test --workspace`, which builds them).

use std::time::Duration;

use integration_tests::{
    Proc, calibrate_sim_part, nodes_of, path_arg, unique_namespace, wait_until,
};

/// Generous bounds for a loaded 2-core machine: nothing here depends on prompt scheduling.
const START: Duration = Duration::from_secs(60);
const EXIT: Duration = Duration::from_secs(60);

#[test]
fn sigterm_then_sigcont_stops_every_process() {
    stops_every_process("sigcont", &[libc::SIGTERM]);
}

#[test]
fn sigterm_then_sigusr1_then_sigcont_stops_every_process() {
    stops_every_process("sigusr1", &[libc::SIGTERM, libc::SIGUSR1]);
}

/// Starts every process in a namespace of its own (`tag`), stops them, sends `signals` to
/// each, continues them and asserts that each exits 0.
fn stops_every_process(tag: &str, signals: &[i32]) {
    let ns = unique_namespace(tag);
    // The replay publishes raw samples: apart from the acquisition's.
    let replay_ns = format!("{ns}-replay");
    let dir = std::env::temp_dir().join(&ns);
    std::fs::create_dir_all(&dir).unwrap();
    let calib = calibrate_sim_part(&dir, 5);
    let (calib, six, mcap) = (
        path_arg(&calib).to_string(),
        // The six-position session calibrate_sim_part recorded.
        dir.join("six-position.csv"),
        dir.join("run.mcap"),
    );
    let serve = |exe: &str, extra: &[&str]| {
        let mut args = vec!["serve", "--calib", &calib, "--namespace", &ns];
        args.extend_from_slice(extra);
        Proc::spawn(exe, &args)
    };
    let mut procs = vec![
        serve("mems-calibrate", &[]),
        serve("mems-odometry", &[]),
        serve("mems-odometry", &["--spin"]),
        Proc::spawn("mems-topic", &["hz", "mems/imu/raw", "--namespace", &ns]),
        Proc::spawn(
            "mems-record",
            &["--out", path_arg(&mcap), "--namespace", &ns],
        ),
        Proc::spawn(
            "mems-acquire",
            &["--source", "sim", "--rate", "200", "--namespace", &ns],
        ),
        Proc::spawn(
            "mems-replay",
            &[
                path_arg(&six),
                "--namespace",
                &replay_ns,
                "--wait-subscribers",
                "1",
                "--wait-timeout",
                "600",
            ],
        ),
    ];
    // A process has installed its handlers before it creates its first port. One that exits
    // first has failed to start (its stderr, above, says why).
    for p in &mut procs {
        let what = format!("the ports of {} (process {})", p.name(), p.pid());
        wait_until(START, &what, || {
            if let Some(status) = p.exited() {
                panic!("{} exited ({status}) before it created a port", p.name());
            }
            nodes_of(p.pid()).iter().any(|n| !n.port_ids.is_empty())
        });
    }
    for p in &procs {
        p.signal(libc::SIGSTOP);
    }
    for signal in signals {
        for p in &procs {
            p.signal(*signal);
        }
    }
    for p in &procs {
        p.signal(libc::SIGCONT);
    }
    let names = [
        "calibrate serve",
        "odometry serve",
        "odometry serve --spin",
        "topic hz",
        "record",
        "acquire",
        "replay",
    ];
    for (p, name) in procs.into_iter().zip(names) {
        let (status, out) = p.wait(EXIT);
        assert!(status.success(), "{name}: {status}, stdout: {out}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
