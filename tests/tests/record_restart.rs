//! `mems-stack --record` when its recorder is killed with SIGKILL mid-run (simulated MPU-9250
//! at 1 kHz, unique namespace).
//!
//! Asserted: the stack restarts the recorder, which continues the run in the file's next
//! segment instead of overwriting it; read as one run, the recording holds every sample of
//! every topic but one range around the kill, and each topic's missing range is named by a
//! `gap` event after the new segment's `segment` event. The length of the raw gap is printed
//! (its figure for a 60 s run is measured by the command in docs/acquisition.md); the test
//! bounds it only loosely, so that a loaded machine does not fail it.

use std::time::Duration;

use integration_tests::{
    Proc, child_named, missing_ranges, path_arg, unique_namespace, wait_until,
};
use ipc_types::{odometry_flags, service};
use recording::mcap::{EventKind, read_all};
use recording::segment;

const WAIT: Duration = Duration::from_secs(30);

/// The last raw sequence number in the (possibly still growing) file `path` alone (not its
/// successors); 0 before any.
fn last_raw_seq(path: &std::path::Path) -> u64 {
    recording::mcap::last_seqs(path)
        .ok()
        .and_then(|last| last.iter().find(|(t, _)| *t == service::RAW).map(|l| l.1))
        .unwrap_or(0)
}

#[test]
fn a_killed_recorder_continues_the_run_and_the_gap_is_recorded() {
    let ns = unique_namespace("recrestart");
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
    wait_until(WAIT, "1 s of raw samples recorded", || {
        last_raw_seq(&rec) > 1000
    });
    let record = child_named(stack.pid(), "mems-record").expect("record runs");
    // SAFETY: kill(2) on a process of this test's own stack; no memory is involved.
    assert_eq!(unsafe { libc::kill(record as i32, libc::SIGKILL) }, 0);
    wait_until(WAIT, "mems-record restarted", || {
        child_named(stack.pid(), "mems-record").is_some_and(|new| new != record)
    });
    let second = segment::path(&rec, 1);
    let resumed = last_raw_seq(&rec) + 1000;
    wait_until(WAIT, "1 s of raw samples in the next segment", || {
        last_raw_seq(&second) > resumed
    });
    let (status, summary) = stack.wait(WAIT);
    assert!(status.success(), "mems-stack failed: {status}");
    assert!(
        summary.contains("restarts: record 1, odometry 0, calibrate 0, acquire 0"),
        "{summary}"
    );

    let c = read_all(&rec).unwrap();
    let files: Vec<_> = c.segments.iter().map(|s| s.path.clone()).collect();
    assert_eq!(files, [rec.clone(), second], "the run is two files");
    assert_eq!(
        c.segments[0].truncation, None,
        "the killed recorder's file is whole (a footer after every flush)"
    );
    assert_eq!(
        c.truncation, None,
        "the restarted recorder finished the run"
    );
    assert!(
        c.events
            .iter()
            .any(|e| (e.kind, e.from_seq) == (EventKind::Segment, Some(1))),
        "the split is recorded: {:?}",
        c.events
    );

    let raw: Vec<u64> = c.raw.iter().map(|s| s.seq).collect();
    let corrected: Vec<u64> = c.corrected.iter().map(|s| s.seq).collect();
    let odometry: Vec<u64> = c
        .odometry
        .iter()
        .filter(|s| s.flags & odometry_flags::REVISION == 0)
        .map(|s| s.seq)
        .collect();
    assert_eq!(raw[0], 0, "recorded from the first sample");
    for (topic, seqs) in [
        (service::RAW, &raw),
        (service::CORRECTED, &corrected),
        (service::ODOMETRY, &odometry),
    ] {
        let missing = missing_ranges(seqs);
        assert!(missing.len() <= 1, "{topic}: one range lost: {missing:?}");
        let announced: Vec<(u64, u64)> = c
            .events
            .iter()
            .filter(|e| e.service == topic && e.kind == EventKind::Gap)
            .map(|e| (e.from_seq.unwrap(), e.to_seq.unwrap()))
            .collect();
        assert_eq!(
            announced, missing,
            "{topic}: the gap events name what is missing"
        );
    }
    if let [(from, to)] = missing_ranges(&raw)[..] {
        let at = |seq: u64| {
            c.raw
                .iter()
                .find(|s| s.seq == seq)
                .unwrap()
                .stamps
                .sample_ns
        };
        let gap_ms = (at(to + 1) - at(from - 1)) as f64 * 1e-6;
        eprintln!("raw samples {from}..={to} lost across the recorder restart: {gap_ms:.0} ms");
        assert!(gap_ms < 5000.0, "{gap_ms} ms lost");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
