//! `mems-stack` with a subscriber of its raw samples that stops taking them after its first
//! sample, as a client process that hangs or is stopped (SIGSTOP): this test process holds
//! the subscriber (simulated MPU-9250 at 1 kHz, unique namespace).
//!
//! Asserted: acquire does not wait on the stopped subscriber for as long as its sensor FIFO
//! lasts (a wait of 2 s, as before, loses about 1950 samples at the FIFO; the bound used here,
//! 1000, leaves room for what a loaded machine loses anyway), it gives the stopped
//! subscriber's samples up, and the stack's summary counts them (`undelivered`), while the
//! stack's own stages lose nothing.
//!
//! (`mems-acquire` killed with SIGKILL, and what its restart lost counted at the source:
//! `acquire_resume.rs`.)

use std::time::Duration;

use integration_tests::{Proc, unique_namespace, wait_until};
use ipc_types::{RawImuSample, service};

/// The number after `label` in `line` (e.g. "undelivered 5" -> 5).
fn count_after(line: &str, label: &str) -> u64 {
    let at = line
        .find(label)
        .unwrap_or_else(|| panic!("{label:?} missing from: {line}"));
    line[at + label.len()..]
        .split(|c: char| !c.is_ascii_digit())
        .find(|s| !s.is_empty())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no number after {label:?} in: {line}"))
}

#[test]
fn a_stopped_subscriber_loses_samples_counted_and_acquire_keeps_its_fifo() {
    let ns = unique_namespace("stalled");
    let node = service::node().unwrap();
    let raw = service::open::<RawImuSample>(&node, &service::full_name(&ns, service::RAW)).unwrap();
    let stalled = service::subscriber(&raw).unwrap();
    let stack = Proc::spawn("mems-stack", &["--duration", "12", "--namespace", &ns]);
    // Connected once a sample came; then it takes no more: its 4096-sample buffer fills after
    // about 4.1 s at 1 kHz, and the stack publishes for about 12 s.
    wait_until(Duration::from_secs(60), "a first raw sample", || {
        stalled.receive().unwrap().is_some()
    });
    assert_eq!(
        integration_tests::child_named(stack.pid(), "mems-foxglove"),
        None,
        "no live view (and no listening socket) without --foxglove"
    );
    let (status, summary) = stack.wait(Duration::from_secs(60));
    assert!(status.success(), "mems-stack failed: {status}\n{summary}");
    let line = summary
        .lines()
        .find(|l| l.starts_with("sensor lost"))
        .unwrap_or_else(|| panic!("no status line in: {summary}"));
    assert!(
        count_after(line, "undelivered") > 0,
        "the stopped subscriber's samples are counted: {line}"
    );
    assert!(
        count_after(line, "sensor lost") < 1000,
        "acquire waited on the stopped subscriber: {line}"
    );
    for topic in ["raw", "corrected", "odometry"] {
        let hop = &line[line.find(&format!("{topic} ")).unwrap()..];
        assert_eq!(count_after(hop, "lost"), 0, "{topic}: {line}");
    }
    drop(stalled);
}
