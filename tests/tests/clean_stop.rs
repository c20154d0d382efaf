//! A clean stop of a recording stack records no lost publisher: `mems-stack --duration`
//! stops its processes source first and the recorder last, and each publisher announces that
//! it leaves (`ipc_types::wake::LEAVING`), so the recorder writes no `publisher_lost` event and
//! `mems-info` reports "publisher lost 0". (Before the announcement, the recorder saw the
//! three publishers go and wrote `publisher_lost` for each it checked in time.)
//!
//! Needs the binaries: `cargo build -p mems-stack -p acquire -p calibrate -p odometry -p
//! mems-record -p mems-sim -p mems-info` (or `cargo test --workspace`, which builds them).

use integration_tests::{path_arg, run_ok, unique_namespace};
use recording::mcap::{EventKind, read_all};

#[test]
fn a_stack_stopped_cleanly_records_no_lost_publisher() {
    let ns = unique_namespace("clean-stop");
    let dir = std::env::temp_dir().join(&ns);
    std::fs::create_dir_all(&dir).unwrap();
    let run = dir.join("run.mcap");
    run_ok(
        "mems-stack",
        &[
            "--duration",
            "6",
            "--record",
            path_arg(&run),
            "--namespace",
            &ns,
        ],
    );
    let contents = read_all(&run).unwrap();
    assert!(
        contents.raw.len() > 1000,
        "{} raw samples",
        contents.raw.len()
    );
    let lost: Vec<_> = contents
        .events
        .iter()
        .filter(|e| e.kind == EventKind::PublisherLost)
        .collect();
    assert!(lost.is_empty(), "{lost:?}");
    let info = run_ok("mems-info", &[path_arg(&run)]);
    assert!(info.contains("publisher lost 0,"), "{info}");
    let _ = std::fs::remove_dir_all(&dir);
}
