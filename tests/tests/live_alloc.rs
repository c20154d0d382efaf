//! The live processes allocate nothing per sample in steady state, counted on the real
//! processes: a simulated drive of the calibrated part (so the odometry aligns, moves and
//! revises) replayed at twice real time through `mems-calibrate serve`, `mems-odometry serve`
//! and `mems-record`. Each counts its serving thread's allocation calls after a warm-up of
//! `MEMS_ALLOC_WARMUP` inputs (`alloc_count::steady`) and prints them in its summary:
//!
//! - the stages reach the system allocator 0 times; their pool serves one block per published
//!   message (iceoryx2 0.10's loan, see `alloc_count::pool`) and nothing else;
//! - the recorder's allocations come from the MCAP writer's chunks (mcap 0.26 builds each
//!   chunk's message index and keeps a chunk index for the summary), not from its messages:
//!   at most [`PER_CHUNK`] per chunk flushed (a chunk is closed every 50 ms), fewer than one
//!   per two messages.

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use integration_tests::{Proc, bin, calibrate_sim_part, path_arg, simulate, unique_namespace};

/// Inputs before the steady-state count starts: the calibration stage's 2 s of learning and
/// the odometry's alignment, at 1 kHz, and a margin.
const WARMUP: u64 = 4000;
/// Most allocation calls the recorder may make per chunk flushed.
const PER_CHUNK: u64 = 100;

/// `steady state after W inputs: N inputs, P pool allocations, S system allocations` in
/// `stderr`, as (N, P, S).
fn steady(who: &str, stderr: &str) -> (u64, u64, u64) {
    let line = stderr
        .lines()
        .find(|l| l.contains("steady state after"))
        .unwrap_or_else(|| panic!("{who}: no steady-state line in\n{stderr}"));
    let at = line.find("steady state after").unwrap();
    let after: Vec<u64> = line[at..]
        .split(|c: char| !c.is_ascii_digit())
        .filter_map(|w| w.parse().ok())
        .collect();
    assert!(after.len() >= 4, "{who}: {line}");
    assert_eq!(
        after[0], WARMUP,
        "{who}: warm-up not taken from the environment: {line}"
    );
    (after[1], after[2], after[3])
}

/// The number after `key` in `text` (e.g. "published 123").
fn number_after(text: &str, key: &str) -> u64 {
    let at = text
        .find(key)
        .unwrap_or_else(|| panic!("no {key:?} in\n{text}"))
        + key.len();
    text[at..]
        .trim_start()
        .split(|c: char| !c.is_ascii_digit())
        .next()
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no number after {key:?} in\n{text}"))
}

/// A live process whose stderr goes to a file; killed if the test fails before stopping it.
struct Live(Child);

impl Drop for Live {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts binary `name` with `args` in namespace `ns`, the warm-up in its environment, stderr
/// to `dir/name.err`.
fn start(dir: &Path, name: &str, args: &[&str], ns: &str) -> Live {
    let err = std::fs::File::create(dir.join(format!("{name}.err"))).unwrap();
    let child = Command::new(bin(name))
        .args(args)
        .args(["--namespace", ns])
        .env("MEMS_ALLOC_WARMUP", WARMUP.to_string())
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::from(err))
        .spawn()
        .unwrap_or_else(|e| panic!("cannot start {name}: {e}"));
    Live(child)
}

/// Stops `live` with SIGTERM, waits for its exit and returns its stderr (its summary).
fn stop(dir: &Path, name: &str, mut live: Live) -> String {
    // SAFETY: kill(2) on our own child; no memory is involved.
    let rc = unsafe { libc::kill(live.0.id() as i32, libc::SIGTERM) };
    assert_eq!(rc, 0, "kill({name}) failed");
    let status = live.0.wait().unwrap();
    assert!(status.success(), "{name} failed: {status}");
    std::fs::read_to_string(dir.join(format!("{name}.err"))).unwrap()
}

#[test]
fn live_processes_allocate_nothing_per_sample_in_steady_state() {
    let dir = std::env::temp_dir().join(unique_namespace("live-alloc"));
    std::fs::create_dir_all(&dir).unwrap();
    let calib = calibrate_sim_part(&dir, 1);
    // The calibrated part (datasheet preset, seed 1) driving: 4 s of rest, then motions.
    let drive = simulate(
        &dir,
        "drive.mcap",
        &[
            "drive",
            "--duration",
            "24",
            "--rate",
            "1000",
            "--initial-rest",
            "4",
            "--preset",
            "datasheet",
            "--seed",
            "1",
        ],
    );
    let ns = unique_namespace("live-alloc");
    let calib = path_arg(&calib);
    let out = dir.join("run.mcap");
    let record = start(&dir, "mems-record", &["--out", path_arg(&out)], &ns);
    let odometry = start(&dir, "mems-odometry", &["serve", "--calib", calib], &ns);
    let calibrate = start(
        &dir,
        "mems-calibrate",
        &[
            "serve",
            "--calib",
            calib,
            "--learn-s",
            "2",
            "--learn-first-s",
            "2",
        ],
        &ns,
    );
    // The recorder and the calibration stage subscribe to the raw samples.
    let (status, replayed) = Proc::spawn(
        "mems-replay",
        &[
            path_arg(&drive),
            "--speed",
            "2",
            "--wait-subscribers",
            "2",
            "--wait-timeout",
            "60",
            "--namespace",
            &ns,
        ],
    )
    .wait(Duration::from_secs(120));
    assert!(status.success(), "mems-replay failed: {status}: {replayed}");
    // Samples still queued when a stage stops only shorten its count.
    let calibrate = stop(&dir, "mems-calibrate", calibrate);
    let odometry = stop(&dir, "mems-odometry", odometry);
    let record = stop(&dir, "mems-record", record);

    let (n, pool, system) = steady("mems-calibrate", &calibrate);
    assert!(n >= 15_000, "mems-calibrate: {n} steady-state samples");
    assert_eq!(
        system, 0,
        "mems-calibrate: {system} system allocations for {n} samples"
    );
    assert!(
        pool <= n,
        "mems-calibrate: {pool} pool blocks for {n} samples: more than iceoryx2's loan"
    );
    assert!(
        calibrate.contains("0 requests found it empty"),
        "{calibrate}"
    );

    let (n, pool, system) = steady("mems-odometry", &odometry);
    assert!(n >= 15_000, "mems-odometry: {n} steady-state samples");
    let received = number_after(&odometry, "received");
    let published = number_after(&odometry, "published");
    assert!(
        published > received,
        "the odometry published revisions (its hindsight ran): {odometry}"
    );
    assert_eq!(
        system, 0,
        "mems-odometry: {system} system allocations for {n} samples"
    );
    assert!(
        pool <= published,
        "mems-odometry: {pool} pool blocks, more than the {published} states published"
    );
    assert!(odometry.contains("0 requests found it empty"), "{odometry}");

    let (n, pool, system) = steady("mems-record", &record);
    let chunks = number_after(&record, "system allocations,");
    assert!(n >= 50_000, "mems-record: {n} steady-state messages");
    assert!(chunks >= 1, "{record}");
    let calls = pool + system;
    assert!(
        calls <= PER_CHUNK * chunks,
        "mems-record: {calls} allocations for {chunks} chunks ({n} messages)"
    );
    assert!(
        calls * 2 < n,
        "mems-record: {calls} allocations for {n} messages: not per chunk"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
