//! `mems-stack` as a real supervisor: its calibrate and then its odometry process are killed
//! with SIGKILL during a recorded run (simulated MPU-9250 at 1 kHz, unique namespace).
//!
//! Asserted: each killed stage is restarted (a new process of the same binary, counted in the
//! stack's summary); its peers keep their processes and their streams (the recording holds
//! every raw sample, and every corrected sample except those the dead calibrate never made);
//! the gap shows in the recording explicitly, as missing sequence ranges on the killed stage's
//! topic and the recorder's `gap`, `publisher_lost` and `publisher_back` events naming exactly
//! those ranges; and once the stack has exited, nothing of the killed processes' iceoryx2 nodes
//! remains (no node record, no `/dev/shm` segment of their ports, no service of the namespace).
//!
//! And `mems-stack` itself killed with SIGKILL: its children die with it (none is left alive;
//! the time they took is printed, its figure is measured by the command in
//! docs/acquisition.md); a new stack refuses to record over the recording left there, before
//! it starts anything, leaving the file as it was; and the next stack that starts removes what
//! the killed one left: its and its children's iceoryx2 nodes, their shared memory and
//! services, and its work directory.

use std::time::Duration;

use integration_tests::{
    NodeFootprint, Proc, child_named, children, leftovers, missing_ranges, nodes_of, path_arg,
    run_ok, service_exists, unique_namespace, wait_until,
};
use ipc_types::{OdometryState, service};
use recording::mcap::{EventKind, RecorderEvent, read_all};

const WAIT: Duration = Duration::from_secs(20);

/// The last sequence number of `topic` in the growing recording (0 before any).
fn last_seq(rec: &std::path::Path, topic: &str) -> u64 {
    let Ok(c) = read_all(rec) else { return 0 };
    let seqs: Vec<u64> = match topic {
        service::CORRECTED => c.corrected.iter().map(|s| s.seq).collect(),
        service::ODOMETRY => live(&c.odometry),
        _ => c.raw.iter().map(|s| s.seq).collect(),
    };
    seqs.last().copied().unwrap_or(0)
}

/// Sequence numbers of the live (non-revision) odometry states.
fn live(states: &[OdometryState]) -> Vec<u64> {
    states
        .iter()
        .filter(|s| s.flags & ipc_types::odometry_flags::REVISION == 0)
        .map(|s| s.seq)
        .collect()
}

/// SIGKILLs the stack's child `exe` once its iceoryx2 node exists, waits until the stack has
/// started a new one, and returns the footprint of the killed process's node with ports.
fn kill_and_await_restart(stack: &Proc, exe: &str) -> NodeFootprint {
    let pid = child_named(stack.pid(), exe).unwrap_or_else(|| panic!("{exe} runs"));
    let mut nodes = Vec::new();
    wait_until(WAIT, &format!("{exe}'s iceoryx2 node"), || {
        // The node with the process's ports (mems-calibrate also has the node of its dead-node
        // cleanup thread, which has none).
        nodes = nodes_of(pid);
        nodes.retain(|n| !n.port_ids.is_empty());
        nodes.len() == 1
    });
    // SAFETY: kill(2) on a process of this test's own stack; no memory is involved.
    assert_eq!(unsafe { libc::kill(pid as i32, libc::SIGKILL) }, 0);
    wait_until(WAIT, &format!("{exe} restarted"), || {
        child_named(stack.pid(), exe).is_some_and(|new| new != pid)
    });
    nodes.remove(0)
}

/// The recorder's events about `topic` as (kind, from_seq, to_seq).
fn events_on(events: &[RecorderEvent], topic: &str) -> Vec<(EventKind, Option<u64>, Option<u64>)> {
    events
        .iter()
        .filter(|e| e.service == topic)
        .map(|e| (e.kind, e.from_seq, e.to_seq))
        .collect()
}

#[test]
fn killed_stages_are_restarted_peers_keep_running_and_the_gap_is_recorded() {
    let ns = unique_namespace("stackkill");
    let dir = std::env::temp_dir().join(&ns);
    std::fs::create_dir_all(&dir).unwrap();
    let rec = dir.join("run.mcap");
    let stack = Proc::spawn(
        "mems-stack",
        &[
            "--duration",
            "10",
            "--record",
            path_arg(&rec),
            "--namespace",
            &ns,
        ],
    );
    wait_until(WAIT, "1 s of corrected samples recorded", || {
        last_seq(&rec, service::CORRECTED) > 1000
    });
    let acquire = child_named(stack.pid(), "mems-acquire").expect("acquire runs");
    let record = child_named(stack.pid(), "mems-record").expect("record runs");

    let calibrate_node = kill_and_await_restart(&stack, "mems-calibrate");
    let odometry = child_named(stack.pid(), "mems-odometry").expect("odometry runs");
    let after_restart = last_seq(&rec, service::RAW) + 1000;
    wait_until(WAIT, "1 s of corrected samples after the restart", || {
        last_seq(&rec, service::CORRECTED) > after_restart
    });
    assert_eq!(
        child_named(stack.pid(), "mems-odometry"),
        Some(odometry),
        "odometry kept running while calibrate was down"
    );
    let odometry_node = kill_and_await_restart(&stack, "mems-odometry");
    let after_restart = last_seq(&rec, service::RAW) + 1000;
    wait_until(WAIT, "1 s of odometry states after the restart", || {
        last_seq(&rec, service::ODOMETRY) > after_restart
    });
    for (exe, pid) in [("mems-acquire", acquire), ("mems-record", record)] {
        assert_eq!(
            child_named(stack.pid(), exe),
            Some(pid),
            "{exe} kept running"
        );
    }

    let (status, summary) = stack.wait(WAIT);
    assert!(status.success(), "mems-stack failed: {status}");
    assert!(
        summary.contains("restarts: record 0, odometry 1, calibrate 1, acquire 0"),
        "{summary}"
    );

    // The recording: raw complete; corrected missing exactly one range, announced; odometry
    // missing that range (it is fed by corrected) and one more, its own, announced.
    let c = read_all(&rec).unwrap();
    assert_eq!(c.truncation, None, "the recorder finished the file");
    let raw: Vec<u64> = c.raw.iter().map(|s| s.seq).collect();
    assert_eq!(raw[0], 0);
    assert_eq!(missing_ranges(&raw), [], "acquire lost nothing");
    // At most the source's own exit at shutdown (it is stopped first).
    let last = raw.last().copied();
    let raw_events = events_on(&c.events, service::RAW);
    assert!(
        raw_events
            .iter()
            .all(|e| *e == (EventKind::PublisherLost, last, last)),
        "raw events {raw_events:?}"
    );
    let corrected: Vec<u64> = c.corrected.iter().map(|s| s.seq).collect();
    let cor_gaps = missing_ranges(&corrected);
    assert_eq!(cor_gaps.len(), 1, "one corrected gap: {cor_gaps:?}");
    let (a, b) = cor_gaps[0];
    assert_eq!(
        *corrected.last().unwrap(),
        *raw.last().unwrap(),
        "calibrate (restarted) kept up to the end"
    );
    let cor_events = events_on(&c.events, service::CORRECTED);
    assert!(
        cor_events.contains(&(EventKind::PublisherLost, Some(a - 1), Some(a - 1)))
            && cor_events.contains(&(EventKind::Gap, Some(a), Some(b))),
        "corrected gap {a}..={b} not announced: {cor_events:?}"
    );
    assert!(
        cor_events
            .iter()
            .any(|(k, _, _)| *k == EventKind::PublisherBack)
    );
    let odo = live(&c.odometry);
    let odo_gaps = missing_ranges(&odo);
    assert_eq!(odo_gaps.len(), 2, "odometry gaps {odo_gaps:?}");
    assert!(
        odo_gaps[0].0 <= a && odo_gaps[0].1 >= b,
        "odometry misses what calibrate never made: {odo_gaps:?} vs {a}..={b}"
    );
    let (oa, ob) = odo_gaps[1];
    assert!(oa > b, "the odometry kill came after the calibrate restart");
    let odo_events = events_on(&c.events, service::ODOMETRY);
    for (from, to) in &odo_gaps {
        assert!(
            odo_events.contains(&(EventKind::Gap, Some(*from), Some(*to))),
            "odometry gap {from}..={to} not announced: {odo_events:?}"
        );
    }
    assert!(odo_events.contains(&(EventKind::PublisherLost, Some(oa - 1), Some(oa - 1))));
    assert!(*odo.last().unwrap() > ob + 1000, "odometry resumed");

    // Nothing of the killed nodes is left, and no service of the namespace survives the stack.
    for node in [&calibrate_node, &odometry_node] {
        assert_eq!(leftovers(node), Vec::<std::path::PathBuf>::new());
    }
    for pid in [acquire, record, odometry] {
        assert_eq!(nodes_of(pid), [], "node of process {pid} left behind");
    }
    for base in [
        service::RAW,
        service::CORRECTED,
        service::ODOMETRY,
        service::HINT,
    ] {
        assert!(!service_exists(&ns, base), "{base} left behind");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Whether process `pid` still runs (a zombie does not: it is dead, waiting to be reaped).
fn alive(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|stat| {
        stat.rsplit_once(')')
            .is_some_and(|(_, rest)| !rest.trim_start().starts_with('Z'))
    })
}

#[test]
fn a_killed_stack_takes_its_children_and_the_next_start_cleans_up() {
    let ns = unique_namespace("stackkill9");
    let dir = std::env::temp_dir().join(&ns);
    std::fs::create_dir_all(&dir).unwrap();
    let rec = dir.join("run.mcap");
    let stack = Proc::spawn(
        "mems-stack",
        &["--record", path_arg(&rec), "--namespace", &ns],
    );
    wait_until(WAIT, "raw samples recorded", || {
        last_seq(&rec, service::RAW) > 500
    });
    let kids = children(stack.pid());
    let mut exes: Vec<&str> = kids.iter().map(|(_, exe)| exe.as_str()).collect();
    exes.sort_unstable();
    assert_eq!(
        exes,
        [
            "mems-acquire",
            "mems-calibrate",
            "mems-odometry",
            "mems-record"
        ]
    );
    let pids: Vec<u32> = kids
        .iter()
        .map(|(pid, _)| *pid)
        .chain([stack.pid()])
        .collect();
    let mut nodes = Vec::new();
    // At least one node per process (a process may hold a second, port-less one for its
    // dead-node cleanup thread).
    wait_until(WAIT, "every process's iceoryx2 node", || {
        let per_process: Vec<Vec<NodeFootprint>> = pids.iter().map(|&pid| nodes_of(pid)).collect();
        let all = per_process.iter().all(|n| !n.is_empty());
        nodes = per_process.into_iter().flatten().collect();
        all
    });
    // The stack's private work directory: mems-stack-PID- and random characters, 0700.
    let prefix = format!("mems-stack-{}-", stack.pid());
    let work = std::fs::read_dir(std::env::temp_dir())
        .unwrap()
        .flatten()
        .find(|e| e.file_name().to_string_lossy().starts_with(&prefix))
        .map(|e| e.path())
        .unwrap_or_else(|| panic!("no {prefix}* directory while the stack runs"));
    let meta = work.symlink_metadata().unwrap();
    assert!(meta.is_dir());
    assert_eq!(
        std::os::unix::fs::PermissionsExt::mode(&meta.permissions()) & 0o777,
        0o700,
        "{} is private",
        work.display()
    );

    stack.signal(libc::SIGKILL);
    let killed = std::time::Instant::now();
    let (status, _) = stack.wait(WAIT);
    assert_eq!(
        std::os::unix::process::ExitStatusExt::signal(&status),
        Some(libc::SIGKILL)
    );
    wait_until(WAIT, "every child of the killed stack dead", || {
        kids.iter().all(|(pid, _)| !alive(*pid))
    });
    eprintln!(
        "the killed stack's children were gone {:.0} ms after the kill",
        killed.elapsed().as_secs_f64() * 1e3
    );

    // A stack that cannot record where asked stops before anything starts, file untouched.
    let left = std::fs::read(&rec).unwrap();
    let refused = Proc::spawn(
        "mems-stack",
        &["--record", path_arg(&rec), "--namespace", &ns],
    );
    let (status, _) = refused.wait(WAIT);
    assert!(!status.success(), "an existing recording is refused");
    assert_eq!(std::fs::read(&rec).unwrap(), left, "and left as it was");

    run_ok("mems-stack", &["--duration", "1", "--namespace", &ns]);
    for node in &nodes {
        assert_eq!(leftovers(node), Vec::<std::path::PathBuf>::new());
    }
    for pid in pids {
        assert_eq!(nodes_of(pid), [], "node of process {pid} left behind");
    }
    assert!(!work.exists(), "{} left behind", work.display());
    for base in [service::RAW, service::CORRECTED, service::ODOMETRY] {
        assert!(!service_exists(&ns, base), "{base} left behind");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
