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

use std::time::Duration;

use integration_tests::{
    NodeFootprint, Proc, child_named, leftovers, missing_ranges, nodes_of, path_arg,
    service_exists, unique_namespace, wait_until,
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
